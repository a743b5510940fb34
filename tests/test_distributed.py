"""Bricks on a real Dask cluster: a scheduler and two workers started as processes on 127.0.0.1
(`dask scheduler`, `dask worker`), rendering the same image as the local render; an unreachable
scheduler and a worker killed mid-frame; the CLI's options."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cli_util import assert_error, assert_usage_error, run
from conftest import SAMPLE_FILES, load_sample
from gatun_py.pipeline.sortlast import render_bricks, split_for_render
from gatun_py.pipeline.stream import View, render_mesh_file
from gatun_py.raycast import Camera
from gatun_py.raycast.image import to_rgb8

distributed = pytest.importorskip("distributed", reason="dask[distributed] is not installed (pip install 'gatun_py[dask]')")
from gatun_py.pipeline.distributed import BrickCluster, ClusterError  # noqa: E402

pytestmark = pytest.mark.slow
DASK = Path(sys.executable).with_name("dask")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for_workers(address, n, timeout=60.0):
    client = distributed.Client(address, timeout="20s", set_as_default=False)
    try:
        client.wait_for_workers(n, timeout=timeout)
    finally:
        client.close()


@pytest.fixture
def cluster_processes(tmp_path):
    """A scheduler and two workers as separate processes; all of them killed at the end, pass or fail."""
    if not DASK.exists():
        pytest.skip(f"the dask command is not installed beside {sys.executable}")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    procs = []

    def start(*args):
        p = subprocess.Popen([str(DASK), *args], env=env, cwd=tmp_path, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
        procs.append(p)
        return p

    try:
        start("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")
        workers = [start("worker", address, "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1",
                         "--no-dashboard", "--local-directory", str(tmp_path / f"w{i}")) for i in range(2)]
        _wait_for_workers(address, 2)
        yield address, workers
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_real_scheduler_and_two_workers_render_the_local_image(cluster_processes, tmp_path):
    address, _ = cluster_processes
    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 8)
    views = [View(Camera(64, 64, az, 20), "post", mode) for az, mode in ((30, "volume"), (120, "face"))]
    with BrickCluster(scheduler=address) as cluster:
        assert len(cluster.workers) == 2
        per_worker = cluster.load(bricks)
        assert sorted(i for w in per_worker for i in w) == list(range(8)) and all(per_worker)
        frames = list(cluster.render_series(views, extent))
    for view, frame in zip(views, frames):
        local = render_bricks(bricks, view, extent)
        whole = render_mesh_file(mesh, view)
        assert np.array_equal(frame.image, local.image)  # same kernels, same fragments, same order
        assert np.abs(to_rgb8(frame.image).astype(int) - to_rgb8(whole.image).astype(int)).max() <= 1
        assert frame.stats["bricks"] == 8 and frame.stats["workers"] == 2


def test_cli_on_a_real_scheduler(cluster_processes, tmp_path):
    address, _ = cluster_processes
    out, ref = tmp_path / "c.png", tmp_path / "ref.png"
    res = run("render", SAMPLE_FILES["post"][0], "-o", out, "--scheduler", address, "--bricks", "4", "--tf", "post",
              "--size", "48", "-q")
    assert res.exit_code == 0, res.output
    assert run("render", SAMPLE_FILES["post"][0], "-o", ref, "--tf", "post", "--size", "48", "-q").exit_code == 0
    res = run("compare", out, ref)
    assert res.exit_code == 0 and "rmse 0.0000" in res.output, res.output


def test_a_worker_killed_mid_series_is_survived_or_reported(cluster_processes, tmp_path):
    """Kill a worker while frames are in flight: the frames still come out right (Dask reloads the
    bricks on the survivor) or the series fails with ClusterError; never a wrong image."""
    address, workers = cluster_processes
    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 4)
    views = [View(Camera(48, 48, 36.0 * k, 10), "post") for k in range(6)]
    refs = [render_bricks(bricks, v, extent).image for v in views]
    with BrickCluster(scheduler=address) as cluster:
        cluster.load(bricks)
        got = []
        try:
            for i, frame in enumerate(cluster.render_series(views, extent)):
                got.append(frame.image)
                if i == 0:
                    os.killpg(workers[0].pid, signal.SIGKILL)
        except ClusterError as e:
            assert "failed" in str(e)
        for img, ref in zip(got, refs):
            assert np.array_equal(img, ref)
    assert len(got) >= 1


def test_unreachable_scheduler_is_a_clear_error_within_the_timeout(tmp_path):
    port = _free_port()  # nothing listens there
    t0 = time.perf_counter()
    with pytest.raises(ClusterError, match="cannot reach"):
        BrickCluster(scheduler=f"tcp://127.0.0.1:{port}", timeout=2)
    assert time.perf_counter() - t0 < 30
    out = tmp_path / "x.png"
    res = run("render", SAMPLE_FILES["post"][0], "-o", out, "--scheduler", f"tcp://127.0.0.1:{port}", "--timeout", "2")
    assert_error(res, "cannot reach")
    assert not out.exists()


def test_local_cluster_orbit_writes_every_frame(tmp_path):
    res = run("render", SAMPLE_FILES["post"][0], "-o", tmp_path / "f{frame}.png", "--workers", "2", "--orbit", "3",
              "--tf", "post", "--size", "32", "-q")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f0.png", "f1.png", "f2.png"]


def test_cluster_usage_errors(tmp_path):
    src = SAMPLE_FILES["post"][0]
    out = tmp_path / "o.png"
    assert_usage_error(run("render", src, "-o", out, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"), "not both")
    assert_usage_error(run("render", src, "-o", out, "--bricks", "4"), "--bricks")
    assert_usage_error(run("render", src, "-o", out, "--workers", "2", "--ratio", "0.5"), "--ratio")
    assert_usage_error(run("render", src, "-o", out, "--orbit", "3"), "--orbit")
    assert_usage_error(run("render", src, "-o", out, "--workers", "0"), "--workers")
    assert not out.exists()


def test_a_glob_of_time_steps_renders_file_after_file(tmp_path):
    import shutil

    for i in range(2):
        shutil.copy(SAMPLE_FILES["post"][0], tmp_path / f"step{i}.vtk")
    out = tmp_path / "out"
    out.mkdir()
    res = run("render", tmp_path / "step*.vtk", "-o", out / "t{frame}.png", "--workers", "1", "--orbit", "2",
              "--tf", "post", "--size", "24", "-q")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["t0.png", "t1.png", "t2.png", "t3.png"]
    assert (out / "t0.png").read_bytes() == (out / "t2.png").read_bytes()  # same data, same view
    assert_error(run("render", tmp_path / "none*.vtk", "-o", out / "x.png", "--workers", "1"), "no file matches")


def test_bricks_move_to_the_quicker_worker_and_the_image_does_not_change():
    """Skewed render times move a brick from the slower worker to the quicker one (one per frame,
    its old copy freed); the frames stay bit-identical to the one-process render."""
    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 6)
    views = [View(Camera(40, 40, 50.0 * k, 15), "post") for k in range(3)]
    with BrickCluster(workers=2, threads_per_worker=1, timeout=60) as cluster:
        cluster.load(bricks)
        before = cluster.placement()
        assert cluster.render(views[0], extent).stats["bands"] == 2
        slow = set(before[0])
        cluster._brick_s = [1.0 if i in slow else 0.01 for i in range(6)]  # worker 0 "took" 100x longer
        frame = cluster.render(views[1], extent)
        after = cluster.placement()
        assert cluster.moves == 1 and frame.stats["brick_moves"] == 1
        moved = set(before[0]) - set(after[0])
        assert len(moved) == 1 and moved <= set(after[1])
        (i,) = moved
        assert len(cluster.client.who_has(cluster._bricks[i])[cluster._bricks[i].key]) == 1  # moved, not copied
        for view in views[1:]:
            got = cluster.render(view, extent) if view is not views[1] else frame
            assert np.array_equal(got.image, render_bricks(bricks, view, extent).image)


@pytest.fixture(scope="module")
def post_bricked_file(tmp_path_factory):
    """post.vtk compressed as 4 bricks with their forests and levels."""
    import gatun_py

    path = tmp_path_factory.mktemp("post_bricked") / "post4.tetc"
    gatun_py.compress(load_sample("post")[0], path, bricks=4, jobs=1)
    return path


def test_budget_on_a_cluster_picks_a_level_per_brick(post_bricked_file, tmp_path, monkeypatch):
    from gatun_py.codec import TetcReader
    from gatun_py.errors import OptionError
    from gatun_py.pipeline.sortlast import BrickRef, MeshExtent

    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    reader = TetcReader(post_bricked_file)
    refs = [BrickRef(str(post_bricked_file), k) for k in range(reader.n_bricks)]
    extent = MeshExtent.of_reader(reader)
    view = View(Camera(48, 48, 30, 20), "post")
    with BrickCluster(workers=2, threads_per_worker=1, timeout=60) as cluster:
        with pytest.raises(OptionError, match="budget=True"):
            cluster.load(refs)
            cluster.render(view, extent, budget=1.0)  # bricks held as meshes: no levels to pick from
        cluster.load(refs, budget=True)
        generous = cluster.render(view, extent, budget=60.0)
        tight = cluster.render(view, extent, budget=1e-4)
    assert generous.stats["brick_levels"] == [0] * 4 and generous.stats["brick_ratios"] == [0.0] * 4
    assert np.array_equal(generous.image, render_bricks(refs, view, extent).image)  # the full mesh everywhere
    assert all(lv > 0 for lv in tight.stats["brick_levels"]) and min(tight.stats["brick_ratios"]) > 0.5
    assert tight.stats["tets_rendered"] < generous.stats["tets_rendered"]
    # the bricks chose what one process would choose for the same budget and the same grouping
    local = render_bricks(refs, view, extent, budget=1e-4)
    assert local.stats["brick_levels"] == tight.stats["brick_levels"]


def test_cli_budget_on_a_local_cluster(post_bricked_file, tmp_path, monkeypatch):
    monkeypatch.setenv("TETC_CACHE_DIR", str(tmp_path))
    out = tmp_path / "b{frame}.png"
    res = run("render", post_bricked_file, "-o", out, "--workers", "2", "--budget", "0.5", "--orbit", "2",
              "--tf", "post", "--size", "32", "-q", "--stats")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "b0.png").exists() and (tmp_path / "b1.png").exists()
    plain = tmp_path / "plain.png"
    assert_error(run("render", SAMPLE_FILES["post"][0], "-o", plain, "--workers", "1", "--budget", "0.5"), "bricked")
    assert not plain.exists()


def test_one_band_and_no_moves_give_the_same_image():
    """Compositing on one worker (bands=1) and fixed placement are the same frames, and skewed
    times move nothing when moves are off."""
    mesh = load_sample("post")[0]
    bricks, extent = split_for_render(mesh, 4)
    view = View(Camera(36, 30, 70, 25), "post", "face")
    with BrickCluster(workers=2, threads_per_worker=1, timeout=60, bands=1, move_bricks=False) as cluster:
        cluster.load(bricks)
        cluster._brick_s = [5.0, 0.0, 5.0, 0.0]
        frame = cluster.render(view, extent)
        assert cluster.moves == 0 and frame.stats["bands"] == 1
    assert np.array_equal(frame.image, render_bricks(bricks, view, extent).image)
    with pytest.raises(Exception, match="bands"):
        BrickCluster(workers=1, bands=0)
