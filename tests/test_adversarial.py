"""Adversarial inputs (issue 19, items 3-5): what a hostile but realistic user sees.

Each test asserts the exact user-visible outcome: exit code 2 and a one-line message
naming the problem, the input file unchanged, no file outside ``--out``, a ValueError
naming the option, outlines of crops equal to those of the whole image.  Nothing here
calibrates: the checks fire before any computing (``sorjax.calibrate`` is replaced by
a stub where the command line must get past it)."""

from __future__ import annotations

import json
import math
import os
import sys
import tracemalloc
import warnings
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sorjax
from sorjax import _extract as E
from sorjax import _masks as M
from sorjax import _unmixing as U
from sorjax import scenes
from sorjax._files import atomic_folder, atomic_path, check_output, safe_name, write_text
from sorjax.cli import main
from sorjax.experiment import ConfigError, parse_config
from sorjax.experiment import _runner as runner

FAST = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


# ------------------------------------------------------------------------ helpers


def _disc_mask(shape=(200, 300), centre=(150.0, 100.0), radius=50.0, soft=False) -> np.ndarray:
    """uint8 0/255 (or anti-aliased) mask of a disc; centre (x, y), px."""
    m = np.zeros(shape, np.uint8)
    c = tuple(int(round(v * 16)) for v in centre)
    cv2.circle(m, c, int(round(radius * 16)), 255, -1, cv2.LINE_AA if soft else cv2.LINE_8, 4)
    return m


def _photo(path, centre=(150.0, 100.0), radius=50.0, shape=(200, 300)):
    img = np.full(shape + (3,), 200, np.uint8)
    cv2.circle(img, tuple(int(v * 16) for v in centre), int(radius * 16), (30, 60, 170), -1, cv2.LINE_AA, 4)
    cv2.imwrite(str(path), img)
    return str(path)


def _one_line_error(err: str, *words) -> None:
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert lines and lines[-1].startswith("sorjax: error:"), err
    assert "Traceback" not in err, err
    assert len([ln for ln in lines if ln.startswith("sorjax: error:")]) == 1, err
    for w in words:
        assert w in lines[-1], (w, err)


def _tree(root) -> set[str]:
    return {os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs}


class _Never:
    """Stands in for a computation that must not start."""

    def __init__(self, what):
        self.what = what

    def __call__(self, *a, **k):
        raise AssertionError(f"{self.what} ran before the outputs were checked")


def _fake_calibration(outlines):
    """What sorjax.calibrate returns, for the command line's tables and files: a
    successful K and each view's symmetry axis through its outline's centre."""
    homs = []
    for o in outlines:
        c = np.asarray(o).mean(0)
        homs.append(SimpleNamespace(rms=0.01, l_s=np.array([1.0, 0.0, -c[0]]), v_x=np.array([0.0, 1.0, 1e-3])))
    n = len(outlines)
    K = np.array([[800.0, 0, 150], [0, 800.0, 100], [0, 0, 1]])
    return SimpleNamespace(
        used=tuple(range(n)), view_rms=np.full(n, 0.01), dropped=(), homologies=homs, success=True, message="ok",
        details="", std=np.ones(4), fu=800.0, fv=800.0, u0=150.0, v0=100.0, K=K, perspective_px=float("nan"),
        perspective_z=float("nan"), method="bundle", aspect_ratio=None,
    )


@pytest.fixture
def stub_calibrate(monkeypatch):
    """Replace sorjax.calibrate by a stub that records the outlines it gets."""
    seen = []

    def fake(outlines, **kw):
        seen.append([np.asarray(o) for o in outlines])
        return _fake_calibration(outlines)

    monkeypatch.setattr(sorjax, "calibrate", fake)
    return seen


# ------------------------------------------------------------- 3. safe outputs


def test_boxes_file_is_never_replaced_by_the_json_twin(tmp_path, capsys, monkeypatch):
    """``--boxes scene.json --out scene.yaml`` used to replace the boxes with the twin."""
    monkeypatch.chdir(tmp_path)
    _photo(tmp_path / "img.png")
    boxes = json.dumps({"img.png": [[90, 40, 210, 160]]})
    (tmp_path / "scene.json").write_text(boxes)
    monkeypatch.setattr(sorjax, "outlines_from_image", _Never("the extraction"))
    assert main(["calibrate", "img.png", "--boxes", "scene.json", "--out", "scene.yaml"]) == 2
    _one_line_error(capsys.readouterr().err, "--out", "scene.json", "would replace the input")
    assert (tmp_path / "scene.json").read_text() == boxes
    assert _tree(tmp_path) == {"img.png", "scene.json"}


def test_an_overlay_never_replaces_an_input_image(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _photo(tmp_path / "img.png")
    _photo(tmp_path / "cam_overlay_img.png", centre=(100, 100))  # what the overlay of img.png would be called
    before = (tmp_path / "cam_overlay_img.png").read_bytes()
    monkeypatch.setattr(sorjax, "outlines_from_image", _Never("the extraction"))
    assert main(["calibrate", "img.png", "cam_overlay_img.png", "--out", "cam.yaml"]) == 2
    _one_line_error(capsys.readouterr().err, "cam_overlay_img.png", "would replace the input")
    assert (tmp_path / "cam_overlay_img.png").read_bytes() == before


@pytest.mark.parametrize("where, words", [
    ("afile/cam.yaml", ("--out", "is a file")),
    ("afile/deeper/cam.yaml", ("--out", "is a file")),
    ("folder", ("--out", "is a folder")),
    ("folder/", ("--out", "is a folder")),
])
def test_out_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys, monkeypatch, where, words):
    """``--out`` under a file, or naming a folder: exit 2 before any outline is read
    (it used to be a traceback after the whole calibration)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "folder").mkdir()
    o = scenes.two_spheres(f=700.0).outlines
    np.save(tmp_path / "a.npy", o[0])
    np.save(tmp_path / "b.npy", o[1])
    monkeypatch.setattr(sorjax, "calibrate", _Never("the calibration"))
    monkeypatch.setattr("sorjax.cli._read_outlines", _Never("reading the outlines"))
    assert main(["calibrate", "a.npy", "b.npy", "--out", where]) == 2
    _one_line_error(capsys.readouterr().err, *words)
    assert _tree(tmp_path) == {"afile", "a.npy", "b.npy"}


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc (a folder no one can write in)")
def test_out_in_an_unwritable_place(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sorjax, "calibrate", _Never("the calibration"))
    assert main(["calibrate", "a.npy", "b.npy", "--out", "/proc/sorjax-test/cam.yaml"]) == 2
    _one_line_error(capsys.readouterr().err, "--out", "cannot write in /proc")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="a super-user writes in read-only folders")
def test_out_in_a_read_only_folder(tmp_path, capsys, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    monkeypatch.setattr(sorjax, "calibrate", _Never("the calibration"))
    try:
        assert main(["calibrate", "a.npy", "b.npy", "--out", str(ro / "cam.yaml")]) == 2
    finally:
        ro.chmod(0o700)
    _one_line_error(capsys.readouterr().err, "--out", "cannot write in")


def test_two_images_of_one_name_get_two_overlays_each_with_its_own_outlines(tmp_path, stub_calibrate, capsys):
    """a/img.png and b/img.png used to share one overlay, the second drawn with the
    first one's outlines."""
    files = []
    for sub, cx in (("a", 80.0), ("b", 220.0)):
        (tmp_path / sub).mkdir()
        files.append(_photo(tmp_path / sub / "img.png", centre=(cx, 100.0)))
        cv2.imwrite(str(tmp_path / sub / "mask.png"), _disc_mask(centre=(cx, 100.0)))
    out = tmp_path / "out" / "cam.yaml"
    assert main(["calibrate", *files, "--masks", str(tmp_path / "a" / "mask.png"), str(tmp_path / "b" / "mask.png"),
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("/img.png#0") == 2  # the table names each view by its path where file names repeat
    pngs = sorted(p for p in os.listdir(out.parent) if p.endswith(".png"))
    assert len(pngs) == 2, pngs
    for png, cx in zip(pngs, (80, 220)):
        img = cv2.imread(str(out.parent / png))
        green = (img[:, :, 1] > 150) & (img[:, :, 0] < 100) & (img[:, :, 2] < 100)
        xs = np.nonzero(green)[1]
        assert len(xs) > 100 and abs(np.median(xs) - cx) < 15, (png, np.median(xs) if len(xs) else None)
    names = {p for p in os.listdir(out.parent)}
    assert {"cam.yaml", "cam.json"} <= names and not any(".tmp" in n for n in names)
    twin = json.loads(out.with_suffix(".json").read_text())
    assert len({v["source"] for v in twin["views"]}) == 2


def test_the_overlay_of_a_large_photograph_is_drawn_reduced(tmp_path, stub_calibrate, monkeypatch):
    """Above OVERLAY_MAX_SIDE px the overlay is drawn on the photograph read grey at 1/2,
    1/4 or 1/8 of its size (memory), the outlines scaled to it."""
    monkeypatch.setattr("sorjax.cli.OVERLAY_MAX_SIDE", 150)  # the 300 px wide photo: drawn at 1/2
    img = _photo(tmp_path / "img.png", centre=(220.0, 100.0))
    cv2.imwrite(str(tmp_path / "mask.png"), _disc_mask(centre=(220.0, 100.0)))
    assert main(["calibrate", img, "--masks", str(tmp_path / "mask.png"), "--out", str(tmp_path / "cam.yaml")]) == 0
    over = cv2.imread(str(tmp_path / "cam_overlay_img.png"))
    assert over.shape == (100, 150, 3)
    green = (over[:, :, 1] > 150) & (over[:, :, 0] < 100) & (over[:, :, 2] < 100)
    assert abs(np.median(np.nonzero(green)[1]) - (220.5 / 2 - 0.5)) < 8


def test_write_errors_after_the_check_are_one_line(tmp_path, stub_calibrate, capsys, monkeypatch):
    """A disk that fills up (or a folder removed) between the check and the write."""
    o = scenes.two_spheres(f=700.0).outlines
    np.save(tmp_path / "a.npy", o[0])
    np.save(tmp_path / "b.npy", o[1])

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("sorjax._camera_io.write_camera", full_disk)
    assert main(["calibrate", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--out", str(tmp_path / "c.yaml")]) == 2
    _one_line_error(capsys.readouterr().err, "No space left on device")


def test_atomic_writes_leave_the_old_file_or_the_new_one(tmp_path):
    target = tmp_path / "f.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["f.txt"]
    write_text(target, "new")
    assert target.read_text() == "new" and os.listdir(tmp_path) == ["f.txt"]
    assert oct(target.stat().st_mode & 0o777) != oct(0o600)  # not mkstemp's private mode
    with pytest.raises(RuntimeError):
        with atomic_folder(tmp_path / "run") as d:
            (d / "results.json").write_text("{}")
            raise RuntimeError("interrupted")
    assert os.listdir(tmp_path) == ["f.txt"]
    with atomic_folder(tmp_path / "run") as d:
        (d / "results.json").write_text("{}")
    assert sorted(os.listdir(tmp_path)) == ["f.txt", "run"] and os.listdir(tmp_path / "run") == ["results.json"]


@given(st.text(min_size=0, max_size=40))
@FAST
def test_safe_names_stay_one_plain_folder(tmp_path, name):
    s = safe_name(name)
    assert s and "/" not in s and "\\" not in s and not s.startswith(".") and s not in (".", "..")
    assert (tmp_path / s).resolve().parent == tmp_path.resolve()


@pytest.mark.parametrize("name", ["../../x", "a/b", "/abs", ".hidden", "..", ""])
def test_config_names_that_are_paths_are_refused(name):
    with pytest.raises(ConfigError, match="name must be a plain name"):
        parse_config({"name": name})


@given(st.sampled_from(["../../x", "..", "a/../../b", "/etc/x", "~/x", "x\\..\\..\\y", "..\x00", "\u2215..\u2215x"]))
@FAST
def test_run_folder_stays_inside_out_whatever_the_name(tmp_path, name):
    """A config built in Python skips the schema: the run folder is still inside out."""
    cfg = parse_config({"name": "ok"}).replace(name=name)
    root = runner.run_folder(cfg, tmp_path / "runs")
    assert root.resolve().parent == (tmp_path / "runs").resolve()


def _tiny_config(tmp_path, name="tiny") -> str:
    path = tmp_path / "tiny.toml"
    path.write_text(f'name = "{name}"\ntrials = 2\nmethods = ["IIb"]\n[scene]\nn_views = 3\n[bound]\nenabled = false\n')
    return str(path)


def test_experiment_name_escaping_out_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(runner, "run_trials", _Never("the trials"))
    out = tmp_path / "deep" / "runs"
    assert main(["experiment", _tiny_config(tmp_path, "../../x"), "--out", str(out), "--quiet"]) == 2
    _one_line_error(capsys.readouterr().err, "name must be a plain name", "../../x")
    assert _tree(tmp_path) == {"tiny.toml"}


def test_experiment_out_under_a_file_is_refused_before_any_trial(tmp_path, capsys, monkeypatch):
    (tmp_path / "afile").write_text("x")
    monkeypatch.setattr(runner, "run_trials", _Never("the trials"))
    assert main(["experiment", _tiny_config(tmp_path), "--out", str(tmp_path / "afile" / "runs"), "--quiet"]) == 2
    _one_line_error(capsys.readouterr().err, "--out", "is a file")


def test_experiment_where_every_trial_fails_exits_1(tmp_path, capsys, monkeypatch):
    """It used to exit 0 with an all-NaN table."""

    def failing(cfg, workers=None, progress=True):
        return [dict(row=0, trial=t, seed=t, methods={}, error="scene: the object leaves the image")
                for t in range(cfg.trials)]

    monkeypatch.setattr(runner, "run_trials", failing)
    out = tmp_path / "runs"
    assert main(["experiment", _tiny_config(tmp_path), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    _one_line_error(err, "every one of the 2 trials failed", "the object leaves the image")
    runs = os.listdir(out / "tiny")
    assert len(runs) == 1 and not runs[0].startswith(".")  # the run directory is complete, for inspection
    assert "table.md" in os.listdir(out / "tiny" / runs[0])


def test_check_output_names_the_flag_and_the_input(tmp_path):
    f = tmp_path / "data.json"
    f.write_text("{}")
    with pytest.raises(ValueError, match=r"^--out: writing data.json would replace the input"):
        check_output(tmp_path / "sub" / ".." / "data.json", inputs=[str(f)], what="--out")
    with pytest.raises(ValueError, match="outside"):
        check_output(tmp_path / "x.yaml", inside=tmp_path / "sub")


# ------------------------------------------------------------ 4. bounded memory


@given(
    cx=st.floats(0, 300), cy=st.floats(0, 200), r=st.floats(4, 60), soft=st.booleans(),
    smooth=st.sampled_from([0.0, 0.5, 1.0, 2.0, 4.0]), second=st.booleans(), border=st.sampled_from(["refuse", "cut"]),
)
@FAST
def test_outlines_from_crops_equal_those_of_the_whole_mask(cx, cy, r, soft, smooth, second, border):
    """Objects anywhere (cut by the frame too), one or two (two windows, or one when
    close), soft or binary, any smoothing: the windows give the whole mask's outlines."""
    m = _disc_mask(centre=(cx, cy), radius=r, soft=soft)
    if second:
        m = np.maximum(m, _disc_mask(centre=(300 - cx, 200 - cy), radius=0.6 * r, soft=soft))
    field = M._as_field(m, None)

    def outlines(crop):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                return M._outlines_from_field(field, min_area=10.0, smooth=smooth, border=border, crop=crop)
            except ValueError as e:
                return str(e)

    whole, crops = outlines(False), outlines(True)
    if isinstance(whole, str):
        assert crops == whole
        return
    assert len(crops) == len(whole)
    for a, b in zip(crops, whole):
        assert a.shape == b.shape and np.max(np.abs(a - b)) <= 1e-9


def test_image_windows_and_tiles_equal_the_whole_image():
    """The unmixing and the edge measure tile by tile, and GrabCut's automatic start on
    a window, give the numbers of the whole image."""
    from sorjax import render

    r = render.random_table_scene(3, scenes.intrinsics(800.0), n_objects=2)
    src = E._as_bgr(r.image)
    H, W = src.shape
    fg = np.zeros((H, W), bool)
    for o in r.objects:
        fg |= o.coverage >= 0.5
    img = src.f64(0, H, 0, W)
    old_tile = U._TILE
    try:
        U._TILE = 96  # many tiles on a small image
        tiled = E._soft_alpha_tiled(lambda *w: src.f64(*w), fg, inner=1.5)
        sharp = E._edge_sharpness(lambda *w: src.f64(*w), fg)
    finally:
        U._TILE = old_tile
    np.testing.assert_array_equal(tiled, E._soft_alpha(img, fg, inner=1.5))
    assert sharp == E._edge_sharpness(img, fg)
    # the automatic start: the old whole-image construction against the window's
    small = cv2.resize(fg.astype(np.uint8), (W // 3, H // 3), interpolation=cv2.INTER_AREA).astype(bool)
    rr = 3
    m = cv2.resize(small.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST).astype(bool)
    init = np.full((H, W), cv2.GC_BGD, np.uint8)
    init[E._dilate(m, 2 * rr)] = cv2.GC_PR_BGD
    init[m] = cv2.GC_PR_FGD
    init[E._erode(m, 2 * rr)] = cv2.GC_FGD
    for win in ((0, 0, W, H), (100, 80, 400, 300), (300, 200, W, H)):
        np.testing.assert_array_equal(E._auto_init(small, (H, W), win, rr), init[win[1]:win[3], win[0]:win[2]])


def test_a_huge_mask_with_one_small_object_costs_little_beyond_itself():
    """8000 x 8000 uint8 (64 MB): the old code made a float64 copy and a padded one
    (> 1 GB); the windows need a few MB (experiments/memory.py: 20000 x 20000)."""
    m = np.zeros((8000, 8000), np.uint8)
    cv2.circle(m, (5000, 3000), 80, 255, -1)
    tracemalloc.start()
    try:
        out = sorjax.outlines_from_mask(m)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(out) == 1 and abs(np.hypot(*(out[0] - [5000, 3000]).T).mean() - 80.5) < 1.0
    assert peak < 40e6, peak


def test_object_regions_above_the_pixel_limit_are_refused(monkeypatch):
    monkeypatch.setattr("sorjax._masks.MAX_WINDOW_PIXELS", 10_000)  # the mask path's limit
    with pytest.raises(ValueError, match=r"at most 0 Mpx.*Downsample"):
        sorjax.outlines_from_mask(_disc_mask())


# -------------------------------------------------------- 5. options validated

O = scenes.two_spheres(f=700.0).outlines[0]


@pytest.mark.parametrize("kw, words", [
    (dict(n_samples=0), "n_samples must be an integer >= 10"),
    (dict(n_samples=2.5), "n_samples must be an integer"),
    (dict(n_points=3), "n_points must be an integer >= 64"),
    (dict(n_points=True), "n_points must be an integer"),
    (dict(n_samples=500, n_points=256), r"n_samples \(500\) must not exceed n_points"),
    (dict(max_steps=0), "max_steps must be an integer >= 1"),
    (dict(smooth_px=-1.0), "smooth_px must be a finite number >= 0"),
    (dict(smooth_px=float("nan")), "smooth_px must be a finite number"),
    (dict(robust="yes"), "robust must be True or False"),
    (dict(init=(np.ones(2), np.ones(2))), r"init must be \(v_x, l_s\).*shapes \(2,\) and \(2,\)"),
    (dict(init=np.eye(3)), r"init must be \(v_x, l_s\)"),
    (dict(init=(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))), "v_x lies on l_s"),
    (dict(init=(np.array([0, 1.0, 0]), np.array([0, 0, 1.0]))), "line at infinity"),
    (dict(init=(np.array([0, 1.0, np.nan]), np.array([1.0, 0, -5]))), "NaN"),
])
def test_fit_homology_options(kw, words):
    """n_samples = 0 was a ZeroDivisionError, a wrong-shape init a matmul error,
    n_points = 3 a 'converged' fit of garbage."""
    with pytest.raises(ValueError, match=words):
        sorjax.fit_homology(O, **kw)


@pytest.mark.parametrize("n", [0, 3, 63, 2.5, True, 1 << 20])
def test_make_outline_n_points(n):
    with pytest.raises(ValueError, match="n_points must be an integer"):
        sorjax.make_outline(O, n)


@given(st.floats(1e8, 1e300), st.booleans())
@FAST
def test_coordinates_far_beyond_any_image_are_refused(scale, offset):
    """Coordinates near 1e200 gave NaN outlines and a numpy LinAlgError."""
    bad = O + scale if offset else O * scale
    with pytest.raises(ValueError, match=r"outline: has coordinates up to .* px"):
        sorjax.make_outline(bad)
    with pytest.raises(ValueError, match=r"outline 1: has coordinates up to"):
        sorjax.calibrate([O, bad])


@pytest.mark.parametrize("kw, words", [
    (dict(aspect_ratio=True), "aspect_ratio must be a positive finite number"),
    (dict(aspect_ratio=np.bool_(True)), "aspect_ratio must be a positive finite number"),
    (dict(image_size=(True, True)), "image_size must be"),
    (dict(image_size=(640.5, 480)), "image_size must be"),
    (dict(n_points=10), "n_points must be an integer >= 64"),
])
def test_calibrate_options(kw, words):
    with pytest.raises(ValueError, match=words):
        sorjax.calibrate([O, O], **kw)


@pytest.mark.parametrize("kw, words", [
    (dict(smooth=True), "smooth must be a number"),
    (dict(min_area=True), "min_area must be a number"),
    (dict(min_area=float("inf")), "min_area must be a finite number"),
    (dict(smooth=25.0), "smooth must be a finite number >= 0 and <= 20"),
    (dict(label=[255, 0]), "label must be one number"),
    (dict(label="255"), "label must be one number"),
    (dict(label=True), "label must be one number"),
    (dict(label=float("nan")), "label must be a finite number"),
])
def test_outlines_from_mask_options(kw, words):
    with pytest.raises(ValueError, match=words):
        sorjax.outlines_from_mask(_disc_mask(), **kw)


@pytest.mark.parametrize("kw, words", [
    (dict(refine="no"), "refine must be True or False"),
    (dict(iterations=True), "iterations must be an integer"),
    (dict(iterations=0), "iterations must be an integer >= 1 and <= 50"),
    (dict(smooth=-1.0), "smooth must be a finite number >= 0"),
])
def test_outlines_from_image_options(kw, words):
    img = np.full((100, 100, 3), 200, np.uint8)
    with pytest.raises(ValueError, match=words):
        sorjax.outlines_from_image(img, boxes=[(20, 20, 80, 80)], **kw)


def test_sixteen_bit_masks_through_the_api():
    m = (_disc_mask() > 0).astype(np.uint16) * 65535
    (o,) = sorjax.outlines_from_mask(m)
    (ref,) = sorjax.outlines_from_mask(_disc_mask())
    np.testing.assert_allclose(o, ref, atol=1e-9)


def _rgba(mask, opaque):
    if opaque:  # the mask in the colour, alpha all 255
        return np.dstack([mask] * 3 + [np.full(mask.shape, 255, np.uint8)])
    return np.dstack([np.full(mask.shape, 90, np.uint8)] * 3 + [mask])  # a cut-out: the alpha is the mask


def _quantised(levels):
    aa = _disc_mask(soft=True)
    step = 256 // levels
    return (np.minimum(aa // step, levels - 1) * (255 // (levels - 1))).astype(np.uint8)


@pytest.mark.parametrize("kind, make", [
    ("16-bit 0/65535", lambda: (_disc_mask() > 0).astype(np.uint16) * 65535),
    ("16-bit soft", lambda: (_disc_mask(soft=True).astype(np.uint16) * 257)),
    ("0/128/255", lambda: _quantised(3)),
    ("4 levels", lambda: _quantised(4)),
    ("anti-aliased 0..255", lambda: _disc_mask(soft=True)),
    ("opaque RGBA", lambda: _rgba(_disc_mask(), True)),
    ("RGBA cut-out", lambda: _rgba(_disc_mask(soft=True), False)),
    ("0/1", lambda: (_disc_mask() > 0).astype(np.uint8)),
    ("two levels 3/7", lambda: np.where(_disc_mask() > 0, 7, 3).astype(np.uint8)),
])
def test_mask_files_are_read_by_what_they_hold(tmp_path, stub_calibrate, capsys, kind, make):
    """16-bit and quantised soft masks were read as label images (one object became
    several views), an opaque RGBA mask as one object touching the border."""
    img = _photo(tmp_path / "img.png")
    mask = str(tmp_path / "mask.png")
    assert cv2.imwrite(mask, make())
    assert main(["calibrate", img, img, "--masks", mask, mask]) == 0, capsys.readouterr().err
    (outs,) = stub_calibrate
    assert len(outs) == 2  # one object per mask: one view each
    radius = np.hypot(*(outs[0] - [150.0, 100.0]).T)
    assert abs(radius.mean() - 50.0) < 0.8 and radius.std() < 0.5, (kind, radius.mean(), radius.std())


def test_label_images_still_give_one_view_per_label(tmp_path, stub_calibrate):
    lab = np.zeros((200, 300), np.uint16)
    lab[_disc_mask(centre=(80, 100), radius=40) > 0] = 1
    lab[_disc_mask(centre=(220, 100), radius=40) > 0] = 2
    lab[_disc_mask(centre=(150, 40), radius=20) > 0] = 3
    img = _photo(tmp_path / "img.png")
    cv2.imwrite(str(tmp_path / "lab.png"), lab)
    assert main(["calibrate", img, "--masks", str(tmp_path / "lab.png")]) == 0
    assert len(stub_calibrate[0]) == 3


API_ONLY = ("border=", "label=", "min_area", "outlines_from_mask", "boxes=")


@pytest.mark.parametrize("case", ["border", "tiny", "constant", "blank photo"])
def test_command_line_hints_name_flags_not_api_options(tmp_path, capsys, monkeypatch, case):
    monkeypatch.setattr(sorjax, "calibrate", _Never("the calibration"))
    img = _photo(tmp_path / "img.png")
    mask = tmp_path / "mask.png"
    argv = ["calibrate", img, img, "--masks", str(mask), str(mask)]
    if case == "border":
        cv2.imwrite(str(mask), _disc_mask(centre=(10, 100)))
    elif case == "tiny":
        cv2.imwrite(str(mask), _disc_mask(radius=4))
    elif case == "constant":
        cv2.imwrite(str(mask), np.full((200, 300), 255, np.uint8))
    else:
        cv2.imwrite(img, np.full((200, 300, 3), 128, np.uint8))
        argv = ["calibrate", img]
    assert main(argv) == 2
    err = capsys.readouterr().err
    _one_line_error(err)
    assert not any(w in err for w in API_ONLY), err
    if case == "blank photo":
        assert "--boxes" in err and "--masks" in err
    with pytest.raises(ValueError) as info, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if case == "border":
            sorjax.outlines_from_mask(_disc_mask(centre=(10, 100)))
        else:
            raise ValueError("border='cut'")
    assert "border='cut'" in str(info.value)  # the API keeps naming its own options


def test_boxes_naming_no_image_are_an_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sorjax, "outlines_from_image", _Never("the extraction"))
    img = _photo(tmp_path / "img.png")
    (tmp_path / "boxes.json").write_text(json.dumps({"img.png": [[90, 40, 210, 160]], "IMG_0001.png": [[1, 1, 9, 9]]}))
    assert main(["calibrate", img, img, "--boxes", str(tmp_path / "boxes.json")]) == 2
    _one_line_error(capsys.readouterr().err, "boxes.json", "'IMG_0001.png'", "name no image")


def test_boxes_keyed_by_a_file_name_two_images_share_are_an_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sorjax, "outlines_from_image", _Never("the extraction"))
    for sub in "ab":
        (tmp_path / sub).mkdir()
        _photo(tmp_path / sub / "img.png")
    (tmp_path / "boxes.json").write_text(json.dumps({"img.png": [[90, 40, 210, 160]]}))
    assert main(["calibrate", str(tmp_path / "a" / "img.png"), str(tmp_path / "b" / "img.png"),
                 "--boxes", str(tmp_path / "boxes.json")]) == 2
    _one_line_error(capsys.readouterr().err, "names 2 different images", "paths as given")


@pytest.mark.parametrize("argv, flag", [
    (["experiment", "table1-quick", "--workers", "-3"], "--workers"),
    (["experiment", "table1-quick", "--trials", "0"], "--trials"),
    (["experiment", "table1-quick", "--seed", "-1"], "--seed"),
    (["calibrate", "a.npy", "b.npy", "--aspect-ratio", "-1"], "--aspect-ratio"),
    (["calibrate", "a.npy", "b.npy", "--aspect-ratio", "nan"], "--aspect-ratio"),
])
def test_command_line_numbers(capsys, argv, flag):
    """``--workers -3`` used to run on one worker, silently."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {flag}: must be" in err and "Traceback" not in err


def test_workers_in_the_api():
    with pytest.raises(ValueError, match="workers must be an integer >= 0"):
        runner.use_cpu_devices(-3)
    with pytest.raises(ValueError, match="trials must be an integer >= 1"):
        runner.run_experiment(parse_config({"name": "x"}), out=None, trials=0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))
