"""Command line: ``sorjax calibrate IMAGE|OUTLINE... [--masks ...] [--boxes ...] [--out camera.yaml]``,
``sorjax experiment CONFIG.toml`` and ``sorjax table1``.

``sorjax calibrate`` takes photographs (objects found automatically, or inside
``--boxes``, or given by ``--masks``; each object one view) or outline files (one
outline per file: ``.npy``, or text with two columns ``x y`` in pixels; or ``.npz``
files of :func:`sorjax.save_outlines`, several outlines each with their error
attributes), calibrates,
prints K with its standard deviations and a per-view table, and with ``--out`` writes
an OpenCV YAML, a JSON twin and overlay images.  Errors in the input are reported in one line with
exit code 2, never a traceback; an image that gives no outline is dropped with a one-line warning and
the run goes on with the others.  Images are files of any format OpenCV reads (by suffix, or by
content for other suffixes than an outline file's: :mod:`sorjax._image_files`); one above 60 Mpx
is refused from its header, before it is decoded.  Outlines found in photographs (no ``--masks``), and outline files
of :func:`sorjax.save_outlines` whose outlines carry an ``outline_error`` (every outline of the run
then), are calibrated with the outline error measured from the outlines
(``calibrate(outline_error="measured")``).

Outputs are safe: every file to write is checked before any work (its folder exists
or can be created and is writable, it is not one of the inputs), each is written to a
temporary file beside it and renamed when complete, and an experiment's run
directory stays inside ``--out``.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

import numpy as np

from . import _image_files


def _read_outlines(path: str) -> list[np.ndarray]:
    """The outlines of one outline file: one from ``.npy`` or text, every one of a
    :func:`sorjax.save_outlines` ``.npz`` (with their attributes); each checked as
    :func:`sorjax.calibrate` checks outlines (at least ``MIN_POINTS`` points, closed,
    ...), the message naming the file.  An empty or unreadable file is a one-line
    ValueError (numpy's "input contained no data" warning caught, not printed)."""
    from ._image_files import opencv_reads
    from ._outline import validate_points

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{path}: no such file")
    if p.suffix.lower() == ".npz":  # an empty one: "not an outline file written by sorjax.save_outlines (...)"
        from ._outline_files import load_outlines

        read = load_outlines(p)
    elif p.stat().st_size == 0:
        raise ValueError(f"{path}: the file is empty; an outline file holds one outline, x y pixel coordinates "
                         "(a row per point, as text or .npy), or the outlines of sorjax.save_outlines (.npz)")
    else:
        try:
            with warnings.catch_warnings(record=True):  # loadtxt's "input contained no data": said below
                warnings.simplefilter("always")
                if p.suffix.lower() == ".npy":
                    read = [np.load(p, allow_pickle=False)]
                else:
                    read = [np.loadtxt(p, delimiter="," if p.suffix.lower() == ".csv" else None, ndmin=2)]
        except Exception as e:  # unreadable files are the user's to fix
            if opencv_reads(p):
                raise ValueError(f"{path}: an image (by its content), not an outline file: give it its image "
                                 "suffix (.png, .jpg, ...) to calibrate from the photograph") from None
            raise ValueError(f"{path}: could not read an (N, 2) array of pixel coordinates "
                             f"({' '.join(str(e).split())})") from None
        if not isinstance(read[0], np.ndarray):  # np.load of a zip: an .npz archive under another suffix
            read[0].close()
            raise ValueError(f"{path}: an .npz archive, not one array: name it .npz if sorjax.save_outlines wrote it, "
                             "or save one outline per file with np.save")
        if read[0].size == 0:
            raise ValueError(f"{path}: holds no numbers (only blank lines or comments); an outline file holds x y "
                             "pixel coordinates, a row per point")
    for k, o in enumerate(read):
        validate_points(o, name=path if len(read) == 1 else f"{path}: outline {k}")
    return read


# every format OpenCV's imread reads (sorjax._image_files): .png, .jpg, .ppm, .pfm, .exr, .hdr, ...
IMAGE_SUFFIXES = _image_files.IMAGE_SUFFIXES


def _read_image(path: str, flags) -> np.ndarray:
    """``cv2.imread(path, flags)``, its size first read from the file's header and refused
    above ``sorjax._image_files.MAX_IMAGE_PIXELS`` before anything is decoded."""
    return _image_files.read_image(path, flags)


def _read_boxes(path: str | None, images: list[str]) -> list:
    """One entry per image (None: automatic detection) from the ``--boxes`` JSON: a
    list (one entry per image) or ``{image file name (or path as given): boxes}``.
    A key that names no image, or a file name shared by several images, is an error."""
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
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: could not be read ({e})") from None
    if isinstance(data, list):
        if len(data) != len(images):
            raise ValueError(f"{path}: a list of boxes needs one entry per image ({len(images)}), got {len(data)}")
        return data
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected {{image file name: [[x0, y0, x1, y1], ...]}} or one list per image")
    as_given = [os.path.normpath(f) for f in images]
    names = [Path(f).name for f in images]
    out = [None] * len(images)
    unmatched = []
    for key, boxes in data.items():
        hits = [i for i, g in enumerate(as_given) if g == os.path.normpath(key)]
        if not hits:
            hits = [i for i, n in enumerate(names) if n == key]
            if len({as_given[i] for i in hits}) > 1:
                raise ValueError(f"{path}: the key {key!r} names {len(hits)} different images "
                                 f"({', '.join(images[i] for i in hits)}); key them by their paths as given")
        if not hits:
            unmatched.append(key)
        for i in hits:
            out[i] = boxes
    if unmatched:
        shown = ", ".join(map(repr, unmatched[:5])) + (" ..." if len(unmatched) > 5 else "")
        raise ValueError(f"{path}: {len(unmatched)} key(s) name no image given: {shown}; the keys must be the "
                         f"images' file names ({', '.join(sorted(set(names))[:5])}) or their paths as given")
    return out


def _chunks(n: int, width: int):
    step = max(1, (1 << 22) // max(width, 1))
    for i in range(0, n, step):
        yield i, min(n, i + step)


def _mask_channel(mask: np.ndarray) -> np.ndarray:
    """One channel of a colour mask file: the alpha of an RGBA mask when it varies (a
    cut-out), else the colour channels: one when they are equal, their maximum when not."""
    if mask.shape[2] == 4:
        alpha = mask[:, :, 3]
        if alpha.min() != alpha.max():
            return alpha
        mask = mask[:, :, :3]  # opaque (alpha constant): the colour is the mask
    H, W = mask.shape[:2]
    if all(np.all(mask[i0:i1] == mask[i0:i1, :, :1]) for i0, i1 in _chunks(H, W)):
        return mask[:, :, 0]
    out = np.empty((H, W), mask.dtype)
    for i0, i1 in _chunks(H, W):
        out[i0:i1] = mask[i0:i1].max(axis=2)
    return out


def _value_counts(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct values of ``mask`` and their pixel counts, a block of rows at a time."""
    H, W = mask.shape
    if mask.dtype in (np.uint8, np.uint16):
        counts = np.zeros(1 << (8 * mask.dtype.itemsize), np.int64)
        for i0, i1 in _chunks(H, W):
            counts += np.bincount(mask[i0:i1].ravel(), minlength=len(counts))
        vals = np.flatnonzero(counts)
        return vals.astype(mask.dtype), counts[vals]
    tally: dict = {}
    for i0, i1 in _chunks(H, W):
        v, c = np.unique(mask[i0:i1], return_counts=True)
        for x, n in zip(v.tolist(), c.tolist()):
            tally[x] = tally.get(x, 0) + n
    vals = np.array(sorted(tally), dtype=mask.dtype)
    return vals, np.array([tally[x] for x in vals.tolist()], np.int64)


def _mask_outlines(mask: np.ndarray, name: str) -> list[np.ndarray]:
    """Outlines of a mask file, whatever it holds:

    * two values (0/255, 0/1, 0/65535, any two levels): a binary mask, the higher value
      the object;
    * 8- or 16-bit with 0 and full scale (255, 65535) and values between on fewer pixels
      than full scale (anti-aliased or quantised edges, e.g. 0/128/255): a soft mask;
    * float in [0, 1]: a soft mask;
    * any other integer mask: a label image, one set of outlines per positive label.

    A colour file gives one channel first (:func:`_mask_channel`)."""
    import sorjax

    if mask.ndim == 3:
        mask = _mask_channel(mask)
    vals, counts = _value_counts(mask)
    if len(vals) == 1:
        raise ValueError(f"{name}: the mask is constant (every pixel {vals[0]}): no object marked")
    if len(vals) == 2:
        return sorjax.outlines_from_mask(mask, label=vals[1])
    full = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}.get(mask.dtype)
    if mask.dtype.kind == "f":
        if vals[0] >= 0 and vals[-1] <= 1:
            return sorjax.outlines_from_mask(mask)
        raise ValueError(f"{name}: a float mask must hold values in [0, 1] (or two levels); got values in "
                         f"[{vals[0]:g}, {vals[-1]:g}]")
    if full is not None and vals[0] == 0 and vals[-1] == full and counts[1:-1].sum() < counts[-1]:
        return sorjax.outlines_from_mask(mask)  # soft: edges between 0 and full scale
    out = []
    labels = vals[vals > 0]
    for v in labels:
        try:
            out.extend(sorjax.outlines_from_mask(mask, label=v))
        except ValueError as e:
            warnings.warn(f"label {v}: {e}; left out", stacklevel=2)
    if not out:
        raise ValueError(f"{name}: read as a label image ({len(labels)} positive labels), and no label gave an object "
                         "outline (see the warnings)")
    return out


def _labels(files: list[str]) -> list[str]:
    """How each input file is named in the table, the JSON twin and the overlay names:
    its file name, or its path as given where file names repeat (a/img.png, b/img.png),
    plus ``@k`` (its position) where even that repeats."""
    names = [Path(f).name for f in files]
    out = [n if names.count(n) == 1 else os.path.normpath(f) for n, f in zip(names, files)]
    return [lab if out.count(lab) == 1 else f"{lab}@{k}" for k, lab in enumerate(out)]


def _overlay_paths(yml: Path, files: list[str]) -> list[Path]:
    """One overlay PNG per image beside the camera file: ``<camera>_overlay_<image
    stem>.png``, the stem being the image's path as given (made a plain file name)
    where stems repeat (a/img.png, b/img.png), and ``_2``, ``_3`` added where even
    that repeats: never two images on one file."""
    from ._files import safe_name

    stems = [Path(f).stem for f in files]
    out, taken = [], set()
    for f, stem in zip(files, stems):
        if stems.count(stem) > 1:
            stem = os.path.splitext(os.path.normpath(f))[0]
        base = f"{yml.stem}_overlay_{safe_name(stem, 'image')}"
        name, k = base, 2
        while name in taken:
            name, k = f"{base}_{k}", k + 1
        taken.add(name)
        out.append(yml.parent / f"{name}.png")
    return out


def _plan_outputs(args, images: list[str]):
    """``(camera YAML, JSON twin, overlay PNGs)`` of ``--out``, each checked before any
    work (:func:`sorjax._files.check_output`): a writable place, none of the inputs."""
    from ._camera_io import camera_paths
    from ._files import check_output

    if args.out is None:
        return None
    if args.out.endswith(("/", os.sep)) or Path(args.out).is_dir():
        raise ValueError(f"--out {args.out} is a folder; give the camera file to write, e.g. "
                         f"{os.path.join(args.out, 'camera.yaml')}")
    yml, twin = camera_paths(args.out)
    overlays = _overlay_paths(yml, images) if images else []
    inputs = [*args.outlines, *(args.masks or []), *([args.boxes] if args.boxes else [])]
    for path in (yml, twin, *overlays):
        check_output(path, inputs=inputs, what="--out")
    return yml, twin, overlays


def _views_from_images(args, labels: list[str]):
    """(outlines, sources, images, size, dropped) from the image files (and
    masks/boxes); ``images``: ``(file, index of its first view, number of views)``;
    ``dropped``: the labels of the images that gave no outline.  An image (or mask)
    that gives no outline is dropped with a one-line warning naming it and the run
    goes on (a box that gives none is left out by the extractor, with a warning naming
    it); an image that cannot be read, or whose size differs, is an error.  No image
    is kept in memory (the overlays read them again)."""
    import cv2

    import sorjax

    from ._masks import command_line_hints

    if args.masks and len(args.masks) != len(args.outlines):
        raise ValueError(f"--masks needs one mask per image: {len(args.outlines)} images, {len(args.masks)} masks")
    for f in [*args.outlines, *(args.masks or [])]:  # every size from its header before any image is decoded
        if Path(f).is_file():
            _image_files.check_image_size(f)
    boxes = _read_boxes(args.boxes, args.outlines)
    outlines, sources, images, size, dropped = [], [], [], None, []
    for k, f in enumerate(args.outlines):
        # with a mask the photograph is read for its size only: grey (a third of colour; OpenCV's reader
        # holds about twice its output while decoding)
        img = _read_image(f, cv2.IMREAD_GRAYSCALE if args.masks else cv2.IMREAD_COLOR)
        h, w = img.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise ValueError(f"{f}: {w}x{h} px, but the first image is {size[0]}x{size[1]}: one camera, one image size")
        with warnings.catch_warnings(record=True) as caught, command_line_hints():
            warnings.simplefilter("always")
            if args.masks:
                del img  # a mask needs no photograph: one large array at a time
                try:
                    mask = _read_image(args.masks[k], cv2.IMREAD_UNCHANGED)
                except ValueError as e:
                    raise ValueError(f"{f}: {e}") from None
                if mask.shape[:2] != (h, w):
                    raise ValueError(f"{f}: {args.masks[k]}: mask is {mask.shape[1]}x{mask.shape[0]} px but its "
                                     f"image {f} is {w}x{h} px")
            failure = None
            try:
                if args.masks:
                    found = _mask_outlines(mask, args.masks[k])
                    del mask
                else:
                    found = sorjax.outlines_from_image(img, boxes=boxes[k])
                    del img
            except ValueError as e:  # no outline from this image: the others may still serve
                found, failure = [], e
        for wmsg in caught:
            print(f"warning: {labels[k]}: {wmsg.message}", file=sys.stderr)
        if not found:
            print(f"warning: {labels[k]}: no outline; image dropped, the run goes on without it"
                  + (f": {failure}" if failure else ""), file=sys.stderr)
            dropped.append(labels[k])
        images.append((f, len(outlines), len(found)))
        for j, o in enumerate(found):
            outlines.append(o)
            sources.append(f"{labels[k]}#{j}")
    return outlines, sources, images, size, dropped


OVERLAY_MAX_SIDE = 8192  # px: a larger photograph's overlay is drawn on it read grey at 1/2, 1/4 or 1/8 of its size


def _overlay(f: str, views, png: Path, size, lens=None) -> None:
    """Draw the overlay of image ``f`` (``views`` in its pixels and ``lens``, as for
    :func:`sorjax._camera_io.draw_overlay`) into ``png``; an image larger than
    ``OVERLAY_MAX_SIDE`` is read grey and reduced by OpenCV and the views scaled to it
    (OpenCV decodes the whole image whatever the reduction: a 20000 x 20000 photograph
    costs 2.3 GB in colour, 0.4 GB grey)."""
    import cv2

    from ._camera_io import draw_overlay

    k = next((k for k in (1, 2, 4) if max(size) / k <= OVERLAY_MAX_SIDE), 8)
    flag = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_GRAYSCALE_2, 4: cv2.IMREAD_REDUCED_GRAYSCALE_4,
            8: cv2.IMREAD_REDUCED_GRAYSCALE_8}[k]
    if k > 1:  # pixel centres: x' = (x + 0.5) / k - 0.5
        S = np.array([[1.0 / k, 0.0, 0.5 / k - 0.5], [0.0, 1.0 / k, 0.5 / k - 0.5], [0.0, 0.0, 1.0]])
        ST = np.linalg.inv(S).T
        views = [((np.asarray(o) + 0.5) / k - 0.5, None if l is None else ST @ l, None if v is None else S @ v, lab)
                 for o, l, v, lab in views]
        lens = None if lens is None else (S @ lens[0], lens[1])  # K' = S K: the same normalised coordinates
    draw_overlay(_read_image(f, flag), views, png, lens)


def _number_arg(lo: float, lo_open: bool, what: str):
    """An argparse type: a finite number ``> lo`` (``lo_open``) or ``>= lo``."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not (np.isfinite(x) and (x > lo if lo_open else x >= lo)):
            raise argparse.ArgumentTypeError(f"must be a finite number {'>' if lo_open else '>='} {lo:g}"
                                             f"{f' ({what})' if what else ''}, got {text!r}")
        return x

    return parse


def _int_arg(lo: int, what: str):
    """An argparse type: an integer ``>= lo``."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if n < lo:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lo}{f' ({what})' if what else ''}, got {text!r}")
        return n

    return parse


_nonnegative = _number_arg(0.0, False, "")


def _outline_error_arg(text: str):
    """``--outline-error``: a number of px >= 0, or "measured"."""
    return "measured" if text == "measured" else _nonnegative(text)


def _option_arg(text: str):
    """``--option NAME=VALUE``: a field of :class:`sorjax.Options` and its value."""
    import dataclasses

    from .core._options import Options

    name, eq, value = text.partition("=")
    fields = {f.name: f for f in dataclasses.fields(Options)}
    if not eq or name.strip() not in fields:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE with NAME a field of sorjax.Options "
                                         f"({', '.join(fields)}); got {text!r}")
    try:  # budgets and counts are integers, thresholds numbers (checked again by calibrate)
        return name.strip(), (int(value) if isinstance(getattr(Options(), name.strip()), int) else float(value))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name.strip()}: not a number: {value!r}") from None


def _finite_arg(what: str):
    """An argparse type: any finite number."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not np.isfinite(x):
            raise argparse.ArgumentTypeError(f"must be a finite number ({what}), got {text!r}")
        return x

    return parse


def _calibrate(args) -> int:
    import sorjax

    from ._camera_io import write_camera
    from ._compile import enable_compilation_cache

    # the homology fit and the calibration compile for about 30 s on a CPU: kept on disk,
    # so that only a machine's first run pays for them (experiments do the same)
    enable_compilation_cache()

    is_image = [_image_files.is_image_file(f) for f in args.outlines]  # by suffix, else by content
    if any(is_image) and not all(is_image):
        raise ValueError("give either images or outline files (.npy/.txt/.csv/.npz), not both")
    if not any(is_image) and (args.masks or args.boxes):
        raise ValueError("--masks and --boxes go with images")
    labels = _labels(args.outlines)
    plan = _plan_outputs(args, args.outlines if any(is_image) else [])  # before any work
    if any(is_image):
        outlines, sources, images, size, dropped_images = _views_from_images(args, labels)
    else:
        read = [_read_outlines(f) for f in args.outlines]
        outlines = [o for got in read for o in got]
        sources = [lab if len(got) == 1 else f"{lab}#{j}" for lab, got in zip(labels, read) for j in range(len(got))]
        images, size, dropped_images = [], None, []
    print(f"{len(outlines)} outline(s) from {len(args.outlines)} file(s)"
          + (f" ({len(dropped_images)} image(s) gave none and were dropped)" if dropped_images else ""))
    need = 1 if (args.principal_point is not None or args.centre_principal_point) else 2
    if dropped_images and len(outlines) < need:
        raise ValueError(f"too few views left: {len(outlines)} outline(s) from {len(images) - len(dropped_images)} "
                         f"image(s) after {len(dropped_images)} of {len(images)} gave none "
                         f"({', '.join(dropped_images[:5])}{' ...' if len(dropped_images) > 5 else ''}: see the "
                         f"warnings); calibration needs at least {'one' if need == 1 else 'two'}. Add images, or "
                         "give boxes (--boxes) or masks (--masks) for the objects")
    outline_error = args.outline_error
    if outline_error is None:  # photographs (and saved image outlines): measured; masks and plain files: the default
        measured = any(np.isfinite(getattr(o, "outline_error", np.nan)) for o in outlines)
        outline_error = "measured" if (any(is_image) and not args.masks) or measured else 0.1
    principal_point = args.principal_point
    if args.centre_principal_point:
        if size is None:
            raise ValueError("--centre-principal-point needs the image size, which outline files do not give: pass "
                             "the images (with --masks), or --principal-point CX CY")
        principal_point = "centre"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = sorjax.calibrate(outlines, method=args.method, aspect_ratio=args.aspect_ratio,
                               outline_error=outline_error, image_size=size, distortion=args.distortion,
                               principal_point=principal_point, focal_length=args.focal,
                               options=sorjax.Options(**dict(args.option)))
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    used = set(cal.used)
    rms = dict(zip(cal.used, np.asarray(cal.view_rms).tolist()))
    dropped = dict(getattr(cal, "dropped", ()))
    print(" view  source                          symmetry rms (px)  status")
    for i, src in enumerate(sources):
        status = "used" if i in used else f"dropped: {dropped.get(i, 'not used')}"
        r = rms.get(i, float(cal.homologies[i].rms))
        print(f" {i:4d}  {src if len(src) <= 30 else '...' + src[-27:]:30s}  {r:17.3f}  {status}")
    k_lens = getattr(cal, "distortion", None)
    lens = (np.asarray(cal.K), np.asarray(k_lens)) if (
        cal.success and k_lens is not None and np.all(np.isfinite(np.asarray(k_lens)))) else None
    if plan is not None and images:
        for (f, first, n), png in zip(images, plan[2]):
            views = []
            for i in range(first, first + n):
                h = cal.homologies[i]
                label = f"{i}" + ("" if i in used else " (dropped)")
                if lens is None:
                    views.append((outlines[i], np.asarray(h.l_s), np.asarray(h.v_x), label))
                elif i in used:  # the bundle's axis and vertex, of the pinhole image
                    j = list(cal.used).index(i)
                    views.append((outlines[i], np.asarray(cal.l_s[j]), np.asarray(cal.v_x[j]), label))
                else:  # its own fit is of the distorted outline: the outline only
                    views.append((outlines[i], None, None, label))
            _overlay(f, views, png, size, lens)
    if not cal.success:
        print(f"calibration failed: {cal.message}", file=sys.stderr)
        if getattr(cal, "details", ""):
            print(cal.details, file=sys.stderr)
        return 1
    std = cal.std
    print(f"method {cal.method}; views used {len(used)} of {len(outlines)}")
    f_held = getattr(cal, "fixed_focal_length", None) is not None
    pp_held = getattr(cal, "fixed_principal_point", None) is not None
    held = {"fu": f_held, "fv": f_held, "u0": pp_held, "v0": pp_held}
    for n, v, s in zip(("fu", "fv", "u0", "v0"), (cal.fu, cal.fv, cal.u0, cal.v0), std):
        print(f"  {n} = {v:10.3f} px" + ("  (fixed)" if held[n] else f"  +- {s:.3f}" if np.isfinite(s) else ""))
    if getattr(cal, "distortion", None) is not None:
        for n, v, s in zip(("k1", "k2"), np.asarray(cal.distortion), np.asarray(cal.distortion_std)):
            print(f"  {n} = {v:10.5f}" + (f"     +- {s:.5f}" if np.isfinite(v) else "  (not determined)"))
    print("K =")
    print(np.array2string(np.asarray(cal.K), precision=3, suppress_small=True))
    if np.isfinite(cal.perspective_px):
        print(f"perspective shown by the outlines: {cal.perspective_px:.3g} px RMS (z = {cal.perspective_z:.3g}; "
              f"the focal length needs >= {3 * cal.outline_error:.3g} px, 3 x the outline error of "
              f"{cal.outline_error:.3g} px)")
    off = getattr(cal, "outline_offset", None)
    off_std = getattr(cal, "outline_offset_std", None)
    off = np.asarray(off if off is not None else [], float)
    off_std = np.asarray(off_std if off_std is not None else [], float)
    if off.size and np.all(np.isfinite(off)) and np.ptp(off) == 0:  # one offset shared by the outlines
        print(f"outlines' offset along their normals, estimated with K: {off[0]:+.3g} +- {off_std[0]:.2g} px "
              "(positive: outside the true edge, a dilated mask; its effect is removed from K)")
    if plan is not None:
        if size is None:
            pts = np.concatenate([np.asarray(o).reshape(-1, 2) for o in outlines])
            size = tuple(int(np.ceil(x)) + 1 for x in pts.max(axis=0))
        yml, js = write_camera(cal, plan[0], size, sources)
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

    from .experiment._runner import failure_summary, run_folder

    path = _find_config(args.config)
    cfg = load_config(path)
    run_folder(cfg, args.out, "--out")  # before any trial: the run directory can be written inside --out
    use_cpu_devices(cfg.workers if args.workers is None else args.workers)  # before JAX starts its backend
    res = run_experiment(cfg, out=args.out, trials=args.trials, seed=args.seed, workers=args.workers,
                         progress=not args.quiet, source=path.read_text())
    print((res.path / "table.md").read_text())
    print(f"wrote {res.path}")
    failed = failure_summary(res.records)
    if failed:
        print(f"sorjax: error: {failed}; nothing was estimated (the run directory has the details)", file=sys.stderr)
        return 1
    return 0


def _table1(args) -> int:
    args.config = "table1-quick" if args.quick else "table1"
    return _experiment(args)


def _add_run_args(p):
    p.add_argument("--out", default="runs", help="folder for the run directories (default: runs)")
    p.add_argument("--trials", type=_int_arg(1, "trials per row"), default=None,
                   help="trials per row (overrides the config)")
    p.add_argument("--seed", type=_int_arg(0, ""), default=None, help="seed (overrides the config)")
    p.add_argument("--workers", type=_int_arg(0, "0: one per core"), default=None,
                   help="CPU devices the trials are split over (0: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="sorjax", description="Camera calibration from surfaces of revolution.")
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate", help="calibrate from photographs (or masks) of SORs, or from outline files")
    c.add_argument("outlines", nargs="+", metavar="FILE",
                   help="images (.png, .jpg, ...) or outline files (.npy, or text with x y columns, or .npz of "
                        "sorjax.save_outlines)")
    c.add_argument("--masks", nargs="+", default=None, help="one mask per image (binary, soft or label image)")
    c.add_argument("--boxes", default=None, help="JSON: {image file name: [[x0, y0, x1, y1], ...]}")
    c.add_argument("--out", default=None, help="camera.yaml to write (OpenCV FileStorage, plus a .json twin and "
                   "one overlay PNG per image)")
    c.add_argument("--method", default="bundle", choices=["bundle", "I", "IIa", "IIb"])
    c.add_argument("--aspect-ratio", type=_number_arg(0.0, True, "fu / fv"), default=None, help="known fu / fv")
    c.add_argument("--distortion", choices=("none", "k1", "k1k2"), default="none",
                   help="lens model: none (pinhole, default), k1 or k1k2 (OpenCV's radial terms, estimated by the "
                        "bundle and written to the camera file)")
    pp = c.add_mutually_exclusive_group()
    pp.add_argument("--principal-point", nargs=2, type=_finite_arg("the principal point (px)"), default=None,
                    metavar=("CX", "CY"), help="hold the principal point fixed at (CX, CY) px (OpenCV's "
                    "CALIB_FIX_PRINCIPAL_POINT); one outline is then enough for the focal length")
    pp.add_argument("--centre-principal-point", action="store_true",
                    help="hold the principal point fixed at the image centre ((width - 1) / 2, (height - 1) / 2); "
                         "needs images")
    c.add_argument("--focal", type=_number_arg(0.0, True, "the focal length fv (px)"), default=None, metavar="F",
                   help="hold the focal length fv fixed at F px (fu = aspect ratio x F, the aspect ratio 1 unless "
                        "--aspect-ratio; OpenCV's CALIB_FIX_FOCAL_LENGTH): only the principal point (and the "
                        "distortion) is estimated")
    c.add_argument("--outline-error", type=_outline_error_arg, default=None, metavar="PX|measured",
                   help="systematic error of the outlines in px that their symmetry does not show "
                        "(segmentation, lens distortion); the outlines must show 3x this much perspective "
                        "for the focal length to count as determined. 'measured': the RMS of the views' "
                        "symmetry residuals, at least 0.1 px (the default for photographs without --masks "
                        "and for .npz outline files whose outlines carry an outline_error; otherwise the "
                        "default is 0.1; 0 for exact outlines)")
    c.add_argument("--option", type=_option_arg, action="append", default=[], metavar="NAME=VALUE",
                   help="a threshold or budget of sorjax.Options (its docstring says what each does), repeatable: "
                        "e.g. --option consistency_p=1e-3")
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
    except (ValueError, OSError) as e:  # the user's input or the file system: one line, never a traceback
        print(f"sorjax: error: {' '.join(str(e).splitlines())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
