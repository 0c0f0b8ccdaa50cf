"""Detector layouts, preprocessing, decoding and NMS against closed forms and brute force."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fidelity.coco.detectors import (
    COCO80_CATEGORY_IDS,
    COCO80_NAMES,
    Detector,
    Letterbox,
    nms,
    postprocess,
    preprocess,
    recognise_layout,
    resize_bilinear,
)
from fidelity.errors import InputFileError

IMG = [("images", [1, 3, 640, 640])]


def test_recognise_known_layouts() -> None:
    assert recognise_layout(IMG, [("output0", [1, 84, 8400])]).kind == "ultralytics"
    e2e = recognise_layout(IMG, [("output0", [1, 300, 6])], {"end2end": "True"})
    assert e2e.kind == "ultralytics-e2e"
    yx = recognise_layout([("images", [1, 3, 416, 416])], [("output", [1, 3549, 85])])
    assert yx.kind == "yolox" and yx.num_classes == 80 and yx.input_size == (416, 416)
    assert yx.names == COCO80_NAMES
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


def test_dynamic_and_multi_output_are_errors() -> None:
    with pytest.raises(InputFileError, match="dynamic"):
        recognise_layout([("images", ["batch", 3, 640, 640])], [("o", [1, 84, 8400])])
    with pytest.raises(InputFileError, match="one output"):
        recognise_layout(IMG, [("a", [1, 84, 8400]), ("b", [1, 84, 8400])])


def test_coco80_mapping_is_official() -> None:
    assert len(COCO80_CATEGORY_IDS) == 80 == len(set(COCO80_CATEGORY_IDS))
    assert COCO80_CATEGORY_IDS[COCO80_NAMES.index("bicycle")] == 2
    assert COCO80_CATEGORY_IDS[COCO80_NAMES.index("stop sign")] == 13
    assert COCO80_CATEGORY_IDS[-1] == 90


def test_resize_matches_scipy_half_pixel_bilinear() -> None:
    from scipy.ndimage import map_coordinates

    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    out = resize_bilinear(img, 23, 31)
    ys = np.clip((np.arange(23) + 0.5) * 37 / 23 - 0.5, 0, 36)
    xs = np.clip((np.arange(31) + 0.5) * 53 / 31 - 0.5, 0, 52)
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    for c in range(3):
        ref = map_coordinates(img[..., c].astype(float), [yy, xx], order=1)
        np.testing.assert_allclose(out[..., c], ref, atol=1e-3)


def brute_nms(boxes: np.ndarray, scores: np.ndarray, thr: float) -> list[int]:
    """Textbook greedy NMS, one pair at a time (independent of the vectorised version)."""
    order = sorted(range(len(scores)), key=lambda i: -scores[i])
    keep: list[int] = []
    for i in order:
        ok = True
        for k in keep:
            ix = max(0.0, min(boxes[i, 2], boxes[k, 2]) - max(boxes[i, 0], boxes[k, 0]))
            iy = max(0.0, min(boxes[i, 3], boxes[k, 3]) - max(boxes[i, 1], boxes[k, 1]))
            inter = ix * iy
            a = (boxes[i, 2] - boxes[i, 0]) * (boxes[i, 3] - boxes[i, 1])
            b = (boxes[k, 2] - boxes[k, 0]) * (boxes[k, 3] - boxes[k, 1])
            if inter / (a + b - inter) > thr:
                ok = False
                break
        if ok:
            keep.append(i)
    return keep


def test_nms_equals_brute_force() -> None:
    rng = np.random.default_rng(7)
    xy = rng.uniform(0, 100, (300, 2))
    wh = rng.uniform(5, 40, (300, 2))
    boxes = np.concatenate([xy, xy + wh], 1).astype(np.float32)
    scores = rng.uniform(0, 1, 300).astype(np.float32)
    assert nms(boxes, scores, 0.5).tolist() == brute_nms(boxes, scores, 0.5)
    assert nms(boxes, scores, 0.5, max_keep=10).tolist() == brute_nms(boxes, scores, 0.5)[:10]


def test_letterbox_geometry_ultralytics() -> None:
    lay = recognise_layout(IMG, [("output0", [1, 84, 8400])])
    img = np.full((480, 640, 3), 200, np.uint8)
    x, box = preprocess(img, lay)
    assert x.shape == (1, 3, 640, 640) and x.dtype == np.float32
    assert box == Letterbox(1.0, 0.0, 80.0)
    np.testing.assert_allclose(x[0, :, 0, 0], 114 / 255, rtol=1e-6)  # pad
    np.testing.assert_allclose(x[0, :, 320, 320], 200 / 255, rtol=1e-6)
    assert np.all(x[0, :, 79, :] == np.float32(114 / 255)) and np.all(x[0, :, 560, :] < 0.5)


def test_yolox_preprocess_is_bgr_top_left() -> None:
    lay = recognise_layout([("images", [1, 3, 416, 416])], [("output", [1, 3549, 85])])
    img = np.zeros((200, 400, 3), np.uint8)
    img[..., 0] = 250  # red
    x, box = preprocess(img, lay)
    assert box.gain == pytest.approx(416 / 400) and box.pad_x == 0 and box.pad_y == 0
    assert x[0, 2, 10, 10] == 250 and x[0, 0, 10, 10] == 0  # R is channel 2 (BGR), 0-255
    assert x[0, 0, 300, 10] == 114  # padding below the image


def test_ultralytics_decode_maps_back_to_image() -> None:
    lay = recognise_layout(IMG, [("output0", [1, 84, 8400])])
    raw = np.zeros((1, 84, 8400), np.float32)
    raw[0, :4, 5] = [320, 330, 100, 60]  # cx, cy, w, h in letterboxed pixels
    raw[0, 4 + 2, 5] = 0.9  # car
    raw[0, :4, 6] = [321, 331, 100, 60]  # duplicate, lower score: suppressed
    raw[0, 4 + 2, 6] = 0.8
    raw[0, 4 + 0, 6] = 0.5  # ... but its person score survives (multi-label, per class NMS)
    det = postprocess(raw, lay, Letterbox(1.0, 0.0, 80.0), (480, 640))
    assert det.shape == (2, 6)
    np.testing.assert_allclose(det[0], [270, 220, 370, 280, 0.9, 2], atol=1e-4)
    assert det[1, 5] == 0 and det[1, 4] == pytest.approx(0.5)


def test_yolox_decode_closed_form() -> None:
    lay = recognise_layout([("images", [1, 3, 416, 416])], [("output", [1, 3549, 85])])
    raw = np.zeros((1, 3549, 85), np.float32)
    k = 2704 + 3 * 26 + 4  # stride-16 level, grid cell (x=4, y=3)
    raw[0, k, :4] = [0.5, 0.25, np.log(2.0), 0.0]
    raw[0, k, 4] = 0.8
    raw[0, k, 5 + 1] = 0.5  # bicycle
    det = postprocess(raw, lay, Letterbox(0.5, 0.0, 0.0), (832, 832))
    cx, cy, w, h = (4.5) * 16, (3.25) * 16, 32.0, 16.0
    expect = np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]) / 0.5
    np.testing.assert_allclose(det[0, :4], expect, atol=1e-3)
    assert det[0, 4] == pytest.approx(0.4) and det[0, 5] == 1
    assert len(det) == 1  # every other anchor scores 0 < conf 0.01


def test_e2e_decode_filters_and_caps() -> None:
    lay = recognise_layout(IMG, [("output0", [1, 300, 6])], {"end2end": "True"})
    raw = np.zeros((1, 300, 6), np.float32)
    raw[0, 0] = [10, 90, 110, 190, 0.7, 3]
    raw[0, 1] = [0, 80, 10, 90, 0.0005, 1]  # below conf 0.001
    det = postprocess(raw, lay, Letterbox(1.0, 0.0, 80.0), (480, 640))
    np.testing.assert_allclose(det, [[10, 10, 110, 110, 0.7, 3]])


def test_missing_model_file(tmp_path) -> None:
    with pytest.raises(InputFileError, match="does not exist"):
        Detector(tmp_path / "nope.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(InputFileError, match="cannot load"):
        Detector(bad)


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
