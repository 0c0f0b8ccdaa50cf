"""Is the standard error of a measured ΔmAP right? Three checks on a validation store's stored
detections (no inference), written to reports/validation/standard_error.md|json.

A loss is ``100 * (mAP(baseline) - mAP(cell))`` with each mAP pooled over every image of the
run (COCO's precision-recall curves pool the detections of all images). Its SE was the paired
SE of the per-fold losses, then the leave-one-fold-out jackknife of the pooled loss; it is now
the paired image bootstrap (fidelity.coco.loss, fidelity.coco.bootstrap). The checks:

1. Split sample (the independent reference): a detector run on N images is cut into P
   disjoint interleaved subsets; the spread of a camera's losses over the subsets is the SE on
   N/P images with no model of mAP at all, and the SEs the tool states on a subset are set
   against it (ratio of root mean squares; coverage of the residuals on every subset for the
   first P).
2. Paired image bootstrap of the pooled loss on a few cells (R resamples, seed stated), every
   draw re-evaluated as a data set of its own, against the tool's re-weighted bootstrap on the
   same draws.
3. Summary of fold SE against jackknife SE over every cell of the store.

Usage: python -m benchmarks.studies.standard_error STORE ANNOTATIONS [--split MODEL] [--bootstrap
       MODEL:CAMERA ...] [--resamples R] [--out reports/validation/standard_error] [--render]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

import numpy as np

from fidelity.coco.bootstrap import bootstrap_weights, draw_scores, match_records, weighted_scores
from fidelity.coco.loss import (
    bootstrap_standard_error,
    jackknife_standard_error,
    paired_standard_error,
)
from fidelity.coco.scoring import FOLDS, coco_from_dict, evaluate_detections, load_annotations
from fidelity.coco.validate.store import ValidationStore
from fidelity.coco.validate.suite import BASELINE

QUARTERS = 4
#: The SEs compared: the paired fold SE, the leave-one-fold-out jackknife, the image bootstrap.
KINDS = ("fold_se", "jackknife_se", "bootstrap_se")


def _pooled(gt: Any, dets: dict[int, np.ndarray], ids: list[int]) -> float:
    return evaluate_detections(gt, dets, ids, method="auto").map


def _ses(gt: Any, base: dict[int, np.ndarray], cell: dict[int, np.ndarray], ids: list[int],
         cache: dict[tuple[Any, ...], Any]) -> tuple[float | None, float | None, float | None]:
    """Fold SE, jackknife SE and bootstrap SE of the loss on ``ids``, as the tool computes
    them (the bootstrap: fidelity.coco.bootstrap.draw_scores, its default draws and seed)."""
    def b(sub: list[int]) -> float:
        key = tuple(sub)
        if key not in cache:
            cache[key] = _pooled(gt, base, sub)
        return float(cache[key])

    folds = [ids[k::FOLDS] for k in range(FOLDS)]
    rests = [[i for i in ids if i not in set(f)] for f in folds]
    key = ("draws", *ids)
    if key not in cache:
        cache[key] = draw_scores(gt, base, ids)
    return (paired_standard_error([b(f) for f in folds], [_pooled(gt, cell, f) for f in folds]),
            jackknife_standard_error([b(r) for r in rests], [_pooled(gt, cell, r) for r in rests]),
            bootstrap_standard_error(cache[key].map, draw_scores(gt, cell, ids).map))


def split_sample(store: ValidationStore, gt: Any, model: str, parts: int, every: bool,
                 say: Any) -> dict[str, Any]:
    """Check 1 for every camera of ``model``, the images cut into ``parts`` interleaved
    subsets: the spread of the subsets' losses (disjoint images: independent) against the SEs
    the tool states on a subset; ``every``: SEs on every subset (coverage), else on the
    first only (root mean square)."""
    base = store.detections(model, BASELINE)
    ids = sorted(base)
    subsets = [ids[q::parts] for q in range(parts)]
    cache: dict[tuple[Any, ...], Any] = {}
    cams: list[dict[str, Any]] = []
    for c in store.cells():
        if c.model != model or c.camera in (BASELINE, "ideal-srgb8") or c.map == \
                (store.cell(model, BASELINE) or c).map:
            continue  # a camera identical to the baseline has no spread to check
        cell = store.detections(model, c.camera)
        losses = np.array([100 * (_pooled(gt, base, s) - _pooled(gt, cell, s)) for s in subsets])
        ses = [_ses(gt, base, cell, s, cache) for s in (subsets if every else subsets[:1])]
        cams.append({"camera": c.camera, "losses": losses.tolist()}
                    | {k: [x[i] for x in ses] for i, k in enumerate(KINDS)})
        say(f"split sample {model} {parts} parts: {c.camera}")
    return summarise({"model": model, "images": len(ids), "parts": parts,
                      "subset_images": len(subsets[0]), "per_camera": cams}, every)


def summarise(split: dict[str, Any], every: bool) -> dict[str, Any]:
    """The empirical SE of a split-sample run (its ``per_camera`` losses and stated SEs) and,
    per estimator (:data:`KINDS` and the larger of bootstrap and jackknife, the tool's), the
    root mean square of its SEs against it; ``every``: the coverage of the residual of each
    subset's loss against the other subsets' mean (variance SE² · P/(P − 1))."""
    cams = split["per_camera"]
    parts = split["parts"]
    for c in cams:
        c["larger_se"] = [None if b is None and j is None else max(x for x in (b, j) if x)
                          for b, j in zip(c["bootstrap_se"], c["jackknife_se"], strict=True)]
    emp = float(np.sqrt(np.mean([np.var(c["losses"], ddof=1) for c in cams])))
    out = dict(split) | {"cameras": len(cams), "empirical_se": emp}
    for k in (*KINDS, "larger_se"):
        v = [x for c in cams for x in c[k] if x is not None]
        out[k] = {"rms": float(np.sqrt(np.mean(np.square(v)))), "ratio": 0.0}
        out[k]["ratio"] = out[k]["rms"] / emp
        z = []
        if every:
            for c in cams:
                losses = np.asarray(c["losses"])
                for q, se in enumerate(c[k]):
                    if se:
                        r = losses[q] - np.delete(losses, q).mean()
                        z.append(float(r / (se * np.sqrt(parts / (parts - 1)))))
        if z:
            a = np.abs(np.asarray(z))
            out[k] |= {"trials": len(a), "within_1": float(np.mean(a <= 1)),
                       "within_2": float(np.mean(a <= 2)),
                       "mean_z2": float(np.mean(np.square(a)))}
    return out


def bootstrap(store: ValidationStore, gt: Any, model: str, camera: str, resamples: int,
              seed: int) -> dict[str, Any]:
    """Check 2: paired image bootstrap SE of the pooled loss of one cell."""
    base, cell = store.detections(model, BASELINE), store.detections(model, camera)
    ids = sorted(base)
    ds = gt.dataset
    anns: dict[int, list[dict[str, Any]]] = {}
    for a in ds["annotations"]:
        anns.setdefault(a["image_id"], []).append(a)
    imgs = {im["id"]: im for im in ds["images"]}
    rng = np.random.default_rng(seed)
    losses = []
    t0 = time.perf_counter()
    for _ in range(resamples):
        images: list[dict[str, Any]] = []
        boxes: list[dict[str, Any]] = []
        db: dict[int, np.ndarray] = {}
        dc: dict[int, np.ndarray] = {}
        for j, p in enumerate(rng.integers(0, len(ids), len(ids))):
            src, new = ids[p], j + 1
            images.append(imgs[src] | {"id": new})
            boxes += [a | {"id": len(boxes) + k + 1, "image_id": new}
                      for k, a in enumerate(anns.get(src, []))]
            db[new], dc[new] = base[src], cell[src]
        g = coco_from_dict({"images": images, "annotations": boxes,
                            "categories": ds["categories"]})
        sub = list(range(1, len(ids) + 1))
        losses.append(100 * (_pooled(g, db, sub) - _pooled(g, dc, sub)))
    brute_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    w = bootstrap_weights(len(ids), resamples, seed)
    fast = 100 * (weighted_scores(match_records(gt, base, ids), w)["map"]
                  - weighted_scores(match_records(gt, cell, ids), w)["map"])
    fast_s = time.perf_counter() - t0
    c = store.cell(model, camera)
    b = store.cell(model, BASELINE)
    assert c is not None and b is not None
    return {"model": model, "camera": camera, "images": len(ids), "resamples": resamples,
            "seed": seed, "loss": 100 * (b.map - c.map),
            "bootstrap_se": float(np.std(losses, ddof=1)),
            "reweighted_se": float(np.std(fast, ddof=1)),
            "max_draw_difference": float(np.max(np.abs(fast - np.asarray(losses)))),
            "fold_se": paired_standard_error([f.map for f in b.folds], [f.map for f in c.folds]),
            "jackknife_se": jackknife_standard_error([f.rest_map for f in b.folds],
                                                     [f.rest_map for f in c.folds]),
            "seconds": brute_s, "reweighted_seconds": fast_s}


def overview(store: ValidationStore) -> dict[str, Any]:
    """Check 3: fold SE against jackknife SE per model over every cell."""
    cells = {(c.model, c.camera): c for c in store.cells()}
    out: dict[str, Any] = {}
    for (m, cam), c in sorted(cells.items()):
        b = cells.get((m, BASELINE))
        if cam == BASELINE or b is None:
            continue
        f = paired_standard_error([x.map for x in b.folds], [x.map for x in c.folds])
        j = jackknife_standard_error([x.rest_map for x in b.folds], [x.rest_map for x in c.folds])
        if f and j:
            out.setdefault(m, []).append(j / f)
    return {m: {"cells": len(r), "median_ratio": statistics.median(r), "min_ratio": min(r),
                "max_ratio": max(r)} for m, r in out.items()}


def markdown(doc: dict[str, Any]) -> str:
    lines = ["# Standard error of a measured ΔmAP: fold SE, jackknife and image bootstrap", "",
             f"Generated by `python -m benchmarks.studies.standard_error` on {doc['machine']} from the "
             f"validation store's detections ({doc['store_images']}); no inference. Loss = "
             "100·(pooled mAP of the baseline − pooled mAP of the cell) on the same images.", ""]
    splits = doc.get("split") or []
    if splits:
        lines += ["## Split sample (independent reference)", "",
                  "The detector's images cut into P interleaved disjoint subsets; the spread of "
                  "the subsets' losses per camera (cameras identical to the baseline left out) "
                  "is the SE on a subset's image count, without any model of how mAP behaves. "
                  "Against it, the SEs the tool states on a subset (root mean square over the "
                  "cameras; on every subset where coverage is given: the residual of a subset's "
                  "loss against the other subsets' mean, in stated SEs, should be within 1 for "
                  "~68 % and within 2 for ~95 %, mean z² ≈ 1).", "",
                  "| detector | subsets × images | cameras | empirical SE | fold SE: "
                  "rms, ratio | jackknife SE: rms, ratio | bootstrap SE: rms, ratio | larger "
                  "of bootstrap and jackknife (the tool's): rms, ratio | coverage fold: ±1, "
                  "±2, z² | coverage jackknife | coverage bootstrap | coverage larger |",
                  "|---|---|---:|---:|---|---|---|---|---|---|---|---|"]
        for s in splits:
            def cov(r: dict[str, Any]) -> str:
                return (f"{100 * r['within_1']:.0f} %, {100 * r['within_2']:.0f} %, "
                        f"{r['mean_z2']:.2f} ({r['trials']})" if "trials" in r else "–")
            f, j, b, g = (s[k] for k in (*KINDS, "larger_se"))
            lines.append(f"| {s['model']} | {s['parts']} × {s['subset_images']} | "
                         f"{s['cameras']} | {s['empirical_se']:.3f} | {f['rms']:.3f}, "
                         f"{f['ratio']:.2f} | {j['rms']:.3f}, {j['ratio']:.2f} | "
                         f"{b['rms']:.3f}, {b['ratio']:.2f} | {g['rms']:.3f}, {g['ratio']:.2f} | "
                         f"{cov(f)} | {cov(j)} | {cov(b)} | {cov(g)} |")
        lines.append("")
    if doc.get("bootstrap"):
        lines += ["## Paired image bootstrap: every draw re-evaluated against re-weighted", "",
                  "Brute force: each draw's images made a data set of their own and scored by "
                  "COCO evaluation; re-weighted: the tool's estimator "
                  "(`fidelity.coco.bootstrap`, one evaluation per run, the same draws).", "",
                  "| detector | camera | images | loss | fold SE | jackknife SE | bootstrap SE "
                  "(R, seed) | re-weighted SE | largest draw difference | time brute, "
                  "re-weighted |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for b in doc["bootstrap"]:
            rw = (f"{b['reweighted_se']:.4f} | {b['max_draw_difference']:.4f} | "
                  f"{b['seconds']:.0f} s, {b['reweighted_seconds']:.1f} s"
                  if "reweighted_se" in b else "– | – | –")
            lines.append(f"| {b['model']} | {b['camera']} | {b['images']} | {b['loss']:+.3f} | "
                         f"{b['fold_se']:.3f} | {b['jackknife_se']:.3f} | "
                         f"{b['bootstrap_se']:.4f} ({b['resamples']}, {b['seed']}) | {rw} |")
        lines.append("")
    lines += ["## Jackknife SE / fold SE over every cell", "", "| detector | cells | median | "
              "range |", "|---|---:|---:|---|"]
    for m, r in doc["overview"].items():
        lines.append(f"| {m} | {r['cells']} | {r['median_ratio']:.2f} | "
                     f"{r['min_ratio']:.2f}–{r['max_ratio']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    from benchmarks.machine import machine_words, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("annotations")
    ap.add_argument("--split", default=None, help="model for the split-sample check")
    ap.add_argument("--parts", default="4,2,8",
                    help="subset counts of the split-sample check (the first: SEs on every "
                         "subset, for coverage)")
    ap.add_argument("--bootstrap", nargs="*", default=[], help="MODEL:CAMERA cells")
    ap.add_argument("--resamples", type=int, default=100)
    ap.add_argument("--seed", type=int, default=20261126)
    ap.add_argument("--out", default="reports/validation/standard_error")
    ap.add_argument("--render", action="store_true",
                    help="only summarise and write OUT.md|json again from OUT.json's per-camera "
                         "values (no evaluation; STORE and ANNOTATIONS unused)")
    a = ap.parse_args(argv)
    if a.render:
        from pathlib import Path

        old = json.loads(Path(a.out).with_suffix(".json").read_text(encoding="utf-8"))
        old["split"] = [summarise(sp, i == 0) for i, sp in enumerate(old.get("split") or [])]
        write_report(a.out, old, markdown(old))
        return
    store = ValidationStore(a.store, create=False)
    gt = load_annotations(a.annotations)

    def say(s: str) -> None:
        print(s, flush=True)

    doc: dict[str, Any] = {"machine": machine_words(),
                           "store_images": ", ".join(f"{m}: {r.limit_images or 'all'} images"
                                                     for m, r in store.models().items()),
                           "overview": overview(store)}
    if a.split:
        parts = [int(p) for p in a.parts.split(",")]
        doc["split"] = [split_sample(store, gt, a.split, p, i == 0, say)
                        for i, p in enumerate(parts)]
    doc["bootstrap"] = []
    for spec in a.bootstrap:
        m, cam = spec.split(":", 1)
        doc["bootstrap"].append(bootstrap(store, gt, m, cam, a.resamples, a.seed))
        say(json.dumps(doc["bootstrap"][-1]))
    write_report(a.out, doc, markdown(doc))


if __name__ == "__main__":
    main()
