"""Outlines: validation at the boundary, orientation, resampling by arc length.

An :class:`Outline` is a closed curve in pixels (OpenCV convention: the centre of the
top-left pixel is ``(0, 0)``), stored as ``M`` points evenly spaced in arc length,
ordered so that the shoelace area ``1/2 sum (x_i y_{i+1} - x_{i+1} y_i)`` is positive.
Every outline of a calibration is resampled to the same ``M`` so that batches of
views have static shapes (they ``vmap``).

All checks run here, in plain numpy, before anything is traced: a user's mistake
raises :class:`ValueError` saying what is wrong and what to do.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._checks import MAX_POINTS as MAX_RESAMPLED
from ._checks import MIN_POINTS as MIN_RESAMPLED
from ._checks import integer
from ._curves import _segments_cross, perimeter, resample_closed, signed_area  # noqa: F401
from .core._field import gaussian_smooth_closed

DEFAULT_POINTS = 2048
# The fewest distinct points an outline may have.  Measured (fit_homology on ellipses and
# the exact silhouettes of vase, bottle, wine glass and candle holder, resampled to 3-40
# points, rotated, with and without 0.3 px noise, 11 to 2200 px across): it failed
# (FloatingPointError: the outline, smoothed as jagged, collapsed) up to 16 points at
# 100-2000 px, 19 at 40 px and 25 at 11 px; it never failed from 26 points on.  32 keeps a
# margin above that; a denser outline (every pixel of the contour) is what calibration needs.
# A pixel trace (:func:`is_pixel_trace`, e.g. cv2.findContours with CHAIN_APPROX_SIMPLE, which
# keeps only the ends of straight runs) may have fewer: it is replaced by its mask's dense
# outline; it needs MIN_TRACE_POINTS to be recognised as one.
MIN_POINTS = 32
MIN_TRACE_POINTS = 10
MIN_EXTENT_PX = 10.0
# Pixel coordinates of any image lie well within this (a gigapixel panorama is ~1e5
# px across); beyond it squared distances and areas lose all precision or overflow
# (coordinates near 1e200 gave NaN outlines and numpy LinAlgErrors).
MAX_COORDINATE_PX = 1e7


class Outline(eqx.Module):
    """A validated closed outline: ``points`` (M, 2), pixels, evenly spaced in arc
    length, positive shoelace orientation (no repeated end point)."""

    points: Float[Array, "M 2"]

    @property
    def n_points(self) -> int:
        return self.points.shape[-2]

    def perimeter(self) -> Float[Array, ""]:
        return perimeter(self.points)

    def area(self) -> Float[Array, ""]:
        return signed_area(self.points)


def validate_points(points, *, name: str = "outline") -> np.ndarray:
    """Check a user's outline and return it as a clean (N, 2) float64 numpy array.

    Raises ValueError for: wrong shape or dtype, NaN/inf, coordinates beyond
    ``MAX_COORDINATE_PX`` (1e7 px), fewer than ``MIN_POINTS`` (32) distinct points (unless a pixel trace,
    :func:`is_pixel_trace`), a curve smaller than 10 px, an open curve, a point visited twice (a curve
    that touches itself or is traced more than once), a self-intersecting curve, zero
    area.
    """
    if isinstance(points, Outline):
        return np.asarray(points.points, dtype=np.float64)
    if points is None or isinstance(points, (str, bytes, dict)) or np.isscalar(points):
        raise ValueError(
            f"{name}: expected an (N, 2) array of pixel coordinates, got {type(points).__name__} "
            f"{points!r:.40}. Pass one (x, y) point per row (load files first, e.g. with np.loadtxt)."
        )
    try:
        arr = np.asarray(points)
    except Exception as e:  # ragged lists and the like
        raise ValueError(
            f"{name}: could not be read as an (N, 2) array of pixel coordinates ({e}). "
            "Pass a numpy array of shape (N, 2) with one (x, y) point per row."
        ) from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise ValueError(
            f"{name}: expected real numbers, got dtype {arr.dtype}. "
            "Pass an (N, 2) float array of pixel coordinates."
        )
    if arr.ndim == 3 and arr.shape[1] == 1 and arr.shape[2] == 2:  # OpenCV contour
        arr = arr[:, 0, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        hint = " (it looks transposed: pass points.T)" if arr.ndim == 2 and arr.shape[0] == 2 else (
            f" ({arr.shape[0]} outlines? pass one at a time)" if arr.ndim == 3 and arr.shape[2] == 2 else "")
        raise ValueError(
            f"{name}: expected shape (N, 2), got {arr.shape}{hint}. "
            "An outline is one (x, y) pixel coordinate per row."
        )
    arr = arr.astype(np.float64)
    if arr.shape[0] == 0:
        raise ValueError(f"{name}: is empty. Pass the closed outline of the object's silhouette.")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{name}: {int(bad.sum())} of {len(arr)} points are NaN or infinite "
            f"(first at row {int(np.argmax(bad))}). Remove them before calibrating."
        )
    far = float(np.max(np.abs(arr)))
    if far > MAX_COORDINATE_PX:
        raise ValueError(
            f"{name}: has coordinates up to {far:.3g} px; pixel coordinates of an image lie within "
            f"+-{MAX_COORDINATE_PX:.0e} px. Pass the outline in pixels of its image (not scaled or offset)."
        )
    # drop consecutive duplicates and a closing repeat of the first point
    keep = np.ones(len(arr), bool)
    keep[1:] = np.any(np.diff(arr, axis=0) != 0, axis=1)
    rows = np.nonzero(keep)[0]  # the user's row of each kept point
    arr = arr[keep]
    if len(arr) > 1 and np.all(arr[-1] == arr[0]):
        arr, rows = arr[:-1], rows[:-1]
    if len(arr) < MIN_POINTS and not is_pixel_trace(arr):
        raise ValueError(
            f"{name}: has {len(arr)} distinct points; at least {MIN_POINTS} are needed (fewer make the homology fit "
            "fail). Pass a densely sampled outline (e.g. every pixel of the contour, or sorjax.outlines_from_mask)."
        )
    extent = float(np.max(np.ptp(arr, axis=0)))
    if extent < MIN_EXTENT_PX:
        raise ValueError(
            f"{name}: spans only {extent:.3g} px. Outlines must be in pixel coordinates (not "
            f"normalised ones), and an object under {MIN_EXTENT_PX:g} px across is too small to "
            "show its symmetry: use a larger view of it."
        )
    _, first, counts = np.unique(arr, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        j = int(np.argmax(counts > 1))
        p = arr[first[j]]
        again = [int(rows[k]) for k in np.nonzero(np.all(arr == p, axis=1))[0]]
        raise ValueError(
            f"{name}: the point ({p[0]:.6g}, {p[1]:.6g}) occurs {int(counts[j])} times (rows "
            f"{', '.join(map(str, again[:4]))}){' and ' + str(int((counts > 1).sum()) - 1) + ' other points repeat' if (counts > 1).sum() > 1 else ''}: "
            "the curve touches itself or is traced more than once. An outline must visit each "
            "point once, in order around the silhouette; for a mask with one-pixel-wide parts "
            "smooth the mask first (or use a sub-pixel outline)."
        )
    seg = np.linalg.norm(np.diff(arr, axis=0), axis=1)
    gap = float(np.linalg.norm(arr[-1] - arr[0]))
    med = float(np.median(seg))
    if gap > 10 * med and gap > 3.0 and not is_pixel_trace(arr):  # a chain code's closing run may be long
        raise ValueError(
            f"{name}: looks like an open curve: its last point is {gap:.1f} px from its "
            f"first, while neighbouring points are {med:.2f} px apart. An outline must be "
            "the closed boundary of the silhouette; close it, or trace the whole silhouette."
        )
    if _segments_cross(arr):
        raise ValueError(
            f"{name}: crosses itself. An outline must be a simple closed curve (the "
            "boundary of one silhouette); check the point order, or split touching objects."
        )
    perim = float(seg.sum() + gap)
    area = float(signed_area(arr))
    if abs(area) < 1e-4 * perim**2:
        raise ValueError(
            f"{name}: encloses (almost) no area ({abs(area):.3g} px^2 for a perimeter of "
            f"{perim:.1f} px): the points are collinear or the curve doubles back on itself. "
            "Pass the closed boundary of a silhouette."
        )
    return arr


SPARSE_SPACING_PX = 3.0  # mean spacing above which a short outline is called sparse


def make_outline(points, n_points: int = DEFAULT_POINTS, *, name: str = "outline") -> Outline:
    """Validate ``points`` (N, 2 pixels; an :class:`Outline` passes through), orient
    them positively and resample to ``n_points`` evenly spaced points (an integer,
    64 to 65536).

    A pixel-boundary trace (:func:`is_pixel_trace`: what ``cv2.findContours`` returns
    for a binary mask) is first replaced by the outline of the binary mask it bounds,
    as :func:`sorjax.outlines_from_mask` traces it (:func:`outline_of_pixel_trace`),
    with a warning saying so."""
    return _make_outline(points, n_points, name=name, note=True)[0]


def _make_outline(points, n_points: int, *, name: str, note: bool) -> tuple[Outline, tuple[float, float] | None]:
    """:func:`make_outline`, and ``(jitter, left)`` (px, :func:`smooth_jagged`) where
    the points were smoothed as jagged (else None); ``note``: warn when a pixel trace is
    replaced or a jagged outline smoothed (the caller that says so itself,
    :func:`sorjax.calibrate`, passes False)."""
    n_points = integer(n_points, "n_points", lo=MIN_RESAMPLED, hi=MAX_RESAMPLED, what="points of the resampled outline")
    if isinstance(points, Outline) and points.n_points == n_points:
        return points, None
    arr, jagged = validate_points(points, name=name), None
    if not isinstance(points, Outline) and is_pixel_trace(arr):
        arr = outline_of_pixel_trace(arr, name=name)
        if note:
            warnings.warn(f"{name}: {PIXEL_TRACE_NOTE}", stacklevel=4)
    elif not isinstance(points, Outline) and is_jagged(arr):
        arr, *jagged = smooth_jagged(arr)
        if note:
            warnings.warn(f"{name}: {jagged_note(*jagged)}", stacklevel=4)
    if float(signed_area(arr)) < 0:
        arr = arr[::-1]
    spacing = float(np.mean(np.linalg.norm(np.roll(arr, -1, axis=0) - arr, axis=1)))
    if len(arr) < n_points // 4 and spacing > SPARSE_SPACING_PX:
        warnings.warn(
            f"{name}: only {len(arr)} points, {spacing:.1f} px apart on average, interpolated to {n_points} by a "
            "Catmull-Rom curve through them: where the true outline bends between the points the fit is "
            "biased. Pass a denser outline (e.g. from sorjax.outlines_from_mask, 0.5 px apart).",
            stacklevel=4 if note else 3,
        )
    return Outline(jnp.asarray(resample_closed(arr, n_points))), None if jagged is None else tuple(jagged)


# ------------------------------------------------------------------ pixel traces

PIXEL_TRACE_NOTE = (
    "integer coordinates in chain-code steps: read as a trace of a binary mask's boundary pixels (the layout of "
    "cv2.findContours, whose points are the centres of the object's outermost pixels, about half a pixel inside "
    "its edge) and replaced by the outline of the mask it bounds, traced as sorjax.outlines_from_mask traces a "
    "binary mask (the staircase smoothed within the pixel band: no half-pixel inward bias). If the points are "
    "instead a sub-pixel outline rounded to whole pixels, pass them unrounded."
)


def is_pixel_trace(p: np.ndarray) -> bool:
    """Whether the closed polyline ``p`` (N, 2), as :func:`validate_points` returns it,
    is visibly a trace along a binary mask's pixels, as ``cv2.findContours`` gives:
    every coordinate an integer (a pixel centre), every step (closing one included)
    one of the eight chain-code directions (horizontal, vertical or diagonal) and most
    of them unit steps (``CHAIN_APPROX_NONE`` has only unit steps;
    ``CHAIN_APPROX_SIMPLE`` keeps the ends of straight runs)."""
    if len(p) < MIN_TRACE_POINTS or not np.all(p == np.round(p)):
        return False
    d = np.abs(np.diff(np.vstack([p, p[:1]]), axis=0))
    if not np.all((d[:, 0] == 0) | (d[:, 1] == 0) | (d[:, 0] == d[:, 1])):
        return False
    return bool(np.median(np.max(d, axis=1)) == 1.0)


def outline_of_pixel_trace(p: np.ndarray, *, name: str = "outline") -> np.ndarray:
    """The sub-pixel outline (N, 2 px, 0.5 px apart) of the binary mask whose boundary
    pixels the trace ``p`` (:func:`is_pixel_trace`) visits.

    The mask is rebuilt by filling the trace's polygon, its own pixels included (as
    ``cv2.drawContours`` with ``FILLED`` restores a ``cv2.findContours`` region), in a
    window with two empty pixels around it, and traced by the mask path of
    :func:`sorjax.outlines_from_mask` (binary: the crossings half-way between inside
    and outside pixel centres, smoothed within that unit band,
    :func:`sorjax._extract._tube_smooth`): the same outline as that mask's, so with no
    half-pixel inward bias."""
    import cv2

    from ._masks import _check_window, _outlines_from_field  # the mask path (that module imports this one)

    lo = np.floor(p.min(axis=0)).astype(np.int64) - 2
    W, H = (np.ceil(p.max(axis=0)).astype(np.int64) - lo + 3).tolist()
    _check_window((0, H, 0, W), f"pixel trace {name}")
    mask = np.zeros((H, W), np.uint8)
    cv2.fillPoly(mask, [(p - lo).astype(np.int32).reshape(-1, 1, 2)], 1)
    out = _outlines_from_field(mask.astype(np.float64), min_area=0.0, smooth=1.0, border="raise",
                               what=f"binary mask bounded by {name}", crop=False)
    return out[0] + lo.astype(np.float64)


# ------------------------------------------------------------------ jagged outlines
#
# Raw edge points (an edge detector's, a hand tracer's, points with independent noise
# each) zigzag about the curve.  The distance to a zigzag is biased: the closest point
# of a zigzag lies on the spike nearest the sample, so eq. 20's residuals are biased
# towards the samples, and the bundle's K with them (two spheres, f = 700 px, i.i.d.
# 1 px noise per point 0.3 px apart: focal errors of +17 to +144 % at 2-3 std).  Such
# outlines are smoothed along the curve before they are fitted.
JAGGED_PX = 0.05  # point-to-point jitter (px, independent part) above which an outline is smoothed
JAGGED_SMOOTH_PX = 4.0  # the smoothing's Gaussian std along the curve (px)
# Only dense outlines are read as jagged (raw edge points lie <= 1 px apart); a sparse
# polygon (an annotation tool's vertices, irregularly spaced) bends by its own sagitta.
JAGGED_MAX_SPACING_PX = 2.0


def _second_offsets(p: np.ndarray) -> np.ndarray:
    """Signed distance (px) of each point of the closed polyline ``p`` from the chord
    of its two neighbours (NaN where they coincide)."""
    a, c = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    chord, v = c - a, p - a
    length = np.linalg.norm(chord, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (chord[:, 0] * v[:, 1] - chord[:, 1] * v[:, 0]) / length


def point_jitter(p) -> float:
    """The independent point-to-point noise of a closed outline (px, a robust std).

    With ``d_i`` each point's offset from the chord of its neighbours (for noise ``n_i``
    along the normal at even spacing, ``d_i = n_i - (n_{i-1} + n_{i+1}) / 2`` plus the
    curve's own sagitta ``h^2 / 2R``), ``e_i = d_i - (d_{i-1} + d_{i+1}) / 2`` is the
    noise's fourth difference / 4 (variance ``70/16 sigma^2`` for i.i.d. noise) while the
    sagitta, smooth along the curve, cancels.  Returns ``1.4826 MAD(e) / sqrt(70/16)``.
    Smooth outlines give ~0: sorjax's own mask and image outlines <= 0.002 px, the
    paper's noise (smoothed over 2 px) 0.001 px per px of sigma; i.i.d. noise of 0.1 px
    gives 0.10 px (it underestimates large noise: 0.57 for 1 px at 0.3 px spacing)."""
    q = np.asarray(p, np.float64).reshape(-1, 2)
    if len(q) < 5:
        return 0.0
    keep = np.any(q != np.roll(q, 1, axis=0), axis=1)
    q = q[keep]
    if len(q) < 5:
        return 0.0
    d = _second_offsets(q)
    e = d - 0.5 * (np.roll(d, 1) + np.roll(d, -1))
    e = e[np.isfinite(e)]
    if len(e) == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(e - np.median(e))) / np.sqrt(70.0 / 16.0))


def _smoothed(q: np.ndarray, sigma_points: float) -> np.ndarray:
    """The closed sequence ``q`` (N, 2) smoothed by a circular Gaussian of
    ``sigma_points`` points in its index (:func:`sorjax.core._field.gaussian_smooth_closed`)."""
    return np.asarray(gaussian_smooth_closed(jnp.asarray(q, jnp.float64), sigma_points))


def _twiced(q: np.ndarray, sigma_points: float) -> np.ndarray:
    """:func:`_smoothed` by twicing, ``2 G q - G G q`` (gain ``2G - G^2``): the
    Gaussian's shrinkage of curves, ``s^2 / 2R``, taken back to fourth order in ``s``."""
    once = _smoothed(q, sigma_points)
    return 2.0 * once - _smoothed(once, sigma_points)


def _arc_per_point(q: np.ndarray) -> float:
    """Arc length per point (px) of the closed sequence ``q``, measured on it smoothed by
    8 points in its index (a zigzag's own chord length is mostly noise)."""
    return float(perimeter(_smoothed(q, 8.0))) / len(q)


def is_jagged(p: np.ndarray) -> bool:
    """Whether :func:`make_outline` smooths the validated outline ``p`` (N, 2 px) as
    jagged: :func:`point_jitter` above ``JAGGED_PX`` on a dense outline (at most
    ``JAGGED_MAX_SPACING_PX`` of arc per point)."""
    return point_jitter(p) > JAGGED_PX and _arc_per_point(np.asarray(p, np.float64)) <= JAGGED_MAX_SPACING_PX


def smooth_jagged(p: np.ndarray, smooth_px: float = JAGGED_SMOOTH_PX) -> tuple[np.ndarray, float, float]:
    """A jagged closed outline ``p`` (N, 2 px; :func:`point_jitter` > ``JAGGED_PX``)
    smoothed along the curve.  Returns ``(points, jitter, left)``: the smoothed points
    (N, 2 px), the independent noise per point measured about them (px, a robust std)
    and what is left of it after smoothing (px).

    The smoothing runs in the points' index, not their chord length (a zigzag's chord
    length is mostly noise: at 1 px of noise 0.3 px apart it is ~5x the arc), with a
    Gaussian of ``smooth_px`` px of arc (``h``, the arc per point, is measured on the
    outline pre-smoothed by 8 points).  Its shrinkage of curves (``s^2 / 2R``) is taken
    back by twicing, ``G' = 2G - G^2`` (the bias becomes fourth order in ``s``).  The
    noise, white in the index, keeps the variance ``sum_k w_k^2`` of the filter's
    impulse response ``w``: at 1 px of noise 0.3 px apart about 0.17 px, correlated
    over ``smooth_px``."""
    q = np.asarray(p, np.float64)
    sigma_points = max(float(smooth_px) / _arc_per_point(q), 1.0)
    out = _twiced(q, sigma_points)
    delta = np.zeros_like(q)
    delta[0] = 1.0
    impulse = _twiced(delta, sigma_points)[:, 0]  # the filter's weights w_k (w_0 at the point itself)
    tangent = np.roll(out, -1, axis=0) - np.roll(out, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1) / np.linalg.norm(tangent, axis=1)[:, None]
    off = np.sum((q - out) * normal, axis=1)
    spread = 1.4826 * float(np.median(np.abs(off - np.median(off))))
    w2 = float(np.sum(impulse**2))
    jitter = spread / np.sqrt(max(1.0 - 2.0 * float(impulse[0]) + w2, 1e-12))
    return out, jitter, jitter * np.sqrt(w2)


def jagged_note(jitter: float, left: float, jitter_max: float | None = None) -> str:
    """The note saying that outlines were smoothed (:func:`smooth_jagged`): their
    jitter (px; from ``jitter`` to ``jitter_max`` for several) and the most ``left``."""
    amount = f"{jitter:.2g}" if jitter_max is None or f"{jitter_max:.2g}" == f"{jitter:.2g}" else (
        f"{jitter:.2g}-{jitter_max:.2g}")
    return (
        f"the points jitter by {amount} px from point to point (independent noise per point, as raw edge points "
        f"have; the distance to a zigzag is biased towards the samples, which biases K): smoothed along the curve "
        f"(Gaussian of {JAGGED_SMOOTH_PX:g} px, its shrinkage removed), which leaves about {left:.2g} px of noise "
        f"correlated over {JAGGED_SMOOTH_PX:g} px (counted in the uncertainty). Smooth, sub-pixel outlines "
        "(sorjax.outlines_from_mask or sorjax.outlines_from_image) are more accurate."
    )


# The smallest outline error (px RMS) that outlines on a pixel grid carry, whatever
# the outline_error declared (:func:`implied_outline_error`).
QUANTISED_PX = 1.0 / np.sqrt(12.0)  # a coordinate rounded to whole (or half) pixels
STAIRCASE_PX = 0.5  # an unsmoothed staircase along or between pixels (its steps are up to half a pixel off)
# A pixel trace, replaced by its binary mask's outline (:func:`outline_of_pixel_trace`):
# the accuracy of outlines of binary masks.  Measured (experiments/pixel_traces.py, seed
# 0: 45 outlines of renders of known geometry): RMS distance to the exact silhouette
# 0.106 px, mean signed distance -0.003 px (per outline -0.07 to +0.07 px); the
# cv2.findContours points themselves: 0.54 px RMS, -0.46 px.
BINARY_MASK_PX = 0.1


def implied_outline_error(points) -> tuple[float, str]:
    """The outline error (px RMS) the coordinates themselves show, and why:
    ``(BINARY_MASK_PX, "pixel trace")`` for a trace of a binary mask's boundary pixels
    (:func:`is_pixel_trace`, as ``cv2.findContours`` gives; :func:`make_outline`
    replaces it by its mask's outline, as accurate as any binary mask's);
    ``(STAIRCASE_PX, "staircase")`` for other traces on the half-pixel grid with steps
    of at most one pixel in x and y (along pixel edges, or between pixel centres: an
    unsmoothed staircase); ``(QUANTISED_PX, "quantised")`` for other coordinates
    rounded to whole or half pixels (an annotation tool, ``np.round``: uniform rounding
    error, ``1/sqrt(12)`` px per coordinate); ``(0.0, "")`` for sub-pixel outlines (and
    for :class:`Outline` objects, whose points are already resampled)."""
    if isinstance(points, Outline):
        return 0.0, ""
    try:
        p = np.asarray(points, np.float64).reshape(-1, 2)
    except (TypeError, ValueError):
        return 0.0, ""
    if p.size == 0 or not np.all(np.isfinite(p)) or not np.all(np.abs(2.0 * p - np.round(2.0 * p)) < 1e-9):
        return 0.0, ""
    if is_pixel_trace(p):
        return BINARY_MASK_PX, "pixel trace"
    step = np.abs(np.diff(np.vstack([p, p[:1]]), axis=0))
    if np.all(step <= 1.0 + 1e-9):
        return STAIRCASE_PX, "staircase"
    return QUANTISED_PX, "quantised"


def _one_outline_shape(outlines) -> tuple | None:
    """The shape of ``outlines`` when it is one outline passed bare where a list of
    outlines is expected: an :class:`Outline`, a 2-D array (N, 2) -- or (2, N),
    transposed -- of any array type (numpy, JAX, ...), an OpenCV contour (N, 1, 2), or a
    list of (x, y) pairs; else None.  A 3-D array (V, N, 2) is V outlines."""
    if isinstance(outlines, Outline):
        return tuple(outlines.points.shape)
    if outlines is None or isinstance(outlines, (str, bytes, dict)):
        return None
    shape = getattr(outlines, "shape", None)
    if shape is not None and not isinstance(outlines, (list, tuple)):
        try:
            shape = tuple(int(n) for n in shape)
        except (TypeError, ValueError):
            return None
        return shape if len(shape) == 2 or (len(shape) == 3 and shape[1:] == (1, 2)) else None
    if isinstance(outlines, (list, tuple)) and len(outlines) > 0:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                arr = np.asarray(outlines)
        except Exception:
            return None
        if arr.dtype != object and arr.ndim == 2 and arr.shape[1] == 2 and np.issubdtype(arr.dtype, np.number):
            return arr.shape
    return None


def as_outlines(outlines, n_points: int = DEFAULT_POINTS) -> list[Outline]:
    """Validate a sequence of outlines (arrays or :class:`Outline`)."""
    return [o for o, _ in _as_outlines(outlines, n_points)]


def _as_outlines(outlines, n_points: int) -> list[tuple[Outline, tuple[float, float] | None]]:
    """:func:`as_outlines`, each outline with its ``(jitter, left)`` where it was
    smoothed as jagged (:func:`_make_outline`), without warnings (the caller notes)."""
    shape = _one_outline_shape(outlines)
    if shape is not None:
        kind = "list" if isinstance(outlines, list) else "tuple" if isinstance(outlines, tuple) else "array"
        bare = "an Outline" if isinstance(outlines, Outline) else f"a bare {kind} of shape {shape}"
        transposed = len(shape) == 2 and shape[0] == 2 and shape[1] != 2
        raise ValueError(
            f"expected a list of outlines (one per view), got a single outline. Wrap it in a list: pass "
            f"{'[outline.T] (it looks transposed)' if transposed else '[outline]'}, not {bare}; calibration needs at "
            "least two views (or one with principal_point fixed)."
        )
    if outlines is None or isinstance(outlines, (str, bytes, dict)):
        hint = {
            str: " (a file name? load each outline first, e.g. np.loadtxt(path))",
            bytes: "",
            dict: " (pass list(d.values()))",
        }.get(type(outlines), "")
        raise ValueError(
            f"expected a list of outlines (one (N, 2) array of pixel coordinates per view), got "
            f"{type(outlines).__name__}{hint}."
        )
    try:
        seq = list(outlines)
    except TypeError:
        raise ValueError(
            f"expected a list of outlines (one (N, 2) array per view), got {type(outlines).__name__}."
        ) from None
    return [_make_outline(o, n_points, name=f"outline {i}", note=False) for i, o in enumerate(seq)]
