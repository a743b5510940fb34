"""The first ``tetc render`` on a fresh install: what :func:`gatun_py.warmup.compile_for_render`
compiles ahead (in worker processes, side by side) must be everything the render then runs, so the
render itself compiles nothing. Runs in a child process with an empty numba cache (about a minute
of compiling on two cores)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

DATA = Path(__file__).parent / "data"

CHILD = r"""
import json, sys
from numba.core import event
import gatun_py
from gatun_py.warmup import compile_for_render, load_kernels

def compiled_while(run):
    with event.install_recorder("numba:compile") as rec:
        run()
    return sorted({e.data["dispatcher"].py_func.__qualname__ for _, e in rec.buffer if e.is_start})

out = {}
for simplify, kw in ((False, {}), (True, {"ratio": 0.5})):
    compile_for_render(decoder=True, simplify=simplify)
    out[str(simplify)] = compiled_while(lambda: (load_kernels(decoder=True, simplify=simplify),
                                                 gatun_py.render(sys.argv[1], size=48, **kw)))
print(json.dumps(out))
"""


def test_a_first_render_compiles_nothing_beyond_what_was_compiled_ahead(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    from gatun_py.codec.container import VERSION_MAJOR

    today = DATA / f"post_v{VERSION_MAJOR}.tetc"  # what tetc compress writes today
    run = subprocess.run([sys.executable, "-c", CHILD, str(today)], env=env, capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    compiled = json.loads(run.stdout.strip().splitlines()[-1])
    assert compiled == {"False": [], "True": []}
