"""Outlines on disk with what the image said about them.

An outline from a photograph (:func:`sorjax.outlines_from_image`) is a
``sorjax._detect.ImageOutline``: an (N, 2) array in pixels carrying its estimated error
(``outline_error``), its symmetry residual and, when it was averaged with its own mirror
image, the noise that the averaged outline no longer shows (``noise_rms``, ``noise_ell``).
:func:`sorjax.calibrate` reads those attributes; ``np.save`` drops them, and an averaged
outline saved as a plain array then reads as a noise-free one.  :func:`save_outlines`
keeps them in one ``.npz`` file, which :func:`load_outlines` and ``sorjax calibrate
FILE.npz`` read back.

The file holds ``points_0``, ``points_1``, ... ((N_k, 2) float64, px), ``attributes``
((n, A) float64, NaN where an outline has none) and ``attribute_names`` ((A,) str).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from ._detect import ImageOutline

#: the ImageOutline attributes a file keeps, in this order
ATTRIBUTES = ImageOutline.ATTRIBUTES


def save_outlines(path, outlines: Sequence[np.ndarray]) -> str:
    """Write ``outlines`` ((N_k, 2) arrays in pixels, ``ImageOutline`` or plain) with
    their attributes (NaN where absent) to the ``.npz`` file ``path`` (the suffix is
    added when missing); returns the path written.  Plain arrays keep only their points."""
    if isinstance(outlines, np.ndarray) and outlines.ndim == 2:
        raise ValueError("save_outlines takes a list of outlines; got one (N, 2) array: pass [outline]")
    arrays = {}
    rows = []
    for k, o in enumerate(outlines):
        p = np.asarray(o, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
            raise ValueError(f"outline {k}: expected an (N, 2) array of pixel coordinates, N >= 3; got shape {p.shape}")
        arrays[f"points_{k}"] = p
        rows.append([_number(getattr(o, a, math.nan)) for a in ATTRIBUTES])
    if not rows:
        raise ValueError("no outlines to save")
    path = os.fspath(path)
    if not path.endswith(".npz"):
        path += ".npz"
    np.savez(path, attributes=np.array(rows, np.float64), attribute_names=np.array(ATTRIBUTES), **arrays)
    return path


def load_outlines(path) -> list[ImageOutline]:
    """The outlines of a :func:`save_outlines` file, as ``ImageOutline`` arrays with
    their attributes (NaN where none was saved).  A ValueError says what is wrong with a
    file that is not one."""
    what = f"{os.fspath(path)}: not an outline file written by sorjax.save_outlines"
    if not os.path.isfile(path):
        raise ValueError(f"{os.fspath(path)}: no such file")
    if os.path.getsize(path) == 0:
        raise ValueError(f"{what} (the file is empty)")
    try:
        z = np.load(path, allow_pickle=False)
    except Exception:  # noqa: BLE001  (truncated, text, pickled: the user's file to fix)
        raise ValueError(f"{what} (not a .npz archive numpy can read)") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise ValueError(f"{what} (a single array, not a .npz archive of outlines)")
    try:
        with z:
            missing = [k for k in ("attribute_names", "attributes", "points_0") if k not in z.files]
            if missing:
                raise ValueError(f"{what} (no {', '.join(missing)} in it)")
            names = [str(n) for n in z["attribute_names"]]
            attrs = np.asarray(z["attributes"], np.float64)
            n = sum(1 for key in z.files if key.startswith("points_"))
            points = [np.asarray(z[f"points_{k}"], np.float64) for k in range(n)]
    except ValueError:
        raise
    except Exception as e:  # noqa: BLE001
        raise ValueError(f"{what} ({type(e).__name__}: {e})") from None
    if attrs.shape != (n, len(names)):
        raise ValueError(f"{what} ({n} outlines but an attributes array of shape {attrs.shape}, "
                         f"not ({n}, {len(names)}))")
    out = []
    for k, p in enumerate(points):
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"{what} (points_{k} has shape {p.shape}, not (N, 2))")
        kw = {a: float(attrs[k, names.index(a)]) for a in ATTRIBUTES if a in names}
        out.append(ImageOutline(p, **kw))
    return out


def _number(x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return math.nan
    return x if math.isfinite(x) else math.nan
