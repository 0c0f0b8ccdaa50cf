"""COCO AP against hand-computed values (101-point interpolated AP, IoU thresholds .50:.95).

The hand-computed cases run with both scorers; faster-coco-eval is checked against pycocotools
(the reference) to 1e-4 on the shared COCO annotations, with synthetic and real detections.
"""

from __future__ import annotations

import numpy as np
import pytest

from fidelity.coco.detectors import COCO80_CATEGORY_IDS, COCO80_NAMES
from fidelity.coco.loss import paired_standard_error
from fidelity.coco.scoring import (
    COCO_SCORERS,
    coco_from_dict,
    detections_to_coco,
    evaluate_detections,
    load_annotations,
)
from fidelity.core.errors import InputFileError, InvalidValueError


def _gt(boxes: dict[int, list[tuple[int, list[float]]]]) -> object:
    cats = [{"id": c, "name": n} for c, n in zip(COCO80_CATEGORY_IDS, COCO80_NAMES, strict=True)]
    images, anns = [], []
    for img_id, items in boxes.items():
        images.append({"id": img_id, "width": 200, "height": 200, "file_name": f"{img_id}.jpg"})
        for cat, (x, y, w, h) in items:
            anns.append({"id": len(anns) + 1, "image_id": img_id, "category_id": cat,
                         "bbox": [x, y, w, h], "area": w * h, "iscrowd": 0})
    return coco_from_dict({"images": images, "annotations": anns, "categories": cats})


METHODS = list(COCO_SCORERS)


def det(x: float, y: float, w: float, h: float, s: float, cls: int) -> list[float]:
    return [x, y, x + w, y + h, s, cls]


@pytest.mark.parametrize("method", METHODS)
def test_perfect_detection_is_ap_one(method: str) -> None:
    gt = _gt({1: [(1, [10, 10, 50, 80])]})
    score = evaluate_detections(gt, {1: np.array([det(10, 10, 50, 80, 0.9, 0)])}, method=method)
    assert score.map == pytest.approx(1.0) and score.ap["person"] == pytest.approx(1.0)
    assert score.ap["bicycle"] is None  # no ground truth: not a number


@pytest.mark.parametrize("method", METHODS)
def test_false_positive_ranked_first_halves_ap(method: str) -> None:
    # FP (score 0.95) then TP (0.9): precision 1/2 at recall 1 -> 101-point AP = 0.5
    gt = _gt({1: [(1, [10, 10, 50, 80])]})
    d = np.array([det(120, 120, 40, 40, 0.95, 0), det(10, 10, 50, 80, 0.9, 0)])
    assert evaluate_detections(gt, {1: d}, method=method).map == pytest.approx(0.5)
    # TP ranked first: the FP after it does not lower the interpolated precision -> 1.0
    d2 = np.array([det(120, 120, 40, 40, 0.5, 0), det(10, 10, 50, 80, 0.9, 0)])
    assert evaluate_detections(gt, {1: d2}, method=method).map == pytest.approx(1.0)


@pytest.mark.parametrize("method", METHODS)
def test_iou_thresholds_count(method: str) -> None:
    # Box shifted by 10 px in x on a 100x100 GT: IoU = 90*100 / (110*100) = 0.818
    # -> true positive at thresholds .50 ... .80 (7 of 10) -> AP = 0.7, AP50 = 1
    gt = _gt({1: [(3, [0, 0, 100, 100])]})
    score = evaluate_detections(gt, {1: np.array([det(10, 0, 100, 100, 0.8, 2)])}, method=method)
    assert score.map == pytest.approx(0.7)
    assert score.map50 == pytest.approx(1.0)
    assert score.ap["car"] == pytest.approx(0.7)


@pytest.mark.parametrize("method", METHODS)
def test_missed_image_counts_and_mean_over_classes(method: str) -> None:
    gt = _gt({1: [(1, [10, 10, 50, 80])], 2: [(2, [0, 0, 60, 60])]})
    # person found; bicycle image gets no detections -> AP person 1, bicycle 0, mean 0.5
    score = evaluate_detections(gt, {1: np.array([det(10, 10, 50, 80, 0.9, 0)])}, [1, 2], method=method)
    assert score.ap["person"] == pytest.approx(1.0) and score.ap["bicycle"] == pytest.approx(0.0)
    assert score.map == pytest.approx(0.5) and score.images == 2


@pytest.mark.parametrize("method", METHODS)
def test_no_detections_at_all(method: str) -> None:
    gt = _gt({1: [(1, [10, 10, 50, 80])]})
    assert evaluate_detections(gt, {}, [1], method=method).map == 0.0


def test_bad_inputs(tmp_path) -> None:
    gt = _gt({1: [(1, [10, 10, 50, 80])]})
    with pytest.raises(InvalidValueError, match="not in the annotations"):
        evaluate_detections(gt, {7: np.zeros((0, 6))})
    with pytest.raises(InvalidValueError, match="no images"):
        evaluate_detections(gt, {})
    with pytest.raises(InputFileError, match="does not exist"):
        load_annotations(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"images": []}')
    with pytest.raises(InputFileError, match="annotations"):
        load_annotations(bad)


def test_detection_json_uses_xywh_and_category_ids() -> None:
    out = detections_to_coco(5, np.array([det(1, 2, 3, 4, 0.5, 1)]))
    assert out == [{"image_id": 5, "category_id": 2, "bbox": [1.0, 2.0, 3.0, 4.0], "score": 0.5}]


@pytest.mark.shared
def test_shared_ground_truth_scores_one(shared) -> None:
    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())[:200]
    cats = sorted(coco.getCatIds())
    dets = {}
    for i in ids:
        rows = [[x, y, x + w, y + h, 1.0, cats.index(a["category_id"])]
                for a in coco.imgToAnns[i] if not a["iscrowd"]
                for x, y, w, h in [a["bbox"]]]
        dets[i] = np.array(rows, dtype=np.float64).reshape(-1, 6)
    score = evaluate_detections(coco, dets, ids)
    assert score.map == pytest.approx(1.0, abs=1e-3)
    assert score.ap["person"] == pytest.approx(1.0, abs=1e-3)


def test_load_annotated_images_names_what_is_missing(tmp_path) -> None:
    import json as _json

    from fidelity.coco.scoring import load_annotated_images
    from fidelity.core.errors import InputFileError

    doc = {"images": [{"id": 2, "file_name": "b.jpg", "width": 4, "height": 4},
                      {"id": 1, "file_name": "a.jpg", "width": 4, "height": 4}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 2, 2],
                            "area": 4, "iscrowd": 0}],
           "categories": [{"id": 1, "name": "person"}]}
    ann = tmp_path / "ann.json"
    ann.write_text(_json.dumps(doc))
    folder = tmp_path / "img"
    with pytest.raises(InputFileError, match="image folder does not exist"):
        load_annotated_images(folder, ann)
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"")
    with pytest.raises(InputFileError, match="1 annotated images missing, e.g. b.jpg"):
        load_annotated_images(folder, ann)
    (folder / "b.jpg").write_bytes(b"")
    img_dir, coco, ids = load_annotated_images(folder, ann)
    assert img_dir == folder and ids == [1, 2] and coco.imgs[2]["file_name"] == "b.jpg"


def _assert_scores_agree(a, b, tol: float = 1e-4) -> None:
    assert len(a.stats) == len(b.stats) == 12
    np.testing.assert_allclose(b.stats, a.stats, rtol=0, atol=tol)
    assert a.ap.keys() == b.ap.keys()
    for name, ap in a.ap.items():
        if ap is None:
            assert b.ap[name] is None, name
        else:
            assert b.ap[name] == pytest.approx(ap, abs=tol), name


@pytest.mark.shared
def test_faster_coco_eval_agrees_with_pycocotools_on_shared_annotations(shared) -> None:
    """All 12 COCO stats and every class AP within 1e-4 on the 1000 shared images.

    Detections are the ground truth made imperfect the way detectors are: boxes jittered by up
    to 20 % of their size, 15 % dropped, random scores, wrong-class duplicates and random false
    positives (so every IoU threshold, area range, crowd region and maxDets cut is exercised).
    """
    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())
    cats = sorted(coco.getCatIds())
    rng = np.random.default_rng(7)
    dets = {}
    for i in ids:
        rows = []
        img = coco.imgs[i]
        for a in coco.imgToAnns[i]:
            if rng.random() < 0.15:
                continue
            x, y, w, h = a["bbox"]
            jx, jy, jw, jh = rng.uniform(-0.2, 0.2, 4)
            bx, by, bw, bh = x + jx * w, y + jy * h, w * (1 + jw), h * (1 + jh)
            k = cats.index(a["category_id"])
            rows.append([bx, by, bx + bw, by + bh, rng.uniform(0.05, 1.0), k])
            if rng.random() < 0.2:
                rows.append([bx, by, bx + bw, by + bh, rng.uniform(0.0, 0.5),
                             rng.integers(len(cats))])
        for _ in range(rng.integers(0, 8)):
            x1, y1 = rng.uniform(0, img["width"] - 10), rng.uniform(0, img["height"] - 10)
            rows.append([x1, y1, x1 + rng.uniform(5, 200), y1 + rng.uniform(5, 200),
                         rng.uniform(0.0, 0.6), rng.integers(len(cats))])
        dets[i] = np.array(rows, dtype=np.float64).reshape(-1, 6)
    ref = evaluate_detections(coco, dets, ids, method="pycocotools")
    fast = evaluate_detections(coco, dets, ids, method="faster-coco-eval")
    assert 0.1 < ref.map < 0.9  # imperfect enough that the curves are not trivial
    _assert_scores_agree(ref, fast)
    # a subset of images (as the sweep scores the first N by id) agrees as well
    sub = ids[:100]
    _assert_scores_agree(evaluate_detections(coco, dets, sub, method="pycocotools"),
                         evaluate_detections(coco, dets, sub, method="faster-coco-eval"))


@pytest.mark.shared
def test_faster_coco_eval_agrees_on_real_detector_output(shared) -> None:
    """YOLOX-nano on 40 shared images: both scorers give the same numbers to 1e-4."""
    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import read_jpeg

    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())[:40]
    detector = Detector(shared / "models/yolox_nano.onnx", threads=1, provider="cpu")
    dets = {i: detector(read_jpeg(shared / "coco/val2017" / coco.imgs[i]["file_name"])[0])
            for i in ids}
    _assert_scores_agree(evaluate_detections(coco, dets, ids, method="pycocotools"),
                         evaluate_detections(coco, dets, ids, method="faster-coco-eval"))


def test_scorer_names() -> None:
    from fidelity.coco.scoring import resolve_scorer
    from fidelity.core.errors import UnknownNameError

    assert resolve_scorer("auto") in COCO_SCORERS
    assert resolve_scorer("pycocotools") == "pycocotools"
    with pytest.raises(UnknownNameError, match="^cocoapi: unknown COCO scorer; known: "):
        resolve_scorer("cocoapi")


def test_paired_standard_errors_in_points_and_relative_by_hand() -> None:
    # three folds, each losing half its baseline: relative losses 50, 50, 50 % (no spread);
    # in points 25, 20, 30 (sd 5, SE 5/sqrt 3). A fold without a value is left out.
    base, other = [0.5, 0.4, 0.6, None], [0.25, 0.2, 0.3, 0.1]
    assert paired_standard_error(base, other) == pytest.approx(5 / np.sqrt(3))
    assert paired_standard_error(base, other, relative=True) == pytest.approx(0.0, abs=1e-12)
    # relative losses 50 and 25 %: sd 25/sqrt 2, SE 12.5; a zero baseline fold is left out
    assert paired_standard_error([0.4, 0.4, 0.0], [0.2, 0.3, 0.0], relative=True) == \
        pytest.approx(12.5)
    assert paired_standard_error([0.4], [0.2]) is None


# --------------------------------------------------------------------------------------------
# Ultralytics' own AP against hand-computed values


def _gt_crowd(items: list[tuple[int, list[float], int]]) -> object:
    cats = [{"id": c, "name": n} for c, n in zip(COCO80_CATEGORY_IDS, COCO80_NAMES, strict=True)]
    anns = [{"id": k + 1, "image_id": 1, "category_id": c, "bbox": b, "area": b[2] * b[3],
             "iscrowd": crowd} for k, (c, b, crowd) in enumerate(items)]
    return coco_from_dict({"images": [{"id": 1, "width": 200, "height": 200,
                                       "file_name": "1.jpg"}],
                           "annotations": anns, "categories": cats})


@pytest.mark.parametrize("version", ["8.4", "8.3"])
def test_ultralytics_perfect_detection_is_0995(version: str) -> None:
    """One TP: precision 1 up to recall 1 and 0 at recall 1 itself -> trapezoid 0.995."""
    from fidelity.coco.scoring import ultralytics_ap

    gt = _gt({1: [(1, [10, 10, 50, 80])]})
    s = ultralytics_ap(gt, {1: np.array([det(10, 10, 50, 80, 0.9, 0)])}, version=version)
    assert s.map == pytest.approx(0.995) and s.map50 == pytest.approx(0.995)
    assert s.ap["person"] == pytest.approx(0.995) and s.ap["bicycle"] is None
    assert s.targets == 1 and s.detections == 1


def test_ultralytics_ap_by_hand_both_versions() -> None:
    """2 GT; TP (0.9), FP (0.8), TP at IoU 0.62 only (0.7); values worked out by hand.

    IoU < 0.62 thresholds (.50 .55 .60): recall .5 .5 1, precision 1 .5 2/3; envelope 1 up to
    recall .5, 2/3 up to 1, 0 at 1: AP = 0.01 (50 + 50 * 2/3 - 1/2) = 0.828333 (both versions).
    Thresholds .65 ... .95: recall .5 .5 .5, precision 1 .5 1/3: 8.4 drops to 0 after recall
    .5: AP = 0.01 (50 - 1/2) = 0.495; 8.3 falls linearly from 1/3 at recall .5 to 0 at 1:
    AP = 0.49 + 0.01 (1 + 1/3) / 2 + 0.5 * 0.5 / 3 = 0.58.
    """
    from fidelity.coco.scoring import ultralytics_ap

    gt = _gt({1: [(1, [10, 10, 50, 80]), (1, [100, 100, 40, 50])]})
    d = np.array([det(10, 10, 50, 80, 0.9, 0), det(150, 10, 40, 30, 0.8, 0),
                  det(100, 100, 40, 31, 0.7, 0)])
    low, high = 0.01 * (50 + 50 * 2 / 3 - 0.5), 0.495
    s = ultralytics_ap(gt, {1: d}, version="8.4")
    assert s.map50 == pytest.approx(low) and s.map75 == pytest.approx(high)
    assert s.map == pytest.approx((3 * low + 7 * high) / 10)
    old = ultralytics_ap(gt, {1: d}, version="8.3")
    assert old.map50 == pytest.approx(low) and old.map75 == pytest.approx(0.58)
    assert old.map == pytest.approx((3 * low + 7 * 0.58) / 10)


def test_ultralytics_crowd_boxes_are_false_positives() -> None:
    """A detection on a crowd box: COCO ignores it (AP 1), Ultralytics counts it as FP.

    Recall 0, 1 with precision 0, 1/2: envelope 1/2 from recall 0 up to 1, 0 at 1:
    AP = 0.01 (100 * 1/2 - 1/4) = 0.4975 at every threshold.
    """
    from fidelity.coco.scoring import ultralytics_ap

    gt = _gt_crowd([(1, [10, 10, 50, 80], 0), (1, [100, 100, 60, 60], 1)])
    d = {1: np.array([det(100, 100, 60, 60, 0.95, 0), det(10, 10, 50, 80, 0.9, 0)])}
    assert ultralytics_ap(gt, d).map == pytest.approx(0.4975)
    assert ultralytics_ap(gt, d).targets == 1
    assert evaluate_detections(gt, d, method="pycocotools").map == pytest.approx(1.0)


def test_ultralytics_versions_clip_differently() -> None:
    """A box partly outside the image: IoU 5/9 as predicted (8.4: TP at .50 and .55 only),
    1 once clipped (8.3)."""
    from fidelity.coco.scoring import ultralytics_ap

    gt = _gt({1: [(1, [0, 0, 50, 50])]})
    d = {1: np.array([[-40, 0, 50, 50, 0.9, 0]], np.float64)}
    assert ultralytics_ap(gt, d, version="8.4").map == pytest.approx(0.2 * 0.995)
    assert ultralytics_ap(gt, d, version="8.3").map == pytest.approx(0.995)


def test_ultralytics_matching_rules() -> None:
    """d1 (first) overlaps g1 at .6; d2 overlaps g1 at .9 and g2 at .7 (IoU matrix by hand).

    8.4 walks the detections by confidence: d1 takes g1, d2 falls back to g2 (2 TP at .5).
    8.3 keeps each detection's best target only (both g1), then g1's first detection: 1 TP.
    """
    from fidelity.coco.scoring import match_by_confidence, match_by_iou

    iou = np.array([[0.6, 0.9], [0.0, 0.7]])
    new, old = match_by_confidence(iou), match_by_iou(iou)
    assert new[:, 0].tolist() == [True, True] and old[:, 0].tolist() == [True, False]
    # at .65 d1 misses; both rules give d2 the better target g1
    assert new[:, 3].tolist() == [False, True] and old[:, 3].tolist() == [False, True]
    assert not new[:, 9].any() and not old[:, 9].any()  # nothing reaches .95


def test_ultralytics_mean_over_classes_with_targets() -> None:
    """A class with targets and no detection counts 0; a class without targets is left out."""
    from fidelity.coco.scoring import ultralytics_ap

    gt = _gt({1: [(1, [10, 10, 50, 80])], 2: [(2, [0, 0, 60, 60])]})
    d = {1: np.array([det(10, 10, 50, 80, 0.9, 0), det(100, 100, 20, 20, 0.5, 5)])}
    s = ultralytics_ap(gt, d, [1, 2])
    assert s.ap["person"] == pytest.approx(0.995) and s.ap["bicycle"] == 0.0
    assert s.ap["bus"] is None and s.map == pytest.approx(0.995 / 2)
    with pytest.raises(InvalidValueError, match="no images"):
        ultralytics_ap(gt, {})


@pytest.mark.shared
def test_ultralytics_ap_of_ground_truth_is_0995(shared) -> None:
    """The shared ground truth as detections: every non-crowd box found, AP 0.995 per class
    (Ultralytics' trapezoid drops to 0 at recall 1), whatever the crowd boxes."""
    from fidelity.coco.scoring import ultralytics_ap

    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())[:200]
    cats = sorted(coco.getCatIds())
    dets = {}
    for i in ids:
        rows = [[x, y, x + w, y + h, 1.0, cats.index(a["category_id"])]
                for a in coco.imgToAnns[i] if not a["iscrowd"] and a["bbox"][2] > 0
                and a["bbox"][3] > 0 for x, y, w, h in [a["bbox"]]]
        dets[i] = np.array(rows, dtype=np.float64).reshape(-1, 6)
    for version in ("8.4", "8.3"):
        s = ultralytics_ap(coco, dets, ids, version=version)
        assert s.map == pytest.approx(0.995, abs=1e-9), version
        assert s.targets == sum(len(d) for d in dets.values())
