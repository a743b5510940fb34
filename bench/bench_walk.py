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

``--compare DIR`` runs this tree and the plain copy of another commit in ``DIR`` (``git archive REV |
tar -x -C DIR``) in turns, ``--rounds`` fresh processes each, and writes the medians, their ratio
and whether the images are equal into ``bench/sections/render.md``.

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
from common import SAMPLE_FILES, SECTIONS, code_state, load  # noqa: E402


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


def _run_worker(args, tree: str | None, save: str) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    if tree:
        env["PYTHONPATH"] = tree
    cmd = [sys.executable, __file__, "--worker", "--data", args.data, "--size", str(args.size), "--reps",
           str(args.reps), "--order", args.order, "--save", save]
    run = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


def compare(args) -> dict:
    """This tree against ``args.compare``, interleaved; the block for the section."""
    import numpy as np

    # bench_render puts this tree first on sys.path: only the parent may import it, never a worker
    from bench_render import machine_load, replace_block

    load_before = machine_load()
    ours, base = [], []
    with tempfile.TemporaryDirectory() as d:
        for _ in range(args.rounds):
            base.append(_run_worker(args, args.compare, f"{d}/base.npy"))
            ours.append(_run_worker(args, None, f"{d}/ours.npy"))
        a, b = np.load(f"{d}/ours.npy"), np.load(f"{d}/base.npy")
        same = bool(np.array_equal(a, b))
        max_diff = float(np.abs(a.astype(np.float64) - b).max())

    def med(rows, key):
        return float(np.median([r[key] for r in rows]))

    out = {"ours_ns": med(ours, "ns_per_step"), "base_ns": med(base, "ns_per_step"), "steps": ours[0]["steps"],
           "base_steps": base[0]["steps"], "same_image": same, "max_diff": max_diff}
    block = [
        f"### The walk per step, against an earlier commit ({args.data} {args.size}², one thread)", "",
        f"Made by `python bench/bench_walk.py --compare DIR --data {args.data} --size {args.size} --rounds "
        f"{args.rounds} --reps {args.reps}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{load_before} before, {machine_load()} after. `render_mesh` in memory, az 30 el 20, every tet walked, no "
        f"early termination; CPU seconds of the walk phase over its ray–tet steps, best of {args.reps} in a process, "
        f"median of {args.rounds} fresh processes, the two trees in turns (DIR: `git archive REV | tar -x -C DIR`).", "",
        "| tree | steps | ns per step | M steps/s per core |", "|---|---|---|---|",
        f"| this | {out['steps']:,} | {out['ours_ns']:.1f} | {1e3 / out['ours_ns']:.1f} |",
        f"| {args.compare_name} | {out['base_steps']:,} | {out['base_ns']:.1f} | {1e3 / out['base_ns']:.1f} |", "",
        f"This / earlier: **{out['ours_ns'] / out['base_ns']:.3f}**; images equal bit for bit: "
        f"**{'yes' if same else 'no'}** (max difference {max_diff:.1e}). Code: {code_state()}.",
    ]
    if args.write:
        sec = SECTIONS / "render.md"
        sec.write_text(replace_block(sec.read_text(), block[0], block))
    print("\n".join(block))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="bluntfin")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--order", default="file", choices=("file", "morton"))
    ap.add_argument("--count", action="store_true", help="instructions and cache misses per step (valgrind)")
    ap.add_argument("--save", default=None, help="worker: save the image (.npy) to compare variants")
    ap.add_argument("--worker", action="store_true")
    ap.add_argument("--compare", default=None, help="a plain copy of another commit to run against, in turns")
    ap.add_argument("--compare-name", default="earlier", help="what to call it in the table (e.g. its commit)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="--compare: write the block into bench/sections/render.md")
    args = ap.parse_args()
    if args.worker:
        print(json.dumps(worker(args)))
        return
    if args.count:
        print(json.dumps(count(args)))
        return
    if args.compare:
        compare(args)
        return
    os.environ["NUMBA_NUM_THREADS"] = "1"
    t0 = time.time()
    print(json.dumps({**worker(args), "wall_s": round(time.time() - t0, 2)}))


if __name__ == "__main__":
    main()
