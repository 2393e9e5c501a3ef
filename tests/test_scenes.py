"""Tests of sorjax.scenes: exact synthetic SOR scenes and the noise models."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sorjax import scenes as S


# ------------------------------------------------------------------ helpers


def _omega(K):
    Ki = np.linalg.inv(K)
    return Ki.T @ Ki


def _apply(H, pts):
    h = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return h[:, :2] / h[:, 2:3]


def _view_conics(P):
    return [S.sphere_image_conic(P, c, r) for c, r in S.TWO_SPHERES]


@pytest.fixture(scope="module")
def spheres700():
    return S.two_spheres(700.0)


@pytest.fixture(scope="module")
def spheres1400():
    return S.two_spheres(1400.0, n_views=8)


@pytest.fixture(scope="module")
def random_scenes():
    return [S.random_sor_scene(s, n_views=2) for s in (0, 1, 4, 11)]


def _pose(profile, elevation_deg, roll=0.4, azimuth=0.3, f=800.0, frac=0.6, shift=0.1, up=(0, 1, 0)):
    O = np.array([0.0, 0.5 * (profile.y0 + profile.y1), 0.0])
    Rb = math.hypot(0.5 * (profile.y1 - profile.y0), profile.r_max)
    D = 2 * f * Rb / (frac * 480)
    e = math.radians(elevation_deg)
    u = np.array([math.cos(e) * math.sin(azimuth), math.sin(e), math.cos(e) * math.cos(azimuth)])
    R, t = S.look_at(O + D * u, O, up, roll)
    return R, t + np.array([shift * Rb, 0.0, 0.0])


K800 = S.intrinsics(800.0, principal_point=(320.0, 240.0))


# ------------------------------------------------------------------ cameras


def test_look_at_points_the_camera_at_the_target():
    C, T = np.array([1.0, 2.0, 5.0]), np.array([0.2, -0.3, 0.4])
    R, t = S.look_at(C, T, up=(0, 1, 0), roll=0.7)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-14) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(S.camera_centre(R, t), C)
    x = S._project(S.camera_matrix(K800, R, t), T[None])[0]
    assert np.allclose(x, [320.0, 240.0], atol=1e-9)
    # without roll, 'up' points up in the image (y decreases)
    R0, t0 = S.look_at(C, T, up=(0, 1, 0))
    P0 = S.camera_matrix(K800, R0, t0)
    a, b = S._project(P0, np.array([T, T + [0, 0.1, 0]]))
    assert b[1] < a[1] and abs(b[0] - a[0]) < 1e-9 * 800
    with pytest.raises(ValueError, match="parallel"):
        S.look_at((0, 5, 0), (0, 0, 0), up=(0, 1, 0))


# ------------------------------------------------------------------ two spheres


def test_two_spheres_scene_structure(spheres700):
    sc = spheres700
    assert np.allclose(sc.K, [[700, 0, 320], [0, 700, 240], [0, 0, 1]])
    assert len(sc.views) == 3 and sc.image_size == (640, 480) and sc.seed is None
    assert len(sc.outlines) == 3
    for v in sc.views:
        o = v.outline
        assert o.dtype == np.float64 and o.shape[1] == 2 and 1500 <= len(o) <= 4000
        gaps = np.hypot(*(np.roll(o, -1, 0) - o).T)
        assert gaps.max() <= 0.3 * 1.01 and gaps.min() > 1e-6  # closed, dense, no repeats
        assert S._signed_area(o) > 0
        assert o.min() >= 0 and o[:, 0].max() <= 639 and o[:, 1].max() <= 479
        height = np.ptp(o[:, 1])
        assert 160 <= height <= 320  # 1/3 .. 2/3 of the image height
        assert S._self_intersections(o) == 0
        assert np.isclose(math.hypot(*v.l_s[:2]), 1.0) and np.isclose(np.linalg.norm(v.v_x), 1.0)


def test_two_spheres_outline_lies_on_the_sphere_ellipses(spheres700):
    for v in spheres700.views:
        d = np.array([S._conic_distance(C, v.outline) for C in _view_conics(v.P)])
        assert np.min(np.abs(d), axis=0).max() < 1e-8  # on one of the two ellipses (px)
        assert np.max(d, axis=0).min() > -1e-8  # never strictly inside both
        # both spheres contribute, and there are exactly two corners
        on0 = np.abs(d[0]) < 1e-8
        assert on0.any() and (~on0).any()
        assert np.count_nonzero(on0 != np.roll(on0, 1)) == 2


def test_pole_polar_relation_holds_exactly(spheres700, spheres1400, random_scenes):
    for sc in [spheres700, spheres1400, *random_scenes]:
        om = _omega(sc.K)
        for v in sc.views:
            w = om @ v.v_x
            w = w / np.linalg.norm(w)
            l = v.l_s / np.linalg.norm(v.l_s)
            assert np.linalg.norm(np.cross(w, l)) < 1e-12
            assert w @ l > 0  # sign convention l_s = +lambda omega v_x
            # l_s is the image of the axis: it passes through the images of axis points
            for y in (0.0, 0.5, 1.0):
                x = v.P @ np.array([0.0, y, 0.0, 1.0])
                assert abs(v.l_s @ x) / abs(x[2]) < 1e-9


def test_homology_maps_two_sphere_outline_onto_itself(spheres700):
    for v in spheres700.views:
        W = v.W
        assert np.allclose(W @ W, np.eye(3), atol=1e-12)
        x = v.outline[::7]
        y = _apply(W, x)
        conics = _view_conics(v.P)
        d = np.array([S._conic_distance(C, y) for C in conics])
        assert np.min(np.abs(d), axis=0).max() < 1e-7  # exact curve
        assert np.max(d, axis=0).min() > -1e-7
        assert S.distance_to_polyline(y, v.outline).max() < 1e-3  # dense polyline


def test_two_spheres_focal_scaling_keeps_the_outline_size(spheres700, spheres1400):
    for a, b in zip(spheres700.views, spheres1400.views[:3]):
        ea, eb = np.ptp(a.outline, 0), np.ptp(b.outline, 0)
        assert np.allclose(ea, eb, rtol=0.1)
        assert np.allclose(a.outline.mean(0), b.outline.mean(0), atol=15)
        va = np.hypot(*(a.v_x[:2] / a.v_x[2] - [320, 240]))
        vb = np.hypot(*(b.v_x[:2] / b.v_x[2] - [320, 240]))
        assert 1500 < va < 5000 and vb > 3 * va  # finite; weaker perspective at 1400


def test_two_spheres_options_and_errors():
    sc = S.two_spheres(900.0, n_views=1, aspect_ratio=1.05, principal_point=(330.0, 230.0))
    assert np.allclose(sc.K, [[945, 0, 330], [0, 900, 230], [0, 0, 1]])
    with pytest.raises(ValueError, match="n_views"):
        S.two_spheres(n_views=9)
    with pytest.raises(ValueError, match="n_views"):
        S.two_spheres(n_views=0)


def test_sor_construction_agrees_with_the_conic_construction(spheres700):
    """The general SOR machinery on the two-sphere profile (with its crease)
    reproduces the exact conic outline."""
    prof = S.two_spheres_profile()
    (R, t) = S.two_spheres_poses(700.0, 1)[0]
    sil = S.sor_silhouette(prof, spheres700.K, R, t)
    d = np.array([S._conic_distance(C, sil.points) for C in _view_conics(spheres700.views[0].P)])
    assert np.min(np.abs(d), axis=0).max() < 1e-8
    assert np.max(d, axis=0).min() > -1e-8
    ref = spheres700.views[0].outline
    assert abs(S._signed_area(sil.points) / S._signed_area(ref) - 1) < 1e-9


# ------------------------------------------------------------------ general SORs


@pytest.mark.parametrize(
    "name,elevation",
    [("vase", 45.0), ("wine_glass", 10.0), ("candle_holder", -20.0), ("bottle", 75.0), ("cylinder", 30.0)],
)
def test_sor_silhouette_is_exact(name, elevation):
    prof = S.PROFILES[name]()
    R, t = _pose(prof, elevation)
    sil = S.sor_silhouette(prof, K800, R, t)
    P = S.camera_matrix(K800, R, t)
    C = S.camera_centre(R, t)
    # the 3-D points project onto the outline
    assert np.allclose(S._project(P, sil.points_3d), sil.points, atol=1e-9)
    # contour points: surface normal perpendicular to the viewing ray
    X = sil.points_3d[sil.source == "contour"]
    assert len(X) > 100
    phi = np.arctan2(X[:, 2], X[:, 0])
    N = np.column_stack([np.cos(phi), -prof.dr(X[:, 1]), np.sin(phi)])
    V = X - C
    cosang = np.sum(N * V, 1) / np.linalg.norm(N, axis=1) / np.linalg.norm(V, axis=1)
    assert np.abs(cosang).max() < 1e-9
    assert np.allclose(np.hypot(X[:, 0], X[:, 2]), prof.r(X[:, 1]), rtol=1e-12)
    # cap points on the end circles
    Xc = sil.points_3d[sil.source == "cap"]
    assert np.all(np.isclose(Xc[:, 1], prof.y0) | np.isclose(Xc[:, 1], prof.y1))
    # every outline point is on the silhouette: rays touch the solid, none enters it
    m = S.silhouette_margin(prof, K800, R, t, sil.points)
    assert np.abs(m).max() < 1e-12 * prof.scale
    # moving 0.05 px inwards / outwards goes strictly inside / outside
    nrm = S.outline_normals(sil.points)[::25]
    assert np.all(S.silhouette_margin(prof, K800, R, t, sil.points[::25] - 0.05 * nrm) > 1e-9 * prof.scale)
    assert np.all(S.silhouette_margin(prof, K800, R, t, sil.points[::25] + 0.05 * nrm) < -1e-9 * prof.scale)
    # the outline is symmetric under the harmonic homology
    vt = S.view_truth(K800, R, t, sil.points)
    y = _apply(vt.W, sil.points[::9])
    assert np.abs(S.silhouette_margin(prof, K800, R, t, y)).max() < 1e-10 * prof.scale
    assert S.distance_to_polyline(y, sil.points).max() < 2e-3
    gaps = np.hypot(*(np.roll(sil.points, -1, 0) - sil.points).T)
    assert gaps.max() <= 0.3 * 1.01
    assert S._self_intersections(sil.points) == 0


def test_bowl_from_above_shows_its_rim():
    prof = S.bowl()
    sil = S.sor_silhouette(prof, K800, *_pose(prof, 45.0))
    rim = sil.source == "cap"
    assert rim.sum() > 0.3 * len(rim)
    assert np.allclose(sil.points_3d[rim, 1], prof.y1)  # the rim, not the base
    sil = S.sor_silhouette(prof, K800, *_pose(prof, 80.0))  # from nearly straight above
    assert np.all(sil.source == "cap")


def test_vase_neck_hides_part_of_the_contour_generator():
    prof = S.vase()
    R, t = _pose(prof, 45.0)
    C = S.camera_centre(R, t)
    sil = S.sor_silhouette(prof, K800, R, t)
    paths = S._sor_paths(prof, S.camera_matrix(K800, R, t), C)
    cont = [p for p in paths if p.label == "contour"]
    img, X = cont[0].func(np.linspace(cont[0].t0, cont[0].t1, 400))
    hidden = S._max_penetration(prof, C, X - C) > 1e-10 * prof.scale
    assert hidden.any() and (~hidden).any()
    # the outline has corners where the lip's contour emerges from behind the body
    d = np.diff(np.unwrap(np.arctan2(*np.diff(np.vstack([sil.points, sil.points[:1]]), axis=0).T[::-1])))
    assert np.abs(d).max() > 0.3


def test_sor_scene_builds_views_with_ground_truth():
    prof = S.bottle()
    poses = [_pose(prof, 20.0), _pose(prof, -10.0, roll=2.0), np.column_stack(_pose(prof, 50.0, roll=-1.0))]
    sc = S.sor_scene(prof, K800, poses, seed=7)
    assert len(sc.views) == 3 and sc.seed == 7 and "bottle" in sc.description
    for v, (R, t) in zip(sc.views, [poses[0], poses[1], (poses[2][:, :3], poses[2][:, 3])]):
        assert np.allclose(v.P, S.camera_matrix(K800, R, t))
        assert np.allclose(v.W @ v.W, np.eye(3), atol=1e-12)


def test_camera_inside_or_behind_raises():
    prof = S.vase()
    R, _ = S.look_at((0.0, 0.1, 0.0) + np.array([0.0, 0.0, 0.01]), (0.0, 0.1, 1.0))
    t = -R @ np.array([0.0, 0.1, 0.01])
    with pytest.raises(ValueError, match="inside the object"):
        S.sor_silhouette(prof, K800, R, t)
    R, t = S.look_at((0.0, 0.15, 0.5), (0.0, 0.15, 1.0))  # looking away from the vase
    with pytest.raises(ValueError, match="in front of the camera"):
        S.sor_silhouette(prof, K800, R, t)
    R, t = S.look_at((0.0, 1.0, 0.0), (0.0, 0.0, 0.0), up=(0, 0, 1))  # on the axis
    with pytest.raises(ValueError, match="axis"):
        S.sor_silhouette(prof, K800, R, t)
    R, t = _pose(prof, 20.0, frac=1.5)  # too close: outline leaves the image
    with pytest.raises(ValueError, match="leaves the"):
        S.sor_scene(prof, K800, [(R, t)])
    assert len(S.sor_scene(prof, K800, [(R, t)], allow_outside=True).views) == 1
    with pytest.raises(ValueError, match="rotation"):
        S.sor_silhouette(prof, K800, 2 * np.eye(3), np.array([0, 0, 1.0]))


def test_pchip_profile_matches_scipy():
    interp = pytest.importorskip("scipy.interpolate")
    for make in (S.vase, S.wine_glass, S.candle_holder, S.bowl):
        p = make()
        ref = interp.PchipInterpolator(p.control[:, 0], p.control[:, 1])
        y = np.linspace(p.y0, p.y1, 3001)
        assert np.allclose(p.r(y), ref(y), rtol=0, atol=1e-14)
        assert np.allclose(p.dr(y), ref.derivative()(y), rtol=0, atol=1e-11)


def test_profiles_are_valid():
    for name, make in S.PROFILES.items():
        p = make()
        assert p.name == name and p.y1 > p.y0 and p.r_max > 0
        y = np.linspace(p.y0, p.y1, 2001)
        assert np.all(p.r(y) > 0)
        # dr is the derivative of r
        h = 1e-6
        yy = y[10:-10]
        fd = (p.r(yy + h) - p.r(yy - h)) / (2 * h)
        assert np.allclose(p.dr(yy), fd, atol=1e-4 * max(1.0, np.abs(fd).max()))
    with pytest.raises(ValueError):
        S.Profile.from_points("bad", [0.0, 1.0, 0.5], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError):
        S.Profile("neg", 0.0, 1.0, lambda y: y - 0.5, lambda y: np.ones_like(y))


# ------------------------------------------------------------------ random scenes


def test_random_scenes_are_valid(random_scenes):
    for sc in random_scenes:
        w, h = sc.image_size
        assert isinstance(sc.seed, int) and f"seed={sc.seed}" in sc.description
        fu, fv = sc.K[0, 0], sc.K[1, 1]
        assert 500 <= fv <= 1500 and fu == fv
        assert abs(sc.K[0, 2] - w / 2) <= 0.1 * w and abs(sc.K[1, 2] - h / 2) <= 0.1 * h
        for v in sc.views:
            o = v.outline
            assert o.min() >= 0 and o[:, 0].max() <= w - 1 and o[:, 1].max() <= h - 1
            assert np.ptp(o, 0).max() >= 80
            # W maps the outline onto itself (to the chord error of the dense polyline,
            # which reaches a few 1e-3 px where the outline is sharply curved)
            y = _apply(v.W, o[::11])
            assert S.distance_to_polyline(y, o).max() < 2e-2


def test_random_scene_is_deterministic():
    a = S.random_sor_scene(3, n_views=1)
    b = S.random_sor_scene(3, n_views=1)
    c = S.random_sor_scene(5, n_views=1)
    assert np.array_equal(a.K, b.K) and a.description == b.description
    assert np.array_equal(a.views[0].outline, b.views[0].outline)
    assert not np.array_equal(a.K, c.K)
    g = S.random_sor_scene(np.random.default_rng(3), n_views=1, shapes=["cylinder"], vary_aspect=True)
    assert g.seed is None and "cylinder" in g.description
    assert 0.9 <= g.K[0, 0] / g.K[1, 1] <= 1.1
    with pytest.raises(ValueError, match="unknown shape"):
        S.random_sor_scene(0, shapes=["teapot"])


# ------------------------------------------------------------------ noise


def test_paper_noise_properties(spheres700):
    o = spheres700.views[0].outline
    sigma = 1.5
    y = S.paper_noise(o, sigma, 42)
    assert y.shape == o.shape and not np.shares_memory(y, o)
    d = y - o
    n = S.outline_normals(o)
    along = np.sum(d * n, 1)
    assert np.abs(along).max() <= sigma + 1e-12
    assert np.abs(d[:, 0] * n[:, 1] - d[:, 1] * n[:, 0]).max() < 1e-12  # along the normal
    # literal model: smoothing (2 px) lowers the std to about 0.22 sigma
    assert 0.15 * sigma < along.std() < 0.3 * sigma
    kept = np.sum((S.paper_noise(o, sigma, 42, preserve_std=True) - o) * n, 1)
    assert 0.4 * sigma < kept.std() < 0.65 * sigma  # about sigma / sqrt(3), slightly clipped
    assert np.abs(kept).max() > 0.9 * sigma and np.abs(kept).max() <= sigma + 1e-12
    # smooth along the curve: neighbours (0.3 px apart) are strongly correlated
    assert np.corrcoef(along, np.roll(along, 1))[0, 1] > 0.95
    assert np.array_equal(y, S.paper_noise(o, sigma, 42))
    assert not np.allclose(y, S.paper_noise(o, sigma, 43))
    assert np.array_equal(y, S.paper_noise(o, sigma, np.random.default_rng(42)))
    # outward normals: positive displacement grows the area
    assert S._signed_area(o + 0.5 * n) > S._signed_area(o)
    # unsmoothed: i.i.d. uniform
    u = np.sum((S.paper_noise(o, sigma, 1, smooth_px=0.0) - o) * n, 1)
    assert abs(np.corrcoef(u, np.roll(u, 1))[0, 1]) < 0.1
    assert np.array_equal(S.paper_noise(o, 0.0, 1), o)


def test_gaussian_noise_properties(spheres700):
    o = spheres700.views[1].outline
    y = S.gaussian_noise(o, 0.8, 3)
    d = y - o
    n = S.outline_normals(o)
    assert np.abs(d[:, 0] * n[:, 1] - d[:, 1] * n[:, 0]).max() < 1e-12
    assert abs(np.sum(d * n, 1).std() - 0.8) < 0.05
    assert np.array_equal(y, S.gaussian_noise(o, 0.8, 3))
    assert not np.allclose(y, S.gaussian_noise(o, 0.8, 4))


def test_noise_bad_input():
    o = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="sigma"):
        S.paper_noise(o, -1.0, 0)
    with pytest.raises(ValueError, match="sigma"):
        S.gaussian_noise(o, float("nan"), 0)
    with pytest.raises(ValueError, match="smooth_px"):
        S.paper_noise(o, 1.0, 0, smooth_px=-1.0)
    with pytest.raises(ValueError, match=r"\(M, 2\)"):
        S.paper_noise(o[:, :1], 1.0, 0)
    with pytest.raises(TypeError, match="seed"):
        S.paper_noise(o, 1.0, "abc")


@settings(max_examples=25, deadline=None)
@given(
    sigma=st.floats(0.0, 3.0),
    smooth=st.floats(0.0, 6.0),
    seed=st.integers(0, 2**31),
    n=st.integers(8, 400),
)
def test_paper_noise_bound_property(sigma, smooth, seed, n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    o = np.column_stack([100 + 40 * np.cos(t), 80 + 25 * np.sin(t)])
    y = S.paper_noise(o, sigma, seed, smooth_px=smooth)
    d = y - o
    assert np.all(np.hypot(d[:, 0], d[:, 1]) <= sigma + 1e-9)


def test_closest_points_on_polyline_against_each_segment_and_bad_input():
    rng = np.random.default_rng(0)
    poly = rng.normal(size=(40, 2)) * 10.0
    pts = rng.normal(size=(300, 2)) * 10.0
    foot, seg, t = S.closest_points_on_polyline(pts, poly, chunk=64)
    a, b = poly, np.roll(poly, -1, axis=0)
    np.testing.assert_allclose(foot, a[seg] + t[:, None] * (b[seg] - a[seg]), atol=1e-12)
    for x, f in zip(pts, foot):  # no point of any segment is nearer than the foot
        u = np.clip(np.sum((x - a) * (b - a), 1) / np.sum((b - a) ** 2, 1), 0, 1)
        assert np.hypot(*(x - f)) <= np.min(np.hypot(*(x - a - u[:, None] * (b - a)).T)) + 1e-12
    with pytest.raises(ValueError, match="M >= 3"):
        S.closest_points_on_polyline(pts, poly[:2])
    with pytest.raises(ValueError, match="finite"):
        S.closest_points_on_polyline(np.array([[0.0, np.nan]]), poly)
