"""The arguments of :func:`sorjax.calibrate` checked in plain Python before anything
is traced: the method and aspect ratio, the lens model, the sizes, the outline error
(px), the image size (px), the fixed intrinsics (px), the outline noise floors (px),
the precomputed homologies and the number of views; each refusal a ValueError that
says what is wrong and what to pass instead."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._checks import check_options, check_sizes
from ._homology import Homology, homology_residual
from ._calibration_thresholds import OUTLINE_ERROR_PX
from .core._options import Options

METHODS = ("bundle", "I", "IIa", "IIb")


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


def _check_homologies(homologies, n_views, outlines=None, options=None):
    """``homologies`` (a sequence of :class:`Homology`, one per outline, or None)
    checked: their type and number and, given ``outlines`` (the calibration's
    :class:`sorjax.Outline` s, as resampled), that each maps its outline onto itself as
    well as it claims: the outline's RMS symmetry residual under it
    (:func:`sorjax._homology.homology_residual`: eq. 20 at the fit's samples, over the
    samples it kept) at most ``options.homology_ratio`` times its own fitted residual
    ``Homology.rms`` (at least ``options.check_floor_px``).  A homology fitted on the
    outline gets back its own residual (ratio 1); one fitted on another outline (another
    camera, view or object, the outline moved) maps this one onto itself worse than
    its own, and would make K from geometry these outlines do not show.  A ValueError
    names the first view that fails."""
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
        if outlines is not None:
            _check_homology_fit(homologies, outlines, Options() if options is None else options)
    return homologies


def _check_homology_fit(homologies, outlines, options):
    """Each homology maps its outline onto itself within its own residual (see
    :func:`_check_homologies`); a ValueError naming the first view that does not."""
    ratio, floor = float(options.homology_ratio), float(options.check_floor_px)
    if not ratio < math.inf:
        return
    r = homology_residual(outlines, homologies, outlines[0].n_points, options)
    for i, (h, ri) in enumerate(zip(homologies, r)):
        own = float(h.rms)
        lim = ratio * max(own, floor) if math.isfinite(own) else math.nan
        if not ri <= lim:
            raise ValueError(
                f"view {i}: homologies[{i}] does not map its outline onto itself: the outline's RMS symmetry residual "
                f"under it is {ri:.3g} px, against {own:.3g} px for the outline it was fitted on (Homology.rms); at "
                f"most {lim:.3g} px is accepted (options.homology_ratio = {ratio:g} times that, taken as at least "
                f"options.check_floor_px = {floor:g} px). It was fitted on another outline (another camera, view or "
                "object, or the outline moved): pass the homologies fitted on these outlines (sorjax.fit_homology of "
                "each, in the same order), or homologies=None.")


_check_sizes = check_sizes  # n_samples, n_points: the same rules as fit_homology's (sorjax._checks)


def _check_outline_error(outline_error, default: float = OUTLINE_ERROR_PX):
    """``(declared px, per-outline errors (px) or None, measured?)`` from
    :func:`calibrate`'s ``outline_error``: a number, "measured" or one number per outline
    (these two with ``default`` px as the declared floor)."""
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
        return default, None, True
    if isinstance(outline_error, (list, tuple, np.ndarray)):
        try:
            vals = np.asarray(outline_error).tolist() if np.ndim(outline_error) == 1 else None
        except ValueError:  # ragged
            vals = None
        if not vals:
            raise ValueError(bad)
        return default, np.array([px(x, nan_ok=True) for x in vals]), True
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


def _check_arguments(method, aspect_ratio, distortion, n_samples, n_points, outline_error, image_size,
                     principal_point, focal_length, options=None):
    """:func:`calibrate`'s arguments checked before any outline is read: ``(options,
    outline_error px, per-outline errors or None, measured?, image_size, principal point
    fixed, focal length fixed)``, ``options`` with ``n_samples`` (None: its own) in it;
    a ValueError that says what is wrong otherwise."""
    _check_method(method, aspect_ratio)
    if not isinstance(distortion, str) or distortion not in ("none", "k1", "k1k2"):
        raise ValueError(f"distortion must be 'none', 'k1' or 'k1k2' (OpenCV's radial terms); got {distortion!r}.")
    if distortion != "none" and method != "bundle":
        raise ValueError(f"distortion={distortion!r} is estimated by the bundle only; use method='bundle' (the "
                         f"default) instead of {method!r}.")
    options = check_options(options)
    n_samples, _ = _check_sizes(options.n_samples if n_samples is None else n_samples, n_points)
    options = dataclasses.replace(options, n_samples=n_samples)
    default = options.outline_error_px
    if not (math.isfinite(default) and default >= 0):
        raise ValueError(f"options.outline_error_px must be a finite number of pixels >= 0; got {default!r}.")
    outline_error, per_outline, measure = _check_outline_error(default if outline_error is None else outline_error,
                                                               default)
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
    return options, outline_error, per_outline, measure, image_size, pp_fixed, f_fixed


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


# How far (px) beyond the image's edge an outline may reach when image_size is given: the
# image spans [-0.5, W - 0.5] x [-0.5, H - 0.5] (OpenCV: pixel centres 0 .. W - 1), an
# outline traced along a border pixel's edge reaches -0.5 or W - 0.5 exactly, and its
# smoothing and the resampling through its points (Catmull-Rom) may overshoot that by a
# fraction of a pixel.  Beyond 1 px the outlines are not in that image's pixels.
IMAGE_EDGE_TOLERANCE_PX = 1.0


def _check_extent(outlines, image_size) -> None:
    """The outlines (:class:`sorjax.Outline` s) lie inside ``image_size`` ``(w, h)``
    (checked, or None: nothing to check), to within ``IMAGE_EDGE_TOLERANCE_PX`` of its
    edge; a ValueError naming the outline that reaches furthest beyond it otherwise."""
    if image_size is None or not outlines:
        return
    w, h = image_size
    tol = IMAGE_EDGE_TOLERANCE_PX
    lo = np.array([-0.5, -0.5]) - tol
    hi = np.array([w - 0.5, h - 0.5]) + tol
    pts = [np.asarray(o.points, np.float64) for o in outlines]
    mins, maxs = np.array([p.min(axis=0) for p in pts]), np.array([p.max(axis=0) for p in pts])
    over = np.maximum(np.max(maxs - hi, axis=1), np.max(lo - mins, axis=1))
    if not np.any(over > 0):
        return
    i = int(np.argmax(over))
    x0, y0 = mins.min(axis=0)
    x1, y1 = maxs.max(axis=0)
    where = ", ".join(f"{c} = {v:.1f}" for c, v, bad in (
        ("x", mins[i, 0], mins[i, 0] < lo[0]), ("x", maxs[i, 0], maxs[i, 0] > hi[0]),
        ("y", mins[i, 1], mins[i, 1] < lo[1]), ("y", maxs[i, 1], maxs[i, 1] > hi[1])) if bad)
    span = f"the outlines span x = {x0:.1f} .. {x1:.1f}, y = {y0:.1f} .. {y1:.1f} px (outline {i} reaches {where})"
    edge = (f"the {w} x {h} image's pixels run from -0.5 to {w - 0.5:g} in x and to {h - 0.5:g} in y (OpenCV: the "
            f"top-left pixel's centre at (0, 0)), {tol:g} px of tolerance")
    if x0 < lo[0] or y0 < lo[1]:
        raise ValueError(f"the outlines reach beyond image_size {(w, h)}: {span}, left of or above the image; {edge}. "
                         "Pass the outlines in the pixels of the image they were traced in, or image_size=None.")
    swapped = x1 <= h - 0.5 + tol and y1 <= w - 0.5 + tol
    raise ValueError(f"image_size {(w, h)} is smaller than the outlines' extent: {span}; {edge}. Pass the (width, "
                     "height) of the images the outlines were traced in"
                     + (f" (width first: {(h, w)} would hold them)" if swapped else "") + ", or image_size=None.")
