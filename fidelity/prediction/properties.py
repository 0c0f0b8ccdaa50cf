"""What sharpness and noise cost a detector: measured worst-case tables, the SAFE-COLOR way.

SAFE-COLOR maps the chart ΔE to a worst-case loss of COCO mAP through tables measured with
single-parameter colour transforms calibrated on the chart. This module does the same for the
chart's other properties (issue 56):

- **sharpness**: the chart's MTF50 (cycles per pixel at the detector's input, luminance, the
  softer of the two edge directions; :func:`chart_mtf50`), from blur families;
- **noise**: the chart's SNR at its 18 % grey patch (luminance ``mu / sigma`` at the
  detector's input; :func:`chart_snr`), from noise families.

A table (:class:`PropertyTable`, ``fidelity/data/properties/<name>.json``, built by
``fidelity tables`` from a sweep store with ``--degradations``) holds, per detector, every
measured cell: the family (:mod:`fidelity.coco.degradations`), its level, the level's x value
(what the chart measurement reads on the chart degraded the same way) and the cell's losses
with their standard errors. The prediction at a measured x (:func:`predict_property`):

1. every family's loss is interpolated linearly in ``1 / x`` (the blur width for MTF50, the
   noise-to-signal ratio for SNR) between its cells and the undegraded chart (loss 0 at
   ``1 / x_baseline``; 0 for the noise table, whose undegraded chart is noiseless), through
   the running maximum of its losses from the mildest level to the harshest (a worst case
   that never falls as the property worsens; a measured gain counts as no loss);
2. the worst case is the largest over families and detectors of the size class (families whose
   harshest level stops short of x give their harshest loss, a lower bound of theirs there);
3. an x at least as good as the undegraded chart predicts 0; an x worse than every family's
   harshest level gets the table's ceiling (its largest loss), flagged ``beyond``.

The losses of the three properties combine by :data:`COMBINATION` (module ``combine``): the
sum, plus the interaction of blur and noise, :data:`INTERACTION` times
``sqrt(l_sharpness * l_noise)``. Blur and noise together are not sub-additive for every
detector: measured on COCO, their joint loss exceeds the sum of their losses alone by up to
0.99 ``sqrt`` of the product of the two (``benchmarks/studies/combination.py``,
``reports/validation/combination.md``; held-out composites in
``reports/validation/combination-holdout.md``); :data:`INTERACTION` is the smallest factor that
covers the largest of them. What a verdict combines is each property as the chart reads it
with all degradations present (noise also lowers the measured MTF50), which the study
compares with the joint loss. Colour is added without an interaction (none was measured).
"""

from __future__ import annotations

import builtins
import math
from collections.abc import Mapping, Sequence
from dataclasses import field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import display_path, optional_float
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

__all__ = [
    "AXES",
    "COMBINATION",
    "DOMINANCE_ATOL",
    "DOMINANCE_ORDER",
    "DOMINANCE_RTOL",
    "INTERACTING",
    "INTERACTION",
    "LOSS_COLUMNS",
    "PROPERTY_TABLES",
    "Combined",
    "PropertyCell",
    "PropertyJudgement",
    "PropertyPrediction",
    "PropertyTable",
    "TARGET_AXIS_FILE",
    "TargetAxis",
    "chart_mtf50",
    "chart_snr",
    "combine",
    "detector_scale",
    "dominant_property",
    "load_property_table",
    "load_target_axis",
    "parse_property_table",
    "parse_target_axis",
    "predict_property",
    "property_threshold",
    "target_on_table_axis",
    "worst_case_losses",
]

#: Property -> (axis name, unit). Both axes: a lower value is worse.
AXES: Mapping[str, tuple[str, str]] = {
    "sharpness": ("mtf50", "cy/px"),
    "noise": ("snr", "ratio"),
}
#: The loss columns a table may carry (those of the colour tables).
LOSS_COLUMNS: tuple[str, ...] = ("dmap_points", "dmap_relative", "dap_person_points",
                                 "dap_bicycle_points")
#: The shipped table of each property.
PROPERTY_TABLES: Mapping[str, str] = {"sharpness": "coco1000-sharpness",
                                      "noise": "coco1000-noise"}
#: How the properties' losses combine (module docstring).
COMBINATION = "sum + sharpness-noise interaction"
#: The factor of the blur-noise interaction ``sqrt(l_sharpness * l_noise)`` (module
#: docstring): the measured interaction over that product reached 0.99 (YOLO11n, Gaussian
#: blur 1.5 px with noise 0.06 on the encoded values).
INTERACTION = 1.0
#: The properties whose losses interact.
INTERACTING = ("sharpness", "noise")
#: The order a tie for the dominant property is broken in (:func:`dominant_property`): the
#: first of the tied properties in this order wins (any other property after these, by name).
DOMINANCE_ORDER = ("colour", "sharpness", "noise")
#: Losses this close to the largest (relative, absolute) tie with it for the dominant
#: property: the tolerance the recorded JSON outputs compare numbers with, so that another
#: processor's last bits in a fit (or a sum taken in another order) cannot change the name.
DOMINANCE_RTOL, DOMINANCE_ATOL = 1e-6, 1e-9
#: The detector's input side: a detector sees the image letterboxed to this many pixels.
DETECTOR_SIDE = 640
MAX_TABLE_BYTES = 8 << 20


@record
class PropertyCell:
    """One measured cell: ``family`` at ``level`` (its unit), whose chart reads ``x`` on the
    property's axis, and its ``losses`` and their standard errors ``se`` by column (None:
    not measured)."""

    family: str
    level: float
    x: float
    losses: Mapping[str, float | None]
    se: Mapping[str, float | None] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; losses as ``<column>`` and ``<column>_se``."""
        d: dict[str, Any] = {"family": self.family, "level": self.level, "x": self.x}
        for c in LOSS_COLUMNS:
            if c in self.losses:
                d[c] = self.losses[c]
                d[c + "_se"] = self.se.get(c)
        return d


@record
class PropertyTable:
    """A measured worst-case table of one property (module docstring).

    Attributes
    ----------
    name
        The table's name (``coco1000-sharpness``).
    property
        ``sharpness`` or ``noise`` (:data:`AXES`).
    baseline_x
        The undegraded chart's x (inf: noiseless).
    models
        Detector -> its size class (``n`` ... ``x``).
    cells
        Detector -> its cells.
    images
        Detector -> images each cell was scored on.
    provenance
        Where the cells and the calibration came from (free-form JSON).
    path
        The file it was read from (None: built in memory).
    """

    name: str
    property: str
    baseline_x: float
    models: Mapping[str, str]
    cells: Mapping[str, tuple[PropertyCell, ...]]
    images: Mapping[str, int]
    provenance: Mapping[str, Any] = field(default_factory=dict)
    path: Path | None = None

    @builtins.property
    def axis(self) -> str:
        """The axis's name (``mtf50``, ``snr``)."""
        return AXES[self.property][0]

    @builtins.property
    def unit(self) -> str:
        """The axis's unit."""
        return AXES[self.property][1]

    def detectors(self, size: str = "any") -> list[str]:
        """The detectors of size class ``size`` (``any``: all)."""
        return [m for m, s in self.models.items() if size in ("any", s)]

    def to_json(self) -> dict[str, Any]:
        """The table's file (:func:`parse_property_table` reads it back)."""
        return {"kind": "property-table", "name": self.name, "property": self.property,
                "axis": self.axis, "unit": self.unit,
                "baseline_x": None if math.isinf(self.baseline_x) else self.baseline_x,
                "combination": COMBINATION,
                "models": {m: {"size": s, "images": self.images.get(m),
                               "cells": [c.to_json() for c in self.cells.get(m, ())]}
                           for m, s in self.models.items()},
                "provenance": dict(self.provenance)}


def parse_property_table(obj: Any, where: str) -> PropertyTable:
    """A :class:`PropertyTable` from its JSON form; a malformed one is an
    :class:`InputFileError` naming ``where`` and the field."""
    def bad(what: str) -> InputFileError:
        return InputFileError(f"{where}: {what}")

    if not isinstance(obj, Mapping) or obj.get("kind") != "property-table":
        raise bad("not a property table (kind 'property-table')")
    prop = obj.get("property")
    if prop not in AXES:
        raise bad(f"property {prop!r}: expected one of {', '.join(AXES)}")
    base = obj.get("baseline_x")
    baseline = math.inf if base is None else float(base)
    if not baseline > 0:
        raise bad(f"baseline_x {base!r}: must be > 0 (or null: noiseless)")
    models: dict[str, str] = {}
    cells: dict[str, tuple[PropertyCell, ...]] = {}
    images: dict[str, int] = {}
    for m, d in (obj.get("models") or {}).items():
        models[m] = str(d.get("size", "any"))
        if d.get("images") is not None:
            images[m] = int(d["images"])
        rows = []
        for i, c in enumerate(d.get("cells") or ()):
            try:
                x = float(c["x"])
                row = PropertyCell(str(c["family"]), float(c["level"]), x,
                                   {k: optional_float(c.get(k)) for k in LOSS_COLUMNS if k in c},
                                   {k: optional_float(c.get(k + "_se")) for k in LOSS_COLUMNS if k in c})
            except (KeyError, TypeError, ValueError) as exc:
                raise bad(f"models.{m}.cells[{i}]: {exc}") from None
            if not (math.isfinite(x) and x > 0):
                raise bad(f"models.{m}.cells[{i}].x {c.get('x')!r}: must be finite and > 0")
            rows.append(row)
        cells[m] = tuple(rows)
    if not models:
        raise bad("models: no detector")
    return PropertyTable(str(obj.get("name", "")), str(prop), baseline, models, cells, images,
                         dict(obj.get("provenance") or {}))



def load_property_table(property_or_path: str) -> PropertyTable:
    """The shipped table of a property (``sharpness``, ``noise``), a shipped table's name or
    a JSON file's path."""
    name = PROPERTY_TABLES.get(property_or_path, property_or_path)
    path = Path(name)
    if not (path.suffix == ".json" or "/" in name):
        path = resource_dir("data") / "properties" / f"{name}.json"
        if not path.is_file():
            shipped = sorted(p.stem for p in path.parent.glob("*.json"))
            raise unknown_name("property table", name, [*PROPERTY_TABLES, *shipped])
    return _load(path.resolve())


@lru_cache(maxsize=8)
def _load(path: Path) -> PropertyTable:
    if not path.is_file():
        raise InputFileError(f"{display_path(path)}: property table does not exist")
    obj = sc.load_document(path, fmt="json", max_bytes=MAX_TABLE_BYTES, what="property table")
    table = parse_property_table(obj, display_path(path))
    return PropertyTable(**{**table.__dict__, "path": path})


# --------------------------------------------------------------------------------------------
# The worst case


def _inv(x: float) -> float:
    return 0.0 if math.isinf(x) else 1.0 / x


def _chain(points: Sequence[tuple[float, float, float | None]], u0: float
           ) -> list[tuple[float, float, float | None]]:
    """One family's ``(u, loss, se)`` points beyond ``u0`` in order of ``u``, from ``(u0, 0,
    0)``, as the running maximum of the loss (the worst case never falls as the property
    worsens; a point below it takes the previous loss and se)."""
    chain: list[tuple[float, float, float | None]] = [(u0, 0.0, 0.0)]
    for p in sorted(points):
        if p[0] > u0:
            chain.append(p if p[1] >= chain[-1][1] else (p[0], chain[-1][1], chain[-1][2]))
    return chain


def _families(table: PropertyTable, model: str, column: str
              ) -> dict[str, list[tuple[float, float, float | None]]]:
    """A detector's cells of ``column`` by family, as ``(1/x, max(loss, 0), se)``."""
    fams: dict[str, list[tuple[float, float, float | None]]] = {}
    for c in table.cells.get(model, ()):
        loss = c.losses.get(column)
        if loss is not None:
            fams.setdefault(c.family, []).append((_inv(c.x), max(loss, 0.0), c.se.get(column)))
    return fams


def _family_loss(points: Sequence[tuple[float, float, float | None]], u: float, u0: float
                 ) -> tuple[float, float | None, bool] | None:
    """One family's (loss, se, covered) at ``u = 1/x``: linear in u between its points and
    (u0, 0, 0); beyond its harshest point its harshest loss (covered False)."""
    if not points:
        return None
    chain = _chain(points, u0)
    if len(chain) == 1:
        return 0.0, 0.0, True
    if u >= chain[-1][0]:
        return chain[-1][1], chain[-1][2], u == chain[-1][0]
    for (ua, la, sa), (ub, lb, sb) in zip(chain, chain[1:], strict=False):
        if ua <= u <= ub:
            t = 0.0 if ub == ua else (u - ua) / (ub - ua)
            se = None if sa is None or sb is None else (1 - t) * sa + t * sb
            return la + t * (lb - la), se, True
    return 0.0, 0.0, True


@record
class PropertyPrediction:
    """The worst-case loss predicted for one measured property (:func:`predict_property`).

    Attributes
    ----------
    property, axis, unit
        ``sharpness``/``mtf50``/``cy/px`` or ``noise``/``snr``/``ratio``.
    x, u_x
        The value at the detector's input and its standard uncertainty (None: unknown).
    column
        The loss column (``dmap_points``, ...).
    loss, u_loss
        The predicted worst-case loss and its standard uncertainty (table SE and the slope
        times ``u_x``; None: unknown).
    status
        ``in-range``, ``baseline`` (as good as the undegraded chart: 0) or ``beyond`` (worse
        than every measured level: the table's ceiling).
    family, detector
        The family and detector that give the worst case (None at the baseline).
    table
        The table's name.
    scale
        The factor applied to the native value (the detector's input over the image's size;
        1 when the image is at the detector's size).
    native_x
        The value measured at the image's own resolution, on the tables' axis.
    target_x
        Sharpness measured on a slanted-edge target: its MTF50 at the image's resolution
        before :func:`target_on_table_axis` put it on the tables' patch-edge axis
        (``native_x``); None: measured on the chart's own edges, as the tables.
    """

    property: str
    axis: str
    unit: str
    x: float
    u_x: float | None
    column: str
    loss: float
    u_loss: float | None
    status: str
    family: str | None
    detector: str | None
    table: str
    scale: float = 1.0
    native_x: float | None = None
    target_x: float | None = None

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; non-finite numbers as None."""
        def fin(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else v
        return {"property": self.property, "axis": self.axis, "unit": self.unit,
                "x": fin(self.x), "u_x": fin(self.u_x), "native_x": fin(self.native_x),
                "target_x": fin(self.target_x), "scale": self.scale, "column": self.column, "loss": fin(self.loss),
                "u_loss": fin(self.u_loss), "status": self.status, "family": self.family,
                "detector": self.detector, "table": self.table}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PropertyPrediction:
        """Inverse of :meth:`to_json` (a value written as None reads back as inf)."""
        return cls(str(d["property"]), str(d["axis"]), str(d["unit"]),
                   math.inf if d.get("x") is None else float(d["x"]), optional_float(d.get("u_x")),
                   str(d["column"]), math.inf if d.get("loss") is None else float(d["loss"]),
                   optional_float(d.get("u_loss")), str(d["status"]), d.get("family"), d.get("detector"),
                   str(d["table"]), float(d.get("scale", 1.0)), optional_float(d.get("native_x")),
                   optional_float(d.get("target_x")))


def _worst_at(table: PropertyTable, x: float, size: str, column: str
              ) -> tuple[float, float | None, bool, str | None, str | None]:
    u, u0 = _inv(x), _inv(table.baseline_x)
    best: tuple[float, float | None, bool, str | None, str | None] = (0.0, 0.0, True, None, None)
    covered_any = False
    for m in table.detectors(size):
        for fam, pts in _families(table, m, column).items():
            got = _family_loss(pts, u, u0)
            if got is None:
                continue
            loss, se, covered = got
            covered_any |= covered
            if loss > best[0]:
                best = (loss, se, covered, fam, m)
    return best[0], best[1], covered_any, best[3], best[4]


def predict_property(table: PropertyTable, x: float, *, u_x: float | None = None,
                     size: str = "any", column: str = "dmap_points", scale: float = 1.0,
                     native_x: float | None = None, target_x: float | None = None
                     ) -> PropertyPrediction:
    """The worst-case loss of a chart whose property reads ``x`` at the detector's input.

    Parameters
    ----------
    table
        The property's table (:func:`load_property_table`).
    x
        MTF50 (cy/px) or SNR at the detector's input (:func:`detector_scale`), > 0; inf:
        noiseless.
    u_x
        Its standard uncertainty (None: unknown).
    size
        Detector size class (``n`` ... ``x``, ``any``).
    column
        The loss column (:data:`LOSS_COLUMNS`).
    scale, native_x, target_x
        Recorded with the prediction: the factor from the native value, the native value and
        the edge target's MTF50 it was mapped from (:attr:`PropertyPrediction.target_x`).

    Returns
    -------
    PropertyPrediction
        The loss, its uncertainty and the status (module docstring).

    Raises
    ------
    InvalidValueError
        A value that is NaN or not > 0, an unknown column or a size class with no detector.
    """
    if column not in LOSS_COLUMNS:
        raise unknown_name("loss column", column, LOSS_COLUMNS)
    if math.isnan(x) or not x > 0:
        raise InvalidValueError(f"{table.axis} {x!r}: must be a number > 0")
    if not table.detectors(size):
        raise InvalidValueError(f"{table.name}: no detector of size class {size!r} "
                                f"(has {', '.join(sorted(set(table.models.values())))})")
    axis, unit = AXES[table.property]
    if x >= table.baseline_x:
        return PropertyPrediction(table.property, axis, unit, x, u_x, column, 0.0, 0.0,
                                  "baseline", None, None, table.name, scale, native_x, target_x)
    loss, se, covered, fam, det = _worst_at(table, x, size, column)
    if not covered:  # worse than every family's harshest level: the ceiling
        ceiling = max((c.losses.get(column) or 0.0) for m in table.detectors(size)
                      for c in table.cells.get(m, ()))
        return PropertyPrediction(table.property, axis, unit, x, u_x, column, ceiling, None,
                                  "beyond", fam, det, table.name, scale, native_x, target_x)
    u_loss = se
    if u_x is not None and math.isfinite(u_x) and u_x > 0:
        lo = _worst_at(table, x + u_x, size, column)[0] if x + u_x < table.baseline_x else 0.0
        hi = _worst_at(table, max(x - u_x, x / 2), size, column)[0]
        slope_u = abs(hi - lo) / 2
        u_loss = math.hypot(se or 0.0, slope_u) if se is not None else slope_u
    return PropertyPrediction(table.property, axis, unit, x, u_x, column, loss, u_loss,
                              "in-range", fam, det, table.name, scale, native_x, target_x)


def worst_case_losses(table: PropertyTable, xs: ArrayLike, *, size: str = "any",
                      column: str = "dmap_points") -> NDArray[np.float64]:
    """The worst-case loss :func:`predict_property` gives at each of ``xs`` (its ``loss``),
    for a whole curve at once: each family's running-maximum chain built once and read by
    linear interpolation in ``1/x``, the largest over families and detectors; 0 at or above
    the table's baseline, the table's ceiling beyond every family's harshest level.

    Parameters
    ----------
    table
        The property's table (:func:`load_property_table`).
    xs
        Axis values ``(n,)`` at the detector's input, each > 0 (inf: noiseless).
    size, column
        As :func:`predict_property`.

    Returns
    -------
    ndarray
        ``(n,)`` losses in the column's unit.

    Raises
    ------
    InvalidValueError
        An unknown column, a value that is NaN or not > 0, or a size class with no detector.
    """
    if column not in LOSS_COLUMNS:
        raise unknown_name("loss column", column, LOSS_COLUMNS)
    x = np.asarray(xs, np.float64).reshape(-1)
    if np.isnan(x).any() or (x <= 0).any():
        raise InvalidValueError(f"{table.axis}: every value must be a number > 0")
    detectors = table.detectors(size)
    if not detectors:
        raise InvalidValueError(f"{table.name}: no detector of size class {size!r}")
    with np.errstate(divide="ignore"):
        u = np.where(np.isinf(x), 0.0, 1.0 / x)
    u0 = _inv(table.baseline_x)
    worst = np.zeros_like(u)
    covered = np.zeros(u.shape, bool)
    for m in detectors:
        for pts in _families(table, m, column).values():
            chain = _chain(pts, u0)
            if len(chain) == 1:
                covered |= True
                continue
            cu = np.array([p[0] for p in chain])
            cl = np.array([p[1] for p in chain])
            worst = np.maximum(worst, np.interp(u, cu, cl))
            covered |= u <= cu[-1]
    ceiling = max(((c.losses.get(column) or 0.0) for m in detectors
                   for c in table.cells.get(m, ())), default=0.0)
    out: NDArray[np.float64] = np.where(covered, worst, ceiling)
    out[x >= table.baseline_x] = 0.0
    return out


def property_threshold(table: PropertyTable, loss: float, *, size: str = "any",
                       column: str = "dmap_points") -> float | None:
    """The axis value at which the worst-case loss reaches ``loss`` (bisection on the
    monotone worst case, in ``1/x``); None where the table never reaches it."""
    u0 = _inv(table.baseline_x)
    us = [_inv(c.x) for m in table.detectors(size) for c in table.cells.get(m, ())]
    if not us:
        return None
    lo, hi = u0, max(us)
    if _worst_at(table, 1.0 / hi, size, column)[0] < loss:
        return None
    for _ in range(60):
        mid = (lo + hi) / 2
        if mid > 0 and _worst_at(table, 1.0 / mid, size, column)[0] >= loss:
            hi = mid
        else:
            lo = mid
    return 1.0 / hi


# --------------------------------------------------------------------------------------------
# The edge target on the tables' axis

#: The painted edge target's MTF50 against the tables' axis at the same Gaussian blurs
#: (:class:`TargetAxis`; computed by :func:`fidelity.coco.tables.degradation.target_axis`).
TARGET_AXIS_FILE = resource_dir("data") / "turned" / "target-axis.json"


@record
class TargetAxis:
    """Where a slanted-edge target's MTF50 lies on the tables' axis.

    The tables' axis is the calibration chart's patch-edge MTF50
    (:mod:`fidelity.coco.tables.degradation`): narrow ROIs between patches, whose Hamming
    window widens the measured MTF as the blur grows. The target's wide ROIs measure the
    blur's own MTF50 (within 1.4 % of the closed form up to sigma = 4 px). ``points`` holds,
    per Gaussian blur of ``sigma`` px, the target's MTF50 and the calibration chart's, both
    measured by the audit's own code on the blurred images; :meth:`on_table_axis` interpolates
    between them linearly in 1 / MTF50 (the blur width) and keeps the end points' ratio
    beyond them.

    Attributes
    ----------
    points
        ``(sigma px, target MTF50 cy/px, table-axis MTF50 cy/px)``, sigma rising.
    method
        How the points were computed, in words.
    """

    points: tuple[tuple[float, float, float], ...]
    method: str = ""

    def on_table_axis(self, mtf50: float) -> float:
        """The tables'-axis MTF50 (cy/px) of a target MTF50 ``mtf50`` (cy/px, > 0)."""
        if not mtf50 > 0 or not math.isfinite(mtf50):
            raise InvalidValueError(f"target MTF50 {mtf50!r}: must be a finite number > 0")
        u = 1.0 / mtf50
        us = [1.0 / t for _, t, _ in self.points]
        vs = [1.0 / a for _, _, a in self.points]
        if u <= us[0]:
            return mtf50 * us[0] / vs[0]
        if u >= us[-1]:
            return mtf50 * us[-1] / vs[-1]
        k = next(i for i in range(1, len(us)) if us[i] >= u)
        w = (u - us[k - 1]) / (us[k] - us[k - 1])
        return 1.0 / (vs[k - 1] + w * (vs[k] - vs[k - 1]))

    def to_json(self) -> dict[str, Any]:
        """``points`` as ``{sigma_px, target_mtf50, table_mtf50}`` and ``method``."""
        return {"points": [{"sigma_px": a, "target_mtf50": b, "table_mtf50": c}
                           for a, b, c in self.points], "method": self.method}


def parse_target_axis(obj: Any, where: str) -> TargetAxis:
    """A :class:`TargetAxis` from its JSON form (:meth:`TargetAxis.to_json`); ``where``
    names the document in errors."""
    bad = InputFileError(f"{where}: not a target axis file: need points of "
                         f"{{sigma_px, target_mtf50, table_mtf50}}, MTF50s > 0 falling with "
                         f"sigma")
    try:
        pts = tuple((float(p["sigma_px"]), float(p["target_mtf50"]), float(p["table_mtf50"]))
                    for p in obj["points"])
    except (KeyError, TypeError, ValueError) as exc:
        raise bad from exc
    ok = len(pts) >= 2 and all(math.isfinite(v) for p in pts for v in p) and all(
        p[1] > 0 and p[2] > 0 for p in pts) and all(
        b[0] > a[0] and b[1] < a[1] and b[2] < a[2] for a, b in zip(pts, pts[1:], strict=False))
    if not ok:
        raise bad
    return TargetAxis(pts, str(obj.get("method", "")))


@lru_cache(maxsize=1)
def load_target_axis() -> TargetAxis:
    """The shipped :class:`TargetAxis` (:data:`TARGET_AXIS_FILE`)."""
    obj = sc.load_document(TARGET_AXIS_FILE, fmt="json", max_bytes=MAX_TABLE_BYTES,
                           what="target axis")
    return parse_target_axis(obj, display_path(TARGET_AXIS_FILE))


def target_on_table_axis(mtf50: float, u: float | None = None
                         ) -> tuple[float, float | None]:
    """A slanted-edge target's MTF50 (cy/px) and its standard uncertainty on the tables'
    axis (:meth:`TargetAxis.on_table_axis` of the shipped :func:`load_target_axis`; ``u``
    scaled by the same ratio)."""
    x = load_target_axis().on_table_axis(mtf50)
    return x, None if u is None else u * x / mtf50


# --------------------------------------------------------------------------------------------
# The chart's values


def detector_scale(width: int, height: int, side: int = DETECTOR_SIDE) -> float:
    """The letterbox factor from an image of ``width`` x ``height`` pixels to the detector's
    input (``side / max(width, height)``)."""
    if width <= 0 or height <= 0:
        raise InvalidValueError(f"image size {width} x {height}: must be positive")
    return side / max(width, height)


def chart_mtf50(sharpness: Any) -> tuple[float, float | None] | None:
    """The chart's MTF50 at its own resolution: the luminance MTF50 of the softer of its
    measured edges, with that edge's uncertainty; None where no edge's luminance was measured
    (``sharpness``: a :class:`fidelity.measure.chartsharpness.ChartSharpness` or None)."""
    if sharpness is None:
        return None
    found: list[tuple[float, float | None]] = []
    for e in sharpness.edges:
        y = e.channel("Y") if e.refusal is None else None
        if y is not None and y.refusal is None and y.mtf50 is not None and y.mtf50 > 0:
            found.append((float(y.mtf50), y.u_mtf50))
    return min(found, key=lambda t: t[0]) if found else None


def chart_snr(noise: Any) -> tuple[float, float | None] | None:
    """The chart's SNR at its 18 % grey patch at its own resolution and its standard
    uncertainty (``sqrt((1 + SNR^2 / 2) / n)`` for n effective pixels, the patch's pixels over
    their design effect: the sampling error of mu / sigma of a normal sample); None where not
    measured (``noise``: a
    :class:`fidelity.measure.chartnoise.ChartNoise` or None)."""
    if noise is None:
        return None
    snr = float(noise.grey_snr)
    if math.isnan(snr) or not snr > 0:
        return None
    n = None
    for name, p in zip(noise.patches, noise.noise, strict=False):
        if name == noise.grey_patch and p.n > 0:
            n = p.n / max(float(p.design_effect), 1.0)
    if n is None or math.isinf(snr):
        return snr, None
    return snr, math.sqrt((1.0 + snr * snr / 2.0) / float(n))


@record
class Combined:
    """The properties' losses combined (:func:`combine`): ``loss`` and ``u_loss`` (the parts'
    uncertainties propagated to first order), the ``dominant`` property (largest loss, a tie
    broken by :func:`dominant_property`), the parts, the blur-noise ``interaction`` term
    included in ``loss``, the properties not judged (``missing``: not measured), the rule,
    and the validated ``margin`` included in ``loss``
    (:func:`fidelity.prediction.validated.with_margin`; 0: none applied)."""

    loss: float
    u_loss: float | None
    dominant: str
    parts: Mapping[str, float]
    missing: tuple[str, ...] = ()
    rule: str = COMBINATION
    interaction: float = 0.0
    margin: float = 0.0

    @builtins.property
    def rule_loss(self) -> float:
        """The rule's loss before the validated margin (``loss - margin``)."""
        return self.loss - self.margin if self.margin else self.loss

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"loss": self.loss, "u_loss": self.u_loss, "dominant": self.dominant,
                "parts": dict(self.parts), "interaction": self.interaction,
                "margin": self.margin, "missing": list(self.missing), "rule": self.rule}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Combined:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["loss"]), optional_float(d.get("u_loss")), str(d["dominant"]),
                   {str(k): float(v) for k, v in d["parts"].items()},
                   tuple(str(k) for k in d.get("missing") or ()), str(d.get("rule", "sum")),
                   float(d.get("interaction", 0.0)), float(d.get("margin", 0.0)))


def dominant_property(losses: Mapping[str, float]) -> str:
    """The property with the largest loss; a tie (losses within :data:`DOMINANCE_RTOL`
    relative or :data:`DOMINANCE_ATOL` absolute of the largest, e.g. two properties both at
    their baseline's 0) goes to the first of the tied ones in :data:`DOMINANCE_ORDER`, whatever
    the mapping's order, so the verdict's ``... dominates`` clause is the same on every run and
    machine."""
    if not losses:
        raise InvalidValueError("no property measured: nothing dominates")
    top = max(losses.values())
    tied = [k for k, x in losses.items()
            if math.isclose(x, top, rel_tol=DOMINANCE_RTOL, abs_tol=DOMINANCE_ATOL)]

    def rank(k: str) -> tuple[int, str]:
        return (DOMINANCE_ORDER.index(k) if k in DOMINANCE_ORDER else len(DOMINANCE_ORDER), k)

    return min(tied, key=rank)


def combine(parts: Mapping[str, tuple[float, float | None] | None],
            interaction: float = INTERACTION) -> Combined:
    """Combine per-property ``(loss, u)`` (None: not measured) by :data:`COMBINATION`.

    ``loss = sum(l_i) + interaction * sqrt(max(l_s, 0) * max(l_n, 0))`` over the measured
    parts (``l_s``, ``l_n``: sharpness and noise, when both are); its standard uncertainty
    propagates the parts' to first order (``d loss / d l_s = 1 + interaction * sqrt(l_n / l_s)
    / 2``; None where a part's is unknown)."""
    have = {k: v for k, v in parts.items() if v is not None}
    missing = tuple(k for k, v in parts.items() if v is None)
    if not have:
        raise InvalidValueError("no property measured: nothing to combine")
    grad = dict.fromkeys(have, 1.0)
    term = 0.0
    a, b = INTERACTING
    if a in have and b in have and interaction > 0:
        la, lb = max(have[a][0], 0.0), max(have[b][0], 0.0)
        term = interaction * math.sqrt(la * lb)
        if term > 0:
            grad[a] += term / (2 * la)
            grad[b] += term / (2 * lb)
    loss = sum(v[0] for v in have.values()) + term
    us = [(grad[k], v[1]) for k, v in have.items()]
    u = (None if any(x is None for _, x in us)
         else math.sqrt(sum((g * x) ** 2 for g, x in us if x is not None)))
    dominant = dominant_property({k: v[0] for k, v in have.items()})
    return Combined(loss, u, dominant, {k: v[0] for k, v in have.items()}, missing,
                    interaction=term)


@record
class PropertyJudgement:
    """Colour, sharpness and noise judged together (:func:`judge_properties`).

    Attributes
    ----------
    column
        The loss column (``dmap_points`` ...).
    colour, u_colour
        The colour loss that decides a ``max-dmap`` verdict (classic or direction-aware) and
        its standard uncertainty.
    predictions
        The sharpness and noise predictions made (:class:`PropertyPrediction`).
    not_judged
        ``(property, reason)`` for each property not measured or without a table.
    combined
        The losses combined (:data:`fidelity.prediction.properties.COMBINATION`).
    limits
        Property -> the axis value whose worst-case loss equals the colour table's loss at
        ``limit_delta_e`` (None: the table never reaches it), and ``limit_loss`` that loss:
        the default thresholds of a ``max-delta-e`` verdict.
    limit_delta_e, limit_loss
        The ΔE and its predicted loss the limits are equivalent to.
    failed
        The properties over their limit (``max-delta-e``) or the dominant one of a failed
        ``max-dmap`` verdict.
    """

    column: str
    colour: float | None
    u_colour: float | None
    predictions: tuple[PropertyPrediction, ...]
    not_judged: tuple[tuple[str, str], ...]
    combined: Combined | None
    limits: Mapping[str, float | None]
    limit_delta_e: float
    limit_loss: float | None
    failed: tuple[str, ...] = ()

    def prediction(self, prop: str) -> PropertyPrediction | None:
        """The prediction of ``prop``; None if not judged."""
        return next((p for p in self.predictions if p.property == prop), None)

    @property
    def complete(self) -> bool:
        """Whether every property was judged."""
        return not self.not_judged

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"column": self.column, "colour": self.colour, "u_colour": self.u_colour,
                "predictions": {p.property: p.to_json() for p in self.predictions},
                "not_judged": {k: why for k, why in self.not_judged},
                "combined": self.combined.to_json() if self.combined else None,
                "combination": COMBINATION,
                "limits": dict(self.limits), "limit_delta_e": self.limit_delta_e,
                "limit_loss": self.limit_loss, "failed": list(self.failed)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PropertyJudgement:
        """Inverse of :meth:`to_json`."""
        def opt(v: Any) -> float | None:
            return None if v is None else float(v)
        return cls(str(d["column"]), opt(d.get("colour")), opt(d.get("u_colour")),
                   tuple(PropertyPrediction.from_json(p)
                         for p in (d.get("predictions") or {}).values()),
                   tuple((str(k), str(v)) for k, v in (d.get("not_judged") or {}).items()),
                   Combined.from_json(d["combined"]) if d.get("combined") else None,
                   {str(k): opt(v) for k, v in (d.get("limits") or {}).items()},
                   float(d["limit_delta_e"]), opt(d.get("limit_loss")),
                   tuple(str(k) for k in d.get("failed") or ()))
