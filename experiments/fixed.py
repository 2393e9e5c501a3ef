"""Fixed intrinsics (issue 18, items 2 and 3): the focal length from ONE view when the
principal point is known, against the view's angle theta (paper, eq. 37), and every
fixed-parameter combination on random scenes.

Table 1, single view.  A vase (:func:`sorjax.scenes.vase`) seen from 20 deg above, its
centre moved ``d`` px right of the principal point (:func:`sorjax.scenes.pose_at_pixel`),
K = diag(f, f) with the principal point (320, 240) on 640x480, f = 600 and 1200 px.
``theta`` is the angle between the optical axis and the plane through the revolution
axis and the camera centre (eq. 37; :func:`sorjax._messages._view_angles_deg` at the
truth): 0 when the object sits on the principal point (v_x at infinity).  Each
outline is calibrated alone with ``principal_point`` at the truth (aspect ratio 1):
noise-free (focal error, % of f, and the result code), and with the paper's noise
(:func:`sorjax.scenes.paper_noise`, sigma 0.5 px) over noise seeds 0..S-1 (focal RMS,
% of f, over the successful ones; the bundle's mean reported std; how many calibrations
succeeded; how many successes lie beyond 3 of their reported std and the worst
z = (f_est - f) / std).  The paper's eq. 37 predicts an error ~ f eps / (2 w tan theta).

Table 2, every fixed-parameter combination on random SOR scenes
(:func:`sorjax.scenes.random_sor_scene`, seeds printed, 3 views, aspect ratio in [0.9,
1.1]; "+a": the true aspect ratio passed, always with a fixed focal length), noise-free:
worst |K error| (% of f).

    python experiments/fixed.py            # 5 noise seeds, 3 scenes
    python experiments/fixed.py --quick    # 2 noise seeds, 1 scene
    python experiments/fixed.py --seeds 20 # the single view's tail (docs/results.md)
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import sorjax
from sorjax import scenes
from sorjax._messages import _view_angles_deg, code_name

from _common import recorded

OFFSETS = (0.0, 5.0, 15.0, 40.0, 80.0, 140.0, 200.0)  # px right of the principal point
FOCALS = (600.0, 1200.0)
PP = (320.0, 240.0)
SIGMA = 0.5


def single_view_table(n_seeds: int) -> None:
    prof = scenes.vase()
    print(f"\nTable 1: one view, principal point fixed at the truth {PP}, aspect 1; noise: paper_noise "
          f"sigma {SIGMA} px, seeds 0..{n_seeds - 1}")
    print("     f   d(px)  theta(deg)  noise-free err %  code            noisy RMS %  mean std %  |z|>3  worst z  ok   "
          "refused")
    for f in FOCALS:
        K = scenes.intrinsics(f, principal_point=PP)
        for d in OFFSETS:
            sc = scenes.sor_scene(prof, K, [scenes.pose_at_pixel(prof, K, 20.0, 30.0, pixel=(PP[0] + d, PP[1]))])
            v = sc.views[0]
            theta = float(_view_angles_deg(K, v.v_x[None])[0])
            cal, _ = recorded(sorjax.calibrate, [v.outline], principal_point=PP, outline_error=0.0)
            err = 100 * (cal.fv - f) / f if cal.success else math.nan
            errs, stds, refused = [], [], {}
            for s in range(n_seeds):
                noisy = scenes.paper_noise(v.outline, SIGMA, s)
                c, _ = recorded(sorjax.calibrate, [noisy], principal_point=PP, outline_error=0.0)
                if not isinstance(c, Exception) and c.success:
                    errs.append((c.fv - f) / f)
                    stds.append(c.std[1] / f)
                else:
                    name = code_name(c.result) if not isinstance(c, Exception) else "error"
                    refused[name] = refused.get(name, 0) + 1
            rms = 100 * math.sqrt(np.mean(np.square(errs))) if errs else math.nan
            sd = 100 * float(np.mean(stds)) if stds else math.nan
            z = np.asarray(errs) / np.asarray(stds) if errs else np.zeros(0)  # (f_est - f) / its reported std
            worst = f"{z[np.argmax(np.abs(z))]:+7.1f}" if len(z) else "      -"
            print(f"{f:6.0f} {d:7.0f} {theta:11.3f} {err:17.2e}  {code_name(cal.result):15s} {rms:11.3f} {sd:11.3f}"
                  f"  {int(np.sum(np.abs(z) > 3)):5d}  {worst}  {len(errs)}/{n_seeds}  "
                  + ", ".join(f"{k} {n}" for k, n in refused.items()))
            if not cal.success and d == 0.0:
                print(f"        refused: {cal.message[:400]}")


COMBOS = (("pp", True, False, False), ("pp+a", True, False, True), ("focal+a", False, True, True),
          ("pp+focal+a", True, True, True))


def combinations_table(seeds) -> None:
    print(f"\nTable 2: fixed-parameter combinations, noise-free random scenes (seeds {list(seeds)}, 3 views): worst "
          "|K error| % of f (fixed values at the truth)")
    print(" scene    f      a      " + "  ".join(f"{n:>12s}" for n, _, _, _ in COMBOS))
    for seed in seeds:
        sc = scenes.random_sor_scene(seed, n_views=3, vary_aspect=True)
        K = np.asarray(sc.K)
        a_true = K[0, 0] / K[1, 1]
        row = []
        for _, pp, foc, a in COMBOS:
            kw = dict(principal_point=(K[0, 2], K[1, 2])) if pp else {}
            if foc:
                kw["focal_length"] = float(K[1, 1])
            if a:
                kw["aspect_ratio"] = float(a_true)
            cal, _ = recorded(sorjax.calibrate, sc.outlines, outline_error=0.0, **kw)
            e = np.max(np.abs(np.asarray(cal.K) - K)) / K[1, 1] * 100 if cal.success else math.nan
            row.append(f"{e:12.2e}" if cal.success else f"{code_name(cal.result)[:12]:>12s}")
        print(f" {seed:5d} {K[1, 1]:6.0f} {a_true:6.3f}  " + "  ".join(row))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--seeds", type=int, default=5, help="noise seeds per single-view cell (default 5)")
    args = p.parse_args()
    t = time.time()
    single_view_table(2 if args.quick else args.seeds)
    combinations_table(range(1) if args.quick else range(3))
    print(f"\n{time.time() - t:.0f} s")


if __name__ == "__main__":
    main()
