"""Metro-style distance between two triangle surfaces, in % of a bounding-box diagonal.

Points are sampled on each surface (the vertices, plus area-proportional random samples on the
faces) and their distance to the other surface is measured exactly (point to triangle) among the
triangles near the nearest sample of that surface. The symmetric RMS and Hausdorff (max) distances
are what Cignoni et al.'s Metro reports. Needs scipy (a dependency of scikit-image) for the
k-d tree; imported here only, so the core pipeline does not need it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


def sample_surface(points, triangles, n_samples: int, seed: int = 0, *, cover: bool = False):
    """The vertices plus ``n_samples`` area-weighted uniform points on the faces: (points, face id
    of each sample, -1 for vertices).

    ``cover``: also put points on every face in proportion to its longest edge, so that a long
    sliver (tiny area, few area-weighted samples) is still found by a nearest-sample search.
    """
    p = np.asarray(points, np.float64)
    t = np.asarray(triangles, np.int64)
    if len(t) == 0:
        return p, np.full(len(p), -1)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    rng = np.random.default_rng(seed)
    tot = area.sum()
    prob = area / tot if tot > 0 else np.full(len(t), 1.0 / len(t))
    f = rng.choice(len(t), size=int(n_samples), p=prob)
    if cover:
        spacing = np.sqrt(tot / max(n_samples, 1)) if tot > 0 else 1.0
        longest = np.max([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                          np.linalg.norm(a - c, axis=1)], axis=0)
        per_face = np.clip(np.ceil(longest / max(spacing, 1e-300)), 1, 64).astype(np.int64)
        f = np.concatenate([f, np.repeat(np.arange(len(t)), per_face)])
    r1 = np.sqrt(rng.random(len(f)))
    r2 = rng.random(len(f))
    s = (1 - r1)[:, None] * a[f] + (r1 * (1 - r2))[:, None] * b[f] + (r1 * r2)[:, None] * c[f]
    return np.vstack([p, s]), np.concatenate([np.full(len(p), -1), f])


@njit(cache=True, error_model="numpy")  # a flat triangle divides by zero: nan, not an exception
def _point_triangle(px, py, pz, a, b, c):
    """Squared distance from a point to a triangle (Ericson, Real-Time Collision Detection 5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0 and d2 <= 0:
        qx, qy, qz = a[0], a[1], a[2]
    else:
        bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0 and d4 <= d3:
            qx, qy, qz = b[0], b[1], b[2]
        else:
            vc = d1 * d4 - d3 * d2
            cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
            d5 = abx * cpx + aby * cpy + abz * cpz
            d6 = acx * cpx + acy * cpy + acz * cpz
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            if vc <= 0 and d1 >= 0 and d3 <= 0:
                v = d1 / (d1 - d3)
                qx, qy, qz = a[0] + v * abx, a[1] + v * aby, a[2] + v * abz
            elif d6 >= 0 and d5 <= d6:
                qx, qy, qz = c[0], c[1], c[2]
            elif vb <= 0 and d2 >= 0 and d6 <= 0:
                w = d2 / (d2 - d6)
                qx, qy, qz = a[0] + w * acx, a[1] + w * acy, a[2] + w * acz
            elif va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                qx, qy, qz = b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])
            else:
                den = 1.0 / (va + vb + vc)
                v = vb * den
                w = vc * den
                qx = a[0] + abx * v + acx * w
                qy = a[1] + aby * v + acy * w
                qz = a[2] + abz * v + acz * w
    return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2


@njit(cache=True, parallel=True, error_model="numpy")
def _distances(q, cand, pts, tris):
    """Per query point, the smallest exact distance to the candidate triangles of its row."""
    out = np.empty(q.shape[0])
    for i in prange(q.shape[0]):
        best = np.inf
        for k in range(cand.shape[1]):
            f = cand[i, k]
            if f < 0:
                continue
            d = _point_triangle(q[i, 0], q[i, 1], q[i, 2], pts[tris[f, 0]], pts[tris[f, 1]], pts[tris[f, 2]])
            if d < best:
                best = d
        out[i] = np.sqrt(best)
    return out


def one_sided(query, points, triangles, *, k: int = 64, n_samples: int = 200_000, seed: int = 1):
    """Distance from every query point to the surface (points, triangles).

    The candidates are the faces of the ``k`` surface samples nearest the query (plus the faces
    around the nearest vertices), then measured exactly; with samples far denser than the faces
    this finds the closest face.
    """
    from scipy.spatial import cKDTree  # optional dependency (scipy comes with scikit-image)

    p = np.asarray(points, np.float64)
    t = np.asarray(triangles, np.int64)
    if len(t) == 0:
        return np.full(len(query), np.inf)
    samples, face = sample_surface(p, t, max(n_samples, 4 * len(t)), seed, cover=True)
    # vertices map to one face around them
    vface = np.full(len(p), -1, np.int64)
    vface[t[:, 0]] = np.arange(len(t))
    vface[t[:, 1]] = np.arange(len(t))
    vface[t[:, 2]] = np.arange(len(t))
    face = np.where(face < 0, vface[np.minimum(np.arange(len(face)), len(p) - 1)], face)
    tree = cKDTree(samples)
    _, idx = tree.query(np.asarray(query, np.float64), k=k)
    cand = face[idx]
    return _distances(np.asarray(query, np.float64), cand, p, t.astype(np.int64))


def surface_distance(a_points, a_tris, b_points, b_tris, *, diagonal: float, n_samples: int = 200_000,
                     seed: int = 0) -> dict:
    """Symmetric sampled distance between surfaces A and B in % of ``diagonal``.

    Returns ``rms``, ``hausdorff`` (both symmetric: the larger of the two directions) and
    ``rms_ab``, ``rms_ba``, ``max_ab``, ``max_ba``.
    """
    qa, _ = sample_surface(a_points, a_tris, n_samples, seed)
    qb, _ = sample_surface(b_points, b_tris, n_samples, seed + 1)
    dab = one_sided(qa, b_points, b_tris, n_samples=n_samples)
    dba = one_sided(qb, a_points, a_tris, n_samples=n_samples)
    s = 100.0 / diagonal
    rms_ab = float(np.sqrt(np.mean(dab ** 2))) * s
    rms_ba = float(np.sqrt(np.mean(dba ** 2))) * s
    return {"rms": max(rms_ab, rms_ba), "hausdorff": max(float(dab.max()), float(dba.max())) * s,
            "rms_ab": rms_ab, "rms_ba": rms_ba, "max_ab": float(dab.max()) * s, "max_ba": float(dba.max()) * s}
