"""Every figure of the chart report, as PNG bytes (matplotlib, Agg backend, no screen).

One place sets the backend and turns a figure into PNG bytes (:func:`new_figure`,
:func:`png_bytes`); the COCO, validation and benchmark reports use the same two. Chart figures
take a :class:`~fidelity.chart.measure.ChartMeasurement` (patches in row-major order):

- :func:`swatches`: the chart, each patch split into reference and measured colour;
- :func:`delta_e_map`: ΔE00 as a heat map on the chart's layout;
- :func:`delta_e_bars`: ΔE00 per patch, with the mean and a limit;
- :func:`ab_arrows`: the a*b* plane with an arrow from each reference to its measurement;
- :func:`tone_curve`: measured against reference L* of the neutral patches;
- :func:`chart_location`: where each patch was sampled in an image;
- :func:`prediction_curve`: the table's ΔE → loss curves with this chart's point and limits.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from fidelity.chart.locate import ChartLocation
    from fidelity.chart.measure import ChartMeasurement
    from fidelity.prediction.directional import DirectionalPrediction
    from fidelity.prediction.table import Prediction

#: Resolution of every PNG.
DPI = 110


def new_figure(width: float, height: float, nrows: int = 1, ncols: int = 1
               ) -> tuple[Figure, Any]:
    """A matplotlib figure and its axes (``plt.subplots``) on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=(width, height))


def png_bytes(fig: Figure, dpi: int = DPI) -> bytes:
    """The figure as PNG bytes (tight bounding box); the figure is closed."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _grid(n: int) -> tuple[int, int]:
    """Rows and columns of a chart of ``n`` patches (4 x 6 for the Macbeth chart)."""
    return (4, 6) if n == 24 else (int(np.ceil(n / 6)), 6)


def _clip01(values: NDArray[np.float64] | None, k: int) -> NDArray[np.float64]:
    if values is None:
        return np.full(3, 0.5)
    return np.clip(np.asarray(values[k], np.float64), 0.0, 1.0)


def swatches(m: ChartMeasurement, labels: tuple[str, str] = ("reference", "measured")
             ) -> bytes:
    """The chart, each patch split into reference (left half) and measured (right half);
    ``labels`` name the two halves in the title."""
    n = len(m.patch_names)
    rows, cols = _grid(n)
    cell, gap = 60, 16
    img = np.full((rows * (cell + gap) + gap, cols * (cell + gap) + gap, 3), 0.12)
    for k in range(n):
        r, c = divmod(k, cols)
        y0, x0 = gap + r * (cell + gap), gap + c * (cell + gap)
        img[y0:y0 + cell, x0:x0 + cell // 2] = _clip01(m.reference_srgb, k)
        img[y0:y0 + cell, x0 + cell // 2:x0 + cell] = _clip01(m.srgb, k)
    fig, ax = new_figure(7.2, 5.2)
    ax.imshow(img, interpolation="nearest")
    for k, name in enumerate(m.patch_names):
        r, c = divmod(k, cols)
        y0, x0 = gap + r * (cell + gap), gap + c * (cell + gap)
        ax.text(x0 + cell / 2, y0 + cell + gap * 0.5, f"{name}\nΔE {m.delta_e[k]:.2f}",
                ha="center", va="center", fontsize=5.5, color="white", linespacing=1.0)
    ax.set_title(f"{labels[0]} (left half) | {labels[1]} (right half) per patch", fontsize=9)
    ax.axis("off")
    return png_bytes(fig)


def delta_e_map(m: ChartMeasurement, limit: float | None = None) -> bytes:
    """ΔE00 of each patch as a heat map on the chart's layout (value written in each cell;
    with ``limit``, cells above it are outlined)."""
    n = len(m.patch_names)
    rows, cols = _grid(n)
    grid = np.full((rows, cols), np.nan)
    grid.ravel()[:n] = m.delta_e
    fig, ax = new_figure(7.0, 4.6)
    vmax = max(float(np.nanmax(grid)), limit or 0.0, 1.0)
    im = ax.imshow(grid, cmap="magma_r", vmin=0.0, vmax=vmax)
    for k, name in enumerate(m.patch_names):
        r, c = divmod(k, cols)
        v = float(m.delta_e[k])
        dark = v > 0.55 * vmax
        ax.text(c, r - 0.12, f"{v:.2f}", ha="center", va="center", fontsize=10,
                fontweight="bold", color="white" if dark else "black")
        ax.text(c, r + 0.25, name, ha="center", va="center", fontsize=6,
                color="white" if dark else "black")
        if limit is not None and v > limit:
            ax.add_patch(_rectangle(c - 0.47, r - 0.47, 0.94, 0.94))
    ax.set_xticks([])
    ax.set_yticks([])
    title = "ΔE00 per patch on the chart"
    if limit is not None:
        title += f" (outlined: above the limit {limit:g})"
    ax.set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.035, pad=0.02, label="ΔE00")
    return png_bytes(fig)


def _rectangle(x: float, y: float, w: float, h: float) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((x, y), w, h, fill=False, edgecolor="tab:red", linewidth=2.2)


def delta_e_bars(m: ChartMeasurement, limit: float | None = None) -> bytes:
    """ΔE00 per patch as bars coloured like the measured patch, with the mean and a limit."""
    de = m.delta_e
    fig, ax = new_figure(8.5, 3.4)
    colours = [_clip01(m.srgb, k) for k in range(len(de))]
    ax.bar(range(len(de)), de, color=colours, edgecolor="black", linewidth=0.5)
    ax.axhline(m.mean_delta_e, color="tab:blue", ls="--", lw=1,
               label=f"mean {m.mean_delta_e:.2f}")
    if limit is not None:
        ax.axhline(limit, color="tab:red", ls=":", lw=1.2, label=f"limit {limit:g}")
    ax.set_xticks(range(len(de)), list(m.patch_names), rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("ΔE00")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return png_bytes(fig)


def ab_arrows(m: ChartMeasurement, labels: tuple[str, str] = ("reference", "measured")
              ) -> bytes:
    """The CIELAB a*b* plane: each patch's reference (circle, its own colour) with an arrow to
    the measured colour; the direction of every hue and chroma error at a glance (``labels``
    name the two ends in the title)."""
    fig, ax = new_figure(6.4, 6.0)
    ref, meas = m.reference_lab, m.lab
    for k in range(len(m.patch_names)):
        colour = _clip01(m.reference_srgb, k) if m.reference_srgb is not None else "grey"
        ax.scatter(ref[k, 1], ref[k, 2], s=70, color=colour, edgecolor="black", zorder=3)
        ax.annotate("", xy=(meas[k, 1], meas[k, 2]), xytext=(ref[k, 1], ref[k, 2]),
                    arrowprops={"arrowstyle": "->", "color": "black", "lw": 1.0}, zorder=4)
        ax.scatter(meas[k, 1], meas[k, 2], s=14, color="black", zorder=5)
    lim = max(10.0, float(np.max(np.abs(np.concatenate([ref[:, 1:], meas[:, 1:]])))) * 1.1)
    ax.axhline(0, color="grey", lw=0.6)
    ax.axvline(0, color="grey", lw=0.6)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("a*")
    ax.set_ylabel("b*")
    ax.set_title(f"a*b*: {labels[0]} (circles) → {labels[1]} (dots)", fontsize=9)
    ax.grid(alpha=0.3)
    return png_bytes(fig)


def tone_curve(m: ChartMeasurement, neutral_indices: Sequence[int]) -> bytes:
    """Measured against reference L* of the neutral patches (the grey-scale tone curve),
    with the identity; a camera's tone error shows as distance from the diagonal."""
    idx = list(neutral_indices)
    fig, ax = new_figure(5.2, 4.6)
    ref_l, meas_l = m.reference_lab[idx, 0], m.lab[idx, 0]
    ax.plot([0, 100], [0, 100], color="grey", lw=0.8, ls="--", label="identity")
    order = np.argsort(ref_l)
    ax.plot(ref_l[order], meas_l[order], "o-", color="black", ms=5, label="neutral patches")
    for k, i in enumerate(idx):
        ax.annotate(m.patch_names[i], (ref_l[k], meas_l[k]), fontsize=6, xytext=(4, -8),
                    textcoords="offset points")
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    ax.set_aspect("equal")
    ax.set_xlabel("reference L*")
    ax.set_ylabel("measured L*")
    ax.set_title("tone curve of the neutral patches", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    return png_bytes(fig)


def chart_location(pixels: NDArray[Any], location: ChartLocation, *, encoding: str = "linear",
                   exposure_ev: float = 0.0, found: bool = False) -> bytes:
    """The image with every patch's sampling window outlined and numbered.

    Linear pixels are shown at the audit's exposure (``2**exposure_ev``), sRGB-encoded; NaN/Inf
    show as black. The corner patches are labelled, so a wrong orientation or a grid off the
    patches is seen at once.
    """
    from fidelity.chart.locate import CORNER_PATCHES, apply_homography
    from fidelity.colour import colorimetry as cm

    arr = np.asarray(pixels, dtype=np.float64)
    arr = np.where(np.isfinite(arr), arr, 0.0)
    if encoding == "linear":
        arr = np.asarray(cm.delinearize_srgb(np.clip(arr * 2.0 ** exposure_ev, 0.0, 1.0)),
                         dtype=np.float64)
    arr = np.clip(arr, 0.0, 1.0)
    height, width = arr.shape[:2]
    fig, ax = new_figure(7.2, 7.2 * height / max(width, 1))
    ax.imshow(arr, interpolation="antialiased")
    half = location.window / 2.0
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half],
                       [-half, -half]])
    cols = location.cols
    for k in range(location.rows * cols):
        r, c = divmod(k, cols)
        quad = apply_homography(location.homography, square + (c, r))
        ax.plot(quad[:, 0], quad[:, 1], color="white", lw=0.8)
        ax.plot(quad[:, 0], quad[:, 1], color="black", lw=0.8, ls=(0, (2, 2)))
        ax.text(*location.centres[k], str(k + 1), ha="center", va="center", fontsize=6,
                color="white", bbox={"facecolor": "black", "alpha": 0.5, "pad": 0.5, "lw": 0})
    for name, (x, y) in zip(CORNER_PATCHES, location.corners, strict=True):
        ax.text(x, y + location.pitch_px * 0.3, name, fontsize=6, color="yellow", ha="center",
                va="top", bbox={"facecolor": "black", "alpha": 0.6, "pad": 0.5, "lw": 0})
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)
    how = "found in the image" if found else "from --corners"
    ax.set_title(f"sampling windows ({location.window:g} patch pitch), corners {how}", fontsize=9)
    ax.axis("off")
    return png_bytes(fig)


#: Prediction columns drawn by :func:`prediction_curve`: label, colour, line style.
_CURVE_STYLE: dict[str, tuple[str, str, str]] = {
    "dmap_points": ("ΔmAP (points)", "tab:red", "-"),
    "dmap_relative": ("ΔmAP (% of baseline)", "tab:orange", "--"),
    "dap_person_points": ("person ΔAP (points)", "tab:blue", "-"),
    "dap_bicycle_points": ("bicycle ΔAP (points)", "tab:green", "-"),
}


def prediction_curve(prediction: Prediction, limit_dmap: float | None = None,
                     limit_delta_e: float | None = None) -> bytes:
    """The table's ΔE → loss curves with this chart's point on each; a ΔmAP limit as a
    horizontal line, a ΔE limit as a vertical one."""
    from fidelity.prediction.table import predict_curve

    de = prediction.delta_e
    xmax = max(30.0, de * 1.2, (limit_delta_e or 0.0) * 1.2)
    grid = np.linspace(0.0, xmax, 601)
    fig, ax = new_figure(7.5, 4.2)
    for col, (label, colour, style) in _CURVE_STYLE.items():
        y = predict_curve(grid, col, size=prediction.size, table=prediction.table,
                          method=prediction.method)
        if np.all(np.isnan(y)):
            continue
        ax.plot(grid, y, color=colour, lw=1.3, label=label, ls=style)
        v = prediction.columns[col].value
        if v is not None:
            ax.plot([de], [v], "o", color=colour, ms=7, mec="black")
    ax.axvline(de, color="grey", lw=0.8, ls=":")
    ax.annotate(f"this chart: ΔE {de:.2f}", (de, 0), xytext=(5, 5), textcoords="offset points",
                fontsize=8)
    rng = prediction.columns["dmap_points"].delta_e_range
    if rng is not None and rng[1] < xmax:
        ax.axvspan(rng[1], xmax, color="grey", alpha=0.12, label="beyond the table (ceiling)")
    if limit_dmap is not None:
        ax.axhline(limit_dmap, color="black", ls=":", lw=1, label=f"limit {limit_dmap:g}")
    if limit_delta_e is not None:
        ax.axvline(limit_delta_e, color="tab:red", ls="-.", lw=1.1,
                   label=f"ΔE limit {limit_delta_e:g}")
    ax.set_xlabel("chart ΔE00 (mean over 24 patches)")
    ax.set_ylabel("predicted loss" + (" (upper bound)" if prediction.table.kind.upper_bound
                                      else ""))
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0, 105)
    ax.set_xlim(0, xmax)
    ax.set_title(f"table {prediction.table.name} ({prediction.table.kind}), detector size "
                 f"{prediction.size_used}, {prediction.method} interpolation", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return png_bytes(fig)


def family_curves(directional: DirectionalPrediction, classic: Prediction | None = None,
                  column: str = "dmap_points") -> bytes:
    """The direction-aware table's family curves (worst case of each transform family) and
    the classic curve (worst over every transform), with this chart's classic and
    direction-aware predictions at its ΔE."""
    from fidelity.prediction.directional import load_directional_table
    from fidelity.prediction.table import predict_curve

    tab = load_directional_table(directional.table.get("path") or directional.table["name"])
    de = directional.delta_e
    xmax = max(24.0, de * 1.2)
    grid = np.linspace(0.0, xmax, 481)
    fig, ax = new_figure(7.5, 4.2)
    y = predict_curve(grid, column, size=directional.size, table=tab.classic)
    ax.plot(grid, y, color="black", lw=1.6, label="classic: worst over every transform")
    styles = {"tone": "tab:blue", "chroma": "tab:green", "hue": "tab:purple",
              "contrast": "tab:red", "pull_mean": "tab:orange"}
    weights = {t.family: t.weight for t in directional.terms}
    for fam, ftab in tab.families.items():
        fy = predict_curve(grid, column, size=directional.size, table=ftab)
        curves, _ = ftab.select(directional.size)
        end = min(float(c.delta_e[-1]) for c in curves)
        fy = np.where(grid <= end, fy, np.nan)  # beyond its range a family is not drawn
        w = weights.get(fam, 0.0)
        ax.plot(grid, fy, color=styles.get(fam, "grey"), lw=1.0 + 2.0 * w,
                label=f"{fam} (weight {100 * w:.0f} %)", alpha=0.9)
    if classic is not None and classic.columns[column].value is not None:
        ax.plot([de], [classic.columns[column].value], "s", color="black", ms=7,
                label="this chart, classic")
    dv = directional.columns.get(column)
    if dv is not None:
        ax.plot([de], [dv], "o", color="gold", mec="black", ms=8,
                label="this chart, direction-aware")
    ax.axvline(de, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("chart ΔE00 (mean over 24 patches)")
    ax.set_ylabel(_CURVE_STYLE[column][0] + " predicted")
    ax.set_yscale("symlog", linthresh=1.0)
    axes_plain_ticks(ax)
    ax.set_xlim(0, xmax)
    ax.set_ylim(bottom=0)
    ax.set_title(f"direction-aware table {tab.name}: worst case per transform family, size "
                 f"{directional.size_used}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return png_bytes(fig)


def chart_pair(left: tuple[NDArray[Any], ChartLocation, str, float],
               right: tuple[NDArray[Any], ChartLocation, str, float],
               titles: tuple[str, str] = ("simulation", "real camera")) -> bytes:
    """Two charts side by side, each cropped to its chart with the sampling windows drawn:
    ``(pixels, location, encoding, exposure_ev)`` for each."""
    from fidelity.chart.locate import apply_homography
    from fidelity.colour import colorimetry as cm

    fig, axes = new_figure(11.0, 4.4, 1, 2)
    for ax, (pixels, loc, encoding, ev), title in zip(axes, (left, right), titles,
                                                       strict=True):
        arr = np.asarray(pixels, dtype=np.float64)
        arr = np.where(np.isfinite(arr), arr, 0.0)
        if encoding == "linear":
            arr = np.asarray(cm.delinearize_srgb(np.clip(arr * 2.0 ** ev, 0.0, 1.0)),
                             dtype=np.float64)
        arr = np.clip(arr, 0.0, 1.0)
        corners = apply_homography(loc.homography, np.array(
            [[-0.6, -0.6], [loc.cols - 0.4, -0.6], [loc.cols - 0.4, loc.rows - 0.4],
             [-0.6, loc.rows - 0.4]]))
        x0, y0 = np.floor(corners.min(axis=0)).astype(int)
        x1, y1 = np.ceil(corners.max(axis=0)).astype(int)
        h, w = arr.shape[:2]
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
        ax.imshow(arr[y0:y1 + 1, x0:x1 + 1], interpolation="antialiased",
                  extent=(x0 - 0.5, x1 + 0.5, y1 + 0.5, y0 - 0.5))
        half = loc.window / 2.0
        square = np.array([[-half, -half], [half, -half], [half, half], [-half, half],
                           [-half, -half]])
        for k in range(loc.rows * loc.cols):
            r, c = divmod(k, loc.cols)
            quad = apply_homography(loc.homography, square + (c, r))
            ax.plot(quad[:, 0], quad[:, 1], color="white", lw=0.7)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    return png_bytes(fig)


def axes_plain_ticks(ax: Axes) -> None:
    """Tick labels as plain numbers on the log and symlog axes of ``ax`` (0.5, 1, 10 rather
    than 10^0); a symlog axis (linear below 1) gets ticks at 1, 2 and 5 per decade. Linear
    axes are left as they are."""
    from matplotlib.ticker import FuncFormatter, SymmetricalLogLocator

    for axis in (ax.xaxis, ax.yaxis):
        scale = axis.get_scale()
        if scale == "symlog":
            axis.set_major_locator(SymmetricalLogLocator(base=10, linthresh=1.0,
                                                         subs=[1.0, 2.0, 5.0]))
        if scale in ("log", "symlog"):
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


__all__ = [
    "DPI",
    "ab_arrows",
    "axes_plain_ticks",
    "chart_location",
    "chart_pair",
    "delta_e_bars",
    "delta_e_map",
    "family_curves",
    "new_figure",
    "png_bytes",
    "prediction_curve",
    "swatches",
    "tone_curve",
]
