"""Closed-form chart rendering, patch sampling, the render CLI; independent references are
colour-science colorimetry and closed-form expectations."""

from __future__ import annotations

import json

import colour
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from fidelity.camera.model import DEFAULT_CAMERA
from fidelity.camera.render import ChartLayout, patch_means, render_chart
from fidelity.cli import main
from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import WHITEPOINT_D65_XYZ, delta_e_2000
from fidelity.core.errors import UnknownNameError

SRGB_D65_XY = np.array([0.3127, 0.3290])


@pytest.mark.parametrize("spectra", ["BabelColor Average", "ColorChecker N Ohta"])
def test_ideal_camera_under_d65_is_exact(spectra: str) -> None:
    r = render_chart("ideal", "D65", spectra=spectra)
    assert r.measurement.mean_delta_e < 0.01
    assert r.renderer == "closed-form" and r.variant is None
    assert r.linear_image.dtype == np.float32 and r.display_image.dtype == np.float32
    assert r.linear_image.shape == r.display_image.shape and r.linear_image.shape[2] == 3


def _colour_expected_error_d65_balanced_under_a() -> float:
    """Second method: colour-science tristimulus under A, read as if D65 were the white, vs the
    Bradford-adapted reference."""
    shape = colour.SpectralShape(380, 780, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["A"].copy().align(shape, interpolator=colour.LinearInterpolator)
    sds = colour.SDS_COLOURCHECKERS["BabelColor Average"]
    xyz = np.array([
        colour.sd_to_XYZ(sd.copy().align(shape, interpolator=colour.LinearInterpolator,
                                         extrapolator_kwargs={"method": "Constant"}),
                         cmfs, ill, method="Integration") for sd in sds.values()
    ]) / 100
    xyz_w = colour.sd_to_XYZ(colour.sd_ones(shape), cmfs, ill, method="Integration") / 100
    # camera balanced for D65: the tabulated-D65 white becomes (1, 1, 1) in sRGB
    ill65 = colour.SDS_ILLUMINANTS["D65"].copy().align(shape, interpolator=colour.LinearInterpolator)
    w65 = colour.sd_to_XYZ(colour.sd_ones(shape), cmfs, ill65, method="Integration") / 100
    rgb = colour.XYZ_to_RGB(xyz, "sRGB", apply_cctf_encoding=False)
    rgb = rgb / colour.XYZ_to_RGB(w65, "sRGB", apply_cctf_encoding=False)
    seen = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "sRGB", apply_cctf_decoding=False), SRGB_D65_XY)
    adapted = colour.adaptation.chromatic_adaptation_VonKries(
        xyz, xyz_w, WHITEPOINT_D65_XYZ, transform="Bradford")
    return float(np.mean(delta_e_2000(seen, colour.XYZ_to_Lab(adapted, SRGB_D65_XY))))


def test_camera_balanced_for_d65_under_illuminant_a_shows_the_large_error(tmp_path) -> None:
    cam = tmp_path / "d65-balanced.toml"
    cam.write_text('[sensitivities]\nsource = "ideal"\n[white_balance]\nmethod = "illuminant"\nilluminant = "D65"\n')
    r = render_chart(str(cam), "A")
    expected = _colour_expected_error_d65_balanced_under_a()
    assert expected > 10
    assert r.measurement.mean_delta_e == pytest.approx(expected, rel=0.01)
    # the same camera under D65 is exact
    assert render_chart(str(cam), "D65").measurement.mean_delta_e < 0.01


def test_safecolor_reference_is_offered_but_not_default() -> None:
    scene = render_chart("ideal", "D65")
    safe = render_chart("ideal", "D65", reference="safecolor")
    assert scene.measurement.mean_delta_e < 0.01
    assert 1.0 < safe.measurement.mean_delta_e < 3.5
    assert "SAFE-COLOR" in safe.conventions["reference"]["reference"]
    with pytest.raises(UnknownNameError):
        render_chart("ideal", reference="d50")


def test_clipping_rule_linear_float_vs_display_output(tmp_path) -> None:
    """An sRGB-encoded (clipped) ideal camera loses out-of-gamut cyan; the float one does not."""
    cam = tmp_path / "ideal-srgb.toml"
    cam.write_text('[sensitivities]\nsource = "ideal"\n[white_balance]\nmethod = "illuminant"\n[tone]\ncurve = "srgb"\n')
    clipped = render_chart(str(cam), "D65")
    float_out = render_chart("ideal", "D65")
    cyan = clipped.measurement.patch_names.index("cyan")
    assert float_out.measurement.srgb[cyan, 0] < 0  # cyan is outside the sRGB gamut
    assert clipped.measurement.delta_e[cyan] > 1.0
    assert float_out.measurement.delta_e[cyan] < 0.01
    assert clipped.conventions["clipping"].startswith("output clipped")


def test_default_camera_is_realistic_and_noisy() -> None:
    r = render_chart(DEFAULT_CAMERA, "D65")
    assert 0.3 < r.measurement.mean_delta_e < 4.0
    assert np.all(r.measurement.noise > 0)  # 12-bit output with shot + read noise
    again = render_chart(DEFAULT_CAMERA, "D65")
    np.testing.assert_array_equal(r.linear_image, again.linear_image)  # seeded
    other = render_chart(DEFAULT_CAMERA, "D65", seed=123)
    assert not np.array_equal(r.linear_image, other.linear_image)
    ideal = render_chart("ideal", "D65")
    np.testing.assert_allclose(ideal.measurement.noise, 0.0, atol=1e-9)


def test_vignetting_darkens_corner_patches(tmp_path) -> None:
    cam = tmp_path / "vig.toml"
    cam.write_text('[sensitivities]\nsource = "ideal"\n[white_balance]\nmethod = "illuminant"\n[vignetting]\ndiagonal_fov_deg = 70\n')
    r = render_chart(str(cam), "D65")
    base = render_chart("ideal", "D65")
    ratio = r.camera_rgb[:, 1] / base.camera_rgb[:, 1]
    assert ratio[0] < ratio[8] and ratio[0] < 0.9  # corner patch darker than a central one


def test_layout_and_robust_patch_sampling() -> None:
    lay = ChartLayout.for_patch_size(16)
    assert (lay.height, lay.width) == (4 * 16 + 5 * 4, 6 * 16 + 7 * 4)
    values = np.arange(72, dtype=float).reshape(24, 3)
    img = lay.paint(values)
    y0, y1, x0, x1 = lay.window(5)
    img[y0, x0] = 1e6  # a firefly inside the window
    means, stds = patch_means(img, lay)
    np.testing.assert_allclose(means, values)  # trimmed mean ignores it
    assert stds[5, 0] > 0 and stds[4, 0] == 0
    px = img[y0:y1, x0:x1].reshape(-1, 3)
    np.testing.assert_allclose(stds[5], px.std(axis=0, ddof=1))


def test_render_cli_writes_json_exr_and_png(tmp_path) -> None:
    import OpenImageIO as oiio

    out, js = tmp_path / "out", tmp_path / "r.json"
    res = CliRunner().invoke(main, ["render", "--camera", "ideal", "--illuminant", "D65",
                                    "--renderer", "closed-form", "--out", str(out),
                                    "--json", str(js)])
    assert res.exit_code == 0, res.output
    d = json.loads(js.read_text())
    for key in ("mean_delta_e", "max_delta_e", "renderer", "variant", "seconds", "patches",
                "conventions", "camera"):
        assert key in d
    assert d["renderer"] == "closed-form" and d["variant"] is None and d["mean_delta_e"] < 0.01
    same = render_chart("ideal", "D65").measurement  # what the command measured
    assert d["mean_delta_e"] == pytest.approx(same.mean_delta_e, abs=1e-9)
    assert d["max_delta_e"] == pytest.approx(same.max_delta_e, abs=1e-9)
    assert [p["name"] for p in d["patches"]] == list(load_chart("safecolor").patch_names)
    for p in d["patches"]:
        assert {"name", "delta_e", "lab", "srgb", "camera_rgb"} <= set(p)
    exr = oiio.ImageBuf(str(out / "raw_camera.exr"))
    assert exr.spec().format == oiio.FLOAT and exr.spec().nchannels == 3
    png = oiio.ImageBuf(str(out / "developed.png"))
    assert png.spec().width == exr.spec().width and png.spec().format == oiio.UINT16


def test_render_cli_bad_camera_file_is_one_line_exit_2(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("quantisation: {bits: 64}\n")
    res = CliRunner().invoke(main, ["render", "--camera", str(bad)])
    assert res.exit_code == 2
    assert "bad.yaml" in res.output and "[quantisation].bits" in res.output
    assert "Traceback" not in res.output


def test_gamma_tone_curve_is_measured_as_srgb(tmp_path) -> None:
    """A gamma-2.2 encoding read as sRGB: expected error from colour-science's sRGB decoding."""
    from fidelity.colour.spectral import scene_reference

    cam = tmp_path / "gamma.toml"
    cam.write_text('[sensitivities]\nsource = "ideal"\n[white_balance]\nmethod = "illuminant"\n[tone]\ncurve = "gamma"\ngamma = 2.2\n')
    r = render_chart(str(cam), "D65")
    ref = scene_reference("D65")
    encoded = np.clip(ref.linear_srgb, 0, 1) ** (1 / 2.2)
    seen = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(encoded), SRGB_D65_XY)
    expected = delta_e_2000(seen, ref.lab)
    np.testing.assert_allclose(r.measurement.delta_e, expected, atol=0.01)
    assert 0.3 < r.measurement.mean_delta_e < 5


@pytest.mark.parametrize(("name", "key"), [("D50", "D50"), ("F2", "FL2"), ("F11", "FL11"),
                                           ("LED", "LED-B4"), ("A", "A")])
def test_named_illuminants_are_the_cie_tables(name: str, key: str) -> None:
    from fidelity.colour.spectral import load_illuminant

    ill = load_illuminant(name)
    np.testing.assert_allclose(ill.values, colour.SDS_ILLUMINANTS[key].values)
    r = render_chart("ideal", name)
    assert np.isfinite(r.measurement.mean_delta_e)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 300), st.integers(1, 3), st.floats(0.0, 0.49), st.integers(0, 2**32 - 1))
def test_trimmed_mean_is_scipys_trim_mean_bit_for_bit(n, channels, proportion, seed) -> None:
    """The patch means' trimmed mean against the anchor, scipy.stats.trim_mean, on random
    windows (ties included: values drawn from few levels half the time)."""
    from scipy.stats import trim_mean

    from fidelity.camera.render import trimmed_mean

    rng = np.random.default_rng(seed)
    values = rng.normal(size=(n, channels))
    if seed % 2:
        values = np.round(values * 4) / 4
    np.testing.assert_array_equal(trimmed_mean(values, proportion),
                                  trim_mean(values, proportion, axis=0))


def test_trimmed_mean_refuses_a_proportion_that_cuts_everything() -> None:
    from fidelity.camera.render import trimmed_mean

    with pytest.raises(ValueError, match="outside"):
        trimmed_mean(np.ones((4, 3)), 0.5)


def _frame_values(cam):  # type: ignore[no-untyped-def]
    from fidelity.measure.pixels import measure_pixels

    r = render_chart(cam, "D65", frame=True)
    assert r.frame is not None and r.frame.srgb.shape == (480, 640, 3)
    m = measure_pixels(r.frame.srgb, r.frame.corners, encoding="srgb", reference="scene",
                       uncertainty=False)
    return r, m


def _gauss_pixel_mtf50(sigma: float) -> float:
    """MTF50 of exp(-2 pi^2 s^2 f^2) |sinc f| (the lens and the 1 px aperture), by bisection."""
    lo, hi = 1e-4, 0.99
    for _ in range(80):
        f = (lo + hi) / 2
        v = float(np.exp(-2 * np.pi ** 2 * sigma ** 2 * f ** 2) * np.sinc(f))
        lo, hi = (f, hi) if v > 0.5 else (lo, f)
    return lo


@pytest.mark.parametrize("sigma,tol", [(None, 0.04), (1.0, 0.04), (1.5, 0.04), (2.5, 0.12)])
def test_the_turned_frame_carries_the_cameras_optics(sigma, tol) -> None:
    """The check's turned chart goes through the camera's lens: its e-SFR MTF50 (the softer
    edge's luminance) follows the closed form of the Gaussian PSF times the pixel aperture.
    It reads a few per cent high as the blur widens: the ROI across a patch edge ends in the
    14 px gap between patches, which cuts the edge spread's tails (docs/sharpness_noise.md,
    Limits)."""
    import dataclasses

    from fidelity.camera.model import load_camera
    from fidelity.prediction.properties import chart_mtf50

    cam = load_camera("ideal")
    if sigma is not None:
        cam = dataclasses.replace(cam, optics=dataclasses.replace(
            cam.optics, kind="gaussian", sigma_px=sigma))
    _, m = _frame_values(cam)
    got = chart_mtf50(m.sharpness)
    assert got is not None
    want = _gauss_pixel_mtf50(sigma or 0.0)
    assert got[0] == pytest.approx(want, rel=tol)
    assert got[0] >= want  # truncated tails make an edge look sharper, never softer


def test_the_turned_frame_carries_the_cameras_noise() -> None:
    """SNR at grey of the turned chart against the noise model's closed form: an ideal camera
    (no CCM, linear output) with full well N electrons and read noise r has, per channel, var
    = mu / N + (r / N)^2 in raw units; the white-balance gain g scales both, and the
    luminance Y = sum w_c g_c raw_c of independent channels has var sum (w_c g_c)^2 var_c."""
    import dataclasses

    from fidelity.camera.model import Noise, load_camera
    from fidelity.prediction.properties import chart_snr

    full_well, read = 400.0, 4.0
    cam = dataclasses.replace(load_camera("ideal"), noise=Noise(full_well, read, 7))
    r, m = _frame_values(cam)
    got = chart_snr(m.noise)
    assert got is not None and got[1] is not None
    grey = r.measurement.patch_names.index(m.noise.grey_patch)
    mu = np.asarray(r.camera_rgb[grey])  # the chart's raw mean of the grey patch
    g = np.asarray(r.conventions["white_balance_gains"])
    w = np.array([0.2126, 0.7152, 0.0722])
    var = mu / full_well + (read / full_well) ** 2
    want = float(w @ (g * mu) / np.sqrt(np.sum((w * g) ** 2 * var)))
    assert got[0] == pytest.approx(want, rel=0.05)
    assert abs(got[0] - want) <= 3 * got[1] + 0.02 * want
