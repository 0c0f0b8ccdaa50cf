"""The diagnosis in every report (issue 57): the terminal's ``diagnosis:`` line, the HTML
summary, the JSON report (its schema) and a failed gate's JUnit message; on camera models of
the validation suite whose mistake their files state (an exposure 0.7 EV over, white balance
for D50 under D65) and on the built-in camera, whose colour error is its sensitivities'."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.pipeline.check import check_camera
from fidelity.pipeline.records import ChartReport
from fidelity.report.chart import chart_document, summary_facts
from fidelity.report.jsonform import chart_report_json
from fidelity.report.terminal import summary_lines

CAMERAS = Path(__file__).resolve().parents[2] / "cameras"
OVER = CAMERAS / "nikon5100-overexposed.toml"


def stated_overexposure() -> float:
    """The file's exposure error: its fixed gain against the auto gain its comment states
    (``auto gain 0.9932 x 2^0.7``)."""
    text = OVER.read_text()
    gain = tomllib.loads(text)["exposure"]["gain"]
    return math.log2(gain / 0.9932)


def test_the_terminal_html_and_json_carry_the_cause(tmp_path):
    report = check_camera(str(OVER))
    ev = stated_overexposure()
    d = report.diagnosis
    assert d is not None and [c.kind for c in d.causes] == ["exposure"]
    assert d.exposure_ev == pytest.approx(ev, abs=0.05)
    lines = summary_lines(report)
    assert f"diagnosis: exposure {ev:+.2f} EV" in "\n".join(lines)
    facts = dict(summary_facts(report).items)
    assert facts["likely cause (a camera pipeline fitted to the patches)"].startswith(
        f"exposure {ev:+.2f} EV")
    assert "likely cause" in json.dumps(chart_document(report).sections[0].blocks[0].items,
                                        ensure_ascii=False)
    doc = json.loads(json.dumps(chart_report_json(report)))
    again = ChartReport.from_json(doc)  # checked against the report schema first
    assert again.diagnosis == d and doc["diagnosis"]["causes"][0]["kind"] == "exposure"


def test_a_camera_without_a_pipeline_cause_prints_no_diagnosis_line():
    report = check_camera("nikon-5100")
    assert report.diagnosis is not None and not report.diagnosis.systematic
    assert not any(ln.startswith("diagnosis:") for ln in summary_lines(report))


def test_a_failed_gates_junit_message_names_the_cause(tmp_path):
    junit = tmp_path / "colour.xml"
    r = CliRunner().invoke(main, ["gate", "--camera", str(OVER), "--max-delta-e", "3",
                                  "--junit", str(junit)])
    assert r.exit_code == 1, r.output
    failure = ET.parse(junit).getroot().find(".//failure")
    assert failure is not None
    message = failure.get("message") or ""
    assert message.startswith("FAIL: mean ΔE00 9.85 > 3")
    assert f"; likely cause: exposure {stated_overexposure():+.2f} EV" in message
    assert failure.text == message


def test_a_failure_without_a_cause_says_only_the_verdict(tmp_path):
    junit = tmp_path / "colour.xml"
    r = CliRunner().invoke(main, ["gate", "--camera", "nikon-5100", "--max-delta-e", "0.5",
                                  "--junit", str(junit)])
    assert r.exit_code == 1, r.output
    message = ET.parse(junit).getroot().find(".//failure").get("message")
    assert message.startswith("FAIL: mean ΔE00 1.02 > 0.5") and "likely cause" not in message


def test_white_balance_for_the_wrong_light_is_named():
    d = check_camera(str(CAMERAS / "nikon5100-wb-d50.toml")).diagnosis
    assert d is not None and d.causes[0].kind == "white-balance", d.summary()
    # white balanced for D50 under D65: too little red correction, too much blue
    assert d.causes[0].values["red_gain"] < 1 < d.causes[0].values["blue_gain"]


def test_a_four_times_too_bright_exr_reads_plus_2_ev_everywhere(tmp_path):
    """The scene's closed form with 4x the light (the missing USD importer scale), audited at
    its corners with the exposure fixed: the diagnosis, the HTML's tone fit (the clipped
    patches left out: gamma 1, not 0.63) and the JUnit message all say +2.00 EV."""
    from fidelity.chart.image import read_image, write_exr
    from fidelity.chart.read import ReadOptions
    from fidelity.pipeline.check import audit_image
    from fidelity.report.chart import tone_facts
    from tests.pipeline.test_no_false_alarms import closed_form_scene

    files, corners = closed_form_scene(tmp_path)
    bright = write_exr(tmp_path / "x4.exr", read_image(files["exr"]).pixels * 4.0)
    report = audit_image(bright, corners, read=ReadOptions(exposure=0.0))
    d = report.diagnosis
    assert [c.kind for c in d.causes] == ["exposure"]
    assert d.exposure_ev == pytest.approx(2.0, abs=0.01)
    (label, text), = tone_facts(report)
    assert text.startswith("gamma 1.000 relative to the reference, exposure +2.00 EV")
    junit = tmp_path / "x4.xml"
    r = CliRunner().invoke(main, ["gate", str(bright), "--corners", corners, "--exposure", "0",
                                  "--max-delta-e", "3", "--junit", str(junit)])
    assert r.exit_code == 1, r.output
    assert "diagnosis: exposure +2.00 EV" in r.output
    message = ET.parse(junit).getroot().find(".//failure").get("message")
    assert "; likely cause: exposure +2.00 EV: every patch ×4.000" in message
