"""Radial lens distortion of the scenes' outlines.

OpenCV's radial model about the principal point in camera-normalised coordinates,
``m_d = (1 + k1 |m|^2 + k2 |m|^4) m``, ``x = K m_d`` (:mod:`sorjax.core._distortion`).
A distorted outline is the pinhole silhouette mapped exactly through the distortion
(the map is one-to-one where it is used: every pinhole outline point must lie within
0.9 of the model's monotone radius, else ValueError), traced densely enough that the
distorted points are still at most ``spacing`` pixels apart.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ._scene_camera import _check_K


def _distortion_note(k) -> str:
    return "" if k is None else f", radial distortion k1={k[0]:g} k2={k[1]:g}"


def _as_pair(k):
    return None if k is None else (float(k[0]), float(k[1]))


def _check_distortion(distortion):
    """``None`` or the float64 (2,) ``(k1, k2)`` of a ``distortion`` argument."""
    if distortion is None:
        return None
    k = np.asarray(distortion, dtype=np.float64).reshape(-1)
    if k.shape != (2,) or not np.all(np.isfinite(k)):
        raise ValueError(f"distortion must be None or finite (k1, k2), got {distortion!r}")
    return k


def distort_outline(outline, K, distortion, what: str = "outline") -> np.ndarray:
    """Pinhole outline points (M, 2, pixels) mapped through the radial distortion
    ``(k1, k2)`` about ``K``'s principal point (:func:`sorjax.core._distortion.distort`,
    exact), point ``i`` the image of point ``i``.  Raises ValueError when a
    point lies beyond 0.9 of the model's monotone radius (where it folds or is close
    to folding: no longer a one-to-one, invertible image)."""
    from .core._distortion import distort, monotone_radius

    K = _check_K(K)
    k = _check_distortion(distortion)
    x = np.asarray(outline, dtype=np.float64)
    m = np.linalg.solve(K, np.column_stack([x, np.ones(len(x))]).T).T[:, :2]
    rmax = 0.9 * float(monotone_radius(k))
    rho = float(np.max(np.hypot(m[:, 0], m[:, 1])))
    if rho > rmax:
        raise ValueError(f"{what}: reaches normalised radius {rho:.3f}, beyond 0.9 of where the distortion "
                         f"k = ({k[0]:g}, {k[1]:g}) stops being one-to-one ({rmax:.3f})")
    return np.asarray(distort(x, K, k))


def _traced_distorted(trace: Callable[[float], np.ndarray], K, k, spacing: float, what: str):
    """``(outline, pinhole outline or None)``: ``trace(spacing)`` (a pinhole outline at
    that spacing) distorted by ``k`` (None: as it is), retraced finer when the
    distortion stretches it beyond ``spacing``; both rolled to start at the distorted
    outline's top-most point (point ``i`` of one is the image of point ``i`` of the
    other)."""
    pts = trace(spacing)
    if k is None:
        return pts, None
    d = distort_outline(pts, K, k, what)
    gap = float(np.max(np.hypot(*(np.roll(d, -1, axis=0) - d).T)))
    if gap > spacing:
        pts = trace(spacing * 0.98 * spacing / gap)
        d = distort_outline(pts, K, k, what)
    top = -int(np.argmin(d[:, 1]))
    return np.roll(d, top, axis=0), np.roll(pts, top, axis=0)
