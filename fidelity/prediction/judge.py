"""A chart ΔE judged: the classic prediction, the direction-aware one and a criterion's verdict.

What ``check``, ``audit``, ``gate`` and ``compare`` do after measuring a chart, in one place:
predict the worst-case loss of the chart ΔE from a table (:func:`fidelity.prediction.table.predict`),
predict the direction-aware loss of the chart's errors (:mod:`fidelity.prediction.directional`)
and apply the criterion to the prediction asked for (``bound``: ``classic`` or ``directional``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from fidelity.core.errors import unknown_name
from fidelity.prediction.table import Prediction
from fidelity.prediction.tablefile import PredictionTable, TableKind
from fidelity.prediction.verdict import SIMPLE, Criterion, DecisionRule, Verdict

if TYPE_CHECKING:
    from fidelity.measure.colour import ChartMeasurement
    from fidelity.prediction.directional import DirectionalPrediction


class Judgement(NamedTuple):
    """The ``prediction`` (classic), the ``verdict`` (None without a criterion) and the
    ``directional`` prediction (None without a measurement)."""

    prediction: Prediction
    verdict: Verdict | None
    directional: DirectionalPrediction | None


def directional_table_name(table: PredictionTable | str | None) -> str | None:
    """The name (or path) of ``table`` when it is a direction-aware table
    (:attr:`TableKind.DIRECTIONAL`), else None (the default direction-aware table answers)."""
    if isinstance(table, str):
        from fidelity.prediction.tablefile import load_prediction_table

        return table if load_prediction_table(table).kind is TableKind.DIRECTIONAL else None
    if table is not None and table.kind is TableKind.DIRECTIONAL and table.path is not None:
        return str(table.path)
    return None


def directional_prediction(measurement: ChartMeasurement, size: str = "any",
                           table: PredictionTable | str | None = None) -> DirectionalPrediction:
    """The direction-aware prediction of a chart: from ``table`` when it is a direction-aware
    table (:attr:`TableKind.DIRECTIONAL`), else from the default one.

    Parameters
    ----------
    measurement
        The chart's per-patch measurement (its Lab errors give the directions).
    size
        Detector size class (``n`` ... ``x``, ``any``).
    table
        A prediction table's name, path or object; None or a table of another kind: the
        default direction-aware table.
    """
    from fidelity.prediction.directional import predict_chart

    return predict_chart(measurement, size=size, table=directional_table_name(table))


def judge(mean_delta_e: float, size: str = "any", table: PredictionTable | str | None = None,
          criterion: Criterion | None = None, measurement: ChartMeasurement | None = None,
          bound: str = "classic", *, decision: DecisionRule = SIMPLE,
          delta_e_uncertainty: float | None = None) -> Judgement:
    """Predict the loss of a chart ΔE and apply ``criterion``.

    Parameters
    ----------
    mean_delta_e
        The chart ΔE (mean ΔE00 over the patches), >= 0.
    size, table
        Detector size class and prediction table (name, path or object; None: the default).
    criterion
        The gate; None: no verdict.
    measurement
        The chart's measurement, for the direction-aware prediction (None: none made).
    bound
        Which prediction decides a ``max-dmap`` verdict: ``classic`` (the table's worst case
        over every transform) or ``directional`` (needs ``measurement``).
    decision, delta_e_uncertainty
        The decision rule (:class:`~fidelity.prediction.verdict.DecisionRule`) and the chart
        ΔE's standard uncertainty (None: unknown). A classic ``max-dmap`` verdict uses the
        predicted loss's uncertainty (:func:`fidelity.prediction.interval.prediction_interval`);
        a direction-aware one has none.

    Returns
    -------
    Judgement
    """
    from fidelity.prediction.directional import BOUNDS, evaluate_directional
    from fidelity.prediction.table import predict
    from fidelity.prediction.verdict import evaluate

    if bound not in BOUNDS:
        raise unknown_name("bound", bound, BOUNDS)
    prediction = predict(mean_delta_e, size=size, table=table)
    directional = (directional_prediction(measurement, size, table)
                   if measurement is not None else None)
    verdict = None
    if criterion:
        if bound == "directional" and directional is not None:
            verdict = evaluate_directional(mean_delta_e, directional, criterion,
                                           decision=decision,
                                           delta_e_uncertainty=delta_e_uncertainty)
        else:
            loss_u = None
            if criterion.kind == "max-dmap":
                from fidelity.prediction.interval import prediction_interval

                interval = prediction_interval(prediction, delta_e_uncertainty or 0.0,
                                               criterion.column, decision.k)
                if interval is not None and (interval.table_se is not None
                                             or delta_e_uncertainty is not None):
                    loss_u = interval.standard_uncertainty
            verdict = evaluate(mean_delta_e, prediction, criterion, decision=decision,
                               delta_e_uncertainty=delta_e_uncertainty, loss_uncertainty=loss_u)
    return Judgement(prediction, verdict, directional)


__all__ = ["Judgement", "directional_prediction", "directional_table_name", "judge"]
