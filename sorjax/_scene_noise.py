"""Noise models of the scenes' outlines (pixels).

:func:`paper_noise` (the paper's smoothed uniform noise along the normal) and
:func:`gaussian_noise` (i.i.d. Gaussian along the normal), both along the outward
normals of :func:`outline_normals`; :func:`distance_to_polyline` to check outlines
against an exact one.
"""

from __future__ import annotations

import math

import numpy as np

from ._curves import _check_outline, closest_points_on_polyline
from ._scene_trace import _signed_area
from ._scene_types import SeedLike, _rng


def _check_sigma(sigma) -> float:
    sigma = float(sigma)
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a finite number >= 0 (pixels), got {sigma}")
    return sigma


def distance_to_polyline(points, polyline, chunk: int = 256) -> np.ndarray:
    """Unsigned distance (pixels) from each of ``points`` (K, 2) to the closed polyline
    ``polyline`` (M, 2): the nearest of its M segments, searched exhaustively
    (:func:`closest_points_on_polyline`).  For checking outlines against an exact one."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    foot, _, _ = closest_points_on_polyline(pts, polyline, chunk)
    return np.hypot(*(pts - foot).T)


def outline_normals(outline) -> np.ndarray:
    """Unit outward normals (M, 2) of a closed outline, from central differences.

    Tangent ``T_i = x_{i+1} - x_{i-1}`` (cyclic); normal ``(T_y, -T_x) / |T|`` times the
    sign of the shoelace area, which points outwards for either orientation.
    """
    x = _check_outline(outline)
    T = np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0)
    nt = np.hypot(T[:, 0], T[:, 1])
    if np.any(nt <= 0):
        raise ValueError("outline has repeated points: the normal is undefined")
    T /= nt[:, None]
    s = 1.0 if _signed_area(x) >= 0 else -1.0
    return s * np.column_stack([T[:, 1], -T[:, 0]])


def paper_noise(
    outline, sigma: float, seed_or_rng: SeedLike, *, smooth_px: float = 2.0, preserve_std: bool = False
) -> np.ndarray:
    """The paper's noise: each outline point moved along its normal by smoothed uniform noise.

    Exactly:

    1. arc length ``s_i`` of each point along the closed polyline (total length ``L``);
    2. ``N = max(8, ceil(L / delta))`` (at most ``4 M + 8``) magnitudes
       ``u_k ~ U(-sigma, sigma)`` i.i.d. at arc-length spacing ``L / N``,
       ``delta = min(1, smooth_px / 2)`` px;
    3. circular convolution with a normalised periodic Gaussian of standard deviation
       ``smooth_px`` px of arc length: the paper's text, literally ("uniform random
       noise of maximum sigma ... the magnitudes of the noise were smoothed by a
       Gaussian filter").  Smoothing lowers the amplitude: with the default 2 px the
       displacement's standard deviation is about ``0.22 sigma`` (``sigma / sqrt(3)``
       times ``1 / sqrt(2 sqrt(pi) smooth_px / delta)``).  With ``preserve_std=True``
       the smoothed magnitudes are instead multiplied by ``1 / sqrt(sum w_k^2)`` (``w``
       the kernel weights) so that the marginal standard deviation is again
       ``sigma / sqrt(3)``, that of the raw uniform noise, and clipped to
       ``[-sigma, sigma]`` (about 8 % of the values are clipped);
    4. periodic linear interpolation at ``s_i`` and displacement of point ``i`` by that
       amount along its outward normal (:func:`outline_normals`).

    ``smooth_px = 0`` (or below 1e-9) gives i.i.d. ``U(-sigma, sigma)`` magnitudes per point.  Returns a
    new (M, 2) array; the input is not modified.
    """
    x = _check_outline(outline)
    sigma = _check_sigma(sigma)
    smooth_px = float(smooth_px)
    if not (np.isfinite(smooth_px) and smooth_px >= 0):
        raise ValueError(f"smooth_px must be >= 0, got {smooth_px}")
    rng, _ = _rng(seed_or_rng)
    nrm = outline_normals(x)
    M = len(x)
    if smooth_px < 1e-9:
        m = rng.uniform(-sigma, sigma, M)
    else:
        seg = np.hypot(*(np.roll(x, -1, axis=0) - x).T)
        s = np.concatenate([[0.0], np.cumsum(seg[:-1])])
        L = float(seg.sum())
        N = min(max(8, int(math.ceil(L / min(1.0, smooth_px / 2.0)))), 4 * M + 8)
        delta = L / N
        u = rng.uniform(-sigma, sigma, N)
        k = np.arange(N)
        dist = np.minimum(k, N - k) * delta
        wgt = np.exp(-0.5 * (dist / smooth_px) ** 2)
        wgt /= wgt.sum()
        sm = np.real(np.fft.ifft(np.fft.fft(u) * np.fft.fft(wgt)))
        if preserve_std:
            sm = np.clip(sm / math.sqrt(np.sum(wgt**2)), -sigma, sigma)
        pos = s / delta
        i0 = np.floor(pos).astype(np.int64)
        fr = pos - i0
        i0 %= N
        m = (1.0 - fr) * sm[i0] + fr * sm[(i0 + 1) % N]
    return x + m[:, None] * nrm


def gaussian_noise(outline, sigma: float, seed_or_rng: SeedLike) -> np.ndarray:
    """Each outline point moved along its outward normal (:func:`outline_normals`) by an
    i.i.d. ``N(0, sigma^2)`` amount (pixels).  Returns a new (M, 2) array."""
    x = _check_outline(outline)
    sigma = _check_sigma(sigma)
    rng, _ = _rng(seed_or_rng)
    return x + rng.normal(0.0, sigma, len(x))[:, None] * outline_normals(x)
