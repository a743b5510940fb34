"""Partitioned test data: a gmsh mesh cut into k-d pieces as a solver writes them, each refined.

The base mesh (``bench/gmsh_meshes.py``) is cut into ``--pieces`` k-d pieces (balanced by tets),
each with its own numbering, and every piece is refined on its own (every tet into 8 at its edge
midpoints, the scalar interpolated: ``gatun_py.mesh.pieces.refine_midpoints``) and written as a
``.vtu`` file, with a ``.pvtu`` file naming them. A midpoint depends only on its edge's two ends,
so the refined pieces meet exactly: the data is a conforming partitioned mesh 8x the base, and
no process ever holds it whole (the largest thing in memory is the base mesh, 1/8 of it).

``--target-tets N`` picks the base: the gmsh flange of the size nearest N / 8 (``--base`` names
one). Cached under ``bench/out/pieces/<base>-p<pieces>-r<refine>/`` (gitignored)::

    python bench/pieces_data.py --target-tets 8e6            # flange-1m refined: 6.5 M tets
    python bench/pieces_data.py --target-tets 74e6           # flange-12m refined: about 75 M tets
    python bench/pieces_data.py --base flange-1m --refine 0  # the base itself in 16 pieces
    python bench/pieces_data.py --target-tets 8e6 --whole    # also the whole refined mesh as one .vtu
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from gmsh_meshes import SIZES, mesh_path  # noqa: E402

OUT = HERE / "out" / "pieces"
# tets of the flange per nominal size (what gmsh gives, 5-20 % under the nominal)
FLANGE_TETS = {"50k": 47_000, "200k": 172_000, "1m": 810_000, "2m": 1_600_000, "5m": 3_930_000, "10m": 7_800_000,
               "12m": 9_400_000}  # 12m: not built yet, scaled from 10m


def base_for(target: float, refine: int) -> str:
    """The flange whose refined size is nearest ``target`` tets (in ratio)."""
    want = target / 8 ** refine
    size = min(SIZES, key=lambda s: abs(math.log(FLANGE_TETS[s] / want)))
    return f"flange-{size}"


def data_dir(base: str, pieces: int, refine: int) -> Path:
    return OUT / f"{base}-p{pieces}-r{refine}"


def make(base: str, pieces: int = 16, refine: int = 1, *, whole: bool = False, force: bool = False,
         log=print) -> Path:
    """The ``.pvtu`` of ``base`` in ``pieces`` pieces, each refined ``refine`` times (built if missing)."""
    from gatun_py.mesh import read_mesh, write_mesh
    from gatun_py.mesh.partition import partition_tets, split_bricks
    from gatun_py.mesh.pieces import refine_midpoints, write_pvtu_index

    d = data_dir(base, pieces, refine)
    pvtu = d / "pieces.pvtu"
    whole_path = d / "whole.vtu"
    if pvtu.exists() and (whole_path.exists() or not whole) and not force:
        return pvtu
    d.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    mesh = read_mesh(mesh_path(base, log=log))[0]
    bricks = split_bricks(mesh, partition_tets(mesh, pieces))
    if whole:
        w = mesh
        for _ in range(refine):
            w = refine_midpoints(w)
        write_mesh(w, whole_path, force=True)
        log(f"whole: {w.n_tets:,} tets, {w.n_points:,} points")
        del w
    del mesh
    paths, total, like = [], 0, None
    for i, b in enumerate(bricks):  # one refined piece in memory at a time
        m = b.mesh
        bricks[i] = None
        for _ in range(refine):
            m = refine_midpoints(m)
        paths.append(d / f"pieces_{i}.vtu")
        write_mesh(m, paths[-1], force=True)
        total += m.n_tets
        like = like or m
        log(f"  piece {i}: {m.n_tets:,} tets")
    write_pvtu_index(pvtu, paths, like, force=True)
    log(f"{pvtu}: {len(paths)} pieces, {total:,} tets in {time.perf_counter() - t0:.0f} s")
    return pvtu


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target-tets", type=float, default=8e6, help="about this many tets after refinement")
    ap.add_argument("--base", default=None, help="the gmsh mesh to cut (default: from --target-tets)")
    ap.add_argument("--pieces", type=int, default=16)
    ap.add_argument("--refine", type=int, default=1, choices=(0, 1, 2))
    ap.add_argument("--whole", action="store_true", help="also write the whole refined mesh as whole.vtu")
    ap.add_argument("--force", action="store_true")
    a = ap.parse_args(argv)
    base = a.base or base_for(a.target_tets, a.refine)
    print(make(base, a.pieces, a.refine, whole=a.whole, force=a.force))
    return 0


if __name__ == "__main__":
    sys.exit(main())
