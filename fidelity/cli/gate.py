"""``fidelity gate``: pass/fail for CI on an image's chart or a camera model's render.

Exit codes: 0 pass, 1 fail, 2 error (one line on stderr, no traceback; with ``--junit`` the
error is also written as a JUnit ``<error>``). The helpers here (measuring an image or a camera
into a report) are shared by ``fidelity audit`` and ``fidelity check``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import click

from fidelity.errors import FidelityError
from fidelity.prediction.table import CLASS_COLUMNS, SIZES, Prediction, predict
from fidelity.prediction.verdict import EXIT_ERROR, Criterion, Verdict, evaluate

PATH = click.Path(dir_okay=False, path_type=Path)


#: Image options shared by ``audit`` and ``gate``.
colourspace_option = click.option(
    "--colourspace", default=None,
    help="RGB primaries of the pixels: a colour-science name (ACEScg, 'ITU-R BT.2020', "
         "'Display P3', ...). Default: the EXR's chromaticities attribute, else sRGB.")
negatives_option = click.option(
    "--negatives", type=click.Choice(["keep", "exclude"]), default="keep", show_default=True,
    help="Pixels with a negative channel: keep them in the linear mean (out-of-gamut colours in "
         "a scene-linear render) or exclude them like NaN/Inf.")


def image_report(
    image: Path, corners: str | None, *, command: str, encoding: str | None, exposure: str | None,
    layer: str | None, reference: str, illuminant: str, size: str, table: str | None,
    criterion: Criterion | None = None, location_figure: bool = False,
    negatives: str = "keep", colourspace: str | None = None,
) -> tuple[dict[str, Any], Prediction, Verdict | None, str | None]:
    """Audit ``image`` and build its report (measurement, prediction, optional verdict), and
    with ``location_figure`` the base64 PNG of where the patches were sampled (for HTML).

    ``corners`` ``None`` (or empty): the chart is found in the image
    (:func:`fidelity.chart.find.find_chart`); the corners it found go into the report."""
    from fidelity.chart.measure import measure_image
    from fidelity.report.chart import build_report

    result = measure_image(image, corners or None, layer=layer, encoding=encoding, exposure=exposure,
                         reference=reference, illuminant=illuminant, negatives=negatives,
                         colourspace=colourspace)
    prediction = predict(result.mean_delta_e, size=size, table=table)
    verdict = evaluate(result.mean_delta_e, prediction, criterion) if criterion else None
    info = dict(result.image or {})
    source = {"type": "image", **info, "corners": result.location.corners.tolist(),
              "corners_found": result.detection.to_dict() if result.detection else None,
              "colourspace": result.colourspace,
              "exposure_mode": result.exposure_mode, "reference": result.reference.name}
    report = build_report(
        command, result.measurement, source=source, prediction=prediction, verdict=verdict,
        exposure_ev=result.exposure_ev, bad_pixels=result.bad_pixels,
        patch_extras=[{"valid_pixels": int(n),
                       "bad_pixels": int(result.bad_pixels["per_patch"].get(name, 0))}
                      for name, n in zip(result.reference.patch_names, result.valid_pixels,
                                         strict=True)],
        conventions={"reference": result.reference.conventions,
                     "audit": "patches located by the homography of the 4x6 grid from the corner "
                              "patch centres; central window of "
                              f"{result.location.window:g} pitch; mean in linear light; "
                              "exposure on the neutral patches (EV) unless fixed; sRGB encoded "
                              "and clipped to [0, 1]"},
        details={"location": result.location.to_dict(),
                 "clipped_patches": list(result.clipped_patches),
                 "encoding": result.encoding},
    )
    figure = None
    if location_figure:
        from fidelity.chart.image import read_image
        from fidelity.report.chart import plot_chart_location

        figure = plot_chart_location(read_image(image, layer=layer).pixels, result.location,
                                     encoding=result.encoding, exposure_ev=result.exposure_ev,
                                     found=result.detection is not None)
    return report, prediction, verdict, figure


def camera_report(
    camera: str, *, command: str, illuminant: str, renderer: str, reference: str, size: str,
    table: str | None, criterion: Criterion | None = None, seed: int | None = None,
) -> tuple[dict[str, Any], Prediction, Verdict | None]:
    """Render ``camera``'s chart (:func:`fidelity.camera.render.render_chart`) and build its report."""
    from fidelity.camera.render import render_chart
    from fidelity.report.chart import build_report

    render = render_chart(camera, illuminant, renderer, reference=reference, seed=seed)
    m = render.measurement
    prediction = predict(m.mean_delta_e, size=size, table=table)
    verdict = evaluate(m.mean_delta_e, prediction, criterion) if criterion else None
    rd = render.to_dict()
    source = {"type": "render", "camera": getattr(render.camera, "name", str(camera)),
              "illuminant": illuminant, "renderer": render.renderer, "variant": render.variant,
              "seconds": render.seconds, "reference": reference}
    report = build_report(
        command, m, source=source, prediction=prediction, verdict=verdict,
        conventions={"render": rd.get("conventions", {})},
        details={"camera": rd.get("camera"), "settings": rd.get("settings")},
    )
    return report, prediction, verdict


def write_outputs(report: dict[str, Any], prediction: Prediction, *, json_path: Path | None,
                  html_path: Path | None, protect: tuple[str, ...] = (),
                  location_png: str | None = None) -> list[Path]:
    """Write the JSON and HTML reports that were asked for; return their paths."""
    from fidelity.report.chart import write_html_report, write_json_report

    written = []
    if json_path is not None:
        written.append(write_json_report(json_path, report, protect=protect))
    if html_path is not None:
        written.append(write_html_report(html_path, report, prediction, protect=protect,
                                         location_png=location_png))
    return written


def make_criterion(max_delta_e: float | None, max_dmap: float | None, cls: str | None,
                   unit: str) -> Criterion:
    """The gate's criterion from its options (exactly one of the two limits)."""
    if (max_delta_e is None) == (max_dmap is None):
        raise click.UsageError("give exactly one of --max-delta-e X or --max-dmap P")
    if max_delta_e is not None:
        if cls is not None:
            raise click.UsageError("--class goes with --max-dmap, not --max-delta-e")
        return Criterion("max-delta-e", float(max_delta_e))
    return Criterion("max-dmap", float(max_dmap), cls or "all", unit)  # type: ignore[arg-type]


def _error_line(message: str) -> None:
    click.echo(f"fidelity: error: {message}", err=True)


def _write_junit(junit: Path, cases: list[Any]) -> None:
    """Write the JUnit file; a failure to write it is an error (exit 2)."""
    from fidelity.report.chart import write_junit

    try:
        write_junit(junit, cases)
    except (FidelityError, OSError) as exc:
        _error_line(f"{junit}: cannot write JUnit XML: {exc}")
        sys.exit(EXIT_ERROR)


def report_paths(images: tuple[Path, ...], path: Path | None, suffix: str, *,
                 folder: bool = False) -> list[Path | None]:
    """Where each image's report goes: ``path`` itself, or, when ``path`` is a folder
    (``folder``, or an existing directory), the image's file name + ``suffix`` in it."""
    if path is None:
        return [None] * len(images)
    if not (folder or path.is_dir()):
        return [path] * len(images)
    names = [img.name for img in images]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FidelityError(f"several images are named {', '.join(twice)}: their reports in "
                            f"{path} would collide; gate them in separate runs")
    return [path / f"{n}{suffix}" for n in names]


@click.command()
@click.argument("images", nargs=-1, type=PATH)
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
@click.option("--encoding", type=click.Choice(["linear", "srgb"]), default=None,
              help="Image pixel encoding (default: linear for float formats, else sRGB).")
@click.option("--exposure", default=None, help="Image exposure: auto or a fixed EV.")
@click.option("--layer", default=None, help="EXR layer or part name.")
@colourspace_option
@negatives_option
@click.option("--reference", default=None,
              help="Reference: safecolor (image default) or scene (camera default).")
@click.option("--illuminant", default="D65", show_default=True, help="Scene illuminant.")
@click.option("--renderer", default="closed-form", show_default=True,
              help="Camera renderer: closed-form or mitsuba.")
@click.option("--junit", type=PATH, help="Write JUnit XML (one test case per image or camera).")
@click.option("--json", "json_path", type=click.Path(path_type=Path),
              help="Write the JSON report (several images: a folder, one report per image).")
@click.option("--html", "html_path", type=click.Path(path_type=Path),
              help="Write the HTML report (several images: a folder, one report per image).")
def gate(images: tuple[Path, ...], corners: str | None, camera: str | None,
         max_delta_e: float | None, max_dmap: float | None, cls: str | None, unit: str,
         size: str, table: str | None, encoding: str | None, exposure: str | None,
         layer: str | None, colourspace: str | None, negatives: str, reference: str | None,
         illuminant: str, renderer: str, junit: Path | None, json_path: Path | None,
         html_path: Path | None) -> None:
    """Gate a camera's colour fidelity: exit 0 pass, 1 fail, 2 error.

    \b
    fidelity gate render.exr --max-delta-e 3
    fidelity gate photo.jpg --corners 102,88,610,95,604,420,98,414 --max-delta-e 3
    fidelity gate --camera nikon-5100 --max-dmap 1 --class person --junit colour.xml
    fidelity gate day.exr dusk.exr tunnel.exr --max-delta-e 3 --junit colour.xml

    Several IMAGEs are gated one by one (one JUnit test case each; --json and --html name
    folders that get IMAGE-NAME.json / .html, as an existing folder does for one image); the
    exit code is 2 if any image could not be measured, else 1 if any failed, else 0.
    """
    if images and camera is not None:
        raise click.UsageError("give IMAGE(s) or --camera, not both")
    if not images and camera is None:
        raise click.UsageError("give one or more IMAGEs, or --camera")
    if camera is not None and any(v is not None for v in (corners, encoding, exposure, layer,
                                                          colourspace)):
        raise click.UsageError("--corners, --encoding, --exposure, --layer and --colourspace "
                               "apply to an IMAGE, not to --camera")
    many = len(images) > 1
    try:
        from fidelity.fileio import check_outputs

        # a folder (always so with several images) gets one report per image (or camera)
        subjects = images or (Path(camera or ""),)
        json_paths = report_paths(subjects, json_path, ".json", folder=many)
        html_paths = report_paths(subjects, html_path, ".html", folder=many)
        outputs: dict[str, Path | None] = {"--junit": junit}
        for img, jp, hp in zip(subjects, json_paths, html_paths, strict=True):
            outputs[f"--json ({img})" if many else "--json"] = jp
            outputs[f"--html ({img})" if many else "--html"] = hp
        check_outputs(outputs, {"--camera": camera, "--table": table, "--reference": reference,
                                "--illuminant": illuminant}
                      | {(f"IMAGE {img}" if many else "IMAGE"): img for img in images})
    except FidelityError as exc:  # no JUnit file either: it may be the input named
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)

    from fidelity.report.chart import GateCase

    try:
        criterion = make_criterion(max_delta_e, max_dmap, cls, unit)
    except FidelityError as exc:
        if junit is not None:
            subject = ", ".join(map(str, images)) if images else camera
            _write_junit(junit, [GateCase(f"colour fidelity of {subject}", error=str(exc))])
        _error_line(str(exc))
        sys.exit(EXIT_ERROR)
    image_options = dict(corners=corners, command="gate", encoding=encoding, exposure=exposure,
                         layer=layer, reference=reference or "safecolor",
                         illuminant=illuminant, size=size, table=table, criterion=criterion,
                         negatives=negatives, colourspace=colourspace)

    def measure(subject: Path, jp: Path | None, hp: Path | None) -> tuple[GateCase, int]:
        """Gate one image (or the camera); its outputs written; errors become the case's."""
        name = f"colour fidelity of {subject if images else camera}: {criterion.describe()}"
        t0 = time.perf_counter()
        try:
            if images:
                report, prediction, verdict, figure = image_report(
                    subject, location_figure=hp is not None, **image_options)
            else:
                report, prediction, verdict = camera_report(
                    camera or "", command="gate", illuminant=illuminant, renderer=renderer,
                    reference=reference or "scene", size=size, table=table,
                    criterion=criterion)
                figure = None
            assert verdict is not None
            write_outputs(report, prediction, json_path=jp, html_path=hp,
                          protect=tuple(map(str, images)), location_png=figure)
        except FidelityError as exc:
            message = str(exc)
        except Exception as exc:  # noqa: BLE001 - a gate must answer 2, never a traceback
            message = f"unexpected {type(exc).__name__}: {exc}".replace("\n", " ")
        else:
            return GateCase(name, report=report, seconds=time.perf_counter() - t0), \
                verdict.exit_code
        return GateCase(name, error=message, seconds=time.perf_counter() - t0), EXIT_ERROR

    cases: list[GateCase] = []
    codes: list[int] = []
    for subject, jp, hp in zip(subjects, json_paths, html_paths, strict=True):
        case, code = measure(subject, jp, hp)
        cases.append(case)
        codes.append(code)
        if many:
            click.echo(f"{subject}:" if case.error is None else f"{subject}: error")
        if case.error is not None:
            _error_line(case.error)
            continue
        assert case.report is not None
        for line in _short(case.report):
            click.echo(("  " if many else "") + line)
    if junit is not None:
        _write_junit(junit, cases)
    if many:
        failed = sum(c == 1 for c in codes)
        errors = sum(c == EXIT_ERROR for c in codes)
        click.echo(f"gate: {codes.count(0)} of {len(codes)} passed, {failed} failed, "
                   f"{errors} could not be measured")
    sys.exit(EXIT_ERROR if EXIT_ERROR in codes else max(codes))


def _short(report: dict[str, Any]) -> list[str]:
    from fidelity.report.chart import summary_lines

    return summary_lines(report)
