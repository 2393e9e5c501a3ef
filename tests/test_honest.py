"""Every success with a finite std that covers its error (issue 42): the systematic
outline offset in the covariance (against finite differences of the estimate), the
linear methods' own covariance, their aspect check, masks' declared offset."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sorjax
from sorjax import scenes
from sorjax.core._checks import CULPRIT_VIEWS, MODEL_CONTRADICTED, MODEL_OK
from sorjax.core._linear import null_vector


def offset(o, d):
    """The closed outline ``o`` moved by ``d`` px along its outward normals."""
    o = np.asarray(o, float)
    t = np.roll(o, -1, 0) - np.roll(o, 1, 0)
    n = np.stack([t[:, 1], -t[:, 0]], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    area = 0.5 * np.sum(o[:, 0] * np.roll(o[:, 1], -1) - np.roll(o[:, 0], -1) * o[:, 1])
    return o + d * (n if area > 0 else -n)


def _k(cal):
    K = np.asarray(cal.K)
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


@pytest.fixture(scope="module")
def scene():
    K = scenes.intrinsics(1100.0, principal_point=(512.0, 384.0))
    return scenes.random_sor_scene(0, 3, K=K, image_size=(1024, 768))


def _cal(outs, offset_px=0.0, **kw):
    opts = sorjax.Options(outline_error_px=0.0, outline_offset_px=offset_px)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sorjax.calibrate(outs, image_size=(1024, 768), options=opts, **kw)


def test_the_bundle_estimates_a_shared_offset_and_removes_its_effect(scene):
    """Exact outlines all moved by ``d`` px along their normals (an eroded or dilated
    mask): with no offset declared the focal length follows ``d`` and lands many of
    its std off; declared (a prior of 1 px), the bundle estimates the offset (``d``
    within 0.05 px), its effect is gone from K, and K lies within 3
    std."""
    true = np.array([1100.0, 1100.0, 512.0, 384.0])
    moved = {}
    for d in (-1.0, 0.0, 1.0):
        outs = [offset(o, d) for o in scene.outlines]
        moved[d] = (_cal(outs), _cal(outs, 1.0))
    for d in (-1.0, 1.0):
        bare, declared = moved[d]
        assert bare.success and declared.success
        assert np.max(np.abs(_k(bare) - true)[:2] / bare.std[:2]) > 5
        assert np.all(np.abs(_k(declared) - true) <= 3 * declared.std)
        np.testing.assert_allclose(np.asarray(declared.outline_offset), d, atol=0.05)
        assert np.all(np.asarray(declared.outline_offset_std) < 0.1)
        undeclared_shift = np.abs(_k(bare) - _k(moved[0.0][0]))[:2]
        declared_shift = np.abs(_k(declared) - _k(moved[0.0][1]))[:2]
        assert np.all(undeclared_shift > 2.0) and np.all(declared_shift < 0.1 * undeclared_shift)
    assert np.all(np.isnan(np.asarray(_cal(list(scene.outlines), method="IIb").outline_offset)))


def test_the_model_checks_read_the_residuals_without_the_estimated_offset():
    """A shared offset of every outline (a mask eroded or dilated) is estimated by the
    bundle and taken out of the residuals the model checks read
    (``core._covariance.OutlineOffsets.refit``): it is no evidence against the camera (the
    views' consistency p-value rises from below 1e-4, evidence 1.8e-3 / 3.6e-3 px, which
    refused these, to above 0.1, evidence below 3e-4 px), while offsets that differ
    between views, which no shared offset explains, still make the views inconsistent
    and refuse the calibration."""
    K = scenes.intrinsics(1100.0, principal_point=(512.0, 384.0))
    sc = scenes.random_sor_scene(1, 3, K=K, image_size=(1024, 768))
    true = np.array([1100.0, 1100.0, 512.0, 384.0])
    for d in (1.0, -2.0):
        cal = _cal([offset(o, d) for o in sc.outlines], 1.0)
        assert cal.success and int(cal.checks.verdict) == MODEL_OK
        assert float(cal.checks.consistency_p) > 0.01 and float(cal.checks.consistency_px) < 5e-4
        assert np.all(np.abs(_k(cal) - true) <= 3 * cal.std)
        np.testing.assert_allclose(np.asarray(cal.outline_offset), d, atol=0.05)
    mixed = _cal([offset(o, d) for o, d in zip(sc.outlines, (1.0, -1.0, 1.0))], 1.0)
    assert not mixed.success and int(mixed.checks.verdict) == MODEL_CONTRADICTED
    assert int(mixed.checks.culprit) == CULPRIT_VIEWS and float(mixed.checks.consistency_px) > 1e-3


def test_a_linear_methods_offset_variance_is_its_change_per_px_squared(scene):
    """A linear method does not estimate the offset: its std includes the prior's
    effect, ``sigma^2 s^2`` with ``s`` its change per px of a shared offset (implicit
    differentiation through each view's fit and autodiff through the method), against
    central differences of the estimate itself (exact outlines: the noise's share is
    tiny)."""
    outs = list(scene.outlines)
    h, sigma = 0.25, 0.7
    base, wide = _cal(outs, method="IIb"), _cal(outs, sigma, method="IIb")
    assert base.success and wide.success
    np.testing.assert_allclose(_k(wide), _k(base), rtol=1e-12)  # the estimate does not move
    s = (_k(_cal([offset(o, h) for o in outs], method="IIb"))
         - _k(_cal([offset(o, -h) for o in outs], method="IIb"))) / (2 * h)
    assert np.all(np.abs(s[:2]) > 0.5)  # K moves by more than 0.5 px per px of offset here
    np.testing.assert_allclose(wide.std**2 - base.std**2, sigma**2 * s**2, rtol=0.1, atol=1e-3)


def test_outlines_traced_from_masks_carry_the_mask_offset(scene):
    """outlines_from_mask's outlines say what offset a mask may carry, and calibrate
    takes the largest as the offset's prior (as Options.outline_offset_px)."""
    import cv2

    mask = np.zeros((200, 300), np.uint8)
    cv2.ellipse(mask, (150, 100), (80, 50), 0, 0, 360, 255, -1)
    (o,) = sorjax.outlines_from_mask(mask)
    assert isinstance(o, sorjax.ImageOutline) and o.outline_offset == sorjax.MASK_OFFSET_PX
    outs = list(scene.outlines)
    plain = _cal(outs)
    tagged = _cal([sorjax.ImageOutline(outs[0], outline_offset=1.0), *outs[1:]])
    declared = _cal(outs, 1.0)
    np.testing.assert_array_equal(_k(tagged), _k(declared))
    np.testing.assert_array_equal(tagged.std, declared.std)
    assert np.all(tagged.std > plain.std)


def test_null_vector_derivative_matches_finite_differences():
    rng = np.random.default_rng(0)
    for m in (4, 6):  # fewer rows than columns (two views) and more
        A = jnp.asarray(rng.normal(size=(m, 5)))
        dA = jnp.asarray(rng.normal(size=(m, 5)))
        w, dw = jax.jvp(null_vector, (A,), (dA,))
        h = 1e-6
        fd = (null_vector(A + h * dA) * jnp.sign(null_vector(A + h * dA) @ w)
              - null_vector(A - h * dA) * jnp.sign(null_vector(A - h * dA) @ w)) / (2 * h)
        np.testing.assert_allclose(np.asarray(dw), np.asarray(fd), atol=1e-6)


@pytest.fixture(scope="module")
def noisy_spheres():
    sc = scenes.two_spheres(f=700.0)
    return sc, [scenes.paper_noise(o, 1.0, 10 + i) for i, o in enumerate(sc.outlines)]


@pytest.mark.parametrize("method", ["I", "IIa", "IIb"])
def test_linear_methods_report_a_finite_std(noisy_spheres, method):
    sc, outs = noisy_spheres
    cal = sorjax.calibrate(outs, method=method)
    assert cal.success
    assert np.all(np.isfinite(cal.std)) and np.all(cal.std > 0)
    err = np.abs(_k(cal) - np.array([700.0, 700.0, 320.0, 240.0]))
    assert np.all(err <= 3 * cal.std)


def test_method_iib_with_a_wrong_aspect_is_flagged_and_covered():
    """IIb takes fu / fv = 1; on a camera with 1.1 Method IIa's estimate puts 1 at
    z = 2.9 of its std: not confirmed (linear_aspect_z, just inside and just outside),
    a warning, and the std widens to cover the difference."""
    sc = scenes.two_spheres(f=800.0, aspect_ratio=1.1)
    outs = [scenes.paper_noise(o, 0.5, 20 + i) for i, o in enumerate(sc.outlines)]
    true = np.array([sc.K[0, 0], sc.K[1, 1], sc.K[0, 2], sc.K[1, 2]])
    with pytest.warns(UserWarning, match=r"aspect_ratio=1 is not what the outlines show.*Method IIa"):
        cal = sorjax.calibrate(outs, method="IIb")
    assert np.all(np.isfinite(cal.std))
    # every intrinsic reported (here fu's widened std is above a third of it: not
    # determined, NaN, and the result says so) lies within 3 std
    est = _k(cal)
    assert cal.success or cal.message
    assert np.all(np.isnan(est) | (np.abs(est - true) <= 3 * cal.std)) and np.any(np.isfinite(est))
    z = float(cal.checks.aspect_z)
    assert 2.0 < z < 4.0
    stds = []
    for factor, flagged in ((1 - 1e-6, True), (1 + 1e-6, False)):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            c = sorjax.calibrate(outs, method="IIb", options=sorjax.Options(linear_aspect_z=z * factor))
        assert any("aspect_ratio=1 is not what" in str(x.message) for x in w) == flagged
        stds.append(c.std)
    np.testing.assert_array_equal(stds[0], cal.std)
    assert np.all(stds[1][:2] < 0.5 * stds[0][:2])
    assert np.max(np.abs(_k(c) - true)[:2] / c.std[:2]) > 3  # unflagged: not covered
