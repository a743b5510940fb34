"""The time model and budget planning: properties, not timings.

* the plan is the finest simplification whose prediction fits, never a finer one;
* the model learns: fed frames of a machine k times slower, its predictions converge to k times;
* the work estimate learns a view's counts from a frame and reproduces them;
* the costs cache round-trips and shrugs off garbage; seeding gives positive finite costs;
* ``tetc render --budget`` plans from the file's metadata (no per-file calibration) and renders
  exactly the target it planned.
"""

import json
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_sample
from gatun_py.codec import TetcReader
from gatun_py.pipeline import budget as B
from gatun_py.pipeline.budget import (BudgetPlan, Costs, FramePlanner, LevelSize, TimeModel, Work, WorkEstimator,
                                      estimated_tets, load_costs, plan_for_budget, save_costs)
from gatun_py.pipeline.stream import View, render_tetc
from gatun_py.raycast.camera import Camera


def _levels(n_points=4096, tets0=20000, k=8):
    out = []
    for i in range(k + 1):
        merges = n_points - -(-n_points // (1 << i))
        tets = max(int(tets0 / 2 ** i), 1)
        out.append(LevelSize(i, merges, tets, n_points >> i, max(int(tets ** (2 / 3)), 4), True))
    return out


def _start_index(levels, n):
    return max(i for i, lv in enumerate(levels) if lv.merges <= n)


def _predictor(levels, costs, pixels=256 * 256):
    est = WorkEstimator(levels, bbox=([0, 0, 0], [1, 1, 1]), step=0.01)
    model = TimeModel(costs)
    return lambda i, n: model.predict(est.estimate(levels[i], n, pixels, 0.5))


costs_strategy = st.builds(Costs, *[st.floats(0.0, 1e-2)] + [st.floats(0.0, 1e-6)] * 2 + [st.floats(0.0, 1e-2)]
                           + [st.floats(0.0, 1e-6)] * 5 + [st.floats(0.0, 1e-2)])


@settings(max_examples=150, deadline=None)
@given(st.floats(1e-4, 2.0), costs_strategy)
def test_plan_is_the_finest_that_fits(budget, costs):
    levels = _levels()
    predict = _predictor(levels, costs)
    max_merges = levels[-1].merges
    plan = plan_for_budget(levels, predict, budget, max_merges)
    i = next(k for k, lv in enumerate(levels) if lv.level == plan.level)
    assert plan.merges >= levels[i].merges
    assert plan.predicted_s == pytest.approx(predict(i, plan.merges))
    if plan.feasible:
        assert plan.predicted_s <= budget * (1 + 1e-12)
        n = plan.merges - 1  # one merge fewer (finer) does not fit from the level it would start at
        if n >= 0:
            assert predict(_start_index(levels, n), n) > budget
    else:  # nothing fits: the coarsest the file can reach
        assert plan.level == levels[-1].level and plan.merges == max_merges
        assert all(predict(j, lv.merges) > budget for j, lv in enumerate(levels))


@settings(max_examples=50, deadline=None)
@given(st.floats(0.01, 1.0), st.floats(0.01, 1.0))
def test_a_larger_budget_never_plans_coarser(b1, b2):
    levels = _levels()
    predict = _predictor(levels, Costs())
    lo, hi = sorted((b1, b2))
    p_lo = plan_for_budget(levels, predict, lo, levels[-1].merges)
    p_hi = plan_for_budget(levels, predict, hi, levels[-1].merges)
    assert p_hi.merges <= p_lo.merges


def test_levels_without_a_forest_are_never_simplified_on_the_fly():
    levels = [LevelSize(0, 0, 1000, 400, 100, False), LevelSize(1, 200, 500, 200, 60, False)]
    predict = lambda i, n: 1e-4 * estimated_tets(levels, n)  # noqa: E731
    plan = plan_for_budget(levels, predict, 0.07, 300)  # level 0 (0.1 s) too slow, level 1 (0.05 s) fits
    assert (plan.level, plan.merges) == (1, 200)
    plan = plan_for_budget(levels, predict, 0.01, 300)  # nothing fits, and level 1 cannot go further
    assert (plan.level, plan.merges, plan.feasible) == (1, 200, False)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.2, 5.0), st.floats(0.2, 5.0), st.integers(0, 2**31 - 1))
def test_model_converges_to_a_slower_machine(k_decode, k_render, seed):
    """Frames from a machine whose stages are k times the seed's: predictions follow."""
    rng = np.random.default_rng(seed)
    truth = Costs().scaled(k_decode, k_render)
    model = TimeModel(Costs())
    for _ in range(40):
        w = Work(*rng.uniform([0, 0, 1e3, 1e4, 1e4, 100, 1e4], [1e6, 1e5, 1e6, 1e7, 1e7, 1e5, 1e6]))
        model.observe(w, decode_s=truth.decode_s(w), render_s=truth.render_s(w), other_s=0.004)
    w = Work(5e5, 0, 2e5, 3e6, 3e6, 1e4, 2.6e5)
    assert model.predict_stages(w)["decode_s"] == pytest.approx(truth.decode_s(w), rel=1e-3)
    assert model.predict_stages(w)["render_s"] == pytest.approx(truth.render_s(w), rel=1e-3)
    assert model.predict_stages(w)["other_s"] == pytest.approx(0.004, rel=1e-3)


def test_tiny_stages_teach_nothing():
    """A 2-tet decode measures its fixed part: it must not blow up the cost per tet."""
    model = TimeModel(Costs())
    w = Work(tets_decoded=2, tets_rendered=2, steps=10, samples=10, boundary_faces=6, pixels=16)
    model.observe(w, decode_s=0.005, render_s=0.004, other_s=0.0)
    assert model.decode_scale == 1.0 and model.render_scale == 1.0


def test_one_outlier_frame_moves_the_model_only_part_way():
    model = TimeModel(Costs())
    w = Work(1e5, 0, 1e5, 1e6, 1e6, 1e3, 6.5e4)
    before = model.predict(w)
    model.observe(w, decode_s=100 * Costs().decode_s(w), render_s=100 * Costs().render_s(w), other_s=0.002)
    assert before < model.predict(w) < 100 * before / 2


def test_work_estimate_reproduces_an_observed_frame():
    levels = _levels()
    est = WorkEstimator(levels, bbox=([0, 0, 0], [2, 1, 1]), step=0.05)
    stats = {"rays": 10000, "rays_hit": 4000, "steps": 90000, "samples": 120000, "tets_rendered": levels[2].tets}
    est.observe(stats, step_factor=2.0)
    w = est.estimate(levels[2], levels[2].merges, 10000, coverage=0.9, step_factor=2.0)
    assert w.steps == pytest.approx(90000) and w.samples == pytest.approx(120000)
    assert w.tets_rendered == levels[2].tets and w.forest_points == 0  # no filtering at a stored level
    w1 = est.estimate(levels[2], levels[2].merges, 10000, coverage=0.9, step_factor=1.0)
    assert w1.samples == pytest.approx(240000)  # half the step, twice the samples
    w_fly = est.estimate(levels[2], (levels[2].merges + levels[3].merges) // 2, 10000, coverage=0.9)
    assert w_fly.forest_points == levels[2].points and w_fly.tets_rendered < levels[2].tets
    assert est.estimate(levels[2], levels[2].merges, 10000, decoded=True).tets_decoded == 0


def test_work_estimate_learns_the_tets_the_transfer_function_culls():
    """A frame whose transfer function hid 3/4 of the tets: the estimate of the same view renders
    a quarter of each level's tets (what the face table receives), and the level's own size (for
    the steps' cube-root rule) stays the whole level's."""
    levels = _levels()
    est = WorkEstimator(levels, bbox=([0, 0, 0], [2, 1, 1]), step=0.05)
    shown = levels[1].tets // 4
    stats = {"rays": 10000, "rays_hit": 4000, "steps": 30000, "samples": 50000, "tets_rendered": levels[1].tets,
             "tets_culled": levels[1].tets - shown, "level": 1}
    est.observe(stats)
    w = est.estimate(levels[1], levels[1].merges, 10000, coverage=0.9)
    assert w.tets_rendered == pytest.approx(shown, rel=1e-3) and w.steps == pytest.approx(30000)
    assert est.seen[1][0] == levels[1].tets
    # another level of the same view: the same visible share, the steps by its own size
    w2 = est.estimate(levels[2], levels[2].merges, 10000, coverage=0.9)
    assert w2.tets_rendered == pytest.approx(levels[2].tets * shown / levels[1].tets, rel=1e-3)
    # a frame that culls nothing resets the share
    est.observe(dict(stats, tets_culled=0))
    assert est.estimate(levels[1], levels[1].merges, 10000).tets_rendered == levels[1].tets


def test_first_guess_overestimates_rays_from_the_bounding_box():
    """Before any frame, the hits are the projected box's rectangle: at least the real hits."""
    mesh, _ = load_sample("post")
    from gatun_py.raycast.caster import render_mesh

    cam = Camera(64, 48, 30, 20)
    fitted = cam.fit(*mesh.bbox)
    est = WorkEstimator(_levels(), bbox=mesh.bbox, step=0.1)
    res = render_mesh(mesh, fitted, "post")
    assert est.coverage(fitted) * 64 * 48 >= res.stats["rays_hit"]


def test_costs_cache_round_trip(tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    assert load_costs("k") is None
    c = Costs().scaled(2.0, 3.0)
    save_costs(c, "k")
    assert load_costs("k") == c
    assert load_costs("other machine") is None
    (tmp_path / "costs.json").write_text("garbage")
    assert load_costs("k") is None
    (tmp_path / "costs.json").write_text(json.dumps({"k": {"fixed_s": -1}}))
    assert load_costs("k") is None


def test_seeded_costs_are_positive_and_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    costs, seeded = B.machine_costs()
    assert seeded
    values = [getattr(costs, f) for f in Costs.__dataclass_fields__]
    assert all(math.isfinite(v) and v > 0 for v in values)
    # The seed scales the reference costs per stage: their ratios within a stage are kept.
    ref = Costs()
    assert costs.per_step / costs.per_sample == pytest.approx(ref.per_step / ref.per_sample)
    assert B.machine_costs() == (costs, False)


def test_plan_file_budget_renders_the_planned_target(post_tetc, tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    view = View(Camera(48, 40, 30, 20), tf="post")
    tight, plan_t, planner, _ = B.plan_file_budget(post_tetc, view, 1e-4)
    loose, plan_l, _, seeded = B.plan_file_budget(post_tetc, view, 100.0)
    assert not seeded  # the first call seeded the machine's costs; nothing is per file
    assert not plan_t.feasible and tight.merges == planner.max_merges  # coarsest possible
    assert plan_l.feasible and (loose.level, loose.merges) == (0, 0)  # the full mesh
    res = render_tetc(post_tetc, view, target=tight)
    assert res.stats["merges"] == tight.merges and res.stats["level"] == tight.level
    # The planner observed the probe: the view's hit rays are known, not guessed.
    assert planner.estimator.hit_fraction is not None


def test_the_seeding_does_not_eat_the_budget(post_tetc, tmp_path, monkeypatch):
    """A first budget render on a machine plans as the second does: seeding the costs (once) is
    not charged to the frame."""
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))

    def slow_seed(**_):
        time.sleep(0.6)  # a busy machine's seeding
        return Costs()

    monkeypatch.setattr(B, "seed_costs", slow_seed)
    view = View(Camera(48, 40, 30, 20), tf="post")
    first, plan1, _, seeded1 = B.plan_file_budget(post_tetc, view, 0.5)
    again, plan2, _, seeded2 = B.plan_file_budget(post_tetc, view, 0.5)
    assert seeded1 and not seeded2
    assert plan2.feasible and plan2.scale == 1.0  # post at 48x40 fits half a second
    assert (plan1.feasible, plan1.scale, first.level, first.merges) == (True, 1.0, again.level, again.merges)


def test_frame_planner_learns_from_a_frame(post_tetc, tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    reader = TetcReader(post_tetc)
    planner = FramePlanner(reader, TimeModel(Costs()), step=float(reader.meta["render_step"]))
    view = View(Camera(64, 64, 10, 40), tf="post")
    res = render_tetc(reader, view, level=2)
    lv = planner.level_size(2)
    planner.observe(res.stats, total_s=1.0)
    w = planner.estimate(2, lv.merges, 64 * 64, 1.0)
    assert w.steps == pytest.approx(res.stats["steps"]) and w.samples == pytest.approx(res.stats["samples"])
    assert planner.model.frames == 1


def test_still_plans_shrink_the_image_only_when_no_level_fits(post_tetc):
    """``rescale``: full size at any level first; a smaller image only when even the coarsest level
    cannot make it at full size; the step is never coarsened for a still."""
    reader = TetcReader(post_tetc)
    planner = FramePlanner(reader, TimeModel(Costs()), step=float(reader.meta["render_step"]))
    fitted = Camera(512, 512).fit(*[np.asarray(x) for x in reader.meta["bbox"]])
    coarsest_full = planner.plan(1e-9, fitted)
    for budget in (100.0, 0.5 * coarsest_full.predicted_s, 1.01 * coarsest_full.predicted_s):
        plan = planner.plan(budget, fitted, rescale=True)
        assert plan.step_factor == 1.0
        if plan.scale < 1.0:
            assert budget < coarsest_full.predicted_s and plan.feasible  # no level fits at full size
        else:
            assert plan.feasible and (plan.level, plan.merges) == (lambda p: (p.level, p.merges))(
                planner.plan(budget, fitted))


@pytest.mark.parametrize("drag", [False, True])
def test_drag_plans_coarsen_step_and_size_only_when_levels_cannot(post_tetc, drag):
    reader = TetcReader(post_tetc)
    planner = FramePlanner(reader, TimeModel(Costs()), step=float(reader.meta["render_step"]))
    fitted = Camera(512, 512).fit(*[np.asarray(x) for x in reader.meta["bbox"]])
    generous = planner.plan(100.0, fitted, drag=drag)
    assert (generous.scale, generous.step_factor, generous.merges) == (1.0, 1.0, 0)
    tiny = planner.plan(1e-4, fitted, drag=drag)
    assert not tiny.feasible
    if drag:
        assert tiny.scale < 1.0  # the cheapest setting was tried
    else:
        assert (tiny.scale, tiny.step_factor) == (1.0, 1.0)
    assert isinstance(tiny, BudgetPlan)
