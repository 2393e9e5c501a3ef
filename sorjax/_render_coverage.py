"""Exact anti-aliased rasterisation for :mod:`sorjax.render`: the fraction of each
pixel covered by a polygon, computed exactly along image rows with ``supersample``
sub-rows per pixel (a box pixel, as a real sensor's).

Pixels as in OpenCV: the centre of pixel ``(row i, column j)`` is ``(x, y) = (j, i)``;
the pixel covers ``[j - 0.5, j + 0.5] x [i - 0.5, i + 0.5]``.
"""

from __future__ import annotations

import math

import numpy as np


def polygon_coverage(polygon, shape: tuple[int, int], supersample: int = 32):
    """Fraction of each pixel covered by a closed polygon.

    Parameters
    ----------
    polygon : (M, 2) array
        Closed simple polygon in pixels (OpenCV convention; no repeated end point; any
        orientation).  For a self-intersecting polygon the result is the clipped
        winding number, not the even-odd area.
    shape : (H, W)
        Image size in pixels (rows, columns).
    supersample : int
        Sub-rows per pixel row.  Along each sub-row the covered length of every pixel is
        exact; the sub-rows are averaged (midpoint rule), so the coverage is exact for
        edges that are not nearly horizontal and within ``1 / supersample`` otherwise.

    Returns
    -------
    coverage : (H, W) float64 in [0, 1]
        Parts of the polygon outside the image are clipped.
    """
    p = np.asarray(polygon, dtype=np.float64)
    H, W = int(shape[0]), int(shape[1])
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"polygon must be a finite (M, 2) array with M >= 3, got shape {p.shape}")
    S = int(supersample)
    if S < 1:
        raise ValueError("supersample must be >= 1")
    cov = np.zeros((H, W))
    q = np.roll(p, -1, axis=0)
    ya, yb = p[:, 1], q[:, 1]
    lo, hi = np.minimum(ya, yb), np.maximum(ya, yb)
    # sub-row g has centre y_g = -0.5 + (g + 0.5) / S; an edge owns the sub-rows with
    # lo <= y_g < hi (half-open, so every crossing is counted once)
    g_lo = np.maximum(np.ceil((lo + 0.5) * S - 0.5), 0).astype(np.int64)
    g_hi = np.minimum(np.ceil((hi + 0.5) * S - 0.5) - 1, H * S - 1).astype(np.int64)
    n = np.maximum(g_hi - g_lo + 1, 0)
    if n.sum() == 0:
        return cov
    e = np.repeat(np.arange(len(p)), n)
    start = np.repeat(np.cumsum(n) - n, n)
    g = g_lo[e] + (np.arange(int(n.sum())) - start)
    y = -0.5 + (g + 0.5) / S
    xa, xb = p[e, 0], q[e, 0]
    x = xa + (y - ya[e]) * (xb - xa) / (yb[e] - ya[e])
    area = 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))
    # with a positive area (clockwise as displayed) the right side goes down: a downward
    # crossing ends a covered run, an upward one starts it
    w = np.where(yb[e] > ya[e], -1.0, 1.0) * (1.0 if area > 0 else -1.0)
    jc = np.floor(x + 0.5)  # column whose square holds x
    frac = jc + 0.5 - x  # covered part of that column to the right of x
    jci = np.clip(jc, -1, W).astype(np.int64)
    nrow = H * S
    part = np.zeros(nrow * (W + 2))
    step = np.zeros(nrow * (W + 2))
    inside = (jc >= 0) & (jc <= W - 1)
    np.add.at(part, g[inside] * (W + 2) + jci[inside] + 1, w[inside] * frac[inside])
    k = np.where(jc < 0, 0, jci + 1)  # first fully covered column (local +1 offset)
    okk = k <= W - 1
    np.add.at(step, g[okk] * (W + 2) + k[okk] + 1, w[okk])
    rows = part.reshape(nrow, W + 2) + np.cumsum(step.reshape(nrow, W + 2), axis=1)
    rows = rows[:, 1 : W + 1]
    cov = rows.reshape(H, S, W).mean(axis=1)
    return np.clip(cov, 0.0, 1.0)


def _coverage_in_box(polygon, shape, supersample, margin=2):
    """polygon_coverage computed in the polygon's bounding box only; full-size result."""
    H, W = shape
    x0 = max(0, int(math.floor(polygon[:, 0].min())) - margin)
    y0 = max(0, int(math.floor(polygon[:, 1].min())) - margin)
    x1 = min(W, int(math.ceil(polygon[:, 0].max())) + margin + 1)
    y1 = min(H, int(math.ceil(polygon[:, 1].max())) + margin + 1)
    cov = np.zeros((H, W))
    if x1 > x0 and y1 > y0:
        cov[y0:y1, x0:x1] = polygon_coverage(polygon - [x0, y0], (y1 - y0, x1 - x0), supersample)
    return cov
