"""The quality of the outlines a calibration allows for: the outline error (px) raised
to what outlines on a pixel grid carry at least, the outlines' own error estimates,
the outline error measured from the outlines (``calibrate(outline_error="measured")``)
and, for such outlines, the view the consistency check blames almost alone (left out
by :func:`sorjax.calibrate`)."""

from __future__ import annotations

import math
from typing import Sequence

import jax.numpy as jnp
import numpy as np

from ._outline import BINARY_MASK_PX, PIXEL_TRACE_NOTE, implied_outline_error, jagged_note
from .core._assess import USED, outline_radius, view_verdicts
from .core._checks import CULPRIT_VIEWS
from .core._options import Options
from .core._viewfit import ViewHomologies
from ._messages import code_name
from ._calibration_checks import _is_number
from ._calibration_thresholds import OUTLINE_ERROR_PX


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
