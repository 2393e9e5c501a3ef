"""Bad input fails fast and clear at the boundary (issue 42, item 3): each case a
one-line ValueError in the API and exit code 2 with that line on stderr in the command
line, no traceback, no library warning (numpy, OpenCV, Pillow), and refused before any
JAX program is compiled (each API check is timed: far under a compilation's seconds)."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import time
import warnings
import zlib

import numpy as np
import pytest

import sorjax
from sorjax import _image_files
from sorjax._outline import MIN_POINTS
from sorjax.cli import main

FAST_S = 5.0  # an API refusal before any compilation (a compilation takes tens of seconds here)


def _ellipse(n=600, cx=300.0, cy=240.0, a=120.0, b=80.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([cx + a * np.cos(t), cy + b * np.sin(t)], 1)


E = _ellipse()


def _refused(call, *words, exc=ValueError):
    """``call()`` raises ``exc`` with one line holding every one of ``words``, fast and
    with no warning; returns the message."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(exc) as info:
            call()
    took = time.perf_counter() - t0
    msg = str(info.value)
    assert type(info.value) is exc, type(info.value)
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)
    assert not caught, [str(w.message) for w in caught]
    assert took < FAST_S, took
    return msg


def _cli_refused(capfd, argv, *words):
    """``sorjax`` with ``argv``: exit 2, one line on stderr (fd level: OpenCV's C++ log
    included) holding every one of ``words``, no traceback, no warning."""
    capfd.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(argv)
    err = capfd.readouterr().err
    assert code == 2, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sorjax: error: "), err
    assert "Traceback" not in err and "arning" not in err and "WARN" not in err and "ERROR:" not in err, err
    for w in words:
        assert w in err, (w, err)
    assert not caught, [str(w.message) for w in caught]
    return lines[0]


# ------------------------------------------------------------ 1. too few points


def test_too_few_points_named_with_the_outline_and_the_minimum(tmp_path, capfd):
    """An outline of 12 points ended in a FloatingPointError from inside the homology
    fit (exit 1 with a traceback on the command line)."""
    few = _ellipse(12)
    _refused(lambda: sorjax.calibrate([E, few]), "outline 1: has 12 distinct points", f"at least {MIN_POINTS}")
    _refused(lambda: sorjax.fit_homology(few), "outline: has 12 distinct points", f"at least {MIN_POINTS}")
    _refused(lambda: sorjax.make_outline(_ellipse(MIN_POINTS - 1)), f"has {MIN_POINTS - 1} distinct points")
    np.savetxt(tmp_path / "good.txt", E)
    np.savetxt(tmp_path / "few.txt", few)
    _cli_refused(capfd, ["calibrate", str(tmp_path / "good.txt"), str(tmp_path / "few.txt")],
                 "few.txt: has 12 distinct points", f"at least {MIN_POINTS}")


def test_the_minimum_number_of_points_is_enough():
    """``MIN_POINTS`` points fit, where the fit failed up to 25 points (the smallest
    outlines, 11 px across; see ``sorjax._outline.MIN_POINTS``): an ellipse and the exact
    silhouette of a bottle at 11 px, and a vase at 250 px."""
    from sorjax import scenes
    from sorjax._curves import resample_closed

    shapes = [_ellipse(4000, 0.0, 0.0)]
    for name in ("bottle", "vase"):
        o = np.asarray(scenes.random_sor_scene(2, 1, shapes=[name]).outlines[0])
        shapes.append(o - o.mean(0))
    for dense, extent in zip(shapes, (11.0, 11.0, 250.0)):
        p = resample_closed(dense * extent / np.ptp(dense, 0).max(), MIN_POINTS) + 300.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the sparse outline's own note
            h = sorjax.fit_homology(p)
        assert np.isfinite(float(h.rms)) and np.all(np.isfinite(np.asarray(h.v_x))), extent


def test_a_sparse_pixel_trace_is_still_read():
    """A ``cv2.findContours`` trace with ``CHAIN_APPROX_SIMPLE`` may have fewer than
    ``MIN_POINTS`` points; it is replaced by its mask's dense outline, so it is not refused."""
    cv2 = pytest.importorskip("cv2")
    mask = np.zeros((80, 80), np.uint8)
    cv2.ellipse(mask, (40, 40), (9, 6), 0, 0, 360, 255, -1)  # 18 x 12 px: 28 points
    c = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0][0][:, 0, :].astype(np.float64)
    assert len(c) < MIN_POINTS
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the note that it was read as a pixel trace
        o = sorjax.make_outline(c, 256)
    assert np.isfinite(np.asarray(o.points)).all()


# ------------------------------------------------------------ 2. huge images


def _blank_png(path, w: int, h: int) -> None:
    """A ``w x h`` 1-bit all-zero PNG, compressed a block of rows at a time (no ``w h``
    array: 20000 x 20000 takes well under a second and 50 kB)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    row = b"\0" * (1 + (w + 7) // 8)  # filter byte, then w bits
    comp = zlib.compressobj(9)
    idat = b"".join(comp.compress(row * min(1000, h - i)) for i in range(0, h, 1000)) + comp.flush()
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 1, 0, 0, 0, 0))
                + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


def test_a_huge_png_is_refused_from_its_header(tmp_path):
    """A 20000 x 20000 PNG was decoded before the 60 Mpx limit was checked (3-7 minutes,
    several GB); its size is now read from its header.  The command line, in a process
    of its own, refuses it in well under a second (the whole process, imports included:
    about 6 s here; its bound is generous, for a loaded machine) with a peak resident
    memory (VmHWM) under 1 GB (about 190 MB)."""
    huge = tmp_path / "huge.png"
    t0 = time.perf_counter()
    _blank_png(huge, 20000, 20000)
    assert time.perf_counter() - t0 < 10 and huge.stat().st_size < 1_000_000
    assert _image_files.header_size(huge) == (20000, 20000)
    child = (
        "import sys, time\n"
        "from sorjax.cli import main\n"
        "t0 = time.perf_counter()\n"
        f"code = main(['calibrate', {str(huge)!r}])\n"
        "took = time.perf_counter() - t0\n"
        "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')] if sys.platform == 'linux' else []\n"
        "print(code, took, int(hwm[0].split()[1]) * 1024 if hwm else -1)\n"
    )
    t0 = time.perf_counter()
    env = {**os.environ, "SORJAX_CACHE": str(tmp_path / "xla")}
    r = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=120, env=env)
    wall = time.perf_counter() - t0
    code, took, peak = r.stdout.split()
    assert int(code) == 2, r
    assert r.stderr.strip().splitlines() == [
        f"sorjax: error: {huge}: the image is 20000 x 20000 px (400 Mpx), above the 60 Mpx this command reads "
        "(memory; read from the file's header, nothing decoded). Downsample it (e.g. cv2.resize with "
        "cv2.INTER_AREA; its masks alike) or crop it around the objects"], r.stderr
    assert float(took) < 1.0 and wall < 60.0, (took, wall)  # the whole process: about 6 s (imports), alone
    assert int(peak) < 1 << 30, int(peak) / 2**20


def test_the_header_size_of_every_format(tmp_path, monkeypatch):
    """Pillow reads the headers of most formats (its bomb limit, 89 Mpx with a warning
    and 179 Mpx with an error, lifted for the read and restored, no warning); PFM,
    Radiance HDR and OpenEXR headers are parsed here.  An image above the limit (set
    low here) is refused, as a mask is, before anything is decoded."""
    cv2 = pytest.importorskip("cv2")
    from PIL import Image

    img = np.full((30, 40, 3), 100, np.uint8)
    written = []
    for ext in (".png", ".jpg", ".bmp", ".ppm", ".pgm", ".pfm", ".hdr", ".pic", ".sr", ".tif", ".webp"):
        a = img.astype(np.float32) / 255 if ext in (".pfm", ".hdr", ".pic") else img[:, :, 0] if ext == ".pgm" else img
        if cv2.imwrite(str(tmp_path / f"x{ext}"), a):
            written.append(tmp_path / f"x{ext}")
    # an OpenEXR header (this OpenCV may have no EXR codec): magic, version, attributes, end
    exr = tmp_path / "x.exr"
    attr = b"dataWindow\0box2i\0" + struct.pack("<i4i", 16, 5, 7, 44, 36)
    exr.write_bytes(b"\x76\x2f\x31\x01" + struct.pack("<i", 2) + b"channels\0chlist\0" + struct.pack("<i", 1) + b"\0"
                    + attr + b"\0" + b"\0" * 64)
    written.append(exr)
    limit = Image.MAX_IMAGE_PIXELS
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for p in written:
            assert _image_files.header_size(p) == (40, 30), p
            assert _image_files.is_image_file(p)
        _blank_png(tmp_path / "big.png", 20000, 20000)  # above Pillow's bomb limits
        assert _image_files.header_size(tmp_path / "big.png") == (20000, 20000)
    assert not caught and Image.MAX_IMAGE_PIXELS == limit
    monkeypatch.setattr(_image_files, "MAX_IMAGE_PIXELS", 1000)
    for p in written:
        with pytest.raises(ValueError, match=r"40 x 30 px .* above the 0 Mpx this command reads"):
            _image_files.check_image_size(p)
    with pytest.raises(ValueError, match=r"40 x 30 px"):
        _image_files.read_image(written[0], cv2.IMREAD_COLOR)


def test_a_huge_mask_is_refused_before_its_image_is_decoded(tmp_path, capfd, monkeypatch):
    cv2 = pytest.importorskip("cv2")
    cv2.imwrite(str(tmp_path / "photo.png"), np.full((48, 64, 3), 100, np.uint8))
    _blank_png(tmp_path / "mask.png", 20000, 20000)
    monkeypatch.setattr(cv2, "imread", lambda *a, **k: pytest.fail("an image was decoded"))
    _cli_refused(capfd, ["calibrate", str(tmp_path / "photo.png"), "--masks", str(tmp_path / "mask.png")],
                 "mask.png: the image is 20000 x 20000 px (400 Mpx), above the 60 Mpx")


# ------------------------------------------------------------ 3. every OpenCV format is an image


@pytest.mark.parametrize("ext", [".ppm", ".pgm", ".pbm", ".pnm", ".pfm", ".hdr", ".pic", ".sr", ".ras", ".jp2",
                                 ".tiff", ".dib", ".jpe", ".webp"])
def test_every_opencv_format_is_an_image(tmp_path, capfd, ext):
    """A .ppm was read as outline text ("could not read an (N, 2) array ... could not
    convert string 'P6'"); every format OpenCV reads is an image, by its suffix."""
    cv2 = pytest.importorskip("cv2")
    p = tmp_path / f"photo{ext}"
    a = np.full((40, 50, 3), 100, np.uint8)
    if ext in (".pfm", ".hdr", ".pic"):
        a = a.astype(np.float32) / 255
    elif ext in (".pbm", ".pgm"):
        a = a[:, :, 0]
    if not cv2.imwrite(str(p), a):
        pytest.skip(f"this OpenCV writes no {ext}")
    assert ext in _image_files.IMAGE_SUFFIXES and _image_files.is_image_file(p)
    assert _image_files.read_image(p, cv2.IMREAD_COLOR).shape == (40, 50, 3)
    np.savetxt(tmp_path / "o.txt", E)
    _cli_refused(capfd, ["calibrate", str(p), str(tmp_path / "o.txt")], "give either images or outline files")


def test_an_image_under_another_suffix_is_an_image(tmp_path, capfd):
    """A PNG named ``.dat`` or with no suffix was read as outline text ("'utf-8' codec
    can't decode byte 0x89"): OpenCV's signature check (cv2.haveImageReader) makes it
    an image; under an outline file's suffix (.txt) it is named as an image."""
    cv2 = pytest.importorskip("cv2")
    cv2.imwrite(str(tmp_path / "a.png"), np.full((40, 50, 3), 100, np.uint8))
    data = (tmp_path / "a.png").read_bytes()
    np.savetxt(tmp_path / "o.txt", E)
    for name in ("photo.dat", "photo"):
        (tmp_path / name).write_bytes(data)
        assert _image_files.is_image_file(tmp_path / name)
        _cli_refused(capfd, ["calibrate", str(tmp_path / name), str(tmp_path / "o.txt")],
                     "give either images or outline files")
    (tmp_path / "photo.txt").write_bytes(data)
    _cli_refused(capfd, ["calibrate", str(tmp_path / "photo.txt"), str(tmp_path / "o.txt")],
                 "photo.txt: an image (by its content), not an outline file")
    # text under an unknown suffix is still an outline file; not-an-image under an image suffix is named
    np.savetxt(tmp_path / "o.xy", E)
    assert not _image_files.is_image_file(tmp_path / "o.xy")
    (tmp_path / "text.png").write_text("1 2\n3 4\n")
    _cli_refused(capfd, ["calibrate", str(tmp_path / "text.png")], "text.png: not an image OpenCV can read")
    (tmp_path / "cut.png").write_bytes(data[:60])  # a PNG cut short: OpenCV's own log stays silent
    _cli_refused(capfd, ["calibrate", str(tmp_path / "cut.png")], "cut.png: not an image OpenCV can read")


# ------------------------------------------------------------ 4. empty or unreadable outline files


@pytest.mark.parametrize("name, data, words", [
    ("empty.txt", b"", "empty.txt: the file is empty"),
    ("empty.csv", b"", "empty.csv: the file is empty"),
    ("empty.npy", b"", "empty.npy: the file is empty"),
    ("empty.npz", b"", "empty.npz: not an outline file written by sorjax.save_outlines (the file is empty)"),
    ("comments.txt", b"# x y\n\n", "comments.txt: holds no numbers (only blank lines or comments)"),
    ("ragged.txt", b"1 2 3\n4 5\n", "ragged.txt: could not read an (N, 2) array of pixel coordinates"),
    ("binary.txt", b"\xff\xfe\x00garbage", "binary.txt: could not read an (N, 2) array"),
    ("cut.npy", b"\x93NUMPY\x01\x00", "cut.npy: could not read an (N, 2) array"),
    ("one.txt", b"1 2 3\n4 5 6\n", "one.txt: expected shape (N, 2), got (2, 3)"),
    ("zip.npy", None, "zip.npy: an .npz archive, not one array"),
])
def test_an_empty_or_unreadable_outline_file_is_named_in_one_line(tmp_path, capfd, name, data, words):
    """An empty text file gave numpy's "loadtxt: input contained no data" warning, then
    "outline 0: expected shape (N, 2), got (0, 1)"."""
    if data is None:
        np.savez(tmp_path / "a.npz", points_0=E)
        (tmp_path / "a.npz").rename(tmp_path / name)
    else:
        (tmp_path / name).write_bytes(data)
    np.savetxt(tmp_path / "good.txt", E)
    _cli_refused(capfd, ["calibrate", str(tmp_path / name), str(tmp_path / "good.txt")], words)


def test_load_outlines_names_an_empty_or_missing_file(tmp_path):
    (tmp_path / "empty.npz").write_bytes(b"")
    _refused(lambda: sorjax.load_outlines(tmp_path / "empty.npz"),
             "not an outline file written by sorjax.save_outlines (the file is empty)")
    _refused(lambda: sorjax.load_outlines(tmp_path / "missing.npz"), "missing.npz: no such file")


# ------------------------------------------------------------ 5. one bare outline


def test_a_single_bare_outline_is_named_as_such():
    """One outline passed where a list is expected: said so, with what to pass (it gave
    "expected shape (N, 2), got (2,)" for arrays other than numpy's and short lists)."""
    jnp = pytest.importorskip("jax.numpy")
    for bare, shape in ((E, "array of shape (600, 2)"), (jnp.asarray(E), "array of shape (600, 2)"),
                        (E.tolist(), "list of shape (600, 2)"), (E[:5].tolist(), "list of shape (5, 2)"),
                        (E[:, None, :], "array of shape (600, 1, 2)")):
        _refused(lambda: sorjax.calibrate(bare), "got a single outline. Wrap it in a list: pass [outline]",
                 f"not a bare {shape}", "at least two views")
    _refused(lambda: sorjax.calibrate(E.T), "pass [outline.T] (it looks transposed)")
    _refused(lambda: sorjax.fit_homology(np.stack([E, E + 5])), "got (2, 600, 2) (2 outlines? pass one at a time)")


def test_a_3d_array_is_read_as_that_many_outlines():
    """(V, N, 2): V outlines of N points each (documented in ``calibrate``)."""
    from sorjax._outline import as_outlines

    outs = as_outlines(np.stack([E, E + 5, E - 5]), 256)
    assert len(outs) == 3 and all(o.points.shape == (256, 2) for o in outs)


# ------------------------------------------------------------ 6. image_size smaller than the outlines


def test_an_image_size_smaller_than_the_outlines_is_named_as_such():
    """The outlines reaching beyond image_size were calibrated and refused for the
    wrong cause ("the estimated principal point lies outside the 100x100 image ... add
    a view")."""
    outs = [E, E + [40.0, 20.0]]  # x 180 .. 460, y 160 .. 340
    msg = _refused(lambda: sorjax.calibrate(outs, image_size=(200, 150)),
                   "image_size (200, 150) is smaller than the outlines' extent",
                   "the outlines span x = 180.0 .. 460.0, y = 160.0 .. 340.0 px", "outline 1 reaches x = 460.0",
                   "or image_size=None")
    assert "width first" not in msg
    _refused(lambda: sorjax.calibrate(outs, image_size=(400, 640)), "image_size (400, 640) is smaller",
             "(width first: (640, 400) would hold them)")
    _refused(lambda: sorjax.calibrate([E - 300.0, E], image_size=(640, 480)),
             "the outlines reach beyond image_size (640, 480)", "left of or above the image")


def test_the_image_edge_tolerance():
    """An outline may reach up to IMAGE_EDGE_TOLERANCE_PX (1 px) beyond the image's
    edge (-0.5 and W - 0.5: an outline traced along a border pixel's edge reaches it)."""
    from sorjax._calibration_checks import IMAGE_EDGE_TOLERANCE_PX, _check_extent
    from sorjax._outline import as_outlines

    assert IMAGE_EDGE_TOLERANCE_PX == 1.0
    box = np.array([[-0.5, -0.5], [639.5, -0.5], [639.5, 479.5], [-0.5, 479.5]])
    sides = [np.linspace(box[i], box[(i + 1) % 4], 1000, endpoint=False) for i in range(4)]
    frame = np.concatenate(sides)  # the image's own edge
    for shift, ok in ((0.0, True), (0.9, True), (1.1, False)):
        outs = as_outlines([frame + [shift, 0.0], frame - [0.0, shift]], 256)
        if ok:
            _check_extent(outs, (640, 480))
        else:
            with pytest.raises(ValueError, match="image_size|beyond image_size"):
                _check_extent(outs, (640, 480))
