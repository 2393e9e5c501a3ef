"""The whole calibration as one pure function of fixed-shape arrays.

    points (V, M, 2) px -> prepare_views -> fit_views (eq. 20, per view)
      -> view verdicts (conic / not symmetric: masked, never removed)
      -> Method I / IIa / IIb (normalised coordinates) -> the bundle (2V + 4)
      -> covariance, perspective evidence, verdicts -> :class:`CoreResult`

:func:`calibrate` runs it all; :func:`calibrate_homologies` starts from per-view
homologies (pixels) already fitted, so that several methods share one set of fits (as
an experiment comparing estimators does).  Both are jit / vmap / grad clean: ``method``
and ``options`` are static, everything else is an array.  ``aspect``: the known
``fu / fv`` or NaN (free; "I" and "IIb" then take 1, "IIa" is always free).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._distorted import (DISTORTION_MODELS, bundle_estimate_distorted, distortion_gate)
from ._model import BundleProblem, axis_params, make_problem, pack_seeds, with_model
from ._bundle import (bundle_seeds, bundle_solution)
from ._covariance import homology_covariance, homology_estimator_covariance
from ._camera import intrinsics_matrix, transform_points
from ._linear import linear_estimate
from ._assess import (DUPLICATE, USED, assess, axes_intersection, outline_extent, outline_radius,
                      principal_point_determined,
                      perspective_gate, view_verdicts)
from ._checks import (CULPRIT_ASPECT, CULPRIT_FIXED, CULPRIT_LENS, CULPRIT_VIEWS, MODEL_CONTRADICTED, MODEL_OK,
                      MODEL_WIDENED, NO_CULPRIT, ModelChecks, aspect_of, consistency, duplicate_views,
                      fixed_aspect_check,
                      fixed_release, lens_release, n_free_intrinsics, view_scores)
from ._options import Options
from ._prepare import joint_transform, prepare_views
from ._result import RESULTS, CoreResult
from ._solvers import traced_once
from ._viewfit import ViewHomologies, fit_views, homologies_in_pixels, with_noise_floor

METHODS = ("bundle", "I", "IIa", "IIb")


def _nan(shape):
    return jnp.full(shape, jnp.nan)


def _intrinsics(K):
    """``(fu, fv, u0, v0)`` of a (3, 3) ``K`` (px)."""
    return jnp.stack([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


def calibrate(points: Float[Array, "V M 2"], method: str = "bundle", aspect=jnp.nan, *, options: Options = Options(),
              image_size=None, valid=None, distortion: str = "none", fixed=None, noise=None,
              noise_ell=None) -> CoreResult:
    """Calibrate from ``V`` outlines of ``M`` evenly spaced pixel points each (e.g.
    :func:`sorjax.make_outline`'s points, positively oriented).

    Args:
        points: (V, M, 2) pixels.
        method: "bundle", "I", "IIa" or "IIb" (static).
        aspect: known ``fu / fv`` (scalar array) or NaN.
        options: :class:`Options` (static).
        image_size: (2,) ``(width, height)`` px, or None / NaN when unknown.
        valid: (V,) bool, views to consider (False: padding, left out); default all.
        distortion: the lens model of the bundle (static): "none" (a pinhole), "k1"
            or "k1k2" (OpenCV's radial terms, estimated with the intrinsics:
            :func:`sorjax.core._distorted.bundle_estimate_distorted`; the bundle only).
        fixed: (4,) intrinsics held at known values, ``(fu, fv, u0, v0)`` px with NaN
            where free (OpenCV's fixed-parameter flags: a principal point, a focal
            length), or None (all free; the program traced before fixed parameters
            existed).  The bundle only.  With a known aspect ratio fix ``fv`` (``fu =
            aspect fv``).  Fewer intrinsics to estimate need fewer views: with the
            principal point fixed and at most two intrinsics free, one view with a
            finite ``v_x`` is enough (:func:`views_needed`).
        noise: (V,) each outline's noise floor, px: the RMS symmetry residual it would
            show (as ``ViewHomologies.rms``; 0 or NaN: none), or None (none).  For
            outlines whose symmetry residuals understate their noise (averaged with
            their own mirror image, as :func:`sorjax.outlines_from_image` does): every
            estimate of the noise level (covariance, model checks, perspective and
            distortion evidence, the solver's stopping test, whether a view's ``v_x``
            is at infinity: :func:`sorjax.core.with_noise_floor`) takes each view's
            residuals as at least this (:attr:`sorjax.core._model.BundleProblem.noise`);
            the cost, and so the estimate of ``K``, is the same.
        noise_ell: (V,) the correlation length along the curve (px) of the noise
            behind each floor (:attr:`sorjax.Homology.noise_ell` of the outline before
            it was averaged; 0 or NaN: unknown), or None.  Where a floor binds, the
            covariance takes this as the view's noise correlation length instead of
            reading one off residuals that no longer show the noise
            (:attr:`sorjax.core._model.BundleProblem.noise_ell`).  Without ``noise`` no
            floor binds, and it has no effect.
    """
    homs = fit_homologies(points, options)
    return calibrate_homologies(points, homs, method, aspect, options=options, image_size=image_size, valid=valid,
                                distortion=distortion, fixed=fixed, noise=noise, noise_ell=noise_ell)


def fit_homologies(points: Float[Array, "V M 2"], options: Options = Options(), sequential: bool | None = None
                   ) -> ViewHomologies:
    """Every view's harmonic homology (eq. 20, automatic start, robust), in pixels:
    :func:`prepare_views`, :func:`fit_views`, :func:`homologies_in_pixels`.
    ``sequential`` (static): the views one after another (``jax.lax.map``; on a CPU
    faster and far quicker to compile) instead of ``jax.vmap``; None (default): on
    the CPU only."""
    if sequential is None:
        sequential = jax.default_backend() == "cpu"
    views = prepare_views(points, options.n_samples)
    return homologies_in_pixels(views, fit_views(views, options, sequential=sequential), options)


class _Common(NamedTuple):
    """What every method of one calibration shares."""

    radius: Array
    duplicate_of: Array
    drop: Array
    used: Array
    n_used: Array
    all_inf: Array
    T: Array
    rms_u: Array
    points_n: Array
    l_n: Array
    inliers: Array
    problem: BundleProblem


def _common(points, homs: ViewHomologies, valid, options: Options, noise=None, noise_ell=None) -> _Common:
    radius = outline_radius(points)
    drop = view_verdicts(homs.rms, homs.rms_untrimmed, radius, homs.is_conic, homs.trimmed, valid, options)
    dup = duplicate_views(points, drop == USED, options)
    drop = jnp.where((drop == USED) & (dup >= 0), DUPLICATE, drop).astype(jnp.int32)
    used = drop == USED
    # the normalisation is a constant for differentiation (K in pixels does not depend on it)
    T = jax.lax.stop_gradient(joint_transform(points, used))
    points_n = transform_points(T, points)
    inliers = homs.inliers.astype(jnp.float64)
    return _Common(
        radius=radius, duplicate_of=dup, drop=drop, used=used, n_used=jnp.sum(used),
        all_inf=jnp.all(jnp.where(used, homs.at_infinity, True)), T=T, rms_u=jnp.where(used, homs.rms, jnp.nan),
        points_n=points_n, l_n=homs.l_s @ jnp.linalg.inv(T),  # lines map by T^-T
        inliers=inliers,
        # the joint fields, samples, weights and noise floors: built once, shared by every method
        problem=make_problem(points_n, options.n_samples, None, inliers, used,
                             noise=None if noise is None else noise * T[0, 0], noise_ell=noise_ell),
    )


def _bundle(c: _Common, homs: ViewHomologies, aspect, options: Options, fixed=None):
    """The bundle for one aspect model (``fixed``: intrinsics held fixed, px, or None)
    and the score statistics of its views (:func:`sorjax.core._checks.view_scores`),
    of the lens distortion it holds at 0 and of the intrinsics it holds fixed
    (:func:`sorjax.core._checks.lens_release`, :func:`~sorjax.core._checks.fixed_release`;
    None without fixed intrinsics): ``(BundleOut, (S, delta_px2, n, lens, fixed))``."""
    seeds, seed_ok = bundle_seeds(homs.v_x, homs.l_s, c.used, c.T, aspect, fixed)
    out, lin = bundle_solution(c.points_n, c.used, c.inliers, c.l_n, seeds, seed_ok, aspect, c.T, options, fixed,
                               base=c.problem)
    y = jax.lax.stop_gradient(out.y)
    args = (y, c.points_n, c.used, c.inliers, aspect, c.T, options)
    # every check reads the one Jacobian pass at the solution (the covariance's), its
    # residuals refitted with the outlines' estimated offset
    kw = dict(base=c.problem, ell=jax.lax.stop_gradient(out.noise_ell), lin=lin)
    lens = lens_release(*args, fixed, **kw)
    held = None if fixed is None else fixed_release(*args, fixed, **kw)
    return out, view_scores(*args, fixed, **kw) + (lens, held)


def _distorted(c: _Common, homs: ViewHomologies, aspect, options: Options, distortion: str, fixed=None):
    """The bundle with radial distortion (:func:`sorjax.core._distorted.bundle_estimate_distorted`)
    and the evidence gate for it (:func:`sorjax.core._distorted.distortion_gate`: the fit with
    ``k = 0`` must be worse by the noise and by the declared outline error).  Returns
    ``(BundleOut, (k (2,), k_std (2,), g_px, z))``: with the evidence, the fit with
    distortion; without it, the distortion-free fit with its covariance widened by
    ``d d^T`` (``d`` the difference between the two fits' ``(fu, fv, u0, v0)``: the
    outlines cannot tell which is right) and ``k`` NaN (not determined)."""
    seeds, seed_ok = bundle_seeds(homs.v_x, homs.l_s, c.used, c.T, aspect, fixed)
    d = bundle_estimate_distorted(c.points_n, c.used, c.inliers, c.l_n, seeds, seed_ok, aspect, c.T, options,
                                  distortion, fixed, base=c.problem)
    fit, free = d.fit, d.free
    gate, g, z = distortion_gate(d.delta, fit.n, jnp.sqrt(fit.s2), options)
    gate = gate & d.ok
    dd = jnp.where(jnp.all(jnp.isfinite(fit.K)), _intrinsics(fit.K) - _intrinsics(free.K), jnp.inf)
    widened = eqx.tree_at(lambda b: b.cov, free, free.cov + jnp.outer(dd, dd))
    fit = eqx.tree_at(lambda b: b.y, fit, free.y)  # (the charts differ in size; y is not used beyond here)
    out = jax.tree_util.tree_map(lambda a, b: jnp.where(gate, a, b), fit, widened)
    k = jnp.zeros(2).at[: d.k.shape[0]].set(d.k)
    k_std = jnp.zeros(2).at[: d.k.shape[0]].set(d.k_std)
    return out, (jnp.where(gate, k, jnp.nan), k_std, g, z)


def _bundles(c: _Common, homs: ViewHomologies, aspects, options: Options, fixed=None):
    """The bundles of every aspect model in ``aspects`` (one traced solver,
    ``jax.lax.map``) and the free-aspect fit the model checks compare a known aspect
    ratio with: the one among them when there is one, else one more solve, run only
    when some aspect ratio is known (``jax.lax.cond``; under ``jax.vmap`` both branches
    run).  Returns ``(stacked results, free result)``."""
    k = aspects.shape[0]
    need = jnp.any(jnp.isfinite(aspects)) & ~jnp.any(jnp.isnan(aspects))
    run_aspects = jnp.concatenate([aspects, jnp.full(1, jnp.nan)])
    run = jnp.concatenate([jnp.ones(k, bool), need[None]])
    solve, shape = traced_once(lambda a: _bundle(c, homs, a, options, fixed), aspects[0])
    skip = lambda a: jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shape)  # noqa: E731
    outs = jax.lax.map(lambda ar: jax.lax.cond(ar[1], solve, skip, ar[0]), (run_aspects, run))
    i_free = jnp.where(jnp.any(jnp.isnan(aspects)), jnp.argmax(jnp.isnan(aspects)), k)
    return outs, jax.tree_util.tree_map(lambda x: x[i_free], outs)


def _linear_aspect(method: str, aspect):
    """The aspect ratio a linear method imposes: NaN (free) for IIa, else the known
    one or 1."""
    return jnp.asarray(jnp.nan) if method == "IIa" else jnp.where(jnp.isnan(aspect), 1.0, aspect)


def _homology_cov(c: _Common, homs: ViewHomologies, K, a_m, options: Options):
    """:func:`sorjax.core._covariance.homology_covariance` of the views' fits,
    linearised at the estimate ``K`` (px; the identity where not finite) and the
    fitted axes."""
    Kn = c.T @ jnp.where(jnp.all(jnp.isfinite(K)), K, jnp.eye(3))
    k = pack_seeds(jnp.stack([Kn[0, 0], Kn[1, 1], Kn[0, 2], Kn[1, 2]])[None], jnp.ones(1, bool))[0]
    l_n = jnp.where(c.used[:, None], c.l_n, jnp.asarray([1.0, 0.0, 0.0]))
    return homology_covariance((k, axis_params(l_n)), with_model(c.problem, a_m), c.T, options)


def _linear_cov(c: _Common, homs: ViewHomologies, hc, K, a_m, method: str):
    """The covariance (px^2) of a linear method's own estimate ``K``: its first-order
    propagation from every view's homology fit (``hc``, :func:`_homology_cov`) through
    the method, differentiated by autodiff
    (:func:`sorjax.core._covariance.homology_estimator_covariance`).  NaN where ``K``
    is not finite.  Returns ``(cov, cov_offset)``, the second the part the declared
    outline offset makes."""
    v_n = jnp.where(c.used[:, None], homs.v_x @ c.T.T, jnp.asarray([0.0, 0.0, 1.0]))
    T_inv = jnp.linalg.inv(c.T)

    def estimate(v, l):  # normalised homologies -> the method's (fu, fv, u0, v0) px
        return _intrinsics(linear_estimate(v @ T_inv.T, l @ c.T, c.used, c.T, a_m, method=method)[0])

    cov, cov_off = homology_estimator_covariance(estimate, v_n, hc)
    good = jnp.all(jnp.isfinite(K)) & jnp.all(jnp.isfinite(cov))
    return jnp.where(good, cov, jnp.nan), jnp.where(good, cov_off, 0.0)


def _check_fixed(fixed):
    """``fixed`` as a (4,) float64 array, or None."""
    if fixed is None:
        return None
    fixed = jnp.asarray(fixed, jnp.float64)
    if fixed.shape != (4,):
        raise ValueError(f"fixed must be (fu, fv, u0, v0) px with NaN where free, shape (4,); got {fixed.shape}")
    return fixed


def views_needed(aspect, fixed=None):
    """The fewest used views that can determine the free intrinsics: 2, or 1 when the
    principal point is fixed and at most two intrinsics are free (each view gives two
    constraints, the pole-polar relation ``omega v_x ~ l_s``: with the principal point
    and the aspect ratio known, one view gives the focal length and a redundant
    constraint; with the aspect ratio free, ``fu`` and ``fv`` exactly).  With the
    principal point free one view is never enough, even with the focal length fixed:
    the principal point then lies on the line through ``v_x`` orthogonal to ``l_s`` at
    either root of ``d (D - d) = f^2`` (two cameras fit)."""
    if fixed is None:
        return jnp.asarray(2)
    pp_fixed = jnp.all(jnp.isfinite(fixed[2:]))
    return jnp.where(pp_fixed & (n_free_intrinsics(aspect, fixed) <= 2), 1, 2)


def _per_view(x, n: int, name: str, what: str):
    """``x`` (one number or (n,)) as (n,) float64 with NaN, infinite or negative entries 0, or
    None; a ValueError for any other shape."""
    if x is None:
        return None
    x = jnp.asarray(x, jnp.float64)
    if x.ndim > 1 or (x.ndim == 1 and x.shape[0] != n):
        raise ValueError(f"{name} must be {what} per outline, shape ({n},), or one number; got shape {x.shape}")
    x = jnp.broadcast_to(x, (n,))
    return jnp.where(jnp.isfinite(x) & (x > 0), x, 0.0)


def _check(points, valid, image_size, aspect, noise=None, noise_ell=None):
    points = jnp.asarray(points, jnp.float64)
    valid = jnp.ones(points.shape[0], bool) if valid is None else jnp.asarray(valid, bool)
    image_size = _nan(2) if image_size is None else jnp.asarray(image_size, jnp.float64)
    V = points.shape[0]
    noise = _per_view(noise, V, "noise", "one floor (px)")  # NaN or negative: no floor
    noise_ell = _per_view(noise_ell, V, "noise_ell", "one correlation length (px)")  # NaN or <= 0: unknown
    return points, valid, image_size, jnp.asarray(aspect, jnp.float64), noise, noise_ell


def calibrate_homologies(points: Float[Array, "V M 2"], homs: ViewHomologies, method: str = "bundle", aspect=jnp.nan,
                         *, options: Options = Options(), image_size=None, valid=None,
                         distortion: str = "none", fixed=None, noise=None, noise_ell=None) -> CoreResult:
    """:func:`calibrate` from per-view homologies already fitted (pixels)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    if distortion not in DISTORTION_MODELS:
        raise ValueError(f"distortion must be one of {tuple(DISTORTION_MODELS)}; got {distortion!r}")
    if distortion != "none" and method != "bundle":
        raise ValueError(f"distortion={distortion!r} is estimated by the bundle only; got method={method!r}")
    if fixed is not None and method != "bundle":
        raise ValueError(f"fixed intrinsics are held by the bundle only; got method={method!r}")
    fixed = _check_fixed(fixed)
    points, valid, image_size, aspect, noise, noise_ell = _check(points, valid, image_size, aspect, noise, noise_ell)
    homs = homs if noise is None else with_noise_floor(homs, noise, options)
    c = _common(points, homs, valid, options, noise, noise_ell)
    if distortion != "none":
        out, dist = _distorted(c, homs, aspect, options, distortion, fixed)
        return _finish(points, homs, c, method, aspect, image_size, options, bundle=(out, None), distortion=dist,
                       fixed=fixed)
    if method == "bundle":
        outs, free = _bundles(c, homs, aspect[None], options, fixed)
        b = jax.tree_util.tree_map(lambda x: x[0], outs)
        return _finish(points, homs, c, method, aspect, image_size, options, bundle=b, free=free, fixed=fixed)
    a_m = _linear_aspect(method, aspect)
    K, omega, ok = linear_estimate(homs.v_x, homs.l_s, c.used, c.T, a_m, method=method)
    hc = _homology_cov(c, homs, K, a_m, options)
    free = None
    if method != "IIa":  # the aspect ratio it imposes, checked against Method IIa's
        Kf, _, okf = linear_estimate(homs.v_x, homs.l_s, c.used, c.T, jnp.nan, method="IIa")
        free = (Kf, okf, _linear_cov(c, homs, hc, Kf, jnp.nan, "IIa"))
    return _finish(points, homs, c, method, aspect, image_size, options,
                   linear=(K, omega, ok, _linear_cov(c, homs, hc, K, a_m, method), a_m, free))


def calibrate_methods(points: Float[Array, "V M 2"], homs: ViewHomologies, methods: tuple[str, ...], aspects,
                      *, options: Options = Options(), image_size=None, valid=None,
                      fixed=None, noise=None, noise_ell=None) -> tuple[CoreResult, ...]:
    """:func:`calibrate_homologies` for several ``methods`` (static tuple) with their
    ``aspects`` (one each, NaN: free) at once, as an experiment comparing estimators
    runs them: the bundles of every aspect model share one traced solver
    (``jax.lax.map`` over the aspects), and so do the linear methods' covariances.
    The same numbers as separate calls, a fraction of the compilation.  ``fixed``
    (intrinsics held fixed, px; None: none) applies to the bundle only: the linear
    methods' results ignore it; ``noise`` and ``noise_ell`` as :func:`calibrate`'s."""
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"method must be one of {METHODS}; got {m!r}")
    points, valid, image_size, _, noise, noise_ell = _check(points, valid, image_size, jnp.nan, noise, noise_ell)
    homs = homs if noise is None else with_noise_floor(homs, noise, options)
    aspects = jnp.asarray(aspects, jnp.float64).reshape(len(methods))
    c = _common(points, homs, valid, options, noise, noise_ell)
    ib = [i for i, m in enumerate(methods) if m == "bundle"]
    il = [i for i, m in enumerate(methods) if m != "bundle"]
    fixed = _check_fixed(fixed)
    bundles, free = _bundles(c, homs, aspects[jnp.asarray(ib)], options, fixed) if ib else (None, None)
    lin = {}
    if il:
        a_ms = jnp.stack([_linear_aspect(methods[i], aspects[i]) for i in il])
        ests = [linear_estimate(homs.v_x, homs.l_s, c.used, c.T, a_ms[j], method=methods[i]) for j, i in enumerate(il)]
        # one covariance of the views' fits for every linear method, linearised at the
        # first finite estimate (the point moves it to second order only)
        Ks = jnp.stack([e[0] for e in ests])
        first = jnp.argmax(jnp.all(jnp.isfinite(Ks), axis=(1, 2)))
        hc = _homology_cov(c, homs, Ks[first], a_ms[first], options)
        covs = [_linear_cov(c, homs, hc, ests[j][0], a_ms[j], methods[i]) for j, i in enumerate(il)]
        free = None
        if any(methods[i] != "IIa" for i in il):  # Method IIa's estimate checks the aspect ratio the others impose
            j = next((j for j, i in enumerate(il) if methods[i] == "IIa"), None)
            if j is None:
                Kf, _, okf = linear_estimate(homs.v_x, homs.l_s, c.used, c.T, jnp.nan, method="IIa")
                free = (Kf, okf, _linear_cov(c, homs, hc, Kf, jnp.nan, "IIa"))
            else:
                free = (ests[j][0], ests[j][2], covs[j])
        lin = {i: ests[j] + (covs[j], a_ms[j], None if methods[i] == "IIa" else free) for j, i in enumerate(il)}
    out = []
    for i, m in enumerate(methods):
        if m == "bundle":
            b = jax.tree_util.tree_map(lambda x: x[ib.index(i)], bundles)
            out.append(_finish(points, homs, c, m, aspects[i], image_size, options, bundle=b, free=free, fixed=fixed))
        else:
            out.append(_finish(points, homs, c, m, aspects[i], image_size, options, linear=lin[i]))
    return tuple(out)


def _model_checks(out, scores, free_fit, aspect, c: _Common, options: Options, fixed=None):
    """The model checks of a bundle estimate (:mod:`sorjax.core._checks`): ``(checks,
    cov)`` with ``cov`` the bundle's covariance widened as the checks say."""
    S, delta, n, lens, held = scores
    free_out = free_fit[0]
    a_free, a_std, a_z, a_px, a_rej, a_beyond = fixed_aspect_check(
        aspect, out.K, out.cost, free_out.K, free_out.cov, free_out.cost, free_out.ok, out.n, options,
        free_s2=free_out.s2)
    dof, p, g, v_rej, v_beyond, birge = consistency(S, delta, n, c.used, aspect, options, fixed)
    lens_ok = out.ok & jnp.isfinite(lens.score)
    l_rej, l_beyond = lens.rejected & lens_ok, lens.beyond & lens_ok
    f_rej = f_beyond = jnp.asarray(False)
    if held is not None:
        f_rej, f_beyond = held.rejected & out.ok, held.beyond & out.ok
    # A lens's distortion or a wrong fixed intrinsic also makes the views disagree, and
    # one view of no surface of revolution also moves k1 or a released principal point:
    # of the views and the held parameters the more significant test is to blame
    # (measured: a k1 = -0.05 lens p 5e-26 with the views at p 0.12; a principal point
    # 20 px off p 3e-17 against the views' 3e-16; a flat figure among three views: the
    # views p 1e-19 against k1's 7e-15).
    views_first = lambda p_held: v_rej & (p < p_held)  # noqa: E731
    l_rej, l_beyond = l_rej & ~views_first(lens.p), l_beyond & ~views_first(lens.p)
    if held is not None:
        f_rej, f_beyond = f_rej & ~views_first(held.p), f_beyond & ~views_first(held.p)
    v_rej, v_beyond = v_rej & ~(l_rej | f_rej), v_beyond & ~(l_rej | f_rej)
    d = jnp.where(a_rej & ~a_beyond, _intrinsics(out.K) - _intrinsics(free_out.K), 0.0)
    d_lens = jnp.where(l_rej & ~l_beyond, lens.shift, 0.0)
    d_held = jnp.zeros(4) if held is None else jnp.where(f_rej & ~f_beyond, held.shift, 0.0)
    inflation = jnp.where(v_rej & ~v_beyond, jnp.maximum(birge, 1.0), 1.0)
    cov = out.cov * inflation + jnp.outer(d, d) + jnp.outer(d_lens, d_lens) + jnp.outer(d_held, d_held)
    contradicted = a_beyond | v_beyond | l_beyond | f_beyond
    widened = a_rej | v_rej | l_rej | f_rej
    verdict = jnp.where(contradicted, MODEL_CONTRADICTED, jnp.where(widened, MODEL_WIDENED, MODEL_OK))
    # the culprit: the first of aspect, lens, fixed intrinsics, views that contradicts
    # the model, else the first that widened it
    order = jnp.stack([a_beyond, l_beyond, f_beyond, v_beyond, a_rej, l_rej, f_rej, v_rej])
    names = jnp.array([CULPRIT_ASPECT, CULPRIT_LENS, CULPRIT_FIXED, CULPRIT_VIEWS] * 2)
    culprit = jnp.where(jnp.any(order), names[jnp.argmax(order)], NO_CULPRIT)
    nan = jnp.asarray(jnp.nan)
    checks = ModelChecks(
        outline_error_px=jnp.asarray(options.outline_error_px, jnp.float64), aspect_fixed=jnp.asarray(aspect),
        aspect_free=a_free, aspect_free_std=a_std, aspect_z=a_z, aspect_px=a_px, view_score=S,
        view_px=jnp.where(c.used, jnp.sqrt(delta / jnp.maximum(n, 1.0)), jnp.nan), consistency_dof=dof,
        consistency_p=p, consistency_px=g,
        lens_k1=jnp.where(lens_ok, lens.released[-1], nan), lens_p=jnp.where(lens_ok, lens.p, nan),
        lens_px=jnp.where(lens_ok, lens.px, nan), lens_rejected=l_rej,
        fixed_p=nan if held is None else held.p, fixed_px=nan if held is None else held.px,
        fixed_shift=jnp.full(4, jnp.nan) if held is None else held.shift, fixed_rejected=f_rej,
        inflation=inflation, verdict=verdict.astype(jnp.int32),
        culprit=culprit.astype(jnp.int32), duplicate_of=c.duplicate_of)
    return checks, cov


def _no_checks(aspect, c: _Common, options: Options) -> ModelChecks:
    """The checks of an estimate none were run on (the bundle's own model checks,
    :func:`_model_checks`, need its cost and Jacobian): duplicates found; a linear
    method's aspect check is added by :func:`_linear_checks`."""
    nan = jnp.asarray(jnp.nan)
    V = c.used.shape[0]
    return ModelChecks(
        outline_error_px=jnp.asarray(options.outline_error_px, jnp.float64), aspect_fixed=jnp.asarray(aspect),
        aspect_free=nan, aspect_free_std=nan, aspect_z=nan, aspect_px=nan, view_score=jnp.full(V, jnp.nan),
        view_px=jnp.full(V, jnp.nan), consistency_dof=jnp.asarray(0, jnp.int32), consistency_p=nan,
        consistency_px=nan, lens_k1=nan, lens_p=nan, lens_px=nan, lens_rejected=jnp.asarray(False), fixed_p=nan,
        fixed_px=nan, fixed_shift=jnp.full(4, jnp.nan), fixed_rejected=jnp.asarray(False), inflation=jnp.asarray(1.0),
        verdict=jnp.asarray(MODEL_OK, jnp.int32),
        culprit=jnp.asarray(NO_CULPRIT, jnp.int32), duplicate_of=c.duplicate_of)


def _linear_checks(a_m, K, cov, free, c: _Common, options: Options):
    """The model check of a linear method that imposes an aspect ratio ``a_m`` (Method
    I, IIb): Method IIa's estimate with the aspect ratio free (``free``: ``(K, ok,
    (cov, cov_offset))`` px) puts ``fu / fv`` at ``a_free +- a_std`` (its own
    first-order covariance); ``z = |a_free - a_m| / a_std >= linear_aspect_z`` rejects
    ``a_m``, and the covariance is then widened by ``d d^T`` (``d`` the difference
    between the two estimates' ``(fu, fv, u0, v0)``: the outlines cannot tell which
    is right), the verdict :data:`MODEL_WIDENED` with the aspect ratio to blame (as the
    bundle's check, :func:`sorjax.core._checks.fixed_aspect_check`, without its cost
    comparison: a linear method has none).  Returns ``(checks, cov)``."""
    checks = _no_checks(a_m, c, options)
    if free is None:
        return checks, cov
    Kf, okf, (covf, _) = free
    checked = okf & jnp.all(jnp.isfinite(Kf)) & jnp.isfinite(a_m) & jnp.all(jnp.isfinite(K))
    a_free, a_std = aspect_of(Kf, covf)
    z = jnp.abs(a_free - a_m) / jnp.maximum(a_std, 1e-300)
    rejected = checked & (z >= options.linear_aspect_z)
    d = jnp.where(rejected, _intrinsics(K) - _intrinsics(Kf), 0.0)
    nan = jnp.asarray(jnp.nan)
    checks = eqx.tree_at(
        lambda ch: (ch.aspect_free, ch.aspect_free_std, ch.aspect_z, ch.verdict, ch.culprit), checks,
        (jnp.where(checked, a_free, nan), jnp.where(checked, a_std, nan), jnp.where(checked, z, nan),
         jnp.where(rejected, MODEL_WIDENED, MODEL_OK).astype(jnp.int32),
         jnp.where(rejected, CULPRIT_ASPECT, NO_CULPRIT).astype(jnp.int32)))
    return checks, cov + jnp.outer(d, d)


def _finish(points, homs: ViewHomologies, c: _Common, method: str, aspect, image_size, options: Options, bundle=None,
            linear=None, free=None, distortion=None, fixed=None) -> CoreResult:
    """The verdicts and the result of one method's estimate (``bundle``: a
    :class:`sorjax.core._bundle.BundleOut` and its views' scores, ``free`` the same of the
    free-aspect fit; ``linear``: ``(K, omega, ok, (cov, cov_offset), a_m, free)``, the
    covariances px^2, ``a_m`` the aspect ratio the method imposes (NaN: IIa) and
    ``free`` Method IIa's ``(K, ok, (cov, cov_offset))`` or None; ``fixed``: the
    intrinsics the bundle held fixed, px, or None)."""
    if linear is not None:
        fixed = None
    free_aspect = jnp.isnan(aspect) if method == "bundle" else jnp.asarray(method == "IIa")
    if fixed is not None:
        pp_fixed = jnp.all(jnp.isfinite(fixed[2:]))
        focal_fixed = jnp.isfinite(fixed[1]) & (jnp.isfinite(fixed[0]) | jnp.isfinite(aspect))
    used, n_used, all_inf, radius, rms_u = c.used, c.n_used, c.all_inf, c.radius, c.rms_u
    if bundle is not None:
        out, scores = bundle
        K, omega, ok = out.K, out.omega, out.ok
        if fixed is not None:  # the values held fixed, exactly as given (not through log / exp and T)
            fu_fixed = jnp.where(jnp.isfinite(fixed[0]), fixed[0], jnp.where(focal_fixed, aspect * fixed[1], jnp.nan))
            Kf = intrinsics_matrix(fu_fixed, fixed[1], fixed[2], fixed[3])
            K = jnp.where(jnp.isfinite(Kf), Kf, K)
        if scores is None:  # (the model checks of the pinhole bundle do not apply)
            checks, cov = _no_checks(aspect, c, options), out.cov
        else:
            checks, cov = _model_checks(out, scores, free, aspect, c, options, fixed)
        s_px = jnp.sqrt(out.s2)
        cov_off = out.cov_offset
        offset, offset_std = out.offset, out.offset_std
        persp_ok, g_px, z = perspective_gate(out.evidence, out.n, s_px, options)
        if fixed is not None:  # a fixed focal length needs no evidence for perspective
            persp_ok = persp_ok | focal_fixed
        cost, view_rms, steps, vx, ls = out.cost, jnp.where(used, out.view_rms, jnp.nan), out.steps, out.v_x, out.l_s
        code = RESULTS.where(ok & jnp.all(jnp.isfinite(K)), RESULTS.successful, RESULTS.not_converged)
        assessed = jnp.all(jnp.isfinite(K)) & (K[0, 0] > 0) & (K[1, 1] > 0)
    else:
        K, omega, ok, (cov, cov_off), a_m, free_lin = linear
        offset = offset_std = jnp.full(used.shape[0], jnp.nan)
        floor = c.problem.noise
        rms = homs.rms if floor is None else jnp.maximum(homs.rms, floor / c.T[0, 0])  # (the floors in px)
        s_px = jnp.sqrt(jnp.sum(jnp.where(used, rms, 0.0) ** 2) / jnp.maximum(n_used, 1))
        finite = jnp.all(jnp.isfinite(K))
        persp_ok, g_px, z = jnp.asarray(True), jnp.asarray(jnp.nan), jnp.asarray(jnp.nan)
        cost, view_rms, steps, vx, ls = jnp.asarray(jnp.nan), rms_u, jnp.asarray(0, jnp.int32), homs.v_x, homs.l_s
        code = RESULTS.where(ok, RESULTS.successful,
                             RESULTS.degenerate if method == "I" else RESULTS.not_positive_definite)
        assessed = ok & finite & (K[0, 0] > 0) & (K[1, 1] > 0)
        checks, cov = _linear_checks(a_m, K, cov, free_lin, c, options)

    if distortion is None:
        nan = jnp.asarray(jnp.nan)
        dist_k, dist_std, dist_g, dist_z = jnp.zeros(2), jnp.zeros(2), nan, nan
    else:
        dist_k, dist_std, dist_g, dist_z = distortion
    est = _intrinsics(K)
    rms_radius = jnp.sqrt(jnp.sum(jnp.where(used, radius**2, 0.0)) / jnp.maximum(n_used, 1))
    cov_unit = (cov - cov_off) / jnp.maximum(s_px, 1e-300) ** 2  # the part that scales with the residuals
    verdict = assess(est, cov_unit, s_px, rms_radius, outline_extent(points, used), image_size, free_aspect, all_inf,
                     persp_ok, options, n_used == 1, cov_offset=cov_off)
    determined = verdict.determined & assessed
    success = code == RESULTS.successful

    # every v_x at infinity and no focal length from the estimate: the principal point
    # only, where the imaged axes meet (paper, Section 6)
    pp_only = all_inf & (~success | ~assessed | ~jnp.all(determined[:2]))
    pp, cov_pp, spread = axes_intersection(homs.l_s, used)
    pp_found = jnp.all(jnp.isfinite(pp))
    pp_det = pp_found & principal_point_determined(pp, cov_pp, rms_radius, image_size, options)
    K_pp = jnp.where(pp_det, intrinsics_matrix(jnp.nan, jnp.nan, pp[0], pp[1]), _nan((3, 3)))
    cov_pp4 = _nan((4, 4)).at[0, 0].set(jnp.inf).at[1, 1].set(jnp.inf).at[2:, 2:].set(
        jnp.where(jnp.isfinite(cov_pp), cov_pp, jnp.inf))

    partial = assessed & ~jnp.all(determined)
    code_partial = RESULTS.where(~jnp.any(determined[:2]) & jnp.all(determined[2:]), RESULTS.only_principal_point,
                                 RESULTS.degenerate)
    if fixed is not None:
        # the principal point given: "only the principal point" would be nothing found;
        # every v_x at infinity then leaves the focal length free (the imaged axes all
        # pass through the principal point): degenerate, the fixed principal point in K
        code_partial = RESULTS.where(pp_fixed, RESULTS.degenerate, code_partial)
        no_focal = pp_fixed & pp_only
        pp_only = pp_only & ~pp_fixed
    code = RESULTS.where(partial, code_partial, code)
    K_out = _mask_undetermined(K, determined)
    success = code == RESULTS.successful
    K_out = jnp.where(success | partial, K_out, _nan((3, 3)))
    omega = jnp.where(success, omega, _nan((3, 3)))

    # a model the outlines contradict (a wrong known aspect ratio, views of another
    # camera or of no surface of revolution): refused, whatever the estimate
    contradicted = (checks.verdict == MODEL_CONTRADICTED) & (success | partial)
    code = RESULTS.where(contradicted, RESULTS.inconsistent, code)
    K_out = jnp.where(contradicted, _nan((3, 3)), K_out)
    omega = jnp.where(contradicted, _nan((3, 3)), omega)

    code = RESULTS.where(pp_only, RESULTS.where(pp_det, RESULTS.only_principal_point, RESULTS.degenerate), code)
    K_out = jnp.where(pp_only, K_pp, K_out)
    determined = jnp.where(pp_only, jnp.stack([False, False, pp_det, pp_det]), determined)
    cov = jnp.where(pp_only, jnp.where(pp_found, cov_pp4, _nan((4, 4))), cov)
    omega = jnp.where(pp_only, _nan((3, 3)), omega)
    view_rms = jnp.where(pp_only, rms_u, view_rms)
    vx = jnp.where(pp_only, homs.v_x, vx)
    ls = jnp.where(pp_only, homs.l_s, ls)
    if fixed is not None:
        code = RESULTS.where(no_focal, RESULTS.degenerate, code)
        K_out = jnp.where(no_focal, intrinsics_matrix(jnp.nan, jnp.nan, fixed[2], fixed[3]), K_out)
        cov = jnp.where(no_focal, _nan((4, 4)).at[0, 0].set(jnp.inf).at[1, 1].set(jnp.inf).at[2:, 2:].set(0.0), cov)
        omega = jnp.where(no_focal, _nan((3, 3)), omega)
        determined = jnp.where(no_focal, jnp.array([False, False, True, True]), determined)

    few = n_used < views_needed(aspect, fixed)
    code = RESULTS.where(few, RESULTS.too_few_views, code)
    K_out = jnp.where(few, _nan((3, 3)), K_out)
    cov = jnp.where(few, _nan((4, 4)), cov)
    omega = jnp.where(few, _nan((3, 3)), omega)

    return CoreResult(
        K=K_out, K_raw=K, omega=omega, result=code, covariance=cov, std=verdict.std, determined=determined,
        implausible=verdict.implausible, weak=verdict.weak, aspect_weak=verdict.aspect_weak,
        cost=jnp.asarray(cost, jnp.float64), s_px=s_px, steps=jnp.asarray(steps, jnp.int32), used=used,
        drop_reason=c.drop, view_rms=view_rms, v_x=vx, l_s=ls, all_at_infinity=all_inf,
        perspective_px=jnp.asarray(g_px, jnp.float64), perspective_z=jnp.asarray(z, jnp.float64),
        perspective_ok=jnp.asarray(persp_ok), axes_spread_deg=spread, checks=checks,
        distortion=dist_k, distortion_std=dist_std, distortion_px=dist_g, distortion_z=dist_z,
        outline_offset=offset, outline_offset_std=offset_std,
    )


def _mask_undetermined(K, determined):
    """``K`` with NaN at the intrinsics not determined."""
    nan = jnp.nan
    fu = jnp.where(determined[0], K[0, 0], nan)
    fv = jnp.where(determined[1], K[1, 1], nan)
    u0 = jnp.where(determined[2], K[0, 2], nan)
    v0 = jnp.where(determined[3], K[1, 2], nan)
    return intrinsics_matrix(fu, fv, u0, v0)
