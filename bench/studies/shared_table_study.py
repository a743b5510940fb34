"""What one table of distinct values per channel, shared by every level, would save (a format-8 study).

Run: ``python bench/shared_table_study.py FILE.tetc`` (a file with levels, e.g. from ``tetc compress``).

Every level's geometry is coded in table mode twice by today's kernels: with its own table (what
format 7 sends per level) and with level 0's (a superset: a coarser level's vertices are level 0's).
The shared table's own cost is measured by coding it with a single vertex. *Shared, paid once* =
the sum over the levels with the shared table, less the table's cost in every level but one.
Prints bytes per channel (x, y, z, density); nothing is written.
"""

from __future__ import annotations

import sys

import numpy as np

from gatun_py.codec import TetcReader
from gatun_py.codec import _geometry_kernels as K
from gatun_py.codec import geometry as G
from gatun_py.codec.cutborder import encode_connectivity


def table_mode_sizes(vf, refs, tables_list) -> np.ndarray:
    """Stream bytes per channel of ``vf`` (decode order) in table mode against these tables."""
    offs = np.zeros(K.N_CHANNELS + 1, np.int64)
    offs[1:] = np.cumsum([len(t) for t in tables_list])
    streams = G._run_encode(vf, refs, np.ones(K.N_CHANNELS, np.int64), np.concatenate(tables_list), offs,
                            K.candidate_table(3))
    return np.array([len(s) for s in streams])


def main(path) -> None:
    reader = TetcReader(open(path, "rb").read())
    shared = None
    own_total = np.zeros(K.N_CHANNELS)
    shared_total = np.zeros(K.N_CHANNELS)
    n_levels = len(reader.levels)
    for lv in reader.levels:
        mesh = reader.decode_mesh(lv["level"])
        conn = encode_connectivity(mesh.n_points, mesh.tets)
        refs = G._as_refs(conn.predictors, mesh.n_points)
        vo = conn.vertex_order
        vf = G._channels(np.ascontiguousarray(mesh.points[vo], np.float32), np.ascontiguousarray(mesh.density[vo]))
        own = [np.unique(G._ordered(vf)[:, ch]) for ch in range(K.N_CHANNELS)]
        if shared is None:
            shared = own
            table_cost = table_mode_sizes(vf[:1], refs[:1], shared)
            print("shared table's own cost (bytes, x y z density):", table_cost.tolist())
        s_own = table_mode_sizes(vf, refs, own)
        s_shared = table_mode_sizes(vf, refs, shared)
        own_total += s_own
        shared_total += s_shared
        print(f"level {lv['level']}: {mesh.n_points} points, own tables {s_own.tolist()}, shared {s_shared.tolist()}")
    print("all levels, own tables:", own_total.astype(int).tolist())
    print("all levels, shared table paid once:", (shared_total - (n_levels - 1) * table_cost).astype(int).tolist())


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
