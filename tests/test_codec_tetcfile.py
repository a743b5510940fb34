"""The .tetc container and the streaming decoder: lossless files, batch guarantees, damaged files."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_sample
from gatun_py.codec import LevelPayload, TetcReader, decode_mesh, encode_tetc, iter_decode, write_tetc
from gatun_py.codec.container import MAGIC, PREAMBLE_SIZE, Container, build_container
from gatun_py.codec.cutborder import encode_connectivity
from gatun_py.errors import CorruptFileError, FormatVersionError, OptionError, OutputError, TetcError
from gatun_py.mesh import TetMesh
from gatun_py.mesh.validate import validate_tets
from meshgen import AWKWARD, mesh_strategy
from naive_codec import canonical_tets


def _bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def assert_lossless(mesh: TetMesh, decoded: TetMesh):
    vo = encode_connectivity(mesh.n_points, mesh.tets).vertex_order
    assert decoded.n_points == mesh.n_points and decoded.n_tets == mesh.n_tets
    assert np.array_equal(_bits(decoded.points), _bits(mesh.points[vo]))
    assert np.array_equal(_bits(decoded.density), _bits(mesh.density[vo]))
    assert canonical_tets(vo[decoded.tets]) == canonical_tets(mesh.tets)
    assert decoded.scalar_name == mesh.scalar_name


@pytest.mark.parametrize("name", ["post", "fire", "bluntfin", "combustion"])
def test_samples_round_trip_bit_for_bit(name):
    mesh = load_sample(name)[0]
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh)], source=name)
    assert_lossless(mesh, decode_mesh(data))


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_awkward_round_trip(name):
    mesh = AWKWARD[name]()
    assert_lossless(mesh, decode_mesh(encode_tetc([LevelPayload(0, 0.0, 0, mesh)])))


@settings(max_examples=100, deadline=None)
@given(mesh_strategy())
def test_random_meshes_round_trip(mesh):
    assert_lossless(mesh, decode_mesh(encode_tetc([LevelPayload(0, 0.0, 0, mesh)])))


def test_special_floats_and_coincident_points():
    mesh = AWKWARD["jittered_grid"]()
    pts = mesh.points.copy()
    dens = mesh.density.copy()
    pts[1] = pts[0]  # coincident vertices
    pts[2, 0] = -0.0
    dens[3] = np.float32(1e-42)  # denormal
    dens[4] = np.float32(-3.4e38)
    m, _ = validate_tets(pts, dens, mesh.tets, scalar_name="rho")  # moving vertex 1 inverts tets: re-orient
    assert_lossless(m, decode_mesh(encode_tetc([LevelPayload(0, 0.0, 0, m)])))


def _check_batches(data, mesh, batch_tets):
    batches = list(iter_decode(data, batch_tets=batch_tets))
    known = 0
    seen_tets = False
    for i, b in enumerate(batches):
        assert b.first == known
        assert b.points.shape == (len(b.points), 3) and b.points.dtype == np.float32
        assert b.density.shape == (len(b.points),) and b.density.dtype == np.float32
        assert b.boundary.dtype == np.int32 and b.tets.dtype == np.int32
        known += len(b.points)
        if len(b.boundary):
            assert not seen_tets and i == 0  # the whole boundary comes first
            assert b.boundary.max() < known
        if len(b.tets):
            seen_tets = True
            assert b.tets.max() < known and len(b.tets) <= batch_tets
    assert known == mesh.n_points
    assert sum(len(b.tets) for b in batches) == mesh.n_tets
    assert sum(len(b.boundary) for b in batches) == len(mesh.boundary_faces())
    return batches


def test_batches_obey_the_decode_batch_guarantees(small_sample):
    data = encode_tetc([LevelPayload(0, 0.0, 0, small_sample)])
    batches = _check_batches(data, small_sample, 1000)
    assert len(batches) >= small_sample.n_tets // 1000


def test_unreferenced_vertices_come_last():
    mesh = AWKWARD["unreferenced"]()
    batches = _check_batches(encode_tetc([LevelPayload(0, 0.0, 0, mesh)]), mesh, 7)
    last = batches[-1]
    assert len(last.tets) == 0 and len(last.points) == 3


def test_levels_and_forest_sections(tmp_path):
    mesh = AWKWARD["delaunay"]()
    n = mesh.n_points
    parent = np.arange(n, dtype=np.int32)
    rank = np.full(n, 2**31 - 1, dtype=np.int32)
    parent[5], rank[5] = 6, 0  # one merge 5 -> 6
    levels = [LevelPayload(0, 0.0, 0, mesh, (parent, rank)), LevelPayload(1, 0.5, 1, AWKWARD["single_tet"]())]
    path = tmp_path / "m.tetc"
    write_tetc(path, levels, source="x/y.vtu")
    r = TetcReader(path)
    assert [lv["level"] for lv in r.levels] == [0, 1]
    assert r.meta["source"] == "y.vtu" and r.meta["points"] == n
    assert_lossless(AWKWARD["single_tet"](), r.decode_mesh(1))
    fp, fr = r.read_forest(0)
    vo = encode_connectivity(n, mesh.tets).vertex_order
    k = int(np.flatnonzero(vo == 5)[0])
    assert vo[fp[k]] == 6 and fr[k] == 0 and np.sum(fr != 2**31 - 1) == 1
    assert r.read_forest(1) is None
    # the forest's decode kept level 0's connectivity: decode_mesh takes it over (copied into its array)
    assert r._decoded[0] == 0
    assert np.array_equal(r.decode_mesh(0).tets, TetcReader(path).decode_mesh(0).tets)
    assert r._decoded is None
    with pytest.raises(OptionError):
        r.decode_mesh(2)
    with pytest.raises(OutputError):
        write_tetc(path, mesh)


def test_reader_seeks_only_the_level_it_needs(tmp_path):
    path = tmp_path / "m.tetc"
    write_tetc(path, [LevelPayload(0, 0.0, 0, AWKWARD["cavity"]()), LevelPayload(1, 0.5, 0, AWKWARD["single_tet"]())])
    data = bytearray(path.read_bytes())
    r = TetcReader(bytes(data))
    off, length, _ = r.container.index["L0/tets"]
    data[off + length // 2] ^= 0xFF  # damage level 0 only
    r = TetcReader(bytes(data))
    r.decode_mesh(1)
    with pytest.raises(CorruptFileError):
        r.decode_mesh(0)


@pytest.fixture(scope="module")
def post_levels():
    """LOX post with 4 levels of its decimation (format 8: the levels' value tables chain)."""
    from gatun_py.simplify import build_levels, decimate

    mesh = load_sample("post")[0]
    return encode_tetc([LevelPayload(x.level, x.ratio, x.n_merges, x.mesh)
                        for x in build_levels(mesh, decimate(mesh), 4)])


def test_one_reader_decodes_chained_levels_in_any_order(post_levels):
    """A reader keeps the coarser levels' tables it decoded for the next decodes: any order of
    levels gives what a fresh reader gives for each."""
    from gatun_py.codec.geometry import chained_channels

    r = TetcReader(post_levels)
    n = len(r.levels)
    assert chained_channels(r.read_section("L0/geometry"))  # the chain is there to test
    fresh = [TetcReader(post_levels).decode_mesh(lv) for lv in range(n)]
    for lv in [1, 0, n - 1, 2, 0, 1]:
        m = r.decode_mesh(lv)
        assert np.array_equal(m.points.view(np.int32), fresh[lv].points.view(np.int32))
        assert np.array_equal(m.density.view(np.int32), fresh[lv].density.view(np.int32))
        assert np.array_equal(m.tets, fresh[lv].tets)
    assert {lv for lv, _ in r._value_tables} == set(range(1, n))  # level 0's tables are no one's base


@pytest.mark.parametrize("major", [7, 8])
def test_a_newer_geometry_coding_in_an_older_format_is_refused(post_levels, major):
    """Geometry coding 5 comes with format 9 (coding 4 with 8): a file that says 7 or 8 and holds
    it is damaged."""
    from gatun_py.codec.container import split_container

    data = bytearray(build_container(*split_container(post_levels)))
    struct.pack_into("<H", data, 8, major)
    with pytest.raises(CorruptFileError, match=f"coding 5 in a file of format {major}"):
        TetcReader(bytes(data)).decode_mesh(0)


@pytest.fixture(scope="module")
def post_file():
    return encode_tetc([LevelPayload(0, 0.0, 0, load_sample("post")[0])], source="post.vtk")


def _must_fail(data):
    # decode_mesh reads every section of the level (the exact arrays too), iter_decode only the stream's
    with pytest.raises(CorruptFileError):
        TetcReader(bytes(data)).decode_mesh(0)


def test_truncation_at_100_points(post_file):
    for cut in np.linspace(0, len(post_file) - 1, 100).astype(int):
        _must_fail(post_file[:cut])


def test_1000_random_byte_flips(post_file):
    rng = np.random.default_rng(1234)
    for _ in range(1000):
        data = bytearray(post_file)
        pos = int(rng.integers(0, len(data)))
        data[pos] ^= int(rng.integers(1, 256))
        _must_fail(data)


def test_not_a_tetc_file_and_newer_version(post_file):
    with pytest.raises(CorruptFileError, match="not a .tetc"):
        TetcReader(b"solid ascii stl\n" * 4)
    newer = bytearray(post_file)
    struct.pack_into("<H", newer, 8, 99)
    with pytest.raises(FormatVersionError, match="newer"):
        TetcReader(bytes(newer))


def _with_meta(meta, sections):
    return build_container(meta, sections)


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_fuzzed_headers_and_lengths(data):
    """Rewritten metadata (valid CRC) with absurd counts or index entries: always a clean error."""
    base = TetcReader(encode_tetc([LevelPayload(0, 0.0, 0, AWKWARD["two_components"]())]))
    meta = json.loads(json.dumps(base.meta))
    sections = [(name, base.read_section(name)) for name in base.container.section_names()]
    lv = meta["levels"][0]
    key = data.draw(st.sampled_from(["points", "tets", "boundary_faces", "boundary_vertices", "referenced_points"]))
    lv[key] = data.draw(st.one_of(st.integers(-5, 2**40), st.just(lv[key] + 1), st.just(lv[key] - 1),
                                  st.text(max_size=3), st.none()))
    blob = _with_meta({k: v for k, v in meta.items() if k != "sections"}, sections)
    try:
        list(iter_decode(blob))
    except CorruptFileError:
        return
    # only a harmless change may decode: the counts must then be what the file holds
    assert lv[key] == base.levels[0][key]


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**64 - 1), st.integers(0, 40), st.binary(min_size=1, max_size=8))
def test_fuzzed_raw_header_bytes(seed, pos, junk):
    base = bytearray(encode_tetc([LevelPayload(0, 0.0, 0, AWKWARD["single_tet"]())]))
    end = min(len(base), pos + len(junk))
    base[pos:end] = junk[: end - pos]
    try:
        list(iter_decode(bytes(base)))
    except CorruptFileError:
        pass


def test_absurd_lengths_rejected_before_allocation():
    pre = struct.pack("<8sHHII", MAGIC, 1, 0, 2**31, 0)
    with pytest.raises(CorruptFileError):
        Container(pre + b"{}")
    entry = {"name": "L0/tets", "offset": PREAMBLE_SIZE + 200, "length": 2**60, "crc32": 0}
    meta = {"format": "tetc", "sections": [entry]}
    blob = json.dumps(meta).encode()
    with pytest.raises(CorruptFileError, match="outside the file"):
        Container(struct.pack("<8sHHII", MAGIC, 1, 0, len(blob), zlib.crc32(blob)) + blob + bytes(300))


def test_deeply_nested_metadata_is_rejected():
    blob = b"[" * 100_000 + b"]" * 100_000
    with pytest.raises(CorruptFileError, match="JSON"):
        Container(struct.pack("<8sHHII", MAGIC, 1, 0, len(blob), zlib.crc32(blob)) + blob)


def test_missing_file_is_a_read_error(tmp_path):
    with pytest.raises(TetcError, match="no such file"):
        TetcReader(tmp_path / "nope.tetc")
