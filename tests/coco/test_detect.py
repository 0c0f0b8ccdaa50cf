"""Finding the chart without --corners: synthetic images with known geometry.

Each image is drawn through a homography built here in closed form (rotation, scale,
perspective; :func:`test_audit.draw_chart`), so the true corner-patch centres are known
independently of fidelity.chart.locate. Checked: the corners found lie within 3 % of a patch pitch of
the truth, in every
orientation the grid allows (turned, quarter-turned in a portrait image, mirrored) and on HDR
input with NaN/Inf; the audit then measures the same ΔE as with the true
corners; an image without a chart is a one-line error.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.find import colour_order, find_chart
from fidelity.chart.locate import homography_from_points
from fidelity.cli import main
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_chart
from fidelity.core.errors import InvalidValueError, UnknownNameError
from fidelity.measure.pixels import measure_pixels
from fidelity.prediction.transforms import apply_transform
from tests.pipeline.test_audit import (
    GRID_CORNERS,
    draw_chart,
    expected_delta_e,
    map_points,
    write_exr,
    write_png8,
)

CHART = load_chart("safecolor")
LINEAR = cm.linearize_srgb(CHART.srgb)


def grid_homography(pitch: float, angle: float, centre: tuple[float, float],
                    perspective: tuple[float, float] = (0.0, 0.0), mirror: bool = False
                    ) -> np.ndarray:
    """Grid (u, v) -> image (x, y): about the chart centre (2.5, 1.5), optionally mirrored,
    turned by ``angle``, scaled to ``pitch`` px, moved to ``centre``, with a perspective row."""
    c, s = math.cos(angle), math.sin(angle)
    m = -1.0 if mirror else 1.0
    to_centre = np.array([[m, 0, -2.5 * m], [0, 1, -1.5], [0, 0, 1.0]])
    turn = np.array([[c * pitch, -s * pitch, centre[0]], [s * pitch, c * pitch, centre[1]],
                     [0, 0, 1.0]])
    h = turn @ to_centre
    h[2, :2] = perspective
    h[2, 2] = 1.0 - perspective[0] * 2.5 - perspective[1] * 1.5  # centre keeps its place
    return h


CASES = {
    "frontal": (grid_homography(52, 0.0, (320, 240)), (480, 640)),
    "tilted with perspective": (grid_homography(60, 0.2, (330, 250), (0.02, -0.02)), (480, 640)),
    "upside down": (grid_homography(48, math.pi + 0.05, (300, 230)), (480, 640)),
    "quarter turn, portrait": (grid_homography(56, math.pi / 2, (240, 330)), (640, 480)),
    "mirrored": (grid_homography(50, 0.1, (320, 240), mirror=True), (480, 640)),
    "small, off centre": (grid_homography(20, -0.1, (460, 150)), (480, 640)),
}


def scene(h: np.ndarray, size: tuple[int, int], patch_linear: np.ndarray = LINEAR,
          seed: int = 0) -> np.ndarray:
    """A linear image: the chart (dark frame, 0.84-pitch patches) on a grey, noisy table."""
    height, width = size
    chart = draw_chart(patch_linear, h=h, size=size, background=0.02)
    frame = draw_chart(np.ones((24, 3)), h=h, size=size, background=0.0, patch_fraction=2.4)
    rng = np.random.default_rng(seed)
    table = 0.25 * (1.0 + 0.1 * rng.standard_normal((height, width, 1))) * np.ones(3)
    on_chart = frame.max(axis=-1, keepdims=True) > 0
    return np.where(on_chart, chart, table)


@pytest.mark.parametrize("case", list(CASES))
def test_corners_found_in_every_orientation(case):
    h, size = CASES[case]
    truth = map_points(h, GRID_CORNERS)
    pitch = float(np.linalg.norm(truth[1] - truth[0]) / 5)
    found = find_chart(scene(h, size))
    err = np.linalg.norm(found.corners - truth, axis=-1).max()
    assert err < 0.03 * pitch, (case, found.corners.tolist(), truth.tolist())
    assert found.swatches >= 6 and found.candidates >= 1


def test_small_chart_in_a_large_image_is_searched_in_tiles_and_refined_on_a_crop():
    # 180 px wide in a 2400 px frame: too small at the detector's 1440 px working width
    h = grid_homography(30, -0.15, (1900, 500))
    found = find_chart(scene(h, (1800, 2400)))
    truth = map_points(h, GRID_CORNERS)
    assert np.linalg.norm(found.corners - truth, axis=-1).max() < 0.03 * 30
    x0, y0, x1, y1 = found.region
    assert (x1 - x0) < 400 and (y1 - y0) < 400  # the answer came from the chart's surroundings
    assert x0 <= truth[:, 0].min() and truth[:, 0].max() <= x1


def test_hdr_input_with_bad_pixels_and_the_audit_it_feeds():
    h, size = CASES["tilted with perspective"]
    camera = apply_transform(CHART.srgb, "saturation-inc", 1.2)  # a camera with colour error
    img = scene(h, size, cm.linearize_srgb(camera)) * 900.0  # HDR scale
    img[5:40, 5:40] = np.nan
    img[300:310, 10:20, 1] = np.inf
    found = measure_pixels(img, None, encoding="linear", reference="safecolor")
    given = measure_pixels(img, map_points(h, GRID_CORNERS), encoding="linear", reference="safecolor")
    assert found.detection is not None and given.detection is None
    assert found.mean_delta_e == pytest.approx(given.mean_delta_e, abs=1e-9)
    assert found.mean_delta_e == pytest.approx(expected_delta_e(np.clip(camera, 0, 1), CHART.lab),
                                               abs=0.02)
    assert found.to_json()["detection"]["corners_text"].count(",") == 7


def test_srgb_png_through_the_cli_prints_the_corners_it_found(tmp_path):
    h, size = CASES["upside down"]
    path = tmp_path / "photo.png"
    stored = write_png8(path, cm.delinearize_srgb(scene(h, size)))
    r = CliRunner().invoke(main, ["audit", str(path), "--json", str(tmp_path / "a.json"),
                                  "--html", str(tmp_path / "a.html")])
    assert r.exit_code == 0, r.output
    page = (tmp_path / "a.html").read_text()
    assert "Where the patches were sampled" in page and 'aria-label="sampling windows"' in page
    doc = json.loads((tmp_path / "a.json").read_text())
    found = doc["source"]["corners_found"]
    assert found["method"] == "segmentation"
    truth = map_points(h, GRID_CORNERS)
    assert np.abs(np.array(found["corners"]) - truth).max() < 1.0
    # the --corners it prints are the corners found, rounded; given back, they audit the same
    text = found["corners_text"]
    assert f"--corners {text}" in r.stdout
    printed = np.array([float(v) for v in text.split(",")]).reshape(4, 2)
    np.testing.assert_allclose(printed, found["corners"], atol=0.05 + 1e-9)
    again = CliRunner().invoke(main, ["audit", str(path), "--corners", text, "--json",
                                      str(tmp_path / "b.json")])
    assert again.exit_code == 0
    given = json.loads((tmp_path / "b.json").read_text())
    assert given["source"]["corners_found"] is None
    assert given["mean_delta_e"] == pytest.approx(doc["mean_delta_e"], abs=1e-6)
    assert given["max_delta_e"] == pytest.approx(doc["max_delta_e"], abs=1e-6)
    assert given["worst_patch"] == doc["worst_patch"]
    del stored


def test_no_chart_is_a_clear_error(tmp_path):
    rng = np.random.default_rng(3)
    noise = rng.uniform(0, 1, (300, 400, 3))
    with pytest.raises(InvalidValueError, match="no colour chart found"):
        find_chart(noise)
    with pytest.raises(InvalidValueError, match="the image is black"):
        find_chart(np.zeros((50, 60, 3)))
    with pytest.raises(UnknownNameError, match="chart detection method"):
        find_chart(noise, method="neural")
    path = tmp_path / "table.exr"
    write_exr(path, noise.astype(np.float32))
    r = CliRunner().invoke(main, ["gate", str(path), "--max-delta-e", "3"])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"fidelity: error: {path}: ")
    assert "--corners" in lines[0]


def test_colour_order_prefers_the_right_order_over_any_plausible_camera_error():
    from scipy.stats import spearmanr

    right = apply_transform(CHART.srgb, "hue", 20.0)  # ΔE of several units
    right = cm.linearize_srgb(np.clip(right, 0, 1)) * 3.0 * np.array([1.0, 0.8, 0.5])  # light
    grid = np.arange(24).reshape(4, 6)
    good = colour_order(right, LINEAR, trim=0)
    # the classic formula is Spearman's correlation (scipy), up to near-ties
    feats = [np.c_[x, np.log(x[:, :1] + 2e-3) - np.log(x[:, 1:2] + 2e-3),
                   np.log(x[:, 2:3] + 2e-3) - np.log(x[:, 1:2] + 2e-3)] for x in (right, LINEAR)]
    expected = np.mean([spearmanr(feats[0][:, k], feats[1][:, k]).statistic for k in range(5)])
    assert good == pytest.approx(expected, abs=1e-3)  # ties (equal log ratios) aside
    assert good > 0.9
    for wrong in (grid[::-1, ::-1], grid[:, ::-1], grid[::-1, :], np.roll(grid, 1, axis=0)):
        assert colour_order(right[wrong.ravel()], LINEAR) < 0.5


def test_homography_least_squares_from_many_points():
    h = np.array([[31.0, -4.0, 100.0], [6.0, 27.0, 40.0], [0.004, -0.01, 1.0]])
    uv = np.stack(np.meshgrid(np.arange(6.0), np.arange(4.0)), -1).reshape(-1, 2)
    xy = map_points(h, uv)
    np.testing.assert_allclose(homography_from_points(uv, xy), h, rtol=1e-9, atol=1e-12)
    # noise of 0.3 px on 24 points: the fitted map stays within the noise at the corners
    rng = np.random.default_rng(1)
    fit = homography_from_points(uv, xy + rng.normal(0, 0.3, xy.shape))
    assert np.abs(map_points(fit, GRID_CORNERS) - map_points(h, GRID_CORNERS)).max() < 0.6
    with pytest.raises(InvalidValueError, match="all on one line"):
        homography_from_points(np.c_[np.arange(6.0), np.zeros(6)], xy[:6])


def test_missing_opencv_is_a_clear_error_that_suggests_corners(monkeypatch):
    import sys

    from fidelity.core.errors import FidelityError

    monkeypatch.setitem(sys.modules, "cv2", None)  # import fails
    h, size = CASES["frontal"]
    with pytest.raises(FidelityError, match="OpenCV.*--corners"):
        find_chart(scene(h, size))
