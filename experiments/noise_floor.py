"""Is the reported uncertainty right for outlines averaged with their own mirror image?

Each trial puts the paper's noise (``scenes.paper_noise``, sigma px, smoothed along the
curve) on the three outlines of ``scenes.two_spheres`` (f = 700 px, or ``--f``) and calibrates
them three ways with the bundle (``outline_error=0``, as a synthetic study):

* ``raw``: the noisy outlines;
* ``averaged``: each outline averaged with its own mirror image under its robust
  homology fit (:func:`sorjax._detect.symmetric_average`, every point confirmed, as
  :func:`sorjax.outlines_from_image` does), no noise floor: symmetric by construction,
  the residuals no longer show the noise;
* ``averaged + floor``: the same outlines with each one's symmetry residual before the
  averaging as its noise floor (``calibrate(outline_noise=...)``, what
  ``ImageOutline.noise_rms`` carries), the noise's correlation length read off the
  averaged outlines' residuals (as in session 24);
* ``averaged + floor + ell``: the same with the correlation length of the noise before
  the averaging as well (``calibrate(outline_noise_ell=...)``, what
  ``ImageOutline.noise_ell`` carries).

It prints, per way, the cameras calibrated, the RMS focal error, the median reported
std and the RMS of ``z = error / std`` per intrinsic (1 when the std is right, below 1
when it is too large); and, per outline, how ``core.with_noise_floor``'s ``infinity_z``
of the averaged outline (the vertex's distance from the line at infinity in standard
errors, scaled by ``rms / noise``) compares with the raw outline's own (it keeps the
correlation length read off the averaged outline).

    python experiments/noise_floor.py --trials 20 --seed 1000
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import sorjax
from sorjax import core, scenes
from sorjax._calibration import view_homologies
from sorjax._homology import DEFAULT_SAMPLES
from sorjax._detect import DetectOptions, outline_homology, symmetric_average


def averaged(outline: np.ndarray, o: DetectOptions = DetectOptions()):
    """``outline`` averaged with its mirror image (all points confirmed), its symmetry
    residual before the averaging, that noise's correlation length (px) and the raw
    outline's ``infinity_z``."""
    h = outline_homology(outline)
    avg = symmetric_average(outline, h.W, np.ones(len(outline), bool), o)
    return avg, float(h.rms), float(h.noise_ell), float(h.infinity_z)


def floored_z(outlines, noise) -> np.ndarray:
    """``infinity_z`` of each outline's own fit under ``core.with_noise_floor``."""
    homs = view_homologies([sorjax.fit_homology(q) for q in outlines], DEFAULT_SAMPLES)
    return np.asarray(core.with_noise_floor(homs, np.asarray(noise)).infinity_z)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--seed", type=int, default=1000, help="trial t uses numpy seed SEED + t")
    p.add_argument("--sigma", type=float, default=1.0, help="the paper's noise, px (default 1)")
    p.add_argument("--f", type=float, default=700.0, help="the focal length, px (default 700)")
    a = p.parse_args(argv)
    sc = scenes.two_spheres(f=a.f)
    K = np.asarray(sc.K)
    truth = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    ways = ("raw", "averaged", "averaged + floor", "averaged + floor + ell")
    rows: dict[str, list] = {w: [] for w in ways}
    z_ratio: list[float] = []
    t0 = time.time()
    print(f"noise floor check: two spheres, f {a.f:g} px, sigma {a.sigma:g} px, {a.trials} trials, seeds "
          f"{a.seed}..{a.seed + a.trials - 1}")
    for t in range(a.trials):
        rng = np.random.default_rng(a.seed + t)
        raw = [np.asarray(scenes.paper_noise(v, a.sigma, rng), np.float64) for v in sc.outlines]
        avg, noise, ell, z_raw = zip(*(averaged(q) for q in raw))
        z_ratio += list(floored_z(avg, noise) / np.array(z_raw))
        for way, outs, kw in (("raw", raw, {}), ("averaged", list(avg), {}),
                              ("averaged + floor", list(avg), {"outline_noise": list(noise)}),
                              ("averaged + floor + ell", list(avg), {"outline_noise": list(noise),
                                                                     "outline_noise_ell": list(ell)})):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                c = sorjax.calibrate(outs, outline_error=0.0, **kw)
            est = np.array([c.fu, c.fv, c.u0, c.v0])
            rows[way].append((est - truth, np.asarray(c.std, float), bool(c.success)))
    print(f"{time.time() - t0:.0f} s")
    for way in ways:
        err = np.array([r[0] for r in rows[way]])
        std = np.array([r[1] for r in rows[way]])
        ok = np.array([r[2] for r in rows[way]])
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.sqrt(np.nanmean((err[ok] / std[ok]) ** 2, axis=0)) if ok.any() else np.full(4, np.nan)
        f_err = np.sqrt(np.mean(err[ok][:, :2] ** 2)) if ok.any() else np.nan
        print(f"  {way:22s} calibrated {ok.sum():2d}/{len(ok)}  focal RMS error {f_err:6.2f} px  median std "
              f"{np.median(std[:, :2]):6.2f} px  rms z (fu fv u0 v0) " + " ".join(f"{v:.2f}" for v in z))
    q = np.percentile(z_ratio, [0, 50, 100])
    print(f"  infinity_z of the averaged outlines under the floor / the raw outlines' own, {len(z_ratio)} outlines: "
          f"min {q[0]:.2f}  median {q[1]:.2f}  max {q[2]:.2f}")


if __name__ == "__main__":
    main()
