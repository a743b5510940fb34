"""``tetc render``: streaming decode + object-space ray casting into a PNG."""

from __future__ import annotations

import re
import time
from pathlib import Path

import click

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


def _peak_rss_mb() -> float:
    import resource
    import sys

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


def _kernels_cached() -> bool:
    """Whether numba has compiled the render kernels into its cache already."""
    from gatun_py.render import _raycast_kernels

    cache_dir = Path(_raycast_kernels.__file__).parent / "__pycache__"
    return any(cache_dir.glob("_raycast_kernels.*.nbc"))


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output PNG.")
@click.option("--tf", "tf_spec", default="default", show_default=True, metavar="NAME|FILE",
              help="Transfer function: a preset (default, bluntfin, combustion, post, fire), a JSON file "
                   "(project or ParaView format) or a matplotlib colormap name.")
@click.option("--mode", type=click.Choice(["volume", "face"]), default="volume", show_default=True,
              help="volume: uniform samples every --step; face: one sample per tet (at its faces).")
@click.option("--step", type=float, default=None,
              help="Sample spacing for --mode volume [default: half the median boundary edge].")
@click.option("--size", default="256", show_default=True, metavar="W[xH]", help="Image size in pixels.")
@click.option("--azimuth", type=float, default=0.0, show_default=True, help="Degrees about the view-up axis.")
@click.option("--elevation", type=float, default=0.0, show_default=True, help="Degrees up about the focal point.")
@click.option("--zoom", type=float, default=1.0, show_default=True, help="Zoom factor (VTK's Camera.Zoom).")
@click.option("--stats", "show_stats", is_flag=True, help="Print one JSON object with timings and counts on stdout.")
@mesh_input_options
@force_option
@quiet_option
def render(input, output, tf_spec, mode, step, size, azimuth, elevation, zoom, show_stats, scalar, q_file, q_var,
           cell_to_point, force, quiet):
    """Volume-render INPUT (a .tetc file or any mesh file) into a PNG.

    Tets are rendered as they are decoded: rays start on the boundary surface and walk inward
    from both ends of each segment. The camera follows VTK: 30 degree perspective fitted to the
    bounding sphere, then --azimuth, --elevation, refit, --zoom. Black background.
    """
    t_start = time.perf_counter()
    from gatun_py._atomic import check_output_path
    from gatun_py.render import Camera, load_transfer_function, render_batches, write_png

    width, height = parse_size(size)
    if step is not None and not step > 0:
        raise OptionError(f"--step must be positive, got {step:g}")
    camera = Camera(width, height, azimuth, elevation, zoom)
    tf = load_transfer_function(tf_spec)
    check_output_path(output, force=force)  # fail before the work, not after
    if not _kernels_cached():
        status("compiling the renderer (first run only, up to a minute)...", quiet)

    if Path(input).suffix.lower() == ".tetc":
        from gatun_py.codec.tetcfile import TetcReader

        reader = TetcReader(input)
        lv = reader.level_meta(0)
        batches = reader.iter_decode(0)
        n_tets = int(lv["tets"])
        scalar_range = lv.get("scalar_range") or reader.meta.get("scalar_range")
    else:
        from gatun_py.mesh import read_mesh
        from gatun_py.render import mesh_batches

        t0 = time.perf_counter()
        mesh, report = read_mesh(input, **read_kwargs(scalar, q_file, q_var, cell_to_point))
        read_s = time.perf_counter() - t0
        for note in report.notes:
            status(f"note: {note}", quiet)
        batches = mesh_batches(mesh)
        n_tets = mesh.n_tets
        scalar_range = mesh.scalar_range

    with progress_bar("rendering", n_tets if n_tets >= 100_000 else 0, quiet) as update:
        result = render_batches(batches, camera, tf, mode=mode, step=step, scalar_range=scalar_range,
                                expected_tets=n_tets, progress=update)
    write_png(output, result.image, force=force)
    st = result.stats
    if Path(input).suffix.lower() != ".tetc":
        st["decode_s"] += read_s
    st["total_s"] = time.perf_counter() - t_start
    st["peak_rss_mb"] = _peak_rss_mb()
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
