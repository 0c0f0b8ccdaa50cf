"""COCO-C's colour corruptions on the chart ΔE scale.

COCO-C (Michaelis et al., "Benchmarking Robustness in Object Detection", 2019) corrupts COCO
images with the ``imagecorruptions`` package (Rusak & Mitzkus, after Hendrycks & Dietterich
2019) at severities 1-5. Three of its corruptions change only colour and tone, pixel by pixel
(or by a per-image statistic), so a colour chart measures them as it measures a camera
(x = image / 255 in float64):

- ``brightness``: HSV value V <- clip(V + c, 0, 1), c = 0.1, 0.2, 0.3, 0.4, 0.5;
- ``contrast``: per channel clip((x - mean) c + mean, 0, 1) with the image's mean,
  c = 0.4, 0.3, 0.2, 0.1, 0.05;
- ``saturate``: HSV saturation S <- clip(S a + b, 0, 1), (a, b) = (0.3, 0), (0.1, 0), (2, 0),
  (5, 0.1), (20, 0.2);

then ``clip(x, 0, 1) * 255`` truncated to uint8 (``imagecorruptions.corrupt`` returns
``np.uint8(...)``); HSV is scikit-image's ``rgb2hsv`` / ``hsv2rgb`` (hexcone; where two
channels share the maximum the later of R, G, B sets the hue). :func:`corrupt` implements these
definitions in numpy and equals the package bit for bit (tests compare them on random and COCO
images when ``imagecorruptions`` is installed: ``pip install scikit-image`` and ``pip install
--no-deps imagecorruptions==1.1.2``, whose ``opencv-python`` requirement would be a second
OpenCV build).

The other sixteen corruptions are left out on purpose: noise (gaussian, shot, impulse,
speckle) has zero mean and averages out of a patch mean, blur (defocus, glass, motion, zoom,
gaussian), pixelate, JPEG and elastic transform change spatial detail, and the weather
corruptions (snow, frost, fog, spatter) overlay random, spatially varying textures: a flat
chart's mean ΔE either misses them or depends on where the texture falls, so a chart ΔE would
not mean what it means for a camera.

The chart ΔE of a corruption (:func:`corruption_chart`) is measured like the SAFE-COLOR
calibration: the calibration chart (:data:`fidelity.colour.charts.DEFAULT_CHART`, reference
Lab -> sRGB clipped to [0, 1]) as an 8-bit image of 24 flat 32-pixel patches and nothing else
(so ``contrast`` pulls towards the chart's mean, as ``pull_mean`` does in the calibration), the
corruption applied to the image, each patch's colour read back and compared with the reference
in CIEDE2000.
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.coco.bounds import BoundCell, summarise_cells
from fidelity.coco.dataset import all_triples, colour_codes, to_uint8
from fidelity.coco.measure import MeasuredLoss, measure_mapping
from fidelity.coco.spatial import (
    AXIS_LABELS,
    CHART_DRAWS,
    IMAGECORRUPTIONS_VERSION,
    PARAMETERS,
    PROPERTY,
    SEVERITIES,
    SPATIAL_CORRUPTIONS,
    AxisValue,
    SpatialCorruption,
    chart_axis_value,
    check_severity,
    check_spatial,
    split_names,
)
from fidelity.coco.tables.degradation import calibration_chart
from fidelity.colour.charts import DEFAULT_CHART, load_chart
from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import json_ready
from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.core.version import __version__
from fidelity.measure.colour import measure_chart
from fidelity.prediction.directional import error_parts, predict_chart
from fidelity.prediction.properties import (
    PropertyPrediction,
    load_property_table,
    predict_property,
)
from fidelity.prediction.table import predict
from fidelity.prediction.tablefile import load_prediction_table

if TYPE_CHECKING:
    from fidelity.coco.bounds import BoundCell, ClassBounds
    from fidelity.measure.colour import ChartMeasurement

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

#: Parameters per severity 1-5 (imagecorruptions 1.1.2, ``corruptions.py``).
BRIGHTNESS: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5)
CONTRAST: tuple[float, ...] = (0.4, 0.3, 0.2, 0.1, 0.05)
SATURATE: tuple[tuple[float, float], ...] = ((0.3, 0.0), (0.1, 0.0), (2.0, 0.0), (5.0, 0.1),
                                             (20.0, 0.2))
#: The colour corruptions of COCO-C, in the package's order.
CORRUPTIONS: tuple[str, ...] = ("brightness", "contrast", "saturate")
#: Every corruption ``fidelity coco-c`` and ``predict --coco-c`` take: the colour ones on the
#: chart ΔE scale, the noise and blur ones (:mod:`fidelity.coco.spatial`) on the SNR and MTF50
#: scales.
ALL_CORRUPTIONS: tuple[str, ...] = CORRUPTIONS + SPATIAL_CORRUPTIONS
#: Side of a patch of the chart image, pixels.
PATCH_PX = 32


def _check(name: str, severity: int) -> None:
    if name not in CORRUPTIONS:
        raise unknown_name("colour corruption", name, CORRUPTIONS)
    check_severity(name, severity)


def check_any(name: str, severity: int) -> None:
    """An error unless ``name`` is one of :data:`ALL_CORRUPTIONS` and ``severity`` 1-5."""
    if name in SPATIAL_CORRUPTIONS:
        check_spatial(name, severity)
    elif name in CORRUPTIONS:
        _check(name, severity)
    else:
        raise unknown_name("COCO-C corruption", name, ALL_CORRUPTIONS)


def parse_corruption(spec: str) -> tuple[str, int]:
    """``"contrast:3"`` -> ``("contrast", 3)`` (any of :data:`ALL_CORRUPTIONS`); errors name
    the text."""
    name, _, sev = str(spec).partition(":")
    try:
        severity = int(sev)
    except ValueError:
        raise InvalidValueError(f"--coco-c {spec!r}: expected CORRUPTION:SEVERITY, e.g. "
                                f"contrast:3 (corruptions: {', '.join(ALL_CORRUPTIONS)}; "
                                "severities 1-5)") from None
    check_any(name.strip(), severity)
    return name.strip(), severity


# --------------------------------------------------------------------------------------------
# HSV as scikit-image computes it
# --------------------------------------------------------------------------------------------


def rgb_to_hsv_skimage(rgb: F64) -> F64:
    """RGB (..., 3) in [0, 1] -> HSV (..., 3), the operations of ``skimage.color.rgb2hsv``.

    V = max, S = (max - min) / max (0 where max = min), H from the channel holding the max
    (B over G over R when they tie), H = (h / 6) mod 1, 0 where max = min.
    """
    arr = np.asarray(rgb, dtype=np.float64)
    out = np.empty_like(arr)
    v = arr.max(-1)
    delta = np.ptp(arr, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = delta / v
        s[delta == 0.0] = 0.0
        idx = arr[..., 0] == v
        out[idx, 0] = (arr[idx, 1] - arr[idx, 2]) / delta[idx]
        idx = arr[..., 1] == v
        out[idx, 0] = 2.0 + (arr[idx, 2] - arr[idx, 0]) / delta[idx]
        idx = arr[..., 2] == v
        out[idx, 0] = 4.0 + (arr[idx, 0] - arr[idx, 1]) / delta[idx]
        h = (out[..., 0] / 6.0) % 1.0
    h[delta == 0.0] = 0.0
    out[..., 0] = h
    out[..., 1] = s
    out[..., 2] = v
    out[np.isnan(out)] = 0
    return out


def hsv_to_rgb_skimage(hsv: F64) -> F64:
    """HSV (..., 3) -> RGB (..., 3), the operations of ``skimage.color.hsv2rgb``."""
    arr = np.asarray(hsv, dtype=np.float64)
    hi = np.floor(arr[..., 0] * 6)
    f = arr[..., 0] * 6 - hi
    p = arr[..., 2] * (1 - arr[..., 1])
    q = arr[..., 2] * (1 - f * arr[..., 1])
    t = arr[..., 2] * (1 - (1 - f) * arr[..., 1])
    v = arr[..., 2]
    sector = hi.astype(np.uint8) % 6
    out = np.empty(arr.shape, dtype=np.float64)
    for k, (a, b, c) in enumerate(((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v),
                                   (v, p, q))):
        sel = sector == k
        out[sel, 0] = a[sel]
        out[sel, 1] = b[sel]
        out[sel, 2] = c[sel]
    return out


# --------------------------------------------------------------------------------------------
# The corruptions
# --------------------------------------------------------------------------------------------


def _truncate(x: F64) -> U8:
    """``np.uint8(clip(x, 0, 1) * 255)``: the package's float -> uint8 (truncation)."""
    out: U8 = (np.clip(x, 0, 1) * 255).astype(np.uint8)
    return out


def _hsv_corruption(x: F64, name: str, severity: int) -> F64:
    hsv = rgb_to_hsv_skimage(x)
    if name == "brightness":
        hsv[..., 2] = np.clip(hsv[..., 2] + BRIGHTNESS[severity - 1], 0, 1)
    else:
        a, b = SATURATE[severity - 1]
        hsv[..., 1] = np.clip(hsv[..., 1] * a + b, 0, 1)
    return hsv_to_rgb_skimage(hsv)


def contrast_means(rgb8: U8) -> F64:
    """The per-channel image mean of ``contrast`` (float64 of ``image / 255``, as the package
    computes it)."""
    x = np.asarray(rgb8) / 255.0
    means: F64 = np.mean(x, axis=(0, 1), keepdims=True)
    return means


def corrupt(rgb8: U8, name: str, severity: int) -> U8:
    """Apply a COCO-C colour corruption to an (H, W, 3) uint8 sRGB image (module docstring):
    the same numbers as ``imagecorruptions.corrupt(rgb8, severity, name)``.

    Parameters
    ----------
    rgb8
        The image: uint8 sRGB codes in [0, 255], shape (H, W, 3).
    name
        The corruption: ``brightness``, ``contrast`` or ``saturate`` (:data:`CORRUPTIONS`).
    severity
        COCO-C severity, an integer 1-5 (parameters :data:`BRIGHTNESS`, :data:`CONTRAST`,
        :data:`SATURATE`).

    Returns
    -------
    numpy.ndarray
        The corrupted image, uint8, shape (H, W, 3): ``clip(x, 0, 1) * 255`` truncated.

    Raises
    ------
    UnknownNameError
        ``name`` not a colour corruption. Exit code 2.
    InvalidValueError
        ``severity`` not 1-5, or an image that is not (H, W, 3) uint8. Exit code 2.

    References
    ----------
    C. Michaelis et al., *Benchmarking Robustness in Object Detection: Autonomous Driving
    when Winter is Coming*, 2019 (COCO-C); D. Hendrycks, T. Dietterich, *Benchmarking Neural
    Network Robustness to Common Corruptions and Perturbations*, ICLR 2019;
    ``imagecorruptions`` 1.1.2.
    """
    _check(name, severity)
    a = np.asarray(rgb8)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3) uint8, got {a.shape} {a.dtype}")
    x = a / 255.0
    if name == "contrast":
        c = CONTRAST[severity - 1]
        means = np.mean(x, axis=(0, 1), keepdims=True)
        return _truncate((x - means) * c + means)
    return _truncate(_hsv_corruption(x, name, severity))


@dataclass
class CorruptionMap:
    """A fast, exact 8-bit :func:`corrupt` for one (corruption, severity): ``brightness`` and
    ``saturate`` act on each pixel alone, so they are one look-up in a table of all 2^24
    colours (built once, 48 MiB); ``contrast`` depends on the image's mean, so it is three
    256-entry tables per image."""

    name: str
    severity: int
    build_seconds: float = 0.0
    _cube: U8 | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check(self.name, self.severity)

    def cube(self, chunk: int = 1 << 20) -> U8:
        """The (2^24, 3) table of a per-pixel corruption (``brightness``, ``saturate``)."""
        if self.name == "contrast":
            raise InvalidValueError("contrast depends on the image mean: it has no colour table")
        if self._cube is None:
            t0 = time.perf_counter()
            table = np.empty((1 << 24, 3), dtype=np.uint8)
            for s in range(0, 1 << 24, chunk):
                e = min(s + chunk, 1 << 24)
                table[s:e] = _truncate(_hsv_corruption(all_triples(s, e), self.name,
                                                       self.severity))
            self._cube = table
            self.build_seconds = time.perf_counter() - t0
        return self._cube

    def __call__(self, rgb8: U8) -> U8:
        a = np.asarray(rgb8)
        if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
            raise InvalidValueError(f"image must be (H, W, 3) uint8, got {a.shape} {a.dtype}")
        if self.name == "contrast":
            c = CONTRAST[self.severity - 1]
            means = contrast_means(a)[0, 0]
            levels = np.arange(256, dtype=np.float64) / 255.0
            out = np.empty_like(a)
            for ch in range(3):
                lut = _truncate((levels - means[ch]) * c + means[ch])
                out[..., ch] = lut[a[..., ch]]
            return out

        result: U8 = self.cube()[colour_codes(a)]
        return result

    @property
    def key(self) -> str:
        """The mapping key of the measurement store."""
        return f"coco-c:{self.name}:{self.severity}:imagecorruptions-{IMAGECORRUPTIONS_VERSION}"


# --------------------------------------------------------------------------------------------
# On the chart
# --------------------------------------------------------------------------------------------


def chart_image(srgb: F64, rows: int = 4, cols: int = 6, patch_px: int = PATCH_PX) -> U8:
    """An 8-bit image of flat patches (rows x cols, ``patch_px`` square, row-major order) of
    encoded sRGB colours (n, 3) in [0, 1], rounded to code values."""
    codes = to_uint8(np.asarray(srgb, dtype=np.float64)).reshape(rows, cols, 3)
    return np.ascontiguousarray(np.repeat(np.repeat(codes, patch_px, axis=0), patch_px, axis=1))


def patch_colours(image: U8, rows: int = 4, cols: int = 6, patch_px: int = PATCH_PX) -> F64:
    """The mean encoded sRGB (n, 3) of each flat patch of a :func:`chart_image`."""
    a = np.asarray(image, dtype=np.float64) / 255.0
    out: F64 = a.reshape(rows, patch_px, cols, patch_px, 3).mean(axis=(1, 3)).reshape(-1, 3)
    return out


def corruption_chart(name: str, severity: int, chart: str | None = None) -> Any:
    """The :class:`~fidelity.measure.colour.ChartMeasurement` of the calibration chart's 8-bit
    image after the corruption (module docstring): its ``mean_delta_e`` is the corruption's
    chart ΔE."""
    _check(name, severity)
    ch = load_chart(chart or DEFAULT_CHART)
    image = corrupt(chart_image(ch.srgb, ch.rows, ch.cols), name, severity)
    return measure_chart(patch_colours(image, ch.rows, ch.cols), ch.lab, ch.patch_names,
                         reference_srgb=ch.srgb)


def uncorrupted_chart_delta_e(chart: str | None = None) -> float:
    """The chart ΔE of the 8-bit chart image itself (gamut clipping and 8-bit rounding): the
    floor every corruption's chart ΔE starts from."""
    ch = load_chart(chart or DEFAULT_CHART)
    img = chart_image(ch.srgb, ch.rows, ch.cols)
    return float(delta_e_2000(srgb_to_lab(patch_colours(img, ch.rows, ch.cols)), ch.lab).mean())


# --------------------------------------------------------------------------------------------
# The COCO-C table: chart ΔE, prediction and measured loss per (corruption, severity)
# --------------------------------------------------------------------------------------------


#: Detector size class of the predictions a COCO-C cell records.
PREDICTION_SIZE = "n"


@record
class CellPrediction:
    """The predicted ΔmAP of a COCO-C cell's chart error for detector size ``size``, from the
    shipped tables: classic (worst case over the SAFE-COLOR transforms at the chart ΔE) and
    direction-aware (:mod:`fidelity.prediction.directional`), in percentage points and in %
    of the baseline mAP."""

    classic: float | None
    directional: float | None
    classic_relative: float | None
    directional_relative: float | None
    size: str = PREDICTION_SIZE

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"classic": self.classic, "directional": self.directional,
                "classic_relative": self.classic_relative,
                "directional_relative": self.directional_relative, "size": self.size}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CellPrediction:
        """Inverse of :meth:`to_json`."""
        return cls(d.get("classic"), d.get("directional"), d.get("classic_relative"),
                   d.get("directional_relative"), str(d.get("size", PREDICTION_SIZE)))


def predict_cell(measurement: ChartMeasurement, size: str = PREDICTION_SIZE) -> CellPrediction:
    """The classic and the direction-aware predicted ΔmAP of a corrupted chart (detector size
    ``size``), from the shipped tables."""
    classic = predict(measurement.mean_delta_e, size=size, transforms=False)
    d = predict_chart(measurement, size=size)
    return CellPrediction(classic.dmap_points, d.dmap_points, classic.dmap_relative,
                          d.dmap_relative, size)


@record
class CorruptionCell:
    """One (corruption, severity): its chart ΔE (mean, max, worst patch), the direction parts
    of the chart error (:class:`fidelity.prediction.directional.ErrorParts`, as JSON), the
    measured loss per detector (:class:`fidelity.coco.measure.MeasuredLoss`) and the loss
    predicted from the chart (:class:`CellPrediction`; None in a table written before it was
    recorded: :func:`with_predictions`)."""

    corruption: str
    severity: int
    parameter: Any
    chart_delta_e: float
    chart_max_delta_e: float
    worst_patch: str
    parts: Mapping[str, Any]
    measured: tuple[Any, ...] = ()
    prediction: CellPrediction | None = None

    def to_json(self) -> dict[str, Any]:
        """Field names as keys (``measured``, ``prediction``: their JSON)."""
        return {"corruption": self.corruption, "severity": self.severity,
                "parameter": self.parameter, "chart_delta_e": self.chart_delta_e,
                "chart_max_delta_e": self.chart_max_delta_e, "worst_patch": self.worst_patch,
                "parts": dict(self.parts), "measured": [m.to_json() for m in self.measured],
                "prediction": self.prediction.to_json() if self.prediction else None}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CorruptionCell:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["corruption"]), int(d["severity"]), _parameter_of(d),
                   float(d["chart_delta_e"]), float(d["chart_max_delta_e"]),
                   str(d["worst_patch"]), dict(d.get("parts") or {}), _measured_of(d),
                   CellPrediction.from_json(d["prediction"]) if d.get("prediction") else None)

    def measured_for(self, model: str) -> Any:
        """The :class:`~fidelity.coco.measure.MeasuredLoss` of ``model`` (None if absent)."""
        return _measured_for(self.measured, model)


@record
class SpatialCell:
    """One noise or blur (corruption, severity) (:mod:`fidelity.coco.spatial`): its value on
    the property's axis (:class:`~fidelity.coco.spatial.AxisValue`: the chart's MTF50 or SNR
    and its uncertainty), the worst-case loss the property table predicts there (detector
    size :data:`PREDICTION_SIZE`, :class:`~fidelity.prediction.properties.PropertyPrediction`;
    None until computed: :func:`with_predictions`) and the measured loss per detector."""

    corruption: str
    severity: int
    parameter: Any
    axis: AxisValue
    measured: tuple[Any, ...] = ()
    prediction: PropertyPrediction | None = None

    @property
    def property(self) -> str:  # sharpness or noise (no docstring: no second API target of
        # that name, which the tables' "property" attributes would refer to ambiguously)
        return PROPERTY[self.corruption]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys (``axis``, ``measured``, ``prediction``: their JSON)."""
        return {"corruption": self.corruption, "severity": self.severity,
                "parameter": self.parameter, "property": self.property,
                "axis": self.axis.to_json(), "measured": [m.to_json() for m in self.measured],
                "prediction": self.prediction.to_json() if self.prediction else None}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SpatialCell:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["corruption"]), int(d["severity"]), _parameter_of(d),
                   AxisValue.from_json(d["axis"]), _measured_of(d),
                   PropertyPrediction.from_json(d["prediction"]) if d.get("prediction")
                   else None)

    def measured_for(self, model: str) -> Any:
        """The :class:`~fidelity.coco.measure.MeasuredLoss` of ``model`` (None if absent)."""
        return _measured_for(self.measured, model)

    def bound(self, model: str) -> BoundCell | None:
        """The measured loss of ``model`` beside the predicted one
        (:class:`~fidelity.coco.bounds.BoundCell`, the prediction as its ``classic``); None
        when ``model`` was not measured here."""
        m = self.measured_for(model)
        if m is None:
            return None
        p = self.prediction
        return BoundCell(m.dmap_points, m.dmap_points_se, p.loss if p else None, None)


def predict_spatial(axis: AxisValue, size: str = PREDICTION_SIZE) -> PropertyPrediction | None:
    """The worst-case ΔmAP (points) the property table predicts at a corruption's axis value
    for detector size ``size``, x's uncertainty propagated
    (:func:`fidelity.prediction.properties.predict_property`); None where x is unknown."""
    if axis.x is None:
        return None
    return predict_property(load_property_table(axis.property), axis.x, u_x=axis.u, size=size)


def spatial_chart_cells(corruptions: Sequence[str] = SPATIAL_CORRUPTIONS,
                        severities: Sequence[int] = SEVERITIES,
                        draws: int = CHART_DRAWS) -> list[SpatialCell]:
    """The chart side of every noise or blur (corruption, severity): its axis value and the
    loss predicted there, no COCO."""
    chart = calibration_chart()
    out = []
    for name in corruptions:
        for sev in severities:
            axis = chart_axis_value(name, sev, draws, chart)
            out.append(SpatialCell(name, sev, PARAMETERS[name][sev - 1], axis,
                                   prediction=predict_spatial(axis)))
    return out


def _parameter_of(d: Mapping[str, Any]) -> Any:
    """A cell's ``parameter`` read back from JSON (a list was a tuple)."""
    param = d["parameter"]
    return tuple(param) if isinstance(param, list) else param


def _measured_of(d: Mapping[str, Any]) -> tuple[MeasuredLoss, ...]:
    """A cell's ``measured`` losses read back from JSON."""
    return tuple(MeasuredLoss.from_json(m) for m in d.get("measured") or ())


def _measured_for(measured: Sequence[Any], model: str) -> Any:
    """The measured loss of ``model`` among a cell's ``measured`` (None if absent)."""
    return next((m for m in measured if m.model == model), None)


def _cell_of(cells: Sequence[Any], corruption: str, severity: int) -> Any:
    """The cell of (corruption, severity) among ``cells``; an error when it is not there."""
    for c in cells:
        if c.corruption == corruption and c.severity == severity:
            return c
    raise InvalidValueError(f"{corruption}:{severity} is not in the COCO-C table")


def _models_of(cells: Sequence[Any]) -> list[str]:
    """Detectors measured in some of ``cells``, in first-seen order."""
    return list(dict.fromkeys(m.model for c in cells for m in c.measured))


@record
class CocoCResults:
    """The COCO-C table (:func:`run_coco_c`): one :class:`CorruptionCell` per colour
    (corruption, severity), the chart used, its own 8-bit ΔE (``floor_delta_e``), provenance
    (``meta``; the noise and blur run's under ``meta["spatial_run"]``), and one
    :class:`SpatialCell` per noise or blur (corruption, severity) (``spatial``)."""

    cells: tuple[CorruptionCell, ...]
    chart: str
    floor_delta_e: float
    meta: Mapping[str, Any]
    spatial: tuple[SpatialCell, ...] = ()

    def cell(self, corruption: str, severity: int) -> CorruptionCell:
        """The cell of (corruption, severity); an error when it is not in the table."""
        cell: CorruptionCell = _cell_of(self.cells, corruption, severity)
        return cell

    def spatial_cell(self, corruption: str, severity: int) -> SpatialCell:
        """The noise or blur cell of (corruption, severity); an error when it is not in the
        table."""
        cell: SpatialCell = _cell_of(self.spatial, corruption, severity)
        return cell

    def spatial_models(self) -> list[str]:
        """Detectors measured in some noise or blur cell, in first-seen order."""
        return _models_of(self.spatial)

    def spatial_bounds(self) -> ClassBounds:
        """How often the property tables' prediction bounds the measured loss of the noise
        and blur cells (plainly and within 2 SE; :func:`fidelity.coco.bounds.summarise_cells`,
        the prediction in its ``classic`` place)."""
        return summarise_cells([b for c in self.spatial for m in c.measured
                                if (b := c.bound(str(m.model))) is not None])

    def models(self) -> list[str]:
        """Detectors measured in some cell, in first-seen order."""
        return _models_of(self.cells)

    def bound_cells(self) -> list[tuple[CorruptionCell, str, BoundCell]]:
        """(cell, detector, its :class:`~fidelity.coco.bounds.BoundCell`) for every detector
        measured in a cell: the measured ΔmAP (points) and its SE beside the cell's recorded
        classic and direction-aware predictions (None when it has none)."""
        out = []
        for c in self.cells:
            p = c.prediction
            for m in c.measured:
                out.append((c, str(m.model), BoundCell(
                    m.dmap_points, m.dmap_points_se, p.classic if p else None,
                    p.directional if p else None)))
        return out

    def bounds(self) -> ClassBounds:
        """How often the classic and the direction-aware prediction bound the measured loss
        (plainly and within 2 SE) and their median over-prediction, over every (cell,
        detector) measured (:func:`fidelity.coco.bounds.summarise_cells`)."""
        return summarise_cells([b for _, _, b in self.bound_cells()])

    def to_json(self) -> dict[str, Any]:
        """``{"chart", "floor_delta_e", "cells", "meta"}``, and ``"spatial_cells"`` when
        there are noise or blur cells."""
        doc: dict[str, Any] = {"chart": self.chart, "floor_delta_e": self.floor_delta_e,
                               "cells": [c.to_json() for c in self.cells],
                               "meta": dict(self.meta)}
        if self.spatial:
            doc["spatial_cells"] = [c.to_json() for c in self.spatial]
        out: dict[str, Any] = json_ready(doc)
        return out

    def without_locations(self) -> CocoCResults:
        """These results with each measurement's input paths cut to their names: the form
        shipped as ``fidelity/data/coco-c.json``, which names its inputs (and the dataset by
        its fingerprint, ``settings["dataset"]``) but not where they lay on the machine that
        measured them."""
        def named(m: Any) -> Any:
            settings = {k: Path(v).name if k in ("images_folder", "annotations") else v
                        for k, v in m.settings.items()}
            return replace(m, settings=settings)

        def names(meta: Mapping[str, Any]) -> dict[str, Any]:
            return {k: Path(v).name if k in ("images", "annotations") and v
                    else names(v) if k == "spatial_run" and isinstance(v, Mapping) else v
                    for k, v in meta.items()}

        return replace(self, meta=names(self.meta),
                       cells=tuple(replace(c, measured=tuple(named(m) for m in c.measured))
                                   for c in self.cells),
                       spatial=tuple(replace(c, measured=tuple(named(m) for m in c.measured))
                                     for c in self.spatial))

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CocoCResults:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(CorruptionCell.from_json(c) for c in d["cells"]), str(d["chart"]),
                   float(d["floor_delta_e"]), dict(d.get("meta") or {}),
                   tuple(SpatialCell.from_json(c) for c in d.get("spatial_cells") or ()))


def _parameter(name: str, severity: int) -> Any:
    return {"brightness": BRIGHTNESS, "contrast": CONTRAST,
            "saturate": SATURATE}[name][severity - 1]


def chart_cells(corruptions: Sequence[str] = CORRUPTIONS,
                severities: Sequence[int] = SEVERITIES) -> list[CorruptionCell]:
    """The chart side of every (corruption, severity): chart ΔE, direction parts and the loss
    predicted from them, no COCO."""
    out = []
    for name in corruptions:
        for sev in severities:
            m = corruption_chart(name, sev)
            out.append(CorruptionCell(name, sev, _parameter(name, sev), m.mean_delta_e,
                                      m.max_delta_e, m.worst_patch,
                                      error_parts(m.reference_lab, m.lab).to_json(),
                                      prediction=predict_cell(m)))
    return out


def with_predictions(results: CocoCResults) -> CocoCResults:
    """``results`` with each cell's predicted loss (:func:`predict_cell`,
    :func:`predict_spatial`) where it has none (a table written before the predictions were
    recorded, or with them taken out to be recomputed from new tables)."""
    return replace(results, cells=tuple(
        c if c.prediction is not None else
        replace(c, prediction=predict_cell(corruption_chart(c.corruption, c.severity)))
        for c in results.cells), spatial=tuple(
        c if c.prediction is not None else replace(c, prediction=predict_spatial(c.axis))
        for c in results.spatial))


def _run_meta(inputs: Any, limit: int | None, threads: int | None, definitions: str
              ) -> dict[str, Any]:
    return {"fidelity": __version__, "python": platform.python_version(),
            "machine": {"platform": platform.platform(), "threads": threads},
            "images": str(inputs.images), "annotations": str(inputs.annotations),
            "models": [f"{m.path.name}" + (f"@{m.limit}" if m.limit else "")
                       for m in inputs.models], "limit": limit, "definitions": definitions}


#: How the noise and blur corruptions are applied and seeded, as the results record it.
SPATIAL_DEFINITIONS = (f"imagecorruptions {IMAGECORRUPTIONS_VERSION} (gaussian_noise, "
                       "shot_noise, defocus_blur, gaussian_blur), called from "
                       "fidelity.coco.spatial (gaussian_blur with channel_axis=-1 where the "
                       "package's multichannel=True fails); numpy's global generator seeded "
                       "per image with sha256('imagecorruptions:<name>:<severity>:<image "
                       "id>')[:4]")


def run_coco_c(inputs: Any, corruptions: Sequence[str] = CORRUPTIONS,
               severities: Sequence[int] = SEVERITIES, *, limit: int | None = None,
               store: Any = None, threads: int | None = 1, provider: str = "auto",
               progress: bool = False, log: Any = None) -> CocoCResults:
    """Measure every (corruption, severity) on COCO with every detector of ``inputs``
    (:func:`fidelity.coco.measure.measure_mapping`; resumable through its store) and put each
    next to its chart value: a colour corruption's chart ΔE, a noise or blur corruption's
    chart SNR or MTF50 (:mod:`fidelity.coco.spatial`; ``corruptions`` may mix both)."""
    colour, spatial = split_names(corruptions)
    for name in colour:
        _check(name, 1)
    cells = []
    for cell in chart_cells(colour, severities):
        fn = CorruptionMap(cell.corruption, cell.severity)
        measured = measure_mapping(
            fn, fn.key, inputs, limit=limit, store=store, threads=threads, provider=provider,
            progress=progress, log=log,
            description={"corruption": cell.corruption, "severity": cell.severity,
                         "parameter": cell.parameter,
                         "definition": f"imagecorruptions {IMAGECORRUPTIONS_VERSION}"})
        cells.append(replace(cell, measured=tuple(measured)))
    spatial_cells = []
    for sc in spatial_chart_cells(spatial, severities):
        sfn = SpatialCorruption(sc.corruption, sc.severity)
        measured = measure_mapping(
            sfn, sfn.key, inputs, limit=limit, store=store, threads=threads,
            provider=provider, progress=progress, log=log,
            description={"corruption": sc.corruption, "severity": sc.severity,
                         "parameter": sc.parameter, "definition": SPATIAL_DEFINITIONS})
        spatial_cells.append(replace(sc, measured=tuple(measured)))
    meta: dict[str, Any] = {}
    if colour:
        meta = _run_meta(inputs, limit, threads,
                         f"imagecorruptions {IMAGECORRUPTIONS_VERSION} (brightness, contrast, "
                         "saturate), reimplemented in fidelity.coco.corruptions and checked "
                         "equal bit for bit")
    if spatial:
        meta["spatial_run"] = _run_meta(inputs, limit, threads, SPATIAL_DEFINITIONS) | {
            "date": time.strftime("%Y-%m-%d", time.gmtime()), "chart_draws": CHART_DRAWS}
    return CocoCResults(tuple(cells), DEFAULT_CHART, uncorrupted_chart_delta_e(), meta,
                        tuple(spatial_cells))


def merge_results(base: CocoCResults, new: CocoCResults) -> CocoCResults:
    """``new`` with the cells of ``base`` it does not measure kept (``fidelity coco-c
    --update``): each (corruption, severity) of ``new`` replaces that of ``base``; the colour
    run's provenance is ``new``'s when it has colour cells, else ``base``'s, and
    ``meta["spatial_run"]`` likewise for the noise and blur cells."""
    def merged(old: Sequence[Any], fresh: Sequence[Any], order: Sequence[str]
               ) -> tuple[Any, ...]:
        have = {(c.corruption, c.severity) for c in fresh}
        kept = [c for c in old if (c.corruption, c.severity) not in have] + list(fresh)
        return tuple(sorted(kept, key=lambda c: (order.index(c.corruption), c.severity)))

    cells = merged(base.cells, new.cells, CORRUPTIONS)
    spatial = merged(base.spatial, new.spatial, SPATIAL_CORRUPTIONS)
    src = new if new.cells else base
    meta = {k: v for k, v in src.meta.items() if k != "spatial_run"}
    run = (new if new.spatial else base).meta.get("spatial_run")
    if run is not None:
        meta["spatial_run"] = run
    return CocoCResults(cells, src.chart, src.floor_delta_e, meta, spatial)


#: The shipped COCO-C table (package data), written by ``fidelity coco-c --data``.
DATA_FILE = "coco-c.json"


def load_coco_c(path: str | os.PathLike[str] | None = None) -> CocoCResults:
    """The COCO-C table: ``path`` or the shipped ``fidelity/data/coco-c.json``."""
    p = Path(path) if path is not None else resource_dir("data") / DATA_FILE
    try:
        return CocoCResults.from_json(json.loads(p.read_text(encoding="utf-8")))
    except FileNotFoundError:
        raise InputFileError(f"{p}: no COCO-C table (run fidelity coco-c --data {p})") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputFileError(f"{p}: not a COCO-C table ({exc})") from None


@record
class CocoCAnswer:
    """What ``fidelity predict --coco-c NAME:SEVERITY`` answers: the corruption's chart
    measurement (its chart ΔE), the classic and the direction-aware predictions at that ΔE,
    and the losses measured on COCO (from the shipped table)."""

    corruption: str
    severity: int
    parameter: Any
    measurement: Any
    prediction: Any
    directional: Any
    measured: tuple[Any, ...]
    table_path: str

    @property
    def chart_delta_e(self) -> float:
        """The corruption's chart ΔE (mean ΔE00)."""
        return float(self.measurement.mean_delta_e)

    def to_json(self) -> dict[str, Any]:
        """The answer as JSON."""
        return {"corruption": self.corruption, "severity": self.severity,
                "parameter": self.parameter, "chart_delta_e": self.chart_delta_e,
                "chart_max_delta_e": float(self.measurement.max_delta_e),
                "worst_patch": self.measurement.worst_patch,
                "prediction": self.prediction.to_json(),
                "directional_prediction": self.directional.to_json(),
                "measured": [m.to_json() for m in self.measured],
                "table": self.table_path}


def coco_c_answer(spec: str, *, size: str = "any", table: str | None = None,
                  data: str | os.PathLike[str] | None = None) -> CocoCAnswer:
    """The chart ΔE, the predicted and the measured loss of a COCO-C corruption
    (``"contrast:3"``): the chart side computed now (:func:`corruption_chart`), the measured
    loss from the COCO-C table (:func:`load_coco_c`)."""
    name, severity = parse_corruption(spec)
    _check(name, severity)
    m = corruption_chart(name, severity)
    prediction = predict(m.mean_delta_e, size=size, table=table)
    directional = predict_chart(m, size=size, table=_directional_name(table))
    results = load_coco_c(data)
    try:
        measured = results.cell(name, severity).measured
    except InvalidValueError:
        measured = ()
    path = str(data) if data is not None else str(resource_dir("data") / DATA_FILE)
    return CocoCAnswer(name, severity, _parameter(name, severity), m, prediction, directional,
                       tuple(measured), path)


@record
class SpatialAnswer:
    """What ``fidelity predict --coco-c NAME:SEVERITY`` answers for a noise or blur
    corruption: its value on the property's axis (the chart's MTF50 or SNR, computed now), the
    property table's worst-case prediction there and the losses measured on COCO (from the
    shipped table)."""

    corruption: str
    severity: int
    parameter: Any
    axis: AxisValue
    prediction: PropertyPrediction | None
    measured: tuple[Any, ...]
    table_path: str

    @property
    def property(self) -> str:  # sharpness or noise (no docstring: no second API target of
        # that name, which the tables' "property" attributes would refer to ambiguously)
        return PROPERTY[self.corruption]

    def to_json(self) -> dict[str, Any]:
        """The answer as JSON."""
        name, unit = AXIS_LABELS[self.property]
        out: dict[str, Any] = json_ready({
            "corruption": self.corruption, "severity": self.severity,
            "parameter": self.parameter, "property": self.property, "axis_name": name,
            "unit": unit, "axis": self.axis.to_json(),
            "prediction": self.prediction.to_json() if self.prediction else None,
            "measured": [m.to_json() for m in self.measured], "table": self.table_path})
        return out


def spatial_answer(spec: str, *, size: str = "any",
                   data: str | os.PathLike[str] | None = None) -> SpatialAnswer:
    """The chart value, the predicted and the measured loss of a noise or blur corruption
    (``"gaussian_blur:3"``): the chart side computed now (:func:`chart_axis_value`,
    :func:`predict_spatial` for detector size ``size``), the measured loss from the COCO-C
    table (:func:`load_coco_c`)."""
    name, severity = parse_corruption(spec)
    check_spatial(name, severity)
    axis = chart_axis_value(name, severity)
    prediction = predict_spatial(axis, size)
    results = load_coco_c(data)
    try:
        measured = results.spatial_cell(name, severity).measured
    except InvalidValueError:
        measured = ()
    path = str(data) if data is not None else str(resource_dir("data") / DATA_FILE)
    return SpatialAnswer(name, severity, PARAMETERS[name][severity - 1], axis, prediction,
                         tuple(measured), path)


def _directional_name(table: str | None) -> str | None:
    """``table`` when it is a direction-aware table, else None (the default one)."""
    if table is None:
        return None

    return table if load_prediction_table(table).kind == "directional" else None


__all__ = [
    "ALL_CORRUPTIONS",
    "BRIGHTNESS",
    "CONTRAST",
    "CORRUPTIONS",
    "PATCH_PX",
    "PREDICTION_SIZE",
    "SATURATE",
    "SEVERITIES",
    "SPATIAL_DEFINITIONS",
    "DATA_FILE",
    "SpatialAnswer",
    "SpatialCell",
    "check_any",
    "merge_results",
    "predict_spatial",
    "spatial_answer",
    "spatial_chart_cells",
    "CocoCAnswer",
    "CocoCResults",
    "CellPrediction",
    "CorruptionCell",
    "CorruptionMap",
    "chart_cells",
    "chart_image",
    "coco_c_answer",
    "contrast_means",
    "corrupt",
    "corruption_chart",
    "hsv_to_rgb_skimage",
    "load_coco_c",
    "parse_corruption",
    "predict_cell",
    "patch_colours",
    "rgb_to_hsv_skimage",
    "run_coco_c",
    "uncorrupted_chart_delta_e",
    "with_predictions",
]
