"""Radial distortion in the bundle (issue 18): how well do outlines of surfaces of
revolution determine K and k1, and what does ignoring the distortion cost?

Synthetic scenes (seeded; the seeds are printed): a random perturbed SOR
(:func:`sorjax.scenes.random_sor_scene`, objects anywhere in the image) in 3 to 6 views,
f uniform in [450, 1100] px on 640x480, unit aspect ratio (known to the calibration),
principal point within 5 % of the image centre, and OpenCV's radial distortion
k1 in {-0.3, -0.15, 0, +0.1} (k2 = 0) applied exactly to each pinhole silhouette.  The
same scene seeds serve every k1 (the poses differ only where a distorted outline had
to be redrawn).

Each trial runs what the core will run: the per-view homology fits on the observed
(distorted) outlines (:func:`sorjax.core.fit_homologies`), the linear seeds, the
distortion-free bundle and the bundle with k1 (:func:`sorjax.core._bundle.
bundle_estimate_distorted`), every real view used (views are padded to 6 and masked,
so one program serves all counts; the view verdicts' "not symmetric" drops are only
counted, in the column ``drops``).

Tables:

1. noise-free: worst K error over the scenes (max of |fu|, |fv|, |u0|, |v0| errors, % of
   f) and worst |k1 error| with k1 estimated; the focal error of the distortion-free
   bundle (mean and worst, % of f): what ignoring distortion costs.
2. the paper's noise (:func:`sorjax.scenes.paper_noise`) at sigma = 0.5 and 1 px: focal
   RMS (% of f) without and with k1 estimated, the mean focal bias of the
   distortion-free bundle, k1 RMS, the linearised standard deviations the bundle
   reports for f and k1 (mean over trials; the efficiency bound of the extended model
   to first order), and how often the evidence gate says k1 is determined
   (:func:`sorjax.core._distorted.distortion_gate`, declared outline error 0.1 px), with the
   medians of its RMS gain per sample ``g`` (px) and its z-score.

    python experiments/distortion.py            # 8 scenes, 3 noise draws each
    python experiments/distortion.py --quick    # 2 scenes, 1 noise draw
    python experiments/distortion.py --draws 0  # the noise-free table alone
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

import sorjax
from sorjax import scenes
from sorjax.core._distorted import (bundle_estimate_distorted, distortion_gate)
from sorjax.core._bundle import bundle_seeds
from sorjax.core._camera import transform_points
from sorjax.core import Options, fit_homologies, joint_transform
from sorjax.core._assess import USED, outline_radius, view_verdicts
from sorjax.experiment._runner import enable_compilation_cache

K1S = (-0.3, -0.15, 0.0, 0.1)
SIGMAS = (0.5, 1.0)
V_MAX = 6
M = 1024
OPTIONS = Options()
GROSS = 25.0  # % of f: a focal error beyond this is a gross failure (a wrong basin), not noise


def scene_camera(seed: int):
    """``(K, n_views)`` of scene ``seed``: f in [450, 1100] px, principal point within
    5 % of the centre of 640x480, 3-6 views."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(450.0, 1100.0)
    pp = (320.0 + rng.uniform(-32.0, 32.0), 240.0 + rng.uniform(-24.0, 24.0))
    return scenes.intrinsics(f, principal_point=pp), int(rng.integers(3, 7))


def make_scene(seed: int, k1: float):
    K, n = scene_camera(seed)
    return scenes.random_sor_scene(seed, n, K=K, distortion=None if k1 == 0.0 else (k1, 0.0))


@jax.jit
def trial(points, valid):
    """One calibration of padded (V_MAX, M, 2) pixel outlines: the distortion-free and
    the k1 bundle (unit aspect), and the per-view verdicts."""
    homs = fit_homologies(points, OPTIONS)
    aspect = jnp.asarray(1.0)
    T = joint_transform(points, valid)
    pn = transform_points(T, points)
    ln = homs.l_s @ jnp.linalg.inv(T)  # lines map by T^-T
    seeds, seed_ok = bundle_seeds(homs.v_x, homs.l_s, valid, T, aspect)
    out = bundle_estimate_distorted(pn, valid, homs.inliers.astype(jnp.float64), ln, seeds, seed_ok, aspect, T,
                                    OPTIONS, distortion="k1")
    drop = view_verdicts(homs.rms, homs.rms_untrimmed, outline_radius(points), homs.is_conic, homs.trimmed, valid,
                         OPTIONS)
    gate, _, _ = distortion_gate(out.delta, out.fit.n, jnp.sqrt(out.fit.s2), OPTIONS)
    return out, jnp.sum((drop != USED) & valid), gate


def padded(outlines):
    pts = [np.asarray(sorjax.make_outline(o, M).points) for o in outlines]
    valid = np.zeros(V_MAX, bool)
    valid[: len(pts)] = True
    pts += [pts[0]] * (V_MAX - len(pts))
    return jnp.asarray(np.stack(pts)), jnp.asarray(valid)


def run(outlines, K, k1):
    out, drops, gate = jax.block_until_ready(trial(*padded(outlines)))
    f = K[1, 1]
    Kd, Kf = np.asarray(out.fit.K), np.asarray(out.free.K)
    est = np.array([Kd[0, 0], Kd[1, 1], Kd[0, 2], Kd[1, 2]])
    tru = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    return dict(
        ok=bool(out.ok), k_err=100 * np.max(np.abs(est - tru)) / f, f_err=100 * (Kd[1, 1] - f) / f,
        f_free=100 * (Kf[1, 1] - f) / f, k1_err=float(out.k[0]) - k1, f_std=100 * float(np.sqrt(out.cov[1, 1])) / f,
        k1_std=float(out.k_std[0]), drops=int(drops), gate=bool(gate), delta=float(out.delta),
        g_px=float(np.sqrt(max(float(out.delta), 0.0) / float(out.fit.n))),
        z=float(np.sqrt(max(float(out.delta), 0.0) / float(out.fit.s2))),
    )


def rms(x):
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 scenes, 1 noise draw each (a few minutes)")
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--draws", type=int, default=3, help="noise draws per scene and sigma (0: the noise-free table alone)")
    ap.add_argument("--seed", type=int, default=1800, help="first scene seed")
    ap.add_argument("--save", help="write every trial's numbers to this JSON file")
    args = ap.parse_args()
    enable_compilation_cache()
    n_sc, draws = (2, 1) if args.quick else (args.scenes, args.draws)
    seeds = list(range(args.seed, args.seed + n_sc))
    print(f"scene seeds {seeds[0]}..{seeds[-1]}; noise seed of (scene s, sigma index i, draw d, view j): "
          f"s * 1000 + i * 100 + d * 10 + j")
    t0 = time.time()
    rows = {}
    for k1 in K1S:
        for s in seeds:
            sc = make_scene(s, k1)
            K = sc.K
            r0 = run(sc.outlines, K, k1)
            noisy = []
            for i, sig in enumerate(SIGMAS):
                for d in range(draws):
                    outl = [scenes.paper_noise(o, sig, s * 1000 + i * 100 + d * 10 + j) for j, o in enumerate(sc.outlines)]
                    noisy.append((sig, run(outl, K, k1)))
            rows[(k1, s)] = (sc, r0, noisy)
            print(f"  k1 {k1:+.2f} scene {s}: f {K[1, 1]:.0f} px, {len(sc.views)} views, noise-free K err "
                  f"{r0['k_err']:.2e} % f, k1 err {r0['k1_err']:+.1e}, free bundle f err {r0['f_free']:+.2f} % "
                  f"({time.time() - t0:.0f} s)", flush=True)

    print("\nnoise-free (k1 estimated; the distortion-free bundle beside it)")
    print("   k1  | scenes | fails | worst K err % f | worst |k1 err| | free f err % f: median, worst | drops")
    for k1 in K1S:
        r = [rows[(k1, s)][1] for s in seeds]
        ok = [x for x in r if x["ok"]]
        print(f" {k1:+.2f} | {len(r):6d} | {len(r) - len(ok):5d} | {max(x['k_err'] for x in ok):15.2e} | "
              f"{max(abs(x['k1_err']) for x in ok):14.1e} | {np.median([x['f_free'] for x in r]):+8.2f}, "
              f"{max((x['f_free'] for x in r), key=abs):+8.2f} | {sum(x['drops'] for x in r)}")

    if not draws:  # --draws 0: the noise-free table alone
        print(f"\n{time.time() - t0:.0f} s")
        return
    print(f"\npaper noise (unit aspect known); focal errors in % of f; a trial is gross when |f err| > {GROSS:g} %")
    print("(RMS and bias over the trials that are not gross; 'bound': the median linearised std of f the bundle "
          "with k1 reports, the extended model's efficiency bound to first order; 'err/std': median |f err| / std)")
    print("   k1  | sigma | trials | fails || free: gross | med |err| | RMS    | bias    || k1: gross | med |err| | "
          "RMS    | bound  | err/std | k1 RMS  | med k1 std | gate k1 | med g px | med z | drops")
    for k1 in K1S:
        for sig in SIGMAS:
            r = [x for s in seeds for (g, x) in rows[(k1, s)][2] if g == sig]
            ok = [x for x in r if x["ok"]]
            free = np.array([x["f_free"] for x in r])
            fk = np.array([x["f_err"] for x in ok])
            fine_free, fine_k = np.abs(free) <= GROSS, np.abs(fk) <= GROSS
            good = [x for x, f in zip(ok, fine_k) if f]
            print(f" {k1:+.2f} | {sig:5.1f} | {len(r):6d} | {len(r) - len(ok):5d} || {np.sum(~fine_free):11d} | "
                  f"{np.median(np.abs(free)):9.2f} | {rms(free[fine_free]):6.2f} | {np.mean(free[fine_free]):+7.2f} || "
                  f"{np.sum(~fine_k):9d} | {np.median(np.abs(fk)):9.2f} | {rms(fk[fine_k]):6.2f} | "
                  f"{np.median([x['f_std'] for x in good]):6.2f} | "
                  f"{np.median([abs(x['f_err']) / x['f_std'] for x in good]):7.2f} | "
                  f"{rms([x['k1_err'] for x in good]):7.4f} | {np.median([x['k1_std'] for x in good]):10.4f} | "
                  f"{sum(x['gate'] for x in r):3d}/{len(r):<3d} | {np.median([x['g_px'] for x in r]):8.3f} | "
                  f"{np.median([x['z'] for x in r]):5.1f} | {sum(x['drops'] for x in r)}")
    if args.save:
        out = {f"{k1:+.2f}/{s}": dict(noise_free=rows[(k1, s)][1], noisy=[dict(sigma=g, **x) for g, x in rows[(k1, s)][2]])
               for k1 in K1S for s in seeds}
        with open(args.save, "w") as fh:
            json.dump(dict(seeds=seeds, draws=draws, trials=out), fh, indent=1)
        print(f"per-trial results: {args.save}")
    print(f"\n{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
