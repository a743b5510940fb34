"""Table 1 of the paper (data sets) with today's reader: sizes, faces, degenerate elements, read time.

Run: ``python bench/bench_mesh.py``  →  ``bench/sections/mesh.md``
"""

from __future__ import annotations

import sys

import numpy as np

from common import SAMPLE_FILES, load, table, timed, write_section

PAPER = {"bluntfin": (40960, 187395, 381548, 13516), "combustion": (47025, 215040, 437888, 15616)}


def main() -> None:
    from gatun_py.mesh.model import face_multiplicity

    rows = []
    for name in SAMPLE_FILES:
        secs, (mesh, rep) = timed(load, name)
        counts, _ = face_multiplicity(mesh.tets)
        paper = PAPER.get(name)
        ok = "" if paper is None else ("= paper" if paper == (mesh.n_points, mesh.n_tets, len(counts),
                                                                 len(mesh.boundary_faces())) else "≠ paper")
        distinct = "/".join(str(len(np.unique(mesh.points[:, a]))) for a in range(3))
        rows.append([name, mesh.n_points, mesh.n_tets, len(counts), len(mesh.boundary_faces()), ok,
                     rep.zero_volume_tets, rep.coincident_points, distinct, f"{secs:.2f}"])
    text = "## Data sets (paper Table 1)\n\n"
    text += "Command: `python bench/bench_mesh.py` (reads each bundled sample with `read_mesh`).\n\n"
    text += table(["data set", "points", "tets", "faces", "boundary faces", "Table 1", "zero-volume tets",
                   "coincident points", "distinct x/y/z", "read s"], rows)
    write_section("mesh", text)


if __name__ == "__main__":
    main() if "--help" not in sys.argv else print(__doc__)
