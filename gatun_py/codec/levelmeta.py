"""A stored level's metadata as a typed record: what the file's JSON says about one level.

The metadata of a ``.tetc`` file lists its levels (``meta["levels"]``; a bricked file's are the sums
over its bricks, :func:`~.brickindex.brick_levels_summary`), each a JSON object with the counts the
decoder needs. :meth:`LevelMeta.from_json` checks one such object once and gives its fields typed;
:meth:`LevelMeta.to_json` gives back the same object, keys in the same order, so a file rewritten
from records has the same bytes. The record reads as a mapping too (``lv["points"]``,
``lv.get("ratio", 0.0)``): callers that took the JSON objects keep working.

Examples
--------
>>> lv = LevelMeta.from_json({"level": 1, "ratio": 0.5, "merges_before": 3, "points": 4, "tets": 1,
...                           "boundary_faces": 4, "boundary_vertices": 4, "referenced_points": 4})
>>> lv.points, lv.has_forest, lv["ratio"]
(4, False, 0.5)
>>> lv.to_json()["merges_before"]
3
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field

from ..errors import CorruptFileError

_MAX_COUNT = 2**31 - 1
_COUNTS = ("points", "tets", "boundary_faces")


def _count(d: dict, key: str, lo: int = 0, hi: int = _MAX_COUNT) -> int:
    v = d.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise CorruptFileError(f"corrupt metadata: bad {key!r}")
    return v


@dataclass(frozen=True, eq=False)
class LevelMeta(Mapping):
    """One stored level (see the module docstring).

    Attributes
    ----------
    level : int
        The level's number (0: the full mesh).
    points, tets, boundary_faces, boundary_vertices, referenced_points : int
        The decoder's counts.
    ratio : float
        The share of the forest's merges applied before this level (0.0 when not given).
    merges_before : int
        Merges applied before this level (0 when not given).
    has_forest : bool
        Whether the level stores the forest of its remaining merges.
    """

    level: int
    points: int
    tets: int
    boundary_faces: int
    boundary_vertices: int
    referenced_points: int
    ratio: float = 0.0
    merges_before: int = 0
    has_forest: bool = False
    _json: dict = field(default_factory=dict, repr=False)  # the object as read: keys, order, the rest

    @classmethod
    def from_json(cls, d) -> LevelMeta:
        """The record of one level's JSON object; :class:`~gatun_py.errors.CorruptFileError` if a
        count, the level number or the ratio is missing or out of range."""
        if not isinstance(d, dict):
            raise CorruptFileError("corrupt metadata: bad level entry")
        level = _count(d, "level", 0, 64)
        n = _count(d, "points")
        tets, faces = _count(d, "tets"), _count(d, "boundary_faces")
        bv, ref = _count(d, "boundary_vertices", 0, n), _count(d, "referenced_points", 0, n)
        merges = _count(d, "merges_before") if "merges_before" in d else 0
        ratio = d.get("ratio", 0.0)
        if not isinstance(ratio, (int, float)) or isinstance(ratio, bool) or not 0.0 <= ratio <= 1.0:
            raise CorruptFileError("corrupt metadata: bad level ratio")
        return cls(level, n, tets, faces, bv, ref, ratio, merges, bool(d.get("has_forest", False)), dict(d))

    def to_json(self) -> dict:
        """The level's JSON object: the one read, with this record's fields (same keys, same order)."""
        out = dict(self._json)
        for f in dataclasses.fields(self):
            if f.name in out:
                out[f.name] = getattr(self, f.name)
        return out

    # read as the JSON object it came from
    def __getitem__(self, key):
        if key in self._json and key in _FIELDS:
            return getattr(self, key)
        return self._json[key]

    def __iter__(self):
        return iter(self._json)

    def __len__(self):
        return len(self._json)

    def __eq__(self, other):
        if isinstance(other, Mapping):
            return self.to_json() == dict(other)
        return NotImplemented

    __hash__ = None


_FIELDS = frozenset(f.name for f in dataclasses.fields(LevelMeta))
