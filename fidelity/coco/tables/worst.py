"""The worst case over transforms at each level: per model, and per detector size class.

* Worst case of a model at ΔE: the transform with the largest ``dmap_points`` among the
  finished, reachable cells at that ΔE (``worst_transform``). Person and bicycle columns are
  worst cases of their own (the largest ΔAP over the same transforms), so each column is an
  upper envelope over transforms, as a prediction bound needs.
* Worst case of a size class (n, s, m, l, x): the largest value over the models of that size.
* A row lists how many transforms were finished at its ΔE (``transforms_done`` of
  ``transforms_reachable``); rows with missing transforms are marked partial.

The rows are built from the cells of :mod:`fidelity.coco.tables.grid`, whatever property
their transforms change; the level is named ``delta_e``, colour's axis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from fidelity.coco.tables.grid import CellDelta, finished_value, model_size
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepCell


@record
class RareShare:
    """How much of a worst-case ΔmAP comes from rare classes
    (:func:`~fidelity.coco.tables.classes.rare_class_shares`): ``dmap_points_rare`` (points),
    from ``rare_classes`` of the ``classes`` scored."""

    dmap_points_rare: float
    rare_classes: int
    classes: int


@record
class WorstCaseRow:
    """The worst case over transforms at one ΔE for one model (:func:`worst_case_rows`).

    ``dmap_points`` is the worst transform's ΔmAP (points), ``dmap_relative`` and ``map`` the
    same cell's; the ΔAP columns are each their own worst case over the transforms done.
    ``transforms_done`` of ``transforms_reachable`` were finished (``partial`` when fewer);
    ``unreachable`` lists the transforms that cannot reach this ΔE. The first row of a model
    is its baseline (ΔE 0, no worst transform, no losses).
    """

    delta_e: float
    worst_transform: str | None
    dmap_points: float
    dmap_relative: float | None
    map: float
    dap_person_points: float | None
    dap_bicycle_points: float | None
    dap_person_relative: float | None
    dap_bicycle_relative: float | None
    transforms_done: int
    transforms_reachable: int
    unreachable: tuple[str, ...]
    partial: bool
    dmap_points_se: float | None = None
    dmap_relative_se: float | None = None
    rare: RareShare | None = None

    @property
    def is_baseline(self) -> bool:
        """Whether this is the ΔE 0 row (no transform)."""
        return self.worst_transform is None

    def to_json(self) -> dict[str, Any]:
        """The row as ``tables.json`` holds it (the baseline row has no ``*_se`` keys)."""
        if self.is_baseline:
            return {"delta_e": self.delta_e, "worst_transform": None,
                    "dmap_points": self.dmap_points, "dmap_relative": self.dmap_relative,
                    "dap_person_points": self.dap_person_points,
                    "dap_bicycle_points": self.dap_bicycle_points,
                    "dap_person_relative": self.dap_person_relative,
                    "dap_bicycle_relative": self.dap_bicycle_relative, "map": self.map,
                    "transforms_done": self.transforms_done,
                    "transforms_reachable": self.transforms_reachable,
                    "unreachable": list(self.unreachable), "partial": self.partial}
        d: dict[str, Any] = {
            "delta_e": self.delta_e, "worst_transform": self.worst_transform,
            "dmap_points": self.dmap_points, "dmap_relative": self.dmap_relative,
            "dmap_points_se": self.dmap_points_se, "dmap_relative_se": self.dmap_relative_se,
            "map": self.map, "dap_person_points": self.dap_person_points,
            "dap_bicycle_points": self.dap_bicycle_points,
            "dap_person_relative": self.dap_person_relative,
            "dap_bicycle_relative": self.dap_bicycle_relative,
            "transforms_done": self.transforms_done,
            "transforms_reachable": self.transforms_reachable,
            "unreachable": list(self.unreachable), "partial": self.partial}
        if self.rare is not None:
            d |= {"dmap_points_rare": self.rare.dmap_points_rare,
                  "rare_classes": self.rare.rare_classes, "classes": self.rare.classes}
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WorstCaseRow:
        """Inverse of :meth:`to_json`."""
        rare = None
        if "dmap_points_rare" in d:
            rare = RareShare(d["dmap_points_rare"], int(d["rare_classes"]), int(d["classes"]))
        return cls(float(d["delta_e"]), d.get("worst_transform"), d["dmap_points"],
                   d.get("dmap_relative"), d["map"], d.get("dap_person_points"),
                   d.get("dap_bicycle_points"), d.get("dap_person_relative"),
                   d.get("dap_bicycle_relative"), int(d["transforms_done"]),
                   int(d["transforms_reachable"]), tuple(d.get("unreachable") or ()),
                   bool(d["partial"]), d.get("dmap_points_se"), d.get("dmap_relative_se"), rare)


@record
class SizeClassRow:
    """The worst case over the models of one size class at one ΔE (:func:`size_class_rows`).

    ``worst_model``/``worst_transform`` give the largest ``dmap_points``; the other loss
    columns are each their own maximum over the ``models`` models used (``model_names``: the
    models complete at this ΔE, or all when none is, then ``partial``).
    """

    delta_e: float
    worst_model: str
    worst_transform: str | None
    dmap_points: float
    dmap_points_se: float | None
    dmap_relative: float | None
    dap_person_points: float | None
    dap_bicycle_points: float | None
    models: int
    model_names: tuple[str, ...]
    partial: bool

    def to_json(self) -> dict[str, Any]:
        """The row as ``tables.json`` holds it."""
        return {"delta_e": self.delta_e, "worst_model": self.worst_model,
                "worst_transform": self.worst_transform, "dmap_points": self.dmap_points,
                "dmap_points_se": self.dmap_points_se, "dmap_relative": self.dmap_relative,
                "dap_person_points": self.dap_person_points,
                "dap_bicycle_points": self.dap_bicycle_points, "models": self.models,
                "model_names": list(self.model_names), "partial": self.partial}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SizeClassRow:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["delta_e"]), d["worst_model"], d.get("worst_transform"),
                   d["dmap_points"], d.get("dmap_points_se"), d.get("dmap_relative"),
                   d.get("dap_person_points"), d.get("dap_bicycle_points"), int(d["models"]),
                   tuple(d.get("model_names") or ()), bool(d["partial"]))


def _max_or_none(values: Sequence[float | None]) -> float | None:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return max(v) if v else None


def worst_case_rows(rows: Sequence[CellDelta], baseline: SweepCell,
                    transforms: Sequence[str] | None = None) -> list[WorstCaseRow]:
    """Worst case over transforms at each ΔE for one model (see module docstring)."""
    by_de: dict[float, list[CellDelta]] = {}
    for r in rows:
        by_de.setdefault(r.delta_e, []).append(r)
    out = [WorstCaseRow(0.0, None, 0.0, 0.0, finished_value(baseline.map), 0.0, 0.0, 0.0, 0.0, 0, 0,
                        (), False)]
    for de in sorted(by_de):
        group = by_de[de]
        done = [r for r in group if r.done]
        unreachable = tuple(sorted(r.transform for r in group if r.status == "unreachable"))
        if not done:
            continue
        worst = max(done, key=lambda r: finished_value(r.dmap_points))
        reachable = (len(transforms) - len(unreachable)) if transforms else len(done)
        se = worst.errors
        out.append(WorstCaseRow(
            delta_e=de, worst_transform=worst.transform, dmap_points=finished_value(worst.dmap_points),
            dmap_relative=worst.dmap_relative, map=finished_value(worst.map),
            dap_person_points=_max_or_none([r.dap_person_points for r in done]),
            dap_bicycle_points=_max_or_none([r.dap_bicycle_points for r in done]),
            dap_person_relative=_max_or_none([r.dap_person_relative for r in done]),
            dap_bicycle_relative=_max_or_none([r.dap_bicycle_relative for r in done]),
            transforms_done=len(done), transforms_reachable=reachable, unreachable=unreachable,
            partial=len(done) < reachable,
            dmap_points_se=se.dmap_points if se is not None else None,
            dmap_relative_se=se.dmap_relative if se is not None else None,
        ))
    return out


def size_class_rows(per_model: Mapping[str, Sequence[WorstCaseRow]]
                    ) -> dict[str, list[SizeClassRow]]:
    """Worst case over the models of each size class, per ΔE."""
    groups: dict[str, list[str]] = {}
    for m in per_model:
        groups.setdefault(model_size(m), []).append(m)
    out: dict[str, list[SizeClassRow]] = {}
    for size, models in sorted(groups.items()):
        des = sorted({r.delta_e for m in models for r in per_model[m]})
        rows = []
        for de in des:
            at_de = [(m, r) for m in models for r in per_model[m] if r.delta_e == de]
            # The worst case over the models whose row at this ΔE is complete (every reachable
            # transform measured); a partial row could understate it. Only when no model is
            # complete does the row fall back to the partial ones (and is marked partial).
            complete = [(m, r) for m, r in at_de if not r.partial]
            cand = complete or at_de
            m, w = max(cand, key=lambda mr: mr[1].dmap_points)
            rows.append(SizeClassRow(
                delta_e=de, worst_model=m, worst_transform=w.worst_transform,
                dmap_points=w.dmap_points, dmap_points_se=w.dmap_points_se,
                dmap_relative=_max_or_none([r.dmap_relative for _, r in cand]),
                dap_person_points=_max_or_none([r.dap_person_points for _, r in cand]),
                dap_bicycle_points=_max_or_none([r.dap_bicycle_points for _, r in cand]),
                models=len(cand), model_names=tuple(mm for mm, _ in cand),
                partial=not complete))
        out[size] = rows
    return out


__all__ = [
    "RareShare",
    "SizeClassRow",
    "WorstCaseRow",
    "size_class_rows",
    "worst_case_rows",
]
