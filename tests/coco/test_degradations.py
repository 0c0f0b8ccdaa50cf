"""The sweep's blur and noise families (fidelity.coco.degradations) against closed forms: the
Gaussian blur's MTF50 on the calibration chart is exp(-2 pi^2 sigma^2 f^2) |sinc f| = 0.5, the
sensor noise's SNR at the grey patch is mu / sigma of the Poisson-Gaussian model through the
luminance weights, COCO-C's gaussian_noise adds the stated sigma on the encoded values; the
noise is the same for the same image and level and differs between images; bad levels and
names are refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fidelity.coco.degradations import (
    DEGRADATIONS,
    READ_NOISE_E,
    Degradation,
    encode_srgb8,
    family,
)
from fidelity.coco.tables.degradation import calibrate_level, calibration_chart, chart_value
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference
from fidelity.core.errors import InvalidValueError, UnknownNameError


@pytest.fixture(scope="module")
def chart():
    return calibration_chart()


def _closed_form_mtf50(sigma: float) -> float:
    """Bisection on exp(-2 pi^2 sigma^2 f^2) |sinc f| = 0.5 (numpy's sinc: sin(pi f)/(pi f))."""
    lo, hi = 1e-6, 0.99
    for _ in range(80):
        mid = (lo + hi) / 2
        value = math.exp(-2 * math.pi ** 2 * sigma ** 2 * mid ** 2) * abs(np.sinc(mid))
        lo, hi = (mid, hi) if value > 0.5 else (lo, mid)
    return (lo + hi) / 2


@pytest.mark.parametrize("sigma", [1.0, 1.5, 2.0, 3.0])
def test_gaussian_blur_mtf50_on_the_chart_is_the_closed_form(chart, sigma):
    level = calibrate_level("gaussian-blur", sigma, chart)
    expected = _closed_form_mtf50(sigma)
    assert level.x is not None and level.u is not None
    # the chart's patch edges give a window of half the patch gap: at wider blurs the stated
    # uncertainty (k = 2) grows and covers its truncation of the edge spread
    assert abs(level.x - expected) <= 2 * level.u + 0.03 * expected, (sigma, level, expected)


def test_the_undegraded_chart_is_as_sharp_as_the_pixel_aperture(chart):
    got = chart_value(*chart, "sharpness")
    assert got is not None
    assert abs(got[0] - _closed_form_mtf50(0.0)) <= 0.05 * _closed_form_mtf50(0.0)


def test_blur_levels_order_the_mtf50(chart):
    for name in ("gaussian-blur", "defocus-blur"):
        xs = [calibrate_level(name, lv, chart).x for lv in DEGRADATIONS[name].levels[::3]]
        assert all(a is not None and b is not None and a > b for a, b in zip(xs, xs[1:], strict=False)), xs


@pytest.mark.parametrize("full_well", [300.0, 1200.0, 5000.0])
def test_sensor_noise_snr_at_grey_is_the_poisson_gaussian_closed_form(chart, full_well):
    level = calibrate_level("sensor-noise", full_well, chart)
    # neutral 5: the reference's 8-bit code as the chart holds it, linear, luminance (BT.709)
    ref = load_reference("safecolor")
    code = np.rint(np.asarray(ref.srgb)[ref.patch_names.index("neutral 5")] * 255) / 255
    grey = np.asarray(cm.linearize_srgb(code))
    weights = np.array([0.2126, 0.7152, 0.0722])
    mu = float(weights @ grey)
    var = (np.maximum(grey, 0) * full_well + READ_NOISE_E ** 2) / full_well ** 2
    expected = mu / math.sqrt(float(weights ** 2 @ var))
    assert level.x is not None
    assert abs(level.x - expected) <= 0.08 * expected, (level.x, expected)


def test_coco_c_gaussian_noise_adds_its_sigma_on_the_encoded_values():
    grey = np.full((400, 400, 3), 128, np.uint8)
    out = Degradation("gaussian-noise", 0.04)(grey)
    d = (out.astype(float) - 128.0) / 255.0
    assert abs(d.std() - 0.04) < 0.002
    assert abs(d.mean() + 0.5 / 255) < 0.002  # truncation to 8 bits (COCO-C's np.uint8)


def test_noise_is_seeded_by_the_image_and_level():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (64, 80, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (64, 80, 3), dtype=np.uint8)
    for name in ("sensor-noise", "gaussian-noise"):
        lv = DEGRADATIONS[name].levels[4]
        d = Degradation(name, lv)
        assert np.array_equal(d(a), d(a))
        da, db = d(a).astype(int) - a, d(b).astype(int) - b
        assert not np.array_equal(da, db)
        assert not np.array_equal(d(a), Degradation(name, DEGRADATIONS[name].levels[5])(a))


def test_blur_keeps_a_flat_image_and_the_input():
    flat = np.full((40, 50, 3), 90, np.uint8)
    keep = flat.copy()
    for name in ("gaussian-blur", "defocus-blur"):
        out = Degradation(name, 3.0)(flat)
        assert out.dtype == np.uint8 and out.shape == flat.shape
        assert np.abs(out.astype(int) - 90).max() <= 1
    assert np.array_equal(flat, keep)


def test_encoding_table_matches_the_exact_rounding():
    x = np.random.default_rng(0).random(200_000)
    exact = np.rint(cm.delinearize_srgb(x) * 255).astype(np.uint8)
    got = encode_srgb8(x)
    assert np.abs(got.astype(int) - exact).max() <= 1
    assert (got != exact).mean() < 0.005
    assert encode_srgb8(np.array([-1.0, 0.0, 1.0, 7.0])).tolist() == [0, 0, 255, 255]


@pytest.mark.parametrize("level", [0.0, -1.0, math.nan, math.inf])
def test_bad_levels_are_refused(level):
    with pytest.raises(InvalidValueError, match="gaussian-blur"):
        Degradation("gaussian-blur", level)


def test_unknown_family_names_the_known_ones():
    with pytest.raises(UnknownNameError, match="gaussian-blur"):
        family("motion-blurr")


def test_every_family_has_ten_levels_or_more_mildest_first():
    for f in DEGRADATIONS.values():
        assert len(f.levels) >= 10
        order = sorted(f.levels, reverse=f.name == "sensor-noise")
        assert list(f.levels) == order
