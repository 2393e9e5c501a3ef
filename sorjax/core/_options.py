"""Every threshold of the calibration pipeline, in one documented object.

:class:`Options` is an ``equinox.Module``.  Its sizes and budgets (integers) are
static fields: they fix the compiled program's shapes and loop bounds (except
``measured_leave_out``, which only the shell reads).  Its thresholds
(floats) are ordinary leaves: passed through ``jax.jit`` they are traced, so one
compiled program serves any thresholds (and ``jax.vmap`` can sweep one).  Code in the
core therefore uses the thresholds in array expressions only, never in Python ``if``.  The defaults are the values the measurements in ``docs/results.md`` were
made with; the comments say where each came from.
"""

from __future__ import annotations

import equinox as eqx


class Options(eqx.Module):
    """Thresholds and budgets of the per-view fit, the bundle and the verdicts.

    Sizes and budgets (they fix the compiled program's shapes and loop bounds):

    * ``n_samples``: samples per outline in eq. 20 (the paper's N = 100).
    * ``max_steps``: step limit of the per-view polish (Gauss-Newton, then
      Levenberg-Marquardt).
    * ``bundle_max_steps``: step limit of each bundle solve.
    * ``screen_steps``: loose Levenberg-Marquardt steps that screen every start of the
      per-view fit (measured on 1000 noisy random views: 5 steps started 996 in the
      right basin, 15 steps 997).
    * ``trim_rounds``: robust re-weighting rounds of the per-view fit.
    * ``distortion_screen_steps``: loose Levenberg-Marquardt steps that screen every
      seed of the bundle with distortion before the best are polished (measured: from
      seeds in the right basin the cost reached the noise floor in 7-21 steps; from
      the f -> infinity basin it stalled within 2-10).

    Per-view fit (pixels unless said otherwise):

    * ``trim_k``, ``trim_floor_px``: a sample is an outlier when its residual exceeds
      ``max(trim_k * 1.4826 * median|r|, trim_floor_px)``; never below half of the
      samples are kept.
    * ``infinity_z``: ``v_x`` is at infinity when within this many standard errors of
      the line at infinity.
    * ``conic_ratio``, ``conic_floor_px``: an outline is a conic (no calibration
      information) when its conic residual is at most ``conic_ratio * rms +
      conic_floor_px``.

    Views kept or dropped:

    * ``asymmetry_px``, ``asymmetry_rel``: dropped as not symmetric when the untrimmed
      RMS symmetry residual exceeds both ``asymmetry_px`` and ``asymmetry_rel`` times
      the outline's RMS radius (experiments/degenerate.py: noise of 2 px stays below
      1.4 px; smooth random blobs of 20 % modulation 2.6 px).
    * ``warn_asymmetry_px``: kept with a warning above this.
    * ``max_trimmed``, ``note_trimmed``: dropped when the robust fit trimmed more than
      ``max_trimmed`` of the samples; a note from ``note_trimmed`` on.

    Verdicts on the estimate:

    * ``undetermined``: an intrinsic whose standard deviation exceeds this fraction
      of the focal length (a 3-sigma interval reaching zero) is not determined.
    * ``focal_undetermined``: a focal length from ONE view (principal point fixed)
      whose standard deviation exceeds this fraction of itself is not determined:
      1/6, where the 3-sigma interval of ``w ~ 1 / f^2`` (the vertex's inverse
      distance, which the outline determines linearly) reaches zero, so that no
      finite upper bound of f is supported.  With 1/3 one view almost on the
      principal point's axis gave fv = 451 +- 107 px for a true 1200 (z = -7; issue
      18).  Not applied to several views: on Table 1 (3 views) the focal lengths with
      std between 1/6 and 1/3 of f lay within their std (0-2 of ~100 per cell beyond
      3 std), and 1/6 there refused up to 60 % of Method I's trials at f = 1400 px.
    * ``min_focal_fraction``: a focal length below this fraction of the outlines'
      extent is implausible (more than 90 deg of view).
    * ``max_fov_deg``: with the image size known, a wider field of view is implausible.
    * ``weak_rel_std``, ``residual_floor_px``: warn of weak geometry when a focal
      length's relative std, for a residual of at least ``residual_floor_px``,
      exceeds ``weak_rel_std``.
    * ``outline_error_px``: systematic outline error the symmetry residual does not
      show (0.1 px: good sub-pixel outlines; 0 for synthetic studies).
    * ``outline_offset_px``: the prior standard deviation (px) of a systematic offset
      of the outlines along their normals shared by all of them (an eroded or dilated
      mask, a segmenter's threshold), which the symmetry residuals do not show.  The
      bundle estimates it as a nuisance with this prior, at the larger of this and
      ``outline_error_px`` (:func:`sorjax.core._covariance.offset_fit`): where
      perspective makes it visible its effect on the intrinsics is removed and its
      estimate's uncertainty widens the covariance, elsewhere the prior does; the
      linear methods' covariance includes the prior's effect.  0 by default (the
      outline error's 0.1 px then); outlines traced from masks carry
      :data:`sorjax.MASK_OFFSET_PX` (1 px, ``ImageOutline.outline_offset``), and
      :func:`sorjax.calibrate` takes the largest.  Measured (experiments/outline_bias.py,
      five cameras of photo-like renders, masks eroded or dilated by up to 2 px):
      the focal length moved 0.68 % of f per px of offset without the estimate,
      0.03 % with it.
    * ``measured_undetermined``: with outlines of measured quality (the shell's
      ``calibrate(outline_error="measured")``, outlines found in photographs) an
      intrinsic counts as determined only when its standard deviation, widened by the
      views' leave-one-out (jackknife) spread, is at most this fraction of the focal
      length: 1/60, so that 3 std stay within 5 % of it.  Such outlines carry errors
      (a leak into a shadow, a symmetric piece of clutter taken for an object) that
      their own residuals do not show; a K that one view moves by more than that is
      reported as not determined (issue 17: fv 347 +- 82 px for a true 876 from
      automatically found outlines with three fragments of one object among them).
    * ``measured_leave_out``, ``measured_leave_share``: with outlines of measured
      quality, views the consistency check refuses are left out one at a time (at most
      ``measured_leave_out``, and never below 3 views) while one view holds at least
      ``measured_leave_share`` of the score statistic, and the calibration is run again
      on the others (the shell's :func:`sorjax.calibrate`; the same compiled program,
      the view masked).  One false detection among automatically found outlines (a
      symmetric piece of clutter, 5.4 px from the joint model, score 82.6 of 85) refused
      a camera whose other six outlines were good (issue 17).
    * ``perspective_z``, ``perspective_factor``: the focal length is determined only
      when the best camera with no perspective fits worse by a z-score of at least
      ``perspective_z`` and by at least ``perspective_factor * outline_error_px`` RMS.

    Model checks (:mod:`sorjax.core._checks`):

    * ``consistency_z``: a known aspect ratio is rejected when the free-aspect bundle
      puts it this many standard deviations away (Wald).
    * ``linear_aspect_z``: the aspect ratio Methods I and IIb impose (1, or the known
      one) is not confirmed when Method IIa's free estimate puts it this many of its
      standard deviations away; their covariance then includes the difference between
      the two estimates, with a warning.  Lower than ``consistency_z``: Method IIa's
      aspect ratio is several times less precise than the bundle's (measured: the
      two-sphere scene with fu / fv = 1.1, f = 800 px, noise 0.5 px: IIa put 1 at 2.9
      std while IIb's fu was 4.9 of its own std off; the bundle puts 1 at about 10 std).
      About 5 % of the linear calibrations of a camera with the imposed aspect ratio
      are widened so.
    * ``consistency_p``: the views are inconsistent with one camera when the score
      statistic of releasing every view's homology has a chi-square p-value below this.
    * ``duplicate_px``: an outline within this RMS distance (px) of an earlier one is
      the same view twice.
    * ``check_floor_px``: evidence below this RMS per sample (px) never fails a check:
      the numerical floor of the distance fields (exact outlines fit to < 4e-5 px).
    * ``homology_ratio``: a homology passed in (the shell's ``calibrate(homologies=...)``)
      is refused, naming its view, when its outline's RMS symmetry residual under it
      (eq. 20 at the fit's samples, over the samples it kept) exceeds this many times its
      own fitted residual ``Homology.rms`` (at least ``check_floor_px``): it was fitted
      on another outline.  Measured (``experiments/user_homologies.py``, paper and
      Gaussian noise of 0.5-2 px, four scenes): fitted on the very outline, at most 1
      (447 fits: any ``n_samples``, robust or not, trimmed or not); on the same curve started
      elsewhere, resampled to other ``n_points`` or smoothed by 1 px, at most 1.18; on
      the same views seen with f = 1400 px instead of 800, median 12 and 95 % above 1.5
      (the rest map the outline within 0.3 px of its noise; each of 69 three-view sets
      had a view above 5.8); moved by 2-5 px, 93-99 % above 1.5 (the rest moved along the
      axis); another view 35 and up, another object 2e4 and up.  inf: no check.

    Uncertainty (:func:`sorjax.core._covariance.covariance`, :mod:`sorjax.core._noise`):

    * ``covariance_smooth_px``: the Jacobian of the covariance is read off the
      outlines smoothed along the curve by a Gaussian of this many px (noisy normals
      overstate the information: measured 0.89x / 0.93x / 0.96x the RMS error with the
      noisy outlines / smoothed by 6 px / the noise-free ones, paper noise at 1 px).
    * ``noise_ell_min_px``, ``noise_ell_max_px``: the range of the outline noise's
      correlation length searched (geometric grid).
    """

    n_samples: int = eqx.field(static=True, default=100)
    max_steps: int = eqx.field(static=True, default=100)
    bundle_max_steps: int = eqx.field(static=True, default=200)
    screen_steps: int = eqx.field(static=True, default=5)
    trim_rounds: int = eqx.field(static=True, default=3)
    distortion_screen_steps: int = eqx.field(static=True, default=20)

    trim_k: float = 4.0
    trim_floor_px: float = 0.1
    infinity_z: float = 3.0
    conic_ratio: float = 1.5
    conic_floor_px: float = 1e-3

    asymmetry_px: float = 2.0
    asymmetry_rel: float = 0.01
    warn_asymmetry_px: float = 1.0
    max_trimmed: float = 0.2
    note_trimmed: float = 0.02

    undetermined: float = 1.0 / 3.0
    focal_undetermined: float = 1.0 / 6.0
    min_focal_fraction: float = 0.5
    max_fov_deg: float = 120.0
    weak_rel_std: float = 0.05
    residual_floor_px: float = 0.1
    outline_error_px: float = 0.1
    outline_offset_px: float = 0.0
    measured_undetermined: float = 1.0 / 60.0
    measured_leave_out: int = 2  # read by the shell only: an ordinary leaf, so changing it recompiles nothing
    measured_leave_share: float = 0.5
    perspective_z: float = 3.0
    perspective_factor: float = 3.0
    consistency_z: float = 4.0
    linear_aspect_z: float = 2.0
    consistency_p: float = 1e-4
    duplicate_px: float = 0.25
    check_floor_px: float = 1e-3
    homology_ratio: float = 1.5
    covariance_smooth_px: float = 6.0
    noise_ell_min_px: float = 0.25
    noise_ell_max_px: float = 32.0
