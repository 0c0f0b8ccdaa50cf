"""``fidelity predict``: chart ΔE -> predicted worst-case detection loss."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import click

from fidelity.cli.context import write_json_output
from fidelity.cli.options import common_options, json_option
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import check_outputs
from fidelity.pipeline.check import prediction_domain
from fidelity.prediction.directional import DEFAULT_DIRECTIONAL_TABLE, family_losses
from fidelity.prediction.interpolate import INTERPOLATIONS
from fidelity.prediction.interval import prediction_interval
from fidelity.prediction.judge import directional_table_name
from fidelity.prediction.properties import (
    PropertyTable,
    combine,
    load_property_table,
    predict_property,
    property_threshold,
)
from fidelity.prediction.table import delta_e_limit, predict
from fidelity.prediction.tablefile import (
    CLASS_COLUMNS,
    DEFAULT_TABLE,
    SIZES,
    available_tables,
    load_prediction_table,
)
from fidelity.prediction.validated import with_margin
from fidelity.prediction.verdict import Criterion
from fidelity.report.jsonform import coco_c_answer_json, predict_json
from fidelity.report.words import COLUMN_LABELS, combined_rule_words, prediction_notes

if TYPE_CHECKING:
    from fidelity.prediction.interval import PredictionInterval
    from fidelity.prediction.table import Prediction


@click.command()
@click.option("--delta-e", type=float, help="Chart ΔE (mean ΔE00 over the 24 patches).")
@click.option("--delta-e-uncertainty", type=float, default=0.0, show_default=True,
              metavar="U", help="With --delta-e: its standard uncertainty (k=1), e.g. from the "
                                "instrument that measured it; propagated through the table's "
                                "slope into the ± of the predicted ΔmAP.")
@click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)), default="all",
              show_default=True, help="Class to print first: all (mAP), person or bicycle.")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class: n, s, m, l, x or any.")
@click.option("--table", default=None, help="Prediction table name or JSON path "
              "(default: the fidelity.prediction.tablefile.DEFAULT_TABLE).")
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
@click.option("--direction", default=None,
              type=click.Choice(["tone", "chroma", "hue", "contrast", "pull_mean"]),
              help="With --delta-e: the direction-aware loss of an error entirely of this "
                   "transform family (default: every family's is listed).")
@click.option("--coco-c", "coco_c", default=None, metavar="CORRUPTION:SEVERITY",
              help="Instead of --delta-e: a COCO-C corruption, severity 1-5: a colour one "
                   "(brightness, contrast, saturate) with its chart ΔE, a noise or blur one "
                   "(gaussian_noise, shot_noise, defocus_blur, gaussian_blur) with its chart "
                   "SNR or MTF50; its predicted and measured loss.")
@click.option("--mtf50", type=float, default=None, metavar="X",
              help="Instead of (or with) --delta-e: the chart's MTF50 in cy/px at the "
                   "detector's 640 px input: its predicted loss from the sharpness table.")
@click.option("--snr", type=float, default=None, metavar="Y",
              help="Instead of (or with) --delta-e: the chart's SNR at 18 % grey at the "
                   "detector's input: its predicted loss from the noise table. With several "
                   "of --delta-e, --mtf50 and --snr: each and their sum.")
@json_option("Write the prediction (or the ΔE limit) as JSON")
@click.option("--list-tables", is_flag=True, help="List the prediction tables and exit.")
@common_options
def predict_cmd(delta_e: float | None, delta_e_uncertainty: float, cls: str, size: str,
                table: str | None, method: str | None, baseline_map: float | None,
                max_dmap: float | None, unit: str, direction: str | None, coco_c: str | None,
                mtf50: float | None, snr: float | None, json_path: str | None,
                list_tables: bool) -> None:
    """Predict what a chart ΔE costs detectors, or the ΔE limit of a loss budget.

    With --delta-e: ΔmAP (points and % of baseline) with its standard uncertainty (the
    measured table's sampling error at that ΔE and --delta-e-uncertainty through the table's
    slope), ΔAP person and bicycle, and the SAFE-COLOR transform parameters that produce this
    ΔE on the chart. With --max-dmap: the largest chart ΔE that keeps the predicted loss within
    a budget.

    \b
    fidelity predict --delta-e 4.2 --class person --json predict.json
    fidelity predict --max-dmap 1 --unit relative      # ΔE limit for <= 1 % of baseline mAP
    fidelity predict --coco-c contrast:3               # a COCO-C corruption on the ΔE scale
    fidelity predict --coco-c gaussian_blur:3          # ... or on the MTF50 / SNR scale
    fidelity predict --mtf50 0.15 --snr 12 --delta-e 2 # sharpness, noise, colour and the sum
    """
    if list_tables:
        for name in available_tables():
            t = load_prediction_table(name)
            mark = " (default)" if name == DEFAULT_TABLE else ""
            click.echo(f"{name}{mark}: {t.kind}, sizes {', '.join(t.sizes())} - {t.title}")
        return
    if mtf50 is not None or snr is not None:
        if max_dmap is not None or coco_c is not None:
            raise click.UsageError("--mtf50/--snr go alone or with --delta-e")
        check_outputs({"--json": json_path}, {"--table": table})
        _print_properties(delta_e, mtf50, snr, cls, size, table, json_path)
        return
    if sum(v is not None for v in (delta_e, max_dmap, coco_c)) != 1:
        raise click.UsageError("give --delta-e X or --max-dmap P (or --coco-c CORRUPTION:SEVERITY)")

    check_outputs({"--json": json_path}, {"--table": table})
    if delta_e is None and delta_e_uncertainty != 0:
        raise click.UsageError("--delta-e-uncertainty goes with --delta-e")
    if coco_c is not None:
        _print_coco_c(coco_c, size, table, json_path)
        return
    if max_dmap is not None:
        _print_limit(max_dmap, cls, unit, size, table, method, json_path)
        return
    assert delta_e is not None  # one of the two was given

    for flag, value in (("--delta-e", delta_e), ("--delta-e-uncertainty", delta_e_uncertainty)):
        if not (math.isfinite(value) and value >= 0):
            raise InvalidValueError(f"{flag} {value!r}: must be a finite number >= 0")
    p = predict(delta_e, size=size, table=table, method=method, baseline_map=baseline_map)
    interval = _interval(p, delta_e_uncertainty)
    b = "<= " if p.upper_bound else ""

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{b}{v:.2f}"

    pm = interval.plus_minus() if interval is not None else ""
    lines = {
        "all": f"ΔmAP: {f(p.dmap_points)}{pm} percentage points, {f(p.dmap_relative)} % of "
               f"baseline",
        "person": f"person ΔAP: {f(p.dap_person_points)} percentage points",
        "bicycle": f"bicycle ΔAP: {f(p.dap_bicycle_points)} percentage points",
    }
    click.echo(f"ΔE00 {p.delta_e:g} -> table {p.table.name} ({p.table.kind}), detector size "
               f"{p.size_used}, {p.method} interpolation")
    click.echo("  " + lines[cls])
    for k, line in lines.items():
        if k != cls:
            click.echo("  " + line)
    for note in prediction_notes(p):
        click.echo(f"  note: {note}")
    reach = [t for t in p.transforms if t.reachable and t.param is not None]
    if reach:
        click.echo("  SAFE-COLOR transforms at this ΔE: " + ", ".join(
            f"{t.transform} {t.param:.4g}" for t in reach))
    families = (_print_families(delta_e, size, table, direction) if p.kind.measured
                else None)
    if json_path is not None:
        doc = predict_json(p, families, interval, prediction_domain(p))
        click.echo(f"wrote {write_json_output(json_path, doc)}")


def _print_properties(delta_e: float | None, mtf50: float | None, snr: float | None,
                      cls: str, size: str, table: str | None, json_path: str | None) -> None:
    """``--mtf50`` / ``--snr`` (and ``--delta-e``): each property's worst-case loss of
    ``cls`` and their sum."""
    column = {"all": "dmap_points", "person": "dap_person_points",
              "bicycle": "dap_bicycle_points"}[cls]
    label = COLUMN_LABELS.get(column, column)
    parts: dict[str, tuple[float, float | None] | None] = {}
    used: dict[str, PropertyTable] = {}
    out: dict[str, Any] = {"column": column, "size": size}
    if delta_e is not None:
        if not (math.isfinite(delta_e) and delta_e >= 0):
            raise InvalidValueError(f"--delta-e {delta_e!r}: must be a finite number >= 0")
        p = predict(delta_e, size=size, table=table)
        col = p.columns.get(column)
        value = None if col is None else col.value
        parts["colour"] = None if value is None else (max(value, 0.0), None)
        shown = "n/a" if value is None else f"{value:.2f} points"
        click.echo(f"colour: ΔE00 {delta_e:g} -> predicted {label} {shown} "
                   f"(table {p.table.name})")
        out["colour"] = {"delta_e": delta_e, "loss": value, "table": p.table.name}
    for prop, x, flag in (("sharpness", mtf50, "--mtf50"), ("noise", snr, "--snr")):
        if x is None:
            continue
        if math.isnan(x) or not x > 0:
            raise InvalidValueError(f"{flag} {x!r}: must be a number > 0")
        t = load_property_table(prop)
        used[prop] = t
        pp = predict_property(t, x, size=size, column=column)
        parts[prop] = (pp.loss, pp.u_loss)
        limit = property_threshold(t, _loss_at_3(column, size, table), size=size, column=column)
        pm = "" if pp.u_loss is None else f" ± {pp.u_loss:.2f}"
        note = {"baseline": "; as good as the undegraded chart",
                "beyond": "; beyond the table: its ceiling (conservative)"}.get(pp.status, "")
        axis = "MTF50" if prop == "sharpness" else "SNR"
        worst = f", worst case {pp.family} on {pp.detector}" if pp.family else ""
        click.echo(f"{prop}: {axis} {x:g} -> predicted {label} {pp.loss:.2f}{pm} points "
                   f"(table {t.name}{worst}{note})")
        if limit is not None:
            click.echo(f"  the loss of ΔE00 3 is reached at {axis} {limit:.3g}")
        out[prop] = pp.to_json() | {"limit_at_delta_e_3": limit}
    if len([v for v in parts.values() if v is not None]) > 1:
        c = with_margin(combine(parts), column, used, size)
        click.echo(f"combined ({combined_rule_words(c)}): {label} {c.loss:.2f} points; "
                   f"{c.dominant} dominates")
        out["combined"] = c.to_json()
    if json_path:
        write_json_output(json_path, out)


def _loss_at_3(column: str, size: str, table: str | None) -> float:
    col = predict(3.0, size=size, table=table).columns.get(column)
    return 0.0 if col is None or col.value is None else float(col.value)


def _interval(p: Prediction, delta_e_uncertainty: float) -> PredictionInterval | None:
    """The predicted ΔmAP's interval; None where there is nothing to state: no value, or a
    table of published bounds (no sampling error) answering an exact ΔE."""
    interval = prediction_interval(p, delta_e_uncertainty)
    if interval is None or (interval.table_se is None and delta_e_uncertainty == 0):
        return None
    return interval


def _print_families(delta_e: float, size: str, table: str | None,
                    direction: str | None) -> dict[str, float | None]:
    """The direction-aware loss of an error entirely of each family (or one)."""
    dtab = directional_table_name(table)
    got = family_losses(delta_e, size=size, table=dtab)
    if direction is not None:
        got = {direction: got[direction]}
    name = dtab or DEFAULT_DIRECTIONAL_TABLE
    click.echo(f"  direction-aware ΔmAP ({name}) of an error entirely of one family: " + ", ".join(
        f"{f} {'n/a' if v is None else f'{v:.2f}'}" + (" (classic curve)" if src == "classic"
                                                       else "")
        for f, (v, src) in got.items()))
    click.echo("  (a measured chart splits its error over the families: fidelity check, "
               "audit, gate and compare report it)")
    return {f: v for f, (v, _) in got.items()}


def _print_coco_c(spec: str, size: str, table: str | None, json_path: str | None) -> None:
    from fidelity.coco.corruptions import (  # noqa: PLC0415 (the COCO benchmark, loaded at the call)
        coco_c_answer,
        parse_corruption,
    )
    from fidelity.coco.spatial import SPATIAL_CORRUPTIONS  # noqa: PLC0415 (as above)

    if parse_corruption(spec)[0] in SPATIAL_CORRUPTIONS:
        if table is not None:
            raise click.UsageError("--table names a colour table: not with a noise or blur "
                                   "corruption (its prediction is the property table's)")
        _print_spatial(spec, size, json_path)
        return
    a = coco_c_answer(spec, size=size, table=table)
    p, d = a.prediction, a.directional

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f}"

    click.echo(f"COCO-C {a.corruption} severity {a.severity} (parameter {a.parameter}): chart "
               f"ΔE00 {a.chart_delta_e:.2f} (max {a.measurement.max_delta_e:.2f}, "
               f"{a.measurement.worst_patch}); lightness {d.parts.lightness:.2f}, chroma "
               f"{d.parts.chroma:.2f}, hue {d.parts.hue:.2f}")
    click.echo(f"  predicted ΔmAP: classic {f(p.dmap_points)} points, {f(p.dmap_relative)} % "
               f"(table {p.table.name}, detector size {p.size_used}); direction-aware "
               f"{f(d.dmap_points)} points, {f(d.dmap_relative)} % ({d.explanation()})")
    _print_measured(a.measured, a.table_path, None)
    if json_path is not None:
        click.echo(f"wrote {write_json_output(json_path, coco_c_answer_json(a))}")


def _print_measured(measured: Any, table_path: Any, predicted: float | None) -> None:
    """A COCO-C answer's measured losses, one line per detector (with ``predicted``, a
    property table's loss: whether each lies within it, or within 2 SE of it)."""
    if not measured:
        click.echo(f"  measured: not in the COCO-C table {table_path}")
    for m in measured:
        se = "" if m.dmap_points_se is None else f" ± {m.dmap_points_se:.2f}"
        rel = "undefined" if m.dmap_relative is None else f"{m.dmap_relative:.2f}"
        bounded = ""
        if predicted is not None:
            lo = m.dmap_points - 2 * (m.dmap_points_se or 0.0)
            bounded = ("; within the prediction" if m.dmap_points <= predicted else
                       "; within 2 SE of the prediction" if lo <= predicted else
                       "; above the prediction")
        click.echo(f"  measured ΔmAP: {m.dmap_points:.2f}{se} points, {rel} % "
                   f"of baseline mAP {100 * m.baseline_map:.2f} ({m.model}, {m.images} COCO "
                   f"images; COCO-C table{bounded})")


def _print_spatial(spec: str, size: str, json_path: str | None) -> None:
    """``--coco-c`` of a noise or blur corruption: its chart SNR or MTF50, the property
    table's predicted and the measured loss."""
    from fidelity.coco.corruptions import spatial_answer  # noqa: PLC0415 (the COCO benchmark, loaded at the call)
    from fidelity.coco.spatial import AXIS_LABELS  # noqa: PLC0415 (as above)

    a = spatial_answer(spec, size=size)
    name, unit = AXIS_LABELS[a.property]
    ax = a.axis
    d = 4 if a.property == "sharpness" else 2
    if ax.x is None:
        value = f"chart {name}: not measured"
    else:
        u = "" if ax.u is None else f" ± {ax.u:.{d}f}"
        how = ("the softer edge's luminance MTF50" if a.property == "sharpness" else
               f"18 % grey, mean of {len(ax.draws)} seeded draws, one draw's spread "
               f"{ax.spread:.{d}f}" if ax.spread is not None else "18 % grey")
        value = f"chart {name} {ax.x:.{d}f}{u} {unit} ({how})"
    click.echo(f"COCO-C {a.corruption} severity {a.severity} (parameter {a.parameter}): "
               f"{value}")
    p = a.prediction
    if p is not None:
        pm = "" if p.u_loss is None else f" ± {p.u_loss:.2f}"
        note = {"baseline": "; as good as the undegraded chart",
                "beyond": "; beyond the table: its ceiling (conservative)"}.get(p.status, "")
        worst = f", worst case {p.family} on {p.detector}" if p.family else ""
        click.echo(f"  predicted ΔmAP: {p.loss:.2f}{pm} points (table {p.table}, detector "
                   f"size {size}{worst}{note})")
    _print_measured(a.measured, a.table_path, None if p is None else p.loss)
    if json_path is not None:
        click.echo(f"wrote {write_json_output(json_path, a.to_json())}")


def _print_limit(max_dmap: float, cls: str, unit: str, size: str, table: str | None,
                 method: str | None, json_path: str | None) -> None:
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
