"""A newcomer's first runs: what a command costs with an empty numba cache, with and without the
README's set-up step (`tetc warmup`), and when it says that it compiles.

Each row runs the installed ``tetc`` in a fresh process with its own empty ``NUMBA_CACHE_DIR``
(so nothing of this checkout's cache is used): the command cold, then ``tetc warmup`` and the same
command after it. Writes ``bench/sections/first_run.md``.

    python bench/bench_first_run.py [--quick]
    python bench/bench_first_run.py --notice [--before OTHER_TETC] [--rounds N]

``--notice`` measures only the start-up: seconds from the start of each command (empty cache) to its
compile notice, against `tetc --version` run just before it, median of N interleaved rounds; with
``--before``, another install's `tetc` (e.g. the main checkout's) in the same rounds. Writes
``bench/sections/first_run_notice.md``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import SAMPLE_FILES, TETC, code_state, table, write_section

BLUNTFIN = str(SAMPLE_FILES["bluntfin"][0])
POST = str(SAMPLE_FILES["post"][0])


def kernels(cache: Path) -> set:
    """The compiled kernels (one .nbc file per kernel and signature) numba's cache holds."""
    return {p.relative_to(cache) for p in cache.rglob("*.nbc")} if cache.exists() else set()


def version_s(env, cwd) -> float:
    """Seconds `tetc --version` takes: the start-up every command pays (importing the CLI)."""
    t0 = time.perf_counter()
    subprocess.run([str(TETC), "--version"], cwd=cwd, env=env, capture_output=True, check=True)
    return time.perf_counter() - t0


def timed_run(args, env, cwd) -> tuple[float, float | None, int, str]:
    """(wall seconds, seconds until the compile notice or None, exit code, first stderr line)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(TETC), *args], cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    notice_s, first = None, ""
    for line in proc.stderr:
        if not first and line.strip():
            first = line.strip()
        if notice_s is None and line.startswith("tetc: compiling"):
            notice_s = time.perf_counter() - t0
    code = proc.wait()
    return time.perf_counter() - t0, notice_s, code, first


def notice_s(tetc, args, env, cwd) -> float | None:
    """Seconds from the start of ``tetc args`` to its compile notice (the process is ended then)."""
    import signal

    t0 = time.perf_counter()
    proc = subprocess.Popen([str(tetc), *args], cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    seconds = None
    try:
        for line in proc.stderr:
            if line.startswith("tetc: compiling"):
                seconds = time.perf_counter() - t0
                break
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    return seconds


def notice_main(argv) -> int:
    import statistics

    rounds = int(argv[argv.index("--rounds") + 1]) if "--rounds" in argv else 5
    installs = [("this checkout", TETC)]
    if "--before" in argv:
        installs.append(("before", Path(argv[argv.index("--before") + 1])))
    work = Path(tempfile.mkdtemp(prefix="tetc_notice_"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(work / "empty-cache"), TETC_COMPILE_NOTICE="1")
    tiny = Path(__file__).resolve().parents[1] / "gatun_py" / "warmup.tetc"
    cases = [("compress", ["compress", BLUNTFIN, "-o", "x.tetc", "--force"]),
             ("decompress", ["decompress", tiny, "-o", "x.vtu", "--force"]),
             ("render", ["render", tiny, "-o", "x.png", "--force"]),
             ("isosurface", ["isosurface", tiny, "--value", "0.5", "-o", "x.vtp", "--force"])]
    times = {(who, case): [] for who, _ in installs for case in ["--version"] + [c for c, _ in cases]}
    loads = []
    try:
        for _ in range(rounds):
            for who, tetc in installs:
                t0 = time.perf_counter()
                # a session of its own as the commands below (Linux schedules sessions as groups: the same share)
                subprocess.run([str(tetc), "--version"], cwd=work, env=env, capture_output=True, check=True,
                               start_new_session=True)
                times[who, "--version"].append(time.perf_counter() - t0)
                for case, args in cases:
                    s = notice_s(tetc, [str(a) for a in args], env, work)
                    times[who, case].append(float("nan") if s is None else s)
            loads.append(os.getloadavg()[0])
    finally:
        shutil.rmtree(work, ignore_errors=True)
    rows = []
    for who, _ in installs:
        ver = statistics.median(times[who, "--version"])
        for case in ["--version"] + [c for c, _ in cases]:
            med = statistics.median(times[who, case])
            rows.append([who, case, f"{med:.2f}", f"{med / ver:.2f}"])
        print(rows[-5:], flush=True)
    text = [
        "## First runs: seconds to the compile notice\n",
        f"`python bench/bench_first_run.py --notice{' --before ...' if len(installs) > 1 else ''}` ({code_state()}; "
        f"load average {min(loads):.1f}-{max(loads):.1f} during the rounds, on {os.cpu_count()} cores). Each command "
        "with an empty `NUMBA_CACHE_DIR`: seconds from its start to the `tetc: compiling` line on stderr (the "
        f"process is ended there), median of {rounds} rounds interleaved with `tetc --version` (the start-up every "
        "command pays) and with the other install. A loaded machine stretches both alike: compare the ratios.\n",
        table(["install", "command", "median s", "/ tetc --version"], rows),
    ]
    write_section("first_run_notice", "\n".join(text))
    return 0


def main(argv) -> int:
    if "--notice" in argv:
        return notice_main(argv)
    quick = "--quick" in argv
    work = Path(tempfile.mkdtemp(prefix="tetc_first_run_"))
    shutil.copy(POST, work / "post.vtk")
    base = {k: v for k, v in os.environ.items() if k != "TETC_COMPILE_NOTICE"}
    cases = [("compress Blunt-fin", ["compress", BLUNTFIN, "-o", "bf.tetc", "--force"])]
    if not quick:
        cases += [("decompress", ["decompress", "post.tetc", "-o", "post.vtu", "--force"]),
                  ("render", ["render", "post.tetc", "-o", "post.png", "--force"]),
                  ("isosurface", ["isosurface", "post.tetc", "--value", "0.5", "-o", "iso.vtp", "--force"])]
    rows = []
    try:
        # the .tetc input of the later rows, made with this checkout's warm cache
        subprocess.run([str(TETC), "compress", "post.vtk", "-o", "post.tetc", "--force", "-q"], cwd=work, check=True)
        warmup_s = None
        for label, args in cases:
            cache = work / f"cache-{len(rows)}"
            env = dict(base, NUMBA_CACHE_DIR=str(cache))
            ver = version_s(env, work)  # interleaved with the cold run: the same load
            cold, notice_s, code, first = timed_run(args, env, work)
            n_cold = len(kernels(cache))
            shutil.rmtree(cache, ignore_errors=True)
            w, _, wcode, _ = timed_run(["warmup", "-q"], env, work)
            warmup_s = w if warmup_s is None else warmup_s
            before = kernels(cache)
            after, after_notice, acode, _ = timed_run(args, env, work)
            n_after = len(kernels(cache) - before)
            warm, _, _, _ = timed_run(args, env, work)
            shutil.rmtree(cache, ignore_errors=True)
            rows.append([label, cold, n_cold, "-" if notice_s is None else f"{notice_s:.2f}", f"{ver:.2f}", w, after,
                         n_after, "yes" if after_notice is not None else "no", warm, f"{code}/{wcode}/{acode}"])
            print(rows[-1], flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    text = [
        "## First runs: compile notices and `tetc warmup`\n",
        f"`python bench/bench_first_run.py` ({code_state()}; load average {load:.1f} at the end, on "
        f"{os.cpu_count()} cores). Each row: the installed `tetc` with an empty `NUMBA_CACHE_DIR`; *cold* is the "
        "command's first run (it compiles what it needs, and says so: *notice at* is the seconds from the "
        "start to that line on stderr, against `tetc --version` just before it; *kernels compiled*: the "
        "compiled kernels (.nbc files, one per kernel and signature) the run added to the cache, which "
        "does not depend on load); then `tetc warmup` (the README's set-up step) in a fresh empty cache, "
        "the command's first run after it, and a second run.\n",
        table(["command", "cold s", "kernels compiled cold", "notice at s", "tetc --version s", "tetc warmup s",
               "first run after warmup s", "kernels compiled after warmup", "notice after warmup", "warm s",
               "exit codes"], rows),
        "",
        "Inputs: Blunt-fin (`sample_meshes/bluntfin`), post.vtk compressed for the other rows.",
    ]
    write_section("first_run", "\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
