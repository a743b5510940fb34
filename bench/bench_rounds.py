"""Rounds of independent merges: what the rounds cost in image quality and what they
save in the forest's rank bits, per number of rounds per level.

Run: ``python bench/bench_rounds.py [--rounds 0,16,32,64] [--meshes bluntfin,combustion]``
-> ``bench/sections/rounds.md``. ``rounds = 0`` is the plain greedy order (the forest of the
previous versions, bit for bit), measured in the same run.

For every mesh and number of rounds: the whole decimation (wall and process CPU seconds), its
reach (merges / points), the ranks' *ascending runs* per bucket (a run: consecutive ranks whose
vertices ascend in :func:`gatun_py.simplify.decimation.canonical_key`; the fewest rounds a decoder
must be told to rebuild the ranks from the keys) and the entropy of each vertex's run id inside
its bucket (bits per vertex of the whole mesh: what a coding of the round id without context
pays, against log2 of the orders inside the buckets for the exact ranks); then the RMSE (0-255,
256², volume mode) of the render after N = floor(ratio x points) merges against the full render,
three views, beside VTK's quadric decimation to the same tet count (median of 5 runs, rendered
by our renderer): the cells of ``bench_pipeline.py --only quality``, computed in memory.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from common import code_state, load, table, write_section

QUALITY_VIEWS = [(30.0, 20.0), (120.0, -30.0), (200.0, 60.0)]
RATIOS = (0.5, 0.9)
VTK_RUNS = 5


def rank_runs(forest, key, n_points):
    """(ascending runs over all buckets, entropy of the run ids in bits per vertex, log2 of the
    orders inside the buckets per vertex)."""
    from gatun_py.simplify.levels import level_merges

    by_rank = np.empty(forest.n_merges, np.int64)
    merged = np.flatnonzero(forest.rank < forest.n_merges)
    by_rank[forest.rank[merged]] = merged
    k = key[by_rank]
    runs, bits, bound = 0, 0.0, 0.0
    lo, i = 0, 1
    while lo < forest.n_merges:
        hi = min(forest.n_merges, level_merges(n_points, i)) if i < 63 else forest.n_merges
        i += 1
        if hi <= lo:
            continue
        seg = k[lo:hi]
        rid = np.cumsum(np.concatenate([[True], seg[1:] <= seg[:-1]])) - 1
        count = np.bincount(rid)
        runs += len(count)
        bits -= float((count * np.log2(count / count.sum())).sum())
        bound += math.lgamma(hi - lo + 1) / math.log(2)
        lo = hi
    return runs, bits / n_points, bound / n_points


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", default="0,16,32,64", help="rounds per level to compare (0 = greedy)")
    ap.add_argument("--meshes", default="bluntfin,combustion")
    args = ap.parse_args(argv)
    from bench_pipeline import rgb8, view
    from bench_simplify import to_vtk, vtk, vtk_arrays, vtk_quadric

    from gatun_py.mesh import validate_tets
    from gatun_py.mesh.model import default_step
    from gatun_py.pipeline.quality import compare_images
    from gatun_py.pipeline.stream import View
    from gatun_py.raycast import Camera
    from gatun_py.raycast.caster import render_mesh
    from gatun_py.simplify import decimate, simplified_mesh
    from gatun_py.simplify.decimation import canonical_key

    from bench_pipeline import DATASETS

    rounds = [int(x) for x in args.rounds.split(",")]
    unknown = set(args.meshes.split(",")) - set(DATASETS)
    if unknown:
        ap.error(f"no view and transfer function for {', '.join(sorted(unknown))}: choose among {', '.join(DATASETS)}")
    decimate(load("post")[0], rounds=rounds[-1])  # load / compile the kernels
    cost_rows, rmse_rows = [], []
    for name in args.meshes.split(","):
        mesh, _ = load(name)
        key = canonical_key(mesh)
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
        rng = mesh.scalar_range
        step = default_step(mesh.points, mesh.boundary_faces())
        cams = []
        for az, el in QUALITY_VIEWS:
            v = View(Camera(256, 256, az, el), view(name, 256).tf, "volume")
            cams.append((v, v.camera.fit(lo, hi)))

        def render(m, cam, v):
            return rgb8(render_mesh(m, cam, v.tf, mode="volume", step=step, scalar_range=rng).image)

        refs = [render(mesh, cam, v) for v, cam in cams]
        forests = {}
        for r in rounds:
            t, c = time.perf_counter(), time.process_time()
            forests[r] = decimate(mesh, rounds=r)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            runs, bits, bound = rank_runs(forests[r], key, mesh.n_points)
            cost_rows.append([name, r, f"{wall:.2f}", f"{cpu:.2f}", f"{forests[r].n_merges / mesh.n_points:.4f}",
                              f"{runs:,}", f"{bits:.2f}", f"{bound:.2f}"])
            print(cost_rows[-1], file=sys.stderr, flush=True)
        for ratio in RATIOS:
            n_merges = int(math.floor(ratio * mesh.n_points))
            ours = {r: simplified_mesh(mesh, forests[r], n_merges) for r in rounds}
            n_tets = ours[rounds[0]].n_tets
            vtk_meshes = []
            if vtk is not None:
                ug = to_vtk(mesh)
                for _ in range(VTK_RUNS):
                    dec = vtk_quadric(ug, 1.0 - n_tets / mesh.n_tets)[0]
                    pts, tets, dens = vtk_arrays(dec)
                    try:
                        vtk_meshes.append(validate_tets(pts.astype(np.float32), dens.astype(np.float32), tets)[0])
                    except Exception:  # noqa: BLE001 (VTK's output is not always a valid mesh)
                        pass
            for (v, cam), ref, (az, el) in zip(cams, refs, QUALITY_VIEWS):
                theirs = [compare_images(ref, render(vm, cam, v)).rmse for vm in vtk_meshes]
                med = float(np.median(theirs)) if theirs else float("nan")
                row = [name, ratio, f"({az:g}, {el:g})", f"{med:.3f}" if theirs else "n/a"]
                for r in rounds:
                    e = compare_images(ref, render(ours[r], cam, v)).rmse
                    row.append(f"{e:.3f} ({ours[r].n_tets:,})" + ("" if not theirs or e <= med else " **>VTK**"))
                rmse_rows.append(row)
                print(row, file=sys.stderr, flush=True)
    import os

    load_avg = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    text = ["## Rounds of independent merges\n",
            f"Command: `python bench/bench_rounds.py --rounds {args.rounds} --meshes {args.meshes}` "
            f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {load_avg}, 2 cores shared; "
            f"code: {code_state()}). *rounds* = rounds per level (0 = the greedy order of the previous versions, "
            f"same run). *runs* = ascending runs of the canonical key over the ranks of each bucket; *run-id bits* "
            f"= their entropy per vertex (no context); *exact-order bound* = log2 of the orders inside the buckets "
            f"per vertex (what the greedy order costs). Decimation in wall / process CPU seconds (2 threads).\n",
            table(["mesh", "rounds", "decimate wall s", "CPU s", "reach", "runs", "run-id bits/vertex",
                   "exact-order bound"], cost_rows) + "\n",
            "RMSE (0-255) against the full render after floor(ratio x points) merges (tets in brackets), "
            f"VTK's quadric decimation to the greedy forest's tet count: median of {VTK_RUNS} runs.\n",
            table(["mesh", "ratio", "view", "VTK median"] + [f"rounds {r}" for r in rounds], rmse_rows) + "\n"]
    write_section("rounds", "\n".join(text))


if __name__ == "__main__":
    main()
