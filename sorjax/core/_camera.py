"""Camera intrinsics, the image of the absolute conic, and coordinate normalisation.

Conventions
-----------
Pixels follow OpenCV: the centre of the top-left pixel is ``(0, 0)``, ``x`` grows to
the right and ``y`` downwards.  Homogeneous points are 3-vectors ``(x, y, 1)`` up to
scale; homogeneous lines ``l`` satisfy ``l . x = 0``.

The intrinsics have zero skew::

    K = [[fu, 0, u0],
         [0, fv, v0],
         [0,  0,  1]]          (fu, fv, u0, v0 in pixels)

and the image of the absolute conic (IAC) is ``omega = K^-T K^-1``, which with zero
skew has the form ``[[w1, 0, w2], [0, w3, w4], [w2, w4, w5]]``.  Written out::

    w1 = 1/fu^2, w2 = -u0/fu^2, w3 = 1/fv^2, w4 = -v0/fv^2,
    w5 = u0^2/fu^2 + v0^2/fv^2 + 1.

Inverting that (the closed form of the Cholesky factorisation for zero skew), with
omega known only up to scale::

    u0 = -w2/w1,  v0 = -w4/w3,  lam = w5 - w2^2/w1 - w4^2/w3,
    fu = sqrt(lam/w1),  fv = sqrt(lam/w3),

and omega is positive definite (so a real camera exists) iff, after fixing the sign
so that ``w1 > 0``: ``w3 > 0`` and ``lam > 0``.

Normalisation
-------------
All estimation runs in normalised coordinates ``x_n = T x`` with the isotropic
similarity ``T = [[1/s, 0, -cx/s], [0, 1/s, -cy/s], [0, 0, 1]]``; then
``K_n = T K``, ``omega = T^T omega_n T``, lines map as ``l_n = T^-T l`` and points as
``v_n = T v``.  Being isotropic, ``T`` keeps angles and ratios of distances, so unit
aspect ratio and Method I's orthogonality survive it.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def intrinsics_matrix(fu, fv, u0, v0) -> Float[Array, "3 3"]:
    """``K = [[fu, 0, u0], [0, fv, v0], [0, 0, 1]]`` (pixels; zero skew)."""
    fu, fv, u0, v0 = (jnp.asarray(a, dtype=jnp.float64) for a in (fu, fv, u0, v0))
    z, o = jnp.zeros_like(fu), jnp.ones_like(fu)
    return jnp.stack(
        [jnp.stack([fu, z, u0], -1), jnp.stack([z, fv, v0], -1), jnp.stack([z, z, o], -1)],
        -2,
    )


def omega_vector_from_intrinsics(fu, fv, u0, v0) -> Float[Array, "5"]:
    """The five entries ``(w1, w2, w3, w4, w5)`` of ``omega = K^-T K^-1`` (zero skew)."""
    fu, fv, u0, v0 = (jnp.asarray(a, dtype=jnp.float64) for a in (fu, fv, u0, v0))
    w1, w3 = 1.0 / fu**2, 1.0 / fv**2
    return jnp.stack([w1, -u0 * w1, w3, -v0 * w3, u0**2 * w1 + v0**2 * w3 + 1.0], -1)


def omega_matrix(w: Float[Array, "... 5"]) -> Float[Array, "... 3 3"]:
    """Symmetric 3x3 IAC ``[[w1, 0, w2], [0, w3, w4], [w2, w4, w5]]`` from its 5-vector."""
    w = jnp.asarray(w)
    w1, w2, w3, w4, w5 = (w[..., i] for i in range(5))
    z = jnp.zeros_like(w1)
    return jnp.stack(
        [jnp.stack([w1, z, w2], -1), jnp.stack([z, w3, w4], -1), jnp.stack([w2, w4, w5], -1)],
        -2,
    )


def intrinsics_from_omega_vector(w: Float[Array, "... 5"]):
    """Closed-form zero-skew Cholesky: ``(fu, fv, u0, v0, positive_definite)``.

    ``w`` is omega's 5-vector up to any non-zero scale (sign included).  When omega is
    not positive definite the returned focal lengths are NaN and the flag is False:
    the caller must report that, never turn it into a K.
    """
    w = jnp.asarray(w)
    w = w * jnp.sign(w[..., :1] + jnp.where(w[..., :1] == 0, 1.0, 0.0))
    w1, w2, w3, w4, w5 = (w[..., i] for i in range(5))
    u0 = -w2 / w1
    v0 = -w4 / w3
    lam = w5 - w2**2 / w1 - w4**2 / w3
    pd = (w1 > 0) & (w3 > 0) & (lam > 0)
    fu = jnp.where(pd, jnp.sqrt(jnp.where(pd, lam / w1, 1.0)), jnp.nan)
    fv = jnp.where(pd, jnp.sqrt(jnp.where(pd, lam / w3, 1.0)), jnp.nan)
    return fu, fv, u0, v0, pd


def normalising_transform(points, weights=None):
    """Isotropic similarity ``T`` (3x3) that centres ``points`` (..., P, 2, pixels) on
    their mean and scales their RMS distance from it to ``sqrt(2)``.

    numpy in, numpy out (at the boundary); a JAX array (or tracer) in gives the same
    in ``jax.numpy`` (jit / vmap / grad clean).  ``weights`` (..., P), optional: a
    weighted mean and RMS (0 leaves a point out; the views dropped by a calibration)."""
    xp = np if isinstance(points, np.ndarray) and (weights is None or isinstance(weights, np.ndarray)) else jnp
    points = xp.asarray(points, dtype=xp.float64).reshape(-1, 2)
    w = xp.ones(points.shape[0]) if weights is None else xp.asarray(weights, dtype=xp.float64).reshape(-1)
    sw = xp.maximum(xp.sum(w), 1e-300)
    c = xp.sum(w[:, None] * points, axis=0) / sw
    s = xp.sqrt(xp.sum(w * xp.sum((points - c) ** 2, axis=1)) / sw / 2.0)
    s = xp.where(s > 0, s, 1.0)
    o, z = xp.ones_like(s), xp.zeros_like(s)
    return xp.stack([xp.stack([o / s, z, -c[0] / s]), xp.stack([z, o / s, -c[1] / s]), xp.stack([z, z, o])])


def pixel_intrinsics(T, fu, fv, u0, v0) -> Float[Array, "4"]:
    """``(fu, fv, u0, v0)`` in pixels from intrinsics in the coordinates ``x_n = T x``
    of an isotropic similarity ``T``: ``K = T^-1 K_n`` (differentiable)."""
    s = 1.0 / T[0, 0]
    return jnp.stack([fu * s, fv * s, (u0 - T[0, 2]) * s, (v0 - T[1, 2]) * s])


def transform_points(T, x: Float[Array, "... 2"]) -> Float[Array, "... 2"]:
    """Apply a similarity/affine ``T`` (3x3 with last row (0,0,1)) to inhomogeneous
    points; numpy in (both numpy), numpy out."""
    if not (isinstance(x, np.ndarray) and isinstance(T, np.ndarray)):
        T = jnp.asarray(T)
    return x @ T[:2, :2].T + T[:2, 2]


def angle_between_rays(K, p, q) -> Float[Array, ""]:
    """Angle in degrees between the viewing rays ``K^-1 p`` and ``K^-1 q`` of two
    homogeneous image points (sign-agnostic: ``p`` and ``-p`` are the same point)."""
    Kinv = jnp.linalg.inv(jnp.asarray(K))
    a, b = Kinv @ jnp.asarray(p), Kinv @ jnp.asarray(q)
    c = jnp.abs(a @ b) / (jnp.linalg.norm(a) * jnp.linalg.norm(b))
    return jnp.degrees(jnp.arccos(jnp.clip(c, 0.0, 1.0)))


def angle_between_lines(l, m) -> Float[Array, ""]:
    """Angle in degrees between two image lines' directions (homogeneous, pixels)."""
    a = jnp.asarray(l)[:2]
    b = jnp.asarray(m)[:2]
    s = jnp.abs(a[0] * b[1] - a[1] * b[0])
    c = jnp.abs(a @ b)
    return jnp.degrees(jnp.arctan2(s, c))


def angle_between_planes(K, l, m) -> Float[Array, ""]:
    """Angle in degrees between the planes through the camera centre that two image
    lines back-project to (normals ``K^T l``, ``K^T m``): sensitive to both the
    direction and the position of the lines."""
    K = jnp.asarray(K)
    a, b = K.T @ jnp.asarray(l), K.T @ jnp.asarray(m)
    c = jnp.abs(a @ b) / (jnp.linalg.norm(a) * jnp.linalg.norm(b))
    return jnp.degrees(jnp.arccos(jnp.clip(c, 0.0, 1.0)))
