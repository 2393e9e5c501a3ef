"""Model checks (issue 19): what sorjax.calibrate reports for misspecified models, and
what the checks cost.

Each case is a synthetic scene with known K (exact outlines unless said; noise from
the paper's model with the seed shown).  For each, the result code, the focal length
with its standard deviation, the error in % of f and in standard deviations, and the
checks' verdict.  "Confident wrong K" would be a success with an error above 3 std; a
refusal (K NaN) or a warning with a widened std are the acceptable outcomes.  Then the
warm time of one calibration (3 views) with the aspect ratio free (no extra solve:
the score test only) and known (one more bundle solve, the free fit), as ratios in one
run.

    python experiments/checks.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import sorjax
from sorjax import scenes
from sorjax._messages import code_name

VERDICTS = ("ok", "widened", "contradicted")
CULPRITS = ("", " (aspect)", " (views)", " (lens)", " (fixed)")


def planar_leaf(K):
    """A flat mirror-symmetric figure on a tilted plane (not a surface of revolution)."""
    t = np.linspace(0, 2 * np.pi, 1200, endpoint=False)
    X = np.stack([0.05 * np.sin(t) * (1 + 0.4 * np.cos(t)), 0.08 * np.cos(t), np.zeros_like(t)], 1)
    C = np.array([0.25, 0.2, 0.35])
    R, _ = scenes.look_at(C, (0.0, 0.0, 0.0))
    x = (K @ (R @ (X - C).T)).T
    return x[:, :2] / x[:, 2:]


def cases():
    sq = scenes.two_spheres(f=800.0)
    ne = scenes.two_spheres(f=800.0, aspect_ratio=1.02)
    a, b = scenes.two_spheres(f=700.0), scenes.two_spheres(f=1400.0)
    two = list(a.outlines)[:2] + list(b.outlines)[:2]
    yield "square pixels, aspect_ratio=1.0 (right)", sq.K, sq.outlines, dict(aspect_ratio=1.0)
    yield "square pixels, aspect_ratio=1.01", sq.K, sq.outlines, dict(aspect_ratio=1.01)
    yield "square pixels, aspect_ratio=1.01, outline_error=0", sq.K, sq.outlines, dict(aspect_ratio=1.01,
                                                                                        outline_error=0.0)
    yield "square pixels, aspect_ratio=1.1", sq.K, sq.outlines, dict(aspect_ratio=1.1)
    yield "fu/fv = 1.02, aspect_ratio=1.0", ne.K, ne.outlines, dict(aspect_ratio=1.0)
    yield "2 views f=700 + 2 views f=1400", a.K, two, {}
    yield "2 views f=700 + 2 views f=1400, outline_error=0", a.K, two, dict(outline_error=0.0)
    yield "3 views + a flat symmetric figure, outline_error=0", sq.K, list(sq.outlines) + [planar_leaf(sq.K)], dict(
        outline_error=0.0)
    yield "3 views + view 1 again", sq.K, list(sq.outlines) + [sq.outlines[1]], {}
    # what the model holds (issue 18): lens distortion at k1 = 0, fixed intrinsics
    for k1 in (-0.05, 0.05):
        bd = scenes.random_sor_scene(1801, 4, distortion=(k1, 0.0))
        yield f"lens k1 = {k1:+.2f}, distortion='none' (random SOR 1801)", bd.K, bd.outlines, {}
        yield f"lens k1 = {k1:+.2f}, distortion='none', outline_error=0", bd.K, bd.outlines, dict(outline_error=0.0)
        yield f"lens k1 = {k1:+.2f}, distortion='k1', outline_error=0", bd.K, bd.outlines, dict(
            outline_error=0.0, distortion="k1")
    cx, cy = sq.K[0, 2], sq.K[1, 2]
    for off in (0.0, 3.0, 20.0):
        yield (f"principal point fixed {off:g} px off", sq.K, sq.outlines, dict(principal_point=(cx + off, cy - off)))
    yield ("principal point fixed 20 px off, outline_error=0", sq.K, sq.outlines,
           dict(principal_point=(cx + 20, cy - 20), outline_error=0.0))
    for s in range(3):
        yield (f"np.round(noisy outline) sigma 0.5, seed {100 + s}", sq.K,
               [np.round(scenes.paper_noise(o, 0.5, 100 + s + 10 * i)[::8]) for i, o in enumerate(sq.outlines)], {})
    for s in range(3):
        yield (f"consistent views, paper noise 1 px, seed {50 * s}, outline_error=0", sq.K,
               [scenes.paper_noise(o, 1.0, 50 * s + i) for i, o in enumerate(sq.outlines)], dict(outline_error=0.0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5, help="warm calibrations timed per model (default 5)")
    args = p.parse_args(argv)
    print(f"{'case':56s} {'result':22s} {'fv +- std (px)':>18s} {'err %f':>7s} {'err/std':>7s} "
          f"{'checks':>22s} {'confident wrong':>15s}")
    for name, K, outs, kw in cases():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cal = sorjax.calibrate(outs, **kw)
        e = np.array([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]])
        z = np.abs(e) / np.asarray(cal.std)
        zmax = float(np.nanmax(z)) if np.any(np.isfinite(z)) else float("nan")
        wrong = cal.success and zmax > 3
        print(f"{name:56s} {code_name(cal.result):22s} {cal.fv:9.1f} +- {cal.std[1]:<6.3g} "
              f"{100 * np.nanmax(np.abs(e)) / K[1, 1] if np.any(np.isfinite(e)) else float('nan'):7.2f} "
              f"{zmax:7.2f} {VERDICTS[int(cal.checks.verdict)] + CULPRITS[int(cal.checks.culprit)]:>22s} {'YES' if wrong else 'no':>15s}")
    sc = scenes.two_spheres(f=700.0)
    outs = [scenes.paper_noise(o, 1.0, 7 + i) for i, o in enumerate(sc.outlines)]
    homs = tuple(sorjax.fit_homology(o) for o in outs)
    times = {}
    for label, kw in (("aspect free (score test only)", {}), ("aspect known (+ the free fit)", dict(aspect_ratio=1.0))):
        sorjax.calibrate(outs, homologies=homs, **kw)  # compile
        t0 = time.perf_counter()
        for _ in range(args.repeats):
            sorjax.calibrate(outs, homologies=homs, **kw)
        times[label] = (time.perf_counter() - t0) / args.repeats
    base = times["aspect free (score test only)"]
    print("\nwarm time of one calibration from fitted homologies (3 views; all four methods run, as calibrate does):")
    for k, v in times.items():
        print(f"  {k:32s} {1000 * v:7.1f} ms   ratio {v / base:.2f}")


if __name__ == "__main__":
    main()
