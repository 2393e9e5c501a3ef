import numpy as np
import pytest

from sorjax._outline import (JAGGED_PX, is_jagged, make_outline, point_jitter, resample_closed, signed_area,
                             smooth_jagged, validate_points)


def ellipse(n=300, a=120.0, b=70.0, cx=320.0, cy=240.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([cx + a * np.cos(t), cy + b * np.sin(t)], 1)


def test_resampling_is_even_and_oriented():
    pts = ellipse()[::-1]  # negative orientation in, positive out
    o = make_outline(pts, 256)
    p = np.asarray(o.points)
    assert p.shape == (256, 2)
    assert float(signed_area(p)) > 0
    seg = np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1)
    assert seg.std() / seg.mean() < 0.01
    np.testing.assert_allclose(float(o.area()), np.pi * 120 * 70, rtol=2e-3)


def test_closing_duplicate_and_opencv_layout_accepted():
    pts = ellipse()
    a = validate_points(np.vstack([pts, pts[:1]]))
    assert len(a) == len(pts)
    b = validate_points(pts[:, None, :].astype(np.int32))  # cv2.findContours layout
    assert b.shape == (len(pts), 2)


@pytest.mark.parametrize(
    "bad, words",
    [
        (np.zeros((0, 2)), "empty"),
        (ellipse()[:5], "at least 32"),
        (np.where(np.arange(300)[:, None] == 7, np.nan, ellipse()), "NaN"),
        (ellipse().T, "transposed"),
        (ellipse()[:150], "open curve"),
        (np.vstack([np.stack([np.linspace(0, 100, 25)] * 2, 1), np.stack([np.linspace(96, 4, 24)] * 2, 1)]), "area"),
        (np.array(["a", "b"] * 10).reshape(10, 2), "dtype"),
        ([[1, 2], [3]], "could not be read"),
    ],
)
def test_bad_outlines_raise_clear_errors(bad, words):
    with pytest.raises(ValueError, match=words):
        validate_points(bad)


def test_self_intersection_detected():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    figure_eight = np.stack([100 * np.sin(t), 60 * np.sin(2 * t)], 1) + 300
    with pytest.raises(ValueError, match="crosses itself"):
        validate_points(figure_eight)


def test_resample_closed_passes_through_vertices_of_a_square():
    sq = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    r = resample_closed(sq, 40)
    np.testing.assert_allclose(r[::10], sq)


def _signed_distance(pts, exact):
    """Distance (px) of each point to the closed polyline ``exact``, negative inside."""
    from sorjax.scenes import _points_in_polygon, distance_to_polyline

    return np.where(_points_in_polygon(exact, pts), -1.0, 1.0) * distance_to_polyline(pts, exact)


def test_findcontours_trace_is_read_as_its_binary_mask():
    """cv2.findContours of a rendered binary mask: recognised as a pixel trace, replaced
    by the outline sorjax.outlines_from_mask gives for that mask (to 1e-9 px), with a
    note; no inward bias (mean signed distance to the exact silhouette within 0.05 px,
    against about -0.47 px for the trace itself)."""
    import cv2

    import sorjax
    from sorjax import render
    from sorjax._outline import BINARY_MASK_PX, implied_outline_error, is_pixel_trace, outline_of_pixel_trace
    from sorjax.scenes import distance_to_polyline

    r = render.random_table_scene(1, n_objects=2)
    binary = r.mask >= 0.5
    from_mask = sorjax.outlines_from_mask(binary)
    for approx in (cv2.CHAIN_APPROX_NONE, cv2.CHAIN_APPROX_SIMPLE):
        cnts, _ = cv2.findContours(binary.astype(np.uint8), cv2.RETR_EXTERNAL, approx)
        assert len(cnts) == 2
        for c in cnts:
            trace = c[:, 0, :].astype(np.float64)
            assert is_pixel_trace(trace) and implied_outline_error(c) == (BINARY_MASK_PX, "pixel trace")
            exact = min(r.outlines, key=lambda e: np.linalg.norm(e.mean(0) - trace.mean(0)))
            assert np.mean(_signed_distance(trace, exact)) < -0.4  # cv2's points: half a pixel inside
            out = outline_of_pixel_trace(trace)
            mine = min(from_mask, key=lambda e: np.linalg.norm(e.mean(0) - trace.mean(0)))
            assert distance_to_polyline(out, mine).max() < 1e-9
            d = _signed_distance(out, exact)
            assert abs(np.mean(d)) < 0.05 and np.sqrt(np.mean(d**2)) < 0.15
            with pytest.warns(UserWarning, match="read as a trace of a binary mask's boundary pixels"):
                o = make_outline(c, 1024)
            assert abs(np.mean(_signed_distance(np.asarray(o.points), exact))) < 0.05
    # not traces: sub-pixel points, rounded sparse points, a 4-point integer square
    ell = ellipse()
    assert not is_pixel_trace(ell) and not is_pixel_trace(np.round(ell))
    sq = np.array([[0, 0], [40, 0], [40, 40], [0, 40]], float)
    assert not is_pixel_trace(np.vstack([np.linspace(sq[i], sq[(i + 1) % 4], 4, endpoint=False) for i in range(4)]))


def test_point_jitter_reads_independent_noise_and_ignores_smooth_curves():
    rng = np.random.default_rng(0)
    e = ellipse(4000)  # 0.15 px apart
    normal = np.stack([70 * np.cos(np.linspace(0, 2 * np.pi, 4000, endpoint=False)),
                       120 * np.sin(np.linspace(0, 2 * np.pi, 4000, endpoint=False))], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert point_jitter(e) < 1e-6 and point_jitter(e[::20]) < 1e-3  # dense or sparse, no jitter
    for sigma in (0.02, 0.05):  # read well below the spacing; beyond it, under-read but seen
        j = point_jitter(e + rng.normal(0, sigma, 4000)[:, None] * normal)
        assert abs(j / sigma - 1) < 0.15, (sigma, j)
    assert point_jitter(e + rng.normal(0, 1.0, 4000)[:, None] * normal) > 4 * JAGGED_PX
    # noise smoothed along the curve (the paper's: 2 px) is not jitter, even at 2 px
    from sorjax.scenes import paper_noise

    assert point_jitter(paper_noise(e, 2.0, rng)) < JAGGED_PX / 10


def test_smooth_jagged_removes_the_jitter_and_keeps_the_curve():
    rng = np.random.default_rng(1)
    e = ellipse(4000)
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    normal = np.stack([70 * np.cos(t), 120 * np.sin(t)], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    exact, _, left0 = smooth_jagged(e)
    assert np.abs(exact - e).max() < 2e-3  # twicing: no shrinkage of the curve (Gaussian alone: 0.05-0.2 px)
    noisy = e + rng.normal(0, 1.0, 4000)[:, None] * normal
    out, jitter, left = smooth_jagged(noisy)
    assert abs(jitter - 1.0) < 0.1
    off = np.sum((out - e) * normal, axis=1)  # the same index: the smoothing keeps the points' order
    assert abs(np.sqrt(np.mean(off**2)) / left - 1) < 0.25, (np.sqrt(np.mean(off**2)), left)
    assert left < 0.2 and abs(off.mean()) < 0.02
    # make_outline smooths jagged input, with a warning saying so; smooth input passes untouched
    with pytest.warns(UserWarning, match="jitter by"):
        o = make_outline(noisy, 1024)
    assert point_jitter(np.asarray(o.points)) < JAGGED_PX


def test_sparse_polygons_are_not_read_as_jagged():
    # an annotation tool's polygon: 40 irregularly spaced vertices of an ellipse (~15 px
    # apart) bends by its sagitta, not by noise; it is interpolated, not smoothed
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0, 2 * np.pi, 40))
    poly = np.stack([320 + 120 * np.cos(t), 240 + 70 * np.sin(t)], 1)
    assert not is_jagged(poly)
    e = ellipse(4000)
    assert is_jagged(e + rng.normal(0, 0.3, e.shape)) and not is_jagged(e)
