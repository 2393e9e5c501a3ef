"""Exact silhouettes of a general surface of revolution.

The projection of the solid is the union over ``y`` of the filled ellipses that image
the discs.  Its boundary consists of (i) the images of the contour generator, where the
surface normal ``N = (cos phi, -r'(y), sin phi)`` is perpendicular to the viewing ray
``X - C``, i.e. (``C`` in object coordinates)::

    Cx cos(phi) + Cz sin(phi) = g(y) = r(y) - r'(y) (y - Cy)
    phi = alpha +- arccos(g(y) / rho_c),  rho_c = hypot(Cx, Cz),  alpha = atan2(Cz, Cx)

(two branches, the two sides of the outline, joining at folds where ``|g| = rho_c``),
and (ii) arcs of the ellipses that image the end circles (and the crease circles at
declared profile breaks).  A candidate point is *hidden* when its viewing ray enters the
interior of the solid: ``max_s r(y(s)) - rho(s) > 0`` along the ray (``rho(s)`` the
distance of the ray point from the axis), found by a dense search along the ray followed
by golden-section refinement of the local maxima (exact to rounding).  The visible pieces
are traced into one outline by :mod:`sorjax._scene_trace`.  Pixels and cameras as in
:mod:`sorjax.scenes`; object units those of the profile.
"""

from __future__ import annotations

import math

import numpy as np

from ._scene_camera import _as_pose, _check_K, _project, camera_centre, camera_matrix
from ._scene_profiles import Profile
from ._scene_trace import _Path, _trace_outline
from ._scene_types import Silhouette


def _max_penetration(profile: Profile, C: np.ndarray, D: np.ndarray, n_grid: int = 256,
                     n_peaks: int = 4, iters: int = 48) -> np.ndarray:
    """``max_{s > 0} r(y(s)) - rho(s)`` along the rays ``C + s D`` (object units).

    Positive: the ray enters the interior of the solid (its pixel is strictly inside
    the silhouette); zero: it touches the surface; negative (``-inf`` if the ray misses
    the bounding cylinder): it passes outside.  Dense search over the part of the ray
    inside the bounding cylinder and height slab, then golden-section refinement of
    the ``n_peaks`` best local maxima (exact to rounding for smooth profiles).
    """
    D = np.atleast_2d(np.asarray(D, dtype=np.float64))
    D = D / np.linalg.norm(D, axis=1)[:, None]
    m = len(D)
    Cx, Cy, Cz = (float(c) for c in C)
    Dx, Dy, Dz = D.T
    y0, y1 = profile.y0, profile.y1
    tiny = 1e-14
    flat = np.abs(Dy) < tiny
    with np.errstate(divide="ignore", invalid="ignore"):
        sa, sb = (y0 - Cy) / Dy, (y1 - Cy) / Dy
    in_slab = y0 <= Cy <= y1
    lo = np.where(flat, -np.inf if in_slab else np.inf, np.minimum(sa, sb))
    hi = np.where(flat, np.inf if in_slab else -np.inf, np.maximum(sa, sb))
    Rc = profile.r_max * 1.001 + 1e-12 * profile.scale
    a = Dx**2 + Dz**2
    b = 2.0 * (Cx * Dx + Cz * Dz)
    c = Cx**2 + Cz**2 - Rc**2
    disc = b**2 - 4.0 * a * c
    ok = (a > tiny) & (disc >= 0)
    sq = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c_lo, c_hi = (-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)
    par = a <= tiny
    c_lo = np.where(ok, c_lo, np.where(par & (c <= 0), -np.inf, np.inf))
    c_hi = np.where(ok, c_hi, np.where(par & (c <= 0), np.inf, -np.inf))
    lo = np.maximum(np.maximum(lo, c_lo), 0.0)
    hi = np.minimum(hi, c_hi)
    out = np.full(m, -np.inf)
    valid = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    if not valid.any():
        return out
    vi = np.flatnonzero(valid)
    lo, hi, Dv = lo[vi], hi[vi], D[vi]

    def h(s, Dr):
        y = np.clip(Cy + s * Dr[:, 1:2] if s.ndim == 2 else Cy + s * Dr[:, 1], y0, y1)
        if s.ndim == 2:
            rho = np.hypot(Cx + s * Dr[:, 0:1], Cz + s * Dr[:, 2:3])
        else:
            rho = np.hypot(Cx + s * Dr[:, 0], Cz + s * Dr[:, 2])
        return profile.r(y) - rho

    u = np.linspace(0.0, 1.0, n_grid)
    S = lo[:, None] + (hi - lo)[:, None] * u[None, :]
    H = h(S, Dv)
    best = H.max(axis=1)
    eps = 1e-10 * profile.scale
    und = np.flatnonzero(best <= eps)  # undecided rows: refine their local maxima
    if len(und):
        Hu, Su = H[und], S[und]
        pad = np.pad(Hu, ((0, 0), (1, 1)), constant_values=-np.inf)
        is_max = (Hu >= pad[:, :-2]) & (Hu >= pad[:, 2:])
        vm = np.where(is_max, Hu, -np.inf)
        k = min(n_peaks, n_grid)
        top = np.argpartition(-vm, k - 1, axis=1)[:, :k]
        rows = np.repeat(np.arange(len(und)), k)
        cols = top.reshape(-1)
        keep = np.isfinite(vm[rows, cols])
        rows, cols = rows[keep], cols[keep]
        A = Su[rows, np.maximum(cols - 1, 0)]
        B = Su[rows, np.minimum(cols + 1, n_grid - 1)]
        Dr = Dv[und][rows]
        g = (math.sqrt(5.0) - 1.0) / 2.0
        x1, x2 = B - g * (B - A), A + g * (B - A)
        f1, f2 = h(x1, Dr), h(x2, Dr)
        for _ in range(iters):
            left = f1 > f2
            B = np.where(left, x2, B)
            A = np.where(left, A, x1)
            nx1 = np.where(left, B - g * (B - A), x2)
            nx2 = np.where(left, x1, A + g * (B - A))
            xn = np.where(left, nx1, nx2)
            fn = h(xn, Dr)
            f1, f2 = np.where(left, fn, f2), np.where(left, f1, fn)
            x1, x2 = nx1, nx2
        ref = np.full(len(und), -np.inf)
        np.maximum.at(ref, rows, np.maximum(f1, f2))
        best[und] = np.maximum(best[und], ref)
    out[vi] = best
    return out


def _check_camera(profile: Profile, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera centre in object coordinates; ValueError for unusable cameras."""
    C = camera_centre(R, t)
    rho_c = math.hypot(C[0], C[2])
    if profile.y0 <= C[1] <= profile.y1 and rho_c <= float(profile.r(np.array([C[1]]))[0]):
        raise ValueError(
            f"the camera centre {np.round(C, 6).tolist()} is inside the object {profile.name!r} "
            "(object coordinates): move the camera out of the solid"
        )
    if rho_c <= 1e-9 * profile.scale:
        raise ValueError("the camera centre lies on the revolution axis: l_s and v_x are undefined")
    ys = np.linspace(profile.y0, profile.y1, 4001)
    depth = R[2, 1] * ys + t[2] - profile.r(ys) * math.hypot(R[2, 0], R[2, 2])
    if depth.min() <= 1e-6 * profile.scale:
        raise ValueError(
            f"the object {profile.name!r} is not entirely in front of the camera "
            f"(minimum depth {depth.min():.3g} object units)"
        )
    return C


def _sor_paths(profile: Profile, P: np.ndarray, C: np.ndarray) -> list[_Path]:
    Cx, Cy, Cz = C
    rho_c = math.hypot(Cx, Cz)
    alpha = math.atan2(Cz, Cx)
    eps = 1e-10 * profile.scale
    edges = [profile.y0, *sorted(profile.breaks), profile.y1]
    n_edges = len(edges)

    def hidden(img, X):
        return _max_penetration(profile, C, X - C) > eps

    def hidden_strict(img, X):
        return _max_penetration(profile, C, X - C) > 1e-3 * eps

    def make_g(a, b):
        da = 1e-12 * (b - a)

        def g(y):
            return profile.r(y) - profile.dr(np.clip(y, a + da, b - da)) * (y - Cy)

        return g

    def contour_func(ymap, g):
        def func(tau):
            tau = np.asarray(tau, dtype=np.float64)
            y, sig = ymap(tau)
            th = np.arccos(np.clip(g(y) / rho_c, -1.0, 1.0))
            phi = alpha + sig * th
            r = profile.r(y)
            X = np.column_stack([r * np.cos(phi), y, r * np.sin(phi)])
            return _project(P, X), X

        return func

    paths: list[_Path] = []
    junctions: dict[int, list[float]] = {e: [] for e in range(n_edges)}
    for ei in range(n_edges - 1):
        a, b = edges[ei], edges[ei + 1]
        g = make_g(a, b)
        ys = np.linspace(a, b, 2049)
        with np.errstate(invalid="ignore", over="ignore"):
            q = rho_c**2 - g(ys) ** 2
        pos = np.nan_to_num(q, nan=-1.0, neginf=-1.0) >= 0

        def root(i):  # fold between ys[i] and ys[i + 1]; returned on the q >= 0 side
            lo_, hi_ = ys[i], ys[i + 1]
            good_lo = bool(pos[i])
            for _ in range(80):
                mid = 0.5 * (lo_ + hi_)
                ok = rho_c**2 - g(np.array([mid]))[0] ** 2 >= 0
                if ok == good_lo:
                    lo_ = mid
                else:
                    hi_ = mid
            return lo_ if good_lo else hi_

        idx = np.flatnonzero(pos)
        if len(idx) == 0:
            continue
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        for run in runs:
            ia, ib = int(run[0]), int(run[-1])
            fold_a, fold_b = ia > 0, ib < len(ys) - 1
            ya = root(ia - 1) if fold_a else a
            yb = root(ib) if fold_b else b
            if not yb > ya:
                continue
            if fold_a and fold_b:
                def ymap(t, ya=ya, yb=yb):
                    return ya + (yb - ya) * 0.5 * (1.0 - np.cos(t)), np.where(np.mod(t, 2 * np.pi) < np.pi, 1.0, -1.0)
                paths.append(_Path(contour_func(ymap, g), hidden, 0.0, 2 * math.pi, True, "contour",
                                   hidden_strict=hidden_strict))
            elif fold_a or fold_b:
                if fold_a:
                    def ymap(t, ya=ya, yb=yb):
                        y = np.where(np.abs(t) >= np.pi / 2, yb, ya + (yb - ya) * (1.0 - np.cos(t)))
                        return y, np.where(t >= 0, 1.0, -1.0)
                else:
                    def ymap(t, ya=ya, yb=yb):
                        y = np.where(np.abs(t) >= np.pi / 2, ya, yb - (yb - ya) * (1.0 - np.cos(t)))
                        return y, np.where(t >= 0, 1.0, -1.0)
                paths.append(_Path(contour_func(ymap, g), hidden, -math.pi / 2, math.pi / 2, False, "contour",
                                   hidden_strict=hidden_strict))
            else:
                for sgn in (1.0, -1.0):
                    def ymap(t, sgn=sgn):
                        return t, np.full(np.shape(t), sgn)
                    paths.append(_Path(contour_func(ymap, g), hidden, ya, yb, False, "contour",
                                       hidden_strict=hidden_strict))
            for end_y, is_fold, e in ((ya, fold_a, ei), (yb, fold_b, ei + 1)):
                if not is_fold:
                    th = float(np.arccos(np.clip(g(np.array([end_y]))[0] / rho_c, -1.0, 1.0)))
                    junctions[e] += [alpha + th, alpha - th]
    for e, ye in enumerate(edges):
        re = float(profile.r(np.array([ye]))[0])
        if re <= 1e-12 * profile.scale:
            continue

        def circle(t, ye=ye, re=re):
            t = np.asarray(t, dtype=np.float64)
            X = np.column_stack([re * np.cos(t), np.full(t.shape, ye), re * np.sin(t)])
            return _project(P, X), X

        nodes = np.mod(np.asarray(junctions[e], dtype=np.float64), 2 * math.pi)
        label = "cap" if e in (0, n_edges - 1) else "crease"
        paths.append(_Path(circle, hidden, 0.0, 2 * math.pi, True, label, nodes, hidden_strict))
    return paths


def sor_silhouette(profile: Profile, K, R, t, *, spacing: float = 0.3) -> Silhouette:
    """Exact silhouette of the solid of revolution ``profile`` seen by ``K [R | t]``.

    ``(R, t)`` is camera-from-object (``x_cam = R X + t``).  The outline is the outer
    boundary of the projected solid (the union over ``y`` of the images of the discs of
    radius ``r(y)``), built from both branches of the contour generator
    (``Cx cos phi + Cz sin phi = r - r' (y - Cy)``) and the end/crease circles, with the
    hidden parts removed exactly (see the module docstring).  Points are spaced at most
    ``spacing`` px apart, nearly uniformly; every point lies on the true silhouette to
    rounding (verified: the penetration of its viewing ray is below ``1e-10`` times the
    object size).

    Raises ValueError when the camera is inside the object, on its axis, when the
    object is not entirely in front of the camera, or when the outline cannot be
    built (pieces that do not join, self-intersections).
    """
    if not spacing > 0:
        raise ValueError("spacing must be positive")
    K = _check_K(K)
    R, t = _as_pose((R, t))
    C = _check_camera(profile, R, t)
    P = camera_matrix(K, R, t)
    paths = _sor_paths(profile, P, C)
    eps = 1e-10 * profile.scale
    # Visibility is classified on samples <= `coarse` px apart; an occlusion shorter than
    # that can be missed, which the final checks detect: then retry with finer samples.
    last_err: Exception | None = None
    for coarse in (1.0, 0.25, 0.0625):
        try:
            img, X, lab = _trace_outline(paths, spacing=spacing, coarse_gap=coarse)
        except ValueError as err:
            last_err = err
            continue
        pen = _max_penetration(profile, C, X - C)
        if np.all(pen <= eps):
            return Silhouette(points=img, points_3d=X, source=lab.astype(str))
        last_err = ValueError(
            f"could not separate the visible silhouette exactly (max penetration "
            f"{float(pen.max()):.3g}): the pose gives an outline that cannot be built"
        )
    assert last_err is not None
    raise last_err


def silhouette_margin(profile: Profile, K, R, t, points) -> np.ndarray:
    """Penetration of the viewing rays of pixel ``points`` (N, 2) into the solid.

    ``max_{s > 0} r(y(s)) - rho(s)`` along each back-projected ray, in object units:
    ``> 0`` strictly inside the silhouette, ``0`` on it, ``< 0`` outside (``-inf`` when
    the ray misses the bounding cylinder).  Near the silhouette a pixel displacement
    ``d`` changes it by about ``d * depth / f``.
    """
    K = _check_K(K)
    R, t = _as_pose((R, t))
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    rays = np.column_stack([pts, np.ones(len(pts))]) @ np.linalg.inv(K).T @ R
    return _max_penetration(profile, camera_centre(R, t), rays)
