"""Predict what a chart's colour error costs object detectors: ΔE00 -> ΔmAP, ΔAP person/bicycle.

The prediction reads a prediction table (:mod:`fidelity.prediction.tablefile`: the file, its
columns and the registry; the default :data:`~fidelity.prediction.tablefile.DEFAULT_TABLE`)
at the chart's ΔE, each column interpolated on its running maximum and answered
conservatively outside its range (:mod:`fidelity.prediction.interpolate`). :func:`predict`
gives every column's answer (:class:`Prediction`); :func:`delta_e_limit` is its inverse, the
largest ΔE within a loss budget.

When a size class has no curve of its own, the ``any`` curve (the worst over all sizes) answers
and the result says so. A size's aggregate curve (``model`` null) answers for it; without one,
when several per-model curves match, the worst (largest) value answers.

What is colour's here: the axis (the chart ΔE) and the SAFE-COLOR transform parameters a
prediction lists (:mod:`fidelity.prediction.colour`). A second camera property's prediction
would read its own tables with the same file format and interpolation, and list its own
transforms from a sibling of :mod:`fidelity.prediction.colour`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import field
from typing import Any

import numpy as np

from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.prediction.colour import TransformParameter, transform_parameters
from fidelity.prediction.interpolate import (
    INTERPOLATIONS,
    ColumnPrediction,
    ColumnStatus,
    SamplingError,
    column_values,
    points_ceiling,
    predict_curve,
)
from fidelity.prediction.tablefile import (
    CEILING,
    CLASS_COLUMNS,
    COLUMNS,
    Curve,
    PredictionTable,
    TableKind,
    load_prediction_table,
)


@record
class DeltaELimit:
    """The largest chart ΔE whose predicted loss stays within a limit (:func:`delta_e_limit`).

    ``delta_e``: that ΔE (None: even the table's first point predicts more); ``status``:
    ``"inside"`` (the loss reaches the limit inside the table's range), ``"whole-range"`` (it
    stays within the limit up to the table's last ΔE; beyond it the ceiling, total loss,
    applies) or ``"none"``; ``loss_at_limit``: the predicted loss there.
    """

    max_loss: float
    column: str
    delta_e: float | None
    status: str
    loss_at_limit: float | None
    table: str
    size_used: str
    delta_e_range: tuple[float, float]

    def rounded_down(self, decimals: int = 2) -> float | None:
        """``delta_e`` as :func:`limit_rounded_down` prints it (None stays None)."""
        return None if self.delta_e is None else limit_rounded_down(self.delta_e, decimals)

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"max_loss": self.max_loss, "column": self.column, "delta_e": self.delta_e,
                "status": self.status, "loss_at_limit": self.loss_at_limit,
                "table": self.table, "size_used": self.size_used,
                "delta_e_range": list(self.delta_e_range)}


def limit_rounded_down(delta_e: float, decimals: int = 2) -> float:
    """A ΔE limit rounded *down* to ``decimals`` places: a printed limit that is safe to gate on
    (:func:`delta_e_limit`'s bisection ends up to 1e-6 below the exact limit; that does not
    count, so 2.9999995 prints as 3.00, while 3.6561 prints as 3.65, not 3.66)."""
    scale = 10.0 ** decimals
    return math.floor((delta_e + 1e-6) * scale) / scale


def delta_e_limit(max_loss: float, column: str = "dmap_points", *, size: str = "any",
                  table: PredictionTable | str | None = None, method: str | None = None,
                  tol: float = 1e-6) -> DeltaELimit:
    """The largest chart ΔE at which the predicted ``column`` loss is still <= ``max_loss``:
    the inverse of :func:`predict_curve`, for setting a gate's ΔE threshold from a loss budget.

    Predictions are non-decreasing in ΔE (each column is its running maximum before
    interpolation, and the interpolations keep that order), so the ΔE values within the
    budget form one interval from 0; its upper end is found by bisection to ``tol``. Searched
    inside the range of the table's curves for ``size``; ``max_loss`` in the column's unit
    (points, or percent of baseline for ``dmap_relative``).

    Parameters
    ----------
    max_loss
        The loss budget, a finite number >= 0, in the column's unit: percentage points, or
        percent of the baseline mAP for ``dmap_relative``.
    column
        The loss column: ``dmap_points`` (default), ``dmap_relative``,
        ``dap_person_points`` or ``dap_bicycle_points``.
    size
        Detector size class ``n``, ``s``, ``m``, ``l``, ``x`` or ``any`` (default).
    table
        Table name, path or object; None:
        :data:`~fidelity.prediction.tablefile.DEFAULT_TABLE`.
    method
        Interpolation (``pchip``, ``linear``, ``step``); None: the table's own.
    tol
        Width in ΔE00 at which the bisection stops, > 0; the limit found is at most ``tol``
        below the exact one.

    Returns
    -------
    DeltaELimit
        ``delta_e``: the largest chart ΔE (mean ΔE00) whose predicted loss is <= ``max_loss``
        (None when even the table's first point predicts more), its ``status``
        (``inside``, ``whole-range`` or ``none``), the loss there, the table, the size that
        answered and the ΔE range searched.

    Raises
    ------
    UnknownNameError
        An unknown column, size class, table name or interpolation. Exit code 2.
    InvalidValueError
        ``max_loss`` not a finite number >= 0, or a table without data of the column for the
        size. Exit code 2.
    InputFileError
        A table file that is missing or invalid. Exit code 2.
    """
    tab = table if isinstance(table, PredictionTable) else load_prediction_table(table)
    if column not in COLUMNS:
        raise unknown_name("prediction column", column, COLUMNS)
    if not math.isfinite(max_loss) or max_loss < 0:
        raise InvalidValueError(f"loss limit {max_loss!r} must be a finite number >= 0")
    curves, size_used = tab.select(size)
    ranges = [(float(c.delta_e[0]), float(c.delta_e[-1])) for c in curves
              if np.any(~np.isnan(c.values[column]))]
    if not ranges:
        raise InvalidValueError(f"table {tab.name!r} has no {column} data for size {size!r}")
    lo, hi = min(r[0] for r in ranges), min(r[1] for r in ranges)

    def f(x: float) -> float:
        return float(predict_curve([x], column, size=size, table=tab, method=method)[0])

    def result(de: float | None, status: str) -> DeltaELimit:
        return DeltaELimit(float(max_loss), column, de, status,
                           None if de is None else f(de), tab.name, size_used, (lo, hi))

    if f(lo) > max_loss:
        return result(None, "none")
    if f(hi) <= max_loss:
        return result(hi, "whole-range")
    a, b = lo, hi  # f(a) <= max_loss < f(b)
    while b - a > tol:
        mid = 0.5 * (a + b)
        a, b = (mid, b) if f(mid) <= max_loss else (a, mid)
    return result(a, "inside")


@record
class Prediction:
    """The predicted detection loss for one chart ΔE (see :func:`predict`).

    ``columns`` holds each loss column's answer (:class:`ColumnPrediction`), ``size_used`` the
    detector size class whose curves answered (``any``, or the sizes a table has, comma
    separated, when it has no curve for ``size``), ``dmap_points_se`` the sampling error of a
    measured table around ``delta_e`` (None for published bounds, a table without SEs, or a
    ΔE beyond the table's range, answered by the total loss).
    What the numbers mean in words is written by :mod:`fidelity.report.words`.

    Attributes
    ----------
    delta_e
        The chart ΔE (mean ΔE00) predicted at, >= 0.
    size
        The detector size class asked: ``n``, ``s``, ``m``, ``l``, ``x`` or ``any``.
    size_used
        The size class whose curves answered.
    columns
        Per loss column (``dmap_points``, ``dmap_relative``, ``dap_person_points``,
        ``dap_bicycle_points``) its value (percentage points; ``dmap_relative`` in percent of
        the baseline mAP), status and the ΔE range of its curve.
    table
        The prediction table that answered (after :meth:`from_json`: its summary, without
        curves).
    method
        The interpolation used: ``pchip``, ``linear`` or ``step``.
    baseline_map
        The detector's baseline mAP@[.50:.95] in percent, (0, 100], when given; else None.
    transforms
        The SAFE-COLOR transform parameters that put the chart at ``delta_e`` (empty when
        not asked for).
    dmap_points_se
        The sampling error of a measured table's ``dmap_points`` at the table points next to
        ``delta_e``, percentage points; None for published bounds, a table without SEs, or a
        ΔE beyond the table's range.
    column_se
        The same for each other column the table states standard errors of
        (``dmap_relative`` in percent of the baseline, ``dap_person_points``,
        ``dap_bicycle_points`` in points), from the curve that answered that column.
    """

    delta_e: float
    size: str
    size_used: str
    columns: dict[str, ColumnPrediction]
    table: PredictionTable
    method: str
    baseline_map: float | None
    transforms: tuple[TransformParameter, ...]
    dmap_points_se: SamplingError | None = None
    column_se: dict[str, SamplingError] = field(default_factory=dict)

    def se(self, column: str) -> SamplingError | None:
        """The sampling error of ``column``'s answer (:attr:`dmap_points_se` for
        ``dmap_points``, else :attr:`column_se`); None where the table has none."""
        if column == "dmap_points":
            return self.dmap_points_se
        return self.column_se.get(column)

    @property
    def kind(self) -> TableKind:
        """The kind of the table that answered."""
        return self.table.kind

    @property
    def upper_bound(self) -> bool:
        """True when the values are published upper bounds, not measured worst cases."""
        return self.table.kind.upper_bound

    @property
    def dmap_points(self) -> float | None:
        """Predicted ΔmAP in percentage points (upper bound for published tables)."""
        return self.columns["dmap_points"].value

    @property
    def dmap_relative(self) -> float | None:
        """Predicted ΔmAP in percent of the baseline mAP."""
        return self.columns["dmap_relative"].value

    @property
    def dap_person_points(self) -> float | None:
        """Predicted person ΔAP in percentage points."""
        return self.columns["dap_person_points"].value

    @property
    def dap_bicycle_points(self) -> float | None:
        """Predicted bicycle ΔAP in percentage points."""
        return self.columns["dap_bicycle_points"].value

    @property
    def dmap_points_interval(self) -> tuple[float, float] | None:
        """``dmap_points`` ± its larger sampling error (one standard error, k = 1), in
        percentage points; None without a measured SE or a value."""
        v, se = self.dmap_points, self.dmap_points_se
        if v is None or se is None:
            return None
        return (v - se.high, v + se.high)

    @property
    def out_of_range(self) -> bool:
        """True when any column was answered outside its table range."""
        return any(c.status in (ColumnStatus.BELOW_RANGE, ColumnStatus.ABOVE_RANGE)
                   for c in self.columns.values())

    def value(self, cls: str = "all", unit: str = "points") -> float | None:
        """The loss for ``cls`` (``all``, ``person``, ``bicycle``) in ``unit``."""
        if cls not in CLASS_COLUMNS:
            raise unknown_name("class", cls, CLASS_COLUMNS)
        if unit == "relative":
            if cls != "all":
                raise InvalidValueError(f"--class {cls}: only 'all' has a relative ΔmAP; use points")
            return self.dmap_relative
        if unit != "points":
            raise unknown_name("unit", unit, ("points", "relative"))
        return self.columns[CLASS_COLUMNS[cls]].value

    def to_json(self) -> dict[str, Any]:
        """JSON form of the fields: ``dmap_points``, ``dmap_relative``, ``dap_person_points``,
        ``dap_bicycle_points``, ``bound`` (published upper bounds), the per-column answers,
        ``dmap_points_se`` and ``dmap_points_interval``, ``table`` (its summary) and
        ``transforms``. The report's JSON adds the notes in words
        (:func:`fidelity.report.jsonform.prediction_json`)."""
        interval = self.dmap_points_interval
        return {
            "delta_e": self.delta_e,
            "size": self.size,
            "size_used": self.size_used,
            **{col: self.columns[col].value for col in COLUMNS},
            "bound": self.upper_bound,
            "out_of_range": self.out_of_range,
            "columns": {col: c.to_json() for col, c in self.columns.items()},
            "interpolation": self.method,
            "baseline_map": self.baseline_map,
            "dmap_points_se": self.dmap_points_se.to_json() if self.dmap_points_se else None,
            "dmap_points_interval": list(interval) if interval else None,
            "column_se": {col: se.to_json() for col, se in self.column_se.items()},
            "table": self.table.summary(),
            "transforms": [tp.to_json() for tp in self.transforms],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Prediction:
        """Inverse of :meth:`to_json`; the table comes back as its summary, without curves
        (:meth:`PredictionTable.from_summary`)."""
        baseline = data.get("baseline_map")
        se = data.get("dmap_points_se")
        return cls(
            delta_e=float(data["delta_e"]), size=str(data["size"]),
            size_used=str(data["size_used"]),
            columns={str(k): ColumnPrediction.from_json(v) for k, v in data["columns"].items()},
            table=PredictionTable.from_summary(data["table"]),
            method=str(data["interpolation"]),
            baseline_map=None if baseline is None else float(baseline),
            transforms=tuple(TransformParameter.from_json(tp) for tp in data["transforms"]),
            dmap_points_se=SamplingError.from_json(se) if se else None,
            column_se={str(k): SamplingError.from_json(v)
                       for k, v in (data.get("column_se") or {}).items()},
        )


def predict(
    delta_e: float,
    size: str = "any",
    table: PredictionTable | str | None = None,
    *,
    method: str | None = None,
    baseline_map: float | None = None,
    transforms: bool = True,
) -> Prediction:
    """Predict the worst-case detection loss of a chart's mean ΔE00.

    Parameters
    ----------
    delta_e
        The chart ΔE (mean CIEDE2000 over the 24 patches), >= 0.
    size
        Detector size class ``n, s, m, l, x`` or ``any``.
    table
        Table name, path or object; ``None`` is
        :data:`~fidelity.prediction.tablefile.DEFAULT_TABLE`.
    method
        Interpolation (``pchip``, ``linear``, ``step``); default the table's own.
    baseline_map
        Baseline mAP@[.50:.95] in percent (0, 100] of the detector, when known. It resolves the
        paper's points-vs-relative ambiguity conservatively: for ``published-bounds`` tables the
        relative loss becomes ``max(X, 100 * X / baseline_map)``; the points ceiling above the
        range becomes ``baseline_map``.
    transforms
        Also list the SAFE-COLOR transform parameters that produce ``delta_e`` on the chart
        (from the shipped calibration table).

    Returns
    -------
    Prediction
        Per loss column the worst-case loss at ``delta_e`` (``dmap_points``,
        ``dap_person_points``, ``dap_bicycle_points`` in percentage points of mAP@[.50:.95]
        or AP; ``dmap_relative`` in percent of the baseline mAP), how each was answered
        (interpolated; below the range: the first point's value; above it: the ceiling, total
        loss; no data), and the sampling error of a measured table.

    Raises
    ------
    InvalidValueError
        ``delta_e`` not a finite number >= 0, or ``baseline_map`` outside (0, 100].
        Exit code 2.
    UnknownNameError
        An unknown size class, table name or interpolation. Exit code 2.
    InputFileError
        A table file that is missing or invalid. Exit code 2.

    References
    ----------
    Damschen, Avula, Mohamad, SAFE-COLOR, IEEE IV 2025 (the ΔE -> ΔmAP tables).
    """
    de = float(delta_e)
    if not math.isfinite(de) or de < 0:
        raise InvalidValueError(f"ΔE {delta_e!r} must be a finite number >= 0")
    if baseline_map is not None and not (0 < float(baseline_map) <= 100):
        raise InvalidValueError(f"--baseline-map {baseline_map!r}: the baseline mAP must be in "
                                "(0, 100] percent")
    tab = table if isinstance(table, PredictionTable) else load_prediction_table(table)
    m = method or tab.interpolation
    if m not in INTERPOLATIONS:
        raise unknown_name("interpolation method", m, INTERPOLATIONS)
    curves, size_used = tab.select(size)
    t = np.array([de])
    columns: dict[str, ColumnPrediction] = {}
    answering: Curve | None = None
    answered: dict[str, Curve] = {}
    for col in COLUMNS:
        best_v, best_s, rng = math.nan, 2, None
        for c in curves:
            v, s, r = column_values(c, col, t, m,
                                     points_ceiling(c, col, tab.curves, baseline_map))
            if r is not None and (math.isnan(best_v) or v[0] > best_v):
                best_v, best_s, rng = float(v[0]), int(s[0]), r
                answered[col] = c
                if col == "dmap_points":
                    answering = c
        if math.isnan(best_v):
            columns[col] = ColumnPrediction(None, ColumnStatus.NO_DATA, None)
            continue
        status = {0: ColumnStatus.INTERPOLATED, -1: ColumnStatus.BELOW_RANGE,
                  1: ColumnStatus.ABOVE_RANGE}[best_s]
        raised_from = None
        if (col == "dmap_relative" and tab.kind.upper_bound and baseline_map
                and columns.get("dmap_points") and columns["dmap_points"].value is not None):
            pts = columns["dmap_points"].value
            alt = min(CEILING, 100.0 * pts / float(baseline_map))
            if alt > best_v:
                raised_from, best_v = best_v, alt
        columns[col] = ColumnPrediction(best_v, status, rng, raised_from)
    # the sampling error of the measured points the answer interpolates; none for a ceiling
    # beyond the table's range (the total loss: a bound by construction, not a measured point)
    dmap = columns.get("dmap_points")
    se = (_bracketing_se(answering, de) if tab.kind.measured and dmap is not None
          and dmap.status is ColumnStatus.INTERPOLATED else None)
    others: dict[str, SamplingError] = {}
    for col in COLUMNS:
        answer = columns[col]
        if col == "dmap_points" or not tab.kind.measured or answer.status is not \
                ColumnStatus.INTERPOLATED or answer.raised_from is not None:
            continue
        got = _bracketing_se(answered.get(col), de, col)
        if got is not None:
            others[col] = SamplingError(*got)
    return Prediction(
        delta_e=de, size=size, size_used=size_used, columns=columns, table=tab, method=m,
        baseline_map=float(baseline_map) if baseline_map is not None else None,
        transforms=tuple(transform_parameters(de)) if transforms else (),
        dmap_points_se=SamplingError(*se) if se else None,
        column_se=others,
    )


def _bracketing_se(curve: Curve | None, delta_e: float, column: str = "dmap_points"
                   ) -> tuple[float, float] | None:
    """(min, max) SE of ``column`` at the table points next to ``delta_e`` (None: unknown)."""
    ses = None if curve is None else curve.se(column)
    if curve is None or ses is None:
        return None
    x = curve.delta_e
    i = int(np.searchsorted(x, delta_e))  # first point at or above delta_e
    between = 0 < i < len(x) and x[i] != delta_e
    hi = min(i, len(x) - 1)
    se = ses[hi - 1 if between else hi: hi + 1]
    se = se[np.isfinite(se)]
    return (float(se.min()), float(se.max())) if se.size else None


__all__ = [
    "DeltaELimit",
    "Prediction",
    "delta_e_limit",
    "limit_rounded_down",
    "predict",
]
