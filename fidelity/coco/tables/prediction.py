"""The measured prediction table a sweep's tables make, with its provenance.

:func:`prediction_table` writes the worst cases of :class:`~fidelity.coco.tables.build.Tables`
as a document of the prediction-table format (:mod:`fidelity.prediction.tablefile`): one
curve per size class and per model, the partial rows left out, and the provenance of every
number (models, images, versions, machines, standard errors). Its source words name colour's
transforms (SAFE-COLOR's, calibrated on the chart) and its curves are over the chart ΔE, the
only axis the table format has so far.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fidelity.coco.tables.build import ModelSummary, Tables
from fidelity.coco.tables.provenance import STANDARD_ERROR_WORDS, scorer_words
from fidelity.coco.tables.worst import SizeClassRow, WorstCaseRow
from fidelity.core.fileio import portable_paths


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

    for size, srows in tables.size_classes.items():
        curves.append({"size": size, "model": None, "points": complete_points(
            size, srows, [f"worst over {r.models} model(s) of size {size}: "
                          f"{', '.join(r.model_names)}" for r in srows])})
    for m, wrows in tables.worst_case.items():
        info = tables.models[m]
        curves.append({"size": info.size, "model": m, "baseline_map": info.baseline_map,
                       "baseline_ap": info.baseline_ap or {},
                       "points": complete_points(m, wrows, [
                           f"{m} worst case over {r.transforms_done} transforms"
                           for r in wrows])})
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


def _round(v: float | None, nd: int = 4) -> float | None:
    return None if v is None else round(float(v), nd)


__all__ = [
    "prediction_table",
    "standard_error_methods",
]
