"""A plain (non-editable) wheel installed into a fresh virtual environment, used from outside the
checkout, as a new user would: presets ship inside the package, the CLI installs as gatun_py.cli,
nothing reads sample_meshes/ at run time.

Slow (it installs the dependencies into a new environment and compiles the kernels there), so it is
marked ``slow``; CI runs it. Skips only when no wheel can be built or installed for want of the
package index, and says so.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
import venv
from pathlib import Path

import pytest

from samples import SAMPLES

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def _run(cmd, cwd, env=None, timeout=900):
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    work = tmp_path_factory.mktemp("wheel")
    res = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", work / "dist", ROOT], cwd=work)
    if res.returncode != 0:
        if "Could not find a version" in res.stderr or "NewConnectionError" in res.stderr:
            pytest.skip(f"cannot build a wheel without the package index: {res.stderr.strip()[-300:]}")
        pytest.fail(f"pip wheel failed:\n{res.stdout}\n{res.stderr}")
    wheels = list((work / "dist").glob("gatun_py-*.whl"))
    assert len(wheels) == 1, wheels
    env_dir = work / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    res = _run([py, "-m", "pip", "install", "-q", wheels[0]], cwd=work)
    if res.returncode != 0:
        if "Could not find a version" in res.stderr or "NewConnectionError" in res.stderr:
            pytest.skip(f"cannot install the dependencies without the package index: {res.stderr.strip()[-300:]}")
        pytest.fail(f"pip install failed:\n{res.stdout}\n{res.stderr}")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["NUMBA_CACHE_DIR"] = str(work / "numba-cache")
    run_dir = work / "elsewhere"
    run_dir.mkdir()
    return env_dir, env, run_dir, wheels[0]


def test_wheel_contents(installed):
    import zipfile

    names = zipfile.ZipFile(installed[3]).namelist()
    assert "gatun_py/cli/main.py" in names and "gatun_py/raycast/presets/bluntfin.json" in names
    assert "gatun_py/warmup.tetc" in names
    assert not any(n.startswith("cli/") for n in names), "a bare top-level 'cli' package must not be installed"


def test_commands_from_the_wheel(installed, tmp_path):
    env_dir, env, cwd, _ = installed
    tetc = env_dir / "bin" / "tetc"
    post = SAMPLES["post"][0]
    out = tmp_path / "post.tetc"
    res = _run([tetc, "compress", post, "-o", out, "--levels", "2", "--quiet"], cwd, env)
    assert res.returncode == 0, res.stderr
    res = _run([tetc, "decompress", out, "-o", tmp_path / "back.vtu", "--ratio", "0.5", "--quiet"], cwd, env)
    assert res.returncode == 0, res.stderr
    res = _run([tetc, "render", out, "-o", tmp_path / "preset.png", "--tf", "post", "--size", "32", "--quiet"],
               cwd, env)
    assert res.returncode == 0, res.stderr
    tf = tmp_path / "tf.json"
    tf.write_text(json.dumps({"color": [{"x": 0, "rgb": [0, 0, 1]}, {"x": 1, "rgb": [1, 0, 0]}],
                              "opacity": [{"x": 0, "a": 0.1}, {"x": 1, "a": 0.8}], "unit_distance": 0.5}))
    res = _run([tetc, "render", out, "-o", tmp_path / "file.png", "--tf", tf, "--size", "32", "--quiet"], cwd, env)
    assert res.returncode == 0, res.stderr
    res = _run([tetc, "render", out, "-o", tmp_path / "default.png", "--size", "32", "--quiet"], cwd, env)
    assert res.returncode == 0, res.stderr
    for name in ("preset", "file", "default"):
        assert (tmp_path / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_python_api_from_the_wheel(installed, tmp_path):
    env_dir, env, cwd, _ = installed
    script = textwrap.dedent(f"""
        import gatun_py, meshio, os
        assert "site-packages" in gatun_py.__file__, gatun_py.__file__
        f = gatun_py.compress({str(SAMPLES["post"][0])!r}, {str(tmp_path / "api.tetc")!r}, mesh_only=True)
        frame = gatun_py.render(f, size=24, tf="bluntfin")
        frame.save({str(tmp_path / "api.jpg")!r})
        m = meshio.read({str(tmp_path / "api.tetc")!r})
        print(f.n_tets, frame.rgb.shape, len(m.cells[0].data), sorted(gatun_py.render.__module__.split(".")))
    """)
    res = _run([env_dir / "bin" / "python", "-c", script], cwd, env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[0] == "8750" and "(24, 24, 3)" in res.stdout



def _usage_lines():
    """The README's Usage block, line by line, as argv lists (comments and `source` left out)."""
    import re
    import shlex

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    start = readme.index("## Usage")
    block = re.search(r"```sh\n(.*?)```", readme[start:], re.S).group(1)
    for line in block.splitlines():
        argv = shlex.split(line, comments=True)
        if argv and argv[0] != "source":
            yield line.split("#")[0].strip(), argv


def _cache_files(d: Path) -> set:
    return {p.relative_to(d) for p in d.rglob("*") if p.suffix in (".nbi", ".nbc")} if d.exists() else set()


def test_readme_walkthrough_from_the_wheel(installed, tmp_path):
    """A newcomer's first hour: the wheel in a fresh venv, an empty numba cache, every line of the
    README's Usage section in order from a folder holding the samples. Every line exits 0 and writes
    what it names; every line that compiled (numba's cache grew) said so on stderr, and none said so
    without compiling; after `tetc warmup` (the README's first line) no line compiles anything.
    Then the README's Python block, in the same folder."""
    import re

    env_dir, env, _, _ = installed
    env = dict(env, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"), TETC_COMPILE_NOTICE="1")
    # the Dask line: the README says to install Dask for it (make install does)
    res = _run([env_dir / "bin" / "python", "-m", "pip", "install", "-q", "dask[distributed]"], tmp_path, env)
    if res.returncode != 0:
        pytest.skip(f"cannot install dask without the package index: {res.stderr.strip()[-300:]}")
    cwd = tmp_path / "walk"
    cwd.mkdir()
    (cwd / "sample_meshes").symlink_to(ROOT / "sample_meshes")
    cache = Path(env["NUMBA_CACHE_DIR"])
    compiled_after_warmup = []
    warmed = False
    for line, argv in _usage_lines():
        assert argv[0] == "tetc", line
        before = _cache_files(cache)
        t0 = time.perf_counter()
        # generous: a loaded CI machine compiles the warm-up many times slower than two free cores
        res = _run([env_dir / "bin" / "tetc", *argv[1:]], cwd, env, timeout=3600)
        assert res.returncode == 0, f"{line}\n{res.stderr[-3000:]}"
        grew = _cache_files(cache) - before
        said = "tetc: compiling" in res.stderr
        print(f"{time.perf_counter() - t0:7.1f} s  compiled {len(grew):3d}  said {said!s:5}  {line}")  # -rA shows it
        if argv[1] != "warmup":
            assert said == bool(grew), f"{line}: compiled {len(grew)} kernels, said so: {said}\n{res.stderr[-2000:]}"
            if grew and warmed:
                compiled_after_warmup.append((line, sorted(str(p) for p in grew)[:5]))
        else:
            warmed = True
            assert "ready" in res.stderr and grew, res.stderr
        for opt in ("-o", "--png"):
            if opt in argv:
                out = argv[argv.index(opt) + 1]
                if "{frame}" in out:
                    assert len(list(cwd.glob(out.replace("{frame}", "*")))) >= 1, line
                else:
                    assert (cwd / out).stat().st_size > 0, line
        if "--json" in argv or "--stats" in argv:
            json.loads(res.stdout)
        if argv[1] == "compare":
            assert re.search(r'"ssim"', res.stdout), res.stdout
    # the warm-up covers the README: a kernel typed or reached differently on real data would show here
    # (gatun_py.warmup._readme runs the README's lines through the verbs on a tiny mesh)
    assert compiled_after_warmup == [], compiled_after_warmup
    code = (ROOT / "README.md").read_text(encoding="utf-8")
    code = re.search(r"The same from Python.*?```python\n(.*?)```", code, re.S).group(1)
    res = _run([env_dir / "bin" / "python", "-c", code], cwd, env, timeout=1200)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (cwd / "bf90_api.png").stat().st_size > 0 and (cwd / "bf99.tetc").stat().st_size > 0


def test_a_checkout_shadowing_the_wheel_uses_the_wheel_s_cache(installed, tmp_path):
    """`python` started in the repository root imports the checkout's gatun_py, not the installed
    one; numba keys its cache by source path, but the checkout's kernels (the same sources as the
    wheel's) load from the installed copy's cache: nothing compiles a second time."""
    env_dir, env, _, _ = installed
    cache = tmp_path / "cache"
    env = dict(env, NUMBA_CACHE_DIR=str(cache), TETC_COMPILE_NOTICE="1")
    py = env_dir / "bin" / "python"
    warm = "from gatun_py.warmup import _filter_on_mesh\n_filter_on_mesh()\n"
    res = _run([py, "-c", "import gatun_py\nassert 'site-packages' in gatun_py.__file__\n" + warm], tmp_path, env)
    assert res.returncode == 0, res.stderr
    cached = _cache_files(cache)
    assert cached, "the installed copy compiled nothing into NUMBA_CACHE_DIR"
    code = ("import gatun_py, gatun_py._compile_notice as n\n"
            "assert 'site-packages' not in gatun_py.__file__\n"
            "print(n.shadowed_install(), n.cache_twin())\n"
            "assert n.uncached(['filter']) == [], n.uncached(['filter'])\n"
            "n.watch()\n" + warm)
    res = _run([py, "-c", code], ROOT, env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("site-packages") == 2, res.stdout
    assert _cache_files(cache) == cached and "compiling" not in res.stderr, res.stderr
    res = _run([py, "-c", "import gatun_py._compile_notice as n; print(n.shadowed_install())"], tmp_path, env)
    assert res.returncode == 0 and res.stdout.strip() == "None", res.stdout + res.stderr
