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
from .core._assess import USED, outline_radius, view_verdicts
from .core._checks import CULPRIT_VIEWS, ModelChecks
from .core._calibrate import _intrinsics, calibrate_homologies
from .core._options import Options
from .core._result import RESULTS
from .core._viewfit import ViewHomologies
from ._messages import (_NAMES, _code_item, _left_out_text, code_name, details_for, distortion_notes, dropped_views,
                        model_notes, verdict_notes, view_notes)

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




_check_sizes = check_sizes  # n_samples, n_points: the same rules as fit_homology's (sorjax._checks)


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
            (:attr:`sorjax.core._model.BundleProblem.noise`); the cost, and so ``K``, is
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
    outline_error, per_outline, measure, image_size, pp_fixed, f_fixed = _check_arguments(
        method, aspect_ratio, distortion, n_samples, n_points, outline_error, image_size, principal_point,
        focal_length)
    prepared = _as_outlines(outlines, n_points)
    outs, smoothed = [o for o, _ in prepared], [j for _, j in prepared]
    noise = _outline_noise(outline_noise, outlines, len(outs))
    noise_ell = _outline_noise(outline_noise_ell, outlines, len(outs), "outline_noise_ell", "noise_ell")
    aspect_ratio = _check_views(len(outs), per_outline, pp_fixed, f_fixed, aspect_ratio)
    homologies = _check_homologies(homologies, len(outs))
    if homologies is None:
        homologies = tuple(fit_homology(o, n_samples=n_samples, n_points=n_points) for o in outs)
    homologies = tuple(homologies)
    points = np.stack([np.asarray(o.points, np.float64) for o in outs])
    homs = view_homologies(homologies, n_samples)
    raw = list(outlines) if isinstance(outlines, (list, tuple, np.ndarray)) else []
    outline_error, notes = _grid_floor(raw, smoothed, float(outline_error), measure)
    if measure and per_outline is None:
        per_outline = _own_errors(raw)
    a = None if method in ("IIa",) or (method == "bundle" and aspect_ratio is None) else (
        1.0 if aspect_ratio is None else float(aspect_ratio)
    )
    fixed = None
    if pp_fixed is not None or f_fixed is not None:
        fixed = (math.nan, math.nan if f_fixed is None else f_fixed) + (pp_fixed or (math.nan, math.nan))
    aspect = math.nan if aspect_ratio is None else float(aspect_ratio)
    size = (math.nan, math.nan) if image_size is None else image_size
    run = functools.partial(_run_core, points, homs, method, aspect, image_size=size, distortion=distortion,
                            fixed=fixed, noise=noise, noise_ell=noise_ell)
    if measure:
        r, outline_error, left_out, more = _measured(run, per_outline, float(outline_error), n_samples)
        notes += more
    else:
        r, left_out = run(Options(n_samples=n_samples, outline_error_px=outline_error)), {}
    dup_of = np.asarray(r.checks.duplicate_of)
    notes = (notes + view_notes(homs, r.drop_reason, dup_of=dup_of) + model_notes(r, outline_error, fixed)
             + distortion_notes(r, distortion, outline_error) + verdict_notes(r, method, a, outs))
    for msg in notes:
        warnings.warn(msg, stacklevel=2)
    details = details_for(r, homs, outs, method, a, outline_error, image_size, pp_fixed, fixed)
    cal = _calibration(r, homologies, method, a, details, left_out, notes, outline_error, distortion, pp_fixed,
                       f_fixed, tuple(dropped_views(homs, r.drop_reason, dup_of)))
    if throw and not cal.success:
        raise CalibrationError(cal.message)
    return cal


def _check_arguments(method, aspect_ratio, distortion, n_samples, n_points, outline_error, image_size,
                     principal_point, focal_length):
    """:func:`calibrate`'s arguments checked before any outline is read: ``(outline_error
    px, per-outline errors or None, measured?, image_size, principal point fixed, focal
    length fixed)``; a ValueError that says what is wrong otherwise."""
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
    return outline_error, per_outline, measure, image_size, pp_fixed, f_fixed


def _check_views(n: int, per_outline, pp_fixed, f_fixed, aspect_ratio):
    """The number of outlines ``n`` checked against what the calibration needs (a
    ValueError that says what to add); returns the aspect ratio to impose (1 for one
    view with a fixed principal point, or a fixed focal length, unless given)."""
    if per_outline is not None and len(per_outline) != n:
        raise ValueError(f"outline_error: got {len(per_outline)} per-outline errors for {n} outlines; give one "
                         "number (px) per outline, in the same order, or one number for all, or 'measured'.")
    if n == 1 and pp_fixed is not None:
        aspect_ratio = 1.0 if aspect_ratio is None else aspect_ratio  # the single-view case: square pixels
    if f_fixed is not None and aspect_ratio is None:
        aspect_ratio = 1.0  # a fixed focal length fixes fu = aspect fv: square pixels unless told
    if n < (1 if pp_fixed is not None else 2):
        raise ValueError(
            f"calibration needs at least two outlines (views) of surfaces of revolution; got "
            f"{n}. One outline gives only its own axis l_s and vanishing point v_x "
            "(use sorjax.fit_homology): two constraints on the four intrinsics (fu, fv, u0, v0), "
            "which leaves the camera undetermined. Add an outline from another view (the object "
            "moved or tilted, or another object), or fix the principal point (principal_point=(cx, cy) or "
            "'centre'; the command line's --principal-point CX CY or --centre-principal-point): one view then "
            "gives the focal length."
        )
    return aspect_ratio


def _grid_floor(raw, smoothed, outline_error: float, measure: bool) -> tuple[float, list[str]]:
    """The outline error raised to what outlines on a pixel grid carry at least (their
    quantisation, a mask's staircase, a pixel trace: :func:`implied_outline_error`;
    ``smoothed``: per outline, what :func:`sorjax._outline._as_outlines` smoothed away),
    and the notes that say so: ``(outline_error px, notes)``."""
    implied = [implied_outline_error(o) for o in raw] or [(0.0, "")]
    floor_px, floor_kind = max(implied, key=lambda t: t[0])
    traces = [i for i, t in enumerate(implied) if t[1] == "pixel trace"]
    notes = [f"outline{'s' if len(traces) > 1 else ''} {', '.join(map(str, traces))}: {PIXEL_TRACE_NOTE}"
             ] if traces else []
    jagged = [(i, j) for i, j in enumerate(smoothed) if j]
    if jagged:
        jit = [j[0] for _, j in jagged]
        notes.append(f"outline{'s' if len(jagged) > 1 else ''} {', '.join(str(i) for i, _ in jagged)}: "
                     + jagged_note(min(jit), max(j[1] for _, j in jagged), max(jit)))
    if floor_px > outline_error:
        which = [i for i, t in enumerate(implied) if t[0] == floor_px]
        why = {"staircase": "an unsmoothed staircase along or between pixels (up to half a pixel off the edge)",
               "pixel trace": "a binary mask's boundary pixels (its outline is as accurate as a binary mask's, "
                              f"about {BINARY_MASK_PX:g} px)",
               }.get(floor_kind, "rounded to whole or half pixels (1/sqrt(12) px of rounding error per coordinate)")
        notes.append(
            f"outline{'s' if len(which) > 1 else ''} {', '.join(map(str, which))}: the coordinates are {why}; "
            f"the outline error is taken as {floor_px:.2g} px instead of the {'default' if measure else 'declared'} "
            f"{outline_error:g} px. Sub-pixel outlines (sorjax.outlines_from_mask on a soft mask, or the 0.5 "
            "level of a blurred mask) are more accurate.")
        outline_error = floor_px
    return outline_error, notes


def _measured(run, per_outline, floor_px: float, n_samples: int):
    """The calibration of outlines of measured quality (``outline_error="measured"``):
    the outline error measured (:func:`measured_outline_error`, at least ``floor_px``),
    a view the consistency check blames almost alone left out and the rest calibrated
    again (:func:`dominant_view`, ``Options.measured_leave_out`` views at most), then the
    leave-one-view-out check (:func:`jackknife`; pinhole only).  ``run(options,
    leave_out=...)``: :func:`_run_core` with everything else bound (a
    ``functools.partial``: the outlines, homologies, method, aspect ratio, image size,
    lens model, fixed intrinsics and noise floors).  Returns ``(r, outline_error,
    left_out {view: why}, notes)``."""
    points, homs, method, aspect = run.args
    kw = run.keywords

    def measured(left_out):
        return measured_outline_error(homs, points, per_outline, floor=floor_px, options=Options(n_samples=n_samples),
                                      left_out=list(left_out), noise=kw["noise"])

    outline_error, note = measured({})
    notes = [note]
    options = Options(n_samples=n_samples, outline_error_px=float(outline_error))
    r = run(options)
    left_out: dict[int, str] = {}
    while len(left_out) < int(options.measured_leave_out):
        dom = dominant_view(r, options)
        if dom is None:
            break
        j, share = dom
        notes.append(_left_out_text(r, j, share))
        left_out[j] = f"inconsistent with the other views ({100 * share:.0f} % of the consistency score)"
        outline_error, notes[0] = measured(left_out)
        options = Options(n_samples=n_samples, outline_error_px=float(outline_error))
        r = run(options, leave_out=list(left_out))
    if kw["distortion"] == "none":
        r, jack_notes = jackknife(r, points, homs, method, aspect, options, kw["image_size"], kw["fixed"],
                                  left_out=list(left_out), noise=kw["noise"], noise_ell=kw["noise_ell"])
        notes += jack_notes
    return r, outline_error, left_out, notes


def _calibration(r, homologies, method: str, a, details, left_out, notes, outline_error, distortion: str, pp_fixed,
                 f_fixed, dropped) -> Calibration:
    """The :class:`Calibration` of the core's result ``r`` (numpy) and its texts."""
    n = {"none": 0, "k1": 1, "k1k2": 2}[distortion]
    return Calibration(
        jnp.asarray(r.K), jnp.asarray(r.omega), homologies, _code_item(r.result), jnp.asarray(r.covariance),
        jnp.asarray(r.cost), jnp.asarray(r.view_rms[r.used]), jnp.asarray(r.steps), jnp.asarray(r.v_x[r.used]),
        jnp.asarray(r.l_s[r.used]), method, a, tuple(int(i) for i in np.flatnonzero(r.used)), details,
        tuple((i, left_out.get(i, why)) for i, why in dropped), tuple(notes), float(r.perspective_px),
        float(r.perspective_z), float(outline_error), jax.tree_util.tree_map(jnp.asarray, r.checks), distortion,
        None if n == 0 else jnp.asarray(r.distortion[:n]), None if n == 0 else jnp.asarray(r.distortion_std[:n]),
        pp_fixed, f_fixed,
    )
