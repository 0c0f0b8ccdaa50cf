"""Prediction tables: the published-bounds default against the paper's statements, interpolation,
out-of-range answers, the registry, and the transform parameters at a ΔE."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from fidelity.core.errors import FidelityError, InputFileError, UnknownNameError
from fidelity.core.resources import shared_dir
from fidelity.prediction import colour as pc
from fidelity.prediction import interpolate as ip
from fidelity.prediction import table as pr
from fidelity.prediction import tablefile as tf

#: The published-bounds table, named explicitly (the statements below are the paper's).
SC = "safecolor-2025"


def test_default_table_is_the_measured_sweep_covering_its_plan():
    """The default is the project's measured table, complete: every model at every sweep ΔE."""
    from fidelity.coco.sweep import SWEEP_TARGETS

    table = tf.load_prediction_table()
    assert tf.DEFAULT_TABLE == "coco1000-measured" == table.name and table.kind == "measured"
    prov = table.provenance
    assert prov["omitted_partial_points"] == []
    models = prov["models"]
    assert set(models) == {"yolox_nano", "yolo11n-int8dyn", "yolov8n-int8dyn", "yolov10n-int8dyn"}
    for info in models.values():
        assert len(info["sha256"]) == 64 and info["images"] >= 100 and info["conventions"]
    assert prov["images"] and prov["versions"]["onnxruntime"]
    for curve in table.curves:  # the aggregate and every model: ΔE 0 ... 24, nothing missing
        assert list(curve.delta_e) == [float(t) for t in SWEEP_TARGETS], curve.model
        assert not np.isnan(curve.values["dmap_points"]).any(), curve.model
    # the published bounds stay available by name
    assert tf.load_prediction_table("safecolor-2025").kind == "published-bounds"


@pytest.mark.parametrize("delta_e,column,bound", [
    (3.0, "dmap_points", 1.0),          # ΔE ≤ 3 keeps ΔmAP below 1 %
    (6.0, "dmap_points", 3.0),          # ΔE ≤ 6: every model keeps ΔmAP < 3 %
    (12.0, "dmap_points", 10.0),        # ΔE ≤ 12 keeps it below 10 %
    (3.0, "dmap_relative", 1.0),
    (3.0, "dap_person_points", 1.0),    # person: ΔAP below 1 % needs ΔE ≤ 3
    (1.0, "dap_bicycle_points", 1.0),   # bicycle: ΔAP below 1 % needs ΔE ≤ 1
    (11.0, "dap_bicycle_points", 11.0),  # ΔE 11 for ΔAP below 11 %
    (24.0, "dmap_relative", 100.0),     # at ΔE 24 mAP drops to 0
])
def test_published_statements(delta_e, column, bound):
    p = pr.predict(delta_e, table=SC, transforms=False)
    assert p.columns[column].value == pytest.approx(bound)
    # and everywhere below the statement's ΔE the prediction stays within the bound
    for de in np.linspace(0, delta_e, 13):
        assert pr.predict(de, table=SC, transforms=False).columns[column].value <= bound + 1e-12


def test_bicycle_one_delta_e_per_point_between_1_and_11():
    for de in (1.0, 2.5, 4.0, 7.5, 11.0):
        assert pr.predict(de, table=SC, transforms=False).dap_bicycle_points == pytest.approx(de)


def test_every_point_cites_a_statement_of_the_paper():
    shared = shared_dir()
    if shared is None or not (shared / "reference" / "safecolor.md").is_file():
        pytest.skip("../shared/reference/safecolor.md not available")
    text = (shared / "reference" / "safecolor.md").read_text(encoding="utf-8")
    norm = " ".join(text.split())
    table = tf.load_prediction_table("safecolor-2025")
    for curve in table.curves:
        for src in curve.sources:
            quotes = re.findall(r"'([^']+)'", src)
            assert quotes, f"point without a quoted statement: {src}"
            for q in quotes:
                for piece in q.replace("[ΔmAP] ", "").split(" ... "):
                    assert " ".join(piece.split()) in norm, piece


def test_predictions_are_monotone_and_conservative_beyond_range():
    grid = np.linspace(0, 40, 401)
    for col in tf.COLUMNS:
        v = ip.predict_curve(grid, col, table=SC)
        assert np.all(np.diff(v) >= -1e-12), col
    far = pr.predict(30.0, table=SC, transforms=False)
    assert far.out_of_range
    assert far.columns["dmap_points"].status == "above-range"
    assert far.dmap_points == 100.0 and far.dmap_relative == 100.0
    assert {c.status for c in far.columns.values()} == {ip.ColumnStatus.ABOVE_RANGE}
    assert far.columns["dmap_points"].delta_e_range == (0.0, 24.0)


@pytest.mark.parametrize("name", tf.available_tables())
def test_every_shipped_table_predicts_monotone_losses(name):
    grid = np.linspace(0, 40, 161)
    for col in tf.COLUMNS:
        v = ip.predict_curve(grid, col, table=name)
        assert np.all(np.isfinite(v)) and np.all(np.diff(v) >= -1e-12), (name, col)


def test_points_vs_relative_with_a_baseline():
    p = pr.predict(6.0, table=SC, baseline_map=37.5, transforms=False)
    assert p.dmap_points == pytest.approx(3.0)
    # the paper's "3 %" read as points is 3/37.5 = 8 % of the baseline: the larger bound wins
    assert p.dmap_relative == pytest.approx(100 * 3.0 / 37.5)
    assert p.columns["dmap_relative"].raised_from == pytest.approx(3.0)  # the table's value
    plain = pr.predict(6.0, table=SC, transforms=False)
    assert plain.dmap_relative == pytest.approx(3.0)
    assert plain.upper_bound and plain.kind is tf.TableKind.PUBLISHED_BOUNDS
    assert plain.columns["dmap_relative"].raised_from is None and plain.baseline_map is None
    assert plain.dmap_points_se is None and plain.dmap_points_interval is None
    with pytest.raises(FidelityError, match="baseline mAP"):
        pr.predict(6.0, table=SC, baseline_map=0.0)


def _measured_table() -> dict:
    def pts(values):
        return [{"delta_e": de, "dmap_points": v, "dmap_relative": 2 * v, "dap_person_points": v,
                 "dap_bicycle_points": None, "worst_transform": "contrast-inc", "source": "test"}
                for de, v in values]

    return {
        "name": "measured-test", "title": "t", "kind": "measured", "provenance": {},
        "units": {}, "curves": [
            {"size": "n", "model": "a", "points": pts([(1, 0.2), (3, 0.5), (6, 0.4), (12, 4.0)])},
            {"size": "n", "model": "b", "points": pts([(1, 0.1), (3, 0.9), (6, 1.5), (12, 3.0)])},
            {"size": "x", "model": "c", "baseline_map": 0.42, "points": pts([(2, 0.05), (12, 1.0)])},
        ],
    }


def test_measured_table_reports_the_sampling_error_of_its_points():
    doc = _measured_table()
    plain = pr.predict(3.0, size="n", table=tf.parse_prediction_table(doc), transforms=False)
    assert plain.kind is tf.TableKind.MEASURED and not plain.upper_bound
    assert plain.dmap_points_se is None  # no SEs in the file: none reported
    for curve, ses in zip(doc["curves"][:2], ([0.1, 0.3, 0.2, 0.5], [0.15, 0.25, 0.4, 0.6]),
                          strict=True):
        for point, se in zip(curve["points"], ses, strict=True):
            point["dmap_points_se"] = se
    table = tf.parse_prediction_table(doc)
    # model b answers (worst) at ΔE 3 exactly: its point's SE
    at3 = pr.predict(3.0, size="n", table=table, transforms=False)
    assert at3.dmap_points_se == ip.SamplingError(0.25, 0.25)
    assert at3.dmap_points_interval == pytest.approx((0.9 - 0.25, 0.9 + 0.25))
    # between ΔE 3 and 6: the SEs of model b's two bracketing points
    at4 = pr.predict(4.0, size="n", table=table, transforms=False)
    assert at4.dmap_points_se == ip.SamplingError(0.25, 0.40)
    lo, hi = at4.dmap_points_interval
    assert hi - lo == pytest.approx(0.8) and (lo + hi) / 2 == pytest.approx(at4.dmap_points)
    # the JSON form carries them, and reads them back
    back = pr.Prediction.from_json(json.loads(json.dumps(at4.to_json())))
    assert back.dmap_points_se == at4.dmap_points_se
    assert back.dmap_points_interval == pytest.approx(at4.dmap_points_interval)


def test_measured_table_worst_model_pchip_running_max():
    table = tf.parse_prediction_table(_measured_table())
    assert table.interpolation == "pchip"
    p = pr.predict(3.0, size="n", table=table, transforms=False)
    assert p.dmap_points == pytest.approx(0.9)  # worst of the two n models
    # model a dips at ΔE 6 (0.4 < 0.5): its running maximum keeps it at 0.5; model b's 1.5 wins
    assert pr.predict(6.0, size="n", table=table, transforms=False).dmap_points == pytest.approx(1.5)
    v = ip.predict_curve(np.linspace(1, 12, 111), size="n", table=table)
    assert np.all(np.diff(v) >= -1e-12)
    # PCHIP passes through the points and stays inside each interval's values
    assert pr.predict(12.0, size="n", table=table, transforms=False).dmap_points == pytest.approx(4.0)
    mid = pr.predict(9.0, size="n", table=table, method="pchip", transforms=False).dmap_points
    assert 1.5 <= mid <= 4.0
    # linear and step for comparison (closed forms)
    assert pr.predict(9.0, size="x", table=table, method="linear", transforms=False).dmap_points == pytest.approx(0.05 + 0.95 * 0.7)
    assert pr.predict(9.0, size="x", table=table, method="step", transforms=False).dmap_points == pytest.approx(1.0)


def test_a_sizes_aggregate_curve_answers_before_its_per_model_curves():
    # A table with an aggregate curve for size n (worst over its measured models, ΔE 0..12)
    # and a per-model curve still being measured (ΔE 0..1). The aggregate answers for size n:
    # at ΔE 4.5 the linear chord (3, 0.9)-(6, 1.5) gives 1.2, not the total-loss ceiling that
    # the narrow curve alone would answer beyond ΔE 1.
    doc = _measured_table()
    doc["interpolation"] = "linear"
    worst = {"size": "n", "model": None, "points": [
        {"delta_e": de, "dmap_points": v, "dmap_relative": None, "dap_person_points": None,
         "dap_bicycle_points": None, "worst_transform": None, "source": "test"}
        for de, v in [(0, 0.0), (3, 0.9), (6, 1.5), (12, 4.0)]]}
    narrow = {"size": "n", "model": "d", "baseline_map": 0.4, "points": [
        {"delta_e": de, "dmap_points": v, "dmap_relative": None, "dap_person_points": None,
         "dap_bicycle_points": None, "worst_transform": None, "source": "test"}
        for de, v in [(0, 0.0), (1, 0.3)]]}
    doc["curves"] = [*doc["curves"], worst, narrow]
    table = tf.parse_prediction_table(doc)
    p = pr.predict(4.5, size="n", table=table, transforms=False)
    assert p.columns["dmap_points"].status == "interpolated"
    assert p.dmap_points == pytest.approx(1.2)


def test_total_loss_beyond_the_range_is_the_baseline_in_points():
    """Above the last ΔE every points column is the baseline itself (losing everything loses
    the baseline), for an aggregate curve the largest of its models' baselines."""
    def pts(values):
        return [{"delta_e": de, "dmap_points": v, "dmap_relative": 100 * v / 40,
                 "dap_person_points": v, "dap_bicycle_points": v, "worst_transform": None,
                 "source": "test"} for de, v in values]

    doc = {"name": "t", "kind": "measured", "interpolation": "linear", "curves": [
        {"size": "n", "model": None, "points": pts([(0, 0.0), (12, 9.0)])},
        {"size": "n", "model": "a", "baseline_map": 0.30, "baseline_ap": {"person": 0.5},
         "points": pts([(0, 0.0), (12, 9.0)])},
        {"size": "n", "model": "b", "baseline_map": 0.38, "baseline_ap": {"person": 0.45,
                                                                          "bicycle": None},
         "points": pts([(0, 0.0), (12, 8.0)])}]}
    table = tf.parse_prediction_table(doc)
    far = pr.predict(20.0, size="n", table=table, transforms=False)
    assert far.dmap_points == pytest.approx(38.0)  # largest baseline mAP of the size's models
    assert far.dap_person_points == pytest.approx(50.0)  # largest person baseline AP
    assert far.dap_bicycle_points == 100.0  # no bicycle baseline known: 100 points
    assert far.dmap_relative == 100.0
    assert {c.delta_e_range for c in far.columns.values()} == {(0.0, 12.0)}
    assert {c.status for c in far.columns.values()} == {ip.ColumnStatus.ABOVE_RANGE}
    # the caller's detector baseline bounds an aggregate curve's mAP loss
    assert pr.predict(20.0, size="n", table=table, transforms=False,
                      baseline_map=25.0).dmap_points == pytest.approx(25.0)
    assert ip.predict_curve([20.0], "dap_person_points", size="n", table=table)[0] == 50.0
    with pytest.raises(InputFileError, match=r"curves\[0\]\.baseline_ap: expected an object"):
        tf.parse_prediction_table({**doc, "curves": [{**doc["curves"][1], "baseline_ap": [1]}]})


def test_measured_table_ranges_and_sizes():
    table = tf.parse_prediction_table(_measured_table())
    below = pr.predict(1.0, size="x", table=table, transforms=False)
    assert below.columns["dmap_points"].status == "below-range"
    assert below.dmap_points == pytest.approx(0.05)  # the first point: loss grows with ΔE
    assert below.dap_bicycle_points is None
    assert below.columns["dap_bicycle_points"].status == "no-data"
    beyond = pr.predict(20.0, size="x", table=table, transforms=False)
    # beyond the range: total loss, i.e. the model's whole baseline (0.42 as a fraction = 42 points)
    assert beyond.dmap_points == pytest.approx(42.0) and beyond.dmap_relative == 100.0
    assert beyond.columns["dmap_points"].status == "above-range"
    m = pr.predict(5.0, size="m", table=table, transforms=False)
    assert m.size_used == ",".join(table.sizes()) and "m" not in table.sizes()
    assert m.size == "m"
    with pytest.raises(UnknownNameError, match="detector size"):
        pr.predict(5.0, size="xl", table=table)


def test_registry_picks_up_files(tmp_path, monkeypatch):
    shutil.copy(tf.prediction_dir() / "safecolor-2025.json", tmp_path)
    (tmp_path / "measured-test.json").write_text(json.dumps(_measured_table()))
    monkeypatch.setattr(tf, "prediction_dir", lambda: tmp_path)
    assert tf.available_tables() == ["measured-test", "safecolor-2025"]
    table = tf.load_prediction_table("measured-test")
    assert table.kind == "measured"
    # read once a process while the file is unchanged, and again when it changes
    assert tf.load_prediction_table(tmp_path / "measured-test.json") is table
    changed = _measured_table()
    changed["title"] = "changed on disk"
    (tmp_path / "measured-test.json").write_text(json.dumps(changed, indent=1))
    assert tf.load_prediction_table("measured-test").title == "changed on disk"
    assert pr.predict(3.0, size="n", table="measured-test", transforms=False).dmap_points == pytest.approx(0.9)
    with pytest.raises(UnknownNameError, match=r"^nope: unknown prediction table; known: measured-test, safecolor-2025$"):
        tf.load_prediction_table("nope")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(InputFileError, match="broken.json"):
        tf.load_prediction_table("broken")
    bad = _measured_table()
    bad["kind"] = "guess"
    with pytest.raises(InputFileError, match="kind"):
        tf.parse_prediction_table(bad)


def test_transform_parameters_match_the_published_calibration():
    # safecolor.md: contrast-dec at ΔE 1 = 0.9535; gamma-inc at 12 = 1.5509; hue at 3 = 5.3371;
    # pull_mean at 6 = 0.7263 (4 decimals)
    for de, name, want in [(1, "contrast-dec", 0.9535), (12, "gamma-inc", 1.5509),
                           (3, "hue", 5.3371), (6, "pull_mean", 0.7263)]:
        rows = {r.transform: r for r in pc.transform_parameters(de)}
        assert rows[name].param == pytest.approx(want, abs=2e-3)
        assert rows[name].method == "calibrated"


def test_transform_parameters_between_targets_reach_that_delta_e():
    from fidelity.colour.charts import load_chart
    from fidelity.measure.colour import chart_delta_e
    from fidelity.prediction.transforms import apply_transform

    chart = load_chart("safecolor")
    rows = pc.transform_parameters(2.5)
    assert len(rows) == 10
    for r in rows:
        assert r.reachable and r.method == "solved" and r.param is not None
        assert r.bracket is not None
        lo, hi = sorted(q for _, q in r.bracket)
        assert lo <= r.param <= hi
        assert chart_delta_e(apply_transform(chart.srgb, r.transform, r.param), chart.lab) == pytest.approx(2.5, rel=3e-3)
    interp = {r.transform: r for r in pc.transform_parameters(2.5, solve=False)}
    assert interp["hue"].method == "interpolated"
    assert all(not r.reachable for r in pc.transform_parameters(0.1))
    far = {r.transform: r for r in pc.transform_parameters(30.0)}
    assert far["contrast-dec"].param is None and not far["contrast-dec"].reachable
    # the reach of the transform is only in the method's words (TransformParameter has no field)
    assert "at most" in str(far["contrast-dec"].method)


def test_prediction_dict_keys():
    d = pr.predict(4.0, table=SC).to_json()
    for key in ("dmap_points", "dmap_relative", "dap_person_points", "dap_bicycle_points",
                "table", "transforms"):
        assert key in d
    assert d["table"]["name"] == "safecolor-2025" and "provenance" in d["table"]
    json.dumps(d, allow_nan=False)


def _one_curve(points, interpolation="linear"):
    return tf.parse_prediction_table({
        "name": "limit-test", "kind": "measured", "interpolation": interpolation, "curves": [
            {"size": "n", "model": "m", "points": [
                {"delta_e": de, "dmap_points": v, "dmap_relative": 10 * v,
                 "dap_person_points": v, "dap_bicycle_points": None, "worst_transform": None,
                 "source": "test"} for de, v in points]}]})


def test_delta_e_limit_inverts_the_prediction_closed_form():
    table = _one_curve([(0, 0.0), (6, 3.0), (12, 9.0)])
    # chords: 0.5 points per ΔE to 6, then 1 per ΔE: 1 point at ΔE 2, 6 points at ΔE 9
    assert pr.delta_e_limit(1.0, table=table).delta_e == pytest.approx(2.0, abs=1e-5)
    lim = pr.delta_e_limit(6.0, table=table)
    assert lim.status == "inside" and lim.delta_e == pytest.approx(9.0, abs=1e-5)
    assert lim.loss_at_limit == pytest.approx(6.0, abs=1e-5)
    assert pr.delta_e_limit(30.0, "dmap_relative", table=table).delta_e == pytest.approx(6.0, abs=1e-5)
    # a dip is lifted to the running maximum: the loss stays at 1 from ΔE 3 to 6
    dip = _one_curve([(0, 0.0), (3, 1.0), (6, 0.5), (9, 2.0)])
    assert pr.delta_e_limit(1.0, table=dip).delta_e == pytest.approx(6.0, abs=1e-5)
    whole = pr.delta_e_limit(9.0, table=table)
    assert whole.status == "whole-range" and whole.delta_e == 12.0
    assert pr.delta_e_limit(1.0, "dap_bicycle_points", table=_measured_table_bicycle()).status == "none"
    with pytest.raises(FidelityError, match="no dap_bicycle_points data"):
        pr.delta_e_limit(1.0, "dap_bicycle_points", table=table)
    with pytest.raises(FidelityError, match="must be a finite number >= 0"):
        pr.delta_e_limit(-1.0, table=table)


def _measured_table_bicycle():
    """A curve whose first point (ΔE 1) already loses 2 points in every column."""
    doc = {"name": "b", "kind": "measured", "interpolation": "linear", "curves": [
        {"size": "n", "model": "m", "points": [
            {"delta_e": de, "dmap_points": v, "dmap_relative": v, "dap_person_points": v,
             "dap_bicycle_points": v, "worst_transform": None, "source": "t"}
            for de, v in [(1, 2.0), (6, 3.0)]]}]}
    return tf.parse_prediction_table(doc)


@pytest.mark.parametrize("name", tf.available_tables())
@pytest.mark.parametrize("column", ["dmap_points", "dmap_relative", "dap_person_points"])
def test_delta_e_limit_agrees_with_a_root_finder_on_shipped_tables(name, column):
    """Second method: scipy's brentq on predict_curve - budget, where the loss crosses it."""
    from scipy.optimize import brentq

    for budget in (1.0, 3.0, 10.0):
        lim = pr.delta_e_limit(budget, column, table=name)
        if lim.status != "inside":
            continue
        def g(x: float, budget: float = budget) -> float:
            return ip.predict_curve([x], column, table=name)[0] - budget

        root = brentq(g, lim.delta_e_range[0], lim.delta_e_range[1], xtol=1e-9)
        # the crossing is unique unless the curve is flat at the budget (then brentq may land
        # anywhere on the flat part, never beyond the limit)
        assert root <= lim.delta_e + 1e-5
        assert g(lim.delta_e) <= 1e-9 and g(lim.delta_e + 1e-4) > 0


def test_predict_command_gives_the_delta_e_limit(tmp_path):
    from click.testing import CliRunner

    from fidelity.cli import main

    r = CliRunner().invoke(main, ["predict", "--max-dmap", "1", "--table", "safecolor-2025",
                                  "--json", str(tmp_path / "l.json")])
    assert r.exit_code == 0, r.output
    # the paper's table: ΔE 3 -> 1, so the limit is ΔE 3 exactly
    doc = json.loads((tmp_path / "l.json").read_text())
    assert doc["delta_e"] == pytest.approx(3.0)
    assert (doc["max_loss"], doc["column"], doc["table"], doc["size_used"]) == (
        1.0, "dmap_points", "safecolor-2025", "any")
    assert doc["status"] == "inside" and doc["loss_at_limit"] == pytest.approx(1.0)
    assert doc["delta_e_range"] == [0.0, 24.0]
    # the threshold to gate on: the limit rounded down, 3.00
    assert pr.limit_rounded_down(doc["delta_e"]) == 3.0
    r = CliRunner().invoke(main, ["predict", "--max-dmap", "1", "--delta-e", "2"])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("fidelity: error: ")
    assert "--delta-e" in lines[0] and "--max-dmap" in lines[0]


def test_delta_e_limit_rounds_down_for_printing():
    """A printed limit must be safe to gate on: never rounded up past the exact limit."""
    from fidelity.prediction.table import DeltaELimit

    def lim(de: float | None) -> DeltaELimit:
        return DeltaELimit(1.0, "dmap_points", de, "inside", 1.0, "t", "n", (0.0, 24.0))

    assert lim(3.6561).rounded_down() == 3.65  # round() would print 3.66, beyond the limit
    assert lim(2.9999995).rounded_down() == 3.00  # the bisection's last 1e-6 below 3 does not count
    assert lim(2.998).rounded_down() == 2.99
    assert lim(0.0).rounded_down() == 0.0
    assert lim(6.4399).rounded_down(1) == 6.4
    assert lim(None).rounded_down() is None


def test_predict_command_states_the_uncertainty_of_its_answer(tmp_path):
    """``predict --delta-e`` prints ΔmAP ± u (k=1): the table's sampling error at that ΔE (the
    larger SE of the two points around it) combined with ``--delta-e-uncertainty`` through the
    table's slope, here a closed form on a linear two-model table; its JSON carries the
    interval and the validity domain. A ceiling beyond the table's range carries no SE; bad
    uncertainties are one error line."""
    from click.testing import CliRunner

    from fidelity.cli import main

    doc = _measured_table() | {"interpolation": "linear"}
    for curve, ses in zip(doc["curves"][:2], ([0.1, 0.3, 0.2, 0.5], [0.15, 0.25, 0.4, 0.6]),
                          strict=True):
        for point, se in zip(curve["points"], ses, strict=True):
            point["dmap_points_se"] = se
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["predict", "--delta-e", "4", "--size", "n", "--table",
                                  str(path), "--delta-e-uncertainty", "0.5", "--json", str(out)])
    assert r.exit_code == 0, r.output
    # model b answers at ΔE 4: 0.9 + (1.5 - 0.9) / 3 = 1.1, slope 0.2 per ΔE on [3, 6];
    # SE max(0.25, 0.40); u = sqrt(0.40^2 + (0.2 x 0.5)^2)
    u = (0.40 ** 2 + (0.2 * 0.5) ** 2) ** 0.5
    assert f"ΔmAP: 1.10 ± {u:.2f} (k=1) percentage points" in r.output
    got = json.loads(out.read_text())
    iv = got["prediction_interval"]
    assert iv["value"] == pytest.approx(1.1) and iv["table_se"] == pytest.approx(0.40)
    assert iv["slope"] == pytest.approx(0.2) and iv["delta_e_uncertainty"] == 0.5
    assert iv["standard_uncertainty"] == pytest.approx(u)
    assert got["validity"]["inside"] is True
    assert [c["name"] for c in got["validity"]["checks"]] == [
        "table ΔE range", "detector size", "table kind", "detector preprocessing"]
    # an exact ΔE: the table's sampling error alone
    r = CliRunner().invoke(main, ["predict", "--delta-e", "4", "--size", "n", "--table",
                                  str(path)])
    assert "ΔmAP: 1.10 ± 0.40 (k=1) percentage points" in r.output, r.output
    # beyond the range the answer is the total loss, a bound by construction: no ± and no SE
    r = CliRunner().invoke(main, ["predict", "--delta-e", "40", "--json", str(out)])
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.output.splitlines() if "ΔmAP:" in ln)
    assert "±" not in line
    got = json.loads(out.read_text())
    assert got["dmap_points_se"] is None and got["prediction_interval"] is None
    assert got["validity"]["checks"][0]["inside"] is False
    for bad in ("nan", "-0.1", "inf"):
        r = CliRunner().invoke(main, ["predict", "--delta-e", "4",
                                      "--delta-e-uncertainty", bad])
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.exit_code == 2 and len(lines) == 1, r.output
        assert lines[0].startswith("fidelity: error: --delta-e-uncertainty "), lines
    r = CliRunner().invoke(main, ["predict", "--max-dmap", "1", "--delta-e-uncertainty", "0.2"])
    assert r.exit_code == 2 and "--delta-e-uncertainty goes with --delta-e" in r.stderr
