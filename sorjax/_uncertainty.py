"""Predicted error of the bundle and the efficiency bound, for a synthetic scene.

For a scene with known truth and a known noise model, linearise the bundle's
residuals (eq. 20 over all views, ``l_s = omega v_x``) at the truth, both in the
parameters ``y`` (Jacobian ``J``) and in the noise, the displacements ``n`` of the
outline points along their normals (Jacobian ``B``: the noise moves the samples *and*
the target curves).  With ``Sigma_n`` the covariance of the noise model, the
residuals' covariance is ``Sigma_r = B Sigma_n B^T`` and

* the bundle (unweighted least squares) has, to first order, the sandwich covariance
  ``C = (J^T J)^-1 J^T Sigma_r J (J^T J)^-1``;
* the best estimator built on these residuals (generalised least squares, i.e. the
  Cramer-Rao bound when the residuals are the Gaussian measurements) has
  ``C* = (J^T Sigma_r^+ J)^-1``.

Both are pushed to the pixel intrinsics ``(fu, fv, u0, v0)``.  ``Sigma_n`` follows
:func:`sorjax.scenes.paper_noise` (uniform magnitudes of maximum ``sigma`` at spacing
``delta`` px, smoothed by a Gaussian of ``smooth_px``: ``Cov(s, s') = sigma^2 / 3 *
delta / (2 sqrt(pi) smooth_px) * exp(-(s - s')^2 / (4 smooth_px^2))`` for arc lengths
``s, s'``; times ``2 sqrt(pi) smooth_px / delta`` with ``preserve_std``) or
:func:`sorjax.scenes.gaussian_noise` (variance ``sigma^2``, independent).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .core._model import (BundleProblem, axis_params, intrinsic_params, residuals, unpack_intrinsics)
from .core._camera import normalising_transform, pixel_intrinsics, transform_points
from .core._field import curve, setup
from ._outline import DEFAULT_POINTS, make_outline


class ErrorPrediction(eqx.Module):
    """Covariances (px^2) of ``(fu, fv, u0, v0)``: ``bundle`` (first-order covariance
    of the bundle estimate) and ``bound`` (the efficiency bound); ``f`` the true fv."""

    bundle: Float[Array, "4 4"]
    bound: Float[Array, "4 4"]
    f: float = eqx.field(static=True)

    def percent(self, which: str = "bundle") -> np.ndarray:
        """Standard deviations of (fu, fv, u0, v0) in % of f."""
        return np.sqrt(np.diag(np.asarray(getattr(self, which)))) / self.f * 100


def _noise_covariance(arc: np.ndarray, perimeter: float, sigma: float, model: str, smooth_px: float, preserve_std: bool):
    d = np.abs(arc[:, None] - arc[None, :])
    d = np.minimum(d, perimeter - d)
    if model == "gaussian":
        return np.eye(len(arc)) * sigma**2
    if smooth_px <= 0:
        return np.eye(len(arc)) * sigma**2 / 3.0
    delta = min(1.0, smooth_px / 2.0)
    c0 = sigma**2 / 3.0 * (1.0 if preserve_std else delta / (2.0 * np.sqrt(np.pi) * smooth_px))
    return c0 * np.exp(-(d**2) / (4.0 * smooth_px**2))


@functools.partial(jax.jit, static_argnames=("n_samples",))
def _jacobians(y0, pn, normals, weights, aspect, n_samples: int):
    """Jacobians of the stacked residuals at ``y0`` in the parameters (``J``) and in
    the normal displacements of the outline points (``B``), one compiled program."""
    flat0, unravel = jax.flatten_util.ravel_pytree(y0)

    def R(flat, n):
        p = pn + n[..., None] * normals
        fields, samples, _ = jax.vmap(lambda q: setup(q, n_samples))(p)  # weights: held at the unperturbed ones
        prob = BundleProblem(fields, samples, weights, aspect)
        return residuals(unravel(flat), prob)

    n0 = jnp.zeros(pn.shape[:2])
    return jax.jacfwd(R, argnums=0)(flat0, n0), jax.jacrev(R, argnums=1)(flat0, n0)


@functools.partial(jax.jit, static_argnames=("n_samples",))
def _geometry(pn, n_samples: int):
    """Unit tangents at the knots and the sample weights of each view's field."""
    fields, _, weights = jax.vmap(lambda p: setup(p, n_samples))(pn)
    m = pn.shape[1]
    tangents = jax.vmap(lambda f: jax.vmap(lambda t: curve(f, t)[1])(jnp.arange(m, dtype=jnp.float64)))(fields)
    return tangents, weights


@jax.jit
def _intrinsics_jacobian(y0, T, aspect):
    """Jacobian of the pixel intrinsics ``(fu, fv, u0, v0)`` in the flat parameters."""
    flat0, unravel = jax.flatten_util.ravel_pytree(y0)
    return jax.jacfwd(lambda f: pixel_intrinsics(T, *unpack_intrinsics(unravel(f)[0], aspect)))(flat0)


def predicted_error(
    scene,
    sigma: float,
    *,
    noise: str = "paper",
    smooth_px: float = 2.0,
    preserve_std: bool = False,
    aspect_ratio: float | None = None,
    n_samples: int = 100,
    n_points: int = DEFAULT_POINTS,
) -> ErrorPrediction:
    """First-order error of the bundle and the efficiency bound for ``scene``
    (a :class:`sorjax.scenes.Scene`) under ``noise`` ("paper" or "gaussian") of level
    ``sigma`` px; ``aspect_ratio`` as in ``calibrate(method="bundle")``.  Gaussian noise is
    taken as independent between the resampled points (an approximation: the input's
    denser points are interpolated)."""
    if noise not in ("paper", "gaussian"):
        raise ValueError(f"noise must be 'paper' or 'gaussian', got {noise!r}")
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma!r}")
    pts = np.stack([np.asarray(make_outline(o, n_points).points) for o in scene.outlines])
    V, M = pts.shape[:2]
    T = normalising_transform(pts.reshape(-1, 2))
    s = 1.0 / T[0, 0]
    pn = transform_points(T, pts)
    tangents, weights = _geometry(jnp.asarray(pn), n_samples)
    tangents = np.asarray(tangents)
    normals = np.stack([tangents[..., 1], -tangents[..., 0]], -1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)

    K = np.asarray(scene.K)
    Kn = T @ K
    free = aspect_ratio is None
    # the padded chart (log fu, log fv, u0, v0) for both aspect models, so that they share
    # one compiled program: with a known aspect ratio log fu is ignored (fu = a fv,
    # :func:`sorjax.core._model.unpack_intrinsics`) and its zero column is dropped below,
    # which leaves exactly the compact chart (log fv, u0, v0)
    k0 = intrinsic_params(Kn, True)
    y0 = (k0, axis_params(np.stack([np.linalg.solve(T.T, np.asarray(v.l_s)) for v in scene.views])))
    aspect = jnp.asarray(np.nan if free else float(aspect_ratio))
    cols = np.arange(len(k0) + 2 * V) >= (0 if free else 1)

    J, B = _jacobians(y0, jnp.asarray(pn), jnp.asarray(normals), weights, aspect, n_samples)
    J, B = np.asarray(J)[:, cols], np.asarray(B).reshape(J.shape[0], V * M)
    keep = np.asarray(weights).reshape(-1) > 0
    J, B = J[keep], B[keep]

    # noise covariance per view (px^2 -> normalised units^2), views independent:
    # Sigma_r = sum_j B_j C_j B_j^T
    seg = np.linalg.norm(np.roll(pts, -1, axis=1) - pts, axis=-1)
    Sr = np.zeros((B.shape[0], B.shape[0]))
    for j in range(V):
        arc = np.concatenate([[0.0], np.cumsum(seg[j][:-1])])
        per = float(seg[j].sum())
        C = _noise_covariance(arc, per, sigma, noise, smooth_px, preserve_std)
        Bj = B[:, j * M : (j + 1) * M]
        Sr += Bj @ (C / s**2) @ Bj.T
    JtJ_inv = np.linalg.inv(J.T @ J)
    C_ols = JtJ_inv @ J.T @ Sr @ J @ JtJ_inv
    w, U = np.linalg.eigh(Sr)
    w_inv = np.where(w > 1e-10 * w.max(), 1.0 / np.maximum(w, 1e-300), 0.0)
    C_gls = np.linalg.inv(J.T @ (U * w_inv) @ U.T @ J)

    G = np.asarray(_intrinsics_jacobian(y0, jnp.asarray(T), aspect))[:, cols]
    return ErrorPrediction(jnp.asarray(G @ C_ols @ G.T), jnp.asarray(G @ C_gls @ G.T), float(K[1, 1]))
