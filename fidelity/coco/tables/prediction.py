"""The measured prediction table a sweep's tables make, with its provenance.

:func:`prediction_table` writes the worst cases of :class:`~fidelity.coco.tables.build.Tables`
as a document of the prediction-table format (:mod:`fidelity.prediction.tablefile`): one
curve per size class and per model, the partial rows left out, and the provenance of every
number (models, images, versions, machines, standard errors). Its source words name colour's
transforms (SAFE-COLOR's, calibrated on the chart) and its curves are over the chart ΔE, the
only axis the table format has so far.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from fidelity.coco.tables.build import ModelSummary, Tables
from fidelity.coco.tables.provenance import STANDARD_ERROR_WORDS, scorer_words
from fidelity.coco.tables.worst import SizeClassRow, WorstCaseRow
from fidelity.core.fileio import portable_paths

if TYPE_CHECKING:
    from fidelity.coco.tables.grid import CellDelta


def prediction_table(tables: Tables, name: str = "coco1000-measured") -> dict[str, Any]:
    """A measured prediction table from the worst cases: the JSON document of the
    prediction-table schema (``fidelity/data/schemas``) that
    :func:`fidelity.prediction.tablefile.parse_prediction_table` reads."""
    meta = tables.meta
    # Partial rows (a reachable transform not measured yet) could understate the worst case:
    # they stay in the report but not in the prediction table; provenance lists them.
    curves: list[dict[str, Any]] = []
    omitted: list[str] = []

    def complete_points(label: str, rows: Sequence[WorstCaseRow | SizeClassRow],
                        sources: Sequence[str]) -> list[dict[str, Any]]:
        omitted.extend(f"{label} ΔE {r.delta_e:g}" for r in rows if r.partial)
        return [_point(r, src) for r, src in zip(rows, sources, strict=True) if not r.partial]

    ses = {m: {r.delta_e: row_errors(r, tables.cells.get(m, ())) for r in wrows}
           for m, wrows in tables.worst_case.items()}
    for size, srows in tables.size_classes.items():
        points = complete_points(size, srows, [f"worst over {r.models} model(s) of size "
                                               f"{size}: {', '.join(r.model_names)}"
                                               for r in srows])
        for point in points:
            point |= size_class_errors(point, tables.worst_case, ses)
        curves.append({"size": size, "model": None, "points": points})
    for m, wrows in tables.worst_case.items():
        info = tables.models[m]
        points = complete_points(m, wrows, [f"{m} worst case over {r.transforms_done} "
                                            f"transforms" for r in wrows])
        for point in points:
            point |= {f"{col}_se": _round(se)
                      for col, se in ses[m][point["delta_e"]].items() if col != "dmap_points"}
        curves.append({"size": info.size, "model": m, "baseline_map": info.baseline_map,
                       "baseline_ap": info.baseline_ap or {}, "points": points})
    return {
        "name": name,
        "title": "Measured worst-case detection loss on the shared COCO val2017 subset",
        "kind": "measured",
        "interpolation": "linear",
        "provenance": {
            "source": "fidelity sweep (issue 5): SAFE-COLOR transforms calibrated on the chart, "
                      "JPEG re-encoded with original tables, ONNX detectors, COCO box AP ("
                      + scorer_words(meta.get("scorers")) + ")",
            "models": {m: _model_provenance(info) for m, info in tables.models.items()},
            "images": portable_paths(meta.get("data")), "versions": meta.get("versions"),
            "machine": meta.get("machine"), "machines": meta.get("machines"),
            "cells_done": tables.cells_done, "cells_unreachable": tables.cells_unreachable,
            "worst_case": "per ΔE the transform with the largest ΔmAP in points; person and "
                          "bicycle columns are their own worst case over the same transforms",
            "omitted_partial_points": omitted,
            "aligned_image_counts": {m: a.to_json() for m, a in tables.aligned.items()},
            "standard_errors": {m: STANDARD_ERROR_WORDS[k]
                                for m, k in standard_error_methods(tables).items()},
        } | ({"earlier": portable_paths(meta["earlier"])} if meta.get("earlier") else {})
          | ({"imported": meta["imported"]} if meta.get("imported") else {})
          | ({"scores_files": meta["scores_files"]} if meta.get("scores_files") else {})
          | ({"versions_seen": meta["versions_seen"]}
             if len(meta.get("versions_seen") or ()) > 1 else {}),
        "units": {
            "dmap_points": "percentage points of mAP@[.50:.95] (100*(baseline-transformed))",
            "dmap_relative": "percent of the baseline mAP",
            "dap_person_points": "percentage points of person AP@[.50:.95]",
            "dap_bicycle_points": "percentage points of bicycle AP@[.50:.95]",
        },
        "curves": curves,
    }


def standard_error_methods(tables: Tables) -> dict[str, str]:
    """Per model, how its ΔmAP standard errors were computed: ``"larger"``, ``"bootstrap"``,
    ``"jackknife"``, ``"folds"`` or ``"mixed"`` (keys of
    :data:`~fidelity.coco.tables.provenance.STANDARD_ERROR_WORDS`); models without SEs left
    out."""
    out: dict[str, str] = {}
    for m, rows in tables.cells.items():
        kinds = {r.errors.method for r in rows if r.errors is not None
                 and r.errors.dmap_points is not None and r.errors.method is not None}
        if kinds:
            out[m] = kinds.pop() if len(kinds) == 1 else "mixed"
    return out


def _model_provenance(info: ModelSummary) -> dict[str, Any]:
    keep = ("file", "sha256", "size", "limit_images", "images", "baseline_map")
    st = info.settings
    return ({k: v for k, v in info.to_json().items() if k in keep}
            | {"conventions": st.get("conventions")}
            | ({"earlier_runs": st["earlier"]} if st.get("earlier") else {}))


def _point(r: WorstCaseRow | SizeClassRow, source: str) -> dict[str, Any]:
    return {"delta_e": r.delta_e, "dmap_points": _round(r.dmap_points),
            "dmap_relative": _round(r.dmap_relative),
            "dap_person_points": _round(r.dap_person_points),
            "dap_bicycle_points": _round(r.dap_bicycle_points),
            "dmap_points_se": _round(r.dmap_points_se),
            "worst_transform": r.worst_transform, "source": source,
            "partial": bool(r.partial)}


#: The loss columns of a table point; each has its standard error beside it (``<column>_se``).
SE_COLUMNS = ("dmap_points", "dmap_relative", "dap_person_points", "dap_bicycle_points")


def row_errors(row: WorstCaseRow, cells: Sequence[CellDelta]) -> dict[str, float | None]:
    """The standard error of each loss column of one model's worst-case ``row``: the SE of the
    cell whose value the row took (:func:`~fidelity.coco.tables.worst.worst_case_rows`): the
    worst transform's cell for ``dmap_points`` and ``dmap_relative``, and for each safety
    class the cell with its largest ΔAP among the transforms done at that ΔE (None: the cell
    has no SE; the baseline row has none)."""
    if row.is_baseline:
        return {col: None for col in SE_COLUMNS}
    out: dict[str, float | None] = {"dmap_points": row.dmap_points_se,
                                    "dmap_relative": row.dmap_relative_se}
    done = [c for c in cells if c.done and c.delta_e == row.delta_e]
    for col in ("dap_person_points", "dap_bicycle_points"):
        have = [c for c in done if _finite(getattr(c, col))]
        worst = max(have, key=lambda c: getattr(c, col)) if have else None
        out[col] = (getattr(worst.errors, col) if worst is not None
                    and worst.errors is not None else None)
    return out


def size_class_errors(point: dict[str, Any], worst: Mapping[str, Sequence[WorstCaseRow]],
                      ses: Mapping[str, Mapping[float, Mapping[str, float | None]]]
                      ) -> dict[str, float | None]:
    """The standard errors of a size-class ``point`` beside ``dmap_points_se`` (the worst
    model's): per column, the SE of the model whose worst-case row gave the column's value
    (:func:`~fidelity.coco.tables.worst.size_class_rows` takes each column's own maximum over
    the models of its source)."""
    de = point["delta_e"]
    models = [m for m in worst if m in point["source"]]
    out: dict[str, float | None] = {}
    for col in SE_COLUMNS[1:]:
        best, best_v = None, -math.inf
        for m in models:
            row = next((r for r in worst[m] if r.delta_e == de), None)
            v = None if row is None else getattr(row, col)
            if v is not None and _finite(v) and v > best_v:
                best, best_v = m, v
        out[f"{col}_se"] = _round(ses[best][de][col]) if best is not None else None
    return out


def _finite(v: float | None) -> bool:
    return v is not None and math.isfinite(v)


def _round(v: float | None, nd: int = 4) -> float | None:
    return None if v is None else round(float(v), nd)


__all__ = [
    "SE_COLUMNS",
    "prediction_table",
    "row_errors",
    "size_class_errors",
    "standard_error_methods",
]
