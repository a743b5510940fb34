"""Files written by earlier versions of the format still decode bit-exactly, and reference renders hold.

``tests/data/post_v{2,...,11}.tetc`` (formats 2 to 11, each written by ``tests/data/make_golden.py N``
with the code of its time: format 3 at commit e8af4f5) hold float64 coordinates and point arrays of
four dtypes/shapes; ``post_v{N}.json`` the hashes of every level's decoded points, arrays, tets and
forest.

``tests/data/post_v1.tetc`` was written by format 1 (commit 4545c9c) from ``post.vtk`` with every
level and the merge forest; ``post_v1.json`` holds the SHA-256 of every level's decoded points,
scalar, tets and forest as that version decoded them. A future reader must give the same bytes.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import gatun_py
from gatun_py.codec import TetcReader
from gatun_py.raycast.image import read_png_rgb
from samples import SAMPLES

DATA = Path(__file__).resolve().parent / "data"
GOLDEN = DATA / "post_v1.tetc"
EXPECTED = json.loads((DATA / "post_v1.json").read_text())


def _sha(a) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def test_golden_file_is_unchanged():
    assert hashlib.sha256(GOLDEN.read_bytes()).hexdigest() == EXPECTED["file_sha256"]


def _check_forest(reader, level, want):
    forest = reader.read_forest(int(level))
    if want["forest_parent"] is None:
        assert forest is None
    else:
        assert _sha(forest[0].astype(np.int32)) == want["forest_parent"]
        assert _sha(forest[1].astype(np.int32)) == want["forest_rank"]


@pytest.mark.parametrize("level", sorted(EXPECTED["levels"], key=int))
def test_format_1_decodes_bit_exactly(level):
    r = TetcReader(GOLDEN)
    want = EXPECTED["levels"][level]
    m = r.decode_mesh(int(level))
    assert (m.n_points, m.n_tets) == (want["n_points"], want["n_tets"])
    assert str(m.points.dtype) == want["points_dtype"] and str(m.density.dtype) == want["density_dtype"]
    assert _sha(m.points) == want["points"]
    assert _sha(m.density) == want["density"]
    assert _sha(m.tets.astype(np.int32)) == want["tets"]
    _check_forest(r, level, want)


GOLDEN_VERSIONS = (2, 3, 4, 5, 6, 7, 8, 9, 10, 11)  # one golden file per format version since 2, each written when it came
GOLDEN_OF = {v: DATA / f"post_v{v}.tetc" for v in GOLDEN_VERSIONS}
EXPECTED_OF = {v: json.loads((DATA / f"post_v{v}.json").read_text()) for v in GOLDEN_VERSIONS}


@pytest.mark.parametrize("version", GOLDEN_VERSIONS)
def test_golden_file_of_each_version_is_unchanged(version):
    assert TetcReader(GOLDEN_OF[version]).container.major == version
    assert _sha(np.frombuffer(GOLDEN_OF[version].read_bytes(), np.uint8)) == EXPECTED_OF[version]["file_sha256"]


@pytest.mark.parametrize("version, level", [(v, lv) for v in GOLDEN_VERSIONS
                                            for lv in sorted(EXPECTED_OF[v]["levels"], key=int)])
def test_each_format_decodes_bit_exactly(version, level):
    r = TetcReader(GOLDEN_OF[version])
    want = EXPECTED_OF[version]["levels"][level]
    m = r.decode_mesh(int(level))
    assert (m.n_points, m.n_tets) == (want["n_points"], want["n_tets"])
    assert str(m.points.dtype) == want["points_dtype"]
    assert _sha(m.points) == want["points"]
    assert _sha(m.tets.astype(np.int32)) == want["tets"]
    got = {name: [str(a.dtype), list(a.shape), _sha(a)] for name, a in m.point_data.items()}
    assert got == want["arrays"]
    _check_forest(r, level, want)


@pytest.mark.parametrize("old, new", [(3, 4), (4, 5), (5, 6), (6, 7), (7, 8), (8, 9), (9, 10)])
def test_consecutive_formats_hold_the_same_mesh(old, new):
    """Formats 4 to 8 changed only how the sections are coded (4: geometry; 5: connectivity and
    geometry; 6 and 7: the forest; 8: the geometry's value tables): the same mesh decodes from the
    golden file of each."""
    a, b = (TetcReader(GOLDEN_OF[v]).decode_mesh(0) for v in (old, new))
    np.testing.assert_array_equal(a.tets, b.tets)
    np.testing.assert_array_equal(a.points.view(np.int64), b.points.view(np.int64))
    for name in a.point_data:
        np.testing.assert_array_equal(a.point_data[name], b.point_data[name])


@pytest.mark.parametrize("old, new, shrink, what", [(7, 8, 0.8, "chained"), (8, 9, 0.99, "steps")])
def test_formats_7_8_and_9_hold_the_same_levels(old, new, shrink, what):
    """Formats 8 and 9 changed only the geometry sections (8: value tables chained across the
    levels; 9: rank steps on table-mode channels): every level of consecutive golden files, points,
    arrays, tets and forest, decodes to the same arrays, and the newer geometry is smaller and uses
    what its format added."""
    from gatun_py.codec.geometry import geometry_stream_sizes

    assert EXPECTED_OF[old]["levels"] == EXPECTED_OF[new]["levels"]
    a, b = (TetcReader(GOLDEN_OF[v]) for v in (old, new))
    for level in reversed(range(len(a.levels))):  # coarsest first: the chain's tables come from the reader's cache
        ma, mb = a.decode_mesh(level), b.decode_mesh(level)
        np.testing.assert_array_equal(ma.points.view(np.int64), mb.points.view(np.int64))
        np.testing.assert_array_equal(ma.tets, mb.tets)
    geometry = [sum(r.container.section_size(f"L{i}/geometry") for i in range(len(r.levels))) for r in (a, b)]
    assert geometry[1] < shrink * geometry[0]
    modes = geometry_stream_sizes(b.read_section("L0/geometry"))
    if what == "chained":
        assert "chained" in [modes[c + "_mode"] for c in ("x", "y", "z", "density")]
    else:
        assert any(modes[c + "_steps"] for c in ("x", "y", "z", "density"))


def test_forest_codings_2_and_3_hold_the_same_forest():
    """Formats 6 and 7 store the same decimation (rounds forest) in forest codings 2 and 3, and the
    same connectivity, so every level's forest decodes to the same arrays from both."""
    a, b = (TetcReader(GOLDEN_OF[v]) for v in (6, 7))
    assert len(a.levels) == len(b.levels)
    for level in range(len(a.levels)):
        fa, fb = a.read_forest(level), b.read_forest(level)
        assert (fa is None) == (fb is None)
        if fa is not None:
            np.testing.assert_array_equal(fa[0], fb[0])
            np.testing.assert_array_equal(fa[1], fb[1])


@pytest.mark.parametrize("version", GOLDEN_VERSIONS)
def test_golden_file_is_the_generated_mesh(version):
    """Level 0 of each golden file is lossless against the mesh ``make_golden`` builds."""
    import importlib.util  # the generator lives beside the data, not in an importable package
    spec = importlib.util.spec_from_file_location("make_golden", DATA / "make_golden.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    src, dec = mod.golden_mesh(), TetcReader(GOLDEN_OF[version]).decode_mesh(0)
    order_src = np.lexsort(src.points.T[::-1])
    order_dec = np.lexsort(dec.points.T[::-1])
    np.testing.assert_array_equal(src.points[order_src].view(np.int64), dec.points[order_dec].view(np.int64))
    for name, a in src.point_data.items():
        np.testing.assert_array_equal(a[order_src], dec.point_data[name][order_dec])


def test_golden_level_0_is_the_source_mesh():
    """The golden file is lossless against the real input: same points, scalar and tets up to order."""
    path, kw, _ = SAMPLES["post"]
    src, _ = gatun_py.read_mesh(path, **kw)
    dec = TetcReader(GOLDEN).decode_mesh(0)

    def canon(m):
        # format 1 stored float32: compare the source's float32 rounding (post.vtk holds doubles)
        key = np.concatenate([m.points32.view(np.uint32), m.density.view(np.uint32)[:, None]], axis=1)
        order = np.lexsort(key.T[::-1])
        rank = np.empty(len(order), np.int64)
        rank[order] = np.arange(len(order))
        tets = np.sort(rank[m.tets], axis=1)
        return key[order], tets[np.lexsort(tets.T[::-1])]

    (ka, ta), (kb, tb) = canon(src), canon(dec)
    np.testing.assert_array_equal(ka, kb)
    np.testing.assert_array_equal(ta, tb)


RENDERS = {
    "post_full_az30_el20": dict(azimuth=30, elevation=20),
    "post_r90_az30_el20": dict(azimuth=30, elevation=20, ratio=0.9),
    "post_face_az120_elm30": dict(azimuth=120, elevation=-30, mode="face"),
    "post_level3_az200_el60": dict(azimuth=200, elevation=60, level=3),
}


@pytest.mark.parametrize("name", sorted(RENDERS))
def test_reference_renders(name):
    """64² renders of the golden file against the images committed with it (made at commit 0.2.0's
    layering, kernels unchanged since 4545c9c). Exact on this platform; a different LLVM may round a
    sample differently, so one level of 255 is tolerated on a handful of pixels."""
    frame = gatun_py.render(GOLDEN, size=64, tf="post", **RENDERS[name])
    ref = read_png_rgb(DATA / "renders" / f"{name}.png").astype(int)
    diff = np.abs(frame.rgb.astype(int) - ref)
    assert diff.max() <= 1, diff.max()
    assert (diff > 0).sum() <= 8
    assert frame.stats["rays_unfinished"] == 0


SERIES_GOLDEN = {10: DATA / "series_v10.tetc", 11: DATA / "series_v11.tetc"}  # a time series per format version since 10


@pytest.mark.parametrize("version", sorted(SERIES_GOLDEN))
def test_series_golden_file_decodes_bit_exactly(version):
    """Every step of the golden series (8 steps compressed together, 2 appended; deforming, three
    dtypes), at level 0 and level 1, decodes to the hashes written with it."""
    import gatun_py

    path = SERIES_GOLDEN[version]
    want = json.loads(path.with_suffix(".json").read_text())
    assert _sha(np.frombuffer(path.read_bytes(), np.uint8)) == want["file_sha256"]
    f = gatun_py.open(path)
    assert f.reader.container.major == version and list(f.times) == want["times"] and f.n_steps == 10
    for k in reversed(range(f.n_steps)):  # backwards: each step from its keyframe, not from the walk
        m, w = f.mesh(step=k), want["steps"][k]
        assert _sha(m.points) == w["points"] and _sha(m.tets.astype(np.int32)) == w["tets"]
        assert {name: [str(a.dtype), list(a.shape), _sha(a)] for name, a in m.point_data.items()} == w["arrays"]
        assert _sha(f.mesh(level=1, step=k).points) == w["level1_points"]
