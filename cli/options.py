"""Option decorators and helpers shared by the ``tetc`` commands."""

from __future__ import annotations

import contextlib
import functools
import json
import sys

import click

from gatun_py.mesh.plot3d import Q_VARIABLES


def mesh_input_options(f):
    """--scalar, --q, --q-var, --cell-to-point: how to read a mesh file."""
    f = click.option("--cell-to-point", is_flag=True,
                     help="Allow a cell-data scalar, averaged to the points (volume-weighted).")(f)
    f = click.option("--q-var", type=click.Choice(Q_VARIABLES), default="density", show_default=True,
                     help="PLOT3D: which quantity of the Q file becomes the scalar.")(f)
    f = click.option("--q", "q_file", type=click.Path(dir_okay=False), default=None,
                     help="PLOT3D: the Q (solution) file; default: the ...q... file beside an ...xyz... grid.")(f)
    f = click.option("--scalar", default=None, metavar="NAME",
                     help="Point-data array to use as the scalar (needed when the file has several).")(f)
    return f


def read_kwargs(scalar, q_file, q_var, cell_to_point) -> dict:
    return dict(scalar=scalar, q_file=q_file, q_var=q_var, cell_to_point=cell_to_point)


force_option = click.option("--force", "-f", is_flag=True, help="Overwrite the output file if it exists.")
quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress output on stderr.")
json_option = click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")


def echo_json(obj) -> None:
    click.echo(json.dumps(obj, indent=2, default=_json_default))


def _json_default(o):
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def status(msg: str, quiet: bool) -> None:
    """A one-line status message on stderr (so stdout stays clean for --json / --stats)."""
    if not quiet:
        click.echo(msg, err=True)


@contextlib.contextmanager
def progress_bar(label: str, total: int, quiet: bool):
    """Yield an ``update(n)`` callable drawing a progress bar on stderr; a no-op when quiet."""
    if quiet or total <= 0:
        yield lambda n=1: None
        return
    with click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True) as bar:
        yield bar.update


def with_progress(f):
    """Inject ``progress(label, total)`` -> context manager honouring --quiet."""

    @functools.wraps(f)
    def wrapper(*args, quiet=False, **kwargs):
        return f(*args, quiet=quiet, **kwargs)

    return quiet_option(wrapper)
