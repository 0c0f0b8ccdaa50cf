"""The cells of a sweep's grid, transform × level × detector, against their baselines.

Every transformed cell of a model is paired with its baseline, the same model on the same
images decoded and re-encoded without transform (:func:`cell_deltas`): ΔmAP in points,
``dmap_points = 100 * (mAP_baseline - mAP_cell)`` (percentage points of COCO
mAP@[.50:.95]), and relative, ``dmap_relative = 100 * (mAP_baseline - mAP_cell) /
mAP_baseline`` (percent of the baseline mAP); the same for the ΔAP of the safety classes,
person and bicycle (:func:`fidelity.coco.loss.loss_estimate`). Every done cell of a model is
scored on one image count (:func:`align_image_counts`) and gets standard errors
(:func:`add_standard_errors`). Nothing here knows what the level measures; it is named
``delta_e`` (the sweep cell's ``target``), colour's axis.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from fidelity.coco.bootstrap import Draws
from fidelity.coco.loss import loss_estimate, score_loss
from fidelity.coco.scoring import FoldScore, evaluate_detections, resolve_scorer
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepCell, SweepStore


#: Classes called safety-critical by SAFE-COLOR.
SAFETY_CLASSES: tuple[str, ...] = ("person", "bicycle")


@record
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


@record
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


@record
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


def finished_value(x: float | None) -> float:
    """A value a finished cell always has (its score, its loss); a ValueError when None."""
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


__all__ = [
    "SAFETY_CLASSES",
    "AlignedCount",
    "CellDelta",
    "CellErrors",
    "add_standard_errors",
    "align_image_counts",
    "cell_deltas",
    "finished_value",
    "model_size",
    "parse_image_caps",
]
