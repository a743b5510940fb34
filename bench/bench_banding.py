"""Wood-grain banding of the default sample step: the former rule (half the median boundary edge)
against today's (that, and at most 1/512 of the bounding-box diagonal), on real files.

Banding is measured as the RMSE (0-255, over the pixels either image covers) of a render at the
default step against one at a 16x finer step (the converged image): sampling error, of which the
wood-grain rings are the visible part. Each file with its own preset and with the ``default``
transfer function (the most opaque one, where bands show most). Writes
``bench/sections/banding.md`` and ``bench/figures/banding_<name>.png`` (former | today | 16x finer).

    python bench/bench_banding.py [--quick]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from common import FIGURES, SAMPLE_FILES, code_state, table, write_section

SIZE = 256
VIEW = dict(azimuth=30, elevation=20)
GMSH = "block-50k"


def former_step(points, boundary_faces) -> float:
    """The rule before the diagonal bound: half the median boundary edge."""
    p = np.asarray(points, np.float64)
    f = np.asarray(boundary_faces)
    e = np.linalg.norm(np.concatenate([p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 1]], p[f[:, 0]] - p[f[:, 2]]]),
                       axis=1)
    return float(np.median(e[e > 0])) * 0.5


def meshes(quick: bool):
    from gatun_py.mesh import read_mesh

    for name in ("bluntfin", "combustion", "post", "fire"):
        path, kw, tf = SAMPLE_FILES[name]
        yield name, read_mesh(path, **kw)[0], tf
    if quick:
        return
    try:
        from gmsh_meshes import mesh_path

        yield f"gmsh {GMSH}", read_mesh(mesh_path(GMSH))[0], "default"
    except Exception as e:  # gmsh missing: the table says so
        print(f"skipping the gmsh mesh: {e}", file=sys.stderr)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.astype(np.float64), b.astype(np.float64)
    mask = (a.sum(axis=2) > 0) | (b.sum(axis=2) > 0)
    return float(np.sqrt(((a - b) ** 2).sum(axis=2)[mask].mean() / 3)) if mask.any() else 0.0


def main(argv) -> int:
    import gatun_py
    from gatun_py.mesh import default_step
    from gatun_py.raycast.image import write_image

    quick = "--quick" in argv
    size = 128 if quick else SIZE
    rows = []
    figures = []
    for name, mesh, preset in meshes(quick):
        bnd = mesh.boundary_faces()
        old, new = former_step(mesh.points, bnd), default_step(mesh.points, bnd)
        lo, hi = mesh.bbox
        diag = float(np.linalg.norm(np.asarray(hi, np.float64) - np.asarray(lo, np.float64)))
        ref_step = min(old, new) / 16
        for tf in dict.fromkeys((preset, "default")):
            imgs, secs = {}, {}
            for label, step in (("ref", ref_step), ("old", old), ("new", new)):
                t0 = time.perf_counter()
                imgs[label] = gatun_py.render(mesh, size=size, tf=tf, step=step, **VIEW).rgb
                secs[label] = time.perf_counter() - t0
            rows.append([name, f"{mesh.n_tets:,}", tf, f"{diag / old:.0f}", f"{diag / new:.0f}",
                         rmse(imgs["old"], imgs["ref"]), rmse(imgs["new"], imgs["ref"]),
                         secs["old"], secs["new"]])
            print(rows[-1], flush=True)
            if tf == "default" and not quick:
                FIGURES.mkdir(parents=True, exist_ok=True)
                fig = FIGURES / f"banding_{name.split()[-1]}.png"
                write_image(fig, np.concatenate([imgs["old"], imgs["new"], imgs["ref"]], axis=1), force=True)
                figures.append((name, fig.name))
    text = [
        "## Default sample step: banding\n",
        f"`python bench/bench_banding.py` ({code_state()}): {size}² renders at azimuth 30, elevation 20. "
        "*Former*: half the median boundary edge; *today*: that, and at most 1/512 of the bounding-box "
        "diagonal (`gatun_py.mesh.default_step`). Banding: RMSE (0-255, covered pixels) against a 16x finer "
        "step; the wood-grain rings are the visible part of it. Render times are one run each on the "
        "machine as it was (ratios, not absolutes).\n",
        table(["mesh", "tets", "tf", "samples/diagonal former", "today", "RMSE former", "RMSE today",
               "render s former", "today"], rows),
        "",
    ]
    for name, fig in figures:
        text.append(f"![{name}: former step | today's | 16x finer](figures/{fig})")
    text.append("\nEach figure: the former default step, today's, and a 16x finer step (the `default` "
                "transfer function).")
    write_section("banding", "\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
