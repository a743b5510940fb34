"""Exact coding of a point array in its own dtype: the ``L{i}/array/{j}`` and ``L{i}/points64`` sections.

Any (n,) or (n, k) array of float32, float64 or integers, in decode order, comes back bit for bit
(``-0.0``, NaN payloads, denormals, any integer). Per component:

1. every value becomes a *reduced ordered integer*: a float's sign and magnitude bits folded so that
   integer order is float order (``m`` for positive, ``~m`` for negative), an integer its value;
   then shifted right by the component's common trailing zero bits (a float64 array that holds
   float32 values loses its 29 zero bits here);
2. a predictor, chosen by the encoder per component, predicts each vertex from the vertices the
   connectivity coder put around it (the refs ``(a, b, c, apex)`` of :mod:`.geometry`: the face the
   vertex closes and the apex behind it), from the previous vertex, from the float32 rounding
   that the geometry section already holds (coordinates, the default scalar), or as the linear
   field through the ref tet at the vertex's float32 position (computed on values in float64);
3. the residual modulo 2**64 is zigzagged and coded by one of two coders, whichever is smaller:
   *range*: range coded (:mod:`.rangecoder`), its bit length in a context (the bit length of the
   first ref's residual), three modelled bits below the leading one, the rest raw; *planes*: a
   width byte w, then an xz (LZMA) stream of the w low bytes of every residual, plane by plane
   (it wins on repeated patterns). The encoder range-codes every predictor, keeps the smallest,
   and tries the planes on that predictor's residuals.

Layout (little endian)::

    u8  version (1)
    u8  dtype code (DTYPES)
    u16 components k
    u32 n
    k x (u8 predictor (0-6), u8 shift, u8 coder (0 range, 1 planes), u32 stream length)
    ... the k streams

The decoder checks the header against what the metadata expects and the stream lengths against the
block's size, checks every ref in its kernel, and requires each stream to be consumed exactly.
"""

from __future__ import annotations

import lzma
import struct

import numpy as np

from ..errors import CorruptFileError
from . import _array_kernels as K
from .rangecoder import check_decoder, dec_init, dec_state, enc_state, new_model

__all__ = ["DTYPES", "encode_array", "ArrayDecoder", "dtype_name", "check_dtype"]

FORMAT_VERSION = 1
DTYPES = ["float32", "float64", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64"]
MAX_COMPONENTS = 1024
_HEADER = struct.Struct("<BBHI")
_COMPONENT = struct.Struct("<BBBI")
CODER_RANGE, CODER_PLANES = 0, 1
# LZMA's best ratio on real residual planes is far below this; a planes stream that claims more
# output per input byte is a bomb (checked before decompressing)
_MAX_EXPANSION = 1 << 16  # xz reaches ~7000:1 on long runs of zeros (a constant array is legit)
_MAX_VALUES_PER_RANGE_BYTE = 1024


def dtype_name(dtype) -> str:
    """The format's name of a supported dtype (byte order dropped), or ValueError."""
    dt = np.dtype(dtype)
    name = dt.newbyteorder("=").name if dt.byteorder not in "=|" else dt.name
    if name == "bool":
        name = "uint8"
    if name not in DTYPES:
        raise ValueError(f"unsupported point-array dtype {dt} (supported: {', '.join(DTYPES)})")
    return name


def check_dtype(name) -> np.dtype:
    """The numpy dtype of a format dtype name; CorruptFileError for anything else."""
    if not isinstance(name, str) or name not in DTYPES:
        raise CorruptFileError(f"corrupt metadata: unknown array dtype {name!r}")
    return np.dtype(name).newbyteorder("<")


def _is_float(dt: np.dtype) -> bool:
    return dt.kind == "f"


def _bits(dt: np.dtype) -> int:
    return dt.itemsize * 8


def _to_int64(values: np.ndarray) -> np.ndarray:
    """The raw bit pattern (floats) or value (integers) as int64, per element."""
    dt = values.dtype
    if _is_float(dt):
        return values.view(np.int32 if dt.itemsize == 4 else np.int64).astype(np.int64)
    if dt == np.uint64:
        return values.view(np.int64).astype(np.int64)
    return values.astype(np.int64)


def _shift_of(raw: np.ndarray, dt: np.dtype) -> int:
    """Common trailing zero bits of the magnitudes (floats) or values (integers)."""
    mag = raw & ((1 << (_bits(dt) - 1)) - 1) if _is_float(dt) else raw
    acc = np.bitwise_or.reduce(mag) if mag.size else 0
    if acc == 0:
        return 0
    acc = int(acc) & 0xFFFFFFFFFFFFFFFF
    return (acc & -acc).bit_length() - 1


def _bounds(dt: np.dtype, shift: int) -> tuple[int, int]:
    """The range of reduced ordered integers of a dtype after ``shift`` (predictions are clamped to it)."""
    if _is_float(dt):
        hi = ((1 << (_bits(dt) - 1)) - 1) >> shift
        return -hi - 1, hi
    if dt == np.uint64:
        return -(1 << 63) >> shift, ((1 << 63) - 1) >> shift
    info = np.iinfo(dt)
    return int(info.min) >> shift, int(info.max) >> shift


def _reduce(raw: np.ndarray, dt: np.dtype, shift: int) -> np.ndarray:
    """raw int64 patterns -> reduced ordered int64 (exact: the shifted-out bits are zero)."""
    if _is_float(dt):
        mbits = _bits(dt) - 1
        m = (raw & ((1 << mbits) - 1)) >> shift
        return np.where(raw < 0, ~m, m)
    return raw >> shift


def _expand(o: np.ndarray, dt: np.dtype, shift: int) -> np.ndarray:
    """Inverse of :func:`_reduce` into an array of dtype ``dt``."""
    if _is_float(dt):
        neg = o < 0
        m = np.where(neg, ~o, o) << shift
        if dt.itemsize == 8:
            u = m.astype(np.uint64) | (neg.astype(np.uint64) << np.uint64(63))
            return u.view(np.float64)
        u = (m | (neg.astype(np.int64) << 31)).astype(np.uint32)
        return u.view(np.float32)
    v = o << shift
    if dt == np.uint64:
        return v.view(np.uint64)
    return v.astype(dt)


def _external(pred_values: np.ndarray, dt: np.dtype, shift: int, lo: int, hi: int) -> np.ndarray:
    """Reduced ordered image of an external prediction given as values (any float or int array)."""
    if _is_float(dt):
        return np.clip(_reduce(_to_int64(np.asarray(pred_values).astype(dt)), dt, shift), lo, hi)
    v = np.nan_to_num(np.asarray(pred_values, np.float64), nan=0.0)
    v = np.clip(v, -9.2e18, 9.2e18).astype(np.int64) >> shift
    return np.clip(v, lo, hi)


def _lin_state(dt: np.dtype, shift: int, positions, values: np.ndarray) -> tuple:
    """The tuple the kernels' linear predictor works with (see ``_array_kernels._predict``):
    positions (n, 4) float32, the vertices' values as float64 (filled by the kernels), the value
    kind and shift, and scratch views for bit casts."""
    kind = K.VALUE_INT if not _is_float(dt) else (K.VALUE_F64 if dt.itemsize == 8 else K.VALUE_F32)
    i64 = np.zeros(1, np.int64)
    i32 = np.zeros(1, np.int32)
    pos = positions if positions is not None else np.zeros((0, 4), np.float32)
    return (pos, values, np.array([kind, shift], np.int64), i64, i64.view(np.float64), i32, i32.view(np.float32))


def encode_array(values, refs, *, external=None, positions=None) -> bytes:
    """Code a point array exactly, in decode order.

    Parameters
    ----------
    values : (n,) or (n, k) array
        float32, float64 or integer values (bool is stored as uint8).
    refs : (n, 4) int32
        The geometry refs of every vertex (decode ids ``< k`` or -1).
    external : array of the same shape, optional
        A prediction the decoder will have too (the float32 rounding held by the geometry section).
    positions : (n, 3) float32, optional
        The vertices' float32 coordinates (the geometry section's): enables the linear predictor.

    Returns
    -------
    bytes

    Examples
    --------
    >>> import numpy as np
    >>> v = np.array([0.1, 0.2, -0.0, np.pi])
    >>> refs = np.array([[-1] * 4, [0, -1, -1, -1], [0, 1, -1, -1], [0, 1, 2, -1]], np.int32)
    >>> d = ArrayDecoder(encode_array(v, refs), n_points=4, dtype="float64", components=1)
    >>> out = d.decode(refs)
    >>> out.view(np.int64).tolist() == v.view(np.int64).tolist()
    True
    """
    values = np.asarray(values)
    dt = np.dtype(dtype_name(values.dtype)).newbyteorder("<")
    values = np.ascontiguousarray(values, dtype=dt)
    n = values.shape[0]
    k = 1 if values.ndim == 1 else (values.shape[1] if values.ndim == 2 else MAX_COMPONENTS + 1)
    cols = values.reshape(n, k) if k <= MAX_COMPONENTS else values
    if values.ndim > 2 or k > MAX_COMPONENTS or (values.ndim == 2 and k == 0):
        raise ValueError(f"point arrays are (n,) or (n, k) with k <= {MAX_COMPONENTS}, got shape {values.shape}")
    refs = np.ascontiguousarray(refs, dtype=np.int32)
    if refs.shape != (n, 4):
        raise ValueError(f"refs must have shape ({n}, 4), got {refs.shape}")
    ext_cols = None if external is None else np.asarray(external).reshape(n, k)
    pos4 = None
    if positions is not None:
        pos4 = np.zeros((n, 4), np.float32)
        pos4[:, :3] = np.asarray(positions, np.float32).reshape(n, 3)
    header = [_HEADER.pack(FORMAT_VERSION, DTYPES.index(dtype_name(dt)), k, n)]
    streams = []
    for c in range(k):
        raw = _to_int64(cols[:, c])
        shift = _shift_of(raw, dt)
        lo, hi = _bounds(dt, shift)
        o = np.ascontiguousarray(_reduce(raw, dt, shift))
        ext = (np.ascontiguousarray(_external(ext_cols[:, c], dt, shift, lo, hi)) if ext_cols is not None
               else np.zeros(0, np.int64))
        kinds = [kind for kind in range(K.N_PREDICTORS) if (kind != K.PRED_EXTERNAL or ext_cols is not None)
                 and (kind != K.PRED_LINEAR or pos4 is not None)]
        lin = _lin_state(dt, shift, pos4, np.zeros(n if pos4 is not None else 0))
        best = None
        for kind in kinds:
            zz = K.residuals(o, refs, kind, ext if kind == K.PRED_EXTERNAL else o[:0], lo, hi, lin)
            stream = _range_code(zz, refs)
            if best is None or len(stream) < len(best[2]):
                best = (kind, CODER_RANGE, stream, zz)
        planes = _planes(best[3])
        if len(planes) < len(best[2]):
            best = (best[0], CODER_PLANES, planes, None)
        header.append(_COMPONENT.pack(best[0], shift, best[1], len(best[2])))
        streams.append(best[2])
    return b"".join(header) + b"".join(streams)


def _planes(zz: np.ndarray) -> bytes:
    n = zz.shape[0]
    top = int(zz.view(np.uint64).max()) if n else 0
    width = max(1, (top.bit_length() + 7) // 8)
    b = np.ascontiguousarray(zz.view(np.uint8).reshape(n, 8)[:, :width].T).tobytes()
    return bytes([width]) + lzma.compress(b, preset=9 | lzma.PRESET_EXTREME)


def _unplanes(stream: bytes, n: int) -> np.ndarray:
    """Residuals of a planes stream, decompressing no more than they can fill."""
    if len(stream) < 1 or not 1 <= stream[0] <= 8:
        raise CorruptFileError("corrupt array section: bad plane width")
    width = stream[0]
    raw_len = n * width
    if raw_len > _MAX_EXPANSION * (len(stream) - 1) + 4096:
        raise CorruptFileError(f"corrupt array section: {raw_len} bytes cannot come from {len(stream) - 1}")
    try:
        dec = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)
        body = dec.decompress(stream[1:], max_length=raw_len + 1)
    except lzma.LZMAError as e:
        raise CorruptFileError(f"corrupt array section: {e}") from None
    if len(body) != raw_len or not dec.eof or dec.unused_data:
        raise CorruptFileError("corrupt array section: payload has the wrong length")
    zz = np.zeros((n, 8), np.uint8)
    zz[:, :width] = np.frombuffer(body, np.uint8).reshape(width, n).T
    return zz.view(np.int64).reshape(n)


def _range_code(zz: np.ndarray, refs: np.ndarray) -> bytes:
    n = zz.shape[0]
    st = enc_state()
    out = np.empty(16 * n + 64, np.uint8)  # at most ~9 bytes per residual: never overflows
    nbytes = K.encode_residuals(st, out, zz, refs, new_model(K.MODEL_SIZE), np.zeros(n, np.uint8))
    return out[:nbytes].tobytes()


class ArrayDecoder:
    """Streaming decoder of one coded point array, batch by batch in decode order.

    Parameters
    ----------
    data : bytes
        The section written by :func:`encode_array`.
    n_points : int
        Vertices the level has (the header must agree).
    dtype : str
        The dtype the metadata announces (the header must agree).
    components : int
        Components the metadata announces (the header must agree).

    Attributes
    ----------
    values : (n,) or (n, k) array of ``dtype``
        Filled up to :attr:`n_decoded`.
    """

    def __init__(self, data, *, n_points: int, dtype: str, components: int):
        data = bytes(data)
        dt = check_dtype(dtype)
        if len(data) < _HEADER.size:
            raise CorruptFileError("corrupt array section: truncated header")
        version, code, k, n = _HEADER.unpack_from(data)
        if version != FORMAT_VERSION:
            raise CorruptFileError(f"corrupt array section: unknown version {version}")
        if code >= len(DTYPES) or DTYPES[code] != dtype_name(dt) or k != components or not 1 <= k <= MAX_COMPONENTS:
            raise CorruptFileError("corrupt array section: dtype or components do not match the metadata")
        if n != n_points:
            raise CorruptFileError(f"corrupt array section: {n} values, the level has {n_points} points")
        off = _HEADER.size + k * _COMPONENT.size
        if len(data) < off:
            raise CorruptFileError("corrupt array section: truncated header")
        self.kinds, self.shifts, self.coders, lengths = [], [], [], []
        for c in range(k):
            kind, shift, coder, length = _COMPONENT.unpack_from(data, _HEADER.size + c * _COMPONENT.size)
            if kind >= K.N_PREDICTORS or shift >= _bits(dt) or coder not in (CODER_RANGE, CODER_PLANES):
                raise CorruptFileError("corrupt array section: bad component header")
            self.kinds.append(kind)
            self.shifts.append(shift)
            self.coders.append(coder)
            lengths.append(length)
        if off + sum(lengths) != len(data):
            raise CorruptFileError("corrupt array section: stream lengths do not match the section size")
        for coder, length in zip(self.coders, lengths):
            # a range-coded value costs at least 7 decisions of the most skewed probability the coder
            # reaches (~0.01 bit): more values per byte cannot be (checked before allocating)
            if coder == CODER_RANGE and n > _MAX_VALUES_PER_RANGE_BYTE * (length + 16):
                raise CorruptFileError(f"corrupt array section: {n} values cannot fit in a {length}-byte stream")
        self.n_points, self.dtype, self.components = int(n), dt, int(k)
        buf = np.frombuffer(data, np.uint8)
        self._streams, self._st, self._probs, self._lens, self._o, self._bounds = [], [], [], [], [], []
        self._fv = []
        for c in range(k):
            stream = buf[off:off + lengths[c]]
            off += lengths[c]
            st = dec_state()
            if self.coders[c] == CODER_RANGE:
                dec_init(st, stream)
            else:  # residuals decoded now (bounded by n), the stream is no longer needed
                stream = _unplanes(stream.tobytes(), n)
            self._streams.append(stream)
            self._st.append(st)
            self._probs.append(new_model(K.MODEL_SIZE))
            self._lens.append(np.zeros(n, np.uint8))
            self._o.append(np.zeros(n, np.int64))
            self._bounds.append(_bounds(dt, self.shifts[c]))
            self._fv.append(np.zeros(n if self.kinds[c] == K.PRED_LINEAR else 0))
        self.values = np.empty((n,) if components == 1 else (n, k), dt)
        self.n_decoded = 0

    def needs_external(self) -> bool:
        """True when some component is predicted from the geometry's float32 rounding."""
        return K.PRED_EXTERNAL in self.kinds

    def decode(self, refs, external=None, positions=None) -> np.ndarray:
        """Decode the next ``len(refs)`` vertices (refs as decode ids); returns a view of :attr:`values`.

        ``external`` (same length, the float32 values of the geometry section) is required when
        :meth:`needs_external`; ``positions`` ((n, 4) float32, every vertex's coordinates in
        columns 0-2 at least up to the last one decoded: the geometry decoder's ``values``) when a
        component uses the linear predictor.
        """
        refs = np.ascontiguousarray(refs, dtype=np.int32)
        start, stop = self.n_decoded, self.n_decoded + len(refs)
        if refs.ndim != 2 or refs.shape[1] != 4 or stop > self.n_points:
            raise CorruptFileError("corrupt array section: more vertices than announced")
        ext_cols = None if external is None else np.asarray(external).reshape(len(refs), self.components)
        for c in range(self.components):
            lo, hi = self._bounds[c]
            kind = self.kinds[c]
            ext = np.zeros(0, np.int64)
            if kind == K.PRED_EXTERNAL:
                if ext_cols is None:
                    raise CorruptFileError("corrupt array section: external prediction without a float32 channel")
                ext = np.ascontiguousarray(_external(ext_cols[:, c], self.dtype, self.shifts[c], lo, hi))
            pos = None
            if kind == K.PRED_LINEAR:
                pos = None if positions is None else np.asarray(positions)
                if pos is None or pos.dtype != np.float32 or pos.ndim != 2 or pos.shape[1] < 3 or len(pos) < stop \
                        or not pos.flags.c_contiguous:
                    raise CorruptFileError("corrupt array section: linear prediction without the vertex positions")
            lin = _lin_state(self.dtype, self.shifts[c], pos, self._fv[c])
            if self.coders[c] == CODER_RANGE:
                status = K.decode_component(self._st[c], self._streams[c], self._probs[c], self._lens[c],
                                            self._o[c], refs, start, stop, kind, ext, lo, hi, lin)
                if status != K.BAD_REF:
                    check_decoder(self._st[c], self._streams[c], "array section", complete=False)
            else:
                status = K.reconstruct(self._o[c], self._streams[c], refs, start, stop, kind, ext, lo, hi, lin)
            if status == K.BAD_REF:
                raise CorruptFileError("corrupt file: a vertex refers to one not yet decoded")
            if status != K.OK:
                raise CorruptFileError("corrupt array section: the coded data is damaged")
            col = _expand(self._o[c][start:stop], self.dtype, self.shifts[c])
            if self.components == 1:
                self.values[start:stop] = col
            else:
                self.values[start:stop, c] = col
        self.n_decoded = stop
        return self.values[start:stop]

    def finish(self) -> np.ndarray:
        """The whole array; CorruptFileError unless every vertex was decoded."""
        if self.n_decoded != self.n_points:
            raise CorruptFileError("corrupt array section: fewer vertices decoded than announced")
        for st, stream, coder in zip(self._st, self._streams, self.coders):
            if coder == CODER_RANGE:
                check_decoder(st, stream, "array section")
        return self.values
