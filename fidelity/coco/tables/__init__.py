"""Worst-case tables from a sweep store, the paper comparison and the measured prediction table.

Definitions (all derived from the finished cells of :mod:`fidelity.coco.sweep`):

* ΔmAP in points: ``dmap_points = 100 * (mAP_baseline - mAP_cell)`` (percentage points of
  COCO mAP@[.50:.95]); relative: ``dmap_relative = 100 * (mAP_baseline - mAP_cell) /
  mAP_baseline`` (percent of the baseline mAP). The baseline is the same model on the same
  images decoded and re-encoded without transform (ΔE 0). The same for ΔAP of person and bicycle.
* Worst case of a model at ΔE: the transform with the largest ``dmap_points`` among the
  finished, reachable cells at that ΔE (``worst_transform``). Person and bicycle columns are
  worst cases of their own (the largest ΔAP over the same transforms), so each column is an
  upper envelope over transforms, as a prediction bound needs.
* Worst case of a size class (n, s, m, l, x): the largest value over the models of that size.
* A row lists how many transforms were finished at its ΔE (``transforms_done`` of
  ``transforms_reachable``); rows with missing transforms are marked partial.

Paper comparison (SAFE-COLOR findings, ``shared/reference/safecolor.md``) is computed by
:func:`compare_with_paper` from the same numbers. The records (:class:`CellDelta`,
:class:`WorstCaseRow`, :class:`SizeClassRow`, :class:`Tables`, :class:`TablesResult`, ...)
are frozen dataclasses; ``to_json``/``from_json`` write and read them as ``tables.json`` holds
them. The report (Markdown, HTML, plots) is :mod:`fidelity.report.coco`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
from fidelity.coco.loss import loss_estimate
from fidelity.coco.store import RegisteredModel
from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import json_ready, portable_paths

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepCell, SweepStore

#: Classes called safety-critical by SAFE-COLOR.
SAFETY_CLASSES: tuple[str, ...] = ("person", "bicycle")

#: Classes with at most this many ground-truth boxes in a model's images count as rare.
RARE_BOXES = 5


# --------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CellErrors:
    """Standard errors of a cell's losses (:func:`add_standard_errors`): ΔmAP in points and
    relative (% of baseline), ΔAP of person and bicycle in points; None with fewer than 2
    usable draws or folds. ``method`` (of ΔmAP's): ``"larger"`` (the larger of the paired image
    bootstrap and the jackknife of the whole-run loss), ``"bootstrap"`` (the bootstrap alone),
    ``"jackknife"`` (leave-one-fold-out; tables measured before the bootstrap) or ``"folds"``
    (paired fold SE; tables measured before the jackknife)
    (:func:`fidelity.coco.loss.loss_estimate`)."""

    dmap_points: float | None
    dmap_relative: float | None
    dap_person_points: float | None
    dap_bicycle_points: float | None
    method: str | None = "folds"


@dataclass(frozen=True)
class CellDelta:
    """One transformed cell of a model against its baseline (:func:`cell_deltas`).

    ``status`` ``"done"`` or ``"unreachable"``; a done cell has ``map``, ``map50`` (fractions)
    and the losses: ``dmap_points`` (percentage points), ``dmap_relative`` (% of the baseline
    mAP) and per safety class its AP (``ap_person``, fraction) and ΔAP (points, relative);
    None where the baseline or the cell has no value. ``errors``: standard errors, when
    computed.
    """

    model: str
    transform: str
    delta_e: float
    param: float | None
    status: str
    reason: str | None
    images: int | None
    map: float | None = None
    map50: float | None = None
    dmap_points: float | None = None
    dmap_relative: float | None = None
    ap_person: float | None = None
    dap_person_points: float | None = None
    dap_person_relative: float | None = None
    ap_bicycle: float | None = None
    dap_bicycle_points: float | None = None
    dap_bicycle_relative: float | None = None
    errors: CellErrors | None = None

    @property
    def done(self) -> bool:
        """Whether the cell was scored (not unreachable)."""
        return self.status == "done"

    def dap_points(self, cls: str) -> float | None:
        """ΔAP of safety class ``cls`` (``"person"``, ``"bicycle"``) in points."""
        return {"person": self.dap_person_points, "bicycle": self.dap_bicycle_points}[cls]

    def dap_relative(self, cls: str) -> float | None:
        """ΔAP of safety class ``cls`` in % of its baseline AP."""
        return {"person": self.dap_person_relative, "bicycle": self.dap_bicycle_relative}[cls]

    def to_json(self) -> dict[str, Any]:
        """The cell as ``tables.json`` holds it (score keys only for a done cell, ``*_se`` keys
        only with standard errors)."""
        d: dict[str, Any] = {"model": self.model, "transform": self.transform,
                             "delta_e": self.delta_e, "param": self.param,
                             "status": self.status, "reason": self.reason,
                             "images": self.images}
        if self.done:
            d |= {"map": self.map, "map50": self.map50, "dmap_points": self.dmap_points,
                  "dmap_relative": self.dmap_relative, "ap_person": self.ap_person,
                  "dap_person_points": self.dap_person_points,
                  "dap_person_relative": self.dap_person_relative,
                  "ap_bicycle": self.ap_bicycle, "dap_bicycle_points": self.dap_bicycle_points,
                  "dap_bicycle_relative": self.dap_bicycle_relative}
        if self.errors is not None:
            e = self.errors
            d |= {"dmap_points_se": e.dmap_points, "dmap_relative_se": e.dmap_relative,
                  "dap_person_points_se": e.dap_person_points,
                  "dap_bicycle_points_se": e.dap_bicycle_points, "se_method": e.method}
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CellDelta:
        """Inverse of :meth:`to_json`."""
        errors = None
        if "dmap_points_se" in d:
            errors = CellErrors(d["dmap_points_se"], d.get("dmap_relative_se"),
                                d.get("dap_person_points_se"), d.get("dap_bicycle_points_se"),
                                d.get("se_method", "folds"))
        return cls(d["model"], d["transform"], float(d["delta_e"]), d.get("param"),
                   d["status"], d.get("reason"), d.get("images"), d.get("map"), d.get("map50"),
                   d.get("dmap_points"), d.get("dmap_relative"), d.get("ap_person"),
                   d.get("dap_person_points"), d.get("dap_person_relative"),
                   d.get("ap_bicycle"), d.get("dap_bicycle_points"),
                   d.get("dap_bicycle_relative"), errors)


@dataclass(frozen=True)
class RareShare:
    """How much of a worst-case ΔmAP comes from rare classes (:func:`rare_class_shares`):
    ``dmap_points_rare`` (points), from ``rare_classes`` of the ``classes`` scored."""

    dmap_points_rare: float
    rare_classes: int
    classes: int


@dataclass(frozen=True)
class WorstCaseRow:
    """The worst case over transforms at one ΔE for one model (:func:`worst_case_rows`).

    ``dmap_points`` is the worst transform's ΔmAP (points), ``dmap_relative`` and ``map`` the
    same cell's; the ΔAP columns are each their own worst case over the transforms done.
    ``transforms_done`` of ``transforms_reachable`` were finished (``partial`` when fewer);
    ``unreachable`` lists the transforms that cannot reach this ΔE. The first row of a model
    is its baseline (ΔE 0, no worst transform, no losses).
    """

    delta_e: float
    worst_transform: str | None
    dmap_points: float
    dmap_relative: float | None
    map: float
    dap_person_points: float | None
    dap_bicycle_points: float | None
    dap_person_relative: float | None
    dap_bicycle_relative: float | None
    transforms_done: int
    transforms_reachable: int
    unreachable: tuple[str, ...]
    partial: bool
    dmap_points_se: float | None = None
    dmap_relative_se: float | None = None
    rare: RareShare | None = None

    @property
    def is_baseline(self) -> bool:
        """Whether this is the ΔE 0 row (no transform)."""
        return self.worst_transform is None

    def to_json(self) -> dict[str, Any]:
        """The row as ``tables.json`` holds it (the baseline row has no ``*_se`` keys)."""
        if self.is_baseline:
            return {"delta_e": self.delta_e, "worst_transform": None,
                    "dmap_points": self.dmap_points, "dmap_relative": self.dmap_relative,
                    "dap_person_points": self.dap_person_points,
                    "dap_bicycle_points": self.dap_bicycle_points,
                    "dap_person_relative": self.dap_person_relative,
                    "dap_bicycle_relative": self.dap_bicycle_relative, "map": self.map,
                    "transforms_done": self.transforms_done,
                    "transforms_reachable": self.transforms_reachable,
                    "unreachable": list(self.unreachable), "partial": self.partial}
        d: dict[str, Any] = {
            "delta_e": self.delta_e, "worst_transform": self.worst_transform,
            "dmap_points": self.dmap_points, "dmap_relative": self.dmap_relative,
            "dmap_points_se": self.dmap_points_se, "dmap_relative_se": self.dmap_relative_se,
            "map": self.map, "dap_person_points": self.dap_person_points,
            "dap_bicycle_points": self.dap_bicycle_points,
            "dap_person_relative": self.dap_person_relative,
            "dap_bicycle_relative": self.dap_bicycle_relative,
            "transforms_done": self.transforms_done,
            "transforms_reachable": self.transforms_reachable,
            "unreachable": list(self.unreachable), "partial": self.partial}
        if self.rare is not None:
            d |= {"dmap_points_rare": self.rare.dmap_points_rare,
                  "rare_classes": self.rare.rare_classes, "classes": self.rare.classes}
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WorstCaseRow:
        """Inverse of :meth:`to_json`."""
        rare = None
        if "dmap_points_rare" in d:
            rare = RareShare(d["dmap_points_rare"], int(d["rare_classes"]), int(d["classes"]))
        return cls(float(d["delta_e"]), d.get("worst_transform"), d["dmap_points"],
                   d.get("dmap_relative"), d["map"], d.get("dap_person_points"),
                   d.get("dap_bicycle_points"), d.get("dap_person_relative"),
                   d.get("dap_bicycle_relative"), int(d["transforms_done"]),
                   int(d["transforms_reachable"]), tuple(d.get("unreachable") or ()),
                   bool(d["partial"]), d.get("dmap_points_se"), d.get("dmap_relative_se"), rare)


@dataclass(frozen=True)
class SizeClassRow:
    """The worst case over the models of one size class at one ΔE (:func:`size_class_rows`).

    ``worst_model``/``worst_transform`` give the largest ``dmap_points``; the other loss
    columns are each their own maximum over the ``models`` models used (``model_names``: the
    models complete at this ΔE, or all when none is, then ``partial``).
    """

    delta_e: float
    worst_model: str
    worst_transform: str | None
    dmap_points: float
    dmap_points_se: float | None
    dmap_relative: float | None
    dap_person_points: float | None
    dap_bicycle_points: float | None
    models: int
    model_names: tuple[str, ...]
    partial: bool

    def to_json(self) -> dict[str, Any]:
        """The row as ``tables.json`` holds it."""
        return {"delta_e": self.delta_e, "worst_model": self.worst_model,
                "worst_transform": self.worst_transform, "dmap_points": self.dmap_points,
                "dmap_points_se": self.dmap_points_se, "dmap_relative": self.dmap_relative,
                "dap_person_points": self.dap_person_points,
                "dap_bicycle_points": self.dap_bicycle_points, "models": self.models,
                "model_names": list(self.model_names), "partial": self.partial}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SizeClassRow:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["delta_e"]), d["worst_model"], d.get("worst_transform"),
                   d["dmap_points"], d.get("dmap_points_se"), d.get("dmap_relative"),
                   d.get("dap_person_points"), d.get("dap_bicycle_points"), int(d["models"]),
                   tuple(d.get("model_names") or ()), bool(d["partial"]))


@dataclass(frozen=True)
class ModelSummary:
    """A swept model in the tables: its store registration (None if it was never registered),
    size class, baseline scores (fractions) and the image count its cells are reported on."""

    registration: RegisteredModel | None
    size: str
    baseline_map: float
    baseline_map50: float
    baseline_ap: dict[str, float | None]
    images: int

    @property
    def settings(self) -> dict[str, Any]:
        """The detector's provenance settings (empty without a registration)."""
        return self.registration.settings if self.registration is not None else {}

    def to_json(self) -> dict[str, Any]:
        """The registration's keys followed by the summary's."""
        reg = self.registration.to_json() if self.registration is not None else {}
        return reg | {"size": self.size, "baseline_map": self.baseline_map,
                      "baseline_map50": self.baseline_map50, "baseline_ap": self.baseline_ap,
                      "images": self.images}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ModelSummary:
        """Inverse of :meth:`to_json`."""
        reg = RegisteredModel.from_json(d) if "file" in d else None
        return cls(reg, d["size"], d["baseline_map"], d["baseline_map50"],
                   dict(d.get("baseline_ap") or {}), int(d["images"]))


@dataclass(frozen=True)
class AlignedCount:
    """The image count a model's cells are reported on (:func:`align_image_counts`):
    ``images``; the counts its cells were ``stored`` on; how many cells were ``rescored`` from
    their stored detections; whether ``--images`` asked for it (``capped``)."""

    images: int
    stored: tuple[int, ...]
    rescored: int
    capped: bool

    def to_json(self) -> dict[str, Any]:
        """``{"images", "stored", "rescored", "capped"}``."""
        return {"images": self.images, "stored": list(self.stored), "rescored": self.rescored,
                "capped": self.capped}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> AlignedCount:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["images"]), tuple(int(x) for x in d["stored"]), int(d["rescored"]),
                   bool(d["capped"]))


@dataclass(frozen=True)
class Tables:
    """Everything the report needs from a sweep store (:func:`build_tables`).

    ``models``: per model its :class:`ModelSummary`; ``cells``: per model every transformed
    cell (:class:`CellDelta`); ``worst_case``: per model its :class:`WorstCaseRow` per ΔE;
    ``size_classes``: per size class its :class:`SizeClassRow` per ΔE; ``meta``: the store's
    provenance (JSON) with its ``scorers``; ``transforms``: planned and seen transforms;
    ``cells_done``, ``cells_unreachable``; ``standard_errors``: whether SEs were computed;
    ``aligned``: per model its :class:`AlignedCount` (with annotations only); ``rare_boxes``:
    the rare-class threshold of :class:`RareShare` (None without annotations).
    """

    models: dict[str, ModelSummary]
    cells: dict[str, tuple[CellDelta, ...]]
    worst_case: dict[str, tuple[WorstCaseRow, ...]]
    size_classes: dict[str, tuple[SizeClassRow, ...]]
    meta: dict[str, Any]
    transforms: tuple[str, ...]
    cells_done: int
    cells_unreachable: int
    standard_errors: bool
    aligned: dict[str, AlignedCount]
    rare_boxes: int | None

    def to_json(self) -> dict[str, Any]:
        """The ``tables`` object of ``tables.json``."""
        return {
            "models": {m: v.to_json() for m, v in self.models.items()},
            "cells": {m: [r.to_json() for r in rows] for m, rows in self.cells.items()},
            "worst_case": {m: [r.to_json() for r in rows]
                           for m, rows in self.worst_case.items()},
            "size_classes": {s: [r.to_json() for r in rows]
                             for s, rows in self.size_classes.items()},
            "meta": self.meta, "transforms": list(self.transforms),
            "cells_done": self.cells_done, "cells_unreachable": self.cells_unreachable,
            "standard_errors": self.standard_errors,
            "aligned": {m: a.to_json() for m, a in self.aligned.items()},
            "rare_boxes": self.rare_boxes,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Tables:
        """Inverse of :meth:`to_json`."""
        return cls(
            {m: ModelSummary.from_json(v) for m, v in d["models"].items()},
            {m: tuple(CellDelta.from_json(r) for r in rows) for m, rows in d["cells"].items()},
            {m: tuple(WorstCaseRow.from_json(r) for r in rows)
             for m, rows in d["worst_case"].items()},
            {s: tuple(SizeClassRow.from_json(r) for r in rows)
             for s, rows in d["size_classes"].items()},
            dict(d.get("meta") or {}), tuple(d["transforms"]), int(d["cells_done"]),
            int(d["cells_unreachable"]), bool(d.get("standard_errors")),
            {m: AlignedCount.from_json(a) for m, a in (d.get("aligned") or {}).items()},
            d.get("rare_boxes"))


@dataclass(frozen=True)
class PaperFinding:
    """One SAFE-COLOR finding checked against our measurements (:func:`compare_with_paper`):
    the ``claim``, our ``verdict`` ("agrees", "disagrees", "not enough data", qualified) and
    the ``evidence`` in words and numbers."""

    claim: str
    verdict: str
    evidence: str

    def to_json(self) -> dict[str, str]:
        """``{"claim", "verdict", "evidence"}``."""
        return {"claim": self.claim, "verdict": self.verdict, "evidence": self.evidence}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PaperFinding:
        """Inverse of :meth:`to_json`."""
        return cls(d["claim"], d["verdict"], d["evidence"])


@dataclass(frozen=True)
class BudgetLimit:
    """The largest chart ΔE (None: none) whose predicted loss in ``column`` stays within
    ``budget``; ``status`` as :class:`fidelity.prediction.table.DeltaELimit` says it."""

    column: str
    budget: float
    delta_e: float | None
    status: str

    def to_json(self) -> dict[str, Any]:
        """``{"column", "budget", "delta_e", "status"}``."""
        return {"column": self.column, "budget": self.budget, "delta_e": self.delta_e,
                "status": self.status}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BudgetLimit:
        """Inverse of :meth:`to_json`."""
        return cls(d["column"], float(d["budget"]), d.get("delta_e"), d["status"])


@dataclass(frozen=True)
class CurveLimits:
    """The ΔE limits of one curve of the measured table (:func:`delta_e_limits`): a size
    class's worst case (``model`` None) or one model's."""

    size: str
    model: str | None
    limits: tuple[BudgetLimit, ...]

    def to_json(self) -> dict[str, Any]:
        """``{"size", "model", "limits"}``."""
        return {"size": self.size, "model": self.model,
                "limits": [x.to_json() for x in self.limits]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CurveLimits:
        """Inverse of :meth:`to_json`."""
        return cls(d["size"], d.get("model"),
                   tuple(BudgetLimit.from_json(x) for x in d["limits"]))


@dataclass(frozen=True)
class TablesResult:
    """What ``fidelity tables`` computes: the :class:`Tables`, the paper comparison and the
    ΔE limits; :meth:`to_json` is ``tables.json``."""

    tables: Tables
    comparison: tuple[PaperFinding, ...]
    limits: tuple[CurveLimits, ...]

    def to_json(self) -> dict[str, Any]:
        """``{"tables", "comparison", "delta_e_limits"}`` (strict JSON values)."""
        out: dict[str, Any] = json_ready({
            "tables": self.tables.to_json(), "comparison": [c.to_json() for c in self.comparison],
            "delta_e_limits": [x.to_json() for x in self.limits]})
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TablesResult:
        """Inverse of :meth:`to_json` (reads ``tables.json``)."""
        return cls(Tables.from_json(d["tables"]),
                   tuple(PaperFinding.from_json(c) for c in d["comparison"]),
                   tuple(CurveLimits.from_json(x) for x in d.get("delta_e_limits") or ()))


@dataclass(frozen=True)
class ClassShare:
    """One class's part of a cell's ΔmAP (:func:`class_breakdown`): its non-crowd ground-truth
    ``boxes``, AP of the baseline and of the cell (fractions), ``dap_points`` = 100 (AP₀ − AP)
    and ``share_points`` = ``dap_points`` / K (K classes scored)."""

    name: str
    boxes: int
    ap_baseline: float
    ap: float
    dap_points: float
    share_points: float

    def to_json(self) -> dict[str, Any]:
        """``{"name", "boxes", "ap_baseline", "ap", "dap_points", "share_points"}``."""
        return {"name": self.name, "boxes": self.boxes, "ap_baseline": self.ap_baseline,
                "ap": self.ap, "dap_points": self.dap_points, "share_points": self.share_points}


@dataclass(frozen=True)
class ShareGroup:
    """A group of classes (rare or common) in :class:`CellExplanation`: how many, their mean
    ΔAP (points; None for none) and the points of ΔmAP they account for."""

    classes: int
    mean_dap_points: float | None
    share_points: float

    def to_json(self) -> dict[str, Any]:
        """``{"classes", "mean_dap_points", "share_points"}``."""
        return {"classes": self.classes, "mean_dap_points": self.mean_dap_points,
                "share_points": self.share_points}


@dataclass(frozen=True)
class CellExplanation:
    """Which classes one stored cell's ΔmAP comes from (:func:`explain_cell`)."""

    model: str
    transform: str
    delta_e: float
    images: int
    dmap_points: float
    rare_boxes: int
    rare: ShareGroup
    common: ShareGroup
    classes: tuple[ClassShare, ...]

    def to_json(self) -> dict[str, Any]:
        """The breakdown as ``fidelity tables --explain --json`` writes it."""
        return {"model": self.model, "transform": self.transform, "delta_e": self.delta_e,
                "images": self.images, "dmap_points": self.dmap_points,
                "rare_boxes": self.rare_boxes, "rare": self.rare.to_json(),
                "common": self.common.to_json(), "classes": [c.to_json() for c in self.classes]}


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def model_size(model: str) -> str:
    """Size class of a model from its name: nano/n -> "n", ... , else "any".

    ``yolo11n-int8dyn`` -> n, ``yolov8s`` -> s, ``yolox_nano`` -> n, ``yolox_tiny`` -> n.
    """
    m = model.lower()
    if "nano" in m or "tiny" in m:
        return "n"
    hit = re.search(r"(?:yolo(?:v\d+|\d+|x)?)[-_]?([nsmlx])(?:\b|[-_.]|u|$)", m)
    return hit.group(1) if hit else "any"


def _delta(base: float | None, value: float | None) -> tuple[float | None, float | None]:
    """(points, relative) loss of ``value`` against ``base``
    (:func:`fidelity.coco.loss.loss_estimate`)."""
    loss = loss_estimate(base, value)
    return loss.points, loss.relative


def _value(x: float | None) -> float:
    """A value a finished cell always has (its score, its loss)."""
    if x is None:
        raise ValueError("a finished cell without a score")
    return x


def cell_deltas(cells: Sequence[SweepCell]) -> dict[str, list[CellDelta]]:
    """Per model: every transformed cell with its ΔmAP and ΔAP (points and relative).

    Cells of a model without a finished baseline are left out, and so are done cells scored on
    another number of images than their model's baseline (a sweep caught while extending a
    model's image limit): a ΔmAP needs both scores on the same images.
    """
    by_model: dict[str, list[CellDelta]] = {}
    base = {c.model: c for c in cells if c.transform == "baseline" and c.done}
    for c in cells:
        if c.transform == "baseline" or c.model not in base:
            continue
        b = base[c.model]
        if c.done and c.images != b.images:
            continue
        row = CellDelta(c.model, c.transform, float(c.target), c.param, c.status, c.reason,
                        c.images)
        if c.done:
            b_ap, c_ap = b.ap or {}, c.ap or {}
            pts, rel = _delta(b.map, c.map)
            person = _delta(b_ap.get("person"), c_ap.get("person"))
            bicycle = _delta(b_ap.get("bicycle"), c_ap.get("bicycle"))
            row = replace(row, map=c.map, map50=c.map50, dmap_points=pts, dmap_relative=rel,
                          ap_person=c_ap.get("person"), dap_person_points=person[0],
                          dap_person_relative=person[1], ap_bicycle=c_ap.get("bicycle"),
                          dap_bicycle_points=bicycle[0], dap_bicycle_relative=bicycle[1])
        by_model.setdefault(c.model, []).append(row)
    return by_model


def parse_image_caps(spec: str | None, models: Sequence[str]) -> dict[str, int]:
    """``"500"`` (every model) or ``"yolov8n-int8dyn=500,yolov10n-int8dyn=500"`` -> model -> N.

    Raises :class:`fidelity.core.errors.InvalidValueError` naming the entry for a count that is not
    a positive integer or a model the store does not hold.
    """
    from fidelity.core.errors import InvalidValueError

    caps: dict[str, int] = {}
    for entry in (spec or "").split(","):
        entry = entry.strip()
        if not entry:
            continue
        model, _, count = entry.rpartition("=")
        try:
            n = int(count)
        except ValueError:
            n = 0
        if n < 1:
            raise InvalidValueError(f"--images {entry!r}: expected N or MODEL=N with N a "
                                    "positive integer")
        if not model:
            caps |= {m: n for m in models}
        elif model not in models:
            raise InvalidValueError(f"--images {entry!r}: no model {model!r} in the store "
                                    f"(it holds {', '.join(sorted(models)) or 'none'})")
        else:
            caps[model] = n
    return caps


def align_image_counts(store: SweepStore, coco: Any, cells: Sequence[SweepCell],
                       method: str = "auto", progress: bool = False,
                       images: Mapping[str, int] | None = None
                       ) -> tuple[list[SweepCell], dict[str, AlignedCount]]:
    """Every done cell of a model scored on the same images: the first N by image id.

    N is the fewest images any done cell of the model (baseline included) was scored on, or
    ``images[model]`` where that is fewer (a report on an earlier state of a sweep that has
    moved on). A sweep caught while extending a model's image limit (``model.onnx@N`` raised)
    holds cells on the old and on the new count; the cells on more images are re-scored here
    on the first N from their stored detections (no inference; the store is not changed), so
    that every ΔmAP pairs a cell with its baseline on the same images and no row of the
    worst-case table is left partial. Returns the cells (re-scored ones carry
    ``rescored_from``, their stored count) and per model its :class:`AlignedCount`.
    """
    from tqdm import tqdm

    from fidelity.coco.scoring import evaluate_detections, resolve_scorer

    method = resolve_scorer(method)
    ids_all = sorted(coco.getImgIds())
    counts: dict[str, set[int]] = {}
    for c in cells:
        if c.done and c.images:
            counts.setdefault(c.model, set()).add(int(c.images))
    common = {m: min(n) for m, n in counts.items()}
    caps = dict(images or {})
    capped = {m for m in common if m in caps and caps[m] < common[m]}
    common |= {m: caps[m] for m in capped}
    todo = [c for c in cells if c.done and c.images and c.images > common[c.model]]
    rescored: dict[int, SweepCell] = {}
    for c in tqdm(todo, desc="aligning image counts", unit="cell", disable=not progress):
        ids = ids_all[: common[c.model]]
        s = evaluate_detections(coco, store.detections(c.model, c.transform, c.target), ids,
                                method=method)
        rescored[id(c)] = replace(c, map=s.map, map50=s.map50, map75=s.map75, ap=s.ap,
                                  images=s.images, rescored_from=c.images)
    out = [rescored.get(id(c), c) for c in cells]
    info = {m: AlignedCount(common[m], tuple(sorted(counts[m])),
                            sum(c.model == m for c in todo), m in capped)
            for m in common}
    return out, info


def _max_or_none(values: Sequence[float | None]) -> float | None:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return max(v) if v else None


def worst_case_rows(rows: Sequence[CellDelta], baseline: SweepCell,
                    transforms: Sequence[str] | None = None) -> list[WorstCaseRow]:
    """Worst case over transforms at each ΔE for one model (see module docstring)."""
    by_de: dict[float, list[CellDelta]] = {}
    for r in rows:
        by_de.setdefault(r.delta_e, []).append(r)
    out = [WorstCaseRow(0.0, None, 0.0, 0.0, _value(baseline.map), 0.0, 0.0, 0.0, 0.0, 0, 0,
                        (), False)]
    for de in sorted(by_de):
        group = by_de[de]
        done = [r for r in group if r.done]
        unreachable = tuple(sorted(r.transform for r in group if r.status == "unreachable"))
        if not done:
            continue
        worst = max(done, key=lambda r: _value(r.dmap_points))
        reachable = (len(transforms) - len(unreachable)) if transforms else len(done)
        se = worst.errors
        out.append(WorstCaseRow(
            delta_e=de, worst_transform=worst.transform, dmap_points=_value(worst.dmap_points),
            dmap_relative=worst.dmap_relative, map=_value(worst.map),
            dap_person_points=_max_or_none([r.dap_person_points for r in done]),
            dap_bicycle_points=_max_or_none([r.dap_bicycle_points for r in done]),
            dap_person_relative=_max_or_none([r.dap_person_relative for r in done]),
            dap_bicycle_relative=_max_or_none([r.dap_bicycle_relative for r in done]),
            transforms_done=len(done), transforms_reachable=reachable, unreachable=unreachable,
            partial=len(done) < reachable,
            dmap_points_se=se.dmap_points if se is not None else None,
            dmap_relative_se=se.dmap_relative if se is not None else None,
        ))
    return out


def size_class_rows(per_model: Mapping[str, Sequence[WorstCaseRow]]
                    ) -> dict[str, list[SizeClassRow]]:
    """Worst case over the models of each size class, per ΔE."""
    groups: dict[str, list[str]] = {}
    for m in per_model:
        groups.setdefault(model_size(m), []).append(m)
    out: dict[str, list[SizeClassRow]] = {}
    for size, models in sorted(groups.items()):
        des = sorted({r.delta_e for m in models for r in per_model[m]})
        rows = []
        for de in des:
            at_de = [(m, r) for m in models for r in per_model[m] if r.delta_e == de]
            # The worst case over the models whose row at this ΔE is complete (every reachable
            # transform measured); a partial row could understate it. Only when no model is
            # complete does the row fall back to the partial ones (and is marked partial).
            complete = [(m, r) for m, r in at_de if not r.partial]
            cand = complete or at_de
            m, w = max(cand, key=lambda mr: mr[1].dmap_points)
            rows.append(SizeClassRow(
                delta_e=de, worst_model=m, worst_transform=w.worst_transform,
                dmap_points=w.dmap_points, dmap_points_se=w.dmap_points_se,
                dmap_relative=_max_or_none([r.dmap_relative for _, r in cand]),
                dap_person_points=_max_or_none([r.dap_person_points for _, r in cand]),
                dap_bicycle_points=_max_or_none([r.dap_bicycle_points for _, r in cand]),
                models=len(cand), model_names=tuple(mm for mm, _ in cand),
                partial=not complete))
        out[size] = rows
    return out


def class_breakdown(coco: Any, baseline: Mapping[int, np.ndarray], cell: Mapping[int, np.ndarray],
                    image_ids: Sequence[int], method: str = "auto") -> list[ClassShare]:
    """Which classes a cell's ΔmAP comes from: per class ΔAP and its share of the ΔmAP.

    COCO mAP@[.50:.95] is the unweighted mean of the per-class APs over the K classes that have
    ground truth in the evaluated images (COCO evaluation, Lin et al. 2014; classes without
    ground truth are skipped), so ΔmAP = Σ_c ΔAP_c / K: a class with one box weighs as much as
    person with thousands, and one detection ranked below a false positive halves that class's
    AP. ``baseline``, ``cell``: per-image (K, 6) detections (:mod:`fidelity.coco.sweep` store);
    ``image_ids``: the images both are scored on. Returns one :class:`ClassShare` per class
    with ground truth, sorted by share, largest loss first. The shares sum to the ΔmAP in
    points.
    """
    from fidelity.coco.scoring import evaluate_detections

    ids = sorted(int(i) for i in image_ids)
    b = evaluate_detections(coco, baseline, ids, method=method)
    c = evaluate_detections(coco, cell, ids, method=method)
    return _breakdown(b.ap, c.ap, box_counts(coco, ids))


def box_counts(coco: Any, image_ids: Sequence[int]) -> dict[str, int]:
    """Non-crowd ground-truth boxes per class name in the images ``image_ids``."""
    from collections import Counter

    return dict(Counter(coco.cats[a["category_id"]]["name"]
                        for a in coco.loadAnns(coco.getAnnIds(imgIds=list(image_ids)))
                        if not a.get("iscrowd")))


def _breakdown(ap_base: Mapping[str, float | None], ap_cell: Mapping[str, float | None],
               boxes: Mapping[str, int]) -> list[ClassShare]:
    pairs = [(n, b, c) for n, b in ap_base.items()
             if b is not None and (c := ap_cell.get(n)) is not None]
    rows = [ClassShare(n, int(boxes.get(n, 0)), b, c, 100.0 * (b - c),
                       100.0 * (b - c) / len(pairs)) for n, b, c in pairs]
    return sorted(rows, key=lambda r: (-r.share_points, r.name))


def rare_class_shares(coco: Any, per_model: Mapping[str, Sequence[WorstCaseRow]],
                      cells: Sequence[SweepCell], baselines: Mapping[str, SweepCell],
                      rare_boxes: int = RARE_BOXES) -> dict[str, list[WorstCaseRow]]:
    """The worst-case rows with their :class:`RareShare` (``rare``).

    ``dmap_points_rare``: the points of the row's ΔmAP that come from classes with at most
    ``rare_boxes`` ground-truth boxes in the model's images (:func:`class_breakdown` of the
    worst transform's cell against the baseline, from the per-class APs the cells were scored
    with, so that the shares add up to the row's ΔmAP); ``rare_classes`` of ``classes`` such
    classes. COCO mAP weighs every present class alike, so on a few hundred images these rows
    can be moved by one re-ranked detection of a one-box class.
    """
    ids_all = sorted(coco.getImgIds())
    ap = {(c.model, c.transform, c.target): c.ap or {} for c in cells if c.done}
    boxes = {m: box_counts(coco, ids_all[: b.images]) for m, b in baselines.items()}
    out: dict[str, list[WorstCaseRow]] = {}
    for m, rows in per_model.items():
        out[m] = []
        for r in rows:
            if r.delta_e <= 0 or not r.worst_transform:
                out[m].append(r)
                continue
            shares = _breakdown(baselines[m].ap or {},
                                ap[(m, r.worst_transform, float(r.delta_e))], boxes[m])
            rare = [x for x in shares if x.boxes <= rare_boxes]
            out[m].append(replace(r, rare=RareShare(float(sum(x.share_points for x in rare)),
                                                    len(rare), len(shares))))
    return out


def explain_cell(store: SweepStore, coco: Any, model: str, transform: str, target: float, *,
                 images: int | None = None, rare_boxes: int = RARE_BOXES,
                 method: str = "auto") -> CellExplanation:
    """:func:`class_breakdown` of one stored cell against its model's baseline.

    Both are scored from their stored detections on the first N images by id: N = ``images``,
    at most the smaller of the two cells' counts, which is the default (a report built while
    the model's limit is raised uses the model's common count: pass it to compare). ``rare``
    and ``common`` split the classes at ``rare_boxes`` ground-truth boxes: how many classes,
    their mean ΔAP and the points of ΔmAP they account for. Raises
    :class:`~fidelity.core.errors.InvalidValueError` naming the cell when it or the baseline is not
    a finished cell of the store.
    """
    from fidelity.core.errors import InvalidValueError

    found: dict[str, SweepCell] = {}
    for t, e in ((transform, float(target)), ("baseline", 0.0)):
        rec = store.cell(model, t, e)
        if rec is None or not rec.done:
            have = sorted({x.model for x in store.cells()})
            state = "not in the store" if rec is None else rec.status
            raise InvalidValueError(f"cell {model} {t} ΔE {e:g}: {state} (models: "
                                    f"{', '.join(have) or 'none'})")
        found[t] = rec
    n = min(int(found[transform].images or 0), int(found["baseline"].images or 0))
    if images is not None:
        if not 0 < images <= n:
            raise InvalidValueError(f"cell {model} {transform} ΔE {float(target):g}: --images "
                                    f"{images} is not in 1..{n} (images stored for the cell "
                                    "and its baseline)")
        n = int(images)
    ids = sorted(coco.getImgIds())[:n]
    rows = class_breakdown(coco, store.detections(model, "baseline", 0.0),
                           store.detections(model, transform, float(target)), ids, method)

    def part(sel: list[ClassShare]) -> ShareGroup:
        return ShareGroup(len(sel),
                          float(np.mean([r.dap_points for r in sel])) if sel else None,
                          float(sum(r.share_points for r in sel)))

    return CellExplanation(model, transform, float(target), n,
                           float(sum(r.share_points for r in rows)), rare_boxes,
                           part([r for r in rows if r.boxes <= rare_boxes]),
                           part([r for r in rows if r.boxes > rare_boxes]), tuple(rows))


def add_standard_errors(store: SweepStore, coco: Any, deltas: Mapping[str, Sequence[CellDelta]],
                        baselines: Mapping[str, SweepCell], method: str = "auto",
                        progress: bool = False) -> dict[str, list[CellDelta]]:
    """The rows with their :class:`CellErrors` (done cells).

    Standard errors of each whole-run loss: the larger of the paired image bootstrap
    (:func:`fidelity.coco.bootstrap.draw_scores`: 200 draws, fixed seed; the baseline and the
    cell scored on the same draws) and the leave-one-fold-out jackknife over
    :data:`fidelity.coco.scoring.FOLDS` interleaved image folds
    (:func:`fidelity.coco.loss.loss_estimate`; no relative SE for a baseline mAP of 0). Both
    are computed from the stored detections (no inference) and cached in the store; ``method``:
    the COCO scorer of the fold scores (the bootstrap's one evaluation is pycocotools').
    """
    from tqdm import tqdm

    from fidelity.coco.bootstrap import Draws
    from fidelity.coco.loss import score_loss
    from fidelity.coco.scoring import FoldScore

    ids_all = sorted(coco.getImgIds())
    todo = [(m, r) for m, rows in deltas.items() for r in rows if r.done]
    base_draws: dict[str, Draws] = {}
    base_folds: dict[str, list[FoldScore]] = {}
    errors: dict[int, CellErrors] = {}
    for m, r in tqdm(todo, desc="standard errors", unit="cell", disable=not progress):
        ids = ids_all[: baselines[m].images]
        if m not in base_draws:
            base_draws[m] = store.draw_scores(coco, m, "baseline", 0.0, ids)
            base_folds[m] = store.fold_scores(coco, m, "baseline", 0.0, ids, method)
        draws = store.draw_scores(coco, m, r.transform, r.delta_e, ids)
        folds = store.fold_scores(coco, m, r.transform, r.delta_e, ids, method)

        b = baselines[m]
        base: dict[str, float | None] = {"map": b.map, **(b.ap or {})}
        cell: dict[str, float | None] = {"map": r.map, "person": r.ap_person,
                                         "bicycle": r.ap_bicycle}
        loss, person, bicycle = (score_loss(k, base, cell, base_folds[m], folds,
                                            base_draws[m], draws)
                                 for k in ("map", "person", "bicycle"))
        errors[id(r)] = CellErrors(loss.points_se, loss.relative_se, person.points_se,
                                   bicycle.points_se, loss.se_method)
    return {m: [replace(r, errors=errors[id(r)]) if id(r) in errors else r for r in rows]
            for m, rows in deltas.items()}


def build_tables(store: SweepStore, coco: Any = None, *, method: str = "auto",
                 progress: bool = False, images: Mapping[str, int] | None = None) -> Tables:
    """Everything the report needs, from a :class:`fidelity.coco.sweep.SweepStore`.

    ``coco``: the sweep's annotations (pycocotools ``COCO``); when given, every model's cells
    are scored on one image count (:func:`align_image_counts`; ``images`` caps it per model)
    and every done cell gets standard errors (:func:`add_standard_errors`).
    Without it, cells scored on another image count than their baseline are left out
    (:func:`cell_deltas`), there are no SEs, and ``images`` is an error.
    """
    cells = store.cells()
    if not cells:
        raise InputFileError(f"{store.path}: the sweep store has no finished cells yet")
    models = store.models()
    aligned: dict[str, AlignedCount] = {}
    if images and coco is None:
        from fidelity.core.errors import InvalidValueError

        raise InvalidValueError("--images needs the COCO annotations, to re-score cells on "
                                "fewer images: pass --annotations")
    if coco is not None:
        cells, aligned = align_image_counts(store, coco, cells, method, progress, images)
    deltas = cell_deltas(cells)
    baselines = {c.model: c for c in cells if c.transform == "baseline" and c.done}
    if coco is not None:
        deltas = add_standard_errors(store, coco, deltas, baselines, method, progress)
    meta = store.meta()
    grid = meta.get("grid") or {}
    planned = grid.get("transforms")
    if not planned:
        from fidelity.prediction.transforms import TRANSFORMS

        planned = list(TRANSFORMS)
    seen = {c.transform for c in cells if c.transform != "baseline"}
    transforms = sorted(set(planned) | seen)
    per_model = {m: worst_case_rows(rows, baselines[m], transforms)
                 for m, rows in deltas.items()}
    for m in baselines:
        per_model.setdefault(m, worst_case_rows([], baselines[m], transforms))
    if coco is not None:
        per_model = rare_class_shares(coco, per_model, cells, baselines)
    return Tables(
        models={m: ModelSummary(models.get(m), model_size(m), _value(b.map), _value(b.map50),
                                {k: (b.ap or {}).get(k) for k in SAFETY_CLASSES},
                                int(b.images or 0))
                for m, b in baselines.items()},
        cells={m: tuple(rows) for m, rows in deltas.items()},
        worst_case={m: tuple(rows) for m, rows in per_model.items()},
        size_classes={s: tuple(rows) for s, rows in size_class_rows(per_model).items()},
        meta=meta | {"scorers": store.scorers()},
        transforms=tuple(transforms),
        cells_done=sum(c.done for c in cells),
        cells_unreachable=sum(c.status == "unreachable" for c in cells),
        standard_errors=coco is not None,
        aligned=aligned,
        rare_boxes=RARE_BOXES if coco is not None else None,
    )


#: What a kept model's measurement record holds of the tables' meta that measured it.
RUN_KEYS = ("versions", "machine", "machines", "scorers", "imported")


def record_by_name(record: Mapping[str, Any]) -> dict[str, Any]:
    """A file record (``file``, ``sha256``) with its file by name alone: tables of older
    versions recorded a path on their machine, which names the machine, not the data."""
    return dict(record) | ({"file": Path(str(record["file"])).name} if record.get("file") else {})


def earlier_runs(prev: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The measurement records an earlier merge kept (``runs``); a record of an older version,
    one for all its kept models with at most one ``via``, as one run."""
    if not prev:
        return []
    if "runs" in prev:
        return [dict(r) for r in prev["runs"]]
    via = prev.get("via")
    run = {k: v for k, v in record_by_name(prev).items() if k != "via"}
    return [run | ({"via": [record_by_name(via)]} if via else {})]


def runs_passed_on(runs: Sequence[Mapping[str, Any]], models: Sequence[str],
                   via: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The ``runs`` that measured some of ``models``, each narrowed to those, with ``via``
    (files passed through since, newest last) extended."""
    passed = []
    for run in runs:
        mine = [m for m in models if m in (run.get("models") or ())]
        if mine:
            through = [*(run.get("via") or []), *via]
            passed.append(dict(run) | {"models": mine} | ({"via": through} if through else {}))
    return passed


def _kept_provenance(kept: Sequence[str], earlier: Tables, source: Mapping[str, Any]
                     ) -> dict[str, Any]:
    """Where the kept models were measured: ``source`` (the earlier tables' file and SHA-256)
    and the kept models, with ``runs``, one record per run that measured some of them: the
    earlier tables' own store for the models it measured (the file by name, with that store's
    versions, machine(s), scorers and imported scores files), and for the models it had kept
    itself the records it carried, each with ``via`` naming the files it has passed through
    since. So a model kept through several merges is still named with the machine and
    versions that measured it."""
    carried = earlier_runs(earlier.meta.get("earlier") or {})
    carried_models = {m for r in carried for m in r.get("models") or ()}
    runs: list[dict[str, Any]] = []
    own = [m for m in kept if m not in carried_models]
    if own:
        runs.append(record_by_name(source) | {"models": own} | {
            k: earlier.meta[k] for k in RUN_KEYS if earlier.meta.get(k) is not None})
    runs += runs_passed_on(carried, kept, [record_by_name(source)])
    return dict(source) | {"models": list(kept), "runs": runs}


def merge_tables(tables: Tables, earlier: Tables, source: Mapping[str, Any]) -> Tables:
    """``tables`` (from a store) with the models of an ``earlier`` tables.json it does not hold.

    For re-measuring some detectors and keeping the others as they were measured: every model
    of ``tables`` replaces its namesake in ``earlier``; the kept models bring their own rows,
    cells, image alignment and registration (hence their recorded preprocessing and settings,
    which the prediction table's provenance carries per model). The size classes are the
    worst case over the merged models again. ``meta["earlier"]`` names what was kept and where
    it came from: ``source`` (e.g. the file's name and SHA-256) and, per run that measured
    some of the kept models (``runs``), that run's ``versions``, ``machine(s)``, ``scorers``
    and imported scores files, through any number of merges.

    Both must be measured on the same images (``meta["data"]``: image count and the file names
    of the image folder and annotations) and, where both have one, with the same rare-class
    threshold, else :class:`~fidelity.core.errors.InvalidValueError`. Standard errors count only
    where both have them.
    """
    from pathlib import PurePath

    from fidelity.core.errors import InvalidValueError

    def data_key(meta: Mapping[str, Any]) -> tuple[Any, ...]:
        d = meta.get("data") or {}
        return (d.get("image_count"), PurePath(str(d.get("images") or "")).name,
                PurePath(str(d.get("annotations") or "")).name)

    if data_key(tables.meta) != data_key(earlier.meta):
        raise InvalidValueError(
            f"{source.get('file', 'the earlier tables')}: measured on other images "
            f"({data_key(earlier.meta)}) than the store ({data_key(tables.meta)}); tables of "
            "different image sets cannot be merged")
    if None not in (tables.rare_boxes, earlier.rare_boxes) and \
            tables.rare_boxes != earlier.rare_boxes:
        raise InvalidValueError(
            f"{source.get('file', 'the earlier tables')}: rare-class threshold "
            f"{earlier.rare_boxes} against the store's {tables.rare_boxes}")
    kept = [m for m in earlier.models if m not in tables.models]
    if not kept:
        return tables
    worst = dict(tables.worst_case) | {m: earlier.worst_case[m] for m in kept
                                       if m in earlier.worst_case}
    kept_rows = [r for m in kept for r in earlier.cells.get(m, ())]
    return Tables(
        models=dict(tables.models) | {m: earlier.models[m] for m in kept},
        cells=dict(tables.cells) | {m: earlier.cells[m] for m in kept if m in earlier.cells},
        worst_case=worst,
        size_classes={s: tuple(rows) for s, rows in size_class_rows(worst).items()},
        meta=tables.meta | {"earlier": _kept_provenance(kept, earlier, source)},
        transforms=tuple(sorted(set(tables.transforms) | set(earlier.transforms))),
        # a kept model's baseline is a done cell too (the rows are its transformed cells)
        cells_done=tables.cells_done + len(kept) + sum(r.done for r in kept_rows),
        cells_unreachable=tables.cells_unreachable
        + sum(r.status == "unreachable" for r in kept_rows),
        standard_errors=tables.standard_errors and earlier.standard_errors,
        aligned=dict(tables.aligned) | {m: earlier.aligned[m] for m in kept
                                        if m in earlier.aligned},
        rare_boxes=tables.rare_boxes if tables.rare_boxes is not None else earlier.rare_boxes,
    )


def tables_result(store: SweepStore, coco: Any = None, *, progress: bool = False,
                  images: Mapping[str, int] | None = None,
                  earlier: tuple[Tables, Mapping[str, Any]] | None = None) -> TablesResult:
    """:func:`build_tables` with its paper comparison and ΔE limits (``tables.json``);
    ``earlier``: (tables, source) whose models the store does not hold are kept
    (:func:`merge_tables`)."""
    tables = build_tables(store, coco, progress=progress, images=images)
    if earlier is not None:
        tables = merge_tables(tables, *earlier)
    return TablesResult(tables, tuple(compare_with_paper(tables)),
                        tuple(delta_e_limits(tables)))


# --------------------------------------------------------------------------------------------
# Paper comparison
# --------------------------------------------------------------------------------------------


def _loss_and_se(r: WorstCaseRow, key: str) -> tuple[float | None, float | None]:
    """A worst-case row's loss ``key`` (``dmap_points`` or ``dmap_relative``) and its SE."""
    if key == "dmap_points":
        return r.dmap_points, r.dmap_points_se
    return r.dmap_relative, r.dmap_relative_se


def _beyond_noise(rows: Sequence[WorstCaseRow], key: str, bound: float) -> bool:
    """Whether some row's ``key`` exceeds ``bound`` by more than 2 of its standard errors
    (a row without an SE counts when it exceeds at all)."""
    for r in rows:
        v, se = _loss_and_se(r, key)
        if v is not None and v > bound + (2 * se if se else 0.0):
            return True
    return False


def _threshold_verdict(rows: Sequence[WorstCaseRow], bound: float) -> str:
    """The verdict on "worst-case ΔmAP stays below ``bound`` %" over worst-case ``rows``.

    The paper's "%" may be points or a share of the baseline, so both are tested: "agrees" if
    every relative loss is below the bound; "agrees if read as points" if only the points are;
    else "disagrees". Each exceedance is qualified "within 2 SE" where no row exceeds the
    bound by more than twice its standard error in that unit, else "beyond 2 SE" (the worst
    case over ten noisy transforms is biased upwards by about one SE); without standard
    errors, unqualified.
    """
    rel = max((r.dmap_relative or 0.0) for r in rows)
    pts = max((r.dmap_points or 0.0) for r in rows)
    if rel < bound:
        return "agrees"

    def by(key: str) -> str:
        if not any(_loss_and_se(r, key)[1] for r in rows):  # no standard errors: no qualifier
            return ""
        return " (beyond 2 SE)" if _beyond_noise(rows, key, bound) else " (within 2 SE)"

    if pts < bound:
        return f"agrees if read as points; exceeded as a share of baseline{by('dmap_relative')}"
    return (f"disagrees: exceeded in points{by('dmap_points')} and as a share of "
            f"baseline{by('dmap_relative')}")


#: SAFE-COLOR's thresholds: worst-case ΔmAP below ``bound`` % up to chart ΔE ``limit``.
PAPER_THRESHOLDS: tuple[tuple[int, float], ...] = ((3, 1.0), (6, 3.0), (12, 10.0))

#: Transforms SAFE-COLOR names as the worst up to ΔE 24.
PAPER_WORST: frozenset[str] = frozenset({"contrast-inc", "contrast-dec", "saturation-inc"})


def compare_with_paper(tables: Tables) -> list[PaperFinding]:
    """Check the SAFE-COLOR findings against our measurements; one :class:`PaperFinding` each.

    Verdicts are "agrees", "disagrees" or "not enough data" (qualified where the data are
    incomplete or the exceedance is within the noise).
    """
    cells = [r for rows in tables.cells.values() for r in rows if r.done]
    out = _ranking_findings(tables, cells)
    out += _worst_transform_findings(tables, cells)
    out += _threshold_findings(tables)
    out += _safety_class_findings(cells)
    return out


def _ranking_findings(tables: Tables, cells: Sequence[CellDelta]) -> list[PaperFinding]:
    """Harm ranking, per model: mean relative ΔmAP per transform over the ΔE values <= 12
    (every transform reaches them on the chart) at which that model has all transforms; the
    overall ranking averages the per-model means."""
    planned = list(tables.transforms)
    vals: dict[tuple[str, str, float], float] = {
        (r.model, r.transform, r.delta_e): r.dmap_relative for r in cells
        if r.dmap_relative is not None}
    per_model: dict[str, dict[str, float]] = {}
    used: dict[str, list[float]] = {}
    for m in sorted(tables.cells):
        common = sorted(d for d in {k[2] for k in vals if k[0] == m}
                        if d <= 12 and all((m, t, d) in vals for t in planned))
        if common and max(common) >= 6:  # at ΔE < 6 losses are within the scatter
            used[m] = common
            per_model[m] = {t: float(np.mean([vals[(m, t, d)] for d in common]))
                            for t in planned}
    most = "contrast increase and decrease hurt detection most"
    least = "hue changes hurt least"
    if not per_model:
        return [PaperFinding(claim, "not enough data",
                             "no model has all transforms at a ΔE in 6..12 yet")
                for claim in (most, least)]
    mean = {t: float(np.mean([pm[t] for pm in per_model.values()])) for t in planned}
    order = sorted(mean, key=mean.__getitem__, reverse=True)
    ranks = {m: sorted(pm, key=pm.__getitem__, reverse=True) for m, pm in per_model.items()}
    ev = ", ".join(f"{t} {mean[t]:.2f} %" for t in order)
    lists = {m: ", ".join(f"{d:g}" for d in ds) for m, ds in used.items()}
    if len(set(lists.values())) == 1:
        which = "every model" if len(used) > 1 else next(iter(used))
        where = f"mean relative ΔmAP ({which} at ΔE {next(iter(lists.values()))}): "
    else:
        where = ("mean relative ΔmAP ("
                 + "; ".join(f"{m} at ΔE {lists[m]}" for m in used) + "): ")
    top = {"contrast-inc", "contrast-dec"}
    per = "; ".join(f"{m}: top two {', '.join(r[:2])}, mildest {r[-1]}"
                    for m, r in ranks.items())
    return [
        PaperFinding(most, "agrees" if set(order[:2]) == top
                     else "partly agrees" if set(order[:2]) & top else "disagrees",
                     where + ev + ". Per model: " + per),
        PaperFinding(least, "agrees" if order[-1] == "hue" else "disagrees",
                     f"mildest: {order[-1]} ({mean[order[-1]]:.2f} %); hue "
                     f"{mean['hue']:.2f} %, rank {order.index('hue') + 1} of "
                     f"{len(order)} (1 = most harmful)") if "hue" in mean else
        PaperFinding(least, "not enough data", "the sweep has no hue cells (transforms "
                     f"swept: {', '.join(order)})"),
    ]


def noise_floor(cells: Sequence[CellDelta]) -> tuple[float | None, list[float]]:
    """The smallest ΔE measured and the relative ΔmAP of every done cell there: the scatter
    that any small perturbation of the images causes on this image set."""
    low_de = min((r.delta_e for r in cells if r.done), default=None)
    low = [r.dmap_relative for r in cells if r.done and r.delta_e == low_de
           and r.dmap_relative is not None]
    return low_de, low


def _worst_transform_findings(tables: Tables, cells: Sequence[CellDelta]
                              ) -> list[PaperFinding]:
    """The worst transform, only where the worst loss stands out of the scatter: twice the sd
    of the relative ΔmAP over all cells at the smallest ΔE (measured noise floor)."""
    low_de, low = noise_floor(cells)
    floor = 2 * float(np.std(low, ddof=1)) if len(low) >= 3 else 0.0
    worst = [(r.worst_transform, r.delta_e, r.partial)
             for rows in tables.worst_case.values() for r in rows
             if r.worst_transform and r.delta_e <= 24 and (r.dmap_relative or 0) > floor]
    if not worst:
        return []
    wset = {w for w, _, _ in worst}
    others = sorted(f"{w} at ΔE {d:g}" for w, d, _ in worst if w not in PAPER_WORST)
    verdict = "agrees" if wset <= PAPER_WORST else "disagrees"
    if any(p for _, _, p in worst):
        verdict = "so far " + verdict + " (incomplete)"
    return [PaperFinding(
        "worst case up to ΔE 24 is contrast-inc, contrast-dec or saturation-inc", verdict,
        f"rows whose worst relative ΔmAP exceeds the noise floor {floor:.2f} % (2 sd at ΔE "
        f"{low_de:g}): worst transforms " + ", ".join(sorted(wset))
        + (f"; exceptions: {', '.join(others)}" if others else ""))]


def _threshold_findings(tables: Tables) -> list[PaperFinding]:
    """"ΔE ≤ limit keeps worst-case ΔmAP below bound %", for each of :data:`PAPER_THRESHOLDS`."""
    out = []
    for limit, bound in PAPER_THRESHOLDS:
        claim = f"ΔE ≤ {limit} keeps worst-case ΔmAP below {bound:g} %"
        at_limit = [(m, r) for m, rows in tables.worst_case.items() for r in rows
                    if 0 < r.delta_e <= limit]
        if not at_limit:
            out.append(PaperFinding(claim, "not enough data", "no cells"))
            continue
        m_rel, r_rel = max(at_limit, key=lambda mr: mr[1].dmap_relative or 0)
        m_pts, r_pts = max(at_limit, key=lambda mr: mr[1].dmap_points or 0)
        rel, pts = r_rel.dmap_relative, r_pts.dmap_points
        se = r_pts.dmap_points_se
        verdict = _threshold_verdict([r for _, r in at_limit], bound)
        pts_text = f"{pts:.2f}" + (f" ± {se:.2f} SE" if se else "")
        se_rel = r_rel.dmap_relative_se
        rel_text = f"{rel:.2f} %" + (f" ± {se_rel:.2f} SE" if se_rel else "")
        if r_pts.rare is not None:
            pts_text += (f", of which {r_pts.rare.dmap_points_rare:.2f} from the "
                         f"{r_pts.rare.rare_classes} classes with at most "
                         f"{tables.rare_boxes} boxes")
        partial = any(r.partial for _, r in at_limit)
        missing_de = sorted({d for d in (1, 2, 3, 4, 5, 6, 8, 10, 12) if d <= limit}
                            - {r.delta_e for _, r in at_limit})
        if not verdict.startswith("disagrees") and (partial or missing_de):
            verdict = "so far " + verdict + " (incomplete)"
        out.append(PaperFinding(
            claim, verdict,
            f"largest relative loss {rel_text} ({m_rel}, {r_rel.worst_transform} at ΔE "
            f"{r_rel.delta_e:g}); largest loss in points {pts_text} ({m_pts}, "
            f"{r_pts.worst_transform} at ΔE {r_pts.delta_e:g}); "
            f"{sum(r.transforms_done for _, r in at_limit)} cells"
            + (f"; ΔE not yet measured: {missing_de}" if missing_de else "")))
    return out


def _safety_class_findings(cells: Sequence[CellDelta]) -> list[PaperFinding]:
    """Person and bicycle more sensitive than the mean: relative ΔAP > relative ΔmAP in most
    cells with ΔmAP > 0.5 %."""
    out = []
    for cls in SAFETY_CLASSES:
        more = total = 0
        for r in cells:
            rel_c = r.dap_relative(cls)
            if rel_c is None or r.dmap_relative is None or r.dmap_relative <= 0.5:
                continue
            total += 1
            more += rel_c > r.dmap_relative
        out.append(PaperFinding(
            f"{cls} is more sensitive than the mean (relative ΔAP > ΔmAP)",
            "not enough data" if total == 0 else ("agrees" if more > total / 2 else "disagrees"),
            f"{cls} lost more (relative) than mAP in {more} of {total} cells with ΔmAP > 0.5 %"))
    return out


# --------------------------------------------------------------------------------------------
# Measured prediction table and the ΔE limits it implies
# --------------------------------------------------------------------------------------------


def prediction_table(tables: Tables, name: str = "coco1000-measured") -> dict[str, Any]:
    """A measured prediction table from the worst cases: the JSON document of the
    prediction-table schema (``fidelity/data/schemas``) that
    :func:`fidelity.prediction.table.parse_prediction_table` reads."""
    meta = tables.meta
    # Partial rows (a reachable transform not measured yet) could understate the worst case:
    # they stay in the report but not in the prediction table; provenance lists them.
    curves: list[dict[str, Any]] = []
    omitted: list[str] = []

    def complete_points(label: str, rows: Sequence[WorstCaseRow | SizeClassRow],
                        sources: Sequence[str]) -> list[dict[str, Any]]:
        omitted.extend(f"{label} ΔE {r.delta_e:g}" for r in rows if r.partial)
        return [_point(r, src) for r, src in zip(rows, sources, strict=True) if not r.partial]

    for size, srows in tables.size_classes.items():
        curves.append({"size": size, "model": None, "points": complete_points(
            size, srows, [f"worst over {r.models} model(s) of size {size}: "
                          f"{', '.join(r.model_names)}" for r in srows])})
    for m, wrows in tables.worst_case.items():
        info = tables.models[m]
        curves.append({"size": info.size, "model": m, "baseline_map": info.baseline_map,
                       "baseline_ap": info.baseline_ap or {},
                       "points": complete_points(m, wrows, [
                           f"{m} worst case over {r.transforms_done} transforms"
                           for r in wrows])})
    return {
        "name": name,
        "title": "Measured worst-case detection loss on the shared COCO val2017 subset",
        "kind": "measured",
        "interpolation": "linear",
        "provenance": {
            "source": "fidelity sweep (issue 5): SAFE-COLOR transforms calibrated on the chart, "
                      "JPEG re-encoded with original tables, ONNX detectors, COCO box AP ("
                      + scorer_words(meta.get("scorers")) + ")",
            "models": {m: _model_provenance(info) for m, info in tables.models.items()},
            "images": portable_paths(meta.get("data")), "versions": meta.get("versions"),
            "machine": meta.get("machine"), "machines": meta.get("machines"),
            "cells_done": tables.cells_done, "cells_unreachable": tables.cells_unreachable,
            "worst_case": "per ΔE the transform with the largest ΔmAP in points; person and "
                          "bicycle columns are their own worst case over the same transforms",
            "omitted_partial_points": omitted,
            "aligned_image_counts": {m: a.to_json() for m, a in tables.aligned.items()},
            "standard_errors": {m: STANDARD_ERROR_WORDS[k]
                                for m, k in standard_error_methods(tables).items()},
        } | ({"earlier": portable_paths(meta["earlier"])} if meta.get("earlier") else {})
          | ({"imported": meta["imported"]} if meta.get("imported") else {})
          | ({"versions_seen": meta["versions_seen"]}
             if len(meta.get("versions_seen") or ()) > 1 else {}),
        "units": {
            "dmap_points": "percentage points of mAP@[.50:.95] (100*(baseline-transformed))",
            "dmap_relative": "percent of the baseline mAP",
            "dap_person_points": "percentage points of person AP@[.50:.95]",
            "dap_bicycle_points": "percentage points of bicycle AP@[.50:.95]",
        },
        "curves": curves,
    }


#: How each standard-error method was computed (provenance and reports).
STANDARD_ERROR_WORDS: dict[str, str] = {
    "larger": f"the larger, per cell, of the paired image bootstrap of the whole-run loss "
              f"({BOOTSTRAP_RESAMPLES} draws of the images with replacement, seed "
              f"{BOOTSTRAP_SEED}) and the leave-one-fold-out jackknife over 5 interleaved image "
              "folds (fidelity.coco.loss.loss_estimate; each understates alone in some regime, "
              "reports/validation/standard_error.md)",
    "bootstrap": f"paired image bootstrap of the whole-run loss, {BOOTSTRAP_RESAMPLES} draws of "
                 f"the images with replacement, seed {BOOTSTRAP_SEED}, baseline and cell scored "
                 "on the same draws "
                 "(fidelity.coco.bootstrap.draw_scores, fidelity.coco.loss."
                 "bootstrap_standard_error)",
    "jackknife": "leave-one-fold-out jackknife of the whole-run loss over 5 interleaved image "
                 "folds (fidelity.coco.loss.jackknife_standard_error; measured before the "
                 "bootstrap; larger than the bootstrap on 1000-image cells, "
                 "reports/validation/standard_error.md)",
    "folds": "paired SE of the per-fold losses over 5 interleaved image folds (measured before "
             "the jackknife; understates the SE of the whole-run loss, "
             "reports/validation/standard_error.md)",
    "mixed": "more than one of these methods over the model's cells",
}


def standard_error_methods(tables: Tables) -> dict[str, str]:
    """Per model, how its ΔmAP standard errors were computed: ``"larger"``, ``"bootstrap"``,
    ``"jackknife"``, ``"folds"`` or ``"mixed"`` (keys of :data:`STANDARD_ERROR_WORDS`); models
    without SEs left out."""
    out: dict[str, str] = {}
    for m, rows in tables.cells.items():
        kinds = {r.errors.method for r in rows if r.errors is not None
                 and r.errors.dmap_points is not None and r.errors.method is not None}
        if kinds:
            out[m] = kinds.pop() if len(kinds) == 1 else "mixed"
    return out


def _model_provenance(info: ModelSummary) -> dict[str, Any]:
    keep = ("file", "sha256", "size", "limit_images", "images", "baseline_map")
    st = info.settings
    return ({k: v for k, v in info.to_json().items() if k in keep}
            | {"conventions": st.get("conventions")}
            | ({"earlier_runs": st["earlier"]} if st.get("earlier") else {}))


def _point(r: WorstCaseRow | SizeClassRow, source: str) -> dict[str, Any]:
    return {"delta_e": r.delta_e, "dmap_points": _round(r.dmap_points),
            "dmap_relative": _round(r.dmap_relative),
            "dap_person_points": _round(r.dap_person_points),
            "dap_bicycle_points": _round(r.dap_bicycle_points),
            "dmap_points_se": _round(r.dmap_points_se),
            "worst_transform": r.worst_transform, "source": source,
            "partial": bool(r.partial)}


def _round(v: float | None, nd: int = 4) -> float | None:
    return None if v is None else round(float(v), nd)


def scorer_words(scorers: Sequence[Mapping[str, Any]] | None) -> str:
    """Which COCO scorers scored the store's cells, in words."""
    if not scorers:
        return "pycocotools"
    parts = [f"{e['scorer']}" + (f" from {e['since']}" if e.get("since") else "")
             for e in scorers]
    return ", then ".join(parts)


#: Loss budgets of :func:`delta_e_limits`: the paper's 1 / 3 / 10, read both ways.
LIMIT_BUDGETS: tuple[tuple[str, float], ...] = (
    ("dmap_relative", 1.0), ("dmap_relative", 3.0), ("dmap_relative", 10.0),
    ("dmap_points", 1.0), ("dmap_points", 3.0), ("dmap_points", 10.0))


def delta_e_limits(tables: Tables) -> list[CurveLimits]:
    """The chart ΔE limits the measured worst cases imply, against the paper's ΔE 3 / 6 / 12.

    For every curve of the measured prediction table (each size class's worst case over its
    models, and each model's), the largest chart ΔE whose predicted loss stays within each of
    :data:`LIMIT_BUDGETS` (:func:`fidelity.prediction.table.delta_e_limit`: the curves as
    ``fidelity predict`` uses them, running maximum, linear between the measured ΔE).
    """
    from fidelity.prediction.table import delta_e_limit, parse_prediction_table

    table = parse_prediction_table(json_ready(prediction_table(tables)))
    out = []
    for curve in table.curves:
        if len(curve.delta_e) < 2:  # only the baseline measured: nothing to say
            continue
        one = replace(table, curves=(curve,))
        limits = []
        for column, budget in LIMIT_BUDGETS:
            lim = delta_e_limit(budget, column, size=curve.size, table=one)
            limits.append(BudgetLimit(column, budget, lim.delta_e, lim.status))
        out.append(CurveLimits(curve.size, curve.model, tuple(limits)))
    return out


# --------------------------------------------------------------------------------------------
# Store provenance


def _names(kind: str) -> sc.Node:
    return sc.ListOf(sc.String(), describe=f"a list of {kind} names")


#: The provenance (``meta`` table) of a sweep store as ``fidelity sweep`` writes it and the
#: reports read it: each value is JSON; only the keys read are checked, others pass.
SWEEP_META_SCHEMA = sc.Table(fields=(
    sc.Field("grid", sc.Table(fields=(
        sc.Field("transforms", _names("transform")),
        sc.Field("targets", sc.ListOf(sc.Number(lo=0.0), describe="a list of ΔE values >= 0")),
        sc.Field("models", _names("model")),
    ), extra=True)),
    sc.Field("data", sc.Table(fields=(
        sc.Field("images", sc.String(nullable=True)),
        sc.Field("annotations", sc.String(nullable=True)),
        sc.Field("image_count", sc.Integer(lo=0, nullable=True)),
    ), extra=True)),
    sc.Field("scorers", sc.ListOf(sc.OneOf(options=(
        sc.String(), sc.Table(fields=(sc.Field("scorer", sc.String(), required=True),
                                      sc.Field("since", sc.String(nullable=True))),
                              extra=True)), describe="a scorer name or {scorer, since}"))),
    sc.Field("versions", sc.MapOf(nullable=True)),
    sc.Field("versions_seen", sc.ListOf(sc.MapOf(nullable=True), nullable=True)),
    sc.Field("machine", sc.MapOf(nullable=True)),
    sc.Field("machines", sc.ListOf(sc.MapOf(), nullable=True)),
    sc.Field("imported", sc.ListOf(sc.Table(fields=(
        sc.Field("file", sc.String(), required=True),
        sc.Field("sha256", sc.String(), required=True),
    ), extra=True), describe="the scores files imported (file, sha256, ...)")),
), extra=True)


def check_store_meta(db: Any, path: str, schema: sc.Node = SWEEP_META_SCHEMA) -> None:
    """Check a results store's provenance (its ``meta`` table, read through the open SQLite
    connection ``db``; nothing is written) against ``schema``: every value JSON, the keys the
    reports read of the right shape. Raises :class:`~fidelity.core.schema.SchemaError`
    ``<store> (provenance): <key>: <problem>``."""
    import sqlite3

    origin = f"{path} (provenance)"
    try:
        rows = list(db.execute("SELECT key, value FROM meta"))
    except sqlite3.DatabaseError as exc:
        raise sc.SchemaError(f"{origin}: cannot read: {exc}") from None
    meta: dict[str, Any] = {}
    for key, value in rows:
        meta[str(key)] = sc.parse_text(str(value), "json", f"{origin}: {key}")
    sc.validate(meta, schema, origin)


__all__ = [
    "STANDARD_ERROR_WORDS",
    "standard_error_methods",
    "SWEEP_META_SCHEMA",
    "check_store_meta",
    "LIMIT_BUDGETS",
    "PAPER_THRESHOLDS",
    "RARE_BOXES",
    "SAFETY_CLASSES",
    "AlignedCount",
    "BudgetLimit",
    "CellDelta",
    "CellErrors",
    "CellExplanation",
    "ClassShare",
    "CurveLimits",
    "ModelSummary",
    "PaperFinding",
    "RareShare",
    "ShareGroup",
    "SizeClassRow",
    "Tables",
    "TablesResult",
    "WorstCaseRow",
    "add_standard_errors",
    "align_image_counts",
    "box_counts",
    "build_tables",
    "cell_deltas",
    "class_breakdown",
    "compare_with_paper",
    "delta_e_limits",
    "explain_cell",
    "merge_tables",
    "model_size",
    "noise_floor",
    "parse_image_caps",
    "prediction_table",
    "rare_class_shares",
    "scorer_words",
    "size_class_rows",
    "tables_result",
    "worst_case_rows",
]
