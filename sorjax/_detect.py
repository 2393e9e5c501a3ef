"""Finding surfaces of revolution in a photograph without boxes, and moving outlines
onto the image's edges.

Object finding (:func:`find_objects`)
-------------------------------------
Proposals (regions on the image reduced to at most ``DetectOptions.max_side`` px) come
from several cues, because no single one survives every background:

* ``border``: GrabCut initialised with the whole image but a border band as probable
  foreground (a plain background reaching the border all round);
* ``saliency``: frequency-tuned saliency (Achanta et al., CVPR 2009): the distance, in
  Lab, of the blurred image from the image's mean colour, thresholded by Otsu, and the
  spectral residual (Hou and Zhang, CVPR 2007) of each Lab channel;
* ``colour``: mean-shift filtering, then k-means of the Lab colours (lightness weighted
  down, so that a shaded object stays one cluster); each cluster's connected regions;
* ``smooth``: regions of low edge density (Canny edges per unit area), where a smooth,
  shaded object differs from a textured table or patterned wall.

A region is a proposal when its area lies between ``min_area_frac`` and
``max_area_frac`` of the image, it keeps clear of the border band and its solidity
(area / convex hull area) is at least ``min_solidity``; proposals whose boxes overlap by
more than ``same_iou`` are one.  Each proposal is segmented on the reduced image by
GrabCut from its box grown by ``box_grow`` (as for a user's box), and judged by the
symmetry of its outline (a segmentation refused as not symmetric, or running out of
its box after ``grow_rounds`` growths, is tried again from the box grown by each of
``retry_grow``: the margin decides GrabCut's background sample, and a metal or glossy
object on a table of like colour is cut whole from one margin and not from another):
the harmonic homology fitted to it (:func:`sorjax.fit_homology`, robust) must map the
outline onto itself within ``symmetry_px`` px RMS (or ``symmetry_rel`` of the outline's
size when larger), over at least ``min_inliers`` of
its samples, before trimming within ``untrimmed_factor`` times that, and it must not be
a polygon of at most ``polygon_vertices`` straight sides (within ``polygon_rel`` of its
size plus ``polygon_px``, the rounding of its corners by blur and segmentation: a tile,
a box face, a wallpaper pattern, which are symmetric too).  A surface of
revolution's outline does (a mug's handle is trimmed); a leak into the background, two
objects merged, a box or other clutter do not.  A kept segmentation whose fit trimmed
more than ``1 - recut_inliers`` of its outline, and one refused as a leak (symmetric
once trimmed, but not before), is cut again by its own symmetry
(:func:`symmetric_recut`): where the region and its mirror image under the fitted
homology disagree, GrabCut starts from background, so that a one-sided leak (a
shadow, a patch of table) or bite is dropped or filled by the colours, and the judge
looks again.  The refined full-resolution outline is cut the same way when its fit
trims more than ``1 - recut_inliers`` of it (:func:`mirror_grabcut`, called by
``sorjax._extract._finish_all``, boxes included).  Of symmetric segmentations
that overlap (by more than ``overlap`` of the smaller) the largest is kept: a part of an
object (one bulb of a lying vase) may be symmetric too.  Each proposal dropped that
overlaps no kept object is reported with its reason.

Edge refinement (:func:`refine_to_edges`)
-----------------------------------------
Each outline point ``x_i`` (0.5 px apart) is moved along its outward normal ``n_i`` to
the object/background edge of the colour image: the image (blurred by ``edge_blur``
px) is sampled on ``x_i + t n_i``, ``|t| <= reach`` in steps of ``step`` px; the
colour profile is projected on its own step direction ``c_i`` (outside mean minus
inside mean) and the edge is the maximum of its derivative, located to a fraction of
a sample by a parabola through the three samples around it.  A point is rejected as
ambiguous when the colour step ``|c_i|`` is below ``min_contrast`` grey levels, when
the peak is weaker than ``weak_peak`` times the outline's median peak, when a second
peak at least ``second_peak`` times as high lies more than ``peak_gap`` px away
(shadow, reflection, the object's own texture), when the peak is more than
``max_width`` times as wide as the outline's lower-quartile peak (a soft shadow; two
equal edges 1.5 px apart under a blur of about 0.9 px merge into one peak only 1.2 times
as wide, which is not told from shading and is kept), when ``c_i`` turns by more than
``max_turn_deg`` from its neighbours' median step (an inconsistent colour step), or
when the peak is at the end of the search.  The accepted offsets are smoothed along
the outline (Gaussian-weighted local quadratic of ``curve_sigma`` px of arc, offsets
more than ``clip_k`` robust standard deviations from it dropped once) and the outline
moves by the smooth offset; where no point is accepted within the smoothing window it
stays where it was.

The outline's error (px RMS, ``ImageOutline.outline_error``) is estimated from the
data (:func:`outline_quality`): ``sqrt(e^2 + r^2)``, ``r`` the RMS symmetry residual of
the harmonic homology fitted to the outline (the larger of the trimmed and the
untrimmed one) and ``e = sqrt(s^2 / n_eff + b^2 + q^2)``
with ``s`` the robust scatter of the accepted
edge points about the smooth curve, ``n_eff`` the number of accepted points per
smoothing window, ``b`` the RMS of the offsets between the two independent edge
estimates (the unmixed segmentation and the gradient maximum: what either may carry as
bias), and ``q`` the rejected fraction times ``reject_px`` (where the edge could not be
confirmed).

Symmetric averaging (:func:`symmetric_average`)
-----------------------------------------------
A refined outline and its own mirror image under its fitted homology are two estimates of
one curve.  The outline moves to their average, weighted by where the image confirms the
edge (``unconfirmed_weight`` where it does not): a bite or bump on one side takes the
mirror image of the other, and the two sides' independent errors are averaged (where they
disagree by more than ``average_px``; 0 by default: everywhere).  The error attributes are
those of the outline before the averaging, and ``noise_rms`` its symmetry residual then:
the noise the averaged outline no longer shows, which the calibration takes as the view's
noise floor.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import cv2
import numpy as np

__all__ = ["DetectOptions", "ImageOutline", "find_objects", "outline_quality", "refine_to_edges"]


@dataclass(frozen=True)
class DetectOptions:
    """Thresholds of the automatic object finding and of the edge refinement (see the
    module docstring); lengths in pixels of the full-resolution image unless said."""

    # proposals (on the image reduced to max_side px)
    max_side: int = 640
    border_frac: float = 0.015  # border band, fraction of the smaller side (>= 5 px reduced)
    min_area_frac: float = 2e-3
    max_area_frac: float = 0.5
    min_solidity: float = 0.35
    same_iou: float = 0.7  # proposal boxes overlapping more are one proposal
    max_proposals: int = 24
    clusters: int = 8  # k-means clusters of the colour cue
    edge_window: int = 9  # reduced px: window of the edge density
    # segmentation and judge
    box_grow: float = 0.15  # GrabCut rectangle: the box grown by this fraction of its larger side ...
    box_grow_min: int = 8  # ... and at least this many px
    symmetry_px: float = 1.0  # RMS symmetry residual (trimmed) of a kept outline, px ...
    symmetry_rel: float = 0.006  # ... or this fraction of its larger extent, when larger
    # the untrimmed residual within this many times the limit: on the photo sets (seeds 0, 7) the outlines
    # within 1 px of the truth had 0.2-0.9 times the limit, the leaks and shadows kept at 4 (3-21 px off) 1.6-2.6
    untrimmed_factor: float = 1.5
    polygon_vertices: int = 6  # an outline within polygon_rel of its size plus polygon_px from a polygon of
    polygon_rel: float = 0.01  # this many vertices (tiles, box faces) is not a surface of revolution's
    # ... polygon_px (reduced px): what blur and GrabCut round off a polygon's corners; with
    # polygon_rel alone a box face with corners rounded by 2-3 px passed (photo sets 0 and 7,
    # 3 cameras: the false detections kept had 3-8 vertices at 1.5 + 1 % of the size, 20 of
    # 25 at most 6 on set 7; the true objects 11-24, none below 11 at 1.0-2.0 px)
    polygon_px: float = 1.5
    min_inliers: float = 0.7  # fraction of the homology fit's samples kept by its trimming
    overlap: float = 0.3  # kept segmentations overlapping more (intersection / smaller area) are one object
    grow_rounds: int = 2  # a segmentation reaching its box's sides: the box grown that way, this many times
    grow_step: float = 0.5  # ... by this fraction of its size
    recut_inliers: float = 0.97  # a kept segmentation whose homology fit trims more is re-cut by its symmetry
    recut_px: float = 2.0  # reduced px: the sure-foreground margin and background band of the re-cut
    recut_gain: float = 0.8  # the re-cut replaces the segmentation when its untrimmed residual is this much lower
    # a proposal whose segmentation is not symmetric, or runs out of its box (grown grow_rounds times) other
    # than at the image border, is segmented again from its box grown by each of these (instead of box_grow)
    # until one is kept: GrabCut's colour models, and so its cut of a glossy or metal object against a table
    # of like colour, change with the background sample the margin gives
    retry_grow: tuple = (0.08, 0.3)
    # edge refinement
    reach: float = 2.5
    side_px: float = 1.5  # the colours on each side: means over reach to reach + side_px px from the outline
    prior_px: float = 0.75  # local maxima weighted by a Gaussian of this std (px) about the segmentation's edge
    step: float = 0.25
    edge_blur: float = 0.7
    normal_sigma: float = 2.0  # px of arc: Gaussian derivative giving the normals
    min_contrast: float = 12.0  # grey levels (8-bit units) of the colour step
    weak_peak: float = 0.35
    second_peak: float = 0.6
    peak_gap: float = 1.0
    max_turn_deg: float = 35.0
    max_width: float = 1.5  # a peak wider than this times the outline's lower-quartile width is two edges
    curve_sigma: float = 3.0  # px of arc
    clip_k: float = 3.0
    move_px: float = 0.3  # the outline moves only where the edge lies farther than this (see refine_to_edges)
    min_support: float = 0.3  # fraction of a smoothing window's points accepted for the outline to move
    reject_px: float = 0.5
    # automatic finding only: an outline whose estimated error (outline_quality) is larger is dropped.  On the
    # photo sets (seeds 0 and 7, 3 cameras x 4 images) the outlines kept within 1 px of an object had 0.12-0.96
    # px; 21 of 31 false detections (box faces, wedges, parts of objects) and 5 of 8 outlines 1.3-54 px off
    # had more than 1 px, 11 and 4 more than 1.5 px
    max_error_px: float = 1.5
    # symmetric averaging (symmetric_average): the weight of a point whose edge refine_to_edges did not
    # confirm, against 1 for a confirmed one (an unconfirmed point whose mirror partner is confirmed takes
    # the partner's mirror image for 5/6), the weights smoothed along the outline by a Gaussian of
    # weight_sigma px of arc (no step where the confirmation changes).  Chosen on random_photo_set seeds
    # 100-129 (161 outlines; median RMS 0.378 px with 0.05 and no smoothing, 0.363 px with these)
    unconfirmed_weight: float = 0.2
    weight_sigma: float = 2.0
    # ... taken where a point and its mirror partner disagree by more than average_px (all of it beyond
    # twice that, a ramp between, smoothed as the weights); 0 (default): everywhere.  The residuals an
    # outline averaged everywhere no longer shows go to the calibration as its noise floor
    # (ImageOutline.noise_rms); without that floor, random_photo_set seed 122's camera was refused as
    # inconsistent (0.099 px of residual taken for the whole noise), with it calibrated within 0.1 %
    # (session 24).  1 px averages only the defects (median RMS 0.43 px against 0.36 px)
    average_px: float = 0.0


class ImageOutline(np.ndarray):
    """An outline (N, 2) float64 array in pixels, with what the image said about it.

    Attributes
    ----------
    outline_error : float
        Estimated RMS distance (px) of the outline from the object's true edge,
        from the data (see :mod:`sorjax._detect`'s "Edge refinement"); NaN when the
        outline was not refined on the image.
    edge_contrast : float
        Median colour step (8-bit grey levels) across the accepted edge points.
    accepted : float
        Fraction of the outline's points whose edge was confirmed on the image.
    symmetry_rms : float
        RMS symmetry residual (px) of the robust harmonic homology fitted to the
        refined outline, before it was averaged with its mirror image (without
        refinement: to the segmentation's outline when the object was found
        automatically, NaN with a box).
    noise_rms : float
        RMS symmetry residual (px) of the refined outline before it was averaged with
        its own mirror image (:func:`symmetric_average`; NaN when it was not): the
        noise that the averaged outline no longer shows, which :func:`sorjax.calibrate`
        takes as each view's noise floor (its ``outline_noise``).
    noise_ell : float
        The correlation length along the curve (px) of that noise, read off the same
        fit's residuals (:attr:`sorjax.Homology.noise_ell`; NaN when not averaged):
        :func:`sorjax.calibrate`'s ``outline_noise_ell``.

    Arithmetic returns plain arrays' values with these attributes copied; use
    ``np.asarray(o)`` for a plain array."""

    outline_error: float
    edge_contrast: float
    accepted: float
    symmetry_rms: float
    noise_rms: float
    noise_ell: float

    #: the attributes above, in order (what :func:`sorjax.save_outlines` keeps)
    ATTRIBUTES = ("outline_error", "edge_contrast", "accepted", "symmetry_rms", "noise_rms", "noise_ell")

    def __new__(cls, points, *, outline_error=math.nan, edge_contrast=math.nan, accepted=math.nan,
                symmetry_rms=math.nan, noise_rms=math.nan, noise_ell=math.nan):
        obj = np.asarray(points, dtype=np.float64).view(cls)
        obj.outline_error = float(outline_error)
        obj.edge_contrast = float(edge_contrast)
        obj.accepted = float(accepted)
        obj.symmetry_rms = float(symmetry_rms)
        obj.noise_rms = float(noise_rms)
        obj.noise_ell = float(noise_ell)
        return obj

    def __array_finalize__(self, obj):
        for k in self.ATTRIBUTES:
            setattr(self, k, getattr(obj, k, math.nan))

    def __reduce__(self):  # pickles (worker processes) keep the attributes
        base = super().__reduce__()
        return base[0], base[1], (base[2], self.__dict__)

    def __setstate__(self, state):
        arr_state, attrs = state
        super().__setstate__(arr_state)
        self.__dict__.update(attrs)


# ----------------------------------------------------------------------------------
# Proposals
# ----------------------------------------------------------------------------------


def _reduce(img: np.ndarray, max_side: int) -> tuple[np.ndarray, float]:
    H, W = img.shape[:2]
    s = min(1.0, max_side / max(H, W))
    if s == 1.0:
        return img, 1.0
    return cv2.resize(img, (max(16, round(W * s)), max(16, round(H * s))), interpolation=cv2.INTER_AREA), s


def _regions(mask: np.ndarray, cue: str, band: int, o: DetectOptions, out: list) -> None:
    """Append ``(cue, region)`` for each connected region of ``mask`` that may be an
    object (size, clear of the border band, solidity)."""
    h, w = mask.shape
    m = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    for c in range(1, n):
        x, y, bw, bh, area = stats[c]
        if not (o.min_area_frac * h * w <= area <= o.max_area_frac * h * w) or min(bw, bh) < 8:
            continue
        if x <= band or y <= band or x + bw >= w - band or y + bh >= h - band:
            continue
        comp = (lab[y:y + bh, x:x + bw] == c).astype(np.uint8)
        cnts, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        hull = cv2.convexHull(np.concatenate(cnts))
        if area / max(cv2.contourArea(hull), 1.0) < o.min_solidity:
            continue
        out.append((cue, (int(x), int(y), int(x + bw - 1), int(y + bh - 1)), int(area)))


def _cue_border(sm, band, iterations, o, out):
    from ._segment import _grabcut

    h, w = sm.shape[:2]
    fg = _grabcut(sm, None, (band, band, w - 2 * band, h - 2 * band), iterations)
    _regions(fg, "border", band, o, out)


def _otsu(a: np.ndarray) -> np.ndarray:
    u8 = cv2.normalize(a, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    _, t = cv2.threshold(u8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return t > 0


def _cue_saliency(lab, band, o, out):
    h, w = lab.shape[:2]
    blurred = cv2.GaussianBlur(lab, (0, 0), 2.0)
    ft = np.linalg.norm(blurred - lab.reshape(-1, 3).mean(0), axis=2)
    _regions(_otsu(ft), "saliency", band, o, out)
    # spectral residual on a 64 px wide copy, per Lab channel
    sw = 64
    sh = max(8, round(h * sw / w))
    sr = np.zeros((sh, sw))
    for ch in range(3):
        g = cv2.resize(lab[:, :, ch], (sw, sh), interpolation=cv2.INTER_AREA)
        F = np.fft.fft2(g)
        amp = np.log(np.abs(F) + 1e-9)
        res = amp - cv2.blur(amp, (3, 3), borderType=cv2.BORDER_WRAP)
        sr += np.abs(np.fft.ifft2(np.exp(res + 1j * np.angle(F)))) ** 2
    sr = cv2.GaussianBlur(cv2.resize(sr, (w, h), interpolation=cv2.INTER_LINEAR), (0, 0), 0.02 * max(h, w))
    _regions(sr > 3.0 * sr.mean(), "saliency", band, o, out)


def _cue_colour(sm, lab, band, o, out):
    h, w = sm.shape[:2]
    ms = cv2.pyrMeanShiftFiltering(sm, 8, 18)
    L = cv2.cvtColor(ms, cv2.COLOR_BGR2LAB).astype(np.float32)
    L[:, :, 0] *= 0.4  # shading changes lightness most
    data = L.reshape(-1, 3)
    cv2.setRNGSeed(7)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 0.5)
    _, labels, _ = cv2.kmeans(data, o.clusters, None, crit, 2, cv2.KMEANS_PP_CENTERS)
    labels = labels.reshape(h, w)
    for c in range(o.clusters):
        m = cv2.morphologyEx((labels == c).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
        _regions(m, "colour", band, o, out)


def _cue_smooth(sm, band, o, out):
    g = cv2.GaussianBlur(cv2.cvtColor(sm, cv2.COLOR_BGR2GRAY), (0, 0), 1.0)
    e = cv2.Canny(g, 20, 50).astype(np.float32) / 255.0
    dens = cv2.blur(e, (o.edge_window, o.edge_window))
    smooth = dens < 0.02
    # object interiors are smooth; close the gaps its speculars and shading edges leave
    m = cv2.morphologyEx(smooth.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((7, 7), np.uint8))
    _regions(m, "smooth", band, o, out)


def _box_iou(a, b) -> float:
    ix = max(0, min(a[2], b[2]) - max(a[0], b[0]) + 1)
    iy = max(0, min(a[3], b[3]) - max(a[1], b[1]) + 1)
    inter = ix * iy
    ua = (a[2] - a[0] + 1) * (a[3] - a[1] + 1) + (b[2] - b[0] + 1) * (b[3] - b[1] + 1) - inter
    return inter / max(ua, 1)


def proposals(sm: np.ndarray, iterations: int, o: DetectOptions) -> list:
    """``[(cue, box), ...]``: candidate object boxes ``(x0, y0, x1, y1)`` (inclusive
    pixels of the reduced image ``sm``) from the cues of the module docstring, the
    largest region first, boxes overlapping by more than ``same_iou`` merged into one."""
    h, w = sm.shape[:2]
    band = max(5, int(round(o.border_frac * min(h, w))))
    lab = cv2.cvtColor(sm, cv2.COLOR_BGR2LAB).astype(np.float64)
    found: list = []
    border: list = []
    with ThreadPoolExecutor(max_workers=1) as ex:  # the border cue's GrabCut beside the other cues
        job = ex.submit(_cue_border, sm, band, iterations, o, border)
        _cue_saliency(lab, band, o, found)
        _cue_colour(sm, lab, band, o, found)
        _cue_smooth(sm, band, o, found)
        job.result()
    found = border + found
    found.sort(key=lambda f: -f[2])
    kept: list = []
    for cue, box, _ in found:
        if all(_box_iou(box, b) <= o.same_iou for _, b in kept):
            kept.append((cue, box))
    return kept[: o.max_proposals]


# ----------------------------------------------------------------------------------
# Segmentation and the symmetry judge
# ----------------------------------------------------------------------------------


def grow_box(box, shape, o: DetectOptions):
    """The box ``(x0, y0, x1, y1)`` grown by ``box_grow`` of its larger side (at least
    ``box_grow_min`` px), clipped to the image: integer, inclusive."""
    H, W = shape
    x0, y0, x1, y1 = box
    m = max(o.box_grow_min, int(round(o.box_grow * max(x1 - x0, y1 - y0))))
    return (max(0, int(math.floor(x0)) - m), max(0, int(math.floor(y0)) - m),
            min(W - 1, int(math.ceil(x1)) + m), min(H - 1, int(math.ceil(y1)) + m))


def symmetry_of(fg: np.ndarray, offset=(0, 0)):
    """``(outline, homology)`` of the binary region ``fg`` (its outline from the mask
    path, in the coordinates of a larger image where ``fg`` starts at column
    ``offset[0]``, row ``offset[1]``), or ``(None, None)`` when it has none."""
    from ._masks import _outlines_from_field
    from ._homology import fit_homology

    F = np.pad(fg.astype(np.float64), 2)
    try:
        outs = _outlines_from_field(F, min_area=1.0, smooth=1.0, border="cut", what="segmentation", crop=False)
    except ValueError:
        return None, None
    p = outs[0] + np.array([offset[0] - 2.0, offset[1] - 2.0])
    try:
        h = fit_homology(p, robust=True)
    except (ValueError, FloatingPointError):
        return p, None
    return p, h


def symmetry_limit(p, o: DetectOptions) -> float:
    """The largest trimmed RMS symmetry residual (px) of a kept outline ``p``:
    ``symmetry_px``, or ``symmetry_rel`` of its larger extent when larger."""
    return max(o.symmetry_px, o.symmetry_rel * float(np.max(np.max(p, 0) - np.min(p, 0))))


def judge(p, h, o: DetectOptions) -> tuple[bool, str, float]:
    """Whether the outline ``p`` with its fitted homology ``h`` is a surface of
    revolution's: ``(ok, reason if not, trimmed RMS residual px)``."""
    if h is None:
        return False, "no homology could be fitted to its outline", math.inf
    size = float(np.max(p.max(0) - p.min(0)))
    limit = symmetry_limit(p, o)
    tol = o.polygon_rel * size + o.polygon_px
    poly = cv2.approxPolyDP(np.asarray(p, np.float32).reshape(-1, 1, 2), tol, True)
    if len(poly) <= o.polygon_vertices:
        return False, (f"a polygon ({len(poly)} straight sides within {tol:.1f} px): a tile, a box "
                       "face or a pattern, not a surface of revolution"), math.inf
    rms, raw = float(h.rms), float(h.rms_untrimmed)
    frac = float(np.mean(np.asarray(h.inliers))) if h.inliers is not None else 1.0
    if not np.isfinite(rms) or rms > limit:
        return False, (f"not symmetric: no harmonic homology maps its outline onto itself (residual {rms:.2f} px "
                       f"RMS, limit {limit:.2f} px)"), rms
    if frac < o.min_inliers or raw > o.untrimmed_factor * limit:
        return False, (f"symmetric over only {100 * frac:.0f} % of its outline (untrimmed residual {raw:.2f} px): "
                       "a leak or a merged neighbour"), rms
    return True, "", rms


def mirrored(region: np.ndarray, W, offset=(0, 0)) -> np.ndarray:
    """The bool image ``region`` (a window whose top-left pixel is ``offset`` = (x, y)
    of the image the homology ``W`` (3x3, pixels) is in) mapped by ``W``: the pixels
    whose image under the harmonic homology lies in the region (``W`` is an involution,
    so this is also the region's image).  Pixels mapped from outside the window are
    False."""
    x, y = offset
    T = np.array([[1.0, 0.0, -x], [0.0, 1.0, -y], [0.0, 0.0, 1.0]]) @ np.asarray(W, np.float64) @ \
        np.array([[1.0, 0.0, x], [0.0, 1.0, y], [0.0, 0.0, 1.0]])
    h, w = region.shape
    out = cv2.warpPerspective(region.astype(np.uint8), T, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.astype(bool)


def mirror_grabcut(img: np.ndarray, win, fg: np.ndarray, W, iterations: int, o: DetectOptions):
    """The region ``fg`` (bool, the window ``win`` = (x0, y0, x1, y1) of the uint8 BGR
    image ``img``) segmented again by GrabCut with its own mirror image under the
    harmonic homology ``W`` (3x3, pixels of ``img``) as a guide: the bool region, or
    None when the homology does not map the region near onto itself (they share less
    than half of it) or GrabCut keeps less than half of it.

    The region ``R`` and its mirror ``W(R)`` agree where the outline is right: ``R &
    W(R)`` is probable foreground (sure foreground ``recut_px`` inside it), the
    disagreement ``R ^ W(R)`` and a band of ``recut_px`` around ``R | W(R)`` probable
    background, the rest background, so that only the colours put a one-sided part
    (a leak on one side, or the mirror of a bite on the other) back."""
    from ._segment import _dilate, _erode, _grabcut, _largest_component

    x0, y0, x1, y1 = win
    m = mirrored(fg, np.asarray(W), (x0, y0))
    both, either = fg & m, fg | m
    if both.sum() < 0.5 * fg.sum():
        return None
    r = max(1, int(round(o.recut_px)))
    init = np.full(fg.shape, cv2.GC_BGD, np.uint8)
    init[_dilate(either, r)] = cv2.GC_PR_BGD
    init[both] = cv2.GC_PR_FGD
    init[_erode(both, r)] = cv2.GC_FGD
    try:
        new = _largest_component(_grabcut(np.ascontiguousarray(img[y0:y1, x0:x1]), init, None, iterations))
    except cv2.error:
        return None
    return new if new.sum() >= 0.5 * fg.sum() else None


def needs_recut(hom, o: DetectOptions) -> bool:
    """Whether the robust homology fit ``hom`` trimmed more than ``1 - recut_inliers`` of
    its outline: a one-sided leak or bite that :func:`mirror_grabcut` may cut."""
    return hom is not None and hom.inliers is not None and \
        float(np.mean(np.asarray(hom.inliers))) < o.recut_inliers


def symmetric_recut(sm: np.ndarray, win, fg: np.ndarray, hom, iterations: int, o: DetectOptions,
                    judged_ok: bool = True):
    """A segmentation's one-sided defects cut by its own symmetry: ``(fg, trimmed RMS
    residual px)`` of the new segmentation, or None to keep ``fg``.

    A region may be symmetric once its homology fit has trimmed a leak into the
    background on one side (a shadow, a patch of table of the object's colour) or a
    bite: up to ``1 - min_inliers`` of the outline is trimmed, and the outline lies
    tens of pixels off there (photo sets: 17-21 px RMS for three such outlines that the
    judge kept).  The region is segmented again by :func:`mirror_grabcut` (the image
    ``sm``, the window ``win``, the fitted homology ``hom``); the new segmentation is
    taken when :func:`judge` keeps it and, for a region the judge had kept
    (``judged_ok``), its untrimmed residual is at most ``recut_gain`` times the old one;
    a kept region is tried only when its fit trimmed more than ``1 - recut_inliers`` of
    the outline (:func:`needs_recut`)."""
    raw0 = float(hom.rms_untrimmed)
    if judged_ok and not needs_recut(hom, o):
        return None
    new = mirror_grabcut(sm, win, fg, hom.W, iterations, o)
    if new is None:
        return None
    x0, y0 = win[:2]
    p, h = symmetry_of(new, (x0, y0))
    if p is None:
        return None
    ok, _, rms = judge(p, h, o)
    if not ok or (judged_ok and float(h.rms_untrimmed) > o.recut_gain * raw0):
        return None
    return new, rms


def _judge_or_recut(sm, win, fg, iterations: int, o: DetectOptions):
    """``(ok, reason if not, segmentation, trimmed RMS residual px, its limit px)`` of the
    region ``fg`` in the window ``win`` of the reduced image ``sm``: :func:`judge`, and
    :func:`symmetric_recut` for a region that is symmetric once trimmed (kept, or
    refused as a leak).  Regions further from symmetric are not re-cut: on the photo
    sets that found no object more and added fragments of objects (a bowl's halves
    between its painted bands)."""
    p, hom = symmetry_of(fg, win[:2])
    if p is None:
        return False, "no outline", fg, math.inf, math.inf
    limit = symmetry_limit(p, o)
    ok, why, rms = judge(p, hom, o)
    if hom is not None and np.isfinite(rms) and rms <= limit:
        cut = symmetric_recut(sm, win, fg, hom, iterations, o, judged_ok=ok)
        if cut is not None:
            return True, "", cut[0], cut[1], limit
    return ok, why, fg, rms, limit


def _mask_iou(a, b, smaller: bool = False) -> float:
    """Intersection over union of two masks ``(window (x0, y0, x1, y1), bool mask)``
    (``smaller``: over the smaller mask's area)."""
    (wa, fa), (wb, fb) = a, b
    x0, y0 = max(wa[0], wb[0]), max(wa[1], wb[1])
    x1, y1 = min(wa[2], wb[2]), min(wa[3], wb[3])
    if x1 <= x0 or y1 <= y0:
        return 0.0
    ia = fa[y0 - wa[1]:y1 - wa[1], x0 - wa[0]:x1 - wa[0]]
    ib = fb[y0 - wb[1]:y1 - wb[1], x0 - wb[0]:x1 - wb[0]]
    inter = float(np.sum(ia & ib))
    if smaller:
        return inter / max(float(min(fa.sum(), fb.sum())), 1.0)
    return inter / max(float(fa.sum() + fb.sum()) - inter, 1.0)


def _segment_region(sm: np.ndarray, pbox, iterations: int, o: DetectOptions):
    """GrabCut of the proposal ``pbox`` on the reduced image ``sm`` (its box grown by
    :func:`grow_box`): ``(window (x0, y0, x1, y1), foreground in it, sides of the grown
    box or 'image border' that the foreground reaches)``."""
    from ._segment import _crop_box, _grabcut, _largest_component

    h, w = sm.shape[:2]
    box = grow_box(pbox, (h, w), o)
    cx0, cy0, cx1, cy1 = win = _crop_box(box, (h, w), margin_frac=0.0, margin_min=4)
    crop = np.ascontiguousarray(sm[cy0:cy1, cx0:cx1])
    rect = (box[0] - cx0, box[1] - cy0, box[2] - box[0] + 1, box[3] - box[1] + 1)
    try:
        cut_fg = _grabcut(crop, None, rect, iterations)
    except cv2.error:  # no background (or foreground) sample: the box grown to the whole crop
        return win, np.zeros(crop.shape[:2], bool), []
    fg = _largest_component(cut_fg, (pbox[0] - cx0, pbox[1] - cy0, pbox[2] - cx0, pbox[3] - cy0))
    if not fg.any():
        return win, fg, []
    ys, xs = np.nonzero(fg)
    bx0, by0, bx1, by1 = box[0] - cx0, box[1] - cy0, box[2] - cx0, box[3] - cy0
    cut = [side for side, hit in (("left", box[0] > 0 and xs.min() <= bx0),
                                  ("right", box[2] < w - 1 and xs.max() >= bx1),
                                  ("top", box[1] > 0 and ys.min() <= by0),
                                  ("bottom", box[3] < h - 1 and ys.max() >= by1)) if hit]
    if xs.min() + cx0 == 0 or ys.min() + cy0 == 0 or xs.max() + cx0 == w - 1 or ys.max() + cy0 == h - 1:
        cut.append("image border")
    return win, fg, cut


def segment_proposal(sm: np.ndarray, s: float, proposal, iterations: int, area_min: float, o: DetectOptions,
                     retry_at_border: bool = False):
    """``(window, fg or None, why it was dropped or its trimmed RMS residual)`` of one
    proposal ``(cue, box)`` (``box`` inclusive pixels of the reduced image ``sm``, whose
    scale is ``s``; regions under ``area_min`` reduced px^2 are nothing): segmented by
    GrabCut from its box grown by ``box_grow`` (a segmentation reaching a side of its
    box looks further that way, ``grow_rounds`` times), judged by the symmetry of its
    outline (:func:`_judge_or_recut`), and, when that segmentation is not symmetric or
    runs out of its box other than at the image border, segmented again from the box
    grown by each of ``retry_grow`` in turn until one is kept (the reason given is the
    first segmentation's; a segmentation reaching the image border is tried again only
    with ``retry_at_border``, for a box known to be clear of the border, where reaching
    it is a leak).  ``fg`` is a bool image of the window ``(x0, y0, x1, y1)``."""
    h, w = sm.shape[:2]

    def look_with(pbox, where, og):
        """``(window, fg or None, why it was dropped or its trimmed RMS residual, whether
        another margin may do better)`` of the box ``pbox`` segmented with the options
        ``og``."""
        for _ in range(og.grow_rounds + 1):
            win, fg, cut = _segment_region(sm, pbox, iterations, og)
            if fg.sum() < area_min or not cut or "image border" in cut:
                break
            # part of a larger object (a bottle's body without its neck): look further that way
            bw, bh = pbox[2] - pbox[0] + 1, pbox[3] - pbox[1] + 1
            pbox = (max(0, pbox[0] - int(og.grow_step * bw)) if "left" in cut else pbox[0],
                    max(0, pbox[1] - int(og.grow_step * bh)) if "top" in cut else pbox[1],
                    min(w - 1, pbox[2] + int(og.grow_step * bw)) if "right" in cut else pbox[2],
                    min(h - 1, pbox[3] + int(og.grow_step * bh)) if "bottom" in cut else pbox[3])
        if fg.sum() < area_min:
            return win, None, f"a region at {where}: GrabCut found no object in it", False
        if cut:
            return win, fg, (f"a region at {where}: its segmentation runs out of the region ({', '.join(cut)}): "
                             "part of a larger region, or background"), retry_at_border or "image border" not in cut
        ok, why, fg, rms, limit = _judge_or_recut(sm, win, fg, iterations, og)
        return win, fg, (rms if ok else f"a region at {where}: {why}"), limit < rms < math.inf

    cue, pbox = proposal
    where = (f"x {pbox[0] / s:.0f}..{(pbox[2] + 1) / s - 1:.0f}, y {pbox[1] / s:.0f}..{(pbox[3] + 1) / s - 1:.0f} "
             f"({cue} cue)")
    first = win, fg, res, retry = look_with(pbox, where, o)
    for grow in o.retry_grow if retry else ():
        win, fg, res, _ = look_with(pbox, where, replace(o, box_grow=grow))
        if not isinstance(res, str):
            return win, fg, res
    return first[:3]


def judged_box(img: np.ndarray, box, *, iterations: int, min_area: float, o: DetectOptions):
    """The object in the box ``(x0, y0, x1, y1)`` (inclusive pixels of the uint8 BGR
    image ``img``) found as the automatic detection finds one from a proposal
    (:func:`segment_proposal` on the image reduced to at most ``max_side`` px, scale
    ``s``), except that the box does not grow past where it was drawn (``grow_rounds``
    0) and, for a box clear of the image border, a segmentation that leaks to the
    border is tried from the other margins too: ``(region, symmetry_rms px, s)`` with
    ``region`` a bool image of the reduced size, or ``(None, why, s)`` when no
    segmentation of it is symmetric."""
    sm, s = _reduce(img, o.max_side)
    h, w = sm.shape[:2]
    x0, y0, x1, y1 = box
    pbox = (max(0, int(math.floor(x0 * s))), max(0, int(math.floor(y0 * s))),
            min(w - 1, int(math.ceil((x1 + 1) * s)) - 1), min(h - 1, int(math.ceil((y1 + 1) * s)) - 1))
    clear = pbox[0] > 0 and pbox[1] > 0 and pbox[2] < w - 1 and pbox[3] < h - 1
    win, fg, res = segment_proposal(sm, s, ("box", pbox), iterations, max(min_area * s * s, 16.0),
                                    replace(o, grow_rounds=0), retry_at_border=clear)
    if isinstance(res, str):
        return None, res, s
    region = np.zeros((h, w), bool)
    region[win[1]:win[3], win[0]:win[2]] = fg
    return region, res / s, s


def find_objects(img: np.ndarray, *, iterations: int, min_area: float, o: DetectOptions,
                 threads: int | None = None):
    """Surfaces of revolution in the uint8 BGR image ``img``, found with no boxes, on
    the image reduced to at most ``max_side`` px (scale ``s``).

    Returns ``(objects, notes, s)``: ``objects`` a list of ``(region, symmetry_rms)``,
    ``region`` a bool image of the reduced size holding the object's GrabCut
    segmentation there and ``symmetry_rms`` its outline's symmetry residual (reduced
    px), most symmetric first; ``notes`` one line per proposal dropped that overlaps no
    kept object, saying why (proposals in which GrabCut kept nothing are not named: a
    patch of the background).  ``threads``: proposals segmented side by side (None: one
    per CPU core); the result does not depend on it."""
    sm, s = _reduce(img, o.max_side)
    h, w = sm.shape[:2]
    area_min = max(min_area * s * s, 16.0)

    def look(proposal):
        return segment_proposal(sm, s, proposal, iterations, area_min, o)

    # each proposal is segmented and judged on its own, side by side (OpenCV's GrabCut
    # releases the GIL); the proposals are then taken in order as before
    props = proposals(sm, iterations, o)
    workers = max(1, min(len(props), threads if threads is not None else (os.cpu_count() or 1)))
    if workers > 1:
        with ThreadPoolExecutor(max_workers=workers) as ex:
            looks = list(ex.map(look, props))
    else:
        looks = [look(pr) for pr in props]
    judged = []  # (rms, window, fg)
    dropped = []  # (window, fg or None, note)
    accepted = []  # boxes of the segmentations judged symmetric
    for (cue, pbox), (win, fg, res) in zip(props, looks):
        if any(_box_iou(pbox, b) > o.same_iou for b in accepted):
            continue  # a kept object seen again by another cue
        if isinstance(res, str):
            dropped.append((win, fg, res))
            continue
        cx0, cy0 = win[:2]
        judged.append((res, win, fg))
        ys, xs = np.nonzero(fg)
        accepted.append((xs.min() + cx0, ys.min() + cy0, xs.max() + cx0, ys.max() + cy0))
    # of overlapping symmetric segmentations the largest: a part of an object (one bulb
    # of a vase) can be symmetric too, a leak is not
    judged.sort(key=lambda j: -int(j[2].sum()))
    kept = []
    for rms, win, fg in judged:
        if all(_mask_iou((win, fg), (kw, kf), smaller=True) <= o.overlap for _, kw, kf in kept):
            kept.append((rms, win, fg))
    kept.sort(key=lambda j: j[0])
    notes, seen = [], []
    for win, fg, note in dropped:
        if fg is None:
            continue
        if fg is not None and any(_mask_iou((win, fg), (kw, kf)) > 0.05 for _, kw, kf in kept):
            continue  # another look at a kept object
        if fg is not None and any(_mask_iou((win, fg), sn) > 0.5 for sn in seen):
            continue  # the same region seen by another cue
        if fg is not None:
            seen.append((win, fg))
        notes.append(note)
    objects = []
    for rms, (x0, y0, x1, y1), fg in kept:
        region = np.zeros((h, w), bool)
        region[y0:y1, x0:x1] = fg
        objects.append((region, rms / s))
    return objects, notes, s


# ----------------------------------------------------------------------------------
# Edge refinement
# ----------------------------------------------------------------------------------


def _periodic_smooth(v: np.ndarray, w: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-weighted (``sigma`` samples) mean of the periodic sequence ``v`` with
    weights ``w``: ``(smoothed value, sum of the weights)`` at each sample (a mean, not
    a polynomial: no extrapolation across runs of rejected points)."""
    n = len(v)
    k = np.arange(n)
    d = np.where(k <= n // 2, k, k - n).astype(np.float64)
    g = np.fft.rfft(np.exp(-0.5 * (d / sigma) ** 2))
    num = np.fft.irfft(np.fft.rfft(v * w) * g, n)
    den = np.fft.irfft(np.fft.rfft(w) * g, n)
    return num / np.maximum(den, 1e-12), den


def refine_to_edges(image, p: np.ndarray, o: DetectOptions, keep: bool = False):
    """Move the closed outline ``p`` (N, 2), points about 0.5 px apart, along its
    normals onto the colour edge of ``image``, a function of a window ``(y0, y1, x0,
    x1)`` giving the float64 BGR image there (8-bit units), within ``shape``.

    Returns ``(q, stats)``: the moved outline (N, 2) and a dict with ``outline_error``
    (px, see the module docstring), ``edge_contrast`` and ``accepted`` (and with
    ``keep``, ``kept``: (N,) bool, the points whose edge was confirmed)."""
    from ._masks import _periodic_gauss

    image_fn, shape = image
    H, W = shape
    n = len(p)
    seg = np.hypot(*(np.roll(p, -1, axis=0) - p).T)
    spacing = float(np.mean(seg))
    d1 = _periodic_gauss(p, o.normal_sigma / spacing, 1)
    sp = np.maximum(np.hypot(d1[:, 0], d1[:, 1]), 1e-12)
    nrm = np.column_stack([d1[:, 1], -d1[:, 0]]) / sp[:, None]  # outward for a positive area
    ts = np.arange(-o.reach - o.side_px, o.reach + o.side_px + 1e-9, o.step)
    pad = int(math.ceil(o.reach + o.side_px + 4 * o.edge_blur + 4))
    x0, y0 = max(0, int(math.floor(p[:, 0].min())) - pad), max(0, int(math.floor(p[:, 1].min())) - pad)
    x1, y1 = min(W, int(math.ceil(p[:, 0].max())) + pad + 1), min(H, int(math.ceil(p[:, 1].max())) + pad + 1)
    img = cv2.GaussianBlur(np.ascontiguousarray(image_fn(y0, y1, x0, x1), dtype=np.float32), (0, 0), o.edge_blur)
    sx = (p[:, None, 0] + ts[None] * nrm[:, None, 0] - x0).astype(np.float32)
    sy = (p[:, None, 1] + ts[None] * nrm[:, None, 1] - y0).astype(np.float32)
    prof = cv2.remap(img, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)  # (n, T, 3)
    inside_img = ((sx >= 0) & (sy >= 0) & (sx <= x1 - x0 - 1) & (sy <= y1 - y0 - 1)).all(axis=1) & \
        (p[:, 0] > pad - 0.5) & (p[:, 1] > pad - 0.5) & (p[:, 0] < W - pad) & (p[:, 1] < H - pad)
    near = (np.abs(ts) >= 1.5) & (np.abs(ts) <= o.reach)
    c = prof[:, near & (ts > 0)].mean(1) - prof[:, near & (ts < 0)].mean(1)  # outside minus inside
    step_far = np.linalg.norm(prof[:, ts >= o.reach].mean(1) - prof[:, ts <= -o.reach].mean(1), axis=1)
    cn = np.linalg.norm(c, axis=1)
    u = c / np.maximum(cn, 1e-9)[:, None]
    s = np.einsum("ntk,nk->nt", prof, u)
    g = np.gradient(s, o.step, axis=1)  # rises across the edge, outward
    core = np.abs(ts) <= o.reach
    # the maximum of the derivative weighted by a Gaussian prior about t = 0: the
    # segmentation's edge is rarely far off, and the prior keeps a point off the
    # object's own shading gradient next to a dark limb (the gradient maximum alone was
    # worse on textured renders: 0.26 px RMS against 0.24, 1.26 px against 1.08 on a
    # dark limb); it also pulls the result towards the start (0.8 px off -> 0.44 px)
    locmax = np.zeros_like(g, dtype=bool)
    locmax[:, 1:-1] = (g[:, 1:-1] >= g[:, :-2]) & (g[:, 1:-1] >= g[:, 2:])
    prior = np.exp(-0.5 * (ts / o.prior_px) ** 2)
    k = np.argmax(np.where(core[None], g * prior[None], -np.inf), axis=1)
    ki = np.clip(k, 1, len(ts) - 2)
    gm, g0, gp = g[np.arange(n), ki - 1], g[np.arange(n), ki], g[np.arange(n), ki + 1]
    den = gm - 2 * g0 + gp
    frac = np.where(den < -1e-12, 0.5 * (gm - gp) / np.where(den < -1e-12, den, -1.0), 0.0)
    t = ts[ki] + np.clip(frac, -0.5, 0.5) * o.step
    peak = g0
    # second peak: the largest local maximum of g more than peak_gap from the first
    away = np.abs(ts[None] - t[:, None]) > o.peak_gap
    second = np.max(np.where(locmax & away & core[None], g, 0.0), axis=1)
    # colour step consistency with the neighbours (median of unit steps within 5 px of arc)
    m = max(1, int(round(5.0 / spacing)))
    nb = np.stack([np.roll(u, j, axis=0) for j in range(-m, m + 1)])
    med = np.median(nb, axis=0)
    med /= np.maximum(np.linalg.norm(med, axis=1), 1e-9)[:, None]
    turn = np.degrees(np.arccos(np.clip(np.sum(u * med, axis=1), -1.0, 1.0)))
    ok = inside_img & (cn >= o.min_contrast) & (peak > 0) & np.isfinite(t)
    ok &= (k > 0) & (k < len(ts) - 1) & (np.abs(t) < o.reach - 0.5 * o.step)
    medpeak = float(np.median(peak[ok])) if ok.any() else 0.0
    ok &= peak >= o.weak_peak * medpeak
    ok &= second < o.second_peak * peak
    ok &= turn <= o.max_turn_deg
    # a peak much wider than the outline's typical one: two edges closer than the blur
    # resolves (a halo, a half shadow); width of a Gaussian peak of the same area (the
    # colour step) and height
    width = step_far / np.maximum(g0 * math.sqrt(2.0 * math.pi), 1e-12)
    if ok.any():
        ok &= width <= o.max_width * float(np.percentile(width[ok], 25))
    sig = o.curve_sigma / spacing
    stats = {"outline_error": math.nan, "edge_contrast": float(np.median(cn[ok])) if ok.any() else 0.0,
             "accepted": float(np.mean(ok))}
    if keep:
        stats["kept"] = ok
    if ok.sum() < 8:
        return p, stats
    for _ in range(2):
        ts_, wsum = _periodic_smooth(np.where(ok, t, 0.0), ok.astype(np.float64), sig)
        r = t - ts_
        scale = 1.4826 * float(np.median(np.abs(r[ok]))) + 1e-3
        bad = ok & (np.abs(r) > o.clip_k * scale + 0.1)
        if not bad.any():
            break
        ok &= ~bad
    ts_, wsum = _periodic_smooth(np.where(ok, t, 0.0), ok.astype(np.float64), sig)
    full = o.curve_sigma / spacing * math.sqrt(2.0 * math.pi)  # the weight of a window of accepted points
    have = wsum >= o.min_support * full
    shift = np.where(have, np.clip(ts_, -o.reach, o.reach), 0.0)
    # where the two edge estimates agree to within move_px the unmixed one stands (it is
    # the better on clean edges: 0.1 px against 0.27 px at a shaded limb); beyond, the
    # image's edge is taken, with a linear blend from move_px to twice it
    disagree = shift
    shift = shift * np.clip(np.abs(shift) / o.move_px - 1.0, 0.0, 1.0)
    q = p + shift[:, None] * nrm
    r = (t - ts_)[ok]
    s_pt = 1.4826 * float(np.median(np.abs(r)))
    n_eff = max(1.0, float(np.median(wsum[ok])))
    bias = float(np.sqrt(np.mean(disagree[have] ** 2))) if have.any() else 0.0
    rej = 1.0 - float(np.mean(ok))
    stats["outline_error"] = float(math.sqrt(s_pt**2 / n_eff + bias**2 + (rej * o.reject_px) ** 2))
    stats["accepted"] = float(np.mean(ok))
    stats["point_scatter"] = s_pt
    return q, stats


def symmetric_average(p: np.ndarray, W, confirmed: np.ndarray, o: DetectOptions) -> np.ndarray:
    """The closed outline ``p`` (N, 2 px) averaged with its own mirror image under its
    harmonic homology ``W`` (3x3, pixel coordinates; :func:`outline_homology`).

    A surface of revolution's outline is mapped onto itself by ``W`` (``W = W^-1``), so
    ``p`` and ``W(p)`` are two estimates of one curve whose errors are independent where
    the outline's two sides were found independently (their own edges, table and wall
    behind them).  The weighted average of a point and its mirror partner is

        ``a_i = (w_i p_i + w'_i f_i) / (w_i + w'_i)``,

    ``f_i`` the nearest point to ``p_i`` of the polyline ``W(p)``, ``w_i`` 1 where
    :func:`refine_to_edges` confirmed the image's edge at ``p_i`` (``confirmed``, (N,)
    bool) and ``unconfirmed_weight`` where it did not (then smoothed along the outline
    by a Gaussian of ``weight_sigma`` px of arc), ``w'_i`` the same weight of the
    partner (interpolated along its segment of ``W(p)``).  Each point moves a share
    ``s_i`` of the way there, ``q_i = p_i + s_i (a_i - p_i)``, with ``s_i`` 0 where
    ``|f_i - p_i| <= average_px``, 1 beyond twice that, linear between (smoothed as the
    weights); ``average_px = 0`` (the default) averages every point.  A bite or bump on
    one side is thus replaced by the mirror image of the other side where the other
    side's edge is confirmed and its own is not, and halved where both or neither are;
    the two sides' independent errors are averaged (divided by about sqrt 2).  The
    averaged outline is symmetric by construction: the calibration, which measures the
    outlines' noise by their symmetry residuals, must be told the noise it no longer
    shows (``outlines_from_image`` hands the residual before the averaging on as
    ``ImageOutline.noise_rms``, :func:`sorjax.calibrate`'s ``outline_noise``).  A
    defect that is symmetric itself (a contact shadow centred on the axis, a whole
    outline off by a constant) is not seen, and symmetry cannot tell a leak on one side
    from a bite on the other: the image's edge decides, where it can.

    On the photo-like renders (:func:`sorjax.render.random_photo_set` seeds 100-129, one
    camera of 4 images each, the 161 outlines found and matched to an unoccluded object;
    the options were chosen on them) the median RMS distance to the exact silhouette went
    from 0.51 px to 0.36 px (0.40 px with ``average_px`` 0.5, 0.43 px with 1), the share
    within 1 px from 75 to 80 % (78 % with 1)."""
    from ._masks import _periodic_gauss
    from ._homology import transfer
    from ._curves import closest_points_on_polyline

    p = np.asarray(p, np.float64)
    m = np.asarray(transfer(np.asarray(W, np.float64), p))
    foot, seg, t = closest_points_on_polyline(p, m)
    spacing = float(np.mean(np.hypot(*(np.roll(p, -1, axis=0) - p).T)))

    def along(v):  # smoothed along the outline by weight_sigma px of arc
        return _periodic_gauss(v[:, None], o.weight_sigma / spacing, 0)[:, 0] if o.weight_sigma > 0 else v

    w = np.maximum(along(np.where(np.asarray(confirmed, bool), 1.0, float(o.unconfirmed_weight))),
                   float(o.unconfirmed_weight))
    w_mirror = w[seg] * (1.0 - t) + w[(seg + 1) % len(p)] * t
    q = (w[:, None] * p + w_mirror[:, None] * foot) / (w + w_mirror)[:, None]
    if o.average_px <= 0:
        return q
    share = along(np.clip(np.hypot(*(foot - p).T) / o.average_px - 1.0, 0.0, 1.0))
    return p + share[:, None] * (q - p)


def outline_homology(p: np.ndarray):
    """The robust harmonic homology fitted to the outline ``p`` (N, 2 px), or None when
    none can be fitted."""
    from ._homology import fit_homology

    try:
        return fit_homology(p, robust=True)
    except (ValueError, FloatingPointError):
        return None


def outline_quality(p: np.ndarray, stats: dict, hom=False) -> dict:
    """The :class:`ImageOutline` attributes of the refined outline ``p`` from the edge
    statistics of :func:`refine_to_edges` and the symmetry of ``p`` itself: a surface
    of revolution's outline is mapped onto itself by its harmonic homology, so its
    symmetry residual (px) shows the outline's errors that are not symmetric (a leak
    on one side, a bite, noise).  ``symmetry_rms`` is the robust fit's (trimmed) RMS
    residual; ``outline_error`` is ``sqrt(e^2 + u^2)``, ``e`` the edge estimate and
    ``u`` the larger of the trimmed and the untrimmed residual, because what the
    trimming leaves out (a leak, a shadow) is part of the outline's error.  On the
    photo-like renders (random_photo_set seeds 0 and 7, 3 cameras x 4 images) the
    trimmed residual in its place gave declared errors of 0.16-1.19 times the actual
    RMS error (10th-90th percentile, median 0.76, 36 outlines matched to objects) and
    as little as 1/100 of it for a leak (three outlines 17-21 px off read 0.2-1.6 px);
    with the untrimmed residual (and the re-cut and the limits of
    :func:`find_objects`) 0.71-1.50 (median 1.21, 30 outlines, the worst 0.21).

    ``hom``: the outline's homology when already fitted (:func:`outline_homology`; None
    when none could be); by default it is fitted here."""
    h = outline_homology(p) if hom is False else hom
    sym, raw = (float(h.rms), float(h.rms_untrimmed)) if h is not None else (math.nan, math.nan)
    u = max(sym, raw) if np.isfinite(raw) else sym
    err = stats.get("outline_error", math.nan)
    if np.isfinite(u):
        err = u if not np.isfinite(err) else math.hypot(err, u)
    return {"outline_error": err, "edge_contrast": stats.get("edge_contrast", math.nan),
            "accepted": stats.get("accepted", math.nan), "symmetry_rms": sym}
