"""Selective refinement from bricked forests (third round, step 2).

A bricked file holds one forest per brick, every brick's cut vertices locked, so any
choice of one prefix length per brick is a conforming, flip-free mesh by construction (the cut
faces are the same triangles at every prefix). A *selective* cut here = a prefix length per brick,
chosen for the view and transfer function, against the uniform cut of the unbricked forest at
equal total tets.

* reach: the fewest tets each K can get to (every brick's forest exhausted; cut vertices never
  merge), against the uniform cuts at 95 / 99 % merged;
* allocation: per brick an error curve E_b(m) (image error with brick b at prefix m, the others
  full; *oracle*: measured renders of the whole mesh; *estimate*: brick b rendered alone), then
  the greedy marginal allocation over the curves' lower convex hulls (give tets to the brick with
  the largest error drop per tet) to the goal's tets; the stitched mesh rendered and compared with
  the unbricked uniform cut and with the bricked uniform one (the same share of each brick's
  merges) at the same tets;
* two tiers: the exhausted bricks stitched in groups (the k-d tree's subtrees) and decimated again
  with only the group's outer cut vertices locked; how far that reaches.

Run: ``python bench/bench_selective_bricks.py [--quick]`` -> ``bench/sections/selective_bricks.md``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from bench_selective import (DATASETS, RATIOS, SIZE, VIEWS, InMemoryRenderer as Renderer, rmse, sse, tetc_file,
                             transfer_functions)
from common import WORK, code_state, table, write_section

QUICK = "--quick" in sys.argv
KS = [8, 27, 64]
FRACTIONS = (0.0, 0.5, 0.8, 0.9, 0.95, 0.98, 1.0)  # of a brick's merges, where its error is measured


def bricked_file(name, k):
    import gatun_py
    from common import SAMPLE_FILES

    path = WORK / f"{name}_k{k}.tetc"
    if not path.exists():
        src, kw, _ = SAMPLE_FILES[name]
        t0 = time.perf_counter()
        gatun_py.compress(src, path, bricks=k, jobs=1, **kw)
        print(f"compressed {name} as {k} bricks in {time.perf_counter() - t0:.1f} s", flush=True)
    return path


class Bricks:
    """Every brick's level 0, forest, tets per prefix length and cut vertices; stitched meshes."""

    def __init__(self, reader):
        from gatun_py.codec.bricks import read_cut
        from gatun_py.simplify.dependencies import merge_dependencies

        self.reader = reader
        self.k = reader.n_bricks
        self.n_cut = int(reader.meta["cut_points"])
        self.meshes, self.forests, self.cuts, self.tets_after, self.n_merges = [], [], [], [], []
        for b in range(self.k):
            br = reader.brick(b)
            mesh = br.decode_mesh(0)
            forest = br.read_forest(0)
            removed = merge_dependencies(mesh, forest, reduce=False).removed
            self.meshes.append(mesh)
            self.forests.append(forest)
            self.cuts.append(read_cut(reader, b, 0))
            self.tets_after.append(mesh.n_tets - np.concatenate([[0], np.cumsum(removed, dtype=np.int64)]))
            self.n_merges.append(removed.size)
        self._cache = {}

    def tets(self, m) -> int:
        return int(sum(t[int(x)] for t, x in zip(self.tets_after, m)))

    def brick_mesh(self, b, m):
        from gatun_py.simplify.forest import ancestors, mesh_from_ancestors

        key = (b, int(m))
        if key not in self._cache:
            if len(self._cache) > 4 * self.k + 64:
                self._cache.clear()
            parent, rank = self.forests[b]
            mesh, kept = mesh_from_ancestors(self.meshes[b], ancestors(parent, rank, int(m)))
            pos, ids = self.cuts[b]
            self._cache[key] = (mesh, (np.searchsorted(kept, pos), ids))
        return self._cache[key]

    def stitched(self, m):
        from gatun_py.codec.bricks import stitch_bricks

        parts = [self.brick_mesh(b, x) for b, x in enumerate(m)]
        return stitch_bricks([p[0] for p in parts], [p[1] for p in parts], self.n_cut)


def error_curves(bricks, render, full, *, alone=False):
    """Per brick: (merges, tets, error) at FRACTIONS of its merges. Oracle: the whole mesh with
    brick b at that prefix, the others full (SSE against the full render); ``alone``: brick b
    rendered by itself at that prefix against itself full."""
    curves = []
    zero = [0] * bricks.k
    for b in range(bricks.k):
        ms = sorted({int(round(f * bricks.n_merges[b])) for f in FRACTIONS})
        ref = render(bricks.brick_mesh(b, 0)[0]) if alone else full
        pts = []
        for m in ms:
            if m == 0:
                pts.append((0, int(bricks.tets_after[b][0]), 0.0))
                continue
            if alone:
                img = render(bricks.brick_mesh(b, m)[0])
            else:
                mm = list(zero)
                mm[b] = m
                img = render(bricks.stitched(mm))
            pts.append((m, int(bricks.tets_after[b][m]), sse(ref, img)))
        curves.append(pts)
    return curves


def _hull(pts):
    """The lower convex hull of (tets, error) points, from the coarsest (fewest tets) up."""
    pts = sorted(pts, key=lambda p: p[1])
    hull = []
    for p in pts:
        while len(hull) >= 2:
            (_, t1, e1), (_, t2, e2) = hull[-2], hull[-1]
            # drop the middle point when it lies on or above the segment from hull[-2] to p
            if (e2 - e1) * (p[1] - t1) >= (p[2] - e1) * (t2 - t1):
                hull.pop()
            else:
                break
        if hull and p[2] >= hull[-1][2]:
            continue  # more tets, no less error: never worth it
        hull.append(p)
    return hull


def allocate(bricks, curves, goal):
    """Prefix lengths (one per brick) with at most ``goal`` tets by the greedy marginal allocation
    over the curves' lower hulls; None when the bricks cannot get down to ``goal``."""
    hulls = [_hull(c) for c in curves]
    m = [h[0][0] for h in hulls]  # coarsest point of each hull
    if bricks.tets(m) > goal:
        return None
    at = [0] * bricks.k
    while True:
        best, gain = None, 0.0
        for b, h in enumerate(hulls):
            if at[b] + 1 < len(h):
                (_, t1, e1), (_, t2, e2) = h[at[b]], h[at[b] + 1]
                g = (e1 - e2) / max(t2 - t1, 1)
                if g > gain:
                    best, gain = b, g
        if best is None:
            return m
        nxt = hulls[best][at[best] + 1]
        trial = list(m)
        trial[best] = nxt[0]
        if bricks.tets(trial) <= goal:
            m, at[best] = trial, at[best] + 1
            continue
        # part of the step: the fewest merges of this brick that still fit
        room = goal - (bricks.tets(m) - int(bricks.tets_after[best][m[best]]))
        ok = np.flatnonzero(bricks.tets_after[best] <= room)
        ok = ok[ok >= nxt[0]]
        if ok.size:
            m[best] = int(ok[0])
        return m


def uniform_bricked(bricks, goal):
    """The same share of every brick's merges, the smallest share with at most ``goal`` tets."""
    lo, hi = 0.0, 1.0
    if bricks.tets([bricks.n_merges[b] for b in range(bricks.k)]) > goal:
        return None
    for _ in range(40):
        mid = (lo + hi) / 2
        if bricks.tets([int(mid * n) for n in bricks.n_merges]) <= goal:
            hi = mid
        else:
            lo = mid
    return [int(hi * n) for n in bricks.n_merges]


def unbricked(reader, render, src, goal):
    from gatun_py.pipeline.selective import uniform_cut
    from gatun_py.simplify.dependencies import cut_ancestors
    from gatun_py.simplify.forest import mesh_from_ancestors

    if not hasattr(reader, "_bench_mesh0"):
        reader._bench_mesh0 = reader.decode_mesh(0)
    cut = uniform_cut(src, tets=goal)
    mesh = mesh_from_ancestors(reader._bench_mesh0, cut_ancestors(src.parent, src.rank, cut))[0]
    return render(mesh), mesh.n_tets


def reach_rows(name, src_reader, rows):
    from gatun_py.codec import TetcReader
    from gatun_py.pipeline.selective import selective_source, uniform_cut

    src = selective_source(src_reader)
    n = src.points.shape[0]
    goals = {r: src.deps.cut_tets(src.n_tets, uniform_cut(src, merges=int(r * n))) for r in RATIOS}
    for k in KS:
        reader = TetcReader(bricked_file(name, k))
        bricks = Bricks(reader)
        lowest = bricks.tets(bricks.n_merges)
        n_cut = int(reader.meta["cut_points"])
        rows.append([name, k, src.n_tets, n_cut, 100.0 * n_cut / n, lowest, 100.0 * lowest / src.n_tets,
                     goals[0.95], goals[0.99], lowest / goals[0.95]])
        print(rows[-1], flush=True)


def allocation_rows(name, k, shares, rows, *, views=None, tfs=None):
    """Per view / TF and goal (a share of the tets): the oracle and estimated per-brick allocations
    against the unbricked and bricked uniform cuts."""
    from gatun_py.codec import TetcReader
    from gatun_py.pipeline.selective import selective_source
    from gatun_py.pipeline.stream import View
    from gatun_py.raycast.camera import Camera

    base = TetcReader(tetc_file(name))
    src = selective_source(base)
    reader = TetcReader(bricked_file(name, k))
    bricks = Bricks(reader)
    lowest = bricks.tets(bricks.n_merges)
    for label, tf in tfs or transfer_functions(name, cutoff=True):
        for az, el in views or VIEWS:
            t0 = time.perf_counter()
            view = View(Camera(SIZE, SIZE, az, el), tf=tf)
            render = Renderer(base, view)
            full = render(bricks.stitched([0] * bricks.k))
            oracle = error_curves(bricks, render, full)
            alone = error_curves(bricks, render, full, alone=True)
            for share in shares:
                goal = max(int(share * src.n_tets), lowest)
                img_u, tets_u = unbricked(base, render, src, goal)
                ru = rmse(full, img_u)
                row = [name, k, label, f"({az:g}, {el:g})", goal, tets_u, ru]
                for m in (uniform_bricked(bricks, goal), allocate(bricks, oracle, goal), allocate(bricks, alone, goal)):
                    if m is None:
                        row += ["-", "-"]
                        continue
                    mesh = bricks.stitched(m)
                    row += [mesh.n_tets, rmse(full, render(mesh)) / ru]
                row.append(time.perf_counter() - t0)
                rows.append(row)
                print(rows[-1], flush=True)


def kd_groups(count, depth, first=0):
    """Brick index ranges of the k-d tree's subtrees ``depth`` splits down (as partition_tets
    splits: the lower half gets count // 2 bricks)."""
    if depth == 0 or count == 1:
        return [(first, first + count)]
    low = count // 2
    return kd_groups(low, depth - 1, first) + kd_groups(count - low, depth - 1, first + low)


def tier_forest(mesh, tet_group):
    """A forest over ``mesh`` whose vertices used by tets of two groups are locked (none for one
    group), and the tets after each prefix of it."""
    from gatun_py.simplify import decimate
    from gatun_py.simplify.dependencies import merge_dependencies

    locked = None
    if tet_group.max() > 0:
        lo = np.full(mesh.n_points, np.iinfo(np.int64).max)
        hi = np.full(mesh.n_points, -1)
        for c in range(4):
            np.minimum.at(lo, mesh.tets[:, c], tet_group)
            np.maximum.at(hi, mesh.tets[:, c], tet_group)
        locked = lo != hi
    forest = decimate(mesh, locked=locked)
    removed = merge_dependencies(mesh, forest, reduce=False).removed
    return forest, mesh.n_tets - np.concatenate([[0], np.cumsum(removed, dtype=np.int64)]), locked


def tier_rows(name, k, rows, switch: float = 1.0):
    """Tiers above the bricks: the exhausted bricks stitched, decimated again with only the cut
    vertices between the k-d tree's subtrees locked (8 subtrees, then none), each tier exhausted
    before the next (``switch`` < 1: each brick, then each group, stops at that share of its
    forest's merges, before the forest's costly tail). Below the last locked tier's reach the
    cut is forced: a prefix of the top tier's forest (no choice left); its RMSE against the
    unbricked uniform cut at the 95 / 99 % goals, for every view and TF."""
    from gatun_py.codec import TetcReader
    from gatun_py.pipeline.selective import selective_source, uniform_cut
    from gatun_py.pipeline.stream import View
    from gatun_py.raycast.camera import Camera
    from gatun_py.simplify.forest import ancestors, mesh_from_ancestors

    base = TetcReader(tetc_file(name))
    src = selective_source(base)
    n = src.points.shape[0]
    goals = {r: src.deps.cut_tets(src.n_tets, uniform_cut(src, merges=int(r * n))) for r in RATIOS}
    bricks = Bricks(TetcReader(bricked_file(name, k)))
    first = [int(switch * x) for x in bricks.n_merges]
    mesh = bricks.stitched(first)
    brick_of_tet = np.repeat(np.arange(k), [bricks.brick_mesh(b, first[b])[0].n_tets for b in range(k)])
    reach = [bricks.tets(first)]
    t0 = time.perf_counter()
    for depth in ([3, 0] if k > 8 else [0]):
        group = np.zeros(k, np.int64)
        for g, (a, b) in enumerate(kd_groups(k, depth)):
            group[a:b] = g
        forest, tets_after, locked = tier_forest(mesh, group[brick_of_tet])
        if depth:  # a locked tier: done before the next (its tets then lie in one group each)
            mesh = mesh_from_ancestors(mesh, ancestors(forest.parent, forest.rank, int(switch * forest.n_merges)))[0]
            reach.append(mesh.n_tets)
            brick_of_tet = np.zeros(mesh.n_tets, np.int64)  # the next (top) tier locks nothing
    build_s = time.perf_counter() - t0
    for ratio in RATIOS:
        goal = goals[ratio]
        m = int(np.flatnonzero(tets_after <= goal)[0]) if (tets_after <= goal).any() else forest.n_merges
        cut = mesh_from_ancestors(mesh, ancestors(forest.parent, forest.rank, m))[0]
        errs = []
        for label, tf in transfer_functions(name, cutoff=True):
            for az, el in VIEWS:
                render = Renderer(base, View(Camera(SIZE, SIZE, az, el), tf=tf))
                full = render(bricks.stitched([0] * k))
                img_u, _ = unbricked(base, render, src, goal)
                errs.append(rmse(full, render(cut)) / rmse(full, img_u))
        rows.append([name, k, f"{switch:.0%}", f"{ratio:.0%}", goal, " / ".join(f"{x:,}" for x in reach), int(tets_after[-1]),
                     cut.n_tets, float(np.median(errs)), float(min(errs)), float(max(errs)), build_s])
        print(rows[-1], flush=True)



SHARES = (0.12, 0.2, 0.3, 0.45)  # goals for the allocation, as shares of the full mesh's tets
SWITCHES = (1.0, 0.9)  # share of each brick's merges applied before the tier above takes over


def main():
    """Reach, allocation and tiers; the rows are kept in bench/out (``--tiers-only``: measure the
    tiers again, keep the rest)."""
    import json

    from gatun_py.codec import TetcReader

    keep = WORK / "selective_bricks_rows.json"
    if "--tiers-only" in sys.argv:
        reach, alloc, _ = json.loads(keep.read_text())
    else:
        reach, alloc = [], []
        for name in DATASETS:
            reach_rows(name, TetcReader(tetc_file(name)), reach)
        for name in DATASETS:
            for k in (KS[:1] if QUICK else KS):
                lowest = next(r[6] for r in reach if r[0] == name and r[1] == k) / 100.0
                shares = [s for s in SHARES if s > lowest] or [lowest]
                # K = 8: every TF; more bricks (a minute per brick and TF): the sample's TF
                allocation_rows(name, k, shares, alloc, views=VIEWS[:1],
                                tfs=None if k == KS[0] else transfer_functions(name)[:1])
    tiers = []
    for name in DATASETS:
        for k in (KS[:1] if QUICK else KS):
            for switch in SWITCHES:
                tier_rows(name, k, tiers, switch)
    WORK.mkdir(parents=True, exist_ok=True)
    keep.write_text(json.dumps([reach, alloc, tiers], default=float))
    ok = [r for r in alloc if r[10] != "-"]
    text = f"""# Selective refinement from bricked forests

Code: {code_state()}. {SIZE}², volume mode, in memory: every mesh (stitched bricks, unbricked cuts)
rendered with the full mesh's camera, scalar range and step. RMSE on 0-255 against the full
render. Bricked files: `tetc compress --bricks K` of the same samples (default levels, cut
vertices locked in every brick's forest); unbricked: the file of `bench_selective.py`.

## Reach: the fewest tets a bricked file's per-brick prefixes can give

{table(["data", "K", "tets", "cut vertices", "cut % of points", "fewest tets", "% of tets", "goal 95 %",
        "goal 99 %", "fewest / goal 95 %"], reach)}

No K reaches the issue's 95 % or 99 % cells: at 95 % merged 5 % of the vertices are left, and the
locked cut vertices alone are {min(r[4] for r in reach):.1f}-{max(r[4] for r in reach):.1f} % of all the points.

## Per-brick prefixes chosen for the view against uniform, at equal tets (view (30, 20))

Goal = a share of the tets the bricks can reach. TFs: the sample's preset, its opacities x 0.3, and
the preset fully transparent below the scalar's 75th percentile (K = 8; the preset only for more
bricks). *unbricked uniform*: the first N merges of the
unbricked forest. *bricked uniform*: the same share of every brick's merges. *oracle*: per-brick
prefixes by the greedy marginal allocation over measured error curves (the whole mesh rendered with
brick b at {len(FRACTIONS) - 1} prefix lengths, the others full); *estimate*: the same from brick b
rendered alone. Ratios are RMSE / unbricked uniform RMSE.

{table(["data", "K", "TF", "view", "goal tets", "unbricked tets", "RMSE unbricked uniform", "bricked uniform tets",
        "bricked uniform / unbricked", "oracle tets", "oracle / unbricked", "estimate tets", "estimate / unbricked",
        "cell s"], alloc)}

Median oracle / unbricked uniform: **{np.median([r[10] for r in ok]):.3f}** (best {min(r[10] for r in ok):.3f});
bricked uniform / unbricked uniform {np.median([r[8] for r in ok]):.3f}: the locks cost more than the
per-brick choice gains.

## Two tiers and more: the exhausted bricks stitched and decimated again

Tier 2 (K > 8): the bricks stitched when each has applied the *switch* share of its merges (100 %:
exhausted) and decimated with only the cut vertices between the 8 subtrees of the k-d tree locked;
the top tier: the tiers below (each at the same switch share) decimated with nothing locked. Below the last locked tier's
reach every brick and group must be done first, so the cut is *forced*: a prefix of the top tier's
forest, with no choice left for a view or TF. Its RMSE / the unbricked uniform RMSE at the 95 / 99 %
goals, over the 3 views x 3 TFs. The last 2 % of the bricks' merges lose 1.5-15 % of the mesh's
volume (measured by hand, K = 8 / 64: Blunt-fin 0.9986 / 0.999 of it at 98 %, 0.848 / 0.939
exhausted; Combustion 0.996 / 0.995, 0.941 / 0.980; the unbricked forest keeps 0.999-1.000 down to
the 95 % goal): switching before that tail is what keeps the forced cut near uniform.

{table(["data", "K", "switch", "merged", "goal tets", "reach per tier (tets)", "top tier fewest", "forced cut tets",
        "median / unbricked", "best", "worst", "tiers built s"], tiers)}
"""
    write_section("selective_bricks", text)



if __name__ == "__main__":
    main()
