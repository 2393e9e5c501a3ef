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
