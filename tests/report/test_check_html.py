"""The HTML check report an assessor reads (issue 58): points and % of baseline on separate,
labelled axes, each curve with the table's ± 1 SE band, the detectors and the table named,
the input's SHA-256 shown, every column's ± in the summary, and a pass outside the validity
domain not shown as a plain green pass."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.pipeline.check import DEFAULT_CRITERION, check_camera
from fidelity.pipeline.records import GateResult
from fidelity.prediction.table import predict
from fidelity.report.chartfigures import _se_band
from fidelity.report.gate import gate_overview_document

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "fidelity" / "data" / "prediction" / "coco1000-measured.json"


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    out = tmp_path_factory.mktemp("html")
    r = CliRunner().invoke(main, ["--no-config", "check", "--html", str(out / "r.html"),
                                  "--json", str(out / "r.json")])
    assert r.exit_code == 0, r.output
    return (out / "r.html").read_text(encoding="utf-8"), json.loads(
        (out / "r.json").read_text(encoding="utf-8"))


def _figure(html: str, label: str) -> str:
    found = re.search(r'<svg[^>]*aria-label="' + re.escape(label) + r'".*?</svg>', html, re.S)
    assert found, label
    return found.group(0)


def _texts(svg: str) -> list[str]:
    return [re.sub(r"<[^>]+>", "", t) for t in re.findall(r"<text[^>]*>.*?</text>", svg, re.S)]


def test_points_and_percent_on_separate_labelled_axes_with_bands(page):
    html, _ = page
    points = _figure(html, "predicted loss in percentage points against chart ΔE")
    relative = _figure(html, "predicted ΔmAP in % of baseline against chart ΔE")
    pt, rt = _texts(points), _texts(relative)
    assert any(t.startswith("predicted loss, percentage points") for t in pt)
    assert any(t.startswith("predicted ΔmAP, % of the baseline mAP") for t in rt)
    assert "ΔmAP (% of baseline)" not in pt and "ΔmAP (points)" not in rt
    # one band per column with SEs: three in points, one in percent
    band = r'<polygon[^>]*fill-opacity="0.15"'
    assert len(re.findall(band, points)) == 3 and len(re.findall(band, relative)) == 1
    assert "± 1 SE of the table (k=1)" in pt and "± 1 SE of the table (k=1)" in rt


@pytest.mark.parametrize("column", ["dmap_points", "dmap_relative", "dap_bicycle_points"])
def test_the_band_is_the_tables_stated_se(column):
    """At the table's points the band's half-width is the SE the size-class curve states."""
    curve = next(c for c in json.loads(SHIPPED.read_text())["curves"] if c["model"] is None)
    xs = np.array([p["delta_e"] for p in curve["points"][1:6]])
    se = _se_band(predict(1.0), column, xs)
    assert se is not None
    np.testing.assert_allclose(se, [p[f"{column}_se"] for p in curve["points"][1:6]])


def test_detectors_table_hash_and_every_columns_u_are_shown(page):
    html, doc = page
    text = re.sub(r"<[^>]+>", " ", html)
    shipped = REPO / "fidelity" / "data" / "cameras" / "nikon-5100.toml"
    assert f"camera file sha256 {hashlib.sha256(shipped.read_bytes()).hexdigest()}" in \
        re.sub(r"\s+", " ", text)
    assert "detectors measured yolo11n-int8dyn, yolov10n-int8dyn, yolov8n-int8dyn, " \
           "yolox_nano" in re.sub(r"\s+", " ", text)
    assert "prediction table coco1000-measured (measured)" in re.sub(r"\s+", " ", text)
    u = {i["column"]: i["standard_uncertainty"] for i in doc["prediction_intervals"]}
    flat = re.sub(r"\s+", " ", text)
    assert f"{doc['prediction']['dap_bicycle_points']:.2f} ± {u['dap_bicycle_points']:.2f} " \
           "(k=1), u ≥ the value: mostly noise" in flat
    assert f"{doc['prediction']['dmap_relative']:.2f} ± {u['dmap_relative']:.2f} (k=1)" in flat


def test_a_pass_outside_the_domain_is_amber(page, tmp_path):
    """A scene under an illuminant the validation did not render (D50) passes outside the
    validity domain: an amber banner naming it, not a plain green pass; the default camera
    under D65 is inside."""
    _, inside = page
    assert inside["validity"]["inside"]
    r = CliRunner().invoke(main, ["--no-config", "check", "--illuminant", "D50",
                                  "--html", str(tmp_path / "r.html"),
                                  "--json", str(tmp_path / "r.json")])
    assert r.exit_code == 0, r.output
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    doc = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    assert doc["verdict"]["passed"] and not doc["validity"]["inside"]
    banner = re.search(r'class="headline tone-(\w+)">(.*?)</div>', html, re.S)
    assert banner and banner.group(1) == "outside"
    assert "PASS — outside the validity domain" in banner.group(2)
    assert "illuminant D50: not among those the validation rendered" in banner.group(2)
    assert ".tone-outside{" in html


def test_a_gate_overview_of_passes_outside_the_domain_is_amber():
    """All subjects pass, one outside: the overview says how many and is not plain green."""
    noisy = check_camera("nikon-5100", illuminant="D50")
    clean = check_camera(str(REPO / "cameras" / "nikon5100-cheung-d65.toml"))
    assert clean.validity.inside and not noisy.validity.inside
    cases = [GateResult(n, DEFAULT_CRITERION, report=r)
             for n, r in (("noisy", noisy), ("clean", clean))]
    doc = gate_overview_document(cases, [None, None])
    assert doc.headline.tone == "outside"
    assert "1 of 2 outside the validity domain" in doc.headline.message
    assert gate_overview_document(cases[1:], [None]).headline.tone == "pass"


@pytest.mark.parametrize("camera", [None, "ideal-gauss0.5.toml"])
def test_each_mtf50_cell_above_nyquist_says_so(tmp_path, camera):
    """The per-edge, per-channel table marks exactly the MTF50 cells whose value is above the
    0.5 cy/px Nyquist frequency, as the terminal's line does: the default camera's edge
    target (MTF50 0.58-0.62 cy/px) all eight, a 0.5 px Gaussian lens (0.37 cy/px) none."""
    extra = [] if camera is None else ["--camera", str(REPO / "cameras" / "properties" / camera)]
    r = CliRunner().invoke(main, ["--no-config", "check", "--html", str(tmp_path / "r.html"),
                                  "--json", str(tmp_path / "r.json"), *extra])
    assert r.exit_code in (0, 1), r.output
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    record = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    cells = re.findall(r'<tr><td>(horizontal|vertical)</td><td>[^<]*</td><td>([RGBY])</td>'
                       r'<td class="num">([^<]*)</td>', html)
    channels = [(e["direction"], c["channel"], c["mtf50"])
                for e in record["sharpness"]["edges"] for c in e["channels"]]
    assert len(cells) == len(channels) == 8
    for (direction, channel, text), (d, ch, mtf50) in zip(cells, channels, strict=True):
        assert (direction, channel) == (d, ch)
        assert text.endswith(" (above Nyquist)") == (mtf50 > 0.5), (text, mtf50)
    assert sum(t.endswith(" (above Nyquist)") for *_, t in cells) == (8 if camera is None else 0)
