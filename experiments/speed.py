"""Speed of sorjax on the paper's Table 1, against a plain numpy/scipy baseline.

Four measurements, printed as a table:

1. The whole ``configs/table1.toml`` (or ``--trials`` per cell) through
   ``sorjax.experiment.run_trials`` with one worker per CPU core (``--workers``), wall
   time including JAX's compilation (a fresh compilation cache is used unless
   ``--warm-cache``).
2. One warm Table 1 trial (every method) in one process, at sigma = 2 px: the cost per
   trial once compiled; the table's wall time less trials x this is compilation,
   tracing and what the workers lose to each other.
3. One warm 3-view bundle calibration (two-sphere scene, f = 700 px, sigma = 1 px,
   homologies given): median over repeated calls of ``calibrate(method="bundle")``.
4. A baseline written the way a researcher would without sorjax: numpy +
   ``scipy.optimize.least_squares`` on the same residuals (eq. 20: distance from the
   transferred samples to the outline polyline, nearest vertex by a k-d tree then the
   two adjacent segments), per-view fits from the same automatic starting candidates,
   Method IIb by SVD, then the unit-aspect bundle seeded by it; a Python loop over
   trials.  sorjax runs the same trials with the same methods (IIb, bundle-unit) in
   the same process and the ratio of the two per-trial times is printed.

    python experiments/speed.py                     # full Table 1 (1400 calibrations)
    python experiments/speed.py --trials 10         # 10 trials per cell
    python experiments/speed.py --workers 1         # the table in one worker process
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np


def _table1_config(trials: int | None = None):
    from sorjax.experiment import load_config

    cfg = load_config(os.path.join(os.path.dirname(__file__), "..", "configs", "table1.toml"))
    return cfg if trials is None else cfg.replace(trials=trials)


def run_table1(trials: int | None, warm_cache: bool, workers: int) -> tuple[float, int]:
    if not warm_cache:
        os.environ["SORJAX_CACHE"] = tempfile.mkdtemp(prefix="sorjax-xla-")
    from sorjax.experiment import run_trials

    t0 = time.perf_counter()
    recs = run_trials(_table1_config(trials), workers=workers, progress=True)
    return time.perf_counter() - t0, len(recs)


def steady_trial(n: int = 20) -> dict[str, float]:
    """Warm time of one Table 1 trial (every method) in this process, ms, for the cells
    sigma = 2 px at f = 700 and 1400: the cost per trial once everything is compiled
    (the rest of the table's wall time is compilation and tracing, per worker)."""
    from sorjax.experiment._trials import run_trial

    cfg = _table1_config()
    out = {}
    for r, row in enumerate(cfg.rows()):
        if row["sigma"] != 2.0:
            continue
        ts = []
        for t in range(2 * n):  # the first half warms up; median: a rare path's compilation is no trial's cost
            t0 = time.perf_counter()
            run_trial(cfg, r, row, t)
            ts.append(time.perf_counter() - t0)
        out[f"f = {row['f']:g}"] = 1000 * statistics.median(ts[n:])
    return out


def warm_bundle(repeats: int = 30) -> tuple[float, float]:
    """Median time of one warm ``calibrate(method="bundle")`` on 3 views with their
    homologies given: from raw (N, 2) arrays (validated and resampled on every call)
    and from :class:`sorjax.Outline` objects validated once (as the experiment runner
    passes them: every method of a trial reuses them)."""
    import sorjax
    from sorjax import scenes
    from sorjax._outline import as_outlines

    sc = scenes.two_spheres(700.0)
    raw = [scenes.paper_noise(o, 1.0, np.random.default_rng([0, i])) for i, o in enumerate(sc.outlines)]
    hs = tuple(sorjax.fit_homology(o) for o in raw)
    out = []
    for outs in (raw, as_outlines(raw)):
        sorjax.calibrate(outs, homologies=hs, outline_error=0.0)
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            cal = sorjax.calibrate(outs, homologies=hs, outline_error=0.0)
            np.asarray(cal.K)
            ts.append(time.perf_counter() - t0)
        out.append(statistics.median(ts))
    return out[0], out[1]


# ------------------------------------------------------------------- the baseline


def _baseline_distance(tree, poly, y):
    """Unsigned distance from points y to the closed polyline (nearest vertex, then
    its two segments)."""
    _, k = tree.query(y)
    n = len(poly)
    best = np.full(len(y), np.inf)
    for a, b in ((k - 1) % n, k), (k, (k + 1) % n):
        p, q = poly[a], poly[b]
        d = q - p
        t = np.clip(np.sum((y - p) * d, 1) / np.maximum(np.sum(d * d, 1), 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(y - p - t[:, None] * d, axis=1))
    return best


def _W(v, l):
    return np.eye(3) - 2.0 * np.outer(v, l) / (v @ l)


def _transfer(W, x):
    xh = np.c_[x, np.ones(len(x))] @ W.T
    return xh[:, :2] / xh[:, 2:3]


def _sph(a, b):
    return np.array([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)])


def baseline_trial(outs, starts, n_samples=100):
    """Per-view fits, IIb and the unit-aspect bundle with scipy; returns (fu, fv, u0, v0)."""
    from scipy.optimize import least_squares
    from scipy.spatial import cKDTree

    allp = np.concatenate(outs)
    c, s = allp.mean(0), np.sqrt(np.mean(np.sum((allp - allp.mean(0)) ** 2, 1)) / 2)
    polys = [(o - c) / s for o in outs]
    trees = [cKDTree(p) for p in polys]
    samples = []
    for p in polys:
        seg = np.linalg.norm(np.roll(p, -1, 0) - p, axis=1)
        arc = np.r_[0, np.cumsum(seg)]
        t = np.linspace(0, arc[-1], n_samples, endpoint=False)
        pc = np.vstack([p, p[:1]])
        samples.append(np.c_[np.interp(t, arc, pc[:, 0]), np.interp(t, arc, pc[:, 1])])
    T = np.array([[1 / s, 0, -c[0] / s], [0, 1 / s, -c[1] / s], [0, 0, 1.0]])

    vs, ls = [], []
    for j in range(len(polys)):
        best = None
        for v0, l0 in starts[j]:
            v0 = T @ v0
            l0 = np.linalg.solve(T.T, l0)
            v0 = v0 / np.linalg.norm(v0)
            l0 = l0 / np.linalg.norm(l0[:2])
            x0 = np.array([np.arctan2(v0[1], v0[0]), np.arcsin(np.clip(v0[2], -1, 1)),
                           np.arctan2(l0[1], l0[0]), -l0[2]])

            def res(x, j=j):
                v = _sph(x[0], x[1])
                l = np.array([np.cos(x[2]), np.sin(x[2]), -x[3]])
                return _baseline_distance(trees[j], polys[j], _transfer(_W(v, l), samples[j]))

            sol = least_squares(res, x0, method="lm", xtol=1e-10, ftol=1e-10, max_nfev=400)
            if best is None or sol.cost < best.cost:
                best = sol
        x = best.x
        vs.append(_sph(x[0], x[1]))
        ls.append(np.array([np.cos(x[2]), np.sin(x[2]), -x[3]]))

    # Method IIb (unit aspect, zero skew): omega = [[w1, 0, w2], [0, w1, w3], [w2, w3, w4]]
    rows = []
    for v, l in zip(vs, ls):
        Bv = np.array([[v[0], v[2], 0, 0], [v[1], 0, v[2], 0], [0, v[0], v[1], v[2]]])
        P = np.cross(l, np.eye(3))  # l x (omega v) = 0: two independent rows
        rows.extend(P[:2] @ Bv)
    w = np.linalg.svd(np.array(rows))[2][-1]
    w = w / w[0]
    u0, v0 = -w[1], -w[2]
    f2 = w[3] - u0**2 - v0**2
    if not f2 > 0:
        return None
    f = np.sqrt(f2)

    def bres(y):
        f, u0, v0 = np.exp(y[0]), y[1], y[2]
        Ki = np.linalg.inv(np.array([[f, 0, u0], [0, f, v0], [0, 0, 1.0]]))
        om = Ki.T @ Ki
        out = []
        for j in range(len(polys)):
            v = _sph(y[3 + 2 * j], y[4 + 2 * j])
            out.append(_baseline_distance(trees[j], polys[j], _transfer(_W(v, om @ v), samples[j])))
        return np.concatenate(out)

    y0 = [np.log(f), u0, v0]
    for v in vs:
        y0 += [np.arctan2(v[1], v[0]), np.arcsin(np.clip(v[2], -1, 1))]
    sol = least_squares(bres, np.array(y0), method="lm", xtol=1e-10, ftol=1e-10, max_nfev=2000)
    f, u0, v0 = np.exp(sol.x[0]), sol.x[1], sol.x[2]
    K = np.linalg.inv(T) @ np.array([[f, 0, u0], [0, f, v0], [0, 0, 1.0]])
    return K[0, 0], K[1, 1], K[0, 2], K[1, 2]


def compare_baseline(n: int):
    import sorjax
    from sorjax import scenes
    from sorjax._camera import normalising_transform
    from sorjax.core import prepare_views
    from sorjax.core._viewfit import automatic_starts
    from sorjax._outline import make_outline
    import jax.numpy as jnp

    sc = scenes.two_spheres(700.0)
    trials = [[scenes.paper_noise(o, 1.0, np.random.default_rng([1, t, i])) for i, o in enumerate(sc.outlines)]
              for t in range(n)]

    def starts_of(o):  # the same automatic candidates as sorjax's, in pixels (not timed)
        pts = np.asarray(make_outline(o).points)
        T = normalising_transform(pts)
        views = prepare_views(jnp.asarray(pts)[None], 100)
        vs, ls, valid = (np.asarray(a) for a in automatic_starts(views.points[0], views.samples[0]))
        cands = list(zip(vs[valid], ls[valid]))
        return [(np.linalg.solve(T, v), T.T @ l) for v, l in cands]

    starts = [[starts_of(o) for o in outs] for outs in trials]
    # sorjax: fits + IIb + unit-aspect bundle, warm: every trial once untimed, so that
    # the solver paths some trials need (a fallback, the stationarity test) are
    # compiled before timing, as they are after the first few trials of an experiment
    for outs in trials:
        hs = tuple(sorjax.fit_homology(o) for o in outs)
        sorjax.calibrate(outs, "IIb", homologies=hs, outline_error=0.0)
        sorjax.calibrate(outs, aspect_ratio=1.0, homologies=hs, outline_error=0.0)
    t0 = time.perf_counter()
    sj = []
    for outs in trials:
        hs = tuple(sorjax.fit_homology(o) for o in outs)
        sorjax.calibrate(outs, "IIb", homologies=hs, outline_error=0.0)
        sj.append(sorjax.calibrate(outs, aspect_ratio=1.0, homologies=hs, outline_error=0.0).fu)
    t_sorjax = (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    bl = [baseline_trial(outs, st) for outs, st in zip(trials, starts)]
    t_base = (time.perf_counter() - t0) / n
    e_s = np.array(sj) / 700 * 100 - 100
    e_b = np.array([np.nan if b is None else b[0] for b in bl]) / 700 * 100 - 100
    return t_sorjax, t_base, e_s, e_b


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trials", type=int, default=None, help="trials per Table 1 cell (default: the config's 100)")
    p.add_argument("--baseline-trials", type=int, default=10)
    p.add_argument("--warm-cache", action="store_true", help="reuse the on-disk compilation cache")
    p.add_argument("--skip-table", action="store_true")
    p.add_argument("--workers", type=int, default=0, help="worker processes for the table (0: one per core)")
    a = p.parse_args(argv)
    lines = []
    if not a.skip_table:
        wall, n = run_table1(a.trials, a.warm_cache, a.workers)
        w = a.workers or os.cpu_count()
        lines.append(f"Table 1, {n} trials (I, IIa, IIb, bundle, bundle-unit), {os.cpu_count()} cores, {w} workers: "
                     f"{wall:.1f} s wall incl. compilation ({1000 * wall / n:.0f} ms per trial); target 30 s")
    steady = steady_trial()
    lines.append("one warm Table 1 trial (every method, one process, sigma 2 px, median): "
                 + ", ".join(f"{k}: {v:.0f} ms" for k, v in steady.items()))
    t_raw, t_val = warm_bundle()
    lines.append(f"one warm 3-view bundle calibration (homologies given): {1000 * t_val:.1f} ms from validated "
                 f"Outlines, {1000 * t_raw:.1f} ms from raw arrays (validated every call); target 10 ms")
    ts, tb, es, eb = compare_baseline(a.baseline_trials)
    lines.append(f"{a.baseline_trials} trials, fits + IIb + unit-aspect bundle: sorjax {1000 * ts:.0f} ms/trial, "
                 f"numpy/scipy baseline {1000 * tb:.0f} ms/trial: sorjax {tb / ts:.2f}x faster")
    lines.append(f"  focal error RMS (%): sorjax {np.sqrt(np.nanmean(es**2)):.2f}, baseline {np.sqrt(np.nanmean(eb**2)):.2f}"
                 f" ({int(np.isnan(eb).sum())} baseline failures)")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
