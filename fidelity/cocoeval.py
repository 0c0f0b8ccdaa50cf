"""COCO box AP with pycocotools as the reference implementation.

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
import io
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.detectors import COCO80_CATEGORY_IDS
from fidelity.errors import InputFileError, InvalidValueError


@dataclass(frozen=True)
class CocoScore:
    """COCO box metrics of one detector run (fractions in [0, 1])."""

    map: float
    map50: float
    map75: float
    ap: dict[str, float | None]
    images: int
    detections: int
    stats: tuple[float, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with ``map``, ``map50``, ``map75``, ``ap`` (name -> AP), ``images``."""
        return {"map": self.map, "map50": self.map50, "map75": self.map75, "ap": self.ap,
                "images": self.images, "detections": self.detections,
                "stats": list(self.stats)}


def load_annotations(path: str | os.PathLike[str]) -> Any:
    """Load a COCO annotation file into a quiet ``pycocotools.coco.COCO`` object."""

    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: annotation file does not exist")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{p}: not a readable COCO JSON file: {exc}") from exc
    for key in ("images", "annotations", "categories"):
        if key not in data:
            raise InputFileError(f"{p}: COCO annotation file lacks the {key!r} list")
    return coco_from_dict(data)


def load_annotated_images(
    images: str | os.PathLike[str], annotations: str | os.PathLike[str]
) -> tuple[Path, Any, list[int]]:
    """The image folder, its COCO annotations and the image ids (ascending) of a run.

    Every annotated image must be present in ``images``; a missing folder or image is an
    :class:`~fidelity.errors.InputFileError` naming it.
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
    d = np.asarray(detections, dtype=np.float64).reshape(-1, 6)
    out = []
    cat = np.asarray(category_ids)
    for x1, y1, x2, y2, s, c in d:
        out.append({"image_id": int(image_id), "category_id": int(cat[int(c)]),
                    "bbox": [round(float(x1), 3), round(float(y1), 3),
                             round(float(x2 - x1), 3), round(float(y2 - y1), 3)],
                    "score": round(float(s), 5)})
    return out


def evaluate_detections(coco_gt: Any, detections: Mapping[int, np.ndarray],
                        image_ids: Sequence[int] | None = None) -> CocoScore:
    """Score per-image (K, 6) detections against ground truth with pycocotools ``COCOeval``.

    ``image_ids``: the images evaluated (default: the keys of ``detections``). An image without
    detections still counts (its ground truth is missed).
    """
    from pycocotools.cocoeval import COCOeval

    ids = sorted(int(i) for i in (image_ids if image_ids is not None else detections))
    if not ids:
        raise InvalidValueError("no images to evaluate")
    known = set(coco_gt.getImgIds())
    missing = [i for i in ids if i not in known]
    if missing:
        raise InvalidValueError(f"image ids not in the annotations: {missing[:5]}")
    cat_ids = sorted(coco_gt.getCatIds())
    if len(cat_ids) == len(COCO80_CATEGORY_IDS):
        mapping: Sequence[int] = cat_ids
    else:
        mapping = COCO80_CATEGORY_IDS
    results: list[dict[str, Any]] = []
    for i in ids:
        det = detections.get(i)
        if det is not None and len(det):
            results.extend(detections_to_coco(i, det, mapping))
    with contextlib.redirect_stdout(io.StringIO()):
        if results:
            coco_dt = coco_gt.loadRes(results)
        else:
            coco_dt = coco_from_dict({"images": coco_gt.dataset["images"], "annotations": [],
                                      "categories": coco_gt.dataset["categories"]})
        ev = COCOeval(coco_gt, coco_dt, "bbox")
        ev.params.imgIds = ids
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    precision = ev.eval["precision"]  # (T, R, K, A, M)
    ap: dict[str, float | None] = {}
    names = {c["id"]: c["name"] for c in coco_gt.dataset["categories"]}
    for k, cid in enumerate(ev.params.catIds):
        p = precision[:, :, k, 0, -1]
        p = p[p > -1]
        ap[names[cid]] = float(np.mean(p)) if p.size else None
    stats = tuple(float(s) for s in ev.stats)
    return CocoScore(map=max(stats[0], 0.0), map50=max(stats[1], 0.0), map75=max(stats[2], 0.0),
                     ap=ap, images=len(ids), detections=len(results), stats=stats)
