import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax.core._camera import (
    angle_between_planes,
    intrinsics_from_omega_vector,
    intrinsics_matrix,
    normalising_transform,
    omega_matrix,
    omega_vector_from_intrinsics,
    transform_points,
)


@pytest.mark.parametrize("fu,fv,u0,v0", [(700.0, 700.0, 320.0, 240.0), (1400.0, 1330.0, 300.5, 260.25)])
def test_omega_roundtrip_matches_definition(fu, fv, u0, v0):
    K = np.asarray(intrinsics_matrix(fu, fv, u0, v0))
    omega_def = np.linalg.inv(K).T @ np.linalg.inv(K)
    omega = np.asarray(omega_matrix(omega_vector_from_intrinsics(fu, fv, u0, v0)))
    np.testing.assert_allclose(omega, omega_def, rtol=1e-12, atol=1e-18)
    for scale in (1.0, -3.7, 1e-6):  # omega is defined up to scale, sign included
        w = scale * omega_vector_from_intrinsics(fu, fv, u0, v0)
        est = intrinsics_from_omega_vector(w)
        np.testing.assert_allclose([float(x) for x in est[:4]], [fu, fv, u0, v0], rtol=1e-10)
        assert bool(est[4])


def test_not_positive_definite_gives_nan_and_flag():
    w = omega_vector_from_intrinsics(700.0, 700.0, 320.0, 240.0)
    w = w.at[4].set(0.5 * (w[1] ** 2 / w[0] + w[3] ** 2 / w[2]))  # lam < 0
    fu, fv, u0, v0, ok = intrinsics_from_omega_vector(w)
    assert not bool(ok)
    assert np.isnan(float(fu)) and np.isnan(float(fv))
    # jit and vmap give the same answers as eager
    ws = jnp.stack([w, omega_vector_from_intrinsics(800.0, 810.0, 300.0, 200.0)])
    out = jax.jit(jax.vmap(intrinsics_from_omega_vector))(ws)
    assert [bool(x) for x in out[4]] == [False, True]
    np.testing.assert_allclose(float(out[0][1]), 800.0, rtol=1e-12)


def test_normalisation_maps_K_omega_lines_consistently():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 640, size=(200, 2))
    T = normalising_transform(pts)
    pn = np.asarray(transform_points(T, pts))
    np.testing.assert_allclose(pn.mean(0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sqrt(np.mean(np.sum(pn**2, 1))), np.sqrt(2.0), rtol=1e-12)
    K = np.asarray(intrinsics_matrix(700.0, 650.0, 330.0, 250.0))
    Kn = T @ K  # upper triangular with zero skew: the similarity keeps the form
    assert abs(Kn[0, 1]) < 1e-15 and abs(Kn[1, 0]) < 1e-15
    omega = np.linalg.inv(K).T @ np.linalg.inv(K)
    omega_n = np.linalg.inv(Kn).T @ np.linalg.inv(Kn)
    np.testing.assert_allclose(T.T @ omega_n @ T, omega, rtol=1e-10)
    # a line through two points stays through their images
    x, y = np.r_[pts[0], 1], np.r_[pts[1], 1]
    ln = np.linalg.solve(T.T, np.cross(x, y))
    assert abs(ln @ (T @ x)) < 1e-9 and abs(ln @ (T @ y)) < 1e-9


def test_plane_angle_detects_offset_and_direction():
    K = np.asarray(intrinsics_matrix(700.0, 700.0, 320.0, 240.0))
    l = np.array([1.0, 0.0, -320.0])
    assert float(angle_between_planes(K, l, l * -2.0)) < 1e-6
    shifted = np.array([1.0, 0.0, -327.0])  # 7 px at f = 700 is ~0.57 degrees
    np.testing.assert_allclose(float(angle_between_planes(K, l, shifted)), np.degrees(np.arctan(7 / 700)), rtol=1e-9)
