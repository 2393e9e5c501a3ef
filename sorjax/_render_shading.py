"""Backgrounds and object shading for :mod:`sorjax.render` (float BGR, 0-255): the
plain renders' wooden table and wall, the photo-like backdrop with shadows, reflections
and clutter (:mod:`sorjax._photo`), each object's shading frame and colour.

Shading is only meant to look plausible (it is not used as ground truth).  With lens
distortion the table, the wall and the objects' shading are sampled at each pixel's
undistorted (pinhole) position, :func:`_pixel_grid`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from . import _photo


def _pixel_grid(K, shape, k):
    """``(xs, ys)`` (H, W): the pinhole (undistorted) position of every pixel centre
    for the radial distortion ``k`` (None: the pixel centres themselves)."""
    H, W = shape
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    if k is None:
        return xs, ys
    from .core._distortion import undistort

    u = np.asarray(undistort(np.stack([xs, ys], axis=-1), K, k))
    return u[..., 0], u[..., 1]


def _background(K, Rc, tc, shape, rng, table_colour, wall_colour, grid=None):
    """Table (wood grain, perspective-correct) below the horizon, wall above; float BGR.
    ``grid``: the (pinhole) positions of the pixels, :func:`_pixel_grid`."""
    H, W = shape
    Ki = np.linalg.inv(K)
    C = -Rc.T @ tc
    xs, ys = _pixel_grid(K, shape, None) if grid is None else grid
    d = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ (Rc.T @ Ki).T  # world ray directions
    dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
    img = np.empty((H, W, 3))
    down = d[..., 1] < -1e-9
    lam = np.where(down, -C[1] / np.where(down, d[..., 1], -1.0), 0.0)
    X = C[0] + lam * d[..., 0]
    Z = C[2] + lam * d[..., 2]
    dist = np.where(down, lam * np.linalg.norm(d, axis=-1), np.inf)
    # wood grain along a random direction, faded where a pixel spans several rings
    phi = rng.uniform(0, math.pi)
    period = 0.018
    u = X * math.cos(phi) + Z * math.sin(phi)
    v = -X * math.sin(phi) + Z * math.cos(phi)
    f = math.sqrt(abs(K[0, 0] * K[1, 1]))
    foot = dist / f / np.maximum(np.abs(dn[..., 1]), 0.05)  # metres per pixel on the table
    fade = np.clip(1.5 - 3.0 * foot / period, 0.0, 1.0)
    ph = rng.uniform(0, 2 * math.pi, 3)
    grain = np.sin(2 * math.pi * (u + 0.004 * np.sin(2 * math.pi * v / 0.37 + ph[0])) / period + ph[1])
    blotch = np.sin(2 * math.pi * v / 0.23 + ph[2]) * np.sin(2 * math.pi * u / 0.41)
    tone = 1.0 + 0.06 * fade * grain + 0.05 * blotch
    light = 1.0 / (1.0 + 0.08 * np.where(down, dist, 0.0))  # a little darker far away
    tcol = np.asarray(table_colour, dtype=np.float64)
    img[:] = (tcol[None, None, :] * (tone * light)[..., None])
    # wall above the horizon: vertical gradient
    wcol = np.asarray(wall_colour, dtype=np.float64)
    up = np.clip(dn[..., 1], 0.0, 1.0)
    wall = wcol[None, None, :] * (0.85 + 0.3 * up)[..., None]
    far = ~down | (dist > 12.0)
    img[far] = wall[far]
    return img


def _object_frame(truth, box, grid=None):
    """Shading frame of an object on the pixels of ``box`` (inclusive): ``u`` (signed
    position across the body, -1 to 1 from one side of the outline to the other about
    the image of the axis), ``nz = sqrt(1 - u^2)``, ``along`` (0 to 1 along the axis
    image), ``L`` (the outline's length along the axis image, px), ``pd`` (signed
    distance from the axis image, px) and ``l`` (the axis image, ``a^2 + b^2 = 1``); with
    distortion (``grid``: the pinhole positions of the pixels) computed in the pinhole
    image, about its outline and axis."""
    x0, y0, x1, y1 = box
    l = truth.l_s
    o = truth.outline if truth.outline_pinhole is None else truth.outline_pinhole
    dirv = np.array([l[1], -l[0]])  # along the image of the axis
    sd = o @ l[:2] + l[2]  # signed distance of outline points from the axis image
    ss = o @ dirv
    if grid is None:
        xs, ys = np.meshgrid(np.arange(x0, x1 + 1, dtype=np.float64), np.arange(y0, y1 + 1, dtype=np.float64))
    else:
        xs, ys = grid[0][y0 : y1 + 1, x0 : x1 + 1], grid[1][y0 : y1 + 1, x0 : x1 + 1]
    pd = xs * l[0] + ys * l[1] + l[2]
    ps = xs * dirv[0] + ys * dirv[1]
    # half-widths of the outline on each side of the axis image, per 1-px slice along it
    s0, s1 = ss.min(), ss.max()
    nb = max(2, int(math.ceil(s1 - s0)) + 1)
    b = np.clip(((ss - s0)).astype(np.int64), 0, nb - 1)
    wr = np.full(nb, np.nan)
    wl = np.full(nb, np.nan)
    pos, neg = sd >= 0, sd < 0
    np.fmax.at(wr, b[pos], sd[pos])
    np.fmax.at(wl, b[neg], -sd[neg])
    centers = np.arange(nb) + 0.5
    for w in (wr, wl):
        okw = np.isfinite(w)
        if okw.sum() == 0:
            w[:] = 1.0
        else:
            w[:] = np.interp(centers, centers[okw], w[okw])
        np.maximum(w, 0.5, out=w)
    pb = np.clip(ps - s0, 0, nb - 1)
    half = np.where(pd >= 0, np.interp(pb, centers, wr), np.interp(pb, centers, wl))
    u = np.clip(pd / half, -1.0, 1.0)
    nz = np.sqrt(np.clip(1.0 - u * u, 0.0, 1.0))
    along = np.clip((ps - s0) / max(s1 - s0, 1.0), 0.0, 1.0)
    return {"u": u, "nz": nz, "along": along, "L": max(s1 - s0, 1.0), "pd": pd, "l": l}


def _object_colour_field(truth, base, box, light_angle, grid=None, material="plain", params=None,
                         specular=1.0, bg_sample=None):
    """Shaded colour (float BGR, 0-255) of an object on the pixels of ``box``
    (inclusive).  ``"plain"``: Lambertian-looking across the body (:func:`_object_frame`),
    a specular stripe, a slight gradient along the axis; the other materials
    (:func:`sorjax._photo.shade_material`) need their ``params`` and, for glass,
    ``bg_sample``."""
    g = _object_frame(truth, box, grid)
    return _photo.shade_material(material, params or {}, base, g, light_angle, specular, bg_sample)


def _distorter(K, kd):
    """Pinhole pixels -> distorted pixels (None without distortion)."""
    if kd is None:
        return None
    from .core._distortion import distort

    return lambda uv: np.asarray(distort(np.asarray(uv, np.float64), K, np.asarray(kd, np.float64)))


def _behind(img, box):
    """``sample(dx, dy)``: the image (float BGR) on the pixels of ``box``, displaced by
    ``(dx, dy)`` px (bilinear; for what a glass object shows of the scene behind)."""
    x0, y0, x1, y1 = box
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1, dtype=np.float64), np.arange(y0, y1 + 1, dtype=np.float64))
    src = img.astype(np.float32)

    def sample(dx, dy):
        return cv2.remap(src, (xs + dx).astype(np.float32), (ys + dy).astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REFLECT).astype(np.float64)

    return sample


def _photo_backdrop(K, Rc, tc, items, placed, looks, w, h, grid, kd, style, srng):
    """The photo-like background (:mod:`sorjax._photo`) with the objects' shadows and
    reflections, the clutter blocks, and the objects' looks with the light angle of the
    style's light in each object's shading frame."""
    solids = []
    L = Rc @ _photo.light_direction(style)  # camera frame
    out = []
    for (obj, prof, R, t, pts, pin), (k, _, _, _, truth, depth, colour), (mat, prm, _) in zip(items, placed, looks):
        Rwo, two = Rc.T @ R, Rc.T @ (t - tc)
        rings = _photo.solid_rings(prof, Rwo, two)
        flat = rings.reshape(-1, 3)
        foot = flat[:, [0, 2]].mean(0)
        zc = flat @ Rc[2] + tc[2]
        o = truth.outline
        lo, hi = o.min(0), o.max(0)
        solids.append({"rings": rings, "foot": (float(foot[0]), float(foot[1])),
                       "radius": float(np.max(np.hypot(flat[:, 0] - foot[0], flat[:, 2] - foot[1]))),
                       "depth": (float(zc.min()), float(zc.max())), "box": (lo[0], lo[1], hi[0], hi[1]),
                       "size": float(np.ptp(flat, axis=0).max()), "px": float(max(hi - lo)),
                       "colour": colour, "material": mat})
        # u > 0 on the side of the axis image that l_s points to (to the right when l_x > 0)
        la = math.atan2(L[0], -L[2]) * (1.0 if truth.l_s[0] >= 0 else -1.0)
        out.append((mat, prm, float(np.clip(la, -1.4, 1.4))))
    wall = _photo.wall_plane(style, Rc, tc, np.concatenate([s["rings"].reshape(-1, 3) for s in solids])
                             if solids else np.zeros((0, 3)))
    ph = srng.uniform(0.0, 1.0, 4)
    g = _pixel_grid(K, (h, w), None) if grid is None else grid
    img, table = _photo.backdrop(style, K, Rc, tc, (h, w), g, wall, ph)
    blocks = _photo.place_clutter(srng, style, K, Rc, tc, (h, w), solids, wall)
    _photo.shadows_and_reflections(img, table, style, K, Rc, tc, solids, blocks, _distorter(K, kd))
    return img, blocks, out
