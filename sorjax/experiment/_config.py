"""Experiment configs: a TOML schema, parsed and validated in plain Python.

A config describes one study: a scene (the paper's two spheres, a given surface of
revolution seen from given poses, or random SOR scenes), a noise model, the
estimators to compare, the number of trials and the seed.  Any entry of
``scene.f``, ``scene.n_views``, ``scene.shape`` and ``noise.sigma`` may be a list:
the study then sweeps the cartesian product of those lists (in that order), and
each combination is one row of the result table.  Example (``configs/table1.toml``)::

    name = "table1"
    description = "The paper's Table 1 (Section 8)"
    seed = 0
    trials = 100
    methods = ["I", "IIa", "IIb", "bundle", "bundle-unit"]

    [scene]
    type = "two_spheres"
    f = [700.0, 1400.0]
    n_views = 3

    [noise]
    model = "paper"
    sigma = [0.5, 0.7, 1.0, 1.2, 1.5, 1.7, 2.0]

Top-level keys
    name (str, default: the file's stem; a plain name: it is the folder of the run
    directories, and any character but letters, digits, '.', '_', '-' becomes '_'
    there), description (str), seed (int >= 0,
    default 0), trials (int >= 1, default 100), methods (list of "I", "IIa", "IIb",
    "bundle" (free aspect), "bundle-unit" (aspect ratio 1 imposed); default all),
    gross_error (float, % of f, default 20: a trial whose focal error exceeds it, or
    that fails, counts as a gross failure and is left out of the RMS), workers (int
    >= 0: CPU devices the trials are split over, 0 = one per core; default 1: on a CPU
    one device running the trials in a compiled loop is faster than batching them).
[scene]
    type: "two_spheres" (the paper's scene, :func:`sorjax.scenes.two_spheres`),
    "sor" (``profile`` seen from ``poses``) or "random_sor" (a new random scene
    per trial, :func:`sorjax.scenes.random_sor_scene`).
    f (px, > 0; sweepable; optional for random_sor, whose f is then random in
    [500, 1500]), n_views (int; sweepable; two_spheres: 1 to 8; sor: the number of
    poses; random_sor: >= 2), aspect_ratio (fu / fv, default 1), principal_point
    ([u0, v0] px, default the image centre), image_size ([width, height] px,
    default [640, 480]).
    sor only: profile (one of vase, bowl, bottle, wine_glass, candle_holder,
    cylinder), poses (list of tables ``{eye = [x, y, z], target = [x, y, z],
    roll = degrees}`` in object units; the revolution axis is the object's y axis).
    random_sor only: shape (a profile name or a list to sweep; default: all
    shapes mixed), lying (bool, default true: objects may lie on their side),
    vary_aspect (bool, default false).
[noise]
    model: "paper" (uniform displacement along the normal of maximum sigma,
    smoothed along the curve; :func:`sorjax.scenes.paper_noise`) or "gaussian";
    sigma (px, > 0; sweepable), smooth_px (default 2), preserve_std (default false).
[fit]
    n_samples (samples per view, default 100 as in the paper), n_points (outline
    resampling, default 2048), outline_error (px, default 0: synthetic outlines carry
    only the configured noise, no systematic error; see ``sorjax.calibrate``).
[bound]
    enabled (bool, default true): for fixed scenes, the first-order error of the
    bundle and the efficiency bound (:func:`sorjax.predicted_error`) per row.
[reference]
    Optional published numbers drawn beside the results: label (str), sigma (px),
    f (list of px), focal_rms (list of % of f, one per f).

Unknown keys and bad values raise :class:`ConfigError` naming the key.
"""

from __future__ import annotations

import itertools
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

METHODS = ("I", "IIa", "IIb", "bundle", "bundle-unit")
SCENE_TYPES = ("two_spheres", "sor", "random_sor")
SHAPES = ("vase", "bowl", "bottle", "wine_glass", "candle_holder", "cylinder")
SWEEPS = ("f", "n_views", "shape", "sigma")


class ConfigError(ValueError):
    """A config that does not follow the schema; the message names the key."""


@dataclass(frozen=True)
class Pose:
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    roll: float = 0.0


@dataclass(frozen=True)
class SceneConfig:
    type: str = "two_spheres"
    f: tuple[float | None, ...] = (700.0,)
    n_views: tuple[int, ...] = (3,)
    aspect_ratio: float = 1.0
    principal_point: tuple[float, float] | None = None
    image_size: tuple[int, int] = (640, 480)
    profile: str | None = None
    poses: tuple[Pose, ...] = ()
    shape: tuple[str | None, ...] = (None,)
    lying: bool = True
    vary_aspect: bool = False


@dataclass(frozen=True)
class NoiseConfig:
    model: str = "paper"
    sigma: tuple[float, ...] = (1.0,)
    smooth_px: float = 2.0
    preserve_std: bool = False


@dataclass(frozen=True)
class FitConfig:
    n_samples: int = 100
    n_points: int = 2048
    outline_error: float = 0.0


@dataclass(frozen=True)
class Reference:
    label: str
    sigma: float
    f: tuple[float, ...]
    focal_rms: tuple[float, ...]


@dataclass(frozen=True)
class Config:
    """A validated experiment config (see the module docstring for the schema)."""

    name: str
    description: str = ""
    seed: int = 0
    trials: int = 100
    methods: tuple[str, ...] = METHODS
    gross_error: float = 20.0
    workers: int = 1
    scene: SceneConfig = field(default_factory=SceneConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    bound: bool = True
    reference: Reference | None = None

    def rows(self) -> list[dict]:
        """The sweep: one dict ``{f, n_views, shape, sigma}`` per row, in order."""
        axes = (self.scene.f, self.scene.n_views, self.scene.shape, self.noise.sigma)
        return [dict(zip(SWEEPS, combo)) for combo in itertools.product(*axes)]

    def swept(self) -> tuple[str, ...]:
        """The sweep axes with more than one value."""
        axes = dict(f=self.scene.f, n_views=self.scene.n_views, shape=self.scene.shape, sigma=self.noise.sigma)
        return tuple(k for k in SWEEPS if len(axes[k]) > 1)

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **kw) -> "Config":
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d.update(kw)
        return Config(**d)


# ------------------------------------------------------------------ validation


def _take(table: dict, where: str, allowed: dict):
    """Check ``table``'s keys against ``allowed`` (key -> validator) and apply them."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: expected a table, got {type(table).__name__}")
    out = {}
    for k, v in table.items():
        key = f"{where}.{k}" if where else k
        if k not in allowed:
            raise ConfigError(f"unknown key {key!r}; allowed here: {', '.join(sorted(allowed))}")
        out[k] = allowed[k](v, key)
    return out


def _num(lo=None, hi=None, lo_open=False):
    def check(v, key):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError(f"{key} must be a number, got {v!r}")
        v = float(v)
        if v != v or v in (float("inf"), float("-inf")):
            raise ConfigError(f"{key} must be finite, got {v!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise ConfigError(f"{key} must be {'>' if lo_open else '>='} {lo}, got {v!r}")
        if hi is not None and v > hi:
            raise ConfigError(f"{key} must be <= {hi}, got {v!r}")
        return v

    return check


def _int(lo=None, hi=None):
    def check(v, key):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{key} must be an integer, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f"between {lo} and {hi}" if hi is not None else f">= {lo}"
            raise ConfigError(f"{key} must be {rng}, got {v!r}")
        return v

    return check


def _str(choices=None):
    def check(v, key):
        if not isinstance(v, str):
            raise ConfigError(f"{key} must be a string, got {v!r}")
        if choices is not None and v not in choices:
            raise ConfigError(f"{key} must be one of {', '.join(map(repr, choices))}; got {v!r}")
        return v

    return check


def _name(v, key):
    v = _str()(v, key)
    if not v.strip() or any(c in v for c in "/\\\0") or v.startswith("."):
        raise ConfigError(f"{key} must be a plain name, the run's folder in --out (letters, digits, '_', '-', '.'; "
                          f"no path, not starting with '.'); got {v!r}")
    return v


def _bool(v, key):
    if not isinstance(v, bool):
        raise ConfigError(f"{key} must be true or false, got {v!r}")
    return v


def _sweep(item):
    def check(v, key):
        vals = v if isinstance(v, list) else [v]
        if not vals:
            raise ConfigError(f"{key}: an empty list sweeps nothing; give a value or a list of values")
        out = tuple(item(x, f"{key}[{i}]" if isinstance(v, list) else key) for i, x in enumerate(vals))
        if len(set(out)) != len(out):
            raise ConfigError(f"{key} lists a value twice: {list(out)}")
        return out

    return check


def _pair(item):
    def check(v, key):
        if not isinstance(v, list) or len(v) != 2:
            raise ConfigError(f"{key} must be a list of two numbers, got {v!r}")
        return tuple(item(x, f"{key}[{i}]") for i, x in enumerate(v))

    return check


def _vec3(v, key):
    if not isinstance(v, list) or len(v) != 3:
        raise ConfigError(f"{key} must be a list of three numbers, got {v!r}")
    return tuple(_num()(x, f"{key}[{i}]") for i, x in enumerate(v))


def _poses(v, key):
    if not isinstance(v, list) or not v:
        raise ConfigError(f"{key} must be a non-empty list of tables {{eye = [x, y, z], target = [x, y, z], roll = deg}}")
    out = []
    for i, p in enumerate(v):
        d = _take(p, f"{key}[{i}]", dict(eye=_vec3, target=_vec3, roll=_num(-360, 360)))
        for req in ("eye", "target"):
            if req not in d:
                raise ConfigError(f"{key}[{i}] needs {req!r}")
        out.append(Pose(**d))
    return tuple(out)


def _methods(v, key):
    vals = v if isinstance(v, list) else [v]
    if not vals:
        raise ConfigError(f"{key} must name at least one method of {', '.join(METHODS)}")
    out = tuple(_str(METHODS)(m, key) for m in vals)
    if len(set(out)) != len(out):
        raise ConfigError(f"{key} lists a method twice: {list(out)}")
    return out


def _reference(v, key):
    d = _take(v, key, dict(label=_str(), sigma=_num(0, lo_open=True), f=_sweep(_num(0, lo_open=True)),
                           focal_rms=_sweep(_num(0))))
    for req in ("label", "sigma", "f", "focal_rms"):
        if req not in d:
            raise ConfigError(f"{key} needs {req!r}")
    if len(d["f"]) != len(d["focal_rms"]):
        raise ConfigError(f"{key}: f and focal_rms must have the same length")
    return Reference(**d)


def parse_config(data: dict, name: str = "experiment") -> Config:
    """Validate a config given as a dict (e.g. parsed TOML); ``name`` is the default
    for the ``name`` key."""
    top = _take(
        data,
        "",
        dict(
            name=_name, description=_str(), seed=_int(0), trials=_int(1), methods=_methods,
            gross_error=_num(0, lo_open=True), workers=_int(0), scene=lambda v, k: v,
            noise=lambda v, k: v, fit=lambda v, k: v, bound=lambda v, k: v, reference=_reference,
        ),
    )
    sc = _take(
        top.pop("scene", {}),
        "scene",
        dict(
            type=_str(SCENE_TYPES), f=_sweep(_num(0, lo_open=True)), n_views=_sweep(_int(1)),
            aspect_ratio=_num(0, lo_open=True), principal_point=_pair(_num()), image_size=_pair(_int(16)),
            profile=_str(SHAPES), poses=_poses, shape=_sweep(_str(SHAPES)), lying=_bool, vary_aspect=_bool,
        ),
    )
    stype = sc.get("type", "two_spheres")
    only = dict(sor=("profile", "poses"), random_sor=("shape", "lying", "vary_aspect"))
    for t, keys in only.items():
        for k in keys:
            if k in sc and stype != t:
                raise ConfigError(f"scene.{k} applies to scene.type = {t!r} only (this scene is {stype!r})")
    if stype == "two_spheres":
        for n in sc.get("n_views", (3,)):
            if not 1 <= n <= 8:
                raise ConfigError(f"scene.n_views must be between 1 and 8 for the two-sphere scene, got {n}")
    if stype == "sor":
        for req in ("profile", "poses"):
            if req not in sc:
                raise ConfigError(f"scene.type = 'sor' needs scene.{req}")
        nv = sc.get("n_views", (len(sc["poses"]),))
        if nv != (len(sc["poses"]),):
            raise ConfigError(f"scene.n_views is the number of scene.poses ({len(sc['poses'])}) for a 'sor' scene")
        sc["n_views"] = nv
    if stype == "random_sor":
        for n in sc.get("n_views", (3,)):
            if n < 2:
                raise ConfigError(f"scene.n_views must be >= 2 (calibration needs two views), got {n}")
        sc.setdefault("f", (None,))
        if sc.get("vary_aspect") and "aspect_ratio" in sc:
            raise ConfigError("scene.aspect_ratio and scene.vary_aspect = true contradict each other")
    elif stype != "random_sor" and "f" not in sc:
        sc["f"] = (700.0,)
    scene = SceneConfig(**sc)

    noise = NoiseConfig(**_take(top.pop("noise", {}), "noise", dict(
        model=_str(("paper", "gaussian")), sigma=_sweep(_num(0, lo_open=True)), smooth_px=_num(0),
        preserve_std=_bool)))
    fit = FitConfig(**_take(top.pop("fit", {}), "fit", dict(n_samples=_int(10, 10000), n_points=_int(64, 1 << 16),
                                                               outline_error=_num(0))))
    bound = _take(top.pop("bound", {}), "bound", dict(enabled=_bool)).get("enabled", True)
    top.setdefault("name", name)
    return Config(scene=scene, noise=noise, fit=fit, bound=bound, **top)


def load_config(path) -> Config:
    """Read and validate a TOML config file."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{path}: no such config file")
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from None
    try:
        return parse_config(data, name=p.stem)
    except ConfigError as e:
        raise ConfigError(f"{p.name}: {e}") from None
