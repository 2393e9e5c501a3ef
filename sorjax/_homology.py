"""Harmonic homologies of surface-of-revolution outlines and their per-view fit.

The outline of a surface of revolution is mapped onto itself by the harmonic homology
(the paper's eq. 11)::

    W(v, l) = I - 2 v l^T / (v^T l)

with axis ``l = l_s`` (the image of the revolution axis) and vertex ``v = v_x``.  W is
an involution, fixes every point of ``l_s`` and has 4 degrees of freedom.

Per view we minimise the paper's eq. 20::

    Cost(v, l) = sum_i d(W(v, l) x_i)^2

over ``N`` samples ``x_i`` evenly spaced along the outline, ``d`` being the signed
orthogonal distance to the outline (:mod:`sorjax.core._field`).  The fit runs in
per-view normalised coordinates (centroid at the origin, RMS radius sqrt 2) with the
parameters ``p = (theta, rho, d1, d2)``::

    l = (cos theta, sin theta, -rho),     v = normalise(v0 + d1 e1 + d2 e2),

``v0`` the starting vertex (unit 3-vector) and ``e1, e2`` an orthonormal basis of its
tangent plane on the sphere: a chart that stays well conditioned when ``v_x`` goes to
infinity (``v`` then has a vanishing third coordinate, nothing diverges).

Initialisation is automatic (the paper picked bitangents by hand):

* bitangents of the convex hull: every pair of concavities ("pockets" between the
  outline and its hull) gives bitangents ``l_b, l_b'`` touching at ``x1, x2`` and
  ``x1', x2'``; then ``v_x = (x1 x x1') x (x2 x x2')`` and ``l_s`` joins
  ``l_b x l_b'`` and ``(x1 x x2') x (x1' x x2)`` (paper, Section 5.1);
* a symmetry-axis search: mirror symmetries (``v`` at infinity orthogonal to ``l``)
  over a grid of axis directions and offsets, the best few local minima kept;
* for a nearly conic outline (a bowl from above), the pole-polar pairs of its
  best-fitting conic, each an exact symmetry of the conic;

every candidate is screened by a few Levenberg-Marquardt steps
(:func:`sorjax.core._solvers.least_squares`) and the one with the lowest cost is polished.  The fit itself is the pure, jit / vmap-able
:func:`sorjax.core._viewfit.fit_view` (a fixed-size set of starts, robust trimming as a
fixed number of masked rounds); :func:`fit_homology` is its shell: validation, then one
jitted call, then a :class:`Homology`.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._checks import boolean, check_options, check_sizes, integer, number
from ._outline import DEFAULT_POINTS, make_outline, perimeter


class Homology(eqx.Module):
    """A fitted harmonic homology of one outline (pixels).

    Attributes:
        l_s: image of the revolution axis, homogeneous line with ``a^2 + b^2 = 1``.
        v_x: vertex (vanishing point), homogeneous, unit norm; ``v_x[2] -> 0`` when it
            is at infinity.
        W: ``I - 2 v_x l_s^T / (v_x^T l_s)``, pixels.
        rms: RMS symmetry residual ``sqrt(Cost / N)`` in pixels.
        cost: eq. 20's cost in px^2.
        converged: the optimiser reported success.
        steps: Levenberg-Marquardt steps taken.
        conic_rms: RMS distance (px, Sampson) of the outline from its best-fitting
            conic.  A conic outline (a sphere, or a bowl seen from above showing only
            its rim) is symmetric under infinitely many homologies and carries no
            calibration information (the paper's Section 6): see :attr:`is_conic`.
        infinity_z: how many standard errors ``v_x`` lies from the line at infinity:
            ``|v_3| / std(v_3)`` in the fit's normalised coordinates, the standard
            error from the fit's Jacobian and its residual (first order; affine
            invariant).  See :attr:`v_x_at_infinity`.  None for homologies built by
            hand.
        inliers: (N,) the samples the fit kept (robust fit: samples whose residual
            is an outlier, e.g. on a mug's handle, are trimmed); ``rms`` and ``cost``
            are over these.  None for homologies built by hand.
        rms_untrimmed: RMS symmetry residual (px) of the fit to all samples, before
            any trimming: :func:`sorjax.calibrate` judges whether a view is symmetric
            at all by it, so that trimming never makes an asymmetric outline (a
            segmentation leak) pass.  None for homologies built by hand.
        noise_ell: the correlation length along the curve (px) of the outline's
            noise, read off the fit's residuals (:mod:`sorjax.core._noise`); with ``rms``,
            what an outline later averaged with its own mirror image passes on as its
            noise floor (:func:`sorjax.calibrate`'s ``outline_noise``,
            ``outline_noise_ell``).  None for homologies built by hand.
    """

    l_s: Float[Array, "3"]
    v_x: Float[Array, "3"]
    W: Float[Array, "3 3"]
    rms: Float[Array, ""]
    cost: Float[Array, ""]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    conic_rms: Float[Array, ""]
    infinity_z: Float[Array, ""] | None = None
    inliers: Bool[Array, " N"] | None = None
    rms_untrimmed: Float[Array, ""] | None = None
    noise_ell: Float[Array, ""] | None = None

    @property
    def trimmed(self) -> float:
        """Fraction of the samples trimmed as outliers by the robust fit (0 if none)."""
        return 0.0 if self.inliers is None else float(1.0 - np.mean(np.asarray(self.inliers)))

    @property
    def v_x_at_infinity(self) -> bool:
        """``v_x`` is at infinity as far as this outline can tell: within
        ``Options().infinity_z`` (3) standard errors of the line at infinity, or so far away
        (``|v_3| < 1e-9`` of the unit vertex in pixels) that no noise-free fit could
        place it better.  The camera then looks straight at the revolution axis (the
        outline has skew or mirror symmetry; paper, Section 6): the view constrains
        the principal point (it lies on ``l_s``) but not the focal length.

        The standard error assumes independent residuals; with noise correlated along
        the outline (or a rough, densely sampled outline) it is optimistic, so the test
        errs towards calling ``v_x`` finite.  :func:`sorjax.calibrate` acts on it only
        when the joint estimate cannot fix the focal length either."""
        return self.judged(Options())[0]

    @property
    def is_conic(self) -> bool:
        """The outline is explained by a conic about as well as by this homology
        (``conic_rms <= conic_ratio * rms + conic_floor_px``, :class:`sorjax.core.Options`):
        its homology is not determined, so the view says nothing about the camera."""
        return self.judged(Options())[1]

    def judged(self, options) -> tuple[bool, bool]:
        """``(v_x_at_infinity, is_conic)`` by the thresholds of ``options`` (a
        :class:`sorjax.Options`; the properties use the defaults)."""
        at_inf = abs(float(np.asarray(self.v_x)[2])) < 1e-9 or (
            self.infinity_z is not None and bool(self.infinity_z < options.infinity_z))
        conic = bool(self.conic_rms <= options.conic_ratio * self.rms + options.conic_floor_px)
        return at_inf, conic


# The maths (sorjax.core._symmetry) and the per-view fit (sorjax.core._viewfit).
from .core._symmetry import homology_matrix, symmetry_checked, symmetry_feet, symmetry_residuals, transfer  # noqa: E402,F401
from ._compile import one_off_jit  # noqa: E402
from .core._options import Options  # noqa: E402
from .core._prepare import prepare_views  # noqa: E402
from .core._viewfit import fit_view, pixel_homology  # noqa: E402

DEFAULT_SAMPLES = Options().n_samples


@functools.partial(one_off_jit, static_argnames=("smooth",))
def _fit_core(points, init, options, smooth):
    """Prepare one outline (pixels), fit it and express the fit in pixels."""
    views = prepare_views(points[None], options.n_samples, smooth)
    view = jax.tree_util.tree_map(lambda a: a[0], views)
    T = view.T
    if init is not None:
        init = (T @ init[0], jnp.linalg.solve(T.T, init[1]))
    fit = fit_view(view.fields, view.samples, view.weights, view.points, options, init, 1.0 / T[0, 0])
    return pixel_homology(fit, T, options)


def _check_init(init):
    """``init`` as two float64 3-vectors ``(v_x, l_s)``, or None; ValueError otherwise."""
    if init is None:
        return None
    what = ("init must be (v_x, l_s): the starting vertex and axis, two homogeneous 3-vectors in pixels "
            "(e.g. (np.array([0, 1, 0]), np.array([1, 0, -320])) for a vertical axis x = 320)")
    try:
        v, l = (np.asarray(a, dtype=np.float64) for a in init)
    except (TypeError, ValueError):
        raise ValueError(f"{what}; got {init!r:.80}.") from None
    if v.shape != (3,) or l.shape != (3,):
        raise ValueError(f"{what}; got shapes {v.shape} and {l.shape}.")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(l))):
        raise ValueError(f"{what}; got NaN or infinite entries.")
    if not np.any(v) or np.hypot(l[0], l[1]) == 0.0:
        raise ValueError(f"{what}; v_x is zero or l_s is the line at infinity.")
    if abs(v @ l) <= 1e-12 * np.linalg.norm(v) * np.linalg.norm(l):
        raise ValueError(f"{what}; v_x lies on l_s (v_x . l_s = 0), where the homology is not defined.")
    return v, l


def fit_homology(
    outline,
    *,
    n_samples: int | None = None,
    n_points: int = DEFAULT_POINTS,
    init=None,
    max_steps: int | None = None,
    smooth_px: float = 0.0,
    robust: bool = True,
    options: Options | None = None,
) -> Homology:
    """Fit the harmonic homology of one outline by minimising eq. 20.

    Args:
        outline: (N, 2) pixel coordinates of a closed outline, or an :class:`Outline`.
        n_samples: number of samples ``x_i`` evenly spaced along the outline (the paper
            uses 100); None: ``options.n_samples`` (100 by default).
        n_points: the outline is resampled to this many points for its distance field.
        init: optional starting homology ``(v_x, l_s)`` in pixels (homogeneous); by
            default the start is found automatically (bitangents of the convex hull,
            a symmetry-axis search and, for a nearly conic outline, pole-polar pairs
            of its conic; the lowest screened cost wins).
        max_steps: step limit of each polishing solve; None: ``options.max_steps`` (100
            by default).
        smooth_px: smooth the outline along the curve (Gaussian, std in px of arc
            length) before building its distance field and samples; 0 (default) uses
            the outline as given.
        robust: trim samples whose residual is an outlier (a handle, a shadow, an
            occlusion: above ``max(trim_k * 1.4826 median|r|, trim_floor_px)``) and
            refit, ``options.trim_rounds`` times at most, never below half of the
            samples; ``Homology.inliers`` says which were kept.
        options: the per-view fit's thresholds and budgets (:class:`sorjax.Options`:
            ``trim_k``, ``trim_floor_px``, ``screen_steps``, ``trim_rounds``,
            ``covariance_smooth_px``, ``noise_ell_min_px``, ``noise_ell_max_px``; the
            fit's ``infinity_z`` and ``conic_*`` verdicts are read by the calibration);
            None: the defaults.  ``n_samples`` and ``max_steps``, when given, replace
            its fields.  Thresholds are traced: other values compile nothing new.

    Returns:
        :class:`Homology` in pixels, with the RMS symmetry residual in px.

    Raises:
        ValueError: a bad outline, or an option out of range (``n_samples`` an integer
        >= 10 and <= ``n_points``, ``n_points`` 64 to 65536, ``max_steps`` >= 1,
        ``smooth_px`` >= 0, ``robust`` a bool, ``init`` two 3-vectors with
        ``v_x . l_s != 0``), naming the option.

    The fit is :func:`sorjax.core._viewfit.fit_view` (pure, jit / vmap-able), run once
    under ``jax.jit``.
    """
    options = check_options(options)
    n_samples, n_points = check_sizes(options.n_samples if n_samples is None else n_samples, n_points)
    max_steps = integer(options.max_steps if max_steps is None else max_steps, "max_steps", lo=1, hi=100_000,
                        what="steps of each polishing solve")
    smooth_px = number(smooth_px, "smooth_px", lo=0.0, unit="px of arc length")
    robust = boolean(robust, "robust")
    init = _check_init(init)
    o = make_outline(outline, n_points)
    pts = np.asarray(o.points)
    smooth = float(smooth_px) / (perimeter(pts) / o.n_points) if smooth_px else 0.0
    options = dataclasses.replace(options, n_samples=int(n_samples), max_steps=int(max_steps),
                                  trim_rounds=options.trim_rounds if robust else 0)
    if init is not None:
        init = tuple(jnp.asarray(a) for a in init)
    h = _fit_core(jnp.asarray(pts), init, options, smooth)
    if not np.isfinite(float(h.cost)):
        raise FloatingPointError("every start of the homology fit gave a non-finite cost")
    return Homology(l_s=h.l_s, v_x=h.v_x, W=h.W, rms=h.rms, cost=h.cost, converged=h.converged, steps=h.steps,
                    conic_rms=h.conic_rms, infinity_z=h.infinity_z, inliers=h.inliers,
                    rms_untrimmed=h.rms_untrimmed, noise_ell=h.noise_ell)


@functools.partial(one_off_jit, static_argnames=("n_samples",))
def _outline_residuals(points, v_x, l_s, n_samples):
    """``(r, w)``: eq. 20's residuals (V, N) px of each outline ``points`` (V, M, 2 px)
    under the homology ``(v_x, l_s)`` (V, 3 each, px), at the samples and with the corner
    weights (V, N) of the per-view fit with ``n_samples`` samples (the same field, samples
    and weights as :func:`fit_homology`'s, so that a homology fitted on the outline gets
    back its own residuals).  One compiled program per shape."""
    views = prepare_views(points, n_samples)
    v = jnp.einsum("vij,vj->vi", views.T, v_x)  # points map by T, lines by T^-T
    l = jnp.einsum("vji,vj->vi", jnp.linalg.inv(views.T), l_s)
    r = jax.vmap(symmetry_residuals)(v, l, views.samples, views.fields, views.weights)
    return r * views.scale[:, None], views.weights


def homology_residual(outlines, homologies, n_points: int = DEFAULT_POINTS, options: Options | None = None
                      ) -> np.ndarray:
    """The RMS symmetry residual (px) of each outline under its given homology: how well
    ``homologies[i]`` (a :class:`Homology`) maps ``outlines[i]`` onto itself, read as
    :func:`fit_homology` reads its own fit (eq. 20 at the same samples: as many as the
    homology's ``inliers``, else ``options.n_samples``; over the samples it kept; with
    the fit's trimming rule, ``options.trim_k`` and ``options.trim_floor_px``, applied
    once more, so that an outline with a handle is judged by the samples that have a
    mirror image; ``options`` None: the defaults).  A homology fitted on this very
    outline gives back its own ``rms``; one fitted on another outline (another camera,
    view or object, the outline moved) more.  Returns (V,) px."""
    options = Options() if options is None else options
    outs = [make_outline(o, n_points) for o in outlines]
    points = np.stack([np.asarray(o.points, np.float64) for o in outs])
    out = np.full(len(outs), np.nan)
    sizes = [options.n_samples if h.inliers is None else int(np.shape(h.inliers)[0]) for h in homologies]
    for n in sorted(set(sizes)):
        idx = [i for i, s in enumerate(sizes) if s == n]
        B = max(4, 1 << (len(idx) - 1).bit_length())  # padded view counts: one program for 2 to 4 views, ...
        pick = idx + [idx[0]] * (B - len(idx))
        v = np.stack([np.asarray(homologies[i].v_x, np.float64) for i in pick])
        l = np.stack([np.asarray(homologies[i].l_s, np.float64) for i in pick])
        r, w = (np.asarray(a) for a in _outline_residuals(points[pick], v, l, n))
        for j, i in enumerate(idx):
            h = homologies[i]
            keep = np.ones(n, bool) if h.inliers is None else np.asarray(h.inliers, bool)
            out[i] = _kept_rms(r[j], w[j], keep, options)
    return out


def _kept_rms(r, w, keep, options: Options) -> float:
    """RMS of the weighted residuals ``r * w`` (px) over the samples ``keep`` (the
    homology's inliers) that the fit's trimming rule keeps (``max(trim_k * 1.4826
    median|r|, trim_floor_px)``, never below half of them)."""
    o = options
    a = np.abs(r * w)
    base = keep & (w > 0)
    if not base.any():
        return float("nan")
    lim = max(o.trim_k * 1.4826 * float(np.median(a[base])), o.trim_floor_px)
    kept = base & (a <= lim)
    if kept.sum() < base.sum() // 2:
        kept = base
    return float(np.sqrt(np.sum(a[kept] ** 2) / np.sum(w[kept])))
