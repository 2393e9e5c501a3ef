"""Peak memory of outlines from a huge mask or photograph holding one small object.

Each case runs in a Python process of its own (``--child CASE``), which reports its
peak resident memory (``resource.getrusage(RUSAGE_SELF).ru_maxrss``), the same
after the imports and after building the input (so the input's own share is
visible), and the wall time of the call.  (Linux keeps a process's peak across
fork and exec, so the parent stays small: the cli-mask files are written by another
child.)  Cases, on SIZE x SIZE px (default 20000):

  mask-u8      outlines_from_mask on a uint8 0/255 mask holding one disc (radius 150 px)
  mask-soft    the same disc anti-aliased (an 8-bit soft mask)
  mask-bool    the disc as a bool mask
  label-u16    a uint16 label image with two discs (labels 1 and 2), label=2
  image-boxes  outlines_from_image on a uint8 BGR photograph, one disc (radius 300 px) in a box
  image-auto   the same, one disc of radius 0.03 SIZE (600 px) found automatically
  cli-mask     ``sorjax calibrate IMAGE --masks MASK --out camera.yaml`` on PNG files
               (uint8 BGR image, 8-bit mask) holding two discs: reading, extraction, the
               (failed: discs are conics) calibration, the overlay.  The command line
               refuses images above 60 Mpx from their headers (exit 2, nothing decoded:
               sorjax._image_files.MAX_IMAGE_PIXELS), so at the default size this case
               measures that refusal; --size 7000 or less measures the whole run

The issue's bound: under 2 GB for a 20000 x 20000 mask holding one small object.

Usage: python experiments/memory.py [--size 20000] [--cases mask-u8 image-boxes ...] [--timeout 900]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

CASES = ("mask-u8", "mask-soft", "mask-bool", "label-u16", "image-boxes", "image-auto", "cli-mask")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _disc(shape, centre, radius, value, dtype, soft=False):
    import cv2
    import numpy as np

    m = np.zeros(shape, dtype)
    m.fill(0)  # touch every page: an input read from a file is resident
    sh = 4
    c = tuple(int(round(v * (1 << sh))) for v in centre)
    cv2.circle(m, c, int(round(radius * (1 << sh))), value, -1, cv2.LINE_AA if soft else cv2.LINE_8, sh)
    return m


def _files(size: int, folder: str) -> tuple[str, str]:
    """A photograph and a mask (PNG) with two discs, for the cli-mask case."""
    import cv2
    import numpy as np

    n = size
    img = np.full((n, n, 3), 90, np.uint8)
    mask = np.zeros((n, n), np.uint8)
    for (cx, cy), r in (((0.3 * n, 0.4 * n), 200.0), ((0.7 * n, 0.6 * n), 260.0)):
        c = (int(cx * 16), int(cy * 16))
        cv2.circle(img, c, int(r * 16), (40, 170, 230), -1, cv2.LINE_AA, 4)
        cv2.circle(mask, c, int(r * 16), 255, -1, cv2.LINE_AA, 4)
    paths = os.path.join(folder, "image.png"), os.path.join(folder, "mask.png")
    cv2.imwrite(paths[0], img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    cv2.imwrite(paths[1], mask, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    return paths


def child(case: str, size: int, files: list[str]) -> dict:
    import warnings

    import numpy as np

    import sorjax

    after_import = _rss_mb()
    n = size
    centre = (0.61 * n, 0.37 * n)
    if case == "mask-u8":
        data, call = _disc((n, n), centre, 150.0, 255, np.uint8), lambda d: sorjax.outlines_from_mask(d)
    elif case == "mask-soft":
        data, call = _disc((n, n), centre, 150.0, 255, np.uint8, soft=True), lambda d: sorjax.outlines_from_mask(d)
    elif case == "mask-bool":
        data = _disc((n, n), centre, 150.0, 1, np.uint8).view(bool)
        call = lambda d: sorjax.outlines_from_mask(d)  # noqa: E731
    elif case == "label-u16":
        data = _disc((n, n), centre, 150.0, 2, np.uint16)
        data[_disc((n, n), (0.2 * n, 0.8 * n), 120.0, 1, np.uint8) > 0] = 1
        call = lambda d: sorjax.outlines_from_mask(d, label=2)  # noqa: E731
    elif case in ("image-boxes", "image-auto"):
        import cv2

        r = 300.0 if case == "image-boxes" else 0.03 * n
        data = np.full((n, n, 3), 90, np.uint8)
        c = tuple(int(v * 16) for v in centre)
        cv2.circle(data, c, int(r * 16), (40, 170, 230), -1, cv2.LINE_AA, 4)
        box = [(centre[0] - r - 30, centre[1] - r - 30, centre[0] + r + 30, centre[1] + r + 30)]
        call = (lambda d: sorjax.outlines_from_image(d, boxes=box)) if case == "image-boxes" else \
            (lambda d: sorjax.outlines_from_image(d))
    elif case == "cli-mask":
        from sorjax.cli import main

        data = None

        def call(_):
            import contextlib
            import io

            err = io.StringIO()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
                code = main(["calibrate", files[0], "--masks", files[1], "--out",
                             os.path.join(os.path.dirname(files[0]), "camera.yaml")])
            return [code, err.getvalue().strip().splitlines()[-1:]]
    else:
        raise SystemExit(f"unknown case {case}")
    with_input = _rss_mb()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = call(data)
    seconds = time.perf_counter() - t0
    what = res if case == "cli-mask" else f"{len(res)} outline(s), {len(res[0])} points"
    return dict(case=case, size=n, after_import_mb=after_import, with_input_mb=with_input, peak_mb=_rss_mb(),
                seconds=seconds, result=what)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=20000)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--files", nargs="*", default=[], help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child == "files":
        print(json.dumps(_files(args.size, args.files[0])))
        return
    if args.child:
        print(json.dumps(child(args.child, args.size, args.files)))
        return
    import sorjax

    print(f"sorjax {sorjax.__file__}; {args.size} x {args.size} px; peak = ru_maxrss of the process")
    print(f"{'case':12s} {'imports MB':>10s} {'+input MB':>10s} {'peak MB':>9s} {'work MB':>8s} {'s':>6s}  result")
    with tempfile.TemporaryDirectory() as tmp:
        files = ()
        if "cli-mask" in args.cases:  # written by a process of its own: a child inherits its parent's peak (fork)
            r = subprocess.run([sys.executable, __file__, "--child", "files", "--size", str(args.size), "--files", tmp],
                               capture_output=True, text=True, timeout=args.timeout, check=True)
            files = json.loads(r.stdout.strip().splitlines()[-1])
        for case in args.cases:
            cmd = [sys.executable, __file__, "--child", case, "--size", str(args.size), "--files", *files]
            try:
                r = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
            except subprocess.TimeoutExpired:
                print(f"{case:12s} timed out after {args.timeout:.0f} s")
                continue
            if r.returncode != 0:
                tail = (r.stderr.strip().splitlines() or ["?"])[-1]
                print(f"{case:12s} failed (exit {r.returncode}): {tail}")
                continue
            d = json.loads(r.stdout.strip().splitlines()[-1])
            print(f"{case:12s} {d['after_import_mb']:10.0f} {d['with_input_mb']:10.0f} {d['peak_mb']:9.0f} "
                  f"{d['peak_mb'] - d['with_input_mb']:8.0f} {d['seconds']:6.1f}  {d['result']}")


if __name__ == "__main__":
    main()
