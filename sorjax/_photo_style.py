"""The look of a photo-like render (:mod:`sorjax._photo`): :class:`PhotoStyle`, its
checks, random styles and a one-line description.  Lengths in metres unless said
otherwise, colours BGR 0-255.
"""

from __future__ import annotations

from dataclasses import dataclass

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
