"""Harmonic homologies of surface-of-revolution outlines and their per-view fit.

The outline of a surface of revolution is mapped onto itself by the harmonic homology
(the paper's eq. 11)::

    W(v, l) = I - 2 v l^T / (v^T l)

with axis ``l = l_s`` (the image of the revolution axis) and vertex ``v = v_x``.  W is
an involution, fixes every point of ``l_s`` and has 4 degrees of freedom.

Per view we minimise the paper's eq. 20::

    Cost(v, l) = sum_i d(W(v, l) x_i)^2

over ``N`` samples ``x_i`` evenly spaced along the outline, ``d`` being the signed
orthogonal distance to the outline (:mod:`sorjax._field`).  The fit runs in
per-view normalised coordinates (centroid at the origin, RMS radius sqrt 2) with the
parameters ``p = (theta, rho, d1, d2)``::

    l = (cos theta, sin theta, -rho),     v = normalise(v0 + d1 e1 + d2 e2),

``v0`` the starting vertex (unit 3-vector) and ``e1, e2`` an orthonormal basis of its
tangent plane on the sphere: a chart that stays well conditioned when ``v_x`` goes to
infinity (``v`` then has a vanishing third coordinate, nothing diverges).

Initialisation is automatic (the paper picked bitangents by hand):

* bitangents of the convex hull: every pair of concavities ("pockets" between the
  outline and its hull) gives bitangents ``l_b, l_b'`` touching at ``x1, x2`` and
  ``x1', x2'``; then ``v_x = (x1 x x1') x (x2 x x2')`` and ``l_s`` joins
  ``l_b x l_b'`` and ``(x1 x x2') x (x1' x x2)`` (paper, Section 5.1);
* a symmetry-axis search: mirror symmetries (``v`` at infinity orthogonal to ``l``)
  over a grid of axis directions and offsets, the best few local minima kept;
* for a nearly conic outline (a bowl from above), the pole-polar pairs of its
  best-fitting conic, each an exact symmetry of the conic;

every candidate is refined by Levenberg-Marquardt (optimistix) and the one with the
lowest cost wins.
"""

from __future__ import annotations

import functools

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from ._camera import normalising_transform, transform_points
from ._field import DistanceField, closest_parameter, curve_points, make_field, sample_weights, signed_distances
from ._outline import DEFAULT_POINTS, make_outline, perimeter
from ._solvers import Solved, is_stale, polish, solvers, until_fresh

DEFAULT_SAMPLES = 100
INFINITY_Z = 3.0
CONIC_RATIO = 1.5
CONIC_FLOOR_PX = 1e-3
_GRID_DIRECTIONS = 48
_GRID_OFFSETS = (-0.3, -0.15, 0.0, 0.15, 0.3)


class Homology(eqx.Module):
    """A fitted harmonic homology of one outline (pixels).

    Attributes:
        l_s: image of the revolution axis, homogeneous line with ``a^2 + b^2 = 1``.
        v_x: vertex (vanishing point), homogeneous, unit norm; ``v_x[2] -> 0`` when it
            is at infinity.
        W: ``I - 2 v_x l_s^T / (v_x^T l_s)``, pixels.
        rms: RMS symmetry residual ``sqrt(Cost / N)`` in pixels.
        cost: eq. 20's cost in px^2.
        converged: the optimiser reported success.
        steps: Levenberg-Marquardt steps taken.
        conic_rms: RMS distance (px, Sampson) of the outline from its best-fitting
            conic.  A conic outline (a sphere, or a bowl seen from above showing only
            its rim) is symmetric under infinitely many homologies and carries no
            calibration information (the paper's Section 6): see :attr:`is_conic`.
        infinity_z: how many standard errors ``v_x`` lies from the line at infinity:
            ``|v_3| / std(v_3)`` in the fit's normalised coordinates, the standard
            error from the fit's Jacobian and its residual (first order; affine
            invariant).  See :attr:`v_x_at_infinity`.  None for homologies built by
            hand.
        inliers: (N,) the samples the fit kept (robust fit: samples whose residual
            is an outlier, e.g. on a mug's handle, are trimmed); ``rms`` and ``cost``
            are over these.  None for homologies built by hand.
        rms_untrimmed: RMS symmetry residual (px) of the fit to all samples, before
            any trimming: :func:`sorjax.calibrate` judges whether a view is symmetric
            at all by it, so that trimming never makes an asymmetric outline (a
            segmentation leak) pass.  None for homologies built by hand.
    """

    l_s: Float[Array, "3"]
    v_x: Float[Array, "3"]
    W: Float[Array, "3 3"]
    rms: Float[Array, ""]
    cost: Float[Array, ""]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    conic_rms: Float[Array, ""]
    infinity_z: Float[Array, ""] | None = None
    inliers: Bool[Array, " N"] | None = None
    rms_untrimmed: Float[Array, ""] | None = None

    @property
    def trimmed(self) -> float:
        """Fraction of the samples trimmed as outliers by the robust fit (0 if none)."""
        return 0.0 if self.inliers is None else float(1.0 - np.mean(np.asarray(self.inliers)))

    @property
    def v_x_at_infinity(self) -> bool:
        """``v_x`` is at infinity as far as this outline can tell: within
        ``INFINITY_Z`` (3) standard errors of the line at infinity, or so far away
        (``|v_3| < 1e-9`` of the unit vertex in pixels) that no noise-free fit could
        place it better.  The camera then looks straight at the revolution axis (the
        outline has skew or mirror symmetry; paper, Section 6): the view constrains
        the principal point (it lies on ``l_s``) but not the focal length.

        The standard error assumes independent residuals; with noise correlated along
        the outline (or a rough, densely sampled outline) it is optimistic, so the test
        errs towards calling ``v_x`` finite.  :func:`sorjax.calibrate` acts on it only
        when the joint estimate cannot fix the focal length either."""
        if abs(float(np.asarray(self.v_x)[2])) < 1e-9:
            return True
        return self.infinity_z is not None and bool(self.infinity_z < INFINITY_Z)

    @property
    def is_conic(self) -> bool:
        """The outline is explained by a conic about as well as by this homology
        (``conic_rms <= CONIC_RATIO * rms + CONIC_FLOOR_PX``): its homology is not
        determined, so the view says nothing about the camera."""
        return bool(self.conic_rms <= CONIC_RATIO * self.rms + CONIC_FLOOR_PX)


# ---------------------------------------------------------------------------- maths


def homology_matrix(v: Float[Array, "3"], l: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Harmonic homology ``W = I - 2 v l^T / (v^T l)`` (any consistent coordinates)."""
    return jnp.eye(3) - 2.0 * jnp.outer(v, l) / (v @ l)


def transfer(W: Float[Array, "3 3"], x: Float[Array, "N 2"]) -> Float[Array, "N 2"]:
    """Map inhomogeneous points by the homography ``W`` (guarded against points sent
    to infinity, which are sent very far instead)."""
    y = x @ W[:, :2].T + W[:, 2]
    w = y[:, 2]
    w = jnp.where(jnp.abs(w) < 1e-12, jnp.where(w < 0, -1e-12, 1e-12), w)
    return y[:, :2] / w[:, None]


def symmetry_residuals(
    v: Float[Array, "3"], l: Float[Array, "3"], samples: Float[Array, "N 2"], field: DistanceField, weights=None,
    hints=None,
) -> Float[Array, "N"]:
    """The residuals of eq. 20: ``w_i d(W(v, l) x_i)`` for each sample ``x_i``, in the
    units of the field (pixels if the field and samples are in pixels); ``weights``
    ``w_i`` default to 1 (:func:`sorjax._field.sample_weights` zeroes samples at
    corners); ``hints`` (N,) optional closest-point parameters to search near
    (:func:`sorjax._field.closest_parameter_near`)."""
    r = signed_distances(field, transfer(homology_matrix(v, l), samples), hints)
    return r if weights is None else r * weights


def symmetry_feet(v: Float[Array, "3"], l: Float[Array, "3"], samples: Float[Array, "N 2"],
                  field: DistanceField) -> Float[Array, " N"]:
    """Parameters (knot units) of the outline's points closest to the transferred
    samples ``W(v, l) x_i`` (whole-outline search, no gradient): the hints of a solve
    started at ``(v, l)``."""
    return jax.vmap(closest_parameter, in_axes=(None, 0))(field, transfer(homology_matrix(v, l), samples))


def _tangent_basis(v0: np.ndarray) -> np.ndarray:
    """Orthonormal (3, 2) basis of the plane orthogonal to the unit vector ``v0``."""
    a = np.eye(3)[int(np.argmin(np.abs(v0)))]
    e1 = np.cross(v0, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(v0, e1)
    return np.stack([e1, e2], axis=1)


def _unpack(p, v0, E):
    l = jnp.stack([jnp.cos(p[0]), jnp.sin(p[0]), -p[1]])
    v = v0 + E @ p[2:]
    return v / jnp.linalg.norm(v), l


def _pack(v: np.ndarray, l: np.ndarray):
    """Start parameters ``(p0, v0, E)`` from a homology (v, l) in normalised coords."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    l = np.asarray(l, float) / np.linalg.norm(l[:2])
    return np.array([np.arctan2(l[1], l[0]), -l[2], 0.0, 0.0]), v, _tangent_basis(v)


# ---------------------------------------------------------------- initialisation


def _convex_hull_indices(p: np.ndarray) -> np.ndarray:
    """Indices of the convex hull vertices of ``p`` (n, 2), sorted by index."""
    hull = cv2.convexHull(np.ascontiguousarray(p, dtype=np.float32), returnPoints=False)
    return np.unique(hull.reshape(-1).astype(int))


def _pockets(p: np.ndarray, min_depth: float):
    """Concavities of a positively oriented closed curve: ``(depth, i, j)`` for every
    hull edge from vertex ``i`` to ``j`` (in curve order) whose skipped stretch of
    outline lies deeper than ``min_depth`` inside the hull, deepest first."""
    n = len(p)
    h = _convex_hull_indices(p)
    out = []
    for a, b in zip(h, np.roll(h, -1)):
        gap = (b - a) % n
        if gap < 3:
            continue
        idx = (a + np.arange(1, gap)) % n
        d = p[b] - p[a]
        nrm = np.hypot(*d)
        if nrm == 0:
            continue
        depth = np.max(np.abs((p[idx, 0] - p[a, 0]) * d[1] - (p[idx, 1] - p[a, 1]) * d[0]) / nrm)
        if depth > min_depth:
            out.append((float(depth), int(a), int(b)))
    out.sort(reverse=True)
    return out


def _hom(x):
    return np.array([x[0], x[1], 1.0])


def bitangent_candidates(p: np.ndarray, max_pockets: int = 4) -> list[tuple[np.ndarray, np.ndarray]]:
    """Homologies ``(v, l)`` from pairs of convex-hull bitangents (paper, Sec. 5.1).

    ``p`` is the positively oriented outline in normalised coordinates.  For pockets
    spanning ``a1 -> a2`` and ``b1 -> b2`` along the curve, the reflection pairs
    ``a1 <-> b2`` and ``a2 <-> b1``.
    """
    scale = np.sqrt(np.mean(np.sum((p - p.mean(0)) ** 2, axis=1)))
    pockets = _pockets(p, min_depth=0.03 * scale)[:max_pockets]
    cands = []
    for i in range(len(pockets)):
        for j in range(i + 1, len(pockets)):
            a1, a2 = _hom(p[pockets[i][1]]), _hom(p[pockets[i][2]])
            b1, b2 = _hom(p[pockets[j][1]]), _hom(p[pockets[j][2]])
            # order the two pockets along the curve so that a1 < a2 <= b1 < b2
            v = np.cross(np.cross(a1, b2), np.cross(a2, b1))
            l = np.cross(np.cross(np.cross(a1, a2), np.cross(b1, b2)),
                         np.cross(np.cross(a1, b1), np.cross(b2, a2)))
            if np.linalg.norm(v) < 1e-12 or np.linalg.norm(l[:2]) < 1e-12:
                continue
            if abs(v @ l) < 1e-9 * np.linalg.norm(v) * np.linalg.norm(l):
                continue  # vertex on the axis: not a homology
            cands.append((v, l))
    return cands


@jax.jit
def _mirror_costs(knots, samples, thetas, offsets):
    """Truncated eq. 20 cost of the mirror symmetries with axis directions ``thetas``
    and offsets ``offsets`` (a grid), ``v`` at infinity orthogonal to the axis.  The
    distance is to the nearest of the coarse ``knots`` (enough to rank a grid)."""

    def cost(theta, rho):
        l = jnp.stack([jnp.cos(theta), jnp.sin(theta), -rho])
        v = jnp.stack([jnp.cos(theta), jnp.sin(theta), 0.0])
        y = transfer(homology_matrix(v, l), samples)
        # |y - k|^2 = |y|^2 + |k|^2 - 2 y.k, the cross term as one matrix product
        d2 = jnp.sum(y**2, -1)[:, None] + jnp.sum(knots**2, -1)[None, :] - 2.0 * y @ knots.T
        return jnp.mean(jnp.minimum(jnp.min(d2, -1), 0.25))  # truncated: robust to gross mismatch

    return jax.vmap(lambda t: jax.vmap(lambda r: cost(t, r))(offsets))(thetas)


_GRID_KNOTS = 64
_GRID_SAMPLES = 50


def mirror_candidates(points_n: np.ndarray, samples, keep: int = 3):
    """Best local minima of the mirror-symmetry grid search (normalised coords).

    The grid's cost reads the distance to the nearest of ``_GRID_KNOTS`` outline points
    from ``_GRID_SAMPLES`` of the samples: enough to rank a grid whose candidates are
    refined anyway (a quarter of the work of 128 knots and 100 samples; measured on 400
    noisy random views: the same views started in the right basin)."""
    thetas = np.linspace(0.0, np.pi, _GRID_DIRECTIONS, endpoint=False)
    offsets = np.asarray(_GRID_OFFSETS)
    knots = points_n[np.linspace(0, len(points_n), _GRID_KNOTS, endpoint=False).astype(int)]
    sub = samples[:: max(1, samples.shape[0] // _GRID_SAMPLES)]
    c = np.asarray(_mirror_costs(knots, sub, thetas, offsets))
    best = c.min(axis=1)
    is_min = (best <= np.roll(best, 1)) & (best <= np.roll(best, -1))
    order = [i for i in np.argsort(best) if is_min[i]][:keep]
    out = []
    for i in order:
        t, r = thetas[i], offsets[int(np.argmin(c[i]))]
        out.append((np.array([np.cos(t), np.sin(t), 0.0]), np.array([np.cos(t), np.sin(t), -r])))
    return out


# ------------------------------------------------------------------------ refine


_BARRIER_AT = 0.3
_BARRIER_GAIN = 100.0


def _residuals(p, args):
    """Eq. 20's residuals plus one barrier residual, ``100 relu(0.3 - a)`` with
    ``a = |v . l| / (|v| |l|)`` in the view's normalised coordinates.

    As ``v`` approaches the axis ``l`` the homology degenerates into a projection that
    sends every point to ``v``; with ``v`` on the outline that "fits" perfectly.  The
    true vertex is far from that: ``a`` is the sine of the angle between the axis and
    the direction from the outline's centre to ``v`` (1 for a mirror symmetry), above
    0.99 in every synthetic view we measured, so the barrier is 0 at every real
    solution and only walls off the degenerate ones."""
    field, samples, weights, v0, E = args[:5]
    hints = args[5] if len(args) > 5 else None  # closest-point parameters to search near
    v, l = _unpack(p, v0, E)
    r = symmetry_residuals(v, l, samples, field, weights, hints)
    a = jnp.abs(v @ l) / jnp.linalg.norm(l)
    return jnp.concatenate([r, _BARRIER_GAIN * jax.nn.relu(_BARRIER_AT - a)[None]])


# Screening (COARSE_STEPS loose Levenberg-Marquardt steps from every start), then
# polishing: see :mod:`sorjax._solvers`.  Measured on 400 noisy random views (paper
# noise, sigma 1 px; experiments/accuracy.py's init study): 15, 8 and 5 screening steps
# all started 399-400 of them in the right basin (390-393 axes within 1 deg); on the
# study's 1000 views, 5 steps: 996 in the right basin, 969 axes within 1 deg (15 steps:
# 997 and 964).  5 steps cost a third of 15 (the polish takes ~6 Gauss-Newton steps more).
_SOLVERS = solvers(rtol=1e-10, atol=1e-10)
COARSE_STEPS = 5
SCREEN_BATCH = 4  # starts screened by one vmapped call (one compilation for any count)


def refine(field: DistanceField, samples, weights, p0, v0, E, max_steps: int = 100, method: str = "lm"):
    """Minimise eq. 20 from one start ``(p0, v0, E)`` (normalised coordinates) with
    ``method``: "lm" (Levenberg-Marquardt), "gn" (Gauss-Newton) or "screen" (loose
    Levenberg-Marquardt: the screening stage of :func:`fit_homology`).  Returns
    ``(v, l, cost, converged, steps, p, r, stale)`` with ``r`` eq. 20's residuals; pure,
    jit/vmap-able.

    As in the bundle (:func:`sorjax._bundle.solve`) the solver searches each closest
    point only near where it was at ``p0``; ``r`` and the cost are searched over the
    whole outline, and ``stale`` says that they differ from the solver's (a closest
    point left its window: solve again from ``p``)."""
    args = (field, samples, weights, v0, E)
    hints = symmetry_feet(*_unpack(p0, v0, E), samples, field)
    sol = optx.least_squares(_residuals, _SOLVERS[method], p0, args=args + (hints,), max_steps=max_steps,
                             throw=False)
    v, l = _unpack(sol.value, v0, E)
    r = _residuals(sol.value, args)
    stale = is_stale(r, _residuals(sol.value, args + (hints,)))
    ok = sol.result == optx.RESULTS.successful
    return v, l, jnp.sum(r**2), ok, sol.stats["num_steps"], sol.value, r[:-1], stale


@functools.partial(jax.jit, static_argnames=("n_samples", "smooth"))
def _view_setup(points_n, n_samples: int, smooth: float = 0.0):
    field = make_field(points_n, smooth)
    return field, curve_points(field, n_samples), sample_weights(field, n_samples)


_refine_jit = jax.jit(refine, static_argnames=("max_steps", "method"))


@jax.jit
def _screen(field, samples, weights, p0, v0, E):
    """Screen a batch of starts (leading axis) at once: ``(cost, p, steps)`` of each
    after at most ``COARSE_STEPS`` loose Levenberg-Marquardt steps."""

    def one(p, v, e):
        out = refine(field, samples, weights, p, v, e, max_steps=COARSE_STEPS, method="screen")
        return out[2], out[5], out[4]

    return jax.vmap(one)(p0, v0, E)


def _refine_candidates(field, samples, weights, cands, max_steps: int = 100):
    """Screen every start ``(v, l)`` (normalised coordinates) with a few loose
    Levenberg-Marquardt steps (``SCREEN_BATCH`` starts per vmapped call, the last batch
    padded by repeating a start), then polish the lowest-cost one to convergence
    (Gauss-Newton, or Levenberg-Marquardt where that fails or ends above its start)."""
    starts = [_pack(v0, l0) for v0, l0 in cands]
    if not starts:
        raise FloatingPointError("every start of the homology fit gave a non-finite cost")
    costs, ps, steps0 = [], [], []
    for i in range(0, len(starts), SCREEN_BATCH):
        chunk = starts[i:i + SCREEN_BATCH]
        chunk = chunk + [chunk[0]] * (SCREEN_BATCH - len(chunk))
        c, p, n = _screen(field, samples, weights, *(np.stack(a) for a in zip(*chunk)))
        costs.append(np.asarray(c))
        ps.append(np.asarray(p))
        steps0.append(np.asarray(n))
    costs = np.concatenate(costs)[: len(starts)]
    ps = np.concatenate(ps)
    costs = np.where(np.isfinite(costs), costs, np.inf)
    if not np.isfinite(costs).any():
        raise FloatingPointError("every start of the homology fit gave a non-finite cost")
    k = int(np.argmin(costs))  # the first of equal costs, as the serial screen kept
    cost0 = float(costs[k])
    v0, E = starts[k][1:]
    out0_p = ps[k]

    def run(p, method):
        def once(p):
            out = _refine_jit(field, samples, weights, p, v0, E, max_steps=max_steps, method=method)
            return out, out[5], int(out[4]), bool(out[7])

        out, steps = until_fresh(once, p)
        return Solved(out[5], bool(out[3]), float(out[2]), steps, out)

    final, steps = polish(run, out0_p, cost0)
    out = final.out
    return out[0], out[1], float(out[2]), out[3], int(np.concatenate(steps0)[k]) + steps, out[6]


TRIM_K = 4.0  # robust standard deviations
TRIM_FLOOR_PX = 0.1
TRIM_ROUNDS = 3


def outlier_samples(r_px: np.ndarray, active: np.ndarray, inliers: np.ndarray | None = None) -> np.ndarray:
    """Samples (among ``active``) whose symmetry residual (px) is an outlier:
    ``|r| > max(TRIM_K s, TRIM_FLOOR_PX)`` with the robust scale ``s = 1.4826
    median|r|`` over the current ``inliers`` (default: the active samples).  Noise
    alone trims almost nothing (Gaussian residuals: 6e-5 of the samples); a part of
    the outline with no mirror image (a mug's handle, a shadow, a bite taken by an
    occluder) leaves residuals of several px there, and at its mirror image."""
    a = np.abs(np.asarray(r_px))
    base = active if inliers is None else active & inliers
    if not base.any():
        return np.zeros_like(active)
    s = 1.4826 * float(np.median(a[base]))
    return active & (a > max(TRIM_K * s, TRIM_FLOOR_PX))


def _robust_refits(field, samples, weights, fit, scale: float, max_steps: int):
    """Trimmed refits of a per-view fit ``(v, l, cost, ok, steps, r)`` (normalised):
    up to ``TRIM_ROUNDS`` times, trim the outliers (:func:`outlier_samples`, scale
    from the samples kept so far) and refit from the current solution, never below
    half of the samples.  Returns the final fit and the inlier mask (corner samples,
    weight 0, count as inliers).  A handle so large that it inflates the residuals
    everywhere can mask itself (no outlier stands out): such a view keeps a high RMS
    residual and :func:`sorjax.calibrate` drops or flags it."""
    w0 = np.asarray(weights)
    active = w0 > 0
    keep = np.ones_like(active)
    for _ in range(TRIM_ROUNDS):
        out = outlier_samples(np.asarray(fit[5]) * scale, active, keep) & keep
        if not out.any() or (keep & ~out & active).sum() < active.sum() // 2:
            break
        keep = keep & ~out
        new = _refine_candidates(field, samples, jnp.asarray(w0 * keep), [(np.asarray(fit[0]), np.asarray(fit[1]))],
                                 max_steps=max_steps)
        fit = new[:4] + (fit[4] + new[4], new[5])
    return fit, keep


@jax.jit
def _infinity_z(field, samples, weights, v, l, cost):
    """``|v_3| / std(v_3)`` for the fitted ``(v, l)`` (normalised coordinates): the
    Gauss-Newton covariance ``s^2 (J^T J)^-1`` of eq. 20's parameters in a chart
    centred on the solution, ``s^2 = cost / (N - 4)``."""
    v = v / jnp.linalg.norm(v)
    l = l / jnp.linalg.norm(l[:2])
    p = jnp.stack([jnp.arctan2(l[1], l[0]), -l[2], 0.0, 0.0])
    e1 = jnp.cross(v, jnp.eye(3)[jnp.argmin(jnp.abs(v))])
    e1 = e1 / jnp.linalg.norm(e1)
    E = jnp.stack([e1, jnp.cross(v, e1)], axis=1)
    J = jax.jacfwd(_residuals)(p, (field, samples, weights, v, E))
    s2 = cost / jnp.maximum(jnp.sum(weights) - 4.0, 1.0)
    cov = s2 * jnp.linalg.pinv(J.T @ J, hermitian=True)
    var3 = E[2] @ cov[2:, 2:] @ E[2]
    return jnp.abs(v[2]) / jnp.sqrt(jnp.maximum(var3, 1e-300))


def fit_conic(points_n: np.ndarray):
    """Algebraic least-squares conic of points (normalised coordinates): the SVD null
    vector of ``[x^2, xy, y^2, x, y, 1]``.  Returns ``(C, rms)``: the symmetric 3x3
    conic and the RMS Sampson distance of the points from it (points' units)."""
    x, y = points_n[:, 0], points_n[:, 1]
    D = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], 1)
    # the SVD of the small triangular factor (same null vector as D's own SVD; a LAPACK
    # SVD of the tall D took 2-16 ms once XLA's threads were busy, this 0.05 ms)
    a, b, c, d, e, f = np.linalg.svd(np.linalg.qr(D, mode="r"))[2][-1]
    val = D @ np.array([a, b, c, d, e, f])
    gx, gy = 2 * a * x + b * y + d, b * x + 2 * c * y + e
    rms = float(np.sqrt(np.mean(val**2 / np.maximum(gx**2 + gy**2, 1e-300))))
    return np.array([[a, b / 2, d / 2], [b / 2, c, e / 2], [d / 2, e / 2, f]]), rms


NEAR_CONIC = 0.05  # normalised units (the outline's RMS radius is sqrt 2)


def conic_candidates(points_n: np.ndarray, n_dir: int = 36, conic=None):
    """For a nearly conic outline (a bowl seen from above): every line ``l`` through
    the conic's centre with its pole ``v = C^-1 l`` is an exact homology of the conic;
    the outline's departure from the conic picks the right one, so these are starts.
    ``conic`` is :func:`fit_conic`'s result when already at hand.  36 directions: of
    1000 noisy random views, 6 started outside the basin of the best fit with 12
    directions, 3 with 36 (more did not help); only near-conic outlines pay for them."""
    C, rms = fit_conic(points_n) if conic is None else conic
    if rms > NEAR_CONIC:
        return []
    try:
        Ci = np.linalg.inv(C)
    except np.linalg.LinAlgError:
        return []
    centre = Ci[:, 2] / Ci[2, 2] if abs(Ci[2, 2]) > 1e-12 else np.array([0.0, 0.0, 1.0])
    out = []
    for t in np.linspace(0.0, np.pi, n_dir, endpoint=False):
        l = np.array([np.cos(t), np.sin(t), -(np.cos(t) * centre[0] + np.sin(t) * centre[1])])
        v = Ci @ l
        if np.linalg.norm(v) > 0 and abs(v @ l) > 1e-9 * np.linalg.norm(v) * np.linalg.norm(l):
            out.append((v, l))
    return out


def _to_pixels(T: np.ndarray, v, l, cost, ok, steps, scale, n_samples, conic, z=None, inliers=None,
               rms_untrimmed=None) -> Homology:
    """The :class:`Homology` in pixels of a fit in the coordinates of ``T`` (numpy
    arithmetic: a handful of 3-vectors, no per-op dispatch)."""
    v_pix = np.linalg.solve(T, np.asarray(v, dtype=np.float64))
    v_pix = v_pix / np.linalg.norm(v_pix)
    l_pix = T.T @ np.asarray(l, dtype=np.float64)
    l_pix = l_pix / np.linalg.norm(l_pix[:2])
    cost_px = float(cost) * scale**2
    W = np.eye(3) - 2.0 * np.outer(v_pix, l_pix) / (v_pix @ l_pix)
    fields = dict(
        l_s=l_pix, v_x=v_pix, W=W, rms=np.sqrt(cost_px / n_samples), cost=np.float64(cost_px),
        converged=np.bool_(bool(ok)), steps=np.int64(int(steps)), conic_rms=np.float64(float(conic) * scale),
        infinity_z=None if z is None else np.float64(float(z)),
        inliers=None if inliers is None else np.asarray(inliers),
        rms_untrimmed=None if rms_untrimmed is None else np.float64(float(rms_untrimmed)),
    )
    return Homology(**jax.device_put(fields))  # one transfer for every field


def fit_homology(
    outline,
    *,
    n_samples: int = DEFAULT_SAMPLES,
    n_points: int = DEFAULT_POINTS,
    init=None,
    max_steps: int = 100,
    smooth_px: float = 0.0,
    robust: bool = True,
) -> Homology:
    """Fit the harmonic homology of one outline by minimising eq. 20.

    Args:
        outline: (N, 2) pixel coordinates of a closed outline, or an :class:`Outline`.
        n_samples: number of samples ``x_i`` evenly spaced along the outline (the paper
            uses 100).
        n_points: the outline is resampled to this many points for its distance field.
        init: optional starting homology ``(v_x, l_s)`` in pixels (homogeneous); by
            default the start is found automatically (bitangents of the convex hull
            and a symmetry-axis search, the lowest final cost wins).
        max_steps: Levenberg-Marquardt step limit.
        smooth_px: smooth the outline along the curve (Gaussian, std in px of arc
            length) before building its distance field and samples; 0 (default) uses
            the outline as given.
        robust: trim samples whose residual is an outlier (:func:`outlier_samples`:
            a handle, a shadow, an occlusion) and refit (:func:`_robust_refits`;
            never below half of the samples); ``Homology.inliers`` says which were
            kept.  Outlines with no outlier are not refitted.

    Returns:
        :class:`Homology` in pixels, with the RMS symmetry residual in px.
    """
    o = make_outline(outline, n_points)
    pts = np.asarray(o.points)
    T = normalising_transform(pts)
    scale = 1.0 / T[0, 0]
    pn = transform_points(T, pts)
    smooth = float(smooth_px) / (perimeter(pts) / o.n_points) if smooth_px else 0.0
    field, samples, weights = _view_setup(pn, n_samples, smooth)
    conic = fit_conic(pn)
    if init is not None:
        v0, l0 = (np.asarray(a, dtype=np.float64) for a in init)
        cands = [(T @ v0, np.linalg.solve(T.T, l0))]
    else:
        cands = bitangent_candidates(pn) + mirror_candidates(pn, samples) + conic_candidates(pn, conic=conic)
    fit = _refine_candidates(field, samples, weights, cands, max_steps=max_steps)
    w_np = np.asarray(weights)
    rms_all = float(np.sqrt(fit[2] / max(float(np.sum(w_np)), 1.0))) * scale
    inliers = np.ones(n_samples, bool)
    if robust:
        fit, inliers = _robust_refits(field, samples, weights, fit, scale, max_steps)
    v, l, cost, ok, steps, _ = fit
    w = w_np * inliers
    z = _infinity_z(field, samples, w, np.asarray(v), np.asarray(l), np.float64(cost))
    return _to_pixels(T, v, l, cost, ok, steps, scale, float(np.sum(w)), conic[1], z, inliers, rms_all)
