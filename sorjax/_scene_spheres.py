"""Two intersecting spheres (Section 8 of the paper): the object, its camera poses and its
exact outline.

A sphere with centre ``c`` and radius ``rho`` is the quadric
``Q = [[I, -c], [-c^T, c.c - rho^2]]``; its image is the conic ``C = (P Q^-1 P^T)^-1``
(an ellipse).  The outline is the boundary of the union of the two filled ellipses: the
arcs of each ellipse outside the other one, sampled through the ellipses' parametric
forms, the corners found by bisection to machine precision.  Object units are "sphere
units" (only ratios matter), pixels and cameras as in :mod:`sorjax.scenes`.
"""

from __future__ import annotations

import math

import numpy as np

from ._scene_camera import look_at
from ._scene_trace import _Path, _trace_outline


#: The two spheres ``((centre, radius), (centre, radius))`` in object units; the
#: revolution axis is the object Y axis.  Radii 1.0 and 0.75, centres 1.2 apart: the
#: spheres meet in the circle ``y = 0.78229...``, radius 0.6228.
TWO_SPHERES = (((0.0, 0.0, 0.0), 1.0), ((0.0, 1.2, 0.0), 0.75))

#: Camera positions of :func:`two_spheres` (at f = 700, 640x480): (elevation deg,
#: azimuth deg, roll deg, du px, dv px).  The camera looks at the object centre
#: ``O = (0, 0.475, 0)`` from distance 8.5 along the direction
#: ``(cos e sin a, sin e, cos e cos a)`` (up = +Y, the small sphere on top), is rolled
#: about its optical axis, and is then translated parallel to the image plane so that
#: ``O`` images ``(du, dv)`` px from the principal point.
TWO_SPHERES_VIEWS = (
    (25.0, 0.0, 10.0, 170.0, 20.0),
    (-20.0, 120.0, -15.0, -160.0, -30.0),
    (5.0, 240.0, 30.0, 150.0, 80.0),
    (40.0, 60.0, -35.0, -150.0, 90.0),
    (-35.0, 200.0, 20.0, 150.0, 50.0),
    (15.0, 300.0, 60.0, -80.0, -110.0),
    (-5.0, 30.0, -50.0, 150.0, -60.0),
    (50.0, 160.0, 5.0, -175.0, -10.0),
)

_TWO_SPHERES_CENTRE = np.array([0.0, 0.475, 0.0])
_TWO_SPHERES_DISTANCE = 8.5


def sphere_image_conic(P, centre, radius) -> np.ndarray:
    """Image conic ``C = (P Q^-1 P^T)^-1`` of the sphere with ``centre`` and ``radius``.

    Uses the dual quadric ``Q* = [[c c^T - rho^2 I, c], [c^T, 1]]`` (``Q Q* = -rho^2 I``).
    The result is scaled so that ``x^T C x < 0`` inside the ellipse and
    ``|| C ||_F = 1``.
    """
    P = np.asarray(P, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    Qs = np.zeros((4, 4))
    Qs[:3, :3] = np.outer(c, c) - radius**2 * np.eye(3)
    Qs[:3, 3] = Qs[3, :3] = c
    Qs[3, 3] = 1.0
    Cd = P @ Qs @ P.T
    Cm = np.linalg.inv(Cd)
    Cm = 0.5 * (Cm + Cm.T)
    x0 = P @ np.append(c, 1.0)
    if x0 @ Cm @ x0 > 0:
        Cm = -Cm
    return Cm / np.linalg.norm(Cm)


def _ellipse_param(Cm: np.ndarray):
    """Centre, axes matrix ``E`` such that ``x(t) = x0 + E (cos t, sin t)`` traces the conic."""
    A, b, c = Cm[:2, :2], Cm[:2, 2], Cm[2, 2]
    x0 = -np.linalg.solve(A, b)
    k = b @ np.linalg.solve(A, b) - c
    if k < 0:
        A, k = -A, -k
    lam, V = np.linalg.eigh(A / k)
    if not np.all(lam > 0):
        raise ValueError("a sphere does not image as an ellipse: it is not entirely in front of the camera")
    return x0, V * (1.0 / np.sqrt(lam))[None, :]


def _conic_distance(Cm: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """First-order signed distance (px) of pixels to a conic (negative inside)."""
    h = np.column_stack([pts, np.ones(len(pts))])
    Ch = h @ Cm
    val = np.sum(Ch * h, axis=1)
    grad = 2.0 * np.hypot(Ch[:, 0], Ch[:, 1])
    return val / grad


def two_spheres_poses(
    f: float = 700.0, n_views: int = 3, *, image_size=(640, 480), aspect_ratio: float = 1.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Camera poses ``(R, t)`` of :func:`two_spheres` (see :data:`TWO_SPHERES_VIEWS`).

    The rotation and the pixel offset of the object centre from the principal point are
    those of the table (offsets scaled by ``height / 480``); the depth of the object
    centre is ``8.5 * (f / 700) * (480 / height)``, so the outline keeps the same size
    and place in pixels for any ``f`` while perspective weakens as ``f`` grows (the
    viewing rays get closer to the optical axis), as the paper's error analysis
    assumes.
    """
    if not 1 <= n_views <= len(TWO_SPHERES_VIEWS):
        raise ValueError(f"n_views must be between 1 and {len(TWO_SPHERES_VIEWS)}, got {n_views}")
    h = float(image_size[1])
    s = h / 480.0
    fu, fv = aspect_ratio * f, f
    D = _TWO_SPHERES_DISTANCE * (f / 700.0) / s
    O = _TWO_SPHERES_CENTRE
    poses = []
    for e, a, roll, du, dv in TWO_SPHERES_VIEWS[:n_views]:
        e, a = math.radians(e), math.radians(a)
        u = np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
        R, _ = look_at(O + _TWO_SPHERES_DISTANCE * u, O, (0.0, 1.0, 0.0), math.radians(roll))
        c_cam = np.array([du * s * D / fu, dv * s * D / fv, D])
        poses.append((R, c_cam - R @ O))
    return poses


def _two_sphere_outline(P: np.ndarray, spacing: float) -> np.ndarray:
    conics = [sphere_image_conic(P, c, r) for c, r in TWO_SPHERES]
    paths = []
    for i in range(2):
        x0, E = _ellipse_param(conics[i])
        other = conics[1 - i]

        def func(t, x0=x0, E=E):
            img = x0[None, :] + np.column_stack([np.cos(t), np.sin(t)]) @ E.T
            return img, np.zeros((len(t), 0))

        def hidden(img, aux, other=other):
            return _conic_distance(other, img) < -1e-9

        def hidden_strict(img, aux, other=other):
            return _conic_distance(other, img) < -1e-12

        paths.append(_Path(func, hidden, 0.0, 2.0 * math.pi, True, f"sphere{i}", hidden_strict=hidden_strict))
    img, _, _ = _trace_outline(paths, spacing=spacing, coarse_gap=1.0)
    return img
