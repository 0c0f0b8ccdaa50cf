"""``fidelity calibrate`` end to end through the command line."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.colour.charts import load_chart
from fidelity.measure.colour import chart_delta_e


def test_calibrate_writes_json_and_csv(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(main, ["calibrate", "--targets", "1-3,30", "--transforms", "hue,saturation-inc",
                               "--json", str(tmp_path / "t.json"), "--csv", str(tmp_path / "t.csv")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "t.json").read_text())
    assert set(doc) == {"chart", "baseline_delta_e", "entries"}
    chart = load_chart()
    assert doc["chart"] == chart.name == "safecolor"
    # the untransformed chart's own ΔE00 (its sRGB against its Lab)
    assert doc["baseline_delta_e"] == pytest.approx(chart_delta_e(chart.srgb, chart.lab),
                                                    rel=1e-9)
    assert len(doc["entries"]) == 8
    assert [(e["transform"], e["target"]) for e in doc["entries"]] == [
        (t, float(x)) for t in ("hue", "saturation-inc") for x in (1, 2, 3, 30)]
    for e in doc["entries"]:
        if e["reachable"]:
            assert e["delta_e"] == pytest.approx(e["target"], abs=1e-6), e
    unreachable = [e for e in doc["entries"] if not e["reachable"]]
    assert [(e["transform"], e["target"], e["param"]) for e in unreachable] == [("saturation-inc", 30.0, None)]
    rows = list(csv.DictReader((tmp_path / "t.csv").open()))
    assert rows[0]["transform"] == "hue" and float(rows[2]["target"]) == 3.0


def test_calibrate_another_chart(tmp_path: Path) -> None:
    doc = load_chart().to_json()
    doc["name"] = "greys"
    doc["layout"] = {"rows": 1, "cols": 6}
    doc["patches"] = doc["patches"][18:]
    chart = tmp_path / "greys.json"
    chart.write_text(json.dumps(doc))
    res = CliRunner().invoke(main, ["calibrate", "--chart", str(chart), "--targets", "2",
                                    "--transforms", "brightness-inc", "--json", str(tmp_path / "g.json")])
    assert res.exit_code == 0, res.output
    out = json.loads((tmp_path / "g.json").read_text())
    assert out["chart"] == "greys" and out["entries"][0]["reachable"]


def test_calibrate_errors_exit_2_with_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    for args, names in [
        (["calibrate", "--chart", "nope"], ["error: nope: unknown chart"]),
        (["calibrate", "--targets", "x"], ["--targets", "'x'"]),
        (["calibrate", "--transforms", "contrast"], ["--transforms: contrast: unknown transform"]),
        (["calibrate", "--chart", str(tmp_path / "missing.json")], [str(tmp_path / "missing.json")]),
    ]:
        res = runner.invoke(main, args)
        assert res.exit_code == 2, (args, res.output)
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), res.output
        assert all(n in lines[0] for n in names), (names, lines[0])
        assert "Traceback" not in res.output
