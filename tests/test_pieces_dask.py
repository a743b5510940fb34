"""Pieces compressed as Dask tasks: the same bytes as in one process, also when a worker dies."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

distributed = pytest.importorskip("distributed",
                                  reason="dask[distributed] is not installed (pip install 'gatun_py[dask]')")

from cli_util import run  # noqa: E402
from gatun_py.mesh.pieces import write_pvtu  # noqa: E402
from gatun_py.pipeline.compress_pieces import compress_pieces  # noqa: E402
from test_distributed import cluster_processes  # noqa: E402,F401 (a fixture)
from test_pieces import rich_mesh, solver_pieces  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def pieces(tmp_path_factory):
    d = tmp_path_factory.mktemp("dask_pieces")
    write_pvtu(solver_pieces(rich_mesh((14, 13, 12), seed=9), 6, seed=2), d / "run.pvtu")
    ref = d / "ref.tetc"
    compress_pieces(d / "run.pvtu", ref, jobs=1)  # with levels: the decimation runs on the workers
    return d / "run.pvtu", ref.read_bytes()


def test_local_workers_write_the_one_process_bytes(pieces, tmp_path):
    path, ref = pieces
    out = tmp_path / "w.tetc"
    res = run("compress", path, "--workers", 2, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    assert out.read_bytes() == ref


def test_a_worker_killed_mid_compress_changes_nothing(pieces, cluster_processes, tmp_path):
    path, ref = pieces
    address, workers = cluster_processes
    out = tmp_path / "k.tetc"
    errors = []
    t = threading.Thread(target=lambda: _catch(errors, compress_pieces, path, out, scheduler=address))
    t.start()
    client = distributed.Client(address, timeout="20s", set_as_default=False)
    try:
        deadline = time.monotonic() + 120
        killed = False
        while t.is_alive() and time.monotonic() < deadline and not killed:
            busy = [w for w, keys in client.processing().items() if any("encode_piece" in str(k) for k in keys)]
            if len(busy) == 2:  # both workers inside the second pass
                os.killpg(workers[0].pid, signal.SIGKILL)
                killed = True
            time.sleep(0.02)
    finally:
        client.close()
    t.join(300)
    assert killed and not errors, errors
    assert out.read_bytes() == ref


def _catch(errors, fn, *args, **kwargs):
    try:
        fn(*args, **kwargs)
    except Exception as e:  # reported by the test
        errors.append(e)
