"""``fidelity check``: render the default camera, measure, predict, verdict, write the report."""

from __future__ import annotations

import json
import re
from pathlib import Path

import colour
import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.prediction.tablefile import DEFAULT_TABLE, prediction_dir

REPO = Path(__file__).resolve().parents[2]


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def default_check(tmp_path_factory):
    """``fidelity check`` with no arguments, run in an empty folder."""
    import os

    folder = tmp_path_factory.mktemp("check")
    old = os.getcwd()
    os.chdir(folder)
    try:
        result = run("check")
    finally:
        os.chdir(old)
    return folder, result


def _default_table_chord(delta_e: float) -> float:
    table = json.loads((prediction_dir() / f"{DEFAULT_TABLE}.json").read_text())
    assert table.get("interpolation") == "linear"
    curves = [c for c in table["curves"] if c.get("model") is None]
    any_size = [c for c in curves if c["size"] == "any"]
    values = []
    for c in any_size or curves:
        pts = [(p["delta_e"], p["dmap_points"]) for p in c["points"]
               if p.get("dmap_points") is not None]
        x = np.array([p[0] for p in pts])
        y = np.maximum.accumulate(np.array([p[1] for p in pts]))
        assert x[0] <= delta_e <= x[-1]
        values.append(float(np.interp(delta_e, x, y)))
    return max(values)


def test_no_arguments_prints_a_verdict_and_writes_the_report(default_check):
    from fidelity.camera.model import DEFAULT_CAMERA

    folder, r = default_check
    assert r.exit_code in (0, 1), r.output
    out = r.stdout
    assert "report: fidelity-report/report.html" in out
    assert (folder / "fidelity-report" / "report.html").is_file()
    doc = json.loads((folder / "fidelity-report" / "report.json").read_text())
    assert doc["command"] == "check" and doc["source"]["type"] == "render"
    assert doc["source"]["camera"] == DEFAULT_CAMERA
    # the chart: mean and max ΔE00, the max that of the worst patch
    patches = {p["name"]: p["delta_e"] for p in doc["patches"]}
    assert doc["mean_delta_e"] == pytest.approx(np.mean(list(patches.values())), abs=1e-12)
    assert doc["max_delta_e"] == max(patches.values()) == patches[doc["worst_patch"]]
    # the prediction at the chart's ΔE, from the default table, in points and % of baseline
    pred = doc["prediction"]
    assert pred["delta_e"] == doc["mean_delta_e"] and pred["table"]["name"] == DEFAULT_TABLE
    assert pred["dmap_points"] > 0 and pred["dmap_relative"] > pred["dmap_points"]
    # the default gate: mean ΔE00 <= 3
    v = doc["verdict"]
    assert (v["criterion"]["kind"], v["limit"]) == ("max-delta-e", 3.0)
    assert v["value"] == v["delta_e"] == doc["mean_delta_e"]
    assert v["passed"] == (doc["mean_delta_e"] <= 3.0) == (r.exit_code == 0)
    assert v["reason"] == ("within-limit" if v["passed"] else "over-limit")
    # a line per measurement and per prediction (the validated bound and the combined loss
    # included), none naming the validity domain: the default camera lies inside it
    lines = out.strip().splitlines()
    assert len(lines) <= 15 and not any("outside the validity domain" in ln for ln in lines)


@pytest.mark.parametrize("page", ["README.md", "docs/index.md", "docs/check.md"])
def test_readme_example_is_what_check_prints(default_check, page):
    """The ``$ fidelity check`` block of the README and the docs is the tool's real output,
    line for line."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / page).read_text(encoding="utf-8")
    block = re.search(r"```text\n\$ fidelity check\n(.*?)```", text, re.S)
    assert block, f"{page} lost its `$ fidelity check` example"
    _, r = default_check
    assert r.stdout.strip().splitlines() == block.group(1).strip().splitlines()


def test_report_numbers_agree_with_colour_science(default_check):
    jsonschema = pytest.importorskip("jsonschema")
    from fidelity.pipeline.records import report_schema

    folder, _ = default_check
    doc = json.loads((folder / "fidelity-report" / "report.json").read_text())
    jsonschema.validate(doc, report_schema())
    srgb = np.array([p["srgb"] for p in doc["patches"]])
    ref = np.array([p["reference_lab"] for p in doc["patches"]])
    lab = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(srgb))
    de = colour.delta_E(lab, ref, method="CIE 2000")
    # colour-science uses the 4-decimal IEC matrix: Lab agrees to about 0.01, ΔE to a few 1e-3
    assert doc["mean_delta_e"] == pytest.approx(float(de.mean()), abs=5e-3)
    assert doc["max_delta_e"] == pytest.approx(float(de.max()), abs=5e-3)
    # the default table's answer, recomputed from its file: the chord through the running
    # maximum of the size-"any" curve, else the worst over the aggregate (model-less) curves
    assert doc["prediction"]["dmap_points"] == pytest.approx(
        _default_table_chord(doc["mean_delta_e"]))
    html = (folder / "fidelity-report" / "report.html").read_text()
    # the verdict first, then the chart, the colour-error figures and the prediction curve
    assert html.index("PASS") < html.index('aria-label="the chart: reference against measured"')
    for alt in ("ΔE00 on the chart layout", "a*b* errors", "tone curve of the neutral patches",
                "ΔE00 per patch", "predicted loss in percentage points against chart ΔE",
                "predicted ΔmAP in % of baseline against chart ΔE",
                "worst case per transform family and the classic curve",
                "worst-case loss against mtf50, this chart&#x27;s point and the limit equivalent "
                "to the ΔE limit",
                "worst-case loss against snr, this chart&#x27;s point and the limit equivalent "
                "to the ΔE limit"):
        assert f'role="img" aria-label="{alt}"' in html
    # every figure is inline SVG drawn from the numbers, none a PNG
    # two prediction axes; the edge target's MTF curve and the noise curve
    assert html.count("<svg ") == 12 and "data:image/png" not in html
    assert "<details><summary>Patches</summary>" in html
    for text in ("Provenance", DEFAULT_TABLE, doc["provenance"]["version"]):
        assert text in html
    # the camera file's hash (the check's input), and the detectors the table measured
    import hashlib

    from fidelity.camera.model import DEFAULT_CAMERA
    from fidelity.core.resources import resource_dir

    shipped = resource_dir("data") / "cameras" / f"{DEFAULT_CAMERA}.toml"
    digest = hashlib.sha256(shipped.read_bytes()).hexdigest()
    assert doc["provenance"]["input_sha256"] == digest
    assert f"<th>camera file sha256</th><td>{digest}</td>" in html
    assert "yolox_nano" in html and "yolo11n-int8dyn" in html


def test_ideal_camera_passes_and_a_strict_limit_fails(tmp_path):
    r = run("check", "--camera", "ideal", "--out", tmp_path / "ideal")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "ideal" / "report.json").read_text())
    assert doc["mean_delta_e"] < 0.05  # the ideal camera sees the scene reference exactly
    v = doc["verdict"]
    assert v["passed"] is True and v["reason"] == "within-limit"
    assert (v["value"], v["limit"]) == (doc["mean_delta_e"], 3.0)
    r = run("check", "--max-delta-e", "0.01", "--out", tmp_path / "strict")
    assert r.exit_code == 1, r.output
    doc = json.loads((tmp_path / "strict" / "report.json").read_text())
    v = doc["verdict"]
    assert v["passed"] is False and v["reason"] == "over-limit"
    assert (v["value"], v["limit"]) == (doc["mean_delta_e"], 0.01) and v["value"] > 0.01


def test_unknown_camera_is_one_line_exit_2(tmp_path):
    r = run("check", "--camera", "no-such-camera", "--out", tmp_path / "x")
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: ")
    assert lines[0].startswith("fidelity: error: no-such-camera: unknown camera; known: ")
    assert not (tmp_path / "x").exists()


def test_a_soft_lens_fails_the_check_on_sharpness(tmp_path) -> None:
    """The rendered camera's sharpness and noise are measured on the turned chart and judged:
    the example camera with a Gaussian lens of 1.5 px (cameras/optics) passes on colour (ΔE00
    1.01) and fails on sharpness, at the MTF50 the closed form gives (0.1227 cy/px with the
    pixel aperture; the chart's edges read it 4 % high); the default camera's noise is
    judged."""
    from fidelity.pipeline.check import check_camera
    from fidelity.prediction.verdict import Criterion

    soft = check_camera(str(REPO / "cameras" / "optics" / "nikon5100-soft-lens.toml"),
                        criterion=Criterion("max-delta-e", 3.0))
    assert soft.mean_delta_e < 3 and not soft.verdict.passed
    assert soft.properties is not None
    (sharp,) = [p for p in soft.properties.predictions if p.property == "sharpness"]
    assert sharp.x == pytest.approx(0.1227, rel=0.05) and sharp.x > 0.1227
    assert sharp.loss is not None and sharp.loss > 2
    default = check_camera(None, criterion=Criterion("max-delta-e", 3.0))
    assert default.verdict is not None and default.verdict.passed
    assert default.properties is not None and not default.properties.not_judged
    assert {p.property for p in default.properties.predictions} == {"sharpness", "noise"}
    assert default.noise is not None and 20 < default.noise.grey_snr < 200
