"""Sub-pixel outlines of objects from masks (binary or soft), in pixels.

Pixels follow OpenCV's convention (the centre of the top-left pixel is ``(0, 0)``); the
convention in full, the method, the outlines' orientation and the memory bounds are those described in
:mod:`sorjax._extract` (photographs are segmented there, then traced here).
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import warnings

import cv2
import numpy as np

from ._checks import number
from ._image_outline import ImageOutline
from ._level_trace import _clean_loop, _shoelace, _start_at_top, _trace_level, _tube_smooth, _unbend

__all__ = ["outlines_from_mask"]

_BORDER_MODES = ("refuse", "cut", "raise")

# Windows: objects are located on a grid of _BLOCK px and traced or segmented in
# windows of at most MAX_WINDOW_PIXELS (work arrays of ~30 bytes per pixel for a mask,
# more for a photograph's unmixing).
_BLOCK = 8
MAX_WINDOW_PIXELS = 60_000_000
#: the standard deviation (px) of the systematic offset along the normals that an outline
#: traced from a mask is taken to carry (:attr:`sorjax.ImageOutline.outline_offset`): a
#: segmenter's mask is eroded or dilated by up to about a pixel (a matting threshold, a
#: learned mask, a blurred edge), which the outline's symmetry does not show.  Chosen
#: from measurement (experiments/outline_bias.py, docs/results.md): masks of photo-like
#: renders eroded and dilated by 0.5, 1 and 2 px.
MASK_OFFSET_PX = 1.0
_CHUNK_ELEMENTS = 1 << 22  # elements per block of rows when a whole image is scanned


def _row_blocks(H: int, W: int, multiple: int = 1):
    """``(i0, i1)`` blocks of rows of an ``H x W`` image, each a multiple of
    ``multiple`` rows (but the last) and about ``_CHUNK_ELEMENTS`` pixels."""
    rows = max(multiple, (_CHUNK_ELEMENTS // max(W, 1)) // multiple * multiple)
    for i0 in range(0, H, rows):
        yield i0, min(H, i0 + rows)


# Hints in messages name the API's options, or the command line's flags when it is
# the command line that calls (:func:`command_line_hints`).
_FOR_CLI = contextvars.ContextVar("sorjax_extract_for_cli", default=False)
_HINTS = {
    "label": ("pass label=VALUE to choose the object(s)",
              "give a mask with the object(s) non-zero on a zero background"),
    "float": ("Divide an 8-bit mask by 255, or pass a label image with label=VALUE",
              "Save the mask as an 8-bit image (0 background, 255 object)"),
    "min_area_is": ("min_area = ", ""),
    "min_area": ("lower min_area if the objects are really that small",
                 "show the objects larger (the command line ignores smaller ones)"),
    "cut": (", or pass border='cut' to keep the cut outline", ""),
    "cut_all": ("reframe, or pass border='cut'", "reframe so that the whole objects are visible"),
    "boxes": ("pass boxes=[(x0, y0, x1, y1), ...] around the objects, or a mask to outlines_from_mask",
              "give boxes around the objects (--boxes FILE.json) or masks (--masks)"),
}


def _hint(key: str) -> str:
    return _HINTS[key][_FOR_CLI.get()]


@contextlib.contextmanager
def command_line_hints():
    """Within this block, messages give the command line's flags instead of the
    API's options (``sorjax calibrate`` has no ``label``, ``border`` or ``min_area``)."""
    token = _FOR_CLI.set(True)
    try:
        yield
    finally:
        _FOR_CLI.reset(token)


# ----------------------------------------------------------------------------------
# Input checks
# ----------------------------------------------------------------------------------


def _check_unit_range(a: np.ndarray, what: str, meaning: str, fix: str, tol: float) -> None:
    """Check that a float ``mask`` or ``image`` is finite and within [0, 1] (+- tol),
    a block of rows at a time (no copy of the whole); otherwise a ValueError saying
    how to fix it."""
    lo, hi = math.inf, -math.inf
    rows = a.reshape(a.shape[0], -1)
    for i0, i1 in _row_blocks(rows.shape[0], rows.shape[1]):
        blk = rows[i0:i1]
        if not np.all(np.isfinite(blk)):
            raise ValueError(f"{what} contains NaN or infinite values")
        lo, hi = min(lo, float(blk.min())), max(hi, float(blk.max()))
    if lo < -tol or hi > 1.0 + tol:
        raise ValueError(
            f"a float {what} must hold values in [0, 1]{' ' + meaning if meaning else ''}; got values in "
            f"[{lo:g}, {hi:g}]. {fix}"
        )


class _Field:
    """A validated mask seen as a field in [0, 1] (1 = object) without converting
    the whole of it: :meth:`window` converts a window to float64, :meth:`support`
    says which pixels of a block of rows are non-zero; ``binary`` (every value 0 or
    1) and ``peak`` (the largest value) are of the whole field.  ``convert`` and
    ``nonzero`` are elementwise, so a window's values are the whole field's."""

    def __init__(self, m, convert, nonzero, binary: bool, peak: float):
        self.m, self.shape = m, m.shape
        self._convert, self._nonzero = convert, nonzero
        self.binary, self.peak = bool(binary), float(peak)

    @classmethod
    def of_array(cls, F: np.ndarray) -> "_Field":
        """A float64 field in [0, 1] already in memory."""
        return cls(F, lambda a: a, lambda a: a > 0, _is_binary(F), float(F.max()))

    def window(self, y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
        return np.ascontiguousarray(self._convert(self.m[y0:y1, x0:x1]), dtype=np.float64)

    def support(self, i0: int, i1: int) -> np.ndarray:
        return np.asarray(self._nonzero(self.m[i0:i1]), dtype=bool)

    def any_of(self, test) -> bool:
        """Whether ``test`` (elementwise, on the caller's values) holds anywhere."""
        H, W = self.shape
        return any(bool(np.any(test(self.m[i0:i1]))) for i0, i1 in _row_blocks(H, W))


def _values_present(m: np.ndarray, limit: int = 21) -> np.ndarray:
    """The distinct values of ``m`` (the first ``limit`` in order), a block at a time."""
    vals = np.array([], dtype=m.dtype)
    for i0, i1 in _row_blocks(*m.shape):
        vals = np.union1d(vals, np.unique(m[i0:i1]))[: 1000]
    return vals[:limit]


def _check_label(label):
    arr = np.asarray(label) if not isinstance(label, (str, bytes)) else np.asarray(None)
    if isinstance(label, (bool, np.bool_)) or arr.ndim != 0 or not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"label must be one number, the value of the object's pixels in the label image; "
                         f"got {label!r:.60}")
    if not math.isfinite(float(label)):
        raise ValueError(f"label must be a finite number (the value of the object's pixels); got {label!r}")
    return label


def _as_field(mask, label) -> _Field:
    """The mask as a :class:`_Field` (values in [0, 1], 1 = object), with clear errors."""
    if isinstance(mask, (str, bytes)) or mask is None:
        raise ValueError(
            f"mask must be a 2-D array (H, W), got {type(mask).__name__}; read an image file "
            "first, e.g. cv2.imread(path, cv2.IMREAD_UNCHANGED)"
        )
    m = np.asarray(mask)
    if m.ndim == 3 and m.shape[2] == 1:
        m = m[:, :, 0]
    if m.ndim == 3 and m.shape[2] in (3, 4):
        raise ValueError(
            f"mask has shape {m.shape}: that looks like a colour image. Pass a single-channel "
            "mask (H, W), e.g. cv2.imread(path, cv2.IMREAD_GRAYSCALE), or use "
            "sorjax.outlines_from_image for a photograph"
        )
    if m.ndim != 2:
        raise ValueError(f"mask must be a 2-D array (H, W), got shape {m.shape}")
    if m.shape[0] < 3 or m.shape[1] < 3:
        raise ValueError(f"mask must be at least 3x3 pixels, got {m.shape[0]}x{m.shape[1]}")
    if m.dtype == object or not (np.issubdtype(m.dtype, np.number) or m.dtype == bool):
        raise ValueError(f"mask must be numeric or boolean, got dtype {m.dtype}")
    is_float = np.issubdtype(m.dtype, np.floating)
    if label is not None:
        label = _check_label(label)
        fld = _Field(m, lambda a: (a == label).astype(np.float64), lambda a: a == label, True, 1.0)
        if is_float and fld.any_of(lambda a: ~np.isfinite(a)):
            raise ValueError("label image contains NaN or infinite values")
        if not fld.any_of(lambda a: a == label):
            vals = _values_present(m)
            shown = ", ".join(str(v) for v in vals[:20]) + (" ..." if len(vals) > 20 else "")
            raise ValueError(f"label {label!r} does not occur in the label image (values present: {shown})")
        return fld
    if m.dtype == bool:
        return _Field(m, lambda a: a.astype(np.float64), lambda a: a, True, 1.0 if m.any() else 0.0)
    if is_float:
        _check_unit_range(m, "mask", "(0 background, 1 object, fractions at anti-aliased edges)", _hint("float"), 1e-9)

        def convert(a):
            return np.clip(a.astype(np.float64), 0.0, 1.0)

        fld = _Field(m, convert, lambda a: a > 0, True, min(1.0, max(0.0, float(m.max()))))
        fld.binary = not fld.any_of(lambda a: (a > 0) & (a < 1))  # values within 1e-9 of 0 or 1 are clipped to them
        return fld
    # integer masks
    lo, hi = int(m.min()), int(m.max())
    full = 255.0 if hi == 255 else (65535.0 if hi == 65535 and m.dtype.itemsize == 2 else None)
    if lo >= 0 and hi <= 1:
        return _Field(m, lambda a: a.astype(np.float64), lambda a: a != 0, True, float(hi))
    if lo >= 0 and full is not None:  # 0/255 binary or 8-bit soft alpha (16-bit: 0/65535, 0..65535)

        def convert(a):
            return a.astype(np.float64) / full

        fld = _Field(m, convert, lambda a: a != 0, True, 1.0)
        fld.binary = not fld.any_of(lambda a: (a > 0) & (a < hi))
        return fld
    raise ValueError(
        f"integer mask with values in [{lo}, {hi}]: expected 0/1 or 0/255 (or an 8-bit soft "
        "mask up to 255, a 16-bit one up to 65535). If this is a label image (one value per object), "
        f"{_hint('label')}"
    )


def _check_options(min_area, smooth, border) -> tuple[float, float]:
    min_area = number(min_area, "min_area", lo=0.0, unit="pixels^2")
    smooth = number(smooth, "smooth", lo=0.0, hi=20.0, unit="pixels (Gaussian sigma)")
    if border not in _BORDER_MODES:
        raise ValueError(f"border must be one of {_BORDER_MODES}, got {border!r}")
    return min_area, smooth


def _blur(F: np.ndarray, sigma: float) -> np.ndarray:
    if sigma <= 0:
        return F
    r = _blur_radius(sigma)
    return cv2.GaussianBlur(F, (2 * r + 1, 2 * r + 1), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE)


def _blur_radius(sigma: float) -> int:
    """Half-width (px) of :func:`_blur`'s kernel (0: no blur)."""
    return max(1, int(math.ceil(4.0 * sigma))) if sigma > 0 else 0


def _object_windows(field: _Field, margin: int) -> list[tuple[int, int, int, int]]:
    """Disjoint windows ``(y0, y1, x0, x1)`` (px, ends excluded) that together hold
    every non-zero pixel of ``field``, each at least ``margin`` px from the sides of
    its window (or at the image border): a blur and a trace that read less than
    ``margin`` px around a pixel see in a window what they see in the whole field.

    The non-zero pixels are found a block of rows at a time and marked on a grid of
    ``_BLOCK`` px; the marks are grown by the margin and their bounding boxes merged
    until none overlap or touch (all on the grid: a few MB for a 20000 px image)."""
    H, W = field.shape
    b = _BLOCK
    coarse = np.zeros((-(-H // b), -(-W // b)), np.uint8)
    cols = np.arange(0, W, b)
    for i0, i1 in _row_blocks(H, W, multiple=b):
        nz = field.support(i0, i1)
        rows = np.logical_or.reduceat(nz, np.arange(0, i1 - i0, b), axis=0)
        coarse[i0 // b: -(-i1 // b)] = np.logical_or.reduceat(rows, cols, axis=1)
    if not coarse.any():
        return []
    c = -(-int(margin) // b)  # a non-zero pixel lies >= c * b >= margin px inside its grown cells
    canvas = cv2.dilate(coarse, np.ones((2 * c + 1, 2 * c + 1), np.uint8))
    while True:
        _, _, stats, _ = cv2.connectedComponentsWithStats(canvas, connectivity=8)
        boxes = stats[1:]
        if np.all(boxes[:, 4] == boxes[:, 2] * boxes[:, 3]):  # every group a filled, separate rectangle
            break
        canvas[:] = 0
        for x, y, w, h, _ in boxes:
            canvas[y:y + h, x:x + w] = 1
    order = np.lexsort((boxes[:, 0], boxes[:, 1]))  # top to bottom, then left to right
    return [(int(y) * b, min(H, int(y + h) * b), int(x) * b, min(W, int(x + w) * b))
            for x, y, w, h, _ in boxes[order]]


def _check_window(win, what: str) -> None:
    y0, y1, x0, x1 = win
    n = (y1 - y0) * (x1 - x0)
    if n > MAX_WINDOW_PIXELS:
        raise ValueError(
            f"the {what} has an object region of {x1 - x0} x {y1 - y0} px ({n / 1e6:.0f} Mpx); outlines are traced "
            f"at full resolution in regions of at most {MAX_WINDOW_PIXELS / 1e6:.0f} Mpx (memory). Downsample the "
            f"image (e.g. cv2.resize with cv2.INTER_AREA) or crop it around the objects"
        )


def _border_sides(p: np.ndarray, shape, margin: float = 1.0) -> list[str]:
    """Image sides the outline comes within ``margin`` px of (the image spans
    [-0.5, W - 0.5] x [-0.5, H - 0.5])."""
    H, W = shape
    sides = []
    if p[:, 0].min() < -0.5 + margin:
        sides.append("left")
    if p[:, 0].max() > W - 0.5 - margin:
        sides.append("right")
    if p[:, 1].min() < -0.5 + margin:
        sides.append("top")
    if p[:, 1].max() > H - 0.5 - margin:
        sides.append("bottom")
    return sides


def _describe(p: np.ndarray, area: float) -> str:
    x0, y0 = p.min(0)
    x1, y1 = p.max(0)
    return f"area {area:.0f} px^2, x {x0:.0f}..{x1:.0f}, y {y0:.0f}..{y1:.0f}"


def _is_binary(F) -> bool:
    return bool(np.all((F == 0.0) | (F == 1.0)))


def _trace_window(field: _Field, win, smooth: float, tube: bool) -> list[tuple[float, np.ndarray]]:
    """``(shoelace area, loop)`` of the 0.5 level lines in the window ``win`` of the
    field (whole-image coordinates)."""
    y0, y1, x0, x1 = win
    F = field.window(y0, y1, x0, x1)
    G = F if tube else _blur(F, smooth)
    # a ring of zeros closes every level line: an object cut by the frame gets the frame
    # (-0.5 or W - 0.5) as part of its outline (inside the image the window's ring lies
    # where the field is zero anyway)
    G = np.pad(G, 1, mode="constant", constant_values=0.0)
    return [(_shoelace(p), p - 1.0) for p in _trace_level(G, 0.5, cubic=not tube, offset=(x0, y0))]


def _outlines_from_field(F, *, min_area, smooth, border, what="mask", crop=True):
    """Outer 0.5-level outlines of the field ``F`` (an (H, W) array in [0, 1] or a
    :class:`_Field`); see outlines_from_mask.  ``crop``: trace each group of objects
    in its own window (:func:`_object_windows`), else the whole field at once."""
    field = F if isinstance(F, _Field) else _Field.of_array(F)
    H, W = field.shape
    binary = field.binary
    tube = binary and smooth > 0  # binary: the staircase smoothed within its band, no blur
    # the blur reads _blur_radius px around a pixel, the cubic refinement 2 samples on each side
    windows = _object_windows(field, _blur_radius(0.0 if tube else smooth) + 4) if crop else [(0, H, 0, W)]
    loops = []
    for win in windows:
        if crop:
            _check_window(win, what)
        loops.extend(_trace_window(field, win, smooth, tube))
    outer = sorted([(a, p) for a, p in loops if a > 0], key=lambda ap: -ap[0])
    if not outer:
        raise ValueError(
            f"the {what} holds no object: no pixel reaches 0.5 after smoothing (max "
            f"{field.peak:.3g}). Check that the object is marked with 1 (or 255) on 0, "
            f"or {_hint('label')} in a label image"
        )
    big = [(a, p) for a, p in outer if a >= min_area]
    if not big:
        raise ValueError(
            f"the {what} holds no object of at least {_hint('min_area_is')}{min_area:g} px^2 (largest: "
            f"{outer[0][0]:.1f} px^2); {_hint('min_area')}"
        )
    # variance of the blur that moved the level set, and the arc-length scale on which
    # curvature is measured
    variance = smooth**2 + (0.0 if binary else 1.0 / 12.0)  # a soft mask is box-filtered
    out, refused = [], []
    for k, (a, p) in enumerate(big):
        if tube:
            p = _clean_loop(_tube_smooth(p))
        else:
            p = _unbend(_clean_loop(p), variance, 0.5, 3.0 if binary else 2.0)
        sides = _border_sides(p, (H, W))
        if sides and border != "cut":
            msg = (
                f"{what}: object {k} ({_describe(p, a)}) touches the image border ({', '.join(sides)}): "
                "part of it may lie outside the image, so its outline is not the object's "
                f"silhouette. Refused; reframe so that the whole object is visible{_hint('cut')}"
            )
            if border == "raise":
                raise ValueError(msg)
            warnings.warn(msg, stacklevel=3)
            refused.append(k)
            continue
        if sides:  # border == "cut": the frame is part of the outline
            p = np.column_stack([np.clip(p[:, 0], -0.5, W - 0.5), np.clip(p[:, 1], -0.5, H - 0.5)])
        out.append(_start_at_top(p))
    if not out:
        raise ValueError(
            f"every object in the {what} ({len(refused)}) touches the image border and was "
            f"refused (see the warnings); {_hint('cut_all')}"
        )
    return out


def outlines_from_mask(
    mask,
    *,
    label=None,
    min_area: float = 100.0,
    smooth: float = 1.0,
    border: str = "refuse",
) -> list[np.ndarray]:
    """Sub-pixel outlines of the objects of a mask, largest first.

    Parameters
    ----------
    mask : (H, W) array
        * bool, or integer 0/1 or 0/255 (16-bit: 0/65535): a binary mask (object =
          True/1/255/65535);
        * uint8 with values up to 255: an 8-bit soft mask (alpha 255 = object); uint16
          up to 65535: a 16-bit one;
        * float in [0, 1]: a soft mask, e.g. the fraction of each pixel covered by the
          object (anti-aliased render, alpha matte);
        * any other integer array is a label image: pass ``label``.
    label : number, optional
        With a label image, the value of the pixels of the object(s) wanted; the mask is
        ``mask == label``.

    Any size of mask: the objects are traced in windows around them (see the module's
    "Memory"), so a huge mask costs little more than itself.
    min_area : float
        Objects enclosing less than this many pixels^2 are ignored (specks).
    smooth : float
        Soft masks: standard deviation, in pixels, of the Gaussian applied to the mask
        before the 0.5 level set is traced (0: none).  The blur moves a curved edge by
        ``~smooth^2 / (2 R)`` px towards its centre of curvature (``R`` the radius of
        curvature in px), which is undone from the traced curve's own curvature, and
        rounds sharp corners over about ``2 smooth`` px.  Binary masks are not blurred:
        any ``smooth > 0`` smooths their staircase inside the band the mask allows
        (:func:`_tube_smooth`, a fixed scale of about 2 px of arc); 0 keeps the raw
        staircase.  Measured on renders of known geometry (RMS distance to the exact
        silhouette): about 0.02 px from anti-aliased (coverage) masks; 0.105 px from
        binary masks (the 0.5 level set of a binary mask blurred by 1, 2 px gave 0.158,
        0.124 px); 0.53 px for ``cv2.findContours``.
    border : {"refuse", "cut", "raise"}
        What to do with an object whose outline comes within 1 px of the image border
        (it may continue outside the image, so its outline is not its silhouette):
        "refuse" drops it with a warning naming the object and the side, "cut" keeps
        it with the image frame (``x = -0.5``, ``x = W - 0.5``, ...) as part of its
        outline, "raise" raises ValueError.

    Returns
    -------
    list of (N, 2) float64 arrays (:class:`sorjax.ImageOutline`)
        One closed outline per object (connected region of the smoothed mask >= 0.5),
        largest area first, in pixels with the OpenCV convention: the centre of pixel
        ``(row i, column j)`` is ``(x, y) = (j, i)``.  No repeated end point, positive
        shoelace area (clockwise as displayed), starting at the top-most point, points
        evenly spaced 0.5 px apart.  Only the outer boundary: holes are ignored.  Never empty.
        Each carries ``outline_offset = MASK_OFFSET_PX``: a mask from a segmenter may
        be eroded or dilated by about a pixel, which :func:`sorjax.calibrate` counts in
        the standard deviations (:attr:`sorjax.Options.outline_offset_px`).

    Raises
    ------
    ValueError
        Wrong shape or dtype, values out of range, a label that does not occur, no object
        (or none of ``min_area``), every object refused at the border, an option out of
        range (``min_area`` >= 0, ``smooth`` 0 to 20, ``label`` one finite number), or an
        object region above ``MAX_WINDOW_PIXELS``.
    """
    min_area, smooth = _check_options(min_area, smooth, border)
    F = _as_field(mask, label)
    return [ImageOutline(p, outline_offset=MASK_OFFSET_PX)
            for p in _outlines_from_field(F, min_area=min_area, smooth=smooth, border=border)]


# ----------------------------------------------------------------------------------
# From colour images
# ----------------------------------------------------------------------------------
