"""What :mod:`sorjax.render` takes and gives: the objects placed on the table
(:class:`TableObject`, their colours :data:`PALETTE`, their poses on the table) and the
results (:class:`Rendering`, :class:`RenderedObject`, :class:`PhotoCamera`,
:class:`PhotoSet`).

World: metres, ``Y`` up, the table is the plane ``Y = 0``; an object's pose in the
results is camera-from-object (``x_cam = R X + t``), as in :mod:`sorjax.scenes`.
Pixels as in OpenCV; colours BGR 0-255.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from . import scenes as _sc

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
