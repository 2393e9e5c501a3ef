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
from typing import Sequence

import numpy as np

# The parts of the scenes live in private modules; their public names (``__all__``) and
# the private helpers that other modules and the tests use are re-exported here.
from ._scene_camera import (_as_pose, _check_K, camera_centre, camera_matrix, harmonic_homology,
                            intrinsics, look_at, pose_at_pixel, view_truth)
from ._scene_distortion import _as_pair, _check_distortion, _distortion_note, _traced_distorted, distort_outline
from ._scene_noise import distance_to_polyline, gaussian_noise, outline_normals, paper_noise
from ._scene_profiles import (PROFILES, Profile, bottle, bowl, candle_holder, cylinder, perturb_profile,
                              two_spheres_profile, vase, wine_glass)
from ._scene_sor import silhouette_margin, sor_silhouette
from ._scene_spheres import TWO_SPHERES, TWO_SPHERES_VIEWS, _two_sphere_outline, sphere_image_conic, two_spheres_poses
from ._scene_types import Scene, SeedLike, Silhouette, ViewTruth, _rng
# names used elsewhere as scenes.<name>
from ._curves import _check_outline as _check_outline, closest_points_on_polyline as closest_points_on_polyline
from ._scene_camera import _project as _project
from ._scene_sor import _max_penetration as _max_penetration, _sor_paths as _sor_paths
from ._scene_spheres import _conic_distance as _conic_distance
from ._scene_trace import _points_in_polygon as _points_in_polygon, _self_intersections as _self_intersections
from ._scene_trace import _signed_area as _signed_area

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


# ----------------------------------------------------------------------------------
# Checks
# ----------------------------------------------------------------------------------


def _check_in_image(img: np.ndarray, image_size, what: str) -> None:
    w, h = image_size
    if img[:, 0].min() < 0 or img[:, 1].min() < 0 or img[:, 0].max() > w - 1 or img[:, 1].max() > h - 1:
        raise ValueError(
            f"{what}: the outline leaves the {w}x{h} image (x in [{img[:, 0].min():.1f}, "
            f"{img[:, 0].max():.1f}], y in [{img[:, 1].min():.1f}, {img[:, 1].max():.1f}]); "
            "pass allow_outside=True to accept it"
        )


# ----------------------------------------------------------------------------------
# Two intersecting spheres (Section 8 of the paper)
# ----------------------------------------------------------------------------------


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
# Scenes of a general SOR
# ----------------------------------------------------------------------------------


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
