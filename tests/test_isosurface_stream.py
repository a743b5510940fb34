"""The isosurface stream's plumbing: the prefetching decoder, chunked boundaries, the in-flight queue.

None of these may change a result: the prefetched stream must equal ``iter_decode`` batch for batch
(and fail the same way on damage), and the extractor's output must not depend on how a batch is cut
into steps or how far the decoder runs ahead.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from meshgen import grid_mesh

from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
from gatun_py.codec.prefetch import iter_decode_prefetched
from gatun_py.errors import CorruptFileError
from gatun_py.contour import extract as iso_extract
from gatun_py.contour import isosurface
from gatun_py.mesh import TetMesh


def _tetc(mesh) -> bytes:
    return encode_tetc([LevelPayload(0, 0.0, 0, mesh)])


def _with_unused_vertices(mesh, k=3):
    """The mesh plus k vertices no tet references (the stream's last batch carries them)."""
    pts = np.concatenate([mesh.points, mesh.points[:k] + 0.5]).astype(np.float32)
    dens = np.concatenate([mesh.density, np.arange(k, dtype=np.float32)])
    return TetMesh(pts, dens, mesh.tets)


def _same_batches(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.first == y.first
        for name in ("points", "density", "boundary", "tets"):
            assert np.array_equal(getattr(x, name), getattr(y, name)), name


@pytest.mark.parametrize("batch_tets", [1, 7, 64, 100_000])
@pytest.mark.parametrize("unused", [0, 3])
def test_prefetched_stream_equals_iter_decode(batch_tets, unused):
    mesh = grid_mesh(6, 5, 4, jitter=0.2, seed=3)
    if unused:
        mesh = _with_unused_vertices(mesh, unused)
    data = _tetc(mesh)
    ref = list(TetcReader(data).iter_decode(0, batch_tets=batch_tets))
    got = list(iter_decode_prefetched(TetcReader(data), 0, batch_tets=batch_tets, depth=2))
    _same_batches(got, ref)
    assert sum(len(b.tets) for b in got) == mesh.n_tets
    assert sum(len(b.points) for b in got) == mesh.n_points


def _threads() -> set:
    return {t for t in threading.enumerate() if t.name == "tetc-connectivity"}


@pytest.mark.parametrize("section", ["L0/tets", "L0/boundary", "L0/geometry"])
def test_prefetched_stream_raises_damage_in_the_caller_and_stops(section):
    mesh = grid_mesh(7, 6, 5, jitter=0.2, seed=5)
    reader = TetcReader(_tetc(mesh))
    raw = bytearray(reader.read_section(section))
    failures = 0
    for pos in range(len(raw) // 4, len(raw), max(1, len(raw) // 12)):
        bad = bytearray(raw)
        bad[pos] ^= 0xA5
        r = TetcReader(_tetc(mesh))
        # the container checks CRCs, so feed the damaged code to the reader as if it were stored
        r.read_section = lambda name, _bad=bytes(bad), _r=r, _orig=r.read_section: (
            _bad if name == section else _orig(name))
        try:
            ref_error = None
            list(r.iter_decode(0, batch_tets=16))
        except CorruptFileError as e:
            ref_error = e
        try:
            list(iter_decode_prefetched(r, 0, batch_tets=16))
            got_error = None
        except CorruptFileError as e:
            got_error = e
        assert (ref_error is None) == (got_error is None)
        failures += got_error is not None
        assert not _threads()  # the producer thread never outlives the stream
    assert failures  # some of the damage was caught


def test_prefetched_stream_closed_early_stops_its_thread():
    mesh = grid_mesh(8, 8, 6, jitter=0.2, seed=7)
    gen = iter_decode_prefetched(TetcReader(_tetc(mesh)), 0, batch_tets=8, depth=1)
    next(gen)
    next(gen)  # the producer is now running (and blocked on the full queue)
    assert _threads()
    gen.close()
    assert not _threads()


def _surface_bytes(s):
    return (s.points.tobytes(), s.triangles.tobytes(), {k: v.tobytes() for k, v in s.point_data.items()},
            s.stats["faces_extracted"], s.stats["collapses"])


@pytest.mark.parametrize("ratio", [None, 0.2])
def test_output_does_not_depend_on_boundary_chunks_or_queue_depth(monkeypatch, ratio):
    mesh = grid_mesh(12, 10, 8, jitter=0.25, seed=11)
    data = _tetc(mesh)
    v = float(np.quantile(mesh.density, 0.4))
    ref = _surface_bytes(isosurface(TetcReader(data), values=v, ratio=ratio, batch_faces=150))
    monkeypatch.setattr(iso_extract, "BOUNDARY_CHUNK", 5)
    monkeypatch.setattr(iso_extract, "MAX_IN_FLIGHT", 0)
    assert _surface_bytes(isosurface(TetcReader(data), values=v, ratio=ratio, batch_faces=150)) == ref


def test_tables_scale_with_the_band_not_the_boundary(monkeypatch):
    """A batch carrying a large boundary no longer reserves hash slots for all of it at once."""
    mesh = grid_mesh(30, 30, 4, jitter=0.1, seed=2)  # a flat slab: many boundary faces
    first = next(iter(TetcReader(_tetc(mesh)).iter_decode(0)))
    nb = len(first.boundary)
    monkeypatch.setattr(iso_extract, "BOUNDARY_CHUNK", 64)
    ex = iso_extract._Extractor(float(np.median(mesh.density)), ratio=None, faces=None, batch_faces=10**6,
                                importance=None, grad_scale=1.0)
    vals = np.empty((mesh.n_points, 4), np.float32)
    vals[:len(first.points), :3] = first.points
    vals[:len(first.points), 3] = first.density
    ex.add(vals, first.tets, first.boundary, 0)
    border = int(ex.sizes[0])  # boundary faces that touch the surface
    assert border < nb / 4
    # room for what is in the table plus one chunk's worst case, not for every boundary face
    assert len(ex.ftab) <= iso_extract._pow2(4 * (2 * border + 64))
    assert len(ex.ftab) < 4 * nb


def test_tetc_stream_lends_its_values_and_gives_the_mesh_files_surface():
    """The .tetc path reads vertices from the decoder's array (no copy); the surface must equal the
    one from the same mesh fed as an in-memory stream, which fills an array of our own."""
    from gatun_py.codec.prefetch import PrefetchedDecode

    mesh = grid_mesh(9, 8, 7, jitter=0.25, seed=4)
    reader = TetcReader(_tetc(mesh))
    stream = PrefetchedDecode(reader)
    batches = iter(stream)
    first = next(batches)
    assert stream.values is not None and np.shares_memory(first.points, stream.values)
    batches.close()
    decoded = reader.decode_mesh(0)  # the stream's vertex and tet order
    v = float(np.quantile(mesh.density, 0.6))
    for ratio in (None, 0.3):
        a = isosurface(TetcReader(_tetc(mesh)), values=v, ratio=ratio, batch_faces=100)
        b = isosurface(decoded, values=v, ratio=ratio, batch_faces=100)
        assert a.n_triangles == b.n_triangles > 0
        if ratio is None:
            assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)


def test_an_extraction_does_not_load_scipy_linalg_and_blas_still_works():
    """numba's array library loads without its BLAS probe (scipy.linalg and its OpenBLAS stay out of
    the process: time and memory), and jitted np.dot still finds BLAS afterwards. In a fresh
    interpreter: this one has loaded numba's library long ago."""
    import subprocess
    import sys

    code = """if True:
        import sys
        import numpy as np
        from gatun_py.contour import isosurface
        from gatun_py.warmup import SHIPPED_TETC
        from gatun_py.codec import TetcReader
        lo, hi = TetcReader(SHIPPED_TETC).meta["scalar_range"]
        s = isosurface(SHIPPED_TETC, values=(lo + hi) / 2, ratio=0.5)
        assert s.n_triangles > 0
        assert "scipy.linalg" not in sys.modules, "scipy.linalg loaded"
        from numba import njit
        dot = njit(lambda a, b: np.dot(a, b))
        assert dot(np.arange(3.0), np.ones(3)) == 3.0
        print("ok")
    """
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "ok"
