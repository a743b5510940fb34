"""Saying so, once per process and on stderr, when a run is about to compile numba kernels.

numba compiles a kernel on its first call after an install and caches it on disk; a first run can
sit in compilation for a minute or two. Two mechanisms, so that no compile goes unannounced:

* :func:`announce` (the commands, at their start): probes numba's on-disk cache for the kernels a
  command runs, by file name, without importing numba or the kernels (that alone takes a second),
  and prints the notice with an estimate when one is missing;
* :func:`watch` (the library verbs, and the commands as a fallback): a numba event listener that
  prints the notice when a compilation actually starts and none was printed yet (a kernel the
  probe does not know of, another argument type, a stale cache).

``TETC_COMPILE_NOTICE=0`` silences both (the test suite does, so its output checks do not depend
on what the cache holds); the commands' ``--quiet`` does too.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import os
import sys
import threading
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent

# The kernels each part of the pipeline calls first ("module relative to gatun_py": names): the
# probe's evidence that the part is compiled. Not every kernel (their callees compile with them);
# tests/test_compile_notice.py checks that each is a cached numba kernel of that module.
PARTS = {
    "encoder": {"codec._cutborder_kernels": ("_encode_tets_run", "encode_boundary", "tet_neighbours"),
                "codec._geometry_kernels": ("encode_kernel",), "codec.rangecoder": ("enc_sym",)},
    "decimation": {"simplify._decimate_kernels": ("_run_rounds", "_accumulate_quadrics", "_vertex_topology"),
                   "codec._forest_kernels": ("encode_rounds3_kernel",)},
    "dependencies": {"simplify._dependency_kernels": ("_dependencies",)},
    "decoder": {"codec._cutborder_kernels": ("_decode_tets_run", "decode_boundary"),
                "codec._geometry_kernels": ("_decode_vertices_run",), "codec.rangecoder": ("dec_init",)},
    "forest decoder": {"codec._forest_kernels": ("decode_rounds3_kernel",),
                       "simplify._forest_kernels": ("ancestors_kernel",)},
    "filter": {"simplify._filter_kernels": ("filter_items",)},
    "renderer": {"raycast._walk": ("advance", "settle"), "raycast._boundary": ("_boundary_hits",),
                 "raycast._facetable": ("insert_tets",)},
    "isosurface": {"contour.marching": ("extract_batch",), "contour.qem": ("decimate",)},
}

# Seconds of compiling per part on two cores in one process (the first run of a command compiles
# its parts one after the other, unless the command compiles them side by side, as render does),
# from first runs with an empty cache on a quiet machine (bench/sections/first_run.md); a loaded
# machine takes longer.
SECONDS = {"encoder": 35, "decimation": 70, "dependencies": 5, "decoder": 22, "forest decoder": 10, "filter": 5,
           "renderer": 15, "isosurface": 15}

TETC_MAGIC = b"TETC\x89\r\n\x1a"  # gatun_py.codec.container.MAGIC (a test keeps them equal): not imported
# from there, since the codec's package loads numba and its kernels


def is_tetc(path) -> bool:
    """Whether ``path`` is a ``.tetc`` file: its first bytes are the magic (a file that cannot be
    opened, or a path of no file yet, by its suffix)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(TETC_MAGIC)) == TETC_MAGIC
    except (OSError, TypeError):
        return str(path).lower().endswith(".tetc")


_lock = threading.Lock()
_said = False


def enabled() -> bool:
    return os.environ.get("TETC_COMPILE_NOTICE", "1").strip().lower() not in ("0", "no", "false", "off")


def silence() -> None:
    """No notice from this process from now on (``--quiet``)."""
    global _said
    with _lock:
        _said = True


@functools.lru_cache(maxsize=None)
def shadowed_install() -> str | None:
    """Where the installed gatun_py is, when this process imported another copy: a source checkout
    in the working folder (``python`` puts it first on the path) shadowing a plain ``pip install``;
    None otherwise (an editable install is the checkout itself). Found on ``sys.path`` as the import
    system would without the checkout (importlib.metadata would cost a command's start-up a tenth
    of a second)."""
    root = PACKAGE_DIR.parent
    if not (root / "pyproject.toml").is_file():
        return None
    try:
        paths = [p for p in sys.path if Path(p or ".").resolve() != root]
        spec = importlib.machinery.PathFinder.find_spec("gatun_py", paths)
        if spec is None or not spec.submodule_search_locations:
            return None
        installed = Path(next(iter(spec.submodule_search_locations))).resolve()
    except (OSError, ValueError, ImportError):
        return None
    return str(installed) if installed != PACKAGE_DIR and (installed / "__init__.py").is_file() else None


def say(text: str) -> bool:
    """Print ``text`` on stderr unless a notice was printed already (or notices are off); whether it was."""
    global _said
    with _lock:
        if _said or not enabled():
            return False
        _said = True
    installed = shadowed_install()
    if installed and cache_twin() is None:
        text += (f"\ntetc: note: this Python imported gatun_py from the checkout {PACKAGE_DIR.parent}, not the "
                 f"installed package ({installed}), whose kernels' sources differ, so they compile a second time; "
                 "run Python from another folder, or install the checkout editable (pip install -e ., as make "
                 "install does)")
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass
    return True


# -- one cache for a checkout and its installed copy ----------------------------------------------

@functools.lru_cache(maxsize=None)
def cache_twin() -> Path | None:
    """The installed gatun_py whose numba cache this process's kernels use instead of their own: when
    this process imported a checkout (``python`` started in the repository root) that shadows a
    plain ``pip install`` of the same kernels (every module that uses numba byte for byte the same).
    numba keys its cache by the source file's path, so without this the checkout would compile
    everything a second time. None otherwise (the kernels then cache as numba places them)."""
    installed = shadowed_install()
    if installed is None:
        return None
    twin = Path(installed)
    try:
        for source in PACKAGE_DIR.rglob("*.py"):
            data = source.read_bytes()
            # all of them: a kernel inlines the kernels it calls from other modules into its own
            # cached code, so one differing callee makes every cached caller wrong
            if b"numba" in data and (twin / source.relative_to(PACKAGE_DIR)).read_bytes() != data:
                return None
    except OSError:
        return None
    return twin


def _cached_as(source: Path) -> Path:
    """The file whose numba cache holds the kernels of ``source`` (its installed twin, see
    :func:`cache_twin`, or itself)."""
    twin = cache_twin()
    if twin is not None:
        try:
            return twin / source.resolve().relative_to(PACKAGE_DIR)
        except ValueError:
            pass
    return source


def share_installed_cache() -> bool:
    """When :func:`cache_twin` names an installed copy, make numba cache this checkout's kernels
    where it caches that copy's (before any kernel module is imported: numba finds a kernel's cache
    when it is decorated); whether it does. Costs nothing (no numba import) otherwise."""
    if cache_twin() is None:
        return False
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    if any(getattr(c, "tetc_twin", False) for c in impl._locator_classes):
        return True
    defaults = list(impl._locator_classes)

    class InstalledTwinLocator:
        """numba's own locators, handed the installed twin of a gatun_py source file."""

        tetc_twin = True

        @classmethod
        def from_function(cls, py_func, py_file):
            twin = _cached_as(Path(py_file))
            if twin == Path(py_file):
                return None
            for locator in defaults:
                found = locator.from_function(py_func, str(twin))
                if found is not None:
                    return found
            return None

    impl._locator_classes.insert(0, InstalledTwinLocator)
    return True


# -- the probe ------------------------------------------------------------------------------------

def _cache_dirs(source: Path) -> list[Path]:
    """Where numba keeps the cache of the kernels of ``source`` (as numba.core.caching locates it)."""
    parent = source.parent
    sub = f"{parent.name}_{hashlib.sha1(str(parent).encode()).hexdigest()}"
    user_dir = os.environ.get("NUMBA_CACHE_DIR")
    if user_dir:
        return [Path(user_dir) / sub]
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    in_tree = parent / "__pycache__"
    user_wide = Path(xdg) / "numba" / sub
    return [in_tree, user_wide] if os.access(parent, os.W_OK) else [user_wide]


def _kernel_cached(module: str, name: str) -> bool:
    source = _cached_as(PACKAGE_DIR.joinpath(*module.split(".")).with_suffix(".py"))
    try:
        mtime = source.stat().st_mtime
    except OSError:
        return True  # not ours to judge
    for d in _cache_dirs(source):
        try:
            # an index older than its source is stale (numba keys it by the source's contents)
            if any(p.stat().st_mtime >= mtime for p in d.glob(f"{source.stem}.{name}-*.nbi")):
                return True
        except OSError:
            continue
    return False


def uncached(parts) -> list[str]:
    """Those of ``parts`` (names of :data:`PARTS`) whose kernels numba's cache does not hold."""
    return [part for part in parts
            if not all(_kernel_cached(m, n) for m, names in PARTS[part].items() for n in names)]


def _describe(parts: list[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def estimate_s(parts, *, side_by_side: bool = False) -> float:
    """Seconds to compile ``parts`` on two cores: their sum, or with ``side_by_side`` (two processes)
    half of it but at least the longest part."""
    s = [SECONDS[p] for p in parts]
    return max(max(s), sum(s) / 2) if side_by_side and s else float(sum(s))


def _about(seconds: float) -> str:
    return f"about {seconds:.0f} s" if seconds < 90 else f"about {seconds / 60:.0f} min"


def announce(parts, *, side_by_side: bool = False, quiet: bool = False) -> list[str]:
    """Say once, on stderr, that this run compiles (with an estimate) when numba's cache lacks the
    kernels of any of ``parts``; returns the parts missing. ``quiet``: say nothing, now or later."""
    missing = uncached(parts)
    if quiet:
        silence()
    elif missing:
        say(f"tetc: compiling the {_describe(missing)} for this machine (first run only, "
            f"{_about(estimate_s(missing, side_by_side=side_by_side))} on two cores; "
            "`tetc warmup` compiles everything ahead)...")
    watch()
    return missing


def worker_initargs() -> tuple:
    """``initargs`` of a process pool whose ``initializer`` is :func:`worker_init`: whether this
    process said its notice already (or was told not to)."""
    return (_said,)


def worker_init(parent_said: bool) -> None:
    """In a worker process (spawned: it shares no state with its parent): say the notice if the
    worker compiles and the parent has not said it (its probe found the parts cached, but the
    workers' arguments need another compilation)."""
    if parent_said:
        silence()
    else:
        watch()


# -- the fallback: numba's compile event ----------------------------------------------------------

_watching = False


def watch() -> None:
    """From now on, the first numba compilation in this process prints a notice (if none was)."""
    global _watching
    if _watching or not enabled():
        return
    from numba.core import event  # the verbs load numba anyway; this module must not on import

    class _Listener(event.Listener):
        def on_start(self, ev):
            if _said:
                return
            try:
                fn = ev.data["dispatcher"].py_func
                what = f"{fn.__module__.removeprefix('gatun_py.')}.{fn.__qualname__}"
            except (KeyError, AttributeError):
                what = "kernels"
            say(f"tetc: compiling numba kernels ({what} first) for this machine: a first run takes "
                "up to a few minutes; later runs load them from the cache (`tetc warmup` compiles "
                "everything ahead)...")

        def on_end(self, ev):
            pass

    with _lock:
        if not _watching:
            event.register("numba:compile", _Listener())
            _watching = True
