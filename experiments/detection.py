"""Automatic object finding and edge refinement on textured renders (issue 17 items 2, 3).

Renders of sorjax.render.random_table_scene whose table and wall are given strong
textures (wood grain, tiles, cloth, striped or dotted wallpaper; chosen by the seed) in
place of the renderer's mild wood grain, then sorjax.outlines_from_image with no boxes
(fully automatic) and with tight boxes (the exact bounding boxes).  For each object:
found or not (a found outline within 10 px of its centroid), the RMS distance of the
outline to the exact silhouette, and the outline's own error estimate
(``outline.outline_error``).  Also the ycb-video photographs of the project's shared
real data (``--ycb DIR``): each true or approximate SOR with a ground-truth mask, the
outline from the image (automatic, and from the mask's box) against
outlines_from_mask of the ground-truth label.

Usage: python experiments/detection.py [--seed 0] [--scenes 12] [--objects 3]
       [--noise 2] [--blur 0.5] [--jpeg 90] [--ycb DIR] [--quick]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import time

import cv2
import numpy as np

import sorjax
from _common import recorded
from sorjax import render as R
from sorjax import scenes as S
from sorjax.experiment._runner import enable_compilation_cache

TEXTURES = ("wood", "tiles", "cloth")
WALLS = ("stripes", "dots", "plain")


def _texture(kind: str, xs, ys, rng) -> np.ndarray:
    """Multiplicative tone (H, W, 3) of a texture in image coordinates."""
    H, W = xs.shape
    ph = rng.uniform(0, 2 * math.pi, 4)
    a = rng.uniform(0, math.pi)
    u = xs * math.cos(a) + ys * math.sin(a)
    v = -xs * math.sin(a) + ys * math.cos(a)
    if kind == "wood":
        per = rng.uniform(6, 14)
        t = 1.0 + 0.22 * np.sin(2 * math.pi * (u + 4 * np.sin(v / 37 + ph[0])) / per + ph[1]) \
            + 0.1 * np.sin(2 * math.pi * v / 90 + ph[2])
        return np.repeat(t[..., None], 3, axis=2)
    if kind == "tiles":
        s = rng.uniform(25, 50)
        iu, iv = np.floor(u / s).astype(int), np.floor(v / s).astype(int)
        cols = rng.uniform(0.88, 1.12, (64, 1)) * rng.uniform(0.95, 1.05, (64, 3))
        t = cols[(iu * 7 + iv * 13) % 64]
        grout = (np.abs(u / s - np.round(u / s)) * s < 1.5) | (np.abs(v / s - np.round(v / s)) * s < 1.5)
        t[grout] = 0.45
        return t
    if kind == "cloth":
        per = rng.uniform(3, 6)
        t = 1.0 + 0.15 * np.sin(2 * math.pi * u / per) * np.sin(2 * math.pi * v / per + ph[3]) \
            + 0.15 * (np.sin(2 * math.pi * u / (7 * per)) > 0)
        return np.repeat(t[..., None], 3, axis=2)
    if kind == "stripes":
        per = rng.uniform(15, 40)
        t = np.where(np.sin(2 * math.pi * xs / per + ph[0]) > 0, 1.15, 0.8)
        tint = rng.uniform(0.8, 1.2, 3)
        return t[..., None] * tint[None, None]
    if kind == "dots":
        s = rng.uniform(12, 25)
        d = np.hypot((xs % s) - s / 2, (ys % s) - s / 2)
        t = np.where(d < s / 4, 0.6, 1.05)
        return np.repeat(t[..., None], 3, axis=2)
    return np.ones((H, W, 3))


@contextlib.contextmanager
def textured(seed: int):
    """Within this block, random_table_scene paints a strong texture on the table and
    the wall (kinds and scales from ``seed``): the renderer's ``_background`` wrapped."""
    orig = R._background
    rng = np.random.default_rng(seed)
    table = TEXTURES[int(rng.integers(len(TEXTURES)))]
    wall = WALLS[int(rng.integers(len(WALLS)))]

    def background(K, Rc, tc, shape, rng_, table_colour, wall_colour, grid=None):
        img = orig(K, Rc, tc, shape, rng_, table_colour, wall_colour, grid)
        H, W = shape
        xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
        d = np.stack([xs, ys, np.ones_like(xs)], -1) @ (Rc.T @ np.linalg.inv(K)).T
        down = d[..., 1] < 0
        tcol = rng.uniform(60, 200, 3)
        base = np.where(down[..., None], tcol[None, None] * _texture(table, xs, ys, rng),
                        img * _texture(wall, xs, ys, rng))
        return np.clip(base, 0, 255)

    R._background = background
    try:
        yield f"{table} table, {wall} wall"
    finally:
        R._background = orig


def textured_scene(seed: int, n_objects: int = 3, noise: float = 2.0, blur: float = 0.5, jpeg: int | None = 90):
    """A textured random table scene and its description; ``jpeg``: quality (None: none)."""
    with textured(seed) as what:
        r = R.random_table_scene(seed, n_objects=n_objects, noise=noise, blur=blur)
    img = r.image
    if jpeg:
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg)])
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return r, img, what


def rms_to(outline: np.ndarray, exact: np.ndarray) -> float:
    return float(np.sqrt(np.mean(S.distance_to_polyline(np.asarray(outline), exact) ** 2)))


def match(found, exact, tol=10.0):
    out = []
    for e in exact:
        d = [np.linalg.norm(np.asarray(f).mean(0) - e.mean(0)) for f in found]
        k = int(np.argmin(d)) if d else -1
        out.append(found[k] if d and d[k] < tol else None)
    return out


def renders(args):
    print(f"(a) textured renders: {args.scenes} scenes x {args.objects} objects, noise {args.noise:g}, "
          f"blur {args.blur:g} px, JPEG quality {args.jpeg}; seeds {args.seed}..{args.seed + args.scenes - 1}")
    rows = {"auto": [], "tight box": []}
    t0 = time.time()
    for s in range(args.seed, args.seed + args.scenes):
        r, img, what = textured_scene(s, args.objects, args.noise, args.blur, args.jpeg)
        exact = r.outlines
        line = f"    seed {s:>3} f {r.K[0, 0]:6.0f}  {what:<24}"
        for mode, boxes in (("auto", None), ("tight box", r.boxes)):
            res, ws = recorded(sorjax.outlines_from_image, img, boxes)
            found = [] if isinstance(res, Exception) else res
            m = match(found, exact)
            cells = []
            for o, e in zip(m, exact):
                if o is None:
                    rows[mode].append((math.nan, math.nan))
                    cells.append("  -  ")
                else:
                    v = rms_to(o, e)
                    rows[mode].append((v, float(getattr(o, "outline_error", math.nan))))
                    cells.append(f"{v:.2f}/{rows[mode][-1][1]:.2f}")
            extra = len(found) - sum(o is not None for o in m)
            line += f"  {mode}: {' '.join(cells)}" + (f" +{extra}" if extra else "")
        print(line)
    for mode, v in rows.items():
        a = np.asarray(v)
        ok = np.isfinite(a[:, 0])
        if not ok.any():
            print(f"    {mode}: nothing found")
            continue
        print(f"    {mode:<9}: found {ok.sum()}/{len(a)} ({100 * ok.mean():.0f} %), outline RMS median "
              f"{np.median(a[ok, 0]):.3f} px, <= 1 px for {100 * np.mean(a[ok, 0] <= 1.0):.0f} % of found; "
              f"estimated error / actual RMS median {np.nanmedian(a[ok, 1] / a[ok, 0]):.2f}, "
              f"estimate >= actual for {100 * np.mean(a[ok, 1] >= a[ok, 0]):.0f} %")
    print(f"    targets: >= 90 % found, median <= 0.3 px, <= 1 px for >= 90 %   [{time.time() - t0:.0f} s]")
    print()


def ycb(args):
    root = args.ycb
    meta = json.load(open(os.path.join(root, "meta.json")))
    print("(b) ycb-video: outline RMS distance (px) from the image to outlines_from_mask of the ground-truth label")
    vals = {"auto": [], "box": []}
    for im in meta["images"]:
        if not im.get("mask"):
            continue
        img = cv2.imread(os.path.join(root, im["image"]))
        lab = cv2.imread(os.path.join(root, im["mask"]), cv2.IMREAD_UNCHANGED)
        for ob in im["objects"]:
            if ob["sor"] == "no" or not np.any(lab == ob["mask_id"]):
                continue
            ref, _ = recorded(sorjax.outlines_from_mask, lab, label=ob["mask_id"])
            if isinstance(ref, Exception):
                print(f"    {im['image']} {ob['name']}: reference: {ref}")
                continue
            ref = ref[0]
            ys, xs = np.nonzero(lab == ob["mask_id"])
            box = (xs.min() - 6, ys.min() - 6, xs.max() + 6, ys.max() + 6)
            line = f"    {os.path.basename(im['image']):<32} {ob['name']:<22} ({ob['sor']:<6})"
            for mode, boxes in (("auto", None), ("box", [box])):
                res, ws = recorded(sorjax.outlines_from_image, img, boxes)
                found = [] if isinstance(res, Exception) else res
                (o,) = match(found, [ref], tol=15.0)
                if o is None:
                    line += f"  {mode}: not found"
                    vals[mode].append(math.nan)
                else:
                    v = rms_to(o, ref)
                    vals[mode].append(v)
                    line += f"  {mode}: {v:.3f} px (est. {float(getattr(o, 'outline_error', math.nan)):.2f})"
            print(line)
    for mode, v in vals.items():
        a = np.asarray(v)
        ok = np.isfinite(a)
        print(f"    {mode}: {ok.sum()}/{len(a)} found, RMS median {np.median(a[ok]) if ok.any() else math.nan:.3f} px")
    print()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--objects", type=int, default=3)
    ap.add_argument("--noise", type=float, default=2.0)
    ap.add_argument("--blur", type=float, default=0.5)
    ap.add_argument("--jpeg", type=int, default=90)
    ap.add_argument("--ycb", default=None, help="folder of the ycb-video set (images/, masks/, meta.json)")
    ap.add_argument("--quick", action="store_true", help="4 scenes")
    args = ap.parse_args(argv)
    if args.quick:
        args.scenes = 4
    enable_compilation_cache()
    print(f"sorjax object finding experiment, seed {args.seed}")
    print()
    renders(args)
    if args.ycb:
        ycb(args)


if __name__ == "__main__":
    main()
