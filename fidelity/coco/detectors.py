"""COCO object detectors through onnxruntime, with the validation conventions of their authors.

The output layout is recognised from the model itself (input/output shapes and metadata), never
from its file name:

``ultralytics``  one output ``1 x (4+C) x N`` (e.g. 1x84x8400): rows ``cx, cy, w, h`` in
    letterboxed pixels followed by C class scores (sigmoid already applied). Needs NMS.
    Validation conventions (Ultralytics ``DetectionValidator``): confidence 0.001, IoU 0.7,
    multi-label NMS per class, at most 30000 boxes into NMS and 300 detections out.
``ultralytics-e2e``  one output ``1 x K x 6`` (YOLOv10 end-to-end, e.g. 1x300x6):
    ``x1, y1, x2, y2, score, class`` in letterboxed pixels; NMS-free. Conventions: confidence
    0.001, 300 out.
``yolox``  one output ``1 x N x (5+C)`` where N equals the number of grid cells of strides
    8/16/32 for the input size (3549 for 416x416): raw ``x, y, log w, log h, objectness, C class
    scores`` (objectness and classes already sigmoid). Decode ``xy = (p + grid) * stride``,
    ``wh = exp(p) * stride``, score = obj * max class. Conventions (YOLOX ``COCOEvaluator`` /
    ``yolox_base.Exp``): confidence 0.01, NMS IoU 0.65 per class, single label per box, no cap
    on detections (COCO scoring keeps the best 100 per image).

Preprocessing per family:

* Ultralytics: letterbox to the model's square input keeping aspect ratio, centred, pad value
  114, bilinear resize (OpenCV ``INTER_LINEAR`` convention, reproduced in numpy), RGB, /255.
* YOLOX: resize by ``r = min(S/h, S/w)`` into the top-left corner, pad 114, BGR, 0-255 floats
  (``ValTransform(legacy=False)``).

Boxes are returned in original image pixels as ``x1, y1, x2, y2`` plus score and a COCO
*class index* 0..C-1 (the 80-class contiguous index; :func:`coco80_to_category_ids` maps it to
annotation category ids).
"""

from __future__ import annotations

import ast
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.errors import InputFileError, InvalidValueError

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

#: Validation conventions per layout (the model authors' own evaluation settings).
CONVENTIONS: dict[str, dict[str, Any]] = {
    "ultralytics": {
        "source": "Ultralytics DetectionValidator (yolo val defaults)",
        "conf": 0.001, "iou": 0.7, "max_det": 300, "max_nms": 30000, "multi_label": True,
        "preprocess": "letterbox centred, pad 114, bilinear, RGB/255",
    },
    "ultralytics-e2e": {
        "source": "Ultralytics DetectionValidator, end-to-end head (YOLOv10), no NMS",
        "conf": 0.001, "iou": None, "max_det": 300, "max_nms": None, "multi_label": False,
        "preprocess": "letterbox centred, pad 114, bilinear, RGB/255",
    },
    "yolox": {
        "source": "YOLOX COCOEvaluator with yolox_base.Exp test_conf / nmsthre",
        "conf": 0.01, "iou": 0.65, "max_det": None, "max_nms": None, "multi_label": False,
        "preprocess": "resize into top-left corner, pad 114, bilinear, BGR 0-255",
    },
}

#: Detection array columns: x1, y1, x2, y2, score, class index.
DETECTION_COLUMNS: tuple[str, ...] = ("x1", "y1", "x2", "y2", "score", "class")


@dataclass(frozen=True)
class ModelLayout:
    """What :func:`recognise_layout` found out about a model."""

    kind: str
    input_name: str
    input_size: tuple[int, int]  # (height, width)
    num_classes: int
    output_name: str
    names: tuple[str, ...]
    metadata: dict[str, str] = field(default_factory=dict)


def _static_dims(shape: list[Any], what: str, path: str) -> list[int]:
    dims = []
    for d in shape:
        if not isinstance(d, int):
            raise InputFileError(f"{path}: {what} has a dynamic dimension {d!r} (shape {shape}); "
                                 "export the model with a static batch-1 input")
        dims.append(d)
    return dims


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

    Rules (first match wins): a single ``1x3xHxW`` input and a single 3-D output;
    ``1 x 6 x K`` is never accepted (ambiguous); ``1 x K x 6`` with metadata ``end2end`` true
    or K <= 1000 is the YOLOv10 end-to-end layout; ``1 x (4+C) x N`` with N equal to the anchor
    count of strides 8/16/32 is Ultralytics; ``1 x N x (5+C)`` with N equal to that anchor count
    is YOLOX. Anything else raises :class:`InputFileError` naming the shapes.
    """
    meta = dict(metadata or {})
    if len(input_shapes) != 1:
        raise InputFileError(f"{path}: expected one input tensor, found {len(input_shapes)}: "
                             f"{input_shapes}; not a recognised detector layout")
    in_name, in_shape = input_shapes[0]
    dims = _static_dims(list(in_shape), "input", path)
    if len(dims) != 4 or dims[0] != 1 or dims[1] != 3:
        raise InputFileError(f"{path}: input {in_name!r} has shape {dims}; expected 1x3xHxW")
    h, w = dims[2], dims[3]
    if len(output_shapes) != 1:
        raise InputFileError(f"{path}: expected one output tensor, found {len(output_shapes)} "
                             f"({output_shapes}); not a recognised detector layout "
                             "(Ultralytics 1x84xN, YOLOv10 1x300x6, YOLOX 1xNx85)")
    out_name, out_shape = output_shapes[0]
    odims = _static_dims(list(out_shape), "output", path)
    anchors = _yolox_cells(h, w)
    if len(odims) == 3 and odims[0] == 1:
        _, a, b = odims
        e2e_flag = str(meta.get("end2end", "")).lower() == "true"
        if b == 6 and (e2e_flag or a <= 1000) and a != anchors:
            names = _names_from_metadata(meta, 80)
            return ModelLayout("ultralytics-e2e", in_name, (h, w), len(names), out_name,
                               names, meta)
        if b == anchors and a > 4:
            nc = a - 4
            return ModelLayout("ultralytics", in_name, (h, w), nc, out_name,
                               _names_from_metadata(meta, nc), meta)
        if a == anchors and b > 5:
            nc = b - 5
            return ModelLayout("yolox", in_name, (h, w), nc, out_name,
                               _names_from_metadata(meta, nc), meta)
    raise InputFileError(
        f"{path}: unrecognised detector output layout {odims} for input {dims}; known layouts: "
        f"Ultralytics 1x(4+C)x{anchors}, YOLOv10 end-to-end 1xKx6, YOLOX 1x{anchors}x(5+C)")


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


def resize_bilinear(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Bilinear resize with OpenCV ``INTER_LINEAR`` sampling (half-pixel centres, no antialias).

    ``image``: (H, W, C) uint8 or float. Returns float32 (h, w, C) in the input's value range.
    Source coordinate ``x = (i + 0.5) * W / w - 0.5`` clamped to the image, as OpenCV does.
    """
    src_h, src_w = image.shape[:2]
    if (src_h, src_w) == (height, width):
        return image.astype(np.float32)

    def axis(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = (np.arange(n_out, dtype=np.float64) + 0.5) * (n_in / n_out) - 0.5
        x = np.clip(x, 0, n_in - 1)
        x0 = np.floor(x).astype(np.intp)
        x1 = np.minimum(x0 + 1, n_in - 1)
        return x0, x1, (x - x0).astype(np.float32)

    y0, y1, fy = axis(height, src_h)
    x0, x1, fx = axis(width, src_w)
    top = image[y0].astype(np.float32)
    rows = top + (image[y1].astype(np.float32) - top) * fy[:, None, None]
    left = rows[:, x0]
    out: np.ndarray = left + (rows[:, x1] - left) * fx[None, :, None]
    return out


@dataclass(frozen=True)
class Letterbox:
    """Geometry that maps model-input pixels back to original image pixels."""

    gain: float
    pad_x: float
    pad_y: float


def preprocess(rgb: np.ndarray, layout: ModelLayout) -> tuple[np.ndarray, Letterbox]:
    """Turn an (H, W, 3) uint8 RGB image into the model's 1x3xHxW float32 input."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InvalidValueError(f"image has shape {rgb.shape}; expected (H, W, 3) RGB")
    th, tw = layout.input_size
    h, w = rgb.shape[:2]
    r = min(th / h, tw / w)
    x = np.full((1, 3, th, tw), 114.0, dtype=np.float32)
    if layout.kind == "yolox":
        nh, nw = int(h * r), int(w * r)
        top = left = 0
        order = (2, 1, 0)  # BGR, 0-255
        box = Letterbox(r, 0.0, 0.0)
    else:
        nw, nh = int(round(w * r)), int(round(h * r))
        dw, dh = (tw - nw) / 2, (th - nh) / 2
        top, left = int(round(dh - 0.1)), int(round(dw - 0.1))
        order = (0, 1, 2)  # RGB
        box = Letterbox(r, float(left), float(top))
    resized = resize_bilinear(rgb, nh, nw)
    for c, src in enumerate(order):
        x[0, c, top:top + nh, left:left + nw] = resized[:, :, src]
    if layout.kind != "yolox":
        x /= np.float32(255.0)
    return x, box


# --------------------------------------------------------------------------------------------
# Postprocessing


def nms(boxes: np.ndarray, scores: np.ndarray, iou: float, max_keep: int | None = None
        ) -> np.ndarray:
    """Greedy non-maximum suppression (torchvision ``nms`` semantics): indices kept, best first.

    A box is suppressed when its IoU with a kept higher-scoring box is strictly above ``iou``.
    ``max_keep`` stops after that many kept boxes (exact, since kept boxes come in score order).
    """
    order = np.argsort(-scores, kind="stable")
    x1, y1, x2, y2 = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
    areas = np.maximum(x2 - x1, 0) * np.maximum(y2 - y1, 0)
    keep: list[int] = []
    while order.size:
        i = order[0]
        keep.append(int(i))
        if max_keep is not None and len(keep) >= max_keep:
            break
        rest = order[1:]
        xx1 = np.maximum(x1[i], x1[rest])
        yy1 = np.maximum(y1[i], y1[rest])
        xx2 = np.minimum(x2[i], x2[rest])
        yy2 = np.minimum(y2[i], y2[rest])
        inter = np.maximum(xx2 - xx1, 0) * np.maximum(yy2 - yy1, 0)
        union = areas[i] + areas[rest] - inter
        ious = np.where(union > 0, inter / np.where(union > 0, union, 1), 0)
        order = rest[ious <= iou]
    return np.asarray(keep, dtype=np.intp)


def batched_nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray, iou: float,
                max_keep: int | None = None, offset: float = 7680.0) -> np.ndarray:
    """Per-class NMS by offsetting each class's boxes (Ultralytics ``max_wh`` = 7680 trick)."""
    shifted = boxes + (classes.astype(np.float32) * offset)[:, None]
    return nms(shifted, scores, iou, max_keep)


def _xywh_to_xyxy(b: np.ndarray) -> np.ndarray:
    out = np.empty_like(b)
    out[:, 0] = b[:, 0] - b[:, 2] / 2
    out[:, 1] = b[:, 1] - b[:, 3] / 2
    out[:, 2] = b[:, 0] + b[:, 2] / 2
    out[:, 3] = b[:, 1] + b[:, 3] / 2
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


def postprocess(output: np.ndarray, layout: ModelLayout, box: Letterbox,
                image_size: tuple[int, int], conventions: dict[str, Any] | None = None
                ) -> np.ndarray:
    """Decode a raw model output into (K, 6) float32 ``x1, y1, x2, y2, score, class`` rows.

    Boxes are mapped back to the original image (``(x - pad) / gain``) and clipped to it.
    """
    conv = dict(CONVENTIONS[layout.kind])
    if conventions:
        conv.update({k: v for k, v in conventions.items() if v is not None})
    conf, iou, max_det = conv["conf"], conv["iou"], conv["max_det"]
    out = np.asarray(output, dtype=np.float32)[0]
    if layout.kind == "ultralytics":
        pred = out.T  # (N, 4+C)
        cls_scores = pred[:, 4:]
        if conv.get("multi_label", True):
            ii, jj = np.nonzero(cls_scores > conf)
            boxes = _xywh_to_xyxy(pred[ii, :4])
            scores = cls_scores[ii, jj]
            classes = jj
        else:
            jj = cls_scores.argmax(1)
            scores = cls_scores[np.arange(len(jj)), jj]
            ii = np.nonzero(scores > conf)[0]
            boxes, scores, classes = _xywh_to_xyxy(pred[ii, :4]), scores[ii], jj[ii]
        max_nms = conv.get("max_nms") or len(scores)
        if len(scores) > max_nms:
            top = np.argsort(-scores, kind="stable")[:max_nms]
            boxes, scores, classes = boxes[top], scores[top], classes[top]
        keep = batched_nms(boxes, scores, classes, iou, max_det)
        boxes, scores, classes = boxes[keep], scores[keep], classes[keep]
    elif layout.kind == "ultralytics-e2e":
        sel = out[:, 4] > conf
        d = out[sel]
        if max_det is not None:
            d = d[np.argsort(-d[:, 4], kind="stable")[:max_det]]
        boxes, scores, classes = d[:, :4].copy(), d[:, 4], d[:, 5].astype(np.intp)
    elif layout.kind == "yolox":
        grid, strides = yolox_grid(*layout.input_size)
        xy = (out[:, :2] + grid) * strides
        wh = np.exp(out[:, 2:4]) * strides
        cls = out[:, 5:]
        jj = cls.argmax(1)
        scores = out[:, 4] * cls[np.arange(len(jj)), jj]
        sel = scores >= conf
        boxes = _xywh_to_xyxy(np.concatenate([xy, wh], 1)[sel])
        scores, classes = scores[sel], jj[sel]
        keep = batched_nms(boxes, scores, classes, iou, max_det)
        boxes, scores, classes = boxes[keep], scores[keep], classes[keep]
    else:  # pragma: no cover - layouts are closed
        raise InvalidValueError(f"unknown layout {layout.kind!r}")
    h, w = image_size
    boxes = boxes.astype(np.float32)
    boxes[:, [0, 2]] = np.clip((boxes[:, [0, 2]] - box.pad_x) / box.gain, 0, w)
    boxes[:, [1, 3]] = np.clip((boxes[:, [1, 3]] - box.pad_y) / box.gain, 0, h)
    res = np.empty((len(scores), 6), dtype=np.float32)
    res[:, :4] = boxes
    res[:, 4] = scores
    res[:, 5] = classes
    return res


# --------------------------------------------------------------------------------------------
# Sessions


def default_providers() -> list[str]:
    """Execution providers, best first: CUDA when onnxruntime offers it, then CPU."""
    import onnxruntime as ort

    avail = ort.get_available_providers()
    chosen = [p for p in ("CUDAExecutionProvider",) if p in avail]
    return chosen + ["CPUExecutionProvider"]


class Detector:
    """An ONNX COCO detector: ``detector(rgb_uint8) -> (K, 6)`` detections in image pixels.

    ``threads``: onnxruntime intra-op threads (``None``: onnxruntime's default, all cores).
    ``provider``: ``"auto"`` (CUDA if present, else CPU), ``"cpu"`` or ``"cuda"``.
    ``conf``/``iou``/``max_det`` override the authors' conventions (``None`` keeps them).
    """

    def __init__(self, path: str | os.PathLike[str], *, threads: int | None = None,
                 provider: str = "auto", conf: float | None = None, iou: float | None = None,
                 max_det: int | None = None) -> None:
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
        if provider == "auto":
            providers = default_providers()
        elif provider == "cpu":
            providers = ["CPUExecutionProvider"]
        elif provider == "cuda":
            providers = ["CUDAExecutionProvider", "CPUExecutionProvider"]
        else:
            raise InvalidValueError(f"provider {provider!r}: expected auto, cpu or cuda")
        try:
            self.session = ort.InferenceSession(str(p), sess_options=opts, providers=providers)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputFileError(f"{p}: onnxruntime cannot load the model: {exc}") from exc
        meta = dict(self.session.get_modelmeta().custom_metadata_map)
        self.path = p
        self.threads = threads
        self.layout = recognise_layout(
            [(i.name, list(i.shape)) for i in self.session.get_inputs()],
            [(o.name, list(o.shape)) for o in self.session.get_outputs()], meta, str(p))
        check_detector(self.layout, str(p))
        self.conventions = dict(CONVENTIONS[self.layout.kind])
        for k, v in (("conf", conf), ("iou", iou), ("max_det", max_det)):
            if v is not None:
                self.conventions[k] = v
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
            "threads": self.threads,
            "ultralytics_version": self.layout.metadata.get("version"),
        }

    def raw(self, rgb: np.ndarray) -> tuple[np.ndarray, Letterbox]:
        """Run the network on an (H, W, 3) uint8 RGB image; raw output and letterbox geometry."""
        x, box = preprocess(rgb, self.layout)
        out = self.session.run([self.layout.output_name], {self.layout.input_name: x})[0]
        check_raw_output(out, self.layout, str(self.path))
        return out, box

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        out, box = self.raw(rgb)
        return postprocess(out, self.layout, box, rgb.shape[:2], self.conventions)
