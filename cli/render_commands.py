"""``tetc render``: streaming decode + simplification + object-space ray casting into an image."""

from __future__ import annotations

import time

import click

import gatun_py
from gatun_py._runtime import check_output_path, compile_for_render, load_render_kernels, peak_rss_mb

from .options import (POSITIVE, RATIO, Colour, FiniteFloat, camera_options, check_step, echo_json, force_option,
                      interruptible, logger, mesh_input_options, output_option, progress_reporter, quiet_option,
                      records, require_file, selective_options, status, transfer_function_options)


def _component(ctx, param, text):
    """--component: None, a component index, or "magnitude"."""
    if text is None or text == "magnitude":
        return text
    try:
        k = int(text)
    except ValueError:
        raise click.BadParameter(f"{text!r} is neither a component index nor 'magnitude'",
                                 param_hint="'--component'") from None
    if k < 0:
        raise click.BadParameter(f"{k} is not a component index (0, 1, 2, ...)", param_hint="'--component'")
    return k


@click.command()
@click.argument("input", type=click.Path(dir_okay=False))
@output_option("Output image: .png, .jpg, .webp, .tif or .bmp (format from the extension).")
@transfer_function_options()
@click.option("--opacity-model", type=click.Choice(["gatun", "vtk"]), default=None,
              help="gatun: opacity a holds for a path of unit_distance, 1-(1-a)^(d/u) [the default, unless the "
                   "TF file says otherwise]; vtk: as VTK's unstructured-grid ray caster, attenuation a/u "
                   "(1-exp(-a d/u)) with the opacity read only at the colour points (to compare with VTK).")
@click.option("--mode", type=click.Choice(["volume", "face"]), default="volume", show_default=True,
              help="volume: uniform samples every --step; face: one sample per tet (at its faces).")
@click.option("--step", type=POSITIVE, default=None,
              help="Sample spacing for --mode volume [default: half the median boundary edge, at most 1/512 of "
                   "the bounding-box diagonal; a .tetc file uses the step recorded when it was compressed].")
@camera_options()
@click.option("--component", default=None, metavar="K|magnitude", callback=_component,
              help="For a vector point array (--scalar NAME): render component K (0-based) or its magnitude "
                   "[default: component 0]. .tetc input.")
@click.option("--background", type=Colour(), default="black", show_default=True,
              help="Background colour: a name, #rrggbb, or r,g,b in 0..1.")
@click.option("--colorbar", is_flag=True, help="Add a colour bar with the scalar's name and range on the right.")
@click.option("--ratio", type=RATIO, default=None,
              help="Simplify to this ratio (merged / all vertices, 0..1): starts from the most simplified "
                   "stored level still finer, then simplifies on the fly. .tetc input only.")
@click.option("--level", type=click.IntRange(min=0), default=None, help="Render stored level i as it is.")
@click.option("--budget", type=POSITIVE, default=None, metavar="SECONDS",
              help="Frame-time budget: pick the finest level and ratio predicted to fit, by a model of costs per "
                   "decoded tet, ray-tet step, sample and boundary face (measured once per machine in under a "
                   "second and cached; no per-file calibration). .tetc input only; with --workers/--scheduler a "
                   "bricked file (compress --bricks K), every brick picking its level for its share of each frame.")
@click.option("--pipeline", type=click.Choice(["streaming", "generic"]), default="streaming", show_default=True,
              help="streaming: decode, simplify and render in one pass; generic: decode all, simplify, render "
                   "(the paper's baseline).")
@click.option("--lean/--no-lean", default=False,
              help="Free each face of the mesh once no ray needs it, so memory holds the tets in flight, not the "
                   "whole mesh (5 M tets at 512²: 450 MB instead of 1.2 GB; renders 1.5-2x slower). "
                   "Off by default for the time it costs; pays off above ~1 M tets. .tetc, "
                   "--pipeline streaming only.")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Render on a local Dask cluster of N worker processes: the mesh is cut into bricks that stay on "
                   "the workers, and their ray fragments are composited exactly (same image as without). INPUT "
                   "may then be a glob ('steps/*.tetc', quoted): time steps, rendered file after file. "
                   "Needs Dask: pip install 'dask[distributed]' (or the extra: pip install 'gatun_py[dask]').")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="Render on a running Dask cluster (workers started with `dask worker`, NUMBA_CACHE_DIR on a "
                   "shared folder so they compile nothing). The input must be readable by the client.")
@click.option("--bricks", "n_bricks", type=click.IntRange(1, 4096), default=None, metavar="K",
              help="With --workers/--scheduler: cut an unbricked input into K bricks [default: 4 per worker].")
@click.option("--orbit", type=click.IntRange(min=1), default=1, show_default=True, metavar="N",
              help="Render N frames around the mesh (azimuth + 360 k / N), each written as it completes: to "
                   "OUTPUT with {frame} replaced by the frame number, or with _0000, _0001, ... added.")
@click.option("--timeout", type=POSITIVE, default=10.0, show_default=True, metavar="SECONDS",
              help="With --scheduler: how long to wait for it.")
@click.option("--stats", "show_stats", is_flag=True, help="Print one JSON object with timings and counts on stdout.")
@click.option("--time", "at_time", type=FiniteFloat(), default=None, metavar="T",
              help="A .tetc time series: render the step at time T (or give --time-step K).")
@click.option("--steps", "step_range", default=None, metavar="A:B[:S]",
              help="A .tetc time series: render steps A, A+S, ... below B (a Python slice; B empty: to the last), "
                   "one image each, named by {frame} and {step} in OUTPUT (e.g. run_{step:04d}.png), the scalar "
                   "range common to all of them unless --range.")
@selective_options(budget=True)
@mesh_input_options
@force_option
@quiet_option
@records("view", "detail", "read", "cluster")
def render(input, output, view, detail, read, cluster, pipeline, n_bricks, orbit, show_stats, at_time, step_range, force,
           quiet):
    """Volume-render INPUT (a .tetc file or any mesh file) into an image.

    Tets are rendered as they are decoded: rays start on the boundary surface and walk inward
    from both ends of each segment. The camera follows VTK: 30 degree perspective fitted to the
    bounding sphere, then --azimuth, --elevation, refit, --zoom.
    """
    from gatun_py._runtime import announce, is_tetc
    from gatun_py.raycast.options import image_format

    t_start = time.perf_counter()
    if sum(x is not None for x in (at_time, step_range, read.time_step)) > 1:
        raise click.UsageError("give at most one of --time, --steps and --time-step")
    check_step(input, read.time_step, at_time)
    if step_range is not None:
        if cluster.used or orbit > 1:
            raise click.UsageError("--steps renders on this machine: not with --workers, --scheduler or --orbit")
        _render_steps(input, output, _slice(step_range), dict(view=view, detail=detail, read=read, pipeline=pipeline),
                      force=force, quiet=quiet, show_stats=show_stats)
        return
    if n_bricks is not None and not cluster.used:
        raise click.UsageError("--bricks is for rendering on a cluster (--workers or --scheduler)")
    if cluster.used or orbit > 1:
        _check_series_options(detail, view, pipeline)
    if cluster.used:
        _render_on_cluster(input, output, workers=cluster.workers, scheduler=cluster.scheduler, bricks=n_bricks,
                           orbit=orbit, view=view, detail=detail, read=read, force=force, timeout=cluster.timeout,
                           show_stats=show_stats, quiet=quiet)
        return
    if orbit > 1:
        raise click.UsageError("--orbit renders a series on a cluster: give --workers N (a local one) or --scheduler")
    image_format(output)  # refuse what cannot be written before the work, not after
    check_output_path(output, force=force)
    require_file(input)
    decoder = is_tetc(input)  # a mesh file is rendered without the decoder: no need to compile it
    simplify = detail.simplifies
    parts = (["decoder"] if decoder else []) + ["renderer"] + (["forest decoder", "filter"] if decoder and simplify
                                                               else [])
    missing = announce(parts, side_by_side=decoder, quiet=quiet)
    if missing:
        compile_for_render(decoder=decoder, simplify=simplify, lean=view.lean, mode=view.mode)
    startup_s = load_render_kernels(lean=view.lean, decoder=decoder, simplify=simplify) + (time.perf_counter() - t_start)
    t_start = time.perf_counter()  # total_s: from opening the input to the image written
    with progress_reporter("rendering", quiet) as progress, interruptible():
        frame = gatun_py.render(input, view=view, detail=detail, read=read, pipeline=pipeline, progress=progress,
                                log=logger(quiet), time=at_time)
    frame.save(output, force=force)
    st = frame.stats
    st["total_s"] = time.perf_counter() - t_start
    st["startup_s"] = startup_s  # imports and loading the compiled kernels, before the input is opened
    st["peak_rss_mb"] = peak_rss_mb()
    st["output"] = str(output)
    if show_stats:
        echo_json(st)
    else:
        w, h = st["size"]
        status(f"wrote {output} ({w}x{h}, {st['tets_rendered']} tets, {st['total_s']:.2f} s)", quiet)


def _check_series_options(detail, view, pipeline):
    unsupported = [name for name, given in (("--ratio", detail.ratio is not None),
                                            ("--colorbar", view.colorbar), ("--lean", view.lean),
                                            ("--pipeline generic", pipeline != "streaming"),
                                            ("--component", view.component is not None)) if given]
    if unsupported:
        raise click.UsageError(f"{', '.join(unsupported)} cannot be used with --workers, --scheduler or --orbit")


def _render_on_cluster(input, output, *, show_stats, quiet, **options):
    from gatun_py.api import render_frames  # start-up time: numba loads with it

    t0 = time.perf_counter()
    done = {"n": 0}

    def progress(n, total):
        done["n"] = n
        status(f"frame {n}/{total} written ({time.perf_counter() - t0:.1f} s)", quiet)

    frames = render_frames(input, output, progress=progress, log=logger(quiet), **options)
    if show_stats:
        echo_json({"frames": frames, "total_s": time.perf_counter() - t0, "peak_rss_mb": peak_rss_mb()})
    elif len(frames) == 1:
        st = frames[0]
        status(f"wrote {st['output']} ({st['tets_rendered']} tets, {st['bricks']} bricks on {st['workers']} workers, "
               f"{time.perf_counter() - t0:.2f} s)", quiet)


def _slice(text: str) -> tuple:
    """--steps A:B[:S] as (start, stop, stride), empty parts None."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise click.BadParameter(f"{text!r} is not A:B or A:B:S", param_hint="'--steps'")
    try:
        out = tuple(int(x) if x.strip() else None for x in parts) + (None,) * (3 - len(parts))
    except ValueError:
        raise click.BadParameter(f"{text!r}: A, B and S are whole numbers", param_hint="'--steps'") from None
    if out[2] == 0:
        raise click.BadParameter(f"{text!r}: the stride S must not be 0", param_hint="'--steps'")
    return out


def _render_steps(input, output, steps, options, *, force, quiet, show_stats):
    require_file(input)
    with progress_reporter("rendering steps", quiet) as progress, interruptible():
        stats = gatun_py.render_steps(input, output, steps=steps, force=force, progress=progress,
                                      log=logger(quiet), **options)
    for st in stats:
        status(f"wrote {st['output']} (step {st['step']}, time {st['time']:g})", quiet)
    if show_stats:
        echo_json(stats)
