"""Worst-case tables, plots and reports from a sweep store.

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
:func:`compare_with_paper` from the same numbers.
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.errors import InputFileError
from fidelity.fileio import portable_paths

#: Classes called safety-critical by SAFE-COLOR.
SAFETY_CLASSES: tuple[str, ...] = ("person", "bicycle")


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
    if base is None or value is None:
        return None, None
    pts = 100.0 * (base - value)
    rel = 100.0 * (base - value) / base if base > 0 else None
    return pts, rel


def cell_deltas(cells: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Per model: every done transformed cell with its ΔmAP and ΔAP (points and relative).

    Cells of a model without a finished baseline are left out, and so are done cells scored on
    another number of images than their model's baseline (a sweep caught while extending a
    model's image limit): a ΔmAP needs both scores on the same images.
    """
    by_model: dict[str, list[dict[str, Any]]] = {}
    base = {c["model"]: c for c in cells if c["transform"] == "baseline" and c["status"] == "done"}
    for c in cells:
        if c["transform"] == "baseline" or c["model"] not in base:
            continue
        b = base[c["model"]]
        if c["status"] == "done" and c.get("images") != b.get("images"):
            continue
        row: dict[str, Any] = {"model": c["model"], "transform": c["transform"],
                               "delta_e": float(c["target"]), "param": c["param"],
                               "status": c["status"], "reason": c.get("reason"),
                               "images": c.get("images")}
        if c["status"] == "done":
            row["map"] = c["map"]
            row["map50"] = c["map50"]
            row["dmap_points"], row["dmap_relative"] = _delta(b["map"], c["map"])
            for cls in SAFETY_CLASSES:
                bv = (b.get("ap") or {}).get(cls)
                cv = (c.get("ap") or {}).get(cls)
                row[f"ap_{cls}"] = cv
                row[f"dap_{cls}_points"], row[f"dap_{cls}_relative"] = _delta(bv, cv)
        by_model.setdefault(c["model"], []).append(row)
    return by_model


def parse_image_caps(spec: str | None, models: Sequence[str]) -> dict[str, int]:
    """``"500"`` (every model) or ``"yolov8n-int8dyn=500,yolov10n-int8dyn=500"`` -> model -> N.

    Raises :class:`fidelity.errors.InvalidValueError` naming the entry for a count that is not
    a positive integer or a model the store does not hold.
    """
    from fidelity.errors import InvalidValueError

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


def align_image_counts(store: Any, coco: Any, cells: Sequence[dict[str, Any]],
                       method: str = "auto", progress: bool = False,
                       images: Mapping[str, int] | None = None
                       ) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """Every done cell of a model scored on the same images: the first N by image id.

    N is the fewest images any done cell of the model (baseline included) was scored on, or
    ``images[model]`` where that is fewer (a report on an earlier state of a sweep that has
    moved on). A sweep caught while extending a model's image limit (``model.onnx@N`` raised)
    holds cells on the old and on the new count; the cells on more images are re-scored here
    on the first N from their stored detections (no inference; the store is not changed), so
    that every ΔmAP pairs a cell with its baseline on the same images and no row of the
    worst-case table is left partial. Returns the cells (re-scored ones carry
    ``rescored_from``, their stored count) and per model ``{"images": N, "rescored": k,
    "stored": sorted stored counts, "capped": whether images[model] set N}``.
    """
    from tqdm import tqdm

    from fidelity.coco.scoring import evaluate_detections, resolve_scorer

    method = resolve_scorer(method)
    ids_all = sorted(coco.getImgIds())
    counts: dict[str, set[int]] = {}
    for c in cells:
        if c["status"] == "done" and c.get("images"):
            counts.setdefault(c["model"], set()).add(int(c["images"]))
    common = {m: min(n) for m, n in counts.items()}
    caps = dict(images or {})
    capped = {m for m in common if m in caps and caps[m] < common[m]}
    common |= {m: caps[m] for m in capped}
    todo = [c for c in cells if c["status"] == "done" and c.get("images")
            and c["images"] > common[c["model"]]]
    rescored: dict[int, dict[str, Any]] = {}
    for c in tqdm(todo, desc="aligning image counts", unit="cell", disable=not progress):
        ids = ids_all[: common[c["model"]]]
        s = evaluate_detections(coco, store.detections(c["model"], c["transform"], c["target"]),
                                ids, method=method)
        rescored[id(c)] = c | {"map": s.map, "map50": s.map50, "map75": s.map75, "ap": s.ap,
                               "images": s.images, "rescored_from": c["images"]}
    out = [rescored.get(id(c), c) for c in cells]
    info = {m: {"images": common[m], "stored": sorted(counts[m]),
                "rescored": sum(c["model"] == m for c in todo), "capped": m in capped}
            for m in common}
    return out, info


def _max_or_none(values: list[float | None]) -> float | None:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return max(v) if v else None


def worst_case_rows(rows: Sequence[dict[str, Any]], baseline: dict[str, Any],
                    transforms: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Worst case over transforms at each ΔE for one model (see module docstring)."""
    by_de: dict[float, list[dict[str, Any]]] = {}
    for r in rows:
        by_de.setdefault(r["delta_e"], []).append(r)
    out = [{"delta_e": 0.0, "worst_transform": None, "dmap_points": 0.0, "dmap_relative": 0.0,
            "dap_person_points": 0.0, "dap_bicycle_points": 0.0, "dap_person_relative": 0.0,
            "dap_bicycle_relative": 0.0, "map": baseline["map"], "transforms_done": 0,
            "transforms_reachable": 0, "unreachable": [], "partial": False}]
    for de in sorted(by_de):
        group = by_de[de]
        done = [r for r in group if r["status"] == "done"]
        unreachable = sorted(r["transform"] for r in group if r["status"] == "unreachable")
        if not done:
            continue
        worst = max(done, key=lambda r: r["dmap_points"])
        reachable = (len(transforms) - len(unreachable)) if transforms else len(done)
        out.append({
            "delta_e": de, "worst_transform": worst["transform"],
            "dmap_points": worst["dmap_points"], "dmap_relative": worst["dmap_relative"],
            "dmap_points_se": worst.get("dmap_points_se"),
            "dmap_relative_se": worst.get("dmap_relative_se"),
            "map": worst["map"],
            "dap_person_points": _max_or_none([r.get("dap_person_points") for r in done]),
            "dap_bicycle_points": _max_or_none([r.get("dap_bicycle_points") for r in done]),
            "dap_person_relative": _max_or_none([r.get("dap_person_relative") for r in done]),
            "dap_bicycle_relative": _max_or_none([r.get("dap_bicycle_relative") for r in done]),
            "transforms_done": len(done), "transforms_reachable": reachable,
            "unreachable": unreachable, "partial": len(done) < reachable,
        })
    return out


def size_class_rows(per_model: dict[str, list[dict[str, Any]]]) -> dict[str, list[dict[str, Any]]]:
    """Worst case over the models of each size class, per ΔE."""
    groups: dict[str, list[str]] = {}
    for m in per_model:
        groups.setdefault(model_size(m), []).append(m)
    out: dict[str, list[dict[str, Any]]] = {}
    for size, models in sorted(groups.items()):
        des = sorted({r["delta_e"] for m in models for r in per_model[m]})
        rows = []
        for de in des:
            at_de = [(m, r) for m in models for r in per_model[m] if r["delta_e"] == de]
            # The worst case over the models whose row at this ΔE is complete (every reachable
            # transform measured); a partial row could understate it. Only when no model is
            # complete does the row fall back to the partial ones (and is marked partial).
            complete = [(m, r) for m, r in at_de if not r["partial"]]
            cand = complete or at_de
            m, w = max(cand, key=lambda mr: mr[1]["dmap_points"])
            rows.append({
                "delta_e": de, "worst_model": m, "worst_transform": w["worst_transform"],
                "dmap_points": w["dmap_points"], "dmap_points_se": w.get("dmap_points_se"),
                "dmap_relative": _max_or_none([r["dmap_relative"] for _, r in cand]),
                "dap_person_points": _max_or_none([r["dap_person_points"] for _, r in cand]),
                "dap_bicycle_points": _max_or_none([r["dap_bicycle_points"] for _, r in cand]),
                "models": len(cand), "model_names": [mm for mm, _ in cand],
                "partial": not complete,
            })
        out[size] = rows
    return out


def class_breakdown(coco: Any, baseline: Mapping[int, np.ndarray], cell: Mapping[int, np.ndarray],
                    image_ids: Sequence[int], method: str = "auto") -> list[dict[str, Any]]:
    """Which classes a cell's ΔmAP comes from: per class ΔAP and its share of the ΔmAP.

    COCO mAP@[.50:.95] is the unweighted mean of the per-class APs over the K classes that have
    ground truth in the evaluated images (COCO evaluation, Lin et al. 2014; classes without
    ground truth are skipped), so ΔmAP = Σ_c ΔAP_c / K: a class with one box weighs as much as
    person with thousands, and one detection ranked below a false positive halves that class's
    AP. ``baseline``, ``cell``: per-image (K, 6) detections (:mod:`fidelity.coco.sweep` store);
    ``image_ids``: the images both are scored on. Returns one row per class with ground truth:
    ``name``, ``boxes`` (non-crowd ground-truth boxes in the images), ``ap_baseline``, ``ap``
    (fractions), ``dap_points`` = 100 (AP₀ − AP), ``share_points`` = ``dap_points`` / K, sorted
    by share, largest loss first. The shares sum to the ΔmAP in points.
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
               boxes: Mapping[str, int]) -> list[dict[str, Any]]:
    names = [n for n, v in ap_base.items() if v is not None and ap_cell.get(n) is not None]
    rows = [{"name": n, "boxes": int(boxes.get(n, 0)), "ap_baseline": ap_base[n],
             "ap": ap_cell[n], "dap_points": 100.0 * (ap_base[n] - ap_cell[n])}  # type: ignore[operator]
            for n in names]
    for r in rows:
        r["share_points"] = r["dap_points"] / len(rows)
    return sorted(rows, key=lambda r: (-r["share_points"], r["name"]))


#: Classes with at most this many ground-truth boxes in a model's images count as rare.
RARE_BOXES = 5


def add_rare_class_shares(coco: Any, per_model: dict[str, list[dict[str, Any]]],
                          cells: Sequence[dict[str, Any]], baselines: dict[str, dict[str, Any]],
                          rare_boxes: int = RARE_BOXES) -> None:
    """Add ``dmap_points_rare``, ``rare_classes``, ``classes`` to the worst-case rows.

    ``dmap_points_rare``: the points of the row's ΔmAP that come from classes with at most
    ``rare_boxes`` ground-truth boxes in the model's images (:func:`class_breakdown` of the
    worst transform's cell against the baseline, from the per-class APs the cells were scored
    with, so that the shares add up to the row's ΔmAP); ``rare_classes`` of ``classes`` such
    classes. COCO mAP weighs every present class alike, so on a few hundred images these rows
    can be moved by one re-ranked detection of a one-box class.
    """
    ids_all = sorted(coco.getImgIds())
    ap = {(c["model"], c["transform"], float(c["target"])): c.get("ap") or {}
          for c in cells if c["status"] == "done"}
    boxes = {m: box_counts(coco, ids_all[: b["images"]]) for m, b in baselines.items()}
    for m, rows in per_model.items():
        for r in rows:
            if r["delta_e"] <= 0 or not r.get("worst_transform"):
                continue
            shares = _breakdown(baselines[m].get("ap") or {},
                                ap[(m, r["worst_transform"], float(r["delta_e"]))], boxes[m])
            rare = [x for x in shares if x["boxes"] <= rare_boxes]
            r["dmap_points_rare"] = float(sum(x["share_points"] for x in rare))
            r["rare_classes"] = len(rare)
            r["classes"] = len(shares)


def explain_cell(store: Any, coco: Any, model: str, transform: str, target: float, *,
                 images: int | None = None, rare_boxes: int = RARE_BOXES,
                 method: str = "auto"
                 ) -> dict[str, Any]:
    """:func:`class_breakdown` of one stored cell against its model's baseline.

    Both are scored from their stored detections on the first N images by id: N = ``images``,
    at most the smaller of the two cells' counts, which is the default (a report built while
    the model's limit is raised uses the model's common count: pass it to compare). ``rare``
    and ``common`` split the classes at
    ``rare_boxes`` ground-truth boxes: how many classes, their mean ΔAP and the points of ΔmAP
    they account for. Raises :class:`~fidelity.errors.InvalidValueError` naming the cell when it
    or the baseline is not a finished cell of the store.
    """
    from fidelity.errors import InvalidValueError

    found = {}
    for t, e in ((transform, float(target)), ("baseline", 0.0)):
        rec = store.cell(model, t, e)
        if rec is None or rec["status"] != "done":
            have = sorted({x["model"] for x in store.cells()})
            state = "not in the store" if rec is None else f"{rec['status']}"
            raise InvalidValueError(f"cell {model} {t} ΔE {e:g}: {state} (models: "
                                    f"{', '.join(have) or 'none'})")
        found[t] = rec
    n = min(int(found[transform]["images"]), int(found["baseline"]["images"]))
    if images is not None:
        if not 0 < images <= n:
            raise InvalidValueError(f"cell {model} {transform} ΔE {float(target):g}: --images "
                                    f"{images} is not in 1..{n} (images stored for the cell "
                                    "and its baseline)")
        n = int(images)
    ids = sorted(coco.getImgIds())[:n]
    rows = class_breakdown(coco, store.detections(model, "baseline", 0.0),
                           store.detections(model, transform, float(target)), ids, method)

    def part(sel: list[dict[str, Any]]) -> dict[str, Any]:
        return {"classes": len(sel),
                "mean_dap_points": float(np.mean([r["dap_points"] for r in sel])) if sel else None,
                "share_points": float(sum(r["share_points"] for r in sel))}

    return {"model": model, "transform": transform, "delta_e": float(target), "images": n,
            "dmap_points": float(sum(r["share_points"] for r in rows)), "rare_boxes": rare_boxes,
            "rare": part([r for r in rows if r["boxes"] <= rare_boxes]),
            "common": part([r for r in rows if r["boxes"] > rare_boxes]), "classes": rows}


def add_standard_errors(store: Any, coco: Any, deltas: dict[str, list[dict[str, Any]]],
                        baselines: dict[str, dict[str, Any]], method: str = "auto",
                        progress: bool = False) -> None:
    """Add ``dmap_points_se``, ``dmap_relative_se``, ``dap_person_points_se``,
    ``dap_bicycle_points_se`` to rows.

    Paired standard errors over :data:`fidelity.coco.scoring.FOLDS` interleaved image folds: per
    fold the loss of the cell against the baseline on the same images,
    ``SE = std(loss_k, ddof=1) / sqrt(K)`` (:func:`fidelity.coco.scoring.paired_standard_error`).
    Fold scores are computed from the stored detections (no inference) and cached in the store.
    """
    from tqdm import tqdm

    from fidelity.coco.scoring import paired_standard_error

    ids_all = sorted(coco.getImgIds())
    todo = [(m, r) for m, rows in deltas.items() for r in rows if r["status"] == "done"]
    base_folds: dict[str, list[dict[str, Any]]] = {}
    for m, r in tqdm(todo, desc="fold scores", unit="cell", disable=not progress):
        ids = ids_all[: baselines[m]["images"]]
        if m not in base_folds:
            base_folds[m] = store.fold_scores(coco, m, "baseline", 0.0, ids, method)
        folds = store.fold_scores(coco, m, r["transform"], r["delta_e"], ids, method)
        for key, col, relative in (("map", "dmap_points_se", False),
                                   ("map", "dmap_relative_se", True),
                                   ("person", "dap_person_points_se", False),
                                   ("bicycle", "dap_bicycle_points_se", False)):
            r[col] = paired_standard_error([f[key] for f in base_folds[m]],
                                           [f[key] for f in folds], relative=relative)


def build_tables(store: Any, coco: Any = None, *, method: str = "auto",
                 progress: bool = False, images: Mapping[str, int] | None = None
                 ) -> dict[str, Any]:
    """Everything the report needs, from a :class:`fidelity.coco.sweep.SweepStore`.

    ``coco``: the sweep's annotations (pycocotools ``COCO``); when given, every model's cells
    are scored on one image count (:func:`align_image_counts`; ``images`` caps it per model)
    and every done cell gets paired fold standard errors (:func:`add_standard_errors`).
    Without it, cells scored on another image count than their baseline are left out
    (:func:`cell_deltas`), there are no SEs, and ``images`` is an error.
    """
    cells = store.cells()
    if not cells:
        raise InputFileError(f"{store.path}: the sweep store has no finished cells yet")
    models = store.models()
    aligned: dict[str, dict[str, Any]] = {}
    if images and coco is None:
        from fidelity.errors import InvalidValueError

        raise InvalidValueError("--images needs the COCO annotations, to re-score cells on "
                                "fewer images: pass --annotations")
    if coco is not None:
        cells, aligned = align_image_counts(store, coco, cells, method, progress, images)
    deltas = cell_deltas(cells)
    baselines = {c["model"]: c for c in cells if c["transform"] == "baseline"
                 and c["status"] == "done"}
    if coco is not None:
        add_standard_errors(store, coco, deltas, baselines, method, progress)
    grid = store.meta().get("grid") or {}
    planned = grid.get("transforms")
    if not planned:
        from fidelity.prediction.transforms import TRANSFORMS

        planned = list(TRANSFORMS)
    seen = {c["transform"] for c in cells if c["transform"] != "baseline"}
    transforms = sorted(set(planned) | seen)
    per_model = {m: worst_case_rows(rows, baselines[m], transforms)
                 for m, rows in deltas.items()}
    for m in baselines:
        per_model.setdefault(m, worst_case_rows([], baselines[m], transforms))
    if coco is not None:
        add_rare_class_shares(coco, per_model, cells, baselines)
    return {
        "models": {m: {**models.get(m, {}), "size": model_size(m),
                       "baseline_map": baselines[m]["map"],
                       "baseline_map50": baselines[m]["map50"],
                       "baseline_ap": {k: baselines[m]["ap"].get(k) for k in SAFETY_CLASSES},
                       "images": baselines[m]["images"]} for m in baselines},
        "cells": deltas,
        "worst_case": per_model,
        "size_classes": size_class_rows(per_model),
        "meta": store.meta() | {"scorers": store.scorers()},
        "transforms": transforms,
        "cells_done": sum(c["status"] == "done" for c in cells),
        "cells_unreachable": sum(c["status"] == "unreachable" for c in cells),
        "standard_errors": coco is not None,
        "aligned": aligned,
        "rare_boxes": RARE_BOXES if coco is not None else None,
    }


def _beyond_noise(rows: Sequence[dict[str, Any]], key: str, bound: float) -> bool:
    """Whether some row's ``key`` exceeds ``bound`` by more than 2 of its standard errors
    (a row without an SE counts when it exceeds at all)."""
    for r in rows:
        v, se = r.get(key), r.get(key + "_se")
        if v is not None and v > bound + (2 * se if se else 0.0):
            return True
    return False


def _threshold_verdict(rows: Sequence[dict[str, Any]], bound: float) -> str:
    """The verdict on "worst-case ΔmAP stays below ``bound`` %" over worst-case ``rows``.

    The paper's "%" may be points or a share of the baseline, so both are tested: "agrees" if
    every relative loss is below the bound; "agrees if read as points" if only the points are;
    else "disagrees". Each exceedance is qualified "within 2 SE" where no row exceeds the
    bound by more than twice its standard error in that unit, else "beyond 2 SE" (the worst
    case over ten noisy transforms is biased upwards by about one SE); without standard
    errors, unqualified.
    """
    rel = max((r.get("dmap_relative") or 0.0) for r in rows)
    pts = max((r.get("dmap_points") or 0.0) for r in rows)
    if rel < bound:
        return "agrees"

    def by(key: str) -> str:
        if not any(r.get(key + "_se") for r in rows):  # no standard errors: no qualifier
            return ""
        return " (beyond 2 SE)" if _beyond_noise(rows, key, bound) else " (within 2 SE)"

    if pts < bound:
        return f"agrees if read as points; exceeded as a share of baseline{by('dmap_relative')}"
    return (f"disagrees: exceeded in points{by('dmap_points')} and as a share of "
            f"baseline{by('dmap_relative')}")


def compare_with_paper(tables: dict[str, Any]) -> list[dict[str, Any]]:
    """Check the SAFE-COLOR findings against our measurements; one dict per finding.

    Each has ``claim``, ``verdict`` ("agrees", "disagrees", "not enough data") and ``evidence``.
    """
    out: list[dict[str, Any]] = []
    cells = [r for rows in tables["cells"].values() for r in rows if r["status"] == "done"]
    # 1. harm ranking, per model: mean relative ΔmAP per transform over the ΔE values <= 12
    #    (every transform reaches them on the chart) at which that model has all transforms;
    #    the overall ranking averages the per-model means.
    planned = list(tables["transforms"])
    vals: dict[tuple[str, str, float], float] = {
        (r["model"], r["transform"], r["delta_e"]): r["dmap_relative"] for r in cells
        if r["dmap_relative"] is not None}
    per_model: dict[str, dict[str, float]] = {}
    used: dict[str, list[float]] = {}
    for m in sorted(tables["cells"]):
        common = sorted(d for d in {k[2] for k in vals if k[0] == m}
                        if d <= 12 and all((m, t, d) in vals for t in planned))
        if common and max(common) >= 6:  # at ΔE < 6 losses are within the scatter
            used[m] = common
            per_model[m] = {t: float(np.mean([vals[(m, t, d)] for d in common]))
                            for t in planned}
    if per_model:
        mean = {t: float(np.mean([pm[t] for pm in per_model.values()])) for t in planned}
        order = sorted(mean, key=mean.get, reverse=True)
        ranks = {m: sorted(pm, key=pm.get, reverse=True) for m, pm in per_model.items()}
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
        out.append({"claim": "contrast increase and decrease hurt detection most",
                    "verdict": "agrees" if set(order[:2]) == top
                    else "partly agrees" if set(order[:2]) & top else "disagrees",
                    "evidence": where + ev + ". Per model: " + per})
        out.append({"claim": "hue changes hurt least",
                    "verdict": "agrees" if order[-1] == "hue" else "disagrees",
                    "evidence": f"mildest: {order[-1]} ({mean[order[-1]]:.2f} %); hue "
                                f"{mean['hue']:.2f} %, rank {order.index('hue') + 1} of "
                                f"{len(order)} (1 = most harmful)"})
    else:
        for claim in ("contrast increase and decrease hurt detection most",
                      "hue changes hurt least"):
            out.append({"claim": claim, "verdict": "not enough data",
                        "evidence": "no model has all transforms at a ΔE in 6..12 yet"})
    # 2. worst transform, only where the worst loss stands out of the scatter: twice the sd of
    #    the relative ΔmAP over all cells at the smallest ΔE (measured noise floor).
    low_de = min((r["delta_e"] for r in cells), default=None)
    low = [r["dmap_relative"] for r in cells if r["delta_e"] == low_de
           and r["dmap_relative"] is not None]
    floor = 2 * float(np.std(low, ddof=1)) if len(low) >= 3 else 0.0
    worst = [(r["worst_transform"], r["delta_e"], r["partial"])
             for rows in tables["worst_case"].values() for r in rows
             if r["worst_transform"] and r["delta_e"] <= 24
             and (r["dmap_relative"] or 0) > floor]
    if worst:
        wset = {w for w, _, _ in worst}
        ok = wset <= {"contrast-inc", "contrast-dec", "saturation-inc"}
        others = sorted(f"{w} at ΔE {d:g}" for w, d, _ in worst
                        if w not in {"contrast-inc", "contrast-dec", "saturation-inc"})
        verdict = "agrees" if ok else "disagrees"
        if any(p for _, _, p in worst):
            verdict = "so far " + verdict + " (incomplete)"
        out.append({"claim": "worst case up to ΔE 24 is contrast-inc, contrast-dec or "
                             "saturation-inc",
                    "verdict": verdict,
                    "evidence": f"rows whose worst relative ΔmAP exceeds the noise floor "
                                f"{floor:.2f} % (2 sd at ΔE {low_de:g}): worst transforms "
                                + ", ".join(sorted(wset))
                                + (f"; exceptions: {', '.join(others)}" if others else "")})
    for limit, bound in ((3, 1.0), (6, 3.0), (12, 10.0)):
        vals = [(m, r) for m, rows in tables["worst_case"].items() for r in rows
                if 0 < r["delta_e"] <= limit]
        if not vals:
            out.append({"claim": f"ΔE ≤ {limit} keeps worst-case ΔmAP below {bound:g} %",
                        "verdict": "not enough data", "evidence": "no cells"})
            continue
        m_rel, r_rel = max(vals, key=lambda mr: mr[1]["dmap_relative"] or 0)
        m_pts, r_pts = max(vals, key=lambda mr: mr[1]["dmap_points"] or 0)
        rel, pts = r_rel["dmap_relative"], r_pts["dmap_points"]
        se = r_pts.get("dmap_points_se")
        verdict = _threshold_verdict([r for _, r in vals], bound)
        pts_text = f"{pts:.2f}" + (f" ± {se:.2f} SE" if se else "")
        se_rel = r_rel.get("dmap_relative_se")
        rel_text = f"{rel:.2f} %" + (f" ± {se_rel:.2f} SE" if se_rel else "")
        if r_pts.get("dmap_points_rare") is not None:
            pts_text += (f", of which {r_pts['dmap_points_rare']:.2f} from the "
                         f"{r_pts['rare_classes']} classes with at most "
                         f"{tables.get('rare_boxes')} boxes")
        partial = any(r["partial"] for _, r in vals)
        missing_de = sorted({d for d in (1, 2, 3, 4, 5, 6, 8, 10, 12) if d <= limit}
                            - {r["delta_e"] for _, r in vals})
        if not verdict.startswith("disagrees") and (partial or missing_de):
            verdict = "so far " + verdict + " (incomplete)"
        out.append({"claim": f"ΔE ≤ {limit} keeps worst-case ΔmAP below {bound:g} %",
                    "verdict": verdict,
                    "evidence": f"largest relative loss {rel_text} ({m_rel}, "
                                f"{r_rel['worst_transform']} at ΔE {r_rel['delta_e']:g}); "
                                f"largest loss in points {pts_text} ({m_pts}, "
                                f"{r_pts['worst_transform']} at ΔE {r_pts['delta_e']:g}); "
                                f"{sum(r['transforms_done'] for _, r in vals)} cells"
                                + (f"; ΔE not yet measured: {missing_de}" if missing_de else "")})
    for cls in SAFETY_CLASSES:
        more = total = 0
        for r in cells:
            rel_c = r.get(f"dap_{cls}_relative")
            if rel_c is None or r["dmap_relative"] is None or r["dmap_relative"] <= 0.5:
                continue
            total += 1
            more += rel_c > r["dmap_relative"]
        out.append({"claim": f"{cls} is more sensitive than the mean (relative ΔAP > ΔmAP)",
                    "verdict": "not enough data" if total == 0 else
                    ("agrees" if more > total / 2 else "disagrees"),
                    "evidence": f"{cls} lost more (relative) than mAP in {more} of {total} "
                                "cells with ΔmAP > 0.5 %"})
    return out


def prediction_table(tables: dict[str, Any], name: str = "coco1000-measured") -> dict[str, Any]:
    """A measured prediction table (CORE_API prediction-table schema) from the worst cases."""
    meta = tables["meta"]
    # Partial rows (a reachable transform not measured yet) could understate the worst case:
    # they stay in the report but not in the prediction table; provenance lists them.
    curves = []
    omitted: list[str] = []

    def complete_points(label: str, rows: list[dict[str, Any]],
                        source: Callable[[dict[str, Any]], str]) -> list[dict[str, Any]]:
        omitted.extend(f"{label} ΔE {r['delta_e']:g}" for r in rows if r["partial"])
        return [_point(r, source(r)) for r in rows if not r["partial"]]

    for size, rows in tables["size_classes"].items():
        curves.append({"size": size, "model": None, "points": complete_points(
            size, rows, lambda r, size=size: f"worst over {r['models']} model(s) of size {size}: "
                                  f"{', '.join(r.get('model_names', []))}")})
    for m, rows in tables["worst_case"].items():
        curves.append({"size": tables["models"][m]["size"], "model": m,
                       "baseline_map": tables["models"][m]["baseline_map"],
                       "baseline_ap": tables["models"][m].get("baseline_ap") or {},
                       "points": complete_points(m, rows, lambda r, m=m: f"{m} worst case over "
                                                 f"{r['transforms_done']} transforms")})
    return {
        "name": name,
        "title": "Measured worst-case detection loss on the shared COCO val2017 subset",
        "kind": "measured",
        "interpolation": "linear",
        "provenance": {
            "source": "fidelity sweep (issue 5): SAFE-COLOR transforms calibrated on the chart, "
                      "JPEG re-encoded with original tables, ONNX detectors, COCO box AP ("
                      + _scorer_words(meta.get("scorers")) + ")",
            "models": {m: {k: v for k, v in info.items() if k in ("file", "sha256", "size",
                                                                   "limit_images", "images",
                                                                   "baseline_map")}
                       | {"conventions": (info.get("settings") or {}).get("conventions")}
                       | ({"earlier_runs": (info.get("settings") or {})["earlier"]}
                          if (info.get("settings") or {}).get("earlier") else {})
                       for m, info in tables["models"].items()},
            "images": portable_paths(meta.get("data")), "versions": meta.get("versions"),
            "machine": meta.get("machine"),
            "cells_done": tables["cells_done"], "cells_unreachable": tables["cells_unreachable"],
            "worst_case": "per ΔE the transform with the largest ΔmAP in points; person and "
                          "bicycle columns are their own worst case over the same transforms",
            "omitted_partial_points": omitted,
            "aligned_image_counts": tables.get("aligned") or {},
        },
        "units": {
            "dmap_points": "percentage points of mAP@[.50:.95] (100*(baseline-transformed))",
            "dmap_relative": "percent of the baseline mAP",
            "dap_person_points": "percentage points of person AP@[.50:.95]",
            "dap_bicycle_points": "percentage points of bicycle AP@[.50:.95]",
        },
        "curves": curves,
    }


def _point(r: dict[str, Any], source: str) -> dict[str, Any]:
    return {"delta_e": r["delta_e"], "dmap_points": _round(r["dmap_points"]),
            "dmap_relative": _round(r["dmap_relative"]),
            "dap_person_points": _round(r["dap_person_points"]),
            "dap_bicycle_points": _round(r["dap_bicycle_points"]),
            "dmap_points_se": _round(r.get("dmap_points_se")),
            "worst_transform": r["worst_transform"], "source": source,
            "partial": bool(r.get("partial"))}


def _round(v: float | None, nd: int = 4) -> float | None:
    return None if v is None else round(float(v), nd)


# --------------------------------------------------------------------------------------------
# Plots and report


def _fig_png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return buf.getvalue()


def make_plots(tables: dict[str, Any]) -> dict[str, bytes]:
    """PNG plots: mAP vs ΔE per transform (per model), worst case per model, log degradation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out: dict[str, bytes] = {}
    for m, rows in tables["cells"].items():
        base = tables["models"][m]["baseline_map"]
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for t in tables["transforms"]:
            pts = sorted((r["delta_e"], r["map"]) for r in rows
                         if r["transform"] == t and r["status"] == "done")
            if pts:
                x, y = zip(*([(0.0, base)] + pts), strict=True)
                ax.plot(x, np.asarray(y) * 100, marker="o", ms=3, label=t)
        ax.set_xlabel("chart ΔE00 (mean over 24 patches)")
        ax.set_ylabel("mAP@[.50:.95] (%)")
        ax.set_title(f"{m}: mAP against ΔE per transform")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        out[f"map_vs_de_{m}.png"] = _fig_png(fig)
        plt.close(fig)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    lowest = np.inf  # smallest positive loss: the log axis starts just below it
    for m, rows in tables["worst_case"].items():
        x = np.array([r["delta_e"] for r in rows], dtype=float)
        y = np.array([r["dmap_relative"] for r in rows], dtype=float)
        se = np.array([np.nan if r.get("dmap_relative_se") is None
                       else 2.0 * r["dmap_relative_se"] for r in rows], dtype=float)
        (line,) = a1.plot(x, y, marker="o", ms=3, label=m)
        colour_ = line.get_color()
        bars = np.isfinite(se)
        if bars.any():
            a1.errorbar(x[bars], y[bars], yerr=se[bars], ls="none", color=colour_, lw=0.8,
                        capsize=2)
        part = [(r["delta_e"], r["dmap_relative"]) for r in rows if r["partial"]]
        if part:
            a1.plot(*zip(*part, strict=True), ls="none", marker="o", ms=8, mfc="white",
                    color=colour_)
        pos = y > 0
        if pos.any():
            lowest = min(lowest, float(y[pos].min()))
            a2.semilogy(x[pos], y[pos], marker="o", ms=3, label=m, color=colour_)
            b = pos & bars
            if b.any():  # on the log axis a bar stops just above zero
                lower = np.minimum(se[b], 0.95 * y[b])
                a2.errorbar(x[b], y[b], yerr=[lower, se[b]], ls="none", color=colour_,
                            lw=0.8, capsize=2)
    # SAFE-COLOR's claims as the step they make: < 1 % up to ΔE 3, < 3 % to 6, < 10 % to 12
    for ax in (a1, a2):
        ax.step([0, 3, 6, 12], [1, 1, 3, 10], where="pre", color="black", lw=1, ls="--",
                label="SAFE-COLOR bound (1 / 3 / 10 %)")
        ax.set_xlabel("chart ΔE00")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    a1.set_ylabel("worst-case ΔmAP (% of baseline)")
    a1.set_title("worst case per model, ±2 SE (open circle: not all transforms done)",
                 fontsize=10)
    if np.isfinite(lowest):  # bars reaching towards zero are cut at the axis
        a2.set_ylim(bottom=min(0.5, lowest / 2))
    a2.set_ylabel("worst-case ΔmAP (% of baseline, log)")
    a2.set_title("degradation on a log scale, ±2 SE", fontsize=10)
    out["worst_case.png"] = _fig_png(fig)
    plt.close(fig)
    return out


def _fmt(v: Any, nd: int = 2) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{nd}f}"
    return str(v)


def _conventions_words(conv: dict[str, Any]) -> str:
    """The post-processing thresholds in words: no NMS for an end-to-end head, no cap if None."""
    iou = conv.get("iou")
    max_det = conv.get("max_det")
    return (f"conf {conv.get('conf')}, "
            + ("no NMS (end-to-end)" if iou is None else f"NMS IoU {iou}") + ", "
            + ("no detection cap" if max_det is None else f"max_det {max_det}"))


def _run_history_words(info: dict[str, Any], capped: bool = False) -> str:
    """The sweep runs behind a model's cells, in words (its latest registration and the
    registrations it replaced, see :meth:`fidelity.coco.store.ResultsStore.register_model`);
    ``capped``: the image count was asked for (``--images``), not set by the cells."""
    st = info.get("settings") or {}
    limit, images = info.get("limit_images"), info.get("images")
    words = ""
    if limit and images and limit != images:
        which = f"first {images} asked for (`--images`)" if capped else (
            f"{images} that every cell has")
        words += (f" Latest run registered for the first {limit} images; reported on the "
                  f"{which}.")
    earlier = st.get("earlier") or []
    if earlier:
        runs = "; ".join(
            f"first {e.get('limit_images') or 'all'} images"
            + "".join(f", {k} {e[k]}" for k in ("threads", "providers") if k in e)
            for e in earlier)
        words += f" Earlier runs over the same file (oldest first): {runs}."
    return words


def _scorer_words(scorers: Sequence[dict[str, Any]] | None) -> str:
    """Which COCO scorers scored the store's cells, in words."""
    if not scorers:
        return "pycocotools"
    parts = [f"{e['scorer']}" + (f" from {e['since']}" if e.get("since") else "")
             for e in scorers]
    return ", then ".join(parts)


def report_markdown(tables: dict[str, Any], comparison: list[dict[str, Any]],
                    plots: Sequence[str] = (),
                    limits: list[dict[str, Any]] | None = None) -> str:
    """The Markdown report (``limits``: :func:`delta_e_limits`, after the paper comparison)."""
    meta = tables["meta"]
    lines = ["# COCO benchmark: measured cost of colour error", ""]
    lines.append(f"Cells finished: {tables['cells_done']} done, {tables['cells_unreachable']} "
                 "unreachable (transform cannot reach the ΔE on the chart).")
    v = meta.get("versions", {})
    lines.append(f"Versions: {', '.join(f'{k} {x}' for k, x in v.items())}. "
                 f"Machine: {meta.get('machine', {})}.")
    d = meta.get("data", {})
    lines.append(f"Images: {d.get('image_count')} shared COCO val2017 images "
                 "(person-biased subset, see shared/coco/PROVENANCE.md); a model swept on "
                 "fewer uses the first N by image id.")
    for m, a in (tables.get("aligned") or {}).items():
        if a.get("capped"):
            lines.append(f"- {m}: reported on the first {a['images']} images, as asked "
                         f"(`--images`; cells stored on {' and '.join(map(str, a['stored']))} "
                         f"images, re-scored from their stored detections: {a['rescored']}).")
        elif a["rescored"]:
            lines.append(f"- {m}: caught while its image limit was being raised (cells on "
                         f"{' and '.join(map(str, a['stored']))} images); reported on the first "
                         f"{a['images']}, so that every ΔmAP pairs a cell with its baseline on "
                         f"the same images (cells re-scored from their stored detections: "
                         f"{a['rescored']}).")
    lines += ["", "Method: each image is decoded as sRGB code values (ICC profiles not applied), "
              "transformed with the parameter calibrated on the chart for (transform, ΔE) "
              "(fidelity.prediction.calibration, full precision; listed per cell below), rounded to 8 bit "
              "(exact 8-bit tables, equal to the float64 reference), JPEG-encoded with the "
              "original quantization tables and subsampling, decoded, and passed to the "
              "detector; ΔE 0 is the baseline (decode and re-encode only). Scoring: COCO box AP "
              f"({_scorer_words(meta.get('scorers'))}; faster-coco-eval agrees with the "
              "pycocotools reference to 1e-4, tested). Detections of every image are stored, so any cell can be "
              "re-scored without inference (`fidelity sweep --rescore`)."]
    for m, info in tables["models"].items():
        st = info.get("settings") or {}
        lines.append(f"- {m}: file {info.get('file')} (sha256 {str(info.get('sha256'))[:16]}), "
                     f"layout {st.get('layout')}, input {st.get('input_size')}, providers "
                     f"{st.get('providers')}, {st.get('threads')} intra-op thread(s); "
                     f"{(st.get('conventions') or {}).get('source')}; "
                     f"{(st.get('conventions') or {}).get('preprocess')}."
                     + _run_history_words(
                         info, bool((tables.get("aligned") or {}).get(m, {}).get("capped"))))
    lines += ["", "ΔmAP in **points** = 100·(mAP₀ − mAP); **relative** = 100·(mAP₀ − mAP)/mAP₀. "
              "ΔAP person/bicycle in points, each the worst over transforms at that ΔE."]
    if tables.get("standard_errors"):
        ses = {m: [r["dmap_points_se"] for r in rows if r.get("dmap_points_se") is not None]
               for m, rows in tables["cells"].items()}
        medians = ", ".join(f"{m} {float(np.median(s)):.2f}" for m, s in ses.items() if s)
        lines.append("± values are standard errors of ΔmAP, paired over 5 interleaved image "
                     "folds (SE = sd of the per-fold losses / √5; for relative ΔmAP each "
                     "fold's loss as a share of that fold's baseline); in points median "
                     f"{medians} ({sum(map(len, ses.values()))} cells). A worst case "
                     "over ten transforms is biased upwards by this noise.")
    lines.append("")
    lines += ["## Models", "", "| model | size | images | baseline mAP | AP50 | AP person | "
              "AP bicycle | conventions |", "|---|---|---|---|---|---|---|---|"]
    for m, info in tables["models"].items():
        conv = (info.get("settings") or {}).get("conventions", {})
        ap = info["baseline_ap"]
        lines.append(f"| {m} | {info['size']} | {info['images']} | {info['baseline_map']:.4f} | "
                     f"{info['baseline_map50']:.4f} | {_fmt(ap.get('person'), 4)} | "
                     f"{_fmt(ap.get('bicycle'), 4)} | {_conventions_words(conv)} |")
    grid = meta.get("grid") or {}
    targets = sorted({float(t) for t in grid.get("targets", []) if float(t) > 0}
                     | {r["delta_e"] for rows in tables["cells"].values() for r in rows})
    lines += ["", "## Coverage (which cells this report is built from)", "",
              "✓ done, ✗ unreachable on the chart (recorded with its reason), · not yet run.", ""]
    for m in tables["models"]:
        have = {(r["transform"], r["delta_e"]): r["status"] for r in tables["cells"].get(m, [])}
        done = sum(v == "done" for v in have.values())
        unr = sum(v == "unreachable" for v in have.values())
        lines += [f"**{m}**: baseline + {done} transformed cells done, {unr} unreachable, "
                  f"{len(tables['transforms']) * len(targets) - done - unr} not yet run.", "",
                  "| ΔE | " + " | ".join(tables["transforms"]) + " |",
                  "|---|" + "---|" * len(tables["transforms"])]
        for de in targets:
            marks = [{"done": "✓", "unreachable": "✗"}.get(have.get((t, de), ""), "·")
                     for t in tables["transforms"]]
            lines.append(f"| {de:g} | " + " | ".join(marks) + " |")
        lines.append("")
    started = set(tables["models"])
    for spec in grid.get("models", []):
        stem = str(spec).split("@")[0].rsplit(".", 1)[0]
        if stem not in started:
            lines += [f"**{stem}** (planned as {spec}): not started yet.", ""]
    low = [r["dmap_relative"] for rows in tables["cells"].values() for r in rows
           if r["status"] == "done" and r["delta_e"] == min(targets or [0])
           and r["dmap_relative"] is not None]
    if len(low) >= 3:
        lines += [f"Noise floor: at ΔE {min(targets):g} the {len(low)} measured cells give "
                  f"relative ΔmAP from {min(low):.2f} % to {max(low):.2f} % (sd "
                  f"{float(np.std(low, ddof=1)):.2f} %); differences of that size between "
                  "transforms or against a threshold are within the scatter that any small "
                  "perturbation of the images causes on this image set, not findings.", ""]
    lines += ["", "## Comparison with SAFE-COLOR", "", "| paper's finding | ours | evidence |",
              "|---|---|---|"]
    for c in comparison:
        lines.append(f"| {c['claim']} | **{c['verdict']}** | {c['evidence']} |")
    if limits:
        lines += _limits_markdown(limits)
    rare_n = tables.get("rare_boxes")
    for m, rows in tables["worst_case"].items():
        rare_col = rare_n is not None and any("dmap_points_rare" in r for r in rows)
        lines += ["", f"## Worst case: {m}", ""]
        if rare_col:
            k = next((r for r in rows if "classes" in r), {})
            lines += [f"Of which rare: the points of ΔmAP that come from the "
                      f"{k.get('rare_classes', '?')} of {k.get('classes', '?')} classes with at "
                      f"most {rare_n} ground-truth boxes in the model's images (mAP weighs every "
                      "class alike; `fidelity tables STORE --explain MODEL:TRANSFORM:ΔE` lists "
                      "them).", ""]
        lines += ["| ΔE | worst transform | ΔmAP points |"
                  + (" of which rare |" if rare_col else "")
                  + " ΔmAP relative % | ΔAP person pts | ΔAP bicycle pts | transforms done | "
                  "unreachable |", "|---|---|---|" + ("---|" if rare_col else "")
                  + "---|---|---|---|---|"]
        for r in rows[1:]:
            se, se_rel = r.get("dmap_points_se"), r.get("dmap_relative_se")
            rare = f"{_fmt(r.get('dmap_points_rare'))} | " if rare_col else ""
            lines.append(f"| {r['delta_e']:g} | {r['worst_transform']} | "
                         f"{_fmt(r['dmap_points'])}{f' ± {se:.2f}' if se else ''} | {rare}"
                         f"{_fmt(r['dmap_relative'])}{f' ± {se_rel:.2f}' if se_rel else ''} | "
                         f"{_fmt(r['dap_person_points'])} | {_fmt(r['dap_bicycle_points'])} | "
                         f"{r['transforms_done']}/{r['transforms_reachable']}"
                         f"{' (partial)' if r['partial'] else ''} | "
                         f"{', '.join(r['unreachable']) or '–'} |")
    for size, rows in tables["size_classes"].items():
        lines += ["", f"## Worst case: size class {size}", "",
                  "| ΔE | worst model | worst transform | ΔmAP points | ΔmAP relative % | "
                  "ΔAP person pts | ΔAP bicycle pts |", "|---|---|---|---|---|---|---|"]
        lines.insert(len(lines) - 2, "Each column is its own worst case over the models of "
                     "this size (and their transforms); partial: a model or transform missing.")
        lines.insert(len(lines) - 2, "")
        for r in rows[1:]:
            lines.append(f"| {r['delta_e']:g}{' (partial)' if r['partial'] else ''} | "
                         f"{r['worst_model']} | {r['worst_transform']} | "
                         f"{_fmt(r['dmap_points'])} | {_fmt(r['dmap_relative'])} | "
                         f"{_fmt(r['dap_person_points'])} | {_fmt(r['dap_bicycle_points'])} |")
    for m, rows in tables["cells"].items():
        lines += ["", f"## All cells: {m}", "", "| transform | ΔE | param | mAP | ΔmAP pts | "
                  "ΔmAP rel % | ΔAP person pts | ΔAP bicycle pts |", "|---|---|---|---|---|---|---|---|"]
        for r in sorted(rows, key=lambda r: (r["transform"], r["delta_e"])):
            if r["status"] != "done":
                lines.append(f"| {r['transform']} | {r['delta_e']:g} | – | unreachable | | | | |")
                continue
            lines.append(f"| {r['transform']} | {r['delta_e']:g} | {r['param']:.4f} | "
                         f"{r['map']:.4f} | {_fmt(r['dmap_points'])} | "
                         f"{_fmt(r['dmap_relative'])} | {_fmt(r['dap_person_points'])} | "
                         f"{_fmt(r['dap_bicycle_points'])} |")
    if plots:
        lines += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"


def report_html(markdown: str, plots: dict[str, bytes]) -> str:
    """A self-contained HTML page: the Markdown tables as HTML plus the plots inlined."""
    body: list[str] = []
    in_table = False
    for line in markdown.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set("".join(cells)) <= set("-: "):
                continue
            if not in_table:
                body.append("<table>")
                in_table = True
                tag = "th"
            else:
                tag = "td"
            body.append("<tr>" + "".join(f"<{tag}>{_inline(c)}</{tag}>" for c in cells) + "</tr>")
            continue
        if in_table:
            body.append("</table>")
            in_table = False
        if line.startswith("!["):
            name = line[line.index("(") + 1:-1]
            if name in plots:
                b64 = base64.b64encode(plots[name]).decode()
                body.append(f'<p><img alt="{html.escape(name)}" src="data:image/png;base64,'
                            f'{b64}"></p>')
        elif line.startswith("# "):
            body.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line.startswith("## "):
            body.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.strip():
            body.append(f"<p>{_inline(line)}</p>")
    if in_table:
        body.append("</table>")
    style = ("body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:"
             "collapse;font-size:13px}td,th{border:1px solid #ccc;padding:2px 6px}img{max-width:"
             "100%}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>COCO benchmark</title>"
            f"<style>{style}</style></head><body>{''.join(body)}</body></html>\n")


def _inline(text: str) -> str:
    t = html.escape(text)
    return re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", t)


def write_report(store: Any, out_dir: str | os.PathLike[str],
                 prediction_path: str | os.PathLike[str] | None = None,
                 name: str = "coco1000-measured", coco: Any = None,
                 progress: bool = False, images: Mapping[str, int] | None = None
                 ) -> dict[str, Path]:
    """Write report.md, report.html, tables.json, plots and (optionally) the prediction table.

    ``coco``: annotations for standard errors; ``images``: per-model image caps (see
    :func:`build_tables`).
    """
    from fidelity.fileio import write_bytes_atomic, write_json_atomic, write_text_atomic

    out = Path(out_dir)
    tables = build_tables(store, coco, progress=progress, images=images)
    comparison = compare_with_paper(tables)
    limits = delta_e_limits(tables)
    plots = make_plots(tables)
    md = report_markdown(tables, comparison, sorted(plots), limits)
    written = {}
    for fname, data in plots.items():
        written[fname] = write_bytes_atomic(out / fname, data)
    written["report.md"] = write_text_atomic(out / "report.md", md)
    written["report.html"] = write_text_atomic(out / "report.html", report_html(md, plots))
    written["tables.json"] = write_json_atomic(out / "tables.json", _jsonable(
        {"tables": {k: v for k, v in tables.items()}, "comparison": comparison,
         "delta_e_limits": limits}))
    if prediction_path is not None:
        written["prediction"] = write_json_atomic(prediction_path,
                                                  _jsonable(prediction_table(tables, name)))
    return written


#: Loss budgets of :func:`delta_e_limits`: the paper's 1 / 3 / 10, read both ways.
LIMIT_BUDGETS: tuple[tuple[str, float], ...] = (
    ("dmap_relative", 1.0), ("dmap_relative", 3.0), ("dmap_relative", 10.0),
    ("dmap_points", 1.0), ("dmap_points", 3.0), ("dmap_points", 10.0))


def delta_e_limits(tables: dict[str, Any]) -> list[dict[str, Any]]:
    """The chart ΔE limits the measured worst cases imply, against the paper's ΔE 3 / 6 / 12.

    For every curve of the measured prediction table (each size class's worst case over its
    models, and each model's), the largest chart ΔE whose predicted loss stays within each of
    :data:`LIMIT_BUDGETS` (:func:`fidelity.prediction.table.delta_e_limit`: the curves as ``fidelity
    predict`` uses them, running maximum, linear between the measured ΔE).
    """
    from dataclasses import replace

    from fidelity.prediction.table import delta_e_limit, parse_prediction_table

    table = parse_prediction_table(_jsonable(prediction_table(tables)))
    out = []
    for curve in table.curves:
        if len(curve.delta_e) < 2:  # only the baseline measured: nothing to say
            continue
        one = replace(table, curves=(curve,))
        limits = []
        for column, budget in LIMIT_BUDGETS:
            lim = delta_e_limit(budget, column, size=curve.size, table=one)
            limits.append({"column": column, "budget": budget, "delta_e": lim.delta_e,
                           "status": lim.status})
        out.append({"size": curve.size, "model": curve.model, "limits": limits})
    return out


def _limits_markdown(limits: list[dict[str, Any]]) -> list[str]:
    from fidelity.prediction.table import limit_rounded_down

    def cell(x: dict[str, Any]) -> str:
        if x["status"] == "none":
            return "none"
        return (f"{limit_rounded_down(x['delta_e']):.2f}"
                + ("+" if x["status"] == "whole-range" else ""))

    head = [f"≤ {b:g} %" if c == "dmap_relative" else f"≤ {b:g} pts" for c, b in LIMIT_BUDGETS]
    lines = ["", "## ΔE limits our worst cases imply", "",
             "The largest chart ΔE00 at which the worst-case ΔmAP stays within each budget, as "
             "`fidelity predict --max-dmap P [--unit relative]` computes it from the curves "
             "(running maximum, linear between measured ΔE; rounded down to 0.01 as `predict` "
             "prints it). SAFE-COLOR's thresholds: ΔE 3 for 1 %, 6 for 3 %, 12 for 10 %. "
             "\"+\" = the budget holds over the whole table.", "",
             "| curve | " + " | ".join(head) + " |", "|---|" + "---|" * len(head)]
    for row in limits:
        name = (f"size {row['size']} (worst of its models)" if row["model"] is None
                else row["model"])
        lines.append(f"| {name} | " + " | ".join(cell(x) for x in row["limits"]) + " |")
    return lines


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
