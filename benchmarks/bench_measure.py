"""Benchmark: the pieces of a measured loss (--measure, fidelity coco-c), against anchors.

1. COCO-C corruptions on COCO images: ``fidelity.coco.corruptions.CorruptionMap`` (a 2^24
   colour table, or per-image 256-entry tables for contrast) against the anchor
   ``imagecorruptions.corrupt`` (the package COCO-C uses), same images, same run, best of N;
   the outputs are checked equal.
2. The direction-aware prediction of a chart (the six transform fits) against the classic
   prediction (anchor: ``fidelity.prediction.table.predict``) of the same chart.
3. Optionally (``--measure N``) one ``check --measure`` of a camera on N COCO images with the
   baseline already cached (wall time: emulation fit, 2^24 table, inference, scoring) against
   the baseline inference of those images alone (anchor), both with YOLOX-nano.

Writes reports/benchmarks/measure.json with the machine. Run:
``python -m benchmarks.bench_measure [--measure 1000]`` (needs ../shared or $FIDELITY_SHARED
for the images and, for 1 and 3, the [coco-c] and [coco] extras).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import best_time, machine_info
from fidelity.core.fileio import write_json_atomic


def bench_corruptions(images: list[np.ndarray], repeats: int) -> list[dict[str, Any]]:
    import imagecorruptions

    from fidelity.coco.corruptions import CORRUPTIONS, CorruptionMap

    rows = []
    for name in CORRUPTIONS:
        fast = CorruptionMap(name, 3)
        t0 = time.perf_counter()
        if name != "contrast":
            fast.cube()
        build = time.perf_counter() - t0
        t_fast = best_time(lambda f=fast: [f(im) for im in images], repeats) / len(images)
        t_ref = best_time(lambda n=name: [imagecorruptions.corrupt(im, 3, n) for im in images],
                          repeats) / len(images)
        equal = all(np.array_equal(fast(im), imagecorruptions.corrupt(im, 3, name))
                    for im in images)
        rows.append({"corruption": name, "severity": 3, "ms_per_image_fidelity": 1e3 * t_fast,
                     "ms_per_image_imagecorruptions": 1e3 * t_ref, "speedup": t_ref / t_fast,
                     "table_build_seconds": build, "equal": equal, "images": len(images)})
        print(f"  {name:11s} fidelity {1e3 * t_fast:6.1f} ms/image, imagecorruptions "
              f"{1e3 * t_ref:6.1f} ms/image: {t_ref / t_fast:5.1f}x (table {build:.1f} s once), "
              f"equal {equal}")
    return rows


def bench_directional(repeats: int) -> dict[str, Any]:
    from fidelity.camera.render import render_chart
    from fidelity.prediction.directional import load_directional_table, predict_chart
    from fidelity.prediction.table import load_prediction_table, predict

    m = render_chart("nikon-5100").measurement
    dtab, ctab = load_directional_table(), load_prediction_table()
    t_dir = best_time(lambda: predict_chart(m, table=dtab), repeats)
    t_cls = best_time(lambda: predict(m.mean_delta_e, table=ctab), repeats)
    print(f"  direction-aware prediction {1e3 * t_dir:.0f} ms, classic {1e3 * t_cls:.0f} ms "
          f"(ratio {t_dir / t_cls:.1f})")
    return {"seconds_directional": t_dir, "seconds_classic": t_cls, "ratio": t_dir / t_cls}


def bench_measure(n: int) -> dict[str, Any]:
    from fidelity.coco.measure import MeasureRequest, measure_mapping, resolve_coco_inputs
    from fidelity.pipeline.check import check_camera

    inputs = resolve_coco_inputs()
    with tempfile.TemporaryDirectory() as store:
        t0 = time.perf_counter()

        def identity(rgb: np.ndarray) -> np.ndarray:
            return rgb

        # the anchor: the baseline and an identity cell, two plain passes over the images
        measure_mapping(identity, "bench-identity", inputs, limit=n, store=store)
        t_pass = (time.perf_counter() - t0) / 2
        req = MeasureRequest(inputs, limit=n, store=store)
        t0 = time.perf_counter()
        report = check_camera("cameras/nikon5100-gamma22.toml", measure=req)
        t_check = time.perf_counter() - t0
    m = report.measured[0]
    print(f"  check --measure on {n} images (baseline cached): {t_check:.0f} s; one plain "
          f"detector pass over them: {t_pass:.0f} s (ratio {t_check / t_pass:.2f}); "
          f"{m.summary()}")
    return {"images": n, "seconds_check_measure_cached_baseline": t_check,
            "seconds_one_detector_pass": t_pass, "ratio": t_check / t_pass,
            "measured": m.to_json()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--images", type=int, default=8, help="COCO images for the corruptions")
    ap.add_argument("--measure", type=int, default=0, help="also time check --measure on N")
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parents[1] / "reports/benchmarks/measure.json")
    args = ap.parse_args()
    from fidelity.coco.jpeg import read_jpeg
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    if shared is None:
        raise SystemExit("needs ../shared or FIDELITY_SHARED (COCO images)")
    files = sorted((shared / "coco" / "val2017").glob("*.jpg"))[: args.images]
    images = [read_jpeg(f)[0] for f in files]
    print(f"COCO-C severity 3 on {len(images)} COCO images (best of {args.repeats}):")
    out: dict[str, Any] = {"benchmark": "measured loss pieces", "machine": machine_info(),
                           "load_average": os.getloadavg(),
                           "corruptions": bench_corruptions(images, args.repeats),
                           "directional": bench_directional(max(args.repeats, 5))}
    if args.measure:
        out["measure"] = bench_measure(args.measure)
    write_json_atomic(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
