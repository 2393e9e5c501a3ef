"""Command line: ``sorjax calibrate OUTLINE...`` and ``sorjax table1``.

``sorjax calibrate`` reads one outline per file (``.npy``, or text with two columns
``x y`` in pixels, e.g. ``.txt``/``.csv``), calibrates and prints K with its standard
deviations and a per-view table.  Errors in the input are reported in one line with
exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np


def _read_outline(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        if p.suffix == ".npy":
            return np.load(p)
        delim = "," if p.suffix == ".csv" else None
        return np.loadtxt(p, delimiter=delim, ndmin=2)
    except Exception as e:  # unreadable files are the user's to fix
        raise ValueError(f"{path}: could not read an (N, 2) array of pixel coordinates ({e})") from None


def _calibrate(args) -> int:
    import sorjax

    outlines = [_read_outline(f) for f in args.outlines]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = sorjax.calibrate(outlines, method=args.method, aspect_ratio=args.aspect_ratio)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    if not cal.success:
        print(f"calibration failed: {cal.message}", file=sys.stderr)
        return 1
    std = cal.std
    names = ("fu", "fv", "u0", "v0")
    vals = (cal.fu, cal.fv, cal.u0, cal.v0)
    print(f"method {cal.method}; views used {list(cal.used)} of {len(outlines)}")
    for n, v, s in zip(names, vals, std):
        print(f"  {n} = {v:10.3f} px" + (f"  +- {s:.3f}" if np.isfinite(s) else ""))
    print("K =")
    print(np.array2string(np.asarray(cal.K), precision=3, suppress_small=True))
    print(" view  file                            symmetry rms (px)")
    for k, i in enumerate(cal.used):
        print(f" {i:4d}  {Path(args.outlines[i]).name[:30]:30s}  {float(cal.view_rms[k]):.3f}")
    return 0


def _table1(args) -> int:
    root = Path(__file__).resolve().parent.parent / "experiments" / "table1.py"
    if not root.is_file():
        raise ValueError("experiments/table1.py is not available in this installation")
    import runpy

    sys.argv = [str(root)] + (["--quick"] if args.quick else ["--trials", str(args.trials)]) + ["--seed", str(args.seed)]
    runpy.run_path(str(root), run_name="__main__")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="sorjax", description="Camera calibration from surfaces of revolution.")
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate", help="calibrate from outline files (one (N, 2) pixel array per view)")
    c.add_argument("outlines", nargs="+", help=".npy or text files with x y columns")
    c.add_argument("--method", default="bundle", choices=["bundle", "I", "IIa", "IIb"])
    c.add_argument("--aspect-ratio", type=float, default=None, help="known fu / fv")
    c.set_defaults(func=_calibrate)
    t = sub.add_parser("table1", help="the paper's Table 1 on the two-sphere scene")
    t.add_argument("--quick", action="store_true")
    t.add_argument("--trials", type=int, default=100)
    t.add_argument("--seed", type=int, default=0)
    t.set_defaults(func=_table1)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        print(f"sorjax: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
