"""Write a golden ``.tetc`` file of the current format and the hashes of what it decodes to.

Run once per format version, when the version is introduced, and commit both files::

    python tests/data/make_golden.py 2     # -> tests/data/post_v2.tetc, post_v2.json
    python tests/data/make_golden.py series 10   # -> series_v10.tetc, series_v10.json (a time series)

The mesh is ``post.vtk`` with float64 coordinates and point arrays of several dtypes and
component counts, so every kind of section of the format is present. The test
(``tests/test_format_stability.py``) then checks that every later reader decodes the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import gatun_py  # noqa: E402
from gatun_py.codec import TetcReader  # noqa: E402
from gatun_py.mesh import TetMesh  # noqa: E402
from gatun_py.mesh.validate import validate_tets  # noqa: E402
from samples import SAMPLES  # noqa: E402


def sha(a) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def golden_mesh() -> TetMesh:
    path, kw, _ = SAMPLES["post"]
    src, _ = gatun_py.read_mesh(path, **kw)
    p = np.asarray(src.points, np.float64) * (1 + 1e-9)  # not float32-representable: points64 is stored
    x, y, z = p.T
    arrays = {
        src.scalar_name: np.asarray(src.density, np.float32),
        "wave64": np.sin(3 * x) * np.cos(2 * y) + z,                        # float64
        "cell_id": (np.arange(len(p)) * 7 % 1000).astype(np.int32),          # integer
        "velocity": np.stack([y, -x, 0.1 * z], axis=1).astype(np.float32),  # 3 components
    }
    return TetMesh(p, None, src.tets, src.scalar_name, point_data=arrays)


def describe(path: Path) -> dict:
    r = TetcReader(path)
    levels = {}
    for level in range(len(r.levels)):
        m = r.decode_mesh(level)
        forest = r.read_forest(level)
        levels[str(level)] = {
            "n_points": int(m.n_points), "n_tets": int(m.n_tets),
            "points_dtype": str(m.points.dtype), "points": sha(m.points),
            "tets": sha(m.tets.astype(np.int32)),
            "arrays": {name: [str(a.dtype), list(a.shape), sha(a)] for name, a in m.point_data.items()},
            "forest_parent": None if forest is None else sha(forest[0].astype(np.int32)),
            "forest_rank": None if forest is None else sha(forest[1].astype(np.int32)),
        }
    return {"file_sha256": sha(np.frombuffer(path.read_bytes(), np.uint8)), "levels": levels}


def series_meshes(n_steps: int = 10):
    """Steps of the committed solver series (``series_heat.npz``, deforming), each with a float64
    temperature, its float32 copy and an integer array: every kind of step section."""
    with np.load(HERE / "series_heat.npz") as z:
        tets, moved, temp, times = z["tets"], z["moved"], z["temperature"], z["times"]
    out = []
    for k in range(n_steps):
        data = {"temperature": temp[k], "t32": temp[k].astype(np.float32),
                "band": np.floor(temp[k] / 10).astype(np.int16)}
        out.append(validate_tets(moved[k], None, tets, scalar_name="temperature",
                                 point_data=data)[0])
    return out, [float(t) for t in times[:n_steps]]


def describe_series(path: Path) -> dict:
    f = gatun_py.open(path)
    steps = []
    for k in range(f.n_steps):
        m = f.mesh(step=k)
        steps.append({"points": sha(m.points), "tets": sha(m.tets.astype(np.int32)),
                      "arrays": {name: [str(a.dtype), list(a.shape), sha(a)] for name, a in m.point_data.items()},
                      "level1_points": sha(f.mesh(level=1, step=k).points)})
    return {"file_sha256": sha(np.frombuffer(path.read_bytes(), np.uint8)), "times": list(f.times), "steps": steps}


def main_series(version: int) -> None:
    """``series_v{N}.tetc``: 8 steps compressed together (keyframes every 4, levels 0..2), then 2 appended."""
    from gatun_py.pipeline.series import append_step, write_series

    out = HERE / f"series_v{version}.tetc"
    meshes, times = series_meshes(10)
    write_series(out, meshes[:8], times[:8], levels=2, keyframe_interval=4, force=True)
    for m, t in zip(meshes[8:], times[8:]):
        append_step(out, m, t)
    (HERE / f"series_v{version}.json").write_text(json.dumps(describe_series(out), indent=1) + "\n")
    print(f"wrote {out} ({out.stat().st_size} bytes) and its hashes")


def main(version: int) -> None:
    out = HERE / f"post_v{version}.tetc"
    # levels 1 to 9, as the golden files of formats 2 to 8 (written when the default kept them all):
    # consecutive formats then hold the same levels
    gatun_py.compress(golden_mesh(), out, levels=9, force=True)
    (HERE / f"post_v{version}.json").write_text(json.dumps(describe(out), indent=1) + "\n")
    print(f"wrote {out} ({out.stat().st_size} bytes) and its hashes")


if __name__ == "__main__":
    if sys.argv[1] == "series":  # python tests/data/make_golden.py series 10
        main_series(int(sys.argv[2]))
    else:
        main(int(sys.argv[1]))
