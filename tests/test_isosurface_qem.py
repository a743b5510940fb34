"""QEM cost and placement (gatun_py.contour.qem) against the plain reference in naive_qem."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from naive_qem import (DET_FLOOR, naive_border_planes, naive_current_quadric, naive_edge_cost, naive_face_quadrics,
                       naive_fan_distance, naive_placement, naive_segment_min, plane_quadric, quadric_cost)

from gatun_py.contour import qem


def _place(q, pu, pv, bu=False, bv=False):
    vq = np.zeros((2, qem.QUADRIC_WIDTH))
    vq[0, qem.CURRENT] = q  # the edge's quadric is the sum of its ends': put it all on u
    vpos = np.array([pu, pv], np.float64)
    vbnd = np.array([bu, bv], np.uint8)
    cost, x, y, z = qem._placement(vq, vpos, vbnd, 0, 1, np.empty(10))
    return cost, np.array([x, y, z])


def _random_quadric(rng, n_planes, centre, spread):
    q = np.zeros(10)
    for _ in range(n_planes):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        p = centre + spread * rng.normal(size=3)
        q += plane_quadric(n, -n @ p, w=rng.uniform(0.1, 2.0))
    return q


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_planes=st.integers(1, 6), spread=st.sampled_from([0.0, 0.01, 0.5, 3.0]))
def test_placement_is_the_reference_choice(seed, n_planes, spread):
    rng = np.random.default_rng(seed)
    pu, pv = rng.normal(size=3), rng.normal(size=3)
    q = _random_quadric(rng, n_planes, 0.5 * (pu + pv), spread)
    a = np.array([[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]])
    tr = np.trace(a)
    margin = abs(np.linalg.det(a + qem.PLACE_RIDGE * tr * np.eye(3))) / (DET_FLOOR * tr ** 3)
    assume(abs(margin - 1) > 1e-3)  # on the singularity threshold rounding may decide either way
    cost, p = _place(q, pu, pv)
    ref_cost, ref_p = naive_placement(q, pu, pv, ridge=qem.PLACE_RIDGE, reach=qem.PLACE_REACH)
    scale = max(abs(q[9]), quadric_cost(q, pu), quadric_cost(q, pv), 1e-12)
    # the reported cost is the quadric at the reported point, never negative
    assert cost == pytest.approx(max(quadric_cost(q, p), 0.0), rel=1e-7, abs=1e-9 * scale)
    # never worse than any point of the edge, and as good as the reference's pick
    assert cost <= naive_segment_min(q, pu, pv)[0] + 1e-9 * scale
    assert cost <= ref_cost + 1e-9 * scale
    assert ref_cost <= cost + 1e-6 * scale + 1e-12  # the reference samples the segment: equal up to that


def test_full_rank_quadric_lands_on_its_minimum():
    rng = np.random.default_rng(7)
    for _ in range(50):
        target = rng.normal(size=3)
        q = np.zeros(10)
        for n in np.eye(3) + 0.2 * rng.normal(size=(3, 3)):  # three independent planes through target
            n = n / np.linalg.norm(n)
            q += plane_quadric(n, -n @ target)
        pu, pv = target + 0.3 * rng.normal(size=3), target + 0.3 * rng.normal(size=3)
        if np.linalg.norm(target - 0.5 * (pu + pv)) > np.linalg.norm(pv - pu):
            continue  # the optimum is only taken near the edge
        cost, p = _place(q, pu, pv)
        assert np.linalg.norm(p - target) < 1e-2 * np.linalg.norm(pv - pu)
        assert cost < 1e-3 * quadric_cost(q, pu) + 1e-12  # the ridge costs a little


def test_flat_quadric_stays_near_the_edge():
    """One plane: every point of it costs 0; the vertex must not slide anywhere on the plane. It
    lands on the plane near the midpoint (ridge solve) or at the cheapest point of the edge."""
    n = np.array([0.0, 0.0, 1.0])
    q = plane_quadric(n, -1.0)  # z = 1
    for pu, pv in [((0.0, 0.0, 1.2), (1.0, 0.0, 0.9)), ((0.0, 0.0, 1.2), (1.0, 0.0, 1.1)),
                   ((5.0, 3.0, 1.0), (5.5, 3.0, 1.0))]:
        pu, pv = np.array(pu), np.array(pv)
        cost, p = _place(q, pu, pv)
        assert cost <= naive_segment_min(q, pu, pv)[0] + 1e-12
        assert np.linalg.norm(p - 0.5 * (pu + pv)) <= 0.5 * np.linalg.norm(pv - pu)


@pytest.mark.parametrize("bu, bv", [(True, False), (False, True), (True, True)])
def test_border_constraint_planes_hold_a_boundary_collapse(bu, bv):
    """A boundary vertex's quadric carries heavy planes through the border line (Garland's
    perpendicular constraints): whatever the faces pull toward, the result stays on that line."""
    rng = np.random.default_rng(5)
    q = _random_quadric(rng, 4, np.array([0.0, 0.5, 0.5]), 0.5)
    # the border: the x axis, held by the planes y = 0 and z = 0
    q += plane_quadric([0.0, 1.0, 0.0], 0.0, w=1e4) + plane_quadric([0.0, 0.0, 1.0], 0.0, w=1e4)
    pu, pv = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    cost, p = _place(q, pu, pv, bu, bv)
    assert abs(p[1]) < 1e-3 and abs(p[2]) < 1e-3
    ref_cost, _ = naive_placement(q, pu, pv, ridge=qem.PLACE_RIDGE, reach=qem.PLACE_REACH)
    assert cost == pytest.approx(ref_cost, rel=1e-6, abs=1e-9)


def _wavy_patch(n=24, seed=0):
    """An open height-field surface (border all round), triangulated with random diagonals."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    z = 0.1 * np.sin(5 * x) * np.cos(4 * y) + 0.002 * rng.normal(size=x.shape)
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            tris += [(a, b, c), (a, c, d)] if rng.random() < 0.5 else [(a, b, d), (b, c, d)]
    return pts, np.array(tris, np.int32)


def _state(pts, tris, importance=None):
    nv = len(pts)
    imp = np.ones(nv) if importance is None else np.asarray(importance, np.float64)
    return dict(vpos=pts.astype(np.float64).copy(), vq=np.zeros((nv, qem.QUADRIC_WIDTH)), vbnd=np.zeros(nv, np.uint8),
                vlock=np.zeros(nv, np.uint8), vdead=np.zeros(nv, np.uint8), vimp=imp, vfresh=np.ones(nv, np.uint8),
                tris=tris.astype(np.int32).copy())


def _decimate(st, target):
    nt = len(st["tris"])
    qem.add_face_quadrics(st["vpos"], st["vq"], st["vimp"], st["tris"], 0, nt)
    return qem.decimate(st["vpos"], st["vq"], st["vbnd"], st["vlock"], st["vdead"], st["vimp"], st["vfresh"],
                        st["tris"], len(st["vpos"]), nt, target, 0.0, np.empty(0, np.int64))


@pytest.mark.parametrize("seed, keep", [(0, 0.5), (1, 0.2), (2, 0.05)])
def test_current_quadrics_are_the_faces_as_they_are(seed, keep):
    """After any number of collapses every live vertex's current quadric is the reference's
    memoryless quadric of the surface as it is (faces around it now, border planes)."""
    pts, tris = _wavy_patch(seed=seed)
    imp = np.random.default_rng(seed).uniform(0.5, 2.0, len(pts))
    st = _state(pts, tris, imp)
    target = int(keep * len(tris))
    alive, done = _decimate(st, target)
    assert done > 0 and target - 2 <= alive <= target  # an interior collapse removes two faces
    live_t = st["tris"][st["tris"][:, 0] >= 0]
    for v in np.unique(live_t):
        ref = naive_current_quadric(st["vpos"], live_t, v, border_weight=qem.BOUNDARY_WEIGHT, importance=imp)
        assert np.allclose(st["vq"][v, qem.CURRENT], ref, rtol=1e-9, atol=1e-15), v


def test_history_quadrics_are_conserved():
    """A collapse adds the removed vertex's history to the survivor's: over the live vertices the
    history sums to every original face's quadric (three corners each) plus the original border's
    planes (at their history weight), whatever was collapsed."""
    pts, tris = _wavy_patch(seed=3)
    expect = np.zeros(10)
    for n, d, w in naive_face_quadrics(pts, tris):
        expect += 3 * plane_quadric(n, d, w)
    for v in range(len(pts)):
        expect += naive_border_planes(pts, tris, v, qem.BOUNDARY_HISTORY_WEIGHT)
    st = _state(pts, tris)
    _, done = _decimate(st, len(tris) // 10)
    assert done > 0
    live = st["vdead"] == 0
    got = st["vq"][live][:, qem.HISTORY].sum(axis=0)
    assert np.allclose(got, expect, rtol=1e-9, atol=1e-12)


def test_cost_weighs_current_and_history():
    """The placement works on current + HISTORY_WEIGHT x history of both ends."""
    rng = np.random.default_rng(11)
    for _ in range(20):
        pu, pv = rng.normal(size=3), rng.normal(size=3)
        cur = [_random_quadric(rng, 2, 0.5 * (pu + pv), 0.3) for _ in range(2)]
        hist = [_random_quadric(rng, 3, 0.5 * (pu + pv), 0.3) for _ in range(2)]
        vq = np.zeros((2, qem.QUADRIC_WIDTH))
        for i in range(2):
            vq[i, qem.CURRENT], vq[i, qem.HISTORY] = cur[i], hist[i]
        cost, x, y, z = qem._placement(vq, np.array([pu, pv]), np.zeros(2, np.uint8), 0, 1, np.empty(10))
        q = cur[0] + cur[1] + qem.HISTORY_WEIGHT * (hist[0] + hist[1])
        ref_cost, _ = naive_placement(q, pu, pv, ridge=qem.PLACE_RIDGE, reach=qem.PLACE_REACH)
        scale = max(abs(q[9]), quadric_cost(q, pu), quadric_cost(q, pv), 1e-12)
        assert cost == pytest.approx(max(quadric_cost(q, np.array([x, y, z])), 0.0), rel=1e-7, abs=1e-9 * scale)
        assert abs(cost - ref_cost) <= 1e-6 * scale + 1e-12


def test_edge_cost_is_the_reference_key():
    """The heap key: the placement's cost over the quadric's weight to COST_WEIGHT_POWER, times the
    larger importance of the ends; a quadric with ten times the weight of the same planes (a region
    ten times larger) costs more, but less than ten times more, and importance scales the key."""
    rng = np.random.default_rng(12)
    for _ in range(30):
        pu, pv = rng.normal(size=3), rng.normal(size=3)
        cur = [_random_quadric(rng, 3, 0.5 * (pu + pv), 0.3) for _ in range(2)]
        hist = [_random_quadric(rng, 3, 0.5 * (pu + pv), 0.3) for _ in range(2)]
        imp = rng.uniform(0.5, 3.0, 2)
        vq = np.zeros((2, qem.QUADRIC_WIDTH))
        for i in range(2):
            vq[i, qem.CURRENT], vq[i, qem.HISTORY] = cur[i], hist[i]
        vpos = np.array([pu, pv])
        key = qem._edge_cost(vq, vpos, np.zeros(2, np.uint8), imp, 0, 1, np.empty(10))
        q = cur[0] + cur[1] + qem.HISTORY_WEIGHT * (hist[0] + hist[1])
        ref = naive_edge_cost(q, pu, pv, imp[0], imp[1], ridge=qem.PLACE_RIDGE, reach=qem.PLACE_REACH,
                              weight_power=qem.COST_WEIGHT_POWER)
        assert key == pytest.approx(ref, rel=1e-6, abs=1e-12 * max(abs(q[9]), 1.0))
        heavy = qem._edge_cost(10 * vq, vpos, np.zeros(2, np.uint8), imp, 0, 1, np.empty(10))
        if key > 1e-9:
            assert key < heavy < 10 * key
            assert heavy == pytest.approx(key * 10 ** (1 - qem.COST_WEIGHT_POWER), rel=1e-6)


def test_border_survives_on_an_open_patch():
    """The patch's border (a square) stays: every border vertex stays on the square's sides, up to
    what the soft constraint planes allow (a few % of the grid spacing)."""
    pts, tris = _wavy_patch(seed=4)
    st = _state(pts, tris)
    _decimate(st, len(tris) // 20)
    live_t = st["tris"][st["tris"][:, 0] >= 0]
    e = np.sort(np.concatenate([live_t[:, [0, 1]], live_t[:, [1, 2]], live_t[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    border = np.unique(u[c == 1])
    xy = st["vpos"][border, :2]
    on_side = np.minimum(np.minimum(np.abs(xy[:, 0]), np.abs(xy[:, 0] - 1)),
                         np.minimum(np.abs(xy[:, 1]), np.abs(xy[:, 1] - 1)))
    assert on_side.max() < 0.05 / 23  # grid spacing 1/23


def _fan_case(rng, pts, tris):
    """An interior edge (u, v) of the patch, chains of points for u and v, a new position near the edge."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    u, v = edges[rng.choice(np.flatnonzero(count == 2))]
    new = 0.5 * (pts[u] + pts[v]) + 0.02 * rng.normal(size=3)
    others = rng.choice(np.setdiff1d(np.arange(len(pts)), [u, v]), size=rng.integers(0, 12), replace=False)
    # u stands for itself and some of the points; v for itself and the rest (chains through nxt)
    nxt = np.full(len(pts), -1, np.int64)
    cut = len(others) // 2
    for head, members in ((u, others[:cut]), (v, others[cut:])):
        prev = head
        for m in members:
            nxt[prev] = m
            prev = m
    return int(u), int(v), new, nxt, np.concatenate([[u, v], others])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_fan_distance_is_the_reference(seed):
    """The one-sided distance of a collapse: the farthest of the points that u and v stand for from
    the faces around them after the merge, against exact distances from the metric module's routine;
    with a floor it reports max(floor, distance), and past a ceiling it may stop early (between the
    ceiling and the true distance)."""
    rng = np.random.default_rng(seed)
    pts, tris = _wavy_patch(n=8, seed=seed % 1000)
    pts = pts + 0.05 * rng.normal(size=pts.shape)  # the points the chains stand for are off the surface
    u, v, new, nxt, members = _fan_case(rng, pts, tris)
    nv, nt = len(pts), len(tris)
    start, cnt, refs, _ = qem._build_adjacency(nv, tris.astype(np.int32), nt, 0)
    args = (new[0], new[1], new[2], u, v, start, cnt, refs, tris.astype(np.int32), pts, pts, nxt,
            np.empty((1, qem.FAN_WIDTH)))
    ref = naive_fan_distance(pts, tris, u, v, new, pts[members])
    got, _ = qem._fan_distance(*args, 0.0, np.inf)
    assert got == pytest.approx(ref, rel=1e-9, abs=1e-15)
    floor = rng.uniform(0, 2) * ref
    assert qem._fan_distance(*args, floor, np.inf)[0] == pytest.approx(max(floor, ref), rel=1e-9, abs=1e-15)
    if ref > 0:
        ceiling = rng.uniform(0, 1) * ref
        early, _ = qem._fan_distance(*args, 0.0, ceiling)
        assert ceiling < early <= ref * (1 + 1e-9)


def test_a_closed_piece_is_not_removed_for_free():
    """The last collapse of a closed piece (two faces back to back on edge uv: both die) leaves no
    face for its points: they are measured to the new vertex, not counted as distance 0."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    tris = np.array([[0, 1, 2], [1, 0, 2]], np.int32)
    start, cnt, refs, _ = qem._build_adjacency(4, tris, 2, 0)
    nxt = np.array([2, 3, -1, -1], np.int64)  # u = 0 stands for 0 and 2, v = 1 for 1 and 3
    new = np.array([0.5, 0.0, 0.0])
    d, _ = qem._fan_distance(new[0], new[1], new[2], 0, 1, start, cnt, refs, tris, pts, pts, nxt,
                             np.empty((1, qem.FAN_WIDTH)), 0.0, np.inf)
    assert d == pytest.approx(np.max(np.sum((pts - new) ** 2, axis=1)))
    assert d == pytest.approx(naive_fan_distance(pts, tris, 0, 1, new, pts))
