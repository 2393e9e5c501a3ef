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

from ._camera import intrinsics_matrix, normalising_transform, omega_vector_from_intrinsics, omega_matrix
from ._homology import DEFAULT_SAMPLES, Homology, fit_homology
from ._bundle import covariance, fit_bundle, unpack_intrinsics, vertices
from ._linear import method_i, method_ii
from ._outline import DEFAULT_POINTS, as_outlines

METHODS = ("bundle", "I", "IIa", "IIb")


class RESULTS(eqx.Enumeration):
    """Result codes of a calibration (in the style of ``optimistix.RESULTS``)."""

    successful = ""
    not_positive_definite = (
        "The image of the absolute conic estimated from these views is not positive "
        "definite: no real camera agrees with them. The views are too noisy or too "
        "few, or an outline is not a surface of revolution. Add views with stronger "
        "perspective (objects off-centre, seen from above or below)."
    )
    not_converged = (
        "The bundle adjustment did not converge. The outlines may not be surfaces of "
        "revolution, or the views may not determine the camera; inspect view_rms."
    )
    too_few_views = (
        "Fewer than two views carry calibration information (conic outlines were dropped). "
        "Add views of surfaces of revolution whose profile is visible, from other positions."
    )
    degenerate = (
        "The views do not determine the intrinsics with this method (e.g. fewer than two "
        "views with a finite vanishing point, or parallel constraint lines). Add views "
        "with the object placed elsewhere in the image or tilted differently."
    )


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
        used: indices of the views used (conic outlines are dropped with a warning);
            ``view_rms``, ``v_x`` and ``l_s`` refer to these views, ``homologies`` to all.
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

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``(fu, fv, u0, v0)`` in px (NaN when unknown)."""
        return np.sqrt(np.diag(np.asarray(self.covariance)))

    @property
    def fu(self) -> float:
        return float(self.K[0, 0])

    @property
    def fv(self) -> float:
        return float(self.K[1, 1])

    @property
    def u0(self) -> float:
        return float(self.K[0, 2])

    @property
    def v0(self) -> float:
        return float(self.K[1, 2])

    @property
    def success(self) -> bool:
        return bool(self.result == RESULTS.successful)

    @property
    def message(self) -> str:
        return RESULTS[self.result]

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
    A = np.diag([1.0 / a, 1.0, 1.0])
    v = np.stack([np.asarray(h.v_x) for h in homologies]) @ (T @ A).T
    l = np.stack([np.asarray(h.l_s) for h in homologies]) @ np.linalg.inv(T @ A)
    v, l = jnp.asarray(v), jnp.asarray(l)
    if method == "I":
        fu, fv, u0, v0, ok = method_i(v, l)
        code = RESULTS.where(ok, RESULTS.successful, RESULTS.degenerate)
    else:
        fu, fv, u0, v0, ok, _ = method_ii(v, l, unit_aspect=(method == "IIb"), weights=weights)
        code = RESULTS.where(ok, RESULTS.successful, RESULTS.not_positive_definite)
    Kn = intrinsics_matrix(fu, fv, u0, v0)
    K = jnp.asarray(np.linalg.inv(A) @ np.linalg.inv(T)) @ Kn
    omega_n = omega_matrix(omega_vector_from_intrinsics(fu, fv, u0, v0))
    TA = jnp.asarray(T @ A)
    omega = TA.T @ omega_n @ TA
    return K, omega, code


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
    K, omega, code = _linear_once(homologies, method, T, a, weights)
    if method == "I":
        return K, omega, code
    guess = K if bool(code == RESULTS.successful) else None
    if guess is None:
        K_i, _, code_i = _linear_once(homologies, "I", T, a)
        guess = K_i if bool(code_i == RESULTS.successful) else None
    if guess is not None and np.all(np.isfinite(np.asarray(guess))):
        K2, omega2, code2 = _linear_once(homologies, method, conditioning_from_K(guess, a), a, weights)
        if bool(code2 == RESULTS.successful) or not bool(code == RESULTS.successful):
            return K2, omega2, code2
    return K, omega, code


def _bundle_calibration(outs, homologies, T, aspect_ratio, n_samples, all_homologies, used) -> Calibration:
    """Seed the 2V+4 (or 2V+3) bundle with every linear method that succeeds (IIa,
    IIb and I; with a known aspect ratio their estimates are projected onto it) and
    keep the solution of lowest cost: one linear seed can be far off when a view is
    weak.  With no positive-definite linear seed, a spread of plausible cameras."""
    scale = 1.0 / T[0, 0]
    a = 1.0 if aspect_ratio is None else float(aspect_ratio)
    seeds = []
    for m in ("IIa", "IIb", "I"):
        K, _, code = linear_calibration(homologies, m, T, None if m == "IIa" else a)
        if bool(code == RESULTS.successful):
            Kn = T @ np.asarray(K)
            fu, fv = Kn[0, 0], Kn[1, 1]
            if aspect_ratio is not None:
                fv = np.sqrt(fu * fv / a)
                fu = a * fv
            if np.all(np.isfinite([fu, fv, Kn[0, 2], Kn[1, 2]])) and fu > 0 and fv > 0:
                seeds.append((fu, fv, Kn[0, 2], Kn[1, 2]))
    if not seeds:
        seeds = [(a * f, f, 0.0, 0.0) for f in (2.0, 5.0, 12.0)]
    pts_n = np.stack([np.asarray(o.points) @ T[:2, :2].T + T[:2, 2] for o in outs])
    v_n = np.stack([T @ np.asarray(h.v_x) for h in homologies])
    y, res, steps, r, problem = fit_bundle(pts_n, v_n, seeds, aspect_ratio, n_samples)
    cov, _ = covariance(y, problem, jnp.asarray(T))
    fu, fv, u0, v0 = unpack_intrinsics(y[0], problem.aspect)
    Kn = intrinsics_matrix(fu, fv, u0, v0)
    K = jnp.asarray(np.linalg.inv(T)) @ Kn
    omega = jnp.linalg.inv(K).T @ jnp.linalg.inv(K)
    ok = (res == optx.RESULTS.successful) & jnp.all(jnp.isfinite(K))
    code = RESULTS.where(ok, RESULTS.successful, RESULTS.not_converged)
    rv = r.reshape(len(outs), -1) * scale
    view_rms = jnp.sqrt(jnp.mean(rv**2, axis=1))
    cost = jnp.sum(rv**2)
    K = jnp.where(ok, K, jnp.nan)
    vx = vertices(y[1], problem.v0, problem.E) @ jnp.asarray(np.linalg.inv(T)).T
    vx = vx / jnp.linalg.norm(vx, axis=1, keepdims=True)
    ls = vx @ omega
    ls = ls / jnp.linalg.norm(ls[:, :2], axis=1, keepdims=True)
    a = None if aspect_ratio is None else float(aspect_ratio)
    return Calibration(K, omega, all_homologies, code, cov, cost, view_rms, steps, vx, ls, "bundle", a, used)


def calibrate(
    outlines,
    method: str = "bundle",
    aspect_ratio: float | None = None,
    *,
    n_samples: int = DEFAULT_SAMPLES,
    n_points: int = DEFAULT_POINTS,
    homologies=None,
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
        throw: raise :class:`CalibrationError` instead of returning a failed result.

    Returns:
        :class:`Calibration` with ``K`` (pixels) and a result code.
    """
    _check_method(method, aspect_ratio)
    outs = as_outlines(outlines, n_points)
    if len(outs) < 2:
        raise ValueError(
            f"calibration needs at least two outlines (views) of surfaces of revolution; got "
            f"{len(outs)}. One outline gives only its own axis l_s and vanishing point v_x "
            "(use sorjax.fit_homology), i.e. two of the four intrinsics' constraints."
        )
    if homologies is None:
        homologies = tuple(fit_homology(o, n_samples=n_samples, n_points=n_points) for o in outs)
    elif len(homologies) != len(outs):
        raise ValueError(f"got {len(homologies)} homologies for {len(outs)} outlines.")
    for i, h in enumerate(homologies):
        if not bool(h.converged):
            warnings.warn(f"view {i}: the homology fit did not converge (rms {float(h.rms):.3g} px).", stacklevel=2)
    used = []
    for i, h in enumerate(homologies):
        if h.is_conic:
            warnings.warn(
                f"view {i}: the outline is a conic to within {float(h.conic_rms):.2g} px (its symmetry "
                f"residual is {float(h.rms):.2g} px), like a sphere or a bowl seen from above showing "
                "only its rim: infinitely many homologies fit it, so it carries no calibration "
                "information (paper, Section 6). Dropped; use views where the body's profile shows.",
                stacklevel=2,
            )
        else:
            used.append(i)
    homologies = tuple(homologies)
    a = None if method in ("IIa",) or (method == "bundle" and aspect_ratio is None) else (
        1.0 if aspect_ratio is None else float(aspect_ratio)
    )
    if len(used) < 2:
        nan3, nan4 = jnp.full((3, 3), jnp.nan), jnp.full((4, 4), jnp.nan)
        cal = Calibration(
            nan3, nan3, homologies, RESULTS.too_few_views, nan4, jnp.asarray(jnp.nan),
            jnp.zeros((0,)), jnp.asarray(0), jnp.zeros((0, 3)), jnp.zeros((0, 3)), method, a, tuple(used),
        )
        if throw:
            raise CalibrationError(cal.message)
        return cal
    outs_u = [outs[i] for i in used]
    homs_u = tuple(homologies[i] for i in used)
    T = normalising_transform(np.concatenate([np.asarray(o.points) for o in outs_u]))
    if method == "bundle":
        cal = _bundle_calibration(outs_u, homs_u, T, aspect_ratio, n_samples, homologies, tuple(used))
    else:
        K, omega, code = linear_calibration(homs_u, method, T, aspect_ratio)
        nan = jnp.full((4, 4), jnp.nan)
        rms = jnp.stack([h.rms for h in homs_u])
        vx = jnp.stack([h.v_x for h in homs_u])
        ls = jnp.stack([h.l_s for h in homs_u])
        cal = Calibration(
            K, omega, homologies, code, nan, jnp.asarray(jnp.nan), rms, jnp.asarray(0), vx, ls, method, a, tuple(used)
        )
    if throw and not cal.success:
        raise CalibrationError(cal.message)
    return cal
