"""The README's usage examples run as written, in order, and its Python block too."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
pytestmark = pytest.mark.slow


def _block(after: str, lang: str) -> str:
    start = README.index(after)
    m = re.search(rf"```{lang}\n(.*?)```", README[start:], re.S)
    assert m, f"no ```{lang} block after {after!r}"
    return m.group(1)


def _commands():
    for line in _block("## Usage", "sh").splitlines():
        argv = shlex.split(line, comments=True)
        if argv and argv[0] != "source":
            yield argv


def test_usage_examples_run_in_order(tmp_path):
    (tmp_path / "sample_meshes").symlink_to(ROOT / "sample_meshes")
    env = dict(os.environ, TETC_CACHE_DIR=str(tmp_path / "cache"))
    bindir = Path(sys.executable).parent
    for argv in _commands():
        assert argv[0] == "tetc", argv
        res = subprocess.run([str(bindir / "tetc"), *argv[1:]], cwd=tmp_path, env=env, capture_output=True,
                             text=True, timeout=600)
        assert res.returncode == 0, f"{' '.join(argv)}\n{res.stderr}"
    assert (tmp_path / "bf_vtk.jpg").read_bytes()[:3] == b"\xff\xd8\xff"
    code = _block("The same from Python", "python")
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "bf90_api.png").exists() and (tmp_path / "bf99.tetc").exists()
