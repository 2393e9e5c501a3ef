"""Photo-like scenes for :mod:`sorjax.render`: a test bed that is hard for segmentation.

``render(..., style=PhotoStyle(...))`` (or ``style="photo"``) draws the same exactly
known solids of revolution as the plain renders, in a scene made to look like a
photograph of a table (everything below is only meant to look plausible; none of it is
ground truth, and none of it changes the objects' exact coverages, except clutter
placed in front of an object, which hides part of it exactly as a nearer object does):

* **Table** (the plane ``Y = 0``), textured in table coordinates (metres) and so seen in
  perspective: ``"wood"`` (planks with dark joints, grain, per-plank tone), ``"tiles"``
  (square tiles with grout, per-tile tone), ``"checks"`` (a gingham cloth: two sets of
  stripes and a fine weave), ``"plain"``.  Patterns are pre-filtered by each pixel's
  footprint on the table (edges one footprint wide, contrast faded where a pixel spans
  a period), so they do not alias.
* **Wall**: a vertical plane ``wall_distance`` metres behind the farthest object, facing
  the camera, with ``"stripes"`` (vertical), ``"wallpaper"`` (a repeating lattice of
  diamonds and dots) or ``"plain"``; where it meets the table there is a hard edge.
* **Clutter**: boxes, wedges and prisms with elliptic (non-circular) sections standing
  on the table behind and beside the objects (never touching them in 3-D), flat-shaded
  faces with exact anti-aliased coverage; with ``clutter_in_front`` some may stand in
  front of an object and hide part of it (that object is then ``occluded``).
* **Light**: one directional light (``light_azimuth_deg``, ``light_elevation_deg``).
  Cast shadows of the objects and the clutter on the table (the union of the shadows of
  the solids' cross-section discs, which is the solid's shadow), soft (``penumbra``), a
  contact shadow under each object, and on a glossy table (``reflection`` > 0) a faded,
  slightly blurred mirror image of each object below it.
* **Materials** (``TableObject.material``, or drawn from ``materials``): ``"plain"``
  (the plain renders' shading), ``"glossy"`` (stronger highlight and the reflection of
  a window), ``"painted"`` (bands of a second colour around the body: edges inside the
  object), ``"glass"`` (see-through: the scene behind, magnified across the axis and
  tinted, a darkened rim, highlights: low contrast against the background) and
  ``"metal"`` (an environment of dark and bright bands reflected across the body:
  high contrast inside the object).
* **Camera**: defocus (a Gaussian point-spread function), vignetting, sensor noise
  (Gaussian plus shot noise growing with the signal), JPEG compression
  (``cv2.imencode`` at a quality).

Every random choice comes from the seed of the render.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

# the style, the scene's layout and the textures have modules of their own; the renderer
# uses them through this one
from ._photo_layout import (  # noqa: F401
    Block as Block,
    Wall as Wall,
    _to_pixels,
    block_layer as block_layer,
    light_direction as light_direction,
    place_clutter as place_clutter,
    wall_plane as wall_plane,
)
from ._photo_style import (  # noqa: F401
    MATERIALS as MATERIALS,
    TABLES as TABLES,
    WALLS as WALLS,
    PhotoStyle as PhotoStyle,
    check_material as check_material,
    check_style as check_style,
    describe as describe,
    random_style as random_style,
)
from ._photo_textures import _mix, _table_texture, _wall_texture


# ----------------------------------------------------------------------------------
# Background: table, wall, shadows, reflections
# ----------------------------------------------------------------------------------


def backdrop(style: PhotoStyle, K, Rc, tc, shape, grid, wall: Wall | None, ph):
    """Table and wall (float BGR) and the table mask; ``grid``: the pinhole positions
    of the pixels (render's ``_pixel_grid``)."""
    H, W = shape
    xs, ys = grid
    Ki = np.linalg.inv(K)
    C = -Rc.T @ tc
    d = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ (Rc.T @ Ki).T
    dl = np.linalg.norm(d, axis=-1)
    f = math.sqrt(abs(K[0, 0] * K[1, 1]))
    down = d[..., 1] < -1e-9
    lam_t = np.where(down, -C[1] / np.where(down, d[..., 1], -1.0), np.inf)
    if wall is not None:
        nd = d @ wall.n
        toward = nd < -1e-9
        lam_w = np.where(toward, (wall.d - wall.n @ C) / np.where(toward, nd, -1.0), np.inf)
    else:
        lam_w = np.full((H, W), np.inf)
    table = down & (lam_t <= lam_w) & (lam_t * dl < 40.0)
    img = np.empty((H, W, 3))
    # table
    lt = np.where(table, lam_t, 0.0)
    X = C[0] + lt * d[..., 0]
    Z = C[2] + lt * d[..., 2]
    cos_t = np.maximum(np.abs(d[..., 1]) / dl, 0.05)
    foot = lt * dl / f / cos_t
    tcol = _table_texture(style, X[table], Z[table], foot[table], ph)
    L = light_direction(style)
    spot = 1.0 / (1.0 + 0.15 * np.hypot(X[table] - 0.5 * L[0], Z[table] - 0.5 * L[2]) ** 2)
    img[table] = tcol * (0.75 + 0.35 * spot)[:, None]
    # wall
    wl = ~table & np.isfinite(lam_w)
    if wall is not None and wl.any():
        lw = lam_w[wl]
        Pw = C[None, :] + lw[:, None] * d[wl]
        tang = np.cross(np.array([0.0, 1.0, 0.0]), wall.n)
        cos_w = np.maximum(np.abs(d[wl] @ wall.n) / dl[wl], 0.05)
        fw = lw * dl[wl] / f / cos_w
        wcol = _wall_texture(style, Pw @ tang, Pw[:, 1], fw, ph)
        shade = 0.8 + 0.25 * np.clip(1.0 - Pw[:, 1] / 1.5, 0.0, 1.0) * (0.6 + 0.4 * max(0.0, -(wall.n @ L)))
        img[wl] = wcol * shade[:, None]
    rest = ~table & ~wl
    if rest.any():
        up = np.clip(d[rest][:, 1] / dl[rest], 0.0, 1.0)
        img[rest] = np.asarray(style.wall_colour, np.float64)[None, :] * (0.85 + 0.3 * up)[:, None]
    return img * style.exposure, table


def solid_rings(prof, Rwo, two, n_y: int = 28, n_phi: int = 36) -> np.ndarray:
    """World points (n_y, n_phi, 3) of circles of the solid (the cross-section discs'
    rims), from base to top."""
    y = np.linspace(prof.y0, prof.y1, n_y)
    r = np.asarray(prof.r(y), dtype=np.float64)
    ph = np.linspace(0.0, 2.0 * math.pi, n_phi, endpoint=False)
    Xo = np.stack([r[:, None] * np.cos(ph), np.repeat(y[:, None], n_phi, 1), r[:, None] * np.sin(ph)], -1)
    return Xo @ Rwo.T + two


def _fill(mask, pts, value):
    """Fill the convex hull of image points ``pts`` (N, 2) into ``mask`` (float32) with
    ``value`` (1/16 px precision, anti-aliased)."""
    if len(pts) < 3 or not np.all(np.isfinite(pts)) or np.abs(pts).max() > 1e5:
        return
    hull = cv2.convexHull(np.round(pts * 16).astype(np.int32))
    cv2.fillConvexPoly(mask, hull, float(value), lineType=cv2.LINE_AA, shift=4)


def shadows_and_reflections(img, table, style, K, Rc, tc, solids, blocks, distort):
    """Darken the table by the cast and contact shadows of ``solids`` (dicts with
    ``rings`` (n_y, n_phi, 3) world, ``colour``, ``material``, ``px`` (image size, px))
    and ``blocks``, and mix in the glossy table's reflections; in place."""
    H, W = table.shape
    L = light_direction(style)
    size_px = float(np.mean([s["px"] for s in solids])) if solids else 0.1 * W
    if style.shadow > 0:
        m = np.zeros((H, W), np.float32)
        for s in solids:
            X = s["rings"]
            P = X - (X[..., 1:2] / L[1]) * L
            uv, z = _to_pixels(K, Rc, tc, P, distort)
            for k in range(len(uv)):
                if z[k].min() > 0.01:
                    _fill(m, uv[k], 1.0)
        for b in blocks:
            P = b.vertices - (b.vertices[:, 1:2] / L[1]) * L
            uv, z = _to_pixels(K, Rc, tc, np.concatenate([P, b.vertices[b.vertices[:, 1] < 1e-9]]), distort)
            if z.min() > 0.01:
                _fill(m, uv, 1.0)
        sig = max(0.7, style.penumbra * size_px)
        soft = 0.5 * _gauss(m, 0.35 * sig) + 0.5 * _gauss(m, sig)
        img *= (1.0 - style.shadow * soft * table)[..., None]
    if style.contact > 0:
        m = np.zeros((H, W), np.float32)
        for s in solids:
            X = s["rings"].copy()
            low = X[..., 1] < 0.25 * (X[..., 1].max() - X[..., 1].min()) + X[..., 1].min() + 1e-9
            X[..., 1] = 0.0
            uv, z = _to_pixels(K, Rc, tc, X, distort)
            for k in range(len(uv)):
                if low[k].all() and z[k].min() > 0.01:
                    _fill(m, uv[k], 1.0)
        soft = _gauss(m, max(1.0, 0.03 * size_px))
        img *= (1.0 - style.contact * soft * table)[..., None]
    if style.reflection > 0:
        a = np.zeros((H, W), np.float32)
        acc = np.zeros((H, W, 3), np.float32)
        for s in solids:
            X = s["rings"].copy()
            hgt = X[..., 1].max() - X[..., 1].min() + 1e-9
            X[..., 1] = -X[..., 1]
            uv, z = _to_pixels(K, Rc, tc, X, distort)
            depth_k = -X[..., 1].mean(-1)  # height of each ring above the table
            one = np.zeros((H, W), np.float32)
            for k in np.argsort(-depth_k):  # farthest from the table first: max() by overwriting
                if z[k].min() > 0.01:
                    _fill(one, uv[k], style.reflection * math.exp(-depth_k[k] / (0.6 * hgt)))
            gain = {"metal": 1.4, "glass": 0.5}.get(s["material"], 1.0)
            one = np.minimum(one * gain, 0.8)
            acc += one[..., None] * np.asarray(s["colour"], np.float32) * 0.8
            a += one
        ab = _gauss(a, 1.2)  # a glossy, not a perfect, mirror
        colour = cv2.GaussianBlur(acc, (0, 0), 1.2) / np.maximum(ab, 1e-6)[..., None]
        mix = np.minimum(ab, 0.8) * table
        img[:] = img * (1.0 - mix[..., None]) + np.clip(colour, 0, 255) * mix[..., None]


def _gauss(m, sigma):
    if sigma <= 0:
        return m.astype(np.float64)
    return cv2.GaussianBlur(m.astype(np.float32), (0, 0), float(sigma)).astype(np.float64)


# ----------------------------------------------------------------------------------
# Materials
# ----------------------------------------------------------------------------------


def material_params(rng, material: str) -> dict:
    """Random look of one object of ``material`` (drawn once per object)."""
    if material == "metal":
        n = int(rng.integers(3, 6))
        return {"edges": np.sort(rng.uniform(-1.0, 1.0, n)), "levels": rng.uniform(0.0, 1.0, n + 1) ** 0.7,
                "tilt": rng.uniform(-0.6, 0.6), "tint": rng.uniform(0.85, 1.0, 3)}
    if material == "painted":
        n = int(rng.integers(1, 4))
        cuts = np.sort(rng.uniform(0.1, 0.9, 2 * n))
        return {"bands": cuts.reshape(n, 2), "colour2": rng.uniform(20, 235, 3)}
    if material == "glass":
        return {"tint": rng.uniform(0.85, 0.98, 3), "mag": rng.uniform(0.35, 0.7), "rim": rng.uniform(0.25, 0.5)}
    if material == "glossy":
        return {"window": np.sort(rng.uniform(-0.7, 0.2, 2)), "win_along": np.sort(rng.uniform(0.1, 0.9, 2))}
    return {}


def shade_material(material, prm, base, g, light_angle, specular, bg_sample):
    """Colour (float BGR) of an object of ``material`` on its box, from the shading
    frame ``g`` (render's ``_object_frame``: ``u`` across the body in [-1, 1], ``nz``,
    ``along`` in [0, 1], ``L`` the length along the axis in px, ``pd``, ``l``);
    ``bg_sample(dx, dy)`` the image behind, displaced by (dx, dy) px, for glass."""
    u, nz, along = g["u"], g["nz"], g["along"]
    la = light_angle
    diffuse = np.clip(u * math.sin(la) + nz * math.cos(la), 0.0, 1.0)
    hv = 0.5 * la + 0.15
    cosh = np.clip(u * math.sin(hv) + nz * math.cos(hv), 0.0, 1.0)
    b = np.asarray(base, dtype=np.float64)
    if material == "glass":
        shift = (1.0 - prm["mag"]) * g["pd"]  # magnified across the axis
        behind = bg_sample(-shift * g["l"][0], -shift * g["l"][1])
        rim = np.clip((np.abs(u) - 0.7) / 0.3, 0.0, 1.0) ** 1.5
        col = behind * prm["tint"][None, None, :] * (1.0 - prm["rim"] * rim)[..., None]
        col += (specular * 230.0 * cosh**200 + specular * 60.0 * np.clip(1.0 - np.abs(np.abs(u) - 0.85) / 0.05, 0, 1)
                * (along > 0.2))[..., None]
        return col
    if material == "metal":
        ang = np.arcsin(np.clip(u, -1, 1)) * (2.0 / math.pi) + prm["tilt"] * (along - 0.5)
        gy, gx = np.gradient(ang) if min(ang.shape) > 1 else (np.ones_like(ang), np.ones_like(ang))
        px = np.maximum(np.hypot(gx, gy), 1e-6)  # change of ang per pixel: band edges 1 px wide
        lev = prm["levels"][0] + sum((prm["levels"][k + 1] - prm["levels"][k]) * np.clip((ang - e) / px + 0.5, 0, 1)
                                     for k, e in enumerate(prm["edges"]))
        col = (25.0 + 215.0 * lev)[..., None] * prm["tint"][None, None, :] * (0.8 + 0.2 * b / 255.0)[None, None, :]
        return col + (specular * 200.0 * cosh**40)[..., None]
    # which end of the axis is "down" on the table does not matter for the look
    shade = (0.3 + 0.7 * diffuse) * (0.92 + 0.08 * along)
    if material == "painted":
        inside = np.zeros_like(along)
        for a0, a1 in prm["bands"]:
            inside = np.maximum(inside, np.clip((along - a0) * g["L"] + 0.5, 0, 1) * np.clip((a1 - along) * g["L"] + 0.5, 0, 1))
        col = _mix(b, prm["colour2"], inside) * shade[..., None]
    else:
        col = b[None, None, :] * shade[..., None]
    if material == "glossy":
        w0, w1 = prm["window"]
        a0, a1 = prm["win_along"]
        win = (np.clip((u - w0) * 20, 0, 1) * np.clip((w1 - u) * 20, 0, 1) * np.clip((along - a0) * g["L"] * 0.5, 0, 1)
               * np.clip((a1 - along) * g["L"] * 0.5, 0, 1))
        return col + (specular * 255.0 * cosh**150 + 90.0 * specular * win * nz)[..., None]
    return col + (specular * 200.0 * cosh**60)[..., None]


# ----------------------------------------------------------------------------------
# Camera
# ----------------------------------------------------------------------------------


def finish(img, rng, style: PhotoStyle, noise: float, blur: float) -> np.ndarray:
    """Defocus, vignetting, noise, 8-bit rounding and JPEG: the uint8 BGR image."""
    H, W = img.shape[:2]
    sig = math.hypot(float(blur), style.defocus)
    if sig > 0:
        r = max(1, int(math.ceil(4 * sig)))
        img = cv2.GaussianBlur(img, (2 * r + 1, 2 * r + 1), sig, borderType=cv2.BORDER_REPLICATE)
    if style.vignette > 0:
        yy, xx = np.mgrid[0:H, 0:W]
        rr = ((xx - 0.5 * (W - 1)) ** 2 + (yy - 0.5 * (H - 1)) ** 2) / (0.25 * (W * W + H * H))
        img = img * (1.0 - style.vignette * rr)[..., None]
    var = noise**2 + style.shot_noise**2 * np.clip(img, 0, 255) / 255.0
    if np.any(var > 0):
        img = img + rng.normal(0.0, 1.0, img.shape) * np.sqrt(var)
    out = np.clip(np.round(img), 0, 255).astype(np.uint8)
    if style.jpeg is not None:
        ok, buf = cv2.imencode(".jpg", out, [int(cv2.IMWRITE_JPEG_QUALITY), int(style.jpeg)])
        if not ok:
            raise RuntimeError("cv2.imencode failed to compress the render as JPEG")
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out

