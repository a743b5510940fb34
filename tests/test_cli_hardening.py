"""What breaks outside the happy path: full disks, special files, closed pipes, outputs that are inputs."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cli_util import assert_error, assert_usage_error, run
from samples import SAMPLES

POST = SAMPLES["post"][0]


def test_full_disk_is_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    def no_space(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", no_space)
    out = tmp_path / "x.tetc"
    assert_error(run("compress", POST, "-o", out, "--mesh-only", "--quiet"), "cannot write", "No space left")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    png = tmp_path / "x.png"
    assert_error(run("render", POST, "-o", png, "--size", 16, "--quiet"), "No space left")
    assert list(tmp_path.iterdir()) == []


def test_special_files_are_never_replaced(tmp_path):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    assert_error(run("render", POST, "-o", fifo, "--size", 8, "--force", "--quiet"), "not a regular file")
    assert fifo.is_fifo()
    link = tmp_path / "null.vtu"
    link.symlink_to("/dev/null")
    assert_error(run("convert", POST, "-o", link, "--force", "--quiet"), "not a regular file")
    assert Path("/dev/null").is_char_device()


def test_output_equal_to_input_is_refused_even_with_force(tmp_path):
    src = tmp_path / "post.vtk"
    src.write_bytes(Path(POST).read_bytes())
    assert_error(run("convert", src, "-o", src, "--force", "--quiet"), "is the input file")
    assert_usage_error(run("compress", src, "-o", src, "--force", "--quiet"), "NAME.tetc")  # not even tried
    tetc = tmp_path / "post.tetc"
    assert run("compress", src, "-o", tetc, "--mesh-only", "--quiet").exit_code == 0
    before = tetc.read_bytes()
    assert_error(run("compress", tetc, "-o", tetc, "--force", "--quiet"), "is the input file")
    assert src.read_bytes() == Path(POST).read_bytes() and tetc.read_bytes() == before


def test_compress_writes_only_names_ending_in_tetc(tmp_path):
    for name in ("x.png", "x.vtu", "x"):
        res = run("compress", POST, "-o", tmp_path / name, "--quiet")
        assert_usage_error(res, "NAME.tetc", "tetc render", "tetc decompress")
        assert not (tmp_path / name).exists()
    assert run("compress", POST, "-o", tmp_path / "X.TETC", "--mesh-only", "--quiet").exit_code == 0


def test_decompress_to_a_tetc_name_says_it_writes_a_mesh_format(tmp_path, post_tetc):
    out = tmp_path / "y.tetc"
    assert_error(run("decompress", post_tetc, "-o", out, "--quiet"), "decompress and convert write a mesh file",
                 ".vtu", ".msh", "tetc compress")
    assert not out.exists()


@pytest.mark.parametrize("ext", [".stl", ".ply", ".obj"])
def test_mesh_outputs_that_hold_no_tets_are_refused(tmp_path, ext):
    out = tmp_path / f"x{ext}"
    assert_error(run("convert", POST, "-o", out, "--quiet"), "holds no tetrahedra", ".vtu")
    assert not out.exists()


def test_a_closed_stderr_pipe_does_not_abort_the_work(tmp_path):
    """`tetc compress ... 2>&1 | head -1`: the reader goes away after one line; the file is still written."""
    out = tmp_path / "x.tetc"
    tetc = Path(sys.executable).parent / "tetc"
    proc = subprocess.run(f"'{tetc}' compress '{POST}' -o '{out}' 2>&1 | head -c 1", shell=True,
                          capture_output=True, timeout=300, executable="/bin/bash")
    assert proc.returncode == 0
    assert out.exists() and out.stat().st_size > 1000


def test_ctrl_c_stops_a_long_render_at_once_and_leaves_no_file(tmp_path):
    """A render that would take a minute (2048², the finest step the mesh allows) ends within a couple
    of seconds of SIGINT, with no image and no temporary file (the bound here is loose for a busy
    machine; the bench report quotes the measured delay)."""
    import signal
    import time

    out = tmp_path / "x.png"
    tetc = Path(sys.executable).parent / "tetc"
    proc = subprocess.Popen([str(tetc), "render", str(POST), "-o", str(out), "--size", "2048", "--step", "1e-9",
                             "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(6.0)  # past start-up: inside the kernels
    assert proc.poll() is None, proc.communicate()
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    assert time.perf_counter() - t0 < 5.0
    assert proc.returncode != 0
    assert list(tmp_path.iterdir()) == []
