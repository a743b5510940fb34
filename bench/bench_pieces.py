"""Pieces: a partitioned result compressed piece by piece, against the same mesh as one piece.

Data (``bench/pieces_data.py``): the gmsh flange cut into 16 k-d pieces, each with its own
numbering, written as ``.pvtu`` + ``.vtu`` pieces; refined once (every tet into 8) for the larger
sizes. For every size, each a fresh ``tetc`` process under GNU time (wall seconds, peak MB):

* ``tetc compress pieces.pvtu`` (one process, levels) against ``tetc compress whole.vtu`` (the
  same mesh as one file, one piece): bytes, bits per tet, seconds, tets per second, peak MB;
* ``--memory`` splitting the pieces further (peak MB against the limit);
* ``--workers 2`` (a local Dask cluster): seconds against one process, and the same bytes;
* ``tetc render --size 512`` and ``tetc isosurface`` of the pieced file (seconds, peak MB), and
  VTK's read of the ``.pvtu`` plus ``vtkContour3DLinearGrid`` (in a fresh process) as the peer.

Targets: bytes and bits per tet within 5 % of one piece; peak set by the largest piece,
not the whole mesh; ``--workers 2`` byte-identical and faster; isosurface memory <= 0.5x VTK's.

    python bench/bench_pieces.py              # 0.8 M (the flange in 16 pieces) and 6.5 M (refined)
    python bench/bench_pieces.py --quick      # 0.8 M only
    python bench/bench_pieces.py --reuse      # sizes measured before are taken from bench/out/pieces/
    python bench/bench_pieces.py --big        # adds the ~75 M-tet run (flange-12m refined; ~1 h,
                                              # 8 GB; needs the whole quiet machine)
    python bench/bench_pieces.py --big-only --big-target 8e6   # only the --big path, at ~6.5 M
                                              # tets (flange-1m refined): a check of the script
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import code_state, run_tetc, table, write_section  # noqa: E402
from pieces_data import base_for, make  # noqa: E402

SIZES = [("flange-1m", 0), ("flange-1m", 1)]  # 0.81 M and 6.5 M tets
BIG = ("flange-12m", 1)  # about 75 M tets (the gmsh flange is built first: minutes, several GB)


_VTK_SCRIPT = r"""
import sys, time, resource
import vtk
t0 = time.perf_counter()
r = vtk.vtkXMLPUnstructuredGridReader()
r.SetFileName(sys.argv[1])
r.Update()
ug = r.GetOutput()
ug.GetPointData().SetActiveScalars("density")
c = vtk.vtkContour3DLinearGrid()
c.SetInputData(ug)
c.SetValue(0, float(sys.argv[2]))
c.Update()
print(c.GetOutput().GetNumberOfCells(), time.perf_counter() - t0)
"""


def vtk_contour(pvtu: Path, value: float, cwd: Path) -> tuple[int, float, float]:
    """(triangles, wall seconds of the whole process (as the tetc rows: start-up and imports
    included), peak MB) of VTK reading the .pvtu and contouring it, in a fresh process."""
    script = cwd / "vtk_contour.py"
    script.write_text(_VTK_SCRIPT)
    peak_file = cwd / ".vtk-peak"
    t0 = time.perf_counter()
    p = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", str(peak_file), sys.executable, str(script), str(pvtu),
                        str(value)], capture_output=True, text=True)
    if p.returncode != 0:
        return 0, float("nan"), float("nan")
    tris, _ = p.stdout.split()
    return int(tris), time.perf_counter() - t0, int(peak_file.read_text().split()[-1]) / 1024.0


def level_bytes(path: Path) -> tuple[int, int]:
    """(bytes of level 0's sections, levels stored by every brick) of a .tetc file."""
    import re

    from gatun_py.codec import TetcReader
    r = TetcReader(path)
    c = r.container
    l0 = sum(c.section_size(n) for n in c.section_names() if re.match(r"(B\d+/)?L0/", n))
    levels = min(len(r.brick(k).levels) for k in range(r.n_bricks)) if r.n_bricks > 1 else len(r.levels)
    return l0, levels


def _tetc(args, cwd, what, rows, timeout=7200):
    code, lines, secs, peak = run_tetc(args, cwd, timeout=timeout)
    if code != 0:
        raise SystemExit(f"{what} failed: {lines[-1] if lines else code}")
    return secs, peak


def measure(base: str, refine: int, work: Path, *, workers: bool = True, one_piece: bool = True) -> dict:
    pvtu = make(base, 16, refine, whole=one_piece)
    whole = pvtu.with_name("whole.vtu")
    out = {"name": f"{base} r{refine}"}
    pieced = work / "pieces.tetc"
    secs, peak = _tetc(["compress", pvtu, "-o", pieced, "--jobs", "1", "-q", "--force"], work, "pieces", None)
    from gatun_py.codec import TetcReader
    r = TetcReader(pieced)
    tets = int(r.meta["tets"])
    out.update(tets=tets, bytes=pieced.stat().st_size, secs=secs, peak=peak, bricks=r.n_bricks,
               largest=max(int(b["tets"]) for b in r.meta["bricks"]))
    out["l0_bytes"], out["levels"] = level_bytes(pieced)
    # --memory a quarter of what the largest piece needs: every piece split into ~4 bricks
    limit_mb = max(64, out["largest"] * 400 // 4 >> 20)
    m = work / "memory.tetc"
    s0, p0 = _tetc(["compress", pvtu, "-o", m, "--jobs", "1", "--memory", f"{limit_mb}M", "-q", "--force"], work,
                   "memory", None)
    out.update(memory_limit=limit_mb, memory_secs=s0, memory_peak=p0, memory_bricks=TetcReader(m).n_bricks,
               memory_bytes=m.stat().st_size)
    m.unlink()
    if one_piece:
        single = work / "whole.tetc"
        s1, p1 = _tetc(["compress", whole, "-o", single, "--jobs", "1", "-q", "--force"], work, "whole", None)
        out.update(whole_bytes=single.stat().st_size, whole_secs=s1, whole_peak=p1)
        out["whole_l0_bytes"], out["whole_levels"] = level_bytes(single)
    if workers:
        w = work / "workers.tetc"
        s2, p2 = _tetc(["compress", pvtu, "-o", w, "--workers", "2", "-q", "--force"], work, "workers", None)
        out.update(workers_secs=s2, workers_same=w.read_bytes() == pieced.read_bytes())
        w.unlink()
    lo, hi = r.meta["scalar_range"]
    value = lo + 0.5 * (hi - lo)
    s3, p3 = _tetc(["render", pieced, "-o", work / "r.png", "--size", "512", "-q", "--force"], work, "render", None)
    s4, p4 = _tetc(["isosurface", pieced, "--value", value, "-o", work / "iso.ply", "-q", "--force"], work, "iso", None)
    tris, s5, p5 = vtk_contour(pvtu, value, work)
    out.update(render_secs=s3, render_peak=p3, iso_secs=s4, iso_peak=p4, vtk_tris=tris, vtk_secs=s5, vtk_peak=p5)
    return out


def main(argv: list[str]) -> int:
    quick, big, reuse = "--quick" in argv, "--big" in argv or "--big-only" in argv, "--reuse" in argv
    sizes = [] if "--big-only" in argv else SIZES[:1] if quick else SIZES
    big_size = BIG
    if "--big-target" in argv:  # the --big run at another size (the flange nearest target / 8, refined once)
        big_size = (base_for(float(argv[argv.index("--big-target") + 1]), 1), 1)
    load = os.getloadavg()[0]
    results = []
    (HERE / "out").mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(dir=HERE / "out") as tmp:
        for base, refine in sizes + ([big_size] if big and big_size not in sizes else []):
            cache = HERE / "out" / "pieces" / f"result-{base}-r{refine}.json"
            if reuse and cache.exists():  # a size measured by an earlier run (--reuse only)
                results.append(json.loads(cache.read_text()))
                continue
            work = Path(tmp) / f"{base}-{refine}"
            work.mkdir()
            t0 = time.perf_counter()
            results.append(measure(base, refine, work, one_piece=not (big and (base, refine) == big_size),
                                   workers=True))
            results[-1]["load"] = os.getloadavg()[0]
            cache.write_text(json.dumps(results[-1]))
            print(results[-1], f"({time.perf_counter() - t0:.0f} s)", flush=True)
    rows = []
    for x in results:
        wb, w0 = x.get("whole_bytes"), x.get("whole_l0_bytes")
        rows.append([x["name"], x["tets"], x["bricks"], x["largest"], x["bytes"], 8.0 * x["bytes"] / x["tets"],
                     f"{100.0 * (x['bytes'] / wb - 1):+.2f} %" if wb else "-",
                     f"{100.0 * (x['l0_bytes'] / w0 - 1):+.2f} %" if w0 and "l0_bytes" in x else "-",
                     f"{x.get('levels', '-')} / {x.get('whole_levels', '-')}", x["secs"], x["tets"] / x["secs"],
                     x["peak"], x.get("whole_secs", "-"), x.get("whole_peak", "-")])
    split = [[x["name"], x["bricks"], x["peak"], f"{x['memory_limit']}M", x["memory_bricks"], x["memory_peak"],
              x["memory_secs"], f"{100.0 * (x['memory_bytes'] / x['bytes'] - 1):+.2f} %"]
             for x in results if "memory_peak" in x]
    cluster = [[x["name"], x["secs"], x["workers_secs"], x["secs"] / x["workers_secs"], str(x["workers_same"])]
               for x in results if "workers_secs" in x]
    rest = [[x["name"], x["render_secs"], x["render_peak"], x["iso_secs"], x["iso_peak"], x["vtk_secs"], x["vtk_peak"],
             x["iso_peak"] / x["vtk_peak"], x["iso_secs"] / x["vtk_secs"]] for x in results if "render_secs" in x]
    loads = ", ".join(f"{x['name']}: {x['load']:.0f}" for x in results if "load" in x)
    text = f"""## Pieces: a partitioned result compressed piece by piece

`python bench/bench_pieces.py` ({code_state()}; load average {load:.1f} on {os.cpu_count()} cores at the
start; at the end of each size: {loads or "-"}. Times on a loaded machine are indicative, the byte
counts and peaks are not). Data:
`bench/pieces_data.py` (the gmsh flange cut into 16 k-d pieces with their own numbering, `.pvtu` +
`.vtu`; `r1`: every piece refined once, 8x the tets). Each figure is a fresh `tetc` process under
GNU time, levels stored (`--jobs 1`); "one piece" is `tetc compress whole.vtu` of the same mesh.

{table(["mesh", "tets", "bricks", "largest brick", "bytes", "bits/tet", "vs one piece", "level 0 vs one piece",
        "levels (pieces / one)", "s", "tets/s", "peak MB", "one piece s", "one piece peak MB"], rows)}

"vs one piece" compares whole files: a pieced file's bricks keep their shared points at every
level, so they stop at a coarser level count than one piece (as `--bricks K` files do), which
makes the whole file smaller; "level 0 vs one piece" is the lossless mesh alone.

`--memory LIMIT` (a quarter of the estimated need of the largest piece, 400 B/tet) splits every
piece into bricks; peak MB of the one process against the limit:

{table(["mesh", "bricks", "peak MB", "--memory", "bricks", "peak MB", "s", "bytes vs pieces"], split)}

`--workers 2` (a local Dask cluster, two worker processes) against one process:

{table(["mesh", "1 process s", "2 workers s", "speed-up", "same bytes"], cluster)}

From the pieced file: `tetc render --size 512` and `tetc isosurface` at the middle of the scalar
range, against VTK reading the `.pvtu` and contouring it (`vtkContour3DLinearGrid`, fresh process):

{table(["mesh", "render s", "render peak MB", "isosurface s", "isosurface peak MB", "VTK s", "VTK peak MB",
        "memory vs VTK", "time vs VTK"], rest)}
"""
    write_section("pieces", text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
