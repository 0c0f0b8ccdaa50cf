"""``fidelity calibrate``: the SAFE-COLOR calibration table."""

from __future__ import annotations

import time
from pathlib import Path

import click

from fidelity.cli.context import write_json_output
from fidelity.cli.options import Targets, TransformNames, common_options, json_option
from fidelity.colour.charts import DEFAULT_CHART, load_chart
from fidelity.core.fileio import check_outputs, write_text_atomic
from fidelity.prediction.calibration import (
    DEFAULT_TARGETS,
    calibration_table,
    calibration_table_csv,
    calibration_table_text,
)
from fidelity.prediction.transforms import TRANSFORMS


@click.command()
@click.option("--chart", default=DEFAULT_CHART, show_default=True,
              help="Built-in chart name or path to a chart JSON file.")
@click.option("--targets", type=Targets(baseline=False), default=None,
              help="Comma-separated target ΔE values or ranges (e.g. '1-12,15,18'). "
                   "Default: 1..12, 15, 18, ..., 45.")
@click.option("--transforms", "transform_names", type=TransformNames(), default=None,
              help=f"'all' or comma-separated transforms (default: all ten): "
                   f"{', '.join(TRANSFORMS)}.")
@json_option("Write the table as JSON")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the table as CSV.")
@click.option("--markdown", "md_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the table as Markdown.")
@common_options
def calibrate(chart: str, targets: list[float] | None, transform_names: list[str] | None,
              json_path: str | None, csv_path: Path | None, md_path: Path | None) -> None:
    """Print the SAFE-COLOR calibration table.

    For each transform and target ΔE, the parameter that puts the chart at that mean CIEDE2000
    from its reference (Brent's method to |ΔE - target| <= 1e-4). Unreachable targets show '-'.
    """
    check_outputs({"--json": json_path, "--csv": csv_path, "--markdown": md_path},
                  {"--chart": chart})
    c = load_chart(chart)
    tlist = DEFAULT_TARGETS if targets is None else targets
    t0 = time.perf_counter()
    table = calibration_table(c, tlist, transform_names)
    seconds = time.perf_counter() - t0
    if json_path:
        write_json_output(json_path, table.to_json())
    if csv_path:
        write_text_atomic(csv_path, calibration_table_csv(table))
    if md_path:
        title = f"# SAFE-COLOR calibration table: chart `{table.chart}`\n\n"
        body = calibration_table_text(table, markdown=True)
        regen = ("\nRegenerate with `fidelity calibrate --json fidelity/data/calibration-safecolor.json "
                 "--csv reports/calibration/calibration-safecolor.csv --markdown "
                 "reports/calibration/calibration-safecolor.md`.\n")
        write_text_atomic(md_path, title + body + regen)
    click.echo(calibration_table_text(table))
    reached = [abs(e.delta_e - e.target) for e in table.entries if e.reachable]
    count = len(table.entries)
    click.echo(f"{count} {'entry' if count == 1 else 'entries'} ({len(reached)} reachable) in "
               f"{seconds:.2f} s" + (f"; largest |ΔE - target| = {max(reached):.1e}"
                                     if reached else ""))
