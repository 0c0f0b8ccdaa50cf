"""``fidelity check``: render a camera's chart, measure, predict, verdict, report."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from fidelity.cli.options import STDOUT, common_options, json_option, write_json_output
from fidelity.prediction.table import SIZES
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E

#: Where ``fidelity check`` writes its report unless told otherwise.
DEFAULT_OUTPUT_DIR = "fidelity-report"


@click.command()
@click.option("--camera", default=None,
              help="Camera model: built-in name or TOML path (default: the built-in realistic "
                   "camera, fidelity.camera.model.DEFAULT_CAMERA).")
@click.option("--illuminant", default="D65", show_default=True, help="Scene illuminant.")
@click.option("--renderer", default="closed-form", show_default=True,
              help="closed-form (exact, fast) or mitsuba (spectral path tracer).")
@click.option("--reference", type=click.Choice(["scene", "safecolor"]), default="scene",
              show_default=True, help="Reference colours: the scene's spectra or the paper's Lab.")
@click.option("--max-delta-e", type=float, default=DEFAULT_MAX_DELTA_E, show_default=True,
              help="Pass when the mean ΔE00 <= X (SAFE-COLOR: ΔE <= 3 keeps ΔmAP below 1 %).")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class for the predicted loss.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=DEFAULT_OUTPUT_DIR, show_default=True,
              help="Folder for report.html and report.json.")
@json_option("Write the JSON report here instead of OUT/report.json")
@click.option("--html", "html_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the HTML report here instead of OUT/report.html.")
@common_options
def check(camera: str | None, illuminant: str, renderer: str, reference: str,
          max_delta_e: float, size: str, table: str | None, out_dir: Path,
          json_path: str | None, html_path: Path | None) -> None:
    """Is this camera model's colour good enough for perception testing?

    Renders the spectral colour chart through the camera, measures ΔE00, predicts the detection
    loss and prints a verdict (exit 0 pass, 1 fail, 2 error); writes an HTML and a JSON report.
    """
    from fidelity.camera.model import DEFAULT_CAMERA
    from fidelity.check import check_camera
    from fidelity.fileio import check_outputs
    from fidelity.prediction.verdict import Criterion
    from fidelity.report.chart import RenderSource, write_chart_report
    from fidelity.report.terminal import summary_lines

    cam = camera or DEFAULT_CAMERA
    html = html_path or out_dir / "report.html"
    to_stdout = json_path == STDOUT
    json_file = None if to_stdout else Path(json_path) if json_path else out_dir / "report.json"
    check_outputs({"--html": html, "--json": json_file},
                  {"--camera": cam, "--table": table, "--illuminant": illuminant})
    report = check_camera(cam, illuminant=illuminant, renderer=renderer, reference=reference,
                          size=size, table=table,
                          criterion=Criterion("max-delta-e", max_delta_e))
    write_chart_report(report, json_path=json_file, html_path=html)
    if to_stdout:
        write_json_output(STDOUT, report.to_json())
    src = report.source
    assert isinstance(src, RenderSource)
    variant = f" ({src.variant})" if src.variant else ""
    click.echo(f"fidelity check: camera {src.camera}, illuminant {illuminant}, "
               f"{src.renderer} renderer{variant}, {reference} reference")
    for line in summary_lines(report):
        click.echo("  " + line)
    click.echo(f"  report: {html}" + (f" (JSON: {json_file})" if json_file else ""))
    sys.exit(report.exit_code)
