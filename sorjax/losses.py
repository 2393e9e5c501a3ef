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
(or a :class:`BundleStart` of arrays, to ``jax.vmap`` over trials) with implicit
differentiation, so ``jax.grad`` / ``jax.jacobian`` of the intrinsics with respect to
the outline points works (sensitivity studies).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .core._model import (BundleProblem, axis_params, residuals, unpack_intrinsics)
from .core._camera import normalising_transform, omega_matrix, omega_vector_from_intrinsics, pixel_intrinsics
from .core._field import DistanceField, curve_points, sample_weights, setup, signed_distance, signed_distances
from .core._field import make_field as _make_field
from .core._solvers import Method, least_squares
from .core._symmetry import homology_matrix, symmetry_residuals, transfer

__all__ = [
    "BundleStart",
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


_TIGHT = Method(True, 1e-11, 1e-13)  # Levenberg-Marquardt
_POLISH = Method(False, 1e-13, 1e-15)  # Gauss-Newton
_POLISH_STEPS = 6


class BundleStart(eqx.Module):
    """Where :func:`calibrated_intrinsics` starts its solve, as arrays (pixels): ``K``
    (3, 3, zero skew) and one axis ``l_s`` (V, 3) per view, with the aspect-ratio model
    (``aspect_ratio``: the known ``fu / fv``, or None to estimate it; static, so it
    selects the compiled program).  Stack starts over trials (``jax.tree.map(lambda *x:
    jnp.stack(x), *starts)``) and ``jax.vmap`` over them; a :class:`sorjax.Calibration`
    converts by :meth:`of`."""

    K: Float[Array, "3 3"]
    l_s: Float[Array, "V 3"]
    aspect_ratio: float | None = eqx.field(static=True, default=None)

    @classmethod
    def of(cls, calibration) -> "BundleStart":
        """The start a :class:`sorjax.Calibration` holds: its ``K``, ``l_s`` and
        ``aspect_ratio`` (its ``l_s`` rows are those of the views it used)."""
        a = calibration.aspect_ratio
        return cls(jnp.asarray(calibration.K, jnp.float64), jnp.asarray(calibration.l_s, jnp.float64),
                   None if a is None else float(a))


def _start_chart(T, start: BundleStart, n_views: int):
    """The bundle's solver chart (:func:`sorjax.core._model.unpack_intrinsics`,
    :func:`sorjax.core._model.axis_params`) at ``start``, in the coordinates ``x_n = T x``."""
    Kn = T @ start.K
    if start.aspect_ratio is None:
        k0 = jnp.stack([jnp.log(Kn[0, 0]), jnp.log(Kn[1, 1]), Kn[0, 2], Kn[1, 2]])
    else:
        k0 = jnp.stack([jnp.log(Kn[1, 1]), Kn[0, 2], Kn[1, 2]])
    a0 = axis_params(start.l_s @ jnp.linalg.inv(T))  # lines map by T^-T
    if a0.shape[0] != n_views:
        raise ValueError(f"the start has {a0.shape[0]} axes l_s for {n_views} outlines")
    return k0, a0


def calibrated_intrinsics(
    points: Float[Array, "V M 2"], start, n_samples: int = 100, max_steps: int = 200
) -> Float[Array, "4"]:
    """``(fu, fv, u0, v0)`` in pixels from re-solving the bundle on ``points``
    (V outlines, M evenly spaced pixel points each, e.g. the ``make_outline`` points the
    calibration used), with ``n_samples`` samples per outline.

    ``start``: a :class:`sorjax.Calibration` (its K, axes and aspect-ratio model; when
    it dropped views and ``points`` holds all of them, the views it used are taken) or
    a :class:`BundleStart` of arrays, which ``jax.vmap`` maps over trials::

        starts = jax.tree.map(lambda *x: jnp.stack(x), *[BundleStart.of(c) for c in cals])
        f = jax.jit(jax.vmap(lambda p, s: calibrated_intrinsics(p, s, 40)))
        k = f(points, starts)                     # points (trials, V, M, 2) -> (trials, 4)

    Pure (jit / vmap / grad clean).  Differentiable in ``points`` by implicit
    differentiation of the optimum (:func:`sorjax.core._solvers.implicit_minimum`); the coordinate
    normalisation (computed from ``points`` under ``stop_gradient``) and the start are
    constants.  The solve is Levenberg-Marquardt to a relative step of 1e-11 within
    ``max_steps``; it does not raise when it runs out of steps (start it at a
    calibration's estimate, which is near the optimum)."""
    if not isinstance(start, BundleStart):
        used = tuple(getattr(start, "used", ()))
        start = BundleStart.of(start)
        if used and len(used) == start.l_s.shape[0] and len(used) < points.shape[0]:
            points = jnp.asarray(points)[jnp.asarray(used)]
    points = jnp.asarray(points, dtype=jnp.float64)
    T = jax.lax.stop_gradient(normalising_transform(jax.lax.stop_gradient(points)))
    pn = points @ T[:2, :2].T + T[:2, 2]
    fields, samples, weights = jax.vmap(lambda p: setup(p, n_samples))(pn)
    a = start.aspect_ratio
    y0 = jax.lax.stop_gradient(_start_chart(T, start, points.shape[0]))
    args = BundleProblem(fields, samples, weights, jnp.asarray(jnp.nan if a is None else a, jnp.float64))
    y, _, _ = least_squares(residuals, y0, args, _TIGHT, max_steps)
    # Levenberg-Marquardt may stop on a step its damping shrank (~1e-9 short of the
    # optimum); a few undamped Gauss-Newton steps settle it to rounding, which finite
    # differences of a single outline point (1e-4 px) need.  Gradients: implicit, at
    # this optimum (the first solve's output is only a start), by the core's one
    # mechanism (:func:`sorjax.core._solvers.implicit_minimum`).
    y, _, _ = least_squares(residuals, jax.lax.stop_gradient(y), args, _POLISH, _POLISH_STEPS)
    return pixel_intrinsics(T, *unpack_intrinsics(y[0], args.aspect))
