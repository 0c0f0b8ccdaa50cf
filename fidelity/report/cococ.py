"""The COCO-C report: COCO-C's colour corruptions on the chart ΔE scale, its noise and blur
corruptions on the chart SNR and MTF50 scales.

Built as one :class:`~fidelity.report.document.Document` from
:class:`fidelity.coco.corruptions.CocoCResults` (:func:`cococ_document`) and written as
``cococ.html`` and ``cococ.md`` with ``cococ.json`` and the SVG figures
(:func:`write_cococ_report`). Reading order: the headline (each corruption's chart ΔE over
severities 1-5 and what it costs), the table (chart ΔE, its direction, the classic and the
direction-aware predicted ΔmAP, the measured ΔmAP ± SE per detector), the noise and blur
table (:data:`SPATIAL_SECTION`: the chart SNR or MTF50 ± u, the property table's predicted
ΔmAP ± u, the measured ΔmAP ± SE per detector and whether the prediction bounds it), the
figures, the method and what was run.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.coco.corruptions import PREDICTION_SIZE
from fidelity.coco.spatial import AXIS_LABELS
from fidelity.core.fileio import write_json_atomic
from fidelity.prediction.properties import PROPERTY_TABLES
from fidelity.report import cocofigures as cf
from fidelity.report import document
from fidelity.report.document import (
    Document,
    Figure,
    Headline,
    Section,
    Text,
    section,
    svg_figure,
    table,
)
from fidelity.report.format import number
from fidelity.report.html import write_document

if TYPE_CHECKING:
    from fidelity.coco.corruptions import CocoCResults, CorruptionCell, SpatialCell

#: Title of the report.
TITLE = "COCO-C corruptions on the chart ΔE, MTF50 and SNR scales"
#: Figure file names.
DELTA_E_FIGURE = "cococ-chart-delta-e.svg"
LOSS_FIGURE = "cococ-loss-vs-delta-e.svg"
MTF50_FIGURE = "cococ-loss-vs-mtf50.svg"
SNR_FIGURE = "cococ-loss-vs-snr.svg"
#: Every figure the report may write.
FIGURES = (DELTA_E_FIGURE, LOSS_FIGURE, MTF50_FIGURE, SNR_FIGURE)
#: Title of the noise and blur section.
SPATIAL_SECTION = "Blur and noise corruptions on the MTF50 / SNR scale"


def predictions(cell: CorruptionCell) -> dict[str, float | None]:
    """The cell's recorded predictions (:class:`fidelity.coco.corruptions.CellPrediction`) by
    name; every value None when the cell has none."""
    p = cell.prediction
    if p is None:
        return dict.fromkeys(("classic", "directional", "classic_relative",
                              "directional_relative"))
    return {"classic": p.classic, "directional": p.directional,
            "classic_relative": p.classic_relative,
            "directional_relative": p.directional_relative}


def cococ_figures(results: CocoCResults, preds: Mapping[tuple[str, int], Mapping[str, Any]]
                  ) -> dict[str, Figure]:
    """Every figure by file name (SVG, :mod:`fidelity.report.cocofigures`)."""
    out = {DELTA_E_FIGURE: svg_figure(cf.cococ_delta_e_plot(results), DELTA_E_FIGURE,
                                      "chart ΔE against COCO-C severity",
                                      "Each corruption applied to the calibration chart as an "
                                      "8-bit image; dotted: the chart's own ΔE before any "
                                      "corruption.")}
    if any(c.measured for c in results.cells):
        out[LOSS_FIGURE] = svg_figure(cf.cococ_loss_plot(results, preds), LOSS_FIGURE,
                                      "measured loss against chart ΔE",
                                      "Measured ΔmAP (±2 SE) of each corruption and severity at "
                                      "its chart ΔE, the classic worst-case curve and the "
                                      "direction-aware prediction of each cell.")
    for prop, name, axis in (("sharpness", MTF50_FIGURE, "MTF50"), ("noise", SNR_FIGURE, "SNR")):
        if any(c.measured for c in results.spatial if c.property == prop):
            out[name] = svg_figure(
                cf.cococ_property_plot(results, prop, PREDICTION_SIZE), name,
                f"measured loss against chart {axis}",
                f"Measured ΔmAP (±2 SE) of each {'blur' if prop == 'sharpness' else 'noise'} "
                f"corruption and severity at its chart {axis} (log axis), and the worst case "
                f"of the property table (detector size {PREDICTION_SIZE}) the predictions "
                "read.")
    return out


def _headline(results: CocoCResults, figure: Figure | None) -> Headline:
    lines = ["**COCO-C's colour corruptions, severities 1-5, on the chart ΔE scale:**", ""]
    lines += _severity_lines(
        results.cells, sorted({c.corruption for c in results.cells}), results.models(),
        lambda cells: "chart ΔE " + ", ".join(f"{c.chart_delta_e:.1f}" for c in cells))
    lines += _bound_lines(results)
    lines += _spatial_headline(results)
    return Headline("\n".join(lines), "info", figure)


def _severity_lines(cells: Sequence[Any], names: Sequence[str], models: Sequence[str],
                    chart: Callable[[list[Any]], str]) -> list[str]:
    """One headline line per corruption of ``names``: its ``chart`` values (of its cells in
    severity order) and, where every severity has it, the first model's measured ΔmAP."""
    lines = []
    for name in names:
        ordered = sorted((c for c in cells if c.corruption == name), key=lambda c: c.severity)
        text = f"- {name}: {chart(ordered)}"
        if models:
            got = [c.measured_for(models[0]) for c in ordered]
            if all(g is not None for g in got):
                text += (f"; measured ΔmAP ({models[0]}) "
                         + ", ".join(f"{g.dmap_points:.1f}" for g in got if g is not None))
        lines.append(text + ".")
    return lines


def axis_text(cell: SpatialCell, digits: int | None = None) -> str:
    """``MTF50 0.0755 ± 0.0047`` / ``SNR 3.743 ± 0.019``: the cell's chart value (4 decimals
    for MTF50 in cy/px, 3 for SNR, unless ``digits``)."""
    name = AXIS_LABELS[cell.property][0]
    d = digits if digits is not None else (4 if cell.property == "sharpness" else 3)
    if cell.axis.x is None:
        return f"{name} not measured"
    u = "" if cell.axis.u is None else f" ± {cell.axis.u:.{d}f}"
    return f"{name} {cell.axis.x:.{d}f}{u}"


def _spatial_headline(results: CocoCResults) -> list[str]:
    """The headline's lines on the noise and blur cells: each corruption's chart values over
    severities and how often the property tables' prediction bounds the measured loss."""
    if not results.spatial:
        return []
    lines = ["", "**COCO-C's noise and blur corruptions on the chart SNR and MTF50 scales:**",
             ""]
    def chart(cells: list[Any]) -> str:
        d = 3 if cells[0].property == "sharpness" else 2
        return (f"chart {AXIS_LABELS[cells[0].property][0]} "
                + ", ".join(number(c.axis.x, d) for c in cells))

    lines += _severity_lines(results.spatial,
                             list(dict.fromkeys(c.corruption for c in results.spatial)),
                             results.spatial_models(), chart)
    s = results.spatial_bounds()
    tables = ", ".join(f"`{t}`" for t in dict.fromkeys(
        c.prediction.table for c in results.spatial if c.prediction is not None))
    if s.cells:
        lines.append(
            f"- Property-table bound ({tables}): the measured "
            f"loss within it in **{s.classic_within} of {s.cells}** (detector, corruption, "
            f"severity) cells ({s.classic_within_2se} within 2 SE); median over-prediction "
            f"{number(s.classic_median_ratio, 1)}×.")
    return lines


def _bound_word(cell: SpatialCell, model: str) -> str:
    """``yes`` (measured <= predicted), ``within 2 SE``, ``no`` or ``–``."""
    b = cell.bound(model)
    if b is None or b.classic_within is None:
        return "–"
    if b.classic_within:
        return "yes"
    return "within 2 SE" if b.classic_within_2se else "no"


def spatial_table(results: CocoCResults) -> document.Table:
    """The noise and blur table of the report (:data:`SPATIAL_SECTION`), one row per cell
    named ``corruption:severity`` (what ``fidelity predict --coco-c`` takes)."""
    models = results.spatial_models()
    header = ["corruption:severity", "parameter", "chart value (MTF50 cy/px, SNR)",
              "predicted ΔmAP"]
    header += [f"measured ΔmAP, {m}" for m in models] + [f"bounded, {m}" for m in models]
    rows = []
    for c in results.spatial:
        p = c.prediction
        if p is None:
            pred = "–"
        else:
            pm = "" if p.u_loss is None else f" ± {p.u_loss:.2f}"
            pred = f"{p.loss:.2f}{pm}" + (" (beyond the table)" if p.status == "beyond" else "")
        row = [f"{c.corruption}:{c.severity}", str(c.parameter), axis_text(c), pred]
        for m in models:
            x = c.measured_for(m)
            row.append("–" if x is None else f"{x.dmap_points:.2f} ± "
                                             f"{number(x.dmap_points_se)} ({x.images})")
        row += [_bound_word(c, m) for m in models]
        rows.append(row)
    return table(header, rows, numeric=[False, False, False, True]
                 + [True] * len(models) + [False] * len(models))


def _meta_lines(meta: Mapping[str, Any]) -> str:
    """The provenance as a Markdown list, the noise and blur run's (``spatial_run``) as a
    nested list."""
    lines = []
    for k, v in sorted(meta.items()):
        if k == "spatial_run" and isinstance(v, Mapping):
            lines.append(f"- {k}:")
            lines += [f"  - {kk}: {vv}" for kk, vv in sorted(v.items())]
        else:
            lines.append(f"- {k}: {v}")
    return "\n".join(lines)


def _spatial_method(results: CocoCResults) -> str:
    """The method's clause on the noise and blur corruptions (empty without them)."""
    run = results.meta.get("spatial_run")
    if not results.spatial or not isinstance(run, Mapping):
        return ""
    return ("; four of those, the noise and blur corruptions `gaussian_noise`, `shot_noise`, "
            "`defocus_blur` and `gaussian_blur`, go on the chart SNR and MTF50 scales instead "
            f"({run.get('definitions', '')}; `fidelity.coco.spatial`)")


def _spatial_text(results: CocoCResults) -> str:
    run = results.meta.get("spatial_run") or {}
    draws = run.get("chart_draws", "several")
    return (
        "Chart value: the calibration chart (640 × 480, turned 5°, the sharpness and noise "
        "tables' own) corrupted and measured as an audit measures it: MTF50 in cy/px (the "
        "softer patch edge's luminance e-SFR; ± its measurement's uncertainty) for the blurs, "
        "the 18 % grey patch's luminance SNR in linear light for the noises (the mean over "
        f"{draws} seeded draws, ± its standard error). Predicted: the worst case of "
        f"`{PROPERTY_TABLES['sharpness']}` or `{PROPERTY_TABLES['noise']}` at that value for "
        f"detector size {PREDICTION_SIZE}, the "
        "value's uncertainty propagated (what `fidelity predict --mtf50 X` / `--snr Y` "
        "prints; 'beyond the table': worse than every measured level, the table's ceiling). "
        "Measured: ΔmAP in percentage points ± one SE (the larger of the paired image "
        "bootstrap and the 5-fold jackknife), image count in brackets. Bounded: measured ≤ "
        "predicted (yes), measured − 2 SE ≤ predicted (within 2 SE), else no.")


def _bound_lines(results: CocoCResults) -> list[str]:
    """The headline's lines on how the two predictions bound the measured losses, naming the
    cells beyond the direction-aware one (none when no cell has both)."""
    s = results.bounds()
    if not s.cells or s.classic_median_ratio is None and s.directional_median_ratio is None:
        return []
    beyond = [f"{model} {c.corruption} {c.severity} by {b.measured - b.directional:.2f} points "
              + (f"({(b.measured - b.directional) / b.se:.2f} SE)" if b.se else "(no SE)")
              for c, model, b in results.bound_cells()
              if b.directional_within is False and b.measured is not None
              and b.directional is not None]
    tail = f"; beyond it: {', '.join(beyond)}" if beyond else ""
    return [
        f"- Classic bound (`coco1000-measured`): the measured loss within it in "
        f"**{s.classic_within} of {s.cells}** (detector, corruption, severity) cells "
        f"({s.classic_within_2se} within 2 SE); median over-prediction "
        f"{number(s.classic_median_ratio, 1)}×.",
        f"- Direction-aware bound (`coco1000-directional`): within it in "
        f"**{s.directional_within} of {s.cells}** ({s.directional_within_2se} within 2 SE); "
        f"median over-prediction {number(s.directional_median_ratio, 1)}×{tail}."]


def cococ_document(results: CocoCResults, notes: str | None = None) -> Document:
    """The COCO-C report of ``results``; ``notes`` (Markdown) becomes its "Analysis"
    section."""
    preds = {(c.corruption, c.severity): predictions(c) for c in results.cells}
    figs = cococ_figures(results, preds)
    models = results.models()
    header = ["corruption", "severity", "parameter", "chart ΔE00", "max (patch)",
              "L / C / H parts", "classic ΔmAP", "direction-aware ΔmAP"]
    header += [f"measured ΔmAP, {m}" for m in models]
    rows = []
    for c in sorted(results.cells, key=lambda c: (c.corruption, c.severity)):
        p = preds[(c.corruption, c.severity)]
        parts = c.parts
        row = [c.corruption, str(c.severity), str(c.parameter), f"{c.chart_delta_e:.2f}",
               f"{c.chart_max_delta_e:.1f} ({c.worst_patch})",
               f"{parts.get('lightness', 0):.1f} / {parts.get('chroma', 0):.1f} / "
               f"{parts.get('hue', 0):.1f}", number(p["classic"]), number(p["directional"])]
        for m in models:
            x = c.measured_for(m)
            row.append("–" if x is None else f"{x.dmap_points:.2f} ± "
                                             f"{number(x.dmap_points_se)} ({x.images})")
        rows.append(row)
    sections: list[Section | None] = [
        section("ΔE, prediction and measured loss per corruption and severity", Text(
            "ΔmAP in percentage points of mAP@[.50:.95] against the ΔE = 0 baseline (the same "
            "JPEG round trip without corruption), measured ± its standard error as its run "
            "computed it (now the larger of the paired image bootstrap and the 5-fold "
            "jackknife; earlier runs: the jackknife or the paired SE over 5 image folds), "
            "image count in brackets; predictions for detector size n from "
            "the "
            "shipped tables (classic: `coco1000-measured`; direction-aware: "
            "`coco1000-directional`); parts: the chart ΔE split into lightness, chroma and hue "
            "(`fidelity.prediction.directional.error_parts`)."),
            table(header, rows, numeric=[False, True, False, True, False, False, True, True]
                  + [True] * len(models))),
        section(SPATIAL_SECTION, Text(_spatial_text(results)), spatial_table(results))
        if results.spatial else None,
        section("Analysis", Text(notes.strip())) if notes else None,
        section("Figures", *[figs[k] for k in (LOSS_FIGURE, MTF50_FIGURE, SNR_FIGURE)
                             if k in figs]),
        section("Method", Text(
            "- Corruptions: `brightness` (HSV V + c), `contrast` (per channel (x − mean)·c + "
            "mean), `saturate` (HSV S·a + b) of the `imagecorruptions` package "
            f"({results.meta.get('definitions', '')}); the other corruptions change spatial "
            "detail or overlay random textures, which a flat chart's mean cannot measure "
            f"(`fidelity.coco.corruptions`){_spatial_method(results)}.\n"
            f"- Chart ΔE: the calibration chart `{results.chart}` (reference Lab → sRGB clipped, "
            "the chart the SAFE-COLOR transforms were calibrated on) as an 8-bit image of 24 "
            "flat 32-pixel patches and nothing else, corrupted, each patch read back, CIEDE2000 "
            f"against the reference; the uncorrupted 8-bit chart reads {results.floor_delta_e:.3f}.\n"
            "- Loss: every COCO image corrupted, then the JPEG round trip of the sweep "
            "(original quantisation tables and subsampling), the detector run; the baseline "
            "is the round trip alone (`fidelity.coco.measure`).")),
        section("What was run", Text(_meta_lines(results.meta))),
    ]
    return Document(TITLE, _headline(results, figs.get(DELTA_E_FIGURE)),
                    tuple(s for s in sections if s is not None),
                    subtitle="Generated by `fidelity coco-c` (fidelity/coco/corruptions.py); "
                             "every number is computed from stored detections and the chart.")


def write_cococ_report(results: CocoCResults, out_dir: str | os.PathLike[str],
                       notes: str | None = None, data: str | os.PathLike[str] | None = None
                       ) -> list[Path]:
    """Write ``cococ.html``, ``cococ.md`` (with its figures) and ``cococ.json`` into
    ``out_dir``, and the shipped data file ``data`` when given (its input paths cut to their
    names: :meth:`~fidelity.coco.corruptions.CocoCResults.without_locations`); atomically."""
    out = Path(out_dir)
    written = write_document(cococ_document(results, notes), html=out / "cococ.html",
                             markdown=out / "cococ.md")
    written.append(write_json_atomic(out / "cococ.json", results.to_json()))
    if data is not None:
        written.append(write_json_atomic(data, results.without_locations().to_json()))
    return written


__all__ = [
    "DELTA_E_FIGURE",
    "FIGURES",
    "LOSS_FIGURE",
    "MTF50_FIGURE",
    "SNR_FIGURE",
    "SPATIAL_SECTION",
    "axis_text",
    "TITLE",
    "cococ_document",
    "cococ_figures",
    "predictions",
    "spatial_table",
    "write_cococ_report",
]
