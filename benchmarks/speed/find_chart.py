"""Finding the chart in photos: fidelity's cascade against OpenCV's mcc detector and
colour-checker-detection's segmentation, side by side on the same images.

Images (:mod:`tests.fixtures.chart_photos`, seeded, generated into a cache folder, never
committed): real COCO val2017 photos as backgrounds (``coco``; default ``$FIDELITY_SHARED/coco/val2017``
or ``../shared``), resized to 640, 1600 or 4000 px on the long side (4000 x 3000 = 12 MP), with
a rendered chart (patch colours from :func:`fidelity.camera.render.render_chart` for several
cameras and illuminants) composited in perspective at many sizes, turns and tilts, under
coloured light, with exposure from dark to clipped, shading, blur, noise, partial occlusion and
JPEG compression: 60 classic charts, 25 minis (smaller), 20 Passports (two charts side by side,
one 24-patch), 6 SG-like 140-patch charts that must be refused, and 20 images with no chart.
``quick`` takes every fifth image.

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

Also writes ``table.md`` (``table-quick.md``) under ``reports/find_chart``.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from fidelity.colour import colorimetry as cm
from fidelity.core.fileio import write_text_atomic
from tests.fixtures.chart_photos import COUNTS, SCENES_VERSION, cache_folder, generate, scene_specs
from tests.fixtures.chart_scenes import corners_correct, decode_jpeg

ANCHOR = ("OpenCV's mcc detector (cv2.mcc, MCC24) and colour-checker-detection's segmentation "
          "when installed, on the same decoded photos")
PARAMETERS = {"quick": Parameter(False, "every fifth image"),
              "seed": Parameter(19, "the photo set's seed"),
              "coco": Parameter(None, "folder of COCO JPEGs (default: the shared val2017)"),
              "cache": Parameter(None, "folder of the generated images (default under ~/.cache)"),
              "finders": Parameter("fidelity,mcc,colour-checker-detection", "finders to run")}
QUICK = {"quick": True}
NEEDS = ("shared",)
ARTEFACTS = "reports/find_chart"

#: Aspect ratios of a chart that colour-checker-detection accepts: fidelity's former setting
#: (its default, 1.35-1.65, loses almost every chart seen in perspective).
CCD_ASPECT_RATIO = (1.1, 2.0)

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


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    coco = Path(ctx["coco"]) if ctx["coco"] else (
        shared / "coco/val2017" if shared else Path("../shared/coco/val2017"))
    seed, quick = ctx["seed"], ctx["quick"]
    cache = Path(ctx["cache"]) if ctx["cache"] else cache_folder(seed)
    records = generate(scene_specs(quick), coco, cache, seed)
    available: dict[str, Finder] = {"fidelity": (_float_srgb, find_fidelity),
                                    "mcc": (_bgr8, find_mcc)}
    if _ccd_available():
        available["colour-checker-detection"] = (_linear, find_ccd)
    finders = {k: available[k] for k in ctx["finders"].split(",") if k in available}
    # warm up imports and OpenCV's first call, so the first image's time is the finder's own
    for prepare, finder in finders.values():
        finder(prepare(np.zeros((64, 64, 3), np.uint8) + 128))
    rows = run(records, finders)
    summary = summarise(rows, list(finders))
    ctx.log(table(summary, list(finders)))
    return {"benchmark": "chart finding on COCO photos with composited charts",
            "quick": quick, "seed": seed, "scenes_version": SCENES_VERSION,
            "counts": {k: sum(r["kind"] == k for r in rows) for k in COUNTS},
            "opencv": _opencv_version(), "summary": summary, "images": rows}


def cases(details: dict[str, Any]) -> list[Case]:
    s = details["summary"]
    finders = [k for k in s if isinstance(s[k], dict)]
    n = len(details["images"])
    big = sum(r["conditions"]["width"] * r["conditions"]["height"] >= 10e6
              for r in details["images"])
    out = []
    for anchor in (f for f in finders if f != "fidelity"):
        ours, other = s["fidelity"], s[anchor]

        def words(x: dict[str, Any]) -> str:
            return (f"{x['found_correct']}/{x['charts']} found correctly, "
                    f"{x['answered_wrongly']} wrong, {x['false_positives']}/"
                    f"{x['no_chart_images']} false positives")

        note = f"fidelity {words(ours)}; {anchor} {words(other)}"
        given = ({"wall": s["median_time_ratio_fidelity_over_mcc"],
                  "of": "median of the per-image ratios"}
                 if anchor == "mcc" and "median_time_ratio_fidelity_over_mcc" in s else {})
        out.append(case(f"every photo, against {anchor}",
                        figures("fidelity find_chart", ours["median_seconds"]),
                        figures(anchor, other["median_seconds"]), per="image",
                        statistic=f"median over {n} photos, one run each", note=note, **given))
        if ours["median_seconds_12mp"] is not None and other["median_seconds_12mp"] is not None:
            out.append(case(f"12 MP photos, against {anchor}",
                            figures("fidelity find_chart", ours["median_seconds_12mp"],
                                    cpu_s=ours["median_cpu_seconds_12mp"]),
                            figures(anchor, other["median_seconds_12mp"],
                                    cpu_s=other["median_cpu_seconds_12mp"]), per="image",
                            statistic=f"median over the {big} photos of 12 MP, one run each"))
    return out


def report(result: dict[str, Any], folder: Path) -> None:
    """``table.md`` (``table-quick.md`` of a quick run): each finder's scores and times."""
    d = result["details"]
    finders = [k for k in d["summary"] if isinstance(d["summary"][k], dict)]
    name = "table-quick.md" if d["quick"] else "table.md"
    write_text_atomic(folder / name, table(d["summary"], finders))
