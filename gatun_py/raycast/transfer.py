"""Transfer functions: scalar -> colour and opacity, piecewise linear.

Accepted sources (``load_transfer_function``):

* the project's JSON format (BRIEF.md, "Conventions"): ``color`` points ``{"x", "rgb"}``,
  ``opacity`` points ``{"x", "a"}``, ``x`` normalised to the scalar range unless
  ``"absolute": true``, and ``unit_distance`` (opacity ``a`` is for a path of that length, in the
  mesh's units) or ``unit_distance_relative`` (the same as a fraction of the mesh's bounding-box
  diagonal, so that a mesh in any unit renders alike; the default when neither is given, 0.01);
  optionally ``"opacity_model": "vtk"`` (below);
* ParaView's exported colormap JSON (``RGBPoints`` = x, r, g, b, ...; optionally ``Points`` =
  x, a, 0.5, 0.0, ...), possibly a list holding one such object;
* a preset name: one of the package's ``presets/*.json`` (``bluntfin``, ``default``, ...);
* a matplotlib colormap name (matplotlib is optional), with the default opacity ramp.

Two opacity models (``TransferFunction.opacity_model``) say what the opacity ``a`` of a point means:

* ``"gatun"`` (the default, BRIEF.md "Conventions"): ``a`` is the opacity of a path of length
  ``unit_distance``; a path of length d has opacity ``1 - (1 - a) ** (d / unit_distance)``.
* ``"vtk"``: what VTK's ``vtkUnstructuredGridVolumeRayCastMapper`` computes with its default
  integrator (``vtkUnstructuredGridPartialPreIntegration``; the linear and pre-integration ones
  share it). ``a / unit_distance`` is an attenuation coefficient, so a path of length d has opacity
  ``1 - exp(-a d / unit_distance)``; and the opacity function is only read at VTK's control points
  (the colour function's points, the first opacity point and the two ends of the data range) and
  interpolated linearly between them, so opacity points that are not colour points are lost.
  Both are expressed through the opacity of a path of ``unit_distance`` (``evaluate``, ``table``),
  so the renderer needs no other change.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import OptionError

# Presets ship inside the package (read through importlib.resources, so a wheel or a zip works).
PRESETS = resources.files(f"{__package__}.presets")

# Number of entries of the lookup tables the kernels interpolate in (per table, over the scalar
# range); fine enough that the piecewise-linear re-interpolation error is far below 8-bit output.
TABLE_SIZE = 4096

OPACITY_MODELS = ("gatun", "vtk")


@dataclass(frozen=True)
class TransferFunction:
    """A piecewise-linear colour and opacity map.

    Parameters
    ----------
    color_x, color_rgb : (k,), (k, 3) float64
        Colour control points (``x`` ascending).
    opacity_x, opacity_a : (j,), (j,) float64
        Opacity control points; ``a`` in [0, 1] is the opacity of a path of length ``unit_distance``.
    absolute : bool
        ``x`` in scalar units; otherwise normalised to the mesh's scalar range.
    unit_distance : float
        Path length for which the opacity values hold (VTK's ScalarOpacityUnitDistance); with
        ``unit_relative`` a fraction of the mesh's bounding-box diagonal (:meth:`for_size`).
    name : str
        Where it came from, for messages.
    opacity_model : {"gatun", "vtk"}
        How ``a`` turns into opacity along a path (module docstring); ``resolve`` applies VTK's
        resampling of the opacity function for ``"vtk"``.
    """

    color_x: np.ndarray
    color_rgb: np.ndarray
    opacity_x: np.ndarray
    opacity_a: np.ndarray
    absolute: bool = False
    unit_distance: float = 1.0
    name: str = "transfer function"
    opacity_model: str = "gatun"
    unit_relative: bool = False

    def __post_init__(self):
        if self.opacity_model not in OPACITY_MODELS:
            raise OptionError(f"opacity model must be one of {', '.join(OPACITY_MODELS)}, "
                              f"got {self.opacity_model!r}")
        if not (math.isfinite(self.unit_distance) and self.unit_distance > 0):
            raise OptionError(f"transfer function {self.name}: the unit distance must be a positive number, "
                              f"got {self.unit_distance!r}")

    def for_size(self, diagonal: float) -> "TransferFunction":
        """The function with its unit distance in the mesh's units, for a mesh whose bounding box
        has this diagonal (a relative unit distance is a fraction of it; an absolute one is kept).

        Examples
        --------
        >>> tf = load_transfer_function("default")
        >>> tf.unit_relative, tf.for_size(200.0).unit_distance
        (True, 2.0)
        """
        if not self.unit_relative:
            return self
        d = float(diagonal)
        if not (math.isfinite(d) and d > 0):
            d = 1.0
        return replace(self, unit_distance=self.unit_distance * d, unit_relative=False)

    def with_opacity_model(self, model: str) -> "TransferFunction":
        """The same function read with another opacity model (``"gatun"`` or ``"vtk"``)."""
        return replace(self, opacity_model=model)

    def resolve(self, scalar_range) -> "TransferFunction":
        """Return the same function with ``x`` in scalar units (``absolute=True``).

        With the ``"vtk"`` opacity model the opacity points are also replaced by VTK's control
        points over this scalar range (idempotent for the same range).
        """
        tf = self
        lo, hi = data_range(scalar_range)
        if not self.absolute:
            tf = replace(self, color_x=lo + self.color_x * (hi - lo), opacity_x=lo + self.opacity_x * (hi - lo),
                         absolute=True)
        if tf.opacity_model == "vtk":
            x, a = vtk_opacity_points(tf.color_x, tf.opacity_x, tf.opacity_a, (lo, hi))
            tf = replace(tf, opacity_x=x, opacity_a=a)
        return tf

    def evaluate(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Colour (..., 3) and opacity (...) at scalar values ``s`` (absolute functions only).

        The opacity is that of a path of length ``unit_distance`` under ``opacity_model``: the
        interpolated ``a`` for ``"gatun"``, ``1 - exp(-a)`` for ``"vtk"`` (``a / unit_distance`` being
        VTK's attenuation coefficient). Either way a path of length d then has opacity
        ``1 - (1 - opacity) ** (d / unit_distance)``.
        """
        if not self.absolute:
            raise ValueError("resolve() the transfer function against a scalar range first")
        s = np.asarray(s, dtype=np.float64)
        rgb = np.stack([np.interp(s, self.color_x, self.color_rgb[:, c]) for c in range(3)], axis=-1)
        a = np.interp(s, self.opacity_x, self.opacity_a)
        if self.opacity_model == "vtk":
            a = -np.expm1(-a)
        return rgb, a

    def table(self, scalar_range, size: int = TABLE_SIZE):
        """Lookup table (size, 4) of (r, g, b, a) sampled uniformly over ``scalar_range``.

        Returns ``(table, lo, inv_spacing)``; the kernels and the reference interpolate linearly
        between entries (and clamp outside), so both see the same function.
        """
        tf = self.resolve(scalar_range)
        lo, hi = data_range(scalar_range)
        xs = np.linspace(lo, hi, size)
        rgb, a = tf.evaluate(xs)
        tab = np.empty((size, 4), dtype=np.float64)
        tab[:, :3] = rgb
        tab[:, 3] = np.clip(a, 0.0, 1.0)
        return tab, lo, (size - 1) / (hi - lo)


def data_range(scalar_range) -> tuple[float, float]:
    """The scalar range a normalised transfer function is stretched over: ``scalar_range`` itself,
    except for a constant field (``hi <= lo``), which gets ``[v - 1/2, v + 1/2]``.

    A constant field (or a mesh stored without a scalar, whose values are all 0) then renders at
    the middle of the transfer function: a uniform medium that shows the shape, where the low end
    of most transfer functions is transparent and would leave the image empty.

    >>> data_range((0.0, 0.0))
    (-0.5, 0.5)
    >>> data_range((1.0, 3.0))
    (1.0, 3.0)
    """
    lo, hi = (float(v) for v in scalar_range)
    if not hi > lo:
        return lo - 0.5, lo + 0.5
    return lo, hi


def vtk_opacity_points(color_x, opacity_x, opacity_a, scalar_range):
    """The opacity function as VTK's piecewise-linear ray integrators see it.

    ``vtkUnstructuredGridPartialPreIntegration`` (and ``...LinearRayIntegrator``) cache the transfer
    function at a set of control points and interpolate linearly between them. The set is meant to
    hold every colour and opacity point, but the loop over the opacity points stops after the first
    one (it tests for the *lower* end of the function's range), so it holds the colour points, the
    first opacity point and the two ends of the data range only; the opacity between them is the
    straight line between its values there.

    Parameters
    ----------
    color_x, opacity_x, opacity_a : array_like
        Control points in scalar units (ascending ``x``).
    scalar_range : (lo, hi)
        The data range (VTK adds both ends as control points).

    Returns
    -------
    x, a : (k,) float64
        Opacity control points equivalent to VTK's cache.
    """
    opacity_x = np.asarray(opacity_x, dtype=np.float64)
    x = np.unique(np.concatenate([np.asarray(color_x, dtype=np.float64), opacity_x[:1],
                                  np.asarray(scalar_range, dtype=np.float64).reshape(2)]))
    return x, np.interp(x, opacity_x, np.asarray(opacity_a, dtype=np.float64))


def _fail(src: str, msg: str):
    raise OptionError(f"transfer function {src}: {msg}")


def _points(obj, key, valkey, width, src):
    pts = obj.get(key)
    if not isinstance(pts, list) or not pts:
        _fail(src, f"'{key}' must be a non-empty list of points")
    xs, vs = [], []
    for i, p in enumerate(pts):
        if not isinstance(p, dict) or "x" not in p or valkey not in p:
            _fail(src, f"{key}[{i}] must be an object with 'x' and '{valkey}'")
        try:
            x = float(p["x"])
            v = np.asarray(p[valkey], dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            _fail(src, f"{key}[{i}] holds a non-numeric value")
        if v.size != width:
            _fail(src, f"{key}[{i}].{valkey} must have {width} value(s)")
        xs.append(x)
        vs.append(v)
    return _check_xy(np.array(xs), np.array(vs), key, src)


def _check_xy(xs, vs, key, src):
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(vs))):
        _fail(src, f"'{key}' holds NaN or infinite values")
    if np.any(np.diff(xs) < 0):
        _fail(src, f"'{key}' x values must be ascending")
    if np.any(vs < 0) or np.any(vs > 1):
        _fail(src, f"'{key}' values must lie in [0, 1]")
    return xs, vs


def from_dict(obj, src: str = "transfer function") -> TransferFunction:
    """Build a transfer function from a parsed JSON object (project or ParaView format)."""
    if isinstance(obj, list):
        if len(obj) != 1:
            _fail(src, "a ParaView colormap list must hold exactly one colormap")
        obj = obj[0]
    if not isinstance(obj, dict):
        _fail(src, "expected a JSON object")
    if "RGBPoints" in obj:
        return _from_paraview(obj, src)
    if "color" not in obj or "opacity" not in obj:
        _fail(src, "expected 'color' and 'opacity' lists (or ParaView 'RGBPoints')")
    cx, crgb = _points(obj, "color", "rgb", 3, src)
    ox, oa = _points(obj, "opacity", "a", 1, src)
    ud, relative = _unit_distance(obj, src)
    absolute = obj.get("absolute", False)
    if not isinstance(absolute, bool):
        _fail(src, "'absolute' must be true or false")
    model = obj.get("opacity_model", "gatun")
    if model not in OPACITY_MODELS:
        _fail(src, f"'opacity_model' must be one of {', '.join(map(repr, OPACITY_MODELS))}")
    return TransferFunction(cx, crgb, ox, oa.reshape(-1), absolute, ud, src, model, relative)


DEFAULT_RELATIVE_UNIT = 0.01  # of the bounding-box diagonal, when a source gives no unit distance


def _unit_distance(obj, src) -> tuple[float, bool]:
    """(unit distance, relative?) of a JSON object: ``unit_distance`` in mesh units, or
    ``unit_distance_relative`` as a fraction of the bounding-box diagonal (the default, 0.01)."""
    if "unit_distance" in obj and "unit_distance_relative" in obj:
        _fail(src, "give 'unit_distance' or 'unit_distance_relative', not both")
    key = "unit_distance" if "unit_distance" in obj else "unit_distance_relative"
    raw = obj.get(key, DEFAULT_RELATIVE_UNIT)
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        _fail(src, f"'{key}' must be a number, got {raw!r}")
    ud = float(raw)
    if not (math.isfinite(ud) and ud > 0):
        _fail(src, f"'{key}' must be a positive finite number, got {raw!r}")
    return ud, key == "unit_distance_relative"


def _from_paraview(obj, src):
    try:
        rgbp = np.asarray(obj["RGBPoints"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        _fail(src, "'RGBPoints' must be a flat list of numbers")
    if rgbp.size == 0 or rgbp.size % 4:
        _fail(src, "'RGBPoints' must hold x, r, g, b quadruples")
    cx, crgb = _check_xy(rgbp[0::4], rgbp.reshape(-1, 4)[:, 1:], "RGBPoints", src)
    # ParaView colormaps carry absolute scalar values; they are normalised to [0, 1] over their
    # own span so that a map exported for one data set applies to the mesh being rendered.
    lo, hi = cx[0], cx[-1]
    span = hi - lo if hi > lo else 1.0
    cx = (cx - lo) / span
    if "Points" in obj:
        try:
            pts = np.asarray(obj["Points"], dtype=np.float64).reshape(-1, 4)
        except (TypeError, ValueError):
            _fail(src, "'Points' must hold x, a, midpoint, sharpness quadruples")
        ox, oa = _check_xy((pts[:, 0] - lo) / span, pts[:, 1], "Points", src)
    else:
        ox, oa = DEFAULT_OPACITY
    ud, relative = _unit_distance(obj, src)
    return TransferFunction(cx, crgb, np.asarray(ox, float), np.asarray(oa, float), False, ud, src,
                            unit_relative=relative)


# A linear opacity ramp, used with colour-only sources (ParaView RGBPoints, matplotlib names).
DEFAULT_OPACITY = (np.array([0.0, 1.0]), np.array([0.0, 0.5]))


def preset_names() -> list[str]:
    """Names of the bundled presets (``gatun_py/raycast/presets/*.json``)."""
    return sorted(p.name[:-5] for p in PRESETS.iterdir() if p.name.endswith(".json"))


def _from_matplotlib(name: str) -> TransferFunction:
    try:
        import matplotlib  # optional dependency
    except ImportError:
        _fail(repr(name), "not a file or preset; matplotlib colormap names need matplotlib "
              "(pip install matplotlib)")
    try:
        cmap = matplotlib.colormaps[name]
    except KeyError:
        _fail(repr(name), f"unknown name: not a file, a preset ({', '.join(preset_names())}) "
              "or a matplotlib colormap")
    xs = np.linspace(0.0, 1.0, 256)
    rgb = np.asarray(cmap(xs))[:, :3].astype(np.float64)
    return TransferFunction(xs, rgb, *DEFAULT_OPACITY, False, DEFAULT_RELATIVE_UNIT, f"matplotlib:{name}",
                            unit_relative=True)


def load_transfer_function(spec) -> TransferFunction:
    """Load a transfer function from a path, a preset name, a matplotlib name or a dict.

    Parameters
    ----------
    spec : str, os.PathLike, dict, list or TransferFunction
        A JSON file (project or ParaView format), a preset name (``bluntfin``, ``default``, ...),
        a matplotlib colormap name, an already parsed JSON object, or a transfer function.

    Returns
    -------
    TransferFunction

    Raises
    ------
    OptionError
        Unknown names, unreadable files and malformed JSON, with one clear message.
    """
    if isinstance(spec, TransferFunction):
        return spec
    if isinstance(spec, (dict, list)):
        return from_dict(spec)
    s = str(spec)
    path = Path(s)
    if not path.is_file():
        preset = PRESETS / f"{s}.json"
        if s in preset_names():
            path = preset
        elif s.lower().endswith(".json"):
            _fail(s, "file not found")
        else:
            return _from_matplotlib(s)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        _fail(s, f"cannot read: {e.strerror or e}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        _fail(s, f"malformed JSON: {e}")
    return from_dict(obj, s)
