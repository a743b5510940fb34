"""From a premultiplied RGBA render to an 8-bit picture: background, colour bar, image files.

PNG is written by our own encoder (no filtering, zlib level 6: byte-stable across library versions);
the other formats go through Pillow, which scikit-image already depends on. Every file is written
atomically, in the format its extension names, or refused.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .._atomic import write_bytes_atomic
from .options import IMAGE_FORMATS, image_format, parse_colour  # noqa: F401  (light: the CLI's checks)

# extension -> Pillow format name (PNG is ours)


def to_rgb8(image, background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(H, W, 3) uint8 of a premultiplied RGBA image composited over ``background`` (RGB in 0..1).

    Examples
    --------
    >>> import numpy as np
    >>> px = np.array([[[0.5, 0.0, 0.0, 0.5]]])           # half-transparent red, premultiplied
    >>> to_rgb8(px).tolist(), to_rgb8(px, (1, 1, 1)).tolist()
    ([[[128, 0, 0]]], [[[255, 128, 128]]])
    """
    img = np.asarray(image, dtype=np.float64)
    rgb = np.nan_to_num(img[..., :3], nan=0.0, posinf=1.0, neginf=0.0)
    bg = np.asarray(background, dtype=np.float64).reshape(3)
    if np.any(bg != 0.0) and img.shape[-1] == 4:
        alpha = np.clip(np.nan_to_num(img[..., 3:4], nan=0.0), 0.0, 1.0)
        rgb = rgb + (1.0 - alpha) * bg
    return np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)


def upscale_rgb8(rgb8: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8: ``rgb8`` resized with bilinear filtering (a budget render drawn small).

    Examples
    --------
    >>> import numpy as np
    >>> upscale_rgb8(np.full((2, 3, 3), 200, np.uint8), 6, 4).shape
    (4, 6, 3)
    """
    img = Image.fromarray(np.ascontiguousarray(rgb8, dtype=np.uint8))
    return np.asarray(img.resize((int(width), int(height)), Image.BILINEAR))


def add_colorbar(rgb8: np.ndarray, table: np.ndarray, scalar_range, label: str,
                 background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The image with a colour bar on its right: the transfer function's colours (opacity as
    brightness over the background), the scalar's name, and the range's two ends.

    ``table`` is the (k, 4) RGBA lookup table over ``scalar_range`` (``TransferFunction.table``).
    """
    h, w, _ = rgb8.shape
    bar_w = max(8, w // 32)
    pad = max(4, w // 64)
    font = ImageFont.load_default()
    lo, hi = (float(v) for v in scalar_range)
    texts = [label, f"{hi:.4g}", f"{lo:.4g}"]
    probe = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    text_w = max(probe.textbbox((0, 0), t, font=font)[2] for t in texts)
    text_h = max(probe.textbbox((0, 0), t, font=font)[3] for t in texts)
    panel_w = 2 * pad + max(bar_w + pad + text_w, text_w)
    out = np.empty((h, w + panel_w, 3), np.uint8)
    out[:, :w] = rgb8
    bg = np.asarray(background, np.float64).reshape(3)
    out[:, w:] = np.clip(np.rint(bg * 255), 0, 255).astype(np.uint8)
    top, bottom = pad + text_h + pad, h - pad
    if bottom - top >= 4:
        t = np.linspace(1.0, 0.0, bottom - top)
        idx = np.clip(np.rint(t * (len(table) - 1)).astype(int), 0, len(table) - 1)
        rgba = table[idx]
        alpha = np.clip(0.25 + 0.75 * rgba[:, 3:4] / max(float(table[:, 3].max()), 1e-12), 0.0, 1.0)
        col = np.clip(np.rint((rgba[:, :3] * alpha + (1 - alpha) * bg) * 255), 0, 255).astype(np.uint8)
        out[top:bottom, w + pad:w + pad + bar_w] = col[:, None, :]
    img = Image.fromarray(out)
    draw = ImageDraw.Draw(img)
    ink = (0, 0, 0) if bg.mean() > 0.5 else (255, 255, 255)
    draw.text((w + pad, pad), label, fill=ink, font=font)
    x = w + pad + bar_w + pad
    draw.text((x, top), texts[1], fill=ink, font=font)
    draw.text((x, max(top, bottom - text_h)), texts[2], fill=ink, font=font)
    return np.asarray(img)


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


def image_bytes(rgb8, fmt: str, *, quality: int = 92) -> bytes:
    """Encode (H, W, 3) uint8 in ``fmt`` (a value of :data:`IMAGE_FORMATS`, any case); ``quality``
    for JPEG and WebP (the files renders write use 92, the viewer's frames what the page asks)."""
    fmt = fmt.upper()
    if fmt == "PNG":
        return png_bytes(rgb8)
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb8, dtype=np.uint8)).save(buf, format=fmt, **(
        {"quality": quality} if fmt in ("JPEG", "WEBP") else {}))
    return buf.getvalue()


def read_png_rgb(path) -> np.ndarray:
    """Read an 8-bit RGB(A) image into (H, W, 3) uint8."""
    with Image.open(path) as im:
        img = np.asarray(im.convert("RGB"))
    return np.asarray(img[..., :3], dtype=np.uint8)


def write_image(path, image, *, force: bool = False) -> None:
    """Write a render (premultiplied RGBA float, or RGB uint8) atomically, in the format of its extension."""
    fmt = image_format(path)
    img = np.asarray(image)
    rgb8 = img if img.dtype == np.uint8 and img.shape[-1] == 3 else to_rgb8(img)
    write_bytes_atomic(path, image_bytes(rgb8, fmt), force=force)


write_png = write_image  # the name the pipeline has always used; any extension in IMAGE_FORMATS works
