"""Photo-like renders (sorjax.render with a PhotoStyle, sorjax._photo): deterministic,
exact ground truth unchanged by the looks, and actually harder than the plain renders."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from sorjax import render as R

SIZE = (400, 300)
SIZE_PX = (100.0, 170.0)


def _scene(seed=3, style="photo", **kw):
    return R.random_table_scene(seed, image_size=SIZE, n_objects=2, size_px=SIZE_PX, style=style, **kw)


@pytest.fixture(scope="module")
def style():
    # textured table and wall, clutter that may occlude, shadows, a glossy table, glass and metal
    return replace(R.random_style(np.random.default_rng(5)), table="tiles", wall="wallpaper", wall_distance=0.3,
                   clutter=5, clutter_in_front=True, reflection=0.2, materials=("glass", "metal"), jpeg=85)


@pytest.fixture(scope="module")
def photo(style):
    return _scene(style=style)


@pytest.fixture(scope="module")
def plain():
    return _scene(style=None)


def test_deterministic(style, photo):
    again = _scene(style=style)
    assert np.array_equal(again.image, photo.image)
    assert again.description == photo.description
    other = _scene(seed=4, style=style)
    assert not np.array_equal(other.image, photo.image)


def test_truth_is_the_plain_renders(photo, plain):
    # the style changes the looks, not the geometry: same K, pose, outlines
    assert np.array_equal(photo.K, plain.K)
    for a, b in zip(photo.objects, plain.objects):
        assert np.array_equal(a.truth.outline, b.truth.outline)
        assert a.box == b.box


def test_soft_masks_are_exact_coverages(photo):
    shape = photo.labels.shape
    for o in photo.objects:
        exact = R.polygon_coverage(o.truth.outline, shape)
        if o.occluded:  # hidden in part by clutter or an object in front: never more than the silhouette
            assert np.all(o.coverage <= exact + 1e-12) and (exact - o.coverage).max() > 0.5
        else:
            np.testing.assert_allclose(o.coverage, exact, atol=1e-12)


def _gradient_energy(img, mask):
    # structure, not noise: the grey image smoothed over ~2 px first
    g = cv2.GaussianBlur(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float64), (0, 0), 2.0)
    gx = cv2.Sobel(g, cv2.CV_64F, 1, 0)
    gy = cv2.Sobel(g, cv2.CV_64F, 0, 1)
    return float(np.mean(np.hypot(gx, gy)[mask]))


def test_background_has_texture(photo, plain):
    # away from the objects, the photo-like background has far more edges than the plain one
    far = cv2.dilate((photo.mask > 0).astype(np.uint8), np.ones((15, 15), np.uint8)) == 0
    e_photo, e_plain = _gradient_energy(photo.image, far), _gradient_energy(plain.image, far)
    assert e_photo > 4.0 * e_plain, (e_photo, e_plain)


def test_shadows_do_not_change_coverage(style, photo):
    lit = _scene(style=replace(style, shadow=0.0, contact=0.0, reflection=0.0))
    for a, b in zip(lit.objects, photo.objects):
        assert np.array_equal(a.coverage, b.coverage)
    # the shadows darken the table near the objects (not the objects themselves)
    near = (cv2.dilate((photo.mask > 0).astype(np.uint8), np.ones((41, 41), np.uint8)) > 0) & (photo.mask == 0)
    g0 = lit.image.astype(np.float64).mean(-1)
    g1 = photo.image.astype(np.float64).mean(-1)
    assert g1[near].mean() < g0[near].mean() - 2.0


@pytest.mark.parametrize("change", [{"jpeg": None}, {"jpeg": 40}, {"shot_noise": 10.0}, {"defocus": 2.0}])
def test_camera_effects_change_the_image_not_the_truth(style, photo, change):
    r = _scene(style=replace(style, **change))
    assert not np.array_equal(r.image, photo.image)
    assert np.array_equal(r.labels, photo.labels)
    for a, b in zip(r.objects, photo.objects):
        assert np.array_equal(a.coverage, b.coverage) and a.occluded == b.occluded


def test_noise_argument_changes_only_the_image(style, photo):
    r = _scene(style=style, noise=6.0)
    assert np.abs(r.image.astype(int) - photo.image.astype(int)).mean() > 1.0
    assert np.array_equal(r.labels, photo.labels)


def test_materials_are_used(photo):
    assert "materials glass" in photo.description or "materials metal" in photo.description


def test_glass_is_low_contrast():
    # a glass object shows the scene behind it: inside its silhouette the image is much
    # closer to the background rendered without it than a plain object's is
    st = replace(R.PhotoStyle(), clutter=0, shadow=0.0, contact=0.0, defocus=0.0, shot_noise=0.0, jpeg=None,
                 vignette=0.0, table="plain", wall="plain")
    K = np.array([[700.0, 0, 200], [0, 700.0, 150], [0, 0, 1]])
    from sorjax import scenes as S

    cam = S.look_at((0.3, 0.4, 0.9), (0.0, 0.14, 0.0))
    objs = lambda m: [R.TableObject("bottle", (0.0, 0.0), material=m, colour=(60, 60, 180))]  # noqa: E731
    empty = R.render(K, cam, [], image_size=SIZE, style=st, noise=0.0)
    diffs = {}
    for m in ("glass", "plain"):
        r = R.render(K, cam, objs(m), image_size=SIZE, style=st, noise=0.0)
        inner = cv2.erode((r.objects[0].coverage > 0.99).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
        diffs[m] = np.abs(r.image.astype(float) - empty.image.astype(float))[inner].mean()
    assert diffs["glass"] < 0.6 * diffs["plain"], diffs


def test_bad_style_is_refused():
    with pytest.raises(ValueError, match="style must be"):
        _scene(style="fancy")
    with pytest.raises(ValueError, match="style.table"):
        _scene(style=replace(R.PhotoStyle(), table="marble"))
    with pytest.raises(ValueError, match="style.jpeg"):
        _scene(style=replace(R.PhotoStyle(), jpeg=5))
    with pytest.raises(ValueError, match="material"):
        R.render(np.diag([500.0, 500.0, 1.0]), (np.eye(3), np.array([0.0, 0.0, 1.0])),
                 [R.TableObject("bottle", material="gold")])


def test_random_photo_set():
    # short focal lengths: small images, a cheap test (determinism: the renders' own test)
    ps = R.random_photo_set(2, cameras=2, images=1, objects=(2, 2), f_range=(450.0, 700.0))
    assert len(ps.cameras) == 2 and ps.seed == 2
    fs = [c.K[1, 1] for c in ps.cameras]
    assert 450.0 <= fs[0] <= np.sqrt(450.0 * 700.0) <= fs[1] <= 700.0  # one per log-half of the range
    for c in ps.cameras:
        assert c.image_size in R.PHOTO_SIZES and len(c.renders) == 1 and len(c.seeds) == 1
        r = c.renders[0]
        assert r.image.shape == (c.image_size[1], c.image_size[0], 3) and len(r.objects) == 2
        assert np.array_equal(r.K, c.K) and "photo style" in r.description
