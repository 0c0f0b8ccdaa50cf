"""A chart ΔE judged: the classic prediction, the direction-aware one and a criterion's verdict.

What ``check``, ``audit``, ``gate`` and ``compare`` do after measuring a chart, in one place:
predict the worst-case loss of the chart ΔE from a table (:func:`fidelity.prediction.table.predict`),
predict the direction-aware loss of the chart's errors (:mod:`fidelity.prediction.directional`)
and apply the criterion to the prediction asked for (``bound``: ``classic`` or ``directional``).

How to judge travels as one frozen record, :class:`JudgeOptions` (detector size class,
prediction table, which bound decides, the decision rule), from the command line through the
public API (``check_camera(..., judge=JudgeOptions(size="n"))``) to :func:`judge_chart`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from fidelity.core.errors import unknown_name
from fidelity.prediction.directional import (
    BOUNDS,
    DirectionalPrediction,
    evaluate_directional,
    predict_chart,
)
from fidelity.prediction.interval import prediction_interval
from fidelity.prediction.table import Prediction, predict
from fidelity.prediction.tablefile import PredictionTable, TableKind, load_prediction_table
from fidelity.prediction.verdict import SIMPLE, Criterion, DecisionRule, Verdict, evaluate

if TYPE_CHECKING:
    from fidelity.measure.colour import ChartMeasurement


@dataclass(frozen=True)
class JudgeOptions:
    """How a measured chart is judged: which loss is predicted and how a verdict decides
    (``check``, ``audit``, ``gate``, ``compare`` and ``fit`` and their library functions take
    one as ``judge=``).

    Attributes
    ----------
    size
        Detector size class of the prediction (``n``, ``s``, ``m``, ``l``, ``x`` or ``any``:
        :data:`fidelity.prediction.tablefile.SIZES`).
    table
        The prediction table: a name, a JSON path or a loaded
        :class:`~fidelity.prediction.tablefile.PredictionTable`; None: the default table.
    bound
        Which prediction decides a ``max-dmap`` verdict (:data:`BOUNDS`): ``classic`` (the
        table's worst case over every transform) or ``directional`` (the direction-aware
        prediction of the chart's errors); both are reported.
    decision
        The decision rule of a verdict (:class:`~fidelity.prediction.verdict.DecisionRule`:
        simple, or guarded with the value's expanded uncertainty).
    """

    size: str = "any"
    table: PredictionTable | str | None = None
    bound: str = "classic"
    decision: DecisionRule = SIMPLE

    def __post_init__(self) -> None:
        if self.bound not in BOUNDS:
            raise unknown_name("bound", self.bound, BOUNDS)

    @property
    def table_input(self) -> str | None:
        """The table as a command's input, a file or a name, for the overwrite check of
        outputs; None for the default table or a loaded one."""
        return self.table if isinstance(self.table, str) else None


#: Every judging option at its default.
DEFAULT_JUDGE = JudgeOptions()


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
    return predict_chart(measurement, size=size, table=directional_table_name(table))


def judge_chart(mean_delta_e: float, judge: JudgeOptions = DEFAULT_JUDGE,
                criterion: Criterion | None = None, measurement: ChartMeasurement | None = None,
                *, delta_e_uncertainty: float | None = None) -> Judgement:
    """Predict the loss of a chart ΔE and apply ``criterion``.

    Parameters
    ----------
    mean_delta_e
        The chart ΔE (mean ΔE00 over the patches), >= 0.
    judge
        How to judge (:class:`JudgeOptions`): detector size class, prediction table, which
        bound decides a ``max-dmap`` verdict (``directional`` needs ``measurement``) and the
        decision rule.
    criterion
        The gate; None: no verdict.
    measurement
        The chart's measurement, for the direction-aware prediction (None: none made).
    delta_e_uncertainty
        The chart ΔE's standard uncertainty (None: unknown). A classic ``max-dmap`` verdict
        uses the predicted loss's uncertainty
        (:func:`fidelity.prediction.interval.prediction_interval`); a direction-aware one has
        none.

    Returns
    -------
    Judgement
        The classic prediction, the verdict (None without ``criterion``) and the
        direction-aware prediction (None without ``measurement``).
    """
    size, table, bound, decision = judge.size, judge.table, judge.bound, judge.decision
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
                interval = prediction_interval(prediction, delta_e_uncertainty or 0.0,
                                               criterion.column, decision.k)
                if interval is not None and (interval.table_se is not None
                                             or delta_e_uncertainty is not None):
                    loss_u = interval.standard_uncertainty
            verdict = evaluate(mean_delta_e, prediction, criterion, decision=decision,
                               delta_e_uncertainty=delta_e_uncertainty, loss_uncertainty=loss_u)
    return Judgement(prediction, verdict, directional)


__all__ = ["BOUNDS", "DEFAULT_JUDGE", "JudgeOptions", "Judgement", "directional_prediction",
           "directional_table_name", "judge_chart"]
