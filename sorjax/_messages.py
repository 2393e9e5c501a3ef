"""The messages of a calibration, made at the edge from the core's arrays: result codes
by name, why a view was dropped, what the model checks found, which intrinsics are not
determined and what view would help (:func:`sorjax.calibrate`'s warnings and
:attr:`sorjax.Calibration.notes`).  Numbers in, strings out; nothing here is traced.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .core._assess import (ASYMMETRIC, COLLAPSED_FOCAL, CONIC, DUPLICATE, MASKED, PP_OUTSIDE, TRIMMED, USED, WIDE_FOV,
                           axes_intersection, inside_image)
from .core._checks import CULPRIT_ASPECT, CULPRIT_FIXED, CULPRIT_LENS, MODEL_WIDENED
from .core._options import Options
from .core._result import RESULTS

_O = Options()  # the defaults; the values live in sorjax.core.Options
_NAMES = ("fu", "fv", "u0", "v0")
MAX_FOV_DEG = _O.max_fov_deg  # (sorjax._calibration explains it)

# Advice thresholds (which extra view would help).
PARALLEL_AXES_DEG = 10.0
NEAR_AXIS_DEG = 10.0
SMALL_OUTLINE_RAD = 0.15


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


def _implausible_text(code: int, est, outs, image_size=None, options: Options = _O) -> str:
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
            f"({options.max_fov_deg:g} deg): the outlines' errors, not their perspective, made it"
        )
    if code == PP_OUTSIDE:
        return (
            f"the estimated principal point ({est[2]:.0f}, {est[3]:.0f}) lies outside the {w}x{h} image: "
            "the outlines' errors, not their perspective, made it"
        )
    return ""  # pragma: no cover


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


def _drop_texts(h, i: int, d: int, name: str, dup_of=None, options: Options = _O):
    """``(reason, warning)`` for view ``i`` dropped by the core for reason ``d``
    (:data:`sorjax.core._assess.DROP_REASONS`; ``dup_of`` (V,) the view each
    duplicates; ``options``: the thresholds), or None when it is used."""
    o = options
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


def view_notes(h, drop_reason, names=None, dup_of=None, options: Options = _O) -> list[str]:
    """The per-view warnings of a calibration, from the per-view homologies ``h``
    (:class:`sorjax.core.ViewHomologies`, numpy) and the core's drop reasons: fits
    that did not converge, views dropped (conic, not symmetric) and kept with a
    caveat (trimmed, high residual), by the thresholds of ``options``."""
    names = names or [f"view {i}" for i in range(len(drop_reason))]
    o = options
    notes = [f"{name}: the homology fit did not converge (rms {float(h.rms[i]):.3g} px)."
             for i, name in enumerate(names) if not bool(h.converged[i])]
    for i, name in enumerate(names):
        dropped = _drop_texts(h, i, int(drop_reason[i]), name, dup_of, o)
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


def dropped_views(h, drop_reason, dup_of=None, options: Options = _O) -> tuple[tuple[int, str], ...]:
    """``(view index, reason)`` of each view the core left out."""
    out = []
    for i, d in enumerate(np.asarray(drop_reason)):
        dropped = _drop_texts(h, i, int(d), f"view {i}", dup_of, options)
        if dropped is not None:
            out.append((i, dropped[0]))
    return tuple(out)


def _advice_for(r, points, free_aspect: bool) -> list[str]:
    used = np.flatnonzero(np.asarray(r.used))
    return _advice(np.asarray(r.K_raw), np.asarray(r.v_x)[used], np.asarray(r.l_s)[used],
                   [points[i] for i in used], free_aspect, bool(r.aspect_weak), list(used))


def verdict_notes(r, method: str, a, points=None, options: Options = _O) -> list[str]:
    """The warning of a successful but weak calibration (its focal length uncertain by
    more than ``Options.weak_rel_std``), from the core's result ``r`` (numpy)."""
    if code_name(r.result) != "successful" or not np.isfinite(float(r.weak)):
        return []
    tips = ("; ".join(_advice_for(r, points, a is None)) + ".") if points is not None else "add views."
    return [
        f"weak geometry: the focal length is uncertain by {100 * float(r.weak):.3g} % (1 sigma, for a "
        f"symmetry residual (or outline noise) of {max(float(r.s_px), options.residual_floor_px):.2g} px): " + tips
    ]


def _worst_views(ch, k: int = 2) -> str:
    """The views whose release from the joint model lowers the cost most (text)."""
    S = np.asarray(ch.view_score, float)
    order = [int(i) for i in np.argsort(-np.nan_to_num(S, nan=-1.0)) if np.isfinite(S[i])][:k]
    return ", ".join(f"view {i} (score {S[i]:.3g}, {float(ch.view_px[i]):.2g} px)" for i in order)


def _aspect_text(ch) -> str:
    better = (f", and fit {float(ch.aspect_px):.2g} px RMS better" if np.isfinite(float(ch.aspect_px))
              else " (Method IIa)")  # a linear method's check: no cost to compare
    return (f"aspect_ratio={float(ch.aspect_fixed):g} is not what the outlines show: with the aspect ratio free "
            f"they give fu / fv = {float(ch.aspect_free):.4f} +- {float(ch.aspect_free_std):.2g}, "
            f"{float(ch.aspect_z):.3g} standard deviations away{better}")


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


def distortion_notes(r, distortion: str, outline_error: float, options: Options = _O) -> list[str]:
    """The warning of a distortion model the outlines do not support (the
    distortion-free K returned, its std widened), from the core's result ``r``."""
    if distortion == "none" or np.all(np.isfinite(np.asarray(r.distortion))):
        return []
    g, z = float(r.distortion_px), float(r.distortion_z)
    o = options
    why = (f"noise alone could do (needs z >= {o.perspective_z:g})" if not z >= o.perspective_z else
           f"a systematic outline error of {float(outline_error):g} px (outline_error) could do (needs >= "
           f"{o.perspective_factor * float(outline_error):.2g} px)")
    return [f"distortion={distortion!r}: the outlines do not determine the radial distortion: the fit without it is "
            f"only {g:.2g} px RMS worse (z = {z:.2g}), which {why}. Returned: the distortion-free K, its standard "
            "deviations widened by the difference to the fit with distortion (the outlines cannot tell distortion "
            "from a change of focal length), and NaN coefficients. Add views with objects near the image's edges "
            "and corners, where distortion is strongest."]


def model_notes(r, outline_error: float, fixed=None, options: Options = _O) -> list[str]:
    """The warning of a calibration whose model the outlines do not confirm (the
    uncertainty widened: :mod:`sorjax.core._checks`), from the core's result ``r``;
    ``fixed``: the intrinsics held fixed (px, NaN: free) or None."""
    ch = r.checks
    if int(ch.verdict) != MODEL_WIDENED or code_name(r.result) not in ("successful", "degenerate",
                                                                      "only_principal_point"):
        return []
    notes = []
    # (a linear method's aspect check has no cost to compare, aspect_px NaN, and its own threshold)
    z_limit = options.consistency_z if np.isfinite(float(ch.aspect_px)) else options.linear_aspect_z
    if np.isfinite(float(ch.aspect_z)) and float(ch.aspect_z) >= z_limit:
        notes.append(
            _aspect_text(ch) + f", within what the outline error allowed for ({float(outline_error):g} px) could "
            "cause. The standard deviations include the difference between the fixed and the free estimates; "
            "if the aspect ratio is not known exactly, pass aspect_ratio=None (Methods I and IIb then take 1: "
            "use the bundle or Method IIa).")
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
                fixed=None, options: Options = _O) -> str:
    """What is specific to a result that is not a plain success (``Calibration.details``);
    ``fixed_pp``: the principal point held fixed (px) or None; ``fixed``: every
    intrinsic held fixed (px, NaN: free) or None."""
    name = code_name(r.result)
    if name == "inconsistent":
        ch = r.checks
        lim = f"{options.perspective_factor * float(outline_error):.2g}"
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
        why = "; ".join(f"view {i}: {reason}" for i, reason in dropped_views(h, drop, options=options))
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
        why = _implausible_text(int(r.implausible), np.array(est), [points[i] for i in used], image_size, options)
        why = f" Not a plausible camera: {why}." if why else ""
        if not bool(r.perspective_ok):
            z, g = float(r.perspective_z), float(r.perspective_px)
            o = options
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


def _left_out_text(r, j: int, share: float) -> str:
    ch = r.checks
    n = int(np.asarray(r.used, bool).sum()) - 1
    return (f"view {j} left out: the views were not consistent with one camera (chi-square p = "
            f"{float(ch.consistency_p):.2g} on {int(ch.consistency_dof)} degrees of freedom, "
            f"{float(ch.consistency_px):.2g} px RMS) and this view held {100 * share:.0f} % of the disagreement "
            f"(score {float(ch.view_score[j]):.3g}, {float(ch.view_px[j]):.2g} px): most likely it is not a surface "
            f"of revolution seen by this camera (a false detection or a poor segmentation; check the overlay). "
            f"Calibrated again from the other {n} views.")
