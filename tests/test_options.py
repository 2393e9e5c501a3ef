"""Every threshold of :class:`sorjax.Options` reaches the work through
``sorjax.calibrate(..., options=...)`` (and ``fit_homology(..., options=...)``), tested
by its effect: each threshold set just inside and just outside the value the
calibration measured, and the outcome flips exactly there (the decision, the warning
or the message a user sees).  The thresholds are traced, so every calibration here
runs the same compiled programs (three views of two spheres, padded to four).

Seeded: the scene is ``scenes.two_spheres(f=700)`` with ``paper_noise`` at 0.5 px,
seeds 10, 11, 12."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

import sorjax
from sorjax import Options, scenes
from sorjax._calibration import view_homologies
from sorjax._calibration_checks import _check_arguments

IN, OUT = 1.0 + 1e-6, 1.0 - 1e-6  # a threshold just above / just below a measured value


@pytest.fixture(scope="module")
def scene():
    sc = scenes.two_spheres(f=700.0)
    outs = [scenes.paper_noise(o, 0.5, 10 + i) for i, o in enumerate(sc.outlines)]
    homs = tuple(sorjax.fit_homology(o) for o in outs)
    return sc, outs, homs


def _cal(scene, **kw):
    """``(calibration, warnings)`` of the scene's outlines with its per-view fits."""
    _, outs, homs = scene
    kw.setdefault("homologies", homs)
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        cal = sorjax.calibrate(outs, **kw)
    return cal, [str(w.message) for w in ws]


@pytest.fixture(scope="module")
def base(scene):
    cal, ws = _cal(scene)
    assert cal.success and not ws, (cal.message, ws)
    return cal


def _est(cal):
    return np.array([cal.fu, cal.fv, cal.u0, cal.v0])


def _with(**kw):
    return dataclasses.replace(Options(), **kw)


def test_the_default_options_change_nothing(scene, base):
    cal, _ = _cal(scene, options=Options())
    np.testing.assert_array_equal(_est(cal), _est(base))
    np.testing.assert_array_equal(cal.std, base.std)


def test_undetermined(scene, base):
    """An intrinsic is determined when its std is at most ``undetermined`` of the focal
    length (each focal length of itself)."""
    est, std = _est(base), base.std
    ratio = np.max(std / np.array([est[0], est[1], *(2 * [math.sqrt(est[0] * est[1])])]))
    inside, _ = _cal(scene, options=_with(undetermined=ratio * IN))
    outside, _ = _cal(scene, options=_with(undetermined=ratio * OUT))
    assert inside.success and not outside.success
    assert "Not determined by these views" in outside.details


def test_weak_rel_std_and_residual_floor(scene, base):
    """The weak-geometry warning: the focal lengths' relative std (at a residual of at
    least ``residual_floor_px``) above ``weak_rel_std``."""
    est, std = _est(base), base.std
    ratio = max(std[0] / est[0], std[1] / est[1])
    _, ws_in = _cal(scene, options=_with(weak_rel_std=ratio * OUT))
    _, ws_out = _cal(scene, options=_with(weak_rel_std=ratio * IN))
    assert any(w.startswith("weak geometry") for w in ws_in) and not ws_out
    _, ws = _cal(scene, options=_with(residual_floor_px=1e3))
    assert any(w.startswith("weak geometry") and "of 1e+03 px" in w for w in ws)


def test_perspective_z_factor_and_outline_error(scene, base):
    """The focal length is determined only with evidence for perspective: ``z >=
    perspective_z`` and ``g >= perspective_factor * outline_error_px``."""
    z, g = base.perspective_z, base.perspective_px
    assert _cal(scene, options=_with(perspective_z=z * OUT))[0].success
    out, _ = _cal(scene, options=_with(perspective_z=z * IN))
    assert not out.success and "needs z >=" in out.details
    f = g / Options().outline_error_px
    assert _cal(scene, options=_with(perspective_factor=f * OUT))[0].success
    out, _ = _cal(scene, options=_with(perspective_factor=f * IN))
    assert not out.success and "outline_error" in out.details
    e = g / Options().perspective_factor
    assert _cal(scene, options=_with(outline_error_px=e * OUT))[0].success
    out, _ = _cal(scene, options=_with(outline_error_px=e * IN))
    assert not out.success and out.outline_error == pytest.approx(e * IN)
    # the argument, when given, wins over the field
    assert _cal(scene, outline_error=0.0, options=_with(outline_error_px=e * IN))[0].success


def test_min_focal_fraction_and_max_fov(scene, base):
    _, outs, _ = scene
    pts = np.concatenate([np.asarray(sorjax.make_outline(o).points) for o in outs])
    extent = float(np.max(pts.max(0) - pts.min(0)))
    frac = min(base.fu, base.fv) / extent
    assert _cal(scene, options=_with(min_focal_fraction=frac * OUT))[0].success
    out, _ = _cal(scene, options=_with(min_focal_fraction=frac * IN))
    assert not out.success and "would put outlines" in out.details
    size = (640, 480)
    fov = max(2 * math.degrees(math.atan(w / (2 * f))) for w, f in zip(size, (base.fu, base.fv)))
    assert _cal(scene, image_size=size, options=_with(max_fov_deg=fov * IN))[0].success
    out, _ = _cal(scene, image_size=size, options=_with(max_fov_deg=fov * OUT))
    assert not out.success and f"({fov * OUT:g} deg)" in out.details


def test_asymmetry_and_its_warning(scene, base):
    """A view is dropped when its RMS symmetry residual exceeds both ``asymmetry_px``
    and ``asymmetry_rel`` of its radius; a warning above ``warn_asymmetry_px``."""
    _, _, homs = scene
    rms = np.array([max(float(h.rms), float(h.rms_untrimmed)) for h in homs])
    worst = int(np.argmax(rms))
    kept, _ = _cal(scene, options=_with(asymmetry_px=rms[worst] * IN, asymmetry_rel=0.0))
    cut, ws = _cal(scene, options=_with(asymmetry_px=rms[worst] * OUT, asymmetry_rel=0.0))
    assert kept.used == (0, 1, 2) and [i for i, _ in cut.dropped] == [worst]
    assert any(w.startswith(f"view {worst}: the outline is not symmetric") for w in ws)
    kept, _ = _cal(scene, options=_with(asymmetry_px=0.0, asymmetry_rel=1.0))  # both must be exceeded
    assert kept.used == (0, 1, 2)
    _, ws = _cal(scene, options=_with(warn_asymmetry_px=rms[worst] * OUT))
    assert [w for w in ws if "high symmetry residual" in w] and ws[0].startswith(f"view {worst}:")
    assert not _cal(scene, options=_with(warn_asymmetry_px=rms[worst] * IN))[1]


def test_infinity_and_conic_verdicts(scene):
    """``infinity_z`` and ``conic_ratio`` / ``conic_floor_px`` judge the per-view fits
    (exactly at the measured value), and reach the calibration."""
    _, _, homs = scene
    h = homs[0]
    z = float(h.infinity_z)
    assert bool(view_homologies(homs, 100, _with(infinity_z=z * IN)).at_infinity[0])
    assert not bool(view_homologies(homs, 100, _with(infinity_z=z * OUT)).at_infinity[0])
    # every v_x at infinity: the focal length is then judged at a residual of at least
    # residual_floor_px (5 px here: determined with finite vertices, not with infinite ones)
    assert _cal(scene, options=_with(residual_floor_px=5.0))[0].success
    out, _ = _cal(scene, options=_with(infinity_z=1e9, residual_floor_px=5.0))
    assert not out.success and out.details.startswith("Every view's v_x is at infinity")
    floor = float(h.conic_rms) - Options().conic_ratio * float(h.rms)
    assert bool(view_homologies(homs, 100, _with(conic_floor_px=floor * IN)).is_conic[0])
    assert not bool(view_homologies(homs, 100, _with(conic_floor_px=floor * OUT)).is_conic[0])
    ratio = (float(h.conic_rms) - Options().conic_floor_px) / float(h.rms)
    assert bool(view_homologies(homs, 100, _with(conic_ratio=ratio * IN)).is_conic[0])
    assert not bool(view_homologies(homs, 100, _with(conic_ratio=ratio * OUT)).is_conic[0])
    out, ws = _cal(scene, options=_with(conic_floor_px=1e3))
    assert out.result == sorjax.RESULTS.too_few_views and all("is a conic" in w for w in ws)


def _rejected(cal) -> bool:
    """The model checks widened the std or refused the model."""
    from sorjax.core._checks import MODEL_OK

    return int(cal.checks.verdict) != MODEL_OK


def test_consistency_and_check_floor(scene, base):
    """The views' consistency: rejected at ``p < consistency_p`` unless the evidence
    is below ``check_floor_px``."""
    p = float(base.checks.consistency_p)
    assert 1e-4 < p < 1.0
    assert _cal(scene, options=_with(consistency_p=p * OUT))[0].success
    assert _rejected(_cal(scene, options=_with(consistency_p=p * IN))[0]) and not _rejected(base)
    px = float(base.checks.consistency_px)
    assert not _rejected(_cal(scene, options=_with(consistency_p=p * IN, check_floor_px=px * IN))[0])
    assert _rejected(_cal(scene, options=_with(consistency_p=p * IN, check_floor_px=px * OUT))[0])


def test_consistency_z(scene):
    """A known aspect ratio is contradicted at ``z >= consistency_z`` (the warning that
    names it; 1.02 is 10 std from the free fit's 0.999 here)."""
    known, _ = _cal(scene, aspect_ratio=1.02)
    z = float(known.checks.aspect_z)
    assert 5 < z < 20
    said = lambda ws: any(w.startswith("aspect_ratio=1.02 is not what the outlines show") for w in ws)  # noqa: E731
    assert said(_cal(scene, aspect_ratio=1.02, options=_with(consistency_z=z * OUT))[1])
    assert not said(_cal(scene, aspect_ratio=1.02, options=_with(consistency_z=z * IN))[1])


def test_duplicate_px(scene):
    """A view within ``duplicate_px`` RMS of an earlier one is the same view twice."""
    _, outs, homs = scene
    twice = list(outs) + [np.asarray(outs[0]) + 0.1]
    h4 = homs + (sorjax.fit_homology(twice[3]),)
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        same = sorjax.calibrate(twice, homologies=h4)
        other = sorjax.calibrate(twice, homologies=h4, options=_with(duplicate_px=0.01))
    assert [i for i, _ in same.dropped] == [3] and "the same outline as view 0" in same.dropped[0][1]
    assert other.used == (0, 1, 2, 3)


def test_noise_model_options_reach_the_covariance(scene):
    """``covariance_smooth_px`` and the range of correlation lengths move the std, not K
    (with no prior on the outlines' offset: its estimate reads the smoothed Jacobian,
    and moves K by a few 1e-5 relative with the default prior)."""
    ref, _ = _cal(scene, options=_with(outline_error_px=0.0))
    for kw in ({"covariance_smooth_px": 1.0}, {"noise_ell_max_px": 0.25}, {"noise_ell_min_px": 16.0}):
        cal, _ = _cal(scene, options=_with(outline_error_px=0.0, **kw))
        np.testing.assert_allclose(_est(cal), _est(ref), rtol=1e-9, err_msg=str(kw))
        assert np.max(np.abs(cal.std / ref.std - 1.0)) > 1e-3, kw


def test_focal_undetermined_for_one_view():
    """One view's focal length (principal point fixed) is determined when its std is at
    most ``focal_undetermined`` of itself (several views: ``undetermined``)."""
    import jax.numpy as jnp

    from sorjax.core._assess import assess

    est = jnp.array([700.0, 700.0, 320.0, 240.0])
    cov = jnp.diag(jnp.array([70.0, 70.0, 1.0, 1.0]) ** 2)  # 10 % of f at s = 1 px
    nan2 = jnp.array([jnp.nan, jnp.nan])

    def det(single, **kw):
        v = assess(est, cov, 1.0, 100.0, 300.0, nan2, False, False, True, _with(**kw), single)
        return bool(v.determined[1])

    assert det(True, focal_undetermined=0.1 * IN) and not det(True, focal_undetermined=0.1 * OUT)
    assert det(False, focal_undetermined=0.1 * OUT)  # not for several views


def test_per_view_fit_options(scene):
    """The per-view fit's thresholds and budgets: ``trim_k`` / ``trim_floor_px`` (an
    outline with a bump is trimmed; with either at infinity it is not),
    ``trim_rounds`` (0: as ``robust=False``), ``max_steps`` and ``n_samples`` (the
    arguments win over the fields)."""
    sc, outs, _ = scene
    o = np.array(outs[0], dtype=float)
    c = o.mean(0)
    k = slice(len(o) // 8, len(o) // 8 + len(o) // 40)
    o[k] = c + (o[k] - c) * 1.03  # a bump 3 % out: not symmetric, about 7 % of the samples trimmed
    h = sorjax.fit_homology(o)
    assert h.trimmed > 0.02
    for kw in ({"trim_k": math.inf}, {"trim_floor_px": 1e3}):
        assert sorjax.fit_homology(o, options=_with(**kw)).trimmed == 0.0, kw
    plain = sorjax.fit_homology(o, robust=False)
    no_rounds = sorjax.fit_homology(o, options=_with(trim_rounds=0))
    np.testing.assert_array_equal(np.asarray(no_rounds.v_x), np.asarray(plain.v_x))
    t = h.trimmed
    cal, ws = _cal(scene, homologies=(h,) + scene[2][1:], options=_with(note_trimmed=t * IN))
    assert not any("were left out of the fit" in w for w in ws)
    cal, ws = _cal(scene, homologies=(h,) + scene[2][1:], options=_with(note_trimmed=t * OUT))
    assert any(w.startswith("view 0:") and "were left out of the fit" in w for w in ws)
    cal, _ = _cal(scene, homologies=(h,) + scene[2][1:], options=_with(max_trimmed=t * OUT))
    assert [i for i, _ in cal.dropped] == [0] and "trimmed" in cal.dropped[0][1]
    cal, _ = _cal(scene, homologies=(h,) + scene[2][1:], options=_with(max_trimmed=t * IN))
    assert cal.used == (0, 1, 2)


def test_option_values_are_checked():
    """A bad options object or field is named in one ValueError, before any work."""
    args = ("bundle", None, "none", None, 2048, None, None, None, None)
    with pytest.raises(ValueError, match=r"options\.trim_k must be a real number"):
        _check_arguments(*args, _with(trim_k=math.nan))
    with pytest.raises(ValueError, match=r"options\.max_steps must be an integer >= 1"):
        _check_arguments(*args, _with(max_steps=0))
    with pytest.raises(ValueError, match="options must be a sorjax.Options"):
        _check_arguments(*args, {"trim_k": 1.0})
    with pytest.raises(ValueError, match=r"options\.outline_error_px must be a finite number of pixels"):
        _check_arguments(*args, _with(outline_error_px=-1.0))
    opts = _check_arguments(*args, _with(n_samples=64))[0]
    assert opts.n_samples == 64
    opts = _check_arguments("bundle", None, "none", 80, 2048, None, None, None, None, _with(n_samples=64))[0]
    assert opts.n_samples == 80  # the argument wins
    opts, err = _check_arguments(*args, _with(outline_error_px=0.3))[:2]
    assert err == 0.3 and opts.outline_error_px == 0.3
