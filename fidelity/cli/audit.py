"""``fidelity audit``: measure a colour chart in any render or photo."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.options import (
    IMAGE_PATH,
    STDOUT,
    FrameRange,
    bound_option,
    common_options,
    evidence_option,
    evidence_outputs,
    expand_folders,
    frame_report_names,
    frame_subjects,
    frames_summary,
    image_read_options,
    max_pixels_option,
    measure_inputs,
    measure_options,
    measure_request,
    report_paths,
    write_evidence_files,
    write_subject_reports,
)
from fidelity.core.fileio import display_path
from fidelity.prediction.tablefile import SIZES
from fidelity.prediction.verdict import EXIT_ERROR

if TYPE_CHECKING:
    from fidelity.chart.read import ReadOptions
    from fidelity.chart.recording import FrameSelection


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
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class for the predicted loss.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
@click.option("--json", "json_path", type=click.Path(),
              help="Write the JSON report here (a folder, existing or written with a "
                   "trailing /: IMAGE-NAME.json in it; '-': standard output).")
@click.option("--html", "html_path", type=click.Path(),
              help="Write the HTML report here (a folder, existing or written with a "
                   "trailing /: IMAGE-NAME.html in it).")
@click.option("--frames", type=FrameRange(), default=None, metavar="FRAMES",
              help="With recordings: audit each of these frames of --topic, N,M,... or "
                   "START:STOP[:STEP] (0:300:30; negative from the end: -10:), each its own "
                   "report; instead of --frame and --time.")
@max_pixels_option
@bound_option
@evidence_option
@measure_options
@common_options
def audit(image: tuple[Path, ...], corners: str | None, read: ReadOptions,
          reference: str, illuminant: str, size: str, table: str | None,
          json_path: str | None, html_path: str | None, frames: FrameSelection | None,
          max_pixels: int | None, bound: str, measure: bool, images: str | None,
          annotations: str | None, models: str | None, limit: int | None,
          evidence_paths: tuple[Path, ...]) -> None:
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
    from dataclasses import replace

    from fidelity.cli import error_line
    from fidelity.core.fileio import check_outputs
    from fidelity.pipeline.check import audit_image, audit_images
    from fidelity.pipeline.records import GateResult, ImageSource
    from fidelity.report.terminal import summary_lines

    if frames is not None and (read.frame is not None or read.time is not None):
        raise click.UsageError("give --frames, or --frame N or --time T, not both")
    read = replace(read, max_pixels=max_pixels)
    image = expand_folders(image)
    reports_of = image  # what each subject's report is named after
    frame_of: list[int] | None = None
    if frames is not None:  # each selected frame of each recording is a subject
        image, frame_of = frame_subjects(image, frames, read.topic)
        reports_of = frame_report_names(image, frame_of)
    names = ([display_path(img) for img in image] if frame_of is None else
             [f"{display_path(img)} frame {k}" for img, k in zip(image, frame_of, strict=True)])
    many = len(image) > 1
    # an existing folder, or one written with a trailing separator, gets IMAGE-NAME.json /
    # .html, as in `fidelity gate`; several images always do
    to_stdout = json_path is not None and str(json_path) == STDOUT
    if to_stdout and many:
        raise click.UsageError("--json - (standard output) takes one IMAGE; give a folder")
    json_files = report_paths(reports_of, None if to_stdout or json_path is None
                              else Path(json_path), ".json", folder=many or _folder(json_path))
    html_files = report_paths(reports_of, None if html_path is None else Path(html_path),
                              ".html", folder=many or _folder(html_path))
    outputs: dict[str, Path | None] = dict(evidence_outputs(evidence_paths))
    for name, jf, hf in zip(names, json_files, html_files, strict=True):
        outputs[f"--json ({name})" if many else "--json"] = jf
        outputs[f"--html ({name})" if many else "--html"] = hf
    # several images' HTML reports get an overview page beside them, as a gate's do
    overview = None
    if many and html_path is not None:
        from fidelity.report.gate import OVERVIEW_NAME

        overview = outputs["--html (overview)"] = Path(html_path) / OVERVIEW_NAME
    check_outputs(outputs, {"--table": table, "--reference": reference,
                            "--illuminant": illuminant}
                  | {(f"IMAGE {img}" if many else "IMAGE"): img for img in image}
                  | measure_inputs(images, annotations, models))
    request = measure_request(measure, images, annotations, models, limit)
    options = {"reference": reference, "illuminant": illuminant, "size": size, "table": table,
               "bound": bound, "measure": request}
    if many:  # an input error of one subject is its result's; the others are still audited
        cases = audit_images(image, corners, read=read, frames=frame_of, **options)
    else:  # an input error is the command's (one line, exit 2)
        only = replace(read, frame=frame_of[0], time=None) if frame_of else read
        subject = f"{image[0]} frame {frame_of[0]}" if frame_of else str(image[0])
        cases = [GateResult(subject, report=audit_image(image[0], corners, read=only,
                                                        **options))]
    done = [write_subject_reports(case, jf, hf, image)
            for case, jf, hf in zip(cases, json_files, html_files, strict=True)]
    cases = [case for case, _ in done]
    indent = "  " if many else ""
    for (case, written), name in zip(done, names, strict=True):
        report = case.report
        if report is None:
            if many:
                click.echo(f"{name}: error")
            error_line(case.error or "not measured")
            continue
        if to_stdout:
            from fidelity.cli.options import write_json_output
            from fidelity.report.jsonform import chart_report_json

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
    if overview is not None:
        from fidelity.report.gate import write_gate_overview

        write_gate_overview(overview, cases,
                            [hf if case.report is not None else None
                             for case, hf in zip(cases, html_files, strict=True)],
                            frame_of, None if frame_of is None else
                            [display_path(img) for img in image], audit=True)
        written_all.append(overview)
        click.echo(f"wrote {display_path(overview)}")
    if frame_of is not None:
        for line in frames_summary(cases, image, frame_of):
            click.echo(line)
    if evidence_paths:
        from fidelity.report.evidence import write_evidence

        write_evidence_files(evidence_paths, write_evidence, "audit",
                             [(c.subject, c.report, c.error) for c in cases],
                             EXIT_ERROR if failed else 0, results=written_all)
    if many:
        what = "images" if frame_of is None else "frames"
        click.echo(f"audit: {len(cases) - failed} of {len(cases)} {what} measured"
                   + (f", {failed} could not be" if failed else ""))
    if failed:
        sys.exit(EXIT_ERROR)


def _folder(value: str | None) -> bool:
    """Whether an output option names a folder by its trailing separator (``out/``)."""
    return value is not None and value.endswith(("/", os.sep))
