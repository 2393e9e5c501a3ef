"""The joint bundle with OpenCV's radial distortion (issue 18).

``(k1[, k2])`` about the principal point in camera-normalised coordinates join the
intrinsics (``2V + 5`` / ``2V + 6`` parameters, ``problem.n_dist``); each sample of an
observed outline is undistorted, moved by the pinhole homology and distorted again
(:func:`sorjax.core._model.distorted_transfer`), then read from the outline's own
field.  The distortion-free bundle runs first; the distorted fit is polished from its
solution and from the linear seeds (:func:`fit_distorted`), and the evidence gate
(:func:`distortion_gate`) decides whether the outlines show the distortion.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._solvers import polish_traced, traced_once
from ._options import Options
from ._model import (BundleProblem, axis_params, checked_residuals, fixed_chart, make_problem, pack_seeds, split_params,
                     with_model)
from ._bundle import (BundleOut, FALLBACK_FOCALS, _SOLVERS, _converged, _runner, _solved, bundle_estimate, solve)


# ------------------------------------------------------------ radial distortion (issue 18)

DISTORTION_MODELS = {"none": 0, "k1": 1, "k1k2": 2}  # name -> number of radial coefficients


# k1 of the seeds built from the linear estimates (:func:`distorted_seeds`): none, and
# a strong barrel distortion.  Measured on random scenes (experiments/distortion.py):
# with k1 = -0.3 the distortion-free bundle can run off to f -> infinity (no
# perspective: the distortion looks like its absence), where k1 has no effect at all
# and a polish from that solution stays there.
K1_SEEDS = (0.0, -0.25)


def distorted_seeds(y_free, l_n, used, seeds, seed_ok, n_dist: int):
    """The seeds of the bundle with distortion: the distortion-free solution
    ``y_free = (k (4,), a (V, 2))`` with zero distortion, then every intrinsic seed
    ``seeds`` (S, 4) (normalised ``(fu, fv, u0, v0)``, :func:`bundle_seeds`) with the
    per-view fits' axes ``l_n`` and ``k1`` in :data:`K1_SEEDS` (``k2 = 0``).  The
    fallback spread of :func:`bundle_seeds` (its last ``len(FALLBACK_FOCALS)`` rows) is
    tried here even where a linear seed exists: the linear methods read distorted
    outlines as a pinhole's, and a strong distortion sends all of them to a wrong
    focal length (measured: k1 = -0.3, f = 527 px, every linear seed at 5x the true
    f, each polish in the f -> infinity basin, where k1 has no effect; from the spread
    with k1 = 0 or -0.25 the polish reaches the truth).

    Returns ``((k (P, 4 + n), a (P, V, 2)), ok (P,))``, ``P = 1 + S len(K1_SEEDS)``."""
    k0, a0 = y_free
    l = jnp.where(used[:, None], jnp.asarray(l_n, jnp.float64), jnp.asarray([1.0, 0.0, 0.0]))
    al = axis_params(l)
    seed_ok = jnp.asarray(seed_ok, bool).at[-len(FALLBACK_FOCALS):].set(True)
    ks = pack_seeds(seeds, seed_ok)
    z = jnp.zeros(n_dist - 1)
    kk = [jnp.concatenate([k0, jnp.zeros(n_dist)])[None]]
    aa = [a0[None]]
    oks = [jnp.all(jnp.isfinite(k0)) & jnp.all(jnp.isfinite(a0))]
    for k1 in K1_SEEDS:
        d = jnp.concatenate([jnp.full((1,), k1), z])
        kk.append(jnp.concatenate([ks, jnp.broadcast_to(d, (ks.shape[0], n_dist))], axis=1))
        aa.append(jnp.broadcast_to(al, (ks.shape[0],) + al.shape))
        oks.append(jnp.asarray(seed_ok, bool))
    return (jnp.concatenate(kk), jnp.concatenate(aa)), jnp.concatenate([jnp.atleast_1d(o) for o in oks])


def fit_distorted(problem: BundleProblem, y_seeds, seed_ok, options: Options = Options()):
    """The bundle with distortion (``problem.n_dist = n > 0``) from the seeds ``y_seeds =
    (k (P, 4 + n), a (P, V, 2))`` that are ``seed_ok`` (:func:`distorted_seeds`): each
    seed screened by ``options.distortion_screen_steps`` loose Levenberg-Marquardt steps
    (``lax.map``), then polished from its screened end in the order of the screened
    costs (Gauss-Newton, Levenberg-Marquardt as the fallback,
    :func:`sorjax.core._solvers.polish_traced`, each solve repeated while stale, accepted at
    its step limit when as good as stationary, as :func:`fit_bundle`) until one
    converges (``lax.while_loop``).  Ranking by the cost at the seeds themselves is not
    enough: a wrong basin (f -> infinity, where k1 has no effect) is as good as
    stationary at once, while the right one's seeds need a few steps to show their
    lower cost.  Pure.

    Returns ``(y, ok, steps)``: ``y = (k (4 + n,), a (V, 2))`` the converged polish (else
    the one of lowest cost), steps of every screen and polish."""
    run, r0 = _runner(problem, options.bundle_max_steps)
    seed_ok = jnp.asarray(seed_ok, bool)

    def screened(y0):
        r0, feet0, _ = checked_residuals(y0, problem)
        y, _, n, r, _, feet = solve(y0, problem, max_steps=options.distortion_screen_steps, method="screen",
                                    hints=feet0)
        cost, cost0 = jnp.sum(r**2), jnp.sum(r0**2)
        better = jnp.isfinite(cost) & (cost <= cost0)  # (a screen that made things worse: its seed)
        y, feet = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), (y, feet), (y0, feet0))
        cost = jnp.where(better, cost, cost0)
        return (y, feet), jnp.where(jnp.isfinite(cost), cost, jnp.inf), jnp.asarray(n, jnp.int32)

    first = jax.tree_util.tree_map(lambda x: x[0], y_seeds)
    screened, shapes = traced_once(screened, first)

    def screen(args):
        y0, good = args
        skip = lambda: jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)  # noqa: E731
        out = jax.lax.cond(good, lambda: screened(y0), skip)
        return out[0], jnp.where(good, out[1], jnp.inf), out[2]

    starts, costs, screen_steps = jax.lax.map(screen, (y_seeds, seed_ok))
    P = costs.shape[0]
    order = jnp.lexsort((jnp.arange(P), costs, ~seed_ok))  # the screened costs, lowest first; ties: the first

    def cond(c):
        i, done = c[0], c[1]
        return (i < P) & ~done & seed_ok[order[jnp.minimum(i, P - 1)]]

    def body(c):
        i, _, have, best_bad, best_cost, best_y, total = c
        j = order[i]
        final, steps = polish_traced(run, jax.tree_util.tree_map(lambda x: x[j], starts), costs[j], _SOLVERS["gn"],
                                     _SOLVERS["lm"], r0)
        y, ok, cost = _converged(final._replace(y=final.y[0]), problem)
        better = ~have | (best_bad & ok) | ((best_bad == ~ok) & (cost < best_cost))
        pick = lambda new, old: jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), new, old)  # noqa: E731
        return (i + 1, ok, jnp.asarray(True), jnp.where(better, ~ok, best_bad), jnp.where(better, cost, best_cost),
                pick(y, best_y), total + steps)

    init = (jnp.asarray(0, jnp.int32), jnp.asarray(False), jnp.asarray(False), jnp.asarray(True),
            jnp.asarray(jnp.inf), jax.tree_util.tree_map(lambda x: x[order[0]], starts[0]),
            jnp.sum(screen_steps))
    _, _, _, bad, _, y, total = jax.lax.while_loop(cond, body, init)
    return y, ~bad, total


class DistortedBundleOut(eqx.Module):
    """The bundle with radial distortion (:func:`bundle_estimate_distorted`), all arrays.

    Attributes:
        fit: the :class:`BundleOut` of the fit with distortion.  Its ``K``, ``omega``,
            ``v_x``, ``l_s`` are those of the pinhole (undistorted) image; ``y = (k (4 +
            n,), a)`` with ``k``'s last ``n`` entries ``(k1[, k2])``; ``cov`` the (4, 4)
            block of ``(fu, fv, u0, v0)`` (px^2); ``s2``, ``cost``, ``view_rms`` of the
            fit's residuals (px^2, px^2, px); ``evidence`` for perspective: the cost of
            the best camera with no perspective (fitted without distortion: in that
            limit the normalised radii, so the distortion, vanish) minus this fit's
            cost (px^2).
        k: (n,) the distortion coefficients ``(k1[, k2])``: OpenCV's radial terms
            (dimensionless; camera-normalised coordinates ``K^-1 x``).
        k_std: (n,) their standard deviations (inf where the views do not determine
            them).
        cov: (4 + n, 4 + n) joint covariance of ``(fu, fv, u0, v0, k1[, k2])`` (px^2 in
            the intrinsics' block, px in the cross terms, none in ``k``'s).
        free: the :class:`BundleOut` of the distortion-free bundle (the seed).
        delta: ``free.cost - fit.cost`` (px^2): how much the distortion model lowers
            the cost, the evidence for distortion (:func:`distortion_gate`).  When the
            distortion-free bundle did not converge (a strong distortion sends it
            towards f -> infinity) its cost is taken as the lower of where it stopped
            and the cost of the best camera with no perspective (that limit).
        ok: the fit with distortion converged and its estimate is finite (bool); the
            distortion-free fit's own ``free.ok`` may be False (then the calibration
            can only use the fit with distortion, when its gate passes).
    """

    fit: BundleOut
    k: Float[Array, " n"]
    k_std: Float[Array, " n"]
    cov: Float[Array, "p p"]
    free: BundleOut
    delta: Float[Array, ""]
    ok: Array


@functools.partial(jax.jit, static_argnames=("distortion",))
def bundle_estimate_distorted(points_n, used, inliers, l_n, seeds, seed_ok, aspect, T, options: Options = Options(),
                              distortion: str = "k1", fixed=None, base=None) -> DistortedBundleOut:
    """The joint bundle with OpenCV's radial distortion, ``2V + 4 + n`` parameters
    (``n = 1`` for "k1", 2 for "k1k2"; ``2V + 3 + n`` for a known aspect ratio): each
    sample ``x`` of an observed outline is undistorted, moved by its view's homology,
    distorted again and read from the outline's own distance field
    (:func:`distorted_transfer`).  The distortion-free bundle (:func:`bundle_estimate`)
    runs first; the distorted fit is polished from its solution with zero distortion
    and from the linear seeds with k1 in :data:`K1_SEEDS`, the best kept
    (:func:`distorted_seeds`, :func:`fit_distorted`).  Pure: jit, vmap over trials (``distortion`` static,
    ``options`` unbatched), grad (implicit, :func:`implicit_solution`).

    Args: as :func:`bundle_estimate` (``points_n`` (V, M, 2) observed, i.e. distorted,
    outline points in the normalised frame ``x_n = T x``; ``T`` (3, 3) the normalising
    similarity; ``seeds`` (S, 4) normalised; ``aspect`` NaN: free), and
    ``distortion``: "k1" or "k1k2"; ``fixed`` (4,) intrinsics held fixed, px, NaN:
    free, and ``base`` the problem of ``points_n`` or None, as :func:`bundle_estimate`'s).

    Returns a :class:`DistortedBundleOut` (pixels; ``k`` dimensionless)."""
    n = DISTORTION_MODELS.get(distortion, 0)
    if n == 0:
        raise ValueError(f"distortion must be 'k1' or 'k1k2' (use bundle_estimate for none); got {distortion!r}")
    free = bundle_estimate(points_n, used, inliers, l_n, seeds, seed_ok, aspect, T, options, fixed, base=base)
    used = jnp.asarray(used, bool)
    T = jnp.asarray(T, jnp.float64)
    fixed_n = None if fixed is None else fixed_chart(fixed, T)
    pinhole = (make_problem(points_n, options.n_samples, aspect, inliers, used, fixed_n) if base is None
               else with_model(base, aspect, fixed_n))
    problem = dataclasses.replace(pinhole, n_dist=n)
    frozen = jax.lax.stop_gradient(problem)
    y_seeds, ok_seeds = distorted_seeds(jax.lax.stop_gradient(free.y), jax.lax.stop_gradient(l_n), used,
                                        jax.lax.stop_gradient(seeds), seed_ok, n)
    y, ok, steps = fit_distorted(frozen, y_seeds, ok_seeds, options)
    fit, cov = _solved(y, problem, T, used, steps, ok, options)
    y, cost = fit.y, fit.cost
    ok = fit.ok & jnp.all(jnp.isfinite(y[0]))
    fit = eqx.tree_at(lambda b: (b.ok, b.evidence), fit, (ok, free.evidence + free.cost - cost))
    k = split_params(y[0], problem)[1]
    # The distortion-free model's cost: its bundle's, or, when that did not converge (a
    # strong distortion sends it towards f -> infinity, the camera with no
    # perspective), the lower of where it stopped and that limit's cost (fmin: a NaN
    # evidence leaves the stopping cost), so that delta never overstates the evidence.
    ref = jnp.where(free.ok, free.cost, jnp.fmin(free.cost, free.cost + free.evidence))
    return DistortedBundleOut(fit=fit, k=k, k_std=jnp.sqrt(jnp.diagonal(cov)[4:]), cov=cov, free=free,
                              delta=ref - cost, ok=ok)


def distortion_gate(delta_px2, n, s_px, options: Options = Options(), z_min: float = 3.0, factor: float = 3.0):
    """``(ok, g_px, z)``: whether the outlines support the distortion model, as
    :func:`sorjax.core._assess.perspective_gate` decides for perspective.

    ``delta_px2`` the cost (px^2) by which the distortion-free bundle fits worse
    (:attr:`DistortedBundleOut.delta`) over ``n`` samples, ``s_px`` the residual standard
    deviation of the fit with distortion (``sqrt(fit.s2)``): ``g_px = sqrt(delta / n)``
    (RMS per sample) and ``z = sqrt(delta) / s_px`` (for one extra parameter and
    Gaussian residuals ``delta / s^2`` is chi-square with one degree of freedom: z = 3
    is a 3-sigma test).  ``ok`` when ``z >= z_min`` and ``g_px >= factor *
    options.outline_error_px`` (the declared systematic outline error, which the
    residuals do not show).  ``z_min`` and ``factor``: defaults as the perspective
    gate's (Options.perspective_z, perspective_factor)."""
    import dataclasses

    from ._assess import perspective_gate

    opts = dataclasses.replace(options, perspective_z=z_min, perspective_factor=factor)
    return perspective_gate(delta_px2, n, s_px, opts)
