"""Time-critical rendering (paper 5, 6.3): map a frame-time budget to a level and a ratio.

End-to-end time is close to linear in the tets handled, so a file's frame time is modelled as::

    T = fixed_s + decode_s_per_tet * (tets of the stored level decoded)
                + render_s_per_tet * (tets left after on-the-fly simplification)

``fixed_s`` covers what does not scale with tets (ray set-up per pixel, boundary intersection,
PNG output). The three coefficients are calibrated per file, image size and mode on first use
(two probe renders of coarse stored levels) and kept in the user's cache directory.

Given a budget B, :func:`plan_for_budget` walks the stored levels from the finest: the first level
whose own ratio fits is taken as is; if it does not fit but can be simplified on the fly far
enough before the next level starts, the finest such ratio is taken (starting from that level).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class LevelSize:
    level: int
    merges: int  # N_i: merges of the full forest applied in this stored level
    tets: int


@dataclass(frozen=True)
class TimeModel:
    fixed_s: float
    decode_s_per_tet: float
    render_s_per_tet: float

    def predict(self, decoded_tets: float, rendered_tets: float) -> float:
        return self.fixed_s + self.decode_s_per_tet * decoded_tets + self.render_s_per_tet * rendered_tets


@dataclass(frozen=True)
class BudgetPlan:
    level: int  # stored level to start from
    merges: int  # target number of merges N (>= that level's N_i)
    predicted_s: float
    feasible: bool  # False: even the coarsest level is predicted to exceed the budget


def estimated_tets(levels: list[LevelSize], merges: int) -> float:
    """Tets left after ``merges`` merges, interpolated linearly between stored levels."""
    ls = sorted(levels, key=lambda x: x.merges)
    if merges <= ls[0].merges:
        return float(ls[0].tets)
    for lo, hi in zip(ls[:-1], ls[1:]):
        if merges <= hi.merges:
            f = (merges - lo.merges) / max(hi.merges - lo.merges, 1)
            return lo.tets + f * (hi.tets - lo.tets)
    return float(ls[-1].tets)


def plan_for_budget(levels: list[LevelSize], model: TimeModel, budget_s: float, max_merges: int) -> BudgetPlan:
    """The finest simplification whose predicted frame time is within ``budget_s``.

    Examples
    --------
    >>> lv = [LevelSize(0, 0, 1000), LevelSize(1, 50, 500), LevelSize(2, 75, 250)]
    >>> m = TimeModel(0.01, 1e-4, 1e-4)
    >>> plan_for_budget(lv, m, 0.2, 80)       # level 0 needs 0.21 s, level 1 0.11 s
    BudgetPlan(level=0, merges=..., predicted_s=..., feasible=True)
    """
    ls = sorted(levels, key=lambda x: x.merges)
    for i, lv in enumerate(ls):
        t_own = model.predict(lv.tets, lv.tets)
        if t_own <= budget_s:
            return BudgetPlan(lv.level, lv.merges, t_own, True)
        end = ls[i + 1].merges if i + 1 < len(ls) else max_merges
        if end <= lv.merges:
            continue
        # On the fly from this level: decoding cost fixed, rendering shrinks with the merges.
        t_end = model.predict(lv.tets, estimated_tets(ls, end))
        if t_end > budget_s:
            continue
        lo, hi = lv.merges, end  # t(lo) > budget >= t(hi): bisect for the smallest fitting N
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if model.predict(lv.tets, estimated_tets(ls, mid)) <= budget_s:
                hi = mid
            else:
                lo = mid
        return BudgetPlan(lv.level, hi, model.predict(lv.tets, estimated_tets(ls, hi)), True)
    last = ls[-1]
    return BudgetPlan(last.level, max(last.merges, max_merges), model.predict(last.tets, estimated_tets(ls, max_merges)),
                      False)


def fit_time_model(probes: list[dict]) -> TimeModel:
    """Coefficients from probe renders, each a dict with ``decoded_tets``, ``rendered_tets``,
    ``decode_s`` (decode + filter), ``render_s`` and ``total_s``.

    Decoding is proportional to the tets decoded; rendering is a least-squares line over the tets
    rendered (its intercept is per-pixel work: ray set-up, boundary, samples); what the two do not
    explain (file opening, PNG output) goes into the fixed cost, averaged over the probes.
    """
    dec = sum(p["decode_s"] for p in probes) / max(sum(p["decoded_tets"] for p in probes), 1)
    r = np.array([p["rendered_tets"] for p in probes], float)
    y = np.array([p["render_s"] for p in probes], float)
    if len(probes) > 1 and np.ptp(r) > 0:
        ren = max(float(np.polyfit(r, y, 1)[0]), 0.0)
    else:
        ren = float(y.max() / max(r.max(), 1.0))
    fixed = max(float(np.mean([p["total_s"] - dec * p["decoded_tets"] - ren * p["rendered_tets"] for p in probes])),
                0.0)
    return TimeModel(fixed, dec, ren)


# -- calibration cache ------------------------------------------------------------------------

def cache_dir() -> Path:
    """Where calibrations live: $TETC_CACHE_DIR, else $XDG_CACHE_HOME/tetc, else ~/.cache/tetc."""
    if os.environ.get("TETC_CACHE_DIR"):
        return Path(os.environ["TETC_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "tetc"


def calibration_key(file_id: str, size: tuple[int, int], mode: str, extra: str = "") -> str:
    machine = f"{platform.node()}|{platform.machine()}|{os.cpu_count()}|{os.environ.get('NUMBA_NUM_THREADS', '')}"
    return hashlib.sha1(f"{machine}|{file_id}|{size[0]}x{size[1]}|{mode}|{extra}".encode()).hexdigest()[:20]


def load_model(key: str) -> TimeModel | None:
    try:
        data = json.loads((cache_dir() / "timing.json").read_text())
        return TimeModel(**data[key])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def save_model(key: str, model: TimeModel) -> None:
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
        path = d / "timing.json"
        try:
            data = json.loads(path.read_text())
            if not isinstance(data, dict):
                data = {}
        except (OSError, ValueError):
            data = {}
        data[key] = asdict(model)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(json.dumps(data, indent=1))
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only home only costs a re-calibration next time


# -- planning a file's render ---------------------------------------------------------------------

def _file_id(path) -> str:
    st = os.stat(path)
    return f"{os.path.abspath(path)}|{st.st_size}|{st.st_mtime_ns}"


def _probe_levels(levels: list[LevelSize]) -> list[LevelSize]:
    """The coarsest stored level and those closest to 1/16 and 1/4 of the full mesh's tets."""
    ls = sorted(levels, key=lambda x: x.merges)
    picks = {ls[-1].level: ls[-1]}
    for frac in (1 / 16, 1 / 4):
        goal = max(ls[0].tets * frac, 1.0)
        lv = min(ls, key=lambda x: abs(math.log(max(x.tets, 1) / goal)))
        picks.setdefault(lv.level, lv)
    return list(picks.values())


def calibrate(path, view, levels: list[LevelSize], *, repeats: int = 3) -> TimeModel:
    """Time whole frames (open, decode, render, PNG written) of a few stored levels and fit the model.

    Each probe is the median of ``repeats`` warm frames, so the model predicts a typical frame,
    not the luckiest one.
    """
    import statistics
    import tempfile

    from ..render.image import write_png
    from .stream import Target, render_tetc

    probes = []
    with tempfile.TemporaryDirectory(prefix="tetc-calib-") as tmp:
        png = Path(tmp) / "probe.png"
        render_tetc(path, view, target=Target(levels[-1].level, levels[-1].merges, 0.0, levels[-1].merges))
        for lv in _probe_levels(levels):
            runs = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                res = render_tetc(path, view, target=Target(lv.level, lv.merges, 0.0, lv.merges))
                write_png(png, res.image, force=True)  # a frame ends with its PNG on disk
                runs.append((time.perf_counter() - t0, res.stats))
            total = statistics.median(t for t, _ in runs)
            st = min(runs, key=lambda r: abs(r[0] - total))[1]
            probes.append(dict(decoded_tets=lv.tets, rendered_tets=st["tets_rendered"],
                               decode_s=st["decode_s"] + st["filter_s"], render_s=st["render_s"], total_s=total))
    return fit_time_model(probes)


def model_key(path, view) -> str:
    """Calibration key of a file rendered with a view (camera, transfer function, sampling)."""
    tf = view.tf
    tf_key = tf if isinstance(tf, str) else json.dumps(getattr(tf, "__dict__", tf), sort_keys=True, default=str)
    cam = view.camera
    return calibration_key(_file_id(path), (cam.width, cam.height), view.mode,
                           f"{tf_key}|{view.step}|{cam.azimuth}|{cam.elevation}|{cam.zoom}")


def plan_file_budget(path, view, budget_s: float, *, recalibrate: bool = False):
    """(Target, BudgetPlan, TimeModel, calibrated_now) for rendering ``path`` within ``budget_s``."""
    if not math.isfinite(float(budget_s)):
        from ..errors import OptionError

        raise OptionError(f"--budget must be a number of seconds, got {budget_s}")
    from ..codec import TetcReader
    from ..simplify.levels import Target, forest_merges, stored_levels

    reader = TetcReader(path)
    pts = int(reader.meta["points"])
    levels = [LevelSize(int(lv["level"]), int(lv.get("merges_before", 0)), int(lv["tets"]))
              for lv in stored_levels(reader)]
    key = model_key(path, view)
    model = None if recalibrate else load_model(key)
    calibrated = model is None
    if model is None:
        model = calibrate(path, view, levels)
        save_model(key, model)
    reach = forest_merges(reader)
    # Only stored levels with a forest can be simplified further on the fly.
    plan = plan_for_budget(levels, model, float(budget_s), reach)
    start = next(lv for lv in reader.levels if int(lv["level"]) == plan.level)
    merges = plan.merges if start.get("has_forest") else int(start.get("merges_before", 0))
    target = Target(plan.level, merges, merges / max(pts, 1), int(start.get("merges_before", 0)))
    return target, plan, model, calibrated
