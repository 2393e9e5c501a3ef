"""The one least-squares loop (sorjax.core._solvers): against optimistix and a known
optimum, Gauss-Newton and Levenberg-Marquardt as data, eager / jit / vmap, implicit
gradients against central differences, the stopping rules, and the control flow that
traces each solve once."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from sorjax.core._solvers import (NULL_RCOND, Method, Solved, least_squares, polish_traced, solvers,
                                  until_fresh_traced)

T = jnp.linspace(0.0, 2.0, 25)


def _data(seed=0):
    rng = np.random.default_rng(seed)
    return jnp.asarray(2.0 * np.exp(-1.3 * np.asarray(T)) + 0.3 + 0.01 * rng.standard_normal(T.shape))


def _res(y, data):
    """Residuals of the model ``a exp(-b t) + c`` (a pytree of parameters)."""
    return y["a"] * jnp.exp(-y["b"] * T) + y["c"] - data


Y0 = {"a": jnp.asarray(1.0), "b": jnp.asarray(0.5), "c": jnp.asarray(0.0)}  # far: Gauss-Newton alone diverges
NEAR = {"a": jnp.asarray(1.8), "b": jnp.asarray(1.1), "c": jnp.asarray(0.2)}
TIGHT = solvers(rtol=1e-12, atol=1e-14)


def _flat(y):
    return np.array([float(y[k]) for k in "abc"])


@pytest.mark.parametrize("name", ["gn", "lm"])
def test_matches_optimistix(name):
    """Both methods reach optimistix's Levenberg-Marquardt optimum (an independent
    implementation) to 1e-9, converged, in fewer steps than the budget: from a far
    start Levenberg-Marquardt, from a near one Gauss-Newton (undamped, it can diverge
    from a far one)."""
    data = _data()
    ref = optx.least_squares(_res, optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14), Y0, args=data, max_steps=500)
    y0 = Y0 if name == "lm" else NEAR
    y, ok, steps = jax.jit(lambda d: least_squares(_res, y0, d, TIGHT[name], 200))(data)
    assert bool(ok) and 0 < int(steps) < 200
    np.testing.assert_allclose(_flat(y), _flat(ref.value), rtol=1e-9, atol=1e-12)
    # the gradient of the cost vanishes there
    g = jax.grad(lambda y: jnp.sum(_res(y, data) ** 2))(y)
    assert max(abs(float(v)) for v in jax.tree_util.tree_leaves(g)) < 1e-9


def test_method_is_data():
    """One traced loop: Gauss-Newton and Levenberg-Marquardt, their tolerances and the
    step budget as arrays through ``jax.vmap`` give what separate calls give."""
    data = _data(1)
    methods = Method(jnp.array([False, True]), jnp.array([1e-12, 1e-12]), jnp.array([1e-14, 1e-14]))
    budgets = jnp.array([200, 200])
    ys, oks, steps = jax.jit(jax.vmap(lambda m, n: least_squares(_res, NEAR, data, m, n)))(methods, budgets)
    for i, name in enumerate(["gn", "lm"]):
        y, ok, n = least_squares(_res, NEAR, data, TIGHT[name], 200)
        np.testing.assert_allclose(_flat(jax.tree_util.tree_map(lambda x: x[i], ys)), _flat(y), rtol=1e-12)
        assert bool(oks[i]) == bool(ok) and int(steps[i]) == int(n)


def test_vmap_equals_loop():
    """vmap over problems (data) equals a Python loop of eager calls."""
    datas = jnp.stack([_data(s) for s in range(4)])
    ys, oks, _ = jax.jit(jax.vmap(lambda d: least_squares(_res, Y0, d, TIGHT["lm"], 200)))(datas)
    for i in range(4):
        y, ok, _ = least_squares(_res, Y0, datas[i], TIGHT["lm"], 200)
        np.testing.assert_allclose(_flat(jax.tree_util.tree_map(lambda x: x[i], ys)), _flat(y), rtol=1e-12)
        assert bool(oks[i]) and bool(ok)


def test_step_budget():
    """A budget too small to converge stops there and says so (``ok`` False); one step
    more than the converged run needs is enough."""
    data = _data(2)
    _, ok, n = least_squares(_res, Y0, data, TIGHT["lm"], 200)
    assert bool(ok)
    _, ok_short, n_short = least_squares(_res, Y0, data, TIGHT["lm"], int(n) - 1)
    assert not bool(ok_short) and int(n_short) == int(n) - 1
    _, ok_exact, n_exact = least_squares(_res, Y0, data, TIGHT["lm"], int(n))
    assert bool(ok_exact) and int(n_exact) == int(n)


def test_unused_parameter_stays_put():
    """A parameter no residual depends on (a masked view, a padded chart entry) has a
    zero Jacobian column: neither method moves it (the truncated SVD, the damping)."""
    def res(y, data):
        return _res({"a": y[0], "b": y[1], "c": y[2]}, data)

    y0 = jnp.array([1.8, 1.1, 0.2, 7.0])
    for name in ("gn", "lm"):
        y, ok, _ = least_squares(res, y0, _data(), TIGHT[name], 200)
        assert bool(ok) and float(y[3]) == 7.0


def test_gauss_newton_ignores_null_directions():
    """Two parameters that enter only as their sum: Gauss-Newton moves along the
    determined direction only (the singular value of the other is below NULL_RCOND),
    so their difference keeps its start value."""
    def res(y, data):
        return _res({"a": y[0], "b": y[1] + y[2], "c": y[3]}, data)

    y0 = jnp.array([1.8, 0.5, 0.6, 0.2])
    y, ok, _ = least_squares(res, y0, _data(), TIGHT["gn"], 200)
    assert bool(ok)
    np.testing.assert_allclose(float(y[1] - y[2]), -0.1, atol=1e-9)
    np.testing.assert_allclose(float(y[1] + y[2]), _flat(least_squares(_res, NEAR, _data(), TIGHT["gn"], 200)[0])[1],
                               rtol=1e-9)
    assert NULL_RCOND < 1e-3


def test_non_finite_start_fails_cleanly():
    """A start where the residuals are not finite: no exception, not converged."""
    y0 = dict(Y0, b=jnp.asarray(jnp.nan))
    for name in ("gn", "lm"):
        _, ok, _ = least_squares(_res, y0, _data(), TIGHT[name], 50)
        assert not bool(ok)


def test_implicit_gradient_matches_central_differences():
    """d(solution)/d(data) by the implicit function theorem (forward and reverse mode)
    against central differences of whole solves."""
    data = _data(3)

    def fit(d):
        y, _, _ = least_squares(_res, Y0, d, TIGHT["lm"], 200)
        return y["b"]

    direction = jnp.asarray(np.random.default_rng(4).standard_normal(T.shape))
    h = 1e-4  # (the solves' own precision, about 1e-10, limits a smaller step)
    fd = (float(fit(data + h * direction)) - float(fit(data - h * direction))) / (2 * h)
    rev = float(jax.jit(jax.grad(fit))(data) @ direction)
    fwd = float(jax.jvp(fit, (data,), (direction,))[1])
    np.testing.assert_allclose(rev, fd, rtol=1e-5)
    np.testing.assert_allclose(fwd, fd, rtol=1e-5)
    np.testing.assert_allclose(rev, fwd, rtol=1e-12)


def test_each_solve_traced_once():
    """The re-solve loop and the Gauss-Newton / Levenberg-Marquardt rounds trace their
    solve once each when given the shapes of what it returns (``out0``)."""
    traced = []
    data = _data(5)

    def run(state, method):
        def once(y):
            traced.append(1)
            y_end, ok, n = least_squares(_res, y, data, method, 200)
            return (ok, _res(y_end, data)), y_end, n, jnp.asarray(False)

        (ok, r), y, steps = until_fresh_traced(once, state, (jnp.asarray(False), jnp.zeros(T.shape)))
        return Solved(y, ok, jnp.sum(r**2), steps, r)

    cost0 = jnp.sum(_res(NEAR, data) ** 2)
    final, steps = jax.jit(lambda: polish_traced(run, NEAR, cost0, TIGHT["gn"], TIGHT["lm"], jnp.zeros(T.shape)))()
    assert len(traced) == 1
    assert bool(final.ok) and float(final.cost) < float(cost0) and int(steps) > 0
    y, _, _ = least_squares(_res, NEAR, data, TIGHT["gn"], 200)
    np.testing.assert_allclose(_flat(final.y), _flat(y), rtol=1e-12)


def test_polish_falls_back_to_levenberg_marquardt():
    """Where Gauss-Newton fails (a budget of one step), the second round runs
    Levenberg-Marquardt from the better point and its steps are counted too."""
    data = _data(6)
    lm = TIGHT["lm"]
    gn_one = Method(False, 1e-12, 1e-14)

    def run(y, method):
        budget = jnp.where(method.damped, 200, 1)
        y_end, ok, n = least_squares(_res, y, data, method, budget)
        r = _res(y_end, data)
        return Solved(y_end, ok, jnp.sum(r**2), n, r)

    cost0 = jnp.sum(_res(Y0, data) ** 2)
    final, steps = polish_traced(run, Y0, cost0, gn_one, lm, jnp.zeros(T.shape))
    y, _, n_lm = least_squares(_res, Y0, data, lm, 200)
    assert bool(final.ok) and int(steps) > int(final.steps) >= 1
    np.testing.assert_allclose(_flat(final.y), _flat(y), rtol=1e-8)


@pytest.mark.parametrize("model", ["free", "known aspect", "fixed principal point"])
def test_solves_in_the_calibration_program(monkeypatch, model):
    """The whole calibration (:func:`sorjax.core.calibrate`: per-view fits, linear seeds,
    bundle, covariance, model checks) traced by ``jax.make_jaxpr`` holds two solve
    loops: the per-view fit (screen, polish and refits as one loop) and the bundle
    (every seed's Gauss-Newton round, its Levenberg-Marquardt fallback and the
    no-perspective reference fit as one loop).  With a known aspect ratio (the
    free-aspect fit the check compares with runs through the same loop) and with fixed
    intrinsics the part after the per-view fits (:func:`sorjax.core.calibrate_homologies`)
    holds the one bundle loop.  A further solver fails this test."""
    import sorjax
    from sorjax import core, scenes
    from sorjax.core import _solvers

    sc = scenes.two_spheres(f=700.0)
    points = jnp.stack([sorjax.make_outline(o).points for o in sc.outlines])
    kw = {"free": {}, "known aspect": {"aspect": 1.0},
          "fixed principal point": {"fixed": jnp.array([jnp.nan, jnp.nan, 320.0, 240.0])}}[model]
    homs = None if model == "free" else core.fit_homologies(points)
    traced = []
    inner = _solvers._minimise
    monkeypatch.setattr(_solvers, "_minimise", lambda *a, **k: traced.append(1) or inner(*a, **k))
    jax.clear_caches()  # (the inner jitted functions' traces of an earlier test would hide their solves)
    if homs is None:
        jax.make_jaxpr(lambda p: core.calibrate(p))(points)
        assert len(traced) == 2
    else:
        jax.make_jaxpr(lambda p, h: core.calibrate_homologies(p, h, **kw))(points, homs)
        assert len(traced) == 1



def test_traced_once_replays_without_tracing_again():
    """:func:`sorjax.core._solvers.traced_once`: the shapes of the result from one trace,
    and a replay equal to the function (eagerly, under jit, vmap and grad, closing over
    traced values) with no second trace."""
    from sorjax.core._solvers import traced_once

    calls = []

    def f(x, y):
        calls.append(1)
        return {"s": jnp.sin(x) * y, "n": jnp.sum(x**2)}

    x = jnp.linspace(0.1, 1.0, 5)

    def outer(y):
        replay, shapes = traced_once(lambda x: f(x, y), x)
        assert shapes["s"].shape == (5,) and shapes["n"].shape == ()
        return jax.lax.map(lambda xi: replay(xi)["n"], jnp.stack([x, 2 * x]))

    got = jax.jit(outer)(3.0)
    assert len(calls) == 1
    np.testing.assert_allclose(got, [float(jnp.sum(x**2)), float(jnp.sum(4 * x**2))], rtol=1e-14)
    np.testing.assert_allclose(jax.vmap(outer)(jnp.array([1.0, 2.0]))[:, 1], float(jnp.sum(4 * x**2)), rtol=1e-14)

    def g(y):
        replay, _ = traced_once(lambda x: f(x, y), x)
        return jnp.sum(replay(x)["s"])

    np.testing.assert_allclose(jax.grad(g)(2.0), float(jnp.sum(jnp.sin(x))), rtol=1e-14)
