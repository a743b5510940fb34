"""The brick index of a bricked ``.tetc`` file and the view of one brick as a file of its own.

A file written with K > 1 bricks (format 3) has a metadata key ``"bricks"``: per brick its
``bounds`` ([lo, hi] of its points), ``points``, ``tets``, ``cut_points`` (vertices it shares with
other bricks) and ``levels`` (the level list a one-brick file keeps at the top level). Every section
of brick k is named ``B{k}/`` + the name it would have in a one-brick file. :class:`BrickView`
presents brick k to :class:`~gatun_py.codec.tetcfile.TetcReader` as a container whose sections drop
the prefix and whose metadata is the file's with the brick's entry in place of the index, so a
brick is read by exactly the code that reads a whole file.

This module checks the index against itself and the section table before anything is decoded; a
disagreement is a :class:`~gatun_py.errors.CorruptFileError`.
"""

from __future__ import annotations

import math
import re

from ..errors import CorruptFileError

__all__ = ["BRICKS_KEY", "MAX_BRICKS", "BrickView", "brick_prefix", "parse_brick_index", "brick_levels_summary"]

BRICKS_KEY = "bricks"
MAX_BRICKS = 4096  # as gatun_py.mesh.partition.MAX_BRICKS (the codec does not import the mesh partition)
# sections every stored level of a brick must have (the one-brick layout) plus the brick's cut list
LEVEL_SECTIONS = ("boundary", "tets", "geometry", "cut")
# keys of a brick's entry that describe the brick itself rather than override the file's metadata
_OWN_KEYS = ("bounds", "cut_points")
_BRICK_NAME = re.compile(r"B(\d+)/")


def brick_prefix(k: int) -> str:
    """The section-name prefix of brick ``k``: ``"B{k}/"``."""
    return f"B{int(k)}/"


def _count(entry: dict, key: str, k: int, hi: int = 2**31 - 1) -> int:
    v = entry.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or not 0 <= v <= hi:
        raise CorruptFileError(f"corrupt brick index: brick {k} has a bad {key!r}")
    return v


def _bounds(entry: dict, k: int) -> list:
    b = entry.get("bounds")
    ok = (isinstance(b, list) and len(b) == 2 and all(isinstance(r, list) and len(r) == 3 for r in b)
          and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for r in b for x in r))
    if not ok or any(lo > hi for lo, hi in zip(*b)):
        raise CorruptFileError(f"corrupt brick index: brick {k} has bad bounds")
    return [[float(x) for x in b[0]], [float(x) for x in b[1]]]


def parse_brick_index(meta: dict, container) -> list[dict]:
    """The metadata of every brick (what a one-brick file of that brick would hold), checked.

    Returns ``[]`` for a file without a brick index (a one-brick file). Raises
    :class:`CorruptFileError` when the index is malformed, its counts disagree with the file's
    totals, a brick misses a section of a level it lists, or a section belongs to no brick.
    """
    if BRICKS_KEY not in meta:
        return []
    if container.major < 3:
        raise CorruptFileError("corrupt metadata: a brick index in a file older than format 3")
    entries = meta[BRICKS_KEY]
    if not isinstance(entries, list) or not 2 <= len(entries) <= MAX_BRICKS:
        raise CorruptFileError(f"corrupt brick index: expected a list of 2..{MAX_BRICKS} bricks")
    if "levels" in meta:
        raise CorruptFileError("corrupt metadata: a bricked file keeps its levels in its bricks")
    base = {key: v for key, v in meta.items() if key not in (BRICKS_KEY, "sections", "cut_points")}
    out, tets, points, cut = [], 0, 0, 0
    for k, e in enumerate(entries):
        if not isinstance(e, dict):
            raise CorruptFileError(f"corrupt brick index: brick {k} is not an object")
        bounds = _bounds(e, k)
        n = _count(e, "points", k)
        tets += _count(e, "tets", k)
        cut += _count(e, "cut_points", k, n)
        points += n
        levels = e.get("levels")
        if not isinstance(levels, list) or not levels or not all(isinstance(lv, dict) for lv in levels):
            raise CorruptFileError(f"corrupt brick index: brick {k} lists no levels")
        prefix = brick_prefix(k)
        for lv in levels:
            i = lv.get("level")
            if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i <= 64:
                raise CorruptFileError(f"corrupt brick index: brick {k} has a bad level number")
            for part in LEVEL_SECTIONS:
                if not container.has_section(f"{prefix}L{i}/{part}"):
                    raise CorruptFileError(f"corrupt file: brick {k} lists level {i} but section "
                                           f"{prefix}L{i}/{part!s} is missing")
        sub = dict(base)
        sub.update({key: v for key, v in e.items() if key not in _OWN_KEYS})
        sub["bbox"] = bounds
        sub["brick"] = k
        sub["brick_bounds"] = bounds
        sub["brick_cut_points"] = e["cut_points"]
        out.append(sub)
    total_points, total_tets = meta.get("points"), meta.get("tets")
    total_cut = meta.get("cut_points")
    if tets != total_tets:
        raise CorruptFileError(f"corrupt brick index: the bricks hold {tets} tets, the file {total_tets}")
    if not isinstance(total_cut, int) or isinstance(total_cut, bool) or not 0 <= total_cut <= cut // 2:
        raise CorruptFileError("corrupt brick index: bad 'cut_points' (each cut vertex is in two bricks or more)")
    if not isinstance(total_points, int) or points - cut + total_cut != total_points:
        raise CorruptFileError(f"corrupt brick index: the bricks' points ({points}, {cut} of them shared as "
                               f"{total_cut} cut vertices) do not add up to the file's {total_points}")
    for name in container.section_names():
        m = _BRICK_NAME.match(name)
        if m is None or int(m.group(1)) >= len(entries):
            raise CorruptFileError(f"corrupt file: section {name!r} belongs to no brick of the index")
    return out


_SUMMED = ("merges_before", "points", "tets", "boundary_faces", "boundary_vertices", "referenced_points")


def brick_levels_summary(brick_metas: list[dict]) -> list[dict]:
    """The levels every brick stores, each with the counts of a level entry summed over the bricks
    (a shared vertex counts once per brick, cut faces are boundary faces of both bricks) and the
    ratio of the summed merges to the summed points."""
    common = set.intersection(*({lv.get("level") for lv in b["levels"]} for b in brick_metas))
    n0 = sum(int(b["points"]) for b in brick_metas)
    out = []
    for i in sorted(common):
        per = [next(lv for lv in b["levels"] if lv.get("level") == i) for b in brick_metas]
        sums = {}
        for key in _SUMMED:
            vals = [lv.get(key, 0) for lv in per]
            if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in vals):
                raise CorruptFileError(f"corrupt brick index: bad {key!r} in level {i}")
            sums[key] = sum(vals)
        out.append({"level": i, "ratio": min(1.0, sums["merges_before"] / n0) if n0 else 0.0, **sums})
    if not out:
        raise CorruptFileError("corrupt brick index: no level is stored by every brick")
    return out


class BrickView:
    """Brick ``k`` of a container, seen as a container of its own.

    Section names lose the ``B{k}/`` prefix; ``meta`` is the brick's (see
    :func:`parse_brick_index`). Everything else (version, file name, size) is the file's.
    """

    def __init__(self, container, k: int, meta: dict):
        self._c = container
        self.prefix = brick_prefix(k)
        self.meta = meta
        self.major = container.major
        self.size = container.size
        self.name = f"{container.name}[brick {k}]"

    def __repr__(self) -> str:
        return f"BrickView({self.name!r})"

    def section_names(self) -> list[str]:
        p = self.prefix
        return [n[len(p):] for n in self._c.section_names() if n.startswith(p)]

    def has_section(self, name: str) -> bool:
        return self._c.has_section(self.prefix + name)

    def section_size(self, name: str) -> int:
        return self._c.section_size(self.prefix + name)

    def read_section_head(self, name: str, n: int) -> bytes:
        return self._c.read_section_head(self.prefix + name, n)

    def read_section(self, name: str) -> bytes:
        return self._c.read_section(self.prefix + name)
