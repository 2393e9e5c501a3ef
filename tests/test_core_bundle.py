"""The linear methods and the bundle as pure functions of masked, fixed-shape arrays
(sorjax.core._linear.linear_estimate, sorjax.core._bundle.bundle_seeds / fit_bundle /
bundle_estimate): exact on a noise-free scene, blind to masked views, the same under
jit(vmap) as one trial at a time, and at a stationary point of the cost.

Every bundle call here has V = 4 views of M = 1024 points, 100 samples (three views
and a fourth masked, as the shell pads): one compiled program (and one more for the
vmapped one)."""

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._bundle import (bundle_estimate, bundle_seeds)
from sorjax.core._model import (make_problem, residuals)
from sorjax.core._camera import transform_points
from sorjax.core._linear import LINEAR_METHODS, linear_estimate, linear_estimates
from sorjax.core import Options, joint_transform

F = 700.0
M = 1024
OPTIONS = Options()


@pytest.fixture(scope="module")
def scene():
    return scenes.two_spheres(f=F)


def _points(outlines):
    return np.stack([np.asarray(sorjax.make_outline(o, M).points) for o in outlines])


def _inputs(points, v, l, used, aspect):
    """Everything bundle_estimate takes, from pixel points and homologies."""
    T = joint_transform(points, used)
    pn = transform_points(T, jnp.asarray(points))
    ln = jnp.linalg.solve(T.T, jnp.asarray(l).T).T  # lines map by T^-T
    seeds, seed_ok = bundle_seeds(v, l, used, T, aspect)
    inl = jnp.ones((len(v), OPTIONS.n_samples))
    return pn, jnp.asarray(used), inl, ln, seeds, seed_ok, jnp.asarray(aspect, jnp.float64), T


def _exact(scene):
    v = np.stack([np.asarray(view.v_x) for view in scene.views])
    l = np.stack([np.asarray(view.l_s) for view in scene.views])
    return v, l


def _padded(points, v, l):
    """Three views and a masked 4th, a copy of view 0 (as the shell pads)."""
    return (np.concatenate([points, points[:1]]), np.concatenate([v, v[:1]]), np.concatenate([l, l[:1]]),
            np.array([True, True, True, False]))


def _garbage(rng, points, v, l):
    """A 4th view of junk: random points far away, random homology."""
    p4 = rng.normal(size=(1, M, 2)) * 300 + 5000.0
    return (np.concatenate([points, p4]), np.concatenate([v, rng.normal(size=(1, 3))]),
            np.concatenate([l, rng.normal(size=(1, 3))]), np.array([True, True, True, False]))


def test_linear_methods_exact_on_noise_free_homologies(scene):
    v, l = _exact(scene)
    used = np.ones(len(v), bool)
    T = joint_transform(_points(scene.outlines), used)
    for m in LINEAR_METHODS:
        K, omega, ok = linear_estimate(v, l, used, T, 1.0, method=m)
        assert bool(ok), m
        np.testing.assert_allclose(np.asarray(K), np.asarray(scene.K), rtol=1e-4, atol=1e-4 * F, err_msg=m)
        Ki = np.linalg.inv(np.asarray(K))
        np.testing.assert_allclose(np.asarray(omega), Ki.T @ Ki, rtol=1e-9, atol=1e-18)
    Ks, _, oks = linear_estimates(v, l, used, T, 1.0)
    assert Ks.shape == (3, 3, 3) and bool(jnp.all(oks))


def test_linear_methods_ignore_a_masked_view(scene):
    """A masked 4th view of garbage (NaN homology included) changes nothing."""
    rng = np.random.default_rng(0)
    v, l = _exact(scene)
    v = v + 1e-3 * rng.normal(size=v.shape)  # not exact: every digit must still agree
    pts = _points(scene.outlines)
    T3 = joint_transform(pts, np.ones(3, bool))
    pts4, v4, l4, used4 = _garbage(rng, pts, v, l)
    T4 = joint_transform(pts4, used4)
    np.testing.assert_allclose(np.asarray(T4), np.asarray(T3), rtol=1e-12)
    v4[3] = np.nan
    for m in LINEAR_METHODS:
        for a in (1.0, 1.3):
            K3, _, ok3 = linear_estimate(v, l, np.ones(3, bool), T3, a, method=m)
            K4, _, ok4 = linear_estimate(v4, l4, used4, T4, a, method=m)
            assert bool(ok3) == bool(ok4)
            np.testing.assert_allclose(np.asarray(K4), np.asarray(K3), rtol=1e-9, atol=1e-9 * F, err_msg=m)


def test_bundle_seeds_project_onto_a_known_aspect_and_fall_back(scene):
    v, l = _exact(scene)
    used = np.ones(3, bool)
    T = joint_transform(_points(scene.outlines), used)
    seeds, ok = bundle_seeds(v, l, used, T, 1.0)
    np.testing.assert_array_equal(np.asarray(ok), [True] * 3 + [False] * 3)
    np.testing.assert_allclose(np.asarray(seeds[:3, 0]), np.asarray(seeds[:3, 1]), rtol=1e-12)  # fu = a fv
    seeds, ok = bundle_seeds(v, l, used, T, jnp.nan)
    assert bool(jnp.all(ok[:3])) and not bool(jnp.any(ok[3:]))
    # one view only: no linear method works, the spread (a f, f, 0, 0), f = 2, 5, 12
    seeds, ok = bundle_seeds(v, l, np.array([True, False, False]), T, 2.0)
    np.testing.assert_array_equal(np.asarray(ok), [False] * 3 + [True] * 3)
    np.testing.assert_allclose(np.asarray(seeds[3:]), [[4.0, 2, 0, 0], [10.0, 5, 0, 0], [24.0, 12, 0, 0]])


@pytest.fixture(scope="module")
def exact_bundle(scene):
    """The bundle on the noise-free outlines (exact homologies as seeds), free and unit
    aspect, 3 views + a masked 4th: a copy of view 0, or garbage."""
    v, l = _exact(scene)
    pts = _points(scene.outlines)
    out = {}
    for name, aspect in (("free", np.nan), ("unit", 1.0)):
        out[name] = bundle_estimate(*_inputs(*_padded(pts, v, l), aspect), OPTIONS)
        pts4, v4, l4, used4 = _garbage(np.random.default_rng(1), pts, v, l)
        out[name + "4"] = bundle_estimate(*_inputs(pts4, v4, l4, used4, aspect), OPTIONS)
    return out


@pytest.mark.parametrize("name", ["free", "unit"])
def test_bundle_exact_on_noise_free_outlines(scene, exact_bundle, name):
    out = exact_bundle[name]
    assert bool(out.ok)
    np.testing.assert_allclose(np.asarray(out.K), np.asarray(scene.K), rtol=1e-4, atol=1e-4 * F)
    assert float(out.cost) / float(out.n) < 1e-4**2  # RMS residual below 1e-4 px
    assert float(out.evidence) > 0 and np.all(np.isfinite(np.asarray(out.cov)))
    if name == "unit":
        assert float(out.K[0, 0]) == pytest.approx(float(out.K[1, 1]), rel=1e-12)


@pytest.mark.parametrize("name", ["free", "unit"])
def test_bundle_ignores_a_masked_view(exact_bundle, name):
    """What a masked 4th view holds (garbage, or a copy of a used view) changes nothing:
    the estimate, its covariance, the degrees of freedom (s2), the evidence and the
    per-view diagnostics of the used views."""
    a, b = exact_bundle[name], exact_bundle[name + "4"]
    np.testing.assert_allclose(np.asarray(b.K), np.asarray(a.K), rtol=1e-9, atol=1e-9 * F)
    for field in ("cost", "s2", "n", "evidence"):
        np.testing.assert_allclose(float(getattr(b, field)), float(getattr(a, field)), rtol=1e-6, atol=1e-14,
                                   err_msg=field)
    np.testing.assert_allclose(np.asarray(b.cov), np.asarray(a.cov), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(b.v_x[:3]), np.asarray(a.v_x[:3]), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(b.l_s[:3]), np.asarray(a.l_s[:3]), rtol=1e-9, atol=1e-12)
    assert np.all(np.isnan(np.asarray(b.v_x[3]))) and np.all(np.isnan(np.asarray(a.v_x[3])))
    assert np.isnan(float(b.view_rms[3]))
    assert int(b.steps) == int(a.steps) and bool(b.ok)


def _noisy_homologies(v, l, T, rng):
    """Exact homologies perturbed as a per-view fit's are: in normalised coordinates,
    the vertex by 1e-2 of its norm, the axis (a^2 + b^2 = 1) by 1e-3."""
    T = np.asarray(T)
    vn = v @ T.T
    vn = vn / np.linalg.norm(vn, axis=1, keepdims=True) + 1e-2 * rng.normal(size=v.shape)
    ln = np.linalg.solve(T.T, l.T).T
    ln = ln / np.linalg.norm(ln[:, :2], axis=1, keepdims=True) + 1e-3 * rng.normal(size=l.shape)
    return np.linalg.solve(T, vn.T).T, ln @ T


@pytest.fixture(scope="module")
def noisy_trials(scene):
    """8 trials: the paper's noise (1 px) on the outlines, homology seeds a little off."""
    v, l = _exact(scene)
    trials = []
    for t in range(8):
        rng = np.random.default_rng(500 + t)
        pts = _points([scenes.paper_noise(o, 1.0, rng) for o in scene.outlines])
        vt, lt = _noisy_homologies(v, l, joint_transform(pts, np.ones(3, bool)), rng)
        trials.append(_inputs(*_padded(pts, vt, lt), np.nan if t % 2 else 1.0))
    return trials


@pytest.fixture(scope="module")
def single_outs(noisy_trials):
    return [bundle_estimate(*args, OPTIONS) for args in noisy_trials]


def test_bundle_jit_vmap_equals_single_calls(noisy_trials, single_outs):
    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *noisy_trials)
    batched = jax.jit(jax.vmap(bundle_estimate, in_axes=(0,) * 8 + (None,)))(*stacked, OPTIONS)
    for t, out in enumerate(single_outs):
        np.testing.assert_allclose(np.asarray(batched.K[t]), np.asarray(out.K), rtol=1e-9, atol=1e-9 * F)
        assert bool(batched.ok[t]) == bool(out.ok)
        np.testing.assert_allclose(float(batched.cost[t]), float(out.cost), rtol=1e-9)
        np.testing.assert_allclose(np.asarray(batched.cov[t]), np.asarray(out.cov), rtol=1e-6)


def test_fit_bundle_reaches_a_stationary_point_near_the_truth(scene, noisy_trials, single_outs):
    """Independent of how the solve got there: the cost's gradient vanishes at
    fit_bundle's optimum (``BundleOut.y``; relative to its size a few percent off), and
    K is near the truth.  (Against
    the host-loop implementation this replaced, on 8 trials at f = 700 / 1400 px, both
    aspect models, K agreed to 1e-13 relative with the same step counts.)"""
    for args, out in zip(noisy_trials, single_outs):
        pn, used, inl, ln, seeds, seed_ok, aspect, T = args
        problem = make_problem(pn, OPTIONS.n_samples, aspect, inl, used)
        y = out.y
        assert bool(out.ok) and int(out.steps) > 0
        flat, unravel = jax.flatten_util.ravel_pytree(y)

        def cost(f, problem):
            return jnp.sum(residuals(unravel(f), problem) ** 2)

        gradient = jax.jit(jax.grad(cost))
        g_opt = jnp.linalg.norm(gradient(flat, problem))
        off = flat.at[1].add(0.03)  # fv 3 % off
        g_off = jnp.linalg.norm(gradient(off, problem))
        assert float(g_opt) < 1e-6 * float(g_off), (float(g_opt), float(g_off))
        K = np.asarray(out.K)
        assert abs(K[1, 1] / F - 1) < 0.05 and abs(K[0, 0] / F - 1) < 0.05
        assert np.all(np.abs(K[:2, 2] - np.asarray(scene.K)[:2, 2]) < 0.05 * F)


def test_bundle_estimate_differentiates_through_the_solve(noisy_trials, single_outs):
    """jax.grad of the bundle's focal length with respect to the outline points (the
    optimum differentiated implicitly; the solvers' loops stay out of the gradient)
    matches central differences, and the forward value is untouched."""
    args = noisy_trials[1]

    def fv(pn):
        return bundle_estimate(pn, *args[1:], OPTIONS).K[1, 1]

    assert float(fv(args[0])) == float(single_outs[1].K[1, 1])
    g = jax.grad(fv)(args[0])
    d = jnp.asarray(np.random.default_rng(0).normal(size=args[0].shape))
    h = 1e-5
    fd = (fv(args[0] + h * d) - fv(args[0] - h * d)) / (2 * h)
    np.testing.assert_allclose(float(jnp.sum(g * d)), float(fd), rtol=1e-3)
