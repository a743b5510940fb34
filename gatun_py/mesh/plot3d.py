"""PLOT3D single-block grids (XYZ + Q files), as the NASA Blunt-fin and Combustion data.

Layout (no Fortran record markers, no block count, either byte order):

* XYZ file: ``int32 ni, nj, nk``, then ``float32 X[nk][nj][ni]``, ``Y``, ``Z`` (i fastest),
  optionally ``int32 IBLANK[nk][nj][ni]``.
* Q file: ``int32 ni, nj, nk``, ``float32 fsmach, alpha, re, time``, then
  ``float32 Q[5][nk][nj][ni]`` = density, x/y/z momentum, stagnation energy.

Trailing bytes after the data (padding) are ignored.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ReadError

GAMMA = 1.4

Q_VARIABLES = (
    "density",
    "momentum-x",
    "momentum-y",
    "momentum-z",
    "energy",
    "velocity-x",
    "velocity-y",
    "velocity-z",
    "velocity-magnitude",
    "momentum-magnitude",
    "pressure",
)

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


def read_q(path, dims: tuple[int, int, int], variable: str = "density") -> np.ndarray:
    """One scalar per grid point from a Q file, as float32."""
    path = Path(path)
    if variable not in Q_VARIABLES:
        raise ReadError(f"unknown --q-var {variable!r}; choose one of {', '.join(Q_VARIABLES)}")
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
    q = np.frombuffer(raw, dtype=f"{bo}f4", count=5 * n, offset=28).reshape(5, n)
    direct = {"density": 0, "momentum-x": 1, "momentum-y": 2, "momentum-z": 3, "energy": 4}
    if variable in direct:
        return np.ascontiguousarray(q[direct[variable]].astype(np.float32))
    q64 = q.astype(np.float64)
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
    return out.astype(np.float32)


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
