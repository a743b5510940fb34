"""A shaded preview of a triangle surface: z-buffered rasterisation with Lambert shading.

Same camera as the volume renderer (:class:`~gatun_py.raycast.camera.Camera`, VTK's conventions),
a headlight at the camera (as VTK's default light), two-sided diffuse shading plus a little ambient
light, colour by a per-vertex scalar through a matplotlib-free two-tone ramp. Enough to see what an
isosurface looks like without another tool; not a replacement for ParaView.
"""

from __future__ import annotations

import numpy as np
from numba import njit

AMBIENT = 0.15
#: colours of the lowest and highest scalar (a cool-to-warm pair; one colour if the scalar is flat)
LOW_RGB = (0.23, 0.30, 0.75)
HIGH_RGB = (0.71, 0.02, 0.15)
FLAT_RGB = (0.85, 0.85, 0.80)


@njit(cache=True)
def _raster(sx, sy, depth, tris, shade, rgb, image, zbuf):
    """Fill every triangle's pixels (centres inside, top-left rule free: ties go to the nearer)."""
    h, w = zbuf.shape
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if depth[a] <= 0 or depth[b] <= 0 or depth[c] <= 0:
            continue  # behind the camera: skip rather than wrap around
        x0, y0, x1, y1, x2, y2 = sx[a], sy[a], sx[b], sy[b], sx[c], sy[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0:
            continue
        lo_x = max(int(np.floor(min(x0, x1, x2))), 0)
        hi_x = min(int(np.ceil(max(x0, x1, x2))), w - 1)
        lo_y = max(int(np.floor(min(y0, y1, y2))), 0)
        hi_y = min(int(np.ceil(max(y0, y1, y2))), h - 1)
        for j in range(lo_y, hi_y + 1):
            py = j + 0.5
            for i in range(lo_x, hi_x + 1):
                px = i + 0.5
                l0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / area
                l1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / area
                l2 = 1.0 - l0 - l1
                if l0 < 0 or l1 < 0 or l2 < 0:
                    continue
                # perspective-correct depth: interpolate 1/z in screen space
                iz = l0 / depth[a] + l1 / depth[b] + l2 / depth[c]
                z = 1.0 / iz
                if z >= zbuf[j, i]:
                    continue
                zbuf[j, i] = z
                s = shade[f]
                for k in range(3):
                    col = (l0 / depth[a] * rgb[a, k] + l1 / depth[b] * rgb[b, k] + l2 / depth[c] * rgb[c, k]) * z
                    image[j, i, k] = col * s
                image[j, i, 3] = 1.0


def render_surface(points, triangles, camera, *, scalar=None, bbox=None) -> np.ndarray:
    """Render a triangle surface to a premultiplied RGBA float image (H, W, 4), black background.

    Parameters
    ----------
    points : (n, 3) array
    triangles : (m, 3) int array
    camera : Camera
        Fitted to ``bbox`` (default: the surface's own bounding box), as ``tetc render`` fits it to
        the mesh, so the two line up when given the mesh's box.
    scalar : (n,) array, optional
        Colours the surface (low blue, high red); one colour when absent or constant.
    bbox : (lo, hi), optional

    Examples
    --------
    >>> from gatun_py.raycast.camera import Camera
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    >>> img = render_surface(pts, np.array([[0, 1, 2]]), Camera(32, 32))
    >>> img.shape, bool(img[..., 3].any())
    ((32, 32, 4), True)
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if bbox is None:
        lo, hi = (p.min(axis=0), p.max(axis=0)) if len(p) else (np.zeros(3), np.ones(3))
    else:
        lo, hi = bbox
    cam = camera.fit(lo, hi)
    image = np.zeros((cam.height, cam.width, 4), np.float32)
    if len(t) == 0:
        return image
    fwd, right, up = cam.basis()
    rel = p - cam.position
    depth = rel @ fwd
    safe = np.where(depth > 0, depth, 1.0)
    xy = cam.project(np.where((depth > 0)[:, None], p, cam.position + fwd))
    sx = np.ascontiguousarray(xy[:, 0])
    sy = np.ascontiguousarray(xy[:, 1])
    # Lambert with a headlight: |cos| between the face normal and the view ray to its centre
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1)
    ln[ln == 0] = 1.0
    view = (a + b + c) / 3.0 - cam.position
    view /= np.maximum(np.linalg.norm(view, axis=1), 1e-300)[:, None]
    shade = AMBIENT + (1.0 - AMBIENT) * np.abs(np.einsum("ij,ij->i", n / ln[:, None], view))
    rgb = np.empty((len(p), 3))
    s = None if scalar is None else np.asarray(scalar, np.float64)
    if s is None or len(s) != len(p) or not np.isfinite(s).all() or s.max() <= s.min():
        rgb[:] = FLAT_RGB
    else:
        u = ((s - s.min()) / (s.max() - s.min()))[:, None]
        rgb[:] = (1 - u) * np.array(LOW_RGB) + u * np.array(HIGH_RGB)
    zbuf = np.full((cam.height, cam.width), np.inf)
    img64 = np.zeros((cam.height, cam.width, 4))
    _raster(sx, sy, safe, t, shade, rgb, img64, zbuf)
    return img64.astype(np.float32)
