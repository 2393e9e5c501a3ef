"""Object proposals of the automatic finding (:func:`sorjax._detect.find_objects`):
candidate boxes ``(x0, y0, x1, y1)`` (inclusive pixels of the image reduced to at most
``DetectOptions.max_side`` px) from several cues, each a region that may be an object.
The cues and the rules a region must pass are described in :mod:`sorjax._detect`'s
docstring ("Object finding").
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from ._detect_options import DetectOptions


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
