"""What a limit on the mean ΔE00 allows (:func:`fidelity.prediction.judge.limit_allows`) and
the verdict that records it."""

from __future__ import annotations

import pytest

from fidelity.prediction.judge import judge_chart, limit_allows
from fidelity.prediction.table import predict
from fidelity.prediction.tablefile import load_prediction_table
from fidelity.prediction.verdict import Criterion, Verdict
from fidelity.report.words import verdict_message


def _table_relative_at(delta_e: float) -> float:
    """Linear interpolation of the shipped table's size-n aggregate curve, by hand."""
    tab = load_prediction_table(None)
    curve = next(c for c in tab.curves if c.model is None)
    x, y = list(curve.delta_e), list(curve.values["dmap_relative"])
    for i in range(1, len(x)):
        if x[i - 1] <= delta_e <= x[i]:
            t = (delta_e - x[i - 1]) / (x[i] - x[i - 1])
            return float(y[i - 1] + t * (y[i] - y[i - 1]))
    raise AssertionError(delta_e)


@pytest.mark.parametrize("limit", [3.0, 2.5, 0.5])
def test_the_limit_allows_the_tables_relative_loss_at_the_limit(limit):
    at = limit_allows(limit, predict(1.0))
    assert at == pytest.approx(_table_relative_at(limit), abs=1e-9)


def test_a_delta_e_verdict_says_what_its_limit_allows_and_reads_back():
    j = judge_chart(1.0, criterion=Criterion("max-delta-e", 3.0))
    v = j.verdict
    assert v is not None and v.passed
    assert v.limit_loss_relative == pytest.approx(2.392, abs=1e-3)
    assert "(up to 2.39 % of baseline for these detectors)" in verdict_message(v)
    back = Verdict.from_json(v.to_json())
    assert back.limit_loss_relative == v.limit_loss_relative


def test_a_loss_verdict_has_no_delta_e_allowance():
    j = judge_chart(1.0, criterion=Criterion("max-dmap", 1.0, unit="relative"))
    assert j.verdict is not None and j.verdict.limit_loss_relative is None
    assert not j.verdict.passed  # 1.20 % of baseline at ΔE 1 > 1 %


@pytest.mark.parametrize("u", [None, 0.0, 0.5])
def test_the_colour_loss_of_a_delta_e_verdict_carries_its_uncertainty(u):
    """Under the default ΔE criterion, the properties' colour part and the combined loss
    carry the colour loss's standard uncertainty: the table's SE at the ΔE with u(ΔE) through
    the table's slope (a central difference over ± u), by hand from the table here."""
    j = judge_chart(1.0, criterion=Criterion("max-delta-e", 3.0), delta_e_uncertainty=u,
                    properties=True)
    judged = j.properties
    assert judged is not None and judged.colour == pytest.approx(predict(1.0).columns[
        "dmap_points"].value)
    se = predict(1.0).se("dmap_points").high
    du = 0.0 if u is None else u
    slope = ((predict(1.5).columns["dmap_points"].value
              - predict(0.5).columns["dmap_points"].value) / 1.0) if du else 0.0
    assert judged.u_colour == pytest.approx((se ** 2 + (slope * du) ** 2) ** 0.5, rel=1e-9)
    assert judged.combined is not None and judged.combined.u_loss == pytest.approx(
        judged.u_colour)
