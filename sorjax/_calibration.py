"""From outlines to intrinsics: the :class:`Calibration` result and :func:`calibrate`.

Data flow (the paper's): outlines -> per-view harmonic homologies (eq. 20) ->
Method I / IIa / IIb in normalised coordinates -> K in pixels.
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import optimistix as optx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._camera import normalising_transform, transform_points
from ._homology import DEFAULT_SAMPLES, Homology, fit_homology
from ._bundle import bundle_estimate, bundle_seeds, linearised_covariance
from ._linear import linear_estimate, linear_in_pixels
from .core._options import Options
from ._outline import DEFAULT_POINTS, as_outlines
from .core._result import RESULTS

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


def _check_method(method: str, aspect_ratio):
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}; got {method!r}.")
    if aspect_ratio is not None:
        if not isinstance(aspect_ratio, (int, float, np.floating, np.integer)) or not (
            math.isfinite(aspect_ratio) and aspect_ratio > 0
        ):
            raise ValueError(f"aspect_ratio must be a positive finite number (fu / fv); got {aspect_ratio!r}.")
        if method == "IIa":
            raise ValueError(
                "method 'IIa' estimates the aspect ratio itself; to impose a known aspect "
                "ratio use method='IIb' (or 'I') with aspect_ratio=..."
            )


def _linear_once(homologies, method: str, T: np.ndarray, a: float, weights=None):
    TA = T @ np.diag([1.0 / a, 1.0, 1.0])
    v, l = _stacked_homologies(homologies)
    K, omega, ok = linear_in_pixels(v, l, TA, weights, method=method)
    return K, omega, _linear_code(ok, method)


def _stacked_homologies(homologies):
    return (np.stack([np.asarray(h.v_x) for h in homologies]), np.stack([np.asarray(h.l_s) for h in homologies]))


def _linear_code(ok, method: str):
    if bool(ok):
        return RESULTS.successful
    return RESULTS.degenerate if method == "I" else RESULTS.not_positive_definite


def conditioning_from_K(K, a: float = 1.0) -> np.ndarray:
    """The isotropic normalisation ``T = K'^-1`` for an estimate ``K`` (``K' = A K`` with
    the aspect-ratio map ``A = diag(1/a, 1, 1)``): in those coordinates omega is close
    to the identity, the best conditioning for Method II's linear system."""
    K = np.asarray(K)
    s, cx, cy = K[1, 1], K[0, 2] / a, K[1, 2]
    return np.array([[1 / s, 0, -cx / s], [0, 1 / s, -cy / s], [0, 0, 1.0]])


def linear_calibration(homologies, method: str, T: np.ndarray, aspect_ratio=None, weights=None):
    """Run a linear method on fitted homologies (pixels).  Returns ``(K, omega, code)``.

    ``T`` is the isotropic normalising similarity of the pixels (e.g.
    :func:`sorjax._camera.normalising_transform` of all outline points).  Methods
    IIa/IIb are solved twice: once in ``T``'s coordinates, then again in coordinates
    normalised by that first estimate (or by Method I's when the first is not
    positive definite), where omega is near the identity and the algebraic error is
    balanced between its entries (the same conditioning idea as Hartley's
    normalisation; it lowered IIb's focal error by about a quarter on the two-sphere
    scene at sigma = 2 px)."""
    a = 1.0 if aspect_ratio is None else float(aspect_ratio)
    v, l = _stacked_homologies(homologies)
    # the pure core (sorjax._linear.linear_estimate); host conversion only here
    K, omega, ok = linear_estimate(v, l, np.ones(len(v), bool), np.asarray(T), a, method=method, weights=weights)
    return K, omega, _linear_code(ok, method)


def _bundle_calibration(outs, homologies, T, aspect_ratio, n_samples):
    """Seed the 2V+4 (or 2V+3) bundle with every linear method that succeeds (IIa,
    IIb and I; with a known aspect ratio their estimates are projected onto it): one
    linear seed can be far off when a view is weak, so :func:`fit_bundle` screens
    them all and polishes the best.  With no positive-definite linear seed, a spread
    of plausible cameras.

    Returns ``(K, omega, code, cov, cost, view_rms, steps, v_x, l_s, s_px, evidence)``;
    ``K`` is the raw estimate (not yet masked on failure), ``s_px`` the residual
    standard error, ``evidence = (delta_px2, n)`` the cost (px^2) by which the best
    camera with no perspective fits worse (:func:`sorjax._bundle.orthographic_cost`)
    and the number of samples it is summed over."""
    v, l = _stacked_homologies(homologies)
    used = np.ones(len(outs), bool)
    aspect = np.nan if aspect_ratio is None else float(aspect_ratio)
    # the pure core (sorjax._bundle): seeds, fit, covariance, evidence in one program each
    seeds, seed_ok = bundle_seeds(v, l, used, np.asarray(T), aspect)
    out = bundle_estimate(_normalised_points(outs, T), used, _inlier_mask(homologies, n_samples),
                          _axes_normalised(homologies, T), seeds, seed_ok, aspect, np.asarray(T),
                          Options(n_samples=n_samples))
    code = RESULTS.successful if bool(out.ok) else RESULTS.not_converged
    evidence = (float(out.evidence), float(out.n))
    return (out.K, out.omega, code, out.cov, out.cost, out.view_rms, int(out.steps), out.v_x, out.l_s,
            float(np.sqrt(out.s2)), evidence)


def _linearised_covariance(outs, homologies, K, T, aspect_ratio, n_samples):
    """Covariance of ``(fu, fv, u0, v0)`` per px^2 of symmetry residual, for a linear
    method's estimate ``K``: the bundle's linearisation (:func:`sorjax._bundle.covariance`)
    at ``K`` with the per-view fits' axes.  It measures how well these views
    determine the intrinsics whatever the estimator (infinite where they don't)."""
    cov = linearised_covariance(_normalised_points(outs, T), np.ones(len(outs), bool), _inlier_mask(homologies, n_samples),
                                _axes_normalised(homologies, T), np.asarray(K), np.asarray(T),
                                np.nan if aspect_ratio is None else float(aspect_ratio), n_samples)
    return np.asarray(cov)


def _perspective(evidence, s_px: float, outline_error: float):
    """``(ok, g_px, z)``: the evidence for perspective ``(delta_px2, n)`` as an RMS per
    sample ``g_px`` and a z-score ``sqrt(delta) / s_px``, and whether it passes the gate
    (``z >= PERSPECTIVE_Z`` and ``g_px >= PERSPECTIVE_FACTOR * outline_error``)."""
    delta, n = evidence
    g = math.sqrt(max(delta, 0.0) / max(n, 1.0))
    z = math.sqrt(max(delta, 0.0)) / max(s_px, 1e-300)
    return bool(z >= PERSPECTIVE_Z and g >= PERSPECTIVE_FACTOR * float(outline_error)), g, z


def _inlier_mask(homologies, n_samples: int) -> np.ndarray:
    """(V, N) 0/1: the samples each view's robust fit kept (all where it gives none).
    Sample ``k`` is at the same curve parameter in the per-view fit and in the bundle
    (both take ``n_samples`` points of the same spline), so the masks carry over."""
    rows = []
    for h in homologies:
        m = None if h.inliers is None else np.asarray(h.inliers, dtype=np.float64)
        rows.append(m if m is not None and m.shape == (n_samples,) else np.ones(n_samples))
    return np.stack(rows)


def _normalised_points(outs, T) -> np.ndarray:
    """(V, M, 2) outline points in the coordinates of the similarity ``T``."""
    return transform_points(T, np.stack([np.asarray(o.points) for o in outs]))


def _axes_normalised(homologies, T) -> np.ndarray:
    """(V, 3) per-view axes ``l_s`` in the coordinates of ``T`` (lines map by ``T^-T``)."""
    return np.stack([np.linalg.solve(T.T, np.asarray(h.l_s)) for h in homologies])


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
ASYMMETRY_PX = 2.0
ASYMMETRY_REL = 0.01
WARN_ASYMMETRY_PX = 1.0
# The robust per-view fit trims samples with no mirror image (a handle, a shadow); a
# view that needs more than MAX_TRIMMED of its samples trimmed is not a surface of
# revolution, and from NOTE_TRIMMED on the trimming is reported.  Measured: a smooth
# 8 px handle over 12 % of a vase's outline trims 14 % (the handle and its mirror
# image); GrabCut outlines of ycb-video cans that leaked into the background trimmed
# 15-22 % and, kept, gave a confident wrong K: hence 20 %, and the symmetry test on the
# untrimmed residual.
MAX_TRIMMED = 0.2
NOTE_TRIMMED = 0.02
# An intrinsic is "not determined" when its standard deviation (the covariance at the
# estimate, scaled by the residual -- at least RESIDUAL_FLOOR_PX when every v_x is at
# infinity) is infinite or above UNDETERMINED times the focal length (for the
# principal point: times the outlines' RMS radius when the focal length itself is not
# determined): a 3-sigma interval reaching zero.
UNDETERMINED = 1.0 / 3.0
# A focal length below MIN_FOCAL_FRACTION of the extent of the outlines (their
# bounding box's larger side, px) would put them across more than 90 degrees of view,
# where a lens without distortion (sorjax's model) is implausible: a collapsed
# estimate, never "determined" -- nor is the principal point estimated with it.  Seen
# on real photographs with weak perspective and imperfect outlines: f fell to 1..25 px,
# and to 168 px (nocs-real275, true 590) and 177 px (ycb-video, true 1067) with a std
# of 13-15 px and the principal point 7 to 20 std off.
MIN_FOCAL_FRACTION = 0.5
# With the image size known (``calibrate(image_size=...)``), an estimate is also
# implausible when it gives the image a field of view above MAX_FOV_DEG across (wider
# lenses are fisheyes, far from a pinhole without distortion) or puts the principal
# point outside the image.  (ycb-video, true f 1067 px: f 177 +- 13 px, a 122 deg view
# of its 640 px width -- caught only by this bound, narrowly.)
MAX_FOV_DEG = 120.0
# Weak geometry: warn when the relative standard deviation of a focal length exceeds
# WEAK_REL_STD, the covariance scaled by the residual but at least RESIDUAL_FLOOR_PX
# (about the accuracy of good sub-pixel outlines), so that a configuration that only
# noise-free outlines could calibrate is flagged too.
WEAK_REL_STD = 0.05
RESIDUAL_FLOOR_PX = 0.1
# Perspective evidence (bundle).  Only perspective fixes the focal length, and under
# weak perspective an outline shows very little of it (a 5 % focal error changes the
# symmetry of typical outlines by about 0.25 px).  Systematic errors of the outlines
# (segmentation bias, lens distortion, an object that is not quite a surface of
# revolution) hide from the symmetry residual but can fake or cancel that much, and the
# bundle's covariance, a linearisation at its own estimate, can then be confident far
# from the truth.  So the focal length counts as determined only when the best camera
# with no perspective (:func:`sorjax._bundle.orthographic_cost`) fits the outlines worse
# by a cost delta with sqrt(delta / s^2) >= PERSPECTIVE_Z (the noise cannot explain it)
# and sqrt(delta / n) >= PERSPECTIVE_FACTOR * outline_error px (nor can a systematic
# error of the outlines of `outline_error` px RMS: a fully aligned one changes the cost
# by n outline_error^2).  Measured: the real photographs of nvlabs-6dof-graspnet
# (experiments/realdata.py; approximate masks) show 0.20 to 0.22 px of perspective and
# gave f 271 +- 16 px for a true 616 without this gate; the two-sphere scene shows 0.7
# to 0.8 px at f = 700 and 0.14 to 0.28 px at f = 1400 (1 to 2 px of noise); rendered
# objects near the image centre at f = 1250 to 1500 px 0.23 to 0.24 px.
OUTLINE_ERROR_PX = 0.1
PERSPECTIVE_Z = 3.0
PERSPECTIVE_FACTOR = 3.0
# Advice thresholds (which extra view would help).
PARALLEL_AXES_DEG = 10.0
NEAR_AXIS_DEG = 10.0
SMALL_OUTLINE_RAD = 0.15
_NAMES = ("fu", "fv", "u0", "v0")


def _outline_radius(outline) -> float:
    p = np.asarray(outline.points)
    return float(np.sqrt(np.mean(np.sum((p - p.mean(0)) ** 2, axis=1))))


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


def _ls_intersection(ls: np.ndarray):
    """Least-squares intersection of lines (V, 3) (``a^2 + b^2 = 1``): ``(point, cov,
    spread_deg)``; ``cov`` is NaN with fewer than 3 lines, ``point`` NaN when they
    are (nearly) parallel."""
    A, b = ls[:, :2], -ls[:, 2]
    N = A.T @ A
    spread = _axis_spread_deg(ls)
    if spread < 1.0:
        return np.full(2, np.nan), np.full((2, 2), np.nan), spread
    x = np.linalg.solve(N, A.T @ b)
    if len(ls) >= 3:
        s2 = float(np.sum((A @ x - b) ** 2)) / (len(ls) - 2)
        cov = s2 * np.linalg.inv(N)
    else:
        cov = np.full((2, 2), np.nan)
    return x, cov, spread


def _fmt_std(x, sd):
    """``x +- sd`` in px: one decimal, or 3 significant digits beyond 1e6 px (a focal
    length that ran off towards the no-perspective limit)."""
    xs = f"{x:.1f}" if abs(x) < 1e6 else f"{x:.3g}"
    return f"{xs} +- {sd:.2g}" if np.isfinite(sd) else f"{xs} +- inf"


def _assess(K, cov_unit, s_px, outs, vx, ls, free_aspect: bool, used=None, floor_verdict: bool = False,
            perspective_ok: bool = True, image_size=None):
    """Which intrinsics the views determine.  Returns ``(determined (4,) bool, std (4,),
    weak or None, advice)`` for the raw estimate ``K`` (pixels), the covariance per
    px^2 of residual ``cov_unit`` and the residual standard error ``s_px``.  ``std``
    and the verdicts are for ``s_px`` -- or, with ``floor_verdict`` (every ``v_x`` at
    infinity, where theory says the focal length is free), for
    ``max(s_px, RESIDUAL_FLOOR_PX)``, so that the estimate must fix the focal length
    robustly to override that.  ``weak`` is the relative std of a focal length at
    ``max(s_px, RESIDUAL_FLOOR_PX)`` when above ``WEAK_REL_STD``.  Without enough
    evidence for perspective (``perspective_ok`` False), with a collapsed focal length
    (below ``MIN_FOCAL_FRACTION`` of the outlines' extent) or with the principal point
    outside the image or a field of view above ``MAX_FOV_DEG`` (``image_size = (width,
    height)``, when given) nothing is determined: such an estimate rests on systematic
    errors of the outlines, not on their perspective."""
    K = np.asarray(K)
    est = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    var = np.diag(np.asarray(cov_unit))
    s_floor = max(s_px, RESIDUAL_FLOOR_PX)
    std = np.where(np.isfinite(var), np.sqrt(np.abs(var)), np.inf) * s_px
    std_floor = std / max(s_px, 1e-300) * s_floor
    judged = std_floor if floor_verdict else std
    radius = np.sqrt(np.mean([_outline_radius(o) ** 2 for o in outs]))
    plausible = not _implausible(est, outs, image_size)
    focal_ok = np.isfinite(std[:2]) & (judged[:2] <= UNDETERMINED * np.abs(est[:2]))
    ref = np.sqrt(abs(est[0] * est[1])) if focal_ok.all() else radius
    pp_ok = np.isfinite(std[2:]) & (judged[2:] <= UNDETERMINED * ref)
    determined = np.concatenate([focal_ok, pp_ok]) & plausible & perspective_ok
    weak = None
    rel_floor = std_floor[:2] / np.abs(est[:2])
    aspect_weak = free_aspect and not determined.all()
    if determined.all() and np.max(rel_floor) > WEAK_REL_STD:
        weak = float(np.max(rel_floor))
        if free_aspect:  # relative std of fu / fv
            c = np.asarray(cov_unit)
            q = c[0, 0] / est[0] ** 2 + c[1, 1] / est[1] ** 2 - 2 * c[0, 1] / (est[0] * est[1])
            aspect_weak = bool(np.sqrt(max(q, 0.0)) * s_floor > WEAK_REL_STD)
    advice = _advice(K, vx, ls, outs, free_aspect, aspect_weak, used)
    return determined, std, weak, advice


def _implausible(est, outs, image_size=None) -> str:
    """Why the estimate ``(fu, fv, u0, v0)`` (px) is implausible for a camera without
    lens distortion that took these outlines (empty when it is not)."""
    pts = np.concatenate([np.asarray(getattr(o, "points", o)).reshape(-1, 2) for o in outs])
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    f = float(np.min(np.abs(est[:2])))
    if f < MIN_FOCAL_FRACTION * extent:
        deg = 2.0 * math.degrees(math.atan(extent / (2.0 * max(f, 1e-300))))
        return (
            f"the estimate (f = {f:.0f} px) would put outlines {extent:.0f} px apart across {deg:.0f} deg of "
            "view, which a lens without distortion does not do: the outlines' errors, not their "
            "perspective, made it"
        )
    if image_size is not None:
        w, h = image_size
        fov = [2.0 * math.degrees(math.atan(n / (2.0 * max(abs(x), 1e-300)))) for n, x in ((w, est[0]), (h, est[1]))]
        if max(fov) > MAX_FOV_DEG:
            return (
                f"the estimate (fu = {est[0]:.0f}, fv = {est[1]:.0f} px) gives the {w}x{h} image a field of view of "
                f"{fov[0]:.0f} x {fov[1]:.0f} deg, beyond what lenses without distortion reach "
                f"({MAX_FOV_DEG:g} deg): the outlines' errors, not their perspective, made it"
            )
        if not (-0.5 <= est[2] <= w - 0.5 and -0.5 <= est[3] <= h - 0.5):
            return (
                f"the estimated principal point ({est[2]:.0f}, {est[3]:.0f}) lies outside the {w}x{h} image: "
                "the outlines' errors, not their perspective, made it"
            )
    return ""


def _nan_calibration(homologies, result, method, a, used, details, dropped, notes, K=None, cov=None, rms=None,
                     vx=None, ls=None):
    nan3, nan4 = jnp.full((3, 3), jnp.nan), jnp.full((4, 4), jnp.nan)
    return Calibration(
        nan3 if K is None else jnp.asarray(K), nan3, homologies, result, nan4 if cov is None else jnp.asarray(cov),
        jnp.asarray(jnp.nan), jnp.zeros((0,)) if rms is None else jnp.asarray(rms), jnp.asarray(0),
        jnp.zeros((0, 3)) if vx is None else jnp.asarray(vx), jnp.zeros((0, 3)) if ls is None else jnp.asarray(ls),
        method, a, tuple(used), details, tuple(dropped), tuple(notes),
    )


def _check_sizes(n_samples, n_points):
    for name, val, lo in (("n_samples", n_samples, 10), ("n_points", n_points, 64)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
            raise ValueError(f"{name} must be an integer >= {lo}; got {val!r}.")
    if n_samples > n_points:
        raise ValueError(f"n_samples ({n_samples}) must not exceed n_points ({n_points}).")


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


def calibrate(
    outlines,
    method: str = "bundle",
    aspect_ratio: float | None = None,
    *,
    n_samples: int = DEFAULT_SAMPLES,
    n_points: int = DEFAULT_POINTS,
    homologies=None,
    outline_error: float = OUTLINE_ERROR_PX,
    image_size: tuple[int, int] | None = None,
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
            outlines with only random noise (synthetic studies).
        image_size: ``(width, height)`` of the images in px, when known: an estimate
            with the principal point outside the image, or a field of view above
            ``MAX_FOV_DEG`` (120 deg), is then reported as not determined (the outlines'
            errors made it, not their perspective).
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
      intersection of the ``l_s`` in ``K[:2, 2]`` and NaN focal lengths;
    * the bundle's focal length is not determined when the outlines show too little
      perspective (``outline_error``): the best camera with no perspective must fit
      them clearly worse, beyond their noise and their systematic error;
    * a successful calibration whose focal length has a relative standard deviation
      above ``WEAK_REL_STD`` (5 %; residual taken as at least 0.1 px) gives a warning
      saying what kind of extra view would help.
    """
    _check_method(method, aspect_ratio)
    _check_sizes(n_samples, n_points)
    if isinstance(outline_error, bool) or not isinstance(outline_error, (int, float, np.integer, np.floating)) or not (
        math.isfinite(outline_error) and outline_error >= 0
    ):
        raise ValueError(f"outline_error must be a finite number of pixels >= 0; got {outline_error!r}.")
    if image_size is not None:
        try:
            iw, ih = (int(x) for x in image_size)
            if iw <= 0 or ih <= 0 or (iw, ih) != tuple(image_size):
                raise ValueError
        except (TypeError, ValueError):
            raise ValueError(f"image_size must be (width, height) in pixels, two positive integers; got "
                             f"{image_size!r}.") from None
        image_size = (iw, ih)
    outs = as_outlines(outlines, n_points)
    if len(outs) < 2:
        raise ValueError(
            f"calibration needs at least two outlines (views) of surfaces of revolution; got "
            f"{len(outs)}. One outline gives only its own axis l_s and vanishing point v_x "
            "(use sorjax.fit_homology): two constraints on the four intrinsics (fu, fv, u0, v0), "
            "which leaves the camera undetermined. Add an outline from another view (the object "
            "moved or tilted, or another object)."
        )
    homologies = _check_homologies(homologies, len(outs))
    notes: list[str] = []

    def note(msg):
        notes.append(msg)
        warnings.warn(msg, stacklevel=3)

    if homologies is None:
        homologies = tuple(fit_homology(o, n_samples=n_samples, n_points=n_points) for o in outs)
    for i, h in enumerate(homologies):
        if not bool(h.converged):
            note(f"view {i}: the homology fit did not converge (rms {float(h.rms):.3g} px).")
    used, dropped = [], []
    for i, h in enumerate(homologies):
        rms, radius = float(h.rms), _outline_radius(outs[i])
        if h.rms_untrimmed is not None:  # symmetric at all? judged before any trimming
            rms = max(rms, float(h.rms_untrimmed))
        if h.is_conic:
            note(
                f"view {i}: the outline is a conic to within {float(h.conic_rms):.2g} px (its symmetry "
                f"residual is {rms:.2g} px), like a sphere or a bowl seen from above showing "
                "only its rim: infinitely many homologies fit it, so it carries no calibration "
                "information (paper, Section 6). Dropped; use views where the body's profile shows."
            )
            dropped.append((i, "conic outline"))
        elif h.trimmed > MAX_TRIMMED:
            note(
                f"view {i}: the outline is not symmetric: {100 * h.trimmed:.0f} % of its samples have no "
                f"mirror image under the best harmonic homology (more than {100 * MAX_TRIMMED:.0f} % "
                "cannot be a handle or a shadow on a surface of revolution). Dropped; check the "
                "segmentation of this view."
            )
            dropped.append((i, f"not symmetric ({100 * h.trimmed:.0f} % of the outline trimmed)"))
        elif not np.isfinite(rms) or (rms > ASYMMETRY_PX and rms > ASYMMETRY_REL * radius):
            note(
                f"view {i}: the outline is not symmetric: its best harmonic homology leaves an RMS "
                f"symmetry residual of {rms:.3g} px (a surface of revolution with up to 2 px of noise "
                f"stays below about {ASYMMETRY_PX:g} px), so it is not the outline of a surface of "
                "revolution (or it is broken, occluded or merged with something else). Dropped; "
                "check the segmentation of this view."
            )
            dropped.append((i, f"not symmetric (rms {rms:.3g} px)"))
        else:
            if h.trimmed >= NOTE_TRIMMED:
                note(
                    f"view {i}: {100 * h.trimmed:.0f} % of the outline's samples have no mirror image (a "
                    "handle, a shadow, an occlusion?) and were left out of the fit."
                )
            if rms > WARN_ASYMMETRY_PX:
                note(
                    f"view {i}: high symmetry residual ({rms:.3g} px): a noisy outline, or not quite a "
                    "surface of revolution; kept. Check its segmentation."
                )
            used.append(i)
    homologies = tuple(homologies)
    a = None if method in ("IIa",) or (method == "bundle" and aspect_ratio is None) else (
        1.0 if aspect_ratio is None else float(aspect_ratio)
    )
    free_aspect = a is None

    def finish(cal):
        if throw and not cal.success:
            raise CalibrationError(cal.message)
        return cal

    if len(used) < 2:
        why = "; ".join(f"view {i}: {r}" for i, r in dropped)
        details = (
            f"{len(outs)} views given, {len(used)} usable ({why}). A single view gives only two "
            "constraints on the four intrinsics."
        )
        return finish(_nan_calibration(homologies, RESULTS.too_few_views, method, a, used, details, dropped, notes))
    outs_u = [outs[i] for i in used]
    homs_u = tuple(homologies[i] for i in used)
    rms_u = jnp.stack([h.rms for h in homs_u])
    vx_h = np.stack([np.asarray(h.v_x) for h in homs_u])
    ls_h = np.stack([np.asarray(h.l_s) for h in homs_u])

    def principal_point_only():
        """Every v_x at infinity and the estimate cannot fix the focal length: the
        principal point is where the imaged axes meet (paper, Section 6)."""
        pp, cov_pp, spread = _ls_intersection(ls_h)
        vs = ", ".join(str(i) for i in used)
        if not np.all(np.isfinite(pp)):
            details = (
                f"Every view's v_x is at infinity (views {vs}) and their imaged axes are parallel "
                f"(within {spread:.2g} deg), so not even the principal point is determined. Add a view "
                "with the object away from the image centre."
            )
            return finish(_nan_calibration(homologies, RESULTS.degenerate, method, a, used, details, dropped, notes,
                                           rms=rms_u, vx=vx_h, ls=ls_h))
        K = np.array([[np.nan, 0.0, pp[0]], [0.0, np.nan, pp[1]], [0.0, 0.0, 1.0]])
        cov = np.full((4, 4), np.nan)
        cov[0, 0] = cov[1, 1] = np.inf
        cov[2:, 2:] = cov_pp
        sd = np.sqrt(np.diag(cov_pp))
        details = (
            f"Every view's v_x is at infinity (views {vs}): the imaged axes meet at the principal "
            f"point ({_fmt_std(pp[0], sd[0])}, {_fmt_std(pp[1], sd[1])}) px; the focal length is not "
            "determined."
        )
        return finish(_nan_calibration(homologies, RESULTS.only_principal_point, method, a, used, details, dropped,
                                       notes, K=K, cov=cov, rms=rms_u, vx=vx_h, ls=ls_h))

    # every v_x at infinity (within its uncertainty): only the principal point is
    # estimable, unless the joint estimate below does determine the focal length
    all_at_infinity = all(h.v_x_at_infinity for h in homs_u)
    T = normalising_transform(np.concatenate([np.asarray(o.points) for o in outs_u]))
    perspective_ok, g_px, z_persp = True, math.nan, math.nan
    if method == "bundle":
        K, omega, code, cov, cost, view_rms, steps, vx, ls, s_px, evidence = _bundle_calibration(
            outs_u, homs_u, T, aspect_ratio, n_samples
        )
        cov_unit = np.asarray(cov) / max(s_px, 1e-300) ** 2
        perspective_ok, g_px, z_persp = _perspective(evidence, s_px, outline_error)
    else:
        K, omega, code = linear_calibration(homs_u, method, T, aspect_ratio)
        cov = jnp.full((4, 4), jnp.nan)
        cost, view_rms, steps, vx, ls = jnp.asarray(jnp.nan), rms_u, jnp.asarray(0), jnp.asarray(vx_h), jnp.asarray(ls_h)
        s_px = float(np.sqrt(np.mean(np.asarray(rms_u) ** 2)))
        cov_unit = None
        if bool(code == RESULTS.successful) and np.all(np.isfinite(np.asarray(K))):
            cov_unit = _linearised_covariance(outs_u, homs_u, K, T, a, n_samples)

    details = ""
    K_np = np.asarray(K)
    assessed = cov_unit is not None and np.all(np.isfinite(K_np)) and K_np[0, 0] > 0 and K_np[1, 1] > 0
    if assessed:
        determined, std, weak, advice = _assess(
            K_np, cov_unit, s_px, outs_u, np.asarray(vx), np.asarray(ls), free_aspect, used, all_at_infinity,
            perspective_ok, image_size,
        )
    if all_at_infinity and (not bool(code == RESULTS.successful) or not assessed or not determined[:2].all()):
        return principal_point_only()
    if assessed:
        est = [K_np[0, 0], K_np[1, 1], K_np[0, 2], K_np[1, 2]]
        if not determined.all():
            code = RESULTS.only_principal_point if (not determined[:2].any() and determined[2:].all()) else RESULTS.degenerate
            det = ", ".join(f"{n} = {_fmt_std(x, sd)} px" for n, x, sd, d in zip(_NAMES, est, std, determined) if d)
            und = ", ".join(f"{n} ({_fmt_std(x, sd)} px)" for n, x, sd, d in zip(_NAMES, est, std, determined) if not d)
            why = _implausible(np.array(est), outs_u, image_size)
            why = f" Not a plausible camera: {why}." if why else ""
            if not perspective_ok:
                why += (
                    f" The outlines show too little perspective to fix the focal length: the best camera with "
                    f"no perspective fits them only {g_px:.2g} px RMS worse (z = {z_persp:.2g}), which "
                    + (f"noise alone could do (needs z >= {PERSPECTIVE_Z:g})" if z_persp < PERSPECTIVE_Z else
                       f"a systematic outline error of {float(outline_error):g} px (outline_error) could do "
                       f"(needs >= {PERSPECTIVE_FACTOR * float(outline_error):.2g} px)")
                    + "."
                )
            details = (
                f"Not determined by these views: {und}"
                + (f"; determined: {det}" if det else "")
                + "." + why + " To fix it: " + "; ".join(advice) + "."
            )
            mask = np.array([[not determined[0], False, not determined[2]], [False, not determined[1], not determined[3]],
                             [False, False, False]])
            K = jnp.asarray(np.where(mask, np.nan, K_np))
        elif weak is not None and bool(code == RESULTS.successful):
            note(
                f"weak geometry: the focal length is uncertain by {100 * weak:.3g} % (1 sigma, for a "
                f"symmetry residual of {max(s_px, RESIDUAL_FLOOR_PX):.2g} px): " + "; ".join(advice) + "."
            )
    if not bool(code == RESULTS.successful):
        omega = jnp.full((3, 3), jnp.nan)
        if not details:  # no analysis of what is determined: nothing is reported
            K = jnp.full((3, 3), jnp.nan)
    cal = Calibration(
        K, omega, homologies, code, jnp.asarray(cov), jnp.asarray(cost), view_rms, jnp.asarray(steps), jnp.asarray(vx),
        jnp.asarray(ls), method, a, tuple(used), details, tuple(dropped), tuple(notes), float(g_px), float(z_persp),
    )
    return finish(cal)
