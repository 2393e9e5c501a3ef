"""Photo-like renders through a lens with radial distortion (issue 18): calibrate from
the renders' object masks with and without the distortion model.

Each image set is three renders (:func:`sorjax.render.random_table_scene`, seeds
``100 * set + 0..2``, three objects each) by one camera, K = 800 px, principal point
(330, 235), OpenCV radial distortion ``k1`` (default -0.2).  The outlines are the
sub-pixel outlines of the renders' label masks (:func:`sorjax.outlines_from_mask`, the
``sorjax calibrate --masks`` path).  Each set is calibrated with ``distortion="none"``
and ``"k1"`` at the default outline error (0.1 px) and at 0 (masks taken as exact).

    python experiments/photo_distortion.py [--sets 2] [--k1 -0.2]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import sorjax
from sorjax import render, scenes
from sorjax._calibration import code_name


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", type=int, default=2, help="image sets (default 2)")
    p.add_argument("--k1", type=float, default=-0.2, help="the lens's k1 (default -0.2)")
    args = p.parse_args(argv)
    K = scenes.intrinsics(800.0, principal_point=(330.0, 235.0))
    for st in range(args.sets):
        outs = []
        for s in range(3):
            r = render.random_table_scene(100 * st + s, K, n_objects=3, distortion=(args.k1, 0.0))
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


if __name__ == "__main__":
    main()
