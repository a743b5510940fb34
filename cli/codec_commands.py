"""``tetc compress`` and ``tetc decompress``."""

from __future__ import annotations

from pathlib import Path

import click

from .main import tetc
from .options import force_option, mesh_input_options, quiet_option, read_kwargs, status


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output .tetc file.")
@mesh_input_options
@force_option
@quiet_option
def compress(input, output, scalar, q_file, q_var, cell_to_point, force, quiet):
    """Compress INPUT (any readable mesh or PLOT3D grid) losslessly into a .tetc file.

    Connectivity is cut-border coded, coordinates and density are predicted and coded exactly:
    decompressing gives back every float bit for bit (vertices and tets in another order).
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
    status(f"read {input}: {mesh.n_points} points, {mesh.n_tets} tets; compressing...", quiet)
    n = write_tetc(output, mesh, source=Path(input).name, force=force)
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
@click.option("--level", default=0, show_default=True, type=click.IntRange(min=0),
              help="Which stored level to decode (0 = the full mesh).")
@force_option
@quiet_option
def decompress(input, output, level, force, quiet):
    """Decompress a .tetc file into any mesh format meshio writes."""
    from gatun_py.codec import TetcReader
    from gatun_py.mesh import write_mesh
    from gatun_py._atomic import check_output_path

    check_output_path(output, force=force)
    reader = TetcReader(input)
    mesh = reader.decode_mesh(level)
    write_mesh(mesh, output, force=force)
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)
