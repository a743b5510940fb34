"""What value tables chained across levels would save (the format-8 gate study).

Run: ``python bench/chained_table_study.py FILE.tetc [...]`` (files with levels, from ``tetc compress``).

A coarser level's vertices are a subset of the finer level's, values kept bit for bit, so level
k+1's table of a channel's distinct values T_{k+1} is a subset of level k's T_k. A *chained* table
sends only the additions A_k = T_k minus T_{k+1}; the ranks against T_k are coded as today. Per
level and channel, today's kernels code the channel as prediction residuals and as ranks in its
own table; the chained stream is estimated as the own-table stream less the cost of T_k coded
alone plus the cost of A_k coded alone (a table's cost alone: the table with one vertex; the one
vertex and the stream's end cancel). Per channel a dynamic programme over the levels, coarsest
first, picks prediction, own table or chained table (chained only where level k+1 codes the channel
with a table and T_{k+1} is a subset of T_k). Prints per file the geometry bytes per level today
and with the best choice, and the whole file's bytes and all-levels / level-0 ratio (from the
container's section sizes). Nothing is written. (The gate of format 8: files with levels 15.5-15.9 %
smaller on Blunt-fin, Combustion and LOX post, 1.9 % on Room fire; format 8 builds it as geometry
coding 4, with ranks on nearly all-distinct channels only in levels of at most 4096 vertices.)
"""

from __future__ import annotations

import sys

import numpy as np

from gatun_py.codec import TetcReader
from gatun_py.codec import _geometry_kernels as K
from gatun_py.codec import geometry as G
from gatun_py.codec.cutborder import encode_connectivity

PRED, OWN, CHAIN = 0, 1, 2


def sizes(vf, refs, tables_list, modes, cands, wpar=None) -> np.ndarray:
    offs = np.zeros(K.N_CHANNELS + 1, np.int64)
    offs[1:] = np.cumsum([len(t) for t in tables_list])
    streams = G._run_encode(vf, refs, np.asarray(modes, np.int64), np.concatenate(tables_list), offs, cands, wpar=wpar)
    return np.array([len(s) for s in streams])


def level_figures(reader, lv):
    """(per-channel [pred, own, table alone] sizes, tables, today's geometry block bytes)."""
    i = lv["level"]
    block = reader.container.read_section(f"L{i}/geometry")
    mesh = reader.decode_mesh(i)
    conn = encode_connectivity(mesh.n_points, mesh.tets)
    refs = G._as_refs(conn.predictors, mesh.n_points)
    vo = conn.vertex_order
    vf = G._channels(np.ascontiguousarray(mesh.points32[vo]), np.ascontiguousarray(mesh.density[vo]))
    tables = [np.unique(G._ordered(vf)[:, ch]) for ch in range(K.N_CHANNELS)]
    xy = True
    if block is not None:
        _, mode_bits, _, _ = G.check_geometry_header(np.frombuffer(block, np.uint8))
        xy = bool(mode_bits & G.XY_TABLE_BIT)
    cands = K.candidate_table(3, xy)
    wpar = K.link_all(refs, vf)
    pred = sizes(vf, refs, tables, [0] * 4, cands, wpar)
    own = sizes(vf, refs, tables, [1] * 4, cands, wpar)
    alone = sizes(vf[:1], refs[:1], tables, [1] * 4, cands)
    return pred, own, alone, tables, vf, refs, cands, len(block) if block is not None else None


def main(path) -> None:
    reader = TetcReader(open(path, "rb").read())
    c = reader.container
    levels = sorted(reader.levels, key=lambda lv: lv["level"])
    figs = [level_figures(reader, lv) for lv in levels]
    nl = len(levels)
    # chained sizes, per level and channel (inf where the chain is impossible)
    chain = np.full((nl, K.N_CHANNELS), np.inf)
    for k in range(nl - 1):
        pred, own, alone, tables, vf, refs, cands, _ = figs[k]
        coarse = figs[k + 1][3]
        for ch in range(K.N_CHANNELS):
            if not np.isin(coarse[ch], tables[ch], assume_unique=True).all():
                continue
            adds = np.setdiff1d(tables[ch], coarse[ch], assume_unique=True)
            tl = [np.zeros(1, np.int64)] * K.N_CHANNELS
            tl[ch] = adds if len(adds) else np.zeros(0, np.int64)
            # additions alone: code them as a table with one vertex (a table of 0 entries codes too)
            if len(adds):
                a = sizes(vf[:1], refs[:1], [adds if q == ch else tables[q] for q in range(4)], [1] * 4, cands)[ch]
            else:
                a = sizes(vf[:1], refs[:1], [tables[q] if q != ch else np.zeros(0, np.int64) for q in range(4)],
                          [1 if q != ch else 0 for q in range(4)], cands)[ch]
            chain[k, ch] = own[ch] - alone[ch] + a
    # dynamic programme per channel, coarsest level first: best[k][s], s = 0 predicted, 1 table
    choice_total = np.zeros(nl)
    today_total = np.zeros(nl)
    picks = np.zeros((nl, K.N_CHANNELS), int)
    for ch in range(K.N_CHANNELS):
        INF = float("inf")
        best = np.full((nl + 1, 2), INF)
        arg = np.zeros((nl + 1, 2), int)
        best[nl] = (0, INF)  # nothing coarser: no chain
        for k in range(nl - 1, -1, -1):
            pred, own = figs[k][0][ch], figs[k][1][ch]
            bp = min(best[k + 1])
            best[k, 0] = pred + bp
            arg[k, 0] = PRED
            best[k, 1] = own + bp
            arg[k, 1] = OWN
            if best[k + 1, 1] < INF and chain[k, ch] + best[k + 1, 1] < best[k, 1]:
                best[k, 1] = chain[k, ch] + best[k + 1, 1]
                arg[k, 1] = CHAIN
        s = int(np.argmin(best[0]))
        for k in range(nl):
            m = arg[k, s]
            picks[k, ch] = m
            choice_total[k] += (figs[k][0], figs[k][1], chain[k])[m][ch]
            s = 1 if m != PRED else int(np.argmin(best[k + 1])) if k + 1 < nl else 0
            if m == CHAIN:
                s = 1
    print(path)
    geo_today = []
    for k, lv in enumerate(levels):
        block = figs[k][7]
        geo_today.append(block)
        names = "".join("PTC"[m] for m in picks[k])
        print(f"  level {lv['level']:2d}: {lv['points']:6d} pts, geometry {block} B, streams pred {figs[k][0].tolist()} "
              f"own {figs[k][1].tolist()} chain {[None if np.isinf(x) else int(x) for x in chain[k]]} -> {names} "
              f"{int(choice_total[k]) + G.HEADER_SIZE + 1} B")
    total = len(open(path, "rb").read())
    saved = sum(geo_today) - sum(int(x) + G.HEADER_SIZE + 1 for x in choice_total)
    lv0 = level0_bytes(c)
    print(f"  file {total} B, level-0 sections {lv0} B, all/level0 {total / lv0:.3f}; "
          f"chained best {total - saved} B ({100 * saved / total:.1f} % smaller), all/level0 {(total - saved) / lv0:.3f}")


def level0_bytes(c) -> int:
    return sum(size for name, size in section_sizes(c).items() if name.startswith("L0/"))


def section_sizes(c) -> dict:
    return {name: c.section_size(name) for name in c.section_names()}


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for p in sys.argv[1:]:
        main(p)
