"""fidelity compare: sim against real on synthetic chart images with known colours."""

from __future__ import annotations

import json
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.image import write_png
from fidelity.cli import main
from fidelity.colour.charts import load_reference
from fidelity.colour.colorimetry import delinearize_srgb, delta_e_2000, linearize_srgb, srgb_to_lab
from fidelity.pipeline.compare import compare_charts
from fidelity.pipeline.records import ComparisonReport
from fidelity.prediction.interval import prediction_interval
from fidelity.report.compare import comparison_lines
from fidelity.report.jsonform import comparison_json

PATCH, GAP = 40, 10
#: A known 3x3 colour matrix (linear light), what the "real camera" does differently.
M = np.array([[0.90, 0.08, 0.02], [0.05, 0.92, 0.03], [0.00, 0.10, 0.90]])


def _centre(i: int) -> tuple[float, float]:
    r, c = divmod(i, 6)
    return (GAP + c * (PATCH + GAP) + PATCH / 2 - 0.5, GAP + r * (PATCH + GAP) + PATCH / 2 - 0.5)


CORNERS = ",".join(f"{v:g}" for i in (0, 5, 23, 18) for v in _centre(i))


def _image(colours: np.ndarray) -> np.ndarray:
    img = np.zeros((4 * PATCH + 5 * GAP, 6 * PATCH + 7 * GAP, 3))
    for i, rgb in enumerate(colours):
        r, c = divmod(i, 6)
        y, x = GAP + r * (PATCH + GAP), GAP + c * (PATCH + GAP)
        img[y:y + PATCH, x:x + PATCH] = rgb
    return img


def _q16(x: np.ndarray) -> np.ndarray:
    return np.round(np.clip(x, 0, 1) * 65535) / 65535


@pytest.fixture(scope="module")
def charts(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cmp")
    sim = np.clip(load_reference("scene").srgb, 0, 1)
    real = np.clip(delinearize_srgb(np.clip(linearize_srgb(sim) @ M.T, 0, 1)), 0, 1)
    darker = np.clip(delinearize_srgb(linearize_srgb(sim) * 2 ** -0.5), 0, 1)
    paths = {}
    for name, colours in (("sim", sim), ("real", real), ("darker", darker)):
        paths[name] = write_png(folder / f"{name}.png", _image(colours), 16)
    return paths, sim, real


def test_a_chart_compared_with_itself_is_zero(charts):
    paths, _, _ = charts
    r = compare_charts(paths["sim"], paths["sim"], sim_corners=CORNERS, real_corners=CORNERS)
    assert r.mean_delta_e == 0.0 and r.max_delta_e == 0.0
    assert r.normalisation.exposure_ev == 0.0
    assert r.prediction.dmap_points == 0.0


def test_a_known_matrix_gives_the_closed_form_delta_e(charts):
    """Sim against the same chart through a 3x3 matrix: ΔE00 per patch is the closed form's
    (the colours as the 16-bit PNG stores them), direction signs included."""
    paths, sim, real = charts
    r = compare_charts(paths["sim"], paths["real"], sim_corners=CORNERS, real_corners=CORNERS,
                       normalise_mode="none")
    expected = delta_e_2000(srgb_to_lab(_q16(sim)), srgb_to_lab(_q16(real)))
    # float32 pixels as read: 5e-5 ΔE00
    np.testing.assert_allclose(r.measurement.delta_e, expected, atol=5e-5)
    assert r.mean_delta_e == pytest.approx(float(expected.mean()), abs=1e-5)
    # each chart's own ΔE against the reference is its audit's
    ref = load_reference("scene").lab
    for report, colours in ((r.sim, sim), (r.real, real)):
        assert report.mean_delta_e == pytest.approx(
            float(delta_e_2000(srgb_to_lab(_q16(colours)), ref).mean()), abs=5e-5)


def test_exposure_normalisation_removes_an_exposure_difference(charts):
    paths, _, _ = charts
    raw = compare_charts(paths["darker"], paths["sim"], sim_corners=CORNERS,
                         real_corners=CORNERS, normalise_mode="none")
    norm = compare_charts(paths["darker"], paths["sim"], sim_corners=CORNERS,
                          real_corners=CORNERS)
    assert raw.mean_delta_e > 3
    assert norm.normalisation.exposure_ev == pytest.approx(0.5, abs=0.01)
    assert norm.mean_delta_e < 0.3  # what is left: clipping of the brightest patches
    wb = compare_charts(paths["real"], paths["sim"], sim_corners=CORNERS, real_corners=CORNERS,
                        normalise_mode="exposure+wb")
    plain = compare_charts(paths["real"], paths["sim"], sim_corners=CORNERS,
                           real_corners=CORNERS)
    assert wb.normalisation.gains is not None and wb.mean_delta_e < plain.mean_delta_e


def test_compare_cli_gates_writes_junit_json_html(charts, tmp_path):
    paths, _, _ = charts
    args = ["compare", str(paths["sim"]), str(paths["real"]), "--sim-corners", CORNERS,
            "--real-corners", CORNERS, "--normalise", "none"]
    r = CliRunner().invoke(main, [*args, "--max-delta-e", "0.5", "--junit",
                                  str(tmp_path / "j.xml"), "--json", str(tmp_path / "c.json"),
                                  "--html", str(tmp_path / "c.html")])
    assert r.exit_code == 1, r.output
    suite = ET.parse(tmp_path / "j.xml").getroot().find("testsuite")
    assert suite.get("failures") == "1"
    # compare names itself, and says what it wrote as for every other output (issue 57)
    assert [c.get("classname") for c in suite.iter("testcase")] == ["fidelity.compare"]
    assert suite.find("testcase/properties/property[@name='mean_delta_e']") is not None
    wrote = [ln for ln in r.stdout.splitlines() if ln.startswith("wrote ")]
    assert wrote == [f"wrote {tmp_path / name}" for name in ("j.xml", "c.json", "c.html")]
    doc = json.loads((tmp_path / "c.json").read_text())
    # the gate judged the sim-to-real ΔE (not either chart's own) against the limit
    s2r = doc["sim_to_real"]
    direct = compare_charts(paths["sim"], paths["real"], sim_corners=CORNERS,
                            real_corners=CORNERS, normalise_mode="none")
    assert s2r["mean_delta_e"] == pytest.approx(direct.mean_delta_e, abs=1e-12)
    assert s2r["normalisation"]["mode"] == "none"
    v = doc["verdict"]
    assert v["passed"] is False and v["reason"] == "over-limit" and v["limit"] == 0.5
    assert v["value"] == v["delta_e"] == s2r["mean_delta_e"] > 0.5
    back = ComparisonReport.from_json(doc)
    assert comparison_json(back) == doc
    html = (tmp_path / "c.html").read_text()
    for alt in ("the simulated and the real chart, sampling windows outlined",
                "sim-to-real ΔE00 per patch",
                "a*b*: arrows from the simulated colour to the real one"):
        assert f'aria-label="{alt}"' in html
    r = CliRunner().invoke(main, [*args, "--max-delta-e", "10", "--json", "-"])
    assert r.exit_code == 0
    v = json.loads(r.stdout)["verdict"]
    assert v["passed"] is True and v["reason"] == "within-limit"
    assert v["value"] == s2r["mean_delta_e"] and v["limit"] == 10.0
    r = CliRunner().invoke(main, [*args, "--max-dmap", "100", "--bound", "directional",
                                  "--json", "-"])
    assert r.exit_code == 0
    out = json.loads(r.stdout)
    v = out["verdict"]
    # the direction-aware prediction at the sim-to-real ΔE decided it
    assert v["bound"] == out["bound"] == "directional" and v["reason"] == "within-limit"
    assert v["delta_e"] == pytest.approx(s2r["mean_delta_e"], abs=1e-12)
    assert v["value"] == pytest.approx(out["directional_prediction"]["dmap_points"])
    r = CliRunner().invoke(main, ["compare", str(paths["sim"]), str(tmp_path / "none.png"),
                                  "--max-delta-e", "1"])
    assert r.exit_code == 2 and r.stderr.startswith("fidelity: error:")


def test_compare_measure_needs_coco_inputs(charts, monkeypatch, tmp_path):
    paths, _, _ = charts
    monkeypatch.setenv("FIDELITY_SHARED", str(tmp_path / "nowhere"))
    r = CliRunner().invoke(main, ["compare", str(paths["sim"]), str(paths["real"]),
                                  "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--measure"])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("fidelity: error: ")
    assert "--images" in lines[0] and "FIDELITY_SHARED" in lines[0]


def test_compare_is_in_the_public_api():
    import fidelity

    assert fidelity.compare_charts is compare_charts
    assert Path(fidelity.compare_charts.__module__.replace(".", "/") + ".py").name == "compare.py"


def test_the_html_summary_states_the_uncertainty_and_the_interval(charts):
    """The summary table of the comparison page gives the sim-to-real ΔE with its standard
    uncertainty and the classic prediction with its interval, as the terminal does."""
    from fidelity.measure.uncertainty import uncertain_text
    from fidelity.report.compare import comparison_document
    from fidelity.report.document import Facts

    paths, _, _ = charts
    r = compare_charts(paths["sim"], paths["real"], sim_corners=CORNERS, real_corners=CORNERS,
                       normalise_mode="none")
    assert r.uncertainty is not None and r.interval is not None
    assert r.uncertainty.value == pytest.approx(r.mean_delta_e, abs=1e-12)
    facts = next(b for s in comparison_document(r).sections for b in s.blocks
                 if isinstance(b, Facts))
    rows = dict(facts.items)
    u = r.uncertainty.combined
    assert rows["sim-to-real ΔE00"].startswith(f"mean {uncertain_text(r.mean_delta_e, u)} (k=1)")
    assert f"± {r.interval.standard_uncertainty:.2f} (k=1) points" in \
        rows["predicted ΔmAP of the difference, classic"]


def test_compare_states_each_loss_column_with_its_own_uncertainty(charts, tmp_path):
    """Every loss column of the comparison's prediction has its own ± (k = 1): that column's
    table SE and the sim-to-real ΔE's uncertainty through that column's slope, the same
    numbers prediction_interval gives for the column, printed beside each value."""
    paths, _, _ = charts
    r = compare_charts(paths["sim"], paths["real"], sim_corners=CORNERS, real_corners=CORNERS,
                       normalise_mode="none")
    by = {i.column: i for i in r.intervals}
    assert set(by) == {"dmap_points", "dmap_relative", "dap_person_points",
                       "dap_bicycle_points"}
    u = r.uncertainty.combined
    for column, i in by.items():
        direct = prediction_interval(r.prediction, u, column, 2.0)
        assert i.standard_uncertainty == pytest.approx(direct.standard_uncertainty, rel=1e-12)
        assert i.table_se is not None and i.table_se > 0  # the column's own SE, not none
    # the relative column's SE is its own, not the points column's
    assert by["dmap_relative"].table_se != by["dmap_points"].table_se
    text = "\n".join(comparison_lines(r))
    p = r.prediction
    assert (f"{p.dmap_relative:.2f} ± {by['dmap_relative'].standard_uncertainty:.2f} "
            "% of baseline") in text
    assert (f"person {p.dap_person_points:.2f} ± "
            f"{by['dap_person_points'].standard_uncertainty:.2f} points") in text
    assert (f"bicycle {p.dap_bicycle_points:.2f} ± "
            f"{by['dap_bicycle_points'].standard_uncertainty:.2f} points") in text
    # the record keeps them
    back = ComparisonReport.from_json(comparison_json(r))
    assert [i.to_json() for i in back.intervals] == [i.to_json() for i in r.intervals]
