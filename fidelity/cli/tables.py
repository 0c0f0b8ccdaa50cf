"""``fidelity tables``: worst-case tables, plots and a report from a sweep store."""

from __future__ import annotations

import click


@click.command()
@click.argument("store_dir", type=click.Path(file_okay=False))
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Report folder (default: STORE_DIR/report).")
@click.option("--prediction", "prediction", default=None, type=click.Path(dir_okay=False),
              help="Also write the measured prediction table (CORE_API schema) to this file.")
@click.option("--name", default="coco1000-measured", show_default=True,
              help="Name of the prediction table.")
@click.option("--annotations", default=None, type=click.Path(dir_okay=False),
              help="COCO annotations of the sweep, for standard errors (default: the file the "
                   "sweep recorded, if it is there).")
@click.option("--standard-errors/--no-standard-errors", default=True, show_default=True,
              help="Paired standard errors over 5 image folds, from the stored detections "
                   "(computed once, then cached in the store).")
@click.option("--progress/--no-progress", default=True, show_default=True)
def tables(store_dir: str, out: str | None, prediction: str | None, name: str,
           annotations: str | None, standard_errors: bool, progress: bool) -> None:
    """Worst case per model and size class, paper comparison, plots, Markdown/HTML report."""
    from pathlib import Path

    from fidelity.sweep import SweepStore
    from fidelity.tables import write_report

    store = SweepStore(store_dir, create=False)
    coco = None
    if standard_errors:
        from fidelity.cocoeval import load_annotations

        recorded = (store.meta().get("data") or {}).get("annotations")
        if annotations:  # given: it must load (a missing file is an error naming it)
            coco = load_annotations(annotations)
        elif recorded and Path(recorded).is_file():
            coco = load_annotations(recorded)
        else:
            click.echo(f"no annotations ({recorded or 'none recorded'}): report without "
                       "standard errors (pass --annotations)", err=True)
    written = write_report(store, out or Path(store_dir) / "report", prediction, name, coco,
                           progress)
    for k, p in written.items():
        click.echo(f"{k:<14} {p}")
