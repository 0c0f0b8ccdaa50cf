"""``fidelity audit``: measure a colour chart in any render or photo."""

from __future__ import annotations

from pathlib import Path

import click

from fidelity.cli.gate import (
    PATH,
    colourspace_option,
    image_report,
    negatives_option,
    report_paths,
    write_outputs,
)
from fidelity.prediction.table import SIZES


@click.command()
@click.argument("image", type=PATH)
@click.option("--corners", default=None,
              help="X1,Y1,X2,Y2,X3,Y3,X4,Y4: image centres of the dark skin, bluish green, black "
                   "and white patches (the chart's top-left, top-right, bottom-right, "
                   "bottom-left patch as seen); pixel (row i, column j) is at x=j, y=i. "
                   "Default: the chart is found in the image and the corners printed.")
@click.option("--encoding", type=click.Choice(["linear", "srgb"]), default=None,
              help="Pixel encoding (default: linear for EXR/HDR/float TIFF, sRGB otherwise).")
@click.option("--exposure", default=None,
              help="auto (neutral patches; default for linear input) or a fixed EV "
                   "(pixels x 2**EV; default 0 for sRGB input).")
@click.option("--layer", default=None, help="EXR layer (e.g. 'diffuse' for diffuse.R) or part.")
@colourspace_option
@negatives_option
@click.option("--reference", default="safecolor", show_default=True,
              help="safecolor (the paper's Lab), scene (BabelColor spectra under --illuminant) "
                   "or a chart JSON.")
@click.option("--illuminant", default="D65", show_default=True,
              help="Illuminant of the scene reference.")
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class for the predicted loss.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
@click.option("--json", "json_path", type=click.Path(path_type=Path),
              help="Write the JSON report here (a folder: IMAGE-NAME.json in it).")
@click.option("--html", "html_path", type=click.Path(path_type=Path),
              help="Write the HTML report here (a folder: IMAGE-NAME.html in it).")
@click.option("--quiet", "-q", is_flag=True, help="Print nothing.")
def audit(image: Path, corners: str | None, encoding: str | None, exposure: str | None,
          layer: str | None, colourspace: str | None, negatives: str, reference: str,
          illuminant: str, size: str, table: str | None, json_path: Path | None, html_path: Path | None, quiet: bool) -> None:
    """Measure the chart in IMAGE: ΔE00 per patch, mean and max, exposure, bad pixels.

    \b
    fidelity audit render.exr --json audit.json
    fidelity audit photo.jpg --corners 102,88,610,95,604,420,98,414
    """
    from fidelity.fileio import check_outputs

    # an existing folder gets IMAGE-NAME.json / .html, as in `fidelity gate`
    (json_path,) = report_paths((image,), json_path, ".json")
    (html_path,) = report_paths((image,), html_path, ".html")
    check_outputs({"--json": json_path, "--html": html_path},
                  {"IMAGE": image, "--table": table, "--reference": reference,
                   "--illuminant": illuminant})
    report, prediction, _, figure = image_report(
        image, corners, command="audit", encoding=encoding, exposure=exposure, layer=layer,
        reference=reference, illuminant=illuminant, size=size, table=table,
        location_figure=html_path is not None, negatives=negatives,
        colourspace=colourspace)
    written = write_outputs(report, prediction, json_path=json_path, html_path=html_path,
                            protect=(str(image),), location_png=figure)
    if not quiet:
        from fidelity.report.chart import summary_lines

        click.echo(f"{image}: {report['source'].get('format')} {report['source'].get('pixel_type')}"
                   f" {report['source'].get('width')}x{report['source'].get('height')}, "
                   f"{report['source'].get('encoding')} pixels")
        for line in summary_lines(report):
            click.echo(line)
        for p in written:
            click.echo(f"wrote {p}")
