"""Prepare: outline points (V, M, 2) in pixels -> normalisation, fields, samples, weights.

Two coordinate systems, both isotropic similarities of the pixels
(:func:`sorjax.core._camera.normalising_transform`: centroid at the origin, RMS radius
sqrt 2):

* per view, ``T_j`` of that outline alone: the per-view fit (eq. 20) runs there;
* jointly, ``T`` of every view that is used (a 0/1 view mask): the linear methods and
  the bundle run there.

Everything is a pure function of fixed-shape arrays (jit / vmap / grad clean): a view
left out is masked, never removed, so a batch of calibrations stacks.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ._camera import normalising_transform, transform_points
from ._field import DistanceField, setup


class Views(eqx.Module):
    """Per-view data for the per-view fits, each view in its own normalised coordinates.

    Attributes:
        T: (V, 3, 3) per-view normalising similarities, ``x_n = T_j x`` (pixels in).
        points: (V, M, 2) the outlines' evenly spaced points, normalised.
        fields: the stacked (V) :class:`sorjax.core._field.DistanceField` of ``points``.
        samples: (V, N, 2) eq. 20's samples ``x_i``, normalised.
        weights: (V, N) 0 at samples near a corner of the outline, else 1.
    """

    T: Float[Array, "V 3 3"]
    points: Float[Array, "V M 2"]
    fields: DistanceField
    samples: Float[Array, "V N 2"]
    weights: Float[Array, "V N"]

    @property
    def scale(self) -> Float[Array, " V"]:
        """Pixels per normalised unit of each view."""
        return 1.0 / self.T[:, 0, 0]


def prepare_views(points: Float[Array, "V M 2"], n_samples: int, smooth_samples: float = 0.0) -> Views:
    """:class:`Views` of ``V`` outlines of ``M`` evenly spaced pixel points each
    (e.g. :func:`sorjax.make_outline`'s).  ``smooth_samples``: Gaussian smoothing along
    each curve before its field is built (std in samples of ``M``; 0: none)."""
    points = jnp.asarray(points, dtype=jnp.float64)
    T = jax.vmap(normalising_transform)(points)
    pn = jax.vmap(transform_points)(T, points)
    fields, samples, weights = jax.vmap(lambda p: setup(p, n_samples, smooth_samples))(pn)
    return Views(T, pn, fields, samples, weights)


def joint_transform(points: Float[Array, "V M 2"], used: Bool[Array, " V"]) -> Float[Array, "3 3"]:
    """The joint normalising similarity ``T`` of the used views' points (pixels)."""
    points = jnp.asarray(points, dtype=jnp.float64)
    w = jnp.broadcast_to(jnp.asarray(used, jnp.float64)[:, None], points.shape[:2])
    return normalising_transform(points, w)
