"""Benchmark of on-the-fly isosurfaces: quality, time and memory against the cascades.

Run as ``python bench/bench_isosurface.py [--quick] [--big NAME.tetc]``; writes
``bench/sections/isosurface.md`` and ``bench/figures/iso_*.png``.

* **Exactness**: at ratio 1 our triangles against VTK's ``vtkContour3DLinearGrid`` of the same mesh.
* **Quality**: Metro-style sampled symmetric RMS and Hausdorff distance to the full-resolution
  surface (in % of the mesh's bounding-box diagonal), ours at R = 0.2 / 0.05 / 0.01 against the
  cascades (VTK's contour, then ``vtkQuadricDecimation``, fast-simplification, pyfqmr or
  meshoptimizer) asked for our face count, on Blunt-fin, Combustion and a gmsh mesh of >= 1 M tets,
  two isovalues each (near the 30 % and 70 % quantiles of the distinct vertex scalars).
* **Importance**: error in the high-gradient part of the surface against the rest, with and
  without an importance function that weights it.
* **Time and memory** on a large mesh: ``tetc isosurface`` from the ``.tetc`` against each cascade
  from the ``.vtu``, every one a separate process (median of several runs, peak RSS from the
  kernel's accounting of the child), and the locked band and memory over time of one of our runs.

A cascade can be run on its own: ``python bench/bench_isosurface.py --peer vtk|fast|pyfqmr|meshopt
--vtu MESH.vtu --value V --ratio R -o OUT.ply``.
"""

from __future__ import annotations

import argparse
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

from common import FIGURES, MESH_CACHE, SECTIONS, WORK, code_state, table, write_section  # noqa: E402

OUT = WORK / "iso"
RATIOS = (0.2, 0.05, 0.01)
PEERS = ("vtk", "fast", "pyfqmr", "meshopt")
BIG_DEFAULT = MESH_CACHE / "flange-10m.tetc"
PEER_NAMES = {"vtk": "VTK quadric", "fast": "fast-simplification", "pyfqmr": "pyfqmr", "meshopt": "meshoptimizer"}
TETC = [str(ROOT / ".venv" / "bin" / "tetc")] if (ROOT / ".venv" / "bin" / "tetc").exists() else ["tetc"]


# -- the cascades ---------------------------------------------------------------------------------------

def vtk_read_contour(vtu: str, value: float):
    """VTK's read of a .vtu and vtkContour3DLinearGrid: (points (n, 3) float64, triangles (m, 3))."""
    import vtk

    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(vtu))
    r.Update()
    ug = r.GetOutput()
    pd = ug.GetPointData()
    if pd.GetScalars() is None:
        pd.SetActiveScalars(pd.GetArrayName(0))
    c = vtk.vtkContour3DLinearGrid()
    c.SetInputData(ug)
    c.SetValue(0, value)
    c.Update()
    return c.GetOutput()


def polydata_arrays(poly):
    from vtk.util.numpy_support import vtk_to_numpy

    if poly.GetNumberOfPoints() == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    p = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    t = vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).reshape(-1, 3).astype(np.int64)
    return p, t


def decimate_peer(peer: str, points, tris, target_faces: int, poly=None):
    """One decimator on a triangle surface to about ``target_faces``: (points, triangles)."""
    f = len(tris)
    if target_faces >= f:
        return points, tris
    if peer == "vtk":
        import vtk

        if poly is None:
            poly = _to_polydata(points, tris)
        # vtkQuadricDecimation gives up (reduction 0) on the contour's coincident points (degenerate
        # grid cells); merging them first is what a ParaView user has to do as well
        clean = vtk.vtkCleanPolyData()
        clean.SetInputData(poly)
        clean.Update()
        f = clean.GetOutput().GetNumberOfPolys()
        d = vtk.vtkQuadricDecimation()
        d.SetInputData(clean.GetOutput())
        d.SetTargetReduction(1.0 - target_faces / f)
        d.VolumePreservationOff()
        d.Update()
        return polydata_arrays(d.GetOutput())
    if peer == "fast":
        import fast_simplification

        p, t = fast_simplification.simplify(points.astype(np.float32), tris.astype(np.int64),
                                            target_reduction=1.0 - target_faces / f)
        return np.asarray(p, np.float64), np.asarray(t, np.int64)
    if peer == "pyfqmr":
        import pyfqmr

        s = pyfqmr.Simplify()
        s.setMesh(points.astype(np.float64), tris.astype(np.int32))
        s.simplify_mesh(target_count=int(target_faces), aggressiveness=7, preserve_border=True, verbose=False)
        p, t, _ = s.getMesh()
        return np.asarray(p, np.float64), np.asarray(t, np.int64)
    if peer == "meshopt":
        import meshoptimizer

        idx = tris.astype(np.uint32).ravel()
        dest = np.empty_like(idx)
        n = meshoptimizer.simplify(dest, idx, points.astype(np.float32), target_index_count=3 * int(target_faces),
                                   target_error=1.0)
        t = dest[:n].reshape(-1, 3).astype(np.int64)
        used, inv = np.unique(t, return_inverse=True)
        return points[used], inv.reshape(-1, 3)
    raise ValueError(peer)


def _to_polydata(points, tris):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    poly = vtk.vtkPolyData()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(points, np.float64), deep=True))
    poly.SetPoints(pts)
    ca = vtk.vtkCellArray()
    ca.SetData(numpy_to_vtkIdTypeArray(3 * np.arange(len(tris) + 1, dtype=np.int64), deep=True),
               numpy_to_vtkIdTypeArray(np.ascontiguousarray(tris, np.int64).ravel(), deep=True))
    poly.SetPolys(ca)
    return poly


def run_peer(args) -> int:
    """A whole cascade as one process: read .vtu, contour, decimate, write PLY."""
    poly = vtk_read_contour(args.vtu, args.value)
    p, t = polydata_arrays(poly)
    target = int(np.ceil(args.ratio * len(t)))
    p2, t2 = decimate_peer(args.peer, p, t, target, poly=poly)
    if args.peer == "vtk":
        import vtk

        w = vtk.vtkPLYWriter()
        w.SetFileName(args.output)
        w.SetInputData(_to_polydata(p2, t2))
        w.Write()
    else:
        import meshio

        meshio.write(args.output, meshio.Mesh(p2, [("triangle", t2.astype(np.int32))]), file_format="ply")
    print(json.dumps({"faces_in": len(t), "faces": len(t2)}))
    return 0


# -- data ------------------------------------------------------------------------------------------------

def datasets(quick: bool):
    """name -> (mesh source for read_mesh, read kwargs)."""
    d = {"Blunt-fin": (ROOT / "sample_meshes" / "bluntfin" / "bluntfinxyz.bin", {}),
         "Combustion": (ROOT / "sample_meshes" / "combustion_chamber" / "combxyz.bin", {})}
    if not quick:
        try:
            from gmsh_meshes import mesh_path

            d["gmsh flange 1M"] = (mesh_path("flange-1m"), {})
        except Exception as e:  # gmsh (bench extra) missing or the mesh cannot be built
            print(f"skipping the gmsh mesh: {e}", file=sys.stderr)
    return d


def prepared(name, src, kw):
    """(TetMesh, .tetc path, .vtu path) of a data set, the files cached in bench/out/iso."""
    from gatun_py.codec import write_tetc
    from gatun_py.mesh import read_mesh, write_mesh

    OUT.mkdir(parents=True, exist_ok=True)
    stem = name.lower().replace(" ", "_").replace("-", "")
    mesh = read_mesh(src, **kw)[0]
    tetc, vtu = OUT / f"{stem}.tetc", OUT / f"{stem}.vtu"
    if not tetc.exists():
        write_tetc(tetc, mesh, source=str(src))
    if not vtu.exists():
        write_mesh(mesh, vtu)
    return mesh, tetc, vtu


# -- parts -----------------------------------------------------------------------------------------------

def isovalue(density, q: float) -> float:
    """The q-quantile of the vertex scalars, moved half way to the next distinct value: an isovalue
    that no vertex holds exactly (where one does, VTK emits zero-area triangles that we do not)."""
    u = np.unique(np.asarray(density, np.float64))
    i = min(int(np.searchsorted(u, np.quantile(u, q))), len(u) - 2)
    return float((u[i] + u[i + 1]) / 2)


def part_quality(quick: bool):
    from gatun_py.contour import isosurface
    from gatun_py.contour.metrics import surface_distance

    rows, curves, exact_rows = [], {}, []
    samples = 60_000 if quick else 150_000
    for name, (src, kw) in datasets(quick).items():
        mesh, tetc, vtu = prepared(name, src, kw)
        lo, hi = mesh.bbox
        diag = float(np.linalg.norm(hi - lo))
        for q in (0.3, 0.7):
            v = isovalue(mesh.density, q)
            full = isosurface(tetc, values=v)
            poly = vtk_read_contour(vtu, v)
            vp, vt = polydata_arrays(poly)
            from scipy.spatial import cKDTree

            dmax = float(cKDTree(vp).query(full.points)[0].max()) / diag if len(vp) else 0.0
            floor = surface_distance(full.points, full.triangles, full.points, full.triangles, diagonal=diag,
                                     n_samples=samples)["rms"]  # the metric's own error: surface to itself
            exact_rows.append([name, f"{v:.5g}", full.n_triangles, len(vt), f"{dmax:.1e}", f"{floor:.5f}"])
            print(f"{name} iso {v:.5g}: {full.n_triangles} faces (VTK {len(vt)})", flush=True)
            key = (name, v)
            curves[key] = {"ours": [], **{p: [] for p in PEERS}}
            for r in RATIOS:
                t0 = time.perf_counter()
                ours = isosurface(tetc, values=v, ratio=r)
                t_ours = time.perf_counter() - t0
                e = surface_distance(full.points, full.triangles, ours.points, ours.triangles, diagonal=diag,
                                     n_samples=samples)
                row = [name, f"{v:.4g}", r, full.n_triangles, ours.n_triangles, f"{e['rms']:.4f}",
                       f"{e['hausdorff']:.3f}", f"{ours.stats['peak_locked']}"]
                curves[key]["ours"].append((ours.n_triangles, e["rms"], e["hausdorff"]))
                best = None
                for peer in PEERS:
                    try:
                        t0 = time.perf_counter()
                        pp, pt = decimate_peer(peer, vp, vt, ours.n_triangles, poly=poly)
                        dt = time.perf_counter() - t0
                    except Exception as ex:  # a peer not installed
                        print(f"  {peer}: {ex}", file=sys.stderr)
                        continue
                    ep = surface_distance(full.points, full.triangles, pp, pt, diagonal=diag, n_samples=samples)
                    curves[key][peer].append((len(pt), ep["rms"], ep["hausdorff"]))
                    if abs(len(pt) - ours.n_triangles) <= 0.1 * ours.n_triangles + 10:
                        if best is None or ep["rms"] < best[2]:
                            best = (peer, len(pt), ep["rms"], ep["hausdorff"])
                    print(f"  R={r} {peer}: {len(pt)} faces rms {ep['rms']:.4f} haus {ep['hausdorff']:.3f} "
                          f"({dt:.2f} s)", flush=True)
                print(f"  R={r} ours: {ours.n_triangles} faces rms {e['rms']:.4f} haus {e['hausdorff']:.3f} "
                      f"({t_ours:.2f} s)", flush=True)
                if best:
                    rr = e["rms"] / best[2] if best[2] > 0 else float("inf")
                    hr = e["hausdorff"] / best[3] if best[3] > 0 else float("inf")
                    row += [f"{PEER_NAMES[best[0]]} ({best[1]})", f"{best[2]:.4f}", f"{best[3]:.3f}",
                            f"{rr:.2f}", f"{hr:.2f}", "yes" if rr <= 1 and hr <= 1 else "no"]
                else:
                    row += ["-", "-", "-", "-", "-", "-"]
                rows.append(row)
    return exact_rows, rows, curves


BRICKS_QUALITY = 8


def part_bricked_quality(quick: bool):
    """Ours from a bricked file (K = 8, skipping the bricks the isovalue misses) against ours from
    the one-stream file, at every ratio of the quality table: faces, RMS and Hausdorff distance to
    the full-resolution surface."""
    from gatun_py.codec import TetcReader
    from gatun_py.contour import isosurface
    from gatun_py.contour.metrics import surface_distance
    from gatun_py.pipeline.bricks import compress_bricks

    rows = []
    samples = 60_000 if quick else 150_000
    for name, (src, kw) in list(datasets(True).items()):
        mesh, tetc, _ = prepared(name, src, kw)
        bricked = OUT / f"{tetc.stem}_k{BRICKS_QUALITY}.tetc"
        if not bricked.exists():
            bricked.write_bytes(compress_bricks(mesh, BRICKS_QUALITY, mesh_only=True))
        lo, hi = mesh.bbox
        diag = float(np.linalg.norm(hi - lo))
        for q in (0.3, 0.7):
            v = isovalue(mesh.density, q)
            full = isosurface(tetc, values=v)
            full_b = isosurface(TetcReader(bricked), values=v)
            for r in RATIOS:
                one = isosurface(tetc, values=v, ratio=r)
                t0 = time.perf_counter()
                br = isosurface(TetcReader(bricked), values=v, ratio=r)
                dt = time.perf_counter() - t0
                e1 = surface_distance(full.points, full.triangles, one.points, one.triangles, diagonal=diag,
                                      n_samples=samples)
                eb = surface_distance(full.points, full.triangles, br.points, br.triangles, diagonal=diag,
                                      n_samples=samples)
                b = br.stats["bricks"]
                rows.append([name, f"{v:.4g}", r, f"{full.n_triangles} / {full_b.n_triangles}",
                             f"{b['bricks_decoded']} of {b['bricks']}", one.n_triangles, f"{e1['rms']:.4f}",
                             f"{e1['hausdorff']:.3f}", br.n_triangles, f"{eb['rms']:.4f}", f"{eb['hausdorff']:.3f}",
                             f"{eb['rms'] / e1['rms']:.2f}" if e1["rms"] > 0 else "-",
                             f"{eb['hausdorff'] / e1['hausdorff']:.2f}" if e1["hausdorff"] > 0 else "-",
                             f"{one.stats['peak_locked']} / {br.stats['peak_locked']}", br.stats["locked_at_end"]])
                print(f"{name} {v:.4g} R={r}: one stream {one.n_triangles} rms {e1['rms']:.4f}, bricked "
                      f"{br.n_triangles} rms {eb['rms']:.4f} ({dt:.2f} s)", flush=True)
    return rows


def part_importance():
    from gatun_py.contour import isosurface
    from gatun_py.contour.metrics import one_sided
    from gatun_py.mesh import read_mesh

    mesh = read_mesh(ROOT / "sample_meshes" / "bluntfin" / "bluntfinxyz.bin")[0]
    lo, hi = mesh.bbox
    diag = float(np.linalg.norm(hi - lo))
    rows = []
    for q in (0.3, 0.7):
        v = isovalue(mesh.density, q)
        full = isosurface(mesh, values=v)
        g = full.point_data["gradient_magnitude"]
        cut = float(np.quantile(g, 0.8))
        scale = diag / (mesh.scalar_range[1] - mesh.scalar_range[0])
        imp = {"points": [{"x": 0.0, "w": 1.0}, {"x": 0.9 * cut * scale, "w": 1.0}, {"x": cut * scale, "w": 50.0}]}
        hot = g >= cut
        for r in (0.05, 0.01):
            res = {}
            for label, tf in (("plain", None), ("importance", imp)):
                s = isosurface(mesh, values=v, ratio=r, importance_tf=tf)
                d = one_sided(full.points, s.points, s.triangles) * 100 / diag
                res[label] = (s.n_triangles, float(np.sqrt(np.mean(d[hot] ** 2))), float(np.sqrt(np.mean(d[~hot] ** 2))))
            rows.append([f"{v:.4g}", r, res["plain"][0], f"{res['plain'][1]:.4f}", f"{res['plain'][2]:.4f}",
                         res["importance"][0], f"{res['importance'][1]:.4f}", f"{res['importance'][2]:.4f}"])
    return rows


def part_levels():
    """Extraction from pre-simplified levels of the tet mesh (crack-free coarse surfaces), then QEM."""
    from gatun_py.codec import TetcReader, write_tetc  # noqa: F401
    from gatun_py.contour import isosurface
    from gatun_py.contour.metrics import surface_distance
    from gatun_py.mesh import read_mesh

    src = ROOT / "sample_meshes" / "bluntfin" / "bluntfinxyz.bin"
    path = OUT / "bluntfin_levels.tetc"
    if not path.exists():
        subprocess.run(TETC + ["compress", str(src), "-o", str(path), "--quiet", "--force"], check=True)
    mesh = read_mesh(src)[0]
    lo, hi = mesh.bbox
    diag = float(np.linalg.norm(hi - lo))
    v = isovalue(mesh.density, 0.7)
    full = isosurface(path, values=v)
    levels = sorted(int(lv["level"]) for lv in TetcReader(path).levels)
    rows = []
    for level in levels[:6]:
        for ratio in (None, 0.2):
            t0 = time.perf_counter()
            s = isosurface(path, values=v, level=level, ratio=ratio)
            dt = time.perf_counter() - t0
            e = surface_distance(full.points, full.triangles, s.points, s.triangles, diagonal=diag, n_samples=100_000)
            rows.append([level, ratio or 1, s.stats["tets"], s.stats["faces_extracted"], s.n_triangles,
                         f"{e['rms']:.4f}", f"{e['hausdorff']:.3f}", f"{dt:.2f}"])
            print(f"  level {level} R={ratio}: {s.n_triangles} faces rms {e['rms']:.4f}", flush=True)
    return {"value": v, "full": full.n_triangles, "rows": rows}


def _child(cmd) -> tuple[float, float, str, float]:
    """Wall seconds, peak RSS (MB) of the child process, its stdout, its CPU seconds (user + system)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env={**os.environ, "NUMBA_NUM_THREADS": "2"})
    out = p.stdout.read().decode()
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{cmd[:3]} failed ({p.returncode})")
    return time.perf_counter() - t0, ru.ru_maxrss / 1024.0, out, ru.ru_utime + ru.ru_stime


#: bare interpreters, for what the pipelines' peaks hold beyond their imports
BARE = {"bare: import vtk": [sys.executable, "-c", "import vtk"],
        "bare: import gatun_py.isosurface, numba": [sys.executable, "-c",
                                                    "import gatun_py, gatun_py.isosurface, numba"]}


def _timed(cmds: dict, runs: int) -> tuple[dict, dict]:
    """Run every command once (warm-up, not counted), then ``runs`` times, interleaved so that drift
    hits everyone alike: ({name: [(wall, rss, cpu), ...]}, {name: the --stats JSON of its last run})."""
    res = {k: [] for k in cmds}
    stats = {}
    for i in range(runs + 1):
        for k, cmd in cmds.items():
            try:
                wall, rss, out, cpu = _child(cmd)
            except RuntimeError as e:
                print(e, file=sys.stderr)
                continue
            if "--stats" in cmd:
                stats[k] = json.loads(out)
            if i == 0:
                print(f"  (warm-up) {k}: {wall:.2f} s {rss:.0f} MB", flush=True)
                continue
            res[k].append((wall, rss, cpu))
            print(f"  {k}: {wall:.2f} s {rss:.0f} MB", flush=True)
    return res, stats


def _rows(res: dict, ours_k: str, peers=()) -> list:
    """Table rows (median of the runs): each line's time and memory, and ours / it. With ``peers``,
    also ours / each of them (the ratios to the cascades of the bricked lines)."""
    med = {k: (statistics.median(x[0] for x in r), statistics.median(x[1] for x in r),
               statistics.median(x[2] for x in r)) for k, r in res.items() if r}
    rows = []
    for k, (w, m, c) in med.items():
        samples = ", ".join(f"{x[0]:.2f}" for x in res[k])
        bare = k in BARE
        row = [k, f"{w:.2f}", samples, f"{c:.2f}", f"{m:.0f}", "" if bare or ours_k not in med else f"{med[ours_k][0] / w:.2f}",
               "" if bare or ours_k not in med else f"{med[ours_k][1] / m:.2f}"]
        for p in peers:
            ok = not bare and k.startswith("ours") and p in med
            row += [f"{w / med[p][0]:.2f} / {m / med[p][1]:.2f}" if ok else ""]
        rows.append(row)
    return rows


def _ours_cmd(tetc: Path, v: float, ratio: float, out: str) -> list:
    return TETC + ["isosurface", str(tetc), "--value", str(v), "--ratio", str(ratio), "-o", str(OUT / out), "--force",
                   "--quiet", "--stats"]


def _bricked_name(path: Path) -> str:
    from gatun_py.codec import TetcReader

    return f"ours, bricked K={TetcReader(path).n_bricks}"


def _brick_summary(name: str, st: dict, size: int) -> list:
    b = st.get("bricks") or {}
    return [name, f"{size / 1e6:.1f}", f"{b.get('bricks_decoded', '?')} of {b.get('bricks', '?')}",
            f"{b.get('tets', 0):,}", b.get("peak_bricks_decoding", "?"), b.get("peak_bricks_held", "?"),
            f"{st.get('peak_locked', 0):,}", f"{st.get('locked_at_end', 0):,}", f"{st.get('faces_extracted', 0):,}",
            f"{st.get('faces', 0):,}", f"{st.get('decode_s', 0):.2f}", f"{st.get('peak_rss_mb', 0):.0f}"]


def part_big(tetc: Path, vtu: Path, runs: int, value: float | None = None, bricked=(), value2: float | None = None):
    """Time and memory of one isosurface at R = 0.05 on a large mesh: ours against every cascade.

    Every pipeline runs once first, not counted (numba's cache, the page cache), then ``runs``
    times, interleaved. ``bricked``: the same mesh in bricked files, a line each; ``value2``: a
    second isovalue (one that fewer bricks hold), ours and the two fastest cascades again.
    """
    from gatun_py.codec import TetcReader

    OUT.mkdir(parents=True, exist_ok=True)
    reader = TetcReader(tetc)
    lo_s, hi_s = reader.meta["scalar_range"]
    v = lo_s + 0.35 * (hi_s - lo_s) if value is None else float(value)
    ratio = 0.05
    bricked = [Path(b) for b in bricked]
    cmds = {"ours (tetc isosurface)": _ours_cmd(tetc, v, ratio, "big_ours.ply")}
    for b in bricked:
        cmds[_bricked_name(b)] = _ours_cmd(b, v, ratio, f"big_{b.stem}.ply")
    for peer in PEERS:
        cmds[f"VTK read + contour + {PEER_NAMES[peer]}"] = [sys.executable, __file__, "--peer", peer, "--vtu", str(vtu),
                                                            "--value", str(v), "--ratio", str(ratio),
                                                            "-o", str(OUT / f"big_{peer}.ply")]
    cmds.update(BARE)
    load0 = os.getloadavg()[0]
    ours_k = next(iter(cmds))
    cascades = [f"VTK read + contour + {PEER_NAMES[p]}" for p in ("vtk", "meshopt")]
    res, stats = _timed(cmds, runs)
    out = {"value": v, "ratio": ratio, "rows": _rows(res, ours_k, cascades if bricked else ()),
           "stats": stats.get(ours_k), "tets": int(reader.level_meta(0)["tets"]), "file": tetc.name, "runs": runs,
           "code": code_state(), "size_mb": tetc.stat().st_size / 1e6,
           "bricked": [b.name for b in bricked],
           "bricks": [_brick_summary(_bricked_name(b), stats.get(_bricked_name(b), {}), b.stat().st_size)
                      for b in bricked],
           "bricked_bands": {_bricked_name(b): (stats.get(_bricked_name(b)) or {}).get("band", []) for b in bricked}}
    if value2 is not None:
        cmds2 = {k: c for k, c in cmds.items() if k.startswith("ours") or k in cascades}
        cmds2 = {k: [str(value2) if x == str(v) else x for x in c] for k, c in cmds2.items()}
        res2, stats2 = _timed(cmds2, runs)
        out["value2"] = float(value2)
        out["rows2"] = _rows(res2, ours_k, cascades if bricked else ())
        out["bricks2"] = [_brick_summary(_bricked_name(b), stats2.get(_bricked_name(b), {}), b.stat().st_size)
                          for b in bricked]
        out["stats2"] = stats2.get(ours_k)
    out["load"] = [load0, os.getloadavg()[0]]
    return out


def _rss_now() -> float:
    """VmRSS of this process, MB (the memory children read it often: statm is one line)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _memory_stages_child(tetc: str, value: float) -> int:
    """(child) Where the peak of one isosurface run goes; one JSON line on stdout.

    In one fresh process: RSS after each import, after a run on the 90-tet file shipped with the
    package (the floor: numba's runtime and our kernels' compiled code, loaded on the first call),
    then the real run with RSS sampled every 5 ms, the arrays the decoders and the extractor hold
    at the last tets (sizes; the connectivity border counted as far as it was used), and the RSS a
    round of collapses adds while it runs. tracemalloc cannot see most of this (numba's runtime
    allocates outside it), so everything is RSS or array sizes.
    """
    import gc
    import importlib
    import threading

    rec = {"numpy": _rss_now()}
    import numba  # noqa: F401

    rec["numba"] = _rss_now()
    ex = importlib.import_module("gatun_py.contour.extract")
    importlib.import_module("gatun_py.cli.main")  # what the command imports before the verb
    from gatun_py.codec import _cutborder_kernels as CK
    from gatun_py.codec.cutborder import ConnectivityDecoder
    from gatun_py.codec.geometry import GeometryDecoder

    rec["modules"] = _rss_now()
    had_scipy = "scipy.linalg" in sys.modules
    ex.load_kernels(tetc)  # as tetc isosurface does: the kernels, then LLVM's code pages handed back
    rec["floor"] = _rss_now()
    rec["scipy_linalg_by_numba"] = "scipy.linalg" in sys.modules and not had_scipy

    samples, stop = [], threading.Event()
    t0 = time.perf_counter()

    def sample():
        while not stop.is_set():
            samples.append((round(time.perf_counter() - t0, 3), round(_rss_now(), 1)))
            time.sleep(0.005)

    def mb(x):
        return round(x / 2**20, 1)

    def _border_mb(B):
        """The cut border: its element table as far as slots were handed out, its list heads and queue."""
        used = int(B[3][CK.BS_BUMP]) * CK.E_COLS * B[0].itemsize
        return mb(min(used, B[0].nbytes) + B[1].nbytes + B[2].nbytes)

    def held(cls):
        out = {}
        for obj in gc.get_objects():
            if isinstance(obj, cls):
                for name, v in vars(obj).items():
                    if name == "_B" and v is not None:
                        out["border"] = _border_mb(v)
                        continue
                    for a in (v if isinstance(v, tuple) else (v,)):
                        if isinstance(a, np.ndarray) and a.nbytes >= 2**20:
                            out[name] = round(out.get(name, 0) + mb(a.nbytes), 1)
        return out

    total = ex.TetcReader(tetc).level_meta(0)["tets"]
    at_end = {}

    class Watched(ex.PrefetchedDecode):  # the arrays held when the last tets come out
        def __iter__(self):
            seen, conn, border = 0, None, 0.0
            for batch in super().__iter__():
                seen += len(batch.tets)
                if conn is None and len(batch.tets):
                    conn = next(o for o in gc.get_objects() if isinstance(o, ConnectivityDecoder))
                if conn is not None and getattr(conn, "_B", None) is not None:  # freed with the last tets
                    border = max(border, _border_mb(conn._B))
                if seen == total and len(batch.tets) and not at_end:
                    at_end.update(geometry=held(GeometryDecoder), connectivity=held(ConnectivityDecoder),
                                  extraction=held(ex._Extractor), rss=_rss_now())
                    at_end["connectivity"]["border (at its largest)"] = round(border, 1)
                yield batch

    rounds = []
    decimate = ex._Extractor.decimate

    def watched_decimate(self, *, final):
        a = time.perf_counter() - t0
        decimate(self, final=final)
        rounds.append((round(a, 3), round(time.perf_counter() - t0, 3), final))

    ex.PrefetchedDecode, ex._Extractor.decimate = Watched, watched_decimate
    th = threading.Thread(target=sample, daemon=True)
    th.start()
    s = ex.isosurface(tetc, values=value, ratio=0.05)
    stop.set()
    th.join()
    with open("/proc/self/status") as fh:
        hwm = next(int(ln.split()[1]) / 1024 for ln in fh if ln.startswith("VmHWM"))
    t_peak, peak = max(samples, key=lambda x: x[1])
    # what a round adds: the highest sample during it minus the last sample before it
    adds = []
    for a, b, final in rounds:
        before = [r for t, r in samples if t <= a]
        during = [r for t, r in samples if a <= t <= b]
        if before and during:
            adds.append(round(max(during) - before[-1], 1))
    rec.update(peak=round(hwm, 1), sampled_peak=peak, t_peak=t_peak, at_end=at_end, rounds=rounds,
               round_adds=adds, peak_in_round=any(a <= t_peak <= b + 1.0 for a, b, _ in rounds),
               total_s=round(s.stats["total_s"], 2), samples=samples[::4])
    print(json.dumps(rec))
    return 0


def part_memory_stages(tetc: Path, value: float):
    """Run :func:`_memory_stages_child` in a fresh process (the isovalue and ratio of :func:`part_big`)."""
    p = subprocess.run([sys.executable, __file__, "--memory-stages", str(tetc), "--value", str(value)],
                       capture_output=True, text=True,
                       env={**os.environ, "NUMBA_NUM_THREADS": "2"})
    if p.returncode != 0:
        print(p.stderr, file=sys.stderr)
        return None
    return json.loads(p.stdout.strip().splitlines()[-1])


# -- report ----------------------------------------------------------------------------------------------

def plots(curves, big):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIGURES.mkdir(parents=True, exist_ok=True)
    keys = list(curves)
    n = len(keys)
    if n:
        _plot_error_curves(plt, curves, keys, n)
    if big and big.get("stats"):
        _plot_memory(plt, big)


def _plot_error_curves(plt, curves, keys, n):
    import matplotlib.ticker

    fig, axes = plt.subplots(2, (n + 1) // 2, figsize=(4.2 * ((n + 1) // 2), 7), squeeze=False)
    for ax, key in zip(axes.ravel(), keys):
        for label, pts in curves[key].items():
            if not pts:
                continue
            pts = sorted(pts)
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-" if label == "ours" else ".--",
                      label="ours (on the fly)" if label == "ours" else PEER_NAMES[label], lw=2 if label == "ours" else 1)
        ax.set_title(f"{key[0]}, iso {key[1]:.4g}", fontsize=9)
        ax.set_xlabel("faces")
        ax.set_ylabel("RMS distance, % of diagonal")
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(FIGURES / "iso_error_vs_faces.png", dpi=110)
    plt.close(fig)


def _plot_memory(plt, big):
    """Memory over one run, the stream's timeline (when each batch was decoded and extracted, the
    rounds of collapses) and the surface held."""
    band = big["stats"]["band"]
    st = big.get("stages") or {}
    fig, ax = plt.subplots(1, 3, figsize=(15, 3.8))
    t = [b["t_s"] for b in band]
    ax[0].plot(t, [b["rss_mb"] for b in band], label="ours (tetc isosurface): RSS at each batch")
    if st.get("samples"):
        ax[0].plot([x[0] for x in st["samples"]], [x[1] for x in st["samples"]], lw=0.8,
                   label="ours in one process, sampled every 20 ms")
        for a, b_, _ in st.get("rounds", []):
            ax[0].axvspan(a, b_, color="orange", alpha=0.2, lw=0)
        if "floor" in st:
            ax[0].axhline(st["floor"], ls=":", lw=1, color="black", label="floor: the same run on 90 tets")
    for name, bband in big.get("bricked_bands", {}).items():
        ax[0].plot([b["t_s"] for b in bband], [b["rss_mb"] for b in bband], lw=1, label=f"{name}: RSS at each batch")
    for row in big["rows"][1:]:
        if row[0] in BARE or row[0].startswith("ours"):
            continue
        ax[0].axhline(float(row[4]), ls="--", lw=1, label=f"{row[0].split(' + ')[-1]} cascade peak", color="grey")
    ax[0].set_xlabel("seconds (orange: rounds of collapses)")
    ax[0].set_ylabel("MB")
    ax[0].legend(fontsize=6)
    ax[0].set_title("memory over one run", fontsize=9)
    if band and "decoded_s" in band[0]:
        k = range(len(band))
        ax[1].plot([b["decoded_s"] for b in band], k, label="batch decoded (out of the stream)")
        ax[1].plot(t, k, label="batch extracted (worker done)")
        prev = 0
        for b in band:  # a batch whose extraction ran a round: its span, shaded
            if b["rounds"] > prev:
                ax[1].axhspan(band.index(b) - 0.5, band.index(b) + 0.5, color="orange", alpha=0.5, lw=0)
                prev = b["rounds"]
        ax[1].set_xlabel("seconds")
        ax[1].set_ylabel("batch (65,536 tets)")
        ax[1].legend(fontsize=7)
        ax[1].set_title("timeline: decoding runs ahead, extraction follows", fontsize=9)
    ax[2].plot(t, [b["faces"] for b in band], label="faces held")
    ax[2].plot(t, [b["faces_extracted"] for b in band], label="faces extracted so far")
    ax[2].plot(t, [b["locked"] for b in band], label="locked vertices (band)")
    ax[2].set_yscale("log")
    ax[2].set_xlabel("seconds")
    ax[2].legend(fontsize=7)
    ax[2].set_title("surface held and locked band", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIGURES / "iso_memory_over_time.png", dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--big", default=str(BIG_DEFAULT) if BIG_DEFAULT.exists() else None,
                    help="large .tetc for time and memory (its .vtu beside it; default: the 7.8 M-tet gmsh flange "
                         "from the shared cache when it is there)")
    ap.add_argument("--big-value", type=float, default=None,
                    help="isovalue for the large mesh (default: 35 %% of its scalar range)")
    ap.add_argument("--big-bricked", action="append", default=[], metavar="FILE",
                    help="the large mesh as a bricked .tetc (repeat for several K): a line each")
    ap.add_argument("--big-value2", type=float, default=None,
                    help="a second isovalue for the large mesh (one fewer bricks hold): ours and two cascades")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--only", choices=["quality", "bricks", "levels", "big", "stages", "report"], default=None,
                    help="run one part (stages: where the large run's memory goes, also part of big; report: "
                         "only rewrite the section and figures from the saved results)")
    ap.add_argument("--peer", choices=PEERS)
    ap.add_argument("--memory-stages", metavar="TETC", help=argparse.SUPPRESS)
    ap.add_argument("--vtu")
    ap.add_argument("--value", type=float)
    ap.add_argument("--ratio", type=float)
    ap.add_argument("-o", "--output")
    args = ap.parse_args(argv)
    if args.peer:
        return run_peer(args)
    if args.memory_stages:
        return _memory_stages_child(args.memory_stages, args.value)
    cache = OUT / "results.json"
    saved = json.loads(cache.read_text()) if cache.exists() else {}
    if args.only in (None, "quality"):
        exact, quality, curves = part_quality(args.quick)
        saved.update(exact=exact, quality=quality, importance=part_importance(),
                     curves=[[list(k), v] for k, v in curves.items()])
    if args.only in (None, "bricks"):
        saved["bricks_quality"] = part_bricked_quality(args.quick)
    if args.only in (None, "levels"):
        saved["levels"] = part_levels()
    if args.only in (None, "big") and args.big:
        big = Path(args.big)
        saved["big"] = part_big(big, big.with_suffix(".vtu"), args.runs, args.big_value, args.big_bricked,
                                args.big_value2)
        OUT.mkdir(parents=True, exist_ok=True)
        cache.write_text(json.dumps(saved))  # the timed runs are kept even if the stages fail
        saved["big"]["stages"] = part_memory_stages(big, saved["big"]["value"])
    if args.only == "stages" and args.big and saved.get("big"):
        saved["big"]["stages"] = part_memory_stages(Path(args.big), saved["big"]["value"])
    OUT.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(saved))
    curves = {tuple(k): v for k, v in saved.get("curves", [])}
    plots(curves, saved.get("big"))
    text = report(saved)
    old = SECTIONS / "isosurface.md"
    if "quality" not in saved and old.exists():  # a partial run (--only big): keep the other tables
        text = _splice_big(old.read_text(), text)
        text = _splice_part(text, report({"bricks_quality": saved.get("bricks_quality")}), _BRICKS_HEADING,
                            before=_LEVELS_HEADING)
    elif "big" not in saved and old.exists():  # a run without the large mesh: keep its part
        text = _splice_big(text, old.read_text())
    write_section("isosurface", text)
    return 0


_BIG_HEADING = "### Time and memory on a large mesh"
_BRICKS_HEADING = "### From a bricked file"
_LEVELS_HEADING = "### Starting from a pre-simplified level"


def _splice_part(old: str, new: str, heading: str, *, before: str) -> str:
    """``old`` with its part under ``heading`` (to the next ``### ``) replaced by ``new``'s, or
    inserted before the part under ``before`` (appended when there is none)."""
    if heading not in new:
        return old
    part = new[new.index(heading):]
    nxt = part.find("\n### ")
    part = (part[:nxt] if nxt >= 0 else part).rstrip() + "\n\n"
    if heading in old:
        head, rest = old.split(heading, 1)
        nxt = rest.find("\n### ")
        return head + part + (rest[nxt + 1:] if nxt >= 0 else "")
    if before in old:
        head, rest = old.split(before, 1)
        return head + part + before + rest
    return old.rstrip() + "\n\n" + part


def _splice_big(old: str, new: str) -> str:
    """``old`` with its large-mesh part replaced by ``new``'s (appended when ``old`` has none)."""
    if _BIG_HEADING not in new:
        return old
    part = new[new.index(_BIG_HEADING):]
    if _BIG_HEADING not in old:
        return old.rstrip() + "\n\n" + part
    head, rest = old.split(_BIG_HEADING, 1)
    nxt = rest.find("\n### ")
    tail = rest[nxt:] if nxt >= 0 else ""
    return head + part.rstrip() + "\n" + tail


def _quality_tally(rows) -> str:
    """One line: in how many cells RMS, Hausdorff and both are at most the best cascade's."""
    # from the errors' columns, not the ratios rounded to 2 decimals (a 1.002 would count as <= 1)
    done = [r for r in rows if len(r) > 13 and r[11] != "-"]
    rr = [float(r[5]) / float(r[9]) if float(r[9]) > 0 else float("inf") for r in done]
    hr = [float(r[6]) / float(r[10]) if float(r[10]) > 0 else float("inf") for r in done]
    both = sum(1 for r in done if r[13] == "yes")
    if not rr:
        return ""
    gm = lambda x: float(np.exp(np.mean(np.log(x))))  # noqa: E731
    return (f"Cells with RMS <= the best cascade's: {sum(x <= 1 for x in rr)} of {len(rr)}; Hausdorff: "
            f"{sum(x <= 1 for x in hr)} of {len(hr)}; both: {both} of {len(rr)}. Geometric mean of the ratios: "
            f"RMS {gm(rr):.3f}, Hausdorff {gm(hr):.3f}; worst: RMS {max(rr):.3f}, Hausdorff {max(hr):.2f}.")


def report(s) -> str:
    out = ["## On-the-fly isosurfaces", ""]
    if "exact" in s:
        out += ["### Exactness at ratio 1 against VTK's vtkContour3DLinearGrid", "",
                table(["data set", "isovalue", "our faces", "VTK faces", "max vertex distance / diagonal",
                       "metric floor (RMS of the surface to itself, %)"], s["exact"]), ""]
    if "quality" in s:
        out += ["### Quality at equal face counts (sampled symmetric distance to the full surface, % of the diagonal)", "",
                "Ours: `isosurface(tetc, ratio=R)` with the default batch of 100 000 faces, streamed from the "
                "`.tetc`. Cascades: VTK's contour, then each decimator asked for our face count; "
                "the best cascade is the one with the lowest RMS within 10 % of our count. "
                "Ratios: ours / that cascade's; target met = both ratios <= 1.", "",
                table(["data set", "iso", "R", "full faces", "our faces", "our RMS", "our Hausdorff", "peak locked",
                       "best cascade (faces)", "its RMS", "its Hausdorff", "RMS ratio", "Hausdorff ratio",
                       "target met"], s["quality"]), "",
                _quality_tally(s["quality"]), "",
                "![error over faces](../figures/iso_error_vs_faces.png)", ""]
    if "importance" in s:
        out += ["### Importance (Peng et al.): Blunt-fin, weight 50 on the top 20 % gradient magnitude", "",
                "RMS distance (% of diagonal) of the full surface's vertices to the simplified surface, in the "
                "weighted (high-gradient) region and in the rest.", "",
                table(["iso", "R", "plain faces", "plain RMS important", "plain RMS rest", "weighted faces",
                       "weighted RMS important", "weighted RMS rest"], s["importance"]), ""]
    if s.get("bricks_quality"):
        out += [f"### From a bricked file (K = {BRICKS_QUALITY}) against the one-stream file", "",
                f"`tetc compress --bricks {BRICKS_QUALITY} --mesh-only`; the bricks whose stored scalar range "
                "misses the isovalue are not decoded. Distance to the full-resolution surface (% of the "
                "diagonal); ratios: bricked / one stream. Full faces: one stream / bricked (equal: the same "
                "surface, one vertex per cut edge).", "",
                table(["data set", "iso", "R", "full faces", "bricks decoded", "one-stream faces", "RMS",
                       "Hausdorff", "bricked faces", "RMS", "Hausdorff", "RMS ratio", "Hausdorff ratio",
                       "peak locked (one / bricked)", "locked at end (bricked)"], s["bricks_quality"]), ""]
    if s.get("levels"):
        lv = s["levels"]
        out += [f"### Starting from a pre-simplified level (Blunt-fin, isovalue {lv['value']:.4g}, full surface "
                f"{lv['full']:,} faces)", "",
                "The tet mesh of a stored level is conforming, so its surface has no cracks; QEM (R) then "
                "refines the surface quality. Distance to the full-resolution surface, % of the diagonal.", "",
                table(["level", "R", "tets streamed", "faces extracted", "faces", "RMS", "Hausdorff", "seconds"],
                      lv["rows"]), ""]
    if s.get("big"):
        b = s["big"]
        st = b["stats"] or {}
        out += [f"### Time and memory on a large mesh ({b['tets']:,} tets, isovalue {b['value']:.4g}, R = {b['ratio']})", "",
                f"`python bench/bench_isosurface.py --only big --big {b.get('file', '?')} --big-value {b['value']:.4g} "
                + "".join(f"--big-bricked {f} " for f in b.get("bricked", []))
                + (f"--big-value2 {b['value2']:.4g} " if b.get("value2") is not None else "")
                + f"--runs {b.get('runs', '?')}` ({b.get('code', '?')}). "
                "Each line is a whole process (median of the runs, interleaved, after one warm-up run each); "
                "ours reads the `.tetc`, the cascades VTK's `.vtu`; peak RSS from the kernel's accounting of the "
                "child. Ratios: ours / that line. The bare lines only import, for what each peak holds beyond "
                "its interpreter.", "",
                table(["pipeline", "wall s (median)", "samples", "CPU s (median)", "peak RSS MB", "time ratio",
                       "memory ratio"] + _cascade_columns(b), b["rows"]), ""]
        out += _bricked_report(b)
        if b.get("load"):
            out += [f"Load average (1 min) {b['load'][0]:.1f} at the start and {b['load'][1]:.1f} at the end, on 2 "
                    "cores: wall times on a busy machine favour the single-threaded cascades (ours keeps three "
                    "threads fed), so compare the CPU column too.", ""]
        if st:
            out += [f"Our run: {st['faces_extracted']:,} faces extracted, {st['faces']:,} written, at most "
                    f"{st['peak_faces']:,} held; locked band at most {st['peak_locked']:,} vertices "
                    f"({100 * st['peak_locked'] / max(st['faces_extracted'], 1):.2f} % of the faces extracted); "
                    f"decode {st['decode_s']:.1f} s, extraction {st['extract_s']:.1f} s, QEM {st['qem_s']:.1f} s.",
                    _timeline_line(st), "",
                    "![memory over time](../figures/iso_memory_over_time.png)", ""]
        if b.get("stages"):
            out += _stages_report(b)
    return "\n".join(out)


def _cascade_columns(b) -> list:
    return (["ours / VTK quadric cascade (time / memory)", "ours / meshoptimizer cascade (time / memory)"]
            if b.get("bricked") else [])


_BRICK_COLUMNS = ["file", "MB", "bricks decoded", "tets decoded", "peak bricks decoding", "peak bricks held",
                  "peak locked", "locked at end", "faces extracted", "faces", "decode wait s", "peak RSS MB"]


def _bricked_report(b) -> list:
    """The bricked lines' own figures, and the second isovalue's table."""
    if not b.get("bricked"):
        return []
    one = ["ours (tetc isosurface), one stream", f"{b.get('size_mb', 0):.1f}", "1 of 1", f"{b['tets']:,}", "", "",
           f"{(b.get('stats') or {}).get('peak_locked', 0):,}", f"{(b.get('stats') or {}).get('locked_at_end', 0):,}",
           f"{(b.get('stats') or {}).get('faces_extracted', 0):,}", f"{(b.get('stats') or {}).get('faces', 0):,}",
           f"{(b.get('stats') or {}).get('decode_s', 0):.2f}", f"{(b.get('stats') or {}).get('peak_rss_mb', 0):.0f}"]
    out = [f"Bricked files of the same mesh (`tetc compress --bricks K --mesh-only`), isovalue {b['value']:.4g}: "
           "only the bricks whose stored scalar range holds the isovalue are decoded, on 2 threads; the "
           "last columns of the table above are a bricked line's time and memory over the two cascades'. "
           "Stats of the last run of each:", "", table(_BRICK_COLUMNS, [one] + b["bricks"]), ""]
    if b.get("rows2"):
        out += [f"Second isovalue {b['value2']:.4g} (fewer bricks hold it), the same runs:", "",
                table(["pipeline", "wall s (median)", "samples", "CPU s (median)", "peak RSS MB", "time ratio",
                       "memory ratio"] + _cascade_columns(b), b["rows2"]), "",
                table(_BRICK_COLUMNS, b["bricks2"]), ""]
    return out


def _timeline_line(st) -> str:
    """How far extraction trails decoding, from the per-batch records (when both times are there)."""
    band = st.get("band") or []
    if not band or "decoded_s" not in band[0]:
        return ""
    lag = sorted(b["t_s"] - b["decoded_s"] for b in band)
    return (f"Timeline: a batch is extracted a median {lag[len(lag) // 2]:.2f} s after it is decoded (at most "
            f"{lag[-1]:.2f} s, behind a round of collapses); the last one {band[-1]['t_s'] - band[-1]['decoded_s']:.2f} s "
            f"after, and the final round, once the stream is over, takes the last {st['total_s'] - band[-1]['t_s']:.2f} s "
            f"of the verb's {st['total_s']:.2f} s.")


def _stages_report(b) -> list:
    """Where our peak goes, from :func:`_memory_stages_child`: the floor every run pays (imports,
    numba's runtime, compiled code), the decoders' and the extractor's arrays at the end of the
    stream, what a round of collapses adds, and the rest."""
    st = b["stages"]
    if "floor" not in st:  # results saved by an older version of this script
        return []
    end = st["at_end"]
    geo, conn, ext = (sum(end[k].values()) for k in ("geometry", "connectivity", "extraction"))
    rnd = max(st["round_adds"][:-1] or [0.0])  # mid-stream rounds (the final one runs after the decoders are gone)
    rest = st["peak"] - st["floor"] - geo - conn - ext - rnd

    def parts(d):
        return ", ".join(f"{k} {v:.0f}" for k, v in d.items())

    scipy = " (numba's first kernel call imports scipy.linalg, with its own OpenBLAS, to look for a BLAS)" \
        if st.get("scipy_linalg_by_numba") else ""
    rows = [["interpreter and numpy", f"{st['numpy']:.0f}"],
            ["numba import (mostly the pages of libllvmlite.so its loading touches)", f"{st['numba'] - st['numpy']:.0f}"],
            ["our modules, meshio, click", f"{st['modules'] - st['numba']:.0f}"],
            ["numba's runtime and our kernels' compiled code, loaded from the cache on the 90-tet file shipped "
             "with the package, less the LLVM code pages then handed back (as `tetc isosurface` does)" + scipy,
             f"{st['floor'] - st['modules']:.0f}"],
            ["= floor: what the process holds before the file is opened", f"{st['floor']:.0f}"],
            ["geometry decoder: " + parts(end["geometry"]), f"{geo:.0f}"],
            ["connectivity decoder: " + parts(end["connectivity"]), f"{conn:.0f}"],
            ["extraction state: " + parts(end["extraction"]), f"{ext:.0f}"],
            ["a round of collapses mid-stream (heap, face lists; the largest rise while one runs)", f"{rnd:.0f}"],
            ["the rest (batches in flight and queued, allocator slack, Python objects)", f"{rest:.0f}"],
            ["= our peak in this run", f"{st['peak']:.0f}"]]
    when = ("during a round of collapses or within a second after it (its memory goes back at the next trim "
            "of the heap)") if st.get("peak_in_round") else "outside the rounds"
    return [f"Where our peak goes (MB, measured in one process: RSS after each import and after loading the "
            f"kernels, then the arrays held at the last tets of the real run; the peak came at "
            f"{st['t_peak']:.1f} s of {st['total_s']:.1f} s, {when}, before the end of the stream frees the "
            f"decoders):", "", table(["part", "MB"], rows), ""]


if __name__ == "__main__":
    sys.exit(main())
