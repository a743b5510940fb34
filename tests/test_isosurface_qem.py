"""QEM cost and placement (gatun_py.isosurface.qem) against the plain reference in naive_qem."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from naive_qem import DET_FLOOR, naive_placement, naive_segment_min, plane_quadric, quadric_cost

from gatun_py.isosurface import qem


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
