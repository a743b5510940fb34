"""Slow, obviously correct reference of the merge-forest codings 1 (format 3) and 2 (format 6).

:func:`naive_encode_forest_on_mesh` and :func:`naive_encode_forest_rounds` write the bytes of
:func:`gatun_py.codec.forest.encode_forest_on_mesh` and
:func:`gatun_py.codec.forest.encode_forest_rounds` with Python sets, lists and integers (and
:class:`naive_codec.NaiveRangeEncoder`), straight from the description in ``docs/format.md``, so
the kernels' bytes can be compared one for one.
"""

from __future__ import annotations

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
    by_rank = sorted((v for v in range(n) if rank[v] != ROOT_RANK), key=lambda v: rank[v])
    rounds = {}  # vertex -> round inside its bucket
    n_rounds = []
    for j in range(len(b) - 1):
        rid = 0
        for i in range(b[j], b[j + 1]):
            if i > b[j] and not key[by_rank[i]] > key[by_rank[i - 1]]:
                rid += 1
            rounds[by_rank[i]] = rid
        n_rounds.append(rid + 1)
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


def _parents(enc, parent, rank, k, n, nbrs, flag_model, index_model):
    """Pass 2 of both codings: every merge's parent among the live neighbours, in rank order."""
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
