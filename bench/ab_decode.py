"""In-process A/B of the decoder: this checkout's ``gatun_py`` against another commit's, on the same
files, interleaved in one process (so that the machine's load weighs on both alike).

Run: ``python bench/ab_decode.py FILE.tetc [...] [--base REV] [--reps N] [--connectivity]``. The
other commit's ``gatun_py`` (``git archive REV``, default ``main``) is unpacked into a temporary
folder as the package ``gatun_base``; its kernels compile into that folder's cache on the first
run. Prints per file the median CPU seconds of a level-0 decode (``--connectivity``: the
connectivity streams alone) of each and their ratio; the decoded tets must be equal.
"""

from __future__ import annotations

import argparse
import io
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def unpack_base(rev: str, where: Path) -> None:
    """``gatun_py`` of commit ``rev`` as the package ``gatun_base`` in ``where``."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "gatun_py"], capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(where, filter="data")
    shutil.move(where / "gatun_py", where / "gatun_base")
    for path in (where / "gatun_base").rglob("*.py"):  # the few absolute imports of the package itself
        text = path.read_text(encoding="utf-8")
        if "from gatun_py." in text:
            path.write_text(text.replace("from gatun_py.", "from gatun_base."), encoding="utf-8")


def decode_level0(codec, path):
    return codec.TetcReader(path).decode_mesh(0).tets


def decode_connectivity(codec, path):
    r = codec.TetcReader(path)
    return r._level_tets(0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--base", default="main")
    ap.add_argument("--reps", type=int, default=11)
    ap.add_argument("--connectivity", action="store_true")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="tetc-ab-") as tmp:
        unpack_base(args.base, Path(tmp))
        sys.path.insert(0, tmp)
        import gatun_base.codec as A
        import gatun_py.codec as B

        run = decode_connectivity if args.connectivity else decode_level0
        for path in args.files:
            assert np.array_equal(run(A, path), run(B, path)), f"{path}: the two decode differently"
            ta, tb = [], []
            for i in range(args.reps):
                for mod, ts in ((A, ta), (B, tb)) if i % 2 == 0 else ((B, tb), (A, ta)):
                    t = time.process_time()
                    run(mod, path)
                    ts.append(time.process_time() - t)
            ma, mb = statistics.median(ta), statistics.median(tb)
            print(f"{Path(path).name}: {args.base} {ma:.4f} s, this checkout {mb:.4f} s CPU (medians of {args.reps}), "
                  f"ratio {mb / ma:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
