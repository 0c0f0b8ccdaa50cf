"""Predict what a chart's colour error costs object detectors: ΔE00 -> ΔmAP, ΔAP person/bicycle.

Prediction tables are JSON files in ``fidelity/data/prediction/<name>.json`` (the registry is
the folder: a table is available as soon as its file is there); the schema is in
``CORE_API.md`` ("Prediction table schema"). Each table holds worst-case curves ΔE -> loss for
detector size classes ``n, s, m, l, x`` or ``any``. Columns:

- ``dmap_points``: percentage points of COCO mAP@[.50:.95], ``100 * (baseline - transformed)``;
- ``dmap_relative``: percent of the baseline mAP, ``100 * (baseline - transformed) / baseline``;
- ``dap_person_points``, ``dap_bicycle_points``: percentage points of the class AP.

The default is ``coco1000-measured``, the project's measured table (``fidelity tables`` from the
COCO sweep: per ΔE the worst case over the ten SAFE-COLOR transforms for four nano detectors on
the shared 1000-image val2017 subset; see reports/coco). ``safecolor-2025`` holds only the
SAFE-COLOR paper's published statements (each point cites its statement), as upper bounds.

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

When a size class has no curve of its own, the ``any`` curve (the worst over all sizes) answers
and the result says so. A size's aggregate curve (``model`` null) answers for it; without one,
when several per-model curves match, the worst (largest) value answers.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import cached_while_unchanged, display_path
from fidelity.core.resources import resource_dir

#: The table used when none is named: the project's measured table (the COCO sweep, issue 5).
DEFAULT_TABLE = "coco1000-measured"

#: Loss columns of a prediction table, in output order.
COLUMNS: tuple[str, ...] = ("dmap_points", "dmap_relative", "dap_person_points",
                            "dap_bicycle_points")
#: Detector size classes (Ultralytics nano ... extra large) and ``any``.
SIZES: tuple[str, ...] = ("n", "s", "m", "l", "x", "any")
#: ``--class`` choices -> the column that measures that class's loss in points.
CLASS_COLUMNS: dict[str, str] = {
    "all": "dmap_points",
    "person": "dap_person_points",
    "bicycle": "dap_bicycle_points",
}
#: Largest possible loss in each column (total loss) when nothing better is known.
CEILING = 100.0



class TableKind(StrEnum):
    """What a prediction table's values are.

    ``published-bounds``: upper bounds read from a publication (the worst case over its
    transforms and detectors); ``measured``: the worst loss measured over the transforms (and
    models) at each ΔE, with sampling error; ``directional``: a measured table that also holds
    per-family curves (:mod:`fidelity.prediction.directional`). The value is the JSON ``kind``.
    """

    PUBLISHED_BOUNDS = "published-bounds"
    MEASURED = "measured"
    DIRECTIONAL = "directional"

    @property
    def upper_bound(self) -> bool:
        """True when the values are upper bounds rather than measured worst cases."""
        return self is TableKind.PUBLISHED_BOUNDS

    @property
    def measured(self) -> bool:
        """True when the values were measured (and carry sampling error)."""
        return self is not TableKind.PUBLISHED_BOUNDS


_KINDS = tuple(k.value for k in TableKind)


def prediction_dir() -> Path:
    """The folder of shipped prediction tables (the registry)."""
    return resource_dir("data") / "prediction"


def available_tables() -> list[str]:
    """Names of the prediction tables in the registry folder, sorted."""
    folder = prediction_dir()
    return sorted(p.stem for p in folder.glob("*.json")) if folder.is_dir() else []


@dataclass(frozen=True)
class Curve:
    """One worst-case curve of a table: ``delta_e`` (n,) and each column's (n,) values
    (NaN where the table has null), for a detector ``size`` and optional ``model``."""

    size: str
    model: str | None
    delta_e: np.ndarray
    values: dict[str, np.ndarray]
    sources: tuple[str, ...]
    worst_transforms: tuple[str | None, ...]
    baseline_map: float | None = None
    #: standard error of ``dmap_points`` at each point (measured tables; NaN where unknown)
    dmap_points_se: np.ndarray | None = None
    #: baseline AP in percent per class column (``dap_person_points`` ...), where known
    baseline_ap: dict[str, float] = field(default_factory=dict)

    def baseline_points(self, column: str) -> float | None:
        """The curve's baseline in percent for a points column (None: unknown or relative)."""
        if column == "dmap_points":
            return self.baseline_map
        return self.baseline_ap.get(column)


@dataclass(frozen=True)
class PredictionTable:
    """A prediction table read from JSON (see the module docstring and CORE_API.md)."""

    name: str
    title: str
    kind: TableKind
    provenance: dict[str, Any]
    units: dict[str, str]
    curves: tuple[Curve, ...]
    interpolation: str = "pchip"
    path: Path | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    def sizes(self) -> list[str]:
        """Size classes that have a curve of their own."""
        return sorted({c.size for c in self.curves}, key=SIZES.index)

    def select(self, size: str = "any") -> tuple[list[Curve], str]:
        """Curves that answer for ``size`` and the size they were made for.

        A size with its own curves gets those; otherwise the ``any`` curves (worst over every
        size); a table without ``any`` curves then answers with all its curves (worst case).
        Among the curves of one size, the table's aggregate curve (``model`` null: its own
        worst case over the models of that size) answers when it has one; per-model curves
        answer (worst of them) only when it has none. A table with neither the size asked
        for nor ``any`` answers with the worst case over the sizes it has, named by them
        (``"n"`` for a table of nano detectors, ``"n,s"`` for two sizes). A per-model curve that covers a narrower
        ΔE range, e.g. a model still being measured, then cannot turn every answer beyond that
        range into the total-loss ceiling.
        """
        if size not in SIZES:
            raise unknown_name("detector size", size, SIZES)

        def preferred(curves: list[Curve]) -> list[Curve]:
            aggregate = [c for c in curves if c.model is None]
            return aggregate or curves

        own = [c for c in self.curves if c.size == size]
        if own:
            return preferred(own), size
        anyc = [c for c in self.curves if c.size == "any"]
        if anyc:
            return preferred(anyc), "any"
        return preferred(list(self.curves)), ",".join(self.sizes())

    @classmethod
    def from_summary(cls, data: Mapping[str, Any]) -> PredictionTable:
        """The table as :meth:`summary` identifies it, without its curves (a prediction read
        back from JSON names its table; :func:`load_prediction_table` gives the curves)."""
        path = data.get("path")
        return cls(name=str(data["name"]), title=str(data.get("title", "")),
                   kind=TableKind(str(data["kind"])),
                   provenance=dict(data.get("provenance") or {}),
                   units=dict(data.get("units") or {}), curves=(),
                   interpolation=str(data.get("interpolation", "pchip")),
                   path=Path(path) if path else None)

    def summary(self) -> dict[str, Any]:
        """JSON-ready identification of the table (name, title, kind, provenance, units)."""
        return {
            "name": self.name,
            "title": self.title,
            "kind": self.kind.value,
            "interpolation": self.interpolation,
            "path": str(self.path) if self.path else None,
            "provenance": self.provenance,
            "units": self.units,
        }


def _distinct_delta_e(curve: Mapping[str, Any]) -> tuple[str, str] | None:
    de = sorted(float(p["delta_e"]) for p in curve["points"])
    if any(b <= a for a, b in zip(de, de[1:], strict=False)):
        return "points", "delta_e values must be distinct numbers >= 0"
    return None


def _some_loss(curve: Mapping[str, Any]) -> tuple[str, str] | None:
    if any(p.get(col) is not None for p in curve["points"] for col in COLUMNS):
        return None
    return "points", f"no loss values: every point lacks {', '.join(COLUMNS)}"


_LOSS = sc.Number(nullable=True)

#: One point of a curve: the chart ΔE and the loss in each column (``null``: not measured).
POINT_SCHEMA = sc.Table(fields=(
    sc.Field("delta_e", sc.Number(lo=0.0), required=True),
    *(sc.Field(col, _LOSS) for col in COLUMNS),
    sc.Field("dmap_points_se", sc.Number(lo=0.0, nullable=True)),
    sc.Field("worst_transform", sc.String(nullable=True)),
    sc.Field("source", sc.AnyValue()),
    sc.Field("partial", sc.Boolean(nullable=True)),
), extra=True)

#: One curve: a detector size (and model), its points and baselines.
CURVE_SCHEMA = sc.Table(fields=(
    sc.Field("size", sc.String(choices=SIZES, ignore_case=False), default="any"),
    sc.Field("model", sc.String(nullable=True)),
    sc.Field("points", sc.ListOf(POINT_SCHEMA, min_items=1), required=True),
    sc.Field("baseline_map", sc.Number(lo=0.0, hi=100.0, nullable=True)),
    sc.Field("baseline_ap", sc.MapOf(sc.Number(lo=0.0, hi=100.0, nullable=True),
                                     nullable=True, describe="an object (class -> AP)")),
), extra=True, rules=(sc.Check(_distinct_delta_e), sc.Check(_some_loss)))

#: A prediction table file (CORE_API.md, "Prediction table schema").
PREDICTION_TABLE_SCHEMA = sc.Table(fields=(
    sc.Field("name", sc.String(nonempty=True), required=True),
    sc.Field("kind", sc.String(choices=_KINDS, ignore_case=False), required=True),
    sc.Field("curves", sc.ListOf(CURVE_SCHEMA, min_items=1), required=True),
    sc.Field("interpolation", sc.String(choices=("pchip", "linear", "step"), ignore_case=False),
             default="pchip"),
    sc.Field("title", sc.String()),
    sc.Field("provenance", sc.MapOf(), default={}),
    sc.Field("units", sc.MapOf(), default={}),
), extra=True)

#: Largest prediction table file read, in bytes.
MAX_TABLE_BYTES = 16 << 20


def _percent(v: float | None) -> float | None:
    """A baseline in percent: a fraction in (0, 1] (pycocotools' scale) is multiplied by 100;
    larger values are taken as percent already."""
    if v is None:
        return None
    return v * 100.0 if v <= 1.0 else v


def _column(points: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    return np.array([math.nan if p.get(key) is None else float(p[key]) for p in points])


def parse_prediction_table(obj: dict[str, Any], origin: str = "<table>") -> PredictionTable:
    """Validate a prediction-table JSON object (:data:`PREDICTION_TABLE_SCHEMA`) and build a
    :class:`PredictionTable`. Raises :class:`~fidelity.core.schema.SchemaError` (an
    :class:`InputFileError`) as ``<origin>: <field>: <problem>``."""
    v = sc.validate(obj, PREDICTION_TABLE_SCHEMA, origin)
    curves = []
    for c in v["curves"]:
        pts = sorted(c["points"], key=lambda p: float(p["delta_e"]))
        ap = c.get("baseline_ap") or {}
        baseline_ap = {col: _percent(ap.get(cls)) for cls, col in CLASS_COLUMNS.items()
                       if cls != "all" and ap.get(cls) is not None}
        curves.append(Curve(
            size=c["size"],
            model=c.get("model"),
            delta_e=_column(pts, "delta_e"),
            values={col: _column(pts, col) for col in COLUMNS},
            sources=tuple(str(p.get("source", "")) for p in pts),
            worst_transforms=tuple(p.get("worst_transform") for p in pts),
            baseline_map=_percent(c.get("baseline_map")),
            baseline_ap={k: val for k, val in baseline_ap.items() if val is not None},
            dmap_points_se=(_column(pts, "dmap_points_se")
                            if any("dmap_points_se" in p for p in pts) else None),
        ))
    return PredictionTable(
        name=str(v["name"]),
        title=str(v.get("title", v["name"])),
        kind=TableKind(str(v["kind"])),
        provenance=dict(v["provenance"]),
        units=dict(v["units"]),
        curves=tuple(curves),
        interpolation=str(v["interpolation"]),
        raw=obj,
    )


def load_prediction_table(name_or_path: str | os.PathLike[str] | None = None) -> PredictionTable:
    """Load a table by registry name (``safecolor-2025``, ...) or from a JSON file path.

    ``None`` loads :data:`DEFAULT_TABLE`. Raises :class:`UnknownNameError` for an unknown name
    and :class:`InputFileError` for an unreadable or malformed file.
    """
    name = DEFAULT_TABLE if name_or_path is None else str(name_or_path)
    path = Path(name)
    if not (path.suffix == ".json" or os.sep in name or "/" in name):
        path = prediction_dir() / f"{name}.json"
        if not path.is_file():
            raise unknown_name("prediction table", name, available_tables())
    if not path.is_file():
        raise InputFileError(f"{display_path(path)}: prediction table does not exist")
    return _load_table_file(path)


@cached_while_unchanged(maxsize=16)
def _load_table_file(path: Path) -> PredictionTable:
    """The table in ``path``, read and validated once a process while the file is unchanged
    (a table is never modified once built)."""
    obj = sc.load_document(path, fmt="json", max_bytes=MAX_TABLE_BYTES,
                           what="prediction table")
    table = parse_prediction_table(obj, display_path(path))
    return PredictionTable(**{**table.__dict__, "path": path})


# --------------------------------------------------------------------------- interpolation

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


@dataclass(frozen=True)
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


@dataclass(frozen=True)
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


def _column_values(curve: Curve, column: str, delta_e: np.ndarray, method: str,
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
        v, _, _ = _column_values(c, column, t, m, points_ceiling(c, column, tab.curves))
        best = np.fmax(best, v)
    return best


@dataclass(frozen=True)
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


@dataclass(frozen=True)
class Prediction:
    """The predicted detection loss for one chart ΔE (see :func:`predict`).

    ``columns`` holds each loss column's answer (:class:`ColumnPrediction`), ``size_used`` the
    detector size class whose curves answered (``any``, or the sizes a table has, comma
    separated, when it has no curve for ``size``), ``dmap_points_se`` the sampling error of a
    measured table around ``delta_e`` (None for published bounds, a table without SEs, or a
    ΔE beyond the table's range, answered by the total loss).
    What the numbers mean in words is written by :mod:`fidelity.report.words`.
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
        Table name, path or object; ``None`` is :data:`DEFAULT_TABLE`.
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
    for col in COLUMNS:
        best_v, best_s, rng = math.nan, 2, None
        for c in curves:
            v, s, r = _column_values(c, col, t, m,
                                     points_ceiling(c, col, tab.curves, baseline_map))
            if r is not None and (math.isnan(best_v) or v[0] > best_v):
                best_v, best_s, rng = float(v[0]), int(s[0]), r
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
    return Prediction(
        delta_e=de, size=size, size_used=size_used, columns=columns, table=tab, method=m,
        baseline_map=float(baseline_map) if baseline_map is not None else None,
        transforms=tuple(transform_parameters(de)) if transforms else (),
        dmap_points_se=SamplingError(*se) if se else None,
    )


def _bracketing_se(curve: Curve | None, delta_e: float) -> tuple[float, float] | None:
    """(min, max) SE of ``dmap_points`` at the table points next to ``delta_e`` (None: unknown)."""
    if curve is None or curve.dmap_points_se is None:
        return None
    x = curve.delta_e
    i = int(np.searchsorted(x, delta_e))  # first point at or above delta_e
    between = 0 < i < len(x) and x[i] != delta_e
    hi = min(i, len(x) - 1)
    se = curve.dmap_points_se[hi - 1 if between else hi: hi + 1]
    se = se[np.isfinite(se)]
    return (float(se.min()), float(se.max())) if se.size else None


@dataclass(frozen=True)
class TransformParameter:
    """The parameter of one SAFE-COLOR transform that gives chart ΔE ``delta_e``.

    ``param`` is None when ``reachable`` is False; ``method`` says how it was found
    (``calibrated``, ``solved``, ``interpolated``) or why it is unreachable; ``bracket`` holds
    the two calibrated (ΔE, parameter) points around ``delta_e``, when there are two.
    """

    transform: str
    delta_e: float
    param: float | None
    reachable: bool
    method: str | None
    bracket: tuple[tuple[float, float], tuple[float, float]] | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form (``bracket`` as two ``{"delta_e", "param"}`` objects)."""
        return {"transform": self.transform, "delta_e": self.delta_e, "param": self.param,
                "reachable": self.reachable, "method": self.method,
                "bracket": None if self.bracket is None else
                [{"delta_e": e, "param": q} for e, q in self.bracket]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TransformParameter:
        """Inverse of :meth:`to_json`."""
        b = data.get("bracket")
        param = data.get("param")
        return cls(str(data["transform"]), float(data["delta_e"]),
                   None if param is None else float(param), bool(data["reachable"]),
                   data.get("method"),
                   None if not b else ((float(b[0]["delta_e"]), float(b[0]["param"])),
                                       (float(b[1]["delta_e"]), float(b[1]["param"]))))


def transform_parameters(delta_e: float, calibration: Any = None, *,
                         solve: bool = True) -> list[TransformParameter]:
    """The SAFE-COLOR transform parameters that give chart ΔE ``delta_e``, one per transform.

    From the shipped calibration table (``fidelity.prediction.calibration.load_calibration_table()``): at
    a calibrated target, the table's parameter (``method: "calibrated"``). Between targets the
    table's two bracketing entries are given (``bracket``) and the parameter is solved on the
    chart for this exact ΔE (``fidelity.prediction.calibration.calibrate_transform``, ``method: "solved"``),
    or, with ``solve=False``, interpolated linearly in ΔE between the bracket
    (``method: "interpolated"``; below the first target the identity at the chart's baseline ΔE
    is the lower end). A ΔE below the chart's baseline or beyond a transform's reach is
    reported as unreachable (``param: null``), not as a number.
    """
    if calibration is None:
        from fidelity.prediction.calibration import load_calibration_table

        calibration = load_calibration_table()
    from fidelity.prediction.transforms import TRANSFORMS

    baseline = float(calibration.baseline_delta_e)
    by_transform: dict[str, list[Any]] = {}
    for e in calibration.entries:
        by_transform.setdefault(e.transform, []).append(e)
    out: list[TransformParameter] = []
    for name, entries in by_transform.items():
        entries = sorted(entries, key=lambda e: float(e.target))
        spec = TRANSFORMS.get(name)
        nodes: list[tuple[float, float]] = []
        if spec is not None:
            nodes.append((baseline, float(spec.identity)))
        unreachable_from = None
        for e in entries:
            if e.reachable and e.param is not None:
                nodes.append((float(e.target), float(e.param)))
            elif unreachable_from is None:
                unreachable_from = float(e.target)
        row: dict[str, Any] = {"transform": name, "delta_e": delta_e, "param": None,
                               "reachable": False, "method": None, "bracket": None}
        exact = [e for e in entries if abs(float(e.target) - delta_e) < 1e-9]
        below = [n for n in nodes if n[0] <= delta_e]
        above = [n for n in nodes if n[0] >= delta_e]
        if below and above:
            row["bracket"] = [{"delta_e": below[-1][0], "param": below[-1][1]},
                              {"delta_e": above[0][0], "param": above[0][1]}]
        if exact and exact[0].reachable and exact[0].param is not None:
            row.update(param=float(exact[0].param), reachable=True, method="calibrated",
                       bracket=None)
        elif delta_e <= baseline:
            row.update(method=f"unreachable: at or below the chart's baseline ΔE {baseline:.4g}")
        elif solve:
            from fidelity.prediction.calibration import calibrate_transform

            entry = calibrate_transform(name, delta_e)
            if entry.reachable and entry.param is not None:
                row.update(param=float(entry.param), reachable=True, method="solved")
            else:
                row.update(method=f"unreachable: the transform reaches at most ΔE "
                                  f"{entry.delta_e:.4g}")
        elif row["bracket"] and (unreachable_from is None or delta_e < unreachable_from):
            (e0, p0), (e1, p1) = below[-1], above[0]
            p = p0 if e1 == e0 else p0 + (p1 - p0) * (delta_e - e0) / (e1 - e0)
            row.update(param=float(p), reachable=True, method="interpolated")
        else:
            row.update(method="unreachable within the transform's range")
        out.append(TransformParameter(
            name, float(row["delta_e"]), row["param"], row["reachable"], row["method"],
            None if row["bracket"] is None else (
                (float(row["bracket"][0]["delta_e"]), float(row["bracket"][0]["param"])),
                (float(row["bracket"][1]["delta_e"]), float(row["bracket"][1]["param"])))))
    return out


__all__ = [
    "CEILING",
    "CLASS_COLUMNS",
    "COLUMNS",
    "DEFAULT_TABLE",
    "INTERPOLATIONS",
    "PREDICTION_TABLE_SCHEMA",
    "SIZES",
    "ColumnPrediction",
    "ColumnStatus",
    "Curve",
    "DeltaELimit",
    "Prediction",
    "PredictionTable",
    "SamplingError",
    "TableKind",
    "TransformParameter",
    "available_tables",
    "delta_e_limit",
    "load_prediction_table",
    "parse_prediction_table",
    "predict",
    "predict_curve",
    "prediction_dir",
    "transform_parameters",
]
