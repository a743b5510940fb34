"""Selective refinement against uniform refinement, in the same run.

* the issue's target table: Blunt-fin and Combustion, each with its transfer function and a more
  transparent one (opacities x 0.3), three views, 95 % and 99 % of the vertices merged; RMSE
  (0-255) against the full-resolution render of the same view at equal tet counts;
* PSNR over tets for both (Combustion, figure) and the tets each needs for equal quality;
* ``--budget`` runs (0.05-0.5 s at 256²): selective vs uniform, PSNR and measured frame time;
* selection cost against the frame time, the importance ablation, the ``deps`` section's size;
* the diagnosis of what limits the selective cut (second round): on the same cells, an
  *unsafe* cut (the importance order without the dependency closure: overlaps allowed) and *legal*
  cuts (the importance order with a run-time legality check instead of the closure,
  :func:`gatun_py.simplify.dependencies.legal_cut`), with the shipped importance and with a region
  error (:func:`gatun_py.pipeline.selective.region_error`); and the per-merge image error measured
  in each merge's prefix state (render before and after it) against what each predictor says.

Run: ``python bench/bench_selective.py [--quick]`` → ``bench/sections/selective.md`` + ``bench/figures/``.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from common import FIGURES, SAMPLE_FILES, WORK, code_state, table, write_section

QUICK = "--quick" in sys.argv
DATASETS = ["bluntfin", "combustion"]
VIEWS = [(30.0, 20.0), (120.0, -30.0), (200.0, 60.0)]
RATIOS = [0.95, 0.99]
SIZE = 256
BUDGETS = [0.05, 0.1, 0.2, 0.5]


def tetc_file(name):
    import gatun_py

    WORK.mkdir(parents=True, exist_ok=True)
    path = WORK / f"{name}_selective.tetc"
    if not path.exists():
        src, kw, _ = SAMPLE_FILES[name]
        t0 = time.perf_counter()
        gatun_py.compress(src, path, dependencies=True, **kw)
        print(f"compressed {name} in {time.perf_counter() - t0:.1f} s", flush=True)
    return path


def transfer_functions(name, *, cutoff: bool = False):
    """(label, spec): the sample's preset and the same with every opacity x 0.3; with ``cutoff``
    also a third, fully transparent below the scalar's 75th percentile (see :func:`_cutoff`)."""
    out = [(name, name), (f"{name} x0.3", _transparent(name))]
    if cutoff:
        out.append((f"{name} 0 below p75", _cutoff(name)))
    return out


def _preset(name):
    from importlib.resources import files

    spec = json.loads(files("gatun_py.raycast.presets").joinpath(f"{name}.json").read_text())
    spec.pop("comment", None)
    return spec


def _cutoff(name):
    """The sample's preset with zero opacity below the 75th percentile of the scalar over the
    vertices (normalised to the file's range): 3/4 of the vertices fully transparent (the preset:
    29-39 %), Peng's case for a TF importance; the opacity ramps from 0 there to the preset's next
    point."""
    from gatun_py.codec import TetcReader

    reader = TetcReader(tetc_file(name))
    lo, hi = (float(x) for x in reader.meta["scalar_range"])
    s = np.concatenate([b.density for b in reader.iter_decode(0)])
    x0 = float((np.percentile(s, 75) - lo) / (hi - lo))
    spec = _preset(name)
    spec["opacity"] = [{"x": 0.0, "a": 0.0}, {"x": x0, "a": 0.0}] + [p for p in spec["opacity"] if p["x"] > x0]
    return spec


def _transparent(name):
    from importlib.resources import files

    spec = json.loads(files("gatun_py.raycast.presets").joinpath(f"{name}.json").read_text())
    spec.pop("comment", None)
    spec["opacity"] = [dict(p, a=p["a"] * 0.3) for p in spec["opacity"]]
    return spec


def rgb(res):
    from gatun_py.raycast.image import to_rgb8

    return to_rgb8(res.image, (0.0, 0.0, 0.0))


def quality(full, res):
    from gatun_py.pipeline.quality import compare_images

    d = compare_images(full, rgb(res))
    return d.rmse, d.psnr


class InMemoryRenderer:
    """Renders meshes in memory with the full mesh's camera, scalar range and step (those of
    ``reader``'s file), so cuts made outside the file's own pipeline compare with its renders."""

    def __init__(self, reader, view):
        from gatun_py.pipeline.stream import file_view

        self.view, self.camera, self.rng, self.step, _ = file_view(reader, view)

    def __call__(self, mesh):
        """(H, W, 3) uint8 on black."""
        from gatun_py.raycast.image import to_rgb8
        from gatun_py.raycast.caster import render_mesh

        res = render_mesh(mesh, self.camera, self.view.tf, mode=self.view.mode, step=self.step, scalar_range=self.rng)
        return to_rgb8(res.image, (0.0, 0.0, 0.0))


def sse(a, b) -> float:
    """Sum of squared differences of two 0-255 images."""
    d = a.astype(np.float64) - b.astype(np.float64)
    return float((d * d).sum())


def rmse(full, img) -> float:
    """RMSE as every table of this section quotes it (:func:`compare_images`)."""
    from gatun_py.pipeline.quality import compare_images

    return compare_images(full, img).rmse


def target_table(reader, name, rows, ablation):
    from gatun_py.pipeline.selective import FACTORS, render_selective
    from gatun_py.pipeline.stream import View, render_tetc
    from gatun_py.raycast.camera import Camera

    n = int(reader.meta["points"])
    for label, tf in transfer_functions(name):
        for az, el in (VIEWS[:1] if QUICK else VIEWS):
            view = View(Camera(SIZE, SIZE, az, el), tf=tf)
            full = rgb(render_tetc(reader, view))
            for ratio in RATIOS:
                u = render_selective(reader, view, merges=int(ratio * n), uniform=True)
                s = render_selective(reader, view, tets=u.stats["cut_tets"])
                ru, _ = quality(full, u)
                rs, _ = quality(full, s)
                rows.append([name, label, f"({az:g}, {el:g})", f"{ratio:.0%}", u.stats["cut_tets"], s.stats["cut_tets"],
                             ru, rs, rs / ru if ru else float("nan"), s.stats["flipped_tets"],
                             s.stats["selection_s"] * 1e3, s.stats["render_s"] + s.stats["decode_s"] + s.stats["filter_s"]])
                print(rows[-1], flush=True)
                if ratio == RATIOS[0] and (az, el) == VIEWS[0] and label == name:
                    abl = [name, rs]
                    for drop in FACTORS:
                        a = render_selective(reader, view, tets=u.stats["cut_tets"],
                                             factors=tuple(f for f in FACTORS if f != drop))
                        abl.append(quality(full, a)[0])
                    abl.append(ru)
                    ablation.append(abl)


def _cut_tets(tets, anc) -> int:
    """Tets of a cut's mesh (four distinct ancestors), for any cut."""
    a = np.sort(anc[tets], axis=1)
    return int(((a[:, 0] != a[:, 1]) & (a[:, 1] != a[:, 2]) & (a[:, 2] != a[:, 3])).sum())


def _unsafe_cut(src, order, goal):
    """The shortest prefix of ``order`` (no closure) whose mesh has at most ``goal`` tets."""
    from gatun_py.simplify.dependencies import cut_ancestors

    lo, hi = 0, order.size
    while lo < hi:
        mid = (lo + hi) // 2
        cut = np.zeros(order.size, bool)
        cut[order[:mid]] = True
        if _cut_tets(src.tets, cut_ancestors(src.parent, src.rank, cut)) <= goal:
            hi = mid
        else:
            lo = mid + 1
    cut = np.zeros(order.size, bool)
    cut[order[:lo]] = True
    return cut


def _render_cut(reader, view, src, cut):
    from gatun_py.pipeline.stream import render_tetc
    from gatun_py.simplify.dependencies import cut_ancestors
    from gatun_py.simplify.levels import Target

    n = src.points.shape[0]
    return render_tetc(reader, view, target=Target(0, int(cut.sum()), cut.sum() / n, 0),
                       ancestors=cut_ancestors(src.parent, src.rank, cut))


def _predictors(reader, view, src):
    """(importance as shipped, region error) for a view."""
    from gatun_py.pipeline.selective import _transfer_function, merge_importance, region_error
    from gatun_py.pipeline.stream import file_render_defaults

    lo, hi, rng, _ = file_render_defaults(reader)
    tf = _transfer_function(reader, view.tf, float(np.linalg.norm(hi - lo)))
    cam = view.camera.fit(lo, hi)
    return (merge_importance(src, cam, tf, lo=lo, hi=hi, scalar_range=rng),
            region_error(src, cam, tf, lo=lo, hi=hi, scalar_range=rng))


def diagnose(reader, name, rows):
    """Per cell of the target table: RMSE / uniform of the closed cut, the unsafe cut and the legal
    cuts (tets reached, selection time), all against the uniform cut with the same tets."""
    from gatun_py.pipeline import _importance_kernels as IK
    from gatun_py.pipeline.selective import render_selective, selective_source
    from gatun_py.pipeline.stream import View, render_tetc
    from gatun_py.raycast.camera import Camera
    from gatun_py.simplify.dependencies import legal_cut, legal_cut_base

    n = int(reader.meta["points"])
    base = None
    for label, tf in transfer_functions(name):
        for az, el in (VIEWS[:1] if QUICK else VIEWS):
            view = View(Camera(SIZE, SIZE, az, el), tf=tf)
            full = rgb(render_tetc(reader, view))
            src = selective_source(reader, view.scalar, view.component)
            if base is None:
                base = legal_cut_base(src.tets, src.points, src.parent, src.rank)
            imp, err = _predictors(reader, view, src)
            # the region error per removed tet, never before a child merge (children first)
            err_key = IK._subtree_max(err / np.maximum(src.deps.removed, 1), src.vertex, src.target, src.rank)
            for ratio in RATIOS:
                u = render_selective(reader, view, merges=int(ratio * n), uniform=True)
                goal = u.stats["cut_tets"]
                ru = quality(full, u)[0]
                rc = quality(full, render_selective(reader, view, tets=goal))[0]
                unsafe = _unsafe_cut(src, np.argsort(imp, kind="stable"), goal)
                rx = quality(full, _render_cut(reader, view, src, unsafe))[0]
                row = [name, label, f"({az:g}, {el:g})", f"{ratio:.0%}", goal, ru, rc / ru, rx / ru]
                for key in (imp, err_key):
                    t0 = time.perf_counter()
                    cut, tets, _ = legal_cut(base, np.argsort(key, kind="stable"), tets=goal)
                    sel = time.perf_counter() - t0
                    row += [quality(full, _render_cut(reader, view, src, cut))[0] / ru, tets, sel * 1e3]
                rows.append(row)
                print(rows[-1], flush=True)


NOISE = [0.001, 0.01, 0.05, 0.2]


def order_sensitivity(reader, name):
    """The uniform order (rank) with Gaussian noise of sigma = noise x k ranks, at 95 % merged, view
    (30, 20): RMSE / uniform of the closed, unsafe, legal and legal children-first cuts it gives."""
    from gatun_py.pipeline.selective import choose_cut, render_selective, selective_source
    from gatun_py.pipeline.stream import View, render_tetc
    from gatun_py.raycast.camera import Camera
    from gatun_py.simplify.dependencies import legal_cut, legal_cut_base

    view = View(Camera(SIZE, SIZE, *VIEWS[0]), tf=name)
    full = rgb(render_tetc(reader, view))
    src = selective_source(reader, view.scalar, view.component)
    base = legal_cut_base(src.tets, src.points, src.parent, src.rank)
    u = render_selective(reader, view, merges=int(RATIOS[0] * int(reader.meta["points"])), uniform=True)
    goal, ru = u.stats["cut_tets"], quality(full, u)[0]
    rng = np.random.default_rng(1)
    rows = []
    for noise in NOISE[:2] if QUICK else NOISE:
        key = np.arange(src.n_merges) + rng.normal(0.0, noise * src.n_merges, src.n_merges)
        order = np.argsort(key, kind="stable")
        row = [name, noise, quality(full, _render_cut(reader, view, src, choose_cut(src, key, tets=goal)))[0] / ru,
               quality(full, _render_cut(reader, view, src, _unsafe_cut(src, order, goal)))[0] / ru]
        for first in (False, True):
            cut, tets, rejected = legal_cut(base, order, tets=goal, children_first=first)
            row += [quality(full, _render_cut(reader, view, src, cut))[0] / ru, tets, rejected]
        rows.append(row)
        print(rows[-1], flush=True)
    return rows


def per_merge_correlation(reader, name, n_merges):
    """Spearman correlation between each predictor and the image change a merge makes in its
    prefix state (sum of squared 0-255 differences between the renders before and after it, 128²,
    view (30, 20)), over merges drawn from ranks 50-99 %."""
    from scipy.stats import spearmanr

    from gatun_py.pipeline.selective import render_selective, selective_source
    from gatun_py.pipeline.stream import View
    from gatun_py.raycast.camera import Camera

    view = View(Camera(128, 128, *VIEWS[0]), tf=name)
    src = selective_source(reader, view.scalar, view.component)
    imp, err = _predictors(reader, view, src)
    k = src.n_merges
    ranks = np.sort(np.random.default_rng(0).choice(np.arange(k // 2, int(0.99 * k)), n_merges, replace=False))
    measured = []
    for r in ranks:
        a = rgb(render_selective(reader, view, merges=int(r), uniform=True)).astype(np.float64)
        b = rgb(render_selective(reader, view, merges=int(r) + 1, uniform=True)).astype(np.float64)
        measured.append(float(((a - b) ** 2).sum()))
    measured = np.array(measured)
    preds = {"rank (uniform order)": np.arange(k) + 1.0, "importance (shipped)": imp, "region error": err}
    return [[name, n_merges, float(np.mean(measured == 0))] +
            [float(spearmanr(p[ranks], measured).statistic) for p in preds.values()]]


def psnr_curve(reader, name):
    """(tets, uniform PSNR, selective PSNR) over a geometric series of tet counts."""
    from gatun_py.pipeline.selective import render_selective
    from gatun_py.pipeline.stream import View, render_tetc
    from gatun_py.raycast.camera import Camera

    view = View(Camera(SIZE, SIZE, *VIEWS[0]), tf=name)
    full = rgb(render_tetc(reader, view))
    t0 = int(reader.meta["tets"])
    out = []
    for frac in (np.geomspace(0.005, 0.7, 5 if QUICK else 10)):
        u = render_selective(reader, view, tets=int(frac * t0), uniform=True)
        s = render_selective(reader, view, tets=int(frac * t0))
        out.append((u.stats["cut_tets"], quality(full, u)[1], s.stats["cut_tets"], quality(full, s)[1]))
        print(name, out[-1], flush=True)
    return out


def equal_quality(curve):
    """For each uniform point: the selective tets reaching its PSNR (interpolated), and the ratio."""
    st = np.array([c[2] for c in curve], float)
    sp = np.array([c[3] for c in curve], float)
    order = np.argsort(sp)
    rows = []
    for ut, up, _, _ in curve:
        if sp.min() <= up <= sp.max():
            need = float(np.interp(up, sp[order], st[order]))
            rows.append([ut, up, need, need / ut])
    return rows


def budget_runs(path, name):
    import gatun_py

    from gatun_py.pipeline.stream import View, render_tetc
    from gatun_py.raycast.camera import Camera

    f = gatun_py.open(path)
    full = rgb(render_tetc(f.reader, View(Camera(SIZE, SIZE, *VIEWS[0]), tf=name)))
    rows = []
    for b in (BUDGETS[:2] if QUICK else BUDGETS):
        row = [name, b]
        for sel in (False, True):
            g = gatun_py.open(path)  # a fresh reader: one frame of a one-shot command
            t0 = time.perf_counter()
            fr = gatun_py.render(g, size=SIZE, tf=name, azimuth=VIEWS[0][0], elevation=VIEWS[0][1], budget=b,
                                 selective=sel)
            wall = time.perf_counter() - t0
            from gatun_py.pipeline.quality import compare_images

            d = compare_images(full, fr.rgb)
            row += [fr.stats["tets_rendered"], wall, d.psnr]
        row.append(row[7] - row[4])
        rows.append(row)
        print(rows[-1], flush=True)
    return rows


def plot(curves):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, c in curves.items():
        ax.semilogx([x[0] for x in c], [x[1] for x in c], "o-", label=f"{name} uniform")
        ax.semilogx([x[2] for x in c], [x[3] for x in c], "s--", label=f"{name} selective")
    ax.set_xlabel("tets rendered")
    ax.set_ylabel("PSNR vs full resolution (dB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out = FIGURES / "selective_psnr.png"
    fig.savefig(out, dpi=110)
    return out


# Measured by hand (not by this script), 2026-11-24, load average ~8 on the 2-core machine.
NOTES = """Selection cost per frame, views cycling (3 views x 95/99 % x 4), TF fixed, the first frame of
each TF left out (it builds the TF's colour and extinction grid once), median over 24 frames,
`plan_cut`'s `select_s`, commit 401eb9d against the base be6ee92 in alternating runs (twice each,
load average 8-10): Blunt-fin 7.7-8.0 / 7.7-9.8 ms (TF / TF x0.3) against 24-38 / 24-36 ms;
Combustion 10.7-11.3 / 10.2-10.8 ms against 40-41 / 40-41 ms (3.1-4.7x less). What is left: the
stable sort of the effective importance (about half), the importance's own kernels.

A forest built in rounds of independent merges (decimator option tried in commit 139dcb4 and
reverted: a merge waits for the next round when it would touch the star of an earlier merge of
the round; default forest bit-identical): the merge at rank 95 % still depends, transitively, on
94 / 86 / 89 % of the earlier merges on post / fire / Combustion, against 97 / 87 / 80 % for the
greedy forest. Rounds do not free the closed cut.

Closed cuts in the middle ranks, where the closure leaves freedom (view (30, 20), the sample's TF,
PSNR against full resolution at 2 / 5 / 15 / 40 % of the tets), by the order they follow: rank
(uniform) 50.6 / 55.6 / 63.3 / 75.8 dB on Blunt-fin and 36.8 / 43.4 / 52.6 / 62.6 on Combustion;
the shipped importance 50.6 / 55.1 / 59.4 / 67.6 and 36.1 / 43.0 / 53.2 / 62.8; the region error
per removed tet 49.7 / 55.4 / 59.4 / 65.5 and 35.6 / 42.6 / 51.8 / 59.8. The forest order wins
where there is freedom too."""


BOUND = """## The bound: no importance and no brick choice reaches 0.5x with these forests

Measured by `bench/bench_selective_bound.py` ([selective_bound.md](selective_bound.md)) and
`bench/bench_selective_bricks.py` ([selective_bricks.md](selective_bricks.md)), 256², in memory,
RMSE / the uniform cut's RMSE at equal tets (the unbricked forest's first N merges). The first
three rows: 18 cells per column, 2 samples x 3 views x 3 TFs (the sample's; its opacities x 0.3;
the sample's with zero opacity below the scalar's 75th percentile, 3/4 of the vertices fully
transparent against 29-39 % for the preset); the bricked rows: per K (and goal), each the median
over views and TFs. Median (range).

| cut | chosen by | 95 % merged | 99 % merged | flip-free |
|---|---|---|---|---|
| closed (shipped) | importance: colour x light x size x forest | 1.068 (0.92-1.18) | 1.054 (1.00-1.41) | yes |
| closed | *oracle*: the measured image error per tet of each 4^3-grid region's merges, best of 16 orders per cell | 0.983 (0.88-1.19) | 0.992 (0.95-2.73) | yes |
| no closure | the oracle's order | 16.8 (1.1-39) | 4.95 (2.9-18) | no: 61-1,349 inverted tets |
| bricked, K = 8 / 27 / 64, a prefix per brick | anything | unreachable: fewest tets 2.2-9.9x the goal | unreachable | yes |
| bricked, a prefix per brick, at 12-45 % of the tets (reachable) | oracle allocation over measured per-brick error curves | 1.67 (1.25-9.3) at those tets | | yes |
| bricks, then tiers with the shared cuts unlocked (each tier handing over at 90 % of its merges) | nothing left to choose: a prefix of the top tier's forest | 1.34 (0.99-1.82) over K = 8 / 27 / 64 | 1.01 (0.80-1.41) | yes |

What this says: (1) knowing the image error of every region by measurement moves a closed cut by
at most 12 % of uniform's RMSE at 95-99 % merged: the closure of a late merge holds 80-97 % of the
earlier ones, and the forest's order is already close to the best one; (2) freedom from the closure costs
overlaps and is worse, 1.1-39x; (3) bricks are free but cannot go below their locked cut vertices
(9.5-34 % of the points, against 1-5 % left at 99-95 % merged), and where they reach, the locks
cost 1.2-30x uniform's RMSE before any choice (median 2.6x) and the best per-brick choice wins back
less than that; (4) tiers restore the reach but leave the cut forced exactly where the targets are.
The 0.5x and 1/4 targets were set against Okuyan's uniform baseline, far weaker than this forest's
(see the note above the ablation): with this forest they are out of reach for any importance.
The one gain seen is a forest effect, not a selective one: the top tier's forest (a second
decimation of a 13-25 % mesh) is 0.80-0.95x uniform at 99 % on Combustion (the same cut for every
view), and 0.99-1.82x at 95 % and on Blunt-fin."""


def main():
    from gatun_py.codec import TetcReader

    rows, ablation, curves, budgets, sizes, diag, corr, noise = [], [], {}, [], [], [], [], []
    for name in DATASETS:
        path = tetc_file(name)
        reader = TetcReader(path)
        deps = reader.container.section_size("deps")
        sizes.append([name, reader.meta["tets"], reader.meta["dependencies"]["entries"],
                      reader.meta["dependencies"]["entries"] / reader.meta["dependencies"]["merges"],
                      deps, path.stat().st_size, 100.0 * deps / path.stat().st_size, 8.0 * deps / reader.meta["tets"]])
        target_table(reader, name, rows, ablation)
        diagnose(reader, name, diag)
        noise += order_sensitivity(reader, name)
        corr += per_merge_correlation(reader, name, 50 if QUICK else 200)
        curves[name] = psnr_curve(reader, name)
        budgets += budget_runs(path, name)
    fig = plot(curves)
    ratios = [r[8] for r in rows]
    sel_share = [r[10] / 1e3 / r[11] for r in rows]
    text = f"""# Selective refinement

Code: {code_state()}. {SIZE}², volume mode, in-process, warm JIT. Uniform = the first N merges;
selective = the closed cut of the least important merges with the same number of tets (or fewer).
RMSE on 0-255 against the full-resolution render of the same view and transfer function.

## Target: RMSE selective / uniform <= 0.5 at equal tets

{table(["data", "TF", "view (az, el)", "merged", "uniform tets", "selective tets", "RMSE uniform", "RMSE selective",
        "selective / uniform", "flipped", "selection ms", "frame s"], rows)}

Median selective / uniform RMSE: **{np.median(ratios):.3f}** (target <= 0.5; best {min(ratios):.3f}, worst
{max(ratios):.3f}). Flipped tets over all cuts: {sum(r[9] for r in rows)}. Selection cost: median
{100 * np.median(sel_share):.1f} % of the frame (target <= 5 %).

{BOUND}

## What limits the selective cut

Same cells, RMSE / uniform RMSE at equal tets. *closed*: the shipped cut (importance, dependency
closure). *unsafe*: the same importance order with no closure (overlapping tets allowed), the
shortest prefix of it with at most the uniform cut's tets. *legal*: the same order with the
run-time legality check instead of the closure (each merge applied only if the decimator's tests
pass on the cut mesh as it is: an edge of it, the link condition, positive volumes, boundary
normals; only onto its own parent), and *legal (region)*: the legal cut ordered by the region error
per removed tet, children first. A legal cut stops when no legal merge is left: its tets can stay
above the goal.

{table(["data", "TF", "view", "merged", "tets", "RMSE uniform", "closed / uniform", "unsafe / uniform",
        "legal / uniform", "legal tets", "legal ms", "legal (region) / uniform", "legal (region) tets",
        "legal (region) ms"], diag)}

Medians: closed {np.median([r[6] for r in diag]):.3f}, unsafe {np.median([r[7] for r in diag]):.3f},
legal {np.median([r[8] for r in diag]):.3f} (reaching the goal in {sum(r[9] <= r[4] for r in diag)} of
{len(diag)} cells), legal (region) {np.median([r[11] for r in diag]):.3f} ({sum(r[12] <= r[4] for r in diag)}
of {len(diag)}).

How much the order matters: the uniform order with a little noise (Gaussian, sigma = the share of
the k merges given, in ranks), 95 % merged, view (30, 20), the sample's TF; RMSE / uniform.

{table(["data", "noise (x k ranks)", "closed", "unsafe", "legal", "legal tets", "legal rejected (first pass)",
        "legal children-first", "tets", "rejected (first pass)"], noise)}

Per-merge image change in the merge's prefix state against its predictors (Spearman):

{table(["data", "merges", "share with no change", "rank (uniform order)", "importance (shipped)",
        "region error"], corr)}

{NOTES}

## Importance ablation (RMSE at 95 %, view (30, 20), each factor left out)

{table(["data", "all factors", "no colour", "no light", "no size", "no forest", "uniform"], ablation)}

## PSNR over tets (view (30, 20), the sample's TF)

{"![PSNR over tets](../figures/selective_psnr.png)" if fig else "(matplotlib not installed: no figure)"}

""" + "\n\n".join(f"""### {name}

{table(["uniform tets", "uniform PSNR", "selective tets", "selective PSNR"], c)}

Equal quality:

{table(["uniform tets", "PSNR", "selective tets for that PSNR", "selective / uniform"], equal_quality(c))
                if equal_quality(c) else "no overlap of the PSNR ranges"}""" for name, c in curves.items()) + f"""

## Time budget (view (30, 20), the sample's TF; a fresh reader per frame, as one `tetc render` command)

{table(["data", "budget s", "uniform tets", "uniform s", "uniform PSNR", "selective tets", "selective s",
        "selective PSNR", "PSNR gain dB"], budgets)}

## Size of the `deps` section

{table(["data", "tets", "dependencies", "per merge", "deps bytes", "file bytes", "% of file", "bits/tet"], sizes)}
"""
    write_section("selective", text)


if __name__ == "__main__":
    main()
