"""Which features predict the fourth vertex? The measurement behind connectivity coding 2.

Run: ``python bench/conn_study.py [flange-1m] [combustion] ...`` (flanges from ``TETC_FLANGE_V4_DIR``,
default ``/work/cache/v4``; samples by name). Prints, per mesh, the static conditional entropy
(bits per tet) of the candidate-index symbol (escape included) under coding 1's ranking and
context, and under rankings by the learnt probability of candidate classes built from what a
decoder knows, with the context (candidates, the best two classes' probabilities quantised to 8
levels, previous escape); then the case (c) index's entropy ordered by age and by decoded tets.

It replays coding 1's encoder traversal (the same border and candidate gather, no coding) and logs
per tet: the candidates' scores, gate edges, ages, decoded-tet counts, boundary flags, and the
decoded tets around each gate edge (exact, from an edge table: what a decoder could know only
with an edge hash; coding 2 uses the cheap per-vertex counts instead). The probabilities are
fitted on the mesh itself (an upper bound of what an adaptive model learns).
"""

from __future__ import annotations

import os
import sys
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from gatun_py.codec import _cutborder_kernels as K  # noqa: E402
from gatun_py.codec import rangecoder as rc  # noqa: E402
from gatun_py.codec.cutborder import _sorted_halfedges, encode_connectivity  # noqa: E402

FLANGE_V4_DIR = Path(os.environ.get("TETC_FLANGE_V4_DIR", "/work/cache/v4"))

NC = 8
NF = 16 + 6 * NC + 8


@njit(cache=True)
def edge_id(ekey, n, u, v):
    if u > v:
        u, v = v, u
    key = np.int64(u) * n + v
    lo, hi = 0, ekey.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if ekey[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def replay(tets, nbr, tgt, B, dec_of, order, nv0, ekey, n, ndec, val, vdec, feats):
    m = tets.shape[0]
    tvisited = np.zeros(m, np.bool_)
    cand = np.empty(K.MAX_C1, np.int64); cscore = np.empty(K.MAX_C1, np.int64); cseq = np.empty(K.MAX_C1, np.int64)
    c2 = np.empty(K.MAX_C2, np.int64); c2seq = np.empty(K.MAX_C2, np.int64)
    cface = np.empty((K.MAX_C1, 3), np.int64); cfirst = np.empty(K.MAX_C1, np.int64)
    cface_full = np.zeros(1, np.int64)
    cf2 = np.empty((K.MAX_C1, 3), np.int64)
    nv = nv0
    E, vhead, Q, bs = B
    qcap = Q.shape[0]
    for done in range(m):
        s = -1
        while bs[K.BS_QHEAD] < bs[K.BS_QTAIL]:
            h = bs[K.BS_QHEAD] & (qcap - 1)
            bs[K.BS_QHEAD] += 1
            if E[Q[h, 0] * K.E_COLS + K.E_SEQ] == Q[h, 1]:
                s = Q[h, 0]
                break
        if s == -1:
            return -1
        a = np.int64(E[s * K.E_COLS + 0]); b = np.int64(E[s * K.E_COLS + 1]); c = np.int64(E[s * K.E_COLS + 2])
        ao = order[a]; bo = order[b]; co = order[c]
        t = tgt[s]
        tvisited[t] = True
        do = -1
        for k in range(4):
            w = tets[t, k]
            if w != ao and w != bo and w != co:
                do = w
        d = dec_of[do]
        fage = bs[K.BS_SEQ] - E[s * K.E_COLS + K.E_SEQ]
        cface_full[0] = 0
        n1 = K._gather_face(B, s, cand, cscore, cseq, cface, cface_full)
        for i in range(n1):
            cfirst[i] = cand[i]
            cf2[i, 0] = cface[i, 0]; cf2[i, 1] = cface[i, 1]; cf2[i, 2] = cface[i, 2]
        K._sort_candidates(cand, cscore, cseq, n1)
        K._remove(B, 3, s)
        sym = K.ESC
        if d != -1:
            for i in range(min(n1, K.MAX_C1)):
                if cand[i] == d:
                    sym = i
                    break
        e_bc = edge_id(ekey, n, bo, co); e_ab = edge_id(ekey, n, ao, bo); e_ac = edge_id(ekey, n, ao, co)
        f = feats[done]
        f[0] = n1
        f[1] = sym
        f[2] = ndec[e_bc]; f[3] = ndec[e_ab]; f[4] = ndec[e_ac]
        f[5] = val[e_bc]; f[6] = val[e_ab]; f[7] = val[e_ac]
        f[8] = fage
        f[9] = bs[K.BS_SEQ]
        f[10] = vdec[ao]; f[11] = vdec[bo]; f[12] = vdec[co]
        f[13] = -1  # case c index by age
        f[14] = -1  # n2
        f[15] = 0 if d == -1 else vdec[do]
        for i in range(min(n1, NC)):
            x = cand[i]
            j = 0
            while cfirst[j] != x:
                j += 1
            mask = 0
            for ed in range(3):
                if cf2[j, ed] != -1:
                    mask |= 1 << ed
            f[16 + 6 * i] = cscore[i]
            f[17 + 6 * i] = mask
            f[18 + 6 * i] = bs[K.BS_SEQ] - cseq[i]
            f[19 + 6 * i] = vdec[order[x]]
            f[20 + 6 * i] = 1 if x == d else 0
            f[21 + 6 * i] = 1 if x < nv0 else 0
        if sym == K.ESC and d != -1:
            n2 = K._gather_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq)
            f[14] = n2
            for i in range(n2):
                if c2[i] == d:
                    f[13] = i
            # study: multiplicity of each c2 entry, and vd; ranks of d under alternative orders
            cnt = np.zeros(n2, np.int64)
            for k in range(3):
                u = a if k == 0 else (b if k == 1 else c)
                node = vhead[u]
                while node != -1:
                    g = node >> 2
                    node = E[(node >> 2) * K.E_COLS + K.E_NEXT + (node & 3)]
                    for cj in range(3):
                        w = E[g * K.E_COLS + cj]
                        for i in range(n2):
                            if c2[i] == w:
                                cnt[i] += 1
            jd = f[13]
            if jd >= 0:
                r1 = 0
                r2 = 0
                r3 = 0
                for i in range(n2):
                    vi = vdec[order[c2[i]]]
                    vj = vdec[do]
                    if vi < vj or (vi == vj and i < jd):  # coding 2's order: fewest decoded tets first
                        r1 += 1
                    if cnt[i] > cnt[jd] or (cnt[i] == cnt[jd] and i < jd):
                        r2 += 1
                    if cnt[i] * 64 + vi > cnt[jd] * 64 + vj or (cnt[i] * 64 + vi == cnt[jd] * 64 + vj and i < jd):
                        r3 += 1
                f[16 + 6 * NC] = r1
                f[17 + 6 * NC] = r2
                f[18 + 6 * NC] = r3
                f[19 + 6 * NC] = cnt[jd]
        if d == -1:
            d = nv
            dec_of[do] = nv
            order[nv] = do
            nv += 1
        flip = K._tet_flip(tets, t, ao, bo, co, do)
        t1 = b if flip else c
        t2 = c if flip else b
        s0, s1, s2 = K._apply_tet(B, a, t1, t2, d)
        for k in range(3):
            slot = s0 if k == 0 else (s1 if k == 1 else s2)
            if slot >= 0:
                wo = order[a] if k == 0 else (order[t1] if k == 1 else order[t2])
                kk = 0 if tets[t, 0] == wo else (1 if tets[t, 1] == wo else (2 if tets[t, 2] == wo else 3))
                tgt[slot] = nbr[t, kk]
        # update decoded-edge counts
        for i in range(4):
            vdec[tets[t, i]] += 1
            for j in range(i + 1, 4):
                ndec[edge_id(ekey, n, tets[t, i], tets[t, j])] += 1
    return nv


def run(points, tets):
    n = int(points); tets = np.ascontiguousarray(tets, np.int32); m = len(tets)
    e = encode_connectivity(n, tets, coding=1)
    nbr = np.empty((m, 4), np.int32); K.tet_neighbours(tets, nbr)
    faces = np.empty((int(np.count_nonzero(nbr == -1)), 3), np.int64); owner = np.empty(len(faces), np.int64)
    nf = K.boundary_from_neighbours(tets, nbr, faces, owner)
    # redo boundary to get dec_of/order and face_src
    dec_of = np.full(n, -1, np.int64); order = np.full(n, -1, np.int64); pred = np.full((n, 4), -1, np.int32)
    out_faces = np.zeros((nf, 3), np.int32); face_src = np.zeros(nf, np.int64)
    hkey, hface = _sorted_halfedges(faces)
    def rb(st, out):
        B = K.new_border(n, 3 * nf + 8, 3 * nf + 8)
        rb.res = K.encode_boundary(st, out, faces, hkey, hface, n, B, dec_of, order, pred, out_faces, face_src)
    rc.run_encoder(rb, capacity=rc.capacity_hint(nf * 4))
    nbv = rb.res[0]
    bowner = owner[face_src]
    B = K.new_border(n, nf + 2 * m + 8, nf + 3 * m + 8)
    tgt = np.full(nf + 3 * m + 8, -1, np.int32)
    tgt[K.add_faces(B, out_faces, -1)] = bowner
    ed = np.concatenate([tets[:, [i, j]] for i in range(4) for j in range(i + 1, 4)]).astype(np.int64)
    ed.sort(axis=1)
    keys = ed[:, 0] * n + ed[:, 1]
    ekey, cnt = np.unique(keys, return_counts=True)
    ndec = np.zeros(len(ekey), np.int64)
    vdec = np.zeros(n, np.int64)
    feats = np.full((m, NF), -1, np.int64)
    replay(tets, nbr, tgt, B, dec_of, order, nbv, ekey, n, ndec, cnt.astype(np.int64), vdec, feats)
    return e, feats




def cond_entropy(ctx, sym) -> float:
    """Total bits of ``sym`` coded with a static model per context (the empirical entropy)."""
    by = defaultdict(Counter)
    for k, s in zip(ctx, sym):
        by[k][s] += 1
    total = 0.0
    for c in by.values():
        v = np.array(list(c.values()), float)
        total -= float((v * np.log2(v / v.sum())).sum())
    return total


def study(name: str, F: np.ndarray) -> None:
    m = len(F)
    n1, sym, ndec = F[:, 0], F[:, 1], F[:, 2:5]
    sc, mask, vd, isd, bd = (F[:, 16 + k::6][:, :NC] for k in (0, 1, 3, 4, 5))
    valid = np.arange(NC)[None, :] < np.minimum(n1, NC)[:, None]
    prev = np.r_[0, (sym[:-1] == K.ESC).astype(int)]
    s1 = np.where(n1 > 0, np.minimum(sc[:, 0], 3), 0)
    s2 = np.where(n1 > 1, np.minimum(sc[:, 1], 3), 0)
    print(f"{name}: {m:,} tets; coding 1 ranking and context: "
          f"{cond_entropy(zip(np.minimum(n1, 4), s1, s2, prev), sym) / m:.3f} bits/tet")
    gvd = F[:, 10:13]  # decoded tets on a, b, c; edges: 0 = bc, 1 = ab, 2 = ac
    edge_vd = np.stack([gvd[:, 1] + gvd[:, 2], gvd[:, 0] + gvd[:, 1], gvd[:, 0] + gvd[:, 2]], 1)
    nd_max = np.full((m, NC), -1)
    ev_max = np.full((m, NC), -1)
    for e in range(3):
        on = (mask >> e) & 1
        nd_max = np.maximum(nd_max, np.where(on, ndec[:, e][:, None], -1))
        ev_max = np.maximum(ev_max, np.where(on, edge_vd[:, e][:, None], -1))
    classes = {
        "score": sc,
        "score, decoded tets around its gate edge (exact)": sc * 16 + np.minimum(nd_max, 9),
        "score, decoded tets on it / 3": sc * 16 + np.minimum(vd // 3, 15),
        "score, decoded tets on it / 3, boundary": (sc * 16 + np.minimum(vd // 3, 15)) * 2 + bd,
        "coding 2: score, on it / 3, boundary, on its gate edge's ends / 6":
            ((sc * 16 + np.minimum(vd // 3, 15)) * 2 + bd) * 16 + np.minimum(ev_max // 6, 15),
    }
    for label, cls in classes.items():
        cls = np.where(valid, cls, -1)
        u, inv = np.unique(cls[valid], return_inverse=True)
        p = np.bincount(inv, weights=isd[valid]) / np.bincount(inv)
        P = np.full(cls.shape, -1.0)
        P[valid] = p[inv]
        order = np.argsort(np.where(valid, -P, 9) + np.arange(NC)[None, :] * 1e-6, 1)
        hit = (isd * valid).sum(1) > 0
        rank = np.argsort(order, 1)[np.arange(m), (isd * valid).argmax(1)]
        new = np.where(hit & (sym < K.ESC), rank, K.ESC)
        new = np.where(sym >= NC, sym, new)
        Ps = np.take_along_axis(P, order, 1)
        q = np.where(Ps < 0, 0, np.minimum((Ps * 8).astype(int) + 1, 8))
        bits = cond_entropy(zip(np.minimum(n1, 4), q[:, 0], q[:, 1], prev), new) / m
        print(f"  {label}: {len(u)} classes, {bits:.3f} bits/tet")
    cc = F[:, 13] >= 0
    for label, j in (("by age (coding 1)", F[cc, 13]), ("by decoded tets, fewest first (coding 2)",
                                                         F[cc, 16 + 6 * NC])):
        v, c = np.unique(j, return_counts=True)
        p = c / c.sum()
        print(f"  case (c), {100 * cc.mean():.1f} % of tets, index {label}: {-(p * np.log2(p)).sum():.2f} bits")


def main() -> None:
    from gatun_py.codec import TetcReader

    for name in sys.argv[1:] or ["flange-1m", "combustion"]:
        if name.startswith("flange"):
            mesh = TetcReader(FLANGE_V4_DIR / f"{name}.tetc").decode_mesh()
        else:
            from common import load
            mesh = load(name)[0]
        _, feats = run(mesh.n_points, mesh.tets)
        study(name, feats)


if __name__ == "__main__":
    main()
