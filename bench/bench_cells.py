"""Cells as given: what the cells, the cell arrays and the whole file cost, against xz -9 and pcodec.

For every input (the Room fire hexes, gmsh meshes with physical groups made here, a mixed
hex/pyramid/tet mesh made here, and, when ``TETC_VTK_DATA`` names a directory, the files of VTK's
example data listed in ``VTK_FILES`` found there, e.g. a checkout of pyvista/vtk-data's ``Data/``):

* ``raw xz``: ``xz -9`` (preset 9) of the input's arrays as given, one stream: the points, every
  point array, every cell block's ids in meshio's dtype, every cell array;
* ``mesh-only`` and ``default`` (with the merge forest and levels): the ``.tetc`` file, over ``raw
  xz`` (targets: at most 0.5 and 1.0);
* ``cells``: the mesh-only file over the mesh-only file of the same mesh already split into tets
  (no cells stored; target for hexahedral meshes: at most 1.1);
* ``cell arrays``: the ``C/data`` sections over the best of pcodec and xz -9 on each cell array in
  file order (its blocks concatenated; target at most 0.8);
* ``keep-order``: the file with ``keep_order`` over the default file (target on a gmsh mesh: at
  most 1.15), the same for mesh-only files in brackets, and what the numbering cost.

Every file round-trips exactly (tests/cells_check.py) before its figures are written.

    python bench/bench_cells.py [--quick] [--no-costs] [--nodes]
        # --quick: no default (levels) files above 60k tets; --no-costs: keep the level-cost table
        # of the last run (the samples' forests and levels, which this script does not change);
        # --nodes: only the quadratic nodes' cost before / after their edge prediction (cells_nodes.md)
"""

from __future__ import annotations

import lzma
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import ROOT, SECTIONS  # noqa: E402  (puts tests/ on the path)

VTK_FILES = ["notch_disp.vtu", "QuadraticTetra.vtu", "QuadraticWedge.vtu", "QuadraticPyramid.vtu",
             "TriQuadraticHexahedron.vtu", "CylinderQuadratic.vtk", "StructuredGrid.vts", "SampleStructGrid.vtk",
             "AngularSector.vtk", "can.vtu", "carotid.vtk", "kitchen.vtk", "hexa.vtk", "mesh_fs8.exo",
             "dataset.vtu", "notch_stress.vtk", "Wedge.vtu", "uGridEx.vtk", "mug.e"]


def _xz(b: bytes) -> int:
    return len(lzma.compress(b, preset=9))


def _pcodec(a) -> int | None:
    try:
        from pcodec import ChunkConfig, standalone
    except ImportError:
        return None
    a = np.ascontiguousarray(a).ravel()
    if a.dtype.kind == "b":
        a = a.astype(np.uint8)
    if a.dtype.kind not in "fiu" or a.dtype.itemsize < 2:
        a = a.astype(np.int16 if a.dtype.kind == "i" else np.uint16)
    try:
        return len(standalone.simple_compress(a.astype(a.dtype.newbyteorder("=")), ChunkConfig()))
    except Exception:
        return None


def _raw(m) -> bytes:
    parts = [np.ascontiguousarray(m.points).tobytes()]
    parts += [np.ascontiguousarray(v).tobytes() for v in m.point_data.values()]
    parts += [np.ascontiguousarray(c.data).tobytes() for c in m.cells]
    parts += [np.ascontiguousarray(a).tobytes() for v in m.cell_data.values() for a in v]
    return b"".join(parts)


def inputs(tmp: Path) -> list:
    sys.path.insert(0, str(ROOT / "tests"))
    from mixedgen import mixed_mesh, tetra10_mesh

    out = [("Room fire (hexahedra)", ROOT / "sample_meshes" / "room_fire" / "fire_ug.vtu")]
    try:
        from test_cells import _gmsh_box

        for order in (1, 2):
            p = tmp / f"gmsh_box_order{order}.msh"
            _gmsh_box(p, order)
            out.append((f"gmsh box, 2 physical volumes (order {order})", p))
    except Exception as e:  # gmsh missing: said in the table's notes
        print(f"gmsh meshes skipped: {e}", file=sys.stderr)
    mixed = tmp / "mixed.vtu"
    m = mixed_mesh(8, 8, 6, 3)
    del m.cell_data["flag"]
    m.point_sets.clear()
    m.cell_sets.clear()
    m.field_data.clear()
    m.write(mixed)
    out.append(("mixed hex/pyramid/tet (made here)", mixed))
    t10 = tmp / "tetra10.vtu"
    tetra10_mesh(n=8).write(t10)
    out.append(("tetra10 grid (made here)", t10))
    data = os.environ.get("TETC_VTK_DATA")
    if data:
        for name in VTK_FILES:
            if (Path(data) / name).exists():
                out.append((f"VTK data {name}", Path(data) / name))
    return out


def _reference(path):
    """The input as meshio (or tetc's Exodus reader) gives it: what the round trip must give back."""
    from gatun_py.mesh.exodus import EXODUS_SUFFIXES, read_exodus
    from gatun_py.mesh.io import _meshio_read, _unescape_names

    if Path(path).suffix.lower() in EXODUS_SUFFIXES:
        return read_exodus(Path(path))[0]
    orig = _meshio_read(Path(path))
    if Path(path).suffix.lower() == ".vtk":
        _unescape_names(orig)
    return orig


def measure(label, path, tmp: Path, quick: bool) -> dict:
    import meshio

    import gatun_py
    from cells_check import check_round_trip, vertex_order_of
    from gatun_py.codec import TetcReader
    from gatun_py.mesh import read_mesh

    orig = _reference(path)
    tm, rep = read_mesh(path)
    raw = _raw(orig)
    row = {"input": label, "cells": ", ".join(f"{c.type} {len(c.data)}" for c in orig.cells),
           "tets": tm.n_tets, "raw": len(raw)}
    t0 = time.perf_counter()
    row["raw_xz"] = _xz(raw)
    mo = tmp / "mo.tetc"
    gatun_py.compress(path, mo, mesh_only=True, force=True)
    row["mesh_only"] = mo.stat().st_size
    stored_cells = "cells" in TetcReader(mo).meta
    if stored_cells:
        check_round_trip(orig, meshio.read(mo), vertex_order_of(tm))
    split = tmp / "split.tetc"
    gatun_py.compress(tm, split, mesh_only=True, force=True)
    row["split"] = split.stat().st_size
    r = TetcReader(mo)
    sizes = {n: r.container.section_size(n) for n in r.container.section_names()}
    row["cell_bytes"] = sum(v for k, v in sizes.items() if k.startswith("C/") and not k.startswith("C/data"))
    row["data_bytes"] = sum(v for k, v in sizes.items() if k.startswith("C/data"))
    peers = 0
    for name, per in orig.cell_data.items():
        a = np.concatenate([np.asarray(x).reshape(len(x), -1) for x in per])
        p = _pcodec(a)
        x = _xz(np.ascontiguousarray(a).tobytes())
        peers += min(x, p) if p is not None else x
    row["data_peer"] = peers
    keep = tmp / "keep.tetc"
    gatun_py.compress(path, keep, mesh_only=True, force=True, keep_order=True)
    row["keep_mesh_only"] = keep.stat().st_size
    info = gatun_py.info(keep)["keep_order"]
    row["keep_bits"] = (info["bits_per_point"], info["bits_per_cell"])
    if not quick or tm.n_tets <= 60_000:
        full = tmp / "full.tetc"
        gatun_py.compress(path, full, force=True)
        row["default"] = full.stat().st_size
        if tm.n_tets <= 20_000 or not quick:
            gatun_py.compress(path, keep, force=True, keep_order=True)
            row["keep_default"] = keep.stat().st_size
    row["seconds"] = time.perf_counter() - t0
    return row


def node_costs(inputs_: list, tmp: Path) -> list[str]:
    """Quadratic inputs: the mesh-only file with the higher-order nodes coded on their edges and
    faces (today) and as loose points (before), over the file of the same mesh split into tets
    (the nodes kept as loose points there, and no cell arrays: the last column leaves them out).
    The two files differ only in level 0's geometry and point-array sections, so "before" is
    today's file with those sections coded without the refs. Each file round-trips first."""
    import meshio

    import gatun_py
    from cells_check import check_round_trip, vertex_order_of
    from gatun_py.codec import TetcReader
    from gatun_py.codec.tetcfile import LevelPayload, encode_level, node_blocks
    from gatun_py.mesh import read_mesh

    lines = ["", "Quadratic cells: the nodes' coordinates (and point arrays) predicted from their edge's or face's "
             "corners (`node_costs`; mesh-only files, bytes exact):", "",
             "| input | nodes | split (tets) | before | after | before / split | after / split | after / before "
             "| cell arrays (C/data) | after without them / split |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, path in inputs_:
        try:
            tm, rep = read_mesh(path)
            quad = node_blocks(rep.cells)
            if not quad:
                continue
            mo = tmp / "nodes.tetc"
            gatun_py.compress(path, mo, mesh_only=True, force=True)
            orig = _reference(path)
            check_round_trip(orig, meshio.read(mo), vertex_order_of(tm))
            split = tmp / "nodes_split.tetc"
            gatun_py.compress(tm, split, mesh_only=True, force=True)

            def level0(nb):
                enc = encode_level(LevelPayload(0, 0.0, 0, tm, node_blocks=nb), chainable=False)
                return sum(len(v) for v in enc.sections.values())

            after = mo.stat().st_size
            before = after - level0(quad) + level0(())
            n_nodes = tm.n_points - len(np.unique(tm.tets))
            sp = split.stat().st_size
            r = TetcReader(mo)
            data = sum(r.container.section_size(k) for k in r.container.section_names() if k.startswith("C/data"))
            lines.append(f"| {label} | {n_nodes:,} | {sp:,} | {before:,} | {after:,} | {before / sp:.3f} | "
                         f"{after / sp:.3f} | {after / before:.3f} | {data:,} | {(after - data) / sp:.3f} |")
        except Exception as e:  # one line per input, as the main table
            lines.append(f"| {label} | {type(e).__name__}: {str(e)[:80]} | | | | | | | | |")
        print(lines[-1], flush=True)
    return lines


def level_costs(tmp: Path) -> list[str]:
    """What the merge forest with its levels, and the merge dependencies, add to the samples' files
    (the figures the --mesh-only and --dependencies help texts quote)."""
    import gatun_py
    from samples import SAMPLES

    lines = ["", "What the forest with its levels and the merge dependencies cost on the samples "
             "(`--mesh-only`, default, `--dependencies`):", "",
             "| sample | mesh-only | default | default / mesh-only | --dependencies | deps / default |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, (path, kw, _) in SAMPLES.items():
        sizes = {}
        for label, opts in (("mesh_only", dict(mesh_only=True)), ("default", {}), ("deps", dict(dependencies=True))):
            out = tmp / f"{name}_{label}.tetc"
            gatun_py.compress(path, out, force=True, **opts, **kw)
            sizes[label] = out.stat().st_size
        lines.append(f"| {name} | {sizes['mesh_only']:,} | {sizes['default']:,} | "
                     f"{sizes['default'] / sizes['mesh_only']:.2f} | {sizes['deps']:,} | "
                     f"{sizes['deps'] / sizes['default']:.2f} |")
        print(lines[-1], flush=True)
    return lines


def main(argv) -> int:
    quick = "--quick" in argv
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if "--nodes" in argv:  # the quadratic nodes' before / after alone
            lines = node_costs(inputs(tmp), tmp)
            SECTIONS.mkdir(parents=True, exist_ok=True)
            (SECTIONS / "cells_nodes.md").write_text("\n".join(lines[1:]) + "\n")
            return 0
        for label, path in inputs(tmp):
            print(f"-- {label}", flush=True)
            try:
                rows.append(measure(label, path, tmp, quick))
            except Exception as e:
                rows.append({"input": label, "error": f"{type(e).__name__}: {e}"})
            print(rows[-1], flush=True)
        if "--no-costs" in argv and (SECTIONS / "cells.md").exists():
            old = (SECTIONS / "cells.md").read_text().splitlines()
            at = next((i for i, ln in enumerate(old) if ln.startswith("What the forest")), len(old))
            costs = [""] + old[at:]
        else:
            costs = level_costs(tmp)
    lines = [
        "## Cells as given: cost of the cells, the cell arrays and the file against xz -9 of the arrays",
        "",
        "`python bench/bench_cells.py` (with `TETC_VTK_DATA=<pyvista/vtk-data checkout>/Data` for VTK's example "
        "files). *raw xz*: `xz -9` of the input's arrays as given (points, point arrays, cell ids in "
        "meshio's dtype, cell arrays). *cells*: the mesh-only file over the mesh-only file of the same "
        "mesh split into tets (target 1.1 for hexahedra). *cell arrays*: C/data sections over the best of "
        "pcodec and xz -9 per array in file order (target 0.8). Targets for the file: mesh-only <= 0.5, "
        "default <= 1.0 of raw xz. Every input with cells round-trips exactly first.",
        "",
        "| input | cells | tets | raw xz | mesh-only / raw xz | default / raw xz | cells: file / split | "
        "cell sections | cell arrays / best peer | keep-order / default (mesh-only) | keep-order bits per point, per cell |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['input']} | {r['error'][:120]} | | | | | | | | | |")
            continue
        d = f"{r['default'] / r['raw_xz']:.2f}" if "default" in r else "(quick)"
        data = (f"{r['data_bytes']:,} / {r['data_peer']:,} = {r['data_bytes'] / r['data_peer']:.2f}"
                if r["data_peer"] else "none")
        keep = f"{r['keep_default'] / r['default']:.3f}" if "keep_default" in r else "-"
        lines.append(f"| {r['input']} | {r['cells'][:60]} | {r['tets']:,} | {r['raw_xz']:,} | "
                     f"{r['mesh_only'] / r['raw_xz']:.2f} | {d} | {r['mesh_only'] / r['split']:.3f} | "
                     f"{r['cell_bytes']:,} | {data} | {keep} ({r['keep_mesh_only'] / r['mesh_only']:.3f}) | "
                     f"{r['keep_bits'][0]:.1f}, {r['keep_bits'][1]:.1f} |")
    lines += costs
    SECTIONS.mkdir(parents=True, exist_ok=True)
    (SECTIONS / "cells.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
