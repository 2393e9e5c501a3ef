"""Per-view harmonic homology fit (eq. 20) against ground truth."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._camera import angle_between_planes, angle_between_rays
from sorjax._homology import homology_matrix, symmetry_residuals, transfer
from sorjax.losses import distance_field, outline_samples, sample_weights


@pytest.fixture(scope="module")
def spheres():
    return scenes.two_spheres(f=700.0)


def test_homology_matrix_is_a_harmonic_homology():
    rng = np.random.default_rng(0)
    v, l = jnp.asarray(rng.normal(size=3)), jnp.asarray(rng.normal(size=3))
    W = homology_matrix(v, l)
    np.testing.assert_allclose(W @ W, np.eye(3), atol=1e-12)  # involution
    p = jnp.cross(l, jnp.asarray(rng.normal(size=3)))  # a point of l
    np.testing.assert_allclose(np.cross(W @ p, p), 0, atol=1e-12)  # fixed
    np.testing.assert_allclose(np.cross(W @ v, v), 0, atol=1e-12)  # vertex fixed
    x = jnp.asarray(rng.normal(size=3))
    assert abs(float(jnp.linalg.det(jnp.stack([v, x, W @ x])))) < 1e-10  # v, x, Wx collinear
    np.testing.assert_allclose(np.linalg.eigvalsh((W + W.T) / 2).size, 3)
    assert np.isclose(np.linalg.det(np.asarray(W)), -1.0)


def test_noise_free_fit_matches_truth(spheres):
    for view in spheres.views:
        h = sorjax.fit_homology(view.outline)
        assert bool(h.converged)
        assert float(h.rms) < 1e-5
        assert float(angle_between_planes(spheres.K, h.l_s, view.l_s)) < 1e-3
        assert float(angle_between_rays(spheres.K, h.v_x, view.v_x)) < 1e-2
        np.testing.assert_allclose(float(jnp.hypot(h.l_s[0], h.l_s[1])), 1.0, rtol=1e-12)


@pytest.mark.parametrize("seed", [1, 7])
def test_random_sor_views_any_roll_and_lying(seed):
    sc = scenes.random_sor_scene(seed, n_views=2)
    for view in sc.views:
        h = sorjax.fit_homology(view.outline)
        assert float(angle_between_planes(sc.K, h.l_s, view.l_s)) < 1e-3
        assert float(angle_between_rays(sc.K, h.v_x, view.v_x)) < 1e-2


def test_start_point_and_direction_invariance(spheres):
    o = spheres.views[1].outline
    ref = sorjax.fit_homology(o)
    for other in (np.roll(o, 137, axis=0), o[::-1]):
        h = sorjax.fit_homology(other)
        assert float(angle_between_planes(spheres.K, h.l_s, ref.l_s)) < 1e-4
        assert float(angle_between_rays(spheres.K, h.v_x, ref.v_x)) < 1e-3


def test_noisy_fit_stays_close(spheres):
    view = spheres.views[0]
    noisy = scenes.paper_noise(view.outline, 1.0, 3)
    h = sorjax.fit_homology(noisy)
    assert 0.05 < float(h.rms) < 1.0  # the noise shows in the residual
    assert float(angle_between_planes(spheres.K, h.l_s, view.l_s)) < 0.5
    # and so does its correlation length (Gaussian smoothing of 2 px by construction;
    # 4 px or more for the same noise smoothed by 6 px)
    assert 1.0 <= float(h.noise_ell) <= 3.5
    smoother = sorjax.fit_homology(scenes.paper_noise(view.outline, 1.0, 3, smooth_px=6.0))
    assert float(smoother.noise_ell) >= 4.0


def test_residuals_jit_vmap_and_gradient(spheres):
    """The eq.-20 residuals: jit == eager, vmap over views == loop, grad == FD."""
    pts = jnp.stack([sorjax.make_outline(v.outline, 256).points for v in spheres.views])
    fields = jax.jit(jax.vmap(distance_field))(pts)
    samples = jax.jit(jax.vmap(lambda f: outline_samples(f, 50)))(fields)
    weights = jax.jit(jax.vmap(lambda f: sample_weights(f, 50)))(fields)
    vs = jnp.stack([jnp.asarray(v.v_x) for v in spheres.views])
    ls = jnp.stack([jnp.asarray(v.l_s) for v in spheres.views])
    batched = jax.jit(jax.vmap(symmetry_residuals))(vs, ls, samples, fields, weights)
    for i in range(len(spheres.views)):
        f_i = jax.tree_util.tree_map(lambda a: a[i], fields)
        eager = symmetry_residuals(vs[i], ls[i], samples[i], f_i, weights[i])
        np.testing.assert_allclose(np.asarray(batched[i]), np.asarray(eager), rtol=1e-10, atol=1e-10)
        assert float(jnp.max(jnp.abs(eager))) < 1e-2  # truth is (nearly) a zero of eq. 20
    f0 = jax.tree_util.tree_map(lambda a: a[0], fields)
    l_off = ls[0] + jnp.array([0.0, 0.0, 2.0])  # move the axis 2 px: residuals grow

    @jax.jit
    def cost(v):
        return jnp.sum(symmetry_residuals(v, l_off, samples[0], f0) ** 2)

    g = jax.jit(jax.grad(cost))(vs[0])
    d = jnp.asarray([0.3, -0.2, 0.1]) * jnp.abs(vs[0]).max()
    h = 1e-7
    fd = (cost(vs[0] + h * d) - cost(vs[0] - h * d)) / (2 * h)
    np.testing.assert_allclose(float(g @ d), float(fd), rtol=1e-5)


def test_transfer_maps_outline_onto_itself(spheres):
    view = spheres.views[2]
    x = jnp.asarray(view.outline[::40])
    y = np.asarray(transfer(jnp.asarray(view.W), x))
    d = np.min(np.linalg.norm(view.outline[None, :, :] - y[:, None, :], axis=-1), axis=1)
    assert d.max() < 0.3  # within the dense outline's spacing


def _with_handle(o, start, frac=0.12, height=8.0):
    """Add a smooth outward bump (a 'handle', no mirror image) over ``frac`` of the outline."""
    o = np.asarray(o, float)
    t = (np.arange(len(o)) / len(o) - start) % 1.0
    bump = np.sin(np.pi * np.minimum(t, frac) / frac) ** 2 * (t < frac) * height
    tan = np.roll(o, -1, 0) - np.roll(o, 1, 0)
    nrm = np.stack([tan[:, 1], -tan[:, 0]], 1) / np.linalg.norm(tan, axis=1, keepdims=True)
    out = o + bump[:, None] * nrm
    return out if abs(sorjax_area(out)) > abs(sorjax_area(o)) else o - bump[:, None] * nrm


def sorjax_area(p):
    from sorjax._outline import signed_area

    return float(signed_area(p))


@pytest.fixture(scope="module")
def vase_with_handle():
    K = scenes.intrinsics(800.0)
    sc = scenes.sor_scene(scenes.vase(), K, [scenes.look_at((0.8, -0.5, -1.6), (0.0, 0.0, 0.0), roll=0.3)])
    return sc, _with_handle(sc.outlines[0], 0.15)


def test_robust_fit_trims_a_handle(vase_with_handle):
    sc, out = vase_with_handle
    K, view = sc.K, sc.views[0]
    plain = sorjax.fit_homology(out, robust=False)
    robust = sorjax.fit_homology(out)
    err = lambda h: float(angle_between_planes(K, h.l_s, view.l_s))  # noqa: E731
    assert plain.trimmed == 0.0 and err(plain) > 0.1  # the handle drags the plain fit
    assert err(robust) < 0.02 and float(robust.rms) < 0.3 < float(plain.rms)
    assert 0.05 < robust.trimmed < 0.4  # the handle and its mirror image
    r = np.asarray(robust.inliers)
    assert r.shape == (100,) and r.dtype == bool


def test_robust_fit_leaves_noisy_outlines_alone(spheres):
    o = scenes.paper_noise(spheres.outlines[0], 1.0, np.random.default_rng(5))
    a, b = sorjax.fit_homology(o), sorjax.fit_homology(o, robust=False)
    assert a.trimmed == 0.0
    np.testing.assert_allclose(np.asarray(a.l_s), np.asarray(b.l_s), atol=1e-12)


def test_calibrate_reports_trimmed_views(vase_with_handle):
    sc, out = vase_with_handle
    with pytest.warns(UserWarning, match="no mirror image"):
        cal = sorjax.calibrate([out, out + np.array([40.0, 10.0])], method="IIb")
    assert any("no mirror image" in n for n in cal.notes)
