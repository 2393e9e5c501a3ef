"""Fixed intrinsics in the style of OpenCV's flags (issue 18, items 2 and 3): the
principal point and / or the focal length held at known values, and the focal length
from a single view when the principal point is known.

Every test but the one with distortion shares one compiled program (the core with
fixed intrinsics, 4 padded views)."""

import warnings

import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._linear import focal_from_principal_point
from sorjax.core._calibrate import views_needed

CENTRE = (319.5, 239.5)  # OpenCV's image centre of a 640 x 480 image: ((w - 1) / 2, (h - 1) / 2)


def _calibrate(outlines, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sorjax.calibrate(outlines, outline_error=0.0, **kw)


@pytest.fixture(scope="module")
def spheres():
    return scenes.two_spheres(f=700.0, principal_point=CENTRE)


@pytest.fixture(scope="module")
def random_scene():
    return scenes.random_sor_scene(3, n_views=3, vary_aspect=True)


def _pp(K):
    return (float(K[0, 2]), float(K[1, 2]))


COMBOS = [  # (name, principal point fixed, focal length fixed, aspect ratio known)
    ("pp", True, False, False), ("pp+aspect", True, False, True),
    ("focal", False, True, False), ("focal+aspect", False, True, True),
    ("pp+focal", True, True, False), ("pp+focal+aspect", True, True, True),
]


@pytest.mark.parametrize("name,pp,focal,aspect", COMBOS, ids=[c[0] for c in COMBOS])
@pytest.mark.parametrize("which", ["two_spheres", "random"])
def test_every_fixed_combination_recovers_the_truth(which, name, pp, focal, aspect, spheres, random_scene):
    """Noise-free outlines, the fixed values at the truth: K within 0.01 % of f, the
    fixed entries exactly as given with a standard deviation of 0, the free ones with a
    finite positive one.  (A fixed focal length without a known aspect ratio takes 1:
    on the random scene with fu / fv != 1 the aspect ratio is passed.)"""
    sc = spheres if which == "two_spheres" else random_scene
    K = np.asarray(sc.K)
    a_true = K[0, 0] / K[1, 1]
    kw = {}
    if pp:
        kw["principal_point"] = _pp(K)
    if focal:
        kw["focal_length"] = float(K[1, 1])
    if aspect or (focal and abs(a_true - 1.0) > 1e-12):
        kw["aspect_ratio"] = float(a_true)
    cal = _calibrate(sc.outlines, **kw)
    assert cal.success, cal.message
    f = K[1, 1]
    np.testing.assert_allclose(np.asarray(cal.K), K, atol=1e-4 * f)
    std = cal.std
    held = np.array([focal, focal, pp, pp])
    assert np.all(std[held] == 0.0)
    assert np.all(np.isfinite(std[~held]) & (std[~held] > 0))
    if pp:
        assert cal.fixed_principal_point == _pp(K) and cal.principal_point.tolist() == list(_pp(K))
    if focal:
        assert cal.fixed_focal_length == f and cal.fv == f


def test_centre_principal_point_is_opencvs_image_centre(spheres):
    cal = _calibrate(spheres.outlines, principal_point="centre", image_size=spheres.image_size)
    assert cal.success and cal.fixed_principal_point == CENTRE
    np.testing.assert_allclose(cal.fv, 700.0, rtol=1e-4)


@pytest.mark.parametrize("view", [0, 1, 2])
def test_single_view_gives_the_focal_length(spheres, view):
    """One outline, the principal point at the truth: f within 0.01 % (the aspect ratio
    taken as 1), and the closed form of the seed agrees."""
    K = np.asarray(spheres.K)
    cal = _calibrate([spheres.outlines[view]], principal_point=_pp(K))
    assert cal.success, cal.message
    assert cal.aspect_ratio == 1.0 and cal.used == (0,)
    np.testing.assert_allclose([cal.fu, cal.fv], [700.0, 700.0], rtol=1e-4)
    v = spheres.views[view]
    f, ok = focal_from_principal_point(v.v_x[None], v.l_s[None], np.array([True]), np.array(_pp(K)), 1.0)
    assert bool(ok) and abs(float(f) - 700.0) < 1e-6 * 700.0


def test_single_view_with_vx_at_infinity_is_refused_with_the_reason():
    """The optical axis meets the revolution axis: v_x at infinity, l_s through the
    principal point, every focal length fits: RESULTS.degenerate naming the reason."""
    K = scenes.intrinsics(800.0, principal_point=(320.0, 240.0))
    prof = scenes.vase()
    sc = scenes.sor_scene(prof, K, [scenes.pose_at_pixel(prof, K, 25.0, 30.0)])
    assert abs(sc.views[0].v_x[2]) < 1e-9
    cal = _calibrate(sc.outlines, principal_point=(320.0, 240.0))
    assert not cal.success and cal.result == sorjax.RESULTS.degenerate
    assert "v_x is at infinity" in cal.message and "focal length is not determined" in cal.message
    assert np.isnan(cal.fu) and np.isnan(cal.fv) and cal.principal_point.tolist() == [320.0, 240.0]
    f, ok = focal_from_principal_point(sc.views[0].v_x[None], sc.views[0].l_s[None], np.array([True]),
                                       np.array([320.0, 240.0]), 1.0)
    assert not bool(ok)


def test_views_needed_depends_on_the_free_intrinsics():
    nan = np.nan
    assert int(views_needed(nan)) == 2 and int(views_needed(1.0)) == 2
    assert int(views_needed(1.0, np.array([nan, nan, 320.0, 240.0]))) == 1  # f only
    assert int(views_needed(nan, np.array([nan, nan, 320.0, 240.0]))) == 1  # fu, fv: exactly determined
    assert int(views_needed(1.0, np.array([nan, 700.0, nan, nan]))) == 2  # u0, v0: two roots from one view
    assert int(views_needed(nan, np.array([nan, nan, 320.0, nan]))) == 2


def test_validation_names_the_option_and_the_flag(spheres):
    o = spheres.outlines
    with pytest.raises(ValueError, match="needs image_size"):
        sorjax.calibrate(o, principal_point="centre")
    for bad in ("middle", (1.0,), (1.0, float("nan")), (True, 2.0), 3.0):
        with pytest.raises(ValueError, match="principal_point must be .*--principal-point"):
            sorjax.calibrate(o, principal_point=bad)
    for bad in (0.0, -5.0, float("inf"), True, "700"):
        with pytest.raises(ValueError, match="focal_length must be a positive .*--focal"):
            sorjax.calibrate(o, focal_length=bad)
    with pytest.raises(ValueError, match="bundle only"):
        sorjax.calibrate(o, method="IIb", principal_point=(1.0, 2.0))
    with pytest.raises(ValueError, match="at least two outlines.*--principal-point"):
        sorjax.calibrate(o[:1])


def test_command_line_fixed_parameters(tmp_path, spheres, capsys):
    from sorjax.cli import main

    f0 = tmp_path / "view0.npy"
    np.save(f0, spheres.outlines[0])
    assert main(["calibrate", str(f0), "--centre-principal-point"]) == 2
    assert "--centre-principal-point needs the image size" in capsys.readouterr().err
    assert main(["calibrate", str(f0), "--principal-point", "319.5", "239.5", "--outline-error", "0"]) == 0
    out = capsys.readouterr().out
    assert "u0 =    319.500 px  (fixed)" in out and "fv =    700.000 px" in out


def test_fixed_principal_point_with_distortion():
    """The bundle with k1 and the principal point held fixed (another compiled
    program): K and k1 back to the truth on a distorted noise-free scene."""
    sc = scenes.random_sor_scene(5, n_views=4, distortion=(-0.2, 0.0))
    K = np.asarray(sc.K)
    cal = _calibrate(sc.outlines, principal_point=_pp(K), distortion="k1")
    assert cal.success, cal.message
    np.testing.assert_allclose(np.asarray(cal.K), K, atol=5e-4 * K[1, 1])
    assert abs(float(cal.distortion[0]) + 0.2) < 1e-3 and cal.std[2] == 0.0
