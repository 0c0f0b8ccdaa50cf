"""``fidelity compare``: the simulator's chart against the real camera's, patch by patch."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.context import STDOUT, evidence_outputs, write_evidence_files, write_json_output
from fidelity.cli.options import (
    IMAGE_PATH,
    PATH,
    chart_pair_options,
    common_options,
    evidence_option,
    image_read_options,
    json_option,
    judge_options,
    measure_options,
)
from fidelity.cli.values import make_criterion, measure_inputs, measure_request
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import check_outputs, display_path
from fidelity.pipeline.compare import compare_charts
from fidelity.pipeline.records import GateResult
from fidelity.prediction.tablefile import CLASS_COLUMNS
from fidelity.prediction.verdict import EXIT_ERROR
from fidelity.report.compare import comparison_lines, write_comparison_report
from fidelity.report.evidence import write_evidence
from fidelity.report.jsonform import comparison_json
from fidelity.report.junit import write_junit

#: The ``classname`` of compare's JUnit test case.
JUNIT_CLASS = "fidelity.compare"

if TYPE_CHECKING:
    from fidelity.chart.read import ReadOptions
    from fidelity.prediction.judge import JudgeOptions


@click.command()
@click.argument("sim", type=IMAGE_PATH)
@click.argument("real", type=IMAGE_PATH)
@chart_pair_options
@click.option("--max-delta-e", type=float, default=None,
              help="Pass when the sim-to-real chart ΔE00 (mean over the patches) <= X.")
@click.option("--max-dmap", type=float, default=None,
              help="Pass when the predicted ΔmAP (or class ΔAP) of the difference <= P.")
@click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)), default=None,
              help="Class of --max-dmap: all (mAP, default), person, bicycle.")
@click.option("--unit", type=click.Choice(["points", "relative"]), default="points",
              show_default=True, help="Unit of --max-dmap.")
@judge_options()
@click.option("--reference", default="scene", show_default=True,
              help="What each chart's own ΔE is measured against: scene, safecolor or a chart "
                   "JSON.")
@click.option("--illuminant", default="D65", show_default=True,
              help="Illuminant of the scene reference.")
@image_read_options
@click.option("--junit", type=PATH, help="Write JUnit XML (one test case).")
@json_option("Write the comparison as JSON")
@click.option("--html", "html_path", type=PATH, default=None, help="Write the HTML report.")
@evidence_option
@measure_options
@common_options
def compare(sim: Path, real: Path, sim_corners: str | None, real_corners: str | None,
            sim_ocio_colourspace: str | None, real_ocio_colourspace: str | None,
            normalise_mode: str, max_delta_e: float | None, max_dmap: float | None,
            cls: str | None, unit: str, judge: JudgeOptions,
            reference: str, illuminant: str, read: ReadOptions,
            junit: Path | None,
            json_path: str | None, html_path: Path | None, measure: bool, images: str | None,
            annotations: str | None, models: str | None, limit: int | None,
            evidence_paths: tuple[Path, ...]) -> None:
    """Compare a simulated chart with the real camera's: sim-to-real ΔE00 and its cost.

    SIM is the simulator's render of the chart scene, REAL a photo of the same chart taken
    by the real camera (any format audit reads). Both charts are audited, the simulated one
    is matched to the real one on the neutral patches (--normalise), and each patch is
    compared in CIEDE2000; the loss the difference would cost a detector is predicted
    (classic and direction-aware) and, with --measure, measured on COCO. With --max-delta-e
    or --max-dmap: exit 0 pass, 1 fail, 2 input error, 3 bug, 4 undecided (--decision
    guarded), as fidelity gate.

    \b
    fidelity compare sim.exr photo.jpg --real-corners 102,88,610,95,604,420,98,414
    fidelity compare sim.exr photo.png --max-delta-e 5 --junit sim-vs-real.xml --html r.html
    fidelity compare sim.exr drive.bag --topic /camera/image_raw --time 12.5

    REAL (or SIM) may be a robot recording (ROS 1 bag, ROS 2 bag, MCAP file): --topic,
    --frame and --time then choose its message.
    """
    to_stdout = json_path == STDOUT
    check_outputs({"--json": None if to_stdout else json_path, "--html": html_path,
                   "--junit": junit, **evidence_outputs(evidence_paths)},
                  {"SIM": sim, "REAL": real, "--table": judge.table_input, "--reference": reference,
                   "--illuminant": illuminant} | measure_inputs(images, annotations, models))
    criterion = None
    if max_delta_e is not None or max_dmap is not None:
        criterion = make_criterion(max_delta_e, max_dmap, cls, unit)
    elif cls is not None:
        raise click.UsageError("--class goes with --max-dmap")
    request = measure_request(measure, images, annotations, models, limit)
    subject = f"{sim} against {real}"
    try:
        report = compare_charts(
            sim, real, sim_corners=sim_corners, real_corners=real_corners,
            normalise_mode=normalise_mode, reference=reference, illuminant=illuminant,
            criterion=criterion, judge=judge, read=read,
            sim_ocio_colourspace=sim_ocio_colourspace,
            real_ocio_colourspace=real_ocio_colourspace, measure=request)
    except FidelityError as exc:
        if junit is not None:
            write_junit(junit, [GateResult(subject, criterion, error=str(exc))],
                        classname=JUNIT_CLASS)
        raise
    write_comparison_report(report, json_path=None if to_stdout else json_path,
                            html_path=html_path, protect=(sim, real))
    for line in comparison_lines(report):
        click.echo(line)
    if junit is not None:
        try:
            write_junit(junit, [GateResult(subject, criterion, report=report.as_chart_report())],
                        classname=JUNIT_CLASS)
        except (FidelityError, OSError) as exc:
            click.echo(f"fidelity: error: {junit}: cannot write JUnit XML: {exc}", err=True)
            sys.exit(EXIT_ERROR)
        click.echo(f"wrote {display_path(junit)}")
    if json_path is not None:
        where = write_json_output(json_path, comparison_json(report))
        if not to_stdout:
            click.echo(f"wrote {display_path(where)}")
    if html_path is not None:
        click.echo(f"wrote {display_path(html_path)}")
    if evidence_paths:
        write_evidence_files(
            evidence_paths, write_evidence, "compare", [(subject, report, None)],
            report.exit_code, results=[None if to_stdout or json_path is None
                                       else Path(json_path), html_path, junit])
    sys.exit(report.exit_code)
