"""Closed polylines in the plane: area, length, self-crossings, resampling, nearest points.

Plain geometry of ``(..., M, 2)`` point arrays (pixels or any units), numpy in and out
(``signed_area`` and ``perimeter`` also take jax arrays).  The bottom of the layering:
outlines, masks, images and scenes all build on it.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def _xp(p):
    """numpy for numpy input (no JAX dispatch at the boundary), else jax.numpy."""
    return np if isinstance(p, np.ndarray) else jnp


def signed_area(p) -> Float[Array, ""]:
    """Shoelace area of a closed polygon (..., M, 2); positive for our orientation."""
    xp = _xp(p)
    q = xp.roll(p, -1, axis=-2)
    return 0.5 * xp.sum(p[..., 0] * q[..., 1] - q[..., 0] * p[..., 1], axis=-1)


def perimeter(p) -> Float[Array, ""]:
    """Length of a closed polygon (..., M, 2), closing edge included."""
    xp = _xp(p)
    return xp.sum(xp.linalg.norm(xp.roll(p, -1, axis=-2) - p, axis=-1), axis=-1)


def _segments_cross(p: np.ndarray) -> bool:
    """True when two non-adjacent edges of the closed polygon ``p`` (n, 2) cross."""
    n = len(p)
    if n > 200:  # decimate: loops smaller than ~1/200 of the outline are noise, not an error
        p = p[np.linspace(0, n, 200, endpoint=False).astype(int)]
        n = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    d = b - a

    def orient(o, dd, x):  # sign of cross(dd, x - o), broadcast (n, 1) vs (1, n)
        return dd[:, None, 0] * (x[None, :, 1] - o[:, None, 1]) - dd[:, None, 1] * (
            x[None, :, 0] - o[:, None, 0]
        )

    o1 = orient(a, d, a)
    o2 = orient(a, d, b)
    # segment i = (a_i, b_i), segment j = (a_j, b_j): they cross when a_j, b_j lie on
    # opposite sides of line i and a_i, b_i on opposite sides of line j.
    s1 = o1 * o2 < 0  # [i, j]: a_j and b_j straddle line i
    s2 = s1.T  # [i, j]: a_i and b_i straddle line j
    idx = np.arange(n)
    gap = np.abs(idx[:, None] - idx[None, :])
    adjacent = (gap <= 1) | (gap >= n - 1)
    return bool(np.any(s1 & s2 & ~adjacent))


def resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    """Resample a closed polyline (N, 2) to ``n`` points evenly spaced in arc length,
    starting at its first point.

    Between input points the curve is a cubic Hermite (Catmull-Rom) interpolant in
    arc length, with tangents by central differences: it passes through every input
    point, and for a smooth curve sampled at spacing ``h`` with radius ``R`` it stays
    within about ``h^4 / R^3`` of it, where straight chords would cut ``h^2 / (8 R)``
    inside.  (Arc length is measured along the chords.)"""
    p = np.asarray(points, dtype=np.float64)
    m = len(p)
    h = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)  # segment i: p_i -> p_{i+1}
    s = np.concatenate([[0.0], np.cumsum(h)])
    tan = (np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)) / (h + np.roll(h, 1))[:, None]
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    i = np.clip(np.searchsorted(s, t, side="right") - 1, 0, m - 1)
    u = ((t - s[i]) / h[i])[:, None]
    j = (i + 1) % m
    hi = h[i][:, None]
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * p[i] + h10 * hi * tan[i] + h01 * p[j] + h11 * hi * tan[j]


def _check_outline(outline) -> np.ndarray:
    x = np.asarray(outline, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2 or len(x) < 3:
        raise ValueError(f"outline must be an (M, 2) array with M >= 3, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("outline contains non-finite values")
    return x


def closest_points_on_polyline(points, polyline, chunk: int = 256) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest point of the closed polyline ``polyline`` (M, 2) to each of ``points``
    (K, 2), searched exhaustively over its M segments (O(K M), in chunks of ``chunk``
    points): ``(foot (K, 2), segment (K,) int, t (K,))``, the foot being
    ``polyline[segment] + t (polyline[segment + 1] - polyline[segment])`` with ``t`` in
    [0, 1] (the segment after the last vertex closes the polyline).  Units are the
    points' (pixels).  Raises ``ValueError`` for a polyline that is not an (M, 2) array
    of M >= 3 finite points, or points that are not finite (x, y) pairs."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.size % 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"points must be finite (x, y) pairs (an (K, 2) array), got shape {pts.shape}")
    pts = pts.reshape(-1, 2)
    a = _check_outline(polyline)
    ab = np.roll(a, -1, axis=0) - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    seg = np.empty(len(pts), dtype=np.intp)
    tt = np.empty(len(pts))
    for s in range(0, len(pts), chunk):
        ap = pts[s : s + chunk, None, :] - a[None]
        t = np.clip(np.sum(ap * ab[None], -1) / L2[None], 0.0, 1.0)
        d = ap - t[..., None] * ab[None]
        k = np.argmin(np.sum(d * d, -1), axis=1)
        seg[s : s + chunk] = k
        tt[s : s + chunk] = t[np.arange(len(k)), k]
    return a[seg] + tt[:, None] * ab[seg], seg, tt
