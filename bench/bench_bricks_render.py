"""Bricked rendering: exact sort-last compositing and Dask workers.

    python bench/bench_bricks_render.py [--quick] [--mesh flange-1m] [--big flange-10m] [--size 512]
    python bench/bench_bricks_render.py --scaling [--mesh flange-1m] [--bricks 16] [--frames 5] [--bands 1] [--no-moves]

Writes ``bench/sections/composite.md``:

1. **Equality**: every sample (and the gmsh meshes) rendered whole and as 8 and 64 bricks whose
   fragments are composited, volume and face modes: the largest difference on 0-255 and how many
   pixels differ at all (target: <= 1, bit-identical where sampling allows).
2. **Workers**: a ``LocalCluster`` of 1 and of 2 worker processes (one numba thread each, so the
   ratio is the distribution's own scaling), both up at once and rendering frames in turn, one
   of each, so the ratio of each pair is taken under the same machine load; the median ratio is
   quoted (target: >= 1.6). Also 1 worker with 2 threads, the one-process baseline.
3. **Memory per worker**: each worker's peak RSS after its bricks and the frames, beside the tets it
   holds (target: the part above the idle worker proportional to its bricks).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
from common import SAMPLE_FILES, code_state, load, table, write_section  # noqa: E402
from gmsh_meshes import mesh_path  # noqa: E402

from gatun_py._runtime import peak_rss_mb  # noqa: E402
from gatun_py.mesh import read_mesh  # noqa: E402
from gatun_py.pipeline.sortlast import split_for_render, render_bricks  # noqa: E402
from gatun_py.pipeline.stream import View, render_mesh_file  # noqa: E402
from gatun_py.raycast.camera import Camera  # noqa: E402
from gatun_py.raycast.image import to_rgb8  # noqa: E402


def _diff(a, b):
    a8, b8 = to_rgb8(a).astype(int), to_rgb8(b).astype(int)
    return int(np.abs(a8 - b8).max()), int(np.count_nonzero(np.any(a != b, axis=2))), \
        int(np.count_nonzero(np.any(a8 != b8, axis=2)))


HEADER = ["mesh", "tets", "K", "mode", "image × views", "max diff 0-255", "pixels ≠ (float)", "pixels ≠ (8-bit)",
          "overlaps", "whole s/frame", "bricked s/frame (one process)", "split s"]


def equality_rows(name, mesh, tf, *, size, views, bricks=(8, 64), modes=("volume", "face"), log=print):
    rows = []
    for k in bricks:
        t0 = time.perf_counter()
        parts, extent = split_for_render(mesh, k)
        split_s = time.perf_counter() - t0
        for mode in modes:
            worst8 = worst_px = worst_px8 = 0
            whole_s = bricked_s = 0.0
            overlaps = 0
            for az, el in views:
                view = View(Camera(size, size, az, el), tf, mode)
                t0 = time.perf_counter()
                whole = render_mesh_file(mesh, view)
                whole_s += time.perf_counter() - t0
                t0 = time.perf_counter()
                bricked = render_bricks(parts, view, extent)
                bricked_s += time.perf_counter() - t0
                d8, px, px8 = _diff(bricked.image, whole.image)
                worst8, worst_px, worst_px8 = max(worst8, d8), max(worst_px, px), max(worst_px8, px8)
                overlaps += bricked.stats["fragments_overlapping_pixels"]
            rows.append([name, f"{mesh.n_tets:,}", k, mode, f"{size}²×{len(views)}", worst8, worst_px, worst_px8,
                         overlaps, whole_s / len(views), bricked_s / len(views), split_s])
            log(rows[-1])
    return rows


def scaling(mesh, tf, *, size, frames, n_bricks, log=print, **cluster_options):
    """Frame times of a 1-worker and a 2-worker LocalCluster (1 thread each) in turn; also 1 worker x 2 threads."""
    from gatun_py.pipeline.distributed import BrickCluster  # optional dependency (dask)

    parts, extent = split_for_render(mesh, n_bricks)
    tets = [p.n_tets for p in parts]
    views = [View(Camera(size, size, 360.0 * i / frames, 20.0), tf) for i in range(frames + 1)]
    out = {"load": " / ".join(f"{x:.1f}" for x in os.getloadavg())}
    clusters = {"1 worker × 1 thread": BrickCluster(workers=1, threads_per_worker=1, timeout=60, **cluster_options),
                "2 workers × 1 thread": BrickCluster(workers=2, threads_per_worker=1, timeout=60, **cluster_options)}
    try:
        idle = {name: c.client.run(peak_rss_mb) for name, c in clusters.items()}
        placed = {name: c.load(parts) for name, c in clusters.items()}
        times = {name: [] for name in clusters}
        for v in views:  # one frame of each in turn: the same load on the machine for both
            for name, c in clusters.items():
                t0 = time.perf_counter()
                c.render(v, extent)
                times[name].append(time.perf_counter() - t0)
        for name, c in clusters.items():
            peaks = c.client.run(peak_rss_mb)
            workers = c.workers
            placed[name] = c.placement()  # where the bricks are after the frames (they move)
            out[name] = {
                "frames_s": times[name][1:],  # the first frame of each is warm-up
                "workers": [(w, sum(tets[i] for i in placed[name][j]), idle[name][w], peaks[w])
                            for j, w in enumerate(workers)],
            }
        one, two = times["1 worker × 1 thread"][1:], times["2 workers × 1 thread"][1:]
        out["ratios"] = [a / b for a, b in zip(one, two)]
    finally:
        for c in clusters.values():
            c.close()
    c2 = BrickCluster(workers=1, threads_per_worker=2, timeout=60, **cluster_options)
    try:
        c2.load(parts)
        ts = []
        for v in views:
            t0 = time.perf_counter()
            c2.render(v, extent)
            ts.append(time.perf_counter() - t0)
        out["1 worker × 2 threads"] = {"frames_s": ts[1:]}
    finally:
        c2.close()
    log({k: (statistics.median(v["frames_s"]) if isinstance(v, dict) else v) for k, v in out.items() if k != "ratios"})
    return out


def orbit_throughput(parts, extent, tf, *, size, frames, rounds=2, log=print, **cluster_options):
    """Seconds for an orbit of ``frames`` views through ``render_series`` (frames in flight, as
    ``tetc render --workers N --orbit`` renders) on 1 and on 2 workers (1 thread each), both
    clusters up, rounds alternating; the best round of each."""
    from gatun_py.pipeline.distributed import BrickCluster  # optional dependency (dask)

    views = [View(Camera(size, size, 360.0 * i / frames, 20.0), tf) for i in range(frames)]
    clusters = {n: BrickCluster(workers=n, threads_per_worker=1, timeout=60, **cluster_options) for n in (1, 2)}
    try:
        for c in clusters.values():
            c.load(parts)
            c.render(views[0], extent)  # warm-up
        best = {n: float("inf") for n in clusters}
        for _ in range(rounds):
            for n, c in clusters.items():
                t0 = time.perf_counter()
                for _res in c.render_series(views, extent):
                    pass
                best[n] = min(best[n], time.perf_counter() - t0)
        moves = clusters[2].moves
    finally:
        for c in clusters.values():
            c.close()
    log({"orbit 1 worker s": best[1], "orbit 2 workers s": best[2], "moves": moves})
    return best, moves


def scaling_section(mesh_name, *, size, frames, n_bricks, orbit_frames=8, log=print, bands=None, moves=True):
    """``--scaling``: only the 1 vs 2 worker figures (per frame and over an orbit), as a subsection."""
    mesh = read_mesh(mesh_path(mesh_name))[0]
    parts, extent = split_for_render(mesh, n_bricks)
    opts = dict(bands=bands, move_bricks=moves)
    sc = scaling(mesh, "default", size=size, frames=frames, n_bricks=n_bricks, log=log, **opts)
    med = {k: statistics.median(v["frames_s"]) for k, v in sc.items() if isinstance(v, dict)}
    orbit, n_moves = orbit_throughput(parts, extent, "default", size=size, frames=orbit_frames, log=log, **opts)
    r = sc["ratios"]
    return [
        "", f"### 1 vs 2 workers, {'direct-send compositing' if bands is None else f'{bands} band(s)'}, "
        f"{'bricks moved by measured time' if moves else 'bricks not moved'} ({mesh_name}, "
        f"{mesh.n_tets:,} tets, {n_bricks} bricks, {size}²)",
        "", f"`python bench/bench_bricks_render.py --scaling --mesh {mesh_name} --bricks {n_bricks} --frames {frames}"
        f"{'' if bands is None else f' --bands {bands}'}{'' if moves else ' --no-moves'}` "
        f"({code_state()}); load average at the start {sc['load']} (1 / 5 / 15 min) on 2 cores. Both clusters up, "
        "one frame of each in turn (`BrickCluster.render`, a frame at a time), the first frame of each dropped; "
        "then an orbit through `render_series` (frames in flight), best of 2 alternating rounds. Target: 2 workers "
        ">= 1.6x faster than 1.",
        "", table(["cluster", "median s/frame", "min", "max"],
                  [[k, med[k], min(sc[k]["frames_s"]), max(sc[k]["frames_s"])] for k in med]),
        "", f"Per frame, ratio 1 worker / 2 workers frame by frame: median **{statistics.median(r):.2f}x** "
        f"(min {min(r):.2f}, max {max(r):.2f}).",
        "", f"Orbit of {orbit_frames} frames: 1 worker {orbit[1]:.2f} s, 2 workers {orbit[2]:.2f} s = "
        f"**{orbit[1] / orbit[2]:.2f}x** ({n_moves} brick moves on the 2-worker cluster).",
    ]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="samples only, small images, no cluster")
    ap.add_argument("--mesh", default="flange-1m", help="the gmsh mesh for the big rows and the workers")
    ap.add_argument("--big", default=None, help="a larger gmsh mesh for the equality table (e.g. flange-10m)")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--bricks", type=int, default=16, help="bricks for the worker scaling")
    ap.add_argument("--append-big", default=None, metavar="NAME",
                    help="only the equality rows of gmsh mesh NAME (e.g. flange-10m), appended to the section")
    ap.add_argument("--scaling", action="store_true",
                    help="only the 1 vs 2 worker figures on --mesh, appended to the section")
    ap.add_argument("--bands", type=int, default=None,
                    help="--scaling: row bands per frame (default one per worker; 1 = composite on one worker)")
    ap.add_argument("--no-moves", action="store_true", help="--scaling: keep every brick where it was placed")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    if args.scaling:
        text = scaling_section(args.mesh, size=args.size, frames=args.frames, n_bricks=args.bricks, bands=args.bands,
                               moves=not args.no_moves)
        section = ROOT / "bench" / "sections" / "composite.md"
        old = section.read_text() if section.exists() else ""
        write_section("composite", old + "\n".join(text + ["", f"Wall time {time.perf_counter() - t_start:.0f} s."]))
        return
    if args.append_big:
        huge = read_mesh(mesh_path(args.append_big))[0]
        rows = equality_rows(args.append_big, huge, "default", size=args.size, views=[(30.0, 20.0)])
        section = ROOT / "bench" / "sections" / "composite.md"
        old = section.read_text() if section.exists() else ""
        write_section("composite", old + "\n".join([
            "", f"### Bricked == whole on {args.append_big}",
            "", f"`python bench/bench_bricks_render.py --append-big {args.append_big}` ({code_state()}), same columns.",
            "", table(HEADER, rows), "", f"Wall time {time.perf_counter() - t_start:.0f} s."]))
        return
    sample_views = [(0.0, 0.0), (90.0, 20.0), (45.0, 70.0)]
    rows = []
    for name, (_path, _kw, tf) in SAMPLE_FILES.items():
        mesh = load(name)[0]
        rows += equality_rows(name, mesh, tf, size=128 if args.quick else 256, views=sample_views)
    big = None
    if not args.quick:
        big = read_mesh(mesh_path(args.mesh))[0]
        rows += equality_rows(args.mesh, big, "default", size=args.size, views=[(30.0, 20.0)])
        if args.big:
            huge = read_mesh(mesh_path(args.big))[0]
            rows += equality_rows(args.big, huge, "default", size=args.size, views=[(30.0, 20.0)])
            del huge
    text = [
        "## Bricked rendering: exact sort-last compositing and Dask workers",
        "",
        f"`python bench/bench_bricks_render.py{' --quick' if args.quick else ''}` ({code_state()}). Each mesh is cut "
        "into K k-d bricks (`split_for_render`), every brick ray-cast on its own into fragments, the fragments sorted "
        "by depth per pixel and composited (`raycast.composite`), against the whole mesh's render (same camera, "
        "transfer function, step).",
        "",
        "### Bricked == whole",
        "",
        "Target: max difference <= 1 on 0-255, bit-identical where sampling allows. *pixels ≠ (float)*: pixels "
        "whose float RGBA differs at all; *overlaps*: pixels with fragments overlapping in depth beyond 1e-12 "
        "relative (folded grids' one-ended segments).",
        "",
        table(HEADER, rows),
    ]
    if big is not None:
        sc = scaling(big, "default", size=args.size, frames=args.frames, n_bricks=args.bricks)
        med = {k: statistics.median(v["frames_s"]) for k, v in sc.items() if isinstance(v, dict)}
        text += [
            "",
            f"### 1 vs 2 workers ({args.mesh}, {big.n_tets:,} tets, {args.bricks} bricks, {args.size}², "
            f"{args.frames} frames of an orbit after one warm-up frame)",
            "",
            f"Load average when the scaling started: {sc['load']} (1 / 5 / 15 min) on 2 cores.",
            "",
            "Both clusters are up at once and render one frame each in turn, so each ratio compares frames taken "
            "under the same load (the machine's 2 cores are shared with other work). Target: 2 workers >= 1.6x "
            "faster than 1.",
            "",
            table(["cluster", "median s/frame", "min", "max"],
                  [[k, med[k], min(sc[k]["frames_s"]), max(sc[k]["frames_s"])] for k in med]),
            "",
            f"Ratio 1 worker / 2 workers (1 thread each), frame by frame: median **{statistics.median(sc['ratios']):.2f}x** "
            f"(min {min(sc['ratios']):.2f}, max {max(sc['ratios']):.2f}).",
            "",
            "### Memory per worker",
            "",
            table(["cluster", "worker", "tets held", "idle peak RSS MB", "peak RSS MB after frames",
                   "MB above idle per M tets"],
                  [[k, w.rsplit(":", 1)[-1], t, i, p, (p - i) / max(t / 1e6, 1e-9)]
                   for k in ("1 worker × 1 thread", "2 workers × 1 thread") for (w, t, i, p) in sc[k]["workers"]]),
        ]
    text += ["", f"Bench wall time {time.perf_counter() - t_start:.0f} s."]
    write_section("composite", "\n".join(text))


if __name__ == "__main__":
    main()
