"""Every bad input that the command line meets, run as a user would: command, exit code,
the message, wall time and peak memory (``python bench/bench_hostile.py`` -> ``sections/hostile.md``).

The crafted ``.tetc`` files (forest bomb, tiny stored step) are built here from the golden file;
the decoder's own adversarial suite is ``tests/test_hostile_files.py``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from common import ROOT, SAMPLE_FILES, TETC, WORK, run_tetc, table, write_section

from gatun_py.codec.container import build_container, split_container

GOLDEN = ROOT / "tests" / "data" / "post_v1.tetc"
POST = SAMPLE_FILES["post"][0]


def run(args, cwd):
    """(exit code, first error or note line it printed, wall s, peak MB of the command's own process)."""
    code, lines, dt, peak = run_tetc(args, cwd, timeout=120)
    msg = next((ln for ln in lines if "error" in ln or "note" in ln or "Error" in ln), lines[0] if lines else "")
    return code, msg, dt, peak


def _with_meta(src, out, **changes):
    meta, sections = split_container(src)
    for k, v in changes.items():
        if k == "level0":
            meta["levels"][0].update(v)
        else:
            meta[k] = v
    out.write_bytes(build_container(meta, sections))
    return out


def main() -> int:
    work = WORK / "hostile"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    (work / "post.vtk").write_bytes(Path(POST).read_bytes())
    from gatun_py import compress

    fresh = compress(work / "post.vtk", work / "post.tetc").path  # today's format
    bomb = _with_meta(fresh, work / "bomb.tetc", points=2**31 - 2,
                      level0={"points": 2**31 - 2, "referenced_points": 2**31 - 2, "boundary_vertices": 1000})
    tiny = _with_meta(fresh, work / "tiny_step.tetc", render_step=1e-12)
    pv = {"RGBPoints": [0, 0, 0, 1, 1, 1, 0, 0]}
    for name, ud in (("zero", 0), ("abc", "abc"), ("nan", "nan")):
        (work / f"pv_{name}.json").write_text(json.dumps(dict(pv, unit_distance=ud)))
    fifo = work / "fifo.png"
    os.mkfifo(fifo)
    cases = [
        ("crafted 90 KB-style file claiming 2^31 points, --ratio", ["render", bomb, "-o", "b.png", "--ratio", "0.5"]),
        ("crafted file, decompress", ["decompress", bomb, "-o", "b.vtu"]),
        ("--step 1e-9 at 64²", ["render", "post.vtk", "-o", "s.png", "--size", "64", "--step", "1e-9"]),
        ("file whose stored render_step is 1e-12", ["render", tiny, "-o", "t.png", "--size", "64"]),
        ("decompress to .stl", ["decompress", GOLDEN, "-o", "x.stl"]),
        ("convert to .ply", ["convert", "post.vtk", "-o", "x.ply"]),
        ("convert to .obj", ["convert", "post.vtk", "-o", "x.obj"]),
        ("render -o x.jpg", ["render", GOLDEN, "-o", "x.jpg", "--size", "32"]),
        ("render -o x.gif (no writer)", ["render", GOLDEN, "-o", "x.gif", "--size", "32"]),
        ("compress a.vtk -o a.vtk -f", ["compress", "post.vtk", "-o", "post.vtk", "-f"]),
        ("output /dev/null --force", ["convert", "post.vtk", "-o", "/dev/null", "--force"]),
        ("output a named pipe --force", ["render", GOLDEN, "-o", fifo, "--force", "--size", "8"]),
        ("ParaView TF, unit_distance 0", ["render", GOLDEN, "-o", "p0.png", "--tf", "pv_zero.json"]),
        ("ParaView TF, unit_distance \"abc\"", ["render", GOLDEN, "-o", "p1.png", "--tf", "pv_abc.json"]),
        ("ParaView TF, unit_distance \"nan\"", ["render", GOLDEN, "-o", "p2.png", "--tf", "pv_nan.json"]),
        ("--size 0", ["render", GOLDEN, "-o", "z.png", "--size", "0"]),
        ("--size 1000000", ["render", GOLDEN, "-o", "z.png", "--size", "1000000"]),
        ("--step -1", ["render", GOLDEN, "-o", "z.png", "--step", "-1"]),
        ("--zoom 0", ["render", GOLDEN, "-o", "z.png", "--zoom", "0"]),
        ("--ratio 1.5", ["render", GOLDEN, "-o", "z.png", "--ratio", "1.5"]),
        ("--budget -1", ["render", GOLDEN, "-o", "z.png", "--budget", "-1"]),
        ("missing input", ["render", "nope.tetc", "-o", "z.png"]),
    ]
    rows = []
    for label, args in cases:
        code, msg, dt, peak = run(args, work)
        rows.append([label, "`" + " ".join(Path(str(a)).name if str(a).startswith(str(ROOT)) else str(a)
                                           for a in args) + "`", code, msg.replace("|", "/")[:150],
                     f"{dt:.2f}", f"{peak:.0f}"])
    t0 = time.perf_counter()
    piped = subprocess.run(f"'{TETC}' compress post.vtk -o piped.tetc 2>&1 | head -1", cwd=work, shell=True,
                           executable="/bin/bash", capture_output=True, timeout=120)
    code, dt = piped.returncode, time.perf_counter() - t0
    rows.append(["closed stderr pipe (`2>&1 | head -1`)", "`tetc compress post.vtk -o piped.tetc`", code,
                 f"file written: {(work / 'piped.tetc').exists()}", f"{dt:.2f}", ""])
    jpg = (work / "x.jpg").read_bytes()[:3] == b"\xff\xd8\xff" if (work / "x.jpg").exists() else False
    rows.append(["(check) x.jpg holds JPEG bytes", "", "", str(jpg), "", ""])

    # Ctrl-C: a render that would take minutes, interrupted past start-up
    p = subprocess.Popen([str(TETC), "render", "post.vtk", "-o", "c.png", "--size", "2048", "--step", "1e-9", "-q"],
                         cwd=work, stderr=subprocess.PIPE, stdout=subprocess.PIPE)
    time.sleep(6.0)
    t0 = time.perf_counter()
    p.send_signal(signal.SIGINT)
    p.wait(timeout=60)
    rows.append(["SIGINT 6 s into a minute-long 2048² render", "`tetc render post.vtk --size 2048 --step 1e-9`",
                 p.returncode, f"stopped {time.perf_counter() - t0:.3f} s after SIGINT; image left: "
                               f"{(work / 'c.png').exists()}", "", ""])

    # a mesh in millimetres and the same in metres: the default transfer function renders alike
    from gatun_py import TetMesh, read_mesh, render
    m = read_mesh(POST)[0]
    small = TetMesh(np.asarray(m.points) * np.float32(0.001), m.density, m.tets, m.scalar_name)
    a, b = render(m, size=128).rgb.astype(float), render(small, size=128).rgb.astype(float)
    rows.append(["default TF, mesh scaled by 0.001", "`gatun_py.render(mesh)` vs scaled", "",
                 f"mean brightness {a.mean():.2f} vs {b.mean():.2f}; max pixel difference {np.abs(a - b).max():.0f}",
                 "", ""])

    text = ("## Hostile and careless input\n\n"
            f"`python bench/bench_hostile.py`, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}: every case run "
            "as a user would from a shell (exit 0 success, 1 error, 2 usage error); the message is the first "
            "error or note line on stderr; peak is the child's maximum resident memory. The decoder's own "
            "adversarial suite (hypothesis over headers, sections and metadata under a memory and time limit) is "
            "`tests/test_hostile_files.py`; a full disk is simulated in `tests/test_cli_hardening.py`.\n\n"
            + table(["case", "command", "exit", "message", "s", "peak MB"], rows) + "\n")
    write_section("hostile", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
