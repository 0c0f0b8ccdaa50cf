"""Before and after per cell: two ``tables.json`` of the same sweep grid, for the detectors
whose recorded preprocessing differs between them (issue 32 req 4: the final before/after of
the re-measured tables).

Per re-measured detector and (transform, ΔE) cell done in both: ΔmAP in points before and
after, the change, each side's paired SE (5 image folds) and the change in units of the
after-SE; per ΔE the worst case (what the prediction table uses) before and after. Both sides
are the same images, so the two ΔmAPs are correlated and the change is not tested against a
combined SE: it is set beside each side's own SE.

Usage: python -m benchmarks.tools.compare_tables BEFORE.json AFTER.json --out reports/coco/NAME
       (writes NAME.md and NAME.json; BEFORE from git: git show REV:reports/coco/tables.json)
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fidelity.coco.tables.build import Tables
from fidelity.coco.tables.colour import TablesResult
from fidelity.coco.tables.grid import CellDelta


def _tables(path: Path) -> Tables:
    return TablesResult.from_json(json.loads(path.read_text(encoding="utf-8"))).tables


def _preprocess(t: Tables, model: str) -> str | None:
    conv = t.models[model].settings.get("conventions") or {}
    return conv.get("preprocess")


def _se(r: CellDelta) -> float | None:
    return r.errors.dmap_points if r.errors is not None else None


def _se_methods(rows: list[CellDelta]) -> list[str]:
    """The SE estimators of ``rows`` (keys of ``STANDARD_ERROR_WORDS``), most frequent first."""
    from collections import Counter

    return [str(m) for m, _ in Counter(r.errors.method for r in rows
                                       if r.errors is not None).most_common()]


def _se_words(methods: list[str]) -> str:
    from fidelity.coco.tables.provenance import STANDARD_ERROR_WORDS

    return " / ".join(STANDARD_ERROR_WORDS.get(m, m) for m in methods) or "none"


def compare(before: Tables, after: Tables) -> dict[str, Any]:
    """The per-cell and worst-case comparison of the re-measured detectors (JSON-ready)."""
    models = [m for m in after.models if m in before.models
              and _preprocess(before, m) != _preprocess(after, m)]
    out: dict[str, Any] = {"models": {}}
    for m in models:
        old = {(r.transform, r.delta_e): r for r in before.cells[m] if r.done}
        cells = []
        for r in after.cells[m]:
            o = old.get((r.transform, r.delta_e))
            if not r.done or o is None or r.dmap_points is None or o.dmap_points is None:
                continue
            change = r.dmap_points - o.dmap_points
            se = _se(r)
            cells.append({"transform": r.transform, "delta_e": r.delta_e,
                          "before": o.dmap_points, "after": r.dmap_points, "change": change,
                          "se_before": _se(o), "se_after": se,
                          "change_in_se": change / se if se else None})
        worst = []
        wb = {w.delta_e: w for w in before.worst_case[m]}
        for w in after.worst_case[m]:
            b = wb.get(w.delta_e)
            if w.delta_e == 0 or b is None or w.dmap_points is None or b.dmap_points is None:
                continue
            worst.append({"delta_e": w.delta_e, "before": b.dmap_points,
                          "before_transform": b.worst_transform, "after": w.dmap_points,
                          "after_transform": w.worst_transform,
                          "change": w.dmap_points - b.dmap_points,
                          "se_after": w.dmap_points_se, "partial": bool(w.partial)})
        changes = [abs(c["change"]) for c in cells]
        in_se = [abs(c["change_in_se"]) for c in cells if c["change_in_se"] is not None]
        largest = max(cells, key=lambda c: abs(c["change"])) if cells else None
        out["models"][m] = {
            "preprocessing_before": _preprocess(before, m),
            "preprocessing_after": _preprocess(after, m),
            "baseline_map_before": before.models[m].baseline_map,
            "baseline_map_after": after.models[m].baseline_map,
            "images": after.models[m].images,
            "se_before": _se_methods([r for r in before.cells[m] if r.done]),
            "se_after": _se_methods([r for r in after.cells[m] if r.done]),
            "cells": cells, "worst_case": worst,
            "summary": {
                "cells": len(cells),
                "median_abs_change": statistics.median(changes) if changes else None,
                "largest_change": largest,
                "beyond_2_se": sum(x > 2 for x in in_se),
                "beyond_1_se": sum(x > 1 for x in in_se),
                "largest_worst_case_change": max((abs(w["change"]) for w in worst),
                                                 default=None),
            },
        }
    return out


def markdown(result: dict[str, Any], before: str, after: str) -> str:
    lines = ["# Before and after the preprocessing change, per cell\n",
             f"Generated by `python -m benchmarks.tools.compare_tables {before} {after}`: ΔmAP in "
             "points of mAP@[.50:.95] (100 × (baseline − cell)) with the detector preprocessing "
             "before issue 24 (before) and this version's (after), same images, same ONNX "
             "models. SE: each side's standard error of ΔmAP as its tables state it (the "
             "estimator is named per detector); the two sides share their images, so their "
             "difference is set beside the after-SE, not tested against a combined one.\n"]
    for m, d in result["models"].items():
        s = d["summary"]
        big = s["largest_change"]
        lines += [f"## {m} ({d['images']} images)\n",
                  f"- preprocessing before: {d['preprocessing_before']}",
                  f"- preprocessing after: {d['preprocessing_after']}",
                  f"- baseline mAP {d['baseline_map_before']:.4f} → "
                  f"{d['baseline_map_after']:.4f}",
                  f"- SE before: {_se_words(d['se_before'])}",
                  f"- SE after: {_se_words(d['se_after'])}",
                  f"- {s['cells']} cells: median |change| {s['median_abs_change']:.3f} points; "
                  f"largest {big['change']:+.3f} ({big['transform']} ΔE {big['delta_e']:g}: "
                  f"{big['before']:.3f} → {big['after']:.3f}); beyond 1 after-SE "
                  f"{s['beyond_1_se']}, beyond 2 after-SE {s['beyond_2_se']}",
                  f"- worst case per ΔE (the prediction table's points): largest |change| "
                  f"{s['largest_worst_case_change']:.3f} points\n",
                  "| ΔE | worst before | worst after | change | SE after |",
                  "|---:|---|---|---:|---:|"]
        for w in d["worst_case"]:
            se = "" if w["se_after"] is None else f"{w['se_after']:.2f}"
            lines.append(f"| {w['delta_e']:g} | {w['before']:.3f} ({w['before_transform']}) | "
                         f"{w['after']:.3f} ({w['after_transform']}) | {w['change']:+.3f} | "
                         f"{se} |")
        lines += ["", "| transform | ΔE | before | after | change | SE before | SE after | "
                      "change / SE after |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for c in sorted(d["cells"], key=lambda c: (c["transform"], c["delta_e"])):
            def f(v: float | None, nd: int = 2) -> str:
                return "" if v is None else f"{v:.{nd}f}"
            lines.append(f"| {c['transform']} | {c['delta_e']:g} | {c['before']:.3f} | "
                         f"{c['after']:.3f} | {c['change']:+.3f} | {f(c['se_before'])} | "
                         f"{f(c['se_after'])} | {f(c['change_in_se'])} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def before_after_main(doc: str | None, read: Callable[[Path], Any],
                      compare_: Callable[[Any, Any], dict[str, Any]],
                      markdown_: Callable[[dict[str, Any], str, str], str]) -> None:
    """The command line of a before/after comparison: BEFORE AFTER --out NAME, each side read
    with ``read``, NAME.json and NAME.md written."""
    ap = argparse.ArgumentParser(description=(doc or "").split("\n\n")[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="NAME: writes NAME.md, NAME.json")
    a = ap.parse_args()
    result = compare_(read(a.before), read(a.after))
    a.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    a.out.with_suffix(".md").write_text(markdown_(result, str(a.before), str(a.after)))
    print(a.out.with_suffix(".md"))


def main() -> None:
    before_after_main(__doc__, _tables, compare, markdown)


if __name__ == "__main__":
    main()
