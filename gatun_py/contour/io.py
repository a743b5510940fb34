"""Writing a :class:`~gatun_py.isosurface.Surface`: any meshio surface format, plus VTK ``.vtp``.

meshio has no PolyData (``.vtp``) writer, and ``.vtp`` is what ParaView users expect for a surface,
so it is written here (XML, raw base64 binary, no compression). Everything is written atomically.
"""

from __future__ import annotations

import base64
import struct

import numpy as np

from .._atomic import atomic_path
from ..errors import OutputError
from .paths import MESHIO_SURFACE, SURFACE_SUFFIXES, check_surface_path  # noqa: F401  (light: the CLI's check)

def write_surface(surface, path, *, force: bool = False) -> None:
    """Write ``surface`` to ``path``; the format follows the extension (see ``SURFACE_SUFFIXES``)."""
    path = check_surface_path(path, force=force)
    suffix = path.suffix.lower()
    with atomic_path(path, force=force) as tmp:
        if suffix == ".vtp":
            tmp.write_bytes(_vtp_bytes(surface))
        else:
            pts = np.asarray(surface.points, np.float64)
            cells = [("triangle", np.asarray(surface.triangles, np.int32 if suffix == ".ply" else np.int64).reshape(-1, 3))]
            pdata = {} if suffix in (".stl", ".obj", ".off", ".wkt") else dict(surface.point_data)
            if suffix == ".ply":  # meshio's PLY writer wants float32/64 point data of one component
                pdata = {k: np.asarray(v, np.float32) for k, v in pdata.items()}
            import meshio  # start-up time: `tetc isosurface` checks its output path before its notice

            try:
                meshio.write(str(tmp), meshio.Mesh(pts, cells, point_data=pdata), file_format=MESHIO_SURFACE[suffix])
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise OutputError(f"cannot write {path}: {e}") from None


def _b64(arr: np.ndarray) -> str:
    raw = np.ascontiguousarray(arr).tobytes()
    return base64.b64encode(struct.pack("<Q", len(raw)) + raw).decode("ascii")


def _vtp_bytes(surface) -> bytes:
    pts = np.asarray(surface.points, np.float32)
    tris = np.asarray(surface.triangles, np.int64).reshape(-1, 3)
    offsets = 3 * np.arange(1, len(tris) + 1, dtype=np.int64)
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
             "  <PolyData>",
             f'    <Piece NumberOfPoints="{len(pts)}" NumberOfVerts="0" NumberOfLines="0" '
             f'NumberOfStrips="0" NumberOfPolys="{len(tris)}">']
    if surface.point_data:
        first = next(iter(surface.point_data))
        lines.append(f'      <PointData Scalars="{first}">')
        for name, arr in surface.point_data.items():
            a = np.asarray(arr, np.float32)
            lines.append(f'        <DataArray type="Float32" Name="{name}" format="binary">{_b64(a)}</DataArray>')
        lines.append("      </PointData>")
    lines += ["      <Points>",
              f'        <DataArray type="Float32" NumberOfComponents="3" format="binary">{_b64(pts)}</DataArray>',
              "      </Points>", "      <Polys>",
              f'        <DataArray type="Int64" Name="connectivity" format="binary">{_b64(tris.ravel())}</DataArray>',
              f'        <DataArray type="Int64" Name="offsets" format="binary">{_b64(offsets)}</DataArray>',
              "      </Polys>", "    </Piece>", "  </PolyData>", "</VTKFile>", ""]
    return "\n".join(lines).encode("ascii")
