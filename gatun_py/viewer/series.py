"""The time steps of a series file in the viewer: which step a frame shows, and its batches.

A frame of step ``k`` renders the same levels, forest and cached topology as step 0: the session's
:class:`~gatun_py.viewer.session.CachingReader` gives the target level's batches (from its cache
when the level is small enough, else streamed), and :meth:`SeriesFrames.batches` swaps in step
``k``'s coordinates and scalar, gathered from level 0 through the level's vertex map. Changing
step therefore decodes only that step's arrays (and its coordinates when the mesh moves), never the
mesh or the forest again; decoded steps are kept in a bounded cache (least recently used out
first, step 0 kept).

The budget planner sees a step's decode as a cost of its own: the time to decode the steps a
request still needs (none when cached) is predicted from the last decodes and taken off the
frame's budget before the level is chosen.
"""

from __future__ import annotations

import collections
import time
from dataclasses import replace

import numpy as np

from ..codec.stepreader import StepDecoder
from ..codec.tetcfile import _POINTS
from ..errors import OptionError
from ..mesh.model import scalar_of

__all__ = ["SeriesFrames", "parse_step", "STEP_CACHE_BYTES"]

STEP_CACHE_BYTES = 512 << 20  # decoded steps kept, at most (each: level 0's points and point arrays)
MIN_STEP_CACHE = 2
DECODE_SAMPLES = 8  # seconds per decoded step: the median of the last this many


def parse_step(obj: dict) -> int:
    """The ``"step"`` of a frame request (default 0; negative counts from the end).

    Examples
    --------
    >>> parse_step({"step": 3}), parse_step({})
    (3, 0)
    >>> parse_step({"step": 1.5})
    Traceback (most recent call last):
    ...
    gatun_py.errors.OptionError: 'step' must be a whole number (a time step of the series), got 1.5
    """
    v = obj.get("step", 0)
    if isinstance(v, bool) or not isinstance(v, int):
        raise OptionError(f"'step' must be a whole number (a time step of the series), got {v!r}")
    return v


class SeriesFrames:
    """The steps of the file a :class:`~gatun_py.viewer.session.ViewerSession` holds open.

    Parameters
    ----------
    reader : CachingReader
        The session's reader (step 0's levels, forest and cached batches).
    cache_bytes : int
        Memory the decoded steps may take.
    """

    def __init__(self, reader, *, cache_bytes: int = STEP_CACHE_BYTES):
        self.reader = reader
        self.steps = StepDecoder(reader)
        per_step = int(reader.meta["points"]) * (
            sum(dt.itemsize * c for _, dt, c in reader.arrays) + 3 * reader.points_dtype.itemsize)
        self.steps.cache_steps = max(MIN_STEP_CACHE, cache_bytes // max(per_step, 1))
        self.decode_s = collections.deque(maxlen=DECODE_SAMPLES)

    @property
    def n_steps(self) -> int:
        return self.steps.n_steps

    def info(self) -> dict:
        """What the page's step slider needs: the step count and each step's time."""
        return {"n_steps": self.n_steps, "times": [float(t) for t in self.steps.times]}

    def check(self, step: int) -> int:
        """``step`` as an index; OptionError (the request's fault) when the file has no such step."""
        return self.steps.check_step(step)

    def predict_decode_s(self, step: int) -> float:
        """Predicted seconds to make ``step``'s values ready (0 when cached; before any decode was
        measured, a guess of 0: the first step decoded teaches the model)."""
        todo = [s for s in self.steps.pending(step) if s != 0]  # step 0's values come with the mesh
        if not todo or not self.decode_s:
            return 0.0
        return len(todo) * float(np.median(self.decode_s))

    def values(self, step: int) -> tuple[dict, float]:
        """(step's values in level 0's decode order, seconds spent decoding them now)."""
        todo = [s for s in self.steps.pending(step) if s != 0]
        t0 = time.perf_counter()
        vals = self.steps.values(step)
        spent = time.perf_counter() - t0
        if todo:
            self.decode_s.append(spent / len(todo))
        return vals, spent

    def batches(self, level: int, step: int, *, scalar: str | None = None):
        """The batches of ``level`` (the reader's own, cached or streamed) carrying ``step``'s
        coordinates and scalar (the file's default scalar, or the point array ``scalar``)."""
        vals, _ = self.values(step)
        name = self.reader.scalar_name if scalar is None else scalar
        if name not in vals:
            raise OptionError(f"no point array named {name!r}")
        ids = self.steps.level_map(level)
        points, values = vals[_POINTS], vals[name]
        for batch in self.reader.iter_decode(level):
            k = len(batch.points)
            sel = slice(batch.first, batch.first + k) if ids is None else ids[batch.first:batch.first + k]
            with np.errstate(over="ignore"):
                density = scalar_of({name: values[sel]}, name, None).astype(np.float32)
            yield replace(batch, points=points[sel].astype(np.float32), density=density)
