"""Unstructured test meshes: CAD-like shapes meshed by gmsh with graded tets and a smooth scalar.

The samples are structured or curvilinear grids; real unstructured meshes (graded Delaunay, no
grid order to exploit) behave differently in every stage, so the benchmarks and some tests use
these too. Three shapes, each built with gmsh's OpenCASCADE kernel and meshed with the parallel
HXT Delaunay mesher under an analytic size field (finest near holes / the inner wall, up to about
8x coarser away from them):

``block``   a block with three through-holes of different radii;
``bend``    a thick-walled 90-degree pipe bend with straight ends;
``flange``  a flange: a disk with a hub, a bore and eight bolt holes.

The scalar is a smooth analytic field of the normalised coordinates (waves plus a Gaussian bump),
stored as float32 point data ``density``. Sizes: ``50k`` (for tests), ``200k``, ``1m``, ``2m``,
``5m``, ``10m`` tets nominal: the size is calibrated on two coarse meshes (tets ~ h^-3), and the
counts come out 5 to 20 % under (flange: 47k, 172k, 810k, 1.60 M, 3.93 M, 7.80 M).

``mesh_path("flange-1m")`` returns the cached ``.vtu`` under ``bench/out/gmsh/`` (gitignored),
generating it first when it is missing (needs the ``gmsh`` package, in the ``bench`` and ``test``
extras). ``python bench/gmsh_meshes.py block-50k flange-1m ...`` builds them ahead of time.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CACHE = Path(__file__).resolve().parent / "out" / "gmsh"
SHAPES = ("block", "bend", "flange")
SIZES = {"50k": 50_000, "200k": 200_000, "1m": 1_000_000, "2m": 2_000_000, "5m": 5_000_000, "10m": 10_000_000,
         "12m": 12_000_000}  # 12m: the base of the 74 M-tet partitioned data (bench/pieces_data.py)
# Tet count of the calibration mesh: large enough that the count scales as h^-3 from there.
_CALIBRATION_TETS = 30_000


def names() -> list[str]:
    """Every mesh name ``mesh_path`` accepts (``shape-size``)."""
    return [f"{s}-{z}" for s in SHAPES for z in SIZES]


def _parse(name: str) -> tuple[str, int]:
    shape, _, size = name.partition("-")
    if shape not in SHAPES or size not in SIZES:
        raise ValueError(f"unknown gmsh mesh {name!r}: expected one of {', '.join(names())}")
    return shape, SIZES[size]


# -- geometry: each builder adds one volume and returns the size field as a gmsh MathEval
# expression in x, y, z with H standing for the finest size ------------------------------------
def _block(occ):
    box = occ.addBox(0, 0, 0, 4, 2, 1)
    holes = [occ.addCylinder(x, y, -0.1, 0, 0, 1.2, r) for x, y, r in ((0.8, 1.0, 0.35), (2.0, 0.9, 0.2),
                                                                     (3.1, 1.1, 0.45))]
    occ.cut([(3, box)], [(3, h) for h in holes])
    # finest at the rims of the holes, growing with the distance to the nearest hole axis
    d = "Min(Min(Sqrt((x-0.8)^2+(y-1.0)^2)-0.35, Sqrt((x-2.0)^2+(y-0.9)^2)-0.2), Sqrt((x-3.1)^2+(y-1.1)^2)-0.45)"
    return f"H*(1+7*Min(1,Max(0,{d})/0.8))"


def _bend(occ):
    # a quarter torus (bend radius 3, pipe radius 1, bore 0.6) and two straight legs of length 2
    outer = occ.addTorus(0, 0, 0, 3, 1, angle=math.pi / 2)
    inner = occ.addTorus(0, 0, 0, 3, 0.6, angle=math.pi / 2)
    leg1 = occ.addCylinder(3, 0, 0, 0, -2, 0, 1)
    leg1i = occ.addCylinder(3, 0.01, 0, 0, -2.02, 0, 0.6)
    leg2 = occ.addCylinder(0, 3, 0, -2, 0, 0, 1)
    leg2i = occ.addCylinder(0.01, 3, 0, -2.02, 0, 0, 0.6)
    solid, _ = occ.fuse([(3, outer)], [(3, leg1), (3, leg2)])
    bore, _ = occ.fuse([(3, inner)], [(3, leg1i), (3, leg2i)])
    occ.cut(solid, bore)
    # finest at the inner wall of the bend, coarser outward and along the legs
    r = "Sqrt((Sqrt(x^2+y^2)-3)^2+z^2)"
    leg = "Max(0,Max(-y,-x))"
    return f"H*(1+5*Min(1,Max(0,{r}-0.6)/0.4)+2*Min(1,{leg}/2))"


def _flange(occ):
    disk = occ.addCylinder(0, 0, 0, 0, 0, 0.4, 3)
    hub = occ.addCylinder(0, 0, 0.4, 0, 0, 1.2, 1.5)
    body, _ = occ.fuse([(3, disk)], [(3, hub)])
    cuts = [(3, occ.addCylinder(0, 0, -0.1, 0, 0, 1.8, 0.9))]
    for k in range(8):
        ang = 2 * math.pi * k / 8
        cuts.append((3, occ.addCylinder(2.3 * math.cos(ang), 2.3 * math.sin(ang), -0.1, 0, 0, 0.6, 0.25)))
    occ.cut(body, cuts)
    # finest at the bore and on the bolt circle
    r = "Sqrt(x^2+y^2)"
    return f"H*(1+7*Min(1,Min(Max(0,{r}-0.9)/1.2,Abs({r}-2.3)/0.6)))"


_BUILDERS = {"block": _block, "bend": _bend, "flange": _flange}


def scalar_field(points: np.ndarray) -> np.ndarray:
    """The smooth analytic scalar at ``points`` (n, 3): waves and a bump in normalised coordinates."""
    p = np.asarray(points, np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    u = (p - lo) / np.where(hi > lo, hi - lo, 1.0)
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    f = (np.sin(3.0 * np.pi * x) * np.cos(2.0 * np.pi * y) + 0.5 * np.sin(2.0 * np.pi * (x + z))
         + 1.5 * np.exp(-((x - 0.6) ** 2 + (y - 0.4) ** 2 + (z - 0.5) ** 2) / 0.02))
    return f.astype(np.float32)


def _mesh_shape(gmsh, shape: str, h: float, threads: int):
    """Mesh ``shape`` at finest size h: (points float64 (n, 3), tets int64 (m, 4))."""
    gmsh.clear()
    gmsh.model.add(shape)
    occ = gmsh.model.occ
    expr = _BUILDERS[shape](occ)
    occ.synchronize()
    field = gmsh.model.mesh.field
    f = field.add("MathEval")
    field.setString(f, "F", expr.replace("H", repr(h)))
    field.setAsBackgroundMesh(f)
    for opt, val in (("Mesh.MeshSizeExtendFromBoundary", 0), ("Mesh.MeshSizeFromPoints", 0),
                     ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.Algorithm", 6), ("Mesh.Algorithm3D", 10),
                     ("General.NumThreads", threads), ("Mesh.Optimize", 1)):
        gmsh.option.setNumber(opt, val)
    gmsh.model.mesh.generate(3)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    types, _, conn = gmsh.model.mesh.getElements(3)
    tets = np.concatenate([np.asarray(c, np.int64).reshape(-1, 4) for t, c in zip(types, conn) if t == 4])
    # node tags -> dense ids over the nodes the tets use (drops nodes only the surfaces carry)
    tags = np.asarray(tags, np.int64)
    coords = np.asarray(coords).reshape(-1, 3)
    lut = np.full(tags.max() + 1, -1, np.int64)
    lut[tags] = np.arange(tags.size)
    tets = lut[tets]
    used = np.unique(tets)
    remap = np.full(tags.size, -1, np.int64)
    remap[used] = np.arange(used.size)
    return coords[used], remap[tets]


def _orient(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Tets made positively oriented (swap two corners of the negative ones)."""
    p = points[tets]
    v = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    neg = v < 0
    tets = tets.copy()
    tets[neg, 2], tets[neg, 3] = tets[neg, 3], tets[neg, 2].copy()
    return tets


def generate(name: str, out: Path, *, threads: int | None = None, log=None) -> Path:
    """Generate mesh ``name`` (``shape-size``) into the ``.vtu`` file ``out``."""
    import gmsh  # optional dependency (bench/test extras): imported only when a mesh is built
    import meshio

    shape, target = _parse(name)
    # one thread by default: HXT's result depends on the thread count, and the cache should not
    threads = threads or 1
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        # calibrate: tets ~ C / h^3 (the size field is proportional to h everywhere)
        h0 = 0.1
        _, t0 = _mesh_shape(gmsh, shape, h0, threads)
        h = h0 * (t0.shape[0] / _CALIBRATION_TETS) ** (1 / 3)
        _, t1 = _mesh_shape(gmsh, shape, h, threads)
        h = h * (t1.shape[0] / target) ** (1 / 3)
        t = time.perf_counter()
        pts, tets = _mesh_shape(gmsh, shape, h, threads)
        if log:
            log(f"{name}: {tets.shape[0]:,} tets, {pts.shape[0]:,} points in {time.perf_counter() - t:.1f} s")
    finally:
        gmsh.finalize()
    tets = _orient(pts, tets)
    mesh = meshio.Mesh(pts.astype(np.float32), [("tetra", tets.astype(np.int64))],
                       point_data={"density": scalar_field(pts)})
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".vtu", dir=out.parent)
    os.close(fd)
    try:
        meshio.write(tmp, mesh, binary=True, compression=None)
        os.chmod(tmp, 0o644)  # mkstemp's 0600 is not what a cache file should be
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out


def mesh_path(name: str, *, log=None) -> Path:
    """Path of the cached ``.vtu`` of gmsh mesh ``name`` (e.g. ``"flange-1m"``), built if missing."""
    _parse(name)
    path = CACHE / f"{name}.vtu"
    if not path.exists():
        generate(name, path, log=log)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"meshes to build (default: every shape at 50k and 1m); any of "
                                             f"{', '.join(names())}")
    ap.add_argument("--force", action="store_true", help="rebuild even when cached")
    args = ap.parse_args(argv)
    todo = args.names or [f"{s}-{z}" for s in SHAPES for z in ("50k", "1m")]
    for name in todo:
        try:
            _parse(name)
        except ValueError as e:
            ap.error(str(e))
        path = CACHE / f"{name}.vtu"
        if args.force and path.exists():
            path.unlink()
        print(mesh_path(name, log=lambda s: print(s, file=sys.stderr)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
