"""``tetc compress`` and ``tetc decompress``."""

from __future__ import annotations

from pathlib import Path

import click

from .main import tetc
from .options import force_option, mesh_input_options, progress_bar, quiet_option, read_kwargs, status


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output .tetc file.")
@click.option("--levels", "n_levels", type=click.IntRange(min=0), default=None,
              help="Store pre-simplified levels 1..K (ratio 1-1/2^i) [default: every level the merge forest "
                   "reaches, up to 13].")
@click.option("--mesh-only", is_flag=True, help="Store only the mesh: no merge forest, no levels.")
@click.option("--w-density", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Decimation: weight of the density (mass) error.")
@click.option("--w-geometry", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Decimation: weight of the boundary geometry error.")
@mesh_input_options
@force_option
@quiet_option
def compress(input, output, n_levels, mesh_only, w_density, w_geometry, scalar, q_file, q_var, cell_to_point,
             force, quiet):
    """Compress INPUT (any readable mesh or PLOT3D grid) losslessly into a .tetc file.

    Connectivity is cut-border coded, coordinates and density are predicted and coded exactly:
    decompressing gives back every float bit for bit (vertices and tets in another order).
    Unless --mesh-only, the mesh is also decimated (Van Gelder) into a merge forest stored with it,
    plus pre-simplified levels, for `tetc decompress --ratio` and time-critical rendering.
    """
    import time

    from gatun_py.codec import write_tetc
    from gatun_py.codec.info import tetc_info
    from gatun_py.mesh import read_mesh
    from gatun_py._atomic import check_output_path

    check_output_path(output, force=force)  # fail before the (long) work
    t0 = time.perf_counter()
    mesh, report = read_mesh(input, **read_kwargs(scalar, q_file, q_var, cell_to_point))
    for note in report.notes:
        status(f"note: {note}", quiet)
    status(f"read {input}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)
    if mesh_only:
        payload = mesh
    else:
        from gatun_py.codec import LevelPayload
        from gatun_py.simplify import build_levels, decimate, storage_forests

        with progress_bar("decimating", mesh.n_points, quiet) as update:
            forest = decimate(mesh, w_density=w_density, w_geometry=w_geometry, progress=update)
        levels = build_levels(mesh, forest, n_levels)
        status(f"merge forest: {forest.n_merges} merges (max ratio {forest.max_ratio:.5f}); "
               f"levels {', '.join(str(lv.level) for lv in levels)}", quiet)
        payload = [LevelPayload(lv.level, lv.ratio, lv.n_merges, lv.mesh, (f.parent, f.rank))
                   for lv, f in zip(levels, storage_forests(levels))]
    status("compressing...", quiet)
    n = write_tetc(output, payload, source=Path(input).name, force=force)
    dt = time.perf_counter() - t0
    if not quiet:
        info = tetc_info(output)
        status(f"wrote {output}: {n} bytes ({8.0 * n / max(mesh.n_tets, 1):.2f} bits/tet overall, "
               f"connectivity {info['bits_per_tet_connectivity']:.2f} bits/tet, "
               f"geometry {info['bits_per_vertex_geometry']:.1f} bits/vertex) in {dt:.1f} s", quiet)


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output mesh; format from the extension (.vtu, .vtk, .msh, .xdmf, ...).")
@click.option("--level", default=None, type=click.IntRange(min=0),
              help="Which stored level to decode (0 = the full mesh, the default).")
@click.option("--ratio", default=None, type=float,
              help="Simplify to this ratio (merged / all vertices) with the stored merge forest, starting "
                   "from the most simplified stored level that is still finer.")
@force_option
@quiet_option
def decompress(input, output, level, ratio, force, quiet):
    """Decompress a .tetc file into any mesh format meshio writes."""
    from gatun_py.errors import OptionError
    from gatun_py.mesh import write_mesh
    from gatun_py.simplify import read_simplified
    from gatun_py._atomic import check_output_path

    if level is not None and ratio is not None:
        raise OptionError("--level and --ratio are exclusive")
    check_output_path(output, force=force)
    mesh = read_simplified(input, ratio=ratio, level=level)
    write_mesh(mesh, output, force=force)
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)
