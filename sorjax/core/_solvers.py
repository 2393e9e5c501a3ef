"""Least-squares solvers shared by the per-view fit (eq. 20) and the bundle.

Both minimise a sum of squared distances from a few starting points, in two stages:

* **screen** every start with a few loose Levenberg-Marquardt steps and keep the one of
  lowest cost (a start far from the minimum needs the damping);
* **polish** that one to convergence by Gauss-Newton (full steps: near a minimum of
  these small-residual problems it takes about half of Levenberg-Marquardt's steps,
  whose damping decays slowly), and by Levenberg-Marquardt where Gauss-Newton fails or
  ends above its start (:func:`polish`).

The Gauss-Newton step is a truncated-SVD least-squares solve: it never moves along a
direction whose singular value is below ``NULL_RCOND`` of the largest, i.e. one the data
do not determine (``NULL_RCOND^2`` is the bundle covariance's null eigenvalue
threshold).  With a plain QR step, a degenerate view set (a level camera and upright
objects, free aspect ratio) let fv drift from 800 to 1025 px along its null direction,
where the damped Levenberg-Marquardt step stays put.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

NULL_RCOND = 1e-6
# The solvers search each closest point of the distance fields only near where it was at
# the start (sorjax.core._field.closest_parameter_near); a solve whose residuals differ from
# whole-outline ones by more than STALE_TOL (normalised units, ~1e-7 px: another closest
# point, not round-off) is "stale" and is run again from its end, RESOLVES times at most.
STALE_TOL = 1e-9
RESOLVES = 3
SCREEN = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-6)


def solvers(rtol: float, atol: float) -> dict[str, Any]:
    """The three optimistix solvers by name: "lm" (Levenberg-Marquardt), "gn"
    (Gauss-Newton, truncated SVD) with tolerances ``rtol, atol``, and "screen"."""
    return {
        "lm": optx.LevenbergMarquardt(rtol=rtol, atol=atol),
        "gn": optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.SVD(rcond=NULL_RCOND)),
        "screen": SCREEN,
    }


class Solved(NamedTuple):
    """One solve's outcome as :func:`polish` needs it; ``out`` is the caller's own."""

    y: Any
    ok: bool
    cost: float
    steps: int
    out: Any


def is_stale(r_whole, r_near):
    """Whether a solve's residuals searched near their hints (``r_near``) differ from
    the whole-outline ones (``r_whole``) by more than ``STALE_TOL``: traced, jit-safe."""
    return jnp.max(jnp.abs(r_whole - r_near)) > STALE_TOL


def until_fresh(solve_once: Callable[[Any], tuple], y0) -> tuple[Any, int]:
    """``solve_once(y) -> (out, y_end, steps, stale)``, run from ``y0`` and again from
    its end while it reports ``stale`` (``RESOLVES`` runs at most).  Returns the last
    ``out`` and the steps of all runs."""
    steps, y = 0, y0
    for _ in range(RESOLVES):
        out, y, n, stale = solve_once(y)
        steps += n
        if not stale:
            break
    return out, steps


def polish(run: Callable[[Any, str], Solved], y0, cost0: float) -> tuple[Solved, int]:
    """Gauss-Newton from ``y0`` (of cost ``cost0``); when it does not converge or ends
    above ``cost0``, Levenberg-Marquardt from the better of its end and ``y0`` (Gauss-
    Newton can cycle in a flat valley).  ``run(y, method)`` solves from ``y``.  Returns
    the final :class:`Solved` and the steps of both."""
    gn = run(y0, "gn")
    improved = bool(np.isfinite(gn.cost) and gn.cost <= cost0 * (1 + 1e-12))
    if gn.ok and improved:
        return gn, gn.steps
    lm = run(gn.y if improved else y0, "lm")
    return lm, gn.steps + lm.steps


# ------------------------------------------------------------------ traced versions
#
# The same two control-flow patterns as pure functions of arrays (jit / vmap / grad
# clean): ``lax.while_loop`` for the bounded re-solve and a select for the fallback.
# Under ``vmap`` a batched loop runs until every lane is done, masking the finished
# ones; the fallback solve starts from the Gauss-Newton end when that improved on the
# start, so a lane that did not need it converges in a step or two.


def until_fresh_traced(solve_once: Callable[[Any], tuple], y0) -> tuple[Any, Any, Any]:
    """Traced :func:`until_fresh`: ``solve_once(y) -> (out, y_end, steps, stale)`` (all
    arrays) run from ``y0``, then again from its end while ``stale``, ``RESOLVES``
    runs at most.  Returns ``(out, y_end, steps)`` of the last run (steps summed).

    The solver is traced once (inside the loop); the loop's first ``out`` is zeros of
    the right shapes, replaced by the first run."""

    shapes = jax.eval_shape(solve_once, y0)
    zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes[0])

    def cond(c):
        i, stale = c[0], c[1]
        return (i == 0) | (stale & (i < RESOLVES))

    def body(c):
        i, _, y, steps, _ = c
        out, y_end, n, stale = solve_once(y)
        return i + 1, jnp.asarray(stale, bool), y_end, steps + jnp.asarray(n, jnp.int32), out

    init = (jnp.asarray(0, jnp.int32), jnp.asarray(True), y0, jnp.asarray(0, jnp.int32), zeros)
    _, _, y, steps, out = jax.lax.while_loop(cond, body, init)
    return out, y, steps


def polish_traced(run: Callable[[Any, str], Solved], y0, cost0) -> tuple[Solved, Any]:
    """Traced :func:`polish`: Gauss-Newton from ``y0`` (cost ``cost0``), then, only
    where Gauss-Newton did not converge or ended above ``cost0``, Levenberg-Marquardt
    from the better of its end and ``y0`` (``lax.cond``: skipped when not needed, except
    under ``vmap``, where both run and the result is selected).  ``run(y, method)``
    returns a :class:`Solved` of arrays.  Returns ``(final, steps)``, the steps
    counting both solves where the second was needed."""
    gn = run(y0, "gn")
    improved = jnp.isfinite(gn.cost) & (gn.cost <= cost0 * (1 + 1e-12))
    use_gn = gn.ok & improved
    start = jax.tree_util.tree_map(lambda a, b: jnp.where(improved, a, b), gn.y, y0)
    final = jax.lax.cond(use_gn, lambda: gn, lambda: run(start, "lm"))
    steps = gn.steps + jnp.where(use_gn, 0, final.steps)
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
