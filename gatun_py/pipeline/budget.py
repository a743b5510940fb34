"""Time-critical rendering (paper 5, 6.3): map a frame-time budget to a level and a ratio.

End-to-end time is close to linear in the tets handled (paper Figure 10), but not exactly: per-pixel
work (ray set-up, boundary, samples) does not shrink with the mesh. So instead of one straight line
the model is the measured frame time of every stored level at its own ratio (total, and the part
spent decoding), taken on first use for this file, image size and view (a few seconds) and kept in
the user's cache directory. Between two stored levels, starting from the finer one, decoding costs
what that level costs and rendering is interpolated in the tets left.

Given a budget B, :func:`plan_for_budget` walks the stored levels from the finest: the first level
whose own time fits is taken as is; if it does not fit but can be simplified on the fly far enough
before the next level starts, the finest such ratio is taken (starting from that level).
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


@dataclass(frozen=True)
class LevelSize:
    level: int
    merges: int  # N_i: merges of the full forest applied in this stored level
    tets: int


@dataclass(frozen=True)
class LevelTimes:
    """Measured frame time of every stored level at its own ratio, finest level first."""

    total_s: tuple
    decode_s: tuple  # the part spent decoding (and filtering)

    def predict(self, levels: list[LevelSize], i: int, merges: int) -> float:
        """Frame time starting from stored level ``i`` (finest first) and going to ``merges``."""
        t_i, d_i = self.total_s[i], self.decode_s[i]
        if i + 1 >= len(levels) or merges <= levels[i].merges:
            return t_i
        r_i = t_i - d_i
        r_next = self.total_s[i + 1] - self.decode_s[i + 1]
        span = max(levels[i].tets - levels[i + 1].tets, 1)
        frac = (estimated_tets(levels, merges) - levels[i + 1].tets) / span
        return d_i + r_next + (r_i - r_next) * min(max(frac, 0.0), 1.0)


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


def plan_for_budget(levels: list[LevelSize], model: LevelTimes, budget_s: float, max_merges: int) -> BudgetPlan:
    """The finest simplification whose predicted frame time is within ``budget_s``.

    Examples
    --------
    >>> lv = [LevelSize(0, 0, 1000), LevelSize(1, 50, 500), LevelSize(2, 75, 250)]
    >>> m = LevelTimes((0.21, 0.11, 0.06), (0.05, 0.03, 0.02))
    >>> plan_for_budget(lv, m, 0.2, 80).level          # level 0 needs 0.21 s: simplify it on the fly
    0
    >>> plan_for_budget(lv, m, 0.1, 80).level          # level 1 (0.11 s) too slow at its own ratio
    1
    """
    ls = sorted(levels, key=lambda x: x.merges)
    for i, lv in enumerate(ls):
        t_own = model.predict(ls, i, lv.merges)
        if t_own <= budget_s:
            return BudgetPlan(lv.level, lv.merges, t_own, True)
        end = ls[i + 1].merges if i + 1 < len(ls) else max_merges
        if end <= lv.merges or model.predict(ls, i, end) > budget_s:
            continue
        lo, hi = lv.merges, end  # t(lo) > budget >= t(hi): bisect for the smallest fitting N
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if model.predict(ls, i, mid) <= budget_s:
                hi = mid
            else:
                lo = mid
        return BudgetPlan(lv.level, hi, model.predict(ls, i, hi), True)
    last = len(ls) - 1
    return BudgetPlan(ls[last].level, ls[last].merges, model.predict(ls, last, ls[last].merges), False)


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


def load_model(key: str, n_levels: int | None = None) -> LevelTimes | None:
    """The cached calibration under ``key`` (None if absent, damaged, or for another level count)."""
    try:
        data = json.loads((cache_dir() / "timing.json").read_text())
        model = LevelTimes(tuple(float(x) for x in data[key]["total_s"]),
                           tuple(float(x) for x in data[key]["decode_s"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if len(model.total_s) != len(model.decode_s) or (n_levels is not None and len(model.total_s) != n_levels):
        return None
    return model


def save_model(key: str, model: LevelTimes) -> None:
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


def calibrate(path, view, levels: list[LevelSize], *, repeats: int = 3) -> LevelTimes:
    """Time whole frames (open, decode, render, PNG written) of every stored level, finest first.

    Each level's figure is the median of ``repeats`` warm frames, so the model predicts a typical
    frame, not the luckiest one.
    """
    import statistics
    import tempfile

    from ..render.image import write_png
    from .stream import Target, render_tetc

    ls = sorted(levels, key=lambda x: x.merges)
    totals, decodes = [], []
    with tempfile.TemporaryDirectory(prefix="tetc-calib-") as tmp:
        png = Path(tmp) / "probe.png"
        for lv in ls:
            target = Target(lv.level, lv.merges, 0.0, lv.merges)
            runs = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                res = render_tetc(path, view, target=target)
                write_png(png, res.image, force=True)  # a frame ends with its PNG on disk
                runs.append((time.perf_counter() - t0, res.stats["decode_s"] + res.stats["filter_s"]))
            total = statistics.median(t for t, _ in runs)
            totals.append(total)
            decodes.append(min(runs, key=lambda r: abs(r[0] - total))[1])
    return LevelTimes(tuple(totals), tuple(decodes))


def model_key(path, view) -> str:
    """Calibration key of a file rendered with a view (camera, transfer function, sampling)."""
    tf = view.tf
    tf_key = tf if isinstance(tf, str) else json.dumps(getattr(tf, "__dict__", tf), sort_keys=True, default=str)
    cam = view.camera
    return calibration_key(_file_id(path), (cam.width, cam.height), view.mode,
                           f"{tf_key}|{view.step}|{cam.azimuth}|{cam.elevation}|{cam.zoom}")


def plan_file_budget(path, view, budget_s: float, *, recalibrate: bool = False):
    """(Target, BudgetPlan, LevelTimes, calibrated_now) for rendering ``path`` within ``budget_s``."""
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
    model = None if recalibrate else load_model(key, len(levels))
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
