"""The re-weighted COCO accumulation (fidelity.coco.bootstrap) against pycocotools itself: all
weights 1 give COCO's mAP; a bootstrap draw gives the mAP of the drawn images re-evaluated."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fidelity.coco.bootstrap import bootstrap_weights, match_records, weighted_scores
from fidelity.coco.scoring import coco_from_dict, evaluate_detections
from fidelity.core.errors import InvalidValueError

CATS = [{"id": 1, "name": "person"}, {"id": 2, "name": "bicycle"}, {"id": 3, "name": "car"},
        {"id": 4, "name": "motorcycle"}]


def synthetic(n_images: int = 40, seed: int = 7, digits: int = 6
              ) -> tuple[dict[str, Any], dict[int, np.ndarray]]:
    """Ground truth (with crowd boxes, empty images, a class with no detections and one with
    no ground truth) and detections (jittered true boxes, duplicates, false positives; scores
    rounded to ``digits``: 2 makes ties across images), in the stored (K, 6) x1 y1 x2 y2 score class-index form (class index = id - 1
    for these four categories, as the 80-class mapping of COCO's first four)."""
    rng = np.random.default_rng(seed)
    images, anns, dets = [], [], {}
    for i in range(1, n_images + 1):
        images.append({"id": i, "width": 640, "height": 480, "file_name": f"{i}.jpg"})
        rows = []
        for _ in range(int(rng.integers(0, 6)) if i % 9 else 0):
            cat = int(rng.choice([1, 1, 2, 3]))  # no ground truth of category 4
            x, y = rng.uniform(0, 500), rng.uniform(0, 350)
            w, h = rng.uniform(8, 140), rng.uniform(8, 130)
            crowd = int(rng.random() < 0.08)
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": cat,
                         "bbox": [x, y, w, h], "area": w * h, "iscrowd": crowd})
            if cat == 3 or rng.random() < 0.2:  # car is never detected; some misses
                continue
            for _ in range(1 + int(rng.random() < 0.25)):  # sometimes a duplicate
                j = rng.normal(0, 0.12 * min(w, h), 4)
                rows.append([x + j[0], y + j[1], x + w + j[2], y + h + j[3],
                             round(float(rng.uniform(0.05, 1.0)), digits), cat - 1])
        for _ in range(int(rng.integers(0, 4))):  # false positives, some of category 4
            x, y = rng.uniform(0, 560), rng.uniform(0, 400)
            rows.append([x, y, x + rng.uniform(5, 80), y + rng.uniform(5, 80),
                         round(float(rng.uniform(0.01, 0.9)), digits), int(rng.choice([0, 1, 3]))])
        dets[i] = np.asarray(rows, dtype=np.float32).reshape(-1, 6)
    return {"images": images, "annotations": anns, "categories": CATS}, dets


def _duplicated(data: dict[str, Any], dets: dict[int, np.ndarray], draw: np.ndarray
                ) -> tuple[Any, dict[int, np.ndarray]]:
    """The drawn images as a data set of their own (an image drawn twice is two images)."""
    images, anns, out = [], [], {}
    by_image: dict[int, list[dict[str, Any]]] = {}
    for a in data["annotations"]:
        by_image.setdefault(a["image_id"], []).append(a)
    for j, src in enumerate(draw, start=1):
        images.append({"id": j, "width": 640, "height": 480, "file_name": f"{j}.jpg"})
        for a in by_image.get(int(src), []):
            anns.append(a | {"id": len(anns) + 1, "image_id": j})
        out[j] = dets[int(src)]
    return coco_from_dict({"images": images, "annotations": anns, "categories": CATS}), out


def test_all_weights_one_is_cocos_own_map_and_class_ap() -> None:
    data, dets = synthetic()
    gt = coco_from_dict(data)
    ids = sorted(dets)
    ref = evaluate_detections(gt, dets, ids, method="pycocotools")
    got = weighted_scores(match_records(gt, dets, ids), np.ones((1, len(ids))))
    assert got["map"][0] == pytest.approx(ref.map, abs=1e-12)
    assert got["person"][0] == pytest.approx(ref.ap["person"], abs=1e-12)
    assert got["bicycle"][0] == pytest.approx(ref.ap["bicycle"], abs=1e-12)


@pytest.mark.parametrize(("seed", "digits", "tol"), [(1, 6, 1e-9), (2, 6, 1e-9), (3, 6, 1e-9),
                                                     (1, 2, 3e-3), (2, 2, 3e-3)])
def test_a_draw_scores_as_the_drawn_images_re_evaluated(seed: int, digits: int,
                                                        tol: float) -> None:
    """Exact without tied scores; with ties across images the order within a tie differs (a
    re-evaluation puts the copies of an image apart, weights keep them in one place), which
    moves a precision point inside the tie, hence the AP a little."""
    data, dets = synthetic(seed=seed + 10, digits=digits)
    gt = coco_from_dict(data)
    ids = sorted(dets)
    rng = np.random.default_rng(seed)
    draw = np.asarray(ids)[rng.integers(0, len(ids), len(ids))]
    w = np.zeros((1, len(ids)))
    np.add.at(w[0], np.searchsorted(ids, draw), 1.0)
    g2, d2 = _duplicated(data, dets, draw)
    ref = evaluate_detections(g2, d2, sorted(d2), method="pycocotools")
    got = weighted_scores(match_records(gt, dets, ids), w)
    assert got["map"][0] == pytest.approx(ref.map, abs=tol)
    assert got["person"][0] == pytest.approx(ref.ap["person"], abs=tol)


def test_hard_cases_zero_weights_and_missing_classes() -> None:
    data, dets = synthetic(n_images=12, seed=3)
    gt = coco_from_dict(data)
    ids = sorted(dets)
    rec = match_records(gt, dets, ids)
    assert rec.index("car") is not None  # ground truth, never detected: AP 0, counted
    out = weighted_scores(rec, np.ones((1, len(ids))), classes=("car", "motorcycle", "train"))
    assert out["car"][0] == 0.0
    assert np.isnan(out["motorcycle"][0])  # detections but no ground truth: left out
    assert np.isnan(out["train"][0])  # not among the categories at all
    none = weighted_scores(rec, np.zeros((2, len(ids))))
    assert np.all(np.isnan(none["map"]))  # no image drawn: no ground truth, no mAP
    # only images without ground truth of a class drawn: that class is NaN, mAP still defined
    person = rec.categories[rec.index("person")]  # type: ignore[index]
    w = (person.gt == 0).astype(float)[None, :]
    if w.sum() and np.any(rec.categories[rec.index("bicycle")].gt * w[0]):  # type: ignore[index]
        assert np.isnan(weighted_scores(rec, w)["person"][0])
    tiny = weighted_scores(rec, np.full((1, len(ids)), 1e-300))  # denormal-scale weights
    assert tiny["map"][0] == pytest.approx(out["map"][0], abs=1e-12)
    with pytest.raises(InvalidValueError):
        weighted_scores(rec, np.ones((1, len(ids) + 1)))
    with pytest.raises(InvalidValueError):
        weighted_scores(rec, -np.ones((1, len(ids))))
    with pytest.raises(InvalidValueError):
        match_records(gt, dets, [])


def test_bootstrap_weights_are_draws_with_replacement_and_reproducible() -> None:
    w = bootstrap_weights(50, resamples=30, seed=5)
    assert w.shape == (30, 50) and np.all(w.sum(axis=1) == 50)
    assert np.array_equal(w, bootstrap_weights(50, resamples=30, seed=5))
    assert not np.array_equal(w, bootstrap_weights(50, resamples=30, seed=6))
    rng = np.random.default_rng(5)
    first = np.bincount(rng.integers(0, 50, 50), minlength=50)
    assert np.array_equal(w[0], first)


@pytest.mark.parametrize("digits", [6, 2])
def test_counting_accumulation_equals_the_whole_one_bit_for_bit(digits: int) -> None:
    """Whole-number weights take the accumulation at the true positives only; it gives the
    very numbers of the accumulation over every detection (the path of fractional weights),
    draw by draw, category by category (crowd-ignored detections, ties, zero weights)."""
    from fidelity.coco.bootstrap import _category_ap, _category_ap_counts

    data, dets = synthetic(n_images=60, seed=11, digits=digits)
    ids = sorted(dets)
    rec = match_records(coco_from_dict(data), dets, ids)
    w = np.vstack([np.ones((1, len(ids))), np.zeros((1, len(ids))),
                   bootstrap_weights(len(ids), resamples=64, seed=2)])
    assert any(np.any(~(c.tp | c.fp)) for c in rec.categories)  # ignored detections present
    for c in rec.categories:
        np.testing.assert_array_equal(_category_ap_counts(c, w), _category_ap(c, w))
    # fractional weights take the whole accumulation
    half = weighted_scores(rec, w[2:] + 0.5)
    assert np.all(np.isfinite(half["map"]))
