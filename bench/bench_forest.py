"""Benchmark of the merge forest's coding (issue 12): bits per vertex and the size of all levels.

Run as ``python bench/bench_forest.py [--quick] [names...]``; writes ``bench/sections/forest.md``.

For each mesh (samples, then the gmsh meshes of ``bench/gmsh_meshes.py``): the forest is built
once with ``decimate`` (cached in ``bench/out/forests/``, never committed) and its levels with
``build_levels``; every level is encoded as ``tetc compress`` writes it (``encode_level``), and its
forest section is compared with the format-2 coding of the same forest (LZMA, ``encode_forest``).
Also the lower bound of any coding that treats the order inside a rank bucket as arbitrary
(log2 of the bucket sizes' factorials), and the time to encode and to decode level 0's forest
(decode = ``TetcReader.read_forest``: the level's connectivity, then the forest).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "bench"))

import gmsh_meshes  # noqa: E402
from common import table  # noqa: E402
from conftest import SAMPLE_FILES, load_sample  # noqa: E402

from gatun_py.codec.forest import ROOT_RANK, decode_forest, encode_forest, encode_forest_on_mesh  # noqa: E402
from gatun_py.codec.tetcfile import LevelPayload, TetcReader, encode_level, encode_tetc  # noqa: E402
from gatun_py.mesh import read_mesh  # noqa: E402
from gatun_py.simplify import MergeForest, build_levels, decimate, storage_forests  # noqa: E402

NAMES = {"bluntfin": "Blunt-fin", "combustion": "Combustion", "fire": "Room fire", "post": "LOX post",
         "block-50k": "gmsh block 50k", "flange-1m": "gmsh flange 1M"}
CACHE = ROOT / "bench" / "out" / "forests"


def load(name):
    if name in SAMPLE_FILES:
        return load_sample(name)[0]
    return read_mesh(gmsh_meshes.mesh_path(name, log=lambda m: print(m, file=sys.stderr, flush=True)))[0]


def forest_of(name, mesh):
    path = CACHE / f"{name}.npz"
    if path.exists():
        d = np.load(path)
        if len(d["parent"]) == mesh.n_points:
            return MergeForest(d["parent"], d["rank"], int((d["rank"] != ROOT_RANK).sum()))
    f = decimate(mesh)
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez(path, parent=f.parent, rank=f.rank)
    return f


def cpu_best(fn, repeat: int = 3) -> float:
    """Best process CPU time of ``fn()`` (single-threaded work: robust to a loaded machine)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def rank_bound_bits(n, k):
    """log2 of the orders inside the 1 - 1/2^i buckets: what any coding pays that cannot predict them."""
    bits, b = 0.0, 0
    while b < k:
        nxt = min(b + max(1, (n - b) // 2), k)
        bits += math.lgamma(nxt - b + 1) / math.log(2)
        b = nxt
    return bits


def _entropy(*columns) -> float:
    """Empirical entropy in bits of the joint values of integer columns."""
    _, count = np.unique(np.stack(columns, 1), axis=0, return_counts=True)
    p = count / count.sum()
    return float(-(p * np.log2(p)).sum())


PREDICT_BINS = 32  # the rank's place in its bucket and every predictor, in this many quantiles


def rank_predictability(mesh, forest, vertex_order):
    """Bits per vertex that a predictor of a merged vertex's place inside its rank bucket could
    save: sum over buckets of (vertices) x (H(place) - H(place | predictor)), places and predictors
    in ``PREDICT_BINS`` quantile bins, over n. Only the coarse part of the order is measured (the
    rest of a place is at least as hard to predict), and the plug-in estimate of H(place |
    predictor) is low by about bins^2 / (2 N ln 2) on a bucket of N vertices, in the predictor's
    favour. Predictors a decoder could have: after the connectivity, the vertex's degree and the
    mean place of its neighbours decoded before it in the same bucket; after the geometry too,
    error proxies of the decimator's (its star's sum of |scalar difference| x edge length, its
    shortest edge)."""
    n = mesh.n_points
    dec_of = np.empty(n, np.int64)
    dec_of[vertex_order] = np.arange(n)
    k = forest.n_merges
    rank = np.where(forest.rank == ROOT_RANK, k, forest.rank).astype(np.int64)
    tets = mesh.tets
    pairs = np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(4) if a != b])
    pairs = np.unique(pairs, axis=0)
    row, col = pairs[:, 0], pairs[:, 1]
    pts, scalar = mesh.points.astype(np.float64), mesh.density.astype(np.float64)
    length = np.linalg.norm(pts[row] - pts[col], axis=1)
    star_error = np.bincount(row, np.abs(scalar[row] - scalar[col]) * length, n)
    shortest = np.full(n, np.inf)
    np.minimum.at(shortest, row, length)
    degree = np.bincount(row, minlength=n).astype(np.float64)
    bounds = [0]
    while bounds[-1] < k:
        bounds.append(min(bounds[-1] + max(1, (n - bounds[-1]) // 2), k))
    saved = {"neighbours' places": 0.0, "degree": 0.0, "star error (geometry)": 0.0, "shortest edge (geometry)": 0.0}
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        members = (rank >= lo) & (rank < hi)
        if hi - lo < 64 * PREDICT_BINS:
            continue  # too few for the estimate (the small late buckets hold few vertices anyway)
        place = np.minimum(((rank - lo) * PREDICT_BINS) // (hi - lo), PREDICT_BINS - 1)
        h = _entropy(place[members])
        # neighbours decoded before the vertex (smaller decode id) in the same bucket: mean place
        earlier = members[row] & members[col] & (dec_of[col] < dec_of[row])
        total = np.bincount(row[earlier], (rank[col[earlier]] - lo) / (hi - lo), n)
        seen = np.bincount(row[earlier], minlength=n)
        neighbours = np.where(seen > 0, np.minimum((total / np.maximum(seen, 1) * PREDICT_BINS).astype(int),
                                                   PREDICT_BINS - 1), PREDICT_BINS)
        m = int(members.sum())
        for label, value in (("neighbours' places", neighbours.astype(np.float64)), ("degree", degree),
                             ("star error (geometry)", star_error), ("shortest edge (geometry)", shortest)):
            v = value[members]
            if label != "neighbours' places":
                v = np.searchsorted(np.quantile(v, np.linspace(0, 1, PREDICT_BINS + 1)[1:-1]), v)
            saved[label] += m * (h - (_entropy(v, place[members]) - _entropy(v)))
    return {label: bits / n for label, bits in saved.items()}


def measure(name):
    mesh = load(name)
    n = mesh.n_points
    t0 = time.perf_counter()
    forest = forest_of(name, mesh)
    t_forest = time.perf_counter() - t0
    levels = build_levels(mesh, forest)
    payloads = [LevelPayload(x.level, x.ratio, x.n_merges, x.mesh, (f.parent, f.rank))
                for x, f in zip(levels, storage_forests(levels))]
    mesh_bytes, new_f, old_f = [], [], []
    enc_s = None
    for p in payloads:
        t0 = time.perf_counter()
        e = encode_level(p)
        dt = time.perf_counter() - t0
        fsec = e.sections.get(f"L{p.level}/forest", b"")
        mesh_bytes.append(sum(len(v) for k, v in e.sections.items() if not k.endswith("/forest")))
        new_f.append(len(fsec))
        if p.forest is not None:
            vo = e.vertex_order
            dec_of = np.empty(len(vo), np.int64)
            dec_of[vo] = np.arange(len(vo))
            parent, rank = (np.asarray(a) for a in p.forest)
            old_f.append(len(encode_forest(dec_of[parent[vo]], rank[vo])))
        else:
            old_f.append(0)
        if p.level == 0:
            enc_s = dt
    # encode time of level 0's forest alone, decode time through the reader, and the old coding's decode
    on_boundary = np.zeros(mesh.n_points, bool)
    on_boundary[mesh.boundary_faces().ravel()] = True
    enc_forest_s = cpu_best(lambda: encode_forest_on_mesh(forest.parent, forest.rank, mesh.tets, boundary=on_boundary))
    reader = TetcReader(encode_tetc(payloads[:1]))
    dec_s = cpu_best(lambda: reader.read_forest(0))
    conn_s = cpu_best(lambda: reader._level_tets(0))
    old_bytes = encode_forest(*reader.read_forest(0))
    old_dec_s = cpu_best(lambda: decode_forest(old_bytes, n))
    k = forest.n_merges
    predictability = rank_predictability(mesh, forest, encode_level(payloads[0]).vertex_order)
    lvl0_new = mesh_bytes[0] + new_f[0]
    lvl0_old = mesh_bytes[0] + old_f[0]
    return dict(name=NAMES.get(name, name), points=n, tets=mesh.n_tets, levels=len(levels),
                new_bpv=8 * new_f[0] / n, old_bpv=8 * old_f[0] / n, bound=(rank_bound_bits(n, k)) / n,
                ratio_new=(sum(mesh_bytes) + sum(new_f)) / lvl0_new, ratio_old=(sum(mesh_bytes) + sum(old_f)) / lvl0_old,
                mesh_ratio=sum(mesh_bytes) / mesh_bytes[0], forests_new=sum(new_f), forests_old=sum(old_f),
                lvl0_new=lvl0_new, all_new=sum(mesh_bytes) + sum(new_f), enc=enc_forest_s, dec=dec_s, conn=conn_s, old_dec=old_dec_s,
                t_forest=t_forest, level_bytes=list(zip(mesh_bytes, new_f, old_f)), predictability=predictability)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="meshes (default: the samples, gmsh block-50k and flange-1m)")
    ap.add_argument("--quick", action="store_true", help="the samples only")
    args = ap.parse_args(argv)
    if not args.names:
        args.names = ["bluntfin", "combustion", "fire", "post"] + ([] if args.quick else ["block-50k", "flange-1m"])
    rows = []
    for name in args.names:
        r = measure(name)
        print(f"{r['name']}: {r['new_bpv']:.2f} bits/vertex (was {r['old_bpv']:.2f}), all/level0 "
              f"{r['ratio_new']:.3f} (was {r['ratio_old']:.3f}), decode {r['dec']:.3f} s", flush=True)
        rows.append(r)
    lines = [
        "## Merge forest coding (issue 12)", "",
        f"Command: `python bench/bench_forest.py` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average "
        + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + ", 2 cores shared). Forest from `decimate` (cached), levels "
        "from `build_levels`, every level encoded with `encode_level` as `tetc compress` writes it. *format 3* = the "
        "forest coded after the level's mesh (parents among live neighbours, ranks as a context-modelled 1−1/2^i "
        "bucket + the position among the bucket's free ranks: `docs/format.md`); *format 2* = the same forest "
        "LZMA-coded as before. *bound* = log2 of the orders inside the buckets per vertex: what any coding pays "
        "that cannot predict the decimator's order inside a bucket (so ≤ 12 bits/vertex is out of reach for an exact "
        "greedy order once log2(n) is above about 15). Decode = `TetcReader.read_forest(0)` (decodes the level's "
        "connectivity, then the forest), *connectivity* = that first part alone (a render at a ratio then reuses it for the stream instead of decoding it again), *format 2 decode* = `decode_forest` of the LZMA coding; encode = `encode_forest_on_mesh`; all best of 3, process CPU seconds (single-threaded). Targets: ≤ 12 bits/vertex, "
        "all levels ≤ 2.0 × level 0.", "",
        table(["mesh", "points", "tets", "levels", "level-0 forest bits/vertex, format 3", "format 2", "rank bound",
               "all / level 0, format 3", "format 2", "meshes alone: all / level 0", "forests bytes, format 3",
               "format 2", "encode CPU s", "decode CPU s", "of which connectivity", "forest alone",
               "format 2 decode CPU s"],
              [[r["name"], r["points"], r["tets"], r["levels"], f"{r['new_bpv']:.2f}", f"{r['old_bpv']:.2f}",
                f"{r['bound']:.2f}", f"{r['ratio_new']:.3f}", f"{r['ratio_old']:.3f}", f"{r['mesh_ratio']:.3f}",
                r["forests_new"], r["forests_old"], f"{r['enc']:.3f}", f"{r['dec']:.3f}", f"{r['conn']:.3f}",
                f"{r['dec'] - r['conn']:.3f}", f"{r['old_dec']:.3f}"]
               for r in rows]), "",
        "Reading: the forests shrink by 35–38 %, but *all / level 0* moves the wrong way, because a smaller "
        "level-0 forest shrinks the denominator: (all) ≤ 2 × (level 0) needs level 0's forest to exceed the other "
        "levels' forests by (meshes alone − 2) × level 0's mesh bytes. Where the meshes alone are above 2.0 × "
        "(Blunt-fin 2.52, Combustion 2.39, LOX post 2.68, Room fire 2.16, gmsh block 2.16) no forest coding reaches "
        "the target, and a better one moves further away from it; the levels' meshes have to shrink (decimated "
        "meshes code at more bits per tet than the grids they come from). The 12 bits/vertex target is below the "
        "*rank bound* plus any parent coding on every mesh above ~10 k vertices: the exact greedy order costs about "
        "log2(n) − 3.4 bits per vertex by itself.", "",
    ]
    labels = list(rows[0]["predictability"])
    lines += ["Can the order inside a rank bucket be predicted? (issue 12: code the rank as its place in a predicted "
              "order only if that saves ≥ 1.5 bits/vertex.) Bits per vertex a predictor could save on the rank's place "
              f"in its bucket, measured offline (`rank_predictability`: {PREDICT_BINS} quantile bins of the place and of "
              "the predictor, buckets of ≥ 2,048 vertices; the estimate is biased in the predictor's favour). The "
              "geometry columns need the forest coded after the geometry.", "",
              table(["mesh"] + labels, [[r["name"]] + [f"{r['predictability'][x]:.2f}" for x in labels] for r in rows]),
              "",
              "Reading: every predictor saves a fraction of a bit per vertex, far from the 1.5 bits/vertex that would pay "
              "for a new coding (and for moving the forest after the geometry, which a render at a ratio would then have "
              "to decode before its first frame): the greedy order inside a bucket follows errors that change with every "
              "merge around a vertex, so the format keeps the uniform place. Decode speed comes from the decoder alone "
              "(same bytes): candidates counted in place, the idx-th selected instead of sorting the list, tier 1 only "
              "after a tier-0 miss, a Fenwick tree per bucket, the adjacency from the vertex-to-tet incidence without "
              "sorting its rows; what remains is memory-bound (a merge's candidates are the live representatives of "
              "about 13 neighbours scattered over the level, in rank order).", ""]
    r0 = rows[0]
    lines += [f"Per level ({r0['name']}): bytes of the mesh, of the forest in format 3 and in format 2.", "",
              table(["level", "mesh bytes", "forest bytes, format 3", "format 2"],
                    [[i, a, b, c] for i, (a, b, c) in enumerate(r0["level_bytes"])]), ""]
    out = ROOT / "bench" / "sections" / "forest.md"
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
