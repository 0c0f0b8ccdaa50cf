"""The chart's noise in an audit (fidelity.measure.chartnoise through measure_pixels): on a
synthetic chart turned 5 degrees, blurred by a Gaussian of 1 px and given Poisson-Gaussian
noise of known read noise and gain, the photon transfer finds them within their uncertainty
and the SNR at the 18 % grey is the simulated grey's mu / sigma; a posterised 8-bit chart
states the refusal; a very noisy one still gets an answer or a stated refusal."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.colour import colorimetry as cm
from fidelity.measure.chartnoise import ChartNoise, grey_index
from fidelity.measure.noise import LUMINANCE_WEIGHTS
from fidelity.measure.pixels import measure_pixels
from fidelity.pipeline.records import ChartReport
from fidelity.report.terminal import texture_lines
from tests.measure.chartimage import corners, render
from tests.pipeline.test_audit import write_exr

READ_NOISE = 0.002  # linear units (1 = full scale)
GAIN = 1.0 / 4000.0  # linear units per electron: 4000 e- at full scale


@pytest.fixture(scope="module")
def clean():
    return render(angle_deg=5.0, sigma=1.0)


@pytest.fixture(scope="module")
def noisy(clean):
    img, h = clean
    rng = np.random.default_rng(7)
    out = GAIN * rng.poisson(img / GAIN) + rng.normal(0.0, READ_NOISE, img.shape)
    return out, h


def test_photon_transfer_finds_the_simulated_read_noise_and_gain(noisy):
    img, h = noisy
    m = measure_pixels(img, corners(h), uncertainty=False)
    n = m.noise
    assert n is not None and n.refusal is None and n.transfer is not None
    t = n.transfer
    assert n.patches == ("white 9.5", "neutral 8", "neutral 6.5", "neutral 5", "neutral 3.5",
                         "black 2")
    assert abs(t.read_noise - READ_NOISE) <= 3 * t.u_read_noise, (t.read_noise, t.u_read_noise)
    assert abs(t.gain - GAIN) <= 3 * t.u_gain, (t.gain, t.u_gain)
    assert t.u_gain < 0.1 * GAIN
    assert n.linearisation == "none (linear input)"
    json.dumps(n.to_json(), allow_nan=False)
    assert ChartNoise.from_json(json.loads(json.dumps(n.to_json()))) == n


def test_snr_at_grey_is_mu_over_sigma_of_the_simulated_grey(clean, noisy):
    img, h = noisy
    m = measure_pixels(img, corners(h), uncertainty=False)
    n = m.noise
    ref = m.reference
    k = grey_index(ref.patch_names, ref.neutral_indices)
    assert n.grey_patch == ref.patch_names[k] == "neutral 5"
    # the noiseless grey window's channel means, and the luminance's variance of independent
    # Poisson-Gaussian channels: sum_c w_c^2 (sigma_read^2 + K mu_c)
    mu = m.location.windows[k].values(clean[0]).mean(axis=0)
    w = np.array(LUMINANCE_WEIGHTS)
    expected = float(w @ mu) / math.sqrt(float(np.sum(w ** 2 * (READ_NOISE ** 2 + GAIN * mu))))
    count = m.location.windows[k].count
    assert n.grey_snr == pytest.approx(expected, rel=4 / math.sqrt(2 * count)), (n.grey_snr,
                                                                                 expected)
    assert n.grey_snr_db == pytest.approx(20 * math.log10(n.grey_snr))
    line = texture_lines(m)[0]
    assert line.startswith(f"noise: SNR {n.grey_snr_db:.1f} dB at the 18 % grey (neutral 5; "
                           "read noise ")
    assert "gain" in line and "per electron" in line


def test_srgb_encoded_input_is_decoded_before_the_noise(noisy):
    img, h = noisy
    encoded = cm.delinearize_srgb(np.clip(img, 0.0, None))
    m = measure_pixels(encoded, corners(h), encoding="srgb", uncertainty=False)
    n = m.noise
    assert n.linearisation.startswith("sRGB transfer function decoded")
    t = n.transfer
    assert abs(t.gain - GAIN) <= 3 * t.u_gain
    assert abs(t.read_noise - READ_NOISE) <= 3 * t.u_read_noise + 2e-4  # the clip at 0


def test_posterised_8_bit_chart_states_the_refusal(clean):
    img, h = clean
    codes = np.clip(np.rint(cm.delinearize_srgb(img) * 255), 0, 255).astype(np.uint8)
    m = measure_pixels(codes, corners(h), encoding="srgb", uncertainty=False)
    n = m.noise
    assert n is not None and n.transfer is None
    assert n.refusal is not None and n.refusal[0] == "zero-variance"
    assert "uint8 codes / 255" in n.linearisation
    d = n.to_json()
    assert d["photon_transfer"] is None and d["refusal"]["reason"] == "zero-variance"
    json.dumps(d, allow_nan=False)
    assert "photon transfer refused, zero-variance" in texture_lines(m)[0]


def test_a_very_noisy_chart_gets_an_answer_or_a_stated_refusal(clean):
    img, h = clean
    rng = np.random.default_rng(3)
    m = measure_pixels(img + rng.normal(0.0, 0.08, img.shape), corners(h), uncertainty=False)
    n = m.noise
    assert n is not None
    assert (n.transfer is None) != (n.refusal is None)
    assert math.isfinite(n.grey_snr) and n.grey_snr > 0
    if n.transfer is not None:
        assert n.transfer.read_noise == pytest.approx(0.08, abs=3 * n.transfer.u_read_noise)
    json.dumps(n.to_json(), allow_nan=False)


def test_the_audit_report_carries_noise_and_sharpness(noisy, tmp_path):
    img, h = noisy
    path = tmp_path / "chart.exr"
    write_exr(path, img.astype(np.float32))
    out = tmp_path / "a.json"
    text = ",".join(f"{v:.4f}" for v in corners(h).ravel())
    html = tmp_path / "a.html"
    r = CliRunner().invoke(main, ["--no-config", "audit", str(path), "--corners", text,
                                  "--json", str(out), "--html", str(html)],
                           catch_exceptions=False)
    assert r.exit_code in (0, 1), r.output
    assert "noise: SNR " in r.output and "sharpness: MTF50 " in r.output
    page = html.read_text(encoding="utf-8")
    assert "Noise and sharpness" in page and "MTF50, cy/px" in page
    data = json.loads(out.read_text())
    assert data["noise"]["photon_transfer"]["gain"] > 0
    assert {e["direction"] for e in data["sharpness"]["edges"]} == {"horizontal", "vertical"}
    report = ChartReport.from_json(data)
    assert report.noise is not None and report.noise.to_json() == data["noise"]
    assert report.sharpness is not None and report.sharpness.to_json() == data["sharpness"]


def test_a_large_window_takes_its_noise_from_an_even_pixel_lattice():
    """Issue 59: a neutral window over NOISE_SAMPLE_PIXELS is read on every s-th pixel down
    and across (s the least stride leaving at most the limit), spanning the window; its
    standard deviation is numpy's over the whole window within 4 sampling standard errors
    (``sigma / sqrt(2 n)``) for white noise and for noise correlated over 8 pixels."""
    import cv2

    from fidelity.measure.noise import patch_noise
    from fidelity.measure.pixels import NOISE_SAMPLE_PIXELS, _noise_sample

    rng = np.random.default_rng(3)
    mask = np.ones((700, 650), bool)
    mask[:, :20] = False
    keep = _noise_sample(3, 7, mask)
    assert keep is not None and keep.shape == (int(mask.sum()),)
    assert NOISE_SAMPLE_PIXELS / 4 < keep.sum() <= NOISE_SAMPLE_PIXELS
    rows, cols = np.nonzero(mask)
    assert set(((rows[keep] + 3) % 2).tolist()) == {0} and set(((cols[keep] + 7) % 2).tolist()) == {0}
    assert rows[keep].max() > 690 and cols[keep].min() < 25  # spans the window
    assert _noise_sample(0, 0, np.ones((150, 150), bool)) is None
    white = rng.normal(0.5, 0.01, (700, 650, 3))
    blurred = np.stack([cv2.GaussianBlur(white[..., c], (0, 0), 8.0) for c in range(3)], -1)
    for img in (white, blurred):
        px = img[mask]
        full = px.std(axis=0, ddof=1)
        got = patch_noise(px[keep])
        n = int(keep.sum())
        for c, name in enumerate("RGB"):
            sigma = got.channel(name).sigma
            assert abs(sigma - full[c]) <= 4 * full[c] / np.sqrt(2 * n), (name, sigma, full[c])
        assert got.n == n
