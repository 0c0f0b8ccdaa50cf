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
def tables(store_dir: str, out: str | None, prediction: str | None, name: str) -> None:
    """Worst case per model and size class, paper comparison, plots, Markdown/HTML report."""
    from pathlib import Path

    from fidelity.sweep import SweepStore
    from fidelity.tables import write_report

    store = SweepStore(store_dir, create=False)
    written = write_report(store, out or Path(store_dir) / "report", prediction, name)
    for k, p in written.items():
        click.echo(f"{k:<14} {p}")
