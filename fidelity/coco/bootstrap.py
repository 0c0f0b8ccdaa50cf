"""Paired image bootstrap of pooled COCO scores, from one evaluation per run.

A loss is a difference of mAPs *pooled* over all images, so its standard error is that of a
difference of two pooled statistics of the same images. The image bootstrap draws the images
with replacement, scores both runs on each draw and takes the spread of the differences
(Efron & Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 6; paired: both runs see
the same draw). Re-running COCO evaluation on every draw costs minutes a cell; this module
evaluates each run once and re-weights:

COCO matching (``pycocotools.cocoeval.COCOeval.evaluateImg``) is done per image and category,
independently of every other image, so a draw that holds an image ``w`` times holds its matches
``w`` times. :func:`match_records` keeps, per category, every scored detection's score, image
and true/false-positive flag per IoU threshold, and each image's count of non-ignored ground
truth; :func:`weighted_scores` then runs COCO's accumulation (``COCOeval.accumulate``: sort by
score, cumulative true/false positives, precision envelope, 101 recall points, mean over IoU
thresholds, recall points and the categories with ground truth) with each detection and ground
truth counted ``w`` times, for many draws at once (for whole-number weights, as a draw's
image counts are, at the true positives only: :func:`_category_ap_counts`, the same numbers
for a tenth of the work). With every weight 1 it is COCO's mAP
(tested to 1e-12 against pycocotools); on a draw it equals re-scoring the drawn images
(tested against re-evaluation of duplicated images).

Scope: box AP, area "all", at most 100 detections per image and category (COCO's defaults for
mAP@[.50:.95], the number the tables use).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fidelity.coco.scoring import coco_results, evaluated_pycocotools
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

__all__ = ["BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "CategoryMatches", "Draws", "MatchRecords",
           "bootstrap_weights", "draw_scores", "match_records", "weighted_scores"]

#: Draws of the bootstrap (the standard error's own relative error is about 1/sqrt(2 B): 5 %).
BOOTSTRAP_RESAMPLES = 200
#: Seed of the draws (numpy ``default_rng``), so a standard error is reproducible.
BOOTSTRAP_SEED = 20261127
#: COCO's recall points of AP (``COCOeval.params.recThrs``).
_RECALL = np.linspace(0.0, 1.00, 101)
#: COCO's IoU thresholds of AP@[.50:.95].
_IOU = np.linspace(0.5, 0.95, 10)


@record
class CategoryMatches:
    """One category's matches over a run, in COCO's order (score descending, stable).

    Shapes: ``image`` (N,) index into the run's images; ``tp``, ``fp`` (T, N) bool per IoU
    threshold (an ignored detection is neither); ``gt`` (I,) non-ignored ground-truth boxes
    per image.
    """

    name: str
    image: np.ndarray
    tp: np.ndarray
    fp: np.ndarray
    gt: np.ndarray


@record
class MatchRecords:
    """Per-category matches of one run over ``image_ids`` (:func:`match_records`)."""

    image_ids: tuple[int, ...]
    categories: tuple[CategoryMatches, ...]

    def index(self, name: str) -> int | None:
        """Position of the category called ``name`` (None: not among them)."""
        for k, c in enumerate(self.categories):
            if c.name == name:
                return k
        return None


def match_records(coco_gt: Any, detections: Mapping[int, np.ndarray],
                  image_ids: Sequence[int]) -> MatchRecords:
    """Evaluate a run once with ``pycocotools`` (box, area "all", 100 detections) and keep the
    per-image matches (module docstring).

    ``detections``: per image id (K, 6) ``x1, y1, x2, y2, score, class-index`` (as stored).
    """
    ids = sorted(int(i) for i in image_ids)
    if not ids:
        raise InvalidValueError("no images to evaluate")
    ev = evaluated_pycocotools(coco_gt, coco_results(coco_gt, detections, ids), ids,
                               area_all_only=True)
    n_img = len(ids)
    max_det = ev.params.maxDets[-1]
    names = {c["id"]: c["name"] for c in coco_gt.dataset["categories"]}
    cats = []
    for k, cid in enumerate(ev.params.catIds):
        entries = ev.evalImgs[k * n_img:(k + 1) * n_img]
        img, scores, tp, fp = [], [], [], []
        gt = np.zeros(n_img, dtype=np.float64)
        for i, e in enumerate(entries):
            if e is None:
                continue
            s = np.asarray(e["dtScores"][:max_det], dtype=np.float64)
            m = np.asarray(e["dtMatches"], dtype=np.float64)[:, :max_det].reshape(len(_IOU), -1)
            ig = np.asarray(e["dtIgnore"], dtype=bool)[:, :max_det].reshape(len(_IOU), -1)
            gt[i] = np.count_nonzero(np.logical_not(e["gtIgnore"]))
            img.append(np.full(len(s), i, dtype=np.int64))
            scores.append(s)
            tp.append(np.logical_and(m != 0, ~ig))
            fp.append(np.logical_and(m == 0, ~ig))
        if not img:
            continue
        sc = np.concatenate(scores)
        order = np.argsort(-sc, kind="mergesort")
        cats.append(CategoryMatches(names[cid], np.concatenate(img)[order],
                                    np.concatenate(tp, axis=1)[:, order],
                                    np.concatenate(fp, axis=1)[:, order], gt))
    return MatchRecords(tuple(ids), tuple(cats))


def bootstrap_weights(n_images: int, resamples: int = BOOTSTRAP_RESAMPLES,
                      seed: int = BOOTSTRAP_SEED) -> np.ndarray:
    """(B, I) image counts of ``resamples`` draws of ``n_images`` images with replacement
    (draw ``b`` is ``default_rng(seed).integers(0, I, I)`` called the ``b``-th time)."""
    rng = np.random.default_rng(seed)
    w = np.zeros((resamples, n_images), dtype=np.float64)
    for b in range(resamples):
        np.add.at(w[b], rng.integers(0, n_images, n_images), 1.0)
    return w


def _precision_at_recalls(rc: np.ndarray, pr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """COCO's interpolated precision at its 101 recall points, per row: ``rc``, ``pr`` (R, n)
    recall and precision along the ranks of each row (recall not decreasing; NaN or Inf
    recall, of a draw without ground truth, taken as 0), ``rows`` (R,) each row's number in
    one search over all rows (offset 2 a row: recall <= 1). Returns (R, 101): the precision
    envelope at the first rank reaching each recall point, 0 where none does."""
    n = rc.shape[1]
    env = np.maximum.accumulate(pr[:, ::-1], axis=1)[:, ::-1]
    rc = np.where(np.isfinite(rc), rc, 0.0) + 2.0 * rows[:, None]
    at = np.searchsorted(rc.ravel(), (_RECALL[None, :] + 2.0 * rows[:, None]).ravel(),
                         side="left").reshape(len(rows), -1)
    col = at - (np.arange(len(rows)) * n)[:, None]
    q: np.ndarray = np.where(col < n, env[np.arange(len(rows))[:, None], np.minimum(col, n - 1)],
                             0.0)
    return q


def _category_ap(c: CategoryMatches, w: np.ndarray) -> np.ndarray:
    """(B,) AP of one category under image weights ``w`` (B, I); NaN where it has no
    ground truth in the draw (COCO leaves such a category out of the mean)."""
    b = w.shape[0]
    npig = w @ c.gt
    dw = w[:, c.image]  # (B, N) each detection counted as often as its image
    n = dw.shape[1]
    ap = np.zeros(b)
    if n:
        with np.errstate(invalid="ignore", divide="ignore"):
            tp = np.cumsum(dw[:, None, :] * c.tp[None], axis=2)  # (B, T, N)
            fp = np.cumsum(dw[:, None, :] * c.fp[None], axis=2)
            rc = (tp / npig[:, None, None]).reshape(-1, n)
            pr = (tp / (tp + fp + np.spacing(1))).reshape(-1, n)
        q = _precision_at_recalls(rc, pr, np.arange(b * len(_IOU), dtype=np.float64))
        ap = q.reshape(b, len(_IOU), -1).mean(axis=(1, 2))
    return np.where(npig > 0, ap, np.nan)


def _category_ap_counts(c: CategoryMatches, w: np.ndarray) -> np.ndarray:
    """:func:`_category_ap` for whole-number weights (image counts, as the bootstrap's), bit
    for bit, computed at the true positives only.

    Recall rises only at a true positive, so the first rank that reaches a recall point is
    a true positive (or the first rank, for recall 0), and between two true positives the
    precision only falls: the precision envelope there is the envelope over the true
    positives. The false positives before each true positive are all detections weighed
    before it less the ignored ones and the true positives: one cumulative sum of the
    weights per draw, shared by the ten IoU thresholds, instead of two per threshold. With
    whole-number weights every count is an exact integer in float64, so precision and recall
    are the same numbers as the cumulative sums over every detection give.
    """
    b = w.shape[0]
    npig = w @ c.gt
    n = len(c.image)
    if not n:
        return np.where(npig > 0, 0.0, np.nan)
    dw = w[:, c.image]  # (B, N)
    every = np.cumsum(dw, axis=1)  # (B, N) weight of the detections up to each rank
    q = np.zeros((b, len(_IOU), len(_RECALL)))
    for t in range(len(_IOU)):
        # the rows of _category_ap's one search over every (draw, threshold), numbered alike
        # (draw-major): the same offsets, rounded alike, give the same first ranks
        rows = np.arange(b, dtype=np.float64) * len(_IOU) + t
        at_tp = np.flatnonzero(c.tp[t])
        if not at_tp.size:
            continue
        tp = np.cumsum(dw[:, at_tp], axis=1)  # (B, K)
        ignored = np.flatnonzero(~(c.tp[t] | c.fp[t]))
        fp = every[:, at_tp] - tp
        if ignored.size:
            before = np.searchsorted(ignored, at_tp, side="right")  # ignored up to each rank
            cum = np.concatenate([np.zeros((b, 1)), np.cumsum(dw[:, ignored], axis=1)], axis=1)
            fp -= cum[:, before]
        with np.errstate(invalid="ignore", divide="ignore"):
            rc = tp / npig[:, None]
            pr = tp / (tp + fp + np.spacing(1))
        q[:, t] = _precision_at_recalls(rc, pr, rows)
    ap = q.mean(axis=(1, 2))
    return np.where(npig > 0, ap, np.nan)


def weighted_scores(records: MatchRecords, weights: np.ndarray,
                    classes: Sequence[str] = ("person", "bicycle"),
                    elements: int = 4_000_000) -> dict[str, np.ndarray]:
    """COCO mAP@[.50:.95] and the AP of ``classes`` under image weights (module docstring).

    Parameters
    ----------
    records
        One run's matches (:func:`match_records`).
    weights
        (B, I) how often each of the run's I images counts in each of B draws (all ones: the
        run itself; :func:`bootstrap_weights`: bootstrap draws); >= 0, any common scale per
        draw.
    classes
        Category names whose AP is returned too (NaN in a draw without their ground truth).
    elements
        Memory bound: draws of a category are computed together as long as draws x 10 IoU
        thresholds x its detections stay under this (each such array 8 bytes an element).

    Returns
    -------
    dict
        ``{"map": (B,), <class>: (B,)}``, fractions in [0, 1]; mAP NaN in a draw without any
        ground truth.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != len(records.image_ids):
        raise InvalidValueError(f"weights of shape {w.shape}: expected (draws, "
                                f"{len(records.image_ids)}) for the run's images")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InvalidValueError("weights must be finite and >= 0")
    # COCO's precision has an absolute epsilon (for counts >= 1): scale each draw so that its
    # smallest positive weight is 1 (counts stay as they are; the scores are scale-free)
    pos = np.where(w > 0, w, np.inf).min(axis=1, keepdims=True)
    w = np.where(np.isfinite(pos), w / np.where(np.isfinite(pos), pos, 1.0), w)
    # whole-number weights (image counts) whose sums stay exact in float64: the counting
    # accumulation (same numbers, a tenth of the passes over the draws x detections)
    counts = bool(np.all(w == np.round(w))) and float(w.sum(axis=1).max(initial=0.0)) < 2.0**52
    category_ap = _category_ap_counts if counts else _category_ap
    aps = np.full((w.shape[0], len(records.categories)), np.nan)
    for k, c in enumerate(records.categories):
        step = max(1, min(w.shape[0], int(elements // max(1, len(_IOU) * len(c.image)))))
        for s in range(0, w.shape[0], step):
            aps[s:s + step, k] = category_ap(c, w[s:s + step])
    valid = np.isfinite(aps)
    count = valid.sum(axis=1)
    with np.errstate(invalid="ignore"):
        out = {"map": np.where(count > 0, np.nansum(aps, axis=1) / np.maximum(count, 1),
                               np.nan)}
    for name in classes:
        at = records.index(name)
        out[name] = aps[:, at] if at is not None else np.full(w.shape[0], np.nan)
    return out


def _finite(x: np.ndarray) -> tuple[float | None, ...]:
    return tuple(float(v) if np.isfinite(v) else None for v in x)


@record
class Draws:
    """One run's scores on the image bootstrap's draws (:func:`draw_scores`), as the stores
    keep them for standard errors: ``map``, ``person``, ``bicycle`` per draw (fractions; None
    in a draw without ground truth of the class). Two runs' draws are paired (same images drawn
    in draw ``b``) when their ``resamples``, ``seed`` and ``images`` agree
    (:meth:`pairs_with`)."""

    resamples: int
    seed: int
    images: int
    map: tuple[float | None, ...]
    person: tuple[float | None, ...]
    bicycle: tuple[float | None, ...]

    def value(self, key: str) -> tuple[float | None, ...]:
        """The draws of score ``key``: ``"map"``, ``"person"`` or ``"bicycle"``."""
        return {"map": self.map, "person": self.person, "bicycle": self.bicycle}[key]

    @property
    def current(self) -> bool:
        """Whether these are this version's draws (:data:`BOOTSTRAP_RESAMPLES` draws with
        :data:`BOOTSTRAP_SEED`); a store scores cells again whose draws are not."""
        return (self.resamples, self.seed) == (BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED)

    def pairs_with(self, other: Draws) -> bool:
        """Whether draw ``b`` of both runs drew the same images."""
        return (self.resamples, self.seed, self.images) == \
            (other.resamples, other.seed, other.images)

    def to_json(self) -> dict[str, Any]:
        """The stores' format (None for a draw without the class)."""
        return {"resamples": self.resamples, "seed": self.seed, "images": self.images,
                "map": list(self.map), "person": list(self.person),
                "bicycle": list(self.bicycle)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Draws:
        """Inverse of :meth:`to_json`."""
        def col(k: str) -> tuple[float | None, ...]:
            return tuple(None if v is None else float(v) for v in d.get(k) or ())

        return cls(int(d["resamples"]), int(d["seed"]), int(d["images"]), col("map"),
                   col("person"), col("bicycle"))


def draw_scores(coco_gt: Any, detections: Mapping[int, np.ndarray], image_ids: Sequence[int],
                resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED) -> Draws:
    """A run's mAP, person and bicycle AP on ``resamples`` bootstrap draws of its images
    (:func:`bootstrap_weights` with ``seed``; one COCO evaluation, :func:`match_records`, then
    :func:`weighted_scores`). For 1000 images on one core: the evaluation about 4-8 s, the
    200 draws about 1 s."""
    rec = match_records(coco_gt, detections, image_ids)
    out = weighted_scores(rec, bootstrap_weights(len(rec.image_ids), resamples, seed))
    return Draws(int(resamples), int(seed), len(rec.image_ids), _finite(out["map"]),
                 _finite(out["person"]), _finite(out["bicycle"]))
