"""The exposure judged, not hidden (issue 57): a render of an exported chart scene gated with
its manifest is measured at the manifest's expected exposure, and an image with four times
the light fails by +2.00 EV; without a manifest the normalisation is stated and the exposure
named as not judged.

The renders are the scene's closed form (:func:`tests.fixtures.chart_scenes.closed_form_render`:
each patch its albedo x white level, the frame its reflectance); the exposure error of a
scaled copy is log2 of the scale, exactly.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.image import write_exr
from fidelity.chart.read import ReadOptions
from fidelity.cli import main
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.pipeline.check import audit_image
from fidelity.pipeline.records import ChartReport
from fidelity.prediction.exposure import ExposureJudgement, judge_exposure
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.verdict import Criterion
from fidelity.scene.export import export_scene
from fidelity.scene.manifest import read_manifest
from fidelity.scene.model import build_scene
from tests.fixtures.chart_scenes import closed_form_render

SIZE = (320, 240)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """An exported glTF scene at a white level other than 1 (its manifest's exposure is not
    0), its correct render and one with four times the light."""
    root = tmp_path_factory.mktemp("exposure")
    scene = build_scene("D65", resolution=SIZE, white_level=0.8)
    export_scene(scene, "mitsuba", root / "chart")
    right, bright = root / "right.exr", root / "bright.exr"
    write_exr(right, closed_form_render(scene).astype(np.float32))
    write_exr(bright, (4.0 * closed_form_render(scene)).astype(np.float32))
    return scene, root / "chart" / "manifest.json", right, bright


def test_the_manifest_reads_back_what_the_export_wrote(exported):
    scene, manifest, _, _ = exported
    m = read_manifest(manifest)
    assert m.corners == scene.corners_option()
    assert m.exposure_ev == pytest.approx(-math.log2(0.8))
    assert (m.white_level, m.reference, m.illuminant) == (0.8, scene.reference, "D65")
    assert read_manifest(manifest.parent) == m  # the folder stands for its manifest.json


@pytest.mark.parametrize("text, problem", [
    ("{", "not JSON"), ('{"kind": "x"}', "not a chart scene manifest"),
    ('{"kind": "fidelity chart scene", "white_level": 1, "corners": "1,2"}',
     "expected_exposure.gate_exposure_ev is not a finite number"),
])
def test_a_bad_manifest_is_one_line_naming_it(tmp_path, text, problem):
    p = tmp_path / "m odd.json"
    p.write_text(text)
    with pytest.raises(InputFileError, match=problem):
        read_manifest(p)
    r = CliRunner().invoke(main, ["gate", str(tmp_path / "x.exr"), "--manifest", str(p),
                                  "--max-delta-e", "1"])
    assert r.exit_code == 2


def test_four_times_the_light_is_plus_two_ev(exported):
    _, manifest, right, bright = exported
    m = read_manifest(manifest)
    judge = JudgeOptions(exposure_source="manifest")
    crit = Criterion("max-delta-e", 0.5)
    ok = audit_image(right, m.corners, read=ReadOptions(exposure=m.exposure_ev),
                     criterion=crit, judge=judge)
    assert ok.exposure is not None and ok.exposure.error_ev == pytest.approx(0.0, abs=1e-4)
    assert ok.verdict is not None and ok.verdict.passed
    over = audit_image(bright, m.corners, read=ReadOptions(exposure=m.exposure_ev),
                       criterion=crit, judge=judge)
    assert over.exposure is not None
    assert over.exposure.error_ev == pytest.approx(2.0, abs=1e-4)
    assert over.exposure.factor == pytest.approx(4.0, rel=1e-4)
    assert over.verdict is not None and not over.verdict.passed
    assert over.verdict.exposure == over.exposure
    # auto exposure normalises it away: nothing judged, the colour alone passes
    auto = audit_image(bright, m.corners, criterion=crit)
    assert auto.exposure is None and auto.exposure_ev == pytest.approx(-2 + m.exposure_ev,
                                                                        abs=1e-4)
    assert auto.verdict is not None and auto.verdict.passed


def test_gate_with_the_manifest_fails_the_bright_render_and_says_why(exported, tmp_path):
    _, manifest, right, bright = exported
    r = CliRunner().invoke(main, ["gate", str(right), "--manifest", str(manifest),
                                  "--max-delta-e", "0.5"])
    assert r.exit_code == 0, r.output
    assert "exposure correction fixed at +0.32 EV; the image +0.00 EV from the expected exposure" in r.output
    out = tmp_path / "bright.json"
    r = CliRunner().invoke(main, ["gate", str(bright), "--manifest", str(manifest),
                                  "--max-delta-e", "0.5", "--json", str(out),
                                  "--junit", str(tmp_path / "j.xml")])
    assert r.exit_code == 1, r.output
    verdict = [ln for ln in r.output.splitlines() if ln.startswith("FAIL")]
    assert verdict and "FAIL: mean ΔE00 24.52 > 0.5 (" in verdict[0]
    assert "), and exposure +2.00 EV from the expected (|error| > 0.3 EV)" in verdict[0]
    doc = json.loads(out.read_text())
    assert doc["exposure"]["error_ev"] == pytest.approx(2.0, abs=1e-4)
    assert doc["exposure"]["source"] == "manifest" and doc["exposure"]["passed"] is False
    assert doc["verdict"]["exposure"] == doc["exposure"]
    back = ChartReport.from_json(doc)
    assert back.exposure == ExposureJudgement.from_json(doc["exposure"])
    assert "+2.00 EV" in (tmp_path / "j.xml").read_text()
    # measured at the expected exposure, the colour fails by itself; a wider exposure limit
    # leaves the colour's failure alone in the verdict
    assert doc["mean_delta_e"] > 10
    r = CliRunner().invoke(main, ["gate", str(bright), "--manifest", str(manifest),
                                  "--max-delta-e", "0.5", "--max-exposure-error", "2.1"])
    assert r.exit_code == 1, r.output
    verdict = [ln for ln in r.output.splitlines() if ln.startswith("FAIL")]
    assert verdict and "exposure" not in verdict[0]
    assert "+2.00 EV from the expected exposure (4 x as bright; limit ±2.1 EV" in r.output


def test_without_a_manifest_the_normalisation_is_stated(exported):
    _, _, _, bright = exported
    r = CliRunner().invoke(main, ["audit", str(bright)])
    assert r.exit_code == 0, r.output
    assert ("exposure normalised: -1.68 EV on the neutral patches (auto: the image's own "
            "exposure is not judged" in r.output)


def test_an_explicit_exposure_is_judged_too(exported):
    scene, _, _, bright = exported
    r = CliRunner().invoke(main, ["gate", str(bright), "--corners", scene.corners_option(),
                                  "--exposure", f"{-math.log2(0.8)}", "--max-delta-e", "3"])
    assert r.exit_code == 1, r.output
    assert "the expected exposure from --exposure" in r.output


def test_the_explicit_options_win_over_the_manifest(exported):
    """--exposure given beside --manifest is the expected exposure (its source named)."""
    _, manifest, _, bright = exported
    r = CliRunner().invoke(main, ["gate", str(bright), "--manifest", str(manifest),
                                  "--exposure", f"{-math.log2(0.8) - 2}", "--max-delta-e", "1"])
    assert r.exit_code == 0, r.output
    assert "the expected exposure from --exposure" in r.output


def test_judge_exposure_hard_cases():
    assert judge_exposure(0.0, None, 0.3, "manifest") is None  # black neutrals: nothing
    e = judge_exposure(0.5, 0.5 - 0.3, 0.3, "--exposure")
    assert e is not None and e.passed  # the limit itself passes
    assert str(e.error_ev) != "-0.0"
    with pytest.raises(InvalidValueError):
        judge_exposure(0.0, 0.0, 0.0, "manifest")
    with pytest.raises(InvalidValueError):
        judge_exposure(0.0, 0.0, float("nan"), "manifest")
    with pytest.raises(InvalidValueError):
        JudgeOptions(max_exposure_error=-1)


@pytest.mark.parametrize("mode", ["none", "exposure", "exposure+wb"])
def test_compare_reports_the_real_exposure_difference(exported, mode):
    """Both renders auto-exposed by their audits: the sim-to-real ΔE is ~0 whatever the
    normalisation, and the difference the audits took out is still reported: +2.00 EV."""
    from fidelity.pipeline.compare import compare_charts

    scene, _, right, bright = exported
    c = scene.corners_option()
    report = compare_charts(bright, right, sim_corners=c, real_corners=c, normalise_mode=mode)
    assert report.normalisation.difference_ev == pytest.approx(2.0, abs=1e-4)
    assert report.normalisation.audit_auto == (True, True)
    assert "the simulation's pixels are +2.000 EV from the real camera's" in \
        (report.normalisation.difference_words() or "")
    assert report.measurement.mean_delta_e < 0.05
    # at a fixed exposure the audits keep it (the bright chart clips), and the difference is
    # the same, measured on the linear means
    fixed = compare_charts(bright, right, sim_corners=c, real_corners=c, normalise_mode=mode,
                           read=ReadOptions(exposure=0.0))
    assert fixed.normalisation.difference_ev == pytest.approx(2.0, abs=1e-4)
    assert fixed.normalisation.audit_auto == (False, False)
    assert fixed.measurement.mean_delta_e > (10 if mode == "none" else 1)
    back = type(fixed.normalisation).from_json(fixed.normalisation.to_json())
    assert back == fixed.normalisation


def test_fit_without_normalisation_corrects_the_exposure(exported, tmp_path):
    """fit --normalise none of a render with four times the light: SIM is measured at REAL's
    exposure (not auto-exposed away), so the gains are 1/4 and the cube brings ΔE 24.5 to ~0;
    the report states the +2 EV difference."""
    pytest.importorskip("PyOpenColorIO", reason="the [fit] extra (opencolorio)")
    scene, _, right, bright = exported
    c = scene.corners_option()
    out = tmp_path / "fit"
    r = CliRunner().invoke(main, ["fit", str(bright), str(right), "--sim-corners", c,
                                  "--real-corners", c, "--normalise", "none",
                                  "--correction", "gains", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "the simulation's pixels are +2.000 EV from the real camera's" in r.output
    assert "already matches" not in r.output
    corr = json.loads((out / "correction.json").read_text())
    np.testing.assert_allclose(corr["gains"], 0.25, rtol=1e-3)
    report = json.loads((out / "report.json").read_text())
    assert report["before"]["mean_delta_e"] > 10 and report["after"]["mean_delta_e"] < 0.05
