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
from dataclasses import dataclass

import cv2
import numpy as np

from ._checks import boolean, integer, number

TABLES = ("wood", "tiles", "checks", "plain")
WALLS = ("stripes", "wallpaper", "plain")
MATERIALS = ("plain", "glossy", "painted", "glass", "metal")


@dataclass(frozen=True)
class PhotoStyle:
    """How a photo-like render looks (:mod:`sorjax._photo`); all lengths in metres
    unless said otherwise, colours BGR 0-255.

    Attributes
    ----------
    table : {"wood", "tiles", "checks", "plain"}
    table_colour, table_colour2 : (b, g, r)
        Main colour and second colour (joints and grain, grout, the checks).
    table_scale : float
        Plank width, tile size or check period.
    wall : {"stripes", "wallpaper", "plain"}
    wall_colour, wall_colour2 : (b, g, r)
    wall_scale : float
        Stripe period or motif size.
    wall_distance : float or None
        Distance of the wall behind the farthest object, along the camera's horizontal
        viewing direction; None: no wall (the horizon is at infinity, as in the plain
        renders).
    clutter : int
        Number of clutter items to place (fewer when they do not fit).
    clutter_in_front : bool
        Whether clutter may stand in front of an object and hide up to a third of it.
    light_azimuth_deg, light_elevation_deg : float
        Direction towards the light: azimuth from world ``X`` towards ``Z``, elevation
        above the table.
    shadow : float
        Darkening in full shadow, 0 (no shadows) to 0.9.
    penumbra : float
        Softness of the shadows: Gaussian sigma as a fraction of the objects' mean image
        size.
    contact : float
        Darkening of the contact shadow under each object, 0 to 0.9.
    reflection : float
        Strength of the table's mirror reflection of the objects, 0 (matte) to 0.6.
    specular : float
        Scale of the objects' highlights, 0 to 3.
    materials : tuple of str
        Materials drawn (uniformly) for the objects whose ``material`` is None.
    exposure : float
        Overall brightness factor, 0.5 to 1.5.
    vignette : float
        Darkening at the image corners, 0 to 0.6.
    defocus : float
        Gaussian point-spread sigma, pixels (added in quadrature to ``render``'s ``blur``).
    shot_noise : float
        Standard deviation of the signal-dependent noise at full white, grey levels
        (``sigma^2 = noise^2 + shot_noise^2 * value / 255``).
    jpeg : int or None
        JPEG quality (``cv2.IMWRITE_JPEG_QUALITY``, 10 to 100) the image is compressed
        at; None: not compressed.
    """

    table: str = "wood"
    table_colour: tuple[float, float, float] = (70, 105, 150)
    table_colour2: tuple[float, float, float] = (35, 55, 90)
    table_scale: float = 0.15
    wall: str = "stripes"
    wall_colour: tuple[float, float, float] = (200, 205, 210)
    wall_colour2: tuple[float, float, float] = (150, 170, 185)
    wall_scale: float = 0.08
    wall_distance: float | None = 0.4
    clutter: int = 3
    clutter_in_front: bool = False
    light_azimuth_deg: float = 40.0
    light_elevation_deg: float = 50.0
    shadow: float = 0.45
    penumbra: float = 0.03
    contact: float = 0.35
    reflection: float = 0.0
    specular: float = 1.0
    materials: tuple[str, ...] = MATERIALS
    exposure: float = 1.0
    vignette: float = 0.2
    defocus: float = 0.5
    shot_noise: float = 2.0
    jpeg: int | None = 90


def check_style(style) -> PhotoStyle | None:
    """``style`` as a validated :class:`PhotoStyle` (``"photo"``: the defaults; None:
    the plain renders)."""
    if style is None:
        return None
    if isinstance(style, str):
        if style != "photo":
            raise ValueError(f"style must be None (plain), 'photo' or a sorjax.render.PhotoStyle; got {style!r}")
        return PhotoStyle()
    if not isinstance(style, PhotoStyle):
        raise ValueError(f"style must be None (plain), 'photo' or a sorjax.render.PhotoStyle; got "
                         f"{type(style).__name__}")
    if style.table not in TABLES:
        raise ValueError(f"style.table must be one of {TABLES}; got {style.table!r}")
    if style.wall not in WALLS:
        raise ValueError(f"style.wall must be one of {WALLS}; got {style.wall!r}")
    for name in ("table_colour", "table_colour2", "wall_colour", "wall_colour2"):
        c = np.asarray(getattr(style, name), dtype=np.float64)
        if c.shape != (3,) or not np.all((c >= 0) & (c <= 255)):
            raise ValueError(f"style.{name} must be (b, g, r) with values 0-255; got {getattr(style, name)!r}")
    number(style.table_scale, "style.table_scale", lo=1e-3, hi=10.0, unit="m")
    number(style.wall_scale, "style.wall_scale", lo=1e-3, hi=10.0, unit="m")
    if style.wall_distance is not None:
        number(style.wall_distance, "style.wall_distance", lo=0.0, hi=100.0, unit="m")
    integer(style.clutter, "style.clutter", lo=0, hi=20, what="clutter items")
    boolean(style.clutter_in_front, "style.clutter_in_front")
    number(style.light_azimuth_deg, "style.light_azimuth_deg", unit="deg")
    number(style.light_elevation_deg, "style.light_elevation_deg", lo=10.0, hi=90.0, unit="deg")
    number(style.shadow, "style.shadow", lo=0.0, hi=0.9)
    number(style.penumbra, "style.penumbra", lo=0.0, hi=0.5)
    number(style.contact, "style.contact", lo=0.0, hi=0.9)
    number(style.reflection, "style.reflection", lo=0.0, hi=0.6)
    number(style.specular, "style.specular", lo=0.0, hi=3.0)
    number(style.exposure, "style.exposure", lo=0.5, hi=1.5)
    number(style.vignette, "style.vignette", lo=0.0, hi=0.6)
    number(style.defocus, "style.defocus", lo=0.0, hi=10.0, unit="px")
    number(style.shot_noise, "style.shot_noise", lo=0.0, hi=50.0, unit="grey levels")
    if style.jpeg is not None:
        integer(style.jpeg, "style.jpeg", lo=10, hi=100, what="JPEG quality")
    mats = tuple(style.materials)
    if not mats or any(m not in MATERIALS for m in mats):
        raise ValueError(f"style.materials must be a non-empty tuple of {MATERIALS}; got {style.materials!r}")
    return style


def check_material(material, what: str) -> str:
    if material is None:
        return "plain"
    if material not in MATERIALS:
        raise ValueError(f"{what}: material must be None or one of {MATERIALS}; got {material!r}")
    return material


#: Table colours (main, second) BGR: oak, walnut, pine; white/grey/terracotta tiles;
#: red, blue, green checks.
_TABLE_COLOURS = {
    "wood": (((70, 105, 150), (35, 55, 90)), ((45, 65, 95), (20, 30, 50)), ((120, 170, 210), (70, 115, 160))),
    "tiles": (((215, 215, 210), (120, 120, 120)), ((95, 95, 100), (200, 200, 195)), ((70, 100, 180), (180, 190, 200))),
    "checks": (((235, 235, 240), (50, 50, 190)), ((240, 235, 235), (150, 80, 30)), ((235, 240, 235), (60, 130, 40))),
    "plain": (((150, 155, 160), (150, 155, 160)), ((60, 60, 60), (60, 60, 60)), ((200, 215, 225), (200, 215, 225))),
}
_WALL_COLOURS = (((200, 205, 210), (150, 170, 185)), ((225, 230, 235), (120, 140, 90)),
                 ((170, 190, 215), (225, 235, 240)), ((140, 120, 100), (200, 190, 180)))


def random_style(rng: np.random.Generator) -> PhotoStyle:
    """A random :class:`PhotoStyle`: a textured table (wood, tiles or checks), a striped
    or papered wall (plain one time in six), 2 to 6 clutter items (in front of an object
    one time in five), light from any azimuth 30 to 70 degrees up, a glossy table two
    times in five, defocus 0.3 to 1 px, noise, JPEG quality 70 to 95 (most of the time)."""
    table = ("wood", "tiles", "checks")[int(rng.integers(3))]
    tc = _TABLE_COLOURS[table][int(rng.integers(3))]
    wc = _WALL_COLOURS[int(rng.integers(len(_WALL_COLOURS)))]
    scale = {"wood": (0.08, 0.2), "tiles": (0.08, 0.3), "checks": (0.015, 0.06)}[table]
    wall = "plain" if rng.uniform() < 1 / 6 else ("stripes", "wallpaper")[int(rng.integers(2))]
    return PhotoStyle(
        table=table, table_colour=tc[0], table_colour2=tc[1], table_scale=float(rng.uniform(*scale)),
        wall=wall, wall_colour=wc[0], wall_colour2=wc[1], wall_scale=float(rng.uniform(0.03, 0.15)),
        wall_distance=float(rng.uniform(0.15, 0.8)),
        clutter=int(rng.integers(2, 7)), clutter_in_front=bool(rng.uniform() < 0.2),
        light_azimuth_deg=float(rng.uniform(0, 360)), light_elevation_deg=float(rng.uniform(30, 70)),
        shadow=float(rng.uniform(0.25, 0.6)), penumbra=float(rng.uniform(0.01, 0.06)),
        contact=float(rng.uniform(0.2, 0.45)),
        reflection=0.0 if rng.uniform() < 0.6 else float(rng.uniform(0.1, 0.3)),
        specular=float(rng.uniform(0.5, 1.5)), exposure=float(rng.uniform(0.85, 1.1)),
        vignette=float(rng.uniform(0.0, 0.35)), defocus=float(rng.uniform(0.3, 1.0)),
        shot_noise=float(rng.uniform(1.0, 4.0)),
        jpeg=None if rng.uniform() < 0.15 else int(rng.integers(70, 96)),
    )


def describe(style: PhotoStyle) -> str:
    """One line naming the style's choices."""
    wall = "no wall" if style.wall_distance is None else f"{style.wall} wall {style.wall_distance:.2f} m behind"
    return (f"photo style: {style.table} table, {wall}, {style.clutter} clutter"
            f"{' (may occlude)' if style.clutter_in_front else ''}, shadows {style.shadow:.2f}, reflection "
            f"{style.reflection:.2f}, defocus {style.defocus:.2f} px, shot noise {style.shot_noise:.1f}, "
            f"JPEG {style.jpeg if style.jpeg is not None else 'none'}")


# ----------------------------------------------------------------------------------
# Pre-filtered patterns
# ----------------------------------------------------------------------------------


def _square(x, period, foot, duty=0.5):
    """Square wave in [0, 1] (1 on the first ``duty`` of each period) box-filtered by a
    pixel footprint ``foot`` (same units as ``x``): edges ``foot`` wide, contrast faded
    to the mean where a pixel spans half a period or more."""
    t = np.mod(x / period, 1.0)
    d = np.where(t < duty, np.minimum(t, duty - t), -np.minimum(t - duty, 1.0 - t)) * period
    v = np.clip(d / np.maximum(foot, 1e-12) + 0.5, 0.0, 1.0)
    fade = np.clip(2.0 - 4.0 * foot / (period * min(duty, 1.0 - duty) * 2.0), 0.0, 1.0)
    return duty + (v - duty) * fade


def _smooth_fade(foot, period):
    """Contrast of a smooth (sine) pattern of ``period`` seen with footprint ``foot``."""
    return np.clip(1.5 - 3.0 * foot / period, 0.0, 1.0)


def _hash(i, j, salt=0.0):
    """Pseudo-random value in [0, 1) of integer lattice cells ``(i, j)``."""
    v = np.sin(i * 127.1 + j * 311.7 + salt * 74.7) * 43758.5453
    return v - np.floor(v)


def _mix(a, b, t):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return a + (b - a) * np.asarray(t)[..., None]


def _table_texture(style: PhotoStyle, X, Z, foot, ph):
    """Table colour (float BGR) at table points ``(X, Z)`` (metres) seen with footprint
    ``foot`` (metres per pixel); ``ph``: random phases."""
    c1, c2, s = style.table_colour, style.table_colour2, style.table_scale
    a = ph[0] * math.pi
    u = X * math.cos(a) + Z * math.sin(a)
    v = -X * math.sin(a) + Z * math.cos(a)
    if style.table == "wood":
        plank = np.floor(v / s)
        tone = 0.85 + 0.3 * _hash(plank, 0.0, ph[1])
        shift = 3.0 * _hash(plank, 1.0, ph[1])
        period = 0.012
        wob = 0.006 * np.sin(2 * math.pi * (u / 0.45 + shift)) + 0.003 * np.sin(2 * math.pi * u / 0.11)
        grain = np.sin(2 * math.pi * ((v + wob) / period + shift))
        g = 0.5 + 0.5 * np.sign(grain) * np.abs(grain) ** 0.5
        g = 0.5 + (g - 0.5) * _smooth_fade(foot, period)
        col = _mix(c1, c2, 0.45 * g) * tone[..., None]
        joint = _square(v + 0.0015, s, foot, duty=0.003 / s)  # 3 mm dark joints between planks
        return col * (1.0 - 0.55 * joint)[..., None]
    if style.table == "tiles":
        ti, tj = np.floor(u / s), np.floor(v / s)
        tone = 0.9 + 0.2 * _hash(ti, tj, ph[1])
        marble = 1.0 + 0.05 * _smooth_fade(foot, 0.05) * np.sin(2 * math.pi * (u + 0.3 * v) / 0.05 + 6 * _hash(ti, tj))
        col = np.asarray(c1, np.float64) * (tone * marble)[..., None]
        gw = min(0.006, 0.1 * s)
        grout = (1.0 - _square(u + 0.5 * gw, s, foot, gw / s)) * (1.0 - _square(v + 0.5 * gw, s, foot, gw / s))
        return _mix(c2, col, grout)
    if style.table == "checks":
        sx = _square(u, s, foot)
        sz = _square(v, s, foot)
        weave = 1.0 + 0.06 * _smooth_fade(foot, 0.002) * np.sin(2 * math.pi * u / 0.002) * np.sin(2 * math.pi * v / 0.002)
        return _mix(c1, c2, 0.5 * (sx + sz)) * weave[..., None]
    return np.broadcast_to(np.asarray(c1, np.float64), X.shape + (3,)).copy()


def _wall_texture(style: PhotoStyle, s_, Y, foot, ph):
    """Wall colour (float BGR) at wall points (``s_`` along the wall, height ``Y``)."""
    c1, c2, p = style.wall_colour, style.wall_colour2, style.wall_scale
    if style.wall == "stripes":
        a = _square(s_ + ph[2] * p, p, foot, duty=0.35 + 0.3 * ph[3])
        return _mix(c1, c2, a)
    if style.wall == "wallpaper":
        q = p / math.sqrt(2.0)
        r1 = (s_ + Y) / math.sqrt(2.0) + ph[2] * q
        r2 = (s_ - Y) / math.sqrt(2.0)
        diamond = _square(r1, q, foot, 0.5) * _square(r2, q, foot, 0.5)
        gi, gj = np.round(s_ / p), np.round(Y / p)
        dd = np.hypot(s_ - gi * p, Y - gj * p)
        dot = np.clip((0.14 * p - dd) / np.maximum(foot, 1e-12) + 0.5, 0.0, 1.0)
        dot = dot * np.clip(2.0 - 4.0 * foot / (0.28 * p), 0.0, 1.0)
        base = _mix(c1, c2, 0.35 * diamond)
        return _mix(base, np.asarray(c2, np.float64) * 0.7, dot)
    return np.broadcast_to(np.asarray(c1, np.float64), s_.shape + (3,)).copy()


# ----------------------------------------------------------------------------------
# Scene layout: wall plane, clutter
# ----------------------------------------------------------------------------------


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


def _to_pixels(K, Rc, tc, X, distort):
    uv, z = _project(K, Rc, tc, X.reshape(-1, 3))
    if distort is not None:
        uv = distort(uv)
    return uv.reshape(X.shape[:-1] + (2,)), z.reshape(X.shape[:-1])


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
# Clutter and materials
# ----------------------------------------------------------------------------------


def block_layer(block: Block, K, Rc, tc, shape, style, coverage, distort):
    """``(box, coverage, colour)`` of a clutter block in its image box (x0, y0, x1, y1
    inclusive): the exact coverage of its visible faces (``coverage(polygon)``, a
    full-size array) and flat Lambert shading; None when it is not in view."""
    H, W = shape
    C = -Rc.T @ tc
    L = light_direction(style)
    cov = np.zeros((H, W))
    col = np.zeros((H, W, 3))
    for f in block.faces:
        p = block.vertices[list(f)]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        nrm /= np.linalg.norm(nrm)
        if nrm @ (C - p.mean(0)) <= 0:
            continue
        uv, z = _to_pixels(K, Rc, tc, p, distort)
        if z.min() <= 0.01:
            continue
        if uv[:, 0].max() < -1 or uv[:, 1].max() < -1 or uv[:, 0].min() > W or uv[:, 1].min() > H:
            continue
        uv = np.clip(uv, -W, 2 * W)
        cf = coverage(uv)
        shade = style.exposure * (0.45 + 0.6 * max(0.0, float(nrm @ L)))
        cov += cf
        col += cf[..., None] * (np.asarray(block.colour) * shade)
    if cov.max() <= 0:
        return None
    ys, xs = np.nonzero(cov > 0)
    box = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))
    x0, y0, x1, y1 = box
    c = np.clip(cov[y0 : y1 + 1, x0 : x1 + 1], 0.0, 1.0)
    colour = col[y0 : y1 + 1, x0 : x1 + 1] / np.maximum(cov[y0 : y1 + 1, x0 : x1 + 1], 1e-12)[..., None]
    return box, c, colour


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

