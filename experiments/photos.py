"""Outlines and calibration from photo-like renders (issue 17's done-when harness).

Each set is :func:`sorjax.render.random_photo_set` (seed printed): 5 cameras with f from
450 to 1600 px (640x480 to 1280x960 images), 4 images per camera of 2-3 solids of
revolution each, on textured tables in front of patterned walls, with clutter, cast
shadows, reflections, glass and metal objects, defocus, noise and JPEG
(:mod:`sorjax._photo`).  For every image, outlines come from

* ``auto``  : ``sorjax.outlines_from_image(image)`` (automatic object finding);
* ``boxes`` : ``sorjax.outlines_from_image(image, boxes)`` with the exact bounding boxes
  grown by 8 px (with ``--boxes``);
* ``masks`` : ``sorjax.outlines_from_mask`` of each object's exact soft mask (its
  coverage), the reference (the ``sorjax calibrate --masks`` path);
* ``masks@PX`` (with ``--mask-errors PX ...``): the same outlines calibrated with
  ``outline_error=PX``: how accurate outlines from images must be for the
  perspective gate to let each camera through;
* ``contours`` : ``cv2.findContours`` of each object's binary mask (coverage >= 0.5),
  passed to ``sorjax.calibrate`` as they are (with ``--contours``).

Only the public extraction functions are called, so the script measures whatever
extraction sorjax has.  Printed per column:

* found: true objects matched by an outline (intersection over union of the filled
  outline with the object's mask >= 0.5, one outline per object); objects partly
  hidden by clutter are counted apart (``occluded``) and left out of the outline error;
* outline error: RMS distance (px) of a found outline's points to the exact silhouette;
  the median over found unoccluded objects and the fraction within 1 px; in the summary
  also the objects found *and* within 1 px (good outlines), which compares columns that
  keep poor outlines (boxes) with those that drop them (auto);
* calibration of each camera: ``sorjax.calibrate`` (defaults: bundle, free aspect,
  ``image_size`` given) on all outlines of its images (false detections included, as a
  user would pass them), with the outline error the command line uses: ``"measured"``
  for outlines found in images (auto, boxes), the default 0.1 px for masks and outline
  files (masks, contours): focal error % (the larger of fu, fv),
  ``ok`` within 2 %, ``refused`` with the reason, ``WRONG`` beyond 2 %; for every
  intrinsic reported as determined (finite in ``K``), ``|error| / std``: "confident
  wrong" when beyond 3 std or 5 % of f.

Issue 17's targets (automatic column): >= 90 % found, median RMS <= 0.3 px, >= 90 % of
them within 1 px, every camera ok or refused, no confident wrong K over >= 30 sets.

    python experiments/photos.py [--sets 5] [--seed 0] [--boxes] [--contours] [--no-auto] [--no-masks]
                                 [--save DIR] [--outlines DIR] [--mask-errors PX ...] [--no-symmetric]
                                 [--max-error PX] [--quick]

Cost: a set renders in about 15 s of CPU (most of it the exact silhouettes); the run's
time is mostly ``sorjax.calibrate`` (one call per camera and column, 10 to 16 views,
compiled once per padded view count and then kept in the compilation cache) and the
automatic extraction (seconds per 1280x960 image).
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import time

import cv2
import numpy as np

import sorjax
from _common import recorded
from sorjax import render, scenes
from sorjax.experiment._runner import enable_compilation_cache

MATCH_IOU = 0.5  # a found outline is an object's when its filled area overlaps the object's mask this much
BOX_MARGIN = 8  # px added to the exact boxes in the boxes column
WITHIN_PX = 1.0  # outline RMS counted as "within"
FOCAL_OK = 2.0  # % focal error counted as calibrated
WRONG_STD, WRONG_PCT = 3.0, 5.0  # a determined intrinsic beyond either is "confident wrong"
NAMES = ("fu", "fv", "u0", "v0")
IMAGE_COLUMNS = ("auto", "boxes")  # outlines found in images: calibrated with outline_error="measured", as the CLI


def _call(fn, *a, **kw):
    """``(result or the exception, [warning texts])``: a failure never ends the run."""
    return recorded(fn, *a, errors=(Exception,), **kw)


def _first_line(text: str, n: int = 110) -> str:
    t = " ".join(str(text).split())
    return t if len(t) <= n else t[: n - 3] + "..."


from sorjax._outline_files import ATTRIBUTES as _ATTRS  # noqa: E402  (what sorjax.save_outlines keeps)


def _extract(name: str, r: render.Rendering, store: str | None, stem: str, symmetric: bool = True):
    """The outlines of ``r`` from the image (``name`` "auto" or "boxes"), or the
    exception; with ``store`` (a folder, ``--outlines``) they are read from
    ``store/stem_name.pkl`` when there and written there otherwise (plain arrays and
    their ``sorjax._detect.ImageOutline`` attributes), so that a study's calibrations
    can be rerun without extracting again.  The file is reused whatever code wrote it:
    empty the folder after changing the extraction."""
    path = os.path.join(store, f"{stem}_{name}.pkl") if store else None
    if path and os.path.exists(path):
        with open(path, "rb") as fh:
            saved = pickle.load(fh)
        if isinstance(saved, Exception):
            return saved
        from sorjax._detect import ImageOutline
        return [ImageOutline(pts, **attrs) for pts, attrs in saved]
    if name == "auto":
        res, _ = _call(sorjax.outlines_from_image, r.image, symmetric=symmetric)
    else:
        w, h = r.image_size
        bx = [(max(0, b[0] - BOX_MARGIN), max(0, b[1] - BOX_MARGIN), min(w - 1, b[2] + BOX_MARGIN),
               min(h - 1, b[3] + BOX_MARGIN)) for b in r.boxes]
        res, _ = _call(sorjax.outlines_from_image, r.image, bx, symmetric=symmetric)
    if path:
        os.makedirs(store, exist_ok=True)
        saved = res if isinstance(res, Exception) else [
            (np.asarray(o), {k: float(getattr(o, k, math.nan)) for k in _ATTRS}) for o in res]
        with open(path, "wb") as fh:
            pickle.dump(saved, fh)
    return res


def _below(outlines: list, limit: float, label: str):
    """``--max-error``: the outlines whose estimated error (``outline_error``, px) is at
    most ``limit`` (those without one kept), or a ValueError when none is left, as
    ``sorjax.outlines_from_image`` says it."""
    kept = [o for o in outlines if not getattr(o, "outline_error", 0.0) > limit]
    if not kept:
        return ValueError(f"{label}: every outline's estimated error is above --max-error {limit:g} px")
    return kept


def _filled(outline: np.ndarray, shape) -> np.ndarray:
    m = np.zeros(shape, np.uint8)
    cv2.fillPoly(m, [np.round(np.asarray(outline) * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
    return m.astype(bool)


def match(found: list[np.ndarray], r: render.Rendering) -> list[int | None]:
    """For each object of ``r``, the index of the found outline with the largest
    intersection over union with its mask (>= MATCH_IOU, each outline used once)."""
    shape = r.labels.shape
    masks = [o.coverage >= 0.5 for o in r.objects]
    fills = [_filled(f, shape) for f in found]
    pairs = []
    for i, m in enumerate(masks):
        for j, f in enumerate(fills):
            inter = np.count_nonzero(m & f)
            if inter:
                pairs.append((inter / np.count_nonzero(m | f), i, j))
    out: list[int | None] = [None] * len(masks)
    used = set()
    for iou, i, j in sorted(pairs, reverse=True):
        if iou >= MATCH_IOU and out[i] is None and j not in used:
            out[i] = j
            used.add(j)
    return out


def outline_rms(outline: np.ndarray, exact: np.ndarray) -> float:
    return float(np.sqrt(np.mean(scenes.distance_to_polyline(outline, exact) ** 2)))


class Column:
    """Tallies of one outline source."""

    def __init__(self, name: str, declared: float | str | None = None):
        self.name = name
        # the outline error calibrate is given: "measured" for outlines found in images
        # (as the CLI), the default 0.1 px for masks and outline files, or as asked
        self.declared = declared if declared is not None else "measured" if name in IMAGE_COLUMNS else 0.1
        self.objects = self.found = self.occluded = self.occluded_found = self.extra = 0
        self.rms: list[float] = []
        self.image_failures: list[str] = []
        self.cameras: list[str] = []  # "ok", "refused", "WRONG"
        self.focal_err: list[float] = []
        self.determined = 0
        self.confident_wrong: list[str] = []
        self.seconds = self.cal_seconds = 0.0

    def add_image(self, r: render.Rendering, res, label: str) -> list[np.ndarray]:
        self.objects += sum(not o.occluded for o in r.objects)
        self.occluded += sum(o.occluded for o in r.objects)
        if isinstance(res, Exception):
            self.image_failures.append(f"{label}: {type(res).__name__}: {_first_line(res)}")
            return []
        m = match(res, r)
        for o, j in zip(r.objects, m):
            if j is None:
                continue
            if o.occluded:
                self.occluded_found += 1
                continue
            self.found += 1
            self.rms.append(outline_rms(res[j], o.truth.outline))
        self.extra += len(res) - sum(j is not None for j in m)
        return list(res)

    def add_camera(self, K: np.ndarray, outlines: list[np.ndarray], size) -> str:
        if len(outlines) < 2:
            self.cameras.append("refused")
            return f"refused: {len(outlines)} outline(s)"
        t0 = time.perf_counter()
        cal, ws = _call(sorjax.calibrate, outlines, image_size=size, outline_error=self.declared)
        self.cal_seconds += time.perf_counter() - t0
        if isinstance(cal, Exception):
            self.cameras.append("refused")
            return f"refused: {type(cal).__name__}: {_first_line(cal, 90)}"
        est = np.asarray(cal.K)
        est = np.array([est[0, 0], est[1, 1], est[0, 2], est[1, 2]])
        tru = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
        std = np.asarray(cal.std)
        f = float(K[1, 1])
        err_pct = 100.0 * (est - tru) / f
        bad = []
        for k in range(4):
            if not np.isfinite(est[k]):
                continue
            self.determined += 1
            z = abs(est[k] - tru[k]) / std[k] if np.isfinite(std[k]) and std[k] > 0 else math.inf
            if z > WRONG_STD or abs(err_pct[k]) > WRONG_PCT:
                bad.append(f"{NAMES[k]} {est[k]:.1f} +- {std[k]:.1f} for {tru[k]:.1f} ({z:.1f} std, {err_pct[k]:+.1f} %)")
        self.confident_wrong += bad
        focal = np.abs(err_pct[:2])
        if not cal.success or not np.all(np.isfinite(est[:2])):
            self.cameras.append("refused")
            text = f"refused: {_first_line(cal.message, 90)}"
        else:
            fe = float(np.max(focal))
            self.focal_err.append(fe)
            ok = fe <= FOCAL_OK
            self.cameras.append("ok" if ok else "WRONG")
            text = f"f err {fe:5.2f} % {'ok' if ok else 'WRONG'} (std {100 * std[1] / f:.2f} %)"
            if ws:
                text += f"; {len(ws)} warning(s): {_first_line(ws[0], 60)}"
        if bad:
            text += "; CONFIDENT WRONG: " + "; ".join(bad)
        return text

    def summary(self) -> str:
        rms = np.asarray(self.rms)
        med = f"{np.median(rms):.3f}" if rms.size else "-"
        within = f"{100 * np.mean(rms <= WITHIN_PX):.0f} %" if rms.size else "-"
        good = int(np.sum(rms <= WITHIN_PX))
        cams = len(self.cameras)
        fe = np.asarray(self.focal_err)
        return (f"{self.name:<6} found {self.found}/{self.objects} ({100 * self.found / max(self.objects, 1):.0f} %)"
                f" [+{self.extra} other outlines; occluded {self.occluded_found}/{self.occluded}], "
                f"outline RMS median {med} px, within {WITHIN_PX:g} px {within} (found and within: {good}, "
                f"{100 * good / max(self.objects, 1):.0f} % of the objects); cameras ok {self.cameras.count('ok')}"
                f"/{cams}, refused {self.cameras.count('refused')}, WRONG {self.cameras.count('WRONG')}"
                f" (median focal err {np.median(fe) if fe.size else float('nan'):.2f} %); confident wrong K "
                f"{len(self.confident_wrong)} of {self.determined} determined; image failures "
                f"{len(self.image_failures)}; extraction {self.seconds:.0f} s, calibration {self.cal_seconds:.0f} s")


def run_set(seed: int, args, columns: dict[str, Column]) -> None:
    t0, c0 = time.perf_counter(), time.process_time()
    ps = render.random_photo_set(seed, cameras=args.cameras, images=args.images)
    n_img = sum(len(c.renders) for c in ps.cameras)
    n_obj = sum(len(r.objects) for c in ps.cameras for r in c.renders)
    n_occ = sum(o.occluded for c in ps.cameras for r in c.renders for o in r.objects)
    print(f"set seed {seed}: {ps.description}; {n_img} images, {n_obj} objects ({n_occ} occluded); "
          f"rendered in {time.perf_counter() - t0:.0f} s ({time.process_time() - c0:.0f} s CPU)", flush=True)
    if args.save:
        os.makedirs(args.save, exist_ok=True)
        for ci, cam in enumerate(ps.cameras):
            for k, r in enumerate(cam.renders):
                stem = os.path.join(args.save, f"set{seed}_cam{ci}_img{k}")
                cv2.imwrite(stem + ".png", r.image)
                cv2.imwrite(stem + "_labels.png", r.labels.astype(np.uint8))
    for ci, cam in enumerate(ps.cameras):
        K = cam.K
        print(f"  camera {ci}: fu {K[0, 0]:.1f} fv {K[1, 1]:.1f} u0 {K[0, 2]:.1f} v0 {K[1, 2]:.1f}, "
              f"{cam.image_size[0]}x{cam.image_size[1]}, {len(cam.renders)} images "
              f"(random_table_scene seeds {', '.join(str(x) for x in cam.seeds)})", flush=True)
        for name, col in columns.items():
            outs = []
            before = (col.found, col.objects, len(col.rms), len(col.image_failures))
            for k, r in enumerate(cam.renders):
                label = f"set {seed} camera {ci} image {k}"
                t1 = time.perf_counter()
                if name in IMAGE_COLUMNS:
                    res = _extract(name, r, args.outlines, f"set{seed}_cam{ci}_img{k}", not args.no_symmetric)
                    if args.max_error is not None and not isinstance(res, Exception):
                        res = _below(res, args.max_error, label)
                elif name == "contours":
                    res = [c[:, 0, :].astype(np.float64) for o in r.objects
                           for c in cv2.findContours((o.coverage >= 0.5).astype(np.uint8), cv2.RETR_EXTERNAL,
                                                     cv2.CHAIN_APPROX_NONE)[0] if len(c) >= 8]
                else:
                    res = []
                    for o in r.objects:
                        got, _ = _call(sorjax.outlines_from_mask, o.coverage)
                        res += [] if isinstance(got, Exception) else got[:1]
                col.seconds += time.perf_counter() - t1
                outs += col.add_image(r, res, label)
            rms = col.rms[before[2]:]
            fails = col.image_failures[before[3]:]
            cal = col.add_camera(K, outs, cam.image_size)
            print(f"    {name:<6} found {col.found - before[0]:>2}/{col.objects - before[1]:<2} outlines {len(outs):>2}  "
                  f"RMS med {np.median(rms) if rms else float('nan'):6.3f} px  <=1px "
                  f"{100 * np.mean(np.asarray(rms) <= WITHIN_PX) if rms else float('nan'):4.0f} %   {cal}", flush=True)
            for fmsg in fails[:2]:
                print(f"           failed: {fmsg}")
            if len(fails) > 2:
                print(f"           ... and {len(fails) - 2} more image failure(s)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=5, help="image sets (default 5)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first set; the sets are seed, seed+1, ...")
    ap.add_argument("--cameras", type=int, default=5, help="cameras per set (default 5)")
    ap.add_argument("--images", type=int, default=4, help="images per camera (default 4)")
    ap.add_argument("--boxes", action="store_true", help="also extract with the exact boxes (grown by 8 px)")
    ap.add_argument("--contours", action="store_true",
                    help="also cv2.findContours outlines of each object's binary mask (coverage >= 0.5)")
    ap.add_argument("--no-auto", action="store_true", help="skip the automatic column")
    ap.add_argument("--no-masks", action="store_true", help="skip the masks (reference) column")
    ap.add_argument("--save", metavar="DIR", help="write each image (PNG of the JPEG-decoded render) and its label "
                                                  "image (object k = k + 1) to DIR")
    ap.add_argument("--outlines", metavar="DIR", help="keep the outlines found in images (auto, boxes) in DIR and "
                                                      "reuse them when there: rerun the calibrations of a study "
                                                      "without extracting again (empty DIR after changing the "
                                                      "extraction)")
    ap.add_argument("--mask-errors", metavar="PX", type=float, nargs="+", default=[],
                    help="also calibrate the masks' outlines declaring these outline errors (px): how accurate must "
                         "outlines be for the perspective gate to let a camera through (a column masks@PX each)")
    ap.add_argument("--no-symmetric", action="store_true",
                    help="outlines_from_image(symmetric=False): no averaging with the outlines' mirror images (the "
                         "outlines before session 23), to compare; with --outlines, a folder of its own")
    ap.add_argument("--max-error", metavar="PX", type=float, default=None,
                    help="drop the outlines found in images (auto, boxes) whose estimated error (outline_error) "
                         "exceeds PX px before matching and calibrating: what a tighter limit than "
                         "sorjax._detect.DetectOptions.max_error_px (1.5 px, automatic finding only) would give")
    ap.add_argument("--quick", action="store_true", help="2 sets")
    args = ap.parse_args(argv)
    if args.quick:
        args.sets = 2
    if args.max_error is not None and not (math.isfinite(args.max_error) and args.max_error > 0):
        ap.error(f"--max-error: an outline error is a number of pixels > 0, got {args.max_error}")
    enable_compilation_cache()
    names = (([] if args.no_auto else ["auto"]) + (["boxes"] if args.boxes else [])
             + ([] if args.no_masks else ["masks"]) + (["contours"] if args.contours else []))
    columns = {n: Column(n) for n in names}
    for e in args.mask_errors:
        if not (math.isfinite(e) and e >= 0):
            ap.error(f"--mask-errors: an outline error is a number of pixels >= 0, got {e}")
        columns[f"masks@{e:g}"] = Column(f"masks@{e:g}", declared=e)
    names = list(columns)
    if not names:
        ap.error("no column left to run (drop --no-auto or --no-masks, or add --boxes / --contours / --mask-errors)")
    print(f"sorjax photo-like test bed: {args.sets} set(s), seeds {args.seed}..{args.seed + args.sets - 1}, "
          f"{args.cameras} cameras x {args.images} images; columns {', '.join(names)}"
          + ("; outlines not averaged with their mirror images (--no-symmetric)" if args.no_symmetric else "")
          + (f"; outlines above {args.max_error:g} px of estimated error dropped (--max-error)"
             if args.max_error is not None else ""),
          flush=True)
    t0 = time.perf_counter()
    for s in range(args.seed, args.seed + args.sets):
        run_set(s, args, columns)
    print(f"summary over {args.sets} set(s) (seeds {args.seed}..{args.seed + args.sets - 1}), "
          f"{time.perf_counter() - t0:.0f} s:")
    for col in columns.values():
        print("  " + col.summary())
        for msg in col.confident_wrong[:5]:
            print(f"         confident wrong: {msg}")
    print(f"  targets (auto): found >= 90 %, median RMS <= 0.3 px, >= 90 % within {WITHIN_PX:g} px, every camera "
          f"ok or refused, no confident wrong K (over >= 30 sets)")


if __name__ == "__main__":
    main()
