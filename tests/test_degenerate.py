"""Degenerate geometry and bad input (paper, Section 6): detected, reported, never a
silent wrong K.  Scenes are exact (sorjax.scenes) so every claim is checked against
the ground truth."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes

K_TRUE = scenes.intrinsics(800.0, principal_point=(330.0, 250.0))
HEIGHT = 480

# (elevation deg, azimuth deg, roll rad[, pixel where the object's centre lands])
AT_INFINITY = [(30, 0, 0.3), (-10, 70, -0.5), (50, 200, 1.0)]  # object centre at the principal point
FINITE = (50, 200, 1.0, (150, 120))
MIRROR = [(0, 0, 0), (20, 90, 0)]  # upright, roll 0, centred: mirror-symmetric outlines
LEVEL_UPRIGHT = [(0, 0, 0, (200, 250)), (0, 70, 0, (450, 200)), (0, 200, 0, (330, 300))]
NEAR_AXIS = [(30, 0, 0.3, (340, 260)), (-10, 70, -0.5, (320, 245)), (50, 200, 1.0, (335, 240))]
GOOD = [(30, 0, 0.3, (150, 150)), (-10, 70, -0.5, (480, 350)), (50, 200, 1.0, (200, 380))]


def pose_at(profile, K, el_deg, az_deg, roll=0.0, pix=None):
    return scenes.pose_at_pixel(profile, K, el_deg, az_deg, roll, pix, image_height=HEIGHT)


def posed(specs):
    prof = scenes.vase()
    return scenes.sor_scene(prof, K_TRUE, [pose_at(prof, K_TRUE, *s) for s in specs])


def fits(outlines):
    return tuple(sorjax.fit_homology(o) for o in outlines)


def k_error(cal, K=K_TRUE) -> float:
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    return float(np.max(np.abs(est - np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))) / K[1, 1])


def blob(seed, R=120.0, amp=0.35, n=1500):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = np.ones_like(t)
    for k in range(2, 7):
        r += rng.uniform(0.5, 1.0) * amp / (k - 1) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
    return np.stack([320 + R * r * np.cos(t), 240 + R * r * np.sin(t)], 1)


def sphere_outline(K, pose, centre, radius, n=800):
    """Exact image of a sphere: points of its image conic on rays from the centre's image."""
    P = scenes.camera_matrix(K, *pose)
    C = scenes.sphere_image_conic(P, centre, radius)
    x0 = P @ np.append(centre, 1.0)
    c = np.array([x0[0] / x0[2], x0[1] / x0[2], 1.0])
    pts = []
    for th in np.linspace(0, 2 * np.pi, n, endpoint=False):
        d = np.array([math.cos(th), math.sin(th), 0.0])
        a, b, cc = d @ C @ d, 2 * c @ C @ d, c @ C @ c
        s = max((-b + math.sqrt(b * b - 4 * a * cc)) / (2 * a), (-b - math.sqrt(b * b - 4 * a * cc)) / (2 * a))
        pts.append(c[:2] + s * d[:2])
    return np.array(pts)


@pytest.fixture(scope="module")
def good():
    sc = posed(GOOD)
    return sc, fits(sc.outlines)


@pytest.fixture(scope="module")
def at_infinity():
    sc = posed(AT_INFINITY)
    return sc, fits(sc.outlines)


# ------------------------------------------------------------------ conic outlines


def test_sphere_and_ellipse_outlines_are_dropped_with_the_reason(good):
    sc, homs = good
    prof = scenes.vase()
    sphere = sphere_outline(K_TRUE, pose_at(prof, K_TRUE, 20, 40, 0.2, (200, 180)), np.array([0.0, 0.15, 0.0]), 0.08)
    h = sorjax.fit_homology(sphere)
    assert h.is_conic and not any(g.is_conic for g in homs)
    with pytest.warns(UserWarning, match=r"view 1: the outline is a conic.*Dropped"):
        cal = sorjax.calibrate(
            [sc.outlines[0], sphere, sc.outlines[1], sc.outlines[2]], method="IIb", homologies=(homs[0], h) + homs[1:]
        )
    assert cal.success and cal.used == (0, 2, 3) and cal.dropped == ((1, "conic outline"),)
    assert k_error(cal) < 1e-4
    t = np.linspace(0, 2 * np.pi, 800, endpoint=False)
    ellipse = np.stack([300 + 90 * np.cos(t + 0.3), 200 + 60 * np.sin(t)], 1)
    with pytest.warns(UserWarning, match="conic"):
        few = sorjax.calibrate([sphere, sc.outlines[0], ellipse], method="IIb")
    assert few.result == sorjax.RESULTS.too_few_views and not few.success and np.isnan(np.asarray(few.K)).all()
    assert "view 0: conic outline" in few.message and "view 2: conic outline" in few.message
    assert "A single view gives only two constraints" in few.message
    with pytest.raises(sorjax.CalibrationError, match="Fewer than two views"), pytest.warns(UserWarning):
        sorjax.calibrate([sphere, sc.outlines[0]], throw=True)


# ----------------------------------------------------------------- v_x at infinity


@pytest.mark.parametrize("method", ["bundle", "I", "IIa", "IIb"])
def test_every_vx_at_infinity_gives_only_the_principal_point(at_infinity, good, method):
    sc, homs = at_infinity
    for view, h in zip(sc.views, homs):
        assert abs(view.v_x[2]) < 1e-12  # the scene really has v_x at infinity
        assert h.v_x_at_infinity
        assert abs(view.l_s @ np.array([K_TRUE[0, 2], K_TRUE[1, 2], 1.0])) < 1e-9  # l_s through the pp
    assert not any(h.v_x_at_infinity for h in good[1])
    cal = sorjax.calibrate(sc.outlines, method=method, homologies=homs)
    assert cal.result == sorjax.RESULTS.only_principal_point and not cal.success
    assert np.isnan(cal.fu) and np.isnan(cal.fv)  # no invented focal length
    np.testing.assert_allclose(cal.principal_point, K_TRUE[:2, 2], atol=1e-4)
    assert np.isinf(cal.std[:2]).all() and np.all(cal.std[2:] < 1e-3)
    assert "principal point" in cal.message and "views 0, 1, 2" in cal.message
    with pytest.raises(sorjax.CalibrationError, match="not the focal length"):
        sorjax.calibrate(sc.outlines, method=method, homologies=homs, throw=True)


def test_two_imaged_axes_do_not_determine_the_principal_point(at_infinity):
    """Two views with v_x at infinity: their imaged axes always meet, so the meeting
    point cannot show its own error and is not reported as the principal point (a
    photo set's two poor outlines put it 3800 px below a 768 px image, reported as
    determined before); three views report it (above)."""
    sc, homs = at_infinity
    cal = sorjax.calibrate(sc.outlines[:2], homologies=homs[:2], image_size=(640, HEIGHT))
    assert cal.result == sorjax.RESULTS.degenerate and not cal.success
    assert np.isnan(np.asarray(cal.K)).all()
    # the meeting point is named in the message, with why it is not reported
    assert "not reported as the principal point" in cal.message and "only 2 imaged axes" in cal.message
    assert f"({K_TRUE[0, 2]:.1f}, {K_TRUE[1, 2]:.1f})" in cal.message
    three = sorjax.calibrate(sc.outlines, homologies=homs, image_size=(640, HEIGHT))
    assert three.result == sorjax.RESULTS.only_principal_point
    np.testing.assert_allclose(three.principal_point, K_TRUE[:2, 2], atol=1e-4)


def test_a_principal_point_outside_the_image_is_not_reported(at_infinity):
    """Three views with v_x at infinity whose axes meet outside the image (the image
    given smaller than the camera's): the outlines do not fit in it either, and
    calibrate names that before anything runs (it reported the implausible principal
    point, the wrong cause); the core's own check, that a meeting point outside the
    image is not reported, is in the next test."""
    sc, homs = at_infinity
    small = (200, 150)  # the true principal point (330, 250) lies outside it
    with pytest.raises(ValueError, match=r"image_size \(200, 150\) is smaller than the outlines' extent"):
        sorjax.calibrate(sc.outlines, homologies=homs, image_size=small)


def test_the_core_reports_the_principal_point_only_where_determined(at_infinity):
    """The core's ``determined`` flags agree with the finite entries of ``K`` in the
    principal-point-only case, under jit as eagerly; a meeting point outside the image
    (given smaller than the camera's, 200 x 150: the true principal point (330, 250)
    lies outside it) is not reported."""
    from sorjax import core

    sc, homs = at_infinity
    pts = np.stack([np.asarray(o)[np.linspace(0, len(o), 400, endpoint=False).astype(int)] for o in sc.outlines])
    cal = jax.jit(lambda p, s: core.calibrate(p, image_size=s))  # the image size traced: one program per n
    for n in (2, 3):
        for size in ((640.0, HEIGHT), (200.0, 150.0)):
            r = cal(jnp.asarray(pts[:n]), jnp.array(size))
            K = np.asarray(r.K)
            det = np.asarray(r.determined)
            assert not det[:2].any()
            assert det[2] == det[3] == (n == 3 and size[0] == 640.0)
            np.testing.assert_array_equal(np.isfinite([K[0, 2], K[1, 2]]), det[2:])


def test_few_dof_widening_is_students_t():
    """The widening of a std estimated from nu residuals is t_nu(Phi(3)) / 3 (scipy),
    eagerly and under jit."""
    stats = pytest.importorskip("scipy.stats")
    from sorjax.core._assess import few_dof_widening

    nu = np.arange(1, 80)
    want = stats.t.ppf(stats.norm.cdf(3.0), nu) / 3.0
    np.testing.assert_allclose([float(few_dof_widening(int(v))) for v in nu], want, rtol=1e-3)
    np.testing.assert_allclose(jax.jit(jax.vmap(few_dof_widening))(jnp.asarray(nu, jnp.float64)), want, rtol=1e-3)


def test_three_axes_meeting_point_covers_its_truth_at_3_std():
    """Three lines through a point, each shifted along its normal by Gaussian noise
    (20000 trials, vmapped under jit): the meeting point is within 3 of its reported
    standard deviations per coordinate in 99.73 % of trials, as stated; the bare
    scatter (one degree of freedom) would be off by more in about a quarter."""
    from sorjax.core._assess import axes_intersection, few_dof_widening

    rng = np.random.default_rng(7)
    n, k = 20000, 3
    p = np.array([320.0, 240.0])
    th = rng.uniform(0.0, np.pi, (n, k))
    a = np.stack([np.cos(th), np.sin(th)], -1)
    c = -(a @ p) + rng.normal(0.0, 1.5, (n, k))
    ls = np.concatenate([a, c[..., None]], -1)
    used = np.ones((n, k), bool)
    x, cov, _ = jax.jit(jax.vmap(axes_intersection))(jnp.asarray(ls), jnp.asarray(used))
    sd = np.sqrt(np.diagonal(np.asarray(cov), axis1=1, axis2=2))
    z = np.abs(np.asarray(x) - p) / sd
    ok = np.all(np.isfinite(z), axis=1)
    assert ok.mean() > 0.99
    beyond = np.mean(z[ok] > 3.0)
    assert 0.0008 < beyond < 0.006, beyond  # 0.27 % expected
    bare = np.mean(z[ok] * float(few_dof_widening(1)) > 3.0)
    assert bare > 0.15, bare


def test_every_vx_at_infinity_with_noise(at_infinity):
    sc, _ = at_infinity
    outs = [scenes.paper_noise(o, 1.0, 10 + i) for i, o in enumerate(sc.outlines)]
    cal = sorjax.calibrate(outs)
    assert cal.result == sorjax.RESULTS.only_principal_point
    assert np.isnan(cal.fv)
    assert np.max(np.abs(cal.principal_point - K_TRUE[:2, 2])) < 2.0
    # outlines of measured quality: the same principal point, within its std
    measured = sorjax.calibrate(outs, outline_error="measured", image_size=(640, HEIGHT))
    assert measured.result == sorjax.RESULTS.only_principal_point
    np.testing.assert_allclose(measured.principal_point, cal.principal_point)
    assert np.all(np.abs(measured.principal_point - K_TRUE[:2, 2]) < 3 * measured.std[2:] + 0.5)


def test_one_finite_vx_is_enough(at_infinity):
    sc = posed(AT_INFINITY[:2] + [FINITE])
    cal = sorjax.calibrate(sc.outlines)
    assert cal.success, cal.message
    assert k_error(cal) < 1e-4


def test_mirror_views_free_aspect_is_reported_not_invented():
    """Two mirror-symmetric views (v_x at infinity, imaged axis vertical through the
    principal point) and one general view: with a free aspect ratio fu, fv and v0 are
    not determined (exact null directions: infinite std); with unit aspect they are."""
    sc = posed(MIRROR + [FINITE])
    homs = fits(sc.outlines)
    assert [h.v_x_at_infinity for h in homs] == [True, True, False]
    cal = sorjax.calibrate(sc.outlines, homologies=homs)
    assert cal.result == sorjax.RESULTS.degenerate and not cal.success
    assert np.isnan([cal.fu, cal.fv, cal.v0]).all()
    assert abs(cal.u0 - K_TRUE[0, 2]) < 1e-3  # the one intrinsic these views do fix
    assert np.isinf(cal.std[[0, 1, 3]]).all() and cal.std[2] < 1e-2
    assert "Not determined by these views: fu" in cal.message and "aspect_ratio=1.0" in cal.message
    unit = sorjax.calibrate(sc.outlines, aspect_ratio=1.0, homologies=homs)
    assert unit.success and k_error(unit) < 1e-4


def test_parallel_imaged_axes_leave_fv_free():
    """Upright objects seen by a level camera: every l_s is vertical and every v_x lies on
    the horizon, so fv never enters the constraints (free aspect)."""
    sc = posed(LEVEL_UPRIGHT)
    homs = fits(sc.outlines)
    cal = sorjax.calibrate(sc.outlines, homologies=homs)
    assert cal.result == sorjax.RESULTS.degenerate
    assert np.isnan(cal.fv) and abs(cal.fu - K_TRUE[0, 0]) < 1e-2
    assert "Not determined by these views: fv" in cal.message
    assert "all imaged axes are within" in cal.message and "aspect_ratio=1.0" in cal.message
    unit = sorjax.calibrate(sc.outlines, aspect_ratio=1.0, homologies=homs)
    assert unit.success and k_error(unit) < 1e-4


def test_near_degenerate_views_warn_with_advice():
    """The object within 10 px of the principal point in every view: v_x far away
    (about 1 deg from the optical axis).  Exact outlines still give K, with a warning
    that the geometry is weak and what to add.  With 1 px of noise the views cannot
    fix the focal length: only the principal point is reported -- never a confident K."""
    sc = posed(NEAR_AXIS)
    with pytest.warns(UserWarning, match=r"weak geometry.*straight at the object's axis.*edge or corner"):
        cal = sorjax.calibrate(sc.outlines, outline_error=0.0)  # exact outlines
    assert cal.success and k_error(cal) < 1e-4
    assert any("weak geometry" in n for n in cal.notes)
    # the same outlines if they may carry 0.1 px of systematic error (the default): they
    # show far less perspective than 3 x 0.1 px, so the focal length is not determined
    assert cal.perspective_px < 0.3
    real = sorjax.calibrate(sc.outlines)
    assert not real.success and np.isnan(real.fv)
    for seed in (10, 20):
        outs = [scenes.paper_noise(o, 1.0, seed + i) for i, o in enumerate(sc.outlines)]
        for oe in (0.0, 0.1):
            pp_only = sorjax.calibrate(outs, outline_error=oe)
            assert not pp_only.success and np.isnan(pp_only.fv)
            if pp_only.result == sorjax.RESULTS.only_principal_point:
                assert np.all(np.abs(pp_only.principal_point - K_TRUE[:2, 2]) < 3 * pp_only.std[2:] + 1.0)
            else:  # too little perspective (the evidence gate), or three axes whose meeting
                # point's scatter (one degree of freedom) does not fix it: nothing is reported
                assert pp_only.result == sorjax.RESULTS.degenerate and np.isnan(pp_only.principal_point).all()
                assert ("too little perspective" in pp_only.message
                        or "not reported as the principal point" in pp_only.message)


def test_weak_geometry_with_noise_is_reported_through_the_covariance():
    """The object 40 px from the principal point (v_x about 3 deg from the optical
    axis), 1 px of noise: K with a focal std above 5 %, a warning, and an error the
    std accounts for."""
    sc = posed([(30, 0, 0.3, (370, 290)), (-10, 70, -0.5, (290, 250)), (50, 200, 1.0, (330, 210))])
    outs = [scenes.paper_noise(o, 1.0, 10 + i) for i, o in enumerate(sc.outlines)]
    with pytest.warns(UserWarning, match=r"weak geometry: the focal length is uncertain by .* %.*straight at"):
        cal = sorjax.calibrate(outs, outline_error=0.0)  # the synthetic noise is the only error
    assert cal.success and cal.std[1] / K_TRUE[1, 1] > 0.05
    assert abs(cal.fv - K_TRUE[1, 1]) < 3 * cal.std[1]


def test_no_warning_for_a_good_configuration(good):
    sc, homs = good
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal = sorjax.calibrate(sc.outlines, homologies=homs)
    assert cal.success and k_error(cal) < 1e-4 and cal.notes == () and cal.details == ""


def test_same_view_three_times_is_degenerate(good):
    sc, homs = good
    with pytest.warns(UserWarning, match=r"view 1: the same outline as view 0.*Dropped"):
        cal = sorjax.calibrate([sc.outlines[0]] * 3, method="IIb", homologies=(homs[0],) * 3)
    assert not cal.success and cal.result == sorjax.RESULTS.too_few_views
    assert np.isnan(np.asarray(cal.K)[[0, 1], [0, 1]]).all()
    assert cal.dropped == ((1, "the same outline as view 0"), (2, "the same outline as view 0"))


# ------------------------------------------------------------- not symmetric at all


def test_asymmetric_blob_is_dropped(good):
    sc, homs = good
    b = blob(1)
    hb = sorjax.fit_homology(b)
    assert float(hb.rms) > 3.0  # vs < 1e-4 px for the true views
    assert all(float(h.rms) < 1e-4 for h in homs)
    with pytest.warns(UserWarning, match=r"view 1: the outline is not symmetric.*Dropped"):
        cal = sorjax.calibrate([sc.outlines[0], b] + sc.outlines[1:], homologies=(homs[0], hb) + homs[1:])
    assert cal.success and cal.used == (0, 2, 3) and cal.dropped[0][0] == 1
    assert k_error(cal) < 1e-4
    with pytest.warns(UserWarning, match="not symmetric"):
        few = sorjax.calibrate([b, blob(2), sc.outlines[0]])
    assert few.result == sorjax.RESULTS.too_few_views and "not symmetric" in few.message


# ------------------------------------------------------------------------ bad input


def _ellipse(n=600):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([320 + 120 * np.cos(t), 240 + 70 * np.sin(t)], 1)


E = _ellipse()
_NAN = E.copy()
_NAN[4] = np.nan
_INF = E.copy()
_INF[9, 1] = -np.inf
_T = np.linspace(0, 2 * np.pi, 200, endpoint=False)
_EIGHT = np.stack([100 * np.sin(_T), 60 * np.sin(2 * _T)], 1) + 300


@pytest.mark.parametrize(
    "outlines, kwargs, words",
    [
        ([], {}, "at least two outlines.*got 0"),
        ([E], {}, "at least two outlines.*got 1.*two constraints on the four intrinsics"),
        (E, {}, r"got a single outline. Wrap it in a list: pass \[outline\], not a bare array of shape \(600, 2\)"),
        (E[:, None, :], {}, "got a single outline"),
        (E.tolist(), {}, "got a single outline"),
        ("view.txt", {}, "got str.*np.loadtxt"),
        (None, {}, "got NoneType"),
        ({"a": E, "b": E}, {}, "got dict"),
        (3, {}, "got int"),
        ([E, _NAN], {}, "outline 1: 1 of 600 points are NaN or infinite .first at row 4"),
        ([E, _INF], {}, "outline 1: 1 of 600 points are NaN or infinite .first at row 9"),
        ([E, np.zeros((0, 2))], {}, "outline 1: is empty"),
        ([E, E[:5]], {}, "outline 1: has 5 distinct points; at least 32"),
        ([E, np.ones((40, 2))], {}, "outline 1: has 1 distinct points"),
        ([E, E[:300]], {}, "outline 1: looks like an open curve"),
        ([E, _EIGHT], {}, "outline 1: crosses itself"),
        ([E, np.vstack([E, E])], {}, "outline 1: the point .* occurs 2 times.*traced more than once"),
        ([E, np.vstack([E[:100], E[40:41], E[100:]])], {}, r"outline 1: .*occurs 2 times \(rows 40, 100\)"),
        ([E / 1000, E], {}, "outline 0: spans only .* px. Outlines must be in pixel coordinates"),
        ([E, np.hstack([E, E[:, :1]])], {}, r"outline 1: expected shape \(N, 2\), got \(600, 3\)"),
        ([E, E.T], {}, "transposed"),
        ([E, E[:, 0]], {}, r"expected shape \(N, 2\)"),
        ([E, E.astype(str)], {}, "expected real numbers, got dtype <U"),
        ([E, E.astype(complex)], {}, "got dtype complex128"),
        ([E, [[1, 2], [3]]], {}, "could not be read"),
        ([E, None], {}, "outline 1: expected an .N, 2. array.*got NoneType"),
        ([E, "abc"], {}, "outline 1: .*got str 'abc'"),
        ([E, E], {"method": "III"}, "method must be one of"),
        ([E, E], {"aspect_ratio": 0.0}, "aspect_ratio must be a positive"),
        ([E, E], {"n_samples": 0}, "n_samples must be an integer >= 10"),
        ([E, E], {"n_points": 16}, "n_points must be an integer >= 64"),
        ([E, E], {"homologies": [None]}, "got 1 homologies for 2 outlines"),
        ([E, E], {"homologies": [None, None]}, r"homologies\[0\] is a NoneType, not a sorjax.Homology"),
    ],
)
def test_bad_input_says_what_is_wrong_before_any_tracing(outlines, kwargs, words):
    with pytest.raises(ValueError, match=words) as info:
        sorjax.calibrate(outlines, **kwargs)
    frames = [str(e.path) for e in info.traceback]
    assert not any(("jax" in p and "sorjax" not in p) or "optimistix" in p for p in frames), frames


def test_collapsed_focal_length_is_never_determined():
    # a focal length with a small std that would put the outlines across more than 90
    # degrees of view (seen on weak real photographs: 20 px, 168 px for a true 590) is
    # refused as undetermined, and so is the principal point estimated with it
    import jax.numpy as jnp

    from sorjax._messages import _implausible_text
    from sorjax.core import Options
    from sorjax.core._assess import COLLAPSED_FOCAL, PLAUSIBLE, WIDE_FOV, assess, implausible, outline_extent

    sc = scenes.two_spheres(700.0)
    outs = [sorjax.make_outline(o) for o in sc.outlines]
    pts = jnp.stack([o.points for o in outs])
    extent = float(outline_extent(pts, jnp.ones(len(outs), bool)))
    assert np.isclose(extent, max(np.ptp(np.concatenate([np.asarray(o.points) for o in outs]), axis=0)))
    nan2 = jnp.full(2, jnp.nan)

    def determined(est, image_size=nan2):
        return np.asarray(assess(jnp.asarray(est), jnp.eye(4) * 1e-4, 0.5, 100.0, extent, image_size, False, False,
                                 True, Options()).determined)

    assert not determined([20.0, 20.0, 320.0, 240.0]).any()
    code = int(implausible(jnp.array([20.0, 20.0, 320.0, 240.0]), extent, nan2, Options()))
    assert code == COLLAPSED_FOCAL
    assert "deg of view" in _implausible_text(code, np.array([20.0, 20.0, 320.0, 240.0]), outs)
    for f, ok in ((0.45 * extent, False), (0.55 * extent, True), (700.0, True)):
        assert determined([f, f, 320.0, 240.0]).all() == ok, f
    # a principal point outside the image, when its size is known
    assert determined([700.0, 700.0, 700.0, 240.0]).all()
    assert not determined([700.0, 700.0, 700.0, 240.0], jnp.array([640.0, 480.0])).any()
    # a field of view above 120 deg across a 640 px image (f < 184.75 px) is no lens
    # without distortion, whatever the outlines' extent (here 100 px)
    small = [100 * np.stack([np.cos(t), np.sin(t)], 1) for t in [np.linspace(0, 2 * np.pi, 50)]]
    for f, bad in ((180.0, True), (190.0, False)):
        est = np.array([f, f, 320.0, 240.0])
        code = int(implausible(jnp.asarray(est), 200.0, jnp.array([640.0, 480.0]), Options()))
        assert (code == WIDE_FOV) == bad, (f, code)
        assert not bad or "field of view" in _implausible_text(code, est, small, (640, 480))
        assert int(implausible(jnp.asarray(est), 200.0, nan2, Options())) == PLAUSIBLE
