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

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any, NamedTuple

from fidelity.core.errors import FidelityError, InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.measure.chartsharpness import TARGET_METHOD
from fidelity.prediction.directional import (
    BOUNDS,
    DirectionalPrediction,
    evaluate_directional,
    predict_chart,
)
from fidelity.prediction.exposure import (
    DEFAULT_MAX_EXPOSURE_ERROR_EV,
    EXPOSURE_SOURCES,
    ExposureJudgement,
)
from fidelity.prediction.interval import prediction_interval
from fidelity.prediction.properties import (
    PropertyJudgement,
    PropertyPrediction,
    PropertyTable,
    chart_mtf50,
    chart_snr,
    combine,
    load_property_table,
    predict_property,
    property_threshold,
    target_on_table_axis,
)
from fidelity.prediction.table import Prediction, predict
from fidelity.prediction.tablefile import PredictionTable, TableKind, load_prediction_table
from fidelity.prediction.validated import with_margin
from fidelity.prediction.verdict import (
    SIMPLE,
    Criterion,
    DecisionRule,
    Verdict,
    VerdictReason,
    evaluate,
    judge_value,
)

if TYPE_CHECKING:
    from fidelity.measure.colour import ChartMeasurement


@record
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
    max_exposure_error
        The largest exposure error that passes, in EV, where the exposure is judged (a fixed
        exposure given, :mod:`fidelity.prediction.exposure`).
    exposure_source
        Where a fixed exposure came from: ``--exposure`` or the scene ``manifest``
        (:data:`~fidelity.prediction.exposure.EXPOSURE_SOURCES`).
    """

    size: str = "any"
    table: PredictionTable | str | None = None
    bound: str = "classic"
    decision: DecisionRule = SIMPLE
    max_exposure_error: float = DEFAULT_MAX_EXPOSURE_ERROR_EV
    exposure_source: str = "--exposure"

    def __post_init__(self) -> None:
        if self.bound not in BOUNDS:
            raise unknown_name("bound", self.bound, BOUNDS)
        if not (math.isfinite(self.max_exposure_error) and self.max_exposure_error > 0):
            raise InvalidValueError(f"--max-exposure-error {self.max_exposure_error!r}: must "
                                    f"be a positive number of EV")
        if self.exposure_source not in EXPOSURE_SOURCES:
            raise unknown_name("exposure source", self.exposure_source, EXPOSURE_SOURCES)

    @property
    def table_input(self) -> str | None:
        """The table as a command's input, a file or a name, for the overwrite check of
        outputs; None for the default table or a loaded one."""
        return self.table if isinstance(self.table, str) else None


#: Every judging option at its default.
DEFAULT_JUDGE = JudgeOptions()


class Judgement(NamedTuple):
    """The ``prediction`` (classic), the ``verdict`` (None without a criterion), the
    ``directional`` prediction (None without a measurement) and the ``properties``' judgement
    (sharpness and noise besides colour; None where not asked for)."""

    prediction: Prediction
    verdict: Verdict | None
    directional: DirectionalPrediction | None
    properties: PropertyJudgement | None = None


#: The properties a verdict judges besides colour, in report order.
JUDGED_PROPERTIES: tuple[str, ...] = ("sharpness", "noise")


def _native_value(prop: str, measured: Any) -> tuple[tuple[float, float | None] | None, str]:
    if measured is None:
        return None, "not measured"
    got = chart_mtf50(measured) if prop == "sharpness" else chart_snr(measured)
    if got is None:
        why = ("no edge's luminance MTF50 was measured" if prop == "sharpness"
               else "the grey patch's SNR was not measured")
        codes = sorted({e.refusal[0] for e in getattr(measured, "edges", ()) if e.refusal}
                       | {c.refusal[0] for e in getattr(measured, "edges", ())
                          for c in e.channels if c.channel == "Y" and c.refusal})
        return None, why + (f" (refused: {', '.join(codes)})" if codes else "")
    return got, ""


def judge_properties(verdict: Verdict | None, prediction: Prediction, criterion: Criterion | None,
                     *, size: str = "any", sharpness: Any = None, noise: Any = None,
                     scale: float = 1.0, tables: Mapping[str, Any] | None = None,
                     delta_e_uncertainty: float | None = None
                     ) -> tuple[PropertyJudgement, Verdict | None]:
    """Judge sharpness and noise beside colour, and the verdict they make together.

    Parameters
    ----------
    verdict
        The colour verdict (:func:`judge_chart`); None without a criterion.
    prediction
        The classic colour prediction.
    criterion
        The gate (None: no verdict).
    size
        Detector size class.
    sharpness, noise
        The chart's :class:`~fidelity.measure.chartsharpness.ChartSharpness` and
        :class:`~fidelity.measure.chartnoise.ChartNoise` at the image's resolution (None: not
        measured: the property is not judged, and the verdict says so). Sharpness measured on
        a slanted-edge target (``method``
        :data:`~fidelity.measure.chartsharpness.TARGET_METHOD`) is put on the tables'
        patch-edge axis first
        (:func:`~fidelity.prediction.properties.target_on_table_axis`).
    scale
        The detector's input over the image's size
        (:func:`fidelity.prediction.properties.detector_scale`): MTF50 is divided by it (at
        most the undegraded chart's: a downscaled image is at most as sharp as the
        detector's pixels), the SNR by ``min(scale, 1)`` (downscaling averages
        ``1 / scale^2`` pixels of white noise).
    tables
        Property -> its table (None: the shipped ones).
    delta_e_uncertainty
        The chart ΔE's standard uncertainty (ΔE00), which enters the colour loss's
        uncertainty through the table's slope
        (:func:`~fidelity.prediction.interval.prediction_interval`) with the table's SE
        (None: the SE alone).

    Returns
    -------
    tuple
        The :class:`~fidelity.prediction.properties.PropertyJudgement` and the verdict: for ``max-dmap``, the combined loss
        against the limit; for ``max-delta-e`` with limit L, the colour verdict failed also by
        any property whose worst-case loss exceeds the colour table's at ΔE L.
    """
    column = criterion.column if criterion is not None and criterion.kind == "max-dmap" \
        else "dmap_points"
    limit_de = criterion.limit if criterion is not None and criterion.kind == "max-delta-e" \
        else 3.0
    col = prediction.columns.get(column)
    limit_loss = None
    try:
        limit_col = predict(limit_de, size=size, table=prediction.table).columns.get(column)
        limit_loss = None if limit_col is None else limit_col.value
    except FidelityError:
        limit_loss = None
    colour = col.value if col is not None else None
    u_colour = None
    if verdict is not None and verdict.criterion.kind == "max-dmap":
        colour, u_colour = verdict.value, verdict.uncertainty
    if u_colour is None and colour is not None:
        # the colour loss's own standard uncertainty: the table's SE and u(ΔE) through its slope
        interval = prediction_interval(prediction, delta_e_uncertainty or 0.0, column)
        if interval is not None and (interval.table_se is not None
                                     or delta_e_uncertainty is not None):
            u_colour = interval.standard_uncertainty
    preds: list[PropertyPrediction] = []
    skipped: list[tuple[str, str]] = []
    limits: dict[str, float | None] = {}
    used: dict[str, PropertyTable] = {}
    for prop, measured in zip(JUDGED_PROPERTIES, (sharpness, noise), strict=True):
        try:
            table = (tables or {}).get(prop) or load_property_table(prop)
        except FidelityError as exc:
            skipped.append((prop, f"no table: {exc}"))
            continue
        used[prop] = table
        limits[prop] = (property_threshold(table, limit_loss, size=size, column=column)
                        if limit_loss is not None else None)
        got, why = _native_value(prop, measured)
        if got is None:
            skipped.append((prop, why))
            continue
        target_x = None
        if prop == "sharpness" and getattr(measured, "method", None) == TARGET_METHOD:
            # a slanted-edge target's MTF50 on the tables' patch-edge axis
            target_x = got[0]
            got = target_on_table_axis(*got)
        factor = scale if prop == "sharpness" else min(scale, 1.0)
        x, u = got[0] / factor, (None if got[1] is None else got[1] / factor)
        if prop == "sharpness" and x > table.baseline_x:
            # a downscaled image is at most as sharp as the detector's own pixels
            x, u = table.baseline_x, None
        try:
            preds.append(predict_property(table, x, u_x=u, size=size, column=column,
                                          scale=factor, native_x=got[0],
                                          target_x=target_x))
        except FidelityError as exc:
            skipped.append((prop, str(exc)))
    parts: dict[str, tuple[float, float | None] | None] = {
        "colour": None if colour is None else (max(colour, 0.0), u_colour)}
    parts |= {p.property: (p.loss, p.u_loss) for p in preds}
    combined = (with_margin(combine(parts), column, used, size)
                if any(v is not None for v in parts.values()) else None)
    failed: tuple[str, ...] = ()
    if criterion is not None and verdict is not None:
        if criterion.kind == "max-dmap" and combined is not None and preds:
            verdict = judge_value(criterion, combined.loss, verdict.delta_e,
                                  decision=verdict.decision, uncertainty=combined.u_loss,
                                  bound=verdict.bound, status=verdict.status,
                                  upper_bound=verdict.upper_bound, table=verdict.table,
                                  conservative=verdict.conservative
                                  or any(p.status == "beyond" for p in preds))
            if not verdict.passed:
                failed = (combined.dominant,)
        elif criterion.kind == "max-delta-e" and limit_loss is not None:
            failed = tuple(p.property for p in preds if p.loss > limit_loss)
            if failed and verdict.passed:
                verdict = replace(verdict, passed=False, reason=VerdictReason.OVER_LIMIT)
    judgement = PropertyJudgement(column, colour, u_colour, tuple(preds), tuple(skipped),
                                  combined, limits, float(limit_de), limit_loss, failed)
    if verdict is not None:
        verdict = replace(verdict, properties=judgement)
    return judgement, verdict


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


def limit_allows(limit_delta_e: float, prediction: Prediction) -> float | None:
    """What a limit on the mean ΔE00 allows: the predicted worst-case ΔmAP in percent of the
    baseline mAP at ΔE00 = ``limit_delta_e``, from ``prediction``'s table and size class.

    Parameters
    ----------
    limit_delta_e
        The ``max-delta-e`` limit, ΔE00, >= 0.
    prediction
        A prediction whose table (with its curves) and size class answer.

    Returns
    -------
    float or None
        ΔmAP in % of baseline, in [0, 100]; None when the table has no curves (read back from
        JSON) or no relative column.
    """
    if not prediction.table.curves:
        return None
    try:
        at = predict(limit_delta_e, size=prediction.size, table=prediction.table,
                     method=prediction.method, baseline_map=prediction.baseline_map,
                     transforms=False)
    except FidelityError:
        return None
    return at.dmap_relative


def judge_chart(mean_delta_e: float, judge: JudgeOptions = DEFAULT_JUDGE,
                criterion: Criterion | None = None, measurement: ChartMeasurement | None = None,
                *, delta_e_uncertainty: float | None = None, properties: bool = False,
                sharpness: Any = None, noise: Any = None, scale: float = 1.0,
                exposure: ExposureJudgement | None = None) -> Judgement:
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
        The chart ΔE's standard uncertainty (None: unknown). A ``max-dmap`` verdict uses the
        predicted loss's uncertainty of the criterion's own column (points, relative, person
        or bicycle: :func:`fidelity.prediction.interval.prediction_interval`); a
        direction-aware one its own column's SE
        (:attr:`~fidelity.prediction.directional.DirectionalPrediction.standard_errors`) with
        the ΔE's uncertainty through the classic column's slope (a table without SEs: the
        classic column's uncertainty, :func:`fidelity.prediction.directional.evaluate_directional`).
    properties
        Judge sharpness and noise too (:func:`judge_properties` with ``sharpness``, ``noise``
        and ``scale``; a property not measured is named as not judged).
    sharpness
        The chart's :class:`~fidelity.measure.chartsharpness.ChartSharpness` (None: not
        measured).
    noise
        The chart's :class:`~fidelity.measure.chartnoise.ChartNoise` (None: not measured).
    scale
        The detector's input over the image's size.
    exposure
        The image's exposure judged (:func:`fidelity.prediction.exposure.judge_exposure`;
        None: not judged): over its limit, it fails the verdict.

    Returns
    -------
    Judgement
        The classic prediction, the verdict (None without ``criterion``), the
        direction-aware prediction (None without ``measurement``) and the properties'
        judgement (None unless ``properties``).
    """
    size, table, bound, decision = judge.size, judge.table, judge.bound, judge.decision
    prediction = predict(mean_delta_e, size=size, table=table)
    directional = (directional_prediction(measurement, size, table)
                   if measurement is not None else None)
    verdict = None
    if criterion:
        loss_u = None
        if criterion.kind == "max-dmap":  # the criterion's own column's uncertainty
            interval = prediction_interval(prediction, delta_e_uncertainty or 0.0,
                                           criterion.column, decision.k)
            if interval is not None and (interval.table_se is not None
                                         or delta_e_uncertainty is not None):
                loss_u = interval.standard_uncertainty
            if bound == "directional" and directional is not None:
                # its own SE, with u(ΔE) through the classic column's slope
                own = directional.uncertainty(
                    criterion.column, interval.propagated if interval is not None else 0.0)
                loss_u = own if own is not None else loss_u
        if bound == "directional" and directional is not None:
            verdict = evaluate_directional(mean_delta_e, directional, criterion,
                                           decision=decision,
                                           delta_e_uncertainty=delta_e_uncertainty,
                                           loss_uncertainty=loss_u)
        else:
            verdict = evaluate(mean_delta_e, prediction, criterion, decision=decision,
                               delta_e_uncertainty=delta_e_uncertainty, loss_uncertainty=loss_u)
    if verdict is not None and criterion is not None and criterion.kind == "max-delta-e":
        verdict = replace(verdict, limit_loss_relative=limit_allows(criterion.limit, prediction))
    judged = None
    if properties:
        judged, verdict = judge_properties(verdict, prediction, criterion, size=size,
                                           sharpness=sharpness, noise=noise, scale=scale,
                                           delta_e_uncertainty=delta_e_uncertainty)
    if verdict is not None and exposure is not None:
        verdict = replace(verdict, exposure=exposure)
        if not exposure.passed:
            verdict = replace(verdict, passed=False, reason=VerdictReason.OVER_LIMIT)
    return Judgement(prediction, verdict, directional, judged)


__all__ = ["BOUNDS", "DEFAULT_JUDGE", "JUDGED_PROPERTIES", "JudgeOptions", "Judgement",
           "directional_prediction", "directional_table_name", "judge_chart",
           "judge_properties", "limit_allows"]
