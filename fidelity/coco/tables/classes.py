"""Which classes a cell's loss comes from: per-class shares and the rare classes.

COCO mAP@[.50:.95] is the unweighted mean of the per-class APs, so a class with one box
weighs as much as person with thousands (:func:`class_breakdown`). The worst-case rows carry
the points of their ΔmAP that come from classes with at most :data:`RARE_BOXES` boxes
(:func:`rare_class_shares`); ``fidelity tables --explain`` breaks one stored cell down
(:func:`explain_cell`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.scoring import evaluate_detections
from fidelity.coco.tables.worst import RareShare, WorstCaseRow
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepCell, SweepStore


#: Classes with at most this many ground-truth boxes in a model's images count as rare.
RARE_BOXES = 5


@record
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


@record
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


@record
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
    ids = sorted(int(i) for i in image_ids)
    b = evaluate_detections(coco, baseline, ids, method=method)
    c = evaluate_detections(coco, cell, ids, method=method)
    return _breakdown(b.ap, c.ap, box_counts(coco, ids))


def box_counts(coco: Any, image_ids: Sequence[int]) -> dict[str, int]:
    """Non-crowd ground-truth boxes per class name in the images ``image_ids``."""
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
    """The worst-case rows with their :class:`~fidelity.coco.tables.worst.RareShare` (``rare``).

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


__all__ = [
    "RARE_BOXES",
    "CellExplanation",
    "ClassShare",
    "ShareGroup",
    "box_counts",
    "class_breakdown",
    "explain_cell",
    "rare_class_shares",
]
