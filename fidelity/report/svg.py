"""A small SVG drawing kit for the report's figures: shapes, text, axes, scales, a colour map.

The chart report's figures (:mod:`fidelity.report.chartfigures`) are written as SVG text
straight from the numbers, so an HTML report costs milliseconds and no plotting library is
imported on the ``check``/``audit``/``gate`` path. Everything here is pure string building:

- :class:`Canvas`: an SVG document of a given size (pixels) with rectangles, lines, polylines
  (NaN breaks a line), circles, polygons, arrows (drawn as a line and a filled head, so no
  ``<marker>`` ids can collide between figures inlined in one page), text and raster images;
- :class:`Scale` (``linear``, ``log``, or ``symlog``: linear below 1, 1 + log10 above, like
  matplotlib's ``symlog`` with ``linthresh=1``) and :class:`Axes` (frame, ticks, grid, axis labels, a
  legend);
- :func:`nice_ticks` / :func:`symlog_ticks` / :func:`log_ticks`: tick positions; :func:`magma_r`: the reversed
  *magma* colour map (anchors sampled from matplotlib's); :func:`png_data_uri`: an RGB image as
  a PNG ``data:`` URI (zlib only).

Text is 11 px or larger at the figure's natural size (the page shows figures at that size or
scales them down only on narrow screens).
"""

from __future__ import annotations

import base64
import html
import math
import struct
import zlib
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from fidelity.core.record import record

#: The font stack of every figure (the page's own).
FONT = 'system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif'
#: Smallest text of any figure, px.
MIN_FONT_PX = 11
#: Colours of the named lines (matplotlib's tab10 values, so the figures look as before).
COLOURS = {"red": "#d62728", "orange": "#ff7f0e", "blue": "#1f77b4", "green": "#2ca02c",
           "purple": "#9467bd", "gold": "#ffd700", "grey": "#808080", "black": "#000000"}

#: matplotlib's ``magma`` at 17 evenly spaced points (0 .. 1).
_MAGMA = ("#000004", "#0a0822", "#1d1147", "#36106b", "#51127c", "#6a1c81", "#832681",
          "#9c2e7f", "#b73779", "#d0416f", "#e75263", "#f56b5c", "#fc8961", "#fea772",
          "#fec488", "#fde2a3", "#fcfdbf")


def _f(v: float) -> str:
    """A coordinate with two decimals, no trailing zeros."""
    s = f"{v:.2f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def hex_colour(rgb: Sequence[float] | NDArray[np.float64]) -> str:
    """``#rrggbb`` of an RGB triple in 0..1 (clipped; NaN as mid grey)."""
    a = np.asarray(rgb, np.float64)[:3]
    a = np.where(np.isfinite(a), np.clip(a, 0.0, 1.0), 0.5)
    r, g, b = (int(round(float(v) * 255)) for v in a)
    return f"#{r:02x}{g:02x}{b:02x}"


def _rgb(hexcode: str) -> NDArray[np.float64]:
    return np.array([int(hexcode[i:i + 2], 16) for i in (1, 3, 5)], np.float64) / 255.0


def magma_r(t: float) -> str:
    """The reversed *magma* colour map at ``t`` in 0..1 (0: pale yellow, 1: near black),
    linear between 17 anchors of matplotlib's map."""
    t = 1.0 - min(max(float(t), 0.0), 1.0) if math.isfinite(t) else 0.5
    x = t * (len(_MAGMA) - 1)
    i = min(int(x), len(_MAGMA) - 2)
    w = x - i
    return hex_colour((1 - w) * _rgb(_MAGMA[i]) + w * _rgb(_MAGMA[i + 1]))


def luminance(hexcode: str) -> float:
    """Relative luminance (0..1, sRGB-decoded) of ``#rrggbb``: dark fills take white text."""
    c = _rgb(hexcode)
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return float(lin @ np.array([0.2126, 0.7152, 0.0722]))


def png_data_uri(rgb: NDArray[np.float64]) -> str:
    """An RGB image ``(h, w, 3)`` in 0..1 as a ``data:image/png;base64,`` URI (8 bit, zlib)."""
    a = np.asarray(rgb, np.float64)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"png_data_uri needs an (h, w, 3) image, got shape {a.shape}")
    a8 = np.round(np.clip(np.where(np.isfinite(a), a, 0.0), 0.0, 1.0) * 255).astype(np.uint8)
    h, w = a8.shape[:2]
    raw = np.concatenate([np.zeros((h, 1), np.uint8), a8.reshape(h, 3 * w)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + chunk(b"IEND", b""))
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


class Canvas:
    """An SVG document ``width`` x ``height`` px; shapes are appended in drawing order."""

    def __init__(self, width: float, height: float, label: str = "") -> None:
        self.width, self.height, self.label = float(width), float(height), label
        self.parts: list[str] = []

    def rect(self, x: float, y: float, w: float, h: float, fill: str = "none",
             stroke: str | None = None, width: float = 1.0, opacity: float = 1.0,
             crisp: bool = False) -> None:
        """A rectangle (top-left ``x``, ``y``); ``crisp``: no anti-aliased edges (abutting
        colour fields without a seam)."""
        s = f' stroke="{stroke}" stroke-width="{_f(width)}"' if stroke else ""
        o = f' fill-opacity="{_f(opacity)}"' if opacity < 1 else ""
        e = ' shape-rendering="crispEdges"' if crisp else ""
        self.parts.append(f'<rect x="{_f(x)}" y="{_f(y)}" width="{_f(w)}" height="{_f(h)}" '
                          f'fill="{fill}"{o}{s}{e}/>')

    def line(self, x1: float, y1: float, x2: float, y2: float, stroke: str = "#000",
             width: float = 1.0, dash: str | None = None) -> None:
        """A straight line; ``dash`` an SVG dash array ("4 3")."""
        d = f' stroke-dasharray="{dash}"' if dash else ""
        self.parts.append(f'<line x1="{_f(x1)}" y1="{_f(y1)}" x2="{_f(x2)}" y2="{_f(y2)}" '
                          f'stroke="{stroke}" stroke-width="{_f(width)}"{d}/>')

    def polyline(self, xs: Sequence[float] | NDArray[np.float64],
                 ys: Sequence[float] | NDArray[np.float64], stroke: str = "#000",
                 width: float = 1.0, dash: str | None = None, opacity: float = 1.0) -> None:
        """A line through the points; a non-finite point breaks it into pieces."""
        d = f' stroke-dasharray="{dash}"' if dash else ""
        o = f' stroke-opacity="{_f(opacity)}"' if opacity < 1 else ""
        run: list[str] = []
        for x, y in [*zip(xs, ys, strict=True), (math.nan, math.nan)]:
            if math.isfinite(x) and math.isfinite(y):
                run.append(f"{_f(x)},{_f(y)}")
                continue
            if len(run) > 1:
                self.parts.append(f'<polyline points="{" ".join(run)}" fill="none" '
                                  f'stroke="{stroke}" stroke-width="{_f(width)}" '
                                  f'stroke-linejoin="round"{d}{o}/>')
            run = []

    def circle(self, cx: float, cy: float, r: float, fill: str = "#000",
               stroke: str | None = None, width: float = 1.0) -> None:
        """A circle (a marker)."""
        s = f' stroke="{stroke}" stroke-width="{_f(width)}"' if stroke else ""
        self.parts.append(f'<circle cx="{_f(cx)}" cy="{_f(cy)}" r="{_f(r)}" fill="{fill}"{s}/>')

    def polygon(self, points: Sequence[tuple[float, float]], fill: str = "none",
                stroke: str | None = None, width: float = 1.0, dash: str | None = None) -> None:
        """A closed polygon."""
        s = f' stroke="{stroke}" stroke-width="{_f(width)}"' if stroke else ""
        d = f' stroke-dasharray="{dash}"' if dash else ""
        pts = " ".join(f"{_f(x)},{_f(y)}" for x, y in points)
        self.parts.append(f'<polygon points="{pts}" fill="{fill}"{s}{d}/>')

    def arrow(self, x1: float, y1: float, x2: float, y2: float, stroke: str = "#000",
              width: float = 1.2, head: float = 7.0) -> None:
        """An arrow from (x1, y1) to (x2, y2): a line and a filled head of length ``head``
        (shortened to the arrow's own length when it is shorter)."""
        length = math.hypot(x2 - x1, y2 - y1)
        if length <= 1e-9:
            return
        ux, uy = (x2 - x1) / length, (y2 - y1) / length
        hl = min(head, length)
        bx, by = x2 - ux * hl, y2 - uy * hl
        hw = 0.45 * hl
        self.line(x1, y1, bx, by, stroke, width)
        self.polygon([(x2, y2), (bx - uy * hw, by + ux * hw), (bx + uy * hw, by - ux * hw)],
                     fill=stroke)

    def text(self, x: float, y: float, s: str, size: float = 12.0,
             anchor: Literal["start", "middle", "end"] = "start", fill: str = "#1d232b",
             weight: str = "normal", rotate: float | None = None,
             baseline: Literal["auto", "middle", "hanging"] = "auto",
             halo: str | None = None) -> None:
        """Text at (x, y) of ``size`` px (at least :data:`MIN_FONT_PX`); ``halo``: an outline
        colour that keeps it legible over a picture."""
        size = max(size, MIN_FONT_PX)
        attrs = [f'x="{_f(x)}" y="{_f(y)}" font-size="{_f(size)}"']
        if anchor != "start":
            attrs.append(f'text-anchor="{anchor}"')
        if baseline != "auto":
            attrs.append(f'dominant-baseline="{"central" if baseline == "middle" else baseline}"')
        if fill != "#1d232b":
            attrs.append(f'fill="{fill}"')
        if weight != "normal":
            attrs.append(f'font-weight="{weight}"')
        if rotate is not None:
            attrs.append(f'transform="rotate({_f(rotate)} {_f(x)} {_f(y)})"')
        if halo:
            attrs.append(f'stroke="{halo}" stroke-width="3" paint-order="stroke" '
                         f'stroke-linejoin="round"')
        self.parts.append(f'<text {" ".join(attrs)}>{html.escape(s, quote=False)}</text>')

    def image(self, x: float, y: float, w: float, h: float, uri: str) -> None:
        """A raster image (a ``data:`` URI) stretched over the rectangle, pixels kept sharp."""
        self.parts.append(f'<image x="{_f(x)}" y="{_f(y)}" width="{_f(w)}" height="{_f(h)}" '
                          f'preserveAspectRatio="none" style="image-rendering:pixelated" '
                          f'href="{uri}"/>')

    def group(self, svg: str) -> None:
        """Raw SVG markup (already escaped), e.g. a ``<linearGradient>`` definition."""
        self.parts.append(svg)

    def render(self) -> str:
        """The SVG element (inline in HTML, or a standalone ``.svg`` file)."""
        w, h = _f(self.width), _f(self.height)
        label = f' role="img" aria-label="{html.escape(self.label)}"' \
            if self.label else ""
        return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
                f'viewBox="0 0 {w} {h}"{label} font-family=\'{FONT}\' '
                f'fill="#1d232b" style="background:#fff">'
                + "".join(self.parts) + "</svg>")


def nice_ticks(lo: float, hi: float, target: int = 6) -> list[float]:
    """Ticks at 1, 2, 2.5 or 5 times a power of ten covering [lo, hi], about ``target`` of them."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(target - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    n = int(math.floor((hi - first) / step + 1e-9)) + 1
    return [round(first + i * step, 10) for i in range(n)]


def symlog_ticks(hi: float, lo: float = 0.0) -> list[float]:
    """Ticks of a symlog axis from ``lo`` (at most 0) to ``hi``: 0, then 1, 2, 5 per decade
    either side of it, ascending."""
    def side(top: float) -> list[float]:
        out, v = [], 1.0
        while v <= top * (1 + 1e-9):
            out += [m * v for m in (1.0, 2.0, 5.0) if m * v <= top * (1 + 1e-9)]
            v *= 10.0
        return out

    return [-t for t in reversed(side(-lo))] + [0.0] + side(hi)


def log_ticks(lo: float, hi: float) -> list[float]:
    """Ticks of a log axis over [``lo``, ``hi``] (``lo`` > 0): 1, 2, 5 per decade."""
    if not (lo > 0 and hi > lo):
        return []
    out, v = [], 10.0 ** math.floor(math.log10(lo))
    while v <= hi * (1 + 1e-9):
        out += [round(m * v, 12) for m in (1.0, 2.0, 5.0) if lo * (1 - 1e-9) <= m * v
                <= hi * (1 + 1e-9)]
        v *= 10.0
    return out


def tick_label(v: float) -> str:
    """A tick value as short plain text (0.5, 1, 10, 2.5)."""
    return f"{v:g}" if abs(v) < 1e6 else f"{v:.0e}"


@record
class Scale:
    """A data interval [``lo``, ``hi``] of a ``linear`` or ``symlog`` axis (symlog: linear
    below 1 in magnitude, 1 + log10 above: continuous with slope 1 at 1, like matplotlib's
    ``symlog`` with ``linthresh=1``)."""

    lo: float
    hi: float
    kind: Literal["linear", "symlog", "log"] = "linear"

    def transform(self, v: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """The axis coordinate of data value(s) ``v`` (before mapping to pixels); on a
        ``log`` axis log10, NaN at or below zero."""
        a = np.asarray(v, np.float64)
        if self.kind == "linear":
            return a
        if self.kind == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.asarray(np.where(a > 0, np.log10(np.where(a > 0, a, 1.0)), np.nan),
                                  np.float64)
        mag = np.abs(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(mag <= 1.0, a, np.sign(a) * (1.0 + np.log10(np.maximum(mag, 1.0))))
        return np.asarray(out, np.float64)

    def fraction(self, v: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """Where ``v`` lies along the axis, 0 at ``lo`` and 1 at ``hi``."""
        t0, t1 = (float(self.transform(x)) for x in (self.lo, self.hi))
        return (self.transform(v) - t0) / (t1 - t0 if t1 != t0 else 1.0)

    def ticks(self) -> list[float]:
        """Tick positions inside the interval."""
        if self.kind == "symlog":
            return [t for t in symlog_ticks(self.hi, min(self.lo, 0.0)) if t >= self.lo]
        if self.kind == "log":
            return log_ticks(self.lo, self.hi)
        return nice_ticks(self.lo, self.hi)


#: A legend entry: kind (``line``, ``box`` or a marker of :data:`MARKERS`), label, colour,
#: dash pattern, size (line width, marker size, or a box's opacity).
LegendEntry = tuple[str, str, str, str | None, float]

#: The point markers: circle, square, diamond, triangle up, triangle down.
MARKERS = ("o", "s", "D", "^", "v")


def shape_at(c: Canvas, shape: str, px: float, py: float, size: float, fill: str,
             edge: str = "#000", width: float = 1.0) -> None:
    """A marker of ``shape`` (:data:`MARKERS`; anything else a circle) centred at pixel
    (``px``, ``py``), reaching ``size`` px from its centre."""
    r = size
    if shape == "s":
        c.rect(px - r, py - r, 2 * r, 2 * r, fill, edge, width)
    elif shape == "D":
        c.polygon([(px, py - r), (px + r, py), (px, py + r), (px - r, py)], fill, edge, width)
    elif shape in ("^", "v"):
        d = -1.0 if shape == "^" else 1.0
        c.polygon([(px, py + d * r), (px + r, py - d * r * 0.75), (px - r, py - d * r * 0.75)],
                  fill, edge, width)
    else:
        c.circle(px, py, r, fill, edge, width)


class Axes:
    """A plot area of ``canvas`` at (``x``, ``y``), ``w`` x ``h`` px, with data scales."""

    def __init__(self, canvas: Canvas, x: float, y: float, w: float, h: float,
                 xscale: Scale, yscale: Scale) -> None:
        self.c, self.x, self.y, self.w, self.h = canvas, x, y, w, h
        self.xs, self.ys = xscale, yscale
        self.legend_entries: list[LegendEntry] = []

    def px(self, v: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """Pixel x of data x."""
        return self.x + self.w * self.xs.fraction(v)

    def py(self, v: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """Pixel y of data y (up is larger)."""
        return self.y + self.h * (1.0 - self.ys.fraction(v))

    def frame(self, xlabel: str = "", ylabel: str = "", grid: bool = True,
              xticks: Sequence[float] | None = None, yticks: Sequence[float] | None = None,
              ) -> None:
        """Background, grid, ticks with their labels, the frame and the axis labels."""
        c = self.c
        c.rect(self.x, self.y, self.w, self.h, fill="#fff")
        xt = list(self.xs.ticks() if xticks is None else xticks)
        yt = list(self.ys.ticks() if yticks is None else yticks)
        for t in xt:
            px = float(self.px(t))
            if grid:
                c.line(px, self.y, px, self.y + self.h, "#e3e6ea", 1)
            c.line(px, self.y + self.h, px, self.y + self.h + 4, "#333", 1)
            c.text(px, self.y + self.h + 17, tick_label(t), 12, "middle")
        for t in yt:
            py = float(self.py(t))
            if grid:
                c.line(self.x, py, self.x + self.w, py, "#e3e6ea", 1)
            c.line(self.x - 4, py, self.x, py, "#333", 1)
            c.text(self.x - 7, py, tick_label(t), 12, "end", baseline="middle")
        c.rect(self.x, self.y, self.w, self.h, stroke="#333", width=1)
        if xlabel:
            c.text(self.x + self.w / 2, self.y + self.h + 36, xlabel, 13, "middle")
        if ylabel:
            c.text(self.x - 44, self.y + self.h / 2, ylabel, 13, "middle", rotate=-90)

    def plot(self, xs: Sequence[float] | NDArray[np.float64],
             ys: Sequence[float] | NDArray[np.float64], colour: str, width: float = 1.5,
             dash: str | None = None, label: str | None = None, opacity: float = 1.0) -> None:
        """A line in data coordinates (clipped to the plot area by the frame's bounds)."""
        py = np.clip(self.py(np.asarray(ys, np.float64)), self.y, self.y + self.h)
        self.c.polyline(self.px(np.asarray(xs, np.float64)), py, colour, width, dash, opacity)
        if label:
            self.legend_entries.append(("line", label, colour, dash, width))

    def marker(self, x: float, y: float, colour: str, size: float = 5.0, shape: str = "o",
               label: str | None = None, edge: str = "#000") -> None:
        """A point marker of ``shape`` (:data:`MARKERS`), ``size`` px from its centre."""
        shape_at(self.c, shape, float(self.px(x)), float(self.py(y)), size, colour, edge)
        if label:
            self.legend_entries.append((shape, label, colour, None, size))

    def errorbar(self, xs: Sequence[float] | NDArray[np.float64],
                 ys: Sequence[float] | NDArray[np.float64],
                 yerr: Sequence[float] | NDArray[np.float64], colour: str, shape: str = "o",
                 size: float = 4.0, label: str | None = None) -> None:
        """Points with vertical error bars from ``y - yerr`` to ``y + yerr`` (:meth:`bars`);
        non-finite points are left out."""
        self.bars(xs, ys, yerr, yerr, colour, 1.0)
        for x, y in zip(xs, ys, strict=True):
            if math.isfinite(x) and math.isfinite(y):
                shape_at(self.c, shape, float(self.px(x)), float(self.py(y)), size, colour,
                         "#000", 0.6)
        if label:
            self.legend_entries.append((shape, label, colour, None, size))

    def bars(self, xs: Sequence[float] | NDArray[np.float64],
             ys: Sequence[float] | NDArray[np.float64],
             lower: Sequence[float] | NDArray[np.float64],
             upper: Sequence[float] | NDArray[np.float64], colour: str,
             width: float = 1.0) -> None:
        """Vertical error bars from ``y - lower`` to ``y + upper``, capped, clipped to the
        plot area (a cap at the area's edge is left off); bars of zero length and non-finite
        ends (e.g. at or below zero on a log axis) are left out."""
        top, bottom = self.y, self.y + self.h
        for x, y, lo, hi in zip(xs, ys, lower, upper, strict=True):
            if not all(math.isfinite(float(v)) for v in (x, y, lo, hi)) or lo + hi <= 0:
                continue
            ends = [float(self.py(v)) for v in (y - lo, y + hi)]
            if not all(math.isfinite(e) for e in ends):
                continue
            px = float(self.px(x))
            y0, y1 = (min(max(e, top), bottom) for e in ends)
            self.c.line(px, y0, px, y1, colour, width)
            for yy in (y0, y1):
                if top < yy < bottom:
                    self.c.line(px - 2.5, yy, px + 2.5, yy, colour, width)

    def region(self, xs: Sequence[float] | NDArray[np.float64],
               ys: Sequence[float] | NDArray[np.float64], colour: str, opacity: float,
               label: str | None = None) -> None:
        """A filled polygon through the data points (e.g. the area below a line)."""
        px, py = self.px(np.asarray(xs, np.float64)), self.py(np.asarray(ys, np.float64))
        py = np.clip(py, self.y, self.y + self.h)
        pts = " ".join(f"{_f(float(a))},{_f(float(b))}" for a, b in zip(px, py, strict=True))
        self.c.parts.append(f'<polygon points="{pts}" fill="{colour}" '
                            f'fill-opacity="{_f(opacity)}"/>')
        if label:
            self.legend_entries.append(("box", label, colour, None, opacity))

    def vline(self, x: float, colour: str, width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> None:
        """A vertical line across the plot area at data ``x``."""
        px = float(self.px(x))
        self.c.line(px, self.y, px, self.y + self.h, colour, width, dash)
        if label:
            self.legend_entries.append(("line", label, colour, dash, width))

    def hline(self, y: float, colour: str, width: float = 1.0, dash: str | None = None,
              label: str | None = None) -> None:
        """A horizontal line across the plot area at data ``y``."""
        py = float(self.py(y))
        self.c.line(self.x, py, self.x + self.w, py, colour, width, dash)
        if label:
            self.legend_entries.append(("line", label, colour, dash, width))

    def span(self, x0: float, x1: float, colour: str, opacity: float, label: str | None = None
             ) -> None:
        """A shaded vertical band from data ``x0`` to ``x1``."""
        p0, p1 = float(self.px(x0)), float(self.px(x1))
        self.c.rect(p0, self.y, p1 - p0, self.h, colour, opacity=opacity)
        if label:
            self.legend_entries.append(("box", label, colour, None, opacity))

    def legend(self, corner: Literal["lower right", "upper left", "upper right"] = "lower right"
               ) -> None:
        """The legend of every labelled element, in a box at ``corner`` of the plot area."""
        if not self.legend_entries:
            return
        c, row = self.c, 17.0
        width = 38 + 6.2 * max(len(e[1]) for e in self.legend_entries)
        height = row * len(self.legend_entries) + 8
        x0 = self.x + 8 if corner == "upper left" else self.x + self.w - width - 8
        y0 = self.y + 8 if corner.startswith("upper") else self.y + self.h - height - 8
        c.rect(x0, y0, width, height, "#fff", "#ccc", 1, opacity=0.92)
        for i, entry in enumerate(self.legend_entries):
            legend_entry(c, entry, x0, y0 + 4 + row * (i + 0.5))


def legend_entry(c: Canvas, entry: LegendEntry, x0: float, yy: float) -> float:
    """Draw one legend entry with its key at ``x0`` and its text's middle at ``yy``; returns
    the width it takes (about 6.2 px a character at 11 px)."""
    kind, label, colour, dash, size = entry
    if kind == "line":
        c.line(x0 + 6, yy, x0 + 26, yy, colour, size, dash)
    elif kind == "box":
        c.rect(x0 + 8, yy - 5, 16, 10, colour, "#999", 0.5, opacity=max(size, 0.3))
    else:
        shape_at(c, kind, x0 + 16, yy, 5, colour, "#000")
    c.text(x0 + 31, yy, label, 11, baseline="middle")
    return 38 + 6.2 * len(label)


def legend_column(c: Canvas, entries: Sequence[LegendEntry], x: float, y: float) -> None:
    """A legend as a column of ``entries`` from (``x``, ``y``) down, 17 px a row (e.g. to
    the right of a plot with many lines)."""
    for i, e in enumerate(entries):
        legend_entry(c, e, x, y + 17 * i)


def legend_row(c: Canvas, entries: Sequence[LegendEntry], y: float) -> int:
    """A legend as a row of ``entries`` centred across the canvas at height ``y`` (e.g. one
    legend for several panels, out of the data's way), wrapped onto further rows 17 px
    apart where the canvas is too narrow; returns the number of rows."""
    widths = [38 + 6.2 * len(e[1]) for e in entries]
    rows: list[list[int]] = [[]]
    for i, w in enumerate(widths):
        if rows[-1] and sum(widths[j] for j in rows[-1]) + w > c.width - 16:
            rows.append([])
        rows[-1].append(i)
    for r, row in enumerate(rows):
        x = (c.width - sum(widths[i] for i in row)) / 2
        for i in row:
            legend_entry(c, entries[i], x, y + 17 * r)
            x += widths[i]
    return len(rows)


__all__ = [
    "COLOURS",
    "FONT",
    "MARKERS",
    "MIN_FONT_PX",
    "Axes",
    "Canvas",
    "Scale",
    "LegendEntry",
    "hex_colour",
    "legend_column",
    "legend_entry",
    "legend_row",
    "log_ticks",
    "luminance",
    "magma_r",
    "nice_ticks",
    "png_data_uri",
    "shape_at",
    "symlog_ticks",
    "tick_label",
]
