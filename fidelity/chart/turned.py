"""A 24-patch chart painted turned on the pixel grid, for the sharpness and noise measurements.

The ISO 12233:2017 e-SFR needs an edge turned at least 2 degrees from the pixel grid; a chart
painted on the grid (the closed-form render of :mod:`fidelity.camera.render`) has none. A
:class:`TurnedChart` is the 6 x 4 patch lattice under a rotation by ``angle_deg`` and a scale
of ``pitch_px`` pixels per patch, centred in an image of ``size`` (H, W) pixels. Each patch is
a square of ``patch_fraction`` of the pitch; the rest is the frame. Pixels are area-sampled:
``supersample`` x ``supersample`` points per pixel, box-averaged (a pixel aperture of one
pixel), so a painted edge is the ideal sampled step of a sharp camera.

Two users, one geometry: the sharpness and noise tables are calibrated on
:data:`CALIBRATION_GEOMETRY` with the reference chart's colours
(:mod:`fidelity.coco.tables.degradation`), and ``fidelity check`` paints the camera's own raw
patch values on the same geometry before the camera's optics, noise and development
(:func:`fidelity.camera.frame.render_frame`), so that a check's MTF50 and SNR are on the
tables' axes.

Lattice coordinates: ``(u, v)`` = (column, row) of a patch centre, ``u`` in 0..5, ``v`` in
0..3, row-major patch index ``6 v + u`` (dark skin first, black last).

Beside the chart, ``fidelity check`` renders an ISO 12233:2017 slanted-edge target
(:class:`PaintedEdgeTarget`, :data:`CHECK_EDGE_TARGET`: a 176 px square of reflectance 0.2
turned 5 degrees on a 0.8 field, 4:1) and measures the sharpness on its wide edges; the
patch edges between the chart's narrow gaps remain the tables' axis, onto which
:class:`fidelity.prediction.properties.TargetAxis` maps the target's MTF50.
"""

from __future__ import annotations

import io
import math
from dataclasses import astuple
from functools import lru_cache
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.core.fileio import write_bytes_atomic
from fidelity.core.record import record

__all__ = ["CALIBRATION_GEOMETRY", "CHECK_EDGE_TARGET", "COVERAGE_FILE", "PaintedEdgeTarget",
           "TurnedChart", "coverage_file_bytes", "write_coverage_file"]

#: Columns and rows of the lattice.
_COLS, _ROWS = 6, 4


@record
class TurnedChart:
    """The geometry of a turned chart (module docstring).

    Attributes
    ----------
    size
        Image ``(height, width)`` in pixels, each >= 8.
    angle_deg
        Rotation of the lattice, degrees (counter-clockwise in image ``(x, y)``, y down).
    pitch_px
        Distance between neighbouring patch centres, pixels (> 0).
    patch_fraction
        Patch side as a share of the pitch, in (0, 1).
    supersample
        Sampling points per pixel along each axis, >= 1.
    """

    size: tuple[int, int] = (480, 640)
    angle_deg: float = 5.0
    pitch_px: float = 90.0
    patch_fraction: float = 0.84
    supersample: int = 4

    def __post_init__(self) -> None:
        h, w = self.size
        if h < 8 or w < 8 or not self.pitch_px > 0 or not 0 < self.patch_fraction < 1 \
                or self.supersample < 1:
            raise ValueError(f"turned chart geometry out of its domain: {self}")

    def scaled(self, scale: int) -> TurnedChart:
        """The same chart at ``scale`` times the size and pitch (the same scene seen by a
        camera of ``scale`` times the resolution)."""
        h, w = self.size
        return TurnedChart((h * scale, w * scale), self.angle_deg, self.pitch_px * scale,
                           self.patch_fraction, self.supersample)

    def homography(self) -> NDArray[np.float64]:
        """The (3, 3) map from lattice ``(u, v, 1)`` to image ``(x, y, 1)`` (pixel centres at
        integer coordinates)."""
        h, w = self.size
        a = math.radians(self.angle_deg)
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c * self.pitch_px, -s * self.pitch_px],
                        [s * self.pitch_px, c * self.pitch_px]])
        t = np.array([(w - 1) / 2, (h - 1) / 2]) - rot @ np.array([(_COLS - 1) / 2,
                                                                     (_ROWS - 1) / 2])
        return np.array([[rot[0, 0], rot[0, 1], t[0]], [rot[1, 0], rot[1, 1], t[1]],
                         [0.0, 0.0, 1.0]])

    def corners(self) -> NDArray[np.float64]:
        """Image ``(x, y)`` of the centres of the dark skin, bluish green, black and white
        patches, ``(4, 2)``: the corners an audit takes."""
        uv = np.array([[0, 0], [_COLS - 1, 0], [_COLS - 1, _ROWS - 1], [0, _ROWS - 1]], float)
        p = np.c_[uv, np.ones(4)] @ self.homography().T
        return np.asarray(p[:, :2] / p[:, 2:], dtype=np.float64)

    def paint(self, patches: ArrayLike, frame: ArrayLike) -> NDArray[np.float64]:
        """The chart image ``(H, W, C)``: ``patches`` ``(24, C)`` values in lattice order and
        ``frame`` ``(C,)`` elsewhere, area-sampled (module docstring). Linear values in, linear
        values out (the box average is only meaningful in linear light)."""
        p = np.asarray(patches, dtype=np.float64)
        f = np.asarray(frame, dtype=np.float64).reshape(-1)
        if p.ndim != 2 or p.shape[0] != _COLS * _ROWS or f.shape != (p.shape[1],):
            raise ValueError(f"patches (24, C) and frame (C,) expected, got {p.shape} and "
                             f"{f.shape}")
        pure, mixed, samples = _coverage(self)
        table = np.vstack([p, f[None, :]])
        h, w = self.size
        out = table[pure].reshape(h * w, -1)
        out[mixed] = table[samples].mean(axis=1)
        return out.reshape(h, w, -1)


_Coverage = tuple[NDArray[np.uint8], NDArray[np.intp], NDArray[np.uint8]]

#: :data:`CALIBRATION_GEOMETRY`'s :func:`_coverage`, computed once and shipped (every
#: ``fidelity check`` paints that chart; computing it takes 0.07 s): its arrays with the
#: geometry they are of, read only where that geometry is the chart's
#: (tests/chart/test_turned.py computes it again and compares; :func:`coverage_file_bytes`
#: writes it).
COVERAGE_FILE = Path(__file__).resolve().parents[1] / "data" / "turned" / "coverage.npz"


def coverage_file_bytes(chart: TurnedChart | None = None) -> bytes:
    """The content of :data:`COVERAGE_FILE` for ``chart``.

    Parameters
    ----------
    chart
        The geometry (default :data:`CALIBRATION_GEOMETRY`).

    Returns
    -------
    bytes
        A compressed NumPy ``.npz``: the chart's pixel labels, mixed pixels and their samples'
        labels (computed, not read), with its geometry (height, width, ``angle_deg``,
        ``pitch_px``, ``patch_fraction``, ``supersample``).
    """
    chart = CALIBRATION_GEOMETRY if chart is None else chart
    labels, mixed, samples = _compute_coverage(chart)
    buf = io.BytesIO()
    np.savez_compressed(buf, geometry=np.array(_geometry_key(chart), np.float64),
                        labels=labels, mixed=mixed.astype(np.int64), samples=samples)
    return buf.getvalue()


def write_coverage_file(path: Path = COVERAGE_FILE) -> Path:
    """Write :func:`coverage_file_bytes` of :data:`CALIBRATION_GEOMETRY` atomically.

    Parameters
    ----------
    path
        Where (default :data:`COVERAGE_FILE`).

    Returns
    -------
    Path
        The file written.
    """
    return write_bytes_atomic(path, coverage_file_bytes())


def _geometry_key(chart: TurnedChart) -> tuple[float, ...]:
    h, w = chart.size
    return (float(h), float(w), *(float(v) for v in astuple(chart)[1:]))


def _shipped_coverage(chart: TurnedChart) -> _Coverage | None:
    """:data:`COVERAGE_FILE`'s arrays where they are of ``chart``'s geometry, else None."""
    if not COVERAGE_FILE.is_file():
        return None
    with np.load(COVERAGE_FILE) as d:
        if tuple(d["geometry"].tolist()) != _geometry_key(chart):
            return None
        labels = np.asarray(d["labels"], np.uint8)
        mixed = np.asarray(d["mixed"], np.intp)
        samples = np.asarray(d["samples"], np.uint8)
    h, w = chart.size
    n = chart.supersample
    if labels.shape != (h, w) or samples.shape != (mixed.size, n * n):
        return None
    for a in (labels, mixed, samples):
        a.setflags(write=False)
    return labels, mixed, samples


@lru_cache(maxsize=4)
def _coverage(chart: TurnedChart) -> _Coverage:
    """:func:`_compute_coverage` of ``chart``, read from :data:`COVERAGE_FILE` where it holds
    that geometry's."""
    shipped = _shipped_coverage(chart)
    return shipped if shipped is not None else _compute_coverage(chart)


def _compute_coverage(chart: TurnedChart) -> _Coverage:
    """Where each pixel's area lies: ``(pure, mixed, samples)``: the label (patch index
    0..23, 24 the frame) of every pixel ``(H, W)``; the flat indices ``(M,)`` of the pixels
    that a region boundary may cross; and their sampling points' labels ``(M, n * n)``.

    A pixel is pure when the circle about its centre through its corners (radius
    ``sqrt(2) / 2`` px) lies inside one region; only the others are supersampled."""
    h, w = chart.size
    hi = np.asarray(np.linalg.inv(chart.homography()), dtype=np.float64)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    labels, margin = _label(chart, hi, xs.ravel(), ys.ravel())
    mixed = np.flatnonzero(margin <= math.sqrt(0.5) / chart.pitch_px)
    n = chart.supersample
    offsets = (np.arange(n) + 0.5) / n - 0.5
    oy, ox = np.meshgrid(offsets, offsets, indexing="ij")
    px = (xs.ravel()[mixed, None] + ox.ravel()[None, :]).ravel()
    py = (ys.ravel()[mixed, None] + oy.ravel()[None, :]).ravel()
    samples, _ = _label(chart, hi, px, py)
    for a in (labels, mixed, samples):
        a.setflags(write=False)
    return labels.reshape(h, w), mixed, samples.reshape(mixed.size, n * n)


def _label(chart: TurnedChart, hi: NDArray[np.float64], x: NDArray[np.float64],
           y: NDArray[np.float64]) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """The region label of image points ``(x, y)`` and their distance, in lattice units, to
    the nearest region boundary (a lower bound where it is a lattice corner)."""
    u = hi[0, 0] * x + hi[0, 1] * y + hi[0, 2]
    v = hi[1, 0] * x + hi[1, 1] * y + hi[1, 2]
    col = np.clip(np.rint(u), 0, _COLS - 1)
    row = np.clip(np.rint(v), 0, _ROWS - 1)
    half = chart.patch_fraction / 2
    du, dv = np.abs(u - col), np.abs(v - row)
    inside = (du <= half) & (dv <= half)
    margin = np.where(inside, np.minimum(half - du, half - dv),
                      np.maximum(np.where(du > half, du - half, 0.0),
                                 np.where(dv > half, dv - half, 0.0)))
    labels = np.where(inside, row * _COLS + col, _COLS * _ROWS).astype(np.uint8)
    return labels, margin


#: The calibration chart's geometry: COCO's image size (640 x 480), turned 5 degrees, 90 px
#: pitch, patches 0.84 of it, 4 x 4 samples per pixel.
CALIBRATION_GEOMETRY = TurnedChart()


@record
class PaintedEdgeTarget:
    """An ISO 12233:2017 slanted-edge target painted on the pixel grid: a dark square of
    ``side_px`` pixels turned ``angle_deg`` (counter-clockwise in image ``(x, y)``, y down, as
    :class:`TurnedChart`), centred on a light field that fills an image of ``size`` (H, W).
    The square's coverage of each pixel is area-sampled on ``supersample`` x ``supersample``
    points (only where its boundary may cross the pixel), so its edges are the ideal sampled
    steps of a sharp camera (the pixel aperture's ``|sinc|``).

    Attributes
    ----------
    size
        Image ``(height, width)`` in pixels; the square must fit in it.
    side_px
        The square's side, pixels (> 0).
    angle_deg
        The square's turn from the pixel grid, degrees.
    dark, light
        The square's and the field's reflectances (spectrally flat, in (0, 1]; 0.2 and 0.8:
        ISO 12233:2017's 4:1 e-SFR contrast, as :mod:`fidelity.scene.model`'s target).
    supersample
        Sampling points per pixel along each axis at the boundary, >= 1.
    """

    size: tuple[int, int] = (320, 320)
    side_px: float = 176.0
    angle_deg: float = 5.0
    dark: float = 0.2
    light: float = 0.8
    supersample: int = 16

    def __post_init__(self) -> None:
        h, w = self.size
        reach = self.side_px * (abs(math.cos(math.radians(self.angle_deg)))
                                + abs(math.sin(math.radians(self.angle_deg)))) / 2
        if not (self.side_px > 0 and 2 * reach < min(h, w) and 0 < self.dark <= 1
                and 0 < self.light <= 1 and self.supersample >= 1):
            raise ValueError(f"edge target geometry out of its domain: {self}")

    @property
    def centre(self) -> tuple[float, float]:
        """Image ``(x, y)`` of the square's centre (the image's)."""
        h, w = self.size
        return (w - 1) / 2, (h - 1) / 2

    def square_corners(self) -> NDArray[np.float64]:
        """Image ``(x, y)`` of the square's corners ``(4, 2)``: top left, top right, bottom
        right, bottom left as seen (the order of
        :class:`fidelity.measure.chartsharpness.EdgeTargetCorners`)."""
        s = self.side_px / 2
        local = np.array([[-s, -s], [s, -s], [s, s], [-s, s]])
        a = math.radians(self.angle_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return np.asarray(local @ rot.T + np.asarray(self.centre), np.float64)

    def field_corners(self) -> NDArray[np.float64]:
        """Image ``(x, y)`` of the light field's corners ``(4, 2)``: the image's outer edges,
        the same order."""
        h, w = self.size
        return np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])

    def coverage(self) -> NDArray[np.float64]:
        """The share of each pixel's area ``(H, W)`` inside the square, in [0, 1]."""
        return _target_coverage(self)

    def paint(self, white: ArrayLike) -> NDArray[np.float64]:
        """The target image ``(H, W, C)`` in linear values: ``white`` ``(C,)`` (the response
        to a perfect white reflector) times :attr:`light` on the field and :attr:`dark` on the
        square, mixed by :meth:`coverage` (the box average is only meaningful in linear
        light)."""
        wv = np.asarray(white, dtype=np.float64).reshape(-1)
        cov = self.coverage()[..., None]
        out: NDArray[np.float64] = wv * (self.light + (self.dark - self.light) * cov)
        return out


@lru_cache(maxsize=4)
def _target_coverage(target: PaintedEdgeTarget) -> NDArray[np.float64]:
    h, w = target.size
    cx, cy = target.centre
    a = math.radians(target.angle_deg)
    c, s = math.cos(a), math.sin(a)
    half = target.side_px / 2

    def reach(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        # the square's own (u, v) coordinates: its inside is max(|u|, |v|) < half
        dx, dy = x - cx, y - cy
        out: NDArray[np.float64] = np.maximum(np.abs(c * dx + s * dy), np.abs(-s * dx + c * dy))
        return out

    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    r = reach(xs, ys)
    cov = (r < half).astype(np.float64)
    mixed = np.abs(r - half) <= math.sqrt(0.5)  # the boundary may cross the pixel
    n = target.supersample
    off = (np.arange(n) + 0.5) / n - 0.5
    oy, ox = np.meshgrid(off, off, indexing="ij")
    inside = reach(xs[mixed][:, None] + ox.ravel()[None, :],
                   ys[mixed][:, None] + oy.ravel()[None, :]) < half
    cov[mixed] = inside.mean(axis=1)
    cov.setflags(write=False)
    return cov


#: The slanted-edge target ``fidelity check`` renders beside its turned chart: a 176 px square
#: of reflectance 0.2 turned 5 degrees on a 0.8 field, 320 x 320 pixels.
CHECK_EDGE_TARGET = PaintedEdgeTarget()
