"""``fidelity fit``: the correction that makes the simulator's chart match the real camera's."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.options import (
    IMAGE_PATH,
    chart_pair_options,
    common_options,
    evidence_option,
    image_read_options,
)
from fidelity.prediction.table import SIZES

if TYPE_CHECKING:
    from fidelity.chart.measure import ReadOptions


@click.command()
@click.argument("sim", type=IMAGE_PATH)
@click.argument("real", type=IMAGE_PATH)
@click.option("--out", "out", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="Folder for correction.cube, correction.ocio, correction.json, report.json "
                   "and report.html.")
@click.option("--correction", "model", type=click.Choice(["gains", "matrix", "matrix+curve",
                                            "root-polynomial"]),
              default="matrix", show_default=True,
              help="The correction's form: per-channel gains, a 3x3 matrix, a shared tone curve "
                   "then a matrix, or Finlayson's root-polynomial (degree 2).")
@click.option("--objective", type=click.Choice(["linear", "ciede2000"]), default=None,
              help="What the fit minimises: squared differences in linear RGB, or squared "
                   "CIEDE2000 (default: ciede2000, the lower cross-validated ΔE00).")
@chart_pair_options
@click.option("--size", type=click.Choice(list(SIZES)), default="any", show_default=True,
              help="Detector size class of the predicted ΔmAP.")
@click.option("--table", default=None, help="Prediction table (name or JSON path).")
@click.option("--reference", default="scene", show_default=True,
              help="What each chart is audited against: scene, safecolor or a chart JSON.")
@click.option("--illuminant", default="D65", show_default=True,
              help="Illuminant of the scene reference.")
@image_read_options
@evidence_option
@common_options
def fit(sim: Path, real: Path, out: Path, model: str, objective: str | None,
        sim_corners: str | None, real_corners: str | None, normalise_mode: str, size: str,
        table: str | None, reference: str, illuminant: str, read: ReadOptions,
        evidence_path: Path | None) -> None:
    """Fit the correction from the simulator's chart onto the real camera's, as a 3D LUT.

    SIM and REAL are read as fidelity compare reads them. The correction (gains, matrix,
    tone curve and matrix, or root-polynomial) is fitted on the patches neither camera
    clipped, cross-validated leaving 3 patches out at a time, baked by OpenColorIO into
    OUT/correction.cube (with OUT/correction.ocio, a config that loads it), checked against
    the model through OpenColorIO's processor, and SIM is put through the cube and compared
    with REAL again: ΔE00 and predicted ΔmAP before and after.

    \b
    fidelity fit sim.png photo.jpg --out correction/
    fidelity fit sim.exr photo.jpg --out c/ --correction root-polynomial --normalise none
    """
    from fidelity.fileio import check_outputs, display_path
    from fidelity.fit import fit_and_verify
    from fidelity.report.fit import fit_lines, write_fit_report

    names = ("correction.cube", "correction.ocio", "correction.json", "report.json",
             "report.html")
    check_outputs({**{n: out / n for n in names}, "--evidence": evidence_path},
                  {"SIM": sim, "REAL": real, "--table": table, "--reference": reference,
                   "--illuminant": illuminant})
    report = fit_and_verify(
        sim, real, out, model=model, objective=objective, sim_corners=sim_corners,
        real_corners=real_corners, normalise_mode=normalise_mode, reference=reference,
        illuminant=illuminant, size=size, table=table,
        read=read)
    write_fit_report(report, json_path=out / "report.json", html_path=out / "report.html",
                     protect=(sim, real))
    for line in fit_lines(report):
        click.echo(line)
    click.echo(f"wrote {', '.join(display_path(out / n) for n in names)}")
    if evidence_path is not None:
        from fidelity.report.evidence import write_fit_evidence

        write_fit_evidence(evidence_path, report)
        click.echo(f"wrote {display_path(evidence_path)}")
