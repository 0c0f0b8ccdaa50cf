"""Run one ONNX detector over an annotated COCO image folder and score it (``fidelity evaluate``).

The loop is :meth:`fidelity.coco.detectors.Detector.detect_stream`: JPEG decoding and
preprocessing on a worker thread ahead of the network, decoding/NMS behind it. Scores: COCO
box AP (:func:`fidelity.coco.scoring.evaluate_detections`, always) and, on request,
Ultralytics' own mAP (:func:`fidelity.coco.scoring.ultralytics_ap`), computed from the same
detections (unclipped for Ultralytics 8.4's rule, clipped to the image for COCO).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.scoring import CocoScore, UltralyticsScore
from fidelity.errors import InputFileError

#: ``--metric`` names: COCO AP, and Ultralytics' AP under the rules of a version.
METRICS: dict[str, str | None] = {"coco": None, "ultralytics": "8.4", "ultralytics-8.3": "8.3"}


@dataclass(frozen=True)
class Evaluation:
    """Scores of one detector on one image set, with what ran and how long it took."""

    detector: dict[str, Any]
    coco: CocoScore
    ultralytics: dict[str, UltralyticsScore]  # by metric name ("ultralytics", ...)
    scorer: str
    images: int
    detect_seconds: float  # the detection loop: decode, preprocess, network, NMS
    seconds: float  # everything, scoring included

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the COCO score's fields at the top level, then one key per other metric."""
        out = self.coco.to_dict() | {"seconds": self.seconds,
                                     "detect_seconds": self.detect_seconds,
                                     "detector": self.detector, "scorer": self.scorer}
        for name, score in self.ultralytics.items():
            out[name] = score.to_dict()
        return out


def evaluate_model(model: str | os.PathLike[str], images: str | os.PathLike[str],
                   annotations: str | os.PathLike[str], *, limit: int | None = None,
                   threads: int | None = None, provider: str = "auto", scorer: str = "auto",
                   metrics: Sequence[str] = ("coco",), prefetch: int = 4,
                   progress: Callable[[int], Any] | None = None) -> Evaluation:
    """Detect on the first ``limit`` annotated images (by id) and score.

    ``metrics``: names from :data:`METRICS`; COCO AP is always computed. ``progress`` is
    called with 1 after each image (a progress bar's ``update``). Missing images are an
    :class:`~fidelity.errors.InputFileError` before any inference.
    """
    from fidelity.coco.detectors import Detector, clip_boxes
    from fidelity.coco.jpeg import read_jpeg
    from fidelity.coco.scoring import (
        evaluate_detections,
        load_annotations,
        resolve_scorer,
        ultralytics_ap,
    )
    from fidelity.errors import unknown_name

    for m in metrics:
        if m not in METRICS:
            raise unknown_name("metric", m, list(METRICS))
    method = resolve_scorer(scorer)
    det = Detector(model, threads=threads, provider=provider)
    coco = load_annotations(annotations)
    ids = sorted(coco.getImgIds())[:limit] if limit else sorted(coco.getImgIds())
    folder = Path(images)
    if not folder.is_dir():
        raise InputFileError(f"{folder}: image folder does not exist")
    missing = [i for i in ids if not (folder / coco.imgs[i]["file_name"]).is_file()]
    if missing:  # before any inference
        raise InputFileError(f"{folder}: {len(missing)} of the {len(ids)} annotated images "
                             f"to evaluate are missing, e.g. {coco.imgs[missing[0]]['file_name']}")
    sizes: dict[int, tuple[int, int]] = {}

    def load(i: int) -> np.ndarray:
        rgb = read_jpeg(folder / coco.imgs[i]["file_name"])[0]
        sizes[i] = (rgb.shape[0], rgb.shape[1])
        return rgb

    t0 = time.perf_counter()
    raw: dict[int, np.ndarray] = {}
    for i, d in det.detect_stream(ids, load, prefetch=prefetch, clip=False):
        raw[i] = d
        if progress is not None:
            progress(1)
    detect_s = time.perf_counter() - t0
    clipped = {i: clip_boxes(d, sizes[i]) for i, d in raw.items()}
    score = evaluate_detections(coco, clipped, ids, method=method)
    ultra = {m: ultralytics_ap(coco, raw, ids, version=v) for m in dict.fromkeys(metrics)
             if (v := METRICS[m]) is not None}
    return Evaluation(det.describe(), score, ultra, method, len(ids), detect_s,
                      time.perf_counter() - t0)
