"""Homologies passed in with ``calibrate(homologies=...)``: how well does each map its outline?

The check (``sorjax._calibration_checks._check_homologies``, issue 42) reads each
outline's RMS symmetry residual under the homology given for it
(:func:`sorjax._homology.homology_residual`: eq. 20 at the fit's own samples, over the
samples it kept) and refuses the homology when that exceeds ``Options.homology_ratio``
times the homology's own fitted residual ``Homology.rms`` (at least
``Options.check_floor_px``).  This script measures that ratio

* for homologies fitted on the very outline (``matched``: ``n_samples`` 20, 50, 100), and
  on variants of it (``--variants``: the same curve started elsewhere or reversed,
  resampled to 1024 points, fitted with ``robust=False`` or ``smooth_px=1``, an
  outline with a bump trimmed by the robust fit, at 50 samples too);
* for homologies fitted on another outline: the same view seen by a camera with
  f = 1400 px instead of 800 (``camera``: same poses, the outline about as large and in
  the same place), another view of the scene (``view``), the outline moved by 2-5 px in
  a random direction (``shift``), another object (``object``, ``--variants``);

on the two-sphere scene and three random SOR scenes (3 views each), with the paper's
noise and i.i.d. Gaussian noise of 0.5, 1 and 2 px (``--variants``: the paper's noise of
0, 0.5, 1, 2 px).  It prints min / median / max of the ratio per case, and the share
of each case a threshold refuses.

    python experiments/user_homologies.py
    python experiments/user_homologies.py --variants
"""

from __future__ import annotations

import argparse
import itertools
import warnings

import numpy as np

import sorjax
from sorjax import scenes
from sorjax._homology import homology_residual
from sorjax._scene_camera import intrinsics

FLOOR = sorjax.Options().check_floor_px


def scene_pairs():
    """``(name, outlines at f = 800, the same views at f = 1400)``."""
    yield "spheres", scenes.two_spheres(f=800.0).outlines, scenes.two_spheres(f=1400.0).outlines
    for seed in (1, 2, 3):
        ka, kb = (intrinsics(f, principal_point=(330.0, 235.0)) for f in (800.0, 1400.0))
        yield (f"sor{seed}", scenes.random_sor_scene(seed, n_views=3, K=ka).outlines,
               scenes.random_sor_scene(seed, n_views=3, K=kb).outlines)


def noisy(outs, kind, sigma, seed):
    if sigma == 0:
        return [np.asarray(o, float) for o in outs]
    add = scenes.paper_noise if kind == "paper" else scenes.gaussian_noise
    return [add(o, sigma, seed + i) for i, o in enumerate(outs)]


def main_cases(rng, sizes):
    rows = []
    for name, A, B in scene_pairs():
        for kind, sigma in itertools.product(("paper", "gauss"), (0.5, 1.0, 2.0)):
            seed = int(rng.integers(1 << 30))
            na, nb = noisy(A, kind, sigma, seed), noisy(B, kind, sigma, seed)
            moved = [o + rng.uniform(2, 5) * np.array([np.cos(t), np.sin(t)])
                     for o, t in zip(na, rng.uniform(0, 2 * np.pi, len(na)))]
            try:
                [sorjax.make_outline(o) for o in na + nb + moved]
            except ValueError:  # Gaussian noise of 2 px on a 0.3 px spacing can cross the outline over itself
                continue
            for n in sizes:
                ha, hb, hs = ([sorjax.fit_homology(o, n_samples=n) for o in x] for x in (na, nb, moved))
                V = len(na)
                cases = ([("matched", i, ha[i]) for i in range(V)] + [("camera", i, hb[i]) for i in range(V)]
                         + [("view", i, ha[(i + 1) % V]) for i in range(V)] + [("shift", i, hs[i]) for i in range(V)])
                r = homology_residual([na[i] for _, i, _ in cases], [h for _, _, h in cases])
                rows += [(c, name, f"{kind} {sigma:g} px, N={n}", ri / max(float(h.rms), FLOOR))
                         for (c, i, h), ri in zip(cases, r)]
        print(f"{name}: {len(rows)} cases so far", flush=True)
    return rows


def variant_cases(rng):
    rows = []
    ka = intrinsics(800.0, principal_point=(330.0, 235.0))
    sc = [("spheres", scenes.two_spheres(f=800.0).outlines)] + [
        (f"sor{s}", scenes.random_sor_scene(s, n_views=3, K=ka).outlines) for s in (1, 2, 3)]

    def add(case, o, h, name, sigma):
        r = float(homology_residual([o], [h])[0])
        rows.append((case, name, f"paper {sigma:g} px", r / max(float(h.rms), FLOOR)))

    for j, (name, outs) in enumerate(sc):
        for sigma in (0.0, 0.5, 1.0, 2.0):
            for i, o in enumerate(noisy(outs, "paper", sigma, int(rng.integers(1 << 30)))):
                add("matched", o, sorjax.fit_homology(o), name, sigma)
                add("matched: n_points 1024", o, sorjax.fit_homology(o, n_points=1024), name, sigma)
                add("matched: started elsewhere", o,
                    sorjax.fit_homology(np.roll(o, int(rng.integers(1, len(o))), axis=0)), name, sigma)
                add("matched: reversed", o, sorjax.fit_homology(o[::-1]), name, sigma)
                add("matched: robust=False", o, sorjax.fit_homology(o, robust=False), name, sigma)
                add("matched: smooth_px=1", o, sorjax.fit_homology(o, smooth_px=1.0), name, sigma)
                b = np.array(o, float)
                c, k = b.mean(0), slice(len(b) // 8, len(b) // 8 + len(b) // 40)
                b[k] = c + (b[k] - c) * 1.03  # a bump 3 % out: trimmed by the robust fit
                add("matched: bump (trimmed)", b, sorjax.fit_homology(b), name, sigma)
                add("matched: bump, N=50", b, sorjax.fit_homology(b, n_samples=50), name, sigma)
                add("object", o, sorjax.fit_homology(sc[(j + 1) % len(sc)][1][i]), name, sigma)
        print(f"{name}: {len(rows)} variant cases so far", flush=True)
    return rows


def report(rows, thresholds):
    cases = sorted({r[0] for r in rows}, key=lambda c: (not c.startswith("matched"), c))
    head = f"{'case':28s} {'n':>4s} {'min':>9s} {'median':>9s} {'max':>9s}  refused at "
    print(head + ", ".join(map(str, thresholds)))
    for c in cases:
        q = np.array([r[3] for r in rows if r[0] == c])
        share = ", ".join(f"{np.mean(~(q <= t)):.0%}" for t in thresholds)
        print(f"{c:28s} {len(q):4d} {q.min():9.4g} {np.median(q):9.4g} {q.max():9.4g}  {share}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", action="store_true", help="also the variants of the matched fits and other objects")
    ap.add_argument("--sizes", default="20,50,100", help="n_samples of the fits (comma-separated)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(args.seed)
    rows = main_cases(rng, [int(s) for s in args.sizes.split(",")])
    if args.variants:
        rows += variant_cases(rng)
    report(rows, (1.25, 1.5, 2.0))


if __name__ == "__main__":
    main()
