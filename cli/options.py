"""Option types, decorators and output helpers shared by the ``tetc`` commands.

Option values are checked by click types, so a bad value is a usage error (exit 2) with click's
message naming the option; whatever depends on the input file is checked by the library (exit 1).
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import signal
import sys
import threading

import click

from gatun_py.errors import OptionError, ReadError
from gatun_py.limits import MAX_IMAGE_SIDE, MAX_ZOOM, Q_VARIABLES  # light: parsing the options loads no numba
from gatun_py.pipeline.requests import Cluster, Detail, ForestOptions, ReadOptions, View  # numba-free: the records check the options

# record field -> the click parameter that gives it, per record a command receives
VIEW_PARAMS = {"size": "size", "tf": "tf_spec", "azimuth": "azimuth", "elevation": "elevation", "zoom": "zoom",
               "scalar_range": "scalar_range", "mode": "mode", "step": "step", "opacity_model": "opacity_model",
               "background": "background", "colorbar": "colorbar", "lean": "lean", "component": "component"}
DETAIL_PARAMS = {"ratio": "ratio", "level": "level", "budget": "budget", "selective": "selective", "tets": "tets"}
READ_PARAMS = {"scalar": "scalar", "q_file": "q_file", "q_var": "q_var", "cell_to_point": "cell_to_point",
               "time_step": "time_step"}
FOREST_PARAMS = {"levels": "n_levels", "mesh_only": "mesh_only", "w_density": "w_density", "w_geometry": "w_geometry",
                 "w_sample": "w_sample", "dependencies": "dependencies"}
CLUSTER_PARAMS = {"workers": "workers", "scheduler": "scheduler", "timeout": "timeout"}
_RECORDS = {"view": (View, VIEW_PARAMS), "detail": (Detail, DETAIL_PARAMS), "read": (ReadOptions, READ_PARAMS),
            "forest": (ForestOptions, FOREST_PARAMS), "cluster": (Cluster, CLUSTER_PARAMS)}
# the options whose flag is not the parameter's name with dashes
_FLAGS = {"tf_spec": "--tf", "scalar_range": "--range", "q_file": "--q", "n_levels": "--levels"}


class FiniteFloat(click.ParamType):
    """A finite float, optionally bounded (``lo_open``: strictly above ``lo``)."""

    name = "float"

    def __init__(self, lo=None, hi=None, *, lo_open=False):
        self.lo, self.hi, self.lo_open = lo, hi, lo_open

    def convert(self, value, param, ctx):
        try:
            v = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo):
            self.fail(f"{value} must be {'>' if self.lo_open else '>='} {self.lo:g}", param, ctx)
        if self.hi is not None and v > self.hi:
            self.fail(f"{value} must be <= {self.hi:g}", param, ctx)
        return v


class ImageSize(click.ParamType):
    """``256`` or ``320x200``: whole pixels in 1..MAX_IMAGE_SIDE."""

    name = "W[xH]"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        m = re.fullmatch(r"\s*(\d+)\s*(?:[xX*]\s*(\d+)\s*)?", str(value))
        if not m:
            self.fail(f"{value!r} is not W or WxH in pixels", param, ctx)
        w = int(m.group(1))
        h = int(m.group(2)) if m.group(2) is not None else w
        if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
            self.fail(f"{value!r}: each side must be 1..{MAX_IMAGE_SIDE} pixels", param, ctx)
        return w, h


class Colour(click.ParamType):
    name = "COLOUR"

    def convert(self, value, param, ctx):
        from gatun_py.raycast.options import parse_colour  # start-up time (numpy loads after the notice)

        try:
            return parse_colour(value)
        except ValueError as e:
            self.fail(str(e), param, ctx)


POSITIVE = FiniteFloat(0.0, lo_open=True)
ANGLE = FiniteFloat()
RATIO = FiniteFloat(0.0, 1.0)
ZOOM = FiniteFloat(1.0 / MAX_ZOOM, MAX_ZOOM)


def mesh_input_options(f):
    """--scalar, --q, --q-var, --cell-to-point: how to read a mesh file."""
    f = click.option("--cell-to-point", is_flag=True,
                     help="Use a cell-data array, averaged to the points (volume-weighted): the only one, or "
                          "the one --scalar names.")(f)
    f = click.option("--q-var", type=click.Choice(Q_VARIABLES), default="density", show_default=True,
                     help="PLOT3D: which quantity of the Q file becomes the scalar.")(f)
    f = click.option("--q", "q_file", type=click.Path(dir_okay=False), default=None,
                     help="PLOT3D: the Q (solution) file; default: the ...q... file beside an ...xyz... grid.")(f)
    f = click.option("--time-step", type=int, default=None, metavar="T",
                     help="Exodus and VTKHDF: the time step whose arrays to read (0-based, -1 the last) "
                          "[default: the last; compress stores every step]. A .tetc time series: the "
                          "step to use [default: 0].")(f)
    f = click.option("--scalar", default=None, metavar="NAME",
                     help="Point-data array to use as the scalar (needed when the file has several).")(f)
    return f


def selective_options(*, budget: bool):
    """--selective and --tets N: a view- and transfer-function-dependent cut of the merge forest
    (``budget``: the command has --budget, which --selective takes too)."""
    amounts = "--ratio, --tets or --budget" if budget else "--ratio or --tets"

    def decorate(f):
        f = click.option("--tets", type=click.IntRange(min=1), default=None, metavar="N",
                         help="With --selective: at most N tets (above the mesh's count: the full mesh).")(f)
        f = click.option("--selective", is_flag=True,
                         help="Simplify where the view and transfer function say it matters least (hidden, "
                              f"transparent, small on screen), never flipping a tet; with {amounts}. A file "
                              "compressed without `tetc compress --dependencies` is simplified uniformly, with "
                              "a note.")(f)
        return f

    return decorate


def _helper(prefix: str, text: str) -> str:
    return f"{prefix}: {text}" if prefix else text[0].upper() + text[1:]


def camera_options(prefix: str = "", *, size_default: str = "256", size_help: str = "image size in pixels."):
    """--size, --azimuth, --elevation, --zoom: the camera, as ``tetc render`` takes it.

    ``prefix`` starts each help text where the options only matter with another one, e.g.
    "With --selective" or "Preview".
    """

    def decorate(f):
        f = click.option("--zoom", type=ZOOM, default=1.0, show_default=True,
                         help=_helper(prefix, "zoom factor (VTK's Camera.Zoom)."))(f)
        f = click.option("--elevation", type=ANGLE, default=0.0, show_default=True,
                         help=_helper(prefix, "degrees up about the focal point."))(f)
        f = click.option("--azimuth", type=ANGLE, default=0.0, show_default=True,
                         help=_helper(prefix, "degrees about the view-up axis."))(f)
        f = click.option("--size", type=ImageSize(), default=size_default, show_default=True,
                         help=_helper(prefix, size_help))(f)
        return f

    return decorate


def transfer_function_options(prefix: str = ""):
    """--tf and --range: the transfer function and the scalar range it is normalised to."""

    def decorate(f):
        f = click.option("--range", "scalar_range", type=(FiniteFloat(), FiniteFloat()), default=None,
                         metavar="MIN MAX",
                         help=_helper(prefix, "scalar range the transfer function is normalised to [default: the "
                                              "mesh's]. Fix it to compare time steps or files."))(f)
        f = click.option("--tf", "tf_spec", default="default", show_default=True, metavar="NAME|FILE",
                         help=_helper(prefix, "transfer function: a preset (default, bluntfin, combustion, post, "
                                              "fire), a JSON file (project or ParaView format) or a matplotlib "
                                              "colormap name."))(f)
        return f

    return decorate


def records(*names: str, only=None, **params):
    """Give the command the request records ``names`` (``"view"``, ``"detail"``, ``"read"``,
    ``"forest"``) built from its options, in place of those options (:data:`VIEW_PARAMS`...;
    ``params``: {field: parameter} where a command names an option otherwise, e.g.
    ``detail={"ratio": "mesh_ratio"}``; ``only``: the record fields the command has options for,
    when not all). Put it right above the function, below the options.

    The records check every value and combination (:mod:`gatun_py.pipeline.requests`); what they
    refuse is a usage error (exit 2) naming the command's options. What the library finds wrong
    with a file an option names (a transfer-function JSON) stays an error of the input (exit 1).
    """

    def decorate(f):
        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            flags = {}
            for name in names:
                cls, given = _RECORDS[name]
                fields = {field: param for field, param in {**given, **params.get(name, {})}.items()
                          if param in kwargs and (only is None or field in only)}
                values = {field: kwargs.pop(param) for field, param in fields.items()}
                flags.update({field: _FLAGS.get(param, "--" + param.replace("_", "-")) for field, param in fields.items()})
                try:
                    kwargs[name] = cls(**values)
                except OptionError as e:
                    if not getattr(e, "fields", None):
                        raise
                    raise click.UsageError(_name_flags(str(e), flags)) from None
            return f(*args, **kwargs)

        return wrapper

    return decorate


def _name_flags(message: str, flags: dict) -> str:
    """A record's message with its field names as the command's options (``selective=True`` -> ``--selective``).

    >>> _name_flags("tets needs selective=True", {"tets": "--tets", "selective": "--selective"})
    '--tets needs --selective'
    """
    for field in sorted(flags, key=len, reverse=True):
        message = re.sub(rf"(?<![\w-]){field}(=True)?(?![\w])", flags[field], message)
    return message


def require_file(path) -> None:
    """Refuse a missing input before anything slow (compiling kernels, starting a cluster) runs."""
    if not os.path.isfile(path):
        raise ReadError(f"{path}: no such file")


def read_kwargs(scalar, q_file, q_var, cell_to_point, time_step=None) -> dict:
    return dict(scalar=scalar, q_file=q_file, q_var=q_var, cell_to_point=cell_to_point, time_step=time_step)


def output_option(help_text: str, callback=None):
    return click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help=help_text,
                        callback=callback)


def tetc_name(ctx, param, value):
    """An output ``.tetc`` file: a name with another extension (``-o x.png``, ``-o x.vtu``) is most
    likely a mix-up with render or decompress, and would hide a .tetc file behind a wrong name."""
    if value is not None and not str(value).lower().endswith(".tetc"):
        raise click.BadParameter(f"{value!r}: tetc compress writes a .tetc file, so name it NAME.tetc "
                                 "(images come from tetc render, mesh files from tetc decompress)")
    return value


force_option = click.option("--force", "-f", is_flag=True, help="Overwrite the output file if it exists.")
jobs_option = click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, metavar="N",
                           help="Cores to use on the bricks of a bricked file [default: all].")
def _silence_notices(ctx, param, value):
    if value:
        from gatun_py._runtime import silence

        silence()  # the first-run compile notice too
    return value


quiet_option = click.option("--quiet", "-q", is_flag=True, callback=_silence_notices,
                            help="No progress output on stderr.")
json_option = click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")


def echo_json(obj) -> None:
    click.echo(json.dumps(obj, indent=2, default=_json_default))


def _json_default(o):
    tolist = getattr(o, "tolist", None)  # numpy scalars and arrays (numpy is not imported to parse options)
    if tolist is not None:
        return tolist()
    raise TypeError(type(o).__name__)


def status(msg: str, quiet: bool) -> None:
    """A one-line status message on stderr (so stdout stays clean for --json / --stats)."""
    if not quiet:
        click.echo(msg, err=True)


def logger(quiet: bool):
    """The ``log`` callable the library's verbs take: one line on stderr unless --quiet."""
    return lambda msg: status(msg, quiet)


@contextlib.contextmanager
def interruptible():
    """Let Ctrl-C end the process at once while compiled kernels run.

    numba's kernels hold the interpreter for as long as they run, so Python's own SIGINT handler
    (KeyboardInterrupt) would only fire when a kernel returns: seconds or minutes into a large
    render. Inside this block SIGINT has its default action, which ends the process immediately.
    Nothing is lost: outputs are written atomically after the block, so an interrupted render
    leaves no file behind.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def progress_reporter(label: str, quiet: bool, *, min_total: int = 100_000):
    """Yield a ``progress(done, total)`` callable (the library verbs' protocol) that draws a bar on
    stderr once it knows the total, for work of at least ``min_total`` items; a no-op when quiet.
    The bar is closed (its line ended) as soon as ``done`` reaches ``total``, so that the status
    lines the verb prints afterwards start on a line of their own."""
    state = {"bar": None, "done": 0, "closed": False}

    def close() -> None:
        if state["bar"] is not None and not state["closed"]:
            state["closed"] = True
            state["bar"].__exit__(None, None, None)

    def progress(done: int, total: int) -> None:
        if quiet or total < min_total or state["closed"]:
            return
        if state["bar"] is None:
            state["bar"] = click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True)
            state["bar"].__enter__()
        state["bar"].update(done - state["done"])
        state["done"] = done
        if done >= total:
            close()

    try:
        yield progress
    finally:
        close()


@contextlib.contextmanager
def progress_bar(label: str, total: int, quiet: bool):
    """Yield an ``update(n)`` callable drawing a progress bar on stderr; a no-op when quiet."""
    if quiet or total <= 0:
        yield lambda n=1: None
        return
    with click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True) as bar:
        yield bar.update


def check_step(input, step=None, at_time=None) -> None:
    """A usage error (exit 2, one line) when a .tetc INPUT has no step ``step`` or none at ``at_time``;
    anything else about the file is the library's to report."""
    if step is None and at_time is None:
        return
    from gatun_py.pipeline.stream import is_tetc

    if not os.path.isfile(input) or not is_tetc(input):
        return
    import gatun_py
    from gatun_py.errors import OptionError

    try:
        gatun_py.open(input).step_index(step=step, time=at_time)
    except OptionError as e:
        raise click.BadParameter(str(e), param_hint="'--time'" if at_time is not None else "'--step'") from None
