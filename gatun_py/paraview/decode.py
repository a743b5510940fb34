"""The decoder the ParaView plugin runs: one step of a ``.tetc`` file into a VTKHDF file.

``python -m gatun_py.paraview.decode FILE.tetc OUT [--step K] [--ratio R | --level L] [--tets]``
writes the mesh of step K (at ratio R or stored level L; the cells as given where the file stores
them, unless --tets) to OUT (a folder of ``.npy`` files when OUT ends in
``.npydir``, what the plugin asks for; ``.vtkhdf``, as ``.vtu`` where h5py is missing; any mesh format)
and prints one line of JSON on stdout: what the file holds (time values, arrays, levels, the largest
ratio) and what was written. ``--info`` prints the JSON without decoding. An error prints one line,
``tetc: error: ...``, on stderr and exits 1 (2 for a usage error): the plugin shows that line in
ParaView's output window.

``--serve`` keeps one process for many requests: it imports gatun_py and loads the decoder's kernels
at once, then answers one JSON request per line on stdin (``{"file", "output", "step", "ratio",
"level"}``) with one JSON line on stdout (the description, or ``{"error": ...}``), until stdin closes.
The plugin starts it when ParaView loads the plugin, so opening a file and stepping through a series
do not wait for another Python to start.

It runs in the Python gatun_py is installed in, apart from ParaView's: that Python's numpy and
numba never meet ParaView's.
"""

from __future__ import annotations

import argparse

import numpy as np
import importlib.util
import json
import os
import sys
import tempfile
from pathlib import Path

import meshio

from ..errors import OptionError, TetcError
from ..mesh import write_mesh
from ..mesh.io import to_meshio
from ..mesh.vtkhdf import _parts, _topology, write_vtkhdf

# the tiny file shipped for warming up the kernels (gatun_py/warmup.tetc)
WARMUP_TETC = Path(__file__).resolve().parents[1] / "warmup.tetc"


def _stored_cells(f) -> dict | None:
    """The metadata of the cells as given that ``f`` stores (None: its tets are its cells)."""
    meta = f.reader.meta.get("cells")
    return meta if isinstance(meta, dict) else None


def describe(f) -> dict:
    """What the plugin needs to know of an open file (a :class:`gatun_py.TetcFile`)."""
    n_steps = int(getattr(f, "n_steps", 1))
    times = [float(t) for t in getattr(f, "times", (0.0,))]
    cells = _stored_cells(f) or {}
    cell_arrays = []
    for e in cells.get("cell_data") or []:
        if isinstance(e, dict) and isinstance(e.get("name"), str) and e.get("blocks"):
            shape = e["blocks"][0].get("shape") or []
            cell_arrays.append([e["name"], int(np.prod(shape)) if shape else 1])
    return {
        "n_steps": n_steps,
        "times": times,
        "point_arrays": [[name, int(k)] for name, _, k in f.arrays if name],
        "cell_arrays": cell_arrays,
        "cell_blocks": [[str(b.get("type")), int(b.get("cells", 0))] for b in cells.get("blocks") or []
                        if isinstance(b, dict)],
        "levels": f.levels,
        "max_ratio": float(f.max_ratio),
        "points": f.n_points,
        "tets": f.n_tets,
    }


def step_mesh(f, step: int, *, ratio: float | None = None, level: int | None = None, tets: bool = False):
    """The mesh of ``step`` at ``ratio`` or ``level`` (what :func:`write_vtkhdf` takes): the cells
    as given (a ``meshio.Mesh`` of their blocks and cell arrays) where the file stores them and the
    full mesh is asked for without ``tets``, else a TetMesh of the tets."""
    n_steps = int(getattr(f, "n_steps", 1))
    if not 0 <= step < n_steps:
        raise OptionError(f"no time step {step}: the file has {n_steps}")
    if n_steps > 1:
        return f.mesh(ratio, level=level, step=step)
    mesh = f.mesh(ratio, level=level)
    if tets or ratio is not None or level not in (None, 0) or _stored_cells(f) is None:
        return mesh
    from ..codec.cells import read_cells, restore_order  # the codec (numba) loads at the first decode

    cells = read_cells(f.reader, mesh.tets, mesh.n_points, mesh.points)
    return to_meshio(*restore_order(mesh, cells))


ARRAYS_SUFFIX = ".npydir"


def write_arrays(mesh, folder) -> dict:
    """The mesh as plain ``.npy`` files in ``folder`` (created): what the plugin turns into a VTK grid
    with no parsing at all, faster for ParaView 5.11 to load than a VTKHDF or ``.vtu`` file
    (``bench/sections/paraview.md``). Returns the manifest: file of the points, the VTK cells (connectivity, offsets and
    one cell type or a types file) and every point and cell array by name."""
    points, cells, point_data, cell_data = _parts(mesh)
    os.makedirs(folder, exist_ok=True)
    if len(cells) == 1 and cells[0][0] == "tetra":  # the usual case: no copy into VTK's int64 layout
        conn = np.ascontiguousarray(cells[0][1])
        big = conn.dtype != np.int32 or 4 * len(conn) >= 2**31
        conn = conn.astype(np.int64) if big else conn
        offsets = np.arange(0, 4 * len(conn) + 1, 4, dtype=conn.dtype)
        types, cell_type = None, 10
    else:
        types, offsets, conn = _topology(cells)
        cell_type = None
    out = {"points": "points.npy", "connectivity": "connectivity.npy", "offsets": "offsets.npy",
           "cell_type": cell_type, "types": None if types is None else "types.npy", "point_data": [], "cell_data": []}
    save = {"points": points, "connectivity": conn.reshape(-1), "offsets": offsets}
    if types is not None:
        save["types"] = types
    for i, (name, a) in enumerate(point_data.items()):
        save[f"p{i}"] = a.view(np.uint8) if a.dtype == np.bool_ else a
        out["point_data"].append([name, f"p{i}.npy"])
    for i, (name, blocks) in enumerate(cell_data.items()):
        a = np.concatenate([np.asarray(b) for b in blocks])
        save[f"c{i}"] = a.view(np.uint8) if a.dtype == np.bool_ else a  # VTK has no bool arrays
        out["cell_data"].append([name, f"c{i}.npy"])
    for key, a in save.items():
        np.save(os.path.join(folder, f"{key}.npy"), np.ascontiguousarray(a), allow_pickle=False)
    return out


def decode(source, output, *, step: int = 0, ratio: float | None = None, level: int | None = None,
           tets: bool = False) -> dict:
    """Decode ``step`` of ``source`` into ``output`` (overwritten) and return :func:`describe` of it
    with the cells and points written: the cells as given where the file stores them (``tets``: the
    tets they were split into)."""
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
        mesh = step_mesh(f, step, ratio=ratio, level=level, tets=tets)
        if str(output).endswith(ARRAYS_SUFFIX):
            out["arrays"] = write_arrays(mesh, output)
        elif str(output).endswith(".vtkhdf"):
            write_vtkhdf(output, mesh, force=True)
        elif isinstance(mesh, meshio.Mesh):
            mesh.write(output)
        else:
            write_mesh(mesh, output, force=True)
        n_cells = sum(len(c.data) for c in mesh.cells) if isinstance(mesh, meshio.Mesh) else int(mesh.n_tets)
        out.update(output=os.fspath(output), step=step, cells=int(n_cells), written_points=int(len(mesh.points)))
    return out


def _answer(req: dict) -> dict:
    try:
        return decode(req["file"], _output(req.get("output")), step=int(req.get("step", 0)), ratio=req.get("ratio"),
                      level=req.get("level"), tets=bool(req.get("tets", False)))
    except TetcError as e:
        return {"error": str(e)}
    except MemoryError:
        return {"error": "out of memory"}
    except (KeyError, TypeError, ValueError) as e:  # a malformed request: the plugin's bug, said plainly
        return {"error": f"bad request to the decoder: {e!r}"}


def _output(output):
    """``output``, as ``.vtu`` where h5py is missing (the plugin reads what the answer names)."""
    if output is not None and output.endswith(".vtkhdf") and importlib.util.find_spec("h5py") is None:
        return output[: -len(".vtkhdf")] + ".vtu"
    return output


def serve(stdin=None, stdout=None) -> int:
    """Answer requests, one JSON line each, until ``stdin`` closes (see the module's help)."""
    stdin, stdout = stdin or sys.stdin, stdout or sys.stdout
    from ..api import open as open_tetc  # load the verbs now, not at the first request

    try:  # the decoder's kernels (from numba's cache) and h5py load on first use: use them now
        with tempfile.TemporaryDirectory() as tmp:
            decode(WARMUP_TETC, os.path.join(tmp, "warm.vtkhdf") if importlib.util.find_spec("h5py") else None)
        open_tetc(WARMUP_TETC)
    except Exception:  # noqa: BLE001 (a warm-up only: whatever went wrong, the real requests say it)
        pass
    print(json.dumps({"ready": True}), file=stdout, flush=True)
    for line in stdin:
        if not line.strip():
            continue
        try:
            req = json.loads(line)
        except ValueError:
            req = {}
        print(json.dumps(_answer(req) if isinstance(req, dict) else {"error": "bad request"}), file=stdout, flush=True)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m gatun_py.paraview.decode", description=__doc__.split("\n")[0])
    p.add_argument("file")
    p.add_argument("output", nargs="?")
    p.add_argument("--step", type=int, default=0)
    p.add_argument("--ratio", type=float, default=None)
    p.add_argument("--level", type=int, default=None)
    p.add_argument("--tets", action="store_true", help="the tets, not the cells as given")
    p.add_argument("--info", action="store_true", help="print what the file holds, decode nothing")
    p.add_argument("--serve", action="store_true", help="answer JSON requests on stdin, one per line")
    if argv is None and "--serve" in sys.argv[1:2] or argv == ["--serve"]:
        return serve()
    args = p.parse_args(argv)
    output = None if args.info else _output(args.output)
    if output is None and not args.info:
        p.error("give an output file, or --info")
    try:
        out = decode(args.file, output, step=args.step, ratio=args.ratio, level=args.level, tets=args.tets)
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
