"""The paper's linear methods: Method I (Sec. 5.2.1) and Method II (Sec. 5.2.2).

All functions are pure ``jax.numpy`` on stacked per-view homologies ``v`` (V, 3) and
``l`` (V, 3), in *normalised* coordinates (an isotropic similarity of the pixels, see
:mod:`sorjax.core._camera`), so they ``jit`` and ``vmap`` over trials.  Each returns the
intrinsics ``(fu, fv, u0, v0)`` in those coordinates and a validity flag.

Method II (eqs. 27-28).  The pole-polar constraint ``omega v ~ l`` says that
``m = omega v`` is parallel to ``l``.  With zero skew ``m = B(v) w`` is linear in
``w = (w1, ..., w5)``::

    B(v) = [[v1, v3, 0,  0,  0 ],
            [0,  0,  v2, v3, 0 ],
            [0,  v1, 0,  v2, v3]],

and ``m || l`` is ``p^T B(v) w = q^T B(v) w = 0`` for an orthonormal basis ``p, q`` of
the plane orthogonal to ``l``.  These are exactly the paper's eqs. 27-28 (which are two
rows of ``(omega v) x l = 0``) recombined so that they never lose rank (eqs. 27-28
become dependent when ``l_3 = 0``, i.e. when the axis passes through the origin of the
coordinates).  ``v`` and ``l`` are scaled to unit norm first.  IIa solves for ``w`` as
the right singular vector of the smallest singular value; IIb imposes unit aspect
ratio, ``w1 = w3``.  Optional per-view weights multiply each view's two rows.

Method I (eqs. 21-23, zero skew and unit aspect).  ``l_x = (l2 v3, -l1 v3,
l1 v2 - l2 v1)`` is the line through ``v`` orthogonal to ``l``; the principal point is
the least-squares intersection of the ``l_x`` (each scaled to ``a^2 + b^2 = 1``), and
``f = mean_i sqrt(dist(x0_i, v_i) dist(x0_i, l_i))`` with ``x0_i`` the principal
point projected onto ``l_x,i`` (by default a mean weighted by each view's sensitivity
to the principal point, see :func:`method_i`).  A known aspect ratio ``a = fu/fv`` is handled by
eqs. 24-26: map ``v -> diag(1/a, 1, 1) v`` and ``l -> diag(a, 1, 1) l``, solve, then
``u0 = a u0'``, ``fu = a f``, ``fv = f`` (do that mapping in pixels, before
normalising).  Views whose ``v`` is at infinity (``|v3| ~ 0``) give no ``l_x`` and
are left out; Method I needs two views with finite, distinct ``l_x``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._camera import intrinsics_from_omega_vector, intrinsics_matrix, omega_matrix, omega_vector_from_intrinsics


def _unit(x):
    return x / jnp.linalg.norm(x, axis=-1, keepdims=True)


def pole_polar_rows(v: Float[Array, "V 3"], l: Float[Array, "V 3"]) -> Float[Array, "2V 5"]:
    """The 2 linear constraints per view on ``w`` (see module docstring)."""
    v, l = _unit(v), _unit(l)
    v1, v2, v3 = v[:, 0], v[:, 1], v[:, 2]
    z = jnp.zeros_like(v1)
    B = jnp.stack(
        [jnp.stack([v1, v3, z, z, z], -1), jnp.stack([z, z, v2, v3, z], -1), jnp.stack([z, v1, z, v2, v3], -1)],
        -2,
    )  # (V, 3, 5)
    # orthonormal basis of l's orthogonal complement, built without branches
    a = jnp.where(jnp.abs(l[:, :1]) < 0.6, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
    p = _unit(jnp.cross(l, a))
    q = jnp.cross(l, p)
    rows = jnp.stack([jnp.einsum("vi,vij->vj", p, B), jnp.einsum("vi,vij->vj", q, B)], 1)
    return rows.reshape(-1, 5)


@jax.custom_jvp
def null_vector(A: Float[Array, "m n"]) -> Float[Array, " n"]:
    """The unit right singular vector of ``A``'s smallest singular value (SVD; ``m``
    may be below ``n``), differentiable: the smallest eigenvector ``w`` of ``M = A^T
    A``, whose derivative is ``dw = -(M - lambda_0)^+ dM w`` (first-order perturbation
    theory, the other eigenvectors of ``M``; JAX's SVD has no derivative with
    ``full_matrices=True``).  What the linear methods' first-order covariance
    differentiates through."""
    return jnp.linalg.svd(A, full_matrices=True)[2][-1]


@null_vector.defjvp
def _null_vector_jvp(primals, tangents):
    (A,), (dA,) = primals, tangents
    w = null_vector(A)
    lam, U = jnp.linalg.eigh(A.T @ A)
    dM = dA.T @ A + A.T @ dA
    gap = lam - lam[0]
    inv = jnp.where(gap > 0, 1.0 / jnp.where(gap > 0, gap, 1.0), 0.0).at[0].set(0.0)
    return w, -(U * inv) @ (U.T @ (dM @ w))


@functools.partial(jax.jit, static_argnames=("unit_aspect",))
def method_ii(v, l, *, unit_aspect: bool, weights=None):
    """Method IIa (``unit_aspect=False``) or IIb (``True``).

    Returns ``(fu, fv, u0, v0, ok, w)`` in the coordinates of ``v, l``; ``ok`` is False
    when the estimated omega is not positive definite (then fu, fv are NaN)."""
    A = pole_polar_rows(v, l)
    if weights is not None:
        A = A * jnp.repeat(jnp.asarray(weights), 2)[:, None]
    if unit_aspect:
        A4 = jnp.stack([A[:, 0] + A[:, 2], A[:, 1], A[:, 3], A[:, 4]], -1)
        w4 = null_vector(A4)
        w = jnp.stack([w4[0], w4[1], w4[0], w4[2], w4[3]])
    else:
        w = null_vector(A)
    fu, fv, u0, v0, ok = intrinsics_from_omega_vector(w)
    return fu, fv, u0, v0, ok, w


@functools.partial(jax.jit, static_argnames=("weighted",))
def method_i(v, l, *, finite_tol: float = 1e-9, weighted: bool = True, used=None):
    """Method I (unit aspect ratio, zero skew).

    ``weighted=False`` is eq. 23 as printed, the plain mean of the per-view
    ``f_i = sqrt(d_v d_l)`` (``d_v = dist(x0_i, v_i)``, ``d_l = dist(x0_i, l_i)``,
    ``d_v d_l = f_i^2``).  ``weighted=True`` (default) weighs each ``f_i`` by
    ``1 / (1 + s_i^2)`` with ``s_i = |d_v - d_l| / (2 f_i)``, the derivative of ``f_i``
    with respect to the principal point moving along ``l_x`` (eq. 22's error reaches
    every ``f_i`` that way).  For an ordinary view ``s_i`` is below about 1 and the
    weights are nearly equal; for a view whose ``v_x`` lies thousands of focal lengths
    away (the optical axis nearly in the plane through the revolution axis) ``d_l`` is a
    fraction of a pixel and ``s_i ~ d_v / 2f`` is huge: a principal point 1e-4 px off
    moved such a view's ``f_i`` by a percent, and the plain mean with it.  Both agree
    exactly on exact homologies.

    ``used`` (V,) bool, optional: the views to use (a masked view gets zero weight,
    whatever its homology holds).

    Returns ``(f, f, u0, v0, ok)`` in the coordinates of ``v, l``.  ``ok`` is False when
    fewer than two views have a finite vertex or their lines ``l_x`` are parallel."""
    if used is not None:
        v, l = masked_homologies(v, l, used)
    v, l = _unit(v), _unit(l)
    l1, l2 = l[:, 0], l[:, 1]
    v1, v2, v3 = v[:, 0], v[:, 1], v[:, 2]
    lx = jnp.stack([l2 * v3, -l1 * v3, l1 * v2 - l2 * v1], -1)
    finite = jnp.abs(v3) > finite_tol
    if used is not None:
        finite = finite & jnp.asarray(used, bool)
    nrm = jnp.linalg.norm(lx[:, :2], axis=-1)
    wgt = jnp.where(finite & (nrm > 0), 1.0, 0.0)
    lx = lx / jnp.where(nrm > 0, nrm, 1.0)[:, None]
    A = lx[:, :2] * wgt[:, None]
    b = -lx[:, 2] * wgt
    N = A.T @ A
    det = jnp.linalg.det(N)
    ok = (jnp.sum(wgt) >= 2) & (det > 1e-12 * jnp.trace(N) ** 2)
    x0 = jnp.linalg.solve(jnp.where(ok, N, jnp.eye(2)), A.T @ b)
    # project x0 onto each l_x, distances to v (inhomogeneous) and to l
    s = lx[:, :2] @ x0 + lx[:, 2]
    x0i = x0[None, :] - s[:, None] * lx[:, :2]
    vin = v[:, :2] / jnp.where(finite, v3, 1.0)[:, None]
    dv = jnp.linalg.norm(x0i - vin, axis=-1)
    dl = jnp.abs(jnp.sum(x0i * l[:, :2], -1) + l[:, 2]) / jnp.linalg.norm(l[:, :2], axis=-1)
    fi = jnp.sqrt(dv * dl)
    if weighted:
        sens = jnp.abs(dv - dl) / (2.0 * jnp.maximum(fi, 1e-300))
        wgt = wgt / (1.0 + jnp.where(wgt > 0, sens, 0.0) ** 2)
    f = jnp.sum(jnp.where(wgt > 0, fi, 0.0) * wgt) / jnp.maximum(jnp.sum(wgt), 1e-300)
    f = jnp.where(ok, f, jnp.nan)
    return f, f, x0[0], x0[1], ok


# ------------------------------------------------------------------ masked, pure
#
# The functional core's linear methods: views are masked, never removed (a (V,) bool
# ``used``).  A masked view's homology may hold anything (NaN included): it is replaced
# by a harmless placeholder before any arithmetic, and its rows / weight are zero, so
# the estimate equals the one of the used views alone.

_PLACEHOLDER_V = (0.0, 0.0, 1.0)
_PLACEHOLDER_L = (1.0, 0.0, 0.0)
LINEAR_METHODS = ("IIa", "IIb", "I")  # the order of :func:`linear_estimates` (and of the bundle's seeds)


def masked_homologies(v, l, used):
    """``(v, l)`` (V, 3) with the masked views' rows replaced by a finite placeholder."""
    used = jnp.asarray(used, bool)[:, None]
    v = jnp.where(used, v, jnp.asarray(_PLACEHOLDER_V, dtype=jnp.result_type(v, jnp.float64)))
    l = jnp.where(used, l, jnp.asarray(_PLACEHOLDER_L, dtype=jnp.result_type(l, jnp.float64)))
    return v, l


def _aspect_map(aspect):
    """``A = diag(1/a, 1, 1)`` (eqs. 24-26)."""
    a = jnp.asarray(aspect, jnp.float64)
    return jnp.diag(jnp.stack([1.0 / a, jnp.ones_like(a), jnp.ones_like(a)]))


def conditioning_from_K(K, aspect=1.0):
    """The isotropic normalisation ``T = K'^-1`` for an estimate ``K`` (``K' = A K``,
    ``A = diag(1/a, 1, 1)``): there omega is close to the identity, the best
    conditioning for Method II's linear system.  Traced."""
    s, cx, cy = K[1, 1], K[0, 2] / aspect, K[1, 2]
    z, o = jnp.zeros_like(s), jnp.ones_like(s)
    return jnp.stack([jnp.stack([o / s, z, -cx / s]), jnp.stack([z, o / s, -cy / s]), jnp.stack([z, z, o])])


def _once(v, l, used, TA, method: str, weights):
    """One pass of ``method`` in the coordinates ``x' = TA x``: ``(K, omega, ok)`` px."""
    vn = v @ TA.T
    ln = l @ jnp.linalg.inv(TA)
    if method == "I":
        fu, fv, u0, v0, ok = method_i(vn, ln, used=used)
    else:
        w = jnp.asarray(used, jnp.float64) * (1.0 if weights is None else jnp.asarray(weights, jnp.float64))
        fu, fv, u0, v0, ok, _ = method_ii(vn, ln, unit_aspect=(method == "IIb"), weights=w)
    K = jnp.linalg.solve(TA, intrinsics_matrix(fu, fv, u0, v0))
    omega = TA.T @ omega_matrix(omega_vector_from_intrinsics(fu, fv, u0, v0)) @ TA
    return K, omega, ok


@functools.partial(jax.jit, static_argnames=("method",))
def linear_estimate(v_pix, l_pix, used, T, aspect=1.0, *, method: str, weights=None):
    """``method`` ("I", "IIa" or "IIb") on the used views' pixel homologies, with the
    two-pass conditioning of :func:`sorjax._calibration.linear_calibration`: solved in
    the coordinates ``T A`` (``T`` the joint normalising similarity, ``A = diag(1/a,
    1, 1)`` the aspect map; ``aspect`` 1 for unit), and for Method II again in the
    coordinates normalised by that first estimate -- or by Method I's when the first is
    not positive definite -- the second kept where it succeeds or the first failed.

    Pure (jit / vmap / grad): ``v_pix, l_pix`` (V, 3), ``used`` (V,) bool, ``T`` (3, 3),
    ``aspect`` a scalar (1.0 for unit; ignored by IIa, which estimates it), optional
    per-view ``weights`` (V,) for Method II.  Returns ``(K, omega, ok)`` in pixels;
    ``ok`` False: Method I degenerate, or omega not positive definite (Method II)."""
    used = jnp.asarray(used, bool)
    v, l = masked_homologies(jnp.asarray(v_pix, jnp.float64), jnp.asarray(l_pix, jnp.float64), used)
    a = jnp.asarray(1.0 if method == "IIa" else aspect, jnp.float64)
    A = _aspect_map(a)
    K1, om1, ok1 = _once(v, l, used, T @ A, method, weights)
    if method == "I":
        return K1, om1, ok1
    KI, _, okI = _once(v, l, used, T @ A, "I", None)
    guess = jnp.where(ok1, K1, KI)
    have = (ok1 | okI) & jnp.all(jnp.isfinite(guess))
    T2 = conditioning_from_K(jnp.where(have, guess, jnp.eye(3)), a)
    K2, om2, ok2 = _once(v, l, used, T2 @ A, method, weights)
    second = have & (ok2 | ~ok1)
    return jnp.where(second, K2, K1), jnp.where(second, om2, om1), jnp.where(second, ok2, ok1)


@jax.jit
def linear_estimates(v_pix, l_pix, used, T, aspect=1.0):
    """The three methods of :data:`LINEAR_METHODS` ("IIa", "IIb", "I") in one call:
    ``(K (3, 3, 3), omega (3, 3, 3), ok (3,))`` px, stacked in that order (IIa with a
    free aspect ratio, IIb and I with ``aspect``)."""
    outs = [linear_estimate(v_pix, l_pix, used, T, aspect, method=m) for m in LINEAR_METHODS]
    return tuple(jnp.stack(x) for x in zip(*outs))


@jax.jit
def focal_from_principal_point(v_pix, l_pix, used, pp, aspect=1.0):
    """The focal length ``f = fv`` (px, ``fu = aspect f``) from the used views' homologies
    and a known principal point ``pp = (u0, v0)`` px: the single-view case of Wong,
    Mendonca and Cipolla (IVC 2004), in least squares over the views.

    With the principal point moved to the origin and the aspect map ``A = diag(1/a, 1,
    1)`` applied (``v -> A v``, ``l -> A^-T l``, eqs. 24-26), ``omega = diag(w, w, 1)``
    with ``w = 1 / f^2``, and the pole-polar relation ``omega v ~ l`` is
    ``(omega v) x l = 0``, three equations linear in ``w`` (two independent)::

        w (v2 l3, -v1 l3, v1 l2 - v2 l1) = (v3 l2, -v3 l1, 0)

    (``v``, ``l`` scaled to unit norm).  One view gives two constraints on one unknown:
    ``f^2 = dist(pp, v_x) dist(pp, l_s)`` (eq. 23) when the principal point lies on the
    line through ``v_x`` orthogonal to ``l_s``; the component orthogonal to that is the
    residual the bundle then minimises.  Stacked over the used views, ``w = sum A.b /
    sum A.A``.  Degenerate: ``v_x`` at infinity (``v3 = 0``; then ``l_s`` passes through
    the principal point, ``l3 = 0``): no equation involves ``w`` (the camera looks
    straight at the axis; the focal length is free).

    Pure (jit / vmap).  Returns ``(f, ok)``: ``ok`` when ``w > 0`` and finite (``w <= 0``:
    ``v_x`` and ``l_s`` on the same side of the principal point, no real camera; ``w =
    0``: every ``v_x`` at infinity)."""
    used = jnp.asarray(used, bool)
    v, l = masked_homologies(jnp.asarray(v_pix, jnp.float64), jnp.asarray(l_pix, jnp.float64), used)
    pp = jnp.asarray(pp, jnp.float64)
    a = jnp.asarray(aspect, jnp.float64)
    # x' = A (x - pp): points by M = A Tr, lines by M^-T
    M = _aspect_map(a) @ jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]).at[:2, 2].set(-pp)
    vn = _unit(v @ M.T)
    ln = _unit(l @ jnp.linalg.inv(M))
    A = jnp.stack([vn[:, 1] * ln[:, 2], -vn[:, 0] * ln[:, 2], vn[:, 0] * ln[:, 1] - vn[:, 1] * ln[:, 0]], axis=1)
    b = jnp.stack([vn[:, 2] * ln[:, 1], -vn[:, 2] * ln[:, 0], jnp.zeros_like(vn[:, 0])], axis=1)
    m = used[:, None].astype(jnp.float64)
    den = jnp.sum(m * A * A)
    w = jnp.sum(m * A * b) / jnp.where(den > 0, den, 1.0)
    ok = (den > 0) & (w > 0) & jnp.isfinite(w) & jnp.all(jnp.isfinite(pp))
    return jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, w, 1.0)), jnp.nan), ok
