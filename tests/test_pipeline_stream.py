"""The integrated pipeline: streaming filtered renders equal the generic path and the simplified
mesh's render, whichever stored level they start from."""

import numpy as np
import pytest

from conftest import load_sample
from gatun_py.codec import LevelPayload, TetcReader, write_tetc
from gatun_py.errors import OptionError
from gatun_py.pipeline.stream import View, render_tetc
from gatun_py.simplify.levels import Target, resolve_target
from gatun_py.raycast.camera import Camera
from gatun_py.raycast.caster import render_mesh
from gatun_py.simplify import build_levels, decimate, simplified_mesh

TOL = 1e-5


@pytest.fixture(scope="module")
def post_levels(tmp_path_factory):
    mesh, _ = load_sample("post")
    forest = decimate(mesh)
    levels = build_levels(mesh, forest)
    path = tmp_path_factory.mktemp("pipe") / "post.tetc"
    write_tetc(path, [LevelPayload(lv.level, lv.ratio, lv.n_merges, lv.mesh, (lv.forest.parent, lv.forest.rank))
                      for lv in levels])
    return mesh, forest, levels, path


VIEW = View(Camera(48, 40, 30, 20), tf="post")


@pytest.mark.parametrize("ratio", [0.0, 0.3, 0.5, 0.8, 0.9])
def test_streaming_equals_generic_and_simplified_mesh(post_levels, ratio):
    mesh, forest, levels, path = post_levels
    s = render_tetc(path, VIEW, ratio=ratio)
    g = render_tetc(path, VIEW, ratio=ratio, pipeline="generic")
    assert np.abs(s.image - g.image).max() <= TOL
    assert s.stats["rays_unfinished"] == 0 and s.stats["nan_pixels"] == 0
    # Oracle: the simplified mesh (tetc decompress --ratio R) rendered whole, same camera/step/range.
    n = int(np.floor(ratio * mesh.n_points))
    simple = simplified_mesh(mesh, forest, n)
    reader = TetcReader(path)
    lo, hi = (np.asarray(x) for x in reader.meta["bbox"])
    step = reader.meta.get("render_step") or None
    ref = render_mesh(simple, Camera(48, 40, 30, 20).fit(lo, hi), "post", step=step or s.stats["step"],
                      scalar_range=tuple(reader.meta["scalar_range"]))
    assert np.abs(s.image - ref.image).max() <= TOL
    assert s.stats["tets_rendered"] == simple.n_tets


def test_every_level_gives_the_level_zero_image(post_levels):
    mesh, forest, levels, path = post_levels
    reader = TetcReader(path)
    deepest = levels[-1]
    n = deepest.n_merges + (forest.n_merges - deepest.n_merges) // 2
    base = render_tetc(path, VIEW, target=Target(0, n, n / mesh.n_points, 0))
    for lv in levels:
        if lv.n_merges > n:
            break
        img = render_tetc(path, VIEW, target=Target(lv.level, n, n / mesh.n_points, lv.n_merges)).image
        assert np.abs(img - base.image).max() <= TOL, lv.level
    assert resolve_target(reader, ratio=n / mesh.n_points).level == deepest.level


def test_targets_and_bad_options(post_levels):
    mesh, forest, levels, path = post_levels
    reader = TetcReader(path)
    t = resolve_target(reader, ratio=levels[1].ratio)
    assert (t.level, t.merges) == (1, levels[1].n_merges)
    t = resolve_target(reader, ratio=(levels[1].ratio + levels[2].ratio) / 2)
    assert t.level == 1 and t.merges > levels[1].n_merges
    assert resolve_target(reader, level=2).merges == levels[2].n_merges
    with pytest.raises(OptionError, match="is outside"):
        resolve_target(reader, ratio=1.5)
    with pytest.raises(OptionError, match="level 40 is not stored"):
        resolve_target(reader, level=40)
    if forest.max_ratio < 1.0:
        with pytest.raises(OptionError, match="forest holds"):
            resolve_target(reader, ratio=1.0)
    with pytest.raises(OptionError, match="either"):
        resolve_target(reader, ratio=0.5, level=1)


def test_corrupt_render_metadata_is_a_typed_error(post_levels, monkeypatch):
    from gatun_py.errors import CorruptFileError
    from gatun_py.pipeline.stream import file_render_defaults

    reader = TetcReader(post_levels[3])
    for bad in ({"bbox": [[0, 0], [1, 1, 1]]}, {"bbox": "x"}, {"scalar_range": [0, float("nan")]}, {"bbox": None}):
        monkeypatch.setattr(reader, "meta", {**reader.meta, **bad})
        with pytest.raises(CorruptFileError, match="corrupt metadata"):
            file_render_defaults(reader)
