"""The automatic starts of the per-view fit (:func:`sorjax.core._viewfit.fit_view`), a
fixed-size set computed inside the program, in one view's normalised coordinates
(:mod:`sorjax.core._prepare`):

* bitangents of the convex hull (paper, Section 5.1): the hull's vertices are the
  outline points extreme along ``HULL_DIRECTIONS`` directions; a pocket is a gap
  between consecutive hull vertices along the curve, its depth the largest distance of
  the skipped points from the chord (``jax.ops.segment_max``); the ``MAX_POCKETS``
  deepest pockets deeper than ``0.03`` of the RMS radius, their ends moved to the exact
  hull edge (:func:`_exact_edge`: the same touching points as an exact convex hull),
  give their 6 pairs;
* mirror symmetries on a grid of axis directions and offsets, the ``MIRROR_KEEP``
  lowest local minima over the directions (top-k over the masked minima);
* for a nearly conic outline (conic residual below ``NEAR_CONIC``), the
  ``CONIC_DIRECTIONS`` pole-polar pairs of its best-fitting conic;

``N_STARTS`` (45) slots in all, an unused slot masked (``valid`` False): the same
starts as the host code this replaces.  Each start is a homology ``(v, l)``: ``v`` the
vertex, ``l`` the axis (homogeneous, normalised coordinates).

Everything here is jit / vmap clean: no host syncs, no Python control flow on values.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._symmetry import homology_matrix, transfer

# ------------------------------------------------------------------ fixed sizes

HULL_DIRECTIONS = 256  # hull vertices: the points extreme along these directions
MAX_POCKETS = 4  # deepest concavities kept: their 6 pairs are bitangent starts
POCKET_DEPTH = 0.03  # a pocket counts when deeper than this fraction of the RMS radius
MIRROR_DIRECTIONS = 48
MIRROR_OFFSETS = (-0.3, -0.15, 0.0, 0.15, 0.3)
MIRROR_KNOTS = 64  # the grid's cost: distance to the nearest of these outline points
MIRROR_SAMPLES = 50  # ... from about this many of the samples
MIRROR_KEEP = 3
NEAR_CONIC = 0.05  # normalised units (the outline's RMS radius is sqrt 2)
# 36 directions: of 1000 noisy random views, 6 started outside the basin of the best fit
# with 12 directions, 3 with 36 (more did not help)
CONIC_DIRECTIONS = 36
N_BITANGENT = MAX_POCKETS * (MAX_POCKETS - 1) // 2
N_STARTS = N_BITANGENT + MIRROR_KEEP + CONIC_DIRECTIONS


# ------------------------------------------------------------- starting points


def _hom(x):
    return jnp.concatenate([x, jnp.ones_like(x[..., :1])], axis=-1)


HULL_WINDOW = 64  # the exact bitangent's touching points are searched +- this many points
HULL_ITERATIONS = 6


def _exact_edge(points, ia, ib):
    """The hull edge (bitangent) near the approximate one from point ``ia`` to ``ib``:
    alternately the points extreme along the chord's outward normal within
    ``HULL_WINDOW`` of each end, until the chord supports the outline there."""
    m = points.shape[0]
    k = jnp.arange(-HULL_WINDOW, HULL_WINDOW + 1)
    c = points.mean(0)

    def step(_, e):
        ia, ib = e
        d = points[ib] - points[ia]
        n = jnp.stack([d[..., 1], -d[..., 0]], -1)
        n = jnp.where(jnp.sum(n * (c - points[ia]), -1, keepdims=True) > 0, -n, n)  # outward
        wa, wb = (ia[..., None] + k) % m, (ib[..., None] + k) % m
        ia = jnp.take_along_axis(wa, jnp.argmax(jnp.sum(points[wa] * n[..., None, :], -1), -1)[..., None], -1)[..., 0]
        ib = jnp.take_along_axis(wb, jnp.argmax(jnp.sum(points[wb] * n[..., None, :], -1), -1)[..., None], -1)[..., 0]
        return ia, ib

    return jax.lax.fori_loop(0, HULL_ITERATIONS, step, (ia, ib))


def bitangent_starts(points: Float[Array, "M 2"]):
    """Bitangent starts ``(vs, ls, valid)`` (``N_BITANGENT`` slots) of a positively
    oriented closed outline (normalised coordinates).  For pockets spanning ``a1 -> a2``
    and ``b1 -> b2`` along the curve, the reflection pairs ``a1 <-> b2`` and
    ``a2 <-> b1``: ``v = (a1 x b2) x (a2 x b1)`` and ``l`` joins the meet of the two
    bitangents and ``(a1 x b1) x (b2 x a2)``."""
    m = points.shape[0]
    th = jnp.arange(HULL_DIRECTIONS) * (2.0 * np.pi / HULL_DIRECTIONS)
    u = jnp.stack([jnp.cos(th), jnp.sin(th)], 1)
    h = jnp.sort(jnp.argmax(points @ u.T, axis=0))  # hull vertices, curve order (repeats)
    hn = jnp.roll(h, -1)
    gap = (hn - h) % m
    # each point's hull edge: the last hull vertex at or before it (cyclically)
    seg = jnp.searchsorted(h, jnp.arange(m), side="right") - 1
    seg = jnp.where(seg < 0, HULL_DIRECTIONS - 1, seg)
    pa, pb = points[h], points[hn]
    d = pb - pa
    nrm = jnp.hypot(d[:, 0], d[:, 1])
    safe = jnp.where(nrm > 0, nrm, 1.0)
    q = points - pa[seg]
    dist = jnp.abs(q[:, 0] * d[seg, 1] - q[:, 1] * d[seg, 0]) / safe[seg]
    depth = jax.ops.segment_max(dist, seg, num_segments=HULL_DIRECTIONS)
    scale = jnp.sqrt(jnp.mean(jnp.sum((points - points.mean(0)) ** 2, axis=1)))
    ok = (gap >= 3) & (nrm > 0) & (depth > POCKET_DEPTH * scale)
    top, idx = jax.lax.top_k(jnp.where(ok, depth, -jnp.inf), MAX_POCKETS)
    has = jnp.isfinite(top)
    ia, ib = _exact_edge(points, h[idx], hn[idx])
    A1, A2 = _hom(points[ia]), _hom(points[ib])
    ii, jj = np.triu_indices(MAX_POCKETS, k=1)
    a1, a2, b1, b2 = A1[ii], A2[ii], A1[jj], A2[jj]
    v = jnp.cross(jnp.cross(a1, b2), jnp.cross(a2, b1))
    l = jnp.cross(jnp.cross(jnp.cross(a1, a2), jnp.cross(b1, b2)), jnp.cross(jnp.cross(a1, b1), jnp.cross(b2, a2)))
    nv, nl = jnp.linalg.norm(v, axis=1), jnp.linalg.norm(l, axis=1)
    valid = has[ii] & has[jj] & (nv >= 1e-12) & (jnp.linalg.norm(l[:, :2], axis=1) >= 1e-12)
    valid = valid & (jnp.abs(jnp.sum(v * l, 1)) >= 1e-9 * nv * nl) & jnp.all(jnp.isfinite(v) & jnp.isfinite(l), 1)
    return v, l, valid


def mirror_starts(points: Float[Array, "M 2"], samples: Float[Array, "N 2"]):
    """The ``MIRROR_KEEP`` best local minima (over the axis directions, cyclic) of the
    mirror-symmetry grid: ``(vs, ls, valid)``, ``v`` at infinity orthogonal to ``l``.
    The grid's cost is eq. 20's truncated at 0.25, with the distance to the nearest of
    ``MIRROR_KNOTS`` outline points from about ``MIRROR_SAMPLES`` samples."""
    m, n = points.shape[0], samples.shape[0]
    knots = points[np.linspace(0, m, MIRROR_KNOTS, endpoint=False).astype(int)]
    sub = samples[:: max(1, n // MIRROR_SAMPLES)]
    thetas = jnp.asarray(np.linspace(0.0, np.pi, MIRROR_DIRECTIONS, endpoint=False))
    offsets = jnp.asarray(MIRROR_OFFSETS)

    def cost(theta, rho):
        l = jnp.stack([jnp.cos(theta), jnp.sin(theta), -rho])
        v = jnp.stack([jnp.cos(theta), jnp.sin(theta), 0.0])
        y = transfer(homology_matrix(v, l), sub)
        d2 = jnp.sum(y**2, -1)[:, None] + jnp.sum(knots**2, -1)[None, :] - 2.0 * y @ knots.T
        return jnp.mean(jnp.minimum(jnp.min(d2, -1), 0.25))

    c = jax.vmap(lambda t: jax.vmap(lambda r: cost(t, r))(offsets))(thetas)
    best = c.min(axis=1)
    is_min = (best <= jnp.roll(best, 1)) & (best <= jnp.roll(best, -1))
    # the lowest minima, the first of equal ones first (top_k of the negated costs)
    neg, i = jax.lax.top_k(jnp.where(is_min, -best, -jnp.inf), MIRROR_KEEP)
    t, r = thetas[i], offsets[jnp.argmin(c[i], axis=1)]
    zero = jnp.zeros_like(t)
    v = jnp.stack([jnp.cos(t), jnp.sin(t), zero], 1)
    l = jnp.stack([jnp.cos(t), jnp.sin(t), -r], 1)
    return v, l, jnp.isfinite(neg)


def fit_conic(points: Float[Array, "M 2"]):
    """Algebraic least-squares conic of points: the null vector of ``[x^2, xy, y^2, x,
    y, 1]`` (SVD of its QR factor).  Returns ``(C, rms)``: the symmetric 3x3 conic and
    the RMS Sampson distance of the points from it (points' units)."""
    x, y = points[:, 0], points[:, 1]
    D = jnp.stack([x * x, x * y, y * y, x, y, jnp.ones_like(x)], 1)
    R = jnp.linalg.qr(D, mode="r")
    a, b, c, d, e, f = jnp.linalg.svd(R)[2][-1]
    val = D @ jnp.stack([a, b, c, d, e, f])
    gx, gy = 2 * a * x + b * y + d, b * x + 2 * c * y + e
    rms = jnp.sqrt(jnp.mean(val**2 / jnp.maximum(gx**2 + gy**2, 1e-300)))
    C = jnp.stack([jnp.stack([a, b / 2, d / 2]), jnp.stack([b / 2, c, e / 2]), jnp.stack([d / 2, e / 2, f])])
    return C, rms


def conic_starts(C, rms):
    """For a nearly conic outline (``rms <= NEAR_CONIC``): the lines ``l`` through the
    conic's centre in ``CONIC_DIRECTIONS`` directions with their poles ``v = C^-1 l``,
    each an exact homology of the conic: ``(vs, ls, valid)``."""
    Ci = jnp.linalg.inv(C)
    near = (rms <= NEAR_CONIC) & jnp.all(jnp.isfinite(Ci))
    far = jnp.abs(Ci[2, 2]) > 1e-12
    centre = jnp.where(far, Ci[:, 2] / jnp.where(far, Ci[2, 2], 1.0), jnp.array([0.0, 0.0, 1.0]))
    t = jnp.asarray(np.linspace(0.0, np.pi, CONIC_DIRECTIONS, endpoint=False))
    l = jnp.stack([jnp.cos(t), jnp.sin(t), -(jnp.cos(t) * centre[0] + jnp.sin(t) * centre[1])], 1)
    v = l @ Ci.T
    nv, nl = jnp.linalg.norm(v, axis=1), jnp.linalg.norm(l, axis=1)
    valid = near & (nv > 0) & (jnp.abs(jnp.sum(v * l, 1)) > 1e-9 * nv * nl)
    return v, l, valid


def automatic_starts(points, samples, conic=None):
    """All ``N_STARTS`` automatic starts ``(vs, ls, valid)``, in the order bitangents,
    mirror grid, conic (the argmin keeps the first of equal screened costs)."""
    C, rms = fit_conic(points) if conic is None else conic
    parts = (bitangent_starts(points), mirror_starts(points, samples), conic_starts(C, rms))
    return tuple(jnp.concatenate(a) for a in zip(*parts))
