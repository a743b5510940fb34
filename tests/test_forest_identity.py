"""The merge forests of the samples are the ones stored: a change to the decimator that is meant to
keep the forests bit-identical (speed work, reshaping) is checked here.

``tests/data/forest_hashes.json`` holds, per sample, the sha256 (first 16 hex digits) of the int32
parent and rank arrays and the merge count of ``decimate(mesh)`` with the default weights. Written
by ``python bench/forest_identity.py --meshes post,fire,bluntfin,combustion --out
tests/data/forest_hashes.json``; a change that is meant to change the forests rewrites it, and
says so.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import load_sample
from gatun_py.simplify import decimate

STORED = json.loads((Path(__file__).resolve().parent / "data" / "forest_hashes.json").read_text())


def forest_hash(forest) -> str:
    """sha256 of the forest's int32 parent and rank arrays and its merge count (16 hex digits)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(forest.parent, np.int32).tobytes())
    h.update(np.ascontiguousarray(forest.rank, np.int32).tobytes())
    h.update(str(int(forest.n_merges)).encode())
    return h.hexdigest()[:16]


def test_the_hash_sees_a_changed_rank():
    forest = decimate(load_sample("post")[0], max_merges=50)
    rank = forest.rank.copy()
    i, j = np.flatnonzero(rank < forest.n_merges)[:2]
    rank[i], rank[j] = rank[j], rank[i]
    changed = SimpleNamespace(parent=forest.parent, rank=rank, n_merges=forest.n_merges)
    assert forest_hash(changed) != forest_hash(forest)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(STORED))
def test_forest_is_the_stored_one(name):
    assert forest_hash(decimate(load_sample(name)[0])) == STORED[name]
