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
from dataclasses import replace
from pathlib import Path

import click

from fidelity.camera.model import CameraModel, camera_files, load_camera
from fidelity.chart.read import ReadOptions
from fidelity.chart.recording import FrameSelection
from fidelity.cli.context import (
    STDOUT,
    evidence_outputs,
    from_settings,
    write_evidence_files,
    write_json_output,
)
from fidelity.cli.options import (
    IMAGE_PATH,
    PATH,
    FrameRange,
    cat_option,
    common_options,
    evidence_option,
    image_read_options,
    judge_options,
    loss_limit_options,
    manifest_options,
    max_pixels_option,
)
from fidelity.cli.subjects import (
    frames_summary,
    plan_subjects,
    recordings_noise,
    write_frames_noise,
)
from fidelity.cli.values import make_criterion
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import check_outputs, display_path
from fidelity.measure.chartsharpness import EdgeTargetCorners
from fidelity.pipeline.check import gate as gate_subjects
from fidelity.pipeline.records import GateResult, gate_exit_code
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.verdict import EXIT_ERROR, EXIT_UNDECIDED
from fidelity.report.evidence import write_evidence
from fidelity.report.jsonform import chart_report_json
from fidelity.report.junit import write_junit
from fidelity.report.terminal import summary_lines


def _error_line(message: str) -> None:
    click.echo(f"fidelity: error: {message}", err=True)


def _write_junit(junit: Path, cases: Sequence[GateResult]) -> None:
    """Write the JUnit file; a failure to write it is an error (exit 2)."""
    try:
        write_junit(junit, cases)
    except (FidelityError, OSError) as exc:
        _error_line(f"{junit}: cannot write JUnit XML: {exc}")
        sys.exit(EXIT_ERROR)


def _settled(images: tuple[Path, ...], camera: str | None, max_delta_e: float | None,
             max_dmap: float | None) -> tuple[str | None, float | None, float | None]:
    """``--camera``, ``--max-delta-e`` and ``--max-dmap`` once the settings file's values have
    yielded to what the command line names."""
    if images and camera is not None and from_settings("camera"):
        camera = None
    if max_dmap is not None and max_delta_e is not None and from_settings("max_delta_e"):
        max_delta_e = None
    if max_delta_e is not None and max_dmap is not None and from_settings("max_dmap"):
        max_dmap = None
    return camera, max_delta_e, max_dmap


def _check_usage(images: tuple[Path, ...], camera: str | None, corners: str | None,
                 read: ReadOptions, frames: FrameSelection | None, renderer: str) -> None:
    """The options that do not go together (a usage error, exit 2)."""
    if images and camera is not None:
        raise click.UsageError("give IMAGE(s) or --camera, not both")
    if not images and camera is None:
        raise click.UsageError("give one or more IMAGEs, or --camera")
    if camera is not None and (corners is not None or read.given()):
        raise click.UsageError("--corners, --manifest, --encoding, --exposure, --layer, --bayer, "
                               "--colourspace, --topic, --frame and --time apply to an IMAGE, "
                               "not to --camera")
    if frames is not None and not images:
        raise click.UsageError("--frames applies to recordings given as IMAGEs")
    if frames is not None and (read.frame is not None or read.time is not None):
        raise click.UsageError("give --frames, or --frame N or --time T, not both")
    if images and renderer != "closed-form" and not from_settings("renderer"):
        raise click.UsageError("--renderer applies to --camera (a camera model rendered), not "
                               "to an IMAGE")


def _print_case(case: GateResult, written: Sequence[Path], *, many: bool, camera: bool,
                setting: str) -> None:
    """One subject's lines: its name (several subjects), the camera (a camera's gate), the
    summary and the files written; an error as one line on stderr."""
    if many:
        subject = display_path(case.subject)
        click.echo(f"{subject}:" if case.error is None else f"{subject}: error")
    if case.error is not None or case.report is None:
        _error_line(case.error or "no report")
        return
    if camera:
        click.echo(f"camera {case.report.source.title}, {setting}")
    indent = "  " if many else ""
    for line in summary_lines(case.report):
        click.echo(indent + line)
    for path in written:
        click.echo(f"{indent}wrote {display_path(path)}")


@click.command()
@click.argument("images", nargs=-1, type=IMAGE_PATH)
@click.option("--corners", help="X1,Y1,...,X4,Y4: centres of the dark skin, bluish green, black "
              "and white patches in IMAGE (default: the chart is found); with several images, "
              "for all of them.")
@click.option("--camera", help="Camera model (built-in name or TOML path) instead of an image.")
@click.option("--max-delta-e", type=float, help="Pass when the chart's mean ΔE00 <= X.")
@loss_limit_options
@judge_options()
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
              help="With recordings and videos: gate each of these frames (of --topic), "
                   "N,M,... or START:STOP[:STEP] (0:300:30; negative from the end: -10:), "
                   "each its own "
                   "subject (JUnit test case, report); instead of --frame and --time.")
@max_pixels_option
@cat_option
@evidence_option
@common_options
@manifest_options
def gate(images: tuple[Path, ...], corners: str | None, camera: str | None,
         max_delta_e: float | None, max_dmap: float | None, cls: str | None, unit: str,
         judge: JudgeOptions, read: ReadOptions,
         reference: str, illuminant: str, renderer: str, junit: Path | None,
         json_path: Path | None, html_path: Path | None,
         frames: FrameSelection | None, max_pixels: int | None, cat: str,
         evidence_paths: tuple[Path, ...],
         edge_target: EdgeTargetCorners | None = None) -> None:
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
    camera, max_delta_e, max_dmap = _settled(images, camera, max_delta_e, max_dmap)
    _check_usage(images, camera, corners, read, frames, renderer)
    try:
        # a camera is the one subject, its reports named after it
        plan = plan_subjects(images or (Path(camera or ""),), frames, read.topic, json_path,
                             html_path)
        # the camera file is parsed once, here; a camera that cannot be read is its subject's
        # error (a JUnit <error> too), as an image that cannot be read is
        model: CameraModel | None = None
        camera_error: FidelityError | None = None
        if camera is not None:
            try:
                model = load_camera(camera)
            except FidelityError as exc:
                camera_error = exc
        camera_inputs = (model.files if model is not None else
                         camera_files(camera) if camera is not None else ())
        inputs: dict[str, str | Path | None] = {
            "--camera": camera, "--table": judge.table_input, "--reference": reference,
            "--illuminant": illuminant, **{f"--camera ({f.name})": f for f in camera_inputs}}
        if camera is None:
            inputs |= plan.inputs()
        check_outputs({"--junit": junit, **evidence_outputs(evidence_paths), **plan.outputs()},
                      inputs)
    except FidelityError as exc:  # no JUnit file either: it may be the input named
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)
    images = plan.images if camera is None else ()

    try:
        criterion = make_criterion(max_delta_e, max_dmap, cls, unit)
    except FidelityError as exc:
        if junit is not None:
            subject = ", ".join(map(str, images)) if images else str(camera)
            _write_junit(junit, [GateResult(subject, error=str(exc))])
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)
    if camera_error is not None:
        cases = [GateResult(str(camera), criterion, error=str(camera_error))]
    else:
        cases = gate_subjects(
            criterion, images, camera=model, corners=corners,
            read=replace(read, max_pixels=max_pixels), reference=reference,
            illuminant=illuminant, renderer=renderer, judge=judge, frames=plan.frames, cat=cat,
            edge_target=edge_target)
    done = plan.write_reports(cases)
    cases = [case for case, _ in done]
    many = plan.many
    for case, written in done:
        _print_case(case, written, many=many, camera=camera is not None,
                    setting=f"illuminant {illuminant}, {renderer} renderer")
    noise = ([] if plan.frames is None else
             recordings_noise(cases, images, plan.frames, replace(read, max_pixels=max_pixels),
                              reference, illuminant))
    try:
        overview = plan.write_overview(cases, audit=False, noise=noise)
    except (FidelityError, OSError) as exc:  # as a JUnit file that cannot be written
        _error_line(f"{plan.overview}: cannot write the overview: {exc}")
        sys.exit(EXIT_ERROR)
    if overview is not None:
        click.echo(f"wrote {display_path(overview)}")
    if junit is not None:
        _write_junit(junit, cases)
        click.echo(f"wrote {display_path(junit)}")
    if plan.to_stdout and cases[0].report is not None:
        write_json_output(STDOUT, chart_report_json(cases[0].report))
    write_evidence_files(evidence_paths, write_evidence, "gate",
                         [(c.subject, c.report, c.error) for c in cases],
                         gate_exit_code(cases),
                         results=[*(p for _, w in done for p in w), junit])
    if plan.frames is not None:
        for line in frames_summary(cases, images, plan.frames):
            click.echo(line)
        for n in noise:
            click.echo(n.summary())
        for p in write_frames_noise(noise, json_path):
            click.echo(f"wrote {display_path(p)}")
    if many:
        codes = [c.exit_code for c in cases]
        undecided = (f", {codes.count(EXIT_UNDECIDED)} undecided"
                     if EXIT_UNDECIDED in codes else "")
        click.echo(f"gate: {codes.count(0)} of {len(codes)} passed, {codes.count(1)} failed"
                   f"{undecided}, {codes.count(EXIT_ERROR)} could not be measured")
    sys.exit(gate_exit_code(cases))
