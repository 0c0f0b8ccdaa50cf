"""The pieces of a measured loss (``check --measure``, ``fidelity coco-c``), against anchors.

1. COCO-C corruptions on COCO images: ``fidelity.coco.corruptions.CorruptionMap`` (a 2^24
   colour table, or per-image 256-entry tables for contrast) against the anchor
   ``imagecorruptions.corrupt`` (the package COCO-C uses), same images, same run, best of N;
   the outputs are checked equal.
2. The direction-aware prediction of a chart (the six transform fits) against the classic
   prediction (anchor: ``fidelity.prediction.table.predict``) of the same chart.
3. Optionally (``measure``: N images) one ``check --measure`` of a camera on N COCO images with the
   baseline already cached (wall time: emulation fit, 2^24 table, inference, scoring) against
   the baseline inference of those images alone (anchor), both with YOLOX-nano.

Needs ../shared or $FIDELITY_SHARED for the images, imagecorruptions for 1 and the coco extra
for 3.
"""

from __future__ import annotations

import os
import tempfile
import time
from typing import Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import best_time

ANCHOR = ("imagecorruptions.corrupt (the package COCO-C uses) per COCO image; the classic "
          "prediction; one plain detector pass over the images")
PARAMETERS = {"repeats": Parameter(3, "best of N"),
              "images": Parameter(8, "COCO images for the corruptions"),
              "measure": Parameter(0, "also time check --measure on N images (0: not)")}
QUICK = {"repeats": 1, "images": 2}
NEEDS = ("shared", "imagecorruptions")


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
    from fidelity.prediction.table import predict
    from fidelity.prediction.tablefile import load_prediction_table

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


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.coco.jpeg import read_jpeg
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    if shared is None:
        raise SystemExit("needs ../shared or FIDELITY_SHARED (COCO images)")
    repeats = ctx["repeats"]
    files = sorted((shared / "coco" / "val2017").glob("*.jpg"))[: ctx["images"]]
    images = [read_jpeg(f)[0] for f in files]
    ctx.log(f"COCO-C severity 3 on {len(images)} COCO images (best of {repeats}):")
    out: dict[str, Any] = {"benchmark": "measured loss pieces", "repeats": repeats,
                           "load_average": os.getloadavg(),
                           "corruptions": bench_corruptions(images, repeats),
                           "directional": bench_directional(max(repeats, 5))}
    if ctx["measure"]:
        out["measure"] = bench_measure(ctx["measure"])
    return out


def cases(details: dict[str, Any]) -> list[Case]:
    repeats = details.get("repeats")
    best = f"best of {repeats}" if repeats else "best of N (N not recorded)"
    out = [case(f"{r['corruption']} severity {r['severity']}",
                figures("fidelity.coco.corruptions.CorruptionMap",
                        r["ms_per_image_fidelity"] / 1000),
                figures("imagecorruptions.corrupt", r["ms_per_image_imagecorruptions"] / 1000),
                per="image", statistic=f"{best} passes over {r['images']} COCO images",
                note=(f"outputs equal: {r['equal']}; the table built once in "
                      f"{r['table_build_seconds']:.1f} s"))
           for r in details["corruptions"]]
    d = details["directional"]
    out.append(case("prediction of a chart (nikon-5100)",
                    figures("direction-aware predict_chart", d["seconds_directional"]),
                    figures("classic predict", d["seconds_classic"]), per="call",
                    statistic=f"best of {max(repeats, 5)}" if repeats
                    else "best of N (N not recorded)"))
    m = details.get("measure")
    if m:
        out.append(case(f"check --measure on {m['images']} images, the baseline cached",
                        figures("check_camera(..., measure=...)",
                                m["seconds_check_measure_cached_baseline"]),
                        figures("one plain detector pass over the images",
                                m["seconds_one_detector_pass"]),
                        per="run", statistic="one run"))
    return out
