"""Renders are bounded whatever the step: from the user or from a crafted file."""

from __future__ import annotations

from pathlib import Path

import pytest

import gatun_py
from cli_util import run
from gatun_py.codec import TetcReader
from gatun_py.codec.container import build_container, split_container
from gatun_py.pipeline.stream import MAX_SAMPLES_PER_DIAGONAL, bounded_step

GOLDEN = Path(__file__).resolve().parent / "data" / "post_v1.tetc"
POST = Path(__file__).resolve().parents[1] / "sample_meshes" / "lox_post_tets" / "post.vtk"


def _with_meta(path, out, **changes):
    meta, sections = split_container(path)
    meta.update(changes)
    out.write_bytes(build_container(meta, sections))
    return out


@pytest.mark.parametrize("step", [1e-9, 1e-300, 0.0001])
def test_bounded_step_never_goes_below_the_finest(step):
    s, notes = bounded_step(step, [0, 0, 0], [1, 1, 1])
    finest = 3 ** 0.5 / MAX_SAMPLES_PER_DIAGONAL
    assert s >= finest * (1 - 1e-12)
    assert (s == step) == (not notes)


def test_a_tiny_step_from_the_user_is_raised_with_a_note(tmp_path):
    res = run("render", GOLDEN, "-o", tmp_path / "x.png", "--size", 16, "--step", "1e-9", "--tf", "post")
    assert res.exit_code == 0, res.output
    assert "note: step 1e-09 is below the finest this mesh allows" in res.stderr
    frame = gatun_py.render(GOLDEN, size=16, step=1e-9, tf="post")
    assert frame.stats["step"] > 1e-9 and frame.stats["rays_unfinished"] == 0


def test_a_file_with_a_tiny_stored_step_renders_bounded(tmp_path):
    src = gatun_py.compress(POST, tmp_path / "post.tetc", mesh_only=True).path
    bad = _with_meta(src, tmp_path / "tiny_step.tetc", render_step=1e-12)
    notes = []
    frame = gatun_py.render(bad, size=16, tf="post", log=notes.append)
    assert any("the file's step 1e-12" in n for n in notes)
    lo, hi = TetcReader(bad).meta["bbox"]
    assert frame.stats["step"] == pytest.approx(bounded_step(1e-12, lo, hi)[0])
