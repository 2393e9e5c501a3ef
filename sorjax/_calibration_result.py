"""The result of :func:`sorjax.calibrate`: :class:`Calibration` (the estimated
intrinsics in pixels, their covariance in px^2, the per-view fits and every text the
calibration reported) and :class:`CalibrationError`, and how the core's result (numpy)
becomes a :class:`Calibration`."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._homology import Homology
from .core._checks import ModelChecks
from .core._result import RESULTS
from ._messages import _code_item


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
        outline_offset, outline_offset_std: per used view (the order of ``used``), the
            outline's systematic offset along its outward normals (px; positive: the
            outline lies outside the object's true edge, a dilated mask) that the
            bundle estimated as a nuisance, with the prior
            :attr:`sorjax.Options.outline_offset_px` (or the outline error, or the
            outlines' own ``outline_offset``, the largest): ``K`` has its effect
            removed and the standard deviations include what is left of it.  NaN for
            the linear methods (their standard deviations include the prior's effect).
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
    outline_offset: Float[Array, " V"] | None = None
    outline_offset_std: Float[Array, " V"] | None = None

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
        pp_fixed, f_fixed, jnp.asarray(r.outline_offset[r.used]), jnp.asarray(r.outline_offset_std[r.used]),
    )
