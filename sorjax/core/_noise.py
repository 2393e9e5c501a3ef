"""The outline noise model behind the bundle's uncertainty: eq. 20's residual covariance.

Residual ``i`` of a view, ``r_i = w_i d(W x_i)`` (``x_i`` a sample at knot parameter
``t_i``, ``w_i`` its weight, ``d`` the outline's signed distance field), reads the
outline's noise in two places: at the sample, which moves with the outline, and at the
target curve near ``W x_i``, whose closest point has parameter ``f_i`` (the foot).  With
``n(t)`` the outline's displacement along its outward normal at parameter ``t``,
to first order::

    r_i = a_i n(t_i) - w_i n(f_i),     a_i = w_i grad d(W x_i) . dW x_i / dx_i nu_i

(``nu_i`` the outward normal at the sample: ``a_i`` is the weighted residual's
sensitivity to its sample's own displacement, a JVP; a curve moved outward by ``n``
lowers the signed distance of a point near it by ``n``).  The noise is taken as a
stationary process along each outline, independent between outlines, of variance
``sigma_n^2`` and Gaussian correlation in arc length ``s`` (pixels)::

    Cov(n(s), n(s')) = sigma_n^2 rho(s - s'),   rho(s) = exp(-s^2 / (4 ell^2))

(the correlation of white noise smoothed by a Gaussian of standard deviation ``ell``,
as :func:`sorjax.scenes.paper_noise` makes it).  So ``Sigma_r = sigma_n^2 S(ell)``
with, per view,

    S_ik = a_i a_k rho(t_i - t_k) - a_i w_k rho(t_i - f_k) - w_i a_k rho(f_i - t_k)
           + w_i w_k rho(f_i - f_k),

and the covariance of least squares is the sandwich ``F^-1 G^T Sigma_r G F^-1``.
Mirror pairs (a foot near another sample) share their noise; so do neighbours when
``ell`` is comparable with the samples' spacing; and ``|a_i|`` varies along the
outline (the homology stretches some parts more than others): all three are in ``S``.

``ell`` and ``sigma_n^2`` are estimated from the residuals by matching moments: the
residuals at the optimum are ``Q r`` with ``Q = I - U U^T`` (``U`` an orthonormal
basis of the Jacobian's columns), so ``E[r r^T] = sigma_n^2 Q S Q``.  On a grid of
``ell`` the correlation of neighbouring residuals and of mirror pairs predicted by
``Q S Q`` is compared with the residuals' own; the closest gives ``ell``, and
``sigma_n^2 = |r|^2 / tr(Q S Q)``.

Measured (two-sphere scene, f = 700 px, the paper's noise at sigma 1 px, ``ell`` = 2 px
by construction; 60 trials): the estimated ``ell`` had median 2.0 px (10-90 %:
1.7-2.4), and the standard deviations from this model matched those from the true noise
covariance pushed through the exact noise Jacobian to 1 %.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._field import DistanceField, curve, curve_points, gaussian_smooth_closed, make_field

# the grid of correlation lengths searched (px): N_ELL quarter octaves up to the
# Options' noise_ell_max_px, none below its noise_ell_min_px (:func:`ell_grid`)
N_ELL = 29


class NoiseGeometry(eqx.Module):
    """Where each residual reads the outline's noise (per view, stacked):
    ``a`` (V, N) the weighted sensitivity to the sample's own displacement, ``w``
    (V, N) the weights (the target's coefficient is ``-w``), ``dist`` (4, V, N, N) the
    arc lengths (px) between sample-sample, sample-foot, foot-sample and foot-foot
    parameters, and ``near``, ``mirror`` (V, N, N) 0/1 masks of the pairs whose
    correlations identify ``ell``: neighbouring samples (within 2.5 samples' spacing)
    and mirror pairs (a foot within 1.5 spacings of the other sample)."""

    a: Float[Array, "V N"]
    w: Float[Array, "V N"]
    dist: Float[Array, "4 V N N"]
    near: Float[Array, "V N N"]
    mirror: Float[Array, "V N N"]


def noise_geometry(a, w, feet, px_per_knot, n_knots: int) -> NoiseGeometry:
    """The :class:`NoiseGeometry` of residuals with sensitivities ``a`` (V, N),
    weights ``w`` (V, N) and feet ``feet`` (V, N) (knot units) on outlines of
    ``n_knots`` knots spaced ``px_per_knot`` (V,) px; the samples at ``t_i = i M / N``."""
    V, N = a.shape
    M = n_knots
    t = jnp.arange(N) * (M / N)
    sp = M / N

    def one(f, h):
        def gap(x, y):
            d = jnp.abs(x[:, None] - y[None, :])
            return jnp.minimum(d, M - d)

        tt, tf, ft, ff = gap(t, t), gap(t, f), gap(f, t), gap(f, f)
        eye = jnp.eye(N, dtype=bool)
        near = (tt < 2.5 * sp) & ~eye
        mirror = (jnp.minimum(ft, tf) < 1.5 * sp) & ~near & ~eye
        return jnp.stack([tt, tf, ft, ff]) * h, near.astype(a.dtype), mirror.astype(a.dtype)

    dist, near, mirror = jax.vmap(one)(feet, px_per_knot)
    return NoiseGeometry(a, w, jnp.moveaxis(dist, 1, 0), near, mirror)


def unit_blocks(geo: NoiseGeometry, ell_px) -> Float[Array, "V N N"]:
    """``S(ell)`` per view: the residuals' covariance for outline noise of unit
    variance (normalised units^2 when ``a``, ``w`` are) and correlation length ``ell`` px
    (one for all views, or (V,) one per view)."""
    ell = jnp.reshape(jnp.asarray(ell_px, geo.a.dtype), (-1, 1, 1))
    rho = jnp.exp(-(geo.dist**2) / (4.0 * ell**2))
    a, w = geo.a, geo.w
    return (a[:, :, None] * a[:, None, :] * rho[0] - a[:, :, None] * w[:, None, :] * rho[1]
            - w[:, :, None] * a[:, None, :] * rho[2] + w[:, :, None] * w[:, None, :] * rho[3])


def ell_grid(ell_min_px, ell_max_px):
    """The correlation lengths :func:`estimate_noise` searches (px): ``N_ELL`` values in
    quarter octaves up to ``ell_max_px``, ``ell_k = ell_max 2^(-(N_ELL - 1 - k) / 4)``
    (ascending), and which of them are searched: those not below ``ell_min_px`` (with
    the defaults, 0.25 to 32 px, all 29).  Quarter octaves because two steps halve
    ``ell^2``: ``rho`` at ``ell_{k-2}`` is ``rho`` at ``ell_k`` squared, so the search
    needs two exponentials, not ``N_ELL``."""
    k = jnp.arange(N_ELL)
    ells = ell_max_px * 2.0 ** (-(N_ELL - 1 - k) / 4.0)
    return ells, ells >= ell_min_px * (1.0 - 1e-12)


def noise_moments(geo: NoiseGeometry, J: Float[Array, "VN p"], ell_min_px, ell_max_px):
    """The moments :func:`estimate_noise` matches, on :func:`ell_grid`: ``(ells, searched,
    m)`` with ``m`` (N_ELL, V, 3) each view's sums ``sum(A_k * S(ell))`` of ``A_k`` the diagonal
    blocks of ``Q P_k Q`` (``P_k`` the identity, the neighbour pairs, the mirror pairs;
    ``Q`` the projector off ``J``'s columns) against the unit-variance residual
    covariance ``S(ell)`` (:func:`unit_blocks`).

    Taken for every ``ell`` at once: ``A_k`` and ``S`` are symmetric, so the two cross
    terms of ``S`` count as one; the sample-sample term depends on the samples' gap
    only (they lie on a lattice), so it is summed over ``N // 2 + 1`` gaps; the
    foot-foot term over the upper triangle; and ``rho`` on the quarter-octave grid
    comes from two exponentials by repeated squaring (relative round-off below 1e-11).
    The same values as building each ``S(ell)`` whole, at about a third of the cost."""
    V, N = geo.a.shape
    # an orthonormal basis of J's columns (rank-revealing: a direction the views do
    # not determine at all adds nothing)
    Uf, s, _ = jnp.linalg.svd(J, full_matrices=False)
    Uf = Uf * (s > 1e-10 * jnp.max(s))[None, :]
    U = Uf.reshape(V, N, -1)

    def projected(P):  # the diagonal blocks of Q P Q, P block-diagonal (V, N, N)
        UP = jnp.einsum("vnp,vnm->vpm", U, P)  # U_v^T P_v
        C = jnp.einsum("vpm,vmq->pq", UP, U)  # sum_v U_v^T P_v U_v
        return (P - jnp.einsum("vnp,vpm->vnm", U, UP) - jnp.einsum("vpn,vmp->vnm", UP, U)
                + jnp.einsum("vnp,pq,vmq->vnm", U, C, U))

    eye = jnp.broadcast_to(jnp.eye(N), (V, N, N))
    A = jnp.stack([projected(eye), projected(geo.near), projected(geo.mirror)])  # (3, V, N, N)
    ells, searched = ell_grid(ell_min_px, ell_max_px)

    # sum(A_k * S(ell)) = sum_j <B_kj, rho_j(ell)> over S's terms a a^T rho_ss,
    # -a w^T rho_sf (twice: the foot-sample term is its transpose) and w w^T rho_ff.
    # rho_ss depends on the samples' gap only (they lie on a lattice, t_i = i M / N):
    # its sum is over N // 2 + 1 gaps; rho_ff is symmetric, 1 on the diagonal: its sum
    # is over the upper triangle (twice) plus a constant.
    a, w = geo.a, geo.w
    i = jnp.arange(N)
    gap = jnp.abs(i[:, None] - i[None, :])
    gap = jnp.minimum(gap, N - gap)
    n_gap = N // 2 + 1
    ss = jnp.transpose(A * (a[:, :, None] * a[:, None, :]), (2, 3, 0, 1)).reshape(N * N, 3, V)
    ss = jax.ops.segment_sum(ss, gap.reshape(-1), n_gap)  # (n_gap, 3, V)
    ss = jnp.transpose(ss, (1, 2, 0))  # (3, V, n_gap)
    x_ss = geo.dist[0][:, 0, :n_gap]  # (V, n_gap): row 0 holds every gap once
    iu, ju = jnp.triu_indices(N, 1)
    ff = A * (w[:, :, None] * w[:, None, :])
    B = jnp.concatenate([ss, (-2.0 * A * (a[:, :, None] * w[:, None, :])).reshape(3, V, -1),
                         2.0 * ff[:, :, iu, ju]], axis=2)  # (3, V, L)
    const = jnp.sum(jnp.diagonal(ff, axis1=2, axis2=3), axis=2).T  # (V, 3): rho_ff = 1 on the diagonal
    x = jnp.concatenate([x_ss, geo.dist[1].reshape(V, -1), geo.dist[3][:, iu, ju]], axis=1) ** 2 / 4.0
    n_pairs = (N_ELL + 1) // 2

    def down(carry, _):  # two grid values, then each squared: two quarter-octaves lower
        e1, e2 = carry
        return (e1 * e1, e2 * e2), jnp.stack([jnp.einsum("kvl,vl->vk", B, e1),
                                              jnp.einsum("kvl,vl->vk", B, e2)]) + const

    top = (jnp.exp(-x / ells[-1] ** 2), jnp.exp(-x / ells[-2] ** 2))
    _, m = jax.lax.scan(down, top, None, length=n_pairs)  # (n_pairs, 2, V, 3): ells[-1 - 2i], ells[-2 - 2i]
    m = m.reshape(2 * n_pairs, V, 3)[:N_ELL][::-1]  # ascending, as ells
    return ells, searched, m


def estimate_noise(geo: NoiseGeometry, r: Float[Array, "V N"], J: Float[Array, "VN p"], ell_min_px, ell_max_px,
                   floor=None, floor_ell=None):
    """``(ell, sigma_n^2)`` from the residuals ``r`` at an optimum of a model with
    Jacobian ``J`` (the module's moment matching over :func:`ell_grid`, the moments
    :func:`noise_moments`; ``sigma_n^2`` in ``r``'s units squared, ``ell`` (V,) each
    view's correlation length, px).  Residuals that are all zero give ``sigma_n^2 = 0``.

    ``floor`` (V,): each view's residual sum of squares counted as at least this
    (``n_j noise_j^2``, a noise floor: :func:`sorjax.core._covariance.floored_rss`), or None.
    ``floor_ell`` (V,): the correlation length (px) of the noise behind each floor
    (NaN or <= 0: unknown), or None.  A view whose floor binds (above its residuals'
    sum of squares) and whose floor's correlation length is known takes that length
    (the nearest grid value): its residuals no longer show its noise (an outline
    averaged with its mirror image is smooth, and would read as noise correlated over
    tens of pixels).  The other views share one length matched to their residuals.
    The level ``sigma_n^2 = sum_j max(|r_j|^2, floor_j) / sum_j tr(Q S_j(ell_j) Q)``
    is one for all views."""
    ells, searched, m = noise_moments(geo, J, ell_min_px, ell_max_px)
    V = r.shape[0]
    rss = jnp.sum(r**2, axis=1)
    floor = jnp.zeros(V) if floor is None else jnp.asarray(floor, r.dtype)
    fell = jnp.full(V, jnp.nan) if floor_ell is None else jnp.asarray(floor_ell, r.dtype)
    known = (floor > rss) & (fell > 0)  # NaN compares False
    use = (~known).astype(r.dtype)
    emp = jnp.stack([jnp.einsum("vn,vnm,vm->v", r, geo.near, r), jnp.einsum("vn,vnm,vm->v", r, geo.mirror, r)])
    emp = (emp @ use) / jnp.maximum(rss @ use, 1e-300)
    mu = jnp.einsum("kvj,v->kj", m, use)
    ratios = mu[:, 1:] / jnp.maximum(mu[:, 0:1], 1e-300)
    miss = jnp.where(searched, jnp.sum((ratios - emp) ** 2, axis=1), jnp.inf)
    k = jnp.argmin(miss)
    # the grid value nearest each known floor length (ell_k = ell_max 2^(-(N_ELL-1-k)/4))
    lo = jnp.argmax(searched)
    kf = jnp.round(N_ELL - 1 + 4.0 * jnp.log2(jnp.where(known, fell, 1.0) / ells[-1])).astype(k.dtype)
    kv = jnp.where(known, jnp.clip(kf, lo, N_ELL - 1), k)
    m0 = jnp.sum(m[kv, jnp.arange(V), 0])
    return ells[kv], jnp.sum(jnp.maximum(rss, floor)) / jnp.maximum(m0, 1e-300)


def knot_spacing_px(field: DistanceField, scale) -> Float[Array, ""]:
    """An outline's knot spacing in pixels (its perimeter over its knots; ``scale``
    pixels per unit of the field)."""
    k = field.knots
    return jnp.sum(jnp.linalg.norm(jnp.roll(k, -1, axis=0) - k, axis=-1)) * scale / k.shape[0]


def sample_normals(field: DistanceField, n: int) -> Float[Array, "n 2"]:
    """Unit outward normals at the ``n`` samples ``t_i = i M / n`` of an outline
    (:func:`sorjax.core._field.curve_points`), whichever way it runs."""
    k = field.knots
    area = 0.5 * jnp.sum(k[:, 0] * jnp.roll(k[:, 1], -1) - jnp.roll(k[:, 0], -1) * k[:, 1])
    t = jnp.arange(n) * (k.shape[0] / n)
    d1 = jax.vmap(lambda s: curve(field, s)[1])(t)
    nrm = jnp.stack([d1[:, 1], -d1[:, 0]], axis=-1)  # outward for a positively oriented curve
    return jnp.where(area < 0, -1.0, 1.0) * nrm / jnp.linalg.norm(nrm, axis=-1, keepdims=True)


def jacobian_and_normal_sensitivity(fn, p, samples: Float[Array, "... 2"], normals: Float[Array, "... 2"]):
    """``(J, r, a)`` of the residuals ``r = fn(p, samples)`` in one forward-mode pass:
    ``J = dr/dp`` (``r``'s shape, then ``p``'s), ``r`` itself, and ``a = d/dt r(p,
    samples + t normals)`` at ``t = 0`` (``r``'s shape): each residual's sensitivity to
    the samples moving along ``normals`` (unit outward normals, :func:`sample_normals`),
    the ``a_i`` of this module's noise model.  Units: ``a`` is ``r``'s units per unit of
    the samples' coordinates."""

    def moved(p, t):
        r = fn(p, samples + t * normals)
        return r, r

    (J, a), r = jax.jacfwd(moved, argnums=(0, 1), has_aux=True)(p, jnp.zeros((), samples.dtype))
    return J, r, a


def smoothed_outline(field: DistanceField, n: int, smooth_px, scale):
    """``(field, samples)`` of the outline smoothed along the curve by a Gaussian of
    ``smooth_px`` px (``scale`` px per unit): where a covariance reads its Jacobian,
    the noise's tilt of the normals averaged out."""
    sm = make_field(gaussian_smooth_closed(field.knots, smooth_px / knot_spacing_px(field, scale)))
    return sm, curve_points(sm, n)


def noise_meat(G: Float[Array, "VN q"], blocks: Float[Array, "V N N"]) -> Float[Array, "q q"]:
    """``G^T Sigma_r G`` for a block-diagonal ``Sigma_r`` (one block per view)."""
    V, N = blocks.shape[:2]
    Gv = G.reshape(V, N, -1)
    return jnp.einsum("vnp,vnm,vmq->pq", Gv, blocks, Gv)
