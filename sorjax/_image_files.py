"""Image files as the command line reads them: which files are images, their size read
from the file's header before anything is decoded, and the decoding itself.

* Which files are images: every format OpenCV's ``imread`` reads, by suffix
  (:data:`IMAGE_SUFFIXES`, its documentation's list), and a file of another suffix
  (not an outline file's, :data:`OUTLINE_SUFFIXES`) whose content OpenCV recognises
  (``cv2.haveImageReader``: the file's first bytes, its signature) -- a PPM or a PNG
  without its suffix is not read as outline text.
* The size: an image above :data:`MAX_IMAGE_PIXELS` (the pixel limit of an object
  region, ``sorjax._masks.MAX_WINDOW_PIXELS``, 60 Mpx) is refused from its header, in
  milliseconds, instead of after minutes and gigabytes of decoding (a 20000 x 20000 PNG
  took 3-7 minutes and several GB).  Pillow (installed with matplotlib) reads the
  header of most formats without decoding (``Image.open(p).size``; its own
  decompression-bomb limit is lifted for that read, which decodes nothing);
  PFM, Radiance HDR and OpenEXR, which it does not read, have their headers parsed
  here.  (OpenCV's ``OPENCV_IO_MAX_IMAGE_PIXELS`` cannot serve: OpenCV reads it once,
  when ``cv2`` is imported, which ``import sorjax`` does.)  A file whose header
  neither reads is left to OpenCV, whose own limit is 1 Gpx.
* The decoding: OpenCV's log (its messages on malformed files) is silenced for the
  call; a file it cannot decode is a one-line ValueError.
"""

from __future__ import annotations

import contextlib
import re
import struct
import warnings
from pathlib import Path

import numpy as np

from ._masks import MAX_WINDOW_PIXELS

# The formats of OpenCV's imread (its documentation, 4.x and 5.x; a build may lack some
# codecs, e.g. OpenEXR or JPEG XL: such a file is then refused as unreadable).
IMAGE_SUFFIXES = (
    ".png", ".jpg", ".jpeg", ".jpe", ".bmp", ".dib", ".tif", ".tiff", ".webp", ".avif",
    ".jp2", ".j2k", ".pbm", ".pgm", ".ppm", ".pxm", ".pnm", ".pfm", ".sr", ".ras",
    ".exr", ".hdr", ".pic", ".gif", ".jxl",
)
# Suffixes of outline files (:func:`sorjax.cli._read_outlines`): read as outlines whatever
# their content; any other suffix is an image when OpenCV recognises the content.
OUTLINE_SUFFIXES = (".npy", ".npz", ".txt", ".csv")
# The most pixels an image file may have (checked on its header, before decoding): the
# limit of an object region (``sorjax._masks.MAX_WINDOW_PIXELS``).
MAX_IMAGE_PIXELS = MAX_WINDOW_PIXELS
_HEADER_BYTES = 1 << 16  # read of PFM, HDR and EXR headers


@contextlib.contextmanager
def _opencv_quiet():
    """OpenCV's log silenced (it prints "[ERROR:0@...] ... readHeader ..." on malformed
    files and "[ WARN:0@...] ... can't open/read file" on missing ones)."""
    import cv2

    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None or not hasattr(log, "setLogLevel"):
        yield
        return
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        log.setLogLevel(level)


def opencv_reads(path) -> bool:
    """Whether OpenCV recognises the content of the existing file ``path`` as an image
    (its signature; nothing is decoded)."""
    import cv2

    have = getattr(cv2, "haveImageReader", None)
    if have is None or not Path(path).is_file():
        return False
    try:
        with _opencv_quiet():
            return bool(have(str(path)))
    except Exception:  # noqa: BLE001  (an unreadable file is not an image)
        return False


def is_image_file(path) -> bool:
    """Whether the command line reads ``path`` as an image: an image suffix
    (:data:`IMAGE_SUFFIXES`), or a suffix other than an outline file's
    (:data:`OUTLINE_SUFFIXES`) on a file whose content OpenCV recognises."""
    suffix = Path(path).suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        return True
    return suffix not in OUTLINE_SUFFIXES and opencv_reads(path)


def _pillow_size(path) -> tuple[int, int] | None:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover  (matplotlib installs it)
        return None
    limit = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None  # its bomb check: this read decodes nothing, and sorjax's limit is lower
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                w, h = im.size
        return int(w), int(h)
    except Exception:  # noqa: BLE001  (a format it does not read, or a broken header)
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = limit


def _pfm_size(head: bytes) -> tuple[int, int] | None:
    if head[:2] not in (b"PF", b"Pf"):
        return None
    tok = head.split(None, 3)
    return int(tok[1]), int(tok[2])


_HDR_RESOLUTION = re.compile(rb"\s*[-+]([XY])\s+(\d+)\s+[-+]([XY])\s+(\d+)\s*")


def _hdr_size(head: bytes) -> tuple[int, int] | None:
    """Radiance HDR: the resolution line after the header's blank line, e.g. ``-Y 480 +X 640``."""
    if not head.startswith((b"#?RADIANCE", b"#?RGBE")):
        return None
    for line in head.split(b"\n")[1:]:
        m = _HDR_RESOLUTION.fullmatch(line)
        if m:
            n1, n2 = int(m.group(2)), int(m.group(4))
            return (n2, n1) if m.group(1) == b"Y" else (n1, n2)
    return None


def _exr_size(head: bytes) -> tuple[int, int] | None:
    """OpenEXR: the ``dataWindow`` attribute (box2i: xMin, yMin, xMax, yMax) of the header."""
    if head[:4] != b"\x76\x2f\x31\x01":
        return None
    i = 8
    while i < len(head) and head[i] != 0:
        j = head.index(b"\0", i)
        k = head.index(b"\0", j + 1)
        size = int.from_bytes(head[k + 1:k + 5], "little")
        if head[i:j] == b"dataWindow" and head[j + 1:k] == b"box2i" and size == 16:
            x0, y0, x1, y1 = struct.unpack("<4i", head[k + 5:k + 21])
            return x1 - x0 + 1, y1 - y0 + 1
        i = k + 5 + size
    return None


def header_size(path) -> tuple[int, int] | None:
    """``(width, height)`` px of the image file ``path`` from its header, nothing
    decoded; None where neither Pillow nor the parsers here read it."""
    size = _pillow_size(path)
    if size is not None:
        return size
    try:
        with open(path, "rb") as f:
            head = f.read(_HEADER_BYTES)
        for parse in (_pfm_size, _hdr_size, _exr_size):
            size = parse(head)
            if size is not None:
                return size
    except (OSError, ValueError, IndexError, struct.error):
        pass
    return None


def check_image_size(path, limit: int | None = None) -> tuple[int, int] | None:
    """The header size of the image file ``path`` (:func:`header_size`), after checking it
    against ``limit`` pixels (None: :data:`MAX_IMAGE_PIXELS`): a ValueError above it."""
    limit = MAX_IMAGE_PIXELS if limit is None else limit
    size = header_size(path)
    if size is not None and size[0] * size[1] > limit:
        w, h = size
        raise ValueError(
            f"{path}: the image is {w} x {h} px ({w * h / 1e6:.0f} Mpx), above the {limit / 1e6:.0f} Mpx this command "
            f"reads (memory; read from the file's header, nothing decoded). Downsample it (e.g. cv2.resize with "
            f"cv2.INTER_AREA; its masks alike) or crop it around the objects"
        )
    return size


def read_image(path, flags) -> np.ndarray:
    """The image file ``path`` decoded by ``cv2.imread(path, flags)``, after
    :func:`check_image_size`; a one-line ValueError for a missing file, an image above
    the limit, or a file OpenCV cannot decode (its log silenced)."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{path}: no such file")
    check_image_size(path)
    try:
        with _opencv_quiet():
            img = cv2.imread(str(p), flags)
    except cv2.error as e:  # its own limits (OPENCV_IO_MAX_IMAGE_*), a codec's failure
        raise ValueError(f"{path}: not an image OpenCV can read ({' '.join(str(e).split())})") from None
    if img is None:
        why = ("damaged or truncated?" if opencv_reads(p) else
               "its content is no image format this OpenCV build reads")
        raise ValueError(f"{path}: not an image OpenCV can read ({why})")
    return img
