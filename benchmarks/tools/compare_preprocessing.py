"""How much the issue-24 preprocessing moves COCO mAP and ΔmAP: old vs new detections.

New detections are read from a sweep store made with the current code (``fidelity sweep
--out DIR``); old ones are computed here with ``fidelity/coco/detectors.py`` as it was at git
revision ``--old-rev`` (rounded sizes, a float bilinear resize and one gain), loaded from git,
on the images whose model input differs: for the Ultralytics family the images whose long side
is not the input size (the others give the same input, which is checked on a few), for YOLOX
all. Both sets are scored with COCO AP on the same images; per cell the ΔmAP against the
baseline in points and relative, old and new.

Usage: python -m benchmarks.tools.compare_preprocessing STORE MODEL.onnx
       --cells baseline:0,contrast-inc:6,saturation-inc:10 [--images 1000]
       [--old-rev 68f87e1] [--json out.json]      (needs ../shared or $FIDELITY_SHARED)
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np


def old_detectors(rev: str) -> ModuleType:
    """``fidelity/coco/detectors.py`` at git revision ``rev``, imported as a module."""
    repo = Path(__file__).resolve().parents[2]
    src = subprocess.run(["git", "show", f"{rev}:fidelity/coco/detectors.py"], cwd=repo,
                         check=True, capture_output=True, text=True).stdout
    path = Path(tempfile.mkdtemp()) / "old_detectors.py"
    path.write_text(src, encoding="utf-8")
    spec = importlib.util.spec_from_file_location("old_detectors", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["old_detectors"] = module
    spec.loader.exec_module(module)
    return module


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("model")
    ap.add_argument("--cells", default="baseline:0")
    ap.add_argument("--images", type=int, default=1000)
    ap.add_argument("--old-rev", default="68f87e1", help="git revision of the old detectors")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    from fidelity.coco.dataset import BASELINE, PixelMap, calibrated_param
    from fidelity.coco.jpeg import read_jpeg, roundtrip_jpeg
    from fidelity.coco.scoring import evaluate_detections, load_annotations
    from fidelity.coco.sweep import SweepStore
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    if shared is None:
        print("skipped: ../shared (COCO images, models) not present", file=sys.stderr)
        return 0
    old = old_detectors(args.old_rev)
    model = Path(args.model)
    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())[: args.images]
    store = SweepStore(args.store)
    det = old.Detector(model, threads=1)
    size = max(det.layout.input_size)

    def differs(i: int) -> bool:
        im = coco.imgs[i]
        return bool(det.layout.kind == "yolox" or max(im["height"], im["width"]) != size)

    todo = [i for i in ids if differs(i)]
    control = [i for i in ids if not differs(i)][:3]
    res: dict[str, Any] = {"model": model.stem, "images": len(ids), "old_rev": args.old_rev,
                           "recomputed_old": len(todo), "cells": {}}
    for cell in args.cells.split(","):
        transform, target = cell.split(":")[0], float(cell.split(":")[1])
        t0 = time.time()
        stored = store.detections(model.stem, transform, target)
        missing = [i for i in ids if i not in stored]
        if missing:
            raise SystemExit(f"{cell}: {len(missing)} images not in the store")
        new = {i: stored[i] for i in ids}
        param = None if transform == BASELINE else calibrated_param(transform, target)[0]
        pm = PixelMap.build(transform, param)
        olds = dict(new)
        for i in todo + control:
            rgb, settings = read_jpeg(shared / "coco/val2017" / coco.imgs[i]["file_name"])
            d = det(roundtrip_jpeg(pm(rgb), settings))
            if i in control:
                if not np.array_equal(d, new[i]):
                    raise SystemExit(f"{cell}: image {i} differs though its input does not")
            else:
                olds[i] = d
        changed = sum(1 for i in todo if not (olds[i].shape == new[i].shape
                                              and np.allclose(olds[i], new[i], atol=1e-3)))
        sn = evaluate_detections(coco, new, ids, method="faster-coco-eval")
        so = evaluate_detections(coco, olds, ids, method="faster-coco-eval")
        res["cells"][cell] = {"map_new": sn.map, "map_old": so.map,
                              "person_new": sn.ap.get("person"),
                              "person_old": so.ap.get("person"),
                              "images_with_changed_detections": changed,
                              "seconds": time.time() - t0}
        print(f"{model.stem} {cell}: mAP new {sn.map:.5f} old {so.map:.5f} "
              f"({100 * (sn.map - so.map):+.3f} points), {changed} images changed", flush=True)
    base = res["cells"].get("baseline:0")
    if base:
        for cell, v in res["cells"].items():
            if cell == "baseline:0":
                continue
            for tag in ("new", "old"):
                b, m = base[f"map_{tag}"], v[f"map_{tag}"]
                v[f"dmap_points_{tag}"] = 100 * (b - m)
                v[f"dmap_relative_{tag}"] = 100 * (b - m) / b
            v["dmap_points_change"] = v["dmap_points_new"] - v["dmap_points_old"]
            print(f"{model.stem} {cell}: ΔmAP new {v['dmap_points_new']:.3f} old "
                  f"{v['dmap_points_old']:.3f} points ({v['dmap_points_change']:+.3f}); "
                  f"relative new {v['dmap_relative_new']:.2f} old {v['dmap_relative_old']:.2f} %")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
