"""The chart report's figures as SVG, drawn from the numbers (:mod:`fidelity.report.svg`).

Every figure of the ``check``/``audit``/``gate``/``compare`` HTML report, as SVG text: no
plotting library is imported, so the whole report costs milliseconds. Chart figures take a
:class:`~fidelity.measure.colour.ChartMeasurement` (patches in row-major order); patches are
numbered 1..n in chart order in every figure:

- :func:`swatches`: the chart, each patch split into reference and measured colour;
- :func:`delta_e_map`: ΔE00 as a heat map on the chart's layout (reversed *magma*);
- :func:`delta_e_bars`: ΔE00 per patch, with the mean and a limit;
- :func:`ab_arrows`: the a*b* plane, an arrow from each reference to its measurement, each
  point numbered; small errors are drawn magnified (the factor is in the title);
- :func:`tone_curve`: measured against reference L* of the neutral patches, with a fitted
  tone curve (gamma and exposure, :func:`fidelity.measure.colour.fit_tone`) where given;
- :func:`chart_location` / :func:`chart_pair`: where each patch was sampled in an image;
- :func:`prediction_curve` / :func:`family_curves`: the table's ΔE → loss curves with this
  chart's point and the limits;
- :func:`mtf_curves` / :func:`noise_curves`: luminance MTF curves with their MTF50, and the
  neutral patches' noise against signal with the photon-transfer line, one series per chart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.locate import CORNER_PATCHES, apply_homography
from fidelity.colour import colorimetry as cm
from fidelity.prediction.directional import load_directional_table
from fidelity.prediction.interpolate import predict_curve
from fidelity.prediction.properties import worst_case_losses
from fidelity.report.svg import (
    COLOURS,
    Axes,
    Canvas,
    Scale,
    hex_colour,
    luminance,
    magma_r,
    png_data_uri,
)

if TYPE_CHECKING:
    from fidelity.chart.locate import ChartLocation
    from fidelity.measure.colour import ChartMeasurement, ToneFit
    from fidelity.prediction.directional import DirectionalPrediction
    from fidelity.prediction.properties import PropertyPrediction, PropertyTable
    from fidelity.prediction.table import Prediction

#: Longest side of an image drawn under the sampling windows, px (the image is box-averaged
#: down to it; the page shows it at about this size).
IMAGE_PX = 900


def _grid(n: int) -> tuple[int, int]:
    """Rows and columns of a chart of ``n`` patches (4 x 6 for the Macbeth chart)."""
    return (4, 6) if n == 24 else (max(int(math.ceil(n / 6)), 1), 6)


def _colour(values: NDArray[np.float64] | None, k: int) -> str:
    return "#808080" if values is None else hex_colour(values[k])


def _title(c: Canvas, text: str, width: float) -> None:
    c.text(width / 2, 20, text, 13, "middle", weight="600")


def swatches(m: ChartMeasurement, labels: tuple[str, str] = ("reference", "measured")) -> str:
    """The chart, each patch split into reference (left half) and measured (right half), its
    number, name and ΔE00 under it; ``labels`` name the two halves in the title."""
    n = len(m.patch_names)
    rows, cols = _grid(n)
    cell, gapx, label_h, top = 96.0, 14.0, 34.0, 34.0
    width = cols * (cell + gapx) + gapx
    height = top + rows * (cell + label_h + 8) + 6
    c = Canvas(width, height, "the chart: reference against measured")
    c.rect(0, top - 4, width, height - top + 4, "#1e1f22")
    _title(c, f"{labels[0]} (left half) | {labels[1]} (right half) per patch", width)
    for k, name in enumerate(m.patch_names):
        r, col = divmod(k, cols)
        x0, y0 = gapx + col * (cell + gapx), top + 6 + r * (cell + label_h + 8)
        c.rect(x0, y0, cell / 2, cell, _colour(m.reference_srgb, k), crisp=True)
        c.rect(x0 + cell / 2, y0, cell / 2, cell, _colour(m.srgb, k), crisp=True)
        c.text(x0 + cell / 2, y0 + cell + 14, f"{k + 1} {name}", 11.5, "middle", "#f2f2f2")
        c.text(x0 + cell / 2, y0 + cell + 29, f"ΔE {m.delta_e[k]:.2f}", 11.5, "middle",
               "#f2f2f2", weight="600")
    return c.render()


def delta_e_map(m: ChartMeasurement, limit: float | None = None) -> str:
    """ΔE00 of each patch as a heat map on the chart's layout (value and name in each cell;
    with ``limit``, cells above it are outlined in red), with a colour bar."""
    n = len(m.patch_names)
    rows, cols = _grid(n)
    cw, ch, left, top = 82.0, 70.0, 8.0, 34.0
    bar_x = left + cols * cw + 18
    width, height = bar_x + 62, top + rows * ch + 12
    c = Canvas(width, height, "ΔE00 on the chart layout")
    title = "ΔE00 per patch on the chart"
    if limit is not None:
        title += f" (outlined: above the limit {limit:g})"
    _title(c, title, width)
    finite = m.delta_e[np.isfinite(m.delta_e)]
    vmax = max(float(finite.max()) if finite.size else 0.0, limit or 0.0, 1.0)
    for k, name in enumerate(m.patch_names):
        r, col = divmod(k, cols)
        v = float(m.delta_e[k])
        fill = magma_r(v / vmax)
        ink = "#fff" if luminance(fill) < 0.3 else "#000"
        x0, y0 = left + col * cw, top + r * ch
        c.rect(x0, y0, cw, ch, fill, crisp=True)
        c.text(x0 + cw / 2, y0 + ch * 0.42, f"{v:.2f}", 15, "middle", ink, "700")
        short = name if len(name) <= 13 else name[:12] + "…"
        c.text(x0 + cw / 2, y0 + ch * 0.75, short, 11, "middle", ink)
        if limit is not None and v > limit:
            c.rect(x0 + 3, y0 + 3, cw - 6, ch - 6, stroke=COLOURS["red"], width=2.5)
    c.rect(left, top, cols * cw, rows * ch, stroke="#333", width=1)
    stops = "".join(f'<stop offset="{i / 16:.4f}" stop-color="{magma_r(1 - i / 16)}"/>'
                    for i in range(17))
    gid = "fidelity-magma-r"  # the same gradient wherever it appears in a page
    c.group(f'<defs><linearGradient id="{gid}" x1="0" y1="0" x2="0" y2="1">{stops}'
            "</linearGradient></defs>")
    bar_h = rows * ch
    c.group(f'<rect x="{bar_x}" y="{top}" width="14" height="{bar_h}" fill="url(#{gid})" '
            'stroke="#333" stroke-width="0.5"/>')
    scale = Scale(0.0, vmax)
    for t in scale.ticks():
        py = top + bar_h * (1 - t / vmax)
        c.line(bar_x + 14, py, bar_x + 18, py, "#333")
        c.text(bar_x + 21, py, f"{t:g}", 11, baseline="middle")
    c.text(bar_x + 54, top + bar_h / 2, "ΔE00", 12, "middle", rotate=-90)
    return c.render()


def delta_e_bars(m: ChartMeasurement, limit: float | None = None) -> str:
    """ΔE00 per patch as bars coloured like the measured patch, with the mean and a limit."""
    de = np.asarray(m.delta_e, np.float64)
    n = len(de)
    width, height = 560.0, 322.0
    c = Canvas(width, height, "ΔE00 per patch")
    top = max(float(np.nanmax(de)) if n else 1.0, limit or 0.0, 0.5) * 1.08
    ax = Axes(c, 54, 14, width - 66, 190, Scale(-0.6, n - 0.4), Scale(0.0, top))
    ax.frame(ylabel="ΔE00", xticks=[])
    bw = ax.w / n * 0.78
    for k in range(n):
        x = float(ax.px(k))
        y = float(ax.py(float(de[k]) if np.isfinite(de[k]) else 0.0))
        c.rect(x - bw / 2, y, bw, ax.y + ax.h - y, _colour(m.srgb, k), "#000", 0.5)
        c.text(x + 4, ax.y + ax.h + 8, f"{k + 1} {m.patch_names[k]}", 11, "end", rotate=-60,
               baseline="middle")
    ax.hline(m.mean_delta_e, COLOURS["blue"], 1.2, "5 3", f"mean {m.mean_delta_e:.2f}")
    if limit is not None:
        ax.hline(limit, COLOURS["red"], 1.4, "2 2", f"limit {limit:g}")
    ax.legend("upper left")
    return c.render()


def _magnification(lengths: NDArray[np.float64], px_per_unit: float) -> int:
    """Factor that makes the median error arrow at least 14 px long (1, 2, 5, 10 or 20)."""
    finite = np.sort(lengths[np.isfinite(lengths)])  # np.median's first call imports np.ma
    n = finite.size
    med = float(finite[(n - 1) // 2] + finite[n // 2]) / 2.0 * px_per_unit if n else 0.0
    for k in (1, 2, 5, 10, 20):
        if med * k >= 14.0:
            return k
    return 20


def ab_arrows(m: ChartMeasurement, labels: tuple[str, str] = ("reference", "measured")) -> str:
    """The CIELAB a*b* plane: each patch's reference (a circle in its own colour, numbered)
    with an arrow to the measured colour (the arrow's tip). Arrows shorter than the markers
    would hide, so when the median error is under 14 px every error vector is drawn
    magnified by one factor (1, 2, 5, 10 or 20, named in the title); the circles stay at the
    true reference colours."""
    size = 520.0
    c = Canvas(size, size + 20, "a*b* errors")
    ref, meas = np.asarray(m.reference_lab, np.float64), np.asarray(m.lab, np.float64)
    both = np.concatenate([ref[:, 1:], meas[:, 1:]])
    both = both[np.all(np.isfinite(both), axis=1)]
    lim = max(10.0, float(np.max(np.abs(both))) * 1.12 if both.size else 10.0)
    lim = float(math.ceil(lim / 10.0) * 10.0)
    ax = Axes(c, 62, 36, size - 80, size - 80, Scale(-lim, lim), Scale(-lim, lim))
    ax.frame("a*", "b*")
    ax.hline(0, "#999", 0.8)
    ax.vline(0, "#999", 0.8)
    err = meas[:, 1:] - ref[:, 1:]
    k_mag = _magnification(np.hypot(err[:, 0], err[:, 1]), ax.w / (2 * lim))
    title = f"a*b*: {labels[0]} (circles) → {labels[1]} (arrow tips)"
    if k_mag > 1:
        title += f", errors drawn ×{k_mag}"
    _title(c, title, size)
    r = 6.5
    for k in range(len(m.patch_names)):
        if not np.all(np.isfinite(ref[k, 1:])):
            continue
        x0, y0 = float(ax.px(ref[k, 1])), float(ax.py(ref[k, 2]))
        c.circle(x0, y0, r, _colour(m.reference_srgb, k), "#000", 1)
    for k in range(len(m.patch_names)):
        if not (np.all(np.isfinite(ref[k, 1:])) and np.all(np.isfinite(err[k]))):
            continue
        x0, y0 = float(ax.px(ref[k, 1])), float(ax.py(ref[k, 2]))
        tip = ref[k, 1:] + k_mag * err[k]
        x1, y1 = float(ax.px(tip[0])), float(ax.py(tip[1]))
        c.arrow(x0, y0, x1, y1, "#000", 1.3, 7.0)
        # the number goes on the side away from the arrow
        dx, dy = x1 - x0, y1 - y0
        norm = math.hypot(dx, dy) or 1.0
        lx, ly = x0 - 13 * dx / norm, y0 - 13 * dy / norm
        if norm < 1.5:
            lx, ly = x0 + 11, y0 - 9
        c.text(lx, ly, str(k + 1), 11, "middle", baseline="middle", halo="#fff")
    return c.render()


def tone_curve(m: ChartMeasurement, neutral_indices: Sequence[int],
               fit: ToneFit | None = None) -> str:
    """Measured against reference L* of the neutral patches (the grey-scale tone curve),
    with the identity and, given ``fit``, the fitted power law
    (:class:`~fidelity.measure.colour.ToneFit`) drawn through them."""
    idx = list(neutral_indices)
    size = 440.0
    c = Canvas(size, size + 10, "tone curve of the neutral patches")
    _title(c, "tone curve of the neutral patches", size)
    ax = Axes(c, 62, 34, size - 84, size - 84, Scale(0.0, 100.0), Scale(0.0, 100.0))
    ax.frame("reference L*", "measured L*")
    ax.plot([0, 100], [0, 100], "#808080", 1, "4 3", "identity")
    if fit is not None:
        lref = np.linspace(0.5, 100.0, 200)
        y_ref = np.asarray(cm.lab_to_xyz(np.stack([lref, 0 * lref, 0 * lref], axis=1))[:, 1],
                           np.float64)
        y_fit = fit.predict(y_ref / float(cm.WHITEPOINT_D65_XYZ[1]))
        l_fit = cm.xyz_to_lab(np.repeat(y_fit[:, None], 3, axis=1), white=(1.0, 1.0, 1.0))
        ax.plot(lref, np.asarray(l_fit[:, 0], np.float64), COLOURS["orange"], 1.6, None,
                f"fit: gamma {fit.gamma:.2f}, {fit.offset_ev:+z.2f} EV")
    ref_l = np.asarray(m.reference_lab, np.float64)[idx, 0]
    meas_l = np.asarray(m.lab, np.float64)[idx, 0]
    order = np.argsort(ref_l)
    ax.plot(ref_l[order], meas_l[order], "#000", 1.5, None, "measured")
    for k, i in enumerate(idx):
        if np.isfinite(ref_l[k]) and np.isfinite(meas_l[k]):
            ax.marker(float(ref_l[k]), float(meas_l[k]), "#000", 4.5)
            right = ref_l[k] > 70  # near the right edge the label goes left of the point
            c.text(float(ax.px(ref_l[k])) + (-9 if right else 7),
                   float(ax.py(meas_l[k])) + (4 if right else 14),
                   f"{i + 1} {m.patch_names[i]}", 11, "end" if right else "start",
                   halo="#fff")
    ax.legend("upper left")
    return c.render()


def _display(pixels: NDArray[Any], encoding: str, exposure_ev: float
             ) -> tuple[NDArray[np.float64], float]:
    """The image box-averaged to at most :data:`IMAGE_PX` on its long side, shown as sRGB
    (linear pixels at ``2**exposure_ev``, NaN/Inf black); and the scale factor used."""
    arr = np.asarray(pixels)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    arr = arr[:, :, :3]
    h, w = arr.shape[:2]
    step = max(1, int(math.ceil(max(h, w) / IMAGE_PX)))
    hh, ww = (h // step) * step or h, (w // step) * step or w
    small = np.asarray(arr[:hh, :ww], np.float64)
    small = np.where(np.isfinite(small), small, 0.0)
    if step > 1:
        small = small.reshape(hh // step, step, ww // step, step, 3).mean(axis=(1, 3))
    if encoding == "linear":
        small = np.asarray(cm.delinearize_srgb(np.clip(small * 2.0 ** exposure_ev, 0.0, 1.0)),
                           np.float64)
    return np.clip(small, 0.0, 1.0), float(step)


def _windows(c: Canvas, location: ChartLocation, scale: float, dx: float, dy: float,
             numbers: bool) -> None:
    """Outline every sampling window (white and dashed black) and number it."""
    half = location.window / 2.0
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    for k in range(location.rows * location.cols):
        r, col = divmod(k, location.cols)
        quad = apply_homography(location.homography, square + (col, r)) / scale
        pts = [(float(x) + dx, float(y) + dy) for x, y in quad]
        c.polygon(pts, stroke="#fff", width=1.2)
        c.polygon(pts, stroke="#000", width=1.2, dash="3 3")
        if numbers:
            cx, cy = np.asarray(location.centres[k], np.float64) / scale
            c.text(float(cx) + dx, float(cy) + dy, str(k + 1), 11, "middle", "#fff",
                   baseline="middle", halo="#000")


def chart_location(pixels: NDArray[Any], location: ChartLocation, *, encoding: str = "linear",
                   exposure_ev: float = 0.0, found: bool = False,
                   edges: Sequence[tuple[str, tuple[int, int, int, int]]] = ()) -> str:
    """The image with every patch's sampling window outlined and numbered; the corner patches
    are named, so a wrong orientation or a grid off the patches is seen at once. Linear pixels
    are shown at the audit's exposure (``2**exposure_ev``), sRGB-encoded; NaN/Inf as black.
    ``edges``: each measured edge's label and region ``(x0, y0, width, height)`` in pixels
    (:attr:`fidelity.measure.chartsharpness.EdgeSharpness.roi`), outlined in cyan."""
    img, scale = _display(pixels, encoding, exposure_ev)
    h, w = img.shape[:2]
    # shown at IMAGE_PX wide at most; small images are enlarged to at least 480 px
    zoom = min(IMAGE_PX / w, max(1.0, 480.0 / w))
    top = 30.0
    c = Canvas(w * zoom, h * zoom + top, "sampling windows")
    how = "found in the image" if found else "from --corners"
    _title(c, f"sampling windows ({location.window:g} patch pitch), corners {how}", w * zoom)
    c.image(0, top, w * zoom, h * zoom, png_data_uri(img))
    s = scale / zoom
    _windows(c, location, s, 0.0, top, numbers=True)
    for name, (x, y) in zip(CORNER_PATCHES, location.corners, strict=True):
        c.text(float(x) / s, float(y + location.pitch_px * 0.3) / s + top + 10, name, 11,
               "middle", "#ffeb3b", halo="#000")
    for label, (x0, y0, ew, eh) in edges:
        c.rect(x0 / s, y0 / s + top, ew / s, eh / s, stroke="#00e5ff", width=1.6)
        c.text(x0 / s, y0 / s + top - 3, label, 11, "start", "#00e5ff", halo="#000")
    return c.render()


def chart_pair(left: tuple[NDArray[Any], ChartLocation, str, float],
               right: tuple[NDArray[Any], ChartLocation, str, float],
               titles: tuple[str, str] = ("simulation", "real camera")) -> str:
    """Two charts side by side, each cropped to its chart with the sampling windows drawn:
    ``(pixels, location, encoding, exposure_ev)`` for each."""
    panel, gap, top = 440.0, 20.0, 30.0
    c = Canvas(2 * panel + gap, panel * 0.75 + top, "the two charts")
    for i, ((pixels, loc, encoding, ev), title) in enumerate(zip((left, right), titles,
                                                                  strict=True)):
        corners = apply_homography(loc.homography, np.array(
            [[-0.6, -0.6], [loc.cols - 0.4, -0.6], [loc.cols - 0.4, loc.rows - 0.4],
             [-0.6, loc.rows - 0.4]]))
        h, w = np.asarray(pixels).shape[:2]
        x0, y0 = (max(int(v), 0) for v in np.floor(corners.min(axis=0)))
        x1, y1 = int(min(np.ceil(corners[:, 0].max()), w - 1)), int(
            min(np.ceil(corners[:, 1].max()), h - 1))
        crop = np.asarray(pixels)[y0:y1 + 1, x0:x1 + 1]
        img, scale = _display(crop, encoding, ev)
        ih, iw = img.shape[:2]
        zoom = min(panel / iw, panel * 0.75 / ih)
        ox = i * (panel + gap) + (panel - iw * zoom) / 2
        c.text(i * (panel + gap) + panel / 2, 20, title, 13, "middle", weight="600")
        c.image(ox, top, iw * zoom, ih * zoom, png_data_uri(img))
        s = scale / zoom
        _windows(c, loc, s, ox - x0 / s, top - y0 / s, numbers=False)
    return c.render()


#: Prediction columns drawn by :func:`prediction_curve`: label, colour, dash.
_CURVE_STYLE: dict[str, tuple[str, str, str | None]] = {
    "dmap_points": ("ΔmAP (points)", COLOURS["red"], None),
    "dmap_relative": ("ΔmAP (% of baseline)", COLOURS["orange"], "6 3"),
    "dap_person_points": ("person ΔAP (points)", COLOURS["blue"], None),
    "dap_bicycle_points": ("bicycle ΔAP (points)", COLOURS["green"], None),
}


def _curve_canvas(label: str, title: str, xmax: float, ymax: float
                  ) -> tuple[Canvas, Axes]:
    c = Canvas(680, 380, label)
    _title(c, title, 680)
    ax = Axes(c, 64, 32, 596, 290, Scale(0.0, xmax), Scale(0.0, ymax, "symlog"))
    return c, ax


#: The units :func:`prediction_curve` draws on separate axes: its columns and the axis label.
_CURVE_UNITS: dict[str, tuple[tuple[str, ...], str]] = {
    "points": (("dmap_points", "dap_person_points", "dap_bicycle_points"),
               "predicted loss, percentage points of AP"),
    "relative": (("dmap_relative",), "predicted ΔmAP, % of the baseline mAP"),
}


def _se_band(prediction: Prediction, column: str, grid: NDArray[np.float64]
             ) -> NDArray[np.float64] | None:
    """The table's standard error of ``column`` along ``grid`` (linear between the points of
    the curve that answers the size class, the size-class curve first); None without SEs."""
    curves, _ = prediction.table.select(prediction.size)
    for c in sorted(curves, key=lambda c: c.model is not None):
        se = c.se(column)
        if se is not None and np.isfinite(se).any():
            ok = np.isfinite(se)
            return np.asarray(np.interp(grid, c.delta_e[ok], se[ok], right=np.nan),
                              dtype=np.float64)
    return None


def prediction_curve(prediction: Prediction, limit_dmap: float | None = None,
                     limit_delta_e: float | None = None, unit: str = "points") -> str:
    """The table's ΔE → loss curves of one ``unit`` (``points``: ΔmAP, person and bicycle ΔAP
    in percentage points; ``relative``: ΔmAP in % of the baseline), each with its ± 1 SE band
    (the table's stated standard error, k = 1) and this chart's point on each; a limit in
    that unit as a horizontal line, a ΔE limit as a vertical one (symlog loss axis: linear
    below 1, logarithmic above, labelled with its unit)."""
    columns, ylabel = _CURVE_UNITS[unit]
    de = prediction.delta_e
    xmax = max(30.0, de * 1.2, (limit_delta_e or 0.0) * 1.2)
    grid = np.linspace(0.0, xmax, 301)
    c, ax = _curve_canvas(
        f"predicted loss against chart ΔE, {'percentage points' if unit == 'points' else '% of baseline'}",
        f"table {prediction.table.name} ({prediction.table.kind}"
        + (", upper bound" if prediction.table.kind.upper_bound else "")
        + f"), size {prediction.size_used}, {prediction.method}; y linear below 1, log above",
        xmax, 105.0)
    # the unit alone on the axis: a longer label outgrows the plot's height
    ax.frame("chart ΔE00 (mean over 24 patches)", ylabel,
             yticks=[0, 1, 2, 5, 10, 20, 50, 100])
    rng = prediction.columns["dmap_points"].delta_e_range
    if rng is not None and rng[1] < xmax:
        ax.span(rng[1], xmax, "#808080", 0.15, "beyond the table (ceiling)")
    points = []
    banded = False
    for col in columns:
        label, colour, dash = _CURVE_STYLE[col]
        y = predict_curve(grid, col, size=prediction.size, table=prediction.table,
                          method=prediction.method)
        if np.all(np.isnan(y)):
            continue
        se = _se_band(prediction, col, grid)
        if se is not None:
            ok = np.isfinite(se) & np.isfinite(y)
            xs, lo, hi = grid[ok], np.maximum(y[ok] - se[ok], 0.0), y[ok] + se[ok]
            ax.region(np.concatenate([xs, xs[::-1]]), np.concatenate([hi, lo[::-1]]), colour,
                      0.15, None if banded else "± 1 SE of the table (k=1)")
            banded = True
        ax.plot(grid, y, colour, 1.6, dash, label)
        v = prediction.columns[col].value
        if v is not None:
            points.append((v, colour))
    ax.vline(de, "#808080", 1, "2 3")
    if limit_dmap is not None:
        ax.hline(limit_dmap, "#000", 1.2, "2 2", f"limit {limit_dmap:g}")
    if limit_delta_e is not None:
        ax.vline(limit_delta_e, COLOURS["red"], 1.2, "7 3 2 3", f"ΔE limit {limit_delta_e:g}")
    for v, colour in points:
        ax.marker(de, v, colour, 5.5)
    c.text(float(ax.px(de)) + 6, ax.y + ax.h - 8, f"this chart: ΔE {de:.2f}", 12)
    ax.legend("lower right")
    return c.render()


def property_curve(prediction: PropertyPrediction, table: PropertyTable,
                   limit_x: float | None = None) -> str:
    """A property's worst-case loss against its axis (MTF50 linear, SNR logarithmic), with
    this chart's point and the limit equivalent to the ΔE limit as a vertical line."""
    sharp = prediction.axis == "mtf50"
    xs_cells = [c.x for m in table.models for c in table.cells[m]]
    lo = min(xs_cells) * 0.8 if xs_cells else 0.01
    hi = table.baseline_x * 1.05 if sharp else max(xs_cells) * 1.5 if xs_cells else 100.0
    grid = (np.linspace(lo, hi, 240) if sharp else np.geomspace(max(lo, 0.5), hi, 240))
    loss = worst_case_losses(table, grid, column=prediction.column)
    ymax = max(5.0, float(np.nanmax(loss)) * 1.2, prediction.loss * 1.2)
    c = Canvas(680, 380, f"predicted loss against {prediction.axis}")
    _title(c, f"table {table.name}: worst case over {len(table.models)} detectors", 680)
    ax = Axes(c, 64, 32, 596, 290, Scale(lo, hi, "linear" if sharp else "log"),
              Scale(0.0, ymax, "symlog"))
    ax.frame("MTF50 (cy/px at the detector's input)" if sharp else
             "SNR at 18 % grey (at the detector's input)", "predicted worst-case loss (points)",
             yticks=[v for v in (0, 1, 2, 5, 10, 20, 50, 100) if v <= ymax])
    ax.plot(grid, loss, COLOURS["blue"], 1.6, None, "worst case (all families)")
    for fam, colour in zip(sorted({c.family for m in table.models for c in table.cells[m]}),
                           (COLOURS["orange"], COLOURS["green"], COLOURS["purple"]),
                           strict=False):
        pts = sorted((c.x, c.losses.get(prediction.column) or 0.0)
                     for m in table.models for c in table.cells[m] if c.family == fam)
        for k, (x, y) in enumerate(pts):
            ax.marker(x, max(y, 0.0), colour, 3.5,
                      label=f"{fam} (measured cells)" if k == 0 else None)
    x = min(max(prediction.x, lo), hi)
    if limit_x is not None and lo <= limit_x <= hi:
        ax.vline(limit_x, COLOURS["red"], 1.2, "7 3 2 3", f"limit {limit_x:.3g}")
    ax.marker(x, prediction.loss, "#000", 6.0, label=f"this chart: {prediction.x:.3g}")
    ax.legend("upper right")
    return c.render()


#: Colours of the transform families in :func:`family_curves`.
_FAMILY_COLOURS = {"tone": COLOURS["blue"], "chroma": COLOURS["green"],
                   "hue": COLOURS["purple"], "contrast": COLOURS["red"],
                   "pull_mean": COLOURS["orange"]}


def family_curves(directional: DirectionalPrediction, classic: Prediction | None = None,
                  column: str = "dmap_points") -> str:
    """The direction-aware table's family curves (worst case of each transform family, line
    width growing with its weight) and the classic curve (worst over every transform), with
    this chart's classic and direction-aware predictions at its ΔE."""
    tab = load_directional_table(directional.table.get("path") or directional.table["name"])
    de = directional.delta_e
    xmax = max(24.0, de * 1.2)
    grid = np.linspace(0.0, xmax, 241)
    classic_y = predict_curve(grid, column, size=directional.size, table=tab.classic)
    curves = []
    weights = {t.family: t.weight for t in directional.terms}
    for fam, ftab in tab.families.items():
        fy = predict_curve(grid, column, size=directional.size, table=ftab)
        fc, _ = ftab.select(directional.size)
        end = min(float(cv.delta_e[-1]) for cv in fc)
        curves.append((fam, np.where(grid <= end, fy, np.nan), weights.get(fam, 0.0)))
    finite = [float(np.nanmax(y)) for y in [classic_y, *(cv[1] for cv in curves)]
              if np.any(np.isfinite(y))]
    ymax = max([1.0, *finite]) * 1.15
    c, ax = _curve_canvas(
        "worst case per transform family and the classic curve",
        f"direction-aware table {tab.name}: worst case per transform family, size "
        f"{directional.size_used}", xmax, ymax)
    ax.frame("chart ΔE00 (mean over 24 patches)", _CURVE_STYLE[column][0] + " predicted")
    ax.plot(grid, classic_y, "#000", 2.0, None, "classic: worst over every transform")
    for fam, fy, w in curves:
        ax.plot(grid, fy, _FAMILY_COLOURS.get(fam, "#808080"), 1.0 + 2.0 * w, None,
                f"{fam} (weight {100 * w:.0f} %)", opacity=0.9)
    ax.vline(de, "#808080", 1, "2 3")
    if classic is not None and classic.columns[column].value is not None:
        ax.marker(de, float(classic.columns[column].value or 0.0), "#000", 5.5, "s",
                  "this chart, classic")
    dv = directional.columns.get(column)
    if dv is not None:
        ax.marker(de, float(dv), COLOURS["gold"], 6.5, "o", "this chart, direction-aware")
    ax.legend("lower right")
    return c.render()


#: One chart's MTF curve for :func:`mtf_curves`: its label, frequencies (cy/px), MTF and MTF50
#: (cy/px; None: not reached).
MTFSeries = tuple[str, Sequence[float], Sequence[float], float | None]
#: One chart's noise for :func:`noise_curves`: its label, each neutral patch's mean and
#: standard deviation, and the photon-transfer line ``(read_variance, gain)`` (None: refused).
NoiseSeries = tuple[str, Sequence[float], Sequence[float], tuple[float, float] | None]
#: Colour and marker of the first, second, ... series of :func:`mtf_curves` and
#: :func:`noise_curves`.
_SERIES_STYLE = ((COLOURS["blue"], "o"), (COLOURS["orange"], "s"), (COLOURS["green"], "D"))


def mtf_curves(series: Sequence[MTFSeries], xmax: float = 0.5) -> str:
    """Luminance MTF curves on one plot (frequency 0 to ``xmax`` cy/px, MTF 0 to 1.05), each
    chart's MTF50 marked on its curve at 0.5 with a dotted vertical line, the MTF = 0.5 level
    as a grey line; the legend gives each curve's MTF50."""
    c = Canvas(680, 380, "luminance MTF against spatial frequency")
    _title(c, "luminance MTF of each chart's softer edge", 680)
    ax = Axes(c, 64, 32, 596, 290, Scale(0.0, xmax), Scale(0.0, 1.05))
    ax.frame("spatial frequency (cy/px)", "MTF", yticks=[0, 0.2, 0.4, 0.5, 0.6, 0.8, 1.0])
    ax.hline(0.5, "#808080", 1.0, "2 3")
    for k, (label, fs, mtf, mtf50) in enumerate(series):
        colour, shape = _SERIES_STYLE[k % len(_SERIES_STYLE)]
        f = np.asarray(fs, np.float64)
        keep = f <= xmax
        ax.plot(f[keep], np.asarray(mtf, np.float64)[keep], colour, 1.8,
                None if k == 0 else "6 3", label)
        if mtf50 is not None and 0.0 <= mtf50 <= xmax:
            ax.vline(mtf50, colour, 1.0, "1 3")
            ax.marker(mtf50, 0.5, colour, 5.5, shape, f"{label}: MTF50 {mtf50:.3g} cy/px")
    ax.legend("upper right")
    return c.render()


def noise_curves(series: Sequence[NoiseSeries]) -> str:
    """Noise against signal of the neutral patches: each chart's standard deviation against
    its mean (points) and its photon-transfer line ``sigma = sqrt(read_variance + gain mu)``
    where fitted (the legend says where refused)."""
    c = Canvas(680, 380, "noise against signal of the neutral patches")
    _title(c, "neutral patches: standard deviation against mean (photon transfer)", 680)
    mus = [float(v) for _, mu, _, _ in series for v in mu if math.isfinite(float(v))]
    sig = [float(v) for _, _, sg, _ in series for v in sg if math.isfinite(float(v))]
    xmax = max(max(mus, default=1.0) * 1.08, 1e-9)
    ymax = max(max(sig, default=0.0) * 1.2, 1e-9)
    ax = Axes(c, 72, 32, 588, 290, Scale(0.0, xmax), Scale(0.0, ymax))
    ax.frame("mean signal μ (linear, black level off)", "standard deviation σ")
    grid = np.linspace(0.0, xmax, 121)
    for k, (label, mu, sg, fit) in enumerate(series):
        colour, shape = _SERIES_STYLE[k % len(_SERIES_STYLE)]
        for j, (x, y) in enumerate(zip(mu, sg, strict=True)):
            ax.marker(float(x), float(y), colour, 4.5, shape,
                      (label if fit is not None else f"{label} (photon transfer refused)")
                      if j == 0 else None)
        if fit is not None:
            read_var, gain = fit
            ax.plot(grid, np.sqrt(np.maximum(read_var + gain * grid, 0.0)), colour, 1.4,
                    None if k == 0 else "6 3", f"{label}: σ² = {read_var:.3g} + {gain:.3g} μ")
    ax.legend("lower right")
    return c.render()


__all__ = [
    "IMAGE_PX",
    "MTFSeries",
    "NoiseSeries",
    "mtf_curves",
    "noise_curves",
    "ab_arrows",
    "chart_location",
    "chart_pair",
    "delta_e_bars",
    "delta_e_map",
    "family_curves",
    "prediction_curve",
    "swatches",
    "tone_curve",
]
