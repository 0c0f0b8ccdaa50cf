"""The tables of a sweep store: every cell, worst case and size class, with its provenance.

:func:`build_tables` reads a :class:`fidelity.coco.sweep.SweepStore` into :class:`Tables`
(cells of :mod:`~fidelity.coco.tables.grid`, worst cases of
:mod:`~fidelity.coco.tables.worst`, rare-class shares of
:mod:`~fidelity.coco.tables.classes`); :func:`merge_tables` keeps the models of an earlier
``tables.json`` that the store does not hold. The records are frozen dataclasses;
``to_json``/``from_json`` write and read them as ``tables.json`` holds them.

The transforms of a store whose grid names none are SAFE-COLOR's
(:data:`fidelity.prediction.transforms.TRANSFORMS`); a second property's sweep names its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import PurePath
from typing import TYPE_CHECKING, Any

from fidelity.coco.store import RegisteredModel
from fidelity.coco.tables.classes import RARE_BOXES, rare_class_shares
from fidelity.coco.tables.grid import (
    SAFETY_CLASSES,
    AlignedCount,
    CellDelta,
    add_standard_errors,
    align_image_counts,
    cell_deltas,
    finished_value,
    model_size,
)
from fidelity.coco.tables.provenance import (
    RUN_KEYS,
    earlier_runs,
    record_by_name,
    runs_passed_on,
)
from fidelity.coco.tables.worst import SizeClassRow, WorstCaseRow, size_class_rows, worst_case_rows
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.record import record
from fidelity.prediction.transforms import TRANSFORMS

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepStore


@record
class ModelSummary:
    """A swept model in the tables: its store registration (None if it was never registered),
    size class, baseline scores (fractions) and the image count its cells are reported on."""

    registration: RegisteredModel | None
    size: str
    baseline_map: float
    baseline_map50: float
    baseline_ap: dict[str, float | None]
    images: int

    @property
    def settings(self) -> dict[str, Any]:
        """The detector's provenance settings (empty without a registration)."""
        return self.registration.settings if self.registration is not None else {}

    def to_json(self) -> dict[str, Any]:
        """The registration's keys followed by the summary's."""
        reg = self.registration.to_json() if self.registration is not None else {}
        return reg | {"size": self.size, "baseline_map": self.baseline_map,
                      "baseline_map50": self.baseline_map50, "baseline_ap": self.baseline_ap,
                      "images": self.images}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ModelSummary:
        """Inverse of :meth:`to_json`."""
        reg = RegisteredModel.from_json(d) if "file" in d else None
        return cls(reg, d["size"], d["baseline_map"], d["baseline_map50"],
                   dict(d.get("baseline_ap") or {}), int(d["images"]))


@record
class Tables:
    """Everything the report needs from a sweep store (:func:`build_tables`).

    ``models``: per model its :class:`ModelSummary`; ``cells``: per model every transformed
    cell (:class:`~fidelity.coco.tables.grid.CellDelta`); ``worst_case``: per model its
    :class:`~fidelity.coco.tables.worst.WorstCaseRow` per ΔE; ``size_classes``: per size class
    its :class:`~fidelity.coco.tables.worst.SizeClassRow` per ΔE; ``meta``: the store's
    provenance (JSON) with its ``scorers``; ``transforms``: planned and seen transforms;
    ``cells_done``, ``cells_unreachable``; ``standard_errors``: whether SEs were computed;
    ``aligned``: per model its :class:`~fidelity.coco.tables.grid.AlignedCount` (with
    annotations only); ``rare_boxes``: the rare-class threshold of
    :class:`~fidelity.coco.tables.worst.RareShare` (None without annotations).
    """

    models: dict[str, ModelSummary]
    cells: dict[str, tuple[CellDelta, ...]]
    worst_case: dict[str, tuple[WorstCaseRow, ...]]
    size_classes: dict[str, tuple[SizeClassRow, ...]]
    meta: dict[str, Any]
    transforms: tuple[str, ...]
    cells_done: int
    cells_unreachable: int
    standard_errors: bool
    aligned: dict[str, AlignedCount]
    rare_boxes: int | None

    def to_json(self) -> dict[str, Any]:
        """The ``tables`` object of ``tables.json``."""
        return {
            "models": {m: v.to_json() for m, v in self.models.items()},
            "cells": {m: [r.to_json() for r in rows] for m, rows in self.cells.items()},
            "worst_case": {m: [r.to_json() for r in rows]
                           for m, rows in self.worst_case.items()},
            "size_classes": {s: [r.to_json() for r in rows]
                             for s, rows in self.size_classes.items()},
            "meta": self.meta, "transforms": list(self.transforms),
            "cells_done": self.cells_done, "cells_unreachable": self.cells_unreachable,
            "standard_errors": self.standard_errors,
            "aligned": {m: a.to_json() for m, a in self.aligned.items()},
            "rare_boxes": self.rare_boxes,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Tables:
        """Inverse of :meth:`to_json`."""
        return cls(
            {m: ModelSummary.from_json(v) for m, v in d["models"].items()},
            {m: tuple(CellDelta.from_json(r) for r in rows) for m, rows in d["cells"].items()},
            {m: tuple(WorstCaseRow.from_json(r) for r in rows)
             for m, rows in d["worst_case"].items()},
            {s: tuple(SizeClassRow.from_json(r) for r in rows)
             for s, rows in d["size_classes"].items()},
            dict(d.get("meta") or {}), tuple(d["transforms"]), int(d["cells_done"]),
            int(d["cells_unreachable"]), bool(d.get("standard_errors")),
            {m: AlignedCount.from_json(a) for m, a in (d.get("aligned") or {}).items()},
            d.get("rare_boxes"))


def build_tables(store: SweepStore, coco: Any = None, *, method: str = "auto",
                 progress: bool = False, images: Mapping[str, int] | None = None) -> Tables:
    """Everything the report needs, from a :class:`fidelity.coco.sweep.SweepStore`.

    ``coco``: the sweep's annotations (pycocotools ``COCO``); when given, every model's cells
    are scored on one image count (:func:`~fidelity.coco.tables.grid.align_image_counts`;
    ``images`` caps it per model) and every done cell gets standard errors
    (:func:`~fidelity.coco.tables.grid.add_standard_errors`). Without it, cells scored on
    another image count than their baseline are left out
    (:func:`~fidelity.coco.tables.grid.cell_deltas`), there are no SEs, and ``images`` is an
    error.
    """
    cells = store.cells()
    if not cells:
        raise InputFileError(f"{store.path}: the sweep store has no finished cells yet")
    models = store.models()
    aligned: dict[str, AlignedCount] = {}
    if images and coco is None:
        raise InvalidValueError("--images needs the COCO annotations, to re-score cells on "
                                "fewer images: pass --annotations")
    if coco is not None:
        cells, aligned = align_image_counts(store, coco, cells, method, progress, images)
    deltas = cell_deltas(cells)
    baselines = {c.model: c for c in cells if c.transform == "baseline" and c.done}
    if coco is not None:
        deltas = add_standard_errors(store, coco, deltas, baselines, method, progress)
    meta = store.meta()
    grid = meta.get("grid") or {}
    planned = grid.get("transforms")
    if not planned:
        planned = list(TRANSFORMS)
    seen = {c.transform for c in cells if c.transform != "baseline"}
    transforms = sorted(set(planned) | seen)
    per_model = {m: worst_case_rows(rows, baselines[m], transforms)
                 for m, rows in deltas.items()}
    for m in baselines:
        per_model.setdefault(m, worst_case_rows([], baselines[m], transforms))
    if coco is not None:
        per_model = rare_class_shares(coco, per_model, cells, baselines)
    return Tables(
        models={m: ModelSummary(models.get(m), model_size(m), finished_value(b.map), finished_value(b.map50),
                                {k: (b.ap or {}).get(k) for k in SAFETY_CLASSES},
                                int(b.images or 0))
                for m, b in baselines.items()},
        cells={m: tuple(rows) for m, rows in deltas.items()},
        worst_case={m: tuple(rows) for m, rows in per_model.items()},
        size_classes={s: tuple(rows) for s, rows in size_class_rows(per_model).items()},
        meta=meta | {"scorers": store.scorers()},
        transforms=tuple(transforms),
        cells_done=sum(c.done for c in cells),
        cells_unreachable=sum(c.status == "unreachable" for c in cells),
        standard_errors=coco is not None,
        aligned=aligned,
        rare_boxes=RARE_BOXES if coco is not None else None,
    )


def _kept_provenance(kept: Sequence[str], earlier: Tables, source: Mapping[str, Any]
                     ) -> dict[str, Any]:
    """Where the kept models were measured: ``source`` (the earlier tables' file and SHA-256)
    and the kept models, with ``runs``, one record per run that measured some of them: the
    earlier tables' own store for the models it measured (the file by name, with that store's
    versions, machine(s), scorers and imported scores files), and for the models it had kept
    itself the records it carried, each with ``via`` naming the files it has passed through
    since. So a model kept through several merges is still named with the machine and
    versions that measured it."""
    carried = earlier_runs(earlier.meta.get("earlier") or {})
    carried_models = {m for r in carried for m in r.get("models") or ()}
    runs: list[dict[str, Any]] = []
    own = [m for m in kept if m not in carried_models]
    if own:
        runs.append(record_by_name(source) | {"models": own} | {
            k: earlier.meta[k] for k in RUN_KEYS if earlier.meta.get(k) is not None})
    runs += runs_passed_on(carried, kept, [record_by_name(source)])
    return dict(source) | {"models": list(kept), "runs": runs}


def merge_tables(tables: Tables, earlier: Tables, source: Mapping[str, Any]) -> Tables:
    """``tables`` (from a store) with the models of an ``earlier`` tables.json it does not hold.

    For re-measuring some detectors and keeping the others as they were measured: every model
    of ``tables`` replaces its namesake in ``earlier``; the kept models bring their own rows,
    cells, image alignment and registration (hence their recorded preprocessing and settings,
    which the prediction table's provenance carries per model). The size classes are the
    worst case over the merged models again. ``meta["earlier"]`` names what was kept and where
    it came from: ``source`` (e.g. the file's name and SHA-256) and, per run that measured
    some of the kept models (``runs``), that run's ``versions``, ``machine(s)``, ``scorers``
    and imported scores files, through any number of merges.

    Both must be measured on the same images (``meta["data"]``: image count and the file names
    of the image folder and annotations) and, where both have one, with the same rare-class
    threshold, else :class:`~fidelity.core.errors.InvalidValueError`. Standard errors count only
    where both have them.
    """
    def data_key(meta: Mapping[str, Any]) -> tuple[Any, ...]:
        d = meta.get("data") or {}
        return (d.get("image_count"), PurePath(str(d.get("images") or "")).name,
                PurePath(str(d.get("annotations") or "")).name)

    if data_key(tables.meta) != data_key(earlier.meta):
        raise InvalidValueError(
            f"{source.get('file', 'the earlier tables')}: measured on other images "
            f"({data_key(earlier.meta)}) than the store ({data_key(tables.meta)}); tables of "
            "different image sets cannot be merged")
    if None not in (tables.rare_boxes, earlier.rare_boxes) and \
            tables.rare_boxes != earlier.rare_boxes:
        raise InvalidValueError(
            f"{source.get('file', 'the earlier tables')}: rare-class threshold "
            f"{earlier.rare_boxes} against the store's {tables.rare_boxes}")
    kept = [m for m in earlier.models if m not in tables.models]
    if not kept:
        return tables
    worst = dict(tables.worst_case) | {m: earlier.worst_case[m] for m in kept
                                       if m in earlier.worst_case}
    kept_rows = [r for m in kept for r in earlier.cells.get(m, ())]
    return Tables(
        models=dict(tables.models) | {m: earlier.models[m] for m in kept},
        cells=dict(tables.cells) | {m: earlier.cells[m] for m in kept if m in earlier.cells},
        worst_case=worst,
        size_classes={s: tuple(rows) for s, rows in size_class_rows(worst).items()},
        meta=tables.meta | {"earlier": _kept_provenance(kept, earlier, source)},
        transforms=tuple(sorted(set(tables.transforms) | set(earlier.transforms))),
        # a kept model's baseline is a done cell too (the rows are its transformed cells)
        cells_done=tables.cells_done + len(kept) + sum(r.done for r in kept_rows),
        cells_unreachable=tables.cells_unreachable
        + sum(r.status == "unreachable" for r in kept_rows),
        standard_errors=tables.standard_errors and earlier.standard_errors,
        aligned=dict(tables.aligned) | {m: earlier.aligned[m] for m in kept
                                        if m in earlier.aligned},
        rare_boxes=tables.rare_boxes if tables.rare_boxes is not None else earlier.rare_boxes,
    )


__all__ = [
    "ModelSummary",
    "Tables",
    "build_tables",
    "merge_tables",
]
