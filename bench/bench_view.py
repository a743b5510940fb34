"""`tetc view` frame times: a scripted drag against the real server, as a browser drives it.

For every file and budget: start `tetc view FILE --no-browser` in a fresh process (kernels loaded,
machine costs cached, the file never seen by this server), then over its websocket

1. ask for the first frame (budget B, not dragging): its time is the "first frame" figure;
2. drag for --seconds: a request every 1/60 s (azimuth +1.5°, elevation swinging), as pointer
   moves arrive; the server keeps only the newest, so frames come back as fast as they render;
3. release, wait the still delay, ask for the still frame; time release -> full-quality image;
4. render the same view with `tetc render` and compare the still image with it (RMSE on 0-255).

Writes bench/sections/view.md. Usage: python bench/bench_view.py [--files bluntfin combustion ...]
[--extra FILE.tetc:TF ...] [--budgets 0.05 0.1 0.2] [--seconds 4] [--size 512]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import SAMPLE_FILES, WORK, code_state, run_cli, table, write_section  # noqa: E402

TOKEN = "benchtoken0123456789"


def sample_tetc(name: str) -> Path:
    """The sample compressed with levels under bench/out (built once)."""
    out = WORK / f"{name}_levels.tetc"
    if not out.exists():
        path, kw, _ = SAMPLE_FILES[name]
        WORK.mkdir(parents=True, exist_ok=True)
        args = ["compress", str(path), "-o", str(out), "-q"] + [a for k, v in kw.items() for a in (f"--{k}", v)]
        _, p = run_cli(args)
        if p.returncode:
            raise SystemExit(p.stderr)
    return out


class Server:
    """`tetc view FILE --no-browser` in a subprocess; stopped (by its own pid) on exit."""

    def __init__(self, path: Path):
        launcher = "import sys; from gatun_py.cli.main import main; sys.exit(main())"
        self.proc = subprocess.Popen([sys.executable, "-c", launcher, "view", str(path), "--no-browser", "-q",
                                      "--token", TOKEN], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline().strip()
        if not line.startswith("http://"):
            self.proc.kill()
            raise SystemExit(f"tetc view did not start: {line} {self.proc.stderr.read()}")
        self.base = line.split("/?token=")[0]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


async def drive(base: str, *, tf: str, budget: float, seconds: float, size: int, still_delay: float) -> dict:
    import aiohttp

    camera = {"width": size, "height": size, "azimuth": 30.0, "elevation": 20.0, "zoom": 1.0}
    frames = {}  # id -> (receive time, header, image bytes)
    got = {}  # id -> asyncio.Event
    first_shown = {}  # id -> receive time of its first image (a preview or partial image of a still)

    async with aiohttp.ClientSession() as http:
        ws = await http.ws_connect(f"{base}/ws?token={TOKEN}", max_msg_size=1 << 26)

        async def receive():
            header = None
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT:
                    header = json.loads(msg.data)
                    if header["type"] == "error":
                        raise RuntimeError(header["message"])
                elif msg.type == aiohttp.WSMsgType.BINARY and header is not None:
                    if header.get("preview") or header.get("partial"):  # the final frame follows
                        first_shown.setdefault(header["id"], time.perf_counter())
                        continue
                    first_shown.setdefault(header["id"], time.perf_counter())
                    frames[header["id"]] = (time.perf_counter(), header, msg.data)
                    got.setdefault(header["id"], asyncio.Event()).set()

        reader = asyncio.create_task(receive())
        sent = {}

        async def send(i, *, still=False, interacting=False):
            sent[i] = time.perf_counter()
            got.setdefault(i, asyncio.Event())
            await ws.send_str(json.dumps({"type": "frame", "id": i, "still": still, "interacting": interacting,
                                          "camera": dict(camera), "tf": tf, "budget": budget, "format": "jpeg"}))

        await send(1)
        await got[1].wait()
        first_s = frames[1][0] - sent[1]
        i = 1
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            i += 1
            camera["azimuth"] += 1.5
            camera["elevation"] = 20.0 + 15.0 * float(np.sin((i - 1) / 40.0))
            await send(i, interacting=True)
            await asyncio.sleep(1 / 60)
        last_drag = i
        t_release = time.perf_counter()
        await asyncio.sleep(still_delay)
        await send(i + 1, still=True)
        await asyncio.wait_for(got[i + 1].wait(), 600)
        t_final = frames[i + 1][0]
        reader.cancel()
        await ws.close()

    drag = [frames[k] for k in sorted(frames) if 2 <= k <= last_drag]
    server_s = [h["stats"]["server_s"] for _, h, _ in drag]
    recv = [t for t, _, _ in drag]
    still = frames[last_drag + 1]
    return {
        "first_s": first_s, "first_server_s": frames[1][1]["stats"]["server_s"],
        "requests": last_drag - 1, "frames": len(drag),
        "within": float(np.mean(np.asarray(server_s) <= 1.2 * budget)) if server_s else float("nan"),
        "median_s": statistics.median(server_s) if server_s else float("nan"),
        "p90_s": float(np.percentile(server_s, 90)) if server_s else float("nan"),
        "fps": (len(recv) - 1) / (recv[-1] - recv[0]) if len(recv) > 1 else 0.0,
        "levels": sorted({h["stats"]["level"] for _, h, _ in drag}),
        "scales": sorted({h["stats"]["scale"] for _, h, _ in drag}),
        "release_to_full_s": t_final - t_release, "still_server_s": still[1]["stats"]["server_s"],
        "release_to_first_s": first_shown[last_drag + 1] - t_release,
        "still_png": still[2], "camera": camera,
    }


def still_rmse(path: Path, tf: str, camera: dict, png: bytes) -> tuple[float, float]:
    """(RMSE of the viewer's still against `tetc render` of the same view, tetc render's total_s)."""
    from gatun_py.pipeline.quality import compare_files

    with tempfile.TemporaryDirectory() as tmp:
        mine, ref = Path(tmp) / "still.png", Path(tmp) / "render.png"
        mine.write_bytes(png)
        _, p = run_cli(["render", str(path), "-o", str(ref), "--tf", tf, "--size", str(camera["width"]),
                        "--azimuth", repr(camera["azimuth"]), "--elevation", repr(camera["elevation"]),
                        "--zoom", repr(camera["zoom"]), "--stats", "-q"])
        if p.returncode:
            raise SystemExit(p.stderr)
        return compare_files(mine, ref).rmse, json.loads(p.stdout)["total_s"]


def cli_budget(path: Path, tf: str, budget: float, size: int, code: str | None = None) -> dict:
    """`tetc render --budget` in a fresh process: total_s (file opened to PNG written) and the plan.
    ``code``: run that checkout's gatun_py instead (PYTHONPATH, run from an empty folder so this
    checkout is not on the path), with an empty cache directory."""
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, **({"PYTHONPATH": code, "TETC_CACHE_DIR": str(Path(tmp) / "cache")} if code else {}))
        launcher = "import sys; from gatun_py.cli.main import main; sys.exit(main())"
        p = subprocess.run([sys.executable, "-c", launcher, "render", str(Path(path).resolve()), "-o",
                            str(Path(tmp) / "b.png"), "--tf", tf, "--size", str(size), "--azimuth", "30",
                            "--elevation", "20", "--budget", repr(budget), "--stats", "-q"],
                           capture_output=True, text=True, env=env, cwd=tmp)
        if p.returncode:
            raise SystemExit(p.stderr)
        return json.loads(p.stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", nargs="*", default=["bluntfin", "combustion", "fire", "post"])
    ap.add_argument("--extra", nargs="*", default=[], metavar="FILE.tetc:TF", help="more .tetc files and their TF")
    ap.add_argument("--budgets", nargs="*", type=float, default=[0.05, 0.1, 0.2])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--still-delay", type=float, default=0.2)
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--base", default=None, metavar="DIR",
                    help="also time the first `tetc render --budget 0.1` of that checkout (the per-file calibration)")
    args = ap.parse_args(argv)
    os.environ.setdefault("NUMBA_NUM_THREADS", "2")

    load_before = os.getloadavg()[0]
    jobs = [(n, sample_tetc(n), SAMPLE_FILES[n][2]) for n in args.files]
    for spec in args.extra:
        f, _, tf = spec.rpartition(":")
        jobs.append((Path(f).stem, Path(f), tf))
    rows, results, cli_rows, base_rows = [], [], [], []
    for name, path, tf in jobs:
        from gatun_py.codec import TetcReader

        tets = int(TetcReader(path).meta["tets"])
        if args.base:
            old = cli_budget(path, tf, 0.1, args.size, code=args.base)
            new = cli_budget(path, tf, 0.1, args.size)
            base_rows.append([name, tets, old["total_s"], old["level"], new["total_s"], new["level"],
                              f"{old['total_s'] / new['total_s']:.0f}×"])
        for budget in args.budgets:
            with Server(path) as srv:
                r = asyncio.run(drive(srv.base, tf=tf, budget=budget, seconds=args.seconds, size=args.size,
                                      still_delay=args.still_delay))
            rmse, render_s = still_rmse(path, tf, r["camera"], r.pop("still_png"))
            r.update(name=name, tets=tets, budget=budget, rmse=rmse, render_total_s=render_s)
            results.append(r)
            ok_release = r["release_to_full_s"] <= args.still_delay + 1.2 * r["still_server_s"]
            rows.append([name, tets, budget, r["frames"], f"{100 * r['within']:.0f}%", r["median_s"], r["p90_s"],
                         r["fps"], f"{r['levels'][0]}-{r['levels'][-1]}" if r["levels"] else "-",
                         "/".join(f"{s:g}" for s in r["scales"]), r["first_s"],
                         r["release_to_first_s"], r["release_to_full_s"], r["still_server_s"],
                         "yes" if ok_release else "NO", rmse])
            print(json.dumps({k: v for k, v in r.items() if k != "camera"}), flush=True)
            st = cli_budget(path, tf, budget, args.size)
            cli_rows.append([name, tets, budget, st["level"], f"{st['ratio']:.4f}", f"{st.get('image_scale', 1):g}",
                             st["predicted_s"], st["total_s"], f"{st['total_s'] / budget:.2f}",
                             "yes" if st["total_s"] <= 2 * budget else "NO"])
    header = ["file", "tets", "budget s", "drag frames", "≤1.2×budget", "median s", "p90 s", "frames/s",
              "levels", "image scale", "first frame s", "release→first still image s", "release→full s",
              "full render s",
              "≤ delay+1.2×full", "still RMSE vs tetc render"]
    text = f"""## `tetc view`: frame times while dragging, first frame, still refinement

Command: `python bench/bench_view.py {' '.join(argv or sys.argv[1:])}` ({code_state()}). Each row: a fresh
`tetc view` server (kernels loaded, machine costs cached, the file new to it), {args.size}² frames, a
scripted drag of {args.seconds:g} s over the websocket (a request every 1/60 s; the server renders the
newest), then the still frame {args.still_delay:g} s after release. Frame time = the server's time
per frame (plan, decode, filter, render, JPEG encode); frames/s = frames delivered to the client.
Targets: ≥ 90 % of drag frames within 1.2 × the budget; ≥ 10 frames/s at 0.1 s; first frame
≤ 2 × the budget; release → full quality ≤ still delay + 1.2 × the full render's time (the
still frame shows a quick preview and then its own pixels as they finish while it streams:
"release→first still image" is when the first of those reached the client); still
RMSE ≤ 0.5 against `tetc render` of the same view. "image scale": the share of {args.size}² rendered
while dragging (the page scales it up) when levels alone cannot reach the budget. Machine load
(1-minute average, 2 cores): {load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end.

{table(header, rows)}

### `tetc render --budget`: the first budget render of a file (no per-file calibration)

A fresh `tetc render FILE --budget B --size {args.size} --azimuth 30 --elevation 20 --stats` per row
(machine costs cached, nothing known about the file); total_s runs from opening the file to the PNG
written (the probe render and the plan included). Target: ≤ 2 × the budget (before: 106 s of
calibration on a 9.3 M-tet file). "image scale" < 1: no level fits at full size, so a smaller
image was rendered and scaled up.

{table(["file", "tets", "budget s", "level", "ratio", "image scale", "predicted s", "total s", "total / budget", "≤ 2×"],
       cli_rows)}
"""
    if base_rows:
        text += f"""
Against the per-file calibration it replaces (`{args.base}`, the same files, an empty cache, same run):
first `tetc render --budget 0.1` total_s.

{table(["file", "tets", "before s", "before level", "now s", "now level", "before / now"], base_rows)}
"""
    if not args.no_write:
        write_section("view", text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
