"""``fidelity predict``: chart ΔE -> predicted worst-case detection loss."""

from __future__ import annotations

import click

from fidelity.cli.options import common_options, json_option, write_json_output
from fidelity.prediction.table import (
    CLASS_COLUMNS,
    INTERPOLATIONS,
    SIZES,
    available_tables,
    predict,
)


@click.command()
@click.option("--delta-e", type=float, help="Chart ΔE (mean ΔE00 over the 24 patches).")
@click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)), default="all",
              show_default=True, help="Class to print first: all (mAP), person or bicycle.")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class: n, s, m, l, x or any.")
@click.option("--table", default=None, help="Prediction table name or JSON path "
              "(default: the fidelity.prediction.table.DEFAULT_TABLE).")
@click.option("--method", type=click.Choice(list(INTERPOLATIONS)), default=None,
              help="Interpolation (default: the table's own).")
@click.option("--baseline-map", type=float, default=None,
              help="The detector's baseline mAP@[.50:.95] in percent, if known: bounds the "
                   "relative loss under both readings of the paper's '%'.")
@click.option("--max-dmap", type=float, default=None,
              help="Instead of --delta-e: the largest chart ΔE whose predicted loss (of "
                   "--class, in --unit) stays <= P, e.g. for a gate's --max-delta-e.")
@click.option("--unit", type=click.Choice(["points", "relative"]), default="points",
              show_default=True, help="Unit of --max-dmap: percentage points or % of baseline "
                                      "(relative: --class all only).")
@json_option("Write the prediction (or the ΔE limit) as JSON")
@click.option("--list-tables", is_flag=True, help="List the prediction tables and exit.")
@common_options
def predict_cmd(delta_e: float | None, cls: str, size: str, table: str | None,
                method: str | None, baseline_map: float | None, max_dmap: float | None,
                unit: str, json_path: str | None, list_tables: bool) -> None:
    """Predict what a chart ΔE costs detectors, or the ΔE limit of a loss budget.

    With --delta-e: ΔmAP (points and % of baseline), ΔAP person and bicycle, and the
    SAFE-COLOR transform parameters that produce this ΔE on the chart. With --max-dmap: the
    largest chart ΔE that keeps the predicted loss within a budget.

    \b
    fidelity predict --delta-e 4.2 --class person --json predict.json
    fidelity predict --max-dmap 1 --unit relative      # ΔE limit for <= 1 % of baseline mAP
    """
    if list_tables:
        from fidelity.prediction.table import DEFAULT_TABLE, load_prediction_table

        for name in available_tables():
            t = load_prediction_table(name)
            mark = " (default)" if name == DEFAULT_TABLE else ""
            click.echo(f"{name}{mark}: {t.kind}, sizes {', '.join(t.sizes())} - {t.title}")
        return
    if (delta_e is None) == (max_dmap is None):
        raise click.UsageError("give --delta-e X or --max-dmap P")
    from fidelity.fileio import check_outputs

    check_outputs({"--json": json_path}, {"--table": table})
    if max_dmap is not None:
        _print_limit(max_dmap, cls, unit, size, table, method, json_path)
        return
    assert delta_e is not None  # one of the two was given
    p = predict(delta_e, size=size, table=table, method=method, baseline_map=baseline_map)
    b = "<= " if p.table.kind == "published-bounds" else ""

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{b}{v:.2f}"

    lines = {
        "all": f"ΔmAP: {f(p.dmap_points)} percentage points, {f(p.dmap_relative)} % of baseline",
        "person": f"person ΔAP: {f(p.dap_person_points)} percentage points",
        "bicycle": f"bicycle ΔAP: {f(p.dap_bicycle_points)} percentage points",
    }
    click.echo(f"ΔE00 {p.delta_e:g} -> table {p.table.name} ({p.table.kind}), detector size "
               f"{p.size_used}, {p.method} interpolation")
    click.echo("  " + lines[cls])
    for k, line in lines.items():
        if k != cls:
            click.echo("  " + line)
    for note in p.notes:
        click.echo(f"  note: {note}")
    reach = [t for t in p.transforms if t.reachable and t.param is not None]
    if reach:
        click.echo("  SAFE-COLOR transforms at this ΔE: " + ", ".join(
            f"{t.transform} {t.param:.4g}" for t in reach))
    if json_path is not None:
        click.echo(f"wrote {write_json_output(json_path, p.to_json())}")


def _print_limit(max_dmap: float, cls: str, unit: str, size: str, table: str | None,
                 method: str | None, json_path: str | None) -> None:
    from fidelity.prediction.table import delta_e_limit
    from fidelity.prediction.verdict import Criterion

    criterion = Criterion("max-dmap", max_dmap, cls, unit)  # checks the class and unit
    lim = delta_e_limit(max_dmap, criterion.column, size=size, table=table, method=method)
    budget = criterion.describe().removeprefix("predicted ")
    where = f"table {lim.table}, detector size {lim.size_used}"
    if lim.status == "none":
        click.echo(f"no chart ΔE keeps the predicted {budget} ({where}: "
                   f"{lim.delta_e_range[0]:g} already predicts more)")
    elif lim.status == "whole-range":
        click.echo(f"chart ΔE00 <= {lim.delta_e:.2f} (the whole table) keeps the predicted "
                   f"{budget} ({where}); beyond ΔE {lim.delta_e_range[1]:g} nothing is known")
    else:
        de = lim.rounded_down()
        click.echo(f"chart ΔE00 <= {de:.2f} keeps the predicted {budget} ({where}; "
                   f"{lim.loss_at_limit:.2f} at ΔE {lim.delta_e:.4f})")
        click.echo(f"  gate with: fidelity gate IMAGE --max-delta-e {de:.2f}")
    if json_path is not None:
        click.echo(f"wrote {write_json_output(json_path, lim.to_json())}")
