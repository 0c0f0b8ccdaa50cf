"""``fidelity predict``: chart ΔE -> predicted worst-case detection loss."""

from __future__ import annotations

from pathlib import Path

import click

from fidelity.cli.gate import PATH
from fidelity.prediction import CLASS_COLUMNS, INTERPOLATIONS, SIZES, available_tables, predict


@click.command()
@click.option("--delta-e", type=float, help="Chart ΔE (mean ΔE00 over the 24 patches).")
@click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)), default="all",
              show_default=True, help="Class to print first: all (mAP), person or bicycle.")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class: n, s, m, l, x or any.")
@click.option("--table", default=None, help="Prediction table name or JSON path "
              "(default: the fidelity.prediction.DEFAULT_TABLE).")
@click.option("--method", type=click.Choice(list(INTERPOLATIONS)), default=None,
              help="Interpolation (default: the table's own).")
@click.option("--baseline-map", type=float, default=None,
              help="The detector's baseline mAP@[.50:.95] in percent, if known: bounds the "
                   "relative loss under both readings of the paper's '%'.")
@click.option("--json", "json_path", type=PATH, help="Write the prediction as JSON.")
@click.option("--list-tables", is_flag=True, help="List the prediction tables and exit.")
def predict_cmd(delta_e: float | None, cls: str, size: str, table: str | None,
                method: str | None, baseline_map: float | None, json_path: Path | None,
                list_tables: bool) -> None:
    """Predict what a chart ΔE costs detectors: ΔmAP (points and % of baseline), ΔAP person and
    bicycle, and the SAFE-COLOR transform parameters that produce this ΔE on the chart.

    \b
    fidelity predict --delta-e 4.2 --class person --json predict.json
    """
    if list_tables:
        from fidelity.prediction import DEFAULT_TABLE, load_prediction_table

        for name in available_tables():
            t = load_prediction_table(name)
            mark = " (default)" if name == DEFAULT_TABLE else ""
            click.echo(f"{name}{mark}: {t.kind}, sizes {', '.join(t.sizes())} - {t.title}")
        return
    if delta_e is None:
        raise click.UsageError("--delta-e X is required")
    from fidelity.fileio import check_outputs

    check_outputs({"--json": json_path}, {"--table": table})
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
    reach = [t for t in p.transforms if t["reachable"]]
    if reach:
        click.echo("  SAFE-COLOR transforms at this ΔE: " + ", ".join(
            f"{t['transform']} {t['param']:.4g}" for t in reach))
    if json_path is not None:
        from fidelity.fileio import write_json_atomic
        from fidelity.report import _clean

        write_json_atomic(json_path, _clean(p.to_dict()))
        click.echo(f"wrote {json_path}")
