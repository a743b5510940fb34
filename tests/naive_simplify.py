"""Slow, obviously correct references for the decimation kernels and a mesh validity checker.

Everything here recomputes from scratch with Python sets and loops: the boundary from face counts,
links as sets of simplices (with a virtual vertex OMEGA joined to the boundary), volumes with the
same determinant as ``TetMesh.signed_volumes``.
"""

from __future__ import annotations

from collections import Counter
from itertools import combinations

import numpy as np

from gatun_py.mesh.model import TET_FACES

OMEGA = -1
VOLUME_EPS = 1e-10
NORMAL_EPS = 1e-6


def orient6(p, q):
    a = p[q[0]]
    u = p[q[1]] - a
    v = p[q[2]] - a
    w = p[q[3]] - a
    c = (v[1] * w[2] - v[2] * w[1], v[2] * w[0] - v[0] * w[2], v[0] * w[1] - v[1] * w[0])
    return (u[0] * c[0] + u[1] * c[1]) + u[2] * c[2]


def boundary_faces(tets):
    """Outward boundary faces of a list of tets (faces used once)."""
    cnt = Counter(frozenset(t[k] for k in f) for t in tets for f in TET_FACES)
    return [tuple(t[k] for k in f) for t in tets for f in TET_FACES if cnt[frozenset(t[k] for k in f)] == 1]


def boundary_vertices(tets):
    return {v for f in boundary_faces(tets) for v in f}


def pinned_vertices(tets, n):
    """Vertices with a non-manifold neighbourhood (link Euler characteristic, non-manifold edges)."""
    bf = boundary_faces(tets)
    bnd = {v for f in bf for v in f}
    pinned = set()
    ecount = Counter(frozenset(e) for f in bf for e in combinations(f, 2))
    for e, c in ecount.items():
        if c != 2:
            pinned |= set(e)
    for v in range(n):
        star = [t for t in tets if v in t]
        if not star:
            continue
        edges = {w for t in star for w in t if w != v}
        faces = {frozenset(set(t) - {v, w}) for t in star for w in t if w != v}
        chi = len(edges) - len(faces) + len(star)
        if chi != (1 if v in bnd else 2):
            pinned.add(v)
    return pinned


def link(v, tets, bfaces):
    out = set()
    for t in tets:
        if v in t:
            rest = [w for w in t if w != v]
            for k in (1, 2, 3):
                out |= {frozenset(c) for c in combinations(rest, k)}
    for f in bfaces:
        if v in f:
            rest = [w for w in f if w != v] + [OMEGA]
            for k in (1, 2, 3):
                out |= {frozenset(c) for c in combinations(rest, k) if OMEGA in c}
    return out


def edge_link(a, b, tets, bfaces):
    out = set()
    for t in tets:
        if a in t and b in t:
            rest = [w for w in t if w not in (a, b)]
            for k in (1, 2):
                out |= {frozenset(c) for c in combinations(rest, k)}
    for f in bfaces:
        if a in f and b in f:
            rest = [w for w in f if w not in (a, b)] + [OMEGA]
            for k in (1, 2):
                out |= {frozenset(c) for c in combinations(rest, k) if OMEGA in c}
    return out


def tri_area_normal(p, f):
    n = np.cross(p[f[1]] - p[f[0]], p[f[2]] - p[f[0]])
    return n


def interpolate(p, d, q, x):
    """(smallest barycentric coordinate, interpolated density) of point x in tet q."""
    v6 = orient6(p, q)
    lam = []
    for j in range(4):
        pp = [p[w] for w in q]
        pp[j] = x
        lam.append(orient6(np.array(pp), (0, 1, 2, 3)) / v6)
    return min(lam), sum(lam[j] * d[q[j]] for j in range(4))


def quadric_matrix(q):
    """(A 4x4, b 4, c) of a quadric stored as A's upper triangle row by row, b, c."""
    A = np.zeros((4, 4))
    A[np.triu_indices(4)] = q[:10]
    A = A + A.T - np.diag(np.diag(A))
    return A, np.asarray(q[10:14], np.float64), float(q[14])


def quadric_value(q, u):
    A, b, c = quadric_matrix(q)
    u = np.asarray(u, np.float64)
    return max(0.0, float(u @ A @ u + 2 * b @ u + c))


def tet_quadrics(u4, tets, weight):
    """Per-vertex sum over its tets of weight x (squared distance to the tet's 4D hyperplane), as a
    quadric; the hyperplane's normal is the null vector of the three edge vectors (SVD)."""
    u4 = np.asarray(u4, np.float64)
    out = np.zeros((u4.shape[0], 15))
    iu = np.triu_indices(4)
    for t, w in zip(tets, weight):
        if w <= 0:
            continue
        P = u4[list(t)]
        e = P[1:] - P[0]
        nrm = np.linalg.svd(e)[2][-1]  # unit vector orthogonal to the tet's three edges
        d = -nrm @ P[0]
        q = np.concatenate([np.outer(nrm, nrm)[iu], nrm * d, [d * d]]) * w
        for v in t:
            out[v] += q
    return out


def sample_value(p, d, new_tets, x, fallback):
    """The new mesh's value at point x: from the first of ``new_tets`` containing it, else from the
    one it is nearest to (largest smallest barycentric coordinate, the first of equals)."""
    best = None
    for q in new_tets:
        lo, v = interpolate(p, d, q, x)
        if lo >= 0:
            return v
        if best is None or lo > best[0]:
            best = (lo, v)
    return fallback if best is None else best[1]


def evaluate_merge(tets, pts, dens, a, b, *, is_boundary, pinned, wd, wg, wv, wi, wq=0.0, quad=None, u4=None,
                   ws=0.0, samples=None, pw=None, n_power=1.0, max_samples=None):
    """(legal, error) of merging a into b in the mesh ``tets`` (list of 4-tuples).

    ``wd``, ``wg``, ``wv``, ``wi`` (mass, boundary area, swept boundary volume, squared
    interpolation error) are the weights already divided by the normalisation scales, ``wq`` the
    weight of a's quadric ``quad[a]`` evaluated at b's point ``u4[b]``, ``ws`` the weight of the
    sampled error: ``samples`` maps every sample point (an index into ``pts`` and ``dens``, beyond
    the vertices for the tet centroids) to the tet (4-tuple) holding it, ``pw`` its weight; the
    term is the change of sum pw (value - interpolant)^2 over the points in a's tets (if there are
    more than ``max_samples``, every k-th in ``samples`` order, times k, with the smallest such k
    that leaves at most ``max_samples``). The sum is divided by (number of tets the merge
    collapses) ** ``n_power``. ``is_boundary`` is the input's
    boundary vertex set and ``pinned`` the non-manifold vertices.
    """
    p = np.asarray(pts, np.float64)
    d = np.asarray(dens, np.float64)
    star = [t for t in tets if a in t]
    if not any(b in t for t in star) or a in pinned or b in pinned:
        return False, None
    if a in is_boundary and b not in is_boundary:
        return False, None
    dm = 0.0
    new_tets = []
    for t in star:
        old6 = orient6(p, t)
        m_old = old6 / 6.0 * sum(d[w] for w in t) / 4
        if b in t:
            dm += abs(m_old)
            continue
        q = tuple(b if w == a else w for w in t)
        new6 = orient6(p, q)
        lmax = max(np.sum((p[x] - p[y]) ** 2) for x, y in combinations(q, 2)) ** 1.5
        if old6 == 0.0:
            ok = new6 == 0.0 or new6 > VOLUME_EPS * lmax
        else:
            ok = new6 > VOLUME_EPS * lmax or (new6 >= old6 and new6 > 0.0)
        if not ok:
            return False, None
        if new6 > 0:
            new_tets.append(q)
        dm += abs(new6 / 6.0 * sum(d[w] for w in q) / 4 - m_old)
    if wi > 0:
        # the new mesh's value at a's position: from the new tet containing it (or nearest to)
        vals = [interpolate(p, d, q, p[a]) for q in new_tets]
        inside = [abs(d[a] - v) for lo, v in vals if lo >= 0]
        if inside:
            dev = min(inside)
        else:
            # nearest outside: the largest smallest coordinate, ties by the smaller deviation
            dev = min(((-lo, abs(d[a] - v)) for lo, v in vals), default=(0.0, abs(d[a] - d[b])))[1]
        di = wi * dev**2 * sum(abs(orient6(p, t)) / 6.0 for t in star)
    else:
        di = 0.0
    bfaces = boundary_faces(tets)
    ge = 0.0
    swept = 0.0
    if a in is_boundary:
        old = [f for f in bfaces if a in f]
        area = {f: 0.5 * np.linalg.norm(tri_area_normal(p, f)) for f in old}
        total = sum(area.values())
        for f in old:
            if b in f:
                continue
            g = tuple(b if w == a else w for w in f)
            n_old = tri_area_normal(p, f)
            n_new = tri_area_normal(p, g)
            if not np.dot(n_old, n_new) > NORMAL_EPS * np.linalg.norm(n_new) * np.linalg.norm(n_old):
                return False, None
            a_new = 0.5 * np.linalg.norm(n_new)
            swept += abs(orient6(p, (f[0], f[1], f[2], b))) / 6.0
            for h in old:
                if len(set(g) & set(h)) >= 2 and total > 0:
                    ge += abs(a_new - area[h]) * area[h] / total
    if not link(a, tets, bfaces) & link(b, tets, bfaces) <= edge_link(a, b, tets, bfaces):
        return False, None
    qe = quadric_value(quad[a], u4[b]) if wq > 0 else 0.0
    se = 0.0
    if ws > 0 and samples:
        mine = [(x, t) for x, t in samples.items() if t in star]
        k = 1
        if max_samples is not None and len(mine) > max_samples:
            k = -(-len(mine) // int(max_samples))
        for x, t in mine[::k]:
            if orient6(p, t) > 0:
                se -= pw[x] * (d[x] - interpolate(p, d, t, p[x])[1]) ** 2
            own = tuple(b if w == a else w for w in t)
            # the point's own tet first (ties between containing tets only differ by rounding)
            order = ([own] if own in new_tets else []) + [q for q in new_tets if q != own]
            se += pw[x] * (d[x] - sample_value(p, d, order, p[x], d[b])) ** 2
        se *= ws * k
    n_collapsed = sum(1 for t in star if b in t)
    return True, (wd * dm + di + wg * ge + wv * swept + wq * qe + se) / n_collapsed**n_power


def collapse(tets, a, b):
    """The tets after merging a into b (tets of edge ab vanish)."""
    return [tuple(b if w == a else w for w in t) for t in tets if not (a in t and b in t)]


def reassign_samples(tets, pts, dens, samples, a, b):
    """The sample assignment after merging a into b (``samples``: point -> tet 4-tuple, as in
    :func:`evaluate_merge`): a and the points of a's tets go to the first new tet of a's star that
    contains them, else to the one they are nearest to (dropped if the new star is all flat)."""
    p = np.asarray(pts, np.float64)
    star = [t for t in tets if a in t]
    new_star = [tuple(b if w == a else w for w in t) for t in star if b not in t]
    new_star = [q for q in new_star if orient6(p, q) > 0]
    out = {x: t for x, t in samples.items() if a not in t}
    for x in [a] + [x for x, t in samples.items() if a in t]:
        best = None
        for q in new_star:
            lo, _ = interpolate(p, dens, q, p[x])
            if best is None or lo > best[0]:
                best = (lo, q)
            if lo >= 0:
                break
        if best is not None:
            out[x] = best[1]
    return out


def legal_merges(tets, pts, dens, **kw):
    """Every legal (a, b, error) of the mesh: the full candidate set, for small meshes only."""
    out = []
    edges = {(x, y) for t in tets for x in t for y in t if x != y}
    for a, b in sorted(edges):
        ok, e = evaluate_merge(tets, pts, dens, a, b, **kw)
        if ok:
            out.append((a, b, e))
    return out


def ancestors_naive(parent, rank, n_merges):
    """Follow parents while the current vertex's merge is among the first n_merges."""
    out = []
    for v in range(len(parent)):
        while rank[v] < n_merges:
            v = parent[v]
        out.append(v)
    return np.array(out, np.int64)


def check_valid(mesh, n_flat_input: int, label: str = "", *, manifold: bool = True) -> None:
    """Assert the mesh is a valid simplification state.

    No tet with signed volume <= 0 beyond ``n_flat_input`` exactly-flat ones (and none negative),
    no face in more than two tets, no duplicate tets, every boundary edge in exactly two
    boundary faces (closed boundary; an even number when the input itself is not a manifold).
    """
    vol = mesh.signed_volumes()
    assert not np.any(vol < 0), f"{label}: {int((vol < 0).sum())} inverted tets"
    assert int((vol == 0).sum()) <= n_flat_input, f"{label}: {int((vol == 0).sum())} flat tets > {n_flat_input}"
    n = max(mesh.n_points, 1)
    t = np.sort(mesh.tets.astype(np.int64), axis=1)
    assert np.all(t[:, 1:] != t[:, :-1]), f"{label}: repeated vertex in a tet"
    # rows as exact integer keys (Python ints when n**4 would overflow int64)
    tk = ((t[:, 0] * n + t[:, 1]) * n + t[:, 2]) * n + t[:, 3] if n < 2**15 else [tuple(r) for r in t.tolist()]
    assert len(set(tk.tolist() if isinstance(tk, np.ndarray) else tk)) == t.shape[0], f"{label}: duplicate tets"
    f = np.sort(mesh.tets[:, TET_FACES].reshape(-1, 3).astype(np.int64), axis=1)
    _, fc = np.unique((f[:, 0] * n + f[:, 1]) * n + f[:, 2], return_counts=True)
    assert fc.max(initial=0) <= 2, f"{label}: a face shared by {fc.max()} tets"
    bf = mesh.boundary_faces().astype(np.int64)
    if bf.shape[0]:
        e = np.sort(bf[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        _, ec = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
        assert np.all(ec % 2 == 0), f"{label}: boundary not closed ({int((ec % 2 == 1).sum())} open edges)"
        if manifold:
            assert np.all(ec == 2), f"{label}: {int((ec != 2).sum())} boundary edges not in exactly two faces"


def face_neighbours(tets):
    """nbr[t][k] = the tet across the face opposite corner k of t, -1 on the boundary (by a dict of
    sorted faces)."""
    owner = {}
    for t, q in enumerate(tets):
        for k in range(4):
            owner.setdefault(tuple(sorted(w for j, w in enumerate(q) if j != k)), []).append((t, k))
    nbr = [[-1] * 4 for _ in tets]
    for pair in owner.values():
        if len(pair) == 2:
            (t, k), (u, j) = pair
            nbr[t][k], nbr[u][j] = u, t
    return nbr


def max_coverage(mesh, n_random: int = 400, seed: int = 0) -> int:
    """Most tets containing one point (strictly inside, barycentric > 1e-9), over every tet's
    centroid and random points of the bounding box: 1 when no two tets overlap (a plain O(P m)
    reference; small meshes only)."""
    p = mesh.points.astype(np.float64)
    t = mesh.tets.astype(np.int64)
    if t.shape[0] == 0:
        return 0
    rng = np.random.default_rng(seed)
    q = np.concatenate([p[t].mean(axis=1), p.min(axis=0) + rng.random((n_random, 3)) * np.ptp(p, axis=0)])
    p0 = p[t[:, 0]]
    edges = np.stack([p[t[:, 1]] - p0, p[t[:, 2]] - p0, p[t[:, 3]] - p0], axis=2)
    solid = np.linalg.det(edges) != 0  # a flat tet (allowed where the input has them) covers nothing
    p0, inv = p0[solid], np.linalg.inv(edges[solid])
    lam = np.einsum("mij,pmj->pmi", inv, q[:, None, :] - p0[None])
    inside = (lam > 1e-9).all(axis=2) & (lam.sum(axis=2) < 1.0 - 1e-9)
    return int(inside.sum(axis=1).max())
