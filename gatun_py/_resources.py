"""Process resource figures reported by ``--stats`` and the benchmarks."""

from __future__ import annotations

import ctypes
import functools
import resource
import sys


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
