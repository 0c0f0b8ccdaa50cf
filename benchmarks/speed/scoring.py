"""COCO scoring: faster-coco-eval against pycocotools on the sweep's own stored detections.

Two things, on real data (a sweep store, ``fidelity sweep --out DIR``):

* Agreement: every finished cell is re-scored from its stored detections with faster-coco-eval
  and compared with pycocotools (the reference): with the stored numbers for the cells the sweep
  scored with pycocotools (``SweepStore.scorer_of``), with a fresh pycocotools run for the
  others. The largest absolute difference over mAP, AP50, AP75 and every class AP is reported. The issue's
  rule: faster-coco-eval may be the fast path only if it agrees to 1e-4.
* Speed: on a sample of cells, both scorers timed side by side (best of ``repeats``) on the
  same detections.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import best_time

ANCHOR = "pycocotools (the reference scorer) on the same stored detections"
PARAMETERS = {"store": Parameter(None, "a sweep store (fidelity sweep --out DIR; required)"),
              "annotations": Parameter(None, "the COCO annotations (default: the shared subset)"),
              "sample": Parameter(6, "cells timed with both scorers"),
              "check": Parameter(0, "compare only this many cells, drawn at random (0: all)"),
              "repeats": Parameter(2, "best of N")}
QUICK = {"sample": 2, "check": 2, "repeats": 1}
NEEDS = ("onnxruntime",)

if TYPE_CHECKING:
    from fidelity.coco.scoring import CocoScore
    from fidelity.coco.sweep import SweepCell


def _max_difference(ref: SweepCell | CocoScore, score: CocoScore) -> float:
    """Largest |Δ| between a stored cell's (or a reference score's) map, map50, map75, ap
    and a CocoScore."""
    diffs = [abs((ref.map or 0.0) - score.map), abs((ref.map50 or 0.0) - score.map50),
             abs((ref.map75 or 0.0) - score.map75)]
    for name, ap in (ref.ap or {}).items():
        other = score.ap.get(name)
        if (ap is None) != (other is None):
            return float("inf")
        if ap is not None:
            diffs.append(abs(ap - other))
    return float(max(diffs))


def measure(ctx: Context) -> dict[str, Any]:
    from types import SimpleNamespace

    from fidelity.coco.scoring import evaluate_detections, load_annotations
    from fidelity.coco.sweep import SweepStore
    from fidelity.core.resources import shared_dir

    if not ctx["store"]:
        raise SystemExit("scoring: give the sweep store, -p store=DIR")
    shared = shared_dir()
    annotations = ctx["annotations"] or (
        shared / "coco/annotations/instances_val2017_subset.json" if shared else None)
    if annotations is None:
        raise SystemExit("scoring: give the annotations, -p annotations=FILE")
    args = SimpleNamespace(store=Path(ctx["store"]), annotations=Path(annotations),
                           sample=ctx["sample"], check=ctx["check"] or None,
                           repeats=ctx["repeats"])

    store = SweepStore(args.store, create=False)
    scorer_of = store.scorer_of
    coco = load_annotations(args.annotations)
    ids_all = sorted(coco.getImgIds())
    models = store.models()
    cells = [c for c in store.cells() if c.done]
    checked = cells
    if args.check is not None and args.check < len(cells):
        pick = np.random.default_rng(1).choice(len(cells), args.check, replace=False)
        checked = [cells[i] for i in sorted(pick)]

    worst, n, t0 = 0.0, 0, time.perf_counter()
    worst_cell = None
    for c in checked:
        lim = models[c.model].limit_images
        ids = ids_all[:lim] if lim else ids_all
        dets = store.detections(c.model, c.transform, c.target)
        fast = evaluate_detections(coco, dets, ids, method="faster-coco-eval")
        # cells the sweep scored with pycocotools are compared with their stored numbers; the
        # others are scored with pycocotools here
        ref: SweepCell | CocoScore = c if scorer_of(c) == "pycocotools" else \
            evaluate_detections(coco, dets, ids, method="pycocotools")
        d = _max_difference(ref, fast)
        n += 1
        if d > worst:
            worst, worst_cell = d, f"{c.model} {c.transform} ΔE {c.target:g}"
        if n % 25 == 0:
            print(f"{n}/{len(checked)} cells, largest difference so far {worst:.2e}",
                  file=sys.stderr, flush=True)
    agree_s = time.perf_counter() - t0

    rng = np.random.default_rng(0)
    sample = [cells[i] for i in rng.choice(len(cells), min(args.sample, len(cells)),
                                           replace=False)]
    timing = []
    for c in sample:
        lim = models[c.model].limit_images
        ids = ids_all[:lim] if lim else ids_all
        dets = store.detections(c.model, c.transform, c.target)
        t_ref, t_fast = (best_time(lambda m=m, d=dets, i=ids: evaluate_detections(coco, d, i,
                                                                                  method=m),
                                   args.repeats)
                         for m in ("pycocotools", "faster-coco-eval"))
        timing.append({"cell": f"{c.model} {c.transform} ΔE {c.target:g}",
                       "images": len(ids), "pycocotools_s": t_ref, "faster_coco_eval_s": t_fast,
                       "ratio": t_ref / t_fast})
        print(f"{timing[-1]['cell']:<40} {len(ids):>5} img  pycocotools {t_ref:6.2f} s  "
              f"faster-coco-eval {t_fast:6.2f} s  {t_ref / t_fast:4.1f}x", flush=True)

    from importlib.metadata import version

    result = {
        "store": args.store.name, "cells_compared": n, "cells_done": len(cells),
        "largest_difference": worst,
        "largest_difference_cell": worst_cell, "tolerance": 1e-4, "agrees": worst <= 1e-4,
        "agreement_seconds": agree_s, "timing": timing,
        "median_speedup": float(np.median([t["ratio"] for t in timing])) if timing else None,
        "versions": {"pycocotools": version("pycocotools"),
                     "faster-coco-eval": version("faster-coco-eval")},
        "repeats": args.repeats,
        "note": ("every finished cell compared" if n == len(cells) else
                 f"{n} of {len(cells)} finished cells compared, drawn at random (--check)"),
    }
    return result


def cases(details: dict[str, Any]) -> list[Case]:
    repeats = details.get("repeats")
    stat = f"best of {repeats}" if repeats else "best of N (N not recorded)"
    note = (f"largest difference over mAP, AP50, AP75 and class AP "
            f"{details['largest_difference']:.1e} over {details['cells_compared']} cells "
            f"(agrees to {details['tolerance']:g}: {details['agrees']})")
    return [case(f"{t['cell']} ({t['images']} images)",
                 figures("faster-coco-eval", t["faster_coco_eval_s"] / t["images"]),
                 figures("pycocotools", t["pycocotools_s"] / t["images"]), per="image",
                 statistic=stat, note=note)
            for t in details["timing"]]
