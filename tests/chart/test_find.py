"""The chart finder's cascade: verification against the 24-patch layout, chart variants, raw
Bayer frames and the trust checks of the audit.

Scenes come from :mod:`tests.fixtures.chart_scenes` (a chart texture composited through a
homography built in closed form from a tilt, a turn and a pinhole projection, so the true
corner-patch centres are known independently of fidelity.chart), on a synthetic table, small
enough to keep these tests fast. The Bayer test mosaics an RGB image by the CFA definition
(every pixel keeps the one channel its filter passes) and compares the audit of the mosaic with
the audit of the RGB original.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.find import (
    MIN_CONFIDENCE,
    Quads,
    check_corners,
    find_chart,
    make_view,
    patch_side,
    perspective_bias,
    placement_scores,
)
from fidelity.chart.read import ReadOptions
from fidelity.cli import main
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_chart
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.measure.pixels import measure_image, measure_pixels
from tests.fixtures.chart_scenes import corners_correct, make_scene
from tests.pipeline.test_audit import GRID_CORNERS, draw_chart, map_points, write_exr

CHART = load_chart("safecolor")
LINEAR = cm.linearize_srgb(CHART.srgb)


def _scene(kind: str, seed: int, side: int = 900):
    scene = make_scene(kind, None, LINEAR, seed=(19, seed), long_side=side, jpeg=True,
                       hard=False)
    return scene.srgb.astype(np.float32) / 255.0, scene


@pytest.mark.parametrize("kind,seed", [("classic", 1), ("classic", 2), ("mini", 3)])
def test_composited_chart_is_found_within_a_tenth_of_a_pitch(kind, seed):
    pixels, scene = _scene(kind, seed)
    found = find_chart(pixels, encoding="srgb")
    err = np.linalg.norm(found.corners - scene.corners, axis=-1).max() / scene.pitch_px
    assert err < 0.1, (kind, seed, err, scene.conditions)
    assert found.confidence >= MIN_CONFIDENCE and found.checks is not None
    assert found.checks.neutral_order >= 0.8 and found.other_charts == 0


def test_a_candidate_one_row_off_is_corrected_and_given_corners_one_row_off_are_flagged():
    pixels, scene = _scene("classic", 4)
    view, _ = make_view(pixels, (0, 0, pixels.shape[1], pixels.shape[0]), 2000, "srgb")
    # the true grid -> view map, from the truth alone
    from fidelity.chart.locate import homography_from_points

    truth_view = scene.corners  # view = image here (no shrinking)
    grid_to_view = homography_from_points(GRID_CORNERS, truth_view)
    grid = np.stack(np.meshgrid(np.arange(6), np.arange(4)), -1).reshape(-1, 2)
    # a detector that claims the chart one row lower: the 24 cells it reports are shifted
    placement = placement_scores(view, grid_to_view, grid + (0, 1), "test")
    assert placement is not None
    corners = map_points(placement.homography, GRID_CORNERS)
    assert corners_correct(corners, scene.corners, scene.pitch_px, 0.05)
    # measured as given, the shifted placement is rejected: low order, another fits better
    shifted = placement_scores(view, grid_to_view, grid + (0, 1), "test", given=True)
    assert shifted is not None
    assert shifted.checks.colour_order < MIN_CONFIDENCE and shifted.checks.margin < 0
    off = map_points(grid_to_view, GRID_CORNERS + (0, 1))
    checks = check_corners(pixels, off, encoding="srgb")
    assert checks is not None and checks.margin < 0
    right = check_corners(pixels, scene.corners, encoding="srgb")
    assert right is not None and right.margin > 0.15 and right.colour_order > 0.9


def test_passport_gives_the_24_patch_chart_and_says_there_is_another():
    pixels, scene = _scene("passport", 5, side=1000)
    found = find_chart(pixels, encoding="srgb")
    assert corners_correct(found.corners, scene.corners, scene.pitch_px, 0.1)
    assert found.other_charts >= 1 and "Passport" in found.chart
    assert any("Passport" in note for note in found.notes)


def test_an_sg_like_140_patch_chart_is_refused_not_measured():
    pixels, _ = _scene("sg", 6, side=1000)
    with pytest.raises(InvalidValueError, match="24-patch.*SG|SG.*24-patch"):
        find_chart(pixels, encoding="srgb")


def _write_mosaic_png16(path, mosaic):
    import OpenImageIO as oiio

    q = np.clip(np.rint(mosaic * 65535), 0, 65535).astype(np.uint16)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(q.shape[1], q.shape[0], 1, "uint16"))
    assert out.write_image(np.ascontiguousarray(q[..., None]))
    out.close()


def _mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """Keep, at every pixel, the channel its colour filter passes (``pattern``: top-left 2x2)."""
    index = {"R": 0, "G": 1, "B": 2}
    out = np.empty(rgb.shape[:2])
    for k, colour in enumerate(pattern):
        dy, dx = divmod(k, 2)
        out[dy::2, dx::2] = rgb[dy::2, dx::2, index[colour]]
    return out


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG"])
def test_bayer_mosaic_is_demosaiced_and_measures_like_the_rgb_original(tmp_path, pattern):
    h = np.array([[40.0, 2.0, 60.0], [-3.0, 38.0, 50.0], [0.0, 0.0, 1.0]])
    linear = draw_chart(LINEAR * 0.8, h=h, size=(220, 320), background=0.05)
    corners = map_points(h, GRID_CORNERS)
    rgb_path, raw_path = tmp_path / "rgb.exr", tmp_path / "raw.png"
    write_exr(rgb_path, linear.astype(np.float32))
    _write_mosaic_png16(raw_path, _mosaic(linear, pattern))
    rgb = measure_image(rgb_path, corners)
    raw = measure_image(raw_path, corners, read=ReadOptions(bayer=pattern.lower()))
    assert raw.image is not None and raw.image.bayer == pattern
    assert raw.encoding == "linear"
    assert raw.mean_delta_e == pytest.approx(rgb.mean_delta_e, abs=0.05)
    assert np.abs(raw.measurement.delta_e - rgb.measurement.delta_e).max() < 0.3
    # the CLI takes --bayer on audit and gate, and finds the chart in the demosaiced frame
    r = CliRunner().invoke(main, ["audit", str(raw_path), "--bayer", pattern,
                                  "--json", str(tmp_path / "a.json")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "a.json").read_text())
    found = report["source"]["corners_found"]
    assert np.abs(np.array(found["corners"]) - corners).max() < 1.0
    g = CliRunner().invoke(main, ["gate", str(raw_path), "--bayer", pattern,
                                  "--corners", ",".join(map(str, corners.ravel())),
                                  "--max-delta-e", "100"])
    assert g.exit_code == 0, g.output


def test_one_channel_image_without_bayer_is_exit_2_naming_the_option(tmp_path):
    path = tmp_path / "raw.png"
    _write_mosaic_png16(path, np.random.default_rng(0).uniform(0, 1, (40, 60)))
    for command in (["audit", str(path)], ["gate", str(path), "--max-delta-e", "3"]):
        r = CliRunner().invoke(main, command)
        assert r.exit_code == 2
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "--bayer" in lines[0] and str(path) in lines[0]
    rgb = tmp_path / "rgb.exr"
    write_exr(rgb, np.ones((10, 12, 3), np.float32))
    with pytest.raises(InputFileError, match="one-channel mosaic"):
        measure_image(rgb, read=ReadOptions(bayer="RGGB"))


def test_low_confidence_fit_is_an_error_unless_corners_are_given(tmp_path):
    # a 4 x 6 grid of patches in the wrong order: chart-like, but not the chart's layout
    h = np.array([[50.0, 0.0, 70.0], [0.0, 50.0, 60.0], [0.0, 0.0, 1.0]])
    order = np.random.default_rng(2).permutation(24)
    img = draw_chart(LINEAR[order], h=h, size=(300, 420), background=0.02)
    with pytest.raises(InvalidValueError, match="--corners"):
        find_chart(img)
    path = tmp_path / "shuffled.exr"
    write_exr(path, img.astype(np.float32))
    r = CliRunner().invoke(main, ["audit", str(path)])
    assert r.exit_code == 2 and "--corners" in r.stderr
    corners = ",".join(f"{v:.3f}" for v in map_points(h, GRID_CORNERS).ravel())
    r = CliRunner().invoke(main, ["audit", str(path), "--corners", corners,
                                  "--json", str(tmp_path / "s.json")])
    assert r.exit_code == 0, r.output
    checks = json.loads((tmp_path / "s.json").read_text())["source"]["corner_checks"]
    assert checks["colour_order"] < 0.5


def test_audit_json_has_the_corner_centres_and_a_confidence():
    pixels, scene = _scene("classic", 7)
    result = measure_pixels(pixels, None, encoding="srgb")
    d = result.to_json()["detection"]
    assert 0.0 <= d["confidence"] <= 1.0 and d["confidence"] >= MIN_CONFIDENCE
    assert np.abs(np.array(d["corners"]) - scene.corners).max() < 0.1 * scene.pitch_px
    assert d["chart"].startswith("24-patch") and d["checks"]["neutral_order"] >= 0.8


@pytest.mark.parametrize("encoding", ["srgb", "linear"])
def test_a_view_is_the_image_scaled_by_its_peak_and_encoded_to_8_bit_bgr(encoding):
    """A view at full size, against the definition written out here: sRGB codes decoded to the
    nearest of 65536 steps (the sRGB formula of IEC 61966-2-1), divided by the 99th percentile
    of the brightest channel and clipped, then the nearest of 4096 linear steps encoded to
    8-bit sRGB in B, G, R order; with the hard values: below 0, above 1, NaN, Inf."""
    rng = np.random.default_rng(7)
    pixels = rng.random((37, 53, 3)).astype(np.float32)
    pixels[0, :6, 0] = [-0.5, 0.0, 1.0, 1.5, np.nan, np.inf]
    view, peak = make_view(pixels, (0, 0, 53, 37), 53, encoding)

    def srgb_to_linear(v):
        return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)

    def linear_to_srgb(v):
        return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)

    clean = np.nan_to_num(pixels.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if encoding == "srgb":
        lin = srgb_to_linear(np.rint(np.clip(clean, 0, 1) * 65535) / 65535)
    else:
        lin = np.maximum(clean, 0.0)
    assert peak == pytest.approx(np.percentile(lin.max(axis=-1), 99.0), rel=1e-6)
    linear = np.clip(lin / peak, 0.0, 1.0)
    # within one of the 65536 decoding steps (single precision rounds some onto the next)
    np.testing.assert_allclose(view.linear, linear, atol=5e-5)
    codes = np.rint(255 * linear_to_srgb(np.floor(linear * 4095 + 0.5) / 4095))
    assert view.bgr8.dtype == np.uint8 and view.bgr8.flags.c_contiguous
    near = np.abs(view.bgr8[..., ::-1].astype(int) - codes)
    assert near.max() <= 1 and (near == 0).mean() > 0.99  # float32 steps at a code boundary
    np.testing.assert_array_equal(view.to_image, np.eye(3))


def test_perspective_bias_moves_outline_centroids_onto_the_patch_centres() -> None:
    # Closed form: a homography maps a square's centre to the crossing of its image's
    # diagonals, not to the image's centroid; centroid less bias is the mapped centre.
    h = np.array([[130.0, 20.0, 400.0], [-10.0, 90.0, 250.0], [0.12, -0.05, 1.0]])  # grid->px
    cells = np.array([[0.0, 0.0], [5.0, 3.0], [2.0, 1.0]])
    side = 0.8
    half = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * side / 2
    squares = cells[:, None, :] + half
    img = cv2.perspectiveTransform(squares.reshape(1, -1, 2), h).reshape(-1, 4, 2)
    centroids = []
    for q in img:
        m = cv2.moments(q.astype(np.float32))
        centroids.append([m["m10"] / m["m00"], m["m01"] / m["m00"]])
    want = cv2.perspectiveTransform(cells[None], h)[0]
    bias = perspective_bias(h, cells, side)
    np.testing.assert_allclose(np.array(centroids) - bias, want, atol=1e-3)  # float32 moments
    assert np.max(np.abs(np.array(centroids) - want)) > 1.0  # the bias is real: pixels
    # the side comes back from the outlines; an affine map has no bias
    quads = Quads(img, np.array(centroids), np.ones(len(img)))
    assert patch_side(h, quads, np.arange(len(img))) == pytest.approx(side, rel=1e-9)
    affine = np.array([[130.0, 20.0, 400.0], [-10.0, 90.0, 250.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(perspective_bias(affine, cells, side), 0.0, atol=1e-12)
    # a degenerate homography gives no NaN
    assert np.all(np.isfinite(perspective_bias(np.zeros((3, 3)), cells, side)))


@pytest.mark.parametrize("degrees, shown", [(-0.2, "turned 0 degrees"), (0.2, "turned 0 degrees"),
                                            (-90.0, "turned -90 degrees"),
                                            (179.8, "turned 180 degrees")])
def test_orientation_never_reads_minus_zero(degrees, shown) -> None:
    """A chart turned by a fraction of a degree either way reads "turned 0 degrees"."""
    from fidelity.chart.find.cascade import _orientation

    a = np.radians(degrees)
    rot = np.array([[np.cos(a), -np.sin(a), 100.0], [np.sin(a), np.cos(a), 50.0], [0, 0, 1]])
    assert _orientation(rot @ np.diag([40.0, 40.0, 1.0])) == shown
