"""The level record: it gives back the JSON it was read from (same keys, same order, same bytes), reads
as that JSON's mapping, and refuses a bad level entry with the reader's message."""

import json
from pathlib import Path

import pytest

from gatun_py.codec import LevelMeta, TetcReader
from gatun_py.errors import CorruptFileError

DATA = Path(__file__).resolve().parent / "data"
GOLDEN = sorted(DATA.glob("*.tetc"))


def _dumps(x) -> bytes:
    return json.dumps(x, separators=(",", ":"), sort_keys=False).encode()


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
def test_golden_levels_round_trip_to_the_same_json(path):
    r = TetcReader(path)
    raw = r.meta["levels"]
    assert _dumps([lv.to_json() for lv in r.levels]) == _dumps(raw)
    for lv, d in zip(r.levels, raw):
        assert isinstance(lv, LevelMeta)
        assert dict(lv) == d and lv == d and list(lv) == list(d)
        assert (lv.level, lv.points, lv.tets, lv.boundary_faces) == (d["level"], d["points"], d["tets"],
                                                                    d["boundary_faces"])
        assert lv.merges_before == d.get("merges_before", 0) and lv.ratio == d.get("ratio", 0.0)
        assert lv.has_forest == bool(d.get("has_forest", False))
        assert r.level_meta(lv.level) is lv


def test_golden_files_cover_old_and_new_formats():
    names = {p.name for p in GOLDEN}
    assert {"post_v1.tetc", "post_v10.tetc"} <= names


GOOD = {"level": 0, "ratio": 0.0, "merges_before": 0, "points": 5, "tets": 2, "boundary_faces": 6,
        "boundary_vertices": 5, "referenced_points": 5, "bbox": [[0, 0, 0], [1, 1, 1]], "has_forest": True}


def test_missing_optional_keys_stay_missing():
    d = {k: v for k, v in GOOD.items() if k not in ("ratio", "merges_before", "has_forest")}
    lv = LevelMeta.from_json(d)
    assert (lv.ratio, lv.merges_before, lv.has_forest) == (0.0, 0, False)
    assert "ratio" not in lv and lv.get("ratio") is None
    assert _dumps(lv.to_json()) == _dumps(d)
    assert lv["bbox"] == [[0, 0, 0], [1, 1, 1]]


@pytest.mark.parametrize("key,value,message", [
    ("points", -1, "bad 'points'"), ("tets", True, "bad 'tets'"), ("level", 65, "bad 'level'"),
    ("boundary_vertices", 6, "bad 'boundary_vertices'"), ("referenced_points", "5", "bad 'referenced_points'"),
    ("merges_before", 1.5, "bad 'merges_before'"), ("ratio", 1.5, "bad level ratio"),
    ("ratio", False, "bad level ratio"),
])
def test_bad_entries_are_refused(key, value, message):
    with pytest.raises(CorruptFileError, match=message):
        LevelMeta.from_json({**GOOD, key: value})


def test_not_an_object_is_refused():
    with pytest.raises(CorruptFileError, match="bad level entry"):
        LevelMeta.from_json([1, 2])


def test_records_are_frozen():
    lv = LevelMeta.from_json(GOOD)
    with pytest.raises(AttributeError):
        lv.points = 3
