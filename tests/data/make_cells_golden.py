"""Write ``tests/data/cells_v{N}.tetc`` and ``cells_v{N}.json`` (N: today's format version): a small mesh of several components
with every kind of cell block (hexahedra, pyramids, tets, wedges, tetra10), cell arrays of float,
int and bool, field data, point and cell sets, compressed with its levels; the JSON holds the
SHA-256 of everything ``meshio.read`` gives back (tests/test_cells.py checks it).

    python tests/data/make_cells_golden.py        # once per format version, when it comes
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


def golden_mesh() -> meshio.Mesh:
    from mixedgen import mixed_mesh, tetra10_mesh

    a = mixed_mesh(3, 3, 2, 21)
    b = tetra10_mesh(seed=5, n=2)
    # a column of wedges: a 2x2 square of triangles extruded twice
    g = np.array([[x, y, z] for z in range(3) for y in range(3) for x in range(3)], float) + [0, 10, 0]
    pid = lambda x, y, z: x + 3 * y + 9 * z  # noqa: E731
    wedges = []
    for z in range(2):
        for y in range(2):
            for x in range(2):
                for tri in ([(x, y), (x + 1, y), (x + 1, y + 1)], [(x, y), (x + 1, y + 1), (x, y + 1)]):
                    wedges.append([pid(i, j, z) for i, j in tri] + [pid(i, j, z + 1) for i, j in tri])
    n_a, n_b = len(a.points), len(b.points)
    points = np.concatenate([a.points, np.asarray(b.points) + [10.0, 0, 0], g])
    cells = [(c.type, c.data) for c in a.cells] + [("tetra10", b.cells[0].data + n_a),
                                                   ("wedge", np.array(wedges) + n_a + n_b)]
    rng = np.random.default_rng(7)
    n = len(points)
    m = meshio.Mesh(points, cells)
    m.point_data = {"p": rng.normal(size=n), "T": rng.normal(size=n).astype(np.float32)}
    m.cell_data = {"mat": [rng.integers(0, 4, len(d)).astype(np.int32) for _, d in cells],
                   "stress": [rng.normal(size=(len(d), 3)) for _, d in cells],
                   "alive": [rng.random(len(d)) < 0.5 for _, d in cells]}
    m.field_data = {"steel": np.array([1, 3]), "air": np.array([2, 3])}
    m.point_sets = {"origin": np.array([0]), "some": np.arange(0, n, 7)}
    m.cell_sets = {"first": [np.array([0]) for _ in cells]}
    return m


def digest(m: meshio.Mesh) -> dict:
    def h(a):
        a = np.ascontiguousarray(a)
        return [str(a.dtype), list(a.shape), hashlib.sha256(a.tobytes()).hexdigest()]

    return {"points": h(m.points),
            "point_data": {k: h(v) for k, v in m.point_data.items()},
            "cells": [[c.type, h(c.data)] for c in m.cells],
            "cell_data": {k: [h(a) for a in v] for k, v in m.cell_data.items()},
            "field_data": {k: h(v) for k, v in m.field_data.items()},
            "point_sets": {k: h(v) for k, v in m.point_sets.items()},
            "cell_sets": {k: [None if a is None else h(a) for a in v] for k, v in m.cell_sets.items()}}


def main() -> None:
    import gatun_py
    from gatun_py.codec.container import VERSION_MAJOR

    out = HERE / f"cells_v{VERSION_MAJOR}.tetc"
    gatun_py.compress(golden_mesh(), out, force=True, scalar="p")
    data = out.read_bytes()
    expected = {"file_sha256": hashlib.sha256(data).hexdigest(), "decoded": digest(meshio.read(out))}
    (HERE / f"cells_v{VERSION_MAJOR}.json").write_text(json.dumps(expected, indent=1) + "\n")
    print(f"wrote {out} ({len(data)} bytes)")


if __name__ == "__main__":
    main()
