"""Sharpness and noise validated on COCO the way colour is: the verdict's loss against the measured.

A suite of cameras with lenses and sensors (``cameras/properties``, written by
``benchmarks/studies/property_cameras.py``) is emulated on COCO by ``fidelity validate``,
colour, optics and noise (:mod:`fidelity.coco.imaging`), and measured against the baseline
(:func:`fidelity.coco.validate.checks.measured_losses`). Here each cell's measured loss is
set beside what a user is told for that camera:

1. **Predict** (:func:`camera_prediction`): the camera's chart rendered in closed form with
   its turned frame (:func:`fidelity.coco.validate.camera.case_chart`, ``frame=True``: the
   case's illuminant and chromatic adaptation transform), its
   sharpness and noise measured as ``check`` measures them
   (:func:`fidelity.camera.render.frame_properties`), and judged as ``check`` judges them
   (:func:`fidelity.prediction.judge.judge_properties`, detector size ``n``): the colour loss
   of the chart ΔE, the sharpness loss of its MTF50, the noise loss of its SNR and the three
   combined by the shipped rule (:data:`fidelity.prediction.properties.COMBINATION`), for
   each loss column.
2. **Compare** (:func:`property_rows`): the combined loss bounds a cell when the measured loss
   is at most it (:func:`fidelity.coco.validate.checks.bound_check`: within, within 2 SE).
   Each camera's ``group`` names the properties it degrades: ``sharpness`` (it has optics),
   ``noise`` (it adds sensor noise), ``colour`` (its chart ΔE00 is at least
   :data:`COLOUR_ERROR_DELTA_E`).
3. **Summarise** (:func:`property_summary`): per column and group the cells within, the
   median over-prediction (predicted / measured over the cells measured above 0, and over
   those measured more than 2 SE above 0) and every miss with its SE; and how each
   combination rule of :data:`RULES` (the same parts, combined otherwise) bounds the cells
   that degrade two or more properties.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from typing import Any

from fidelity.camera.model import read_camera_file
from fidelity.camera.render import FRAME_SCALE, frame_properties
from fidelity.coco.loss import LOSS_COLUMNS
from fidelity.coco.validate.camera import case_chart
from fidelity.coco.validate.checks import BoundCheck, bound_check, measured_losses
from fidelity.coco.validate.store import ValidationCell, ValidationStore
from fidelity.coco.validate.suite import BASELINE, CameraCase, validated_case
from fidelity.core.fileio import json_ready
from fidelity.core.record import record
from fidelity.prediction.interval import (
    DEGRADATIONS,
    ValidatedProperties,
    validated_degradation,
)
from fidelity.prediction.judge import judge_properties
from fidelity.prediction.properties import COMBINATION, INTERACTING, INTERACTION
from fidelity.prediction.table import predict
from fidelity.prediction.verdict import Criterion

__all__ = [
    "COLOUR_ERROR_DELTA_E",
    "PROPERTIES",
    "RULES",
    "SHIPPED_RULE",
    "CameraPrediction",
    "PropertyResults",
    "PropertyRow",
    "camera_prediction",
    "collect_property_results",
    "combine_rule",
    "property_rows",
    "property_summary",
    "validated_properties",
]

#: A camera degrades colour when its chart ΔE00 is at least this (the exact sRGB camera of the
#: suite reads 0.1-0.3 with its 12-bit quantisation and noise; the Nikon D5100 at its best 1.0).
COLOUR_ERROR_DELTA_E = 0.5
#: The properties judged, in report order.
PROPERTIES: tuple[str, ...] = ("colour", "sharpness", "noise")
#: The detector size class of the predictions (YOLOX-nano and YOLO11n are both ``n``).
SIZE = "n"
#: The combination rule of the verdict (:data:`fidelity.prediction.properties.COMBINATION`).
SHIPPED_RULE = "sum+interaction"
#: The combination rules compared (:func:`combine_rule`).
RULES: tuple[str, ...] = (SHIPPED_RULE, "sum", "probabilistic", "max")
#: The coverage a bound must reach and the median over-prediction it may have (issue 56).
TARGET_COVERAGE = 0.95
TARGET_RATIO = 2.0

#: Each column's criterion (the class and unit a ``max-dmap`` verdict reads it with).
_CRITERIA: Mapping[str, Criterion] = {
    "dmap_points": Criterion("max-dmap", 0.0),
    "dmap_relative": Criterion("max-dmap", 0.0, unit="relative"),
    "dap_person_points": Criterion("max-dmap", 0.0, cls="person"),
    "dap_bicycle_points": Criterion("max-dmap", 0.0, cls="bicycle"),
}


def combine_rule(rule: str, parts: Mapping[str, float]) -> float:
    """The parts' losses (column units: points or % of baseline, each >= 0) combined by
    ``rule``: ``sum+interaction`` (the verdict's: the sum plus
    :data:`~fidelity.prediction.properties.INTERACTION` ``sqrt(l_sharpness l_noise)``),
    ``sum``, ``probabilistic`` (``100 (1 - prod(1 - l_i / 100))``: independent losses of a
    100-point scale) or ``max``."""
    ls = {k: max(v, 0.0) for k, v in parts.items()}
    if rule == "sum":
        return sum(ls.values())
    if rule == SHIPPED_RULE:
        a, b = INTERACTING
        return sum(ls.values()) + INTERACTION * math.sqrt(ls.get(a, 0.0) * ls.get(b, 0.0))
    if rule == "probabilistic":
        return 100.0 * (1.0 - math.prod(1.0 - min(v, 100.0) / 100.0 for v in ls.values()))
    if rule == "max":
        return max(ls.values(), default=0.0)
    raise ValueError(f"unknown combination rule {rule!r}")


@record
class CameraPrediction:
    """What ``check`` tells a user about one camera of the suite (:func:`camera_prediction`).

    ``chart_delta_e``: mean ΔE00 of its chart; ``mtf50``, ``snr``: its turned chart's MTF50
    (cy/px) and SNR at 18 % grey at the detector's input (None: not measured; inf: noiseless);
    ``group``: the properties it degrades (module docstring); ``parts``: column -> property
    -> predicted loss; ``status``: property -> where on its table the prediction came from
    (``in-range``, ``baseline``, ``beyond``); ``combined``: column -> the verdict's combined
    loss; ``dominant``: the property with the largest loss (``dmap_points``);
    ``not_judged``: property -> why it was not judged.
    """

    camera: str
    illuminant: str
    sha256: str
    description: str
    chart_delta_e: float
    mtf50: float | None
    snr: float | None
    group: tuple[str, ...]
    parts: Mapping[str, Mapping[str, float]]
    status: Mapping[str, str]
    combined: Mapping[str, float]
    dominant: str
    not_judged: Mapping[str, str]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys (inf as None)."""
        out: dict[str, Any] = json_ready({
            "camera": self.camera, "illuminant": self.illuminant, "sha256": self.sha256,
            "description": self.description, "chart_delta_e": self.chart_delta_e,
            "mtf50": self.mtf50, "snr": None if self.snr is None or math.isinf(self.snr)
            else self.snr, "snr_noiseless": self.snr is not None and math.isinf(self.snr),
            "group": list(self.group), "parts": {c: dict(p) for c, p in self.parts.items()},
            "status": dict(self.status), "combined": dict(self.combined),
            "dominant": self.dominant, "not_judged": dict(self.not_judged)})
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CameraPrediction:
        """Inverse of :meth:`to_json`."""
        snr = math.inf if d.get("snr_noiseless") else d.get("snr")
        return cls(str(d["camera"]), str(d["illuminant"]), str(d["sha256"]),
                   str(d.get("description", "")), float(d["chart_delta_e"]), d.get("mtf50"),
                   None if snr is None else float(snr), tuple(d["group"]),
                   {c: {k: float(v) for k, v in p.items()} for c, p in d["parts"].items()},
                   dict(d["status"]), {c: float(v) for c, v in d["combined"].items()},
                   str(d["dominant"]), dict(d.get("not_judged") or {}))


def camera_prediction(case: CameraCase) -> CameraPrediction:
    """The verdict's losses for one camera, as ``fidelity check --camera FILE --size n``
    computes them (module docstring, step 1).

    Parameters
    ----------
    case
        The camera file, its scene illuminant and its chromatic adaptation transform
        (:func:`fidelity.coco.validate.camera.case_chart`).

    Returns
    -------
    CameraPrediction
        Its chart values, the per-property and combined losses of every column and its group.
    """
    cam = read_camera_file(case.path)
    render = case_chart(case, cam, frame=True)
    m = render.measurement
    sharpness, noise = frame_properties(render.frame, "scene", case.illuminant)
    prediction = predict(m.mean_delta_e, size=SIZE)
    parts: dict[str, dict[str, float]] = {}
    combined: dict[str, float] = {}
    status: dict[str, str] = {}
    not_judged: dict[str, str] = {}
    mtf50 = snr = None
    dominant = "colour"
    for column, criterion in _CRITERIA.items():
        judged, _ = judge_properties(None, prediction, criterion, size=SIZE,
                                     sharpness=sharpness, noise=noise, scale=FRAME_SCALE)
        p = {"colour": max(judged.colour or 0.0, 0.0)}
        for pred in judged.predictions:
            p[pred.property] = pred.loss
            status[pred.property] = pred.status
            if pred.property == "sharpness":
                mtf50 = pred.x
            else:
                snr = pred.x
        not_judged |= dict(judged.not_judged)
        parts[column] = p
        # the rule's loss: the validated margin is fitted on it (benchmarks.studies.interval)
        combined[column] = (judged.combined.rule_loss if judged.combined is not None
                            else p["colour"])
        if column == "dmap_points" and judged.combined is not None:
            dominant = judged.combined.dominant
    group = tuple(k for k, has in (("colour", m.mean_delta_e >= COLOUR_ERROR_DELTA_E),
                                   ("sharpness", cam.optics.kind != "none"),
                                   ("noise", cam.noise.enabled)) if has)
    return CameraPrediction(case.name, case.illuminant, case.sha256, cam.description,
                            float(m.mean_delta_e), mtf50, snr, group, parts, status, combined,
                            dominant, not_judged)


@record
class PropertyRow:
    """One (camera, detector) cell: the measured losses and SEs by column, the predicted
    loss of every rule of :data:`RULES` by column (``predicted[rule][column]``) and the
    shipped rule's :class:`~fidelity.coco.validate.checks.BoundCheck` by column."""

    camera: str
    model: str
    group: tuple[str, ...]
    images: int
    baseline_map: float
    map: float
    measured: Mapping[str, float | None]
    se: Mapping[str, float | None]
    predicted: Mapping[str, Mapping[str, float]]
    bound: Mapping[str, BoundCheck]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"camera": self.camera, "model": self.model, "group": list(self.group),
                "images": self.images, "baseline_map": self.baseline_map, "map": self.map,
                "measured": dict(self.measured), "se": dict(self.se),
                "predicted": {r: dict(v) for r, v in self.predicted.items()},
                "bound": {c: b.to_json() for c, b in self.bound.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PropertyRow:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["camera"]), str(d["model"]), tuple(d["group"]), int(d["images"]),
                   float(d["baseline_map"]), float(d["map"]), dict(d["measured"]),
                   dict(d["se"]), {r: dict(v) for r, v in d["predicted"].items()},
                   {c: BoundCheck.from_json(b) for c, b in d["bound"].items()})


def property_rows(cameras: Mapping[str, CameraPrediction],
                  cells: Mapping[tuple[str, str], ValidationCell]) -> list[PropertyRow]:
    """The rows of every finished (model, camera) cell of ``cells`` whose camera is in
    ``cameras`` and whose model has its baseline cell (module docstring, step 2)."""
    rows = []
    for (model, camera), c in sorted(cells.items()):
        b = cells.get((model, BASELINE))
        if camera == BASELINE or camera not in cameras or b is None:
            continue
        cam = cameras[camera]
        measured, se, _ = measured_losses(b, c)
        columns = list(LOSS_COLUMNS.values())
        predicted = {rule: {col: (cam.combined[col] if rule == SHIPPED_RULE
                                  else combine_rule(rule, cam.parts[col]))
                            for col in columns} for rule in RULES}
        bound = {col: bound_check(predicted[SHIPPED_RULE][col], measured.get(col),
                                  se.get(col), cam.status.get(cam.dominant, "in-range"))
                 for col in columns}
        rows.append(PropertyRow(camera, model, cam.group, c.images, b.map, c.map,
                                {col: measured.get(col) for col in columns},
                                {col: se.get(col) for col in columns}, predicted, bound))
    return rows


def _median(values: Sequence[float]) -> float | None:
    return statistics.median(values) if values else None


def _stats(rows: Sequence[PropertyRow], column: str, rule: str) -> dict[str, Any]:
    """Coverage and over-prediction of ``rule`` on ``rows`` for ``column``."""
    judged = [r for r in rows if r.measured.get(column) is not None]
    within, within2, ratios, ratios2, misses = 0, 0, [], [], []
    for r in judged:
        m = float(r.measured[column])  # type: ignore[arg-type]
        se = r.se.get(column)
        p = r.predicted[rule][column]
        ok = m <= p
        ok2 = se is not None and m - 2 * se <= p
        within += ok
        within2 += ok or ok2
        if m > 0:
            ratios.append(p / m)
            if se is not None and m > 2 * se:
                ratios2.append(p / m)
        if not ok:
            misses.append({"camera": r.camera, "model": r.model, "predicted": p,
                           "measured": m, "se": se, "excess": m - p,
                           "within_2se": bool(ok2)})
    n = len(judged)
    return {"cells": n, "within": within, "within_2se": within2,
            "share_within": within / n if n else None,
            "median_ratio": _median(ratios), "cells_above_zero": len(ratios),
            "median_ratio_2se": _median(ratios2), "cells_above_2se": len(ratios2),
            "median_predicted": _median([r.predicted[rule][column] for r in judged]),
            "median_measured": _median([float(r.measured[column])  # type: ignore[arg-type]
                                        for r in judged]),
            "misses": misses}


def _meets(s: Mapping[str, Any]) -> bool:
    share, ratio = s["share_within"], s["median_ratio"]
    return (share is not None and share >= TARGET_COVERAGE
            and (ratio is None or ratio <= TARGET_RATIO))


def property_summary(rows: Sequence[PropertyRow]) -> dict[str, Any]:
    """Per column: the shipped rule's coverage and over-prediction over all cells and per
    group (``groups``), and every rule's on the cells that degrade two or more properties
    (``rules``), with the rule that bounds at least :data:`TARGET_COVERAGE` of them with the
    least median over-prediction (``best_rule``; None when none does)."""
    out: dict[str, Any] = {}
    groups = sorted({r.group for r in rows}, key=lambda g: (len(g), [PROPERTIES.index(p)
                                                                     for p in g]))
    for column in LOSS_COLUMNS.values():
        allcells = _stats(rows, column, SHIPPED_RULE)
        by_group = {"+".join(g) or "none": _stats([r for r in rows if r.group == g], column,
                                                  SHIPPED_RULE) for g in groups}
        joint = [r for r in rows if len(r.group) >= 2]
        rules = {rule: _stats(joint, column, rule) for rule in RULES}
        everywhere = {rule: _stats(rows, column, rule) for rule in RULES}
        covering = [k for k in RULES if rules[k]["cells"] and rules[k]["share_within"] is not None
                    and rules[k]["share_within"] >= TARGET_COVERAGE]
        best = min(covering, key=lambda k: rules[k]["median_ratio"] or math.inf, default=None)
        out[column] = {"all": allcells | {"meets_target": _meets(allcells)},
                       "groups": {g: s | {"meets_target": _meets(s)}
                                  for g, s in by_group.items()},
                       "rules": rules, "rules_all_cells": everywhere, "best_rule": best,
                       "joint_cells": len(joint)}
    return out


@record
class PropertyResults:
    """Everything ``properties.json`` holds (:func:`collect_property_results`)."""

    cameras: Mapping[str, CameraPrediction]
    rows: tuple[PropertyRow, ...]
    summary: Mapping[str, Any]
    baselines: Mapping[str, Mapping[str, Any]]
    meta: Mapping[str, Any]

    def to_json(self) -> dict[str, Any]:
        """``properties.json`` (strict JSON values)."""
        out: dict[str, Any] = json_ready({
            "kind": "property-validation", "combination": COMBINATION,
            "target": {"coverage": TARGET_COVERAGE, "median_ratio": TARGET_RATIO},
            "colour_error_delta_e": COLOUR_ERROR_DELTA_E, "size": SIZE,
            "rules": list(RULES), "shipped_rule": SHIPPED_RULE,
            "cameras": {k: c.to_json() for k, c in self.cameras.items()},
            "baselines": dict(self.baselines), "rows": [r.to_json() for r in self.rows],
            "summary": dict(self.summary), "meta": dict(self.meta)})
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PropertyResults:
        """Inverse of :meth:`to_json` (the summary recomputed from the rows)."""
        rows = tuple(PropertyRow.from_json(r) for r in d["rows"])
        return cls({k: CameraPrediction.from_json(c) for k, c in d["cameras"].items()}, rows,
                   property_summary(rows), dict(d.get("baselines") or {}),
                   dict(d.get("meta") or {}))


def collect_property_results(store: ValidationStore, suite: Sequence[CameraCase]
                             ) -> PropertyResults:
    """The property validation of the finished cells of ``store`` for the cameras of
    ``suite`` (each camera's prediction made again from its file: :func:`camera_prediction`)."""
    cells = {(c.model, c.camera): c for c in store.cells()}
    have = {camera for _, camera in cells}
    cameras = {c.name: camera_prediction(c) for c in suite if c.name in have}
    rows = property_rows(cameras, cells)
    baselines = {m: {"map": c.map, "images": c.images}
                 for (m, camera), c in sorted(cells.items()) if camera == BASELINE}
    meta = {k: v for k, v in store.meta().items()
            if k in ("versions", "settings", "models_run", "last_run")}
    return PropertyResults(cameras, tuple(rows), property_summary(rows), baselines, meta)


def validated_properties(results: PropertyResults, suite: Sequence[CameraCase]
                         ) -> ValidatedProperties:
    """The cameras ``results`` validated, as the validity domain states them
    (:class:`~fidelity.prediction.interval.ValidatedProperties`): each camera read from its
    file in ``suite`` (the same SHA-256 as validated, else an :class:`InputFileError`) and its
    noise, optics and vignetting (:meth:`~fidelity.camera.model.CameraModel.degradations`);
    the counts of the ΔmAP (points) cells of the summary; the models of the rows."""
    cases = {c.name: c for c in suite}
    seen: dict[str, list[tuple[str, Mapping[str, float]]]] = {d: [] for d in DEGRADATIONS}
    for name, camera_result in results.cameras.items():
        case = validated_case(cases, name, camera_result.sha256)
        for kind, degradation in read_camera_file(case.path).degradations().items():
            seen[kind].append(degradation)
    a = results.summary["dmap_points"]["all"]
    models = tuple(dict.fromkeys(r.model for r in results.rows))
    return ValidatedProperties(len(results.cameras), models, int(a["cells"]), int(a["within"]),
                               int(a["within_2se"]),
                               {d: validated_degradation(v) for d, v in seen.items()})
