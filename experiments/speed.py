"""Speed of sorjax's compiled trial program on the paper's Table 1 (issue 16), against
a plain numpy/scipy baseline and against the arithmetic its solvers cannot avoid.

One run prints, on this machine:

1. **The table.**  ``configs/table1.toml`` (1400 trials, methods I, IIa, IIb, bundle,
   bundle-unit; ``--trials N`` per cell to shorten) through the experiment runner's
   own pieces (:func:`sorjax.experiment._trials.run_batch` with a
   :class:`~sorjax.experiment._trials.TrialProgram`), in this process, with a fresh
   compilation cache (a temporary ``SORJAX_CACHE``; ``--warm-cache`` keeps the
   user's).  The program's two stages (the per-view fits, the methods) are traced
   (``jit.lower``) one after the other and compiled (``.compile()``) side by side on
   the first chunk, so the wall time splits into trace, compile, the chunks' compute
   and the host's share (drawing the noisy outlines, the records).
   The warm cost of a trial is a chunk's compute time over its trials (the median
   over the chunks; with fewer than 3 chunks the first chunk is run again): wall
   time, with the chunk split over the CPU cores (:class:`sorjax.core.TrialSharder`'s
   host threads), while the floor below is one core's.
2. **The baseline.**  A plain numpy + ``scipy.optimize.least_squares`` implementation
   of the same estimators (eq. 20: distance from the transferred samples to the
   outline polyline, nearest vertex by a k-d tree then its two segments; per-view
   fits from the same automatic starts; Method IIb by SVD; the unit-aspect bundle
   seeded by it; a Python loop over trials) on ``--baseline-trials`` trials of the
   same table, and the ratio of its time per trial to sorjax's warm time per trial.
   sorjax's trial holds five calibrations (I, IIa, IIb, bundle, bundle-unit, with
   covariances and verdicts) and the baseline's two (IIb, bundle-unit), so the ratio
   per trial (the target's measure here) understates sorjax's advantage per
   calibration; both are printed.
3. **The arithmetic floor.**  The solver steps each trial took, read from the
   program's outputs (``ViewHomologies.steps`` per view: its start's screening, the
   polish, the robust refits; ``CoreResult.steps`` per bundle: every seed's solves),
   plus the screening steps of the starts that lost (``options.screen_steps`` for
   every other valid automatic start), each priced at one residual + Jacobian
   evaluation in the solvers' form (closest points searched near a hint), timed
   alone: a jitted ``jax.jacfwd`` of the per-view residuals
   (:func:`sorjax.core._viewfit._residuals`) and of the bundle's
   (:func:`sorjax.core._model.residuals` on :func:`sorjax.core._model.make_problem`), each in
   a ``lax.map`` of ``--floor-calls`` calls so that dispatch is amortised.  The floor
   leaves out the linear algebra of each step, the seed ranking, the covariances and
   the no-perspective evidence solve: it is a lower bound.
4. **The README's main job.**  ``sorjax experiment configs/table1-quick.toml`` in a
   subprocess with a fresh cache: wall time, start to exit.
5. **Devices.**  The backend and device count of this process; with ``--devices N``
   (N > 1) the table again in a subprocess with the trials split over N CPU devices
   (``XLA_FLAGS=--xla_force_host_platform_device_count=N``: the trials vmapped and
   sharded, :class:`sorjax.core.TrialSharder`), fresh cache, to compare with one
   device's compiled loop.

With ``--components`` the trial program's parts (the per-view fits, the methods, one
bundle, its seed loop, covariance and no-perspective fit, the model checks' view
scores) are traced and compiled alone: the size of each one's StableHLO and its compile
time, where a cut of the compilation pays (the parts overlap).

A table of every measure with its target and a pass/miss mark closes the output.

With ``--calibrate-program`` only the program of one ``sorjax.calibrate`` call is
measured (then the script exits): ``random_sor_scene(SEED, VIEWS)`` (``--program-seed``,
``--program-views``; default 0 and 4), the bundle's compiled core
(``sorjax._calibration._core``, the arguments ``calibrate`` passes it) traced and lowered,
its size as StableHLO operations with every called function inlined, its XLA compile
time (at the optimisation level ``XLA_FLAGS`` sets, the default if none), a user's first
``calibrate`` with a fresh cache (wall, the per-view fits' program included) and the
warm run time (median of 8 calls).

    python experiments/speed.py                       # full Table 1 (1400 trials)
    python experiments/speed.py --trials 2            # 2 trials per cell (28), a smoke run
    python experiments/speed.py --trials 10 --devices 2
    python experiments/speed.py --trials 1 --skip-quick --components
    python experiments/speed.py --calibrate-program
    python experiments/speed.py --first-k             # time to the first K, fresh processes
    XLA_FLAGS=--xla_backend_optimization_level=0 python experiments/speed.py --calibrate-program  # the tests' level
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
JSON_TAG = "SPEED-JSON "

TARGET_TABLE_S = 30.0  # issue 5
TARGET_RATIO = 8.0  # issue 16: sorjax at least 8x faster than the baseline
TARGET_FLOOR_RATIO = 2.0  # issue 16: warm within 2x of the arithmetic floor
TARGET_TRIAL_MS = 10.0  # issue 16: at most 10 ms a trial
TARGET_QUICK_S = 20.0  # issue 16: the README's table1-quick


def _table1_config(trials: int | None = None):
    from sorjax.experiment import load_config

    cfg = load_config(os.path.join(ROOT, "configs", "table1.toml"))
    return cfg if trials is None else cfg.replace(trials=trials)


def _fresh_cache() -> str:
    return tempfile.mkdtemp(prefix="sorjax-xla-")


# ------------------------------------------------------------------ 1. the table


class _TimedProgram:
    """Stands in for a :class:`TrialProgram` in ``run_batch``: traces and compiles the
    program explicitly on the first chunk (timed apart), then runs every chunk through
    that executable, timing each and keeping what the floor needs (the solver steps,
    the outline points, one trial's fits and bundle)."""

    def __init__(self, program):
        self.program = program
        self.compiled = None
        self.lower_s = self.compile_s = 0.0
        self.chunks: list[tuple[int, float]] = []  # (trials computed, seconds)
        self.points: list[np.ndarray] = []  # per real trial (V, M, 2)
        self.view_steps: list[np.ndarray] = []  # per real trial (V,)
        self.bundle_steps: list[np.ndarray] = []  # per real trial (number of bundle methods,)
        self.example = None  # (points, homs, K of the bundle) of the first trial

    def run(self, pts):
        import jax

        n, parts = self.program.split(pts)  # the parts run side by side (host threads) on one CPU device
        if self.compiled is None:
            self.compiled = self.program.executables(parts[0])  # both stages traced, then compiled together
            self.lower_s, self.compile_s = self.program.lower_s, self.program.compile_s
        t0 = time.perf_counter()
        out = self.program.run_parts(parts)
        jax.block_until_ready(out)
        dt = time.perf_counter() - t0
        return self.program.fits.trimmed(out, n), dt

    def __call__(self, pts):
        import jax

        pts = np.asarray(pts)
        out, dt = self.run(pts)
        self.chunks.append((len(pts), dt))
        homs, results = out
        # run_batch pads the last chunk by repeating its last trial: leave the copies out
        real = len(pts)
        while real > 1 and np.array_equal(pts[real - 1], pts[real - 2]):
            real -= 1
        hs = np.asarray(homs.steps)[:real]
        bs = [np.asarray(r.steps)[:real] for m, r in results.items() if m.startswith("bundle")]
        for b in range(real):
            self.points.append(pts[b])
            self.view_steps.append(hs[b])
            self.bundle_steps.append(np.array([x[b] for x in bs]))
        if self.example is None:
            m = "bundle" if "bundle" in results else next(iter(results))
            self.example = (pts[0], jax.tree.map(lambda x: np.asarray(x[0]), homs), np.asarray(results[m].K[0]))
        return out


def measure_table(trials: int | None, chunk: int) -> tuple[dict, _TimedProgram, list]:
    """The table through the runner's pieces, timed; returns (numbers, program, records)."""
    t_import = time.perf_counter()
    import jax

    from sorjax.experiment._runner import _tasks, enable_compilation_cache
    from sorjax.experiment._trials import TrialProgram, run_batch

    import_s = time.perf_counter() - t_import
    enable_compilation_cache()
    cfg = _table1_config(trials)
    t0 = time.perf_counter()
    timed = _TimedProgram(TrialProgram(cfg))
    tasks = _tasks(cfg)
    records = run_batch(cfg, tasks, program=timed, chunk=chunk)
    wall = time.perf_counter() - t0
    compute = sum(s for _, s in timed.chunks)
    per = [s / k for k, s in timed.chunks]
    if len(per) < 3:  # too few chunks for a median: run the first again (warm)
        first = np.stack(timed.points[: timed.chunks[0][0]])
        first = np.concatenate([first, np.repeat(first[-1:], timed.chunks[0][0] - len(first), 0)])
        for _ in range(2):
            _, dt = timed.run(first)
            per.append(dt / len(first))
    warm = statistics.median(per)  # the first chunk too: compiled before it ran
    nums = dict(
        trials=len(records), methods=list(cfg.methods), devices=len(jax.devices()), backend=jax.default_backend(),
        chunk=timed.chunks[0][0], n_chunks=len(timed.chunks), wall_s=wall, import_s=import_s,
        lower_s=timed.lower_s, compile_s=timed.compile_s, compute_s=compute,
        host_s=wall - compute - timed.lower_s - timed.compile_s, warm_trial_s=warm,
        first_chunk_trial_s=per[0], failures={m: sum(not r["methods"][m]["success"] for r in records if "methods" in r
                                                     and m in r["methods"]) for m in cfg.methods},
    )
    return nums, timed, records


def table_in_subprocess(trials: int | None, chunk: int, devices: int, warm_cache: bool, timeout: float) -> dict:
    """:func:`measure_table` in a fresh process with ``devices`` CPU devices."""
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={devices}").strip()
    if not warm_cache:
        env["SORJAX_CACHE"] = _fresh_cache()
    cmd = [sys.executable, os.path.abspath(__file__), "--table-json", "--chunk", str(chunk)]
    if warm_cache:
        cmd.append("--warm-cache")
    if trials is not None:
        cmd += ["--trials", str(trials)]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return dict(error=f"timed out after {timeout:.0f} s")
    for line in p.stdout.splitlines():
        if line.startswith(JSON_TAG):
            out = json.loads(line[len(JSON_TAG):])
            out["process_s"] = time.perf_counter() - t0
            return out
    return dict(error=f"exit {p.returncode}: {p.stderr.strip().splitlines()[-1:] or ''}")


# ------------------------------------------------------------- 3. the floor


def _time_map(fn, xs, args, repeats: int = 3) -> float:
    """Seconds per call of ``fn(x, args)`` for ``x`` in ``xs`` (leading axis), run as
    one jitted ``lax.map`` (compiled and run once first): the best of ``repeats``."""
    import jax

    f = jax.jit(lambda xs, args: jax.lax.map(lambda x: fn(x, args), xs))
    jax.block_until_ready(f(xs, args))
    n = jax.tree.leaves(xs)[0].shape[0]
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(xs, args))
        best = min(best, time.perf_counter() - t0)
    return best / n


def _value_and_jacfwd(f):
    """``x -> (f(x), J(x))`` by forward mode, the primal computed once."""
    import jax

    def vj(x, args):
        J, r = jax.jacfwd(lambda z: (f(z, args), f(z, args)), has_aux=True)(x)
        return r, J

    return vj


def residual_jacobian_times(points, homs, K, n_samples: int, calls: int) -> tuple[float, float]:
    """Seconds of one residual + Jacobian evaluation in the solvers' form (closest
    points searched near a hint): one view's eq. 20 (4 parameters), and the bundle's
    (V views, 2V + 4 parameters), on one trial's outlines near its fitted solution."""
    import jax
    import jax.numpy as jnp

    from sorjax.core import _bundle, _model
    from sorjax.core._camera import transform_points
    from sorjax._homology import symmetry_feet
    from sorjax.core import joint_transform, prepare_views
    from sorjax.core._viewfit import _pack, _residuals, _unpack

    rng = np.random.default_rng(0)
    points = jnp.asarray(points, jnp.float64)
    views = prepare_views(points, n_samples)

    # one view, in its own normalised coordinates, at its fit
    T = views.T[0]
    p, v0, E = _pack(T @ homs.v_x[0], jnp.linalg.solve(T.T, homs.l_s[0]))
    field = jax.tree.map(lambda x: x[0], views.fields)
    samples, weights = views.samples[0], views.weights[0]
    hints = symmetry_feet(*_unpack(p, v0, E), samples, field)
    ps = p + 1e-6 * jnp.asarray(rng.standard_normal((calls, 4)))
    t_view = _time_map(_value_and_jacfwd(_residuals), ps, (field, samples, weights, v0, E, hints))

    # the bundle, free aspect, in the joint normalised coordinates, near its estimate
    V = points.shape[0]
    used = jnp.ones(V, bool)
    Tj = joint_transform(points, used)
    problem = _model.make_problem(transform_points(Tj, points), n_samples, None, jnp.asarray(homs.inliers, float), used)
    Kn = np.asarray(Tj) @ (K if np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0 else np.eye(3) * 1000)
    k = jnp.asarray([np.log(Kn[0, 0]), np.log(Kn[1, 1]), Kn[0, 2], Kn[1, 2]])
    a = _model.axis_params(jnp.asarray(homs.l_s) @ jnp.linalg.inv(Tj))
    y = (k, a)
    bh = _model.foot_parameters(y, problem)
    ys = (k + 1e-6 * jnp.asarray(rng.standard_normal((calls, 4))),
          a + 1e-6 * jnp.asarray(rng.standard_normal((calls,) + a.shape)))
    t_bundle = _time_map(_value_and_jacfwd(_bundle._hinted_residuals), ys, (problem, bh))
    return t_view, t_bundle, _solver_step_times(field, samples, weights, p, v0, E, y, problem, rng, max(calls // 10, 8))


def _solver_step_times(field, samples, weights, p, v0, E, y, problem, rng, calls: int) -> tuple[float, float]:
    """Seconds per step of whole solves as the programs run them (a solve's fixed costs
    included: the whole-outline closest-point search at its start and end, the
    solver's linear algebra and loop): per view Levenberg-Marquardt
    (:func:`sorjax.core._viewfit.refine`) and the bundle's Gauss-Newton
    (:func:`sorjax.core._bundle.solve`), from starts perturbed off the fit."""
    import jax
    import jax.numpy as jnp

    from sorjax.core import _bundle
    from sorjax.core._viewfit import refine

    def per_step(solve, xs, args):
        f = jax.jit(lambda xs, args: jax.lax.map(lambda x: solve(x, args), xs))
        jax.block_until_ready(f(xs, args))
        best = math.inf
        for _ in range(2):
            t0 = time.perf_counter()
            steps = jax.block_until_ready(f(xs, args))
            best = min(best, time.perf_counter() - t0)
        return best / max(int(np.sum(np.asarray(steps))), 1)

    ps = p + 3e-2 * jnp.asarray(rng.standard_normal((calls, 4))) * jnp.asarray([1.0, 1.0, 0.1, 0.1])
    t_view = per_step(lambda q, a: refine(*a, q, v0, E, 100, "lm")[4], ps, (field, samples, weights))
    k, a = y
    ys = (k + 1e-2 * jnp.asarray(rng.standard_normal((calls, 4))),
          a + 1e-3 * jnp.asarray(rng.standard_normal((calls,) + a.shape)))
    t_bundle = per_step(lambda yy, prob: _bundle.solve(yy, prob, 200, "gn")[2], ys, problem)
    return t_view, t_bundle


def screening_starts(points_all: list[np.ndarray], n_samples: int) -> np.ndarray:
    """(trials, V) number of valid automatic starts of every view (each is screened)."""
    import jax
    import jax.numpy as jnp

    from sorjax.core import prepare_views
    from sorjax.core._viewfit import automatic_starts

    def one(pts):
        views = prepare_views(pts, n_samples)
        return jax.vmap(lambda p, s: jnp.sum(automatic_starts(p, s)[2]))(views.points, views.samples)

    return np.asarray(jax.jit(lambda x: jax.lax.map(one, x))(jnp.asarray(np.stack(points_all))))


def measure_floor(timed: _TimedProgram, n_samples: int, screen_steps: int, calls: int) -> dict:
    pts, homs, K = timed.example
    t_view, t_bundle, (s_view, s_bundle) = residual_jacobian_times(pts, homs, K, n_samples, calls)
    vs = np.stack(timed.view_steps).astype(float)  # (trials, V)
    bs = np.stack(timed.bundle_steps).astype(float)  # (trials, bundles)
    starts = screening_starts(timed.points, n_samples)
    screen = np.maximum(starts - 1, 0) * screen_steps  # the losing starts' screening
    per_trial = (vs.sum(1) + screen.sum(1)) * t_view + bs.sum(1) * t_bundle
    return dict(
        t_view_s=t_view, t_bundle_s=t_bundle, view_steps=float(vs.sum(1).mean()),
        screen_steps=float(screen.sum(1).mean()), bundle_steps=float(bs.sum(1).mean()),
        starts=float(starts.mean()), floor_trial_s=float(per_trial.mean()),
        floor_trial_no_screen_s=float((vs.sum(1) * t_view + bs.sum(1) * t_bundle).mean()),
        step_view_s=s_view, step_bundle_s=s_bundle,
        solver_trial_s=float(((vs.sum(1) + screen.sum(1)) * s_view + bs.sum(1) * s_bundle).mean()),
    )


def fits_share(timed: _TimedProgram, options, n: int) -> float:
    """Seconds per trial of the per-view fits alone (:func:`sorjax.core.fit_homologies`,
    views one after another, as the one-device program runs them), over the first
    ``n`` trials of the table in one compiled ``lax.map``: the rest of a warm trial is
    the five methods (linear estimates, bundles, covariances, verdicts)."""
    import jax
    import jax.numpy as jnp

    from sorjax import core

    pts = jnp.asarray(np.stack(timed.points[:n]))
    f = jax.jit(lambda x: jax.lax.map(lambda p: core.fit_homologies(p, options, True).steps, x))
    jax.block_until_ready(f(pts))
    best = math.inf
    for _ in range(2):
        t0 = time.perf_counter()
        jax.block_until_ready(f(pts))
        best = min(best, time.perf_counter() - t0)
    return best / len(pts)


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


def pixel_starts(points: np.ndarray, n_samples: int) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """sorjax's automatic starts of every view of one trial (V, M, 2), in pixels."""
    import jax
    import jax.numpy as jnp

    from sorjax.core import prepare_views
    from sorjax.core._viewfit import automatic_starts

    @jax.jit
    def starts(points):
        views = prepare_views(points, n_samples)
        return views.T, jax.vmap(automatic_starts)(views.points, views.samples)

    Ts, (vs, ls, valid) = jax.tree.map(np.asarray, starts(jnp.asarray(points)))
    out = []
    for j, T in enumerate(Ts):
        out.append([(np.linalg.solve(T, v), T.T @ l) for v, l in zip(vs[j][valid[j]], ls[j][valid[j]])])
    return out


def compare_baseline(timed: _TimedProgram, records: list, n: int, n_samples: int) -> dict:
    """The baseline on ``n`` trials of the table spread over its cells (starts not
    timed); its focal errors beside sorjax's bundle-unit on the same trials."""
    idx = np.unique(np.linspace(0, len(timed.points) - 1, n).round().astype(int))
    trials = [timed.points[i] for i in idx]
    starts = [pixel_starts(p, n_samples) for p in trials]
    t0 = time.perf_counter()
    bl = [baseline_trial(list(p), st, n_samples) for p, st in zip(trials, starts)]
    t_base = (time.perf_counter() - t0) / len(trials)
    # the table's records are in task order, as the timed points are (one shape)
    recs = [r for r in records if "error" not in r]
    f_true = np.array([recs[i]["K_true"][0] for i in idx])
    e_b = np.array([np.nan if b is None else b[0] for b in bl]) / f_true * 100 - 100
    e_s = np.array([recs[i]["methods"].get("bundle-unit", {}).get("error", [np.nan])[0] for i in idx])
    return dict(n=len(trials), baseline_trial_s=t_base, err_baseline=e_b.tolist(), err_sorjax=e_s.tolist(),
                baseline_failures=int(np.isnan(e_b).sum()))


# ------------------------------------------------------------ 4. the README's job


def quick_in_subprocess(warm_cache: bool, timeout: float) -> dict:
    env = dict(os.environ)
    if not warm_cache:
        env["SORJAX_CACHE"] = _fresh_cache()
    out = tempfile.mkdtemp(prefix="sorjax-quick-")
    cmd = [sys.executable, "-m", "sorjax", "experiment", os.path.join(ROOT, "configs", "table1-quick.toml"),
           "--out", out, "--quiet"]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return dict(error=f"timed out after {timeout:.0f} s")
    wall = time.perf_counter() - t0
    if p.returncode:
        return dict(error=f"exit {p.returncode}: {p.stderr.strip().splitlines()[-1:]}", wall_s=wall)
    out_s = dict(wall_s=wall)
    for root, _, files in os.walk(out):
        if "results.json" in files:  # the trials' share (run_trials); the rest: start-up, bounds, figures
            with open(os.path.join(root, "results.json")) as fh:
                out_s["trials_s"] = float(json.load(fh)["seconds"])
    return out_s


# ------------------------------------------------------------------------ main


def _ms(s):
    return f"{1000 * s:.1f} ms"


def components(points: np.ndarray, opts, methods: tuple[str, ...]) -> list[tuple[str, float, float, float]]:
    """Where the trial program's compilation goes: each part traced and lowered alone
    (``jax.jit(f).lower``), the size of its StableHLO text and the time XLA takes to
    compile it, for one trial's ``points`` (V, M, 2).  The parts overlap (the methods
    hold the bundles, a bundle its covariance and no-perspective fit).  Returns rows
    ``(name, trace + lower s, MB of text, compile s)``."""
    import jax
    import jax.numpy as jnp

    from sorjax.core import _bundle as B
    from sorjax.core import _covariance as B_covariance
    from sorjax.core import _model as B_model
    from sorjax import core
    from sorjax.core import _calibrate as C
    from sorjax.core import _checks as CH
    from sorjax.experiment._trials import _method_args

    names = tuple(_method_args(m)[0] for m in methods)
    aspects = np.array([_method_args(m)[1] for m in methods])
    P = jnp.asarray(points)
    homs = jax.jit(lambda p: core.fit_homologies(p, opts, True))(P)
    c = jax.jit(lambda p, h: C._common(p, h, jnp.ones(p.shape[0], bool), opts))(P, homs)
    seeds, seed_ok = B.bundle_seeds(homs.v_x, homs.l_s, c.used, c.T, jnp.nan)
    prob = B_model.with_model(c.problem, jnp.nan)
    y = jax.jit(lambda p, l, s, so: B.fit_bundle(p, l, s, so, opts)[0])(prob, c.l_n, seeds, seed_ok)
    parts = [
        ("per-view fits (fit_homologies)", lambda p: core.fit_homologies(p, opts, True), (P,)),
        ("the methods (calibrate_methods)", lambda p, h: C.calibrate_methods(p, h, names, aspects, options=opts),
         (P, homs)),
        ("  one bundle (bundle_estimate)", lambda c, s, so: B.bundle_estimate.__wrapped__(
            c.points_n, c.used, c.inliers, c.l_n, s, so, jnp.nan, c.T, opts, base=c.problem), (c, seeds, seed_ok)),
        ("    its solver loop (fit_bundle: seeds, no-perspective reference)",
         lambda p, l, s, so: B.fit_bundle(p, l, s, so, opts), (prob, c.l_n, seeds, seed_ok)),
        ("    covariance", lambda y, p, T: B_covariance.covariance.__wrapped__(y, p, T), (y, prob, c.T)),
        ("    no-perspective fit on its own", lambda y, p: B.orthographic_cost(y, p), (y, prob)),
        ("  view scores (model checks)", lambda y, c: CH.view_scores(y, c.points_n, c.used, c.inliers, jnp.nan, c.T,
                                                                       opts, base=c.problem, ell=2.0), (y, c)),
    ]
    rows = []
    for name, f, args in parts:
        t0 = time.perf_counter()
        lowered = jax.jit(f).lower(*args)
        t1 = time.perf_counter()
        size = len(lowered.as_text()) / 1e6
        t2 = time.perf_counter()
        lowered.compile()
        rows.append((name, t1 - t0, size, time.perf_counter() - t2))
        print(f"    {name:<34} trace + lower {t1 - t0:5.1f} s  {size:5.2f} MB StableHLO  compile "
              f"{rows[-1][3]:5.1f} s", flush=True)
    return rows


def stablehlo_ops(text: str) -> int:
    """Operations of a lowered program's StableHLO text (``Lowered.as_text()``) with every
    called function inlined: the ``stablehlo.*`` results of ``main`` plus, for each
    ``call``, those of the function called (recursively), as XLA sees them after
    inlining."""
    import collections
    import re

    own, calls, cur = collections.Counter(), collections.defaultdict(list), None
    for line in text.splitlines():
        m = re.match(r"\s*func\.func (?:public |private )?@(\"[^\"]+\"|[\w.$-]+)", line)
        if m:
            cur = m.group(1)
            continue
        if cur is None:
            continue
        m = re.search(r"(?:func\.)?call @(\"[^\"]+\"|[\w.$-]+)", line)  # names with <> are quoted
        if m:
            calls[cur].append(m.group(1))
        if re.search(r"= stablehlo\.\w+", line):
            own[cur] += 1
    memo: dict[str, int] = {}

    def size(f):
        if f not in memo:
            memo[f] = own[f] + sum(size(c) for c in calls[f])
        return memo[f]

    return size("main")


class _Captured(Exception):
    pass


def solve_loops(points) -> int:
    """The solve loops (:func:`sorjax.core._solvers.least_squares`'s loop) traced in
    ``jax.make_jaxpr`` of the whole calibration (:func:`sorjax.core.calibrate`) of
    ``points`` (V, M, 2): issue 41's target is 2 (the per-view fit, the bundle)."""
    import jax
    import jax.numpy as jnp

    from sorjax import core
    from sorjax.core import _solvers

    traced, inner = [], _solvers._minimise
    _solvers._minimise = lambda *a, **k: traced.append(1) or inner(*a, **k)
    try:
        jax.clear_caches()
        jax.make_jaxpr(lambda p: core.calibrate(p))(jnp.asarray(points))
    finally:
        _solvers._minimise = inner
    return len(traced)


def calibrate_program(seed: int = 0, views: int = 4, runs: int = 8) -> dict:
    """The compiled programs of one ``sorjax.calibrate`` call on ``random_sor_scene(seed,
    views)``'s exact outlines: for the per-view fit (:func:`sorjax._homology._fit_core`,
    one outline) and the bundle core (:func:`sorjax._calibration._core`), the
    operations (inlined StableHLO), trace + lower and XLA compile times (s); the solve
    loops in the whole calibration (:func:`solve_loops`); then a first ``calibrate``
    from a fresh compilation cache (wall s: the programs read back from the cache just
    written) and the warm time of one call (median of ``runs``).  Call with a fresh
    ``SORJAX_CACHE``."""
    import jax

    import sorjax
    from sorjax import _calibration as C
    from sorjax import _homology as H
    from sorjax import scenes

    sc = scenes.random_sor_scene(seed, views)
    outlines = [v.outline for v in sc.views]
    core, fit, got = C._core, H._fit_core, {}

    def capture(name):
        def f(*args, **kwargs):  # the arguments calibrate passes; the core is not run
            got.setdefault(name, (args, kwargs))
            if name == "core":
                raise _Captured
            return fit(*args, **kwargs)
        return f

    C._core, H._fit_core = capture("core"), capture("fit")
    try:
        sorjax.calibrate(outlines, image_size=sc.image_size)
    except _Captured:
        pass
    finally:
        C._core, H._fit_core = core, fit
    out = dict(views=views, seed=seed, flags=os.environ.get("XLA_FLAGS", ""))
    for name, program in (("fit", fit), ("core", core)):
        jax.clear_caches()
        args, kwargs = got[name]
        t0 = time.perf_counter()
        lowered = program.lower(*args, **kwargs)
        t1 = time.perf_counter()
        ops = stablehlo_ops(lowered.as_text())
        t2 = time.perf_counter()
        lowered.compile()
        t3 = time.perf_counter()
        out[name] = dict(ops=ops, lower_s=t1 - t0, compile_s=t3 - t2)
    out["ops"], out["lower_s"], out["compile_s"] = (out["core"][k] for k in ("ops", "lower_s", "compile_s"))
    out["solve_loops"] = solve_loops(got["core"][0][0])
    jax.clear_caches()  # the first call traces again, as a new process would
    t4 = time.perf_counter()
    cal = sorjax.calibrate(outlines, image_size=sc.image_size)
    out["first_s"] = time.perf_counter() - t4
    warm = []
    for _ in range(runs):
        t = time.perf_counter()
        cal = sorjax.calibrate(outlines, image_size=sc.image_size)
        warm.append(time.perf_counter() - t)
    out["warm_s"] = statistics.median(warm)
    out["f_err_pct"] = abs(cal.fv / sc.K[1, 1] - 1) * 100
    return out


FIRST_K_SCRIPT = r"""
import time
t0 = time.perf_counter()
import warnings
import numpy as np
import sorjax
from sorjax import scenes
t1 = time.perf_counter()
warnings.simplefilter("ignore")
sc = scenes.two_spheres(f=700.0)
outlines = [scenes.paper_noise(o, 0.5, i) for i, o in enumerate(sc.outlines)]  # 0.5 px, seeds 0, 1, 2
cal = sorjax.calibrate(outlines)
t2 = time.perf_counter()
k1 = sorjax.calibrate(outlines, distortion="k1")
t3 = time.perf_counter()
print("FIRSTK", t1 - t0, t2 - t0, t3 - t2, float(cal.fv), bool(cal.success))
"""


def first_k(timeout: float) -> dict:
    """Time to the first K in fresh Python processes (issue 41's figure): ``import
    sorjax`` + ``sorjax.calibrate`` of the 3 outlines of ``scenes.two_spheres(f=700)``
    with 0.5 px noise (seeds 0-2; pinhole, free aspect), import included; then the
    first ``distortion="k1"`` call in the same process.  Once with an empty cache
    folder (``SORJAX_CACHE``: compilation cache and stored programs), then again with
    the cache that run left (warm)."""
    cache = _fresh_cache()
    out = {}
    for label in ("cold", "warm"):
        env = dict(os.environ, SORJAX_CACHE=cache)
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", FIRST_K_SCRIPT], env=env, capture_output=True, text=True,
                           timeout=timeout)
        wall = time.perf_counter() - t
        line = next((ln for ln in r.stdout.splitlines() if ln.startswith("FIRSTK")), None)
        if line is None:
            raise RuntimeError(f"first-K subprocess failed:\n{r.stderr[-2000:]}")
        _, imp, first, k1, fv, ok = line.split()
        out[label] = dict(import_s=float(imp), first_k_s=float(first), k1_s=float(k1), fv=float(fv),
                          success=ok == "True", wall_s=wall)
    return out


def print_first_k(timeout: float) -> dict:
    print("time to first K: a fresh process, import sorjax + calibrate(3 outlines of two_spheres(f=700), 0.5 px, "
          "seeds 0-2), import included ...", flush=True)
    fk = first_k(timeout)
    for label, target in (("cold", 10.0), ("warm", 3.0)):
        r = fk[label]
        print(f"    {label} cache: import {r['import_s']:.1f} s, first K {r['first_k_s']:.1f} s "
              f"(target <= {target:g} s: {_mark(r['first_k_s'] <= target)}); then distortion='k1' "
              f"{r['k1_s']:.1f} s (target <= 1 s: {_mark(r['k1_s'] <= 1.0)}); fv {r['fv']:.1f} px, success "
              f"{r['success']}")
    return fk


def _mark(ok):
    return "-" if ok is None else ("pass" if ok else "MISS")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trials", type=int, default=None, help="trials per Table 1 cell (default: the config's 100)")
    p.add_argument("--chunk", type=int, default=64, help="trials per compiled chunk (the runner's default 64)")
    p.add_argument("--baseline-trials", type=int, default=10)
    p.add_argument("--floor-calls", type=int, default=400, help="residual + Jacobian calls per floor timing")
    p.add_argument("--warm-cache", action="store_true", help="reuse the on-disk compilation cache (default: fresh)")
    p.add_argument("--devices", type=int, default=0,
                   help="also run the table split over this many CPU devices in a subprocess (0/1: skip)")
    p.add_argument("--workers", type=int, default=None, help="deprecated: the same as --devices")
    p.add_argument("--breakdown", action="store_true",
                   help="also time the per-view fits alone (one more compilation, about a minute)")
    p.add_argument("--skip-quick", action="store_true", help="skip the table1-quick subprocess")
    p.add_argument("--components", action="store_true",
                   help="also trace and compile the trial program's parts alone: StableHLO size and compile time "
                        "of each (a few minutes)")
    p.add_argument("--timeout", type=float, default=1800.0, help="limit of each subprocess, s")
    p.add_argument("--table-json", action="store_true", help=argparse.SUPPRESS)  # the --devices subprocess
    p.add_argument("--calibrate-program", action="store_true",
                   help="only measure one sorjax.calibrate call's compiled program (size, trace, compile, first and "
                        "warm run), then exit")
    p.add_argument("--first-k", action="store_true",
                   help="only measure the time to the first K in fresh processes (empty cache, then warm), then exit")
    p.add_argument("--program-views", type=int, default=4, help="views of --calibrate-program's scene")
    p.add_argument("--program-seed", type=int, default=0, help="random_sor_scene seed of --calibrate-program's scene")
    a = p.parse_args(argv)
    devices = a.devices if a.workers is None else a.workers

    if not a.warm_cache:
        os.environ["SORJAX_CACHE"] = _fresh_cache()  # before the runner enables the cache
    if a.first_k:
        print_first_k(a.timeout)
        return
    if a.calibrate_program:
        import jax

        jax.config.update("jax_enable_x64", True)
        from sorjax.experiment._runner import enable_compilation_cache

        enable_compilation_cache()
        print(f"calibrate's program: random_sor_scene({a.program_seed}, {a.program_views}), exact outlines, "
              f"{'warm' if a.warm_cache else 'fresh'} compilation cache, XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}",
              flush=True)
        r = calibrate_program(a.program_seed, a.program_views)
        for name, what in (("fit", "per-view fit (_fit_core, one outline)"), ("core", "bundle core (_core)")):
            print(f"    {what}: {r[name]['ops']:,} StableHLO operations (called functions inlined); trace + lower "
                  f"{r[name]['lower_s']:.1f} s, XLA compile {r[name]['compile_s']:.1f} s")
        print(f"    solve loops in the whole calibration (make_jaxpr of sorjax.core.calibrate): {r['solve_loops']} "
              f"(target 2: {_mark(r['solve_loops'] == 2)})")
        print(f"    first calibrate (per-view fits compiled, the core from the cache): {r['first_s']:.1f} s; warm "
              f"{_ms(r['warm_s'])} a call (median of 8); focal error {r['f_err_pct']:.2g} %")
        print_first_k(a.timeout)
        return
    if a.table_json:
        nums, _, _ = measure_table(a.trials, a.chunk)
        print(JSON_TAG + json.dumps(nums), flush=True)
        return

    t_run = time.perf_counter()
    print(f"[1] table1.toml ({'config trials' if a.trials is None else f'{a.trials} trials per cell'}), one process, "
          f"{'warm' if a.warm_cache else 'fresh'} compilation cache ...", flush=True)
    tab, timed, records = measure_table(a.trials, a.chunk)
    from sorjax.experiment._trials import options_for

    opts = options_for(_table1_config(a.trials))
    n = tab["trials"]
    print(f"    {tab['backend']} backend, {tab['devices']} device(s), {os.cpu_count()} cores; {n} trials in "
          f"{tab['n_chunks']} chunk(s) of {tab['chunk']}; methods {', '.join(tab['methods'])}")
    print(f"    wall {tab['wall_s']:.1f} s = trace {tab['lower_s']:.1f} s + compile {tab['compile_s']:.1f} s + "
          f"compute {tab['compute_s']:.1f} s + host {tab['host_s']:.1f} s (draws, records); import jax+sorjax "
          f"{tab['import_s']:.1f} s before that")
    print(f"    warm {_ms(tab['warm_trial_s'])} per trial (median over chunks); first chunk {_ms(tab['first_chunk_trial_s'])}"
          f" per trial; failures per method: {tab['failures']}")

    print(f"[3] arithmetic floor ({a.floor_calls} residual + Jacobian calls per timing) ...", flush=True)
    fl = measure_floor(timed, opts.n_samples, opts.screen_steps, a.floor_calls)
    print(f"    one residual + Jacobian: per view {fl['t_view_s'] * 1e6:.0f} us, bundle (3 views) "
          f"{fl['t_bundle_s'] * 1e6:.0f} us")
    print(f"    steps per trial (mean): per-view fits {fl['view_steps']:.0f} + screening of the losing starts "
          f"{fl['screen_steps']:.0f} ({fl['starts']:.1f} valid starts a view), bundles {fl['bundle_steps']:.0f}")
    print(f"    floor {_ms(fl['floor_trial_s'])} per trial ({_ms(fl['floor_trial_no_screen_s'])} without the losing "
          f"starts' screening); warm / floor = {tab['warm_trial_s'] / fl['floor_trial_s']:.2f}")
    print(f"    a whole solve's cost per step (its fixed costs included): per view {fl['step_view_s'] * 1e6:.0f} us "
          f"(LM), bundle {fl['step_bundle_s'] * 1e6:.0f} us (GN): the same steps priced so "
          f"{_ms(fl['solver_trial_s'])} per trial; the rest of the warm trial (starts, padded screening lanes, "
          f"seed ranking, no-perspective fits, covariances, verdicts) {_ms(tab['warm_trial_s'] - fl['solver_trial_s'])}")

    if a.breakdown:
        t_fits = fits_share(timed, opts, min(len(timed.points), 32))
        print(f"    per-view fits alone {_ms(t_fits)} per trial (3 views), so the five methods "
              f"{_ms(tab['warm_trial_s'] - t_fits)}; their solver steps at the floor: fits "
              f"{_ms(fl['floor_trial_s'] - fl['bundle_steps'] * fl['t_bundle_s'])}, bundles "
              f"{_ms(fl['bundle_steps'] * fl['t_bundle_s'])}")

    if a.components:
        print("    the trial program's parts compiled alone (they overlap):", flush=True)
        components(timed.points[0], opts, tab["methods"])

    print(f"[2] numpy/scipy baseline on {a.baseline_trials} of the same trials (fits + IIb + unit bundle) ...",
          flush=True)
    bl = compare_baseline(timed, records, a.baseline_trials, opts.n_samples)
    ratio = bl["baseline_trial_s"] / tab["warm_trial_s"]
    n_m = len(tab["methods"])
    ratio_cal = (bl["baseline_trial_s"] / 2) / (tab["warm_trial_s"] / n_m)
    rms = lambda e: float(np.sqrt(np.nanmean(np.square(e)))) if np.any(np.isfinite(e)) else math.nan  # noqa: E731
    print(f"    baseline {_ms(bl['baseline_trial_s'])} per trial (2 calibrations), sorjax warm "
          f"{_ms(tab['warm_trial_s'])} per trial ({n_m} calibrations): {ratio:.1f}x per trial, {ratio_cal:.1f}x per "
          f"calibration")
    print(f"    focal error RMS (% of f) on these trials: baseline {rms(bl['err_baseline']):.2f}, sorjax bundle-unit "
          f"{rms(bl['err_sorjax']):.2f} ({bl['baseline_failures']} baseline failures)")

    quick = None
    if not a.skip_quick:
        print("[4] sorjax experiment configs/table1-quick.toml in a subprocess, fresh cache ...", flush=True)
        quick = quick_in_subprocess(a.warm_cache, a.timeout)
        if "error" in quick:
            print(f"    {quick['error']}")
        else:
            tr = quick.get("trials_s", math.nan)
            print(f"    {quick['wall_s']:.1f} s wall, start to exit: the trials {tr:.1f} s (run_trials, compilation "
                  f"included), the rest {quick['wall_s'] - tr:.1f} s (start-up, efficiency bounds, figures, files)")

    multi = None
    print(f"[5] this process: {tab['backend']} backend, {tab['devices']} device(s); {os.cpu_count()} CPU cores")
    if devices and devices > 1:
        print(f"    table1.toml again over {devices} CPU devices in a subprocess (vmap, sharded) ...", flush=True)
        multi = table_in_subprocess(a.trials, a.chunk, devices, a.warm_cache, a.timeout)
        if "error" in multi:
            print(f"    {multi['error']}")
        else:
            print(f"    {multi['devices']} devices: wall {multi['wall_s']:.1f} s = trace {multi['lower_s']:.1f} + "
                  f"compile {multi['compile_s']:.1f} + compute {multi['compute_s']:.1f} + host {multi['host_s']:.1f} s;"
                  f" warm {_ms(multi['warm_trial_s'])} per trial (one device: {_ms(tab['warm_trial_s'])}); "
                  f"process {multi['process_s']:.1f} s")

    rows = [
        (f"table1 ({n} trials) wall, compilation incl.", f"{tab['wall_s']:.1f} s", f"<= {TARGET_TABLE_S:g} s (issue 5)",
         tab["wall_s"] <= TARGET_TABLE_S if a.trials is None else None),
        ("  of which trace + compile", f"{tab['lower_s']:.1f} + {tab['compile_s']:.1f} s", "", None),
        ("warm per trial (5 methods, chunk amortised)", _ms(tab["warm_trial_s"]), f"<= {TARGET_TRIAL_MS:g} ms",
         1000 * tab["warm_trial_s"] <= TARGET_TRIAL_MS),
        ("arithmetic floor per trial", _ms(fl["floor_trial_s"]), "", None),
        ("  the same steps as whole solves", _ms(fl["solver_trial_s"]), "", None),
        ("warm / floor", f"{tab['warm_trial_s'] / fl['floor_trial_s']:.2f}", f"<= {TARGET_FLOOR_RATIO:g}",
         tab["warm_trial_s"] / fl["floor_trial_s"] <= TARGET_FLOOR_RATIO),
        ("baseline per trial (numpy/scipy)", _ms(bl["baseline_trial_s"]), "", None),
        ("baseline / sorjax warm, per trial", f"{ratio:.1f}x", f">= {TARGET_RATIO:g}x", ratio >= TARGET_RATIO),
        ("  per calibration (5 vs 2 a trial)", f"{ratio_cal:.1f}x", f">= {TARGET_RATIO:g}x", ratio_cal >= TARGET_RATIO),
    ]
    if quick is not None:
        rows.append(("table1-quick subprocess, fresh cache", quick.get("error", f"{quick.get('wall_s', 0):.1f} s"),
                     f"<= {TARGET_QUICK_S:g} s", None if "error" in quick else quick["wall_s"] <= TARGET_QUICK_S))
    if multi is not None and "error" in multi:
        rows.append((f"table over {devices} devices", multi["error"], "beats 1 device?", False))
    if multi is not None and "error" not in multi:
        rows.append((f"table over {multi['devices']} devices: wall / warm", f"{multi['wall_s']:.1f} s / "
                     f"{_ms(multi['warm_trial_s'])}", "beats 1 device?",
                     multi["wall_s"] < tab["wall_s"] and multi["warm_trial_s"] < tab["warm_trial_s"]))
    w = max(len(r[0]) for r in rows)
    print(f"\nissue 16 measures ({tab['backend']}, {tab['devices']} device(s), {os.cpu_count()} cores; "
          f"this run {time.perf_counter() - t_run:.0f} s)")
    for name, val, tgt, ok in rows:
        print(f"  {name:<{w}}  {val:>16}  {tgt:<22} {_mark(ok)}")


if __name__ == "__main__":
    main()
