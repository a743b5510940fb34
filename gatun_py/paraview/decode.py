"""The decoder the ParaView plugin runs: one step of a ``.tetc`` file into a VTKHDF file.

``python -m gatun_py.paraview.decode FILE.tetc OUT [--step K] [--ratio R | --level L]`` writes the
mesh of step K (at ratio R or stored level L) to OUT (``.vtkhdf``; ``.vtu`` where h5py is missing)
and prints one line of JSON on stdout: what the file holds (time values, arrays, levels, the largest
ratio) and what was written. ``--info`` prints the JSON without decoding. An error prints one line,
``tetc: error: ...``, on stderr and exits 1 (2 for a usage error): the plugin shows that line in
ParaView's output window.

It runs in the Python gatun_py is installed in, apart from ParaView's: that Python's numpy and
numba never meet ParaView's.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys

from ..errors import OptionError, TetcError
from ..mesh import write_mesh
from ..mesh.vtkhdf import write_vtkhdf


def describe(f) -> dict:
    """What the plugin needs to know of an open file (a :class:`gatun_py.TetcFile`)."""
    n_steps = int(getattr(f, "n_steps", 1))
    times = [float(t) for t in getattr(f, "times", (0.0,))]
    return {
        "n_steps": n_steps,
        "times": times,
        "point_arrays": [[name, int(k)] for name, _, k in f.arrays if name],
        "cell_arrays": [[name, int(k)] for name, _, k in getattr(f, "cell_arrays", [])],
        "levels": f.levels,
        "max_ratio": float(f.max_ratio),
        "points": f.n_points,
        "tets": f.n_tets,
    }


def step_mesh(f, step: int, *, ratio: float | None = None, level: int | None = None):
    """The mesh of ``step`` at ``ratio`` or ``level`` (what :func:`write_vtkhdf` takes)."""
    n_steps = int(getattr(f, "n_steps", 1))
    if not 0 <= step < n_steps:
        raise OptionError(f"no time step {step}: the file has {n_steps}")
    if n_steps > 1:
        return f.mesh(ratio, level=level, step=step)
    return f.mesh(ratio, level=level)


def decode(source, output, *, step: int = 0, ratio: float | None = None, level: int | None = None) -> dict:
    """Decode ``step`` of ``source`` into ``output`` (overwritten) and return :func:`describe` of it
    with the cells and points written."""
    from ..api import open as open_tetc  # numba loads only here, not for --help

    f = open_tetc(source)
    out = describe(f)
    if ratio is not None and ratio <= 0:
        ratio = None
    if level is not None and level < 0:
        level = None
    if ratio is not None and level is not None:
        raise OptionError("give a ratio or a level, not both")
    if output is not None:
        mesh = step_mesh(f, step, ratio=ratio, level=level)
        if str(output).endswith(".vtkhdf"):
            write_vtkhdf(output, mesh, force=True)
        else:
            write_mesh(mesh, output, force=True)
        out.update(output=os.fspath(output), step=step, cells=int(mesh.n_tets), written_points=int(mesh.n_points))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m gatun_py.paraview.decode", description=__doc__.split("\n")[0])
    p.add_argument("file")
    p.add_argument("output", nargs="?")
    p.add_argument("--step", type=int, default=0)
    p.add_argument("--ratio", type=float, default=None)
    p.add_argument("--level", type=int, default=None)
    p.add_argument("--info", action="store_true", help="print what the file holds, decode nothing")
    args = p.parse_args(argv)
    output = None if args.info else args.output
    if output is None and not args.info:
        p.error("give an output file, or --info")
    if output is not None and output.endswith(".vtkhdf") and importlib.util.find_spec("h5py") is None:
        output = output[: -len(".vtkhdf")] + ".vtu"  # the plugin reads what the JSON names
    try:
        out = decode(args.file, output, step=args.step, ratio=args.ratio, level=args.level)
    except TetcError as e:
        print(f"tetc: error: {e}", file=sys.stderr)
        return 1
    except MemoryError:
        print("tetc: error: out of memory", file=sys.stderr)
        return 1
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
