"""``fidelity check``: render a camera's chart, measure, predict, verdict, report."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from fidelity.cli.options import (
    STDOUT,
    bound_option,
    common_options,
    decision_options,
    decision_rule,
    evidence_option,
    evidence_outputs,
    from_settings,
    json_option,
    measure_inputs,
    measure_options,
    measure_request,
    write_evidence_files,
    write_json_output,
)
from fidelity.prediction.tablefile import SIZES
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E, Criterion

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
@click.option("--max-delta-e", type=float, default=DEFAULT_MAX_DELTA_E, show_default=True,
              help="Pass when the mean ΔE00 <= X (default: SAFE-COLOR's published threshold; "
                   "fidelity predict --delta-e X gives the loss measured at X).")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class for the predicted loss.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
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
@bound_option
@decision_options
@evidence_option
@measure_options
@common_options
def check(cameras: tuple[str, ...], camera: str | None, illuminant: str, renderer: str,
          reference: str, max_delta_e: float, size: str, table: str | None, out_dir: Path,
          json_path: str | None, html_path: Path | None, report: bool, bound: str,
          measure: bool, images: str | None, annotations: str | None, models: str | None,
          limit: int | None, decision: str, coverage_factor: float, strict: bool,
          evidence_paths: tuple[Path, ...]) -> None:
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
    """
    from fidelity.camera.model import DEFAULT_CAMERA, camera_files
    from fidelity.core.fileio import check_outputs
    from fidelity.prediction.verdict import Criterion

    if cameras and camera is not None and not from_settings("camera"):
        raise click.UsageError("give CAMERAS or --camera, not both")
    subjects = list(cameras) or [camera or DEFAULT_CAMERA]
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
    check_outputs({**outputs, **evidence_outputs(evidence_paths)},
                  {"--table": table, "--illuminant": illuminant}
                  | {f"CAMERA {cam}": cam for cam in subjects}
                  | {f"CAMERA {cam} ({f.name})": f for cam in subjects
                     for f in camera_files(cam)}
                  | measure_inputs(images, annotations, models))
    criterion = Criterion("max-delta-e", max_delta_e)
    rule = decision_rule(decision, coverage_factor, strict)
    request = measure_request(measure, images, annotations, models, limit)
    reports: list[Any] = []
    codes = [_check_one(cam, html, js, to_stdout=to_stdout, many=many, criterion=criterion,
                        illuminant=illuminant, renderer=renderer, reference=reference,
                        size=size, table=table, bound=bound, measure=request, decision=rule,
                        reports=reports)
             for cam, html, js in plans]
    from fidelity.prediction.verdict import worst_exit_code

    code = worst_exit_code(codes)
    if evidence_paths:
        from fidelity.report.evidence import write_evidence

        write_evidence_files(
            evidence_paths, write_evidence, "check",
            [(cam, r, None) for (cam, _, _), r in zip(plans, reports, strict=True)], code,
            results=[p for _, html, js in plans for p in (js, html)], indent="  ")
    sys.exit(code)


def _check_one(cam: str, html: Path | None, json_file: Path | None, *, to_stdout: bool,
               many: bool, criterion: Criterion, illuminant: str, renderer: str,
               reference: str, size: str, table: str | None, bound: str = "classic",
               measure: Any = None, decision: Any = None, reports: list[Any] | None = None
               ) -> int:
    """Check one camera, write its reports, print its verdict; its exit code."""
    from fidelity.pipeline.check import check_camera
    from fidelity.pipeline.records import RenderSource
    from fidelity.prediction.verdict import SIMPLE
    from fidelity.report.chart import write_chart_report
    from fidelity.report.terminal import summary_lines

    report = check_camera(cam, illuminant=illuminant, renderer=renderer, reference=reference,
                          size=size, table=table, criterion=criterion, bound=bound,
                          measure=measure, decision=decision or SIMPLE)
    if reports is not None:
        reports.append(report)
    write_chart_report(report, json_path=json_file, html_path=html)
    if to_stdout:
        from fidelity.report.jsonform import chart_report_json

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
        from fidelity.core.fileio import display_path

        click.echo(f"  report: {display_path(html)}"
                   + (f" (JSON: {display_path(json_file)})" if json_file else ""))
    return report.exit_code
