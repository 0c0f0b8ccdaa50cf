"""Run one ONNX detector over an annotated COCO image folder and score it (``fidelity evaluate``).

The loop is :func:`fidelity.coco.executor.detect_images` (local or on Ray; resumable), whose
workers run :meth:`fidelity.coco.detectors.Detector.detect_stream`: JPEG decoding and
preprocessing on a worker thread ahead of the network, decoding/NMS behind it. Scores: COCO
box AP (:func:`fidelity.coco.scoring.evaluate_detections`, always) and, on request,
Ultralytics' own mAP (:func:`fidelity.coco.scoring.ultralytics_ap`), computed from the same
detections (unclipped for Ultralytics 8.4's rule, clipped to the image for COCO).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.detectors import clip_boxes
from fidelity.coco.executor import ExecutorOptions, ModelFile, detect_images
from fidelity.coco.scoring import (
    CocoScore,
    UltralyticsScore,
    evaluate_detections,
    load_annotations,
    resolve_scorer,
    ultralytics_ap,
)
from fidelity.coco.store import ImageSet
from fidelity.core.errors import InputFileError, unknown_name
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.executor import ExecutorOptions

#: ``--metric`` names: COCO AP, and Ultralytics' AP under the rules of a version.
METRICS: dict[str, str | None] = {"coco": None, "ultralytics": "8.4", "ultralytics-8.3": "8.3"}


@record
class Evaluation:
    """Scores of one detector on one image set, with what ran and how long it took."""

    detector: dict[str, Any]
    coco: CocoScore
    ultralytics: dict[str, UltralyticsScore]  # by metric name ("ultralytics", ...)
    scorer: str
    images: int
    detect_seconds: float  # the detection loop: decode, preprocess, network, NMS
    seconds: float  # everything, scoring included
    computed: int = 0  # images detected now (the others came from an earlier run's store)
    executor: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """JSON form: the COCO score's fields at the top level, then one key per other metric."""
        out = self.coco.to_json() | {"seconds": self.seconds,
                                     "detect_seconds": self.detect_seconds,
                                     "detector": self.detector, "scorer": self.scorer,
                                     "computed": self.computed, "executor": self.executor}
        for name, score in self.ultralytics.items():
            out[name] = score.to_json()
        return out


def evaluate_model(model: str | os.PathLike[str], images: str | os.PathLike[str],
                   annotations: str | os.PathLike[str], *, limit: int | None = None,
                   options: ExecutorOptions | None = None, scorer: str = "auto",
                   metrics: Sequence[str] = ("coco",), store_base: str | os.PathLike[str] | None
                   = None, progress: bool = False) -> Evaluation:
    """Detect on the first ``limit`` annotated images (by id) and score.

    The detection loop is :func:`fidelity.coco.executor.detect_images` (local or Ray,
    ``options``): resumable, its per-image detections kept in a store in the cache, so a killed
    evaluation started again runs only the images it had not finished. ``metrics``: names from
    :data:`METRICS`; COCO AP is always computed (boxes clipped to the image), Ultralytics' from
    the same detections unclipped. Missing images are an
    :class:`~fidelity.core.errors.InputFileError` before any inference.
    """
    for m in metrics:
        if m not in METRICS:
            raise unknown_name("metric", m, list(METRICS))
    method = resolve_scorer(scorer)
    detector = ModelFile.from_path(model)  # a missing model is named first
    coco = load_annotations(annotations)
    ids = sorted(coco.getImgIds())[:limit] if limit else sorted(coco.getImgIds())
    folder = Path(images)
    if not folder.is_dir():
        raise InputFileError(f"{folder}: image folder does not exist")
    missing = [i for i in ids if not (folder / coco.imgs[i]["file_name"]).is_file()]
    if missing:  # before any inference
        raise InputFileError(f"{folder}: {len(missing)} of the {len(ids)} annotated images "
                             f"to evaluate are missing, e.g. {coco.imgs[missing[0]]['file_name']}")
    t0 = time.perf_counter()
    found = detect_images(detector, ImageSet(folder, coco, ids), ids,
                          options or ExecutorOptions(), store_base=store_base,
                          progress=progress)
    raw: dict[int, np.ndarray] = found.detections
    clipped = {i: clip_boxes(d, (int(coco.imgs[i]["height"]), int(coco.imgs[i]["width"])))
               for i, d in raw.items()}
    score = evaluate_detections(coco, clipped, ids, method=method)
    ultra = {m: ultralytics_ap(coco, raw, ids, version=v) for m in dict.fromkeys(metrics)
             if (v := METRICS[m]) is not None}
    return Evaluation(found.detector, score, ultra, method, len(ids), found.seconds,
                      time.perf_counter() - t0, computed=found.new, executor=found.executor)
