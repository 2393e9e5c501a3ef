"""Photo-like renders of surfaces of revolution on a table, with exact ground truth.

A small NumPy/OpenCV renderer for testing outline extraction and calibration from
images: a few solids of revolution (:mod:`sorjax.scenes` profiles) stand or lie on a
wooden table in front of a wall, seen by a pinhole camera ``K`` with known pose.  Each
object's silhouette is the exact outline of :func:`sorjax.scenes.sor_silhouette`; its
coverage of every pixel (the fraction of the pixel's square inside the silhouette) is
computed exactly along image rows and with ``supersample`` sub-rows per pixel, so edges
are anti-aliased as by a real sensor with a box pixel.  The returned soft masks are
these coverages; the image is the coverage-weighted mix of object and background
colours, optionally blurred (a Gaussian point-spread function) and with Gaussian sensor
noise, rounded to 8-bit BGR.

Conventions
-----------
* Pixels as in OpenCV and :mod:`sorjax.scenes`: the centre of pixel ``(row i, column
  j)`` is ``(x, y) = (j, i)``; the pixel covers ``[j - 0.5, j + 0.5] x [i - 0.5, i + 0.5]``.
* World: metres, ``Y`` up, the table is the plane ``Y = 0``.  Camera poses are
  world-to-camera ``(R, t)`` (``x_cam = R X + t``), e.g. from
  :func:`sorjax.scenes.look_at`.  An object's pose in the results is camera-from-object,
  as in :mod:`sorjax.scenes`, so its :class:`~sorjax.scenes.ViewTruth` gives the exact
  ``l_s``, ``v_x`` and homology of that view.
* Shading is only meant to look plausible (it is not used as ground truth): a
  Lambertian-looking profile across each object (its surface normal is approximated
  from the position between the outline's two sides about the image of the axis, so
  like a real shaded body the colour changes fastest right at the limb, and the side
  away from the light is dark there), a specular stripe, a slight gradient along the
  axis.  Objects are drawn far to near; a nearer object hides what it covers of the
  ones behind (their coverage is reduced accordingly and they are marked occluded).
  No shadows in the plain renders; ``style="photo"`` or a :class:`PhotoStyle` gives
  photo-like scenes (textured tables and walls, clutter, cast shadows, reflections,
  glass and metal, defocus, JPEG: :mod:`sorjax._photo`) with the same exact truth, and
  :func:`random_photo_set` whole calibration sets of them.
* Lens distortion (``distortion=(k1, k2)``, default None: a pinhole camera, the same
  images as without the argument): OpenCV's radial model
  (:mod:`sorjax.core._distortion`).  Each object's outline is its pinhole silhouette mapped
  exactly through the distortion (:func:`sorjax.scenes.distort_outline`), so the
  coverages stay exact; the table, the wall and the objects' shading are sampled at
  each pixel's undistorted position (the inverse map, Newton steps), i.e. the distorted
  image is rendered directly, not resampled.  Pixels beyond where the model is
  one-to-one (far corners with strong barrel distortion) show a smooth continuation.

Everything random takes a seed; the same arguments give the same image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Union

import cv2
import numpy as np

from . import _photo
from . import scenes as _sc

__all__ = [
    "MATERIALS",
    "PALETTE",
    "PHOTO_SIZES",
    "PhotoCamera",
    "PhotoSet",
    "PhotoStyle",
    "TableObject",
    "RenderedObject",
    "Rendering",
    "polygon_coverage",
    "render",
    "random_photo_set",
    "random_style",
    "random_table_scene",
]

PhotoStyle = _photo.PhotoStyle
MATERIALS = _photo.MATERIALS
random_style = _photo.random_style

#: Object colours (BGR, 0-255): white porcelain, cobalt, brick red, sage green,
#: mustard, teal, plum, grey stoneware.
PALETTE = (
    (225, 228, 230),
    (160, 70, 30),
    (45, 55, 175),
    (110, 160, 120),
    (40, 175, 215),
    (140, 130, 30),
    (110, 50, 120),
    (150, 150, 145),
)


@dataclass(frozen=True)
class TableObject:
    """A solid of revolution placed on the table.

    Attributes
    ----------
    profile : Profile or str
        A :class:`sorjax.scenes.Profile` or the name of one in :data:`sorjax.scenes.PROFILES`.
    position : (x, z)
        Where it stands on the table (metres, world ``X`` and ``Z``): the foot of an
        upright object, the middle of a lying one.
    lying : bool
        False: upright (axis vertical, base on the table).  True: lying on its side
        with the axis horizontal along ``(cos yaw, 0, sin yaw)``, at the height of its
        largest radius (it floats where the profile is narrower).
    yaw : float
        Radians; the direction of a lying object's axis (unused when upright).
    colour : (b, g, r) or None
        Base colour 0-255; None picks one from :data:`PALETTE` with the seed.
    material : str or None
        How it looks (:data:`MATERIALS`: "plain", "glossy", "painted", "glass", "metal";
        see :mod:`sorjax._photo`); None: "plain" in the plain renders, drawn from the
        style's ``materials`` in photo-like ones.  Never changes its coverage.
    """

    profile: Union[_sc.Profile, str]
    position: tuple[float, float] = (0.0, 0.0)
    lying: bool = False
    yaw: float = 0.0
    colour: tuple[float, float, float] | None = None
    material: str | None = None


@dataclass(frozen=True)
class RenderedObject:
    """One object of a :class:`Rendering` with its exact ground truth.

    Attributes
    ----------
    name : str
        Profile name.
    profile : Profile
    R, t : arrays (3, 3), (3,)
        Camera-from-object pose (``x_cam = R X + t``, object axis = object ``Y``).
    truth : sorjax.scenes.ViewTruth
        Exact outline (pixels), ``l_s``, ``v_x``, ``W`` and ``P`` of this view.
    coverage : (H, W) float64
        Visible fraction of each pixel covered by the object (after occlusion by nearer
        objects): the exact anti-aliased soft mask.
    box : (x0, y0, x1, y1) ints
        Bounding box of the exact outline, pixels, inclusive.
    depth : float
        Depth of the object's centre in the camera (metres).
    occluded : bool
        Whether a nearer object hides part of it (its visible outline is then not
        ``truth.outline``).
    """

    name: str
    profile: _sc.Profile
    R: np.ndarray
    t: np.ndarray
    truth: _sc.ViewTruth
    coverage: np.ndarray
    box: tuple[int, int, int, int]
    depth: float
    occluded: bool


@dataclass(frozen=True)
class Rendering:
    """A rendered image with its ground truth.

    Attributes
    ----------
    image : (H, W, 3) uint8
        BGR image (as ``cv2.imread`` gives).
    K : (3, 3) float64
        True intrinsics, pixels.
    camera : (R, t)
        World-to-camera pose.
    objects : tuple of RenderedObject
        In the order given (random scenes: left to right).
    labels : (H, W) int32
        Label image: ``k + 1`` where object ``k`` covers at least half the pixel (the
        most visible one where several do), 0 elsewhere.
    seed : int or None
    description : str
    distortion : (k1, k2) or None
        The camera's radial distortion (None: a pinhole camera).
    """

    image: np.ndarray
    K: np.ndarray
    camera: tuple[np.ndarray, np.ndarray]
    objects: tuple[RenderedObject, ...]
    labels: np.ndarray
    seed: int | None
    description: str
    distortion: tuple[float, float] | None = None

    @property
    def outlines(self) -> list[np.ndarray]:
        """Exact outlines (pixels) of the objects."""
        return [o.truth.outline for o in self.objects]

    @property
    def mask(self) -> np.ndarray:
        """Soft mask of all objects, (H, W) float64 in [0, 1] (sum of the coverages)."""
        if not self.objects:
            return np.zeros(self.labels.shape)
        return np.clip(np.sum([o.coverage for o in self.objects], axis=0), 0.0, 1.0)

    @property
    def boxes(self) -> list[tuple[int, int, int, int]]:
        """Exact bounding boxes ``(x0, y0, x1, y1)`` of the objects, pixels, inclusive."""
        return [o.box for o in self.objects]

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


# ----------------------------------------------------------------------------------
# Exact anti-aliased rasterisation
# ----------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------
# Shading
# ----------------------------------------------------------------------------------


def _pixel_grid(K, shape, k):
    """``(xs, ys)`` (H, W): the pinhole (undistorted) position of every pixel centre
    for the radial distortion ``k`` (None: the pixel centres themselves)."""
    H, W = shape
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    if k is None:
        return xs, ys
    from .core._distortion import undistort

    u = np.asarray(undistort(np.stack([xs, ys], axis=-1), K, k))
    return u[..., 0], u[..., 1]


def _background(K, Rc, tc, shape, rng, table_colour, wall_colour, grid=None):
    """Table (wood grain, perspective-correct) below the horizon, wall above; float BGR.
    ``grid``: the (pinhole) positions of the pixels, :func:`_pixel_grid`."""
    H, W = shape
    Ki = np.linalg.inv(K)
    C = -Rc.T @ tc
    xs, ys = _pixel_grid(K, shape, None) if grid is None else grid
    d = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ (Rc.T @ Ki).T  # world ray directions
    dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
    img = np.empty((H, W, 3))
    down = d[..., 1] < -1e-9
    lam = np.where(down, -C[1] / np.where(down, d[..., 1], -1.0), 0.0)
    X = C[0] + lam * d[..., 0]
    Z = C[2] + lam * d[..., 2]
    dist = np.where(down, lam * np.linalg.norm(d, axis=-1), np.inf)
    # wood grain along a random direction, faded where a pixel spans several rings
    phi = rng.uniform(0, math.pi)
    period = 0.018
    u = X * math.cos(phi) + Z * math.sin(phi)
    v = -X * math.sin(phi) + Z * math.cos(phi)
    f = math.sqrt(abs(K[0, 0] * K[1, 1]))
    foot = dist / f / np.maximum(np.abs(dn[..., 1]), 0.05)  # metres per pixel on the table
    fade = np.clip(1.5 - 3.0 * foot / period, 0.0, 1.0)
    ph = rng.uniform(0, 2 * math.pi, 3)
    grain = np.sin(2 * math.pi * (u + 0.004 * np.sin(2 * math.pi * v / 0.37 + ph[0])) / period + ph[1])
    blotch = np.sin(2 * math.pi * v / 0.23 + ph[2]) * np.sin(2 * math.pi * u / 0.41)
    tone = 1.0 + 0.06 * fade * grain + 0.05 * blotch
    light = 1.0 / (1.0 + 0.08 * np.where(down, dist, 0.0))  # a little darker far away
    tcol = np.asarray(table_colour, dtype=np.float64)
    img[:] = (tcol[None, None, :] * (tone * light)[..., None])
    # wall above the horizon: vertical gradient
    wcol = np.asarray(wall_colour, dtype=np.float64)
    up = np.clip(dn[..., 1], 0.0, 1.0)
    wall = wcol[None, None, :] * (0.85 + 0.3 * up)[..., None]
    far = ~down | (dist > 12.0)
    img[far] = wall[far]
    return img


def _object_frame(truth, box, grid=None):
    """Shading frame of an object on the pixels of ``box`` (inclusive): ``u`` (signed
    position across the body, -1 to 1 from one side of the outline to the other about
    the image of the axis), ``nz = sqrt(1 - u^2)``, ``along`` (0 to 1 along the axis
    image), ``L`` (the outline's length along the axis image, px), ``pd`` (signed
    distance from the axis image, px) and ``l`` (the axis image, ``a^2 + b^2 = 1``); with
    distortion (``grid``: the pinhole positions of the pixels) computed in the pinhole
    image, about its outline and axis."""
    x0, y0, x1, y1 = box
    l = truth.l_s
    o = truth.outline if truth.outline_pinhole is None else truth.outline_pinhole
    dirv = np.array([l[1], -l[0]])  # along the image of the axis
    sd = o @ l[:2] + l[2]  # signed distance of outline points from the axis image
    ss = o @ dirv
    if grid is None:
        xs, ys = np.meshgrid(np.arange(x0, x1 + 1, dtype=np.float64), np.arange(y0, y1 + 1, dtype=np.float64))
    else:
        xs, ys = grid[0][y0 : y1 + 1, x0 : x1 + 1], grid[1][y0 : y1 + 1, x0 : x1 + 1]
    pd = xs * l[0] + ys * l[1] + l[2]
    ps = xs * dirv[0] + ys * dirv[1]
    # half-widths of the outline on each side of the axis image, per 1-px slice along it
    s0, s1 = ss.min(), ss.max()
    nb = max(2, int(math.ceil(s1 - s0)) + 1)
    b = np.clip(((ss - s0)).astype(np.int64), 0, nb - 1)
    wr = np.full(nb, np.nan)
    wl = np.full(nb, np.nan)
    pos, neg = sd >= 0, sd < 0
    np.fmax.at(wr, b[pos], sd[pos])
    np.fmax.at(wl, b[neg], -sd[neg])
    centers = np.arange(nb) + 0.5
    for w in (wr, wl):
        okw = np.isfinite(w)
        if okw.sum() == 0:
            w[:] = 1.0
        else:
            w[:] = np.interp(centers, centers[okw], w[okw])
        np.maximum(w, 0.5, out=w)
    pb = np.clip(ps - s0, 0, nb - 1)
    half = np.where(pd >= 0, np.interp(pb, centers, wr), np.interp(pb, centers, wl))
    u = np.clip(pd / half, -1.0, 1.0)
    nz = np.sqrt(np.clip(1.0 - u * u, 0.0, 1.0))
    along = np.clip((ps - s0) / max(s1 - s0, 1.0), 0.0, 1.0)
    return {"u": u, "nz": nz, "along": along, "L": max(s1 - s0, 1.0), "pd": pd, "l": l}


def _object_colour_field(truth, base, box, light_angle, grid=None, material="plain", params=None,
                         specular=1.0, bg_sample=None):
    """Shaded colour (float BGR, 0-255) of an object on the pixels of ``box``
    (inclusive).  ``"plain"``: Lambertian-looking across the body (:func:`_object_frame`),
    a specular stripe, a slight gradient along the axis; the other materials
    (:func:`sorjax._photo.shade_material`) need their ``params`` and, for glass,
    ``bg_sample``."""
    g = _object_frame(truth, box, grid)
    return _photo.shade_material(material, params or {}, base, g, light_angle, specular, bg_sample)


def _as_profile(p) -> _sc.Profile:
    if isinstance(p, _sc.Profile):
        return p
    if isinstance(p, str):
        if p not in _sc.PROFILES:
            raise ValueError(f"unknown profile {p!r}; choose from {sorted(_sc.PROFILES)}")
        return _sc.PROFILES[p]()
    raise ValueError(f"profile must be a sorjax.scenes.Profile or a name, got {type(p).__name__}")


def _object_pose(obj: TableObject, prof: _sc.Profile):
    """Object-to-world ``(R_wo, t_wo)``."""
    x, z = (float(v) for v in obj.position)
    if not obj.lying:
        return np.eye(3), np.array([x, -prof.y0, z])
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    Xo = np.array([0.0, 1.0, 0.0])
    Yo = np.array([c, 0.0, s])
    Zo = np.cross(Xo, Yo)
    Rwo = np.column_stack([Xo, Yo, Zo])
    ymid = 0.5 * (prof.y0 + prof.y1)
    return Rwo, np.array([x, prof.r_max, z]) - Rwo @ np.array([0.0, ymid, 0.0])


def _check_image_size(image_size):
    try:
        w, h = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ValueError("image_size must be (width, height) in pixels") from None
    if w < 16 or h < 16:
        raise ValueError(f"image_size must be at least 16x16, got {w}x{h}")
    return w, h


def render(
    K,
    camera,
    objects: Sequence[TableObject],
    *,
    image_size: tuple[int, int] = (640, 480),
    seed: int = 0,
    noise: float = 2.0,
    blur: float = 0.0,
    supersample: int = 32,
    spacing: float = 0.3,
    table_colour=(70, 105, 150),
    wall_colour=(200, 205, 210),
    description: str | None = None,
    distortion: Sequence[float] | None = None,
    style=None,
) -> Rendering:
    """Render solids of revolution on a table seen by ``K [R | t]``.

    Parameters
    ----------
    K : (3, 3)
        Intrinsics (zero skew), pixels.
    camera : (R, t)
        World-to-camera pose (world ``Y`` up, table ``Y = 0``), e.g.
        ``scenes.look_at(centre, target)``.
    objects : sequence of TableObject
    image_size : (width, height)
        Pixels.
    seed : int
        Seeds the colours not given, the table's grain and the noise.
    noise : float
        Standard deviation of the Gaussian sensor noise, in 8-bit grey levels (0: none).
    blur : float
        Standard deviation (pixels) of a Gaussian point-spread function applied before
        the noise (0: none; the soft masks are not blurred).
    supersample : int
        Sub-rows per pixel for the coverage (see :func:`polygon_coverage`).
    spacing : float
        Spacing (pixels) of the exact outlines.
    table_colour, wall_colour : (b, g, r)
        Base colours, 0-255.
    distortion : (k1, k2) or None
        OpenCV radial lens distortion (module docstring); None: a pinhole camera.
    style : None, "photo" or PhotoStyle
        None (default): the plain renders (a wooden table, a plain wall at infinity, no
        shadows).  "photo" or a :class:`PhotoStyle`: a photo-like scene
        (:mod:`sorjax._photo`: textured table and wall, clutter, shadows, reflections,
        materials, defocus, shot noise, JPEG); ``table_colour`` and ``wall_colour``
        are then the style's.  The objects' coverages stay exact either way.

    Returns
    -------
    Rendering

    Raises
    ------
    ValueError
        Bad arguments, or an object whose outline cannot be built or leaves the image.
    """
    K = _sc._check_K(K)
    w, h = _check_image_size(image_size)
    Rc, tc = _sc._as_pose(camera)
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    noise, blur = float(noise), float(blur)
    if not (math.isfinite(noise) and noise >= 0 and math.isfinite(blur) and blur >= 0):
        raise ValueError("noise (grey levels) and blur (pixels) must be finite and >= 0")
    kd = _sc._check_distortion(distortion)
    style = _photo.check_style(style)
    items = []
    for k, obj in enumerate(objects):
        if not isinstance(obj, TableObject):
            raise ValueError(f"objects[{k}] must be a TableObject, got {type(obj).__name__}")
        _photo.check_material(obj.material, f"objects[{k}]")
        prof = _as_profile(obj.profile)
        Rwo, two = _object_pose(obj, prof)
        R, t = Rc @ Rwo, Rc @ two + tc
        what = f"object {k} ({prof.name})"
        pts, pin = _silhouette(prof, K, R, t, spacing, kd, what)
        _sc._check_in_image(pts, (w, h), what)
        items.append((obj, prof, R, t, pts, pin))
    return _render_placed(K, Rc, tc, items, w, h, seed, noise, blur, supersample, table_colour,
                          wall_colour, description, kd, style)


def _silhouette(prof, K, R, t, spacing, kd, what):
    """``(outline, pinhole outline or None)`` of an object: its exact silhouette,
    distorted by ``kd`` (None: none)."""
    return _sc._traced_distorted(lambda sp: _sc.sor_silhouette(prof, K, R, t, spacing=sp).points, K, kd, spacing,
                                 what)


def _render_placed(K, Rc, tc, items, w, h, seed, noise, blur, supersample, table_colour, wall_colour,
                   description, kd=None, style=None):
    rng = np.random.default_rng(int(seed))
    grid = None if kd is None else _pixel_grid(K, (h, w), kd)
    if style is None:
        img = _background(K, Rc, tc, (h, w), rng, table_colour, wall_colour, grid)
    light = rng.uniform(-0.9, 0.9)
    placed = []
    for k, (obj, prof, R, t, points, pin) in enumerate(items):
        truth = _sc.view_truth(K, R, t, points, outline_pinhole=pin)
        centre = R @ np.array([0.0, 0.5 * (prof.y0 + prof.y1), 0.0]) + t
        colour = obj.colour if obj.colour is not None else PALETTE[int(rng.integers(len(PALETTE)))]
        placed.append((k, prof, R, t, truth, float(centre[2]), colour))
    # the photo-like scene and the materials draw from streams of their own, so that the
    # plain renders stay as they were and the scene does not depend on the materials
    srng = np.random.default_rng([int(seed), 1])
    mrng = np.random.default_rng([int(seed), 2])
    looks = []  # (material, parameters, light angle in the object's shading frame)
    for (obj, *_), (k, prof, R, t, truth, depth, colour) in zip(items, placed):
        if obj.material is None and style is not None:
            mat = style.materials[int(mrng.integers(len(style.materials)))]
        else:
            mat = _photo.check_material(obj.material, f"object {k}")
        looks.append((mat, _photo.material_params(mrng, mat), light))
    layers = [("object", i, placed[i][5]) for i in range(len(placed))]
    specular = 1.0
    if style is not None:
        img, blocks, looks = _photo_backdrop(K, Rc, tc, items, placed, looks, w, h, grid, kd, style, srng)
        layers += [("block", j, float(np.mean(b.vertices @ Rc[2] + tc[2]))) for j, b in enumerate(blocks)]
        specular = style.specular
    # far to near: each object is drawn over the ones behind it
    layers.sort(key=lambda lay: -lay[2])
    covs = [None] * len(placed)
    occluded = [False] * len(placed)
    for kind, i, _ in layers:
        if kind == "object":
            k, prof, R, t, truth, depth, colour = placed[i]
            cov = _coverage_in_box(truth.outline, (h, w), supersample)
            o = truth.outline
            box = (max(0, int(math.floor(o[:, 0].min())) - 1), max(0, int(math.floor(o[:, 1].min())) - 1),
                   min(w - 1, int(math.ceil(o[:, 0].max())) + 1), min(h - 1, int(math.ceil(o[:, 1].max())) + 1))
            mat, prm, la = looks[i]
            col = _object_colour_field(truth, colour, box, la, grid, mat, prm, specular,
                                       _behind(img, box) if mat == "glass" else None)
        else:
            lay = _photo.block_layer(blocks[i], K, Rc, tc, (h, w), style,
                                     lambda poly, shp: polygon_coverage(poly, shp, min(8, supersample)),
                                     _distorter(K, kd))
            if lay is None:
                continue
            box, c, col = lay
            cov = np.zeros((h, w))
            cov[box[1] : box[3] + 1, box[0] : box[2] + 1] = c
        x0, y0, x1, y1 = box
        a = cov[y0 : y1 + 1, x0 : x1 + 1, None]
        img[y0 : y1 + 1, x0 : x1 + 1] = a * col + (1.0 - a) * img[y0 : y1 + 1, x0 : x1 + 1]
        for j in range(len(placed)):  # hide what it covers of the objects behind it
            if covs[j] is not None:
                hidden = covs[j] * cov
                if hidden.max() > 1e-9:
                    occluded[j] = True
                    covs[j] = covs[j] * (1.0 - cov)
        if kind == "object":
            covs[i] = cov
    if style is not None:
        image = _photo.finish(img, srng, style, noise, blur)
    else:
        if blur > 0:
            r = max(1, int(math.ceil(4 * blur)))
            img = cv2.GaussianBlur(img, (2 * r + 1, 2 * r + 1), blur, borderType=cv2.BORDER_REPLICATE)
        if noise > 0:
            img = img + rng.normal(0.0, noise, img.shape)
        image = np.clip(np.round(img), 0, 255).astype(np.uint8)
    rendered = []
    for i, (k, prof, R, t, truth, depth, colour) in enumerate(placed):
        o = truth.outline
        box = (int(math.floor(o[:, 0].min())), int(math.floor(o[:, 1].min())),
               int(math.ceil(o[:, 0].max())), int(math.ceil(o[:, 1].max())))
        rendered.append(RenderedObject(name=prof.name, profile=prof, R=R, t=t, truth=truth,
                                       coverage=covs[i], box=box, depth=depth, occluded=occluded[i]))
    labels = np.zeros((h, w), np.int32)
    if rendered:
        stack = np.stack([r.coverage for r in rendered])
        best = np.argmax(stack, axis=0)
        labels = np.where(stack.sum(0) >= 0.5, best + 1, 0).astype(np.int32)
    if description is None:
        description = (
            f"{len(rendered)} object(s) ({', '.join(r.name for r in rendered)}) on a table, "
            f"{w}x{h} px, K = {np.round(K, 2).tolist()}, noise {noise:g}, blur {blur:g}, seed {seed}"
        ) + _sc._distortion_note(kd)
    if style is not None:
        description += "; " + _photo.describe(style) + "; materials " + ", ".join(lk[0] for lk in looks)
    return Rendering(image=image, K=K, camera=(Rc, tc), objects=tuple(rendered), labels=labels,
                     seed=int(seed), description=description, distortion=_sc._as_pair(kd))


def _distorter(K, kd):
    """Pinhole pixels -> distorted pixels (None without distortion)."""
    if kd is None:
        return None
    from .core._distortion import distort

    return lambda uv: np.asarray(distort(np.asarray(uv, np.float64), K, np.asarray(kd, np.float64)))


def _behind(img, box):
    """``sample(dx, dy)``: the image (float BGR) on the pixels of ``box``, displaced by
    ``(dx, dy)`` px (bilinear; for what a glass object shows of the scene behind)."""
    x0, y0, x1, y1 = box
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1, dtype=np.float64), np.arange(y0, y1 + 1, dtype=np.float64))
    src = img.astype(np.float32)

    def sample(dx, dy):
        return cv2.remap(src, (xs + dx).astype(np.float32), (ys + dy).astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REFLECT).astype(np.float64)

    return sample


def _photo_backdrop(K, Rc, tc, items, placed, looks, w, h, grid, kd, style, srng):
    """The photo-like background (:mod:`sorjax._photo`) with the objects' shadows and
    reflections, the clutter blocks, and the objects' looks with the light angle of the
    style's light in each object's shading frame."""
    solids = []
    L = Rc @ _photo.light_direction(style)  # camera frame
    out = []
    for (obj, prof, R, t, pts, pin), (k, _, _, _, truth, depth, colour), (mat, prm, _) in zip(items, placed, looks):
        Rwo, two = Rc.T @ R, Rc.T @ (t - tc)
        rings = _photo.solid_rings(prof, Rwo, two)
        flat = rings.reshape(-1, 3)
        foot = flat[:, [0, 2]].mean(0)
        zc = flat @ Rc[2] + tc[2]
        o = truth.outline
        lo, hi = o.min(0), o.max(0)
        solids.append({"rings": rings, "foot": (float(foot[0]), float(foot[1])),
                       "radius": float(np.max(np.hypot(flat[:, 0] - foot[0], flat[:, 2] - foot[1]))),
                       "depth": (float(zc.min()), float(zc.max())), "box": (lo[0], lo[1], hi[0], hi[1]),
                       "size": float(np.ptp(flat, axis=0).max()), "px": float(max(hi - lo)),
                       "colour": colour, "material": mat})
        # u > 0 on the side of the axis image that l_s points to (to the right when l_x > 0)
        la = math.atan2(L[0], -L[2]) * (1.0 if truth.l_s[0] >= 0 else -1.0)
        out.append((mat, prm, float(np.clip(la, -1.4, 1.4))))
    wall = _photo.wall_plane(style, Rc, tc, np.concatenate([s["rings"].reshape(-1, 3) for s in solids])
                             if solids else np.zeros((0, 3)))
    ph = srng.uniform(0.0, 1.0, 4)
    g = _pixel_grid(K, (h, w), None) if grid is None else grid
    img, table = _photo.backdrop(style, K, Rc, tc, (h, w), g, wall, ph)
    blocks = _photo.place_clutter(srng, style, K, Rc, tc, (h, w), solids, wall)
    _photo.shadows_and_reflections(img, table, style, K, Rc, tc, solids, blocks, _distorter(K, kd))
    return img, blocks, out


def _rough_extent(prof, K, R, t):
    """Image extent of surface samples of the solid (slightly inside the silhouette's)."""
    y = np.linspace(prof.y0, prof.y1, 25)
    r = np.asarray(prof.r(y), dtype=np.float64)
    ph = np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)
    X = np.stack([np.outer(r, np.cos(ph)), np.repeat(y[:, None], len(ph), 1), np.outer(r, np.sin(ph))], -1).reshape(-1, 3)
    xc = X @ R.T + t
    if np.any(xc[:, 2] <= 1e-6):
        return None, None
    uv = xc @ np.asarray(K).T
    uv = uv[:, :2] / uv[:, 2:3]
    return uv.min(0), uv.max(0)


def _fits(lo, hi, w, h, margin, size_px, boxes, gap):
    if lo[0] < margin or lo[1] < margin or hi[0] > w - 1 - margin or hi[1] > h - 1 - margin:
        return False
    if not (0.8 * size_px[0] <= (hi - lo).max() <= 1.15 * size_px[1]):
        return False
    return not any(
        lo[0] < b[1][0] + gap and b[0][0] < hi[0] + gap and lo[1] < b[1][1] + gap and b[0][1] < hi[1] + gap
        for b in boxes
    )


def random_table_scene(
    seed: int,
    K=None,
    *,
    n_objects: int = 3,
    image_size: tuple[int, int] = (640, 480),
    shapes: Sequence[str] | None = None,
    lying: float = 0.25,
    elevation_deg: tuple[float, float] = (15.0, 55.0),
    size_px: tuple[float, float] = (150.0, 280.0),
    margin_px: float = 12.0,
    gap_px: float = 12.0,
    noise: float = 2.0,
    blur: float = 0.0,
    supersample: int = 32,
    max_tries: int = 100,
    distortion: Sequence[float] | None = None,
    style=None,
) -> Rendering:
    """A random table scene, deterministic given ``seed``.

    * Camera (unless ``K`` is given): ``f`` uniform in [500, 1500] px, unit aspect ratio,
      principal point within 10 % of the image centre.
    * View: elevation above the table uniform in ``elevation_deg``, any azimuth, roll
      within +-8 degrees, looking at the table's origin.
    * ``n_objects`` objects (perturbed named profiles, ``shapes`` or all but the
      cylinder), left to right in equal slots of the image width, each scaled to
      ``size_px`` (largest extent in pixels, uniform in the range; kept when the
      rendered extent is within 0.8 x the lower and 1.15 x the upper bound); each
      lies on its side with probability ``lying`` (any yaw); all wholly inside the image
      at least ``margin_px`` from its border, their bounding boxes at least ``gap_px``
      apart (no occlusion).
    * ``distortion``: ``(k1, k2)`` radial lens distortion (module docstring; None:
      none); the layout checks apply to the distorted outlines.
    * ``style``: None (plain), "photo" or a :class:`PhotoStyle` (see :func:`render`).

    Raises RuntimeError when no such layout is found in ``max_tries`` draws.
    """
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    if not (isinstance(n_objects, (int, np.integer)) and 1 <= n_objects <= 8):
        raise ValueError(f"n_objects must be an int from 1 to 8, got {n_objects!r}")
    w, h = _check_image_size(image_size)
    kd = _sc._check_distortion(distortion)
    style = _photo.check_style(style)
    rng = np.random.default_rng(int(seed))
    names = [n for n in _sc.PROFILES if n != "cylinder"] if shapes is None else list(shapes)
    for nm in names:
        if nm not in _sc.PROFILES:
            raise ValueError(f"unknown shape {nm!r}; choose from {sorted(_sc.PROFILES)}")
    if K is None:
        f = rng.uniform(500.0, 1500.0)
        pp = (0.5 * w + rng.uniform(-0.1, 0.1) * w, 0.5 * h + rng.uniform(-0.1, 0.1) * h)
        K = _sc.intrinsics(f, principal_point=pp)
    K = _sc._check_K(K)
    fm = math.sqrt(K[0, 0] * K[1, 1])
    Ki = np.linalg.inv(K)
    for _ in range(max_tries):
        el = math.radians(rng.uniform(*elevation_deg))
        az = rng.uniform(0.0, 2.0 * math.pi)
        roll = math.radians(rng.uniform(-8.0, 8.0))
        typ = rng.uniform(*size_px)
        D = fm * 0.25 / typ  # a 25 cm object at the target is typ px
        Cw = D * np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
        Rc, tc = _sc.look_at(Cw, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), roll)
        slots = rng.permutation(n_objects)
        items, boxes = [], []
        for k in range(n_objects):
            item = None
            for _ in range(12):
                name = names[int(rng.integers(len(names)))]
                prof = _sc.perturb_profile(_sc.PROFILES[name](), rng)
                ext = max(prof.y1 - prof.y0, 2 * prof.r_max)
                size = rng.uniform(*size_px)
                prof = prof.scaled(height=size * D / (fm * ext), width=size * D / (fm * ext))
                lie = bool(rng.uniform() < lying)
                hc = prof.r_max if lie else 0.5 * (prof.y1 - prof.y0)
                sw = (w - 2 * margin_px) / n_objects
                px = margin_px + sw * (slots[k] + rng.uniform(0.3, 0.7))
                py = rng.uniform(0.35, 0.65) * h
                ray = Rc.T @ Ki @ np.array([px, py, 1.0])
                if ray[1] >= -1e-6:
                    continue
                lam = (hc - Cw[1]) / ray[1]
                P = Cw + lam * ray
                if lam <= 0 or np.linalg.norm(P - Cw) > 3 * D:
                    continue
                obj = TableObject(prof, (P[0], P[2]), lying=lie, yaw=float(rng.uniform(0, math.pi)))
                Rwo, two = _object_pose(obj, prof)
                R, t = Rc @ Rwo, Rc @ two + tc
                # cheap check on projected surface samples before the exact silhouette
                lo, hi = _rough_extent(prof, K, R, t)
                if lo is None or not _fits(lo, hi, w, h, margin_px - 2, size_px, boxes, gap_px - 2):
                    continue
                try:
                    pts, pin = _silhouette(prof, K, R, t, 0.3, kd, "random table object")
                except ValueError:
                    continue
                lo, hi = pts.min(0), pts.max(0)
                if not _fits(lo, hi, w, h, margin_px, size_px, boxes, gap_px):
                    continue
                item = (obj, prof, R, t, pts, pin)
                boxes.append((lo, hi))
                break
            if item is None:
                break
            items.append(item)
        if len(items) < n_objects:
            continue
        order = np.argsort([b[0][0] for b in boxes])
        items = [items[i] for i in order]
        desc = (
            f"random table scene (seed={int(seed)}): {n_objects} object(s), elevation "
            f"{math.degrees(el):.0f} deg, camera {D:.2f} m from the target, fu={K[0, 0]:.1f} "
            f"fv={K[1, 1]:.1f} u0={K[0, 2]:.1f} v0={K[1, 2]:.1f}"
        )
        return _render_placed(K, Rc, tc, items, w, h, int(rng.integers(2**31)), float(noise), float(blur),
                              supersample, (70, 105, 150), (200, 205, 210), desc, kd, style)
    raise RuntimeError(f"random_table_scene(seed={seed}): no valid layout in {max_tries} tries")


@dataclass(frozen=True)
class PhotoCamera:
    """One camera of a :class:`PhotoSet`: its true ``K`` (pixels), ``image_size``
    ``(width, height)``, its renders and their seeds (``random_table_scene(seed, K,
    ..., style=random_style(np.random.default_rng([seed, 3])))`` gives each again)."""

    K: np.ndarray
    image_size: tuple[int, int]
    renders: tuple[Rendering, ...]
    seeds: tuple[int, ...] = ()


@dataclass(frozen=True)
class PhotoSet:
    """A set of photo-like renders by several cameras (:func:`random_photo_set`)."""

    seed: int
    cameras: tuple[PhotoCamera, ...]
    description: str


#: Image sizes ``(width, height)`` the cameras of :func:`random_photo_set` choose from.
PHOTO_SIZES = ((640, 480), (800, 600), (1024, 768), (1280, 960))


def random_photo_set(
    seed: int,
    *,
    cameras: int = 5,
    images: int = 4,
    objects: tuple[int, int] = (2, 3),
    f_range: tuple[float, float] = (450.0, 1600.0),
    fov_range_deg: tuple[float, float] = (40.0, 75.0),
    noise: float = 1.0,
    supersample: int = 32,
) -> PhotoSet:
    """A realistic calibration set, deterministic given ``seed``: ``cameras`` cameras,
    each with ``images`` photo-like renders (:func:`random_table_scene` with a
    :func:`random_style` per image) of 2 to 3 (``objects``) solids of revolution.

    * Focal lengths: one per camera, log-uniform within equal parts of ``f_range`` (so
      they span it), pixels.  Image size: of :data:`PHOTO_SIZES`, the one whose
      horizontal field of view is nearest a random value in ``fov_range_deg`` (so a
      long focal length gets a large image, as in phones and cameras).  Aspect ratio 1
      for half the cameras, else uniform in [0.97, 1.03]; principal point within 5 % of
      the image centre.
    * Objects: placed as by :func:`random_table_scene` (left to right in equal slots,
      off-centre, elevation 15 to 55 degrees), sized 150 to 280 px per 640 px of image
      width; a layout that fails is retried with the next seed.

    Every render's seed is recorded in its ``description`` and ``seed``.
    """
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    if not (isinstance(cameras, (int, np.integer)) and cameras >= 1):
        raise ValueError(f"cameras must be an int >= 1, got {cameras!r}")
    if not (isinstance(images, (int, np.integer)) and images >= 1):
        raise ValueError(f"images must be an int >= 1, got {images!r}")
    lo, hi = (int(v) for v in objects)
    if not 1 <= lo <= hi <= 8:
        raise ValueError(f"objects must be (min, max) with 1 <= min <= max <= 8, got {objects!r}")
    f0, f1 = (float(v) for v in f_range)
    if not 0 < f0 <= f1:
        raise ValueError(f"f_range must be (f_min, f_max) pixels with 0 < f_min <= f_max, got {f_range!r}")
    rng = np.random.default_rng([int(seed), 17])
    edges = np.exp(np.linspace(math.log(f0), math.log(f1), cameras + 1))
    cams = []
    for c in range(cameras):
        f = float(np.exp(rng.uniform(math.log(edges[c]), math.log(edges[c + 1]))))
        fov = math.radians(rng.uniform(*fov_range_deg))
        w, h = min(PHOTO_SIZES, key=lambda s: abs(2 * math.atan(s[0] / (2 * f)) - fov))
        a = 1.0 if rng.uniform() < 0.5 else float(rng.uniform(0.97, 1.03))
        pp = (0.5 * w + rng.uniform(-0.05, 0.05) * w, 0.5 * h + rng.uniform(-0.05, 0.05) * h)
        K = _sc.intrinsics(f, aspect_ratio=a, principal_point=pp)
        renders, seeds = [], []
        s = int(rng.integers(2**31))
        while len(renders) < images:
            n = int(rng.integers(lo, hi + 1))
            style = _photo.random_style(np.random.default_rng([s, 3]))
            try:
                renders.append(random_table_scene(s, K, n_objects=n, image_size=(w, h), style=style, noise=noise,
                                                  size_px=(150.0 * w / 640, 280.0 * w / 640), supersample=supersample))
                seeds.append(s)
            except RuntimeError:
                pass
            s += 1
        cams.append(PhotoCamera(K=K, image_size=(w, h), renders=tuple(renders), seeds=tuple(seeds)))
    desc = (f"random photo set (seed={int(seed)}): {cameras} camera(s) x {images} image(s), f "
            + ", ".join(f"{c.K[1, 1]:.0f}" for c in cams) + " px")
    return PhotoSet(seed=int(seed), cameras=tuple(cams), description=desc)
