"""What limits the accuracy of automatic outlines (issue 17): the bulk and the defects.

For every object that ``sorjax.outlines_from_image`` finds in the photo-like renders of
:func:`sorjax.render.random_photo_set` (matched as in ``experiments/photos.py``: IoU >=
0.5, objects hidden by clutter left out), each outline point's distance ``d`` (px) to
the exact silhouette splits the outline's error into

* the **bulk**: the RMS of ``d`` over the points within 1 px (what a perfect defect
  removal would leave), and
* the **defects**: the points beyond 1 px (leaks, bites, shadows), their share of the
  points;

and the outline's own harmonic homology (robust fit) tells which defects symmetry can
see: a point is **flagged** when its mirror image lies more than ``max(1 px, 3 robust
std)`` from the outline.  Printed: the median over outlines of the RMS, the bulk RMS
and the RMS over the unflagged points (what dropping the flagged points would leave),
the share of points beyond 1 px and of those flagged, and the share of the outlines
within 1 px RMS at each limit of the declared error (``ImageOutline.outline_error``,
``DetectOptions.max_error_px``: the outlines above it are dropped).

    python experiments/outline_defects.py [--sets 10] [--seed 100] [--cameras 1] [--images 4] [--outlines DIR]

``--outlines DIR``: the outlines kept by ``experiments/photos.py --outlines DIR`` (the
same sets, cameras and images) are reused, and missing ones extracted and kept there.
Cost: extraction about 20 s per image on 2 cores (none with kept outlines), rendering
5-20 s per set, the homology fits a second per outline.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from photos import _extract, match
from sorjax import render, scenes
from sorjax._homology import fit_homology, transfer

LIMITS = (1.5, 1.2, 1.0, 0.8)  # declared-error limits tabulated (px)


def outline_defects(p: np.ndarray, exact: np.ndarray) -> dict:
    """Bulk, defects and symmetry flags of the outline ``p`` (N, 2 px) against the exact
    silhouette ``exact`` (M, 2 px)."""
    d = scenes.distance_to_polyline(p, exact)
    bad = d > 1.0
    h = fit_homology(p, robust=True)
    r = scenes.distance_to_polyline(np.asarray(transfer(np.asarray(h.W), p)), p)
    flag = r > max(1.0, 3.0 * 1.4826 * float(np.median(r)))
    rms = lambda x: float(np.sqrt(np.mean(x ** 2))) if x.size else float("nan")  # noqa: E731
    return {"rms": rms(d), "bulk": rms(d[~bad]), "unflagged": rms(d[~flag]), "points": len(d),
            "beyond": int(bad.sum()), "flagged": int(flag.sum()), "flagged_beyond": int((flag & bad).sum())}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=10)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--cameras", type=int, default=1)
    ap.add_argument("--images", type=int, default=4)
    ap.add_argument("--outlines", metavar="DIR", help="reuse (and keep) the outlines found, as photos.py --outlines")
    args = ap.parse_args(argv)
    print(f"outline defects: {args.sets} set(s), seeds {args.seed}..{args.seed + args.sets - 1}, "
          f"{args.cameras} camera(s) x {args.images} images", flush=True)
    t0 = time.perf_counter()
    rows = []
    for seed in range(args.seed, args.seed + args.sets):
        ps = render.random_photo_set(seed, cameras=args.cameras, images=args.images)
        for ci, cam in enumerate(ps.cameras):
            for k, r in enumerate(cam.renders):
                res = _extract("auto", r, args.outlines, f"set{seed}_cam{ci}_img{k}")
                if isinstance(res, Exception):
                    continue
                for o, j in zip(r.objects, match(res, r)):
                    if j is None or o.occluded:
                        continue
                    row = outline_defects(np.asarray(res[j], np.float64), o.truth.outline)
                    row["declared"] = float(getattr(res[j], "outline_error", np.nan))
                    rows.append(row)
        print(f"  set {seed}: {len(rows)} outlines so far ({time.perf_counter() - t0:.0f} s)", flush=True)
    if not rows:
        print("no outline found")
        return
    col = {key: np.array([r[key] for r in rows]) for key in rows[0]}
    n, beyond = col["points"].sum(), col["beyond"].sum()
    print(f"{len(rows)} found outlines, {n} points:")
    print(f"  median RMS {np.median(col['rms']):.3f} px; bulk (points within 1 px) {np.median(col['bulk']):.3f} px "
          f"(min {np.min(col['bulk']):.3f}, max {np.max(col['bulk']):.3f}); without the flagged points "
          f"{np.median(col['unflagged']):.3f} px")
    print(f"  points beyond 1 px: {100 * beyond / n:.1f} %; flagged by symmetry: {100 * col['flagged'].sum() / n:.1f} %, "
          f"holding {100 * col['flagged_beyond'].sum() / max(beyond, 1):.0f} % of the points beyond 1 px")
    ratio = col["rms"] / col["declared"]
    print(f"  actual / declared error: median {np.nanmedian(ratio):.2f}, more than 2x for {np.sum(ratio > 2)}, "
          f"more than 5x for {np.sum(ratio > 5)} of {len(rows)}")
    for lim in LIMITS:
        keep = ~(col["declared"] > lim)
        print(f"  declared error <= {lim:g} px: {keep.sum()} of {len(rows)} outlines kept, "
              f"{100 * np.mean(col['rms'][keep] <= 1.0):.0f} % of them within 1 px, median RMS "
              f"{np.median(col['rms'][keep]):.3f} px")


if __name__ == "__main__":
    main()
