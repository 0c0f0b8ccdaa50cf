"""Blind-spot warnings: shadow tones, bit depth, banding; on the validation suite's cameras."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.camera.render import render_chart
from fidelity.chart.image import write_png
from fidelity.cli import main
from fidelity.measure.blindspots import (
    banding,
    bit_depth,
    chart_blind_spots,
    effective_bits,
    shadow_tone,
    warnings,
)

CAMERAS = Path(__file__).resolve().parents[2] / "cameras"


def _kinds(camera: str | Path) -> list[str]:
    r = render_chart(camera)
    return [w.kind for w in warnings(chart_blind_spots(r.measurement,
                                                       bits=r.camera.quantisation_bits))]


@pytest.mark.parametrize("camera, expected", [
    (CAMERAS / "nikon5100-gamma22.toml", ["shadow-tone"]),
    (CAMERAS / "bad-5bit.toml", ["bit-depth"]),
    ("nikon-5100", []),
    ("ideal", []),
    (CAMERAS / "nikon5100-cheung-d65.toml", []),
    (CAMERAS / "nikon5100-underexposed.toml", []),  # exposure scales every tone alike
])
def test_warnings_on_the_suite(camera, expected):
    assert _kinds(camera) == expected


def test_shadow_slope_is_the_local_gamma_of_the_neutrals():
    """A chart whose neutral luminances follow Y_ref^g (scaled by any exposure) reads g."""
    from fidelity.colour.charts import load_reference
    from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
    from fidelity.measure.colour import measure_chart

    ref = load_reference("scene")
    lin = np.clip(linearize_srgb(np.clip(ref.srgb, 0, 1)), 0, 1)
    for g, k in ((1.0, 1.0), (0.9, 0.8), (1.2, 1.5)):
        y = lin.mean(axis=1, keepdims=True)
        out = np.clip(delinearize_srgb(np.clip(k * lin * (y ** (g - 1)), 0, 1)), 0, 1)
        m = measure_chart(out, ref.lab, ref.patch_names)
        spot = shadow_tone(m)
        # neutral patches are grey, so their luminance is y: the slope is g
        assert spot.value == pytest.approx(g, abs=0.02)
        assert spot.at_risk is (abs(g - 1) > 0.05)


def test_bit_depth_and_banding_measure_the_levels():
    assert bit_depth(5).at_risk and not bit_depth(8).at_risk and not bit_depth(None).at_risk
    ramp = np.linspace(0, 1, 800)[None, :, None] * np.ones((300, 1, 3))
    for bits, risk in ((8, False), (7, False), (6, True), (5, True)):
        levels = 2 ** bits - 1
        img = np.round(np.round(ramp * levels) / levels * 255) / 255
        spot = banding(img, "uint8")
        assert spot.value == pytest.approx(bits, abs=0.1) and spot.at_risk is risk
    # 16-bit files: the same content in 16-bit codes
    img = np.round(np.round(ramp * 31) / 31 * 65535) / 65535
    assert banding(img, "uint16").value == pytest.approx(5, abs=0.1)
    flat = np.full((100, 100, 3), 0.5)
    assert banding(flat, "uint8").at_risk is None and banding(flat, "half").at_risk is None
    assert effective_bits(np.zeros((4, 4, 3)), 255)[0] is None


def test_check_and_audit_report_the_warnings(tmp_path):
    r = CliRunner().invoke(main, ["check", "--camera", str(CAMERAS / "bad-5bit.toml"),
                                  "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "report.json").read_text())
    assert [b["kind"] for b in doc["blind_spots"] if b["at_risk"]] == ["bit-depth"]
    # the camera's 5 bits, against the risk threshold of 6
    depth = next(b for b in doc["blind_spots"] if b["kind"] == "bit-depth")
    assert (depth["value"], depth["threshold"]) == (5.0, 6.0)
    html = (tmp_path / "report.html").read_text()
    assert "Blind spots of the chart ΔE" in html and "<strong>warning</strong>" in html
    from fidelity.pipeline.records import ChartReport, report_schema

    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(doc, report_schema())
    assert ChartReport.from_json(doc).warnings[0].kind == "bit-depth"
    # an image: the chart on a smooth gradient, posterised to 5 bits, then 8
    m = render_chart("nikon-5100")
    chart = m.display_image
    h, w = chart.shape[:2]
    canvas = np.linspace(0.1, 0.9, 2 * w)[None, :, None] * np.ones((2 * h, 1, 3))
    canvas[h // 2:h // 2 + h, w // 2:w // 2 + w] = chart
    for bits, expect in ((5, True), (8, False)):
        q = np.round(canvas * (2 ** bits - 1)) / (2 ** bits - 1)
        write_png(tmp_path / f"g{bits}.png", q, 8)
        r = CliRunner().invoke(main, ["audit", str(tmp_path / f"g{bits}.png"), "--json",
                                      str(tmp_path / f"g{bits}.json")])
        assert r.exit_code == 0, r.output
        doc = json.loads((tmp_path / f"g{bits}.json").read_text())
        band = next(b for b in doc["blind_spots"] if b["kind"] == "banding")
        assert band["at_risk"] is expect, band
        # the levels the gradient holds, in bits: those it was posterised to
        assert band["value"] == pytest.approx(bits, abs=0.1), band
        assert (band["value"] <= band["threshold"]) is expect, band


def test_the_quantisation_step_is_the_level_spacing_not_the_most_common_step():
    """Levels round(k Δ): a step of which nine in ten steps are multiples (257: 8 bits in 16),
    or a spacing between codes (255 / 31: 5 bits in 8 step by 8 and 9); a clean image's
    steps take every value, whatever the most common one (its 16 bits are kept)."""
    from fidelity.measure.blindspots import quantisation_step

    def counts(steps: dict[int, int], size: int = 5300) -> np.ndarray:
        c = np.zeros(size, np.int64)
        for d, n in steps.items():
            c[d] = n
        return c

    def histogram(values: np.ndarray) -> dict[int, int]:
        d, n = np.unique(values, return_counts=True)
        return {int(a): int(b) for a, b in zip(d, n, strict=True)}

    assert quantisation_step(counts({257: 40, 514: 50, 771: 30})) == 257
    levels = np.round(np.arange(32) * 255 / 31)
    spacing = quantisation_step(counts(histogram(np.diff(levels).astype(int))))
    assert spacing == pytest.approx(255 / 31, abs=0.05)
    rng = np.random.default_rng(0)
    # a noise-free 16-bit render: one edge's step the most common
    clean = counts(histogram(rng.integers(1, 5000, 8000)) | {1812: 2400})
    assert quantisation_step(clean) == 1
