"""Chart location: homography from the corner patches, patch centres, sampling windows, errors."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from fidelity.chart.locate import (
    apply_homography,
    grid_centres,
    homography_from_points,
    locate_chart,
    parse_corners,
    window_pixels,
)
from fidelity.core.errors import InvalidValueError

GRID_CORNERS = np.array([[0, 0], [5, 0], [5, 3], [0, 3]], dtype=float)


def known_h(angle: float = 0.3, sx: float = 40.0, sy: float = 36.0, tx: float = 90.0,
            ty: float = 70.0, p: tuple[float, float] = (0.015, -0.02)) -> np.ndarray:
    """Rotation * scale, translation and a perspective row: a known projective map."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[sx * c, -sy * s, tx], [sx * s, sy * c, ty], [p[0], p[1], 1.0]])


def project(h: np.ndarray, uv: np.ndarray) -> np.ndarray:
    q = np.c_[uv, np.ones(len(uv))] @ h.T
    return q[:, :2] / q[:, 2:]


def test_homography_recovers_a_known_map():
    h = known_h()
    est = homography_from_points(GRID_CORNERS, project(h, GRID_CORNERS))
    np.testing.assert_allclose(est, h / h[2, 2], rtol=1e-9, atol=1e-9)
    pts = np.random.default_rng(1).uniform(0, 5, size=(50, 2))
    np.testing.assert_allclose(apply_homography(est, pts), project(h, pts), atol=1e-8)


@pytest.mark.parametrize("h", [known_h(), known_h(angle=math.pi, tx=330, ty=250),
                               known_h(angle=0.0, sx=-40.0, tx=300, p=(0.0, 0.0))])
def test_patch_centres_and_windows(h):
    corners = project(h, GRID_CORNERS)
    loc = locate_chart(corners, (320, 400, 3))
    np.testing.assert_allclose(loc.centres, project(h, grid_centres()), atol=1e-8)
    # every sampled pixel maps back inside its patch's central window (half-width 0.25 pitch)
    hinv = np.linalg.inv(h)
    for k, (rows, cols) in enumerate(loc.windows):
        uv = project(hinv, np.c_[cols, rows].astype(float))
        u0, v0 = grid_centres()[k]
        assert np.all(np.abs(uv[:, 0] - u0) <= 0.25 + 1e-9)
        assert np.all(np.abs(uv[:, 1] - v0) <= 0.25 + 1e-9)
        # area of the window in pixels ~ |det J| * 0.5^2 (Jacobian of h at the centre)
        eps = 1e-4
        jac = np.column_stack([(project(h, np.array([[u0 + eps, v0]])) - project(h, np.array([[u0, v0]])))[0] / eps,
                               (project(h, np.array([[u0, v0 + eps]])) - project(h, np.array([[u0, v0]])))[0] / eps])
        area = abs(np.linalg.det(jac)) * 0.25
        assert abs(len(rows) - area) < 0.15 * area + 10


def test_sample_patches_returns_window_pixels():
    h = known_h(angle=0.0, p=(0.0, 0.0))
    img = np.zeros((320, 400, 3))
    loc = locate_chart(project(h, GRID_CORNERS), img.shape)
    cx, cy = np.rint(loc.centres[7]).astype(int)
    img[cy, cx] = 1.0
    samples = window_pixels(img, loc)
    assert len(samples) == 24
    assert samples[7].sum() == 3.0 and all(s.sum() == 0 for i, s in enumerate(samples) if i != 7)


def test_parse_corners():
    np.testing.assert_array_equal(parse_corners("1,2,3,4,5,6,7,8"), [[1, 2], [3, 4], [5, 6], [7, 8]])
    np.testing.assert_array_equal(parse_corners("1.5 2 3 4 5 6 7 8"), [[1.5, 2], [3, 4], [5, 6], [7, 8]])
    with pytest.raises(InvalidValueError, match="expected 8 numbers"):
        parse_corners("1,2,3")
    with pytest.raises(InvalidValueError, match="expected 8 numbers"):
        parse_corners("1,2,3,4,5,6,7,x")
    with pytest.raises(InvalidValueError, match="finite"):
        parse_corners("1,2,3,4,5,6,7,nan")


def test_corners_outside_the_image():
    corners = project(known_h(), GRID_CORNERS)
    corners[2] = [500.0, 100.0]
    with pytest.raises(InvalidValueError, match=r"corner 'black' at \(500, 100\) is outside the 400x320 image"):
        locate_chart(corners, (320, 400, 3))


def test_window_outside_the_image():
    # corner centres inside, but the outer half of the edge patches would leave the image
    h = known_h(angle=0.0, sx=40, sy=40, tx=3.0, ty=3.0, p=(0.0, 0.0))
    with pytest.raises(InvalidValueError) as err:
        locate_chart(project(h, GRID_CORNERS), (320, 400, 3))
    got = re.search(r"patch 'patch 1': its sampling window \(x (\S+) to (\S+), y (\S+) to "
                    r"(\S+)\) reaches outside the 400x320 image", str(err.value))
    assert got, str(err.value)
    x0, x1, y0, y1 = map(float, got.groups())  # the window about the first centre, (3, 3)
    assert x0 < -0.5 and y0 < -0.5 and x0 + x1 == pytest.approx(6) and y0 + y1 == pytest.approx(6)


def test_chart_too_small_to_sample():
    h = known_h(angle=0.0, sx=3.0, sy=3.0, tx=10, ty=10, p=(0.0, 0.0))
    with pytest.raises(InvalidValueError, match=r"chart too small to sample: patch .* pixel"):
        locate_chart(project(h, GRID_CORNERS), (100, 100, 3))
    # 8 px pitch with a 0.5 window: 4x4 = 16 pixels per window, enough
    ok = known_h(angle=0.0, sx=8.0, sy=8.0, tx=10, ty=10, p=(0.0, 0.0))
    loc = locate_chart(project(ok, GRID_CORNERS), (100, 100, 3))
    assert min(len(w[0]) for w in loc.windows) >= 9


def test_degenerate_corners():
    with pytest.raises(InvalidValueError, match="degenerate"):
        locate_chart(np.array([[10, 10], [50, 10], [90, 10], [10, 60]], float), (100, 100, 3))
    with pytest.raises(InvalidValueError, match="degenerate"):
        locate_chart(np.array([[10, 10], [10, 10], [90, 60], [10, 60]], float), (100, 100, 3))
