"""The chart finder on the hard kinds of photo, fidelity against OpenCV's mcc detector.

Images (:mod:`tests.fixtures.hard_scenes`, seeded, made in memory, never committed): real COCO
val2017 photos as backgrounds with a 24-patch chart composited in perspective and one hazard
each (``per_hazard`` images of each): ``distractors`` (tiles on the chart's own grid or not,
a checkerboard, a grey card beside it), ``occluder`` (a leaf or hand with the photo's texture
over two neighbouring patches; more when it reaches over) and ``isp`` (CLAHE local tone mapping
and unsharp-mask halos on a 1920 x 1080 frame). JPEG quality 85.

Scoring, per finder: found correctly (the four corner patch centres within half a pitch of the
truth), answered wrongly (corners more than half a pitch off: must be 0), refused, and the
corner error in patch pitches of the answers; for fidelity also the covered patches left out
against the truth (a patch whose central half-pitch window is more than a tenth covered):
left out, missed (of them, flagged: far from what the other patches predict but flat, so
measured and named in a note, ``FoundChart.flat_off_fit``), and clear patches left out. Time: wall time of each finder on the
same decoded pixels, as in :mod:`benchmarks.speed.find_chart`.

Also writes ``hard-table.md`` under ``reports/find_chart``.
"""

from __future__ import annotations

import glob
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.speed.find_chart import _opencv_version, find_mcc
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from fidelity.colour import colorimetry as cm
from fidelity.core.fileio import write_text_atomic
from tests.fixtures.chart_scenes import corners_correct
from tests.fixtures.hard_scenes import HAZARDS, hard_scene

ANCHOR = "OpenCV's mcc detector (cv2.mcc, MCC24) on the same decoded photos"
PARAMETERS = {"per_hazard": Parameter(20, "photos of each hazard"),
              "seed": Parameter(23, "the photos' seed"),
              "coco": Parameter(None, "folder of COCO JPEGs (default: the shared val2017)")}
QUICK = {"per_hazard": 2}
NEEDS = ("shared",)
ARTEFACTS = "reports/find_chart"


def _fidelity(pixels: np.ndarray) -> tuple[np.ndarray | None, tuple[int, ...],
                                            tuple[int, ...], str]:
    from fidelity.chart.find import find_chart
    from fidelity.core.errors import FidelityError

    try:
        found = find_chart(pixels, encoding="srgb")
    except FidelityError as exc:
        return None, (), (), str(exc).split(":")[0][:80]
    return found.corners, found.occluded, found.flat_off_fit, ""


def run(per_hazard: int, seed: int, coco: Path) -> list[dict[str, Any]]:
    from fidelity.camera.render import render_chart

    files = sorted(glob.glob(str(coco / "*.jpg")))
    if len(files) < 50:
        sys.exit(f"find_hard: need COCO photos in {coco} (found {len(files)})")
    renders = [cm.linearize_srgb(np.clip(render_chart(c, i).measurement.srgb, 0.0, 1.0))
               for c, i in (("ideal", "D65"), ("nikon-5100", "D65"), ("nikon-5100", "A"),
                            ("sigma-sdmerrill", "F11"))]
    order = np.random.default_rng(seed).permutation(len(files))
    rows = []
    n = 0
    for hazard in HAZARDS:
        for k in range(per_hazard):
            scene = hard_scene(hazard, files[order[n % len(files)]], renders[n % len(renders)],
                               seed=(seed, n))
            n += 1
            truth = scene.corners
            assert truth is not None
            row: dict[str, Any] = {"hazard": hazard, "index": k,
                                   "conditions": scene.conditions}
            pixels = scene.srgb.astype(np.float32) / np.float32(255.0)
            t0 = time.perf_counter()
            corners, occluded, flat, why = _fidelity(pixels)
            seconds = time.perf_counter() - t0
            bgr8 = np.ascontiguousarray(scene.srgb[..., ::-1])
            t1 = time.perf_counter()
            try:
                mcc = find_mcc(bgr8)
            except Exception:  # noqa: BLE001 - the anchor's crash counts as not found
                mcc = None
            mcc_seconds = time.perf_counter() - t1
            for name, found, secs in (("fidelity", corners, seconds), ("mcc", mcc, mcc_seconds)):
                res: dict[str, Any] = {"seconds": round(secs, 4), "answered": found is not None,
                                       "correct": corners_correct(found, truth, scene.pitch_px)}
                if found is not None:
                    res["error_pitch"] = round(float(np.linalg.norm(
                        np.asarray(found) - truth, axis=-1).max() / scene.pitch_px), 4)
                row[name] = res
            row["fidelity"]["refused_because"] = why
            covered = {int(v) for v in str(scene.conditions.get("occluded", "")).split(",") if v}
            row["fidelity"]["occluded"] = list(occluded)
            row["fidelity"]["flat_off_fit"] = list(flat)
            row["occluded_truth"] = sorted(covered)
            rows.append(row)
            if sys.stderr.isatty():
                print(f"\r{n}/{per_hazard * len(HAZARDS)} {hazard}", end="", file=sys.stderr)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    return rows


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for hazard in HAZARDS:
        part = [r for r in rows if r["hazard"] == hazard]
        out[hazard] = {}
        for name in ("fidelity", "mcc"):
            errs = [r[name]["error_pitch"] for r in part if r[name]["correct"]]
            out[hazard][name] = {
                "images": len(part),
                "found_correct": sum(r[name]["correct"] for r in part),
                "answered_wrongly": sum(r[name]["answered"] and not r[name]["correct"]
                                        for r in part),
                "refused": sum(not r[name]["answered"] for r in part),
                "median_error_pitch": float(np.median(errs)) if errs else None,
                "max_error_pitch": float(np.max(errs)) if errs else None,
                "median_seconds": float(np.median([r[name]["seconds"] for r in part])),
            }
        found = [r for r in part if r["fidelity"]["correct"]]
        truth = sum(len(r["occluded_truth"]) for r in found)
        named = sum(len(set(r["fidelity"]["occluded"]) & set(r["occluded_truth"]))
                    for r in found)
        false = sum(len(set(r["fidelity"]["occluded"]) - set(r["occluded_truth"]))
                    for r in found)
        flagged = sum(len((set(r["fidelity"].get("flat_off_fit", ())) & set(r["occluded_truth"]))
                          - set(r["fidelity"]["occluded"])) for r in found)
        out[hazard]["fidelity"]["occluded"] = {
            "covered_patches": truth, "named": named, "missed": truth - named,
            "flagged_flat": flagged,
            "clear_patches_named": false,
            "images_exactly_named": sum(set(r["fidelity"]["occluded"]) ==
                                        set(r["occluded_truth"]) for r in found)}
    return out


def table(summary: dict[str, Any]) -> str:
    lines = ["| hazard | finder | found correctly | wrong corners answered | refused | median "
             "/ max corner error (pitch) | covered patches left out (missed, of them flagged flat; "
             "clear left out) | "
             "median s |", "|---|---|---|---|---|---|---|---|"]
    for hazard, per in summary.items():
        for name, s in per.items():
            err = ("-" if s["median_error_pitch"] is None
                   else f"{s['median_error_pitch']:.3f} / {s['max_error_pitch']:.3f}")
            occ = s.get("occluded")
            occ_text = (f"{occ['named']}/{occ['covered_patches']} ({occ['missed']}, of "
                        f"them {occ.get('flagged_flat', 0)} flagged flat; "
                        f"{occ['clear_patches_named']})" if occ else "-")
            lines.append(f"| {hazard} | {name} | {s['found_correct']}/{s['images']} | "
                         f"{s['answered_wrongly']} | {s['refused']} | {err} | {occ_text} | "
                         f"{s['median_seconds']:.2f} |")
    return "\n".join(lines) + "\n"


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    coco = Path(ctx["coco"]) if ctx["coco"] else (
        shared / "coco/val2017" if shared else Path("../shared/coco/val2017"))
    find_mcc(np.zeros((64, 64, 3), np.uint8) + 128)  # warm up OpenCV's first call
    rows = run(ctx["per_hazard"], ctx["seed"], coco)
    summary = summarise(rows)
    ctx.log(table(summary))
    return {"benchmark": "chart finding on hard photos (distractors, occluders, ISP look)",
            "per_hazard": ctx["per_hazard"], "seed": ctx["seed"], "opencv": _opencv_version(),
            "summary": summary, "images": rows}


def cases(details: dict[str, Any]) -> list[Case]:
    out = []
    for hazard, per in details["summary"].items():
        ours, mcc = per["fidelity"], per["mcc"]
        out.append(case(
            hazard, figures("fidelity find_chart", ours["median_seconds"]),
            figures("OpenCV mcc", mcc["median_seconds"]), per="image",
            statistic=f"median over {ours['images']} photos, one run each",
            note=(f"found correctly: fidelity {ours['found_correct']}/{ours['images']} "
                  f"({ours['answered_wrongly']} wrong), mcc {mcc['found_correct']}/"
                  f"{mcc['images']} ({mcc['answered_wrongly']} wrong)")))
    return out


def report(result: dict[str, Any], folder: Path) -> None:
    """``hard-table.md``: each hazard's scores and times."""
    write_text_atomic(folder / "hard-table.md", table(result["details"]["summary"]))
