"""The one table of bundled real samples, used by the tests and the benchmarks.

``SAMPLES[name]`` = (path, read_mesh keyword arguments, transfer-function preset). The data and its
provenance: ``sample_meshes/README.md``.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_DIR = ROOT / "sample_meshes"

SAMPLES = {
    "bluntfin": (SAMPLE_DIR / "bluntfin" / "bluntfinxyz.bin", {}, "bluntfin"),
    "combustion": (SAMPLE_DIR / "combustion_chamber" / "combxyz.bin", {}, "combustion"),
    "post": (SAMPLE_DIR / "lox_post_tets" / "post.vtk", {}, "post"),
    "fire": (SAMPLE_DIR / "room_fire" / "fire_ug.vtu", {"scalar": "t"}, "fire"),
}
