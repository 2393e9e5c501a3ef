"""Layout of the photo-like scenes (:mod:`sorjax._photo`): the light's direction, the
wall plane, and the clutter blocks (boxes, wedges and prisms with elliptic sections on
the table, placed clear of the objects in 3-D) with their exact anti-aliased coverage
and flat shading.  World: metres, ``Y`` up, the table is the plane ``Y = 0``; camera
poses world-to-camera ``(Rc, tc)``; pixels as in OpenCV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._photo_style import PhotoStyle


@dataclass(frozen=True)
class Wall:
    """The wall plane ``n . X = d`` (``n`` horizontal unit, pointing to the camera)."""

    n: np.ndarray
    d: float


def light_direction(style: PhotoStyle) -> np.ndarray:
    """Unit vector towards the light (world)."""
    az, el = math.radians(style.light_azimuth_deg), math.radians(style.light_elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.sin(el), math.cos(el) * math.sin(az)])


def wall_plane(style: PhotoStyle, Rc, tc, points) -> Wall | None:
    """The wall ``style.wall_distance`` behind the farthest of ``points`` (world, (N, 3))
    along the camera's horizontal viewing direction."""
    if style.wall_distance is None:
        return None
    C = -Rc.T @ tc
    fwd = Rc.T @ np.array([0.0, 0.0, 1.0])
    fwd[1] = 0.0
    nf = np.linalg.norm(fwd)
    if nf < 1e-6:  # looking straight down: no wall in view
        return None
    fwd /= nf
    far = float(np.max((np.asarray(points) - C) @ fwd)) if len(points) else 1.0
    n = -fwd
    return Wall(n=n, d=float(n @ C) - (far + float(style.wall_distance)))


@dataclass(frozen=True)
class Block:
    """A convex clutter item: vertices (world, metres), faces (vertex index tuples,
    outward), colour."""

    vertices: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    colour: tuple[float, float, float]


def _prism(base: np.ndarray, length: float) -> tuple[np.ndarray, tuple]:
    """Prism of a convex 2-D polygon ``base`` (n, 2) in local ``(a, b)``, extruded along
    local ``c`` from 0 to ``length``: vertices (2n, 3) local, faces."""
    n = len(base)
    v = np.concatenate([np.column_stack([base, np.zeros(n)]), np.column_stack([base, np.full(n, length)])])
    faces = [tuple(range(n)), tuple(range(n, 2 * n))] + [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
    return v, tuple(faces)


_CLUTTER_COLOURS = ((90, 130, 170), (200, 200, 195), (140, 70, 40), (60, 60, 60), (50, 140, 200), (120, 150, 90),
                    (180, 160, 200), (30, 40, 120))


def _random_block(rng, size: float, at, yaw: float) -> Block:
    """A box, a wedge lying on a side, or an upright prism with an elliptic section,
    about ``size`` metres, standing at ``at`` = (x, z)."""
    kind = int(rng.integers(3))
    c, s = math.cos(yaw), math.sin(yaw)
    if kind == 0 or kind == 2:  # upright: base in the table plane, extruded up
        if kind == 0:
            a, b = size * rng.uniform(0.4, 1.0), size * rng.uniform(0.3, 1.0)
            base = np.array([[-a, -b], [a, -b], [a, b], [-a, b]]) / 2
        else:
            n = int(rng.integers(5, 11))
            th = np.linspace(0, 2 * math.pi, n, endpoint=False) + rng.uniform(0, 1)
            base = np.column_stack([0.5 * size * np.cos(th), 0.5 * size * rng.uniform(0.35, 0.7) * np.sin(th)])
        hgt = size * rng.uniform(0.3, 1.5)
        v, faces = _prism(base, hgt)
        loc = np.column_stack([v[:, 0], v[:, 2], v[:, 1]])  # (a, b, c) -> (x, y=c, z=b)
    else:  # wedge: a right triangle in a vertical plane, extruded horizontally
        a, hgt = size * rng.uniform(0.4, 1.0), size * rng.uniform(0.3, 0.8)
        base = np.array([[-a / 2, 0.0], [a / 2, 0.0], [-a / 2, hgt]])
        L = size * rng.uniform(0.3, 1.0)
        v, faces = _prism(base, L)
        loc = np.column_stack([v[:, 0], v[:, 1], v[:, 2] - L / 2])
    Rw = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    X = loc @ Rw.T + np.array([at[0], 0.0, at[1]])
    ctr = X.mean(0)
    out = []
    for f in faces:  # orient each face outward
        p = X[list(f)]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        out.append(f if nrm @ (p.mean(0) - ctr) > 0 else tuple(reversed(f)))
    colour = _CLUTTER_COLOURS[int(rng.integers(len(_CLUTTER_COLOURS)))]
    return Block(vertices=X, faces=tuple(out), colour=tuple(float(x) for x in colour))


def _project(K, Rc, tc, X):
    """Pixels (N, 2) and depths (N,) of world points (N, 3) (pinhole)."""
    xc = X @ Rc.T + tc
    z = xc[:, 2]
    uv = xc @ K.T
    return uv[:, :2] / np.where(np.abs(uv[:, 2:3]) > 1e-12, uv[:, 2:3], 1e-12), z


def place_clutter(rng, style: PhotoStyle, K, Rc, tc, shape, solids, wall: Wall | None) -> list[Block]:
    """Up to ``style.clutter`` blocks on the table, in view, clear of the objects in 3-D
    (``solids``: dicts with ``foot`` (x, z), ``radius`` (m, horizontal reach), ``depth``
    (min, max camera depth), ``box`` (x0, y0, x1, y1) image box, ``size`` (m)): each
    either does not overlap any object's image box (beside), or is wholly farther than
    the objects it overlaps (behind), or (``clutter_in_front``) wholly nearer than the
    one it overlaps and covering at most a third of its box."""
    H, W = shape
    Ki = np.linalg.inv(K)
    C = -Rc.T @ tc
    size0 = float(np.mean([s["size"] for s in solids])) if solids else 0.2
    blocks: list[Block] = []
    spots: list[tuple[float, float, float]] = []  # (x, z, radius) taken on the table
    spots += [(s["foot"][0], s["foot"][1], s["radius"]) for s in solids]
    for _ in range(12 * style.clutter):
        if len(blocks) >= style.clutter:
            break
        px, py = rng.uniform(-0.1, 1.1) * W, rng.uniform(0.0, 1.1) * H
        ray = Rc.T @ Ki @ np.array([px, py, 1.0])
        if ray[1] >= -1e-6:
            continue
        lam = -C[1] / ray[1]
        P = C + lam * ray
        size = size0 * rng.uniform(0.4, 1.3)
        if wall is not None and wall.n @ P - wall.d < 0.6 * size:
            continue
        blk = _random_block(rng, size, (P[0], P[2]), float(rng.uniform(0, math.pi)))
        reach = float(np.max(np.hypot(blk.vertices[:, 0] - P[0], blk.vertices[:, 2] - P[2])))
        if any(math.hypot(P[0] - x, P[2] - z) < r + reach + 0.01 for x, z, r in spots):
            continue
        uv, z = _project(K, Rc, tc, blk.vertices)
        if z.min() < 0.05 or np.linalg.norm(P - C) > 20.0:
            continue
        lo, hi = uv.min(0), uv.max(0)
        if hi[0] < 0 or hi[1] < 0 or lo[0] > W - 1 or lo[1] > H - 1:
            continue
        ok = True
        for s in solids:
            b = s["box"]
            ov_w = min(hi[0], b[2] + 4) - max(lo[0], b[0] - 4)
            ov_h = min(hi[1], b[3] + 4) - max(lo[1], b[1] - 4)
            if ov_w <= 0 or ov_h <= 0:
                continue  # beside
            if z.min() > s["depth"][1] + 0.005:
                continue  # behind
            if style.clutter_in_front and z.max() < s["depth"][0] - 0.005:
                area = (b[2] - b[0] + 1) * (b[3] - b[1] + 1)
                if ov_w * ov_h <= area / 3.0:
                    continue  # in front, hiding a part
            ok = False
            break
        if ok:
            blocks.append(blk)
            spots.append((P[0], P[2], reach))
    return blocks


def _to_pixels(K, Rc, tc, X, distort):
    uv, z = _project(K, Rc, tc, X.reshape(-1, 3))
    if distort is not None:
        uv = distort(uv)
    return uv.reshape(X.shape[:-1] + (2,)), z.reshape(X.shape[:-1])


def block_layer(block: Block, K, Rc, tc, shape, style, coverage, distort):
    """``(box, coverage, colour)`` of a clutter block in its image box (x0, y0, x1, y1
    inclusive): the exact coverage of its visible faces (``coverage(polygon, (h, w))``,
    e.g. render's ``polygon_coverage``, in the box's pixels) and flat Lambert shading;
    None when it is not in view."""
    H, W = shape
    C = -Rc.T @ tc
    L = light_direction(style)
    faces = []  # (image polygon, shade)
    for f in block.faces:
        p = block.vertices[list(f)]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        nrm /= np.linalg.norm(nrm)
        if nrm @ (C - p.mean(0)) <= 0:
            continue
        uv, z = _to_pixels(K, Rc, tc, p, distort)
        if z.min() <= 0.01:
            continue
        faces.append((np.clip(uv, -W, 2 * W), style.exposure * (0.45 + 0.6 * max(0.0, float(nrm @ L)))))
    if not faces:
        return None
    allp = np.concatenate([uv for uv, _ in faces])
    x0, y0 = max(0, int(math.floor(allp[:, 0].min())) - 1), max(0, int(math.floor(allp[:, 1].min())) - 1)
    x1, y1 = min(W - 1, int(math.ceil(allp[:, 0].max())) + 1), min(H - 1, int(math.ceil(allp[:, 1].max())) + 1)
    if x1 < x0 or y1 < y0:
        return None
    cov = np.zeros((y1 - y0 + 1, x1 - x0 + 1))
    col = np.zeros(cov.shape + (3,))
    for uv, shade in faces:
        cf = coverage(uv - [x0, y0], cov.shape)
        cov += cf
        col += cf[..., None] * (np.asarray(block.colour) * shade)
    if cov.max() <= 0:
        return None
    return (x0, y0, x1, y1), np.clip(cov, 0.0, 1.0), col / np.maximum(cov, 1e-12)[..., None]
