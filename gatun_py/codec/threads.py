"""Threads of the codec: how many a call may use, and a producer thread running a stream ahead.

A level decodes in two stages that depend on each other only through each batch's new-vertex
refs: the connectivity decoder writes them, the geometry decoder reads them, and both kernels
release the GIL. :class:`RunAhead` runs the first stage (any iterator) in a thread of its own up
to ``depth`` items ahead of the caller, which runs the second: on two cores a decode then costs
about the slower stage instead of the sum of both.
"""

from __future__ import annotations

import os
import queue
import threading
from typing import Iterable, Iterator

import numpy as np

from ..errors import OptionError


def default_jobs() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs) -> int:
    """``jobs`` as a positive int (None: all cores)."""
    if jobs is None:
        return default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise OptionError(f"jobs must be a positive integer, got {jobs!r}")
    return int(jobs)


_DONE = object()


class _Failed:
    """What the producer hands over instead of an item when its iterator raised."""

    def __init__(self, error: BaseException):
        self.error = error


class RunAhead:
    """Iterate ``items`` in a producer thread at most ``depth`` items ahead of the caller.

    A context manager: entering starts the thread, leaving (normally, on an error of the caller,
    or when a generator holding it is closed early) stops it and waits for it. Iterating yields
    the items in order; an exception of the producer's iterator is raised in the iterating thread
    at the point of the stream where it occurred, after the items before it. An item must not be
    changed by the producer once handed over (copy what the iterator rewrites).

    Examples
    --------
    >>> with RunAhead(iter(range(5)), depth=2) as ahead:
    ...     [x * x for x in ahead]
    [0, 1, 4, 9, 16]
    >>> def broken():
    ...     yield 1
    ...     raise ValueError("damaged")
    >>> with RunAhead(broken(), depth=1) as ahead:
    ...     out = []
    ...     try:
    ...         for x in ahead:
    ...             out.append(x)
    ...     except ValueError as e:
    ...         out.append(str(e))
    >>> out
    [1, 'damaged']
    """

    def __init__(self, items: Iterable, *, depth: int = 4, name: str = "tetc-run-ahead"):
        self._items = items
        self._handoff = queue.Queue(maxsize=max(1, int(depth)))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._produce, name=name, daemon=True)

    def __repr__(self) -> str:
        state = "running" if self._thread.is_alive() else "idle"
        return f"<RunAhead {self._thread.name}: {state}, {self._handoff.qsize()} item(s) waiting>"

    def _put(self, item) -> bool:
        """Hand ``item`` over, waiting for room; False once the consumer has stopped the stream."""
        while not self._stop.is_set():
            try:
                self._handoff.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def _produce(self) -> None:
        try:
            for item in self._items:
                if not self._put(item):
                    return
            self._put(_DONE)
        except BaseException as e:  # handed to the consumer, which raises it
            self._put(_Failed(e))

    def __enter__(self) -> "RunAhead":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def __iter__(self) -> Iterator:
        while True:
            item = self._handoff.get()
            if item is _DONE:
                return
            if isinstance(item, _Failed):
                raise item.error
            yield item
