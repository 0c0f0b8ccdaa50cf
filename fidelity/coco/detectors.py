"""COCO object detectors through onnxruntime, with the validation conventions of their authors.

The output layout is recognised from the model itself (input/output shapes and metadata), never
from its file name:

``ultralytics``  one output ``B x (4+C) x N`` (e.g. 1x84x8400): rows ``cx, cy, w, h`` in
    letterboxed pixels followed by C class scores (sigmoid already applied). Needs NMS.
    Validation conventions (Ultralytics ``DetectionValidator``): confidence 0.001, IoU 0.7,
    multi-label NMS per class, at most 30000 boxes into NMS and 300 detections out.
``ultralytics-e2e``  one output ``B x K x 6`` (YOLOv10 end-to-end, e.g. 1x300x6):
    ``x1, y1, x2, y2, score, class`` in letterboxed pixels; NMS-free. Conventions: confidence
    0.001, 300 out.
``yolox``  one output ``B x N x (5+C)`` where N equals the number of grid cells of strides
    8/16/32 for the input size (3549 for 416x416): raw ``x, y, log w, log h, objectness, C class
    scores`` (objectness and classes already sigmoid). Decode ``xy = (p + grid) * stride``,
    ``wh = exp(p) * stride``, score = obj * max class. Conventions (YOLOX ``COCOEvaluator`` /
    ``yolox_base.Exp``): confidence 0.01, NMS IoU 0.65 per class, single label per box, no cap
    on detections (COCO scoring keeps the best 100 per image).

The batch dimension B is 1 for the usual static exports; a model whose batch dimension is
symbolic (``dynamic=True`` exports) or a fixed B > 1 is run on several images per call.

Preprocessing per family (:data:`PREPROCESSING`), each a transcription of its reference's
behaviour on 8-bit images (OpenCV ``cv2.resize`` with ``INTER_LINEAR`` on uint8, which rounds in
fixed point and is *not* a float bilinear resize):

* ``ultralytics`` (Ultralytics 8.4 ``YOLODataset.load_image`` + ``LetterBox(scaleup=False)``, the
  ``yolo val`` path): the long side is resized to the input size with ``math.ceil`` sizes
  (``w = min(ceil(w0 r), S)``, ``r = S / max(h0, w0)``; no resize when ``r == 1``), then placed
  centred (``top = round(dh - 0.1)``) on a canvas of 114, RGB, divided by 255 in float32. Boxes
  map back with per-axis gains ``w / w0`` and ``h / h0`` (``ops.scale_boxes`` with
  ``ratio_pad``) and are clipped to the image.
* ``yolox`` (YOLOX ``COCODataset.load_resized_img`` + ``ValTransform(legacy=False)``): resize
  by ``r = min(S_h / h0, S_w / w0)`` to ``int(w0 r) x int(h0 r)``, then ``preproc`` (a second
  resize only where ``int()`` truncation left the long side one pixel short), top-left on a
  canvas of 114, BGR, 0-255 float32, no normalisation. Boxes map back by dividing by ``r``.

Boxes are returned in original image pixels as ``x1, y1, x2, y2`` plus score and a COCO
*class index* 0..C-1 (the 80-class contiguous index; :data:`COCO80_CATEGORY_IDS` maps it to
annotation category ids).

The per-image work (decode -> preprocess -> network -> decode/NMS) is :class:`Detector`
(:meth:`Detector.prepare`, :meth:`Detector.infer`, :meth:`Detector.finish`, or all three in
``detector(rgb)``); :meth:`Detector.detect_stream` runs it over many images with loading and
preprocessing on a small thread pool ahead of the network and decoding behind it.
"""

from __future__ import annotations

import ast
import math
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.record import record

if TYPE_CHECKING:
    from concurrent.futures import Future

K = TypeVar("K")

#: The 80 COCO class names in the contiguous order used by Ultralytics and YOLOX.
COCO80_NAMES: tuple[str, ...] = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat",
    "traffic light", "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog",
    "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella",
    "handbag", "tie", "suitcase", "frisbee", "skis", "snowboard", "sports ball", "kite",
    "baseball bat", "baseball glove", "skateboard", "surfboard", "tennis racket", "bottle",
    "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple", "sandwich",
    "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote",
    "keyboard", "cell phone", "microwave", "oven", "toaster", "sink", "refrigerator", "book",
    "clock", "vase", "scissors", "teddy bear", "hair drier", "toothbrush",
)

#: COCO category ids of the 80 classes, in contiguous order (official COCO 2017 ids).
COCO80_CATEGORY_IDS: tuple[int, ...] = (
    1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 27,
    28, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 46, 47, 48, 49, 50, 51, 52, 53,
    54, 55, 56, 57, 58, 59, 60, 61, 62, 63, 64, 65, 67, 70, 72, 73, 74, 75, 76, 77, 78, 79, 80,
    81, 82, 84, 85, 86, 87, 88, 89, 90,
)

#: Validation conventions per layout (the model authors' own evaluation settings); ``family``
#: names the :data:`PREPROCESSING` entry, ``preprocess`` (added below) describes it.
CONVENTIONS: dict[str, dict[str, Any]] = {
    "ultralytics": {
        "source": "Ultralytics DetectionValidator (yolo val defaults)",
        "conf": 0.001, "iou": 0.7, "max_det": 300, "max_nms": 30000, "multi_label": True,
        "family": "ultralytics",
    },
    "ultralytics-e2e": {
        "source": "Ultralytics DetectionValidator, end-to-end head (YOLOv10), no NMS",
        "conf": 0.001, "iou": None, "max_det": 300, "max_nms": None, "multi_label": False,
        "family": "ultralytics",
    },
    "yolox": {
        "source": "YOLOX COCOEvaluator with yolox_base.Exp test_conf / nmsthre",
        "conf": 0.01, "iou": 0.65, "max_det": None, "max_nms": None, "multi_label": False,
        "family": "yolox",
    },
}

#: Detection array columns: x1, y1, x2, y2, score, class index.
DETECTION_COLUMNS: tuple[str, ...] = ("x1", "y1", "x2", "y2", "score", "class")


@record
class ModelLayout:
    """What :func:`recognise_layout` found out about a model.

    ``batch``: the images per network call the model takes: 1 for the usual static export, a
    fixed B > 1, or ``None`` when the batch dimension is symbolic (any count).
    """

    kind: str
    input_name: str
    input_size: tuple[int, int]  # (height, width)
    num_classes: int
    output_name: str
    names: tuple[str, ...]
    metadata: dict[str, str] = field(default_factory=dict)
    batch: int | None = 1


def _static_dims(shape: list[Any], what: str, path: str) -> list[int]:
    dims = []
    for d in shape:
        if not isinstance(d, int):
            raise InputFileError(f"{path}: {what} has a dynamic dimension {d!r} (shape {shape}); "
                                 "export the model with a static input size")
        dims.append(d)
    return dims


def _batch_dim(d: Any) -> int | None:
    """A tensor's leading dimension: an int, or ``None`` when symbolic (a name or unknown)."""
    return d if isinstance(d, int) and d > 0 else None


def _yolox_cells(h: int, w: int, strides: tuple[int, ...] = (8, 16, 32)) -> int:
    return sum((h // s) * (w // s) for s in strides)


def _names_from_metadata(meta: dict[str, str], num_classes: int) -> tuple[str, ...]:
    raw = meta.get("names")
    if raw:
        try:
            parsed = ast.literal_eval(raw)
            if isinstance(parsed, dict):
                names = tuple(str(parsed[k]) for k in sorted(parsed))
                if len(names) == num_classes:
                    return names
        except (ValueError, SyntaxError):
            pass
    if num_classes == len(COCO80_NAMES):
        return COCO80_NAMES
    return tuple(f"class{i}" for i in range(num_classes))


def recognise_layout(input_shapes: list[tuple[str, list[Any]]],
                     output_shapes: list[tuple[str, list[Any]]],
                     metadata: dict[str, str] | None = None, path: str = "model") -> ModelLayout:
    """Recognise a detector's output layout from its input/output shapes and metadata.

    Rules (first match wins): a single ``Bx3xHxW`` input (H, W static; B static or symbolic)
    and a single 3-D output with the same leading dimension; ``B x 6 x K`` is never accepted
    (ambiguous); ``B x K x 6`` with metadata ``end2end`` true or K <= 1000 is the YOLOv10
    end-to-end layout; ``B x (4+C) x N`` with N equal to the anchor count of strides 8/16/32 is
    Ultralytics; ``B x N x (5+C)`` with N equal to that anchor count is YOLOX. Anything else
    raises :class:`InputFileError` naming the shapes.
    """
    meta = dict(metadata or {})
    if len(input_shapes) != 1:
        raise InputFileError(f"{path}: expected one input tensor, found {len(input_shapes)}: "
                             f"{input_shapes}; not a recognised detector layout")
    in_name, in_shape = input_shapes[0]
    in_shape = list(in_shape)
    if len(in_shape) != 4:
        raise InputFileError(f"{path}: input {in_name!r} has shape {in_shape}; expected Bx3xHxW")
    batch = _batch_dim(in_shape[0])
    dims = [batch or -1] + _static_dims(in_shape[1:], "input", path)
    if dims[1] != 3:
        raise InputFileError(f"{path}: input {in_name!r} has shape {in_shape}; expected Bx3xHxW")
    h, w = dims[2], dims[3]
    if len(output_shapes) != 1:
        raise InputFileError(f"{path}: expected one output tensor, found {len(output_shapes)} "
                             f"({output_shapes}); not a recognised detector layout "
                             "(Ultralytics 1x84xN, YOLOv10 1x300x6, YOLOX 1xNx85)")
    out_name, out_shape = output_shapes[0]
    out_shape = list(out_shape)
    odims = ([_batch_dim(out_shape[0]) or -1] + _static_dims(out_shape[1:], "output", path)
             if out_shape else [])
    anchors = _yolox_cells(h, w)
    if len(odims) == 3 and odims[0] == dims[0]:
        _, a, b = odims
        e2e_flag = str(meta.get("end2end", "")).lower() == "true"
        if b == 6 and (e2e_flag or a <= 1000) and a != anchors:
            names = _names_from_metadata(meta, 80)
            return ModelLayout("ultralytics-e2e", in_name, (h, w), len(names), out_name,
                               names, meta, batch)
        if b == anchors and a > 4:
            nc = a - 4
            return ModelLayout("ultralytics", in_name, (h, w), nc, out_name,
                               _names_from_metadata(meta, nc), meta, batch)
        if a == anchors and b > 5:
            nc = b - 5
            return ModelLayout("yolox", in_name, (h, w), nc, out_name,
                               _names_from_metadata(meta, nc), meta, batch)
    raise InputFileError(
        f"{path}: unrecognised detector output layout {out_shape} for input {in_shape}; known "
        f"layouts: Ultralytics 1x(4+C)x{anchors}, YOLOv10 end-to-end 1xKx6, "
        f"YOLOX 1x{anchors}x(5+C)")


def check_detector(layout: ModelLayout, path: str) -> None:
    """Refuse a model whose layout fidelity cannot score: COCO scoring maps class index k to
    the k-th of the 80 COCO categories (:data:`COCO80_CATEGORY_IDS`), so the model must have
    exactly 80 classes. Raises :class:`InputFileError` naming the model."""
    if layout.num_classes != len(COCO80_CATEGORY_IDS):
        raise InputFileError(f"{path}: the model has {layout.num_classes} classes "
                             f"({layout.kind} layout); COCO scoring needs the "
                             f"{len(COCO80_CATEGORY_IDS)} COCO classes")


def check_raw_output(output: np.ndarray, layout: ModelLayout, path: str) -> None:
    """Refuse a raw model output that cannot be scored: NaN or +-Inf anywhere (boxes, scores,
    classes), or, in the end-to-end layout, a class index that is not a whole number in
    ``[0, classes)``. Raises :class:`InvalidValueError` naming the model, so a broken model
    stops a run with one clear error instead of failing each cell's scoring."""
    out = np.asarray(output)
    if not np.all(np.isfinite(out)):
        bad = int(np.count_nonzero(~np.isfinite(out)))
        raise InvalidValueError(f"{path}: the model output has {bad} NaN or infinite values "
                                f"(shape {list(out.shape)}); it cannot be scored")
    if layout.kind == "ultralytics-e2e" and out.ndim == 3 and out.shape[-1] == 6:
        cls = out[0, :, 5]
        wrong = (cls < 0) | (cls >= layout.num_classes) | (cls != np.round(cls))
        if np.any(wrong):
            raise InvalidValueError(
                f"{path}: the model output has class index {float(cls[wrong][0]):g}, not a "
                f"whole number in [0, {layout.num_classes}); it cannot be scored")


# --------------------------------------------------------------------------------------------
# Preprocessing


@record
class Letterbox:
    """Where an image sits in the model input: ``input = image * gain + pad``, per axis.

    ``gain_x``, ``gain_y``: model-input pixels per image pixel; ``pad_x``, ``pad_y``: offset of
    the image's top-left corner in the model input (pixels). :meth:`to_image` is the inverse.
    """

    gain_x: float
    gain_y: float
    pad_x: float
    pad_y: float

    def to_image(self, boxes: np.ndarray) -> np.ndarray:
        """Map (K, 4) ``x1, y1, x2, y2`` model-input boxes to image pixels (float32, unclipped).

        ``(x - pad_x) / gain_x`` and ``(y - pad_y) / gain_y`` in float32, the arithmetic of
        Ultralytics' ``ops.scale_boxes`` (and of YOLOX's ``bboxes /= scale`` with zero pads).
        """
        b = np.array(boxes, dtype=np.float32, copy=True).reshape(-1, 4)
        b[:, [0, 2]] -= np.float32(self.pad_x)
        b[:, [1, 3]] -= np.float32(self.pad_y)
        b[:, [0, 2]] /= np.float32(self.gain_x)
        b[:, [1, 3]] /= np.float32(self.gain_y)
        return b


@record
class Placement:
    """A resized uint8 image and where it goes on the model-input canvas (``top``, ``left``)."""

    image: np.ndarray  # (h, w, 3) uint8, channel order of the input image
    top: int
    left: int
    letterbox: Letterbox


def _resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """``cv2.resize(img, (width, height), interpolation=cv2.INTER_LINEAR)`` on uint8."""
    import cv2

    return np.asarray(cv2.resize(np.ascontiguousarray(img), (int(width), int(height)),
                                 interpolation=cv2.INTER_LINEAR))


def letterbox_ultralytics(rgb: np.ndarray, size: tuple[int, int]) -> Placement:
    """Ultralytics' validation resize and letterbox of an (H, W, 3) uint8 image.

    ``size`` is the model input (height, width). Two steps, as ``yolo val`` runs them:
    ``YOLODataset.load_image`` scales the long side to ``S = max(size)`` with
    ``r = S / max(h0, w0)`` and sizes ``min(ceil(w0 r), S) x min(ceil(h0 r), S)`` (OpenCV
    ``INTER_LINEAR``; nothing when ``r == 1``); ``LetterBox(new_shape=size, scaleup=False,
    center=True)`` then scales by ``r2 = min(size_h / h, size_w / w, 1)`` to
    ``max(round(w r2), 1) x max(round(h r2), 1)`` (for a square input r2 is 1 and nothing
    happens) and centres the result with ``top = round(dh - 0.1)``, ``left = round(dw - 0.1)``
    (``dh``, ``dw``: half the padding; Python's round, half to even). The gains are the
    per-axis ratios ``h / h0 * r2`` and ``w / w0 * r2`` that ``ratio_pad`` carries.
    Source: Ultralytics 8.4 ``ultralytics/data/base.py`` and ``data/augment.py``.
    """
    th, tw = size
    h0, w0 = rgb.shape[:2]
    long_side = max(th, tw)
    r = long_side / max(h0, w0)
    img, h, w = rgb, h0, w0
    if r != 1:
        w, h = min(math.ceil(w0 * r), long_side), min(math.ceil(h0 * r), long_side)
        img = _resize(rgb, w, h)
    r2 = min(th / h, tw / w, 1.0)
    nw, nh = max(round(w * r2), 1), max(round(h * r2), 1)
    if (nw, nh) != (w, h):
        img = _resize(img, nw, nh)
    top, left = round((th - nh) / 2 - 0.1), round((tw - nw) / 2 - 0.1)
    return Placement(img, top, left, Letterbox(w / w0 * r2, h / h0 * r2, float(left), float(top)))


def letterbox_yolox(rgb: np.ndarray, size: tuple[int, int]) -> Placement:
    """YOLOX's COCO-evaluation resize of an (H, W, 3) uint8 image, placed top-left.

    ``COCODataset.load_resized_img``: ``r = min(S_h / h0, S_w / w0)``, OpenCV ``INTER_LINEAR``
    to ``int(w0 r) x int(h0 r)``; then ``ValTransform`` / ``preproc`` computes its own
    ``r2 = min(S_h / h1, S_w / w1)`` on that image and resizes to ``int(w1 r2) x int(h1 r2)``
    (the same size, a copy, unless ``int()`` truncated the long side); top-left corner of a
    canvas of 114. Boxes go back with the evaluator's ``scale = min(S_h / h0, S_w / w0)``.
    Sides are kept at least 1 pixel (YOLOX would fail on such images).
    Source: YOLOX 0.3.0 ``yolox/data/datasets/coco.py``, ``yolox/data/data_augment.py``,
    ``yolox/evaluators/coco_evaluator.py``.
    """
    th, tw = size
    h0, w0 = rgb.shape[:2]
    r = min(th / h0, tw / w0)
    w1, h1 = max(int(w0 * r), 1), max(int(h0 * r), 1)
    img = rgb if (w1, h1) == (w0, h0) else _resize(rgb, w1, h1)
    r2 = min(th / h1, tw / w1)
    w2, h2 = max(int(w1 * r2), 1), max(int(h1 * r2), 1)
    if (w2, h2) != (w1, h1):
        img = _resize(img, w2, h2)
    return Placement(img, 0, 0, Letterbox(r, r, 0.0, 0.0))


@record
class Preprocessing:
    """One detector family's preprocessing: resize + placement, channel order, value scale."""

    name: str
    reference: str
    place: Callable[[np.ndarray, tuple[int, int]], Placement]
    bgr: bool  # channel order of the model input
    divide_by_255: bool  # float32 input / 255 (else 0-255 floats)
    pad_value: int = 114

    def describe(self) -> str:
        """One line for reports: reference, placement, channel order and value range."""
        return (f"{self.reference}; pad {self.pad_value}, {'BGR' if self.bgr else 'RGB'}"
                f"{'/255' if self.divide_by_255 else ' 0-255'}")

    def fill(self, placement: Placement, out: np.ndarray) -> None:
        """Write the model input for ``placement`` into ``out`` (3, H, W) float32."""
        img = placement.image
        h, w = img.shape[:2]
        t, left = placement.top, placement.left
        pad = (np.float32(self.pad_value) / np.float32(255.0) if self.divide_by_255
               else np.float32(self.pad_value))
        out[:, :t] = pad
        out[:, t + h:] = pad
        out[:, t:t + h, :left] = pad
        out[:, t:t + h, left + w:] = pad
        for c, src in enumerate((2, 1, 0) if self.bgr else (0, 1, 2)):
            dst = out[c, t:t + h, left:left + w]
            if self.divide_by_255:
                np.divide(img[:, :, src], np.float32(255.0), out=dst)
            else:
                np.copyto(dst, img[:, :, src], casting="unsafe")


#: Preprocessing per detector family, by name.
PREPROCESSING: dict[str, Preprocessing] = {
    "ultralytics": Preprocessing(
        "ultralytics", "Ultralytics 8.4 yolo val: long side to S with ceil sizes, OpenCV "
        "INTER_LINEAR on uint8, centred letterbox, per-axis gains", letterbox_ultralytics,
        bgr=False, divide_by_255=True),
    "yolox": Preprocessing(
        "yolox", "YOLOX COCOEvaluator: r = min(S/h, S/w), int() sizes, OpenCV INTER_LINEAR on "
        "uint8, top-left", letterbox_yolox, bgr=True, divide_by_255=False),
}


for _conv in CONVENTIONS.values():
    _conv["preprocess"] = PREPROCESSING[_conv["family"]].describe()


def stale_preprocessing(provenance: Mapping[str, Any]) -> dict[str, str | None]:
    """The detectors of a measured table's ``provenance`` (``models``) whose recorded
    preprocessing (``conventions.preprocess``) is none of this version's
    (:data:`PREPROCESSING`): name -> what they recorded (None: nothing)."""
    current = {p.describe() for p in PREPROCESSING.values()}
    models = provenance.get("models")
    out: dict[str, str | None] = {}
    for name, m in (models.items() if isinstance(models, Mapping) else ()):
        conv = m.get("conventions") if isinstance(m, Mapping) else None
        found = conv.get("preprocess") if isinstance(conv, Mapping) else None
        if found not in current:
            out[str(name)] = None if found is None else str(found)
    return out


def preprocessing_for(layout: ModelLayout) -> Preprocessing:
    """The :data:`PREPROCESSING` entry of a layout's family."""
    return PREPROCESSING[CONVENTIONS[layout.kind]["family"]]


def _check_image(rgb: np.ndarray) -> np.ndarray:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise InvalidValueError(f"image has shape {a.shape} and dtype {a.dtype}; "
                                "expected (H, W, 3) uint8 RGB")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise InvalidValueError(f"image has shape {a.shape}; it has no pixels")
    return a


def preprocess(rgb: np.ndarray, layout: ModelLayout) -> tuple[np.ndarray, Letterbox]:
    """Turn an (H, W, 3) uint8 RGB image into the model's 1x3xHxW float32 input.

    The family's :data:`PREPROCESSING` (see the module docstring); returns the input and the
    :class:`Letterbox` that maps boxes back.
    """
    a = _check_image(rgb)
    pre = preprocessing_for(layout)
    placement = pre.place(a, layout.input_size)
    x = np.empty((1, 3, *layout.input_size), dtype=np.float32)
    pre.fill(placement, x[0])
    return x, placement.letterbox


# --------------------------------------------------------------------------------------------
# Non-maximum suppression


def _overlap_pairs(boxes: np.ndarray, groups: np.ndarray | None, iou: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)``, ``i < j``, of rows in the same group whose IoU is above ``iou``.

    ``boxes``: (n, 4) float32 ``x1, y1, x2, y2`` in suppression order (best first). The IoU is
    computed as torchvision's CPU ``nms`` kernel does, in float32: ``inter / (area_i + area_j -
    inter)`` with ``area = (x2 - x1) (y2 - y1)`` and ``inter = max(0, dx) max(0, dy)``, and
    compared with ``iou`` in float64 (``ovr > iou_threshold`` in C++ promotes to double).

    Only pairs that can pass are evaluated: the IoU of two boxes is at most the 1-D IoU of
    their x intervals (``ox oy / (a_i + a_j - ox oy) <= ox / (w_i + w_j - ox)`` as
    ``oy <= h_i, h_j``), so with ``x1_i <= x1_j`` an IoU above t needs ``x1_j < x1_i + (1 - t)
    w_i``. Rows are sorted by (group, x1) and each row is paired with the rows inside that
    window (widened by 1e-5 in t, far more than float32 rounding of the computed IoU).
    """
    n = len(boxes)
    empty = np.empty(0, dtype=np.intp)
    if n < 2:
        return empty, empty
    x1 = boxes[:, 0].astype(np.float64)
    w = np.maximum(boxes[:, 2].astype(np.float64) - x1, 0.0)
    if groups is not None:  # one sorted key: groups far apart, x1 within
        span = float(np.max(x1 + w) - np.min(x1)) + 1.0
        key = groups.astype(np.float64) * (2.0 * span) + (x1 - float(np.min(x1)))
    else:
        key = x1
    by_key = np.argsort(key, kind="stable")
    ks = key[by_key]
    limit = ks + w[by_key] * (1.0 - min(iou, 1.0) + 1e-5)
    hi = np.searchsorted(ks, limit, side="right")
    count = np.maximum(hi - np.arange(n) - 1, 0)
    total = int(count.sum())
    if total == 0:
        return empty, empty
    a = np.repeat(np.arange(n), count)
    b = a + 1 + (np.arange(total) - np.repeat(np.cumsum(count) - count, count))
    ra, rb = by_key[a], by_key[b]
    if groups is not None:
        same = groups[ra] == groups[rb]
        ra, rb = ra[same], rb[same]
    i, j = np.minimum(ra, rb), np.maximum(ra, rb)
    bx = np.asarray(boxes, dtype=np.float32)
    area = (bx[:, 2] - bx[:, 0]) * (bx[:, 3] - bx[:, 1])
    dx = np.minimum(bx[i, 2], bx[j, 2]) - np.maximum(bx[i, 0], bx[j, 0])
    dy = np.minimum(bx[i, 3], bx[j, 3]) - np.maximum(bx[i, 1], bx[j, 1])
    inter = np.maximum(dx, np.float32(0)) * np.maximum(dy, np.float32(0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ovr = inter / (area[i] + area[j] - inter)
    above = ovr.astype(np.float64) > iou
    return i[above], j[above]


def _greedy_keep(n: int, i: np.ndarray, j: np.ndarray, max_rounds: int = 64) -> np.ndarray:
    """Greedy suppression on a fixed pair list: row j is dropped when a kept row i < j pairs it.

    The greedy answer K is the unique solution of ``K[j] = not any(K[i] for pairs (i, j))``
    (a triangular system). Jacobi iteration from all-kept settles one more row per round at
    least (row j depends only on rows before it), so it reaches K in at most ``n`` rounds and
    stops as soon as a round changes nothing; suppression chains in detector outputs are a few
    links long (4-7 rounds on COCO). After ``max_rounds`` the rest is done row by row.
    """
    keep = np.ones(n, dtype=bool)
    for _ in range(max_rounds):
        new = np.ones(n, dtype=bool)
        new[j[keep[i]]] = False
        if np.array_equal(new, keep):
            return keep
        keep = new
    order = np.argsort(i, kind="stable")  # sequential fallback over a CSR list
    i, j = i[order], j[order]
    starts = np.searchsorted(i, np.arange(n + 1))
    keep = np.ones(n, dtype=bool)
    for row in range(n):
        if keep[row]:
            keep[j[starts[row]:starts[row + 1]]] = False
    return keep


def nms(boxes: np.ndarray, scores: np.ndarray, iou: float, max_keep: int | None = None
        ) -> np.ndarray:
    """Greedy non-maximum suppression (torchvision ``nms`` semantics): indices kept, best first.

    Boxes are visited in descending score order (stable: equal scores keep their input order,
    as torchvision's stable sort); a box is suppressed when its IoU with a kept higher-scoring
    box is strictly above ``iou``. ``max_keep`` returns the first that many (exact, since kept
    boxes come in score order). Vectorised: candidate pairs from a sweep over x
    (:func:`_overlap_pairs`), the greedy order resolved by :func:`_greedy_keep`.
    """
    return batched_nms(boxes, scores, None, iou, max_keep, offset=None)


def batched_nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray | None, iou: float,
                max_keep: int | None = None, offset: float | None = 7680.0) -> np.ndarray:
    """Per-class NMS; indices kept, best first (torchvision ``nms`` semantics per class).

    ``offset``: the coordinate trick of the reference, whose rounding is part of its numbers:
    ``7680`` is Ultralytics' ``max_wh`` (boxes + class * 7680 in float32, IoU on those);
    ``None`` compares the boxes as given within each class (torchvision ``batched_nms`` on
    many boxes). Boxes of different classes never suppress each other.
    """
    b = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    s = np.asarray(scores, dtype=np.float32).reshape(-1)
    n = len(s)
    if not 0.0 <= iou <= 1.0:
        raise InvalidValueError(f"NMS IoU threshold {iou} is outside [0, 1]")
    if n == 0:
        return np.empty(0, dtype=np.intp)
    order = np.argsort(-s, kind="stable")
    b = b[order]
    groups = None
    if classes is not None:
        groups = np.asarray(classes).reshape(-1)[order]
        if offset is not None:
            b = b + (groups.astype(np.float32) * np.float32(offset))[:, None]
    i, j = _overlap_pairs(b, groups, iou)
    kept = order[np.flatnonzero(_greedy_keep(n, i, j))]
    return kept[:max_keep] if max_keep is not None else kept


def torchvision_batched_nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray,
                            iou: float) -> np.ndarray:
    """``torchvision.ops.batched_nms`` on CPU, as YOLOX's ``postprocess`` calls it.

    torchvision offsets the boxes by ``class * (max coordinate + 1)`` (float32) when there are
    at most 1000 boxes and runs NMS class by class above that; both are reproduced, so the
    float32 IoUs are the reference's.
    """
    b = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    if b.size == 0:
        return np.empty(0, dtype=np.intp)
    if b.size > 4000:
        return batched_nms(b, scores, classes, iou, offset=None)
    step = np.float32(b.max()) + np.float32(1.0)
    return batched_nms(b, scores, classes, iou, offset=float(step))


# --------------------------------------------------------------------------------------------
# Postprocessing


def _xywh_to_xyxy(b: np.ndarray) -> np.ndarray:
    out = np.empty_like(b)
    half_w = b[:, 2] / 2
    half_h = b[:, 3] / 2
    out[:, 0] = b[:, 0] - half_w
    out[:, 1] = b[:, 1] - half_h
    out[:, 2] = b[:, 0] + half_w
    out[:, 3] = b[:, 1] + half_h
    return out


def yolox_grid(h: int, w: int, strides: tuple[int, ...] = (8, 16, 32)
               ) -> tuple[np.ndarray, np.ndarray]:
    """YOLOX anchor grid: (N, 2) cell offsets (x, y) and (N, 1) strides, row-major per stride."""
    grids, st = [], []
    for s in strides:
        hs, ws = h // s, w // s
        yv, xv = np.meshgrid(np.arange(hs), np.arange(ws), indexing="ij")
        grids.append(np.stack((xv, yv), 2).reshape(-1, 2))
        st.append(np.full((hs * ws, 1), s))
    return np.concatenate(grids).astype(np.float32), np.concatenate(st).astype(np.float32)


Decoded = tuple[np.ndarray, np.ndarray, np.ndarray]  # boxes (K, 4) xyxy, scores (K,), classes


def _decode_ultralytics(out: np.ndarray, layout: ModelLayout, conv: dict[str, Any]) -> Decoded:
    """``ops.non_max_suppression`` of Ultralytics on one ``(4+C) x N`` output."""
    conf, iou, max_det = conv["conf"], conv["iou"], conv["max_det"]
    cls = out[4:]  # (C, N)
    cand = np.flatnonzero(cls.max(axis=0) > conf)  # anchors with any class above conf
    sub = out[:, cand].T  # (m, 4+C), anchor order
    if conv.get("multi_label", True) and layout.num_classes > 1:
        ii, jj = np.nonzero(sub[:, 4:] > conf)  # anchor-major, as torch.where
        boxes = _xywh_to_xyxy(sub[ii, :4])
        scores, classes = sub[ii, 4 + jj], jj
    else:
        jj = sub[:, 4:].argmax(1)
        scores = sub[np.arange(len(jj)), 4 + jj]
        ii = np.flatnonzero(scores > conf)
        boxes, scores, classes = _xywh_to_xyxy(sub[ii, :4]), scores[ii], jj[ii]
    max_nms = conv.get("max_nms") or len(scores)
    if len(scores) > max_nms:
        top = np.argsort(-scores, kind="stable")[:max_nms]
        boxes, scores, classes = boxes[top], scores[top], classes[top]
    keep = batched_nms(boxes, scores, classes, iou, max_det, offset=7680.0)
    return boxes[keep], scores[keep], classes[keep]


def _decode_e2e(out: np.ndarray, layout: ModelLayout, conv: dict[str, Any]) -> Decoded:
    """End-to-end rows above conf, first ``max_det`` in the model's order (Ultralytics)."""
    d = out[out[:, 4] > conv["conf"]]
    if conv["max_det"] is not None:
        d = d[: conv["max_det"]]
    return d[:, :4].copy(), d[:, 4].copy(), d[:, 5].astype(np.intp)


def _decode_yolox(out: np.ndarray, layout: ModelLayout, conv: dict[str, Any]) -> Decoded:
    """YOLOX grid decode and ``yolox.utils.postprocess`` (single label, batched NMS)."""
    grid, strides = _yolox_grid_cached(*layout.input_size)
    # score = obj * max class <= obj (sigmoid class scores <= 1, and a float32 product by a
    # factor <= 1 cannot round above obj): only anchors with obj >= conf can pass
    cand = np.flatnonzero(out[:, 4] >= conv["conf"])
    cls = out[cand, 5:]
    jj = cls.argmax(1)
    scores = out[cand, 4] * cls[np.arange(len(jj)), jj]
    keep_c = scores >= conv["conf"]
    sel, scores, jj = cand[keep_c], scores[keep_c], jj[keep_c]
    raw = out[sel]
    xy = (raw[:, :2] + grid[sel]) * strides[sel]
    wh = np.exp(raw[:, 2:4]) * strides[sel]
    boxes = _xywh_to_xyxy(np.concatenate([xy, wh], 1))
    classes = jj
    keep = torchvision_batched_nms(boxes, scores, classes, conv["iou"])
    if conv.get("max_det") is not None:
        keep = keep[: conv["max_det"]]
    return boxes[keep], scores[keep], classes[keep]


_GRIDS: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}


def _yolox_grid_cached(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    hit = _GRIDS.get((h, w))
    if hit is None:
        hit = _GRIDS[(h, w)] = yolox_grid(h, w)
    return hit


#: Output decoders per layout: raw output of one image -> boxes (input pixels), scores, classes.
DECODERS: dict[str, Callable[[np.ndarray, ModelLayout, dict[str, Any]], Decoded]] = {
    "ultralytics": _decode_ultralytics,
    "ultralytics-e2e": _decode_e2e,
    "yolox": _decode_yolox,
}


def clip_boxes(detections: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """A copy of (K, 6) detections with x clipped to [0, width] and y to [0, height]."""
    d = np.array(detections, dtype=np.float32, copy=True).reshape(-1, 6)
    h, w = image_size
    d[:, [0, 2]] = np.clip(d[:, [0, 2]], 0, w)
    d[:, [1, 3]] = np.clip(d[:, [1, 3]], 0, h)
    return d


def postprocess(output: np.ndarray, layout: ModelLayout, box: Letterbox,
                image_size: tuple[int, int], conventions: dict[str, Any] | None = None,
                clip: bool = True) -> np.ndarray:
    """Decode one image's raw output into (K, 6) float32 ``x1, y1, x2, y2, score, class`` rows.

    ``output``: the network output for one image, with or without its leading batch axis.
    Boxes are mapped back to the original image with :meth:`Letterbox.to_image` and, with
    ``clip`` (the default, as COCO JSON output), clipped to it (``ops.clip_boxes``).
    """
    conv = dict(CONVENTIONS[layout.kind])
    if conventions:
        conv.update({k: v for k, v in conventions.items() if v is not None})
    out = np.asarray(output, dtype=np.float32)
    if out.ndim == 3:
        if out.shape[0] != 1:
            raise InvalidValueError(f"postprocess takes one image's output, got {out.shape}")
        out = out[0]
    boxes, scores, classes = DECODERS[layout.kind](out, layout, conv)
    res = np.empty((len(scores), 6), dtype=np.float32)
    res[:, :4] = box.to_image(boxes)
    res[:, 4] = scores
    res[:, 5] = classes
    return clip_boxes(res, image_size) if clip else res


# --------------------------------------------------------------------------------------------
# Sessions


#: Options of onnxruntime's CUDA provider: full float32 arithmetic (no TF32 tensor-core
#: rounding, which onnxruntime turns on by default on Ampere and later GPUs and which moved
#: COCO mAP50 by up to a point against the CPU in benchmarks/speed/providers.py).
CUDA_OPTIONS: dict[str, str] = {"use_tf32": "0"}


#: Why a model runs on the CPU although CUDA is offered (``Detector.provider_note``).
CPU_ONLY_NOTE = ("dynamically quantised (ConvInteger, which onnxruntime's CUDA provider does not "
                 "run): on the CPU, where its detections are those of the shipped tables")


def integer_operators(path: str | os.PathLike[str]) -> frozenset[str]:
    """The integer-arithmetic operators (``ConvInteger``, ``MatMulInteger``,
    ``DynamicQuantizeLinear``) in the graph of the ONNX model at ``path`` (read with the
    ``onnx`` package, weights left out); empty when ``onnx`` is not installed."""
    try:
        import onnx
    except ImportError:
        return frozenset()
    model = onnx.load(str(path), load_external_data=False)
    ops = {n.op_type for n in model.graph.node}
    return frozenset(ops & {"ConvInteger", "MatMulInteger", "DynamicQuantizeLinear"})


def default_providers() -> list[str]:
    """Execution providers, best first: CUDA when onnxruntime offers it, then CPU."""
    import onnxruntime as ort

    avail = ort.get_available_providers()
    chosen = [p for p in ("CUDAExecutionProvider",) if p in avail]
    return chosen + ["CPUExecutionProvider"]


@record
class PreparedImage:
    """One image ready for the network: its (3, H, W) input, placement and original size."""

    tensor: np.ndarray
    letterbox: Letterbox
    image_size: tuple[int, int]  # (height, width) of the original image


class Detector:
    """An ONNX COCO detector: ``detector(rgb_uint8) -> (K, 6)`` detections in image pixels.

    ``threads``: onnxruntime intra-op threads (``None``: onnxruntime's default, all cores).
    ``provider``: ``"auto"`` (CUDA if present, else CPU), ``"cpu"`` or ``"cuda"``.
    ``conf``/``iou``/``max_det`` override the authors' conventions (``None`` keeps them).
    ``batch``: images per network call for a model with a symbolic batch dimension (default
    8); a static batch dimension fixes it.

    The per-image work is split so that callers can overlap it: :meth:`prepare` (resize and
    letterbox, thread-safe), :meth:`infer` (the network, several images at once where the
    model allows), :meth:`finish` (decode, NMS, boxes back to the image; thread-safe);
    :meth:`detect_stream` runs the three over an iterable of images.
    """

    def __init__(self, path: str | os.PathLike[str], *, threads: int | None = None,
                 provider: str = "auto", conf: float | None = None, iou: float | None = None,
                 max_det: int | None = None, batch: int | None = None) -> None:
        import onnxruntime as ort

        p = Path(path)
        if not p.is_file():
            raise InputFileError(f"{p}: model file does not exist")
        opts = ort.SessionOptions()
        if threads is not None:
            if threads < 1:
                raise InvalidValueError(f"threads must be >= 1, got {threads}")
            opts.intra_op_num_threads = int(threads)
            opts.inter_op_num_threads = 1
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.provider_note: str | None = None
        if provider == "auto":
            providers = [(name, CUDA_OPTIONS) if name == "CUDAExecutionProvider" else name
                         for name in default_providers()]
            if len(providers) > 1 and "ConvInteger" in integer_operators(p):
                providers = ["CPUExecutionProvider"]
                self.provider_note = CPU_ONLY_NOTE
        elif provider == "cpu":
            providers = ["CPUExecutionProvider"]
        elif provider == "cuda":
            providers = [("CUDAExecutionProvider", CUDA_OPTIONS), "CPUExecutionProvider"]
            if "CUDAExecutionProvider" not in ort.get_available_providers():
                raise InvalidValueError(
                    f"--provider cuda: this onnxruntime ({ort.__version__}) has no CUDA "
                    f"execution provider (it offers {', '.join(ort.get_available_providers())}); "
                    f"install onnxruntime-gpu, or use --provider cpu")
            if "ConvInteger" in integer_operators(p):
                raise InvalidValueError(
                    f"--provider cuda: {p.name} is dynamically quantised (ConvInteger), which "
                    f"onnxruntime's CUDA provider does not run: its nodes would run on the CPU "
                    f"inside a CUDA session, whose detections differ from a CPU session's "
                    f"(benchmarks/speed/providers.py); use --provider cpu")
        else:
            raise InvalidValueError(f"provider {provider!r}: expected auto, cpu or cuda")
        try:
            self.session = ort.InferenceSession(str(p), sess_options=opts, providers=providers)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputFileError(f"{p}: onnxruntime cannot load the model: {exc}") from exc
        if provider == "cuda" and "CUDAExecutionProvider" not in self.session.get_providers():
            # onnxruntime falls back to the CPU, with a log line only, when the CUDA provider
            # cannot start (no GPU, a missing CUDA or cuDNN library)
            raise InvalidValueError(
                f"--provider cuda: onnxruntime could not start its CUDA provider for {p.name} "
                f"(no GPU, or CUDA/cuDNN libraries not found); use --provider cpu")
        meta = dict(self.session.get_modelmeta().custom_metadata_map)
        self.path = p
        self.threads = threads
        inputs = self.session.get_inputs()
        self.layout = recognise_layout(
            [(i.name, list(i.shape)) for i in inputs],
            [(o.name, list(o.shape)) for o in self.session.get_outputs()], meta, str(p))
        check_detector(self.layout, str(p))
        self.input_dtype = np.float16 if inputs[0].type == "tensor(float16)" else np.float32
        self.conventions = dict(CONVENTIONS[self.layout.kind])
        for k, v in (("conf", conf), ("iou", iou), ("max_det", max_det)):
            if v is not None:
                self.conventions[k] = v
        if batch is not None and batch < 1:
            raise InvalidValueError(f"batch must be >= 1, got {batch}")
        if self.layout.batch is not None:  # static: the model decides
            self.batch = self.layout.batch
        else:
            self.batch = batch or 8
        self.preprocessing = preprocessing_for(self.layout)
        self.providers = self.session.get_providers()

    @property
    def name(self) -> str:
        """Model name: the file stem."""
        return self.path.stem

    def describe(self) -> dict[str, Any]:
        """Layout, input size, conventions, provider and threads, for reports and JSON output."""
        return {
            "model": self.name, "file": self.path.name, "layout": self.layout.kind,
            "input_size": list(self.layout.input_size), "classes": self.layout.num_classes,
            "conventions": self.conventions, "providers": self.providers,
            "threads": self.threads, "batch": self.batch,
            "preprocessing": self.preprocessing.describe(),
            "ultralytics_version": self.layout.metadata.get("version"),
            **({"provider_note": self.provider_note} if self.provider_note else {}),
        }

    # -- the three stages ---------------------------------------------------------------------

    def prepare(self, rgb: np.ndarray, out: np.ndarray | None = None) -> PreparedImage:
        """Resize and place an (H, W, 3) uint8 RGB image: the (3, H, W) float32 model input.

        ``out``: a (3, H, W) float32 buffer to write the input into (reused buffers spare the
        page faults of a fresh multi-MiB array per image); a new one when omitted.
        """
        a = _check_image(rgb)
        placement = self.preprocessing.place(a, self.layout.input_size)
        shape = (3, *self.layout.input_size)
        x = out if out is not None and out.shape == shape and out.dtype == np.float32 \
            else np.empty(shape, dtype=np.float32)
        self.preprocessing.fill(placement, x)
        return PreparedImage(x, placement.letterbox, (a.shape[0], a.shape[1]))

    def infer(self, tensors: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Run the network on (3, H, W) inputs; one raw output (with a batch axis of 1) each.

        Each output is checked (:func:`check_raw_output`: no NaN or infinity, whole class
        indices). Inputs go through in calls of :attr:`batch` images (a static batch dimension larger
        than the images left is filled with copies of the last one, whose outputs are dropped).
        """
        outs: list[np.ndarray] = []
        for s in range(0, len(tensors), self.batch):
            chunk = list(tensors[s:s + self.batch])
            n = len(chunk)
            if self.layout.batch is not None and n < self.layout.batch:
                chunk += [chunk[-1]] * (self.layout.batch - n)
            x = chunk[0][None] if len(chunk) == 1 else np.stack(chunk)
            if x.dtype != self.input_dtype:
                x = x.astype(self.input_dtype)
            y = self.session.run([self.layout.output_name], {self.layout.input_name: x})[0]
            for k in range(n):
                out = np.asarray(y[k:k + 1], dtype=np.float32)
                check_raw_output(out, self.layout, str(self.path))
                outs.append(out)
        return outs

    def finish(self, output: np.ndarray, prepared: PreparedImage, clip: bool = True
               ) -> np.ndarray:
        """Detections (K, 6) in image pixels from one image's raw output (:func:`postprocess`)."""
        return postprocess(output, self.layout, prepared.letterbox, prepared.image_size,
                           self.conventions, clip=clip)

    def raw(self, rgb: np.ndarray) -> tuple[np.ndarray, Letterbox]:
        """Run the network on an (H, W, 3) uint8 RGB image; raw output and letterbox geometry."""
        p = self.prepare(rgb)
        return self.infer([p.tensor])[0], p.letterbox

    def __call__(self, rgb: np.ndarray, clip: bool = True) -> np.ndarray:
        p = self.prepare(rgb)
        return self.finish(self.infer([p.tensor])[0], p, clip)

    # -- many images --------------------------------------------------------------------------

    def detect_stream(self, items: Iterable[K], load: Callable[[K], np.ndarray], *,
                      prefetch: int = 4, workers: int = 1, clip: bool = True
                      ) -> Iterator[tuple[K, np.ndarray]]:
        """Detections of many images, in the order of ``items``: ``(item, (K, 6))`` pairs.

        ``load(item)`` returns the (H, W, 3) uint8 RGB image of an item (read, decode,
        transform...). Loading and :meth:`prepare` run on a pool of ``workers`` threads up to
        ``prefetch`` images ahead of the network, and :meth:`finish` runs on the same pool
        behind it, so that on a machine with a core to spare the loop runs at the speed of
        :meth:`infer` alone (JPEG decoding, ``cv2.resize``, numpy and onnxruntime release the
        GIL). With ``workers=1`` (the default) ``load`` is called from one thread, in order,
        so it may use state that is not thread-safe. An exception from ``load`` is raised here,
        at its item. The generator may be abandoned early; queued work is cancelled.
        """
        if prefetch < 1 or workers < 1:
            raise InvalidValueError(f"prefetch and workers must be >= 1, got {prefetch}, "
                                    f"{workers}")
        from concurrent.futures import ThreadPoolExecutor

        source = iter(items)
        pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="fidelity-detect")
        ahead: deque[tuple[K, Future[PreparedImage]]] = deque()
        behind: deque[tuple[K, Future[np.ndarray]]] = deque()
        exhausted = False
        spare: list[np.ndarray] = []  # input buffers the network is done with (list ops are
        # atomic under the GIL; at most ahead + one batch are in use, so none is overwritten)

        def load_prepare(item: K) -> PreparedImage:
            rgb = load(item)
            try:
                buf = spare.pop()
            except IndexError:
                buf = None
            return self.prepare(rgb, buf)

        def top_up() -> None:
            nonlocal exhausted
            while not exhausted and len(ahead) < max(prefetch, self.batch):
                try:
                    item = next(source)
                except StopIteration:
                    exhausted = True
                    return
                ahead.append((item, pool.submit(load_prepare, item)))

        try:
            top_up()
            while ahead:
                batch: list[tuple[K, PreparedImage]] = []
                error: BaseException | None = None
                while ahead and len(batch) < self.batch:
                    item, fut = ahead.popleft()
                    error = fut.exception()
                    if error is not None:  # deliver the items before it, then raise
                        break
                    batch.append((item, fut.result()))
                if error is None:
                    top_up()
                if batch:
                    outs = self.infer([p.tensor for _, p in batch])
                    for (item, p), out in zip(batch, outs, strict=True):
                        behind.append((item, pool.submit(self.finish, out, p, clip)))
                        spare.append(p.tensor)
                if error is not None:
                    while behind:
                        item, done = behind.popleft()
                        yield item, done.result()
                    raise error
                while behind and (behind[0][1].done() or len(behind) > prefetch):
                    item, done = behind.popleft()
                    yield item, done.result()
            while behind:
                item, done = behind.popleft()
                yield item, done.result()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
