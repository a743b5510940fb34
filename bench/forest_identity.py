"""Hashes of the merge forest (parent, rank, merge count) on the samples and two shared meshes.

Run as ``python bench/forest_identity.py [--meshes a,b] [--out FILE] [--check FILE]``: prints one
line per mesh (sha256 of the int32 parent and rank arrays and the merge count), with the CPU time
of the decimation and its counters (evaluations, exact evaluations, heap pops, ...). ``--check``
compares against a JSON file written by ``--out`` on another checkout (the decimator's speed work
must keep the forest bit-identical) and exits 1 on any difference; ``tests/test_forest_identity.py``
checks the samples against ``tests/data/forest_hashes.json``, written so. Import path: whatever
``gatun_py`` the interpreter finds first, so ``PYTHONPATH=<other checkout>`` runs that one.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from conftest import SAMPLE_FILES, load_sample  # noqa: E402
from test_forest_identity import forest_hash  # noqa: E402  (one hash, the test's)

sys.path.insert(0, str(ROOT / "bench"))
from common import MESH_CACHE  # noqa: E402

from gatun_py.mesh import read_mesh  # noqa: E402
from gatun_py.simplify import decimate  # noqa: E402
import gatun_py.simplify.decimation as D  # noqa: E402

SHARED = {"block-50k": MESH_CACHE / "block-50k.vtu", "flange-1m": MESH_CACHE / "flange-1m.vtu"}
DEFAULT = ["post", "fire", "bluntfin", "combustion", "block-50k", "flange-1m"]


def load(name):
    if name in SAMPLE_FILES:
        return load_sample(name)[0]
    return read_mesh(SHARED.get(name, name))[0]


def counted(mesh):
    """decimate() through its state, to read the counters afterwards."""
    state = D.DecimationState(mesh, D.DEFAULT_W_DENSITY, D.DEFAULT_W_GEOMETRY)
    state.start()
    state.run(mesh.n_points)
    counters = state.counters.copy()
    counters += state.tcount.sum(axis=0)
    return state, counters


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", default=",".join(DEFAULT))
    ap.add_argument("--out", help="write the hashes as JSON")
    ap.add_argument("--check", help="compare with a JSON of hashes; exit 1 on a difference")
    ap.add_argument("--counters", action="store_true", help="also print the decimator's counters")
    args = ap.parse_args(argv)
    decimate(load("post"))  # load the kernels
    result = {}
    for name in args.meshes.split(","):
        mesh = load(name)
        c0, t0 = time.process_time(), time.perf_counter()
        forest = decimate(mesh)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        result[name] = forest_hash(forest)
        line = f"{name}: {result[name]} merges {forest.n_merges} cpu {cpu:.2f} s wall {wall:.2f} s"
        if args.counters:
            _, c = counted(mesh)
            K = D.K
            m = max(1, int(c[K.C_MERGES]))
            evals = int(c[K.C_LAZY]) + mesh.n_points * (1 + int(c[K.C_SWEEPS]))
            line += (f"\n  per merge: evaluations {evals / m:.2f} (on pop {c[K.C_LAZY] / m:.2f}), candidates "
                     f"{c[K.C_EVALS] / m:.1f}, exact {c[K.C_EXACT] / m:.2f} (stopped by the bound "
                     f"{c[K.C_PRUNED] / m:.2f}), sample points summed {c[K.C_POINTS] / m:.0f}, points moved "
                     f"{c[K.C_MOVED] / m:.0f}, link tests {c[K.C_LINK] / m:.2f}, heap pops {c[K.C_POPS] / m:.2f} "
                     f"(stale {c[K.C_STALE] / m:.2f}); sweeps {int(c[K.C_SWEEPS])}")
        print(line, flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1))
    if args.check:
        ref = json.loads(Path(args.check).read_text())
        bad = [k for k in result if k in ref and ref[k] != result[k]]
        print("identical" if not bad else f"DIFFERENT: {', '.join(bad)}")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
