"""Compress with levels encoded in threads (and level 0 beside the decimation): the same bytes as
one level after the other, on one thread."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from conftest import load_sample

import gatun_py
from gatun_py import api
from gatun_py.codec import LevelPayload, encode_tetc
from gatun_py.codec.tetcfile import encode_level
from gatun_py.errors import MeshError, OptionError
from gatun_py.mesh import TetMesh
from gatun_py.simplify import (ROOT_RANK, available_levels, build_levels, decimate, level_merges, next_level,
                               storage_forests)


def _payload(mesh):
    forest = decimate(mesh)
    levels = build_levels(mesh, forest)
    return [LevelPayload(x.level, x.ratio, x.n_merges, x.mesh, (f.parent, f.rank))
            for x, f in zip(levels, storage_forests(levels))]


@pytest.mark.parametrize("name", ["post", "fire"])
def test_threads_and_a_pre_encoded_level_give_the_same_bytes(name):
    mesh = load_sample(name)[0]
    payload = _payload(mesh)
    assert len(payload) > 3
    one = encode_tetc(payload, source=name)
    assert encode_tetc(payload, source=name, threads=2) == one
    assert encode_tetc(payload, source=name, threads=3) == one
    pre = {0: encode_level(LevelPayload(0, 0.0, 0, mesh)), 2: encode_level(LevelPayload(2, 0.0, 0, payload[2].mesh))}
    done = []
    assert encode_tetc(payload, source=name, threads=2, mesh_codes=pre, progress=done.append) == one
    assert done == [p.level for p in payload]  # in level order
    assert encode_tetc(payload, source=name, mesh_codes=pre) == one


def test_a_pre_encoded_level_of_another_mesh_is_refused():
    mesh = load_sample("post")[0]
    payload = _payload(mesh)
    pre = {0: encode_level(LevelPayload(0, 0.0, 0, payload[1].mesh))}
    with pytest.raises(OptionError, match="level 0"):
        encode_tetc(payload, mesh_codes=pre)
    with_forest = {1: encode_level(payload[1])}
    with pytest.raises(OptionError, match="level 1"):
        encode_tetc(payload, mesh_codes=with_forest)


def test_compress_bytes_do_not_depend_on_jobs(tmp_path):
    mesh = load_sample("fire")[0]
    digests = set()
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}.tetc"
        f = gatun_py.compress(mesh, out, jobs=jobs)
        assert f.n_points == mesh.n_points and len(f.reader.levels) > 3
        digests.add(hashlib.sha256(out.read_bytes()).hexdigest())
    assert len(digests) == 1
    with pytest.raises(OptionError, match="jobs"):
        gatun_py.compress(mesh, tmp_path / "bad.tetc", jobs=0)
    assert not (tmp_path / "bad.tetc").exists()
    assert np.isfinite(mesh.points).all()


def test_a_failing_level_in_a_thread_raises_its_error():
    mesh = load_sample("post")[0]
    payload = _payload(mesh)
    bad = payload[3]
    tets = bad.mesh.tets.copy()
    tets[0, 0] = bad.mesh.n_points + 5  # an id out of range: check_mesh refuses it in the level's thread
    payload[3] = LevelPayload(bad.level, bad.ratio, bad.merges_before,
                              TetMesh(bad.mesh.points, None, tets, bad.mesh.scalar_name,
                                      point_data=dict(bad.mesh.point_data)), bad.forest)
    with pytest.raises(MeshError):
        encode_tetc(payload, threads=2)


@pytest.mark.parametrize("name", ["post", "fire", "combustion"])
def test_levels_built_from_forest_prefixes_during_the_decimation_are_the_levels(name):
    # decimate hands on_level a prefix as each level's merges are done; the chain of levels built
    # from those prefixes (what compress encodes beside the decimation) is build_levels' own
    mesh = load_sample(name)[0]
    heard = []
    forest = decimate(mesh, on_level=lambda i, prefix: heard.append((i, prefix)))
    final = build_levels(mesh, forest)
    assert [i for i, _ in heard][:len(final) - 1] == [x.level for x in final[1:]]
    prev = None
    for (i, prefix), want in zip(heard, final[1:]):
        assert prefix.n_merges == want.n_merges  # the merges so far, no more
        assert (prefix.rank[prefix.rank != ROOT_RANK] < prefix.n_merges).all()
        got = next_level(mesh, prefix, i, prev)
        prev = got
        assert got.n_merges == want.n_merges and got.ratio == want.ratio
        assert np.array_equal(got.mesh.tets, want.mesh.tets)
        assert np.array_equal(got.vertex_ids, want.vertex_ids)
        assert got.mesh.points.tobytes() == want.mesh.points.tobytes()
        for k, a in want.mesh.point_data.items():
            assert got.mesh.point_data[k].tobytes() == a.tobytes()
    # the forest itself does not depend on being heard
    again = decimate(mesh)
    assert np.array_equal(again.parent, forest.parent) and np.array_equal(again.rank, forest.rank)


def test_plain_order_also_reports_levels_and_keeps_its_forest():
    mesh = load_sample("post")[0]
    heard = []
    forest = decimate(mesh, rounds=0, on_level=lambda i, prefix: heard.append((i, prefix.n_merges)))
    plain = decimate(mesh, rounds=0)
    assert np.array_equal(plain.parent, forest.parent) and np.array_equal(plain.rank, forest.rank)
    reach = available_levels(forest, 62)[1:]
    assert [i for i, _ in heard][:len(reach)] == reach
    assert all(n == level_merges(mesh.n_points, i) for i, n in heard)


def test_compress_encodes_every_level_beside_the_decimation(tmp_path, monkeypatch):
    mesh = load_sample("fire")[0]
    used = []
    codes = api._LevelsBeside.codes

    def spy(self, levels):
        out = codes(self, levels)
        used.append((sorted(out), [x.level for x in levels]))
        return out

    monkeypatch.setattr(api._LevelsBeside, "codes", spy)
    two = gatun_py.compress(mesh, tmp_path / "two.tetc", jobs=2)
    assert used and used[0][0] == used[0][1] and len(used[0][0]) > 4  # every level came from beside, level 0 too
    gatun_py.compress(mesh, tmp_path / "one.tetc", jobs=1)
    assert used[1][0] == []  # one thread: nothing beside
    assert (tmp_path / "two.tetc").read_bytes() == (tmp_path / "one.tetc").read_bytes()
    assert len(two.reader.levels) == len(used[0][1])
    used.clear()
    gatun_py.compress(mesh, tmp_path / "l2.tetc", jobs=2, levels=2)
    assert used[0][0] == used[0][1] == [0, 1, 2]
