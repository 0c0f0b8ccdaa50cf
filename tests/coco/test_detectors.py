"""Detector layouts, preprocessing, decoding and NMS against references and brute force.

The preprocessing references below are straightforward transcriptions of what the detector
authors' validation code does to an image (OpenCV resize on the BGR uint8 image as ``imread``
gives it, ``copyMakeBorder`` / a canvas of 114, ``ops.scale_boxes``), written step by step
from their description; the production code must give the same model input bit for bit.
"""

from __future__ import annotations

import json
import math

import cv2  # any OpenCV build: only cv2.resize, cvtColor and copyMakeBorder are used
import numpy as np
import pytest

from fidelity.coco.detectors import (
    COCO80_CATEGORY_IDS,
    COCO80_NAMES,
    Detector,
    Letterbox,
    batched_nms,
    clip_boxes,
    letterbox_ultralytics,
    letterbox_yolox,
    nms,
    postprocess,
    preprocess,
    recognise_layout,
    torchvision_batched_nms,
)
from fidelity.core.errors import InputFileError, InvalidValueError

IMG = [("images", [1, 3, 640, 640])]
ULTRA = recognise_layout(IMG, [("output0", [1, 84, 8400])])
E2E = recognise_layout(IMG, [("output0", [1, 300, 6])], {"end2end": "True"})
YOLOX = recognise_layout([("images", [1, 3, 416, 416])], [("output", [1, 3549, 85])])


# --------------------------------------------------------------------------------------------
# References (transcriptions of the authors' validation code paths)


def reference_ultralytics(rgb: np.ndarray, size: tuple[int, int] = (640, 640)):
    """Ultralytics ``yolo val``: load_image (long side, ceil) + LetterBox(scaleup=False)."""
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)  # what cv2.imread returns
    h0, w0 = bgr.shape[:2]
    imgsz = max(size)
    r = imgsz / max(h0, w0)
    im = bgr
    if r != 1:
        w, h = (min(math.ceil(w0 * r), imgsz), min(math.ceil(h0 * r), imgsz))
        im = cv2.resize(im, (w, h), interpolation=cv2.INTER_LINEAR)
    h, w = im.shape[:2]
    ratio_pad = (h / h0, w / w0)
    r = min(min(size[0] / h, size[1] / w), 1.0)
    new_unpad = (max(round(w * r), 1), max(round(h * r), 1))
    dw, dh = (size[1] - new_unpad[0]) / 2, (size[0] - new_unpad[1]) / 2
    if (w, h) != new_unpad:
        im = cv2.resize(im, new_unpad, interpolation=cv2.INTER_LINEAR)
    top, bottom = round(dh - 0.1), round(dh + 0.1)
    left, right = round(dw - 0.1), round(dw + 0.1)
    im = cv2.copyMakeBorder(im, top, bottom, left, right, cv2.BORDER_CONSTANT,
                            value=(114, 114, 114))
    x = np.ascontiguousarray(im.transpose(2, 0, 1)[::-1])  # HWC BGR -> CHW RGB
    x = x.astype(np.float32) / 255
    gains = (ratio_pad[0] * r, ratio_pad[1] * r)
    return x, (gains, (left, top))


def reference_scale_boxes(boxes: np.ndarray, ratio_pad, shape: tuple[int, int]) -> np.ndarray:
    """``ops.scale_boxes`` with ``ratio_pad``: subtract the pad, divide by per-axis gain, clip."""
    b = boxes.astype(np.float32).copy()
    (gain_y, gain_x), (pad_x, pad_y) = ratio_pad
    b[:, 0] -= pad_x
    b[:, 1] -= pad_y
    b[:, 2] -= pad_x
    b[:, 3] -= pad_y
    b[:, 0] /= gain_x
    b[:, 1] /= gain_y
    b[:, 2] /= gain_x
    b[:, 3] /= gain_y
    b[:, [0, 2]] = b[:, [0, 2]].clip(0, shape[1])
    b[:, [1, 3]] = b[:, [1, 3]].clip(0, shape[0])
    return b


def reference_yolox(rgb: np.ndarray, size: tuple[int, int] = (416, 416)):
    """YOLOX COCOEvaluator: COCODataset.load_resized_img, then ValTransform's preproc."""
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    r = min(size[0] / img.shape[0], size[1] / img.shape[1])
    img = cv2.resize(img, (int(img.shape[1] * r), int(img.shape[0] * r)),
                     interpolation=cv2.INTER_LINEAR).astype(np.uint8)
    padded = np.ones((size[0], size[1], 3), dtype=np.uint8) * 114
    r2 = min(size[0] / img.shape[0], size[1] / img.shape[1])
    resized = cv2.resize(img, (int(img.shape[1] * r2), int(img.shape[0] * r2)),
                         interpolation=cv2.INTER_LINEAR).astype(np.uint8)
    padded[: int(img.shape[0] * r2), : int(img.shape[1] * r2)] = resized
    return np.ascontiguousarray(padded.transpose(2, 0, 1), dtype=np.float32), r


def textured(h: int, w: int, seed: int = 0, gray: bool = False) -> np.ndarray:
    """A smooth-plus-noise test image (resizing it exercises every interpolation weight)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    base = 127 + 100 * np.sin(xx / 7.0 + seed) * np.cos(yy / 5.0)
    img = base[..., None] + rng.normal(0, 20, (h, w, 1 if gray else 3))
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.repeat(img, 3, axis=2) if gray else img


#: Upscaled, downscaled, exact, odd-sized, thin, portrait, grayscale; YOLOX sizes whose int()
#: truncation leaves the long side a pixel short (23, 93 for 416).
CASES = [((480, 640), False), ((375, 500), False), ((240, 320), False), ((1000, 750), False),
         ((427, 640), False), ((640, 480), False), ((333, 517), False), ((641, 640), False),
         ((1, 900), False), ((900, 3), False), ((60, 93), False), ((10, 23), False),
         ((211, 317), True), ((640, 640), False), ((2000, 1337), True)]


# --------------------------------------------------------------------------------------------
# Layouts


def test_recognise_known_layouts() -> None:
    assert ULTRA.kind == "ultralytics" and ULTRA.batch == 1
    assert E2E.kind == "ultralytics-e2e"
    assert YOLOX.kind == "yolox" and YOLOX.num_classes == 80 and YOLOX.input_size == (416, 416)
    assert YOLOX.names == COCO80_NAMES
    # the anchor count follows the input size, not a constant: 8400 = 80^2 + 40^2 + 20^2
    assert recognise_layout(IMG, [("o", [1, 8400, 85])]).kind == "yolox"


def test_names_from_ultralytics_metadata() -> None:
    names = {i: f"c{i}" for i in range(80)}
    lay = recognise_layout(IMG, [("output0", [1, 84, 8400])], {"names": repr(names)})
    assert lay.names[0] == "c0" and lay.names[79] == "c79"


@pytest.mark.parametrize("out", [[1, 10, 10], [1, 84, 8000], [2, 84, 8400], [1, 8400]])
def test_unknown_layout_is_a_clear_error(out: list[int]) -> None:
    with pytest.raises(InputFileError, match="unrecognised detector output layout"):
        recognise_layout(IMG, [("o", out)], path="m.onnx")


def test_batch_dimension_static_or_symbolic() -> None:
    dyn = recognise_layout([("images", ["batch", 3, 640, 640])], [("o", ["batch", 84, 8400])])
    assert dyn.kind == "ultralytics" and dyn.batch is None
    four = recognise_layout([("images", [4, 3, 416, 416])], [("o", [4, 3549, 85])])
    assert four.kind == "yolox" and four.batch == 4
    with pytest.raises(InputFileError, match="dynamic"):  # spatial dims must be static
        recognise_layout([("images", [1, 3, "h", "w"])], [("o", [1, 84, 8400])])
    with pytest.raises(InputFileError, match="one output"):
        recognise_layout(IMG, [("a", [1, 84, 8400]), ("b", [1, 84, 8400])])


def test_coco80_mapping_is_official() -> None:
    assert len(COCO80_CATEGORY_IDS) == 80 == len(set(COCO80_CATEGORY_IDS))
    assert COCO80_CATEGORY_IDS[COCO80_NAMES.index("bicycle")] == 2
    assert COCO80_CATEGORY_IDS[COCO80_NAMES.index("stop sign")] == 13
    assert COCO80_CATEGORY_IDS[-1] == 90


# --------------------------------------------------------------------------------------------
# Preprocessing against the references


@pytest.mark.parametrize(("shape", "gray"), CASES)
def test_ultralytics_preprocess_equals_reference(shape: tuple[int, int], gray: bool) -> None:
    img = textured(*shape, seed=shape[0] + shape[1], gray=gray)
    x, box = preprocess(img, ULTRA)
    ref, ratio_pad = reference_ultralytics(img)
    assert x.shape == (1, 3, 640, 640) and x.dtype == np.float32
    np.testing.assert_array_equal(x[0], ref)
    (gain_y, gain_x), (pad_x, pad_y) = ratio_pad
    assert box == Letterbox(gain_x, gain_y, pad_x, pad_y)
    rng = np.random.default_rng(3)
    boxes = rng.uniform(-50, 700, (40, 4)).astype(np.float32)
    dets = np.concatenate([boxes, np.ones((40, 2), np.float32)], 1)
    mapped = clip_boxes(np.concatenate([box.to_image(boxes), dets[:, 4:]], 1), shape)
    np.testing.assert_array_equal(mapped[:, :4], reference_scale_boxes(boxes, ratio_pad, shape))


@pytest.mark.parametrize(("shape", "gray"), CASES)
def test_yolox_preprocess_equals_reference(shape: tuple[int, int], gray: bool) -> None:
    img = textured(*shape, seed=shape[0] * 3 + shape[1], gray=gray)
    x, box = preprocess(img, YOLOX)
    if min(int(s * min(416 / shape[0], 416 / shape[1])) for s in shape) == 0:
        # YOLOX itself fails here (cv2.resize to 0 px); we keep one pixel row or column
        assert x.shape == (1, 3, 416, 416) and x[0, :, 0, 0].tolist() != [114.0] * 3
        return
    ref, r = reference_yolox(img)
    np.testing.assert_array_equal(x[0], ref)
    assert box == Letterbox(r, r, 0.0, 0.0)


def test_ultralytics_preprocess_non_square_input() -> None:
    lay = recognise_layout([("images", [1, 3, 384, 640])], [("o", [1, 84, 5040])])
    for shape in [(480, 640), (640, 480), (300, 200), (1080, 1920)]:
        img = textured(*shape, seed=5)
        x, box = preprocess(img, lay)
        ref, ((gy, gx), (px, py)) = reference_ultralytics(img, (384, 640))
        np.testing.assert_array_equal(x[0], ref)
        assert box == Letterbox(gx, gy, px, py)


def test_upscaling_uses_ceil_sizes_and_per_axis_gains() -> None:
    """A 427x640-style case by hand: 200x333 -> long side 640, ceil(200 * 640/333) = 385."""
    pl = letterbox_ultralytics(np.zeros((200, 333, 3), np.uint8), (640, 640))
    assert pl.image.shape == (385, 640, 3)  # round() would give 384
    assert (pl.top, pl.left) == (round(255 / 2 - 0.1), 0) == (127, 0)
    assert pl.letterbox.gain_y == 385 / 200 and pl.letterbox.gain_x == 640 / 333
    # YOLOX: int() sizes; 23 px wide: int(23 * 416/23) = 415, so its preproc resizes again
    pl = letterbox_yolox(np.zeros((10, 23, 3), np.uint8), (416, 416))
    assert pl.image.shape[1] == int(415 * (416 / 415)) and (pl.top, pl.left) == (0, 0)


def test_letterbox_geometry_ultralytics() -> None:
    img = np.full((480, 640, 3), 200, np.uint8)
    x, box = preprocess(img, ULTRA)
    assert box == Letterbox(1.0, 1.0, 0.0, 80.0)
    np.testing.assert_allclose(x[0, :, 0, 0], 114 / 255, rtol=1e-6)  # pad
    np.testing.assert_allclose(x[0, :, 320, 320], 200 / 255, rtol=1e-6)
    assert np.all(x[0, :, 79, :] == np.float32(114 / 255)) and np.all(x[0, :, 560, :] < 0.5)


def test_yolox_preprocess_is_bgr_top_left() -> None:
    img = np.zeros((200, 400, 3), np.uint8)
    img[..., 0] = 250  # red
    x, box = preprocess(img, YOLOX)
    assert box.gain_x == pytest.approx(416 / 400) and box.pad_x == 0 and box.pad_y == 0
    assert x[0, 2, 10, 10] == 250 and x[0, 0, 10, 10] == 0  # R is channel 2 (BGR), 0-255
    assert x[0, 0, 300, 10] == 114  # padding below the image


def test_preprocess_rejects_non_uint8_rgb() -> None:
    with pytest.raises(InvalidValueError, match="uint8"):
        preprocess(np.zeros((10, 10, 3), np.float32), ULTRA)
    with pytest.raises(InvalidValueError, match="uint8"):
        preprocess(np.zeros((10, 10), np.uint8), ULTRA)


# --------------------------------------------------------------------------------------------
# NMS against brute force


def brute_nms(boxes: np.ndarray, scores: np.ndarray, thr: float) -> list[int]:
    """Textbook greedy NMS, one pair at a time, float32 IoU like torchvision's CPU kernel."""
    order = sorted(range(len(scores)), key=lambda i: (-scores[i], i))  # stable descending
    b = boxes.astype(np.float32)
    keep: list[int] = []
    for i in order:
        ok = True
        for k in keep:
            ix = max(np.float32(0), min(b[i, 2], b[k, 2]) - max(b[i, 0], b[k, 0]))
            iy = max(np.float32(0), min(b[i, 3], b[k, 3]) - max(b[i, 1], b[k, 1]))
            inter = np.float32(ix * iy)
            a = (b[k, 2] - b[k, 0]) * (b[k, 3] - b[k, 1])
            c = (b[i, 2] - b[i, 0]) * (b[i, 3] - b[i, 1])
            if float(inter / (a + c - inter)) > thr:
                ok = False
                break
        if ok:
            keep.append(i)
    return keep


def random_boxes(n: int, seed: int, quantise: bool = False):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 100, (n, 2))
    wh = rng.uniform(5, 40, (n, 2))
    boxes = np.concatenate([xy, xy + wh], 1).astype(np.float32)
    scores = rng.uniform(0, 1, n).astype(np.float32)
    if quantise:  # many equal scores: the tie order matters
        scores = np.round(scores * 8) / 8
    return boxes, scores


@pytest.mark.parametrize(("seed", "thr", "quantise"),
                         [(7, 0.5, False), (8, 0.7, False), (9, 0.65, True), (10, 0.3, True),
                          (11, 0.95, False), (12, 0.0, False), (13, 1.0, True)])
def test_nms_equals_brute_force(seed: int, thr: float, quantise: bool) -> None:
    boxes, scores = random_boxes(300, seed, quantise)
    ref = brute_nms(boxes, scores, thr)
    assert nms(boxes, scores, thr).tolist() == ref
    assert nms(boxes, scores, thr, max_keep=10).tolist() == ref[:10]


def test_nms_clusters_and_long_chains() -> None:
    """Dense clusters of near-duplicates (detector-like) and a chain that needs many rounds."""
    rng = np.random.default_rng(2)
    centres = rng.uniform(0, 600, (20, 2))
    boxes = []
    for c in centres:
        size = rng.uniform(20, 200, 2)
        for _ in range(40):
            xy = c + rng.normal(0, 3, 2)
            s = size * rng.uniform(0.9, 1.1, 2)
            boxes.append([*(xy - s / 2), *(xy + s / 2)])
    b = np.asarray(boxes, np.float32)
    s = rng.uniform(0, 1, len(b)).astype(np.float32)
    assert nms(b, s, 0.7).tolist() == brute_nms(b, s, 0.7)
    # chain: box k overlaps box k+1 only; scores decreasing: keep alternates down the chain
    chain = np.array([[k * 2.0, 0, k * 2.0 + 10, 10] for k in range(200)], np.float32)
    cs = np.linspace(1, 0.1, 200).astype(np.float32)
    ref = brute_nms(chain, cs, 0.6)
    assert nms(chain, cs, 0.6).tolist() == ref
    from fidelity.coco.detectors import _greedy_keep, _overlap_pairs

    i, j = _overlap_pairs(chain, None, 0.6)
    np.testing.assert_array_equal(np.flatnonzero(_greedy_keep(200, i, j, max_rounds=3)), ref)


def test_batched_nms_offsets_like_the_references() -> None:
    boxes, scores = random_boxes(400, 21, quantise=True)
    classes = np.random.default_rng(3).integers(0, 5, 400)
    shifted = boxes + (classes.astype(np.float32) * np.float32(7680))[:, None]
    assert batched_nms(boxes, scores, classes, 0.7, 300).tolist() == \
        brute_nms(shifted, scores, 0.7)[:300]
    # torchvision.ops.batched_nms: offsets (max + 1) per class up to 1000 boxes
    step = np.float32(boxes.max()) + np.float32(1)
    tv = boxes + (classes.astype(np.float32) * step)[:, None]
    assert torchvision_batched_nms(boxes, scores, classes, 0.65).tolist() == \
        brute_nms(tv, scores, 0.65)
    # ... and class by class (boxes as given) above
    big_b, big_s = random_boxes(1200, 22)
    big_c = np.random.default_rng(4).integers(0, 3, 1200)
    keep = torchvision_batched_nms(big_b, big_s, big_c, 0.65)
    per_class = []
    for c in range(3):
        idx = np.flatnonzero(big_c == c)
        per_class += [int(idx[k]) for k in brute_nms(big_b[idx], big_s[idx], 0.65)]
    assert sorted(keep.tolist()) == sorted(per_class)
    assert np.all(np.diff(big_s[keep]) <= 0)


def test_nms_edge_cases() -> None:
    assert nms(np.zeros((0, 4), np.float32), np.zeros(0, np.float32), 0.5).size == 0
    same = np.array([[0, 0, 10, 10]] * 3, np.float32)
    assert nms(same, np.array([0.5, 0.5, 0.5], np.float32), 0.5).tolist() == [0]
    zero = np.array([[5, 5, 5, 5], [5, 5, 5, 5]], np.float32)  # zero area: 0/0 never suppresses
    assert nms(zero, np.array([0.9, 0.8], np.float32), 0.5).tolist() == [0, 1]
    with pytest.raises(InvalidValueError, match="IoU"):
        nms(same, np.ones(3, np.float32), 1.5)


# --------------------------------------------------------------------------------------------
# Decoding


def test_ultralytics_decode_maps_back_to_image() -> None:
    raw = np.zeros((1, 84, 8400), np.float32)
    raw[0, :4, 5] = [320, 330, 100, 60]  # cx, cy, w, h in letterboxed pixels
    raw[0, 4 + 2, 5] = 0.9  # car
    raw[0, :4, 6] = [321, 331, 100, 60]  # duplicate, lower score: suppressed
    raw[0, 4 + 2, 6] = 0.8
    raw[0, 4 + 0, 6] = 0.5  # ... but its person score survives (multi-label, per class NMS)
    det = postprocess(raw, ULTRA, Letterbox(1.0, 1.0, 0.0, 80.0), (480, 640))
    assert det.shape == (2, 6)
    np.testing.assert_allclose(det[0], [270, 220, 370, 280, 0.9, 2], atol=1e-4)
    assert det[1, 5] == 0 and det[1, 4] == pytest.approx(0.5)


def test_per_axis_gains_and_clipping() -> None:
    raw = np.zeros((1, 84, 8400), np.float32)
    raw[0, :4, 0] = [100, 200, 400, 100]  # x 300 wide from -100 to 300
    raw[0, 4 + 1, 0] = 0.7
    box = Letterbox(2.0, 4.0, 10.0, 20.0)
    det = postprocess(raw, ULTRA, box, (100, 100), clip=False)
    np.testing.assert_allclose(det[0, :4], [(-100 - 10) / 2, (150 - 20) / 4, (300 - 10) / 2,
                                            (250 - 20) / 4])
    clipped = postprocess(raw, ULTRA, box, (100, 100))
    np.testing.assert_allclose(clipped[0, :4], [0, 32.5, 100, 57.5])


def test_yolox_decode_closed_form() -> None:
    raw = np.zeros((1, 3549, 85), np.float32)
    k = 2704 + 3 * 26 + 4  # stride-16 level, grid cell (x=4, y=3)
    raw[0, k, :4] = [0.5, 0.25, np.log(2.0), 0.0]
    raw[0, k, 4] = 0.8
    raw[0, k, 5 + 1] = 0.5  # bicycle
    det = postprocess(raw, YOLOX, Letterbox(0.5, 0.5, 0.0, 0.0), (832, 832))
    cx, cy, w, h = (4.5) * 16, (3.25) * 16, 32.0, 16.0
    expect = np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]) / 0.5
    np.testing.assert_allclose(det[0, :4], expect, atol=1e-3)
    assert det[0, 4] == pytest.approx(0.4) and det[0, 5] == 1
    assert len(det) == 1  # every other anchor scores 0 < conf 0.01


def test_e2e_decode_filters_and_keeps_model_order() -> None:
    raw = np.zeros((1, 300, 6), np.float32)
    raw[0, 0] = [10, 90, 110, 190, 0.7, 3]
    raw[0, 1] = [0, 80, 10, 90, 0.0005, 1]  # below conf 0.001
    raw[0, 2] = [20, 90, 30, 100, 0.8, 1]  # higher score later: the model's order is kept
    det = postprocess(raw, E2E, Letterbox(1.0, 1.0, 0.0, 80.0), (480, 640))
    np.testing.assert_allclose(det, [[10, 10, 110, 110, 0.7, 3], [20, 10, 30, 20, 0.8, 1]])


# --------------------------------------------------------------------------------------------
# Sessions, batches and the streaming loop (tiny synthetic ONNX models)


def tiny_model(path, batch, kind: str = "ultralytics") -> None:
    """A 64x64 'detector' whose outputs are input pixels (deterministic, image-dependent)."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    n_out = 84 * 84 if kind == "ultralytics" else 84 * 85
    shape_out = [batch, 84, 84] if kind == "ultralytics" else [batch, 84, 85]
    nodes = [
        helper.make_node("Reshape", ["images", "flat"], ["f"]),
        helper.make_node("Slice", ["f", "start", "stop", "axis"], ["s"]),
        helper.make_node("Reshape", ["s", "oshape"], ["output0"]),
    ]
    inits = [
        helper.make_tensor("flat", TensorProto.INT64, [2], [0, -1]),
        helper.make_tensor("start", TensorProto.INT64, [1], [0]),
        helper.make_tensor("stop", TensorProto.INT64, [1], [n_out]),
        helper.make_tensor("axis", TensorProto.INT64, [1], [1]),
        helper.make_tensor("oshape", TensorProto.INT64, [3], [0, *shape_out[1:]]),
    ]
    graph = helper.make_graph(
        nodes, "tiny", [helper.make_tensor_value_info("images", TensorProto.FLOAT,
                                                      [batch, 3, 64, 64])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, shape_out)], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))


@pytest.fixture()
def images():
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, (int(h), int(w), 3), dtype=np.uint8)
            for h, w in rng.integers(20, 120, (9, 2))]


@pytest.mark.parametrize("batch", [1, 4, "batch"])
def test_batched_inference_equals_one_by_one(tmp_path, images, batch) -> None:
    tiny_model(tmp_path / "m.onnx", batch)
    det = Detector(tmp_path / "m.onnx", threads=1, batch=3)
    assert det.layout.kind == "ultralytics"
    assert det.batch == (3 if batch == "batch" else batch)
    single = [det(im) for im in images]
    assert sum(len(d) for d in single) > 0
    prepared = [det.prepare(im) for im in images]
    outs = det.infer([p.tensor for p in prepared])
    for p, out, ref in zip(prepared, outs, single, strict=True):
        np.testing.assert_array_equal(det.finish(out, p), ref)
    streamed = list(det.detect_stream(range(len(images)), lambda i: images[i], prefetch=2))
    assert [k for k, _ in streamed] == list(range(len(images)))
    for (_, d), ref in zip(streamed, single, strict=True):
        np.testing.assert_array_equal(d, ref)


def test_detect_stream_errors_and_early_stop(tmp_path, images) -> None:
    tiny_model(tmp_path / "m.onnx", 1)
    det = Detector(tmp_path / "m.onnx", threads=1)

    def load(i: int) -> np.ndarray:
        if i == 4:
            raise InputFileError("image 4: cannot decode")
        return images[i]

    got = []
    with pytest.raises(InputFileError, match="image 4"):
        for k, _ in det.detect_stream(range(len(images)), load, workers=2):
            got.append(k)
    assert got == [0, 1, 2, 3]  # every image before the failing one, in order
    stream = det.detect_stream(range(len(images)), load)
    assert next(stream)[0] == 0
    stream.close()  # abandons queued work without error
    with pytest.raises(InvalidValueError):
        next(det.detect_stream([], load, prefetch=0))


def test_missing_model_file(tmp_path) -> None:
    with pytest.raises(InputFileError, match="does not exist"):
        Detector(tmp_path / "nope.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(InputFileError, match="cannot load"):
        Detector(bad)


# --------------------------------------------------------------------------------------------
# Shared models and images


def shared_sample(shared, n_upscaled: int, n_other: int):
    """Annotated images: the first ``n_upscaled`` smaller than 640 px and ``n_other`` others."""
    ann = json.loads((shared / "coco/annotations/instances_val2017_subset.json").read_text())
    imgs = sorted(ann["images"], key=lambda r: r["id"])
    up = [r for r in imgs if max(r["height"], r["width"]) < 640][:n_upscaled]
    other = [r for r in imgs if max(r["height"], r["width"]) >= 640][:n_other]
    return ann, up + other


@pytest.mark.shared
def test_shared_images_preprocess_equals_references(shared) -> None:
    """Every family's model input on real COCO images equals its reference's, bit for bit."""
    from fidelity.coco.jpeg import read_jpeg

    _, sample = shared_sample(shared, 30, 10)
    for rec in sample:
        rgb, _ = read_jpeg(shared / "coco/val2017" / rec["file_name"])
        x, box = preprocess(rgb, ULTRA)
        ref, ((gy, gx), (px, py)) = reference_ultralytics(rgb)
        np.testing.assert_array_equal(x[0], ref, err_msg=rec["file_name"])
        assert box == Letterbox(gx, gy, px, py)
        x, box = preprocess(rgb, YOLOX)
        ref, r = reference_yolox(rgb)
        np.testing.assert_array_equal(x[0], ref, err_msg=rec["file_name"])
        assert box == Letterbox(r, r, 0.0, 0.0)


@pytest.mark.shared
def test_shared_models_detections_equal_reference_preprocessing(shared) -> None:
    """Each shared model: detections from our pipeline equal those from the reference input."""
    from fidelity.coco.jpeg import read_jpeg

    _, sample = shared_sample(shared, 2, 1)
    rgbs = [read_jpeg(shared / "coco/val2017" / r["file_name"])[0] for r in sample]
    for f in sorted((shared / "models").glob("*.onnx")):
        det = Detector(f, threads=2)
        for rgb in rgbs:
            if det.layout.kind == "yolox":
                ref, r = reference_yolox(rgb)
                box = Letterbox(r, r, 0.0, 0.0)
            else:
                ref, ((gy, gx), (px, py)) = reference_ultralytics(rgb)
                box = Letterbox(gx, gy, px, py)
            out = det.session.run(None, {det.layout.input_name: ref[None]})[0]
            expect = postprocess(out, det.layout, box, rgb.shape[:2], det.conventions)
            np.testing.assert_array_equal(det(rgb), expect, err_msg=f.name)


@pytest.mark.shared
def test_shared_models_find_annotated_people(shared) -> None:
    """Every shared model: layout from the model, and it finds a ground-truth person."""
    ann = json.loads((shared / "coco/annotations/instances_val2017_subset.json").read_text())
    from fidelity.coco.jpeg import read_jpeg

    img = ann["images"][0]
    gts = [a["bbox"] for a in ann["annotations"]
           if a["image_id"] == img["id"] and a["category_id"] == 1 and not a["iscrowd"]]
    rgb, _ = read_jpeg(shared / "coco/val2017" / img["file_name"])
    kinds = {}
    for f in sorted((shared / "models").glob("*.onnx")):
        det = Detector(f, threads=2)
        kinds[f.stem] = det.layout.kind
        d = det(rgb)
        people = d[(d[:, 5] == 0) & (d[:, 4] > 0.3)]
        best = 0.0
        for x, y, w, h in gts:
            g = np.array([x, y, x + w, y + h])
            ix = np.clip(np.minimum(people[:, 2], g[2]) - np.maximum(people[:, 0], g[0]), 0, None)
            iy = np.clip(np.minimum(people[:, 3], g[3]) - np.maximum(people[:, 1], g[1]), 0, None)
            inter = ix * iy
            union = (people[:, 2] - people[:, 0]) * (people[:, 3] - people[:, 1]) + w * h - inter
            best = max(best, float(np.max(inter / union)) if len(people) else 0.0)
        assert best > 0.7, f"{f.name}: no person box matches ground truth (best IoU {best:.2f})"
        assert det.describe()["conventions"]["conf"] in (0.001, 0.01)
    assert kinds == {"yolo11n-int8dyn": "ultralytics", "yolov8n-int8dyn": "ultralytics",
                     "yolov10n-int8dyn": "ultralytics-e2e", "yolox_nano": "yolox"}


@pytest.mark.shared
def test_cuda_asked_for_is_never_a_silent_cpu_run(shared, monkeypatch) -> None:
    """--provider cuda where onnxruntime has no CUDA provider, or where the provider is offered
    but the session comes up on the CPU alone (onnxruntime's silent fallback: no GPU, missing
    cuDNN), is a clear error, not a CPU run labelled cuda."""
    import onnxruntime as ort

    from fidelity.coco.detectors import Detector

    model = shared / "models" / "yolox_nano.onnx"
    if "CUDAExecutionProvider" not in ort.get_available_providers():
        with pytest.raises(InvalidValueError, match="no CUDA execution provider"):
            Detector(model, provider="cuda")
    monkeypatch.setattr(ort, "get_available_providers",
                        lambda: ["CUDAExecutionProvider", "CPUExecutionProvider"])
    real = ort.InferenceSession

    class CpuOnly(real):  # type: ignore[misc, valid-type]
        def __init__(self, path, sess_options=None, providers=None):
            super().__init__(path, sess_options=sess_options, providers=["CPUExecutionProvider"])

    monkeypatch.setattr(ort, "InferenceSession", CpuOnly)
    with pytest.raises(InvalidValueError, match="could not start its CUDA provider"):
        Detector(model, provider="cuda")
    assert Detector(model, provider="cpu").session.get_providers() == ["CPUExecutionProvider"]


@pytest.mark.shared
# the float model's session asks for the CUDA provider this test only pretends to have
@pytest.mark.filterwarnings("ignore:Specified provider 'CUDAExecutionProvider':UserWarning")
def test_a_dynamically_quantised_model_runs_on_the_cpu_where_cuda_is_offered(shared,
                                                                             monkeypatch) -> None:
    """ConvInteger has no CUDA kernel in onnxruntime: a CUDA session runs those nodes on the
    CPU and its detections differ from a CPU session's (benchmarks/speed/providers.py on an
    H100). With CUDA offered, ``auto`` keeps such a model on the CPU and says why, and
    ``cuda`` is refused; a float model is not affected."""
    import onnxruntime as ort

    from fidelity.coco.detectors import Detector, integer_operators

    int8 = shared / "models" / "yolo11n-int8dyn.onnx"
    fp32 = shared / "models" / "yolox_nano.onnx"
    assert "ConvInteger" in integer_operators(int8)
    assert integer_operators(fp32) == frozenset()
    monkeypatch.setattr(ort, "get_available_providers",
                        lambda: ["CUDAExecutionProvider", "CPUExecutionProvider"])
    d = Detector(int8, provider="auto")
    assert d.providers == ["CPUExecutionProvider"]
    assert "ConvInteger" in d.describe()["provider_note"]
    with pytest.raises(InvalidValueError, match="dynamically quantised"):
        Detector(int8, provider="cuda")
    assert "provider_note" not in Detector(fp32, provider="auto").describe()
