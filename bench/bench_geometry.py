"""Lossless geometry + density coding (gatun_py.codec.geometry) against xz -9, fpzip and pcodec.

Run: ``python bench/bench_geometry.py [--quick] [--big]``  →  ``bench/sections/geometry.md``,
``bench/figures/geometry_bits.png``.

Data: the four samples, then the gmsh meshes (block-50k and flange-1m; ``--big`` adds
flange-10m), taken from ``common.MESH_CACHE`` (``$TETC_MESH_CACHE``) when there, else built by
``bench/gmsh_meshes.py`` (slow). Vertices are coded in the real decode order of the cut-border
connectivity coder (``encode_connectivity``), with its predictor refs. Peers run in the same process
on the same float32 arrays in the file's original order (what a user would compress): ``lzma``
preset 9 (= ``xz -9``), ``fpzip`` (lossless, precision 0) and ``pcodec`` (default level), each with
the best of three layouts for the coordinates. ``--quick`` does one timing repetition instead of 3.
"""

from __future__ import annotations

import lzma
import os
import sys
import time

import numpy as np

from common import FIGURES, MESH_CACHE, SAMPLE_FILES, code_state, load, table, write_section

COMMAND = "python bench/bench_geometry.py"
GMSH = ["block-50k", "flange-1m"]
GMSH_BIG = ["flange-10m"]
TARGET = 0.9  # geometry b/v <= 0.9 x the best peer on every mesh


def _load_any(name):
    if name in SAMPLE_FILES:
        return load(name)[0]
    from gatun_py.mesh import read_mesh

    path = MESH_CACHE / f"{name}.vtu"
    if not path.exists():
        from gmsh_meshes import mesh_path

        path = mesh_path(name, log=lambda msg: print(msg, file=sys.stderr))
    return read_mesh(path)[0]


# ------------------------------------------------------------------------------------------ peers
# Each peer gets the best of three layouts of the coordinates: interleaved (n, 3), planar (3, n)
# as one array, and one array per axis; the density is one array.


def _xz(arr) -> int:
    return len(lzma.compress(np.ascontiguousarray(arr).tobytes(), preset=9))


def _fpzip(arr) -> int | None:
    try:
        import fpzip
    except ImportError:
        return None
    return len(fpzip.compress(np.array(arr, order="C"), precision=0))  # fpzip wants a writable copy


def _pcodec(arr) -> int | None:
    try:
        from pcodec import ChunkConfig, standalone
    except ImportError:
        return None
    return len(standalone.simple_compress(np.ascontiguousarray(arr).ravel(), ChunkConfig()))


PEERS = {"xz": _xz, "fpzip": _fpzip, "pcodec": _pcodec}


def peer_bytes(points, density) -> dict:
    """{peer: (coordinate bytes with the best layout, its layout, density bytes)} (None: not installed)."""
    out = {}
    for name, fn in PEERS.items():
        layouts = {"(n,3)": fn(points), "(3,n)": fn(points.T)}
        per_axis = [fn(points[:, c]) for c in range(3)]
        layouts["per axis"] = None if None in per_axis else sum(per_axis)
        dens = fn(density)
        if dens is None or None in layouts.values():
            out[name] = None
            continue
        best = min(layouts, key=layouts.get)
        out[name] = (layouts[best], best, dens)
    return out


# ------------------------------------------------------------------------------------------ timing
# CPU time of this (single-threaded) process: the benchmark machine is shared by other jobs, and
# wall time under load mostly measures the neighbours.
_clock = time.process_time


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


def _channel_bytes(sizes: dict) -> dict:
    """``geometry_stream_sizes`` with each channel's table stream counted in the channel."""
    out = dict(sizes)
    for c in ("x", "y", "z", "density"):
        out[c] = sizes[c] + sizes.get(c + "_table", 0)
    return out


def _bpv(nbytes, n):
    return 8.0 * nbytes / n


def main(argv: list[str]) -> None:
    from gatun_py.codec.cutborder import encode_connectivity
    from gatun_py.codec.container import VERSION_MAJOR
    from gatun_py.codec.geometry import CODINGS, FORMAT_VERSION, encode_geometry, geometry_stream_sizes

    quick = "--quick" in argv
    repeat = 1 if quick else 3
    names = list(SAMPLE_FILES) + GMSH + (GMSH_BIG if "--big" in argv else [])
    size_rows, peer_rows, file_rows, speed_rows, ablation_rows, plot = [], [], [], [], [], {}
    misses = []
    warm = False
    for name in names:
        print(f"{name}...", file=sys.stderr, flush=True)
        mesh = _load_any(name)
        n, m = mesh.n_points, mesh.n_tets
        points = np.ascontiguousarray(mesh.points, dtype=np.float32)
        density = np.ascontiguousarray(mesh.density, dtype=np.float32)
        tets = mesh.tets
        conn = encode_connectivity(n, tets)
        order, refs = conn.vertex_order, conn.predictors
        p_dec = np.ascontiguousarray(points[order])
        d_dec = np.ascontiguousarray(density[order])
        if not warm:  # compile both codings outside the timings
            for coding in CODINGS:
                _stream_decode(encode_geometry(p_dec, d_dec, refs, coding=coding), refs, n)
            warm = True
        t_enc, blob = _best(lambda: encode_geometry(p_dec, d_dec, refs), repeat)
        t_dec, dec = _best(lambda: _stream_decode(blob, refs, n), repeat)
        ok = (np.array_equal(dec.points.view(np.int32), p_dec.view(np.int32))
              and np.array_equal(dec.density.view(np.int32), d_dec.view(np.int32)))
        blob1, blob2, blob3, blob4 = (encode_geometry(p_dec, d_dec, refs, coding=c) for c in (1, 2, 3, 4))
        # the decode speed of the coding before this one, by this code in the same run
        t_dec_prev, _ = _best(lambda: _stream_decode(blob4, refs, n), repeat)
        # a channel's bytes: its stream and, from coding 4 on, its value table's stream
        sizes = _channel_bytes(geometry_stream_sizes(blob))
        sizes1 = _channel_bytes(geometry_stream_sizes(blob1))
        bpv = _bpv(len(blob), n)

        peers = peer_bytes(points, density)
        totals = {p: _bpv(v[0] + v[2], n) for p, v in peers.items() if v}
        best_peer = min(totals, key=totals.get)
        best_bpv = totals[best_peer]
        # the strictest reading: the best peer per array (coordinates and density may differ)
        mixed = _bpv(min(v[0] for v in peers.values() if v) + min(v[2] for v in peers.values() if v), n)
        ratio = bpv / best_bpv
        if ratio > TARGET:
            misses.append(name)
        channels = ("x", "y", "z", "density")
        modes = "/".join("s" if sizes.get(c + "_steps") else sizes[c + "_mode"][0] for c in channels)
        size_rows.append([name, n, len(blob), round(bpv, 2), " / ".join(f"{_bpv(sizes[c], n):.2f}" for c in channels),
                          modes, *(f"{totals[p]:.2f}" if p in totals else "n/a" for p in PEERS),
                          f"{best_bpv:.2f} ({best_peer})", f"{ratio:.2f}", "met" if ratio <= TARGET else "missed",
                          f"{mixed:.2f}", f"{bpv / mixed:.2f}", "yes" if ok else "NO"])
        peer_rows.append([name, *(f"{_bpv(v[0], n):.2f} {v[1]} + {_bpv(v[2], n):.2f}" if v else "n/a"
                                  for v in peers.values()),
                          f"{_bpv(sum(sizes[c] for c in channels[:3]), n):.2f} + {_bpv(sizes['density'], n):.2f}"])
        plot[name] = (bpv, *(totals.get(p, np.nan) for p in PEERS))

        conn_bytes = len(conn.boundary_code) + len(conn.tet_code)
        xz_sum = _xz(points) + _xz(density) + _xz(tets.astype(np.int32))
        total = conn_bytes + len(blob)
        file_rows.append([name, f"{conn_bytes / 1e3:.1f}", round(8 * conn_bytes / m, 2), f"{len(blob) / 1e3:.1f}",
                          f"{total / 1e3:.1f}", f"{xz_sum / 1e3:.1f}", f"{total / xz_sum:.3f}",
                          "met" if total <= 0.5 * xz_sum else "missed"])

        speed_rows.append([name, n, round(n / t_enc / 1e6, 3), round(1e9 * t_dec_prev / n), round(1e9 * t_dec / n),
                           f"{t_dec_prev / t_dec:.2f}", round(n / t_dec / 1e6, 3), round(m / t_dec / 1e6, 2)])

        no_apex = _bpv(len(encode_geometry(p_dec, d_dec, refs[:, :3])), n)
        no_table = _bpv(len(encode_geometry(p_dec, d_dec, refs, modes=(0, 0, 0, 0))), n)
        rng = np.random.default_rng(0)
        shuffled = rng.permutation(n)
        no_refs = _bpv(len(encode_geometry(np.ascontiguousarray(points[shuffled]),
                                           np.ascontiguousarray(density[shuffled]),
                                           np.full((n, 4), -1, np.int32))), n)
        coords1 = _bpv(sum(sizes1[c] for c in channels[:3]), n)
        coords2 = _bpv(sum(sizes[c] for c in channels[:3]), n)
        ablation_rows.append([name, *(round(_bpv(len(b), n), 2) for b in (blob1, blob2, blob3, blob4)), round(bpv, 2),
                              f"{coords1:.2f} → {coords2:.2f}",
                              f"{_bpv(sizes1['density'], n):.2f} → {_bpv(sizes['density'], n):.2f}",
                              round(no_apex, 2), round(no_table, 2), round(no_refs, 2)])

    load_avg = os.getloadavg()[0]
    text = "## Geometry and density coding (lossless)\n\n"
    text += (f"Command: `{COMMAND}{' --quick' if quick else ''}{' --big' if '--big' in argv else ''}` "
             f"({code_state()}). Vertices in the cut-border decoder's order with its refs (face + apex); "
             f"geometry coding {FORMAT_VERSION} (format {VERSION_MAJOR}); every float checked bit-identical after decoding "
             "(column *exact*). Peers measured in the same run on the same float32 arrays in the file's "
             "original order: xz = Python `lzma` preset 9, fpzip 1.2.5 lossless (precision 0), pcodec "
             "(`standalone.simple_compress`, default level); each peer's coordinates in the best of three layouts "
             "((n,3) interleaved, (3,n) planar, one array per axis; the next table says which), its density "
             "as one array. b/v = bits per vertex for x, y, z and density together (a channel's b/v counts its "
             "value table's stream too; the rest of *bytes* is the block header). *Best peer* = the peer "
             "with the smallest total; the target is ours ≤ 0.9 × that. *Per-array best* is "
             "stricter: the best peer's coordinates plus the best peer's density, even from two different "
             "peers.\n\n")
    text += table(["data set", "points", "bytes", "b/v", "x / y / z / density b/v", "mode x/y/z/d",
                   "xz b/v", "fpzip b/v", "pcodec b/v", "best peer b/v", "ours / best", "≤ 0.9",
                   "per-array best b/v", "ours / per-array best", "exact"], size_rows)
    text += ("\n\nMode: t = value table (ranks in the sorted distinct values of that channel), s = value table "
             "with rank steps (coding 5: most ranks coded as a step of -2..2 from the first ref's rank), p = "
             "prediction residual on the order-preserving integers; chosen per channel, whichever is "
             "smaller.\n\n")
    text += (f"Missed on {', '.join(misses)}." if misses else "Met on every mesh.")
    text += (" On the grid-derived samples (Blunt-fin, post, fire: few distinct coordinates, the file "
             "in grid order) xz of the raw arrays in file order wins on the coordinates (its matches "
             "replay whole grid lines, which the decode order does not keep); this coder wins on the "
             "density everywhere and on the coordinates of the unstructured meshes.\n\n")
    text += "### Peer sizes: coordinates (best layout) + density, b/v\n\n"
    text += table(["data set", "xz", "fpzip", "pcodec", "ours"], peer_rows)
    text += "\n\n### Mesh-only payload against the issue's target (≤ 0.5 × xz -9 of the raw arrays)\n\n"
    text += (f"Command: `{COMMAND}`. Connectivity = the cut-border boundary and tet streams, geometry = "
             "this coder; container header, metadata and CRCs are not included (the codec section has the "
             "real file sizes). xz sum = `lzma` preset 9 of float32 points + float32 density + int32 tets, "
             "each in file order.\n\n")
    text += table(["data set", "connectivity KB", "b/tet", "geometry KB", "total KB", "xz sum KB",
                   "total / xz", "≤ 0.5"], file_rows)
    text += "\n\n### Speed (one thread, warm JIT cache)\n\n"
    text += (f"Command: `{COMMAND}`. Best of {repeat}, process CPU time (the machine is shared; load "
             f"average {load_avg:.1f} on {os.cpu_count()} cores when this ran). Encode = `encode_geometry` "
             "(it tries every mode on channels with repeated values); decode = `GeometryDecoder` in batches "
             f"of 4096 vertices, as the streaming container does, for coding 4 (format 8) and coding {FORMAT_VERSION} "
             f"(format {VERSION_MAJOR}) by this code in the same run (the same kernels decode both). The last "
             f"column converts the coding-{FORMAT_VERSION} decode speed to tets of that mesh per second (the "
             "whole-file budget is 3 M tets/s for everything).\n\n")
    text += table(["data set", "points", "encode M vertices/s", "decode ns/vertex, coding 4",
                   f"decode ns/vertex, coding {FORMAT_VERSION}", f"speed-up {FORMAT_VERSION} vs 4",
                   "decode M vertices/s", "decode ≙ M tets/s"], speed_rows)
    text += "\n\n### What each part of the model buys (b/v)\n\n"
    text += (f"Command: `{COMMAND}`. *coding 1*: the format-3 coder; *coding 2*: adds the tet-geometry "
             "predictors (density: the linear field through the ref tet, the face plane or the boundary "
             "triangle at the vertex's decoded position; coordinates: the apex reflected through the face "
             "centroid, and the centroid plus the face normal times the apex's height or a regular tet's "
             "height), chosen backward-adaptively like the others, and the coordinates' repetition symbol in a "
             "context of which ref value the pattern's first prediction lands nearest; *coding 3*: the same model, "
             "residual mantissa bits in wide range-coder steps, the residual's sign in a context, the repetition "
             "symbol as a flag then an index, the x → y table per block in a small cache; *coding 4*: the value "
             "tables in streams of their own (alone, as here, a block chains to nothing); *coding 5*: rank steps "
             f"on the table-mode channels where they pay. The rest are coding {FORMAT_VERSION} "
             "without a part: "
             "*no apex*: refs without the apex column; *no tables*: prediction residuals only; *no refs*: "
             "vertices in a random order with no refs (each predicted from the previous one), i.e. what the "
             "same entropy coder does without the mesh.\n\n")
    text += table(["data set", "coding 1", "coding 2", "coding 3", "coding 4", f"coding {FORMAT_VERSION}",
                   f"x+y+z, 1 → {FORMAT_VERSION}", f"density, 1 → {FORMAT_VERSION}", "no apex", "no tables",
                   "no refs, shuffled"], ablation_rows)
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
    fig, ax = plt.subplots(figsize=(8.0, 3.6), dpi=120)
    bars = [("tetc geometry", "#1f77b4"), ("xz -9", "#ff7f0e"), ("fpzip", "#2ca02c"), ("pcodec", "#9467bd")]
    for i, (label, colour) in enumerate(bars):
        ax.bar(x + (i - 1.5) * 0.2, [plot[nm][i] for nm in names], 0.2, label=label, color=colour)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("bits per vertex (x, y, z, density)")
    ax.set_title("Lossless geometry + density (peers in file order, best layout)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURES / "geometry_bits.png")
    plt.close(fig)


if __name__ == "__main__":
    main(sys.argv[1:]) if "--help" not in sys.argv else print(__doc__)
