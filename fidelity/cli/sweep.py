"""``fidelity sweep``: every (model, transform, ΔE) cell into a resumable SQLite store."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.context import show_progress
from fidelity.cli.options import (
    DegradationNames,
    ModelList,
    Targets,
    TransformNames,
    common_options,
    executor_options,
    limit_option,
    progress_option,
    scorer_option,
    scores_options,
)
from fidelity.cli.values import cap_models, executor_from, model_inputs, transfer_scores
from fidelity.coco.degradations import DEGRADATIONS
from fidelity.coco.scores import is_scores_file, scores_store_folder
from fidelity.coco.store import process_gone
from fidelity.coco.sweep import SweepStore, cell_label, run_summary, run_sweep, sweep_status
from fidelity.coco.sweep import rescore as do_rescore
from fidelity.coco.tables.provenance import check_store_meta
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import check_outputs, display_path

if TYPE_CHECKING:
    from fidelity.coco.sweep import ModelSpec, SweepStore


@click.command()
@click.option("--models", type=ModelList(), default=None,
              help="Comma-separated ONNX files, each optionally PATH@N (at most the first N "
                   "images by id).")
@click.option("--images", default=None, type=click.Path(file_okay=False))
@click.option("--annotations", type=click.Path(dir_okay=False),
              help="COCO annotations of the images (needed except with --status and "
                   "--import-scores).")
@click.option("--transforms", type=TransformNames(none=True), default="all", show_default=True,
              help="'all', 'none' or comma-separated transform names.")
@click.option("--degradations", type=DegradationNames(), default=None,
              help="Blur and noise families swept at their own levels besides the colour "
                   "transforms ('all' or comma-separated: "
                   + ", ".join(DEGRADATIONS) + "); with --transforms none, only these.")
@click.option("--targets", type=Targets(baseline=True),
              default="0,1,2,3,4,5,6,8,10,12,15,18,21,24", show_default=True,
              help="Chart ΔE targets or ranges a-b; 0 is the baseline (decode + re-encode "
                   "only).")
@click.option("--out", required=True, type=click.Path(),
              help="Folder of the results store (sweep.sqlite); rerun to resume. With "
                   "--status, also a scores file (--export-scores).")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="onnxruntime intra-op threads.")
@click.option("--provider", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True)
@click.option("--order", type=click.Choice(["priority", "ascending", "reverse"]),
              default="priority", show_default=True,
              help="priority: every model's ΔE 1, 3, 6, 12, 24 cells first (the paper's "
                   "thresholds), then the rest; ascending: model by model, ΔE ascending; "
                   "reverse: priority backwards. Runs on one --out share the cells through "
                   "claims in the store, whatever their order.")
@scorer_option
@click.option("--rescore", is_flag=True, help="Only recompute scores from stored detections.")
@scores_options("--out")
@click.option("--status", is_flag=True,
              help="Only say where the store in --out stands (per model: cells done, to do, "
                   "under way, pace); safe while a sweep runs. --out may be a scores file.")
@limit_option()
@progress_option
@executor_options
@common_options
def sweep(models: tuple[ModelSpec, ...] | None, images: str | None, annotations: str | None,
          transforms: list[str], degradations: list[str] | None, targets: list[float], out: str, threads: int, provider: str,
          order: str, scorer: str, rescore: bool, export_scores: str | None,
          import_scores: str | None, status: bool, limit: int | None,
          progress: bool | None, executor: str, address: str | None, workers: int | None) -> None:
    """Run (or resume) the COCO sweep; one line per finished cell on stderr ([k/N] cells).

    \b
    Example:
      fidelity sweep --models yolox_nano.onnx,yolo11n.onnx@250 --images val2017 \\
          --annotations instances.json --out DIR        (rerun the same line to resume)
      fidelity sweep --rescore --annotations instances.json --out DIR
      fidelity sweep --export-scores run.scores.json.gz --annotations instances.json --out DIR
      fidelity sweep --import-scores run.scores.json.gz --out NEWDIR   (then resume there)
      fidelity sweep ... --executor ray --address auto --workers 8   (a Ray cluster)
    """
    carried = Path(out).is_file() and is_scores_file(out)  # a store carried as its scores
    if status and carried:
        with scores_store_folder(out, SweepStore) as folder:
            store = SweepStore(folder, create=False)
            try:
                _print_status(store, shown=out)
            finally:
                store.close()
        return
    if Path(out).is_file():  # the store's folder (a scores file is read by --status alone)
        raise click.BadParameter(f"Directory {out!r} is a file"
                                 + (": give it to --import-scores, or to --status"
                                    if carried else "."), param_hint="'--out'")
    if status:
        store = SweepStore(out, create=False)
        check_store_meta(store.db, str(store.path))
        _print_status(store)
        return
    if transfer_scores(SweepStore, out, "--out", export_scores, import_scores, annotations,
                       scorer):
        return
    if not annotations:
        raise click.UsageError("--annotations is needed (except with --status and "
                               "--import-scores)")
    if rescore:
        n = do_rescore(SweepStore(out, create=False), annotations, method=scorer)
        click.echo(f"rescored {n} cells in {out}")
        return
    if not models or not images:
        raise InvalidValueError("--models and --images are needed (except with --rescore)")
    specs = list(models)

    check_outputs({"--out (sweep.sqlite)": Path(out) / SweepStore.store_name},
                  {"--annotations": annotations, **model_inputs(specs)})
    specs = list(cap_models(specs, limit))
    options = executor_from(executor, address, workers, threads, provider)
    store = run_sweep(specs, images, annotations, out, transforms, targets, threads=threads,
                      provider=provider, order=order, scorer=scorer, executor=options,
                      progress=show_progress(progress), degradations=degradations or ())

    last = store.meta().get("last_run") or {}
    if last.get("items"):
        click.echo(run_summary(last), err=True)
    cells = store.cells()
    done = sum(c.done for c in cells)
    click.echo(f"{done} cells done, {len(cells) - done} unreachable; store {store.path}")


def _print_status(store: SweepStore, shown: str | None = None) -> None:
    """Where ``store`` stands; ``shown``: the scores file it was made from, if it was."""
    rows = sweep_status(store)
    now = time.time()
    click.echo(f"store {store.path}" if shown is None else
               f"scores file {display_path(shown)} (a store's finished cells, none under way)")
    for i in store.meta().get("imported") or []:
        cells = f", {i['cells']} cells" if i.get("cells") is not None else ""
        click.echo(f"imported {i.get('file')} (sha256 {str(i.get('sha256'))[:12]}, exported "
                   f"{i.get('exported')}{cells}; their detections are not in this store)")
    click.echo(f"{'model':<18} {'images':>6} {' done':<9} {'unreachable':>11} {'to do':>5}  "
               "pace and time left")
    for r in rows:
        pace = ("finished" if not r.to_do else "" if r.pace_s is None or r.left_s is None else
                f"{r.pace_s / 60:.1f} min per cell, about {r.left_s / 3600:.1f} h left")
        click.echo(f"{r.model:<18} {r.images or '-':>6} {r.done:>4}/{r.planned:<4}"
                   f"{r.unreachable:>11} {r.to_do:>5}  {pace}")
        claimed = {(str(c.cell[1]), float(c.cell[2])): (c, n)
                   for c, n in zip(r.claims, r.stored, strict=True)}
        for t, e, n in r.under_way:
            if (t, e) not in claimed:
                click.echo(f"{'':<18} under way: {cell_label(t, e)}, {n} of {r.images} images stored"
                           " (no run holds it now)")
        for (t, e), (c, n) in claimed.items():
            who = c.owner.info
            workers = who.get("workers", "?")
            what = (f"{who.get('executor', '?')}, {workers} worker"
                    f"{'' if workers == 1 else 's'}" if who else "unknown run")
            state = ("its process has ended: the next run takes the cell over"
                     if process_gone(c.owner.host, c.owner.pid)
                     else f"heartbeat {max(0.0, now - c.heartbeat):.0f} s ago")
            click.echo(f"{'':<18} under way: {cell_label(t, e)}, {n} of {r.images} images stored; "
                       f"run on {c.owner.host} pid {c.owner.pid} ({what}), {state}")
    if any(r.to_do for r in rows):
        click.echo("pace: wall time per finished cell over a model's last cells (runs side by "
                   "side counted together, pauses as one cell; whatever ran beside it); rerun "
                   "the sweep's command line to resume")
