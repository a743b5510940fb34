"""Lazy names for a package (PEP 562), as scikit-image's ``lazy_loader.attach`` does.

A package lists which submodule defines each public name; the submodule is imported on first access.
Used where importing eagerly would load numba and the kernels for nothing (``import gatun_py``,
``gatun_py.render``, ``gatun_py.isosurface``), so that commands answer ``--help`` at once.
"""

from __future__ import annotations

import importlib
import sys


def attach(package: str, names: dict[str, str]):
    """``(__getattr__, __dir__, __all__)`` for ``package``; ``names`` maps a public name to the
    submodule (relative to the package, e.g. ``"camera"`` or ``"contour.extract"``) defining it."""

    def __getattr__(name):
        if name in names:
            value = getattr(importlib.import_module(f".{names[name]}", package), name)
            setattr(sys.modules[package], name, value)  # later lookups skip this function
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__, sorted(names)
