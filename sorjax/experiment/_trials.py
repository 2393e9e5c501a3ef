"""Trials of an experiment: draw each trial's scene and noise on the host, then push
chunks of trials through one compiled program of the functional core.

Seeds: trial ``t`` of row ``r`` uses ``trial_seed(seed, r, t)`` (a 63-bit integer from
``numpy.random.SeedSequence([seed, r, t])``), recorded in the results; the noise is
drawn from ``default_rng(trial_seed)`` and a random scene from
``default_rng([trial_seed, 1])``.  A trial is therefore reproducible on its own,
whatever the chunking, the number of devices or the order in which trials run.

The program (:class:`TrialProgram`): per trial, the per-view fits once
(:func:`sorjax.core.fit_views`), then every method of the config on them
(:func:`sorjax.core.calibrate_homologies`), ``jax.vmap``-ed over a chunk of trials,
``jax.jit``-ed once per shape (views, points) and sharded over every device JAX sees
(:class:`sorjax.core.TrialSharder`).  The records are made on the host from its
arrays, with the same warnings :func:`sorjax.calibrate` gives.
"""

from __future__ import annotations

import functools
import math
import time

import jax
import numpy as np

from .. import core, scenes
from .._compile import options_for_runs
from .._messages import code_name, verdict_notes, view_notes
from .._outline import is_jagged, resample_closed, signed_area, smooth_jagged
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


def noisy_outlines(cfg: Config, scene, sigma: float, rng) -> list[np.ndarray]:
    """The trial's noisy outlines (the config's noise model, drawn from ``rng``)."""
    nz = cfg.noise
    if nz.model == "gaussian":
        return [scenes.gaussian_noise(o, sigma, rng) for o in scene.outlines]
    return [scenes.paper_noise(o, sigma, rng, smooth_px=nz.smooth_px, preserve_std=nz.preserve_std)
            for o in scene.outlines]


def _resampled(o: np.ndarray, n: int) -> np.ndarray:
    """A synthetic outline, positively oriented, smoothed where it is jagged (as
    :func:`sorjax.make_outline` smooths: i.i.d. noise per point) and resampled to ``n``
    points (the scenes' outlines are valid by construction: no boundary validation)."""
    o = np.asarray(o, dtype=np.float64)
    if is_jagged(o):
        o = smooth_jagged(o)[0]
    return resample_closed(o if signed_area(o) > 0 else o[::-1], n)


def draw_trial(cfg: Config, row_index: int, row: dict, trial: int):
    """One trial's record skeleton and its outline points (V, M, 2) px (None when the
    scene could not be made; the record then says why)."""
    seed = trial_seed(cfg.seed, row_index, trial)
    rec = dict(row=row_index, trial=trial, seed=seed, methods={})
    try:
        scene = scene_for(cfg, row, seed)
    except ValueError as e:
        rec["error"] = f"scene: {e}"
        return rec, None
    K = np.asarray(scene.K)
    rec["K_true"] = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    outs = noisy_outlines(cfg, scene, row["sigma"], np.random.default_rng(seed))
    return rec, np.stack([_resampled(o, cfg.fit.n_points) for o in outs])


def _method_args(m: str):
    """``(core method, aspect)`` of a config's method name."""
    if m == "bundle-unit":
        return "bundle", 1.0
    return m, math.nan


def options_for(cfg: Config) -> core.Options:
    return core.Options(n_samples=cfg.fit.n_samples, outline_error_px=float(cfg.fit.outline_error))


class TrialProgram:
    """The compiled program of a config: ``points (B, V, M, 2) -> (homologies,
    {method: CoreResult})`` with a leading trial axis, sharded over the devices.

    Stages, each one compiled program per shape: the per-view fits
    (:func:`sorjax.core.fit_homologies`), then the methods on them
    (:func:`sorjax.core.calibrate_methods`) in two programs, the bundles' and the
    linear methods' (each its own concept: the bundles share one traced solver, the
    linear methods one covariance; as one program they compiled in 37 s, as two in
    19 + 14 s, side by side).  All are traced on the first chunk and compiled side by
    side (:func:`sorjax.core.compile_together`: XLA compiles one program on one core);
    on one CPU device each chunk's parts run side by side from host threads, fits then
    methods (:class:`sorjax.core.TrialSharder`).  Reuse the
    instance for every chunk of a run.  ``compiler_options``: XLA's options for both
    stages (None: XLA's defaults; :func:`run_batch` picks
    :func:`sorjax._compile.options_for_runs` of its trial count: a short run is
    compile-bound)."""

    def __init__(self, cfg: Config, compiler_options: dict | None = None):
        self.compiler_options = compiler_options
        self.methods = tuple(cfg.methods)
        self.options = options = options_for(cfg)
        names = tuple(_method_args(m)[0] for m in self.methods)
        aspects = np.array([_method_args(m)[1] for m in self.methods])
        sequential = jax.default_backend() == "cpu" and len(jax.devices()) == 1  # core.TrialSharder's ``batch``
        self.fits = core.TrialSharder(lambda points: core.fit_homologies(points, options, sequential))

        def stage(idx):
            ms, ns, asp = tuple(self.methods[i] for i in idx), tuple(names[i] for i in idx), aspects[list(idx)]
            return core.TrialSharder(
                lambda points, homs: dict(zip(ms, core.calibrate_methods(points, homs, ns, asp, options=options))))

        bundles = tuple(i for i, n in enumerate(names) if n == "bundle")
        linear = tuple(i for i, n in enumerate(names) if n != "bundle")
        self.stages = [stage(idx) for idx in (bundles, linear) if idx]
        self.lower_s = self.compile_s = 0.0  # the last new shape's tracing and compilation (s)
        self._homs: dict = {}  # a part's shapes -> the fits' output shapes

    def split(self, points: np.ndarray):
        """``(n, parts)`` of a chunk (:meth:`sorjax.core.TrialSharder.split`)."""
        return self.fits.split(points)

    def executables(self, part):
        """The stages' compiled programs for a part's shapes: ``(fits, [methods'
        stages])``, traced one after the other, compiled together, on first use (timed:
        :attr:`lower_s`, :attr:`compile_s`)."""
        key = core.TrialSharder.shape_key(part)
        if key not in self._homs:
            t0 = time.perf_counter()
            fits = self.fits.lower(*part)
            homs = jax.tree.map(lambda o: jax.ShapeDtypeStruct(o.shape, o.dtype, sharding=self.fits.sharding),
                                fits.out_info)
            cals = [st.lower(*part, homs) for st in self.stages]
            t1 = time.perf_counter()
            exes = core.compile_together([fits, *cals], self.compiler_options)
            self.fits.adopt(part, exes[0])
            for st, exe in zip(self.stages, exes[1:]):
                st.adopt((*part, homs), exe)
            self._homs[key] = homs
            self.lower_s, self.compile_s = t1 - t0, time.perf_counter() - t1
        homs = self._homs[key]
        return self.fits.executable(*part), [st.executable(*part, homs) for st in self.stages]

    def run_parts(self, parts):
        """Every stage on every part (side by side from host threads when there are
        several), concatenated along the trial axis."""
        fit, cals = self.executables(parts[0])

        def both(*p):
            homs = fit(*p)
            results = {}
            for cal in cals:
                results.update(cal(*p, homs))
            return homs, {m: results[m] for m in self.methods}

        return self.fits.run_parts(both, parts)

    def __call__(self, points: np.ndarray):
        n, parts = self.split(points)
        return core.TrialSharder.trimmed(self.run_parts(parts), n)


def records_from(cfg: Config, recs: list[dict], homs, results: dict, seconds: float) -> None:
    """Fill each trial's record (in place) from the program's outputs for a chunk
    (numpy, leading trial axis), ``seconds`` the chunk's wall time."""
    per = seconds / max(len(recs), 1)
    homs = jax.tree_util.tree_map(np.asarray, homs)
    results = jax.tree_util.tree_map(np.asarray, results)
    for b, rec in enumerate(recs):
        h = jax.tree_util.tree_map(lambda x: x[b], homs)
        rec["fit_time"] = per / 2
        rec["l_s"] = h.l_s.tolist()
        rec["v_x"] = h.v_x.tolist()
        rec["view_rms"] = [float(x) for x in h.rms]
        f = rec["K_true"][1]
        for m in cfg.methods:
            r = jax.tree_util.tree_map(lambda x: x[b], results[m])
            K = r.K
            est = [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])]
            err = [(e - k) / f * 100.0 for e, k in zip(est, rec["K_true"])]
            code = code_name(r.result)
            ok = code == "successful" and all(np.isfinite(err))
            gross = (not ok) or max(abs(err[0]), abs(err[1])) > cfg.gross_error
            method, a = _method_args(m)
            warns = view_notes(h, r.drop_reason) + verdict_notes(r, method, None if math.isnan(a) else a)
            rec["methods"][m] = dict(
                estimate=est, error=err, std=[float(s) for s in np.sqrt(np.diag(r.covariance))], code=code,
                success=code == "successful", gross=bool(gross), time=per / (2 * len(cfg.methods)), warnings=warns,
            )


def run_batch(cfg: Config, tasks: list[tuple[int, dict, int]], program: TrialProgram | None = None,
              chunk: int = 64, on_chunk=None) -> list[dict]:
    """Run ``(row_index, row, trial)`` tasks in chunks of ``chunk`` trials (the last
    padded, one compiled program per shape); ``on_chunk(n)`` after each chunk.  The
    program (when not given) is compiled for a short compile when the run is short
    (:func:`sorjax._compile.options_for_runs`: fewer than 200 trials)."""
    program = TrialProgram(cfg, options_for_runs(len(tasks))) if program is None else program
    drawn = [draw_trial(cfg, r, row, t) for r, row, t in tasks]
    by_shape: dict[tuple, list[int]] = {}
    for i, (_, pts) in enumerate(drawn):
        if pts is not None:
            by_shape.setdefault(pts.shape, []).append(i)
    n_dev = len(jax.devices())
    for idx in by_shape.values():
        size = -(-min(chunk, len(idx)) // n_dev) * n_dev  # every chunk this size: one compilation
        for s in range(0, len(idx), size):
            part = idx[s:s + size]
            pts = np.stack([drawn[i][1] for i in part] + [drawn[part[-1]][1]] * (size - len(part)))
            t0 = time.perf_counter()
            homs, results = program(pts)
            jax.block_until_ready(results)
            records_from(cfg, [drawn[i][0] for i in part], homs, results, time.perf_counter() - t0)
            if on_chunk is not None:
                on_chunk(len(part))
    return [rec for rec, _ in drawn]


def run_trial(cfg: Config, row_index: int, row: dict, trial: int) -> dict:
    """Run every method of ``cfg`` on one noisy draw; returns a JSON-able record.

    Errors are in % of the true ``fv`` (the paper's "percent of f"), signed,
    for ``(fu, fv, u0, v0)``."""
    return run_batch(cfg, [(row_index, row, trial)], chunk=1)[0]
