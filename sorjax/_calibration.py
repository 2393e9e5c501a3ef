"""From outlines to intrinsics: the friendly entry point :func:`calibrate` and its
:class:`Calibration`.

This is the boundary: plain-Python validation before anything is traced, then the
functional core (:mod:`sorjax.core`: per-view homologies -> Method I / IIa / IIb ->
the bundle -> verdicts, one compiled program of arrays), then the warnings and
messages, written here from the core's arrays.  The views are padded to a few fixed
counts (masked in the core), so that calibrations of 2, 3 or 4 views share one
compiled program.

The result (:mod:`sorjax._calibration_result`), the argument checks
(:mod:`sorjax._calibration_checks`), the outlines' quality (:mod:`sorjax._calibration_quality`)
and the thresholds (:mod:`sorjax._calibration_thresholds`) live in modules of their own.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from typing import Sequence

import equinox as eqx
import jax
import numpy as np

from ._compile import one_off_jit
from ._homology import DEFAULT_SAMPLES, Homology, fit_homology
from ._outline import DEFAULT_POINTS, _as_outlines
from .core._calibrate import _intrinsics, calibrate_homologies
from .core._options import Options
from .core._result import RESULTS
from .core._viewfit import ViewHomologies
from ._messages import (_NAMES, _left_out_text, code_name, details_for, distortion_notes, dropped_views, model_notes,
                        verdict_notes, view_notes)
from ._calibration_checks import (METHODS as METHODS, _check_arguments, _check_extent, _check_homologies,
                                  _check_views, _outline_noise)
from ._calibration_quality import (_grid_floor, _own_errors, dominant_view as dominant_view,
                                   measured_outline_error as measured_outline_error)
from ._calibration_result import Calibration as Calibration, CalibrationError as CalibrationError, _calibration
from ._calibration_thresholds import (ASYMMETRY_PX as ASYMMETRY_PX, ASYMMETRY_REL as ASYMMETRY_REL,
                                      FOCAL_UNDETERMINED as FOCAL_UNDETERMINED, MAX_FOV_DEG as MAX_FOV_DEG,
                                      MAX_TRIMMED as MAX_TRIMMED, MIN_FOCAL_FRACTION as MIN_FOCAL_FRACTION,
                                      NOTE_TRIMMED as NOTE_TRIMMED, OUTLINE_ERROR_PX as OUTLINE_ERROR_PX,
                                      PERSPECTIVE_FACTOR as PERSPECTIVE_FACTOR, PERSPECTIVE_Z as PERSPECTIVE_Z,
                                      RESIDUAL_FLOOR_PX as RESIDUAL_FLOOR_PX, UNDETERMINED as UNDETERMINED,
                                      WARN_ASYMMETRY_PX as WARN_ASYMMETRY_PX, WEAK_REL_STD as WEAK_REL_STD)


# ------------------------------------------------------------------ the core call


def _bucket(n: int) -> int:
    """The padded view count for ``n`` views: 4, 8, 16, ... (one compiled program each;
    a masked view costs little, a compilation tens of seconds)."""
    return max(4, 1 << (n - 1).bit_length())


def view_homologies(homologies, n_samples: int, options: Options | None = None) -> ViewHomologies:
    """Stack :class:`Homology` fits (numpy) into the core's :class:`ViewHomologies`;
    hand-built ones (no robust-fit fields) count as untrimmed, finite vertex unless
    ``|v_x[2]| < 1e-9``.  Whether a vertex is at infinity and whether an outline is a
    conic are judged by ``options`` (None: the defaults; as
    :attr:`Homology.v_x_at_infinity` and :attr:`Homology.is_conic` do)."""
    o = Options() if options is None else options

    def row(h):
        inl = None if h.inliers is None else np.asarray(h.inliers, bool)
        if inl is None or inl.shape != (n_samples,):
            inl = np.ones(n_samples, bool)
        rms = float(h.rms)
        v, l = np.asarray(h.v_x, np.float64), np.asarray(h.l_s, np.float64)
        at_infinity, is_conic = h.judged(o)
        return dict(
            v_x=v, l_s=l, W=np.asarray(h.W, np.float64), rms=np.float64(rms), cost=np.float64(float(h.cost)),
            rms_untrimmed=np.float64(rms if h.rms_untrimmed is None else float(h.rms_untrimmed)),
            conic_rms=np.float64(float(h.conic_rms)), trimmed=np.float64(h.trimmed),
            infinity_z=np.float64(np.inf if h.infinity_z is None else float(h.infinity_z)),
            at_infinity=np.bool_(at_infinity), is_conic=np.bool_(is_conic),
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


def _core_call(points: np.ndarray, homs: ViewHomologies, method: str, aspect, options: Options, image_size,
               distortion: str = "none", fixed=None, leave_out: Sequence[int] = (), noise=None, noise_ell=None):
    """``(program, args, kwargs)``: the compiled core and its arguments for ``V`` views
    padded to :func:`_bucket` (copies of view 0, masked); see :func:`_run_core`."""
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
        return _core, (*args, fixed, noise, noise_ell), {"method": method}
    return _core_distorted, (*args, distortion, fixed, noise, noise_ell), {}


def _prepare_core(points: np.ndarray, n_samples: int, *args, **kwargs) -> None:
    """Start compiling (or loading) the core program :func:`_run_core` will call with
    these arguments, in a host thread (:meth:`sorjax._compile.one_off_jit.prepare`),
    while the per-view fits run: their homologies only fill arrays of known shapes."""
    blank = Homology(l_s=np.zeros(3), v_x=np.zeros(3), W=np.eye(3), rms=0.0, cost=0.0, converged=True, steps=0,
                     conic_rms=0.0, infinity_z=0.0, inliers=np.ones(n_samples, bool), rms_untrimmed=0.0,
                     noise_ell=0.0)
    homs = view_homologies([blank] * points.shape[0], n_samples)
    program, a, kw = _core_call(points, homs, *args, **kwargs)
    program.prepare(*a, **kw)


def _run_core(points: np.ndarray, homs: ViewHomologies, method: str, aspect, options: Options, image_size,
              distortion: str = "none", fixed=None, leave_out: Sequence[int] = (), noise=None, noise_ell=None):
    """The core on ``V`` views padded to :func:`_bucket` (copies of view 0, masked);
    returns the result of ``method`` as numpy, cut back to ``V`` views.  ``fixed``
    (4,) ``(fu, fv, u0, v0)`` px held fixed (NaN: free), or None; ``leave_out``: views
    masked out as well (the same compiled program); ``noise`` (V,) the views' noise
    floors, px, and ``noise_ell`` (V,) their correlation lengths, px (None: 0, the same
    compiled program)."""
    V = points.shape[0]
    program, a, kw = _core_call(points, homs, method, aspect, options, image_size, distortion, fixed, leave_out,
                                noise, noise_ell)
    r = jax.tree_util.tree_map(np.asarray, program(*a, **kw))
    per_view = ("used", "drop_reason", "view_rms", "v_x", "l_s", "outline_offset", "outline_offset_std")
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


def calibrate(
    outlines,
    method: str = "bundle",
    aspect_ratio: float | None = None,
    *,
    n_samples: int | None = None,
    n_points: int = DEFAULT_POINTS,
    homologies=None,
    outline_error: float | str | Sequence[float] | None = None,
    image_size: tuple[int, int] | None = None,
    distortion: str = "none",
    principal_point=None,
    focal_length: float | None = None,
    outline_noise: float | Sequence[float] | None = None,
    outline_noise_ell: float | Sequence[float] | None = None,
    throw: bool = False,
    options: Options | None = None,
) -> Calibration:
    """Calibrate a camera from the outlines of surfaces of revolution.

    Args:
        outlines: one closed outline per view, each an (N, 2) array of pixel
            coordinates (OpenCV convention) or an :class:`Outline`; at least two.
            A list (or tuple); a 3-D array (V, N, 2) is read as V outlines of N points.
            One outline passed bare (an (N, 2) array) is refused, saying to wrap it in
            a list.  Each needs at least ``sorjax._outline.MIN_POINTS`` (32) distinct
            points.
        method: "bundle" (default: the joint 2V+4 estimator, or 2V+3 with a known
            aspect ratio, seeded by Method II; gives the covariance), "I" (zero skew,
            unit or known aspect ratio; eqs. 21-26), "IIa" (zero skew, free aspect
            ratio; eqs. 27-28) or "IIb" (IIa with ``fu = a fv``).
        aspect_ratio: known ``fu / fv``.  "I" and "IIb" assume 1 when it is None;
            "bundle" then estimates it (free aspect).
        n_samples: samples per outline in the homology fit (eq. 20); None:
            ``options.n_samples`` (100, the paper's N, by default).
        n_points: resampled outline size for the distance fields.
        homologies: optional precomputed per-view :class:`Homology` fits.  Each is
            checked against its outline (its symmetry residual there at most
            ``Options.homology_ratio`` times its own ``rms``): one fitted on another
            outline (another camera, another view) is refused with a ValueError naming
            the view.
        outline_error: the systematic error (px RMS) the outlines may carry that their
            symmetry residual does not show (None: ``options.outline_error_px``, 0.1 px
            by default): segmentation bias, lens distortion, an
            object that is not quite a surface of revolution.  The bundle counts the
            focal length as determined only when the outlines show at least
            ``PERSPECTIVE_FACTOR`` (3) times this much perspective (see
            ``Calibration.perspective_px``).  It is also the least prior standard
            deviation of the outlines' shared offset along their normals, which the
            bundle estimates as a nuisance and every method's standard deviations
            include (``Options.outline_offset_px``; outlines traced from masks carry
            ``MASK_OFFSET_PX``, 1 px: ``Calibration.outline_offset``).  The default,
            0.1 px, is about the accuracy of good sub-pixel outlines of real objects; pass 0 for exact
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
        image_size: ``(width, height)`` of the images in px, when known; the outlines
            must lie in it (within ``IMAGE_EDGE_TOLERANCE_PX``, 1 px, of its edge at
            -0.5 and ``width - 0.5``: a ValueError names one that does not).  An estimate
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
        options: every threshold and budget of the per-view fits, the bundle, the
            verdicts, the model checks and the messages (:class:`sorjax.Options`, its
            docstring says what each one does and where its default comes from), or
            None for the defaults; ``n_samples`` and ``outline_error``, when given,
            replace its ``n_samples`` and ``outline_error_px``.  A ValueError names a
            field that is not a number (NaN included).  The thresholds are traced:
            calibrating with other thresholds compiles nothing new (the budgets and
            ``n_samples`` fix the compiled programs and do).

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
    options, outline_error, per_outline, measure, image_size, pp_fixed, f_fixed = _check_arguments(
        method, aspect_ratio, distortion, n_samples, n_points, outline_error, image_size, principal_point,
        focal_length, options)
    n_samples = options.n_samples
    prepared = _as_outlines(outlines, n_points)
    outs, smoothed = [o for o, _ in prepared], [j for _, j in prepared]
    _check_extent(outs, image_size)  # an image_size the outlines do not fit in, named before anything runs
    noise = _outline_noise(outline_noise, outlines, len(outs))
    noise_ell = _outline_noise(outline_noise_ell, outlines, len(outs), "outline_noise_ell", "noise_ell")
    options = _with_outline_offset(options, outlines)
    aspect_ratio = _check_views(len(outs), per_outline, pp_fixed, f_fixed, aspect_ratio)
    homologies = _check_homologies(homologies, len(outs), outs, options)
    points = np.stack([np.asarray(o.points, np.float64) for o in outs])
    a = None if method in ("IIa",) or (method == "bundle" and aspect_ratio is None) else (
        1.0 if aspect_ratio is None else float(aspect_ratio)
    )
    fixed = None
    if pp_fixed is not None or f_fixed is not None:
        fixed = (math.nan, math.nan if f_fixed is None else f_fixed) + (pp_fixed or (math.nan, math.nan))
    aspect = math.nan if aspect_ratio is None else float(aspect_ratio)
    size = (math.nan, math.nan) if image_size is None else image_size
    core = dict(image_size=size, distortion=distortion, fixed=fixed, noise=noise, noise_ell=noise_ell)
    _prepare_core(points, n_samples, method, aspect, options, **core)  # compiles beside the per-view fits
    if homologies is None:
        homologies = tuple(fit_homology(o, n_points=n_points, options=options) for o in outs)
    homologies = tuple(homologies)
    homs = view_homologies(homologies, n_samples, options)
    raw = list(outlines) if isinstance(outlines, (list, tuple, np.ndarray)) else []
    outline_error, notes = _grid_floor(raw, smoothed, float(outline_error), measure)
    if measure and per_outline is None:
        per_outline = _own_errors(raw)
    run = functools.partial(_run_core, points, homs, method, aspect, **core)
    if measure:
        r, outline_error, left_out, more = _measured(run, per_outline, float(outline_error), options)
        notes += more
    else:
        r, left_out = run(dataclasses.replace(options, outline_error_px=outline_error)), {}
    dup_of, o = np.asarray(r.checks.duplicate_of), options
    notes = (notes + view_notes(homs, r.drop_reason, dup_of=dup_of, options=o) + model_notes(r, outline_error, fixed, o)
             + distortion_notes(r, distortion, outline_error, o) + verdict_notes(r, method, a, outs, o))
    for msg in notes:
        warnings.warn(msg, stacklevel=2)
    details = details_for(r, homs, outs, method, a, outline_error, image_size, pp_fixed, fixed, o)
    cal = _calibration(r, homologies, method, a, details, left_out, notes, outline_error, distortion, pp_fixed,
                       f_fixed, tuple(dropped_views(homs, r.drop_reason, dup_of, o)))
    if throw and not cal.success:
        raise CalibrationError(cal.message)
    return cal


def _with_outline_offset(options: Options, outlines) -> Options:
    """``options`` with ``outline_offset_px`` raised to the largest finite
    ``outline_offset`` its outlines carry (:class:`sorjax.ImageOutline`: those traced
    from masks)."""
    own = [getattr(o, "outline_offset", math.nan) for o in outlines] if isinstance(outlines, (list, tuple)) else []
    own = [float(x) for x in own if isinstance(x, (int, float)) and math.isfinite(x) and x >= 0]
    if own and max(own) > options.outline_offset_px:
        return dataclasses.replace(options, outline_offset_px=max(own))
    return options


def _measured(run, per_outline, floor_px: float, options: Options):
    """The calibration of outlines of measured quality (``outline_error="measured"``):
    the outline error measured (:func:`measured_outline_error`, at least ``floor_px``),
    a view the consistency check blames almost alone left out and the rest calibrated
    again (:func:`dominant_view`, ``Options.measured_leave_out`` views at most), then the
    leave-one-view-out check (:func:`jackknife`; pinhole only).  ``run(options,
    leave_out=...)``: :func:`_run_core` with everything else bound (a
    ``functools.partial``: the outlines, homologies, method, aspect ratio, image size,
    lens model, fixed intrinsics and noise floors); ``options``: the calibration's
    thresholds (its ``outline_error_px`` replaced by the measured one).  Returns ``(r, outline_error,
    left_out {view: why}, notes)``."""
    points, homs, method, aspect = run.args
    kw = run.keywords

    def measured(left_out):
        return measured_outline_error(homs, points, per_outline, floor=floor_px, options=base,
                                      left_out=list(left_out), noise=kw["noise"])

    base = options
    outline_error, note = measured({})
    notes = [note]
    options = dataclasses.replace(base, outline_error_px=float(outline_error))
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
        options = dataclasses.replace(base, outline_error_px=float(outline_error))
        r = run(options, leave_out=list(left_out))
    if kw["distortion"] == "none":
        r, jack_notes = jackknife(r, points, homs, method, aspect, options, kw["image_size"], kw["fixed"],
                                  left_out=list(left_out), noise=kw["noise"], noise_ell=kw["noise_ell"])
        notes += jack_notes
    return r, outline_error, left_out, notes
