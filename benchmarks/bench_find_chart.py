"""Benchmark: finding the chart in photos, fidelity's cascade against OpenCV's mcc detector and
colour-checker-detection's segmentation, side by side on the same images.

Images (:mod:`benchmarks.chart_scenes`, seeded, generated into a cache folder, never committed):
real COCO val2017 photos as backgrounds (``--coco``; default ``$FIDELITY_SHARED/coco/val2017``
or ``../shared``), resized to 640, 1600 or 4000 px on the long side (4000 x 3000 = 12 MP), with
a rendered chart (patch colours from :func:`fidelity.camera.render.render_chart` for several
cameras and illuminants) composited in perspective at many sizes, turns and tilts, under
coloured light, with exposure from dark to clipped, shading, blur, noise, partial occlusion and
JPEG compression: 60 classic charts, 25 minis (smaller), 20 Passports (two charts side by side,
one 24-patch), 6 SG-like 140-patch charts that must be refused, and 20 images with no chart.
``--quick`` takes every fifth image.

Scoring: a chart is found correctly when the four corner patch centres (dark skin, bluish
green, black, white, in that order) lie within half a patch pitch of the truth; any chart
answered on a no-chart image is a false positive; an SG answered with corners is a wrong fit.
Time: wall time of the finder on the decoded pixels in its own input format (fidelity: float32
sRGB as its reader gives; mcc: 8-bit BGR as ``cv2.imread`` gives; colour-checker-detection:
float32 linear; reading and converting excluded), one run per image; the same run times every
finder, so their ratio is fair even on a loaded machine (the load average is recorded), and the
process CPU time beside it (less sensitive to other processes; OpenCV's own threads add to it).

Finders:

- ``fidelity``: :func:`fidelity.chart.find.find_chart` (cascade), on the sRGB pixels;
- ``mcc``: ``cv2.mcc.CCheckerDetector`` (MCC24, one chart) on the full-size 8-bit image, its
  corner patches' centres (patch 0, 5, 23, 18 of its answer);
- ``colour-checker-detection``: ``detect_colour_checkers_segmentation`` on the linearised
  image with the aspect-ratio range fidelity used with it before (:data:`CCD_ASPECT_RATIO`), the centres of its corner swatches from its chart outline (it
  orders the outline itself); only when the package is installed (its metadata requires
  opencv-python, so fidelity does not depend on it: ``pip install --no-deps
  colour-checker-detection``).

Writes ``reports/find_chart/results.json`` (per image and summary, with the machine) and
``reports/find_chart/table.md``.
Run:  python -m benchmarks.bench_find_chart [--quick] [--cache DIR]
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import machine_info
from fidelity.colour import colorimetry as cm
from fidelity.core.fileio import write_bytes_atomic, write_json_atomic, write_text_atomic
from tests.fixtures.chart_scenes import corners_correct, decode_jpeg, make_scene

#: Images per kind (the full benchmark).
COUNTS = {"classic": 60, "mini": 25, "passport": 20, "sg": 6, "none": 20}
#: Long sides, cycled per kind: one in five at 4000 px (12 MP).
LONG_SIDES = (1600, 640, 1600, 4000, 1600)
#: Patch colours: (camera, illuminant) renders, cycled.
RENDERS = (("ideal", "D65"), ("nikon-5100", "D65"), ("nikon-5100", "A"),
           ("sigma-sdmerrill", "F11"), ("nikon-5100", "F11"))
#: Aspect ratios of a chart that colour-checker-detection accepts: fidelity's former setting
#: (its default, 1.35-1.65, loses almost every chart seen in perspective).
CCD_ASPECT_RATIO = (1.1, 2.0)
#: Bumped when the scenes change (the cache key).
SCENES_VERSION = 2


def scene_specs(quick: bool) -> list[tuple[int, str, int]]:
    """``(index, kind, long side)`` of every image, in a fixed order."""
    specs = []
    n = 0
    for kind, count in COUNTS.items():
        for k in range(count):
            # sizes cycle so that every fifth image (--quick) has each size too
            specs.append((n, kind, LONG_SIDES[(k + k // 5) % len(LONG_SIDES)]))
            n += 1
    return specs[::5] if quick else specs


def _patch_colours() -> list[np.ndarray]:
    from fidelity.camera.render import render_chart

    out = []
    for camera, illuminant in RENDERS:
        srgb = render_chart(camera, illuminant).measurement.srgb
        out.append(cm.linearize_srgb(np.clip(srgb, 0.0, 1.0)))
    return out


def generate(specs: list[tuple[int, str, int]], coco: Path, cache: Path, seed: int
             ) -> list[dict[str, Any]]:
    """Make (or load from ``cache``) every image; returns records with the JPEG path and truth."""
    cache.mkdir(parents=True, exist_ok=True)
    files = sorted(glob.glob(str(coco / "*.jpg")))
    if len(files) < 50:
        sys.exit(f"bench_find_chart: need COCO photos in {coco} (found {len(files)})")
    order = np.random.default_rng(seed).permutation(len(files))
    colours: list[np.ndarray] | None = None
    records = []
    for index, kind, side in specs:
        jpg = cache / f"scene_{index:03d}.jpg"
        meta = cache / f"scene_{index:03d}.json"
        if not (jpg.exists() and meta.exists()):
            if colours is None:
                colours = _patch_colours()
            scene = make_scene(kind, files[order[index % len(files)]],
                               colours[index % len(colours)], seed=(seed, index),
                               long_side=side)
            assert scene.jpeg is not None
            write_json_atomic(meta, {
                "index": index, "kind": kind, "background": Path(files[order[index]]).name,
                "render": list(RENDERS[index % len(RENDERS)]),
                "corners": None if scene.corners is None else scene.corners.tolist(),
                "pitch_px": None if np.isnan(scene.pitch_px) else scene.pitch_px,
                "conditions": scene.conditions})
            write_bytes_atomic(jpg, scene.jpeg)
            if sys.stderr.isatty():
                print(f"\rgenerated {index + 1} images", end="", file=sys.stderr)
        records.append({**json.loads(meta.read_text()), "path": str(jpg)})
    if sys.stderr.isatty():
        print(file=sys.stderr)
    return records


# --------------------------------------------------------------------------------------------
# Finders: (prepare, find): prepare turns (H, W, 3) uint8 sRGB into the finder's own input (as
# its usual reader gives it; not timed), find answers (4, 2) corner centres or None (timed).


def _float_srgb(rgb8: np.ndarray) -> np.ndarray:
    return rgb8.astype(np.float32) / np.float32(255.0)  # as fidelity.chart.image.read_image


def find_fidelity(pixels: np.ndarray) -> np.ndarray | None:
    from fidelity.chart.find import find_chart
    from fidelity.core.errors import FidelityError

    try:
        return find_chart(pixels, encoding="srgb").corners
    except FidelityError:
        return None


def _bgr8(rgb8: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb8[..., ::-1])  # as cv2.imread


def find_mcc(bgr8: np.ndarray) -> np.ndarray | None:
    from fidelity.chart.find import mcc_charts

    charts = mcc_charts(bgr8, charts=1)
    if not charts:
        return None
    return charts[0][[0, 5, 23, 18]]


def _opencv_version() -> str:
    import cv2

    return str(cv2.__version__)


def _ccd_available() -> bool:
    try:
        import colour_checker_detection  # noqa: F401
    except ImportError:
        return False
    return True


def _linear(rgb8: np.ndarray) -> np.ndarray:
    return cm.linearize_srgb(rgb8.astype(np.float32) / 255.0).astype(np.float32)


def find_ccd(image: np.ndarray) -> np.ndarray | None:
    import colour_checker_detection as ccd
    from colour_checker_detection.detection.segmentation import (
        SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC as settings,
    )

    from fidelity.chart.locate import apply_homography, homography_from_points

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        charts = ccd.detect_colour_checkers_segmentation(
            image, additional_data=True, aspect_ratio_minimum=CCD_ASPECT_RATIO[0],
            aspect_ratio_maximum=CCD_ASPECT_RATIO[1])
    if not charts:
        return None
    ww, wh = int(settings["working_width"]), int(settings["working_height"])
    rows, cols = 4, 6
    quad = np.asarray(charts[0].quadrilateral, dtype=np.float64)
    # ccd warps outline corner k to rectangle corner k and samples swatch (c, r) at
    # ((c + 0.5) ww / cols, (r + 0.5) wh / rows); its outline is in its working image, which is
    # the input turned 90 degrees clockwise when portrait and resized to the working width
    rect = np.array([[ww, 0], [ww, wh], [0, wh], [0, 0]], dtype=np.float64)
    h = homography_from_points(rect, quad)
    cells = np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], float)
    pts = apply_homography(h, (cells + 0.5) * (ww / cols, wh / rows))
    height, width = image.shape[:2]
    portrait = width < height
    w2, h2 = (height, width) if portrait else (width, height)
    work_h = int(h2 / (w2 / ww))
    x = (pts[:, 0] + 0.5) * w2 / ww - 0.5
    y = (pts[:, 1] + 0.5) * h2 / work_h - 0.5
    if portrait:
        x, y = y, (height - 1) - x
    return np.stack([x, y], axis=-1)


Finder = tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], Any]]


def run(records: list[dict[str, Any]], finders: dict[str, Finder]) -> list[dict[str, Any]]:
    rows = []
    tty = sys.stderr.isatty()
    for n, rec in enumerate(records):
        rgb8 = decode_jpeg(Path(rec["path"]).read_bytes())
        truth = None if rec["corners"] is None else np.asarray(rec["corners"])
        row: dict[str, Any] = {k: rec[k] for k in ("index", "kind", "background", "pitch_px",
                                                     "conditions")}
        for name, (prepare, finder) in finders.items():
            pixels = prepare(rgb8)
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                corners = finder(pixels)
            except Exception as exc:  # noqa: BLE001 - an anchor's crash counts as not found
                corners, row[f"{name}_crash"] = None, f"{type(exc).__name__}: {exc}"
            seconds = time.perf_counter() - t0
            cpu = time.process_time() - c0
            res: dict[str, Any] = {"seconds": round(seconds, 4), "cpu_seconds": round(cpu, 4),
                                   "answered": corners is not None}
            if truth is not None:
                res["correct"] = corners_correct(corners, truth, rec["pitch_px"])
                if corners is not None:
                    res["error_pitch"] = round(float(np.linalg.norm(
                        np.asarray(corners) - truth, axis=-1).max() / rec["pitch_px"]), 4)
            row[name] = res
        rows.append(row)
        if tty:
            done = " ".join(f"{k}:{'ok' if row[k].get('correct', not row[k]['answered']) else '--'}"
                            for k in finders)
            print(f"\r{n + 1}/{len(records)} {rec['kind']:9s} {done}   ", end="", file=sys.stderr)
    if tty:
        print(file=sys.stderr)
    return rows


def summarise(rows: list[dict[str, Any]], finders: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in finders:
        charts = [r for r in rows if r["kind"] in ("classic", "mini", "passport")]
        by_kind = {k: f"{sum(r[name]['correct'] for r in charts if r['kind'] == k)}/"
                      f"{sum(r['kind'] == k for r in charts)}"
                   for k in ("classic", "mini", "passport")}
        wrong = sum(r[name]["answered"] and not r[name]["correct"] for r in charts)
        none = [r for r in rows if r["kind"] == "none"]
        sg = [r for r in rows if r["kind"] == "sg"]
        big = [r[name]["seconds"] for r in rows if r["conditions"]["width"] *
               r["conditions"]["height"] >= 10e6]
        times = [r[name]["seconds"] for r in rows]
        cpu_big = [r[name]["cpu_seconds"] for r in rows if r["conditions"]["width"] *
                   r["conditions"]["height"] >= 10e6]
        out[name] = {
            "found_correct": sum(r[name]["correct"] for r in charts),
            "charts": len(charts),
            "by_kind": by_kind,
            "answered_wrongly": wrong,
            "false_positives": sum(r[name]["answered"] for r in none),
            "no_chart_images": len(none),
            "sg_answered": sum(r[name]["answered"] for r in sg),
            "sg_images": len(sg),
            "median_seconds": float(np.median(times)),
            "median_seconds_12mp": float(np.median(big)) if big else None,
            "median_cpu_seconds_12mp": float(np.median(cpu_big)) if cpu_big else None,
            "max_seconds": float(np.max(times)),
        }
    if "mcc" in finders and "fidelity" in finders:
        ratio = [r["fidelity"]["seconds"] / max(r["mcc"]["seconds"], 1e-6) for r in rows]
        out["median_time_ratio_fidelity_over_mcc"] = float(np.median(ratio))
    return out


def table(summary: dict[str, Any], finders: list[str]) -> str:
    lines = ["| finder | found correctly | by kind (classic / mini / passport) | wrong corners "
             "answered | false positives (no chart) | SG answered (must refuse) | median s "
             "| median s, 12 MP | median CPU s, 12 MP | max s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name in finders:
        s = summary[name]
        mp = "-" if s["median_seconds_12mp"] is None else f"{s['median_seconds_12mp']:.2f}"
        cpu = ("-" if s["median_cpu_seconds_12mp"] is None
               else f"{s['median_cpu_seconds_12mp']:.2f}")
        lines.append(
            f"| {name} | {s['found_correct']}/{s['charts']} | {s['by_kind']['classic']} / "
            f"{s['by_kind']['mini']} / {s['by_kind']['passport']} | {s['answered_wrongly']} | "
            f"{s['false_positives']}/{s['no_chart_images']} | {s['sg_answered']}/{s['sg_images']}"
            f" | {s['median_seconds']:.2f} | {mp} | {cpu} | {s['max_seconds']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    from fidelity.core.resources import shared_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="every fifth image")
    ap.add_argument("--seed", type=int, default=19)
    shared = shared_dir()
    ap.add_argument("--coco", type=Path,
                    default=(shared / "coco/val2017") if shared else Path("../shared/coco/val2017"))
    ap.add_argument("--cache", type=Path, default=None,
                    help="folder for the generated images (default: ~/.cache/fidelity/find_chart)")
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parents[1] / "reports/find_chart")
    ap.add_argument("--finders", default="fidelity,mcc,colour-checker-detection")
    args = ap.parse_args()
    key = hashlib.sha256(f"{SCENES_VERSION}-{args.seed}".encode()).hexdigest()[:10]
    cache = args.cache or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / \
        "fidelity" / "find_chart" / key
    records = generate(scene_specs(args.quick), args.coco, cache, args.seed)
    available: dict[str, Finder] = {"fidelity": (_float_srgb, find_fidelity),
                                    "mcc": (_bgr8, find_mcc)}
    if _ccd_available():
        available["colour-checker-detection"] = (_linear, find_ccd)
    finders = {k: available[k] for k in args.finders.split(",") if k in available}
    # warm up imports and OpenCV's first call, so the first image's time is the finder's own
    for prepare, finder in finders.values():
        finder(prepare(np.zeros((64, 64, 3), np.uint8) + 128))
    rows = run(records, finders)
    summary = summarise(rows, list(finders))
    text = table(summary, list(finders))
    print(text)
    if "median_time_ratio_fidelity_over_mcc" in summary:
        print(f"median time ratio fidelity / mcc per image: "
              f"{summary['median_time_ratio_fidelity_over_mcc']:.2f}")
    args.out.mkdir(parents=True, exist_ok=True)
    name = "results-quick" if args.quick else "results"
    write_json_atomic(args.out / f"{name}.json", {
        "benchmark": "chart finding on COCO photos with composited charts",
        "quick": args.quick, "seed": args.seed, "scenes_version": SCENES_VERSION,
        "counts": {k: sum(r["kind"] == k for r in rows) for k in COUNTS},
        "summary": summary, "images": rows,
        "machine": {**machine_info(), "opencv": _opencv_version()},
        "load_average": os.getloadavg()})
    write_text_atomic(args.out / f"{name.replace('results', 'table')}.md", text)
    print(f"wrote {args.out / (name + '.json')}")


if __name__ == "__main__":
    main()
