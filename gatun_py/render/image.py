"""Turning a premultiplied RGBA render into an 8-bit PNG (black background), written atomically."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from gatun_py._atomic import write_bytes_atomic


def to_rgb8(image) -> np.ndarray:
    """(H, W, 3) uint8 of a premultiplied RGBA image composited on black."""
    rgb = np.asarray(image, dtype=np.float64)[..., :3]
    rgb = np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)


def png_bytes(rgb8) -> bytes:
    """Encode an (H, W, 3) uint8 array as a PNG file (8-bit RGB, no filtering)."""
    rgb8 = np.ascontiguousarray(rgb8, dtype=np.uint8)
    h, w, c = rgb8.shape
    if c != 3:
        raise ValueError("expected an (H, W, 3) array")
    raw = np.zeros((h, 1 + 3 * w), dtype=np.uint8)  # filter byte 0 per row
    raw[:, 1:] = rgb8.reshape(h, 3 * w)

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
            + chunk(b"IEND", b""))


def read_png_rgb(path) -> np.ndarray:
    """Read an 8-bit RGB(A) PNG into (H, W, 3) uint8 (uses scikit-image)."""
    from skimage.io import imread  # 1 s to import: only image comparison reads images

    img = imread(path)
    if img.ndim == 2:
        img = np.stack([img] * 3, axis=-1)
    return np.asarray(img[..., :3], dtype=np.uint8)


def write_png(path, image, *, force: bool = False) -> None:
    """Write a render (premultiplied RGBA float, or RGB uint8) as an 8-bit RGB PNG atomically."""
    img = np.asarray(image)
    rgb8 = img if img.dtype == np.uint8 and img.shape[-1] == 3 else to_rgb8(img)
    write_bytes_atomic(path, png_bytes(rgb8), force=force)
