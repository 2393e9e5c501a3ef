"""Model checks: does one zero-skew pinhole camera explain every view?

The bundle's covariance is a statement about noise *given the model*.  When the model
is wrong -- a known aspect ratio that is not the camera's, views taken by two cameras
(a zoom change, a cropped image), an outline that is not a surface of revolution, the
same view passed twice -- the bundle still finds a best fit and a small standard
deviation, far from the truth.  These checks test the model against the outlines
before a K is called determined.  Pure functions of arrays; the messages are written
at the edge (:mod:`sorjax._calibration`).

1. **Fixed parameters** (:func:`fixed_aspect_check`).  With a known aspect ratio
   ``a0`` the free-aspect bundle is fitted too and the Wald statistic
   ``z = |a_free - a0| / std(a_free)`` computed from its (correlated-noise, sandwich)
   covariance; ``g = sqrt((C_fixed - C_free) / n)`` px is the same evidence as an RMS
   per sample.  The known value is *contradicted* when ``z >= consistency_z`` and ``g
   >= perspective_factor * outline_error_px`` (neither the noise nor the declared
   systematic outline error explains the difference), *not confirmed* when only the
   noise fails to explain it (the covariance then grows by ``d d^T``, ``d`` the
   difference between the fixed and the free estimates of ``(fu, fv, u0, v0)``).
2. **Consistency of the views** (:func:`view_scores`).  Each view's homology is
   released from the pole-polar constraint (its axis and its vertex free: 4
   parameters instead of 2) and the score (Lagrange multiplier) statistic of that
   release is computed at the joint optimum, ``S_j = g_j^T M_j^+ g_j`` with ``g_j =
   J_j^T r_j`` and ``M_j`` the correlated-noise covariance of ``g_j`` (the bundle's
   outline noise model, :func:`sorjax.core._covariance.noise_blocks`).  No
   extra solve: one Jacobian of 4 columns per view.  ``S = sum_j S_j`` is compared
   with a chi-square of ``2 V - 4`` degrees of freedom (``2 V - 3`` with a known
   aspect ratio); ``delta_j = g_j^T (J_j^T J_j)^+ g_j`` (px^2, one Gauss-Newton step's
   decrease of the cost) gives the evidence per sample in px.  Inconsistent views are
   *contradicted* when the evidence also exceeds ``perspective_factor *
   outline_error_px`` RMS; otherwise the covariance is scaled by the Birge ratio
   ``S / dof`` (the views disagree beyond their noise: the noise-only covariance is too
   small by that factor).
3. **Parameters the model holds** (:func:`release_score`): the distortion-free
   bundle holds the lens's radial distortion at ``k1 = 0``, and a calibration with
   fixed intrinsics (a principal point, a focal length) holds them at the given
   values.  Each is released at the optimum and its score statistic computed as for
   the views (one Jacobian, no extra solve): ``S = g^T M^+ g`` with ``g = G^T r``,
   ``G`` the released parameters' Jacobian columns with the held parameters'
   directions projected out and ``M`` its correlated-noise covariance, against a
   chi-square of as many degrees of freedom as parameters released.  One Gauss-Newton
   step of the released model gives what the outlines say instead (``k1``, the
   intrinsics' shift ``d``, px) and the evidence ``g_px = sqrt(g^T (G^T G)^+ g / n)``
   per sample.  Rejected at ``p < consistency_p``: the covariance grows by ``d d^T``;
   *contradicted* when also ``g_px >= perspective_factor * outline_error_px`` (a
   lens with k1 = -0.05 on off-centre objects: refused, with ``distortion="k1"`` as
   the remedy, instead of a K 7-13 % off at a std of 1 %).
4. **Duplicated views** (:func:`duplicate_views`): an outline within
   ``duplicate_px`` RMS of an earlier one is the same view twice (it would shrink the
   standard deviations by sqrt(2) while adding no information): dropped.

Checks 2 and 3 read the bundle's residuals refitted with the outlines' systematic offset
that it estimated (:func:`sorjax.core._covariance.offset_fit`,
:attr:`~sorjax.core._covariance.OutlineOffsets.refit`; the :class:`Linearisation` the
bundle returns): a mask eroded or dilated by a pixel is a known kind of error whose effect
on K is already removed and counted in the covariance, not evidence against the camera
model.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import gammaincc
from jaxtyping import Array, Bool, Float, Int

from ._covariance import (Linearisation, chart_jacobian, floored_rss, lin_axis_columns, lin_vertex_columns, linearise,
                          noise_blocks, project_out, residual_jacobian, residual_variance)
from ._model import (BundleProblem, fixed_chart, free_intrinsics, make_problem, pin_intrinsics, pixel_params, with_model)
from ._noise import noise_meat
from ._options import Options

# ModelChecks.verdict
MODEL_OK, MODEL_WIDENED, MODEL_CONTRADICTED = 0, 1, 2
# ModelChecks.culprit: which check decided the verdict
NO_CULPRIT, CULPRIT_ASPECT, CULPRIT_VIEWS, CULPRIT_LENS, CULPRIT_FIXED = 0, 1, 2, 3, 4


class ModelChecks(eqx.Module):
    """The statistics of the model checks of one calibration (arrays; a batch stacks).

    Attributes:
        outline_error_px: the systematic outline error the checks and the perspective
            gate allowed for (px).
        aspect_fixed: the known ``fu / fv`` that was imposed (NaN: free).
        aspect_free: ``fu / fv`` of the free-aspect bundle (NaN unless a known aspect
            ratio was checked); ``aspect_free_std`` its standard deviation.
        aspect_z: ``|aspect_free - aspect_fixed| / aspect_free_std`` (Wald).
        aspect_px: ``sqrt((C_fixed - C_free) / n)``, px RMS per sample.
        view_score: (V,) each view's score statistic ``S_j`` (NaN: not used).
        view_px: (V,) each view's evidence ``sqrt(delta_j / n_j)``, px RMS per sample.
        consistency_p: the p-value of ``S = sum_j S_j`` against a chi-square of
            ``consistency_dof`` degrees of freedom (NaN with no degree of freedom).
        consistency_px: ``sqrt(sum_j delta_j / n)``, px RMS per sample.
        lens_k1: the radial distortion ``k1`` the outlines show when the model holds
            it at 0 (one Gauss-Newton step of the released model; NaN: not checked,
            e.g. distortion estimated); ``lens_p`` the score test's p-value (chi-square,
            1 degree of freedom), ``lens_px`` its evidence (px RMS per sample).
        lens_rejected: the lens test rejected ``k1 = 0`` and is to blame (more
            significant than the views' test, which rejects too when one view is no
            surface of revolution): the covariance was widened by its shift, or the
            calibration refused.
        fixed_p, fixed_px: the same for the intrinsics held fixed (NaN: none fixed);
        fixed_rejected: as ``lens_rejected``, for the fixed intrinsics;
        fixed_shift: (4,) where releasing them moves ``(fu, fv, u0, v0)`` (px, one
            Gauss-Newton step; NaN: none fixed).
        inflation: the factor the covariance was scaled by (1: none).
        verdict: ``MODEL_OK``, ``MODEL_WIDENED`` (not confirmed: the uncertainty
            includes the model's doubt) or ``MODEL_CONTRADICTED`` (refused).
        culprit: ``NO_CULPRIT``, ``CULPRIT_ASPECT``, ``CULPRIT_VIEWS``, ``CULPRIT_LENS``
            (radial distortion) or ``CULPRIT_FIXED`` (a fixed intrinsic).
        duplicate_of: (V,) the earlier view each view duplicates (-1: none).
    """

    outline_error_px: Float[Array, ""]
    aspect_fixed: Float[Array, ""]
    aspect_free: Float[Array, ""]
    aspect_free_std: Float[Array, ""]
    aspect_z: Float[Array, ""]
    aspect_px: Float[Array, ""]
    view_score: Float[Array, " V"]
    view_px: Float[Array, " V"]
    consistency_dof: Int[Array, ""]
    consistency_p: Float[Array, ""]
    consistency_px: Float[Array, ""]
    lens_k1: Float[Array, ""]
    lens_p: Float[Array, ""]
    lens_px: Float[Array, ""]
    lens_rejected: Bool[Array, ""]
    fixed_p: Float[Array, ""]
    fixed_px: Float[Array, ""]
    fixed_shift: Float[Array, "4"]
    fixed_rejected: Bool[Array, ""]
    inflation: Float[Array, ""]
    verdict: Int[Array, ""]
    culprit: Int[Array, ""]
    duplicate_of: Int[Array, " V"]


DUPLICATE_PROBES = 128  # points of each outline whose distance to the other outline is measured


def duplicate_views(points: Float[Array, "V M 2"], valid: Bool[Array, " V"], options: Options) -> Int[Array, " V"]:
    """Per view, the first earlier valid view whose outline lies within
    ``options.duplicate_px`` (RMS, px, both ways) of its own, else -1.  The distance is
    from ``DUPLICATE_PROBES`` evenly spread points of each outline to the other
    outline's nearest point (outlines of ``M`` evenly spaced points: a resampled copy
    of an outline is within about its spacing)."""
    V, M = points.shape[:2]
    i, j = jnp.arange(V)[:, None], jnp.arange(V)[None, :]
    pairs = (j < i) & valid[:, None] & valid[None, :]
    # cheap screen: a duplicate has (nearly) the same centroid and RMS radius
    c = jnp.mean(points, axis=1)
    rad = jnp.sqrt(jnp.mean(jnp.sum((points - c[:, None]) ** 2, -1), -1))
    near = 10.0 * options.duplicate_px
    cand = pairs & (jnp.linalg.norm(c[:, None] - c[None, :], axis=-1) <= near) & (
        jnp.abs(rad[:, None] - rad[None, :]) <= near)
    sub = points[:, :: max(1, M // DUPLICATE_PROBES)]  # probes: every k-th point, to every point of the other

    def nn_rms(p, q):
        d2 = jnp.sum((p[:, None, :] - q[None, :, :]) ** 2, -1)
        return jnp.sqrt(jnp.mean(jnp.min(d2, axis=1)))

    def distances():
        return jax.vmap(lambda ps, p: jax.vmap(lambda qs, q: jnp.maximum(nn_rms(ps, q), nn_rms(qs, p)))(sub, points))(
            sub, points)

    d = jax.lax.cond(jnp.any(cand), distances, lambda: jnp.full((V, V), jnp.inf))
    same = cand & (d <= options.duplicate_px)
    return jnp.where(jnp.any(same, axis=1), jnp.argmax(same, axis=1), -1).astype(jnp.int32)


def view_scores(y, points_n, used, inliers, aspect, T, options: Options, fixed=None, base=None, *, ell,
                lin: Linearisation | None = None):
    """Score statistics of releasing each view's homology from the pole-polar
    constraint at the bundle's optimum ``y`` (normalised by ``T``); see the module's
    docstring.  Returns ``(S (V,), delta_px2 (V,), n (V,))``: the statistics
    (dimensionless), one Gauss-Newton step's decrease of each view's cost (px^2) and
    each view's number of samples counted (sum of weights); NaN / 0 for views not
    used.  ``fixed`` (4,): intrinsics held fixed (px, NaN: free; None: none), which
    the joint model then does not count among its parameters.  ``base``: the
    calibration's shared problem (:func:`sorjax.core._model.with_model`), or None (built).
    ``ell``: (V,) each view's outline noise correlation length (px), the bundle's
    :attr:`~sorjax.core._bundle.BundleOut.noise_ell`.  ``lin``: the
    :class:`~sorjax.core._covariance.Linearisation` at ``y`` (its axis and vertex columns are
    each view's release), or None (computed here)."""
    fixed_n = None if fixed is None else fixed_chart(fixed, T)
    problem = (make_problem(points_n, options.n_samples, aspect, inliers, used, fixed_n) if base is None
               else with_model(base, aspect, fixed_n))
    if lin is None:
        lin = linearise(y, problem)
    V, N = problem.samples.shape[:2]
    # each view's release (V, N, 4): its axis (theta, rho) and its vertex's two
    # directions, the columns of the one Jacobian pass (block diagonal across views)
    cols = jnp.concatenate([lin_axis_columns(V), lin_vertex_columns(V)], axis=1)
    J = jax.vmap(lambda Jv, c: Jv[:, c])(lin.J.reshape(V, N, -1), cols)
    r = lin.r.reshape(V, N)
    n = jnp.sum(problem.weights, axis=1)
    n_par = jnp.sum(used) * 2 + n_free_intrinsics(aspect, fixed)
    s2 = floored_rss(r, problem) / jnp.maximum(jnp.sum(n) - n_par, 1.0)
    # the block-diagonal Jacobian of all views' releases, (V N, 4 V), for the meat
    G = (J[:, :, None, :] * jnp.eye(V)[:, None, :, None]).reshape(V * N, V * 4)
    meat = noise_meat(G, noise_blocks(problem, lin.feet, T, ell, s2, lin.a))
    g = jnp.einsum("vnk,vn->vk", J, r)
    blocks = jax.vmap(lambda i: jax.lax.dynamic_slice(meat, (4 * i, 4 * i), (4, 4)))(jnp.arange(V))
    S = jax.vmap(lambda gi, Mi: gi @ jnp.linalg.pinv(Mi, hermitian=True) @ gi)(g, blocks)
    JtJ = jnp.einsum("vnk,vnm->vkm", J, J)
    delta = jax.vmap(lambda gi, Hi: gi @ jnp.linalg.pinv(Hi, hermitian=True) @ gi)(g, JtJ) / T[0, 0] ** 2
    return jnp.where(used, S, jnp.nan), jnp.where(used, delta, jnp.nan), jnp.where(used, n, 0.0)


def n_free_intrinsics(aspect, fixed=None):
    """How many of ``(fu, fv, u0, v0)`` the bundle estimates: 4 with a free aspect
    ratio, 3 with a known one, less those held fixed (``fixed`` (4,) px, NaN: free;
    :func:`sorjax.core._model.free_intrinsics`)."""
    if fixed is None:
        return jnp.where(jnp.isnan(aspect), 4, 3)
    return jnp.sum(free_intrinsics(aspect, fixed)).astype(jnp.int32)


def consistency(S, delta_px2, n, used, aspect, options: Options, fixed=None):
    """``(dof, p, g_px, rejected, beyond_error, birge)`` of the views' consistency:
    ``S = sum_j S_j`` against a chi-square of ``dof = 2 V - 4`` (``- 3`` with a known
    aspect ratio; in general ``2 V`` less the free intrinsics,
    :func:`n_free_intrinsics`) degrees of freedom; ``rejected`` when ``p < consistency_p``;
    ``beyond_error`` when also ``g_px = sqrt(sum delta / n) >= perspective_factor *
    outline_error_px``; ``birge = S / dof``.  Evidence below ``check_floor_px``
    (numerical) never rejects."""
    dof = 2 * jnp.sum(used) - n_free_intrinsics(aspect, fixed)
    St = jnp.sum(jnp.where(used, S, 0.0))
    p = jnp.where(dof > 0, gammaincc(jnp.maximum(dof, 1) / 2.0, St / 2.0), jnp.nan)
    g = jnp.sqrt(jnp.sum(jnp.where(used, delta_px2, 0.0)) / jnp.maximum(jnp.sum(n), 1.0))
    rejected = (dof > 0) & (p < options.consistency_p) & (g >= options.check_floor_px)
    beyond = rejected & (g >= options.perspective_factor * options.outline_error_px)
    return dof.astype(jnp.int32), p, g, rejected, beyond, St / jnp.maximum(dof, 1)


def aspect_of(K, cov):
    """``fu / fv`` and its standard deviation (delta method) from ``K`` (px) and the
    covariance of ``(fu, fv, u0, v0)`` (px^2)."""
    a = K[0, 0] / K[1, 1]
    grad = jnp.array([1.0 / K[1, 1], -a / K[1, 1]])
    var = grad @ cov[:2, :2] @ grad
    return a, jnp.sqrt(jnp.where(jnp.isfinite(var), jnp.maximum(var, 0.0), jnp.inf))


def fixed_aspect_check(aspect, fixed_K, fixed_cost, free_K, free_cov, free_cost, free_ok, n, options: Options,
                       free_s2=None):
    """``(a_free, a_std, z, g_px, rejected, beyond_error)`` of a known aspect ratio
    ``aspect`` (NaN: nothing to check; every result False / NaN) against the free
    fit; see the module's docstring.  Rejected only when the free fit is also
    clearly *better*: its cost below the fixed fit's by at least ``consistency_z^2``
    times its residual variance ``free_s2`` (px^2).  A Wald statistic alone trusts
    the free fit's covariance, and a free fit stuck in a worse minimum (a gross failure
    under weak perspective: f = 1400 px, sigma 1.2-2 px in Table 1) has a wrong aspect
    ratio and a small std: 5 in 100 correct unit-aspect calibrations were refused so."""
    checked = jnp.isfinite(aspect) & free_ok
    a_free, a_std = aspect_of(free_K, free_cov)
    z = jnp.abs(a_free - aspect) / jnp.maximum(a_std, 1e-300)
    drop = fixed_cost - free_cost
    g = jnp.sqrt(jnp.maximum(drop, 0.0) / jnp.maximum(n, 1.0))
    better = True if free_s2 is None else drop >= options.consistency_z**2 * free_s2
    rejected = checked & (z >= options.consistency_z) & better & (g >= options.check_floor_px)
    beyond = rejected & (g >= options.perspective_factor * options.outline_error_px)
    nan = jnp.asarray(jnp.nan)
    return (jnp.where(checked, a_free, nan), jnp.where(checked, a_std, nan), jnp.where(checked, z, nan),
            jnp.where(checked, g, nan), rejected, beyond)


class Release(eqx.Module):
    """The score test of releasing parameters a fitted model holds
    (:func:`release_score`), all arrays.

    Attributes:
        score: ``S = g^T M^+ g`` (dimensionless; chi-square with ``dof`` degrees of
            freedom when the held values are right).
        dof: the number of parameters released.
        p: the p-value of ``S`` (NaN with nothing released).
        px: ``sqrt(g^T (G^T G)^+ g / n)``: one Gauss-Newton step's decrease of the cost
            per sample (px RMS).
        shift: (4,) one Gauss-Newton step's change of ``(fu, fv, u0, v0)`` (px).
        released: the released parameters' values after that step (the chart's
            entries; e.g. ``k1``), NaN elsewhere: (nk,).
        rejected: ``p < consistency_p`` and ``px >= check_floor_px``.
        beyond: rejected and ``px >= perspective_factor * outline_error_px``.
    """

    score: Float[Array, ""]
    dof: Int[Array, ""]
    p: Float[Array, ""]
    px: Float[Array, ""]
    shift: Float[Array, "4"]
    released: Float[Array, " nk"]
    rejected: Bool[Array, ""]
    beyond: Bool[Array, ""]


def release_score(y, problem: BundleProblem, release: Bool[Array, " nk"], T, options: Options, ell,
                  jac=None) -> Release:
    """The score (Lagrange multiplier) test of releasing the intrinsic-chart entries
    ``release`` (nk,) of a model fitted at ``y = (k (nk,), a (V, 2))`` (normalised by
    ``T``), in ``problem``'s model where they are free (their values in ``k`` are the
    held ones).  Columns of the Jacobian ``J = [J_h, J_r]`` (held, released) at ``y``:
    ``G = J_r - J_h (J_h^T J_h)^+ J_h^T J_r``, ``g = G^T r`` (``= J_r^T r`` at the held
    model's optimum), ``S = g^T M^+ g`` with ``M = G^T Sigma_r G`` the outline noise
    model's ``Var(g)`` (:func:`sorjax.core._covariance.noise_blocks`, correlation length ``ell``
    px, one or (V,) one per view), ``p = P(chi2_q > S)``;
    the Gauss-Newton step of the released model ``-(J^T J)^+ J^T r`` gives ``shift``
    and ``released``.  No solve: one Jacobian.  ``jac``: ``(J, r, feet, a)`` as
    :func:`sorjax.core._covariance.residual_jacobian` gives them with ``normals=True`` (read off
    the bundle's :class:`~sorjax.core._covariance.Linearisation`), or None (computed here)."""
    nk = y[0].shape[0]
    J, r, feet, a = residual_jacobian(y, problem, normals=True) if jac is None else jac
    rel = jnp.concatenate([jnp.asarray(release, bool), jnp.zeros(J.shape[1] - nk, bool)])
    Jr = jnp.where(rel[None, :], J, 0.0)
    Jh = jnp.where(rel[None, :], 0.0, J)
    G = project_out(Jr, Jh)
    q = jnp.sum(rel).astype(jnp.int32)
    n = jnp.sum(problem.weights)
    s2 = residual_variance(r, y, problem, q)
    g = G.T @ r
    M = noise_meat(G, noise_blocks(problem, feet, T, ell, s2, a))
    S = g @ jnp.linalg.pinv(M, hermitian=True) @ g
    delta = g @ jnp.linalg.pinv(G.T @ G, hermitian=True) @ g / T[0, 0] ** 2
    p = jnp.where(q > 0, gammaincc(jnp.maximum(q, 1) / 2.0, S / 2.0), jnp.nan)
    px = jnp.sqrt(jnp.maximum(delta, 0.0) / jnp.maximum(n, 1.0))
    step = -jnp.linalg.pinv(J.T @ J, hermitian=True) @ (J.T @ r)
    k1 = y[0] + step[:nk]
    shift = pixel_params(k1, problem, T)[:4] - pixel_params(y[0], problem, T)[:4]
    rejected = (q > 0) & (p < options.consistency_p) & (px >= options.check_floor_px)
    beyond = rejected & (px >= options.perspective_factor * options.outline_error_px)
    return Release(score=S, dof=q, p=p, px=px, shift=shift, released=jnp.where(rel[:nk], k1, jnp.nan),
                   rejected=rejected, beyond=beyond)


def _released(lin: Linearisation, held=None, k1: bool = False):
    """:func:`release_score`'s ``jac`` read off the bundle's
    :class:`~sorjax.core._covariance.Linearisation` (:func:`~sorjax.core._covariance.chart_jacobian`)."""
    return chart_jacobian(lin, held, k1), lin.r, lin.feet, lin.a.reshape(-1)


def lens_release(y, points_n, used, inliers, aspect, T, options: Options, fixed=None, base=None, *, ell,
                 lin: Linearisation | None = None) -> Release:
    """:func:`release_score` of the radial distortion ``k1`` that the pinhole bundle's
    solution ``y = (k (4,), a)`` holds at 0 (the model of
    :func:`sorjax.core._model.distorted_transfer` with one coefficient; ``fixed``: the
    intrinsics held fixed, px, or None); ``released[-1]`` is the ``k1`` one
    Gauss-Newton step gives.  ``base``: the calibration's problem
    (:func:`sorjax.core._model.with_model`), or None to build it; ``ell`` as
    :func:`release_score`'s; ``lin`` the :class:`~sorjax.core._covariance.Linearisation` at
    ``y`` (its ``k1`` column is the release), or None (the distorted residuals'
    Jacobian computed here)."""
    fixed_n = None if fixed is None else fixed_chart(fixed, T)
    pinhole = (make_problem(points_n, options.n_samples, aspect, inliers, used, fixed_n) if base is None
               else with_model(base, aspect, fixed_n))
    problem = dataclasses.replace(pinhole, n_dist=1)
    k = jnp.concatenate([y[0], jnp.zeros(1)])
    jac = None if lin is None else _released(lin, None if fixed_n is None else jnp.isfinite(fixed_n), k1=True)
    return release_score((k, y[1]), problem, jnp.arange(5) == 4, T, options, ell, jac)


def fixed_release(y, points_n, used, inliers, aspect, T, options: Options, fixed, base=None, *, ell,
                  lin: Linearisation | None = None) -> Release:
    """:func:`release_score` of the intrinsics ``fixed`` (4,) px (NaN: free) that the
    bundle's solution ``y = (k (4,), a)`` holds: released all at once (as many degrees
    of freedom as are fixed and estimable: ``fu`` with a known aspect ratio follows
    ``fv``); ``base`` and ``lin`` as :func:`lens_release`'s (the
    :class:`~sorjax.core._covariance.Linearisation`'s intrinsic columns are those of the
    released chart)."""
    chart = fixed_chart(fixed, T)
    problem = (make_problem(points_n, options.n_samples, aspect, inliers, used) if base is None
               else with_model(base, aspect))
    k = pin_intrinsics(y[0], chart)
    release = jnp.isfinite(chart) & free_intrinsics(aspect, None)
    jac = None if lin is None else _released(lin)
    return release_score((k, y[1]), problem, release, T, options, ell, jac)
