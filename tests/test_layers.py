"""The package's shape: imports point down the pipeline, and the install names every package.

The stages and what each may import (besides the standard library and third-party packages):

* base: ``gatun_py.errors``, ``gatun_py._atomic``, ``gatun_py._runtime``, ``gatun_py._compile_notice``
  (anyone may import them)
* mesh: base
* codec: mesh
* simplify: codec, mesh
* raycast: mesh
* the stages built on the pipeline's products (contour: mesh, codec, simplify, raycast's preview)
* pipeline: every stage
* the top (``api``, ``meshio_format``, ``warmup``, ``viewer``, ``gatun_py/__init__``), then the CLI.

Every import counts, at module level or inside a function: a function-local import does not make a
cycle legal, it only hides it until run time.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "gatun_py"
CLI = ROOT / "cli"

BASE = {"errors", "_atomic", "_runtime", "_version", "_lazy", "limits", "read_options", "_compile_notice", "_after_import"}
# gatun_py._runtime imports no stage itself; its hooks import, when called, the stages whose kernels
# they probe in numba's cache or load ahead of a run (and numba)
HOOKS = "_runtime"
# stage -> the stages it may import (base always allowed)
ALLOWED = {
    "mesh": {"mesh"},
    "codec": {"codec", "mesh"},
    "simplify": {"simplify", "codec", "mesh"},
    "raycast": {"raycast", "mesh"},
    "contour": {"contour", "simplify", "codec", "mesh", "raycast"},
    "pipeline": {"pipeline", "simplify", "codec", "mesh", "raycast", "contour"},
}
TOP = {"api", "meshio_format", "pyvista_reader", "warmup", "viewer", "paraview", "__init__", "cli", "bricks"}
# function-local imports that are allowed, and why (module, imported name prefix)
LOCAL_OK_REASONS = {
    "matplotlib": "optional dependency",
    "scipy": "start-up time (1.1 s; only hexahedral inputs need it)",
    "skimage": "start-up time (1 s; only image comparison needs it)",
    "vtk": "optional dependency",
    "vtkmodules": "optional dependency",
    "netCDF4": "optional dependency (Exodus input)",
    "h5py": "optional dependency",
    "pyvista": "optional dependency",
    "selenium": "optional dependency",
    "aiohttp": "optional dependency",
    "dask": "optional dependency",
    "distributed": "optional dependency",
    "gmsh": "optional dependency",
    "meshio": "meshio's private table of cell dimensions, guarded: another meshio layout has none; "
              "start-up time (1-3 s): a command says that it compiles before anything loads meshio",
    "PIL": "image I/O only where images are read",
    "paraview": "the ParaView plugin's decorators, present only in ParaView's own Python",
    "numpy": "the ParaView plugin, guarded: a ParaView built without numpy gets VTKHDF files instead",
    "numba": "start-up time: the first-run compile notice is said before numba loads (gatun_py._compile_notice)",
}


# gatun_py modules that may be imported inside a function, and why
LOCAL_OK_MODULES = {
    "viewer.server": "needs the optional aiohttp: imported only when the viewer starts",
    "codec.legacy": "the frozen codings of old formats: a file of today's format never compiles them",
    "api": "start-up time: meshio's .tetc reader and writer load the verbs (and numba) when first called",
    "codec.cells": "start-up time: meshio's .tetc reader loads the codec when first called",
    "mesh.io": "start-up time: meshio's .tetc writer loads the mesh writers when first called",
    "meshio_format": "start-up time: import gatun_py registers .tetc once meshio is imported, not by importing it",
    # an isosurface extraction loads the renderer (and PIL) only when a preview is asked for
    "raycast.camera": "memory and start-up of an isosurface without a preview",
    "raycast.image": "memory and start-up of an isosurface without a preview",
    "raycast.surface": "memory and start-up of an isosurface without a preview",
}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path, path.relative_to(PACKAGE).with_suffix("").parts


def _stage(parts) -> str:
    return parts[0] if len(parts) > 1 else parts[0]


def _imports(path: Path, parts):
    """(line, absolute target module parts below gatun_py or None, top-level name, is_local) per import."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    top_level = {id(n) for n in tree.body}
    package = list(parts[:-1]) if parts[-1] != "__init__" else list(parts[:-1])
    for node in ast.walk(tree):
        local = id(node) not in top_level
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name.split(".")
                inside = name[1:] if name[0] == "gatun_py" else None
                yield node.lineno, inside, name[0], local
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                target = base + (node.module.split(".") if node.module else [])
                if not node.module:  # from . import a, b
                    for alias in node.names:
                        yield node.lineno, target + [alias.name], "gatun_py", local
                    continue
                yield node.lineno, target, "gatun_py", local
            else:
                name = (node.module or "").split(".")
                inside = name[1:] if name[0] == "gatun_py" else None
                if inside == [] and node.names:
                    for alias in node.names:
                        yield node.lineno, [alias.name], "gatun_py", local
                    continue
                yield node.lineno, inside, name[0], local


def _violations():
    out = []
    for path, parts in _modules():
        stage = _stage(parts)
        for line, target, top, local in _imports(path, parts):
            where = f"{path.relative_to(ROOT)}:{line}"
            if local and stage == HOOKS:
                continue
            if target is None:
                if local and top not in LOCAL_OK_REASONS and top not in {"__future__"}:
                    out.append(f"{where}: function-local import of {top} without a stated reason")
                continue
            if local and ".".join(target) not in LOCAL_OK_MODULES:
                out.append(f"{where}: function-local import of gatun_py.{'.'.join(target)}")
            dest = target[0] if target else "__init__"
            if dest in BASE or stage in TOP:
                continue
            if stage in BASE:
                out.append(f"{where}: base module imports gatun_py.{'.'.join(target)}")
            elif stage in ALLOWED and dest not in ALLOWED[stage]:
                out.append(f"{where}: {stage} imports {dest} (allowed: {', '.join(sorted(ALLOWED[stage]))})")
            elif stage not in ALLOWED:
                out.append(f"{where}: module of unknown stage {stage!r}: add it to tests/test_layers.py")
    return out


def test_imports_point_down_the_pipeline():
    assert _violations() == []


def test_cli_imports_only_the_library():
    """The CLI parses and calls the verbs: it may import gatun_py, never be imported by it."""
    for path, parts in _modules():
        text = path.read_text(encoding="utf-8")
        assert "gatun_py.cli" not in text or parts[0] == "cli", path
    for path in CLI.glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module == "cli":
                pytest.fail(f"{path}: imports the bare top-level name 'cli'")


def test_checker_catches_a_violation(tmp_path, monkeypatch):
    """The checker itself: an upward import, hidden in a function, is reported."""
    fake = tmp_path / "gatun_py"
    (fake / "codec").mkdir(parents=True)
    (fake / "codec" / "x.py").write_text("def f():\n    from ..raycast import caster\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", fake)
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    found = _violations()
    assert any("codec imports raycast" in v for v in found) and any("function-local" in v for v in found)


def test_install_names_every_package():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    on_disk = {".".join(("gatun_py",) + p.parent.relative_to(PACKAGE).parts).rstrip(".")
               for p in PACKAGE.rglob("__init__.py")}
    on_disk = {p if p != "gatun_py." else "gatun_py" for p in on_disk} | {"gatun_py.cli"}
    assert on_disk == listed
    assert cfg["package-dir"] == {"gatun_py.cli": "cli"}
    assert not (PACKAGE / "cli").exists(), "gatun_py/cli must come from ./cli through package-dir, not a link"
