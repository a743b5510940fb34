"""Time series in one file: size against pcodec, fpzip, xz -9 and a .pvd of zlib .vtu files;
random access (first against last step); append time; coarse steps (gather against survivors).

Data: real solver runs (``bench/series_data.py``: scikit-fem heat conduction on a gmsh block,
float64; ``deforming`` adds the thermo-elastic displacement to the coordinates at every step).

* **size**: the bytes of every step's arrays (the temperature; deforming: and the coordinates),
  ours (step sections plus step 0's array sections; the mesh is stored once on both sides and left
  out) against the best of pcodec, fpzip and ``xz -9`` applied to each array of each step; and
  the whole file (with its forest and levels, and ``--mesh-only``) against the series written as a
  ``.pvd`` of zlib ``.vtu`` files, what ParaView users write.
* **random access**: decoding step 0 and the last step from a freshly opened file, median of
  interleaved runs.
* **append**: ``tetc append`` of one step to files holding a few and many steps, against
  compressing that step alone (with its forest, and ``--mesh-only``).
* **coarse steps**: a coarse level gathers a step's values from level 0 (what the format does):
  its decode time against level 0's; and the bytes per step that storing each level's survivors
  would add instead.

* **play** (``--only play``): the viewer playing a 40-step series of about 1 M tets
  (``series_data.py play``, the file cached under ``bench/out/series/``) through its frame service
  (:class:`gatun_py.viewer.ViewerSession`, driven by this script, no browser): every frame asks for
  the next step within the budget while the camera turns; the share of frames within 1.2x the
  budget (server side: plan, the step's decode, render, encode) and the budget model's prediction
  error per frame (measured / predicted, which depends on load much less than the times do).

``python bench/bench_series.py [--quick]`` writes ``bench/sections/series.md``; ``--only play [--series NAME]``
writes its part of it (between ``<!-- play -->`` marks, which the other parts' run keeps).
"""

from __future__ import annotations

import lzma
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import gatun_py  # noqa: E402
from gatun_py.codec.steps import encode_step_array  # noqa: E402
from gatun_py.codec.stepreader import StepDecoder  # noqa: E402
from gatun_py.mesh.validate import validate_tets  # noqa: E402
from gatun_py.pipeline.series import append_step, encode_series  # noqa: E402
from series_data import load, series_path, write_pvd  # noqa: E402

SECTION = HERE / "sections" / "series.md"
PLAY_MARKS = ("<!-- play -->", "<!-- /play -->")
PLAY_DIR = HERE / "out" / "series"


def peers(arr) -> dict:
    """Bytes of each peer on one array (coordinates: the better of interleaved and planar)."""
    from pcodec import ChunkConfig, standalone
    import fpzip

    layouts = [np.ascontiguousarray(arr)] + ([np.ascontiguousarray(arr.T)] if arr.ndim == 2 else [])
    return {
        "xz": min(len(lzma.compress(a.tobytes(), preset=9)) for a in layouts),
        "pcodec": min(len(standalone.simple_compress(a.ravel(), ChunkConfig())) for a in layouts),
        "fpzip": min(len(fpzip.compress(np.array(a, order="C"), precision=0)) for a in layouts),
    }


def meshes_of(run, deforming: bool, n=None):
    n = len(run["times"]) if n is None else n
    return [validate_tets(run["moved"][k] if deforming else run["points"], None, run["tets"],
                          scalar_name="temperature", point_data={"temperature": run["temperature"][k]})[0]
            for k in range(n)]


def median_interleaved(fns: dict, runs: int) -> dict:
    times = {k: [] for k in fns}
    for _ in range(runs):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return {k: statistics.median(v) for k, v in times.items()}


def size_rows(name, run, deforming, tmp):
    meshes = meshes_of(run, deforming)
    times = [float(t) for t in run["times"]]
    data = encode_series(meshes, times)
    path = tmp / f"{name}.tetc"
    path.write_bytes(data)
    only = encode_series(meshes, times, mesh_only=True)
    f = gatun_py.open(path)
    c = f.reader.container
    ours = sum(c.section_size(s) for s in c.section_names()
               if s.startswith("S") or s.startswith("L0/array/") or (deforming and s == "L0/points64"))
    per_peer = {"xz": 0, "pcodec": 0, "fpzip": 0}
    best = 0
    for k in range(len(times)):
        arrays = [run["temperature"][k]] + ([run["moved"][k]] if deforming else [])
        for a in arrays:
            p = peers(a)
            for key in per_peer:
                per_peer[key] += p[key]
            best += min(p.values())
    pvd_dir = tmp / f"{name}_pvd"
    write_pvd(run, pvd_dir, deforming=deforming, cell_data=False)
    pvd = sum(p.stat().st_size for p in pvd_dir.iterdir())
    raw = sum(a.nbytes for k in range(len(times))
              for a in [run["temperature"][k]] + ([run["moved"][k]] if deforming else []))
    return {"series": name, "points": meshes[0].n_points, "tets": meshes[0].n_tets, "steps": len(times),
            "interval": f.reader.meta["steps"]["keyframe_interval"], "raw": raw, "ours": ours, **per_peer,
            "best_peer": best, "file": len(data), "mesh_only": len(only), "pvd": pvd}, path, meshes


def access_row(path, runs):
    def first():
        gatun_py.open(path).mesh(step=0, jobs=1)

    def last():
        f = gatun_py.open(path)
        f.mesh(step=f.n_steps - 1, jobs=1)

    def worst():  # the step before a keyframe: the longest chain
        f = gatun_py.open(path)
        iv = f.reader.meta["steps"]["keyframe_interval"]
        f.mesh(step=min(f.n_steps - 1, iv - 1 if iv > 1 else 0), jobs=1)

    first()
    return median_interleaved({"first": first, "last": last, "worst": worst}, runs)


def coarse_row(path, runs):
    """Gather (what the format does) against storing each level's survivors per step."""
    f = gatun_py.open(path)
    sd = StepDecoder(f.reader)
    k = f.n_steps - 1
    levels = [lv["level"] for lv in f.reader.levels]
    coarse = levels[min(2, len(levels) - 1)]
    t = median_interleaved({"level0": lambda: gatun_py.open(path).mesh(step=k, jobs=1),
                            "coarse": lambda: gatun_py.open(path).mesh(level=coarse, step=k, jobs=1),
                            "coarse_step0": lambda: gatun_py.open(path).mesh(level=coarse, jobs=1)}, runs)
    extra = 0
    from gatun_py.codec.decoded_connectivity import DecodedConnectivity

    hist = [sd.values(s)["temperature"] for s in range(max(0, k - 3), k + 1)][::-1]
    for level in levels[1:]:
        ids = sd.level_map(level)
        n = len(ids)
        conn = DecodedConnectivity(f.reader._connectivity_decoder(level))
        refs = np.full((n, 4), -1, np.int32)
        p = np.asarray(conn.predictors)[:n]
        refs[:len(p)] = p
        extra += len(encode_step_array(hist[0][ids], refs, history=[h[ids] for h in hist[1:]]))
    own = f.reader.container.section_size(f"S{k}/array/0")
    return {"level": coarse, **t, "survivor_bytes": extra, "step_bytes": own}


def append_rows(name, run, tmp, runs):
    meshes = meshes_of(run, False)
    times = [float(t) for t in run["times"]]
    rows = []
    new = meshes[-1]
    for held in sorted({4, len(meshes) - 1}):
        base = tmp / f"{name}_held{held}.tetc"
        base.write_bytes(encode_series(meshes[:held], times[:held]))
        data = base.read_bytes()
        work = tmp / f"{name}_append.tetc"

        def one():
            work.write_bytes(data)  # outside the timing below would need a copy per run: small, same for all
            t = time.perf_counter()
            append_step(work, new, times[-1])
            return time.perf_counter() - t

        ts = sorted(one() for _ in range(runs))
        rows.append((held, statistics.median(ts)))
    alone = median_interleaved({
        "alone": lambda: gatun_py.compress(new, tmp / "alone.tetc", force=True),
        "alone_mesh_only": lambda: gatun_py.compress(new, tmp / "alone_mo.tetc", force=True, mesh_only=True)}, runs)
    return rows, alone


def play_file(name: str = "play") -> Path:
    """A series compressed with its levels, cached (``play``: ~1 M tets, 40 steps; the forest
    alone takes minutes)."""
    path = PLAY_DIR / f"{name}.tetc"
    if not path.exists():
        run = load(series_path(name))
        meshes = [validate_tets(run["points"], None, run["tets"], scalar_name="temperature",
                                point_data={"temperature": run["temperature"][k]})[0]
                  for k in range(len(run["times"]))]
        t = time.perf_counter()
        data = encode_series(meshes, [float(x) for x in run["times"]])
        print(f"play series: {meshes[0].n_tets} tets, {len(meshes)} steps, {len(data):,} bytes "
              f"in {time.perf_counter() - t:.0f} s", flush=True)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".part")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    return path


def play_rows(path, budgets, loops: int, size: int):
    """Frames of the viewer playing every step ``loops`` times per budget, the camera turning."""
    from gatun_py.viewer import ViewerSession, parse_request

    rows = []
    for budget in budgets:
        session = ViewerSession(path)  # the machine's measured costs, as `tetc view` starts
        n = session.series.n_steps
        warm = [session.render(parse_request({"camera": {"width": size, "height": size, "azimuth": 3.0 * i},
                                              "budget": budget, "step": 0})) for i in range(5)]
        del warm  # the model's first frames on this view, before playing (as the page's first frames)
        frames = []
        for i in range(loops * n):
            req = parse_request({"camera": {"width": size, "height": size, "azimuth": 15.0 + 3.0 * i},
                                 "budget": budget, "step": i % n})
            st = session.render(req).stats
            frames.append({"loop": i // n, "server_s": st["server_s"],
                           "predicted_s": st["predicted_s"] + st["step_predicted_s"],
                           "step_decode_s": st["step_decode_s"], "level": st["level"], "scale": st["scale"],
                           "tets": st["tets_rendered"]})
        rows.append((budget, n, frames, session.reader.meta["tets"]))
    return rows


def play_section(rows, size: int, load_avg) -> str:
    out = ["## Time series: the viewer playing a series (`bench/bench_series.py --only play`)\n",
           f"A scikit-fem heat run on a gmsh block (`series_data.py`; the target's series is `play`, 40 steps "
           f"of about 1 M tets; `--series NAME` plays another), played "
           f"through the viewer's frame service (`ViewerSession.render`, driven by the script, no browser): "
           f"{size}x{size}, every frame asks for the next step within the budget while the camera turns 3 "
           f"degrees; the first pass decodes every step once (each frame pays its step's decode, which the "
           f"planner takes off the budget), later passes find the steps cached. Server-side time: plan, the "
           f"step's decode, render, encode. Target: >= 90 % of frames within 1.2x the budget. Load average "
           f"when run: {load_avg[0]:.1f} (2 cores shared): the times are loaded; the prediction error "
           f"(measured / predicted per frame) depends on load much less.\n",
           "| tets | budget (s) | pass | frames | within 1.2x budget | median frame (s) | 90th pct frame (s) "
           "| median step decode (s) | measured / predicted: median | 10th-90th pct | levels used |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for budget, n, frames, tets in rows:
        for label, sel in (("first (steps decoded)", [f for f in frames if f["loop"] == 0]),
                           ("later (steps cached)", [f for f in frames if f["loop"] > 0]), ("all", frames)):
            if not sel:
                continue
            t = np.array([f["server_s"] for f in sel])
            ratio = np.array([f["server_s"] / f["predicted_s"] for f in sel if f["predicted_s"] > 0])
            within = float(np.mean(t <= 1.2 * budget))
            levels = sorted({f["level"] for f in sel})
            out.append(f"| {tets:,} | {budget:g} | {label} | {len(sel)} | {100 * within:.0f} % | {np.median(t):.3f} "
                       f"| {np.percentile(t, 90):.3f} | {np.median([f['step_decode_s'] for f in sel]):.4f} "
                       f"| {np.median(ratio):.2f} | {np.percentile(ratio, 10):.2f}-{np.percentile(ratio, 90):.2f} "
                       f"| {', '.join(map(str, levels))} |")
    return "\n".join(out) + "\n"


def main_play(argv) -> int:
    quick = "--quick" in argv
    size = 256 if quick else 512
    name = argv[argv.index("--series") + 1] if "--series" in argv else "play"
    path = play_file(name)
    load_avg = os.getloadavg()
    rows = play_rows(path, [0.1] if quick else [0.1, 0.25], 1 if quick else 3, size)
    text = play_section(rows, size, load_avg)
    old = SECTION.read_text() if SECTION.exists() else ""
    SECTION.write_text(_without_play(old).rstrip("\n") + "\n\n" + _play_block(text))
    print(text)
    print(f"wrote the play part of {SECTION}")
    return 0


def _play_block(text: str) -> str:
    return f"{PLAY_MARKS[0]}\n{text.rstrip()}\n{PLAY_MARKS[1]}\n"


def _without_play(text: str) -> str:
    a, b = PLAY_MARKS
    if a in text and b in text:
        return text[:text.index(a)] + text[text.index(b) + len(b):].lstrip("\n")
    return text


def _play_part(text: str) -> str:
    a, b = PLAY_MARKS
    return text[text.index(a):text.index(b) + len(b)] + "\n" if a in text and b in text else ""


def main(argv) -> int:
    if "--only" in argv and argv[argv.index("--only") + 1:][:1] == ["play"]:
        return main_play(argv)
    quick = "--quick" in argv
    runs = 3 if quick else 7
    names = ["small", "medium"] + ([] if quick or not (HERE / "out" / "series" / "large.npz").exists() else ["large"])
    load_avg = os.getloadavg()
    out = []
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        size, access, coarse = [], [], []
        for name in names:
            run = load(series_path(name))
            for deforming in (False, True):
                label = f"{name}{'-deforming' if deforming else ''}"
                row, path, _ = size_rows(label, run, deforming, tmp)
                size.append(row)
                access.append((label, row["interval"], access_row(path, runs)))
                if not deforming:
                    coarse.append((label, coarse_row(path, runs)))
                print(label, row, flush=True)
        appends = [(name,) + append_rows(name, load(series_path(name)), tmp, runs) for name in names]
    out.append("## Time series (`bench/bench_series.py`)\n")
    out.append(f"Real solver output (scikit-fem heat conduction on a gmsh block, float64; `-deforming`: the "
               f"thermo-elastic displacement moves the points every step), `bench/series_data.py`. Load average "
               f"when run: {load_avg[0]:.1f} (2 cores); times are medians of {runs} interleaved runs.\n")
    out.append("### Size\n")
    out.append("Arrays of every step (temperature; deforming: and coordinates), mesh left out on both sides. "
               "Best peer: per array and step the smallest of xz -9, pcodec and fpzip. Target: ours <= 0.8x best "
               "peer; the whole file <= 0.3x the .pvd of zlib .vtu files.\n")
    out.append("| series | points | tets | steps | K | raw | xz -9 | pcodec | fpzip | best peer | ours | ours / best "
               "| file | mesh-only file | .pvd | mesh-only / .pvd |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in size:
        out.append(f"| {r['series']} | {r['points']} | {r['tets']} | {r['steps']} | {r['interval']} | {r['raw']:,} "
                   f"| {r['xz']:,} | {r['pcodec']:,} | {r['fpzip']:,} | {r['best_peer']:,} | {r['ours']:,} "
                   f"| {r['ours'] / r['best_peer']:.3f} | {r['file']:,} | {r['mesh_only']:,} | {r['pvd']:,} "
                   f"| {r['mesh_only'] / r['pvd']:.3f} |")
    out.append("\n### Random access\n")
    out.append("Decode of one step from a freshly opened file (`f.mesh(step=k)`, one thread). Worst: the step "
               "before the first keyframe after step 0 (the longest prediction chain). Target: last <= 1.5x first.\n")
    out.append("| series | K | first (s) | last (s) | last / first | worst (s) | worst / first |")
    out.append("|---|---|---|---|---|---|---|")
    for label, iv, t in access:
        out.append(f"| {label} | {iv} | {t['first']:.4f} | {t['last']:.4f} | {t['last'] / t['first']:.2f} "
                   f"| {t['worst']:.4f} | {t['worst'] / t['first']:.2f} |")
    out.append("\n### Coarse steps: gather from level 0 (chosen) against survivors per level\n")
    out.append("Gather: a coarse level's vertices take the step's values through the level's map to level 0, so "
               "a coarse step decodes the step's arrays at level 0 (plus the level's mesh). Survivors: each level "
               "would store its vertices' values per step (coded like a step, from the previous steps): the bytes "
               "it would add per step, against the step's own bytes.\n")
    out.append("Chosen: gather. Survivors per level would add their bytes to every step of every file, for a "
               "faster coarse step only when the arrays' decode, not the mesh's, dominates the coarse decode; "
               "gathering keeps a step's bytes to level 0's and the level maps are stored once.\n")
    out.append("| series | level | level 0 of last step (s) | coarse level of last step (s) | coarse level of step 0 (s) "
               "| step bytes | survivors would add | ")
    out.append("|---|---|---|---|---|---|---|")
    for label, c in coarse:
        out.append(f"| {label} | {c['level']} | {c['level0']:.4f} | {c['coarse']:.4f} | {c['coarse_step0']:.4f} "
                   f"| {c['step_bytes']:,} | {c['survivor_bytes']:,} (+{100 * c['survivor_bytes'] / c['step_bytes']:.0f} %) |")
    out.append("\n### Append\n")
    out.append("`append_step` of the last step to a file holding a few or many steps, against compressing that "
               "step alone (`gatun_py.compress`, with its forest and `mesh_only`). Target: < 2x compressing it "
               "alone, independent of the steps held.\n")
    out.append("| series | steps held | append (s) | compress alone (s) | mesh-only alone (s) | append / alone |")
    out.append("|---|---|---|---|---|---|")
    for name, rows, alone in appends:
        for held, t in rows:
            out.append(f"| {name} | {held} | {t:.3f} | {alone['alone']:.3f} | {alone['alone_mesh_only']:.3f} "
                       f"| {t / alone['alone']:.2f} |")
    SECTION.parent.mkdir(exist_ok=True)
    play = _play_part(SECTION.read_text()) if SECTION.exists() else ""  # --only play's part stays
    SECTION.write_text("\n".join(out) + "\n" + ("\n" + play if play else ""))
    print(f"wrote {SECTION}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
