"""Data types of the synthetic scenes and their seed convention.

:class:`ViewTruth` (the exact ground truth of one view), :class:`Scene` (views of a
surface of revolution by one camera ``K``) and :class:`Silhouette` (the exact silhouette
of a SOR in one view); pixels, cameras and outlines follow the conventions of
:mod:`sorjax.scenes`.  Every random function of the scenes takes an ``int`` seed or a
``numpy.random.Generator`` (:data:`SeedLike`, read by ``_rng``); scenes record the
integer seed (``None`` when a Generator was passed or nothing was random).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

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
# Seeds
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
