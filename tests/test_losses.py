"""sorjax.losses is pure JAX: every public function gives the same numbers eagerly,
under ``jax.jit`` and under ``jax.vmap`` (over views or trials), and its gradients
agree with central finite differences (lineax style: jit / vmap / grad)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import losses, scenes

N_POINTS, N_SAMPLES = 256, 40
TOL = dict(rtol=1e-10, atol=1e-10)

# One compiled program per shape, shared by the tests below.
_fit = jax.jit(lambda p, s: losses.calibrated_intrinsics(p, s, N_SAMPLES))
_fit_trials = jax.jit(jax.vmap(lambda p, s: losses.calibrated_intrinsics(p, s, N_SAMPLES)))


def _close(a, b, **tol):
    jax.tree.map(lambda x, y: np.testing.assert_allclose(np.asarray(x), np.asarray(y), **(tol or TOL)), a, b)


def _stack(trees):
    return jax.tree.map(lambda *x: jnp.stack(x), *trees)


@pytest.fixture(scope="module")
def scene():
    sc = scenes.two_spheres(f=700.0)
    outs = [scenes.paper_noise(o, 0.5, 7 + i) for i, o in enumerate(sc.outlines)]
    P = jnp.stack([sorjax.make_outline(o, N_POINTS).points for o in outs])
    fields = jax.jit(jax.vmap(losses.distance_field))(P)
    samples = jax.jit(jax.vmap(lambda f: losses.outline_samples(f, N_SAMPLES)))(fields)
    v = jnp.stack([jnp.asarray(view.v_x, jnp.float64) for view in sc.views])
    l = jnp.stack([jnp.asarray(view.l_s, jnp.float64) for view in sc.views])
    return sc, outs, P, fields, samples, v, l


@pytest.fixture(scope="module")
def calibration(scene):
    """At calibrate's default resolution (the compiled program the other modules use;
    another resolution is another program of about a minute to compile)."""
    _, outs, *_ = scene
    return sorjax.calibrate(outs, outline_error=0.0)


# ------------------------------------------------------------------ jit and vmap


def test_jit_vmap_fields(scene):
    _, _, P, fields, samples, _, _ = scene
    x = samples + 0.3  # off the curve
    cases = [
        (lambda p: losses.distance_field(p), (P,)),
        (lambda p: losses.distance_field(p, 2.0), (P,)),
        (lambda f: losses.outline_samples(f, N_SAMPLES), (fields,)),
        (lambda f: losses.sample_weights(f, N_SAMPLES), (fields,)),
        (losses.signed_distance, (fields, x[:, 0])),
        (losses.signed_distances, (fields, x)),
    ]
    for fn, args in cases:
        eager = [fn(*jax.tree.map(lambda a: a[j], args)) for j in range(P.shape[0])]
        _close(jax.jit(fn)(*jax.tree.map(lambda a: a[0], args)), eager[0])
        _close(jax.jit(jax.vmap(fn))(*args), _stack(eager))


def test_jit_vmap_homology(scene):
    _, _, P, fields, samples, v, l = scene
    l = l + jnp.array([0.0, 0.0, 1.0])  # not at the optimum: non-zero residuals
    w = jnp.ones(samples.shape[:2]).at[:, :3].set(0.0)
    cases = [
        (losses.homology_matrix, (v, l)),
        (lambda v, l, x: losses.transfer(losses.homology_matrix(v, l), x), (v, l, samples)),
        (losses.symmetry_residuals, (v, l, samples, fields)),
        (losses.symmetry_residuals, (v, l, samples, fields, w)),
    ]
    for fn, args in cases:
        eager = [fn(*jax.tree.map(lambda a: a[j], args)) for j in range(P.shape[0])]
        _close(jax.jit(fn)(*jax.tree.map(lambda a: a[0], args)), eager[0])
        _close(jax.jit(jax.vmap(fn))(*args), _stack(eager))


def test_jit_vmap_bundle_residuals(scene):
    sc, _, _, fields, samples, v, _ = scene
    k = jnp.array([sc.K[0, 0], sc.K[1, 1], sc.K[0, 2], sc.K[1, 2]], jnp.float64)
    trials = k * jnp.array([[1.0], [1.01], [0.98]])  # over trials of intrinsics
    eager = [losses.bundle_residuals(t, v, samples, fields) for t in trials]
    assert eager[0].shape == samples.shape[:2]
    _close(jax.jit(losses.bundle_residuals)(trials[0], v, samples, fields), eager[0])
    _close(jax.jit(jax.vmap(losses.bundle_residuals, in_axes=(0, None, None, None)))(trials, v, samples, fields),
           _stack(eager))


def test_jit_calibrated_intrinsics(scene, calibration):
    _, outs, *_ = scene
    P = jnp.stack([sorjax.make_outline(o).points for o in outs])  # the calibration's points and samples
    eager = losses.calibrated_intrinsics(P, calibration)  # the Calibration form
    np.testing.assert_allclose(np.asarray(eager), [calibration.fu, calibration.fv, calibration.u0, calibration.v0],
                               rtol=1e-6)
    _close(jax.jit(losses.calibrated_intrinsics)(P, losses.BundleStart.of(calibration)), eager)
    # at another resolution, started from the calibration: near it, the same under jit
    P = scene[2]
    coarse = losses.calibrated_intrinsics(P, calibration, N_SAMPLES)
    np.testing.assert_allclose(np.asarray(coarse), np.asarray(eager), rtol=0, atol=0.01 * 700.0)  # 1 % of f
    _close(_fit(P, losses.BundleStart.of(calibration)), coarse)


def test_vmap_calibrated_intrinsics_over_trials(scene, calibration):
    _, outs, *_ = scene
    P = jnp.stack([jnp.stack([sorjax.make_outline(scenes.paper_noise(o, 1.0, 100 * t + i), N_POINTS).points
                              for i, o in enumerate(outs)]) for t in range(3)])
    s = losses.BundleStart.of(calibration)
    starts = [losses.BundleStart(s.K * jnp.array([1.0 + 0.002 * t, 1.0 - 0.001 * t, 1.0])[:, None], s.l_s)
              for t in range(3)]
    batched = _fit_trials(P, _stack(starts))
    assert batched.shape == (3, 4)
    # a batched solve and a single one stop within the solver's tolerance of each other
    # (seen: 1.1e-10 relative), not bit for bit
    _close(batched, _stack([_fit(P[t], starts[t]) for t in range(3)]), rtol=1e-8, atol=1e-8)
    assert len({float(x) for x in batched[:, 1]}) == 3  # the trials differ


# ------------------------------------------------------------------------- grad


def _central(f, x, rel=1e-6):
    """Central differences, each coordinate stepped by ``rel`` times its own size
    (homogeneous vectors mix scales: v_x's third entry is ~4e-4, l_s's ~500)."""
    x = np.asarray(x, np.float64)
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        d = np.zeros_like(x)
        d[i] = h = rel * max(abs(x[i]), 1e-6)
        g[i] = (float(f(jnp.asarray(x + d))) - float(f(jnp.asarray(x - d)))) / (2 * h)
    return g


def test_grad_symmetry_residuals(scene):
    _, _, _, fields, samples, v, l = scene
    f0, x0 = jax.tree.map(lambda a: a[0], fields), samples[0]
    v0, l0 = v[0], l[0] + jnp.array([0.0, 0.0, 1.0])
    cost = jax.jit(lambda v, l: jnp.sum(losses.symmetry_residuals(v, l, x0, f0) ** 2))
    gv, gl = jax.grad(cost, argnums=(0, 1))(v0, l0)
    assert float(jnp.abs(gv).max()) > 0
    np.testing.assert_allclose(gv, _central(lambda v: cost(v, l0), v0),
                               rtol=1e-5, atol=1e-8 * float(jnp.abs(gv).max()))
    np.testing.assert_allclose(gl, _central(lambda l: cost(v0, l), l0),
                               rtol=1e-5, atol=1e-8 * float(jnp.abs(gl).max()))


def test_grad_bundle_residuals(scene):
    sc, _, _, fields, samples, v, _ = scene
    k0 = jnp.array([sc.K[0, 0] * 1.02, sc.K[1, 1] * 0.99, sc.K[0, 2] + 3.0, sc.K[1, 2] - 2.0], jnp.float64)
    cost = jax.jit(lambda k, v: jnp.sum(losses.bundle_residuals(k, v, samples, fields) ** 2))
    gk, gv = jax.grad(cost, argnums=(0, 1))(k0, v)
    np.testing.assert_allclose(gk, _central(lambda k: cost(k, v), k0), rtol=1e-5,
                               atol=1e-8 * float(jnp.abs(gk).max()))
    np.testing.assert_allclose(gv, _central(lambda w: cost(k0, w), v), rtol=1e-5,
                               atol=1e-8 * float(jnp.abs(gv).max()))
    # jacobian of the residual vector itself, one column
    J = jax.jit(jax.jacfwd(lambda k: losses.bundle_residuals(k, v, samples, fields)))(k0)
    h = 1e-3
    d = jnp.zeros(4).at[2].set(h)
    r = jax.jit(lambda k: losses.bundle_residuals(k, v, samples, fields))
    fd = (r(k0 + d) - r(k0 - d)) / (2 * h)
    np.testing.assert_allclose(J[..., 2], fd, rtol=1e-5, atol=1e-8 * float(jnp.abs(J[..., 2]).max()))


def test_grad_calibrated_intrinsics_wrt_points(scene, calibration):
    _, _, P, *_ = scene
    s = losses.BundleStart.of(calibration)
    g = jax.jit(jax.grad(lambda p: losses.calibrated_intrinsics(p, s, N_SAMPLES)[1]))(P)
    assert g.shape == P.shape and bool(jnp.all(jnp.isfinite(g)))
    h = 1e-4  # px, along the outline's normal at one point
    for view, i in [(0, 10), (1, 100), (2, 200)]:
        p = np.asarray(P[view])
        t = p[(i + 1) % len(p)] - p[i - 1]
        n = np.array([t[1], -t[0]]) / np.linalg.norm(t)
        d = jnp.zeros_like(P).at[view, i].set(n)
        fd = (float(_fit(P + h * d, s)[1]) - float(_fit(P - h * d, s)[1])) / (2 * h)
        np.testing.assert_allclose(float(jnp.sum(g * d)), fd, rtol=1e-3)
    # every point moved at once, along a random direction (seed 0; formerly a slow test
    # of tests/test_bundle.py at another resolution: the same programs here)
    d = jnp.asarray(np.random.default_rng(0).normal(size=P.shape))
    h = 1e-3
    fd = (float(_fit(P + h * d, s)[1]) - float(_fit(P - h * d, s)[1])) / (2 * h)
    np.testing.assert_allclose(float(jnp.sum(g * d)), fd, rtol=2e-3)
