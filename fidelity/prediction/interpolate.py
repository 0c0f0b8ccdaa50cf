"""A prediction table's curves read at a ΔE: interpolation and the conservative answers.

Interpolation (``method=``, default: the table's ``"interpolation"`` key, else ``"pchip"``):

- ``"pchip"``: monotone piecewise cubic Hermite (Fritsch & Carlson, SIAM J. Numer. Anal. 17,
  1980), ``scipy.interpolate.PchipInterpolator``;
- ``"linear"``: the chord between neighbouring points (an upper bound when the loss is convex in
  ΔE and the points are upper bounds);
- ``"step"``: the next point at or above ΔE (the strictest reading of upper bounds).

Before interpolating, each column is replaced by its running maximum over ΔE (an upper
envelope, so that predictions never decrease with ΔE even if measured points are noisy).
Outside a column's ΔE range the answer is conservative and flagged: below the first point, the
first point's value; above the last, the ceiling: total loss, 100 % relative and, in points, the
baseline itself (:func:`points_ceiling`: the curve's ``baseline_map`` / ``baseline_ap``, else
the detector's baseline mAP given by the caller, else the largest baseline of the table's curves,
else 100 points). Nothing is extrapolated.

Nothing here knows what the axis measures: the curves of :mod:`fidelity.prediction.tablefile`
are read at any value of it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from enum import StrEnum
from typing import Any

import numpy as np

from fidelity.core.errors import unknown_name
from fidelity.core.record import record
from fidelity.prediction.tablefile import (
    CEILING,
    COLUMNS,
    Curve,
    PredictionTable,
    load_prediction_table,
)


def _interp_pchip(x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    from scipy.interpolate import PchipInterpolator

    if len(x) == 1:
        return np.full_like(t, y[0])
    return PchipInterpolator(x, y, extrapolate=False)(t)


def _interp_linear(x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.asarray(np.interp(t, x, y))


def _interp_step(x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(x, t - 1e-12, side="left"), 0, len(x) - 1)
    return y[idx]


#: Interpolation methods, by name (each takes x ascending, y non-decreasing, t inside [x0, xn]).
INTERPOLATIONS: dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]] = {
    "pchip": _interp_pchip,
    "linear": _interp_linear,
    "step": _interp_step,
}


class ColumnStatus(StrEnum):
    """How a column's answer was obtained (see :class:`ColumnPrediction`)."""

    INTERPOLATED = "interpolated"
    BELOW_RANGE = "below-range"
    ABOVE_RANGE = "above-range"
    NO_DATA = "no-data"


@record
class ColumnPrediction:
    """One column's answer: ``value`` and how it was obtained.

    ``status`` is :attr:`ColumnStatus.INTERPOLATED` (inside the column's ΔE range,
    ``delta_e_range``), ``BELOW_RANGE`` (ΔE below the first point: the first point's value, an
    upper bound because loss grows with ΔE), ``ABOVE_RANGE`` (beyond the last point: the
    ceiling, total loss) or ``NO_DATA``. ``raised_from``: for the relative column of a
    published-bounds table given the detector's baseline, the table's value before it was
    raised to ``100 * points / baseline`` (the paper's percent read as points); None when not
    raised.
    """

    value: float | None
    status: ColumnStatus
    delta_e_range: tuple[float, float] | None
    raised_from: float | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``value``, ``status``, ``delta_e_range``, ``raised_from``."""
        return {"value": self.value, "status": self.status.value,
                "delta_e_range": list(self.delta_e_range) if self.delta_e_range else None,
                "raised_from": self.raised_from}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ColumnPrediction:
        """Inverse of :meth:`to_json`."""
        rng = data.get("delta_e_range")
        value = data.get("value")
        raised = data.get("raised_from")
        return cls(None if value is None else float(value), ColumnStatus(str(data["status"])),
                   (float(rng[0]), float(rng[1])) if rng else None,
                   None if raised is None else float(raised))


@record
class SamplingError:
    """The standard error of a measured table's ΔmAP (percentage points) at the table points
    next to a chart ΔE: the smaller (``low``) and the larger (``high``) of the two (equal at a
    table point). From the standard error the sweep recorded per cell
    (:func:`fidelity.coco.loss.loss_estimate`)."""

    low: float
    high: float

    def to_json(self) -> dict[str, float]:
        """``{"low", "high"}`` in percentage points."""
        return {"low": self.low, "high": self.high}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> SamplingError:
        """Inverse of :meth:`to_json`."""
        return cls(float(data["low"]), float(data["high"]))


def points_ceiling(curve: Curve, column: str, curves: Sequence[Curve],
                   baseline_map: float | None = None) -> float:
    """The total-loss ceiling of ``column`` for ``curve`` above its ΔE range.

    Relative columns: 100 %. Points columns: the baseline in percent (losing everything loses
    the baseline): the curve's own (``baseline_map``, ``baseline_ap``); else, for mAP, the
    detector's ``baseline_map`` given by the caller; else the largest of ``curves``' baselines
    (an aggregate curve's models); else 100 points (nothing known).
    """
    if not column.endswith("_points"):
        return CEILING
    own = curve.baseline_points(column)
    if own:
        return own
    if column == "dmap_points" and baseline_map:
        return float(baseline_map)
    known = [b for c in curves if (b := c.baseline_points(column))]
    return max(known) if known else CEILING


def column_values(curve: Curve, column: str, delta_e: np.ndarray, method: str,
                   ceiling: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float] | None]:
    """Values and status codes (0 inside, -1 below, +1 above, 2 no data) of one curve column."""
    y_all = curve.values[column]
    ok = ~np.isnan(y_all)
    if not np.any(ok):
        return np.full(delta_e.shape, np.nan), np.full(delta_e.shape, 2), None
    x = curve.delta_e[ok]
    y = np.maximum.accumulate(y_all[ok])
    lo, hi = float(x[0]), float(x[-1])
    inside = (delta_e >= lo) & (delta_e <= hi)
    out = np.empty(delta_e.shape)
    status = np.zeros(delta_e.shape, dtype=int)
    if np.any(inside):
        out[inside] = INTERPOLATIONS[method](x, y, delta_e[inside])
    below = delta_e < lo
    out[below] = y[0]
    status[below] = -1
    above = delta_e > hi
    out[above] = max(ceiling, float(y[-1]))  # never below the curve (rounded table values)
    status[above] = 1
    return out, status, (lo, hi)


def predict_curve(
    delta_e: Sequence[float] | np.ndarray,
    column: str = "dmap_points",
    *,
    size: str = "any",
    table: PredictionTable | str | None = None,
    method: str | None = None,
) -> np.ndarray:
    """Vectorised worst-case prediction of one ``column`` at every ``delta_e`` (for plots).

    Returns NaN where the table has no data for the column. Values outside the range follow the
    conservative rules of the module docstring.
    """
    tab = table if isinstance(table, PredictionTable) else load_prediction_table(table)
    if column not in COLUMNS:
        raise unknown_name("prediction column", column, COLUMNS)
    m = method or tab.interpolation
    if m not in INTERPOLATIONS:
        raise unknown_name("interpolation method", m, INTERPOLATIONS)
    t = np.atleast_1d(np.asarray(delta_e, dtype=np.float64))
    curves, _ = tab.select(size)
    best = np.full(t.shape, np.nan)
    for c in curves:
        v, _, _ = column_values(c, column, t, m, points_ceiling(c, column, tab.curves))
        best = np.fmax(best, v)
    return best


__all__ = [
    "INTERPOLATIONS",
    "ColumnPrediction",
    "ColumnStatus",
    "SamplingError",
    "column_values",
    "points_ceiling",
    "predict_curve",
]
