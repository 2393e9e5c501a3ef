"""The joint, "statistically optimal" estimator the paper left as future work (Sec. 9).

The model: the image of the absolute conic ``omega`` (zero skew) and one vertex
``v_x`` per view, each view's axis following from the pole-polar relation
``l_s = omega v_x``, so that::

    W = I - 2 v l^T / (v^T l),   l = omega v,   v^T l = v^T omega v > 0 always,

and the residuals are eq. 20's for every view at once: ``d_j(W_j x_ij)`` for the
``N`` samples ``x_ij`` of view ``j``, read from the smooth signed distance field
``d_j`` of its outline; all views stacked (V N residuals).

Parameters (2V + 4 for V views, all in the calibration's normalised coordinates):

* the intrinsics ``k = (log fu, log fv, u0, v0)`` (free aspect ratio), or
  ``(log fv, u0, v0)`` with ``fu = a fv`` for a known aspect ratio ``a`` (2V + 3);
  the logarithms keep ``omega = K^-T K^-1`` positive definite on every step;
* per view, two numbers ``(theta, rho)`` that fix the pole-polar pair through its
  axis, ``l_s = (cos theta, sin theta, -rho)`` and ``v_x = omega^-1 l_s``.

The pair ``(v_x, l_s = omega v_x)`` and ``(v_x = omega^-1 l_s, l_s)`` are the same
2-parameter family for a given omega (omega is invertible), so this is the same 2V+4
model; the chart is chosen for the solver.  An outline pins its axis ``l_s`` down
tightly and its vertex loosely (the vertex moves far along the valley of the cost
when the focal length changes, most of all under weak perspective).  With the axis as
parameter that valley is nearly aligned with the intrinsics, so Levenberg-Marquardt
stops crawling: on the two-sphere scene (f = 700 and 1400, sigma 1 and 2 px, 48
solves) it took 1421 steps against 3609 with a vertex chart, and converged in every
case where the vertex chart ran into its 200-step limit.  The chart stays well
conditioned when ``v_x`` is at infinity (``v_x`` then simply has ``v_3 = 0``) and
never degenerates (``v^T l = l^T omega^-1 l > 0``).

One least-squares loop (:func:`sorjax.core._solvers.least_squares`) with Jacobians by autodiff: every seed (the linear methods' estimates with
the per-view fits' axes, or a safe spread of cameras when no linear omega is positive
definite) is ranked by its cost, the best is polished by
Gauss-Newton (Levenberg-Marquardt as the fallback; see :func:`fit_bundle`).

Radial distortion (issue 18; :func:`bundle_estimate_distorted`): OpenCV's ``(k1[, k2])``
about the principal point in camera-normalised coordinates join the intrinsics
(``2V + 5`` / ``2V + 6`` parameters, ``problem.n_dist``); each sample of an observed
outline is undistorted, moved by the pinhole homology and distorted again
(:func:`distorted_transfer`), then read from the outline's own field.  With
``n_dist = 0`` every function here traces exactly the program it did before.

Uncertainty: at the optimum, the sandwich ``F^-1 G^T Sigma_r G F^-1`` of least squares
(``G`` the intrinsics' Jacobian columns with the per-view parameters projected out,
read off the outlines smoothed by a few pixels; ``F = G^T G``), with ``Sigma_r`` the
residuals' covariance under a model of the outline noise whose level and correlation
length along the curve are estimated from the residuals (:mod:`sorjax.core._noise`), pushed
to the pixel intrinsics ``(fu, fv, u0, v0)`` through the Jacobian of that map;
intrinsics the views do not determine at all get an infinite variance (see
:func:`covariance`).
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._camera import intrinsics_matrix, omega_matrix, omega_vector_from_intrinsics
from ._camera import pixel_intrinsics as _pixel_intrinsics
from ._distortion import distort, undistort
from ._field import DistanceField, checked_distances, closest_parameter, setup, signed_distances
from ._symmetry import homology_matrix, symmetry_checked, symmetry_feet, symmetry_residuals, transfer
from ._linear import focal_from_principal_point, linear_estimates
from ._noise import (NoiseGeometry, estimate_noise, jacobian_and_normal_sensitivity, knot_spacing_px, noise_geometry,
                     noise_meat, sample_normals, smoothed_outline, unit_blocks)
from ._solvers import (NULL_RCOND, Method, Solved, computed_as, is_stale, least_squares, pick, polish_traced, solvers,
                       traced_once, until_fresh_traced)
from ._options import Options


class BundleProblem(eqx.Module):
    """Everything the bundle's residuals need besides its parameters (normalised
    coordinates): per-view fields (stacked pytree), samples (V, N, 2) and their
    weights (V, N), the known aspect ratio (NaN for free aspect), and ``n_dist``
    (static): the number of radial distortion coefficients in the model (0: the
    pinhole bundle; 1: k1; 2: k1, k2; see :func:`distorted_transfer`).

    ``fixed`` (4,): intrinsics held at known values, in the chart's units ``(log fu,
    log fv, u0, v0)`` (normalised; NaN: free; None: all free, the program traced
    before fixed parameters existed), see :func:`pin_intrinsics`.

    A view left out (masked, :func:`make_problem`) keeps its slot with all weights
    zero: its residuals are zero and its ``(theta, rho)`` have zero Jacobian columns
    (the Gauss-Newton step's truncated SVD, the damped Levenberg-Marquardt step and
    :func:`covariance`'s pseudo-inverse leave them alone; :func:`n_params` does not
    count them).

    ``noise`` (V,): each view's outline noise floor (normalised units: the RMS symmetry
    residual the outline would show, the residuals' own units; 0: none), or None (none,
    the program traced before floors existed).  An outline that was made more symmetric
    than it was measured (averaged with its own mirror image,
    :func:`sorjax._detect.symmetric_average`) no longer shows its noise in its
    residuals; every estimate of the noise level (:func:`floored_rss`) then takes a
    view's residual sum of squares as at least ``n_j noise_j^2`` (``n_j`` its samples
    counted), so that the covariance, the model checks and the solver's stopping test
    (:func:`step_sigmas`) are not told that the views are noise-free.  The cost does
    not depend on it.  The noise's level is one for all views (:func:`noise_blocks`): a
    floor on one view raises the level the others are judged at too.

    ``noise_ell`` (V,): the correlation length along the curve (px) of the noise behind
    each floor (NaN or 0: unknown), or None.  A view whose floor binds takes it as its
    noise's correlation length; otherwise it is read off the residuals
    (:func:`sorjax.core._noise.estimate_noise`), which for an averaged outline are smooth and
    read as noise correlated over tens of pixels: standard deviations about 4x too
    large (``experiments/noise_floor.py``)."""

    fields: DistanceField
    samples: Float[Array, "V N 2"]
    weights: Float[Array, "V N"]
    aspect: Float[Array, ""]
    n_dist: int = eqx.field(static=True, default=0)
    fixed: Float[Array, "4"] | None = None
    noise: Float[Array, " V"] | None = None
    noise_ell: Float[Array, " V"] | None = None

    @property
    def used(self):
        """(V,) bool: the views with any sample of non-zero weight."""
        return jnp.any(self.weights > 0, axis=-1)


def pin_intrinsics(k, fixed):
    """The chart ``k`` (4 entries ``(log fu, log fv, u0, v0)`` or 3 ``(log fv, u0,
    v0)``) with its fixed entries replaced by their values: ``fixed`` (4,) in the
    4-chart's units, NaN where free (its ``log fu`` is dropped for the 3-chart), or
    None (``k`` itself).

    OpenCV-style fixed parameters (a principal point, a focal length known): the chart
    keeps its size, and a fixed entry of ``k`` is simply ignored, so that its Jacobian
    column is exactly zero -- as the padded chart's ``k[0]`` with a known aspect ratio
    (:func:`unpack_intrinsics`): the solvers leave it alone, :func:`n_params` does not
    count it and :func:`covariance` gives the pixel intrinsics it held a variance of 0
    (a fixed value), not infinity.  ``jnp.where`` selects: with nothing fixed the
    values and derivatives are bit for bit those of ``k``."""
    if fixed is None:
        return k
    f = fixed if k.shape[-1] == 4 else fixed[1:]
    return jnp.where(jnp.isfinite(f), f, k)


def free_intrinsics(aspect, fixed):
    """(4,) bool: which of ``(fu, fv, u0, v0)`` are estimated, for a known aspect
    ratio ``aspect`` (NaN: free; ``fu = aspect fv`` otherwise) and ``fixed`` (4,) chart
    values (NaN: free; None: none fixed).  ``fu`` is free only with a free aspect ratio
    and no fixed ``fu``."""
    fixed = jnp.full(4, jnp.nan) if fixed is None else jnp.asarray(fixed)
    free = ~jnp.isfinite(fixed)
    return free.at[0].set(free[0] & ~jnp.isfinite(aspect))


def unpack_intrinsics(k, aspect, fixed=None):
    """``(fu, fv, u0, v0)`` (normalised units) from the intrinsic parameters ``k``:
    4 entries ``(log fu, log fv, u0, v0)``, or 3 ``(log fv, u0, v0)`` with
    ``fu = aspect * fv``; entries held fixed (``fixed`` (4,) chart values, NaN: free;
    :func:`pin_intrinsics`) replaced by their values.

    With 4 entries and a known ``aspect`` (not NaN), ``fu = aspect * fv`` and ``k[0]``
    is ignored: the bundle's solvers use this padded chart for both aspect models, so
    that each is compiled once (the ignored entry has a zero Jacobian column, which the
    Gauss-Newton step's truncated SVD, the damped Levenberg-Marquardt step and the
    covariance's null-space test all leave alone; see :func:`n_params`)."""
    k = pin_intrinsics(k, fixed)
    if k.shape[-1] == 4:
        fv = jnp.exp(k[1])
        known = jnp.isfinite(aspect)
        a = jnp.where(known, aspect, 1.0)  # no NaN in the unused branch (its gradient)
        return jnp.where(known, a * fv, jnp.exp(k[0])), fv, k[2], k[3]
    fv = jnp.exp(k[0])
    return aspect * fv, fv, k[1], k[2]


def split_params(k, problem):
    """``(intrinsic chart, distortion coefficients)`` of the bundle's ``k``: with
    ``problem.n_dist = n > 0`` its last ``n`` entries are ``(k1[, k2])``; with none,
    ``(k, None)``."""
    n = problem.n_dist
    return (k, None) if n == 0 else (k[:-n], k[-n:])


def n_params(y, problem) -> Float[Array, ""]:
    """The number of free parameters in ``y = (k, a)``: the intrinsics ``k`` (less the
    ignored ``k[0]`` of the padded chart when the aspect ratio is known,
    :func:`unpack_intrinsics`, and the entries held fixed, :func:`pin_intrinsics`;
    distortion coefficients included) and two per *used* view (a masked view's
    ``(theta, rho)`` touch no residual)."""
    nk = y[0].shape[-1]
    padded = nk - problem.n_dist == 4
    n_used = jnp.sum(problem.used).astype(jnp.float64)
    if problem.fixed is not None:
        n_free = jnp.sum(free_intrinsics(problem.aspect, problem.fixed)).astype(jnp.float64)
        return n_free + problem.n_dist + 2.0 * n_used
    return nk + 2.0 * n_used - (jnp.isfinite(problem.aspect).astype(jnp.float64) if padded else 0.0)


def _intrinsics(k, problem):
    """``(fu, fv, u0, v0)`` (normalised) of the bundle's ``k`` (distortion coefficients
    split off, fixed entries pinned)."""
    return unpack_intrinsics(split_params(k, problem)[0], problem.aspect, problem.fixed)


def fixed_chart(fixed_px, T):
    """The chart values ``(log fu, log fv, u0, v0)`` (normalised by the similarity ``T``,
    ``x_n = T x``: ``f_n = T[0, 0] f``, ``u0_n = T[0, 0] u0 + T[0, 2]``) of intrinsics
    held fixed, ``fixed_px`` (4,) = ``(fu, fv, u0, v0)`` in pixels with NaN where free.
    Traced; NaN stays NaN."""
    p = jnp.asarray(fixed_px, jnp.float64)
    s = T[0, 0]
    f = jnp.where(p[:2] > 0, p[:2], jnp.nan) * s
    return jnp.concatenate([jnp.log(f), jnp.stack([s * p[2] + T[0, 2], s * p[3] + T[1, 2]])])


def pack_intrinsics(fu, fv, u0, v0, free_aspect: bool):
    """The parameters ``k`` of :func:`unpack_intrinsics` from numbers (numpy, at the
    boundary: no per-op dispatch)."""
    fu, fv, u0, v0 = (float(x) for x in (fu, fv, u0, v0))
    with np.errstate(invalid="ignore", divide="ignore"):
        k = [np.log(fu), np.log(fv), u0, v0] if free_aspect else [np.log(fv), u0, v0]
    return np.array(k)  # numpy: jitted functions take it without an eager device_put


def intrinsic_params(Kn, free_aspect: bool):
    """:func:`pack_intrinsics` of a (normalised) zero-skew ``K``, 3x3."""
    Kn = np.asarray(Kn)
    return pack_intrinsics(Kn[0, 0], Kn[1, 1], Kn[0, 2], Kn[1, 2], free_aspect)


def axis_params(l) -> Float[Array, "V 2"]:
    """``(theta, rho)`` per view of homogeneous lines ``l`` (V, 3):
    ``l ~ (cos theta, sin theta, -rho)``.  numpy in, numpy out (boundary); a JAX array
    (or tracer) in gives the same in ``jax.numpy``."""
    xp = np if isinstance(l, np.ndarray) else jnp
    l = xp.asarray(l, dtype=xp.float64)
    l = l / xp.linalg.norm(l[:, :2], axis=1, keepdims=True)
    return xp.stack([xp.arctan2(l[:, 1], l[:, 0]), -l[:, 2]], axis=1)


def pack_seeds(seeds, seed_ok) -> Float[Array, "S 4"]:
    """The padded chart ``(log fu, log fv, u0, v0)`` of intrinsic seeds (S, 4)
    ``(fu, fv, u0, v0)`` (normalised units), traced; the seeds not ``seed_ok`` (and
    any non-positive focal length) give finite junk, never used."""
    seeds = jnp.asarray(seeds, jnp.float64)
    fu, fv = seeds[..., 0], seeds[..., 1]
    good = jnp.asarray(seed_ok, bool) & (fu > 0) & (fv > 0)
    logs = [jnp.where(good, jnp.log(jnp.where(good, x, 1.0)), jnp.where(seed_ok, jnp.nan, 0.0)) for x in (fu, fv)]
    rest = [jnp.where(seed_ok, seeds[..., i], 0.0) for i in (2, 3)]
    return jnp.stack(logs + rest, axis=-1)


def pole_polar_pairs(y, problem: BundleProblem):
    """Per-view ``(v_x, l_s)`` for ``y = (k, (theta, rho))``: ``l_s = (cos theta,
    sin theta, -rho)``, ``v_x = omega^-1 l_s`` (unit norm); (V, 3) each."""
    k, a = y
    omega = omega_matrix(omega_vector_from_intrinsics(*_intrinsics(k, problem)))
    l = jnp.stack([jnp.cos(a[:, 0]), jnp.sin(a[:, 0]), -a[:, 1]], axis=-1)
    v = jnp.linalg.solve(omega, l.T).T  # omega is symmetric: v_j = omega^-1 l_j
    return v / jnp.linalg.norm(v, axis=-1, keepdims=True), l


def distorted_transfer(y, problem: BundleProblem) -> Float[Array, "V N 2"]:
    """Each sample moved by its view's symmetry in the distorted image (normalised
    units), for a problem with distortion (``problem.n_dist > 0``)::

        x' = D(W u),   u = D^-1(x),   D(u) = K' d(K'^-1 u)

    ``x`` a sample of the observed (distorted) outline, ``D`` the radial distortion
    :func:`sorjax.core._distortion.distort` about the principal point in camera-normalised
    coordinates ``K'^-1 u`` (``K' = T K`` the intrinsics in the bundle's normalised
    frame: the similarity ``T`` cancels, and the coefficients are those of pixels),
    ``D^-1`` its Newton inverse, ``W`` the homology of the pinhole (undistorted) image.
    A masked view is mapped with zero distortion (its weights are zero; no NaN from its
    placeholder outline)."""
    d = split_params(y[0], problem)[1]
    Kn = intrinsics_matrix(*_intrinsics(y[0], problem))
    v, l = pole_polar_pairs(y, problem)
    dv = jnp.where(problem.used[:, None], d, 0.0)

    def one(v, l, x, d):
        return distort(transfer(homology_matrix(v, l), undistort(x, Kn, d)), Kn, d)

    return jax.vmap(one)(v, l, problem.samples, dv)


def residuals(y, problem: BundleProblem, hints=None) -> Float[Array, " VN"]:
    """Stacked eq.-20 residuals of all views (normalised units) for ``y = (k, a)``;
    ``hints`` (V, N): closest-point parameters to search near (:func:`foot_parameters`
    of a nearby ``y``), or None to search each whole outline.  With distortion
    (``problem.n_dist > 0``) each sample is moved by :func:`distorted_transfer` and read
    from its outline's own (distorted) distance field."""
    if problem.n_dist:
        x = distorted_transfer(y, problem)
        if hints is None:
            r = jax.vmap(signed_distances)(problem.fields, x)
        else:
            r = jax.vmap(signed_distances)(problem.fields, x, hints)
        return (r * problem.weights).reshape(-1)
    v, l = pole_polar_pairs(y, problem)
    if hints is None:
        r = jax.vmap(symmetry_residuals)(v, l, problem.samples, problem.fields, problem.weights)
    else:
        r = jax.vmap(symmetry_residuals)(v, l, problem.samples, problem.fields, problem.weights, hints)
    return r.reshape(-1)


def checked_residuals(y, problem: BundleProblem, hints=None):
    """:func:`residuals` at the end of a solve that searched closest points near
    ``hints`` (V, N), in one pass (:func:`sorjax.core._field.checked_distances`): ``(r, feet,
    r_near)``, the whole-outline residuals (VN,), their closest-point parameters (V, N)
    (:func:`foot_parameters`: the next solve's hints) and the residuals searched near
    ``hints`` (None: ``r`` again)."""
    if problem.n_dist:
        x = distorted_transfer(y, problem)
        d, t, d_near = jax.vmap(checked_distances, in_axes=(0, 0, None if hints is None else 0))(problem.fields, x,
                                                                                                   hints)
        w = problem.weights
        return (d * w).reshape(-1), t, (d_near * w).reshape(-1)
    v, l = pole_polar_pairs(y, problem)
    r, t, r_near = jax.vmap(symmetry_checked, in_axes=(0, 0, 0, 0, 0, None if hints is None else 0))(
        v, l, problem.samples, problem.fields, problem.weights, hints)
    return r.reshape(-1), t, r_near.reshape(-1)


def foot_parameters(y, problem: BundleProblem) -> Float[Array, "V N"]:
    """Per view and sample, the parameter of the outline's point closest to the
    transferred sample ``W_j x_ij`` (knot units; whole-outline search, no gradient;
    with distortion the sample of :func:`distorted_transfer`)."""
    if problem.n_dist:
        x = distorted_transfer(y, problem)
        return jax.vmap(lambda f, x: jax.vmap(closest_parameter, in_axes=(None, 0))(f, x))(problem.fields, x)
    v, l = pole_polar_pairs(y, problem)
    return jax.vmap(symmetry_feet)(v, l, problem.samples, problem.fields)


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


@jax.jit
def solution_in_pixels(y, problem: BundleProblem, T):
    """``(K, omega, v_x, l_s)`` in pixels for the parameters ``y`` (normalised by the
    similarity ``T``): ``K = T^-1 K'``, unit ``v_x`` and ``l_s = omega v_x`` with
    ``a^2 + b^2 = 1``, one row per view."""
    K = jnp.linalg.solve(T, intrinsics_matrix(*_intrinsics(y[0], problem)))
    Ki = jnp.linalg.inv(K)
    v, l = pole_polar_pairs(y, problem)
    vx = v @ jnp.linalg.inv(T).T
    ls = l @ T
    return (K, Ki.T @ Ki, vx / jnp.linalg.norm(vx, axis=1, keepdims=True),
            ls / jnp.linalg.norm(ls[:, :2], axis=1, keepdims=True))


NULL_EIGENVALUE = NULL_RCOND**2  # 1e-12: the Gauss-Newton polish takes no step where this calls null


def pixel_params(k, problem: BundleProblem, T):
    """The pixel intrinsics ``(fu, fv, u0, v0)`` of the chart ``k`` (normalised by the
    similarity ``T``), followed by the distortion coefficients ``(k1[, k2])`` when the
    problem has them (dimensionless: the same in every frame)."""
    d = split_params(k, problem)[1]
    p = _pixel_intrinsics(T, *_intrinsics(k, problem))
    return p if d is None else jnp.concatenate([p, d])


def residual_jacobian(y, problem: BundleProblem, feet=None, normals: bool = False):
    """``(J, r, feet)`` at ``y``: the Jacobian of the stacked residuals
    (:func:`residuals`) with respect to ``y`` flattened (``k`` first, then each view's
    ``(theta, rho)``), the residuals (normalised units) and the closest-point
    parameters they read (:func:`foot_parameters`; searched once here unless given),
    held fixed as hints for both.

    ``normals`` (static): also return ``a`` (V, N), each weighted residual's
    sensitivity to its own sample moving along the outline's outward normal (what
    :func:`noise_geometry_at` reads), as one more column of the same forward-mode pass:
    ``(J, r, feet, a)``.  One traced evaluation of the residuals instead of three."""
    flat, unravel = jax.flatten_util.ravel_pytree(y)
    if feet is None:
        feet = foot_parameters(y, problem)  # searched once; exact hints for J, r and the mirror pairs
    def res(f, samples):
        return residuals(unravel(f), eqx.tree_at(lambda q: q.samples, problem, samples), feet)

    if normals:
        J, r, a = jacobian_and_normal_sensitivity(res, flat, problem.samples, problem_normals(problem))
        return J, r, feet, a.reshape(problem.weights.shape)
    J, r = jax.jacfwd(lambda f: (res(f, problem.samples),) * 2, has_aux=True)(flat)  # r from the same pass
    return J, r, feet


class Linearisation(eqx.Module):
    """The bundle's residuals at a solution and their Jacobian in an extended chart:
    what the covariance and every model check read (:func:`linearise`), one
    forward-mode pass instead of one per reader.

    Attributes:
        J: (V N, 5 + 4 V) the Jacobian of the residuals (normalised units) with respect
            to, in order: the intrinsic chart ``(log fu, log fv, u0, v0)`` with nothing
            held fixed (a known aspect ratio still ignores ``log fu``), the radial
            distortion ``k1`` at 0 (the first order of :func:`distorted_transfer`), each
            view's axis ``(theta, rho)``, and each view's vertex moved along two
            directions orthogonal to it (the homology released from the pole-polar
            constraint, :func:`sorjax.core._checks.view_scores`).
        r: (V N,) the residuals (searched near ``feet``).
        a: (V, N) each weighted residual's sensitivity to its own sample moving along
            the outline's outward normal (the noise model's geometry,
            :func:`noise_geometry_at`).
        feet: (V, N) the closest-point parameters the residuals read.
    """

    J: Float[Array, "VN P"]
    r: Float[Array, " VN"]
    a: Float[Array, "V N"]
    feet: Float[Array, "V N"]


#: the columns of :attr:`Linearisation.J`: the intrinsic chart, k1, then per view
LIN_K, LIN_K1, LIN_VIEWS = slice(0, 4), 4, 5


def lin_axis_columns(V: int):
    """(V, 2) the columns of each view's ``(theta, rho)`` in :attr:`Linearisation.J`."""
    return LIN_VIEWS + jnp.arange(2 * V).reshape(V, 2)


def lin_vertex_columns(V: int):
    """(V, 2) the columns of each view's two vertex directions in :attr:`Linearisation.J`."""
    return LIN_VIEWS + 2 * V + jnp.arange(2 * V).reshape(V, 2)


def _vertex_basis(v):
    """Two unit vectors orthogonal to ``v`` (3,) and to each other."""
    e = jnp.eye(3)[jnp.argmin(jnp.abs(v))]
    b1 = jnp.cross(v, e)
    b1 = b1 / jnp.linalg.norm(b1)
    return b1, jnp.cross(v, b1)


def linearise(y, problem: BundleProblem, feet=None) -> Linearisation:
    """:class:`Linearisation` of the pinhole bundle's residuals at ``y = (k (4,), a (V,
    2))`` (``problem.n_dist == 0``; its fixed intrinsics are written into ``k`` and then
    released: their columns are those of free parameters, for the check of the values
    held, :func:`sorjax.core._checks.fixed_release`; a reader of the fitted model
    zeroes them).  ``feet``: :func:`foot_parameters` at ``y`` when the caller has them
    (else searched here).

    The distortion column is the derivative at ``k1 = 0`` of :func:`distorted_transfer`
    (``x' = D(W D^-1(x))``): ``D(u) = u + k1 delta(u) + O(k1^2)`` with ``delta(u) =
    distort(u, K, 1) - u``, so ``x' = W(x - k1 delta(x)) + k1 delta(W x) + O(k1^2)``.
    The vertex columns move ``v_x`` along :func:`_vertex_basis` (its scale does not
    change the homology), which with the axis columns spans the release of the view's
    homology from the pole-polar constraint."""
    k, a = y
    k = pin_intrinsics(k, problem.fixed)
    free = dataclasses.replace(problem, fixed=None)
    if feet is None:
        feet = foot_parameters((k, a), free)
    V = a.shape[0]
    p0 = jnp.concatenate([k, jnp.zeros(1, k.dtype), a.reshape(-1), jnp.zeros(2 * V, k.dtype)])
    v_basis = jax.lax.stop_gradient(jax.vmap(_vertex_basis)(pole_polar_pairs((k, a), free)[0]))
    ones = jnp.ones(1, k.dtype)

    def res(p, samples):
        kk, e, aa, dv = p[:4], p[4], p[5:5 + 2 * V].reshape(V, 2), p[5 + 2 * V:].reshape(V, 2)
        Kn = intrinsics_matrix(*unpack_intrinsics(kk, problem.aspect))
        v, l = pole_polar_pairs((kk, aa), free)
        v = v + dv[:, :1] * v_basis[0] + dv[:, 1:] * v_basis[1]

        def one(v, l, x, field, w, h):
            delta = lambda u: distort(u, Kn, ones) - u  # noqa: E731
            xt = transfer(homology_matrix(v, l), x - e * delta(x))
            return signed_distances(field, xt + e * delta(xt), h) * w

        return jax.vmap(one)(v, l, samples, problem.fields, problem.weights, feet).reshape(-1)

    J, r, sens = jacobian_and_normal_sensitivity(res, p0, problem.samples, problem_normals(problem))
    return Linearisation(J=J, r=r, a=sens.reshape(problem.weights.shape), feet=feet)


def problem_normals(problem: BundleProblem) -> Float[Array, "V N 2"]:
    """The outward unit normals of the outlines at their samples."""
    return jax.vmap(lambda f: sample_normals(f, problem.samples.shape[1]))(problem.fields)


def project_out(A, B):
    """``A - B (B^T B)^+ B^T A``: the columns of ``A`` with the span of ``B``'s columns
    projected out (the information on ``A``'s parameters once ``B``'s are fitted is
    ``G^T G`` of the result, a Schur complement)."""
    return A - B @ (jnp.linalg.pinv(B.T @ B, hermitian=True) @ (B.T @ A))


@jax.jit
def covariance(y, problem: BundleProblem, T, feet=None, options: Options = Options(), lin=None):
    """Covariance of the pixel intrinsics ``(fu, fv, u0, v0)`` at ``y`` (followed by
    ``(k1[, k2])`` with distortion, :func:`pixel_params`); returns
    ``(cov, s2, step, ell)`` with ``s2 = |r|^2 / (VN - p)`` (normalised units^2;
    each view's share at least its noise floor, :func:`floored_rss`),
    ``step`` the Gauss-Newton step's Mahalanobis length (:func:`step_sigmas`) and
    ``ell`` (V,) each view's outline noise correlation length (px, :mod:`sorjax.core._noise`).

    The sandwich ``F^-1 G^T Sigma_r G F^-1`` of least squares, with
    ``Sigma_r`` the residuals' covariance under the outline noise model of
    :mod:`sorjax.core._noise` (its level and correlation length estimated from the
    residuals; where a view's noise floor binds, its floor's length,
    :attr:`BundleProblem.noise_ell`) and ``G`` the intrinsics' columns of the Jacobian with the per-view
    pole-polar pairs' directions projected out, ``F = G^T G`` (the Schur complement
    ``J_k^T J_k - J_k^T J_a (J_a^T J_a)^-1 J_a^T J_k``: the information on the
    intrinsics ``k`` once the pairs ``a`` are fitted, whatever chart they are fitted
    in), in the parameters ``(log fu, log fv, u0, v0)``, all of order one, so that
    its eigenvalues compare directly.

    ``G`` (and the noise model's geometry) is taken on the outlines smoothed by a
    Gaussian of ``options.covariance_smooth_px`` px along the curve: the noise tilts
    each target's normal, and a Jacobian read off the noisy normals overstates the
    information (measured: two-sphere scene, the paper's noise at sigma 1 px, the
    standard deviations 0.89x the RMS error with the noisy Jacobian, 0.93x smoothed by
    6 px, 0.96x with the noise-free outlines' Jacobian; RMS error and residuals are
    those of the unsmoothed outlines).

    A direction with eigenvalue below ``NULL_EIGENVALUE`` times the largest is not
    determined by the views at all (e.g. the focal length when every ``v_x`` is at
    infinity): the pixel intrinsics that move along it get an *infinite* variance
    (their covariances with the others NaN) -- a pseudo-inverse would silently give
    them zero variance instead.

    ``feet``: :func:`foot_parameters` at ``y`` when the caller has it (a solver's
    end), else None (searched here).  ``lin``: the :class:`Linearisation` at ``y`` (the
    pinhole bundle's; the Jacobian, residuals and ``feet`` are read from it), or None
    (computed here)."""
    nk = y[0].shape[0]
    if lin is None:
        J, r, feet = residual_jacobian(y, problem, feet)
    else:
        held = jnp.zeros(4, bool) if problem.fixed is None else jnp.isfinite(problem.fixed)
        V = problem.weights.shape[0]
        J = jnp.concatenate([jnp.where(held, 0.0, lin.J[:, LIN_K]), lin.J[:, LIN_VIEWS:LIN_VIEWS + 2 * V]], axis=1)
        r, feet = lin.r, lin.feet
    s2 = residual_variance(r, y, problem)
    step = _step_length(J, r, s2)
    scale = 1.0 / T[0, 0]
    smooth = smoothed_problem(problem, options.covariance_smooth_px, scale)
    Js, _, feet_s, a_s = residual_jacobian(y, smooth, normals=True)
    # the intrinsics' columns with the per-view parameters' directions projected out
    G = project_out(Js[:, :nk], Js[:, nk:])
    F = G.T @ G  # = the Schur complement J_k^T J_k - J_k^T J_a (J_a^T J_a)^-1 J_a^T J_k
    lam, U = jnp.linalg.eigh(0.5 * (F + F.T))
    null = lam <= NULL_EIGENVALUE * jnp.max(jnp.abs(lam))
    F_inv = (U * jnp.where(null, 0.0, 1.0 / jnp.where(null, 1.0, lam))) @ U.T
    geo = noise_geometry_at(smooth, feet_s, scale, a_s)
    ell, level = estimate_noise(geo, r.reshape(geo.a.shape), J, options.noise_ell_min_px, options.noise_ell_max_px,
                                floor=view_floors(problem), floor_ell=problem.noise_ell)
    meat = level * noise_meat(G, unit_blocks(geo, ell))
    cov_k = F_inv @ meat @ F_inv

    Gk = jax.jacfwd(lambda k: pixel_params(k, problem, T))(y[0])
    cov = Gk @ cov_k @ Gk.T
    GU = Gk @ U  # (4 [+ n_dist], nk): each pixel intrinsic along each eigenvector
    leak = jnp.sum(jnp.where(null[None, :], GU**2, 0.0), axis=1)
    undetermined = leak > 1e-8 * jnp.sum(GU**2, axis=1)
    bad = undetermined[:, None] | undetermined[None, :]
    cov = jnp.where(bad, jnp.nan, cov)
    cov = jnp.where(jnp.eye(cov.shape[0], dtype=bool) & bad, jnp.inf, cov)
    return cov, s2, step, ell


def noise_blocks(problem: BundleProblem, feet, T, ell, s2, a) -> Float[Array, "V N N"]:
    """The residuals' covariance per view (normalised units^2) under the outline noise
    model (:mod:`sorjax.core._noise`) with correlation length ``ell`` px, one or (V,) one per
    view (the bundle's, :attr:`BundleOut.noise_ell`), its level from the residual variance
    ``s2`` of the model fitted at ``y``: ``sigma_n^2 = s2 n / tr S`` (``n`` samples
    counted), ``a`` as for :func:`noise_geometry_at`.  What the model checks weigh
    their scores with."""
    geo = noise_geometry_at(problem, feet, 1.0 / T[0, 0], a)
    S = unit_blocks(geo, ell)
    tr = jnp.sum(jnp.trace(S, axis1=1, axis2=2))
    return S * (s2 * jnp.sum(problem.weights) / jnp.maximum(tr, 1e-300))


def view_floors(problem: BundleProblem):
    """(V,) each view's residual sum of squares floor ``n_j noise_j^2`` (normalised
    units^2; ``n_j`` the sum of its weights), or None without floors."""
    if problem.noise is None:
        return None
    return jnp.sum(problem.weights, axis=1) * problem.noise**2


def floored_rss(r, problem: BundleProblem):
    """The residual sum of squares ``sum_j max(|r_j|^2, n_j noise_j^2)`` of the
    residuals ``r`` ((V N,) or (V, N)), each view's at least its noise floor
    (:attr:`BundleProblem.noise`; ``n_j`` the sum of its weights); ``|r|^2`` without
    floors."""
    rss = jnp.sum(jnp.reshape(r, problem.weights.shape) ** 2, axis=1)
    if problem.noise is None:
        return jnp.sum(rss)
    return jnp.sum(jnp.maximum(rss, view_floors(problem)))


def residual_variance(r, y, problem: BundleProblem, n_fixed=0):
    """``s^2 = |r|^2 / (n - p)``: the residual variance of a fit with ``p`` parameters
    (:func:`n_params`, less ``n_fixed`` held ones) to ``n`` weighted samples, each
    view's residuals counted as at least its noise floor (:func:`floored_rss`)."""
    dof = jnp.maximum(jnp.sum(problem.weights) - (n_params(y, problem) - n_fixed), 1)
    return floored_rss(r, problem) / dof


def _step_length(J, r, s2):
    """The Gauss-Newton step's Mahalanobis length ``sqrt(r^T J (J^T J)^+ J^T r) / s``."""
    g = J.T @ r
    return jnp.sqrt(jnp.maximum(g @ jnp.linalg.pinv(J.T @ J, hermitian=True) @ g, 0.0) / jnp.maximum(s2, 1e-300))


def smoothed_problem(problem: BundleProblem, smooth_px, scale) -> BundleProblem:
    """``problem`` with every outline smoothed along the curve by a Gaussian of
    ``smooth_px`` px (``scale`` px per normalised unit,
    :func:`sorjax.core._noise.smoothed_outline`): new fields and samples, the same weights.
    What :func:`covariance` reads the Jacobian from."""
    N = problem.samples.shape[1]
    fields, samples = jax.vmap(lambda f: smoothed_outline(f, N, smooth_px, scale))(problem.fields)
    return dataclasses.replace(problem, fields=fields, samples=samples)


def noise_geometry_at(problem: BundleProblem, feet, scale, a) -> NoiseGeometry:
    """The outline noise model's geometry (:class:`sorjax.core._noise.NoiseGeometry`) of
    the residuals with closest-point parameters ``feet`` (V, N): ``a`` (V, N), each
    weighted residual's sensitivity to its own sample moving along the outward normal
    (:func:`residual_jacobian` with ``normals=True``), the weights and the arc lengths
    (``scale`` px per normalised unit)."""
    M = problem.fields.knots.shape[1]
    spacing = jax.vmap(lambda f: knot_spacing_px(f, scale))(problem.fields)
    return noise_geometry(a.reshape(problem.weights.shape), problem.weights, feet, spacing, M)


def _placeholder_outline(m: int):
    """A unit circle of ``m`` points: what a masked view's field is built on (its
    own points may hold anything, NaN included), all its weights zero."""
    t = jnp.arange(m) * (2.0 * jnp.pi / m)
    return jnp.stack([jnp.cos(t), jnp.sin(t)], axis=-1)


def make_problem(points_n, n_samples: int, aspect=None, inliers=None, used=None, fixed=None,
                 noise=None, noise_ell=None) -> BundleProblem:
    """The :class:`BundleProblem` of (V, M, 2) normalised outline points: fields,
    ``n_samples`` samples per view (:func:`sorjax.core._field.setup`), their corner weights
    times the optional (V, N) 0/1 ``inliers`` mask and the (V,) bool ``used`` mask (a
    masked view keeps its slot: a placeholder field, all weights zero); ``aspect`` the
    known ``fu / fv``, NaN or None (free); ``fixed`` (4,) the chart values of intrinsics
    held fixed (:func:`fixed_chart`; NaN: free) or None; ``noise`` (V,) the views' noise
    floors (normalised units; :attr:`BundleProblem.noise`) or None; ``noise_ell`` (V,)
    their correlation lengths (px; :attr:`BundleProblem.noise_ell`) or None.

    Pure (jit / vmap / grad); nothing is kept between calls: a caller that needs the
    problem twice builds it once and passes it on."""
    pts = jnp.asarray(points_n, jnp.float64)
    V, M = pts.shape[:2]
    used = jnp.ones(V, bool) if used is None else jnp.asarray(used, bool)
    inl = jnp.ones((V, n_samples)) if inliers is None else jnp.asarray(inliers, jnp.float64)
    a = jnp.asarray(jnp.nan if aspect is None else aspect, jnp.float64)
    problem = _build_problem(pts, used, inl, a, n_samples)
    return dataclasses.replace(problem, fixed=None if fixed is None else jnp.asarray(fixed, jnp.float64),
                               noise=None if noise is None else jnp.asarray(noise, jnp.float64),
                               noise_ell=None if noise_ell is None else jnp.asarray(noise_ell, jnp.float64))


def with_model(base: BundleProblem, aspect, fixed=None) -> BundleProblem:
    """``base`` (:func:`make_problem` of some outlines, no aspect ratio, nothing fixed)
    with the known aspect ratio ``aspect`` (NaN: free) and the chart values ``fixed``
    (:func:`fixed_chart`; None: nothing fixed): one problem's fields, samples, weights
    and noise floors serve every model of a calibration."""
    a = jnp.asarray(jnp.nan if aspect is None else aspect, jnp.float64)
    return dataclasses.replace(base, aspect=a, fixed=None if fixed is None else jnp.asarray(fixed, jnp.float64))


@functools.partial(jax.jit, static_argnames=("n_samples",))
def _build_problem(pts, used, inliers, aspect, n_samples: int) -> BundleProblem:
    pts = jnp.where(used[:, None, None], pts, _placeholder_outline(pts.shape[1]))
    fields, samples, weights = jax.vmap(lambda p: setup(p, n_samples))(pts)
    weights = weights * inliers * used[:, None].astype(weights.dtype)
    return BundleProblem(fields, samples, weights, aspect)


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
    """:func:`fit_bundle`, :func:`covariance`'s ``(cov, s2, ell)`` (``T`` the normalising
    similarity) at the ``y`` returned, and the no-perspective reference fit from it
    (:func:`orthographic_cost`).

    One ``lax.while_loop`` whose rounds are the seeds, polished in turn until one
    converges, then the reference: its problem (:func:`orthographic_problem`), start,
    method and step budget are data, so the program holds one traced solve
    (:func:`sorjax.core._solvers.polish_traced`) for both.  Every polished seed's
    covariance is computed in the loop (its Gauss-Newton step is the stationarity test
    of :func:`_converged`), so that the bundle's program holds one covariance, not two.
    ``(cov, s2, ell)`` is NaN when no seed was tried (never: :func:`bundle_seeds` always
    gives one).  Returns ``(y, ok, steps, residuals, (cov, s2, ell), (cost_o, y_o), lin)``:
    ``cost_o`` the reference's cost (normalised units^2) at its solution ``y_o`` (the
    chart of :func:`orthographic_problem` at ``y``); ``steps`` counts the seeds' steps;
    ``lin`` the :class:`Linearisation` at ``y`` that the covariance read (the model
    checks read it too)."""
    max_steps = options.bundle_max_steps
    problem = with_fixed(problem)
    used = problem.used
    l = jnp.where(used[:, None], jnp.asarray(l_seeds_n, jnp.float64), jnp.asarray([1.0, 0.0, 0.0]))
    a0 = axis_params(l)
    seed_ok = jnp.asarray(seed_ok, bool)
    ks = pack_seeds(seeds, seed_ok)
    r0, feet0, _ = jax.vmap(lambda k: checked_residuals((k, a0), problem))(ks)  # feet0: each seed's hints
    costs = jnp.sum(r0**2, axis=1)
    costs = jnp.where(jnp.isfinite(costs), costs, jnp.inf)
    S = ks.shape[0]
    # the seeds to try first, by cost (ties: the first given); the others last
    order = jnp.lexsort((jnp.arange(S), costs, ~seed_ok))
    r0 = jnp.zeros(problem.weights.size)
    n_res, V = problem.weights.size, problem.weights.shape[0]
    n_cov = 4 + problem.n_dist
    gn, lm = _SOLVERS["gn"], _SOLVERS["lm"]
    SEED, REFERENCE, DONE = 0, 1, 2
    nan_cov = (jnp.full((n_cov, n_cov), jnp.nan), jnp.asarray(jnp.nan), jnp.asarray(jnp.nan), jnp.full(V, jnp.nan))
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
            return covariance(y_end, problem, T, feet, options, lin), lin

        (cov, s2, step, ell), lin = jax.lax.cond(seed, at_solution, lambda: (nan_cov, nan_lin))
        y, ok, cost = _converged(final, problem, step)
        better = seed & (~have | (best_bad & ok) | ((best_bad == ~ok) & (cost < best_cost)))
        more = (i + 1 < S) & ~ok & seed_ok[order[jnp.minimum(i + 1, S - 1)]]
        nxt = jnp.where(seed, jnp.where(more, SEED, REFERENCE), DONE)
        return (i + seed, nxt, have | seed, jnp.where(better, ~ok, best_bad), jnp.where(better, cost, best_cost),
                pick(better, y, best_y), pick(better, final.out, best_r), pick(better, (cov, s2, ell), best_cov),
                total + jnp.where(seed, steps, 0), pick(seed, ref, (final.cost, y_end)), pick(better, lin, best_lin))

    init = (jnp.asarray(0, jnp.int32), jnp.where(seed_ok[order[0]], SEED, REFERENCE), jnp.asarray(False),
            jnp.asarray(True), jnp.asarray(jnp.inf), (ks[order[0]], a0), jnp.full(n_res, jnp.nan),
            (jnp.full((n_cov, n_cov), jnp.nan), jnp.asarray(jnp.nan), jnp.full(V, jnp.nan)),
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


def step_sigmas(y, problem: BundleProblem):
    """Mahalanobis length of the Gauss-Newton step at ``y``:
    ``sqrt(r^T J (J^T J)^+ J^T r) / s`` with ``s^2 = |r|^2 / (n - p)``
    (:func:`residual_variance`, the views' noise floors included)."""
    J, r, _ = residual_jacobian(y, problem)
    return _step_length(J, r, residual_variance(r, y, problem))


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


def _solved(y, problem: BundleProblem, T, used, steps, ok, options: Options, given=None):
    """A solver's end ``y`` as a :class:`BundleOut` (its ``evidence`` NaN, for the
    caller to fill) and the covariance of every intrinsic parameter (px; with
    distortion the coefficients follow): the fixed entries pinned, the optimum made
    differentiable (:func:`implicit_solution`), the residuals in pixels.

    ``given``: ``((cov, s2, ell), r)``, :func:`covariance`'s ``(cov, s2, ell)`` and the
    whole-outline :func:`residuals` at ``y`` as the solver computed them (on
    ``stop_gradient`` inputs: :func:`_fit_bundle`), or None (computed here).  Given, they
    are made differentiable by :func:`sorjax.core._solvers.computed_as` instead of traced a
    second time: the same values, half the compilation."""
    y = (pin_params(y[0], problem), y[1])
    y = implicit_solution(y, problem)
    if given is None:
        cov, s2, _, ell = covariance(y, problem, T, None, options)
        r = residuals(y, problem)
    else:
        (cov, s2, ell), r = given
        cov, s2 = computed_as((cov, s2), lambda y, p, T, o: covariance(y, p, T, None, o)[:2], y, problem, T, options)
        r = computed_as(r, residuals, y, problem)
    ell = jax.lax.stop_gradient(ell)
    K, omega, vx, ls = solution_in_pixels(y, problem, T)
    scale = 1.0 / T[0, 0]
    rv = r.reshape(used.shape[0], -1) * scale  # the solver's, differentiable
    nan = jnp.asarray(jnp.nan)
    out = BundleOut(
        y=y, K=K, omega=omega,
        v_x=jnp.where(used[:, None], vx, nan), l_s=jnp.where(used[:, None], ls, nan),
        cov=cov[:4, :4], s2=s2 * scale**2, cost=jnp.sum(rv**2),
        view_rms=jnp.where(used, jnp.sqrt(jnp.mean(rv**2, axis=1)), nan),
        steps=steps, ok=ok & jnp.all(jnp.isfinite(K)), evidence=nan, n=jnp.sum(problem.weights), noise_ell=ell,
    )
    return out, cov


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


@functools.partial(jax.jit, static_argnames=("n_samples",))
def linearised_covariance(points_n, used, inliers, l_n, K, T, aspect, n_samples: int, base=None,
                          options: Options = Options()):
    """Covariance of ``(fu, fv, u0, v0)`` per px^2 of symmetry residual for an estimate
    ``K`` (px): :func:`covariance` at ``K`` with the per-view axes ``l_n`` (normalised)
    -- how well the used views determine the intrinsics whatever the estimator
    (infinite where they don't).  Pure; arguments as :func:`bundle_estimate`'s
    (``base`` its shared problem, or None)."""
    used = jnp.asarray(used, bool)
    problem = make_problem(points_n, n_samples, aspect, inliers, used) if base is None else with_model(base, aspect)
    Kn = T @ K
    k = pack_seeds(jnp.stack([Kn[0, 0], Kn[1, 1], Kn[0, 2], Kn[1, 2]])[None], jnp.ones(1, bool))[0]
    l = jnp.where(used[:, None], jnp.asarray(l_n, jnp.float64), jnp.asarray([1.0, 0.0, 0.0]))
    cov, s2, _, _ = covariance((k, axis_params(l)), problem, T, None, options)
    return cov / (jnp.maximum(s2, 1e-300) / T[0, 0] ** 2)


import jax.flatten_util  # noqa: E402  (registers the submodule used above)
