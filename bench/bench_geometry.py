"""Lossless geometry + density coding (gatun_py.codec.geometry) against xz -9 and fpzip.

Run: ``python bench/bench_geometry.py [--quick]``  →  ``bench/sections/geometry.md``,
``bench/figures/geometry_bits.png``.

Vertices are coded in the real decode order of the cut-border connectivity coder
(``encode_connectivity``), with its predictor refs. Peers run in the same process on the same
arrays: ``lzma`` preset 9 (= ``xz -9``) and ``fpzip`` (lossless, precision 0) on the float32
coordinates and density in the file's original order (what a user would compress), plus xz in
decode order for reference. ``--quick`` does one timing repetition instead of three.
"""

from __future__ import annotations

import lzma
import os
import sys
import time

import numpy as np

from common import FIGURES, SAMPLE_FILES, load, table, write_section

COMMAND = "python bench/bench_geometry.py"


def _xz(arr: np.ndarray) -> int:
    return len(lzma.compress(np.ascontiguousarray(arr).tobytes(), preset=9))


def _fpzip_bytes(points: np.ndarray, density: np.ndarray):
    """fpzip lossless size of the coordinates (best of interleaved and planar layout) and density."""
    try:
        import fpzip
    except ImportError:
        return None
    inter = len(fpzip.compress(np.array(points, order="C"), precision=0))
    planar = len(fpzip.compress(np.array(points.T, order="C"), precision=0))
    return min(inter, planar), len(fpzip.compress(np.array(density), precision=0))


# CPU time of this (single-threaded) process: the benchmark machine is shared by other jobs, and
# wall time under load mostly measures the neighbours.
_clock = time.process_time


def _fpzip_decode_seconds(points, density, repeat):
    try:
        import fpzip
    except ImportError:
        return None
    a = fpzip.compress(np.array(points.T, order="C"), precision=0)
    b = fpzip.compress(np.array(density), precision=0)
    best = np.inf
    for _ in range(max(repeat, 3)):
        t0 = _clock()
        for _ in range(10):  # one run is too short for the process clock
            fpzip.decompress(a)
            fpzip.decompress(b)
        best = min(best, (_clock() - t0) / 10)
    return best


def _best(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = _clock()
        out = fn()
        best = min(best, _clock() - t0)
    return best, out


def _stream_decode(blob, refs, n, batch=4096):
    from gatun_py.codec.geometry import GeometryDecoder

    dec = GeometryDecoder(blob, n_points=n)
    for s in range(0, n, batch):
        dec.decode(refs[s:s + batch])
    dec.finish()
    return dec


def main(argv: list[str]) -> None:
    from gatun_py.codec.cutborder import encode_connectivity
    from gatun_py.codec.geometry import encode_geometry, geometry_stream_sizes

    quick = "--quick" in argv
    repeat = 1 if quick else 3
    size_rows, file_rows, speed_rows, ablation_rows, plot = [], [], [], [], {}
    warm = False
    for name in SAMPLE_FILES:
        mesh, _ = load(name)
        n, m = mesh.n_points, mesh.n_tets
        points, density, tets = mesh.points, mesh.density, mesh.tets
        conn = encode_connectivity(n, tets)
        order, refs = conn.vertex_order, conn.predictors
        p_dec = np.ascontiguousarray(points[order])
        d_dec = np.ascontiguousarray(density[order])
        if not warm:  # compile outside the timings
            _stream_decode(encode_geometry(p_dec, d_dec, refs), refs, n)
            warm = True
        t_enc, blob = _best(lambda: encode_geometry(p_dec, d_dec, refs), repeat)
        t_dec, dec = _best(lambda: _stream_decode(blob, refs, n), repeat)
        ok = (np.array_equal(dec.points.view(np.int32), p_dec.view(np.int32))
              and np.array_equal(dec.density.view(np.int32), d_dec.view(np.int32)))
        sizes = geometry_stream_sizes(blob)
        bpv = 8 * len(blob) / n
        xz_file = 8 * (_xz(points) + _xz(density)) / n
        xz_dec = 8 * (_xz(p_dec) + _xz(d_dec)) / n
        fp = _fpzip_bytes(points, density)
        fp_bpv = 8 * sum(fp) / n if fp else float("nan")
        modes = "/".join(sizes[c + "_mode"][0] for c in ("x", "y", "z", "density"))
        size_rows.append([name, n, len(blob), round(bpv, 2),
                          " / ".join(f"{8 * sizes[c] / n:.2f}" for c in ("x", "y", "z", "density")), modes,
                          round(xz_file, 2), round(xz_dec, 2), round(fp_bpv, 2),
                          f"{bpv / xz_file:.2f}", f"{bpv / fp_bpv:.2f}" if fp else "n/a",
                          "yes" if ok else "NO"])
        plot[name] = (bpv, xz_file, fp_bpv)

        conn_bytes = len(conn.boundary_code) + len(conn.tet_code)
        xz_sum = _xz(points) + _xz(density) + _xz(tets)
        total = conn_bytes + len(blob)
        file_rows.append([name, f"{conn_bytes / 1e3:.1f}", round(8 * conn_bytes / m, 2), f"{len(blob) / 1e3:.1f}",
                          f"{total / 1e3:.1f}", f"{xz_sum / 1e3:.1f}", f"{total / xz_sum:.3f}",
                          "met" if total <= 0.5 * xz_sum else "missed"])

        if name in ("bluntfin", "combustion"):
            t_fp = _fpzip_decode_seconds(points, density, repeat)
            speed_rows.append([name, n, round(n / t_enc / 1e6, 3), round(n / t_dec / 1e6, 3),
                               round(n / t_fp / 1e6, 2) if t_fp else "n/a",
                               round(m / t_dec / 1e6, 2), "met" if n / t_dec >= 1e6 else "missed"])

        no_apex = 8 * len(encode_geometry(p_dec, d_dec, refs[:, :3])) / n
        no_table = 8 * len(encode_geometry(p_dec, d_dec, refs, modes=(0, 0, 0, 0))) / n
        rng = np.random.default_rng(0)
        shuffled = rng.permutation(n)
        no_refs = 8 * len(encode_geometry(np.ascontiguousarray(points[shuffled]),
                                          np.ascontiguousarray(density[shuffled]),
                                          np.full((n, 4), -1, np.int32))) / n
        ablation_rows.append([name, round(bpv, 2), round(no_apex, 2), round(no_table, 2), round(no_refs, 2)])

    text = "## Geometry and density coding (lossless)\n\n"
    text += (f"Command: `{COMMAND}{' --quick' if quick else ''}`. Vertices in the cut-border decoder's order "
             "with its refs (face + apex); every float checked bit-identical after decoding (column *exact*). "
             "Peers measured in the same run on the same arrays: xz = Python `lzma` preset 9 on the raw "
             "float32 arrays; fpzip 1.2.5 lossless (precision 0), coordinates as the better of the (n,3) and "
             "(3,n) layouts, in the file's original order. b/v = bits per vertex for x, y, z and density "
             "together.\n\n")
    text += table(["data set", "points", "bytes", "b/v", "x / y / z / density b/v", "mode x/y/z/d",
                   "xz b/v (file order)", "xz b/v (decode order)", "fpzip b/v", "ours/xz", "ours/fpzip",
                   "exact"], size_rows)
    text += ("\n\nMode: t = value table (ranks in the sorted distinct values of that channel), p = "
             "prediction residual on the order-preserving integers; chosen per channel, whichever is "
             "smaller.\n\n")
    text += "### Mesh-only payload against the issue's target (≤ 0.5 × xz -9 of the raw arrays)\n\n"
    text += (f"Command: `{COMMAND}`. Connectivity = the cut-border boundary and tet streams, geometry = "
             "this coder; container header, metadata and CRCs are not included (the codec section has the "
             "real file sizes). xz sum = `lzma` preset 9 of float32 points + float32 density + int32 tets, "
             "each in file order.\n\n")
    text += table(["data set", "connectivity KB", "b/tet", "geometry KB", "total KB", "xz sum KB",
                   "total / xz", "≤ 0.5"], file_rows)
    text += "\n\n### Speed (one thread, warm JIT cache)\n\n"
    text += (f"Command: `{COMMAND}`. Best of {repeat}, process CPU time (the machine is shared; load "
             f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores when this ran). Encode = "
             "`encode_geometry` (it tries both modes on channels with repeated values); decode = "
             "`GeometryDecoder` in batches of 4096 vertices, as the streaming container does. fpzip "
             "decompression of the same arrays (C library) for reference. The last column converts the "
             "decode speed to tets of that mesh per second (the decoder's budget is 2 M tets/s for "
             "everything).\n\n")
    text += table(["data set", "points", "encode M vertices/s", "decode M vertices/s", "fpzip decode M vertices/s",
                   "decode ≙ M tets/s", "decode ≥ 1 M vertices/s"], speed_rows)
    text += "\n\n### What each part of the model buys (b/v)\n\n"
    text += (f"Command: `{COMMAND}`. *full*: as above. *no apex*: refs without the apex column. "
             "*no tables*: prediction residuals only. *no refs*: vertices in a random order with no refs "
             "(each predicted from the previous one), i.e. what the same entropy coder does without the "
             "mesh.\n\n")
    text += table(["data set", "full", "no apex", "no tables", "no refs, shuffled"], ablation_rows)
    text += "\n\n![bits per vertex](figures/geometry_bits.png)\n"
    _figure(plot)
    write_section("geometry", text)


def _figure(plot: dict) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    names = list(plot)
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(6.4, 3.4), dpi=120)
    for i, (label, colour) in enumerate([("tetc geometry", "#1f77b4"), ("xz -9 (file order)", "#ff7f0e"),
                                         ("fpzip (file order)", "#2ca02c")]):
        ax.bar(x + (i - 1) * 0.27, [plot[nm][i] for nm in names], 0.27, label=label, color=colour)
    ax.set_xticks(x, names)
    ax.set_ylabel("bits per vertex (x, y, z, density)")
    ax.set_title("Lossless geometry + density")
    ax.legend(fontsize=8)
    fig.tight_layout()
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURES / "geometry_bits.png")
    plt.close(fig)


if __name__ == "__main__":
    main(sys.argv[1:]) if "--help" not in sys.argv else print(__doc__)
