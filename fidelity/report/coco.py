"""The COCO benchmark report: worst-case tables, paper comparison and plots of a sweep.

Built as one :class:`~fidelity.report.document.Document` from a
:class:`~fidelity.coco.tables.colour.TablesResult` (:func:`tables_document`) and written as
``report.html`` and ``report.md`` (:func:`write_tables_report`, with ``tables.json`` and the
measured prediction table). Reading order: the headline (the worst case of every model at
SAFE-COLOR's thresholds, with the worst-case plot), the paper comparison and the ΔE limits, the
plots, the worst-case tables, then method and provenance; coverage and the table of every cell
are folded away. Figures: SVG drawn from the numbers by :mod:`fidelity.report.cocofigures`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.tables.colour import LIMIT_BUDGETS, PAPER_THRESHOLDS
from fidelity.coco.tables.prediction import prediction_table, standard_error_methods
from fidelity.coco.tables.provenance import STANDARD_ERROR_WORDS, earlier_runs, scorer_words
from fidelity.core.fileio import json_ready, write_json_atomic
from fidelity.prediction.table import limit_rounded_down
from fidelity.report import cocofigures as cf
from fidelity.report.document import (
    Block,
    Document,
    Facts,
    Figure,
    Headline,
    Section,
    Text,
    section,
    svg_figure,
    table,
)
from fidelity.report.format import listing, number, words
from fidelity.report.html import write_document

if TYPE_CHECKING:
    from fidelity.coco.tables.build import ModelSummary, Tables
    from fidelity.coco.tables.colour import CurveLimits, PaperFinding, TablesResult
    from fidelity.coco.tables.worst import WorstCaseRow

#: Title of the COCO benchmark report.
TITLE = "COCO benchmark: measured cost of colour error"

#: File name of the headline figure.
WORST_CASE_FIGURE = "worst_case.svg"


def map_vs_delta_e_figure(model: str) -> str:
    """File name of a model's mAP-against-ΔE plot."""
    return f"map_vs_de_{model}.svg"


# --------------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------------


def tables_figures(tables: Tables) -> dict[str, Figure]:
    """Every figure of the report by file name: the worst case, then mAP against ΔE per model
    (SVG, :mod:`fidelity.report.cocofigures`)."""
    out = {WORST_CASE_FIGURE: svg_figure(
        cf.worst_case_plot(tables), WORST_CASE_FIGURE,
        "worst-case ΔmAP against chart ΔE per model",
        "Worst-case ΔmAP (% of the baseline mAP) per model against chart ΔE00, ±2 SE; open "
        "circles: not every transform done. Dashed: SAFE-COLOR's bound (1 % to ΔE 3, 3 % to 6, "
        "10 % to 12). Right: the same on a log scale.")}
    for m in tables.cells:
        name = map_vs_delta_e_figure(m)
        out[name] = svg_figure(cf.map_vs_delta_e_plot(tables, m), name,
                               f"{m}: mAP against chart ΔE per transform",
                               f"{m}: mAP@[.50:.95] against chart ΔE00, one line per transform "
                               "(ΔE 0: the baseline).")
    return out


# --------------------------------------------------------------------------------------------
# Words
# --------------------------------------------------------------------------------------------


def conventions_words(conv: Mapping[str, Any]) -> str:
    """The post-processing thresholds in words: no NMS for an end-to-end head, no cap if None;
    the NMS input cap (``max_nms``) and multi-label NMS when the detector sets them."""
    iou = conv.get("iou")
    max_det = conv.get("max_det")
    return (f"conf {conv.get('conf')}, "
            + ("no NMS (end-to-end)" if iou is None else f"NMS IoU {iou}") + ", "
            + ("no detection cap" if max_det is None else f"max_det {max_det}")
            + (f", max_nms {conv['max_nms']}" if conv.get("max_nms") is not None else "")
            + (", multi-label" if conv.get("multi_label") else ""))


def run_history_words(info: ModelSummary, capped: bool = False) -> str:
    """The sweep runs behind a model's cells, in words (its latest registration and the
    registrations it replaced, see :meth:`fidelity.coco.store.ResultsStore.register_model`);
    ``capped``: the image count was asked for (``--images``), not set by the cells."""
    reg = info.registration
    limit, images = (reg.limit_images if reg is not None else None), info.images
    text = ""
    if limit and images and limit != images:
        which = f"first {images} asked for (`--images`)" if capped else (
            f"{images} that every cell has")
        text += (f" Latest run registered for the first {limit} images; reported on the "
                 f"{which}.")
    earlier = info.settings.get("earlier") or []
    if earlier:
        runs = "; ".join(
            f"first {e.get('limit_images') or 'all'} images"
            + "".join(f", {k} {_value_words(e[k])}" for k in ("threads", "providers") if k in e)
            for e in earlier)
        text += f" Earlier runs over the same file (oldest first): {runs}."
    return text


def _value_words(v: Any) -> str:
    return listing(v) if isinstance(v, list | tuple) else str(v)


def _input_words(size: Any) -> str:
    if isinstance(size, list | tuple):
        return "×".join(str(v) for v in size)
    return number(size)


def _model_run_line(m: str, info: ModelSummary, capped: bool) -> str:
    reg = info.registration
    st = info.settings
    conv = st.get("conventions") or {}
    sha = reg.sha256[:16] if reg is not None else number(None)
    return (f"- {m}: file {reg.file if reg is not None else number(None)} (sha256 {sha}), "
            f"layout {st.get('layout')}, input {_input_words(st.get('input_size'))}, providers "
            f"{listing(st.get('providers') or [])}, {st.get('threads')} intra-op thread(s); "
            f"{conv.get('source')}; {conv.get('preprocess')}."
            + run_history_words(info, capped))


def _loss(value: float | None, se: float | None = None) -> str:
    return number(value) + (f" ± {se:.2f}" if se else "")


def _limit_cell(status: str, delta_e: float | None) -> str:
    if status == "none" or delta_e is None:
        return "none"
    return f"{limit_rounded_down(delta_e):.2f}" + ("+" if status == "whole-range" else "")


# --------------------------------------------------------------------------------------------
# Document
# --------------------------------------------------------------------------------------------


def headline(tables: Tables, figure: Figure | None = None) -> Headline:
    """The main finding: every model's worst relative ΔmAP at SAFE-COLOR's thresholds."""
    lines = ["**Worst-case mAP loss (% of the baseline) at SAFE-COLOR's thresholds** (the "
             "paper: " + ", ".join(f"< {b:g} % up to ΔE {lim}" for lim, b in PAPER_THRESHOLDS)
             + "):", ""]
    for m, rows in tables.worst_case.items():
        parts = []
        for lim, _ in PAPER_THRESHOLDS:
            at = [r for r in rows if 0 < r.delta_e <= lim]
            if not at:
                parts.append(f"ΔE ≤ {lim}: not measured")
                continue
            w = max(at, key=lambda r: r.dmap_relative or 0)
            parts.append(f"ΔE ≤ {lim}: **{_loss(w.dmap_relative, w.dmap_relative_se)} %** "
                         f"({w.worst_transform} at ΔE {w.delta_e:g}"
                         + (", incomplete" if any(r.partial for r in at) else "") + ")")
        lines.append(f"- {m}: " + "; ".join(parts))
    return Headline("\n".join(lines), "info", figure)


def _run_section(tables: Tables) -> Section:
    meta = tables.meta
    d = meta.get("data") or {}
    facts = [("cells finished", f"{tables.cells_done} done, {tables.cells_unreachable} "
                                "unreachable (transform cannot reach the ΔE on the chart)"),
             ("images", f"{d.get('image_count')} shared COCO val2017 images (person-biased "
                        "subset, see shared/coco/PROVENANCE.md); a model swept on fewer uses "
                        "the first N by image id"),
             ("models", ", ".join(f"{m} ({info.images} images)"
                                  for m, info in tables.models.items()) or number(None)),
             ("versions", words(meta.get("versions"))),
             ("machine", words(meta.get("machine")))]
    machines = meta.get("machines") or []
    if len(machines) > 1:
        facts.append(("machines", f"{len(machines)} machines ran in this store: " + "; ".join(
            words(m) for m in machines)))
    earlier = meta.get("earlier")
    if earlier:
        facts.append(("kept from earlier tables",
                      f"{', '.join(earlier.get('models') or [])} from {earlier.get('file')} "
                      f"(SHA-256 {str(earlier.get('sha256'))[:12]}…): not re-measured in "
                      "this store"))
        for run in earlier_runs(earlier):  # an older version's one record: one run
            via = " via " + ", ".join(str(v.get("file")) for v in run["via"]) \
                if run.get("via") else ""
            ran = run.get("machines") or []
            where = (f"{len(ran)} machines: " + "; ".join(words(m) for m in ran)
                     if len(ran) > 1 else f"machine {words(run.get('machine'))}")
            facts.append((f"measured: {', '.join(run.get('models') or [])}",
                          f"in {run.get('file')}{via}; versions {words(run.get('versions'))}; "
                          f"{where}"))
    facts.append(("preprocessing", "; ".join(
        f"{m}: {(info.settings.get('conventions') or {}).get('preprocess') or number(None)}"
        for m, info in tables.models.items())))
    notes = []
    for m, a in tables.aligned.items():
        stored = " and ".join(map(str, a.stored))
        if a.capped:
            notes.append(f"- {m}: reported on the first {a.images} images, as asked "
                         f"(`--images`; cells stored on {stored} images, re-scored from their "
                         f"stored detections: {a.rescored}).")
        elif a.rescored:
            notes.append(f"- {m}: caught while its image limit was being raised (cells on "
                         f"{stored} images); reported on the first {a.images}, so that every "
                         "ΔmAP pairs a cell with its baseline on the same images (cells "
                         f"re-scored from their stored detections: {a.rescored}).")
    return section("Run", Facts(tuple(facts)), Text("\n".join(notes)) if notes else None)


def _comparison_section(tables: Tables, comparison: Sequence[PaperFinding]) -> Section:
    rows = [(c.claim, f"**{c.verdict}**", c.evidence) for c in comparison]
    return section("Comparison with SAFE-COLOR",
                   table(["paper's finding", "ours", "evidence"], rows,
                         numeric=[False, False, False]),
                   _noise_floor_text(tables))


def _noise_floor_text(tables: Tables) -> Text | None:
    grid = tables.meta.get("grid") or {}
    targets = _targets(tables, grid)
    low = [r.dmap_relative for rows in tables.cells.values() for r in rows
           if r.done and r.delta_e == min(targets or [0]) and r.dmap_relative is not None]
    if len(low) < 3:
        return None
    return Text(f"Noise floor: at ΔE {min(targets):g} the {len(low)} measured cells give "
                f"relative ΔmAP from {min(low):.2f} % to {max(low):.2f} % (sd "
                f"{float(np.std(low, ddof=1)):.2f} %); differences of that size between "
                "transforms or against a threshold are within the scatter that any small "
                "perturbation of the images causes on this image set, not findings.")


def _targets(tables: Tables, grid: Mapping[str, Any]) -> list[float]:
    return sorted({float(t) for t in grid.get("targets", []) if float(t) > 0}
                  | {r.delta_e for rows in tables.cells.values() for r in rows})


def _limits_section(limits: Sequence[CurveLimits]) -> Section | None:
    if not limits:
        return None
    head = [f"≤ {b:g} %" if c == "dmap_relative" else f"≤ {b:g} pts" for c, b in LIMIT_BUDGETS]
    rows = [[f"size {x.size} (worst of its models)" if x.model is None else x.model]
            + [_limit_cell(b.status, b.delta_e) for b in x.limits] for x in limits]
    return section(
        "ΔE limits our worst cases imply",
        Text("The largest chart ΔE00 at which the worst-case ΔmAP stays within each budget, as "
             "`fidelity predict --max-dmap P [--unit relative]` computes it from the curves "
             "(running maximum, linear between measured ΔE; rounded down to 0.01 as `predict` "
             "prints it). SAFE-COLOR's thresholds: ΔE 3 for 1 %, 6 for 3 %, 12 for 10 %. "
             "\"+\" = the budget holds over the whole table."),
        table(["curve", *head], rows))


def _worst_case_section(tables: Tables, m: str, rows: Sequence[WorstCaseRow]) -> Section:
    rare_n = tables.rare_boxes
    rare_col = rare_n is not None and any(r.rare is not None for r in rows)
    intro = None
    if rare_col:
        k = next((r.rare for r in rows if r.rare is not None), None)
        intro = Text(f"Of which rare: the points of ΔmAP that come from the "
                     f"{k.rare_classes if k else '?'} of {k.classes if k else '?'} classes "
                     f"with at most {rare_n} ground-truth boxes in the model's images (mAP "
                     "weighs every class alike; `fidelity tables STORE --explain "
                     "MODEL:TRANSFORM:ΔE` lists them).")
    header = ["ΔE", "worst transform", "ΔmAP points"] + (["of which rare"] if rare_col else []) \
        + ["ΔmAP relative %", "ΔAP person pts", "ΔAP bicycle pts", "transforms done",
           "unreachable"]
    body = []
    for r in rows[1:]:
        rare = [number(r.rare.dmap_points_rare if r.rare else None)] if rare_col else []
        body.append([f"{r.delta_e:g}", str(r.worst_transform),
                     _loss(r.dmap_points, r.dmap_points_se), *rare,
                     _loss(r.dmap_relative, r.dmap_relative_se), number(r.dap_person_points),
                     number(r.dap_bicycle_points),
                     f"{r.transforms_done}/{r.transforms_reachable}"
                     + (" (partial)" if r.partial else ""),
                     ", ".join(r.unreachable) or number(None)])
    numeric = [True, False] + [True] * (len(header) - 3) + [False]
    return section(f"Worst case: {m}", intro, table(header, body, numeric=numeric))


def _size_class_section(tables: Tables, size: str) -> Section:
    rows = [[f"{r.delta_e:g}" + (" (partial)" if r.partial else ""), r.worst_model,
             str(r.worst_transform), number(r.dmap_points), number(r.dmap_relative),
             number(r.dap_person_points), number(r.dap_bicycle_points)]
            for r in tables.size_classes[size][1:]]
    return section(
        f"Worst case: size class {size}",
        Text("Each column is its own worst case over the models of this size (and their "
             "transforms); partial: a model or transform missing."),
        table(["ΔE", "worst model", "worst transform", "ΔmAP points", "ΔmAP relative %",
               "ΔAP person pts", "ΔAP bicycle pts"], rows,
              numeric=[True, False, False, True, True, True, True]))


def _models_section(tables: Tables) -> Section:
    rows = [[m, info.size, str(info.images), f"{info.baseline_map:.4f}",
             f"{info.baseline_map50:.4f}", number(info.baseline_ap.get("person"), 4),
             number(info.baseline_ap.get("bicycle"), 4),
             conventions_words(info.settings.get("conventions") or {})]
            for m, info in tables.models.items()]
    return section("Models", table(
        ["model", "size", "images", "baseline mAP", "AP50", "AP person", "AP bicycle",
         "conventions"], rows, numeric=[False, False, True, True, True, True, True, False]))


def _method_section(tables: Tables) -> Section:
    runs = "\n".join(_model_run_line(m, info, bool(
        tables.aligned[m].capped if m in tables.aligned else False))
        for m, info in tables.models.items())
    blocks: list[Block | None] = [
        Text("Each image is decoded as sRGB code values (ICC profiles not applied), "
             "transformed with the parameter calibrated on the chart for (transform, ΔE) "
             "(fidelity.prediction.calibration, full precision; listed per cell below), rounded "
             "to 8 bit (exact 8-bit tables, equal to the float64 reference), JPEG-encoded with "
             "the original quantization tables and subsampling, decoded, and passed to the "
             "detector; ΔE 0 is the baseline (decode and re-encode only). Scoring: COCO box AP "
             f"({scorer_words(tables.meta.get('scorers'))}; faster-coco-eval agrees with the "
             "pycocotools reference to 1e-4, tested). Detections of every image are stored, so "
             "any cell can be re-scored without inference (`fidelity sweep --rescore`)."),
        Text(runs) if runs else None,
        Text("ΔmAP in **points** = 100·(mAP₀ − mAP); **relative** = 100·(mAP₀ − mAP)/mAP₀. "
             "ΔAP person/bicycle in points, each the worst over transforms at that ΔE."),
        _standard_error_text(tables),
    ]
    return section("Method", *blocks)


def _standard_error_text(tables: Tables) -> Text | None:
    if not tables.standard_errors:
        return None
    ses = {m: [r.errors.dmap_points for r in rows
               if r.errors is not None and r.errors.dmap_points is not None]
           for m, rows in tables.cells.items()}
    medians = ", ".join(f"{m} {float(np.median(s)):.2f}" for m, s in ses.items() if s)

    methods = standard_error_methods(tables)
    how = "; ".join(f"{m}: {STANDARD_ERROR_WORDS[k]}" for m, k in methods.items())
    return Text("± values are standard errors of ΔmAP, by detector: " + how + " (relative "
                "ΔmAP: the same over each loss as a share of its baseline); in points median "
                f"{medians} ({sum(map(len, ses.values()))} cells). A worst case over ten "
                "transforms is biased upwards by this noise.")


def _coverage_section(tables: Tables) -> Section:
    grid = tables.meta.get("grid") or {}
    targets = _targets(tables, grid)
    blocks: list[Block | None] = [Text("✓ done, ✗ unreachable on the chart (recorded with "
                                       "its reason), · not yet run.")]
    for m in tables.models:
        have = {(r.transform, r.delta_e): r.status for r in tables.cells.get(m, ())}
        done = sum(v == "done" for v in have.values())
        unr = sum(v == "unreachable" for v in have.values())
        todo = len(tables.transforms) * len(targets) - done - unr
        blocks.append(Text(f"**{m}**: baseline + {done} transformed cells done, {unr} "
                           f"unreachable, {todo} not yet run."))
        marks = [[f"{de:g}"] + [{"done": "✓", "unreachable": "✗"}.get(have.get((t, de), ""), "·")
                                for t in tables.transforms] for de in targets]
        blocks.append(table(["ΔE", *tables.transforms], marks,
                            numeric=[True] + [False] * len(tables.transforms)))
    started = set(tables.models)
    for spec in grid.get("models", []):
        stem = str(spec).split("@")[0].rsplit(".", 1)[0]
        if stem not in started:
            blocks.append(Text(f"**{stem}** (planned as {spec}): not started yet."))
    return section("Coverage (which cells this report is built from)", *blocks, folded=True)


def _all_cells_section(tables: Tables, m: str) -> Section:
    rows = []
    for r in sorted(tables.cells[m], key=lambda r: (r.transform, r.delta_e)):
        if not r.done:
            rows.append([r.transform, f"{r.delta_e:g}", number(None), "unreachable", "", "",
                         "", ""])
            continue
        rows.append([r.transform, f"{r.delta_e:g}", number(r.param, 4), number(r.map, 4),
                     number(r.dmap_points), number(r.dmap_relative),
                     number(r.dap_person_points), number(r.dap_bicycle_points)])
    return section(f"All cells: {m}", table(
        ["transform", "ΔE", "param", "mAP", "ΔmAP pts", "ΔmAP rel %", "ΔAP person pts",
         "ΔAP bicycle pts"], rows, numeric=[False] + [True] * 7), folded=True)


def tables_document(result: TablesResult, figures: Mapping[str, Figure] | None = None
                    ) -> Document:
    """The COCO benchmark report of ``result`` (figures: :func:`tables_figures`, made when
    not given)."""
    tables = result.tables
    figs = dict(figures) if figures is not None else tables_figures(tables)
    per_model = [figs[n] for m in tables.cells if (n := map_vs_delta_e_figure(m)) in figs]
    sections: list[Section | None] = [
        _comparison_section(tables, result.comparison),
        _limits_section(result.limits),
        section("mAP against ΔE, per model", *per_model) if per_model else None,
        *(_worst_case_section(tables, m, rows) for m, rows in tables.worst_case.items()),
        *(_size_class_section(tables, s) for s in tables.size_classes),
        _models_section(tables),
        _run_section(tables),
        _method_section(tables),
        _coverage_section(tables),
        *(_all_cells_section(tables, m) for m in tables.cells),
    ]
    return Document(TITLE, headline(tables, figs.get(WORST_CASE_FIGURE)),
                    tuple(s for s in sections if s is not None),
                    footer="Generated by `fidelity tables` from the sweep store; every number "
                           "is computed from stored detections.")


def write_tables_document(result: TablesResult, out_dir: str | os.PathLike[str]
                          ) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` with its SVG figures (atomically); the report
    alone, e.g. rebuilt from a ``tables.json`` (:meth:`TablesResult.from_json`)."""
    out = Path(out_dir)
    return {p.name: p for p in write_document(tables_document(result), html=out / "report.html",
                                              markdown=out / "report.md")}


def write_tables_report(result: TablesResult, out_dir: str | os.PathLike[str],
                        prediction_path: str | os.PathLike[str] | None = None,
                        name: str = "coco1000-measured") -> dict[str, Path]:
    """Write the report (:func:`write_tables_document`), ``tables.json`` and (optionally) the
    measured prediction table, atomically. Returns the paths by name."""
    out = Path(out_dir)
    written = write_tables_document(result, out)
    written["tables.json"] = write_json_atomic(out / "tables.json", result.to_json())
    if prediction_path is not None:
        written["prediction"] = write_json_atomic(
            prediction_path, json_ready(prediction_table(result.tables, name)))
    return written


__all__ = [
    "TITLE",
    "WORST_CASE_FIGURE",
    "conventions_words",
    "headline",
    "run_history_words",
    "tables_document",
    "tables_figures",
    "write_tables_document",
    "write_tables_report",
]
