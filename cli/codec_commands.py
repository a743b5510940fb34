"""``tetc info``, ``tetc convert``, ``tetc compress`` and ``tetc decompress``."""

from __future__ import annotations

import click

import gatun_py
from gatun_py._atomic import check_output_path
from gatun_py._compile_notice import announce

from .options import (RATIO, camera_options, echo_json, force_option, jobs_option, json_option, logger,
                      mesh_input_options, output_option, progress_reporter, quiet_option, read_kwargs, require_file,
                      selective_options, status, tetc_name, transfer_function_options)


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@mesh_input_options
@json_option
def info(input, scalar, q_file, q_var, cell_to_point, time_step, as_json):
    """Describe INPUT: sizes, boundary, degenerate tets, and for .tetc files the codec figures."""
    data = gatun_py.info(input, **read_kwargs(scalar, q_file, q_var, cell_to_point, time_step))
    if as_json:
        echo_json(data)
        return
    for k, v in data.items():
        if k == "sections":  # every section by name: --json has them; "parts" sums them up
            click.echo(f"sections: {len(v)} (tetc info --json lists them)")
        elif k == "parts":
            click.echo("parts (all levels / level 0, bytes):")
            width = max(len(row["part"]) for row in v)
            for row in v:
                click.echo(f"  {row['part']:<{width}}  {row['bytes']:>12,}  {100 * row['share']:5.1f} %  "
                           f"{row['level0_bytes']:>12,}")
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            click.echo(f"{k}:")
            for row in v:
                click.echo("  " + ", ".join(f"{a}={_short(b)}" for a, b in row.items()))
        else:
            click.echo(f"{k}: {_short(v)}")


def _short(v):
    """A value as text, floats to 7 significant digits (--json has them in full)."""
    if isinstance(v, float):
        return f"{v:.7g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_short(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{a}: {_short(b)}" for a, b in v.items()) + "}"
    return str(v)


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@output_option("Output mesh; format from the extension (.vtu, .vtk, .msh, .xdmf, ...).")
@mesh_input_options
@click.option("--refine", type=click.IntRange(min=1, max=16), default=1, show_default=True, metavar="K",
              help="PLOT3D only: cut every grid cell into K×K×K cells on its trilinear map before the "
                   "tet split; the scalar is trilinearly interpolated, so this makes larger meshes "
                   "for scale tests, not new data.")
@force_option
@quiet_option
def convert(input, output, scalar, q_file, q_var, cell_to_point, time_step, refine, force, quiet):
    """Convert INPUT (any readable mesh or PLOT3D grid) into a linear tet mesh file.

    Hexahedra, wedges and pyramids are split into tets conformingly; the scalar is written as
    point data. Floats are kept bit for bit (with --refine, the original grid points are).
    """
    mesh = gatun_py.convert(input, output, refine=refine, force=force, log=logger(quiet),
                            **read_kwargs(scalar, q_file, q_var, cell_to_point, time_step))
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@output_option("Output .tetc file (the name must end in .tetc).", tetc_name)
@click.option("--levels", "n_levels", type=click.IntRange(min=0), default=None,
              help="Store pre-simplified levels 1..K (ratio 1-1/2^i) [default: every level the merge forest "
                   "reaches, up to 13; none under 128 points].")
@click.option("--mesh-only", is_flag=True, help="Store only the mesh: no merge forest, no levels.")
@click.option("--w-density", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Decimation: weight of the density (mass) error.")
@click.option("--w-geometry", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Decimation: weight of the boundary geometry error.")
@click.option("--w-sample", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Decimation: factor on the sampled error (the density error at the original points). "
                   "0 builds the forest 2-2.5x faster, with worse coarse levels (12-26 % more image "
                   "error at ratio 0.9 on the samples).")
@click.option("--bricks", "n_bricks", type=click.IntRange(min=1, max=4096), default=1, show_default=True, metavar="K",
              help="Split the tets into K bricks (k-d tree, balanced by tets), each coded with its own forest "
                   "and levels, to decode on several cores and render apart; 1 = one stream.")
@jobs_option
@click.option("--dependencies", is_flag=True,
              help="Also store the merge dependencies `tetc render --selective` needs (every cut closed under "
                   "them is flip-free); about 20-30 % more bytes, so off by default.")
@mesh_input_options
@click.option("--drop-cell-data", is_flag=True,
              help="Leave out cell arrays (a .tetc file stores point arrays only; without this flag or "
                   "--cell-to-point a mesh with cell data is refused).")
@force_option
@quiet_option
def compress(input, output, n_levels, mesh_only, w_density, w_geometry, w_sample, n_bricks, jobs, dependencies, scalar,
             q_file, q_var, cell_to_point, time_step, drop_cell_data, force, quiet):
    """Compress INPUT (any readable mesh or PLOT3D grid) losslessly into a .tetc file.

    Connectivity is cut-border coded; coordinates (float32 or float64) and every point array, in its
    own dtype, are predicted and coded exactly: decompressing gives back every value bit for bit
    (vertices and tets in another order). --scalar names the default array (rendered, decimated).
    Unless --mesh-only, the mesh is also decimated (Van Gelder) into a merge forest stored with it,
    plus pre-simplified levels, for `tetc decompress --ratio` and time-critical rendering.
    With --bricks K, each brick is decimated and coded on its own (on --jobs processes), its
    vertices shared with other bricks locked so simplified bricks still meet. Without bricks,
    --jobs threads code the levels (level 0 while the decimation runs); the file is the same.
    """
    require_file(input)  # before saying that it compiles
    check_output_path(output, force=force)
    announce(["encoder"] + ([] if mesh_only else ["decimation"]) + (["dependencies"] if dependencies else []),
             quiet=quiet)
    with progress_reporter("decimating", quiet, min_total=1) as progress:
        gatun_py.compress(input, output, levels=n_levels, mesh_only=mesh_only, force=force, w_density=w_density,
                          w_geometry=w_geometry, w_sample=w_sample, progress=progress, log=logger(quiet),
                          drop_cell_data=drop_cell_data, bricks=n_bricks, jobs=jobs, dependencies=dependencies,
                          **read_kwargs(scalar, q_file, q_var, cell_to_point, time_step))


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@output_option("Output mesh (not .tetc); format from the extension (.vtu, .vtk, .msh, .xdmf, ...).")
@click.option("--level", default=None, type=click.IntRange(min=0),
              help="Which stored level to decode (0 = the full mesh, the default).")
@click.option("--ratio", default=None, type=RATIO,
              help="Simplify to this ratio (merged / all vertices, 0..1) with the stored merge forest, "
                   "starting from the most simplified stored level that is still finer.")
@selective_options(budget=False)
@camera_options("With --selective", size_help="the image size the cut is chosen for.")
@transfer_function_options("With --selective")
@jobs_option
@force_option
@quiet_option
def decompress(input, output, level, ratio, selective, tets, size, tf_spec, azimuth, elevation, zoom, scalar_range,
               jobs, force, quiet):
    """Decompress a .tetc file into any mesh format meshio writes that holds tets.

    With --jobs 2 or more (default: all cores) the connectivity decodes on a thread of its own,
    ahead of the geometry; the bricks of a bricked file decode in parallel and are stitched into
    one mesh, each shared vertex once. The output is the same whatever --jobs is. With --selective, write the
    mesh `tetc render --selective` draws for that view and transfer function (same options), e.g.
    to check it or use it elsewhere.
    """
    if sum(x is not None for x in (level, ratio, tets)) > 1:
        raise click.UsageError("--level, --ratio and --tets are exclusive")
    if tets is not None and not selective:
        raise click.UsageError("--tets needs --selective")
    if selective and level is not None:
        raise click.UsageError("--selective takes --ratio or --tets, not --level")
    require_file(input)  # before saying that it compiles
    check_output_path(output, force=force)
    announce(["decoder"] + (["forest decoder"] if ratio is not None or selective else []), quiet=quiet)
    mesh = gatun_py.decompress(input, output, ratio=ratio, level=level, force=force, jobs=jobs, selective=selective,
                               tets=tets, size=size, tf=tf_spec, azimuth=azimuth, elevation=elevation, zoom=zoom,
                               scalar_range=scalar_range, log=logger(quiet))
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)
