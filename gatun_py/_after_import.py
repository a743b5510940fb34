"""Run a function right after a module is first imported, without importing it now.

``import gatun_py`` registers ``.tetc`` with meshio; importing meshio for that would cost every
command a second or more of start-up (meshio loads all its formats and its command line), before
the command could say anything. So registration waits until something imports meshio.
"""

from __future__ import annotations

import sys
import threading
import warnings

_lock = threading.Lock()


class _Loader:
    """The module's own loader, then ``then`` (importlib.abc not imported: start-up time)."""

    def __init__(self, loader, then):
        self._loader, self._then = loader, then

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        # the module sees its own loader, as without the hook
        module.__loader__ = self._loader
        if module.__spec__ is not None:
            module.__spec__.loader = self._loader
        self._loader.exec_module(module)
        try:
            self._then()
        except Exception as e:  # the import itself succeeded: a failed hook must not undo it
            warnings.warn(f"after importing {module.__name__}: {e!r}", RuntimeWarning, stacklevel=2)


class _Finder:
    def __init__(self, name, then):
        self.name, self.then = name, then

    def find_spec(self, fullname, path=None, target=None):
        if fullname != self.name:
            return None
        with _lock:
            if self not in sys.meta_path:
                return None
            sys.meta_path.remove(self)  # once; and the real finders find the spec below
        spec = None
        for finder in list(sys.meta_path):
            find = getattr(finder, "find_spec", None)
            spec = find(fullname, path, target) if find is not None else None
            if spec is not None:
                break
        if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _Loader(spec.loader, self.then)
        return spec


def after_import(name: str, then) -> None:
    """Call ``then()`` once ``name`` (a top-level module) is imported: now if it is already."""
    if name in sys.modules:
        then()
        return
    with _lock:
        sys.meta_path.insert(0, _Finder(name, then))
