"""The thresholds :func:`sorjax.calibrate` judges its input and estimates by, as module
constants (px unless said otherwise): the defaults of :class:`sorjax.core.Options`,
where the values live, with the measurements behind them."""

from __future__ import annotations

from .core._options import Options

# ------------------------------------------------------------ degenerate geometry

# A view is dropped as "not a surface of revolution" when its per-view symmetry
# residual (eq. 20, RMS) exceeds ASYMMETRY_PX *and* ASYMMETRY_REL of the outline's
# RMS radius.  Measured (experiments/degenerate.py, 24 views of random SORs): exact
# outlines fit to < 4e-5 px; with the paper's noise of sigma = 2 px the residual stays
# below 0.7 px, with i.i.d. Gaussian noise of 2 px below 1.4 px (1.8 px in a wider
# probe); smooth random blobs gave 2.6 px (median; 75 % above 2 px) for a radius
# modulation of 20 %, 4.8 px (all above 2 px) for 35 %.  So only clearly asymmetric
# outlines are caught: a mild asymmetry is indistinguishable from noise by this
# residual.  Between WARN_ASYMMETRY_PX and the
# threshold the view is kept with a warning.
_O = Options()  # the defaults; the values live in sorjax.core.Options
ASYMMETRY_PX = _O.asymmetry_px
ASYMMETRY_REL = _O.asymmetry_rel
WARN_ASYMMETRY_PX = _O.warn_asymmetry_px
# The robust per-view fit trims samples with no mirror image (a handle, a shadow); a
# view that needs more than MAX_TRIMMED of its samples trimmed is not a surface of
# revolution, and from NOTE_TRIMMED on the trimming is reported.  Measured: a smooth
# 8 px handle over 12 % of a vase's outline trims 14 % (the handle and its mirror
# image); GrabCut outlines of ycb-video cans that leaked into the background trimmed
# 15-22 % and, kept, gave a confident wrong K: hence 20 %, and the symmetry test on the
# untrimmed residual.
MAX_TRIMMED = _O.max_trimmed
NOTE_TRIMMED = _O.note_trimmed
# An intrinsic is "not determined" when its standard deviation (the covariance at the
# estimate, scaled by the residual -- at least RESIDUAL_FLOOR_PX when every v_x is at
# infinity) is infinite or above UNDETERMINED times the focal length (for the
# principal point: times the outlines' RMS radius when the focal length itself is not
# determined): a 3-sigma interval reaching zero.  A focal length from one view: above
# FOCAL_UNDETERMINED times itself (the 3-sigma interval of 1 / f^2 reaching zero).
UNDETERMINED = _O.undetermined
FOCAL_UNDETERMINED = _O.focal_undetermined
# A focal length below MIN_FOCAL_FRACTION of the extent of the outlines (their
# bounding box's larger side, px) would put them across more than 90 degrees of view,
# where a lens without distortion (sorjax's model) is implausible: a collapsed
# estimate, never "determined" -- nor is the principal point estimated with it.  Seen
# on real photographs with weak perspective and imperfect outlines: f fell to 1..25 px,
# and to 168 px (nocs-real275, true 590) and 177 px (ycb-video, true 1067) with a std
# of 13-15 px and the principal point 7 to 20 std off.
MIN_FOCAL_FRACTION = _O.min_focal_fraction
# With the image size known (``calibrate(image_size=...)``), an estimate is also
# implausible when it gives the image a field of view above MAX_FOV_DEG across (wider
# lenses are fisheyes, far from a pinhole without distortion) or puts the principal
# point outside the image.  (ycb-video, true f 1067 px: f 177 +- 13 px, a 122 deg view
# of its 640 px width -- caught only by this bound, narrowly.)
MAX_FOV_DEG = _O.max_fov_deg
# Weak geometry: warn when the relative standard deviation of a focal length exceeds
# WEAK_REL_STD, the covariance scaled by the residual but at least RESIDUAL_FLOOR_PX
# (about the accuracy of good sub-pixel outlines), so that a configuration that only
# noise-free outlines could calibrate is flagged too.
WEAK_REL_STD = _O.weak_rel_std
RESIDUAL_FLOOR_PX = _O.residual_floor_px
# Perspective evidence (bundle).  Only perspective fixes the focal length, and under
# weak perspective an outline shows very little of it (a 5 % focal error changes the
# symmetry of typical outlines by about 0.25 px).  Systematic errors of the outlines
# (segmentation bias, lens distortion, an object that is not quite a surface of
# revolution) hide from the symmetry residual but can fake or cancel that much, and the
# bundle's covariance, a linearisation at its own estimate, can then be confident far
# from the truth.  So the focal length counts as determined only when the best camera
# with no perspective (:func:`sorjax.core._bundle.orthographic_cost`) fits the outlines worse
# by a cost delta with sqrt(delta / s^2) >= PERSPECTIVE_Z (the noise cannot explain it)
# and sqrt(delta / n) >= PERSPECTIVE_FACTOR * outline_error px (nor can a systematic
# error of the outlines of `outline_error` px RMS: a fully aligned one changes the cost
# by n outline_error^2).  Measured: the real photographs of nvlabs-6dof-graspnet
# (experiments/realdata.py; approximate masks) show 0.20 to 0.22 px of perspective and
# gave f 271 +- 16 px for a true 616 without this gate; the two-sphere scene shows 0.7
# to 0.8 px at f = 700 and 0.14 to 0.28 px at f = 1400 (1 to 2 px of noise); rendered
# objects near the image centre at f = 1250 to 1500 px 0.23 to 0.24 px.
OUTLINE_ERROR_PX = _O.outline_error_px
PERSPECTIVE_Z = _O.perspective_z
PERSPECTIVE_FACTOR = _O.perspective_factor
