"""The joint bundle's model: its problem, its chart and its residuals.

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

Radial distortion (issue 18; :mod:`sorjax.core._distorted`): OpenCV's ``(k1[, k2])``
about the principal point in camera-normalised coordinates join the intrinsics
(``2V + 5`` / ``2V + 6`` parameters, ``problem.n_dist``); each sample of an observed
outline is undistorted, moved by the pinhole homology and distorted again
(:func:`distorted_transfer`), then read from the outline's own field.  With
``n_dist = 0`` every function here traces exactly the program it did before.
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




def pixel_params(k, problem: BundleProblem, T):
    """The pixel intrinsics ``(fu, fv, u0, v0)`` of the chart ``k`` (normalised by the
    similarity ``T``), followed by the distortion coefficients ``(k1[, k2])`` when the
    problem has them (dimensionless: the same in every frame)."""
    d = split_params(k, problem)[1]
    p = _pixel_intrinsics(T, *_intrinsics(k, problem))
    return p if d is None else jnp.concatenate([p, d])


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
