"""Least-squares solvers shared by the per-view fit (eq. 20) and the bundle.

Both minimise a sum of squared distances from a few starting points, in two stages:

* **screen** every start with a few loose Levenberg-Marquardt steps and keep the one of
  lowest cost (a start far from the minimum needs the damping);
* **polish** that one to convergence by Gauss-Newton (full steps: near a minimum of
  these small-residual problems it takes about half of Levenberg-Marquardt's steps,
  whose damping decays slowly), and by Levenberg-Marquardt where Gauss-Newton fails or
  ends above its start (:func:`polish_traced`; Gauss-Newton can cycle in a flat valley).

The Gauss-Newton step is a truncated-SVD least-squares solve: it never moves along a
direction whose singular value is below ``NULL_RCOND`` of the largest, i.e. one the data
do not determine (``NULL_RCOND^2`` is the bundle covariance's null eigenvalue
threshold).  With a plain QR step, a degenerate view set (a level camera and upright
objects, free aspect ratio) let fv drift from 800 to 1025 px along its null direction,
where the damped Levenberg-Marquardt step stays put.

Both methods are one loop, :func:`least_squares` (a ``lax.while_loop``: residuals and
Jacobian by one forward-mode pass, a thin SVD of the Jacobian a step), with the method,
its tolerances and the step budget as data (:class:`Method`), so that a program that
screens, polishes and falls back traces one solve.  Its solution is differentiable by
the implicit function theorem (:func:`implicit_minimum`); the loop is not.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.extend
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

NULL_RCOND = 1e-6
# The solvers search each closest point of the distance fields only near where it was at
# the start (sorjax.core._field.closest_parameter_near); a solve whose residuals differ from
# whole-outline ones by more than STALE_TOL (normalised units, ~1e-7 px: another closest
# point, not round-off) is "stale" and is run again from its end, RESOLVES times at most.
STALE_TOL = 1e-9
RESOLVES = 3


class Method(NamedTuple):
    """How :func:`least_squares` steps and when it stops: data, not a program.

    Attributes:
        damped: Levenberg-Marquardt (True: a step ``(J^T J + lambda I)^-1 J^T r``, kept
            only where the cost falls, ``lambda`` adapted by the gain ratio) or
            Gauss-Newton (False: the full truncated-SVD step ``J^+ r``, always taken;
            singular values below ``NULL_RCOND`` of the largest are left out).
        rtol, atol: the solve has converged when a step moves every parameter by less
            than ``atol + rtol |y|`` and the cost ``f = |r|^2 / 2`` by less than ``atol +
            rtol |f|`` (optimistix's Cauchy test).
    """

    damped: Any
    rtol: Any
    atol: Any


#: the loose screening solve (a few steps from each start)
SCREEN = Method(True, 1e-4, 1e-6)


def solvers(rtol: float, atol: float) -> dict[str, Method]:
    """The three methods by name: "lm" (Levenberg-Marquardt), "gn" (Gauss-Newton,
    truncated SVD) with tolerances ``rtol, atol``, and "screen"."""
    return {"lm": Method(True, rtol, atol), "gn": Method(False, rtol, atol), "screen": SCREEN}


# the trust region of Levenberg-Marquardt (optimistix's ClassicalTrustRegion, in the
# damping lambda = 1 / radius): a gain ratio above HIGH divides lambda by GROW, one
# below LOW (the step is then refused) multiplies it by 1 / SHRINK
_LOW, _HIGH, _GROW, _SHRINK = 0.01, 0.99, 3.5, 0.25


def _minimise(fn, y0, args, method: Method, max_steps, m=None):
    """The loop of :func:`least_squares` on ``stop_gradient`` inputs: ``(y, ok, steps)``."""
    x0, unravel = ravel_pytree(y0)
    n = x0.shape[0]
    damped = jnp.asarray(method.damped, bool)
    rtol = jnp.asarray(method.rtol, x0.dtype)
    atol = jnp.asarray(method.atol, x0.dtype)
    max_steps = jnp.asarray(max_steps, jnp.int32)

    def value_and_jac(x):
        f = lambda x: fn(unravel(x), args)  # noqa: E731
        return jax.vmap(lambda t: jax.jvp(f, (x,), (t,)), out_axes=(None, 1))(jnp.eye(n, dtype=x.dtype))

    if m is None:
        m = jax.eval_shape(lambda x: fn(unravel(x), args), x0).shape[0]

    def propose(x, r, J, lam):
        """The next trial point and the cost reduction its linear model predicts."""
        U, s, Vt = jnp.linalg.svd(J, full_matrices=False)
        g = U.T @ r
        s_max = jnp.max(s)
        inv = jnp.where(damped, s / (s**2 + lam), jnp.where(s > NULL_RCOND * s_max, 1.0 / jnp.where(s > 0, s, 1.0),
                                                             0.0))
        step = -(Vt.T @ (inv * g))
        pred = 0.5 * (jnp.sum(r**2) - jnp.sum((r + J @ step) ** 2))
        return x + step, pred

    def cond(c):
        return ~c["done"]

    def body(c):
        xt = c["xt"]
        rt, Jt = value_and_jac(xt)
        ft = 0.5 * jnp.sum(rt**2)
        first = c["i"] == 0
        finite = jnp.isfinite(ft) & jnp.all(jnp.isfinite(Jt))
        pred = c["pred"]
        ratio = jnp.where(pred > 0, (c["f"] - ft) / jnp.where(pred > 0, pred, 1.0), jnp.where(ft <= c["f"], 1.0, 0.0))
        ratio = jnp.where(finite, ratio, 0.0)
        accept = first | (finite & jnp.where(damped, ratio >= _LOW, True))
        lam = c["lam"]
        lam = jnp.where(first, lam, jnp.where(ratio > _HIGH, lam / _GROW, jnp.where(ratio < _LOW, lam / _SHRINK, lam)))
        y_small = jnp.max(jnp.abs(xt - c["x"]) / (atol + rtol * jnp.abs(xt)), initial=0.0) < 1
        f_small = jnp.abs(ft - c["f"]) < atol + rtol * jnp.abs(ft)
        converged = ~first & accept & finite & y_small & f_small
        x = jnp.where(accept, xt, c["x"])
        r = jnp.where(accept, rt, c["r"])
        J = jnp.where(accept, Jt, c["J"])
        f = jnp.where(accept, ft, c["f"])
        broken = ~finite & (first | ~damped)  # a non-finite start, or a Gauss-Newton step to NaN
        x_next, pred_next = propose(x, r, J, lam)
        steps = c["i"]  # trial points evaluated after the start
        done = converged | broken | (steps >= max_steps)
        return dict(i=c["i"] + 1, x=x, r=r, J=J, f=f, lam=lam, xt=x_next, pred=pred_next, done=done,
                    ok=converged)

    init = dict(i=jnp.asarray(0, jnp.int32), x=x0, r=jnp.zeros(m, x0.dtype), J=jnp.zeros((m, n), x0.dtype),
                f=jnp.asarray(jnp.inf, x0.dtype), lam=jnp.asarray(1.0, x0.dtype), xt=x0,
                pred=jnp.asarray(0.0, x0.dtype), done=jnp.asarray(False), ok=jnp.asarray(False))
    c = jax.lax.while_loop(cond, body, init)
    return unravel(c["x"]), c["ok"], jnp.maximum(c["i"] - 1, 0)


def least_squares(fn: Callable[[Any, Any], Any], y0, args, method: Method, max_steps, n_residuals: int | None = None):
    """Minimise ``|fn(y, args)|^2`` from ``y0`` (a pytree of float arrays; ``fn``
    returns a flat residual vector): one ``lax.while_loop``, Levenberg-Marquardt or
    Gauss-Newton as ``method`` says (:class:`Method`: data, so that both and every
    tolerance and step budget ``max_steps`` (int, may be traced) are one traced loop).

    Each step evaluates the residuals and their Jacobian (forward mode, one pass) at a
    trial point and takes a thin SVD of the Jacobian: the Gauss-Newton step is the
    truncated-SVD solution (directions below ``NULL_RCOND`` of the largest singular
    value, e.g. a parameter no residual depends on, are not moved along), the
    Levenberg-Marquardt step the damped one ``V diag(s / (s^2 + lambda)) U^T r``.

    Returns ``(y, ok, steps)``: the solution, whether the convergence test passed
    within ``max_steps`` steps (bool), and the steps taken (int).  ``y`` is
    differentiable in ``args`` by the implicit function theorem
    (:func:`implicit_minimum`); the loop itself is never differentiated.
    ``n_residuals``: the length of ``fn``'s output when the caller knows it (else
    found by tracing ``fn`` once more)."""
    stop = jax.lax.stop_gradient
    y, ok, steps = _minimise(fn, stop(y0), stop(args), method, max_steps, n_residuals)
    return implicit_minimum(fn, y, args), ok, steps


def implicit_minimum(fn: Callable[[Any, Any], Any], y_star, args):
    """``y_star``, a minimum of ``C(y) = |fn(y, args)|^2``, made differentiable in
    ``args`` by the implicit function theorem: ``dy = -H^+ d(grad_y C)`` with ``H`` the
    Hessian of ``C`` in ``y`` (a pseudo-inverse: parameters no residual depends on have
    zero rows and stay put).  Nothing is traced unless differentiated."""

    @jax.custom_jvp
    def solution(y, args):
        return y

    @solution.defjvp
    def _jvp(primals, tangents):
        y, a = primals
        flat, unravel = ravel_pytree(y)

        def grad_y(x, a):
            return jax.grad(lambda x: jnp.sum(fn(unravel(x), a) ** 2))(x)

        H = jax.jacfwd(grad_y)(flat, a)
        _, dg = jax.jvp(lambda a: grad_y(flat, a), (a,), (tangents[1],))
        return y, unravel(-jnp.linalg.pinv(0.5 * (H + H.T), hermitian=True) @ dg)

    return solution(jax.lax.stop_gradient(y_star), args)


class Solved(NamedTuple):
    """One solve's outcome as :func:`polish_traced` needs it; ``out`` is the caller's own."""

    y: Any
    ok: bool
    cost: float
    steps: int
    out: Any


def is_stale(r_whole, r_near):
    """Whether a solve's residuals searched near their hints (``r_near``) differ from
    the whole-outline ones (``r_whole``) by more than ``STALE_TOL``: traced, jit-safe."""
    return jnp.max(jnp.abs(r_whole - r_near)) > STALE_TOL


# ------------------------------------------------------------------ control flow
#
# Two patterns as pure functions of arrays (jit / vmap / grad clean), each a
# ``lax.while_loop`` that traces its solve once: the bounded re-solve while stale and
# the Gauss-Newton round with its Levenberg-Marquardt fallback.  Under ``vmap`` a
# batched loop runs until every lane is done, masking the finished ones.


def _zeros(shapes):
    return jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)


def traced_once(fn: Callable[..., Any], *args) -> tuple[Callable[..., Any], Any]:
    """``fn`` traced once at ``args``: ``(replay, out_shapes)``, ``replay(*args)`` giving
    ``fn(*args)`` (for arguments of the same shapes) by evaluating the traced program
    rather than tracing ``fn`` again, and ``out_shapes`` the pytree of
    :class:`jax.ShapeDtypeStruct` of its result.  For control flow that needs the
    shapes of a branch's result before the branch (a skipped branch's zeros, a loop's
    first carry): :func:`jax.eval_shape` would trace ``fn`` a second time, which for a
    whole bundle is seconds."""
    closed, out_shapes = jax.make_jaxpr(fn, return_shape=True)(*args)
    out_tree = jax.tree_util.tree_structure(out_shapes)
    run = jax.extend.core.jaxpr_as_fun(closed)

    def replay(*a):
        return jax.tree_util.tree_unflatten(out_tree, run(*jax.tree_util.tree_leaves(a)))

    return replay, out_shapes


def until_fresh_traced(solve_once: Callable[[Any], tuple], y0, out0=None) -> tuple[Any, Any, Any]:
    """``solve_once(y) -> (out, y_end, steps, stale)`` (all
    arrays) run from ``y0``, then again from its end while ``stale``, ``RESOLVES``
    runs at most.  Returns ``(out, y_end, steps)`` of the last run (steps summed).

    The solver is traced once (inside the loop).  ``out0``: arrays shaped as ``out``
    (the loop's first carry, replaced by the first run), or None to find the shapes by
    tracing ``solve_once`` once more (:func:`jax.eval_shape`)."""
    if out0 is None:
        out0 = _zeros(jax.eval_shape(solve_once, y0)[0])

    def cond(c):
        i, stale = c[0], c[1]
        return (i == 0) | (stale & (i < RESOLVES))

    def body(c):
        i, _, y, steps, _ = c
        out, y_end, n, stale = solve_once(y)
        return i + 1, jnp.asarray(stale, bool), y_end, steps + jnp.asarray(n, jnp.int32), out

    init = (jnp.asarray(0, jnp.int32), jnp.asarray(True), y0, jnp.asarray(0, jnp.int32), out0)
    _, _, y, steps, out = jax.lax.while_loop(cond, body, init)
    return out, y, steps


def improves(cost, cost0):
    """Whether a polish round's end (cost ``cost``) is no worse than its start (``cost0``,
    to 1e-12 relative): else Levenberg-Marquardt starts again from the start."""
    return jnp.isfinite(cost) & (cost <= cost0 * (1 + 1e-12))


def pick(cond, a, b):
    """``a`` where ``cond`` else ``b``, leaf by leaf (two pytrees of one structure)."""
    return jax.tree_util.tree_map(lambda x, y: jnp.where(cond, x, y), a, b)


def polish_traced(run: Callable[[Any, Method], Solved], y0, cost0, gn: Method, lm: Method,
                  out0=None, retry=True) -> tuple[Solved, Any]:
    """Gauss-Newton (``gn``) from ``y0`` (cost ``cost0``), then,
    only where Gauss-Newton did not converge or ended above ``cost0``,
    Levenberg-Marquardt (``lm``) from the better of its end and ``y0``.  One
    ``lax.while_loop`` of at most two rounds with the method as data, so ``run(y,
    method)`` (returning a :class:`Solved` of arrays) is traced once: under ``vmap`` a
    lane that needs no second round idles while another runs it.  ``out0``: arrays
    shaped as ``Solved.out`` (None: found by tracing ``run`` once more).  ``retry``
    (bool, may be traced): False runs the first round only (one solve with ``gn``, which
    may then be a damped method too).  Returns ``(final, steps)``, the steps of both
    rounds."""
    if out0 is None:
        out0 = _zeros(jax.eval_shape(run, y0, gn).out)
    solved0 = Solved(y0, jnp.asarray(False), jnp.asarray(jnp.inf, jnp.float64), jnp.asarray(0, jnp.int32), out0)

    def cond(c):
        return c[0] < c[1]

    def body(c):
        i, _, start, _, steps = c
        got = run(start, pick(i == 0, gn, lm))
        improved = improves(got.cost, cost0)
        again = retry & (i == 0) & ~(got.ok & improved)  # Gauss-Newton failed: Levenberg-Marquardt
        start = pick(improved, got.y, y0)
        return i + 1, jnp.where(again, 2, 1).astype(jnp.int32), start, got, steps + jnp.asarray(got.steps, jnp.int32)

    init = (jnp.asarray(0, jnp.int32), jnp.asarray(1, jnp.int32), y0, solved0, jnp.asarray(0, jnp.int32))
    _, _, _, final, steps = jax.lax.while_loop(cond, body, init)
    return final, steps


def computed_as(value, fn: Callable[..., Any], *args):
    """``value``, already computed as ``fn(*args)`` (e.g. inside a solver's loop, on
    ``stop_gradient`` inputs), made differentiable as ``fn(*args)``: its tangent is
    ``jax.jvp(fn, args)``'s (``value``'s own tangent is ignored).  ``fn`` is traced
    only when differentiated, so a program that is not differentiated holds one copy
    of it, the one that computed ``value`` (half the compilation of tracing it again
    to differentiate it).  ``fn`` must close over nothing differentiated: pass every
    differentiable input in ``args``.  The caller guarantees ``value == fn(*args)``."""

    @jax.custom_jvp
    def given(value, *args):
        return value

    @given.defjvp
    def _jvp(primals, tangents):
        _, dout = jax.jvp(fn, primals[1:], tangents[1:])
        return primals[0], dout

    return given(value, *args)
