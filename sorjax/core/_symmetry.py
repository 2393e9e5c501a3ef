"""The harmonic homology and eq. 20's symmetry residuals: the geometry every fit shares.

``W = I - 2 v l^T / (v^T l)`` maps an outline of a surface of revolution onto itself
(Wong, Mendonca and Cipolla 2003, eq. 3): ``l`` is the image of the revolution axis
(``l_s``), ``v`` a vanishing point (``v_x``), homogeneous, in any consistent
coordinates.  The residuals of eq. 20 are the signed distances (the outline's smooth
distance field, :mod:`sorjax.core._field`) of the transferred samples ``W x_i``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._field import DistanceField, checked_distances, closest_parameter, signed_distances


def homology_matrix(v: Float[Array, "3"], l: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Harmonic homology ``W = I - 2 v l^T / (v^T l)`` (any consistent coordinates)."""
    return jnp.eye(3) - 2.0 * jnp.outer(v, l) / (v @ l)


def transfer(W: Float[Array, "3 3"], x: Float[Array, "N 2"]) -> Float[Array, "N 2"]:
    """Map inhomogeneous points by the homography ``W`` (guarded against points sent
    to infinity, which are sent very far instead)."""
    y = x @ W[:, :2].T + W[:, 2]
    w = y[:, 2]
    w = jnp.where(jnp.abs(w) < 1e-12, jnp.where(w < 0, -1e-12, 1e-12), w)
    return y[:, :2] / w[:, None]


def symmetry_residuals(
    v: Float[Array, "3"], l: Float[Array, "3"], samples: Float[Array, "N 2"], field: DistanceField, weights=None,
    hints=None,
) -> Float[Array, "N"]:
    """The residuals of eq. 20: ``w_i d(W(v, l) x_i)`` for each sample ``x_i``, in the
    units of the field (pixels if the field and samples are in pixels); ``weights``
    ``w_i`` default to 1 (:func:`sorjax.core._field.sample_weights` zeroes samples at
    corners); ``hints`` (N,) optional closest-point parameters to search near
    (:func:`sorjax.core._field.closest_parameter_near`)."""
    r = signed_distances(field, transfer(homology_matrix(v, l), samples), hints)
    return r if weights is None else r * weights


def symmetry_checked(v: Float[Array, "3"], l: Float[Array, "3"], samples: Float[Array, "N 2"], field: DistanceField,
                     weights, hints=None):
    """:func:`symmetry_residuals` at the end of a solve that searched closest points
    near ``hints``: ``(r, t, r_near)``, the whole-outline residuals, their closest-point
    parameters (:func:`symmetry_feet`: the next solve's hints) and the residuals
    searched near ``hints`` (:func:`sorjax.core._field.checked_distances`: one pass; None:
    ``r`` again, only the whole outline searched)."""
    d, t, d_near = checked_distances(field, transfer(homology_matrix(v, l), samples), hints)
    return d * weights, t, d_near * weights


def symmetry_feet(v: Float[Array, "3"], l: Float[Array, "3"], samples: Float[Array, "N 2"],
                  field: DistanceField) -> Float[Array, " N"]:
    """Parameters (knot units) of the outline's points closest to the transferred
    samples ``W(v, l) x_i`` (whole-outline search, no gradient): the hints of a solve
    started at ``(v, l)``."""
    return jax.vmap(closest_parameter, in_axes=(None, 0))(field, transfer(homology_matrix(v, l), samples))
