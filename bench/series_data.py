"""Time series from a real solver: transient heat conduction and thermo-elastic deformation.

A block with a cylindrical hole is meshed by gmsh (tets); scikit-fem then runs

* the heat equation ``rho c dT/dt = div(k grad T)`` by implicit Euler: the hole's wall is held at
  a hot temperature switched on at t = 0, the block starts cold, every other wall is insulated;
* the linear elasticity of the thermal strain ``alpha (T - T0) I`` at every step, the block
  clamped at ``z = 0``: the displacement moves the points (the *deforming* series).

Each step gives a point array ``temperature`` (float64), a cell array ``heat_flux`` (the
magnitude of ``-k grad T`` per tet, float64) and, for the deforming case, the moved coordinates.
Every array is solver output in float64: nothing is a formula.

``python bench/series_data.py small`` rewrites ``tests/data/series_heat.npz`` (committed: a few
thousand tets, 40 steps); ``python bench/series_data.py medium large`` caches bigger runs under
``bench/out/series/`` (``series_path(name)`` builds one when it is missing), each as an ``.npz``
and as a ``.pvd`` of zlib ``.vtu`` files (what ParaView users write).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
CACHE = ROOT / "out" / "series"
SMALL = ROOT.parent / "tests" / "data" / "series_heat.npz"
# name -> (finest gmsh size, steps)
SIZES = {"small": (0.12, 40), "medium": (0.045, 60), "large": (0.02, 40), "play": (0.0125, 40)}
# Runs without the thermo-elastic step (a direct solve of the elasticity does not fit a 1 M-tet
# mesh in memory here): their ``moved`` is the rest coordinates at every step.
HEAT_ONLY = {"play"}


def gmsh_block(h: float) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) float64, tets (m, 4) int64) of a 2 x 1 x 1 block with a hole of radius 0.25."""
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("block")
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, 0, 2, 1, 1)
        hole = occ.addCylinder(0.7, 0.5, -0.1, 0, 0, 1.2, 0.25)
        occ.cut([(3, box)], [(3, hole)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 2.5 * h)
        field = gmsh.model.mesh.field
        f = field.add("MathEval")
        field.setString(f, "F", f"{h} * (1 + 3 * Fabs(Sqrt((x - 0.7)^2 + (y - 0.5)^2) - 0.25))")
        field.setAsBackgroundMesh(f)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        points = coords.reshape(-1, 3)
        etypes, _, enodes = gmsh.model.mesh.getElements(3)
        tets = np.asarray(enodes[list(etypes).index(4)], np.int64).reshape(-1, 4)
    finally:
        gmsh.finalize()
    index = np.full(int(tags.max()) + 1, -1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets = index[tets]
    used = np.unique(tets)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    return np.ascontiguousarray(points[used]), remap[tets]


def solve(points: np.ndarray, tets: np.ndarray, n_steps: int, *, dt: float = 0.004, elastic: bool = True) -> dict:
    """Run the heat equation and the thermo-elastic step on the mesh; every array float64.

    Returns a dict: ``points`` (n, 3), ``tets`` (m, 4) as given to the solver (positively
    oriented), ``times`` (s,), ``temperature`` (s, n), ``heat_flux`` (s, m), ``moved`` (s, n, 3).
    ``elastic=False`` skips the thermo-elastic step (``moved`` is then empty) and solves the heat
    equation by conjugate gradients from the previous step (a direct factorisation of a million-tet
    3-D mesh needs more memory than this machine has).
    """
    import scipy.sparse.linalg as sla
    from skfem import Basis, BilinearForm, ElementTetP1, ElementVector, LinearForm, MeshTet, asm
    from skfem.helpers import div, dot, grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    m = MeshTet(points.T.copy(), tets.T.copy())
    basis = Basis(m, ElementTetP1())
    kappa, rho_c = 1.0, 1.0

    @BilinearForm
    def stiffness(u, v, w):
        return kappa * dot(grad(u), grad(v))

    @BilinearForm
    def mass(u, v, w):
        return rho_c * u * v

    K, M = asm(stiffness, basis), asm(mass, basis)
    x = m.p
    r = np.hypot(x[0] - 0.7, x[1] - 0.5)
    hot = np.flatnonzero(r < 0.25 + 1e-6)  # the hole's wall (its nodes lie on the circle)
    T0 = 20.0
    T = np.full(m.p.shape[1], T0)
    A = (M + dt * K).tocsc()
    free = np.setdiff1d(np.arange(len(T)), hot)
    T_hot = 300.0
    Aff = A[free][:, free].tocsc()
    if elastic:
        lu = sla.splu(Aff)
        vbasis = Basis(m, ElementVector(ElementTetP1()))
        # thermo-elasticity: K_e u = f(T), clamped at z = 0
        lam, mu = lame_parameters(200.0, 0.3)
        Ke = asm(linear_elasticity(lam, mu), vbasis)
        alpha = 1.2e-4

        @LinearForm
        def thermal(v, w):
            return (3 * lam + 2 * mu) * alpha * (w["T"] - T0) * div(v)

        clamped = vbasis.get_dofs(lambda p: p[2] < 1e-9).all()
        efree = np.setdiff1d(np.arange(vbasis.N), clamped)
        elu = sla.splu(Ke[efree][:, efree].tocsc())
    else:
        jacobi = sla.LinearOperator(Aff.shape, matvec=lambda v, d=1.0 / Aff.diagonal(): d * v)
    times, temps, fluxes, moved = [], [], [], []
    t = 0.0
    for _ in range(n_steps):
        t += dt
        b = M @ T
        T_new = np.empty_like(T)
        T_new[hot] = T_hot
        rhs = b[free] - A[free][:, hot] @ T_new[hot]
        if elastic:
            T_new[free] = lu.solve(rhs)
        else:
            T_new[free], info = sla.cg(Aff, rhs, x0=T[free], rtol=1e-12, atol=0.0, M=jacobi, maxiter=5000)
            if info != 0:
                raise RuntimeError(f"conjugate gradients did not converge ({info})")
        T = T_new
        # flux magnitude per tet: -k grad T of the P1 field (constant on a tet)
        g = basis.interpolate(T).grad  # (3, m, q)
        flux = kappa * np.sqrt((g.mean(axis=2) ** 2).sum(axis=0))
        times.append(t)
        temps.append(T.copy())
        fluxes.append(flux)
        if elastic:
            f = asm(thermal, vbasis, T=basis.interpolate(T))
            u = np.zeros(vbasis.N)
            u[efree] = elu.solve(f[efree])
            disp = u[vbasis.nodal_dofs].T  # (n, 3)
            moved.append(m.p.T + 10.0 * disp)  # magnified tenfold, as in a deformed-shape plot
    return {"points": np.ascontiguousarray(m.p.T), "tets": np.ascontiguousarray(m.t.T),
            "times": np.array(times), "temperature": np.array(temps), "heat_flux": np.array(fluxes),
            "moved": np.array(moved) if moved else np.zeros((0, len(m.p.T), 3))}


def make(name: str) -> dict:
    h, steps = SIZES[name]
    pts, tets = gmsh_block(h)
    return solve(pts, tets, steps, elastic=name not in HEAT_ONLY)


def write_npz(data: dict, path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as fh:
        np.savez_compressed(fh, **data)
    os.replace(fh.name, path)


def load(path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def write_pvd(data: dict, folder, *, deforming: bool = False, cell_data: bool = True) -> Path:
    """The series as ``folder/run.pvd`` with one zlib ``.vtu`` per step; returns the .pvd path."""
    import meshio

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for k, t in enumerate(data["times"]):
        pts = data["moved"][k] if deforming else data["points"]
        cd = {"heat_flux": [data["heat_flux"][k]]} if cell_data else {}
        m = meshio.Mesh(pts, [("tetra", data["tets"])], point_data={"temperature": data["temperature"][k]},
                        cell_data=cd)
        name = f"step_{k:04d}.vtu"
        meshio.write(folder / name, m, compression="zlib")
        rows.append(f'    <DataSet timestep="{float(t)!r}" part="0" file="{name}"/>')
    pvd = folder / "run.pvd"
    pvd.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                   + "\n".join(rows) + "\n  </Collection>\n</VTKFile>\n")
    return pvd


def series_path(name: str) -> Path:
    """The cached ``.npz`` of a series (``small`` is the committed test file), built when missing."""
    if name == "small":
        if not SMALL.exists():
            write_npz(make("small"), SMALL)
        return SMALL
    path = CACHE / f"{name}.npz"
    if not path.exists():
        write_npz(make(name), path)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="+", choices=sorted(SIZES))
    args = ap.parse_args(argv)
    for name in args.names:
        data = make(name)
        path = SMALL if name == "small" else CACHE / f"{name}.npz"
        write_npz(data, path)
        print(f"{name}: {len(data['points'])} points, {len(data['tets'])} tets, {len(data['times'])} steps "
              f"-> {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
