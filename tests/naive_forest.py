"""Slow, obviously correct reference of the merge-forest codings 1 (format 3), 2 (format 6) and 3 (format 7).

:func:`naive_encode_forest_on_mesh` and :func:`naive_encode_forest_rounds` write the bytes of
:func:`gatun_py.codec.forest.encode_forest_on_mesh` and
:func:`gatun_py.codec.forest.encode_forest_rounds` with Python sets, lists and integers (and
:class:`naive_codec.NaiveRangeEncoder`), straight from the description in ``docs/format.md``, so
the kernels' bytes can be compared one for one.
"""

from __future__ import annotations

import math
import struct

from naive_codec import NaiveRangeEncoder

ROOT_SYMBOL, CAP, SMALL, FLAG_CONTEXTS, DEGREE_CLASSES = 63, 6, 32, 16, 7
ROOT_RANK = 2**31 - 1


class _Encoder(NaiveRangeEncoder):
    def below(self, value, m):
        if m > 65536:
            hi = value >> 16
            self.below(hi, ((m - 1) >> 16) + 1)
            self.below(value & 0xFFFF, min(65536, m - (hi << 16)))
            return
        r = self.range // m
        self.low += value * r
        self.range = r
        self._normalize()


def _bounds(n, k):
    b = [0]
    while b[-1] < k:
        b.append(min(b[-1] + max(1, (n - b[-1]) // 2), k))
    return b


def _neighbours(tets, n):
    nbrs = [set() for _ in range(n)]
    for t in tets:
        for a in t:
            nbrs[int(a)].update(int(b) for b in t if b != a)
    return [sorted(s) for s in nbrs]


def _bucket_symbol(enc, bucket_model, nbrs, boundary, symbol, b, v, r):
    """Code vertex v's bucket symbol in its context (boundary, degree class, smallest symbol of
    the neighbours decoded before); appends it to ``symbol`` and returns it."""
    seen = [symbol[u] for u in nbrs[v] if u < v]
    own = int(bool(boundary[v])) * DEGREE_CLASSES + min(len(nbrs[v]) // 4, DEGREE_CLASSES - 1)
    ctx = own * (CAP + 2) + (1 + min(min(seen), CAP) if seen else 0)
    s = ROOT_SYMBOL if r == ROOT_RANK else next(j for j in range(len(b) - 1) if b[j] <= r < b[j + 1])
    enc.sym(bucket_model.setdefault(ctx, [1 << 14] * 64), 0, 6, s)
    symbol.append(s)
    return s


def naive_encode_forest_on_mesh(parent, rank, tets, boundary) -> bytes:
    parent, rank = [int(x) for x in parent], [int(x) for x in rank]
    n = len(parent)
    k = sum(r != ROOT_RANK for r in rank)
    head = struct.pack("<4sII", b"GFR3", n, k)
    if k == 0:
        return head
    nbrs = _neighbours(tets, n)
    enc = _Encoder()
    bucket_model = {}  # context -> probabilities of its bit tree
    flag_model = [1 << 14] * (2 * FLAG_CONTEXTS)
    index_model = {}
    b = _bounds(n, k)
    free = set(range(k))
    symbol = []
    for v in range(n):
        s = _bucket_symbol(enc, bucket_model, nbrs, boundary, symbol, b, v, rank[v])
        if s != ROOT_SYMBOL:
            in_bucket = sorted(x for x in free if b[s] <= x < b[s + 1])
            enc.below(in_bucket.index(rank[v]), len(in_bucket))
            free.remove(rank[v])
    _parents(enc, parent, rank, k, n, nbrs, flag_model, index_model)
    return head + enc.finish()


def _float_bits(x) -> int:
    return struct.unpack("<I", struct.pack("<f", float(x)))[0]


def naive_key(points, density):
    """The canonical key of every vertex: (x, y, z, value) float32 bit patterns, as a tuple."""
    return [tuple(_float_bits(c) for c in p) + (_float_bits(d),) for p, d in zip(points, density)]



def _rounds(rank, key, b, n):
    """(vertex -> round inside its bucket, rounds per bucket): a round is a maximal run of ranks
    whose keys ascend."""
    by_rank = sorted((v for v in range(n) if rank[v] != ROOT_RANK), key=lambda v: rank[v])
    rounds = {}
    n_rounds = []
    for j in range(len(b) - 1):
        rid = 0
        for i in range(b[j], b[j + 1]):
            if i > b[j] and not key[by_rank[i]] > key[by_rank[i - 1]]:
                rid += 1
            rounds[by_rank[i]] = rid
        n_rounds.append(rid + 1)
    return rounds, n_rounds

def naive_encode_forest_rounds(parent, rank, tets, boundary, points, density) -> bytes:
    """Forest coding 2 (format 6): rounds per bucket, then per vertex its bucket as in coding 1
    and its round uniformly among the bucket's rounds; the parents as in coding 1."""
    parent, rank = [int(x) for x in parent], [int(x) for x in rank]
    n = len(parent)
    k = sum(r != ROOT_RANK for r in rank)
    head = struct.pack("<4sII", b"GFR6", n, k)
    if k == 0:
        return head
    nbrs = _neighbours(tets, n)
    key = naive_key(points, density)
    b = _bounds(n, k)
    rounds, n_rounds = _rounds(rank, key, b, n)
    enc = _Encoder()
    for j, count in enumerate(n_rounds):
        enc.below(count - 1, b[j + 1] - b[j])
    bucket_model = {}
    flag_model = [1 << 14] * (2 * FLAG_CONTEXTS)
    index_model = {}
    symbol = []
    for v in range(n):
        s = _bucket_symbol(enc, bucket_model, nbrs, boundary, symbol, b, v, rank[v])
        if s != ROOT_SYMBOL and n_rounds[s] > 1:
            enc.below(rounds[v], n_rounds[s])
    _parents(enc, parent, rank, k, n, nbrs, flag_model, index_model)
    return head + enc.finish()


def _parents(enc, parent, rank, k, n, nbrs, flag_model, index_model, order=None, absorb=None):
    """Pass 2 of every coding: every merge's parent among the live neighbours, in rank order
    (``order(v, candidates)``: coding 3's order instead of the count's; ``absorb(v, p)`` after the
    merge of v into p)."""
    rep = list(range(n))  # representative (live ancestor) of every vertex, updated after each merge
    children = [[] for _ in range(n)]
    for v in sorted(range(n), key=lambda x: rank[x])[:k]:
        p = parent[v]
        tier0 = [rep[u] for u in nbrs[v]]
        tier1 = [rep[w] for c in children[v] for w in nbrs[c]]
        found = False
        for tier, listed in enumerate((tier0, tier1)):
            skip = {v} | (set(tier0) if tier == 1 else set())
            cand = sorted({x for x in listed if x not in skip}, key=lambda x: (-listed.count(x), x))
            if order is not None:
                cand = order(v, cand)
            if not cand:
                continue
            m = len(cand)
            enc.bit(flag_model, tier * FLAG_CONTEXTS + min(m, FLAG_CONTEXTS - 1), int(p in cand))
            if p in cand:
                if m <= SMALL:
                    enc.sym(index_model.setdefault((tier, m), [1 << 14] * 32), 0, 5, cand.index(p))
                else:
                    enc.below(cand.index(p), m)
                found = True
                break
        if not found:
            enc.below(p, n)
        children[p].append(v)
        rep = [p if x == v else x for x in rep]
        if absorb is not None:
            absorb(v, p)


# -- forest coding 3 (format 7) ----------------------------------------------------------------------
# Every float as the kernels compute it: the same IEEE double operations in the same order
# (Python evaluates a - b + c as (a - b) + c, as the kernels do without fastmath).

QUADRIC_SCALAR_SCALE, PROXY_BINS, PHASES, BUCKET_CLASSES = 0.01, 16, 16, 8


def naive_quadrics(tets, points, density):
    """(q, u): every vertex's 15 quadric terms over its tets and its normalised (x, y, z, value)."""
    pts = [[float(c) for c in p] for p in points]
    val = [float(d) for d in density]
    n = len(pts)
    if n == 0:
        return [], []
    lo = [min(p[c] for p in pts) for c in range(3)]
    hi = [max(p[c] for p in pts) for c in range(3)]
    dx, dy, dz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    diag = math.sqrt(dx * dx + dy * dy + dz * dz)
    diag = diag if diag > 0 and math.isfinite(diag) else 1.0
    s_lo, s_hi = min(val), max(val)
    srange = s_hi - s_lo
    srange = srange if srange > 0 and math.isfinite(srange) else 1.0
    u = [[(p[c] - lo[c]) / diag for c in range(3)] + [QUADRIC_SCALAR_SCALE * ((s - s_lo) / srange)]
         for p, s in zip(pts, val)]
    def volume(a, b, c, d):
        (p0, p1, p2), (q0, q1, q2), (r0, r1, r2) = ([u[x][i] - u[a][i] for i in range(3)] for x in (b, c, d))
        w = abs(p0 * (q1 * r2 - q2 * r1) - p1 * (q0 * r2 - q2 * r0) + p2 * (q0 * r1 - q1 * r0))
        return w if w < math.inf else 0.0

    def terms(a, b, c, d):
        p0, p1, p2, p3 = (u[b][i] - u[a][i] for i in range(4))
        q0, q1, q2, q3 = (u[c][i] - u[a][i] for i in range(4))
        r0, r1, r2, r3 = (u[d][i] - u[a][i] for i in range(4))
        m01, m02, m03 = q0 * r1 - q1 * r0, q0 * r2 - q2 * r0, q0 * r3 - q3 * r0
        m12, m13, m23 = q1 * r2 - q2 * r1, q1 * r3 - q3 * r1, q2 * r3 - q3 * r2
        nrm = [p1 * m23 - p2 * m13 + p3 * m12, -(p0 * m23 - p2 * m03 + p3 * m02),
               p0 * m13 - p1 * m03 + p3 * m01, -(p0 * m12 - p1 * m02 + p2 * m01)]
        w = volume(a, b, c, d)
        length = math.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2] + nrm[3] * nrm[3])
        if not (length > 0 and w > 0 and length < math.inf):
            return None
        nrm = [x / length for x in nrm]
        wn = [w * x for x in nrm]
        return [wn[r] * nrm[c] for r in range(4) for c in range(r, 4)]

    # per vertex: integer sums in units of 2^-36 of its largest tet weight (any tet order gives them)
    corners = [sorted(int(x) for x in t) for t in tets]
    wmax = [0.0] * n
    for t in corners:
        w = volume(*t)
        for x in t:
            wmax[x] = max(wmax[x], w)
    unit = [2.0**36 / w if w > 0 and 2.0**36 / w < math.inf else 0.0 for w in wmax]
    fixed = [[0] * 10 for _ in range(n)]
    for t in corners:
        tt = terms(*t)
        if tt is None:
            continue
        for x in t:
            fixed[x] = [acc + int(term * unit[x]) for acc, term in zip(fixed[x], tt)]
    q = [[float(acc) * (wmax[v] / 2.0**36) for acc in fixed[v]] + [0.0] * 5 for v in range(n)]
    return q, u


def naive_quadric_at(qv, uv, ux):
    """A quadric kept about its vertex (at uv) evaluated at ux."""
    a0, a1, a2, a3 = (x - y for x, y in zip(ux, uv))
    s = (qv[0] * a0 * a0 + qv[4] * a1 * a1 + qv[7] * a2 * a2 + qv[9] * a3 * a3
         + 2.0 * (qv[1] * a0 * a1 + qv[2] * a0 * a2 + qv[3] * a0 * a3
                  + qv[5] * a1 * a2 + qv[6] * a1 * a3 + qv[8] * a2 * a3)
         + 2.0 * (qv[10] * a0 + qv[11] * a1 + qv[12] * a2 + qv[13] * a3) + qv[14])
    return math.inf if s != s else s


def naive_absorb(qv, qp, uv, up):
    """qp + qv, qv moved from about uv to about up (e = up - uv: b += A e, c += e^T A e + 2 b.e)."""
    e = [x - y for x, y in zip(up, uv)]
    rows = ((0, 1, 2, 3), (1, 4, 5, 6), (2, 5, 7, 8), (3, 6, 8, 9))
    ae = [qv[r[0]] * e[0] + qv[r[1]] * e[1] + qv[r[2]] * e[2] + qv[r[3]] * e[3] for r in rows]
    c = (qv[14] + (ae[0] * e[0] + ae[1] * e[1] + ae[2] * e[2] + ae[3] * e[3])
         + 2.0 * (qv[10] * e[0] + qv[11] * e[1] + qv[12] * e[2] + qv[13] * e[3]))
    return ([a + b for a, b in zip(qp[:10], qv[:10])] + [qp[10 + i] + (qv[10 + i] + ae[i]) for i in range(4)]
            + [qp[14] + c])


def naive_encode_forest_on_geometry(parent, rank, tets, boundary, points, density) -> bytes:
    """Forest coding 3 (format 7): coding 2's rounds and parents; a round is coded as its phase in
    the context of (bucket, quantile of the vertex's cheapest merge), then its place in the phase;
    the candidate parents are ordered by the merged vertex's quadric at them (boundary vertices:
    boundary candidates first), the quadrics summed along the replay."""
    parent, rank = [int(x) for x in parent], [int(x) for x in rank]
    n = len(parent)
    k = sum(r != ROOT_RANK for r in rank)
    head = struct.pack("<4sII", b"GFR7", n, k)
    if k == 0:
        return head
    nbrs = _neighbours(tets, n)
    q, u = naive_quadrics(tets, points, density)
    boundary = [bool(x) for x in boundary]
    cheapest = [min([naive_quadric_at(q[v], u[v], u[x]) for x in nbrs[v] if not (boundary[v] and not boundary[x])],
                    default=math.inf) for v in range(n)]
    proxy_bin = [0] * n
    for place, v in enumerate(sorted(range(n), key=lambda v: (cheapest[v], v))):
        proxy_bin[v] = place * PROXY_BINS // n
    key = naive_key(points, density)
    b = _bounds(n, k)
    rounds, n_rounds = _rounds(rank, key, b, n)
    enc = _Encoder()
    for j, count in enumerate(n_rounds):
        enc.below(count - 1, b[j + 1] - b[j])
    bucket_model, phase_model = {}, {}
    symbol = []
    for v in range(n):
        s = _bucket_symbol(enc, bucket_model, nbrs, boundary, symbol, b, v, rank[v])
        if s != ROOT_SYMBOL and n_rounds[s] > 1:
            big_r = n_rounds[s]
            p = min(PHASES, big_r)
            phase = rounds[v] * p // big_r
            enc.sym(phase_model.setdefault((min(s, BUCKET_CLASSES - 1), proxy_bin[v]), [1 << 14] * 16), 0, 4, phase)
            lo, hi = -(-phase * big_r // p), -(-(phase + 1) * big_r // p)
            if hi - lo > 1:
                enc.below(rounds[v] - lo, hi - lo)

    def order(v, cand):
        if len(cand) < 2:
            return list(cand)
        score = {x: naive_quadric_at(q[v], u[v], u[x]) + (1e300 if boundary[v] and not boundary[x] else 0.0) for x in cand}
        return sorted(cand, key=lambda x: (score[x], x))

    def absorb(v, p):
        q[p] = naive_absorb(q[v], q[p], u[v], u[p])

    _parents(enc, parent, rank, k, n, nbrs, [1 << 14] * (2 * FLAG_CONTEXTS), {}, order=order, absorb=absorb)
    return head + enc.finish()
