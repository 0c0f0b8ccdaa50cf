"""The COCO benchmark and COCO-C reports' figures as SVG, drawn from the numbers
(:mod:`fidelity.report.svg`), no plotting library:

- :func:`worst_case_plot`: worst-case relative ΔmAP per model against chart ΔE00, ±2 SE, with
  SAFE-COLOR's bound as a step; right: the same on a log axis;
- :func:`map_vs_delta_e_plot`: one model's mAP@[.50:.95] against chart ΔE00 per transform;
- :func:`cococ_delta_e_plot`: the chart ΔE00 of each COCO-C colour corruption per severity;
- :func:`cococ_loss_plot`: measured ΔmAP (±2 SE) of each corruption cell at its chart ΔE, the
  classic worst-case curve and each cell's direction-aware prediction;
- :func:`cococ_property_plot`: measured ΔmAP (±2 SE) of each noise or blur corruption cell at
  its chart SNR or MTF50, with the property table's worst-case curve.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.coco.tables.colour import PAPER_THRESHOLDS
from fidelity.prediction.interpolate import predict_curve
from fidelity.prediction.properties import load_property_table, worst_case_losses
from fidelity.report.svg import (
    COLOURS,
    MARKERS,
    Axes,
    Canvas,
    LegendEntry,
    Scale,
    legend_column,
    legend_row,
)

if TYPE_CHECKING:
    from fidelity.coco.corruptions import CocoCResults
    from fidelity.coco.tables.build import Tables

#: matplotlib's tab10 colours, one per line in order.
TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
         "#7f7f7f", "#bcbd22", "#17becf")

#: Colours of the COCO-C corruptions.
CORRUPTION_COLOURS = {"brightness": COLOURS["orange"], "contrast": COLOURS["blue"],
                      "saturate": COLOURS["green"], "gaussian_noise": COLOURS["blue"],
                      "shot_noise": COLOURS["orange"], "defocus_blur": COLOURS["green"],
                      "gaussian_blur": COLOURS["red"]}
#: What each property's figure is drawn against: (axis label, table curve's range).
PROPERTY_AXES = {"sharpness": ("chart MTF50 (cy/px, softer edge, luminance)", (0.03, 0.7)),
                 "noise": ("chart SNR at 18 % grey (luminance, linear light)", (1.0, 100.0))}

_F = NDArray[np.float64]


def _single(label: str, title: str, width: float = 980.0, plot_w: float = 560.0,
            plot_h: float = 320.0) -> tuple[Canvas, tuple[float, float, float, float]]:
    """A canvas for one plot (at 64, 40) with room for a legend column on its right."""
    c = Canvas(width, 40 + plot_h + 52, label)
    c.text(64 + plot_w / 2, 22, title, 14, "middle", weight="600")
    return c, (64.0, 40.0, plot_w, plot_h)


def _legend_right(c: Canvas, entries: Sequence[LegendEntry], x: float, y: float) -> None:
    """The legend as a column at (``x``, ``y``), the canvas narrowed to end just after it."""
    legend_column(c, entries, x, y)
    if entries:
        c.width = x + max(38 + 6.2 * len(e[1]) for e in entries) + 12


def _line_points(ax: Axes, x: _F, y: _F, colour: str, size: float = 3.0,
                 label: str | None = None, shape: str = "o", dash: str | None = None) -> None:
    """A line through the points with a marker on each (finite ones)."""
    ax.plot(x, y, colour, 1.4, dash, label)
    for xi, yi in zip(x, y, strict=True):
        if np.isfinite(xi) and np.isfinite(yi) and np.isfinite(ax.py(yi)):
            ax.marker(float(xi), float(yi), colour, size, shape, edge=colour)


def paper_step() -> tuple[_F, _F]:
    """SAFE-COLOR's bound on the relative ΔmAP (%) as a step through its thresholds
    (:data:`fidelity.coco.tables.colour.PAPER_THRESHOLDS`: 1 % up to ΔE 3, 3 % to 6, 10 % to
    12)."""
    x, y, start = [], [], 0.0
    for limit, bound in PAPER_THRESHOLDS:
        x += [start, float(limit)]
        y += [bound, bound]
        start = float(limit)
    return np.array(x, np.float64), np.array(y, np.float64)


def worst_case_plot(tables: Tables) -> str:
    """Worst-case relative ΔmAP (% of baseline) per model against chart ΔE00, ±2 SE (open
    circle: not every transform done), with SAFE-COLOR's bound (1 / 3 / 10 %) as a dashed
    step; right: the same on a log axis (bars reaching zero stop at the axis)."""
    series = []
    for i, (m, rows) in enumerate(tables.worst_case.items()):
        x = np.array([r.delta_e for r in rows], np.float64)
        y = np.array([np.nan if r.dmap_relative is None else r.dmap_relative for r in rows],
                     np.float64)
        se2 = np.array([np.nan if r.dmap_relative_se is None else 2.0 * r.dmap_relative_se
                        for r in rows], np.float64)
        partial = np.array([bool(r.partial) for r in rows])
        series.append((m, TAB10[i % len(TAB10)], x, y, se2, partial))
    xs = [s[2] for s in series] + [np.array([12.0])]
    xmax = max(float(np.nanmax(a)) for a in xs if a.size) * 1.04
    highs = [s[3] + np.nan_to_num(s[4]) for s in series]
    ymax = max([10.0, *(float(np.nanmax(h)) for h in highs if np.any(np.isfinite(h)))]) * 1.08
    lows = [s[3] - np.nan_to_num(s[4]) for s in series]
    ymin = min([0.0, *(float(np.nanmin(v)) for v in lows if np.any(np.isfinite(v)))])
    positive = [float(v) for s in series for v in s[3] if np.isfinite(v) and v > 0]
    log_lo = min(0.5, min(positive) / 2) if positive else 0.5
    pw, ph, gap = 380.0, 300.0, 86.0
    c = Canvas(64 + 2 * pw + gap + 16, 40 + 40 + ph + 52,
               "worst-case ΔmAP against chart ΔE per model")
    c.text(c.width / 2, 22, "Worst-case ΔmAP per model against chart ΔE00 (bars: ±2 SE; open "
           "circle: not every transform done)", 14, "middle", weight="600")
    left = Axes(c, 64, 80, pw, ph, Scale(0.0, xmax), Scale(ymin, ymax))
    right = Axes(c, 64 + pw + gap, 80, pw, ph, Scale(0.0, xmax), Scale(log_lo, ymax, "log"))
    left.frame("chart ΔE00", "worst-case ΔmAP (% of baseline)")
    right.frame("chart ΔE00", "worst-case ΔmAP (% of baseline, log)")
    step_x, step_y = paper_step()
    for ax in (left, right):
        ax.plot(step_x, step_y, "#000", 1.0, "5 3", "SAFE-COLOR bound (" + " / ".join(
            f"{b:g}" for b in step_y[::2]) + " %)" if ax is left else None)
    for m, colour, x, y, se2, partial in series:
        left.bars(x, y, se2, se2, colour, 0.9)
        _line_points(left, x, y, colour, 3.0, m)
        for xi, yi in zip(x[partial], y[partial], strict=True):
            if np.isfinite(yi):
                c.circle(float(left.px(xi)), float(left.py(yi)), 7.0, "#fff", colour, 1.4)
        pos = np.isfinite(y) & (y > 0)
        right.bars(x[pos], y[pos], np.minimum(se2[pos], 0.95 * y[pos]), se2[pos], colour, 0.9)
        _line_points(right, x[pos], y[pos], colour, 3.0)
    c.text(left.x + left.w / 2, left.y - 8, "linear", 13, "middle")
    c.text(right.x + right.w / 2, right.y - 8, "log scale", 13, "middle")
    legend_row(c, left.legend_entries, 46)
    return c.render()


def map_vs_delta_e_plot(tables: Tables, model: str) -> str:
    """``model``'s mAP@[.50:.95] (%) against chart ΔE00 for every transform (ΔE 0: the
    baseline), one line each."""
    base = tables.models[model].baseline_map
    lines = []
    for t in tables.transforms:
        pts = sorted((r.delta_e, float(r.map)) for r in tables.cells.get(model, ())
                     if r.transform == t and r.done and r.map is not None)
        if pts:
            a = np.array([(0.0, base), *pts], np.float64)
            lines.append((t, a[:, 0], a[:, 1] * 100))
    xmax = max([1.0, *(float(x.max()) for _, x, _ in lines)]) * 1.04
    ys = [y for _, _, y in lines]
    lo = min([float(y.min()) for y in ys] + [base * 100]) if ys else 0.0
    hi = max([float(y.max()) for y in ys] + [base * 100]) if ys else 1.0
    pad = max(0.5, (hi - lo) * 0.05)
    c, (x0, y0, w, h) = _single(f"{model}: mAP against chart ΔE per transform",
                                f"{model}: mAP against ΔE per transform")
    ax = Axes(c, x0, y0, w, h, Scale(0.0, xmax), Scale(max(0.0, lo - pad), hi + pad))
    ax.frame("chart ΔE00 (mean over 24 patches)", "mAP@[.50:.95] (%)")
    for i, (t, x, y) in enumerate(lines):
        _line_points(ax, x, y, TAB10[i % len(TAB10)], 2.8, t)
    _legend_right(c, ax.legend_entries, x0 + w + 20, y0 + 10)
    return c.render()


def cococ_delta_e_plot(results: CocoCResults) -> str:
    """Chart ΔE00 of each COCO-C colour corruption against its severity (1-5), with the
    uncorrupted 8-bit chart's own ΔE and SAFE-COLOR's thresholds (ΔE 3, 6, 12)."""
    names = sorted({cell.corruption for cell in results.cells})
    lines = []
    for i, name in enumerate(names):
        cells = sorted((x for x in results.cells if x.corruption == name),
                       key=lambda x: x.severity)
        lines.append((name, MARKERS[i % len(MARKERS)],
                      np.array([x.severity for x in cells], np.float64),
                      np.array([x.chart_delta_e for x in cells], np.float64)))
    top = max([13.0, *(float(np.nanmax(y)) for *_, y in lines if y.size)]) * 1.06
    c, (x0, y0, w, h) = _single("chart ΔE against COCO-C severity",
                                "What each COCO-C colour corruption does to the chart",
                                width=900.0, plot_w=480.0)
    ax = Axes(c, x0, y0, w, h, Scale(0.6, 5.4), Scale(0.0, top))
    ax.frame("COCO-C severity", "chart ΔE00 (mean over 24 patches)", xticks=[1, 2, 3, 4, 5])
    for de in (3.0, 6.0, 12.0):
        ax.hline(de, COLOURS["red"], 0.7)
        c.text(ax.x + ax.w + 4, float(ax.py(de)), f"ΔE {de:g}", 11, fill=COLOURS["red"],
               baseline="middle")
    ax.hline(results.floor_delta_e, "#808080", 1.0, "2 3",
             f"uncorrupted 8-bit chart ({results.floor_delta_e:.2f})")
    for i, (name, shape, x, y) in enumerate(lines):
        colour = CORRUPTION_COLOURS.get(name, TAB10[i % len(TAB10)])
        _line_points(ax, x, y, colour, 4.0, name, shape)
    _legend_right(c, ax.legend_entries, x0 + w + 56, y0 + 10)
    return c.render()


def cococ_loss_plot(results: CocoCResults,
                    preds: Mapping[tuple[str, int], Mapping[str, Any]]) -> str:
    """Measured ΔmAP (points, ±2 SE) of each corruption and severity at its chart ΔE, per
    detector (marker shape), with the classic worst-case curve (coco1000-measured, size n)
    and each cell's direction-aware prediction (dashed, crosses); symlog loss axis."""
    xmax = max([x.chart_delta_e for x in results.cells] + [6.0]) * 1.08
    grid = np.linspace(0.0, xmax, 400)
    classic = predict_curve(grid, "dmap_points", size="n")
    entries: list[LegendEntry] = [("line", "classic worst case (coco1000-measured, size n)",
                                   "#000", None, 1.3)]
    drawn: list[tuple[str, str, _F, _F, list[tuple[str, str, _F, _F, _F]]]] = []
    values = [classic]
    for name in sorted({x.corruption for x in results.cells}):
        cells = sorted((x for x in results.cells if x.corruption == name),
                       key=lambda x: x.chart_delta_e)
        colour = CORRUPTION_COLOURS.get(name, "#808080")
        dx = np.array([x.chart_delta_e for x in cells], np.float64)
        dy = np.array([np.nan if (v := preds[(x.corruption, x.severity)]["directional"]) is None
                       else float(v) for x in cells], np.float64)
        measured = []
        for model, shape in zip(results.models(), MARKERS, strict=False):
            pts = [(x.chart_delta_e, m.dmap_points, m.dmap_points_se or 0.0)
                   for x in cells if (m := x.measured_for(model)) is not None]
            if pts:
                a = np.array(pts, np.float64)
                measured.append((model, shape, a[:, 0], a[:, 1], a[:, 2]))
                values += [a[:, 1] - 2 * a[:, 2], a[:, 1] + 2 * a[:, 2]]
        values.append(dy)
        drawn.append((name, colour, dx, dy, measured))
    finite = [v[np.isfinite(v)] for v in values]
    lo = min([0.0, *(float(v.min()) for v in finite if v.size)])
    hi = max([1.0, *(float(v.max()) for v in finite if v.size)]) * 1.05
    c, (x0, y0, w, h) = _single("measured loss against chart ΔE",
                                "COCO-C colour corruptions: measured loss against chart ΔE",
                                width=1040.0)
    ax = Axes(c, x0, y0, w, h, Scale(0.0, xmax), Scale(lo * 1.05, hi, "symlog"))
    ax.frame("chart ΔE00 of the corruption", "ΔmAP (points)")
    ax.plot(grid, classic, "#000", 1.3)
    for name, colour, dx, dy, measured in drawn:
        ax.plot(dx, dy, colour, 0.9, "5 3")
        for xi, yi in zip(dx, dy, strict=True):
            if np.isfinite(yi):
                px, py = float(ax.px(xi)), float(ax.py(yi))
                c.line(px - 3.5, py - 3.5, px + 3.5, py + 3.5, colour, 1.2)
                c.line(px - 3.5, py + 3.5, px + 3.5, py - 3.5, colour, 1.2)
        entries.append(("line", f"{name}: direction-aware prediction", colour, "5 3", 0.9))
        for model, shape, mx, my, ms in measured:
            ax.errorbar(mx, my, 2 * ms, colour, shape, 4.0)
            entries.append((shape, f"{name}: measured, {model}", colour, None, 4.0))
    _legend_right(c, entries, x0 + w + 20, y0 + 10)
    return c.render()


def cococ_property_plot(results: CocoCResults, prop: str, size: str = "n") -> str:
    """Measured ΔmAP (points, ±2 SE) of each noise (``prop`` ``noise``) or blur
    (``sharpness``) corruption cell at its chart SNR or MTF50, per detector (marker shape),
    with the worst case of the property's shipped table for detector size ``size``
    (:func:`fidelity.prediction.properties.worst_case_losses`); log value axis, symlog loss
    axis."""
    table = load_property_table(prop)
    label, (lo_x, hi_x) = PROPERTY_AXES[prop]
    cells = [x for x in results.spatial if x.property == prop and x.axis.x is not None]
    xs = [float(x.axis.x) for x in cells if x.axis.x is not None]
    lo_x = min([lo_x, *xs]) / 1.1
    hi_x = max([hi_x, *xs]) * 1.1
    grid = np.geomspace(lo_x, hi_x, 400)
    curve = worst_case_losses(table, grid, size=size)
    entries: list[LegendEntry] = [("line", f"worst case ({table.name}, size {size})", "#000",
                                   None, 1.3)]
    values = [curve]
    drawn = []
    for name in sorted({x.corruption for x in cells}):
        colour = CORRUPTION_COLOURS.get(name, "#808080")
        own = sorted((x for x in cells if x.corruption == name), key=lambda x: x.severity)
        for model, shape in zip(results.spatial_models(), MARKERS, strict=False):
            pts = [(float(x.axis.x or 0.0), m.dmap_points, m.dmap_points_se or 0.0)
                   for x in own if (m := x.measured_for(model)) is not None]
            if pts:
                a = np.array(pts, np.float64)
                drawn.append((name, model, colour, shape, a))
                values += [a[:, 1] - 2 * a[:, 2], a[:, 1] + 2 * a[:, 2]]
    finite = [v[np.isfinite(v)] for v in values]
    lo = min([0.0, *(float(v.min()) for v in finite if v.size)])
    hi = max([1.0, *(float(v.max()) for v in finite if v.size)]) * 1.05
    axis = "MTF50" if prop == "sharpness" else "SNR"
    c, (x0, y0, w, h) = _single(f"measured loss against chart {axis}",
                                f"COCO-C {'blur' if prop == 'sharpness' else 'noise'} "
                                f"corruptions: measured loss against chart {axis}",
                                width=1000.0)
    ax = Axes(c, x0, y0, w, h, Scale(lo_x, hi_x, "log"), Scale(lo * 1.05, hi, "symlog"))
    ax.frame(label, "ΔmAP (points)")
    ax.plot(grid, curve, "#000", 1.3)
    for name, model, colour, shape, a in drawn:
        ax.plot(a[:, 0], a[:, 1], colour, 0.8, "4 3")
        ax.errorbar(a[:, 0], a[:, 1], 2 * a[:, 2], colour, shape, 4.0)
        entries.append((shape, f"{name}: measured, {model}", colour, None, 4.0))
    _legend_right(c, entries, x0 + w + 20, y0 + 10)
    return c.render()


__all__ = [
    "CORRUPTION_COLOURS",
    "PROPERTY_AXES",
    "TAB10",
    "cococ_delta_e_plot",
    "cococ_loss_plot",
    "cococ_property_plot",
    "map_vs_delta_e_plot",
    "paper_step",
    "worst_case_plot",
]
