"""What keeps the isosurface run's memory down must not change a result.

* the decoding thread hands the extraction thread only the tets a surface cuts
  (``extract._SurfaceTets``): exactly those (a plain reference below), counted per chunk, and the
  surface equals the one of an extraction fed every tet;
* LLVM's code pages are handed back (``release_code_pages``): the kernels run on, same results;
* the kernels load ahead of the data (``load_kernels``), from a ``.tetc`` file or a mesh.
"""

from __future__ import annotations

import numpy as np
import pytest

from meshgen import grid_mesh

from gatun_py import _runtime
from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
from gatun_py.contour import extract as iso_extract
from gatun_py.contour import isosurface
from gatun_py.mesh import TetMesh


def _cut_reference(scalar, tets, isos) -> np.ndarray:
    """Plain: a tet is kept when, for some isovalue, its corners are not all on one side (above:
    s >= iso, compared in float64) or one of them equals it."""
    keep = np.zeros(len(tets), bool)
    for t, tet in enumerate(tets):
        s = [float(scalar[v]) for v in tet]
        for iso in isos:
            above = [x >= iso for x in s]
            if any(above) != all(above) or any(x == iso for x in s):
                keep[t] = True
    return keep


@pytest.mark.parametrize("n_isos", [1, 3, 6])  # 6: two groups of four isovalues per vertex byte
def test_surface_tets_are_the_cut_ones_in_chunks(monkeypatch, n_isos):
    monkeypatch.setattr(iso_extract, "CHUNK_TETS", 7)
    rng = np.random.default_rng(n_isos)
    n = 400
    # plateaus of 25 vertices at k / 16: tets inside one are cut only when it lies on an isovalue
    scalar = (np.floor(np.arange(n) / n * 16) / 16).astype(np.float32)
    values = np.zeros((n, 4), np.float32)
    values[:, 3] = scalar
    isos = [np.float64(x) for x in rng.choice(np.arange(1, 8) / 8, n_isos, replace=False)]
    isos[0] = np.float64(0.1)  # one that no float32 scalar equals
    sieve = iso_extract._SurfaceTets(n, isos)
    # batches name ever later vertices, as a stream does: the vertex bytes are filled as they come
    n_kept = n_tets = 0
    for top in (60, 61, 250, 400):
        near = rng.integers(0, top - 8, 53)[:, None] + rng.integers(0, 8, (53, 4))  # tets join nearby vertices
        tets = near.astype(np.int32)
        kept, ends = sieve(values[:, 3], tets)
        keep = _cut_reference(scalar, tets, isos)
        np.testing.assert_array_equal(kept, tets[keep])
        last = np.minimum(np.arange(1, 9) * 7, 53) - 1  # 8 chunks of 7 tets (the last one of 4)
        np.testing.assert_array_equal(ends, np.cumsum(keep)[last])
        n_kept, n_tets = n_kept + len(kept), n_tets + len(tets)
    assert 0 < n_kept < n_tets
    empty, no_ends = sieve(values[:, 3], np.zeros((0, 4), np.int32))
    assert empty.shape == (0, 4) and len(no_ends) == 0


def test_sieve_changes_no_surface(monkeypatch):
    """Rounds mid-stream, several isovalues, iso-valued corners: the surface of the sieved stream
    equals the one of the same stream with every tet handed to the extractor."""
    mesh = grid_mesh(9, 8, 7, jitter=0.2, seed=3)
    dens = np.round(mesh.density * 4) / 4  # corners on the isovalues
    mesh = TetMesh(mesh.points, dens.astype(np.float32), mesh.tets)
    lo, hi = mesh.scalar_range
    values = [lo + 0.5 * (hi - lo), float(np.median(dens)), lo + 0.3 * (hi - lo)]
    monkeypatch.setattr(iso_extract, "CHUNK_TETS", 64)
    kw = dict(values=values, ratio=0.2, batch_faces=40)
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh)])
    sieved = isosurface(TetcReader(data), **kw)

    def every_tet(self, scalar, tets):
        tets = np.ascontiguousarray(tets, dtype=np.int32)
        n = len(tets)
        return tets.copy(), np.minimum(np.arange(1, -(-n // iso_extract.CHUNK_TETS) + 1) * iso_extract.CHUNK_TETS, n)

    monkeypatch.setattr(iso_extract._SurfaceTets, "__call__", every_tet)
    whole = isosurface(TetcReader(data), **kw)
    assert sieved.stats["rounds"] > len(values)  # rounds ran mid-stream
    assert sieved.n_triangles > 0
    np.testing.assert_array_equal(sieved.points, whole.points)
    np.testing.assert_array_equal(sieved.triangles, whole.triangles)
    for name in whole.point_data:
        np.testing.assert_array_equal(sieved.point_data[name], whole.point_data[name])
    assert [b["locked"] for b in sieved.stats["band"]] == [b["locked"] for b in whole.stats["band"]]


def test_code_pages_handed_back_and_kernels_run_on():
    mesh = grid_mesh(6, 6, 6, jitter=0.2, seed=1)
    v = float(np.median(mesh.density))
    before = isosurface(mesh, values=v, ratio=0.3, batch_faces=30)
    _runtime.release_code_pages()
    _runtime.release_code_pages()  # twice: nothing left, nothing breaks
    after = isosurface(mesh, values=v, ratio=0.3, batch_faces=30)
    np.testing.assert_array_equal(before.points, after.points)
    np.testing.assert_array_equal(before.triangles, after.triangles)
    # only read-only mappings without private pages: never the relocated constants or data
    for start, length in _runtime._clean_library_ranges(_runtime._CODE_LIBRARY):
        assert start > 0 and length > 0


def test_load_kernels_from_a_file_a_mesh_or_nothing(tmp_path, monkeypatch):
    mesh = grid_mesh(4, 4, 4, seed=2)
    path = tmp_path / "m.tetc"
    path.write_bytes(encode_tetc([LevelPayload(0, 0.0, 0, mesh)]))
    assert iso_extract.load_kernels(path) > 0.0
    assert iso_extract.load_kernels(mesh, simplify=False) > 0.0
    assert iso_extract.load_kernels(tmp_path / "m.vtu") > 0.0  # a mesh file: no decoder
    monkeypatch.setattr(iso_extract, "TINY_TETC", tmp_path / "missing.tetc")
    assert iso_extract.load_kernels(path) == 0.0  # nothing to load with: kernels load when first used
    lo, hi = mesh.scalar_range
    assert isosurface(path, values=(lo + hi) / 2).n_triangles > 0
