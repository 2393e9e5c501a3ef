"""calibrate(distortion="k1"): the bundle with radial distortion through the public
entry point, against ground truth (issue 18), and its evidence gate."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import sorjax
from sorjax import scenes


@pytest.fixture(scope="module")
def distorted():
    return scenes.random_sor_scene(1801, 4, distortion=(-0.15, 0.0))


def test_k1_recovered_noise_free(distorted):
    sc = distorted
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal = sorjax.calibrate(list(sc.outlines), distortion="k1", outline_error=0.0)
    assert cal.success and cal.distortion_model == "k1"
    K = sc.K
    err = np.abs([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]]) / K[1, 1]
    assert err.max() < 5e-4, err  # 0.05 % of f
    assert abs(float(cal.distortion[0]) + 0.15) < 1e-3
    assert np.isfinite(cal.distortion_std).all()


def test_strong_distortion_past_wrong_linear_seeds():
    # k1 = -0.3 at f = 527 px (experiments/distortion.py's scene 1804): every linear
    # seed reads the distorted outlines as a pinhole's and lands at ~5x the true f, and
    # the distortion-free bundle runs off towards f -> infinity (not converged); the
    # bundle with k1 must still find the truth (from the fallback spread of focal
    # lengths) and report it, not refuse for the distortion-free fit's failure
    rng = np.random.default_rng(1804)  # distortion.py's scene_camera(1804)
    f = rng.uniform(450.0, 1100.0)
    K = scenes.intrinsics(f, principal_point=(320.0 + rng.uniform(-32.0, 32.0), 240.0 + rng.uniform(-24.0, 24.0)))
    sc = scenes.random_sor_scene(1804, int(rng.integers(3, 7)), K=K, distortion=(-0.3, 0.0))
    cal = sorjax.calibrate(list(sc.outlines), distortion="k1", aspect_ratio=1.0, outline_error=0.0)
    assert cal.success, cal.message
    err = np.abs([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]]) / K[1, 1]
    assert err.max() < 5e-4, err
    assert abs(float(cal.distortion[0]) + 0.3) < 1e-3


def test_undetermined_distortion_is_said_and_widened(distorted):
    # with the default outline error (0.1 px) the outlines cannot tell this much
    # distortion from a change of focal length: the distortion-free K comes back with
    # a std that covers the difference, NaN k1, and a warning naming the reason
    sc = distorted
    with pytest.warns(UserWarning, match="do not determine the radial distortion"):
        cal = sorjax.calibrate(list(sc.outlines), distortion="k1")
    assert np.isnan(np.asarray(cal.distortion)).all()
    K = sc.K
    e = np.array([cal.fu - K[0, 0], cal.fv - K[1, 1], cal.u0 - K[0, 2], cal.v0 - K[1, 2]])
    ok = np.isfinite(e)
    assert np.all(np.abs(e[ok]) <= 3 * np.asarray(cal.std)[ok])


def test_distortion_option_validated():
    sc = scenes.two_spheres(f=700.0)
    with pytest.raises(ValueError, match="distortion must be"):
        sorjax.calibrate(sc.outlines, distortion="k3")
    with pytest.raises(ValueError, match="bundle only"):
        sorjax.calibrate(sc.outlines, method="IIa", distortion="k1")
