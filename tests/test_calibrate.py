"""calibrate(): Methods I / IIa / IIb and the bundle against ground truth, bad input."""

import functools
import math

import numpy as np
import pytest

import sorjax
from sorjax import scenes


@pytest.fixture(scope="module")
def spheres():
    sc = scenes.two_spheres(f=700.0)
    homs = tuple(sorjax.fit_homology(o) for o in sc.outlines)
    return sc, homs


def rel_err(cal, K):
    return np.abs(np.array([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]])) / K[1, 1]


@pytest.mark.parametrize("method", ["I", "IIa", "IIb", "bundle"])
def test_noise_free_two_spheres(spheres, method):
    sc, homs = spheres
    cal = sorjax.calibrate(sc.outlines, method=method, homologies=homs)
    assert cal.success, cal.message
    assert rel_err(cal, sc.K).max() < 1e-4  # 0.01 % of f
    assert cal.method == method


def test_known_aspect_ratio_methods_I_and_IIb():
    sc = scenes.two_spheres(f=800.0, aspect_ratio=1.05)
    homs = tuple(sorjax.fit_homology(o) for o in sc.outlines)
    for m in ("I", "IIb", "bundle"):
        cal = sorjax.calibrate(sc.outlines, method=m, aspect_ratio=1.05, homologies=homs)
        assert cal.success
        assert rel_err(cal, sc.K).max() < 1e-4, (m, rel_err(cal, sc.K))
        np.testing.assert_allclose(cal.fu / cal.fv, 1.05, rtol=1e-12)
    wrong = sorjax.calibrate(sc.outlines, method="IIb", homologies=homs)  # unit aspect: biased
    assert rel_err(wrong, sc.K).max() > 1e-3
    free = sorjax.calibrate(sc.outlines, method="IIa", homologies=homs)  # free aspect recovers it
    assert rel_err(free, sc.K).max() < 1e-4


def test_noisy_ordering_and_bundle_uncertainty(spheres):
    """With noise the bundle is at least as good as IIb here and reports a std."""
    sc, _ = spheres
    outs = [scenes.paper_noise(o, 1.0, 10 + i) for i, o in enumerate(sc.outlines)]
    cal_b = sorjax.calibrate(outs)
    assert cal_b.method == "bundle" and cal_b.success
    assert np.all(np.isfinite(cal_b.std)) and np.all(cal_b.std > 0)
    assert rel_err(cal_b, sc.K).max() < 0.05
    assert np.all(np.asarray(cal_b.view_rms) < 1.0)


@pytest.mark.filterwarnings("ignore:weak geometry")
def test_outline_noise_is_a_floor_of_the_noise_level_not_of_the_estimate(spheres):
    """``outline_noise`` (an averaged outline's noise, which its residuals no longer
    show) raises the noise level the standard deviations and checks are taken at, and
    only where it exceeds a view's residuals; the estimate does not move.  An
    ImageOutline's ``noise_rms`` attribute says the same."""
    from sorjax._detect import ImageOutline

    sc, _ = spheres
    outs = [scenes.paper_noise(o, 1.0, 10 + i) for i, o in enumerate(sc.outlines)]
    # (no declared outline error: its offset's share of the std does not scale with the noise)
    calibrate = functools.partial(sorjax.calibrate, outline_error=0.0)
    base = calibrate(outs)
    below = calibrate(outs, outline_noise=0.01)  # under every view's residual: no change
    np.testing.assert_array_equal(np.asarray(below.K), np.asarray(base.K))
    np.testing.assert_array_equal(below.std, base.std)
    floor = 4.0 * float(np.max(base.view_rms))
    high = calibrate(outs, outline_noise=[floor] + [float("nan")] * (len(outs) - 1))
    own = calibrate([ImageOutline(outs[0], noise_rms=floor), *outs[1:]])
    for cal in (high, own):
        np.testing.assert_allclose(np.asarray(cal.K), np.asarray(base.K), rtol=1e-12)
        ratio = cal.std / base.std
        # view 0's residual sum of squares raised 16-fold or more, the others' kept:
        # about sqrt(18 / 3) = 2.4 for three equal views
        assert np.all(ratio > 2.0) and np.all(ratio < 4.0), ratio
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-9)  # one level for all
    np.testing.assert_array_equal(own.std, high.std)
    # the floor's own correlation length (outline_noise_ell, ImageOutline.noise_ell):
    # the view's noise model takes it where the floor binds; K stays
    nan = [float("nan")] * (len(outs) - 1)
    for L in (0.5, 12.0):
        given = calibrate(outs, outline_noise=[floor] + nan, outline_noise_ell=[L] + nan)
        attr = calibrate([ImageOutline(outs[0], noise_rms=floor, noise_ell=L), *outs[1:]])
        np.testing.assert_allclose(np.asarray(given.K), np.asarray(base.K), rtol=1e-12)
        np.testing.assert_array_equal(attr.std, given.std)
        assert not np.allclose(given.std, high.std, rtol=0.02), (L, given.std, high.std)
    short = calibrate(outs, outline_noise=[floor] + nan, outline_noise_ell=[0.5] + nan)
    long = calibrate(outs, outline_noise=[floor] + nan, outline_noise_ell=[12.0] + nan)
    assert np.all(short.std < long.std)  # noise correlated over longer arcs averages out less
    with pytest.raises(ValueError, match="outline_noise_ell"):
        sorjax.calibrate(outs, outline_noise=floor, outline_noise_ell=[1.0, 2.0])
    with pytest.raises(ValueError, match="outline_noise_ell"):
        sorjax.calibrate(outs, outline_noise=floor, outline_noise_ell="long")
    # with the outline error measured from the outlines, a floor counts as the residual
    # the outline would show
    measured = sorjax.calibrate(outs, outline_error="measured", outline_noise=2.0)
    np.testing.assert_allclose(measured.outline_error, 2.0, rtol=1e-12)
    # the core: a floor per outline or one number, nothing else
    from sorjax import core

    pts = np.stack([np.asarray(sorjax.make_outline(o).points) for o in outs])
    with pytest.raises(ValueError, match="noise must be one floor"):
        core.calibrate_homologies(pts, None, noise=np.ones(len(outs) + 1))
    with pytest.raises(ValueError, match="noise_ell must be one correlation length"):
        core.calibrate_homologies(pts, None, noise=1.0, noise_ell=np.ones((len(outs), 2)))


def test_result_code_when_not_positive_definite(spheres):
    sc, homs = spheres
    # two views only, and one of them mirrored: inconsistent with any real camera
    flipped = sc.outlines[1].copy()
    flipped[:, 0] = 2 * 320 - flipped[:, 0]
    cal = sorjax.calibrate([sc.outlines[0], flipped], method="IIa")
    if not cal.success:
        assert "positive definite" in cal.message
        assert np.isnan(cal.fu)
        with pytest.raises(sorjax.CalibrationError):
            sorjax.calibrate([sc.outlines[0], flipped], method="IIa", throw=True)


@pytest.mark.parametrize(
    "outlines, words",
    [
        ([np.random.default_rng(0).normal(size=(50, 2))], "a list of outlines"),
        ("not outlines", "got str"),
        ([], "at least two"),
    ],
)
def test_bad_calls(outlines, words):
    with pytest.raises(ValueError, match=words):
        sorjax.calibrate(outlines[0] if isinstance(outlines, list) and len(outlines) == 1 else outlines)


def test_single_view_and_bad_points(spheres):
    sc, _ = spheres
    with pytest.raises(ValueError, match="at least two"):
        sorjax.calibrate([sc.outlines[0]])
    bad = sc.outlines[1].copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="outline 1.*NaN"):
        sorjax.calibrate([sc.outlines[0], bad])
    with pytest.raises(ValueError, match="method"):
        sorjax.calibrate(sc.outlines, method="III")
    with pytest.raises(ValueError, match="aspect_ratio"):
        sorjax.calibrate(sc.outlines, method="IIb", aspect_ratio=-1.0)
    with pytest.raises(ValueError, match="IIa"):
        sorjax.calibrate(sc.outlines, method="IIa", aspect_ratio=1.1)


def test_conic_views_are_dropped_with_a_reason(spheres):
    sc, homs = spheres
    t = np.linspace(0, 2 * np.pi, 800, endpoint=False)
    ellipse = np.stack([300 + 90 * np.cos(t + 0.3), 200 + 60 * np.sin(t)], 1)  # a sphere's outline
    h = sorjax.fit_homology(ellipse)
    assert h.is_conic and float(h.conic_rms) < 1e-3
    assert not homs[0].is_conic and float(homs[0].conic_rms) > 1.0
    with pytest.warns(UserWarning, match="view 1: the outline is a conic"):
        cal = sorjax.calibrate([sc.outlines[0], ellipse, sc.outlines[1], sc.outlines[2]], method="IIb")
    assert cal.used == (0, 2, 3) and cal.success
    assert rel_err(cal, sc.K).max() < 1e-4
    with pytest.warns(UserWarning, match="conic"):
        few = sorjax.calibrate([sc.outlines[0], ellipse])
    assert not few.success and "Fewer than two views" in few.message and np.isnan(few.fu)
    with pytest.raises(sorjax.CalibrationError), pytest.warns(UserWarning):
        sorjax.calibrate([sc.outlines[0], ellipse], throw=True)


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(outline_error=-0.1), "outline_error must be a finite number of pixels >= 0"),
        (dict(outline_error=float("nan")), "outline_error"),
        (dict(outline_error="0.1"), "outline_error"),
        (dict(image_size=(640,)), r"image_size must be \(width, height\)"),
        (dict(image_size=(640, -480)), "image_size"),
        (dict(image_size=(640.5, 480)), "image_size"),
        (dict(outline_noise=-1.0), "outline_noise must be a finite number of pixels >= 0"),
        (dict(outline_noise="0.5"), "outline_noise"),
        (dict(outline_noise=[0.5, 0.5]), "outline_noise: got 2 values for 3 outlines"),
    ],
)
def test_bad_outline_error_and_image_size(spheres, kw, words):
    sc, homs = spheres
    with pytest.raises(ValueError, match=words):
        sorjax.calibrate(sc.outlines, homologies=homs, **kw)


def test_readme_first_example_runs():
    """The README's first Python example (synthetic scene -> homology -> calibrate ->
    predicted error) runs as written: the public API it shows still exists."""
    import contextlib
    import warnings
    import io
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = re.findall(r"```python\n(.*?)```", readme, re.S)[0]
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ns: dict = {}
        exec(compile(block, "README.md", "exec"), ns)
    cal = ns["cal"]
    assert cal.success and abs(cal.fv - 700.0) < 3 * cal.std[1]


def _systematic(o, amp_px, rng):
    """``o`` moved along its normals by a smooth, asymmetric error of ``amp_px`` px RMS
    (three low harmonics of the angle about the centroid: segmentation that leaks and
    shrinks, unlike noise)."""
    c = o.mean(0)
    th = np.arctan2(o[:, 1] - c[1], o[:, 0] - c[0])
    t = np.roll(o, -1, 0) - np.roll(o, 1, 0)
    n = np.column_stack([t[:, 1], -t[:, 0]]) / np.linalg.norm(t, axis=1)[:, None]
    k, ph, a = rng.integers(1, 4, size=3), rng.uniform(0, 2 * np.pi, 3), rng.normal(0, 1, 3)
    d = sum(a[i] * np.cos(k[i] * th + ph[i]) for i in range(3))
    return o + (amp_px / np.sqrt(np.mean(d**2)) * d)[:, None] * n


def test_measured_outline_error_refuses_a_confident_wrong_focal_length():
    """Outlines with ~1 px of systematic error (per-view symmetry residuals 0.04 to 1.1 px): with the
    default outline_error (0.1 px) the bundle reported fu 795 +- 42 px for a true 1000
    (4.9 std off) while its covariance took the residuals for noise correlated only
    between neighbours and mirror pairs; the outline noise model (a correlation length
    estimated from the residuals: the smooth misfit reads as long-correlated noise)
    gives 795 +- 94 px, within 3 std.  With the error measured from the residuals it is
    refused (or within its std).  Seeded (seed 4 of random_sor_scene)."""
    import warnings

    sc = scenes.random_sor_scene(4, 4, K=scenes.intrinsics(1000.0, principal_point=(330.0, 250.0)))
    rng = np.random.default_rng(4)
    outs = [_systematic(o, 1.0, rng) for o in sc.outlines]
    homs = tuple(sorjax.fit_homology(o) for o in outs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = sorjax.calibrate(outs, homologies=homs)
    assert not default.success or abs(default.fu - 1000.0) <= 3 * default.std[0]  # no longer confidently wrong
    with pytest.warns(UserWarning, match=r"outline error 0.6 px, measured from the outlines: the RMS of the 4 kept "
                                         r"views' symmetry residuals \(0.041 to 1.1 px"):
        cal = sorjax.calibrate(outs, homologies=homs, outline_error="measured")
    rms = np.array([float(h.rms) for h in homs])
    assert cal.outline_error == pytest.approx(np.sqrt(np.mean(rms**2)))
    assert any("measured from the outlines" in n for n in cal.notes)
    e = np.abs(np.array([cal.fu, cal.fv, cal.u0, cal.v0]) - np.array([1000.0, 1000.0, 330.0, 250.0]))
    assert not cal.success or np.all(e <= 3 * cal.std)
    assert not cal.success and "too little perspective" in cal.details
    # an extractor's own per-outline estimates raise a view's error where larger
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        per = sorjax.calibrate(outs, homologies=homs, outline_error=[0.0, 2.0, 0.0, 0.0])
    e2 = rms.copy()
    e2[1] = 2.0
    assert per.outline_error == pytest.approx(np.sqrt(np.mean(e2**2)))
    assert any("symmetry residuals and own error estimates" in n for n in per.notes)

    class Carrying(np.ndarray):  # an extractor's outline array with its own error estimate
        outline_error = float("nan")

    carried = [o.view(Carrying) for o in outs]
    carried[1].outline_error = 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = sorjax.calibrate(carried, homologies=homs, outline_error="measured")
    assert own.outline_error == pytest.approx(per.outline_error)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nan = sorjax.calibrate(outs, homologies=homs, outline_error=[float("nan")] * 4)
    assert nan.outline_error == pytest.approx(cal.outline_error)
    for bad in ("measure", [0.1, -1.0, 0.1, 0.1], [0.1, 0.1], [[0.1]], True, float("nan")):
        with pytest.raises(ValueError, match="outline_error"):
            sorjax.calibrate(outs, homologies=homs, outline_error=bad)


def _measured(outs, **options):
    """``calibrate(outs, outline_error="measured")`` (the image path) on a 640x480
    image (``options``: fields of :class:`sorjax.Options`), and its warnings' texts."""
    import warnings

    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        cal = sorjax.calibrate(outs, outline_error="measured", image_size=(640, 480),
                               options=sorjax.Options(**options))
    return cal, [str(w.message) for w in ws]


def _good_views(n=5):
    """``n`` views of a camera with f = 600 px, principal point (330, 250), with 0.05 px
    of noise (random_sor_scene seed 0, noise seed 0), and the truth (fu, fv, u0, v0)."""
    K = scenes.intrinsics(600.0, principal_point=(330.0, 250.0))
    rng = np.random.default_rng(0)
    good = [o + rng.normal(0, 0.05, o.shape) for o in scenes.random_sor_scene(0, n, K=K).outlines]
    return good, np.array([600.0, 600.0, 330.0, 250.0])


def test_measured_outlines_survive_leaving_out_a_view():
    """Outlines of measured quality (outline_error="measured", the image path) are
    checked by leaving out each view (jackknife): five views of a camera with f = 600 px
    (0.05 px noise) stay determined, with the leave-one-out spread in their std; two
    symmetric outlines of another camera (f = 450 px, a stand-in for clutter taken for
    objects) among them gave fu 570 +- 12 px for the true 600 (5 % off) without the
    check, and leave the focal length undetermined with it.  Seeded (random_sor_scene
    seeds 0 and 100)."""
    good, truth = _good_views()
    other = scenes.random_sor_scene(100, 2, K=scenes.intrinsics(450.0, principal_point=(330.0, 250.0))).outlines
    cal, ws = _measured(good)
    assert cal.success and any("leave-one-view-out check" in w for w in ws)
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    assert np.all(np.abs(est - truth) <= 3 * cal.std) and abs(cal.fv - 600.0) < 0.01 * 600.0
    cal, ws = _measured(good + list(other))
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    assert not cal.success and np.all(np.isnan(est[:2]))
    assert any("not determined: with outlines of measured quality" in w for w in ws)
    det = np.isfinite(est)
    assert np.all(np.abs(est - truth)[det] <= np.minimum(3 * cal.std[det], 0.05 * 600.0))


def test_measured_outlines_leave_out_the_view_the_consistency_check_blames():
    """With outlines of measured quality (the image path) a view that holds most of the
    consistency check's score (an outline of another camera here, f = 300 px among five
    views of f = 600 px: a stand-in for a symmetric false detection) is left out and the
    camera calibrated from the others: the same K as from the five views alone, within
    its std, with the view named in ``dropped`` and a warning.  Never below 3 views: two
    good views and the stranger stay refused.  Seeded (random_sor_scene seeds 0, 100)."""
    good, truth = _good_views()
    stranger = scenes.random_sor_scene(100, 1, K=scenes.intrinsics(300.0, principal_point=(200.0, 150.0))).outlines[0]
    alone, _ = _measured(good)
    cal, ws = _measured(good[:2] + [stranger] + good[2:])
    assert cal.success and cal.used == (0, 1, 3, 4, 5)
    assert cal.dropped == ((2, "inconsistent with the other views (91 % of the consistency score)"),)
    assert any(w.startswith("view 2 left out: the views were not consistent with one camera") for w in ws)
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    assert np.all(np.abs(est - truth) <= 3 * cal.std) and abs(cal.fv - 600.0) < 0.01 * 600.0
    np.testing.assert_allclose(est, [alone.fu, alone.fv, alone.u0, alone.v0], rtol=1e-6)
    np.testing.assert_allclose(cal.std, alone.std, rtol=1e-4)
    assert cal.outline_error == pytest.approx(alone.outline_error)
    few, ws = _measured(good[:2] + [stranger])
    assert not few.success and few.dropped == () and not any("left out:" in w for w in ws)


def test_measured_quality_options_by_their_effect():
    """``Options.measured_undetermined`` (the widened std's limit, a fraction of f),
    ``measured_leave_share`` and ``measured_leave_out`` reach the measured-quality runs:
    each just inside and just outside the value the calibration measured (the stranger
    of the test above holds 91 % of the consistency score)."""
    good, _ = _good_views()
    cal, _ = _measured(good)
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    ratio = np.max(cal.std / math.sqrt(est[0] * est[1]))
    assert _measured(good, measured_undetermined=ratio * (1 + 1e-6))[0].success
    out, ws = _measured(good, measured_undetermined=ratio * (1 - 1e-6))
    assert not out.success and any(f"at most {ratio * (1 - 1e-6):.3g} of the focal length" in w for w in ws)
    stranger = scenes.random_sor_scene(100, 1, K=scenes.intrinsics(300.0, principal_point=(200.0, 150.0))).outlines[0]
    views = good[:2] + [stranger] + good[2:]
    cal, _ = _measured(views)
    share = float(cal.dropped[0][1].split("(")[1].split(" %")[0]) / 100  # 91 %, as printed
    assert _measured(views, measured_leave_share=share - 0.01)[0].dropped[0][0] == 2
    kept, ws = _measured(views, measured_leave_share=share + 0.01)
    assert kept.dropped == () and not any("left out:" in w for w in ws)
    kept, ws = _measured(views, measured_leave_out=0)
    assert kept.dropped == () and not any("left out:" in w for w in ws)
