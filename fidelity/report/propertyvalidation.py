"""The property validation as a report: ``properties.md``, ``properties.html``, ``properties.json``.

Renders :class:`fidelity.coco.validate.properties.PropertyResults`: does the loss a verdict
predicts for a camera with a lens and a sensor (colour, sharpness and noise combined) bound
the loss measured on COCO with the camera emulated, per group of properties and loss column,
by how much it over-predicts, every cell it misses by name with its standard error, and how
the combination rules compare. Every sentence is written from the numbers it states.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fidelity.coco.loss import LOSS_COLUMNS
from fidelity.coco.validate.properties import (
    RULES,
    SHIPPED_RULE,
    TARGET_COVERAGE,
    TARGET_RATIO,
    PropertyResults,
)
from fidelity.core.fileio import write_json_atomic
from fidelity.report.document import Document, Headline, Section, Text, Tone, section, table
from fidelity.report.format import number
from fidelity.report.html import write_document

__all__ = ["RULE_WORDS", "TITLE", "property_document", "write_property_report"]

TITLE = "Validation of the sharpness and noise verdict on COCO"

#: How each combination rule reads.
RULE_WORDS: Mapping[str, str] = {
    SHIPPED_RULE: "sum + sqrt(l_sharpness l_noise)",
    "sum": "sum",
    "probabilistic": "1 − Π(1 − l)",
    "max": "max",
}
_COLUMN_WORDS = {"dmap_points": "ΔmAP (points)", "dmap_relative": "ΔmAP (% of baseline)",
                 "dap_person_points": "ΔAP person (points)",
                 "dap_bicycle_points": "ΔAP bicycle (points)"}


def _cells(n: int) -> str:
    return f"{n} cell" if n == 1 else f"{n} cells"


def _share(s: Mapping[str, Any]) -> str:
    return "–" if s["share_within"] is None else f"{100 * s['share_within']:.1f} %"


def _ratio(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f}×"


def _yes(v: bool) -> str:
    return "yes" if v else "**no**"


def _rules_words(column: str, s: Mapping[str, Any]) -> str:
    rules = s["rules"]
    n = s["joint_cells"]
    if not n:
        return "No cell degrades two or more properties: the rules are not compared."
    best = s["best_rule"]
    shipped = rules[SHIPPED_RULE]
    parts = [f"On the {n} cells that degrade two or more properties, the shipped rule "
             f"({RULE_WORDS[SHIPPED_RULE]}) bounds {shipped['within']} of {shipped['cells']} "
             f"({_share(shipped)}) with a median over-prediction of "
             f"{_ratio(shipped['median_ratio'])}."]
    if best is None:
        parts.append(f"No rule bounds {100 * TARGET_COVERAGE:.0f} % of them.")
    elif best == SHIPPED_RULE:
        parts.append(f"It is the rule that bounds at least {100 * TARGET_COVERAGE:.0f} % of "
                     "them with the least over-prediction.")
    else:
        b = rules[best]
        parts.append(f"The rule that bounds at least {100 * TARGET_COVERAGE:.0f} % of them with "
                     f"the least over-prediction is **{RULE_WORDS[best]}**: {b['within']} of "
                     f"{b['cells']} ({_share(b)}), median {_ratio(b['median_ratio'])}, so the "
                     "shipped rule is not the best on these data; the verdict keeps it (a "
                     "change of rule needs its own test).")
    low = [k for k in RULES if rules[k]["share_within"] is not None
           and rules[k]["share_within"] < TARGET_COVERAGE]
    if low:
        parts.append("Below the target: " + "; ".join(
            f"{RULE_WORDS[k]} {rules[k]['within']} of {rules[k]['cells']} ({_share(rules[k])})"
            for k in low) + ".")
    return " ".join(parts)


def headline(results: PropertyResults) -> Headline:
    """Does the verdict's combined loss bound the measured loss (ΔmAP points), overall and
    per group, and which combination rule bounds best."""
    if not results.rows:
        return Headline("No finished (camera, model) cell yet: nothing to compare.", "info")
    s = results.summary["dmap_points"]
    a = s["all"]
    lines = [f"**Does the loss a verdict predicts bound the loss measured on COCO?** "
             f"(ΔmAP in points, {len(results.cameras)} cameras, {a['cells']} cells)", "",
             f"- All cells: within the bound in **{a['within']} of {a['cells']}** "
             f"({_share(a)}; {a['within_2se']} up to 2 SE); median over-prediction "
             f"**{_ratio(a['median_ratio'])}** over the {a['cells_above_zero']} cells measured "
             f"above 0 ({_ratio(a['median_ratio_2se'])} over the {a['cells_above_2se']} "
             f"measured more than 2 SE above 0). Target (≥ {100 * TARGET_COVERAGE:.0f} % within, "
             f"median ≤ {TARGET_RATIO:g}×) met: {_yes(a['meets_target'])}."]
    for g, gs in s["groups"].items():
        lines.append(f"- {g}: {gs['within']} of {gs['cells']} ({_share(gs)}), median "
                     f"{_ratio(gs['median_ratio'])} ({_cells(gs['cells_above_zero'])} above 0); "
                     f"target met: {_yes(gs['meets_target'])}.")
    lines.append(f"- Combination: {_rules_words('dmap_points', s)}")
    misses = a["misses"]
    if misses:
        near = sum(bool(m["within_2se"]) for m in misses)
        lines.append(f"- Beyond the bound: {_cells(len(misses))} ({near} of them within 2 SE), "
                     + ", ".join(f"{m['camera']} / {m['model']} (by {m['excess']:.2f}, SE "
                                 f"{number(m['se'])})" for m in misses) + ".")
    tone: Tone = "pass" if a["meets_target"] else (
        "fail" if a["share_within"] is not None and a["share_within"] < TARGET_COVERAGE
        else "info")
    return Headline("\n".join(lines), tone)


def _group_section(results: PropertyResults) -> Section:
    body = []
    for column in LOSS_COLUMNS.values():
        s = results.summary[column]
        for g, gs in [("all", s["all"]), *s["groups"].items()]:
            cams = len({r.camera for r in results.rows
                        if g == "all" or ("+".join(r.group) or "none") == g})
            body.append([_COLUMN_WORDS[column], g, str(cams), f"{gs['within']}/{gs['cells']}",
                         f"{gs['within_2se']}/{gs['cells']}", _share(gs),
                         f"{_ratio(gs['median_ratio'])} ({gs['cells_above_zero']})",
                         f"{_ratio(gs['median_ratio_2se'])} ({gs['cells_above_2se']})",
                         number(gs["median_predicted"]), number(gs["median_measured"]),
                         _yes(gs["meets_target"])])
    return section(
        "The verdict's bound, per group of properties",
        Text("A camera's group names the properties it degrades: `sharpness` (it has optics), "
             "`noise` (sensor noise), `colour` (its chart ΔE00 is at least "
             f"{results.to_json()['colour_error_delta_e']:g}). The predicted loss is the "
             "verdict's combined loss of `fidelity check --camera FILE --size n`; the median "
             "over-prediction is predicted / measured over the cells measured above 0 (their "
             "count in brackets), then over those measured more than 2 SE above 0."),
        table(["loss", "group", "cameras", "within", "within 2 SE", "share within",
               "median over-prediction (n)", "same, cells > 2 SE (n)", "median predicted",
               "median measured", "target met"], body))


def _rules_section(results: PropertyResults) -> Section:
    body = []
    texts = []
    for column in LOSS_COLUMNS.values():
        s = results.summary[column]
        for rule in RULES:
            rs, ra = s["rules"][rule], s["rules_all_cells"][rule]
            body.append([_COLUMN_WORDS[column],
                         RULE_WORDS[rule] + (" (shipped)" if rule == SHIPPED_RULE else ""),
                         f"{rs['within']}/{rs['cells']}", _share(rs),
                         _ratio(rs["median_ratio"]), _ratio(rs["median_ratio_2se"]),
                         f"{ra['within']}/{ra['cells']}", _ratio(ra["median_ratio"]),
                         "best" if s["best_rule"] == rule else ""])
        texts.append(f"- {_COLUMN_WORDS[column]}: {_rules_words(column, s)}")
    return section(
        "Combination rules",
        Text("The same per-property predictions (colour, sharpness, noise) combined by each "
             "rule, on the cells whose camera degrades two or more properties (then on every "
             "cell). *Best*: the rule that bounds at least "
             f"{100 * TARGET_COVERAGE:.0f} % of those cells with the least median "
             "over-prediction.\n\n" + "\n".join(texts)),
        table(["loss", "rule", "within (joint cells)", "share", "median over-prediction",
               "same, cells > 2 SE", "within (all cells)", "median (all cells)", ""], body))


def _misses_section(results: PropertyResults) -> Section:
    body = []
    for column in LOSS_COLUMNS.values():
        for m in results.summary[column]["all"]["misses"]:
            body.append([m["camera"], m["model"], _COLUMN_WORDS[column], number(m["predicted"]),
                         number(m["measured"]), number(m["se"]), number(m["excess"]),
                         "yes" if m["within_2se"] else "**no**"])
    if not body:
        return section("Cells beyond the bound", Text("None: every cell is within the bound."))
    return section(
        "Cells beyond the bound",
        Text(f"{len(body)} (cell, loss) pairs measured above the verdict's combined loss, by "
             "camera, with the standard error of the measured loss (the larger of the paired "
             "image bootstrap and the jackknife)."),
        table(["camera", "model", "loss", "predicted", "measured", "SE", "excess",
               "within 2 SE"], body))


def _cameras_section(results: PropertyResults) -> Section:
    models = sorted({r.model for r in results.rows})
    cells = {(r.camera, r.model): r for r in results.rows}
    body = []
    for name, c in sorted(results.cameras.items()):
        p = c.parts["dmap_points"]
        snr = "noiseless" if c.snr is not None and c.snr == float("inf") else number(c.snr, 1)
        row = [name, "+".join(c.group) or "none", number(c.chart_delta_e), number(c.mtf50, 3),
               snr, number(p.get("colour")), number(p.get("sharpness")), number(p.get("noise")),
               number(c.combined["dmap_points"]), c.dominant]
        for m in models:
            r = cells.get((name, m))
            row.append("–" if r is None else
                       f"{number(r.measured['dmap_points'])} ± {number(r.se['dmap_points'])}"
                       + ("" if r.bound["dmap_points"].within in (True, None) else " **miss**"))
        body.append(row)
    return section(
        "Per camera (ΔmAP, points)",
        Text("The chart's values at the detector's input (MTF50 in cy/px, SNR at 18 % grey), "
             "the verdict's loss per property and combined, and the loss measured per model "
             "(± SE)."),
        table(["camera", "group", "chart ΔE00", "MTF50", "SNR", "colour", "sharpness", "noise",
               "combined", "dominant", *models], body))


def _run_section(results: PropertyResults) -> Section:
    base = [[m, number(100 * float(b["map"])), str(b["images"])]
            for m, b in results.baselines.items()]
    meta = results.meta
    models = ", ".join(f"{m['model']} on {m['images']} images"
                       for m in meta.get("models_run") or ())
    return section(
        "Baselines and run",
        Text(f"Models: {models or '–'}. Each camera is emulated on COCO with its colour "
             "mapping, its lens's PSF in linear light and its Poisson-Gaussian sensor noise on "
             "the raw signal (`fidelity.coco.imaging`), then the sweep's JPEG round trip."),
        table(["model", "baseline mAP (%)", "images"], base))


def property_document(results: PropertyResults) -> Document:
    """The report of ``results`` (module docstring)."""
    sections = [_group_section(results), _rules_section(results), _misses_section(results),
                _cameras_section(results), _run_section(results)]
    return Document(TITLE, headline(results), tuple(sections),
                    subtitle="Generated by `fidelity validate --properties` "
                             "(fidelity/coco/validate/properties.py) from the results store; "
                             "every number is computed from stored detections and the camera "
                             "files' chart renders.")


def write_property_report(results: PropertyResults, out_dir: str | os.PathLike[str]
                          ) -> list[Path]:
    """Write ``properties.md``, ``properties.html`` and ``properties.json`` into ``out_dir``
    (atomically); returns the paths written."""
    out = Path(out_dir)
    written = write_document(property_document(results), html=out / "properties.html",
                             markdown=out / "properties.md")
    written.append(write_json_atomic(out / "properties.json", results.to_json()))
    return written

