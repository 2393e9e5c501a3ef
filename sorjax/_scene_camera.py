"""Cameras of the synthetic scenes and the exact ground truth of a view.

Pixels follow OpenCV (centre of the top-left pixel at ``(0, 0)``, ``x`` right, ``y``
down).  Cameras: ``P = K [R | t]`` with ``x_cam = R X + t`` (camera from world/object
coordinates), camera centre ``C = -R^T t``; camera axes ``x`` right, ``y`` down, ``z``
forward.  ``K = [[fu, 0, u0], [0, fv, v0], [0, 0, 1]]`` (zero skew), aspect ratio
``fu / fv``.  Angles are in radians in every argument (degrees where a name says so).

Ground truth of a view (:func:`view_truth`), for a revolution axis through ``A0`` with
unit direction ``d``::

    l_s = (P [A0; 1]) x (P [d; 0])          image of the axis, scaled so a^2 + b^2 = 1
    n   = d x (A0 - C)                      normal of the plane through C and the axis
    v_x = K R n                             its vanishing point, scaled to unit norm
    W   = I - 2 v_x l_s^T / (v_x . l_s)     the harmonic homology of the outline

with the signs ``v_x[2] >= 0`` (or its first non-zero entry positive when ``v_x`` is at
infinity) and ``l_s . v_x > 0``; see :mod:`sorjax.scenes` for the derivation.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ._scene_types import ViewTruth


def _project(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixels of the (n, 3) points ``X`` under the 3x4 camera ``P``."""
    h = X @ P[:, :3].T + P[:, 3]
    return h[:, :2] / h[:, 2:3]


def _as_pose(pose) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` from an ``(R, t)`` pair or a 3x4 ``[R | t]``; checks R is a rotation."""
    if isinstance(pose, np.ndarray) and pose.shape == (3, 4):
        R, t = pose[:, :3], pose[:, 3]
    else:
        try:
            R, t = pose
        except (TypeError, ValueError):
            raise ValueError("a pose must be an (R, t) pair or a 3x4 array [R | t]") from None
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if R.shape != (3, 3) or t.shape != (3,):
        raise ValueError(f"pose needs R of shape (3, 3) and t of shape (3,), got {R.shape}, {t.shape}")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise ValueError("pose contains non-finite values")
    if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-9 or np.linalg.det(R) < 0:
        raise ValueError("R must be a rotation matrix (orthonormal, det +1)")
    return R, t


def _check_K(K) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ValueError("K must be a finite 3x3 matrix")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[2] != (0.0, 0.0, 1.0)) or K[1, 0] != 0:
        raise ValueError("K must be upper triangular with positive focal lengths and K[2] = (0, 0, 1)")
    return K


# ----------------------------------------------------------------------------------
# Cameras and view ground truth
# ----------------------------------------------------------------------------------


def intrinsics(
    f: float, *, aspect_ratio: float = 1.0, principal_point: Sequence[float] = (320.0, 240.0)
) -> np.ndarray:
    """Zero-skew ``K = [[aspect_ratio * f, 0, u0], [0, f, v0], [0, 0, 1]]`` (pixels).

    ``f`` is ``fv``; the aspect ratio is ``fu / fv`` as in the paper.
    """
    if not (f > 0 and aspect_ratio > 0):
        raise ValueError("f and aspect_ratio must be positive")
    u0, v0 = (float(c) for c in principal_point)
    return np.array([[aspect_ratio * f, 0.0, u0], [0.0, f, v0], [0.0, 0.0, 1.0]])


def camera_matrix(K, R, t) -> np.ndarray:
    """``P = K [R | t]`` (3x4)."""
    return np.asarray(K, float) @ np.hstack([np.asarray(R, float), np.reshape(t, (3, 1))])


def camera_centre(R, t) -> np.ndarray:
    """Camera centre ``C = -R^T t`` in world/object coordinates."""
    return -np.asarray(R, float).T @ np.reshape(np.asarray(t, float), 3)


def look_at(camera_centre, target, up=(0.0, 1.0, 0.0), roll: float = 0.0):
    """Pose ``(R, t)`` (``x_cam = R X + t``) of a camera at ``camera_centre`` looking at ``target``.

    The optical axis (camera ``z``) points from the centre to ``target``; the camera
    ``y`` axis (image down) is minus the component of ``up`` orthogonal to the optical
    axis, so ``up`` appears upwards in the image when ``roll = 0``.  The camera is then
    rotated by ``roll`` radians about its optical axis: ``R = Rz(roll) R0`` with
    ``Rz = [[c, -s, 0], [s, c, 0], [0, 0, 1]]``; a positive roll turns the image content
    clockwise as displayed (x right, y down) about the principal point.
    """
    C = np.asarray(camera_centre, dtype=np.float64).reshape(3)
    z = np.asarray(target, dtype=np.float64).reshape(3) - C
    nz = np.linalg.norm(z)
    if not nz > 0:
        raise ValueError("look_at: target coincides with the camera centre")
    z /= nz
    u = np.asarray(up, dtype=np.float64).reshape(3)
    u_perp = u - (u @ z) * z
    if np.linalg.norm(u_perp) <= 1e-9 * max(np.linalg.norm(u), 1e-300):
        raise ValueError("look_at: 'up' is parallel to the viewing direction")
    y = -u_perp / np.linalg.norm(u_perp)
    x = np.cross(y, z)
    c, s = math.cos(roll), math.sin(roll)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.stack([x, y, z])
    return R, -R @ C


def pose_at_pixel(profile, K, elevation_deg: float, azimuth_deg: float, roll: float = 0.0, pixel=None,
                  fill: float = 0.5, image_height: float = 480.0):
    """Pose ``(R, t)`` of a camera that sees the upright ``profile``'s centre ``O`` (on
    its axis, half-way up) at ``pixel`` (px; None: the principal point).

    The camera looks at ``O`` from elevation ``elevation_deg`` and azimuth
    ``azimuth_deg`` (degrees, about the object's axis ``y``), rolled by ``roll`` rad
    (:func:`look_at`), at the distance where the object's bounding sphere spans
    ``fill`` of ``image_height``; it is then moved parallel to the image plane so
    that ``O`` lands at ``pixel``.  With ``pixel=None`` the optical axis meets the
    revolution axis and ``v_x`` is at infinity (the degenerate views of the paper's
    Section 6)."""
    K = np.asarray(K, dtype=np.float64)
    O = np.array([0.0, 0.5 * (profile.y0 + profile.y1), 0.0])
    Rb = math.hypot(0.5 * (profile.y1 - profile.y0), profile.r_max)
    D = 2.0 * math.sqrt(K[0, 0] * K[1, 1]) * Rb / (fill * image_height)
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    u = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    R, _ = look_at(O + D * u, O, (0.0, 1.0, 0.0), roll)
    pix = (K[0, 2], K[1, 2]) if pixel is None else pixel
    c_cam = np.array([(pix[0] - K[0, 2]) * D / K[0, 0], (pix[1] - K[1, 2]) * D / K[1, 1], D])
    return R, c_cam - R @ O


def harmonic_homology(v, l) -> np.ndarray:
    """``W = I - 2 v l^T / (v . l)`` (an involution fixing the line ``l`` pointwise)."""
    v = np.asarray(v, dtype=np.float64).reshape(3)
    l = np.asarray(l, dtype=np.float64).reshape(3)
    den = float(v @ l)
    if abs(den) <= 1e-14 * np.linalg.norm(v) * np.linalg.norm(l):
        raise ValueError("harmonic homology undefined: the vertex lies on the axis (v . l = 0)")
    return np.eye(3) - 2.0 * np.outer(v, l) / den


def view_truth(K, R, t, outline, *, axis_point=(0.0, 0.0, 0.0), axis_direction=(0.0, 1.0, 0.0),
               outline_pinhole=None) -> ViewTruth:
    """The :class:`ViewTruth` of a view: ``l_s``, ``v_x`` and ``W`` from the formulas of the
    module docstring, for the revolution axis through ``axis_point`` along
    ``axis_direction`` (world/object coordinates).  ``outline_pinhole``: with lens
    distortion, the undistorted outline (``outline`` being the distorted one)."""
    K = _check_K(K)
    R, t = _as_pose((R, t))
    P = camera_matrix(K, R, t)
    A0 = np.asarray(axis_point, dtype=np.float64).reshape(3)
    d = np.asarray(axis_direction, dtype=np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    C = camera_centre(R, t)
    l = np.cross(P @ np.append(A0, 1.0), P @ np.append(d, 0.0))
    nl = math.hypot(l[0], l[1])
    n = np.cross(d, A0 - C)
    if nl <= 1e-12 * np.linalg.norm(l) or np.linalg.norm(n) <= 1e-12 * np.linalg.norm(A0 - C):
        raise ValueError("the camera centre lies on the revolution axis: l_s and v_x are undefined")
    l = l / nl
    v = K @ R @ n
    v = v / np.linalg.norm(v)
    if v[2] < 0 or (v[2] == 0 and v[np.flatnonzero(v)[0]] < 0):
        v = -v
    if l @ v < 0:
        l = -l
    outline = np.ascontiguousarray(outline, dtype=np.float64)
    if outline_pinhole is not None:
        outline_pinhole = np.ascontiguousarray(outline_pinhole, dtype=np.float64)
    return ViewTruth(outline=outline, l_s=l, v_x=v, W=harmonic_homology(v, l), P=P, outline_pinhole=outline_pinhole)
