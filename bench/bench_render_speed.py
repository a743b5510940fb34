"""Render speed against VTK, and where a frame's time goes (parts of ``bench/bench_render.py``).

    python bench/bench_render.py --only speed     # ours vs VTK PT and ray caster, file to image
    python bench/bench_render.py --only profile   # per-step / per-face / per-sample costs, culling

Both replace their blocks of ``bench/sections/render.md``. ``--data``, ``--sizes``, ``--repeats``
narrow the speed table; ``--peer /path/to/checkout`` also times another checkout's ``tetc render``
in the same interleaved rounds (its ``.venv/bin/tetc``), for the speed-up over it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

SPEED_HEAD = "### Speed: file to image against VTK's projected tetrahedra and ray caster"
PROFILE_HEAD = "### Where a frame's time goes (profile), and invisible tets"
DEFAULT_DATA = ("bluntfin", "combustion", "flange-1m")
DEFAULT_SIZES = (256, 512, 1024)


def tf_transparent_below(name: str, work: Path, cut: float = 0.75) -> Path:
    """The preset ``name`` made transparent below ``cut`` of the scalar range: its colours, opacity 0
    up to ``cut``, then a ramp over a twentieth of the range to the preset's largest opacity."""
    from gatun_py.raycast.transfer import PRESETS

    obj = json.loads((PRESETS / f"{name}.json").read_text())
    top = max(p["a"] for p in obj["opacity"])
    obj["opacity"] = [{"x": 0.0, "a": 0.0}, {"x": cut, "a": 0.0}, {"x": min(1.0, cut + 0.05), "a": top},
                      {"x": 1.0, "a": top}]
    obj.pop("comment", None)
    path = work / f"{name}_t{int(cut * 100)}.json"
    path.write_text(json.dumps(obj))
    return path


def datasets(names, work: Path, log=print) -> list[dict]:
    """Each data set as a mesh-only ``.tetc`` (ours) and a ``.vtu`` (VTK's), with its preset."""
    from bench_render import sample_tetc
    from gatun_py.codec.tetcfile import write_tetc
    from gatun_py.mesh import read_mesh

    out = []
    for name in names:
        if "-" in name:  # a gmsh mesh (bench/gmsh_meshes.py), cached under bench/out/gmsh
            from gmsh_meshes import mesh_path

            vtu = mesh_path(name, log=log)
            tetc = vtu.with_suffix(".tetc")
            if not tetc.exists():
                t0 = time.perf_counter()
                write_tetc(tetc, read_mesh(vtu)[0], source=str(vtu), force=True)
                log(f"  {name}: mesh-only .tetc in {time.perf_counter() - t0:.0f} s")
            rec = {"label": name, "tetc": tetc, "vtu": vtu, "tf": "default"}
        else:
            rec = sample_tetc(name, work)
        from gatun_py.codec import TetcReader

        meta = TetcReader(rec["tetc"]).meta
        rec.update(tets=int(meta["tets"]), scalar=meta["scalar"], range=list(meta["scalar_range"]))
        out.append(rec)
    return out


def _peer_cmd(peer: Path) -> tuple[list, dict]:
    """How to run another checkout's ``tetc``: its own ``.venv/bin/tetc``, else this interpreter with
    the checkout first on the path (a plain copy, e.g. ``git archive COMMIT | tar -x -C DIR``)."""
    exe = peer / ".venv" / "bin" / "tetc"
    if exe.exists():
        return [str(exe)], {}
    return [sys.executable, "-m", "gatun_py.cli.main"], {"PYTHONPATH": str(peer), "cwd": str(peer)}


def _ours(tetc_exe, d, tf, size, threads, png, extra_env=None):
    extra_env = dict(extra_env or {})
    cwd = extra_env.pop("cwd", None)
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), **extra_env)
    cmd = [*tetc_exe, "render", str(d["tetc"]), "-o", str(png), "--tf", str(tf), "--size", f"{size}x{size}",
           "--azimuth", "30", "--elevation", "20", "--stats", "--quiet", "--force"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env, cwd=cwd)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout)


def _vtk(d, tf, size, mapper, work):
    from bench_render import run_worker

    return run_worker("vtk", input=d["vtu"], tf=tf, out=work / f"vtk_{mapper}.npy", scalar=d["scalar"],
                      range=json.dumps(d["range"]), width=size, height=size, azimuth=30.0, elevation=20.0,
                      mapper=mapper)


def speed_section(work: Path, args, have_vtk: bool, log=print) -> list[str]:
    from bench_render import code_note, machine_load, tetc_cmd

    names = (args.data.split(",") if args and args.data else list(DEFAULT_DATA))
    sizes = [int(x) for x in args.sizes.split(",")] if args and args.sizes else list(DEFAULT_SIZES)
    repeats = (args.repeats if args and args.repeats else 3)
    peer = Path(args.peer) if args and args.peer else None
    load_before = machine_load()
    data = datasets(names, work, log)
    ours_exe = tetc_cmd()
    peer_exe, peer_env = _peer_cmd(peer) if peer else (None, {})
    cases = [(d, tfkey, size) for d in data for tfkey in ("dense", "t75") for size in sizes]
    tfs = {d["label"]: {"dense": d["tf"], "t75": tf_transparent_below(d["tf"], work)} for d in data}
    runs: dict = {}
    for d in data:  # warm every JIT cache and the files' pages
        _ours(ours_exe, d, d["tf"], 64, 2, work / "warm.png")
        if peer_exe:
            _ours(peer_exe, d, d["tf"], 64, 2, work / "warm.png", peer_env)
    for rnd in range(repeats):  # interleaved: every way once per round
        for d, tfkey, size in cases:
            tf = tfs[d["label"]][tfkey]
            key = (d["label"], tfkey, size)
            r = runs.setdefault(key, {})
            r.setdefault("ours2", []).append(_ours(ours_exe, d, tf, size, 2, work / "o2.png"))
            r.setdefault("ours1", []).append(_ours(ours_exe, d, tf, size, 1, work / "o1.png"))
            if peer_exe:
                r.setdefault("peer", []).append(_ours(peer_exe, d, tf, size, 2, work / "p.png", peer_env))
            if have_vtk:
                for m in ("pt", "rc"):
                    r.setdefault(m, []).append(_vtk(d, tf, size, m, work))
            from bench_render import run_worker

            r.setdefault("frame", []).append(run_worker("frame", input=d["tetc"], tf=tf, width=size, height=size,
                                                        azimuth=30.0, elevation=20.0))
            log(f"  round {rnd + 1}: {key} ours {r['ours2'][-1]['total_s']:.2f} s"
                + (f", peer {r['peer'][-1]['total_s']:.2f} s" if peer_exe else "")
                + (f", VTK PT {r['pt'][-1]['read_render_s']:.2f} s, RC {r['rc'][-1]['read_render_s']:.2f} s"
                   if have_vtk else ""))
    med = statistics.median

    def m(key, way, field):
        return med(x[field] for x in runs[key][way]) if way in runs[key] else float("nan")

    head = (f"{SPEED_HEAD} (512² targets: ours ≤ 0.25× the faster VTK path from file to image, steady frame "
            "≤ 0.25× VTK's repeat render, 1 → 2 threads ≥ 1.8×, 75 %-transparent frame ≤ 0.5× dense)")
    lines = [head, "",
             "Made by `python bench/bench_render.py --only speed"
             + (f" --data {args.data}" if args and args.data else "")
             + (f" --sizes {args.sizes}" if args and args.sizes else "")
             + (f" --repeats {repeats}" if args and args.repeats else "")
             + (" --peer PATH" if peer else "") + f"` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
             f"load before {load_before}, after {machine_load()} (2 cores: above 2 the figures are slowed, "
             "ratios within a round less so). Medians of "
             f"{repeats} interleaved rounds (each round runs every way of every case once). View az 30 el 20. "
             "*Ours*: `tetc render X.tetc -o X.png --tf TF --size N×N --stats`, `total_s` (opening the file to "
             "the PNG written: decode included), NUMBA_NUM_THREADS=2 unless said. *VTK PT* / *VTK RC*: a fresh "
             "process reads the `.vtu` and renders once with `vtkProjectedTetrahedraMapper` (OpenGL on Mesa "
             "llvmpipe) / `vtkUnstructuredGridVolumeRayCastMapper` (AutoAdjustSampleDistances off), read + "
             "first render; *repeat* its second render. *dense*: the data set's preset; *t75*: the preset "
             "transparent below 75 % of the scalar range (`tf_transparent_below`). *Steady frame*: a second "
             "`render_mesh` of the decoded mesh in the same process (`--worker frame`)."
             + (f" *Peer*: `{peer}`'s `tetc render`, same runs." if peer else ""), ""]
    cols = ["data", "tets", "size", "TF", "ours s (decode / render)"]
    if peer:
        cols += ["peer s", "ours / peer"]
    cols += ["VTK PT s", "VTK RC s", "**ours / faster VTK**", "steady frame s", "VTK repeat s (faster)",
             "**frame / VTK repeat**", "1 thread s", "**1→2 threads**", "t75 / dense frame", "steps",
             "M steps/s per core"]
    lines += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for d, tfkey, size in cases:
        key = (d["label"], tfkey, size)
        o2, o1 = m(key, "ours2", "total_s"), m(key, "ours1", "total_s")
        pt, rc = m(key, "pt", "read_render_s"), m(key, "rc", "read_render_s")
        rep = min(m(key, "pt", "repeat_s"), m(key, "rc", "repeat_s"))
        frame = m(key, "frame", "second_s")
        dense_frame = m((d["label"], "dense", size), "frame", "second_s")
        last = runs[key]["ours2"][-1]
        walk_cpu = med(x["cpu_s"]["walk"] for x in runs[key]["ours1"])
        row = [d["label"], f"{d['tets']:,}", f"{size}²", tfkey,
               f"{o2:.3f} ({m(key, 'ours2', 'decode_s'):.3f} / {m(key, 'ours2', 'render_s'):.3f})"]
        if peer:
            pp = m(key, "peer", "total_s")
            row += [f"{pp:.3f}", f"{o2 / pp:.2f}"]
        row += [f"{pt:.3f}", f"{rc:.3f}", f"**{o2 / min(pt, rc):.2f}**", f"{frame:.3f}", f"{rep:.3f}",
                f"**{frame / rep:.2f}**", f"{o1:.3f}",
                f"**{m(key, 'ours1', 'render_s') / m(key, 'ours2', 'render_s'):.2f}**",
                f"{frame / dense_frame:.2f}" if tfkey == "t75" else "", f"{last['steps']:,}",
                f"{last['steps'] / walk_cpu / 1e6:.1f}" if walk_cpu > 0 else ""]
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "*1→2 threads*: `render_s` with one thread over `render_s` with two (decode excluded). "
              "*M steps/s per core*: ray–tet steps over the walk's CPU seconds (`cpu_s.walk` of `--stats`, "
              "one thread). " + code_note(), ""]
    return lines


def worker_asm(args=None) -> dict:
    """Instruction mix of the compiled walk (``advance_rays``, the walk inlined): packed (SIMD) against
    scalar double arithmetic. Run with an empty NUMBA_CACHE_DIR: cached code carries no assembly."""
    import collections
    import importlib
    import re

    sys.path.insert(0, str(ROOT / "tests"))
    from meshgen import delaunay_mesh

    from gatun_py.raycast import Camera, render_mesh

    walk = importlib.import_module("gatun_py.raycast._walk")
    render_mesh(delaunay_mesh(40), Camera(8, 8), "default")
    asm = "\n".join(walk.advance_rays.inspect_asm(sig) for sig in walk.advance_rays.signatures)
    ins = collections.Counter(m.group(1) for line in asm.splitlines()
                              if (m := re.match(r"\s+([a-z][a-z0-9]*)\s", line)))
    ops = r"v?(mul|add|sub|div|fmadd\d+|fmsub\d+|fnmadd\d+|max|min|sqrt)"
    return {"instructions": sum(ins.values()),
            "packed_double": sum(v for k, v in ins.items() if re.fullmatch(ops + "pd", k)),
            "scalar_double": sum(v for k, v in ins.items() if re.fullmatch(ops + "sd", k)),
            "ymm_lines": sum("ymm" in line for line in asm.splitlines())}


def asm_note(work: Path) -> str:
    from bench_render import run_worker

    cache = work / "asm_cache"
    cache.mkdir(exist_ok=True)
    old = os.environ.get("NUMBA_CACHE_DIR")
    os.environ["NUMBA_CACHE_DIR"] = str(cache)
    try:
        a = run_worker("asm")
    finally:
        if old is None:
            os.environ.pop("NUMBA_CACHE_DIR", None)
        else:
            os.environ["NUMBA_CACHE_DIR"] = old
    return (f"The compiled walk (`advance_rays` with `_walk` inlined, `python bench/bench_render.py --worker asm` "
            f"with an empty NUMBA_CACHE_DIR): {a['instructions']:,} instructions, {a['scalar_double']} scalar "
            f"double arithmetic instructions (`vmulsd`, `vaddsd`, ...) and {a['packed_double']} packed ones "
            f"(`vmulpd`, ...); the {a['ymm_lines']} lines that touch a `ymm` register are moves (zeroing the "
            "colour and state of a call). LLVM does not vectorise it: every ray takes its own exit face, hash "
            "probe and sample count per step, so there is no loop of identical iterations for the loop "
            "vectoriser, and numba offers no SIMD intrinsics to write ray packets by hand.")


def profile_section(work: Path, args, log=print) -> list[str]:
    """In-process, 512², one and two threads: CPU seconds of each phase (``cpu_s`` of the stats,
    ``time.process_time`` around each: load-independent but for cache and SMT contention) and what
    they buy; culling and early termination against the full walk (max pixel difference)."""
    import numba

    from bench_render import code_note, machine_load
    from gatun_py.codec import TetcReader
    from gatun_py.pipeline.stream import View, file_view
    from gatun_py.raycast import Camera, render_mesh
    from gatun_py.raycast.image import to_rgb8

    names = (args.data.split(",") if args and args.data else list(DEFAULT_DATA))
    size = 512
    load_before = machine_load()
    data = datasets(names, work, log)
    lines = [PROFILE_HEAD, "",
             f"Made by `python bench/bench_render.py --only profile` on "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; load before {load_before}. In one process: "
             f"decode level 0 (`decode_mesh`), then `render_mesh` at {size}², az 30 el 20, medians of 3. "
             "CPU seconds of the process (all threads) around each phase: *segments* (boundary faces "
             "against the pixel rays, pairing into segments), *insert* (tets into the face table), *walk* "
             "(the ray–tet steps, sampling and compositing inside them), *compose* (segments into pixels). "
             "This machine's VM exposes no hardware counters to `perf stat` (instructions, cycles and cache "
             "misses all read `<not supported>`), so CPU time stands in for instruction counts. "
             "*full*: every tet, every ray to its end (`cull=False, terminate=False`); *default*: "
             "invisible tets culled, early termination at 0.99.", ""]
    cols = ["data", "TF", "way", "decode s (ns/tet)", "segments s (ns/boundary hit)", "insert s (ns/tet)",
            "walk s (ns/step)", "compose s", "steps", "samples", "tets culled", "render wall 1 thr / 2 thr s",
            "max pixel diff vs full / vs terminate"]
    lines += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for d in data:
        reader = TetcReader(d["tetc"])
        c0 = time.process_time()
        mesh = reader.decode_mesh(0)
        decode_cpu = time.process_time() - c0
        for tfkey, tf in (("dense", d["tf"]), ("t75", tf_transparent_below(d["tf"], work))):
            view, cam, rng, step, _ = file_view(reader, View(Camera(size, size, 30.0, 20.0), tf))
            ref = prev = None
            for way, kw in (("full", dict(cull=False, terminate=False)), ("terminate", dict(cull=False)),
                            ("default", {})):
                per_thread = {}
                for threads in (1, 2):
                    numba.set_num_threads(threads)
                    res = [render_mesh(mesh, cam, view.tf, step=step, scalar_range=rng, **kw) for _ in range(3)]
                    per_thread[threads] = res
                numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
                rs = per_thread[1]
                st = rs[-1].stats
                cpu = {k: statistics.median(r.stats["cpu_s"][k] for r in rs) for k in st["cpu_s"]}
                img = to_rgb8(rs[-1].image).astype(int)
                if ref is None:
                    ref = img
                if way != "terminate":
                    prev = prev if prev is not None else img
                else:
                    prev = img
                hits = max(st.get("boundary_hits", 0), 1)
                walls = [statistics.median(r.stats["render_s"] for r in per_thread[t]) for t in (1, 2)]
                lines.append("| " + " | ".join([
                    d["label"], tfkey, way, f"{decode_cpu:.3f} ({decode_cpu / mesh.n_tets * 1e9:.0f})",
                    f"{cpu['segments']:.3f} ({cpu['segments'] / hits * 1e9:.0f})",
                    f"{cpu['insert']:.3f} ({cpu['insert'] / max(st['tets_rendered'] - st['tets_culled'], 1) * 1e9:.0f})",
                    f"{cpu['walk']:.3f} ({cpu['walk'] / max(st['steps'], 1) * 1e9:.0f})", f"{cpu['compose']:.3f}",
                    f"{st['steps']:,}", f"{st['samples']:,}", f"{st['tets_culled']:,}",
                    f"{walls[0]:.2f} / {walls[1]:.2f}",
                    f"{int(np.abs(img - ref).max())} / {int(np.abs(img - prev).max())}"]) + " |")
                log(lines[-1])
    lines += ["", "*full* against *terminate*: what early termination saves and changes (at most "
              "255 × (1 − 0.99) ≈ 2.5 levels); *terminate* against *default*: what culling saves, and its image "
              "difference (exact: at most one level of rounding). Per-unit costs are CPU seconds over the units "
              "of the row; on a loaded machine they include the contention of the other processes.", "",
              asm_note(work), "", f"Load after: {machine_load()}. " + code_note(), ""]
    return lines
