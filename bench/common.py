"""Helpers shared by the benchmark scripts: samples, timing, peak memory, markdown tables."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from samples import SAMPLES as SAMPLE_FILES  # noqa: E402,F401  (the one table of samples, shared with the tests)

SECTIONS = ROOT / "bench" / "sections"
FIGURES = ROOT / "bench" / "figures"
WORK = ROOT / "bench" / "out"  # scratch files, not committed
# Large inputs kept between runs (gmsh meshes, big .tetc files, old-format copies): the one place a
# bench script looks for them. Set TETC_MESH_CACHE to a shared folder to reuse another checkout's.
MESH_CACHE = Path(os.environ.get("TETC_MESH_CACHE", WORK / "cache"))


def load(name):
    from gatun_py.mesh import read_mesh

    path, kw, _ = SAMPLE_FILES[name]
    return read_mesh(path, **kw)


def timed(fn, *args, repeat: int = 1, **kwargs):
    """(best wall seconds over ``repeat`` runs, last result)."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return best, out


def peak_rss_mb() -> float:
    from gatun_py._runtime import peak_rss_mb as peak

    return peak()


def run_cli(args: list[str], env: dict | None = None) -> tuple[float, subprocess.CompletedProcess]:
    """Run ``tetc`` in a fresh interpreter; wall seconds including interpreter start-up."""
    e = dict(os.environ, **(env or {}))
    t0 = time.perf_counter()
    # Not `-m gatun_py.cli.main`: run as __main__, the group would be a second copy of the module
    # that the stage modules (compress, render, ...) do not register their commands on.
    launcher = "import sys; from gatun_py.cli.main import main; sys.exit(main())"
    p = subprocess.run([sys.executable, "-c", launcher, *args], capture_output=True, text=True, env=e)
    return time.perf_counter() - t0, p


TETC = Path(sys.executable).with_name("tetc")


def run_tetc(args, cwd, *, timeout: float = 600) -> tuple[int, list[str], float, float]:
    """Run the installed ``tetc`` as a user would: (exit code, the non-empty lines it printed on
    stderr then stdout, wall seconds, peak MB of its own process).

    The peak comes from GNU time's %M: a child forked from this script would inherit this
    script's peak in ru_maxrss; time's child starts small.
    """
    peak_file = Path(cwd) / ".tetc-peak"
    t0 = time.perf_counter()
    p = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", str(peak_file), str(TETC), *map(str, args)], cwd=cwd,
                       capture_output=True, text=True, timeout=timeout)
    seconds = time.perf_counter() - t0
    try:
        peak = int(peak_file.read_text().split()[-1]) / 1024.0
    except (OSError, ValueError, IndexError):
        peak = float("nan")
    peak_file.unlink(missing_ok=True)
    lines = [ln for ln in (p.stderr + p.stdout).splitlines() if ln.strip()]
    return p.returncode, lines, seconds, peak


def table(header: list[str], rows: list[list]) -> str:
    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}" if abs(v) < 1e5 else f"{v:,.0f}"
        if isinstance(v, int):
            return f"{v:,}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)


def note(name: str) -> str:
    """A hand-measured note kept beside the sections (``bench/sections/notes/<name>.md``): figures
    measured once by hand (alternating checkouts, studies) live there, not in the scripts, and a
    script that re-measures its table copies the note in unchanged."""
    return (SECTIONS / "notes" / f"{name}.md").read_text().strip()


def write_section(area: str, text: str) -> Path:
    SECTIONS.mkdir(parents=True, exist_ok=True)
    p = SECTIONS / f"{area}.md"
    p.write_text(text.strip() + "\n")
    print(f"wrote {p}")
    return p


def code_state() -> str:
    """Which code the timings ran: the commit, and whether gatun_py/ had uncommitted changes
    (several people work in one tree), or where gatun_py was imported from if not this checkout."""
    import gatun_py

    def git(*args):
        p = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
        return p.stdout if p.returncode == 0 else ""

    pkg = Path(gatun_py.__file__).resolve().parent
    if pkg != (ROOT / "gatun_py").resolve():  # e.g. PYTHONPATH=<git archive of a commit>
        return f"gatun_py imported from `{pkg}` ({os.environ.get('TETC_CODE_COMMIT', 'commit not given')})"
    dirty = [ln for ln in git("status", "--porcelain", "--", "gatun_py", "cli").splitlines() if ln.strip()]
    state = f"commit {git('rev-parse', '--short', 'HEAD').strip() or '?'}"
    return state + (f" with uncommitted changes in {', '.join(ln[3:] for ln in dirty)}" if dirty else "")


# -- larger meshes for scale tests ---------------------------------------------------------------

REFINABLE = ("bluntfin", "combustion")  # the PLOT3D samples


def refined_paths(name: str, factor: int) -> tuple[Path, Path]:
    """(mesh .vtu, mesh-only .tetc) of a sample refined ``factor``x per axis, under ``bench/out``."""
    stem = WORK / f"{name}_refine{factor}"
    return stem.with_suffix(".vtu"), stem.with_suffix(".tetc")


def refined_tetc(name: str, factor: int, *, force: bool = False, log=print) -> dict:
    """Build (or reuse) a larger scale-test file from a PLOT3D sample; returns its record.

    ``tetc convert GRID --refine K`` (trilinear refinement, interpolated scalar: for timing and
    memory tests, not new data) writes ``bench/out/<name>_refine<K>.vtu``; ``tetc compress
    --mesh-only`` turns that into ``<name>_refine<K>.tetc``. Both run as fresh ``tetc`` processes,
    so the recorded seconds include interpreter start-up. The record (paths, sizes, seconds) is
    kept beside the files in ``<name>_refine<K>.json`` and returned as is while the .tetc exists.
    """
    if name not in REFINABLE:
        raise ValueError(f"{name!r} is not a PLOT3D sample; choose one of {REFINABLE}")
    vtu, tetc = refined_paths(name, factor)
    record_path = tetc.with_suffix(".json")
    if not force and tetc.exists() and record_path.exists():
        return json.loads(record_path.read_text())
    WORK.mkdir(parents=True, exist_ok=True)
    grid = SAMPLE_FILES[name][0]
    rec = {"name": name, "factor": factor, "vtu": str(vtu.relative_to(ROOT)), "tetc": str(tetc.relative_to(ROOT))}
    steps = [("convert", ["convert", str(grid), "-o", str(vtu), "--refine", str(factor), "--force", "--quiet"]),
             ("compress", ["compress", str(vtu), "-o", str(tetc), "--mesh-only", "--force", "--quiet"])]
    for key, args in steps:
        log(f"{name} x{factor}: tetc {' '.join(args[:1] + [Path(a).name if '/' in a else a for a in args[1:]])}")
        sec, p = run_cli(args)
        if p.returncode != 0:
            raise RuntimeError(f"tetc {key} failed: {p.stderr.strip()}")
        rec[f"{key}_s"] = round(sec, 2)
    from gatun_py.codec import TetcReader

    meta = TetcReader(tetc).meta
    rec.update(points=int(meta["points"]), tets=int(meta["tets"]), vtu_mb=round(vtu.stat().st_size / 2**20, 1), tetc_mb=round(tetc.stat().st_size / 2**20, 2))
    record_path.write_text(json.dumps(rec, indent=1) + "\n")
    return rec


def _main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description="Build the cached scale-test files under bench/out/.")
    ap.add_argument("--factors", type=int, nargs="+", default=[2, 3], help="refinement factors (default 2 3)")
    ap.add_argument("--samples", nargs="+", default=list(REFINABLE), choices=REFINABLE)
    ap.add_argument("--force", action="store_true", help="rebuild even if cached")
    a = ap.parse_args(argv)
    rows = []
    for factor in a.factors:
        for name in a.samples:
            r = refined_tetc(name, factor, force=a.force)
            rows.append([name, factor, r["points"], r["tets"], r["tetc"], r["convert_s"], r["compress_s"], r["vtu_mb"], r["tetc_mb"]])
    print(table(["data set", "K", "points", "tets", "file", "convert s", "compress --mesh-only s", ".vtu MB", ".tetc MB"], rows))


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    _main()
