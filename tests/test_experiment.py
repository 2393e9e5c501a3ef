"""Experiment configs, the runner and its run directory."""

import json
from pathlib import Path

import numpy as np
import pytest

from sorjax.cli import main
from sorjax.experiment import ConfigError, load_config, parse_config, run_experiment, run_trial, trial_seed
from sorjax.experiment._trials import TrialProgram, run_batch

CONFIGS = Path(__file__).resolve().parent.parent / "configs"

TINY = """
name = "tiny"
seed = 3
trials = 2
methods = ["IIb", "bundle-unit"]
[scene]
type = "two_spheres"
f = 700.0
n_views = 3
[noise]
sigma = [0.5, 1.0]
[bound]
enabled = false
"""


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("*.toml")), ids=lambda p: p.name)
def test_bundled_configs_load(path):
    cfg = load_config(path)
    assert cfg.name == path.stem
    assert len(cfg.rows()) >= 1 and cfg.trials >= 1


def test_table1_config_is_the_papers():
    cfg = load_config(CONFIGS / "table1.toml")
    assert cfg.trials == 100 and cfg.scene.n_views == (3,)
    assert cfg.scene.f == (700.0, 1400.0)
    assert cfg.noise.sigma == (0.5, 0.7, 1.0, 1.2, 1.5, 1.7, 2.0)
    assert set(cfg.methods) == {"I", "IIa", "IIb", "bundle", "bundle-unit"}
    rows = cfg.rows()
    assert len(rows) == 14 and rows[0]["f"] == 700.0 and rows[7]["f"] == 1400.0 and rows[1]["sigma"] == 0.7
    assert cfg.swept() == ("f", "sigma")


@pytest.mark.parametrize(
    "data, key",
    [
        ({"trails": 3}, "'trails'"),
        ({"scene": {"focal": 700}}, "scene.focal"),
        ({"noise": {"sigma": -1.0}}, "noise.sigma"),
        ({"noise": {"sigma": []}}, "noise.sigma"),
        ({"noise": {"model": "laplace"}}, "noise.model"),
        ({"methods": ["IIc"]}, "methods"),
        ({"trials": 0}, "trials"),
        ({"trials": 2.5}, "trials"),
        ({"seed": -1}, "seed"),
        ({"scene": {"n_views": 9}}, "scene.n_views"),
        ({"scene": {"f": [700.0, "x"]}}, "scene.f[1]"),
        ({"scene": {"type": "cube"}}, "scene.type"),
        ({"scene": {"type": "sor", "profile": "vase"}}, "scene.poses"),
        ({"scene": {"shape": "vase"}}, "scene.shape"),
        ({"scene": {"type": "sor", "profile": "vase", "poses": [{"eye": [0, 0, 5]}]}}, "target"),
        ({"scene": {"type": "random_sor", "n_views": 1}}, "scene.n_views"),
        ({"fit": {"n_samples": 3}}, "fit.n_samples"),
        ({"bound": {"on": True}}, "bound.on"),
        ({"reference": {"label": "x", "sigma": 2.0, "f": [700.0], "focal_rms": [1.0, 2.0]}}, "reference"),
    ],
)
def test_bad_configs_name_the_key(data, key):
    with pytest.raises(ConfigError) as e:
        parse_config(data)
    assert key in str(e.value)


def test_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="no such config"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("trials = [1,\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)


def test_sor_and_random_scenes_parse():
    cfg = parse_config({"scene": {"type": "sor", "profile": "vase", "poses": [
        {"eye": [0.0, 0.3, 1.5], "target": [0.0, 0.1, 0.0], "roll": 10.0},
        {"eye": [1.0, -0.4, 1.2], "target": [0.0, 0.1, 0.0]}]}})
    assert cfg.scene.n_views == (2,) and cfg.scene.poses[0].roll == 10.0
    cfg = parse_config({"scene": {"type": "random_sor", "shape": ["vase", "bowl"], "n_views": [2, 4]}})
    assert cfg.scene.f == (None,)
    assert [(r["shape"], r["n_views"]) for r in cfg.rows()] == [("vase", 2), ("bowl", 2), ("vase", 4), ("bowl", 4)]


def test_trial_seeds_are_distinct_and_stable():
    seeds = {trial_seed(0, r, t) for r in range(5) for t in range(50)}
    assert len(seeds) == 250
    assert trial_seed(7, 1, 2) == trial_seed(7, 1, 2) != trial_seed(8, 1, 2)


def test_end_to_end_run_directory_and_determinism(tmp_path):
    cfg = parse_config(__import__("tomllib").loads(TINY))
    res = run_experiment(cfg, out=tmp_path, workers=1, progress=False, source=TINY)
    d = res.path
    assert d.parent == tmp_path / "tiny"
    for name in ("config.json", "config.toml", "environment.json", "results.json", "table.md", "results.csv",
                 "error_vs_sigma.png", "scene.png"):
        assert (d / name).is_file(), name
    assert (d / "error_vs_sigma.png").read_bytes()[:4] == b"\x89PNG"
    env = json.loads((d / "environment.json").read_text())
    assert env["packages"]["jax"] and env["x64"] is True and env["jax_devices"]
    assert json.loads((d / "config.json").read_text())["seed"] == 3

    out = json.loads((d / "results.json").read_text())
    recs = out["records"]
    assert len(recs) == 4 and [(r["row"], r["trial"]) for r in recs] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    for r in recs:
        assert r["K_true"] == [700.0, 700.0, 320.0, 240.0]
        for m in ("IIb", "bundle-unit"):
            x = r["methods"][m]
            assert x["success"] and x["code"] == "successful"
            # errors are the estimates' differences from the truth, in % of f
            np.testing.assert_allclose(x["error"], (np.array(x["estimate"]) - r["K_true"]) / 7.0, rtol=1e-9)
            assert abs(x["error"][1]) < 10.0
        assert np.isfinite(r["methods"]["bundle-unit"]["std"]).all()

    rows = (d / "results.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 4 * 2
    table = (d / "table.md").read_text()
    assert "| 700 | 0.5 |" in table and "| 700 | 1 |" in table and "IIb: fu / fv / u0 / v0 (gross)" in table
    # the table's RMS is the RMS of the recorded errors
    e = np.array([r["methods"]["IIb"]["error"] for r in recs if r["row"] == 0])
    s = next(x for x in res.summary if x["row"] == 0 and x["method"] == "IIb")
    np.testing.assert_allclose(s["rms"], np.sqrt(np.mean(e**2, axis=0)))

    # determinism: each trial's numbers follow from its seed alone, not from where it
    # sits in a chunk (the same compiled program, the tasks in reverse order)
    tasks = [(r, row, t) for r, row in enumerate(cfg.rows()) for t in range(cfg.trials)]
    program = TrialProgram(cfg)  # one program for the re-runs (the seed is not part of it)
    again = run_batch(cfg, tasks[::-1], program)[::-1]
    for a, b in zip(again, recs):
        assert a["seed"] == b["seed"]
        for m in ("IIb", "bundle-unit"):
            np.testing.assert_allclose(a["methods"][m]["estimate"], b["methods"][m]["estimate"], rtol=1e-10)
    other = run_batch(cfg.replace(seed=4), tasks, program)
    assert other[3]["methods"]["IIb"]["estimate"] != recs[3]["methods"]["IIb"]["estimate"]


def test_a_trial_run_alone_equals_the_same_trial_in_a_chunk():
    """run_trial (a chunk of one: another compiled program) gives the numbers the
    trial had in a chunk of four, to round-off."""
    cfg = parse_config(__import__("tomllib").loads(TINY))
    tasks = [(r, row, t) for r, row in enumerate(cfg.rows()) for t in range(cfg.trials)]
    recs = run_batch(cfg, tasks)
    again = run_trial(cfg, 1, cfg.rows()[1], 1)
    assert again["seed"] == recs[3]["seed"]
    for m in ("IIb", "bundle-unit"):
        np.testing.assert_allclose(again["methods"][m]["estimate"], recs[3]["methods"][m]["estimate"], rtol=1e-10)


def test_cli_experiment(tmp_path, capsys):
    # TINY's methods and trial count: the compiled program of the run above
    cfg = tmp_path / "one.toml"
    cfg.write_text(TINY.replace('name = "tiny"', 'name = "one"'))
    assert main(["experiment", str(cfg), "--out", str(tmp_path / "runs"), "--trials", "2", "--workers", "1",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "| 700 | 0.5 |" in out and "| 700 | 1 |" in out and "wrote" in out
    assert len(list((tmp_path / "runs" / "one").iterdir())) == 1


def test_cli_experiment_bad_input(tmp_path, capsys):
    assert main(["experiment", str(tmp_path / "nope.toml")]) == 2
    assert "no such config" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[noise]\nsigma = -2\n")
    assert main(["experiment", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "noise.sigma" in err and "Traceback" not in err


def test_speed_counts_stablehlo_operations_with_calls_inlined():
    """experiments/speed.py's size of a compiled program (--calibrate-program; the
    operation counts in docs/results.md): a jitted function called twice counts twice,
    as in the same program with the function inlined by Python."""
    import importlib.util

    import jax
    import jax.numpy as jnp

    path = Path(__file__).resolve().parents[1] / "experiments" / "speed.py"
    spec = importlib.util.spec_from_file_location("sorjax_speed_benchmark", path)
    speed = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(speed)
    inner = jax.jit(lambda x: jnp.sin(x) * 2.0)  # lowered as one private function, called twice
    called = jax.jit(lambda x: inner(x) + inner(x + 1.0)).lower(1.0).as_text()
    assert called.count("call @") == 2
    inlined = jax.jit(lambda x: jnp.sin(x) * 2.0 + jnp.sin(x + 1.0) * 2.0).lower(1.0).as_text()
    assert speed.stablehlo_ops(called) == speed.stablehlo_ops(inlined) == 9  # sin, 2, *; twice; 1, +, +


def test_segmentation_ceiling_cuts_by_the_true_axis():
    """experiments/segmentation_ceiling.py's edge-only cut: its frame makes the harmonic
    homology the reflection x' -> -x' (checked on the exact outline), and on a render
    with a plain background it recovers the objects (two bottles) from their edges and
    true axes.  (Glossy objects whose highlight lies along the axis, as in
    random_table_scene(2), are cut along the highlight's edges: a limit of the cut,
    measured by the experiment.)"""
    import importlib.util

    from sorjax import render
    from sorjax._homology import transfer

    path = Path(__file__).resolve().parents[1] / "experiments" / "segmentation_ceiling.py"
    spec = importlib.util.spec_from_file_location("sorjax_segmentation_ceiling", path)
    ceil = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ceil)
    r = render.random_table_scene(9, n_objects=2)
    for ob in (o for o in r.objects if not o.occluded):
        t = ob.truth
        T = ceil.reflection_frame(t.l_s, t.v_x, t.outline.mean(0))
        p = t.outline[::25]
        q = np.asarray(transfer(t.W, p))

        def frame(x):
            h = np.column_stack([x, np.ones(len(x))]) @ T.T
            return h[:, :2] / h[:, 2:]

        a, b = frame(p), frame(q)
        np.testing.assert_allclose(b[:, 0], -a[:, 0], atol=1e-6 * np.abs(a).max())
        np.testing.assert_allclose(b[:, 1], a[:, 1], atol=1e-6 * np.abs(a).max())
        x0, y0, x1, y1 = ob.box
        g = 0.15 * max(x1 - x0, y1 - y0)
        region = ceil.axis_dp(r.image, t.l_s, t.v_x, (x0 - g, y0 - g, x1 + g, y1 + g))
        exact = ob.coverage >= 0.5
        assert region is not None and ceil._iou(region, exact) >= 0.95
