"""The camera check: chart → camera model → render → measure → predict → verdict → report.

Three jobs, each one function that returns typed records (:mod:`fidelity.report.chart`); the
command line only parses options, calls one of them and prints:

- :func:`check_camera`: render a camera model's spectral chart (closed form or Mitsuba 3,
  :mod:`fidelity.camera.render`), measure ΔE00, predict the detection loss
  (:mod:`fidelity.prediction.table`) and apply a criterion (:mod:`fidelity.prediction.verdict`);
- :func:`audit_image`: the same for a chart in any render or photo (EXR, HDR, TIFF, PNG, JPEG;
  found or given by its corners, :mod:`fidelity.chart.measure`);
- :func:`gate`: :func:`audit_image` over several images (or :func:`check_camera` for one
  camera) for CI, each gated, reported and turned into a JUnit case; an input error of one
  image becomes that case's error, not the end of the run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E, Criterion
from fidelity.report.chart import (
    ChartReport,
    ImageSource,
    Provenance,
    RenderSource,
    utc_now,
)

if TYPE_CHECKING:
    from fidelity.camera.model import CameraModel
    from fidelity.prediction.table import Prediction, PredictionTable
    from fidelity.prediction.verdict import Verdict
    from fidelity.report.junit import GateCase

#: The gate of ``fidelity check`` unless told otherwise: mean ΔE00 <= 3 (SAFE-COLOR).
DEFAULT_CRITERION = Criterion("max-delta-e", DEFAULT_MAX_DELTA_E)

#: How ``audit`` locates the patches, in words for the report's conventions.
AUDIT_CONVENTION = ("patches located by the homography of the 4x6 grid from the corner patch "
                    "centres; central window of {window:g} pitch; mean in linear light; "
                    "exposure on the neutral patches (EV) unless fixed; sRGB encoded and "
                    "clipped to [0, 1]")


def _predict_and_judge(mean_delta_e: float, size: str, table: PredictionTable | str | None,
                       criterion: Criterion | None) -> tuple[Prediction, Verdict | None]:
    from fidelity.prediction.table import predict
    from fidelity.prediction.verdict import evaluate

    prediction = predict(mean_delta_e, size=size, table=table)
    verdict = evaluate(mean_delta_e, prediction, criterion) if criterion else None
    return prediction, verdict


def check_camera(
    camera: CameraModel | str | None = None,
    *,
    illuminant: str = "D65",
    renderer: str = "closed-form",
    reference: str = "scene",
    size: str = "any",
    table: PredictionTable | str | None = None,
    criterion: Criterion | None = DEFAULT_CRITERION,
    seed: int | None = None,
    command: str = "check",
) -> ChartReport:
    """Render ``camera``'s chart, measure it, predict its detection loss, apply ``criterion``.

    Parameters
    ----------
    camera
        A built-in camera name, a camera file (TOML or YAML) or a
        :class:`~fidelity.camera.model.CameraModel`; None is the built-in default
        (:data:`fidelity.camera.model.DEFAULT_CAMERA`).
    illuminant
        The scene illuminant (a name such as ``D65``, ``A``, ``F11`` or an SPD CSV file).
    renderer
        ``closed-form`` (exact) or ``mitsuba`` (spectral path tracer).
    reference
        ``scene`` (the chart's spectra under the illuminant, adapted to D65) or ``safecolor``
        (the paper's Lab table).
    size, table
        The detector size class (``n`` ... ``x``, ``any``) and prediction table (name, path or
        table; None: the default table).
    criterion
        The gate (default: mean ΔE00 <= 3, SAFE-COLOR's threshold); None: no verdict.
    seed
        Seed of the camera noise (default: the camera file's).

    Returns
    -------
    ChartReport
        ``mean_delta_e`` (ΔE00, >= 0), the per-patch measurement, ``prediction`` (ΔmAP in
        percentage points and % of baseline, class ΔAP) and ``verdict``.

    Examples
    --------
    >>> report = check_camera("nikon-5100")          # doctest: +SKIP
    >>> round(report.mean_delta_e, 2), report.verdict.passed  # doctest: +SKIP
    (1.02, True)
    """
    from fidelity.camera.model import DEFAULT_CAMERA
    from fidelity.camera.render import render_chart

    render = render_chart(camera if camera is not None else DEFAULT_CAMERA, illuminant,
                          renderer, reference=reference, seed=seed)
    m = render.measurement
    prediction, verdict = _predict_and_judge(m.mean_delta_e, size, table, criterion)
    rd = render.to_json()
    source = RenderSource(camera=render.camera.name, illuminant=illuminant,
                          renderer=render.renderer, variant=render.variant,
                          seconds=render.seconds, reference=reference,
                          camera_settings=rd["camera"], render_settings=rd["settings"])
    return ChartReport(
        command=command, created=utc_now(), measurement=m, source=source,
        provenance=Provenance.collect(None, prediction,
                                      {"render": rd.get("conventions", {})}),
        prediction=prediction, verdict=verdict,
    )


def audit_image(
    image: str | os.PathLike[str],
    corners: str | Sequence[float] | np.ndarray | None = None,
    *,
    layer: str | None = None,
    encoding: str | None = None,
    exposure: float | str | None = None,
    reference: str = "scene",
    illuminant: str = "D65",
    size: str = "any",
    table: PredictionTable | str | None = None,
    criterion: Criterion | None = None,
    negatives: str = "keep",
    colourspace: str | None = None,
    command: str = "audit",
    bayer: str | None = None,
    max_pixels: int | None = None,
) -> ChartReport:
    """Measure the chart in ``image``, predict the detection loss, apply ``criterion``.

    Parameters
    ----------
    image
        An EXR, HDR, TIFF, PNG or JPEG file with a 24-patch ColorChecker in it.
    corners
        Image centres (x, y) of the dark skin, bluish green, black and white patches, as
        ``"X1,Y1,...,X4,Y4"`` or (4, 2); None: the chart is found
        (:func:`fidelity.chart.find.find_chart`).
    layer, encoding, exposure, negatives, colourspace
        How to read the pixels (see :func:`fidelity.chart.measure.measure_image`): EXR layer,
        ``linear``/``srgb`` (default from the file), ``auto`` or a fixed EV, what to do with
        negative values, the RGB primaries.
    bayer
        CFA pattern of a one-channel camera raw mosaic (``RGGB``, ``BGGR``, ``GRBG``,
        ``GBRG``): demosaiced before measuring (:func:`fidelity.chart.image.read_image`).
    reference, illuminant
        ``scene`` (the chart's spectra under ``illuminant``, adapted to D65, as
        :func:`check_camera` uses), ``safecolor`` (the paper's Lab values) or a chart JSON.
    size, table, criterion
        As for :func:`check_camera`; ``criterion`` None: no verdict.
    max_pixels
        Refuse a larger image (width x height) before decoding it (default:
        :func:`fidelity.chart.image.pixel_limit`).

    Returns
    -------
    ChartReport
        With ``exposure_ev``, ``bad_pixels`` and the image source (corners, how they were
        found, where each patch was sampled).
    """
    from fidelity.chart.measure import measure_image

    result = measure_image(image, corners if corners is None or len(corners) else None,
                           layer=layer, encoding=encoding, exposure=exposure,
                           reference=reference, illuminant=illuminant, negatives=negatives,
                           colourspace=colourspace, bayer=bayer, max_pixels=max_pixels)
    prediction, verdict = _predict_and_judge(result.mean_delta_e, size, table, criterion)
    info = result.image
    assert info is not None  # measure_image always describes the file
    source = ImageSource(
        image=info, corners=result.location.corners, location=result.location,
        colourspace=result.colourspace, exposure_mode=result.exposure_mode,
        reference=result.reference.name, encoding=result.encoding,
        clipped_patches=result.clipped_patches, found=result.detection,
        corner_checks=result.corner_checks)
    conventions = {"reference": result.reference.conventions,
                   "audit": AUDIT_CONVENTION.format(window=result.location.window)}
    return ChartReport(
        command=command, created=utc_now(), measurement=result.measurement, source=source,
        provenance=Provenance.collect(info.sha256, prediction,
                                      conventions),
        prediction=prediction, verdict=verdict,
        exposure_ev=result.exposure_ev, bad_pixels=result.bad_pixels,
        valid_pixels=result.valid_pixels,
    )


@dataclass(frozen=True)
class GateOutputs:
    """Where one gated subject's reports go (None: not written)."""

    json_path: Path | None = None
    html_path: Path | None = None


def gate(
    criterion: Criterion,
    images: Sequence[str | os.PathLike[str]] = (),
    *,
    camera: str | None = None,
    outputs: Sequence[GateOutputs] | None = None,
    corners: str | None = None,
    layer: str | None = None,
    encoding: str | None = None,
    exposure: str | None = None,
    negatives: str = "keep",
    colourspace: str | None = None,
    bayer: str | None = None,
    reference: str | None = None,
    illuminant: str = "D65",
    renderer: str = "closed-form",
    size: str = "any",
    table: str | None = None,
    max_pixels: int | None = None,
) -> list[GateCase]:
    """Gate ``images`` one by one (or ``camera``) against ``criterion``; write each one's
    reports to its :class:`GateOutputs`. An input error of one subject (exit code 2) becomes
    its case's ``error``; the others are still measured.

    ``reference`` defaults to ``scene``. Returns one
    :class:`~fidelity.report.junit.GateCase` per subject (its report, or its error, and the
    time it took); :func:`fidelity.report.junit.gate_exit_code` turns them into the exit code.
    """
    from fidelity.errors import FidelityError
    from fidelity.report.chart import write_chart_report
    from fidelity.report.junit import GateCase

    subjects: list[str] = [os.fspath(i) for i in images] or ([camera] if camera else [])
    outs = list(outputs) if outputs is not None else [GateOutputs()] * len(subjects)
    cases: list[GateCase] = []
    for subject, out in zip(subjects, outs, strict=True):
        t0 = time.perf_counter()
        try:
            if images:
                report = audit_image(subject, corners, layer=layer, encoding=encoding,
                                     exposure=exposure, reference=reference or "scene",
                                     illuminant=illuminant, size=size, table=table,
                                     criterion=criterion, negatives=negatives,
                                     colourspace=colourspace, command="gate", bayer=bayer,
                                     max_pixels=max_pixels)
            else:
                report = check_camera(subject, illuminant=illuminant, renderer=renderer,
                                      reference=reference or "scene", size=size, table=table,
                                      criterion=criterion, command="gate")
            write_chart_report(report, json_path=out.json_path, html_path=out.html_path,
                               protect=[os.fspath(i) for i in images])
        except (FidelityError, OSError) as exc:
            cases.append(GateCase(subject, criterion, error=str(exc),
                                  seconds=time.perf_counter() - t0))
        else:
            cases.append(GateCase(subject, criterion, report=report,
                                  seconds=time.perf_counter() - t0))
    return cases


__all__ = ["AUDIT_CONVENTION", "DEFAULT_CRITERION", "GateOutputs", "audit_image", "check_camera", "gate"]
