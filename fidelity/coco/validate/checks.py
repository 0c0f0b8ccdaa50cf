"""Predicted against measured loss, cell by cell: the bound checks and their summaries.

For one (camera, detector) cell, the loss measured against the detector's baseline (ΔmAP in
points and relative, ΔAP of person and bicycle, with standard errors:
:func:`fidelity.coco.loss.score_loss`) is set beside what every prediction table predicts at
the camera's chart value (:func:`predictions_for`); the bound table's prediction bounds the
cell when the measured loss is at most the predicted one (:class:`BoundCheck`: within, and
within 2 SE). :func:`class_summary` counts the cells and cameras within per class. Nothing
here knows which property the chart value measures; it is named ``chart_delta_e``, colour's
axis, as the prediction tables' is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fidelity.coco.loss import LOSS_COLUMNS, Losses, score_loss
from fidelity.coco.validate.store import ValidationCell
from fidelity.core.record import record
from fidelity.prediction.table import predict

#: Classes compared (``all`` = mAP@[.50:.95] over the 80 COCO classes).
CLASSES: tuple[str, ...] = ("all", "person", "bicycle")


#: Key order of the measured losses' standard errors in ``validation.json``.
_SE_KEYS = ("dmap_points", "dap_person_points", "dap_bicycle_points", "dmap_relative")


@record
class TablePrediction:
    """What one prediction table predicts for a camera (:func:`predictions_for`): the
    ``losses`` (points; relative in %), each column's ``status`` and the table's ``kind``."""

    losses: Losses
    status: dict[str, str]
    kind: str

    def to_json(self) -> dict[str, Any]:
        """The losses' keys, then ``status`` and ``kind``."""
        return self.losses.to_json() | {"status": self.status, "kind": self.kind}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TablePrediction:
        """Inverse of :meth:`to_json`."""
        return cls(Losses.from_json(d), dict(d.get("status") or {}), d["kind"])


@record
class BoundCheck:
    """Whether a measured loss is within the worst-case prediction for one class.

    ``within`` is None when either value is missing (then nothing else is set); otherwise
    ``within`` = measured <= predicted, ``excess`` = measured − predicted, ``se`` the
    measurement's standard error, ``within_2se`` = measured − 2 SE <= predicted (None without
    SE) and ``status`` where on the table the prediction came from.
    """

    predicted: float | None
    measured: float | None
    within: bool | None
    se: float | None = None
    excess: float | None = None
    within_2se: bool | None = None
    status: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The check as ``validation.json`` holds it (three keys when not judged)."""
        if self.within is None:
            return {"predicted": self.predicted, "measured": self.measured, "within": None}
        return {"predicted": self.predicted, "measured": self.measured, "se": self.se,
                "within": self.within, "excess": self.excess, "within_2se": self.within_2se,
                "status": self.status}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BoundCheck:
        """Inverse of :meth:`to_json`."""
        return cls(d.get("predicted"), d.get("measured"), d.get("within"), d.get("se"),
                   d.get("excess"), d.get("within_2se"), d.get("status"))


@record
class ValidationRow:
    """Predicted against measured loss of one (camera, model) cell (:func:`validation_row`).

    Scores are fractions; ``measured`` and ``se`` are :class:`fidelity.coco.loss.Losses`
    (points, relative in %) against the model's ΔE = 0 baseline; ``predicted``: per table its
    :class:`TablePrediction`; ``bound``: per class of :data:`fidelity.coco.loss.LOSS_COLUMNS`
    the :class:`BoundCheck` of the bound table.
    """

    camera: str
    model: str
    illuminant: str
    chart_delta_e: float
    images: int
    baseline_map: float
    map: float
    baseline_ap: dict[str, float | None]
    ap: dict[str, float | None]
    measured: Losses
    se: Losses
    predicted: dict[str, TablePrediction]
    bound: dict[str, BoundCheck]

    def to_json(self) -> dict[str, Any]:
        """The row as ``validation.json`` holds it."""
        return {"camera": self.camera, "model": self.model, "illuminant": self.illuminant,
                "chart_delta_e": self.chart_delta_e, "images": self.images,
                "baseline_map": self.baseline_map, "map": self.map,
                "baseline_ap": self.baseline_ap, "ap": self.ap,
                "measured": self.measured.to_json(), "se": self.se.to_json(_SE_KEYS),
                "predicted": {t: p.to_json() for t, p in self.predicted.items()},
                "bound": {c: b.to_json() for c, b in self.bound.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationRow:
        """Inverse of :meth:`to_json`."""
        return cls(d["camera"], d["model"], d["illuminant"], d["chart_delta_e"],
                   int(d["images"]), d["baseline_map"], d["map"], dict(d["baseline_ap"]),
                   dict(d["ap"]), Losses.from_json(d["measured"]), Losses.from_json(d["se"]),
                   {t: TablePrediction.from_json(p) for t, p in d["predicted"].items()},
                   {c: BoundCheck.from_json(b) for c, b in d["bound"].items()})


@record
class ClassSummary:
    """How often the bound holds for one class: judged ``cells``, ``within`` and
    ``within_2se`` of them; ``cameras`` judged and ``cameras_within`` (every model within),
    their share (None without cameras) and the ``(camera, model)`` ``failures``."""

    cells: int
    within: int
    within_2se: int
    cameras: int
    cameras_within: int
    share_cameras_within: float | None
    failures: tuple[tuple[str, str], ...]

    def to_json(self) -> dict[str, Any]:
        """The summary as ``validation.json`` holds it."""
        return {"cells": self.cells, "within": self.within, "within_2se": self.within_2se,
                "cameras": self.cameras, "cameras_within": self.cameras_within,
                "share_cameras_within": self.share_cameras_within,
                "failures": [list(f) for f in self.failures]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ClassSummary:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["cells"]), int(d["within"]), int(d["within_2se"]), int(d["cameras"]),
                   int(d["cameras_within"]), d.get("share_cameras_within"),
                   tuple((str(c), str(m)) for c, m in d.get("failures") or ()))


@record
class ValidationSummary:
    """The bound ``bound_table`` tested, the ``tables`` evaluated, stored cameras left out
    (``not_in_suite``) and per class of :data:`fidelity.coco.loss.LOSS_COLUMNS` its
    :class:`ClassSummary`; ``standard_error``: how the measured losses' SEs were computed,
    ``"larger"``, ``"bootstrap"``, ``"jackknife"``, ``"folds"`` or ``"mixed"``
    (:data:`fidelity.coco.tables.provenance.STANDARD_ERROR_WORDS`)."""

    bound_table: str
    tables: tuple[str, ...]
    not_in_suite: tuple[str, ...]
    classes: dict[str, ClassSummary]
    standard_error: str = "folds"

    def to_json(self) -> dict[str, Any]:
        """``{"bound_table", "tables", "not_in_suite", "standard_error", <class>: ...}``."""
        return {"bound_table": self.bound_table, "tables": list(self.tables),
                "not_in_suite": list(self.not_in_suite),
                "standard_error": self.standard_error} | {
                    c: s.to_json() for c, s in self.classes.items()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationSummary:
        """Inverse of :meth:`to_json`."""
        return cls(d["bound_table"], tuple(d["tables"]), tuple(d.get("not_in_suite") or ()),
                   {c: ClassSummary.from_json(d[c]) for c in LOSS_COLUMNS if c in d},
                   d.get("standard_error", "folds"))


def predictions_for(delta_e: float, baseline_map_percent: float | None,
                    tables: Sequence[str], size: str = "n") -> dict[str, TablePrediction]:
    """What every prediction table predicts at chart ``delta_e``: table -> prediction."""
    out = {}
    for t in tables:
        p = predict(delta_e, size=size, table=t, baseline_map=baseline_map_percent,
                    transforms=False)
        out[t] = TablePrediction(
            Losses(*(p.columns[col].value for col in LOSS_COLUMNS.values())),
            {col: p.columns[col].status for col in LOSS_COLUMNS.values()}, p.table.kind)
    return out


def bound_check(predicted: float | None, measured: float | None, se: float | None,
                status: str) -> BoundCheck:
    """The :class:`BoundCheck` of a ``measured`` loss (standard error ``se``) against its
    ``predicted`` bound, answered with ``status`` on the table (not judged when either is
    missing)."""
    if predicted is None or measured is None:
        return BoundCheck(predicted, measured, None)
    return BoundCheck(predicted, measured, measured <= predicted, se, measured - predicted,
                      (measured - 2 * se) <= predicted if se is not None else None, status)


def validation_row(camera: str, illuminant: str, chart_delta_e: float, b: ValidationCell,
                   c: ValidationCell, tables: Sequence[str], bound: str
                   ) -> tuple[ValidationRow, str | None]:
    """Predicted (by every table of ``tables`` at the camera's ``chart_delta_e``) against
    measured loss of one cell ``c`` against its baseline ``b``
    (:func:`fidelity.coco.loss.score_loss`), judged by the ``bound`` table, and how the mAP
    loss's SE was computed (``se_method``; None: no SE)."""
    measured, se, se_method = measured_losses(b, c)
    pred = predictions_for(chart_delta_e, 100.0 * b.map, tables)
    checks = {cls: bound_check(pred[bound].losses.get(col), measured.get(col), se.get(col),
                               pred[bound].status[col])
              for cls, col in LOSS_COLUMNS.items()}
    row = ValidationRow(camera, c.model, illuminant, chart_delta_e, c.images,
                        b.map, c.map, {k: b.ap.get(k) for k in ("person", "bicycle")},
                        {k: c.ap.get(k) for k in ("person", "bicycle")}, measured, se, pred,
                        checks)
    return row, se_method


def measured_losses(b: ValidationCell, c: ValidationCell) -> tuple[Losses, Losses, str | None]:
    """The losses of cell ``c`` against its baseline ``b`` (ΔmAP in points and relative, ΔAP
    of person and bicycle; :func:`fidelity.coco.loss.score_loss`), their standard errors and
    how the mAP loss's SE was computed (None: no SE)."""
    base: dict[str, float | None] = {"map": b.map, **b.ap}
    cell: dict[str, float | None] = {"map": c.map, **c.ap}
    loss, person, bicycle = (score_loss(k, base, cell, b.folds, c.folds, b.draws, c.draws)
                             for k in ("map", "person", "bicycle"))
    measured = Losses(loss.points, loss.relative, person.points, bicycle.points)
    se = Losses(loss.points_se, loss.relative_se, person.points_se, bicycle.points_se)
    return measured, se, loss.se_method


def class_summary(rows: Sequence[ValidationRow], cls: str) -> ClassSummary:
    """How often the bound holds for class ``cls`` over the judged ``rows``."""
    judged = [r for r in rows if r.bound[cls].within is not None]
    ok = [r for r in judged if r.bound[cls].within]
    ok2 = [r for r in judged if r.bound[cls].within_2se]
    cams = sorted({r.camera for r in judged})
    cams_ok = [k for k in cams if all(r.bound[cls].within for r in judged if r.camera == k)]
    return ClassSummary(len(judged), len(ok), len(ok2), len(cams), len(cams_ok),
                        len(cams_ok) / len(cams) if cams else None,
                        tuple((r.camera, r.model) for r in judged if not r.bound[cls].within))


__all__ = [
    "CLASSES",
    "BoundCheck",
    "ClassSummary",
    "TablePrediction",
    "ValidationRow",
    "ValidationSummary",
    "bound_check",
    "class_summary",
    "measured_losses",
    "predictions_for",
    "validation_row",
]
