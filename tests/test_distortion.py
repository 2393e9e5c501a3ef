"""sorjax.core._distortion: OpenCV's radial model (k1, k2) and its Newton inverse, against
cv2.projectPoints / cv2.undistortPoints, against each other, and differentiated."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax import scenes
from sorjax.core._distortion import (distort, distort_normalised, monotone_radius, opencv_coefficients, undistort,
                                undistort_normalised)

K = np.array([[620.0, 0.0, 331.0], [0.0, 610.0, 236.0], [0.0, 0.0, 1.0]])
COEFFS = [(-0.3, 0.0), (-0.15, 0.0), (0.1, 0.0), (-0.25, 0.08), (0.12, -0.04)]


def _points(k, n=400, seed=0):
    """Pixel points of a 640x480 image within 0.9 of the model's monotone radius."""
    rng = np.random.default_rng(seed)
    x = rng.uniform([0.0, 0.0], [639.0, 479.0], size=(n, 2))
    m = (x - K[:2, 2]) / np.diag(K)[:2]
    r = np.linalg.norm(m, axis=1)
    rmax = 0.9 * float(monotone_radius(np.asarray(k)))
    scale = np.where(r > rmax, rmax / np.maximum(r, 1e-300), 1.0)
    return K[:2, 2] + (m * scale[:, None]) * np.diag(K)[:2]


@pytest.mark.parametrize("k", COEFFS)
def test_distort_equals_cv2_project_points(k):
    x = _points(k)
    m = (x - K[:2, 2]) / np.diag(K)[:2]
    obj = np.column_stack([m, np.ones(len(m))])
    ref, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, opencv_coefficients(k))
    np.testing.assert_allclose(np.asarray(distort(x, K, np.asarray(k))), ref[:, 0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("k", COEFFS)
def test_undistort_equals_cv2_undistort_points(k):
    xd = np.asarray(distort(_points(k), K, np.asarray(k)))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(xd[:, None, :], K, opencv_coefficients(k), P=K, criteria=crit)[:, 0]
    np.testing.assert_allclose(np.asarray(undistort(xd, K, np.asarray(k))), ref, rtol=0, atol=1e-6)


@pytest.mark.parametrize("k", COEFFS)
def test_round_trip_to_1e_10_px(k):
    x = _points(k)
    k = np.asarray(k)
    back = np.asarray(undistort(distort(x, K, k), K, k))
    assert np.max(np.abs(back - x)) < 1e-10
    again = np.asarray(distort(undistort(x, K, k), K, k))
    inside = np.linalg.norm(np.asarray(undistort(x, K, k)) - K[:2, 2], axis=1) / 620.0 < 0.9 * float(monotone_radius(k))
    assert np.max(np.abs(again - x)[inside]) < 1e-10


def test_one_coefficient_equals_k2_zero_and_the_frame_cancels():
    x = _points((-0.2, 0.0), 50)
    a = distort(x, K, jnp.array([-0.2]))
    np.testing.assert_array_equal(np.asarray(a), np.asarray(distort(x, K, jnp.array([-0.2, 0.0]))))
    # a similarity T: distort(T x, T K) = T distort(x, K)
    T = np.array([[1 / 250.0, 0, -1.3], [0, 1 / 250.0, -0.9], [0, 0, 1]])
    xn = x @ T[:2, :2].T + T[:2, 2]
    np.testing.assert_allclose(np.asarray(distort(xn, T @ K, jnp.array([-0.2]))),
                               np.asarray(a) @ T[:2, :2].T + T[:2, 2], atol=1e-13)


def test_jit_vmap_clean():
    ks = jnp.array([[-0.3, 0.0], [0.1, -0.02], [-0.1, 0.05]])
    x = jnp.asarray(_points((-0.3, 0.0), 20))
    f = jax.jit(jax.vmap(lambda k: undistort(distort(x, K, k), K, k)))
    out = f(ks)
    assert out.shape == (3, 20, 2) and out.dtype == jnp.float64
    for i in range(3):
        np.testing.assert_allclose(np.asarray(out[i]), np.asarray(undistort(distort(x, K, ks[i]), K, ks[i])),
                                   atol=1e-12)


def _fd(f, z, h=1e-6):
    z = np.asarray(z, np.float64)
    cols = []
    for i in range(z.size):
        e = np.zeros_like(z)
        e.flat[i] = h
        cols.append((np.asarray(f(z + e)) - np.asarray(f(z - e))) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("k", [(-0.3, 0.0), (0.1, -0.04)])
def test_gradients_match_finite_differences(k):
    """Jacobians of both maps in the point, the coefficients and K's entries; and the
    second derivative of undistort in k1 (the bundle's implicit gradient uses Hessians)."""
    x0 = np.array([512.0, 401.0])
    kk = np.asarray(k)
    Kv = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])

    def Km(v):
        return jnp.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])

    for fun in (distort, undistort):
        for name, g, z in (
            ("x", lambda z: fun(z, K, kk), x0),
            ("k", lambda z: fun(x0, K, z), kk),
            ("K", lambda z: fun(x0, Km(z), kk), Kv),
        ):
            J = np.asarray(jax.jit(jax.jacfwd(g))(jnp.asarray(z)))
            Jr = np.asarray(jax.jit(jax.jacrev(g))(jnp.asarray(z)))
            num = _fd(jax.jit(g), z, h=1e-6 * max(1.0, float(np.max(np.abs(z)))))
            np.testing.assert_allclose(J, num, rtol=1e-6, atol=1e-6, err_msg=f"{fun.__name__} d/d{name}")
            np.testing.assert_allclose(Jr, J, rtol=1e-12, atol=1e-12)
    # second derivative in k1 of the undistorted point
    g1 = jax.jit(jax.grad(lambda k1: undistort(x0, K, jnp.stack([k1, kk[1]]))[0]))
    h2 = float(jax.jit(jax.grad(g1))(kk[0]))
    num = (float(g1(kk[0] + 1e-5)) - float(g1(kk[0] - 1e-5))) / 2e-5
    assert abs(h2 - num) < 1e-5 * max(1.0, abs(num))


def test_normalised_maps_and_monotone_radius():
    k = jnp.array([-0.3, 0.0])
    R = float(monotone_radius(k))
    assert abs(R - (1 / 0.9) ** 0.5) < 1e-12
    assert np.isinf(float(monotone_radius(jnp.array([0.1, 0.0]))))
    m = jnp.array([[0.0, 0.0], [0.3, -0.2]])
    np.testing.assert_allclose(np.asarray(undistort_normalised(distort_normalised(m, k), k)), np.asarray(m), atol=1e-15)
    # smooth at the principal point: finite gradient there
    g = jax.jacfwd(lambda z: undistort_normalised(z, k))(jnp.zeros(2))
    np.testing.assert_allclose(np.asarray(g), np.eye(2), atol=1e-15)
    np.testing.assert_array_equal(opencv_coefficients([-0.2, 0.05]), [-0.2, 0.05, 0, 0, 0])
    np.testing.assert_array_equal(opencv_coefficients([-0.2]), [-0.2, 0, 0, 0, 0])


# ------------------------------------------------------------- scenes with distortion


def _gap(d):
    return float(np.max(np.hypot(*(np.roll(d, -1, axis=0) - d).T)))


def test_scenes_distort_the_pinhole_silhouette_exactly():
    from sorjax import scenes

    plain = scenes.two_spheres(f=700.0, n_views=2)
    same = scenes.two_spheres(f=700.0, n_views=2, distortion=None)
    for a, b in zip(plain.views, same.views):
        np.testing.assert_array_equal(a.outline, b.outline)
        assert b.outline_pinhole is None
    assert same.distortion is None
    for k in ((-0.3, 0.05), (0.1, 0.0)):  # barrel: spacing shrinks; pincushion: retraced finer
        sc = scenes.two_spheres(f=700.0, n_views=2, distortion=k)
        assert sc.distortion == k
        for v in sc.views:
            back = np.asarray(undistort(v.outline, sc.K, np.asarray(k)))
            assert np.max(np.abs(back - v.outline_pinhole)) < 1e-10
            assert _gap(v.outline) <= 0.3 and int(np.argmin(v.outline[:, 1])) == 0
            assert scenes._signed_area(v.outline) > 0
            # the homology maps the pinhole outline onto itself, not the distorted one
            h = np.column_stack([v.outline_pinhole, np.ones(len(v.outline_pinhole))]) @ v.W.T
            assert np.max(scenes.distance_to_polyline(h[:, :2] / h[:, 2:], v.outline_pinhole)) < 1e-3
            h = np.column_stack([v.outline, np.ones(len(v.outline))]) @ v.W.T
            assert np.max(scenes.distance_to_polyline(h[:, :2] / h[:, 2:], v.outline)) > 0.5


def test_random_scene_with_distortion_and_the_fold():
    from sorjax import scenes

    K = scenes.intrinsics(450.0)
    sc = scenes.random_sor_scene(5, 2, K=K, distortion=(-0.3, 0.0))
    assert sc.distortion == (-0.3, 0.0) and "k1=-0.3" in sc.description
    for v in sc.views:
        m = (v.outline_pinhole - K[:2, 2]) / 450.0
        assert np.max(np.hypot(m[:, 0], m[:, 1])) <= 0.9 * float(monotone_radius(np.array([-0.3, 0.0])))
        assert v.outline.min() >= 0 and v.outline[:, 0].max() <= 639 and v.outline[:, 1].max() <= 479
    with pytest.raises(ValueError, match="one-to-one"):
        scenes.two_spheres(f=700.0, n_views=1, distortion=(-3.0, 0.0))


# ------------------------------------------------- camera.yaml with distortion


def _cal(distortion=None, distortion_std=None):
    from types import SimpleNamespace

    return SimpleNamespace(K=K, std=np.array([1.0, 1.0, 2.0, 2.0]), method="bundle", used=[0, 1, 2], fu=K[0, 0],
                           fv=K[1, 1], u0=K[0, 2], v0=K[1, 2], aspect_ratio=None, success=True, message="ok",
                           view_rms=[0.1, 0.2, 0.1], distortion=distortion, distortion_std=distortion_std)


def test_camera_yaml_carries_the_distortion_for_cv2_undistort(tmp_path):
    import json

    from sorjax._camera_io import write_camera

    k = np.array([-0.22, 0.04])
    yml, js = write_camera(_cal(k, [0.003, 0.01]), tmp_path / "camera.yaml", (640, 480))
    fs = cv2.FileStorage(str(yml), cv2.FILE_STORAGE_READ)
    Kr, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fs.release()
    np.testing.assert_array_equal(Kr, K)
    np.testing.assert_array_equal(dist.ravel(), [-0.22, 0.04, 0.0, 0.0, 0.0])
    doc = json.loads(js.read_text())
    assert doc["distortion_coefficients"] == [-0.22, 0.04, 0.0, 0.0, 0.0]
    assert doc["distortion"] == {"k1": -0.22, "k2": 0.04} and doc["distortion_std"] == {"k1": 0.003, "k2": 0.01}
    # an image of small blobs at the distorted positions of pinhole points: cv2.undistort
    # with the file's coefficients puts them back where the pinhole camera sees them
    pin = np.array([[100.0, 80.0], [560.0, 90.0], [90.0, 400.0], [540.0, 410.0], [331.0, 236.0], [450.0, 300.0]])
    xd = np.asarray(distort(pin, K, k))
    yy, xx = np.mgrid[0:480, 0:640].astype(np.float64)
    img = np.zeros((480, 640))
    for p in xd:
        img += np.exp(-((xx - p[0]) ** 2 + (yy - p[1]) ** 2) / (2 * 2.0**2))
    und = cv2.undistort((img * 200).astype(np.float32), Kr, dist)
    for p in pin:
        x0, y0 = int(round(p[0])), int(round(p[1]))
        win = und[y0 - 8:y0 + 9, x0 - 8:x0 + 9].astype(np.float64)
        c = np.array([np.sum(win * xx[y0 - 8:y0 + 9, x0 - 8:x0 + 9]), np.sum(win * yy[y0 - 8:y0 + 9, x0 - 8:x0 + 9])])
        assert np.linalg.norm(c / win.sum() - p) < 0.1


def test_camera_yaml_without_distortion_writes_zeros(tmp_path):
    import json

    from sorjax._camera_io import write_camera

    yml, js = write_camera(_cal(), tmp_path / "cam.yaml", (640, 480))
    fs = cv2.FileStorage(str(yml), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(fs.getNode("distortion_coefficients").mat(), np.zeros((1, 5)))
    fs.release()
    doc = json.loads(js.read_text())
    assert doc["distortion"] is None and doc["distortion_std"] is None
    _, js1 = write_camera(_cal([-0.1]), tmp_path / "one.yaml", (640, 480))
    assert json.loads(js1.read_text())["distortion_std"] == {"k1": None, "k2": 0.0}


# ------------------------------------------------------------- renders with distortion


def test_render_with_distortion_undistorts_to_the_pinhole_render():
    from sorjax import render

    k = (-0.2, 0.0)
    pin = render.random_table_scene(7, n_objects=1, noise=0.0)
    dis = render.random_table_scene(7, n_objects=1, noise=0.0, distortion=k)
    assert dis.distortion == k and pin.distortion is None
    (o,) = dis.objects
    assert np.allclose(o.R, pin.objects[0].R)  # the same layout
    back = np.asarray(undistort(o.truth.outline, dis.K, np.asarray(k)))
    assert np.max(np.abs(back - o.truth.outline_pinhole)) < 1e-10
    dist = opencv_coefficients(k)
    cov = cv2.undistort(o.coverage.astype(np.float32), dis.K, dist)
    inner = (slice(30, -30), slice(30, -30))
    assert np.mean(np.abs(cov - pin.objects[0].coverage)[inner]) < 2e-3
    img = cv2.undistort(dis.image, dis.K, dist).astype(float)
    assert np.mean(np.abs(img - pin.image)[inner]) < 0.5  # grey levels: resampling only
    assert np.mean(np.abs(dis.image.astype(float) - pin.image)[inner]) > 1.0


def test_overlay_pairs_in_the_distorted_image():
    # the overlay's transferred points x -> D(W D^-1 x) land on the distorted outline
    # with the true lens; drawn as a pinhole's (x -> W x) they miss it by pixels
    from sorjax._camera_io import mirror_pairs

    def dist(q, o):  # each point's distance to the closed polygon o
        a, b = o, np.roll(o, -1, axis=0)
        t = np.clip(np.einsum("qnk,nk->qn", q[:, None] - a, b - a) / np.sum((b - a) ** 2, -1), 0, 1)
        return np.min(np.linalg.norm(a + t[..., None] * (b - a) - q[:, None], axis=-1), axis=1)

    sc = scenes.random_sor_scene(1801, 4, distortion=(-0.15, 0.0))
    lens = (sc.K, np.array(sc.distortion))
    for view in sc.views:
        o = view.outline
        p, q = mirror_pairs(o, view.l_s, view.v_x, lens, count=16)
        assert len(q) >= 12
        d = dist(q, o)
        assert d.max() < 0.005, d
    # (the views of this scene: 0.02, 1.1, 5.4 and 12 px off as a pinhole's)
    d0 = [dist(mirror_pairs(v.outline, v.l_s, v.v_x, None, count=16)[1], v.outline).max() for v in sc.views]
    assert max(d0) > 5.0


def test_overlay_drawn_with_a_lens(tmp_path):
    import cv2

    from sorjax._camera_io import draw_overlay

    sc = scenes.random_sor_scene(1801, 2, distortion=(-0.15, 0.0))
    w, h = sc.image_size
    img = np.zeros((h, w, 3), np.uint8)
    views = [(v.outline, v.l_s, v.v_x, str(i)) for i, v in enumerate(sc.views)]
    png = draw_overlay(img, views, tmp_path / "o.png", lens=(sc.K, np.array(sc.distortion)))
    out = cv2.imread(str(png))
    assert out.shape == img.shape and (out[..., 1] > 100).any()  # the outlines, green
