"""``tetc render``: streaming decode + object-space ray casting into a PNG."""

from __future__ import annotations

import re
import time
from pathlib import Path

import click

from gatun_py._resources import peak_rss_mb
from gatun_py.errors import OptionError

from .main import tetc
from .options import echo_json, force_option, mesh_input_options, progress_bar, quiet_option, read_kwargs, status


def parse_size(text: str) -> tuple[int, int]:
    """``"256"`` -> (256, 256); ``"320x200"`` -> (320, 200)."""
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:[xX*]\s*(-?\d+)\s*)?", str(text))
    if not m:
        raise OptionError(f"--size must be W or WxH in pixels, got {text!r}")
    w = int(m.group(1))
    h = int(m.group(2)) if m.group(2) is not None else w
    if w <= 0 or h <= 0:
        raise OptionError(f"--size must be positive, got {text!r}")
    return w, h


def _kernels_cached() -> bool:
    """Whether numba has compiled the render kernels into its cache already."""
    from gatun_py.render import _raycast_kernels

    import numba

    src = Path(_raycast_kernels.__file__)
    if numba.config.CACHE_DIR:  # NUMBA_CACHE_DIR: one folder per source folder, "<name>_<hash>"
        dirs = list(Path(numba.config.CACHE_DIR).glob(f"{src.parent.name}_*"))
    else:
        dirs = [src.parent / "__pycache__"]
    return any(any(d.glob("_raycast_kernels.*.nbc")) for d in dirs)


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output PNG.")
@click.option("--tf", "tf_spec", default="default", show_default=True, metavar="NAME|FILE",
              help="Transfer function: a preset (default, bluntfin, combustion, post, fire), a JSON file "
                   "(project or ParaView format) or a matplotlib colormap name.")
@click.option("--opacity-model", type=click.Choice(["gatun", "vtk"]), default=None,
              help="gatun: opacity a holds for a path of unit_distance, 1-(1-a)^(d/u) [the default, unless the "
                   "TF file says otherwise]; vtk: as VTK's unstructured-grid ray caster, attenuation a/u "
                   "(1-exp(-a d/u)) with the opacity read only at the colour points (to compare with VTK).")
@click.option("--mode", type=click.Choice(["volume", "face"]), default="volume", show_default=True,
              help="volume: uniform samples every --step; face: one sample per tet (at its faces).")
@click.option("--step", type=float, default=None,
              help="Sample spacing for --mode volume [default: half the median boundary edge].")
@click.option("--size", default="256", show_default=True, metavar="W[xH]", help="Image size in pixels.")
@click.option("--azimuth", type=float, default=0.0, show_default=True, help="Degrees about the view-up axis.")
@click.option("--elevation", type=float, default=0.0, show_default=True, help="Degrees up about the focal point.")
@click.option("--zoom", type=float, default=1.0, show_default=True, help="Zoom factor (VTK's Camera.Zoom).")
@click.option("--ratio", type=float, default=None,
              help="Simplify to this ratio (merged / all vertices, 0..1): starts from the most simplified "
                   "stored level still finer, then simplifies on the fly. .tetc input only.")
@click.option("--level", type=click.IntRange(min=0), default=None, help="Render stored level i as it is.")
@click.option("--budget", type=float, default=None, metavar="SECONDS",
              help="Frame-time budget: pick the finest level and ratio predicted to fit, by a model of costs per "
                   "decoded tet, ray-tet step, sample and boundary face (measured once per machine in under a "
                   "second and cached; no per-file calibration).")
@click.option("--pipeline", type=click.Choice(["streaming", "generic"]), default="streaming", show_default=True,
              help="streaming: decode, simplify and render in one pass; generic: decode all, simplify, render "
                   "(the paper's baseline).")
@click.option("--lean/--no-lean", default=False,
              help="Free each face of the mesh once no ray needs it, so memory holds the tets in flight, not the "
                   "whole mesh (5 M tets at 512²: 450 MB instead of 1.2 GB; renders 1.5-2x slower). "
                   "Off by default for the time it costs; pays off above ~1 M tets. .tetc, "
                   "--pipeline streaming only.")
@click.option("--stats", "show_stats", is_flag=True, help="Print one JSON object with timings and counts on stdout.")
@mesh_input_options
@force_option
@quiet_option
def render(input, output, tf_spec, opacity_model, mode, step, size, azimuth, elevation, zoom, ratio, level, budget, pipeline,
           lean, show_stats, scalar, q_file, q_var, cell_to_point, force, quiet):
    """Volume-render INPUT (a .tetc file or any mesh file) into a PNG.

    Tets are rendered as they are decoded: rays start on the boundary surface and walk inward
    from both ends of each segment. The camera follows VTK: 30 degree perspective fitted to the
    bounding sphere, then --azimuth, --elevation, refit, --zoom. Black background.
    """
    t_start = time.perf_counter()
    from gatun_py._atomic import check_output_path
    from gatun_py.render import Camera, load_transfer_function, write_png

    width, height = parse_size(size)
    if step is not None and not step > 0:
        raise OptionError(f"--step must be positive, got {step:g}")
    camera = Camera(width, height, azimuth, elevation, zoom)
    tf = load_transfer_function(tf_spec)
    if opacity_model is not None:
        tf = tf.with_opacity_model(opacity_model)
    check_output_path(output, force=force)  # fail before the work, not after
    if sum(x is not None for x in (ratio, level, budget)) > 1:
        raise click.UsageError("give at most one of --ratio, --level and --budget")
    from gatun_py.warmup import compile_for_render, load_kernels

    if not _kernels_cached():
        status("compiling the decoder and the renderer on two cores (first run only, under a minute; "
               "`make install` does it ahead)...", quiet)
        compile_for_render()

    startup_s = load_kernels(lean=lean) + (time.perf_counter() - t_start)
    t_start = time.perf_counter()  # total_s: from opening the input to the PNG written
    from gatun_py.pipeline.stream import View, is_tetc, render_mesh_file, render_tetc
    from gatun_py.simplify.levels import resolve_target

    view = View(camera, tf, mode, step, lean)
    planned = {}
    if is_tetc(input):
        from gatun_py.codec import TetcReader

        reader = TetcReader(input)
        target = resolve_target(reader, ratio=ratio, level=level)
        if budget is not None:
            from gatun_py.pipeline.budget import load_costs, plan_file_budget

            if load_costs() is None:
                status("measuring this machine's rendering costs for --budget (once, under a second)...", quiet)
            target, plan, _planner, _ = plan_file_budget(reader, view, budget)
            planned = {"predicted_s": plan.predicted_s, "budget_s": budget}
            if not plan.feasible:
                status(f"note: the budget of {budget:g} s cannot be met: rendering the coarsest level "
                       f"(predicted {plan.predicted_s:.3f} s)", quiet)
        n_tets = int(reader.level_meta(target.level)["tets"])
        t_frame = time.perf_counter()
        with progress_bar("rendering", n_tets if n_tets >= 100_000 else 0, quiet) as update:
            result = render_tetc(reader, view, pipeline=pipeline, target=target, progress=update)
    else:
        if ratio is not None or level is not None or budget is not None:
            raise OptionError("--ratio, --level and --budget need a .tetc file with a merge forest "
                              "(make one with: tetc compress INPUT -o FILE.tetc)")
        result = render_mesh_file(input, view, read_kwargs=read_kwargs(scalar, q_file, q_var, cell_to_point))
        for note in result.stats.pop("notes", []):
            status(f"note: {note}", quiet)
    write_png(output, result.image, force=force)
    if planned:  # the machine's costs learn from every budget render
        from gatun_py.pipeline.budget import remember_frame

        remember_frame(_planner, result.stats, total_s=time.perf_counter() - t_frame)
    st = result.stats
    st.pop("filter", None)
    st.update(planned)
    st["total_s"] = time.perf_counter() - t_start
    st["startup_s"] = startup_s  # imports and loading the compiled kernels, before the input is opened
    st["peak_rss_mb"] = peak_rss_mb()
    st["output"] = str(output)
    st["size"] = [width, height]
    if st["rays_hit"] == 0:
        status("note: no ray hits the mesh; the image is black", quiet)
    if st["rays_unfinished"]:
        status(f"warning: {st['rays_unfinished']} rays could not be completed", quiet)
    if show_stats:
        echo_json(st)
    else:
        status(f"wrote {output} ({width}x{height}, {st['tets_rendered']} tets, {st['total_s']:.2f} s)", quiet)
