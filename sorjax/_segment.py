"""Segmentation primitives on images: GrabCut, connected components, morphology, boxes.

Plain OpenCV on numpy arrays (pixels, OpenCV's convention), shared by the automatic
detection (:mod:`sorjax._detect`) and the image path (:mod:`sorjax._extract`).
"""

from __future__ import annotations

import cv2
import numpy as np


def _grabcut(img: np.ndarray, mask: np.ndarray | None, rect, iterations: int) -> np.ndarray:
    """Foreground (bool) of cv2.grabCut, deterministic (OpenCV's RNG reseeded)."""
    cv2.setRNGSeed(12345)
    bgd = np.zeros((1, 65), np.float64)
    fgd = np.zeros((1, 65), np.float64)
    if mask is None:
        m = np.zeros(img.shape[:2], np.uint8)
        cv2.grabCut(img, m, rect, bgd, fgd, iterations, cv2.GC_INIT_WITH_RECT)
    else:
        m = mask.copy()
        cv2.grabCut(img, m, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    return (m == cv2.GC_FGD) | (m == cv2.GC_PR_FGD)


def _largest_component(fg: np.ndarray, within=None) -> np.ndarray:
    """The largest 8-connected component of ``fg`` (with ``within`` = ``(x0, y0, x1,
    y1)``, inclusive: the one with the most pixels inside that box), holes filled."""
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg.astype(np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros_like(fg, dtype=bool)
    if within is None:
        k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    else:
        x0, y0, x1, y1 = within
        k = int(np.argmax(np.bincount(lab[y0:y1 + 1, x0:x1 + 1].ravel(), minlength=n)[1:])) + 1
    comp = lab == k
    # fill holes: outer boundary only
    cnts, _ = cv2.findContours(comp.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros(fg.shape, np.uint8)
    cv2.drawContours(filled, cnts, -1, 1, thickness=cv2.FILLED)
    return filled.astype(bool)


def _crop_box(box, shape, margin_frac=0.15, margin_min=12):
    H, W = shape
    x0, y0, x1, y1 = box
    m = max(margin_min, int(round(margin_frac * max(x1 - x0, y1 - y0))))
    return max(0, x0 - m), max(0, y0 - m), min(W, x1 + m + 1), min(H, y1 + m + 1)


def _dilate(m: np.ndarray, r: int) -> np.ndarray:
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return cv2.dilate(m.astype(np.uint8), k).astype(bool)


def _erode(m: np.ndarray, r: int) -> np.ndarray:
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return cv2.erode(m.astype(np.uint8), k).astype(bool)
