"""``fidelity gate``: pass/fail for CI on an image's chart or a camera model's render.

Exit codes: 0 pass, 1 fail, 2 error (one line on stderr, no traceback; with ``--junit`` the
error is also written as a JUnit ``<error>``), 4 undecided (``--decision guarded``: the value
within its expanded uncertainty of the limit; ``--strict`` makes it a fail). The work is :func:`fidelity.pipeline.check.gate`; the
image options, the criterion and the report paths are :mod:`fidelity.cli.options`', shared with
``fidelity audit`` and ``fidelity compare``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.options import (
    IMAGE_PATH,
    PATH,
    STDOUT,
    FrameRange,
    bound_option,
    common_options,
    decision_options,
    decision_rule,
    evidence_option,
    evidence_outputs,
    expand_folders,
    frame_report_names,
    frame_subjects,
    frames_summary,
    from_settings,
    image_read_options,
    make_criterion,
    max_pixels_option,
    report_paths,
    write_evidence_files,
    write_subject_reports,
)
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import display_path
from fidelity.prediction.tablefile import CLASS_COLUMNS, SIZES
from fidelity.prediction.verdict import EXIT_ERROR, EXIT_UNDECIDED

if TYPE_CHECKING:
    from fidelity.chart.read import ReadOptions
    from fidelity.chart.recording import FrameSelection
    from fidelity.pipeline.records import GateResult


def _error_line(message: str) -> None:
    click.echo(f"fidelity: error: {message}", err=True)


def _write_junit(junit: Path, cases: Sequence[GateResult]) -> None:
    """Write the JUnit file; a failure to write it is an error (exit 2)."""
    from fidelity.report.junit import write_junit

    try:
        write_junit(junit, cases)
    except (FidelityError, OSError) as exc:
        _error_line(f"{junit}: cannot write JUnit XML: {exc}")
        sys.exit(EXIT_ERROR)


@click.command()
@click.argument("images", nargs=-1, type=IMAGE_PATH)
@click.option("--corners", help="X1,Y1,...,X4,Y4: centres of the dark skin, bluish green, black "
              "and white patches in IMAGE (default: the chart is found); with several images, "
              "for all of them.")
@click.option("--camera", help="Camera model (built-in name or TOML path) instead of an image.")
@click.option("--max-delta-e", type=float, help="Pass when the chart's mean ΔE00 <= X.")
@click.option("--max-dmap", type=float, help="Pass when the predicted ΔmAP (or class ΔAP) <= P.")
@click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)),
              help="Class of --max-dmap: all (mAP, default), person, bicycle.")
@click.option("--unit", type=click.Choice(["points", "relative"]), default="points",
              show_default=True, help="Unit of --max-dmap: percentage points or % of baseline.")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class of the prediction.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
@image_read_options
@click.option("--reference", default="scene", show_default=True,
              help="scene (the chart's spectra under --illuminant), safecolor (the paper's Lab "
                   "table) or a chart JSON.")
@click.option("--illuminant", default="D65", show_default=True, help="Scene illuminant.")
@click.option("--renderer", default="closed-form", show_default=True,
              help="Camera renderer: closed-form or mitsuba.")
@click.option("--junit", type=PATH, help="Write JUnit XML (one test case per image or camera).")
@click.option("--json", "json_path", type=click.Path(path_type=Path),
              help="Write the JSON report (several images: a folder, one report per image; "
                   "'-': standard output, one subject only).")
@click.option("--html", "html_path", type=click.Path(path_type=Path),
              help="Write the HTML report (several images: a folder, one report per image "
                   "and index.html, an overview of them all).")
@click.option("--frames", type=FrameRange(), default=None, metavar="FRAMES",
              help="With recordings: gate each of these frames of --topic, N,M,... or "
                   "START:STOP[:STEP] (0:300:30; negative from the end: -10:), each its own "
                   "subject (JUnit test case, report); instead of --frame and --time.")
@max_pixels_option
@bound_option
@decision_options
@evidence_option
@common_options
def gate(images: tuple[Path, ...], corners: str | None, camera: str | None,
         max_delta_e: float | None, max_dmap: float | None, cls: str | None, unit: str,
         size: str, table: str | None, read: ReadOptions,
         reference: str, illuminant: str, renderer: str, junit: Path | None,
         json_path: Path | None, html_path: Path | None,
         frames: FrameSelection | None, max_pixels: int | None, bound: str, decision: str,
         coverage_factor: float, strict: bool, evidence_paths: tuple[Path, ...]) -> None:
    """Gate a camera's colour fidelity: exit 0 pass, 1 fail, 2 input error, 3 bug, 4
    undecided (--decision guarded).

    \b
    fidelity gate render.exr --max-delta-e 3
    fidelity gate photo.jpg --corners 102,88,610,95,604,420,98,414 --max-delta-e 3
    fidelity gate --camera nikon-5100 --max-dmap 1 --class person --junit colour.xml
    fidelity gate day.exr dusk.exr tunnel.exr --max-delta-e 3 --junit colour.xml
    fidelity gate frames/ --max-delta-e 3 --junit colour.xml --html reports/
    fidelity gate drive.bag --topic /camera/image_raw --frame 40 --max-delta-e 3
    fidelity gate drive.bag --topic /camera/image_raw --frames 0:300:30 --max-delta-e 3

    A folder of images stands for its images, in natural order (frame_2 before frame_10).
    Several IMAGEs are gated one by one (one JUnit test case each; --json and --html name
    folders that get IMAGE-NAME.json / .html, as an existing folder does for one image); the
    exit code is 2 if any image could not be measured, else 1 if any failed, else 4 if any
    was undecided, else 0.
    """
    # settings-file values yield to what the command line names
    if images and camera is not None and from_settings("camera"):
        camera = None
    if max_dmap is not None and max_delta_e is not None and from_settings("max_delta_e"):
        max_delta_e = None
    if max_delta_e is not None and max_dmap is not None and from_settings("max_dmap"):
        max_dmap = None
    if images and camera is not None:
        raise click.UsageError("give IMAGE(s) or --camera, not both")
    if not images and camera is None:
        raise click.UsageError("give one or more IMAGEs, or --camera")
    if camera is not None and (corners is not None or read.given()):
        raise click.UsageError("--corners, --encoding, --exposure, --layer, --bayer, "
                               "--colourspace, --topic, --frame and --time apply to an IMAGE, "
                               "not to --camera")
    if frames is not None and not images:
        raise click.UsageError("--frames applies to recordings given as IMAGEs")
    if frames is not None and (read.frame is not None or read.time is not None):
        raise click.UsageError("give --frames, or --frame N or --time T, not both")
    if images and renderer != "closed-form" and not from_settings("renderer"):
        raise click.UsageError("--renderer applies to --camera (a camera model rendered), not "
                               "to an IMAGE")
    from dataclasses import replace

    from fidelity.pipeline.check import gate as gate_subjects
    from fidelity.pipeline.records import GateResult, gate_exit_code
    from fidelity.report.terminal import summary_lines

    try:
        images = expand_folders(images)  # a folder of frames: its images
    except FidelityError as exc:
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)
    to_stdout = json_path is not None and str(json_path) == STDOUT
    if to_stdout and (len(images) > 1 or frames is not None):
        raise click.UsageError("--json - (standard output) takes one IMAGE; give a folder")
    if to_stdout:
        json_path = None
    frame_of: list[int] | None = None
    try:
        from fidelity.core.fileio import check_outputs

        if frames is not None:  # each selected frame of each recording is a subject
            images, frame_of = frame_subjects(images, frames, read.topic)
        many = len(images) > 1
        # a folder (always so with several subjects) gets one report per image (or camera)
        subjects = ((images or (Path(camera or ""),)) if frame_of is None else
                    frame_report_names(images, frame_of))
        json_paths = report_paths(subjects, json_path, ".json", folder=many)
        html_paths = report_paths(subjects, html_path, ".html", folder=many)
        outputs: dict[str, Path | None] = {"--junit": junit, **evidence_outputs(evidence_paths)}
        for img, jp, hp in zip(subjects, json_paths, html_paths, strict=True):
            outputs[f"--json ({img})" if many else "--json"] = jp
            outputs[f"--html ({img})" if many else "--html"] = hp
        # several subjects' HTML reports in a folder get an overview page beside them
        overview = None
        if many and html_path is not None:
            from fidelity.report.gate import OVERVIEW_NAME

            overview = html_path / OVERVIEW_NAME
        outputs["--html (overview)"] = overview
        from fidelity.camera.model import camera_files

        check_outputs(outputs, {"--camera": camera, "--table": table, "--reference": reference,
                                "--illuminant": illuminant}
                      | {f"--camera ({f.name})": f for f in camera_files(camera or "")}
                      | {(f"IMAGE {img}" if many else "IMAGE"): img for img in images})
    except FidelityError as exc:  # no JUnit file either: it may be the input named
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)

    try:
        criterion = make_criterion(max_delta_e, max_dmap, cls, unit)
        rule = decision_rule(decision, coverage_factor, strict)
    except FidelityError as exc:
        if junit is not None:
            subject = ", ".join(map(str, images)) if images else str(camera)
            _write_junit(junit, [GateResult(subject, error=str(exc))])
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)
    cases = gate_subjects(
        criterion, images, camera=camera, corners=corners,
        read=replace(read, max_pixels=max_pixels),
        reference=reference, illuminant=illuminant, renderer=renderer, size=size, table=table,
        bound=bound, decision=rule, frames=frame_of)
    done = [write_subject_reports(case, jp, hp, images)
            for case, jp, hp in zip(cases, json_paths, html_paths, strict=True)]
    cases = [case for case, _ in done]
    for case, written in done:
        if many:
            subject = display_path(case.subject)
            click.echo(f"{subject}:" if case.error is None else f"{subject}: error")
        if case.error is not None or case.report is None:
            _error_line(case.error or "no report")
            continue
        if camera is not None:
            src = case.report.source
            click.echo(f"camera {src.title}, illuminant {illuminant}, {renderer} renderer")
        for line in summary_lines(case.report):
            click.echo(("  " if many else "") + line)
        for path in written:
            click.echo(("  " if many else "") + f"wrote {display_path(path)}")
    if overview is not None:
        from fidelity.report.gate import write_gate_overview

        try:
            write_gate_overview(overview, cases,
                                [hp if c.report is not None else None
                                 for c, hp in zip(cases, html_paths, strict=True)],
                                frame_of, None if frame_of is None else
                                [display_path(img) for img in images])
        except (FidelityError, OSError) as exc:  # as a JUnit file that cannot be written
            _error_line(f"{overview}: cannot write the overview: {exc}")
            sys.exit(EXIT_ERROR)
        click.echo(f"wrote {display_path(overview)}")
    if junit is not None:
        _write_junit(junit, cases)
        click.echo(f"wrote {display_path(junit)}")
    if to_stdout and cases[0].report is not None:
        from fidelity.cli.options import write_json_output
        from fidelity.report.jsonform import chart_report_json

        write_json_output(STDOUT, chart_report_json(cases[0].report))
    if evidence_paths:
        from fidelity.report.evidence import write_evidence

        write_evidence_files(evidence_paths, write_evidence, "gate",
                             [(c.subject, c.report, c.error) for c in cases],
                             gate_exit_code(cases),
                             results=[*(p for _, w in done for p in w), junit])
    if frame_of is not None:
        for line in frames_summary(cases, images, frame_of):
            click.echo(line)
    if many:
        codes = [c.exit_code for c in cases]
        undecided = (f", {codes.count(EXIT_UNDECIDED)} undecided"
                     if EXIT_UNDECIDED in codes else "")
        click.echo(f"gate: {codes.count(0)} of {len(codes)} passed, {codes.count(1)} failed"
                   f"{undecided}, {codes.count(EXIT_ERROR)} could not be measured")
    sys.exit(gate_exit_code(cases))
