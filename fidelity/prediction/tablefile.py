"""The prediction-table file: its schema, its curves and the registry of shipped tables.

Prediction tables are JSON files in ``fidelity/data/prediction/<name>.json`` (the registry is
the folder: a table is available as soon as its file is there); the schema is in
``CORE_API.md`` ("Prediction table schema") and :data:`PREDICTION_TABLE_SCHEMA`. Each table
holds worst-case curves ΔE -> loss for detector size classes ``n, s, m, l, x`` or ``any``.
Columns:

- ``dmap_points``: percentage points of COCO mAP@[.50:.95], ``100 * (baseline - transformed)``;
- ``dmap_relative``: percent of the baseline mAP, ``100 * (baseline - transformed) / baseline``;
- ``dap_person_points``, ``dap_bicycle_points``: percentage points of the class AP.

The default is ``coco1000-measured``, the project's measured table (``fidelity tables`` from the
COCO sweep: per ΔE the worst case over the ten SAFE-COLOR transforms for four nano detectors on
the shared 1000-image val2017 subset; see reports/coco). ``safecolor-2025`` holds only the
SAFE-COLOR paper's published statements (each point cites its statement), as upper bounds.

The curves' axis is the chart's colour error, ``delta_e``: the only camera property with
tables so far. Reading a table at a ΔE is :mod:`fidelity.prediction.interpolate`; the
prediction, :mod:`fidelity.prediction.table`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError, unknown_name
from fidelity.core.fileio import cached_while_unchanged, display_path
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

#: The table used when none is named: the project's measured table (the COCO sweep, issue 5).
DEFAULT_TABLE = "coco1000-measured"

#: Loss columns of a prediction table, in output order.
COLUMNS: tuple[str, ...] = ("dmap_points", "dmap_relative", "dap_person_points",
                            "dap_bicycle_points")
#: Detector size classes (Ultralytics nano ... extra large) and ``any``.
SIZES: tuple[str, ...] = ("n", "s", "m", "l", "x", "any")
#: ``--class`` choices -> the column that measures that class's loss in points.
CLASS_COLUMNS: dict[str, str] = {
    "all": "dmap_points",
    "person": "dap_person_points",
    "bicycle": "dap_bicycle_points",
}
#: Largest possible loss in each column (total loss) when nothing better is known.
CEILING = 100.0


class TableKind(StrEnum):
    """What a prediction table's values are.

    ``published-bounds``: upper bounds read from a publication (the worst case over its
    transforms and detectors); ``measured``: the worst loss measured over the transforms (and
    models) at each ΔE, with sampling error; ``directional``: a measured table that also holds
    per-family curves (:mod:`fidelity.prediction.directional`). The value is the JSON ``kind``.
    """

    PUBLISHED_BOUNDS = "published-bounds"
    MEASURED = "measured"
    DIRECTIONAL = "directional"

    @property
    def upper_bound(self) -> bool:
        """True when the values are upper bounds rather than measured worst cases."""
        return self is TableKind.PUBLISHED_BOUNDS

    @property
    def measured(self) -> bool:
        """True when the values were measured (and carry sampling error)."""
        return self is not TableKind.PUBLISHED_BOUNDS


_KINDS = tuple(k.value for k in TableKind)


def prediction_dir() -> Path:
    """The folder of shipped prediction tables (the registry)."""
    return resource_dir("data") / "prediction"


def available_tables() -> list[str]:
    """Names of the prediction tables in the registry folder, sorted."""
    folder = prediction_dir()
    return sorted(p.stem for p in folder.glob("*.json")) if folder.is_dir() else []


@record
class Curve:
    """One worst-case curve of a table: ``delta_e`` (n,) and each column's (n,) values
    (NaN where the table has null), for a detector ``size`` and optional ``model``."""

    size: str
    model: str | None
    delta_e: np.ndarray
    values: dict[str, np.ndarray]
    sources: tuple[str, ...]
    worst_transforms: tuple[str | None, ...]
    baseline_map: float | None = None
    #: standard error of ``dmap_points`` at each point (measured tables; NaN where unknown)
    dmap_points_se: np.ndarray | None = None
    #: baseline AP in percent per class column (``dap_person_points`` ...), where known
    baseline_ap: dict[str, float] = field(default_factory=dict)
    #: per loss column with standard errors (``<column>_se`` in the file), the SE at each
    #: point (NaN where unknown); ``dmap_points`` is :attr:`dmap_points_se`
    column_se: dict[str, np.ndarray] = field(default_factory=dict)

    def se(self, column: str) -> np.ndarray | None:
        """The standard error of ``column`` at each point (None: the table has none)."""
        if column == "dmap_points":
            return self.dmap_points_se
        return self.column_se.get(column)

    def baseline_points(self, column: str) -> float | None:
        """The curve's baseline in percent for a points column (None: unknown or relative)."""
        if column == "dmap_points":
            return self.baseline_map
        return self.baseline_ap.get(column)


@record
class PredictionTable:
    """A prediction table read from JSON (see the module docstring and CORE_API.md)."""

    name: str
    title: str
    kind: TableKind
    provenance: dict[str, Any]
    units: dict[str, str]
    curves: tuple[Curve, ...]
    interpolation: str = "pchip"
    path: Path | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    def sizes(self) -> list[str]:
        """Size classes that have a curve of their own."""
        return sorted({c.size for c in self.curves}, key=SIZES.index)

    def select(self, size: str = "any") -> tuple[list[Curve], str]:
        """Curves that answer for ``size`` and the size they were made for.

        A size with its own curves gets those; otherwise the ``any`` curves (worst over every
        size); a table without ``any`` curves then answers with all its curves (worst case).
        Among the curves of one size, the table's aggregate curve (``model`` null: its own
        worst case over the models of that size) answers when it has one; per-model curves
        answer (worst of them) only when it has none. A table with neither the size asked
        for nor ``any`` answers with the worst case over the sizes it has, named by them
        (``"n"`` for a table of nano detectors, ``"n,s"`` for two sizes). A per-model curve that covers a narrower
        ΔE range, e.g. a model still being measured, then cannot turn every answer beyond that
        range into the total-loss ceiling.
        """
        if size not in SIZES:
            raise unknown_name("detector size", size, SIZES)

        def preferred(curves: list[Curve]) -> list[Curve]:
            aggregate = [c for c in curves if c.model is None]
            return aggregate or curves

        own = [c for c in self.curves if c.size == size]
        if own:
            return preferred(own), size
        anyc = [c for c in self.curves if c.size == "any"]
        if anyc:
            return preferred(anyc), "any"
        return preferred(list(self.curves)), ",".join(self.sizes())

    @classmethod
    def from_summary(cls, data: Mapping[str, Any]) -> PredictionTable:
        """The table as :meth:`summary` identifies it, without its curves (a prediction read
        back from JSON names its table; :func:`load_prediction_table` gives the curves)."""
        path = data.get("path")
        return cls(name=str(data["name"]), title=str(data.get("title", "")),
                   kind=TableKind(str(data["kind"])),
                   provenance=dict(data.get("provenance") or {}),
                   units=dict(data.get("units") or {}), curves=(),
                   interpolation=str(data.get("interpolation", "pchip")),
                   path=Path(path) if path else None)

    def summary(self) -> dict[str, Any]:
        """JSON-ready identification of the table (name, title, kind, provenance, units)."""
        return {
            "name": self.name,
            "title": self.title,
            "kind": self.kind.value,
            "interpolation": self.interpolation,
            "path": str(self.path) if self.path else None,
            "provenance": self.provenance,
            "units": self.units,
        }


def _distinct_delta_e(curve: Mapping[str, Any]) -> tuple[str, str] | None:
    de = sorted(float(p["delta_e"]) for p in curve["points"])
    if any(b <= a for a, b in zip(de, de[1:], strict=False)):
        return "points", "delta_e values must be distinct numbers >= 0"
    return None


def _some_loss(curve: Mapping[str, Any]) -> tuple[str, str] | None:
    if any(p.get(col) is not None for p in curve["points"] for col in COLUMNS):
        return None
    return "points", f"no loss values: every point lacks {', '.join(COLUMNS)}"


_LOSS = sc.Number(nullable=True)

#: One point of a curve: the chart ΔE and the loss in each column (``null``: not measured).
POINT_SCHEMA = sc.Table(fields=(
    sc.Field("delta_e", sc.Number(lo=0.0), required=True),
    *(sc.Field(col, _LOSS) for col in COLUMNS),
    *(sc.Field(f"{col}_se", sc.Number(lo=0.0, nullable=True)) for col in COLUMNS),
    sc.Field("worst_transform", sc.String(nullable=True)),
    sc.Field("source", sc.AnyValue()),
    sc.Field("partial", sc.Boolean(nullable=True)),
), extra=True)

#: One curve: a detector size (and model), its points and baselines.
CURVE_SCHEMA = sc.Table(fields=(
    sc.Field("size", sc.String(choices=SIZES, ignore_case=False), default="any"),
    sc.Field("model", sc.String(nullable=True)),
    sc.Field("points", sc.ListOf(POINT_SCHEMA, min_items=1), required=True),
    sc.Field("baseline_map", sc.Number(lo=0.0, hi=100.0, nullable=True)),
    sc.Field("baseline_ap", sc.MapOf(sc.Number(lo=0.0, hi=100.0, nullable=True),
                                     nullable=True, describe="an object (class -> AP)")),
), extra=True, rules=(sc.Check(_distinct_delta_e), sc.Check(_some_loss)))

#: A prediction table file (CORE_API.md, "Prediction table schema").
PREDICTION_TABLE_SCHEMA = sc.Table(fields=(
    sc.Field("name", sc.String(nonempty=True), required=True),
    sc.Field("kind", sc.String(choices=_KINDS, ignore_case=False), required=True),
    sc.Field("curves", sc.ListOf(CURVE_SCHEMA, min_items=1), required=True),
    sc.Field("interpolation", sc.String(choices=("pchip", "linear", "step"), ignore_case=False),
             default="pchip"),
    sc.Field("title", sc.String()),
    sc.Field("provenance", sc.MapOf(), default={}),
    sc.Field("units", sc.MapOf(), default={}),
), extra=True)

#: Largest prediction table file read, in bytes.
MAX_TABLE_BYTES = 16 << 20


def _percent(v: float | None) -> float | None:
    """A baseline in percent: a fraction in (0, 1] (pycocotools' scale) is multiplied by 100;
    larger values are taken as percent already."""
    if v is None:
        return None
    return v * 100.0 if v <= 1.0 else v


def _column(points: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    return np.array([math.nan if p.get(key) is None else float(p[key]) for p in points])


def parse_prediction_table(obj: dict[str, Any], origin: str = "<table>") -> PredictionTable:
    """Validate a prediction-table JSON object (:data:`PREDICTION_TABLE_SCHEMA`) and build a
    :class:`PredictionTable`. Raises :class:`~fidelity.core.schema.SchemaError` (an
    :class:`InputFileError`) as ``<origin>: <field>: <problem>``."""
    v = sc.validate(obj, PREDICTION_TABLE_SCHEMA, origin)
    curves = []
    for c in v["curves"]:
        pts = sorted(c["points"], key=lambda p: float(p["delta_e"]))
        ap = c.get("baseline_ap") or {}
        baseline_ap = {col: _percent(ap.get(cls)) for cls, col in CLASS_COLUMNS.items()
                       if cls != "all" and ap.get(cls) is not None}
        curves.append(Curve(
            size=c["size"],
            model=c.get("model"),
            delta_e=_column(pts, "delta_e"),
            values={col: _column(pts, col) for col in COLUMNS},
            sources=tuple(str(p.get("source", "")) for p in pts),
            worst_transforms=tuple(p.get("worst_transform") for p in pts),
            baseline_map=_percent(c.get("baseline_map")),
            baseline_ap={k: val for k, val in baseline_ap.items() if val is not None},
            dmap_points_se=(_column(pts, "dmap_points_se")
                            if any("dmap_points_se" in p for p in pts) else None),
            column_se={col: _column(pts, f"{col}_se") for col in COLUMNS
                       if col != "dmap_points" and any(f"{col}_se" in p for p in pts)},
        ))
    return PredictionTable(
        name=str(v["name"]),
        title=str(v.get("title", v["name"])),
        kind=TableKind(str(v["kind"])),
        provenance=dict(v["provenance"]),
        units=dict(v["units"]),
        curves=tuple(curves),
        interpolation=str(v["interpolation"]),
        raw=obj,
    )


def load_prediction_table(name_or_path: str | os.PathLike[str] | None = None) -> PredictionTable:
    """Load a table by registry name (``safecolor-2025``, ...) or from a JSON file path.

    ``None`` loads :data:`DEFAULT_TABLE`. Raises :class:`UnknownNameError` for an unknown name
    and :class:`InputFileError` for an unreadable or malformed file.
    """
    name = DEFAULT_TABLE if name_or_path is None else str(name_or_path)
    path = Path(name)
    if not (path.suffix == ".json" or os.sep in name or "/" in name):
        path = prediction_dir() / f"{name}.json"
        if not path.is_file():
            raise unknown_name("prediction table", name, available_tables())
    if not path.is_file():
        raise InputFileError(f"{display_path(path)}: prediction table does not exist")
    return _load_table_file(path)


@cached_while_unchanged(maxsize=16)
def _load_table_file(path: Path) -> PredictionTable:
    """The table in ``path``, read and validated once a process while the file is unchanged
    (a table is never modified once built)."""
    obj = sc.load_document(path, fmt="json", max_bytes=MAX_TABLE_BYTES,
                           what="prediction table")
    table = parse_prediction_table(obj, display_path(path))
    return PredictionTable(**{**table.__dict__, "path": path})


__all__ = [
    "CEILING",
    "CLASS_COLUMNS",
    "COLUMNS",
    "CURVE_SCHEMA",
    "DEFAULT_TABLE",
    "MAX_TABLE_BYTES",
    "POINT_SCHEMA",
    "PREDICTION_TABLE_SCHEMA",
    "SIZES",
    "Curve",
    "PredictionTable",
    "TableKind",
    "available_tables",
    "load_prediction_table",
    "parse_prediction_table",
    "prediction_dir",
]
