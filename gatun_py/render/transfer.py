"""Transfer functions: scalar -> colour and opacity, piecewise linear.

Accepted sources (``load_transfer_function``):

* the project's JSON format (BRIEF.md, "Conventions"): ``color`` points ``{"x", "rgb"}``,
  ``opacity`` points ``{"x", "a"}``, ``x`` normalised to the scalar range unless
  ``"absolute": true``, and ``unit_distance`` (opacity ``a`` is for a path of that length);
* ParaView's exported colormap JSON (``RGBPoints`` = x, r, g, b, ...; optionally ``Points`` =
  x, a, 0.5, 0.0, ...), possibly a list holding one such object;
* a preset name: one of the files in ``sample_meshes/tf/`` (``bluntfin``, ``default``, ...);
* a matplotlib colormap name (matplotlib is optional), with the default opacity ramp.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gatun_py.errors import OptionError

PRESET_DIR = Path(__file__).resolve().parents[2] / "sample_meshes" / "tf"

# Number of entries of the lookup tables the kernels interpolate in (per table, over the scalar
# range); fine enough that the piecewise-linear re-interpolation error is far below 8-bit output.
TABLE_SIZE = 4096


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
        Path length for which the opacity values hold (VTK's ScalarOpacityUnitDistance).
    name : str
        Where it came from, for messages.
    """

    color_x: np.ndarray
    color_rgb: np.ndarray
    opacity_x: np.ndarray
    opacity_a: np.ndarray
    absolute: bool = False
    unit_distance: float = 1.0
    name: str = "transfer function"

    def resolve(self, scalar_range) -> "TransferFunction":
        """Return the same function with ``x`` in scalar units (``absolute=True``)."""
        if self.absolute:
            return self
        lo, hi = (float(v) for v in scalar_range)
        span = hi - lo if hi > lo else 1.0
        return TransferFunction(lo + self.color_x * span, self.color_rgb, lo + self.opacity_x * span,
                                self.opacity_a, True, self.unit_distance, self.name)

    def evaluate(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Colour (..., 3) and opacity (...) at scalar values ``s`` (absolute functions only)."""
        if not self.absolute:
            raise ValueError("resolve() the transfer function against a scalar range first")
        s = np.asarray(s, dtype=np.float64)
        rgb = np.stack([np.interp(s, self.color_x, self.color_rgb[:, c]) for c in range(3)], axis=-1)
        return rgb, np.interp(s, self.opacity_x, self.opacity_a)

    def table(self, scalar_range, size: int = TABLE_SIZE):
        """Lookup table (size, 4) of (r, g, b, a) sampled uniformly over ``scalar_range``.

        Returns ``(table, lo, inv_spacing)``; the kernels and the reference interpolate linearly
        between entries (and clamp outside), so both see the same function.
        """
        tf = self.resolve(scalar_range)
        lo, hi = (float(v) for v in scalar_range)
        if not hi > lo:
            hi = lo + 1.0
        xs = np.linspace(lo, hi, size)
        rgb, a = tf.evaluate(xs)
        tab = np.empty((size, 4), dtype=np.float64)
        tab[:, :3] = rgb
        tab[:, 3] = np.clip(a, 0.0, 1.0)
        return tab, lo, (size - 1) / (hi - lo)


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
    ud = obj.get("unit_distance", 1.0)
    absolute = obj.get("absolute", False)
    if not isinstance(absolute, bool):
        _fail(src, "'absolute' must be true or false")
    try:
        ud = float(ud)
    except (TypeError, ValueError):
        _fail(src, "'unit_distance' must be a number")
    if not (np.isfinite(ud) and ud > 0):
        _fail(src, "'unit_distance' must be a positive number")
    return TransferFunction(cx, crgb, ox, oa.reshape(-1), absolute, ud, src)


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
    return TransferFunction(cx, crgb, np.asarray(ox, float), np.asarray(oa, float), False,
                            float(obj.get("unit_distance", 1.0)), src)


# A linear opacity ramp, used with colour-only sources (ParaView RGBPoints, matplotlib names).
DEFAULT_OPACITY = (np.array([0.0, 1.0]), np.array([0.0, 0.5]))


def preset_names() -> list[str]:
    """Names of the bundled presets (the files in ``sample_meshes/tf``)."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.json")) if PRESET_DIR.is_dir() else []


def _from_matplotlib(name: str) -> TransferFunction:
    try:
        import matplotlib
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
    return TransferFunction(xs, rgb, *DEFAULT_OPACITY, False, 1.0, f"matplotlib:{name}")


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
        preset = PRESET_DIR / f"{s}.json"
        if preset.is_file():
            path = preset
        elif s.lower().endswith(".json"):
            _fail(s, "file not found")
        else:
            return _from_matplotlib(s)
    try:
        obj = json.loads(path.read_text())
    except OSError as e:
        _fail(s, f"cannot read: {e.strerror or e}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        _fail(s, f"malformed JSON: {e}")
    return from_dict(obj, s)
