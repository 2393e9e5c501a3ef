"""Pixel traces: ``cv2.findContours`` outlines of binary masks, as users pass them (issue 17, item 5).

A trace of a binary mask's boundary pixels (integer coordinates in chain-code steps) is
recognised by sorjax (:func:`sorjax._outline.is_pixel_trace`) and replaced by the
outline of the mask it bounds, traced as ``sorjax.outlines_from_mask`` traces a binary
mask (the command line's ``--masks`` path).  On seeded photo-like renders
(:func:`sorjax.render.random_table_scene`: images, anti-aliased coverage masks and the
exact silhouettes) with the binary masks ``coverage >= 0.5``:

(a) outline accuracy, px: mean signed distance (negative inside) and RMS distance to
    the exact silhouette of
      * cv2      : cv2.findContours' own points (CHAIN_APPROX_NONE),
      * trace    : those points through sorjax.make_outline (the replacement),
      * mask     : sorjax.outlines_from_mask on the binary mask;
(b) calibration (method "bundle", free aspect ratio, image size known) of each set of
    images of one camera from
      * --masks  : outlines_from_mask of the binary masks, the default outline_error,
      * traces   : the cv2.findContours outlines (CHAIN_APPROX_SIMPLE: the most
                   compact layout, also recognised), the default outline_error,
      * before   : the same traces taken as they are (the staircase half a pixel
                   inside, outline_error 0.5 px: what sorjax did before),
    focal errors in % of the truth; done when the traces calibrate within +-0.2 % of
    the --masks path.

Usage: python experiments/pixel_traces.py [--seed 0] [--sets 5] [--images 3] [--objects 3]
       [--f-range 450 1600]
"""

from __future__ import annotations

import argparse
import time

import cv2
import jax.numpy as jnp
import numpy as np

import sorjax
from _common import recorded
from sorjax import render as R
from sorjax import scenes as S
from sorjax._outline import Outline, resample_closed


def signed_distance(pts: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """Distance (px) of each point to the closed polyline ``exact``, negative inside."""
    return np.where(S._points_in_polygon(exact, pts), -1.0, 1.0) * S.distance_to_polyline(pts, exact)


def nearest(outs: list[np.ndarray], ref: np.ndarray) -> np.ndarray:
    return min(outs, key=lambda o: float(np.linalg.norm(o.mean(0) - ref.mean(0))))


def traces(binary: np.ndarray, approx: int) -> list[np.ndarray]:
    cnts, _ = cv2.findContours(binary.astype(np.uint8), cv2.RETR_EXTERNAL, approx)
    return [c[:, 0, :].astype(np.float64) for c in cnts]


def camera(rng, f: float, size=(640, 480)) -> np.ndarray:
    w, h = size
    a = float(rng.uniform(0.95, 1.05))
    pp = (0.5 * w + rng.uniform(-0.08, 0.08) * w, 0.5 * h + rng.uniform(-0.08, 0.08) * h)
    return S.intrinsics(f, aspect_ratio=a, principal_point=pp)


def renders(K, n: int, objects: int, seed: int):
    out = []
    while len(out) < n:
        try:
            out.append(R.random_table_scene(seed, K=K, n_objects=objects))
        except RuntimeError:
            pass
        seed += 1
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sets", type=int, default=5, help="image sets (one camera each)")
    ap.add_argument("--images", type=int, default=3, help="images per set")
    ap.add_argument("--objects", type=int, default=3, help="objects per image")
    ap.add_argument("--f-range", type=float, nargs=2, default=(450.0, 1600.0), metavar=("F_MIN", "F_MAX"))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print(f"sorjax pixel-trace experiment, seed {args.seed}: {args.sets} sets x {args.images} images x "
          f"{args.objects} objects, f {args.f_range[0]:g} to {args.f_range[1]:g} px, 640x480")
    t0 = time.time()
    acc = {k: ([], []) for k in ("cv2", "trace", "mask")}  # (mean signed, rms) per outline
    rows = []
    for si, f in enumerate(np.linspace(*args.f_range, args.sets)):
        K = camera(rng, float(f))
        seed = int(rng.integers(2**31))
        rs = renders(K, args.images, args.objects, seed)
        mask_outs, simple, raw = [], [], []
        for r in rs:
            binary = r.mask >= 0.5
            mo = sorjax.outlines_from_mask(binary)
            mask_outs += mo
            simple += traces(binary, cv2.CHAIN_APPROX_SIMPLE)
            for c in traces(binary, cv2.CHAIN_APPROX_NONE):
                raw.append(c)
                exact = nearest(r.outlines, c)
                o, _ = recorded(sorjax.make_outline, c, 2048)
                for k, p in (("cv2", c), ("trace", np.asarray(o.points)), ("mask", nearest(mo, c))):
                    d = signed_distance(p, exact)
                    acc[k][0].append(float(np.mean(d)))
                    acc[k][1].append(float(np.sqrt(np.mean(d**2))))
        size = rs[0].image_size
        cal = {
            "--masks": recorded(sorjax.calibrate, mask_outs, image_size=size),
            "traces": recorded(sorjax.calibrate, simple, image_size=size),
            "before": recorded(sorjax.calibrate, [Outline(jnp.asarray(resample_closed(c, 2048))) for c in raw],
                               image_size=size, outline_error=0.5),
        }
        rows.append((si, seed, K, cal))
        print(f"  set {si} (render seeds from {seed}): fu {K[0, 0]:.1f}, fv {K[1, 1]:.1f}, u0 {K[0, 2]:.1f}, "
              f"v0 {K[1, 2]:.1f}; {len(mask_outs)} outlines   [{time.time() - t0:.0f} s]")
        for name, (c, notes) in cal.items():
            if isinstance(c, Exception):
                print(f"    {name:<8} error: {c}")
                continue
            e = 100 * np.array([c.fu / K[0, 0] - 1, c.fv / K[1, 1] - 1])
            sd = 100 * c.std[:2] / np.array([K[0, 0], K[1, 1]])
            note = "" if c.success else f"  refused: {c.message[:90]}"
            print(f"    {name:<8} fu {e[0]:+7.3f} % (std {sd[0]:.2f}), fv {e[1]:+7.3f} % (std {sd[1]:.2f}); "
                  f"outline error {c.outline_error:.3g} px{note}")
    print()
    print("(a) outline accuracy against the exact silhouettes, px (over "
          f"{len(acc['cv2'][0])} outlines): mean signed distance (negative inside) / RMS distance")
    for k in acc:
        m, r = np.asarray(acc[k][0]), np.asarray(acc[k][1])
        print(f"    {k:<6} mean signed {np.mean(m):+.4f} (outlines from {m.min():+.3f} to {m.max():+.3f}); "
              f"RMS {np.sqrt(np.mean(r**2)):.4f} (worst {r.max():.3f})")
    print()
    print("(b) focal error, % of the truth (fu and fv of every set):")
    diff = []
    for name in ("--masks", "traces", "before"):
        e = []
        for _, _, K, cal in rows:
            c = cal[name][0]
            if isinstance(c, Exception) or not np.all(np.isfinite([c.fu, c.fv])):
                e += [np.nan, np.nan]
            else:
                e += [100 * (c.fu / K[0, 0] - 1), 100 * (c.fv / K[1, 1] - 1)]
        e = np.asarray(e)
        ok = np.isfinite(e)
        print(f"    {name:<8} median |err| {np.median(np.abs(e[ok])):.3f} %, worst {np.max(np.abs(e[ok])):.3f} %"
              + (f", {int((~ok).sum() // 2)} set(s) without a focal length" if (~ok).any() else ""))
        if name == "--masks":
            ref = e
        elif name == "traces":
            diff = e - ref
    print(f"    traces - --masks: largest |difference| {np.nanmax(np.abs(diff)):.2e} % of f "
          f"(done when <= 0.2 %)   [{time.time() - t0:.0f} s]")


if __name__ == "__main__":
    main()
