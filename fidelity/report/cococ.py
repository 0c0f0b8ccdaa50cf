"""The COCO-C report: COCO-C's colour corruptions on the chart ΔE scale.

Built as one :class:`~fidelity.report.document.Document` from
:class:`fidelity.coco.corruptions.CocoCResults` (:func:`cococ_document`) and written as
``cococ.html`` and ``cococ.md`` with ``cococ.json`` and the SVG figures
(:func:`write_cococ_report`). Reading order: the headline (each corruption's chart ΔE over
severities 1-5 and what it costs), the table (chart ΔE, its direction, the classic and the
direction-aware predicted ΔmAP, the measured ΔmAP ± SE per detector), the figures, the method
and what was run.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.core.fileio import write_json_atomic
from fidelity.report import cocofigures as cf
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
    from fidelity.coco.corruptions import CocoCResults, CorruptionCell

#: Title of the report.
TITLE = "COCO-C colour corruptions on the chart ΔE scale"
#: Figure file names.
DELTA_E_FIGURE = "cococ-chart-delta-e.svg"
LOSS_FIGURE = "cococ-loss-vs-delta-e.svg"


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
    return out


def _headline(results: CocoCResults, figure: Figure | None) -> Headline:
    lines = ["**COCO-C's colour corruptions, severities 1-5, on the chart ΔE scale:**", ""]
    models = results.models()
    for name in sorted({c.corruption for c in results.cells}):
        cells = sorted((c for c in results.cells if c.corruption == name),
                       key=lambda c: c.severity)
        de = ", ".join(f"{c.chart_delta_e:.1f}" for c in cells)
        text = f"- {name}: chart ΔE {de}"
        if models:
            m0 = models[0]
            got = [c.measured_for(m0) for c in cells]
            if all(g is not None for g in got):
                text += (f"; measured ΔmAP ({m0}) "
                         + ", ".join(f"{g.dmap_points:.1f}" for g in got if g is not None))
        lines.append(text + ".")
    lines += _bound_lines(results)
    return Headline("\n".join(lines), "info", figure)


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
        section("Analysis", Text(notes.strip())) if notes else None,
        section("Figures", *[figs[k] for k in (LOSS_FIGURE,) if k in figs]),
        section("Method", Text(
            "- Corruptions: `brightness` (HSV V + c), `contrast` (per channel (x − mean)·c + "
            "mean), `saturate` (HSV S·a + b) of the `imagecorruptions` package "
            f"({results.meta.get('definitions', '')}); the other corruptions change spatial "
            "detail or overlay random textures, which a flat chart's mean cannot measure "
            "(`fidelity.coco.corruptions`).\n"
            f"- Chart ΔE: the calibration chart `{results.chart}` (reference Lab → sRGB clipped, "
            "the chart the SAFE-COLOR transforms were calibrated on) as an 8-bit image of 24 "
            "flat 32-pixel patches and nothing else, corrupted, each patch read back, CIEDE2000 "
            f"against the reference; the uncorrupted 8-bit chart reads {results.floor_delta_e:.3f}.\n"
            "- Loss: every COCO image corrupted, then the JPEG round trip of the sweep "
            "(original quantisation tables and subsampling), the detector run; the baseline "
            "is the round trip alone (`fidelity.coco.measure`).")),
        section("What was run", Text("\n".join(f"- {k}: {v}" for k, v in
                                               sorted(results.meta.items())))),
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
    "LOSS_FIGURE",
    "TITLE",
    "cococ_document",
    "cococ_figures",
    "predictions",
    "write_cococ_report",
]
