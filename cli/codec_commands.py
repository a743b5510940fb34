"""``tetc info``, ``tetc convert``, ``tetc compress`` and ``tetc decompress``."""

from __future__ import annotations

import click

import gatun_py
from gatun_py._runtime import check_output_path
from gatun_py._runtime import announce


from .options import (RATIO, FiniteFloat, camera_options, check_step, echo_json, force_option, jobs_option, json_option,
                      logger, mesh_input_options, output_option, progress_reporter, quiet_option, read_kwargs, records,
                      require_file, selective_options, status, tetc_name, transfer_function_options)


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
        elif k == "times":
            shown = v if len(v) <= 8 else v[:4] + ["..."] + v[-2:]
            click.echo(f"times: {', '.join(x if isinstance(x, str) else f'{x:.9g}' for x in shown)}")
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
@click.argument("inputs", metavar="INPUT...", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option("Output .tetc file (the name must end in .tetc).", tetc_name)
@click.option("--times", default=None, metavar="T0,T1,...",
              help="A time series of several INPUT files: their times, comma-separated, increasing "
                   "[default: each file's own TimeValue, else 0, 1, 2, ...].")
@click.option("--keyframe-interval", type=click.IntRange(min=1), default=None, metavar="K",
              help="A time series: code every K-th step alone, the others from the steps before them "
                   "[default: chosen so that any step decodes in about 1.5x the time of step 0].")
@click.option("--levels", "n_levels", type=click.IntRange(min=0), default=None,
              help="Store pre-simplified levels 1..K (ratio 1-1/2^i) [default: every level the merge forest "
                   "reaches, up to 13; none under 128 points].")
@click.option("--mesh-only", is_flag=True,
              help="Store only the mesh: no merge forest, no levels (the forest and levels make the file "
                   "2.2-3.2x the mesh-only file on the samples).")
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
                   "them is flip-free); 13-70 % more bytes than the default file on the samples (Blunt-fin "
                   "+70 %), so off by default.")
@mesh_input_options
@click.option("--keep-order", is_flag=True,
              help="Also store the original point order, cell order and each cell's vertex order, so that "
                   "decompress gives the input's numbering back exactly (node sets, boundary conditions); "
                   "tetc info reports what it cost.")
@click.option("--drop-cell-data", is_flag=True,
              help="Leave out the cell arrays (by default they are stored exactly, with the cells as given).")
@click.option("--pieces", is_flag=True,
              help="The INPUTs are the pieces of one mesh (a parallel solver's files, each with its own "
                   "numbering), not time steps: each piece becomes a brick, compressed on its own (--jobs pieces "
                   "at a time), the points repeated at the interfaces stored once. A .pvtu file or one file of an "
                   "Exodus decomposition (name.e.N.i) or a VTKHDF file of several partitions is read as its pieces "
                   "without this flag.")
@click.option("--memory", default=None, metavar="LIMIT",
              help="Split every piece (or one large INPUT) into bricks small enough that compressing one takes "
                   "at most about LIMIT (e.g. 4G) in a process (an estimate of a few hundred bytes per tet), "
                   "compressed one after another; the input itself is still read whole.")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="With pieces: compress them as tasks of a local Dask cluster of N worker processes; the "
                   "file is the same bytes as without. Needs dask[distributed] (pip install 'dask[distributed]').")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="With pieces: compress them on a running Dask cluster, whose workers read their own "
                   "pieces (the paths must be readable there, e.g. a shared folder).")
@force_option
@quiet_option
@records("forest", "read", "cluster")
def compress(inputs, output, forest, read, cluster, times, keyframe_interval, n_bricks, jobs, keep_order, drop_cell_data,
             pieces, memory, force, quiet):
    """Compress INPUT (any readable mesh or PLOT3D grid) losslessly into a .tetc file.

    Connectivity is cut-border coded; coordinates (float32 or float64) and every point array, in its
    own dtype, are predicted and coded exactly: decompressing gives back every value bit for bit
    (vertices and tets in another order). --scalar names the default array (rendered, decimated).
    Unless --mesh-only, the mesh is also decimated (Van Gelder) into a merge forest stored with it,
    plus pre-simplified levels, for `tetc decompress --ratio` and time-critical rendering.
    With --bricks K, each brick is decimated and coded on its own (on --jobs processes), its
    vertices shared with other bricks locked so simplified bricks still meet. Without bricks,
    --jobs threads code the levels (level 0 while the decimation runs); the file is the same.

    A time series goes into one file: several INPUT files in time order, a ParaView .pvd, an XDMF
    temporal collection, an Exodus file's steps or a temporal VTKHDF file's. Every step must have the same points and tets;
    the mesh, forest and levels are stored once (built on step 0), each step's point arrays (and
    coordinates, when they move) coded from the steps before it. `tetc append` adds steps later.

    Pieces (--pieces, a .pvtu file, an Exodus decomposition, a VTKHDF file's partitions) are never held whole: each is read,
    decimated and coded on its own (on --jobs processes, or Dask --workers/--scheduler), so
    memory is that of the largest piece plus the pieces' boundaries.
    """
    for path in inputs:
        require_file(path)  # before saying that it compiles
    check_output_path(output, force=force)
    announce(["encoder"] + ([] if forest.mesh_only else ["decimation"]) + (["dependencies"] if forest.dependencies
                                                                           else []), quiet=quiet)
    from gatun_py.mesh.pieces import is_partitioned  # start-up time: the notice above comes first

    if pieces or is_partitioned(inputs[0], step=read.time_step) or memory is not None:
        if times is not None or keyframe_interval is not None:
            raise click.UsageError("--times and --keyframe-interval are for a time series, not pieces")
        if n_bricks != 1 or forest.dependencies or keep_order:
            raise click.UsageError("--bricks, --dependencies and --keep-order do not apply to pieces (each piece is a brick)")
        with progress_reporter("compressing pieces", quiet, min_total=1) as progress:
            gatun_py.compress_pieces(list(inputs), output, forest=forest, read=read, force=force, memory=memory,
                                     jobs=jobs, workers=cluster.workers, scheduler=cluster.scheduler,
                                     drop_cell_data=drop_cell_data,
                                     progress=progress, log=logger(quiet))
        return
    if cluster.used:
        raise click.UsageError("--workers and --scheduler apply to pieces (--pieces, .pvtu, name.e.N.i)")
    input = inputs
    if times is not None:
        try:
            times = [float(t) for t in times.split(",")]
        except ValueError:
            raise click.BadParameter(f"{times!r} is not a comma-separated list of numbers", param_hint="'--times'")
    series = len(input) > 1 or times is not None or keyframe_interval is not None
    with progress_reporter("decimating", quiet, min_total=1) as progress:
        gatun_py.compress(list(input) if series else input[0], output, times=times,
                          keyframe_interval=keyframe_interval, forest=forest, read=read, force=force,
                          progress=progress, log=logger(quiet), drop_cell_data=drop_cell_data, bricks=n_bricks,
                          jobs=jobs, keep_order=keep_order)


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@output_option("Output mesh (not .tetc); format from the extension (.vtu, .vtk, .msh, .xdmf, ...).")
@click.option("--level", default=None, type=click.IntRange(min=0),
              help="Which stored level to decode (0 = the full mesh, the default).")
@click.option("--ratio", default=None, type=RATIO,
              help="Simplify to this ratio (merged / all vertices, 0..1) with the stored merge forest, "
                   "starting from the most simplified stored level that is still finer.")
@click.option("--step", "--time-step", "step", type=int, default=None, metavar="K",
              help="A time series: the step to write (0-based, negative from the end) [default: 0; with a .pvd "
                   "or .xdmf OUTPUT, every step].")
@click.option("--time", "at_time", type=FiniteFloat(), default=None, metavar="T",
              help="A time series: write the step at time T.")
@click.option("--piece", type=click.IntRange(min=0), default=None, metavar="K",
              help="A file compressed from pieces: decode piece K alone (its bricks, at --level).")
@selective_options(budget=False)
@camera_options("With --selective", size_help="the image size the cut is chosen for.")
@transfer_function_options("With --selective")
@click.option("--as-tets", is_flag=True,
              help="Write the tets the cells were split into, as one block of linear tets, instead of the "
                   "cells as given (hexahedra, wedges, quadratic cells, blocks, cell arrays).")
@jobs_option
@force_option
@quiet_option
@records("view", "detail", only={"size", "tf", "azimuth", "elevation", "zoom", "scalar_range", "ratio", "level",
                                 "selective", "tets"})
def decompress(input, output, detail, view, step, at_time, piece, as_tets, jobs, force, quiet):
    """Decompress a .tetc file into any mesh format meshio writes that holds tets.

    The full mesh comes back as the cells it was compressed from (hexahedra, wedges, pyramids,
    quadratic cells, every block, cell array, field data and set); --as-tets writes their split
    into tets instead.

    With --jobs 2 or more (default: all cores) the connectivity decodes on a thread of its own,
    ahead of the geometry; the bricks of a bricked file decode in parallel and are stitched into
    one mesh, each shared vertex once. The output is the same whatever --jobs is. With --selective, write the
    mesh `tetc render --selective` draws for that view and transfer function (same options), e.g.
    to check it or use it elsewhere.
    """
    if step is not None and at_time is not None:
        raise click.UsageError("--step and --time are exclusive")
    check_step(input, step, at_time)
    if piece is not None and (detail.selective or detail.ratio is not None):
        raise click.UsageError("--piece decodes a stored level: not with --ratio or --selective")
    require_file(input)  # before saying that it compiles
    check_output_path(output, force=force)
    announce(["decoder"] + (["forest decoder"] if detail.ratio is not None or detail.selective else []), quiet=quiet)
    mesh = gatun_py.decompress(input, output, detail=detail, view=view, force=force, jobs=jobs, as_tets=as_tets,
                               step=step, time=at_time, piece=piece, log=logger(quiet))
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)


@click.command()
@click.argument("series", type=click.Path(dir_okay=False))
@click.argument("step_file", metavar="STEP", type=click.Path(dir_okay=False))
@click.option("--time", "at_time", type=FiniteFloat(), default=None, metavar="T",
              help="The new step's time (after the last step's) [default: the last time + 1].")
@click.option("--scalar", default=None, metavar="NAME", help="Point-data array that is the default scalar.")
@click.option("--cell-to-point", is_flag=True, help="Average cell arrays to the points, as when the series was compressed.")
@click.option("--drop-cell-data", is_flag=True, help="Leave out cell arrays.")
@quiet_option
def append(series, step_file, at_time, scalar, cell_to_point, drop_cell_data, quiet):
    """Append STEP (a mesh file with the series' points and tets) to the time series SERIES (.tetc).

    The other steps are not re-encoded: the step is coded from the steps before it and written
    after the last one. An append interrupted midway (a crash, kill -9) leaves every earlier step
    readable; the next append cuts its bytes off first.
    """
    k = gatun_py.append(series, step_file, time=at_time, scalar=scalar, cell_to_point=cell_to_point,
                        drop_cell_data=drop_cell_data, log=logger(quiet))
    status(f"appended step {k} to {series}", quiet)
