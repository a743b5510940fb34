"""Slow, obviously correct references for the codec kernels.

* :class:`NaiveRangeEncoder` / :class:`NaiveRangeDecoder`: the binary range coder written with
  Python integers straight from its definition (LZMA's carry-less-cache scheme), so the numba
  kernels' bytes can be compared one for one.
* :func:`naive_traversal_check`: replays the cut-border traversal with Python sets and a deque
  from the boundary faces and the decoded tets, checking the paper's invariants: every tet is
  attached to the oldest live face of the current surface T, its other faces close faces of T or
  join it, and T is empty at the end.
* :func:`canonical_tets`: order-free comparison form of a tet array (sorted vertex ids + parity).
"""

from __future__ import annotations

from collections import deque

import numpy as np

PROB_BITS = 15
PROB_ONE = 1 << PROB_BITS
ADAPT = 5
TOP = 1 << 24


class NaiveRangeEncoder:
    def __init__(self):
        self.low = 0
        self.range = 0xFFFFFFFF
        self.cache = 0
        self.cache_size = 1
        self.out = bytearray()

    def _shift_low(self):
        if self.low < 0xFF000000 or self.low >= 1 << 32:
            carry = self.low >> 32
            temp = self.cache
            while True:
                self.out.append((temp + carry) & 0xFF)
                temp = 0xFF
                self.cache_size -= 1
                if self.cache_size == 0:
                    break
            self.cache = (self.low >> 24) & 0xFF
        self.cache_size += 1
        self.low = (self.low & 0x00FFFFFF) << 8

    def _normalize(self):
        while self.range < TOP:
            self.range <<= 8
            self._shift_low()

    def bit(self, probs, i, b, shift=ADAPT):
        p = probs[i]
        bound = (self.range >> PROB_BITS) * p
        if b == 0:
            self.range = bound
            probs[i] = p + ((PROB_ONE - p) >> shift)
        else:
            self.low += bound
            self.range -= bound
            probs[i] = p - (p >> shift)
        self._normalize()

    def raw(self, value, nbits):
        for k in range(nbits - 1, -1, -1):
            self.range >>= 1
            if (value >> k) & 1:
                self.low += self.range
            self._normalize()

    def sym(self, probs, base, nbits, s):
        node = 1
        for k in range(nbits - 1, -1, -1):
            b = (s >> k) & 1
            self.bit(probs, base + node, b)
            node = 2 * node + b

    def finish(self) -> bytes:
        for _ in range(5):
            self._shift_low()
        return bytes(self.out)


class NaiveRangeDecoder:
    def __init__(self, data: bytes):
        self.data = data
        self.pos = 0
        self.range = 0xFFFFFFFF
        self.code = 0
        self.overrun = False
        if self._byte() != 0:
            raise ValueError("bad first byte")
        for _ in range(4):
            self.code = (self.code << 8) | self._byte()

    def _byte(self):
        if self.pos < len(self.data):
            b = self.data[self.pos]
        else:
            b = 0
            self.overrun = True
        self.pos += 1
        return b

    def _normalize(self):
        while self.range < TOP:
            self.range <<= 8
            self.code = ((self.code << 8) | self._byte()) & 0xFFFFFFFF

    def bit(self, probs, i, shift=ADAPT):
        p = probs[i]
        bound = (self.range >> PROB_BITS) * p
        if self.code < bound:
            self.range = bound
            probs[i] = p + ((PROB_ONE - p) >> shift)
            b = 0
        else:
            self.code -= bound
            self.range -= bound
            probs[i] = p - (p >> shift)
            b = 1
        self._normalize()
        return b

    def raw(self, nbits):
        v = 0
        for _ in range(nbits):
            self.range >>= 1
            b = 1 if self.code >= self.range else 0
            if b:
                self.code -= self.range
            v = 2 * v + b
            self._normalize()
        return v

    def sym(self, probs, base, nbits):
        node = 1
        for _ in range(nbits):
            node = 2 * node + self.bit(probs, base + node)
        return node - (1 << nbits)


def canonical_tets(tets) -> list[tuple]:
    """Sorted list of (sorted vertex ids..., permutation parity): equal for two tet arrays that
    hold the same oriented tets in any order and any even permutation of each tet."""
    t = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    inv = np.zeros(len(t), np.int64)
    for i in range(4):
        for j in range(i + 1, 4):
            inv += t[:, i] > t[:, j]
    rows = np.concatenate([np.sort(t, axis=1), (inv & 1)[:, None]], axis=1)
    rows = rows[np.lexsort(rows.T[::-1])]
    return [tuple(r) for r in rows.tolist()]


def naive_traversal_check(boundary, tets) -> None:
    """Assert that ``tets`` (decode order) is a FIFO cut-border traversal starting at ``boundary``.

    Faces are compared as vertex sets (the coder handles folded orientations with a flip bit).
    """
    live: dict[frozenset, int] = {}
    queue: deque = deque()
    seq = 0
    for f in boundary:
        key = frozenset(int(x) for x in f)
        assert key not in live, "boundary face repeated"
        live[key] = seq
        queue.append((key, seq))
        seq += 1
    for t in tets:
        t = [int(x) for x in t]
        assert len(set(t)) == 4, "tet with a repeated vertex"
        while True:
            assert queue, "surface T emptied before the last tet"
            key, s = queue.popleft()
            if live.get(key) == s:
                break
        # the current face is the face opposite the tet's last vertex
        assert key == frozenset(t[:3]), "tet not attached to the oldest live face of T"
        del live[key]
        for k in range(3):
            f = frozenset(t[:k] + t[k + 1:])
            if f in live:
                del live[f]
            else:
                live[f] = seq
                queue.append((f, seq))
                seq += 1
    assert not live, "faces left on T after the last tet"


# coding 2's candidate classes (docs/format.md): decoded tets on the candidate / 3 and on the
# ends of its fullest gate edge / 6, each capped at 15, the boundary flag and the score
CODING2_PROB_ONE, CODING2_SHIFT, CODING2_INIT = 1 << 15, 5, {1: (1 << 15) // 4, 2: (15 << 15) // 16, 3: (1 << 15) - 64}


def _coding2_class(score, decoded_x, edge_decoded, boundary_x):
    q = min(decoded_x // 3, 15)
    e = min(edge_decoded // 6, 15)
    return (((min(score, 3) - 1) * 16 + q) * 2 + int(boundary_x)) * 16 + e


def naive_tet_symbols(boundary, tets, n_boundary_vertices, coding=1) -> list:
    """The case of every tet (decode order, decode ids), recomputed from the paper's rules.

    Returns per tet: the rank of its fourth vertex among the apexes of faces of T adjacent to an
    edge of the current face, or 15 for a new vertex, 16 for a vertex of a face sharing only a
    vertex with the current face, 17 for any other vertex; None where the kernel's list caps (15 /
    64 entries) make the case depend on list order. Coding 1 ranks the candidates by how many of
    those faces contain them, then by the age of the oldest; coding 2 first by its class's
    adaptive probability of being the fourth vertex (learnt from the tets before; after a capped
    list the learning depends on list order, so every later tet is None).
    """
    live: dict[frozenset, int] = {}
    by_vertex: dict[int, set] = {}
    queue: deque = deque()
    seq = 0

    def add(key):
        nonlocal seq
        live[key] = seq
        queue.append((key, seq))
        seq += 1
        for v in key:
            by_vertex.setdefault(v, set()).add(key)

    def remove(key):
        del live[key]
        for v in key:
            by_vertex[v].discard(key)

    for f in boundary:
        add(frozenset(int(x) for x in f))
    known = int(n_boundary_vertices)
    out = []
    decoded: dict[int, int] = {}  # coding 2: decoded tets on each vertex (saturating at 255)
    prob: dict[int, int] = {}  # coding 2: class probabilities
    diverged = False
    for t in tets:
        t = [int(x) for x in t]
        while True:
            key, s = queue.popleft()
            if live.get(key) == s:
                break
        cur, d = key, t[3]
        near = set().union(*(by_vertex.get(v, set()) for v in cur)) - {cur}
        score: dict[int, int] = {}
        age: dict[int, int] = {}
        for g in near:
            if len(g & cur) == 2:
                (x,) = g - cur
                score[x] = score.get(x, 0) + 1
                age[x] = min(age.get(x, live[g]), live[g])
        if coding == 1:
            ranked = sorted(score, key=lambda x: (-score[x], age[x]))
        else:
            cls = {}
            for x in score:
                edges = [g & cur for g in near if len(g & cur) == 2 and x in g]
                ev = max(sum(decoded.get(v, 0) for v in e) for e in edges)
                cls[x] = _coding2_class(score[x], decoded.get(x, 0), ev, x < int(n_boundary_vertices))
            p = {x: prob.get(cls[x], CODING2_INIT[min(score[x], 3)]) for x in score}
            ranked = sorted(score, key=lambda x: (-p[x], -min(score[x], 3), age[x]))
        remove(cur)
        if len(ranked) > 15:
            diverged = diverged or coding == 2
            out.append(None)
        elif diverged:
            out.append(None)
        elif d in ranked:
            out.append(ranked.index(d))
        elif d == known:
            out.append(15)
        else:
            ring = {x for g in near if len(g & cur) == 1 for x in g} - cur - set(ranked)
            out.append(None if len(ring) > 64 else (16 if d in ring else 17))
        if d == known:
            known += 1
        if coding == 2 and len(ranked) <= 15:
            # the classes learn from this tet, each from the probability the ranking read
            for x in ranked:
                if x != d:
                    prob[cls[x]] = p[x] - (p[x] >> CODING2_SHIFT)
            if d in ranked:
                prob[cls[d]] = p[d] + ((CODING2_PROB_ONE - p[d]) >> CODING2_SHIFT)
            for v in t:
                decoded[v] = min(decoded.get(v, 0) + 1, 255)
        for k in range(3):
            f = frozenset(t[:k] + t[k + 1:])
            if f in live:
                remove(f)
            else:
                add(f)
    return out
