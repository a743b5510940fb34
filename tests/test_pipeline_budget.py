"""Budget planning: the finest simplification whose predicted time fits, never a finer one."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatun_py.pipeline.budget import LevelSize, LevelTimes, estimated_tets, load_model, plan_for_budget, save_model


def _levels(n_points=4096, tets0=20000, k=8):
    out = []
    for i in range(k + 1):
        merges = n_points - -(-n_points // (1 << i))
        out.append(LevelSize(i, merges, max(int(tets0 / 2 ** i), 1)))
    return out


def _times(levels, fixed, dec, ren):
    """Frame times that grow with the tets, as measured ones do."""
    return LevelTimes(tuple(fixed + (dec + ren) * lv.tets for lv in levels), tuple(dec * lv.tets for lv in levels))


def _start_index(levels, n):
    return max(i for i, lv in enumerate(levels) if lv.merges <= n)


@settings(max_examples=200, deadline=None)
@given(st.floats(1e-4, 1.0), st.floats(0, 0.05), st.floats(1e-8, 1e-5), st.floats(1e-8, 1e-5))
def test_plan_is_the_finest_that_fits(budget, fixed, dec, ren):
    levels = _levels()
    model = _times(levels, fixed, dec, ren)
    max_merges = levels[-1].merges
    plan = plan_for_budget(levels, model, budget, max_merges)
    i = next(k for k, lv in enumerate(levels) if lv.level == plan.level)
    assert plan.merges >= levels[i].merges
    assert plan.predicted_s == pytest.approx(model.predict(levels, i, plan.merges))
    if plan.feasible:
        assert plan.predicted_s <= budget * (1 + 1e-12)
        n = plan.merges - 1  # one merge fewer (finer) would not fit, from whichever level it starts
        if n >= 0:
            assert model.predict(levels, _start_index(levels, n), n) > budget
    else:
        assert plan.level == levels[-1].level and model.total_s[-1] > budget


def test_prediction_matches_the_measurements_at_stored_levels():
    levels = _levels()
    model = _times(levels, 0.01, 1e-6, 3e-6)
    for i, lv in enumerate(levels):
        assert model.predict(levels, i, lv.merges) == model.total_s[i]
    # Half way to the next level from level 2: decoding level 2, rendering in between.
    n = (levels[2].merges + levels[3].merges) // 2
    t = model.predict(levels, 2, n)
    assert model.decode_s[2] + (model.total_s[3] - model.decode_s[3]) < t < model.total_s[2]
    assert estimated_tets(levels, n) == pytest.approx((levels[2].tets + levels[3].tets) / 2, rel=0.01)


def test_model_cache_round_trip(tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    assert load_model("k") is None
    m = LevelTimes((0.3, 0.2), (0.1, 0.05))
    save_model("k", m)
    assert load_model("k") == m and load_model("k", 2) == m
    assert load_model("k", 3) is None  # calibrated for another set of levels
    (tmp_path / "timing.json").write_text("garbage")
    assert load_model("k") is None
