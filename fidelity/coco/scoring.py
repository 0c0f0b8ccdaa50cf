"""COCO box AP with pycocotools as the reference implementation (faster-coco-eval as fast path).

mAP is COCO AP@[.50:.05:.95] (area "all", maxDets 100) averaged over the categories that have
ground truth in the evaluated images; AP50 at IoU 0.5; per-class AP is the same average for one
category (``precision[:, :, k, 0, -1]`` over valid recall points, as ``COCOeval.summarize``
computes it). All values are fractions in [0, 1]; a class without ground truth in the evaluated
images has AP ``None`` (pycocotools marks it -1).

Source: Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014, and the official
``pycocotools.cocoeval.COCOeval``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import logging
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import field
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.detectors import COCO80_CATEGORY_IDS
from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import display_path
from fidelity.core.record import record


@record
class CocoScore:
    """COCO box metrics of one detector run (fractions in [0, 1])."""

    map: float
    map50: float
    map75: float
    ap: dict[str, float | None]
    images: int
    detections: int
    stats: tuple[float, ...] = field(default=())

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict with ``map``, ``map50``, ``map75``, ``ap`` (name -> AP), ``images``."""
        return {"map": self.map, "map50": self.map50, "map75": self.map75, "ap": self.ap,
                "images": self.images, "detections": self.detections,
                "stats": list(self.stats)}


def _annotation_links(doc: Mapping[str, Any]) -> tuple[str, str] | None:
    """Ids unique, every annotation's image and category known."""
    for key in ("images", "categories"):
        ids = [item["id"] for item in doc[key]]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            return key, f"id {dup} is used twice"
    images = {im["id"] for im in doc["images"]}
    categories = {c["id"] for c in doc["categories"]}
    for k, ann in enumerate(doc["annotations"]):
        if ann["image_id"] not in images:
            return f"annotations[{k}].image_id", f"{ann['image_id']} is not an image id"
        if ann["category_id"] not in categories:
            return (f"annotations[{k}].category_id",
                    f"{ann['category_id']} is not a category id of the file")
    return None


def _box(doc: Mapping[str, Any]) -> tuple[str, str] | None:
    if doc["bbox"][2] < 0 or doc["bbox"][3] < 0:
        return "bbox", f"width and height must be >= 0, got {doc['bbox']}"
    return None


#: The parts of a COCO instances file that scoring reads (Lin et al. 2014, cocodataset.org
#: "Data format"): images (id, file_name), box annotations (id, image_id, category_id, bbox
#: [x, y, w, h] in pixels, area, iscrowd) and categories (id, name); at least one of each,
#: ids unique, every annotation's image and category present. Other fields pass unread.
COCO_SCHEMA = sc.Table(fields=(
    sc.Field("images", sc.ListOf(sc.Table(fields=(
        sc.Field("id", sc.Integer(), required=True),
        sc.Field("file_name", sc.String(nonempty=True), required=True),
        sc.Field("width", sc.Integer(lo=1)),
        sc.Field("height", sc.Integer(lo=1)),
    ), extra=True), min_items=1), required=True),
    sc.Field("annotations", sc.ListOf(sc.Table(fields=(
        sc.Field("id", sc.Integer(), required=True),
        sc.Field("image_id", sc.Integer(), required=True),
        sc.Field("category_id", sc.Integer(), required=True),
        sc.Field("bbox", sc.ListOf(sc.Number(), min_items=4, max_items=4,
                                   describe="[x, y, width, height], 4 finite numbers"),
                 required=True),
        sc.Field("area", sc.Number(lo=0.0), required=True),
        sc.Field("iscrowd", sc.Integer(lo=0, hi=1), default=0),
    ), extra=True, rules=(sc.Check(_box),)), min_items=1), required=True),
    sc.Field("categories", sc.ListOf(sc.Table(fields=(
        sc.Field("id", sc.Integer(), required=True),
        sc.Field("name", sc.String(nonempty=True), required=True),
    ), extra=True), min_items=1), required=True),
), extra=True, rules=(sc.Check(_annotation_links),))


def check_annotations(data: Any, origin: str) -> None:
    """Raise :class:`~fidelity.core.schema.SchemaError` ``<origin>: <field>: <problem>`` unless
    ``data`` is a COCO instances document scoring can use (:data:`COCO_SCHEMA`)."""
    sc.validate(data, COCO_SCHEMA, origin)


def load_annotations(path: str | os.PathLike[str]) -> Any:
    """Load a COCO annotation file, checked against :data:`COCO_SCHEMA`, into a quiet
    ``pycocotools.coco.COCO`` object."""
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{display_path(p)}: annotation file does not exist")
    data = sc.load_document(p, fmt="json", what="annotation file")
    check_annotations(data, display_path(p))
    return coco_from_dict(data)


def load_annotated_images(
    images: str | os.PathLike[str], annotations: str | os.PathLike[str]
) -> tuple[Path, Any, list[int]]:
    """The image folder, its COCO annotations and the image ids (ascending) of a run.

    Every annotated image must be present in ``images``; a missing folder or image is an
    :class:`~fidelity.core.errors.InputFileError` naming it.
    """
    img_dir = Path(images)
    if not img_dir.is_dir():
        raise InputFileError(f"{img_dir}: image folder does not exist")
    coco = load_annotations(annotations)
    all_ids = sorted(coco.getImgIds())
    missing = [i for i in all_ids if not (img_dir / coco.imgs[i]["file_name"]).is_file()]
    if missing:
        raise InputFileError(f"{img_dir}: {len(missing)} annotated images missing, e.g. "
                             f"{coco.imgs[missing[0]]['file_name']}")
    return img_dir, coco, all_ids


def coco_from_dict(data: Mapping[str, Any]) -> Any:
    """Build a ``COCO`` object from an in-memory annotation dict (no printing)."""
    from pycocotools.coco import COCO

    coco = COCO()
    coco.dataset = dict(data)
    with contextlib.redirect_stdout(io.StringIO()):
        coco.createIndex()
    return coco


def detections_to_coco(image_id: int, detections: np.ndarray,
                       category_ids: Sequence[int] = COCO80_CATEGORY_IDS) -> list[dict[str, Any]]:
    """Convert (K, 6) ``x1, y1, x2, y2, score, class-index`` rows into COCO result dicts."""
    rows = np.asarray(detections, dtype=np.float64).reshape(-1, 6).tolist()  # Python floats
    cats = [int(c) for c in category_ids]
    image = int(image_id)
    return [{"image_id": image, "category_id": cats[int(c)],
             "bbox": [round(x1, 3), round(y1, 3), round(x2 - x1, 3), round(y2 - y1, 3)],
             "score": round(s, 5)} for x1, y1, x2, y2, s, c in rows]


def coco_results(coco_gt: Any, detections: Mapping[int, np.ndarray],
                  ids: Sequence[int]) -> list[dict[str, Any]]:
    """The COCO result dicts of the images ``ids``, in that order."""
    per_image = _results_by_image(coco_gt, detections, ids)
    return [r for i in ids for r in per_image.get(i, ())]


def _results_by_image(coco_gt: Any, detections: Mapping[int, np.ndarray],
                      ids: Iterable[int]) -> dict[int, list[dict[str, Any]]]:
    """Image id -> its COCO result dicts (:func:`detections_to_coco`; images with none left
    out), category indices mapped as the annotations' 80 categories."""
    cat_ids = sorted(coco_gt.getCatIds())
    mapping: Sequence[int] = cat_ids if len(cat_ids) == len(COCO80_CATEGORY_IDS) \
        else COCO80_CATEGORY_IDS
    out: dict[int, list[dict[str, Any]]] = {}
    for i in ids:
        det = detections.get(i)
        if det is not None and len(det):
            out[i] = detections_to_coco(i, det, mapping)
    return out


def evaluated_pycocotools(coco_gt: Any, results: list[dict[str, Any]], ids: Sequence[int],
                          area_all_only: bool = False) -> Any:
    """``pycocotools.COCOeval`` (box) of ``results`` on ``ids`` after ``evaluate()`` (the
    per-image matches in ``evalImgs``); ``area_all_only``: only the area range "all"."""
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        if results:
            coco_dt = coco_gt.loadRes(results)
        else:
            coco_dt = coco_from_dict({"images": coco_gt.dataset["images"], "annotations": [],
                                      "categories": coco_gt.dataset["categories"]})
        ev = COCOeval(coco_gt, coco_dt, "bbox")
        ev.params.imgIds = list(ids)
        if area_all_only:
            ev.params.areaRng = [[0.0, 1e5 ** 2]]
            ev.params.areaRngLbl = ["all"]
        ev.evaluate()
    return ev


def _accumulate_pycocotools(coco_gt: Any, results: list[dict[str, Any]],
                            ids: Sequence[int]) -> tuple[np.ndarray, list[int], np.ndarray]:
    """(precision (T, R, K, A, M), catIds, stats) with the official ``pycocotools.COCOeval``."""
    ev = evaluated_pycocotools(coco_gt, results, ids)
    with contextlib.redirect_stdout(io.StringIO()):
        ev.accumulate()
        ev.summarize()
    return ev.eval["precision"], list(ev.params.catIds), np.asarray(ev.stats, dtype=np.float64)


def _accumulate_faster_coco_eval(coco_gt: Any, results: list[dict[str, Any]],
                                 ids: Sequence[int]) -> tuple[np.ndarray, list[int], np.ndarray]:
    """The same with ``faster_coco_eval.COCOeval_faster`` (C++ evaluate/accumulate).

    The ground truth is rebuilt from ``coco_gt.dataset`` (a pycocotools ``COCO``), so both
    methods score exactly the same annotations.
    """
    from faster_coco_eval import COCO as FasterCOCO
    from faster_coco_eval import COCOeval_faster

    quiet = logging.getLogger("faster_coco_eval").debug
    gt = FasterCOCO(dict(coco_gt.dataset), print_function=quiet)
    if results:
        dt = gt.loadRes(results)
    else:
        dt = FasterCOCO({"images": coco_gt.dataset["images"], "annotations": [],
                         "categories": coco_gt.dataset["categories"]}, print_function=quiet)
    ev = COCOeval_faster(gt, dt, "bbox", print_function=quiet)
    ev.params.imgIds = list(ids)
    ev.evaluate()
    ev.accumulate()
    ev.summarize()
    return (np.asarray(ev.eval["precision"]), list(ev.params.catIds),
            np.asarray(ev.stats[:12], dtype=np.float64))


#: COCO box scorers, by ``method=`` name. ``pycocotools`` is the reference; ``faster-coco-eval``
#: (same algorithm in C++) is the fast path, used only because
#: ``tests/coco/test_scoring.py`` shows it agrees with pycocotools to 1e-4 on our data.
COCO_SCORERS: dict[str, Callable[[Any, list[dict[str, Any]], Sequence[int]],
                                 tuple[np.ndarray, list[int], np.ndarray]]] = {
    "pycocotools": _accumulate_pycocotools,
    "faster-coco-eval": _accumulate_faster_coco_eval,
}


def scorer_available(method: str) -> bool:
    """Whether the package behind scorer ``method`` can be imported."""
    module = {"pycocotools": "pycocotools", "faster-coco-eval": "faster_coco_eval"}.get(method)
    if module is None:
        raise unknown_name("COCO scorer", method, list(COCO_SCORERS) + ["auto"])
    return importlib.util.find_spec(module) is not None


def resolve_scorer(method: str = "auto") -> str:
    """``auto``: ``faster-coco-eval`` when installed, else ``pycocotools``; else ``method``."""
    if method == "auto":
        return "faster-coco-eval" if scorer_available("faster-coco-eval") else "pycocotools"
    if not scorer_available(method):
        raise InvalidValueError(f"COCO scorer {method!r} is not installed")
    return method


def evaluate_detections(coco_gt: Any, detections: Mapping[int, np.ndarray],
                        image_ids: Sequence[int] | None = None,
                        method: str = "pycocotools") -> CocoScore:
    """Score per-image (K, 6) detections against ground truth with COCO box AP.

    ``image_ids``: the images evaluated (default: the keys of ``detections``). An image without
    detections still counts (its ground truth is missed). ``method``: a key of
    :data:`COCO_SCORERS` or ``"auto"`` (:func:`resolve_scorer`).
    """
    ids = sorted(int(i) for i in (image_ids if image_ids is not None else detections))
    if not ids:
        raise InvalidValueError("no images to evaluate")
    _check_annotated(coco_gt, ids)
    return _score_results(coco_gt, coco_results(coco_gt, detections, ids), ids, method)


def _check_annotated(coco_gt: Any, ids: Sequence[int]) -> None:
    """An error naming the first image ids the annotations do not have."""
    known = set(coco_gt.getImgIds())
    missing = [i for i in ids if i not in known]
    if missing:
        raise InvalidValueError(f"image ids not in the annotations: {missing[:5]}")


def _score_results(coco_gt: Any, results: list[dict[str, Any]], ids: list[int],
                   method: str) -> CocoScore:
    """:func:`evaluate_detections` of COCO result dicts already made (``ids`` sorted)."""
    scorer = COCO_SCORERS[resolve_scorer(method)]
    precision, cat_list, stats_arr = scorer(coco_gt, results, ids)
    ap: dict[str, float | None] = {}
    names = {c["id"]: c["name"] for c in coco_gt.dataset["categories"]}
    for k, cid in enumerate(cat_list):
        p = precision[:, :, k, 0, -1]
        p = p[p > -1]
        ap[names[cid]] = float(np.mean(p)) if p.size else None
    stats = tuple(float(s) for s in stats_arr)
    return CocoScore(map=max(stats[0], 0.0), map50=max(stats[1], 0.0), map75=max(stats[2], 0.0),
                     ap=ap, images=len(ids), detections=len(results), stats=stats)


#: Interleaved image folds used for standard errors (validation and sweep tables).
FOLDS: int = 5


@record
class FoldScore:
    """COCO scores of one image fold (fractions in [0, 1]; None: no ground truth of the class
    in the fold), as the stores keep them for standard errors (:func:`score_folds`).

    ``rest_map``, ``rest_person``, ``rest_bicycle``: the same scores of every *other* image of
    the run (the run without this fold), for the leave-one-fold-out jackknife standard error of
    a loss on the whole run (:func:`fidelity.coco.loss.jackknife_standard_error`); None where
    not computed (stores written before they were) or not defined.
    """

    map: float
    person: float | None
    bicycle: float | None
    images: int
    rest_map: float | None = None
    rest_person: float | None = None
    rest_bicycle: float | None = None

    def value(self, key: str) -> float | None:
        """The score named ``key``: ``"map"``, ``"person"`` or ``"bicycle"``."""
        return {"map": self.map, "person": self.person, "bicycle": self.bicycle}[key]

    def rest_value(self, key: str) -> float | None:
        """The score ``key`` of the run without this fold (None: not computed or defined)."""
        return {"map": self.rest_map, "person": self.rest_person,
                "bicycle": self.rest_bicycle}[key]

    @property
    def has_rest(self) -> bool:
        """Whether the scores of the rest of the run were computed."""
        return self.rest_map is not None

    def to_json(self) -> dict[str, Any]:
        """``{"map", "person", "bicycle", "images"}`` and, when computed, ``"rest": {"map",
        "person", "bicycle"}`` (the stores' format)."""
        out: dict[str, Any] = {"map": self.map, "person": self.person, "bicycle": self.bicycle,
                               "images": self.images}
        if self.has_rest:
            out["rest"] = {"map": self.rest_map, "person": self.rest_person,
                           "bicycle": self.rest_bicycle}
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FoldScore:
        """Inverse of :meth:`to_json`."""
        rest = data.get("rest") or {}
        return cls(data["map"], data.get("person"), data.get("bicycle"), int(data["images"]),
                   rest.get("map"), rest.get("person"), rest.get("bicycle"))


def score_folds(coco_gt: Any, detections: Mapping[int, np.ndarray], image_ids: Sequence[int],
                folds: int = FOLDS, method: str = "pycocotools",
                rest: bool = True) -> list[FoldScore]:
    """Scores of ``folds`` interleaved image folds (``ids[k::folds]``), for standard errors.

    Returns one :class:`FoldScore` per fold (mAP, person and bicycle AP, images) and, with
    ``rest``, the scores of the run without that fold (``FoldScore.rest_*``: what the
    leave-one-fold-out jackknife of a whole-run loss needs; about ``folds - 1`` times the
    scoring work of the run). With fewer images than folds each image is a fold; with fewer
    than 2 images, no folds. Standard errors from them:
    :func:`fidelity.coco.loss.loss_estimate`.
    """
    ids = sorted(int(i) for i in image_ids)
    n = min(int(folds), len(ids))
    out = []
    if n >= 2:
        _check_annotated(coco_gt, ids)
    per_image = _results_by_image(coco_gt, detections, ids) if n >= 2 else {}

    def score(subset: list[int]) -> CocoScore:  # the run's result dicts, made once
        return _score_results(coco_gt, [r for i in subset for r in per_image.get(i, ())],
                              subset, method)

    for k in range(n if n >= 2 else 0):
        fold = ids[k::n]
        s = score(fold)
        r: tuple[float | None, float | None, float | None] = (None, None, None)
        if rest:
            left = set(fold)
            o = score([i for i in ids if i not in left])
            r = (o.map, o.ap.get("person"), o.ap.get("bicycle"))
        out.append(FoldScore(s.map, s.ap.get("person"), s.ap.get("bicycle"), len(fold), *r))
    return out


# --------------------------------------------------------------------------------------------
# Ultralytics' own AP (what ``yolo val`` prints as mAP50-95)

#: IoU thresholds of AP@[.50:.95] (Ultralytics ``DetectionValidator.iouv``).
ULTRALYTICS_IOU_THRESHOLDS: np.ndarray = np.linspace(0.5, 0.95, 10)
_AP_RECALL = np.linspace(0.0, 1.0, 101)
_trapezoid: Callable[..., Any] = getattr(np, "trapezoid", None) or getattr(np, "trapz")  # noqa: B009


@record
class UltralyticsScore:
    """Ultralytics box metrics of one detector run (fractions in [0, 1]).

    ``map`` (mAP50-95), ``map50``, ``map75``: means over the classes with ground truth in the
    evaluated images; ``ap``: AP50-95 per class name (``None`` without ground truth);
    ``targets``: ground-truth boxes counted (crowd and empty boxes are not); ``version``: the
    Ultralytics rules followed (:data:`ULTRALYTICS_RULES`).
    """

    map: float
    map50: float
    map75: float
    ap: dict[str, float | None]
    images: int
    detections: int
    targets: int
    version: str

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict of every field."""
        return {"map": self.map, "map50": self.map50, "map75": self.map75, "ap": self.ap,
                "images": self.images, "detections": self.detections,
                "targets": self.targets, "version": self.version}


def box_iou(a: np.ndarray, b: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """IoU matrix (M, N) of ``x1, y1, x2, y2`` boxes: ``inter / (area_a + area_b - inter + eps)``.

    The formula of Ultralytics ``metrics.box_iou`` (eps 1e-7 in the denominator), in float64.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(2)
    area_a = (a[:, 2:] - a[:, :2]).prod(1)
    area_b = (b[:, 2:] - b[:, :2]).prod(1)
    return np.asarray(inter / (area_a[:, None] + area_b[None, :] - inter + eps))


def match_by_confidence(iou: np.ndarray, thresholds: np.ndarray = ULTRALYTICS_IOU_THRESHOLDS
                        ) -> np.ndarray:
    """Correct-detection matrix (N, T) of one image, Ultralytics >= 8.4 (``match_predictions``).

    ``iou``: (M targets, N detections), zero where the classes differ; detections in
    descending confidence. Per threshold, each detection in turn takes the unclaimed target
    with the highest IoU (the first on ties) and is correct when that IoU reaches the
    threshold (``>=``); a target is claimed once. COCO's greedy matching, one image at a time.
    """
    m, n = iou.shape
    correct = np.zeros((n, len(thresholds)), dtype=bool)
    if m == 0 or n == 0:
        return correct
    claimed = np.zeros((m, len(thresholds)), dtype=bool)
    cols = np.arange(len(thresholds))
    for j in np.flatnonzero((iou >= thresholds.min()).any(0)):
        available = np.where(claimed, 0.0, iou[:, j, None])
        k = available.argmax(0)
        correct[j] = available[k, cols] >= thresholds
        claimed[k, cols] |= correct[j]
    return correct


def match_by_iou(iou: np.ndarray, thresholds: np.ndarray = ULTRALYTICS_IOU_THRESHOLDS
                 ) -> np.ndarray:
    """Correct-detection matrix (N, T) of one image, Ultralytics 8.3 (``match_predictions``).

    Per threshold, of the (target, detection) pairs with IoU at or above it each detection
    keeps its highest-IoU pair, and of those each target keeps the one of the first detection
    (the most confident); the rest are false positives. (Ultralytics breaks exact IoU ties
    by its unstable sort order, here by target order.)
    """
    m, n = iou.shape
    correct = np.zeros((n, len(thresholds)), dtype=bool)
    for t, thr in enumerate(thresholds):
        gi, dj = np.nonzero(iou >= thr)
        if not gi.size:
            continue
        order = np.argsort(-iou[gi, dj], kind="stable")
        gi, dj = gi[order], dj[order]
        _, first_d = np.unique(dj, return_index=True)  # best pair of each detection,
        gi, dj = gi[first_d], dj[first_d]  # now in detection order
        _, first_g = np.unique(gi, return_index=True)  # then each target's first detection
        correct[dj[first_g], t] = True
    return correct


def average_precision_101(recall: np.ndarray, precision: np.ndarray, drop_to_zero: bool = True
                          ) -> float:
    """101-point interpolated AP of one precision/recall curve (Ultralytics ``compute_ap``).

    Sentinels (0, 1) before the curve; after it, ``drop_to_zero`` (8.4): precision 0 from
    the last recall on (``(r_last, 0), (1, 0)``); else (8.3) one point ``(1, 0)``, so that
    the precision falls linearly from the last point to recall 1. The precision envelope
    (running maximum from the right) is sampled at recall 0, 0.01, ..., 1 with ``np.interp``
    and integrated with the trapezoid rule.
    """
    r = np.asarray(recall, dtype=np.float64)
    p = np.asarray(precision, dtype=np.float64)
    if drop_to_zero:
        mrec = np.concatenate(([0.0], r, [r[-1] if len(r) else 1.0], [1.0]))
        mpre = np.concatenate(([1.0], p, [0.0], [0.0]))
    else:
        mrec = np.concatenate(([0.0], r, [1.0]))
        mpre = np.concatenate(([1.0], p, [0.0]))
    mpre = np.flip(np.maximum.accumulate(np.flip(mpre)))
    return float(_trapezoid(np.interp(_AP_RECALL, mrec, mpre), _AP_RECALL))


@record
class UltralyticsRules:
    """What changed between Ultralytics versions in the detection metric."""

    match: Callable[[np.ndarray, np.ndarray], np.ndarray]
    drop_to_zero: bool  # AP sentinel after the last recall
    clip_detections: bool  # IoU on boxes clipped to the image (8.3) or as predicted (8.4)
    description: str


#: Ultralytics' detection-metric rules by version: ``"8.4"`` (8.4.x, current) and ``"8.3"``.
ULTRALYTICS_RULES: dict[str, UltralyticsRules] = {
    "8.4": UltralyticsRules(match_by_confidence, True, False,
                            "Ultralytics 8.4: confidence-ordered matching, precision 0 after "
                            "the last recall, IoU on unclipped boxes"),
    "8.3": UltralyticsRules(match_by_iou, False, True,
                            "Ultralytics 8.3: IoU-ordered matching, precision falls linearly "
                            "to recall 1, IoU on boxes clipped to the image"),
}


def _ultralytics_targets(coco_gt: Any, image_id: int, index: Mapping[int, int]
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth of one image as Ultralytics loads it: (M, 4) xyxy boxes and class indices.

    Crowd annotations are dropped (Ultralytics' COCO conversion skips ``iscrowd``), as are
    boxes with zero width or height and exact duplicates (first kept).
    """
    boxes, classes, seen = [], [], set()
    for a in coco_gt.imgToAnns.get(image_id, []):
        if a.get("iscrowd", 0) or a["category_id"] not in index:
            continue
        x, y, w, h = (float(v) for v in a["bbox"])
        if w <= 0 or h <= 0:
            continue
        key = (index[a["category_id"]], x, y, w, h)
        if key in seen:
            continue
        seen.add(key)
        boxes.append([x, y, x + w, y + h])
        classes.append(index[a["category_id"]])
    return (np.asarray(boxes, dtype=np.float64).reshape(-1, 4),
            np.asarray(classes, dtype=np.intp))


def ultralytics_ap(coco_gt: Any, detections: Mapping[int, np.ndarray],
                   image_ids: Sequence[int] | None = None, version: str = "8.4"
                   ) -> UltralyticsScore:
    """Ultralytics' own box mAP of per-image (K, 6) detections (``yolo val``'s mAP50-95).

    Per image (ascending id), detections in descending confidence are matched to the
    non-crowd ground truth of the same class at the 10 IoU thresholds 0.50:0.05:0.95
    (:data:`ULTRALYTICS_RULES` ``[version].match``). Over all images, per class with ground
    truth: detections sorted by confidence (``np.argsort(-conf)``, as Ultralytics), recall =
    TP / targets, precision = TP / (TP + FP), AP = :func:`average_precision_101` of the
    precision envelope. mAP is the mean over classes with ground truth (a class with no
    detection counts 0). Differences from COCO AP (:func:`evaluate_detections`): crowd boxes
    are not ignore regions (a detection on one is a false positive), no 100-detection cap
    and no area ranges, one trapezoid-integrated curve instead of the mean of 101 samples.
    ``detections`` should be unclipped for ``"8.4"`` (``Detector(..., clip=False)``), which
    computes IoU on the boxes as predicted; ``"8.3"`` clips them to the image first.
    Source: Ultralytics 8.4.190 / 8.3.143, ``utils/metrics.py`` (``ap_per_class``,
    ``compute_ap``), ``engine/validator.py`` (``match_predictions``).
    """
    if version not in ULTRALYTICS_RULES:
        raise unknown_name("Ultralytics metric version", version, list(ULTRALYTICS_RULES))
    rules = ULTRALYTICS_RULES[version]
    ids = sorted(int(i) for i in (image_ids if image_ids is not None else detections))
    if not ids:
        raise InvalidValueError("no images to evaluate")
    cat_ids = sorted(coco_gt.getCatIds())
    mapping: Sequence[int] = cat_ids if len(cat_ids) == len(COCO80_CATEGORY_IDS) \
        else COCO80_CATEGORY_IDS
    index = {int(c): k for k, c in enumerate(mapping)}
    cat_names = {c["id"]: c["name"] for c in coco_gt.dataset["categories"]}
    tps, confs, pred_cls, target_cls = [], [], [], []
    for i in ids:
        if i not in coco_gt.imgs:
            raise InvalidValueError(f"image id not in the annotations: {i}")
        gt_boxes, gt_cls = _ultralytics_targets(coco_gt, i, index)
        d = np.asarray(detections.get(i, np.zeros((0, 6))), dtype=np.float32).reshape(-1, 6)
        d = d[np.argsort(-d[:, 4], kind="stable")]
        if rules.clip_detections:
            img = coco_gt.imgs[i]
            d[:, [0, 2]] = np.clip(d[:, [0, 2]], 0, img["width"])
            d[:, [1, 3]] = np.clip(d[:, [1, 3]], 0, img["height"])
        dc = d[:, 5].astype(np.intp)
        iou = box_iou(gt_boxes, d[:, :4]) * (gt_cls[:, None] == dc[None, :])
        tps.append(rules.match(iou, ULTRALYTICS_IOU_THRESHOLDS))
        confs.append(d[:, 4])
        pred_cls.append(dc)
        target_cls.append(gt_cls)
    tp = np.concatenate(tps)
    conf = np.concatenate(confs).astype(np.float32)
    pcls = np.concatenate(pred_cls)
    tcls = np.concatenate(target_cls)
    order = np.argsort(-conf)
    tp, pcls = tp[order], pcls[order]
    classes, n_targets = np.unique(tcls, return_counts=True)
    ap = np.zeros((len(classes), len(ULTRALYTICS_IOU_THRESHOLDS)))
    for ci, (c, n_l) in enumerate(zip(classes, n_targets, strict=True)):
        sel = pcls == c
        if not sel.any():
            continue
        tpc = tp[sel].cumsum(0)
        fpc = (1 - tp[sel]).cumsum(0)
        recall = tpc / (n_l + 1e-16)
        precision = tpc / (tpc + fpc)
        for t in range(ap.shape[1]):
            ap[ci, t] = average_precision_101(recall[:, t], precision[:, t], rules.drop_to_zero)
    per_class: dict[str, float | None] = {cat_names.get(int(c), str(c)): None for c in mapping}
    for ci, c in enumerate(classes):
        per_class[cat_names.get(int(mapping[c]), str(mapping[c]))] = float(ap[ci].mean())
    has = len(classes) > 0
    return UltralyticsScore(
        map=float(ap.mean()) if has else 0.0, map50=float(ap[:, 0].mean()) if has else 0.0,
        map75=float(ap[:, 5].mean()) if has else 0.0, ap=per_class, images=len(ids),
        detections=int(len(conf)), targets=int(len(tcls)), version=version)
