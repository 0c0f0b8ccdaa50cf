"""The direction-aware prediction table from a COCO sweep's tables.

Per transform family (:data:`fidelity.prediction.directional.FAMILIES`) and detector size
class (and per model), the worst case at each ΔE over the family's transforms: the curves that
:func:`fidelity.prediction.directional.predict_directional` reads (module docstring there).
Built from :class:`fidelity.coco.tables.build.Tables` (e.g. ``reports/coco/tables.json``) and
written to ``fidelity/data/prediction/coco1000-directional.json`` by ``fidelity tables
--directional``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fidelity.coco.tables.build import Tables
from fidelity.coco.tables.prediction import prediction_table
from fidelity.prediction.directional import COLUMNS, DEFAULT_DIRECTIONAL_TABLE, FAMILIES


def _family_point(cells: Sequence[Any], columns: Sequence[str]) -> dict[str, Any] | None:
    """The worst case of a family at one ΔE over ``cells`` (done CellDelta rows)."""
    if not cells:
        return None
    worst = max(cells, key=lambda c: c.dmap_points)
    point: dict[str, Any] = {"worst_transform": worst.transform, "worst_model": worst.model}
    for col in columns:
        vals = [getattr(c, col) for c in cells if getattr(c, col) is not None]
        point[col] = round(float(max(vals)), 4) if vals else None
    se = worst.errors.dmap_points if worst.errors is not None else None
    point["dmap_points_se"] = None if se is None else round(float(se), 4)
    # each other column's SE: that of the cell whose value the column took (as the classic
    # table's, fidelity.coco.tables.prediction.row_errors)
    for col in columns[1:]:
        have = [c for c in cells if getattr(c, col) is not None]
        top = max(have, key=lambda c: getattr(c, col)) if have else None
        v = getattr(top.errors, col) if top is not None and top.errors is not None else None
        point[f"{col}_se"] = None if v is None else round(float(v), 4)
    return point


def directional_table(tables: Tables, name: str = DEFAULT_DIRECTIONAL_TABLE,
                      classic_name: str = "coco1000-measured") -> dict[str, Any]:
    """The direction-aware prediction table (JSON) from a sweep's tables
    (:class:`fidelity.coco.tables.build.Tables`, e.g. read from ``reports/coco/tables.json``).

    Its ``curves`` are the classic measured table's
    (:func:`fidelity.coco.tables.prediction.prediction_table`), so the file also answers as a
    classic table; ``families`` holds, per family, one curve per size class (worst over its
    transforms and the class's models) and per model (worst over its transforms). A family's
    point at a ΔE is kept only when every transform of the family that reaches that ΔE on the
    chart was measured for every model of the curve (a partial point could understate the
    worst case); transforms that cannot reach it are left out, and where none reaches it the
    family's curve ends.
    """
    base = prediction_table(tables, classic_name)
    columns = COLUMNS
    families: dict[str, Any] = {}
    for fam in FAMILIES.values():
        members = set(fam.transforms)
        # per model and ΔE: the family's done cells, and whether every transform of the
        # family has a cell there that is done or unreachable (else the point is partial)
        by_model: dict[str, dict[float, list[Any]]] = {}
        complete: dict[str, dict[float, bool]] = {}
        for model, cells in tables.cells.items():
            seen: dict[float, set[str]] = {}
            ok: dict[float, bool] = {}
            done: dict[float, list[Any]] = {}
            for c in cells:
                if c.transform not in members:
                    continue
                key = float(c.delta_e)
                seen.setdefault(key, set()).add(c.transform)
                ok[key] = ok.get(key, True) and c.status in ("done", "unreachable")
                if c.done:
                    done.setdefault(key, []).append(c)
            by_model[model] = {e: done.get(e, []) for e in seen}
            complete[model] = {e: ok[e] and seen[e] == members for e in seen}
        curves: list[dict[str, Any]] = []
        sizes: dict[str, list[str]] = {}
        for model in sorted(by_model):
            sizes.setdefault(tables.models[model].size, []).append(model)
        for size, models in sorted(sizes.items()):
            targets = sorted({e for m in models for e in by_model[m]})
            points = [{"delta_e": 0.0, **dict.fromkeys(columns, 0.0),
                       **dict.fromkeys((f"{k}_se" for k in columns), None),
                       "worst_transform": None, "source": "ΔE 0: no transform"}]
            for e in targets:
                if not all(complete[m].get(e, False) for m in models):
                    continue
                p = _family_point([c for m in models for c in by_model[m].get(e, [])], columns)
                if p is None:
                    break
                points.append({"delta_e": e, **{k: p[k] for k in columns},
                               **{f"{k}_se": p[f"{k}_se"] for k in columns},
                               "worst_transform": p["worst_transform"],
                               "source": f"worst over {', '.join(fam.transforms)} and "
                                         f"{len(models)} model(s): {p['worst_model']}"})
            curves.append({"size": size, "model": None, "points": points})
            for m in models:
                info = tables.models[m]
                mpoints = [{"delta_e": 0.0, **dict.fromkeys(columns, 0.0),
                            **dict.fromkeys((f"{k}_se" for k in columns), None),
                            "worst_transform": None,
                            "source": "ΔE 0: no transform"}]
                for e in sorted(by_model[m]):
                    if not complete[m].get(e, False):
                        continue
                    p = _family_point(by_model[m][e], columns)
                    if p is None:
                        break
                    mpoints.append({"delta_e": e, **{k: p[k] for k in columns},
                                    **{f"{k}_se": p[f"{k}_se"] for k in columns},
                                    "worst_transform": p["worst_transform"],
                                    "source": f"{m}: worst over {', '.join(fam.transforms)}"})
                curves.append({"size": size, "model": m, "baseline_map": info.baseline_map,
                               "baseline_ap": info.baseline_ap or {}, "points": mpoints})
        families[fam.name] = {"transforms": list(fam.transforms), "fits": list(fam.fits),
                              "direction": fam.direction, "description": fam.description,
                              "curves": curves}
    provenance = dict(base["provenance"])
    # the shipped table's provenance names the function where it was first written
    provenance["directional"] = (
        "fidelity.prediction.directional.directional_table from the sweep's cells: per family "
        "the worst case over its transforms (and the size class's models); prediction = x f_F(E)"
        " + (1 - x) sum_d s_d f_d(E), see the module docstring")
    provenance["classic_table"] = classic_name
    return {**base, "name": name, "kind": "directional",
            "title": "Direction-aware worst-case detection loss on the shared COCO val2017 "
                     "subset (per transform family)",
            "provenance": provenance, "families": families}


__all__ = ["directional_table"]
