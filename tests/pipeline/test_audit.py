"""Audit of synthetic chart images: known transform, known homography, known exposure.

The images are drawn here, independently of fidelity.chart.locate: every pixel is mapped back to chart
grid coordinates through the inverse of a known homography and given the colour of the patch it
falls in. The expected chart ΔE is computed with colour-science (a second implementation of
sRGB -> XYZ -> Lab -> CIEDE2000), PNGs are written with Pillow and EXRs with the OpenEXR module.
"""

from __future__ import annotations

import math
from pathlib import Path

import colour
import numpy as np
import OpenEXR
import pytest
from PIL import Image as PILImage

from fidelity.chart.read import ReadOptions
from fidelity.colour.charts import load_chart
from fidelity.core.errors import FidelityError, InvalidValueError, UnknownNameError
from fidelity.measure import pixels as _measure
from fidelity.measure.pixels import exposure_from_neutrals
from fidelity.prediction.transforms import apply_transform


def measure_image(*args, **kwargs):
    """The audits here compare with the paper's chart (chart.lab) unless a test says otherwise."""
    kwargs.setdefault("reference", "safecolor")
    return _measure.measure_image(*args, **kwargs)


def measure_pixels(*args, **kwargs):
    kwargs.setdefault("reference", "safecolor")
    return _measure.measure_pixels(*args, **kwargs)

#: A known homography grid (u, v) -> image (x, y): rotation, anisotropic scale, perspective.
KNOWN_H = np.array([
    [30.0 * math.cos(0.12), -27.0 * math.sin(0.12), 60.0],
    [30.0 * math.sin(0.12), 27.0 * math.cos(0.12), 50.0],
    [0.012, -0.018, 1.0],
])
GRID_CORNERS = np.array([[0, 0], [5, 0], [5, 3], [0, 3]], dtype=float)


def map_points(h: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Apply a homography to (n, 2) points (closed form, for the tests)."""
    p = np.c_[uv, np.ones(len(uv))] @ h.T
    return p[:, :2] / p[:, 2:]


def draw_chart(patch_rgb: np.ndarray, h: np.ndarray = KNOWN_H, size: tuple[int, int] = (260, 300),
               background: float = 0.05, patch_fraction: float = 0.84) -> np.ndarray:
    """An (H, W, 3) image of a 4x6 chart with flat patches seen through homography ``h``."""
    height, width = size
    yy, xx = np.mgrid[0:height, 0:width].astype(float)
    uv = map_points(np.linalg.inv(h), np.c_[xx.ravel(), yy.ravel()])
    col, row = np.rint(uv[:, 0]), np.rint(uv[:, 1])
    inside = ((np.abs(uv[:, 0] - col) <= patch_fraction / 2) & (np.abs(uv[:, 1] - row) <= patch_fraction / 2)
              & (col >= 0) & (col <= 5) & (row >= 0) & (row <= 3))
    img = np.full((height * width, 3), background, dtype=np.float64)
    idx = (row[inside] * 6 + col[inside]).astype(int)
    img[inside] = patch_rgb[idx]
    return img.reshape(height, width, 3)


def corners_of(h: np.ndarray = KNOWN_H) -> str:
    """The --corners string of the dark skin, bluish green, black, white centres."""
    return ",".join(f"{v:.4f}" for v in map_points(h, GRID_CORNERS).ravel())


def expected_delta_e(srgb: np.ndarray, reference_lab: np.ndarray) -> float:
    """Mean CIEDE2000 by colour-science (independent of fidelity.colour.colorimetry)."""
    xyz = colour.sRGB_to_XYZ(srgb)
    lab = colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    return float(np.mean(colour.delta_E(lab, reference_lab, method="CIE 2000")))


def write_png8(path: Path, srgb: np.ndarray) -> np.ndarray:
    """Write 8-bit PNG with Pillow; return the stored values in [0, 1]."""
    q = np.clip(np.rint(srgb * 255.0), 0, 255).astype(np.uint8)
    PILImage.fromarray(q, mode="RGB").save(path)
    return q.astype(np.float64) / 255.0


def write_exr(path: Path, linear: np.ndarray, channels: tuple[str, ...] = ("R", "G", "B"),
              dtype: type = np.float32) -> None:
    """Write an EXR with the OpenEXR module, one channel per name."""
    data = {name: np.ascontiguousarray(linear[..., i]).astype(dtype) for i, name in enumerate(channels)}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, data).write(str(path))


@pytest.fixture(scope="module")
def chart():
    return load_chart("safecolor")


def test_identity_chart_png_measures_the_known_baseline(tmp_path, chart):
    write_png8(tmp_path / "c.png", draw_chart(chart.srgb))
    result = measure_image(tmp_path / "c.png", corners_of())
    want = expected_delta_e(np.rint(chart.srgb * 255) / 255, chart.lab)
    assert result.exposure_ev == 0.0 and result.exposure_mode == "fixed"
    assert result.encoding == "srgb"
    assert abs(result.mean_delta_e - want) < 0.02


@pytest.mark.parametrize("name,param", [("contrast-inc", 1.35), ("saturation-dec", 0.55),
                                        ("gamma-inc", 1.4), ("hue", 12.0)])
def test_transformed_chart_png(tmp_path, chart, name, param):
    srgb = apply_transform(chart.srgb, name, param)
    write_png8(tmp_path / "c.png", draw_chart(srgb))
    result = measure_image(tmp_path / "c.png", corners_of())
    stored = np.rint(srgb * 255) / 255
    # the known ΔE is that of the chart as stored in 8 bit (rounding alone moves the float
    # chart's ΔE by up to about 0.2: the SAFE-COLOR data sets are 8-bit images too)
    assert abs(result.mean_delta_e - expected_delta_e(stored, chart.lab)) < 0.02
    per_patch = colour.delta_E(colour.XYZ_to_Lab(colour.sRGB_to_XYZ(stored)), chart.lab, method="CIE 2000")
    np.testing.assert_allclose(result.measurement.delta_e, per_patch, atol=0.02)


@pytest.mark.parametrize("name,param,scale", [("hue", 0.0, 0.2), ("hue", 20.0, 0.037),
                                              ("hue", -45.0, 5.3)])
def test_linear_exr_auto_exposure(tmp_path, chart, name, param, scale):
    """Hue rotation barely moves the (nearly achromatic) neutral patches, so auto exposure
    finds the scale: exactly for the untransformed chart, to 0.02 EV otherwise."""
    srgb = apply_transform(chart.srgb, name, param)
    linear = colour.cctf_decoding(draw_chart(srgb), function="sRGB") * scale
    write_exr(tmp_path / "c.exr", linear, dtype=np.float32)
    result = measure_image(tmp_path / "c.exr", corners_of())
    assert result.encoding == "linear" and result.exposure_mode == "auto"
    assert result.exposure_ev == pytest.approx(-math.log2(scale), abs=1e-5 if param == 0 else 0.02)
    assert abs(result.mean_delta_e - expected_delta_e(srgb, chart.lab)) < 0.02


def test_linear_exr_fixed_exposure(tmp_path, chart):
    """saturation-inc brightens the near-neutral patches a little (HSV), which auto exposure
    would take for exposure; a fixed EV measures the transform's ΔE exactly."""
    srgb = apply_transform(chart.srgb, "saturation-inc", 1.8)
    scale = 0.013
    write_exr(tmp_path / "c.exr", colour.cctf_decoding(draw_chart(srgb), function="sRGB") * scale)
    result = measure_image(tmp_path / "c.exr", corners_of(),
                           read=ReadOptions(exposure=-math.log2(scale)))
    assert abs(result.mean_delta_e - expected_delta_e(srgb, chart.lab)) < 0.02
    auto = measure_image(tmp_path / "c.exr", corners_of(), read=ReadOptions(exposure="auto"))
    assert abs(auto.exposure_ev + math.log2(scale)) < 0.03


def test_auto_exposure_absorbs_a_global_brightness_error(tmp_path, chart):
    linear = colour.cctf_decoding(draw_chart(chart.srgb), function="sRGB") * 1.5
    fixed = measure_pixels(linear, corners_of(), encoding="linear", exposure=0.0)
    auto = measure_pixels(linear, corners_of(), encoding="linear")
    assert auto.exposure_ev == pytest.approx(-math.log2(1.5), abs=1e-6)
    assert auto.mean_delta_e == pytest.approx(expected_delta_e(chart.srgb, chart.lab), abs=0.02)
    assert fixed.mean_delta_e > auto.mean_delta_e + 2.0


def test_linear_half_exr_fixed_exposure_with_layer(tmp_path, chart):
    srgb = apply_transform(chart.srgb, "contrast-dec", 0.7)
    scale = 11.0
    linear = colour.cctf_decoding(draw_chart(srgb), function="sRGB") * scale
    write_exr(tmp_path / "c.exr", np.concatenate([linear, linear * 0.5], axis=-1),
              channels=("beauty.R", "beauty.G", "beauty.B", "diffuse.R", "diffuse.G", "diffuse.B"),
              dtype=np.float16)
    result = measure_image(tmp_path / "c.exr", corners_of(),
                           read=ReadOptions(layer="beauty", exposure=-math.log2(scale)))
    assert result.exposure_mode == "fixed"
    assert abs(result.mean_delta_e - expected_delta_e(srgb, chart.lab)) < 0.02
    other = measure_image(tmp_path / "c.exr", corners_of(),
                          read=ReadOptions(layer="diffuse", exposure=-math.log2(scale) + 1.0))
    assert abs(other.mean_delta_e - result.mean_delta_e) < 0.02


def test_16bit_tiff_meets_the_float_chart(tmp_path, chart):
    import OpenImageIO as oiio

    srgb = apply_transform(chart.srgb, "gamma-dec", 0.8)
    img = np.rint(draw_chart(srgb) * 65535).astype(np.uint16)
    out = oiio.ImageOutput.create(str(tmp_path / "c.tif"))
    out.open(str(tmp_path / "c.tif"), oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint16"))
    out.write_image(img)
    out.close()
    result = measure_image(tmp_path / "c.tif", corners_of())
    assert result.encoding == "srgb"
    assert abs(result.mean_delta_e - expected_delta_e(srgb, chart.lab)) < 0.02


def test_bad_pixels_counted_and_excluded(chart):
    srgb = apply_transform(chart.srgb, "hue", 8.0)
    img = colour.cctf_decoding(draw_chart(srgb), function="sRGB")
    clean = measure_pixels(img, corners_of(), encoding="linear", exposure=0.0)
    dirty = img.copy()
    centres = map_points(KNOWN_H, np.array([[1.0, 1.0], [4.0, 2.0]]))  # purplish blue, magenta
    x, y = np.rint(centres[0]).astype(int)
    dirty[y, x] = [np.nan, 0.2, 0.2]
    dirty[y, x + 1] = [np.inf, 0.2, 0.2]
    x, y = np.rint(centres[1]).astype(int)
    dirty[y, x] = [0.2, -0.1, 0.2]
    dirty[0, 0] = np.nan  # outside every sampling window
    result = measure_pixels(dirty, corners_of(), encoding="linear", exposure=0.0,
                          negatives="exclude")
    bp = result.bad_pixels
    w = bp.window
    assert (w.nan, w.inf, w.negative, w.total) == (1, 1, 1, 3)
    assert bp.per_patch == {"purplish blue": 2, "magenta": 1}
    assert bp.image.total == 4
    assert result.mean_delta_e == pytest.approx(clean.mean_delta_e, abs=1e-9)
    # by default a negative value is counted but kept: NaN/Inf alone are excluded
    kept = measure_pixels(dirty, corners_of(), encoding="linear", exposure=0.0).bad_pixels
    assert (kept.window.negative, kept.window.total, kept.per_patch) == (1, 2, {"purplish blue": 2})


def test_negative_values_of_out_of_gamut_colours_are_kept_in_the_linear_mean(chart):
    # a scene-linear render of a colour outside sRGB: red below zero over the whole patch
    lin = colour.cctf_decoding(chart.srgb, function="sRGB")
    lin[17] = [-0.02, 0.18, 0.33]  # "cyan"
    img = draw_chart(lin)
    with pytest.raises(InvalidValueError, match="'cyan': only 0 of"):
        measure_pixels(img, corners_of(), encoding="linear", exposure=0.0, negatives="exclude")
    result = measure_pixels(img, corners_of(), encoding="linear", exposure=0.0)
    assert result.bad_pixels.window.negative == result.valid_pixels[17]
    assert "cyan" in result.clipped_patches
    # expected: the patch mean (flat) encoded as sRGB and clipped, by colour-science
    expected = np.clip(colour.cctf_encoding(np.clip(lin, 0, None), function="sRGB"), 0, 1)
    np.testing.assert_allclose(result.measurement.srgb, expected, atol=1e-9)
    assert result.mean_delta_e == pytest.approx(expected_delta_e(expected, chart.lab), abs=0.02)
    with pytest.raises(UnknownNameError, match="rule for negative values"):
        measure_pixels(img, corners_of(), negatives="clip")


def test_patch_with_too_few_valid_pixels_is_named(chart):
    img = colour.cctf_decoding(draw_chart(chart.srgb), function="sRGB")
    c = map_points(KNOWN_H, np.array([[2.0, 3.0]]))[0]  # neutral 6.5
    x, y = np.rint(c).astype(int)
    img[y - 12:y + 13, x - 12:x + 13] = np.nan
    with pytest.raises(InvalidValueError, match="neutral 6.5"):
        measure_pixels(img, corners_of(), encoding="linear")


def test_exposure_from_neutrals_recovers_scale(chart):
    lin = colour.cctf_decoding(chart.srgb, function="sRGB")
    assert exposure_from_neutrals(lin * 0.25, chart.lab, chart.neutral_indices) == pytest.approx(2.0, abs=1e-6)
    with pytest.raises(FidelityError, match="black"):
        exposure_from_neutrals(lin * 0.0, chart.lab, chart.neutral_indices, chart.patch_names)


def test_scene_reference_differs_from_paper_reference(tmp_path, chart):
    write_png8(tmp_path / "c.png", draw_chart(chart.srgb))
    paper = measure_image(tmp_path / "c.png", corners_of(), reference="safecolor")
    scene = measure_image(tmp_path / "c.png", corners_of(), reference="scene")
    assert scene.reference.name.startswith("scene")
    assert scene.mean_delta_e > paper.mean_delta_e  # BabelColor spectra differ from the paper's Lab
    with pytest.raises(FidelityError, match="unknown reference"):
        measure_image(tmp_path / "c.png", corners_of(), reference="no-such-chart")


def test_audit_dict_has_the_documented_keys(tmp_path, chart):
    write_png8(tmp_path / "c.png", draw_chart(chart.srgb))
    d = measure_image(tmp_path / "c.png", corners_of()).to_json()
    for key in ("mean_delta_e", "max_delta_e", "patches", "exposure_ev", "bad_pixels"):
        assert key in d
    assert len(d["patches"]) == 24
    assert {"delta_e", "delta_l", "delta_c", "delta_h"} <= set(d["patches"][0])
    assert len(d["image"]["sha256"]) == 64


def test_srgb_input_with_auto_exposure(tmp_path, chart):
    """An underexposed 8-bit image (linear light x 0.5 before encoding) is brought back by
    --exposure auto: EV = +1 and the ΔE of the properly exposed chart, within 8-bit rounding."""
    srgb = apply_transform(chart.srgb, "hue", 10.0)
    dark = colour.cctf_encoding(colour.cctf_decoding(srgb, function="sRGB") * 0.5, function="sRGB")
    write_png8(tmp_path / "dark.png", draw_chart(dark))
    fixed = measure_image(tmp_path / "dark.png", corners_of())
    auto = measure_image(tmp_path / "dark.png", corners_of(), read=ReadOptions(exposure="auto"))
    assert auto.exposure_mode == "auto" and auto.exposure_ev == pytest.approx(1.0, abs=0.02)
    assert fixed.exposure_ev == 0.0 and fixed.mean_delta_e > auto.mean_delta_e + 3
    assert abs(auto.mean_delta_e - expected_delta_e(srgb, chart.lab)) < 0.2  # 8-bit rounding x2
    # exactly: the stored 8-bit values, decoded, scaled by the found EV, encoded (colour-science)
    stored = np.rint(dark * 255) / 255
    lifted = colour.cctf_encoding(colour.cctf_decoding(stored, function="sRGB") * 2 ** auto.exposure_ev,
                                  function="sRGB")
    assert abs(auto.mean_delta_e - expected_delta_e(np.clip(lifted, 0, 1), chart.lab)) < 0.02
