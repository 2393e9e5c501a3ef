"""Command line: ``sorjax calibrate IMAGE|OUTLINE... [--masks ...] [--boxes ...] [--out camera.yaml]``,
``sorjax experiment CONFIG.toml`` and ``sorjax table1``.

``sorjax calibrate`` takes photographs (objects found automatically, or inside
``--boxes``, or given by ``--masks``; each object one view) or outline files (one
outline per file: ``.npy``, or text with two columns ``x y`` in pixels), calibrates,
prints K with its standard deviations and a per-view table, and with ``--out`` writes
an OpenCV YAML, a JSON twin and overlay images.  Errors in the input are reported in one line with
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


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


def _read_image(path: str, flags) -> np.ndarray:
    import cv2

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{path}: no such file")
    img = cv2.imread(str(p), flags)
    if img is None:
        raise ValueError(f"{path}: not an image OpenCV can read")
    return img


def _read_boxes(path: str | None, images: list[str]) -> list:
    if path is None:
        return [None] * len(images)
    import json

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    if isinstance(data, list):
        if len(data) != len(images):
            raise ValueError(f"{path}: a list of boxes needs one entry per image ({len(images)}), got {len(data)}")
        return data
    if isinstance(data, dict):
        return [data.get(Path(f).name, data.get(f)) for f in images]
    raise ValueError(f"{path}: expected {{image file name: [[x0, y0, x1, y1], ...]}} or one list per image")


def _mask_outlines(mask: np.ndarray, name: str) -> list[np.ndarray]:
    """Outlines of a mask file: binary/soft masks directly; a label image (more than
    two values) gives one set of outlines per non-zero label."""
    import sorjax

    if mask.ndim == 3:
        mask = mask[..., 0] if np.all(mask == mask[..., :1]) else mask.max(axis=2)
    vals = np.unique(mask)
    if mask.dtype.kind in "iu" and len(vals) > 2 and not (mask.dtype == np.uint8 and vals.min() == 0 and vals.max() == 255
                                                          and len(vals) > 16):
        out = []
        for v in vals[vals != 0]:
            out.extend(sorjax.outlines_from_mask(mask, label=v))
        if not out:
            raise ValueError(f"{name}: no object in this label image")
        return out
    return sorjax.outlines_from_mask(mask)


def _views_from_images(args):
    """(outlines, sources, images, size) from the image files (and masks/boxes)."""
    import cv2

    import sorjax

    if args.masks and len(args.masks) != len(args.outlines):
        raise ValueError(f"--masks needs one mask per image: {len(args.outlines)} images, {len(args.masks)} masks")
    boxes = _read_boxes(args.boxes, args.outlines)
    outlines, sources, images, size = [], [], [], None
    for k, f in enumerate(args.outlines):
        img = _read_image(f, cv2.IMREAD_COLOR)
        h, w = img.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise ValueError(f"{f}: {w}x{h} px, but the first image is {size[0]}x{size[1]}: one camera, one image size")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                if args.masks:
                    mask = _read_image(args.masks[k], cv2.IMREAD_UNCHANGED)
                    if mask.shape[:2] != (h, w):
                        raise ValueError(f"{args.masks[k]}: mask is {mask.shape[1]}x{mask.shape[0]} px but its image "
                                         f"{f} is {w}x{h} px")
                    found = _mask_outlines(mask, args.masks[k])
                else:
                    found = sorjax.outlines_from_image(img, boxes=boxes[k])
            except ValueError as e:
                raise ValueError(f"{f}: {e}") from None
        for wmsg in caught:
            print(f"warning: {Path(f).name}: {wmsg.message}", file=sys.stderr)
        for j, o in enumerate(found):
            outlines.append(o)
            sources.append(f"{Path(f).name}#{j}")
        images.append((f, img, len(found)))
    return outlines, sources, images, size


def _nonnegative(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (np.isfinite(x) and x >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return x


def _calibrate(args) -> int:
    import sorjax

    from ._camera_io import draw_overlay, write_camera

    is_image = [Path(f).suffix.lower() in IMAGE_SUFFIXES for f in args.outlines]
    if any(is_image) and not all(is_image):
        raise ValueError("give either images or outline files (.npy/.txt/.csv), not both")
    if not any(is_image) and (args.masks or args.boxes):
        raise ValueError("--masks and --boxes go with images")
    if any(is_image):
        outlines, sources, images, size = _views_from_images(args)
    else:
        outlines = [_read_outline(f) for f in args.outlines]
        sources = [Path(f).name for f in args.outlines]
        images, size = [], None
    print(f"{len(outlines)} outline(s) from {len(args.outlines)} file(s)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = sorjax.calibrate(outlines, method=args.method, aspect_ratio=args.aspect_ratio,
                               outline_error=args.outline_error, image_size=size)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    used = set(cal.used)
    rms = dict(zip(cal.used, np.asarray(cal.view_rms).tolist()))
    dropped = dict(getattr(cal, "dropped", ()))
    print(" view  source                          symmetry rms (px)  status")
    for i, src in enumerate(sources):
        status = "used" if i in used else f"dropped: {dropped.get(i, 'not used')}"
        r = rms.get(i, float(cal.homologies[i].rms))
        print(f" {i:4d}  {src[:30]:30s}  {r:17.3f}  {status}")
    if args.out is not None and images:
        base = Path(args.out)
        for f, img, n in images:
            first = sources.index(next(s for s in sources if s.startswith(Path(f).name + "#"))) if n else 0
            views = []
            for j in range(n):
                i = first + j
                h = cal.homologies[i]
                views.append((outlines[i], np.asarray(h.l_s), np.asarray(h.v_x), f"{i}" + ("" if i in used else " (dropped)")))
            draw_overlay(img, views, base.parent / f"{base.stem}_overlay_{Path(f).stem}.png")
    if not cal.success:
        print(f"calibration failed: {cal.message}", file=sys.stderr)
        if getattr(cal, "details", ""):
            print(cal.details, file=sys.stderr)
        return 1
    std = cal.std
    print(f"method {cal.method}; views used {len(used)} of {len(outlines)}")
    for n, v, s in zip(("fu", "fv", "u0", "v0"), (cal.fu, cal.fv, cal.u0, cal.v0), std):
        print(f"  {n} = {v:10.3f} px" + (f"  +- {s:.3f}" if np.isfinite(s) else ""))
    print("K =")
    print(np.array2string(np.asarray(cal.K), precision=3, suppress_small=True))
    if np.isfinite(cal.perspective_px):
        print(f"perspective shown by the outlines: {cal.perspective_px:.3g} px RMS (z = {cal.perspective_z:.3g}; "
              f"the focal length needs >= {3 * args.outline_error:.3g} px, 3 x --outline-error)")
    if args.out is not None:
        if size is None:
            pts = np.concatenate([np.asarray(o).reshape(-1, 2) for o in outlines])
            size = tuple(int(np.ceil(x)) + 1 for x in pts.max(axis=0))
        yml, js = write_camera(cal, args.out, size, sources)
        print(f"wrote {yml} and {js}")
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
    from .experiment._runner import use_cpu_devices

    path = _find_config(args.config)
    cfg = load_config(path)
    use_cpu_devices(cfg.workers if args.workers is None else args.workers)  # before JAX starts its backend
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
    p.add_argument("--workers", type=int, default=None, help="CPU devices the trials are split over (0: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="sorjax", description="Camera calibration from surfaces of revolution.")
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate", help="calibrate from photographs (or masks) of SORs, or from outline files")
    c.add_argument("outlines", nargs="+", metavar="FILE",
                   help="images (.png, .jpg, ...) or outline files (.npy, or text with x y columns)")
    c.add_argument("--masks", nargs="+", default=None, help="one mask per image (binary, soft or label image)")
    c.add_argument("--boxes", default=None, help="JSON: {image file name: [[x0, y0, x1, y1], ...]}")
    c.add_argument("--out", default=None, help="camera.yaml to write (OpenCV FileStorage, plus a .json twin and "
                   "one overlay PNG per image)")
    c.add_argument("--method", default="bundle", choices=["bundle", "I", "IIa", "IIb"])
    c.add_argument("--aspect-ratio", type=float, default=None, help="known fu / fv")
    c.add_argument("--outline-error", type=_nonnegative, default=0.1, metavar="PX",
                   help="systematic error of the outlines in px that their symmetry does not show "
                        "(segmentation, lens distortion); the outlines must show 3x this much perspective "
                        "for the focal length to count as determined (default 0.1; 0 for exact outlines)")
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
