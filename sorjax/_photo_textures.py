"""Procedural textures of the photo-like scenes (:mod:`sorjax._photo`): the table's
(``"wood"``, ``"tiles"``, ``"checks"``, ``"plain"``, in table coordinates, metres) and
the wall's (``"stripes"``, ``"wallpaper"``, ``"plain"``), as float BGR 0-255.  Patterns
are pre-filtered by each pixel's footprint (metres per pixel): edges one footprint wide,
contrast faded where a pixel spans a period, so they do not alias.
"""

from __future__ import annotations

import math

import numpy as np

from ._photo_style import PhotoStyle


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
