"""The bundle linearised at a solution: one Jacobian pass, the covariance, the noise level.

Uncertainty: at the optimum, the sandwich ``F^-1 G^T Sigma_r G F^-1`` of least squares
(``G`` the intrinsics' Jacobian columns with the per-view parameters projected out,
read off the outlines smoothed by a few pixels; ``F = G^T G``), with ``Sigma_r`` the
residuals' covariance under a model of the outline noise whose level and correlation
length along the curve are estimated from the residuals (:mod:`sorjax.core._noise`), pushed
to the pixel intrinsics ``(fu, fv, u0, v0)`` through the Jacobian of that map;
intrinsics the views do not determine at all get an infinite variance (see
:func:`covariance`).  :func:`linearise` gives, in one forward-mode pass, the Jacobian
that the covariance and every model check (:mod:`sorjax.core._checks`) read.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._camera import intrinsics_matrix
from ._distortion import distort
from ._field import signed_distances
from ._symmetry import homology_matrix, transfer
from ._noise import (NoiseGeometry, estimate_noise, jacobian_and_normal_sensitivity, knot_spacing_px, noise_geometry,
                     noise_meat, sample_normals, smoothed_outline, unit_blocks)
from ._solvers import NULL_RCOND
from ._options import Options
from ._model import (BundleProblem, foot_parameters, n_params, pin_intrinsics,
                     pixel_params, pole_polar_pairs, residuals, unpack_intrinsics)


NULL_EIGENVALUE = NULL_RCOND**2  # 1e-12: the Gauss-Newton polish takes no step where this calls null


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


def chart_jacobian(lin: Linearisation, held=None, k1: bool = False):
    """The columns of ``lin.J`` in a bundle chart ``(k, [k1,] a)``: the intrinsic chart
    (the entries ``held`` (4,) bool zeroed, as the chart that pins them has them; None:
    none), ``k1`` when asked, then each view's ``(theta, rho)``; (V N, 4 [+ 1] + 2 V)."""
    V = lin.a.shape[0]
    Jk = lin.J[:, LIN_K] if held is None else jnp.where(held, 0.0, lin.J[:, LIN_K])
    k1_col = [lin.J[:, LIN_K1:LIN_K1 + 1]] if k1 else []
    return jnp.concatenate([Jk, *k1_col, lin.J[:, LIN_VIEWS:LIN_VIEWS + 2 * V]], axis=1)


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
    ``(cov, s2, step, ell, offsets)`` with ``s2 = |r|^2 / (VN - p)`` (normalised units^2;
    each view's share at least its noise floor, :func:`floored_rss`),
    ``step`` the Gauss-Newton step's Mahalanobis length (:func:`step_sigmas`),
    ``ell`` (V,) each view's outline noise correlation length (px, :mod:`sorjax.core._noise`)
    and ``offsets`` the outlines' systematic offset estimated as a nuisance
    (:class:`OutlineOffsets`, :func:`offset_fit`): its share of ``cov`` (px^2; 0 where
    ``cov`` is not finite), which does not scale with the residuals, and the shift of
    the intrinsics it makes, which the caller adds to the estimate.

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

    A systematic offset of the outlines along their normals (an eroded or dilated
    mask), with the declared prior :func:`outline_offset`, is estimated as a nuisance
    to first order (:func:`offset_fit`): where perspective makes it visible its effect
    on the intrinsics (their change per unit offset, implicit differentiation through
    the solve) is removed, and what is left of it (its estimate's uncertainty, or the
    prior where it is not visible) widens the covariance.

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
        J = chart_jacobian(lin, None if problem.fixed is None else jnp.isfinite(problem.fixed))
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
    fit = offset_fit(G, Js, geo, r, s2, outline_offset(options) * T[0, 0])
    meat_off = fit.meat
    cov_k = F_inv @ (level * noise_meat(fit.G, unit_blocks(geo, ell)) + meat_off) @ F_inv

    Gk = jax.jacfwd(lambda k: pixel_params(k, problem, T))(y[0])
    cov = Gk @ cov_k @ Gk.T
    cov_off = Gk @ F_inv @ meat_off @ F_inv @ Gk.T
    shift = Gk @ (F_inv @ fit.score)
    GU = Gk @ U  # (4 [+ n_dist], nk): each pixel intrinsic along each eigenvector
    leak = jnp.sum(jnp.where(null[None, :], GU**2, 0.0), axis=1)
    undetermined = leak > 1e-8 * jnp.sum(GU**2, axis=1)
    bad = undetermined[:, None] | undetermined[None, :]
    cov = jnp.where(bad, jnp.nan, cov)
    cov = jnp.where(jnp.eye(cov.shape[0], dtype=bool) & bad, jnp.inf, cov)
    off = OutlineOffsets(cov=jnp.where(bad, 0.0, cov_off), shift=jnp.where(undetermined, 0.0, shift),
                         value=fit.value * scale, std=fit.std * scale, refit=fit.refit)
    return cov, s2, step, ell, off


def outline_offset(options: Options):
    """The standard deviation (px) of the systematic outline offset the covariance
    counts: the larger of :attr:`Options.outline_offset_px` and
    :attr:`Options.outline_error_px` (the declared systematic error of the outlines
    is at least an offset of that size)."""
    return jnp.maximum(options.outline_offset_px, options.outline_error_px)


#: the prior standard deviation of each outline's own offset, as a fraction of the
#: shared one's (:func:`offset_fit`).  0: one offset shared by every outline (one
#: segmenter's bias).  Measured (experiments/outline_bias.py, five cameras of renders,
#: masks eroded or dilated by 0 to 2 px): with own offsets as large as the shared one
#: every run was covered as well, but the std of unbiased masks was 3.4x the
#: offset-free one instead of 2.2x, and the errors' median |z| 0.56 instead of 0.73.
OWN_OFFSET_SHARE = 0.0


class OutlineOffsets(eqx.Module):
    """The outlines' systematic offset along their normals, estimated with the bundle
    (:func:`offset_fit`) and its effect on the intrinsics.

    Attributes:
        cov: (n, n) the part of the covariance of the pixel intrinsics that the
            offset's uncertainty makes (px^2; it does not scale with the residuals).
        shift: (n,) the change of the pixel intrinsics that the estimated offset makes
            (px; already in the estimate the bundle reports).
        value: (V,) each outline's estimated offset (px, outward positive: a dilated
            mask): the shared part plus its own.
        std: (V,) its standard deviation (px).
        refit: (V N,) the change of the residuals when the bundle is refitted to first
            order with the outlines moved back by the estimated offset, ``B_P delta``
            (normalised units; :func:`offset_fit`): the model checks read ``r -
            refit`` (a uniformly offset outline is no evidence against the camera model
            once its effect on K is removed and counted).
    """

    cov: Float[Array, "n n"]
    shift: Float[Array, " n"]
    value: Float[Array, " V"]
    std: Float[Array, " V"]
    refit: Float[Array, " VN"]


class _OffsetFit(NamedTuple):
    G: Array
    meat: Array
    score: Array
    value: Array
    std: Array
    refit: Array


def offset_columns(geo: NoiseGeometry) -> Float[Array, "VN P"]:
    """``B`` (V N, 1 + V): the residuals' change per unit offset of every outline
    along its outward normals (the shared part, the first column) and of each
    outline's own (one column per view): ``a - w`` on the view's rows (this module's
    noise model with ``n(t)`` constant: the sample moves with the outline, ``a``, and
    so does the target curve, ``-w``)."""
    V, N = geo.a.shape
    own = ((geo.a - geo.w)[:, :, None] * jnp.eye(V)[:, None, :]).reshape(V * N, V)
    return jnp.concatenate([jnp.sum(own, axis=1, keepdims=True), own], axis=1)


def offset_fit(G, J, geo: NoiseGeometry, r, s2, sigma) -> _OffsetFit:
    """The outlines' systematic offset estimated as a nuisance of the bundle with a
    prior: offsets ``delta`` (a part shared by every outline and one per outline,
    :func:`offset_columns` ``B``), ``N(0, Lambda)`` (:func:`offset_prior`, normalised
    units; ``sigma`` the declared :func:`outline_offset`), fitted to first order at the bundle's optimum
    with the residuals ``r`` (white, variance ``s2``)::

        delta = H B_P^T r,   H = (B_P^T B_P + s2 Lambda^-1)^-1

    (``B_P``: ``B`` with the span of the bundle's Jacobian ``J`` projected out).
    Where perspective makes the offset visible (``B_P^T B_P`` above ``s2 / sigma^2``)
    it is estimated from the outlines and its effect removed; where not, the prior
    holds it near 0 and its uncertainty widens the covariance.  The intrinsics move by
    ``F^-1 G^T B delta`` (``score``: ``G^T B delta``) and their error is, to first
    order, ``F^-1 (G_eff^T eps + N delta_true)`` with ``G_eff = G - B_P H B^T G`` (what
    the noise ``eps`` reaches them through) and ``N = G^T B (I - H B_P^T B_P)`` (what
    is left of the true offset): the meat ``N Lambda N^T`` here, the noise's read
    off ``G_eff``.  ``sigma = 0``: nothing estimated, ``G_eff = G``, no meat.

    The residuals of the bundle refitted with the offset (to first order: the
    intrinsics and pairs move by ``-(J^T J)^-1 J^T B delta``, ``r`` being orthogonal to
    ``J`` at the optimum) are ``r - B_P delta``.

    Returns ``G_eff``, the offset's meat, the score, each outline's offset (shared
    plus own) with its standard deviation (the posterior's, normalised units), and
    ``B_P delta`` (``refit``)."""
    B = offset_columns(geo)
    P = B.shape[1]
    B_P = project_out(B, J)
    BPB = B_P.T @ B_P
    eye = jnp.eye(P)
    prior = offset_prior(sigma, P - 1)  # Lambda's diagonal
    # H = (B_P^T B_P + s2 Lambda^-1)^-1 = Lambda (B_P^T B_P Lambda + s2 I)^-1 (no inverse of Lambda)
    H = prior[:, None] * jnp.linalg.inv(BPB * prior[None, :] + jnp.maximum(s2, 1e-300) * eye)
    H = 0.5 * (H + H.T)
    delta = H @ (B_P.T @ r)
    GB = G.T @ B
    N = GB @ (eye - H @ BPB)
    post = jnp.maximum(s2, 0.0) * H  # the offsets' posterior covariance (white noise)
    u = jnp.concatenate([jnp.ones((P - 1, 1)), jnp.eye(P - 1)], axis=1)  # each outline: shared + own
    return _OffsetFit(G=G - B_P @ (H @ GB.T), meat=(N * prior[None, :]) @ N.T, score=GB @ delta, value=u @ delta,
                      std=jnp.sqrt(jnp.maximum(jnp.einsum("vp,pq,vq->v", u, post, u), 0.0)), refit=B_P @ delta)


def offset_prior(sigma, V: int):
    """(1 + V,) the prior variances of the offsets of :func:`offset_columns`: ``sigma^2``
    for the shared one, ``(OWN_OFFSET_SHARE sigma)^2`` for each outline's own."""
    return sigma**2 * jnp.concatenate([jnp.ones(1), jnp.full(V, OWN_OFFSET_SHARE**2)])


def offset_meat(G: Float[Array, "VN q"], geo: NoiseGeometry, sigma) -> Float[Array, "q q"]:
    """``G^T B Lambda B^T G``: the meat of the outlines' systematic offset with its
    prior (:func:`offset_columns` ``B``, :func:`offset_prior` ``Lambda``; ``sigma`` in
    normalised units) for an estimator that does not estimate it (the linear methods):
    ``F^-1 G^T B`` is the estimate's change per unit offset."""
    GB = G.T @ offset_columns(geo)
    return (GB * offset_prior(sigma, geo.a.shape[0])[None, :]) @ GB.T


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


def step_sigmas(y, problem: BundleProblem):
    """Mahalanobis length of the Gauss-Newton step at ``y``:
    ``sqrt(r^T J (J^T J)^+ J^T r) / s`` with ``s^2 = |r|^2 / (n - p)``
    (:func:`residual_variance`, the views' noise floors included)."""
    J, r, _ = residual_jacobian(y, problem)
    return _step_length(J, r, residual_variance(r, y, problem))


class HomologyCovariance(eqx.Module):
    """The covariance of every view's homology fit (eq. 20, each view alone), in four
    parameters per view: its axis ``(theta, rho)`` (``l ~ (cos theta, sin theta,
    -rho)``, normalised) and its vertex moved along ``b1``, ``b2``, two unit directions
    orthogonal to it (the columns of :func:`linearise`).

    Attributes:
        cov: (4 V, 4 V) every view's axes first, then every view's vertex directions
            (normalised units^2); block diagonal but for the shared outline offset.
        cov_offset: the part of ``cov`` the declared outline offset makes
            (:func:`offset_meat`).
        axes: (V, 2) the fitted axes ``(theta, rho)``.
        b1, b2: (V, 3) the vertex directions.
        s2: the residual variance of the fit with every homology free (normalised
            units^2).
    """

    cov: Float[Array, "P P"]
    cov_offset: Float[Array, "P P"]
    axes: Float[Array, "V 2"]
    b1: Float[Array, "V 3"]
    b2: Float[Array, "V 3"]
    s2: Float[Array, ""]


def homology_covariance(y, problem: BundleProblem, T, options: Options = Options()) -> HomologyCovariance:
    """:class:`HomologyCovariance` under this module's outline noise model and the
    declared outline offset (:func:`offset_meat`): each view's block of the sandwich
    ``F^-1 J^T Sigma_r J F^-1``, read off the outlines smoothed as :func:`covariance`
    does, linearised at ``y = (k, a)`` (the views' vertices there,
    :func:`pole_polar_pairs`, and the fitted axes ``a``).  The noise level and
    correlation length are matched (:func:`sorjax.core._noise.estimate_noise`) to the
    residuals with every view's homology free, to first order (the residuals at ``y``
    with the homologies' columns projected out), each view's floor included."""
    k, a = y
    V = a.shape[0]
    scale = 1.0 / T[0, 0]
    cols = jnp.concatenate([lin_axis_columns(V).reshape(-1), lin_vertex_columns(V).reshape(-1)])
    raw = linearise(y, problem)
    Jh = raw.J[:, cols]
    r = raw.r - Jh @ jnp.linalg.lstsq(Jh, raw.r, rcond=NULL_RCOND)[0]  # the free homologies' residuals, first order
    dof = jnp.maximum(jnp.sum(problem.weights) - 4 * jnp.sum(problem.used), 1)
    smooth = smoothed_problem(problem, options.covariance_smooth_px, scale)
    lin = linearise(y, smooth)
    G = lin.J[:, cols]
    geo = noise_geometry_at(smooth, lin.feet, scale, lin.a)
    ell, level = estimate_noise(geo, r.reshape(geo.a.shape), Jh, options.noise_ell_min_px, options.noise_ell_max_px,
                                floor=view_floors(problem), floor_ell=problem.noise_ell)
    meat_off = offset_meat(G, geo, outline_offset(options) * T[0, 0])
    meat = level * noise_meat(G, unit_blocks(geo, ell)) + meat_off
    F_inv = jnp.linalg.pinv(G.T @ G, hermitian=True)  # block diagonal: each view's own fit
    v0 = pole_polar_pairs((pin_intrinsics(k, problem.fixed), a), dataclasses.replace(problem, fixed=None))[0]
    b1, b2 = jax.vmap(_vertex_basis)(jax.lax.stop_gradient(v0))
    return HomologyCovariance(cov=F_inv @ meat @ F_inv, cov_offset=F_inv @ meat_off @ F_inv, axes=a, b1=b1, b2=b2,
                              s2=floored_rss(r, problem) / dof)


def homology_estimator_covariance(estimate, v_n, hc: HomologyCovariance):
    """First-order covariance ``A C A^T`` of an estimator of the pixel intrinsics that
    reads only the per-view homologies, ``(fu, fv, u0, v0) = estimate(v, l)`` px with
    ``v, l`` (V, 3) normalised (the paper's linear methods): ``C`` every view's
    homology fit's covariance (:func:`homology_covariance`), ``A`` the estimator's
    Jacobian in the same parameters by forward-mode autodiff, at the fitted vertices
    ``v_n`` (V, 3) moved along ``hc.b1``, ``hc.b2`` and the fitted axes.  Returns
    ``(cov, cov_offset)`` px^2, the second the part the outline offset makes."""
    V = hc.axes.shape[0]
    vf = v_n / jnp.linalg.norm(v_n, axis=-1, keepdims=True)
    vf = vf * jnp.where(jnp.sum(vf * jnp.cross(hc.b1, hc.b2), axis=-1, keepdims=True) < 0, -1.0, 1.0)

    def est(p):
        aa = hc.axes + p[:2 * V].reshape(V, 2)
        dv = p[2 * V:].reshape(V, 2)
        l = jnp.stack([jnp.cos(aa[:, 0]), jnp.sin(aa[:, 0]), -aa[:, 1]], axis=-1)
        return estimate(vf + dv[:, :1] * hc.b1 + dv[:, 1:] * hc.b2, l)

    A = jax.jacfwd(est)(jnp.zeros(4 * V, hc.axes.dtype))
    return A @ hc.cov @ A.T, A @ hc.cov_offset @ A.T


import jax.flatten_util  # noqa: E402  (registers the submodule used above)
