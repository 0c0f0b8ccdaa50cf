"""The sharpness of a located chart: the MTF of its patch edges, across one vertical and one
horizontal edge, per channel.

:func:`chart_sharpness` picks, among the pairs of neighbouring patches whose boundary runs
vertically in the image and among those whose boundary runs horizontally, the pair with the
largest luminance contrast (the patches' measured linear means), and measures the edge of the
pair's brighter patch that faces the other:

1. A luminance profile (linear light) along the line from the bright patch's centre to its
   neighbour's, through the chart's homography (nearest pixels, one sample per pixel, averaged
   over a band of 7 lines 0.3 pitch wide). The edge is where the profile, coming from the
   bright patch, first falls midway between the bright patch's level and the darkest level
   between the two centres (the gap between patches, or the neighbour itself where the chart
   has no gap). The patches being alike, the gap is centred between the two centres: it ends
   at ``1 - t_edge`` pitches (a gap narrower than :data:`MIN_GAP` pitch counts as none, the
   neighbour then the edge's far side).
2. A region of interest, an axis-aligned crop of the image centred on that point: across the
   edge at most :data:`HALF_ACROSS_PX` pixels either side and no more than
   :data:`ACROSS_FRACTION` of the gap (or of the way back to the patch's centre), so that it
   holds one edge; along the edge at most :data:`HALF_ALONG_PX` pixels either side and no more
   than :data:`ALONG_FRACTION` of the patch's side, away from its corners.
3. The edge's angle to the pixel grid (from the homography): turned at least
   :data:`ESFR_MIN_ANGLE_DEG` the ISO 12233:2017 e-SFR
   (:func:`fidelity.measure.sharpness.esfr`), else the erf edge fit
   (:func:`fidelity.measure.sharpness.edge_fit`); the method is recorded.
4. Per channel, R, G, B and the luminance Y: MTF50, MTF10 and the MTF at half Nyquist
   (0.25 cy/px). Their standard uncertainties: the e-SFR's bootstrap of MTF50 on Y
   (:data:`DRAWS` draws), for R, G and B that of Y scaled by the ratio of the channel's
   noise-to-contrast to Y's (the bootstrap's spread grows with it; not a bootstrap of its
   own); the edge fit's from the covariance of its ``sigma`` through the closed-form MTF. The
   e-SFR's MTF10 and MTF at half Nyquist carry no uncertainty (None: not evaluated).

An edge or a channel the method refuses (:class:`fidelity.measure.sharpness.RefusedEdge`: an
ROI too short across or along the edge for a small chart, clipped, a low SNR, a low MTF, the
edge at an angle beyond the e-SFR's) is recorded with its reason and message, never as a
number. Frequencies are in cycles per pixel along the edge normal.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from fidelity.chart.locate import ChartLocation, apply_homography
from fidelity.chart.turned import PaintedEdgeTarget
from fidelity.core.fileio import finite_or_none, optional_float
from fidelity.core.numeric import median
from fidelity.core.record import record
from fidelity.measure.sharpness import (
    HALF_NYQUIST,
    LUMINANCE_WEIGHTS,
    MAX_FREQUENCY,
    MIN_ACROSS_PX,
    MIN_EDGE_PX,
    NYQUIST,
    EdgeFit,
    EdgeSFR,
    Orientation,
    RefusedEdge,
    edge_fit,
    esfr,
)

#: Largest half-width of an ROI across its edge (pixels).
HALF_ACROSS_PX = 24
#: Largest half-length of an ROI along its edge (pixels).
HALF_ALONG_PX = 32
#: Share of the gap (or of the way back to the patch's centre) an ROI's half-width may take.
ACROSS_FRACTION = 0.8
#: Share of the patch's side the ROI's length along the edge may take.
ALONG_FRACTION = 0.5
#: Gaps between patches narrower than this (pitches) count as none.
MIN_GAP = 0.06
#: Edges turned at least this far from the pixel grid (degrees) are measured by the e-SFR.
ESFR_MIN_ANGLE_DEG = 2.0
#: Bootstrap draws of the e-SFR's MTF50 uncertainty on the luminance.
DRAWS = 20
#: Channels measured, in order.
CHANNELS = ("R", "G", "B", "Y")
#: Frequencies (0 to MAX_FREQUENCY) at which an edge fit's luminance MTF curve is kept.
FIT_CURVE_POINTS = 51
#: The two directions of measurement (across a vertical edge, across a horizontal one).
DIRECTIONS = ("horizontal", "vertical")
METHOD = ("the brightest-contrast neighbouring patches' edge per direction, an axis-aligned "
          "crop centred on it; e-SFR (ISO 12233:2017) where the edge is turned at least 2 "
          "degrees from the grid, else the erf edge fit; u of R, G, B's MTF50 from Y's "
          "bootstrap scaled by their noise-to-contrast ratio")

Linearise = Callable[[np.ndarray], np.ndarray]



@record
class ChannelMTF:
    """One channel's MTF figures at one edge.

    Attributes
    ----------
    channel
        ``"R"``, ``"G"``, ``"B"`` or ``"Y"``.
    mtf50, u_mtf50
        MTF50 (cy/px) and its standard uncertainty (k = 1; None: not evaluated).
    mtf10, u_mtf10
        MTF10 (cy/px; None: the curve stays above 0.1) and its uncertainty.
    mtf_half_nyquist, u_mtf_half_nyquist
        The MTF at 0.25 cy/px (unitless) and its uncertainty.
    snr
        The edge's contrast over its per-pixel noise (None: noiseless).
    refusal
        ``(reason, message)`` where the channel was refused (the numbers then None).
    curve
        The luminance channel's MTF curve, ``(frequencies, mtf)`` (cy/px, unitless), 0 to
        :data:`fidelity.measure.sharpness.MAX_FREQUENCY`: the e-SFR itself, or with an edge
        fit the fitted Gaussian's MTF on :data:`FIT_CURVE_POINTS` evenly spaced frequencies;
        None for R, G and B and where refused.
    """

    channel: str
    mtf50: float | None
    u_mtf50: float | None
    mtf10: float | None
    u_mtf10: float | None
    mtf_half_nyquist: float | None
    u_mtf_half_nyquist: float | None
    snr: float | None
    refusal: tuple[str, str] | None = None
    curve: tuple[tuple[float, ...], tuple[float, ...]] | None = None

    @property
    def above_nyquist(self) -> bool:
        """Whether ``mtf50`` is above the Nyquist frequency (0.5 cy/px,
        :data:`fidelity.measure.sharpness.NYQUIST`): measured (the pre-sampling MTF), but
        aliased in the sampled image."""
        return self.mtf50 is not None and self.mtf50 > NYQUIST

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; ``refusal`` as ``{reason, message}`` or None; ``curve`` as
        ``{frequencies, mtf}``, present only where there is one."""
        d: dict[str, Any] = {k: finite_or_none(getattr(self, k)) for k in (
            "mtf50", "u_mtf50", "mtf10", "u_mtf10", "mtf_half_nyquist", "u_mtf_half_nyquist",
            "snr")}
        out = {"channel": self.channel, **d,
               "refusal": ({"reason": self.refusal[0], "message": self.refusal[1]}
                           if self.refusal else None)}
        if self.curve is not None:
            out["curve"] = {"frequencies": list(self.curve[0]), "mtf": list(self.curve[1])}
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ChannelMTF:
        """Inverse of :meth:`to_json`."""
        ref = d.get("refusal")
        return cls(str(d["channel"]), optional_float(d.get("mtf50")), optional_float(d.get("u_mtf50")),
                   optional_float(d.get("mtf10")), optional_float(d.get("u_mtf10")),
                   optional_float(d.get("mtf_half_nyquist")), optional_float(d.get("u_mtf_half_nyquist")),
                   optional_float(d.get("snr")),
                   (str(ref["reason"]), str(ref["message"])) if ref else None,
                   ((tuple(float(f) for f in c["frequencies"]), tuple(float(m) for m in c["mtf"]))
                    if (c := d.get("curve")) else None))


@record
class EdgeSharpness:
    """The MTF of one chart edge (:func:`chart_sharpness`).

    Attributes
    ----------
    direction
        ``"horizontal"`` (measured across a vertical edge) or ``"vertical"`` (across a
        horizontal edge).
    patches
        The bright patch whose edge is measured and its neighbour.
    method
        ``"e-SFR"``, ``"edge fit"`` or None (refused before a method was chosen).
    angle
        The edge's angle to the pixel grid (degrees, from the homography).
    roi
        The crop ``(x0, y0, width, height)`` in pixels (None: none could be placed).
    channels
        R, G, B and Y's :class:`ChannelMTF` (empty where the edge was refused).
    refusal
        ``(reason, message)`` where the edge could not be measured at all.
    """

    direction: str
    patches: tuple[str, str]
    method: str | None
    angle: float
    roi: tuple[int, int, int, int] | None
    channels: tuple[ChannelMTF, ...]
    refusal: tuple[str, str] | None = None

    def channel(self, name: str) -> ChannelMTF | None:
        """The :class:`ChannelMTF` of ``name``; None if not measured."""
        return next((c for c in self.channels if c.channel == name), None)

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"direction": self.direction, "patches": list(self.patches),
                "method": self.method, "angle": finite_or_none(self.angle),
                "roi": list(self.roi) if self.roi else None,
                "channels": [c.to_json() for c in self.channels],
                "refusal": ({"reason": self.refusal[0], "message": self.refusal[1]}
                            if self.refusal else None)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EdgeSharpness:
        """Inverse of :meth:`to_json`."""
        ref = d.get("refusal")
        a, b = d["patches"]
        return cls(str(d["direction"]), (str(a), str(b)),
                   None if d.get("method") is None else str(d["method"]),
                   math.nan if d.get("angle") is None else float(d["angle"]),
                   tuple(int(v) for v in d["roi"]) if d.get("roi") else None,  # type: ignore[arg-type]
                   tuple(ChannelMTF.from_json(c) for c in d["channels"]),
                   (str(ref["reason"]), str(ref["message"])) if ref else None)


@record
class ChartSharpness:
    """The sharpness of a chart (:func:`chart_sharpness`).

    Attributes
    ----------
    edges
        One :class:`EdgeSharpness` per direction of :data:`DIRECTIONS` that had a candidate.
    linearisation
        How the pixels were brought to linear light.
    method
        :data:`METHOD`.
    """

    edges: tuple[EdgeSharpness, ...]
    linearisation: str
    method: str = METHOD

    def edge(self, direction: str) -> EdgeSharpness | None:
        """The edge measured in ``direction`` (``"horizontal"``/``"vertical"``); None."""
        return next((e for e in self.edges if e.direction == direction), None)

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``edges``, ``linearisation``, ``method``."""
        return {"edges": [e.to_json() for e in self.edges], "linearisation": self.linearisation,
                "method": self.method}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ChartSharpness:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(EdgeSharpness.from_json(e) for e in d["edges"]),
                   str(d["linearisation"]), str(d.get("method", METHOD)))


# --------------------------------------------------------------------------------------------


def _gauss_mtf(sigma: float, f: float) -> float:
    sinc = 1.0 if f == 0 else math.sin(math.pi * f) / (math.pi * f)
    return math.exp(-2.0 * math.pi ** 2 * sigma * sigma * f * f) * abs(sinc)


def _gauss_crossing(sigma: float, level: float) -> float | None:
    """First frequency (cy/px) where the Gaussian with the pixel aperture falls to ``level``
    (bisection; None if it stays above up to 0.999)."""
    if _gauss_mtf(sigma, 0.999) > level:
        return None
    lo, hi = 1e-9, 0.999
    while hi - lo > 1e-10:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _gauss_mtf(sigma, mid) > level else (lo, mid)
    return 0.5 * (lo + hi)


def _from_fit(name: str, fit: EdgeFit) -> ChannelMTF:
    s, u = fit.sigma, fit.u_sigma
    h = max(1e-4, 1e-3 * s)
    m10 = _gauss_crossing(s, 0.1)
    u10 = None
    if m10 is not None:
        a, b = _gauss_crossing(s + h, 0.1), _gauss_crossing(max(s - h, 0.0), 0.1)
        if a is not None and b is not None:
            u10 = abs(a - b) / (s + h - max(s - h, 0.0)) * u
    half = _gauss_mtf(s, HALF_NYQUIST)
    d_half = (_gauss_mtf(s + h, HALF_NYQUIST) - _gauss_mtf(max(s - h, 0.0), HALF_NYQUIST)) / (
        s + h - max(s - h, 0.0))
    snr = fit.contrast / fit.noise if fit.noise > 0 else math.inf
    curve = None
    if name == "Y":
        fs = tuple(float(f) for f in np.linspace(0.0, MAX_FREQUENCY, FIT_CURVE_POINTS))
        curve = (fs, tuple(_gauss_mtf(s, f) for f in fs))
    return ChannelMTF(name, fit.mtf50, fit.u_mtf50, m10, u10, half, abs(d_half) * u, finite_or_none(snr),
                      curve=curve)


def _from_sfr(name: str, sfr: EdgeSFR, u: float | None) -> ChannelMTF:
    return ChannelMTF(name, sfr.mtf50, u, sfr.mtf10, None, sfr.mtf_half_nyquist, None,
                      finite_or_none(sfr.snr),
                      curve=(tuple(sfr.frequencies), tuple(sfr.mtf)) if name == "Y" else None)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    wr, wg, wb = LUMINANCE_WEIGHTS
    out: np.ndarray = wr * rgb[..., 0] + wg * rgb[..., 1] + wb * rgb[..., 2]
    return out


def _profile(pixels: np.ndarray, linearise: Linearise, h: np.ndarray, a: np.ndarray,
             b: np.ndarray, samples: int) -> np.ndarray:
    """Luminance along grid points from ``a`` to ``b`` (``samples`` of them), averaged over
    7 lines across a band 0.3 pitch wide."""
    height, width = pixels.shape[:2]
    t = np.linspace(0.0, 1.0, samples)
    d = b - a
    normal = np.array([-d[1], d[0]])
    offsets = np.linspace(-0.15, 0.15, 7)
    uv = a + t[None, :, None] * d + offsets[:, None, None] * normal
    xy = apply_homography(h, uv.reshape(-1, 2))
    x = np.clip(np.rint(xy[:, 0]).astype(np.int64), 0, width - 1)
    y = np.clip(np.rint(xy[:, 1]).astype(np.int64), 0, height - 1)
    lin = linearise(np.asarray(pixels)[y, x])
    out: np.ndarray = _luminance(lin).reshape(len(offsets), samples).mean(axis=0)
    return out


def _measure_edge(pixels: np.ndarray, linearise: Linearise, loc: ChartLocation,
                  names: Sequence[str], bright: int, other: int, direction: str,
                  saturation: float | None, black: float | None) -> EdgeSharpness:
    h = loc.homography
    cols = loc.cols
    ua = np.array([bright % cols, bright // cols], dtype=np.float64)
    ub = np.array([other % cols, other // cols], dtype=np.float64)
    pair = (names[bright], names[other])
    samples = max(16, int(math.ceil(loc.pitch_px)) + 1)
    prof = _profile(pixels, linearise, h, ua, ub, samples)
    t = np.linspace(0.0, 1.0, samples)
    level = median(prof[t <= 0.2])
    low = float(prof[(t > 0.2) & (t < 0.9)].min())
    mid = 0.5 * (level + low)
    below = np.flatnonzero((prof < mid) & (t > 0.2))
    if not level > low or below.size == 0:
        return EdgeSharpness(direction, pair, None, math.nan, None, (),
                             ("flat", f"{pair[0]} / {pair[1]}: no edge between the patches"))
    i = int(below[0])
    te = float(t[i - 1] + (t[i] - t[i - 1]) * (prof[i - 1] - mid) / (prof[i - 1] - prof[i]))
    # the patches are alike and the gap between them centred between their centres: the gap
    # ends at 1 - te; no gap (the edge midway) leaves the neighbour's half to the ROI
    gap = 1.0 - 2.0 * te if 1.0 - 2.0 * te > MIN_GAP else 1.0 - te
    edge_uv = ua + te * (ub - ua)
    centre = apply_homography(h, edge_uv[None, :])[0]
    step = apply_homography(h, (edge_uv + 0.01 * (ub - ua))[None, :])[0] - centre
    along_dir = np.array([-(ub - ua)[1], (ub - ua)[0]])
    step_along = apply_homography(h, (edge_uv + 0.01 * along_dir)[None, :])[0] - centre
    px_per_grid = float(np.hypot(*step)) / 0.01
    vertical_edge = direction == "horizontal"
    angle = math.degrees(math.atan2(abs(step_along[0]), abs(step_along[1])) if vertical_edge
                         else math.atan2(abs(step_along[1]), abs(step_along[0])))
    half_across = int(min(HALF_ACROSS_PX,
                          math.floor(ACROSS_FRACTION * min(gap, te) * px_per_grid)))
    half_along = int(min(HALF_ALONG_PX,
                         math.floor(ALONG_FRACTION * te * px_per_grid)))  # side ~ 2 te pitch
    if 2 * half_across < MIN_ACROSS_PX or 2 * half_along < MIN_EDGE_PX:
        return EdgeSharpness(direction, pair, None, angle, None, (), (
            "too-short", f"{pair[0]} / {pair[1]}: the chart is too small for an edge ROI "
                         f"({2 * half_across} px across the edge, {2 * half_along} px along; "
                         f"need {MIN_ACROSS_PX} and {MIN_EDGE_PX})"))
    hx, hy = (half_across, half_along) if vertical_edge else (half_along, half_across)
    x0, y0 = int(round(centre[0])) - hx, int(round(centre[1])) - hy
    height, width = pixels.shape[:2]
    if x0 < 0 or y0 < 0 or x0 + 2 * hx > width or y0 + 2 * hy > height:
        return EdgeSharpness(direction, pair, None, angle, None, (), (
            "outside", f"{pair[0]} / {pair[1]}: the edge ROI reaches outside the image"))
    roi_box = (x0, y0, 2 * hx, 2 * hy)
    method, out = _edge_channels(pixels, linearise, roi_box, vertical_edge, saturation, black,
                                 angle)
    return EdgeSharpness(direction, pair, method, angle, roi_box, out)


def _edge_channels(pixels: np.ndarray, linearise: Linearise, roi_box: tuple[int, int, int, int],
                   vertical_edge: bool, saturation: float | None, black: float | None,
                   angle: float) -> tuple[str, tuple[ChannelMTF, ...]]:
    """The method and the R, G, B and Y :class:`ChannelMTF` of the edge in ``roi_box``."""
    x0, y0, w, h = roi_box
    roi = linearise(np.asarray(pixels)[y0:y0 + h, x0:x0 + w])
    chans = {"R": roi[..., 0], "G": roi[..., 1], "B": roi[..., 2], "Y": _luminance(roi)}
    orientation: Orientation = "vertical" if vertical_edge else "horizontal"
    use_esfr = angle >= ESFR_MIN_ANGLE_DEG
    out: list[ChannelMTF] = []
    if use_esfr:
        results: dict[str, EdgeSFR | tuple[str, str]] = {}
        for name in ("Y", "R", "G", "B"):
            try:
                results[name] = esfr(chans[name], orientation=orientation,
                                     saturation=saturation, black=black,
                                     draws=DRAWS if name == "Y" else 0)
            except RefusedEdge as e:
                results[name] = (e.reason, f"{name} channel {e}")
        y = results["Y"]
        for name in CHANNELS:
            r = results[name]
            if isinstance(r, tuple):
                out.append(ChannelMTF(name, None, None, None, None, None, None, None, r))
                continue
            u: float | None = None
            if isinstance(y, EdgeSFR) and y.u_mtf50 is not None:
                ratio = ((r.noise / r.contrast) / (y.noise / y.contrast)
                         if y.noise > 0 and r.contrast > 0 and y.contrast > 0 else 1.0)
                u = y.u_mtf50 if name == "Y" else y.u_mtf50 * ratio
            out.append(_from_sfr(name, r, u))
    else:
        for name in CHANNELS:
            try:
                out.append(_from_fit(name, edge_fit(chans[name], orientation=orientation,
                                                    saturation=saturation, black=black)))
            except RefusedEdge as e:
                out.append(ChannelMTF(name, None, None, None, None, None, None, None,
                                      (e.reason, f"{name} channel {e}")))
    return ("e-SFR" if use_esfr else "edge fit"), tuple(out)


def chart_sharpness(pixels: np.ndarray, location: ChartLocation,
                    luminance: Sequence[float] | np.ndarray,
                    names: Sequence[str], *, linearise: Linearise, linearisation: str,
                    saturation: float | None = None,
                    black: float | None = None) -> ChartSharpness:
    """The MTF of the chart's highest-contrast vertical and horizontal patch edges.

    Parameters
    ----------
    pixels
        The ``(H, W, 3)`` image as stored (any dtype); only the profile's pixels and the ROIs
        are read and linearised.
    location
        The chart's location (:func:`fidelity.chart.locate.locate_chart`).
    luminance
        Each patch's linear luminance (its mean), chart order: the pairs' contrast.
    names
        The patch names, chart order.
    linearise
        ``(..., 3)`` stored values -> float64 LINEAR R, G, B of the same shape.
    linearisation
        How ``linearise`` linearises (kept in the record).
    saturation, black
        The encoding's maximum and minimum in linear units (1.0 and 0.0 for an integer or
        encoded image; None for scene-linear floats): ROIs clipped there are refused.

    Returns
    -------
    ChartSharpness
        One :class:`EdgeSharpness` per direction, each channel's MTF50, MTF10 and MTF at half
        Nyquist with their uncertainties, or the refusal with its reason.
    """
    h = location.homography
    rows, cols = location.rows, location.cols
    y = np.asarray(luminance, dtype=np.float64)
    best: dict[str, tuple[float, int, int]] = {}
    for k in range(rows * cols):
        r, c = divmod(k, cols)
        for j in ((k + 1) if c + 1 < cols else None, (k + cols) if r + 1 < rows else None):
            if j is None:
                continue
            d = apply_homography(h, grid_point(j, cols)[None, :])[0] - \
                apply_homography(h, grid_point(k, cols)[None, :])[0]
            direction = "horizontal" if abs(d[0]) >= abs(d[1]) else "vertical"
            contrast = abs(float(y[k] - y[j]))
            if direction not in best or contrast > best[direction][0]:
                bright, other = (k, j) if y[k] >= y[j] else (j, k)
                best[direction] = (contrast, bright, other)
    edges = tuple(_measure_edge(pixels, linearise, location, names, best[d][1], best[d][2], d,
                                saturation, black) for d in DIRECTIONS if d in best)
    return ChartSharpness(edges, linearisation)


@record
class EdgeTargetCorners:
    """A slanted-edge target's corners in the image (a chart scene's manifest gives them:
    :func:`fidelity.scene.manifest.read_manifest`).

    Attributes
    ----------
    square
        The dark square's four corners ``(x, y)`` in pixels (pixel (row i, column j) at
        x = j, y = i): top left, top right, bottom right, bottom left as seen.
    field
        The light field's four corners around it, the same order.
    source
        Where the corners came from (kept in the record).
    """

    square: tuple[tuple[float, float], ...]
    field: tuple[tuple[float, float], ...]
    source: str = "manifest"

    def __post_init__(self) -> None:
        for name in ("square", "field"):
            pts = np.asarray(getattr(self, name), np.float64)
            if pts.shape != (4, 2) or not np.all(np.isfinite(pts)):
                raise ValueError(f"edge target {name}: need 4 finite (x, y) corners")


#: Share of the square's side an edge ROI may take along the edge (centred, away from its
#: corners).
TARGET_ALONG_FRACTION = 0.6
TARGET_METHOD = ("the slanted-edge target's square (corners given): its right edge for the "
                 "horizontal MTF and its bottom edge for the vertical, an axis-aligned crop "
                 "centred on each; e-SFR (ISO 12233:2017) where the edge is turned at least 2 "
                 "degrees from the grid, else the erf edge fit; u of R, G, B's MTF50 from Y's "
                 "bootstrap scaled by their noise-to-contrast ratio")


def target_sharpness(pixels: np.ndarray, target: EdgeTargetCorners, *, linearise: Linearise,
                     linearisation: str, saturation: float | None = None,
                     black: float | None = None, half_across: int = HALF_ACROSS_PX,
                     half_along: int = HALF_ALONG_PX) -> ChartSharpness:
    """The MTF of a slanted-edge target's square, across its right edge (``horizontal``) and
    its bottom edge (``vertical``), per channel, as :func:`chart_sharpness` measures a chart
    edge.

    Parameters
    ----------
    pixels
        The ``(H, W, 3)`` image as stored; only the ROIs are read and linearised.
    target
        The square's and the field's corners in pixels (:class:`EdgeTargetCorners`).
    linearise, linearisation, saturation, black
        As for :func:`chart_sharpness`.
    half_across, half_along
        The largest half-width of an ROI across its edge and half-length along it (pixels;
        :data:`HALF_ACROSS_PX` and :data:`HALF_ALONG_PX` unless told): a wider ROI holds more
        of a blurred edge's spread (the Hamming window's bias of MTF50 falls with it).

    Returns
    -------
    ChartSharpness
        Two :class:`EdgeSharpness` (``patches`` ``("edge target square", "edge target
        field")``), or their refusals: an ROI below the e-SFR's minimum size (the target too
        small in the image) or reaching outside the image. ``method`` :data:`TARGET_METHOD`.
    """
    sq = np.asarray(target.square, np.float64)
    fld = np.asarray(target.field, np.float64)
    height, width = pixels.shape[:2]
    pair = ("edge target square", "edge target field")
    edges = []
    # the right edge (top right -> bottom right) and the bottom one (bottom right -> left)
    for direction, (a, b) in (("horizontal", (1, 2)), ("vertical", (2, 3))):
        vertical_edge = direction == "horizontal"
        p, q = sq[a], sq[b]
        mid = (p + q) / 2
        d = q - p
        side = float(np.hypot(*d))
        angle = math.degrees(math.atan2(abs(d[0]), abs(d[1])) if vertical_edge
                             else math.atan2(abs(d[1]), abs(d[0])))
        # the light margin from the edge's midpoint to the field's edge beyond it
        margin = (float(fld[:, 0].max() - mid[0]) if vertical_edge
                  else float(fld[:, 1].max() - mid[1]))
        across = int(min(half_across, math.floor(ACROSS_FRACTION * min(margin, side / 2))))
        along = int(min(half_along, math.floor(TARGET_ALONG_FRACTION * side / 2)))
        if 2 * across < MIN_ACROSS_PX or 2 * along < MIN_EDGE_PX:
            edges.append(EdgeSharpness(direction, pair, None, angle, None, (), (
                "too-short", f"edge target: the target is too small in the image for an edge "
                             f"ROI ({2 * across} px across the edge, {2 * along} px "
                             f"along; need {MIN_ACROSS_PX} and {MIN_EDGE_PX})")))
            continue
        hx, hy = (across, along) if vertical_edge else (along, across)
        x0, y0 = int(round(mid[0])) - hx, int(round(mid[1])) - hy
        if x0 < 0 or y0 < 0 or x0 + 2 * hx > width or y0 + 2 * hy > height:
            edges.append(EdgeSharpness(direction, pair, None, angle, None, (), (
                "outside", "edge target: the edge ROI reaches outside the image")))
            continue
        roi_box = (x0, y0, 2 * hx, 2 * hy)
        method, channels = _edge_channels(pixels, linearise, roi_box, vertical_edge,
                                          saturation, black, angle)
        edges.append(EdgeSharpness(direction, pair, method, angle, roi_box, channels))
    return ChartSharpness(tuple(edges), linearisation, TARGET_METHOD)


#: Largest half-width across and half-length along its edge of an ROI on a painted edge
#: target (:func:`painted_target_sharpness`), pixels: the target's margin is wide, and a
#: 96 px-wide ROI keeps the Hamming window's bias of MTF50 within 1.4 % up to sigma = 4 px
#: (the chart's 48 px: 5.4 %).
PAINTED_HALF_ACROSS_PX = 48
PAINTED_HALF_ALONG_PX = 64


def painted_target_sharpness(pixels: np.ndarray, target: PaintedEdgeTarget, *,
                             linearise: Linearise, linearisation: str,
                             saturation: float | None = None, black: float | None = None,
                             source: str = "painted edge target") -> ChartSharpness:
    """The MTF of a painted slanted-edge target's square
    (:class:`fidelity.chart.turned.PaintedEdgeTarget`, its corners known) by
    :func:`target_sharpness` with ROIs up to :data:`PAINTED_HALF_ACROSS_PX` x
    :data:`PAINTED_HALF_ALONG_PX` half-sizes.

    Parameters
    ----------
    pixels
        The ``(H, W, 3)`` image of the target (``target.size``).
    target
        The target's geometry.
    linearise, linearisation, saturation, black
        As for :func:`chart_sharpness`.
    source
        Where the corners came from (kept in the corners' record).

    Returns
    -------
    ChartSharpness
        Its two edges (:func:`target_sharpness`).
    """
    corners = EdgeTargetCorners(
        tuple((float(x), float(y)) for x, y in target.square_corners()),
        tuple((float(x), float(y)) for x, y in target.field_corners()), source)
    return target_sharpness(pixels, corners, linearise=linearise, linearisation=linearisation,
                            saturation=saturation, black=black,
                            half_across=PAINTED_HALF_ACROSS_PX,
                            half_along=PAINTED_HALF_ALONG_PX)


def grid_point(k: int, cols: int) -> np.ndarray:
    """Grid ``(u, v)`` of patch ``k`` of a chart ``cols`` wide (row-major)."""
    return np.array([k % cols, k // cols], dtype=np.float64)


__all__ = ["ACROSS_FRACTION", "ALONG_FRACTION", "CHANNELS", "DIRECTIONS", "DRAWS", "FIT_CURVE_POINTS",
           "ESFR_MIN_ANGLE_DEG", "HALF_ACROSS_PX", "HALF_ALONG_PX", "METHOD", "MIN_GAP",
           "PAINTED_HALF_ACROSS_PX", "PAINTED_HALF_ALONG_PX", "ChannelMTF",
           "ChartSharpness", "EdgeSharpness", "EdgeTargetCorners", "TARGET_ALONG_FRACTION", "TARGET_METHOD",
           "chart_sharpness", "grid_point", "painted_target_sharpness", "target_sharpness"]
