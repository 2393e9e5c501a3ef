"""Run an experiment config: chunks of trials through the core's compiled program
(sharded over the devices), then the run directory.

``run_experiment`` writes ``<out>/<config name>/<timestamp>/``:

* ``config.json`` the resolved config (every default filled in) and, when the config
  came from a file, ``config.toml`` a copy of it;
* ``environment.json`` Python, platform, package versions, JAX devices, the git
  commit of the checkout when there is one;
* ``results.json`` every trial (seed, true K, per method: estimate, signed errors in
  % of f, standard deviations, result code, gross-failure flag, time, warnings;
  the per-view fitted l_s and v_x), the per-row summary and the bounds;
* ``table.md`` the paper's layout, ``results.csv`` one line per trial and method;
* figures: ``error_vs_<axis>.png`` for each swept axis and ``scene.png``.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

import numpy as np

from .._compile import enable_compilation_cache as enable_compilation_cache
from .._files import absolute, atomic_folder, check_folder, safe_name
from ._config import Config
from ._report import error_figures, records_csv, reference_lines, scene_figure, summarise, table_markdown
from ._trials import fixed_scene, run_batch, scene_for, trial_seed


@dataclass
class RunResult:
    """What :func:`run_experiment` produced: the run directory (None when not
    written), the per-trial records, the per-row summary, the bounds, the table."""

    path: Path | None
    records: list
    summary: list
    bounds: dict
    table: str
    seconds: float


def environment() -> dict:
    import jax

    pk = {}
    for name in ("sorjax", "jax", "jaxlib", "optimistix", "equinox", "lineax", "numpy", "opencv-python-headless", "matplotlib"):
        try:
            pk[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pk[name] = None
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                                text=True, timeout=5).stdout.strip() or None
    except Exception:  # pragma: no cover
        commit = None
    return dict(
        python=sys.version.split()[0], platform=platform.platform(), cpu_count=os.cpu_count(), packages=pk,
        jax_devices=[str(d) for d in jax.devices()], x64=bool(jax.config.jax_enable_x64), git_commit=commit,
    )


def compute_bounds(cfg: Config) -> dict:
    """Per row, the efficiency bound of the bundle's ``(fu, fv, u0, v0)`` in % of f
    (``"bound"`` for free aspect, ``"bound-unit"`` for a known aspect ratio 1), for
    the fixed scene types.  The bound scales with sigma (the noise covariance is
    proportional to sigma^2), so it is computed once per scene at sigma = 1 px."""
    from .._uncertainty import predicted_error

    if not cfg.bound or cfg.scene.type == "random_sor":
        return {}
    variants = {}
    if "bundle" in cfg.methods or "IIa" in cfg.methods:
        variants["bound"] = None
    if "bundle-unit" in cfg.methods or "IIb" in cfg.methods or "I" in cfg.methods:
        variants["bound-unit"] = 1.0
    out = {k: {} for k in variants}
    cache = {}
    for r, row in enumerate(cfg.rows()):
        for name, a in variants.items():
            key = (row["f"], row["n_views"], name)
            if key not in cache:
                scene = fixed_scene(cfg.scene, row["f"], row["n_views"])
                try:
                    p = predicted_error(scene, 1.0, noise=cfg.noise.model, smooth_px=cfg.noise.smooth_px,
                                        preserve_std=cfg.noise.preserve_std, aspect_ratio=a,
                                        n_samples=cfg.fit.n_samples, n_points=cfg.fit.n_points)
                    cache[key] = p.percent("bound")
                except (ValueError, np.linalg.LinAlgError):
                    cache[key] = None
            v = cache[key]
            out[name][r] = None if v is None else [float(x) * row["sigma"] for x in v]
    return out


def use_cpu_devices(n: int = 0) -> bool:
    """Split trials over ``n`` XLA CPU devices (0: one per core), each running its share
    of a chunk on its own thread: how a run uses every core of one machine.  Takes
    effect only before JAX starts its backend (call it first thing; the command line
    does); returns whether it did.  ``XLA_FLAGS`` set by the user wins."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"workers must be an integer >= 0 (0: one per core), got {n!r}")
    n = (os.cpu_count() or 1) if n == 0 else int(n)
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_force_host_platform_device_count" in flags or n <= 1:
        return False
    try:
        from jax._src import xla_bridge

        if xla_bridge.backends_are_initialized():
            return False
    except Exception:  # pragma: no cover  (private API moved: leave it to the user)
        return False
    os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n}".strip()
    return True


def _tasks(cfg: Config):
    return [(r, row, t) for r, row in enumerate(cfg.rows()) for t in range(cfg.trials)]


def run_trials(cfg: Config, workers: int | None = None, progress: bool = True, chunk: int = 64) -> list[dict]:
    """Run every trial of ``cfg`` and return the records sorted by (row, trial).

    The trials go through one compiled program of the functional core per shape, in
    chunks of ``chunk`` trials sharded over every device JAX sees
    (:class:`sorjax.experiment._trials.TrialProgram`).  ``workers`` is kept for
    compatibility: the number of CPU devices is set before JAX starts
    (:func:`use_cpu_devices`, the command line's ``--workers``)."""
    del workers
    enable_compilation_cache()
    tasks = _tasks(cfg)
    from tqdm.auto import tqdm

    with tqdm(total=len(tasks), unit="trial", disable=not progress, leave=True, dynamic_ncols=True) as bar:
        records = run_batch(cfg, tasks, chunk=chunk, on_chunk=bar.update)
    return sorted(records, key=lambda x: (x["row"], x["trial"]))


def run_experiment(cfg: Config, out: str | os.PathLike | None = "runs", *, trials: int | None = None,
                   seed: int | None = None, workers: int | None = None, progress: bool = True,
                   source: str | None = None) -> RunResult:
    """Run ``cfg`` (``trials``/``seed`` override the config's) and, unless ``out`` is
    None, write the run directory ``out/<name>/<UTC timestamp>/`` (``name`` made a
    plain folder name by :func:`sorjax._files.safe_name`).  Where the run directory
    goes is checked before any trial runs (ValueError when it cannot be written);
    it is filled under a temporary name and renamed when complete."""
    run_root = None if out is None else run_folder(cfg, out)
    for name, value, lo in (("trials", trials, 1), ("seed", seed, 0)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo):
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    if trials is not None:
        cfg = cfg.replace(trials=int(trials))
    if seed is not None:
        cfg = cfg.replace(seed=int(seed))
    enable_compilation_cache()
    # the bounds (a program of their own) computed on a host thread while the trials
    # run: their tracing and compilation overlap the trial programs'
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="sorjax-bounds") as pool:
        bounds_job = pool.submit(compute_bounds, cfg)
        t0 = time.perf_counter()
        records = run_trials(cfg, workers, progress)
        seconds = time.perf_counter() - t0
        bounds = bounds_job.result()
    summary = summarise(cfg, records)
    table = table_markdown(cfg, summary, bounds)
    res = RunResult(None, records, summary, bounds, table, seconds)
    if out is None:
        return res
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%fZ")
    with atomic_folder(run_root / stamp) as path:
        _write_run(cfg, path, records, summary, bounds, table, seconds, source)
    res.path = run_root / stamp
    return res


def run_folder(cfg: Config, out, what: str = "out") -> Path:
    """``out/<name>``, the folder of ``cfg``'s run directories, after checking that it
    can be written and stays inside ``out`` (ValueError naming ``what`` otherwise)."""
    root = Path(out) / safe_name(cfg.name, "experiment")
    if not absolute(root).is_relative_to(absolute(out)):  # safe_name makes this impossible; kept as the rule
        raise ValueError(f"{what}: the run folder {root} would lie outside {out}")
    check_folder(root, what)
    return root


def failure_summary(records: list[dict]) -> str | None:
    """When no trial gave a successful calibration by any method: a sentence with the
    commonest reasons (else None)."""
    reasons: dict[str, int] = {}
    for rec in records:
        if "error" in rec:
            reasons[rec["error"]] = reasons.get(rec["error"], 0) + 1
            continue
        if any(m["success"] for m in rec["methods"].values()):
            return None
        for m, x in rec["methods"].items():
            reasons[f"{m}: {x['code']}"] = reasons.get(f"{m}: {x['code']}", 0) + 1
    top = sorted(reasons.items(), key=lambda kv: -kv[1])[:3]
    return (f"every one of the {len(records)} trials failed, by every method (" +
            "; ".join(f"{why} x {n}" for why, n in top) + ")")


def _write_run(cfg: Config, path: Path, records, summary, bounds, table, seconds, source) -> None:
    (path / "config.json").write_text(json.dumps(cfg.to_dict(), indent=1))
    if source is not None:
        (path / "config.toml").write_text(source)
    (path / "environment.json").write_text(json.dumps(environment(), indent=1))
    (path / "results.json").write_text(json.dumps(
        dict(name=cfg.name, seed=cfg.seed, trials=cfg.trials, seconds=seconds, records=records, summary=summary,
             bounds={k: {str(r): v for r, v in b.items()} for k, b in bounds.items()}),
        indent=1, default=_json_default))
    extra = "\n".join(reference_lines(cfg, summary))
    (path / "table.md").write_text(
        f"# {cfg.name}\n\n{cfg.description}\n\nRMS error in % of f over the trials that are not gross failures "
        f"(failed, or focal error above {cfg.gross_error:g} %; their number in brackets); {cfg.trials} trials per "
        f"row, seed {cfg.seed}, {seconds:.0f} s.\n\n{table}\n" + (f"\n{extra}\n" if extra else ""))
    (path / "results.csv").write_text(records_csv(cfg, records))
    error_figures(cfg, summary, bounds, path)
    _scene_plot(cfg, records, path)


def _scene_plot(cfg: Config, records: list[dict], path: Path) -> None:
    from .. import scenes

    rec = next((r for r in records if r["row"] == 0 and "error" not in r), None)
    if rec is None:
        return
    row = cfg.rows()[0]
    scene = scene_for(cfg, row, rec["seed"])
    rng = np.random.default_rng(rec["seed"])
    if cfg.noise.model == "gaussian":
        noisy = [scenes.gaussian_noise(o, row["sigma"], rng) for o in scene.outlines]
    else:
        noisy = [scenes.paper_noise(o, row["sigma"], rng, smooth_px=cfg.noise.smooth_px,
                                    preserve_std=cfg.noise.preserve_std) for o in scene.outlines]
    homs = [_Line(l) for l in rec.get("l_s", [])] or None
    title = f"{cfg.name}: row 0 (" + ", ".join(f"{k}={v}" for k, v in row.items() if v is not None) + \
        f"), trial 0, seed {rec['seed']}"
    scene_figure(scene, noisy, homs, path / "scene.png", title)


@dataclass
class _Line:
    l_s: list


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON-serialisable: {type(x).__name__}")


__all__ = ["RunResult", "failure_summary", "run_experiment", "run_folder", "run_trials", "compute_bounds", "environment", "trial_seed"]
