"""Photographs and boxes as ``outlines_from_image`` takes them: the image checked and
wrapped (uint8, uint16 or float in [0, 1]; colour, BGRA or grey; converted to float64 BGR
in 8-bit units only on the windows asked for) and the boxes checked (``(x0, y0, x1, y1)``
in pixels, OpenCV's convention as described in :mod:`sorjax._extract`).
"""

from __future__ import annotations

import math

import numpy as np

from ._masks import _check_unit_range, _row_blocks


class _Image:
    """A validated photograph: ``u8`` (H, W, 3) uint8 BGR for GrabCut (the caller's
    own array when it is contiguous uint8 BGR, else converted a block of rows at a
    time) and :meth:`f64`, float64 BGR in 8-bit units, converted only on the windows
    asked for (elementwise: a window's values are the whole image's)."""

    def __init__(self, im: np.ndarray):
        self.im, self.shape = im, im.shape[:2]
        if im.dtype == np.uint8 and im.shape[2] >= 3:
            self.u8 = np.ascontiguousarray(im[:, :, :3])
        else:
            self.u8 = np.empty(im.shape[:2] + (3,), np.uint8)
            for i0, i1 in _row_blocks(*self.shape):
                self.u8[i0:i1] = np.clip(np.round(self._f(im[i0:i1])), 0, 255).astype(np.uint8)

    def _f(self, a: np.ndarray) -> np.ndarray:
        if a.dtype == np.uint8:
            f = a.astype(np.float64)
        elif a.dtype == np.uint16:
            f = a.astype(np.float64) / 257.0
        else:
            f = np.clip(a.astype(np.float64), 0.0, 1.0) * 255.0
        if f.shape[2] == 1:
            f = np.repeat(f, 3, axis=2)
        elif f.shape[2] == 4:
            f = f[:, :, :3]
        return np.ascontiguousarray(f)

    def f64(self, y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
        return self._f(self.im[y0:y1, x0:x1])


def _as_bgr(image) -> _Image:
    """The photograph checked (uint8, uint16 or float in [0, 1]; colour, BGRA or grey)."""
    if isinstance(image, (str, bytes)) or image is None:
        raise ValueError(
            f"image must be an array (H, W, 3), got {type(image).__name__}; read the file "
            "first with cv2.imread(path)"
        )
    im = np.asarray(image)
    if im.ndim == 2:
        im = im[:, :, None]
    if im.ndim != 3 or im.shape[2] not in (1, 3, 4):
        raise ValueError(
            f"image must be (H, W, 3) BGR (as cv2.imread returns), (H, W, 4) or (H, W) grey; "
            f"got shape {im.shape}"
        )
    if im.shape[0] < 16 or im.shape[1] < 16:
        raise ValueError(f"image is too small ({im.shape[1]}x{im.shape[0]} px): need at least 16x16")
    if np.issubdtype(im.dtype, np.floating):
        _check_unit_range(im, "image", "", "Convert 8-bit data to uint8, or divide by 255", 1e-6)
    elif im.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image dtype must be uint8, uint16 or float, got {im.dtype}")
    return _Image(im)


def _check_boxes(boxes, shape) -> list[tuple[int, int, int, int]]:
    H, W = shape
    try:
        arr = [tuple(float(v) for v in b) for b in boxes]
    except (TypeError, ValueError):
        raise ValueError("boxes must be a sequence of (x0, y0, x1, y1) boxes in pixels") from None
    if len(arr) == 0:
        raise ValueError("boxes is empty: pass None for automatic detection, or at least one box")
    out = []
    for k, b in enumerate(arr):
        if len(b) != 4 or not all(math.isfinite(v) for v in b):
            raise ValueError(f"box {k} must be 4 finite numbers (x0, y0, x1, y1) in pixels, got {b}")
        x0, y0, x1, y1 = b
        if not (x1 > x0 + 4 and y1 > y0 + 4):
            raise ValueError(
                f"box {k} = {b}: need x1 > x0 and y1 > y0 (corners top-left, bottom-right, at "
                "least 5 px apart)"
            )
        if x1 < 0 or y1 < 0 or x0 > W - 1 or y0 > H - 1:
            raise ValueError(f"box {k} = {b} lies outside the {W}x{H} image")
        xi0, yi0 = max(0, int(math.floor(x0))), max(0, int(math.floor(y0)))
        xi1, yi1 = min(W - 1, int(math.ceil(x1))), min(H - 1, int(math.ceil(y1)))
        out.append((xi0, yi0, xi1, yi1))
    return out
