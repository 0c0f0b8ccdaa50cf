"""``fidelity tables``: worst-case tables, plots and a report from a sweep store."""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from fidelity.cli.context import show_progress, write_json_output
from fidelity.cli.options import common_options, json_option, progress_option
from fidelity.coco.degradations import DEGRADATIONS
from fidelity.coco.scores import is_scores_file, scores_store_folder
from fidelity.coco.scoring import load_annotations
from fidelity.coco.sweep import SweepStore
from fidelity.coco.tables.classes import RARE_BOXES, explain_cell
from fidelity.coco.tables.colour import TablesResult, tables_result
from fidelity.coco.tables.degradation import property_tables
from fidelity.coco.tables.directional import directional_table
from fidelity.coco.tables.grid import parse_image_caps
from fidelity.coco.tables.prediction import prediction_table
from fidelity.coco.tables.provenance import check_store_meta
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import check_outputs, file_sha256, json_ready, write_json_atomic
from fidelity.core.resources import source_root
from fidelity.report.coco import WORST_CASE_FIGURE, write_tables_report

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepStore


@click.command()
@click.argument("store_dirs", nargs=-1, required=True, type=click.Path(),
                metavar="STORE_DIR...")
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Report folder (default: STORE_DIR/report).")
@click.option("--prediction", "prediction", default=None, type=click.Path(dir_okay=False),
              help="Also write the measured prediction table (CORE_API schema) to this file.")
@click.option("--name", default="coco1000-measured", show_default=True,
              help="Name of the prediction table.")
@click.option("--directional", default=None, type=click.Path(dir_okay=False),
              help="Also write the direction-aware prediction table (per transform family; "
                   "fidelity.prediction.directional) to this file. STORE_DIR may be a "
                   "tables.json: then only the tables are written, from it.")
@click.option("--sharpness", default=None, type=click.Path(dir_okay=False),
              help="Also write the sharpness table (loss against the chart's MTF50, from the "
                   "store's blur cells: fidelity sweep --degradations) to this file; its name "
                   "is the file's stem.")
@click.option("--noise", default=None, type=click.Path(dir_okay=False),
              help="Also write the noise table (loss against the chart's SNR at 18 % grey, "
                   "from the store's noise cells) to this file.")
@click.option("--earlier", default=None, type=click.Path(dir_okay=False),
              metavar="TABLES_JSON",
              help="Keep the models of an earlier tables.json that STORE_DIR does not hold, as "
                   "they were measured (their rows, settings and recorded preprocessing): "
                   "re-measure some detectors, keep the rest. Same images required.")
@click.option("--annotations", default=None, type=click.Path(dir_okay=False),
              help="COCO annotations of the sweep, for standard errors (default: the file the "
                   "sweep recorded, if it is there).")
@click.option("--standard-errors/--no-standard-errors", default=True, show_default=True,
              help="Standard errors of every loss (the larger of the paired image bootstrap "
                   "and the 5-fold jackknife), from the stored detections (computed once, then "
                   "cached in the store).")
@click.option("--explain", "explain", default=None, metavar="MODEL:TRANSFORM:ΔE",
              help="Instead of the report: which classes one cell's ΔmAP comes from (per-class "
                   "ΔAP and share of the ΔmAP, from the stored detections), e.g. "
                   "yolov10n-int8dyn:pull_mean:1.")
@click.option("--rare-boxes", default=RARE_BOXES, show_default=True,
              type=click.IntRange(min=0),
              help="With --explain: classes with at most this many ground-truth boxes in the "
                   "images count as rare.")
@click.option("--limit", "images", default=None, metavar="N|MODEL=N[,...]",
              help="Report on at most the first N images by id, for every model (N) or the "
                   "models named (MODEL=N), re-scoring stored detections: an earlier state of "
                   "a sweep that has moved on (default: all that every cell of a model has). "
                   "With --explain: the cell is scored on the first N.")
@click.option("--top", default=10, show_default=True, type=click.IntRange(min=1),
              help="With --explain: classes listed (largest loss first).")
@json_option("With --explain: also write the breakdown as JSON")
@progress_option
@common_options
def tables(store_dirs: tuple[str, ...], out: str | None, prediction: str | None, name: str,
           directional: str | None, sharpness: str | None, noise: str | None,
           earlier: str | None, annotations: str | None,
           standard_errors: bool, explain: str | None, rare_boxes: int, images: str | None,
           top: int, json_path: str | None, progress: bool | None) -> None:
    """Worst case per model and size class, paper comparison, plots, Markdown/HTML report.

    With --explain MODEL:TRANSFORM:ΔE: the classes one cell's ΔmAP comes from, instead.
    STORE_DIR may be a tables.json (e.g. reports/coco/tables.json): then only --prediction
    and --directional are written, from it. It may be a sweep's scores file (sweep
    --export-scores), or several (one per detector): then the report (--out) is built from
    their cells, and the tables name each file by its path in the source checkout and its
    SHA-256 (provenance.scores_files).
    """
    for path in store_dirs:
        if not Path(path).exists():
            raise InputFileError(f"{path}: no such sweep store folder, scores file or "
                                 "tables.json")
    scores = [p for p in store_dirs if Path(p).is_file() and is_scores_file(p)]
    if len(store_dirs) > 1 and len(scores) < len(store_dirs):
        other = next(p for p in store_dirs if p not in scores)
        raise InvalidValueError(f"{other}: not a scores file: several STORE_DIR are scores "
                                "files (sweep --export-scores), one of each")
    store_dir = store_dirs[0]
    with contextlib.ExitStack() as stack:
        if scores:
            reports = ("report.md", "report.html", "tables.json", WORST_CASE_FIGURE)
            check_outputs({"--prediction": prediction, "--directional": directional}
                          | {f"--out ({n})": Path(out) / n for n in reports if out},
                          {f"STORE_DIR ({p})": p for p in scores})
            store_dir = _store_of_scores(stack, scores, out, explain)
        _tables(store_dir, out, prediction, name, directional, earlier, annotations,
                standard_errors, explain, rare_boxes, images, top, json_path, progress,
                {"sharpness": sharpness, "noise": noise})


def _store_of_scores(stack: contextlib.ExitStack, paths: list[str], out: str | None,
                     explain: str | None) -> str:
    """A temporary sweep store holding the cells of the scores files ``paths`` (removed when
    ``stack`` closes; its provenance names each file by its path in the source checkout and
    SHA-256); its report goes to ``--out``, which is then needed."""
    path = ", ".join(paths)
    if explain:
        raise InvalidValueError(f"{path}: --explain needs the cell's detections, which a "
                                "scores file does not hold: give the sweep store")
    if out is None:
        raise InvalidValueError(f"{path}: a scores file: give --out for the report")
    return str(stack.enter_context(scores_store_folder(
        list[str | os.PathLike[str]](paths), SweepStore, root=source_root())))


def _tables(store_dir: str, out: str | None, prediction: str | None, name: str,
            directional: str | None, earlier: str | None, annotations: str | None,
            standard_errors: bool, explain: str | None, rare_boxes: int, images: str | None,
            top: int, json_path: str | None, progress: bool | None,
            properties: dict[str, str | None] | None = None) -> None:
    report = Path(out or Path(store_dir) / "report")
    wanted = {k: v for k, v in (properties or {}).items() if v}
    if Path(store_dir).is_file():
        if earlier is not None:
            raise InvalidValueError("--earlier merges with a sweep store: STORE_DIR is a "
                                    "tables.json here")
        check_outputs({"--prediction": prediction, "--directional": directional},
                      {"--annotations": annotations, "STORE_DIR": store_dir})
        _tables_from_json(Path(store_dir), prediction, name, directional)
        return
    check_outputs({"--prediction": prediction, "--json": json_path,
                   "--directional": directional} | {f"--{k}": v for k, v in wanted.items()}
                  | ({} if explain else {f"--out ({n})": report / n
                                         for n in ("report.html", "report.md", "tables.json")}),
                  {"--annotations": annotations, "--earlier": earlier},
                  stores={"STORE_DIR": store_dir})
    store = SweepStore(store_dir, create=False)

    check_store_meta(store.db, str(store.path))
    coco = None
    caps = parse_image_caps(images, list(store.models()))
    if explain:
        _explain(store, explain, annotations, rare_boxes, caps, top, json_path)
        return
    if caps and not standard_errors:
        raise InvalidValueError("--limit re-scores cells from the annotations: it cannot be "
                                "combined with --no-standard-errors")
    if standard_errors:
        recorded = (store.meta().get("data") or {}).get("annotations")
        if annotations:  # given: it must load (a missing file is an error naming it)
            coco = load_annotations(annotations)
        elif recorded and Path(recorded).is_file():
            coco = load_annotations(recorded)
        else:
            click.echo(f"no annotations ({recorded or 'none recorded'}): report without "
                       "standard errors (pass --annotations)", err=True)
    if wanted:
        built = property_tables(store, coco, name=name.removesuffix("-measured"),
                                progress=show_progress(progress),
                                say=lambda line: click.echo(line, err=True))
        for prop, path in wanted.items():
            if prop not in built:
                raise InputFileError(f"{store_dir}: no finished {prop} cells for --{prop}")
            table = replace(built[prop], name=Path(path).stem)
            click.echo(f"{prop:<14} {write_json_atomic(path, json_ready(table.to_json()))}")
        if not _has_colour_cells(store):
            return
    kept = _read_earlier(Path(earlier)) if earlier is not None else None
    result = tables_result(store, coco, progress=show_progress(progress), images=caps,
                           earlier=kept)
    written = write_tables_report(result, out or Path(store_dir) / "report", prediction, name)
    if directional is not None:
        written["directional"] = _write_directional(result.tables, directional)
    for k, p in written.items():
        click.echo(f"{k:<14} {p}")


def _has_colour_cells(store: SweepStore) -> bool:
    """Whether the store holds cells of the colour transforms (not only blur and noise)."""
    return any(c.transform != "baseline" and c.transform not in DEGRADATIONS
               for c in store.cells())


def _read_tables_json(path: Any) -> Any:
    """The :class:`~fidelity.coco.tables.colour.TablesResult` of a ``tables.json`` (one-line errors)."""
    try:
        return TablesResult.from_json(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise InputFileError(f"{path}: not a tables.json of fidelity tables ({exc})") from None


def _read_earlier(path: Any) -> tuple[Any, dict[str, Any]]:
    """``--earlier``: its tables and where they came from (file name and SHA-256)."""
    tables_ = _read_tables_json(path).tables
    # the file's name, not where it lay on this machine: provenance names the data
    return tables_, {"file": Path(path).name, "sha256": file_sha256(path)}


def _write_directional(tables_: Any, path: str) -> Any:
    return write_json_atomic(path, json_ready(directional_table(tables_)))


def _tables_from_json(path: Any, prediction: str | None, name: str,
                      directional: str | None) -> None:
    """The prediction tables of a ``tables.json`` (no store, no report)."""
    if prediction is None and directional is None:
        raise InvalidValueError(f"{path}: from a tables.json, give --prediction FILE and/or "
                                "--directional FILE")
    result = _read_tables_json(path)
    if prediction is not None:
        p = write_json_atomic(prediction, json_ready(prediction_table(result.tables, name)))
        click.echo(f"{'prediction':<14} {p}")
    if directional is not None:
        click.echo(f"{'directional':<14} {_write_directional(result.tables, directional)}")


def _explain(store: SweepStore, spec: str, annotations: str | None, rare_boxes: int,
             caps: dict[str, int], top: int, json_path: str | None) -> None:
    parts = spec.rsplit(":", 2)
    try:
        model, transform, target = parts[0], parts[1], float(parts[2])
    except (IndexError, ValueError):
        raise InvalidValueError(f"--explain {spec!r}: expected MODEL:TRANSFORM:ΔE, e.g. "
                                "yolov10n-int8dyn:pull_mean:1") from None
    recorded = (store.meta().get("data") or {}).get("annotations")
    path = annotations or recorded
    if not path or not (annotations or Path(path).is_file()):
        raise InvalidValueError(f"--explain needs the COCO annotations ({path or 'none recorded'}"
                                " is not there): pass --annotations")
    r = explain_cell(store, load_annotations(path), model, transform, target,
                     images=caps.get(model), rare_boxes=rare_boxes)
    click.echo(f"{model} {transform} ΔE {target:g} on {r.images} images: ΔmAP "
               f"{r.dmap_points:.2f} points, the mean of ΔAP over {len(r.classes)} classes")
    for group, word in ((r.rare, f"<= {rare_boxes}"), (r.common, f"> {rare_boxes}")):
        if group.classes and group.mean_dap_points is not None:
            click.echo(f"  classes with {word} boxes ({group.classes}): mean ΔAP "
                       f"{group.mean_dap_points:.2f} points, {group.share_points:.2f} points of "
                       "the ΔmAP")
    click.echo(f"  {'class':<16} {'boxes':>5} {'AP base':>8} {'AP':>8} {'ΔAP pts':>8} "
               f"{'share pts':>9}")
    for c in r.classes[:top]:
        click.echo(f"  {c.name:<16} {c.boxes:>5} {c.ap_baseline:>8.4f} {c.ap:>8.4f} "
                   f"{c.dap_points:>8.2f} {c.share_points:>9.2f}")
    if json_path:
        click.echo(f"  JSON: {write_json_output(json_path, r.to_json())}")
