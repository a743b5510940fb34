"""Lossless benchmark (format 2): float64 coordinates and every point array, bit for bit, and their size.

Run: ``python bench/bench_lossless.py``  →  ``bench/sections/lossless.md``

Data:

* **Blunt-fin, float64**: the PLOT3D grid's coordinates as float64, and the Q variables in float64:
  density and energy (stored as float32 in the Q file, so exact float32 values), pressure (computed
  in float64) and the velocity vector (momentum / density, three float64 components).
* **gmsh flange, float64 nodes**: a ~200k-tet graded Delaunay mesh (``bench/gmsh_meshes.py``)
  with gmsh's own float64 node coordinates, an analytic scalar in float64 and float32, and its
  float64 gradient as a vector array.

Targets: the whole ``.tetc`` (mesh only, no forest) <= 0.5 x ``xz -9`` of the raw arrays
(coordinates, tets as int32, every point array, in file order); the coordinates' share of the file
(geometry x/y/z streams + ``points64``) <= 0.9 x the best of fpzip, pcodec and ``xz -9`` on the
same coordinate array. The adversarial-suite figures come from ``tests/test_hostile_files.py``.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import json  # noqa: E402
import lzma  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from common import ROOT, WORK, code_state, run_tetc, table, write_section  # noqa: E402

sys.path.insert(0, str(ROOT / "tests"))

CMD = "python bench/bench_lossless.py"


def xz(data: bytes) -> int:
    return len(lzma.compress(data, preset=9))


def fpzip_size(a: np.ndarray):
    try:
        import fpzip
    except ImportError:
        return None
    return len(fpzip.compress(np.array(a, order="C"), precision=0))  # it needs a writable buffer


def pcodec_size(a: np.ndarray):
    """pcodec on each column (it codes 1-D numeric sequences)."""
    try:
        import pcodec
        from pcodec import standalone
    except ImportError:
        return None
    cols = a.reshape(len(a), -1)
    return sum(len(standalone.simple_compress(np.ascontiguousarray(cols[:, c]), pcodec.ChunkConfig()))
               for c in range(cols.shape[1]))


# -- data ---------------------------------------------------------------------------------------

def bluntfin64():
    from gatun_py.mesh import TetMesh, plot3d, read_mesh
    from samples import SAMPLES

    path, kw, _ = SAMPLES["bluntfin"]
    mesh32, _ = read_mesh(path, **kw)
    grid = plot3d.read_xyz(path)
    q = plot3d.find_q_file(path)
    pd = {name: plot3d.read_q(q, grid.dims, name, dtype=np.float64) for name in ("density", "pressure", "energy")}
    pd["velocity"] = np.stack([plot3d.read_q(q, grid.dims, f"velocity-{c}", dtype=np.float64) for c in "xyz"], axis=1)
    return TetMesh(grid.xyz.astype(np.float64), None, mesh32.tets, "density", point_data=pd)


def flange64():
    """The flange at ~200k tets with gmsh's float64 nodes (cached as .npz under bench/out)."""
    from gatun_py.mesh import TetMesh

    cache = WORK / "gmsh" / "flange-200k-f64.npz"
    if not cache.exists():
        import gmsh  # bench extra

        import gmsh_meshes as G

        gmsh.initialize(["-noenv"], readConfigFiles=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            h0 = 0.1
            _, t0 = G._mesh_shape(gmsh, "flange", h0, 1)
            h = h0 * (t0.shape[0] / G._CALIBRATION_TETS) ** (1 / 3)
            _, t1 = G._mesh_shape(gmsh, "flange", h, 1)
            h = h * (t1.shape[0] / 200_000) ** (1 / 3)
            pts, tets = G._mesh_shape(gmsh, "flange", h, 1)
        finally:
            gmsh.finalize()
        tets = G._orient(pts, tets)
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cache, points=pts, tets=tets)
    z = np.load(cache)
    pts, tets = z["points"], z["tets"].astype(np.int32)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    u = (pts - lo) / (hi - lo)
    f = np.sin(3 * np.pi * u[:, 0]) * np.cos(2 * np.pi * u[:, 1]) + 0.5 * np.sin(2 * np.pi * (u[:, 0] + u[:, 2]))
    grad = np.stack([3 * np.pi * np.cos(3 * np.pi * u[:, 0]) * np.cos(2 * np.pi * u[:, 1])
                     + np.pi * np.cos(2 * np.pi * (u[:, 0] + u[:, 2])),
                     -2 * np.pi * np.sin(3 * np.pi * u[:, 0]) * np.sin(2 * np.pi * u[:, 1]),
                     np.pi * np.cos(2 * np.pi * (u[:, 0] + u[:, 2]))], axis=1)
    pd = {"f": f, "f32": f.astype(np.float32), "temperature": 300.0 + 40.0 * u[:, 2] ** 2, "grad_f": grad}
    return TetMesh(pts, None, tets, "f", point_data=pd)


# -- measurements -------------------------------------------------------------------------------

def canonical(mesh):
    """Vertex order independent of the file: sort by the exact bits of the coordinates and of every
    array; fully identical vertices share a rank, so tets compare as sets of rank tuples."""
    cols = [mesh.points.reshape(mesh.n_points, -1)] + [a.reshape(mesh.n_points, -1) for a in mesh.point_data.values()]
    key = np.concatenate([np.ascontiguousarray(c).view(np.uint8).reshape(mesh.n_points, -1) for c in cols], axis=1)
    order = np.lexsort(key.T[::-1])
    k = key[order]
    new = np.ones(len(order), bool)
    new[1:] = (k[1:] != k[:-1]).any(axis=1)
    rank = np.empty(len(order), np.int64)
    rank[order] = np.cumsum(new) - 1
    tets = np.sort(rank[mesh.tets], axis=1)
    return order, tets[np.lexsort(tets.T[::-1])]


def round_trip(mesh, data: bytes) -> tuple[bool, float]:
    from gatun_py.codec import TetcReader

    t = time.perf_counter()
    back = TetcReader(data).decode_mesh(0)
    seconds = time.perf_counter() - t
    oa, ta = canonical(mesh)
    ob, tb = canonical(back)
    ok = (back.points.dtype == mesh.points.dtype and mesh.points[oa].tobytes() == back.points[ob].tobytes()
          and np.array_equal(ta, tb) and list(back.point_data) == list(mesh.point_data))
    for name, a in mesh.point_data.items():
        b = back.point_data[name]
        ok = ok and a.dtype == b.dtype and a.shape == b.shape and a[oa].tobytes() == b[ob].tobytes()
    return bool(ok), seconds


def measure(name: str, mesh) -> dict:
    from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
    from gatun_py.codec.geometry import geometry_stream_sizes

    t = time.perf_counter()
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh)])
    enc = time.perf_counter() - t
    exact, dec = round_trip(mesh, data)
    r = TetcReader(data)
    c = r.container
    sizes = {s: c.section_size(s) for s in c.section_names()}
    geo = geometry_stream_sizes(r.read_section("L0/geometry"))
    coords_ours = geo["x"] + geo["y"] + geo["z"] + sizes.get("L0/points64", 0)
    raw = [mesh.points.tobytes(), mesh.tets.astype(np.int32).tobytes()] + [a.tobytes() for a in mesh.point_data.values()]
    xz_raw = xz(b"".join(raw))
    xz_coords = xz(mesh.points.tobytes())
    fp, pc = fpzip_size(mesh.points), pcodec_size(mesh.points)
    peers = {k: v for k, v in (("xz -9", xz_coords), ("fpzip", fp), ("pcodec", pc)) if v is not None}
    best_name = min(peers, key=peers.get)
    arrays = []
    for j, (aname, a) in enumerate(mesh.point_data.items()):
        ours = sizes.get(f"L0/array/{j}", geo["density"] if aname == mesh.scalar_name else 0)
        arrays.append({"name": aname, "dtype": str(a.dtype), "components": 1 if a.ndim == 1 else a.shape[1],
                       "ours": ours, "xz": xz(a.tobytes()), "fpzip": fpzip_size(a) if a.dtype.kind == "f" else None,
                       "pcodec": pcodec_size(a)})
    return {"name": name, "points": mesh.n_points, "tets": mesh.n_tets, "exact": exact, "file": len(data),
            "xz_raw": xz_raw, "raw": sum(map(len, raw)), "coords_ours": coords_ours, "coords_peers": peers,
            "coords_best": best_name, "sections": sizes, "arrays": arrays, "encode_s": enc, "decode_s": dec}


def hostile_figures() -> dict | None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "stats.json"
        env = dict(os.environ, TETC_HOSTILE_STATS=str(out))
        t = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_hostile_files.py"],
                           cwd=ROOT, env=env, capture_output=True, text=True)
        stats = json.loads(out.read_text()) if out.exists() else None
    if stats is not None:
        stats["pytest"] = p.stdout.strip().splitlines()[-1] if p.stdout.strip() else f"exit {p.returncode}"
        stats["wall_s"] = time.perf_counter() - t
    return stats


def _cli(args, cwd) -> tuple[int, str, float, float]:
    """(exit code, last line it printed, seconds, peak RSS MB) of one ``tetc`` run."""
    code, lines, seconds, rss = run_tetc(args, cwd)
    return code, lines[-1] if lines else "", seconds, rss


def issue_cases() -> list:
    """The issue's cases this branch owns, run through the CLI (each in its own process)."""
    import meshio

    from gatun_py.codec import LevelPayload, encode_tetc
    from gatun_py.codec.container import build_container, split_container
    from gatun_py.mesh import TetMesh
    from samples import SAMPLES

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # 1. a float64 .vtu with a float64 scalar (0.1) and more arrays: everything back bit for bit
        pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float64) * 0.1
        tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
        m = TetMesh(pts, None, tets, "p", point_data={"p": np.full(5, 0.1), "u": np.arange(15.0).reshape(5, 3) / 7,
                                                     "id": np.arange(5, dtype=np.int64)})
        from gatun_py.mesh.validate import validate_tets
        m = validate_tets(m.points, None, m.tets, scalar_name="p", point_data=m.point_data)[0]
        meshio.write(tmp / "f64.vtu", meshio.Mesh(m.points, [("tetra", m.tets)], point_data=dict(m.point_data)))
        code, msg, sec, _ = _cli(["compress", "f64.vtu", "--scalar", "p", "-o", "f64.tetc", "--mesh-only"], tmp)
        code2, _, _, _ = _cli(["decompress", "f64.tetc", "-o", "back.vtu"], tmp)
        back = meshio.read(tmp / "back.vtu")
        exact = (back.points.dtype == np.float64 and float(back.point_data["p"][0]) == 0.1
                 and back.point_data["id"].dtype == np.int64 and back.point_data["u"].shape == (5, 3))
        rows.append(["float64 .vtu, 0.1 and 3 arrays", "tetc compress f64.vtu --scalar p -o f64.tetc --mesh-only; "
                     "tetc decompress f64.tetc -o back.vtu", f"{code}, {code2}",
                     f"0.1 -> {float(back.point_data['p'][0])!r}, every array and dtype back: {exact}"])
        # 2. cell data: refused with both ways out
        meshio.write(tmp / "cells.vtu", meshio.Mesh(m.points, [("tetra", m.tets)], point_data={"p": m.point_data["p"]},
                                                    cell_data={"mat": [np.array([1, 2])]}))
        code, msg, _, _ = _cli(["compress", "cells.vtu", "-o", "c.tetc", "--mesh-only"], tmp)
        rows.append(["cell data", "tetc compress cells.vtu -o c.tetc --mesh-only", code, msg])
        # 3. the forest bomb: a level claiming 2^29 - 1 vertices behind a valid CRC
        path, kw, _ = SAMPLES["post"]
        code, msg, _, _ = _cli(["compress", path, "-o", "post.tetc", "--levels", "2"], tmp)
        meta, sections = split_container(tmp / "post.tetc")
        for lv in meta["levels"]:
            lv["points"] = 2**29 - 1
        meta["points"] = 2**29 - 1
        (tmp / "bomb.tetc").write_bytes(build_container(meta, sections))
        _, _, base_sec, base_rss = _cli(["info", "post.tetc"], tmp)  # the interpreter and imports alone
        code, msg, sec, rss = _cli(["render", "bomb.tetc", "--ratio", "0.5", "-o", "bomb.png", "--size", "64"], tmp)
        msg += f"; `tetc info` on the valid file: {base_sec:.2f} s, {base_rss:.0f} MB"
        rows.append(["forest bomb (level points = 2^29-1, valid CRC)", "tetc render bomb.tetc --ratio 0.5 -o bomb.png",
                     code, f"{msg} ({sec:.2f} s for the whole process, peak RSS {rss:.0f} MB)"])
        # 4. the encoder on a mesh with an out-of-range id and with -1
        for bad in (5, -1):
            t = TetMesh(m.points, None, np.array([[0, 1, 2, 3], [1, 2, 3, bad]]), "p", point_data=m.point_data)
            try:
                encode_tetc([LevelPayload(0, 0.0, 0, t)])
                outcome = "accepted (BUG)"
            except Exception as e:  # noqa: BLE001 - the row reports whatever happens
                outcome = f"{type(e).__name__}: {e}"
            rows.append([f"encoder, tet id {bad}", "gatun_py.codec.encode_tetc(...)", "-", outcome])
    return rows


def main() -> int:
    results = [measure("Blunt-fin float64 (PLOT3D Q in float64)", bluntfin64()),
               measure("gmsh flange float64 nodes", flange64())]
    for r in results:
        print(json.dumps({k: v for k, v in r.items() if k not in ("sections", "arrays")}))
    hostile = hostile_figures() if "--no-hostile" not in sys.argv else None
    cases = issue_cases()
    rows = []
    for r in results:
        best = r["coords_peers"][r["coords_best"]]
        rows.append([r["name"], f"{r['points']:,} / {r['tets']:,}", "yes" if r["exact"] else "NO",
                     r["file"], r["xz_raw"], f"{r['file'] / r['xz_raw']:.3f}",
                     r["coords_ours"], ", ".join(f"{k} {v:,}" for k, v in r["coords_peers"].items()),
                     f"{r['coords_ours'] / best:.3f}", f"{r['encode_s']:.2f} / {r['decode_s']:.3f}"])
    arr_rows = []
    for r in results:
        for a in r["arrays"]:
            arr_rows.append([r["name"].split(" ")[0], a["name"], f"{a['dtype']} x{a['components']}", a["ours"], a["xz"],
                             a["fpzip"] if a["fpzip"] is not None else "-",
                             a["pcodec"] if a["pcodec"] is not None else "-"])
    text = f"""
## Lossless: float64 and every point array (format 2)

`{CMD}` ({code_state()}). Whole files are mesh only (no forest, no levels). Raw arrays = coordinates,
tets as int32 and every point array in their dtypes, in file order; the coordinate peers get the same
(n, 3) array in file order (pcodec column by column). "Coordinates ours" = the geometry section's x, y, z
streams (float32) + `points64` (the exact float64 residual; absent when every coordinate is a float32).

Targets: file <= 0.5 x xz -9 of the raw arrays; coordinates <= 0.9 x the best peer; every array bit-exact.

{table(["mesh", "points / tets", "bit-exact (every array, dtype)", "file B", "xz -9 raw B", "file / xz",
        "coordinates ours B", "coordinate peers B", "ours / best peer", "encode / decode s"], rows)}

Per array (bytes; the float32 default scalar's share is the geometry section's density stream):

{table(["mesh", "array", "dtype", "ours", "xz -9", "fpzip", "pcodec"], arr_rows)}

Where the targets are missed and why: the file-size target (0.5 x xz) fails on both meshes because the
arrays computed in float64 (pressure, velocity, the gradient) carry 45-55 bits of entropy per value that
no coder removes: on them every peer lands within a few per cent of us (the table above). Blunt-fin's
coordinates are float32 grid values (no `points64`); the geometry coder works in decode order, where xz
and pcodec exploit the grid's file order (876/824/32 distinct values) at half our cost. The flange's
coordinates miss 0.9 x pcodec by 0.2 %: `points64` is already below the 29 bits per coordinate that
uniform residuals against the float32 rounding would cost; the rest is the float32 geometry coder.
"""
    text += f"""
### The issue's cases (this branch's part)

{table(["case", "command", "exit code", "message / result"], cases)}
"""
    if hostile:
        text += f"""
### Adversarial files

`pytest tests/test_hostile_files.py` (hypothesis over bit flips, truncations, metadata values and section
bytes behind valid CRCs, crafted array headers, the forest bomb, an LZMA bomb): each case in a worker under
RLIMIT_AS = its warmed-up size + 300 MB and a 2 s alarm; the whole read API per case.

| cases | rejected (typed error) | decoded fine | crashes / hangs / tracebacks / MemoryError | max time per case | peak RSS above the warmed-up worker's {hostile['base_rss'] / 2**20:.0f} MB |
|---|---|---|---|---|---|
| {hostile['cases']} | {hostile.get('rejected', 0)} | {hostile.get('ok', 0)} | {sum(hostile.get(k, 0) for k in ('crash', 'hang', 'traceback', 'memory', 'timeout'))} | {hostile['max_seconds']:.3f} s | {hostile['max_rss_above_base_mb']} MB |

pytest: {hostile['pytest']}
"""
    write_section("lossless", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
