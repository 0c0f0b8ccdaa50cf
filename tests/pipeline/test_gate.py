"""``fidelity gate`` / ``audit`` / ``predict`` on the command line: exit codes, reports, JUnit,
and one clear stderr line for every kind of bad input."""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import colour
import numpy as np
import OpenEXR
import pytest
from click.testing import CliRunner
from PIL import Image as PILImage

from fidelity.cli import main
from fidelity.colour.charts import load_chart
from fidelity.core.errors import InvalidValueError
from fidelity.core.resources import resource_dir
from fidelity.prediction.table import predict
from fidelity.prediction.tablefile import DEFAULT_TABLE
from fidelity.prediction.transforms import apply_transform
from fidelity.prediction.verdict import Criterion, evaluate
from tests.pipeline.test_audit import (
    corners_of,
    draw_chart,
    expected_delta_e,
    write_exr,
    write_png8,
)

CHART = load_chart("safecolor")
SRGB = apply_transform(CHART.srgb, "contrast-inc", 1.3)


@pytest.fixture(scope="module")
def png(tmp_path_factory) -> tuple[Path, float]:
    """An 8-bit chart image and its chart ΔE (colour-science on the stored values)."""
    path = tmp_path_factory.mktemp("img") / "chart.png"
    write_png8(path, draw_chart(SRGB))
    return path, expected_delta_e(np.rint(SRGB * 255) / 255, CHART.lab)


def run(*args: str):
    """Run the CLI; audits and gates of an image compare with the paper's chart (CHART.lab),
    as the expected values here are computed, unless a test names its reference."""
    argv = [str(a) for a in args]
    if argv[0] in ("audit", "gate") and "--reference" not in argv and "--camera" not in argv:
        argv += ["--reference", "safecolor"]
    return CliRunner().invoke(main, argv)


def one_error_line(result) -> str:
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("fidelity: error: ")
    assert "Traceback" not in result.output
    return lines[0]


def test_gate_pass_and_fail_on_delta_e(png, tmp_path):
    path, de = png
    ok = run("gate", path, "--corners", corners_of(), "--max-delta-e", f"{de + 0.1:.3f}")
    assert ok.exit_code == 0, ok.output
    bad = run("gate", path, "--corners", corners_of(), "--max-delta-e", f"{de - 0.1:.3f}",
              "--junit", tmp_path / "j.xml", "--json", tmp_path / "r.json", "--html", tmp_path / "r.html")
    assert bad.exit_code == 1, bad.output
    root = ET.parse(tmp_path / "j.xml").getroot()
    suite = root.find("testsuite")
    assert root.get("failures") == "1" and suite.get("tests") == "1"
    props = {p.get("name"): p.get("value") for p in suite.iter("property")}
    assert float(props["mean_delta_e"]) == pytest.approx(de, abs=0.02)
    assert suite.find("testcase/failure") is not None
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mean_delta_e"] == pytest.approx(de, abs=0.02)
    verdict = report["verdict"]
    assert verdict["passed"] is False and verdict["reason"] == "over-limit"
    assert verdict["criterion"]["kind"] == "max-delta-e"
    assert verdict["limit"] == pytest.approx(float(f"{de - 0.1:.3f}"))
    assert verdict["value"] == verdict["delta_e"] == report["mean_delta_e"]
    html = (tmp_path / "r.html").read_text()
    # swatches, sampling windows, ΔE map, a*b*, tone curve, ΔE bars, the prediction curves in
    # points and in % of baseline, the direction-aware family curves, and one curve per
    # property judged besides colour, and the chart's own MTF and noise curves where measured
    judged = len(report["properties"]["predictions"])
    texture = (report["sharpness"] is not None and any(
        c["channel"] == "Y" and c.get("curve") for e in report["sharpness"]["edges"]
        for c in e["channels"])) + (report["noise"] is not None)
    assert html.count("<svg ") == 9 + judged + texture
    assert html.index("FAIL") < html.index('aria-label="sampling windows"')
    assert report["provenance"]["input_sha256"] in html


def _day_and_dusk(png: tuple[Path, float], folder: Path) -> tuple[Path, float, Path, float]:
    """Two renders of the chart, and their chart ΔE: day.png (the ``png`` fixture's) and
    dusk.png (a stronger contrast increase)."""
    import shutil

    path, de = png
    day = folder / "day.png"
    shutil.copy(path, day)
    dusk = folder / "dusk.png"
    srgb = apply_transform(CHART.srgb, "contrast-inc", 1.8)
    write_png8(dusk, draw_chart(srgb))
    return day, de, dusk, expected_delta_e(np.rint(srgb * 255) / 255, CHART.lab)


def test_gate_several_images_one_junit_case_each(png, tmp_path):
    """Three renders: one passes, one fails, one cannot be measured: exit 2, a JUnit suite of
    three cases with their own properties, one JSON and HTML report per measured image."""
    good, de, worse, worse_de = _day_and_dusk(png, tmp_path)
    limit = f"{de + 0.1:.3f}"
    assert worse_de > de + 0.1
    cut = _truncated_png(tmp_path)
    out = tmp_path / "reports"
    r = run("gate", good, worse, cut, "--corners", corners_of(), "--max-delta-e", limit,
            "--junit", tmp_path / "j.xml", "--json", out, "--html", out)
    assert r.exit_code == 2, r.output
    assert one_error_line(r).startswith(f"fidelity: error: {cut}: ")
    # one passed, one failed, one could not be measured
    suite = ET.parse(tmp_path / "j.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("3", "1", "1")
    cases = suite.findall("testcase")
    assert cases[0].find("failure") is None and cases[0].find("error") is None
    assert [c.get("name").split(":")[0] for c in cases] == [
        f"colour fidelity of {p}" for p in (good, worse, cut)]
    means = [float(c.find("properties/property[@name='mean_delta_e']").get("value"))
             for c in cases[:2]]
    assert means == pytest.approx([de, worse_de], abs=0.02)
    assert cases[1].find("failure") is not None and cases[2].find("error") is not None
    assert cases[2].find("error").get("message").startswith(f"{cut}: ")
    assert sorted(p.name for p in out.iterdir()) == ["day.png.html", "day.png.json",
                                                     "dusk.png.html", "dusk.png.json",
                                                     "index.html"]
    # the overview: the outcome, a row per image (the one not measured unlinked, its error)
    page = (out / "index.html").read_text()
    assert "1 of 3 passed" in page and "1 failed" in page and "1 not measured" in page
    assert page.count('href="day.png.html"') == 1 and page.count('href="dusk.png.html"') == 1
    assert "Over the frames" not in page
    day = json.loads((out / "day.png.json").read_text())
    assert day["mean_delta_e"] == pytest.approx(de, abs=0.02)
    assert day["verdict"]["passed"] is True and day["verdict"]["reason"] == "within-limit"
    dusk = json.loads((out / "dusk.png.json").read_text())
    assert dusk["mean_delta_e"] == pytest.approx(worse_de, abs=0.02)
    assert dusk["verdict"]["passed"] is False and dusk["verdict"]["reason"] == "over-limit"
    assert dusk["verdict"]["value"] == dusk["mean_delta_e"]
    assert dusk["verdict"]["limit"] == day["verdict"]["limit"] == pytest.approx(float(limit))
    # without the broken one: exit 1; all passing: exit 0
    assert run("gate", good, worse, "--corners", corners_of(), "--max-delta-e",
               limit).exit_code == 1
    assert run("gate", good, good.rename(tmp_path / "noon.png"), "--corners", corners_of(),
               "--max-delta-e", limit).exit_code == 2  # day.png was renamed away: missing
    ok = run("gate", tmp_path / "noon.png", "--corners", corners_of(), "--max-delta-e", limit,
             "--json", out)  # an existing folder: the report goes in it
    assert ok.exit_code == 0 and (out / "noon.png.json").is_file()
    # two images of one name cannot share a report folder
    import shutil

    (tmp_path / "a").mkdir()
    shutil.copy(tmp_path / "noon.png", tmp_path / "a" / "noon.png")
    r = run("gate", tmp_path / "noon.png", tmp_path / "a" / "noon.png", "--corners",
            corners_of(), "--max-delta-e", limit, "--json", out)
    assert r.exit_code == 2 and "noon.png" in one_error_line(r)
    r = run("audit", tmp_path / "noon.png", "--corners", corners_of(), "--json", out,
            "--html", out)
    assert r.exit_code == 0 and {"noon.png.json", "noon.png.html"} <= {p.name for p in out.iterdir()}


def test_gate_on_predicted_person_loss(png, tmp_path):
    path, de = png
    # safecolor-2025, person: ΔAP < 1 at ΔE 3 and 100 (AP 0) at ΔE 24, chord between them
    person = 1.0 + (de - 3.0) * 99.0 / 21.0
    assert 3 < de < 24
    ok = run("gate", path, "--corners", corners_of(), "--max-dmap", f"{person + 0.2:.3f}", "--class", "person",
             "--table", "safecolor-2025")
    assert ok.exit_code == 0, ok.output
    bad = run("gate", path, "--corners", corners_of(), "--max-dmap", f"{person - 0.2:.3f}", "--class", "person",
              "--table", "safecolor-2025", "--json", tmp_path / "r.json")
    assert bad.exit_code == 1
    doc = json.loads((tmp_path / "r.json").read_text())
    measured = doc["mean_delta_e"]
    assert measured == pytest.approx(de, abs=0.02)
    v = doc["verdict"]
    assert v["passed"] is False and v["reason"] == "over-limit"
    assert (v["criterion"]["kind"], v["criterion"]["cls"], v["criterion"]["unit"]) == (
        "max-dmap", "person", "points")
    assert v["limit"] == pytest.approx(float(f"{person - 0.2:.3f}"))
    # the chord at the ΔE measured, a published upper bound, read inside the table's range
    assert v["value"] == pytest.approx(1.0 + (measured - 3.0) * 99.0 / 21.0, rel=1e-9)
    assert v["value"] == doc["prediction"]["dap_person_points"]
    assert v["delta_e"] == measured
    assert v["upper_bound"] is True and v["table"] == "safecolor-2025"
    assert v["status"] == "interpolated" and v["conservative_answer"] is False


def test_gate_camera(tmp_path):
    r = run("gate", "--camera", "ideal", "--max-delta-e", "0.05", "--junit", tmp_path / "j.xml")
    assert r.exit_code == 0, r.output
    assert ET.parse(tmp_path / "j.xml").getroot().get("failures") == "0"


def test_report_json_matches_the_schema(png, tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    from fidelity.pipeline.records import report_schema

    path, _ = png
    r = run("audit", path, "--corners", corners_of(), "--json", tmp_path / "a.json")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "a.json").read_text())
    jsonschema.validate(doc, report_schema())
    assert doc["command"] == "audit" and doc["verdict"] is None
    for key in ("mean_delta_e", "max_delta_e", "patches", "exposure_ev", "bad_pixels"):
        assert key in doc
    # the per-patch Lab in the report agrees with colour-science's ΔE00 against the reference
    lab = np.array([p["lab"] for p in doc["patches"]])
    ref = np.array([p["reference_lab"] for p in doc["patches"]])
    np.testing.assert_allclose([p["delta_e"] for p in doc["patches"]],
                               colour.delta_E(lab, ref, method="CIE 2000"), atol=1e-6)
    bad = dict(doc)
    bad["mean_delta_e"] = "large"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, report_schema())


def test_audit_linear_exr_cli(tmp_path):
    scale = 0.3
    write_exr(tmp_path / "c.exr", colour.cctf_decoding(draw_chart(SRGB), function="sRGB") * scale)
    r = run("audit", tmp_path / "c.exr", "--corners", corners_of(), "--exposure", f"{-math.log2(scale)}",
            "--json", tmp_path / "a.json")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "a.json").read_text())
    assert doc["mean_delta_e"] == pytest.approx(expected_delta_e(SRGB, CHART.lab), abs=0.02)
    assert doc["source"]["format"] == "openexr" and doc["exposure_ev"] == pytest.approx(-math.log2(scale))


def test_audit_several_images_one_report_each(png, tmp_path):
    """``audit a b c`` (a shell glob): each image audited as ``audit`` of it alone gives, a
    report per image in the folders, the one that cannot be read one error line and exit 2,
    and one credibility record with a subject per image."""
    day, de, dusk, dusk_de = _day_and_dusk(png, tmp_path)
    out = tmp_path / "reports"
    r = run("audit", day, dusk, "--corners", corners_of(), "--json", out, "--html", out,
            "--evidence", tmp_path / "ev.json")
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["day.png.html", "day.png.json",
                                                     "dusk.png.html", "dusk.png.json",
                                                     "index.html"]
    means = [json.loads((out / f"{n}.png.json").read_text())["mean_delta_e"]
             for n in ("day", "dusk")]
    assert means == pytest.approx([de, dusk_de], abs=0.02)
    assert r.stdout.splitlines()[-1] == "audit: 2 of 2 images measured"
    # the overview: no verdicts; each image's chart ΔE in the plot and the table, linked
    page = (out / "index.html").read_text()
    assert "2 of 2 images measured" in page and "passed" not in page
    assert page.count('href="day.png.html"') == 1 and page.count('href="dusk.png.html"') == 1
    assert f"{means[0]:.3f} ± " in page and f"{means[1]:.3f} ± " in page
    assert 'aria-label="chart ΔE over the images of the images audited"' in page
    # the same report as the image audited alone
    alone = run("audit", dusk, "--corners", corners_of(), "--json", tmp_path / "alone.json")
    assert alone.exit_code == 0, alone.output
    assert json.loads((tmp_path / "alone.json").read_text())["patches"] == \
        json.loads((out / "dusk.png.json").read_text())["patches"]
    record = json.loads((tmp_path / "ev.json").read_text())
    assert [s["subject"] for s in record["subjects"]] == [str(day), str(dusk)]
    assert record["record"]["exit_code"] == 0
    again = run("verify", tmp_path / "ev.json", "--rerun")  # the record repeats its run
    assert again.exit_code == 0 and "run again: reproduced" in again.stdout, again.output

    cut = _truncated_png(tmp_path)
    again = tmp_path / "again"
    r = run("audit", day, cut, dusk, "--corners", corners_of(), "--json", again, "--html", again)
    assert r.exit_code == 2, r.output
    assert one_error_line(r).startswith(f"fidelity: error: {cut}: ")
    assert sorted(p.name for p in again.iterdir()) == [
        "day.png.html", "day.png.json", "dusk.png.html", "dusk.png.json", "index.html"]
    page = (again / "index.html").read_text()
    assert "2 of 3 images measured" in page and "1 not measured" in page
    assert "cut.png" in page and 'href="cut.png.html"' not in page
    assert r.stdout.splitlines()[-1] == "audit: 2 of 3 images measured, 1 could not be"
    # standard output takes one report
    r = run("audit", day, dusk, "--json", "-")
    assert r.exit_code == 2 and "takes one IMAGE" in one_error_line(r)


def test_predict_cli(tmp_path):
    r = run("predict", "--delta-e", "4.5", "--class", "bicycle", "--table", "safecolor-2025",
            "--json", tmp_path / "p.json")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "p.json").read_text())
    # chords between the published bounds: ΔmAP (3, 1)-(6, 3); bicycle ΔAP = ΔE between 1 and 11
    assert doc["dmap_points"] == pytest.approx(2.0)
    assert doc["dap_bicycle_points"] == pytest.approx(4.5)
    assert doc["table"]["name"] == "safecolor-2025"
    assert len(doc["transforms"]) == 10
    # published upper bounds, answered inside the table's range
    assert doc["bound"] is True and doc["out_of_range"] is False
    assert doc["table"]["kind"] == "published-bounds" and doc["size_used"] == "any"
    assert doc["columns"]["dap_bicycle_points"]["status"] == "interpolated"
    listing = run("predict", "--list-tables").stdout.splitlines()
    assert any(line.startswith("safecolor-2025") for line in listing)
    assert [line.split(" ")[0] for line in listing if "(default)" in line] == [DEFAULT_TABLE]


def test_verdict_logic():
    p = predict(5.0, table="safecolor-2025", transforms=False)
    v = evaluate(5.0, p, Criterion("max-dmap", 3.0))
    assert v.passed and v.value == pytest.approx(1 + 2 * 2 / 3)
    assert not evaluate(5.0, p, Criterion("max-delta-e", 4.99)).passed
    assert evaluate(5.0, p, Criterion("max-delta-e", 5.0)).passed
    far = evaluate(30.0, predict(30.0, table="safecolor-2025", transforms=False),
                   Criterion("max-dmap", 50.0))
    assert not far.passed and far.conservative
    with pytest.raises(InvalidValueError, match="relative"):
        Criterion("max-dmap", 1.0, "person", "relative")
    with pytest.raises(InvalidValueError):
        Criterion("max-delta-e", -1.0)


# ----------------------------------------------------------------------------- bad input

def _truncated_png(tmp: Path) -> Path:
    write_png8(tmp / "full.png", draw_chart(SRGB))
    data = (tmp / "full.png").read_bytes()
    (tmp / "cut.png").write_bytes(data[: len(data) // 2])
    return tmp / "cut.png"


def _one_channel(tmp: Path) -> Path:
    PILImage.fromarray(np.zeros((260, 300), np.uint8), "L").save(tmp / "grey.png")
    return tmp / "grey.png"


def _unknown_channels(tmp: Path) -> Path:
    z = np.zeros((260, 300), np.float32)
    OpenEXR.File({}, {"X": z, "Y": z, "Z": z}).write(str(tmp / "xyz.exr"))
    return tmp / "xyz.exr"


@pytest.mark.parametrize("make,corners,pattern", [
    (lambda t: t / "missing.png", None, r"missing\.png: image does not exist"),
    (_truncated_png, None, r"cut\.png: truncated or corrupt"),
    (_one_channel, None, r"grey\.png: one-channel image"),
    (_unknown_channels, None, r"xyz\.exr: unknown channels \(X, Y, Z\)"),
    ("png", "5,5,290,5,290,9000,5,250", r"chart\.png: corner 'black' at \(290, 9000\) is outside"),
    ("png", "100,100,110,100,110,106,100,106", r"chart\.png: chart too small to sample"),
])
def test_bad_image_input(png, tmp_path, make, corners, pattern):
    path = png[0] if make == "png" else make(tmp_path)
    for cmd in (["audit"], ["gate", "--max-delta-e", "3"]):
        r = run(*cmd, path, "--corners", corners or corners_of())
        assert r.exit_code == 2, r.output
        assert re.search(pattern, one_error_line(r)), r.stderr


def test_unknown_camera_and_table(png, tmp_path):
    r = run("gate", "--camera", "no-such-camera", "--max-delta-e", "3", "--junit", tmp_path / "j.xml")
    assert r.exit_code == 2
    assert "error: no-such-camera: unknown camera; known: " in one_error_line(r)
    err = ET.parse(tmp_path / "j.xml").getroot().find("testsuite/testcase/error")
    assert err is not None and "no-such-camera" in err.get("message")
    r = run("gate", png[0], "--corners", corners_of(), "--max-delta-e", "3", "--table", "nope")
    assert r.exit_code == 2 and "error: nope: unknown prediction table" in one_error_line(r)
    r = run("predict", "--delta-e", "2", "--table", "nope")
    assert r.exit_code == 2 and "error: nope: unknown prediction table" in one_error_line(r)


def test_without_corners_the_chart_is_found_and_gated_the_same(png, tmp_path):
    path, de = png
    report = tmp_path / "r.json"
    given = run("gate", path, "--corners", corners_of(), "--max-delta-e", f"{de + 0.1:.3f}",
                "--json", report)
    assert json.loads(report.read_text())["source"]["corners_found"] is None
    found = run("gate", path, "--max-delta-e", f"{de + 0.1:.3f}", "--json", report)
    assert found.exit_code == given.exit_code == 0, found.output
    # the found chart: segmentation, its corner patches within half a pixel of the drawn ones
    chart = json.loads(report.read_text())["source"]["corners_found"]
    assert chart["method"] == "segmentation" and chart["swatches"] == 24
    truth = np.array([float(v) for v in corners_of().split(",")]).reshape(4, 2)
    np.testing.assert_allclose(chart["corners"], truth, atol=0.5)
    assert found.stdout.splitlines()[1:] == given.stdout.splitlines()
    assert run("gate", path, "--max-delta-e", f"{de - 0.1:.3f}").exit_code == 1


def test_usage_errors_exit_2(png):
    assert run("gate", png[0], "--corners", corners_of()).exit_code == 2  # no criterion
    assert run("gate", "--camera", "ideal", "--max-delta-e", "3", "--max-dmap", "1").exit_code == 2
    assert run("gate", "--camera", "ideal", "--max-delta-e", "3", "--class", "person").exit_code == 2
    assert run("predict").exit_code == 2
    assert run("gate", "--camera", "ideal", "--corners", corners_of(), "--max-delta-e", "3").exit_code == 2
    assert run("gate", "--camera", "ideal", "--max-delta-e", "abc").exit_code == 2


def test_an_internal_error_exits_3_with_the_traceback_in_a_log(png, monkeypatch, tmp_path):
    import fidelity.pipeline.check as check_mod

    def boom(*a, **k):
        raise RuntimeError("disk on fire\nsecond line")

    monkeypatch.setattr(check_mod, "audit_image", boom)
    monkeypatch.setenv("FIDELITY_CACHE", str(tmp_path / "cache"))
    r = run("gate", png[0], "--corners", corners_of(), "--max-delta-e", "3")
    assert r.exit_code == 3
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output
    assert lines[0].startswith("fidelity: internal error: RuntimeError: disk on fire second line")
    (log,) = (tmp_path / "cache" / "logs").glob("fidelity-*.log")
    assert "Traceback" in log.read_text() and str(log) in lines[0]


def test_report_never_overwrites_the_input(png, tmp_path):
    import shutil

    src = tmp_path / "in.png"
    shutil.copy(png[0], src)
    before = src.read_bytes()
    r = run("gate", src, "--corners", corners_of(), "--max-delta-e", "3", "--json", src)
    assert r.exit_code == 2 and one_error_line(r).startswith(f"fidelity: error: {src}: ")
    assert src.read_bytes() == before
    # --junit too, also on the error path that writes a JUnit error case
    r = run("gate", src, "--corners", corners_of(), "--max-delta-e", "3", "--junit", src)
    assert r.exit_code == 2 and one_error_line(r).startswith(f"fidelity: error: {src}: ")
    assert "--junit" in one_error_line(r)
    assert src.read_bytes() == before
    table = tmp_path / "table.json"
    table.write_text((Path(__file__).parents[2] / "fidelity/data/prediction"
                      / f"{DEFAULT_TABLE}.json").read_text())
    for args in (("gate", "--camera", "ideal", "--max-delta-e", "3", "--table", table,
                  "--junit", table),
                 ("predict", "--delta-e", "3", "--table", table, "--json", table),
                 ("audit", src, "--corners", corners_of(), "--table", table, "--html", table),
                 ("calibrate", "--chart", table, "--json", table)):
        before_table = table.read_bytes()
        r = run(*args)
        assert r.exit_code == 2, args
        assert one_error_line(r).startswith(f"fidelity: error: {table}: "), args
        assert table.read_bytes() == before_table
    r = run("gate", src, "--corners", corners_of(), "--max-delta-e", "3",
            "--json", tmp_path / "r", "--html", tmp_path / "r")
    assert r.exit_code == 2 and one_error_line(r).startswith(f"fidelity: error: {tmp_path / 'r'}: ")
    assert not (tmp_path / "r").exists()


def test_exr_in_bt2020_primaries_is_converted_by_its_chromaticities_attribute(tmp_path):
    """Test data built with the published BT.2087 matrix (not fidelity's): the audit of a
    BT.2020 render equals the audit of the same chart in sRGB primaries."""
    from tests.colour.test_colorimetry import BT2087_2020_TO_709

    lin709 = colour.cctf_decoding(CHART.srgb, function="sRGB")
    lin2020 = lin709 @ np.linalg.inv(BT2087_2020_TO_709).T
    srgb_exr, bt2020_exr, bare_exr = (tmp_path / n for n in ("a.exr", "b.exr", "c.exr"))
    write_exr(srgb_exr, draw_chart(lin709).astype(np.float32))
    data = {c: np.ascontiguousarray(draw_chart(lin2020)[..., i]).astype(np.float32)
            for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION,
              "chromaticities": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290)}
    OpenEXR.File(header, data).write(str(bt2020_exr))
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, data).write(str(bare_exr))

    def audit(*args: object) -> dict:
        r = run("audit", *args, "--corners", corners_of(), "--json", tmp_path / "r.json")
        assert r.exit_code == 0, r.output
        return json.loads((tmp_path / "r.json").read_text())

    def mean_de(*args: object) -> float:
        return audit(*args)["mean_delta_e"]

    want = mean_de(srgb_exr)
    bt2020 = audit(bt2020_exr)
    assert bt2020["mean_delta_e"] == pytest.approx(want, abs=0.01)
    # the primaries were taken from the file's chromaticities attribute
    assert bt2020["source"]["chromaticities"] == pytest.approx(header["chromaticities"],
                                                               abs=1e-6)
    assert bt2020["source"]["colourspace"].startswith("chromaticities")
    assert mean_de(bare_exr, "--colourspace", "ITU-R BT.2020") == pytest.approx(want, abs=0.01)
    assert mean_de(bare_exr) > want + 3  # taken as sRGB primaries: desaturated, visibly wrong
    r = run("audit", bare_exr, "--corners", corners_of(), "--colourspace", "BT.2021")
    assert r.exit_code == 2 and ": BT.2021: unknown RGB colourspace" in one_error_line(r)
    assert str(bare_exr) in one_error_line(r)


def test_negative_values_are_kept_by_default_and_said_so(tmp_path):
    lin = colour.cctf_decoding(CHART.srgb, function="sRGB")
    lin[17] = [-0.02, 0.18, 0.33]  # the cyan of a scene-linear render: red below zero
    path = tmp_path / "neg.exr"
    write_exr(path, draw_chart(lin).astype(np.float32))
    kept = run("audit", path, "--corners", corners_of(), "--json", tmp_path / "r.json")
    assert kept.exit_code == 0, kept.output
    doc = json.loads((tmp_path / "r.json").read_text())
    bad = doc["bad_pixels"]
    cyan = next(p for p in doc["patches"] if p["name"] == "cyan")
    # every pixel of the cyan window has a negative channel, and each is kept in the mean
    assert bad["negatives"] == "keep" and bad["total"] == 0
    assert bad["negative"] == cyan["valid_pixels"] > 100
    assert doc["details"]["clipped_patches"] == ["cyan"]
    excluded = run("audit", path, "--corners", corners_of(), "--negatives", "exclude")
    line = one_error_line(excluded)
    assert excluded.exit_code == 2 and line.startswith(f"fidelity: error: {path}: ")
    assert "'cyan'" in line


def test_the_overview_links_a_report_named_with_spaces_and_shows_names_as_written():
    """Report names come from image names: a space in the link, and Markdown's own characters
    in a name or an error, show as written."""
    from fidelity.pipeline.records import GateResult
    from fidelity.report.gate import gate_overview_document
    from fidelity.report.html import render_html

    cases = [GateResult("day *2* [a].exr", error="no chart | found"),
             GateResult("dusk_1_.exr", error="x")]
    page = render_html(gate_overview_document(cases, ["day *2* [a].exr.html", None]))
    assert 'href="day%20*2*%20%5Ba%5D.exr.html"' in page
    assert "day *2* [a].exr</a>" in page and "no chart | found" in page
    assert "dusk_1_.exr" in page and "<em>" not in page
    assert "0 of 2 passed" in page and "2 not measured" in page


def test_audit_images_api_gives_each_image_its_report_or_error(png, tmp_path):
    """``fidelity.audit_images``: one result per path in order, an unreadable one its error;
    a measured one the report ``audit_image`` gives it alone, and no verdict."""
    import fidelity

    path, de = png
    cut = _truncated_png(tmp_path)
    results = fidelity.audit_images([path, cut], corners_of(), reference="safecolor")
    assert [r.subject for r in results] == [str(path), str(cut)]
    assert results[0].report is not None and results[0].error is None
    assert results[0].report.mean_delta_e == pytest.approx(de, abs=0.02)
    assert results[0].report.verdict is None and results[0].exit_code == 0
    alone = fidelity.audit_image(path, corners_of(), reference="safecolor")
    assert results[0].report.mean_delta_e == alone.mean_delta_e
    assert results[1].report is None and results[1].error.startswith(f"{cut}: ")
    assert results[1].exit_code == 2


def test_the_overview_gives_each_prediction_with_its_interval(png):
    """The overview table's ΔE and ΔmAP columns carry each subject's standard uncertainty:
    the numbers of its report."""
    import fidelity
    from fidelity.report.document import Table
    from fidelity.report.gate import audit_overview_document

    path, _ = png
    (case,) = fidelity.audit_images([path], corners_of(), reference="safecolor")
    r = case.report
    assert r is not None and r.uncertainty is not None and r.interval is not None
    (tab,) = [b for s in audit_overview_document([case], [None]).sections for b in s.blocks
              if isinstance(b, Table)]
    row = dict(zip(tab.header, tab.rows[0], strict=True))
    assert row["mean ΔE00 ± u (k=1)"] == f"{r.mean_delta_e:.3f} ± {r.uncertainty.combined:.3f}"
    assert row["predicted ΔmAP ± u (k=1), points"] == \
        f"{r.prediction.dmap_points:.2f} ± {r.interval.standard_uncertainty:.2f}"


def test_a_folder_of_frames_stands_for_its_images_in_natural_order(png, tmp_path):
    """``gate FOLDER`` and ``audit FOLDER``: each image file directly in it, frame_2 before
    frame_10; other files, hidden files and sub-folders left out; a folder without images is
    one error line."""
    import shutil

    path, de = png
    frames = tmp_path / "frames"
    frames.mkdir()
    for name in ("frame_10.png", "frame_2.PNG", ".frame_1.png"):
        shutil.copy(path, frames / name)
    (frames / "notes.txt").write_text("not an image")
    (frames / "sub.png").mkdir()
    r = run("gate", frames, "--corners", corners_of(), "--max-delta-e", f"{de + 1:.3f}",
            "--junit", tmp_path / "j.xml")
    assert r.exit_code == 0, r.output
    cases = ET.parse(tmp_path / "j.xml").getroot().findall("testsuite/testcase")
    assert [c.get("name").split(":")[0] for c in cases] == [
        f"colour fidelity of {frames / n}" for n in ("frame_2.PNG", "frame_10.png")]
    out = tmp_path / "out"
    r = run("audit", frames, "--corners", corners_of(), "--json", out)
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["frame_10.png.json", "frame_2.PNG.json"]
    empty = tmp_path / "empty"
    empty.mkdir()
    for command in ("gate", "audit"):
        r = run(command, empty, "--max-delta-e", "3") if command == "gate" else \
            run(command, empty)
        assert r.exit_code == 2
        assert one_error_line(r).startswith(f"fidelity: error: {empty}: a folder with no image")


def test_a_folder_that_cannot_be_listed_is_one_error_line(tmp_path, monkeypatch):
    frames = tmp_path / "frames"
    frames.mkdir()

    def refuse(self):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "iterdir", refuse)
    r = run("gate", frames, "--max-delta-e", "3")
    assert r.exit_code == 2
    assert one_error_line(r) == (f"fidelity: error: {frames}: cannot list the folder "
                                 "(Permission denied)")


@pytest.fixture(scope="module")
def degraded_charts(tmp_path_factory):
    """The calibration chart sharp, blurred by sigma 1.5 px and noisy at sigma 0.06 (8-bit
    PNGs): the issue's two examples that passed a 2-point gate on colour alone."""
    from fidelity.chart.image import write_png
    from fidelity.coco.degradations import Degradation
    from fidelity.coco.tables.degradation import calibration_chart

    folder = tmp_path_factory.mktemp("degraded")
    img, _ = calibration_chart()
    out = {}
    for name, fn in (("sharp", None), ("blur", Degradation("gaussian-blur", 1.5)),
                     ("noise", Degradation("gaussian-noise", 0.06))):
        out[name] = folder / f"{name}.png"
        write_png(out[name], (img if fn is None else fn(img)) / 255.0, 8)
    return out


def test_blur_and_noise_fail_a_loss_gate_and_name_the_property(degraded_charts, tmp_path):
    sharp = run("gate", degraded_charts["sharp"], "--max-dmap", "2")
    assert sharp.exit_code == 0, sharp.output
    for name, prop in (("blur", "sharpness"), ("noise", "noise")):
        report = tmp_path / f"{name}.json"
        r = run("gate", degraded_charts[name], "--max-dmap", "2", "--json", report)
        assert r.exit_code == 1, r.output
        assert f"{prop} dominates" in r.output
        doc = json.loads(report.read_text())
        j = doc["properties"]
        assert j["combined"]["dominant"] == prop and doc["verdict"]["value"] > 2
        parts = j["combined"]["parts"]
        interaction = math.sqrt(max(parts.get("sharpness", 0), 0) * max(parts.get("noise", 0), 0))
        assert j["combined"]["interaction"] == pytest.approx(interaction)
        rule = sum(parts.values()) + interaction
        assert doc["verdict"]["value"] == pytest.approx(rule + j["combined"]["margin"])
        assert 0 < j["combined"]["margin"] < 0.01 * rule + 0.01
        assert parts["colour"] == pytest.approx(doc["prediction"]["dmap_points"], abs=1e-9)


def test_a_delta_e_gate_also_fails_a_blurred_chart(degraded_charts):
    r = run("gate", degraded_charts["blur"], "--max-delta-e", "3")
    assert r.exit_code == 1, r.output
    assert "but sharpness: MTF50" in r.output.splitlines()[-1]
    assert run("gate", degraded_charts["sharp"], "--max-delta-e", "3").exit_code == 0


def test_predict_mtf50_and_snr(tmp_path):
    out = tmp_path / "p.json"
    r = run("predict", "--mtf50", "0.1", "--snr", "5", "--delta-e", "1", "--json", out)
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    total = doc["colour"]["loss"] + doc["sharpness"]["loss"] + doc["noise"]["loss"]
    total += math.sqrt(doc["sharpness"]["loss"] * doc["noise"]["loss"])  # their interaction
    # and the validated margin: (L + c) exp(q) - c
    margin = json.loads((resource_dir("data") / "property-margin.json").read_text())
    q, c = margin["columns"]["dmap_points"]["q"], margin["offset"]
    assert doc["combined"]["loss"] == pytest.approx((total + c) * math.exp(q) - c)
    assert doc["combined"]["margin"] == pytest.approx((total + c) * math.expm1(q))
    assert run("predict", "--mtf50", "1.0").exit_code == 0  # sharper than the chart: 0
    for bad in (["--snr", "-1"], ["--mtf50", "nan"]):
        r = run("predict", *bad)
        assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
