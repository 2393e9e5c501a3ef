"""Photo-like renders through a lens with radial distortion (issue 18): calibrate from
the renders' object masks with and without the distortion model.

Each image set is three renders (:func:`sorjax.render.random_table_scene`, seeds
``100 * set + 0..2``, three objects each, 150-280 px; ``--objects``, ``--size``) by one camera, K = 800 px, principal point
(330, 235), OpenCV radial distortion ``k1`` (default -0.2).  The outlines are the
sub-pixel outlines of the renders' label masks (:func:`sorjax.outlines_from_mask`, the
``sorjax calibrate --masks`` path).  Each set is calibrated with ``distortion="none"``
and ``"k1"`` at the default outline error (0.1 px) and at 0 (masks taken as exact).

With ``--cli`` each set goes through the command line instead, as a user would run it:
the renders and their label masks are written as PNG files to a temporary folder and
``sorjax calibrate IMG... --masks MASK... --distortion k1 --aspect-ratio 1 --out camera.yaml``
(square pixels, as rendered) is run on
them (:func:`sorjax.cli.main`); the numbers are read back from the camera file's JSON
twin.  ``--vary`` draws each set's camera (f uniform in [600, 1000] px, the principal
point within 5 % of the image centre; seed ``1000 + set``) instead of K = 800 px.

    python experiments/photo_distortion.py [--sets 2] [--k1 -0.2] [--cli] [--vary] [--objects 3] [--size 150 280]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
import warnings
from pathlib import Path

import cv2

import numpy as np

import sorjax
from sorjax import render, scenes
from sorjax._messages import code_name


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", type=int, default=2, help="image sets (default 2)")
    p.add_argument("--k1", type=float, default=-0.2, help="the lens's k1 (default -0.2)")
    p.add_argument("--cli", action="store_true", help="run each set through `sorjax calibrate --masks` (PNG files)")
    p.add_argument("--vary", action="store_true", help="a different camera per set (seed 1000 + set)")
    p.add_argument("--objects", type=int, default=3, help="objects per render (default 3), left to right")
    p.add_argument("--size", type=float, nargs=2, default=(150.0, 280.0), metavar=("LO", "HI"),
                   help="object extent in px (default 150 280); smaller objects in more slots sit nearer the "
                        "image's edges, where the outlines show more perspective and more distortion")
    args = p.parse_args(argv)
    for st in range(args.sets):
        K = camera(st, args.vary)
        renders = [render.random_table_scene(100 * st + s, K, n_objects=args.objects, size_px=tuple(args.size),
                                             distortion=(args.k1, 0.0)) for s in range(3)]
        if args.cli:
            through_cli(st, K, renders, args.k1)
            continue
        outs = []
        for r in renders:
            for k in range(len(r.objects)):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    try:
                        outs += sorjax.outlines_from_mask(r.labels == k + 1)
                    except ValueError:
                        pass  # an object cut by the frame or hidden
        for dist, oe in (("none", 0.1), ("k1", 0.1), ("none", 0.0), ("k1", 0.0)):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cal = sorjax.calibrate(outs, distortion=dist, outline_error=oe, image_size=(640, 480))
            e = np.array([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]])
            k1 = "-" if cal.distortion is None else f"{float(cal.distortion[0]):+.4f} +- {float(cal.distortion_std[0]):.4f}"
            print(f"set {st} (seeds {100 * st}-{100 * st + 2}, {len(outs)} outlines) distortion={dist:4s} "
                  f"outline_error={oe:g}: {code_name(cal.result):14s} f = {cal.fv:7.1f} +- {cal.std[1]:<7.3g} "
                  f"max error {np.nanmax(np.abs(e)) / K[1, 1] * 100 if np.any(np.isfinite(e)) else float('nan'):5.2f} % "
                  f"({np.nanmax(np.abs(e) / cal.std) if np.any(np.isfinite(e)) else float('nan'):.1f} std), "
                  f"k1 = {k1} ({time.perf_counter() - t0:.0f} s)", flush=True)


def camera(st: int, vary: bool):
    """Set ``st``'s intrinsics: K = 800 px, principal point (330, 235), or with ``vary``
    f uniform in [600, 1000] px and the principal point within 5 % of the centre of
    640x480 (seed ``1000 + st``)."""
    if not vary:
        return scenes.intrinsics(800.0, principal_point=(330.0, 235.0))
    rng = np.random.default_rng(1000 + st)
    return scenes.intrinsics(rng.uniform(600.0, 1000.0),
                             principal_point=(320.0 + rng.uniform(-32, 32), 240.0 + rng.uniform(-24, 24)))


def through_cli(st: int, K, renders, k1: float) -> None:
    """Set ``st`` through ``sorjax calibrate IMG... --masks MASK... --distortion D``
    (D = none and k1; outline error 0.1 px, the default), read back from the JSON
    twin of the camera file."""
    from sorjax.cli import main as cli

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        imgs, masks = [], []
        for i, r in enumerate(renders):
            imgs.append(d / f"set{st}_{i}.png")
            masks.append(d / f"set{st}_{i}_mask.png")
            cv2.imwrite(str(imgs[-1]), r.image)
            cv2.imwrite(str(masks[-1]), r.labels.astype(np.uint8))
        for dist in ("none", "k1"):
            out = d / f"camera_{dist}.yaml"
            argv = ["calibrate", *map(str, imgs), "--masks", *map(str, masks), "--distortion", dist,
                    "--aspect-ratio", "1", "--out", str(out)]
            t0 = time.perf_counter()
            err = io.StringIO()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
                code = cli(argv)
            twin = out.with_suffix(".json")
            if not twin.exists():
                print(f"set {st} --distortion {dist:4s}: exit {code}, no camera file: {err.getvalue().strip()[-300:]}")
                continue
            cam = json.loads(twin.read_text())
            fv, sfv = cam["intrinsics"]["fv"], cam["intrinsics_std"]["fv"]
            kk = cam.get("distortion") or {}
            why = "" if cam["success"] else f"; refused: {cam['message'][:160]}..."
            fe = 100 * (fv - K[1, 1]) / K[1, 1] if fv is not None and np.isfinite(fv) else float("nan")
            k1s = f"k1 = {kk['k1']:+.4f} (true {k1:+.2f})" if kk and kk.get("k1") is not None else "k1 -"
            print(f"set {st} (f = {K[1, 1]:.0f} px) `sorjax calibrate --masks --distortion {dist}`: exit {code}, "
                  f"f error {fe:+.2f} % (std {sfv if sfv is None else round(100 * sfv / K[1, 1], 2)} %), {k1s}"
                  f"{why} ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
