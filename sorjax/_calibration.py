"""From outlines to intrinsics: the friendly entry point :func:`calibrate` and its
:class:`Calibration`.

This is the boundary: plain-Python validation before anything is traced, then the
functional core (:mod:`sorjax.core`: per-view homologies -> Method I / IIa / IIb ->
the bundle -> verdicts, one compiled program of arrays), then the warnings and
messages, written here from the core's arrays.  The views are padded to a few fixed
counts (masked in the core), so that calibrations of 2, 3 or 4 views share one
compiled program.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._checks import check_sizes
from ._compile import one_off_jit
from ._homology import DEFAULT_SAMPLES, Homology, fit_homology
from ._outline import BINARY_MASK_PX, DEFAULT_POINTS, PIXEL_TRACE_NOTE, _as_outlines, implied_outline_error, jagged_note
from .core._assess import (ASYMMETRIC, COLLAPSED_FOCAL, CONIC, DUPLICATE, MASKED, PP_OUTSIDE, TRIMMED, USED, WIDE_FOV,
                           axes_intersection, inside_image, outline_radius, view_verdicts)
from .core._checks import (CULPRIT_ASPECT, CULPRIT_FIXED, CULPRIT_LENS, CULPRIT_VIEWS, MODEL_WIDENED,
                           ModelChecks)
from .core._calibrate import _intrinsics, calibrate_homologies
from .core._options import Options
from .core._result import RESULTS
from .core._viewfit import ViewHomologies

METHODS = ("bundle", "I", "IIa", "IIb")


class CalibrationError(RuntimeError):
    """Raised by ``calibrate(..., throw=True)`` when the calibration did not succeed."""


class Calibration(eqx.Module):
    """Estimated intrinsics of a zero-skew pinhole camera.

    Attributes:
        K: (3, 3) intrinsics in pixels (NaN entries when not successful).
        omega: (3, 3) image of the absolute conic ``K^-T K^-1`` (pixels), as estimated.
        homologies: the per-view :class:`Homology` fits (pixels).
        result: a :class:`RESULTS` code; ``success`` is ``result == successful``.
        covariance: (4, 4) covariance of ``(fu, fv, u0, v0)`` in px^2 (bundle only;
            NaN for the linear methods, which give no uncertainty).
        cost: eq. 20's cost summed over the views at the estimate, px^2 (bundle only).
        view_rms: (V,) RMS symmetry residual of each view, px: under the joint model
            for the bundle, of the free per-view fit for the linear methods.
        steps: optimiser steps (bundle; 0 for the linear methods).
        v_x: (V, 3) the vertices used: jointly estimated for the bundle, the per-view
            fits' for the linear methods (pixels, unit norm).
        l_s: (V, 3) the axes: ``omega v_x`` for the bundle, the per-view fits' for the
            linear methods (pixels, ``a^2 + b^2 = 1``).
        method: "I", "IIa", "IIb" or "bundle".
        aspect_ratio: the known ``fu / fv`` imposed, or None when it was estimated
            (always 1 for "I"/"IIb" without one).
        used: indices of the views used (conic outlines and outlines that are not
            symmetric are dropped with a warning); ``view_rms``, ``v_x`` and ``l_s``
            refer to these views, ``homologies`` to all.
        details: what is specific to this result (empty on plain success): which
            views were dropped, which intrinsics are or are not determined, what to add.
        dropped: ``(view index, reason)`` for each view left out.
        notes: every warning :func:`calibrate` issued for this calibration, in order.
        perspective_px: the evidence for perspective in the outlines (bundle only): how
            much worse, in px RMS per sample, the best camera with no perspective
            (orthographic, every v_x at infinity) fits them than the bundle's estimate
            (NaN for the linear methods, which give no uncertainty either).  Only
            perspective fixes the focal length; see ``outline_error`` in :func:`calibrate`.
        perspective_z: the same evidence in units of the symmetry noise,
            ``sqrt(delta cost / s^2)`` (a z-score against "no perspective").
        outline_error: the outline error allowed for (px): the declared one, or more
            when the coordinates show it (whole-pixel or mask-staircase outlines), or
            the one measured from the outlines (``calibrate(outline_error="measured")``;
            a note says which).
        distortion_model: "none", "k1" or "k1k2" (``calibrate(distortion=...)``).
        distortion: OpenCV's radial coefficients ``(k1,)`` or ``(k1, k2)`` (camera-
            normalised coordinates, as ``cv2.undistort`` takes them); NaN when the
            outlines did not determine them; None for a pinhole.  ``distortion_std``:
            their standard deviations.
        checks: the model checks' statistics (:class:`sorjax.core.ModelChecks`): a
            known aspect ratio against the free fit, the views' consistency with one
            camera, duplicated views.  ``RESULTS.inconsistent`` when the outlines
            contradict the model; the standard deviations widened (and a warning) when
            the model is only not confirmed.
        fixed_principal_point, fixed_focal_length: the intrinsics held fixed
            (``calibrate(principal_point=..., focal_length=...)``; px), None when
            estimated.  Their standard deviations are 0.
    """

    K: Float[Array, "3 3"]
    omega: Float[Array, "3 3"]
    homologies: tuple[Homology, ...]
    result: RESULTS
    covariance: Float[Array, "4 4"]
    cost: Float[Array, ""]
    view_rms: Float[Array, " V"]
    steps: Int[Array, ""]
    v_x: Float[Array, "V 3"]
    l_s: Float[Array, "V 3"]
    method: str = eqx.field(static=True)
    aspect_ratio: float | None = eqx.field(static=True, default=None)
    used: tuple[int, ...] = eqx.field(static=True, default=())
    details: str = eqx.field(static=True, default="")
    dropped: tuple[tuple[int, str], ...] = eqx.field(static=True, default=())
    notes: tuple[str, ...] = eqx.field(static=True, default=())
    perspective_px: float = eqx.field(static=True, default=math.nan)
    perspective_z: float = eqx.field(static=True, default=math.nan)
    outline_error: float = eqx.field(static=True, default=math.nan)
    checks: ModelChecks | None = None
    distortion_model: str = eqx.field(static=True, default="none")
    distortion: Float[Array, " n"] | None = None
    distortion_std: Float[Array, " n"] | None = None
    fixed_principal_point: tuple[float, float] | None = eqx.field(static=True, default=None)
    fixed_focal_length: float | None = eqx.field(static=True, default=None)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``(fu, fv, u0, v0)`` in px (NaN when unknown)."""
        return np.sqrt(np.diag(np.asarray(self.covariance)))

    @property
    def fu(self) -> float:
        return float(np.asarray(self.K)[0, 0])

    @property
    def fv(self) -> float:
        return float(np.asarray(self.K)[1, 1])

    @property
    def u0(self) -> float:
        return float(np.asarray(self.K)[0, 2])

    @property
    def v0(self) -> float:
        return float(np.asarray(self.K)[1, 2])

    @property
    def principal_point(self) -> np.ndarray:
        """``(u0, v0)`` in pixels (also when only the principal point is determined)."""
        return np.array([self.u0, self.v0])

    @property
    def success(self) -> bool:
        return bool(self.result == RESULTS.successful)

    @property
    def message(self) -> str:
        text = RESULTS[self.result]
        return f"{text} {self.details}".strip() if self.details else text

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.K, dtype=dtype)


def _is_number(x) -> bool:
    return not isinstance(x, (bool, np.bool_)) and isinstance(x, (int, float, np.integer, np.floating))


def _check_fixed(principal_point, focal_length, image_size, method: str):
    """``(pp, f)``: the fixed principal point ``(cx, cy)`` px (or None) and focal
    length px (or None), validated (``image_size`` already checked: ``(w, h)`` or
    None)."""
    pp = None
    if principal_point is not None:
        if isinstance(principal_point, str):
            if principal_point not in ("centre", "center"):
                raise ValueError(f"principal_point must be (cx, cy) in pixels or 'centre' (the command line's "
                                 f"--principal-point CX CY or --centre-principal-point); got {principal_point!r}.")
            if image_size is None:
                raise ValueError("principal_point='centre' needs image_size=(width, height) (the command line "
                                 "reads it from the images; with outline files give --principal-point CX CY).")
            pp = ((image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0)
        else:
            try:
                xs = tuple(principal_point)
            except TypeError:
                xs = ()
            if len(xs) != 2 or not all(_is_number(x) and math.isfinite(x) for x in xs):
                raise ValueError(f"principal_point must be (cx, cy), two finite numbers of pixels, or 'centre' (the "
                                 f"command line's --principal-point CX CY or --centre-principal-point); got "
                                 f"{principal_point!r}.")
            pp = (float(xs[0]), float(xs[1]))
            if max(abs(pp[0]), abs(pp[1])) > 1e7:
                raise ValueError(f"principal_point {pp!r} is beyond 1e7 px (outlines are limited to that).")
    f = None
    if focal_length is not None:
        if not _is_number(focal_length) or not (math.isfinite(focal_length) and 0 < focal_length <= 1e9):
            raise ValueError(f"focal_length must be a positive finite number of pixels (fv; the command line's "
                             f"--focal F); got {focal_length!r}.")
        f = float(focal_length)
    if (pp is not None or f is not None) and method != "bundle":
        which = "principal_point" if pp is not None else "focal_length"
        raise ValueError(f"{which} is held fixed by the bundle only; use method='bundle' (the default) instead of "
                         f"{method!r} (the command line's --method).")
    return pp, f


def _check_method(method: str, aspect_ratio):
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}; got {method!r}.")
    if aspect_ratio is not None:
        if isinstance(aspect_ratio, (bool, np.bool_)) or not isinstance(
            aspect_ratio, (int, float, np.floating, np.integer)
        ) or not (math.isfinite(aspect_ratio) and aspect_ratio > 0):
            raise ValueError(f"aspect_ratio must be a positive finite number (fu / fv); got {aspect_ratio!r}.")
        if method == "IIa":
            raise ValueError(
                "method 'IIa' estimates the aspect ratio itself; to impose a known aspect "
                "ratio use method='IIb' (or 'I') with aspect_ratio=..."
            )


# ------------------------------------------------------------ degenerate geometry

# A view is dropped as "not a surface of revolution" when its per-view symmetry
# residual (eq. 20, RMS) exceeds ASYMMETRY_PX *and* ASYMMETRY_REL of the outline's
# RMS radius.  Measured (experiments/degenerate.py, 24 views of random SORs): exact
# outlines fit to < 4e-5 px; with the paper's noise of sigma = 2 px the residual stays
# below 0.7 px, with i.i.d. Gaussian noise of 2 px below 1.4 px (1.8 px in a wider
# probe); smooth random blobs gave 2.6 px (median; 75 % above 2 px) for a radius
# modulation of 20 %, 4.8 px (all above 2 px) for 35 %.  So only clearly asymmetric
# outlines are caught: a mild asymmetry is indistinguishable from noise by this
# residual.  Between WARN_ASYMMETRY_PX and the
# threshold the view is kept with a warning.
_O = Options()  # the defaults; the values live in sorjax.core.Options
ASYMMETRY_PX = _O.asymmetry_px
ASYMMETRY_REL = _O.asymmetry_rel
WARN_ASYMMETRY_PX = _O.warn_asymmetry_px
# The robust per-view fit trims samples with no mirror image (a handle, a shadow); a
# view that needs more than MAX_TRIMMED of its samples trimmed is not a surface of
# revolution, and from NOTE_TRIMMED on the trimming is reported.  Measured: a smooth
# 8 px handle over 12 % of a vase's outline trims 14 % (the handle and its mirror
# image); GrabCut outlines of ycb-video cans that leaked into the background trimmed
# 15-22 % and, kept, gave a confident wrong K: hence 20 %, and the symmetry test on the
# untrimmed residual.
MAX_TRIMMED = _O.max_trimmed
NOTE_TRIMMED = _O.note_trimmed
# An intrinsic is "not determined" when its standard deviation (the covariance at the
# estimate, scaled by the residual -- at least RESIDUAL_FLOOR_PX when every v_x is at
# infinity) is infinite or above UNDETERMINED times the focal length (for the
# principal point: times the outlines' RMS radius when the focal length itself is not
# determined): a 3-sigma interval reaching zero.  A focal length from one view: above
# FOCAL_UNDETERMINED times itself (the 3-sigma interval of 1 / f^2 reaching zero).
UNDETERMINED = _O.undetermined
FOCAL_UNDETERMINED = _O.focal_undetermined
# A focal length below MIN_FOCAL_FRACTION of the extent of the outlines (their
# bounding box's larger side, px) would put them across more than 90 degrees of view,
# where a lens without distortion (sorjax's model) is implausible: a collapsed
# estimate, never "determined" -- nor is the principal point estimated with it.  Seen
# on real photographs with weak perspective and imperfect outlines: f fell to 1..25 px,
# and to 168 px (nocs-real275, true 590) and 177 px (ycb-video, true 1067) with a std
# of 13-15 px and the principal point 7 to 20 std off.
MIN_FOCAL_FRACTION = _O.min_focal_fraction
# With the image size known (``calibrate(image_size=...)``), an estimate is also
# implausible when it gives the image a field of view above MAX_FOV_DEG across (wider
# lenses are fisheyes, far from a pinhole without distortion) or puts the principal
# point outside the image.  (ycb-video, true f 1067 px: f 177 +- 13 px, a 122 deg view
# of its 640 px width -- caught only by this bound, narrowly.)
MAX_FOV_DEG = _O.max_fov_deg
# Weak geometry: warn when the relative standard deviation of a focal length exceeds
# WEAK_REL_STD, the covariance scaled by the residual but at least RESIDUAL_FLOOR_PX
# (about the accuracy of good sub-pixel outlines), so that a configuration that only
# noise-free outlines could calibrate is flagged too.
WEAK_REL_STD = _O.weak_rel_std
RESIDUAL_FLOOR_PX = _O.residual_floor_px
# Perspective evidence (bundle).  Only perspective fixes the focal length, and under
# weak perspective an outline shows very little of it (a 5 % focal error changes the
# symmetry of typical outlines by about 0.25 px).  Systematic errors of the outlines
# (segmentation bias, lens distortion, an object that is not quite a surface of
# revolution) hide from the symmetry residual but can fake or cancel that much, and the
# bundle's covariance, a linearisation at its own estimate, can then be confident far
# from the truth.  So the focal length counts as determined only when the best camera
# with no perspective (:func:`sorjax.core._bundle.orthographic_cost`) fits the outlines worse
# by a cost delta with sqrt(delta / s^2) >= PERSPECTIVE_Z (the noise cannot explain it)
# and sqrt(delta / n) >= PERSPECTIVE_FACTOR * outline_error px (nor can a systematic
# error of the outlines of `outline_error` px RMS: a fully aligned one changes the cost
# by n outline_error^2).  Measured: the real photographs of nvlabs-6dof-graspnet
# (experiments/realdata.py; approximate masks) show 0.20 to 0.22 px of perspective and
# gave f 271 +- 16 px for a true 616 without this gate; the two-sphere scene shows 0.7
# to 0.8 px at f = 700 and 0.14 to 0.28 px at f = 1400 (1 to 2 px of noise); rendered
# objects near the image centre at f = 1250 to 1500 px 0.23 to 0.24 px.
OUTLINE_ERROR_PX = _O.outline_error_px
PERSPECTIVE_Z = _O.perspective_z
PERSPECTIVE_FACTOR = _O.perspective_factor
# Advice thresholds (which extra view would help).
PARALLEL_AXES_DEG = 10.0
NEAR_AXIS_DEG = 10.0
SMALL_OUTLINE_RAD = 0.15
_NAMES = ("fu", "fv", "u0", "v0")


def _axis_spread_deg(ls: np.ndarray) -> float:
    """Largest angle (degrees, 0..90) between the directions of the imaged axes."""
    t = np.arctan2(ls[:, 1], ls[:, 0])
    d = np.abs(t[:, None] - t[None, :]) % np.pi
    return float(np.degrees(np.max(np.minimum(d, np.pi - d))))


def _view_angles_deg(K: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Per view, the angle (degrees) between the optical axis and the plane through the
    revolution axis and the camera centre (theta of the paper's eq. 37): 0 when v_x
    is at infinity."""
    n = np.linalg.solve(K, vx.T).T
    return np.degrees(np.arcsin(np.clip(np.abs(n[:, 2]) / np.linalg.norm(n, axis=1), 0.0, 1.0)))


def _advice(K, vx, ls, outs, free_aspect: bool, aspect_weak: bool, used=None) -> list[str]:
    """What kind of extra view would help, from the geometry of the views (``K`` the
    raw estimate, used only for the angles; it may be poor when it is not determined)."""
    tips = []
    vx, ls = np.asarray(vx), np.asarray(ls)
    for i in range(len(vx)):
        for j in range(i + 1, len(vx)):
            if min(np.linalg.norm(vx[i] - vx[j]), np.linalg.norm(vx[i] + vx[j])) < 1e-6 and min(
                np.linalg.norm(ls[i] - ls[j]), np.linalg.norm(ls[i] + ls[j])
            ) < 1e-6 * (1 + abs(ls[i, 2])):
                vi, vj = (i, j) if used is None else (used[i], used[j])
                tips.append(
                    f"views {vi} and {vj} have the same axis and vertex, so they give the same "
                    "constraints (the same view twice, or two centred upright views?): move or tilt "
                    "the object between views"
                )
    spread = _axis_spread_deg(ls)
    if np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0:
        theta = _view_angles_deg(np.asarray(K), np.asarray(vx))
        if np.max(theta) < NEAR_AXIS_DEG:
            tips.append(
                f"in every view the camera looks almost straight at the object's axis (the plane "
                f"through the axis and the camera makes at most {np.max(theta):.1f} deg with the "
                "optical axis, so v_x is far away and l_s passes near the principal point): add a "
                "view with the object near an edge or corner of the image"
            )
        f = float(np.sqrt(K[0, 0] * K[1, 1]))
        size = max(float(np.hypot(*np.ptp(np.asarray(o.points), axis=0))) for o in outs) / f
        if size < SMALL_OUTLINE_RAD:
            tips.append(
                f"every outline is small for this focal length (at most {np.degrees(size):.1f} deg "
                "across: weak perspective): add a view with the object closer to the camera"
            )
    if spread < PARALLEL_AXES_DEG:
        tips.append(
            f"all imaged axes are within {spread:.1f} deg of each other: add a view with the object "
            "tilted (or the camera rolled) so that its axis appears at another angle in the image"
        )
    if not tips:
        tips.append(
            "add a view with the object off the image centre and seen from above or below "
            "(stronger perspective), or at a different place in the image"
        )
    if free_aspect and aspect_weak:
        tips.append("if the pixels are square, pass aspect_ratio=1.0 (one unknown less)")
    return tips


def _fmt_std(x, sd):
    """``x +- sd`` in px: one decimal, or 3 significant digits beyond 1e6 px (a focal
    length that ran off towards the no-perspective limit)."""
    xs = f"{x:.1f}" if abs(x) < 1e6 else f"{x:.3g}"
    return f"{xs} +- {sd:.2g}" if np.isfinite(sd) else f"{xs} +- inf"


def _implausible_text(code: int, est, outs, image_size=None) -> str:
    """The text of :func:`sorjax.core._assess.implausible`'s ``code`` for the estimate
    ``est = (fu, fv, u0, v0)`` (px) and the outlines ``outs`` (empty when plausible)."""
    if code == USED:
        return ""
    pts = np.concatenate([np.asarray(getattr(o, "points", o)).reshape(-1, 2) for o in outs])
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    f = float(np.min(np.abs(est[:2])))
    if code == COLLAPSED_FOCAL:
        deg = 2.0 * math.degrees(math.atan(extent / (2.0 * max(f, 1e-300))))
        return (
            f"the estimate (f = {f:.0f} px) would put outlines {extent:.0f} px apart across {deg:.0f} deg of "
            "view, which a lens without distortion does not do: the outlines' errors, not their "
            "perspective, made it"
        )
    w, h = image_size if image_size is not None else (math.nan, math.nan)
    if code == WIDE_FOV:
        fov = [2.0 * math.degrees(math.atan(n / (2.0 * max(abs(x), 1e-300)))) for n, x in ((w, est[0]), (h, est[1]))]
        return (
            f"the estimate (fu = {est[0]:.0f}, fv = {est[1]:.0f} px) gives the {w}x{h} image a field of view of "
            f"{fov[0]:.0f} x {fov[1]:.0f} deg, beyond what lenses without distortion reach "
            f"({MAX_FOV_DEG:g} deg): the outlines' errors, not their perspective, made it"
        )
    if code == PP_OUTSIDE:
        return (
            f"the estimated principal point ({est[2]:.0f}, {est[3]:.0f}) lies outside the {w}x{h} image: "
            "the outlines' errors, not their perspective, made it"
        )
    return ""  # pragma: no cover


_check_sizes = check_sizes  # n_samples, n_points: the same rules as fit_homology's (sorjax._checks)


def _check_homologies(homologies, n_views):
    if homologies is not None:
        try:
            homologies = tuple(homologies)
        except TypeError:
            raise ValueError(
                f"homologies must be a sequence of sorjax.Homology (one per outline, from "
                f"sorjax.fit_homology); got {type(homologies).__name__}."
            ) from None
        if len(homologies) != n_views:
            raise ValueError(
                f"got {len(homologies)} homologies for {n_views} outlines; pass one "
                "sorjax.fit_homology result per outline, in the same order (or none)."
            )
        for i, h in enumerate(homologies):
            if not isinstance(h, Homology):
                raise ValueError(
                    f"homologies[{i}] is a {type(h).__name__}, not a sorjax.Homology; "
                    "pass the results of sorjax.fit_homology (or homologies=None)."
                )
    return homologies




# ------------------------------------------------------------- messages (the edge)


def code_name(result) -> str:
    """The name of a :class:`RESULTS` item (also one read back as numpy)."""
    v = int(np.asarray(result._value))
    for name, item in RESULTS._name_to_item.items():
        if int(item._value) == v:
            return name
    return "unknown"  # pragma: no cover


def _code_item(result):
    return RESULTS._name_to_item[code_name(result)]


def _drop_texts(h, i: int, d: int, name: str, dup_of=None):
    """``(reason, warning)`` for view ``i`` dropped by the core for reason ``d``
    (:data:`sorjax.core._assess.DROP_REASONS`; ``dup_of`` (V,) the view each
    duplicates), or None when it is used."""
    o = Options()
    rms = max(float(h.rms[i]), float(h.rms_untrimmed[i]))
    tr = float(h.trimmed[i])
    if d == CONIC:
        return "conic outline", (
            f"{name}: the outline is a conic to within {float(h.conic_rms[i]):.2g} px (its symmetry "
            f"residual is {rms:.2g} px), like a sphere or a bowl seen from above showing "
            "only its rim: infinitely many homologies fit it, so it carries no calibration "
            "information (paper, Section 6). Dropped; use views where the body's profile shows.")
    if d == TRIMMED:
        return f"not symmetric ({100 * tr:.0f} % of the outline trimmed)", (
            f"{name}: the outline is not symmetric: {100 * tr:.0f} % of its samples have no "
            f"mirror image under the best harmonic homology (more than {100 * o.max_trimmed:.0f} % "
            "cannot be a handle or a shadow on a surface of revolution). Dropped; check the "
            "segmentation of this view.")
    if d == ASYMMETRIC:
        return f"not symmetric (rms {rms:.3g} px)", (
            f"{name}: the outline is not symmetric: its best harmonic homology leaves an RMS "
            f"symmetry residual of {rms:.3g} px (a surface of revolution with up to 2 px of noise "
            f"stays below about {o.asymmetry_px:g} px), so it is not the outline of a surface of "
            "revolution (or it is broken, occluded or merged with something else). Dropped; "
            "check the segmentation of this view.")
    if d == MASKED:
        return "left out by the caller", None
    if d == DUPLICATE:
        j = int(dup_of[i]) if dup_of is not None else -1
        other = f"view {j}" if j >= 0 else "an earlier view"
        return f"the same outline as {other}", (
            f"{name}: the same outline as {other} (within {o.duplicate_px:g} px RMS): the same view passed twice "
            "adds no information but would shrink the standard deviations by sqrt(2) as if it did. Dropped; "
            "take each view from a different position of the object or camera.")
    return None


def view_notes(h, drop_reason, names=None, dup_of=None) -> list[str]:
    """The per-view warnings of a calibration, from the per-view homologies ``h``
    (:class:`sorjax.core.ViewHomologies`, numpy) and the core's drop reasons: fits
    that did not converge, views dropped (conic, not symmetric) and kept with a
    caveat (trimmed, high residual)."""
    names = names or [f"view {i}" for i in range(len(drop_reason))]
    o = Options()
    notes = [f"{name}: the homology fit did not converge (rms {float(h.rms[i]):.3g} px)."
             for i, name in enumerate(names) if not bool(h.converged[i])]
    for i, name in enumerate(names):
        dropped = _drop_texts(h, i, int(drop_reason[i]), name, dup_of)
        if dropped is not None:
            if dropped[1]:
                notes.append(dropped[1])
            continue
        rms, tr = max(float(h.rms[i]), float(h.rms_untrimmed[i])), float(h.trimmed[i])
        if tr >= o.note_trimmed:
            notes.append(f"{name}: {100 * tr:.0f} % of the outline's samples have no mirror image (a "
                         "handle, a shadow, an occlusion?) and were left out of the fit.")
        if rms > o.warn_asymmetry_px:
            notes.append(f"{name}: high symmetry residual ({rms:.3g} px): a noisy outline, or not quite a "
                         "surface of revolution; kept. Check its segmentation.")
    return notes


def dropped_views(h, drop_reason, dup_of=None) -> tuple[tuple[int, str], ...]:
    """``(view index, reason)`` of each view the core left out."""
    out = []
    for i, d in enumerate(np.asarray(drop_reason)):
        dropped = _drop_texts(h, i, int(d), f"view {i}", dup_of)
        if dropped is not None:
            out.append((i, dropped[0]))
    return tuple(out)


def _advice_for(r, points, free_aspect: bool) -> list[str]:
    used = np.flatnonzero(np.asarray(r.used))
    return _advice(np.asarray(r.K_raw), np.asarray(r.v_x)[used], np.asarray(r.l_s)[used],
                   [points[i] for i in used], free_aspect, bool(r.aspect_weak), list(used))


def verdict_notes(r, method: str, a, points=None) -> list[str]:
    """The warning of a successful but weak calibration (its focal length uncertain by
    more than ``Options.weak_rel_std``), from the core's result ``r`` (numpy)."""
    if code_name(r.result) != "successful" or not np.isfinite(float(r.weak)):
        return []
    tips = ("; ".join(_advice_for(r, points, a is None)) + ".") if points is not None else "add views."
    return [
        f"weak geometry: the focal length is uncertain by {100 * float(r.weak):.3g} % (1 sigma, for a "
        f"symmetry residual (or outline noise) of {max(float(r.s_px), Options().residual_floor_px):.2g} px): " + tips
    ]


def _worst_views(ch, k: int = 2) -> str:
    """The views whose release from the joint model lowers the cost most (text)."""
    S = np.asarray(ch.view_score, float)
    order = [int(i) for i in np.argsort(-np.nan_to_num(S, nan=-1.0)) if np.isfinite(S[i])][:k]
    return ", ".join(f"view {i} (score {S[i]:.3g}, {float(ch.view_px[i]):.2g} px)" for i in order)


def _aspect_text(ch) -> str:
    return (f"aspect_ratio={float(ch.aspect_fixed):g} is not what the outlines show: with the aspect ratio free "
            f"they give fu / fv = {float(ch.aspect_free):.4f} +- {float(ch.aspect_free_std):.2g}, "
            f"{float(ch.aspect_z):.3g} standard deviations away, and fit {float(ch.aspect_px):.2g} px RMS better")


def _views_text(ch) -> str:
    return (f"the views are not consistent with one camera: released from the joint model their homologies fit "
            f"{float(ch.consistency_px):.2g} px RMS better, far beyond their noise (chi-square p = "
            f"{float(ch.consistency_p):.2g} on {int(ch.consistency_dof)} degrees of freedom); most of it in "
            + _worst_views(ch))


def _lens_text(ch) -> str:
    return (f"the outlines show radial lens distortion, which the pinhole model (distortion='none') holds at zero: "
            f"with k1 released they fit {float(ch.lens_px):.2g} px RMS better (score test p = "
            f"{float(ch.lens_p):.2g}), and one step of the released model gives k1 = {float(ch.lens_k1):.3g}")


def _fixed_text(ch, fixed) -> str:
    names = [n for n, v in zip(_NAMES, fixed) if np.isfinite(v)] if fixed is not None else []
    held = ", ".join(f"{n} = {v:.6g}" for n, v in zip(_NAMES, fixed) if np.isfinite(v)) if names else "the fixed values"
    shift = np.asarray(ch.fixed_shift, float)
    moves = ", ".join(f"{n} by {d:+.3g}" for n, d in zip(_NAMES, shift) if np.isfinite(d) and abs(d) > 0)
    return (f"the fixed intrinsics ({held} px) are not what the outlines show: released they fit "
            f"{float(ch.fixed_px):.2g} px RMS better (score test p = {float(ch.fixed_p):.2g}), and one step of the "
            f"released model moves {moves or 'nothing'} px")


def distortion_notes(r, distortion: str, outline_error: float) -> list[str]:
    """The warning of a distortion model the outlines do not support (the
    distortion-free K returned, its std widened), from the core's result ``r``."""
    if distortion == "none" or np.all(np.isfinite(np.asarray(r.distortion))):
        return []
    g, z = float(r.distortion_px), float(r.distortion_z)
    o = Options()
    why = (f"noise alone could do (needs z >= {o.perspective_z:g})" if not z >= o.perspective_z else
           f"a systematic outline error of {float(outline_error):g} px (outline_error) could do (needs >= "
           f"{o.perspective_factor * float(outline_error):.2g} px)")
    return [f"distortion={distortion!r}: the outlines do not determine the radial distortion: the fit without it is "
            f"only {g:.2g} px RMS worse (z = {z:.2g}), which {why}. Returned: the distortion-free K, its standard "
            "deviations widened by the difference to the fit with distortion (the outlines cannot tell distortion "
            "from a change of focal length), and NaN coefficients. Add views with objects near the image's edges "
            "and corners, where distortion is strongest."]


def model_notes(r, outline_error: float, fixed=None) -> list[str]:
    """The warning of a calibration whose model the outlines do not confirm (the
    uncertainty widened: :mod:`sorjax.core._checks`), from the core's result ``r``;
    ``fixed``: the intrinsics held fixed (px, NaN: free) or None."""
    ch = r.checks
    if int(ch.verdict) != MODEL_WIDENED or code_name(r.result) not in ("successful", "degenerate",
                                                                      "only_principal_point"):
        return []
    notes = []
    if np.isfinite(float(ch.aspect_z)) and float(ch.aspect_z) >= Options().consistency_z:
        notes.append(
            _aspect_text(ch) + f", within what the outline error allowed for ({float(outline_error):g} px) could "
            "cause. The standard deviations include the difference between the fixed and the free estimates; "
            "if the aspect ratio is not known exactly, pass aspect_ratio=None.")
    if bool(ch.lens_rejected):
        notes.append(
            _lens_text(ch) + f", within what the outline error allowed for ({float(outline_error):g} px) could cause. "
            "The standard deviations include the shift of K that this step makes. Calibrate with distortion='k1' "
            "(command line: --distortion k1) to estimate the distortion with K.")
    if bool(ch.fixed_rejected):
        notes.append(
            _fixed_text(ch, fixed) + f", within what the outline error allowed for ({float(outline_error):g} px) "
            "could cause. The standard deviations include that shift; if these values are not known exactly, "
            "leave them free.")
    if float(ch.inflation) > 1.0:
        notes.append(
            _views_text(ch) + f". The standard deviations are scaled by sqrt({float(ch.inflation):.3g}) (the "
            "views' disagreement over their noise). Check that every view comes from the same camera and zoom, "
            "uncropped and unresized, and that each outline is a surface of revolution.")
    return notes


def details_for(r, h, points, method: str, a, outline_error: float, image_size=None, fixed_pp=None,
                fixed=None) -> str:
    """What is specific to a result that is not a plain success (``Calibration.details``);
    ``fixed_pp``: the principal point held fixed (px) or None; ``fixed``: every
    intrinsic held fixed (px, NaN: free) or None."""
    name = code_name(r.result)
    if name == "inconsistent":
        ch = r.checks
        lim = f"{Options().perspective_factor * float(outline_error):.2g}"
        if int(ch.culprit) == CULPRIT_ASPECT:
            return (_aspect_text(ch) + f", more than the outline error allowed for ({float(outline_error):g} px; "
                    f"needs < {lim} px) can explain. Pass aspect_ratio=None to estimate it, or the right value "
                    "(resized or non-square-pixel images have fu / fv != 1).")
        if int(ch.culprit) == CULPRIT_LENS:
            return (_lens_text(ch) + f", more than the outline error allowed for ({float(outline_error):g} px; needs "
                    f"< {lim} px) can explain. Calibrate with distortion='k1' (command line: --distortion k1; "
                    "'k1k2' for a strong wide-angle lens), or undistort the images first.")
        if int(ch.culprit) == CULPRIT_FIXED:
            return (_fixed_text(ch, fixed) + f", more than the declared outline error ({float(outline_error):g} "
                    f"px; needs < {lim} px) can explain. Leave them free, or give the right values (a cropped or "
                    "resized image moves the principal point and scales the focal length).")
        return (_views_text(ch) + f", more than the outline error allowed for ({float(outline_error):g} px; needs < "
                f"{lim} px) can explain. Were all views taken with the same camera and zoom, uncropped and "
                "unresized? Is every outline a surface of revolution (not a flat symmetric shape)? Leave out the "
                "views that disagree, or calibrate each camera on its own.")
    used = np.flatnonzero(np.asarray(r.used))
    drop = np.asarray(r.drop_reason)
    vs = ", ".join(str(i) for i in used)
    if name == "too_few_views":
        why = "; ".join(f"view {i}: {reason}" for i, reason in dropped_views(h, drop))
        if fixed_pp is not None:
            return (f"{len(drop)} views given, {len(used)} usable ({why}). With the principal point fixed one view "
                    "is enough, but none is left.")
        return (f"{len(drop)} views given, {len(used)} usable ({why}). A single view gives only two "
                "constraints on the four intrinsics; fix the principal point (principal_point=, the command "
                "line's --principal-point / --centre-principal-point) to calibrate from one view.")
    if fixed_pp is not None and name == "degenerate" and bool(r.all_at_infinity):
        return (f"The principal point is fixed at ({fixed_pp[0]:.1f}, {fixed_pp[1]:.1f}) px and in every view used "
                f"(views {vs}) v_x is at infinity: the imaged axis l_s passes through the principal point (the "
                "object's axis and the optical axis lie in one plane: the object on a line through the image's "
                "principal point, or the camera looking straight at its axis). The pole-polar relation "
                "omega v_x ~ l_s then holds for every focal length, so the focal length is not determined. Add "
                "(or use instead) a view with the object away from the principal point, seen from above or below.")
    if bool(r.all_at_infinity) and name in ("only_principal_point", "degenerate") and not np.any(
            np.asarray(r.determined)[:2]):
        K = np.asarray(r.K)
        if np.all(np.isfinite(K[:2, 2])):
            sd = np.sqrt(np.diag(np.asarray(r.covariance))[2:])
            return (f"Every view's v_x is at infinity (views {vs}): the imaged axes meet at the principal "
                    f"point ({_fmt_std(K[0, 2], sd[0])}, {_fmt_std(K[1, 2], sd[1])}) px; the focal length is not "
                    "determined.")
        pp, cov_pp, spread = (np.asarray(a) for a in axes_intersection(jnp.asarray(r.l_s), jnp.asarray(r.used)))
        if not np.all(np.isfinite(pp)):
            return (f"Every view's v_x is at infinity (views {vs}) and their imaged axes are parallel "
                    f"(within {float(spread):.2g} deg), so not even the principal point is determined. "
                    "Add a view with the object away from the image centre.")
        sd = np.sqrt(np.abs(np.diag(cov_pp)))
        if not np.all(np.isfinite(sd)):
            why = (f"only {len(used)} imaged axes, which always meet: with fewer than three the views cannot show "
                   "the error of their meeting point")
        else:
            why = f"their meeting point is uncertain by ({sd[0]:.3g}, {sd[1]:.3g}) px"
        if image_size is not None and not bool(inside_image(pp[0], pp[1], np.asarray(image_size, np.float64))):
            why += f", and it lies outside the {float(image_size[0]):.0f} x {float(image_size[1]):.0f} image"
        return (f"Every view's v_x is at infinity (views {vs}): the imaged axes meet at ({pp[0]:.1f}, {pp[1]:.1f}) "
                f"px, which is not reported as the principal point: {why}. Neither the focal length nor the "
                "principal point is determined. Add views with the object away from the image centre, seen from "
                "above or below.")
    det = np.asarray(r.determined)
    if name in ("only_principal_point", "degenerate") and not det.all() and np.all(np.isfinite(np.asarray(r.K_raw))):
        Kr = np.asarray(r.K_raw)
        est = [Kr[0, 0], Kr[1, 1], Kr[0, 2], Kr[1, 2]]
        std = np.asarray(r.std)
        d_ = ", ".join(f"{n} = {_fmt_std(x, s)} px" for n, x, s, d in zip(_NAMES, est, std, det) if d)
        u_ = ", ".join(f"{n} ({_fmt_std(x, s)} px)" for n, x, s, d in zip(_NAMES, est, std, det) if not d)
        why = _implausible_text(int(r.implausible), np.array(est), [points[i] for i in used], image_size)
        why = f" Not a plausible camera: {why}." if why else ""
        if not bool(r.perspective_ok):
            z, g = float(r.perspective_z), float(r.perspective_px)
            o = Options()
            why += (
                f" The outlines show too little perspective to fix the focal length: the best camera with "
                f"no perspective fits them only {g:.2g} px RMS worse (z = {z:.2g}), which "
                + (f"noise alone could do (needs z >= {o.perspective_z:g})" if z < o.perspective_z else
                   f"a systematic outline error of {float(outline_error):g} px (outline_error) could do "
                   f"(needs >= {o.perspective_factor * float(outline_error):.2g} px)")
                + "."
            )
        advice = _advice_for(r, points, a is None)
        return (f"Not determined by these views: {u_}" + (f"; determined: {d_}" if d_ else "") + "." + why
                + " To fix it: " + "; ".join(advice) + ".")
    return ""


# ------------------------------------------------------------------ the core call


def _bucket(n: int) -> int:
    """The padded view count for ``n`` views: 4, 8, 16, ... (one compiled program each;
    a masked view costs little, a compilation tens of seconds)."""
    return max(4, 1 << (n - 1).bit_length())


def view_homologies(homologies, n_samples: int) -> ViewHomologies:
    """Stack :class:`Homology` fits (numpy) into the core's :class:`ViewHomologies`;
    hand-built ones (no robust-fit fields) count as untrimmed, finite vertex unless
    ``|v_x[2]| < 1e-9``."""
    def row(h):
        inl = None if h.inliers is None else np.asarray(h.inliers, bool)
        if inl is None or inl.shape != (n_samples,):
            inl = np.ones(n_samples, bool)
        rms = float(h.rms)
        v, l = np.asarray(h.v_x, np.float64), np.asarray(h.l_s, np.float64)
        return dict(
            v_x=v, l_s=l, W=np.asarray(h.W, np.float64), rms=np.float64(rms), cost=np.float64(float(h.cost)),
            rms_untrimmed=np.float64(rms if h.rms_untrimmed is None else float(h.rms_untrimmed)),
            conic_rms=np.float64(float(h.conic_rms)), trimmed=np.float64(h.trimmed),
            infinity_z=np.float64(np.inf if h.infinity_z is None else float(h.infinity_z)),
            at_infinity=np.bool_(h.v_x_at_infinity), is_conic=np.bool_(h.is_conic),
            converged=np.bool_(bool(h.converged)), steps=np.int32(int(h.steps)), inliers=inl,
            noise_ell=np.float64(np.nan if h.noise_ell is None else float(h.noise_ell)),
        )
    rows = [row(h) for h in homologies]
    return ViewHomologies(**{k: np.stack([r[k] for r in rows]) for k in rows[0]})


@functools.partial(one_off_jit, static_argnames=("method",))
def _core(points, homs, aspect, options, image_size, valid, fixed=None, noise=None, noise_ell=None, *,
          method: str = "bundle"):
    """One method's estimate (:func:`sorjax.core.calibrate_homologies`): one compiled
    program per method and padded view count.  The bundle's program holds no linear
    method beside it (the three linear methods' covariances in the same program made
    it a quarter larger, for the one result a call returns); a linear method's program
    holds no solver.  ``fixed``: intrinsics held fixed (px, NaN: free) or None
    (another compiled program: the one of a free camera stays as it was); ``noise``
    (V,) the views' noise floors, px (0: none), ``noise_ell`` (V,) their correlation
    lengths, px (0: unknown)."""
    return calibrate_homologies(points, homs, method, aspect, options=options, image_size=image_size, valid=valid,
                                fixed=fixed, noise=noise, noise_ell=noise_ell)


@functools.partial(one_off_jit, static_argnames=("distortion",))
def _core_distorted(points, homs, aspect, options, image_size, valid, distortion, fixed=None, noise=None,
                    noise_ell=None):
    """The bundle with radial distortion (``distortion`` "k1" or "k1k2")."""
    return calibrate_homologies(points, homs, "bundle", aspect, options=options, image_size=image_size, valid=valid,
                                distortion=distortion, fixed=fixed, noise=noise, noise_ell=noise_ell)


def _run_core(points: np.ndarray, homs: ViewHomologies, method: str, aspect, options: Options, image_size,
              distortion: str = "none", fixed=None, leave_out: Sequence[int] = (), noise=None, noise_ell=None):
    """The core on ``V`` views padded to :func:`_bucket` (copies of view 0, masked);
    returns the result of ``method`` as numpy, cut back to ``V`` views.  ``fixed``
    (4,) ``(fu, fv, u0, v0)`` px held fixed (NaN: free), or None; ``leave_out``: views
    masked out as well (the same compiled program); ``noise`` (V,) the views' noise
    floors, px, and ``noise_ell`` (V,) their correlation lengths, px (None: 0, the same
    compiled program)."""
    V = points.shape[0]
    B = _bucket(V)
    pad = lambda x: np.concatenate([x, np.repeat(x[:1], B - V, axis=0)]) if B > V else x  # noqa: E731
    valid = np.arange(B) < V
    valid[list(leave_out)] = False
    args = (pad(points), jax.tree_util.tree_map(pad, homs), np.float64(aspect), options,
            np.asarray(image_size, np.float64), valid)
    fixed = None if fixed is None else np.asarray(fixed, np.float64)
    noise = pad(np.zeros(V) if noise is None else np.asarray(noise, np.float64))
    noise_ell = pad(np.zeros(V) if noise_ell is None else np.asarray(noise_ell, np.float64))
    if distortion == "none":
        r = _core(*args, fixed, noise, noise_ell, method=method)
    else:
        r = _core_distorted(*args, distortion, fixed, noise, noise_ell)
    r = jax.tree_util.tree_map(np.asarray, r)
    per_view = ("used", "drop_reason", "view_rms", "v_x", "l_s")
    r = eqx.tree_at(lambda x: [getattr(x, k) for k in per_view], r, [getattr(r, k)[:V] for k in per_view])
    per_check = ("view_score", "view_px", "duplicate_of")
    return eqx.tree_at(lambda x: [getattr(x.checks, k) for k in per_check], r,
                       [getattr(r.checks, k)[:V] for k in per_check])


def _estimate(K) -> np.ndarray:
    """``(fu, fv, u0, v0)`` (px) of a 3x3 ``K``, numpy (the core's ``_intrinsics``)."""
    return np.asarray(_intrinsics(np.asarray(K, np.float64)))


def jackknife(r, points: np.ndarray, homs: ViewHomologies, method: str, aspect, options: Options, image_size,
              fixed=None, left_out: Sequence[int] = (), noise=None, noise_ell=None):
    """The core result ``r`` checked by leaving out each used view in turn, for
    outlines of measured quality (``calibrate(outline_error="measured")``).

    With ``n`` views used and ``theta_i`` the raw estimate ``(fu, fv, u0, v0)`` (px)
    without view ``i``, the jackknife covariance is ``C_J = (n - 1) / n sum_i (theta_i
    - mean) (theta_i - mean)^T`` (Efron and Stein 1981; a leave-one-out estimate that
    is not finite makes it infinite).  The reported covariance becomes ``C + C_J``:
    the bundle's covariance ``C`` is a linearisation that trusts every view, and one
    view whose outline is wrong without looking it (a symmetric fragment of an
    object, a box face, a leak into a shadow) moves the estimate far more than it
    says.  An intrinsic stays determined only when its widened standard deviation is
    at most ``options.measured_undetermined`` (1/60) of the focal length; the others
    are set to NaN and the result code becomes ``degenerate``.  Returns ``(r, notes)``: the result with ``K``, ``covariance``,
    ``std``, ``determined``, ``omega`` and ``result`` updated, and warning texts (none
    when nothing was determined).  ``left_out``: views ``r`` was computed without
    (:func:`dominant_view`, left out by :func:`calibrate`), left out of every run; ``noise``,
    ``noise_ell``: the views' noise floors and their correlation lengths (px) or None.  Costs one run of the compiled core per used view."""
    det = np.asarray(r.determined, bool)
    if not det.any() or code_name(r.result) not in ("successful", "degenerate", "only_principal_point"):
        return r, []
    if bool(r.all_at_infinity) and not det[:2].any():
        # the principal point alone, where three or more imaged axes meet: its covariance
        # is their scatter; the leave-one-out runs would judge the bundle's estimate
        return r, []
    used = np.flatnonzero(np.asarray(r.used))
    n = len(used)
    est = _estimate(r.K_raw)
    loo = np.full((n, 4), np.nan)
    for k, i in enumerate(used):
        ri = _run_core(points, homs, method, aspect, options, image_size, "none", fixed,
                       leave_out=[int(i), *left_out], noise=noise, noise_ell=noise_ell)
        loo[k] = _estimate(ri.K_raw)
    held = np.zeros(4, bool) if fixed is None else np.isfinite(np.asarray(fixed, np.float64))
    loo[:, held] = est[held]
    if n >= 2 and np.all(np.isfinite(loo)):
        dev = loo - loo.mean(0)
        C_J = (n - 1) / n * dev.T @ dev
    else:
        C_J = np.diag(np.where(held, 0.0, np.inf))
    with np.errstate(invalid="ignore"):
        cov = np.asarray(r.covariance, np.float64) + C_J
    std = np.sqrt(np.abs(np.diag(cov)))
    std = np.where(held, 0.0, std)
    f_ref = math.sqrt(abs(est[0] * est[1])) if np.all(np.isfinite(est[:2])) else math.nan
    lim = options.measured_undetermined * f_ref
    new = det & (held | (np.isfinite(std) & (std <= lim)))
    if np.all(np.isfinite(loo)):
        move = np.abs(loo - est)
        worst = int(np.argmax(np.max(move[:, :2], axis=1)))
        moved = (f"leaving out view {int(used[worst])} moves fu by {loo[worst, 0] - est[0]:+.3g} px and fv by "
                 f"{loo[worst, 1] - est[1]:+.3g} px")
    else:
        bad = [int(used[k]) for k in range(n) if not np.all(np.isfinite(loo[k]))]
        moved = f"without view{'s' if len(bad) > 1 else ''} {', '.join(map(str, bad))} there is no estimate"
    f_std = ", ".join(f"{nm} +- {sd:.3g} px" for nm, sd, d in zip(_NAMES, std, det) if d)
    notes = [f"leave-one-view-out check of outlines of measured quality ({n} views): {moved}; the standard "
             f"deviations include that spread (jackknife): {f_std}."]
    lost = det & ~new
    if lost.any():
        notes.append(
            f"{', '.join(nm for nm, d in zip(_NAMES, lost) if d)} not determined: with outlines of measured quality "
            f"(found in images) an intrinsic counts as determined only when its standard deviation, with the "
            f"views' leave-one-out spread, is at most {options.measured_undetermined:.3g} of the focal length "
            f"({lim:.3g} px: 3 std within {300 * options.measured_undetermined:.3g} %); one view moves it more. "
            "Check the outlines (the overlay), leave out the views that are not surfaces of revolution, or add views.")
        K = np.asarray(r.K_raw, np.float64).copy()
        for (a_, b_), d in zip(((0, 0), (1, 1), (0, 2), (1, 2)), new):
            if not d:
                K[a_, b_] = np.nan
        # degenerate, not only_principal_point: that code's text blames the views' geometry
        r = eqx.tree_at(lambda x: (x.K, x.omega, x.result), r, (K, np.full((3, 3), np.nan), RESULTS.degenerate))
    r = eqx.tree_at(lambda x: (x.covariance, x.std, x.determined), r, (cov, std, new))
    return r, notes


def dominant_view(r, options: Options) -> tuple[int, float] | None:
    """``(view, share)`` of a result ``r`` (numpy) that the consistency check refused
    (``inconsistent``, the views to blame) when one view holds at least
    ``options.measured_leave_share`` of the score statistic ``S = sum_j S_j``
    (:func:`sorjax.core._checks.view_scores`) and at least 3 used views would remain;
    else None."""
    ch = r.checks
    if code_name(r.result) != "inconsistent" or int(ch.culprit) != CULPRIT_VIEWS:
        return None
    used = np.asarray(r.used, bool)
    S = np.where(used, np.nan_to_num(np.asarray(ch.view_score, np.float64), nan=0.0), 0.0)
    total = float(S.sum())
    if used.sum() < 4 or not total > 0:
        return None
    j = int(np.argmax(S))
    share = float(S[j]) / total
    return (j, share) if share >= float(options.measured_leave_share) else None


def _left_out_text(r, j: int, share: float) -> str:
    ch = r.checks
    n = int(np.asarray(r.used, bool).sum()) - 1
    return (f"view {j} left out: the views were not consistent with one camera (chi-square p = "
            f"{float(ch.consistency_p):.2g} on {int(ch.consistency_dof)} degrees of freedom, "
            f"{float(ch.consistency_px):.2g} px RMS) and this view held {100 * share:.0f} % of the disagreement "
            f"(score {float(ch.view_score[j]):.3g}, {float(ch.view_px[j]):.2g} px): most likely it is not a surface "
            f"of revolution seen by this camera (a false detection or a poor segmentation; check the overlay). "
            f"Calibrated again from the other {n} views.")


def _check_outline_error(outline_error):
    """``(declared px, per-outline errors (px) or None, measured?)`` from
    :func:`calibrate`'s ``outline_error``: a number, "measured" or one number per outline."""
    bad = ("outline_error must be a finite number of pixels >= 0, 'measured' (taken from the outlines' symmetry "
           f"residuals), or one such number per outline (NaN: no estimate); got {outline_error!r:.80}.")

    def px(x, nan_ok=False):
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)) or not (
                (math.isfinite(x) and x >= 0) or (nan_ok and math.isnan(x))):
            raise ValueError(bad)
        return float(x)

    if isinstance(outline_error, str):
        if outline_error != "measured":
            raise ValueError(bad)
        return OUTLINE_ERROR_PX, None, True
    if isinstance(outline_error, (list, tuple, np.ndarray)):
        try:
            vals = np.asarray(outline_error).tolist() if np.ndim(outline_error) == 1 else None
        except ValueError:  # ragged
            vals = None
        if not vals:
            raise ValueError(bad)
        return OUTLINE_ERROR_PX, np.array([px(x, nan_ok=True) for x in vals]), True
    return px(outline_error), None, False


def _outline_noise(outline_noise, outlines, n: int, name: str = "outline_noise", attr: str = "noise_rms"):
    """:func:`calibrate`'s ``outline_noise`` (or ``outline_noise_ell``: ``name``, read
    from the attribute ``attr``) as (n,) px (0: none), or None (none): given, or the
    outlines' own attributes."""
    if outline_noise is None:
        own = [getattr(o, attr, None) for o in outlines] if isinstance(outlines, (list, tuple)) else []
        own = [float(e) if _is_number(e) and math.isfinite(e) and e > 0 else 0.0 for e in own]
        return np.array(own) if len(own) == n and any(own) else None
    bad = (f"{name} must be a finite number of pixels >= 0, one such number per outline (NaN: none), or "
           f"None; got {outline_noise!r:.80}.")
    vals = np.atleast_1d(np.asarray(outline_noise, dtype=object))
    if vals.ndim != 1 or not all(_is_number(v) and (math.isnan(v) or (math.isfinite(v) and v >= 0)) for v in vals):
        raise ValueError(bad)
    vals = np.nan_to_num(vals.astype(np.float64), nan=0.0)
    if np.ndim(outline_noise) == 0:
        return np.full(n, vals[0])
    if vals.size != n:
        raise ValueError(f"{name}: got {vals.size} values for {n} outlines; give one number (px) per outline, "
                         "in the same order, or one number for all.")
    return vals


def _own_errors(outlines):
    """The outlines' own error estimates (px; NaN: none): the ``outline_error``
    attribute an extractor attaches to its outline arrays (sorjax's image path does),
    or None when no outline has one."""
    own = []
    for o in outlines:
        e = getattr(o, "outline_error", None)
        own.append(float(e) if _is_number(e) and (math.isnan(e) or (math.isfinite(e) and e >= 0)) else math.nan)
    return np.array(own) if np.isfinite(own).any() else None


def measured_outline_error(homs: ViewHomologies, points, per_outline=None, *, floor: float = OUTLINE_ERROR_PX,
                           options: Options = Options(), left_out: Sequence[int] = (),
                           noise=None) -> tuple[float, str]:
    """The outline error (px) measured from the outlines, and a note saying so.

    Each view's error is its symmetry residual, the RMS residual of its homology fit
    (eq. 20, px; ``homs.rms``), or the outline's own error estimate ``per_outline[i]``
    (px, e.g. an extractor's; NaN: none) or its noise floor ``noise[i]`` (px, the residual
    it would show, :func:`calibrate`'s ``outline_noise``) when larger; the measured error is their RMS
    over the views the calibration keeps (:func:`sorjax.core._assess.view_verdicts`: not a
    conic, not asymmetric, not over-trimmed, not in ``left_out``), and at least ``floor``.  A residual
    shows only the outline errors that break the symmetry; a segmentation that leaks
    or shrinks has errors that keep it as well, of about the same size, which the
    perspective gate must allow for: outlines 1 to 2 px from symmetric with the
    default 0.1 px gave a confident wrong K (issue 17: fu 809 +- 29 px for a true 980)."""
    pts = jnp.asarray(points)
    valid = np.ones(pts.shape[0], bool)
    valid[list(left_out)] = False
    keep = np.asarray(view_verdicts(jnp.asarray(homs.rms), jnp.asarray(homs.rms_untrimmed), outline_radius(pts),
                                    jnp.asarray(homs.is_conic), jnp.asarray(homs.trimmed),
                                    jnp.asarray(valid), options)) == USED
    rms = np.asarray(homs.rms, np.float64)
    if noise is not None:  # an averaged outline: the residual it would show
        rms = np.fmax(rms, np.asarray(noise, np.float64))
    err = rms if per_outline is None else np.fmax(rms, np.asarray(per_outline, np.float64))
    ok = keep & np.isfinite(err)
    value = float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else 0.0
    src = "symmetry residuals" if per_outline is None else "symmetry residuals and own error estimates"
    spread = f"{err[ok].min():.2g} to {err[ok].max():.2g} px" if ok.sum() > 1 else (
        f"{err[ok][0]:.2g} px" if ok.any() else "no view kept")
    used = max(value, floor)
    return used, (f"outline error {used:.2g} px, measured from the outlines: the RMS of the {int(ok.sum())} kept "
                  f"views' {src} ({spread}: {value:.2g} px)" + (f", at least {floor:g} px" if floor > value else "")
                  + f"; the focal length counts as determined only when the outlines show >= "
                  f"{options.perspective_factor * used:.2g} px of perspective.")


def calibrate(
    outlines,
    method: str = "bundle",
    aspect_ratio: float | None = None,
    *,
    n_samples: int = DEFAULT_SAMPLES,
    n_points: int = DEFAULT_POINTS,
    homologies=None,
    outline_error: float | str | Sequence[float] = OUTLINE_ERROR_PX,
    image_size: tuple[int, int] | None = None,
    distortion: str = "none",
    principal_point=None,
    focal_length: float | None = None,
    outline_noise: float | Sequence[float] | None = None,
    outline_noise_ell: float | Sequence[float] | None = None,
    throw: bool = False,
) -> Calibration:
    """Calibrate a camera from the outlines of surfaces of revolution.

    Args:
        outlines: one closed outline per view, each an (N, 2) array of pixel
            coordinates (OpenCV convention) or an :class:`Outline`; at least two.
        method: "bundle" (default: the joint 2V+4 estimator, or 2V+3 with a known
            aspect ratio, seeded by Method II; gives the covariance), "I" (zero skew,
            unit or known aspect ratio; eqs. 21-26), "IIa" (zero skew, free aspect
            ratio; eqs. 27-28) or "IIb" (IIa with ``fu = a fv``).
        aspect_ratio: known ``fu / fv``.  "I" and "IIb" assume 1 when it is None;
            "bundle" then estimates it (free aspect).
        n_samples: samples per outline in the homology fit (eq. 20).
        n_points: resampled outline size for the distance fields.
        homologies: optional precomputed per-view :class:`Homology` fits.
        outline_error: the systematic error (px RMS) the outlines may carry that their
            symmetry residual does not show: segmentation bias, lens distortion, an
            object that is not quite a surface of revolution.  The bundle counts the
            focal length as determined only when the outlines show at least
            ``PERSPECTIVE_FACTOR`` (3) times this much perspective (see
            ``Calibration.perspective_px``).  The default, 0.1 px, is about the
            accuracy of good sub-pixel outlines of real objects; pass 0 for exact
            outlines with only random noise (synthetic studies).  ``"measured"``: taken
            from the outlines themselves (:func:`measured_outline_error`: the RMS over
            the views kept of each view's symmetry residual, at least the default) --
            for outlines whose quality is not known, such as outlines found in
            photographs; a sequence of one number per outline (px; NaN: none): as
            "measured", with each view's residual raised to that outline's own error
            estimate (what an extractor reports; with "measured", outline arrays that
            carry an ``outline_error`` attribute give it themselves).  With either, the
            estimate is also checked by leaving out each view in turn
            (:func:`jackknife`): the spread widens the standard deviations, and an
            intrinsic counts as determined only when its widened std is at most
            ``Options.measured_undetermined`` (1/60) of the focal length, so that an
            outline that is wrong without looking it (a symmetric piece of clutter
            taken for an object) cannot make a confident wrong K.  A view that the
            consistency check blames almost alone (:func:`dominant_view`: at least
            ``Options.measured_leave_share`` of its score) is left out and the rest
            calibrated again, at most ``Options.measured_leave_out`` views and never
            below three, with a warning and the view in ``Calibration.dropped``.  Outlines on a
            pixel grid raise it further (whole-pixel coordinates, staircases; a pixel
            trace as ``cv2.findContours`` gives is replaced by its binary mask's
            outline, :func:`sorjax.make_outline`, and counts as accurate as that).
        image_size: ``(width, height)`` of the images in px, when known: an estimate
            with the principal point outside the image, or a field of view above
            ``MAX_FOV_DEG`` (120 deg), is then reported as not determined (the outlines'
            errors made it, not their perspective).
        distortion: the lens model: "none" (default: a pinhole, as the paper), "k1"
            or "k1k2" (OpenCV's radial distortion about the principal point, estimated
            by the bundle with the intrinsics: ``Calibration.distortion``).  The
            coefficients count as determined only when the fit with no distortion is
            worse beyond the noise and ``PERSPECTIVE_FACTOR`` times ``outline_error``
            (as for perspective); otherwise the distortion-free K is returned with its
            standard deviations widened by the difference between the two fits (the
            outlines cannot tell distortion from a change of focal length) and NaN
            coefficients, with a warning.
        principal_point: the principal point held fixed, as OpenCV's
            ``CALIB_FIX_PRINCIPAL_POINT``: ``(cx, cy)`` px, or "centre" for the image
            centre ``((width - 1) / 2, (height - 1) / 2)`` (OpenCV's pixel-centre
            convention; needs ``image_size``); None (default): estimated.  The bundle
            only.  With it, one outline is enough: its ``v_x`` and ``l_s`` then give
            the focal length (Wong, Mendonca and Cipolla, IVC 2004: with the
            principal point at the origin and ``K = diag(a f, f, 1)``, ``omega v_x ~
            l_s`` gives ``f^2 = dist(pp, v_x) dist(pp, l_s)``, and a redundant
            constraint); the aspect ratio is then taken as 1 unless given.  A view
            whose ``v_x`` is at infinity (its imaged axis through the principal
            point) leaves the focal length free: refused as ``RESULTS.degenerate``
            with the reason in ``details``.
        focal_length: ``fv`` px held fixed (``fu = aspect_ratio fv``, the aspect
            ratio 1 unless given), as OpenCV's ``CALIB_FIX_FOCAL_LENGTH``; only the
            principal point (and the distortion, when asked) is estimated.  The
            bundle only.  Two views are still needed unless the principal point is
            fixed too (one view puts the principal point at either of two places).
            Fixed intrinsics have a standard deviation of 0.
        outline_noise: each outline's noise, px: the RMS symmetry residual it would
            show (``Calibration.view_rms``' units), when its residual understates it
            (the outline was processed to look more symmetric than it was measured):
            one number, one per outline (NaN: none),
            or None (default: the ``noise_rms`` attribute of outline arrays that carry
            one, as :func:`sorjax.outlines_from_image`'s do, else none).  An outline
            averaged with its own mirror image (as :func:`sorjax.outlines_from_image`'s
            are) fits its homology better than it
            was measured; the calibration's noise level (covariance, model checks,
            perspective evidence, whether a view's ``v_x`` is at infinity) then takes
            each view's residuals as at least this
            (:attr:`sorjax.core._bundle.BundleProblem.noise`); the cost, and so ``K``, is
            the same.
        outline_noise_ell: the correlation length along the curve (px) of the noise
            behind each ``outline_noise`` (:attr:`Homology.noise_ell` of the outline
            before it was processed): one number, one per outline (NaN: unknown), or
            None (default: the ``noise_ell`` attribute of outline arrays that carry
            one, as :func:`sorjax.outlines_from_image`'s do).  Where a floor binds,
            the covariance takes this length for the view's noise instead of reading
            one off residuals that no longer show it: an averaged outline is smooth,
            and its residuals read as noise correlated over tens of pixels, which
            made the standard deviations about 4x too large
            (``experiments/noise_floor.py``).  Without ``outline_noise`` (given or
            read from the outlines) it has no effect.
        throw: raise :class:`CalibrationError` instead of returning a failed result.

    Returns:
        :class:`Calibration` with ``K`` (pixels) and a result code.

    Degenerate input is detected, never turned into a K:

    * views whose outline is a conic (a sphere) or is not symmetric (RMS symmetry
      residual above ``ASYMMETRY_PX`` px and ``ASYMMETRY_REL`` of its radius) are
      dropped with a warning naming them (``Calibration.dropped``); fewer than two
      left gives ``RESULTS.too_few_views``;
    * the estimate's covariance (the bundle's; for the linear methods the bundle's
      linearisation at their estimate) says which intrinsics the views determine: one
      with an infinite standard deviation or one above a third of the focal length is
      reported NaN, with ``RESULTS.only_principal_point`` (both focal lengths) or
      ``RESULTS.degenerate``; ``Calibration.details`` says which and what view to add;
    * when, in addition, every view's ``v_x`` is at infinity
      (:attr:`Homology.v_x_at_infinity`) -- or the estimate failed -- only the principal
      point is estimable: ``RESULTS.only_principal_point`` with the least-squares
      intersection of the ``l_s`` in ``K[:2, 2]`` and NaN focal lengths, when three
      axes or more fix it (two always meet: their meeting point cannot show its own
      error), its standard deviations (the axes' scatter about it, widened by
      Student's t for their ``k - 2`` degrees of freedom:
      :func:`sorjax.core._assess.few_dof_widening`) are at most a third of the outlines' RMS radius
      and it lies inside the image (``image_size``); else ``RESULTS.degenerate`` with
      K all NaN and the meeting point named in the message;
    * the bundle's focal length is not determined when the outlines show too little
      perspective (``outline_error``): the best camera with no perspective must fit
      them clearly worse, beyond their noise and their systematic error;
    * a successful calibration whose focal length has a relative standard deviation
      above ``WEAK_REL_STD`` (5 %; residual taken as at least 0.1 px) gives a warning
      saying what kind of extra view would help.
    """
    _check_method(method, aspect_ratio)
    if not isinstance(distortion, str) or distortion not in ("none", "k1", "k1k2"):
        raise ValueError(f"distortion must be 'none', 'k1' or 'k1k2' (OpenCV's radial terms); got {distortion!r}.")
    if distortion != "none" and method != "bundle":
        raise ValueError(f"distortion={distortion!r} is estimated by the bundle only; use method='bundle' (the "
                         f"default) instead of {method!r}.")
    _check_sizes(n_samples, n_points)
    outline_error, per_outline, measure = _check_outline_error(outline_error)
    if image_size is not None:
        try:
            iw, ih = (int(x) for x in image_size)
            if iw <= 0 or ih <= 0 or (iw, ih) != tuple(image_size) or any(isinstance(x, (bool, np.bool_))
                                                                            for x in image_size):
                raise ValueError
        except (TypeError, ValueError):
            raise ValueError(f"image_size must be (width, height) in pixels, two positive integers; got "
                             f"{image_size!r}.") from None
        image_size = (iw, ih)
    pp_fixed, f_fixed = _check_fixed(principal_point, focal_length, image_size, method)
    prepared = _as_outlines(outlines, n_points)
    outs, smoothed = [o for o, _ in prepared], [j for _, j in prepared]
    noise = _outline_noise(outline_noise, outlines, len(outs))
    noise_ell = _outline_noise(outline_noise_ell, outlines, len(outs), "outline_noise_ell", "noise_ell")
    if per_outline is not None and len(per_outline) != len(outs):
        raise ValueError(f"outline_error: got {len(per_outline)} per-outline errors for {len(outs)} outlines; give one "
                         "number (px) per outline, in the same order, or one number for all, or 'measured'.")
    if len(outs) == 1 and pp_fixed is not None:
        aspect_ratio = 1.0 if aspect_ratio is None else aspect_ratio  # the single-view case: square pixels
    if f_fixed is not None and aspect_ratio is None:
        aspect_ratio = 1.0  # a fixed focal length fixes fu = aspect fv: square pixels unless told
    if len(outs) < (1 if pp_fixed is not None else 2):
        raise ValueError(
            f"calibration needs at least two outlines (views) of surfaces of revolution; got "
            f"{len(outs)}. One outline gives only its own axis l_s and vanishing point v_x "
            "(use sorjax.fit_homology): two constraints on the four intrinsics (fu, fv, u0, v0), "
            "which leaves the camera undetermined. Add an outline from another view (the object "
            "moved or tilted, or another object), or fix the principal point (principal_point=(cx, cy) or "
            "'centre'; the command line's --principal-point CX CY or --centre-principal-point): one view then "
            "gives the focal length."
        )
    homologies = _check_homologies(homologies, len(outs))
    if homologies is None:
        homologies = tuple(fit_homology(o, n_samples=n_samples, n_points=n_points) for o in outs)
    homologies = tuple(homologies)
    points = np.stack([np.asarray(o.points, np.float64) for o in outs])
    homs = view_homologies(homologies, n_samples)
    # outlines on a pixel grid carry at least their quantisation (or a mask's staircase)
    raw = list(outlines) if isinstance(outlines, (list, tuple, np.ndarray)) else []
    implied = [implied_outline_error(o) for o in raw] or [(0.0, "")]
    floor_px, floor_kind = max(implied, key=lambda t: t[0])
    traces = [i for i, t in enumerate(implied) if t[1] == "pixel trace"]
    floor_note = [f"outline{'s' if len(traces) > 1 else ''} {', '.join(map(str, traces))}: {PIXEL_TRACE_NOTE}"
                  ] if traces else []
    jagged = [(i, j) for i, j in enumerate(smoothed) if j]
    if jagged:
        jit = [j[0] for _, j in jagged]
        floor_note.append(f"outline{'s' if len(jagged) > 1 else ''} {', '.join(str(i) for i, _ in jagged)}: "
                          + jagged_note(min(jit), max(j[1] for _, j in jagged), max(jit)))
    if floor_px > float(outline_error):
        which = [i for i, t in enumerate(implied) if t[0] == floor_px]
        why = {"staircase": "an unsmoothed staircase along or between pixels (up to half a pixel off the edge)",
               "pixel trace": "a binary mask's boundary pixels (its outline is as accurate as a binary mask's, "
                              f"about {BINARY_MASK_PX:g} px)",
               }.get(floor_kind, "rounded to whole or half pixels (1/sqrt(12) px of rounding error per coordinate)")
        floor_note.append(
            f"outline{'s' if len(which) > 1 else ''} {', '.join(map(str, which))}: the coordinates are {why}; "
            f"the outline error is taken as {floor_px:.2g} px instead of the {'default' if measure else 'declared'} "
            f"{float(outline_error):g} px. Sub-pixel outlines (sorjax.outlines_from_mask on a soft mask, or the 0.5 "
            "level of a blurred mask) are more accurate.")
        outline_error = floor_px
    if measure and per_outline is None:
        per_outline = _own_errors(raw)
    floor_px = float(outline_error)
    if measure:
        outline_error, note = measured_outline_error(homs, points, per_outline, floor=floor_px,
                                                     options=Options(n_samples=n_samples), noise=noise)
        floor_note.append(note)
        measured_at = len(floor_note) - 1
    options = Options(n_samples=n_samples, outline_error_px=float(outline_error))
    a = None if method in ("IIa",) or (method == "bundle" and aspect_ratio is None) else (
        1.0 if aspect_ratio is None else float(aspect_ratio)
    )
    fixed = None
    if pp_fixed is not None or f_fixed is not None:
        fixed = (math.nan, math.nan if f_fixed is None else f_fixed) + (pp_fixed or (math.nan, math.nan))
    aspect = math.nan if aspect_ratio is None else float(aspect_ratio)
    size = (math.nan, math.nan) if image_size is None else image_size
    run = functools.partial(_run_core, points, homs, method, aspect, noise=noise, noise_ell=noise_ell)
    r = run(options, size, distortion, fixed)
    # outlines of measured quality (found in images): a view the consistency check blames
    # almost alone is left out, and the rest calibrated again (Options.measured_leave_out)
    left_out: dict[int, str] = {}
    while measure and len(left_out) < int(options.measured_leave_out):
        dom = dominant_view(r, options)
        if dom is None:
            break
        j, share = dom
        floor_note.append(_left_out_text(r, j, share))
        left_out[j] = f"inconsistent with the other views ({100 * share:.0f} % of the consistency score)"
        outline_error, note = measured_outline_error(homs, points, per_outline, floor=floor_px,
                                                     options=Options(n_samples=n_samples), left_out=list(left_out),
                                                     noise=noise)
        floor_note[measured_at] = note
        options = Options(n_samples=n_samples, outline_error_px=float(outline_error))
        r = run(options, size, distortion, fixed, leave_out=list(left_out))

    if measure and distortion == "none":
        r, jack_notes = jackknife(r, points, homs, method, aspect, options, size, fixed, left_out=list(left_out),
                                  noise=noise, noise_ell=noise_ell)
        floor_note += jack_notes
    dup_of = np.asarray(r.checks.duplicate_of)
    notes = (floor_note + view_notes(homs, r.drop_reason, dup_of=dup_of) + model_notes(r, outline_error, fixed)
             + distortion_notes(r, distortion, outline_error) + verdict_notes(r, method, a, outs))
    for msg in notes:
        warnings.warn(msg, stacklevel=2)
    used = tuple(int(i) for i in np.flatnonzero(r.used))
    details = details_for(r, homs, outs, method, a, outline_error, image_size, pp_fixed, fixed)
    cal = Calibration(
        jnp.asarray(r.K), jnp.asarray(r.omega), homologies, _code_item(r.result), jnp.asarray(r.covariance),
        jnp.asarray(r.cost), jnp.asarray(r.view_rms[r.used]), jnp.asarray(r.steps), jnp.asarray(r.v_x[r.used]),
        jnp.asarray(r.l_s[r.used]), method, a, used, details,
        tuple((i, left_out.get(i, why)) for i, why in dropped_views(homs, r.drop_reason, dup_of)),
        tuple(notes), float(r.perspective_px), float(r.perspective_z), float(outline_error),
        jax.tree_util.tree_map(jnp.asarray, r.checks), distortion,
        None if distortion == "none" else jnp.asarray(r.distortion[: {"k1": 1, "k1k2": 2}[distortion]]),
        None if distortion == "none" else jnp.asarray(r.distortion_std[: {"k1": 1, "k1k2": 2}[distortion]]),
        pp_fixed, f_fixed,
    )
    if throw and not cal.success:
        raise CalibrationError(cal.message)
    return cal
