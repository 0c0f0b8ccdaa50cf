"""The validated bound: the predicted ΔmAP's upper bound with the model's own error in it,
fitted on the validation's residuals (issue 58).

The interval of :mod:`fidelity.prediction.interval` is the table's sampling error with the
chart ΔE's uncertainty; it leaves out how far the worst-case prediction itself is from the loss
measured on realistic cameras (docs/validation.md). The validated bound puts that model-form
error in, from the validation's (camera, detector) cells (``m`` measured, ``p`` the classic
prediction, ΔmAP in percentage points):

``U = a max(p, 0) + q``

with ``a`` the least-squares slope through the origin of ``m`` on ``p`` and ``q`` the
split-conformal quantile of the residuals ``m - a p``: the ``ceil((n + 1)(1 - alpha))``-th
smallest of the ``n`` cells' (Vovk, Gammerman & Shafer 2005; Lei et al. 2018, "Distribution-free
predictive inference for regression", JASA 113), which bounds an exchangeable new cell with
probability >= 1 - alpha. ``python -m benchmarks.studies.interval --data`` fits it on the
committed validation cells (``reports/validation/directional.json``) and ships it as
:data:`VALIDATED_BOUND_FILE`, with the coverage it had leaving each camera out (its constants
fitted on the other cameras' cells) and its median over-prediction ``U / m``.

It applies to the table and detector size it was validated with (``coco1000-measured``,
size ``n``; elsewhere none is stated), and holds for cameras like those validated: the
validity domain's checks (:meth:`fidelity.prediction.interval.ValidatedCameras.camera_checks`)
say when a camera is not.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import replace
from functools import lru_cache
from typing import Any

from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.prediction.properties import INTERACTING, Combined, PropertyTable
from fidelity.prediction.table import Prediction

__all__ = ["PROPERTY_MARGIN_FILE", "VALIDATED_BOUND_FILE", "ColumnMargin", "PropertyMargin",
           "ValidatedBound", "load_property_margin", "load_validated_bound", "validated_upper",
           "with_margin"]

#: The shipped bound (``fidelity/data/``), written by the interval study.
VALIDATED_BOUND_FILE = "validated-bound.json"
#: The shipped margin of the combined property loss (``fidelity/data/``), written by
#: ``python -m benchmarks.studies.interval --properties --data``.
PROPERTY_MARGIN_FILE = "property-margin.json"


@record
class ValidatedBound:
    """The fitted bound (module docstring) and how it held on the validation.

    ``method``, ``prediction`` (``classic``), ``column`` (``dmap_points``), the ``table`` and
    detector ``size`` validated; ``alpha`` (miscoverage); ``a`` (unitless) and ``q``
    (percentage points); ``cells`` and ``cameras`` fitted on; leaving each camera out,
    ``cells_covered`` and ``cameras_covered`` (both of its cells); ``median_ratio``, the
    median ``U / m`` over the cells measured above 0, and ``median_ratio_significant`` over
    the ``significant_cells`` measured more than 2 SE above 0; ``source``, the validation
    file's path in the repository and its ``source_sha256``."""

    method: str
    prediction: str
    column: str
    table: str
    size: str
    alpha: float
    a: float
    q: float
    cells: int
    cameras: int
    cells_covered: int
    cameras_covered: int
    median_ratio: float
    median_ratio_significant: float | None
    significant_cells: int
    source: str
    source_sha256: str

    def upper(self, p: float) -> float:
        """``U = a max(p, 0) + q`` (percentage points) for a classic prediction ``p``."""
        return self.a * max(p, 0.0) + self.q

    def applies(self, prediction: Prediction) -> bool:
        """Whether ``prediction`` was made with the table and detector size validated."""
        return (prediction.table.name == self.table and prediction.size_used == self.size)

    def words(self) -> str:
        """``0.141 p + 1.44, calibrated split-conformal at 95 % on the validation's 60 cells;
        leaving each camera out it held 58 of 60``."""
        return (f"{self.a:.3g} p + {self.q:.3g}, {self.method} at {100 * (1 - self.alpha):.0f} % on the "
                f"validation's {self.cells} cells; leaving each camera out it held "
                f"{self.cells_covered} of {self.cells}")

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, with ``kind`` ``validated-bound``."""
        return {"kind": "validated-bound", "method": self.method,
                "prediction": self.prediction, "column": self.column, "table": self.table,
                "size": self.size, "alpha": self.alpha, "a": self.a, "q": self.q,
                "cells": self.cells, "cameras": self.cameras,
                "cells_covered": self.cells_covered, "cameras_covered": self.cameras_covered,
                "median_ratio": self.median_ratio,
                "median_ratio_significant": self.median_ratio_significant,
                "significant_cells": self.significant_cells, "source": self.source,
                "source_sha256": self.source_sha256}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidatedBound:
        """Inverse of :meth:`to_json`."""
        sig = d.get("median_ratio_significant")
        return cls(str(d["method"]), str(d["prediction"]), str(d["column"]), str(d["table"]),
                   str(d["size"]), float(d["alpha"]), float(d["a"]), float(d["q"]),
                   int(d["cells"]), int(d["cameras"]), int(d["cells_covered"]),
                   int(d["cameras_covered"]), float(d["median_ratio"]),
                   None if sig is None else float(sig), int(d["significant_cells"]),
                   str(d["source"]), str(d["source_sha256"]))


def _shipped(name: str) -> dict[str, Any] | None:
    """The JSON document ``fidelity/data/<name>``; None when the package ships none."""
    path = resource_dir("data") / name
    if not path.is_file():
        return None
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


@lru_cache(maxsize=1)
def load_validated_bound() -> ValidatedBound | None:
    """The shipped :class:`ValidatedBound`; None when the package ships none."""
    doc = _shipped(VALIDATED_BOUND_FILE)
    return None if doc is None else ValidatedBound.from_json(doc)


def validated_upper(prediction: Prediction, column: str = "dmap_points"
                    ) -> tuple[float, ValidatedBound] | None:
    """The validated bound of ``prediction``'s ``column`` and the bound it came from; None
    where none applies (another column, table or detector size, or no value)."""
    bound = load_validated_bound()
    if bound is None or column != bound.column or not bound.applies(prediction):
        return None
    c = prediction.columns.get(column)
    if c is None or c.value is None:
        return None
    return bound.upper(c.value), bound


# --------------------------------------------------------------------------------------------
# The margin of the combined property loss (issue 56)


@record
class ColumnMargin:
    """The margin of one loss column and how it held on the sharpness and noise validation.

    ``q``: the split-conformal quantile of ``log((m + c) / (L + c))`` over the validation's
    cells (``m`` measured, ``L`` the combination rule's loss), fitted on all of them;
    ``cells``, ``cameras``; leaving each camera out (``q`` fitted on the other cameras'
    cells), ``cells_covered`` and ``cameras_covered`` (both of its cells), ``median_ratio``
    (median bound / measured over the cells measured above 0) and
    ``median_ratio_significant`` over the ``significant_cells`` measured more than 2 SE above
    0."""

    q: float
    cells: int
    cameras: int
    cells_covered: int
    cameras_covered: int
    median_ratio: float
    median_ratio_significant: float | None
    significant_cells: int

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"q": self.q, "cells": self.cells, "cameras": self.cameras,
                "cells_covered": self.cells_covered, "cameras_covered": self.cameras_covered,
                "median_ratio": self.median_ratio,
                "median_ratio_significant": self.median_ratio_significant,
                "significant_cells": self.significant_cells}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ColumnMargin:
        """Inverse of :meth:`to_json`."""
        sig = d.get("median_ratio_significant")
        return cls(float(d["q"]), int(d["cells"]), int(d["cameras"]), int(d["cells_covered"]),
                   int(d["cameras_covered"]), float(d["median_ratio"]),
                   None if sig is None else float(sig), int(d["significant_cells"]))


@record
class PropertyMargin:
    """The validated margin of the combined colour, sharpness and noise loss.

    The combination rule (:data:`fidelity.prediction.properties.COMBINATION`) bounds the
    validation's measured joint loss in most cells, but a cell measured on the very images a
    table was measured on can sit a few hundredths of a point above its prediction. The margin
    is the split-conformal log-ratio bound of that rule's loss ``L`` (Lei et al. 2018, JASA
    113; ``benchmarks.studies.interval``, ``reports/validation/properties-interval.md``):

    ``U = (L + c) exp(max(q, 0)) - c``

    with ``c`` = :attr:`offset` (in the column's unit) and ``q`` the column's
    :class:`ColumnMargin`. It never lowers the rule's loss (``q`` below 0 counts as 0). It
    applies where it was validated: sharpness and noise both judged, from the ``tables``
    validated, with the detectors of the validated size class (module :func:`applies`).

    Attributes
    ----------
    method
        ``log-ratio split-conformal``.
    rule
        The combination rule it was fitted on.
    tables
        Property -> the table the validation predicted with (``colour``, ``sharpness``,
        ``noise``).
    size
        The detector size class validated.
    alpha
        Miscoverage (0.05).
    offset
        ``c`` (column units; 0.5).
    columns
        Loss column -> its :class:`ColumnMargin`.
    source, source_sha256
        The validation file's path in the repository and its SHA-256.
    """

    method: str
    rule: str
    tables: Mapping[str, str]
    size: str
    alpha: float
    offset: float
    columns: Mapping[str, ColumnMargin]
    source: str
    source_sha256: str

    def upper(self, loss: float, column: str = "dmap_points") -> float:
        """``(max(L, 0) + c) exp(max(q, 0)) - c`` for the rule's loss ``loss`` of
        ``column`` (its unit); the loss itself for a column without a margin."""
        m = self.columns.get(column)
        if m is None:
            return loss
        return (max(loss, 0.0) + self.offset) * math.exp(max(m.q, 0.0)) - self.offset

    def factor(self, column: str = "dmap_points") -> float:
        """``d U / d L``: ``exp(max(q, 0))`` (1 for a column without a margin)."""
        m = self.columns.get(column)
        return 1.0 if m is None else math.exp(max(m.q, 0.0))

    def words(self, column: str = "dmap_points") -> str:
        """``log-ratio split-conformal at 95 % on the validation's 78 cells; leaving each
        camera out it held 75 of 78``."""
        m = self.columns[column]
        return (f"{self.method} at {100 * (1 - self.alpha):.0f} % on the validation's "
                f"{m.cells} cells; leaving each camera out it held {m.cells_covered} of "
                f"{m.cells}")

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, with ``kind`` ``property-margin``."""
        return {"kind": "property-margin", "method": self.method, "rule": self.rule,
                "tables": dict(self.tables), "size": self.size, "alpha": self.alpha,
                "offset": self.offset,
                "columns": {k: v.to_json() for k, v in self.columns.items()},
                "source": self.source, "source_sha256": self.source_sha256}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PropertyMargin:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["method"]), str(d["rule"]),
                   {str(k): str(v) for k, v in d["tables"].items()}, str(d["size"]),
                   float(d["alpha"]), float(d["offset"]),
                   {str(k): ColumnMargin.from_json(v) for k, v in d["columns"].items()},
                   str(d["source"]), str(d["source_sha256"]))


@lru_cache(maxsize=1)
def load_property_margin() -> PropertyMargin | None:
    """The shipped :class:`PropertyMargin`; None when the package ships none."""
    doc = _shipped(PROPERTY_MARGIN_FILE)
    return None if doc is None else PropertyMargin.from_json(doc)


def with_margin(combined: Combined, column: str, tables: Mapping[str, PropertyTable],
                size: str, margin: PropertyMargin | None = None) -> Combined:
    """``combined`` with the validated margin in its loss where the margin applies; as it is
    elsewhere.

    Parameters
    ----------
    combined
        The rule's combination (:func:`fidelity.prediction.properties.combine`).
    column
        Its loss column (:data:`fidelity.prediction.properties.LOSS_COLUMNS`).
    tables
        Property -> the table its loss was predicted from.
    size
        The detector size class of the predictions.
    margin
        The margin (None: the shipped :func:`load_property_margin`).

    Returns
    -------
    Combined
        ``loss`` = :meth:`PropertyMargin.upper` of the rule's loss, ``u_loss`` times
        :meth:`PropertyMargin.factor`, ``margin`` the difference, where: the column has a
        margin; sharpness and noise were both judged (the validation's cells always judged
        both); each from the table validated, whose detectors at ``size`` are those of the
        validated size class. Elsewhere ``combined`` itself (``margin`` 0).
    """
    margin = load_property_margin() if margin is None else margin
    if margin is None or column not in margin.columns or combined.margin:
        return combined
    for prop in INTERACTING:
        table = tables.get(prop)
        if (prop not in combined.parts or table is None
                or table.name != margin.tables.get(prop)
                or table.detectors(size) != table.detectors(margin.size)):
            return combined
    upper = margin.upper(combined.loss, column)
    u = None if combined.u_loss is None else combined.u_loss * margin.factor(column)
    return replace(combined, loss=upper, u_loss=u, margin=upper - combined.loss)
