"""Differentiable losses for use inside your own JAX code.

Everything here is a pure function of arrays (and :class:`DistanceField` pytrees), so
it composes with ``jax.jit``, ``jax.vmap``, ``jax.grad`` and optimistix.  Units are
whatever the outline points are in (pixels unless you normalised them); homogeneous
points and lines are 3-vectors.

Typical use::

    import jax, jax.numpy as jnp
    import sorjax
    from sorjax import losses

    field = losses.distance_field(outline_points)          # (M, 2) evenly spaced points
    samples = losses.outline_samples(field, 100)             # eq. 20's x_i
    w = losses.sample_weights(field, 100)                    # 0 at corners, else 1
    r = losses.symmetry_residuals(v_x, l_s, samples, field, w)  # w_i d(W x_i), (100,)
    g = jax.grad(lambda v: jnp.sum(losses.symmetry_residuals(v, l_s, samples, field) ** 2))(v_x)

The bundle's residuals for V views, with ``l_s = omega v_x`` built in::

    fields = jax.vmap(losses.distance_field)(points)          # points (V, M, 2)
    samples = jax.vmap(lambda f: losses.outline_samples(f, 100))(fields)
    r = losses.bundle_residuals(jnp.array([fu, fv, u0, v0]), v_x, samples, fields)  # (V, 100)

and :func:`calibrated_intrinsics` re-solves the bundle from a :class:`Calibration`
with implicit differentiation, so ``jax.grad`` / ``jax.jacobian`` of the intrinsics
with respect to the outline points works (sensitivity studies).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from ._bundle import BundleProblem, axis_params, intrinsic_params, residuals, unpack_intrinsics
from ._camera import normalising_transform, omega_matrix, omega_vector_from_intrinsics, pixel_intrinsics
from ._field import DistanceField, curve_points, sample_weights, signed_distance, signed_distances
from ._field import make_field as _make_field
from ._homology import homology_matrix, symmetry_residuals, transfer

__all__ = [
    "DistanceField",
    "bundle_residuals",
    "calibrated_intrinsics",
    "distance_field",
    "homology_matrix",
    "outline_samples",
    "sample_weights",
    "signed_distance",
    "signed_distances",
    "symmetry_residuals",
    "transfer",
]


def distance_field(points: Float[Array, "M 2"], smooth_samples: float = 0.0) -> DistanceField:
    """Smooth signed distance field of a closed outline given by ``M`` points evenly
    spaced in arc length (e.g. ``sorjax.make_outline(x).points``); positive outside.
    ``smooth_samples`` > 0 first smooths the points along the curve (Gaussian, std in
    samples) to suppress the outline's own noise."""
    return _make_field(points, smooth_samples)


def outline_samples(field: DistanceField, n: int) -> Float[Array, "n 2"]:
    """``n`` points evenly spaced along the field's curve (the ``x_i`` of eq. 20)."""
    return curve_points(field, n)


def bundle_residuals(
    intrinsics: Float[Array, "4"],
    v_x: Float[Array, "V 3"],
    samples: Float[Array, "V N 2"],
    fields: DistanceField,
) -> Float[Array, "V N"]:
    """Residuals of the joint estimator: ``d_j(W_j x_ij)`` with
    ``W_j = I - 2 v_j v_j^T omega / (v_j^T omega v_j)``, ``omega = K^-T K^-1`` from
    ``intrinsics = (fu, fv, u0, v0)`` (same units as the points), zero skew."""
    fu, fv, u0, v0 = (intrinsics[i] for i in range(4))
    omega = omega_matrix(omega_vector_from_intrinsics(fu, fv, u0, v0))
    l = v_x @ omega
    return jax.vmap(symmetry_residuals)(v_x, l, samples, fields)


_TIGHT = optx.LevenbergMarquardt(rtol=1e-11, atol=1e-13)


def calibrated_intrinsics(points: Float[Array, "V M 2"], calibration, n_samples: int = 100) -> Float[Array, "4"]:
    """``(fu, fv, u0, v0)`` in pixels from re-solving the bundle on ``points``
    (V outlines, M evenly spaced pixel points each, e.g. the ``make_outline`` points the
    calibration used), starting at ``calibration``'s estimate (its K and vertices) and
    with its aspect-ratio model.  Differentiable in ``points`` by implicit
    differentiation of the optimum (optimistix ``ImplicitAdjoint``); the coordinate
    normalisation and the starting point are constants."""
    pts = np.asarray(jax.lax.stop_gradient(points))
    T = normalising_transform(pts.reshape(-1, 2))
    Tj = jnp.asarray(T)
    pn = points @ Tj[:2, :2].T + Tj[:2, 2]
    fields = jax.vmap(_make_field)(pn)
    samples = jax.vmap(lambda f: curve_points(f, n_samples))(fields)
    weights = jax.vmap(lambda f: sample_weights(f, n_samples))(fields)
    a = calibration.aspect_ratio
    problem = BundleProblem(fields, samples, weights, jnp.asarray(np.nan if a is None else a))
    k0 = intrinsic_params(T @ np.asarray(calibration.K), a is None)
    a0 = axis_params(np.asarray(calibration.l_s) @ np.linalg.inv(T))  # lines map by T^-T
    sol = optx.least_squares(
        residuals, _TIGHT, (k0, a0), args=problem, max_steps=200, throw=False,
        adjoint=optx.ImplicitAdjoint(),
    )
    return pixel_intrinsics(T, *unpack_intrinsics(sol.value[0], problem.aspect))
