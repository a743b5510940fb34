"""Format 8: point-array components that repeat another array's are stored once, as references
(the ``copies`` of the metadata's ``arrays``), and come back bit for bit."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gatun_py
from conftest import load_sample
from gatun_py.codec import LevelPayload, TetcReader, encode_tetc
from gatun_py.codec.container import build_container, split_container
from gatun_py.codec.tetcfile import find_copies
from gatun_py.errors import CorruptFileError
from gatun_py.mesh.validate import validate_tets
from meshgen import grid_mesh
from samples import SAMPLE_DIR

FIRE = str(SAMPLE_DIR / "room_fire" / "fire_ug.vtu")


def _bits_equal(a, b) -> bool:
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


def _check_round_trip(mesh, data, batch_tets=7):
    """Every array of level 0 bit for bit through decode_mesh (both thread counts) and iter_decode."""
    r = TetcReader(data)
    for jobs in (1, 2):
        m = r.decode_mesh(0, jobs=jobs)
        # decode order differs from the input's: match vertices through their float64 coordinates
        order = np.lexsort(m.points.T[::-1])
        ref = np.lexsort(mesh.points.astype(m.points.dtype).T[::-1])
        assert _bits_equal(m.points[order], mesh.points.astype(m.points.dtype)[ref])
        for name in mesh.point_data:
            assert _bits_equal(m.point_data[name][order], mesh.point_data[name][ref]), name
    m = r.decode_mesh(0, jobs=1)
    for name, _, k in r.arrays:
        for c in [None] if k == 1 else range(k):
            got = np.concatenate([b.density for b in r.iter_decode(0, scalar=name, component=c, batch_tets=batch_tets)])
            want = m.point_data[name] if c is None else m.point_data[name][:, c]
            with np.errstate(over="ignore"):
                assert _bits_equal(got, want.astype(np.float32)), (name, c)
    return r


def _synthetic(scalar_dtype=np.float32):
    base = grid_mesh(5, 4, 4, jitter=0.2, seed=2)
    n = base.n_points
    rng = np.random.default_rng(3)
    pts = base.points.astype(np.float64) * 1.1
    vec = rng.normal(size=(n, 3))
    ids = rng.integers(-5, 5, size=(n, 2)).astype(np.int32)
    near = vec[:, 1].copy()
    near[n // 2] = np.nextafter(near[n // 2], np.inf)  # one value off: not a copy
    negz = np.zeros(n)
    negz[3] = -0.0  # -0.0 is not 0.0 bit for bit
    pd = {
        "rho": base.density.astype(scalar_dtype),
        "vec": vec,
        "vx": vec[:, 0].copy(),  # one component of a vector, as a scalar
        "vec_again": vec.copy(),  # a whole vector copied
        "mixed": np.stack([rng.normal(size=n), vec[:, 2], near], axis=1),  # one copied component
        "near": near,  # a copy of mixed[2], which is not a copy itself
        "rho_copy": base.density.astype(scalar_dtype),  # the default scalar's values
        "rho_other": base.density.astype(np.float64 if scalar_dtype == np.float32 else np.float32),
        "ids": ids,
        "id1": ids[:, 1].copy(),  # an int array's component
        "zeros": np.zeros(n),
        "negz": negz,
    }
    mesh, _ = validate_tets(pts, None, base.tets, scalar_name="rho", point_data=pd)
    return mesh


@pytest.mark.parametrize("scalar_dtype", [np.float32, np.float64])
def test_synthetic_copies_round_trip(scalar_dtype):
    mesh = _synthetic(scalar_dtype)
    names = [a[0] for a in mesh.arrays]
    j = names.index
    got = {(names[a], c): (names[k], kc) for a, c, k, kc in find_copies(mesh)}
    assert got == {("vx", 0): ("vec", 0), ("vec_again", 0): ("vec", 0), ("vec_again", 1): ("vec", 1),
                   ("vec_again", 2): ("vec", 2), ("mixed", 1): ("vec", 2), ("near", 0): ("mixed", 2),
                   ("rho_copy", 0): ("rho", 0), ("id1", 0): ("ids", 1)}
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh)])
    meta, sections = split_container(data)
    present = {name for name, _ in sections}
    for name in ("vx", "vec_again", "rho_copy", "id1", "near"):  # every component a copy: no section
        assert f"L0/array/{j(name)}" not in present
    for name in ("vec", "mixed", "rho_other", "ids", "zeros", "negz"):
        assert f"L0/array/{j(name)}" in present
    assert meta["arrays"][j("mixed")]["copies"] == [[1, j("vec"), 2]]
    assert "copies" not in meta["arrays"][j("negz")]
    plain = encode_tetc([LevelPayload(0, 0.0, 0, mesh, copies=())])  # ignored: encode_tetc decides
    assert plain == data
    # the caller's find_copies (compress passes the one it already has) writes the same file
    assert encode_tetc([LevelPayload(0, 0.0, 0, mesh)], copies=find_copies(mesh)) == data
    _check_round_trip(mesh, data)


def _column(a, c):
    return a if a.ndim == 1 else a[:, c]


@pytest.mark.slow  # 25 files with levels
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_any_repeats_round_trip(data):
    """Arrays drawn as fresh columns, copies of earlier ones, or copies one value off: find_copies
    finds exactly the bit-equal columns (earlier ones or the scalar's), and the file round-trips."""
    base = grid_mesh(3, 3, 3, seed=4)
    n = base.n_points
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16)))
    pool = {np.dtype("f8"): [], np.dtype("i4"): [], np.dtype("f4"): [base.density]}
    pd = {}
    for a in range(data.draw(st.integers(1, 5))):
        dt = data.draw(st.sampled_from(sorted(pool, key=str)))
        cols = []
        for _ in range(data.draw(st.sampled_from([1, 2, 3]))):
            how = data.draw(st.sampled_from(["fresh", "copy", "near"])) if pool[dt] else "fresh"
            if how == "fresh":
                col = rng.normal(size=n).astype(dt) if dt.kind == "f" else rng.integers(-3, 3, n).astype(dt)
            else:
                col = data.draw(st.sampled_from(pool[dt])).copy()
                if how == "near":
                    col[int(rng.integers(n))] += 1
            pool[dt].append(col)
            cols.append(col)
        pd[f"a{a}"] = cols[0] if len(cols) == 1 else np.stack(cols, axis=1)
    mesh, _ = validate_tets(base.points, base.density, base.tets, scalar_name="d", point_data=pd)
    copies = find_copies(mesh)
    arrays = list(mesh.arrays)
    s = [a[0] for a in arrays].index("d")
    copied = {(j, c) for j, c, _, _ in copies}
    coded = [(s, 0)]
    for j, c, k, kc in copies:
        assert (k < j or k == s) and (k, kc) not in copied and j != s
        assert _bits_equal(_column(mesh.point_data[arrays[j][0]], c), _column(mesh.point_data[arrays[k][0]], kc))
    for j, (name, dt, k) in enumerate(arrays):
        if j == s:
            continue
        own = [c for c in range(k) if (j, c) not in copied]
        for c in own:  # none repeats an earlier array's coded column (its own array's may)
            col = _column(mesh.point_data[name], c)
            assert not any(_bits_equal(col, _column(mesh.point_data[arrays[kk][0]], kc)) for kk, kc in coded)
        coded += [(j, c) for c in own]
    _check_round_trip(mesh, encode_tetc([LevelPayload(0, 0.0, 0, mesh)]))


def test_copies_of_the_default_scalar_in_a_vector():
    """A vector one of whose components is the (float32) default scalar: filled from the geometry."""
    base = grid_mesh(4, 4, 3, seed=1)
    n = base.n_points
    vec = np.stack([np.arange(n, dtype=np.float32), base.density, np.ones(n, np.float32)], axis=1)
    mesh, _ = validate_tets(base.points, base.density, base.tets, scalar_name="d", point_data={"vec": vec})
    names = [a[0] for a in mesh.arrays]
    assert find_copies(mesh) == ((names.index("vec"), 1, names.index("d"), 0),)
    data = encode_tetc([LevelPayload(0, 0.0, 0, mesh)])
    _check_round_trip(mesh, data)


@pytest.mark.slow  # a real sample, every level
def test_fire_with_levels_every_level_bit_exact(tmp_path):
    """Room fire's u, v, w are uvw's components: stored once, and every level decodes them equal to
    their sources and to level 0's values (a coarser level's vertices are level 0's)."""
    out = tmp_path / "fire.tetc"
    gatun_py.compress(FIRE, out, levels=3, scalar="t")
    r = TetcReader(str(out))
    names = [a[0] for a in r.arrays]
    assert {names[j]: rows for j, rows in r.copies.items()} == {
        "u": [(0, names.index("uvw"), 0)], "v": [(0, names.index("uvw"), 1)], "w": [(0, names.index("uvw"), 2)]}
    mesh = load_sample("fire")[0]
    _check_round_trip(mesh, out.read_bytes(), batch_tets=4096)
    full = r.decode_mesh(0)
    key0 = {p.tobytes(): i for i, p in enumerate(full.points)}
    for lv in r.levels[1:]:
        m = r.decode_mesh(lv["level"], jobs=2)
        idx = np.array([key0[p.tobytes()] for p in m.points])
        for name in names:
            assert _bits_equal(m.point_data[name], full.point_data[name][idx]), (lv["level"], name)
        u = np.concatenate([b.density for b in r.iter_decode(lv["level"], scalar="u")])
        assert _bits_equal(u, m.point_data["uvw"][:, 0])
    rows = {row["name"]: row for row in gatun_py.info(str(out))["arrays"]}
    assert rows["u"]["copies"] == "u = uvw[0]" and rows["u"]["bytes"] == 0
    assert "copies" not in rows["uvw"]
    for selective in (False, True):  # the render paths that read one array: u is uvw[0]
        u = gatun_py.render(str(out), size=32, scalar="u", ratio=0.5, selective=selective)
        uvw0 = gatun_py.render(str(out), size=32, scalar="uvw", component=0, ratio=0.5, selective=selective)
        assert np.array_equal(u.rgb, uvw0.rgb) and np.asarray(u.rgb).any()


# -- hostile metadata --------------------------------------------------------------------------

def _copy_file():
    mesh = _synthetic()
    return mesh, encode_tetc([LevelPayload(0, 0.0, 0, mesh)])


def _with_copies(data, j, rows, *, major=None):
    meta, sections = split_container(data)
    meta = json.loads(json.dumps(meta))
    if rows is None:
        meta["arrays"][j].pop("copies", None)
    else:
        meta["arrays"][j]["copies"] = rows
    out = bytearray(build_container(meta, sections))
    if major is not None:
        out[8:10] = int(major).to_bytes(2, "little")
    return bytes(out)


@functools.lru_cache(1)
def _bad_copy_cases():
    mesh, data = _copy_file()
    names = [a[0] for a in mesh.arrays]
    j = names.index
    return data, {
        "missing array": _with_copies(data, j("vx"), [[0, 99, 0]]),
        "negative array": _with_copies(data, j("vx"), [[0, -1, 0]]),
        "missing source component": _with_copies(data, j("vx"), [[0, j("vec"), 3]]),
        "missing own component": _with_copies(data, j("vx"), [[1, j("vec"), 0]]),
        "repeated component": _with_copies(data, j("vec_again"), [[0, j("vec"), 0], [0, j("vec"), 1],
                                                                  [1, j("vec"), 1], [2, j("vec"), 2]]),
        "itself": _with_copies(data, j("mixed"), [[1, j("mixed"), 0]]),
        "later array": _with_copies(data, j("vx"), [[0, j("mixed"), 0]]),
        "chain": _with_copies(data, j("near"), [[0, j("vec_again"), 0]]),
        "cycle": _with_copies(_with_copies(data, j("mixed"), [[0, j("vx"), 0]]), j("vx"), [[0, j("mixed"), 0]]),
        "dtype": _with_copies(data, j("id1"), [[0, j("vec"), 0]]),
        "default scalar copies": _with_copies(data, j("rho"), [[0, j("rho_copy"), 0]]),
        "not a list": _with_copies(data, j("vx"), {"0": 1}),
        "empty": _with_copies(data, j("vx"), []),
        "float index": _with_copies(data, j("vx"), [[0, float(j("vec")), 0]]),
        "bool index": _with_copies(data, j("vx"), [[False, j("vec"), 0]]),
        "short row": _with_copies(data, j("vx"), [[0, j("vec")]]),
        "format 7": _with_copies(data, j("vx"), [[0, j("vec"), 0]], major=7),
        "copies dropped": _with_copies(data, j("vx"), None),  # the section it needs is absent
        "copy with a section": _with_copies(data, j("negz"), [[0, j("zeros"), 0]]),
    }


_BAD = ["missing array", "negative array", "missing source component", "missing own component",
        "repeated component", "itself", "later array", "chain", "cycle", "dtype", "default scalar copies",
        "not a list", "empty", "float index", "bool index", "short row", "format 7", "copies dropped",
        "copy with a section"]


def test_the_valid_copy_file_decodes():
    data, cases = _bad_copy_cases()
    assert sorted(cases) == sorted(_BAD)
    assert TetcReader(data).decode_mesh(0, jobs=1).n_points > 0


@pytest.mark.parametrize("case", _BAD)
def test_bad_copies_are_corrupt(case):
    with pytest.raises(CorruptFileError, match="format 7" if case == "format 7" else None):
        TetcReader(_bad_copy_cases()[1][case]).decode_mesh(0, jobs=1)


def test_cli_info_shows_the_copies(tmp_path):
    from cli_util import run

    out = tmp_path / "fire.tetc"
    run("compress", FIRE, "--scalar", "t", "--mesh-only", "-o", str(out))
    text = run("info", str(out)).output
    line = next(x for x in text.splitlines() if x.strip().startswith("name=u,"))
    assert "bytes=0" in line and "copies=u = uvw[0]" in line
    assert "array 'u'" not in text  # no section: no part
