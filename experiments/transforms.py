"""The functional core under JAX's transformations (prints figures; seeded).

* ``jax.jit(jax.vmap(core.calibrate))`` over ``--trials`` noisy draws of the paper's
  two-sphere scene against the same number of single jitted calls, and against
  ``jax.lax.map`` (the runner's compiled loop): the largest relative difference of K
  and whether every result code agrees (issue 16: K to 1e-9 relative over 64 trials);
* the gradient of the bundle's fv with respect to the outline points
  (``jax.grad`` through :func:`sorjax.core.calibrate_homologies`, the optimum
  differentiated by the implicit function theorem, the per-view fits held fixed)
  against central finite differences, for a few points moved along their normals.

    python experiments/transforms.py --trials 64 --seed 0
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import sorjax
from sorjax import core, scenes


def draw(n: int, seed: int, sigma: float, f: float):
    scene = scenes.two_spheres(f)
    rng = np.random.default_rng(seed)
    return np.stack([
        np.stack([np.asarray(sorjax.make_outline(scenes.paper_noise(o, sigma, rng)).points) for o in scene.outlines])
        for _ in range(n)])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sigma", type=float, default=1.0)
    p.add_argument("--f", type=float, default=700.0)
    a = p.parse_args()
    opts = core.Options(outline_error_px=0.0)
    P = draw(max(a.trials, 1), a.seed, a.sigma, a.f)
    print(f"two spheres, f = {a.f:g} px, sigma = {a.sigma:g} px, {a.trials} trials, seed {a.seed}; "
          f"backend {jax.default_backend()}, {len(jax.devices())} device(s)")

    def one(points):
        return core.calibrate(points, "bundle", jnp.nan, options=opts)

    rows = []
    for name, fn in () if a.trials == 0 else (("single jit calls", None), ("jit(lax.map)", jax.jit(lambda X: jax.lax.map(one, X))),
                     ("jit(vmap)", jax.jit(jax.vmap(one)))):
        t0 = time.perf_counter()
        if fn is None:
            single = jax.jit(one)
            out = [single(x) for x in P]
            out = jax.tree_util.tree_map(lambda *x: np.stack(x), *out)
        else:
            out = jax.block_until_ready(fn(P))
        rows.append((name, jax.tree_util.tree_map(np.asarray, out), time.perf_counter() - t0))
    for name, out, secs in rows:
        ref = rows[0][1]
        rel = np.abs(out.K - ref.K).max(axis=(1, 2)) / np.abs(ref.K).max(axis=(1, 2))
        same = np.array_equal(np.asarray(out.result._value), np.asarray(ref.result._value))
        worst = int(np.argmax(rel))
        print(f"  {name:17s} {secs:7.1f} s (compile included)  max |dK| / |K| = {rel.max():.2e} (trial {worst}, "
              f"{int(out.steps[worst])} bundle steps), {int(np.sum(rel <= 1e-9))} of {len(rel)} trials within 1e-9; "
              f"codes equal: {same}")
    if rows:
        print(f"  successes: {int(np.sum(np.asarray(rows[0][1].result._value) == 0))} of {a.trials}")

    # gradient of fv against central differences (per-view fits held fixed)
    points = jnp.asarray(P[0])
    homs = jax.jit(core.fit_homologies)(points, opts)
    fv = jax.jit(lambda x: core.calibrate_homologies(x, homs, "bundle", jnp.nan, options=opts).K_raw[1, 1])
    g = np.asarray(jax.jit(jax.grad(lambda x: core.calibrate_homologies(
        x, homs, "bundle", jnp.nan, options=opts).K_raw[1, 1]))(points))
    h = 1e-4
    worst = 0.0
    for view, k in ((0, 100), (1, 700), (2, 1500)):
        t = P[0][view, (k + 1) % P.shape[2]] - P[0][view, k - 1]
        n = np.array([t[1], -t[0]]) / np.hypot(*t)
        d = np.zeros_like(P[0])
        d[view, k] = h * n
        fd = (float(fv(points + d)) - float(fv(points - d))) / (2 * h)
        an = float(g[view, k] @ n)
        worst = max(worst, abs(an - fd) / max(abs(fd), 1e-12))
        print(f"  d fv / d point (view {view}, point {k}, along its normal): grad {an:+.6f}  central diff {fd:+.6f}")
    print(f"  largest relative difference {worst:.1e}")


if __name__ == "__main__":
    main()
