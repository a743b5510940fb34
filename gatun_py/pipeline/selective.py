"""Selective refinement: a view- and transfer-function-dependent cut of the merge forest.

A uniform render applies the first N merges. A selective render applies the merges that matter
least for the current view and transfer function (Okuyan et al.'s view-dependent refinement, Peng
et al.'s TF importance), and only *closed* cuts (:mod:`gatun_py.simplify.dependencies`), so no tet
ever flips. The cut's ancestors go to the same on-the-fly filter and ray caster as a uniform
render.

Importance of merge i (v_i into t_i, both kept in level 0's numbering) for a view and a transfer
function: the forest's own error order, modulated by what the view and the transfer function make
of the region (a factor left out of ``factors`` is 1)::

    imp(i) = forest(i) * (EPS + light(i) * colour(i)) * sqrt(size(i))

* ``forest``: (i + 1) / k, the decimator's error order (its error grows with rank): with the other
  factors at 1 the cut is the uniform one. *Buys*: the decimator's judgement of density and
  geometry error where the view has nothing to add.
* ``colour``: Okuyan's colour error over the merged region, zero where the transfer function is
  transparent (Peng): the largest opacity on [s(v_i), s(t_i)] (8 values) plus the largest change
  of the premultiplied colour and opacity (r a, g a, b a, a; mean of the four) from s(v_i) to any
  of them. *Buys*: merges in transparent regions go first (down to EPS = 0.01 of their rank).
* ``light``: the transmittance from the camera to v_i, exp(-integral of the extinction
  -ln(1 - a(s)) / unit_distance), marched through a 32^3 grid of the vertices' mean extinction to
  the points of a 16^3 lattice and interpolated trilinearly at v_i (an object-space coarse render,
  about a millisecond). *Buys*: what is hidden behind opaque matter goes first.
* ``size``: the merge's projected size, |v_i t_i| / depth / pixel angle in pixels (its square root:
  error in an image grows with the area but the rank already grows with the edge), 0 behind the
  camera or off the image. *Buys*: small, far and off-screen regions go first.

Effective importance e(i) = max(imp(i), max over D(i) of e(j)); merges sorted by (e, rank) give
closed prefixes, so a cut for N tets is a sort and a cumulative sum of the removal counts:
O(k log k) per frame. The render starts from the most simplified stored level whose merges the cut
all applies and whose stored forest holds every merge the cut adds (level 0 otherwise). A cut can
also be chosen among one stored level's merges only (``level=``; those before it applied): that
is what ``--budget`` does, with the level and tet count of the uniform plan, so the frame decodes
no more than the uniform one.

Why a selective cut gains little at 95-99 % merged: the dependency closure of a late merge covers
most earlier merges, so a closed cut that applies most merges is nearly the prefix whatever the
importance says; the freedom is in the middle ranks. The closure is still what keeps the quality: a
merge is only as good as the decimator made it in the state it was evaluated in, and only a closed
cut reproduces that state (an unclosed cut overlaps tets; a run-time legality check,
:func:`gatun_py.simplify.dependencies.legal_cut`, is flip-free but loses to uniform). Bricked
forests lock their cut vertices, which bounds how far their cuts reach. The measurements (the
closure's reach, the oracle bound on any importance, bricked forests) are in
``bench/sections/selective.md``, ``selective_bound.md`` and ``selective_bricks.md``.

Examples
--------
>>> import gatun_py, tempfile, os
>>> from gatun_py.warmup import tiny_mesh
>>> path = os.path.join(tempfile.mkdtemp(), "tiny.tetc")
>>> f = gatun_py.compress(tiny_mesh(), path, dependencies=True)
>>> frame = gatun_py.render(path, size=32, selective=True, tets=40)
>>> frame.stats["cut_tets"] <= 40, frame.stats["flipped_tets"]
(True, 0)
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, replace

import numpy as np

from ..codec import TetcReader
from ..errors import CorruptFileError, OptionError
from ..mesh.model import boundary_faces
from ..raycast.transfer import load_transfer_function
from ..simplify.dependencies import MergeDependencies, closed_cut_order, cut_ancestors
from ..simplify.forest import ROOT_RANK, mesh_from_ancestors
from ..simplify.levels import Target, stored_levels
from . import _importance_kernels as K
from .stream import View, file_render_defaults, render_tetc

__all__ = ["FACTORS", "SelectiveSource", "selective_source", "merge_importance", "Cut", "choose_cut", "uniform_cut",
           "plan_cut", "selective_mesh", "render_selective", "flipped_tets", "FlipCounter", "budget_tets",
           "take_batches", "SELECTION_ALLOWANCE_S"]

FACTORS = ("colour", "light", "size", "forest")
REGION_FACTORS = ("colour", "light", "area")
GRID = 32  # voxels per axis of the extinction grid
LIGHT_GRID = 16  # lattice points per axis where the transmittance is marched (then interpolated)
COLOUR_SAMPLES = 8
OPAQUE_SHARE = 1.0  # weight of the largest opacity beside the colour change
EPS = 0.01  # what a transparent or hidden merge keeps of its rank


@dataclass(frozen=True, eq=False)
class SelectiveSource:
    """What selective refinement reads from a file, once per reader and scalar (a TF or view
    change reuses it: nothing else is read again).

    Attributes
    ----------
    deps : MergeDependencies
    parent, rank : (n,) int32
        Level 0's forest (decode order).
    vertex, target : (k,) int64
        v_i and t_i of every merge, by rank, in level 0's numbering.
    points : (n, 3) float64
        Level 0's vertex positions (float32 values).
    scalars : (n,) float64
        The rendered scalar at level 0's vertices.
    n_tets : int
        Level 0's tets.
    tets : (n_tets, 4) int64
        Level 0's tets (decode order).
    level, first : int
        The stored level all of this is of (0 above; another level: its forest, numbering, vertices
        and tets, and the merges its forest holds, ranks renumbered by ``-first`` = -N_level).
    """

    deps: MergeDependencies
    parent: np.ndarray
    rank: np.ndarray
    vertex: np.ndarray
    target: np.ndarray
    points: np.ndarray
    scalars: np.ndarray
    n_tets: int
    level: int = 0
    first: int = 0
    tets: np.ndarray | None = None

    @property
    def n_merges(self) -> int:
        return self.deps.n_merges

    def __repr__(self) -> str:
        return f"<SelectiveSource: {self.points.shape[0]} vertices, {self.n_tets} tets, {self.n_merges} merges>"


def selective_source(reader: TetcReader, scalar: str | None = None, component=None, *,
                     keep_batches: bool = False, level: int = 0) -> SelectiveSource | None:
    """The file's dependencies, forest and level-0 geometry (cached on the reader), or None when
    the file stores no dependencies (written before format 3, or without a forest).

    ``keep_batches``: also keep the level's decoded stream (once, for :func:`take_batches`), so the
    first frame, which had to decode the level for the geometry, does not decode it twice.
    ``level``: the same for a stored level (only the merges its forest holds, renumbered).
    """
    cache = reader.__dict__.setdefault("_selective_cache", {})
    key = (scalar, component, level)
    if key in cache:
        return cache[key]
    if "deps" not in cache:
        raw = reader.read_dependencies()
        cache["deps"] = None if raw is None else MergeDependencies(*raw)
    deps = cache["deps"]
    if deps is None:
        cache[key] = None
        return None
    lv = reader.level_meta(level)
    first = lv.merges_before
    forest = reader.read_forest(level)
    if forest is None:  # a level with nothing left to merge
        forest = (np.arange(lv.points, dtype=np.int32), np.full(lv.points, ROOT_RANK, np.int32))
    parent, rank = forest
    n = parent.shape[0]
    merged = rank != ROOT_RANK
    k = int(merged.sum())
    if level:
        deps = _window(deps, first, k)
    vertex = np.empty(k, np.int64)
    vertex[rank[merged]] = np.flatnonzero(merged)
    points = np.empty((n, 3), np.float64)
    scalars = np.empty(n, np.float64)
    kept = []
    tets = []
    for b in reader.iter_decode(level, scalar=scalar, component=component):
        points[b.first:b.first + len(b.points)] = b.points
        scalars[b.first:b.first + len(b.points)] = b.density
        tets.append(np.asarray(b.tets, np.int64))
        if keep_batches:
            kept.append(b)
    tets = np.concatenate(tets) if tets else np.zeros((0, 4), np.int64)
    if keep_batches:
        reader.__dict__.setdefault("_selective_batches", {})[key] = kept
    src = SelectiveSource(deps, parent, rank, vertex, parent[vertex].astype(np.int64), points, scalars,
                          lv.tets, level, first, tets)
    cache[key] = src
    return src


def _window(deps: MergeDependencies, first: int, k: int) -> MergeDependencies:
    """The DAG of merges ``first .. first + k - 1`` renumbered by ``-first``; dependencies below
    ``first`` dropped (a level after ``first`` merges has them applied)."""
    if first + k > deps.n_merges:
        raise CorruptFileError("a level's forest holds merges beyond the file's dependencies")
    lo, hi = int(deps.ptr[first]), int(deps.ptr[first + k])
    rows = np.repeat(np.arange(k), np.diff(deps.ptr[first:first + k + 1]))
    idx = deps.idx[lo:hi].astype(np.int64) - first
    keep = idx >= 0
    ptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=k))]).astype(np.int64)
    return MergeDependencies(ptr, idx[keep].astype(np.int32), deps.removed[first:first + k].copy())


def take_batches(reader, scalar=None, component=None, level: int = 0):
    """A level's decoded stream kept by :func:`selective_source` (then forgotten), or None."""
    return reader.__dict__.get("_selective_batches", {}).pop((scalar, component, level), None)


def _check_factors(factors, allowed, what: str) -> None:
    bad = set(factors) - set(allowed)
    if bad:
        raise OptionError(f"unknown {what} factor {sorted(bad)[0]!r} (choose from {', '.join(allowed)})")


def _tf_state(src: SelectiveSource, tf, scalar_range, lo, hi) -> dict:
    """What a transfer function gives every frame (cached on the source until the TF changes): the
    extinction grid and the shipped importance's colour change."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    table, t_lo, t_inv = tf.table(scalar_range)
    key = (table.tobytes(), t_lo, t_inv, float(tf.unit_distance), lo.tobytes(), hi.tobytes())
    cache = src.__dict__.setdefault("_importance", {})
    if cache.get("tf_key") != key:
        _, a = tf.resolve(scalar_range).evaluate(src.scalars)
        sigma = -np.log1p(-np.clip(a, 0.0, 0.999)) / tf.unit_distance
        cache.pop("centres", None)
        cache.update(tf_key=key, lo=lo, hi=hi, grid=K._extinction_grid(src.points, sigma, lo, hi, GRID),
                     colour=K._colour_change(table, t_lo, t_inv, src.scalars[src.vertex], src.scalars[src.target],
                                             COLOUR_SAMPLES, OPAQUE_SHARE))
    return cache


def _light(state: dict, eye, points, need) -> np.ndarray:
    """Transmittance from the eye to each point where ``need``d: marched through the extinction
    grid to the centres of a LIGHT_GRID^3 lattice (a coarse render of it, a few thousand rays) and
    interpolated trilinearly, instead of one march per merge (tens of thousands)."""
    lo, hi = state["lo"], state["hi"]
    centres = state.get("centres")
    if centres is None:
        centres = state["centres"] = K._cell_centres(lo, hi, LIGHT_GRID)
    lattice = K._transmittance(state["grid"], lo, hi, eye, centres, GRID)
    return K._trilinear(lattice.reshape(LIGHT_GRID, LIGHT_GRID, LIGHT_GRID), lo, hi, points, need)


def _pixels(camera, points, extent) -> np.ndarray:
    """``extent`` at each point seen from the camera, in pixels (0 behind it or off the image)."""
    fwd, right, up = camera.basis()
    return K._projected_size(points, np.ascontiguousarray(extent, np.float64),
                             np.asarray(camera.position, np.float64), fwd, right, up,
                             float(np.tan(np.radians(camera.view_angle) / 2.0)), float(camera.width),
                             float(camera.height))


def merge_importance(src: SelectiveSource, camera, tf, *, lo, hi, scalar_range, factors=FACTORS) -> np.ndarray:
    """imp(i) of every merge for a fitted camera and a transfer function (with its unit distance
    in the mesh's units) normalised to ``scalar_range`` (see the module docstring); ``factors``
    picks which of :data:`FACTORS` take part."""
    _check_factors(factors, FACTORS, "importance")
    k = src.n_merges
    if k == 0:
        return np.ones(0)
    cache = src.__dict__.setdefault("_importance", {})
    if "pv" not in cache:  # view- and TF-independent: once per source
        cache["pv"] = np.ascontiguousarray(src.points[src.vertex])
        cache["length"] = np.linalg.norm(src.points[src.target] - cache["pv"], axis=1)
    pv = cache["pv"]
    colour = light = size = forest = 1.0
    if "colour" in factors or "light" in factors:
        state = _tf_state(src, tf, scalar_range, lo, hi)
    if "colour" in factors:
        colour = state["colour"]
    if "size" in factors:
        size = np.sqrt(_pixels(camera, pv, cache["length"]))
    if "light" in factors:
        # light only counts through light * colour, and not at all off the image
        need = np.ones(k, np.bool_) if "colour" not in factors else state["colour"] != 0.0
        if "size" in factors:
            need &= size != 0.0
        light = _light(state, np.asarray(camera.position, np.float64), pv, need)
    if "forest" in factors:
        forest = (np.arange(k) + 1.0) / k
    modulation = EPS + light * colour if ("colour" in factors or "light" in factors) else 1.0
    return np.broadcast_to(forest * modulation * size, (k,)).astype(np.float64)


def merge_regions(src: SelectiveSource):
    """(radius, scalar lo, scalar hi) of the region every merge changes in its prefix state (its
    subtree of the forest moving onto t_i), computed once per source."""
    cache = src.__dict__.setdefault("_regions", {})
    if "r" not in cache:
        cache["r"] = K._merge_regions(src.vertex, src.target, src.points, src.scalars)
    return cache["r"]


def boundary_merges(src: SelectiveSource) -> np.ndarray:
    """Merges of a boundary vertex (bool by rank), from the level's tets (once per source, when
    first asked: a plain render does not need it)."""
    cache = src.__dict__.setdefault("_regions", {})
    if "b" not in cache:
        boundary = np.zeros(src.points.shape[0], np.bool_)
        boundary[boundary_faces(src.tets).ravel()] = True
        cache["b"] = boundary[src.vertex]
    return cache["b"]


def region_error(src: SelectiveSource, camera, tf, *, lo, hi, scalar_range, factors=REGION_FACTORS) -> np.ndarray:
    """Predicted image error of every merge in its prefix state, for a fitted camera and a
    transfer function (unit distance in the mesh's units)::

        err(i) = colour(i) * light(i) * area(i)

    * ``colour``: the largest change of premultiplied colour and opacity between t_i's value and
      any value of the region (the subtree's scalar range), the opacity taken over a path through
      the region (so a thin faint region counts little, a thick one as much as it shows);
    * ``light``: transmittance from the camera to t_i (as in :func:`merge_importance`);
    * ``area``: the region's projected area in pixels, (radius / depth / pixel angle)^2, 0 off the
      image.

    A region's error includes its whole subtree's, so err grows up the forest (a merge's error is
    at least roughly its children's): a cut by err is close to closed by itself.
    """
    _check_factors(factors, REGION_FACTORS, "error")
    k = src.n_merges
    if k == 0:
        return np.ones(0)
    radius, s_lo, s_hi = merge_regions(src)
    pt = np.ascontiguousarray(src.points[src.target])
    colour = light = area = 1.0
    if "colour" in factors:
        table, t_lo, t_inv = tf.table(scalar_range)
        colour = K._region_colour_error(table, t_lo, t_inv, s_lo, s_hi, src.scalars[src.target], radius,
                                        boundary_merges(src), float(tf.unit_distance), COLOUR_SAMPLES)
    if "light" in factors:
        state = _tf_state(src, tf, scalar_range, lo, hi)
        light = K._transmittance(state["grid"], state["lo"], state["hi"], np.asarray(camera.position, np.float64),
                                 pt, GRID)
    if "area" in factors:
        area = np.pi * _pixels(camera, pt, radius) ** 2
    return np.broadcast_to(colour * light * area, (k,)).astype(np.float64)


@dataclass(frozen=True, eq=False)
class Cut:
    """A closed cut and where to render it from.

    Attributes
    ----------
    applied : (k,) bool
        Merge r is applied.
    n_tets : int
        Tets of the cut's mesh (T0 - removed merges' counts; exact for a closed cut).
    level, level_merges : int
        The stored level it starts from and that level's N_i.
    ancestors : (n_level,) int32 or None
        Ancestor of every vertex of that level (None: the level as it is).
    select_s : float
        Seconds spent choosing it (importance, sort, ancestors).
    """

    applied: np.ndarray
    n_tets: int
    level: int
    level_merges: int
    ancestors: np.ndarray | None
    select_s: float = 0.0

    @property
    def n_merges(self) -> int:
        return int(self.applied.sum())

    def __repr__(self) -> str:
        return (f"<Cut: {self.n_merges} merges, {self.n_tets} tets, from level {self.level}, "
                f"chosen in {self.select_s * 1e3:.1f} ms>")

    def target(self, n_points: int, first: int = 0) -> Target:
        """The render target (``first``: merges already applied in the cut's own numbering)."""
        m = first + self.n_merges
        return Target(self.level, m, m / n_points if n_points else 0.0, self.level_merges)


def _prefix_count(removed_in_order, n_tets: int, *, merges=None, tets=None) -> int:
    """How many merges of an order to apply: ``merges`` of them, or the fewest that bring the
    mesh to at most ``tets`` tets (none when it has that few already)."""
    k = removed_in_order.shape[0]
    if merges is not None:
        return max(0, min(int(merges), k))
    left = n_tets - np.cumsum(removed_in_order, dtype=np.int64)
    if tets >= n_tets:
        return 0
    hit = np.flatnonzero(left <= tets)
    return int(hit[0]) + 1 if hit.size else k


def choose_cut(src: SelectiveSource, importance, *, merges=None, tets=None) -> np.ndarray:
    """The closed cut (bool per rank) of the least important merges: ``merges`` of them, or as
    many as it takes to get to ``tets`` tets (all merges if the forest cannot)."""
    order = closed_cut_order(src.deps, importance)
    n = _prefix_count(src.deps.removed[order], src.n_tets, merges=merges, tets=tets)
    applied = np.zeros(src.n_merges, np.bool_)
    applied[order[:n]] = True
    return applied


def uniform_cut(src: SelectiveSource, *, merges=None, tets=None) -> np.ndarray:
    """The uniform cut (the first N merges) with ``merges`` merges or at most ``tets`` tets."""
    n = _prefix_count(src.deps.removed, src.n_tets, merges=merges, tets=tets)
    applied = np.zeros(src.n_merges, np.bool_)
    applied[:n] = True
    return applied


def _start(reader, src: SelectiveSource, applied) -> Cut:
    """The most simplified stored level a cut can start from, and the ancestors there (a source of
    another level than 0 starts from its own level)."""
    if src.level:
        anc = cut_ancestors(src.parent, src.rank, applied) if applied.any() else None
        return Cut(applied, src.deps.cut_tets(src.n_tets, applied), src.level, src.first, anc)
    levels = stored_levels(reader)
    best = levels[0]
    total = int(applied.sum())
    for j, lv in enumerate(levels):
        n = lv.merges_before
        # level 0 and the last level keep every merge after them, the others those up to the next
        upto = src.n_merges if j in (0, len(levels) - 1) else levels[j + 1].merges_before
        if applied[:n].all() and not applied[upto:].any() and (lv.has_forest or total == n):
            best = lv
    level, n = int(best["level"]), int(best.get("merges_before", 0))
    cache = reader.__dict__.setdefault("_selective_forests", {0: (src.parent, src.rank)})
    if level not in cache:
        cache[level] = reader.read_forest(level)
    rest = applied[n:]
    anc = None
    if rest.any():
        parent, rank = cache[level]
        anc = cut_ancestors(parent, rank, rest)
    return Cut(applied, src.deps.cut_tets(src.n_tets, applied), level, n, anc)


def _transfer_function(reader, spec, diagonal: float):
    """The view's transfer function, parsed once per reader and spec (a frame of the same TF reuses
    it; a file is read again when it changes)."""
    if not isinstance(spec, (str, os.PathLike, dict, list)):
        return load_transfer_function(spec).for_size(diagonal)
    stamp = os.stat(spec).st_mtime_ns if isinstance(spec, (str, os.PathLike)) and os.path.isfile(spec) else None
    key = (json.dumps(spec, sort_keys=True, default=str), stamp, diagonal)
    cache = reader.__dict__.setdefault("_selective_tfs", {})
    if key not in cache:
        if len(cache) > 16:
            cache.clear()
        cache[key] = load_transfer_function(spec).for_size(diagonal)
    return cache[key]


def plan_cut(reader, view: View, *, ratio=None, tets=None, merges=None, factors=FACTORS,
             uniform: bool = False, level: int = 0) -> Cut | None:
    """The cut of a selective render of ``reader`` for a view: ``ratio`` (merges = floor(ratio *
    points)), ``tets`` (at most that many; above the mesh's count: the full mesh) or ``merges``
    (counted from ``level``: the cut chooses among the merges that stored level's forest holds,
    the ones before it applied; 0: the whole forest).
    None when the file has no dependencies. ``uniform`` gives the prefix cut instead (for
    comparisons)."""
    if sum(x is not None for x in (ratio, tets, merges)) != 1:
        raise OptionError("a selective cut needs exactly one of ratio, tets and merges")
    if tets is not None and (isinstance(tets, bool) or not isinstance(tets, (int, np.integer)) or tets < 1):
        raise OptionError(f"tets must be a whole number >= 1, got {tets!r}")
    src = selective_source(reader, view.scalar, view.component, level=level)  # read once: not selection time
    if src is None:
        return None
    t0 = time.perf_counter()
    if ratio is not None:
        if not 0.0 <= ratio <= 1.0:
            raise OptionError(f"ratio {ratio} is outside [0, 1]")
        n0 = reader.level_meta(0).points
        merges = int(np.floor(ratio * n0)) - src.first
        if not 0 <= merges <= src.n_merges:
            raise OptionError(f"ratio {ratio} needs {merges + src.first} merges; from level {src.level} this "
                              f"file reaches {src.first}..{src.first + src.n_merges} (maximum ratio "
                              f"{(src.first + src.n_merges) / n0:.6f})")
    if uniform:
        applied = uniform_cut(src, merges=merges, tets=tets)
    else:
        lo, hi, rng, _ = file_render_defaults(reader)
        if view.scalar is not None:
            rng = reader.array_range(view.scalar, view.component) or rng
        rng = view.scalar_range if view.scalar_range is not None else rng
        tf = _transfer_function(reader, view.tf, float(np.linalg.norm(hi - lo)))
        imp = merge_importance(src, view.camera.fit(lo, hi), tf, lo=lo, hi=hi, scalar_range=rng, factors=factors)
        applied = choose_cut(src, imp, merges=merges, tets=tets)
    cut = _start(reader, src, applied)
    return replace(cut, select_s=time.perf_counter() - t0)


def selective_mesh(reader, view: View, **kw):
    """The mesh of a selective cut (see :func:`plan_cut`), vertices in its start level's decode
    order; (mesh, cut), or (None, None) when the file has no dependencies."""
    cut = plan_cut(reader, view, **kw)
    if cut is None:
        return None, None
    mesh = reader.decode_mesh(cut.level)
    if cut.ancestors is not None:
        mesh = mesh_from_ancestors(mesh, cut.ancestors)[0]
    return mesh, cut


def flipped_tets(points, tets) -> int:
    """Tets with negative signed volume (inverted), counted on the coordinates given."""
    if len(tets) == 0:
        return 0
    p = np.asarray(points, np.float64)
    t = np.asarray(tets)
    a = p[t[:, 0]]
    vol = np.einsum("ij,ij->i", p[t[:, 1]] - a, np.cross(p[t[:, 2]] - a, p[t[:, 3]] - a))
    return int((vol < 0).sum())


class FlipCounter:
    """Wraps a stream of filtered batches and counts the inverted tets it carries (every tet's
    vertices have arrived by the time the filter forwards it)."""

    def __init__(self, n_points: int):
        self.points = np.zeros((n_points, 3), np.float64)
        self.flipped = 0

    def __call__(self, batches):
        for b in batches:
            self.points[b.first:b.first + len(b.points)] = b.points
            self.flipped += flipped_tets(self.points, b.tets)
            yield b


def render_selective(reader, view: View, *, ratio=None, tets=None, merges=None, pipeline: str = "streaming",
                     progress=None, factors=FACTORS, uniform: bool = False, level: int = 0, log=None):
    """Render a selective cut (see :func:`plan_cut`) through the usual filter and ray caster.

    Returns a :class:`~gatun_py.pipeline.stream.PipelineResult` whose stats add ``selective``
    (True, or False when the file has no dependencies and the render fell back to uniform),
    ``cut_tets``, ``cut_merges``, ``selection_s`` and ``flipped_tets`` (inverted tets counted on
    the rendered stream). Without dependencies: a uniform render at the same ratio (for ``tets``:
    the stored level with the fewest tets still at least that many), noted once through ``log``.
    """
    # the first frame decodes the level once
    src = selective_source(reader, view.scalar, view.component, keep_batches=not view.lean, level=level)
    cut = plan_cut(reader, view, ratio=ratio, tets=tets, merges=merges, factors=factors, uniform=uniform,
                   level=level)
    if cut is None:
        if log is not None:
            log("note: this file stores no merge dependencies (it was compressed without them): rendering uniformly")
        if tets is not None:
            levels = [lv for lv in stored_levels(reader) if lv.tets >= tets] or stored_levels(reader)[:1]
            result = render_tetc(reader, view, level=min(levels, key=lambda lv: lv.tets).level,
                                 pipeline=pipeline, progress=progress)
        else:
            result = render_tetc(reader, view, ratio=ratio, pipeline=pipeline, progress=progress)
        result.stats.update(selective=False)
        return result
    lv = reader.level_meta(cut.level)
    counter = FlipCounter(lv.points)
    n0 = reader.level_meta(0).points
    kept = take_batches(reader, view.scalar, view.component, level)
    decoded = kept if cut.level == level and pipeline == "streaming" else None
    result = render_tetc(reader, view, pipeline=pipeline, target=cut.target(n0, src.first), ancestors=cut.ancestors,
                         watch=counter, progress=progress, decoded=decoded)
    result.stats.update(selective=not uniform, cut_tets=cut.n_tets, cut_merges=cut.n_merges,
                        selection_s=cut.select_s, flipped_tets=counter.flipped)
    return result


def budget_tets(reader, view: View, target) -> int:
    """Tets a selective frame may render for a budget: those of the uniform cut the budget planner
    chose (``target``, :mod:`gatun_py.pipeline.budget`), from the same stored level, so the frame
    decodes and renders as much as the uniform one would."""
    src = selective_source(reader, view.scalar, view.component, keep_batches=not view.lean, level=target.level)
    return max(1, src.deps.cut_tets(src.n_tets, uniform_cut(src, merges=target.merges - src.first)))


SELECTION_ALLOWANCE_S = 0.05  # kept from a selective frame's budget for choosing the cut
