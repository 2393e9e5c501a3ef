"""Property tests (hypothesis) of calibrate() on exact synthetic scenes.

Random surfaces of revolution (every named profile, perturbed), random poses (upright
and lying objects, any roll about the optical axis, anywhere in the image), aspect
ratios 0.9 to 1.1 and principal points off the image centre: the bundle recovers K to
1e-4 of f from noise-free outlines, does not depend on where an outline starts or
which way it runs, and a mirrored image gives the mirrored K.

Few examples, derandomised, so that the file runs in CI in well under a minute once
the solvers are compiled; experiments/degenerate.py runs the same properties over a
few hundred cases and prints the success rate.
"""

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sorjax
from sorjax import scenes

WIDTH, HEIGHT = 640, 480
TOL = 1e-4  # of f

PROPS = settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@st.composite
def cameras(draw):
    f = draw(st.floats(500.0, 1500.0))
    aspect = draw(st.floats(0.9, 1.1))
    du = draw(st.floats(-0.1, 0.1))
    dv = draw(st.floats(-0.1, 0.1))
    return scenes.intrinsics(f, aspect_ratio=aspect, principal_point=(WIDTH * (0.5 + du), HEIGHT * (0.5 + dv)))


@st.composite
def sor_scenes(draw, n_views: int = 3):
    """A random exact scene: drawn camera and profile; the poses (upright or lying with
    probability 1/2, any roll and elevation, anywhere in the image) from a drawn seed."""
    K = draw(cameras())
    shape = draw(st.sampled_from(sorted(scenes.PROFILES)))
    seed = draw(st.integers(0, 2**31 - 1))
    return scenes.random_sor_scene(seed, n_views, K=K, shapes=[shape], lying=True)


def calibrate_quietly(outlines, **kw):
    kw.setdefault("outline_error", 0.0)  # exact outlines
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="weak geometry")
        return sorjax.calibrate(outlines, **kw)


def k_error(cal, K) -> float:
    """Largest error of (fu, fv, u0, v0) in units of the true fv."""
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    true = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    return float(np.max(np.abs(est - true)) / K[1, 1])


@PROPS
@given(sc=sor_scenes())
def test_noise_free_recovery(sc):
    cal = calibrate_quietly(sc.outlines)
    assert cal.success, (sc.description, cal.message)
    assert cal.used == (0, 1, 2)
    assert k_error(cal, sc.K) < TOL, (sc.description, np.asarray(cal.K), sc.K)


@settings(PROPS, max_examples=3)
@given(sc=sor_scenes(), data=st.data())
def test_start_point_and_direction_do_not_matter(sc, data):
    ref = calibrate_quietly(sc.outlines)
    changed = []
    for o in sc.outlines:
        shift = data.draw(st.integers(0, len(o) - 1), label="shift")
        o = np.roll(o, shift, axis=0)
        changed.append(o[::-1] if data.draw(st.booleans(), label="reverse") else o)
    cal = calibrate_quietly(changed)
    assert cal.success and ref.success
    assert k_error(cal, sc.K) < TOL
    np.testing.assert_allclose(np.asarray(cal.K), np.asarray(ref.K), atol=TOL * sc.K[1, 1])


@settings(PROPS, max_examples=3)
@given(sc=sor_scenes())
def test_left_right_flip_gives_flipped_K(sc):
    flipped = []
    for o in sc.outlines:
        o = o.copy()
        o[:, 0] = WIDTH - 1 - o[:, 0]
        flipped.append(o)
    K_flip = sc.K.copy()
    K_flip[0, 2] = WIDTH - 1 - sc.K[0, 2]
    cal = calibrate_quietly(flipped)
    assert cal.success, cal.message
    assert k_error(cal, K_flip) < TOL, (np.asarray(cal.K), K_flip)


@pytest.mark.parametrize("method", ["IIa", "IIb"])
def test_linear_methods_on_one_random_scene(method):
    """Method II too (IIb with the true aspect ratio): exact outlines give K to 1e-4."""
    K = scenes.intrinsics(800.0, aspect_ratio=1.04, principal_point=(300.0, 255.0))
    sc = scenes.random_sor_scene(11, 3, K=K, lying=True)
    cal = calibrate_quietly(sc.outlines, method=method, aspect_ratio=None if method == "IIa" else 1.04)
    assert cal.success, cal.message
    assert k_error(cal, sc.K) < TOL
