"""``fidelity check``: render a camera's chart, measure, predict, verdict, report."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import click
from click.core import ParameterSource

from fidelity.camera.model import DEFAULT_CAMERA, CameraModel, load_camera
from fidelity.cli.context import (
    STDOUT,
    evidence_outputs,
    from_settings,
    write_evidence_files,
    write_json_output,
)
from fidelity.cli.options import (
    cat_option,
    common_options,
    context_option,
    evidence_option,
    json_option,
    judge_options,
    loss_limit_options,
    measure_options,
)
from fidelity.cli.values import make_criterion, measure_inputs, measure_request
from fidelity.coco.validate.suite import is_suite_file
from fidelity.core.fileio import check_outputs, display_path
from fidelity.pipeline.check import check_camera
from fidelity.pipeline.records import ChartReport, RenderSource
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E, Criterion, worst_exit_code
from fidelity.report.chart import write_chart_report
from fidelity.report.jsonform import chart_report_json
from fidelity.report.terminal import summary_lines

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasureRequest
    from fidelity.pipeline.context import Context

#: Where ``fidelity check`` writes its report unless told otherwise.
DEFAULT_OUTPUT_DIR = "fidelity-report"


@click.command()
@click.argument("cameras", nargs=-1)
@click.option("--camera", default=None,
              help="Camera model: built-in name or TOML path (default: the built-in realistic "
                   "camera, fidelity.camera.model.DEFAULT_CAMERA); or give CAMERAS.")
@click.option("--illuminant", default="D65", show_default=True, help="Scene illuminant.")
@click.option("--renderer", default="closed-form", show_default=True,
              help="closed-form (exact, fast) or mitsuba (spectral path tracer).")
@click.option("--reference", type=click.Choice(["scene", "safecolor"]), default="scene",
              show_default=True, help="Reference colours: the scene's spectra or the paper's Lab.")
@click.option("--max-delta-e", type=float, default=None,
              help="Pass when the mean ΔE00 <= X (default: 3, SAFE-COLOR's published "
                   "threshold; by the shipped measured table it allows up to 2.39 % of "
                   "baseline for its detectors; fidelity predict --delta-e X gives the loss "
                   "at X).")
@loss_limit_options
@judge_options()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=DEFAULT_OUTPUT_DIR, show_default=True,
              help="Folder for report.html and report.json (several cameras: a subfolder "
                   "each).")
@json_option("Write the JSON report here instead of OUT/report.json (one camera)")
@click.option("--html", "html_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the HTML report here instead of OUT/report.html "
                                 "(one camera).")
@click.option("--report/--no-report", default=True, show_default=True,
              help="Write the HTML and JSON reports (--no-report: the verdict only, e.g. in a "
                   "pre-commit hook).")
@cat_option
@evidence_option
@context_option
@measure_options
@common_options
def check(cameras: tuple[str, ...], camera: str | None, illuminant: str, renderer: str,
          reference: str, max_delta_e: float | None, max_dmap: float | None,
          cls: str | None, unit: str, judge: JudgeOptions, out_dir: Path,
          json_path: str | None, html_path: Path | None, report: bool,
          measure: bool, images: str | None, annotations: str | None, models: str | None,
          limit: int | None, cat: str, evidence_paths: tuple[Path, ...],
          context_path: Path | None) -> None:
    """Is this camera model's colour good enough for perception testing?

    Renders the spectral colour chart through the camera, measures ΔE00, predicts the detection
    loss and prints a verdict (exit 0 pass, 1 fail, 2 input error, 3 internal error, 4
    undecided with --decision guarded); writes an HTML and a JSON report.
    Several CAMERAS are checked one by one (reports in OUT/CAMERA-NAME/); the exit code is the
    worst.

    \b
    fidelity check                                  # the built-in camera
    fidelity check --camera my-camera.toml
    fidelity check cameras/*.toml --no-report       # each, verdicts only
    fidelity check --camera my.toml --measure       # + the loss measured on COCO
    fidelity check --max-dmap 1 --unit relative     # on the predicted loss instead
    """
    if cameras and camera is not None and not from_settings("camera"):
        raise click.UsageError("give CAMERAS or --camera, not both")
    subjects = list(cameras) or [camera or DEFAULT_CAMERA]
    # the context of use, a suite file and the evidence files are options of check whose
    # machinery (the qualification run, the suite runner: fidelity.cli.suite; the record
    # writers: fidelity.report.evidence) is imported only when the option is given, so that a
    # plain check does not load it
    context: Context | None = None
    if context_path is not None:
        from fidelity.cli.suite import read_context  # noqa: PLC0415 (only for --context)

        context = read_context(context_path)
    if context is not None and context.max_delta_e is not None and \
            click.get_current_context().get_parameter_source("max_delta_e") \
            == ParameterSource.DEFAULT:
        max_delta_e = context.max_delta_e
    criterion = check_criterion(max_delta_e, max_dmap, cls, unit)
    suites = [s for s in subjects if is_suite_file(s)]
    if suites:  # the camera files run under the suite's illuminants and transforms (--cat
        # given: the transform of the cases the suite file gives none of their own)
        if len(suites) > 1:
            raise click.UsageError("give one suite file")
        from fidelity.cli.suite import run_suite_command  # noqa: PLC0415 (only for a suite)

        sys.exit(run_suite_command(
            suites[0], [s for s in subjects if s not in suites], out_dir=out_dir,
            report=report, renderer=renderer, reference=reference,
            criterion=criterion, judge=judge, context=context,
            default_cat=None if click.get_current_context().get_parameter_source("cat")
            == ParameterSource.DEFAULT else cat))
    many = len(subjects) > 1
    if many and (json_path or html_path):
        raise click.UsageError("--json and --html take one camera; several write into --out")
    to_stdout = json_path == STDOUT
    plans = []
    for cam in subjects:
        folder = out_dir / Path(cam).stem if many else out_dir
        html = (html_path or folder / "report.html") if report else None
        json_file = (None if to_stdout or not report else
                     Path(json_path) if json_path else folder / "report.json")
        plans.append((cam, html, json_file))
    outputs: dict[str, Path | None] = {f"{k} ({cam})" if many else k: v
                                       for cam, html, js in plans
                                       for k, v in (("--html", html), ("--json", js))}
    # each camera file is parsed once, here, and passed down as its CameraModel
    models_of = {cam: load_camera(cam) for cam in subjects}
    check_outputs({**outputs, **evidence_outputs(evidence_paths)},
                  {"--table": judge.table_input, "--illuminant": illuminant}
                  | {f"CAMERA {cam}": cam for cam in subjects}
                  | {f"CAMERA {cam} ({f.name})": f for cam in subjects
                     for f in models_of[cam].files}
                  | measure_inputs(images, annotations, models))
    request = measure_request(measure, images, annotations, models, limit)
    reports: list[ChartReport] = []
    codes = [_check_one(cam, models_of[cam], html, js, to_stdout=to_stdout, many=many,
                        criterion=criterion, illuminant=illuminant, renderer=renderer,
                        reference=reference, judge=judge, measure=request, reports=reports,
                        cat=cat)
             for cam, html, js in plans]
    if context is not None:
        from fidelity.cli.suite import assess_context  # noqa: PLC0415 (only for --context)

        assessment, lines = assess_context(context, [(cam, r) for (cam, _, _), r in
                                                     zip(plans, reports, strict=True)])
        reports = [replace(r, context=assessment) for r in reports]
        for (_, html, js), r in zip(plans, reports, strict=True):
            write_chart_report(r, json_path=js, html_path=html)
        for line in lines:
            click.echo(line)
        codes.append(assessment.exit_code)
    code = worst_exit_code(codes)
    if evidence_paths:
        from fidelity.report.evidence import write_evidence  # noqa: PLC0415 (only for --evidence)

        write_evidence_files(
            evidence_paths, write_evidence, "check",
            [(cam, r, None) for (cam, _, _), r in zip(plans, reports, strict=True)], code,
            results=[p for _, html, js in plans for p in (js, html)], indent="  ")
    sys.exit(code)


def check_criterion(max_delta_e: float | None, max_dmap: float | None, cls: str | None,
                    unit: str) -> Criterion:
    """``check``'s criterion: ``--max-dmap`` (with ``--class``, ``--unit``) when given, as
    gate's; else ``--max-delta-e``, default :data:`DEFAULT_MAX_DELTA_E`. A ``--max-delta-e``
    from the settings file yields to ``--max-dmap`` on the command line."""
    if max_dmap is not None and max_delta_e is not None and from_settings("max_delta_e"):
        max_delta_e = None
    if max_dmap is None and max_delta_e is None:
        max_delta_e = DEFAULT_MAX_DELTA_E
    return make_criterion(max_delta_e, max_dmap, cls, unit)


def _check_one(cam: str, model: CameraModel, html: Path | None, json_file: Path | None, *,
               to_stdout: bool, many: bool, criterion: Criterion, illuminant: str,
               renderer: str, reference: str, judge: JudgeOptions,
               measure: MeasureRequest | None, reports: list[ChartReport],
               cat: str = "Bradford") -> int:
    """Check one camera (named ``cam`` on the command line), write its reports, print its
    verdict; its exit code."""
    report = check_camera(model, illuminant=illuminant, renderer=renderer,
                          reference=reference, criterion=criterion, judge=judge,
                          measure=measure, cat=cat)
    reports.append(report)
    write_chart_report(report, json_path=json_file, html_path=html)
    if to_stdout:
        write_json_output(STDOUT, chart_report_json(report))
    src = report.source
    assert isinstance(src, RenderSource)
    variant = f" ({src.variant})" if src.variant else ""
    name = cam if many else src.camera
    click.echo(f"fidelity check: camera {name}, illuminant {illuminant}, "
               f"{src.renderer} renderer{variant}, {reference} reference")
    for line in summary_lines(report):
        click.echo("  " + line)
    if html is not None:
        click.echo(f"  report: {display_path(html)}"
                   + (f" (JSON: {display_path(json_file)})" if json_file else ""))
    return report.exit_code
