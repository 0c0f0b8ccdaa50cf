"""The chart report's SVG figures (fidelity.report.svg, fidelity.report.chartfigures) and the
numbers a colour engineer reads in the report: per-patch SNR and "no noise", the fitted tone
curve, ΔE*ab and ΔE94 (issues 30 and 31)."""

from __future__ import annotations

import base64
import io
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference
from fidelity.measure.colour import (
    NOISE_FLOOR,
    chart_statistics,
    fit_tone,
    measure_chart,
    neutral_patches,
    patch_snr_db,
)
from fidelity.report import chartfigures as cf
from fidelity.report.svg import Scale, magma_r, nice_ticks, png_data_uri, symlog_ticks

SVG = "{http://www.w3.org/2000/svg}"


@pytest.fixture(scope="module")
def ref():
    return load_reference("safecolor")


def _measured(ref, lab, noise=None):
    return measure_chart(cm.lab_to_srgb(lab), ref.lab, ref.patch_names,
                         reference_srgb=ref.srgb, noise=noise)


def _texts(svg: str) -> list[ET.Element]:
    return list(ET.fromstring(svg).iter(SVG + "text"))


def test_magma_r_follows_matplotlibs_map():
    mpl = pytest.importorskip("matplotlib")
    cmap = mpl.colormaps["magma_r"]
    for t in np.linspace(0.0, 1.0, 41):
        want = np.array(cmap(float(t))[:3])
        got = np.array([int(magma_r(float(t))[i:i + 2], 16) for i in (1, 3, 5)]) / 255
        assert np.abs(got - want).max() < 0.02, t


def test_png_data_uri_decodes_to_the_pixels():
    from PIL import Image

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (7, 11, 3)).astype(np.float64) / 255.0
    img[0, 0] = np.nan  # drawn black
    uri = png_data_uri(img)
    assert uri.startswith("data:image/png;base64,")
    back = np.asarray(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))))
    want = np.round(np.nan_to_num(img) * 255).astype(np.uint8)
    np.testing.assert_array_equal(back, want)
    with pytest.raises(ValueError):
        png_data_uri(np.zeros((4, 4)))


def test_ticks_and_the_symlog_scale():
    assert nice_ticks(0, 3.2) == [0, 1, 2, 3]
    assert nice_ticks(0, 30) == [0, 10, 20, 30]
    assert nice_ticks(-100, 100) == [-100, -50, 0, 50, 100]
    assert symlog_ticks(105) == [0, 1, 2, 5, 10, 20, 50, 100]
    s = Scale(0.0, 100.0, "symlog")
    # linear below 1, one decade per unit above, continuous at 1
    np.testing.assert_allclose(s.transform(np.array([0.5, 1.0, 10.0, 100.0])),
                               [0.5, 1.0, 2.0, 3.0])
    assert float(s.fraction(100.0)) == pytest.approx(1.0)
    assert float(s.fraction(0.0)) == 0.0


def test_every_figure_is_valid_svg_with_legible_text(ref):
    rng = np.random.default_rng(0)
    m = _measured(ref, ref.lab + rng.normal(0, 2, ref.lab.shape),
                  noise=np.full((24, 3), 0.01))
    figures = {
        "swatches": cf.swatches(m), "map": cf.delta_e_map(m, 1.5),
        "bars": cf.delta_e_bars(m, 1.5), "ab": cf.ab_arrows(m),
        "tone": cf.tone_curve(m, neutral_patches(m), fit_tone(m)),
    }
    for name, svg in figures.items():
        root = ET.fromstring(svg)  # well-formed XML
        assert root.tag == SVG + "svg", name
        sizes = [float(t.get("font-size", "0")) for t in root.iter(SVG + "text")]
        assert sizes and min(sizes) >= 11, name  # issue 31: swatch labels were ~7 px
    # the numbers written are the measurement's
    swatch = [t.text for t in _texts(figures["swatches"])]
    for k, name in enumerate(m.patch_names):
        assert f"{k + 1} {name}" in swatch and f"ΔE {m.delta_e[k]:.2f}" in swatch
    cells = [t.text for t in _texts(figures["map"])]
    assert all(f"{v:.2f}" in cells for v in m.delta_e)
    # outlined cells: those above the limit
    outlined = [r for r in ET.fromstring(figures["map"]).iter(SVG + "rect")
                if r.get("stroke") == "#d62728"]
    assert len(outlined) == int(np.sum(m.delta_e > 1.5))


def test_bars_are_proportional_to_delta_e(ref):
    lab = ref.lab.copy()
    lab[:, 0] += np.linspace(0.0, 6.0, 24)
    m = _measured(ref, lab)
    root = ET.fromstring(cf.delta_e_bars(m))
    bars = [r for r in root.iter(SVG + "rect") if r.get("stroke") == "#000"
            and r.get("stroke-width") == "0.5"]
    heights = np.array([float(b.get("height")) for b in bars])
    assert len(bars) == 24
    np.testing.assert_allclose(heights / heights.max(), m.delta_e / m.delta_e.max(), atol=0.01)


def _arrow_lengths(svg: str) -> np.ndarray:
    root = ET.fromstring(svg)
    lines = [ln for ln in root.iter(SVG + "line") if ln.get("stroke") == "#000"
             and ln.get("stroke-width") == "1.3"]
    heads = [p for p in root.iter(SVG + "polygon") if p.get("fill") == "#000"]
    assert len(lines) == len(heads)
    out = []
    for ln, head in zip(lines, heads, strict=True):
        tip = [float(v) for v in head.get("points").split()[0].split(",")]
        out.append(np.hypot(tip[0] - float(ln.get("x1")), tip[1] - float(ln.get("y1"))))
    return np.array(out)


def test_small_ab_errors_are_magnified_and_numbered(ref):
    rng = np.random.default_rng(1)
    d = rng.normal(0, 0.3, (24, 3))
    d[:, 0] = 0.0
    small = _measured(ref, ref.lab + d)
    svg = cf.ab_arrows(small)
    title = next(t.text for t in _texts(svg) if t.text.startswith("a*b*:"))
    k = int(re.search(r"errors drawn ×(\d+)", title).group(1))
    lengths = _arrow_lengths(svg)
    assert len(lengths) == 24
    # visible beyond the 6.5 px markers: the median arrow is about 14 px
    assert np.median(lengths) >= 13.5
    # the arrows are the true errors times k, in the plot's pixels per a*b* unit
    err = np.hypot(*(small.lab[:, 1:] - small.reference_lab[:, 1:]).T)
    ratio = lengths / err
    assert np.ptp(ratio) / ratio.mean() < 0.02 and k > 1
    numbers = {t.text for t in _texts(svg)}
    assert {str(i) for i in range(1, 25)} <= numbers
    # large errors are drawn as they are
    big = _measured(ref, ref.lab + np.array([0.0, 8.0, -6.0]))
    assert not any("errors drawn" in t.text for t in _texts(cf.ab_arrows(big)))


def test_fit_tone_recovers_a_power_law(ref):
    gamma, offset = 1.15, -0.4
    y_ref = cm.lab_to_xyz(ref.lab)[:, 1]
    y_meas = 0.18 * 2.0 ** offset * (y_ref / 0.18) ** gamma
    lab = ref.lab.copy()
    lab[:, 0] = cm.xyz_to_lab(np.repeat(y_meas[:, None], 3, axis=1), white=(1.0, 1.0, 1.0))[:, 0]
    fit = fit_tone(_measured(ref, lab))
    assert fit is not None and fit.patches == 6
    assert fit.gamma == pytest.approx(gamma, abs=1e-9)
    assert fit.offset_ev == pytest.approx(offset, abs=1e-9)
    assert fit.rms_ev < 1e-9
    np.testing.assert_allclose(fit.predict(y_ref), y_meas, rtol=1e-9)
    # one neutral with light: no fit
    assert fit_tone(_measured(ref, lab), neutral_patches(_measured(ref, lab))[:1]) is None


def test_patch_snr_and_no_noise(ref):
    m = _measured(ref, ref.lab, noise=np.full((24, 3), 0.01))
    snr = patch_snr_db(m)
    mean = m.srgb.mean(axis=1)
    np.testing.assert_allclose(snr, 20 * np.log10(mean / 0.01))
    stats = chart_statistics(m)
    assert not stats.noise_free and stats.worst_patch == m.patch_names[int(np.argmin(snr))]
    assert stats.worst_patch_snr_db == pytest.approx(float(snr.min()))
    # a noise-free render: rounding-level spread is no noise, not 290 dB
    quiet = _measured(ref, ref.lab, noise=np.full((24, 3), 1e-16))
    assert np.all(np.isposinf(patch_snr_db(quiet)))
    qs = chart_statistics(quiet)
    assert qs.noise_free and qs.snr_db is None and qs.worst_patch is None
    # just above the floor it is a number again
    assert np.all(np.isfinite(patch_snr_db(_measured(ref, ref.lab,
                                                     noise=np.full((24, 3), 2 * NOISE_FLOOR)))))
    # a black patch with noise has no signal (NaN), never an error
    noisy = measure_chart(np.zeros((24, 3)), ref.lab, ref.patch_names,
                          noise=np.full((24, 3), 0.01))
    assert np.all(np.isnan(patch_snr_db(noisy)))
    assert chart_statistics(noisy).snr_db is None
    assert patch_snr_db(_measured(ref, ref.lab)) is None


def test_delta_e_1994_and_1976_agree_with_colour_science():
    colour = pytest.importorskip("colour")
    # colour-science's documented example of delta_E_CIE1994
    a = np.array([48.99183622, -0.10561667, 400.65619925])
    b = np.array([50.65907324, -0.11671910, 402.82235718])
    assert float(cm.delta_e_1994(a, b)) == pytest.approx(1.6711191, abs=1e-7)
    rng = np.random.default_rng(7)
    lab1 = rng.uniform([0, -120, -120], [100, 120, 120], (2000, 3))
    lab2 = lab1 + rng.normal(0, 6, lab1.shape)
    for textiles in (False, True):
        np.testing.assert_allclose(
            cm.delta_e_1994(lab1, lab2, textiles=textiles),
            colour.difference.delta_E_CIE1994(lab1, lab2, textiles=textiles), atol=1e-10)
    np.testing.assert_allclose(cm.delta_e(lab1, lab2, "CIE 1994"),
                               colour.delta_E(lab1, lab2, method="CIE 1994"), atol=1e-10)
    np.testing.assert_allclose(cm.delta_e_1976(lab1, lab2),
                               colour.delta_E(lab1, lab2, method="CIE 1976"), atol=1e-10)
    # identical colours, float32 in -> float32 out, not symmetric
    assert float(cm.delta_e_1994(a, a)) == 0.0
    assert cm.delta_e_1994(lab1.astype(np.float32), lab2.astype(np.float32)).dtype == np.float32
    assert float(cm.delta_e_1994(lab1[0], lab2[0])) != float(cm.delta_e_1994(lab2[0], lab1[0]))


def test_markdown_writes_the_svg_figures(tmp_path, ref):
    from fidelity.report.document import Document, Headline, section, svg_figure
    from fidelity.report.html import write_document

    m = _measured(ref, ref.lab + 1.0)
    fig = svg_figure(cf.swatches(m), "swatches.svg", "the chart")
    doc = Document("t", Headline("h", figure=fig), (section("s", fig),))
    written = write_document(doc, html=tmp_path / "r.html", markdown=tmp_path / "r.md")
    assert (tmp_path / "swatches.svg") in written
    ET.fromstring((tmp_path / "swatches.svg").read_text(encoding="utf-8"))
    assert "![the chart](swatches.svg)" in (tmp_path / "r.md").read_text(encoding="utf-8")
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert html.count('role="img" aria-label="the chart"') == 2


def test_log_ticks_and_scale():
    from fidelity.report.svg import log_ticks

    assert log_ticks(0.3, 120) == [0.5, 1, 2, 5, 10, 20, 50, 100]
    assert log_ticks(1, 1) == [] and log_ticks(0, 10) == []
    s = Scale(0.1, 100.0, "log")
    np.testing.assert_allclose(s.fraction(np.array([0.1, 1.0, 10.0, 100.0])),
                               [0, 1 / 3, 2 / 3, 1])
    assert np.isnan(s.transform(0.0)) and np.isnan(s.transform(-1.0))


def test_error_bars_are_clipped_and_never_nan():
    """Axes.bars: a bar spans y - lower .. y + upper in pixels; one beyond the plot area is
    clipped to it without a cap there; zero-length bars, NaN values and (on a log axis) ends
    at or below zero are left out, so no coordinate is ever NaN."""
    from fidelity.report.svg import Axes, Canvas

    c = Canvas(200, 200)
    ax = Axes(c, 20, 10, 160, 100, Scale(0.0, 10.0), Scale(0.0, 10.0))
    ax.bars([5.0, 6.0, 7.0, np.nan], [4.0, 5.0, 9.0, 1.0], [1.0, 0.0, 1.0, 1.0],
            [2.0, 0.0, 5.0, 1.0], "#123456")
    lines = [ln for ln in ET.fromstring(c.render()).iter(SVG + "line")]
    assert len(lines) == 3 + 2  # bar + 2 caps; clipped bar + 1 cap; zero and NaN: none
    bar = lines[0]
    assert float(bar.get("x1")) == float(ax.px(5.0))
    assert sorted(float(bar.get(k)) for k in ("y1", "y2")) == [float(ax.py(6.0)),
                                                              float(ax.py(3.0))]
    assert min(float(lines[3].get(k)) for k in ("y1", "y2")) == ax.y  # clipped at the top
    log = Canvas(200, 200)
    lax = Axes(log, 20, 10, 160, 100, Scale(0.0, 10.0), Scale(0.1, 100.0, "log"))
    lax.bars([1.0, 2.0], [1.0, 2.0], [1.0, 0.5], [1.0, 1.0], "#000")
    svg = log.render()
    assert "nan" not in svg.lower()
    assert len(list(ET.fromstring(svg).iter(SVG + "line"))) == 3  # only the bar from 1.5 to 3
