"""Turning a rendered image into an 8-bit PNG, written atomically."""

from __future__ import annotations

import io

import numpy as np

from .._atomic import write_bytes_atomic


def to_rgb8(image: np.ndarray) -> np.ndarray:
    """Premultiplied RGBA float (black background) -> (H, W, 3) uint8."""
    rgb = np.asarray(image, dtype=np.float64)[..., :3]
    rgb = np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)


def encode_png(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(to_rgb8(image), mode="RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def write_png(path, image: np.ndarray, *, force: bool = False) -> None:
    write_bytes_atomic(path, encode_png(image), force=force)
