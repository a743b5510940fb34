"""Names import as written: every module of gatun_py by its dotted name, and the CLI only through
the public verbs and :mod:`gatun_py._runtime`."""

from __future__ import annotations

import ast
import importlib.util
import json
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "gatun_py"
CLI = ROOT / "cli"

def _modules() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if "__pycache__" in parts:
            continue
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


MODULES = _modules()


def _failing_imports(names) -> dict:
    """{module: error} of the ``import a.b.c as m`` (which walks the attributes a.b.c) that fail or
    bind something else than the module, in a fresh interpreter: no import of the test session
    helps."""
    code = ("import importlib, json, sys\n"
            "bad = {}\n"
            "for name in sys.argv[1:]:\n"
            "    try:\n"
            "        exec(f'import {name} as m')\n"
            "        if m is not sys.modules[name]:\n"
            "            bad[name] = f'binds {m!r}'\n"
            "    except Exception as e:\n"
            "        bad[name] = f'{type(e).__name__}: {e}'\n"
            "print(json.dumps(bad))\n")
    p = subprocess.run([sys.executable, "-c", code, *names], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_the_walk_finds_every_stage():
    assert {"gatun_py.codec.formats", "gatun_py.codec.legacy.tets1", "gatun_py._runtime",
            "gatun_py.raycast.camera", "gatun_py.simplify.decimation"} <= set(MODULES)


def test_every_module_imports_by_its_dotted_name():
    assert _failing_imports(MODULES) == {}


def test_the_import_check_sees_a_bad_module():
    assert set(_failing_imports(["gatun_py.raycast.no_such_module", "gatun_py.codec.formats"])) == {
        "gatun_py.raycast.no_such_module"}


def test_the_verbs_and_the_stage_packages_have_their_own_names():
    """The verbs ``render`` and ``isosurface`` and the stages ``raycast`` and ``contour`` never meet."""
    code = ("import gatun_py, gatun_py.raycast.camera as c, gatun_py.contour.qem as q\n"
            "print(callable(gatun_py.render), callable(gatun_py.isosurface), c.__name__, q.__name__)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.stdout.split() == ["True", "True", "gatun_py.raycast.camera", "gatun_py.contour.qem"], p.stderr[-2000:]


def _private(module: str) -> bool:
    return any(part.startswith("_") for part in module.split(".")) and module != "gatun_py._runtime"


def _imported_modules(tree: ast.AST):
    """(line, module) of every gatun_py module a file imports, ``from pkg import mod`` included."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("gatun_py"):
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("gatun_py") and not node.level:
            yield node.lineno, node.module
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                if importlib.util.find_spec(node.module) is not None and _is_module(full):
                    yield node.lineno, full


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, AttributeError, ValueError):
        return False


def test_the_cli_imports_no_private_module():
    found = [f"{path.name}:{line}: {module}" for path in sorted(CLI.glob("*.py"))
             for line, module in _imported_modules(ast.parse(path.read_text(encoding="utf-8")))
             if _private(module)]
    assert found == []


def test_the_check_sees_a_private_import():
    tree = ast.parse("from gatun_py.codec import _cutborder_kernels\nimport gatun_py._atomic\n"
                     "from gatun_py._runtime import peak_rss_mb\nfrom gatun_py.codec import TetcReader\n")
    assert [m for _, m in _imported_modules(tree) if _private(m)] == ["gatun_py.codec._cutborder_kernels",
                                                                        "gatun_py._atomic"]
