"""The renderer's option values, checked without numpy or PIL.Image: the CLI checks an output's
image format and a colour before it says that it compiles (and before numba loads)."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import OptionError, OutputError

IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".webp": "WEBP", ".tif": "TIFF",
                 ".tiff": "TIFF", ".bmp": "BMP"}


def image_format(path) -> str:
    """The image format a file name asks for; :class:`OutputError` listing the choices otherwise."""
    ext = Path(path).suffix.lower()
    if ext not in IMAGE_FORMATS:
        raise OutputError(f"{path}: cannot write images as {ext or 'a file without an extension'!r}; "
                          f"choose one of {', '.join(sorted(IMAGE_FORMATS))}")
    return IMAGE_FORMATS[ext]


def parse_colour(text) -> tuple[float, float, float]:
    """A colour as RGB in 0..1 from a name (``white``), ``#rrggbb`` or ``r,g,b`` in 0..1.

    Examples
    --------
    >>> parse_colour("white"), parse_colour("#ff8000"), parse_colour("0, 0.5, 1")
    ((1.0, 1.0, 1.0), (1.0, 0.5019607843137255, 0.0), (0.0, 0.5, 1.0))
    """
    if not isinstance(text, str) and hasattr(text, "__len__"):  # a sequence or an array
        vals = [float(v) for v in text]
    else:
        s = str(text).strip()
        if "," in s:
            try:
                vals = [float(v) for v in s.split(",")]
            except ValueError:
                raise OptionError(f"colour {text!r}: expected r,g,b in 0..1") from None
        else:
            try:
                from PIL import ImageColor  # light (not PIL.Image)

                vals = [c / 255.0 for c in ImageColor.getrgb(s)[:3]]
            except ValueError:
                raise OptionError(f"unknown colour {text!r} (a name, #rrggbb or r,g,b in 0..1)") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals) or min(vals) < 0.0 or max(vals) > 1.0:
        raise OptionError(f"colour {text!r}: expected three values in 0..1")
    return tuple(float(v) for v in vals)
