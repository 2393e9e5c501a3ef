"""What the core returns: result codes and the result pytree (arrays only).

:class:`RESULTS` follows ``optimistix.RESULTS``: an ``equinox.Enumeration`` whose items
are arrays under ``jit`` and ``vmap`` (``RESULTS.where(pred, a, b)``); the message of a
code is ``RESULTS[code]``.  :class:`CoreResult` holds arrays only, so a batch of
results stacks along leading axes.
"""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array, Bool, Float, Int

from ._checks import ModelChecks


class RESULTS(eqx.Enumeration):
    """Result codes of a calibration (in the style of ``optimistix.RESULTS``).

    ``Calibration.message`` is the code's text followed by the specifics of the case
    (``Calibration.details``)."""

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
        "Fewer than two views carry calibration information (views whose outline is a "
        "conic or is not symmetric are dropped). Add views of surfaces of revolution "
        "whose profile is visible, from other positions."
    )
    degenerate = (
        "The views do not determine the intrinsics with this method (e.g. fewer than two "
        "views with a finite vanishing point, parallel constraint lines, or a direction "
        "of the intrinsics the views leave free). Add views with the object placed "
        "elsewhere in the image or tilted differently."
    )
    inconsistent = (
        "The outlines contradict the camera model: no single zero-skew pinhole camera "
        "explains them to within their noise and the declared outline error (a wrong "
        "known parameter, views taken by different cameras or zoom settings, or an "
        "outline that is not a surface of revolution)."
    )
    only_principal_point = (
        "The views determine the principal point but not the focal length: in every view "
        "the camera looked (almost) straight at the object's axis, so the vanishing point "
        "v_x is at infinity and the imaged axis l_s passes through the principal point "
        "(paper, Section 6). K holds the principal point (K[0, 2], K[1, 2]; "
        "Calibration.principal_point) and NaN focal lengths. Add a view with the object "
        "away from the image centre, or seen from higher or lower."
    )


class CoreResult(eqx.Module):
    """One calibration from :func:`sorjax.core.calibrate` (arrays; a batch stacks).

    Attributes:
        K: (3, 3) intrinsics, px; NaN where not determined (all NaN on failure).
        K_raw: (3, 3) the estimate before any verdict (may be far off; for messages).
        omega: (3, 3) the image of the absolute conic, px (NaN on failure).
        result: a :class:`RESULTS` item.
        covariance: (4, 4) of ``(fu, fv, u0, v0)``, px^2 (infinite variance for an
            intrinsic the views leave free; NaN for the linear methods, which give none).
        std: (4,) standard deviations used for the verdicts, px.
        determined: (4,) which of ``(fu, fv, u0, v0)`` the views determine.
        implausible: why the raw estimate is implausible (0: it is not; see
            :mod:`sorjax.core._assess`).
        weak: relative std of the focal length when the geometry is weak, else NaN.
        aspect_weak: with a free aspect ratio, fu / fv is poorly determined.
        cost: eq. 20's cost summed over the used views at the estimate, px^2 (bundle).
        s_px: residual standard error, px (each view's residuals counted as at least its noise floor, ``noise``).
        steps: optimiser steps of the bundle (0 for the linear methods).
        used: (V,) views used; ``drop_reason`` (V,) why the others were not
            (:data:`sorjax.core._assess.DROP_REASONS`).
        view_rms: (V,) RMS symmetry residual per view, px: under the joint model for
            the bundle, of the per-view fit for the linear methods (NaN if dropped).
        v_x, l_s: (V, 3) the vertices and axes used (pixels; unit ``v_x``,
            ``a^2 + b^2 = 1`` for ``l_s``).
        all_at_infinity: every used view's ``v_x`` is at infinity.
        perspective_px, perspective_z: the evidence for perspective (bundle; NaN for
            the linear methods), px RMS per sample and as a z-score.
        perspective_ok: the evidence passes the gate (True for the linear methods).
        axes_spread_deg: largest angle between the used imaged axes.
        distortion: (2,) OpenCV's radial coefficients ``(k1, k2)`` of the lens model
            (zeros for a pinhole; NaN when estimated but not determined by the
            outlines); ``distortion_std`` (2,) their standard deviations (0: fixed).
        distortion_px, distortion_z: the evidence for distortion (the fit with ``k = 0``
            worse by this RMS per sample, px, and z-score; NaN for a pinhole).
        checks: the model checks' statistics (:class:`sorjax.core._checks.ModelChecks`;
            run on the bundle's estimate; a linear method's: its aspect check and the
            duplicates).
        outline_offset, outline_offset_std: (V,) each used outline's systematic offset
            along its outward normals (px, positive: outward, a dilated mask), estimated
            by the bundle as a nuisance with the prior
            :attr:`sorjax.Options.outline_offset_px` (its effect is removed from ``K``,
            :func:`sorjax.core._covariance.offset_fit`), and its std; NaN for the linear
            methods and masked views.
    """

    K: Float[Array, "3 3"]
    K_raw: Float[Array, "3 3"]
    omega: Float[Array, "3 3"]
    result: RESULTS
    covariance: Float[Array, "4 4"]
    std: Float[Array, "4"]
    determined: Bool[Array, "4"]
    implausible: Int[Array, ""]
    weak: Float[Array, ""]
    aspect_weak: Bool[Array, ""]
    cost: Float[Array, ""]
    s_px: Float[Array, ""]
    steps: Int[Array, ""]
    used: Bool[Array, " V"]
    drop_reason: Int[Array, " V"]
    view_rms: Float[Array, " V"]
    v_x: Float[Array, "V 3"]
    l_s: Float[Array, "V 3"]
    all_at_infinity: Bool[Array, ""]
    perspective_px: Float[Array, ""]
    perspective_z: Float[Array, ""]
    perspective_ok: Bool[Array, ""]
    axes_spread_deg: Float[Array, ""]
    checks: ModelChecks
    distortion: Float[Array, "2"]
    distortion_std: Float[Array, "2"]
    distortion_px: Float[Array, ""]
    distortion_z: Float[Array, ""]
    outline_offset: Float[Array, " V"]
    outline_offset_std: Float[Array, " V"]

    @property
    def success(self):
        """Boolean array: the result code is ``successful``."""
        return self.result == RESULTS.successful
