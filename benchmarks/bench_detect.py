"""Benchmark: the accuracy of the chart's corners (fidelity.chart.find): the search's fit alone
against the fit refined at full size, on synthetic scenes with known geometry.

Synthetic scenes with known geometry (the test suite's cases: frontal, tilted with perspective,
upside down, a quarter turn in a portrait image, mirrored, small), each with three cameras: the
reference colours, a contrast-inc camera and a desaturating one (ΔE of several units). For each
the corner error (largest distance of a corner-patch centre from the truth, in % of the patch
pitch) and the time, best of N, of

- anchor: the cascade's search fit alone (``refine=False``: the verified placement of the
  candidate, at the search's reduced size), and
- fidelity: the same, refined at full size by fitting the grid to the patch outlines.

(Finding charts in photos, against OpenCV's mcc and colour-checker-detection:
``benchmarks/bench_find_chart.py``.)

Also the time of the audit itself with given corners, so the cost of not typing them shows.
Writes reports/benchmarks/detect.json.  Run:  python -m benchmarks.bench_detect [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks.machine import best_time, machine_info
from fidelity.chart.find import find_chart
from fidelity.colour import colorimetry as cm
from fidelity.core.fileio import write_json_atomic
from fidelity.measure.pixels import measure_pixels
from fidelity.prediction.transforms import apply_transform

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
from test_detect import CASES, CHART, GRID_CORNERS, grid_homography, map_points, scene  # noqa: E402

#: The test suite's scenes, and a small chart in a large frame (tiled search, crop pass).
SCENES = {**CASES, "small in 2400x1800": (grid_homography(30, -0.15, (1900, 500)), (1800, 2400))}

CAMERAS = {"reference": None, "contrast-inc 1.4": ("contrast-inc", 1.4),
           "saturation-dec 0.5": ("saturation-dec", 0.5)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parents[1] / "reports/benchmarks/detect.json")
    args = ap.parse_args()
    rows = []
    print(f"{'case':26s} {'camera':20s} {'anchor err':>10s} {'fidelity err':>12s} "
          f"{'anchor s':>9s} {'fidelity s':>10s} {'audit s':>8s}")
    for case, (h, size) in SCENES.items():
        truth = map_points(h, GRID_CORNERS)
        pitch = float(np.linalg.norm(truth[1] - truth[0]) / 5)
        for camera, transform in CAMERAS.items():
            srgb = apply_transform(CHART.srgb, *transform) if transform else CHART.srgb
            img = scene(h, size, cm.linearize_srgb(np.clip(srgb, 0, 1)))
            anchor = find_chart(img, refine=False)
            ours = find_chart(img)
            err_a = float(np.linalg.norm(anchor.corners - truth, axis=-1).max()) / pitch * 100
            err_o = float(np.linalg.norm(ours.corners - truth, axis=-1).max()) / pitch * 100
            t_a = best_time(lambda img=img: find_chart(img, refine=False), args.repeats)
            t_o = best_time(lambda img=img: find_chart(img), args.repeats)
            t_audit = best_time(lambda img=img, c=truth: measure_pixels(img, c), args.repeats)
            rows.append({"case": case, "camera": camera, "image": f"{size[1]}x{size[0]}",
                         "pitch_px": round(pitch, 2),
                         "corner_error_percent_pitch": {"anchor": round(err_a, 3),
                                                        "fidelity": round(err_o, 3)},
                         "swatches_fitted": ours.swatches, "orientation": ours.orientation,
                         "seconds": {"anchor": t_a, "fidelity": t_o, "audit_given_corners": t_audit}})
            print(f"{case:26s} {camera:20s} {err_a:9.2f}% {err_o:11.2f}% {t_a:9.3f} {t_o:10.3f} "
                  f"{t_audit:8.3f}")
    ea = np.array([r["corner_error_percent_pitch"]["anchor"] for r in rows])
    eo = np.array([r["corner_error_percent_pitch"]["fidelity"] for r in rows])
    ta = np.array([r["seconds"]["anchor"] for r in rows])
    to = np.array([r["seconds"]["fidelity"] for r in rows])
    summary = {"worst_error_percent_pitch": {"anchor": float(ea.max()), "fidelity": float(eo.max())},
               "median_error_percent_pitch": {"anchor": float(np.median(ea)),
                                              "fidelity": float(np.median(eo))},
               "median_time_ratio_fidelity_over_anchor": float(np.median(to / ta))}
    print(f"corner error, % of patch pitch: worst {ea.max():.2f} (anchor) vs {eo.max():.2f} "
          f"(fidelity), median {np.median(ea):.2f} vs {np.median(eo):.2f}; time ratio "
          f"fidelity/anchor {np.median(to / ta):.2f}x (median)")
    write_json_atomic(args.out, {"benchmark": "chart detection on synthetic scenes",
                                 "repeats": args.repeats, "cases": rows, "summary": summary,
                                 "machine": machine_info()})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
