"""Budget planning: the finest simplification whose predicted time fits, never a finer one."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatun_py.pipeline.budget import (LevelSize, TimeModel, estimated_tets, fit_time_model, load_model,
                                      plan_for_budget, save_model)


def _levels(n_points=4096, tets0=20000, k=8):
    out = []
    for i in range(k + 1):
        merges = n_points - -(-n_points // (1 << i))
        out.append(LevelSize(i, merges, max(int(tets0 / 2 ** i), 1)))
    return out


@settings(max_examples=200, deadline=None)
@given(st.floats(1e-4, 1.0), st.floats(0, 0.05), st.floats(1e-8, 1e-5), st.floats(1e-8, 1e-5))
def test_plan_is_the_finest_that_fits(budget, fixed, dec, ren):
    levels = _levels()
    model = TimeModel(fixed, dec, ren)
    max_merges = levels[-1].merges + 10
    plan = plan_for_budget(levels, model, budget, max_merges)
    start = next(lv for lv in levels if lv.level == plan.level)
    assert plan.merges >= start.merges
    assert plan.predicted_s == pytest.approx(model.predict(start.tets, estimated_tets(levels, plan.merges)))
    if plan.feasible:
        assert plan.predicted_s <= budget * (1 + 1e-12)
        # One merge fewer (finer) would not fit, from whichever level it would start.
        n = plan.merges - 1
        if n >= 0:
            lv = max((x for x in levels if x.merges <= n), key=lambda x: x.merges)
            assert model.predict(lv.tets, estimated_tets(levels, n)) > budget
    else:
        assert plan.level == levels[-1].level


def test_fit_recovers_a_linear_model():
    truth = TimeModel(0.02, 3e-7, 2e-6)
    probes = []
    for d, r in ((1000, 1000), (20000, 20000), (20000, 8000)):
        dec = truth.decode_s_per_tet * d
        ren = truth.render_s_per_tet * r
        probes.append(dict(decoded_tets=d, rendered_tets=r, decode_s=dec, render_s=ren + 0.015,
                           total_s=dec + ren + truth.fixed_s))
    m = fit_time_model(probes)
    assert m.decode_s_per_tet == pytest.approx(truth.decode_s_per_tet)
    assert m.render_s_per_tet == pytest.approx(truth.render_s_per_tet)
    assert m.fixed_s == pytest.approx(truth.fixed_s)


def test_model_cache_round_trip(tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    assert load_model("k") is None
    save_model("k", TimeModel(1.0, 2.0, 3.0))
    assert load_model("k") == TimeModel(1.0, 2.0, 3.0)
    (tmp_path / "timing.json").write_text("garbage")
    assert load_model("k") is None
