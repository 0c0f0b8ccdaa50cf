"""The validation report's figures as SVG, drawn from the numbers (:mod:`fidelity.report.svg`).

Every figure of ``validation.html`` / ``validation.md`` as SVG text, no plotting library:

- :func:`scatter_plot`: measured against predicted loss per class (all, person, bicycle), ±2
  SE, with the identity line (the bound holds below it), for one prediction table;
- :func:`vs_delta_e_plot`: measured loss against the camera's chart ΔE00 per class, with each
  table's worst-case curve for detector size n;
- :func:`bounds_plot`: measured ΔmAP against the classic and the direction-aware prediction;
- :func:`emulation_plot`: mean and largest ΔE00 per camera between its emulation and its own
  rendered chart.

Loss axes are ``symlog`` (linear below 1 point, logarithmic above), so cells of 0.1 and of 20
points are both readable; the models keep one colour and marker shape in every figure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fidelity.coco.loss import LOSS_COLUMNS
from fidelity.prediction.interpolate import predict_curve
from fidelity.report.svg import COLOURS, MARKERS, Axes, Canvas, LegendEntry, Scale, legend_row

if TYPE_CHECKING:
    from fidelity.coco.validate.camera import CameraRecord
    from fidelity.coco.validate.checks import ValidationRow
    from fidelity.coco.validate.colour import ValidationResults

#: The classes plotted, by :data:`fidelity.coco.loss.LOSS_COLUMNS` key, with their titles.
PLOTTED: dict[str, str] = {"all": "mAP@[.50:.95] (all classes)", "person": "AP person",
                           "bicycle": "AP bicycle"}

#: Colours of the models in sorted order (matplotlib's tab10, as the PNG figures were).
MODEL_COLOURS = (COLOURS["blue"], COLOURS["orange"], COLOURS["green"], COLOURS["red"],
                 COLOURS["purple"])

#: Dash patterns of the worst-case curves of the tables, in order.
TABLE_DASHES: tuple[str | None, ...] = (None, "6 3", "2 2", "7 3 2 3")

#: Size of one panel's plot area and the margins around it, px.
PANEL_W, PANEL_H, LEFT, TOP, GAP, BOTTOM = 286.0, 280.0, 60.0, 84.0, 66.0, 50.0

Points = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def _style(models: Sequence[str]) -> dict[str, tuple[str, str]]:
    """Colour and marker shape of each model (sorted)."""
    return {m: (MODEL_COLOURS[i % len(MODEL_COLOURS)], MARKERS[i % len(MARKERS)])
            for i, m in enumerate(sorted(models))}


def _panels(n: int, label: str, title: str) -> tuple[Canvas, list[tuple[float, float]]]:
    """A canvas of ``n`` panels side by side under ``title`` (and a row for the legend);
    each panel's top-left corner."""
    width = LEFT + n * PANEL_W + (n - 1) * GAP + 16
    c = Canvas(width, TOP + PANEL_H + BOTTOM, label)
    c.text(width / 2, 20, title, 14, "middle", weight="600")
    return c, [(LEFT + i * (PANEL_W + GAP), TOP) for i in range(n)]


def _legend(c: Canvas, axes: Sequence[Axes]) -> None:
    """One legend for every panel (each label once, in order of first appearance), in the row
    under the title."""
    seen: dict[str, LegendEntry] = {}
    for ax in axes:
        for e in ax.legend_entries:
            seen.setdefault(e[1], e)
    legend_row(c, list(seen.values()), 40)


def _range(values: Sequence[NDArray[np.float64]], lo: float = 0.0, hi: float = 1.0
           ) -> tuple[float, float]:
    """The data range covering ``values`` (finite ones) and [``lo``, ``hi``], 5 % headroom."""
    finite = [a[np.isfinite(a)] for a in values]
    low = min([lo, *(float(a.min()) for a in finite if a.size)])
    high = max([hi, *(float(a.max()) for a in finite if a.size)])
    return (low * 1.05 if low < 0 else low), high * 1.05


def _arrays(pts: Sequence[tuple[float, float, float]]) -> Points:
    a = np.array(pts, np.float64).reshape(-1, 3)
    return a[:, 0], a[:, 1], a[:, 2]


def _identity_panel(c: Canvas, corner: tuple[float, float], series: Mapping[str, Points],
                    style: Mapping[str, tuple[str, str]], xlabel: str, ylabel: str,
                    title: str) -> Axes:
    """A panel at ``corner``: measured (±2 SE) against predicted per model, the identity line
    and the region below it where the bound holds; both axes symlog over one range covering
    every point and bar."""
    lo, hi = _range([a for pa, ya, sa in series.values() for a in (pa, ya - 2 * sa,
                                                                     ya + 2 * sa)])
    ax = Axes(c, *corner, PANEL_W, PANEL_H, Scale(lo, hi, "symlog"), Scale(lo, hi, "symlog"))
    ax.frame(xlabel, ylabel)
    lo, hi = ax.xs.lo, ax.xs.hi
    diag = np.linspace(lo, hi, 200)
    ax.region(np.r_[diag, hi], np.r_[diag, lo], COLOURS["green"], 0.08, "bound holds")
    ax.plot(diag, diag, "#000", 1.0, "5 3", "identity (measured = predicted)")
    for m, (pa, ya, sa) in series.items():
        colour, shape = style[m]
        ax.errorbar(pa, ya, 2 * sa, colour, shape, 4.0, m)
    ax.c.text(ax.x + ax.w / 2, ax.y - 8, title, 13, "middle")
    return ax


def scatter_plot(rows: Sequence[ValidationRow], table_name: str) -> str:
    """Measured against predicted loss (points, ±2 SE) per class, with the identity line (the
    bound holds below it), for the prediction table ``table_name``."""
    style = _style(list({r.model for r in rows}))
    c, corners = _panels(len(PLOTTED), f"predicted against measured loss, {table_name}",
                         f"Measured loss (bars: ±2 SE) against the loss table {table_name} predicts")
    axes: list[Axes] = []
    for (x, y), (cls, title) in zip(corners, PLOTTED.items(), strict=True):
        col = LOSS_COLUMNS[cls]
        series = {}
        for m in sorted(style):
            pts = [(pv, mv, r.se.get(col) or 0.0) for r in rows if r.model == m
                   if (pv := r.predicted[table_name].losses.get(col)) is not None
                   and (mv := r.measured.get(col)) is not None]
            if pts:
                series[m] = _arrays(pts)
        axes.append(_identity_panel(c, (x, y), series, style, "predicted loss (points)",
                                    "measured loss (points)", title))
    _legend(c, axes)
    return c.render()


def vs_delta_e_plot(rows: Sequence[ValidationRow], tables: Sequence[str]) -> str:
    """Measured loss (points, ±2 SE) against the camera's chart ΔE00 per class, with each of
    ``tables``' worst-case curve for detector size n (a table without the class is left out)."""
    style = _style(list({r.model for r in rows}))
    xmax = max([r.chart_delta_e for r in rows] + [6.0]) * 1.05
    grid = np.linspace(0.0, xmax, 300)
    c, corners = _panels(len(PLOTTED), "measured loss against chart ΔE with the worst-case "
                         "curves", "Measured loss (bars: ±2 SE) against the camera's chart ΔE00, "
                         "with the worst-case curves (detector size n)")
    axes: list[Axes] = []
    for (x, y), (cls, title) in zip(corners, PLOTTED.items(), strict=True):
        col = LOSS_COLUMNS[cls]
        series = {}
        for m in sorted(style):
            pts = [(r.chart_delta_e, mv, r.se.get(col) or 0.0) for r in rows
                   if r.model == m and (mv := r.measured.get(col)) is not None]
            if pts:
                series[m] = _arrays(pts)
        curves = []
        for t, dash in zip(tables, TABLE_DASHES, strict=False):
            try:
                curve = predict_curve(grid, col, size="n", table=t)
            except Exception:  # noqa: BLE001 - a table without this column is left out
                continue
            if np.any(np.isfinite(curve)):
                curves.append((t, dash, curve))
        lo, hi = _range([*(a for _, ya, sa in series.values() for a in (ya - 2 * sa,
                                                                         ya + 2 * sa)),
                         *(cv for _, _, cv in curves)])
        ax = Axes(c, x, y, PANEL_W, PANEL_H, Scale(0.0, xmax), Scale(lo, hi, "symlog"))
        axes.append(ax)
        ax.frame("chart ΔE00 of the camera (mean of 24)", "loss (points)")
        ax.hline(0.0, "#808080", 0.8)
        for t, dash, curve in curves:
            ax.plot(grid, curve, "#000", 1.3, dash, f"worst case, {t}")
        for m, (xa, ya, sa) in series.items():
            colour, shape = style[m]
            ax.errorbar(xa, ya, 2 * sa, colour, shape, 4.0, m)
        c.text(ax.x + ax.w / 2, ax.y - 8, title, 13, "middle")
    _legend(c, axes)
    return c.render()


def bounds_plot(results: ValidationResults) -> str:
    """Measured mAP loss (points, ±2 SE) against both predictions per cell: the classic worst
    case and the direction-aware one, with the identity line."""
    dv = results.directional
    if dv is None:
        raise ValueError("bounds_plot needs results with the direction-aware bound")
    style = _style(list({r.model for r in dv.rows}))
    c, corners = _panels(2, "both bounds against the measured loss",
                         "Measured ΔmAP (bars: ±2 SE) against the classic and the "
                         "direction-aware bound")
    axes: list[Axes] = []
    for (x, y), key, title in zip(corners, ("classic", "directional"),
                                  (f"classic ({results.summary.bound_table})",
                                   f"direction-aware ({dv.table})"), strict=True):
        series = {}
        for m in sorted(style):
            pts = [(float(p), float(c_.measured), c_.se or 0.0) for r in dv.rows if r.model == m
                   for c_ in (r.cells["all"],)
                   if (p := getattr(c_, key)) is not None and c_.measured is not None]
            if pts:
                series[m] = _arrays(pts)
        axes.append(_identity_panel(c, (x, y), series, style, "predicted ΔmAP (points)",
                                    "measured ΔmAP (points)", title))
    _legend(c, axes)
    return c.render()


def emulation_plot(cameras: Mapping[str, CameraRecord]) -> str:
    """Mean and largest ΔE00 per camera between its emulation (the fitted mapping applied to
    the 8-bit reference chart) and the camera's own rendered chart, cameras by chart ΔE."""
    names = sorted(cameras, key=lambda k: cameras[k].chart_delta_e)
    acc = [cameras[n].emulation.accuracy for n in names]
    mean = np.array([a.chart_mean_delta_e for a in acc], np.float64)
    high = np.array([a.chart_max_delta_e for a in acc], np.float64)
    n = max(len(names), 1)
    plot_w = max(360.0, 30.0 * n)
    label_h = 12 + 5.4 * max([len(s) for s in names] + [4])
    c = Canvas(LEFT + plot_w + 24, TOP + 230 + label_h, "emulation accuracy per camera")
    c.text(c.width / 2, 20, "Emulation accuracy: the fitted mapping applied to the 8-bit "
           "reference chart against the camera's rendered chart", 14, "middle", weight="600")
    top = max([0.5, *(float(v) for v in high[np.isfinite(high)])]) * 1.1
    ax = Axes(c, LEFT, TOP, plot_w, 230, Scale(-0.6, n - 0.4), Scale(0.0, top))
    ax.frame(ylabel="ΔE00 emulated vs camera", xticks=[])
    bw = ax.w / n * 0.38
    for k, name in enumerate(names):
        px = float(ax.px(k))
        for v, dx, colour in ((mean[k], -bw, COLOURS["blue"]), (high[k], 0.0, COLOURS["orange"])):
            if np.isfinite(v):
                yv = float(ax.py(float(v)))
                c.rect(px + dx, yv, bw, ax.y + ax.h - yv, colour)
        c.text(px + 4, ax.y + ax.h + 8, name, 11, "end", rotate=-60, baseline="middle")
    ax.legend_entries += [("box", "mean ΔE00 (chart)", COLOURS["blue"], None, 1.0),
                          ("box", "max ΔE00 (chart)", COLOURS["orange"], None, 1.0)]
    _legend(c, [ax])
    return c.render()


__all__ = [
    "MODEL_COLOURS",
    "PLOTTED",
    "bounds_plot",
    "emulation_plot",
    "scatter_plot",
    "vs_delta_e_plot",
]
