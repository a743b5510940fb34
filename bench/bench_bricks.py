"""Bricks: what splitting a file into K bricks costs in size, and what it buys in decode speed.

For every mesh: the mesh-only file at K = 1, 8 and 64 (bytes, cost over K = 1, cut vertices),
``tetc compress --bricks K`` as a fresh process (wall seconds, peak MB of the largest process),
and the whole-mesh decode of the K = 8 file on 1 and 2 threads (median of alternating runs, and
whether both give the same arrays). ``--full`` adds files with forest and levels (decimation:
minutes per million tets).

Targets: size cost <= 5 % at K = 8 and <= 15 % at K = 64 on the ~10 M-tet mesh; decode
on 2 cores >= 1.8 x faster than on 1.

    python bench/bench_bricks.py [--quick] [--full] [--big]   # --big adds flange-10m (built if missing)
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import SAMPLE_FILES, code_state, run_tetc, table, write_section
from gmsh_meshes import CACHE, mesh_path

KS = (1, 8, 64)


def _decode_times(path: Path, rounds: int) -> dict:
    from gatun_py.codec import TetcReader
    from gatun_py.codec.bricks import decode_bricked

    r = TetcReader(path)
    times = {1: [], 2: []}
    out = {}
    decode_bricked(r, jobs=2)  # warm: kernels loaded, file in the page cache
    for _ in range(rounds):
        for jobs in (1, 2):
            t0 = time.perf_counter()
            m = decode_bricked(r, jobs=jobs)
            times[jobs].append(time.perf_counter() - t0)
            out[jobs] = m
    same = all(np.array_equal(getattr(out[1], a), getattr(out[2], a)) for a in ("points", "tets", "density"))
    return {"t1": statistics.median(times[1]), "t2": statistics.median(times[2]), "same": same}


def gil_waits(path: Path) -> float:
    """Share of a one-thread brick decode during which another Python thread waited more than
    20 ms for the GIL (about 0 when the kernels release it; a GIL-holding numba loop scores ~80 %)."""
    import threading

    from gatun_py.codec import TetcReader

    r = TetcReader(path)
    bricks = [r.brick(k) for k in range(r.n_bricks)]
    bricks[0].decode_mesh(0)
    th = threading.Thread(target=lambda: [b.decode_mesh(0) for b in bricks])
    th.start()
    last = t0 = time.perf_counter()
    waited = 0.0
    while th.is_alive():
        now = time.perf_counter()
        if now - last > 0.02:
            waited += now - last
        last = now
    return waited / max(last - t0, 1e-9)


def bench_mesh(label: str, src: Path, kw: dict, tmp: Path, *, full: bool, rounds: int) -> list[list]:
    from gatun_py.codec import TetcReader

    rows = []
    base = None
    extra = [a for k, v in kw.items() for a in (f"--{k.replace('_', '-')}", v)]
    for mode in (["--mesh-only"], []) if full else (["--mesh-only"],):
        for k in KS:
            out = tmp / f"{src.stem}-{k}{'-m' if mode else ''}.tetc"
            code, lines, wall, peak = run_tetc(["compress", src, "-o", out, "--bricks", k, "-q", "-f", *mode, *extra],
                                               tmp, timeout=7200)
            if code != 0:
                rows.append([label, "mesh only" if mode else "full", k, "failed: " + (lines[-1] if lines else "?")]
                            + [""] * 8)
                continue
            r = TetcReader(out)
            size = out.stat().st_size
            base = size if k == 1 else base
            cut = int(r.meta.get("cut_points", 0))
            dec = _decode_times(out, rounds) if k == 8 and mode else None
            if dec is not None:
                dec["gil"] = gil_waits(out)
            levels = [lv["level"] for lv in r.levels]
            rows.append([label, "mesh only" if mode else "full", k, size, f"{100.0 * (size / base - 1):+.2f} %",
                         f"{cut:,} ({100.0 * cut / r.meta['points']:.2f} %)", f"0..{max(levels)}", round(wall, 1),
                         round(peak), "" if dec is None else f"{dec['t1']:.3f} / {dec['t2']:.3f}",
                         "" if dec is None else f"{dec['t1'] / dec['t2']:.2f} x{'' if dec['same'] else ' (DIFFERENT)'}",
                         "" if dec is None else f"{100 * dec['gil']:.0f} %"])
            print(rows[-1], flush=True)
    return rows


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    full = "--full" in argv
    meshes = [(name, Path(path), kw) for name, (path, kw, _) in SAMPLE_FILES.items()]
    if quick:
        meshes = meshes[2:3]
    else:
        meshes.append(("gmsh flange 1M", mesh_path("flange-1m"), {}))
        if "--big" in argv or (CACHE / "flange-10m.vtu").exists():
            meshes.append(("gmsh flange 10M", mesh_path("flange-10m"), {}))
    rounds = 1 if quick else 3
    load_before = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory(dir=CACHE.parent) as d:
        for label, src, kw in meshes:
            rows += bench_mesh(label, src, kw, Path(d), full=full, rounds=rounds)
    text = f"""## Bricks: size cost, compress time, parallel decode

`python bench/bench_bricks.py{' --full' if full else ''}` ({code_state()}). Each file is written by a fresh
`tetc compress --bricks K` process (wall seconds and peak MB of the largest process, GNU time; bricks
are decimated and coded on a pool of all cores); cost = bytes over the K = 1 file of the same kind.
Cut vertices: vertices shared by two bricks or more (stored once in each), % of the mesh's points.
Decode: the whole mesh of the K = 8 file, decoded and stitched on 1 / 2 threads (median of
{rounds} alternating runs in one process, kernels warm), speed-up and whether both runs gave the
same arrays. GIL waits: the share of a one-thread decode during which another Python thread waited
more than 20 ms for the GIL (a GIL-holding numba loop: about 80 %). The machine is shared: wall times carry its load (1-minute load average
{load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end, on {os.cpu_count()} cores; above the core
count, the 2-thread decode cannot get its second core and its speed-up means nothing).

Targets: cost <= 5 % at K = 8 and <= 15 % at K = 64 on the ~10 M-tet mesh; decode 2 cores >= 1.8 x 1 core.

{table(["mesh", "file", "K", "bytes", "cost", "cut vertices", "levels", "compress s", "peak MB",
        "decode 1 / 2 threads s", "speed-up", "GIL waits"], rows)}
"""
    write_section("bricks", text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
