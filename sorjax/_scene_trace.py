"""The outline engine of the exact silhouettes: candidate curves -> visible pieces -> one
closed outline.

A candidate curve (:class:`_Path`) is an exact parametrisation in pixels (an ellipse arc,
a branch of a contour generator, an end circle) with a test of whether its points are
hidden.  :func:`_trace_outline` cuts every path at the exact occlusion points
(bisection), resamples the visible pieces uniformly in arc length by re-evaluating the
exact parametrisation, joins them in boundary order and verifies the result: closed, no
self-intersection, no gap larger than the sample spacing.  Outlines are closed ``(M, 2)``
float64 pixel arrays without a repeated end point, with a positive shoelace area
(:func:`_signed_area`; clockwise as displayed, ``y`` down), starting at the top-most
point (see "Exact silhouettes" in :mod:`sorjax.scenes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


def _signed_area(p: np.ndarray) -> float:
    """Shoelace area of the closed polygon ``p`` (positive: clockwise as displayed)."""
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


# ----------------------------------------------------------------------------------
# Outline engine: exact parametric paths -> visible pieces -> one closed outline
# ----------------------------------------------------------------------------------


@dataclass
class _Path:
    """A candidate curve: ``func(tau) -> (pixels (n, 2), aux (n, k))``, exact for any tau.

    Closed paths are periodic with period ``t1 - t0``.  ``nodes`` are parameters that
    are sampled exactly and, when visible next to a hidden sample, taken as the exact
    visibility boundary (tangential junctions, where bisection would be ill-posed).
    ``hidden(pixels, aux) -> bool`` tells whether points are strictly inside the
    silhouette; ``hidden_strict`` (default: ``hidden``) is a tighter version used to
    locate occlusion corners by bisection.
    """

    func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    hidden: Callable[[np.ndarray, np.ndarray], np.ndarray]
    t0: float
    t1: float
    closed: bool
    label: str
    nodes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hidden_strict: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None


@dataclass
class _Piece:
    img: np.ndarray
    aux: np.ndarray
    label: str
    closed: bool


def _refine(path: _Path, tau: np.ndarray, max_gap: float, img=None, aux=None, max_rounds: int = 60):
    """Insert midpoints until consecutive pixels are at most ``max_gap`` apart."""
    tau = np.asarray(tau, dtype=np.float64)
    if img is None:
        img, aux = path.func(tau)
    for _ in range(max_rounds):
        gap = np.hypot(*np.diff(img, axis=0).T)
        bad = ~(gap <= max_gap)
        if not bad.any():
            return tau, img, aux
        mid = 0.5 * (tau[:-1][bad] + tau[1:][bad])
        mimg, maux = path.func(mid)
        tau = np.concatenate([tau, mid])
        img = np.concatenate([img, mimg])
        aux = np.concatenate([aux, maux])
        order = np.argsort(tau, kind="stable")
        tau, img, aux = tau[order], img[order], aux[order]
    raise ValueError(
        f"could not sample the {path.label} curve finely enough (a point escapes to "
        "infinity?): the pose gives an outline that cannot be built"
    )


def _bisect_boundary(path: _Path, t_vis: np.ndarray, t_hid: np.ndarray, iters: int = 56) -> np.ndarray:
    """Parameters of the visibility boundary, on the visible side, to machine precision."""
    lo, hi = t_vis.copy(), t_hid.copy()
    hidden = path.hidden_strict or path.hidden
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        img, aux = path.func(mid)
        h = hidden(img, aux)
        hi = np.where(h, mid, hi)
        lo = np.where(h, lo, mid)
    return lo


def _resample(path: _Path, tau: np.ndarray, spacing: float, closed: bool, min_len: float):
    """Exact points at (nearly) uniform arc-length spacing <= ``spacing`` on ``tau[0]..tau[-1]``."""
    tau, img, aux = _refine(path, tau, spacing / 8.0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(img, axis=0).T))])
    L = cum[-1]
    if not closed and L < min_len:
        return None
    n = max(int(math.ceil(L / (0.98 * spacing))), 3 if closed else 1)
    tt = np.interp(np.linspace(0.0, L, n + 1), cum, tau)
    tt[0], tt[-1] = tau[0], tau[-1]
    # chords can exceed the nominal spacing where the curvature varies fast: split them
    tt, pimg, paux = _refine(path, tt, spacing)
    if closed:
        tt, pimg, paux = tt[:-1], pimg[:-1], paux[:-1]
    return _Piece(pimg, paux, path.label, closed)


def _visible_pieces(path: _Path, spacing: float, coarse_gap: float, min_len: float, n0: int = 96):
    grid = np.linspace(path.t0, path.t1, n0 + 1)
    tau0 = np.unique(np.concatenate([grid, np.asarray(path.nodes, dtype=np.float64)]))
    tau, img, aux = _refine(path, tau0, coarse_gap)
    if path.closed:
        tau, img, aux = tau[:-1], img[:-1], aux[:-1]
    hid = np.asarray(path.hidden(img, aux), dtype=bool)
    exact = np.isin(tau, path.nodes)
    period = path.t1 - path.t0
    if not hid.any():
        if path.closed:
            return [_resample(path, np.append(tau, tau[0] + period), spacing, True, min_len)]
        piece = _resample(path, tau, spacing, False, min_len)
        return [] if piece is None else [piece]
    if hid.all():
        return []
    if path.closed:  # rotate to start at a hidden sample and repeat it at the end
        n = len(tau)
        k = int(np.argmax(hid))
        order = (np.arange(n) + k) % n
        tau = tau[order] + np.where(order < k, period, 0.0)
        hid, exact = hid[order], exact[order]
        tau = np.append(tau, tau[0] + period)
        hid = np.append(hid, True)
        exact = np.append(exact, exact[0])
    # transitions between consecutive samples
    tr = np.flatnonzero(hid[:-1] != hid[1:])
    vis_idx = np.where(hid[tr], tr + 1, tr)
    hid_idx = np.where(hid[tr], tr, tr + 1)
    bound = tau[vis_idx].copy()
    need = ~exact[vis_idx]
    if need.any():
        bound[need] = _bisect_boundary(path, tau[vis_idx][need], tau[hid_idx][need])
    bmap = dict(zip(tr.tolist(), bound.tolist()))
    pieces = []
    vis = ~hid
    i, n = 0, len(tau)
    while i < n:
        if not vis[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and vis[j + 1]:
            j += 1
        ts = list(tau[i : j + 1])
        if i > 0 and tau[i] != bmap[i - 1]:
            ts.insert(0, bmap[i - 1])
        if j < n - 1 and tau[j] != bmap[j]:
            ts.append(bmap[j])
        ts = np.asarray(ts)
        if len(ts) >= 2 and ts[-1] > ts[0]:
            piece = _resample(path, ts, spacing, False, min_len)
            if piece is not None:
                pieces.append(piece)
        i = j + 1
    return pieces


def _chain(pieces: list[_Piece], join_tol: float, dedupe_tol: float):
    """Join pieces end to end into closed loops; raise ValueError when impossible.

    Where two joined ends are closer than ``dedupe_tol`` only the first is kept.
    """
    loops = [(p.img, p.aux, np.full(len(p.img), p.label)) for p in pieces if p.closed]
    open_ = [p for p in pieces if not p.closed]
    used = np.zeros(len(open_), dtype=bool)
    while not used.all():
        k = int(np.argmin(used))
        used[k] = True
        imgs, auxs, labs = [open_[k].img], [open_[k].aux], [np.full(len(open_[k].img), open_[k].label)]
        start = open_[k].img[0]
        while True:
            end = imgs[-1][-1]
            best, best_d, rev = -1, np.linalg.norm(end - start), False
            for j in np.flatnonzero(~used):
                d0 = np.linalg.norm(end - open_[j].img[0])
                d1 = np.linalg.norm(end - open_[j].img[-1])
                if d0 < best_d:
                    best, best_d, rev = j, d0, False
                if d1 < best_d:
                    best, best_d, rev = j, d1, True
            if best_d > join_tol:
                raise ValueError(
                    f"the visible pieces of the silhouette do not join (gap {best_d:.3g} px): "
                    "the pose gives an outline that cannot be built"
                )
            if best < 0:
                break
            used[best] = True
            p = open_[best]
            pi, pa = (p.img[::-1], p.aux[::-1]) if rev else (p.img, p.aux)
            if np.linalg.norm(pi[0] - end) < dedupe_tol:
                pi, pa = pi[1:], pa[1:]
            imgs.append(pi)
            auxs.append(pa)
            labs.append(np.full(len(pi), p.label))
        img, aux, lab = np.concatenate(imgs), np.concatenate(auxs), np.concatenate(labs)
        if len(img) > 1 and np.linalg.norm(img[-1] - img[0]) < dedupe_tol:
            img, aux, lab = img[:-1], aux[:-1], lab[:-1]
        loops.append((img, aux, lab))
    return loops


def _points_in_polygon(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised."""
    x1, y1 = poly[:, 0][None], poly[:, 1][None]
    q = np.roll(poly, -1, axis=0)
    x2, y2 = q[:, 0][None], q[:, 1][None]
    x, y = pts[:, 0][:, None], pts[:, 1][:, None]
    cond = (y1 > y) != (y2 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
    return (np.sum(cond & (x < xi), axis=1) % 2) == 1


def _self_intersections(p: np.ndarray) -> int:
    """Number of properly crossing pairs of non-adjacent edges of the closed polygon."""
    M = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    cell = max(float(np.max(hi - lo)), 1e-9) * 1.0001
    i0 = np.floor((lo - lo.min(0)) / cell).astype(np.int64)
    i1 = np.floor((hi - lo.min(0)) / cell).astype(np.int64)
    ny = int(i1[:, 1].max()) + 2
    segs, keys = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            ok = (i0[:, 0] + dx <= i1[:, 0]) & (i0[:, 1] + dy <= i1[:, 1])
            idx = np.flatnonzero(ok)
            segs.append(idx)
            keys.append((i0[idx, 0] + dx) * ny + (i0[idx, 1] + dy))
    segs, keys = np.concatenate(segs), np.concatenate(keys)
    order = np.argsort(keys, kind="stable")
    segs, keys = segs[order], keys[order]
    _, counts = np.unique(keys, return_counts=True)
    si, sj = [], []
    for o in range(1, int(counts.max())):
        same = keys[:-o] == keys[o:]
        si.append(segs[:-o][same])
        sj.append(segs[o:][same])
    if not si:
        return 0
    si, sj = np.concatenate(si), np.concatenate(sj)
    dd = np.abs(si - sj)
    keep = (dd > 1) & (dd < M - 1)
    si, sj = si[keep], sj[keep]

    def orient(p0, p1, p2):
        return (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0])

    A, B, Cq, D = a[si], b[si], a[sj], b[sj]
    cross = (orient(A, B, Cq) * orient(A, B, D) < 0) & (orient(Cq, D, A) * orient(Cq, D, B) < 0)
    pairs = {(min(x, y), max(x, y)) for x, y in zip(si[cross].tolist(), sj[cross].tolist())}
    return len(pairs)


def _trace_outline(paths: list[_Path], *, spacing: float, coarse_gap: float):
    """Outer boundary of the silhouette from its candidate paths (see module docstring)."""
    join_tol = min(0.1, 0.5 * spacing)
    min_len = 1e-2 * spacing
    pieces = []
    for p in paths:
        pieces.extend(_visible_pieces(p, spacing, coarse_gap, min_len))
    if not pieces:
        raise ValueError("no visible silhouette piece: the pose gives an outline that cannot be built")
    # Pieces meeting at a corner end within ~1e-7 px of each other (transversal
    # occlusion), or up to ~1e-3 px apart, both slightly past the corner, where the
    # occluding curves cross at a grazing angle (the penetration then grows only
    # quadratically); keeping one of the two end points avoids a tiny bow-tie.
    loops = _chain(pieces, join_tol, dedupe_tol=1e-2 * spacing)
    areas = [abs(_signed_area(l[0])) if len(l[0]) >= 3 else 0.0 for l in loops]
    k = int(np.argmax(areas))
    img, aux, lab = loops[k]
    for j, other in enumerate(loops):  # holes are fine, other outer components are not
        if j == k:
            continue
        pts = other[0][:: max(1, len(other[0]) // 200)]
        inside = _points_in_polygon(img, pts)
        if not inside.all():
            d = np.min(np.hypot(*(pts[~inside][:, None, :] - img[None]).transpose(2, 0, 1)), axis=1)
            if np.any(d > join_tol):
                raise ValueError(
                    "the silhouette has several disjoint components: the pose gives an "
                    "outline that cannot be built"
                )
    if _signed_area(img) < 0:
        img, aux, lab = img[::-1], aux[::-1], lab[::-1]
    s = int(np.argmin(img[:, 1]))
    img, aux, lab = np.roll(img, -s, 0), np.roll(aux, -s, 0), np.roll(lab, -s, 0)
    gaps = np.hypot(*(np.roll(img, -1, 0) - img).T)
    if len(img) < 16 or gaps.max() > spacing * 1.01 + 1e-9:
        raise ValueError(
            f"outline has a gap of {gaps.max():.3g} px (> spacing {spacing} px): the pose gives "
            "an outline that cannot be built"
        )
    if _self_intersections(img):
        raise ValueError("outline self-intersects: the pose gives an outline that cannot be built")
    return img, aux, lab
