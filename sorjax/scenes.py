"""Synthetic scenes with exact ground truth for calibration from surfaces of revolution.

This module is pure NumPy (float64) and
builds the test material of Wong, Mendonca & Cipolla, "Camera Calibration from
Surfaces of Revolution" (TPAMI 2003): the exact silhouette of a surface of revolution
(SOR) seen by a known pinhole camera, with the exact image of the revolution axis
``l_s``, the vanishing point ``v_x`` and the harmonic homology ``W`` of every view.

Conventions
-----------
* Pixels follow OpenCV: the centre of the top-left pixel is ``(0, 0)``, ``x`` grows to
  the right and ``y`` downwards.  Image points are in pixels, homogeneous points are
  3-vectors ``(x, y, 1)`` up to scale, a homogeneous line ``l`` satisfies ``l . x = 0``.
* Cameras: ``P = K [R | t]`` with ``x_cam = R X + t`` (camera from world/object
  coordinates), camera centre ``C = -R^T t``; camera axes: ``x`` right, ``y`` down,
  ``z`` forward (depth > 0 in front of the camera).  ``K = [[fu, 0, u0], [0, fv, v0],
  [0, 0, 1]]`` (zero skew), aspect ratio ``fu / fv``.
* Objects: the revolution axis is the object ``Y`` axis.  A solid of revolution is the
  union of the discs ``{(x, y, z): x^2 + z^2 <= r(y)^2}`` for ``y0 <= y <= y1``, i.e. the
  surface ``X(y, phi) = (r(y) cos phi, y, r(y) sin phi)`` closed by flat end discs where
  ``r(y_end) > 0``.  Object units are metres for the named profiles and "sphere units"
  for the two-sphere scene; only ratios matter.  Angles are in radians in every
  argument (degrees only in the tables of the docstrings).
* Outlines are closed ``(M, 2)`` float64 arrays of exact points of the silhouette, in
  boundary order, without a repeated end point, with a positive shoelace area in
  pixel coordinates (clockwise as displayed, because ``y`` points down), starting at
  the top-most point, and spaced at most ``spacing`` pixels apart (about uniformly).

Ground truth of a view
----------------------
For a camera ``P = K [R | t]`` with centre ``C`` and a revolution axis through ``A0``
with unit direction ``d`` (here ``A0 = 0``, ``d = (0, 1, 0)`` in object coordinates)::

    l_s = (P [A0; 1]) x (P [d; 0])          image of the axis, scaled so a^2 + b^2 = 1
    n   = d x (A0 - C)                      normal of the plane through C and the axis
    v_x = K R n                             its vanishing point, scaled to unit norm
    W   = I - 2 v_x l_s^T / (v_x . l_s)     the harmonic homology of the outline

The plane ``Pi = (n, -n . C)`` back-projects from ``l = K^-T R n``, which is
``omega v_x`` with ``omega = K^-T K^-1``: the pole-polar relation ``l_s ~ omega v_x``
(eq. 18 of the paper) holds exactly.  Signs: ``v_x`` has ``v_x[2] >= 0`` (or its first
non-zero entry positive when ``v_x`` is at infinity) and ``l_s . v_x > 0``, so
``l_s = +lambda omega v_x`` with ``lambda > 0``.

Exact silhouettes
-----------------
* Two spheres (Section 8 of the paper): a sphere with centre ``c`` and radius ``rho``
  is the quadric ``Q = [[I, -c], [-c^T, c.c - rho^2]]``; its image is the conic
  ``C = (P Q^-1 P^T)^-1`` (an ellipse).  The outline is the boundary of the union of the
  two filled ellipses: the arcs of each ellipse outside the other one, sampled through
  the ellipses' parametric forms, the corners found by bisection to machine precision.
* A general SOR: the projection of the solid is the union over ``y`` of the filled
  ellipses that image the discs.  Its boundary consists of (i) the images of the
  contour generator, where the surface normal ``N = (cos phi, -r'(y), sin phi)`` is
  perpendicular to the viewing ray ``X - C``, i.e. (``C`` in object coordinates)::

      Cx cos(phi) + Cz sin(phi) = g(y) = r(y) - r'(y) (y - Cy)
      phi = alpha +- arccos(g(y) / rho_c),  rho_c = hypot(Cx, Cz),  alpha = atan2(Cz, Cx)

  (two branches, the two sides of the outline, joining at folds where
  ``|g| = rho_c``), and (ii) arcs of the ellipses that image the end circles (and the
  crease circles at declared profile breaks).  A candidate point is *hidden* when its
  viewing ray enters the interior of the solid: ``max_s r(y(s)) - rho(s) > 0`` along the
  ray (``rho(s)`` the distance of the ray point from the axis); this maximum is found
  by a dense search along the ray followed by golden-section refinement of the local
  maxima, so it is exact to rounding.  The visible pieces are cut at the exact
  occlusion points (bisection), resampled uniformly in arc length by re-evaluating
  the exact parametrisation, joined in boundary order and verified: closed, no
  self-intersection, no gap larger than the sample spacing, every point on the
  silhouette (max penetration below ``1e-10`` times the object size, i.e. far below
  1e-6 px for the scenes built here).

Lens distortion
---------------
Every scene function takes ``distortion=(k1, k2)`` (default None: a pinhole camera,
every result as without the argument): OpenCV's radial model about the principal point
in camera-normalised coordinates, ``m_d = (1 + k1 |m|^2 + k2 |m|^4) m``, ``x = K m_d``
(:mod:`sorjax.core._distortion`).  A view's outline is then the pinhole silhouette mapped
exactly through the distortion (the map is one-to-one where it is used: every pinhole
outline point must lie within 0.9 of the model's monotone radius,
:func:`sorjax.core._distortion.monotone_radius`, else ValueError), traced densely enough
that the distorted points are still at most ``spacing`` apart;
:attr:`ViewTruth.outline_pinhole` keeps the pinhole outline, and ``l_s``, ``v_x``, ``W``
are those of the pinhole image (the distortion-free model the calibration estimates).

Noise
-----
:func:`paper_noise` (the paper's smoothed uniform noise along the normal) and
:func:`gaussian_noise` (i.i.d. Gaussian along the normal).

Every random function takes an ``int`` seed or a ``numpy.random.Generator``; scenes
record the integer seed (``None`` when a Generator was passed or nothing was random).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence, Union

import numpy as np

from ._curves import _check_outline, closest_points_on_polyline

__all__ = [
    "distance_to_polyline",
    "ViewTruth",
    "Scene",
    "Silhouette",
    "Profile",
    "intrinsics",
    "camera_matrix",
    "camera_centre",
    "look_at",
    "pose_at_pixel",
    "harmonic_homology",
    "view_truth",
    "sphere_image_conic",
    "TWO_SPHERES",
    "TWO_SPHERES_VIEWS",
    "two_spheres_poses",
    "two_spheres",
    "two_spheres_profile",
    "vase",
    "bowl",
    "bottle",
    "wine_glass",
    "candle_holder",
    "cylinder",
    "PROFILES",
    "perturb_profile",
    "sor_silhouette",
    "silhouette_margin",
    "sor_scene",
    "random_sor_scene",
    "outline_normals",
    "paper_noise",
    "gaussian_noise",
    "distort_outline",
]

SeedLike = Union[int, np.integer, np.random.Generator]

# ----------------------------------------------------------------------------------
# Data types
# ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ViewTruth:
    """Exact ground truth of one view.

    Attributes
    ----------
    outline : (M, 2) float64
        Exact dense closed outline in pixels, no repeated end point, ordered along the
        curve (positive shoelace area, i.e. clockwise as displayed), spacing at most
        the scene's sample spacing (0.3 px by default).
    l_s : (3,) float64
        Image of the revolution axis, homogeneous line with ``a^2 + b^2 = 1``.
    v_x : (3,) float64
        Vanishing point of the normal of the plane through the axis and the camera
        centre, homogeneous, unit norm.
    W : (3, 3) float64
        Harmonic homology ``I - 2 v_x l_s^T / (v_x . l_s)``; maps the outline onto itself.
    P : (3, 4) float64
        Camera matrix ``K [R | t]`` of this view (object/world to pixels).
    outline_pinhole : (M', 2) float64 or None
        With lens distortion: the pinhole (undistorted) outline, which ``W`` maps onto
        itself and which :attr:`outline` is the distorted image of; None without.
    """

    outline: np.ndarray
    l_s: np.ndarray
    v_x: np.ndarray
    W: np.ndarray
    P: np.ndarray
    outline_pinhole: np.ndarray | None = None


@dataclass(frozen=True)
class Scene:
    """A set of views of a surface of revolution by one camera ``K``.

    Attributes
    ----------
    K : (3, 3) float64
        True intrinsics (zero skew), pixels.
    views : tuple of ViewTruth
    image_size : (width, height) in pixels.
    seed : int or None
        The seed the scene was drawn with (None when not random or drawn from a
        Generator).
    description : str
        Human-readable account of the scene (object, camera, poses).
    distortion : (k1, k2) or None
        OpenCV radial distortion coefficients of the camera (None: a pinhole camera).
    """

    K: np.ndarray
    views: tuple[ViewTruth, ...]
    image_size: tuple[int, int]
    seed: int | None
    description: str
    distortion: tuple[float, float] | None = None

    @property
    def outlines(self) -> list[np.ndarray]:
        """The views' outlines, ``[view.outline for view in views]``."""
        return [v.outline for v in self.views]


@dataclass(frozen=True)
class Silhouette:
    """Exact silhouette of a SOR in one view (see :func:`sor_silhouette`).

    Attributes
    ----------
    points : (M, 2) float64
        The outline in pixels (same conventions as :attr:`ViewTruth.outline`).
    points_3d : (M, 3) float64
        The object-frame surface points that project onto ``points``.
    source : (M,) str
        Where each point comes from: ``"contour"`` (contour generator: the surface
        normal is perpendicular to the viewing ray), ``"cap"`` (an end circle of the
        solid) or ``"crease"`` (a circle at a declared profile break).
    """

    points: np.ndarray
    points_3d: np.ndarray
    source: np.ndarray


# ----------------------------------------------------------------------------------
# Small helpers
# ----------------------------------------------------------------------------------


def _rng(seed_or_rng: SeedLike) -> tuple[np.random.Generator, int | None]:
    """``(Generator, recorded seed)`` from an int seed or a Generator."""
    if isinstance(seed_or_rng, np.random.Generator):
        return seed_or_rng, None
    if isinstance(seed_or_rng, (int, np.integer)) and not isinstance(seed_or_rng, bool):
        if int(seed_or_rng) < 0:
            raise ValueError(f"seed must be a non-negative int, got {seed_or_rng}")
        return np.random.default_rng(int(seed_or_rng)), int(seed_or_rng)
    raise TypeError(
        f"seed must be an int or a numpy.random.Generator, got {type(seed_or_rng).__name__}"
    )


def _signed_area(p: np.ndarray) -> float:
    """Shoelace area of the closed polygon ``p`` (positive: clockwise as displayed)."""
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


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


# ----------------------------------------------------------------------------------
# Outline engine: exact parametric paths -> visible pieces -> one closed outline
# ----------------------------------------------------------------------------------


@dataclass
class _Path:
    """A candidate curve: ``func(tau) -> (pixels (n, 2), aux (n, k))``, exact for any tau.

    Closed paths are periodic with period ``t1 - t0``.  ``nodes`` are parameters that
    are sampled exactly and, when visible next to a hidden sample, taken as the exact
    visibility boundary (tangential junctions, where bisection would be ill-posed).
    ``hidden(pixels, aux) -> bool`` tells whether points are strictly inside the
    silhouette; ``hidden_strict`` (default: ``hidden``) is a tighter version used to
    locate occlusion corners by bisection.
    """

    func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    hidden: Callable[[np.ndarray, np.ndarray], np.ndarray]
    t0: float
    t1: float
    closed: bool
    label: str
    nodes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hidden_strict: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None


@dataclass
class _Piece:
    img: np.ndarray
    aux: np.ndarray
    label: str
    closed: bool


def _refine(path: _Path, tau: np.ndarray, max_gap: float, img=None, aux=None, max_rounds: int = 60):
    """Insert midpoints until consecutive pixels are at most ``max_gap`` apart."""
    tau = np.asarray(tau, dtype=np.float64)
    if img is None:
        img, aux = path.func(tau)
    for _ in range(max_rounds):
        gap = np.hypot(*np.diff(img, axis=0).T)
        bad = ~(gap <= max_gap)
        if not bad.any():
            return tau, img, aux
        mid = 0.5 * (tau[:-1][bad] + tau[1:][bad])
        mimg, maux = path.func(mid)
        tau = np.concatenate([tau, mid])
        img = np.concatenate([img, mimg])
        aux = np.concatenate([aux, maux])
        order = np.argsort(tau, kind="stable")
        tau, img, aux = tau[order], img[order], aux[order]
    raise ValueError(
        f"could not sample the {path.label} curve finely enough (a point escapes to "
        "infinity?): the pose gives an outline that cannot be built"
    )


def _bisect_boundary(path: _Path, t_vis: np.ndarray, t_hid: np.ndarray, iters: int = 56) -> np.ndarray:
    """Parameters of the visibility boundary, on the visible side, to machine precision."""
    lo, hi = t_vis.copy(), t_hid.copy()
    hidden = path.hidden_strict or path.hidden
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        img, aux = path.func(mid)
        h = hidden(img, aux)
        hi = np.where(h, mid, hi)
        lo = np.where(h, lo, mid)
    return lo


def _resample(path: _Path, tau: np.ndarray, spacing: float, closed: bool, min_len: float):
    """Exact points at (nearly) uniform arc-length spacing <= ``spacing`` on ``tau[0]..tau[-1]``."""
    tau, img, aux = _refine(path, tau, spacing / 8.0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(img, axis=0).T))])
    L = cum[-1]
    if not closed and L < min_len:
        return None
    n = max(int(math.ceil(L / (0.98 * spacing))), 3 if closed else 1)
    tt = np.interp(np.linspace(0.0, L, n + 1), cum, tau)
    tt[0], tt[-1] = tau[0], tau[-1]
    # chords can exceed the nominal spacing where the curvature varies fast: split them
    tt, pimg, paux = _refine(path, tt, spacing)
    if closed:
        tt, pimg, paux = tt[:-1], pimg[:-1], paux[:-1]
    return _Piece(pimg, paux, path.label, closed)


def _visible_pieces(path: _Path, spacing: float, coarse_gap: float, min_len: float, n0: int = 96):
    grid = np.linspace(path.t0, path.t1, n0 + 1)
    tau0 = np.unique(np.concatenate([grid, np.asarray(path.nodes, dtype=np.float64)]))
    tau, img, aux = _refine(path, tau0, coarse_gap)
    if path.closed:
        tau, img, aux = tau[:-1], img[:-1], aux[:-1]
    hid = np.asarray(path.hidden(img, aux), dtype=bool)
    exact = np.isin(tau, path.nodes)
    period = path.t1 - path.t0
    if not hid.any():
        if path.closed:
            return [_resample(path, np.append(tau, tau[0] + period), spacing, True, min_len)]
        piece = _resample(path, tau, spacing, False, min_len)
        return [] if piece is None else [piece]
    if hid.all():
        return []
    if path.closed:  # rotate to start at a hidden sample and repeat it at the end
        n = len(tau)
        k = int(np.argmax(hid))
        order = (np.arange(n) + k) % n
        tau = tau[order] + np.where(order < k, period, 0.0)
        hid, exact = hid[order], exact[order]
        tau = np.append(tau, tau[0] + period)
        hid = np.append(hid, True)
        exact = np.append(exact, exact[0])
    # transitions between consecutive samples
    tr = np.flatnonzero(hid[:-1] != hid[1:])
    vis_idx = np.where(hid[tr], tr + 1, tr)
    hid_idx = np.where(hid[tr], tr, tr + 1)
    bound = tau[vis_idx].copy()
    need = ~exact[vis_idx]
    if need.any():
        bound[need] = _bisect_boundary(path, tau[vis_idx][need], tau[hid_idx][need])
    bmap = dict(zip(tr.tolist(), bound.tolist()))
    pieces = []
    vis = ~hid
    i, n = 0, len(tau)
    while i < n:
        if not vis[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and vis[j + 1]:
            j += 1
        ts = list(tau[i : j + 1])
        if i > 0 and tau[i] != bmap[i - 1]:
            ts.insert(0, bmap[i - 1])
        if j < n - 1 and tau[j] != bmap[j]:
            ts.append(bmap[j])
        ts = np.asarray(ts)
        if len(ts) >= 2 and ts[-1] > ts[0]:
            piece = _resample(path, ts, spacing, False, min_len)
            if piece is not None:
                pieces.append(piece)
        i = j + 1
    return pieces


def _chain(pieces: list[_Piece], join_tol: float, dedupe_tol: float):
    """Join pieces end to end into closed loops; raise ValueError when impossible.

    Where two joined ends are closer than ``dedupe_tol`` only the first is kept.
    """
    loops = [(p.img, p.aux, np.full(len(p.img), p.label)) for p in pieces if p.closed]
    open_ = [p for p in pieces if not p.closed]
    used = np.zeros(len(open_), dtype=bool)
    while not used.all():
        k = int(np.argmin(used))
        used[k] = True
        imgs, auxs, labs = [open_[k].img], [open_[k].aux], [np.full(len(open_[k].img), open_[k].label)]
        start = open_[k].img[0]
        while True:
            end = imgs[-1][-1]
            best, best_d, rev = -1, np.linalg.norm(end - start), False
            for j in np.flatnonzero(~used):
                d0 = np.linalg.norm(end - open_[j].img[0])
                d1 = np.linalg.norm(end - open_[j].img[-1])
                if d0 < best_d:
                    best, best_d, rev = j, d0, False
                if d1 < best_d:
                    best, best_d, rev = j, d1, True
            if best_d > join_tol:
                raise ValueError(
                    f"the visible pieces of the silhouette do not join (gap {best_d:.3g} px): "
                    "the pose gives an outline that cannot be built"
                )
            if best < 0:
                break
            used[best] = True
            p = open_[best]
            pi, pa = (p.img[::-1], p.aux[::-1]) if rev else (p.img, p.aux)
            if np.linalg.norm(pi[0] - end) < dedupe_tol:
                pi, pa = pi[1:], pa[1:]
            imgs.append(pi)
            auxs.append(pa)
            labs.append(np.full(len(pi), p.label))
        img, aux, lab = np.concatenate(imgs), np.concatenate(auxs), np.concatenate(labs)
        if len(img) > 1 and np.linalg.norm(img[-1] - img[0]) < dedupe_tol:
            img, aux, lab = img[:-1], aux[:-1], lab[:-1]
        loops.append((img, aux, lab))
    return loops


def _points_in_polygon(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised."""
    x1, y1 = poly[:, 0][None], poly[:, 1][None]
    q = np.roll(poly, -1, axis=0)
    x2, y2 = q[:, 0][None], q[:, 1][None]
    x, y = pts[:, 0][:, None], pts[:, 1][:, None]
    cond = (y1 > y) != (y2 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
    return (np.sum(cond & (x < xi), axis=1) % 2) == 1


def _self_intersections(p: np.ndarray) -> int:
    """Number of properly crossing pairs of non-adjacent edges of the closed polygon."""
    M = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    cell = max(float(np.max(hi - lo)), 1e-9) * 1.0001
    i0 = np.floor((lo - lo.min(0)) / cell).astype(np.int64)
    i1 = np.floor((hi - lo.min(0)) / cell).astype(np.int64)
    ny = int(i1[:, 1].max()) + 2
    segs, keys = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            ok = (i0[:, 0] + dx <= i1[:, 0]) & (i0[:, 1] + dy <= i1[:, 1])
            idx = np.flatnonzero(ok)
            segs.append(idx)
            keys.append((i0[idx, 0] + dx) * ny + (i0[idx, 1] + dy))
    segs, keys = np.concatenate(segs), np.concatenate(keys)
    order = np.argsort(keys, kind="stable")
    segs, keys = segs[order], keys[order]
    _, counts = np.unique(keys, return_counts=True)
    si, sj = [], []
    for o in range(1, int(counts.max())):
        same = keys[:-o] == keys[o:]
        si.append(segs[:-o][same])
        sj.append(segs[o:][same])
    if not si:
        return 0
    si, sj = np.concatenate(si), np.concatenate(sj)
    dd = np.abs(si - sj)
    keep = (dd > 1) & (dd < M - 1)
    si, sj = si[keep], sj[keep]

    def orient(p0, p1, p2):
        return (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0])

    A, B, Cq, D = a[si], b[si], a[sj], b[sj]
    cross = (orient(A, B, Cq) * orient(A, B, D) < 0) & (orient(Cq, D, A) * orient(Cq, D, B) < 0)
    pairs = {(min(x, y), max(x, y)) for x, y in zip(si[cross].tolist(), sj[cross].tolist())}
    return len(pairs)


def _trace_outline(paths: list[_Path], *, spacing: float, coarse_gap: float):
    """Outer boundary of the silhouette from its candidate paths (see module docstring)."""
    join_tol = min(0.1, 0.5 * spacing)
    min_len = 1e-2 * spacing
    pieces = []
    for p in paths:
        pieces.extend(_visible_pieces(p, spacing, coarse_gap, min_len))
    if not pieces:
        raise ValueError("no visible silhouette piece: the pose gives an outline that cannot be built")
    # Pieces meeting at a corner end within ~1e-7 px of each other (transversal
    # occlusion), or up to ~1e-3 px apart, both slightly past the corner, where the
    # occluding curves cross at a grazing angle (the penetration then grows only
    # quadratically); keeping one of the two end points avoids a tiny bow-tie.
    loops = _chain(pieces, join_tol, dedupe_tol=1e-2 * spacing)
    areas = [abs(_signed_area(l[0])) if len(l[0]) >= 3 else 0.0 for l in loops]
    k = int(np.argmax(areas))
    img, aux, lab = loops[k]
    for j, other in enumerate(loops):  # holes are fine, other outer components are not
        if j == k:
            continue
        pts = other[0][:: max(1, len(other[0]) // 200)]
        inside = _points_in_polygon(img, pts)
        if not inside.all():
            d = np.min(np.hypot(*(pts[~inside][:, None, :] - img[None]).transpose(2, 0, 1)), axis=1)
            if np.any(d > join_tol):
                raise ValueError(
                    "the silhouette has several disjoint components: the pose gives an "
                    "outline that cannot be built"
                )
    if _signed_area(img) < 0:
        img, aux, lab = img[::-1], aux[::-1], lab[::-1]
    s = int(np.argmin(img[:, 1]))
    img, aux, lab = np.roll(img, -s, 0), np.roll(aux, -s, 0), np.roll(lab, -s, 0)
    gaps = np.hypot(*(np.roll(img, -1, 0) - img).T)
    if len(img) < 16 or gaps.max() > spacing * 1.01 + 1e-9:
        raise ValueError(
            f"outline has a gap of {gaps.max():.3g} px (> spacing {spacing} px): the pose gives "
            "an outline that cannot be built"
        )
    if _self_intersections(img):
        raise ValueError("outline self-intersects: the pose gives an outline that cannot be built")
    return img, aux, lab


# ----------------------------------------------------------------------------------
# Two intersecting spheres (Section 8 of the paper)
# ----------------------------------------------------------------------------------

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


def _distortion_note(k) -> str:
    return "" if k is None else f", radial distortion k1={k[0]:g} k2={k[1]:g}"


def _as_pair(k):
    return None if k is None else (float(k[0]), float(k[1]))


def _check_in_image(img: np.ndarray, image_size, what: str) -> None:
    w, h = image_size
    if img[:, 0].min() < 0 or img[:, 1].min() < 0 or img[:, 0].max() > w - 1 or img[:, 1].max() > h - 1:
        raise ValueError(
            f"{what}: the outline leaves the {w}x{h} image (x in [{img[:, 0].min():.1f}, "
            f"{img[:, 0].max():.1f}], y in [{img[:, 1].min():.1f}, {img[:, 1].max():.1f}]); "
            "pass allow_outside=True to accept it"
        )


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


def two_spheres(
    f: float = 700.0,
    *,
    image_size: tuple[int, int] = (640, 480),
    n_views: int = 3,
    aspect_ratio: float = 1.0,
    principal_point: Sequence[float] | None = None,
    spacing: float = 0.3,
    distortion: Sequence[float] | None = None,
) -> Scene:
    """The paper's synthetic scene (Section 8): two intersecting spheres, 1 to 8 views.

    The SOR is the union of the spheres of :data:`TWO_SPHERES` (radii 1.0 and 0.75,
    centres ``(0, 0, 0)`` and ``(0, 1.2, 0)``; axis = object Y axis).  The camera is
    ``K = [[aspect_ratio f, 0, u0], [0, f, v0], [0, 0, 1]]`` with ``(u0, v0)`` the image
    centre ``(width / 2, height / 2)`` = (320, 240) by default, as in the paper.

    Camera positions (at f = 700 on a 640x480 image; see :func:`two_spheres_poses` for
    other f and sizes): looking at ``O = (0, 0.475, 0)`` from distance 8.5, then shifted
    so that ``O`` images at (du, dv) px from the principal point::

        view  elevation  azimuth  roll   (du, dv) px   v_x from centre (f=700)
        0       +25 deg     0     +10    (+170, +20)   2.9e3 px   from above
        1       -20       120     -15    (-160, -30)   3.2e3 px   from below
        2        +5       240     +30    (+150, +80)   2.9e3 px   from the side
        3       +40        60     -35    (-150, +90)   2.9e3 px
        4       -35       200     +20    (+150, +50)   3.1e3 px
        5       +15       300     +60    (-80, -110)   3.6e3 px
        6        -5        30     -50    (+150, -60)   3.5e3 px
        7       +50       160      +5    (-175, -10)   2.9e3 px

    The outline is about 200-235 px tall (0.4-0.5 of the image height) and well off
    centre, roughly perpendicular to the image of the axis, so that the optical axis
    makes about 12-14 deg with the plane through the camera centre and the axis
    (strong perspective): ``v_x`` is finite, about 3000 px from the image centre at
    f = 700 and about four times as far at f = 1400 (same outline size and place).

    Exact outline: each sphere images as the ellipse ``C = (P Q^-1 P^T)^-1``; the outline
    is the boundary of the union of the two filled ellipses (the arc of each ellipse
    outside the other, sampled through the exact parametric form, with the two
    corners found by bisection to machine precision), spacing <= ``spacing`` px.
    ``distortion``: ``(k1, k2)`` radial lens distortion (module docstring; None: none).
    """
    k = _check_distortion(distortion)
    w, h = image_size
    pp = (w / 2.0, h / 2.0) if principal_point is None else principal_point
    K = intrinsics(f, aspect_ratio=aspect_ratio, principal_point=pp)
    views = []
    for i, (R, t) in enumerate(two_spheres_poses(f, n_views, image_size=image_size, aspect_ratio=aspect_ratio)):
        P = camera_matrix(K, R, t)
        img, pin = _traced_distorted(lambda sp, P=P: _two_sphere_outline(P, sp), K, k, spacing, f"two_spheres view {i}")
        _check_in_image(img, image_size, f"two_spheres view {i}")
        views.append(view_truth(K, R, t, img, outline_pinhole=pin))
    desc = (
        f"two intersecting spheres (radii 1.0 and 0.75, centres 1.2 apart), f={f:g}, "
        f"aspect ratio {aspect_ratio:g}, principal point ({pp[0]:g}, {pp[1]:g}), {n_views} views "
        f"from TWO_SPHERES_VIEWS[:{n_views}]"
    ) + _distortion_note(k)
    return Scene(K=K, views=tuple(views), image_size=(int(w), int(h)), seed=None, description=desc,
                 distortion=_as_pair(k))


# ----------------------------------------------------------------------------------
# Profiles of surfaces of revolution
# ----------------------------------------------------------------------------------


def _pchip(x: np.ndarray, v: np.ndarray):
    """PCHIP interpolant of the knots ``(x, v)``: returns ``(f, f')`` as vectorised callables.

    Knot slopes: 0 where the neighbouring secant slopes differ in sign or vanish, else
    their weighted harmonic mean (Fritsch-Carlson); the end slopes use the
    shape-preserving three-point formula.  Outside ``[x0, xn]`` the end cubics extend.
    """
    h = np.diff(x)
    m = np.diff(v) / h
    n = len(x)
    d = np.zeros(n)
    if n == 2:
        d[:] = m[0]
    else:
        w1 = 2.0 * h[1:] + h[:-1]
        w2 = h[1:] + 2.0 * h[:-1]
        same = (np.sign(m[:-1]) * np.sign(m[1:])) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            hm = (w1 + w2) / (w1 / m[:-1] + w2 / m[1:])
        d[1:-1] = np.where(same, hm, 0.0)

        def end(h0, h1, m0, m1):
            e = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
            if np.sign(e) != np.sign(m0):
                return 0.0
            if np.sign(m0) != np.sign(m1) and abs(e) > 3.0 * abs(m0):
                return 3.0 * m0
            return e

        d[0] = end(h[0], h[1], m[0], m[1])
        d[-1] = end(h[-1], h[-2], m[-1], m[-2])

    # power-basis coefficients of each cubic in u = t - x_k (Horner evaluation)
    c0, c1 = v[:-1], d[:-1]
    c2 = (3.0 * m - 2.0 * d[:-1] - d[1:]) / h
    c3 = (d[:-1] + d[1:] - 2.0 * m) / h**2
    inner = x[1:-1]

    def locate(t):
        t = np.asarray(t, dtype=np.float64)
        k = np.searchsorted(inner, t, side="right")
        return k, t - x[k]

    def f(t):
        k, u = locate(t)
        return ((c3[k] * u + c2[k]) * u + c1[k]) * u + c0[k]

    def df(t):
        k, u = locate(t)
        return (3.0 * c3[k] * u + 2.0 * c2[k]) * u + c1[k]

    return f, df


@dataclass(frozen=True, eq=False)
class Profile:
    """Radius function of a solid of revolution about the object Y axis.

    Attributes
    ----------
    name : str
    y0, y1 : float
        Height range (object units), ``y0 < y1``.
    r : callable
        ``r(y) >= 0`` (vectorised); the solid is closed by flat discs at ``y0``/``y1``
        where ``r > 0``.
    dr : callable
        ``r'(y)`` (vectorised), continuous on ``[y0, y1]`` except at ``breaks``.
    breaks : tuple of float
        Heights where ``r'`` jumps (creases); their circles are treated like end
        circles.  Empty for smooth profiles.
    control : (k, 2) array or None
        Control points ``(y, r)`` when built by :meth:`from_points`.
    r_max, scale : float (derived)
        Maximum radius, and ``max(y1 - y0, r_max)``.
    """

    name: str
    y0: float
    y1: float
    r: Callable[[np.ndarray], np.ndarray]
    dr: Callable[[np.ndarray], np.ndarray]
    breaks: tuple[float, ...] = ()
    control: np.ndarray | None = None
    r_max: float = field(init=False)
    scale: float = field(init=False)

    def __post_init__(self):
        if not (np.isfinite(self.y0) and np.isfinite(self.y1) and self.y1 > self.y0):
            raise ValueError(f"profile {self.name!r}: need y0 < y1, got {self.y0}, {self.y1}")
        if any(not (self.y0 < b < self.y1) for b in self.breaks):
            raise ValueError(f"profile {self.name!r}: breaks must lie strictly inside (y0, y1)")
        ys = np.linspace(self.y0, self.y1, 8001)
        rs = np.asarray(self.r(ys), dtype=np.float64)
        if rs.shape != ys.shape or not np.all(np.isfinite(rs)):
            raise ValueError(f"profile {self.name!r}: r(y) must be finite and vectorised")
        if np.any(rs < 0) or rs.max() <= 0:
            raise ValueError(f"profile {self.name!r}: r(y) must be >= 0 and not identically 0")
        inner = ys[1:-1]
        if not np.all(np.isfinite(np.asarray(self.dr(inner), dtype=np.float64))):
            raise ValueError(f"profile {self.name!r}: r'(y) must be finite inside (y0, y1)")
        object.__setattr__(self, "r_max", float(rs.max()))
        object.__setattr__(self, "scale", float(max(self.y1 - self.y0, rs.max())))

    @classmethod
    def from_points(cls, name: str, y, r) -> "Profile":
        """Smooth profile through control points: a PCHIP spline (monotone piecewise cubic
        Hermite, Fritsch-Carlson slopes as in ``scipy.interpolate.PchipInterpolator``;
        C1 and shape preserving, so ``r > 0`` between positive control points); ``dr``
        is its exact derivative."""
        y = np.asarray(y, dtype=np.float64)
        r = np.asarray(r, dtype=np.float64)
        if y.ndim != 1 or y.shape != r.shape or len(y) < 2 or np.any(np.diff(y) <= 0):
            raise ValueError("control points need strictly increasing y and matching r")
        if np.any(r < 0):
            raise ValueError("control radii must be >= 0")
        r_of, dr_of = _pchip(y, r)
        return cls(name=name, y0=float(y[0]), y1=float(y[-1]), r=r_of, dr=dr_of,
                   control=np.column_stack([y, r]))

    def scaled(self, height: float = 1.0, width: float = 1.0, name: str | None = None) -> "Profile":
        """The profile stretched by ``height`` along the axis (about ``y0``) and by ``width``
        radially: ``r_new(y) = width * r(y0 + (y - y0) / height)``."""
        y0, r, dr = self.y0, self.r, self.dr
        ctrl = None
        if self.control is not None:
            ctrl = np.column_stack([y0 + height * (self.control[:, 0] - y0), width * self.control[:, 1]])
        return Profile(
            name=name or self.name,
            y0=y0,
            y1=y0 + height * (self.y1 - y0),
            r=lambda t: width * r(y0 + (np.asarray(t, float) - y0) / height),
            dr=lambda t: (width / height) * dr(y0 + (np.asarray(t, float) - y0) / height),
            breaks=tuple(y0 + height * (b - y0) for b in self.breaks),
            control=ctrl,
        )


def _named(name: str, pts, scale: float) -> Profile:
    pts = np.asarray(pts, dtype=np.float64) * scale
    return Profile.from_points(name, pts[:, 0], pts[:, 1])


def vase(scale: float = 1.0) -> Profile:
    """A 30 cm vase (metres): round body (r 8.8 cm), narrow neck (r 3.2 cm) and a flared
    lip (r 5.8 cm); the neck makes the profile concave, so parts of the contour
    generator are hidden."""
    return _named(
        "vase",
        [(0.000, 0.050), (0.020, 0.066), (0.070, 0.088), (0.120, 0.082), (0.170, 0.058),
         (0.205, 0.038), (0.230, 0.032), (0.260, 0.036), (0.285, 0.050), (0.300, 0.058)],
        scale,
    )


def bowl(scale: float = 1.0) -> Profile:
    """A convex bowl (metres), 7.5 cm tall, base r 4 cm, rim r 9.8 cm; seen from above the
    rim circle is part of the outline."""
    return _named(
        "bowl",
        [(0.000, 0.040), (0.008, 0.045), (0.025, 0.068), (0.045, 0.085), (0.065, 0.095), (0.075, 0.098)],
        scale,
    )


def bottle(scale: float = 1.0) -> Profile:
    """A 28 cm bottle (metres): cylindrical body r 3.8 cm, shoulder, neck r 1.3 cm, lip."""
    return _named(
        "bottle",
        [(0.000, 0.036), (0.010, 0.038), (0.120, 0.038), (0.150, 0.034), (0.180, 0.022),
         (0.200, 0.014), (0.255, 0.013), (0.268, 0.0145), (0.280, 0.0135)],
        scale,
    )


def wine_glass(scale: float = 1.0) -> Profile:
    """A 19 cm wine glass (metres), as a solid: foot r 3.6 cm, stem r 4.5 mm, bowl r 4 cm."""
    return _named(
        "wine_glass",
        [(0.000, 0.036), (0.003, 0.035), (0.008, 0.020), (0.014, 0.006), (0.020, 0.0045),
         (0.075, 0.0045), (0.085, 0.008), (0.100, 0.025), (0.120, 0.036), (0.145, 0.040),
         (0.170, 0.038), (0.190, 0.034)],
        scale,
    )


def candle_holder(scale: float = 1.0) -> Profile:
    """A 15 cm candle holder (metres): wide base r 4.5 cm, stem with a knop, cup r 3.6 cm."""
    return _named(
        "candle_holder",
        [(0.000, 0.045), (0.006, 0.044), (0.015, 0.030), (0.030, 0.016), (0.050, 0.012),
         (0.065, 0.020), (0.080, 0.012), (0.100, 0.011), (0.115, 0.022), (0.130, 0.034),
         (0.140, 0.036), (0.150, 0.033)],
        scale,
    )


def cylinder(radius: float = 0.033, height: float = 0.115) -> Profile:
    """A can: ``r(y) = radius`` on ``[0, height]`` (metres; default a 330 ml can)."""
    if not (radius > 0 and height > 0):
        raise ValueError("radius and height must be positive")
    return Profile(
        name="cylinder",
        y0=0.0,
        y1=float(height),
        r=lambda t: np.full(np.shape(t), float(radius)),
        dr=lambda t: np.zeros(np.shape(t)),
    )


def two_spheres_profile(trim: float = 1e-6) -> Profile:
    """The two spheres of :data:`TWO_SPHERES` as an analytic profile with a crease.

    ``r(y) = sqrt(1 - y^2)`` below the crease ``y_c = 0.7823`` and
    ``sqrt(0.75^2 - (y - 1.2)^2)`` above, on ``[-1 + trim, 1.95 - trim]`` (trimmed so
    that ``r'`` stays finite; tiny end discs close the solid).  Useful to cross-check
    :func:`sor_silhouette` against the conic construction of :func:`two_spheres`.
    """
    (c1, r1), (c2, r2) = TWO_SPHERES
    a, b = c1[1], c2[1]
    yc = (r1**2 - r2**2 + b**2 - a**2) / (2.0 * (b - a))

    def r(y):
        y = np.asarray(y, dtype=np.float64)
        return np.where(y <= yc, np.sqrt(np.maximum(r1**2 - (y - a) ** 2, 0.0)),
                        np.sqrt(np.maximum(r2**2 - (y - b) ** 2, 0.0)))

    def dr(y):
        y = np.asarray(y, dtype=np.float64)
        return np.where(y <= yc, -(y - a) / r(y), -(y - b) / r(y))

    return Profile("two_spheres", a - r1 + trim, b + r2 - trim, r, dr, breaks=(float(yc),))


#: Named profiles: name -> constructor (all in metres).
PROFILES: dict[str, Callable[[], Profile]] = {
    "vase": vase,
    "bowl": bowl,
    "bottle": bottle,
    "wine_glass": wine_glass,
    "candle_holder": candle_holder,
    "cylinder": cylinder,
}


def perturb_profile(profile: Profile, seed_or_rng: SeedLike, amount: float = 0.1) -> Profile:
    """A randomly perturbed copy of ``profile``.

    Height and width are scaled by independent factors ``exp(amount * N(0, 1))``; for a
    control-point profile every control radius is further multiplied by
    ``exp(0.25 * amount * N(0, 1))`` (the spline stays positive).
    """
    rng, _ = _rng(seed_or_rng)
    sh, sw = np.exp(amount * rng.standard_normal(2))
    if profile.control is not None:
        y, r = profile.control.T
        r = r * np.exp(0.25 * amount * rng.standard_normal(len(r)))
        profile = Profile.from_points(profile.name, y, r)
    return profile.scaled(height=float(sh), width=float(sw))


# ----------------------------------------------------------------------------------
# Exact silhouettes of a general SOR
# ----------------------------------------------------------------------------------


def _max_penetration(profile: Profile, C: np.ndarray, D: np.ndarray, n_grid: int = 256,
                     n_peaks: int = 4, iters: int = 48) -> np.ndarray:
    """``max_{s > 0} r(y(s)) - rho(s)`` along the rays ``C + s D`` (object units).

    Positive: the ray enters the interior of the solid (its pixel is strictly inside
    the silhouette); zero: it touches the surface; negative (``-inf`` if the ray misses
    the bounding cylinder): it passes outside.  Dense search over the part of the ray
    inside the bounding cylinder and height slab, then golden-section refinement of
    the ``n_peaks`` best local maxima (exact to rounding for smooth profiles).
    """
    D = np.atleast_2d(np.asarray(D, dtype=np.float64))
    D = D / np.linalg.norm(D, axis=1)[:, None]
    m = len(D)
    Cx, Cy, Cz = (float(c) for c in C)
    Dx, Dy, Dz = D.T
    y0, y1 = profile.y0, profile.y1
    tiny = 1e-14
    flat = np.abs(Dy) < tiny
    with np.errstate(divide="ignore", invalid="ignore"):
        sa, sb = (y0 - Cy) / Dy, (y1 - Cy) / Dy
    in_slab = y0 <= Cy <= y1
    lo = np.where(flat, -np.inf if in_slab else np.inf, np.minimum(sa, sb))
    hi = np.where(flat, np.inf if in_slab else -np.inf, np.maximum(sa, sb))
    Rc = profile.r_max * 1.001 + 1e-12 * profile.scale
    a = Dx**2 + Dz**2
    b = 2.0 * (Cx * Dx + Cz * Dz)
    c = Cx**2 + Cz**2 - Rc**2
    disc = b**2 - 4.0 * a * c
    ok = (a > tiny) & (disc >= 0)
    sq = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c_lo, c_hi = (-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)
    par = a <= tiny
    c_lo = np.where(ok, c_lo, np.where(par & (c <= 0), -np.inf, np.inf))
    c_hi = np.where(ok, c_hi, np.where(par & (c <= 0), np.inf, -np.inf))
    lo = np.maximum(np.maximum(lo, c_lo), 0.0)
    hi = np.minimum(hi, c_hi)
    out = np.full(m, -np.inf)
    valid = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    if not valid.any():
        return out
    vi = np.flatnonzero(valid)
    lo, hi, Dv = lo[vi], hi[vi], D[vi]

    def h(s, Dr):
        y = np.clip(Cy + s * Dr[:, 1:2] if s.ndim == 2 else Cy + s * Dr[:, 1], y0, y1)
        if s.ndim == 2:
            rho = np.hypot(Cx + s * Dr[:, 0:1], Cz + s * Dr[:, 2:3])
        else:
            rho = np.hypot(Cx + s * Dr[:, 0], Cz + s * Dr[:, 2])
        return profile.r(y) - rho

    u = np.linspace(0.0, 1.0, n_grid)
    S = lo[:, None] + (hi - lo)[:, None] * u[None, :]
    H = h(S, Dv)
    best = H.max(axis=1)
    eps = 1e-10 * profile.scale
    und = np.flatnonzero(best <= eps)  # undecided rows: refine their local maxima
    if len(und):
        Hu, Su = H[und], S[und]
        pad = np.pad(Hu, ((0, 0), (1, 1)), constant_values=-np.inf)
        is_max = (Hu >= pad[:, :-2]) & (Hu >= pad[:, 2:])
        vm = np.where(is_max, Hu, -np.inf)
        k = min(n_peaks, n_grid)
        top = np.argpartition(-vm, k - 1, axis=1)[:, :k]
        rows = np.repeat(np.arange(len(und)), k)
        cols = top.reshape(-1)
        keep = np.isfinite(vm[rows, cols])
        rows, cols = rows[keep], cols[keep]
        A = Su[rows, np.maximum(cols - 1, 0)]
        B = Su[rows, np.minimum(cols + 1, n_grid - 1)]
        Dr = Dv[und][rows]
        g = (math.sqrt(5.0) - 1.0) / 2.0
        x1, x2 = B - g * (B - A), A + g * (B - A)
        f1, f2 = h(x1, Dr), h(x2, Dr)
        for _ in range(iters):
            left = f1 > f2
            B = np.where(left, x2, B)
            A = np.where(left, A, x1)
            nx1 = np.where(left, B - g * (B - A), x2)
            nx2 = np.where(left, x1, A + g * (B - A))
            xn = np.where(left, nx1, nx2)
            fn = h(xn, Dr)
            f1, f2 = np.where(left, fn, f2), np.where(left, f1, fn)
            x1, x2 = nx1, nx2
        ref = np.full(len(und), -np.inf)
        np.maximum.at(ref, rows, np.maximum(f1, f2))
        best[und] = np.maximum(best[und], ref)
    out[vi] = best
    return out


def _check_camera(profile: Profile, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera centre in object coordinates; ValueError for unusable cameras."""
    C = camera_centre(R, t)
    rho_c = math.hypot(C[0], C[2])
    if profile.y0 <= C[1] <= profile.y1 and rho_c <= float(profile.r(np.array([C[1]]))[0]):
        raise ValueError(
            f"the camera centre {np.round(C, 6).tolist()} is inside the object {profile.name!r} "
            "(object coordinates): move the camera out of the solid"
        )
    if rho_c <= 1e-9 * profile.scale:
        raise ValueError("the camera centre lies on the revolution axis: l_s and v_x are undefined")
    ys = np.linspace(profile.y0, profile.y1, 4001)
    depth = R[2, 1] * ys + t[2] - profile.r(ys) * math.hypot(R[2, 0], R[2, 2])
    if depth.min() <= 1e-6 * profile.scale:
        raise ValueError(
            f"the object {profile.name!r} is not entirely in front of the camera "
            f"(minimum depth {depth.min():.3g} object units)"
        )
    return C


def _sor_paths(profile: Profile, P: np.ndarray, C: np.ndarray) -> list[_Path]:
    Cx, Cy, Cz = C
    rho_c = math.hypot(Cx, Cz)
    alpha = math.atan2(Cz, Cx)
    eps = 1e-10 * profile.scale
    edges = [profile.y0, *sorted(profile.breaks), profile.y1]
    n_edges = len(edges)

    def hidden(img, X):
        return _max_penetration(profile, C, X - C) > eps

    def hidden_strict(img, X):
        return _max_penetration(profile, C, X - C) > 1e-3 * eps

    def make_g(a, b):
        da = 1e-12 * (b - a)

        def g(y):
            return profile.r(y) - profile.dr(np.clip(y, a + da, b - da)) * (y - Cy)

        return g

    def contour_func(ymap, g):
        def func(tau):
            tau = np.asarray(tau, dtype=np.float64)
            y, sig = ymap(tau)
            th = np.arccos(np.clip(g(y) / rho_c, -1.0, 1.0))
            phi = alpha + sig * th
            r = profile.r(y)
            X = np.column_stack([r * np.cos(phi), y, r * np.sin(phi)])
            return _project(P, X), X

        return func

    paths: list[_Path] = []
    junctions: dict[int, list[float]] = {e: [] for e in range(n_edges)}
    for ei in range(n_edges - 1):
        a, b = edges[ei], edges[ei + 1]
        g = make_g(a, b)
        ys = np.linspace(a, b, 2049)
        with np.errstate(invalid="ignore", over="ignore"):
            q = rho_c**2 - g(ys) ** 2
        pos = np.nan_to_num(q, nan=-1.0, neginf=-1.0) >= 0

        def root(i):  # fold between ys[i] and ys[i + 1]; returned on the q >= 0 side
            lo_, hi_ = ys[i], ys[i + 1]
            good_lo = bool(pos[i])
            for _ in range(80):
                mid = 0.5 * (lo_ + hi_)
                ok = rho_c**2 - g(np.array([mid]))[0] ** 2 >= 0
                if ok == good_lo:
                    lo_ = mid
                else:
                    hi_ = mid
            return lo_ if good_lo else hi_

        idx = np.flatnonzero(pos)
        if len(idx) == 0:
            continue
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        for run in runs:
            ia, ib = int(run[0]), int(run[-1])
            fold_a, fold_b = ia > 0, ib < len(ys) - 1
            ya = root(ia - 1) if fold_a else a
            yb = root(ib) if fold_b else b
            if not yb > ya:
                continue
            if fold_a and fold_b:
                def ymap(t, ya=ya, yb=yb):
                    return ya + (yb - ya) * 0.5 * (1.0 - np.cos(t)), np.where(np.mod(t, 2 * np.pi) < np.pi, 1.0, -1.0)
                paths.append(_Path(contour_func(ymap, g), hidden, 0.0, 2 * math.pi, True, "contour",
                                   hidden_strict=hidden_strict))
            elif fold_a or fold_b:
                if fold_a:
                    def ymap(t, ya=ya, yb=yb):
                        y = np.where(np.abs(t) >= np.pi / 2, yb, ya + (yb - ya) * (1.0 - np.cos(t)))
                        return y, np.where(t >= 0, 1.0, -1.0)
                else:
                    def ymap(t, ya=ya, yb=yb):
                        y = np.where(np.abs(t) >= np.pi / 2, ya, yb - (yb - ya) * (1.0 - np.cos(t)))
                        return y, np.where(t >= 0, 1.0, -1.0)
                paths.append(_Path(contour_func(ymap, g), hidden, -math.pi / 2, math.pi / 2, False, "contour",
                                   hidden_strict=hidden_strict))
            else:
                for sgn in (1.0, -1.0):
                    def ymap(t, sgn=sgn):
                        return t, np.full(np.shape(t), sgn)
                    paths.append(_Path(contour_func(ymap, g), hidden, ya, yb, False, "contour",
                                       hidden_strict=hidden_strict))
            for end_y, is_fold, e in ((ya, fold_a, ei), (yb, fold_b, ei + 1)):
                if not is_fold:
                    th = float(np.arccos(np.clip(g(np.array([end_y]))[0] / rho_c, -1.0, 1.0)))
                    junctions[e] += [alpha + th, alpha - th]
    for e, ye in enumerate(edges):
        re = float(profile.r(np.array([ye]))[0])
        if re <= 1e-12 * profile.scale:
            continue

        def circle(t, ye=ye, re=re):
            t = np.asarray(t, dtype=np.float64)
            X = np.column_stack([re * np.cos(t), np.full(t.shape, ye), re * np.sin(t)])
            return _project(P, X), X

        nodes = np.mod(np.asarray(junctions[e], dtype=np.float64), 2 * math.pi)
        label = "cap" if e in (0, n_edges - 1) else "crease"
        paths.append(_Path(circle, hidden, 0.0, 2 * math.pi, True, label, nodes, hidden_strict))
    return paths


def sor_silhouette(profile: Profile, K, R, t, *, spacing: float = 0.3) -> Silhouette:
    """Exact silhouette of the solid of revolution ``profile`` seen by ``K [R | t]``.

    ``(R, t)`` is camera-from-object (``x_cam = R X + t``).  The outline is the outer
    boundary of the projected solid (the union over ``y`` of the images of the discs of
    radius ``r(y)``), built from both branches of the contour generator
    (``Cx cos phi + Cz sin phi = r - r' (y - Cy)``) and the end/crease circles, with the
    hidden parts removed exactly (see the module docstring).  Points are spaced at most
    ``spacing`` px apart, nearly uniformly; every point lies on the true silhouette to
    rounding (verified: the penetration of its viewing ray is below ``1e-10`` times the
    object size).

    Raises ValueError when the camera is inside the object, on its axis, when the
    object is not entirely in front of the camera, or when the outline cannot be
    built (pieces that do not join, self-intersections).
    """
    if not spacing > 0:
        raise ValueError("spacing must be positive")
    K = _check_K(K)
    R, t = _as_pose((R, t))
    C = _check_camera(profile, R, t)
    P = camera_matrix(K, R, t)
    paths = _sor_paths(profile, P, C)
    eps = 1e-10 * profile.scale
    # Visibility is classified on samples <= `coarse` px apart; an occlusion shorter than
    # that can be missed, which the final checks detect: then retry with finer samples.
    last_err: Exception | None = None
    for coarse in (1.0, 0.25, 0.0625):
        try:
            img, X, lab = _trace_outline(paths, spacing=spacing, coarse_gap=coarse)
        except ValueError as err:
            last_err = err
            continue
        pen = _max_penetration(profile, C, X - C)
        if np.all(pen <= eps):
            return Silhouette(points=img, points_3d=X, source=lab.astype(str))
        last_err = ValueError(
            f"could not separate the visible silhouette exactly (max penetration "
            f"{float(pen.max()):.3g}): the pose gives an outline that cannot be built"
        )
    assert last_err is not None
    raise last_err


def silhouette_margin(profile: Profile, K, R, t, points) -> np.ndarray:
    """Penetration of the viewing rays of pixel ``points`` (N, 2) into the solid.

    ``max_{s > 0} r(y(s)) - rho(s)`` along each back-projected ray, in object units:
    ``> 0`` strictly inside the silhouette, ``0`` on it, ``< 0`` outside (``-inf`` when
    the ray misses the bounding cylinder).  Near the silhouette a pixel displacement
    ``d`` changes it by about ``d * depth / f``.
    """
    K = _check_K(K)
    R, t = _as_pose((R, t))
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    rays = np.column_stack([pts, np.ones(len(pts))]) @ np.linalg.inv(K).T @ R
    return _max_penetration(profile, camera_centre(R, t), rays)


def sor_scene(
    profile: Profile,
    K,
    poses: Sequence,
    *,
    image_size: tuple[int, int] = (640, 480),
    seed: int | None = None,
    spacing: float = 0.3,
    allow_outside: bool = False,
    description: str | None = None,
    distortion: Sequence[float] | None = None,
) -> Scene:
    """Scene of the solid ``profile`` seen by the camera ``K`` from each pose.

    ``poses``: a sequence of ``(R, t)`` pairs (camera from object, ``x_cam = R X + t``;
    e.g. from :func:`look_at`) or 3x4 ``[R | t]`` arrays.  Each view's outline is the
    exact silhouette of :func:`sor_silhouette`; ``l_s``, ``v_x`` and ``W`` follow from
    the axis (object Y axis through the origin).  Raises ValueError when a pose puts the
    camera inside the object or the object partly behind the camera, when the outline
    cannot be built, or when it leaves the image (unless ``allow_outside``).
    ``seed`` is only recorded.  ``distortion``: ``(k1, k2)`` radial lens distortion
    (module docstring; None: none).
    """
    K = _check_K(K)
    k = _check_distortion(distortion)
    if len(poses) == 0:
        raise ValueError("need at least one pose")
    views = []
    for i, pose in enumerate(poses):
        R, t = _as_pose(pose)
        img, pin = _traced_distorted(lambda sp, R=R, t=t: sor_silhouette(profile, K, R, t, spacing=sp).points,
                                     K, k, spacing, f"view {i}")
        if not allow_outside:
            _check_in_image(img, image_size, f"view {i}")
        views.append(view_truth(K, R, t, img, outline_pinhole=pin))
    if description is None:
        description = f"SOR {profile.name!r} in {len(views)} views, K = {np.round(K, 3).tolist()}" + _distortion_note(k)
    return Scene(K=K, views=tuple(views), image_size=(int(image_size[0]), int(image_size[1])),
                 seed=seed, description=description, distortion=_as_pair(k))


def _random_pose(rng, profile: Profile, K, image_size, lying: bool):
    """A random camera-from-object pose; returns (R, t, info)."""
    w, h = image_size
    O = np.array([0.0, 0.5 * (profile.y0 + profile.y1), 0.0])
    Rb = math.hypot(0.5 * (profile.y1 - profile.y0), profile.r_max)
    Y = np.array([0.0, 1.0, 0.0])
    if lying:
        th = rng.uniform(0.0, 2 * math.pi)
        n_t = np.array([math.cos(th), 0.0, math.sin(th)])  # table normal, across the axis
        beta = rng.uniform(math.radians(10.0), math.radians(75.0))
        gam = rng.uniform(0.0, 2 * math.pi)
        u = math.sin(beta) * n_t + math.cos(beta) * (math.cos(gam) * Y + math.sin(gam) * np.cross(Y, n_t))
        up = n_t
        info = f"lying, elevation {math.degrees(beta):.0f} deg, azimuth to axis {math.degrees(gam):.0f} deg"
    else:
        beta = rng.uniform(math.radians(-30.0), math.radians(70.0))
        az = rng.uniform(0.0, 2 * math.pi)
        u = np.array([math.cos(beta) * math.sin(az), math.sin(beta), math.cos(beta) * math.cos(az)])
        up = Y
        info = f"upright, elevation {math.degrees(beta):.0f} deg"
    roll = rng.uniform(-math.pi, math.pi)
    frac = rng.uniform(0.3, 0.75)
    fu, fv, u0, v0 = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    fm = math.sqrt(fu * fv)
    D = 2.0 * fm * Rb / (frac * min(w, h))
    R, _ = look_at(O + D * u, O, up, roll)
    rpix = fm * Rb / math.sqrt(max(D**2 - Rb**2, 1e-12))
    px = rng.uniform(rpix + 2.0, w - 3.0 - rpix) if w - 3.0 - rpix > rpix + 2.0 else 0.5 * (w - 1)
    py = rng.uniform(rpix + 2.0, h - 3.0 - rpix) if h - 3.0 - rpix > rpix + 2.0 else 0.5 * (h - 1)
    c_cam = np.array([(px - u0) * D / fu, (py - v0) * D / fv, D])
    info += f", roll {math.degrees(roll):.0f} deg, centre at ({px:.0f}, {py:.0f}) px"
    return R, c_cam - R @ O, info


def random_sor_scene(
    seed: SeedLike,
    n_views: int = 3,
    *,
    K=None,
    shapes: Sequence[str] | None = None,
    lying: bool = True,
    perturb: bool = True,
    vary_aspect: bool = False,
    image_size: tuple[int, int] = (640, 480),
    spacing: float = 0.3,
    min_size_px: float = 80.0,
    min_axis_angle_deg: float = 15.0,
    max_tries: int = 200,
    distortion: Sequence[float] | None = None,
) -> Scene:
    """A random SOR scene, deterministic given ``seed``.

    * Object: one of ``shapes`` (names of :data:`PROFILES`; default all), perturbed by
      :func:`perturb_profile` when ``perturb``.
    * Camera (unless ``K`` is given): ``f`` uniform in [500, 1500] px, aspect ratio 1
      (uniform in [0.9, 1.1] when ``vary_aspect``), zero skew, principal point off the
      image centre by up to 10 % of the width/height in each direction.  All views
      share K.
    * Each view has its own pose: with probability 1/2 when ``lying`` the object lies on
      its side (horizontal axis, camera 10..75 deg above the table, any azimuth),
      otherwise it stands upright (camera elevation -30..70 deg); any roll about the
      optical axis; object centre anywhere in the image; object size 30..75 % of the
      image's smaller side.  Poses are redrawn when the outline cannot be built, leaves
      the image, spans less than ``min_size_px`` px, or when the line of sight to the
      object centre is within ``min_axis_angle_deg`` of the axis.  ``v_x`` may be
      anywhere (even very far away).
    * ``distortion``: ``(k1, k2)`` radial lens distortion (module docstring; None:
      none, the same scene as without the argument); a pose is also redrawn when the
      distorted outline leaves the image or reaches where the model folds.  The
      random draws do not depend on it except through such redraws.
    """
    kd = _check_distortion(distortion)
    rng, recorded = _rng(seed)
    if n_views < 1:
        raise ValueError("n_views must be >= 1")
    names = list(PROFILES) if shapes is None else list(shapes)
    for nm in names:
        if nm not in PROFILES:
            raise ValueError(f"unknown shape {nm!r}; choose from {sorted(PROFILES)}")
    name = names[int(rng.integers(len(names)))]
    profile = PROFILES[name]()
    if perturb:
        profile = perturb_profile(profile, rng)
    w, h = image_size
    if K is None:
        f = rng.uniform(500.0, 1500.0)
        a = rng.uniform(0.9, 1.1) if vary_aspect else 1.0
        pp = (0.5 * w + rng.uniform(-0.1, 0.1) * w, 0.5 * h + rng.uniform(-0.1, 0.1) * h)
        K = intrinsics(f, aspect_ratio=a, principal_point=pp)
    K = _check_K(K)
    Y = np.array([0.0, 1.0, 0.0])
    views, infos = [], []
    for i in range(n_views):
        for _ in range(max_tries):
            lie = bool(lying and rng.uniform() < 0.5)
            R, t, info = _random_pose(rng, profile, K, image_size, lie)
            C = camera_centre(R, t)
            O = np.array([0.0, 0.5 * (profile.y0 + profile.y1), 0.0])
            cosang = abs((O - C) @ Y) / np.linalg.norm(O - C)
            if cosang > math.cos(math.radians(min_axis_angle_deg)):
                continue
            try:
                img, pin = _traced_distorted(lambda sp, R=R, t=t: sor_silhouette(profile, K, R, t, spacing=sp).points,
                                             K, kd, spacing, "random view")
                _check_in_image(img, image_size, "random view")
            except ValueError:
                continue
            ext = img.max(0) - img.min(0)
            if ext.max() < min_size_px:
                continue
            views.append(view_truth(K, R, t, img, outline_pinhole=pin))
            infos.append(info)
            break
        else:
            raise RuntimeError(f"random_sor_scene: no valid pose for view {i} in {max_tries} tries")
    desc = (
        f"random SOR scene (seed={recorded}): {'perturbed ' if perturb else ''}{name}, "
        f"fu={K[0, 0]:.1f} fv={K[1, 1]:.1f} u0={K[0, 2]:.1f} v0={K[1, 2]:.1f}; views: "
        + "; ".join(infos) + _distortion_note(kd)
    )
    return Scene(K=K, views=tuple(views), image_size=(int(w), int(h)), seed=recorded, description=desc,
                 distortion=_as_pair(kd))


# ----------------------------------------------------------------------------------
# Noise models
# ----------------------------------------------------------------------------------


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
