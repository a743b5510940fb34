"""Format 2: every point array and float64 coordinates come back bit for bit, in their dtypes."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import gatun_py
from conftest import load_sample
from gatun_py.codec.container import VERSION_MAJOR
from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
from gatun_py.codec import _array_kernels as K
from gatun_py.codec.arrays import DTYPES, ArrayDecoder, _lin_state, _range_code, encode_array
from gatun_py.codec.rangecoder import check_decoder, dec_init, dec_state, new_model
from gatun_py.errors import CorruptFileError, MeshError, OptionError
from gatun_py.mesh import TetMesh
from gatun_py.mesh.validate import validate_tets
from meshgen import AWKWARD


def _refs(n, seed=0):
    """Random valid refs: up to three earlier vertices and an apex, or -1."""
    rng = np.random.default_rng(seed)
    refs = np.full((n, 4), -1, np.int32)
    for k in range(1, n):
        m = int(rng.integers(0, min(k, 4) + 1))
        refs[k, :m] = rng.choice(k, m, replace=False)
    return refs


def _decode(data, values, refs, external=None, batch=97, positions=None):
    k = 1 if values.ndim == 1 else values.shape[1]
    dec = ArrayDecoder(data, n_points=len(values), dtype=np.dtype(values.dtype).name, components=k)
    for s in range(0, len(values), batch):
        dec.decode(refs[s:s + batch], None if external is None else external[s:s + batch], positions=positions)
    return dec.finish()


_DTYPES = [np.dtype(d) for d in DTYPES]


@settings(max_examples=120, deadline=None)
@given(st.data())
def test_any_array_round_trips_bit_exactly(data):
    dt = data.draw(st.sampled_from(_DTYPES))
    n = data.draw(st.integers(0, 60))
    k = data.draw(st.sampled_from([None, 1, 3]))
    shape = (n,) if k is None else (n, k)
    if dt.kind == "f":  # any bit pattern: NaN payloads, -0.0, denormals, inf
        bits = data.draw(hnp.arrays(np.dtype(f"u{dt.itemsize}"), shape))
        values = bits.view(dt)
    else:
        values = data.draw(hnp.arrays(dt, shape))
    refs = _refs(n, data.draw(st.integers(0, 9)))
    with np.errstate(over="ignore"):  # float64 beyond float32: inf, as the rounding says
        external = values.astype(np.float32) if dt.kind == "f" and data.draw(st.booleans()) else None
    pos = np.random.default_rng(n).normal(size=(n, 4)).astype(np.float32) if data.draw(st.booleans()) else None
    out = _decode(encode_array(values, refs, external=external, positions=None if pos is None else pos[:, :3]),
                  values, refs, external, positions=pos)
    assert out.dtype == dt and out.shape == ((n,) if k in (None, 1) else (n, k))  # (n, 1) is one component
    assert out.tobytes() == values.tobytes()


def test_every_predictor_round_trips():
    """The encoder picks one predictor per component; each one must invert exactly on its own."""
    rng = np.random.default_rng(3)
    n = 500
    refs = _refs(n)
    o = rng.integers(-2**62, 2**62, n)
    ext = o + rng.integers(-5, 5, n)
    lo, hi = -(1 << 63), (1 << 63) - 1
    pos = rng.normal(size=(n, 4)).astype(np.float32)
    for kind in range(K.N_PREDICTORS):
        e = ext if kind == K.PRED_EXTERNAL else o[:0]
        lin = _lin_state(np.dtype("int64"), 0, pos, np.zeros(n))
        stream = np.frombuffer(_range_code(K.residuals(o, refs, kind, e, lo, hi, lin), refs), np.uint8)
        st = dec_state()
        dec_init(st, stream)
        back = np.zeros(n, np.int64)
        status = K.decode_component(st, stream, new_model(K.MODEL_SIZE), np.zeros(n, np.uint8), back, refs, 0, n,
                                    kind, e, lo, hi, _lin_state(np.dtype("int64"), 0, pos, np.zeros(n)))
        assert status == K.OK and np.array_equal(back, o), kind
        check_decoder(st, stream)


def test_float32_values_in_float64_cost_nothing_extra():
    """A float64 array holding float32 values drops its 29 zero bits; the float32 rounding predicts it."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=2000).astype(np.float32).astype(np.float64)
    refs = _refs(2000)
    assert len(encode_array(v, refs, external=v.astype(np.float32))) < 200
    assert len(encode_array(v, refs)) < 0.6 * v.nbytes


def test_decoder_checks_refs_and_header():
    v = np.arange(10.0)
    refs = _refs(10)
    data = encode_array(v, refs)
    bad = refs.copy()
    bad[5, 0] = 7  # a ref to a vertex not decoded yet
    with pytest.raises(CorruptFileError, match="not yet decoded"):
        _decode(data, v, bad)
    with pytest.raises(CorruptFileError, match="do not match"):
        ArrayDecoder(data, n_points=10, dtype="float32", components=1)
    with pytest.raises(CorruptFileError, match="10 values"):
        ArrayDecoder(data, n_points=11, dtype="float64", components=1)
    with pytest.raises(CorruptFileError):
        ArrayDecoder(data[:-3], n_points=10, dtype="float64", components=1)


def _mesh64(seed=0):
    base = AWKWARD["jittered_grid"]()
    rng = np.random.default_rng(seed)
    n = base.n_points
    pts = base.points.astype(np.float64) + rng.normal(size=(n, 3)) * 1e-9
    pd = {"p": rng.normal(size=n), "T": (300 + rng.random(n)).astype(np.float32), "id": np.arange(n, dtype=np.int64),
          "flag": (rng.random(n) > 0.5), "u": rng.normal(size=(n, 3)), "small": rng.integers(-9, 9, (n, 2)).astype(np.int8)}
    return validate_tets(pts, None, base.tets, scalar_name="p", point_data=pd)[0]


def _same_up_to_order(a: TetMesh, b: TetMesh):
    ka = np.lexsort(a.points.T[::-1])
    kb = np.lexsort(b.points.T[::-1])
    assert a.points.dtype == b.points.dtype and a.points[ka].tobytes() == b.points[kb].tobytes()
    assert list(a.point_data) == list(b.point_data) and a.scalar_name == b.scalar_name
    for name in a.point_data:
        x, y = a.point_data[name], b.point_data[name]
        assert x.dtype == y.dtype and x[ka].tobytes() == y[kb].tobytes(), name
    rank_a = np.empty(a.n_points, np.int64)
    rank_a[ka] = np.arange(a.n_points)
    rank_b = np.empty(b.n_points, np.int64)
    rank_b[kb] = np.arange(b.n_points)
    ta, tb = np.sort(rank_a[a.tets], axis=1), np.sort(rank_b[b.tets], axis=1)
    assert np.array_equal(ta[np.lexsort(ta.T[::-1])], tb[np.lexsort(tb.T[::-1])])


def test_mesh_with_every_kind_of_array_round_trips():
    m = _mesh64()
    data = encode_tetc([LevelPayload(0, 0.0, 0, m)])
    r = TetcReader(data)
    assert r.container.major == VERSION_MAJOR and r.points_dtype == np.float64
    assert [(n, dt.name, k) for n, dt, k in r.arrays] == [
        ("p", "float64", 1), ("T", "float32", 1), ("id", "int64", 1), ("flag", "uint8", 1), ("u", "float64", 3),
        ("small", "int8", 2)]
    back = r.decode_mesh(0)
    expect = TetMesh(m.points, None, m.tets, "p", point_data={**m.point_data, "flag": m.point_data["flag"]})
    _same_up_to_order(expect, back)
    # the stream carries the chosen array as the batches' density
    dens = np.concatenate([b.density for b in r.iter_decode(0, scalar="u", component="magnitude")])
    assert np.array_equal(dens, back.scalar("u", "magnitude").astype(np.float32))
    with pytest.raises(OptionError, match="components"):
        next(r.iter_decode(0, scalar="u"))
    with pytest.raises(OptionError, match="no point array"):
        next(r.iter_decode(0, scalar="nope"))


def test_float32_only_files_have_no_extra_sections():
    mesh = load_sample("post")[0]
    m32 = TetMesh(mesh.points32, mesh.density, mesh.tets, mesh.scalar_name)
    r = TetcReader(encode_tetc([LevelPayload(0, 0.0, 0, m32)]))
    assert sorted(r.container.section_names()) == ["L0/boundary", "L0/geometry", "L0/tets"]


def test_float64_sample_and_levels_keep_every_array(tmp_path):
    """post.vtk with float64 coordinates (not float32 values) and a float64 scalar, through the whole
    compress (forest and levels): level 0 and every level's survivors come back exactly."""
    post = load_sample("post")[0]
    rng = np.random.default_rng(2)
    pts = post.points.astype(np.float64) * (1 + 1e-12 * rng.random((post.n_points, 1)))
    src = TetMesh(pts, None, post.tets, "Pressure",
                  point_data={"Pressure": post.density.astype(np.float64) / 3, "v": rng.normal(size=(post.n_points, 3))})
    f = gatun_py.compress(src, tmp_path / "post.tetc", levels=2)
    assert f.reader.container.has_section("L0/points64")
    _same_up_to_order(src, f.mesh())
    for level in (1, 2):
        m = f.reader.decode_mesh(level)
        assert m.points.dtype == np.float64
        # a level's vertices are input vertices, unchanged
        def rows(mesh):
            return [r.tobytes() for r in np.concatenate([mesh.points, mesh.point_data["Pressure"][:, None],
                                                         mesh.point_data["v"]], axis=1)]
        assert set(rows(m)) <= set(rows(src)) and m.n_points < src.n_points


def test_encoder_validates_before_any_kernel():
    base = AWKWARD["jittered_grid"]()
    for bad, msg in (([[0, 1, 2, base.n_points]], "refers to vertex"), ([[0, 1, 2, -1]], "refers to vertex"),
                     ([[0, 1, 1, 2]], "repeats")):
        m = TetMesh(base.points, base.density, np.concatenate([base.tets, bad]), "d")
        with pytest.raises(MeshError, match=msg):
            encode_tetc([LevelPayload(0, 0.0, 0, m)])
    t = base.tets.copy()
    t[0, [2, 3]] = t[0, [3, 2]]
    with pytest.raises(MeshError, match="negatively oriented"):
        encode_tetc([LevelPayload(0, 0.0, 0, TetMesh(base.points, base.density, t, "d"))])
    with pytest.raises(ValueError, match="32 bits"):
        TetMesh(base.points, base.density, base.tets.astype(np.int64) + 2**32, "d")


def test_cell_data_is_kept_or_dropped_on_request(tmp_path):
    base = AWKWARD["jittered_grid"]()
    m = meshio.Mesh(base.points, [("tetra", base.tets)], point_data={"d": base.density},
                    cell_data={"material": [np.arange(base.n_tets)]})
    gatun_py.compress(m, tmp_path / "a.tetc", mesh_only=True)
    back = meshio.read(tmp_path / "a.tetc")
    assert sorted(back.cell_data["material"][0].tolist()) == list(range(base.n_tets))
    notes = []
    gatun_py.compress(m, tmp_path / "b.tetc", mesh_only=True, drop_cell_data=True, log=notes.append)
    assert any("cell data dropped" in n and "material" in n for n in notes)
    f = gatun_py.compress(m, tmp_path / "c.tetc", mesh_only=True, cell_to_point=True, scalar="d")
    assert [a[0] for a in f.arrays] == ["d", "material"] and f.arrays[1][1] == "float64"


def test_array_ranges_in_the_metadata():
    m = _mesh64()
    r = TetcReader(encode_tetc([LevelPayload(0, 0.0, 0, m)]))
    p = m.point_data["p"]
    assert r.array_range("p") == (p.min(), p.max()) == r.array_range()
    mag = m.scalar("u", "magnitude")
    assert r.array_range("u", "magnitude") == (mag.min(), mag.max())
    assert r.array_range("u", 2) == (m.point_data["u"][:, 2].min(), m.point_data["u"][:, 2].max())
    assert r.array_range("nope") is None


def test_render_any_stored_array(tmp_path):
    """render(scalar=, component=) on a .tetc equals rendering the decoded mesh with that array as scalar."""
    m = _mesh64()
    f = gatun_py.compress(m, tmp_path / "m.tetc", mesh_only=True)
    for pipeline in ("streaming", "generic"):
        a = gatun_py.render(f, size=24, scalar="u", component="magnitude", pipeline=pipeline)
        ref_mesh = f.mesh().with_scalar("u", "magnitude")
        mag = m.scalar("u", "magnitude")
        b = gatun_py.render(ref_mesh, size=24, scalar_range=(mag.min(), mag.max()),
                            step=f.reader.meta["render_step"])
        assert a.stats["scalar"] == "u[magnitude]" and a.stats["scalar_range"] == [mag.min(), mag.max()]
        assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max() <= 1, pipeline
        assert a.rgb.any()
    with pytest.raises(OptionError, match="components"):
        gatun_py.render(f, size=8, scalar="u")
    with pytest.raises(OptionError, match="no point array"):
        gatun_py.render(f, size=8, scalar="nope")
