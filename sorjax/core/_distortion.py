"""OpenCV's radial lens distortion (k1, k2, ...; no tangential terms) and its inverse.

The model, in camera-normalised coordinates ``m = K^-1 x`` (``x`` in pixels, or in any
frame ``x' = T x`` of a similarity ``T`` with ``K' = T K``: the two ``T`` cancel)::

    q = |m|^2,   g(q) = 1 + k1 q + k2 q^2 (+ k3 q^3 ...),   m_d = g(q) m,
    x_d = K m_d,

i.e. OpenCV's ``cv2.projectPoints`` with ``distCoeffs = (k1, k2, 0, 0[, k3])``: the
distortion is radial about the principal point ``(u0, v0)``, its coefficients are
dimensionless (``q`` is a squared tangent of the angle off the optical axis), and it is
the same whatever pixel frame ``K`` is expressed in.

The inverse (undistortion) solves ``s g(s^2 q_d) = 1`` for the scale ``s = |m| / |m_d|``
(``q_d = |m_d|^2``, no square root: smooth at the principal point) by
:data:`NEWTON_STEPS` Newton steps from ``s = 1`` (slope floored at
:data:`SLOPE_FLOOR`: finite everywhere); then ``m = s m_d``.  For barrel
distortion (``k1 < 0, k2 = 0``) the function is concave and increasing in ``s`` and the
steps approach the root monotonically from below; for pincushion (``k1 > 0``) convex,
from above.  The model is one-to-one only while the radial map ``rho -> rho g(rho^2)``
is increasing, ``1 + 3 k1 rho^2 + 5 k2 rho^4 > 0`` (:func:`monotone_radius`); outside
that no inverse exists and the result is meaningless.  Within 90 % of that radius the
round trip is exact to rounding (1e-10 px and better, ``tests/test_distortion.py``).

Everything is ``jax.numpy`` float64, jit / vmap / grad clean; derivatives of
:func:`undistort` go through the unrolled Newton steps, which at convergence equal the
implicit-function derivatives (to first and second order, checked against finite
differences in the tests).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

NEWTON_STEPS = 8  # from s = 1: converged to rounding within 0.9 of the monotone radius (tests)
# The Newton steps divide by the radial map's slope, floored here: beyond the monotone
# radius (no inverse) the result stays finite instead of NaN; within 0.97 of it the
# slope at every iterate is above the floor, so nothing changes there.
SLOPE_FLOOR = 0.05


def _radial(q, k):
    """``g(q) = 1 + k1 q + k2 q^2 + ...`` for coefficients ``k`` (n,), any batch of ``q``."""
    g = jnp.zeros_like(q)
    for i in range(k.shape[-1] - 1, -1, -1):  # Horner
        g = (g + k[i]) * q
    return 1.0 + g


def _radial_slope(q, k):
    """``d(rho g(rho^2)) / d rho = 1 + 3 k1 q + 5 k2 q^2 + ...`` at ``q = rho^2``."""
    g = jnp.zeros_like(q)
    for i in range(k.shape[-1] - 1, -1, -1):
        g = (g + (2 * i + 3) * k[i]) * q
    return 1.0 + g


def _to_normalised(x, K):
    """``m = K^-1 x`` for inhomogeneous ``x`` (..., 2) and upper-triangular ``K``."""
    my = (x[..., 1] - K[1, 2]) / K[1, 1]
    mx = (x[..., 0] - K[0, 2] - K[0, 1] * my) / K[0, 0]
    return jnp.stack([mx, my], axis=-1)


def _from_normalised(m, K):
    """``x = K m`` (inhomogeneous)."""
    return jnp.stack([K[0, 0] * m[..., 0] + K[0, 1] * m[..., 1] + K[0, 2], K[1, 1] * m[..., 1] + K[1, 2]], axis=-1)


def distort_normalised(m: Float[Array, "... 2"], k: Float[Array, " n"]) -> Float[Array, "... 2"]:
    """``m_d = g(|m|^2) m``: camera-normalised coordinates distorted by the radial
    coefficients ``k = (k1, k2, ...)``."""
    k = jnp.asarray(k, jnp.float64)
    q = jnp.sum(m * m, axis=-1)
    return m * _radial(q, k)[..., None]


def undistort_normalised(m_d: Float[Array, "... 2"], k: Float[Array, " n"]) -> Float[Array, "... 2"]:
    """The inverse of :func:`distort_normalised`: ``NEWTON_STEPS`` Newton steps on
    ``f(s) = s g(s^2 q_d) - 1`` from ``s = 1``, ``m = s m_d``."""
    k = jnp.asarray(k, jnp.float64)
    qd = jnp.sum(m_d * m_d, axis=-1)

    def step(_, s):
        q = s * s * qd
        return s - (s * _radial(q, k) - 1.0) / jnp.maximum(_radial_slope(q, k), SLOPE_FLOOR)

    # a loop, not unrolled: the same arithmetic, an eighth of the program to compile
    return m_d * jax.lax.fori_loop(0, NEWTON_STEPS, step, jnp.ones_like(qd))[..., None]


def distort(x: Float[Array, "... 2"], K: Float[Array, "3 3"], k: Float[Array, " n"]) -> Float[Array, "... 2"]:
    """Distort ideal (pinhole) image points ``x`` (..., 2): ``K d(K^-1 x)``.

    ``x`` and ``K`` in pixels (or both in one normalised frame ``T x``, ``T K``);
    ``k = (k1, k2)`` (or ``(k1,)``, or ``(k1, k2, k3)``: OpenCV's radial terms)."""
    K = jnp.asarray(K, jnp.float64)
    return _from_normalised(distort_normalised(_to_normalised(jnp.asarray(x, jnp.float64), K), k), K)


def undistort(x: Float[Array, "... 2"], K: Float[Array, "3 3"], k: Float[Array, " n"]) -> Float[Array, "... 2"]:
    """Ideal (pinhole) image points of distorted points ``x`` (..., 2): the inverse of
    :func:`distort` (``cv2.undistortPoints(x, K, dist, P=K)``, to rounding rather
    than OpenCV's fixed-point iterations).  Units as :func:`distort`."""
    K = jnp.asarray(K, jnp.float64)
    return _from_normalised(undistort_normalised(_to_normalised(jnp.asarray(x, jnp.float64), K), k), K)


def monotone_radius(k) -> Float[Array, ""]:
    """The largest undistorted normalised radius ``rho`` up to which the radial map
    ``rho g(rho^2)`` increases (``1 + 3 k1 rho^2 + 5 k2 rho^4 > 0``): the model is
    invertible inside it; ``inf`` when it increases everywhere.  (k1, k2) only."""
    k = jnp.asarray(k, jnp.float64)
    k1 = k[0]
    k2 = k[1] if k.shape[0] > 1 else jnp.zeros_like(k1)
    # smallest positive root q of 1 + 3 k1 q + 5 k2 q^2
    disc = 9.0 * k1**2 - 20.0 * k2
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    safe2 = jnp.where(k2 == 0, 1.0, k2)
    roots = jnp.stack([(-3.0 * k1 - sq) / (10.0 * safe2), (-3.0 * k1 + sq) / (10.0 * safe2)])
    roots = jnp.where((k2 != 0) & (disc >= 0) & (roots > 0), roots, jnp.inf)
    lin = jnp.where(k1 < 0, -1.0 / (3.0 * jnp.where(k1 < 0, k1, -1.0)), jnp.inf)
    q = jnp.where(k2 == 0, lin, jnp.min(roots))
    return jnp.sqrt(q)


def opencv_coefficients(k) -> Float[Array, "5"]:
    """OpenCV's ``distCoeffs`` ``(k1, k2, p1, p2, k3)`` of radial coefficients ``k``
    (``(k1,)``, ``(k1, k2)`` or ``(k1, k2, k3)``; tangential terms zero).  numpy."""
    import numpy as np

    k = np.asarray(k, dtype=np.float64).reshape(-1)
    if k.size > 3:
        raise ValueError(f"at most three radial coefficients (k1, k2, k3), got {k.size}")
    out = np.zeros(5)
    out[: min(k.size, 2)] = k[:2]
    if k.size == 3:
        out[4] = k[2]
    return out
