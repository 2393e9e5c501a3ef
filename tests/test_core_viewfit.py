"""The per-view fit as a pure function (sorjax.core._viewfit): truth, optimality,
jit/vmap consistency, robust trimming, conic and at-infinity flags.

All views go through one compiled ``jax.lax.map`` (one batch of equal shapes); the
``jax.vmap`` of the same fit is compared with it."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._camera import angle_between_planes, angle_between_rays
from sorjax.core import Options, prepare_views
from sorjax.core._viewfit import (N_STARTS, _pack, _residuals, automatic_starts, fit_view, fit_views,
                                  homologies_in_pixels)
from test_degenerate import K_TRUE, MIRROR, pose_at, posed, sphere_outline
from test_homology import _with_handle

OPTIONS = Options()


def _points(outlines):
    return jnp.stack([sorjax.make_outline(o).points for o in outlines])


@jax.jit
def _fit_all(points):
    views = prepare_views(points, OPTIONS.n_samples)
    fits = fit_views(views, OPTIONS, sequential=True)  # lax.map: the vmap is compared below
    return views, fits, homologies_in_pixels(views, fits, OPTIONS)


@pytest.fixture(scope="module")
def batch():
    """(name, K, truth view or None, outline) of every view tested, fitted in one call."""
    rows = []
    sp = scenes.two_spheres(f=700.0)
    rows += [(f"sphere {i}", sp.K, v, v.outline) for i, v in enumerate(sp.views)]
    for seed in (1, 7):
        sc = scenes.random_sor_scene(seed, n_views=2)
        rows += [(f"sor {seed}.{i}", sc.K, v, v.outline) for i, v in enumerate(sc.views)]
    rows += [(f"noisy sphere {i}", sp.K, v, scenes.paper_noise(v.outline, 1.0, 3 + i)) for i, v in enumerate(sp.views)]
    sc = scenes.random_sor_scene(11, n_views=2)
    rows += [(f"noisy sor {i}", sc.K, v, scenes.paper_noise(v.outline, 1.0, 20 + i)) for i, v in enumerate(sc.views)]
    K = scenes.intrinsics(800.0)
    hs = scenes.sor_scene(scenes.vase(), K, [scenes.look_at((0.8, -0.5, -1.6), (0.0, 0.0, 0.0), roll=0.3)])
    rows.append(("handle", K, hs.views[0], _with_handle(hs.outlines[0], 0.15)))
    prof = scenes.vase()
    sphere = sphere_outline(K_TRUE, pose_at(prof, K_TRUE, 20, 40, 0.2, (200, 180)), np.array([0.0, 0.15, 0.0]), 0.08)
    rows.append(("sphere outline", K_TRUE, None, sphere))
    mirror = posed(MIRROR[:1])
    rows.append(("mirror", K_TRUE, mirror.views[0], mirror.outlines[0]))
    points = _points([r[3] for r in rows])
    views, fits, homs = _fit_all(points)
    return {r[0]: (i, r[1], r[2]) for i, r in enumerate(rows)}, views, fits, homs


def _get(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)


def _errors(K, h, view):
    return float(angle_between_planes(K, h.l_s, view.l_s)), float(angle_between_rays(K, h.v_x, view.v_x))


def test_fixed_number_of_starts(batch):
    rows, views, _, _ = batch
    i = rows["sor 1.0"][0]
    vs, ls, valid = jax.jit(automatic_starts)(views.points[i], views.samples[i])
    assert vs.shape == ls.shape == (N_STARTS, 3) and valid.shape == (N_STARTS,)
    assert bool(valid.any())


def test_noise_free_views_match_truth(batch):
    rows, _, fits, homs = batch
    for name in ("sphere 0", "sphere 1", "sphere 2", "sor 1.0", "sor 1.1", "sor 7.0", "sor 7.1"):
        i, K, view = rows[name]
        h = _get(homs, i)
        dl, dv = _errors(K, h, view)
        assert dl < 1e-3 and dv < 1e-2, (name, dl, dv)
        assert bool(h.converged) and float(h.trimmed) == 0.0
        np.testing.assert_allclose(float(jnp.hypot(h.l_s[0], h.l_s[1])), 1.0, rtol=1e-12)
    for name in ("sphere 0", "sphere 1", "sphere 2"):
        assert float(_get(homs, rows[name][0]).rms) < 1e-5


def test_noisy_views_are_local_minima_near_truth(batch):
    """The noisy fits stop at a stationary point of eq. 20 (gradient ~ 0 in a chart
    centred on the solution), with the axis close to the truth."""
    rows, views, fits, homs = batch
    for name in ("noisy sphere 0", "noisy sphere 1", "noisy sphere 2", "noisy sor 0", "noisy sor 1"):
        i, K, view = rows[name]
        f, h = _get(fits, i), _get(homs, i)
        assert bool(f.converged) and float(h.trimmed) < 0.05  # noise alone trims little
        assert 0.05 < float(h.rms) < 1.0
        p, v0, E = _pack(f.v, f.l)
        args = (_get(views.fields, i), views.samples[i], views.weights[i] * f.inliers, v0, E)
        r = jax.jit(_residuals)(p, args)
        J = jax.jit(jax.jacfwd(_residuals))(p, args)
        np.testing.assert_allclose(float(jnp.sum(r**2)), float(f.cost), rtol=1e-12)
        g = J.T @ r  # half the gradient of the cost
        assert float(jnp.linalg.norm(g)) < 1e-7 * float(jnp.linalg.norm(J)) * float(jnp.linalg.norm(r)), name
        dl, _ = _errors(K, h, view)
        assert dl < 0.5, (name, dl)


def test_jit_vmap_equals_single_calls(batch):
    rows, views, fits, _ = batch
    one = jax.jit(lambda f, s, w, p, sc: fit_view(f, s, w, p, OPTIONS, None, sc))
    for name in ("sor 7.0", "noisy sor 1", "handle"):
        i = rows[name][0]
        single = one(_get(views.fields, i), views.samples[i], views.weights[i], views.points[i], views.scale[i])
        batched = _get(fits, i)
        for a, b in zip(jax.tree_util.tree_leaves(single), jax.tree_util.tree_leaves(batched)):
            if jnp.issubdtype(a.dtype, jnp.floating):
                np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12)
            else:
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_handle_is_trimmed(batch):
    rows, views, fits, homs = batch
    i, K, view = rows["handle"]
    h, f = _get(homs, i), _get(fits, i)
    dl, _ = _errors(K, h, view)
    assert dl < 0.02 and float(h.rms) < 0.3 < float(h.rms_untrimmed)
    assert 0.05 < float(h.trimmed) < 0.4
    assert float(f.n) < float(f.n_untrimmed) and float(f.cost) < float(f.cost_untrimmed)
    assert not bool(h.is_conic)
    # the last refit (started at the previous round's optimum) is a stationary point
    # of eq. 20 over the kept samples
    p, v0, E = _pack(f.v, f.l)
    args = (_get(views.fields, i), views.samples[i], views.weights[i] * f.inliers, v0, E)
    r, J = _residuals(p, args), jax.jacfwd(_residuals)(p, args)
    np.testing.assert_allclose(float(jnp.sum(r**2)), float(f.cost), rtol=1e-12)
    assert float(jnp.linalg.norm(J.T @ r)) < 1e-7 * float(jnp.linalg.norm(J)) * float(jnp.linalg.norm(r))


def test_each_solver_is_traced_once(batch, monkeypatch):
    """One solve in the program: the screen, the polish (Gauss-Newton, its
    Levenberg-Marquardt fallback) and the robust refits are iterations of one while
    loop with the method as data, whatever the trimming rounds."""
    from sorjax.core import _solvers

    rows, views, _, _ = batch
    i = rows["handle"][0]
    args = (_get(views.fields, i), views.samples[i], views.weights[i], views.points[i], views.scale[i])
    inner = _solvers._minimise
    for options in (OPTIONS, Options(trim_rounds=0)):
        traced = []
        monkeypatch.setattr(_solvers, "_minimise", lambda *a, **k: traced.append(1) or inner(*a, **k))
        fit = jax.jit(lambda f, s, w, p, sc: fit_view(f, s, w, p, options, None, sc))  # noqa: B023
        fit.lower(*args)
        assert len(traced) == 1


def test_sphere_outline_is_conic(batch):
    rows, _, _, homs = batch
    assert bool(_get(homs, rows["sphere outline"][0]).is_conic)
    assert not any(bool(_get(homs, rows[n][0]).is_conic) for n in ("sor 1.0", "noisy sor 0", "mirror"))


def test_mirror_view_has_vertex_at_infinity(batch):
    rows, _, _, homs = batch
    i, K, view = rows["mirror"]
    h = _get(homs, i)
    assert abs(view.v_x[2]) < 1e-12
    assert bool(h.at_infinity)
    assert not bool(_get(homs, rows["sor 1.0"][0]).at_infinity)


def test_noise_floor_scales_the_infinity_z_and_decides_the_flags_again(batch):
    """with_noise_floor: a view's v_3 standard error grows with the noise level, so its
    infinity_z falls by rms / noise where the floor is higher (an averaged outline's
    v_x must not pass as finite on residuals it no longer shows); the conic test is
    taken at the floored residual; a floor at or below the residual changes nothing."""
    from sorjax.core import with_noise_floor

    rows, _, _, homs = batch
    V = homs.rms.shape[0]
    same = with_noise_floor(homs, 0.5 * np.asarray(homs.rms), OPTIONS)
    for a, b in zip(jax.tree_util.tree_leaves(same), jax.tree_util.tree_leaves(homs)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    i = rows["noisy sor 0"][0]
    h = _get(homs, i)
    assert not bool(h.at_infinity) and np.isfinite(float(h.infinity_z)) and not bool(h.is_conic)
    floor = np.zeros(V)
    floor[i] = float(h.rms) * float(h.infinity_z) / (0.5 * OPTIONS.infinity_z)  # z falls to half the threshold
    got = jax.jit(with_noise_floor)(homs, floor, OPTIONS)
    np.testing.assert_allclose(float(got.infinity_z[i]), 0.5 * OPTIONS.infinity_z, rtol=1e-12)
    assert bool(got.at_infinity[i]) and float(got.rms[i]) == float(h.rms)
    # the conic test at the floored residual: a conic fits within conic_ratio times a noise this high
    floor[i] = 2.0 * float(h.conic_rms) / OPTIONS.conic_ratio
    assert bool(with_noise_floor(homs, floor, OPTIONS).is_conic[i])
    # under jax.vmap over a batch of floors: each as one call
    floors = np.stack([np.zeros(V), floor])
    batched = jax.vmap(lambda f: with_noise_floor(homs, f, OPTIONS))(jnp.asarray(floors))
    for k in range(2):
        one = with_noise_floor(homs, floors[k], OPTIONS)
        np.testing.assert_array_equal(np.asarray(batched.infinity_z[k]), np.asarray(one.infinity_z))
        np.testing.assert_array_equal(np.asarray(batched.at_infinity[k]), np.asarray(one.at_infinity))
    others = np.arange(V) != i
    np.testing.assert_array_equal(np.asarray(got.infinity_z)[others], np.asarray(homs.infinity_z)[others])
    np.testing.assert_array_equal(np.asarray(got.at_infinity)[others], np.asarray(homs.at_infinity)[others])


def test_init_replaces_the_automatic_starts(batch):
    rows, views, fits, _ = batch
    i = rows["noisy sor 0"][0]
    f = _get(fits, i)
    one = jax.jit(lambda f_, s, w, p, v, l: fit_view(f_, s, w, p, OPTIONS, (v, l), views.scale[i]))
    g = one(_get(views.fields, i), views.samples[i], views.weights[i], views.points[i], f.v * 1.0001, f.l)
    np.testing.assert_allclose(float(g.cost), float(f.cost), rtol=1e-8)
    assert float(jnp.abs(g.l @ f.l)) > 1 - 1e-10


def test_sequential_map_equals_vmap(batch):
    rows, views, fits, _ = batch
    idx = np.array([rows[n][0] for n in ("sor 1.1", "noisy sphere 1", "handle")])
    sub = jax.tree_util.tree_map(lambda a: a[idx], views)
    seq = jax.jit(lambda v: fit_views(v, OPTIONS, sequential=True))(sub)
    for a, b in zip(jax.tree_util.tree_leaves(seq), jax.tree_util.tree_leaves(_get(fits, idx))):
        if jnp.issubdtype(a.dtype, jnp.floating):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12)
        else:
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
