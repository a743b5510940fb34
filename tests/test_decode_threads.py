"""decode_mesh on two threads (the connectivity run ahead of the geometry): the same mesh as on one,
bit for bit, for every kind of file; errors of either thread raised in the caller, the thread gone."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

import gatun_py
from conftest import SAMPLE_FILES, load_sample
from gatun_py.codec import LevelPayload, TetcReader, decode_mesh, encode_tetc
from gatun_py.codec.bricks import brick_jobs, decode_bricked
from gatun_py.codec.container import build_container, split_container
from gatun_py.codec.cutborder import ConnectivityDecoder
from gatun_py.codec.prefetch import PrefetchedDecode
from gatun_py.codec.threads import RunAhead, check_jobs
from gatun_py.errors import CorruptFileError, OptionError
from meshgen import AWKWARD
from test_codec_arrays import _mesh64

GOLDEN = sorted((Path(__file__).parent / "data").glob("post_v*.tetc"))


def _runners() -> set:
    """Names of the producer threads alive now."""
    return {t.name for t in threading.enumerate() if t.name.startswith("tetc-")}


def assert_identical(a, b):
    """Same mesh bit for bit: dtypes, vertex and tet order, every point array."""
    assert a.points.dtype == b.points.dtype and a.points.tobytes() == b.points.tobytes()
    assert a.density.tobytes() == b.density.tobytes()
    assert a.tets.dtype == b.tets.dtype and np.array_equal(a.tets, b.tets)
    assert a.scalar_name == b.scalar_name and list(a.point_data) == list(b.point_data)
    for name in a.point_data:
        x, y = a.point_data[name], b.point_data[name]
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name


@pytest.mark.parametrize("name", sorted(SAMPLE_FILES))
def test_every_sample_decodes_the_same_on_two_threads(name):
    data = encode_tetc([LevelPayload(0, 0.0, 0, load_sample(name)[0])], source=name)
    one = decode_mesh(data, jobs=1)
    assert_identical(one, decode_mesh(data, jobs=2))
    assert_identical(one, decode_mesh(data))  # the default: all cores
    assert one.n_tets == load_sample(name)[0].n_tets


@pytest.mark.parametrize("name", sorted(AWKWARD))
def test_awkward_meshes_decode_the_same_on_two_threads(name):
    """Unreferenced vertices, no tets, one tet, several components: every shape of stream."""
    data = encode_tetc([LevelPayload(0, 0.0, 0, AWKWARD[name]())])
    assert_identical(decode_mesh(data, jobs=1), decode_mesh(data, jobs=2))


def test_float64_and_every_kind_of_array_on_two_threads():
    data = encode_tetc([LevelPayload(0, 0.0, 0, _mesh64())])
    r = TetcReader(data)
    assert r.points_dtype == np.float64 and len(r.arrays) > 4
    one = r.decode_mesh(0, jobs=1)
    assert one.points.dtype == np.float64
    assert_identical(one, TetcReader(data).decode_mesh(0, jobs=2))


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.stem)
def test_every_format_and_level_decodes_the_same_on_two_threads(path):
    """Formats 1..7 (the golden files), every level: the forest codings that decode the level
    first hand their decode over to the threaded path."""
    r = TetcReader(path)
    for lv in r.levels:
        one = TetcReader(path).decode_mesh(lv["level"], jobs=1)
        assert_identical(one, TetcReader(path).decode_mesh(lv["level"], jobs=2))
        r2 = TetcReader(path)
        if r2.read_forest(lv["level"]) is not None:  # keeps its decode of the level for the next
            assert_identical(one, r2.decode_mesh(lv["level"], jobs=2))


def test_bricked_files_and_the_file_verbs(tmp_path):
    m = load_sample("post")[0]
    f = gatun_py.compress(m, tmp_path / "b.tetc", bricks=3, jobs=1)
    one = decode_bricked(f.reader, jobs=1)
    assert_identical(one, decode_bricked(f.reader, jobs=2))
    assert_identical(one, f.mesh(jobs=2))
    assert_identical(f.mesh(ratio=0.3, jobs=1), f.mesh(ratio=0.3, jobs=2))
    plain = gatun_py.compress(m, tmp_path / "p.tetc", jobs=1)
    assert_identical(plain.mesh(jobs=1), plain.mesh(jobs=2))
    assert_identical(plain.mesh(ratio=0.5, jobs=1), plain.mesh(ratio=0.5, jobs=2))
    assert brick_jobs(2, 3) == 1 and brick_jobs(4, 2) == 2 and brick_jobs(1, 1) == 1


def test_tets_are_decoded_into_the_meshs_array(monkeypatch):
    """No extra copy of the tets: each batch is decoded straight into the mesh's own array."""
    outs = []
    real = ConnectivityDecoder.next_tets

    def watched(self, max_tets, *, out=None):
        outs.append(out)
        return real(self, max_tets, out=out)

    monkeypatch.setattr(ConnectivityDecoder, "next_tets", watched)
    data = encode_tetc([LevelPayload(0, 0.0, 0, load_sample("post")[0])])
    mesh = TetcReader(data).decode_mesh(jobs=2)
    assert outs and all(o is not None and np.shares_memory(o, mesh.tets) for o in outs)


def test_jobs_is_checked():
    data = encode_tetc([LevelPayload(0, 0.0, 0, AWKWARD["single_tet"]())])
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(OptionError, match="jobs"):
            TetcReader(data).decode_mesh(jobs=bad)
    assert check_jobs(None) >= 1


def _damaged(data: bytes, section: str, pos: float) -> bytes:
    """``data`` with one byte of ``section`` flipped at fraction ``pos`` of it, CRC rewritten."""
    meta, sections = split_container(data)
    out = []
    for name, payload in sections:
        if name == section:
            p = bytearray(payload)
            p[int(pos * (len(p) - 1))] ^= 0x5A
            payload = bytes(p)
        out.append((name, payload))
    return build_container(meta, out)


@pytest.fixture(scope="module")
def combustion_file():
    return encode_tetc([LevelPayload(0, 0.0, 0, load_sample("combustion")[0])])


def _outcome(data: bytes, jobs: int):
    """The decoded mesh, or the type of error raised."""
    try:
        return TetcReader(data).decode_mesh(jobs=jobs)
    except Exception as e:  # noqa: BLE001 - compared by type below
        return type(e)


@pytest.mark.parametrize("section", ["L0/tets", "L0/boundary", "L0/geometry"])
@pytest.mark.parametrize("pos", [0.0, 0.3, 0.6])
def test_damage_in_either_thread_is_raised_here_and_stops_the_thread(combustion_file, section, pos):
    """A damaged connectivity stream fails in the producer thread, a damaged geometry in the caller's:
    both raise CorruptFileError here, as on one thread, and leave no thread behind."""
    before = _runners()
    data = _damaged(combustion_file, section, pos)
    for jobs in (1, 2):
        with pytest.raises(CorruptFileError):
            TetcReader(data).decode_mesh(jobs=jobs)
        assert _runners() == before


def test_1000_byte_flips_fail_the_same_on_two_threads():
    """Damage anywhere in the file (CRC not rewritten: the container's check) or in a section's
    payload (CRC rewritten: the decoders' checks): with the connectivity on its own thread, the
    same clean error as on one (or, for a flip no decoder can see, the same mesh)."""
    data = encode_tetc([LevelPayload(0, 0.0, 0, load_sample("post")[0])])
    names = [name for name, _ in split_container(data)[1]]
    rng = np.random.default_rng(12)
    before = _runners()
    for i in range(1000):
        if i % 2:
            d = bytearray(data)
            d[int(rng.integers(0, len(d)))] ^= int(rng.integers(1, 256))
            d = bytes(d)
        else:
            d = _damaged(data, names[int(rng.integers(0, len(names)))], float(rng.random()))
        one, two = _outcome(d, 1), _outcome(d, 2)
        if isinstance(one, type):  # an error: the same one on two threads, and a clean one
            assert one is two is CorruptFileError
        else:  # a flip no code can see (the CRC's job, rewritten here): the same mesh both ways
            assert_identical(one, two)
    assert _runners() == before


def _batches(stream):
    return [(b.first, b.points.tobytes(), b.density.tobytes(), np.asarray(b.tets).tobytes(),
             np.asarray(b.boundary).tobytes()) for b in stream]


@pytest.mark.parametrize("scalar", [None, "T", "id"])
def test_iter_decode_on_two_threads_gives_the_same_batches(scalar):
    """The stream a (not lean) render reads with a second core: every batch as on one thread, for
    the default scalar and for other point arrays (decoded beside the geometry)."""
    data = encode_tetc([LevelPayload(0, 0.0, 0, _mesh64())])
    one = _batches(TetcReader(data).iter_decode(0, scalar=scalar, batch_tets=25, jobs=1))
    two = _batches(TetcReader(data).iter_decode(0, scalar=scalar, batch_tets=25, jobs=2, depth=2))
    assert len(one) > 3 and one == two
    with pytest.raises(OptionError):
        next(TetcReader(data).iter_decode(0, jobs=0))


def test_a_stream_closed_early_stops_its_thread():
    data = encode_tetc([LevelPayload(0, 0.0, 0, load_sample("bluntfin")[0])])
    before = _runners()
    stream = iter(PrefetchedDecode(TetcReader(data), batch_tets=500, depth=2))
    next(stream)
    next(stream)
    assert _runners() - before == {"tetc-connectivity"}
    stream.close()
    assert _runners() == before


def test_run_ahead_keeps_order_and_raises_at_the_point_of_failure():
    def items(fail_at):
        for i in range(50):
            if i == fail_at:
                raise ValueError(f"broken at {i}")
            yield i

    for depth in (1, 3, 100):
        with RunAhead(items(-1), depth=depth) as ahead:
            assert list(ahead) == list(range(50))
        got = []
        with pytest.raises(ValueError, match="broken at 17"):
            with RunAhead(items(17), depth=depth) as ahead:
                for x in ahead:
                    got.append(x)
        assert got == list(range(17))


def test_run_ahead_stops_a_producer_waiting_for_room():
    produced = []

    def endless():
        i = 0
        while True:
            produced.append(i)
            yield i
            i += 1

    with RunAhead(endless(), depth=2, name="tetc-test") as ahead:
        it = iter(ahead)
        assert [next(it) for _ in range(5)] == list(range(5))
    assert "tetc-test" not in _runners()
    assert len(produced) <= 5 + 2 + 1  # at most depth items ahead, and the one waiting for room
