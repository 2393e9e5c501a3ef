"""Outlines from pixels (sorjax.outlines_from_mask / outlines_from_image) and the renderer."""

import math
import warnings

import cv2
import numpy as np
import pytest

import sorjax
from sorjax import render as R
from sorjax import scenes as S

# ------------------------------------------------------------------ helpers


def rms_to(outline, exact):
    return float(np.sqrt(np.mean(S.distance_to_polyline(outline, exact) ** 2)))


def match(found, exact):
    """The found outline nearest (by centroid) to each exact outline."""
    return [found[int(np.argmin([np.linalg.norm(f.mean(0) - e.mean(0)) for f in found]))] for e in exact]


def shoelace(p):
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def circle(cx, cy, r, n=4000):
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def disc_coverage(shape, cx, cy, r):
    """Exact-ish soft mask of a disc: a 4000-gon rasterised with exact row coverage."""
    return R.polygon_coverage(circle(cx, cy, r), shape, supersample=64)


def fit_circle(p):
    A = np.column_stack([2 * p, np.ones(len(p))])
    c = np.linalg.lstsq(A, np.sum(p * p, axis=1), rcond=None)[0]
    return c[0], c[1], math.sqrt(c[2] + c[0] ** 2 + c[1] ** 2)


def check_outline(o):
    assert o.dtype == np.float64 and o.ndim == 2 and o.shape[1] == 2 and len(o) > 8
    assert np.linalg.norm(o[0] - o[-1]) > 1e-9  # no repeated end point
    assert shoelace(o) > 0  # clockwise as displayed, like sorjax.scenes
    gaps = np.hypot(*(np.roll(o, -1, axis=0) - o).T)
    assert gaps.max() < 1.5 and gaps.min() > 0


@pytest.fixture(scope="module")
def scene():
    """One photo-like render: 3 objects, f = 900, aspect 1.03, off-centre principal point."""
    K = S.intrinsics(900.0, aspect_ratio=1.03, principal_point=(338.0, 228.0))
    return R.random_table_scene(7, K=K, n_objects=3)


# ------------------------------------------------------------------ pixel convention


def test_pixel_convention_square():
    # pixels (rows 10..39, columns 5..44) set: their squares span x in [4.5, 44.5],
    # y in [9.5, 39.5] (pixel (i, j) is centred on x = j, y = i)
    m = np.zeros((60, 60), np.uint8)
    m[10:40, 5:45] = 255
    (o,) = sorjax.outlines_from_mask(m, min_area=1)
    check_outline(o)
    mid_y = np.abs(o[:, 1] - 24.5) < 1.0
    mid_x = np.abs(o[:, 0] - 24.5) < 1.0
    # a wrong convention is 0.5 px off; the binary staircase smoothing carries a trace
    # of the square's corners 15 px along its sides (0.014 px)
    assert np.allclose(np.sort(o[mid_y, 0])[[0, -1]], [4.5, 44.5], atol=0.03)
    assert np.allclose(np.sort(o[mid_x, 1])[[0, -1]], [9.5, 39.5], atol=0.03)
    assert o[0, 1] == o[:, 1].min()  # starts at the top-most point


@pytest.mark.parametrize("kind", ["soft", "binary"])
def test_pixel_convention_disc(kind):
    cx, cy, r = 40.3, 27.8, 15.6
    if kind == "soft":
        m = disc_coverage((60, 84), cx, cy, r)
    else:  # a pixel is in when its centre (x = column, y = row) is inside the disc
        yy, xx = np.mgrid[0:60, 0:84]
        m = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    (o,) = sorjax.outlines_from_mask(m)
    check_outline(o)
    ex, ey, er = fit_circle(o)
    # a binary disc's own aliasing moves its fitted centre by up to ~0.1 px; a wrong
    # pixel convention would move it by 0.5 px
    tol = 0.05 if kind == "soft" else 0.15
    assert abs(ex - cx) < tol and abs(ey - cy) < tol
    assert abs(er - r) < 0.05
    d = np.hypot(o[:, 0] - cx, o[:, 1] - cy) - r
    assert np.sqrt(np.mean(d**2)) < (0.04 if kind == "soft" else 0.25)


def test_findcontours_is_biased_inwards_and_we_are_not():
    cx, cy, r = 50.4, 44.1, 30.2
    m = disc_coverage((90, 100), cx, cy, r) >= 0.5
    cnts, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    dcv = np.hypot(*(cnts[0][:, 0, :] - [cx, cy]).T) - r
    (o,) = sorjax.outlines_from_mask(m)
    dus = np.hypot(o[:, 0] - cx, o[:, 1] - cy) - r
    assert dcv.mean() < -0.3  # boundary pixel centres: about half a pixel inside
    assert abs(dus.mean()) < 0.05


# ------------------------------------------------------------------ accuracy on renders


def test_subpixel_accuracy_on_rendered_masks(scene):
    exact = scene.outlines
    soft = match(sorjax.outlines_from_mask(scene.mask), exact)
    binary = match(sorjax.outlines_from_mask(scene.mask >= 0.5), exact)
    for o, e in zip(soft, exact):
        check_outline(o)
        assert rms_to(o, e) <= 0.06  # issue target: 0.1 px
        assert rms_to(e[::50], o) <= 0.1  # and the whole exact outline is covered
    for o, e in zip(binary, exact):
        check_outline(o)
        assert rms_to(o, e) <= 0.13  # 0.096 to 0.108 here; 0.105 over 60 renders


def test_binary_staircase_smoothing_stays_in_its_band():
    """The smoothed crossings of a binary mask stay on their grid lines, between the
    inside and outside pixel centres there, and halve the raw staircase's error."""
    from sorjax._extract import _trace_level, _tube_smooth

    cx, cy, a, b, th = 61.3, 47.8, 38.2, 21.7, 0.37
    yy, xx = np.mgrid[0:100, 0:130]
    u = (xx - cx) * math.cos(th) + (yy - cy) * math.sin(th)
    v = -(xx - cx) * math.sin(th) + (yy - cy) * math.cos(th)
    m = (u / a) ** 2 + (v / b) ** 2 <= 1.0
    (p,) = [q - 1.0 for q in _trace_level(np.pad(m.astype(float), 1), 0.5, cubic=False)]
    q = _tube_smooth(p)
    on_row = np.abs(p[:, 1] - np.round(p[:, 1])) < 1e-9
    assert np.all(np.where(on_row, q[:, 1] == p[:, 1], q[:, 0] == p[:, 0]))
    assert np.all(np.abs(q - p).max(axis=1) <= 0.5 + 1e-12)
    t = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    ex = np.column_stack([cx + a * np.cos(t) * math.cos(th) - b * np.sin(t) * math.sin(th),
                          cy + a * np.cos(t) * math.sin(th) + b * np.sin(t) * math.cos(th)])
    raw, smoothed = rms_to(p, ex), rms_to(q, ex)
    assert smoothed < 0.5 * raw and smoothed < 0.1, (raw, smoothed)


def test_label_image(scene):
    assert set(np.unique(scene.labels)) == {0, 1, 2, 3}
    for k, obj in enumerate(scene.objects):
        (o,) = sorjax.outlines_from_mask(scene.labels, label=k + 1)
        assert rms_to(o, obj.truth.outline) <= 0.2
    with pytest.raises(ValueError, match="label"):
        sorjax.outlines_from_mask(scene.labels)  # labels 0..3 without label=
    with pytest.raises(ValueError, match="does not occur"):
        sorjax.outlines_from_mask(scene.labels, label=9)


# ------------------------------------------------------------------ several objects, holes, border


def test_several_objects_largest_first_specks_and_holes_ignored():
    m = disc_coverage((120, 200), 40.0, 60.0, 20.0)
    m += disc_coverage((120, 200), 110.0, 50.0, 30.0)
    m -= disc_coverage((120, 200), 110.0, 50.0, 10.0)  # a hole
    m += disc_coverage((120, 200), 170.0, 80.0, 12.0)
    m += disc_coverage((120, 200), 170.0, 20.0, 3.0)  # speck, area ~28 px^2
    outs = sorjax.outlines_from_mask(np.clip(m, 0, 1), min_area=50)
    assert len(outs) == 3
    radii = [fit_circle(o)[2] for o in outs]
    assert np.allclose(radii, [30.0, 20.0, 12.0], atol=0.02)  # outer boundaries, largest first
    for o in outs:
        check_outline(o)
    assert len(sorjax.outlines_from_mask(np.clip(m, 0, 1), min_area=10)) == 4


def test_border_touching_object_refused_with_reason():
    m = disc_coverage((80, 120), 8.0, 40.0, 15.0)  # cut by the left border
    m += disc_coverage((80, 120), 80.0, 40.0, 20.0)
    with pytest.warns(UserWarning, match=r"object 1 .*touches the image border \(left\)"):
        outs = sorjax.outlines_from_mask(m)
    assert len(outs) == 1 and abs(fit_circle(outs[0])[0] - 80.0) < 0.05
    with pytest.raises(ValueError, match="border"):
        sorjax.outlines_from_mask(m, border="raise")
    cut = sorjax.outlines_from_mask(m, border="cut")
    assert len(cut) == 2
    assert abs(cut[1][:, 0].min() - (-0.5)) < 1e-9  # follows the image frame
    assert np.sum(np.abs(cut[1][:, 0] + 0.5) < 0.02) > 40
    only = disc_coverage((80, 120), 8.0, 40.0, 15.0)
    with pytest.warns(UserWarning, match="border"), pytest.raises(ValueError, match="touches the image border"):
        sorjax.outlines_from_mask(only)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    "mask, kw, msg",
    [
        (np.zeros(10), {}, "2-D"),
        (np.zeros((20, 20, 3), np.uint8), {}, "colour image"),
        (np.zeros((20, 20)), {}, "no object"),
        (np.zeros((20, 20), bool), {}, "no object"),
        (np.full((20, 20), 255.0), {}, r"\[0, 1\]"),
        (np.array([[0.0, np.nan, 0.0]] * 3), {}, "NaN"),
        (np.zeros((2, 2)), {}, "at least 3x3"),
        ("mask.png", {}, "imread"),
        (np.ones((20, 20)), {"min_area": -1}, "min_area"),
        (np.ones((20, 20)), {"smooth": -1}, "smooth"),
        (np.ones((20, 20)), {"border": "clip"}, "border"),
    ],
)
def test_bad_masks(mask, kw, msg):
    with pytest.raises(ValueError, match=msg):
        sorjax.outlines_from_mask(mask, **kw)


def test_too_small_objects_only():
    m = disc_coverage((40, 40), 20.0, 20.0, 3.0)
    with pytest.raises(ValueError, match="min_area"):
        sorjax.outlines_from_mask(m, min_area=100)


# ------------------------------------------------------------------ from images


def test_outlines_from_image_with_boxes(scene):
    boxes = [(b[0] - 8, b[1] - 8, b[2] + 8, b[3] + 8) for b in scene.boxes]
    outs = sorjax.outlines_from_image(scene.image, boxes)
    assert len(outs) == 3
    for o, obj in zip(outs, scene.objects):  # box order
        check_outline(o)
        assert rms_to(o, obj.truth.outline) <= 0.2  # measured about 0.1 px
    plain = sorjax.outlines_from_image(scene.image, boxes, refine=False)
    # the refinement on the image is worth it
    assert np.mean([rms_to(o, b.truth.outline) for o, b in zip(outs, scene.objects)]) < 0.7 * np.mean(
        [rms_to(o, b.truth.outline) for o, b in zip(plain, scene.objects)]
    )


def test_outlines_from_image_blurred_edges():
    # a point-spread function of sigma 0.8 px spreads each edge over 2-3 px: the band of
    # the unmixing widens (0.4 px RMS with the sharp-edge band, about 0.25 with it)
    r = R.random_table_scene(5, n_objects=2, blur=0.8)
    outs = sorjax.outlines_from_image(r.image, [(b[0] - 8, b[1] - 8, b[2] + 8, b[3] + 8) for b in r.boxes])
    for o, obj in zip(outs, r.objects):
        assert rms_to(o, obj.truth.outline) <= 0.35


def test_outlines_from_image_automatic(scene):
    outs = sorjax.outlines_from_image(scene.image)
    assert len(outs) == 3
    areas = [shoelace(o) for o in outs]
    assert areas == sorted(areas, reverse=True)
    for o, e in zip(match(outs, scene.outlines), scene.outlines):
        assert rms_to(o, e) <= 0.25


def test_outlines_from_image_float_and_grey_input(scene):
    box = [tuple(np.add(scene.boxes[0], (-8, -8, 8, 8)))]
    a = sorjax.outlines_from_image(scene.image, box)[0]
    b = sorjax.outlines_from_image(scene.image.astype(np.float64) / 255.0, box)[0]
    assert np.array_equal(a, b)


def test_image_without_object():
    K = S.intrinsics(400.0, principal_point=(160.0, 120.0))
    empty = R.render(K, S.look_at((0.0, 0.5, 0.8), (0.0, 0.0, 0.0)), [], image_size=(320, 240), seed=1)
    with pytest.raises(ValueError, match="no object"):
        sorjax.outlines_from_image(empty.image)


@pytest.mark.parametrize(
    "image, boxes, msg",
    [
        (np.zeros((40, 40, 2), np.uint8), None, "BGR"),
        (np.zeros((8, 8, 3), np.uint8), None, "too small"),
        (np.full((40, 40, 3), 2.0), None, r"\[0, 1\]"),
        (np.zeros((40, 40, 3), np.uint8), [], "empty"),
        (np.zeros((40, 40, 3), np.uint8), [(10, 10, 5, 30)], "x1 > x0"),
        (np.zeros((40, 40, 3), np.uint8), [(100, 100, 130, 130)], "outside"),
        (np.zeros((40, 40, 3), np.uint8), [(1, 2, 3)], "4 finite numbers"),
        (None, None, "array"),
    ],
)
def test_bad_images(image, boxes, msg):
    with pytest.raises(ValueError, match=msg):
        sorjax.outlines_from_image(image, boxes)


def test_box_that_cuts_the_object_is_refused(scene):
    b = scene.boxes[0]
    cy = (b[1] + b[3]) // 2
    tight = [(b[0] - 8, b[1] - 8, b[2] + 8, cy), tuple(np.add(scene.boxes[1], (-8, -8, 8, 8)))]
    with pytest.warns(UserWarning, match="box 0 .*cuts it"):
        outs = sorjax.outlines_from_image(scene.image, tight)
    assert len(outs) == 1 and rms_to(outs[0], scene.objects[1].truth.outline) < 0.2


# ------------------------------------------------------------------ renderer


def test_polygon_coverage_is_the_area_and_matches_point_sampling():
    rng = np.random.default_rng(3)
    th = np.sort(rng.uniform(0, 2 * math.pi, 30))
    rad = 10 + 8 * rng.uniform(size=30)  # a star-shaped, hence simple, polygon
    poly = np.column_stack([25.3 + rad * np.cos(th), 22.6 + rad * np.sin(th)])
    cov = R.polygon_coverage(poly, (48, 52), supersample=32)
    assert abs(cov.sum() - abs(shoelace(poly))) < 1e-3 * abs(shoelace(poly))
    assert np.allclose(R.polygon_coverage(poly[::-1], (48, 52), supersample=32), cov, atol=1e-12)
    s = 16  # brute force: points on a 16 x 16 grid per pixel
    ys, xs = np.mgrid[0 : 48 * s, 0 : 52 * s]
    from matplotlib.path import Path

    inside = Path(poly).contains_points(np.column_stack([(xs.ravel() + 0.5) / s - 0.5, (ys.ravel() + 0.5) / s - 0.5]))
    bf = inside.reshape(48, s, 52, s).mean(axis=(1, 3))
    assert np.abs(bf - cov).max() < 0.05


def test_render_ground_truth_and_determinism(scene):
    again = R.random_table_scene(7, K=scene.K, n_objects=3)
    assert np.array_equal(again.image, scene.image)
    assert scene.image.shape == (480, 640, 3) and scene.image.dtype == np.uint8
    for obj in scene.objects:
        o = obj.truth.outline
        assert not obj.occluded
        assert abs(obj.coverage.sum() - shoelace(o)) < 1e-3 * shoelace(o)  # exact coverage
        assert o[:, 0].min() >= 12 and o[:, 0].max() <= 640 - 13  # margin_px
        ext = (o.max(0) - o.min(0)).max()
        assert 0.8 * 150 <= ext <= 1.15 * 280
        # the outline is the exact silhouette of this pose
        sil = S.sor_silhouette(obj.profile, scene.K, obj.R, obj.t)
        assert np.allclose(sil.points, o)
        # the image of the axis is a symmetry axis: W maps the outline onto itself
        h = np.column_stack([o, np.ones(len(o))]) @ obj.truth.W.T
        assert S.distance_to_polyline(h[:, :2] / h[:, 2:], o).max() < 0.05


def test_render_occlusion_and_inputs():
    K = S.intrinsics(700.0)
    cam = S.look_at((0.0, 0.35, 0.9), (0.0, 0.08, 0.0))
    objs = [R.TableObject("bottle", (0.0, -0.05)), R.TableObject("bowl", (0.02, 0.12), colour=(200, 40, 40))]
    r = R.render(K, cam, objs, noise=0.0, seed=2)
    back, front = r.objects
    assert back.occluded and not front.occluded
    assert back.coverage.sum() < shoelace(back.truth.outline) - 100
    assert abs(front.coverage.sum() - shoelace(front.truth.outline)) < 1e-3 * shoelace(front.truth.outline)
    with pytest.raises(ValueError, match="TableObject"):
        R.render(K, cam, ["vase"])
    with pytest.raises(ValueError, match="unknown profile"):
        R.render(K, cam, [R.TableObject("teapot")])
    with pytest.raises(ValueError, match="leaves"):
        R.render(K, cam, [R.TableObject("vase", (0.6, 0.0))])


# ------------------------------------------------------------------ end to end


def test_end_to_end_calibration_from_rendered_masks():
    K = S.intrinsics(800.0, aspect_ratio=0.97, principal_point=(300.0, 250.0))
    renders = [R.random_table_scene(s, K=K, n_objects=2) for s in (21, 22)]
    outlines = [o for r in renders for o in sorjax.outlines_from_mask(r.mask)]
    assert len(outlines) == 4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = sorjax.calibrate(outlines, method="bundle")
    assert cal.success
    assert abs(cal.fu / K[0, 0] - 1) < 0.01 and abs(cal.fv / K[1, 1] - 1) < 0.01
    assert abs(cal.u0 - K[0, 2]) < 5 and abs(cal.v0 - K[1, 2]) < 5


def test_outlines_from_image_are_repeatable():
    r = R.random_table_scene(1, n_objects=2)
    a = sorjax.outlines_from_image(r.image)
    b = sorjax.outlines_from_image(r.image)
    assert len(a) == len(b) == 2 and all(np.array_equal(x, y) for x, y in zip(a, b))
