import subprocess
import sys

import numpy as np
import pytest

from sorjax import scenes
from sorjax.cli import main


def test_cli_calibrates_from_files(tmp_path, capsys):
    sc = scenes.two_spheres(f=700.0)
    files = []
    for i, o in enumerate(sc.outlines):
        f = tmp_path / f"view{i}.npy" if i else tmp_path / f"view{i}.txt"
        np.save(f, o) if f.suffix == ".npy" else np.savetxt(f, o)
        files.append(str(f))
    assert main(["calibrate", *files, "--method", "IIb"]) == 0
    out = capsys.readouterr().out
    fu = float(out.split("fu =")[1].split("px")[0])
    assert abs(fu - 700.0) < 0.07


def test_cli_bad_input_is_one_line_and_exit_2(tmp_path):
    """... and ``sorjax calibrate`` keeps its compiled programs in ``$SORJAX_CACHE``
    (made before any input is read: later runs skip about 30 s of compilation)."""
    import os

    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n3 nan\n")
    cache = tmp_path / "xla"
    r = subprocess.run([sys.executable, "-m", "sorjax", "calibrate", str(bad), str(tmp_path / "missing.npy")],
                       capture_output=True, text=True, timeout=300, env={**os.environ, "SORJAX_CACHE": str(cache)})
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "sorjax: error:" in r.stderr and ("NaN" in r.stderr or "no such file" in r.stderr)
    assert cache.is_dir()


def test_cli_outline_error_option(tmp_path, capsys):
    """--outline-error reaches calibrate: exact outlines at f = 1400 from near the axis
    show little perspective; declared exact they calibrate, with 1 px of possible
    systematic error the focal length is refused (exit 1, the reason printed); a
    negative value is a usage error (exit 2)."""
    from sorjax.scenes import pose_at_pixel

    K = scenes.intrinsics(1400.0)
    prof = scenes.vase()
    files = []
    for i, (el, az, px) in enumerate(((15, 0, (380, 270)), (-10, 70, (280, 250)), (30, 200, (330, 200)))):
        R, t = pose_at_pixel(prof, K, el, az, roll=0.3 * i, pixel=px)
        o = scenes.sor_scene(prof, K, [(R, t)]).outlines[0]
        files.append(str(tmp_path / f"v{i}.npy"))
        np.save(files[-1], o)
    assert main(["calibrate", *files, "--outline-error", "0"]) == 0
    capsys.readouterr()
    assert main(["calibrate", *files, "--outline-error", "1.0"]) == 1
    assert "too little perspective" in capsys.readouterr().err
    # --option NAME=VALUE reaches sorjax.Options (here the perspective gate's z)
    assert main(["calibrate", *files, "--outline-error", "0", "--option", "perspective_z=1e9"]) == 1
    assert "needs z >= 1e+09" in capsys.readouterr().err
    for bad in ("nonsense=1", "perspective_z", "perspective_z=abc"):
        with pytest.raises(SystemExit) as e:
            main(["calibrate", *files, "--option", bad])
        assert e.value.code == 2 and "--option" in capsys.readouterr().err
    r = subprocess.run([sys.executable, "-m", "sorjax", "calibrate", *files, "--outline-error", "-1"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "outline-error" in r.stderr


def _rendered(tmp_path, n_images=2):
    import cv2

    from sorjax import render

    K = scenes.intrinsics(800.0, aspect_ratio=1.02, principal_point=(330.0, 235.0))
    imgs, masks = [], []
    for s in range(n_images):
        r = render.random_table_scene(s, K, n_objects=2)
        imgs.append(str(tmp_path / f"img{s}.png"))
        masks.append(str(tmp_path / f"lab{s}.png"))
        cv2.imwrite(imgs[-1], r.image)
        # an 8-bit soft (anti-aliased) mask of all objects; binary masks lose about half
        # the outline accuracy to their staircase (see docs/results.md)
        cover = np.max([o.coverage for o in r.objects], axis=0)
        cv2.imwrite(masks[-1], np.round(255 * cover).astype(np.uint8))
    return K, imgs, masks


def test_cli_calibrates_from_images_and_masks_writes_yaml(tmp_path, capsys):
    import cv2

    K, imgs, masks = _rendered(tmp_path)
    out = tmp_path / "out" / "camera.yaml"
    assert main(["calibrate", *imgs, "--masks", *masks, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "img0.png#0" in text and "img1.png#1" in text  # the per-view table
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    Kr = fs.getNode("camera_matrix").mat()
    std = fs.getNode("intrinsics_std").mat().ravel()
    assert int(fs.getNode("image_width").real()) == 640 and int(fs.getNode("image_height").real()) == 480
    fs.release()
    assert np.all(std > 0) and np.all(np.isfinite(std))
    est = np.array([Kr[0, 0], Kr[1, 1], Kr[0, 2], Kr[1, 2]])
    true = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    # soft masks, 4 views: within 1 % of f, and within 3 reported standard deviations
    assert np.all(np.abs(est - true) < 0.01 * K[1, 1])
    assert np.all(np.abs(est - true) < 3 * std), (est - true, std)
    import json

    js = json.loads(out.with_suffix(".json").read_text())
    np.testing.assert_allclose(js["camera_matrix"], Kr)
    assert len(js["views"]) == 4
    # the evidence for perspective, printed and in the twin: above the gate's 0.3 px
    assert js["perspective_px"] > 0.3 and js["perspective_z"] > 3
    assert f"perspective shown by the outlines: {js['perspective_px']:.3g} px" in text
    for s in ("img0", "img1"):
        png = out.parent / f"camera_overlay_{s}.png"
        assert cv2.imread(str(png)).shape == (480, 640, 3)


def test_cli_image_bad_input(tmp_path, capsys):
    import cv2

    _, imgs, masks = _rendered(tmp_path, 1)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640, 3), 128, np.uint8))
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((240, 320), np.uint8))
    cases = [
        (["calibrate", str(tmp_path / "missing.png")], "no such file"),
        (["calibrate", str(blank), str(blank)], "too few views left: 0 outline(s) from 0 image(s) after 2 of 2"),
        (["calibrate", imgs[0], "--masks", str(small)], "mask is 320x240 px"),
        (["calibrate", imgs[0], "--masks", masks[0], masks[0]], "one mask per image"),
    ]
    for argv, msg in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (argv, err)


def test_cli_drops_images_and_boxes_that_give_no_outline(tmp_path, capsys):
    """One box that cuts its object, and an image with nothing in it, are dropped with a
    warning naming them; the run goes on with the rest (it used to end with exit 2).
    Too few views left: refused, saying so."""
    import json

    import cv2

    from sorjax import render

    K, imgs, _ = _rendered(tmp_path)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640, 3), 128, np.uint8))
    boxes = {}
    for s, f in enumerate(imgs):
        r = render.random_table_scene(s, K, n_objects=2)
        boxes[f] = [[max(0, b[0] - 8), max(0, b[1] - 8), min(639, b[2] + 8), min(479, b[3] + 8)] for b in r.boxes]
    x0, y0, x1, y1 = boxes[imgs[0]][0]
    boxes[imgs[0]][0] = [x0 + (x1 - x0) // 3, y0 + (y1 - y0) // 3, x1 - (x1 - x0) // 3, y1 - (y1 - y0) // 3]
    boxes[str(blank)] = [[200, 150, 400, 350]]
    (tmp_path / "boxes.json").write_text(json.dumps(boxes))
    code = main(["calibrate", imgs[0], str(blank), imgs[1], "--boxes", str(tmp_path / "boxes.json")])
    cap = capsys.readouterr()
    assert code in (0, 1), cap.err  # a calibration was attempted (exit 2: the run was ended)
    assert "warning: img0.png: box 0 (" in cap.err
    assert "blank.png: no outline; image dropped, the run goes on without it" in cap.err
    assert "3 outline(s) from 3 file(s) (1 image(s) gave none and were dropped)" in cap.out
    assert "measured from the outlines" in cap.err  # photographs: the outline error is measured
    # one view left from the good box: too few, refused with a reason
    (tmp_path / "one.json").write_text(json.dumps({imgs[0]: boxes[imgs[0]][:1], str(blank): boxes[str(blank)]}))
    assert main(["calibrate", imgs[0], str(blank), "--boxes", str(tmp_path / "one.json")]) == 2
    err = capsys.readouterr().err
    assert "too few views left: 0 outline(s) from 0 image(s) after 2 of 2 gave none (img0.png, blank.png" in err


def test_saved_outlines_keep_their_attributes_and_calibrate_as_before(tmp_path, capsys):
    """sorjax.save_outlines / load_outlines keep an image outline's attributes (np.save
    drops them); ``sorjax calibrate FILE.npz`` reads them: the outlines averaged with their
    mirror image calibrate with the outline error measured and their noise floors, the same
    K and standard deviations as from the arrays in memory, not as noise-free plain arrays."""
    import json
    import math

    import pytest

    import sorjax
    from sorjax._detect import DetectOptions, ImageOutline, outline_homology, symmetric_average

    sc = scenes.two_spheres(f=700.0)
    outs = []
    for i, o in enumerate(sc.outlines):
        raw = np.asarray(scenes.paper_noise(o, 0.1, 40 + i))
        h = outline_homology(raw)
        avg = symmetric_average(raw, h.W, np.ones(len(raw), bool), DetectOptions())
        outs.append(ImageOutline(avg, outline_error=float(h.rms), symmetry_rms=float(h.rms),
                                 noise_rms=float(h.rms), noise_ell=float(h.noise_ell)))
    plain = np.asarray(sc.outlines[0])
    path = sorjax.save_outlines(tmp_path / "outs", [*outs, plain])
    assert path.endswith(".npz")
    back = sorjax.load_outlines(path)
    assert len(back) == 4
    for a, b in zip(outs, back):
        np.testing.assert_array_equal(np.asarray(b), np.asarray(a))
        for k in ("outline_error", "noise_rms", "noise_ell"):
            assert getattr(b, k) == getattr(a, k)
    assert math.isnan(back[3].noise_rms) and math.isnan(back[3].outline_error)
    # the command line on the file: as the arrays in memory (measured outline error, floors)
    sorjax.save_outlines(tmp_path / "three.npz", outs)
    want = sorjax.calibrate(outs, outline_error="measured")
    assert want.success
    assert main(["calibrate", str(tmp_path / "three.npz"), "--out", str(tmp_path / "cam.yaml")]) == 0
    js = json.loads((tmp_path / "cam.json").read_text())
    np.testing.assert_allclose(js["camera_matrix"], np.asarray(want.K), rtol=1e-9)
    got_std = [js["intrinsics_std"][k] for k in ("fx", "fy", "cx", "cy")] if "fx" in js["intrinsics_std"] else \
        list(js["intrinsics_std"].values())
    np.testing.assert_allclose(np.asarray(got_std, float), np.asarray(want.std), rtol=1e-9)
    # the same points as plain arrays are taken as noise-free outlines: another std
    flat = sorjax.calibrate([np.asarray(o) for o in outs])
    assert not np.allclose(np.asarray(flat.std), np.asarray(want.std), rtol=0.1)
    # bad files: one line each
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not an outline file written by sorjax.save_outlines"):
        sorjax.load_outlines(tmp_path / "junk.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    assert main(["calibrate", str(tmp_path / "other.npz"), str(tmp_path / "three.npz")]) == 2
    assert "not an outline file" in capsys.readouterr().err
    with pytest.raises(ValueError, match="outline 0"):
        sorjax.save_outlines(tmp_path / "bad", [np.zeros((5, 3))])
    with pytest.raises(ValueError, match="pass \\[outline\\]"):
        sorjax.save_outlines(tmp_path / "bad", np.zeros((5, 2)))
    # empty, truncated, a renamed .npy, text: one line each, never a traceback
    good = (tmp_path / "three.npz").read_bytes()
    np.save(tmp_path / "arr.npy", np.zeros((5, 2)))
    for name, data in (("empty.npz", b""), ("cut.npz", good[: len(good) // 2]),
                       ("renamed.npz", (tmp_path / "arr.npy").read_bytes()), ("text.NPZ", b"1 2\n3 4\n")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match="not an outline file written by sorjax.save_outlines"):
            sorjax.load_outlines(tmp_path / name)
        assert main(["calibrate", str(tmp_path / name), str(tmp_path / "three.npz")]) == 2
        err = capsys.readouterr().err
        assert "not an outline file" in err and "Traceback" not in err
