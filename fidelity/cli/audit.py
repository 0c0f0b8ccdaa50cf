"""``fidelity audit``: measure a colour chart in any render or photo."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import click

from fidelity.chart.read import ReadOptions
from fidelity.chart.recording import FrameSelection
from fidelity.cli import error_line
from fidelity.cli.context import STDOUT, evidence_outputs, write_evidence_files, write_json_output
from fidelity.cli.options import (
    IMAGE_PATH,
    FrameRange,
    cat_option,
    common_options,
    evidence_option,
    image_read_options,
    judge_options,
    manifest_options,
    max_pixels_option,
    measure_options,
)
from fidelity.cli.subjects import (
    frames_summary,
    plan_subjects,
    recordings_noise,
    write_frames_noise,
)
from fidelity.cli.values import measure_inputs, measure_request
from fidelity.core.fileio import check_outputs, display_path
from fidelity.measure.chartsharpness import EdgeTargetCorners
from fidelity.pipeline.check import audit_image, audit_images
from fidelity.pipeline.records import GateResult, ImageSource
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.verdict import EXIT_ERROR
from fidelity.report.evidence import write_evidence
from fidelity.report.jsonform import chart_report_json
from fidelity.report.terminal import summary_lines


@click.command()
@click.argument("image", nargs=-1, required=True, type=IMAGE_PATH)
@click.option("--corners", default=None,
              help="X1,Y1,X2,Y2,X3,Y3,X4,Y4: image centres of the dark skin, bluish green, black "
                   "and white patches (the chart's top-left, top-right, bottom-right, "
                   "bottom-left patch as seen); pixel (row i, column j) is at x=j, y=i. "
                   "Default: the chart is found in the image and the corners printed.")
@image_read_options
@click.option("--reference", default="scene", show_default=True,
              help="scene (the chart's BabelColor spectra under --illuminant, as render and "
                   "check use), safecolor (the paper's Lab table) or a chart JSON.")
@click.option("--illuminant", default="D65", show_default=True,
              help="Illuminant of the scene reference.")
@judge_options(decision=False)
@click.option("--json", "json_path", type=click.Path(),
              help="Write the JSON report here (a folder, existing or written with a "
                   "trailing /: IMAGE-NAME.json in it; '-': standard output).")
@click.option("--html", "html_path", type=click.Path(),
              help="Write the HTML report here (a folder, existing or written with a "
                   "trailing /: IMAGE-NAME.html in it).")
@click.option("--frames", type=FrameRange(), default=None, metavar="FRAMES",
              help="With recordings and videos: audit each of these frames (of --topic), "
                   "N,M,... or START:STOP[:STEP] (0:300:30; negative from the end: -10:), "
                   "each its own "
                   "report; instead of --frame and --time.")
@max_pixels_option
@cat_option
@evidence_option
@measure_options
@common_options
@manifest_options
def audit(image: tuple[Path, ...], corners: str | None, read: ReadOptions,
          reference: str, illuminant: str,
          json_path: str | None, html_path: str | None, frames: FrameSelection | None,
          max_pixels: int | None, judge: JudgeOptions, measure: bool, images: str | None,
          annotations: str | None, models: str | None, limit: int | None, cat: str,
          evidence_paths: tuple[Path, ...],
          edge_target: EdgeTargetCorners | None = None) -> None:
    """Measure the chart in IMAGE: ΔE00 per patch, mean and max, exposure, bad pixels.

    \b
    fidelity audit render.exr --json audit.json
    fidelity audit photo.jpg --corners 102,88,610,95,604,420,98,414
    fidelity audit render.png --measure      # + the loss measured on COCO
    fidelity audit drive.bag --topic /camera/image_raw --time 12.5
    fidelity audit frames/ --json reports/ --html reports/
    fidelity audit drive.bag --topic /camera/image_raw --frames 0:300:30 --html reports/

    IMAGE is an image file, a folder of them (its images in natural order: frame_2 before
    frame_10) or a robot recording (ROS 1 bag, ROS 2 bag folder or its .db3 / .mcap file,
    MCAP file) with --topic and --frame or --time. Several IMAGEs, or --frames of
    recordings, are audited one by one in one process (--json and --html name folders that
    get IMAGE-NAME.json / .html, and index.html, an overview); one that cannot be measured is
    an error line and the others are still audited; the exit code is then 2.
    """
    if frames is not None and (read.frame is not None or read.time is not None):
        raise click.UsageError("give --frames, or --frame N or --time T, not both")
    read = replace(read, max_pixels=max_pixels)
    plan = plan_subjects(image, frames, read.topic, json_path, html_path)
    check_outputs({**evidence_outputs(evidence_paths), **plan.outputs()},
                  {"--table": judge.table_input, "--reference": reference,
                   "--illuminant": illuminant}
                  | plan.inputs() | measure_inputs(images, annotations, models))
    request = measure_request(measure, images, annotations, models, limit)
    if plan.many:  # an input error of one subject is its result's; the others are still audited
        cases = audit_images(plan.images, corners, read=read, frames=plan.frames,
                             reference=reference, illuminant=illuminant, judge=judge,
                             measure=request, cat=cat, edge_target=edge_target)
    else:  # an input error is the command's (one line, exit 2)
        frame_of = plan.frames
        only = replace(read, frame=frame_of[0], time=None) if frame_of else read
        subject = (f"{plan.images[0]} frame {frame_of[0]}" if frame_of
                   else str(plan.images[0]))
        cases = [GateResult(subject, report=audit_image(
            plan.images[0], corners, read=only, reference=reference, illuminant=illuminant,
            judge=judge, measure=request, cat=cat, edge_target=edge_target))]
    done = plan.write_reports(cases)
    cases = [case for case, _ in done]
    indent = "  " if plan.many else ""
    for (case, written), name in zip(done, plan.names, strict=True):
        report = case.report
        if report is None:
            if plan.many:
                click.echo(f"{name}: error")
            error_line(case.error or "not measured")
            continue
        if plan.to_stdout:
            write_json_output(STDOUT, chart_report_json(report))
        src = report.source
        assert isinstance(src, ImageSource)
        click.echo(f"{name}: {src.image.format} {src.image.pixel_type} "
                   f"{src.image.width}x{src.image.height}, {src.encoding} pixels")
        for line in summary_lines(report):
            click.echo(indent + line)
        for p in written:
            click.echo(f"{indent}wrote {display_path(p)}")
    written_all = [p for _, written in done for p in written]
    failed = sum(case.report is None for case in cases)
    noise = ([] if plan.frames is None else
             recordings_noise(cases, plan.images, plan.frames, read, reference, illuminant))
    overview = plan.write_overview(cases, audit=True, noise=noise)
    if overview is not None:
        written_all.append(overview)
        click.echo(f"wrote {display_path(overview)}")
    if plan.frames is not None:
        for line in frames_summary(cases, plan.images, plan.frames):
            click.echo(line)
        for n in noise:
            click.echo(n.summary())
        for p in write_frames_noise(noise, json_path):
            written_all.append(p)
            click.echo(f"wrote {display_path(p)}")
    write_evidence_files(evidence_paths, write_evidence, "audit",
                         [(c.subject, c.report, c.error) for c in cases],
                         EXIT_ERROR if failed else 0, results=written_all)
    if plan.many:
        what = "images" if plan.frames is None else "frames"
        click.echo(f"audit: {len(cases) - failed} of {len(cases)} {what} measured"
                   + (f", {failed} could not be" if failed else ""))
    if failed:
        sys.exit(EXIT_ERROR)
