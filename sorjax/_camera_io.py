"""Writing a calibration: OpenCV FileStorage YAML, a JSON twin, overlay images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ._files import atomic_path, write_text

NAMES = ("fu", "fv", "u0", "v0")


def write_camera(cal, path, image_size: tuple[int, int], sources=()) -> tuple[Path, Path]:
    """Write ``cal`` to ``path`` (OpenCV FileStorage YAML: ``camera_matrix``,
    ``image_width``, ``image_height``, ``intrinsics_std`` = std of (fu, fv, u0, v0)
    in px, ``distortion_coefficients`` in OpenCV's order ``(k1, k2, p1, p2, k3)``,
    ``method``) and to the same path with suffix ``.json`` (also the per-view symmetry
    RMS and the evidence for perspective, ``perspective_px`` / ``perspective_z``; null
    when not computed).  Returns both paths.

    The distortion coefficients are :func:`distortion_coefficients` of ``cal``: its
    estimated radial ``cal.distortion`` (k1[, k2]) when it has one, else zeros (a
    pinhole camera); ``cv2.undistort(image, camera_matrix, distortion_coefficients)``
    uses them as they are.  The JSON also has ``distortion`` (``k1``, ``k2``) and
    ``distortion_std`` (from ``cal.distortion_std``), null when not estimated, and per
    used view the outlines' systematic offset the bundle estimated with its std
    (``outline_offset_px``, ``outline_offset_std_px``: ``cal.outline_offset``)."""
    import cv2

    path, twin = camera_paths(path)
    K = np.asarray(cal.K, dtype=np.float64)
    std = np.asarray(cal.std, dtype=np.float64).reshape(1, 4)
    dist, dist_std = distortion_coefficients(cal)
    with atomic_path(path) as tmp:  # a temporary file beside it, renamed when complete
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise OSError(f"{path}: could not open the file for writing")
        try:
            fs.write("image_width", int(image_size[0]))
            fs.write("image_height", int(image_size[1]))
            fs.write("camera_matrix", K)
            fs.write("intrinsics_std", std)
            fs.write("distortion_coefficients", dist.reshape(1, 5))
            fs.write("method", str(cal.method))
            fs.write("views_used", int(len(cal.used)))
        finally:
            fs.release()
    write_text(twin, json.dumps(dict(
        image_width=int(image_size[0]), image_height=int(image_size[1]), camera_matrix=K.tolist(),
        intrinsics=dict(zip(NAMES, map(float, (cal.fu, cal.fv, cal.u0, cal.v0)))),
        intrinsics_std=dict(zip(NAMES, [None if not np.isfinite(s) else float(s) for s in std[0]])),
        method=cal.method, aspect_ratio=cal.aspect_ratio, success=bool(cal.success), message=cal.message,
        views=[dict(source=str(src), used=i in cal.used) for i, src in enumerate(sources)],
        dropped=[dict(view=int(i), reason=r) for i, r in getattr(cal, "dropped", ())],
        view_rms_px=[float(x) for x in np.asarray(cal.view_rms)],
        perspective_px=_finite_or_none(getattr(cal, "perspective_px", float("nan"))),
        perspective_z=_finite_or_none(getattr(cal, "perspective_z", float("nan"))),
        distortion_coefficients=dist.tolist(),
        distortion=None if dist_std is None else dict(k1=float(dist[0]), k2=float(dist[1])),
        distortion_std=None if dist_std is None else dict(zip(("k1", "k2"), map(_finite_or_none, dist_std))),
        outline_offset_px=_per_view(getattr(cal, "outline_offset", None)),
        outline_offset_std_px=_per_view(getattr(cal, "outline_offset_std", None)),
    ), indent=1))
    return path, twin


def _per_view(x):
    """A per-used-view array as a JSON list (null entries where not finite), or None."""
    return None if x is None else [_finite_or_none(v) for v in np.asarray(x, np.float64).ravel()]


def camera_paths(path) -> tuple[Path, Path]:
    """The two files :func:`write_camera` writes for ``path``: the YAML (``path``
    itself when it ends in .yaml, .yml or .xml, else with the suffix .yaml) and its
    JSON twin (the YAML's path with the suffix .json)."""
    path = Path(path)
    if path.suffix.lower() not in (".yaml", ".yml", ".xml"):
        path = path.with_suffix(".yaml")
    return path, path.with_suffix(".json")


def distortion_coefficients(cal):
    """``(coefficients (5,), std (2,) or None)``: OpenCV's ``(k1, k2, p1, p2, k3)`` of
    ``cal.distortion`` (radial ``(k1,)`` or ``(k1, k2)``, or five OpenCV coefficients;
    tangential terms zero) and the std of ``(k1, k2)`` (``cal.distortion_std``; NaN
    where absent, 0 for a coefficient not estimated); zeros and None when ``cal`` has
    no finite distortion (a pinhole camera)."""
    from .core._distortion import opencv_coefficients

    k = getattr(cal, "distortion", None)
    if k is None:
        return np.zeros(5), None
    k = np.asarray(k, dtype=np.float64).reshape(-1)
    if k.size == 0 or not np.all(np.isfinite(k)):
        return np.zeros(5), None
    coeffs = k.copy() if k.size == 5 else opencv_coefficients(k)
    s = getattr(cal, "distortion_std", None)
    std = np.full(2, np.nan)
    if s is not None:
        s = np.asarray(s, dtype=np.float64).reshape(-1)[:2]
        std[: s.size] = s
    if k.size == 1:
        std[1] = 0.0
    return coeffs, std


def _finite_or_none(x):
    x = float(x)
    return x if np.isfinite(x) else None


def clip_line(l, w, h):
    """End points of the homogeneous line ``l`` inside the ``w`` x ``h`` image, or None."""
    pts = []
    for x in (0.0, w - 1.0):
        if abs(l[1]) > 1e-12:
            y = -(l[0] * x + l[2]) / l[1]
            if 0 <= y <= h - 1:
                pts.append((x, y))
    for y in (0.0, h - 1.0):
        if abs(l[0]) > 1e-12:
            x = -(l[1] * y + l[2]) / l[0]
            if 0 <= x <= w - 1:
                pts.append((x, y))
    return (pts[0], pts[-1]) if len(pts) >= 2 else None


def _lens_maps(lens):
    """``(distort, undistort)`` of pixel points (numpy in, numpy out) for ``lens = (K,
    k)`` (the pinhole intrinsics, px, and OpenCV's radial coefficients), or the
    identity for None."""
    if lens is None:
        ident = lambda x: np.asarray(x, np.float64)  # noqa: E731
        return ident, ident
    from .core._distortion import distort, undistort

    K, k = (np.asarray(a, np.float64) for a in lens)
    return (lambda x: np.asarray(distort(np.asarray(x, np.float64), K, k)),
            lambda x: np.asarray(undistort(np.asarray(x, np.float64), K, k)))


def mirror_pairs(outline, l, v, lens=None, count: int = 5):
    """``count`` points ``x`` spread along ``outline`` (px) and their mirror images
    ``W x`` by the harmonic homology of axis ``l`` and vertex ``v`` (homogeneous,
    pixels) -- ``D(W D^-1(x))`` through the radial distortion of ``lens = (K, k)``
    when given (``l``, ``v`` then of the pinhole image): ``(x (n, 2), W x (n, 2))``,
    the points whose image is at infinity left out.  On a symmetric outline each ``W
    x`` lies on the outline again."""
    from ._homology import homology_matrix

    o = np.asarray(outline, np.float64)
    dist, undist = _lens_maps(lens)
    W = np.asarray(homology_matrix(np.asarray(v, np.float64), np.asarray(l, np.float64)))
    ps = o[np.linspace(0, len(o), count + 1, endpoint=False).astype(int)[1:]]
    qh = np.c_[undist(ps), np.ones(len(ps))] @ W.T
    ok = np.abs(qh[:, 2]) > 1e-12 * np.linalg.norm(qh, axis=1)
    qs = dist(qh[ok, :2] / qh[ok, 2:]) if ok.any() else np.zeros((0, 2))
    return ps[ok], qs


def draw_overlay(image, views, path, lens=None) -> Path:
    """Draw each view's outline (green), its axis ``l_s`` (magenta), five transferred
    point pairs ``x <-> W x`` (yellow) and an arrow towards ``v_x`` (red) on a copy of
    ``image`` (BGR) and write it to ``path``.  ``views``: ``(outline, l_s, v_x, label)``
    in pixels.

    ``lens``: ``(K, k)`` when the calibration estimated radial distortion (``K`` the
    pinhole intrinsics, px; ``k`` OpenCV's radial coefficients): ``l_s`` and ``v_x``
    are then those of the pinhole (undistorted) image, and the overlay shows them in
    the distorted photograph: the axis as the curve ``D(l_s)`` (points of the line,
    distorted), each pair as ``x <-> D(W D^-1(x))`` (:func:`sorjax.core._distortion.distort`)."""
    import cv2

    img = np.ascontiguousarray(image).copy()
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.dtype != np.uint8:
        img = np.clip(img * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    h, w = img.shape[:2]
    sh = 4  # fixed-point bits for sub-pixel drawing
    pix = lambda p: tuple(int(round(c * (1 << sh))) for c in p)  # noqa: E731
    dist, undist = _lens_maps(lens)
    for outline, l, v, label in views:
        o = np.asarray(outline, dtype=np.float64)
        cv2.polylines(img, [np.round(o * (1 << sh)).astype(np.int32)], True, (0, 200, 0), 1, cv2.LINE_AA, sh)
        if l is None:
            continue
        l, v = np.asarray(l, dtype=np.float64), np.asarray(v, dtype=np.float64)
        # the axis, clipped to the image in the undistorted frame (the distortion is
        # mild at the border) and drawn as a polyline through 64 of its points
        seg = clip_line(l, w, h)
        if seg:
            t = np.linspace(0.0, 1.0, 64 if lens is not None else 2)[:, None]
            curve = dist((1.0 - t) * np.asarray(seg[0]) + t * np.asarray(seg[1]))
            cv2.polylines(img, [np.round(curve * (1 << sh)).astype(np.int32)], False, (255, 0, 255), 1,
                          cv2.LINE_AA, sh)
        for p, q in zip(*mirror_pairs(o, l, v, lens)):
            cv2.line(img, pix(p), pix(q), (0, 220, 255), 1, cv2.LINE_AA, sh)
            cv2.circle(img, pix(q), 3 << sh, (0, 220, 255), 1, cv2.LINE_AA, sh)
        c = o.mean(0)
        cu = undist(c[None])[0]
        d = v[:2] - cu * v[2]
        d = d / (np.linalg.norm(d) + 1e-300)
        tip = dist((cu + 50 * d)[None])[0]
        cv2.arrowedLine(img, pix(c), pix(tip), (0, 0, 255), 2, cv2.LINE_AA, sh, 0.3)
        cv2.putText(img, label, (int(c[0]) + 5, int(c[1]) - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 255), 1,
                    cv2.LINE_AA)
    path = Path(path)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"{path}: could not write the overlay image")
    return path
