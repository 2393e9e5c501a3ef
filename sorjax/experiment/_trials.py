"""One trial of an experiment: draw the scene and the noise, fit, run every method.

Seeds: trial ``t`` of row ``r`` uses ``trial_seed(seed, r, t)`` (a 63-bit integer from
``numpy.random.SeedSequence([seed, r, t])``), recorded in the results; the noise is
drawn from ``default_rng(trial_seed)`` and a random scene from
``default_rng([trial_seed, 1])``.  A trial is therefore reproducible on its own,
whatever the number of workers or the order in which trials run.
"""

from __future__ import annotations

import functools
import math
import time
import warnings

import numpy as np

from .. import scenes
from .._calibration import RESULTS, calibrate
from .._homology import fit_homology
from .._outline import as_outlines
from ._config import Config, SceneConfig


def trial_seed(seed: int, row: int, trial: int) -> int:
    return int(np.random.SeedSequence([seed, row, trial]).generate_state(2, np.uint64)[0] >> np.uint64(1))


def _K(sc: SceneConfig, f: float) -> np.ndarray:
    w, h = sc.image_size
    pp = sc.principal_point if sc.principal_point is not None else (w / 2.0, h / 2.0)
    return scenes.intrinsics(f, aspect_ratio=sc.aspect_ratio, principal_point=pp)


@functools.lru_cache(maxsize=64)
def fixed_scene(sc: SceneConfig, f: float, n_views: int) -> scenes.Scene:
    """The noise-free scene of a row, for the fixed scene types."""
    if sc.type == "two_spheres":
        return scenes.two_spheres(f, image_size=tuple(sc.image_size), n_views=n_views,
                                  aspect_ratio=sc.aspect_ratio, principal_point=sc.principal_point)
    profile = getattr(scenes, sc.profile)()
    poses = [scenes.look_at(p.eye, p.target, roll=math.radians(p.roll)) for p in sc.poses]
    return scenes.sor_scene(profile, _K(sc, f), poses, image_size=tuple(sc.image_size))


def scene_for(cfg: Config, row: dict, seed: int) -> scenes.Scene:
    sc = cfg.scene
    if sc.type != "random_sor":
        return fixed_scene(sc, row["f"], row["n_views"])
    K = None if row["f"] is None else _K(sc, row["f"])
    shapes = None if row["shape"] is None else [row["shape"]]
    return scenes.random_sor_scene(np.random.default_rng([seed, 1]), row["n_views"], K=K, shapes=shapes,
                                   lying=sc.lying, vary_aspect=sc.vary_aspect, image_size=tuple(sc.image_size))


def _code(cal) -> str:
    for name, item in RESULTS._name_to_item.items():
        if bool(cal.result == item):
            return name
    return "unknown"  # pragma: no cover


def _method_args(m: str):
    if m == "bundle-unit":
        return "bundle", 1.0
    return m, None


def run_trial(cfg: Config, row_index: int, row: dict, trial: int) -> dict:
    """Run every method of ``cfg`` on one noisy draw; returns a JSON-able record.

    Errors are in % of the true ``fv`` (the paper's "percent of f"), signed,
    for ``(fu, fv, u0, v0)``."""
    seed = trial_seed(cfg.seed, row_index, trial)
    rec = dict(row=row_index, trial=trial, seed=seed, methods={})
    try:
        scene = scene_for(cfg, row, seed)
    except ValueError as e:
        rec["error"] = f"scene: {e}"
        return rec
    K = np.asarray(scene.K)
    rec["K_true"] = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    sigma = row["sigma"]
    rng = np.random.default_rng(seed)
    nz = cfg.noise
    if nz.model == "gaussian":
        outs = [scenes.gaussian_noise(o, sigma, rng) for o in scene.outlines]
    else:
        outs = [scenes.paper_noise(o, sigma, rng, smooth_px=nz.smooth_px, preserve_std=nz.preserve_std)
                for o in scene.outlines]
    kw = dict(n_samples=cfg.fit.n_samples, n_points=cfg.fit.n_points)
    t0 = time.perf_counter()
    try:
        outs = as_outlines(outs, cfg.fit.n_points)  # validated and resampled once for every method
        homs = tuple(fit_homology(o, **kw) for o in outs)
    except (ValueError, FloatingPointError) as e:
        rec["error"] = f"homology fit: {e}"
        return rec
    rec["fit_time"] = time.perf_counter() - t0
    rec["l_s"] = [np.asarray(h.l_s).tolist() for h in homs]
    rec["v_x"] = [np.asarray(h.v_x).tolist() for h in homs]
    rec["view_rms"] = [float(h.rms) for h in homs]
    f = K[1, 1]
    for m in cfg.methods:
        method, a = _method_args(m)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                cal = calibrate(outs, method=method, aspect_ratio=a, homologies=homs,
                                outline_error=cfg.fit.outline_error, **kw)
            except ValueError as e:
                rec["methods"][m] = dict(code="error", message=str(e), success=False, gross=True,
                                         time=time.perf_counter() - t0)
                continue
        est = [cal.fu, cal.fv, cal.u0, cal.v0]
        err = [(e - k) / f * 100.0 for e, k in zip(est, rec["K_true"])]
        ok = cal.success and all(np.isfinite(err))
        gross = (not ok) or max(abs(err[0]), abs(err[1])) > cfg.gross_error
        rec["methods"][m] = dict(
            estimate=est, error=err, std=[float(s) for s in cal.std], code=_code(cal), success=bool(cal.success),
            gross=bool(gross), time=time.perf_counter() - t0, warnings=[str(w.message) for w in caught],
        )
    return rec


def run_chunk(cfg: Config, tasks: list[tuple[int, dict, int]]) -> list[dict]:
    """Run a list of ``(row_index, row, trial)`` tasks (a worker's unit of work)."""
    return [run_trial(cfg, r, row, t) for r, row, t in tasks]
