"""The ray caster's segment state (private): one tuple of arrays, built by :func:`make_segments`.

A *segment* is the part of one pixel ray between an entry into the mesh and the next exit
(``_boundary`` finds them). It has two *subsegments*: the front one (``FRONT``) walks from the
entry face along the ray, the back one (``BACK``) from the exit face toward the eye; each stops on
the face behind which the next tet has not arrived yet (its water mark) and the segment is done
when the two marks meet (``_walk``).

The kernels take the whole state as one argument ``S`` and unpack it (the codec's border is passed
the same way). ``S[SEG_...]`` names each array:

=============== =================== ==================================================================
field           array               meaning
=============== =================== ==================================================================
``SEG_RAY``     (n,) int32          the pixel ray (row-major pixel index); segments are stored ray by
                                    ray, nearest first
``SEG_FACE``    (n, 2, 3) int32     per subsegment: the face it stands on (sorted vertex ids; -1: this
                                    end does not exist, see ``_pair_hits``)
``SEG_FROM``    (n, 2) int32        per subsegment: the fourth vertex of the tet it came through (-1:
                                    from outside the mesh; ``FOLD_END``: it ended at a fold face)
``SEG_CLEAN``   (n, 2) uint8        per subsegment: 1 if it reached its face by a clean crossing (all
                                    three edge sides agreed), 0 if not, ``NEVER_COUNTS``: its walks
                                    never touch a counting table's counters
``SEG_TS``      (n, 2, 2) float64   per subsegment: ray parameter ``TS_T`` and scalar ``TS_SCALAR``
                                    where it stands
``SEG_ACC``     (n, 2, 4) float64   per subsegment: its composited premultiplied colour (``ACC_R``,
                                    ``ACC_G``, ``ACC_B``, opacity ``ACC_A``)
``SEG_STATE``   (n,) uint8          ``STATE_ACTIVE``, ``STATE_DONE`` or ``STATE_STUCK``
``SEG_STEPS``   (n,) int64          tet steps taken by both subsegments (bounds a looping walk)
``SEG_SAMPLES`` (n,) int64          samples composited (statistics)
``SEG_MARK``    (n,) int64          the last batch that put the segment on the list to advance
=============== =================== ==================================================================
"""

from __future__ import annotations

import numpy as np

SEG_RAY, SEG_FACE, SEG_FROM, SEG_CLEAN, SEG_TS, SEG_ACC, SEG_STATE, SEG_STEPS, SEG_SAMPLES, SEG_MARK = range(10)

FRONT, BACK = 0, 1  # the subsegments (second axis of the per-subsegment arrays)
TS_T, TS_SCALAR = 0, 1  # columns of SEG_TS
ACC_R, ACC_G, ACC_B, ACC_A = 0, 1, 2, 3  # columns of SEG_ACC

STATE_ACTIVE = 0
STATE_DONE = 1
STATE_STUCK = 2

NEVER_COUNTS = 2  # SEG_CLEAN: this segment's walk does not touch the face counters
FOLD_END = -2  # SEG_FROM: the subsegment left the mesh through a fold face (see _walk) and is over


def make_segments(ray, face, came_from, ts, n_rays: int):
    """The segment state ``S`` of segments that have not moved yet, and the rays to watch.

    Parameters
    ----------
    ray : (n,) int32
    face, came_from, ts
        ``SEG_FACE``, ``SEG_FROM`` and ``SEG_TS`` at the boundary (``_boundary.find_segments``).
    n_rays : int

    Returns
    -------
    S : tuple
        Indexed by the ``SEG_*`` constants.
    odd_rays : (n_rays,) uint8 or (0,) uint8
        1 for the rays with a one-ended segment (their boundary crossings did not pair up: a
        grid that overlaps itself), whose segments never count (``NEVER_COUNTS``); empty if none.
    """
    n = len(ray)
    clean = (face[:, :, 0] >= 0).astype(np.uint8)  # boundary crossings are clean
    one_ended = face[:, :, 0].min(axis=1) < 0
    odd_rays = np.zeros(0, dtype=np.uint8)
    if np.any(one_ended):  # rays whose crossings did not pair up may walk some tets twice
        odd_rays = np.zeros(n_rays, dtype=np.uint8)
        odd_rays[ray[one_ended]] = 1
        clean[odd_rays[ray] != 0] = NEVER_COUNTS
    S = (ray, face, came_from, clean, ts, np.zeros((n, 2, 4), dtype=np.float64), np.zeros(n, dtype=np.uint8),
         np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64))
    return S, odd_rays
