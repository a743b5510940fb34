"""Process housekeeping in one place: memory probes, numba's cache, loading the kernels ahead, and
handing memory back to the system.

* :func:`peak_rss_mb`, :func:`rss_mb`: the figures ``--stats`` and the benchmarks report.
* :func:`kernels_cached`, :func:`render_kernels_cached`: whether numba's cache holds a run's
  kernels already (a first run on a fresh install compiles them ahead, on two cores).
* :func:`compile_for_render`, :func:`load_render_kernels`, :func:`load_isosurface_kernels`: the
  warm-up hooks a command calls before it opens the user's file (:mod:`gatun_py.warmup`,
  :func:`gatun_py.contour.extract.load_kernels`), imported when called.
* :func:`release_code_pages`, :func:`trim_heap`: resident pages of LLVM's code and of the C heap
  handed back.

Importing this module is cheap (no numba): the CLI imports it before it parses its options.
"""

from __future__ import annotations

import ctypes
import functools
import os
import resource
import sys
from pathlib import Path

from ._compile_notice import announce, is_tetc, silence  # noqa: F401  (the CLI's first-run notice)
from ._atomic import check_output_path  # noqa: F401  (the CLI's check before the work, with the rest it runs first)


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MB.

    Linux's VmHWM belongs to the current program image; ``ru_maxrss`` survives ``exec`` and so
    reports the parent's peak for a process started from a big one (a benchmark driver).
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


#: the shared library whose code pages :func:`release_code_pages` hands back: numba's LLVM (~170 MB
#: of machine code and constants, of which loading and linking the kernels touch scattered pages)
_CODE_LIBRARY = "libllvmlite"
_MADV_DONTNEED = 4  # <sys/mman.h> on Linux (all architectures)


@functools.cache
def _clean_library_ranges(library: str) -> tuple:
    """(start, length) of the read-only mappings of ``library`` that hold no private (copied) page.

    Such a mapping is the file's own bytes: text and constants. A mapping with a copied page (the
    relocated constants, RELRO) would lose its relocations to MADV_DONTNEED, so it is left out;
    writable mappings too. A library is never remapped once loaded, so the answer is cached.
    """
    ranges, current = [], None
    try:
        with open("/proc/self/smaps") as fh:
            for line in fh:
                head = line.split(None, 5)
                if "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                    lo, _, hi = head[0].partition("-")
                    path = head[5].strip() if len(head) > 5 else ""
                    current = None
                    if library in path.rsplit("/", 1)[-1] and "w" not in head[1]:
                        current = [int(lo, 16), int(hi, 16) - int(lo, 16)]
                elif current is not None and head[0] == "Anonymous:":
                    if int(head[1]) == 0:
                        ranges.append(tuple(current))
                    current = None
    except (OSError, ValueError, IndexError):
        return ()
    return tuple(ranges)


@functools.cache
def _madvise():
    try:
        fn = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, TypeError, AttributeError):
        return None
    fn.argtypes, fn.restype = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int], ctypes.c_int
    return fn


def release_code_pages() -> None:
    """Unmap the resident pages of numba's LLVM library that the process is not using (Linux).

    Why: the kernel maps a file's pages in 64 kB runs around every page touched, and LLVM's static
    constructors (at ``import numba``) and its object linker (when a cached kernel loads) touch
    pages all over its 80 MB of code: ~90 MB of the library end up resident, more than all of our
    data on a small file, and they count in the peak resident memory of every run. They are clean
    pages of the file: MADV_DONTNEED only drops them from this process's page table (they stay in
    the page cache), and a page used again comes back on a minor fault, so the cost is a few
    milliseconds. Call it once the kernels a run needs are loaded (loading more touches the linker
    again). Only read-only mappings without copied pages are touched (see _clean_library_ranges);
    where /proc or madvise is missing nothing happens.
    """
    if "llvmlite.binding" not in sys.modules:  # not loaded: nothing resident
        return
    fn = _madvise()
    if fn is None:
        return
    for start, length in _clean_library_ranges(_CODE_LIBRARY):
        fn(start, length, _MADV_DONTNEED)


def rss_mb() -> float:
    """Resident memory now (not the peak) in MB; 0 where /proc is absent."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library has none (macOS, Windows, musl)."""
    try:
        fn = ctypes.CDLL(None).malloc_trim
    except (OSError, TypeError, AttributeError):
        return None
    fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
    return fn


def trim_heap() -> None:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``; elsewhere nothing).

    Why: freeing a large transient early in a stream (the connectivity decoder's table of refs, the
    boundary's border queue) raises glibc's dynamic mmap threshold to its size and the trim
    threshold to twice that. From then on the per-batch arrays, allocated and freed by several
    threads, come from the arenas, and their freed pages stay resident at the peak. A call costs
    about a millisecond, and it changes no allocator setting of the process (``mallopt`` would,
    for the user's code too).
    """
    fn = _malloc_trim()
    if fn is not None:
        fn(0)


def kernels_cached(*modules) -> bool:
    """Whether numba's cache holds compiled kernels of every one of ``modules``."""
    import numba  # start-up time: options are parsed, and usage errors reported, before numba loads

    def cached(module) -> bool:
        src = Path(module.__file__)
        if numba.config.CACHE_DIR:  # NUMBA_CACHE_DIR: one folder per source folder, "<name>_<hash>"
            dirs = list(Path(numba.config.CACHE_DIR).glob(f"{src.parent.name}_*"))
        else:
            dirs = [src.parent / "__pycache__"]
        return any(any(d.glob(f"{src.stem}.*.nbc")) for d in dirs)

    return all(cached(m) for m in modules)


def render_kernels_cached(*, decoder: bool, simplify: bool = False) -> bool:
    """Whether numba has compiled the render kernels (with ``decoder`` today's decoder's, with
    ``simplify`` the forest decoder's and the filter's) into its cache already."""
    from .codec import _cutborder_kernels, _forest_kernels, _geometry_kernels
    from .raycast import _walk
    from .simplify import _filter_kernels

    return kernels_cached(_walk, *((_cutborder_kernels, _geometry_kernels) if decoder else ()),
                          *((_forest_kernels, _filter_kernels) if decoder and simplify else ()))


def compile_for_render(**kwargs) -> float:
    """:func:`gatun_py.warmup.compile_for_render`: compile a render's kernels on two cores."""
    from .warmup import compile_for_render as compile_

    return compile_(**kwargs)


def load_render_kernels(**kwargs) -> float:
    """:func:`gatun_py.warmup.load_kernels`: load a render's kernels before the user's file."""
    from .warmup import load_kernels

    return load_kernels(**kwargs)


def load_isosurface_kernels(source=None, **kwargs) -> float:
    """:func:`gatun_py.contour.extract.load_kernels`: load an extraction's kernels first."""
    from .contour.extract import load_kernels

    return load_kernels(source, **kwargs)
