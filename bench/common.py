"""Helpers shared by the benchmark scripts: samples, timing, peak memory, markdown tables."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_meshes"
SECTIONS = ROOT / "bench" / "sections"
FIGURES = ROOT / "bench" / "figures"
WORK = ROOT / "bench" / "out"  # scratch files, not committed

# name -> (path, read_mesh keyword arguments, transfer function preset)
SAMPLE_FILES = {
    "bluntfin": (SAMPLES / "bluntfin" / "bluntfinxyz.bin", {}, "bluntfin"),
    "combustion": (SAMPLES / "combustion_chamber" / "combxyz.bin", {}, "combustion"),
    "post": (SAMPLES / "lox_post_tets" / "post.vtk", {}, "post"),
    "fire": (SAMPLES / "room_fire" / "fire_ug.vtu", {"scalar": "t"}, "fire"),
}


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
    from gatun_py._resources import peak_rss_mb as peak

    return peak()


def run_cli(args: list[str], env: dict | None = None) -> tuple[float, subprocess.CompletedProcess]:
    """Run ``tetc`` in a fresh interpreter; wall seconds including interpreter start-up."""
    e = dict(os.environ, **(env or {}))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "gatun_py.cli.main", *args], capture_output=True, text=True, env=e)
    return time.perf_counter() - t0, p


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


def write_section(area: str, text: str) -> Path:
    SECTIONS.mkdir(parents=True, exist_ok=True)
    p = SECTIONS / f"{area}.md"
    p.write_text(text.strip() + "\n")
    print(f"wrote {p}")
    return p
