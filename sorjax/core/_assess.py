"""Verdicts on an estimate: which views are used, which intrinsics are determined.

Pure functions of arrays (the numbers behind :func:`sorjax.calibrate`'s messages; the
messages themselves are written at the edge, in :mod:`sorjax._calibration`).  The
thresholds are :class:`sorjax.core.Options` fields; each rule is documented there.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._options import Options

# Why a view was left out (``CoreResult.drop_reason``); 0: used.
USED, CONIC, TRIMMED, ASYMMETRIC, MASKED, DUPLICATE = 0, 1, 2, 3, 4, 5
DROP_REASONS = ("used", "conic outline", "not symmetric (too much trimmed)", "not symmetric", "masked by the caller",
                "the same view as an earlier one")

# Why an estimate is implausible (``Verdict.implausible``); 0: plausible.
PLAUSIBLE, COLLAPSED_FOCAL, WIDE_FOV, PP_OUTSIDE = 0, 1, 2, 3


def view_verdicts(rms, rms_untrimmed, radius, is_conic, trimmed, valid, options: Options) -> Int[Array, " V"]:
    """Per view, why it is dropped (``USED`` when kept): a conic outline, more than
    ``max_trimmed`` of its samples trimmed, or an untrimmed RMS symmetry residual above
    both ``asymmetry_px`` and ``asymmetry_rel`` of its RMS radius (px); views the caller
    masked (``valid`` False) are ``MASKED``.  The order of the tests is the order of the
    messages: conic first."""
    r = jnp.maximum(rms, rms_untrimmed)
    asym = ~jnp.isfinite(r) | ((r > options.asymmetry_px) & (r > options.asymmetry_rel * radius))
    reason = jnp.where(asym, ASYMMETRIC, USED)
    reason = jnp.where(trimmed > options.max_trimmed, TRIMMED, reason)
    reason = jnp.where(is_conic, CONIC, reason)
    return jnp.where(valid, reason, MASKED).astype(jnp.int32)


def outline_radius(points: Float[Array, "V M 2"]) -> Float[Array, " V"]:
    """Each outline's RMS distance from its centroid (px)."""
    c = jnp.mean(points, axis=-2, keepdims=True)
    return jnp.sqrt(jnp.mean(jnp.sum((points - c) ** 2, -1), -1))


def outline_extent(points: Float[Array, "V M 2"], used: Bool[Array, " V"]) -> Float[Array, ""]:
    """The larger side of the used outlines' joint bounding box (px)."""
    big = jnp.finfo(points.dtype).max
    m = used[:, None, None]
    hi = jnp.max(jnp.where(m, points, -big), axis=(0, 1))
    lo = jnp.min(jnp.where(m, points, big), axis=(0, 1))
    return jnp.max(hi - lo)


def inside_image(u0, v0, image_size) -> Bool[Array, ""]:
    """Whether the point ``(u0, v0)`` (px, pixel centres at integers) lies in the image
    ``image_size = (width, height)``, whose edges are at ``-0.5`` and ``size - 0.5``;
    True when the size is unknown (NaN)."""
    w, h = image_size[0], image_size[1]
    known = jnp.isfinite(w) & jnp.isfinite(h)
    return ~known | ((u0 >= -0.5) & (u0 <= w - 0.5) & (v0 >= -0.5) & (v0 <= h - 0.5))


def implausible(est: Float[Array, "4"], extent, image_size, options: Options) -> Int[Array, ""]:
    """Why ``(fu, fv, u0, v0)`` (px) is implausible for a camera without distortion
    that took outlines ``extent`` px across (``PLAUSIBLE`` when it is not): a focal
    length below ``min_focal_fraction`` of the extent; with ``image_size = (width,
    height)`` (NaN when unknown) a field of view above ``max_fov_deg`` or the principal
    point outside the image."""
    f = jnp.min(jnp.abs(est[:2]))
    w, h = image_size[0], image_size[1]
    known = jnp.isfinite(w) & jnp.isfinite(h)
    fov = 2.0 * jnp.degrees(jnp.arctan(jnp.stack([w, h]) / (2.0 * jnp.maximum(jnp.abs(est[:2]), 1e-300))))
    wide = known & (jnp.max(fov) > options.max_fov_deg)
    outside = ~inside_image(est[2], est[3], image_size)
    code = jnp.where(outside, PP_OUTSIDE, PLAUSIBLE)
    code = jnp.where(wide, WIDE_FOV, code)
    code = jnp.where(f < options.min_focal_fraction * extent, COLLAPSED_FOCAL, code)
    return code.astype(jnp.int32)


class Verdict(eqx.Module):
    """Which intrinsics an estimate determines (arrays; see :func:`assess`).

    Attributes:
        determined: (4,) for ``(fu, fv, u0, v0)``.
        std: (4,) standard deviations, px (the covariance scaled by the residual).
        weak: the larger relative std of a focal length at a residual of at least
            ``residual_floor_px``, when above ``weak_rel_std`` and all is determined;
            else NaN.
        aspect_weak: with a free aspect ratio, fu / fv is poorly determined.
        implausible: why the estimate is implausible (0: it is not).
    """

    determined: Bool[Array, "4"]
    std: Float[Array, "4"]
    weak: Float[Array, ""]
    aspect_weak: Bool[Array, ""]
    implausible: Int[Array, ""]


def assess(est, cov_unit, s_px, radius, extent, image_size, free_aspect, floor_verdict, perspective_ok,
           options: Options, single_view=False, cov_offset=None) -> Verdict:
    """Which of the raw estimate ``est = (fu, fv, u0, v0)`` (px) the views determine,
    from the covariance per px^2 of residual ``cov_unit`` (4, 4) and the residual
    standard error ``s_px``.  An intrinsic is determined when its std is finite and at
    most ``undetermined`` times the focal length (the principal point: times the
    outlines' RMS ``radius`` when the focal length is not determined); a focal length
    from a ``single_view`` (bool) only when its std is at most ``focal_undetermined``
    times itself.  With
    ``floor_verdict`` (every ``v_x`` at infinity, where theory says the focal length is
    free) the std is taken at a residual of at least ``residual_floor_px``, so the
    estimate must fix the focal length robustly to override that.  Nothing is
    determined without enough evidence for perspective (``perspective_ok``) or for an
    implausible estimate (:func:`implausible`).  ``cov_offset`` (4, 4) px^2: a part of
    the covariance that does not scale with the residuals (the declared outline
    offset's, :func:`sorjax.core._covariance.offset_meat`), added to both; None: none."""
    off = jnp.zeros((4, 4)) if cov_offset is None else cov_offset
    var = jnp.diag(cov_unit)
    s_floor = jnp.maximum(s_px, options.residual_floor_px)
    fin = jnp.isfinite(var)
    std = jnp.where(fin, jnp.sqrt(jnp.abs(jnp.where(fin, var, 0.0)) * s_px**2 + jnp.diag(off)), jnp.inf)
    std_floor = jnp.where(fin, jnp.sqrt(jnp.abs(jnp.where(fin, var, 0.0)) * s_floor**2 + jnp.diag(off)), jnp.inf)
    judged = jnp.where(floor_verdict, std_floor, std)
    why = implausible(est, extent, image_size, options)
    focal_frac = jnp.where(single_view, options.focal_undetermined, options.undetermined)
    focal_ok = jnp.isfinite(std[:2]) & (judged[:2] <= focal_frac * jnp.abs(est[:2]))
    ref = jnp.where(jnp.all(focal_ok), jnp.sqrt(jnp.abs(est[0] * est[1])), radius)
    pp_ok = jnp.isfinite(std[2:]) & (judged[2:] <= options.undetermined * ref)
    determined = jnp.concatenate([focal_ok, pp_ok]) & (why == PLAUSIBLE) & perspective_ok
    rel_floor = std_floor[:2] / jnp.abs(est[:2])
    all_det = jnp.all(determined)
    weak = jnp.where(all_det & (jnp.max(rel_floor) > options.weak_rel_std), jnp.max(rel_floor), jnp.nan)
    C = cov_unit * s_floor**2 + off  # at the floor
    q = (C[0, 0] / est[0] ** 2 + C[1, 1] / est[1] ** 2 - 2 * C[0, 1] / (est[0] * est[1]))
    aspect_weak = free_aspect & jnp.where(
        ~all_det, True, jnp.isfinite(weak) & (jnp.sqrt(jnp.maximum(q, 0.0)) > options.weak_rel_std))
    return Verdict(determined, std, weak, aspect_weak, why)


def perspective_gate(delta_px2, n, s_px, options: Options):
    """``(ok, g_px, z)``: the evidence for perspective (the cost, px^2, by which the best
    camera with no perspective fits worse, over ``n`` samples) as an RMS per sample
    ``g_px`` and a z-score ``sqrt(delta) / s_px``; ``ok`` when ``z >= perspective_z`` and
    ``g_px >= perspective_factor * outline_error_px``."""
    d = jnp.maximum(delta_px2, 0.0)
    g = jnp.sqrt(d / jnp.maximum(n, 1.0))
    z = jnp.sqrt(d) / jnp.maximum(s_px, 1e-300)
    return (z >= options.perspective_z) & (g >= options.perspective_factor * options.outline_error_px), g, z


def axis_spread_deg(ls: Float[Array, "V 3"], used: Bool[Array, " V"]) -> Float[Array, ""]:
    """Largest angle (degrees, 0..90) between the directions of the used imaged axes."""
    t = jnp.arctan2(ls[:, 1], ls[:, 0])
    d = jnp.abs(t[:, None] - t[None, :]) % jnp.pi
    d = jnp.minimum(d, jnp.pi - d)
    return jnp.degrees(jnp.max(jnp.where(used[:, None] & used[None, :], d, 0.0)))


def principal_point_determined(pp, cov_pp, radius, image_size, options: Options) -> Bool[Array, ""]:
    """Whether the principal point ``pp`` (2,) px where the imaged axes meet (every
    ``v_x`` at infinity; :func:`axes_intersection`) counts as determined: its covariance
    ``cov_pp`` (2, 2) px^2 is finite (three axes or more: two lines always meet, so two
    views cannot show their own error), its standard deviations are at most
    ``undetermined`` times the outlines' RMS ``radius`` (px; as :func:`assess` judges a
    principal point without a focal length) and, with ``image_size = (width, height)``
    known, it lies inside the image (:func:`inside_image`)."""
    sd = jnp.sqrt(jnp.abs(jnp.diag(cov_pp)))
    tight = jnp.all(jnp.isfinite(sd)) & jnp.all(sd <= options.undetermined * radius)
    return tight & inside_image(pp[0], pp[1], image_size)


# t_nu(Phi(3)) / 3 for nu = 1 .. 30 degrees of freedom (scipy.stats.t.ppf; checked in
# tests/test_degenerate.py): how much wider than a known-variance std a std estimated
# from nu residuals must be for +-3 of it to cover what +-3 sigma covers (99.73 %)
_T_WIDEN = (78.6005, 6.40225, 3.07298, 2.20674, 1.83569, 1.63469, 1.50999, 1.42554, 1.36475, 1.31898,
            1.28331, 1.25476, 1.23140, 1.21193, 1.19547, 1.18138, 1.16917, 1.15849, 1.14908, 1.14072,
            1.13324, 1.12652, 1.12044, 1.11492, 1.10988, 1.10526, 1.10102, 1.09710, 1.09348, 1.09011)


def few_dof_widening(nu) -> Float[Array, ""]:
    """``t_nu(Phi(3)) / 3``: the factor by which a standard deviation estimated from the
    scatter of ``nu`` residuals (``nu`` >= 1, traced) is widened so that +-3 of it
    covers 99.73 %, as +-3 sigma does for a known variance (Student's t; 78.6 for one
    degree of freedom, 6.4 for two, 1.09 for 30; beyond 30 the Cornish-Fisher
    expansion ``1 + (z^2 + 1) / (4 nu) + (5 z^4 + 16 z^2 + 3) / (96 nu^2)``, z = 3)."""
    nu = jnp.asarray(nu, jnp.float64)
    table = jnp.asarray(_T_WIDEN)
    i = jnp.clip(jnp.round(nu).astype(jnp.int32), 1, len(_T_WIDEN)) - 1
    big = jnp.maximum(nu, 1.0)
    series = 1.0 + 10.0 / (4.0 * big) + (5.0 * 81.0 + 16.0 * 9.0 + 3.0) / (96.0 * big**2)
    return jnp.where(nu <= len(_T_WIDEN), table[i], series)


def axes_intersection(ls: Float[Array, "V 3"], used: Bool[Array, " V"]):
    """Least-squares intersection of the used lines ``ls`` (``a^2 + b^2 = 1``):
    ``(point (2,), cov (2, 2), spread_deg)``; ``cov`` NaN with fewer than 3 lines,
    ``point`` NaN when they are (nearly, within 1 deg) parallel.

    ``cov = s^2 (A^T A)^-1 w^2`` (px^2), ``s^2`` the lines' scatter about the point with
    ``k - 2`` degrees of freedom (``k`` lines) and ``w`` :func:`few_dof_widening` of
    them: with three lines ``s^2`` rests on one residual, which is below a ninth of its
    expectation a quarter of the time, and the bare ``s^2`` would put a principal point
    beyond 3 of its "standard deviations" in 20 % of cases (Student's t with one
    degree of freedom: ``1 - 2 atan(3) / pi``); widened, +-3 std covers 99.73 % whatever
    ``k``."""
    w = used.astype(ls.dtype)
    A, b = ls[:, :2] * w[:, None], -ls[:, 2] * w
    N = A.T @ A
    spread = axis_spread_deg(ls, used)
    parallel = spread < 1.0
    x = jnp.linalg.solve(jnp.where(parallel, jnp.eye(2), N), A.T @ b)
    k = jnp.sum(w)
    s2 = jnp.sum((A @ x - b) ** 2) / jnp.maximum(k - 2, 1.0)
    s2 = s2 * few_dof_widening(jnp.maximum(k - 2, 1.0)) ** 2
    cov = jnp.where(k >= 3, s2 * jnp.linalg.inv(jnp.where(parallel, jnp.eye(2), N)), jnp.nan)
    return jnp.where(parallel, jnp.nan, x), jnp.where(parallel, jnp.nan, cov), spread
