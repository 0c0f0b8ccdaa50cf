"""The accuracy and cost of the chart's corners (fidelity.chart.find): the fit refined at full
size against the search's fit alone, on synthetic scenes with known geometry.

The scenes are the test suite's (``tests/coco/test_detect.py``: frontal, tilted with perspective,
upside down, a quarter turn in a portrait image, mirrored) and a small chart in a large frame,
each with three cameras: the reference colours, a contrast-inc camera and a desaturating one
(ΔE of several units). For each, the corner error (largest distance of a corner-patch centre
from the truth, in % of the patch pitch) and the time, best of ``repeats``, of the anchor, the
cascade's search fit alone (``refine=False``: the verified placement of the candidate, at the
search's reduced size), and of ours, the same refined at full size by fitting the grid to the
patch outlines; also the time of the audit itself with given corners, so the cost of not
typing them shows. (Finding charts in photos, against OpenCV's mcc: ``find_chart``.)
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from benchmarks.machine import REPO
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import best_time

ANCHOR = "the chart finder's search fit alone (find_chart(refine=False)), the same scenes"
PARAMETERS = {"repeats": Parameter(3, "best of N calls")}
QUICK = {"repeats": 1}

CAMERAS = {"reference": None, "contrast-inc 1.4": ("contrast-inc", 1.4),
           "saturation-dec 0.5": ("saturation-dec", 0.5)}


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.chart.find import find_chart
    from fidelity.colour import colorimetry as cm
    from fidelity.measure.pixels import measure_pixels
    from fidelity.prediction.transforms import apply_transform

    sys.path.insert(0, str(REPO / "tests"))  # test_detect imports its neighbours by name
    from test_detect import CASES, CHART, GRID_CORNERS, grid_homography, map_points, scene

    # the test suite's scenes, and a small chart in a large frame (tiled search, crop pass)
    scenes = {**CASES,
              "small in 2400x1800": (grid_homography(30, -0.15, (1900, 500)), (1800, 2400))}
    repeats = ctx["repeats"]
    rows = []
    for name, (h, size) in scenes.items():
        truth = map_points(h, GRID_CORNERS)
        pitch = float(np.linalg.norm(truth[1] - truth[0]) / 5)
        for camera, transform in CAMERAS.items():
            srgb = apply_transform(CHART.srgb, *transform) if transform else CHART.srgb
            img = scene(h, size, cm.linearize_srgb(np.clip(srgb, 0, 1)))
            anchor = find_chart(img, refine=False)
            ours = find_chart(img)
            err_a = float(np.linalg.norm(anchor.corners - truth, axis=-1).max()) / pitch * 100
            err_o = float(np.linalg.norm(ours.corners - truth, axis=-1).max()) / pitch * 100
            t_a = best_time(lambda img=img: find_chart(img, refine=False), repeats)
            t_o = best_time(lambda img=img: find_chart(img), repeats)
            t_audit = best_time(lambda img=img, c=truth: measure_pixels(img, c), repeats)
            rows.append({"case": name, "camera": camera, "image": f"{size[1]}x{size[0]}",
                         "pitch_px": round(pitch, 2),
                         "corner_error_percent_pitch": {"anchor": round(err_a, 3),
                                                        "fidelity": round(err_o, 3)},
                         "swatches_fitted": ours.swatches, "orientation": ours.orientation,
                         "seconds": {"anchor": t_a, "fidelity": t_o,
                                     "audit_given_corners": t_audit}})
            ctx.log(f"{name:26s} {camera:20s} {err_a:9.2f}% {err_o:11.2f}% {t_a:9.3f} s "
                    f"{t_o:10.3f} s")
    ea = np.array([r["corner_error_percent_pitch"]["anchor"] for r in rows])
    eo = np.array([r["corner_error_percent_pitch"]["fidelity"] for r in rows])
    ta = np.array([r["seconds"]["anchor"] for r in rows])
    to = np.array([r["seconds"]["fidelity"] for r in rows])
    summary = {"worst_error_percent_pitch": {"anchor": float(ea.max()), "fidelity": float(eo.max())},
               "median_error_percent_pitch": {"anchor": float(np.median(ea)),
                                              "fidelity": float(np.median(eo))},
               "median_time_ratio_fidelity_over_anchor": float(np.median(to / ta))}
    return {"benchmark": "chart detection on synthetic scenes", "repeats": repeats,
            "cases": rows, "summary": summary}


def cases(details: dict[str, Any]) -> list[Case]:
    stat = f"best of {details['repeats']}"
    out = []
    for r in details["cases"]:
        err = r["corner_error_percent_pitch"]
        out.append(case(f"{r['case']}, {r['camera']} ({r['image']})",
                        figures("find_chart (refined at full size)", r["seconds"]["fidelity"]),
                        figures("find_chart(refine=False)", r["seconds"]["anchor"]),
                        per="call", statistic=stat,
                        note=(f"corner error {err['fidelity']:.3f} % of a pitch against "
                              f"{err['anchor']:.3f} %; the audit with given corners "
                              f"{r['seconds']['audit_given_corners']:.3f} s")))
    return out
