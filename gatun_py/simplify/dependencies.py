"""Merge dependencies: which merges a merge needs so that any cut of the forest is flip-free.

Vocabulary: merge i is the merge of rank i, vertex v_i into its parent t_i (a half-edge collapse,
t_i keeps its position). A *cut* is a set of applied merges; its mesh has every vertex replaced by
its ancestor (follow the parent while that vertex's merge is applied, :func:`cut_ancestors`), which
the on-the-fly filter takes unchanged.

Replaying the merges in rank order, ``last[T]`` is the last merge that changed the image of input
tet T, alive or collapsed (a collapsed tet's image keeps following the merges). The dependencies
of merge i are::

    D(i) = { last[T] : T's image contains v_i or t_i just before merge i, dead or alive }

t_i as well as v_i, because the decimator's legality test reads both stars: the volume and
boundary-orientation checks read the tets around v_i, the link condition (``_link_ok``) reads the
tets around t_i and the boundary faces at both ends (faces of those same tets). Dead tets too: a
tet collapsed by a merge r that a cut leaves out is alive in that cut, and if its image reaches
v_i or t_i it would be in a star the decimator never saw; depending on the last merge that moved
it reaches r (each change of a tet depends on the one before), which rules that out.

A cut closed under D (every applied merge has its dependencies applied) is flip-free. Apply its
merges in rank order; when merge i comes, every tet whose image holds v_i or t_i holds it in the
prefix state i too (a vertex's chain of parents has increasing ranks, so the merges that led a
corner there are all earlier than i, hence in the prefix), and its changers are all applied (the
last is in D(i); each earlier changer is a dependency of the next one, by induction), so it has
exactly its prefix-state image and liveness. Merge i therefore sees the stars the decimator
validated: no tet inverts, no boundary face flips, and the link condition keeps the mesh a
manifold. Only the *last* changer is needed for the same reason.

``removed[i]`` = the tets merge i deletes (those holding both v_i and t_i). It is the same at
every closed cut, so a closed cut's mesh has exactly ``T0 - sum(removed[cut])`` tets.

Examples
--------
>>> from gatun_py.warmup import tiny_mesh
>>> from gatun_py.simplify import decimate
>>> from gatun_py.simplify.dependencies import merge_dependencies
>>> mesh = tiny_mesh()
>>> deps = merge_dependencies(mesh, decimate(mesh))
>>> deps.n_merges == decimate(mesh).n_merges, int(deps.removed.sum()) <= mesh.n_tets
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..codec.forest import ROOT_RANK, check_forest
from ..errors import CorruptFileError, OptionError
from . import _dependency_kernels as K

# marks per kept dependency in the transitive reduction's search (see _dependency_kernels._reduce):
# bounds the build time; a search cut short only keeps a redundant dependency
REDUCE_BUDGET = 64

__all__ = ["MergeDependencies", "merge_dependencies", "cut_ancestors", "closed_cut_order", "prefix_cut",
           "LegalCutBase", "legal_cut_base", "legal_cut"]

# passes over the merges a legal cut found illegal (a merge blocked by its neighbourhood may
# become legal once the merges around it are applied)
LEGAL_PASSES = 3


@dataclass(frozen=True, eq=False)
class MergeDependencies:
    """The dependency DAG of a merge forest, by rank, in CSR form.

    Attributes
    ----------
    ptr : (k + 1,) int64
        ``idx[ptr[i]:ptr[i + 1]]`` are merge i's dependencies.
    idx : (nnz,) int32
        Dependencies (ranks), ascending within each merge, all below the merge's own rank.
    removed : (k,) int32
        Tets merge i deletes.
    """

    ptr: np.ndarray
    idx: np.ndarray
    removed: np.ndarray

    @property
    def n_merges(self) -> int:
        return int(self.removed.shape[0])

    def __repr__(self) -> str:
        return (f"<MergeDependencies: {self.n_merges} merges, {self.idx.size} dependencies "
                f"({self.idx.size / max(self.n_merges, 1):.1f} per merge), {int(self.removed.sum())} tets removed>")

    def of(self, i: int) -> np.ndarray:
        """D(i), ascending."""
        return self.idx[self.ptr[i]:self.ptr[i + 1]]

    def is_closed(self, applied) -> bool:
        """Whether a cut (bool per rank) applies every dependency of each merge it applies."""
        return first_unclosed(self, applied) < 0

    def cut_tets(self, n_tets: int, applied) -> int:
        """Tets of a closed cut's mesh, from the removal counts alone."""
        applied = _applied(applied, self.n_merges)
        return int(n_tets - self.removed[applied].astype(np.int64).sum())

    def effective_importance(self, importance) -> np.ndarray:
        """e(i) = max(importance[i], max of e over D(i)): dependencies never outrank their dependants."""
        imp = np.ascontiguousarray(importance, dtype=np.float64)
        if imp.shape != (self.n_merges,):
            raise OptionError(f"importance has shape {imp.shape}, expected ({self.n_merges},)")
        if not np.all(np.isfinite(imp)):
            raise OptionError("importance must be finite")
        return K._effective_importance(imp, self.ptr, self.idx)


def merge_dependencies(mesh, forest, *, reduce: bool = True) -> MergeDependencies:
    """Dependencies and removal counts of a merge forest computed on ``mesh``.

    Parameters
    ----------
    mesh : TetMesh
        The mesh the forest was computed on (its numbering).
    forest : MergeForest or (parent, rank)
    reduce : bool
        Keep only the transitive reduction (the dependencies no other dependency of the merge
        reaches): the same closed cuts, 10-20x fewer entries to store. False gives D(i) as defined
        above.

    Raises
    ------
    OptionError
        The forest does not belong to the mesh (sizes, or a merge that is not an edge).
    """
    parent, rank = (forest.parent, forest.rank) if hasattr(forest, "parent") else forest
    parent = np.ascontiguousarray(parent, dtype=np.int64)
    rank = np.ascontiguousarray(rank, dtype=np.int64)
    if parent.shape != (mesh.n_points,):
        raise OptionError(f"the forest has {parent.shape[0]} vertices, the mesh {mesh.n_points}")
    try:
        k = check_forest(parent, rank)
    except CorruptFileError as e:
        raise OptionError(str(e)) from None
    by_rank = np.empty(k, np.int64)
    merged = rank != ROOT_RANK
    by_rank[rank[merged]] = np.flatnonzero(merged)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    ptr, idx, removed = K._dependencies(tets, by_rank, parent)
    if k and ptr[0] < 0:
        raise OptionError(f"merge {-1 - int(ptr[0])} of the forest is not an edge of the mesh it reaches: "
                          "the forest was not computed on this mesh")
    if reduce:
        ptr, idx = K._reduce(ptr, idx, REDUCE_BUDGET)
    return MergeDependencies(ptr, idx, removed)


def _applied(applied, k: int) -> np.ndarray:
    a = np.asarray(applied)
    if a.dtype != np.bool_ or a.shape != (k,):
        raise OptionError(f"a cut is a bool array over the {k} merges, got {a.dtype} {a.shape}")
    return a


def first_unclosed(deps: MergeDependencies, applied) -> int:
    """The first applied merge with a dependency left out, -1 for a closed cut."""
    return int(K._is_closed(_applied(applied, deps.n_merges), deps.ptr, deps.idx))


def prefix_cut(k: int, n: int) -> np.ndarray:
    """The uniform cut: the first ``n`` of ``k`` merges."""
    out = np.zeros(k, np.bool_)
    out[:n] = True
    return out


def closed_cut_order(deps: MergeDependencies, importance) -> np.ndarray:
    """Ranks sorted by (effective importance, rank): every prefix of this order is a closed cut.

    A dependency j of i has e(j) <= e(i) and j < i, so it comes first. Merges are applied in this
    order (least important first) until the target is met.
    """
    e = deps.effective_importance(importance)
    return np.argsort(e, kind="stable")  # ties keep rank order


def cut_ancestors(parent, rank, applied) -> np.ndarray:
    """Every vertex's ancestor for a cut (bool per rank, ``applied[r]``: merge r is applied).

    With ``applied`` = the first N merges this is :func:`gatun_py.simplify.forest.ancestors`.
    """
    parent = np.ascontiguousarray(parent, dtype=np.int32)
    rank = np.ascontiguousarray(rank, dtype=np.int32)
    applied = np.ascontiguousarray(applied, dtype=np.bool_)
    if parent.shape[0] == 0:
        return np.zeros(0, np.int32)
    return K._cut_ancestors(parent, rank, applied)


@dataclass(frozen=True, eq=False)
class LegalCutBase:
    """What a *legal* cut (:func:`legal_cut`) starts from: a mesh and the merges of its forest.

    A legal cut needs no stored dependencies: each merge is applied only when the decimator's own
    legality tests (an edge of the current mesh, the link condition, no tet flattening or
    inverting, no boundary face turning by 90 degrees or more) pass on the cut mesh as it is at
    that moment, so every cut mesh along the way, and the final one, is valid whatever the order.
    It is weaker than a closed cut (a merge may see a star the decimator never saw, so its error
    is not the forest's) but free to follow any importance.

    Attributes
    ----------
    tets : (m, 4) int64
        The start mesh's tets.
    neighbours : (m, 4) int32
        Tet across the face opposite each corner, -1 on the boundary.
    boundary : (n,) bool
        Boundary vertices.
    points : (n, 3) float64
    vertex, target : (k,) int64
        v_i and t_i of merge i (rank order, the start mesh's numbering).
    """

    tets: np.ndarray
    neighbours: np.ndarray
    boundary: np.ndarray
    points: np.ndarray
    vertex: np.ndarray
    target: np.ndarray

    @property
    def n_merges(self) -> int:
        return int(self.vertex.shape[0])

    def __repr__(self) -> str:
        return (f"<LegalCutBase: {self.points.shape[0]} vertices, {self.tets.shape[0]} tets, "
                f"{self.n_merges} merges>")


def legal_cut_base(tets, points, parent, rank) -> LegalCutBase:
    """The state :func:`legal_cut` starts every cut from (built once per mesh: O(m)).

    Parameters
    ----------
    tets : (m, 4) int array
    points : (n, 3) array
    parent, rank : (n,) int arrays
        The mesh's merge forest (its numbering); ranks from 0.
    """
    T = np.ascontiguousarray(tets, dtype=np.int64)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    parent = np.ascontiguousarray(parent, dtype=np.int64)
    rank = np.ascontiguousarray(rank, dtype=np.int64)
    n = pts.shape[0]
    if parent.shape != (n,) or rank.shape != (n,):
        raise OptionError(f"the forest has {parent.shape[0]} vertices, the mesh {n}")
    try:
        k = check_forest(parent, rank)
    except CorruptFileError as e:
        raise OptionError(str(e)) from None
    vertex = np.empty(k, np.int64)
    merged = rank != ROOT_RANK
    vertex[rank[merged]] = np.flatnonzero(merged)
    head, nxt = K._incidence(T, n)
    nbr = K._face_neighbours(T, head, nxt)
    isb, _ = K._vertex_topology(T, nbr, head, nxt, n)
    return LegalCutBase(T, nbr, isb, pts, vertex, parent[vertex])


def legal_cut(base: LegalCutBase, order, *, tets: int, passes: int = LEGAL_PASSES, children_first: bool = False):
    """A legal cut: the merges of ``order`` (least important first) that are legal on the cut mesh
    when their turn comes, until it has at most ``tets`` tets. A merge moves its vertex onto its
    own parent only (never onto an ancestor further up, which is not an edge the decimator saw);
    ``children_first``: a merge waits until every merge into its vertex is applied (the cut is a
    union of whole subtrees of the forest), tried again on the next of ``passes`` passes.

    The checks are the decimator's, all local (positive tets around the moved vertex, boundary
    orientation, the link condition): every cut is conforming, positive and manifold. In the
    decimator's own order that also kept every tested mesh free of overlapping tets; in another
    order a boundary can fold onto a part of itself that no local check sees (rare: one jittered
    6 x 4 x 5 grid in hypothesis's search, none of 150 random ones), and the region is then covered
    twice.

    Returns
    -------
    applied : (k,) bool
        Merge r is applied (give it to :func:`cut_ancestors`).
    n_tets : int
        Tets of the cut's mesh.
    rejected : int
        Merges found illegal on the first pass (some may have been applied on a later one).

    Examples
    --------
    >>> from gatun_py.warmup import tiny_mesh
    >>> from gatun_py.simplify import decimate
    >>> mesh = tiny_mesh(); forest = decimate(mesh)
    >>> base = legal_cut_base(mesh.tets, mesh.points, forest.parent, forest.rank)
    >>> applied, n_tets, _ = legal_cut(base, np.arange(base.n_merges)[::-1], tets=mesh.n_tets // 2)
    >>> n_tets <= mesh.n_tets // 2 or bool(applied.all())
    True
    """
    order = np.ascontiguousarray(order, dtype=np.int64)
    k = base.n_merges
    if order.ndim != 1 or (order.size and (order.min() < 0 or order.max() >= k)):
        raise OptionError(f"a cut order lists merges 0..{k - 1}")
    applied, n_tets, rejected = K._legal_greedy(order, base.vertex, base.target, base.tets.copy(),
                                                base.neighbours.copy(), base.boundary, base.points,
                                                base.tets.shape[0], int(tets), int(passes), bool(children_first))
    return applied, int(n_tets), int(rejected)
