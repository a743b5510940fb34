"""Trilinear refinement of PLOT3D grids (scale-test meshes): `plot3d.refine_grid`,
`read_mesh(..., refine=K)` and `tetc convert --refine K`."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cli_util import assert_error, run
from conftest import SAMPLES
from gatun_py.errors import OptionError
from gatun_py.mesh import read_mesh
from gatun_py.mesh.model import signed_volumes
from gatun_py.mesh.plot3d import find_q_file, grid_hexes, read_q, read_xyz, refine_cell_mask, refine_grid
from gatun_py.mesh.split import split_hexes_two_colour


def _naive_refine(xyz, scalar, dims, factor):
    """Point by point: locate the parent cell, evaluate its trilinear map at the local coordinates."""
    ni, nj, nk = dims
    vals = np.concatenate([xyz, scalar[:, None]], axis=1).astype(np.float64).reshape(nk, nj, ni, 4)
    fine = [(d - 1) * factor + 1 if d > 1 else 1 for d in dims]
    out = np.empty((fine[2], fine[1], fine[0], 4))
    for kk in range(fine[2]):
        for jj in range(fine[1]):
            for ii in range(fine[0]):
                cell, loc = [], []
                for m, n in ((ii, ni), (jj, nj), (kk, nk)):
                    c = min(m // factor, max(n - 2, 0))
                    cell.append(c)
                    loc.append((m - c * factor) / factor if n > 1 else 0.0)
                acc = np.zeros(4)
                for dk in (0, 1):
                    for dj in (0, 1):
                        for di in (0, 1):
                            w = ((loc[0] if di else 1 - loc[0]) * (loc[1] if dj else 1 - loc[1])
                                 * (loc[2] if dk else 1 - loc[2]))
                            if w:
                                acc += w * vals[cell[2] + dk, cell[1] + dj, cell[0] + di]
                out[kk, jj, ii] = acc
    flat = out.reshape(-1, 4)
    return flat[:, :3], flat[:, 3], tuple(fine)


def _warped_grid(dims, seed=0):
    """A curvilinear grid: a bent, twisted shell section with random point jitter, i fastest."""
    rng = np.random.default_rng(seed)
    ni, nj, nk = dims
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    r = 1.0 + 0.3 * i
    th = 0.25 * j + 0.05 * k
    xyz = np.stack([r * np.cos(th), r * np.sin(th), 0.4 * k + 0.02 * i * j], -1).reshape(-1, 3)
    xyz = xyz + 0.01 * rng.standard_normal(xyz.shape)
    return xyz.astype(np.float32), rng.random(ni * nj * nk).astype(np.float32)


dims_strategy = st.tuples(st.integers(1, 5), st.integers(1, 5), st.integers(1, 4))


@settings(max_examples=40, deadline=None)
@given(dims=dims_strategy, factor=st.integers(1, 4), seed=st.integers(0, 2**16))
def test_refine_matches_pointwise_trilinear_map_and_keeps_old_points(dims, factor, seed):
    xyz, q = _warped_grid(dims, seed)
    fx, fq, fdims = refine_grid(xyz, q, dims, factor)
    nx, nq, ndims = _naive_refine(xyz, q, dims, factor)
    assert fdims == ndims and fx.dtype == np.float32 and fq.dtype == np.float32
    assert fx.shape == (np.prod(fdims), 3) and fq.shape == (np.prod(fdims),)
    np.testing.assert_allclose(fx, nx, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(fq, nq, rtol=1e-6, atol=1e-6)
    # The original grid is the refined grid at stride K, bit for bit.
    ni, nj, nk = fdims
    s = factor
    old = fx.reshape(nk, nj, ni, 3)[::s, ::s, ::s].reshape(-1, 3)
    assert old.tobytes() == xyz.tobytes()
    assert fq.reshape(nk, nj, ni)[::s, ::s, ::s].reshape(-1).tobytes() == q.tobytes()


def test_factor_one_is_identity():
    xyz, q = _warped_grid((4, 3, 5), 1)
    fx, fq, fdims = refine_grid(xyz, q, (4, 3, 5), 1)
    assert fdims == (4, 3, 5)
    assert fx.tobytes() == xyz.tobytes() and fq.tobytes() == q.tobytes()


@settings(max_examples=25, deadline=None)
@given(factor=st.integers(2, 5), coef=st.lists(st.floats(-4, 4), min_size=8, max_size=8))
def test_trilinear_field_is_reproduced(factor, coef):
    """A field trilinear in the grid's index space (and an affine grid) is interpolated exactly."""
    dims = (4, 3, 3)
    ni, nj, nk = dims

    def field(i, j, k):
        a = coef
        return a[0] + a[1] * i + a[2] * j + a[3] * k + a[4] * i * j + a[5] * j * k + a[6] * i * k + a[7] * i * j * k

    def affine(i, j, k):
        return np.stack([0.5 * i + 0.1 * j, 0.7 * j - 0.2 * k, 1.3 * k + 0.05 * i], -1)

    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    xyz = affine(i, j, k).reshape(-1, 3)
    q = field(i, j, k).reshape(-1)
    fx, fq, (fi, fj, fk) = refine_grid(xyz, q, dims, factor)
    k, j, i = np.meshgrid(np.arange(fk) / factor, np.arange(fj) / factor, np.arange(fi) / factor, indexing="ij")
    want_q = field(i, j, k).reshape(-1).astype(np.float32)
    want_x = affine(i, j, k).reshape(-1, 3).astype(np.float32)
    np.testing.assert_allclose(fq, want_q, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(fx, want_x, rtol=1e-6, atol=1e-6)


def test_bad_arguments():
    xyz, q = _warped_grid((3, 3, 3))
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(OptionError, match="positive integer"):
            refine_grid(xyz, q, (3, 3, 3), bad)
    with pytest.raises(Exception, match="needs"):
        refine_grid(xyz[:-1], q, (3, 3, 3), 2)


def test_cell_mask_follows_parent_cells():
    dims, factor = (4, 3, 3), 2
    keep = np.ones(3 * 2 * 2, bool)
    keep[5] = False
    fine = refine_cell_mask(keep, dims, factor)
    fdims = (7, 5, 5)
    assert fine.shape == (6 * 4 * 4,) and int((~fine).sum()) == factor**3
    # Each sub-cell's parent, from the cell's lowest corner in the fine grid.
    hexes, _ = grid_hexes(fdims)
    c = hexes[:, 0]
    fi, fj, fk = c % 7, (c // 7) % 5, c // 35
    parent = (fk // 2) * 6 + (fj // 2) * 3 + fi // 2
    assert np.array_equal(fine, keep[parent])


def _inverted_and_flat(xyz, dims):
    """Tets of the 5-tet split whose orientation disagrees with the grid's handedness, and flat tets.

    The reference sign of each tet is its sign on the straight lattice (i, j, k) of the same dims.
    """
    hexes, colour = grid_hexes(dims)
    tets = split_hexes_two_colour(hexes, colour)
    ni, nj, nk = dims
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    lattice = np.stack([i, j, k], -1).reshape(-1, 3).astype(np.float64)
    ref = np.sign(signed_volumes(lattice, tets))
    s = np.sign(signed_volumes(xyz, tets))
    agree, disagree = int((s == ref).sum()), int((s == -ref).sum())
    return min(agree, disagree), int((s == 0).sum())


def test_bluntfin_refined_is_a_valid_mesh_without_new_inversions():
    path = SAMPLES / "bluntfin" / "bluntfinxyz.bin"
    factor = 2
    base, base_rep = read_mesh(path)
    mesh, rep = read_mesh(path, refine=factor)  # read_mesh runs validate_tets (conforming, no duplicates)
    assert mesh.n_tets == factor**3 * base.n_tets
    assert mesh.n_points == 79 * 63 * 63
    assert any("refined 2x" in n for n in rep.notes)
    assert rep.zero_volume_tets <= factor**3 * base_rep.zero_volume_tets
    assert mesh.scalar_range[0] >= base.scalar_range[0] and mesh.scalar_range[1] <= base.scalar_range[1]
    grid = read_xyz(path)
    q = read_q(find_q_file(path), grid.dims)
    fx, _, fdims = refine_grid(grid.xyz, q, grid.dims, factor)
    inv0, flat0 = _inverted_and_flat(grid.xyz, grid.dims)
    inv1, flat1 = _inverted_and_flat(fx, fdims)
    assert inv1 <= factor**3 * inv0 and flat1 == rep.zero_volume_tets and flat0 == base_rep.zero_volume_tets


def _write_grid(tmp_path, dims, iblank=None):
    xyz, q = _warped_grid(dims, 3)
    head = np.array(dims, "<i4").tobytes()
    raw = head + np.ascontiguousarray(xyz.T).astype("<f4").tobytes()
    if iblank is not None:
        raw += np.asarray(iblank, "<i4").tobytes()
    (tmp_path / "gxyz.bin").write_bytes(raw)
    qq = np.stack([q + 1.0] * 5).astype("<f4")
    (tmp_path / "gq.bin").write_bytes(head + np.zeros(4, "<f4").tobytes() + qq.tobytes())
    return xyz, q + np.float32(1.0)


def test_read_mesh_refine_with_iblank(tmp_path):
    dims = (4, 4, 3)
    ib = np.ones(48, np.int32)
    ib[0] = 0  # one corner cell blanked
    _write_grid(tmp_path, dims, ib)
    coarse, _ = read_mesh(tmp_path / "gxyz.bin")
    fine, rep = read_mesh(tmp_path / "gxyz.bin", refine=3)
    assert coarse.n_tets == 5 * (3 * 3 * 2 - 1)
    assert fine.n_tets == 27 * coarse.n_tets
    assert any("IBLANK" in n for n in rep.notes)


def test_convert_refine_cli(tmp_path):
    xyz, q = _write_grid(tmp_path, (4, 3, 3))
    out = tmp_path / "fine.vtu"
    res = run("convert", tmp_path / "gxyz.bin", "-o", out, "--refine", 2)
    assert res.exit_code == 0, res.output
    back, _ = read_mesh(out)
    assert back.n_tets == 8 * 5 * 3 * 2 * 2 and back.n_points == 7 * 5 * 5
    assert back.points.reshape(5, 5, 7, 3)[::2, ::2, ::2].reshape(-1, 3).tobytes() == xyz.tobytes()
    assert back.density.reshape(5, 5, 7)[::2, ::2, ::2].reshape(-1).tobytes() == q.tobytes()
    # refining a non-PLOT3D input is an error about that input; a bad factor is a usage error.
    res = run("convert", out, "-o", tmp_path / "again.vtu", "--refine", 2)
    assert res.exit_code == 1 and "refinement needs a PLOT3D grid" in res.output
    res = run("convert", tmp_path / "gxyz.bin", "-o", tmp_path / "x.vtu", "--refine", 0)
    assert res.exit_code == 2
    # Factor 1 on a mesh file is the plain conversion.
    res = run("convert", out, "-o", tmp_path / "same.vtu", "--refine", 1)
    assert res.exit_code == 0, res.output
    with pytest.raises(OptionError, match="PLOT3D"):
        read_mesh(out, refine=2)
    assert_error(run("convert", tmp_path / "missing.bin", "-o", tmp_path / "y.vtu", "--refine", 2), "no such file")
