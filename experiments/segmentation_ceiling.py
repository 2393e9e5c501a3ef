"""How many objects could GrabCut segment at all, given perfect boxes (issue 17).

Issue 17 asks the automatic path to find >= 90 % of the objects of the photo-like renders
(:func:`sorjax.render.random_photo_set`).  Finding needs a segmentation first.  For each
object not hidden by clutter, on the image reduced as the automatic detection reduces it
(at most ``DetectOptions.max_side`` px), this measures the intersection over union (IoU)
with the object's exact mask of three segmentations that are each given something the
automatic path does not have:

* ``box``: GrabCut from the object's **exact** bounding box grown by ``box_grow`` (what
  :func:`sorjax._detect.segment_proposal` does with a proposal that is exactly right);
* ``rotated``: GrabCut from the exact mask's minimum-area **rotated** rectangle grown
  the same way (no diagonal corners of table for a lying bottle);
* ``axis DP``: no colour model at all: the image's edges, on the **true** harmonic
  homology.  In the frame where the homology is a reflection ``x' -> -x'`` every line
  through the vertex ``v_x`` is a row, and a surface of revolution's silhouette crosses
  each row in one interval ``[-r, r]`` (every circle of the surface images to a conic
  symmetric about the axis).  Dynamic programming over the rows picks ``r`` per row
  to maximise the colour gradient across the row at ``+r`` and ``-r`` together
  (geometric mean: a shadow or a patch of table on one side has no mirror partner),
  with the cap edges (along the rows) counted between rows and a penalty per pixel
  of change of ``r`` (:func:`axis_dp`).

Printed: per segmentation the objects at IoU >= 0.9 and >= 0.95 (and the median IoU),
and how many are >= 0.9 in at least one of them (an ideal choice between them).  An
object at IoU < 0.9 on the reduced image is rarely within 1 px at full resolution.

    python experiments/segmentation_ceiling.py [--sets 5] [--seed 100]

Cost: about 30 s per set of 4 images on 2 cores (GrabCut twice per object; the DP, a
(rows x widths^2) numpy pass, about 0.1 s).  Seeds are recorded in the output.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from sorjax import render
from sorjax._detect import DetectOptions, _reduce, _segment_region
from sorjax._extract import _grabcut, _largest_component

DP_KAPPA = 1.0  # penalty per px of change of the half-width (in units of the edge scale)
DP_QUANTILE = 95.0  # the edge scale: this percentile of the symmetric edge score in the box
DP_CLIP = 3.0  # a row's gain at most this many edge scales (one strong edge does not decide)
DP_EPS = 2.0  # grey levels added to each side's gradient before the geometric mean
# gain per row for the widest half-width, linear in it: 1.0 favours the outermost pair (a
# highlight on the axis) but gave 159 objects at IoU >= 0.9 over the 30 sets against 162
DP_WIDTH = 0.0


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def rotated_grabcut(sm: np.ndarray, mask: np.ndarray, o: DetectOptions, iterations: int = 5) -> np.ndarray:
    """GrabCut of the reduced image ``sm`` from the minimum-area rotated rectangle of
    ``mask`` grown by ``box_grow`` of its longer side (at least ``box_grow_min`` px)."""
    cnts, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    (cx, cy), (rw, rh), ang = cv2.minAreaRect(np.concatenate(cnts))
    m = max(o.box_grow * max(rw, rh), o.box_grow_min)
    corners = cv2.boxPoints(((cx, cy), (rw + 2 * m, rh + 2 * m), ang))
    inner = np.zeros(sm.shape[:2], np.uint8)
    cv2.fillPoly(inner, [np.round(corners).astype(np.int32)], 1)
    outer = cv2.dilate(inner, np.ones((9, 9), np.uint8))
    init = np.where(inner > 0, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8)
    ys, xs = np.nonzero(outer)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    fg = _grabcut(np.ascontiguousarray(sm[y0:y1, x0:x1]), np.ascontiguousarray(init[y0:y1, x0:x1]), None, iterations)
    out = np.zeros(sm.shape[:2], bool)
    out[y0:y1, x0:x1] = _largest_component(fg)
    return out


def reflection_frame(l_s: np.ndarray, v_x: np.ndarray, centre) -> np.ndarray:
    """3x3 ``T`` taking pixels to a frame where the harmonic homology with axis ``l_s``
    and vertex ``v_x`` (homogeneous, pixels) is ``x' -> -x'``: rows ``l_s . p``, ``m . p``,
    ``n . p`` with ``m`` and ``n`` lines through ``v_x`` (``m`` through the foot of
    ``centre`` on the axis, ``n`` parallel to the axis), scaled so that ``x'`` and
    ``y'`` are about pixels near ``centre``."""
    l = np.asarray(l_s, float) / np.hypot(l_s[0], l_s[1])
    v = np.asarray(v_x, float)
    c = np.array([centre[0], centre[1], 1.0])
    foot = np.array([*(c[:2] - (l @ c) * l[:2]), 1.0])
    m = np.cross(v, foot)
    m /= np.hypot(m[0], m[1])
    n = np.cross(v, np.array([-l[1], l[0], 0.0]))
    T = np.vstack([l * (n @ c), m * (n @ c), n])
    return -T if n @ c < 0 else T


def axis_dp(sm: np.ndarray, l_s, v_x, box) -> np.ndarray | None:
    """The region (bool, the size of ``sm``) that the row DP of the module docstring
    picks in ``box`` = (x0, y0, x1, y1) (reduced px) for the homology ``(l_s, v_x)``, or
    None when it picks no row."""
    x0, y0, x1, y1 = box
    T = reflection_frame(l_s, v_x, (0.5 * (x0 + x1), 0.5 * (y0 + y1)))
    c = np.array([[x0, y0, 1], [x1, y0, 1], [x0, y1, 1], [x1, y1, 1]], float) @ T.T
    cx, cy = c[:, 0] / c[:, 2], c[:, 1] / c[:, 2]
    R = int(np.ceil(np.max(np.abs(cx)))) + 2
    ya = float(np.min(cy)) - 2.0
    ny = int(np.ceil(np.max(cy) + 2.0 - ya)) + 1
    A = np.array([[1.0, 0.0, -R], [0.0, 1.0, ya], [0.0, 0.0, 1.0]])
    rect = cv2.warpPerspective(sm.astype(np.float32), np.linalg.inv(T) @ A, (2 * R + 1, ny),
                               flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    rect = cv2.GaussianBlur(rect, (0, 0), 1.0)
    gx = np.sqrt(np.sum((0.5 * (np.roll(rect, -1, 1) - np.roll(rect, 1, 1))) ** 2, axis=2))
    gy = np.sqrt(np.sum((np.roll(rect, -1, 0) - rect) ** 2, axis=2))  # between rows i and i + 1
    gx[:, [0, -1]] = 0.0
    gy[-1] = 0.0
    sv = np.sqrt((gx[:, R:] + DP_EPS) * (gx[:, R::-1] + DP_EPS)) - DP_EPS  # rows x half-widths 0..R
    sh = np.sqrt((gy[:, R:] + DP_EPS) * (gy[:, R::-1] + DP_EPS)) - DP_EPS
    b = max(float(np.percentile(sv, DP_QUANTILE)), 1e-6)
    sv = np.clip((sv - b) / b, -1.0, DP_CLIP) + DP_WIDTH * np.arange(R + 1)[None, :] / R
    sv[:, 0] = 0.0
    ch = np.cumsum(np.clip((sh - b) / b, -1.0, 1.0), axis=1)
    ch[:, 0] = 0.0
    K = R + 1
    rr = np.arange(K)
    NEG = -1e18
    # states 0..R: the half-width (0: before the object), K: after it
    G = np.full(K + 1, NEG)
    G[0] = 0.0
    G[1:K] = sv[0, 1:] - DP_KAPPA * rr[1:]
    back = np.zeros((ny, K + 1), np.int64)
    jump = DP_KAPPA * np.abs(rr[:, None] - rr[None, :])
    sgn = np.sign(rr[None, :] - rr[:, None])
    for i in range(1, ny):
        trans = G[:K, None] + (ch[i - 1][None, :] - ch[i - 1][:, None]) * sgn - jump  # [from, to]
        a = np.argmax(trans[:, 1:], axis=0)
        new = np.full(K + 1, NEG)
        new[1:K] = trans[a, rr[1:]] + sv[i, 1:]
        back[i, 1:K] = a
        new[0] = G[0]
        close = G[1:K] + ch[i - 1][1:] - DP_KAPPA * rr[1:]
        j = int(np.argmax(close))
        new[K], back[i, K] = (close[j], j + 1) if close[j] >= G[K] else (G[K], K)
        G = new
    end = G[1:K] - DP_KAPPA * rr[1:]
    k = K if G[K] >= end.max() else 1 + int(np.argmax(end))
    r = np.zeros(ny, int)
    for i in range(ny - 1, -1, -1):
        r[i] = 0 if k in (0, K) else k
        k = back[i, k]
    rows = np.flatnonzero(r > 0)
    if rows.size == 0:
        return None
    ys = ya + rows
    half = np.column_stack([r[rows], ys])
    poly = np.vstack([[0.0, ys[0] - 0.5], half, [0.0, ys[-1] + 0.5], half[::-1] * [-1.0, 1.0]])
    P = np.column_stack([poly, np.ones(len(poly))]) @ np.linalg.inv(T).T
    out = np.zeros(sm.shape[:2], np.uint8)
    cv2.fillPoly(out, [np.round(P[:, :2] / P[:, 2:] * 16).astype(np.int32)], 1, shift=4)
    return out.astype(bool)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=5, help="photo sets (default 5)")
    ap.add_argument("--seed", type=int, default=100, help="seed of the first set (default 100)")
    ap.add_argument("--images", type=int, default=4, help="images per set, one camera (default 4)")
    args = ap.parse_args(argv)
    o = DetectOptions()
    names = ("box", "rotated", "axis DP")
    rows, t0 = [], time.perf_counter()
    print(f"segmentation ceiling: random_photo_set seeds {args.seed}..{args.seed + args.sets - 1}, 1 camera x "
          f"{args.images} images; IoU with the exact mask on the image reduced to <= {o.max_side} px")
    for seed in range(args.seed, args.seed + args.sets):
        ps = render.random_photo_set(seed, cameras=1, images=args.images)
        for k, r in enumerate(ps.cameras[0].renders):
            sm, s = _reduce(r.image, o.max_side)
            h, w = sm.shape[:2]
            S, Si = np.diag([s, s, 1.0]), np.diag([1.0 / s, 1.0 / s, 1.0])
            for ob in r.objects:
                if ob.occluded:
                    continue
                exact = cv2.resize(ob.coverage, (w, h), interpolation=cv2.INTER_AREA) >= 0.5
                pbox = tuple(int(round(v * s)) for v in ob.box)
                win, fg, _ = _segment_region(sm, pbox, 5, o)
                box_cut = np.zeros((h, w), bool)
                box_cut[win[1]:win[3], win[0]:win[2]] = fg
                bx = np.array(ob.box, float) * s
                g = o.box_grow * max(bx[2] - bx[0], bx[3] - bx[1])
                dp = axis_dp(sm, Si.T @ ob.truth.l_s, S @ ob.truth.v_x, (bx[0] - g, bx[1] - g, bx[2] + g, bx[3] + g))
                ious = (_iou(box_cut, exact), _iou(rotated_grabcut(sm, exact, o), exact),
                        0.0 if dp is None else _iou(dp, exact))
                rows.append(ious)
                print(f"  set {seed} image {k} {ob.name:13s} " + "  ".join(f"{n} {v:.3f}" for n, v in zip(names, ious)),
                      flush=True)
    A = np.array(rows)
    n = len(A)
    print(f"summary over {n} objects ({time.perf_counter() - t0:.0f} s):")
    for j, name in enumerate(names):
        print(f"  {name:8s} IoU >= 0.9: {np.sum(A[:, j] >= 0.9):3d} ({100 * np.mean(A[:, j] >= 0.9):.0f} %), "
              f">= 0.95: {np.sum(A[:, j] >= 0.95):3d}, median {np.median(A[:, j]):.3f}")
    best = np.sum(np.any(A >= 0.9, axis=1))
    print(f"  any of them IoU >= 0.9: {best} ({100 * best / n:.0f} %)  (issue 17 asks the automatic path to find 90 %)")


if __name__ == "__main__":
    main()
