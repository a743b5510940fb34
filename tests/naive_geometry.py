"""Slow, plain-Python references for the geometry coder (``gatun_py.codec.geometry``).

Two things live here:

* :func:`emulate_decode_order`, a cut-border-like traversal (boundary surface breadth first, then
  the tets grown inward face by face) that yields a realistic decode order and the ``refs`` a
  connectivity coder would hand to the geometry coder. Tests and the benchmark use it so the
  geometry figures are measured on an honest order.
* :func:`naive_symbols`, a direct transcription of the coder's modelling step (predictor,
  order-preserving integer mapping, repetition symbols, residuals) that the numba kernels are
  compared against.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

# --------------------------------------------------------------------------------------------
# decode-order emulation


def emulate_decode_order(tets: np.ndarray, n_points: int):
    """Emulate a cut-border decode order.

    Parameters
    ----------
    tets : (m, 4) int array
        Tetrahedra, original vertex ids.
    n_points : int
        Number of vertices (unreferenced ones are appended at the end).

    Returns
    -------
    order : (n,) int64
        ``order[k]`` is the original id of the k-th decoded vertex.
    refs : (n, 3) int32
        Up to three earlier decode ids to predict vertex k from (-1 where none): for boundary
        vertices the triangle it is attached to, as ``(u, v, w)`` with the new vertex across edge
        ``(u, v)`` from ``w``; for interior vertices the cut-border face it closes.
    """
    tets = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    new_id = np.full(n_points, -1, dtype=np.int64)
    order: list[int] = []
    refs: list[tuple[int, int, int]] = []

    def emit(v, r):
        if new_id[v] < 0:
            new_id[v] = len(order)
            order.append(int(v))
            refs.append(tuple(int(new_id[x]) if x >= 0 else -1 for x in r))

    # faces -> tets
    face_tets: dict = {}
    faces_of = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    for t, tet in enumerate(tets.tolist()):
        for f in faces_of:
            key = tuple(sorted(tet[i] for i in f))
            face_tets.setdefault(key, []).append(t)
    boundary = []
    for t, tet in enumerate(tets.tolist()):
        for f in faces_of:
            tri = tuple(tet[i] for i in f)
            if len(face_tets[tuple(sorted(tri))]) == 1:
                boundary.append(tri)

    # boundary surface, breadth first over edge-adjacent triangles
    edge_tris: dict = {}
    for i, tri in enumerate(boundary):
        for e in range(3):
            key = tuple(sorted((tri[e], tri[(e + 1) % 3])))
            edge_tris.setdefault(key, []).append(i)
    seen_tri = np.zeros(len(boundary), dtype=bool)
    for start in range(len(boundary)):
        if seen_tri[start]:
            continue
        a, b, c = boundary[start]
        emit(a, (-1, -1, -1, -1))
        emit(b, (a, -1, -1, -1))
        emit(c, (a, b, -1, -1))
        seen_tri[start] = True
        queue = deque([start])
        while queue:
            i = queue.popleft()
            tri = boundary[i]
            for e in range(3):
                u, v, w = tri[e], tri[(e + 1) % 3], tri[(e + 2) % 3]
                for j in edge_tris[tuple(sorted((u, v)))]:
                    if seen_tri[j]:
                        continue
                    seen_tri[j] = True
                    x = [q for q in boundary[j] if q != u and q != v][0]
                    emit(x, (u, v, -1, w))
                    queue.append(j)

    # interior: grow the cut border face by face (FIFO)
    visited = np.zeros(len(tets), dtype=bool)
    border = set()
    queue = deque()
    for tri in boundary:
        key = tuple(sorted(tri))
        border.add(key)
        queue.append((tri, -1))
    tet_list = tets.tolist()
    while queue:
        tri, apex = queue.popleft()
        key = tuple(sorted(tri))
        if key not in border:
            continue
        border.discard(key)
        for t in face_tets[key]:
            if visited[t]:
                continue
            visited[t] = True
            tet = tet_list[t]
            d = [q for q in tet if q not in key]
            if d:
                emit(d[0], tri + (apex,))
            for f in faces_of:
                ftri = tuple(tet[i] for i in f)
                fkey = tuple(sorted(ftri))
                if fkey == key:
                    continue
                if fkey in border:
                    border.discard(fkey)
                else:
                    border.add(fkey)
                    queue.append((ftri, [q for q in tet if q not in ftri][0]))
            break
    for v in range(n_points):
        emit(v, (order[-1] if order else -1, -1, -1, -1))
    return np.asarray(order, dtype=np.int64), np.asarray(refs, dtype=np.int32).reshape(-1, 4)


# --------------------------------------------------------------------------------------------
# plain-Python model of the geometry coder

ADJ_CAP = 8  # neighbours remembered per vertex (gatun_py.codec._geometry_kernels.ADJ_CAP)


def ordered_int(value: np.float32) -> int:
    """Order-preserving integer of a float32's bit pattern (negative floats flipped)."""
    bits = int(np.float32(value).view(np.int32))
    return bits ^ 0x7FFFFFFF if bits < 0 else bits


def _face_and_apex(k, ref):
    face = [r for r in ref[:3] if r >= 0]
    apex = ref[3]
    return face, apex


def naive_extra_refs(values: np.ndarray, refs: np.ndarray):
    """For every vertex, the parallelogram partners and extrapolation partners the coder picks.

    Returns a list of ``(par, ext)``: ``par[p]`` for the face pairs (0, 1), (0, 2), (1, 2) is the
    common neighbour w of the pair (not the third face vertex nor the apex) whose x + y - w is
    nearest (3-D) to the first estimate of the new vertex; ``ext[q]`` the neighbour w of face
    vertex q whose 2 f_q - w is nearest. Neighbours: the edges new vertex - face refs seen so far,
    in insertion order, at most ADJ_CAP per vertex.
    """
    xyz = np.asarray(values, dtype=np.float32)[:, :3].astype(np.float64)
    n = len(xyz)
    adj: list[list[int]] = [[] for _ in range(n)]
    out = []
    for k in range(n):
        face, apex = _face_and_apex(k, [int(r) for r in refs[k]])
        par = [-1, -1, -1]
        ext = [-1, -1, -1]
        if len(face) >= 2:
            f = [xyz[v] for v in face]
            if len(face) == 3:
                est = (f[0] + f[1] + f[2] - xyz[apex]) * 0.5 if apex >= 0 else (f[0] + f[1] + f[2]) / 3.0
            else:
                est = f[0] + f[1] - xyz[apex] if apex >= 0 else (f[0] + f[1]) * 0.5
            pairs = [(0, 1, 2), (0, 2, 1), (1, 2, 0)] if len(face) == 3 else [(0, 1, None)]
            for p, (i, j, other) in enumerate(pairs):
                x, y = face[i], face[j]
                excluded = {face[other] if other is not None else -1, apex}
                best, best_d = -1, np.inf
                for w in adj[x]:
                    if w in excluded or w not in adj[y]:
                        continue
                    d = float(np.sum((xyz[x] + xyz[y] - xyz[w] - est) ** 2))
                    if d < best_d:
                        best, best_d = w, d
                par[p] = best
            for q, x in enumerate(face):
                best, best_d = -1, np.inf
                for w in adj[x]:
                    d = float(np.sum((2.0 * xyz[x] - xyz[w] - est) ** 2))
                    if d < best_d:
                        best, best_d = w, d
                ext[q] = best
        for v in face:
            for a, b in ((k, v), (v, k)):
                if b not in adj[a] and len(adj[a]) < ADJ_CAP:
                    adj[a].append(b)
        out.append((par, ext))
    return out


MAX_WEIGHT = 4.0
XY_CACHE_SLOTS = 1 << 13  # coding 3's x -> y cache
REGULAR_HEIGHT = 1.2408064788027995  # sqrt(8 / (3 sqrt(3))): a regular tet's height / sqrt(face area)


def _f(values, v, c):
    return float(values[v, c])


def naive_tri_linear(values, k, p0, p1, p2, ch, fallback):
    """The linear field through triangle (p0, p1, p2) at vertex k's position projected into its
    plane (2x2 normal equations), or ``fallback`` on a flat triangle or a far extrapolation."""
    e1 = [_f(values, p1, c) - _f(values, p0, c) for c in range(3)]
    e2 = [_f(values, p2, c) - _f(values, p0, c) for c in range(3)]
    r = [_f(values, k, c) - _f(values, p0, c) for c in range(3)]
    e11 = e12 = e22 = r1 = r2 = 0.0
    for c in range(3):  # accumulated in the kernel's order
        e11 += e1[c] * e1[c]
        e12 += e1[c] * e2[c]
        e22 += e2[c] * e2[c]
        r1 += r[c] * e1[c]
        r2 += r[c] * e2[c]
    det = e11 * e22 - e12 * e12
    if not det > 1e-12 * e11 * e22:
        return fallback
    u = (r1 * e22 - r2 * e12) / det
    v = (r2 * e11 - r1 * e12) / det
    if not (abs(u) <= MAX_WEIGHT and abs(v) <= MAX_WEIGHT):
        return fallback
    s0 = _f(values, p0, ch)
    return s0 + u * (_f(values, p1, ch) - s0) + v * (_f(values, p2, ch) - s0)


def naive_tet_linear(values, k, p0, p1, p2, p3, ch, fallback):
    """The linear field through tet (p0..p3) at vertex k (barycentric weights by Cramer's rule)."""
    a = [_f(values, p1, c) - _f(values, p0, c) for c in range(3)]
    b = [_f(values, p2, c) - _f(values, p0, c) for c in range(3)]
    cc = [_f(values, p3, c) - _f(values, p0, c) for c in range(3)]
    r = [_f(values, k, c) - _f(values, p0, c) for c in range(3)]

    def cross(u, v):
        return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]

    def dot(u, v):
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    bc, ca, ab = cross(b, cc), cross(cc, a), cross(a, b)
    det = dot(a, bc)
    scale = math.sqrt(dot(a, a) * dot(b, b) * dot(cc, cc))
    if not abs(det) > 1e-9 * scale:
        return fallback
    lam = [dot(r, bc) / det, dot(r, ca) / det, dot(r, ab) / det]
    if not all(abs(x) <= MAX_WEIGHT for x in lam):
        return fallback
    s0 = _f(values, p0, ch)
    return (s0 + lam[0] * (_f(values, p1, ch) - s0) + lam[1] * (_f(values, p2, ch) - s0)
            + lam[2] * (_f(values, p3, ch) - s0))


def naive_beyond_face(values, f0, f1, f2, apex, ch, fallback):
    """Coordinate ch of: 2 g - apex, g + n h_apex, g + n * regular height (n: the face's unit
    normal pointing away from the apex, g its centroid)."""
    g = [(_f(values, f0, c) + _f(values, f1, c) + _f(values, f2, c)) / 3.0 for c in range(3)]
    a = [_f(values, f1, c) - _f(values, f0, c) for c in range(3)]
    b = [_f(values, f2, c) - _f(values, f0, c) for c in range(3)]
    nrm = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    norm = math.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
    out = [2.0 * g[ch] - _f(values, apex, ch)]
    if not (0.0 < norm < math.inf):
        return out + [fallback, fallback]
    h = ((_f(values, apex, 0) - g[0]) * nrm[0] + (_f(values, apex, 1) - g[1]) * nrm[1]
         + (_f(values, apex, 2) - g[2]) * nrm[2]) / norm
    n_c = nrm[ch] / norm
    if h > 0.0:
        n_c, h = -n_c, -h
    return out + [g[ch] - n_c * h, g[ch] + n_c * (REGULAR_HEIGHT * math.sqrt(0.5 * norm))]


def naive_beyond_edge(values, f0, f1, apex, ch, fallback):
    """Coordinate ch of: m - p and m - p/|p| * equilateral height (m: the edge's midpoint, p: the
    apex's offset from the edge's line)."""
    e = [_f(values, f1, c) - _f(values, f0, c) for c in range(3)]
    m = [(_f(values, f0, c) + _f(values, f1, c)) * 0.5 for c in range(3)]
    e2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
    if not (0.0 < e2 < math.inf):
        return [fallback, fallback]
    d = [_f(values, apex, c) - m[c] for c in range(3)]
    t = (d[0] * e[0] + d[1] * e[1] + d[2] * e[2]) / e2
    p = [d[c] - t * e[c] for c in range(3)]
    plen = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    first = m[ch] - p[ch]
    if not (0.0 < plen < math.inf):
        return [first, fallback]
    return [first, m[ch] - p[ch] / plen * (0.8660254037844386 * math.sqrt(e2))]


def _geometric(values, k, face, apex, ch, cands):
    """Version 2's extra candidates (float32-rounded where the kernel stores them)."""
    f32 = lambda x: float(np.float32(x))  # noqa: E731  (the kernel's scratch is float32)
    if len(face) == 3 and apex >= 0:
        if ch == 3:
            centroid = f32(cands[1])
            plane = naive_tri_linear(values, k, *face, ch, centroid)
            tet = f32(naive_tet_linear(values, k, *face, apex, ch, plane))
            return [tet, plane, 0.5 * (tet + centroid)]
        return naive_beyond_face(values, *face, apex, ch, f32(cands[0]))
    if len(face) == 3:
        return [naive_tri_linear(values, k, *face, ch, f32(cands[0])) if ch == 3 else cands[0]]
    if len(face) == 2 and apex >= 0:
        if ch == 3:
            tri = f32(naive_tri_linear(values, k, face[0], face[1], apex, ch, f32(cands[0])))
            return [tri, 0.5 * (tri + f32(cands[0]))]
        return naive_beyond_edge(values, face[0], face[1], apex, ch, f32(cands[0]))
    return []


def _predictions(k, ref, col, extra, values=None, ch=0, coding=1):
    """(pattern, candidate predictions, repetition candidates) of vertex k on one channel."""
    face, apex = _face_and_apex(k, ref)
    if not face:
        if apex >= 0:
            face, apex = [apex], -1
        elif k > 0:
            face = [k - 1]
    eq = []
    for r in face + ([apex] if apex >= 0 else []):
        o = ordered_int(col[r])
        if o not in eq:
            eq.append(o)
    if not face:
        return 0, [None], eq
    if len(face) == 1:
        return 1, [("copy", ordered_int(col[face[0]]))], eq  # a plain copy keeps every bit, NaN too
    par, ext = extra
    v = [float(col[r]) for r in face]

    def parallelogram(i, j, p, fallback):
        return fallback if par[p] < 0 else v[i] + v[j] - float(col[par[p]])

    def extrapolation(q, fallback):
        return fallback if ext[q] < 0 else 2.0 * v[q] - float(col[ext[q]])

    a, b = v[0], v[1]
    if len(face) == 2:
        if apex >= 0:
            d = float(col[apex])
            first = a + b - d
            cands = [first, (a + b) * 0.5, a]
            pat = 3
        else:
            first = (a + b) * 0.5
            cands = [first, a, b]
            pat = 2
        cands = cands + [parallelogram(0, 1, 0, first), extrapolation(0, first), extrapolation(1, first)]
        if coding >= 2:
            cands += _geometric(values, k, face, apex, ch, cands)
        return pat, cands, eq
    c = v[2]
    if apex >= 0:
        d = float(col[apex])
        cands = [(a + b + c - d) * 0.5, (a + b + c) / 3.0, a + b - d, a + c - d, b + c - d, a]
        pat = 5
    else:
        cands = [(a + b + c) / 3.0, a, b, c]
        pat = 4
    h = float(np.float32(cands[0]))  # the kernel reads the first candidate back as float32
    cands += [parallelogram(0, 1, 0, h), parallelogram(0, 2, 1, h), parallelogram(1, 2, 2, h),
              extrapolation(0, h), extrapolation(1, h), extrapolation(2, h)]
    if coding >= 2:
        cands += _geometric(values, k, face, apex, ch, cands)
    return pat, cands, eq


def _candidate_int(x) -> int:
    if x is None:
        return 0
    if isinstance(x, tuple):
        return x[1]
    f = np.float32(x)
    if f != f:  # NaN payloads are not portable: predict 0
        f = np.float32(0.0)
    return ordered_int(f)


def naive_symbols(values: np.ndarray, refs: np.ndarray, modes, coding: int = 1, xy_table: bool = True) -> np.ndarray:
    """What the geometry encoder codes, computed the slow, obvious way.

    Parameters
    ----------
    values : (n, 4) float32
        x, y, z, density in decode order.
    refs : (n, 4) int
        Geometry refs.
    modes : 4 ints
        0 = residual on ordered integers, 1 = residual on ranks in the sorted table of values.
    coding : 1, 2 or 3
        The geometry block's coding version (2 adds the tet-geometry candidates; 3 codes the same
        symbols with another binarisation and keeps the x -> y pairs in a direct-mapped cache).
    xy_table : bool
        Whether y gets the repetition candidate of the x -> y table (always in codings 1 and 2).

    Returns
    -------
    (n, 4, 3) int64
        Per vertex and channel: repetition symbol (-1 when there were no ref values), residual
        (0 for a repetition), index of the predictor used (-1 for a repetition).
    """
    values = np.asarray(values, dtype=np.float32)
    n = values.shape[0]
    out = np.zeros((n, 4, 3), dtype=np.int64)
    extra = naive_extra_refs(values, refs)
    for ch in range(4):
        col = values[:, ch]
        table = sorted({ordered_int(v) for v in col})
        scores: dict = {}
        y_of_x: dict = {}  # channel 1 only: the y last seen with each x
        for k in range(n):
            pat, cands, eq = _predictions(k, [int(r) for r in refs[k]], col, extra[k], values, ch, coding)
            o = ordered_int(col[k])
            if ch == 1 and xy_table:
                x = ordered_int(values[k, 0])
                # coding 3 keeps the pairs in a direct-mapped cache: x's slot holds the last x seen there
                key = x if coding < 3 else ((x * -7046029254386353131) >> 32) & (XY_CACHE_SLOTS - 1)
                if key in y_of_x and y_of_x[key][0] == x and y_of_x[key][1] not in eq:
                    eq.append(y_of_x[key][1])
                y_of_x[key] = (x, o)
            sym = -1
            res = 0
            best = -1
            if eq:
                sym = eq.index(o) if o in eq else len(eq)
            if not eq or sym == len(eq):
                cand_o = [_candidate_int(x) for x in cands]
                sc = scores.setdefault(pat, [0] * len(cand_o))
                best = min(range(len(cand_o)), key=lambda q: (sc[q], q))
                if modes[ch] == 1:
                    rank_pred = min(bisect_left(table, cand_o[best]), len(table) - 1)
                    res = table.index(o) - rank_pred
                else:
                    res = o - cand_o[best]
                # scores: exponentially decayed bit lengths of each candidate's residual
                for q in range(len(cand_o)):
                    sc[q] = sc[q] - (sc[q] >> 4) + (abs(o - cand_o[q]).bit_length() << 4)
            out[k, ch] = (sym, res, best)
    return out


from bisect import bisect_left  # noqa: E402  (kept next to its only user)


def naive_step_context(ranks, base, others, prev_flag):
    """Coding 5's step context index, written plainly: for each of the other refs (r1, r2, apex)
    where its rank lies from ``base`` (0 no ref; 1 two or more below, 2 one below, 3 equal, 4 one
    above, 5 two or more above), then what the previous channel did (0 no previous channel, i.e.
    ``prev_flag`` None; 1 it repeated the first ref's value, flag 0; 2 anything else)."""
    classes = []
    for r in others:
        if r < 0:
            classes.append(0)
            continue
        d = int(ranks[r]) - base
        classes.append(1 if d <= -2 else 2 if d == -1 else 3 if d == 0 else 4 if d == 1 else 5)
    prev = 0 if prev_flag is None else (1 if prev_flag == 0 else 2)
    return ((classes[0] * 6 + classes[1]) * 6 + classes[2]) * 3 + prev
