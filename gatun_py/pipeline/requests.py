"""What a render asks for, as small frozen records that check themselves once, and the frame it returns.

* :class:`View`: how to draw (image size, camera angles, transfer function, mode, sampling step,
  background, colour bar, early ray termination);
* :class:`Detail`: how much of the mesh to draw (a uniform ratio or stored level, a selective
  ratio or tet count, or a frame-time budget);
* :class:`~gatun_py.read_options.ReadOptions`: how to read a mesh file (re-exported here);
* :class:`ForestOptions`: how compression builds the merge forest and levels;
* :class:`Cluster`: a local or running Dask cluster for the work that spreads over processes;
* :class:`Frame`: the picture a render returns, and its encoded bytes.

Every check of a render option is in ``__post_init__`` here: the verbs, the command line and the
viewer build these records and check nothing themselves, so an impossible value gives the same
:class:`~gatun_py.errors.OptionError` and message wherever it comes from. The module loads no
numba (the command line builds the records before any kernel loads).

:func:`split_options` maps the flat keywords of a verb (``render(f, azimuth=30, ratio=0.9)``, the
shorthand scripts use) onto the records, in one place.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import OptionError
from ..limits import MAX_IMAGE_SIDE, MODES
from ..read_options import ReadOptions
from ..raycast.camera import Camera
from ..raycast.image import image_bytes, parse_colour, write_image
from ..raycast.transfer import load_transfer_function

__all__ = ["View", "Detail", "ReadOptions", "ForestOptions", "Cluster", "Frame", "split_options", "check_number", "refused"]


def refused(message: str, *fields: str) -> OptionError:
    """An OptionError about the values of ``fields`` (record field names): the command line turns it
    into a usage error naming its own options (``ratio`` -> ``--ratio``)."""
    e = OptionError(message)
    e.fields = fields
    return e


def check_number(name, v, *, lo=None, lo_open=False, hi=None, allow_none=True):
    """``v`` as a float, or None when allowed; OptionError naming ``name`` when not finite or out of bounds."""
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise refused(f"{name} must be a finite number, got {v!r}", name)
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise refused(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {v!r}", name)
    if hi is not None and v > hi:
        raise refused(f"{name} must be <= {hi:g}, got {v!r}", name)
    return float(v)


def _image_size(size) -> tuple[int, int]:
    try:
        w, h = (size, size) if isinstance(size, (int, np.integer)) else tuple(size)
    except (TypeError, ValueError):
        w = h = None
    for v in (w, h):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v <= MAX_IMAGE_SIDE:
            raise refused(f"image size must be whole pixels in 1..{MAX_IMAGE_SIDE}, got {size!r}", "size")
    return int(w), int(h)


def _set(obj, name, value) -> None:
    object.__setattr__(obj, name, value)  # a frozen record normalises its own fields once, when made


@dataclass(frozen=True, eq=False)
class View:
    """How to draw a frame.

    Parameters
    ----------
    size : int or (int, int)
        Image width and height in pixels (kept as ``(width, height)``).
    tf : str, path-like, dict or TransferFunction
        Transfer function: a preset name (``default``, ``bluntfin``, ``combustion``, ``post``,
        ``fire``), a JSON file (project or ParaView format), a matplotlib colormap name, or a dict.
        Kept loaded, with ``opacity_model`` applied.
    azimuth, elevation, zoom : float
        VTK's camera: 30 degree perspective fitted to the bounding sphere, then these.
    mode : {"volume", "face"}
        Uniform samples every ``step``, or one sample per tet at its faces.
    step : float, optional
        Sample spacing (default: half the median boundary edge of the full mesh, at most 1/512 of
        its bounding-box diagonal; a file compressed by an earlier version keeps the step it recorded).
    scalar_range : (float, float), optional
        The range the transfer function is normalised to (default: the mesh's). Fix it to compare
        files or time steps.
    opacity_model : {"gatun", "vtk"}, optional
        How opacity accumulates (see :mod:`gatun_py.raycast.transfer`).
    background : str or (r, g, b)
        A colour name, ``#rrggbb`` or RGB in 0..1 (kept as RGB in 0..1).
    colorbar : bool
        Add a colour bar with the scalar's name and range on the right.
    lean : bool
        Hold only the tets in flight (less memory, slower).
    terminate : bool
        Stop each ray where its opacity reaches 0.99 (early ray termination, as VTK; what lies behind
        would change the pixel by less than 1 %). Off: every ray is walked to its end, as a bricked
        file's bricks are (sort-last compositing needs whole segments).
    component : None, int or "magnitude"
        ``.tetc``: for a vector array, the component to render or its magnitude.

    Raises
    ------
    OptionError
        Any value out of range, an unknown mode, a transfer function that cannot be loaded.

    Examples
    --------
    >>> v = View(size=(320, 200), azimuth=30, tf="bluntfin")
    >>> v.size, v.camera.azimuth, v.background
    ((320, 200), 30.0, (0.0, 0.0, 0.0))
    """

    size: object = 256
    tf: object = "default"
    azimuth: float = 0.0
    elevation: float = 0.0
    zoom: float = 1.0
    mode: str = "volume"
    step: float | None = None
    scalar_range: tuple | None = None
    opacity_model: str | None = None
    background: object = "black"
    colorbar: bool = False
    lean: bool = False
    terminate: bool = True
    component: object = None

    def __post_init__(self):
        _set(self, "size", _image_size(self.size))
        _set(self, "azimuth", check_number("azimuth", self.azimuth, allow_none=False))
        _set(self, "elevation", check_number("elevation", self.elevation, allow_none=False))
        _set(self, "zoom", check_number("zoom", self.zoom, lo=0.0, lo_open=True, allow_none=False))
        _set(self, "step", check_number("step", self.step, lo=0.0, lo_open=True))
        if self.mode not in MODES:
            raise refused(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}", "mode")
        if self.scalar_range is not None:
            lo, hi = (check_number("scalar_range", v, allow_none=False) for v in self.scalar_range)
            if not hi > lo:
                raise refused(f"scalar_range (MIN, MAX): MIN must be below MAX, got {lo:g} {hi:g}", "scalar_range")
            _set(self, "scalar_range", (lo, hi))
        _set(self, "background", parse_colour(self.background))
        tf = load_transfer_function(self.tf)
        _set(self, "tf", tf if self.opacity_model is None else tf.with_opacity_model(self.opacity_model))
        for name in ("colorbar", "lean", "terminate"):
            _set(self, name, bool(getattr(self, name)))

    @property
    def camera(self) -> Camera:
        """The camera of this view (before it is fitted to a mesh)."""
        w, h = self.size
        return Camera(w, h, self.azimuth, self.elevation, self.zoom)

    def replace(self, **changes) -> "View":
        """This view with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Detail:
    """How much of the mesh to draw: at most one of ``ratio``, ``level``, ``budget`` and ``tets``.

    Parameters
    ----------
    ratio : float, optional
        Simplify to this ratio (merged / all vertices, 0..1), ``.tetc`` only.
    level : int, optional
        Draw a stored level as it is, ``.tetc`` only (not with ``selective``).
    budget : float, optional
        Seconds per frame: the finest level and ratio predicted to fit, ``.tetc`` only.
    selective : bool
        ``.tetc``: simplify where the view and transfer function say it matters least (a closed cut
        of the merge forest, never a flipped tet; :mod:`gatun_py.pipeline.selective`), to
        ``ratio``, ``tets`` or ``budget``.
    tets : int, optional
        With ``selective``: at most this many tets (above the mesh's count: the full mesh).

    Examples
    --------
    >>> Detail(ratio=0.9).simplifies, Detail().simplifies
    (True, False)
    """

    ratio: float | None = None
    level: int | None = None
    budget: float | None = None
    selective: bool = False
    tets: int | None = None

    def __post_init__(self):
        _set(self, "budget", check_number("budget", self.budget, lo=0.0, lo_open=True))
        _set(self, "ratio", check_number("ratio", self.ratio, lo=0.0, hi=1.0))
        if sum(x is not None for x in (self.ratio, self.level, self.budget, self.tets)) > 1:
            raise refused("ratio, level, budget and tets are mutually exclusive: give at most one", "ratio", "level",
                          "budget", "tets")
        if self.tets is not None:
            if isinstance(self.tets, bool) or not isinstance(self.tets, (int, np.integer)) or self.tets < 1:
                raise refused(f"tets must be a whole number >= 1, got {self.tets!r}", "tets")
            if not self.selective:
                raise refused("tets needs selective=True (a uniform render takes a ratio or a level)", "tets", "selective")
        if self.selective and self.level is not None:
            raise refused("selective refinement takes a ratio, tets or a budget, not a stored level", "selective", "level")
        _set(self, "selective", bool(self.selective))

    @property
    def simplifies(self) -> bool:
        """Anything but the full mesh asked for."""
        return self.selective or any(x is not None for x in (self.ratio, self.level, self.budget, self.tets))

    def replace(self, **changes) -> "Detail":
        """This detail with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class ForestOptions:
    """How compression builds the merge forest and the stored levels.

    Parameters
    ----------
    levels : int, optional
        Store pre-simplified levels 1..K (ratio 1 - 1/2^i), those the forest reaches; default
        every level up to 13 that keeps at least 128 points
        (:data:`~gatun_py.simplify.MIN_LEVEL_POINTS`; coarser ratios simplify on the fly from the
        last stored level).
    mesh_only : bool
        Store the mesh alone: no merge forest, no levels.
    w_density, w_geometry : float
        Decimation weights of the mass error and the boundary geometry error (>= 0).
    w_sample : float
        Factor on the decimation's sampled error (>= 0; 0: a faster forest with worse coarse
        levels, see :func:`~gatun_py.simplify.decimate`).
    dependencies : bool
        Also store the merge dependencies that selective refinement needs (``render(...,
        selective=True)``): every cut closed under them is flip-free. They cost file size
        (bench/sections/cells.md), so they are stored only when asked for.

    Examples
    --------
    >>> ForestOptions(levels=3).levels, ForestOptions().w_sample
    (3, 1.0)
    """

    levels: int | None = None
    mesh_only: bool = False
    w_density: float = 1.0
    w_geometry: float = 1.0
    w_sample: float = 1.0
    dependencies: bool = False

    def __post_init__(self):
        if self.levels is not None and (isinstance(self.levels, bool) or not isinstance(self.levels, (int, np.integer))
                                        or self.levels < 0):
            raise refused(f"levels must be a non-negative integer, got {self.levels!r}", "levels")
        for name in ("w_density", "w_geometry", "w_sample"):
            w = getattr(self, name)
            if not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0):
                raise refused(f"{name} must be a finite number >= 0, got {w!r}", name)
        _set(self, "mesh_only", bool(self.mesh_only))
        _set(self, "dependencies", bool(self.dependencies))


@dataclass(frozen=True)
class Cluster:
    """Where work that spreads over processes runs: a local Dask cluster of ``workers`` processes,
    or a running one at ``scheduler`` (``tcp://HOST:PORT``, waited for ``timeout`` seconds).

    Examples
    --------
    >>> Cluster(workers=2).local, Cluster().local
    (True, False)
    """

    workers: int | None = None
    scheduler: str | None = None
    timeout: float = 10.0

    def __post_init__(self):
        if self.workers is not None and self.scheduler is not None:
            raise refused("give either workers (a local cluster) or scheduler (a running one), not both",
                          "workers", "scheduler")
        if self.workers is not None and (isinstance(self.workers, bool) or not isinstance(self.workers, (int, np.integer))
                                         or self.workers < 1):
            raise refused(f"workers must be a whole number >= 1, got {self.workers!r}", "workers")
        _set(self, "timeout", check_number("timeout", self.timeout, lo=0.0, lo_open=True, allow_none=False))

    @property
    def local(self) -> bool:
        """A local cluster is asked for."""
        return self.workers is not None

    @property
    def used(self) -> bool:
        """Any cluster is asked for."""
        return self.workers is not None or self.scheduler is not None


_RECORDS = {"view": View, "detail": Detail, "read": ReadOptions, "forest": ForestOptions, "cluster": Cluster}  # a verb's keyword -> its record
_FIELDS = {cls: {f.name for f in dataclasses.fields(cls)} for cls in _RECORDS.values()}


def split_options(verb: str, options: dict, **records) -> tuple:
    """The records a verb takes (``view=``, ``detail=``, ``read=``: given or None), each changed by
    the verb's flat keywords that name its fields (the shorthand); in the order given.

    A flat keyword changes the record given (``render(f, view=v, azimuth=30)``) or the default one.

    Raises
    ------
    TypeError
        A keyword none of the records has, as Python says it for any function.
    OptionError
        A value a record refuses, or a record of the wrong type.

    Examples
    --------
    >>> v, d, r = split_options("render", {"azimuth": 30, "ratio": 0.5, "scalar": "rho"},
    ...                         view=None, detail=None, read=None)
    >>> v.azimuth, d.ratio, r.scalar
    (30.0, 0.5, 'rho')
    """
    classes = [_RECORDS[name] for name in records]
    unknown = set(options) - set().union(*(_FIELDS[cls] for cls in classes))
    if unknown:
        raise TypeError(f"{verb}() got an unexpected keyword argument {sorted(unknown)[0]!r}")
    out = []
    for (name, given), cls in zip(records.items(), classes):
        if given is not None and not isinstance(given, cls):
            raise OptionError(f"{name} must be a {cls.__name__}, got {type(given).__name__}")
        mine = {k: v for k, v in options.items() if k in _FIELDS[cls]}
        out.append(cls(**mine) if given is None else dataclasses.replace(given, **mine) if mine else given)
    return tuple(out)


@dataclass
class Frame:
    """A rendered image.

    Attributes
    ----------
    rgb : (H, W, 3) uint8
        The picture (over the background, with the colour bar if one was asked for).
    image : (H, W, 4) float32 or None
        The ray caster's premultiplied RGBA, before background and colour bar.
    stats : dict
        Timings and counts (what ``tetc render --stats`` prints).
    data : bytes or None
        The picture encoded (the viewer's frames), in ``mime``.
    mime : str or None
    """

    rgb: np.ndarray
    image: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    data: bytes | None = None
    mime: str | None = None

    def __repr__(self) -> str:
        h, w, _ = self.rgb.shape
        return f"Frame({w}x{h}, tets_rendered={self.stats.get('tets_rendered')}, render_s={self.stats.get('render_s', 0):.3f})"

    @property
    def rgb8(self) -> np.ndarray:
        """The picture (the viewer's name for :attr:`rgb`)."""
        return self.rgb

    def save(self, path, *, force: bool = False) -> None:
        """Write the picture atomically, in the format of the extension (.png, .jpg, .webp, .tif, .bmp)."""
        write_image(path, self.rgb, force=force)

    def _repr_png_(self) -> bytes:
        return image_bytes(self.rgb, "PNG")
