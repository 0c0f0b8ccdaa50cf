"""The split-conformal interval study (``benchmarks/studies/interval.py``, issue 58): its
quantile against the closed form, its coverage on exchangeable data against the conformal
guarantee, and the committed report against the study run again on the committed cells."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.studies import interval as st

REPO = Path(__file__).resolve().parents[1]


def test_conformal_quantile_is_the_order_statistic():
    scores = np.arange(1.0, 20.0)  # 19 scores: rank ceil(20 * 0.95) = 19, the largest
    assert st.conformal_quantile(scores, 0.05) == 19.0
    assert st.conformal_quantile(scores, 0.10) == 18.0  # ceil(20 * 0.9) = 18
    assert st.conformal_quantile(scores[:10], 0.05) == math.inf  # ceil(11 * .95) = 11 > 10


def test_leave_one_camera_out_covers_exchangeable_cells_at_the_promised_rate():
    """On cells drawn alike (residuals N(0, 1) around a prediction), the additive bound covers
    a held-out camera's cells with probability >= 1 - alpha (split conformal), and not far
    above it (the rank is the smallest that guarantees it)."""
    rng = np.random.default_rng(58)
    covered = []
    for _ in range(200):
        n = 30
        camera = np.repeat([f"c{i}" for i in range(n)], 2)
        p = rng.uniform(0, 5, 2 * n)
        m = p + rng.normal(0, 1, 2 * n)
        cells = st.Cells(camera, np.tile(["a", "b"], n), m, np.ones(2 * n), p, p)
        o = st.leave_one_camera_out(cells, "classic", "additive", 0.10)
        covered.append(o.coverage)
    assert 0.90 <= float(np.mean(covered)) <= 0.95


def test_calibrated_slope_is_least_squares_through_the_origin():
    p = np.array([1.0, 2.0, 4.0])
    m = np.array([0.5, 1.1, 1.9])
    want = (0.5 + 2.2 + 7.6) / (1 + 4 + 16)
    assert st.slope(m, p) == pytest.approx(want, rel=1e-15)


def test_the_committed_report_is_the_study_of_the_committed_cells():
    doc = json.loads((REPO / "reports/validation/interval.json").read_text())
    cells = st.read_cells(json.loads(st.VALIDATION.read_text()))
    again = [o.to_json() for o in st.study(cells)]
    assert doc["outcomes"] == json.loads(json.dumps(again))
    assert doc["noise_floor"] == st.noise_floor(cells)
    by = {(o["prediction"], o["method"]): o for o in doc["outcomes"]}
    # the table as it is: the validation's own counts (validation.json's summary)
    summary = json.loads((REPO / "reports/validation/validation.json").read_text())["summary"]
    assert by[("classic", "table")]["cells_covered"] == summary["all"]["within"] == 56
    directional = json.loads(st.VALIDATION.read_text())["summary"]["all"]
    assert by[("directional", "table")]["cells_covered"] == directional["directional_within"]
    assert by[("classic", "table")]["median_ratio"] == pytest.approx(
        directional["classic_median_ratio"], rel=1e-12)
    text = (REPO / "reports/validation/interval.md").read_text(encoding="utf-8")
    assert text == st.markdown(st.study(cells), st.noise_floor(cells), 60,
                               st.per_detector(cells))


def test_each_detector_alone_is_its_own_cells_study():
    """The per-detector rows are the shipped method on that detector's 30 cells (one per
    camera), not the pooled constants; the committed report holds them."""
    cells = st.read_cells(json.loads(st.VALIDATION.read_text()))
    rows = st.per_detector(cells)
    assert [model for model, *_ in rows] == sorted(set(cells.model.tolist()))
    doc = json.loads((REPO / "reports/validation/interval.json").read_text())
    for (model, o, m, se), saved in zip(rows, doc["per_detector"], strict=True):
        k = cells.model == model
        assert o.cells == o.cameras == int(k.sum()) == 30
        assert m == float(np.median(cells.measured[k])) and se == float(np.median(cells.se[k]))
        assert saved == json.loads(json.dumps({"model": model, "median_measured": m,
                                               "median_se": se, **o.to_json()}))
    pooled = next(o for o in st.study(cells)
                  if (o.method, o.prediction) == ("calibrated", "classic"))
    assert {o.constants["a"] for _, o, _, _ in rows} != {pooled.constants["a"]}


def test_jackknife_plus_is_the_order_statistic_of_the_leave_one_out_bounds():
    """CV+ with one cell per fold is the jackknife+ (Barber et al. 2021): the bound of a new
    cell is the ceil((n+1)(1-alpha))-th smallest of a_-i p + (m_i - a_-i p_i), written out
    here with the leave-one-out slopes by hand."""
    p = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    m = np.array([0.3, 0.5, 1.2, 0.9, 1.6])
    new = np.array([2.5])
    alpha = 0.2  # rank ceil(6 * 0.8) = 5 of 5: the largest
    values = []
    for i in range(5):
        keep = np.arange(5) != i
        a = float(np.sum(m[keep] * p[keep]) / np.sum(p[keep] ** 2))
        values.append(a * 2.5 + (m[i] - a * p[i]))
    got, constants = st.cv_plus(m, p, new, alpha)
    assert got[0] == pytest.approx(sorted(values)[4], rel=1e-14)
    assert constants["a"] == pytest.approx(st.slope(m, p))
    # a rank beyond n: no finite bound
    assert math.isinf(st.cv_plus(m, p, new, 0.05)[0][0])
    # folds by camera: cells of one camera leave together
    groups = np.array(["x", "x", "y", "y", "z"])
    got_g, _ = st.cv_plus(m, p, new, 0.2, groups)
    a_x = st.slope(m[2:], p[2:])
    assert got_g[0] >= a_x * 2.5 + (m[0] - a_x * p[0]) - 1e-12  # the largest is >= each


def test_cv_plus_covers_exchangeable_cameras():
    """On cells drawn alike (m = 0.3 p + N(0, 1)), the CV+ bound judged leaving each camera
    out covers at least 1 - 2 alpha (its guarantee), in practice near 1 - alpha."""
    rng = np.random.default_rng(5858)
    covered = []
    for _ in range(100):
        n = 30
        camera = np.repeat([f"c{i}" for i in range(n)], 2)
        p = rng.uniform(0, 5, 2 * n)
        m = 0.3 * p + rng.normal(0, 1, 2 * n)
        cells = st.Cells(camera, np.tile(["a", "b"], n), m, np.ones(2 * n), p, p)
        covered.append(st.leave_one_camera_out(cells, "classic", "calibrated CV+", 0.10).coverage)
    assert 0.85 <= float(np.mean(covered)) <= 0.97


def test_the_property_margins_are_the_study_of_the_property_report():
    """reports/validation/properties-interval.{json,md} are the methods on the committed
    sharpness and noise validation; its ``table`` row is that report's own summary (the
    verdict's combined loss as it is), and a margin fitted leaving each camera out covers
    what the report's misses need (issue 56)."""
    report = json.loads(st.PROPERTIES.read_text())
    cells = st.read_property_cells(report)
    outcomes = st.property_study(cells)
    doc = json.loads((REPO / "reports/validation/properties-interval.json").read_text())
    assert doc["outcomes"] == json.loads(json.dumps([o.to_json() for o in outcomes]))
    text = (REPO / "reports/validation/properties-interval.md").read_text(encoding="utf-8")
    assert text == st.property_markdown(outcomes, "reports/validation/properties.json")
    by = {o.method: o for o in outcomes}
    summary = report["summary"]["dmap_points"]["all"]
    assert by["table"].cells == summary["cells"] and by["table"].cells_covered == summary["within"]
    assert by["table"].median_ratio == pytest.approx(summary["median_ratio"], rel=1e-12)
    assert {(c, d) for c, d, _, _ in by["table"].misses} == {
        (m["camera"], m["model"]) for m in summary["misses"]}
    # an additive margin never lowers a bound: it covers at least the table's cells
    assert by["additive"].constants["q"] >= 0 and (
        by["additive"].cells_covered >= by["table"].cells_covered)
