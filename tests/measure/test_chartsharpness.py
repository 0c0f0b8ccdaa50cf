"""The chart's sharpness in an audit (fidelity.measure.chartsharpness through measure_pixels):
on a synthetic chart blurred by a Gaussian of known sigma in linear light (4x supersampled and
box-averaged: the pixel aperture), the MTF50 of the highest-contrast vertical and horizontal
patch edges is the closed form of that Gaussian times the pixel aperture,
``exp(-2 pi^2 sigma^2 f^2) |sinc f|`` = 0.5, within the stated uncertainty; a chart turned 5
degrees is measured by the e-SFR, an axis-aligned one by the edge fit, and each says so; a very
noisy, a small and a posterised chart get numbers or stated refusals, never an error."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fidelity.colour import colorimetry as cm
from fidelity.measure.chartsharpness import ChartSharpness
from fidelity.measure.pixels import measure_pixels
from fidelity.measure.sharpness import REFUSALS, gaussian_mtf50
from fidelity.report.terminal import plus_minus, texture_lines
from tests.measure.chartimage import corners, render

SIGMA = 1.0  # px
NOISE = 0.002  # linear units

#: The rendering's own approximation of the closed form (4 sub-pixels for the aperture, the
#: Gaussian sampled on them), added to k = 3 times the stated uncertainty.
RENDER_ALLOWANCE = 0.01


def _measure(angle_deg: float, noise: float = NOISE, **kw):
    img, h = render(angle_deg=angle_deg, sigma=SIGMA, **kw)
    img = img + np.random.default_rng(11).normal(0.0, noise, img.shape)
    return measure_pixels(img, corners(h), uncertainty=False)


@pytest.fixture(scope="module")
def turned():
    return _measure(5.0)


@pytest.fixture(scope="module")
def square():
    return _measure(0.0)


def _check_closed_form(m, method: str) -> None:
    s = m.sharpness
    assert s is not None and s.linearisation == "none (linear input)"
    expected = gaussian_mtf50(SIGMA)
    assert [e.direction for e in s.edges] == ["horizontal", "vertical"]
    for e in s.edges:
        assert e.refusal is None and e.method == method, e
        assert e.roi is not None and e.roi[2] >= 16 and e.roi[3] >= 16
        y = e.channel("Y")
        assert y is not None and y.refusal is None and y.u_mtf50 is not None
        assert abs(y.mtf50 - expected) <= 3 * y.u_mtf50 + RENDER_ALLOWANCE * expected, (
            e.direction, y.mtf50, y.u_mtf50, expected)
        for name in "RGB":
            c = e.channel(name)
            assert c is not None and (c.mtf50 is not None or c.refusal is not None)
        assert y.mtf10 is not None and y.mtf10 > y.mtf50
        assert 0 < y.mtf_half_nyquist < 1
    json.dumps(s.to_json(), allow_nan=False)
    assert ChartSharpness.from_json(json.loads(json.dumps(s.to_json()))) == s


def test_turned_chart_e_sfr_matches_the_closed_form(turned):
    _check_closed_form(turned, "e-SFR")
    for e in turned.sharpness.edges:
        assert e.angle == pytest.approx(5.0, abs=0.05)
    line = texture_lines(turned)[1]
    h, v = (e.channel("Y") for e in turned.sharpness.edges)
    assert line == (f"sharpness: MTF50 {plus_minus(h.mtf50, h.u_mtf50)} cy/px horizontal, "
                    f"{plus_minus(v.mtf50, v.u_mtf50)} vertical (e-SFR, luminance)")


def test_axis_aligned_chart_uses_the_edge_fit_and_says_so(square):
    _check_closed_form(square, "edge fit")
    for e in square.sharpness.edges:
        assert e.angle == pytest.approx(0.0, abs=1e-6)
        y = e.channel("Y")
        assert y.u_mtf10 is not None and y.u_mtf_half_nyquist is not None
    assert texture_lines(square)[1].endswith("(edge fit, luminance)")


def test_a_very_noisy_chart_gets_numbers_or_stated_refusals():
    m = _measure(5.0, noise=0.08)
    s = m.sharpness
    assert s is not None and len(s.edges) == 2
    for e in s.edges:
        if e.refusal is not None:
            assert e.refusal[1]
            continue
        for c in e.channels:
            assert (c.mtf50 is None) == (c.refusal is not None)
            if c.refusal is not None:
                assert c.refusal[0] in REFUSALS and c.refusal[1]
    json.dumps(s.to_json(), allow_nan=False)


def test_a_small_chart_states_that_its_edges_are_too_short():
    m = _measure(5.0, pitch=30.0, size=(200, 260))
    s = m.sharpness
    assert s is not None
    assert all(e.refusal is not None and e.refusal[0] == "too-short" for e in s.edges)
    assert all(e.channels == () for e in s.edges)
    assert "horizontal refused (too-short)" in texture_lines(m)[1]


def test_a_posterised_8_bit_chart_is_measured_or_refused_with_its_reason():
    img, h = render(angle_deg=5.0, sigma=SIGMA)
    codes = np.clip(np.rint(cm.delinearize_srgb(img) * 255), 0, 255).astype(np.uint8)
    m = measure_pixels(codes, corners(h), encoding="srgb", uncertainty=False)
    s = m.sharpness
    assert s is not None and "sRGB transfer function decoded" in s.linearisation
    for e in s.edges:
        for c in e.channels:
            assert c.mtf50 is not None or (c.refusal is not None and c.refusal[0] in REFUSALS)
    json.dumps(s.to_json(), allow_nan=False)
