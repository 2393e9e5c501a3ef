"""An outline with what its source said about it (:class:`ImageOutline`): the outlines
found in images (:mod:`sorjax._detect`, :mod:`sorjax._extract`) and traced from masks
(:mod:`sorjax._masks`) carry their measured quality, which :func:`sorjax.calibrate`
reads."""

from __future__ import annotations

import math

import numpy as np


class ImageOutline(np.ndarray):
    """An outline (N, 2) float64 array in pixels, with what the image said about it.

    Attributes
    ----------
    outline_error : float
        Estimated RMS distance (px) of the outline from the object's true edge,
        from the data (see :mod:`sorjax._edge_refinement`'s "Edge refinement"); NaN
        when the outline was not refined on the image.
    edge_contrast : float
        Median colour step (8-bit grey levels) across the accepted edge points.
    accepted : float
        Fraction of the outline's points whose edge was confirmed on the image.
    symmetry_rms : float
        RMS symmetry residual (px) of the robust harmonic homology fitted to the
        refined outline, before it was averaged with its mirror image (without
        refinement: to the segmentation's outline when the object was found
        automatically, NaN with a box).
    noise_rms : float
        RMS symmetry residual (px) of the refined outline before it was averaged with
        its own mirror image (:func:`symmetric_average`; NaN when it was not): the
        noise that the averaged outline no longer shows, which :func:`sorjax.calibrate`
        takes as each view's noise floor (its ``outline_noise``).
    noise_ell : float
        The correlation length along the curve (px) of that noise, read off the same
        fit's residuals (:attr:`sorjax.Homology.noise_ell`; NaN when not averaged):
        :func:`sorjax.calibrate`'s ``outline_noise_ell``.
    outline_offset : float
        The standard deviation (px) of a systematic offset of the outline along its
        normals that its source may carry and its symmetry does not show (an outline
        traced from a mask: :data:`sorjax.MASK_OFFSET_PX`, a segmenter's bias; NaN:
        not known).  :func:`sorjax.calibrate` counts the largest of its outlines' in
        the covariance (:attr:`sorjax.Options.outline_offset_px`).

    Arithmetic returns plain arrays' values with these attributes copied; use
    ``np.asarray(o)`` for a plain array."""

    outline_error: float
    edge_contrast: float
    accepted: float
    symmetry_rms: float
    noise_rms: float
    noise_ell: float
    outline_offset: float

    #: the attributes above, in order (what :func:`sorjax.save_outlines` keeps)
    ATTRIBUTES = ("outline_error", "edge_contrast", "accepted", "symmetry_rms", "noise_rms", "noise_ell", "outline_offset")

    def __new__(cls, points, *, outline_error=math.nan, edge_contrast=math.nan, accepted=math.nan,
                symmetry_rms=math.nan, noise_rms=math.nan, noise_ell=math.nan, outline_offset=math.nan):
        obj = np.asarray(points, dtype=np.float64).view(cls)
        obj.outline_error = float(outline_error)
        obj.edge_contrast = float(edge_contrast)
        obj.accepted = float(accepted)
        obj.symmetry_rms = float(symmetry_rms)
        obj.noise_rms = float(noise_rms)
        obj.noise_ell = float(noise_ell)
        obj.outline_offset = float(outline_offset)
        return obj

    def __array_finalize__(self, obj):
        for k in self.ATTRIBUTES:
            setattr(self, k, getattr(obj, k, math.nan))

    def __reduce__(self):  # pickles (worker processes) keep the attributes
        base = super().__reduce__()
        return base[0], base[1], (base[2], self.__dict__)

    def __setstate__(self, state):
        arr_state, attrs = state
        super().__setstate__(arr_state)
        self.__dict__.update(attrs)
