"""A prediction interval that holds? Split-conformal upper bounds for the model-form error of
the predicted ΔmAP, on the validation's 60 cells (30 cameras x 2 detectors), with
leave-one-camera-out coverage (issue 58).

The validation (``reports/validation/directional.json``, the cells of ``validation.json`` with
both predictions) gives per (camera, detector) cell the measured ΔmAP (points) with its
standard error and the classic and direction-aware predictions of the shipped tables. A bound
``U`` of a cell holds when the measured loss is at most ``U``. Each method below makes ``U``
from the prediction ``p`` and constants fitted on other cells:

- ``table``: the table's prediction as it is (``U = p``), nothing fitted;
- ``additive``: split-conformal on the residual ``m - p`` (``U = p + q``);
- ``log-ratio``: split-conformal on ``log((m + c) / (p + c))``, ``c`` = 0.5 points (a loss can
  be measured below 0), ``U = (p + c) exp(q) - c``;
- ``calibrated``: ``a`` fitted by least squares through the origin (``m ~ a p``), then
  split-conformal on ``m - a p`` (``U = a p + q``).

- ``calibrated CV+``: the cross-validation+ interval (Barber, Candès, Ramdas & Tibshirani
  2021, "Predictive inference with the jackknife+", Ann. Statist. 49(1)) of the calibrated
  model, its folds the training cameras: for each training camera ``k`` the slope ``a_-k``
  is fitted without it, each of its cells ``i`` gets the out-of-fold residual
  ``R_i = m_i - a_-k p_i``, and the bound of a new cell is the
  ``ceil((1 - alpha)(n + 1))``-th smallest of ``a_-k(i) p + R_i`` over the ``n`` training
  cells (one-sided; its guarantee is ``1 - 2 alpha``, in practice near ``1 - alpha``).

``q`` is the split-conformal quantile of the training cells' scores: the
``ceil((n + 1)(1 - alpha))``-th smallest of ``n`` (Vovk et al. 2005; Lei et al. 2018), which
covers an exchangeable new cell with probability >= 1 - alpha. Coverage is measured leaving
one camera out: for each of the 30 cameras the constants are fitted on the other 29 cameras'
58 cells and both of its cells are judged (a camera's two cells share its colours, so a cell
is never judged by constants fitted on its sibling). Over-prediction: the median of
``U / m`` over the cells measured above 0, and over the cells measured more than 2 SE above 0.
The target (issue 58): coverage >= 95 % with a median over-prediction <= 2x.

Usage: python -m benchmarks.studies.interval [--validation reports/validation/directional.json]
       [--out reports/validation/interval] [--data [fidelity/data/validated-bound.json]]
       python -m benchmarks.studies.interval --properties [reports/validation/properties.json]

``--properties``: the same methods on the sharpness and noise validation's cells (the
verdict's combined loss), written to ``properties-interval.md|json`` (issue 56); with
``--data`` it also writes the shipped margin of the combined loss
(:class:`fidelity.prediction.validated.PropertyMargin`, ``fidelity/data/property-margin.json``):
the log-ratio bound of every loss column, fitted on all cells, with its leave-one-camera-out
coverage and over-prediction.

``--data`` also writes the shipped validated bound (:mod:`fidelity.prediction.validated`): the
calibrated bound of the classic prediction fitted on all cells, with its leave-one-camera-out
coverage and over-prediction.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.core.fileio import write_json_atomic, write_text_atomic
from fidelity.prediction.properties import COMBINATION, LOSS_COLUMNS, PROPERTY_TABLES
from fidelity.prediction.tablefile import DEFAULT_TABLE
from fidelity.prediction.validated import (
    PROPERTY_MARGIN_FILE,
    VALIDATED_BOUND_FILE,
    ColumnMargin,
    PropertyMargin,
    ValidatedBound,
)

REPO = Path(__file__).resolve().parents[2]
#: The validation cells with both predictions (``fidelity validate``'s directional part).
VALIDATION = REPO / "reports" / "validation" / "directional.json"
#: Miscoverage: a bound for >= 95 % of new cells.
ALPHA = 0.05
#: The offset of the log-ratio score, percentage points of mAP.
LOG_OFFSET = 0.5
#: The issue's target: coverage and median over-prediction.
TARGET_COVERAGE = 0.95
TARGET_RATIO = 2.0


@dataclass(frozen=True)
class Cells:
    """The validation's cells: ``camera`` and ``model`` names, ``measured`` ΔmAP (points) and
    its ``se``, the ``classic`` and ``directional`` predictions (points), arrays of one length."""

    camera: np.ndarray
    model: np.ndarray
    measured: np.ndarray
    se: np.ndarray
    classic: np.ndarray
    directional: np.ndarray

    def where(self, mask: np.ndarray) -> Cells:
        """The cells where ``mask`` (boolean, one per cell) is true."""
        return Cells(*(getattr(self, f.name)[mask] for f in fields(self)))


def read_cells(doc: Mapping[str, Any], column: str = "all") -> Cells:
    """The cells of a ``directional.json`` document (its ``rows``), loss column ``column``
    (``all``: ΔmAP in points)."""
    rows = [(r["camera"], r["model"], r["cells"][column]) for r in doc["rows"]]
    return Cells(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                 *(np.array([float(r[2][k]) for r in rows])
                   for k in ("measured", "se", "classic", "directional")))


#: The sharpness and noise validation's report (``fidelity validate --properties``).
PROPERTIES = REPO / "reports" / "validation" / "properties.json"
#: The combination rule of the verdict, as the property report names it.
PROPERTY_RULE = "sum+interaction"


def read_property_cells(doc: Mapping[str, Any], column: str = "dmap_points",
                        rule: str = PROPERTY_RULE) -> Cells:
    """The cells of a ``properties.json`` document (its ``rows``): the verdict's combined loss
    (``rule``) as both predictions, loss column ``column`` (ΔmAP in points)."""
    rows = doc["rows"]
    combined = np.array([float(r["predicted"][rule][column]) for r in rows])
    return Cells(np.array([r["camera"] for r in rows]), np.array([r["model"] for r in rows]),
                 np.array([float(r["measured"][column]) for r in rows]),
                 np.array([float(r["se"][column]) for r in rows]), combined, combined.copy())


def property_study(cells: Cells, alpha: float = ALPHA) -> list[Outcome]:
    """Every method (:data:`METHODS`) on the combined loss of the property cells."""
    return [leave_one_camera_out(cells, "classic", method, alpha) for method in METHODS]


def property_markdown(outcomes: Sequence[Outcome], source: str) -> str:
    """The property study's report (every number from :func:`property_study`)."""
    lines = [
        "# A margin for the sharpness and noise verdict: split-conformal bounds on its cells",
        "",
        f"Made by `python -m benchmarks.studies.interval --properties` from `{source}` (the "
        "verdict's combined loss, sum + sqrt(l_sharpness l_noise), against the measured "
        f"ΔmAP in points): {outcomes[0].cells} cells, {outcomes[0].cameras} cameras. Each "
        "bound is judged leaving its camera out, as for colour (`interval.md`). Target: "
        f"coverage >= {TARGET_COVERAGE:.0%} with a median over-prediction <= "
        f"{TARGET_RATIO:g}x. The verdict adds the `{MARGIN_METHOD}` margin to the combined "
        "loss (`fidelity/data/property-margin.json`, fitted on all cells).",
        "",
        "| method | cells covered | cameras covered | median U / measured | same, cells > 2 SE "
        "| fitted on all cells | meets target | misses |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for o in outcomes:
        misses = "; ".join(f"{c} / {d} ({mv:.2f} > {u:.2f})" for c, d, mv, u in o.misses)
        lines.append(f"| {o.method} | {o.coverage_cells()} | {o.constants_words()} | "
                     f"{'yes' if o.meets_target else 'no'} | {misses or '–'} |")
    return "\n".join(lines) + "\n"


def conformal_quantile(scores: np.ndarray, alpha: float = ALPHA) -> float:
    """The split-conformal quantile of ``scores`` (n of them): the ``ceil((n+1)(1-alpha))``-th
    smallest; +inf when that rank exceeds n (too few cells for that coverage)."""
    n = len(scores)
    k = math.ceil((n + 1) * (1 - alpha))
    return math.inf if k > n else float(np.sort(scores)[k - 1])


def slope(m: np.ndarray, p: np.ndarray) -> float:
    """Least squares through the origin, ``m ~ a p``: ``sum(m p) / sum(p^2)``."""
    return float(np.sum(m * p) / np.sum(p * p))


#: A method: (measured, prediction of the training cells, prediction of the judged cells,
#: alpha, the training cells' cameras) -> (bounds of the judged cells, the constants fitted).
Method = Callable[[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray],
                  tuple[np.ndarray, dict[str, float]]]


def table(m: np.ndarray, p: np.ndarray, new: np.ndarray, alpha: float,
          groups: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """The table's prediction as it is."""
    return new.copy(), {}


def cv_plus(m: np.ndarray, p: np.ndarray, new: np.ndarray, alpha: float,
            groups: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """The CV+ upper bound of the calibrated model ``m ~ a p`` (module docstring), its folds
    the ``groups`` (cameras; None: each cell its own fold, the jackknife+)."""
    g = np.arange(len(m)) if groups is None else np.asarray(groups)
    a_out = np.empty_like(m)
    for name in np.unique(g):
        fold = g == name
        a_out[fold] = slope(m[~fold], p[~fold])
    residual = m - a_out * p
    n = len(m)
    k = math.ceil((n + 1) * (1 - alpha))
    if k > n:
        return np.full_like(new, math.inf), {"a": slope(m, p)}
    values = a_out[None, :] * new[:, None] + residual[None, :]
    return np.sort(values, axis=1)[:, k - 1], {"a": slope(m, p),
                                               "a_min": float(a_out.min()),
                                               "a_max": float(a_out.max())}


def additive(m: np.ndarray, p: np.ndarray, new: np.ndarray, alpha: float,
             groups: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """``U = p + q``, q the conformal quantile of ``m - p``."""
    q = conformal_quantile(m - p, alpha)
    return new + q, {"q": q}


def log_ratio(m: np.ndarray, p: np.ndarray, new: np.ndarray, alpha: float,
              groups: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """``U = (p + c) exp(q) - c``, q the conformal quantile of ``log((m + c) / (p + c))``.
    A cell measured at or below ``-c`` would have no log: its score is -inf (it holds under
    any bound)."""
    c = LOG_OFFSET
    with np.errstate(divide="ignore", invalid="ignore"):
        scores = np.where(m + c > 0, np.log(np.maximum(m + c, 1e-300) / (p + c)), -np.inf)
    q = conformal_quantile(scores, alpha)
    return (new + c) * math.exp(q) - c, {"q": q, "c": c}


def calibrated(m: np.ndarray, p: np.ndarray, new: np.ndarray, alpha: float,
               groups: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """``U = a p + q``: ``a`` by least squares through the origin, q the conformal quantile
    of ``m - a p``."""
    a = slope(m, p)
    q = conformal_quantile(m - a * p, alpha)
    return a * new + q, {"a": a, "q": q}


METHODS: Mapping[str, Method] = {"table": table, "additive": additive,
                                 "log-ratio": log_ratio, "calibrated": calibrated,
                                 "calibrated CV+": cv_plus}


@dataclass(frozen=True)
class Outcome:
    """One method on one prediction: leave-one-camera-out ``coverage`` (share of cells),
    ``cells_covered`` of ``cells``, ``cameras_covered`` (both cells) of ``cameras``, the
    median over-prediction ``median_ratio`` (cells measured > 0) and ``median_ratio_significant``
    (measured > 2 SE; None when none), the median bound ``median_bound`` (points), the
    ``misses`` (camera, detector, measured, bound), the constants fitted on all cells
    (``constants``, what a shipped option would use) and whether it meets the target."""

    method: str
    prediction: str
    cells: int
    cells_covered: int
    cameras: int
    cameras_covered: int
    median_ratio: float
    median_ratio_significant: float | None
    significant_cells: int
    median_bound: float
    misses: tuple[tuple[str, str, float, float], ...]
    constants: Mapping[str, float]

    @property
    def coverage(self) -> float:
        return self.cells_covered / self.cells

    @property
    def meets_target(self) -> bool:
        return self.coverage >= TARGET_COVERAGE and self.median_ratio <= TARGET_RATIO

    def coverage_cells(self) -> str:
        """The report's table cells of coverage and over-prediction: cells covered, cameras
        covered, the median over-prediction and the same over the significant cells."""
        return (f"{self.cells_covered} of {self.cells} ({self.coverage:.1%}) | "
                f"{self.cameras_covered} of {self.cameras} | {_fmt(self.median_ratio)} | "
                f"{_fmt(self.median_ratio_significant)} ({self.significant_cells} cells)")

    def constants_words(self) -> str:
        """The constants fitted on all cells, ``a = 0.141, q = 1.44`` (– when none)."""
        return ", ".join(f"{k} = {v:.3g}" for k, v in self.constants.items()) or "–"

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "prediction": self.prediction, "cells": self.cells,
                "cells_covered": self.cells_covered, "coverage": self.coverage,
                "cameras": self.cameras, "cameras_covered": self.cameras_covered,
                "median_ratio": self.median_ratio,
                "median_ratio_significant": self.median_ratio_significant,
                "significant_cells": self.significant_cells,
                "median_bound": self.median_bound,
                "misses": [list(x) for x in self.misses], "constants": dict(self.constants),
                "meets_target": self.meets_target}


def leave_one_camera_out(cells: Cells, prediction: str, method: str,
                         alpha: float = ALPHA) -> Outcome:
    """The bounds of every cell with the constants fitted on the other cameras' cells, and
    what they give (:class:`Outcome`)."""
    m, camera = cells.measured, cells.camera
    p = getattr(cells, prediction)
    fit = METHODS[method]
    bound = np.empty_like(m)
    for name in sorted(set(camera.tolist())):
        judged = camera == name
        bound[judged] = fit(m[~judged], p[~judged], p[judged], alpha, camera[~judged])[0]
    held = m <= bound
    cameras = sorted(set(camera.tolist()))
    positive, significant = m > 0, m > 2 * cells.se
    return Outcome(
        method, prediction, len(m), int(held.sum()), len(cameras),
        sum(bool(held[camera == c].all()) for c in cameras),
        float(np.median(bound[positive] / m[positive])),
        float(np.median(bound[significant] / m[significant])) if significant.any() else None,
        int(significant.sum()), float(np.median(bound)),
        tuple((str(cells.camera[i]), str(cells.model[i]), float(m[i]), float(bound[i]))
              for i in np.flatnonzero(~held)),
        fit(m, p, p, alpha, camera)[1])


def study(cells: Cells, alpha: float = ALPHA) -> list[Outcome]:
    """Every method (:data:`METHODS`) on both predictions."""
    return [leave_one_camera_out(cells, prediction, method, alpha)
            for prediction in ("classic", "directional") for method in METHODS]


def noise_floor(cells: Cells) -> dict[str, float]:
    """How much of the measured losses is measurement noise: the median measured loss, the
    median SE, the cells measured more than 2 SE above 0 and at or below 0."""
    m, se = cells.measured, cells.se
    return {"median_measured": float(np.median(m)), "median_se": float(np.median(se)),
            "significant_cells": int((m > 2 * se).sum()), "cells_at_or_below_0": int((m <= 0).sum())}


def per_detector(cells: Cells, alpha: float = ALPHA) -> list[tuple[str, Outcome, float, float]]:
    """The shipped method (:data:`SHIPPED`) on each detector's cells alone, with that
    detector's median measured loss and median SE: whether one detector measured on more
    images (YOLOX-nano on 1000) reaches the target where the pooled cells do not."""
    out = []
    for model in sorted(set(cells.model.tolist())):
        k = cells.model == model
        own = cells.where(k)
        out.append((model, leave_one_camera_out(own, SHIPPED["prediction"], SHIPPED["method"],
                                                alpha),
                    float(np.median(own.measured)), float(np.median(own.se))))
    return out


def per_detector_words(rows: Sequence[tuple[str, Outcome, float, float]]) -> list[str]:
    """One paragraph from :func:`per_detector`."""
    if not rows:
        return []
    parts = [f"{model}: {o.cells_covered} of {o.cells} cells covered, median U / measured "
             f"{o.median_ratio:.2f}x (median measured {m:.2f}, median SE {se:.2f} points)"
             for model, o, m, se in rows]
    met = [model for model, o, _, _ in rows if o.meets_target]
    return ["**Each detector alone** (the shipped method, its constants fitted on that "
            "detector's cells, leaving each camera out): " + "; ".join(parts) + ". "
            + (f"The target is met by {', '.join(met)} alone." if met else
               "Neither meets the target alone; the median SE over the median measured "
               "loss: " + ", ".join(f"{model} {se / m:.2f}" if m > 0 else f"{model} –"
                                   for model, _, m, se in rows) + ".")]


def _fmt(x: float | None, nd: int = 2) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def cv_plus_words(outcomes: Sequence[Outcome]) -> list[str]:
    """One paragraph: CV+ against the split-conformal calibrated bound, per prediction, and
    whether it is adopted (it would be only by meeting the coverage target with a smaller
    median over-prediction)."""
    by = {(o.prediction, o.method): o for o in outcomes}
    parts = []
    better = []
    for pred in ("classic", "directional"):
        cv, split = by.get((pred, "calibrated CV+")), by.get((pred, "calibrated"))
        if cv is None or split is None:
            continue
        parts.append(f"{pred}: {cv.cells_covered} of {cv.cells} cells covered against "
                     f"{split.cells_covered}, median U / measured {cv.median_ratio:.2f}x "
                     f"against {split.median_ratio:.2f}x ({_fmt(cv.median_ratio_significant)}x"
                     f" against {_fmt(split.median_ratio_significant)}x over the significant "
                     f"cells), median U {cv.median_bound:.2f} against {split.median_bound:.2f}"
                     " points")
        # narrower only by what the report prints (two decimals)
        if cv.coverage >= TARGET_COVERAGE and round(cv.median_ratio, 2) < round(
                split.median_ratio, 2):
            better.append(pred)
    if not parts:
        return []
    verdict = (f"it is narrower at >= {TARGET_COVERAGE:.0%} coverage for "
               f"{', '.join(better)}" if better else
               f"it is no narrower at >= {TARGET_COVERAGE:.0%} coverage (to the two decimals "
               "printed), so it is not adopted")
    return ["**CV+ against split conformal (calibrated).** " + "; ".join(parts) + f": {verdict}."]


def markdown(outcomes: Sequence[Outcome], floor: Mapping[str, float], cells: int,
             detectors: Sequence[tuple[str, Outcome, float, float]] = ()) -> str:
    """The study's report (every number from :func:`study`, :func:`noise_floor` and
    :func:`per_detector`)."""
    best = min((o for o in outcomes if o.coverage >= TARGET_COVERAGE),
               key=lambda o: o.median_ratio)
    met = [o for o in outcomes if o.meets_target]
    lines = [
        "# A prediction interval that holds: split-conformal and CV+ bounds on the validation "
        "cells",
        "",
        "Made by `python -m benchmarks.studies.interval` from `reports/validation/"
        "directional.json` (the validation's cells with the classic and direction-aware "
        f"predictions): {cells} cells, {outcomes[0].cameras} cameras, ΔmAP in points. Each "
        "bound is judged leaving its camera out: its constants are fitted on the other "
        f"cameras' cells (split-conformal quantile, or CV+ over those cameras, at alpha = "
        f"{ALPHA}). Target: coverage >= "
        f"{TARGET_COVERAGE:.0%} with a median over-prediction <= {TARGET_RATIO:g}x.",
        "",
        "| prediction | method | cells covered | cameras covered | median U / measured | "
        "same, cells > 2 SE | median U (points) | fitted on all cells | meets target |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for o in outcomes:
        lines.append(f"| {o.prediction} | {o.method} | {o.coverage_cells()} | "
                     f"{_fmt(o.median_bound)} | {o.constants_words()} | "
                     f"{'yes' if o.meets_target else 'no'} |")
    lines += [
        "",
        f"**Result.** {'The target is met by ' + ', '.join(f'{o.prediction} {o.method}' for o in met) if met else 'No method meets the target'}. "
        f"The smallest median over-prediction at >= {TARGET_COVERAGE:.0%} coverage is "
        f"{best.prediction} {best.method}: {best.coverage:.1%} of cells covered "
        f"({best.cells_covered} of {best.cells}), median U / measured "
        f"{best.median_ratio:.2f}x ({_fmt(best.median_ratio_significant)}x over the "
        f"{best.significant_cells} cells measured more than 2 SE above 0).",
        "",
        *cv_plus_words(outcomes),
        "",
        "**Why not 2x.** The measured losses are mostly measurement noise: the median "
        f"measured ΔmAP is {floor['median_measured']:.2f} points and the median standard "
        f"error of a cell {floor['median_se']:.2f} points; {floor['significant_cells']} of "
        f"{cells} cells are measured more than 2 SE above 0 and {floor['cells_at_or_below_0']} "
        "at or below 0. A bound that covers 95 % of measured cells must cover that noise, so "
        "it lies well above the typical measured value; a ratio to a measured value near 0 "
        "is large whatever the bound. The ratios over the significant cells say more about "
        "the model-form error, but rest on few cells.",
        "",
        *per_detector_words(detectors),
        "",
        "Cells the best method misses (leaving their camera out):",
        "",
    ]
    lines += [f"- {c} / {d}: measured {mv:.2f}, bound {u:.2f}" for c, d, mv, u in best.misses]
    shipped = next(o for o in outcomes
                   if (o.method, o.prediction) == (SHIPPED["method"], SHIPPED["prediction"]))
    lines += ["", f"`check`, `audit` and `gate` print the {shipped.prediction} {shipped.method} "
              f"bound fitted on all {shipped.cells} cells as the *validated bound* "
              f"(`U = {shipped.constants['a']:.3g} p + {shipped.constants['q']:.3g}` points, "
              f"`fidelity/data/{VALIDATED_BOUND_FILE}`, "
              "`fidelity.prediction.validated`) beside the table's prediction and its interval "
              "(table SE and the ΔE uncertainty, which leaves the model-form error out); the "
              "verdict stays on the table's prediction, as the target is not met.", ""]
    return "\n".join(lines)


#: What the shipped validated bound is (:mod:`fidelity.prediction.validated`): the study's
#: method, on the classic prediction, with the table and detector size validated.
SHIPPED = {"method": "calibrated", "prediction": "classic", "table": "coco1000-measured",
           "size": "n"}
#: Where it ships.
DATA = REPO / "fidelity" / "data" / VALIDATED_BOUND_FILE


def shipped_bound(outcomes: Sequence[Outcome], validation: Path) -> ValidatedBound:
    """The :class:`~fidelity.prediction.validated.ValidatedBound` of :data:`SHIPPED` from the
    study's ``outcomes`` (its constants fitted on all cells, its leave-one-camera-out figures)
    and the ``validation`` file they came from (path in the repository and SHA-256)."""
    o = next(o for o in outcomes
             if (o.method, o.prediction) == (SHIPPED["method"], SHIPPED["prediction"]))
    source = (str(validation.relative_to(REPO)) if validation.is_relative_to(REPO)
              else str(validation))
    return ValidatedBound(
        "calibrated split-conformal", o.prediction, "dmap_points", SHIPPED["table"],
        SHIPPED["size"], ALPHA, float(o.constants["a"]), float(o.constants["q"]), o.cells,
        o.cameras, o.cells_covered, o.cameras_covered, o.median_ratio,
        o.median_ratio_significant, o.significant_cells, source,
        hashlib.sha256(validation.read_bytes()).hexdigest())


#: The method of the shipped margin of the combined property loss.
MARGIN_METHOD = "log-ratio"
#: Where it ships.
MARGIN_DATA = REPO / "fidelity" / "data" / PROPERTY_MARGIN_FILE


def shipped_margin(doc: Mapping[str, Any], validation: Path) -> PropertyMargin:
    """The :class:`~fidelity.prediction.validated.PropertyMargin` of the property validation
    ``doc`` (``properties.json``, read from ``validation``): the :data:`MARGIN_METHOD` bound
    of each loss column's combined loss, its ``q`` fitted on all cells, its
    leave-one-camera-out figures (:func:`leave_one_camera_out`)."""
    columns = {}
    for column in LOSS_COLUMNS:
        o = leave_one_camera_out(read_property_cells(doc, column), "classic", MARGIN_METHOD)
        columns[column] = ColumnMargin(float(o.constants["q"]), o.cells, o.cameras,
                                       o.cells_covered, o.cameras_covered, o.median_ratio,
                                       o.median_ratio_significant, o.significant_cells)
    source = (str(validation.relative_to(REPO)) if validation.is_relative_to(REPO)
              else str(validation))
    if doc.get("combination") != COMBINATION:
        raise ValueError(f"{source}: combination {doc.get('combination')!r}, the verdict's "
                         f"is {COMBINATION!r}")
    return PropertyMargin(
        "log-ratio split-conformal", COMBINATION,
        {"colour": DEFAULT_TABLE, **PROPERTY_TABLES}, str(doc["size"]), ALPHA, LOG_OFFSET,
        columns, source, hashlib.sha256(validation.read_bytes()).hexdigest())


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--validation", type=Path, default=VALIDATION)
    ap.add_argument("--out", type=Path, default=REPO / "reports" / "validation" / "interval")
    ap.add_argument("--data", type=Path, nargs="?", const=DATA, default=None,
                    help=f"also write the shipped validated bound (default {DATA.name}; with "
                         f"--properties the margin, default {MARGIN_DATA.name})")
    ap.add_argument("--properties", type=Path, nargs="?", const=PROPERTIES, default=None,
                    help="instead: the methods on the sharpness and noise validation's "
                         f"combined loss (default {PROPERTIES.name}), written to "
                         "properties-interval.md|json beside --out")
    args = ap.parse_args(argv)
    if args.properties is not None:
        source = (str(args.properties.relative_to(REPO))
                  if args.properties.is_relative_to(REPO) else str(args.properties))
        pdoc = json.loads(args.properties.read_text(encoding="utf-8"))
        outcomes = property_study(read_property_cells(pdoc))
        out = args.out.with_name("properties-interval")
        print(write_json_atomic(out.with_suffix(".json"), {
            "source": source, "alpha": ALPHA, "rule": PROPERTY_RULE, "column": "dmap_points",
            "target": {"coverage": TARGET_COVERAGE, "median_ratio": TARGET_RATIO},
            "outcomes": [o.to_json() for o in outcomes]}))
        print(write_text_atomic(out.with_suffix(".md"), property_markdown(outcomes, source)))
        if args.data is not None:
            target = MARGIN_DATA if args.data == DATA else args.data
            print(write_json_atomic(target, shipped_margin(pdoc, args.properties).to_json()))
        return
    cells = read_cells(json.loads(args.validation.read_text(encoding="utf-8")))
    outcomes = study(cells)
    floor = noise_floor(cells)
    doc = {"source": str(args.validation.relative_to(REPO)) if args.validation.is_relative_to(
        REPO) else str(args.validation), "alpha": ALPHA, "log_offset": LOG_OFFSET,
        "target": {"coverage": TARGET_COVERAGE, "median_ratio": TARGET_RATIO},
        "noise_floor": floor, "outcomes": [o.to_json() for o in outcomes],
        "per_detector": [{"model": model, "median_measured": m, "median_se": se,
                          **o.to_json()} for model, o, m, se in per_detector(cells)]}
    print(write_json_atomic(args.out.with_suffix(".json"), doc))
    print(write_text_atomic(args.out.with_suffix(".md"),
                            markdown(outcomes, floor, len(cells.measured),
                                     per_detector(cells))))
    if args.data is not None:
        print(write_json_atomic(args.data, shipped_bound(outcomes, args.validation).to_json()))


if __name__ == "__main__":
    main()
