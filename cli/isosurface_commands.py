"""``tetc isosurface``: isosurfaces straight from the compressed file, simplified on the fly."""

from __future__ import annotations

import math

import click

from gatun_py._runtime import load_isosurface_kernels, peak_rss_mb
from .options import (READ_PARAMS, camera_options, check_step, echo_json, force_option, jobs_option, mesh_input_options,
                      progress_bar, quiet_option, records, require_file, status)


def _finite(ctx, param, values):
    for v in values:
        if not math.isfinite(v):
            raise click.BadParameter(f"{v} is not a finite number")
    return values


@click.command("isosurface")
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("--value", "values", type=float, multiple=True, required=True, callback=_finite, metavar="V",
              help="Isovalue (repeat for several surfaces; they share one output, told apart by the "
                   "'scalar' point array).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output surface: .vtp, .ply, .obj, .stl, .vtk, .vtu, .off, ... (from the extension).")
@click.option("--ratio", type=click.FloatRange(0.0, 1.0, min_open=True), default=None,
              help="Faces kept / faces extracted, in (0, 1]; simplified while extracting (QEM edge "
                   "collapses; a vertex is touched only once every tet around it has been decoded).")
@click.option("--faces", type=click.IntRange(min=1), default=None, help="Target face count (per isovalue) instead of --ratio.")
@click.option("--batch-faces", type=click.IntRange(min=1), default=100_000, show_default=True, metavar="B",
              help="Run the collapse queue after every B new faces. Larger B: closer to in-core "
                   "quality, more memory (about ratio x faces + B faces).")
@click.option("--level", type=click.IntRange(min=0), default=None,
              help=".tetc only: extract from stored pre-simplified level i (a coarser, crack-free start).")
@click.option("--mesh-ratio", type=click.FloatRange(0.0, 1.0), default=None,
              help=".tetc only: extract from the tet mesh simplified on the fly to this ratio (merged / all "
                   "vertices, as tetc render --ratio).")
@click.option("--importance-tf", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help='Importance over the gradient magnitude at the surface, JSON {"points": [{"x": X, "w": W}, ...]} '
                   "(x in scalar range per bounding-box diagonal unless \"absolute\": true): faces with weight W "
                   "keep their detail until their error is W times larger.")
@click.option("--png", type=click.Path(dir_okay=False), default=None,
              help="Also write a shaded preview (Lambert, headlight) with the camera options below, framing "
                   "the surface.")
@click.option("--frame-volume", is_flag=True,
              help="Preview: frame the whole mesh instead of the surface (to line up with tetc render's view).")
@camera_options("Preview", size_default="512", size_help="size in pixels.")
@click.option("--stats", "show_stats", is_flag=True,
              help="Print one JSON object on stdout: timings, counts, peak memory and the locked band per batch.")
@mesh_input_options
@jobs_option
@force_option
@quiet_option
@records("detail", "view", "read", detail={"ratio": "mesh_ratio"},
         only={"ratio", "level", "size", "azimuth", "elevation", "zoom", *READ_PARAMS})
def isosurface(input, values, output, ratio, faces, batch_faces, detail, view, read, importance_tf, png, frame_volume,
               show_stats, jobs, force, quiet):
    """Extract the isosurface(s) of INPUT (a .tetc file or any mesh file) at --value V.

    Marching tetrahedra on each decoded batch, so the surface is exact (no ambiguous cases) and
    crack-free; with --ratio or --faces it is simplified while it is extracted, and the
    full-resolution surface is never held in memory. Normals point toward lower scalar values.

    Of a bricked file (tetc compress --bricks K), only the bricks whose stored scalar range
    contains an isovalue are decoded, --jobs at a time; the surface is the whole mesh's, one
    piece across the cuts.

    \b
    Examples:
      tetc isosurface bf.tetc --value 2.5 -o iso.vtp
      tetc isosurface bf.tetc --value 1.5 --value 3 --ratio 0.1 -o iso.ply --png iso.png
      tetc isosurface big.tetc --value 0.3 --faces 50000 --stats -o iso.ply
    """
    check_step(input, read.time_step)
    from gatun_py._runtime import announce, is_tetc

    if ratio is not None and faces is not None:
        raise click.UsageError("give either --ratio or --faces, not both")
    level = detail.level
    from gatun_py.contour.paths import check_surface_path

    require_file(input)  # before saying that it compiles
    check_surface_path(output, force=force)  # fail before the work, not after
    announce((["decoder"] if is_tetc(input) else []) + ["isosurface"], quiet=quiet)
    from gatun_py.contour import isosurface as extract  # after the notice: numba loads with it

    if png is not None:
        from gatun_py._runtime import check_output_path
        from gatun_py.raycast.options import image_format

        from gatun_py.contour.extract import MAX_PREVIEW_PIXELS

        w, h = view.size
        if w * h > MAX_PREVIEW_PIXELS:
            raise click.BadParameter(f"{w}x{h} is more than {MAX_PREVIEW_PIXELS} pixels", param_hint="--size")
        check_output_path(png, force=force)
        image_format(png)
    total = _expected_tets(input, values, level)
    # the kernels first, on a tiny file: LLVM's pages that loading them touched are then handed
    # back before the data arrives (see load_kernels)
    load_isosurface_kernels(input, simplify=ratio not in (None, 1.0) or faces is not None)
    with progress_bar("extracting", total if total >= 200_000 else 0, quiet) as update:
        last = [0]

        def progress(done):
            update(done - last[0])
            last[0] = done

        surf = extract(input, values=list(values), ratio=ratio, faces=faces, batch_faces=batch_faces, level=level,
                       ratio_mesh=detail.ratio, importance_tf=importance_tf, read_kwargs=read.kwargs(), jobs=jobs,
                       progress=progress)
    st = surf.stats
    lo_s, hi_s = st["scalar_range"]
    for v in st["values_outside_range"]:
        status(f"note: isovalue {v:g} is outside the scalar range [{lo_s:g}, {hi_s:g}]: its surface is empty", quiet)
    surf.save(output, force=force)
    if png is not None:
        surf.save_preview(png, size=view.size, azimuth=view.azimuth, elevation=view.elevation, zoom=view.zoom,
                          frame="volume" if frame_volume else "surface", force=force)
    st["peak_rss_mb"] = peak_rss_mb()
    st["output"] = str(output)
    if show_stats:
        echo_json(st)
    else:
        bricks = st.get("bricks")
        of_bricks = (f", {bricks['bricks_decoded']} of {bricks['bricks']} bricks decoded" if bricks else "")
        status(f"wrote {output} ({surf.n_triangles} triangles from {st['faces_extracted']} extracted{of_bricks}, "
               f"{st['total_s']:.2f} s)", quiet)


def _expected_tets(path, values, level) -> int:
    """Tets the stream will carry, for the progress bar (0 when not cheaply known): of a bricked
    file, those of the bricks an isovalue cuts."""
    try:
        from gatun_py.codec import TetcReader
        from gatun_py.contour.bricked import bricks_to_decode

        reader = TetcReader(path)
        level = level or 0
        if reader.n_bricks > 1:
            return sum(int(reader.brick(k).level_meta(level)["tets"]) for k in bricks_to_decode(reader, values, level))
        return int(reader.level_meta(level)["tets"])
    except Exception:  # not a .tetc (or unreadable: the extraction reports that properly)
        return 0

