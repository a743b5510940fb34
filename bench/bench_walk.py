"""The ray caster's walk alone: cost per ray-tet step, in figures that hold on a loaded machine.

    python bench/bench_walk.py [--data bluntfin] [--size 512] [--reps 5]    # CPU per step, one thread
    python bench/bench_walk.py --count [--size 128]                        # valgrind: per-step counts

The plain run renders a sample in memory (``render_mesh``, az 30 el 20, every tet walked, no early
termination: the same steps every run) ``reps`` times with one numba thread and prints the
walk's CPU seconds (``cpu_s.walk`` of the stats) over its steps, the minimum over the runs.

``--count`` runs the same render under ``valgrind --tool=cachegrind --cache-sim=yes`` once and
twice in a fresh process each; the difference of the two processes' totals is one warm render's
instructions and simulated D1 / last-level data misses, which do not depend on the machine's
load. Both are printed per step (the render's other phases are a few per cent of it; ``--phases``
prints their CPU shares).

``--order morton`` reorders the tets along a Morton curve of their centroids first (what a decoded
batch could be sorted by) to see whether the walk or the insertion gains from it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import SAMPLE_FILES, load  # noqa: E402


def morton_order(mesh) -> "object":
    """Tet order along a Morton (Z-order) curve of the centroids, 21 bits per axis."""
    import numpy as np

    c = mesh.points[mesh.tets].mean(axis=1)
    lo, hi = c.min(axis=0), c.max(axis=0)
    q = ((c - lo) / np.where(hi > lo, hi - lo, 1.0) * (2**21 - 1)).astype(np.uint64)
    code = np.zeros(len(c), dtype=np.uint64)
    for b in range(21):
        for ax in range(3):
            code |= ((q[:, ax] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + ax)
    return np.argsort(code, kind="stable")


def worker(args) -> dict:
    import numpy as np

    from gatun_py.mesh import TetMesh
    from gatun_py.raycast import Camera, render_mesh

    mesh = load(args.data)[0]  # read_mesh gives (mesh, report)
    if args.order == "morton":
        mesh = TetMesh(mesh.points, mesh.density, np.ascontiguousarray(mesh.tets[morton_order(mesh)]),
                       scalar_name=mesh.scalar_name)
    tf = SAMPLE_FILES[args.data][2]
    cam = Camera(args.size, args.size, 30, 20)
    render_mesh(mesh, Camera(16, 16), tf)  # kernels loaded
    best = None
    for _ in range(args.reps):
        res = render_mesh(mesh, cam, tf, cull=False, terminate=False)
        st = res.stats
        if best is None or st["cpu_s"]["walk"] < best["cpu_s"]["walk"]:
            best = st
    out = {"steps": best["steps"], "samples": best["samples"], "cpu_s": best["cpu_s"],
           "ns_per_step": 1e9 * best["cpu_s"]["walk"] / max(best["steps"], 1),
           "image_sum": float(np.asarray(res.image, np.float64).sum())}
    if args.save:
        np.save(args.save, res.image)
    return out


_COUNTS = {"I": r"I\s+refs:\s+([\d,]+)", "D1": r"D1\s+misses:\s+([\d,]+)", "LLd": r"LLd misses:\s+([\d,]+)"}


def _cachegrind(args, reps: int) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as d:
        cmd = ["valgrind", "--tool=cachegrind", "--cache-sim=yes", f"--cachegrind-out-file={d}/cg.out",
               sys.executable, __file__, "--worker", "--data", args.data, "--size", str(args.size), "--reps",
               str(reps), "--order", args.order]
        run = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    out = {k: int(re.search(p, run.stderr).group(1).replace(",", "")) for k, p in _COUNTS.items()}
    out.update(json.loads(run.stdout.strip().splitlines()[-1]))
    return out


def count(args) -> dict:
    one, two = _cachegrind(args, 1), _cachegrind(args, 2)
    steps = two["steps"]
    return {"steps": steps, **{f"{k}_per_step": (two[k] - one[k]) / steps for k in _COUNTS}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="bluntfin")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--order", default="file", choices=("file", "morton"))
    ap.add_argument("--count", action="store_true", help="instructions and cache misses per step (valgrind)")
    ap.add_argument("--save", default=None, help="worker: save the image (.npy) to compare variants")
    ap.add_argument("--worker", action="store_true")
    args = ap.parse_args()
    if args.worker:
        print(json.dumps(worker(args)))
        return
    if args.count:
        print(json.dumps(count(args)))
        return
    os.environ["NUMBA_NUM_THREADS"] = "1"
    t0 = time.time()
    print(json.dumps({**worker(args), "wall_s": round(time.time() - t0, 2)}))


if __name__ == "__main__":
    main()
