"""The surface formats an isosurface is written in, checked without numpy or meshio: `tetc
isosurface` refuses an output it cannot write before it says that it compiles."""

from __future__ import annotations

from pathlib import Path

from .._atomic import check_output_path
from ..errors import OptionError

#: meshio formats that hold a triangle surface (the rest are volume-only or exotic)
MESHIO_SURFACE = {".ply": "ply", ".obj": "obj", ".stl": "stl", ".off": "off", ".vtk": "vtk", ".vtu": "vtu",
                  ".xdmf": "xdmf", ".xmf": "xdmf", ".msh": "gmsh", ".mesh": "medit", ".wkt": "wkt"}
SURFACE_SUFFIXES = (".vtp",) + tuple(MESHIO_SURFACE)


def check_surface_path(path, *, force: bool = False) -> Path:
    """Refuse an output nobody can write (listing the choices) before any work is done."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SURFACE_SUFFIXES:
        raise OptionError(f"cannot write a surface to {path.name!r}: unknown extension {suffix or '(none)'!r}; "
                          f"choose one of {', '.join(SURFACE_SUFFIXES)}")
    return check_output_path(path, force=force)
