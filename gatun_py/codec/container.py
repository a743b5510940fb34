"""The ``.tetc`` container: magic, version, JSON metadata with a section index, CRC32'd sections.

Layout (all integers little endian; see ``docs/format.md``)::

    offset 0   8 bytes   magic  b"TETC\\x89\\r\\n\\x1a"
           8   u16       format version (major)
          10   u16       format version (minor, readers ignore it)
          12   u32       metadata length L (bytes of UTF-8 JSON)
          16   u32       CRC32 of the metadata
          20   L bytes   metadata JSON; its "sections" list is the index:
                         [{"name", "offset", "length", "crc32"}, ...], offsets from file start
          ...  sections, each a record:
                 u16 name length, name (UTF-8), u64 payload length, u32 payload CRC32, payload

A reader checks the magic, the version, the metadata CRC and every index entry against the file
size before allocating anything, then reads (and CRC-checks) only the sections it needs.
"""

from __future__ import annotations

import json
import os
import struct
import zlib

from .._compile_notice import is_tetc  # noqa: F401  (the one test of a .tetc file; a base module needs no codec)
from ..errors import CorruptFileError, FormatVersionError, ReadError

MAGIC = b"TETC\x89\r\n\x1a"
VERSION_MAJOR = 11  # 2: float64 coordinates and every point array (points64, array/j); 3: forest coded after
#                    the mesh, bricks (B{k}/...), merge dependencies (deps); 4: geometry coding 2
#                    (geometry.coding_for_format maps the version to the geometry block's coding);
#                    5: new codings of the connectivity, geometry and forest sections (each module's
#                    coding_for_format maps the version to its section's coding); 6: room for the
#                    next codings of the geometry and forest sections, chosen the same way; 7: forest
#                    coding 3 (the level's quadrics rank the parents and give the rounds a context);
#                    8: geometry coding 4 (value tables apart, chained to the next coarser level's)
#                    9: geometry coding 5 (rank steps on the table-mode channels)
#                    10: time series (steps) and cells as given
#                    11: higher-order nodes coded on their cells' edges and faces (node_refs), cell
#                    arrays as a constant or a counter, each step's cell arrays (S{k}/cell/j):
#                    a version-10 reader would misread or drop them, so it refuses the file
VERSION_MINOR = 0
_PREAMBLE = struct.Struct("<8sHHII")
PREAMBLE_SIZE = _PREAMBLE.size
_REC_NAME = struct.Struct("<H")
_REC_LEN = struct.Struct("<QI")

MAX_METADATA_BYTES = 16 << 20
MAX_SECTIONS = 1 << 16  # 64 bricks x 13 levels x 5 sections already pass 4096
MAX_NAME_BYTES = 256


def record_head(name: str, payload: bytes) -> bytes:
    """The bytes before a section's payload in its record (name, length, crc32)."""
    nb = name.encode("utf-8")
    return _REC_NAME.pack(len(nb)) + nb + _REC_LEN.pack(len(payload), zlib.crc32(payload))


def _record(name: str, payload: bytes) -> bytes:
    return record_head(name, payload) + payload


def build_container(meta: dict, sections: list[tuple[str, bytes]]) -> bytes:
    """Assemble a ``.tetc`` file from metadata and named sections (in this order).

    The section index is written into ``meta["sections"]``.
    """
    names = [n for n, _ in sections]
    if len(set(names)) != len(names):
        raise ValueError("duplicate section names")
    records = [_record(n, bytes(p)) for n, p in sections]
    rows = [(name, len(rec) - len(payload), len(payload), zlib.crc32(payload))
            for (name, payload), rec in zip(sections, records)]
    return container_head(meta, rows) + b"".join(records)


def container_head(meta: dict, rows: list) -> bytes:
    """Preamble and metadata of a container whose sections follow as records of ``rows``
    (``(name, head length, payload length, crc32)`` in file order): the bytes
    :func:`build_container` puts before its first record, for writers that stream the records."""
    # the metadata length depends on the offsets it contains: iterate until it is stable
    meta = dict(meta)
    meta_len = 0
    for _ in range(8):
        off = PREAMBLE_SIZE + meta_len
        index = []
        for name, head, length, crc in rows:
            index.append({"name": name, "offset": off + head, "length": length, "crc32": crc})
            off += head + length
        meta["sections"] = index
        blob = json.dumps(meta, separators=(",", ":"), sort_keys=False).encode("utf-8")
        if len(blob) == meta_len:
            break
        meta_len = len(blob)
    else:  # pragma: no cover - lengths converge after two rounds
        raise RuntimeError("metadata length did not converge")
    return _PREAMBLE.pack(MAGIC, VERSION_MAJOR, VERSION_MINOR, len(blob), zlib.crc32(blob)) + blob


def split_container(source) -> tuple[dict, list[tuple[str, bytes]]]:
    """The metadata (without its section index) and every ``(name, payload)`` of a file, in file
    order: what :func:`build_container` takes, so a file can be rebuilt with changes.

    Examples
    --------
    >>> data = build_container({"format": "x"}, [("a", b"12"), ("b", b"")])
    >>> split_container(data)
    ({'format': 'x'}, [('a', b'12'), ('b', b'')])
    """
    c = source if isinstance(source, Container) else Container(source)
    meta = {k: v for k, v in c.meta.items() if k != "sections"}
    return meta, [(name, c.read_section(name)) for name in c.section_names()]


class Container:
    """Read access to a ``.tetc`` file (path or bytes).

    Parameters
    ----------
    source : str, os.PathLike or bytes
        A file path (sections are read lazily with seeks) or the whole file in memory.

    Attributes
    ----------
    meta : dict
        The metadata; ``meta["sections"]`` is the index.
    size : int
        The file size in bytes.
    """

    def __init__(self, source):
        if isinstance(source, (bytes, bytearray, memoryview)):
            self._data = bytes(source)
            self._path = None
            self.size = len(self._data)
            self.name = "<bytes>"
        else:
            self._data = None
            self._path = os.fspath(source)
            self.name = self._path
            try:
                self.size = os.path.getsize(self._path)
                with open(self._path, "rb"):
                    pass
            except FileNotFoundError:
                raise ReadError(f"{self._path}: no such file") from None
            except IsADirectoryError:
                raise ReadError(f"{self._path}: is a directory") from None
            except OSError as e:
                raise ReadError(f"{self._path}: cannot read ({e.strerror})") from None
        pre = self._read(0, PREAMBLE_SIZE)
        if len(pre) < 8 or pre[:8] != MAGIC:
            raise CorruptFileError(f"{self.name}: not a .tetc file (bad magic bytes)")
        if len(pre) < PREAMBLE_SIZE:
            raise CorruptFileError(f"{self.name}: truncated .tetc header")
        _, major, _minor, meta_len, meta_crc = _PREAMBLE.unpack(pre)
        if major > VERSION_MAJOR:
            raise FormatVersionError(
                f"{self.name}: written by a newer tetc (format version {major}, this reader knows {VERSION_MAJOR})")
        if major < 1:
            raise CorruptFileError(f"{self.name}: invalid format version {major}")
        self.major = int(major)
        if meta_len > MAX_METADATA_BYTES or PREAMBLE_SIZE + meta_len > self.size:
            raise CorruptFileError(f"{self.name}: truncated or corrupt metadata block")
        blob = self._read(PREAMBLE_SIZE, meta_len)
        if zlib.crc32(blob) != meta_crc:
            raise CorruptFileError(f"{self.name}: metadata checksum mismatch (corrupt file)")
        try:
            meta = json.loads(blob.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            raise CorruptFileError(f"{self.name}: metadata is not valid JSON") from None
        if not isinstance(meta, dict) or not isinstance(meta.get("sections"), list):
            raise CorruptFileError(f"{self.name}: metadata lacks the section index")
        index = {}
        data_start = PREAMBLE_SIZE + meta_len
        if len(meta["sections"]) > MAX_SECTIONS:
            raise CorruptFileError(f"{self.name}: absurd number of sections")
        for e in meta["sections"]:
            try:
                name, off, length, crc = e["name"], e["offset"], e["length"], e["crc32"]
            except (TypeError, KeyError):
                raise CorruptFileError(f"{self.name}: malformed section index") from None
            ints = all(isinstance(x, int) and not isinstance(x, bool) for x in (off, length, crc))
            if not (isinstance(name, str) and ints):
                raise CorruptFileError(f"{self.name}: malformed section index")
            if name in index or off < data_start or length < 0 or off + length > self.size or not 0 <= crc < 2**32:
                raise CorruptFileError(f"{self.name}: section {name!r} lies outside the file (truncated or corrupt)")
            index[name] = (off, length, crc)
        self.meta = meta
        self.index = index

    def _read(self, offset: int, length: int) -> bytes:
        if self._data is not None:
            return self._data[offset:offset + length]
        try:
            with open(self._path, "rb") as fh:
                fh.seek(offset)
                return fh.read(length)
        except OSError as e:
            raise ReadError(f"{self._path}: cannot read ({e.strerror})") from None

    def section_names(self) -> list[str]:
        return list(self.index)

    def section_size(self, name: str) -> int:
        return self.index[name][1]

    def has_section(self, name: str) -> bool:
        return name in self.index

    def read_section_head(self, name: str, n: int) -> bytes:
        """The first ``n`` bytes of section ``name``'s payload, not CRC-checked (for header checks that
        come before allocating; :meth:`read_section` checks the whole payload)."""
        if name not in self.index:
            raise CorruptFileError(f"{self.name}: missing section {name!r}")
        off, length, _ = self.index[name]
        return self._read(off, min(int(n), length))

    def read_section(self, name: str) -> bytes:
        """The payload of section ``name``, CRC-checked (the record header is checked too)."""
        if name not in self.index:
            raise CorruptFileError(f"{self.name}: missing section {name!r}")
        off, length, crc = self.index[name]
        nb = name.encode("utf-8")
        head = _REC_NAME.size + len(nb) + _REC_LEN.size
        if off - head < 0:
            raise CorruptFileError(f"{self.name}: corrupt section index")
        rec = self._read(off - head, head + length)
        if len(rec) != head + length:
            raise CorruptFileError(f"{self.name}: section {name!r} is truncated")
        (nlen,) = _REC_NAME.unpack_from(rec, 0)
        rlen, rcrc = _REC_LEN.unpack_from(rec, _REC_NAME.size + len(nb))
        if nlen != len(nb) or rec[_REC_NAME.size:_REC_NAME.size + len(nb)] != nb or rlen != length or rcrc != crc:
            raise CorruptFileError(f"{self.name}: section {name!r} header does not match the index")
        payload = rec[head:]
        if zlib.crc32(payload) != crc:
            raise CorruptFileError(f"{self.name}: section {name!r} checksum mismatch (corrupt file)")
        return payload


