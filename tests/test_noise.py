"""The outline noise model's moment matching (sorjax.core._noise) against the dense formula."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax.core import _noise as nz


def _dense_moments(geo, J, ell_min, ell_max):
    """The moments written out densely: the full projector Q, every grid value's S(ell)
    built whole (unit_blocks) and contracted with the projected masks: (ells, m)."""
    V, N = geo.a.shape
    Uf, s, _ = np.linalg.svd(np.asarray(J), full_matrices=False)
    Uf = Uf * (s > 1e-10 * s.max())[None, :]
    U = Uf.reshape(V, N, -1)
    # the full projector Q = I - U U^T, its diagonal blocks applied to block-diagonal P
    Q = np.eye(V * N) - Uf @ Uf.T

    def projected(P):
        full = np.zeros((V * N, V * N))
        for v in range(V):
            full[v * N:(v + 1) * N, v * N:(v + 1) * N] = P[v]
        QPQ = Q @ full @ Q
        return np.stack([QPQ[v * N:(v + 1) * N, v * N:(v + 1) * N] for v in range(V)])

    A = [projected(np.broadcast_to(np.eye(N), (V, N, N))), projected(np.asarray(geo.near)),
         projected(np.asarray(geo.mirror))]
    ells = np.geomspace(ell_min, ell_max, nz.N_ELL)
    # (N_ELL, V, 3): each view's moments
    return ells, np.array([[np.sum(a * np.asarray(nz.unit_blocks(geo, ell)), axis=(1, 2)) for a in A]
                           for ell in ells]).transpose(0, 2, 1)


def _dense_estimate(geo, r, J, ell_min, ell_max, floor=None, floor_ell=None):
    """The module's moment matching on the dense moments, written out view by view:
    ``(ell (V,), sigma_n^2)``.  A view whose floor binds and whose floor's length is
    known takes the grid value nearest that length, and leaves the matching."""
    ells, m = _dense_moments(geo, J, ell_min, ell_max)
    r = np.asarray(r)
    V = r.shape[0]
    rss = np.sum(r**2, axis=1)
    floor = np.zeros(V) if floor is None else np.asarray(floor)
    fell = np.full(V, np.nan) if floor_ell is None else np.asarray(floor_ell)
    known = np.array([floor[v] > rss[v] and fell[v] > 0 for v in range(V)])
    near = np.einsum("vn,vnm,vm->v", r, geo.near, r)
    mirror = np.einsum("vn,vnm,vm->v", r, geo.mirror, r)
    emp = np.array([near[~known].sum(), mirror[~known].sum()]) / max(rss[~known].sum(), 1e-300)
    mu = m[:, ~known].sum(axis=1)
    k = np.argmin(np.sum((mu[:, 1:] / np.maximum(mu[:, :1], 1e-300) - emp) ** 2, axis=1))
    kv = [int(np.argmin(np.abs(np.log(ells / fell[v])))) if known[v] else k for v in range(V)]
    return ells[kv], np.sum(np.maximum(rss, floor)) / sum(m[kv[v], v, 0] for v in range(V))


def _geometry(rng, V, N=100, M=2048, spacing=1.3):
    a = rng.normal(size=(V, N))
    w = (rng.random((V, N)) > 0.1).astype(float)
    feet = (np.arange(N) * M / N + rng.normal(size=(V, N)) * 300) % M
    geo = nz.noise_geometry(jnp.asarray(a), jnp.asarray(w), jnp.asarray(feet), jnp.full(V, spacing), M)
    return geo, jnp.asarray(rng.normal(size=(V * N, 4 + 2 * V))), jnp.asarray(rng.normal(size=(V, N)) * 0.01)


@pytest.mark.parametrize("V", [1, 3])
def test_noise_moments_match_the_dense_formula(V):
    rng = np.random.default_rng(10 + V)
    for k in range(2):
        geo, J, _ = _geometry(rng, V, spacing=0.7 + 2 * k)
        ells, searched, m = jax.jit(nz.noise_moments)(geo, J, 0.25, 32.0)
        ells_d, m_d = _dense_moments(geo, J, 0.25, 32.0)
        np.testing.assert_allclose(ells, ells_d, rtol=1e-14)
        # every grid value's moments, small ones included (relative to the largest)
        np.testing.assert_allclose(m, m_d, rtol=1e-9, atol=1e-11 * np.max(np.abs(m_d)))


@pytest.mark.parametrize("V", [1, 3])
def test_estimate_noise_matches_the_dense_moments(V):
    rng = np.random.default_rng(V)
    est = jax.jit(nz.estimate_noise)
    for k in range(3):
        geo, J, r = _geometry(rng, V, spacing=0.7 + k)
        # residuals with correlation: the noise smoothed along the outline (moments off 0)
        r = jnp.asarray(np.apply_along_axis(lambda x: np.convolve(np.r_[x[-3:], x, x[:3]], np.ones(4) / 4, "same")
                                            [3:-3], 1, np.asarray(r)))
        ell, level = est(geo, r, J, 0.25, 32.0)
        ell_d, level_d = _dense_estimate(geo, r, J, 0.25, 32.0)
        assert ell.shape == (V,) and np.all(ell == ell[0])  # one length shared by every view
        np.testing.assert_allclose(ell, ell_d, rtol=1e-12)
        assert float(level) == pytest.approx(level_d, rel=1e-9)


def test_a_binding_floor_with_its_own_length_sets_that_views_length():
    """A view whose floor binds and carries a correlation length takes it (the nearest
    grid value) and leaves the matching; the level counts its floor at that length."""
    rng = np.random.default_rng(3)
    V = 3
    geo, J, r = _geometry(rng, V, spacing=1.1)
    r = jnp.asarray(np.apply_along_axis(lambda x: np.convolve(np.r_[x[-3:], x, x[:3]], np.ones(4) / 4, "same")
                                        [3:-3], 1, np.asarray(r)))
    rss = np.sum(np.asarray(r) ** 2, axis=1)
    est = jax.jit(nz.estimate_noise)
    ell0, level0 = est(geo, r, J, 0.25, 32.0)
    # view 1 bound (floor 30x its rss) with a known length; view 2 bound, length unknown;
    # view 0 not bound though its length is given
    floor = jnp.asarray([0.5 * rss[0], 30.0 * rss[1], 10.0 * rss[2]])
    fell = jnp.asarray([5.0, 1.7, np.nan])
    ell, level = est(geo, r, J, 0.25, 32.0, floor, fell)
    ell_d, level_d = _dense_estimate(geo, r, J, 0.25, 32.0, floor, fell)
    np.testing.assert_allclose(ell, ell_d, rtol=1e-12)
    assert float(level) == pytest.approx(level_d, rel=1e-9)
    assert float(ell[1]) == pytest.approx(1.7, rel=0.1) and float(ell[0]) == float(ell[2])
    # by transformation: vmap over floors equals one call each; the level's gradient in
    # the residuals matches central finite differences (view 1 held at its floor)
    floors = jnp.stack([floor, jnp.zeros(V)])
    ell_b, level_b = jax.jit(jax.vmap(lambda f: nz.estimate_noise(geo, r, J, 0.25, 32.0, f, fell)))(floors)
    for k in range(2):
        e_k, l_k = nz.estimate_noise(geo, r, J, 0.25, 32.0, floors[k], fell)
        np.testing.assert_array_equal(ell_b[k], e_k)
        assert float(level_b[k]) == pytest.approx(float(l_k), rel=1e-12)
    lev = lambda r_: nz.estimate_noise(geo, r_, J, 0.25, 32.0, floor, fell)[1]  # noqa: E731
    g = jax.grad(lev)(r)
    assert np.all(np.isfinite(np.asarray(g))) and float(jnp.max(jnp.abs(g[1]))) == 0.0
    d = jnp.asarray(rng.normal(size=r.shape)) * 1e-3
    fd = (float(lev(r + d)) - float(lev(r - d))) / 2.0
    assert float(jnp.sum(g * d)) == pytest.approx(fd, rel=1e-5)
    # no floor at all: as without the arguments; floors that never bind: the same
    for f, e in ((None, None), (jnp.zeros(V), fell), (0.1 * jnp.asarray(rss), jnp.full(V, 2.0))):
        ell2, level2 = est(geo, r, J, 0.25, 32.0, f, e)
        np.testing.assert_allclose(ell2, ell0, rtol=0)
        assert float(level2) == pytest.approx(float(level0), rel=1e-12)


def test_ell_grid_quarter_octaves_down_from_the_largest():
    ells, searched = nz.ell_grid(0.25, 32.0)
    np.testing.assert_allclose(ells, np.geomspace(0.25, 32.0, nz.N_ELL), rtol=1e-14)
    assert bool(jnp.all(searched))
    ells, searched = nz.ell_grid(1.0, 8.0)  # a narrower range: the grid's lower part left out
    assert float(ells[-1]) == 8.0 and float(jnp.min(ells[searched])) == pytest.approx(1.0)
    assert int(jnp.sum(searched)) == 13
    geo, J, r = _geometry(np.random.default_rng(0), 2)
    ell, _ = jax.jit(nz.estimate_noise, static_argnums=(3, 4))(geo, r, J, 1.0, 8.0)
    assert np.all((1.0 - 1e-12 <= ell) & (ell <= 8.0))
    # a floor's length outside the searched range is clipped into it
    ell, _ = nz.estimate_noise(geo, r, J, 1.0, 8.0, jnp.full(2, 1e3), jnp.asarray([0.3, 50.0]))
    np.testing.assert_allclose(ell, [1.0, 8.0], rtol=1e-12)


def test_estimate_noise_under_vmap_equals_single_calls():
    rng = np.random.default_rng(7)
    cases = [_geometry(rng, 2, spacing=0.8 + k) for k in range(3)]
    geo = jax.tree.map(lambda *x: jnp.stack(x), *[c[0] for c in cases])
    J, r = jnp.stack([c[1] for c in cases]), jnp.stack([c[2] for c in cases])
    ell_v, level_v = jax.jit(jax.vmap(lambda g, r, J: nz.estimate_noise(g, r, J, 0.25, 32.0)))(geo, r, J)
    for k, (g, Jk, rk) in enumerate(cases):
        ell, level = nz.estimate_noise(g, rk, Jk, 0.25, 32.0)
        np.testing.assert_array_equal(ell_v[k], ell)
        assert float(level_v[k]) == pytest.approx(float(level), rel=1e-12)


def test_jacobian_and_normal_sensitivity_in_one_pass():
    """``(J, r, a)`` of ``r = fn(p, samples)`` equal the residuals, their Jacobian in
    ``p`` and their derivative along the samples' normals taken one at a time (jacfwd,
    jvp); also under jit and vmap over views."""
    rng = np.random.default_rng(11)
    samples = jnp.asarray(rng.normal(size=(4, 7, 2)))
    normals = jnp.asarray(rng.normal(size=(4, 7, 2)))
    p = jnp.asarray(rng.normal(size=3))

    def fn(p, s):
        return jnp.sin(s @ p[:2]) * p[2] + jnp.sum(s**2, -1) * p[0]

    J, r, a = jax.jit(jax.vmap(lambda s, n: nz.jacobian_and_normal_sensitivity(fn, p, s, n)))(samples, normals)
    for v in range(4):
        np.testing.assert_allclose(r[v], fn(p, samples[v]), rtol=1e-13)
        np.testing.assert_allclose(J[v], jax.jacfwd(fn)(p, samples[v]), rtol=1e-13)
        np.testing.assert_allclose(a[v], jax.jvp(lambda s: fn(p, s), (samples[v],), (normals[v],))[1], rtol=1e-13)
