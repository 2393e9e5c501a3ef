"""Finding surfaces of revolution in a photograph without boxes (moving outlines onto
the image's edges, their estimated error and their symmetric averaging:
:mod:`sorjax._edge_refinement`).

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
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import cv2
import numpy as np

from ._detect_options import DetectOptions
from ._image_outline import ImageOutline
from ._detect_proposals import _box_iou, _reduce, proposals  # noqa: F401
from ._edge_refinement import (  # noqa: F401
    outline_homology, outline_quality, refine_to_edges, symmetric_average,
)
from ._symmetry_judge import (  # noqa: F401
    _judge_or_recut, judge, mirror_grabcut, mirrored, needs_recut, symmetric_recut, symmetry_limit, symmetry_of,
)

__all__ = ["DetectOptions", "ImageOutline", "find_objects", "outline_quality", "refine_to_edges"]


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
