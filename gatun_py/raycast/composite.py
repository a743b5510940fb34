"""Sort-last compositing of ray-segment fragments: the exact way to join bricks rendered apart.

The ray caster cuts every pixel ray into *segments* between two boundary crossings of the mesh it
renders. Render each brick of a partition on its own and every brick's segments are disjoint in
depth from every other brick's (a segment lies inside one brick; a face between two bricks is
boundary of both, and both compute the ray's parameter t there with the same float operations on
the same vertices). So sorting a pixel's segments from all bricks by depth and compositing them
front to back with the paper's equation (4) gives the image of the whole mesh, whatever the
bricks' shapes: non-convex bricks just give several segments per ray (IceT's one-image-per-brick
visibility order cannot do that; VTK-h composites per-pixel fragments the same way).

A :class:`Fragments` is one brick's (or several bricks') segments as columns: pixel, premultiplied
colour and opacity (each segment's two subsegments joined with equation 3), and the depth interval.
:func:`merge_fragments` concatenates (the reduction step between workers); :func:`composite` sorts
and blends. Fully transparent segments are dropped when the fragments are made: they change no
pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ._boundary import group_by_ray, sort_run
from ._segments import ACC_A, ACC_B, ACC_G, ACC_R, BACK, FRONT, SEG_ACC, SEG_FACE, SEG_RAY, SEG_TS, TS_T

# columns of Fragments.depth
DEPTH_FRONT, DEPTH_BACK = 0, 1

# Where a ray crosses the cut between two bricks next to an edge, the brick in front may leave
# through one cut face and the brick behind enter through its neighbour across that edge: the two
# crossings are computed on different triangles and can differ by an ulp or two (post.vtk: up to
# 4e-16 relative). That is not an overlap.
OVERLAP_TOLERANCE = 1e-12

__all__ = ["Fragments", "composite", "merge_fragments", "segment_fragments", "split_rows", "row_bands", "DEPTH_FRONT",
           "DEPTH_BACK"]


@dataclass(frozen=True, eq=False)
class Fragments:
    """Ray-segment fragments of one image: what a brick sends to the compositor.

    Attributes
    ----------
    ray : (n,) int32
        Pixel (row-major index) of each fragment.
    rgba : (n, 4) float64
        Premultiplied colour and opacity of the segment (front subsegment over back, equation 3).
    depth : (n, 2) float64
        Ray parameter t (distance from the eye along the unit ray) where the segment enters
        (``DEPTH_FRONT``) and leaves (``DEPTH_BACK``) the brick.
    width, height : int
        The image the pixels index.
    """

    ray: np.ndarray
    rgba: np.ndarray
    depth: np.ndarray
    width: int
    height: int

    def __len__(self) -> int:
        return int(self.ray.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes of the three columns (what a worker sends per frame)."""
        return int(self.ray.nbytes + self.rgba.nbytes + self.depth.nbytes)

    def __repr__(self) -> str:
        return f"Fragments({len(self)} fragments, {self.width}x{self.height}, {self.nbytes / 2**20:.2f} MB)"

    @classmethod
    def empty(cls, width: int, height: int) -> "Fragments":
        """No fragments (a brick no ray hits)."""
        return cls(np.zeros(0, np.int32), np.zeros((0, 4), np.float64), np.zeros((0, 2), np.float64),
                   int(width), int(height))


@njit(cache=True)
def _segment_fragments(seg_ray, seg_face, seg_ts, seg_acc, entry_t):
    """Equation (3) per segment; the depth interval from the boundary crossings (``entry_t``),
    or, for the end of a one-ended segment (folded grids), from where its walk stopped.
    Transparent segments (all four channels 0) are left out."""
    n = seg_ray.shape[0]
    keep = 0
    for s in range(n):
        of = seg_acc[s, FRONT, ACC_A]
        if of != 0.0 or seg_acc[s, BACK, ACC_A] != 0.0 or seg_acc[s, FRONT, ACC_R] != 0.0 \
                or seg_acc[s, FRONT, ACC_G] != 0.0 or seg_acc[s, FRONT, ACC_B] != 0.0 \
                or seg_acc[s, BACK, ACC_R] != 0.0 or seg_acc[s, BACK, ACC_G] != 0.0 or seg_acc[s, BACK, ACC_B] != 0.0:
            keep += 1
    ray = np.empty(keep, np.int32)
    rgba = np.empty((keep, 4), np.float64)
    depth = np.empty((keep, 2), np.float64)
    k = 0
    for s in range(n):
        front_a, back_a = seg_acc[s, FRONT, ACC_A], seg_acc[s, BACK, ACC_A]
        if front_a == 0.0 and back_a == 0.0 and seg_acc[s, FRONT, ACC_R] == 0.0 \
                and seg_acc[s, FRONT, ACC_G] == 0.0 and seg_acc[s, FRONT, ACC_B] == 0.0 \
                and seg_acc[s, BACK, ACC_R] == 0.0 and seg_acc[s, BACK, ACC_G] == 0.0 \
                and seg_acc[s, BACK, ACC_B] == 0.0:
            continue
        # the same operations, in the same order, as _walk.compose
        wb = 1.0 - front_a
        ray[k] = seg_ray[s]
        rgba[k, 0] = seg_acc[s, FRONT, ACC_R] + wb * seg_acc[s, BACK, ACC_R]
        rgba[k, 1] = seg_acc[s, FRONT, ACC_G] + wb * seg_acc[s, BACK, ACC_G]
        rgba[k, 2] = seg_acc[s, FRONT, ACC_B] + wb * seg_acc[s, BACK, ACC_B]
        rgba[k, 3] = front_a + wb * back_a
        depth[k, 0] = entry_t[s, FRONT] if seg_face[s, FRONT, 0] >= 0 else seg_ts[s, BACK, TS_T]
        depth[k, 1] = entry_t[s, BACK] if seg_face[s, BACK, 0] >= 0 else seg_ts[s, FRONT, TS_T]
        k += 1
    return ray, rgba, depth


def segment_fragments(S, entry_t, width: int, height: int) -> Fragments:
    """The fragments of a finished render's segment state ``S`` (see ``_segments``).

    ``entry_t`` : (n, 2) float64, each segment's ``SEG_TS`` ray parameters before any walk moved
    them (its entry and exit crossings).
    """
    ray, rgba, depth = _segment_fragments(S[SEG_RAY], S[SEG_FACE], S[SEG_TS], S[SEG_ACC], entry_t)
    return Fragments(ray, rgba, depth, int(width), int(height))


def merge_fragments(*parts: Fragments) -> Fragments:
    """All fragments of ``parts`` in one (of the same image size); the reduction step.

    Examples
    --------
    >>> a = Fragments(np.array([0], np.int32), np.array([[0.5, 0, 0, 0.5]]), np.array([[1.0, 2.0]]), 2, 1)
    >>> b = Fragments(np.array([0], np.int32), np.array([[0, 0.5, 0, 0.5]]), np.array([[0.0, 1.0]]), 2, 1)
    >>> merge_fragments(a, b)
    Fragments(2 fragments, 2x1, 0.00 MB)
    """
    if not parts:
        raise ValueError("merge_fragments needs at least one Fragments")
    w, h = parts[0].width, parts[0].height
    for p in parts:
        if (p.width, p.height) != (w, h):
            raise ValueError(f"fragments of a {p.width}x{p.height} image cannot merge with {w}x{h}")
    if len(parts) == 1:
        return parts[0]
    return Fragments(np.concatenate([p.ray for p in parts]), np.concatenate([p.rgba for p in parts]),
                     np.concatenate([p.depth for p in parts]), w, h)


def row_bands(height: int, n: int) -> list[tuple[int, int]]:
    """``height`` rows cut into ``n`` bands (at most one per row) of near-equal height, top first.

    Examples
    --------
    >>> row_bands(10, 3)
    [(0, 4), (4, 7), (7, 10)]
    """
    n = max(1, min(int(n), int(height)))
    cuts = [(int(height) * j + n - 1) // n for j in range(n + 1)]
    return [(cuts[j], cuts[j + 1]) for j in range(n)]


def split_rows(fragments: Fragments, bands) -> list[Fragments]:
    """``fragments`` cut into the image rows ``bands`` ((start, stop) pairs covering the image):
    each part a :class:`Fragments` of its band alone (pixels renumbered from the band's first row),
    in the input's order. Pixels are independent, so compositing the bands apart and stacking the
    rows gives the image of compositing them together (direct-send compositing).

    Examples
    --------
    >>> f = Fragments(np.array([0, 3, 5], np.int32), np.zeros((3, 4)), np.zeros((3, 2)), 2, 3)
    >>> [p.ray.tolist() for p in split_rows(f, row_bands(3, 2))]
    [[0, 3], [1]]
    """
    w = fragments.width
    if len(bands) == 1 and tuple(bands[0]) == (0, fragments.height):
        return [fragments]
    row = fragments.ray // w
    out = []
    for r0, r1 in bands:
        keep = (row >= r0) & (row < r1)
        out.append(Fragments((fragments.ray[keep] - r0 * w).astype(np.int32), fragments.rgba[keep],
                             fragments.depth[keep], w, int(r1 - r0)))
    return out


@njit(cache=True)
def _composite(ray, rgba, depth, n_rays, image):
    """Sort fragments by pixel (counting sort) and, within a pixel, by (front, back) depth
    (insertion sort: pixels have few fragments), then blend front to back (equation 4) into
    ``image``. Returns the number of pixels where two fragments overlap in depth by more than
    ``OVERLAP_TOLERANCE`` (0 for the fragments of a partition: a check, not a failure)."""
    start, order = group_by_ray(ray, n_rays)
    overlaps = 0
    for r in range(n_rays):
        lo, hi = start[r], start[r + 1]
        sort_run(order, lo, hi, depth[:, 0], depth[:, 1])
        bad = False
        for i in range(lo, hi):
            f = order[i]
            if i > lo:
                prev_back = depth[order[i - 1], 1]
                if depth[f, 0] < prev_back - OVERLAP_TOLERANCE * abs(prev_back):
                    bad = True
            # as _walk.compose: the segments of a ray, nearest first
            w = 1.0 - image[r, 3]
            image[r, 0] += w * rgba[f, 0]
            image[r, 1] += w * rgba[f, 1]
            image[r, 2] += w * rgba[f, 2]
            image[r, 3] += w * rgba[f, 3]
        if bad:
            overlaps += 1
    return overlaps


def composite(fragments: Fragments, *, stats: dict | None = None) -> np.ndarray:
    """The image of ``fragments``: every pixel's fragments sorted by depth, composited front to back.

    Parameters
    ----------
    fragments : Fragments
        Typically :func:`merge_fragments` of every brick's.
    stats : dict, optional
        Receives ``fragments_overlapping_pixels``: pixels whose fragments overlap in depth (bricks
        that are not a partition of one mesh; the blend is then in front-depth order).

    Returns
    -------
    (height, width, 4) float32
        Premultiplied RGBA, as :attr:`RenderResult.image`.

    Examples
    --------
    >>> near = Fragments(np.array([0, 1], np.int32), np.array([[0.5, 0, 0, 0.5], [0, 0, 0, 0.25]]),
    ...                  np.array([[1.0, 2.0], [1.0, 2.0]]), 2, 1)
    >>> far = Fragments(np.array([0], np.int32), np.array([[0, 1.0, 0, 1.0]]), np.array([[2.0, 3.0]]), 2, 1)
    >>> composite(merge_fragments(far, near))[0].tolist()
    [[0.5, 0.5, 0.0, 1.0], [0.0, 0.0, 0.0, 0.25]]
    """
    f = fragments
    n_rays = f.width * f.height
    if len(f) and (f.ray.min() < 0 or f.ray.max() >= n_rays):
        raise ValueError(f"fragment pixels must be in 0..{n_rays - 1}")
    image = np.zeros((n_rays, 4), np.float64)
    overlaps = _composite(np.ascontiguousarray(f.ray, np.int32), np.ascontiguousarray(f.rgba, np.float64),
                          np.ascontiguousarray(f.depth, np.float64), n_rays, image)
    if stats is not None:
        stats["fragments_overlapping_pixels"] = int(overlaps)
    return image.reshape(f.height, f.width, 4).astype(np.float32)
