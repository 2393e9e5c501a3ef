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
from typing import Sequence

import cv2
import numpy as np

from . import _photo
from . import scenes as _sc
from ._render_coverage import _coverage_in_box as _coverage_in_box
from ._render_coverage import polygon_coverage as polygon_coverage
from ._render_objects import PALETTE as PALETTE
from ._render_objects import PhotoCamera as PhotoCamera
from ._render_objects import PhotoSet as PhotoSet
from ._render_objects import RenderedObject as RenderedObject
from ._render_objects import Rendering as Rendering
from ._render_objects import TableObject as TableObject
from ._render_objects import _as_profile, _check_image_size, _object_pose
from ._render_shading import _background as _background  # _render_placed looks it up here: tests wrap it
from ._render_shading import _behind, _distorter, _object_colour_field, _photo_backdrop, _pixel_grid

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
