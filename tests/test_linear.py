"""Methods I / IIa / IIb against exact homologies built from a known K.

Independent ground truth: in the camera frame (centre at the origin) an axis through
A0 with direction d gives n = d x A0, v_x = K n and l_s = K^-T n (pole-polar)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax.core._camera import normalising_transform
from sorjax.core._linear import method_i, method_ii, pole_polar_rows


def exact_views(K, n_views, rng):
    vs, ls = [], []
    for _ in range(n_views):
        A0 = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(1.5, 3.0)])
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        n = np.cross(d, A0)
        vs.append(K @ n)
        ls.append(np.linalg.solve(K.T, n))
    return np.array(vs), np.array(ls)


def normalised(K, v, l):
    pts = np.array([[0.0, 0.0], [640.0, 480.0]])
    T = normalising_transform(pts)
    return T, jnp.asarray(v @ T.T), jnp.asarray(l @ np.linalg.inv(T))


def K_from(T, fu, fv, u0, v0):
    Kn = np.array([[float(fu), 0, float(u0)], [0, float(fv), float(v0)], [0, 0, 1.0]])
    return np.linalg.inv(T) @ Kn


@pytest.mark.parametrize("seed", range(5))
def test_method_ii_exact(seed):
    rng = np.random.default_rng(seed)
    K = np.array([[rng.uniform(500, 1500), 0, rng.uniform(280, 360)], [0, 0, rng.uniform(200, 280)], [0, 0, 1.0]])
    K[1, 1] = K[0, 0] / rng.uniform(0.9, 1.1)
    v, l = exact_views(K, int(rng.integers(2, 6)), rng)
    T, vn, ln = normalised(K, v, l)
    fu, fv, u0, v0, ok, _ = method_ii(vn, ln, unit_aspect=False)
    assert bool(ok)
    np.testing.assert_allclose(K_from(T, fu, fv, u0, v0), K, atol=1e-7 * K[0, 0])


@pytest.mark.parametrize("seed", range(5))
def test_unit_aspect_methods_exact(seed):
    rng = np.random.default_rng(100 + seed)
    f = rng.uniform(500, 1500)
    K = np.array([[f, 0, rng.uniform(280, 360)], [0, f, rng.uniform(200, 280)], [0, 0, 1.0]])
    v, l = exact_views(K, int(rng.integers(2, 6)), rng)
    T, vn, ln = normalised(K, v, l)
    for est in (method_ii(vn, ln, unit_aspect=True)[:5], method_i(vn, ln)):
        assert bool(est[4])
        np.testing.assert_allclose(K_from(T, *est[:4]), K, atol=1e-7 * f)


def test_method_i_weighting_tames_a_view_with_a_far_vertex():
    """A view whose v_x lies ~5000 f away (the optical axis 0.01 deg from the plane
    through the revolution axis) has d(x0, l_s) of a fraction of a pixel: a principal
    point 0.01 px off moves its f_i = sqrt(d_v d_l) by percents.  Eq. 23's plain mean
    inherits that; the sensitivity-weighted mean does not.  Both are exact on exact
    homologies."""
    f = 800.0
    K = np.array([[f, 0, 330.0], [0, f, 250.0], [0, 0, 1.0]])
    # normals of the planes through each revolution axis and the camera centre:
    # three ordinary views (v_x about 1.4 f away) and one with the optical axis
    # within 0.01 deg of its plane
    n = np.array([[1.0, 0.0, 0.7], [np.cos(2.0), np.sin(2.0), 0.7], [np.cos(4.0), np.sin(4.0), 0.7], [1.0, 0.3, 2e-4]])
    v, l = n @ K.T, np.linalg.solve(K.T, n.T).T
    assert np.linalg.norm(v[3, :2] / v[3, 2] - K[:2, 2]) > 1000 * f
    T, vn, ln = normalised(K, v, l)
    for weighted in (True, False):
        est = method_i(vn, ln, weighted=weighted)
        np.testing.assert_allclose(K_from(T, *est[:4]), K, atol=1e-6 * f)
    # move view 0's vertex by 0.02 px across its l_x: the principal point moves
    vp = v.copy()
    vp[0, :2] += 0.02 * vp[0, 2] * np.array([-l[0, 1], l[0, 0]]) / np.linalg.norm(l[0, :2])
    T, vn, ln = normalised(K, vp, l)
    err = {}
    for weighted in (True, False):
        err[weighted] = abs(K_from(T, *method_i(vn, ln, weighted=weighted)[:4])[0, 0] - f) / f * 100
    assert err[True] < 0.01, err
    assert err[False] > 10 * err[True], err


def test_rows_are_the_papers_eqs_27_28():
    """Our rank-safe rows span the same constraints as eqs. 27-28."""
    rng = np.random.default_rng(3)
    v, l = rng.normal(size=(1, 3)), rng.normal(size=(1, 3))
    v1, v2, v3 = v[0]
    l1, l2, l3 = l[0]
    paper = np.array(
        [[v1 * l3, v3 * l3 - v1 * l1, 0, -v2 * l1, -v3 * l1], [0, v1 * l2, -v2 * l3, v2 * l2 - v3 * l3, v3 * l2]]
    )
    ours = np.asarray(pole_polar_rows(jnp.asarray(v), jnp.asarray(l)))
    # same row space: stacking adds no rank
    assert np.linalg.matrix_rank(np.vstack([paper, ours]), tol=1e-9) == 2
    # and ours keeps rank 2 where the paper's rows lose it (l3 = 0)
    l0 = l.copy()
    l0[0, 2] = 0.0
    assert np.linalg.matrix_rank(np.asarray(pole_polar_rows(jnp.asarray(v), jnp.asarray(l0))), tol=1e-9) == 2


def test_method_ii_not_positive_definite_reported():
    rng = np.random.default_rng(7)
    K = np.diag([700.0, 700.0, 1.0])
    K[:2, 2] = (320, 240)
    v, l = exact_views(K, 3, rng)
    T, vn, ln = normalised(K, v, l)
    # swap the vertices between views: inconsistent data
    out = method_ii(vn[::-1] + 0.3, ln, unit_aspect=False)
    if not bool(out[4]):
        assert np.isnan(float(out[0]))


def test_jit_and_vmap_over_trials_match_loop():
    rng = np.random.default_rng(11)
    K = np.array([[800.0, 0, 310], [0, 790.0, 250], [0, 0, 1]])
    batch = [normalised(K, *exact_views(K, 3, rng))[1:] for _ in range(4)]
    vb = jnp.stack([b[0] for b in batch])
    lb = jnp.stack([b[1] for b in batch])
    fn = jax.jit(jax.vmap(lambda v, l: method_ii(v, l, unit_aspect=False)[:4]))
    got = np.array(fn(vb, lb))
    loop = np.array([[float(x) for x in method_ii(v, l, unit_aspect=False)[:4]] for v, l in batch]).T
    np.testing.assert_allclose(got, loop, rtol=1e-10)
    gi = np.array(jax.jit(jax.vmap(lambda v, l: method_i(v, l)[:4]))(vb, lb))
    li = np.array([[float(x) for x in method_i(v, l)[:4]] for v, l in batch]).T
    np.testing.assert_allclose(gi, li, rtol=1e-10)
