"""Homologies passed to calibrate(homologies=...) are checked against their outlines:
each must map its outline onto itself as well as its own fit did (issue 42)."""

import dataclasses
import math
import warnings

import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax._calibration_checks import _check_homologies
from sorjax._homology import homology_residual


@pytest.fixture(scope="module")
def cameras():
    """The two-sphere scene at f = 800 px with paper noise of 1 px, and the same noisy
    views seen by a camera with f = 1400 px (same outline size and place), each with
    its outlines' homologies."""
    out = {}
    for f in (800.0, 1400.0):
        sc = scenes.two_spheres(f=f)
        outs = [scenes.paper_noise(o, 1.0, 20 + i) for i, o in enumerate(sc.outlines)]
        out[f] = (sc, outs, tuple(sorjax.fit_homology(o) for o in outs))
    return out


def _outlines(outs):
    return [sorjax.make_outline(o) for o in outs]


def test_a_homology_fitted_on_its_outline_gives_back_its_own_residual(cameras):
    """The residual the check reads is the fit's own (the same samples: as many as the
    fit's inliers), robust trimming included."""
    _, outs, homs = cameras[800.0]
    np.testing.assert_allclose(homology_residual(outs, homs), [float(h.rms) for h in homs], rtol=1e-6)
    o = np.array(outs[0], float)
    c = o.mean(0)
    k = slice(len(o) // 8, len(o) // 8 + len(o) // 40)
    o[k] = c + (o[k] - c) * 1.03  # a bump 3 % out: trimmed by the robust fit
    bump = sorjax.fit_homology(o)
    assert bump.trimmed > 0.02
    np.testing.assert_allclose(homology_residual([o], [bump]), [float(bump.rms)], rtol=1e-6)
    # and the same outline started elsewhere gives about the same residual
    rolled = sorjax.fit_homology(np.roll(outs[2], 333, axis=0))
    assert abs(homology_residual([outs[2]], [rolled])[0] / float(rolled.rms) - 1.0) < 0.2


def test_matched_homologies_pass_and_give_the_same_K(cameras):
    _, outs, homs = cameras[800.0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = sorjax.calibrate(outs)
        given = sorjax.calibrate(outs, homologies=homs)
    assert own.success and given.success, given.message
    np.testing.assert_allclose(np.asarray(given.K), np.asarray(own.K), rtol=1e-9)
    np.testing.assert_allclose(given.std, own.std, rtol=1e-9)


def test_homologies_of_another_camera_are_refused_naming_the_view(cameras):
    """Fits from a camera with f = 1400 px passed with the outlines of one with f =
    800 px: before, IIb took f = 1400 from them (success, no std); now refused."""
    _, outs, _ = cameras[800.0]
    _, _, other = cameras[1400.0]
    for method in ("IIb", "bundle"):
        with pytest.raises(ValueError, match=r"^view 0: homologies\[0\] does not map its outline onto itself") as e:
            sorjax.calibrate(outs, method=method, homologies=other)
    msg = str(e.value)
    assert "Homology.rms" in msg and "options.homology_ratio = 1.5" in msg
    assert "pass the homologies fitted on these outlines" in msg and "homologies=None" in msg
    assert "\n" not in msg


@pytest.mark.parametrize("swap", ["camera", "order"])
def test_a_single_wrong_view_is_named_by_its_index(cameras, swap):
    _, outs, homs = cameras[800.0]
    _, _, other = cameras[1400.0]
    given = (homs[0], other[1], homs[2]) if swap == "camera" else (homs[0], homs[2], homs[1])
    with pytest.raises(ValueError, match=r"^view 1: homologies\[1\] does not map") as e:
        sorjax.calibrate(outs, homologies=given)
    r = homology_residual(outs, given)
    assert f"under it is {r[1]:.3g} px" in str(e.value)
    assert f"against {float(given[1].rms):.3g} px for the outline it was fitted on" in str(e.value)


def test_homology_ratio_option_just_inside_and_outside(cameras):
    """``Options.homology_ratio``: refused just above the measured ratio, passed just
    below it; inf switches the check off."""
    _, outs, homs = cameras[800.0]
    _, _, other = cameras[1400.0]
    given = (homs[0], other[1], homs[2])
    q = homology_residual(outs, given)[1] / float(given[1].rms)
    assert q > 1.5
    o = _outlines(outs)
    base = sorjax.Options()
    assert _check_homologies(given, 3, o, dataclasses.replace(base, homology_ratio=q * 1.001)) == given
    assert _check_homologies(given, 3, o, dataclasses.replace(base, homology_ratio=math.inf)) == given
    with pytest.raises(ValueError, match=r"^view 1: .*options.homology_ratio = "):
        _check_homologies(given, 3, o, dataclasses.replace(base, homology_ratio=q * 0.999))
    # the floor: a homology fitted on an exact outline (rms ~ 1e-9 px) is judged at
    # check_floor_px at least
    sc = cameras[800.0][0]
    exact = sorjax.fit_homology(sc.outlines[0])
    assert float(exact.rms) < 1e-6
    _check_homologies((exact,) + homs[1:], 3, _outlines([sc.outlines[0]] + outs[1:]), base)
    with pytest.raises(ValueError, match=r"^view 0: .*check_floor_px = 0.001 px"):
        _check_homologies((exact,) + homs[1:], 3, o, base)  # the exact fit with the noisy outline: 1 px noise
