"""A slow, obviously correct compositor: the reference for ``raycast.composite``.

For every pixel: collect its fragments, sort them by (front depth, back depth) with Python's
sort, and blend them front to back, one at a time: C += (1 - A) * c, A += (1 - A) * a.
"""

from __future__ import annotations

import numpy as np


def naive_composite(fragments_list):
    """(H, W, 4) float64 premultiplied RGBA of the fragments of every element of ``fragments_list``."""
    width, height = fragments_list[0].width, fragments_list[0].height
    per_pixel: dict[int, list] = {}
    for f in fragments_list:
        for i in range(len(f)):
            per_pixel.setdefault(int(f.ray[i]), []).append((float(f.depth[i, 0]), float(f.depth[i, 1]),
                                                            [float(v) for v in f.rgba[i]]))
    image = np.zeros((height * width, 4))
    for pixel, frags in per_pixel.items():
        frags.sort(key=lambda x: (x[0], x[1]))
        acc = [0.0, 0.0, 0.0, 0.0]
        for _, _, c in frags:
            w = 1.0 - acc[3]
            acc = [acc[k] + w * c[k] for k in range(4)]
        image[pixel] = acc
    return image.reshape(height, width, 4)
