"""``tetc``: compress, simplify and volume-render tetrahedral meshes.

Exit codes: 0 success, 1 error (one line on stderr), 2 usage error.
"""

from __future__ import annotations

import sys

import click

from gatun_py import __version__
from gatun_py.errors import TetcError

from .options import echo_json, force_option, json_option, mesh_input_options, quiet_option, read_kwargs, status


class TetcGroup(click.Group):
    """A click group that turns library errors into one line and exit code 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except TetcError as e:
            click.echo(f"tetc: error: {e}", err=True)
            ctx.exit(1)
        except MemoryError:
            click.echo("tetc: error: out of memory", err=True)
            ctx.exit(1)
        except KeyboardInterrupt:
            click.echo("tetc: interrupted", err=True)
            ctx.exit(130)


@click.group(cls=TetcGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="tetc")
def tetc():
    """Compress tetrahedral volume meshes losslessly, simplify them on the fly and volume-render
    them in one streaming pass.

    \b
    Typical use:
      tetc compress mesh.vtu -o mesh.tetc        lossless, with pre-simplified levels
      tetc render mesh.tetc -o image.png         streaming decode + render
      tetc render mesh.tetc -o f.png --budget 0.1   fit a frame-time budget
      tetc info mesh.tetc --json                 sizes, levels, bits per tet
    """


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output mesh; format from the extension (.vtu, .vtk, .msh, .xdmf, ...).")
@mesh_input_options
@click.option("--refine", type=click.IntRange(min=1, max=16), default=1, show_default=True, metavar="K",
              help="PLOT3D only: cut every grid cell into K×K×K cells on its trilinear map before the "
                   "tet split; the scalar is trilinearly interpolated, so this makes larger meshes "
                   "for scale tests, not new data.")
@force_option
@quiet_option
def convert(input, output, scalar, q_file, q_var, cell_to_point, refine, force, quiet):
    """Convert INPUT (any readable mesh or PLOT3D grid) into a linear tet mesh file.

    Hexahedra, wedges and pyramids are split into tets conformingly; the scalar is written as
    point data. Floats are kept bit for bit (with --refine, the original grid points are).
    """
    import os

    from gatun_py.mesh import read_mesh, write_mesh
    from gatun_py.mesh.plot3d import is_plot3d_input

    if refine != 1 and os.path.isfile(input) and not is_plot3d_input(input, q_file):
        raise click.UsageError("--refine needs a PLOT3D grid input (structured XYZ + Q files)")
    mesh, report = read_mesh(input, refine=refine, **read_kwargs(scalar, q_file, q_var, cell_to_point))
    for note in report.notes:
        status(f"note: {note}", quiet)
    write_mesh(mesh, output, force=force)
    status(f"wrote {output}: {mesh.n_points} points, {mesh.n_tets} tets", quiet)


def mesh_info(mesh, report) -> dict:
    lo, hi = mesh.bbox
    return {
        "points": mesh.n_points,
        "tets": mesh.n_tets,
        "boundary_faces": int(len(mesh.boundary_faces())),
        "zero_volume_tets": report.zero_volume_tets,
        "reoriented_tets": report.reoriented_tets,
        "coincident_points": report.coincident_points,
        "unreferenced_points": report.unreferenced_points,
        "bbox": [lo.tolist(), hi.tolist()],
        "scalar": mesh.scalar_name,
        "scalar_range": list(mesh.scalar_range),
        "notes": list(report.notes),
    }


@tetc.command()
@click.argument("input", type=click.Path(dir_okay=False))
@mesh_input_options
@json_option
def info(input, scalar, q_file, q_var, cell_to_point, as_json):
    """Describe INPUT: sizes, boundary, degenerate tets, and for .tetc files the codec figures."""
    from pathlib import Path

    if Path(input).suffix.lower() == ".tetc":
        from gatun_py.codec.info import tetc_info

        data = tetc_info(input)
    else:
        from gatun_py.mesh import read_mesh

        data = mesh_info(*read_mesh(input, **read_kwargs(scalar, q_file, q_var, cell_to_point)))
    if as_json:
        echo_json(data)
        return
    for k, v in data.items():
        if isinstance(v, list) and v and isinstance(v[0], dict):
            click.echo(f"{k}:")
            for row in v:
                click.echo("  " + ", ".join(f"{a}={b}" for a, b in row.items()))
        else:
            click.echo(f"{k}: {v}")


# Commands of the later stages register themselves on the group when their module is imported.
for _module in ("codec_commands", "render_commands", "compare"):
    try:
        __import__(f"{__package__}.{_module}")
    except ModuleNotFoundError as _e:  # stage not built yet in this checkout
        if _e.name != f"{__package__}.{_module}":
            raise


from .isosurface_commands import isosurface as _isosurface  # noqa: E402

tetc.add_command(_isosurface)


def main(argv=None):
    return tetc.main(args=argv, prog_name="tetc")


if __name__ == "__main__":
    sys.exit(main())
