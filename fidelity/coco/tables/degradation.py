"""Sharpness and noise tables from a sweep's blur and noise cells, calibrated on the chart.

SAFE-COLOR puts each colour cell on the chart-ΔE axis by the ΔE that its transform gives the
chart. A blur or noise cell goes on its property's axis the same way (issue 56, requirement 1):
the calibration chart (:func:`calibration_chart`: the SAFE-COLOR reference chart as an 8-bit
sRGB image of COCO's size, 640 x 480 pixels, turned 5 degrees so that its patch edges get the
ISO 12233 e-SFR) is degraded by the cell's own callable
(:class:`fidelity.coco.degradations.Degradation`, the sweep's) and measured by the audit's own
measurement (:func:`fidelity.measure.pixels.measure_pixels` at the known corners): the softer
edge's luminance MTF50, or the 18 % grey patch's SNR
(:func:`fidelity.prediction.properties.chart_mtf50`, :func:`~.chart_snr`). A table's axis is
then what an audit prints (at the detector's input). The chart is 4x supersampled and
box-averaged (the pixel aperture), so its undegraded MTF50 is that of a sharp camera.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.camera.optics import Optics
from fidelity.chart.turned import CALIBRATION_GEOMETRY, CHECK_EDGE_TARGET
from fidelity.coco.degradations import DEGRADATIONS, Degradation, encode_srgb8
from fidelity.coco.tables.grid import CellDelta, add_standard_errors, cell_deltas, model_size
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import write_bytes_atomic
from fidelity.core.record import record
from fidelity.measure.chartsharpness import painted_target_sharpness
from fidelity.measure.pixels import measure_pixels
from fidelity.prediction.properties import (
    LOSS_COLUMNS,
    TARGET_AXIS_FILE,
    PropertyCell,
    PropertyTable,
    TargetAxis,
    chart_mtf50,
    chart_snr,
)

__all__ = ["CALIBRATION_CHART", "TARGET_AXIS_METHOD", "TARGET_AXIS_SIGMAS", "LevelValue",
           "calibrate_level", "calibration_chart", "chart_value", "property_tables",
           "target_axis", "target_axis_bytes", "write_target_axis_file"]

#: The calibration chart (module docstring): the reference chart's colours on the turned
#: chart's geometry (:data:`fidelity.chart.turned.CALIBRATION_GEOMETRY`), the frame a linear
#: grey of 0.03.
CALIBRATION_CHART: Mapping[str, Any] = {"reference": "safecolor", "frame_linear": 0.03}


def calibration_chart(scale: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The calibration chart (:data:`CALIBRATION_CHART`): ``(image, corners)``, the image
    ``(480, 640, 3)`` uint8 sRGB, the corners the ``(4, 2)`` centres of the dark skin, bluish
    green, black and white patches; ``scale``: the same chart at ``scale`` times the size and
    pitch (the same camera at a higher resolution)."""
    geometry = CALIBRATION_GEOMETRY.scaled(scale)
    rgb = np.asarray(cm.linearize_srgb(load_reference(str(CALIBRATION_CHART["reference"])).srgb),
                     np.float64)
    frame = np.full(3, float(CALIBRATION_CHART["frame_linear"]))
    return encode_srgb8(geometry.paint(rgb, frame)), geometry.corners()


@record
class LevelValue:
    """A level's value on its property's axis: ``x`` and its standard uncertainty ``u``
    (None: not stated), or None with the ``reason`` where the chart could not be measured."""

    family: str
    level: float
    x: float | None
    u: float | None
    reason: str | None = None


def chart_value(image: np.ndarray, corners: np.ndarray, prop: str
                ) -> tuple[float, float | None] | None:
    """The ``prop`` (``sharpness``/``noise``) value of a chart image as an audit measures it."""
    m = measure_pixels(image, corners, encoding="srgb", reference="safecolor",
                       uncertainty=False)
    return chart_mtf50(m.sharpness) if prop == "sharpness" else chart_snr(m.noise)


def calibrate_level(name: str, level: float,
                    chart: tuple[np.ndarray, np.ndarray] | None = None) -> LevelValue:
    """The axis value of family ``name`` at ``level`` (module docstring)."""
    image, corners = chart if chart is not None else calibration_chart()
    prop = DEGRADATIONS[name].property
    got = chart_value(Degradation(name, level)(image), corners, prop)
    if got is None:
        return LevelValue(name, level, None, None,
                          f"the chart's {prop} could not be measured at this level")
    return LevelValue(name, level, got[0], got[1])


def _chart_provenance() -> dict[str, Any]:
    """The calibration chart as the tables' provenance names it: the reference, the turned
    chart's geometry (:data:`~fidelity.chart.turned.CALIBRATION_GEOMETRY`) and the frame."""
    g = CALIBRATION_GEOMETRY
    return {"reference": CALIBRATION_CHART["reference"], "size": list(g.size),
            "angle_deg": g.angle_deg, "pitch_px": g.pitch_px,
            "patch_fraction": g.patch_fraction,
            "frame_linear": CALIBRATION_CHART["frame_linear"], "supersample": g.supersample}


def _data_names(data: Mapping[str, Any]) -> dict[str, Any]:
    """The store's data record with its file and folder paths as their names only (a shipped
    table names the data, not where it lay on the machine that measured it)."""
    return {k: Path(v).name if isinstance(v, str) and ("/" in v or "\\" in v) else v
            for k, v in data.items()}


def _cell(row: CellDelta, x: float) -> PropertyCell:
    e = row.errors
    losses = {"dmap_points": row.dmap_points, "dmap_relative": row.dmap_relative,
              "dap_person_points": row.dap_person_points,
              "dap_bicycle_points": row.dap_bicycle_points}
    se: dict[str, float | None] = {c: None for c in LOSS_COLUMNS}
    if e is not None:
        se = {"dmap_points": e.dmap_points, "dmap_relative": e.dmap_relative,
              "dap_person_points": e.dap_person_points, "dap_bicycle_points": e.dap_bicycle_points}
    return PropertyCell(row.transform, row.delta_e, x, losses, se)


def property_tables(store: Any, coco: Any = None, *, name: str = "coco1000", method: str = "auto",
                    progress: bool = False, say: Callable[[str], None] | None = None
                    ) -> dict[str, PropertyTable]:
    """The sharpness and noise tables of a sweep store's blur and noise cells.

    Parameters
    ----------
    store
        A :class:`fidelity.coco.sweep.SweepStore` with cells of
        :data:`fidelity.coco.degradations.DEGRADATIONS` and baselines.
    coco
        Its annotations (pycocotools ``COCO``), for the standard errors (None: without).
    name
        The tables' name stem (``<name>-sharpness``, ``<name>-noise``).
    method
        The COCO scorer of the fold scores.
    progress
        Show progress bars.
    say
        Receives one line per level the chart could not be measured at (left out).

    Returns
    -------
    dict
        Property -> its :class:`PropertyTable`, for each property with cells.
    """
    cells = [c for c in store.cells() if c.transform == "baseline" or c.transform in DEGRADATIONS]
    if not any(c.transform in DEGRADATIONS and c.done for c in cells):
        raise InputFileError(f"{store.path}: the sweep store has no finished blur or noise "
                             "cells (fidelity sweep --degradations)")
    deltas = cell_deltas(cells)
    baselines = {c.model: c for c in cells if c.transform == "baseline" and c.done}
    if coco is not None:
        deltas = add_standard_errors(store, coco, deltas, baselines, method, progress)
    chart = calibration_chart()
    values: dict[tuple[str, float], LevelValue] = {}
    for rows in deltas.values():
        for r in rows:
            if r.done and (r.transform, r.delta_e) not in values:
                level = calibrate_level(r.transform, r.delta_e, chart)
                values[(r.transform, r.delta_e)] = level
                if level.x is None and say is not None:
                    say(f"{r.transform} {r.delta_e:g}: left out: {level.reason}")
    base_sharp = chart_value(*chart, "sharpness")
    meta = store.meta()
    out: dict[str, PropertyTable] = {}
    for prop in ("sharpness", "noise"):
        per: dict[str, tuple[PropertyCell, ...]] = {}
        for m, rows in deltas.items():
            got = []
            for r in rows:
                v = values.get((r.transform, r.delta_e))
                if (r.done and DEGRADATIONS[r.transform].property == prop and v is not None
                        and v.x is not None):
                    got.append(_cell(r, v.x))
            if got:
                per[m] = tuple(sorted(got, key=lambda c: (c.family, c.level)))
        if not per:
            continue
        baseline = math.inf if prop == "noise" else (base_sharp[0] if base_sharp else math.inf)
        calibration = {"chart": _chart_provenance(),
                       "baseline_x": None if math.isinf(baseline) else baseline,
                       "levels": [{"family": v.family, "level": v.level, "x": v.x,
                                   "reason": v.reason} for v in values.values()
                                  if DEGRADATIONS[v.family].property == prop]}
        out[prop] = PropertyTable(
            f"{name}-{prop}", prop, baseline, {m: model_size(m) for m in per}, per,
            {m: int(baselines[m].images or 0) for m in per},
            {"calibration": calibration,
             "baseline_map": {m: baselines[m].map for m in per},
             "families": {f: {"property": d.property, "parameter": d.parameter,
                              "unit": d.unit, "linear": d.linear}
                          for f, d in DEGRADATIONS.items() if d.property == prop},
             "standard_errors": coco is not None,
             "store": {k: meta.get(k) for k in ("versions", "machine", "grid")}
             | {"data": _data_names(meta.get("data") or {})}}
            | ({"scores_files": meta["scores_files"]} if meta.get("scores_files") else {}))
    return out



#: The Gaussian blurs (sigma, px) at which :func:`target_axis` compares the painted edge
#: target with the calibration chart: the sharp camera and the tables' ``gaussian-blur``
#: levels, and one beyond them.
TARGET_AXIS_SIGMAS: tuple[float, ...] = (0.0, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0,
                                         5.0, 6.0)
TARGET_AXIS_METHOD = ("per Gaussian blur sigma (the camera's gaussian PSF kernel): MTF50 of "
                      "the painted edge target (CHECK_EDGE_TARGET, linear float, luminance, "
                      "the softer edge) and of the calibration chart degraded by the "
                      "gaussian-blur family (8-bit sRGB, the softer patch edge), both by the "
                      "audit's own measurement")


def target_axis(sigmas: tuple[float, ...] = TARGET_AXIS_SIGMAS) -> TargetAxis:
    """The painted edge target's MTF50 against the tables' axis
    (:class:`fidelity.prediction.properties.TargetAxis`), computed.

    Parameters
    ----------
    sigmas
        Gaussian blurs (px, >= 0, rising) at which both are measured.

    Returns
    -------
    TargetAxis
        Per sigma: the target's luminance MTF50 (the softer edge,
        :func:`fidelity.measure.chartsharpness.painted_target_sharpness` of
        :data:`fidelity.chart.turned.CHECK_EDGE_TARGET` blurred in linear light by
        :class:`fidelity.camera.optics.Optics`' gaussian kernel) and the calibration chart's
        degraded by ``gaussian-blur`` (:func:`chart_value`, as :func:`calibrate_level`
        measures the table levels; the sharp chart at sigma 0), both cy/px.

    Raises
    ------
    InvalidValueError
        A level where either could not be measured.
    """
    target = CHECK_EDGE_TARGET
    painted = target.paint(np.ones(3))
    chart = calibration_chart()
    points = []
    for sigma in sigmas:
        img = Optics("gaussian", sigma_px=sigma).apply(painted) if sigma > 0 else painted
        got = chart_mtf50(painted_target_sharpness(img, target, linearise=_as_float,
                                                   linearisation="none (linear input)"))
        table = (chart_value(chart[0], chart[1], "sharpness") if sigma == 0
                 else chart_value(Degradation("gaussian-blur", sigma)(chart[0]), chart[1],
                                  "sharpness"))
        if got is None or table is None:
            raise InvalidValueError(f"target axis at sigma {sigma:g} px: the "
                                    f"{'target' if got is None else 'chart'} was not measured")
        points.append((float(sigma), got[0], table[0]))
    return TargetAxis(tuple(points), TARGET_AXIS_METHOD)


def target_axis_bytes(axis: TargetAxis | None = None) -> bytes:
    """The content of :data:`fidelity.prediction.properties.TARGET_AXIS_FILE`
    (:func:`target_axis` computed unless given), JSON."""
    doc = (axis if axis is not None else target_axis()).to_json()
    return (json.dumps(doc, indent=1) + "\n").encode()


def write_target_axis_file(path: Path = TARGET_AXIS_FILE) -> Path:
    """Write :func:`target_axis_bytes` to ``path`` atomically; returns it."""
    return write_bytes_atomic(path, target_axis_bytes())


def _as_float(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, np.float64)
