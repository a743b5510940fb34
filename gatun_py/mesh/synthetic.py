"""Small synthetic meshes made on the spot: a jittered grid split into tets, with a smooth scalar.

The kernel warm-up and the time model's per-machine seed both need a mesh of a known size that
exercises the real code paths (curved cells, a non-trivial boundary, degenerate-free tets).
"""

from __future__ import annotations

import numpy as np

from .plot3d import grid_hexes
from .split import orient_positive, split_hexes_two_colour
from .validate import validate_tets


def jittered_grid(dims, *, jitter: float, scalar=(1.0, 0.3, 0.0), seed: int = 0):
    """A ``dims`` grid of points moved by up to ``jitter`` per axis, split into positive tets.

    The scalar at a point (x, y, z) is ``sin(a x) + b y + c z`` for ``scalar = (a, b, c)``.

    Examples
    --------
    >>> m = jittered_grid((4, 4, 3), jitter=0.15)
    >>> m.n_points, m.n_tets
    (48, 90)
    """
    k, j, i = np.meshgrid(*(np.arange(d) for d in tuple(dims)[::-1]), indexing="ij")
    pts = np.stack([i, j, k], -1).reshape(-1, 3).astype(np.float64)
    pts += np.random.default_rng(seed).uniform(-jitter, jitter, pts.shape)
    pts = pts.astype(np.float32)
    hexes, colour = grid_hexes(tuple(dims))
    tets = orient_positive(pts, split_hexes_two_colour(hexes, colour))
    a, b, c = scalar
    dens = (np.sin(pts[:, 0] * a) + b * pts[:, 1] + c * pts[:, 2]).astype(np.float32)
    return validate_tets(pts, dens, tets)[0]
