"""Shared fixtures: the bundled real samples and small generated meshes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from samples import SAMPLE_DIR as SAMPLES  # noqa: F401  (the CLI tests import it from here)
from samples import SAMPLES as _TABLE

ROOT = Path(__file__).resolve().parent.parent

# name -> (path, read_mesh keyword arguments); the table itself is tests/samples.py
SAMPLE_FILES = {name: (path, kw) for name, (path, kw, _tf) in _TABLE.items()}

os.environ.setdefault("NUMBA_NUM_THREADS", "2")
# no first-run compile notices: the output checks must not depend on what numba's cache holds
# (tests/test_compile_notice.py runs the commands with notices on, in processes of their own)
os.environ.setdefault("TETC_COMPILE_NOTICE", "0")


_cache: dict = {}


def load_sample(name: str):
    """Read a bundled sample once per test session (returns (TetMesh, MeshReport))."""
    from gatun_py.mesh import read_mesh

    if name not in _cache:
        path, kw = SAMPLE_FILES[name]
        _cache[name] = read_mesh(path, **kw)
    return _cache[name]


@pytest.fixture(params=sorted(SAMPLE_FILES))
def sample(request):
    """Each real sample mesh in turn: (name, TetMesh)."""
    return request.param, load_sample(request.param)[0]


@pytest.fixture
def small_sample():
    """The smallest real sample (post.vtk), for tests that must stay quick."""
    return load_sample("post")[0]


@pytest.fixture(scope="session")
def post_deps_tetc(tmp_path_factory):
    """post.vtk compressed once per session with its merge dependencies (`--dependencies`)."""
    from cli_util import run

    out = tmp_path_factory.mktemp("post_deps") / "post.tetc"
    res = run("compress", SAMPLE_FILES["post"][0], "-o", out, "--dependencies", "--quiet")
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="session")
def post_tetc(tmp_path_factory):
    """post.vtk compressed once per session by `tetc compress` (all levels, merge forest)."""
    from cli_util import run

    out = tmp_path_factory.mktemp("post") / "post.tetc"
    res = run("compress", SAMPLE_FILES["post"][0], "-o", out, "--quiet")
    assert res.exit_code == 0, res.output
    return out

# run by ParaView's own pvbatch (tests/test_paraview_plugin.py), never imported by pytest: it
# imports the paraview package, which only ParaView's Python has
collect_ignore = ["paraview_driver.py"]
