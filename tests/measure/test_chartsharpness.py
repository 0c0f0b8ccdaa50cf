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


@pytest.mark.parametrize("pitch", [30.0, 19.0, 12.0])
def test_a_small_chart_states_that_its_edges_are_too_short(pitch):
    """Pitches of 30, 19 and 12 px: each edge refused, too-short, its message naming the ROI
    it could have and the floor; the terminal line gives the reason code alone (the message
    is in the record and the chart report's table), no number."""
    m = _measure(5.0, pitch=pitch, size=(200, 260))
    s = m.sharpness
    assert s is not None and [e.direction for e in s.edges] == ["horizontal", "vertical"]
    assert all(e.refusal is not None and e.refusal[0] == "too-short" for e in s.edges)
    assert all("the chart is too small for an edge ROI" in e.refusal[1]
               and "need 16 and 20" in e.refusal[1] for e in s.edges)
    assert all(e.channels == () and e.method is None for e in s.edges)
    assert texture_lines(m)[1] == ("sharpness: MTF50 horizontal refused (too-short), vertical "
                                   "refused (too-short) (luminance)")


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


def test_a_very_sharp_chart_states_its_mtf50_above_nyquist():
    """sigma 0.2 px: MTF50 0.516 cy/px in closed form, above the 0.5 cy/px Nyquist frequency.
    Each edge's MTF50 is a number, and the terminal (and the chart report, which prints the
    same line) says it is above Nyquist, aliased in the image. The render's 4 sub-pixels with a
    Gaussian of 0.8 sub-pixel are coarse at this blur (its edge fit reads 0.536 as well): the
    number is checked within 5 % here, to 1 % on exact edges in test_sharpness.py."""
    img, h = render(angle_deg=5.0, sigma=0.2)
    m = measure_pixels(img, corners(h), uncertainty=False)
    s = m.sharpness
    assert s is not None and len(s.edges) == 2
    for e in s.edges:
        y = e.channel("Y")
        assert y is not None and y.mtf50 is not None and y.above_nyquist
        assert y.mtf50 == pytest.approx(gaussian_mtf50(0.2), rel=0.05)
    line = texture_lines(m)[1]
    assert line.count("(above Nyquist)") == 2
    h_y = s.edges[0].channel("Y")
    assert line.startswith(f"sharpness: MTF50 {plus_minus(h_y.mtf50, h_y.u_mtf50)} cy/px "
                           "horizontal (above Nyquist), ")


def test_scene_linear_highlights_above_one_are_measured_alike(turned):
    """The turned chart scaled x4 in linear light (scene-linear floats, white about 3.6, an
    EXR's highlights): measured, not refused as clipped (a float image has no encoding's
    maximum), and MTF50, its uncertainty and the grey SNR are those of the unscaled chart (the
    e-SFR and the SNR are ratios: scale-free)."""
    img, h = render(angle_deg=5.0, sigma=SIGMA)
    img = (img + np.random.default_rng(11).normal(0.0, NOISE, img.shape)) * 4.0
    assert img.max() > 3.0
    bright = measure_pixels(img, corners(h), uncertainty=False)
    _check_closed_form(bright, "e-SFR")
    for a, b in zip(bright.sharpness.edges, turned.sharpness.edges, strict=True):
        for c in "RGBY":
            ca, cb = a.channel(c), b.channel(c)
            assert ca.refusal is None and cb.refusal is None
            assert ca.mtf50 == pytest.approx(cb.mtf50, rel=1e-9), c
            assert ca.u_mtf50 == pytest.approx(cb.u_mtf50, rel=1e-6), c
            assert ca.snr == pytest.approx(cb.snr, rel=1e-9), c
    assert bright.noise.grey_snr_db == pytest.approx(turned.noise.grey_snr_db, abs=1e-9)
    assert texture_lines(bright)[1] == texture_lines(turned)[1]


def test_the_terminal_gives_a_refused_channel_its_reason_code_alone():
    """An edge measured but its luminance refused (clipped) reads ``refused (clipped)``, the
    message left to the record; an edge refused before a method reads its own code; an MTF50
    of exactly the Nyquist frequency is not said to be above it."""
    from types import SimpleNamespace  # noqa: PLC0415 (this test only)

    from fidelity.measure.chartsharpness import ChannelMTF, EdgeSharpness  # noqa: PLC0415

    clipped = ChannelMTF("Y", None, None, None, None, None, None, None,
                         ("clipped", "Y channel roi: clipped edge: 3.1% of the pixels ..."))
    at_nyquist = ChannelMTF("Y", 0.5, 0.01, None, None, 0.8, None, 50.0)
    s = ChartSharpness((EdgeSharpness("horizontal", ("a", "b"), "e-SFR", 5.0, (0, 0, 32, 40),
                                      (clipped,)),
                        EdgeSharpness("vertical", ("a", "c"), "e-SFR", 5.0, (0, 0, 40, 32),
                                      (at_nyquist,))), "none (linear input)")
    line = texture_lines(SimpleNamespace(noise=None, sharpness=s))[0]
    assert line == ("sharpness: MTF50 horizontal refused (clipped), 0.500 ± 0.010 vertical "
                    "(e-SFR, luminance)")
    assert not at_nyquist.above_nyquist and not clipped.above_nyquist
