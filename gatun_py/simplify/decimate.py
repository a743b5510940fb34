"""Offline Van Gelder decimation (paper section 4.1): the greedy vertex-merge order -> merge forest.

The error of merging a into b (a neighbour along an edge) is::

    W_density  * (sum over a's tets of |mass after - mass before|
                  + INTERP_WEIGHT * |density(a) - new interpolant at a| * volume of a's tets)
               / (density range * mesh volume)
  + W_geometry * (the paper's weighted boundary area difference / boundary area
                  + SWEPT_WEIGHT * volume swept by a's boundary faces / mesh volume)

(mass = volume x mean vertex density; a tet containing both a and b collapses and loses all its
mass). Both terms are fractions of a whole-mesh quantity, so the default weights balance them
without knowing the data's units. The interpolation term and the swept volume (sum over a's boundary faces of the tet between
the face and b) are our additions to the paper's errors: the first keeps the scalar field, the
second the boundary in place (see the constants for the measured effect). The
legality rules are listed in
:mod:`gatun_py.simplify._decimate_kernels`.
"""

from __future__ import annotations

import numpy as np

from ..errors import OptionError
from ..mesh import TetMesh
from ..mesh.model import TET_FACES
from . import _decimate_kernels as K
from .forest import MergeForest

__all__ = ["decimate", "DEFAULT_W_DENSITY", "DEFAULT_W_GEOMETRY", "SWEPT_WEIGHT", "INTERP_WEIGHT", "DecimationState"]

DEFAULT_W_DENSITY = 1.0
DEFAULT_W_GEOMETRY = 1.0
# Weight of the swept boundary volume inside the geometry error, relative to the paper's area term.
# The area term alone lets the boundary drift (equal-area faces in a different place): on Blunt-fin
# the sampled scalar RMS error at ratio 0.9 drops from 1.1 % to 0.8 % of the range with it.
SWEPT_WEIGHT = 100.0
# Weight of the interpolation error at the merged vertex inside the density error, relative to the
# paper's mass term: |density(a) - new mesh's interpolant at a's position| x volume around a. Mass
# alone is blind to where the scalar changes; with it the sampled RMS error at ratio 0.9 drops from
# 0.82 % to 0.18 % of the range on Blunt-fin (4.8 % to 1.3 % on Combustion).
INTERP_WEIGHT = 100.0


def _face_adjacency(tets: np.ndarray) -> np.ndarray:
    """nbr[t, k] = the tet across face k of t (the face opposite corner k), -1 on the boundary."""
    m = tets.shape[0]
    nbr = np.full((m, 4), -1, np.int32)
    if m == 0:
        return nbr
    f = np.sort(tets[:, TET_FACES].reshape(-1, 3).astype(np.int64), axis=1)
    n = int(tets.max()) + 1
    key = (f[:, 0] * n + f[:, 1]) * n + f[:, 2] if n < 2**21 else None
    order = np.argsort(key, kind="stable") if key is not None else np.lexsort((f[:, 2], f[:, 1], f[:, 0]))
    s = f[order]
    same = np.all(s[1:] == s[:-1], axis=1)
    i = np.flatnonzero(same)
    a, b = order[i], order[i + 1]
    nbr.reshape(-1)[a] = (b // 4).astype(np.int32)
    nbr.reshape(-1)[b] = (a // 4).astype(np.int32)
    return nbr


def _pinned_vertices(tets: np.ndarray, nbr: np.ndarray, n: int):
    """(is_boundary, pinned): boundary vertices, and vertices whose neighbourhood is not a manifold.

    A vertex is left alone when its link is not a sphere (interior) or a disk (boundary), judged by
    the link's Euler characteristic, or when it lies on a boundary edge not shared by exactly two
    boundary faces (edge- or vertex-touching parts). The link condition keeps every other vertex
    manifold, so this is decided once.
    """
    isb = np.zeros(n, bool)
    pinned = np.zeros(n, bool)
    m = tets.shape[0]
    if m == 0:
        return isb, pinned
    t = tets.astype(np.int64)
    bt, bk = np.nonzero(nbr < 0)
    bfaces = t[bt[:, None], TET_FACES[bk]]
    isb[bfaces.ravel()] = True
    # boundary edges shared by != 2 boundary faces
    if bfaces.shape[0]:
        e = np.sort(bfaces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        ue, cnt = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
        bad = ue[cnt != 2]
        pinned[bad // n] = True
        pinned[bad % n] = True
    # Euler characteristic of every vertex link: V (edges at v) - E (faces at v) + F (tets at v)
    ei = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    pairs = np.sort(t[:, ei].reshape(-1, 2), axis=1)
    ue = np.unique(pairs[:, 0] * n + pairs[:, 1])
    chi = np.bincount(ue // n, minlength=n) + np.bincount(ue % n, minlength=n)
    # every face at v is in two of v's tets, or in one when it is a boundary face
    n_tets_at = np.bincount(t.ravel(), minlength=n)
    n_bfaces_at = np.bincount(bfaces.ravel(), minlength=n)
    chi -= (3 * n_tets_at + n_bfaces_at) // 2
    chi += n_tets_at
    used = np.zeros(n, bool)
    used[t.ravel()] = True
    pinned |= used & np.where(isb, chi != 1, chi != 2)
    return isb, pinned


class DecimationState:
    """All arrays of a running decimation (the kernels mutate them in place)."""

    def __init__(self, mesh: TetMesh, w_density: float, w_geometry: float):
        n, m = mesh.n_points, mesh.n_tets
        self.n = n
        self.pts = mesh.points.astype(np.float64)
        self.T = np.array(mesh.tets, np.int32)
        self.alive = np.ones(m, bool)
        self.nbr = _face_adjacency(self.T)
        self.isb, self.pinned = _pinned_vertices(self.T, self.nbr, n)
        # incidence lists: slot 4t+c, each vertex's slots in tet order
        slots = np.argsort(self.T.reshape(-1), kind="stable").astype(np.int32)
        verts = self.T.reshape(-1)[slots]
        self.head = np.full(n, -1, np.int32)
        self.nxt = np.full(4 * m, -1, np.int32)
        if m:
            first = np.ones(slots.size, bool)
            first[1:] = verts[1:] != verts[:-1]
            self.head[verts[first]] = slots[first]
            cont = ~first[1:]
            self.nxt[slots[:-1][cont]] = slots[1:][cont]
        # normalisation: both errors as fractions of a whole-mesh quantity
        vol = float(np.abs(mesh.signed_volumes()).sum()) if m else 0.0
        lo, hi = mesh.scalar_range
        drange = hi - lo if hi > lo else max(abs(hi), 1.0)
        mass_scale = drange * vol if vol > 0 else 1.0
        bt, bk = np.nonzero(self.nbr < 0)
        if bt.size:
            bf = self.T[bt[:, None], TET_FACES[bk]]
            p = self.pts
            area = 0.5 * np.linalg.norm(np.cross(p[bf[:, 1]] - p[bf[:, 0]], p[bf[:, 2]] - p[bf[:, 0]]), axis=1).sum()
        else:
            area = 0.0
        area_scale = area if area > 0 else 1.0
        self.params = np.array([w_density / mass_scale, w_geometry / area_scale,
                                w_geometry * SWEPT_WEIGHT / (vol if vol > 0 else 1.0), INTERP_WEIGHT])
        self.dens = mesh.density.astype(np.float64)
        self.mark = np.zeros(n, np.int64)
        self.mark_b = np.zeros(n, np.int64)
        self.mark_ab = np.zeros(n, np.int64)
        self.counters = np.zeros(8, np.int64)
        self.ver = np.zeros(n, np.int32)
        self.last_err = np.full(n, -1.0)
        cap = 4 * n + 1024
        self.h_err = np.zeros(cap)
        self.h_v = np.zeros(cap, np.int32)
        self.h_b = np.zeros(cap, np.int32)
        self.h_ver = np.zeros(cap, np.int32)
        self.parent = np.arange(n, dtype=np.int32)
        self.rank = np.full(n, K.ROOT_RANK, np.int32)

    def _mesh_args(self):
        return (self.T, self.alive, self.nbr, self.head, self.nxt, self.pts, self.dens, self.isb, self.pinned,
                self.params, self.mark, self.mark_b, self.mark_ab, self.counters)

    def _heap_args(self):
        return (self.ver, self.h_err, self.h_v, self.h_b, self.h_ver, self.last_err)

    def start(self) -> None:
        """Evaluate every vertex's best merge (the first :meth:`run` does it too)."""
        self.run(0)

    def run(self, max_merges: int) -> bool:
        """Merge until ``max_merges`` in total; True when no legal merge is left."""
        return bool(K._run(*self._mesh_args(), *self._heap_args(), self.parent, self.rank, np.int64(max_merges)))

    def evaluate(self, a: int, b: int):
        """(legal, error) of merging a into b in the current state (for tests against the reference)."""
        st = K._star(a, self.head, self.nxt, self.T, self.alive)
        cand = np.empty(3 * st.shape[0] + 1, np.int64)
        err = np.empty(cand.shape[0])
        nc = K._candidate_errors(a, st, self.T, self.nbr, self.pts, self.dens, self.isb, self.pinned, self.params,
                                 self.mark, self.counters, cand, err)
        hit = np.flatnonzero(cand[:nc] == b)
        if hit.size == 0 or self.pinned[a]:
            return False, None
        ok = K._link_ok(a, b, st, self.T, self.alive, self.nbr, self.head, self.nxt, self.isb, self.mark_b,
                        self.mark_ab, self.counters)
        return bool(ok), float(err[hit[0]])

    def apply(self, a: int, b: int) -> None:
        """Merge a into b without any check (tests replay a forest with this)."""
        st = K._star(a, self.head, self.nxt, self.T, self.alive)
        K._apply_merge(a, b, st, self.T, self.alive, self.nbr, self.head, self.nxt)
        self.parent[a] = b
        self.rank[a] = self.counters[K.C_MERGES]
        self.counters[K.C_MERGES] += 1

    @property
    def n_merges(self) -> int:
        return int(self.counters[K.C_MERGES])

    def current_tets(self) -> np.ndarray:
        return self.T[self.alive].copy()


def decimate(mesh: TetMesh, *, w_density: float = DEFAULT_W_DENSITY, w_geometry: float = DEFAULT_W_GEOMETRY,
             progress=None, max_merges: int | None = None) -> MergeForest:
    """Greedy Van Gelder decimation of a tetrahedral mesh into a merge forest.

    Parameters
    ----------
    mesh : TetMesh
        Positively oriented tets (zero-volume tets allowed: they may stay flat or collapse, but no
        other tet may become flat or inverted).
    w_density, w_geometry : float
        Weights of the (normalised) density and boundary-geometry errors; >= 0, finite.
    progress : callable, optional
        Called as ``progress(k)`` with the number of merges done since the previous call.
    max_merges : int, optional
        Stop after this many merges (default: until no legal merge is left).

    Returns
    -------
    MergeForest
        Every prefix of its merges is a state the decimator checked: positive tets (except the
        input's own flat ones), boundary orientation kept, manifold with a closed boundary.
    """
    for name, w in (("w_density", w_density), ("w_geometry", w_geometry)):
        if not np.isfinite(w) or w < 0:
            raise OptionError(f"{name} must be a finite number >= 0, got {w}")
    state = DecimationState(mesh, float(w_density), float(w_geometry))
    limit = mesh.n_points if max_merges is None else max(0, min(int(max_merges), mesh.n_points))
    state.start()
    done = 0
    chunk = max(1024, mesh.n_points // 50)
    while True:
        target = min(limit, state.n_merges + chunk) if progress is not None else limit
        finished = state.run(target)
        if progress is not None:
            progress(state.n_merges - done)
        done = state.n_merges
        if finished or done >= limit:
            break
    return MergeForest(state.parent.copy(), state.rank.copy(), state.n_merges)
