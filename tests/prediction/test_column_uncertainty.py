"""Every printed loss has its own ± u (issue 58): the shipped measured table states each
column's standard error (points, relative, person, bicycle), traced to the sweep's cells; the
prediction interval of a column uses that column's SE; the guarded decision uses it, so a
column whose SE swamps its value is undecided where the classic points' SE would have passed
it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.coco.tables.build import Tables
from fidelity.coco.tables.prediction import prediction_table
from fidelity.prediction.interval import prediction_interval
from fidelity.prediction.table import predict

REPO = Path(__file__).resolve().parents[2]
TABLES = REPO / "reports" / "coco" / "tables.json"
SHIPPED = REPO / "fidelity" / "data" / "prediction" / "coco1000-measured.json"
#: A camera of the validation suite without noise (the colour column alone decides).
CAMERA = REPO / "cameras" / "nikon5100-cheung-d65.toml"
CLASS_COLUMNS = ("dap_person_points", "dap_bicycle_points")


def _cells():
    return json.loads(TABLES.read_text(encoding="utf-8"))["tables"]["cells"]


def test_shipped_table_is_the_reports_tables_with_every_columns_se():
    """The shipped table is what the code makes of ``reports/coco/tables.json``, and it
    carries a standard error beside every loss column of every measured point."""
    tables = Tables.from_json(json.loads(TABLES.read_text(encoding="utf-8"))["tables"])
    shipped = json.loads(SHIPPED.read_text(encoding="utf-8"))
    assert prediction_table(tables) == shipped
    for curve in shipped["curves"]:
        for point in curve["points"][1:]:  # the ΔE 0 baseline has no SE
            for col in ("dmap_points", "dmap_relative", *CLASS_COLUMNS):
                assert point[f"{col}_se"] is not None and point[f"{col}_se"] >= 0, (
                    curve["model"], point["delta_e"], col)


@pytest.mark.parametrize("column", CLASS_COLUMNS)
def test_a_class_columns_se_is_that_of_the_cell_its_worst_case_took(column):
    """Read from the sweep's cells directly: per model and ΔE, the class column's value is
    its largest ΔAP over the transforms done, and its SE that cell's; the size-class curve
    takes the model with the largest value, and that model's SE."""
    cells = _cells()
    shipped = json.loads(SHIPPED.read_text(encoding="utf-8"))
    per_model = {}
    for curve in shipped["curves"]:
        if curve["model"] is None:
            continue
        model = curve["model"]
        for point in curve["points"][1:]:
            done = [c for c in cells[model] if c["status"] == "done"
                    and c["delta_e"] == point["delta_e"] and c[column] is not None]
            worst = max(done, key=lambda c: c[column])
            assert point[column] == pytest.approx(worst[column], abs=1e-4)
            assert point[f"{column}_se"] == pytest.approx(worst[f"{column}_se"], abs=1e-4)
            per_model[(model, point["delta_e"])] = (point[column], point[f"{column}_se"])
    size = next(c for c in shipped["curves"] if c["model"] is None)
    for point in size["points"][1:]:
        mine = [v for (m, de), v in per_model.items() if de == point["delta_e"]
                and m in point["source"]]
        value, se = max(mine)
        assert point[column] == pytest.approx(value, abs=1e-4)
        assert point[f"{column}_se"] == pytest.approx(se, abs=1e-4)


@pytest.mark.parametrize("column", ["dmap_relative", *CLASS_COLUMNS])
def test_a_columns_interval_uses_its_own_se_around_the_delta_e(column):
    """At ΔE 1.5 the column's table SE is the larger of its SEs at ΔE 1 and 2 of the size
    class curve (read from the file), not the points column's."""
    shipped = json.loads(SHIPPED.read_text(encoding="utf-8"))
    size = next(c for c in shipped["curves"] if c["model"] is None)
    at = {p["delta_e"]: p for p in size["points"]}
    interval = prediction_interval(predict(1.5), 0.0, column)
    assert interval is not None
    assert interval.table_se == pytest.approx(max(at[1.0][f"{column}_se"],
                                                  at[2.0][f"{column}_se"]))
    points = prediction_interval(predict(1.5), 0.0, "dmap_points")
    assert points is not None and points.table_se != interval.table_se


def _verdict(tmp_path, *args):
    out = tmp_path / "r.json"
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", str(CAMERA),
                                  "--decision", "guarded", "--json", str(out), "--html",
                                  str(tmp_path / "r.html"),
                                  *args])
    return r, json.loads(out.read_text(encoding="utf-8"))


@pytest.mark.parametrize(("args", "column"), [
    (("--max-dmap", "1.3", "--unit", "relative"), "dmap_relative"),
    (("--class", "bicycle", "--max-dmap", "1"), "dap_bicycle_points"),
])
def test_the_guarded_decision_uses_the_columns_own_u(tmp_path, args, column):
    """Issue 58's cases: the relative and the bicycle columns passed with U = 0.05 and 0.06
    (the ΔE's uncertainty alone); with their own SE (0.69 % of baseline, 1.19 bicycle points)
    U = k u straddles the limit: undecided, exit 4."""
    r, doc = _verdict(tmp_path, *args)
    assert r.exit_code == 4, r.output
    v = doc["verdict"]
    mine = next(i for i in doc["prediction_intervals"] if i["column"] == column)
    assert v["reason"] == "undecided"
    assert mine["table_se"] == pytest.approx(doc["prediction"]["column_se"][column]["high"])
    # the colour part's u is the column's; sharpness and noise add theirs in quadrature
    assert v["standard_uncertainty"] >= mine["standard_uncertainty"] - 1e-12
    assert v["expanded_uncertainty"] == pytest.approx(2 * v["standard_uncertainty"])
    assert v["value"] + v["expanded_uncertainty"] > float(args[-1] if args[0] == "--class"
                                                          else args[1])


def test_a_swamped_column_says_so_and_a_limit_far_above_still_passes(tmp_path):
    """The bicycle column at ΔE 1 (0.86 ± 1.19): the terminal says its u reaches the value;
    at a limit above value + 2u the guarded decision passes (exit 0)."""
    r, doc = _verdict(tmp_path, "--class", "bicycle", "--max-dmap", "5")
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.output.splitlines() if "predicted ΔAP" in ln)
    bicycle = next(i for i in doc["prediction_intervals"]
                   if i["column"] == "dap_bicycle_points")
    assert f"bicycle {doc['prediction']['dap_bicycle_points']:.2f} ± " \
           f"{bicycle['standard_uncertainty']:.2f}" in line
    assert "bicycle: u >= the value" in line
    assert bicycle["standard_uncertainty"] >= bicycle["value"]
    person = next(i for i in doc["prediction_intervals"] if i["column"] == "dap_person_points")
    assert math.isclose(person["table_se"], doc["prediction"]["column_se"][
        "dap_person_points"]["high"])
