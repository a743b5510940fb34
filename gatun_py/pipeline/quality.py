"""Image quality between two renders (paper 6.4): RMSE on a 0-255 scale over the pixels where
either image has a ray contribution (not black), plus PSNR and SSIM (scikit-image)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import OptionError, ReadError


@dataclass(frozen=True)
class ImageDifference:
    rmse: float  # 0-255 scale, over `pixels`
    psnr: float  # dB, from that RMSE (inf for identical images)
    ssim: float  # whole image, scikit-image
    pixels: int  # pixels where either image is not black

    def as_dict(self) -> dict:
        return asdict(self)


def read_rgb(path) -> np.ndarray:
    """An image file as (H, W, 3) uint8 (alpha composited on black, grey expanded)."""
    from skimage import io  # 1 s to import: only image comparison reads images

    path = Path(path)
    if not path.exists():
        raise ReadError(f"no such file: {path}")
    try:
        img = np.asarray(io.imread(str(path)))
    except Exception as e:  # imageio raises many types on bad files
        raise ReadError(f"cannot read image {path}: {type(e).__name__}: {e}") from None
    return as_rgb8(img, str(path))


def as_rgb8(img: np.ndarray, name: str = "image") -> np.ndarray:
    img = np.asarray(img)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ReadError(f"{name}: not an RGB image (shape {img.shape})")
    if img.dtype != np.uint8:
        if np.issubdtype(img.dtype, np.floating):
            img = np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)
        else:
            raise ReadError(f"{name}: unsupported pixel type {img.dtype} (8-bit images expected)")
    if img.shape[2] == 4:
        a = img[:, :, 3:4].astype(np.float64) / 255.0
        img = np.round(img[:, :, :3] * a).astype(np.uint8)
    return img


def compare_images(a: np.ndarray, b: np.ndarray) -> ImageDifference:
    """RMSE / PSNR / SSIM between two (H, W, 3) uint8 images.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((8, 8, 3), np.uint8); a[2:4, 2:4] = 100
    >>> b = a.copy(); b[2, 2, 0] = 110
    >>> d = compare_images(a, b)
    >>> d.pixels, round(d.rmse, 3)
    (4, 2.887)
    """
    from skimage.metrics import structural_similarity  # with skimage.io: see read_rgb

    a = as_rgb8(a, "first image")
    b = as_rgb8(b, "second image")
    if a.shape != b.shape:
        raise OptionError(f"images differ in size: {a.shape[1]}x{a.shape[0]} vs {b.shape[1]}x{b.shape[0]}")
    mask = (a.max(axis=2) > 0) | (b.max(axis=2) > 0)
    pixels = int(mask.sum())
    if pixels:
        d = a[mask].astype(np.float64) - b[mask].astype(np.float64)
        rmse = float(np.sqrt(np.mean(d * d)))
    else:
        rmse = 0.0
    psnr = math.inf if rmse == 0 else 20.0 * math.log10(255.0 / rmse)
    side = min(a.shape[0], a.shape[1])
    if side >= 7:
        ssim = float(structural_similarity(a, b, channel_axis=2, data_range=255))
    else:  # too small for the 7x7 window
        ssim = 1.0 if np.array_equal(a, b) else float("nan")
    return ImageDifference(rmse, psnr, ssim, pixels)


def compare_files(path_a, path_b) -> ImageDifference:
    return compare_images(read_rgb(path_a), read_rgb(path_b))
