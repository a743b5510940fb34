"""PLOT3D single-block grids (XYZ + Q files), as the NASA Blunt-fin and Combustion data.

Layout (no Fortran record markers, no block count, either byte order):

* XYZ file: ``int32 ni, nj, nk``, then ``float32 X[nk][nj][ni]``, ``Y``, ``Z`` (i fastest),
  optionally ``int32 IBLANK[nk][nj][ni]``.
* Q file: ``int32 ni, nj, nk``, ``float32 fsmach, alpha, re, time``, then
  ``float32 Q[5][nk][nj][ni]`` = density, x/y/z momentum, stagnation energy.

A grid read as a mesh keeps all of it: the five Q planes as point arrays under their names
(:data:`Q_STORED`), the free-stream header as field data (:data:`FREE_STREAM`), the grid's hexahedra
as its cells.

Trailing bytes after the data (padding) are ignored.

:func:`refine_grid` makes larger meshes from these grids for scale tests: every cell's trilinear
map is sampled K times finer per axis and the scalar is trilinearly interpolated (no new data).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import OptionError, ReadError
from ..limits import Q_VARIABLES

GAMMA = 1.4


PLOT3D_SUFFIXES = {".bin", ".xyz", ".x", ".p3d", ".q", ".g", ".grd"}


@dataclass(frozen=True)
class Plot3DGrid:
    dims: tuple[int, int, int]  # ni, nj, nk
    xyz: np.ndarray  # (N, 3) float32, i fastest
    iblank: np.ndarray | None  # (N,) int32 or None


def _header(raw: bytes, path) -> tuple[str, tuple[int, int, int]]:
    if len(raw) < 12:
        raise ReadError(f"{path}: too short for a PLOT3D header ({len(raw)} bytes)")
    for bo in (">", "<"):
        d = np.frombuffer(raw[:12], dtype=f"{bo}i4")
        if np.all(d > 0) and np.all(d < 1 << 20):
            n = int(d[0]) * int(d[1]) * int(d[2])
            if 12 + 12 * n <= len(raw) or bo == "<":
                return bo, (int(d[0]), int(d[1]), int(d[2]))
    raise ReadError(f"{path}: not a single-block PLOT3D file (no plausible ni, nj, nk header)")


def looks_like_plot3d_xyz(path) -> bool:
    """Cheap sniff: a 12-byte header of three positive sizes whose product fits the file size."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as fh:
            raw = fh.read(12)
    except OSError:
        return False
    if len(raw) < 12:
        return False
    for bo in (">", "<"):
        d = np.frombuffer(raw, dtype=f"{bo}i4").astype(np.int64)
        if np.all(d > 0) and np.all(d < 1 << 20):
            n = int(np.prod(d))
            if 12 + 12 * n <= size < 12 + 16 * n + 4096:
                return True
    return False


def read_xyz(path) -> Plot3DGrid:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ReadError(f"cannot read {path}: {e.strerror}") from None
    bo, dims = _header(raw, path)
    n = dims[0] * dims[1] * dims[2]
    need = 12 + 12 * n
    if len(raw) < need:
        raise ReadError(f"{path}: PLOT3D grid {dims[0]}x{dims[1]}x{dims[2]} needs {need} bytes, file has {len(raw)}")
    xyz = np.frombuffer(raw, dtype=f"{bo}f4", count=3 * n, offset=12).reshape(3, n).T.astype(np.float32)
    iblank = None
    if len(raw) >= need + 4 * n:
        ib = np.frombuffer(raw, dtype=f"{bo}i4", count=n, offset=need)
        # Only an IBLANK array if the values look like blanking flags, not trailing padding.
        if np.all(np.abs(ib) < 1000) and np.any(ib != 0):
            iblank = ib.astype(np.int32)
    return Plot3DGrid(dims, np.ascontiguousarray(xyz), iblank)


Q_STORED = ("density", "momentum-x", "momentum-y", "momentum-z", "energy")  # the five planes, file order
FREE_STREAM = ("fsmach", "alpha", "re", "time")  # the Q file's header after the sizes


@dataclass(frozen=True)
class Plot3DSolution:
    """A Q file as stored: the free-stream header and the five planes, float32 bit for bit."""

    free_stream: dict  # name -> (1,) float32, in FREE_STREAM order
    planes: np.ndarray  # (5, N) float32, Q_STORED order


def read_q_file(path, dims: tuple[int, int, int]) -> Plot3DSolution:
    """Every value of a Q file: the header ``fsmach, alpha, re, time`` and the five Q planes, each as
    float32 in native byte order (the file's bits)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ReadError(f"cannot read {path}: {e.strerror}") from None
    bo, qdims = _header(raw, path)
    if qdims != tuple(dims):
        raise ReadError(f"{path}: Q file is {qdims[0]}x{qdims[1]}x{qdims[2]}, grid is {dims[0]}x{dims[1]}x{dims[2]}")
    n = dims[0] * dims[1] * dims[2]
    need = 12 + 16 + 20 * n
    if len(raw) < need:
        raise ReadError(f"{path}: PLOT3D Q file needs {need} bytes, file has {len(raw)}")
    head = np.frombuffer(raw, dtype=f"{bo}f4", count=4, offset=12).astype(np.float32)
    planes = np.frombuffer(raw, dtype=f"{bo}f4", count=5 * n, offset=28).reshape(5, n).astype(np.float32)
    return Plot3DSolution({k: head[i:i + 1].copy() for i, k in enumerate(FREE_STREAM)}, planes)


def q_variable(planes: np.ndarray, variable: str, *, dtype=np.float32) -> np.ndarray:
    """One quantity of :data:`Q_VARIABLES` from the five planes: a stored plane exactly, a derived
    one computed in float64 and returned as ``dtype``."""
    if variable not in Q_VARIABLES:
        raise ReadError(f"unknown Q variable {variable!r}; choose one of {', '.join(Q_VARIABLES)}")
    if variable in Q_STORED:
        return np.ascontiguousarray(planes[Q_STORED.index(variable)].astype(dtype))
    q64 = planes.astype(np.float64)
    rho = q64[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        if variable.startswith("velocity-") and variable != "velocity-magnitude":
            out = q64[1 + "xyz".index(variable[-1])] / rho
        elif variable == "velocity-magnitude":
            out = np.sqrt((q64[1:4] ** 2).sum(axis=0)) / rho
        elif variable == "momentum-magnitude":
            out = np.sqrt((q64[1:4] ** 2).sum(axis=0))
        else:  # pressure, ideal gas
            out = (GAMMA - 1.0) * (q64[4] - 0.5 * (q64[1:4] ** 2).sum(axis=0) / rho)
    return out.astype(dtype)


def read_q(path, dims: tuple[int, int, int], variable: str = "density", *, dtype=np.float32) -> np.ndarray:
    """One scalar per grid point from a Q file, as float32 (or ``dtype=np.float64``: the derived
    variables computed and kept in float64, the stored ones exactly)."""
    if variable not in Q_VARIABLES:
        raise ReadError(f"unknown Q variable {variable!r}; choose one of {', '.join(Q_VARIABLES)}")
    return q_variable(read_q_file(path, dims).planes, variable, dtype=dtype)


def grid_hexes(dims: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Hex cells of an ni×nj×nk grid in VTK numbering (i fastest), and the parity colour of points."""
    ni, nj, nk = dims
    idx = np.arange(ni * nj * nk, dtype=np.int64).reshape(nk, nj, ni)
    c = idx[:-1, :-1, :-1]
    di, dj, dk = 1, ni, ni * nj
    hexes = np.stack(
        [c, c + di, c + di + dj, c + dj, c + dk, c + di + dk, c + di + dj + dk, c + dj + dk], axis=-1
    ).reshape(-1, 8)
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    colour = ((i + j + k) % 2).astype(np.int8).reshape(-1)
    return hexes, colour


def find_q_file(xyz_path) -> Path | None:
    """The Q file beside a grid named like ``<name>xyz.bin`` (-> ``<name>q.bin``), if it exists."""
    p = Path(xyz_path)
    i = p.name.lower().rfind("xyz")
    if i < 0:
        return None
    q = "Q" if p.name[i:i + 3].isupper() else "q"
    cand = p.with_name(p.name[:i] + q + p.name[i + 3:])
    return cand if cand.exists() else None


def is_plot3d_input(path, q_file=None) -> bool:
    """Whether :func:`gatun_py.mesh.read_mesh` reads ``path`` as a PLOT3D grid (same test it uses)."""
    p = Path(path)
    return q_file is not None or (p.suffix.lower() in PLOT3D_SUFFIXES and looks_like_plot3d_xyz(p))


def _refine_axis(values: np.ndarray, axis: int, factor: int) -> np.ndarray:
    """Linear interpolation along one axis of a float64 array, ``factor`` sub-intervals per interval.

    Point ``m`` of the refined axis lies at ``m / factor`` in the old index space; it is computed
    as ``a * (1 - t) + b * t`` with ``t = r / factor``, so ``t = 0`` returns ``a`` exactly and the
    old points survive bit for bit.
    """
    n = values.shape[axis]
    if n < 2 or factor == 1:
        return values
    m = np.arange((n - 1) * factor + 1)
    lo = np.minimum(m // factor, n - 2)
    t = (m - lo * factor) / factor  # in [0, 1]; 1 only at the last point
    shape = [1] * values.ndim
    shape[axis] = len(m)
    t = t.reshape(shape)
    a = np.take(values, lo, axis=axis)
    b = np.take(values, lo + 1, axis=axis)
    return a * (1.0 - t) + b * t


def refine_grid(xyz: np.ndarray, scalar: np.ndarray, dims: tuple[int, int, int], factor: int
                ) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """Trilinear refinement of a structured grid and its point scalar, for scale tests.

    Every cell of the ``ni × nj × nk`` grid is cut into ``factor³`` cells: the new points lie on
    the cell's trilinear map (the same map a trilinear hex element uses), and the scalar is
    trilinearly interpolated there. The result is again a structured grid, so the usual
    conforming 5-tet split applies unchanged. The interpolated scalar adds no information: use
    this to make larger meshes for timing and memory tests, not as data.

    Parameters
    ----------
    xyz : (N, 3) array
        Grid points, ``i`` fastest (PLOT3D order), ``N = ni * nj * nk``.
    scalar : (N,) array
        One value per grid point.
    dims : (int, int, int)
        ``(ni, nj, nk)``.
    factor : int
        Sub-cells per cell along each axis, >= 1; 1 returns copies of the input.

    Returns
    -------
    xyz : (N', 3) float32
        Refined points, ``N' = ni' * nj' * nk'`` with ``ni' = (ni - 1) * factor + 1`` (an axis
        of one point stays one point). The old point ``(i, j, k)`` is new point
        ``(i * factor, j * factor, k * factor)``, bit for bit.
    scalar : (N',) float32
    dims : (int, int, int)
        ``(ni', nj', nk')``.

    Raises
    ------
    OptionError
        If ``factor`` is not a positive integer or the refined grid would be too large.
    ReadError
        If the array sizes do not match ``dims``.
    """
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise OptionError(f"refinement factor must be a positive integer, got {factor!r}")
    factor = int(factor)
    ni, nj, nk = (int(d) for d in dims)
    n = ni * nj * nk
    xyz = np.asarray(xyz)
    scalar = np.asarray(scalar)
    if xyz.shape != (n, 3) or scalar.shape != (n,):
        raise ReadError(f"grid {ni}x{nj}x{nk} needs ({n}, 3) points and ({n},) values, "
                        f"got {xyz.shape} and {scalar.shape}")
    new_dims = tuple((d - 1) * factor + 1 if d > 1 else 1 for d in (ni, nj, nk))
    n_new = new_dims[0] * new_dims[1] * new_dims[2]
    if n_new >= 1 << 31:
        raise OptionError(f"refining {ni}x{nj}x{nk} by {factor} gives {n_new:,} points; "
                          "tet vertex ids are 32-bit")
    # Points and scalar refined together as four float64 channels, axis by axis (k, j, i):
    # successive linear interpolation along the three axes is exactly trilinear per cell.
    grid = np.empty((nk, nj, ni, 4), dtype=np.float64)
    grid[..., :3] = xyz.reshape(nk, nj, ni, 3)
    grid[..., 3] = scalar.reshape(nk, nj, ni)
    for axis in (0, 1, 2):
        grid = _refine_axis(grid, axis, factor)
    flat = grid.reshape(-1, 4)
    return (np.ascontiguousarray(flat[:, :3], dtype=np.float32),
            np.ascontiguousarray(flat[:, 3], dtype=np.float32), new_dims)


def refine_cell_mask(keep: np.ndarray, dims: tuple[int, int, int], factor: int) -> np.ndarray:
    """Per-cell flags of a grid (``grid_hexes`` order) carried to its refinement by ``factor``.

    Each sub-cell inherits its parent cell's flag, so IBLANK keeps blanking the same region.
    """
    ni, nj, nk = dims
    k = np.asarray(keep).reshape(max(nk - 1, 0), max(nj - 1, 0), max(ni - 1, 0))
    for axis in (0, 1, 2):
        k = np.repeat(k, factor, axis=axis)
    return k.reshape(-1)
