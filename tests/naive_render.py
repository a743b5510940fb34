"""A slow, obviously correct ray caster: the reference the fast kernels are compared against.

For every pixel ray: clip the ray against every tet (the four face planes), cut the ray at every
crossing, and composite the pieces between consecutive cuts front to back. In volume mode the scalar at each sample
point t = k * step (k integer) in a piece [t_in, t_out) is interpolated with the barycentric
coordinates of the point in that tet; in face mode each piece takes the average of the transfer
function at its entry and exit points. The transfer function is read from the same lookup
table as the kernels (``TransferFunction.table``), interpolated with ``np.interp``.
"""

from __future__ import annotations

import numpy as np

from gatun_py.mesh.model import TET_FACES


def _table_eval(tab, lo, inv, s):
    xs = lo + np.arange(len(tab)) / inv
    return np.array([np.interp(s, xs, tab[:, c]) for c in range(4)])


OPAQUE = 0.99  # early ray termination, as the ray caster's (gatun_py.raycast._walk.OPAQUE)


def naive_render(mesh, fitted, tf, *, mode="volume", step=None, scalar_range=None, terminate=True, cull=False,
                 tet_values=None):
    """Premultiplied RGBA (H, W, 4) float64 of ``mesh`` seen by the fitted camera ``fitted``.

    ``terminate``: a ray stops at the first sample (face mode: piece) that brings its opacity to
    ``OPAQUE``. ``cull``: leave out, before casting, the tets whose scalar interval the transfer
    function's table shows nowhere, tested the plain way (every table entry from the one below
    the tet's smallest scalar to the one above its largest); the image must not change.
    ``tet_values``: one value per tet, the scalar everywhere inside it (a cell array rendered as a
    constant per cell) instead of the interpolated point scalar.
    """
    from gatun_py.mesh import default_step
    from gatun_py.raycast.transfer import load_transfer_function

    tf = load_transfer_function(tf)
    rng = mesh.scalar_range if scalar_range is None else scalar_range
    if step is None:
        step = default_step(mesh.points, mesh.boundary_faces())
    tab, lo, inv = tf.table(rng)
    unit = tf.resolve(rng).unit_distance
    if mode == "volume":
        tab = tab.copy()
        tab[:, 3] = 1.0 - (1.0 - tab[:, 3]) ** (step / unit)
    eye = np.asarray(fitted.position, dtype=np.float64)
    pts = mesh.points.astype(np.float64)
    dens = mesh.density.astype(np.float64)
    tets = mesh.tets.astype(np.int64)
    vol = mesh.signed_volumes()
    keep = vol > 0  # zero-volume tets hold no part of any ray
    if cull:
        smin, smax = dens[tets].min(axis=1), dens[tets].max(axis=1)
        n = len(tab)
        i0 = np.clip(np.floor((smin - lo) * inv).astype(np.int64) - 1, 0, n - 1)
        i1 = np.clip(np.floor((smax - lo) * inv).astype(np.int64) + 2, 0, n - 1)
        keep &= np.array([np.any(tab[a: b + 1, 3] > 0) for a, b in zip(i0, i1)], dtype=bool)
    tets = tets[keep]
    per_tet = None if tet_values is None else np.asarray(tet_values, np.float32).astype(np.float64)[keep]
    corners = pts[tets]  # (m, 4, 3)
    # outward face normals and a point on each face
    fa = corners[:, TET_FACES[:, 0]]
    fb = corners[:, TET_FACES[:, 1]]
    fc = corners[:, TET_FACES[:, 2]]
    normals = np.cross(fb - fa, fc - fa)  # (m, 4, 3)
    dirs = fitted.ray_directions()
    image = np.zeros((len(dirs), 4))
    # barycentric solve matrices
    T = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # (m, 3, 3)
    Tinv = np.linalg.inv(T)
    for r, d in enumerate(dirs):
        # inside face k iff (eye + t d - fa) . n <= 0  <=>  t * (d.n) <= (fa - eye).n
        dn = normals @ d  # (m, 4)
        rhs = np.einsum("mkj,mkj->mk", fa - eye, normals)
        with np.errstate(divide="ignore", invalid="ignore"):
            tq = rhs / dn
        t_in = np.where(dn < 0, tq, -np.inf).max(axis=1)
        t_out = np.where(dn > 0, tq, np.inf).min(axis=1)
        parallel_out = np.any((dn == 0) & (rhs < 0), axis=1)
        hit = (t_in < t_out) & ~parallel_out
        idx = np.flatnonzero(hit)
        # Cut the ray at every place it crosses a tet face; each piece between two consecutive
        # cuts lies in the tets containing its midpoint (several when the ray runs along shared
        # faces or edges: they agree there, so the first one is taken).
        cuts = np.sort(np.concatenate([t_in[idx], t_out[idx]]))
        merged = []
        for t in cuts:
            if not merged or t - merged[-1] > 1e-9 * (1.0 + abs(t)):
                merged.append(t)
        C = np.zeros(3)
        O = 0.0
        done = False

        def scalar_at(m, t):
            if per_tet is not None:
                return float(per_tet[m])
            x = eye + t * d
            l123 = Tinv[m] @ (x - corners[m, 0])
            w = np.concatenate([[1.0 - l123.sum()], l123])
            return float(w @ dens[tets[m]])

        for a, b in zip(merged[:-1], merged[1:]):
            if done:
                break
            mid = 0.5 * (a + b)
            inside = idx[(t_in[idx] <= mid) & (mid <= t_out[idx])]
            if len(inside) == 0:
                continue  # between two parts of the mesh
            m = inside[0]
            if mode == "volume":
                ks = np.arange(np.floor(a / step) - 1, np.ceil(b / step) + 2)
                ts = ks * step
                for t in ts[(ts >= a) & (ts < b)]:
                    rgba = _table_eval(tab, lo, inv, scalar_at(m, t))
                    al = rgba[3]
                    C += (1 - O) * al * rgba[:3]
                    O += (1 - O) * al
                    if terminate and O >= OPAQUE:
                        done = True
                        break
            else:
                avg = 0.5 * (_table_eval(tab, lo, inv, scalar_at(m, a)) + _table_eval(tab, lo, inv, scalar_at(m, b)))
                al = 1.0 - (1.0 - min(avg[3], 1.0)) ** ((b - a) / unit)
                C += (1 - O) * al * avg[:3]
                O += (1 - O) * al
                done = terminate and O >= OPAQUE
        image[r, :3] = C
        image[r, 3] = O
    return image.reshape(fitted.height, fitted.width, 4)


def naive_face_crossings(mesh, fitted):
    """(n_tets, 4): for each tet face (``TET_FACES`` order), the pixel rays that pass through the
    triangle, found the plain way: every pixel against every face, Moeller-Trumbore style
    (barycentric coordinates of the ray's hit in the face's plane all non-negative)."""
    eye = np.asarray(fitted.position, dtype=np.float64)
    dirs = fitted.ray_directions()
    pts = mesh.points.astype(np.float64) - eye
    out = np.zeros((mesh.n_tets, 4), dtype=np.int64)
    for t, tet in enumerate(mesh.tets):
        for k in range(4):
            a, b, c = (pts[tet[i]] for i in TET_FACES[k])
            e1, e2 = b - a, c - a
            p = np.cross(dirs, e2)
            det = p @ e1
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = -a  # ray origin (the eye, 0) minus a
            u = (p @ s) * inv
            q = np.cross(s, e1)
            v = (dirs @ q) * inv
            hit_t = (q @ e2) * inv
            out[t, k] = int(np.count_nonzero(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (hit_t > 0)))
    return out


def naive_boundary_hits(mesh, fitted):
    """Set of (face index, pixel ray, entering) for the rays crossing each of ``mesh.boundary_faces()``,
    found the plain way: every pixel of the image against every face, with the ray caster's own
    crossing rule (the three directed edge sides ``d . (P_lo x P_hi)`` share a sign; exact zeros
    decided by the first non-zero component of ``P_lo x P_hi``, then as positive), evaluated with
    the same floating-point operations, so the sets must agree exactly."""
    eye = np.asarray(fitted.position, dtype=np.float64)
    dirs = fitted.ray_directions()
    pts = mesh.points.astype(np.float64) - eye
    dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    hits = set()
    for f, face in enumerate(mesh.boundary_faces()):
        signs = []
        for i, j in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
            lo, hi, flip = (i, j, 1.0) if i < j else (j, i, -1.0)
            (ax, ay, az), (bx, by, bz) = pts[lo], pts[hi]
            cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
            v = dx * cx + dy * cy + dz * cz
            tie = next((np.sign(x) for x in (cx, cy, cz) if x != 0.0), 1.0)
            signs.append(np.where(v > 0.0, 1.0, np.where(v < 0.0, -1.0, tie)) * flip)
        crossed = (signs[0] == signs[1]) & (signs[1] == signs[2])
        hits.update((f, int(r), bool(signs[0][r] < 0)) for r in np.flatnonzero(crossed))
    return hits
