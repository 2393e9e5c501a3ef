"""Sub-pixel outlines of objects from masks and from colour photographs.

Pixel convention (OpenCV)
-------------------------
The centre of pixel ``(row i, column j)`` is the image point ``x = j, y = i``; pixel
``(i, j)`` covers the square ``[j - 0.5, j + 0.5] x [i - 0.5, i + 0.5]``.  The centre of
the top-left pixel is therefore ``(0, 0)`` and the image of width ``W`` and height ``H``
spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``.  ``x`` grows to the right, ``y`` downwards.
Outlines are in pixels in this convention, as everywhere in sorjax.

Method
------
An outline is the 0.5 level set of the mask blurred by a Gaussian of ``smooth`` pixels
(standard deviation), traced by marching squares with linear interpolation between
pixel centres and refined along each grid line by cubic (Catmull-Rom) interpolation,
then moved back by the blur's known curvature bias (``variance * curvature / 2``).
For a soft mask whose value is the fraction of each pixel covered by the object (an
anti-aliased render or an alpha matte) the 0.5 level set of a straight edge is exactly
the edge, whatever the blur.  A binary mask (a pixel is in when its centre is) is not
blurred: its staircase crossings, half-way between inside and outside pixel centres,
are smoothed by local quadratic fits while each is kept on the unit segment between
the two centres, where the true edge must cross (:func:`_tube_smooth`).
``cv2.findContours`` instead returns the centres of the boundary pixels: about half a
pixel inside the true edge.

Outlines are closed ``(N, 2)`` float64 arrays without a repeated end point, with a
positive shoelace area in pixel coordinates (clockwise as displayed, because ``y``
points down) and starting at their top-most point, the convention of
:mod:`sorjax.scenes`.  The traced points (about one per pixel, where the level set
crosses the lines between pixel centres) are finally resampled evenly in arc length,
0.5 px apart, along a Catmull-Rom curve through them.

Memory
------
Nothing is converted or traced at the size of the whole image.  The objects are first
located on the caller's own array (its non-zero pixels, scanned a block of rows at a
time onto an 8 px grid), then each group of objects is converted to float64, blurred
and traced in its own window: the window holds every pixel the blur and the tracing
read (``4 smooth + 4`` px around the object), so the outlines equal those traced on
the whole image (tests: to 1e-9 px).  Photographs are segmented in a window around
each object in the same way (GrabCut, the unmixing of edge pixels).  A 20000 x 20000
uint8 mask holding one small object costs its own 400 MB and little more
(experiments/memory.py); a window larger than ``MAX_WINDOW_PIXELS`` (an object
region of 60 Mpx, about 2 GB of work arrays) is refused with an error that says to
downsample.
"""

from __future__ import annotations

import math
import warnings
from typing import Sequence

import cv2
import numpy as np

from ._checks import boolean, integer

__all__ = ["outlines_from_mask", "outlines_from_image"]
from ._segment import _crop_box, _dilate, _erode, _grabcut, _largest_component  # noqa: F401
from ._masks import (  # noqa: F401
    _border_sides, _check_options, _check_window, _hint, _outlines_from_field, outlines_from_mask,
)
from ._level_trace import (  # noqa: F401
    _clean_loop, _periodic_gauss, _resample, _shoelace, _start_at_top, _trace_level, _tube_smooth,
)
from ._image_input import _Image, _as_bgr, _check_boxes
from ._unmixing import _edge_sharpness, _inner_band, _soft_alpha, _soft_alpha_tiled  # noqa: F401


def _segment_box(img, box, k, *, iterations, min_area, init=None):
    """GrabCut of the object in ``box``: ``(crop window, foreground in it)``, or None with a
    warning when nothing usable is found or the box cuts the object.  ``init``: GrabCut's
    initial labels on the crop window ``_crop_box(box)`` (None: from the box).

    A box is a hint, not a wall: GrabCut runs on the box grown by
    ``DetectOptions.box_grow`` (so that a box drawn tight around the object still leaves
    GrabCut a background band all round) and keeps the region with the most pixels inside
    the box given; the object is cut only when it reaches a side of the grown box."""
    from ._detect import DetectOptions, grow_box

    H, W = img.shape[:2]
    given = box
    if init is None:
        box = grow_box(box, (H, W), DetectOptions())
    cx0, cy0, cx1, cy1 = _crop_box(box, (H, W))
    _check_window((cy0, cy1, cx0, cx1), "image")
    crop = np.ascontiguousarray(img[cy0:cy1, cx0:cx1])
    if init is None:
        rect = (box[0] - cx0, box[1] - cy0, box[2] - box[0] + 1, box[3] - box[1] + 1)
        fg = _grabcut(crop, None, rect, iterations)
        fg = _largest_component(fg, (given[0] - cx0, given[1] - cy0, given[2] - cx0, given[3] - cy0))
    else:
        fg = _largest_component(_grabcut(crop, np.ascontiguousarray(init), None, iterations))
    if fg.sum() < max(min_area, 1.0):
        warnings.warn(
            f"box {k} {tuple(given)}: no object found inside (GrabCut kept {int(fg.sum())} px); "
            "check the box encloses the object",
            stacklevel=3,
        )
        return None
    if init is None:
        # GrabCut forces everything outside the (grown) box to background: an object
        # reaching a side of it (one that is not on the image border) was cut by the box
        bx0, by0, bx1, by1 = box[0] - cx0, box[1] - cy0, box[2] - cx0, box[3] - cy0
        sides = {
            "left": (box[0] > 0, fg[by0 : by1 + 1, bx0]),
            "right": (box[2] < W - 1, fg[by0 : by1 + 1, bx1]),
            "top": (box[1] > 0, fg[by0, bx0 : bx1 + 1]),
            "bottom": (box[3] < H - 1, fg[by1, bx0 : bx1 + 1]),
        }
        cut = [name for name, (inside_image, line) in sides.items() if inside_image and line.sum() > 2]
        if cut:
            warnings.warn(
                f"box {k} {tuple(given)}: the object reaches the {', '.join(cut)} side of the box (grown by "
                f"{DetectOptions().box_grow:.0%}), so the box cuts it (or the segmentation leaked); refused. "
                "Enlarge the box",
                stacklevel=3,
            )
            return None
    return (cx0, cy0, cx1, cy1), fg


def _finish(src: _Image, box, k, window, fg, *, inner, min_area, smooth, border):
    """Outline (pixels, whole-image coordinates) of a segmented object, or None with a
    warning; ``inner`` is the unmixing band (None: no refinement, the binary mask)."""
    H, W = src.shape
    cx0, cy0, cx1, cy1 = window
    if inner is None:
        alpha = fg.astype(np.float64)
    else:
        alpha = _soft_alpha_tiled(lambda y0, y1, x0, x1: src.f64(cy0 + y0, cy0 + y1, cx0 + x0, cx0 + x1), fg,
                                  inner=inner)
    # the crop is only a window: pad it with background where it is not at the image border
    pad = ((3 if cy0 > 0 else 0, 3 if cy1 < H else 0), (3 if cx0 > 0 else 0, 3 if cx1 < W else 0))
    big = np.pad(alpha, pad, mode="constant")
    try:
        outs = _outlines_from_field(big, min_area=min_area, smooth=smooth, border="cut" if border == "cut" else "raise",
                                    what="segmentation", crop=False)
    except ValueError as err:
        if border == "raise":
            raise ValueError(f"box {k} {tuple(box)}: {err}") from None
        warnings.warn(f"box {k} {tuple(box)}: {err}", stacklevel=4)
        return None
    p = outs[0] + np.array([cx0 - pad[1][0], cy0 - pad[0][0]], dtype=np.float64)
    return p


def _auto_init(comp: np.ndarray, shape, window, r: int) -> np.ndarray:
    """GrabCut's initial labels on ``window`` (x0, y0, x1, y1) of the ``shape`` (H, W)
    image from ``comp``, a region found on the image reduced to ``comp.shape``: the
    region upsampled (nearest neighbour, the pixels ``cv2.resize`` picks) is probable
    foreground, ``2 r`` px around it probable background, ``2 r`` px inside it sure
    foreground, the rest sure background.  Computed on the window grown by ``2 r + 1``
    px only: the morphology sees there what it sees on the whole image."""
    H, W = shape
    h, w = comp.shape
    cx0, cy0, cx1, cy1 = window
    e = 2 * r + 1
    ex0, ey0, ex1, ey1 = max(0, cx0 - e), max(0, cy0 - e), min(W, cx1 + e), min(H, cy1 + e)
    ys = np.minimum(np.floor(np.arange(ey0, ey1) * (1.0 / (H / h))).astype(np.intp), h - 1)
    xs = np.minimum(np.floor(np.arange(ex0, ex1) * (1.0 / (W / w))).astype(np.intp), w - 1)
    m = comp[ys[:, None], xs[None, :]].astype(bool)
    init = np.full(m.shape, cv2.GC_BGD, np.uint8)
    init[_dilate(m, 2 * r)] = cv2.GC_PR_BGD
    init[m] = cv2.GC_PR_FGD
    init[_erode(m, 2 * r)] = cv2.GC_FGD
    return init[cy0 - ey0:cy1 - ey0, cx0 - ex0:cx1 - ex0]


def _refined(src: _Image, k, b, w, fg, *, inner, min_area, smooth, border, o):
    """``(outline, edge statistics, homology)`` of the segmented object ``fg`` (window
    ``w``) moved onto the image's edges (:func:`sorjax._detect.refine_to_edges`), or None
    with a warning from :func:`_finish`."""
    from ._detect import outline_homology, refine_to_edges

    p = _finish(src, b, k, w, fg, inner=inner, min_area=min_area, smooth=smooth, border=border)
    if p is None:
        return None
    q, stats = refine_to_edges((src.f64, src.shape), p, o)
    p = _start_at_top(_clean_loop(q))
    if border == "cut":
        H, W = src.shape
        p = np.column_stack([np.clip(p[:, 0], -0.5, W - 0.5), np.clip(p[:, 1], -0.5, H - 0.5)])
    return p, stats, outline_homology(p)


def _finish_all(src: _Image, segs, *, refine, min_area, smooth, border, iterations: int,
                symmetric: bool = True) -> list[np.ndarray]:
    """Outlines of the segmented objects ``(index, box, window, fg, symmetry_rms)`` of one
    image, with one unmixing band for all, each moved onto the image's edges when
    ``refine`` (:func:`sorjax._detect.refine_to_edges`), as :class:`ImageOutline` arrays.

    A refined outline whose robust homology fit trims more than ``1 -
    DetectOptions.recut_inliers`` of it (a one-sided leak or bite at full resolution) is
    segmented again with its mirror image as a guide (:func:`sorjax._detect.mirror_grabcut`,
    ``iterations`` of GrabCut) and refined again; the new outline replaces it when its
    estimated error is at most ``recut_gain`` times the old one.  A kept region's re-cut
    at the reduced scale (:func:`sorjax._detect.symmetric_recut`) does not see the leaks
    of the full-resolution GrabCut (a vase 4.5 px RMS from its silhouette, 12 % of it
    trimmed: 0.28 px after).  On the photo-like renders
    (:func:`sorjax.render.random_photo_set` seeds 100-109, one camera, 4 images each)
    the objects found went from 47 to 49 of 102 and the median outline RMS from 0.47 to
    0.43 px; where GrabCut's colours cannot tell a leak from the object (a grey bottle
    neck before a grey box), the outline stays as it was.  With ``symmetric`` the final
    outline is then averaged with its mirror image (:func:`_averaged`)."""
    from ._detect import DetectOptions, ImageOutline, mirror_grabcut, needs_recut, outline_quality

    o = DetectOptions()
    inner = None
    if refine and segs:
        inner = _inner_band([_edge_sharpness(lambda y0, y1, x0, x1, w=w: src.f64(w[1] + y0, w[1] + y1, w[0] + x0,
                                                                              w[0] + x1), fg)
                             for _, _, w, fg, _ in segs])
    out = []
    for k, b, w, fg, sym in segs:
        if not refine:
            p = _finish(src, b, k, w, fg, inner=inner, min_area=min_area, smooth=smooth, border=border)
            if p is not None:
                out.append(ImageOutline(p, symmetry_rms=sym))
            continue
        got = _refined(src, k, b, w, fg, inner=inner, min_area=min_area, smooth=smooth, border=border, o=o)
        if got is None:
            continue
        p, stats, hom = got
        quality = outline_quality(p, stats, hom)
        if needs_recut(hom, o):
            new = mirror_grabcut(src.u8, w, fg, hom.W, iterations, o)
            if new is not None:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the first outline stands: its warnings were given
                    again = _refined(src, k, b, w, new, inner=inner, min_area=min_area, smooth=smooth,
                                     border=border, o=o)
                if again is not None:
                    q_quality = outline_quality(*again)
                    if q_quality["outline_error"] <= o.recut_gain * quality["outline_error"]:
                        p, quality, hom = again[0], q_quality, again[2]
        noise = ell = math.nan
        if symmetric:
            p, noise, ell = _averaged(src, p, hom, o)
        out.append(ImageOutline(p, **quality, noise_rms=noise, noise_ell=ell))
    return out


def _averaged(src: _Image, p: np.ndarray, hom, o) -> tuple[np.ndarray, float, float]:
    """The refined outline ``p`` averaged with its mirror image
    (:func:`sorjax._detect.symmetric_average`, weighted by where
    :func:`sorjax._detect.refine_to_edges` confirms the image's edge), or ``p`` as it is
    when it has no homology, is not symmetric within the judge's limit
    (:func:`sorjax._detect.symmetry_limit`: not a surface of revolution's outline, whose
    mirror image would move it) or touches the image border (its mirror image would
    reach past it), and when the average crosses itself (where the mirror partners of
    neighbouring points lie on different parts of a thin or leaking outline;
    ``random_photo_set(126)`` had one).  Its error attributes stay those of ``p``.
    Returns ``(outline, noise_rms, noise_ell)``: ``noise_rms`` the symmetry residual of
    ``p`` (px, ``hom.rms``) when the outline was averaged, the noise that the averaged
    outline no longer shows (:func:`sorjax.calibrate`'s ``outline_noise``), and
    ``noise_ell`` its correlation length along the curve (px, ``hom.noise_ell``:
    ``outline_noise_ell``); else NaN, NaN."""
    from ._detect import refine_to_edges, symmetric_average, symmetry_limit
    from ._outline import _segments_cross

    if hom is None or not float(hom.rms) <= symmetry_limit(p, o) or _border_sides(p, src.shape, margin=1.5):
        return p, math.nan, math.nan
    _, stats = refine_to_edges((src.f64, src.shape), p, o, keep=True)
    q = symmetric_average(p, hom.W, stats["kept"], o)
    if _segments_cross(q):
        return p, math.nan, math.nan
    return q, float(hom.rms), math.nan if hom.noise_ell is None else float(hom.noise_ell)


def _at_full_resolution(img, comp, s: float, k: int, *, iterations: int, min_area: float):
    """``(box, window, foreground)`` of an object segmented on the image reduced by ``s``
    (``comp``, a bool image of the reduced size) at the full resolution of ``img``:
    GrabCut from the region upsampled (:func:`_auto_init`: it moves within about 2 px of
    the reduced boundary, 4 px of the full image's), or the region itself when ``s`` is
    1; None with a warning when nothing usable is left."""
    H, W = img.shape[:2]
    ys, xs = np.nonzero(comp)
    box = (xs.min() / s, ys.min() / s, (xs.max() + 1) / s - 1, (ys.max() + 1) / s - 1)
    r = max(2, int(round(2.0 / s)))
    ib = (max(0, int(box[0]) - 2 * r), max(0, int(box[1]) - 2 * r),
          min(W - 1, int(math.ceil(box[2])) + 2 * r), min(H - 1, int(math.ceil(box[3])) + 2 * r))
    if s == 1.0:  # the segmentation that was judged
        cx0, cy0, cx1, cy1 = _crop_box(ib, (H, W))
        return ib, (cx0, cy0, cx1, cy1), comp[cy0:cy1, cx0:cx1]
    init = _auto_init(comp, (H, W), _crop_box(ib, (H, W)), r)
    sg = _segment_box(img, ib, k, iterations=iterations, min_area=min_area, init=init)
    return None if sg is None else (ib,) + sg


def outlines_from_image(
    image,
    boxes: Sequence[Sequence[float]] | None = None,
    *,
    min_area: float = 400.0,
    smooth: float = 1.0,
    border: str = "refuse",
    refine: bool = True,
    iterations: int = 5,
    symmetric: bool = True,
) -> list[np.ndarray]:
    """Sub-pixel outlines of the objects in a colour photograph.

    Parameters
    ----------
    image : (H, W, 3) array
        BGR as ``cv2.imread`` returns it: uint8 (or uint16), or float in [0, 1]; grey
        (H, W) and BGRA are accepted.
    boxes : sequence of (x0, y0, x1, y1), optional
        One box per object, in pixels (top-left and bottom-right corners, inclusive),
        around the object; it may be tight.  Each box is first segmented as the
        automatic detection segments a proposal (below; :func:`sorjax._detect.judged_box`):
        GrabCut on the image reduced to at most 640 px from the box grown by 15 % of its
        larger side, then by 8 % and 30 % when that segmentation is not symmetric or
        runs out of the box (for a box clear of the image border, also when it leaks
        to the border), the first symmetric one kept and cut again at full resolution
        near its boundary.  A box none of whose segmentations is symmetric
        is cut by ``cv2.grabCut`` at full resolution from the box grown by 15 % (at least
        8 px; GrabCut needs background inside its rectangle), keeping the region with
        the most pixels inside the box given, and its outline's error is measured as for
        any (a poor one says so); an object reaching the grown box's side is then
        refused as cut.  On photo-like renders (``sorjax.render.random_photo_set``
        seeds 100-129, exact boxes grown by 8 px) a bottle lying across a wood-grain
        table came out at 0.13 px RMS from its silhouette instead of 62 px.  Without
        boxes the objects are found automatically
        (:mod:`sorjax._detect`): proposals from colour clusters, saliency, smooth
        (untextured) regions and GrabCut from the whole image minus a border band, on
        the image reduced to at most 640 px; each proposal is segmented by GrabCut and
        kept when a harmonic homology maps its outline onto itself (the symmetry of a
        surface of revolution's outline: :func:`sorjax.fit_homology`, residual at most
        about 1 px RMS); every other region is dropped with a warning saying why (not
        symmetric, a leak or merged neighbour, cut by the border, ...).  Objects must
        not touch each other (touching objects give one merged outline, which is
        usually dropped as not symmetric).
    min_area : float
        Smallest object kept, pixels^2.
    smooth : float
        Gaussian sigma (pixels) of the final level set (see :func:`outlines_from_mask`).
    border : {"refuse", "cut", "raise"}
        Objects touching the image border (see :func:`outlines_from_mask`).
    refine : bool
        Refine the GrabCut boundary on the image itself: near the boundary each pixel
        is unmixed into local object and background colours, giving a soft mask whose
        0.5 level set is the sub-pixel edge (about 0.1 px RMS on sharp renders with
        sensor noise, against 0.25 px for the GrabCut mask; the band of pixels unmixed
        widens from 1.5 to 2.5 px when the image's edges look blurred, which keeps about
        0.2 px at a blur of 0.8 px; more blur degrades it: about 0.5 px at 1.2 px).
        Then each outline point is checked against the colour edge along its normal
        (:func:`sorjax._detect.refine_to_edges`: gradient maximum, ambiguous points
        rejected) and moved where the two disagree, and the outline's error is
        estimated.  Without it the binary GrabCut mask is used.
    iterations : int
        GrabCut iterations.
    symmetric : bool
        With ``refine``, replace a refined outline by the average of itself and its own
        mirror image under its fitted harmonic homology, weighted towards the side whose
        edge the image confirms (:func:`sorjax._detect.symmetric_average`): a surface of
        revolution's outline is its own mirror image, so its two sides are two
        estimates of one curve; a bite or a bump on one side takes the mirror image of
        the other.  Outlines that are not symmetric within the judge's limit (about
        1 px) or touch the image border are left as they are.  On photo-like renders
        the median distance to the true silhouette fell from 0.51 to 0.36 px RMS.  The
        error attributes below are those of the outline before the averaging, and
        ``noise_rms`` is the symmetry residual the averaged outline no longer shows
        (:func:`sorjax.calibrate` takes it as the view's noise floor).

    Returns
    -------
    list of (N, 2) float64 arrays
        One outline per object (conventions of :func:`outlines_from_mask`; pixel centres
        at integer coordinates), in box order with boxes, largest first without.
        Objects that cannot be segmented, that a box cuts or that touch the image border
        are left out with a warning that says why; so are, without boxes, outlines whose
        estimated error (``outline_error`` below) exceeds
        ``sorjax._detect.DetectOptions.max_error_px`` (1.5 px: most such outlines are
        false detections or poor segmentations).  Each outline is a
        ``sorjax._detect.ImageOutline`` (an ``np.ndarray`` subclass; ``np.asarray``
        gives the plain array) with what the image said about it:

        * ``outline_error`` (float, px): estimated RMS distance of the outline from the
          object's true edge, from the data: ``sqrt(e^2 + symmetry_rms^2)``, ``e`` the
          edge estimate (scatter of the confirmed edge points about the smooth outline
          over the points per smoothing window, the RMS disagreement between the
          unmixed and the gradient edge, half a pixel times the fraction of points
          whose edge was ambiguous); NaN with ``refine=False``.  Read it with
          ``getattr(o, "outline_error", nan)``: it is what to declare as the
          calibration's outline error for outlines from images;
        * ``symmetry_rms`` (px): RMS residual of the harmonic homology fitted to the
          outline (robust fit);
        * ``edge_contrast`` (8-bit grey levels): median colour step across the edge;
        * ``accepted``: fraction of the points whose edge was confirmed on the image;
        * ``noise_rms`` (px): the symmetry residual of the outline before it was
          averaged with its mirror image (NaN when it was not): its noise, which
          :func:`sorjax.calibrate` counts each view's residuals as at least
          (``outline_noise``), because the averaged outline no longer shows it;
        * ``noise_ell`` (px): that noise's correlation length along the curve (NaN
          when not averaged), :func:`sorjax.calibrate`'s ``outline_noise_ell``.

    Raises
    ------
    ValueError
        Bad image or boxes, or no object found at all.
    """
    min_area, smooth = _check_options(min_area, smooth, border)
    iterations = integer(iterations, "iterations", lo=1, hi=50, what="GrabCut iterations")
    refine = boolean(refine, "refine")
    symmetric = boolean(symmetric, "symmetric") and refine
    src = _as_bgr(image)
    img = src.u8
    H, W = img.shape[:2]
    cv2.setRNGSeed(0)  # GrabCut's k-means draws from OpenCV's RNG: same image, same outlines
    segs = []  # (index, box, window, foreground)
    if boxes is not None:
        bxs = _check_boxes(boxes, (H, W))
        from ._detect import DetectOptions, judged_box

        for k, b in enumerate(bxs):
            # as the automatic detection segments a proposal (margins tried, the symmetry
            # judged); a box none of whose segmentations is symmetric is cut from the box
            # at full resolution as it is, its outline's error measured as for any
            comp, sym, s = judged_box(img, b, iterations=int(iterations), min_area=min_area, o=DetectOptions())
            if comp is not None:
                sg = _at_full_resolution(img, comp, s, k, iterations=int(iterations), min_area=min_area)
                if sg is not None:
                    segs.append((k, b) + sg[1:] + (sym,))
                    continue
            sg = _segment_box(img, b, k, iterations=int(iterations), min_area=min_area)
            if sg is not None:
                segs.append((k, b) + sg + (math.nan,))
        out = _finish_all(src, segs, refine=refine, min_area=min_area, smooth=smooth, border=border,
                          iterations=int(iterations), symmetric=symmetric)
        if not out:
            raise ValueError(
                f"no object outline could be extracted from any of the {len(bxs)} boxes (see the "
                "warnings); check that each box encloses one whole object with a small margin"
            )
        return out
    from ._detect import DetectOptions, find_objects

    detect = DetectOptions()
    objects, notes, s = find_objects(img, iterations=int(iterations), min_area=min_area, o=detect)
    for note in notes:
        warnings.warn(f"automatic detection: {note}; dropped", stacklevel=2)
    if not objects:
        raise ValueError(
            "no object found in the image: automatic detection (proposals from colour, saliency, smooth regions "
            "and the border, each segmented by GrabCut and judged by the symmetry of its outline) found no "
            "surface of revolution"
            + (f" ({len(notes)} region(s) dropped, see the warnings)" if notes else "")
            + f". {_hint('boxes')[:1].upper()}{_hint('boxes')[1:]}"
        )
    for k, (comp, sym) in enumerate(objects):
        sg = _at_full_resolution(img, comp, s, k, iterations=int(iterations), min_area=min_area)
        if sg is not None:
            segs.append((k,) + sg + (sym,))
    out = _finish_all(src, segs, refine=refine, min_area=min_area, smooth=smooth, border=border,
                      iterations=int(iterations), symmetric=symmetric)
    limit, kept = detect.max_error_px, []
    for p in out:
        if not getattr(p, "outline_error", 0.0) > limit:  # NaN (no refinement): kept
            kept.append(p)
            continue
        (x0, y0), (x1, y1) = np.asarray(p).min(0), np.asarray(p).max(0)
        warnings.warn(f"automatic detection: a region at x {x0:.0f}..{x1:.0f}, y {y0:.0f}..{y1:.0f}: its outline's "
                      f"estimated error is {p.outline_error:.2g} px (more than {limit:g} px: a false detection or a "
                      "poor segmentation); dropped. Pass a box around the object to keep it", stacklevel=2)
    out = kept
    if not out:
        raise ValueError(f"no object outline could be extracted (see the warnings); {_hint('boxes')}")
    order = np.argsort([-_shoelace(p) for p in out], kind="stable")
    return [out[i] for i in order]
