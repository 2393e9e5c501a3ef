"""The smooth signed distance field against exact distances and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax import scenes
from sorjax.core._field import _argmin, _nearest_knot, curve, make_field, signed_distance, signed_distances
from sorjax._outline import make_outline

A, B, CX, CY = 150.0, 90.0, 320.0, 240.0


def exact_ellipse_distance(p):
    """Signed distance to the ellipse by Newton on the foot-point parameter (float64)."""
    x, y = p[:, 0] - CX, p[:, 1] - CY
    t = np.arctan2(A * y, B * x)
    for _ in range(50):
        cx, cy = A * np.cos(t), B * np.sin(t)
        dx, dy = -A * np.sin(t), B * np.cos(t)
        g = (cx - x) * dx + (cy - y) * dy
        h = dx * dx + dy * dy + (cx - x) * (-A * np.cos(t)) + (cy - y) * (-B * np.sin(t))
        t = t - g / h
    d = np.hypot(x - A * np.cos(t), y - B * np.sin(t))
    return np.where((x / A) ** 2 + (y / B) ** 2 < 1, -d, d)


def ellipse_field(n=512, dense=4000):
    t = np.linspace(0, 2 * np.pi, dense, endpoint=False)
    pts = np.stack([CX + A * np.cos(t), CY + B * np.sin(t)], 1)
    return make_field(make_outline(pts, n).points)


@pytest.mark.parametrize("n", [512, 2048])  # 2048 (the default) takes the decimated search
def test_distance_within_5px_is_accurate(n):
    field = ellipse_field(n=n)
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 2 * np.pi, 2000)
    r = rng.uniform(-5, 5, 2000)
    base = np.stack([CX + A * np.cos(t), CY + B * np.sin(t)], 1)
    nrm = np.stack([B * np.cos(t), A * np.sin(t)], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    q = base + r[:, None] * nrm
    d = np.asarray(jax.jit(signed_distances)(field, jnp.asarray(q)))
    err = np.abs(d - exact_ellipse_distance(q))
    assert err.max() < 0.01, err.max()  # issue 4's bound: 0.01 px within 5 px


def test_hinted_search_matches_the_whole_outline_search_near_its_hint():
    """The solvers search each closest point only near a hint (its parameter at the
    solve's start).  Within NEAR_WINDOW decimated knots of the true closest point it
    finds the same point (value and gradient); a hint on the far side of the outline
    gives another point, farther away, which is what the solvers' staleness test
    (residuals compared with whole-outline ones) catches."""
    from sorjax.core._field import NEAR_WINDOW, SEARCH_KNOTS, closest_parameter

    field = ellipse_field(n=2048)
    m = field.n_knots
    reach = NEAR_WINDOW * max(1, m // SEARCH_KNOTS)
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 500)
    r = rng.uniform(-5, 5, 500)
    q = jnp.asarray(np.stack([CX + (A + r) * np.cos(t), CY + (B + r) * np.sin(t)], 1))
    t_true = jax.jit(jax.vmap(closest_parameter, in_axes=(None, 0)))(field, q)
    distances = jax.jit(signed_distances)
    whole = np.asarray(distances(field, q))
    near = jnp.mod(t_true + rng.uniform(-(reach - 1), reach - 1, 500), m)
    np.testing.assert_allclose(np.asarray(jax.jit(signed_distances)(field, q, near)), whole, rtol=0, atol=1e-12)
    g = jax.jit(jax.vmap(jax.grad(signed_distance, argnums=1), in_axes=(None, 0, 0)))(field, q, near)
    g0 = jax.jit(jax.vmap(jax.grad(signed_distance, argnums=1), in_axes=(None, 0)))(field, q)
    np.testing.assert_allclose(np.asarray(g), np.asarray(g0), atol=1e-10)
    far = np.asarray(distances(field, q, jnp.mod(t_true + m / 2, m)))
    assert np.min(np.abs(far - whole)) > 1e-3  # a stale hint shows (the solvers test at 1e-9)


def test_checked_distances_are_the_whole_and_the_near_search_in_one_pass():
    """What a solver reads at its end (:func:`checked_distances`): the whole-outline
    distances, their closest-point parameters and the distances searched near the
    solve's hints, bit for bit as the three separate evaluations give them (also where
    a hint is stale; to round-off: a program of its own), and the same gradient in
    the points."""
    from sorjax.core._field import checked_distances, closest_parameter

    field = ellipse_field(n=2048)
    m = field.n_knots
    rng = np.random.default_rng(5)
    t = rng.uniform(0, 2 * np.pi, 200)
    r = rng.uniform(-5, 5, 200)
    q = jnp.asarray(np.stack([CX + (A + r) * np.cos(t), CY + (B + r) * np.sin(t)], 1))
    t_true = jax.jit(jax.vmap(closest_parameter, in_axes=(None, 0)))(field, q)
    hints = jnp.mod(t_true + jnp.where(jnp.arange(200) % 7 == 0, m / 2, 3.0), m)  # every 7th stale
    d, feet, d_near = jax.jit(checked_distances)(field, q, hints)
    np.testing.assert_allclose(np.asarray(d), np.asarray(jax.jit(signed_distances)(field, q)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(feet), np.asarray(t_true), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(d_near), np.asarray(jax.jit(signed_distances)(field, q, hints)), rtol=0,
                               atol=1e-12)
    assert np.sum(np.abs(np.asarray(d_near) - np.asarray(d)) > 1e-9) == np.sum(np.arange(200) % 7 == 0)
    d2, _, same = jax.jit(checked_distances)(field, q)
    np.testing.assert_array_equal(np.asarray(d2), np.asarray(same))
    g = jax.jit(jax.grad(lambda x: jnp.sum(checked_distances(field, x, hints)[0] ** 2)))(q)
    g0 = jax.jit(jax.grad(lambda x: jnp.sum(signed_distances(field, x) ** 2)))(q)
    np.testing.assert_allclose(np.asarray(g), np.asarray(g0), rtol=0, atol=1e-12)


def test_computed_as_has_the_value_given_and_the_derivative_of_its_function():
    """:func:`sorjax.core._solvers.computed_as`: a value computed elsewhere (a solver's loop)
    keeps its value and differentiates as the function that computes it (jvp, grad,
    under jit); the function is not traced unless differentiated."""
    from sorjax.core._solvers import computed_as

    traced = []

    def fn(a, b):
        traced.append(1)
        return jnp.sin(a) * b**2

    a, b = jnp.asarray(0.3), jnp.asarray(1.7)
    value = jnp.sin(0.3) * 1.7**2
    assert float(jax.jit(lambda a, b: computed_as(value, fn, a, b))(a, b)) == float(value)
    assert not traced
    g = jax.jit(jax.grad(lambda a, b: computed_as(value, fn, a, b), argnums=(0, 1)))(a, b)
    g0 = jax.grad(fn, argnums=(0, 1))(a, b)
    np.testing.assert_allclose(np.asarray(g), np.asarray(g0), rtol=1e-14)


def test_whole_outline_search_finds_the_closest_point_near_sharp_corners():
    """Near a sharp corner the knot nearest a point can lie nearer the next decimated
    knot than the best one: the search's last pass must reach it (with one decimation
    step each side it did not, and the Newton steps settled on a wrong foot point).
    Against a brute-force search over every knot, points scattered 3 px around the
    corners of a star-shaped outline (ten 36-degree spikes)."""
    from sorjax.core._field import _argmin, _newton_foot, closest_parameter

    k = np.arange(4000)
    ang = 2 * np.pi * k / 4000
    rad = 100 + 60 * np.abs(((k % 400) - 200) / 200.0)  # ten sharp spikes and valleys
    field = make_field(make_outline(np.stack([300 + rad * np.cos(ang), 300 + rad * np.sin(ang)], 1), 2048).points)
    rng = np.random.default_rng(4)
    corners = np.asarray(field.knots)[np.argsort(-np.abs(np.diff(np.asarray(field.knots), 2, axis=0)).sum(1))[:40] + 1]
    q = jnp.asarray(np.repeat(corners, 25, axis=0) + rng.normal(0, 3, (1000, 2)))

    def brute(x):
        return _newton_foot(field, x, _argmin(jnp.sum((field.knots - x) ** 2, -1)).astype(jnp.float64))

    distances = jax.jit(signed_distances)
    exact = distances(field, q, jax.jit(jax.vmap(brute))(q))
    found = distances(field, q, jax.jit(jax.vmap(closest_parameter, in_axes=(None, 0)))(field, q))
    assert float(jnp.max(jnp.abs(found - exact))) < 1e-6


def test_gradient_matches_central_differences():
    field = ellipse_field()
    rng = np.random.default_rng(1)
    q = jnp.asarray(np.stack([CX + A * 1.02 * np.cos(np.r_[0.3, 2.0, 4.0]), CY + B * 0.97 * np.sin(np.r_[0.3, 2.0, 4.0])], 1))
    g = jax.jit(jax.vmap(jax.grad(signed_distance, argnums=1), in_axes=(None, 0)))(field, q)
    h = 1e-5
    distances = jax.jit(signed_distances)
    for k in range(2):
        e = jnp.zeros(2).at[k].set(h)
        fd = (distances(field, q + e) - distances(field, q - e)) / (2 * h)
        np.testing.assert_allclose(np.asarray(g[:, k]), np.asarray(fd), rtol=1e-6, atol=1e-9)
    # gradient with respect to the outline points too (the field is built by FFT)
    pts = make_outline(np.asarray(field.knots), 512).points

    @jax.jit
    def f(p):
        return jnp.sum(signed_distances(make_field(p), q) ** 2)

    gp = jax.jit(jax.grad(f))(pts)
    d = jnp.asarray(rng.normal(size=pts.shape))
    fd = (f(pts + 1e-6 * d) - f(pts - 1e-6 * d)) / 2e-6
    np.testing.assert_allclose(float(jnp.sum(gp * d)), float(fd), rtol=1e-5)
    del rng


def test_field_is_c1_across_knots():
    """The gradient varies continuously as a point moves past a knot."""
    field = ellipse_field(n=128)
    knot = np.asarray(field.knots[10])
    _, tangent, _ = curve(field, 10.0)
    tangent = np.asarray(tangent) / np.linalg.norm(tangent)
    off = np.array([tangent[1], -tangent[0]]) * 3.0  # 3 px outside
    s = np.linspace(-0.5, 0.5, 201)
    pts = jnp.asarray(knot + off + s[:, None] * tangent[None, :] * 0.5)
    g = np.asarray(jax.jit(jax.vmap(jax.grad(signed_distance, argnums=1), in_axes=(None, 0)))(field, pts))
    assert np.max(np.linalg.norm(np.diff(g, axis=0), axis=1)) < 1e-3


def test_sign_convention_and_jit_vmap():
    field = ellipse_field(n=256)
    q = jnp.asarray([[CX, CY], [CX + A + 2.0, CY], [CX, CY - B + 1.0]])
    eager = np.array([float(signed_distance(field, x)) for x in q])
    np.testing.assert_allclose(np.asarray(jax.jit(signed_distances)(field, q)), eager, rtol=1e-12)
    assert eager[0] < 0 and eager[1] > 0 and eager[2] < 0
    np.testing.assert_allclose(eager[1:], [2.0, -1.0], atol=1e-3)


def test_argmin_by_reductions_matches_jnp_argmin():
    rng = np.random.default_rng(3)
    d = rng.integers(0, 5, size=(200, 37)).astype(float)  # many ties: the first index wins
    got = jax.jit(jax.vmap(_argmin))(jnp.asarray(d))
    np.testing.assert_array_equal(np.asarray(got), np.argmin(d, axis=1))


@pytest.mark.parametrize("profile", ["two_spheres", "wine_glass"])
def test_nearest_knot_search_against_brute_force(profile):
    """The three-pass search on 2048 knots (waist corner, thin stem) against the
    nearest of all knots, for points up to ~8 px from the outline."""
    if profile == "two_spheres":
        o = scenes.two_spheres(700.0).outlines[0]
    else:
        sc = scenes.sor_scene(scenes.wine_glass(), scenes.intrinsics(800.0), [scenes.look_at((0.0, -0.4, -3.0), (0.0, 0.0, 0.0))])
        o = sc.outlines[0]
    field = make_field(make_outline(o, 2048).points)
    rng = np.random.default_rng(0)
    x = np.asarray(field.knots)[rng.integers(0, 2048, 4000)] + rng.normal(0, 3.0, (4000, 2))
    got = np.asarray(jax.jit(jax.vmap(_nearest_knot, in_axes=(None, 0)))(field, jnp.asarray(x)))
    d_all = np.linalg.norm(np.asarray(field.knots)[None, :, :] - x[:, None, :], axis=-1)
    best = d_all.min(axis=1)
    mine = d_all[np.arange(len(x)), got]
    assert np.mean(mine == best) > 0.995
    assert np.max(mine - best) < 0.2  # px: within the Newton steps' reach
