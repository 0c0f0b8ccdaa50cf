"""``fidelity calibrate``: the SAFE-COLOR calibration table."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import click
import numpy as np

from fidelity.cli.options import common_options, json_option, write_json_output
from fidelity.colour.charts import DEFAULT_CHART, load_chart
from fidelity.errors import InvalidValueError
from fidelity.fileio import write_text_atomic
from fidelity.prediction.calibration import (
    DEFAULT_TARGETS,
    MAX_TARGETS,
    calibration_table,
    calibration_table_csv,
    calibration_table_text,
)
from fidelity.prediction.transforms import TRANSFORMS, get_transform


def parse_number_list(text: str, what: str) -> list[float]:
    """Parse "1,2,3" and ranges "1-12" (inclusive, step 1) into a list of numbers."""
    values: list[float] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        m = re.fullmatch(r"(\d+(?:\.\d*)?)-(\d+(?:\.\d*)?)", part)
        try:
            if m:
                lo, hi = float(m.group(1)), float(m.group(2))
                if not hi - lo < MAX_TARGETS:  # before np.arange allocates the range
                    raise InvalidValueError(f"{what}: the range {part} has more than "
                                            f"{MAX_TARGETS} values")
                values.extend(float(v) for v in np.arange(lo, hi + 0.5, 1.0) if v <= hi + 1e-9)
            else:
                values.append(float(part))
        except ValueError:
            raise InvalidValueError(f"{what}: cannot read {part!r} as a number or a range a-b") from None
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise InvalidValueError(f"{what}: {part!r} is not a positive finite ΔE")
    if not values:
        raise InvalidValueError(f"{what}: no values given")
    if len(values) > MAX_TARGETS:
        raise InvalidValueError(f"{what}: {len(values)} values, at most {MAX_TARGETS}")
    return values


@click.command()
@click.option("--chart", default=DEFAULT_CHART, show_default=True,
              help="Built-in chart name or path to a chart JSON file.")
@click.option("--targets", default=None,
              help="Comma-separated target ΔE values or ranges (e.g. '1-12,15,18'). "
                   "Default: 1..12, 15, 18, ..., 45.")
@click.option("--transforms", "transform_names", default=None,
              help=f"Comma-separated transforms (default: all ten): {', '.join(TRANSFORMS)}.")
@json_option("Write the table as JSON")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the table as CSV.")
@click.option("--markdown", "md_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the table as Markdown.")
@common_options
def calibrate(chart: str, targets: str | None, transform_names: str | None,
              json_path: str | None, csv_path: Path | None, md_path: Path | None) -> None:
    """Print the SAFE-COLOR calibration table.

    For each transform and target ΔE, the parameter that puts the chart at that mean CIEDE2000
    from its reference (Brent's method to |ΔE - target| <= 1e-4). Unreachable targets show '-'.
    """
    from fidelity.fileio import check_outputs

    check_outputs({"--json": json_path, "--csv": csv_path, "--markdown": md_path},
                  {"--chart": chart})
    c = load_chart(chart)
    tlist = DEFAULT_TARGETS if targets is None else parse_number_list(targets, "--targets")
    names = None
    if transform_names:
        names = [n.strip() for n in transform_names.split(",") if n.strip()]
        for n in names:
            get_transform(n)
    t0 = time.perf_counter()
    table = calibration_table(c, tlist, names)
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
