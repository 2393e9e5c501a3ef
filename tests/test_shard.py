"""sorjax.core's trial sharding: a vmapped study over 2 (forced host) devices gives the
numbers of 1 device, with the trial axis sharded and an odd trial count padded."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

# 5 randomly perturbed circles (an odd count: padded to 6 on 2 devices), their fields
# and the signed distances of fixed probe points: sorjax.core._field.setup +
# sorjax.core._field.signed_distances, one trial per circle.
_STUDY = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp, numpy as np
    from sorjax import core
    from sorjax.core._field import setup, signed_distances

    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    circles = np.stack([
        (r * (1 + 0.02 * np.sin(3 * t + ph)))[:, None] * np.stack([np.cos(t), np.sin(t)], -1) + c
        for r, ph, c in zip(rng.uniform(50, 80, 5), rng.uniform(0, 6, 5), rng.normal(0, 5, (5, 2)))
    ])
    probes = jnp.asarray(rng.normal(0, 60, (16, 2)))

    def trial(points):
        field, samples, weights = setup(points, 20)
        return {"d": signed_distances(field, probes), "samples": samples, "w": weights}

    run = core.TrialSharder(trial)
    out = run(circles)
    again = run(circles[:4])  # an even count: no padding, outputs stay sharded
    one = core.sharded_vmap(trial, circles[:1])
    print(json.dumps({
        "n_devices": len(jax.devices()),
        "out_devices": len(out["d"].sharding.device_set),
        "even_shards": [list(s.data.shape) for s in again["d"].addressable_shards],
        "even_spec": str(again["d"].sharding.spec),
        "shape": list(out["d"].shape),
        "d": np.asarray(out["d"]).tolist(),
        "samples": np.asarray(out["samples"]).tolist(),
        "w": np.asarray(out["w"]).tolist(),
        "even_d": np.asarray(again["d"]).tolist(),
        "one_d": np.asarray(one["d"]).tolist(),
    }))
    """
)


def _run(n_devices: int) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    if n_devices > 1:
        flags.append(f"--xla_force_host_platform_device_count={n_devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    out = subprocess.run([sys.executable, "-c", _STUDY], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_trials_sharded_over_two_devices_equal_one_device():
    two, one = _run(2), _run(1)
    assert two["n_devices"] == 2 and one["n_devices"] == 1
    assert two["out_devices"] == 2  # the outputs live on both devices
    assert two["shape"] == [5, 16]  # the padding trial is dropped
    assert two["even_shards"] == [[2, 16], [2, 16]] and "trials" in two["even_spec"]
    for key in ("d", "samples", "w", "even_d", "one_d"):
        np.testing.assert_allclose(np.asarray(two[key]), np.asarray(one[key]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(two["even_d"]), np.asarray(two["d"])[:4], rtol=0, atol=1e-12)
    assert np.abs(np.asarray(one["d"])).max() > 1.0  # non-trivial numbers


def test_host_threads_split_gives_the_same_numbers():
    """On one CPU device the batch runs as equal parts side by side from host threads:
    every trial's numbers as one loop gives them, padding dropped, one executable."""
    import jax
    import jax.numpy as jnp

    from sorjax import core
    from sorjax.core._field import setup, signed_distances

    jax.config.update("jax_enable_x64", True)
    rng = np.random.default_rng(5)
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    circles = np.stack([(r * (1 + 0.03 * np.sin(2 * t + ph)))[:, None] * np.stack([np.cos(t), np.sin(t)], -1)
                        for r, ph in zip(rng.uniform(40, 90, 7), rng.uniform(0, 6, 7))])
    probes = jnp.asarray(rng.normal(0, 60, (9, 2)))

    def trial(points):
        field, _, _ = setup(points, 20)
        return signed_distances(field, probes)

    one = core.TrialSharder(trial, batch="map", threads=1)
    three = core.TrialSharder(trial, batch="map", threads=3)
    assert one.threads == 1 and three.threads == 3
    n, parts = three.split(circles)  # 7 trials: 3 parts of 3, the last padded
    assert n == 7 and [p[0].shape[0] for p in parts] == [3, 3, 3]
    a, b = np.asarray(one(circles)), np.asarray(three(circles))
    assert a.shape == b.shape == (7, 9)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(np.asarray(three(circles[:2])), a[:2])  # fewer trials than threads
    assert len(three._executables) == 2  # one per part shape
    assert np.abs(a).max() > 1.0
    for bad in (0, 1.5, "2", True):
        with pytest.raises(ValueError, match="threads must be a positive integer"):
            core.TrialSharder(trial, batch="map", threads=bad)
