"""fidelity compare: sharpness and noise, simulation against real camera (issue 55) -- the two
luminance MTF curves and the two noise curves in the HTML and in the JSON."""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.ndimage import gaussian_filter

from fidelity.chart.image import read_image, write_exr
from fidelity.cli import main
from fidelity.pipeline.compare import compare_charts
from fidelity.pipeline.records import ComparisonReport
from fidelity.pipeline.simreal import TextureComparison
from fidelity.report import chartfigures as cf
from fidelity.report.compare import (
    TEXTURE_TITLE,
    comparison_document,
    texture_lines,
    texture_section,
)
from fidelity.report.html import render_html
from fidelity.report.jsonform import comparison_json
from fidelity.report.svg import COLOURS

SVG = "{http://www.w3.org/2000/svg}"


def _render(folder: Path, *extra: str) -> Path:
    r = CliRunner().invoke(main, ["render", "--out", str(folder), "-q", *extra])
    assert r.exit_code == 0, r.output
    return folder


@pytest.fixture(scope="module")
def sharp_and_blurred(tmp_path_factory):
    """A sharp, quiet simulation and a blurred (Gaussian sigma 1.5 px), noisier real camera,
    scene-linear EXR of the same 64 px-per-patch render."""
    folder = tmp_path_factory.mktemp("texture")
    raw = _render(folder / "render", "--pixels-per-patch", "64") / "raw_camera.exr"
    px = np.asarray(read_image(raw).pixels, dtype=np.float64)
    rng = np.random.default_rng(55)

    def noisy(x: np.ndarray, k: float) -> np.ndarray:
        return x + rng.normal(size=x.shape) * np.sqrt(1e-6 + k * np.clip(x, 0, None))

    blurred = np.stack([gaussian_filter(px[..., c], 1.5) for c in range(3)], -1)
    sim = write_exr(folder / "sim.exr", noisy(px, 2e-5).astype(np.float32))
    real = write_exr(folder / "real.exr", noisy(blurred, 2e-4).astype(np.float32))
    return compare_charts(sim, real)


@pytest.fixture(scope="module")
def too_small(tmp_path_factory):
    """The default renders (12 px patches): too small for an edge ROI on either side."""
    folder = tmp_path_factory.mktemp("small")
    a = _render(folder / "a") / "developed.png"
    b = _render(folder / "b", "--camera", "sigma-sdmerrill") / "developed.png"
    return compare_charts(a, b)


def _y_of_softer_edge(report):
    ys = [e.channel("Y") for e in report.sharpness.edges if e.refusal is None]
    return min((y for y in ys if y is not None and y.mtf50 is not None),
               key=lambda y: y.mtf50)


def test_texture_record_from_the_audits(sharp_and_blurred):
    t = sharp_and_blurred.texture
    assert t is not None and t.not_compared == ()
    for side, audit in ((t.sim, sharp_and_blurred.sim), (t.real, sharp_and_blurred.real)):
        y = _y_of_softer_edge(audit)
        assert side.mtf50 == y.mtf50
        assert (side.frequencies, side.mtf) == y.curve
        assert side.patches == audit.noise.patches
        assert side.read_variance == audit.noise.transfer.read_variance
    assert t.mtf50_ratio == pytest.approx(t.sim.mtf50 / t.real.mtf50)
    assert t.mtf50_ratio > 2  # the blurred camera is the softer one
    assert t.snr_difference_db == pytest.approx(
        sharp_and_blurred.sim.noise.grey_snr_db - sharp_and_blurred.real.noise.grey_snr_db)
    assert t.snr_difference_db > 0  # and the noisier one


def test_section_in_the_html(sharp_and_blurred):
    doc = comparison_document(sharp_and_blurred)
    titles = [s.title for s in doc.sections]
    assert TEXTURE_TITLE in titles
    html = render_html(doc)
    assert TEXTURE_TITLE in html
    t = sharp_and_blurred.texture
    words = " ".join(texture_lines(t))
    assert f"ratio {t.mtf50_ratio:.2f}" in words
    assert f"{t.snr_difference_db:+.1f} dB" in words
    assert 'aria-label="luminance MTF of each chart' in html
    assert 'aria-label="neutral patches' in html


def test_mtf50_markers_are_the_records_numbers(sharp_and_blurred):
    t = sharp_and_blurred.texture
    svg = cf.mtf_curves((("simulation", t.sim.frequencies, t.sim.mtf, t.sim.mtf50),
                         ("real camera", t.real.frequencies, t.real.mtf, t.real.mtf50)), 1.0)
    root = ET.fromstring(svg)
    texts = "".join(x.text or "" for x in root.iter(f"{SVG}text"))
    assert f"simulation: MTF50 {t.sim.mtf50:.3g} cy/px" in texts
    assert f"real camera: MTF50 {t.real.mtf50:.3g} cy/px" in texts
    # the plot area of mtf_curves: x 64 + 596 f / xmax, y 32 + 290 (1 - MTF / 1.05)
    y_half = 32 + 290 * (1 - 0.5 / 1.05)
    circles = [(float(c.get("cx")), float(c.get("cy"))) for c in root.iter(f"{SVG}circle")
               if c.get("fill") == COLOURS["blue"]]
    assert any(math.isclose(x, 64 + 596 * t.sim.mtf50, abs_tol=0.06)
               and math.isclose(y, y_half, abs_tol=0.06) for x, y in circles)
    squares = [(float(r.get("x")) + float(r.get("width")) / 2,
                float(r.get("y")) + float(r.get("height")) / 2)
               for r in root.iter(f"{SVG}rect") if r.get("fill") == COLOURS["orange"]]
    assert any(math.isclose(x, 64 + 596 * t.real.mtf50, abs_tol=0.06)
               and math.isclose(y, y_half, abs_tol=0.06) for x, y in squares)


def test_noise_figure_draws_every_patch_and_each_fit(sharp_and_blurred):
    t = sharp_and_blurred.texture
    fits = [(s.read_variance, s.gain) for s in (t.sim, t.real)]
    svg = cf.noise_curves((("simulation", t.sim.mu, t.sim.sigma, fits[0]),
                           ("real camera", t.real.mu, t.real.sigma, fits[1])))
    root = ET.fromstring(svg)
    n_circles = sum(1 for c in root.iter(f"{SVG}circle") if c.get("fill") == COLOURS["blue"])
    assert n_circles == len(t.sim.mu) + 1  # the patches and the legend's marker
    texts = "".join(x.text or "" for x in root.iter(f"{SVG}text"))
    assert f"σ² = {fits[1][0]:.3g} + {fits[1][1]:.3g} μ" in texts


def test_json_carries_the_curves_and_round_trips(sharp_and_blurred):
    d = json.loads(json.dumps(comparison_json(sharp_and_blurred)))
    s2 = d["sharpness_noise"]
    t = sharp_and_blurred.texture
    assert s2["sim"]["curve"]["frequencies"] == list(t.sim.frequencies)
    assert s2["real"]["curve"]["mtf"] == list(t.real.mtf)
    assert s2["real"]["noise"]["sigma"] == list(t.real.sigma)
    assert s2["mtf50_ratio"] == t.mtf50_ratio
    assert TextureComparison.from_json(s2) == t
    back = ComparisonReport.from_json(d)
    assert back.texture == t
    # the audits' luminance channel keeps its curve too
    y = _y_of_softer_edge(back.sim)
    assert y.curve == (t.sim.frequencies, t.sim.mtf)


def test_refused_sharpness_and_noiseless_charts_state_why(too_small):
    t = too_small.texture
    assert t is not None and t.mtf50_ratio is None and t.snr_difference_db is None
    assert {p for p, _ in t.not_compared} == {"sharpness", "noise"}
    sharp_why = dict(t.not_compared)["sharpness"]
    assert "simulation:" in sharp_why and "too small for an edge ROI" in sharp_why
    doc = comparison_document(too_small)
    ts = texture_section(too_small)
    # noise points exist on both sides (the section draws them), no MTF curves
    assert ts is not None
    html = render_html(doc)
    assert 'aria-label="luminance MTF of each chart' not in html
    assert re.search(r"sharpness not compared: simulation: horizontal", html)
    assert "noise not compared: a noiseless chart" in html


def test_section_absent_with_a_reason_line_when_nothing_can_be_drawn(too_small):
    from dataclasses import replace  # noqa: PLC0415

    t = too_small.texture
    gone = replace(t, sim=replace(t.sim, noise_missing="noise not measured", mu=(), sigma=(),
                                  patches=()),
                   not_compared=(t.not_compared[0], ("noise", "simulation: noise not measured")))
    report = replace(too_small, texture=gone)
    assert texture_section(report) is None
    doc = comparison_document(report)
    assert TEXTURE_TITLE not in [s.title for s in doc.sections]
    html = render_html(doc)
    assert "noise not compared: simulation: noise not measured" in html


def test_a_single_chart_report_draws_its_mtf_and_noise_curves(sharp_and_blurred, too_small):
    """The audit's own HTML (fidelity.report.chart): the softer edge's luminance MTF with its
    MTF50 and the neutral patches' σ against μ with the photon-transfer line, from the same
    record the comparison reads; neither where the chart's edges were refused and it is
    noiseless."""
    from fidelity.report.chart import chart_document, texture_figures

    real = sharp_and_blurred.real
    html = render_html(chart_document(real))
    assert 'aria-label="luminance MTF of the softer edge' in html
    assert 'aria-label="neutral patches: σ against μ with the photon-transfer fit' in html
    side = sharp_and_blurred.texture.real
    figs = texture_figures(real)
    assert len(figs) == 2
    texts = "".join(x.text or "" for x in ET.fromstring(figs[0].svg).iter(f"{SVG}text"))
    assert f"this chart: MTF50 {side.mtf50:.3g} cy/px" in texts
    texts = "".join(x.text or "" for x in ET.fromstring(figs[1].svg).iter(f"{SVG}text"))
    assert f"σ² = {side.read_variance:.3g} + {side.gain:.3g} μ" in texts
    assert not any("MTF" in f.alt for f in texture_figures(too_small.sim))


def test_the_image_figure_outlines_each_edge_region(sharp_and_blurred):
    """The image's figure draws each measured edge's region where the record puts it (its
    ROI over the image's display scale), labelled by direction."""
    from fidelity.report.chart import edge_regions

    real = sharp_and_blurred.real
    regions = edge_regions(real)
    assert regions and all(r == e.roi for r, e in zip(
        (r for _, r in regions), (e for e in real.sharpness.edges if e.roi), strict=True))
    pixels = np.asarray(read_image(Path(real.source.image.path)).pixels)
    svg = cf.chart_location(pixels, real.source.location, encoding=real.source.encoding,
                            edges=regions)
    root = ET.fromstring(svg)
    boxes = [r for r in root.iter(f"{SVG}rect") if r.get("stroke") == "#00e5ff"]
    assert len(boxes) == len(regions)
    h, w = pixels.shape[:2]
    zoom = min(cf.IMAGE_PX / w, max(1.0, 480.0 / w))
    for box, (_, (x0, y0, ew, eh)) in zip(boxes, regions, strict=True):
        assert float(box.get("x")) == pytest.approx(x0 * zoom, abs=0.01)
        assert float(box.get("y")) == pytest.approx(y0 * zoom + 30.0, abs=0.01)  # the title
        assert float(box.get("width")) == pytest.approx(ew * zoom, abs=0.01)
        assert float(box.get("height")) == pytest.approx(eh * zoom, abs=0.01)
    texts = [t.text for t in root.iter(f"{SVG}text")]
    assert all(label in texts for label, _ in regions)
