"""The thresholds of the automatic object finding and of the edge refinement
(:class:`DetectOptions`, re-exported by :mod:`sorjax._detect`): lengths in pixels of the
full-resolution image unless said, grey levels in 8-bit units.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DetectOptions:
    """Thresholds of the automatic object finding and of the edge refinement (see the
    docstrings of :mod:`sorjax._detect` and :mod:`sorjax._edge_refinement`); lengths in
    pixels of the full-resolution image unless said."""

    # proposals (on the image reduced to max_side px)
    max_side: int = 640
    border_frac: float = 0.015  # border band, fraction of the smaller side (>= 5 px reduced)
    min_area_frac: float = 2e-3
    max_area_frac: float = 0.5
    min_solidity: float = 0.35
    same_iou: float = 0.7  # proposal boxes overlapping more are one proposal
    max_proposals: int = 24
    clusters: int = 8  # k-means clusters of the colour cue
    edge_window: int = 9  # reduced px: window of the edge density
    # segmentation and judge
    box_grow: float = 0.15  # GrabCut rectangle: the box grown by this fraction of its larger side ...
    box_grow_min: int = 8  # ... and at least this many px
    symmetry_px: float = 1.0  # RMS symmetry residual (trimmed) of a kept outline, px ...
    symmetry_rel: float = 0.006  # ... or this fraction of its larger extent, when larger
    # the untrimmed residual within this many times the limit: on the photo sets (seeds 0, 7) the outlines
    # within 1 px of the truth had 0.2-0.9 times the limit, the leaks and shadows kept at 4 (3-21 px off) 1.6-2.6
    untrimmed_factor: float = 1.5
    polygon_vertices: int = 6  # an outline within polygon_rel of its size plus polygon_px from a polygon of
    polygon_rel: float = 0.01  # this many vertices (tiles, box faces) is not a surface of revolution's
    # ... polygon_px (reduced px): what blur and GrabCut round off a polygon's corners; with
    # polygon_rel alone a box face with corners rounded by 2-3 px passed (photo sets 0 and 7,
    # 3 cameras: the false detections kept had 3-8 vertices at 1.5 + 1 % of the size, 20 of
    # 25 at most 6 on set 7; the true objects 11-24, none below 11 at 1.0-2.0 px)
    polygon_px: float = 1.5
    min_inliers: float = 0.7  # fraction of the homology fit's samples kept by its trimming
    overlap: float = 0.3  # kept segmentations overlapping more (intersection / smaller area) are one object
    grow_rounds: int = 2  # a segmentation reaching its box's sides: the box grown that way, this many times
    grow_step: float = 0.5  # ... by this fraction of its size
    recut_inliers: float = 0.97  # a kept segmentation whose homology fit trims more is re-cut by its symmetry
    recut_px: float = 2.0  # reduced px: the sure-foreground margin and background band of the re-cut
    recut_gain: float = 0.8  # the re-cut replaces the segmentation when its untrimmed residual is this much lower
    # a proposal whose segmentation is not symmetric, or runs out of its box (grown grow_rounds times) other
    # than at the image border, is segmented again from its box grown by each of these (instead of box_grow)
    # until one is kept: GrabCut's colour models, and so its cut of a glossy or metal object against a table
    # of like colour, change with the background sample the margin gives
    retry_grow: tuple = (0.08, 0.3)
    # edge refinement
    reach: float = 2.5
    side_px: float = 1.5  # the colours on each side: means over reach to reach + side_px px from the outline
    prior_px: float = 0.75  # local maxima weighted by a Gaussian of this std (px) about the segmentation's edge
    step: float = 0.25
    edge_blur: float = 0.7
    normal_sigma: float = 2.0  # px of arc: Gaussian derivative giving the normals
    min_contrast: float = 12.0  # grey levels (8-bit units) of the colour step
    weak_peak: float = 0.35
    second_peak: float = 0.6
    peak_gap: float = 1.0
    max_turn_deg: float = 35.0
    max_width: float = 1.5  # a peak wider than this times the outline's lower-quartile width is two edges
    curve_sigma: float = 3.0  # px of arc
    clip_k: float = 3.0
    move_px: float = 0.3  # the outline moves only where the edge lies farther than this (see refine_to_edges)
    min_support: float = 0.3  # fraction of a smoothing window's points accepted for the outline to move
    reject_px: float = 0.5
    # automatic finding only: an outline whose estimated error (outline_quality) is larger is dropped.  On the
    # photo sets (seeds 0 and 7, 3 cameras x 4 images) the outlines kept within 1 px of an object had 0.12-0.96
    # px; 21 of 31 false detections (box faces, wedges, parts of objects) and 5 of 8 outlines 1.3-54 px off
    # had more than 1 px, 11 and 4 more than 1.5 px
    max_error_px: float = 1.5
    # symmetric averaging (symmetric_average): the weight of a point whose edge refine_to_edges did not
    # confirm, against 1 for a confirmed one (an unconfirmed point whose mirror partner is confirmed takes
    # the partner's mirror image for 5/6), the weights smoothed along the outline by a Gaussian of
    # weight_sigma px of arc (no step where the confirmation changes).  Chosen on random_photo_set seeds
    # 100-129 (161 outlines; median RMS 0.378 px with 0.05 and no smoothing, 0.363 px with these)
    unconfirmed_weight: float = 0.2
    weight_sigma: float = 2.0
    # ... taken where a point and its mirror partner disagree by more than average_px (all of it beyond
    # twice that, a ramp between, smoothed as the weights); 0 (default): everywhere.  The residuals an
    # outline averaged everywhere no longer shows go to the calibration as its noise floor
    # (ImageOutline.noise_rms); without that floor, random_photo_set seed 122's camera was refused as
    # inconsistent (0.099 px of residual taken for the whole noise), with it calibrated within 0.1 %
    # (session 24).  1 px averages only the defects (median RMS 0.43 px against 0.36 px)
    average_px: float = 0.0
