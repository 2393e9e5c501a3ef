import numpy as np
import pytest

from sorjax._outline import make_outline, resample_closed, signed_area, validate_points


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
        (ellipse()[:5], "at least 10"),
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
