"""``fidelity fit``: the correction that makes the simulator's chart match the real camera's."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.context import evidence_outputs, write_evidence_files
from fidelity.cli.options import (
    IMAGE_PATH,
    common_options,
    evidence_option,
    fit_pair_options,
    image_read_options,
    judge_options,
    measure_options,
)
from fidelity.cli.values import measure_inputs, measure_request
from fidelity.core.fileio import check_outputs, display_path
from fidelity.correction.lut import CUBE_OUTPUTS
from fidelity.pipeline.fit import (
    fit_and_verify,
    fit_camera_and_verify,
    fit_pairs_and_verify,
    sim_ocio_refused,
)
from fidelity.report.evidence import write_fit_evidence
from fidelity.report.fit import (
    fit_lines,
    shared_fit_lines,
    write_fit_report,
    write_shared_fit_report,
)

if TYPE_CHECKING:
    from fidelity.chart.read import ReadOptions
    from fidelity.coco.measure import MeasureRequest
    from fidelity.pipeline.fit import FitReport
    from fidelity.prediction.judge import JudgeOptions


@click.command()
@click.argument("sim", type=IMAGE_PATH, required=False)
@click.argument("real", type=IMAGE_PATH, required=False)
@click.option("--pair", "pairs", type=(IMAGE_PATH, IMAGE_PATH), multiple=True,
              metavar="SIM REAL",
              help="A SIM and REAL pair of one illuminant, given twice or more instead of SIM "
                   "REAL: one matrix that holds across them, with per-illuminant gains; each "
                   "pair's correction goes to OUT/pair-<k>.")
@click.option("--camera", "camera", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None,
              help="A camera model file instead of a rendered SIM (then give REAL alone): its "
                   "chart is rendered in closed form, the correction fitted and verified, and "
                   "OUT/corrected.toml written: the camera with its colour matrix corrected, "
                   "and its optics (a Gaussian PSF) and noise (the full well) fitted so that "
                   "its turned chart has REAL's MTF50 and SNR at 18 % grey.")
@click.option("--colour-only", "colour_only", is_flag=True,
              help="With --camera: correct the colour matrix only; leave the camera file's "
                   "optics and noise as they are.")
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
@click.option("--cube-output", "cube_output", type=click.Choice(list(CUBE_OUTPUTS)),
              default=None,
              help="What the .cube gives: encoded (sRGB-encoded values) or linear "
                   "(scene-linear values). Default: the SIM's own encoding (encoded for an "
                   "8/16-bit PNG or JPEG, linear for an EXR), as ffmpeg lut3d, oiiotool "
                   "--ociofiletransform and OpenColorIO apply a cube.")
@click.option("--write-corrected", "corrected", is_flag=True,
              help="Also put the whole SIM image through the .cube by OpenColorIO and write it "
                   "(OUT/corrected.png for sRGB-encoded output, OUT/corrected.exr for "
                   "scene-linear output); without it only the patch windows the verification "
                   "measures are transformed.")
@click.option("--accept-warnings", "accept", is_flag=True,
              help="Exit 0 even when fit warns (the model does not express the difference, "
                   "the correction does not lower the ΔE00, or the .cube misses its check); "
                   "the warnings are printed all the same.")
@fit_pair_options
@judge_options(bound=False, decision=False)
@click.option("--reference", default="scene", show_default=True,
              help="What each chart is audited against: scene, safecolor or a chart JSON.")
@click.option("--illuminant", default="D65", show_default=True,
              help="Illuminant of the scene reference.")
@measure_options
@image_read_options
@evidence_option
@common_options
def fit(sim: Path | None, real: Path | None, pairs: tuple[tuple[Path, Path], ...],
        camera: Path | None, colour_only: bool, out: Path,
        model: str, objective: str | None, cube_output: str | None, corrected: bool,
        accept: bool,
        sim_corners: str | None, real_corners: str | None, sim_ocio_colourspace: str | None,
        real_ocio_colourspace: str | None, normalise_mode: str,
        judge: JudgeOptions, reference: str, illuminant: str, measure: bool, images: str | None,
        annotations: str | None, models: str | None, limit: int | None,
        read: ReadOptions, evidence_paths: tuple[Path, ...]) -> None:
    """Fit the correction from the simulator's chart onto the real camera's, as a 3D LUT.

    SIM and REAL are read as fidelity compare reads them. The correction (gains, matrix,
    tone curve and matrix, or root-polynomial) is fitted on the patches neither camera
    clipped, cross-validated leaving 3 patches out at a time, baked by OpenColorIO into
    OUT/correction.cube (with OUT/correction.ocio, a config that loads it), checked against
    the model through OpenColorIO's processor, and SIM is put through the cube and compared
    with REAL again: ΔE00 and predicted ΔmAP before and after.

    The cube's output has the SIM's encoding unless --cube-output says otherwise (sRGB in,
    sRGB out; scene-linear in, scene-linear out, over 0 to the SIM's largest value), with
    no shaper: ffmpeg's lut3d, oiiotool --ociofiletransform and OpenColorIO read it alike.
    Exit 0; 1 with a "fidelity: warning:" line where the model does not express the
    difference, the correction does not lower the ΔE00 or the .cube misses its check
    (--accept-warnings: 0); 2 for an input error.

    \b
    fidelity fit sim.png photo.jpg --out correction/
    fidelity fit sim.exr photo.jpg --out c/ --correction root-polynomial --normalise none
    fidelity fit sim.png photo.jpg --out c/ --write-corrected
    fidelity fit --pair sim_d65.exr real_d65.jpg --pair sim_a.exr real_a.jpg --out c/
    """
    if sim_ocio_colourspace is not None:
        raise sim_ocio_refused("--sim-ocio-colourspace", sim_ocio_colourspace)
    request = measure_request(measure, images, annotations, models, limit)
    if pairs:
        if request is not None or evidence_paths:
            raise click.UsageError("--measure and --evidence go with SIM REAL or --camera, "
                                   "not --pair")
        if sim is not None or real is not None:
            raise click.UsageError("give SIM REAL or --pair SIM REAL (twice or more), not both")
        if len(pairs) < 2:
            raise click.UsageError("--pair is a fit over illuminants: give it twice or more "
                                   "(one pair: fidelity fit SIM REAL)")
        if model != "matrix":
            raise click.UsageError("--pair fits one matrix with per-illuminant gains: "
                                   "--correction matrix only")
        _fit_pairs(pairs, out, sim_corners, real_corners, normalise_mode, judge,
                   reference, illuminant, read, real_ocio_colourspace, corrected,
                   cube_output, accept)
        return
    if colour_only and camera is None:
        raise click.UsageError("--colour-only goes with --camera (a .cube corrects colour "
                               "only)")
    if camera is not None:
        if sim is None or real is not None:
            raise click.UsageError("with --camera give REAL alone: fidelity fit --camera "
                                   "sim.toml REAL --out DIR")
        _fit_camera(camera, sim, out, model, objective, real_corners, normalise_mode,
                    judge, reference, illuminant, read, real_ocio_colourspace, corrected,
                    request, evidence_paths, cube_output, accept, not colour_only)
        return
    if sim is None or real is None:
        raise click.UsageError("give SIM and REAL, or --pair SIM REAL twice or more")

    names: tuple[str, ...] = ("correction.cube", "correction.ocio", "correction.json",
                              "report.json", "report.html")
    if corrected:
        names += ("corrected.png", "corrected.exr")
    check_outputs({**{n: out / n for n in names}, **evidence_outputs(evidence_paths)},
                  {"SIM": sim, "REAL": real, "--table": judge.table_input,
                   "--reference": reference,
                   "--illuminant": illuminant} | measure_inputs(images, annotations, models))
    report = fit_and_verify(
        sim, real, out, model=model, objective=objective, sim_corners=sim_corners,
        real_corners=real_corners, normalise_mode=normalise_mode, reference=reference,
        illuminant=illuminant, judge=judge, read=read,
        real_ocio_colourspace=real_ocio_colourspace, corrected=corrected, measure=request,
        cube_output=cube_output)
    write_fit_report(report, json_path=out / "report.json", html_path=out / "report.html",
                     protect=(sim, real))
    for line in fit_lines(report):
        click.echo(line)
    written = [out / n for n in names[:5]]
    if "corrected" in report.files:
        written.append(Path(report.files["corrected"]))
    click.echo(f"wrote {', '.join(display_path(p) for p in written)}")
    code = _warn(report.warnings, accept)
    _evidence(evidence_paths, report, written, code)
    sys.exit(code)


def _warn(warnings: list[str], accept: bool) -> int:
    """Print each warning as a ``fidelity: warning:`` line (stderr); the exit code: 1 where
    there is one, unless ``accept``."""
    for w in warnings:
        click.echo(f"fidelity: warning: {w}", err=True)
    return 1 if warnings and not accept else 0


def _evidence(paths: tuple[Path, ...], report: FitReport, written: list[Path],
              code: int) -> None:
    write_evidence_files(paths, write_fit_evidence, report, code, results=written)


def _fit_pairs(pairs: tuple[tuple[Path, Path], ...], out: Path, sim_corners: str | None,
               real_corners: str | None, normalise_mode: str, judge: JudgeOptions,
               reference: str, illuminant: str, read: ReadOptions,
               real_ocio_colourspace: str | None, corrected: bool, cube_output: str | None,
               accept: bool) -> None:
    inputs: dict[str, Path | str | None] = {"--table": judge.table_input,
                                            "--reference": reference,
                                            "--illuminant": illuminant}
    for k, (s, r) in enumerate(pairs):
        inputs[f"--pair {k + 1} SIM"] = s
        inputs[f"--pair {k + 1} REAL"] = r
    check_outputs({"report.json": out / "report.json", "report.html": out / "report.html",
                   **{f"pair-{k + 1}": out / f"pair-{k + 1}" for k in range(len(pairs))}},
                  inputs)
    shared = fit_pairs_and_verify(pairs, out, sim_corners=sim_corners, real_corners=real_corners,
                                  normalise_mode=normalise_mode, reference=reference,
                                  illuminant=illuminant, judge=judge, read=read,
                                  real_ocio_colourspace=real_ocio_colourspace,
                                  corrected=corrected, cube_output=cube_output)
    write_shared_fit_report(shared, json_path=out / "report.json",
                            html_path=out / "report.html",
                            protect=[p for pair in pairs for p in pair])
    for line in shared_fit_lines(shared):
        click.echo(line)
    click.echo(f"wrote {display_path(out / 'report.json')}, {display_path(out / 'report.html')} "
               f"and the corrections in {', '.join(display_path(out / f'pair-{k + 1}') for k in range(len(pairs)))}")
    sys.exit(_warn([f"pair {k + 1}: {w}" for k, rep in enumerate(shared.reports)
                    for w in rep.warnings], accept))


def _fit_camera(camera: Path, real: Path, out: Path, model: str, objective: str | None,
                real_corners: str | None, normalise_mode: str, judge: JudgeOptions,
                reference: str, illuminant: str, read: ReadOptions,
                real_ocio_colourspace: str | None, corrected: bool,
                request: MeasureRequest | None, evidence_paths: tuple[Path, ...],
                cube_output: str | None, accept: bool, properties: bool) -> None:
    names = ("correction.cube", "correction.ocio", "correction.json", "report.json",
             "report.html", "corrected.toml", "sim_render.png", "sim_render.exr")
    check_outputs({**{n: out / n for n in names}, **evidence_outputs(evidence_paths)},
                  {"--camera": camera, "REAL": real, "--table": judge.table_input,
                   "--reference": reference, "--illuminant": illuminant})
    report, toml = fit_camera_and_verify(
        camera, real, out, model=model, objective=objective, real_corners=real_corners,
        normalise_mode=normalise_mode, reference=reference, illuminant=illuminant,
        judge=judge, read=read, real_ocio_colourspace=real_ocio_colourspace,
        corrected=corrected, measure=request, cube_output=cube_output, properties=properties)
    write_fit_report(report, json_path=out / "report.json", html_path=out / "report.html",
                     protect=(camera, real))
    for line in fit_lines(report):
        click.echo(line)
    click.echo(f"corrected camera: {display_path(toml)} (fidelity check {display_path(toml)})")
    code = _warn(report.warnings, accept)
    _evidence(evidence_paths, report, [*(out / n for n in names), Path(toml)], code)
    sys.exit(code)
