"""The per-view fit of eq. 20 as one pure function of fixed-shape arrays.

One view, in its own normalised coordinates (:mod:`sorjax.core._prepare`): find the
harmonic homology ``W(v, l)`` minimising the paper's eq. 20::

    Cost(v, l) = sum_i w_i d(W(v, l) x_i)^2

from a fixed-size set of automatic starts, all computed inside the program
(:mod:`sorjax.core._viewfit_starts`: bitangents of the convex hull, mirror symmetries
on a grid, and for a nearly conic outline the pole-polar pairs of its best-fitting
conic), ``N_STARTS`` (45) slots in all, an unused slot masked (cost infinite): the
same starts as the host code this replaces.  Every valid start is screened by
``options.screen_steps`` loose Levenberg-Marquardt steps (the valid starts compacted
to the front and screened one by one until the last valid one, so that the 36 conic
slots cost nothing unless the outline is nearly conic), the lowest cost (the first of
equal ones) is polished (Gauss-Newton, then Levenberg-Marquardt where that fails),
then up to ``options.trim_rounds`` robust rounds trim outlier samples (a handle, a
shadow) and refit from the previous optimum, until the first round with nothing to
trim (never below half of the samples).  The screen, the polish and the refits are
one while loop whose every iteration is one solve, its method, step budget, start and
weights data (:func:`_fit_loop`): the program holds one solve of eq. 20
(:func:`sorjax.core._solvers.least_squares`).

Under ``vmap`` every while loop runs until its slowest lane is done (the others
masked): a batch costs what its most demanding view needs, per loop.

Parameters of a solve (as in :mod:`sorjax._homology`): ``p = (theta, rho, d1, d2)``
with ``l = (cos theta, sin theta, -rho)`` and ``v = normalise(v0 + d1 e1 + d2 e2)``,
``e1, e2`` an orthonormal basis of the tangent plane of the unit sphere at ``v0``.

Everything here is jit / vmap (over views and over trials) clean: no host syncs, no
Python control flow on values.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._field import DistanceField
from ._symmetry import homology_matrix, symmetry_checked, symmetry_feet, symmetry_residuals
from ._noise import (estimate_noise, jacobian_and_normal_sensitivity, knot_spacing_px, noise_geometry, noise_meat,
                      sample_normals, smoothed_outline, unit_blocks)
from ._solvers import Method, improves, is_stale, least_squares, pick, solvers, until_fresh_traced
from ._options import Options
from ._prepare import Views
from ._viewfit_starts import N_STARTS as N_STARTS, automatic_starts as automatic_starts, fit_conic

_BARRIER_AT = 0.3
_BARRIER_GAIN = 100.0
_SOLVERS = solvers(rtol=1e-10, atol=1e-10)


class ViewFit(eqx.Module):
    """One view's fitted homology in its normalised coordinates (arrays only; stacks
    under vmap).

    Attributes:
        v: (3,) unit vertex.
        l: (3,) axis, ``a^2 + b^2 = 1``.
        cost: eq. 20's cost over the kept samples (normalised units^2).
        n: samples counted in ``cost`` (sum of weights over the inliers).
        cost_untrimmed, n_untrimmed: the same for the fit to all samples, before any
            trimming.
        converged: the final solve reported success.
        steps: solver steps taken (screen, polish and refits; a refit is not screened).
        inliers: (N,) samples kept by the robust rounds (weight-0 samples count in).
        infinity_z: ``|v_3| / std(v_3)`` (first order, affine invariant).
        conic_rms: RMS Sampson distance of the outline from its best conic
            (normalised units).
        noise_ell: the correlation length along the curve (px) of the outline's noise,
            as the noise model behind ``infinity_z`` read it off the residuals
            (:func:`sorjax.core._noise.estimate_noise`).
    """

    v: Float[Array, "3"]
    l: Float[Array, "3"]
    cost: Float[Array, ""]
    n: Float[Array, ""]
    cost_untrimmed: Float[Array, ""]
    n_untrimmed: Float[Array, ""]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    inliers: Bool[Array, " N"]
    infinity_z: Float[Array, ""]
    conic_rms: Float[Array, ""]
    noise_ell: Float[Array, ""]


class ViewHomologies(eqx.Module):
    """Homologies in pixels (:func:`pixel_homology` of one view, or stacked over views
    by :func:`homologies_in_pixels`; arrays only).

    ``v_x`` unit, ``l_s`` with ``a^2 + b^2 = 1``, ``W`` the homology matrix; ``rms``
    (px) and ``cost`` (px^2) over the kept samples; ``rms_untrimmed`` (px) of the fit
    to all samples; ``conic_rms`` (px); ``trimmed`` fraction of the samples;
    ``at_infinity``: ``|v_x[2]| < 1e-9`` or ``infinity_z < options.infinity_z``;
    ``is_conic``: ``conic_rms <= conic_ratio * rms + conic_floor_px``; ``noise_ell`` (px)
    the correlation length of the outline's noise read off the residuals
    (:attr:`ViewFit.noise_ell`)."""

    v_x: Float[Array, "3"]
    l_s: Float[Array, "3"]
    W: Float[Array, "3 3"]
    rms: Float[Array, ""]
    cost: Float[Array, ""]
    rms_untrimmed: Float[Array, ""]
    conic_rms: Float[Array, ""]
    trimmed: Float[Array, ""]
    infinity_z: Float[Array, ""]
    at_infinity: Bool[Array, ""]
    is_conic: Bool[Array, ""]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    inliers: Bool[Array, " N"]
    noise_ell: Float[Array, ""]


# ---------------------------------------------------------------- parameters


def _tangent_basis(v0):
    """Orthonormal (3, 2) basis of the plane orthogonal to the unit vector ``v0``."""
    a = jnp.eye(3)[jnp.argmin(jnp.abs(v0))]
    e1 = jnp.cross(v0, a)
    e1 = e1 / jnp.linalg.norm(e1)
    return jnp.stack([e1, jnp.cross(v0, e1)], axis=1)


def _unpack(p, v0, E):
    l = jnp.stack([jnp.cos(p[0]), jnp.sin(p[0]), -p[1]])
    v = v0 + E @ p[2:]
    return v / jnp.linalg.norm(v), l


def _pack(v, l):
    """Start parameters ``(p0, v0, E)`` of a homology (v, l), normalised coordinates."""
    v = v / jnp.linalg.norm(v)
    l = l / jnp.linalg.norm(l[:2])
    p = jnp.stack([jnp.arctan2(l[1], l[0]), -l[2], jnp.zeros_like(l[2]), jnp.zeros_like(l[2])])
    return p, v, _tangent_basis(v)


def _barrier(v, l):
    """The barrier residual ``100 relu(0.3 - |v.l| / |l|)`` (1,)."""
    a = jnp.abs(v @ l) / jnp.linalg.norm(l)
    return _BARRIER_GAIN * jax.nn.relu(_BARRIER_AT - a)[None]


def _residuals(p, args):
    """Eq. 20's residuals plus one barrier residual ``100 relu(0.3 - |v.l| / |l|)``
    walling off the degenerate homologies with ``v`` on the axis (see
    :mod:`sorjax._homology`)."""
    field, samples, weights, v0, E = args[:5]
    hints = args[5] if len(args) > 5 else None
    v, l = _unpack(p, v0, E)
    r = symmetry_residuals(v, l, samples, field, weights, hints)
    return jnp.concatenate([r, _barrier(v, l)])


def refine(field: DistanceField, samples, weights, p0, v0, E, max_steps, method: str | Method, hints=None):
    """Minimise eq. 20 from ``(p0, v0, E)`` with ``method`` ("lm", "gn", "screen" or a
    :class:`sorjax.core._solvers.Method`; ``max_steps`` may be traced),
    the closest points searched near ``hints`` (N,) (:func:`sorjax.core._symmetry.symmetry_feet`
    at ``p0``; None: searched here).  Returns ``(v, l, cost, converged, steps, p, r,
    stale, feet)``: ``r`` the whole-outline residuals, ``stale`` whether they differ
    from the solver's hinted ones (a screen's caller ignores it: its runs are not
    repeated), ``feet`` their closest-point parameters (the hints of a solve from ``p``):
    one pass, :func:`sorjax.core._symmetry.symmetry_checked`."""
    args = (field, samples, weights, v0, E)
    if hints is None:
        hints = symmetry_feet(*_unpack(p0, v0, E), samples, field)
    method = _SOLVERS[method] if isinstance(method, str) else method
    p, ok, steps = least_squares(_residuals, p0, args + (hints,), method, max_steps, samples.shape[0] + 1)
    v, l = _unpack(p, v0, E)
    r, feet, r_near = symmetry_checked(v, l, samples, field, weights, hints)
    stale = is_stale(r, r_near)
    cost = jnp.sum(r**2) + jnp.sum(_barrier(v, l) ** 2)
    return v, l, cost, ok, steps, p, r, stale, feet


class _Fit(eqx.Module):
    v: Array
    l: Array
    cost: Array
    ok: Array
    steps: Array
    r: Array
    feet: Array


def _compact_starts(vs, ls, valid):
    """The starts ``(vs, ls)`` (S, 3) with the valid ones moved to the front (stably:
    their order is kept; an invalid slot holds a harmless copy of the first), packed
    (:func:`_pack`): ``(p0 (S, 4), v0 (S, 3), E (S, 3, 2), n_valid)``."""
    order = jnp.argsort(~valid, stable=True)
    vs, ls, valid = vs[order], ls[order], valid[order]
    vs = jnp.where(valid[:, None], vs, vs[0])
    ls = jnp.where(valid[:, None], ls, ls[0])
    p0, v0, E = jax.vmap(_pack)(vs, ls)
    return p0, v0, E, jnp.sum(valid)


def _fit_loop(field, samples, weights, p0s, v0s, Es, n_valid, scale, options: Options):
    """The screen, the polish and the robust refits as one ``lax.while_loop`` whose
    every iteration is one solve (:func:`refine`, re-run while stale,
    :func:`sorjax.core._solvers.until_fresh_traced`), the method, step budget, start and
    weights chosen as data, so that the program holds one solve of eq. 20:

    * iterations ``0 .. n_valid - 1`` screen the compacted starts ``(p0s, v0s, Es)``,
      one each (``options.screen_steps`` loose Levenberg-Marquardt steps, closest
      points searched over the whole outline); the lowest cost (the first of equal
      ones) is polished;
    * a round of the polish: Gauss-Newton from its start, then, only where that did not
      converge or ended above the start's cost, Levenberg-Marquardt from the better of
      its end and the start (:func:`sorjax.core._solvers.polish_traced`'s rule); every
      solve starts from the closest points the previous one ended with;
    * after round 0 (every sample) and while there is something to trim (never below
      half of the samples), at most ``options.trim_rounds`` rounds refit from the
      previous optimum with the outliers (:func:`_outliers`) given zero weight.

    Returns ``(fit, keep, steps, cost_all)``: the last round's :class:`_Fit` (its cost
    NaN where no start had a finite cost), the samples it kept, every step of the
    chosen start's screen and of the polish, and round 0's cost."""
    n = samples.shape[0]
    z, zi, f = jnp.zeros((), p0s.dtype), jnp.zeros((), jnp.int32), jnp.asarray(False)
    out0 = (jnp.zeros(3), jnp.zeros(3), z, f, zi, jnp.zeros(4), jnp.zeros(n), f, jnp.zeros(n))
    screen, gn, lm = (_SOLVERS[k] for k in ("screen", "gn", "lm"))
    active = weights > 0
    keep = jnp.ones(n, bool)
    fit0 = _Fit(jnp.zeros(3), jnp.zeros(3), z, f, zi, jnp.zeros(n), jnp.zeros(n))

    def cond(c):
        return ~c["done"]

    def body(c):
        screening = c["i"] < n_valid
        s = jnp.minimum(c["i"], p0s.shape[0] - 1)
        lm_round = c["attempt"] == 1
        p_in = jnp.where(screening, p0s[s], c["p"])
        v_in = jnp.where(screening, v0s[s], c["v0"])
        E_in = jnp.where(screening, Es[s], c["E"])
        # a screened start's closest points: searched over the whole outline
        hints = jax.lax.cond(screening, lambda: symmetry_feet(*_unpack(p_in, v_in, E_in), samples, field),
                             lambda: c["feet"])
        method = pick(screening, screen, pick(lm_round, lm, gn))
        budget = jnp.where(screening, options.screen_steps, options.max_steps)
        w = jnp.where(screening, weights, weights * c["kept"])

        def once(state):
            out = refine(field, samples, w, state[0], v_in, E_in, budget, method, state[1])
            return out, (out[5], out[8]), out[4], out[7] & ~screening  # (a screen is not re-run)

        out, (p_end, feet_end), steps = until_fresh_traced(once, (p_in, hints), out0)
        cost, ok = out[2], out[3]

        # -- a screened start: the best so far (the first of equal costs)
        cost_s = jnp.where(jnp.isfinite(cost), cost, jnp.inf)
        better = screening & ((c["i"] == 0) | (cost_s < c["best_cost"]))
        best = pick(better, (cost_s, p_end, v_in, E_in, feet_end, steps),
                    (c["best_cost"], c["best_p"], c["best_v0"], c["best_E"], c["best_feet"], c["best_steps"]))
        last_screen = screening & (c["i"] + 1 >= n_valid)

        # -- a polish solve (Gauss-Newton, or its Levenberg-Marquardt fallback)
        polishing = ~screening
        improved = improves(cost, c["cost0"])
        fallback = polishing & ~lm_round & ~(ok & improved)
        round_done = polishing & ~fallback
        fit = _Fit(out[0], out[1], jnp.where(jnp.isfinite(c["cost0"]), cost, jnp.nan), ok,
                   c["round_steps"] + steps, out[6], out[8])
        trim = _outliers(fit.r * scale, active, c["kept"], options)
        trimmed = c["kept"] & ~trim
        go = jnp.any(trim) & (jnp.sum(trimmed & active) >= jnp.sum(active) // 2)
        rounds = c["round"] + round_done
        more = go & (rounds <= options.trim_rounds)
        # the next round's start: this optimum, its chart centred on it, its cost with the
        # trimmed weights (from this fit's residuals: kept and trimmed are 0 / 1)
        p_next, v_next, E_next = _pack(fit.v, fit.l)
        barrier = _BARRIER_GAIN * jax.nn.relu(_BARRIER_AT - jnp.abs(fit.v @ fit.l) / jnp.linalg.norm(fit.l))
        cost_next = jnp.sum((fit.r * trimmed) ** 2) + barrier**2

        # the start of the next solve: the polish of the best screened start, the
        # fallback from the better of the Gauss-Newton end and its start, or the next round
        start_p = jnp.where(last_screen, best[1], jnp.where(fallback & improved, p_end,
                                                            jnp.where(round_done, p_next, c["p"])))
        start_feet = jnp.where(last_screen, best[4], jnp.where(fallback & improved, feet_end,
                                                               jnp.where(round_done, fit.feet, c["feet"])))
        return dict(
            i=c["i"] + 1, done=round_done & ~more,
            best_cost=best[0], best_p=best[1], best_v0=best[2], best_E=best[3], best_feet=best[4],
            best_steps=best[5],
            p=start_p, feet=start_feet,
            v0=jnp.where(last_screen, best[2], jnp.where(round_done, v_next, c["v0"])),
            E=jnp.where(last_screen, best[3], jnp.where(round_done, E_next, c["E"])),
            cost0=jnp.where(last_screen, best[0], jnp.where(round_done, cost_next, c["cost0"])),
            attempt=jnp.where(fallback, 1, 0).astype(jnp.int32),
            round_steps=jnp.where(fallback, c["round_steps"] + steps, 0).astype(jnp.int32),
            round=rounds, kept=jnp.where(round_done, trimmed, c["kept"]),
            fit=pick(round_done, fit, c["fit"]), keep=jnp.where(round_done, c["kept"], c["keep"]),
            steps=c["steps"] + jnp.where(round_done, fit.steps, 0),
            cost_all=jnp.where(round_done & (c["round"] == 0), fit.cost, c["cost_all"]),
        )

    inf = jnp.asarray(jnp.inf, p0s.dtype)
    init = dict(
        i=zi, done=f, best_cost=inf, best_p=p0s[0], best_v0=v0s[0], best_E=Es[0], best_feet=jnp.zeros(n),
        best_steps=zi, p=p0s[0], feet=jnp.zeros(n), v0=v0s[0], E=Es[0], cost0=inf, attempt=zi, round_steps=zi,
        round=zi, kept=keep, fit=fit0, keep=keep, steps=zi, cost_all=z)
    c = jax.lax.while_loop(cond, body, init)
    return c["fit"], c["keep"], c["best_steps"] + c["steps"], c["cost_all"]


# --------------------------------------------------------------------- robust


def _outliers(r_px, active, keep, options: Options):
    """Samples among ``active & keep`` whose residual (px) exceeds ``max(trim_k s,
    trim_floor_px)``, ``s = 1.4826 median|r|`` over ``active & keep``."""
    a = jnp.abs(r_px)
    base = active & keep
    nb = jnp.sum(base)
    srt = jnp.sort(jnp.where(base, a, jnp.inf))
    lo, hi = jnp.maximum((nb - 1) // 2, 0), nb // 2
    med = 0.5 * (srt[lo] + srt[jnp.minimum(hi, a.shape[0] - 1)])
    s = 1.4826 * med
    out = active & keep & (a > jnp.maximum(options.trim_k * s, options.trim_floor_px))
    return out & (nb > 0)


def _infinity_z(field, samples, weights, v, l, feet, scale, options: Options):
    """``(z, ell)``: ``z = |v_3| / std(v_3)`` of eq. 20's fit at ``(v, l)`` in a chart centred there
    (``feet``: the closest-point parameters at ``(v, l)``; ``scale`` px per unit).
    The covariance is the sandwich of :func:`sorjax.core._covariance.covariance` for one view:
    the Jacobian read off the outline smoothed by ``options.covariance_smooth_px``,
    the residuals' covariance from the outline noise model of :mod:`sorjax.core._noise`
    (level and correlation length ``ell`` px from the residuals).  With ``s^2 (J^T J)^-1``
    instead, ``v_x``'s standard error came out about 1.6x too small on the paper's
    noise, so that views looking almost straight at the axis passed as finite
    ``v_x`` and gave a confidently wrong focal length from one view (issue 18:
    z = -7.7 at theta = 0.24 deg)."""
    p, v, E = _pack(v, l)
    n = samples.shape[0]
    res = lambda p, f, s: _residuals(p, (f, s, weights, v, E, feet))[:-1]  # noqa: E731  (no barrier)
    # one forward-mode pass: the Jacobian, the residuals and their sensitivity to the
    # samples moving along the normals
    J, r, a = jacobian_and_normal_sensitivity(lambda p, s: res(p, field, s), p, samples, sample_normals(field, n))
    sm, sm_samples = smoothed_outline(field, n, options.covariance_smooth_px, scale)
    Js = jax.jacfwd(res)(p, sm, sm_samples)
    geo = noise_geometry(a[None], weights[None], feet[None], knot_spacing_px(field, scale)[None], field.n_knots)
    ell, level = estimate_noise(geo, r[None], J, options.noise_ell_min_px, options.noise_ell_max_px)
    A = jnp.linalg.pinv(Js.T @ Js, hermitian=True)
    cov = A @ (level * noise_meat(Js, unit_blocks(geo, ell))) @ A
    var3 = E[2] @ cov[2:, 2:] @ E[2]
    return jnp.abs(v[2]) / jnp.sqrt(jnp.maximum(var3, 1e-300)), ell[0]


# ------------------------------------------------------------------- the fit


def fit_view(field: DistanceField, samples: Float[Array, "N 2"], weights: Float[Array, " N"],
             points: Float[Array, "M 2"], options: Options = Options(), init=None, scale=1.0) -> ViewFit:
    """Fit one view's harmonic homology (eq. 20) in its normalised coordinates.

    Args:
        field, samples, weights, points: the view's distance field, eq. 20's samples,
            their corner weights and the outline's points (positively oriented), all
            normalised (:func:`sorjax.core.prepare_views`, one view of it).
        options: thresholds and budgets (static).
        init: optional start ``(v, l)`` (normalised coordinates), replacing the
            automatic ones.
        scale: pixels per normalised unit (``options.trim_floor_px`` is in pixels).

    Pure: jit / vmap (views, trials) clean.
    """
    C, conic_rms = fit_conic(points)
    if init is None:
        vs, ls, valid = automatic_starts(points, samples, (C, conic_rms))
    else:
        vs, ls = (jnp.asarray(a, jnp.float64)[None] for a in init)
        valid = jnp.ones(1, bool)
    p0s, v0s, Es, n_valid = _compact_starts(vs, ls, valid)
    fit, keep, steps, cost_all = _fit_loop(field, samples, weights, p0s, v0s, Es, n_valid, scale, options)
    n_all = jnp.sum(weights)
    w = weights * keep
    z, ell = _infinity_z(field, samples, w, fit.v, fit.l, fit.feet, scale, options)
    l = fit.l / jnp.linalg.norm(fit.l[:2])
    return ViewFit(fit.v / jnp.linalg.norm(fit.v), l, fit.cost, jnp.sum(w), cost_all, n_all, fit.ok,
                   steps, keep, z, conic_rms, ell)


def fit_views(views: Views, options: Options = Options(), init=None, sequential: bool = False) -> ViewFit:
    """:func:`fit_view` of every view of ``views`` (``init`` optional ``(v, l)`` of
    shape (V, 3) each, in each view's normalised coordinates).

    ``sequential`` (static): ``jax.lax.map`` over the views instead of ``jax.vmap``.
    The results are the same (to round-off); the cost differs: a vmapped while loop
    runs until its slowest view is done, a mapped one view by view.  Measured on CPU
    (32 noisy random views, 2 busy cores): vmap 53 ms CPU per view (282 s to
    compile), map 34 ms (56 s to compile); on an accelerator vmap is the one to use."""
    if init is None:
        xs = (views.fields, views.samples, views.weights, views.points, views.scale)
        one = lambda x: fit_view(x[0], x[1], x[2], x[3], options, None, x[4])  # noqa: E731
    else:
        xs = (views.fields, views.samples, views.weights, views.points, views.scale, init[0], init[1])
        one = lambda x: fit_view(x[0], x[1], x[2], x[3], options, (x[5], x[6]), x[4])  # noqa: E731
    return jax.lax.map(one, xs) if sequential else jax.vmap(one)(xs)


def pixel_homology(fit: ViewFit, T: Float[Array, "3 3"], options: Options = Options()) -> ViewHomologies:
    """One view's fit in pixels (``T`` its normalising similarity; vmap over views):
    ``v_x = T^-1 v`` (unit), ``l_s = T^T l`` (``a^2 + b^2 = 1``), residuals in px."""
    scale = 1.0 / T[0, 0]
    v = jnp.linalg.solve(T, fit.v)
    v = v / jnp.linalg.norm(v)
    l = T.T @ fit.l
    l = l / jnp.linalg.norm(l[:2])
    cost = fit.cost * scale**2
    rms = jnp.sqrt(cost / fit.n)
    conic = fit.conic_rms * scale
    W = homology_matrix(v, l)
    return ViewHomologies(
        v_x=v, l_s=l, W=W, rms=rms, cost=cost,
        rms_untrimmed=jnp.sqrt(fit.cost_untrimmed / jnp.maximum(fit.n_untrimmed, 1.0)) * scale,
        conic_rms=conic, trimmed=jnp.mean((~fit.inliers).astype(jnp.float64)), infinity_z=fit.infinity_z,
        at_infinity=_at_infinity(v, fit.infinity_z, options), is_conic=_is_conic(conic, rms, options),
        converged=fit.converged, steps=fit.steps, inliers=fit.inliers, noise_ell=fit.noise_ell,
    )


def _at_infinity(v, z, options: Options):
    return (jnp.abs(v[..., 2]) < 1e-9) | (z < options.infinity_z)


def _is_conic(conic_rms, rms, options: Options):
    return conic_rms <= options.conic_ratio * rms + options.conic_floor_px


def with_noise_floor(homs: ViewHomologies, noise, options: Options = Options()) -> ViewHomologies:
    """``homs`` (stacked, pixels) with the verdicts that take the noise from a view's
    own residuals taken at a noise of at least ``noise`` (V,) px (a symmetry residual
    RMS, as ``rms``; 0: none): ``infinity_z`` scaled by ``rms / noise`` where the floor
    is higher (the standard error of ``v_3`` grows with the noise level), and
    ``at_infinity`` and ``is_conic`` decided again from it.  For outlines averaged with
    their own mirror image, whose residuals no longer show their noise
    (:attr:`sorjax.core._model.BundleProblem.noise`): their ``v_x`` would otherwise pass as
    finite far too easily.  ``rms`` itself is left as fitted.

    The scaling keeps the noise's correlation length that the fit read off the
    averaged outline's residuals (``noise_ell``), not the length of the noise behind
    the floor: measured on the paper's noise (1 px, two spheres at f = 700 and 1400 px,
    18 outlines; ``experiments/noise_floor.py``), the scaled ``z`` was 0.94-1.86 times
    (median 1.4) the raw outline's own,
    which errs towards a finite ``v_x``.  It decides only the only-principal-point
    verdict (every view at infinity); the bundle's covariance takes the floor's own
    length (:attr:`sorjax.core._model.BundleProblem.noise_ell`)."""
    noise = jnp.asarray(noise, jnp.float64)
    higher = noise > homs.rms
    z = homs.infinity_z * jnp.where(higher, homs.rms / jnp.where(higher, noise, 1.0), 1.0)
    return eqx.tree_at(lambda h: (h.infinity_z, h.at_infinity, h.is_conic), homs,
                       (z, _at_infinity(homs.v_x, z, options),
                        _is_conic(homs.conic_rms, jnp.maximum(homs.rms, noise), options)))


def homologies_in_pixels(views: Views, fits: ViewFit, options: Options = Options()) -> ViewHomologies:
    """:func:`pixel_homology` of every view (``fits`` from :func:`fit_views`)."""
    return jax.vmap(lambda f, T: pixel_homology(f, T, options))(fits, views.T)
