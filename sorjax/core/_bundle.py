"""The joint, "statistically optimal" estimator the paper left as future work (Sec. 9).

Its model, chart and residuals: :mod:`sorjax.core._model`; its linearisation and
covariance: :mod:`sorjax.core._covariance`; with radial distortion:
:mod:`sorjax.core._distorted`.

One least-squares loop (:func:`sorjax.core._solvers.least_squares`) with Jacobians by
autodiff: every seed (the linear methods' estimates with the per-view fits' axes, or a
safe spread of cameras when no linear omega is positive definite) is ranked by its
cost, the best is polished by Gauss-Newton (Levenberg-Marquardt as the fallback), and
the camera with no perspective (the evidence for perspective) is fitted as one more
round of the same loop (see :func:`_fit_bundle`).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._linear import focal_from_principal_point, linear_estimates
from ._solvers import (Method, Solved, computed_as, is_stale, least_squares, pick, polish_traced, solvers,
                       until_fresh_traced)
from ._options import Options
from ._model import (BundleProblem, axis_params, checked_residuals, fixed_chart, foot_parameters, make_problem,
                     pack_seeds, pin_intrinsics, residuals, solution_in_pixels, split_params, with_model)
from ._camera import intrinsics_matrix, omega_matrix, omega_vector_from_intrinsics
from ._covariance import LIN_VIEWS, Linearisation, OutlineOffsets, covariance, linearise, step_sigmas


def _hinted_residuals(y, args):
    problem, hints = args
    return residuals(y, problem, hints)


# Solvers (:mod:`sorjax.core._solvers`): every seed was once screened by a few loose
# Levenberg-Marquardt steps, the best polished by Gauss-Newton.  Measured on the
# two-sphere scene (40 trials each, unit aspect) against full Levenberg-Marquardt from
# every seed: f = 700, sigma 1 px, 38 -> 25 ms a calibration, the same estimates (to
# 1e-6 % of f); f = 1400, sigma 2 px, 68-100 -> 25 ms, 7 gross failures instead of 10
# (a losing seed no longer crawls to its step limit).  Screening with 8, 4 or 2 steps
# gave the same focal RMS and gross failures over 60 trials (f = 700 sigma 1, f = 1400
# sigma 2, both aspect models); 4 steps: 3-4 ms faster than 8.
#
# Ranking the seeds by their cost as they are, with no screening step, measured against
# 4 screening steps (two-sphere scene, 30 trials each, free / unit aspect focal RMS):
# f = 700 sigma 1: 2.60 / 2.49 % both ways (unit: 2.485 vs 2.494); f = 1400 sigma 1.2:
# 7.30 / 7.56 vs 7.30 / 7.58 %; f = 1400 sigma 2: 11.20 / 11.71 vs 11.32 / 11.87 %, the same
# gross failures (2 / 2) -- a few trials polish a different seed into an equally good
# neighbour -- and 12 solver steps fewer a calibration: no screening steps any more.
_SOLVERS = solvers(rtol=1e-7, atol=1e-9)


def solve(y0, problem: BundleProblem, max_steps=200, method: str | Method = "lm", hints=None):
    """Minimise the bundle's cost from ``y0`` with ``method``: "lm" (Levenberg-Marquardt),
    "gn" (Gauss-Newton) or "screen" (loose Levenberg-Marquardt, for a few steps), or a
    :class:`sorjax.core._solvers.Method` (data; ``max_steps`` may be traced too);
    returns ``(y, ok, steps, residuals, stale, feet)`` (``ok``: converged).

    The solver's residuals search each closest point only near where it was at ``y0``
    (:func:`foot_parameters`; :data:`sorjax.core._field.NEAR_WINDOW`): a third of the
    distance computations of a whole-outline search, half the time of a step.  The
    returned residuals are searched over the whole outlines; ``stale`` is True when
    they differ from the solver's (a closest point moved out of its window during the
    solve), and the caller then solves again from ``y`` (:func:`fit_bundle`).  Measured
    on the two-sphere scene (60 trials, f = 700 and 1400 px, sigma 0.5-2 px): the
    closest points moved at most 28 knots from the best seed to the optimum (median 3),
    within the window of 32.

    ``hints``: :func:`foot_parameters` at ``y0`` when the caller has them (the end of
    the previous solve, ``feet``), else None (searched here).  ``feet``: the
    closest-point parameters of the returned residuals (:func:`checked_residuals`)."""
    if hints is None:
        hints = foot_parameters(y0, problem)
    method = _SOLVERS[method] if isinstance(method, str) else method
    y, ok, steps = least_squares(_hinted_residuals, y0, (problem, hints), method, max_steps, problem.weights.size)
    r, feet, r_near = checked_residuals(y, problem, hints)
    return y, ok, steps, r, is_stale(r, r_near), feet


# The no-perspective reference: the focal length held at ORTHO_LOG_F (log of a focal
# length in the calibration's normalised units, where the outlines span about 1:
# e^9.2 ~ 1e4, a field of view of about 0.01 degree), so that every v_x is at
# infinity and each outline's symmetry is an affine (skew) reflection.
ORTHO_LOG_F = 9.2
# only the cost is needed, to about 1e-4 (the evidence agreed to 5 digits with the
# bundle's tolerances on the two-sphere scene; 2.7 ms instead of 4.1 ms a call)
_ORTHO_SOLVER = Method(True, 1e-4, 1e-6)
ORTHO_MAX_STEPS = 100


def with_fixed(problem: BundleProblem) -> BundleProblem:
    """``problem`` with ``fixed`` an array (all NaN where it was None: the same model,
    bit for bit, :func:`pin_intrinsics`), so that the bundle's solve and the
    no-perspective reference (:func:`orthographic_problem`) share one traced loop."""
    if problem.fixed is not None:
        return problem
    return dataclasses.replace(problem, fixed=jnp.full(4, jnp.nan, problem.samples.dtype))


def orthographic_problem(k, problem: BundleProblem) -> BundleProblem:
    """The bundle's problem of the no-perspective reference at the bundle's chart ``k``
    (4,): ``fv`` held at ``exp(ORTHO_LOG_F)`` (normalised units) and the principal point
    at ``k``'s (it no longer matters there), ``fu`` free for a free aspect ratio (the
    ratio ``fu / fv`` is what the outlines still show), the intrinsics the user fixed
    held as given (:attr:`BundleProblem.fixed`; with ``fu`` fixed and ``fv`` free, ``fv``
    is left free instead, from ``exp(ORTHO_LOG_F)``).  A problem of the same structure
    as :func:`with_fixed`'s: one solve serves both."""
    problem = with_fixed(problem)
    user = problem.fixed
    fv_free = jnp.isnan(problem.aspect) & jnp.isfinite(user[0]) & ~jnp.isfinite(user[1])
    logf = jnp.where(fv_free, jnp.nan, jnp.asarray(ORTHO_LOG_F, k.dtype))
    ortho = jnp.stack([jnp.asarray(jnp.nan, k.dtype), logf, k[2], k[3]])
    return dataclasses.replace(problem, fixed=jnp.where(jnp.isfinite(user), user, ortho))


def orthographic_start(y, problem: BundleProblem):
    """Where the no-perspective reference starts from the bundle's solution ``y = (k
    (4,), a)``: ``fv = exp(ORTHO_LOG_F)``, ``fu / fv`` as at ``y`` (free aspect ratio),
    the same axes."""
    k, a = y
    ratio = jnp.where(jnp.isnan(problem.aspect), k[0] - k[1], 0.0)
    logf = jnp.asarray(ORTHO_LOG_F, k.dtype)
    return jnp.stack([logf + ratio, logf, k[2], k[3]]), a


def orthographic_cost(y, problem: BundleProblem, max_steps: int = ORTHO_MAX_STEPS):
    """Cost (normalised units^2, summed over the samples) of the best camera with no
    perspective, started from the bundle's solution ``y = (k (4,), a)``
    (:func:`orthographic_start`, :func:`orthographic_problem`).

    ``cost - |r(y)|^2`` is the evidence for perspective in the outlines, the only thing
    that fixes the focal length: when it is no larger than noise or systematic errors
    of the outlines could make, the focal length is not determined, whatever the
    bundle's covariance says (that linearisation can be confident far from the truth
    under weak perspective).

    The bundle (:func:`bundle_estimate`) fits it as one more round of its own solver
    loop (:func:`_fit_bundle`); this is the same fit on its own.  Closest points are
    searched near where they were at the start, and the solve is repeated from its end
    should one of them leave its window (as in :func:`solve`)."""
    y0 = orthographic_start(y, problem)
    p = orthographic_problem(y[0], problem)
    run, r0 = _runner(p, max_steps)
    final, _ = polish_traced(run, (y0, foot_parameters(y0, p)), jnp.inf, _ORTHO_SOLVER, _ORTHO_SOLVER, r0,
                             retry=False)
    return final.cost


SEED_BATCH = 6  # the three linear methods' seeds, then the fallback spread (:func:`bundle_seeds`)
FALLBACK_FOCALS = (2.0, 5.0, 12.0)  # normalised units: the spread of cameras tried with no linear seed


@jax.jit
def bundle_seeds(v_pix, l_pix, used, T, aspect, fixed=None):
    """The bundle's intrinsic seeds (normalised units, :data:`SEED_BATCH` of them):
    Methods IIa, IIb and I (:func:`sorjax.core._linear.linear_estimates`; IIb and I with
    the known aspect ratio, 1 for free), projected onto a known aspect ratio
    ``a = aspect`` (``fv = sqrt(fu fv / a)``, ``fu = a fv``; NaN: free), then the
    fallback spread ``(a f, f, 0, 0)`` for f in :data:`FALLBACK_FOCALS`, valid only
    where no linear seed is.

    ``fixed`` (4,): intrinsics held fixed, ``(fu, fv, u0, v0)`` px (NaN: free; None:
    none).  The seeds' fixed entries are replaced in the bundle itself
    (:func:`pin_intrinsics`); with the principal point fixed, the fourth seed (the
    first of the spread) is the focal length of
    :func:`sorjax.core._linear.focal_from_principal_point` (the single-view case, valid
    whenever it is: one view suffices) at that principal point.

    Returns ``(seeds (6, 4), seed_ok (6,))``; a linear seed is valid when its method
    succeeded and its focal lengths are finite and positive."""
    aspect = jnp.asarray(aspect, jnp.float64)
    known = jnp.isfinite(aspect)
    a = jnp.where(known, aspect, 1.0)
    K, _, ok = linear_estimates(v_pix, l_pix, used, T, a)
    Kn = T @ K
    fu, fv, u0, v0 = Kn[:, 0, 0], Kn[:, 1, 1], Kn[:, 0, 2], Kn[:, 1, 2]
    prod = fu * fv / a
    fv_a = jnp.where(prod >= 0, jnp.sqrt(jnp.where(prod >= 0, prod, 0.0)), jnp.nan)
    fu, fv = jnp.where(known, a * fv_a, fu), jnp.where(known, fv_a, fv)
    lin = jnp.stack([fu, fv, u0, v0], axis=-1)
    lin_ok = ok & jnp.all(jnp.isfinite(lin), axis=-1) & (fu > 0) & (fv > 0)
    f = jnp.asarray(FALLBACK_FOCALS)
    spread = jnp.stack([a * f, f, jnp.zeros_like(f), jnp.zeros_like(f)], axis=-1)
    seeds = jnp.concatenate([jnp.where(lin_ok[:, None], lin, spread), spread])
    seed_ok = jnp.concatenate([lin_ok, jnp.broadcast_to(~jnp.any(lin_ok), f.shape)])
    if fixed is not None:
        fixed = jnp.asarray(fixed, jnp.float64)
        f_pp, ok_pp = focal_from_principal_point(v_pix, l_pix, used, fixed[2:], a)
        pp_n = T[:2, :2] @ fixed[2:] + T[:2, 2]
        s = T[0, 0] * f_pp
        closed = jnp.stack([a * s, s, pp_n[0], pp_n[1]])
        seeds = seeds.at[3].set(jnp.where(ok_pp, closed, seeds[3]))
        seed_ok = seed_ok.at[3].set(seed_ok[3] | ok_pp)
    return seeds, seed_ok


def fit_bundle(problem: BundleProblem, l_seeds_n, seeds, seed_ok, options: Options = Options()):
    """Rank the intrinsic seeds by their cost, polish the one of lowest cost to
    convergence (Gauss-Newton; Levenberg-Marquardt when that fails or ends above its
    start, accepted at its step limit when it is as good as stationary:
    :data:`STATIONARY_SIGMAS`); should that not converge either, the next seed, and so
    on.  Pure (jit / vmap): the ranking is one vmapped call, the seeds a
    ``lax.while_loop``, the polish :func:`sorjax.core._solvers.polish_traced` with each
    solve re-run while stale (:func:`sorjax.core._solvers.until_fresh_traced`).

    Args:
        problem: the :class:`BundleProblem` (:func:`make_problem`).
        l_seeds_n: (V, 3) per-view axes from the homology fits (normalised; a masked
            view's row may hold anything).
        seeds: (S, 4) intrinsic seeds ``(fu, fv, u0, v0)`` in normalised units.
        seed_ok: (S,) bool, the seeds to try.
        options: ``bundle_max_steps``, the step limit of each solve.

    Returns ``(y, ok, steps, residuals)``: the padded-chart parameters ``y = (k (4,),
    a (V, 2))``, whether the polish converged (bool), every solver step taken (int),
    the (V N) residuals at ``y``.  Of the seeds tried, the one converged (else the one
    of lowest cost) is returned."""
    return _fit_bundle(problem, l_seeds_n, seeds, seed_ok, options, jnp.eye(3))[:4]


def _fit_bundle(problem: BundleProblem, l_seeds_n, seeds, seed_ok, options: Options, T):
    """:func:`fit_bundle`, :func:`covariance`'s ``(cov, s2, ell, offsets)`` (``T`` the normalising
    similarity) at the ``y`` returned, and the no-perspective reference fit from it
    (:func:`orthographic_cost`).

    One ``lax.while_loop`` whose rounds are the seeds, polished in turn until one
    converges, then the reference: its problem (:func:`orthographic_problem`), start,
    method and step budget are data, so the program holds one traced solve
    (:func:`sorjax.core._solvers.polish_traced`) for both.  Every polished seed's
    covariance is computed in the loop (its Gauss-Newton step is the stationarity test
    of :func:`_converged`), so that the bundle's program holds one covariance, not two.
    ``(cov, s2, ell, offsets)`` is NaN when no seed was tried (never: :func:`bundle_seeds` always
    gives one).  Returns ``(y, ok, steps, residuals, (cov, s2, ell, offsets), (cost_o, y_o), lin)``:
    ``cost_o`` the reference's cost (normalised units^2) at its solution ``y_o`` (the
    chart of :func:`orthographic_problem` at ``y``); ``steps`` counts the seeds' steps;
    ``lin`` the :class:`Linearisation` at ``y`` that the covariance read, its residuals
    refitted with the outlines' estimated offset (:attr:`OutlineOffsets.refit`): what
    the model checks read (a uniformly offset outline, an eroded or dilated mask, is no
    evidence against the camera model once its effect on K is removed and counted)."""
    max_steps = options.bundle_max_steps
    problem = with_fixed(problem)
    used = problem.used
    l = jnp.where(used[:, None], jnp.asarray(l_seeds_n, jnp.float64), jnp.asarray([1.0, 0.0, 0.0]))
    a0 = axis_params(l)
    seed_ok = jnp.asarray(seed_ok, bool)
    ks = pack_seeds(seeds, seed_ok)
    r_seeds, feet0, _ = jax.vmap(lambda k: checked_residuals((k, a0), problem))(ks)  # feet0: each seed's hints
    costs = jnp.sum(r_seeds**2, axis=1)
    costs = jnp.where(jnp.isfinite(costs), costs, jnp.inf)
    S = ks.shape[0]
    # the seeds to try first, by cost (ties: the first given); the others last
    order = jnp.lexsort((jnp.arange(S), costs, ~seed_ok))
    r0 = jnp.zeros(problem.weights.size)
    n_res, V = problem.weights.size, problem.weights.shape[0]
    n_cov = 4 + problem.n_dist
    gn, lm = _SOLVERS["gn"], _SOLVERS["lm"]
    SEED, REFERENCE, DONE = 0, 1, 2
    nan_off = OutlineOffsets(cov=jnp.full((n_cov, n_cov), jnp.nan), shift=jnp.full(n_cov, jnp.nan),
                             value=jnp.full(V, jnp.nan), std=jnp.full(V, jnp.nan), refit=jnp.full(n_res, jnp.nan))
    nan_cov = (jnp.full((n_cov, n_cov), jnp.nan), jnp.asarray(jnp.nan), jnp.asarray(jnp.nan), jnp.full(V, jnp.nan),
               nan_off)
    N = problem.weights.shape[1]
    nan_lin = Linearisation(J=jnp.full((n_res, LIN_VIEWS + 4 * V), jnp.nan), r=jnp.full(n_res, jnp.nan),
                            a=jnp.full((V, N), jnp.nan), feet=jnp.full((V, N), jnp.nan))

    def body(c):
        i, phase, have, best_bad, best_cost, best_y, best_r, best_cov, total, ref, best_lin = c
        seed = phase == SEED
        j = order[jnp.minimum(i, S - 1)]
        # a seed's round, or the no-perspective reference from the best seed's end
        prob = dataclasses.replace(problem, fixed=jnp.where(seed, problem.fixed,
                                                            orthographic_problem(best_y[0], problem).fixed))
        start = pick(seed, (ks[j], a0), orthographic_start(best_y, problem))
        hints = jax.lax.cond(seed, lambda: feet0[j], lambda: foot_parameters(start, prob))
        run, _ = _runner(prob, jnp.where(seed, max_steps, ORTHO_MAX_STEPS))
        final, steps = polish_traced(run, (start, hints), jnp.where(seed, costs[j], jnp.inf),
                                     pick(seed, gn, _ORTHO_SOLVER), pick(seed, lm, _ORTHO_SOLVER), r0, retry=seed)
        (y_end, feet), final = final.y, final._replace(y=final.y[0])
        def at_solution():  # one Jacobian pass for the covariance and the model checks
            lin = linearise(y_end, problem, feet)
            cov = covariance(y_end, problem, T, feet, options, lin)
            # the checks read the residuals refitted with the outlines' estimated offset
            return cov, eqx.tree_at(lambda l: l.r, lin, lin.r - jnp.where(jnp.isfinite(cov[4].refit), cov[4].refit, 0.0))

        (cov, s2, step, ell, off), lin = jax.lax.cond(seed, at_solution, lambda: (nan_cov, nan_lin))
        y, ok, cost = _converged(final, problem, step)
        better = seed & (~have | (best_bad & ok) | ((best_bad == ~ok) & (cost < best_cost)))
        more = (i + 1 < S) & ~ok & seed_ok[order[jnp.minimum(i + 1, S - 1)]]
        nxt = jnp.where(seed, jnp.where(more, SEED, REFERENCE), DONE)
        return (i + seed, nxt, have | seed, jnp.where(better, ~ok, best_bad), jnp.where(better, cost, best_cost),
                pick(better, y, best_y), pick(better, final.out, best_r), pick(better, (cov, s2, ell, off), best_cov),
                total + jnp.where(seed, steps, 0), pick(seed, ref, (final.cost, y_end)), pick(better, lin, best_lin))

    init = (jnp.asarray(0, jnp.int32), jnp.where(seed_ok[order[0]], SEED, REFERENCE), jnp.asarray(False),
            jnp.asarray(True), jnp.asarray(jnp.inf), (ks[order[0]], a0), jnp.full(n_res, jnp.nan),
            (jnp.full((n_cov, n_cov), jnp.nan), jnp.asarray(jnp.nan), jnp.full(V, jnp.nan), nan_off),
            jnp.asarray(0, jnp.int32), (jnp.asarray(jnp.nan), (ks[order[0]], a0)), nan_lin)
    _, _, _, bad, _, y, r, cov, total, ref, lin = jax.lax.while_loop(lambda c: c[1] != DONE, body, init)
    return y, ~bad, total, r, cov, ref, lin


def _runner(problem: BundleProblem, max_steps: int):
    """``run((y, hints), method) -> Solved``: :func:`solve` from ``y`` with the
    closest-point parameters ``hints`` (:func:`foot_parameters` at ``y``), repeated
    from its end while stale (:func:`sorjax.core._solvers.until_fresh_traced`); what
    :func:`sorjax.core._solvers.polish_traced` polishes with.  The :class:`Solved`'s ``y``
    is the pair ``(y, feet)`` at the end: every solve starts from the closest points
    the previous one ended with (no search of its own).  Returns ``(run, r0)``, ``r0``
    zeros shaped as the residuals (the solve loops' first carry)."""

    def run(state, method):
        def once(state):
            y_end, res, n, r, stale, feet = solve(state[0], problem, max_steps=max_steps, method=method,
                                                  hints=state[1])
            return (res, r), (y_end, feet), n, stale

        (ok, r), state, steps = until_fresh_traced(once, state, (jnp.asarray(False), r0))
        return Solved(state, ok, jnp.sum(r**2), steps, r)

    r0 = jnp.zeros(problem.weights.size)
    return run, r0


def _converged(final: Solved, problem: BundleProblem, step=None):
    """``(y, ok, cost)`` of a polish: converged, or stopped by its step limit but as
    good as stationary (:data:`STATIONARY_SIGMAS`), with a finite cost (else inf).
    ``step``: :func:`step_sigmas` at ``final.y`` when the caller has it (else computed
    here, only where needed)."""
    y, cost = final.y, final.cost
    finite = jnp.isfinite(cost)
    if step is None:
        stationary = jax.lax.cond(~final.ok & finite, lambda: step_sigmas(y, problem) < STATIONARY_SIGMAS,
                                  lambda: jnp.asarray(False))
    else:
        stationary = ~final.ok & finite & (step < STATIONARY_SIGMAS)
    ok = (final.ok | stationary) & finite
    return y, ok, jnp.where(finite, cost, jnp.inf)


# A solve that stops at its step limit still counts as converged when the Gauss-Newton
# step that remains is shorter than STATIONARY_SIGMAS standard deviations of the
# estimate (the step's Mahalanobis length under Cov = s^2 (J^T J)^-1): the remaining
# change is far below the uncertainty.  Seen once in 1400 Table 1 trials (f = 700,
# sigma 1.7 px, free aspect): a flat, slightly rough valley where Gauss-Newton cycled
# and Levenberg-Marquardt crawled for 200 steps, changing the cost by 1e-9 relative.
STATIONARY_SIGMAS = 0.01


@jax.custom_jvp
def implicit_solution(y_star, problem: BundleProblem):
    """``y_star`` (a minimum of the bundle's cost for ``problem``), differentiable in
    ``problem`` by the implicit function theorem: ``dy = -H^+ d(grad_y C)`` with ``H``
    the Hessian of the cost in ``y`` (closest points held where they are at ``y_star``;
    ``H^+`` a pseudo-inverse: a masked view's and the padded chart's ignored parameters
    have zero rows).  Nothing is computed unless differentiated: the solvers' loops
    (``lax.while_loop``, which reverse mode cannot go through) stay out of the gradient
    (:func:`bundle_estimate` runs them on ``stop_gradient`` inputs)."""
    return y_star


@implicit_solution.defjvp
def _implicit_solution_jvp(primals, tangents):
    y_star, problem = primals
    dproblem = tangents[1]
    flat, unravel = jax.flatten_util.ravel_pytree(y_star)
    feet = foot_parameters(y_star, problem)

    def grad_y(f, prob):
        return jax.grad(lambda f: jnp.sum(residuals(unravel(f), prob, feet) ** 2))(f)

    H = jax.jacfwd(grad_y)(flat, problem)
    _, dg = jax.jvp(lambda p: grad_y(flat, p), (problem,), (dproblem,))
    return y_star, unravel(-jnp.linalg.pinv(0.5 * (H + H.T), hermitian=True) @ dg)


class BundleOut(eqx.Module):
    """The bundle's estimate, all arrays (pixels unless said otherwise).

    Attributes:
        y: the padded-chart parameters ``(k (4,), a (V, 2))`` (normalised units).
        K: (3, 3) the intrinsics.
        omega: (3, 3) the image of the absolute conic ``K^-T K^-1``.
        v_x, l_s: (V, 3) per-view vertex (unit) and axis (``a^2 + b^2 = 1``); NaN
            for a masked view.
        cov: (4, 4) covariance of ``(fu, fv, u0, v0)`` (px^2; inf / NaN where the
            views do not determine an intrinsic, :func:`covariance`).
        cov_offset: (4, 4) the part of ``cov`` the outlines' systematic offset
            makes (px^2; :func:`sorjax.core._covariance.offset_fit`, its prior
            :func:`sorjax.core._covariance.outline_offset`): it does not scale with the
            residuals.
        offset, offset_std: (V,) each outline's systematic offset along its outward
            normals estimated as a nuisance, and its std (px; NaN: masked); ``K`` has
            its effect removed.
        s2: the residual variance ``|r|^2 / (n - p)`` (px^2).
        cost: the sum of squared residuals (px^2).
        view_rms: (V,) each view's RMS residual over its ``N`` samples (NaN: masked).
        steps: every solver step taken (int).
        ok: the polish converged and K is finite (bool).
        evidence: the cost (px^2) by which the best camera with no perspective fits
            worse (:func:`orthographic_cost`).
        n: the number of samples counted (the sum of the weights).
        noise_ell: (V,) each view's outline noise correlation length along the curve
            (px), as the covariance's noise model took it (:mod:`sorjax.core._noise`: one
            matched to the residuals, or the view's floor's, :attr:`BundleProblem.noise_ell`).
    """

    y: tuple
    K: Float[Array, "3 3"]
    omega: Float[Array, "3 3"]
    v_x: Float[Array, "V 3"]
    l_s: Float[Array, "V 3"]
    cov: Float[Array, "4 4"]
    cov_offset: Float[Array, "4 4"]
    offset: Float[Array, " V"]
    offset_std: Float[Array, " V"]
    s2: Float[Array, ""]
    cost: Float[Array, ""]
    view_rms: Float[Array, " V"]
    steps: Array
    ok: Array
    evidence: Float[Array, ""]
    n: Float[Array, ""]
    noise_ell: Float[Array, " V"]


def pin_params(k, problem: BundleProblem):
    """The bundle's ``k`` (intrinsic chart, then any distortion coefficients) with its
    fixed intrinsics written in (:func:`pin_intrinsics`): the solution a caller reads
    is then the model's, also where a problem without ``fixed`` reads it."""
    if problem.fixed is None:
        return k
    kk, d = split_params(k, problem)
    kk = pin_intrinsics(kk, problem.fixed)
    return kk if d is None else jnp.concatenate([kk, d])


@jax.jit
def bundle_solution(points_n, used, inliers, l_n, seeds, seed_ok, aspect, T, options: Options = Options(),
                    fixed=None, base=None) -> tuple[BundleOut, Linearisation]:
    """The joint bundle, one pure function of arrays (jit, vmap over trials, grad:
    the optimum is differentiated implicitly, :func:`implicit_solution`), and the
    :class:`Linearisation` at its solution (no gradient; what the model checks read).

    Args:
        points_n: (V, M, 2) outline points in the joint normalised coordinates ``T``.
        used: (V,) bool, the views to use (the others keep their slot, masked).
        inliers: (V, N) 0/1, the samples each view's robust fit kept.
        l_n: (V, 3) the per-view fits' axes (normalised): the seeds of ``(theta, rho)``.
        seeds, seed_ok: (S, 4) intrinsic seeds ``(fu, fv, u0, v0)`` (normalised) and
            which to try (:func:`bundle_seeds`).
        aspect: known ``fu / fv`` (scalar), NaN for free.
        T: (3, 3) the normalising similarity (``x_n = T x``).
        options: :class:`sorjax.core.Options` (its static ``n_samples`` and
            ``bundle_max_steps``; under ``jax.vmap`` pass it unbatched, ``in_axes=None``).
        fixed: (4,) intrinsics held at known values, ``(fu, fv, u0, v0)`` px, NaN
            where free (OpenCV's fixed-parameter flags), or None (all free).  A fixed
            entry gets a variance of 0 in ``cov``; ``fu`` fixed needs a free aspect
            ratio (with a known one, fix ``fv``: ``fu = aspect fv``).
        base: the :class:`BundleProblem` of ``points_n`` (:func:`make_problem` with
            ``inliers`` and ``used``, no aspect ratio, nothing fixed), when the caller
            has it (one per calibration, shared by every method), or None (built here).

    Returns ``(BundleOut, Linearisation)``."""
    used = jnp.asarray(used, bool)
    T = jnp.asarray(T, jnp.float64)
    fixed_n = None if fixed is None else fixed_chart(fixed, T)
    if base is None:
        problem = make_problem(points_n, options.n_samples, aspect, inliers, used, fixed_n)
    else:
        problem = with_model(base, aspect, fixed_n)
    frozen = jax.lax.stop_gradient(problem)  # the solvers: no tangents into their loops
    y, ok, steps, r, cov, (cost_o, y_o), lin = _fit_bundle(frozen, jax.lax.stop_gradient(l_n),
                                                           jax.lax.stop_gradient(seeds), seed_ok, options,
                                                           jax.lax.stop_gradient(T))
    out, _ = _solved(y, problem, T, used, steps, ok, options, given=(cov, r))
    # the reference's cost at its solution (envelope theorem: y_o's own derivative does
    # not enter; y_o is passed, not closed over: computed_as's fn may close over no traced value)
    cost_o = computed_as(cost_o, lambda k, p, y_o: jnp.sum(residuals(y_o, orthographic_problem(k, p)) ** 2),
                         out.y[0], problem, jax.lax.stop_gradient(y_o))
    return eqx.tree_at(lambda b: b.evidence, out, cost_o / T[0, 0] ** 2 - out.cost), lin


@jax.jit
def bundle_estimate(points_n, used, inliers, l_n, seeds, seed_ok, aspect, T, options: Options = Options(),
                    fixed=None, base=None) -> BundleOut:
    """The joint bundle, one pure function of arrays (jit, vmap over trials, grad:
    the optimum is differentiated implicitly, :func:`implicit_solution`): :func:`bundle_solution`'s
    :class:`BundleOut`; arguments as there."""
    return bundle_solution(points_n, used, inliers, l_n, seeds, seed_ok, aspect, T, options, fixed, base)[0]


def _cov_s2_shift(c):
    """``(cov, s2, offsets.shift)`` of :func:`covariance`'s result."""
    return c[0], c[1], c[4].shift


def _solved(y, problem: BundleProblem, T, used, steps, ok, options: Options, given=None):
    """A solver's end ``y`` as a :class:`BundleOut` (its ``evidence`` NaN, for the
    caller to fill) and the covariance of every intrinsic parameter (px; with
    distortion the coefficients follow): the fixed entries pinned, the optimum made
    differentiable (:func:`implicit_solution`), the residuals in pixels.

    ``given``: ``((cov, s2, ell, offsets), r)``, :func:`covariance`'s ``(cov, s2, ell, offsets)`` and the
    whole-outline :func:`residuals` at ``y`` as the solver computed them (on
    ``stop_gradient`` inputs: :func:`_fit_bundle`), or None (computed here).  Given, they
    are made differentiable by :func:`sorjax.core._solvers.computed_as` instead of traced a
    second time: the same values, half the compilation."""
    y = (pin_params(y[0], problem), y[1])
    y = implicit_solution(y, problem)
    if given is None:
        cov, s2, _, ell, off = covariance(y, problem, T, None, options)
        r = residuals(y, problem)
    else:
        (cov, s2, ell, off), r = given
        cov, s2, shift = computed_as((cov, s2, off.shift), lambda y, p, T, o: _cov_s2_shift(covariance(y, p, T, None, o)),
                                     y, problem, T, options)
        off = eqx.tree_at(lambda o: o.shift, off, shift)
        r = computed_as(r, residuals, y, problem)
    ell = jax.lax.stop_gradient(ell)
    off = eqx.tree_at(lambda o: (o.cov, o.value, o.std), off, jax.lax.stop_gradient((off.cov, off.value, off.std)))
    K, omega, vx, ls = solution_in_pixels(y, problem, T)
    # the outlines' offset estimated as a nuisance (:func:`sorjax.core._covariance.offset_fit`): its effect removed
    d = off.shift[:4]
    K = intrinsics_matrix(K[0, 0] + d[0], K[1, 1] + d[1], K[0, 2] + d[2], K[1, 2] + d[3])
    omega = omega_matrix(omega_vector_from_intrinsics(K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    scale = 1.0 / T[0, 0]
    rv = r.reshape(used.shape[0], -1) * scale  # the solver's, differentiable
    nan = jnp.asarray(jnp.nan)
    out = BundleOut(
        y=y, K=K, omega=omega,
        v_x=jnp.where(used[:, None], vx, nan), l_s=jnp.where(used[:, None], ls, nan),
        cov=cov[:4, :4], cov_offset=off.cov[:4, :4], offset=jnp.where(used, off.value, nan),
        offset_std=jnp.where(used, off.std, nan), s2=s2 * scale**2, cost=jnp.sum(rv**2),
        view_rms=jnp.where(used, jnp.sqrt(jnp.mean(rv**2, axis=1)), nan),
        steps=steps, ok=ok & jnp.all(jnp.isfinite(K)), evidence=nan, n=jnp.sum(problem.weights), noise_ell=ell,
    )
    return out, cov


import jax.flatten_util  # noqa: E402  (registers the submodule used above)
