"""Profiles of surfaces of revolution: the radius function ``r(y)`` of a solid about the
object ``Y`` axis.

The solid is the union of the discs ``{(x, y, z): x^2 + z^2 <= r(y)^2}`` for
``y0 <= y <= y1``, closed by flat end discs where ``r(y_end) > 0``.  The named profiles
(:data:`PROFILES`) are in metres; :func:`two_spheres_profile` in the "sphere units" of
:data:`TWO_SPHERES`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ._scene_spheres import TWO_SPHERES
from ._scene_types import SeedLike, _rng


def _pchip(x: np.ndarray, v: np.ndarray):
    """PCHIP interpolant of the knots ``(x, v)``: returns ``(f, f')`` as vectorised callables.

    Knot slopes: 0 where the neighbouring secant slopes differ in sign or vanish, else
    their weighted harmonic mean (Fritsch-Carlson); the end slopes use the
    shape-preserving three-point formula.  Outside ``[x0, xn]`` the end cubics extend.
    """
    h = np.diff(x)
    m = np.diff(v) / h
    n = len(x)
    d = np.zeros(n)
    if n == 2:
        d[:] = m[0]
    else:
        w1 = 2.0 * h[1:] + h[:-1]
        w2 = h[1:] + 2.0 * h[:-1]
        same = (np.sign(m[:-1]) * np.sign(m[1:])) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            hm = (w1 + w2) / (w1 / m[:-1] + w2 / m[1:])
        d[1:-1] = np.where(same, hm, 0.0)

        def end(h0, h1, m0, m1):
            e = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
            if np.sign(e) != np.sign(m0):
                return 0.0
            if np.sign(m0) != np.sign(m1) and abs(e) > 3.0 * abs(m0):
                return 3.0 * m0
            return e

        d[0] = end(h[0], h[1], m[0], m[1])
        d[-1] = end(h[-1], h[-2], m[-1], m[-2])

    # power-basis coefficients of each cubic in u = t - x_k (Horner evaluation)
    c0, c1 = v[:-1], d[:-1]
    c2 = (3.0 * m - 2.0 * d[:-1] - d[1:]) / h
    c3 = (d[:-1] + d[1:] - 2.0 * m) / h**2
    inner = x[1:-1]

    def locate(t):
        t = np.asarray(t, dtype=np.float64)
        k = np.searchsorted(inner, t, side="right")
        return k, t - x[k]

    def f(t):
        k, u = locate(t)
        return ((c3[k] * u + c2[k]) * u + c1[k]) * u + c0[k]

    def df(t):
        k, u = locate(t)
        return (3.0 * c3[k] * u + 2.0 * c2[k]) * u + c1[k]

    return f, df


@dataclass(frozen=True, eq=False)
class Profile:
    """Radius function of a solid of revolution about the object Y axis.

    Attributes
    ----------
    name : str
    y0, y1 : float
        Height range (object units), ``y0 < y1``.
    r : callable
        ``r(y) >= 0`` (vectorised); the solid is closed by flat discs at ``y0``/``y1``
        where ``r > 0``.
    dr : callable
        ``r'(y)`` (vectorised), continuous on ``[y0, y1]`` except at ``breaks``.
    breaks : tuple of float
        Heights where ``r'`` jumps (creases); their circles are treated like end
        circles.  Empty for smooth profiles.
    control : (k, 2) array or None
        Control points ``(y, r)`` when built by :meth:`from_points`.
    r_max, scale : float (derived)
        Maximum radius, and ``max(y1 - y0, r_max)``.
    """

    name: str
    y0: float
    y1: float
    r: Callable[[np.ndarray], np.ndarray]
    dr: Callable[[np.ndarray], np.ndarray]
    breaks: tuple[float, ...] = ()
    control: np.ndarray | None = None
    r_max: float = field(init=False)
    scale: float = field(init=False)

    def __post_init__(self):
        if not (np.isfinite(self.y0) and np.isfinite(self.y1) and self.y1 > self.y0):
            raise ValueError(f"profile {self.name!r}: need y0 < y1, got {self.y0}, {self.y1}")
        if any(not (self.y0 < b < self.y1) for b in self.breaks):
            raise ValueError(f"profile {self.name!r}: breaks must lie strictly inside (y0, y1)")
        ys = np.linspace(self.y0, self.y1, 8001)
        rs = np.asarray(self.r(ys), dtype=np.float64)
        if rs.shape != ys.shape or not np.all(np.isfinite(rs)):
            raise ValueError(f"profile {self.name!r}: r(y) must be finite and vectorised")
        if np.any(rs < 0) or rs.max() <= 0:
            raise ValueError(f"profile {self.name!r}: r(y) must be >= 0 and not identically 0")
        inner = ys[1:-1]
        if not np.all(np.isfinite(np.asarray(self.dr(inner), dtype=np.float64))):
            raise ValueError(f"profile {self.name!r}: r'(y) must be finite inside (y0, y1)")
        object.__setattr__(self, "r_max", float(rs.max()))
        object.__setattr__(self, "scale", float(max(self.y1 - self.y0, rs.max())))

    @classmethod
    def from_points(cls, name: str, y, r) -> "Profile":
        """Smooth profile through control points: a PCHIP spline (monotone piecewise cubic
        Hermite, Fritsch-Carlson slopes as in ``scipy.interpolate.PchipInterpolator``;
        C1 and shape preserving, so ``r > 0`` between positive control points); ``dr``
        is its exact derivative."""
        y = np.asarray(y, dtype=np.float64)
        r = np.asarray(r, dtype=np.float64)
        if y.ndim != 1 or y.shape != r.shape or len(y) < 2 or np.any(np.diff(y) <= 0):
            raise ValueError("control points need strictly increasing y and matching r")
        if np.any(r < 0):
            raise ValueError("control radii must be >= 0")
        r_of, dr_of = _pchip(y, r)
        return cls(name=name, y0=float(y[0]), y1=float(y[-1]), r=r_of, dr=dr_of,
                   control=np.column_stack([y, r]))

    def scaled(self, height: float = 1.0, width: float = 1.0, name: str | None = None) -> "Profile":
        """The profile stretched by ``height`` along the axis (about ``y0``) and by ``width``
        radially: ``r_new(y) = width * r(y0 + (y - y0) / height)``."""
        y0, r, dr = self.y0, self.r, self.dr
        ctrl = None
        if self.control is not None:
            ctrl = np.column_stack([y0 + height * (self.control[:, 0] - y0), width * self.control[:, 1]])
        return Profile(
            name=name or self.name,
            y0=y0,
            y1=y0 + height * (self.y1 - y0),
            r=lambda t: width * r(y0 + (np.asarray(t, float) - y0) / height),
            dr=lambda t: (width / height) * dr(y0 + (np.asarray(t, float) - y0) / height),
            breaks=tuple(y0 + height * (b - y0) for b in self.breaks),
            control=ctrl,
        )


def _named(name: str, pts, scale: float) -> Profile:
    pts = np.asarray(pts, dtype=np.float64) * scale
    return Profile.from_points(name, pts[:, 0], pts[:, 1])


def vase(scale: float = 1.0) -> Profile:
    """A 30 cm vase (metres): round body (r 8.8 cm), narrow neck (r 3.2 cm) and a flared
    lip (r 5.8 cm); the neck makes the profile concave, so parts of the contour
    generator are hidden."""
    return _named(
        "vase",
        [(0.000, 0.050), (0.020, 0.066), (0.070, 0.088), (0.120, 0.082), (0.170, 0.058),
         (0.205, 0.038), (0.230, 0.032), (0.260, 0.036), (0.285, 0.050), (0.300, 0.058)],
        scale,
    )


def bowl(scale: float = 1.0) -> Profile:
    """A convex bowl (metres), 7.5 cm tall, base r 4 cm, rim r 9.8 cm; seen from above the
    rim circle is part of the outline."""
    return _named(
        "bowl",
        [(0.000, 0.040), (0.008, 0.045), (0.025, 0.068), (0.045, 0.085), (0.065, 0.095), (0.075, 0.098)],
        scale,
    )


def bottle(scale: float = 1.0) -> Profile:
    """A 28 cm bottle (metres): cylindrical body r 3.8 cm, shoulder, neck r 1.3 cm, lip."""
    return _named(
        "bottle",
        [(0.000, 0.036), (0.010, 0.038), (0.120, 0.038), (0.150, 0.034), (0.180, 0.022),
         (0.200, 0.014), (0.255, 0.013), (0.268, 0.0145), (0.280, 0.0135)],
        scale,
    )


def wine_glass(scale: float = 1.0) -> Profile:
    """A 19 cm wine glass (metres), as a solid: foot r 3.6 cm, stem r 4.5 mm, bowl r 4 cm."""
    return _named(
        "wine_glass",
        [(0.000, 0.036), (0.003, 0.035), (0.008, 0.020), (0.014, 0.006), (0.020, 0.0045),
         (0.075, 0.0045), (0.085, 0.008), (0.100, 0.025), (0.120, 0.036), (0.145, 0.040),
         (0.170, 0.038), (0.190, 0.034)],
        scale,
    )


def candle_holder(scale: float = 1.0) -> Profile:
    """A 15 cm candle holder (metres): wide base r 4.5 cm, stem with a knop, cup r 3.6 cm."""
    return _named(
        "candle_holder",
        [(0.000, 0.045), (0.006, 0.044), (0.015, 0.030), (0.030, 0.016), (0.050, 0.012),
         (0.065, 0.020), (0.080, 0.012), (0.100, 0.011), (0.115, 0.022), (0.130, 0.034),
         (0.140, 0.036), (0.150, 0.033)],
        scale,
    )


def cylinder(radius: float = 0.033, height: float = 0.115) -> Profile:
    """A can: ``r(y) = radius`` on ``[0, height]`` (metres; default a 330 ml can)."""
    if not (radius > 0 and height > 0):
        raise ValueError("radius and height must be positive")
    return Profile(
        name="cylinder",
        y0=0.0,
        y1=float(height),
        r=lambda t: np.full(np.shape(t), float(radius)),
        dr=lambda t: np.zeros(np.shape(t)),
    )


def two_spheres_profile(trim: float = 1e-6) -> Profile:
    """The two spheres of :data:`TWO_SPHERES` as an analytic profile with a crease.

    ``r(y) = sqrt(1 - y^2)`` below the crease ``y_c = 0.7823`` and
    ``sqrt(0.75^2 - (y - 1.2)^2)`` above, on ``[-1 + trim, 1.95 - trim]`` (trimmed so
    that ``r'`` stays finite; tiny end discs close the solid).  Useful to cross-check
    :func:`sor_silhouette` against the conic construction of :func:`two_spheres`.
    """
    (c1, r1), (c2, r2) = TWO_SPHERES
    a, b = c1[1], c2[1]
    yc = (r1**2 - r2**2 + b**2 - a**2) / (2.0 * (b - a))

    def r(y):
        y = np.asarray(y, dtype=np.float64)
        return np.where(y <= yc, np.sqrt(np.maximum(r1**2 - (y - a) ** 2, 0.0)),
                        np.sqrt(np.maximum(r2**2 - (y - b) ** 2, 0.0)))

    def dr(y):
        y = np.asarray(y, dtype=np.float64)
        return np.where(y <= yc, -(y - a) / r(y), -(y - b) / r(y))

    return Profile("two_spheres", a - r1 + trim, b + r2 - trim, r, dr, breaks=(float(yc),))


#: Named profiles: name -> constructor (all in metres).
PROFILES: dict[str, Callable[[], Profile]] = {
    "vase": vase,
    "bowl": bowl,
    "bottle": bottle,
    "wine_glass": wine_glass,
    "candle_holder": candle_holder,
    "cylinder": cylinder,
}


def perturb_profile(profile: Profile, seed_or_rng: SeedLike, amount: float = 0.1) -> Profile:
    """A randomly perturbed copy of ``profile``.

    Height and width are scaled by independent factors ``exp(amount * N(0, 1))``; for a
    control-point profile every control radius is further multiplied by
    ``exp(0.25 * amount * N(0, 1))`` (the spline stays positive).
    """
    rng, _ = _rng(seed_or_rng)
    sh, sw = np.exp(amount * rng.standard_normal(2))
    if profile.control is not None:
        y, r = profile.control.T
        r = r * np.exp(0.25 * amount * rng.standard_normal(len(r)))
        profile = Profile.from_points(profile.name, y, r)
    return profile.scaled(height=float(sh), width=float(sw))
