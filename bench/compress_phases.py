"""Peak resident memory and time of each phase of ``tetc compress`` in one process.

    python bench/compress_phases.py MESH.vtu [OUT.tetc] [--levels]

Without ``--levels`` the compress is ``--mesh-only``; with it, the default compress with every
level: the decimation, the levels' meshes (``build_levels``), each level's encoding and its
forest section are phases too (the encoding phases then sum over the levels; phases that run in
threads beside others overlap in wall time, and their peaks are the process's while they ran).

Each phase (reading with meshio, validation and its parts, the encoder's face pairing, boundary
and tet coding, geometry, metadata, container, write) is wrapped where the pipeline calls it.
The process's high-water mark (``VmHWM``) is read and reset (``/proc/self/clear_refs``) whenever a
phase starts or ends, so each phase is charged the highest resident set seen while it (or a phase
inside it) ran: numba kernels hold the GIL, so a sampling thread would miss their peaks. Linux only.
"""

from __future__ import annotations

import importlib
import sys
import tempfile
import threading
import time
from pathlib import Path

# (module where the pipeline looks the function up, attribute, label), outermost first
PHASES = [
    ("gatun_py.mesh.io", "_meshio_read", "read (meshio)"),
    ("gatun_py.api", "decimate", "decimation (merge forest)"),
    ("gatun_py.api", "build_levels", "level meshes (build_levels)"),
    ("gatun_py.api", "write_tetc", "encode and write the levels"),
    ("gatun_py.codec.tetcfile", "encode_level", "  encode one level (sum)"),
    ("gatun_py.mesh.io", "validate_tets", "validation"),
    ("gatun_py.mesh.validate", "check_tet_ids", "  ids, sorted rows"),
    ("gatun_py.mesh.validate", "face_multiplicity", "  face multiplicity"),
    ("gatun_py.mesh.validate", "signed_volumes", "  signed volumes"),
    ("gatun_py.codec.tetcfile", "check_mesh", "encoder's mesh check"),
    ("gatun_py.codec.tetcfile", "encode_connectivity", "connectivity"),
    ("gatun_py.codec._cutborder_kernels", "tet_neighbours", "  face pairing"),
    ("gatun_py.codec._cutborder_kernels", "boundary_from_neighbours", "  boundary faces"),
    ("gatun_py.codec.cutborder", "_sorted_halfedges", "  boundary half-edges"),
    ("gatun_py.codec._cutborder_kernels", "encode_boundary", "  boundary code"),
    ("gatun_py.codec._cutborder_kernels", "encode_tets", "  tet code"),
    ("gatun_py.codec.tetcfile", "encode_geometry", "geometry"),
    ("gatun_py.codec.tetcfile", "encode_array", "other arrays"),
    ("gatun_py.codec.tetcfile", "_encode_level_forest", "forest section"),
    ("gatun_py.codec.tetcfile", "file_meta", "file metadata"),
    ("gatun_py.codec.tetcfile", "build_container", "container"),
    ("gatun_py.codec.tetcfile", "write_bytes_atomic", "write"),
]


class PhaseMeter:
    def __init__(self):
        # open phases per thread (levels may be encoded in threads): a peak is charged to every
        # phase open in any thread at the time
        self.stacks: dict[int, list[str]] = {threading.get_ident(): ["(outside the phases)"]}
        self.lock = threading.Lock()
        self.peak_mb: dict[str, float] = {}
        self.seconds: dict[str, float] = {}
        self.cpu: dict[str, float] = {}  # process CPU while the phase ran (every thread's)

    def flush(self):
        """Charge the high-water mark since the last flush to every open phase, then reset it."""
        with open("/proc/self/status") as f:
            hwm = next(int(line.split()[1]) for line in f if line.startswith("VmHWM")) / 1024
        for stack in self.stacks.values():
            for label in stack:
                self.peak_mb[label] = max(self.peak_mb.get(label, 0.0), hwm)
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    def wrap(self, module: str, attr: str, label: str):
        mod = importlib.import_module(module)
        inner = getattr(mod, attr)

        def phase(*args, **kwargs):
            me = threading.get_ident()
            with self.lock:
                self.flush()
                self.stacks.setdefault(me, []).append(label)
            t, c = time.perf_counter(), time.process_time()
            try:
                return inner(*args, **kwargs)
            finally:
                with self.lock:
                    self.seconds[label] = self.seconds.get(label, 0.0) + time.perf_counter() - t
                    self.cpu[label] = self.cpu.get(label, 0.0) + time.process_time() - c
                    self.flush()
                    self.stacks[me].pop()

        setattr(mod, attr, phase)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 2
    with_levels = "--levels" in argv
    argv = [a for a in argv if a != "--levels"]
    import gatun_py

    meter = PhaseMeter()
    for module, attr, label in PHASES:
        meter.wrap(module, attr, label)
    with tempfile.TemporaryDirectory() as td:
        out = argv[1] if len(argv) > 1 else str(Path(td) / "out.tetc")
        t0 = time.perf_counter()
        c0 = time.process_time()
        gatun_py.compress(argv[0], out, mesh_only=not with_levels, force=True)
        cpu = time.process_time() - c0
        total = time.perf_counter() - t0
    meter.flush()
    print("| phase | peak RSS MB | wall s | CPU s |\n|---|---|---|---|")
    for _, _, label in PHASES:
        if label in meter.seconds:
            print(f"| {label} | {meter.peak_mb[label]:.0f} | {meter.seconds[label]:.2f} | {meter.cpu[label]:.2f} |")
    print(f"| whole compress (in process) | {max(meter.peak_mb.values()):.0f} | {total:.2f} | {cpu:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
