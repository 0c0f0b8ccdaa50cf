"""The chart finder on the hard kinds of photo seen in use: a chart beside other square,
patch-like objects, a chart partly covered (a leaf, a hand), a frame after a camera ISP, and a
one-channel raw mosaic given without its CFA pattern.

Scenes come from :mod:`tests.fixtures.hard_scenes` (closed-form homography: the true corner patch
centres, and which patches an occluder covers, are known independently of fidelity.chart) on a
synthetic table, small enough to keep these tests fast. The covered chart is also drawn here
directly (a leaf polygon over the white and neutral 8 patches) and audited through the CLI.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.bayer import BAYER_MARGIN, bayer_pattern
from fidelity.chart.find import (
    FoundChart,
    cascade,
    find_chart,
    make_view,
    occluded_patches,
    sample_cells,
)
from fidelity.chart.locate import homography_from_points
from fidelity.chart.read import ReadOptions
from fidelity.cli import main
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_chart
from fidelity.core.errors import InvalidValueError
from fidelity.measure.pixels import measure_image, measure_pixels
from tests.chart.test_find import _mosaic, _write_mosaic_png16
from tests.fixtures.hard_scenes import hard_scene
from tests.pipeline.test_audit import GRID_CORNERS, draw_chart, map_points, write_exr

LINEAR = cm.linearize_srgb(load_chart("safecolor").srgb)


def _error_in_pitches(found: FoundChart, scene) -> float:
    return float(np.linalg.norm(found.corners - scene.corners, axis=-1).max() / scene.pitch_px)


@pytest.mark.parametrize("seed", [0, 3])
def test_a_chart_beside_tiles_a_checkerboard_and_a_grey_card_is_measured_not_refused(seed):
    # seed 0: tiles on the chart's own grid just beyond its frame; seed 3: a board of tiles
    # whose lattice merges with the chart's (both were refused as an SG before)
    scene = hard_scene("distractors", None, LINEAR, seed=(7, seed), long_side=900)
    found = find_chart(scene.srgb.astype(np.float32) / 255.0, encoding="srgb")
    assert _error_in_pitches(found, scene) < 0.05
    assert found.occluded == ()


def _leaf_over_white_and_neutral_8(seed: int = 0, leaf: bool = True):
    h = np.array([[52.0, 4.0, 70.0], [-2.0, 50.0, 60.0], [0.0, 0.0, 1.0]])
    linear = draw_chart(LINEAR * 0.85, h=h, size=(300, 420), background=0.04)
    centres = map_points(h, np.array([[0.0, 3.0], [1.0, 3.0]]))  # white, neutral 8
    a, b = centres
    axis = (b - a) / np.linalg.norm(b - a)
    normal = np.array([-axis[1], axis[0]])
    t = np.linspace(-1, 1, 40)
    mid = (a + b) / 2
    half, width = 1.05 * 52, 0.45 * 50
    across = width * (1 - t ** 2) ** 0.8
    pts = np.concatenate([mid + (t * half)[:, None] * axis + across[:, None] * normal,
                          (mid + (t * half)[:, None] * axis - across[:, None] * normal)[::-1]])
    mask = np.zeros(linear.shape[:2], np.uint8)
    if leaf:
        cv2.fillPoly(mask, [np.rint(pts).astype(np.int32)], 1)
    rng = np.random.default_rng(seed)
    colour = np.array([0.04, 0.09, 0.02]) * (1 + 0.3 * rng.standard_normal(linear.shape[:2] + (1,)))
    out = np.where(mask[..., None] > 0, np.clip(colour, 0, 1), linear)
    return out.astype(np.float32), map_points(h, GRID_CORNERS)


def test_a_leaf_over_two_neutral_patches_is_found_and_the_two_are_named_and_left_out(tmp_path):
    pixels, corners = _leaf_over_white_and_neutral_8()
    found = find_chart(pixels)
    assert np.abs(found.corners - corners).max() < 0.5
    assert found.occluded == (18, 19)
    path = tmp_path / "leaf.exr"
    write_exr(path, pixels)
    r = CliRunner().invoke(main, ["audit", str(path), "--json", str(tmp_path / "a.json")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "a.json").read_text())
    assert report["source"]["corners_found"]["occluded"] == [18, 19]
    left_out = [p["name"] for p in report["patches"] if not p["used"]]
    assert left_out == ["white 9.5", "neutral 8"]
    used = [p["delta_e"] for p in report["patches"] if p["used"]]
    assert report["mean_delta_e"] == pytest.approx(np.mean(used), abs=1e-9)
    assert report["max_delta_e"] == pytest.approx(max(used), abs=1e-9)
    # the covered patches measure far off; the 22 clear ones as on the chart without the leaf
    # (whose exposure is fitted on its six neutrals)
    all_de = [p["delta_e"] for p in report["patches"]]
    clean, _ = _leaf_over_white_and_neutral_8(leaf=False)
    clean_de = measure_pixels(clean, corners).measurement.delta_e
    assert min(all_de[18:20]) > 10
    assert np.abs(np.delete(np.array(all_de), [18, 19]) - np.delete(clean_de, [18, 19])).max() \
        < 0.3
    # with the corners given, nothing is left out: the user's corners are measured as given
    text = ",".join(f"{v:.3f}" for v in corners.ravel())
    r = CliRunner().invoke(main, ["audit", str(path), "--corners", text, "--json",
                                  str(tmp_path / "b.json")])
    assert r.exit_code == 0, r.output
    given = json.loads((tmp_path / "b.json").read_text())
    assert all(p["used"] for p in given["patches"]) and given["mean_delta_e"] > 2.0


@pytest.mark.parametrize("seed", [0, 2])
def test_an_occluder_from_the_scene_generator_is_named_with_the_patches_it_covers(seed):
    scene = hard_scene("occluder", None, LINEAR, seed=(7, seed), long_side=900)
    found = find_chart(scene.srgb.astype(np.float32) / 255.0, encoding="srgb")
    assert _error_in_pitches(found, scene) < 0.05
    truth = tuple(int(k) for k in str(scene.conditions["occluded"]).split(","))
    # a textured cover is named and left out; a cover as flat as a patch cannot be told from
    # the camera's own error in that patch: it is measured, and a note names it
    assert set(found.occluded) <= set(truth)
    flat = [k for k in truth if k not in found.occluded]
    if flat:
        note = next(n for n in found.notes if "far from what the other patches predict" in n)
        assert all(str(k + 1) in note for k in flat)
        assert set(flat) <= set(found.flat_off_fit)
    assert not set(found.flat_off_fit) & set(found.occluded)


def test_the_report_marks_patches_flagged_flat_and_far_off(tmp_path):
    # seed 0: a flat cover over patches 17 and 23 (0-based 16, 22), measured and flagged
    scene = hard_scene("occluder", None, LINEAR, seed=(7, 0), long_side=900)
    path = tmp_path / "occluded photo.png"
    cv2.imwrite(str(path), np.ascontiguousarray(scene.srgb[..., ::-1]))
    r = CliRunner().invoke(main, ["audit", str(path), "--json", str(tmp_path / "a.json"),
                                  "--html", str(tmp_path / "a.html")])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "a.json").read_text())
    flagged = doc["source"]["corners_found"]["flat_off_fit"]
    assert flagged == [16, 22] and all(doc["patches"][k]["used"] for k in flagged)
    html = (tmp_path / "a.html").read_text(encoding="utf-8")
    names = load_chart().patch_names
    for k in flagged:
        assert f"{k + 1} {names[k]} (flagged: far from what the other patches predict" in html
    assert html.count("(flagged: far from") == 2


def test_a_camera_colour_error_is_not_taken_for_an_occluder():
    # every patch off by a strong matrix and a tone curve, one patch far off in hue: the
    # camera's error, measured, not left out (the window is flat)
    h = np.array([[50.0, 0.0, 70.0], [0.0, 50.0, 60.0], [0.0, 0.0, 1.0]])
    m = np.array([[0.8, 0.3, -0.1], [0.1, 0.7, 0.2], [0.0, 0.25, 0.75]])
    patches = np.clip(LINEAR @ m.T, 0, None) ** 0.8
    patches[14] = patches[14][[1, 0, 2]]  # green rendered red-ish: a real camera error
    img = draw_chart(patches, h=h, size=(300, 420), background=0.03)
    grid = np.stack(np.meshgrid(np.arange(6), np.arange(4)), -1).reshape(-1, 2).astype(float)
    view, _ = make_view(img, (0, 0, 420, 300), 1000, "linear")
    means, spread = sample_cells(view, homography_from_points(GRID_CORNERS, map_points(
        h, GRID_CORNERS)), grid)
    assert not occluded_patches(means, spread).any()
    assert find_chart(img).occluded == ()


def test_an_isp_frame_is_fitted_within_a_tenth_of_a_pitch():
    # local tone mapping (CLAHE) and unsharp-mask halos on a 1920 x 1080 dashcam frame
    errors = []
    for seed in (0,):
        scene = hard_scene("isp", None, LINEAR, seed=(7, seed))
        found = find_chart(scene.srgb.astype(np.float32) / 255.0, encoding="srgb")
        errors.append(_error_in_pitches(found, scene))
    assert max(errors) < 0.1, errors


def _chart_mosaic(pattern: str) -> tuple[np.ndarray, np.ndarray]:
    h = np.array([[40.0, 2.0, 60.0], [-3.0, 38.0, 50.0], [0.0, 0.0, 1.0]])
    linear = draw_chart(LINEAR * 0.8, h=h, size=(220, 320), background=0.05)
    return _mosaic(linear, pattern), map_points(h, GRID_CORNERS)


@pytest.mark.parametrize("pattern", ["BGGR", "GRBG"])
def test_a_mosaic_without_bayer_is_audited_with_the_one_pattern_its_chart_fits(tmp_path,
                                                                                pattern):
    mosaic, corners = _chart_mosaic(pattern)
    path = tmp_path / "raw.png"
    _write_mosaic_png16(path, mosaic)
    fit = bayer_pattern(mosaic)
    assert fit.pattern == pattern and fit.margin >= BAYER_MARGIN
    r = CliRunner().invoke(main, ["audit", str(path), "--json", str(tmp_path / "a.json")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "a.json").read_text())
    assert report["source"]["bayer"] == pattern and report["source"]["bayer_found"] is True
    assert np.abs(np.array(report["source"]["corners"]) - corners).max() < 1.0
    given = measure_image(path, corners, read=ReadOptions(bayer=pattern))
    assert report["mean_delta_e"] == pytest.approx(given.mean_delta_e, abs=0.05)


def test_a_grey_mosaic_and_an_ambiguous_fit_keep_the_clear_error(tmp_path, monkeypatch):
    # a chart seen in grey: every pattern gives greys, none fits: exit 2 naming --bayer
    mosaic, _ = _chart_mosaic("RGGB")
    grey = np.repeat(mosaic[..., None], 3, axis=-1).mean(axis=-1)
    grey = cv2.blur(grey, (2, 2))
    path = tmp_path / "grey.png"
    _write_mosaic_png16(path, grey)
    r = CliRunner().invoke(main, ["audit", str(path)])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--bayer" in lines[0] and str(path) in lines[0]
    # two patterns fitting within the margin: no answer
    scores = iter([0.95, 0.95 - BAYER_MARGIN / 2, 0.0, 0.0])

    def fake(pixels, **_):
        c = next(scores)
        if c == 0.0:
            raise InvalidValueError("no colour chart found")
        return FoundChart(corners=np.zeros((4, 2)), method="x", candidates=1, swatches=0,
                          residual_px=float("nan"), confidence=c)

    monkeypatch.setattr(cascade, "find_chart", fake)
    fit = bayer_pattern(mosaic)
    assert fit.pattern is None and fit.margin == pytest.approx(BAYER_MARGIN / 2)
    scores = iter([0.0, 0.95, 0.95 - 1.5 * BAYER_MARGIN, 0.0])
    assert bayer_pattern(mosaic).pattern == "BGGR"


def test_a_chart_with_more_than_four_patches_covered_is_refused_with_its_corners():
    h = np.array([[52.0, 4.0, 70.0], [-2.0, 50.0, 60.0], [0.0, 0.0, 1.0]])
    linear = draw_chart(LINEAR * 0.85, h=h, size=(300, 420), background=0.04)
    # a hand over the six patches of the first three columns of the two top rows
    outline = map_points(h, np.array([[-0.45, -0.45], [2.45, -0.45], [2.45, 1.45],
                                      [-0.45, 1.45]]))
    mask = np.zeros(linear.shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.rint(outline).astype(np.int32)], 1)
    rng = np.random.default_rng(1)
    skin = np.array([0.5, 0.3, 0.2]) * (1 + 0.2 * rng.standard_normal(linear.shape[:2] + (1,)))
    img = np.where(mask[..., None] > 0, np.clip(skin, 0, 1), linear).astype(np.float32)
    with pytest.raises(InvalidValueError, match="look covered.*--corners"):
        find_chart(img)


@pytest.mark.parametrize("size", [(1, 1), (5, 7)])
def test_a_tiny_one_channel_image_without_bayer_is_one_clear_error(size, tmp_path):
    """A one-channel image of a few pixels (a fuzzed 1 x 1 half-float EXR gave exit 3 in the
    demosaicing): the one-line error naming --bayer, exit 2."""
    import OpenImageIO as oiio

    path = tmp_path / "tiny.exr"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(size[1], size[0], 1, "half"))
    out.write_image(np.full((*size, 1), 0.35, np.float16))
    out.close()
    r = CliRunner().invoke(main, ["audit", str(path), "--corners", "8,8,80,8,80,56,8,56"])
    assert r.exit_code == 2, r.output
    assert "--bayer" in r.output and len(r.output.strip().splitlines()) == 1


@pytest.mark.parametrize(("sigma", "seed"), [(0.08, 0), (0.08, 1), (0.10, 2)])
def test_a_chart_under_heavy_noise_is_found_where_it_was_drawn(sigma, seed):
    """Issue 55: Gaussian noise of sigma 0.08 (and 0.10) of full scale on the 8-bit codes of a
    640 px chart was refused as "uniformity 0.18". The uniformity check looks for a grid off
    the patches, so it discounts white noise (structured_spread): the chart is found with its
    corners within a tenth of a pitch."""
    h = np.array([[96.0, 3.0, 60.0], [-2.0, 95.0, 50.0], [0.0, 0.0, 1.0]])
    linear = draw_chart(LINEAR * 0.85, h=h, size=(434, 640), background=0.04)
    codes = cm.delinearize_srgb(np.clip(linear, 0.0, 1.0))
    noisy = np.clip(codes + np.random.default_rng(seed).normal(0.0, sigma, codes.shape), 0, 1)
    img = np.round(noisy * 255).astype(np.uint8).astype(np.float32) / 255.0
    found = find_chart(img, encoding="srgb")
    truth = map_points(h, np.array(GRID_CORNERS, np.float64))
    assert np.abs(found.corners - truth).max() < 0.1 * 96
    assert found.checks.uniformity <= cascade.MAX_UNIFORMITY


def test_the_uniformity_discounts_white_noise_not_a_window_across_a_patch_edge():
    """structured_spread: a flat window under independent noise has (about) none left; a
    window straddling an edge keeps its step's standard deviation, noisy or not."""
    from fidelity.chart.find.placement import structured_spread

    rng = np.random.default_rng(5)
    k = 5
    flat = 0.4 + rng.normal(0.0, 0.08, (2000, k, k, 1))
    assert float(np.median(structured_spread(flat))) < 0.4 * 0.08  # was all of it, 0.08
    step = np.where(np.arange(k) < k // 2, 0.2, 0.6)[None, None, :, None]  # across the window
    edge = np.broadcast_to(step, (1, k, k, 1))
    expected = float(np.std(edge))
    np.testing.assert_allclose(structured_spread(edge), expected, rtol=1e-12)
    noisy_edge = edge + rng.normal(0.0, 0.08, (2000, k, k, 1))
    assert abs(float(np.median(structured_spread(noisy_edge))) - expected) < 0.25 * expected
