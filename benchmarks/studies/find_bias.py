"""The chart finder's corner error with and without the perspective-bias correction of its last
fit (``fidelity.chart.find.perspective_bias``), side by side on the same images in one run.

Images: the photos of ``benchmarks.speed.find_chart`` (:mod:`tests.fixtures.chart_photos`,
seed 19, every chart image; generated into its cache when missing) and the three synthetic
photos of ``fidelity qualify``'s chart-finder check. "Before" is the same code with the correction set to zero. The error is
the largest distance of the four corner-patch centres from the truth, in patch pitches.

    python -m benchmarks.studies.find_bias [--quick] [--out reports/find_chart]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

import fidelity.chart.find.cascade as find
from benchmarks.machine import machine_info
from fidelity.core.fileio import write_json_atomic, write_text_atomic
from fidelity.pipeline.qualify import FINDER_SCENES, synthetic_photo
from tests.fixtures.chart_photos import cache_folder, generate, scene_specs
from tests.fixtures.chart_scenes import decode_jpeg

CORRECTED = find.perspective_bias


def _uncorrected(h: np.ndarray, cells: np.ndarray, side: float) -> np.ndarray:
    return np.zeros_like(np.asarray(cells, np.float64))


def _error(pixels: np.ndarray, truth: np.ndarray, pitch: float) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for name, bias in (("before", _uncorrected), ("after", CORRECTED)):
        find.perspective_bias = bias  # type: ignore[assignment]
        try:
            corners = find.find_chart(pixels, encoding="srgb").corners
            out[name] = float(np.linalg.norm(corners - truth, axis=-1).max() / pitch)
        except Exception:  # noqa: BLE001 - a chart not found is recorded as None
            out[name] = None
        finally:
            find.perspective_bias = CORRECTED
    return out


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    both = [r for r in rows if r["before"] is not None and r["after"] is not None]
    b = np.array([r["before"] for r in both])
    a = np.array([r["after"] for r in both])
    stat = {k: {"median": float(np.median(v)), "mean": float(np.mean(v)),
                "p90": float(np.percentile(v, 90)), "max": float(np.max(v))}
            for k, v in (("before", b), ("after", a))}
    return {"images": len(rows), "found_by_both": len(both), **stat,
            "after_better": int(np.sum(a < b)), "after_worse": int(np.sum(a > b))}


def main() -> None:
    from fidelity.core.resources import shared_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="every fifth photo")
    shared = shared_dir()
    ap.add_argument("--coco", type=Path, default=(shared / "coco/val2017") if shared
                    else Path("../shared/coco/val2017"))
    ap.add_argument("--out", type=Path, default=Path(__file__).parents[2] / "reports/find_chart")
    args = ap.parse_args()
    records = generate(scene_specs(args.quick), args.coco, cache_folder(19), 19)
    photos = []
    for rec in records:
        if rec["corners"] is None or rec["kind"] == "sg":
            continue
        pixels = decode_jpeg(Path(rec["path"]).read_bytes()).astype(np.float32) / np.float32(255.0)
        photos.append({"index": rec["index"], "kind": rec["kind"],
                       **_error(pixels, np.asarray(rec["corners"]), rec["pitch_px"])})
    synthetic = []
    for k, corners in enumerate(FINDER_SCENES):
        photo, truth, _ = synthetic_photo(corners, seed=7 + k)
        pitch = float(np.linalg.norm(truth[1] - truth[0])) / 5.0
        synthetic.append({"scene": k, "corners": [list(c) for c in corners],
                          **_error(photo.astype(np.float32), truth, pitch)})
    doc = {"benchmark": "chart finder corner error with and without the perspective-bias "
                        "correction (patch pitches)",
           "photos": {"summary": _summary(photos), "rows": photos},
           "synthetic": synthetic, "machine": machine_info()}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "perspective_bias.json", doc)
    s = doc["photos"]["summary"]
    m = doc["machine"]
    lines = ["# The chart finder's perspective-bias correction: before and after", "",
             "`python -m benchmarks.studies.find_bias` (one run, both sides on the same images; "
             f"{m.get('cpu', '?')}, {m.get('cores', '?')} cores). Largest distance of the four "
             "corner-patch centres from the truth, in % of the patch pitch. Before: the last "
             "fit to the patch outlines' centroids; after: refitted to the centroids less the "
             "perspective bias the first fit predicts (`fidelity.chart.find.perspective_bias`)."
             " Photos: every chart image of `benchmarks.speed.find_chart` (seed 19) that both "
             "find; synthetic scenes: those of `fidelity qualify`'s chart-finder check.", "",
             "| images | corner error (% of a pitch) | median | mean | 90th percentile | max |",
             "|---|---|---|---|---|---|"]
    for k in ("before", "after"):
        lines.append(f"| {s['found_by_both']} photos (find_chart, seed 19) | {k} | "
                     f"{100 * s[k]['median']:.2f} | {100 * s[k]['mean']:.2f} | "
                     f"{100 * s[k]['p90']:.2f} | {100 * s[k]['max']:.2f} |")
    for r in synthetic:
        lines.append(f"| synthetic scene {r['scene']} (fidelity qualify) | before / after | "
                     f"{100 * (r['before'] or np.nan):.2f} / {100 * (r['after'] or np.nan):.2f}"
                     " | | | |")
    lines.append(f"\nAfter better on {s['after_better']} photos, worse on {s['after_worse']}.\n")
    write_text_atomic(args.out / "perspective_bias.md", "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
