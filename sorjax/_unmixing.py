"""The unmixing of a segmentation's edge pixels into a soft mask, and the sharpness of
the image's edges that chooses its band (images float64 BGR in 8-bit units, lengths in
pixels), computed tile by tile on large windows with the same numbers as on the whole.
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def _soft_alpha(img: np.ndarray, fg: np.ndarray, *, inner: float = 1.5, sigma: float = 1.2,
                extrapolate: float = 2.0) -> np.ndarray:
    """Soft mask: the binary segmentation ``fg`` refined by unmixing its boundary pixels.

    A pixel near the boundary (closer than ``inner`` px) is modelled as
    ``a F + (1 - a) B``: ``a`` the fraction of it that the object covers (blurred by the
    camera's point-spread function, whose 0.5 level is still the edge), ``F`` and ``B``
    the local object and background colours.  ``B`` is the Gaussian-weighted (``sigma``
    px) mean colour of the background pixels ``inner`` to ``inner + 2`` px from the
    boundary; ``F`` is the same mean over the object's pixels ``inner`` to ``inner + 1``
    px inside (``F2``), extrapolated towards the edge by ``extrapolate`` times the
    difference ``F2 - F3`` with the next ring in: shaded objects darken or brighten
    fast towards their limb, like ``sqrt`` of the distance to it, and an
    unextrapolated ``F`` moves the edge of the darker side inwards (on renders at
    f = 1500 px the left-right asymmetry of the outline error fell from 0.13 px RMS
    without extrapolation to 0.04 px with a factor 2, which was also better than 1.5 or
    2.5; ``sigma`` 1.2 px was better than 0.6 to 0.8 px, one round better than two or
    three).  ``a`` is the projection of the colour onto the segment ``B -> F``.  The
    binary value is kept where the model does not fit: contrast ``|F - B|`` below 12
    levels, a colour farther than ``max(12, 0.3 |F - B|)`` from the segment, or local
    colour spread above ``0.25 |F - B|``.  ``img`` is float64 BGR in 8-bit units.
    """
    I = np.asarray(img, dtype=np.float64)

    def wmean(src):
        w = cv2.GaussianBlur(src, (0, 0), sigma)
        m = cv2.GaussianBlur(I * src[:, :, None], (0, 0), sigma) / np.maximum(w, 1e-6)[:, :, None]
        m2 = cv2.GaussianBlur(np.sum(I * I, axis=2) * src, (0, 0), sigma) / np.maximum(w, 1e-6)
        return w, m, np.maximum(m2 - np.sum(m * m, axis=2), 0.0)

    cur = np.asarray(fg, dtype=bool)
    if not cur.any() or cur.all():
        return cur.astype(np.float64)
    u8 = cur.astype(np.uint8)
    din = cv2.distanceTransform(u8, cv2.DIST_L2, 5)
    dout = cv2.distanceTransform(1 - u8, cv2.DIST_L2, 5)
    f2 = ((din >= inner) & (din < inner + 1)).astype(np.float64)
    f3 = ((din >= inner + 1) & (din < inner + 2)).astype(np.float64)
    wf, Fm, vf = wmean(np.maximum(f2, f3))
    wb, Bc, vb = wmean(((dout >= inner) & (dout < inner + 2)).astype(np.float64))
    w2, F2, _ = wmean(f2)
    w3, F3, _ = wmean(f3)
    have2 = w2 > 1e-3
    grad = np.where((have2 & (w3 > 1e-3))[:, :, None], F2 - F3, 0.0)
    Fc = np.where(have2[:, :, None], F2, Fm) + extrapolate * grad
    d = Fc - Bc
    d2 = np.sum(d * d, axis=2)
    e = I - Bc
    a = np.sum(e * d, axis=2) / np.maximum(d2, 1e-9)
    res = np.sqrt(np.maximum(np.sum(e * e, axis=2) - a * a * d2, 0.0))
    c = np.sqrt(d2)
    near = ((din > 0) & (din < inner)) | ((dout > 0) & (dout < inner))
    ok = (near & (wf > 1e-3) & (wb > 1e-3) & (c >= 12.0) & (res <= np.maximum(12.0, 0.3 * c))
          & (np.sqrt(np.maximum(vf, vb)) <= 0.25 * c))
    alpha = cur.astype(np.float64)
    alpha[ok] = np.clip(a[ok], 0.0, 1.0)
    return alpha


def _gradient_magnitude(img: np.ndarray, sigma: float) -> np.ndarray:
    g = cv2.GaussianBlur(img, (0, 0), sigma)
    gx = cv2.Sobel(g, cv2.CV_64F, 1, 0, ksize=1) / 2.0
    gy = cv2.Sobel(g, cv2.CV_64F, 0, 1, ksize=1) / 2.0
    return np.sqrt(np.sum(gx * gx + gy * gy, axis=2))


def _edge_gradients(img: np.ndarray, fg: np.ndarray, core=None) -> tuple[np.ndarray, np.ndarray]:
    """``(fine, coarse)``: at the boundary pixels of ``fg`` (within ``core``, a window
    ``(y0, y1, x0, x1)`` of it, when given), the largest colour-gradient magnitude
    within 2 px after a Gaussian blur of 0.7 px and of 1.5 px."""
    u8 = np.asarray(fg, dtype=np.uint8)
    din = cv2.distanceTransform(u8, cv2.DIST_L2, 5)
    dout = cv2.distanceTransform(1 - u8, cv2.DIST_L2, 5)
    edge = ((din > 0) & (din <= 1)) | ((dout > 0) & (dout <= 1))
    if core is not None:
        y0, y1, x0, x1 = core
        keep = np.zeros_like(edge)
        keep[y0:y1, x0:x1] = True
        edge &= keep
    if not edge.any():
        return np.zeros(0), np.zeros(0)
    k = np.ones((5, 5), np.uint8)
    return cv2.dilate(_gradient_magnitude(img, 0.7), k)[edge], cv2.dilate(_gradient_magnitude(img, 1.5), k)[edge]


def _edge_sharpness(image, fg: np.ndarray) -> float:
    """How wide the colour edges along the boundary of ``fg`` are (see :func:`_inner_band`).

    The median, over the boundary pixels with the stronger half of the gradients, of
    the largest colour-gradient magnitude within 2 px after a Gaussian blur of 1.5 px
    divided by the same after 0.7 px; the step response gives about
    ``sqrt((s^2 + 0.49) / (s^2 + 2.25))`` for an edge of width (sigma) ``s``: larger for
    blurred edges.  ``image``: float64 BGR (H, W, 3), or a function of a window
    ``(y0, y1, x0, x1)`` giving it there (then computed tile by tile, :func:`_tiles`)."""
    parts = [_edge_gradients(image(*pad), fg[pad[0]:pad[1], pad[2]:pad[3]], core)
             for pad, core in _tiles(fg, _EDGE_REACH)] if callable(image) else [_edge_gradients(image, fg)]
    fine = np.concatenate([f for f, _ in parts])
    coarse = np.concatenate([c for _, c in parts])
    if len(fine) == 0:
        return float("nan")
    strong = fine >= np.median(fine)
    return float(np.median(coarse[strong] / np.maximum(fine[strong], 1e-9)))


# Tiles: the unmixing and the edge measure read a few pixels around each pixel (blurs
# of sigma <= 1.5 px: kernel radius <= 6; distances thresholded below 5 px; a 5 x 5
# dilation), so a window is processed in tiles with a halo of _TILE_HALO px: the same
# numbers as on the whole window (tests), in ~100 MB instead of ~500 bytes per pixel.
_TILE = 512
_TILE_HALO = 16
_EDGE_REACH = 2  # boundary pixels: within 1 px of the other side


def _tiles(fg: np.ndarray, reach: int):
    """``(padded window, core within it)`` of the tiles of ``fg`` that hold a boundary
    pixel (within ``reach`` px of both sides), the padded window reaching
    ``_TILE_HALO`` px beyond the core (clipped to ``fg``)."""
    H, W = fg.shape
    for y in range(0, H, _TILE):
        for x in range(0, W, _TILE):
            y0, y1, x0, x1 = max(0, y - _TILE_HALO), min(H, y + _TILE + _TILE_HALO), \
                max(0, x - _TILE_HALO), min(W, x + _TILE + _TILE_HALO)
            near = fg[max(0, y - reach):min(H, y + _TILE + reach), max(0, x - reach):min(W, x + _TILE + reach)]
            if near.all() or not near.any():
                continue
            yield (y0, y1, x0, x1), (y - y0, min(H, y + _TILE) - y0, x - x0, min(W, x + _TILE) - x0)


def _soft_alpha_tiled(image, fg: np.ndarray, *, inner: float) -> np.ndarray:
    """:func:`_soft_alpha` tile by tile (:func:`_tiles`); ``image`` a function of a
    window ``(y0, y1, x0, x1)`` giving the float64 BGR image there."""
    alpha = np.asarray(fg, dtype=np.float64).copy()
    for (y0, y1, x0, x1), (a0, a1, b0, b1) in _tiles(fg, int(math.ceil(inner)) + 1):
        part = _soft_alpha(image(y0, y1, x0, x1), fg[y0:y1, x0:x1], inner=inner)
        alpha[y0 + a0:y0 + a1, x0 + b0:x0 + b1] = part[a0:a1, b0:b1]
    return alpha


def _inner_band(ratios: list[float]) -> float:
    """Band of :func:`_soft_alpha` for an image, from its objects' edge sharpness.

    A sharp edge (box pixels, little blur) mixes colours within about a pixel across
    it; an edge blurred by a point-spread function of sigma ~0.8 px or more mixes them
    over two or three, which the 1.5 px band truncates (on renders blurred by 0.8 px:
    0.44 px RMS error with it, 0.21 px with a 2.5 px band, which on sharp renders is
    worse: 0.15 px against 0.12).  The per-object sharpness ratios of
    :func:`_edge_sharpness` were 0.51-0.58 on sharp renders (one object with a dark,
    low-contrast side: 0.70), 0.55-0.61 at a blur of 0.5 px (where both bands do about
    as well), 0.62-0.67 at 0.8 px; their median over the image's objects above 0.615
    selects the 2.5 px band."""
    r = [v for v in ratios if np.isfinite(v)]
    return 2.5 if r and float(np.median(r)) > 0.615 else 1.5
