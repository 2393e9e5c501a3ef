"""The bundle with radial distortion (sorjax.core._distorted.bundle_estimate_distorted) on exact
distorted scenes (sorjax.scenes ... distortion=(k1, k2)): K and k recovered, the
evidence for distortion, the distortion-free path untouched.

Three views of M = 1024 points, 100 samples, as tests/test_core_bundle.py; the "k1"
program is compiled once (about a minute here), the "k1k2" one and its gradient once
each."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._model import (BundleProblem, make_problem, n_params, residuals)
from sorjax.core._distorted import (bundle_estimate_distorted, distortion_gate)
from sorjax.core._bundle import bundle_seeds
from sorjax.core._camera import transform_points
from sorjax.core import Options, joint_transform

F = 700.0
M = 1024
OPTIONS = Options()


def _inputs(scene):
    """bundle_estimate's arguments for a scene, seeded by its exact (pinhole) homologies."""
    pts = np.stack([np.asarray(sorjax.make_outline(o, M).points) for o in scene.outlines])
    v = np.stack([vw.v_x for vw in scene.views])
    l = np.stack([vw.l_s for vw in scene.views])
    used = np.ones(len(v), bool)
    T = joint_transform(pts, used)
    pn = transform_points(T, jnp.asarray(pts))
    ln = jnp.linalg.solve(T.T, jnp.asarray(l).T).T
    seeds, seed_ok = bundle_seeds(v, l, used, T, jnp.nan)
    return pn, jnp.asarray(used), jnp.ones((len(v), OPTIONS.n_samples)), ln, seeds, seed_ok, jnp.asarray(jnp.nan), T


@pytest.fixture(scope="module")
def distorted():
    sc = scenes.two_spheres(f=F, distortion=(-0.2, 0.0))
    return sc, bundle_estimate_distorted(*_inputs(sc), OPTIONS, distortion="k1")


def test_exact_on_a_noise_free_distorted_scene(distorted):
    sc, out = distorted
    assert bool(out.ok) and bool(out.fit.ok) and bool(out.free.ok)
    np.testing.assert_allclose(np.asarray(out.fit.K), sc.K, atol=1e-3)  # px, 1.4e-6 of f
    assert abs(float(out.k[0]) + 0.2) < 1e-6
    assert out.cov.shape == (5, 5) and out.fit.cov.shape == (4, 4) and out.k_std.shape == (1,)
    np.testing.assert_array_equal(np.asarray(out.fit.cov), np.asarray(out.cov[:4, :4]))
    assert float(out.fit.cost) < 1e-8
    # the distortion-free bundle is far off (distortion mimics weak perspective) and
    # fits worse: the evidence for distortion
    assert abs(float(out.free.K[1, 1]) - F) > 0.2 * F
    assert float(out.delta) == pytest.approx(float(out.free.cost - out.fit.cost))
    assert float(out.delta) > 1e3 * float(out.fit.cost)
    assert float(out.fit.evidence) == pytest.approx(float(out.free.evidence + out.delta), rel=1e-9)
    # residuals vanish at the truth in the normalised frame
    args = _inputs(sc)
    base = make_problem(args[0], OPTIONS.n_samples, None, args[2], args[1])
    prob = BundleProblem(base.fields, base.samples, base.weights, base.aspect, 1)
    assert float(n_params(out.fit.y, prob)) == 4 + 1 + 2 * 3
    assert float(jnp.max(jnp.abs(residuals(out.fit.y, prob)))) < 1e-7


def test_no_distortion_gives_zero_k_and_no_evidence(distorted):
    sc = scenes.two_spheres(f=F)
    out = bundle_estimate_distorted(*_inputs(sc), OPTIONS, distortion="k1")
    assert bool(out.ok)
    assert abs(float(out.k[0])) < 1e-6
    np.testing.assert_allclose(np.asarray(out.fit.K), sc.K, atol=1e-3)
    assert abs(float(out.delta)) < 1e-8
    ok, g, z = distortion_gate(out.delta, out.fit.n, jnp.sqrt(out.fit.s2), Options(outline_error_px=0.1))
    assert not bool(ok)


def test_gate_follows_noise_and_outline_error():
    n, s = 300.0, 0.2
    ok, g, z = distortion_gate(jnp.asarray(36.0 * s**2), n, s)  # z = 6, g = 0.069 px
    assert float(z) == pytest.approx(6.0) and float(g) == pytest.approx(np.sqrt(36 * s**2 / n))
    assert not bool(ok)  # below 3 x the declared 0.1 px outline error
    assert bool(distortion_gate(jnp.asarray(36.0 * s**2), n, s, Options(outline_error_px=0.0))[0])
    assert not bool(distortion_gate(jnp.asarray(4.0 * s**2), n, s, Options(outline_error_px=0.0))[0])  # z = 2
    assert bool(distortion_gate(jnp.asarray(300.0), n, s)[0])  # 1 px per sample


def test_unknown_model_refused():
    with pytest.raises(ValueError, match="k1"):
        bundle_estimate_distorted(*_inputs(scenes.two_spheres(f=F, n_views=2)), OPTIONS, distortion="k3")


def test_k1k2_exact_and_differentiable():
    """Two compiled programs: the estimate (the exact fit and the finite differences
    below) and its implicit gradient."""
    sc = scenes.two_spheres(f=F, n_views=4, distortion=(-0.25, 0.1))
    args = _inputs(sc)
    estimate = jax.jit(lambda p: bundle_estimate_distorted(p, *args[1:], OPTIONS, distortion="k1k2"))
    out = estimate(args[0])
    assert bool(out.ok)
    np.testing.assert_allclose(np.asarray(out.fit.K), sc.K, atol=2e-3)
    np.testing.assert_allclose(np.asarray(out.k), [-0.25, 0.1], atol=1e-5)
    assert out.cov.shape == (6, 6)
    # implicit gradient of k1 in the outline points against central differences, at
    # outlines off the exact data: at the exact outlines k1(t) has a kink (one-sided
    # differences 0.069 and 0.005 at h = 1e-3, the implicit derivative 0.039), off
    # them it is smooth but curved, so the differences are extrapolated in h
    # (Richardson: C(h) = g + d h^2; 0.0531327 at 1e-3, 0.0539252 at 3e-3 -> 0.053034
    # against the implicit 0.053038)
    pn = args[0] + jnp.asarray(np.random.default_rng(1).normal(size=args[0].shape)) * 1e-4
    direction = jnp.asarray(np.random.default_rng(0).normal(size=pn.shape)) * 1e-3

    g = float(jax.jit(jax.grad(
        lambda t: bundle_estimate_distorted(pn + t * direction, *args[1:], OPTIONS, distortion="k1k2").k[0]))(0.0))

    def central(h):
        return (float(estimate(pn + h * direction).k[0]) - float(estimate(pn - h * direction).k[0])) / (2 * h)

    c1, c3 = central(1e-3), central(3e-3)
    num = c1 - (c3 - c1) / 8.0  # d h^2 from the two, taken off C(1e-3)
    assert abs(g - num) < 1e-3 * max(abs(num), 1e-3), (g, c1, c3, num)
