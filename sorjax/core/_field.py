"""A smooth (C^2 curve, C^1 field) signed distance to a closed outline.

The outline's ``M`` evenly spaced points ``X_i`` are interpolated by a periodic
uniform cubic B-spline ``c(t)``, ``t in [0, M)``, with control points ``P`` solving
the circulant system ``(P_{i-1} + 4 P_i + P_{i+1}) / 6 = X_i`` (by FFT, so building
the field is differentiable in the outline points).  On segment ``i`` with
``u = t - i``::

    c(u) = [(1-u)^3 P_{i-1} + (3u^3 - 6u^2 + 4) P_i + (-3u^3 + 3u^2 + 3u + 1) P_{i+1}
            + u^3 P_{i+2}] / 6.

The signed distance of a point ``x`` (pixels, or whatever units the points are in) is
``d(x) = (x - c(t*)) . n(t*)`` with ``t*`` the closest-point parameter and ``n`` the
outward unit normal (positive outside the outline).  ``t*`` is found by a coarse-to-fine
search over the ``M`` knots followed by a few safeguarded Newton steps on
``|x - c(t)|^2``, all under ``stop_gradient``: at the closest point ``x - c`` is
normal to the curve, so ``d d / d x = n(t*)`` exactly (envelope theorem) and the
derivatives with respect to the outline points are also exact to first order.  The
field is therefore C^1 wherever the closest point is unique (everywhere within the
curve's smallest radius of curvature, e.g. within 5 px of any outline that is not
sharper than that), with no kinks at the knots.  Solvers pass a ``hint`` (the closest
point's parameter at their start) to search only the knots near it
(:func:`closest_parameter_near`, a third of the distances) and check their result
against the whole-outline search at the end.

Optionally the points are first smoothed along the curve by a circular Gaussian of
``smooth`` samples, which suppresses the target outline's own noise (it shrinks a
curve of radius R by about ``smooth_px^2 / (2 R)``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

NEWTON_STEPS = 4


class DistanceField(eqx.Module):
    """Periodic cubic B-spline of an outline; call :func:`signed_distance` on it."""

    control: Float[Array, "M 2"]
    knots: Float[Array, "M 2"]  # c(i), the interpolated points

    @property
    def n_knots(self) -> int:
        return self.control.shape[-2]


def gaussian_smooth_closed(points: Float[Array, "M 2"], sigma_samples) -> Float[Array, "M 2"]:
    """Circular Gaussian smoothing of a closed curve's points (FFT; ``sigma`` in samples)."""
    m = points.shape[-2]
    k = jnp.fft.rfftfreq(m)  # cycles per sample
    gain = jnp.exp(-2.0 * (jnp.pi * k * sigma_samples) ** 2)
    return jnp.fft.irfft(jnp.fft.rfft(points, axis=-2) * gain[:, None], n=m, axis=-2)


def make_field(points: Float[Array, "M 2"], smooth_samples: float = 0.0) -> DistanceField:
    """Build the field from ``M`` evenly spaced outline points (jit/vmap/grad-clean)."""
    points = jnp.asarray(points, dtype=jnp.float64)
    if smooth_samples:
        points = gaussian_smooth_closed(points, smooth_samples)
    m = points.shape[-2]
    k = jnp.arange(m // 2 + 1)
    eig = (4.0 + 2.0 * jnp.cos(2.0 * jnp.pi * k / m)) / 6.0
    control = jnp.fft.irfft(jnp.fft.rfft(points, axis=-2) / eig[:, None], n=m, axis=-2)
    return DistanceField(control, points)


# the uniform cubic B-spline's four basis functions as polynomials in u: b_j(u) =
# sum_k u^k _BSPLINE[k, j] (b_0 = (1 - u)^3 / 6, ..., b_3 = u^3 / 6)
_BSPLINE = np.array([[1.0, 4.0, 1.0, 0.0], [-3.0, 0.0, 3.0, 0.0], [3.0, -6.0, 3.0, 0.0], [-1.0, 3.0, -3.0, 1.0]]) / 6.0


def _basis(u):
    """Cubic B-spline basis values, first and second derivatives at ``u`` in [0, 1):
    a (3, 4) array, rows ``b``, ``b'``, ``b''`` (the monomials and their derivatives
    times :data:`_BSPLINE`: one product, a small part of the program that every
    distance evaluation repeats)."""
    o, z, u2 = jnp.ones_like(u), jnp.zeros_like(u), u * u
    powers = jnp.stack([jnp.stack([o, u, u2, u2 * u]), jnp.stack([z, o, 2 * u, 3 * u2]),
                        jnp.stack([z, z, 2 * o, 6 * u])])
    return powers @ _BSPLINE


def curve(field: DistanceField, t):
    """``(c(t), c'(t), c''(t))`` for a scalar parameter ``t`` (knot units, periodic)."""
    m = field.n_knots
    t = jnp.mod(t, m)
    i = jnp.floor(t)
    u = t - i
    idx = (i.astype(jnp.int32) + jnp.arange(-1, 3)) % m
    c = _basis(u) @ field.control[idx]  # (3, 2)
    return c[0], c[1], c[2]


def _argmin(d: Float[Array, " n"]) -> Float[Array, ""]:
    """``jnp.argmin`` (first index of the minimum) from two plain reductions: XLA's
    variadic argmin reduction is several times slower on CPU, and this search runs
    for every residual of every solver step."""
    n = d.shape[-1]
    first = jnp.min(jnp.where(d <= jnp.min(d), jnp.arange(n), n))
    return jnp.minimum(first, n - 1)  # all-NaN input: the last index, not out of range


SEARCH_KNOTS = 512  # the coarse-to-fine search runs on at most this many knots


def _nearest_knot(field: DistanceField, x: Float[Array, "2"]) -> Float[Array, ""]:
    """Index of the knot nearest to ``x``, in three passes: over every ``q``-th knot
    (``q = M / 512`` for ``M > 512`` knots, else 1) a coarse pass over every ``s``-th
    of those (``s ~ sqrt(M / 2q)``), then an exact pass over the ``2 s + 1`` around
    each of the two best coarse ones (two, so that thin parts of a shape, a stem or a
    neck, do not send the search to the wrong side), then an exact pass over the
    ``4 q + 1`` knots around the winner (``2 q`` each side: near a sharp corner the
    nearest knot can lie nearer the next decimated knot than the winner; with ``q``
    each side such a miss left the Newton steps on a wrong foot point, up to 0.017
    normalised units (about 2 px) off, on a random scene's view).  About 115 distances
    for 2048 knots instead of 2048; it returns the exact nearest knot except where two far-apart stretches
    of the outline are equally near (measured: 4 of 20000 points scattered 4 px
    around a two-sphere outline got a knot at most 0.1 px farther; the Newton steps
    of :func:`closest_parameter` start from it)."""
    m = field.n_knots
    if m <= 128:
        return _argmin(jnp.sum((field.knots - x) ** 2, axis=-1))
    q = max(1, m // SEARCH_KNOTS)
    knots = field.knots[::q]
    md = knots.shape[0]
    s = max(1, int(round((md / 2) ** 0.5)))
    dc = jnp.sum((knots[::s] - x) ** 2, axis=-1)
    b1 = _argmin(dc)
    b2 = _argmin(jnp.where(jnp.arange(dc.shape[0]) == b1, jnp.inf, dc))
    idx = (jnp.stack([b1, b2])[:, None] * s + jnp.arange(-s, s + 1)[None, :]).reshape(-1) % md
    j = idx[_argmin(jnp.sum((knots[idx] - x) ** 2, axis=-1))] * q
    if q == 1:
        return j
    idx = (j + jnp.arange(-2 * q, 2 * q + 1)) % m
    return idx[_argmin(jnp.sum((field.knots[idx] - x) ** 2, axis=-1))]


NEAR_WINDOW = 8  # :func:`closest_parameter_near` searches +- this many decimated knots


def _nearest_knot_near(field: DistanceField, x: Float[Array, "2"], hint) -> Float[Array, ""]:
    """Index of the knot nearest to ``x`` among those near the parameter ``hint``: every
    ``q``-th knot within ``NEAR_WINDOW q`` of it (``q = M / 512``, at least 1), then the
    ``4 q + 1`` knots around the best.  34 distances instead of about 115 for 2048
    knots; exact as long as the closest point lies within ``NEAR_WINDOW q`` knots of the
    hint and no other stretch of the outline is nearer."""
    m = field.n_knots
    q = max(1, m // SEARCH_KNOTS)
    h = jnp.round(hint).astype(jnp.int32)
    idx = (h + q * jnp.arange(-NEAR_WINDOW, NEAR_WINDOW + 1)) % m
    j = idx[_argmin(jnp.sum((field.knots[idx] - x) ** 2, axis=-1))]
    if q == 1:
        return j
    idx = (j + jnp.arange(-2 * q, 2 * q + 1)) % m
    return idx[_argmin(jnp.sum((field.knots[idx] - x) ** 2, axis=-1))]


def _newton_foot(field: DistanceField, x, t):
    """``NEWTON_STEPS`` safeguarded Newton steps on ``|x - c(t)|^2`` from ``t`` (a
    loop, not unrolled: the search runs inside every residual, so unrolling it made a
    quarter of the calibration's program)."""

    def step(_, t):
        c, dc, ddc = curve(field, t)
        r = x - c
        g = -r @ dc
        h = jnp.maximum(dc @ dc - r @ ddc, 0.25 * (dc @ dc))
        return t - jnp.clip(g / h, -1.0, 1.0)

    return jax.lax.fori_loop(0, NEWTON_STEPS, step, t)


def closest_parameter(field: DistanceField, x: Float[Array, "2"]) -> Float[Array, ""]:
    """Parameter ``t*`` of the point of the curve closest to ``x`` (no gradient)."""
    field = jax.lax.stop_gradient(field)
    x = jax.lax.stop_gradient(x)
    return _newton_foot(field, x, _nearest_knot(field, x).astype(jnp.float64))


def closest_parameter_near(field: DistanceField, x: Float[Array, "2"], hint) -> Float[Array, ""]:
    """:func:`closest_parameter` searched only near the parameter ``hint`` (a previous
    closest point: a solver's iterates move the transferred samples a few knots at a
    time).  The caller checks that the hint was near enough (see
    :func:`sorjax.core._bundle.solve`)."""
    field = jax.lax.stop_gradient(field)
    x = jax.lax.stop_gradient(x)
    return _newton_foot(field, x, _nearest_knot_near(field, x, jax.lax.stop_gradient(hint)).astype(jnp.float64))


def signed_distance(field: DistanceField, x: Float[Array, "2"], hint=None) -> Float[Array, ""]:
    """Signed distance from ``x`` to the outline: positive outside, negative inside,
    in the units of the outline's points.  Differentiable in ``x`` and in the field.

    The closest parameter is searched without gradient, then one Newton step is
    taken *with* gradient: its value is unchanged at convergence, and its derivative
    is the implicit-function-theorem derivative of the closest point, so first and
    second derivatives of the distance (curvature included) are right: needed by
    implicit differentiation through an optimum, which uses the Hessian.

    ``hint``: search the closest point only near this parameter
    (:func:`closest_parameter_near`); by default the whole outline is searched."""
    t = closest_parameter(field, x) if hint is None else closest_parameter_near(field, x, hint)
    return signed_distance_at(field, x, t)


def signed_distance_at(field: DistanceField, x: Float[Array, "2"], t) -> Float[Array, ""]:
    """:func:`signed_distance` with the closest-point parameter ``t`` already searched
    (:func:`closest_parameter` or :func:`closest_parameter_near`): one Newton step with
    gradient from ``t``, then the distance along the normal there."""
    c, dc, ddc = curve(field, t)
    r = x - c
    h = jnp.maximum(dc @ dc - r @ ddc, 0.25 * (dc @ dc))
    t = t + (r @ dc) / h
    c, dc, _ = curve(field, t)
    n = jnp.stack([dc[1], -dc[0]]) / jnp.linalg.norm(dc)
    return (x - c) @ n


def signed_distances(field: DistanceField, x: Float[Array, "N 2"], hints=None) -> Float[Array, "N"]:
    """:func:`signed_distance` for a batch of points (``hints``: one per point, or None)."""
    if hints is None:
        return jax.vmap(signed_distance, in_axes=(None, 0))(field, x)
    return jax.vmap(signed_distance, in_axes=(None, 0, 0))(field, x, hints)


def checked_distances(field: DistanceField, x: Float[Array, "N 2"], hints=None):
    """What a solver that searched closest points near ``hints`` (N,) needs at its end,
    in one pass: ``(d, t, d_near)``, the signed distances of the points ``x`` with the
    whole outline searched (as :func:`signed_distances` without hints), their
    closest-point parameters ``t`` (:func:`closest_parameter`: the hints of the next
    solve) and the distances searched near ``hints`` (what the solver saw: the two
    differ where a closest point left its window).  The two searches' Newton steps and
    distances are one ``vmap``-ed evaluation: half the program of evaluating each.
    ``hints`` None: ``d_near`` is ``d`` (only the whole outline searched)."""
    fs, xs = jax.lax.stop_gradient(field), jax.lax.stop_gradient(x)

    def one(x, xs, h):
        k = [_nearest_knot(fs, xs)] + ([] if h is None else [_nearest_knot_near(fs, xs, h)])
        t = jax.vmap(lambda k: _newton_foot(fs, xs, k))(jnp.stack(k).astype(jnp.float64))
        d = jax.vmap(lambda t: signed_distance_at(field, x, t))(t)
        return d[0], t[0], d[-1]

    if hints is None:
        return jax.vmap(lambda x, xs: one(x, xs, None))(x, xs)
    return jax.vmap(one)(x, xs, jax.lax.stop_gradient(hints))


CORNER_MIN_DEG = 1.5
CORNER_RATIO = 4.0
CORNER_GUARD = 12


def corner_knots(field: DistanceField) -> Float[Array, " M"]:
    """1.0 at knots where the outline turns abruptly (a corner: the waist of the two
    spheres, a rim meeting a body, an occlusion junction, a jump of curvature), else 0.

    With ``turn_i`` the turning angle at knot ``i``, a corner concentrates its angle in
    one or two knots: ``spike_i = turn_i + max(turn_{i-1}, turn_{i+1})``.  The local
    baseline ``b_i`` is the median turning angle over knots ``i +- 3..6``.  Knot ``i`` is
    a corner when ``spike_i - 2 b_i > max(CORNER_MIN_DEG, CORNER_RATIO b_i)``: a smooth
    curve turns evenly and noise turns every knot, neither makes a spike.  Near a
    corner the interpolating spline rings (decaying by ~0.27 per knot), so distances
    read there are less accurate."""
    p = field.knots
    a = p - jnp.roll(p, 1, axis=-2)
    b = jnp.roll(p, -1, axis=-2) - p
    turn = jnp.abs(jnp.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], jnp.sum(a * b, -1)))
    spike = turn + jnp.maximum(jnp.roll(turn, 1), jnp.roll(turn, -1))
    base = jnp.median(jnp.stack([jnp.roll(turn, k) for k in (-6, -5, -4, -3, 3, 4, 5, 6)]), axis=0)
    thr = jnp.maximum(jnp.radians(CORNER_MIN_DEG), CORNER_RATIO * base)
    return (spike - 2.0 * base > thr).astype(p.dtype)


def sample_weights(field: DistanceField, n: int) -> Float[Array, " n"]:
    """Weights of the ``n`` samples of :func:`curve_points`: 0 for a sample within
    ``CORNER_GUARD`` knots of a corner (:func:`corner_knots`), else 1.  Corners map to
    corners under the homology, so the guard keeps both the samples and their images
    off the ringing part of the spline (which matters at the 1e-3 px level: for exact
    outlines).  When more than 3 % of the knots are corners the outline is noisy
    (noise, not geometry, makes the spikes: exact outlines have a handful) and every
    weight is 1."""
    m = field.n_knots
    c = corner_knots(field)
    near = jnp.zeros_like(c)
    for k in range(-CORNER_GUARD, CORNER_GUARD + 1):
        near = jnp.maximum(near, jnp.roll(c, k))
    idx = jnp.round(jnp.arange(n) * (m / n)).astype(jnp.int32) % m
    w = 1.0 - near[idx]
    return jnp.where(jnp.sum(c) > 0.03 * m, jnp.ones_like(w), w)


def curve_points(field: DistanceField, n: int) -> Float[Array, "n 2"]:
    """``n`` points of the spline at evenly spaced parameters ``t_k = k M / n``
    (evenly spaced in arc length to the accuracy of the knots' spacing)."""
    t = jnp.arange(n) * (field.n_knots / n)
    return jax.vmap(lambda s: curve(field, s)[0])(t)


def setup(points: Float[Array, "M 2"], n_samples: int, smooth_samples: float = 0.0):
    """The one field-setup routine: ``(field, samples, weights)`` of an outline's ``M``
    evenly spaced points: its :class:`DistanceField`, ``n_samples`` evenly spaced
    samples (:func:`curve_points`) and their corner weights (:func:`sample_weights`).
    Pure; ``jax.vmap`` it over views."""
    field = make_field(points, smooth_samples)
    return field, curve_points(field, n_samples), sample_weights(field, n_samples)
