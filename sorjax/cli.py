"""Command line: ``sorjax calibrate OUTLINE...``, ``sorjax experiment CONFIG.toml`` and ``sorjax table1``.

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


def _find_config(name: str) -> Path:
    p = Path(name)
    if p.is_file():
        return p
    repo = Path(__file__).resolve().parent.parent / "configs"
    for cand in (repo / name, repo / f"{name}.toml"):
        if cand.is_file():
            return cand
    known = sorted(c.stem for c in repo.glob("*.toml")) if repo.is_dir() else []
    raise ValueError(f"{name}: no such config file" + (f" (bundled configs: {', '.join(known)})" if known else ""))


def _experiment(args) -> int:
    from .experiment import load_config, run_experiment

    path = _find_config(args.config)
    cfg = load_config(path)
    res = run_experiment(cfg, out=args.out, trials=args.trials, seed=args.seed, workers=args.workers,
                         progress=not args.quiet, source=path.read_text())
    print((res.path / "table.md").read_text())
    print(f"wrote {res.path}")
    return 0


def _table1(args) -> int:
    args.config = "table1-quick" if args.quick else "table1"
    return _experiment(args)


def _add_run_args(p):
    p.add_argument("--out", default="runs", help="folder for the run directories (default: runs)")
    p.add_argument("--trials", type=int, default=None, help="trials per row (overrides the config)")
    p.add_argument("--seed", type=int, default=None, help="seed (overrides the config)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (0: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="sorjax", description="Camera calibration from surfaces of revolution.")
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate", help="calibrate from outline files (one (N, 2) pixel array per view)")
    c.add_argument("outlines", nargs="+", help=".npy or text files with x y columns")
    c.add_argument("--method", default="bundle", choices=["bundle", "I", "IIa", "IIb"])
    c.add_argument("--aspect-ratio", type=float, default=None, help="known fu / fv")
    c.set_defaults(func=_calibrate)
    e = sub.add_parser("experiment", help="run an experiment config (configs/*.toml)")
    e.add_argument("config", help="a TOML config file, or the name of one in configs/ (e.g. table1-quick)")
    _add_run_args(e)
    e.set_defaults(func=_experiment)
    t = sub.add_parser("table1", help="the paper's Table 1 (configs/table1.toml; --quick: table1-quick.toml)")
    t.add_argument("--quick", action="store_true")
    _add_run_args(t)
    t.set_defaults(func=_table1)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        print(f"sorjax: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
