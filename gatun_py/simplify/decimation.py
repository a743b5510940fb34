"""Offline Van Gelder decimation (paper section 4.1): the greedy vertex-merge order -> merge forest.

The error of merging a into b (a neighbour along an edge; b keeps its position and value) is::

    ( W_density  * (MASS_WEIGHT * sum over a's tets of |mass after - mass before| / (density range * mesh volume)
                    + INTERP_WEIGHT * ((density(a) - new interpolant at a) / density range)^2
                                    * volume of a's tets / mesh volume
                    + QUADRIC_WEIGHT * Q_a(b)
                    + SAMPLE_WEIGHT * sum over the sample points p in a's tets of share(p)
                                    * [((density(p) - new interpolant at p) / density range)^2
                                       - ((density(p) - current interpolant at p) / density range)^2])
    + W_geometry * (the paper's weighted boundary area difference / boundary area
                    + SWEPT_WEIGHT * volume swept by a's boundary faces / mesh volume)
    ) / (number of tets the merge collapses) ** COLLAPSE_POWER

(mass = volume x mean vertex density; a tet containing both a and b collapses and loses all its
mass). Every term is a fraction of a whole-mesh quantity, so the default weights balance them
without knowing the data's units.

``Q_a`` is a quadric in (x, y, z, s) that remembers the original field (Garland & Zhou's
simplex quadrics, as in VTK's ``vtkUnstructuredGridQuadricDecimation``): every input tet
contributes its volume fraction x the squared distance to the 4D hyperplane through its four
(position, value) points (divided by ``SCALAR_SCALE``^2) to each of its corners, and a merge
a -> b adds Q_a to Q_b. Q_a(b) is then how far b's (position, value) lies from the linear pieces of every original tet that a
stands for, not only from a's current neighbourhood: this keeps the errors of earlier merges from
piling up. Positions are scaled by the bounding-box diagonal and values by their range times
``SCALAR_SCALE``; with a small scale the distance is the value deviation from each tet's linear
function, damped only for very steep tets.

The sample points measure the error against the original field where the quadric only models
it (as Cignoni et al.'s "accurate error evaluation"): the centroid of every input tet (from the
start) and every vertex merged away so far are points of the original field (position and
value), each listed in the live tet that contains it; a merge a -> b moves a and the points of
a's tets to the tet of the new star that contains them (the nearest one if a boundary merge left
them outside; dropped if no tet of the star is left). ``share(p)`` is a centroid's tet volume
times ``CENTROID_WEIGHT``, or a quarter of the volume of a vertex's input tets, over the mesh
volume. The term is the change of the sampled squared error in the only region the merge
changes, so it may be negative (a merge that fits the original field better than the current mesh
does). Beyond ``MAX_SAMPLES`` points in a's tets (late merges only), every k-th stands for k.

The mass and area terms are the paper's; the interpolation term, the quadric, the sample points,
the swept volume (sum over a's boundary faces of the tet between the face and b) and the division
by the collapsed tets (the comparison that matters is at equal tet counts: it prefers merges that
remove more tets for the same error) are our additions. How the weights below were chosen, and
what each term does to the images and to the time: ``bench/studies/decimation_weights.md`` and
``bench/sections/simplify.md``. The legality rules are listed in
:mod:`gatun_py.simplify._decimate_kernels`.

Each term is one small kernel (``_mass_error``, ``_interp_deviation``, ``_area_error``,
``_swept_volume``, ``_quadric_at``, ``_sample_error``, summed by ``_total_error`` in one fixed
order). The search for a vertex's best merge is a branch and bound: the cheap terms of every
candidate first, with the interpolation term (>= 0) left out and the sampled error at its most
negative (every point's new error 0) as a lower bound, then the two expensive terms only for the
candidates whose bound can still win, and of those the sampled sum stops as soon as the bound with
the points not yet summed at 0 loses (it only grows point by point); the choice is the one of
computing every error, bit for bit. The first evaluation of every vertex and the sweeps run in parallel
(each evaluation only reads the mesh), and their results are pushed in vertex order, so the forest
does not depend on the thread count either.

Rounds of independent merges (what makes the ranks cheap to store). Every level's
interval of ranks [N_i, N_i+1) is split into rounds (``ROUNDS_PER_LEVEL`` equal quotas; a round also
ends early once more than ``ROUND_BLOCKED`` x its quota of popped candidates were blocked, or when
every candidate left is). A merge a -> b locks every vertex of a's star St(a) (the vertices of the
tets around a, a and b included) and marks b as a target; a popped candidate a' -> b' whose a' or
b' is locked, or whose star holds a target, waits for the next round with its heap entry (error)
unchanged. So for any two merges a -> b and a' -> b' of a round: a' and b' are not in St(a), and
b is not in St(a') (whichever came first). Why that makes them commute, every prefix in any order
legal and the end mesh the same:

* no tet contains both a and a' (that would put a' in St(a)), so the two merges relabel and
  collapse disjoint sets of tets, and the sample points they move live in disjoint stars;
* a merge a -> b changes only the tets around a (relabelled or collapsed) and the face adjacency
  of their neighbours across the collapsed tets: those contain b or a; the tets around a' and b'
  contain neither a (a' and b' are not in St(a)) nor, for the gluing across a collapsed tet, the
  pair b and a vertex of St(a) with a' (b is not in St(a')); so St(a'), the boundary faces at a'
  and b', and the links Lk(a'), Lk(b'), Lk(a'b') are the same before and after a -> b;
* the legality of a' -> b' (positive tets of its star, boundary orientation, boundary vertices
  into boundary vertices, the link condition) reads only those, so it holds after a -> b as it
  did before, and symmetrically; by induction every order of a round's merges, and every prefix
  of every order, passes every check, and the relabelled tets are the same in any order.

``tests/test_simplify_rounds.py`` replays every round in random orders with the slow reference
(legal at every step, the same mesh at the round's end). Inside a round the ranks are then
re-assigned by :func:`canonical_key` (float32 bits of position, then value: what the forest's
decoder computes in every level's numbering), a round holding two equal keys being split between
them first; a level's interval stays a union of whole rounds, so level i's forest is still the full
forest's ranks >= N_i minus N_i. Parents always land in a later round than their children (b is
locked by a -> b), so a parent still outranks its child.

The rounds run in one kernel call (``_run_rounds``, no GIL) per eighth of a level: ``tetc compress``
encodes the levels' meshes in a thread meanwhile (level i once ``on_level`` says its merges are
done, level 0 from level 1's end on), so the encoder never waits for a return to Python.

What keeps the merge loop fast, every step bit-identical: every sample point caches its error in
its tet (the star sums read it instead of forming every star tet's planes), a tet's points are a
run of rows (no chain to walk; a stride jumps), an evaluation's scratch arrays are views of a
per-thread buffer, and the heap holds one entry per vertex (no superseded entries to pop). The loop
is bound by memory latency, and a mesher's numbering can have no locality at all, so the state
works in a local numbering (:func:`local_order`: vertices along a Morton curve, tets by their
smallest new vertex id), drops the dead tets as they pile up, and hands out only the caller's
ids; the merges are the same bit for bit (see :class:`DecimationState`; ``bench/forest_identity.py
--check`` and ``tests/test_forest_identity.py``). Where the time goes: ``bench/sections/simplify.md``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from ..codec.forest import canonical_key as forest_key
from ..errors import OptionError
from ..mesh import TetMesh
from ..mesh.model import TET_FACES
from . import _decimate_kernels as K
from .forest import MergeForest
from .levels import level_ends, level_merges

__all__ = ["decimate", "DEFAULT_W_DENSITY", "DEFAULT_W_GEOMETRY", "SWEPT_WEIGHT", "INTERP_WEIGHT", "MASS_WEIGHT",
           "QUADRIC_WEIGHT", "SCALAR_SCALE", "SAMPLE_WEIGHT", "COLLAPSE_POWER",
           "MAX_SAMPLES", "CENTROID_WEIGHT", "DecimationState", "tet_quadrics", "ROUNDS_PER_LEVEL", "local_order",
           "canonical_key"]

# The weights of the error terms (see the module docstring). Each is a fraction of a whole-mesh
# quantity, so they hold across data sets; they were chosen by the image error at equal tet counts
# against the full render and against VTK's quadric decimation (bench/studies/decimation_weights.md,
# bench/sections/simplify.md).
DEFAULT_W_DENSITY = 1.0
DEFAULT_W_GEOMETRY = 1.0
# The swept boundary volume inside the geometry error, relative to the paper's area term: the area
# term alone lets the boundary drift (equal-area faces in a different place).
SWEPT_WEIGHT = 100.0
# The quadric carries most of the density error. What it leaves is the freedom of a decimator that
# picks new vertex values (VTK solves for the quadric's minimum): a merge forest keeps the original
# vertices and values.
QUADRIC_WEIGHT = 1e3
SCALAR_SCALE = 0.01
# The squared interpolation error at the merged vertex: the one thing the quadric does not see
# (how the new neighbourhood interpolates a's own value).
INTERP_WEIGHT = 1e3
# The paper's mass term, off by default: mass gained in one tet and lost in the next cancel, so it
# hides local errors, and with the terms above it only makes the images worse.
MASS_WEIGHT = 0.0
# The sample points (merged vertices and the input tets' centroids) and the power of the collapsed
# tet count; the sample points are most of the decimation's time (``w_sample=0`` leaves them out).
SAMPLE_WEIGHT = 1e4
COLLAPSE_POWER = 1.5
# At most this many sample points per evaluation: beyond, every k-th point of a's star stands for
# k (a bound on the cost of the late merges, whose stars hold thousands of points).
MAX_SAMPLES = 256
# Weight of the input tets' centroids among the sample points (the merged vertices have 1).
CENTROID_WEIGHT = 1.0
# Rounds of independent merges per level (see decimate's ``rounds``), and the fraction of a round's
# quota of blocked candidates that ends it early: more rounds cost the forest's coding more bits per
# vertex (log2 of the rounds), fewer make the order less greedy and the images worse.
ROUNDS_PER_LEVEL = 64
ROUND_BLOCKED = 0.25
# Room for sample point rows beyond the n + m points, as a fraction of n + m: a merge writes the runs
# of its star's points there, and when the rows run out they are rewritten (the more room, the
# rarer the rewrites, each O(n + m); 56 bytes per row).
POINT_SLACK = 0.25
# Tets per chunk of the vectorised set-up (bounds its temporaries).
_CHUNK = 1 << 16


def tet_quadrics(u4: np.ndarray, tets: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per-vertex sum of the weighted 4D hyperplane quadrics of its tets.

    Parameters
    ----------
    u4 : (n, 4) float64
        (x, y, z, s) of every vertex.
    tets : (m, 4) int
    weight : (m,) float64
        Weight of every tet's quadric (flat tets, whose hyperplane is not unique, should get 0).

    Returns
    -------
    (n, 15) float64
        A's upper triangle (00 01 02 03 11 12 13 22 23 33), b (4), c: the quadric of vertex v at
        u is ``u^T A u + 2 b.u + c`` = sum over its tets of weight x (unit normal . (u - corner))^2.
    """
    n = u4.shape[0]
    out = np.zeros((n, 15))
    tets = np.ascontiguousarray(tets, np.int32)  # DecimationState's dtype: one compiled kernel
    m = tets.shape[0]
    if m == 0:
        return out
    # per tet its unit normal, offset and weight (48 bytes; its 15 quadric terms would be 120)
    planes = np.empty((m, 6))
    K._tet_hyperplanes(np.ascontiguousarray(u4, np.float64), tets, np.ascontiguousarray(weight, np.float64), planes)
    K._accumulate_quadrics(tets, planes, out)
    return out


def _topology(T: np.ndarray, n: int):
    """(face neighbours, boundary vertices, pinned vertices) of tets ``T`` in their numbering."""
    head, nxt = K._incidence(T, n)
    nbr = K._face_neighbours(T, head, nxt)
    isb, pinned = K._vertex_topology(T, nbr, head, nxt, n)
    return nbr, isb, pinned


class DecimationState:
    """All arrays of a running decimation (the kernels mutate them in place).

    The kernels work in a local numbering of the vertices and tets (``order``, by default
    :func:`local_order`: neighbours near each other in memory; the caller's numbering of a
    gmsh mesh has none, and the merge loop is bound by memory latency). Everything computed
    from sums over tets or vertices (quadrics, weights, adjacency, scales) is set up in the
    caller's numbering and then renumbered, every vertex's incidence list keeps the caller's tet
    order, and every tie between equal errors goes to the smaller caller's id (``vkey``): so the
    merges are the same in any local numbering, bit for bit. What the state hands out
    (:meth:`prefix`, :meth:`evaluate`, :meth:`apply`, :meth:`current_tets`,
    :meth:`lock_vertices`) is in the caller's numbering; the arrays themselves are local
    (``v_orig[v]``: the caller's id of local vertex v, ``v_local`` its inverse; ``t_orig`` the
    same for tets). Once half of the tet rows are dead, :meth:`compact` drops them (the live ones
    keep their order, every list its live slots in order: the same merges again).

    Parameters
    ----------
    mesh : TetMesh
    w_density, w_geometry : float
    order : (vertex order, tet order), "input" or None
        The local numbering: local vertex i is the caller's ``vertex_order[i]`` (likewise tets);
        "input" keeps the caller's numbering; None: :func:`local_order`.
    w_sample : float
        Factor on the sampled error term (see :func:`decimate`).
    """

    def __init__(self, mesh: TetMesh, w_density: float, w_geometry: float, *, order=None, w_sample: float = 1.0):
        n, m = mesh.n_points, mesh.n_tets
        self.n = n
        pts = mesh.points.astype(np.float64)
        dens = mesh.density.astype(np.float64)
        T0 = np.array(mesh.tets, np.int32)
        # set-up in the caller's numbering (every sum in its order), renumbered below. The face
        # pairing and the vertex topology (GIL-free kernels) run in a thread beside the quadrics
        # and the local order: neither reads the other's results.
        with ThreadPoolExecutor(1, thread_name_prefix="tetc-setup") as pool:
            topology = pool.submit(_topology, T0, n)
            # normalisation: both errors as fractions of a whole-mesh quantity
            tet_vol = np.abs(mesh.signed_volumes()) if m else np.zeros(0)
            vol = float(tet_vol.sum()) if m else 0.0
            lo, hi = mesh.scalar_range
            drange = hi - lo if hi > lo else max(abs(hi), 1.0)
            mass_scale = drange * vol if vol > 0 else 1.0
            vol_n = vol if vol > 0 else 1.0
            # the quadrics carry their weight (W_density x QUADRIC_WEIGHT) so that sums of them stay sums
            lo_p = pts.min(axis=0) if n else np.zeros(3)
            diag = float(np.linalg.norm(pts.max(axis=0) - lo_p)) if n else 1.0
            diag = diag if diag > 0 else 1.0
            u4 = np.empty((n, 4))
            u4[:, :3] = (pts - lo_p) / diag
            u4[:, 3] = SCALAR_SCALE * (dens - lo) / drange
            tet_w = tet_vol / vol_n
            del tet_vol
            quad = tet_quadrics(u4, T0, tet_w * (w_density * QUADRIC_WEIGHT / SCALAR_SCALE**2))
            vw = K._vertex_weights(T0, tet_w, n)
            local = local_order(mesh) if order is None else None
            nbr0, isb0, pinned0 = topology.result()
        bt, bk = np.nonzero(nbr0 < 0)
        if bt.size:
            bf = T0[bt[:, None], TET_FACES[bk]]
            area = 0.5 * np.linalg.norm(np.cross(pts[bf[:, 1]] - pts[bf[:, 0]], pts[bf[:, 2]] - pts[bf[:, 0]]),
                                        axis=1).sum()
            del bf
        else:
            area = 0.0
        del bt, bk
        area_scale = area if area > 0 else 1.0
        self.params = np.array([MASS_WEIGHT * w_density / mass_scale, w_geometry / area_scale,
                                w_geometry * SWEPT_WEIGHT / vol_n, INTERP_WEIGHT * w_density / (drange**2 * vol_n),
                                1.0 if w_density * QUADRIC_WEIGHT > 0 else 0.0,
                                SAMPLE_WEIGHT * w_density * w_sample / drange**2, COLLAPSE_POWER, MAX_SAMPLES])
        # the local numbering
        if order is None:
            v_orig, t_orig = local
        elif isinstance(order, str) and order == "input":
            v_orig, t_orig = np.arange(n), np.arange(m)
        else:
            v_orig, t_orig = (np.asarray(x, np.int64) for x in order)
            if not (np.array_equal(np.sort(v_orig), np.arange(n)) and np.array_equal(np.sort(t_orig), np.arange(m))):
                raise OptionError("order must be a permutation of the vertices and one of the tets")
        self.v_orig = np.ascontiguousarray(v_orig, np.int32)
        self.v_local = np.empty(n, np.int32)
        self.v_local[self.v_orig] = np.arange(n, dtype=np.int32)
        self.t_orig = np.ascontiguousarray(t_orig, np.int32)
        t_local = np.empty(m, np.int32)
        t_local[self.t_orig] = np.arange(m, dtype=np.int32)
        self.T = K._relabel_rows(T0, self.t_orig, self.v_local)
        del T0
        self.nbr = K._relabel_rows(nbr0, self.t_orig, t_local)
        del nbr0
        # incidence lists: slot 4t+c, each vertex's slots in the caller's tet order
        self.head, self.nxt = K._incidence_in_order(self.T, n, t_local)
        del t_local
        self.alive = np.ones(m, bool)
        self.pts = pts[self.v_orig]
        self.dens = dens[self.v_orig]
        del pts, dens
        self.isb = isb0[self.v_orig]
        self.pinned = pinned0[self.v_orig]
        self.u4 = u4[self.v_orig]
        del u4
        self.quad = quad[self.v_orig]
        del quad
        self.vw = vw[self.v_orig]
        # Sample points of the original field, listed in the live tet holding them: every input
        # tet's centroid from the start (ids n + t, weight its volume fraction x CENTROID_WEIGHT),
        # every vertex once merged away (weight a quarter of its tets' volume fraction); one row
        # (x, y, z, value, weight, error) per point, the centroids first (prow: which point a row
        # is, in the local numbering, and the tet its run was written for); error: its weighted
        # squared error in the tet holding it, kept up to date by the merges that move it (see
        # _decimate_kernels._star_samples).
        # A tet's points are a run of rows (tp_head[t], tp_count[t] of them); a merge writes the
        # new runs of its star at the top, and the rows are rewritten from 0 when they run out.
        rows = n + m + int(POINT_SLACK * (n + m))
        self.pdat, self.prow = K._centroid_points(self.pts, self.dens, self.T, tet_w[self.t_orig], CENTROID_WEIGHT,
                                                    rows)
        del tet_w
        self.tp_head = np.arange(m, dtype=np.int32)
        self.tp_count = np.ones(m, np.int32)
        K._set_point_errors(self.T, self.pts, self.dens, self.pdat, self.tp_head, self.tp_count)
        # per thread of the parallel evaluations: stamp rows and counters (stamps, evaluations)
        threads = max(1, int(numba.config.NUMBA_NUM_THREADS))
        self.marks = np.zeros((threads, n), np.int64)
        self.marks_b = np.zeros((threads, n), np.int64)
        self.marks_ab = np.zeros((threads, n), np.int64)
        self.tcount = np.zeros((threads, K.N_COUNTERS), np.int64)
        self.counters = np.zeros(K.N_COUNTERS, np.int64)
        self.counters[K.C_PTOP] = m
        self.ver = np.zeros(n, np.int32)
        self.last_err = np.full(n, -1.0)
        # at most one entry per vertex in the heap (h_pos), and at most one current entry per
        # vertex among those a round sets aside (a full list drops the others first)
        cap = 2 * n + 1024
        self.h_err = np.zeros(cap)
        self.h_v = np.zeros(cap, np.int32)
        self.h_b = np.zeros(cap, np.int32)
        self.h_ver = np.zeros(cap, np.int32)
        self.h_pos = np.full(n, -1, np.int32)  # every vertex's entry in the heap (at most one)
        # the forest so far, local: parent[v] (a local id), rank[v]
        self.parent = np.arange(n, dtype=np.int32)
        self.rank = np.full(n, K.ROOT_RANK, np.int32)
        # rounds of independent merges: the vertices locked by the round stamped in ``lock`` (a
        # merge's star) and ``lock_b`` (its target)
        self.lock = np.zeros(n, np.int64)
        self.lock_b = np.zeros(n, np.int64)
        self.round = 0

    def _mesh_args(self):
        return (self.T, self.alive, self.nbr, self.head, self.nxt, self.pts, self.dens, self.isb, self.pinned,
                self.params, self.quad, self.u4, self.v_orig)

    def _sample_args(self):
        return (self.pdat, self.tp_head, self.tp_count)

    def _heap_args(self):
        return (self.ver, self.h_err, self.h_v, self.h_b, self.h_ver, self.h_pos, self.last_err)

    def start(self) -> None:
        """Evaluate every vertex's best merge (the first :meth:`run` does it too)."""
        self.run(0)

    def run(self, max_merges: int, *, one_round: bool = False, max_blocked: int = 2**62) -> bool:
        """Merge until ``max_merges`` in total; True when no legal merge is left.

        With ``one_round`` the merges are one round of independent merges, which may end before
        ``max_merges``: when every candidate left is blocked by the round's earlier merges, or
        when more than ``max_blocked`` candidates were.
        """
        stamp = 0
        if one_round:
            self.round += 1
            stamp = self.round
        return bool(K._run(*self._mesh_args(), self.marks, self.marks_b, self.marks_ab, self.tcount, self.counters,
                           *self._heap_args(), self.parent, self.rank, np.int64(max_merges), *self._sample_args(),
                           self.vw, self.prow, self.lock, self.lock_b, np.int64(stamp), np.int64(max_blocked)))

    def run_rounds(self, ends: np.ndarray, max_blocked: np.ndarray):
        """Rounds of independent merges (as :meth:`run` with ``one_round``) up to every ``ends[r]``
        in turn, each round with ``max_blocked[r]``, in one kernel call. Returns (the first merge
        count of every round started, finished, the last index of ``ends`` worked on)."""
        ends = np.ascontiguousarray(ends, np.int64)
        starts = np.empty(max(0, int(ends[-1]) - self.n_merges) + 1 if ends.size else 0, np.int64)
        round_no = np.array([self.round], np.int64)
        k, finished, r = K._run_rounds(*self._mesh_args(), self.marks, self.marks_b, self.marks_ab, self.tcount,
                                       self.counters, *self._heap_args(), self.parent, self.rank,
                                       *self._sample_args(), self.vw, self.prow, self.lock, self.lock_b, ends,
                                       np.ascontiguousarray(max_blocked, np.int64), round_no, starts)
        self.round = int(round_no[0])
        return [int(x) for x in starts[:k]], bool(finished), int(r)

    def prefix(self) -> MergeForest:
        """The merges so far as a forest in the caller's numbering (copies; ranks in merge order)."""
        parent = np.empty_like(self.parent)
        parent[self.v_orig] = self.v_orig[self.parent]
        rank = np.empty_like(self.rank)
        rank[self.v_orig] = self.rank
        return MergeForest(parent, rank, self.n_merges)

    def lock_vertices(self, locked: np.ndarray) -> None:
        """Never merge away the vertices of ``locked`` (a bool mask in the caller's numbering)."""
        self.pinned[self.v_local[np.flatnonzero(locked)]] |= K.PIN_KEEP

    def evaluate(self, a: int, b: int):
        """(legal, error) of merging a into b (caller's ids) in the current state (for tests against
        the reference)."""
        a, b = int(self.v_local[a]), int(self.v_local[b])
        st = K._star(a, self.head, self.nxt, self.T, self.alive)
        cand = np.empty(3 * st.shape[0] + 1, np.int64)
        err = np.empty(cand.shape[0])
        nc = K._candidate_errors(a, st, self.T, self.nbr, self.pts, self.dens, self.isb, self.pinned, self.params,
                                 self.quad, self.u4, self.marks[0], self.tcount[0], cand, err, *self._sample_args())
        hit = np.flatnonzero(cand[:nc] == b)
        if hit.size == 0 or self.pinned[a]:
            return False, None
        ok = K._link_ok(a, b, st, self.T, self.alive, self.nbr, self.head, self.nxt, self.isb, self.marks_b[0],
                        self.marks_ab[0], self.tcount[0])
        return bool(ok), float(err[hit[0]])

    def apply(self, a: int, b: int) -> None:
        """Merge a into b (caller's ids) without any check (tests replay a forest with this)."""
        a, b = int(self.v_local[a]), int(self.v_local[b])
        st = K._star(a, self.head, self.nxt, self.T, self.alive)
        nb = np.unique(self.T[st >> 2])
        K._merge(a, b, st, nb[nb != a].astype(np.int64), self.T, self.alive, self.nbr, self.head, self.nxt, self.pts,
                 self.dens, self.params, self.quad, self.pdat, self.vw, self.prow, self.tp_head, self.tp_count,
                 self.counters)
        self.parent[a] = b
        self.rank[a] = self.counters[K.C_MERGES]
        self.counters[K.C_MERGES] += 1

    @property
    def p_orig(self) -> np.ndarray:
        """Which point every row of ``pdat`` is (a local vertex id, or n + t for tet t's centroid)."""
        return self.prow[:, 0]

    @property
    def n_merges(self) -> int:
        return int(self.counters[K.C_MERGES])

    def current_tets(self) -> np.ndarray:
        """The live tets, in the caller's numbering and tet order."""
        live = np.flatnonzero(self.alive)
        return self.v_orig[self.T[live[np.argsort(self.t_orig[live])]]]

    def compact(self) -> None:
        """Drop the dead tets (the live ones keep their order; ``t_orig`` follows): once most tets
        are dead, the star walks touch fewer cache lines. The merges that follow are the same."""
        (self.T, self.nbr, self.nxt, self.tp_head, self.tp_count,
         self.t_orig) = K._compact_tets(self.T, self.alive, self.nbr, self.head, self.nxt, self.tp_head,
                                        self.tp_count, self.t_orig, self.prow, self.counters)
        self.alive = np.ones(self.T.shape[0], bool)

    def compact_if_sparse(self) -> None:
        """:meth:`compact` once at least half of the tet rows are dead (amortised O(1) per merge)."""
        if self.T.shape[0] > 1024 and 2 * np.count_nonzero(self.alive) <= self.T.shape[0]:
            self.compact()


def local_order(mesh: TetMesh):
    """(vertex order, tet order) of the decimator's local numbering: the vertices by the Morton
    code of their position on a 1024^3 grid over the bounding box (the caller's order among
    equal codes), the tets by their smallest new vertex id (then the caller's order). Local
    vertex i is the caller's ``vertex_order[i]``.

    Why: the merge loop walks stars, candidates, quadrics and point lists, and is bound by memory
    latency; a mesher's numbering can have no locality at all (a tet's vertex ids spread over
    the whole range)."""
    n, m = mesh.n_points, mesh.n_tets
    if n == 0:
        return np.zeros(0, np.int64), np.arange(m)
    p = mesh.points.astype(np.float64)
    lo = p.min(axis=0)
    ext = float((p.max(axis=0) - lo).max())
    cell = np.clip(((p - lo) * (1023.0 / ext if ext > 0 else 0.0)).astype(np.int64), 0, 1023)
    code = _spread_bits(cell[:, 0]) | (_spread_bits(cell[:, 1]) << 1) | (_spread_bits(cell[:, 2]) << 2)
    v_order = np.argsort(code, kind="stable")
    v_new = np.empty(n, np.int32)
    v_new[v_order] = np.arange(n, dtype=np.int32)
    first = np.empty(m, np.int32)
    for lo_t in range(0, m, _CHUNK):  # bounded temporaries
        first[lo_t:lo_t + _CHUNK] = v_new[mesh.tets[lo_t:lo_t + _CHUNK]].min(axis=1)
    return v_order, np.argsort(first, kind="stable")


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """10-bit integers with two zero bits after every bit (one axis of a 3D Morton code)."""
    x = x & 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


def canonical_key(mesh: TetMesh) -> np.ndarray:
    """Every vertex's place in the order that ranks follow inside a round: the float32 bit
    patterns of x, y, z and the scalar, compared in that order (dense key ranks, equal points and
    values share one; :func:`gatun_py.codec.forest.canonical_key`, which the forest's decoder
    computes from the level's geometry)."""
    return forest_key(mesh.points, mesh.density)


def _canonical_ranks(rank: np.ndarray, n_merges: int, round_starts: list[int], key: np.ndarray):
    """Ranks re-assigned inside every round in ``key`` order; a round holding two vertices of
    equal key is split between them (in execution order) first. Returns (rank, round_starts)."""
    by_rank = np.empty(n_merges, np.int64)
    merged = np.flatnonzero(rank < n_merges)
    by_rank[rank[merged]] = merged
    k = key[by_rank]
    starts = np.array(sorted({s for s in round_starts if s < n_merges} | {0}), np.int64) if n_merges \
        else np.zeros(0, np.int64)
    while True:
        rid = np.searchsorted(starts, np.arange(n_merges), side="right") - 1
        perm = np.lexsort((k, rid))
        tie = (rid[perm[1:]] == rid[perm[:-1]]) & (k[perm[1:]] == k[perm[:-1]])
        if not tie.any():
            break
        cut = np.maximum(perm[1:][tie], perm[:-1][tie])
        starts = np.union1d(starts, cut)
    out = rank.copy()
    out[by_rank[perm]] = np.arange(n_merges, dtype=out.dtype)
    return out, [int(x) for x in starts]


def _round_ends(n_points: int, limit: int, rounds: int) -> list[int]:
    """(end, quota) of every round at the latest: each level's interval [N_i, N_i+1) in ``rounds``
    equal quotas (of the whole interval, so that ``max_merges`` does not move them), cut at ``limit``."""
    ends = []
    lo = 0
    i = 1
    while lo < limit:
        hi = level_merges(n_points, i) if i < 63 else n_points
        i += 1
        if hi <= lo:
            continue
        quota = -(-(hi - lo) // rounds)
        ends.extend((e, quota) for e in range(lo + quota, hi, quota) if e < limit)
        ends.append((min(hi, limit), quota))
        lo = hi
    return ends


def decimate(mesh: TetMesh, *, w_density: float = DEFAULT_W_DENSITY, w_geometry: float = DEFAULT_W_GEOMETRY,
             w_sample: float = 1.0, progress=None, max_merges: int | None = None, locked=None,
             rounds: int = ROUNDS_PER_LEVEL, round_blocked: float | None = ROUND_BLOCKED, return_rounds: bool = False,
             on_level=None):
    """Greedy Van Gelder decimation of a tetrahedral mesh into a merge forest.

    Parameters
    ----------
    mesh : TetMesh
        Positively oriented tets (zero-volume tets allowed: they may stay flat or collapse, but no
        other tet may become flat or inverted).
    w_density, w_geometry : float
        Weights of the (normalised) density and boundary-geometry errors; >= 0, finite.
    w_sample : float
        Factor on the sampled error, the density error at the original field's points (input
        tets' centroids and merged vertices; part of the density error); >= 0, finite. 0 leaves
        it out: the forest builds faster, but its coarse levels are worse (the figures:
        ``bench/sections/simplify.md``, ``bench/bench_simplify.py --only sampled``).
    progress : callable, optional
        Called as ``progress(k)`` with the number of merges done since the previous call.
    max_merges : int, optional
        Stop after this many merges (default: until no legal merge is left).
    locked : (n_points,) bool array, optional
        Vertices that must keep their place in every prefix of the forest (a brick's cut vertices,
        so that simplified bricks still meet): never merged away. Interior vertices may merge into
        them (that keeps every boundary triangle, so the cut faces stay as they are); boundary
        vertices may not.

    rounds : int
        Rounds of independent merges per level (0: the plain greedy order, one merge at a time).
        Every level's merges [N_i, N_i+1) are split into at most this many rounds of equal
        quota (a round also ends when every candidate left is blocked by its earlier merges);
        ranks inside a round follow :func:`canonical_key`.
    round_blocked : float or None
        A round also ends once more than this fraction of its quota of candidates was blocked
        (None: only at its quota).
    return_rounds : bool
        Also return the first rank of every round.
    on_level : callable, optional
        Called as ``on_level(i, prefix)`` (in the calling thread) as soon as level i's N_i merges
        are done (each level the forest reaches, i >= 1, once, in order; a level whose N_i
        equals the previous one's is skipped, as in
        :func:`~gatun_py.simplify.levels.available_levels`): ``prefix`` is a MergeForest of the
        merges so far, whose first N_i merges are final as a set (the ranks inside a round are
        re-ordered at the end), so level i's mesh can be built from it
        (:func:`~gatun_py.simplify.levels.next_level`) while the decimation goes on.

    Returns
    -------
    MergeForest
        Every prefix of its merges is a state the decimator checked: positive tets (except the
        input's own flat ones), boundary orientation kept, manifold with a closed boundary.
    round_starts : list of int
        Only with ``return_rounds``: the first rank of every round (ascending, from 0).
    """
    for name, w in (("w_density", w_density), ("w_geometry", w_geometry), ("w_sample", w_sample)):
        if not np.isfinite(w) or w < 0:
            raise OptionError(f"{name} must be a finite number >= 0, got {w}")
    state = DecimationState(mesh, float(w_density), float(w_geometry), w_sample=float(w_sample))
    if locked is not None:
        locked = np.asarray(locked)
        if locked.shape != (mesh.n_points,) or locked.dtype != np.bool_:
            raise OptionError(f"locked must be a bool array of one value per point ({mesh.n_points}), "
                              f"got {locked.dtype} {locked.shape}")
        state.lock_vertices(locked)
    if isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or rounds < 0:
        raise OptionError(f"rounds must be an integer >= 0, got {rounds!r}")
    if round_blocked is not None and not (np.isfinite(round_blocked) and round_blocked >= 0):
        raise OptionError(f"round_blocked must be a finite number >= 0 or None, got {round_blocked!r}")
    limit = mesh.n_points if max_merges is None else max(0, min(int(max_merges), mesh.n_points))
    state.start()
    done = 0
    starts = []
    # N_i -> i for the levels on_level hears of (the first i of equal N_i)
    level_at = level_ends(mesh.n_points) if on_level is not None else {}
    if rounds:
        plan = _round_ends(mesh.n_points, limit, int(rounds))
        ends = np.array([e for e, _ in plan], np.int64)
        blocked = np.array([2**62 if round_blocked is None else int(np.ceil(round_blocked * q)) for _, q in plan],
                           np.int64)
        # kernel calls of about an eighth of a level's rounds: progress, and on_level at a level's end
        step = max(1, int(rounds) // 8)
        lo = 0
        while lo < ends.size:
            hi = min(lo + step, ends.size)
            ahead = [j for j in range(lo, hi) if int(ends[j]) in level_at]
            hi = ahead[0] + 1 if ahead else hi  # stop at a level's end
            new_starts, finished, r = state.run_rounds(ends[lo:hi], blocked[lo:hi])
            starts.extend(new_starts)
            if progress is not None:
                progress(state.n_merges - done)
            done = state.n_merges
            if done in level_at and done == ends[lo + r]:
                on_level(level_at[done], state.prefix())
            if finished:
                break
            state.compact_if_sparse()
            lo = hi
    else:
        chunk = max(1024, mesh.n_points // 50)
        while True:
            target = min(limit, state.n_merges + chunk) if progress is not None else limit
            if level_at:  # stop at the next level's end too
                target = min(target, min((e for e in level_at if e > state.n_merges), default=target))
            finished = state.run(target)
            if progress is not None:
                progress(state.n_merges - done)
            done = state.n_merges
            if done in level_at:
                on_level(level_at[done], state.prefix())
            if finished or done >= limit:
                break
            state.compact_if_sparse()
    forest = state.prefix()
    if rounds:
        rank, starts = _canonical_ranks(forest.rank, state.n_merges, starts, canonical_key(mesh))
        forest = MergeForest(forest.parent, rank, state.n_merges)
    return (forest, starts) if return_rounds else forest
