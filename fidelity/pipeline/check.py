"""The camera check: chart → camera model → render → measure → predict → verdict → report.

Three jobs, each one function that returns typed records (:mod:`fidelity.pipeline.records`); the
command line only parses options, calls one of them and prints (:mod:`fidelity.report` renders
the records):

- :func:`check_camera`: render a camera model's spectral chart (closed form or Mitsuba 3,
  :mod:`fidelity.camera.render`), measure ΔE00, predict the detection loss
  (:mod:`fidelity.prediction.table`) and apply a criterion (:mod:`fidelity.prediction.verdict`);
- :func:`audit_image`: the same for a chart in any render or photo (EXR, HDR, TIFF, PNG, JPEG;
  found or given by its corners, :mod:`fidelity.measure.pixels`);
- :func:`gate`: :func:`audit_image` over several images (or :func:`check_camera` for one
  camera) for CI, each gated into a :class:`~fidelity.pipeline.records.GateResult`; an input error of
  one image becomes that result's error, not the end of the run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.camera.model import DEFAULT_CAMERA, camera_file
from fidelity.camera.render import FRAME_SCALE, frame_properties, render_chart
from fidelity.chart.read import DEFAULT_READ, ReadOptions, reads_for
from fidelity.coco.detectors import stale_preprocessing
from fidelity.colour.charts import SCENE_REFERENCE, load_reference
from fidelity.colour.colorimetry import (
    delta_e_2000,
    lab_to_srgb,
    lab_to_xyz,
    linear_srgb_to_xyz,
    linearize_srgb,
    xyz_to_lab,
    xyz_to_linear_srgb,
)
from fidelity.colour.diagnosis import Diagnosis, diagnose
from fidelity.colour.spectral import load_illuminant
from fidelity.core.errors import FidelityError, InvalidValueError
from fidelity.core.fileio import file_sha256
from fidelity.measure.blindspots import banding, chart_blind_spots
from fidelity.measure.chartsharpness import EdgeTargetCorners
from fidelity.measure.colour import measure_chart, neutral_patches
from fidelity.measure.pixels import measure_image
from fidelity.measure.uncertainty import ADAPTATION_SPREAD, adaptation_component
from fidelity.pipeline.records import (
    ChartReport,
    GateResult,
    ImageSource,
    Provenance,
    RenderSource,
    start_platform_lookup,
    utc_now,
)
from fidelity.prediction.exposure import judge_exposure
from fidelity.prediction.interval import (
    DomainCheck,
    load_validated_cameras,
    prediction_interval,
    validity_domain,
)
from fidelity.prediction.judge import DEFAULT_JUDGE, JudgeOptions, judge_chart
from fidelity.prediction.properties import detector_scale
from fidelity.prediction.tablefile import COLUMNS
from fidelity.prediction.validated import validated_upper
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E, Criterion

if TYPE_CHECKING:
    from fidelity.camera.model import CameraModel
    from fidelity.chart.find.result import FoundChart
    from fidelity.coco.measure import MeasuredLoss, MeasureRequest
    from fidelity.measure.colour import ChartMeasurement
    from fidelity.measure.pixels import ImageMeasurement
    from fidelity.measure.uncertainty import UncertaintyBudget
    from fidelity.prediction.interval import DomainCheck, PredictionInterval, ValidityDomain
    from fidelity.prediction.table import Prediction
    from fidelity.prediction.tablefile import PredictionTable

#: The gate of ``fidelity check`` unless told otherwise: mean ΔE00 <= 3 (SAFE-COLOR).
DEFAULT_CRITERION = Criterion("max-delta-e", DEFAULT_MAX_DELTA_E)

#: How ``audit`` locates the patches, in words for the report's conventions.
AUDIT_CONVENTION = ("patches located by the homography of the 4x6 grid from the corner patch "
                    "centres; central window of {window:g} pitch; mean in linear light; "
                    "exposure on the neutral patches (EV) unless fixed; sRGB encoded and "
                    "clipped to [0, 1]")


#: The reference charts the prediction tables were calibrated for: the 24-patch ColorChecker
#: as the scene renders it, or the paper's Lab values of the same chart.
TABLE_REFERENCES = ("scene", "safecolor")


def prediction_domain(prediction: Prediction, *checks: DomainCheck) -> ValidityDomain:
    """The validity domain of ``prediction``'s answer: its table's checks
    (:func:`fidelity.prediction.interval.validity_domain`), then ``checks``, then the
    detector preprocessing of a measured table (:func:`preprocessing_check`)."""
    domain = validity_domain(prediction)
    preprocessing = preprocessing_check(prediction.table)
    for check in (*checks, *([preprocessing] if preprocessing is not None else [])):
        domain = domain.with_check(check)
    return domain


def preprocessing_check(table: PredictionTable) -> DomainCheck | None:
    """Whether a measured ``table``'s detectors were run with this version's detector
    preprocessing (:func:`fidelity.coco.detectors.stale_preprocessing` of its provenance);
    None for a table of published bounds."""
    if not table.kind.measured:
        return None
    stale = stale_preprocessing(table.provenance)
    return DomainCheck(
        "detector preprocessing", not stale,
        f"table {table.name}: every detector measured with this version's preprocessing"
        if not stale else
        f"table {table.name}: {', '.join(sorted(stale))} measured with a detector "
        f"preprocessing other than this version's (the table predates it; rerun the "
        f"sweep and fidelity tables)")


def evidence_of(prediction: Prediction | None, budget: UncertaintyBudget | None,
                reference: str, k: float = 2.0,
                camera: tuple[Mapping[str, str], str,
                              Mapping[str, tuple[str, Mapping[str, float]]]] | None = None
                ) -> tuple[PredictionInterval | None, ValidityDomain | None]:
    """The predicted ΔmAP's interval (with the chart ΔE's uncertainty ``budget``) and the
    validity domain of the answer (the prediction's checks, the ``reference`` chart and, for
    a camera model, ``camera``: its stage kinds, illuminant and degradations (noise, optics,
    vignetting) against the cameras the prediction was validated on, :meth:`~fidelity.prediction.interval.ValidatedCameras.
    camera_checks`)."""
    if prediction is None:
        return None, None

    interval = prediction_interval(prediction, budget.combined if budget else 0.0,
                                   "dmap_points", k)
    upper = validated_upper(prediction, "dmap_points")
    if interval is not None and upper is not None:
        interval = replace(interval, validated_upper=upper[0], validated_method=upper[1].words())
    inside = reference in TABLE_REFERENCES
    domain = prediction_domain(prediction, DomainCheck(
        "reference chart", inside,
        f"reference {reference}: the 24-patch ColorChecker the tables were calibrated on"
        if inside else f"reference {reference}: not the 24-patch ColorChecker the tables "
                       f"were calibrated on; the prediction does not apply to its ΔE"))
    if camera is not None:
        validated = load_validated_cameras()
        if validated is not None:
            for check in validated.camera_checks(*camera):
                domain = domain.with_check(check)
    return interval, domain


def with_adaptation(budget: UncertaintyBudget, measurement: ChartMeasurement,
                    illuminant: str, cat: str) -> UncertaintyBudget:
    """``budget`` with the type-B ``chromatic adaptation`` component of a chart measured
    against the scene reference under ``illuminant`` (not D65): the chart's mean ΔE00 (its
    measured sRGB, the same patches left out) against the reference adapted by each
    transform of :data:`fidelity.measure.uncertainty.ADAPTATION_SPREAD`
    (:func:`fidelity.measure.uncertainty.adaptation_component`; ``cat`` the one used)."""
    by_cat = {c: measure_chart(measurement.srgb, load_reference(SCENE_REFERENCE, illuminant,
                                                                c).lab,
                               measurement.patch_names, excluded=measurement.excluded or None
                               ).mean_delta_e
              for c in ADAPTATION_SPREAD}
    return replace(budget, components=(*budget.components, adaptation_component(by_cat, cat)))


def column_intervals(prediction: Prediction | None, budget: UncertaintyBudget | None,
                     k: float = 2.0) -> tuple[PredictionInterval, ...]:
    """Every loss column of ``prediction`` with its own standard uncertainty
    (:func:`fidelity.prediction.interval.prediction_interval`: that column's table SE and the
    chart ΔE's uncertainty ``budget`` through that column's slope), in
    :data:`fidelity.prediction.tablefile.COLUMNS` order; the columns without a value left
    out; empty without a prediction."""
    if prediction is None:
        return ()
    u = budget.combined if budget else 0.0
    found = (prediction_interval(prediction, u, column, k) for column in COLUMNS)
    return tuple(i for i in found if i is not None)


def _measure(request: MeasureRequest | None, mapping: Any, key: str,
             description: dict[str, Any]) -> tuple[MeasuredLoss, ...]:
    """Run a measurement request on a fitted mapping (nothing without a request)."""
    if request is None:
        return ()
    return tuple(request.run(mapping, key, description))


def check_camera(
    camera: CameraModel | str | None = None,
    *,
    illuminant: str = "D65",
    renderer: str = "closed-form",
    reference: str = "scene",
    criterion: Criterion | None = DEFAULT_CRITERION,
    judge: JudgeOptions = DEFAULT_JUDGE,
    seed: int | None = None,
    command: str = "check",
    measure: MeasureRequest | None = None,
    cat: str = "Bradford",
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
    criterion
        The gate (default: mean ΔE00 <= 3, SAFE-COLOR's threshold); None: no verdict.
    judge
        How to judge (:class:`~fidelity.prediction.judge.JudgeOptions`): the detector size
        class (``n`` ... ``x``, ``any``), the prediction table (name, path or table; None: the
        default), which prediction decides a ``max-dmap`` verdict (``classic``, the table's
        worst case over every transform, or ``directional``,
        :mod:`fidelity.prediction.directional`; the report holds both) and the decision rule
        (:class:`~fidelity.prediction.verdict.DecisionRule`; guarded: with the chart ΔE's
        uncertainty, :mod:`fidelity.measure.uncertainty`).
    seed
        Seed of the camera noise (default: the camera file's).
    command
        The command named in the report (``check``, ``gate``).
    measure
        Also measure the camera's loss on COCO (:class:`fidelity.coco.measure.MeasureRequest`:
        the camera's colour rendering emulated on the images, as ``fidelity validate`` does).
    cat
        The chromatic adaptation of the ``scene`` reference to D65 (one of
        :data:`fidelity.colour.colorimetry.CHROMATIC_ADAPTATION_METHODS`); under an
        illuminant other than D65 the spread of the chart ΔE over the transforms enters its
        uncertainty budget as the type-B ``chromatic adaptation`` component
        (:func:`fidelity.measure.uncertainty.adaptation_component`).

    Returns
    -------
    ChartReport
        ``mean_delta_e`` (ΔE00, >= 0), the per-patch measurement, ``prediction`` (ΔmAP in
        percentage points and % of baseline, class ΔAP) and ``verdict``.

    Raises
    ------
    UnknownNameError
        An unknown camera, illuminant, renderer, reference, table or size class. Exit code 2.
    InputFileError
        A camera, illuminant or table file that is missing or invalid. Exit code 2.
    InvalidValueError
        A camera whose stages give non-finite values, a seed out of range, or a ``max-dmap``
        criterion without a prediction. Exit code 2.

    Examples
    --------
    >>> report = check_camera("nikon-5100")          # doctest: +SKIP
    >>> round(report.mean_delta_e, 2), report.verdict.passed  # doctest: +SKIP
    (1.02, True)
    """
    start_platform_lookup()  # the report's provenance, found while the chart is measured
    render = render_chart(camera if camera is not None else DEFAULT_CAMERA, illuminant,
                          renderer, reference=reference, seed=seed, frame=True, cat=cat)
    m = render.measurement
    u = render.uncertainty
    sharpness, noise = frame_properties(render.frame, reference, illuminant)
    prediction, verdict, directional, judged = judge_chart(
        m.mean_delta_e, judge, criterion, m, delta_e_uncertainty=u.combined if u else None,
        properties=True, sharpness=sharpness, noise=noise, scale=FRAME_SCALE)
    interval, validity = evidence_of(prediction, u, reference, judge.decision.k,
                                     (render.camera.stage_kinds(), illuminant,
                                      render.camera.degradations()))

    spots = chart_blind_spots(m, bits=render.camera.quantisation_bits)
    measured: tuple[MeasuredLoss, ...] = ()
    if measure is not None:
        from fidelity.coco.emulation import emulation_key, fit_emulation  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        emu = fit_emulation(render.camera, illuminant)
        measured = _measure(measure, emu.apply_uint8, emulation_key(emu),
                            {"camera": render.camera.name, "illuminant": illuminant,
                             "emulation": emu.describe()})
    rd = render.to_json()
    source = RenderSource(camera=render.camera.name, illuminant=illuminant,
                          renderer=render.renderer, variant=render.variant,
                          seconds=render.seconds, reference=reference,
                          camera_settings=rd["camera"], render_settings=rd["settings"])
    return ChartReport(
        command=command, created=utc_now(), measurement=m, source=source,
        provenance=Provenance.collect(
            None if (cf := camera_file(render.camera)) is None else file_sha256(cf), prediction,
            {"render": rd.get("conventions", {})}),
        prediction=prediction, verdict=verdict, directional=directional, bound=judge.bound,
        blind_spots=spots, measured=measured, uncertainty=u, interval=interval,
        validity=validity, properties=judged, diagnosis=render_diagnosis(m),
        intervals=column_intervals(prediction, u, judge.decision.k),
        sharpness=sharpness, noise=noise,
    )


#: Largest ΔE00 between a flagged patch and its gamut-clipped reference for its distance from
#: the other patches to be the clipping (an sRGB render of a reference outside the gamut).
GAMUT_CLIPPED_DELTA_E = 1.0


def reference_linear(reference_lab: np.ndarray) -> np.ndarray:
    """The reference patches' linear sRGB ``(n, 3)`` (D65, white Y = 1), unclipped: a
    negative channel is a colour outside the sRGB gamut."""
    return np.asarray(xyz_to_linear_srgb(lab_to_xyz(np.asarray(reference_lab, np.float64))),
                      np.float64)


def render_diagnosis(measurement: ChartMeasurement) -> Diagnosis | None:
    """The likely cause of a camera render's chart error (:func:`fidelity.colour.diagnosis.
    diagnose` of its encoded, clipped sRGB decoded to linear: display-referred, exposure
    fixed at the reference's); None for a chart of fewer than 4 patches used."""
    try:
        return diagnose(linearize_srgb(measurement.srgb), reference_linear(
            measurement.reference_lab), exposure_fixed=True, display_referred=True,
            used=measurement.used, patch_names=measurement.patch_names)
    except InvalidValueError:
        return None


def image_diagnosis(result: ImageMeasurement) -> Diagnosis | None:
    """The likely cause of an audited image's chart error (:func:`fidelity.colour.diagnosis.
    diagnose`): its patches' linear means as read, before the exposure correction; a fixed
    exposure (``--exposure EV``) is the expected one (the image at ``-EV``), the automatic
    one a free parameter; an sRGB-encoded image display-referred. None without the linear
    means or with fewer than 4 patches used."""
    if result.linear_means is None:
        return None
    fixed = result.exposure_mode == "fixed"
    try:
        return diagnose(result.linear_means, reference_linear(result.reference.lab),
                        exposure_fixed=fixed, expected_ev=-result.exposure_ev if fixed else 0.0,
                        display_referred=result.encoding == "srgb",
                        used=result.measurement.used, patch_names=result.reference.patch_names,
                        applied_ev=result.exposure_ev)
    except InvalidValueError:
        return None


def gamut_clipped(result: ImageMeasurement) -> tuple[int, ...]:
    """The patches (0-based) whose reference lies outside the sRGB gamut and whose measured
    colour is that reference clipped into the gamut (within :data:`GAMUT_CLIPPED_DELTA_E`):
    what every sRGB render does, a known limit."""
    if result.linear_means is None:
        return ()
    ref = reference_linear(result.reference.lab)
    outside = np.flatnonzero(np.any(ref < -1e-6, axis=1))
    if not outside.size:
        return ()
    measured = result.linear_means[outside] * 2.0 ** result.exposure_ev
    clipped = np.clip(ref[outside], 0.0, None)
    de = np.asarray(delta_e_2000(xyz_to_lab(linear_srgb_to_xyz(measured)),
                                 xyz_to_lab(linear_srgb_to_xyz(clipped))), np.float64)
    return tuple(int(k) for k, d in zip(outside, de, strict=True)
                 if d <= GAMUT_CLIPPED_DELTA_E)


def explained_find(result: ImageMeasurement) -> FoundChart | None:
    """The chart finder's record of ``result`` with the patches far from the others' fit only
    because their reference is outside the sRGB gamut (:func:`gamut_clipped`) no longer
    flagged, but named in a note that says why."""
    found = result.detection
    if found is None or not found.flat_off_fit:
        return found
    explained = [k for k in gamut_clipped(result) if k in found.flat_off_fit]
    if not explained:
        return found
    names = ", ".join(f"{k + 1} ({result.reference.patch_names[k]})" for k in explained)
    return found.without_flat_off_fit(explained, (
        f"patch(es) {names} far from what the other patches predict only because the "
        f"reference lies outside the sRGB gamut and the image holds it clipped into the gamut, "
        f"as every sRGB render does: a known limit, not a fault"))


def audit_image(
    image: str | os.PathLike[str],
    corners: str | Sequence[float] | np.ndarray | None = None,
    *,
    read: ReadOptions = DEFAULT_READ,
    reference: str = "scene",
    illuminant: str = "D65",
    criterion: Criterion | None = None,
    judge: JudgeOptions = DEFAULT_JUDGE,
    command: str = "audit",
    measure: MeasureRequest | None = None,
    cat: str = "Bradford",
    edge_target: EdgeTargetCorners | None = None,
) -> ChartReport:
    """Measure the chart in ``image``, predict the detection loss, apply ``criterion``.

    Parameters
    ----------
    image
        An EXR, HDR, TIFF, PNG or JPEG file with a 24-patch ColorChecker in it.
    corners
        Image centres (x, y) of the dark skin, bluish green, black and white patches, as
        ``"X1,Y1,...,X4,Y4"`` or (4, 2); None: the chart is found
        (:func:`fidelity.chart.find.cascade.find_chart`).
    read
        How to read the pixels (:class:`~fidelity.chart.read.ReadOptions`): EXR layer,
        ``linear``/``srgb`` (default from the file), ``auto`` or a fixed EV, what to do with
        negative values, the RGB primaries, the Bayer pattern of a raw mosaic, the pixel
        limit.
    reference, illuminant
        ``scene`` (the chart's spectra under ``illuminant``, adapted to D65, as
        :func:`check_camera` uses), ``safecolor`` (the paper's Lab values) or a chart JSON.
    criterion, judge, command
        As for :func:`check_camera`; ``criterion`` None: no verdict.
    measure
        Also measure on COCO what this chart's colour rendering costs a detector: a mapping
        from the reference to the measured colours, fitted on the 24 patches
        (:class:`fidelity.coco.emulation.PatchEmulation`), applied to the images.
    cat
        The chromatic adaptation of the ``scene`` reference, as for :func:`check_camera`
        (under an illuminant other than D65 the spread over the transforms is a type-B
        component of the chart ΔE's uncertainty budget: :func:`with_adaptation`).
    edge_target
        A slanted-edge target's corners in the image (a scene manifest's,
        :func:`fidelity.scene.manifest.read_manifest`): the sharpness, and so the verdict's,
        is measured on its square's edges; None: on the chart's own edges.

    Returns
    -------
    ChartReport
        With ``exposure_ev``, ``bad_pixels`` and the image source (corners, how they were
        found, where each patch was sampled).

    Raises
    ------
    InputFileError
        A missing, unreadable or corrupt image or recording. Exit code 2.
    InvalidValueError
        No chart found, corners outside the image or degenerate, a patch with too few valid
        pixels, an exposure out of range; the message names the file. Exit code 2.
    UnknownNameError
        An unknown reference, illuminant, table, size class or read option (encoding,
        colourspace, Bayer pattern). Exit code 2.
    """
    from concurrent.futures import Future, ThreadPoolExecutor  # 6 ms, the audit's only

    scene = reference == SCENE_REFERENCE
    # the image's banding check runs in a thread while its chart is found and measured (both
    # spend their time in NumPy and OpenCV, which release the GIL): its result is the same
    with ThreadPoolExecutor(max_workers=1) as pool:
        checks: list[Future[Any]] = []
        result = measure_image(image, corners if corners is None or len(corners) else None,
                               read=read, reference=(load_reference(reference, illuminant, cat)
                                                     if scene else reference),
                               illuminant=illuminant,
                               inspect_image=lambda img: checks.append(
                                   pool.submit(_image_banding, img)),
                               edge_target=edge_target)
        banding = [check.result() for check in checks]
    u = result.uncertainty
    if scene and u is not None and load_illuminant(illuminant).name != "D65":
        u = with_adaptation(u, result.measurement, illuminant, cat)
    info = result.image
    assert info is not None  # measure_image always describes the file
    exposure = (judge_exposure(result.exposure_ev, result.neutral_ev,
                               judge.max_exposure_error, judge.exposure_source)
                if read.exposure is not None and result.exposure_mode == "fixed" else None)
    prediction, verdict, directional, judged = judge_chart(
        result.mean_delta_e, judge, criterion, result.measurement,
        delta_e_uncertainty=u.combined if u else None, properties=True,
        sharpness=result.sharpness, noise=result.noise,
        scale=detector_scale(info.width, info.height), exposure=exposure)
    interval, validity = evidence_of(prediction, u, reference, judge.decision.k)
    source = ImageSource(
        image=info, corners=result.location.corners, location=result.location,
        colourspace=result.colourspace, exposure_mode=result.exposure_mode,
        reference=result.reference.name, encoding=result.encoding,
        clipped_patches=result.clipped_patches, found=explained_find(result),
        corner_checks=result.corner_checks)
    conventions = {"reference": result.reference.conventions,
                   "audit": AUDIT_CONVENTION.format(window=result.location.window)}
    spots = (*_image_blind_spots(result.measurement, info, read), *banding)
    measured: tuple[MeasuredLoss, ...] = ()
    if measure is not None:
        emu = chart_emulation(result.measurement)
        measured = _measure(measure, emu.apply_uint8, emu.key(),
                            {"image": info.path, "sha256": info.sha256,
                             "emulation": emu.describe()})
    return ChartReport(
        command=command, created=utc_now(), measurement=result.measurement, source=source,
        provenance=Provenance.collect(info.sha256, prediction,
                                      conventions),
        prediction=prediction, verdict=verdict,
        exposure_ev=result.exposure_ev, bad_pixels=result.bad_pixels,
        valid_pixels=result.valid_pixels, directional=directional, bound=judge.bound,
        blind_spots=spots, measured=measured, uncertainty=u, interval=interval,
        validity=validity, noise=result.noise, sharpness=result.sharpness,
        properties=judged, exposure=exposure, neutral_ev=result.neutral_ev,
        intervals=column_intervals(prediction, u, judge.decision.k),
        diagnosis=image_diagnosis(result),
    )


def _image_blind_spots(measurement: ChartMeasurement, info: Any, read: ReadOptions
                       ) -> tuple[Any, ...]:
    """The blind-spot checks of an audited image's chart: its shadow tones (the image's
    banding: :func:`_image_banding`)."""
    return chart_blind_spots(measurement)


def _image_banding(image: Any) -> Any:
    """The banding check of an image read for its audit
    (:class:`fidelity.chart.image.Image`): judged when its pixels are integer codes."""
    if str(image.pixel_type).lower() in ("uint8", "uint16", "int8", "int16"):
        return banding(image.pixels, image.pixel_type)
    return banding(np.zeros((1, 1, 3)), image.pixel_type)


def chart_emulation(measurement: ChartMeasurement) -> Any:
    """The colour mapping from a chart's reference to its measured colours, fitted on its
    patches (:class:`fidelity.coco.emulation.PatchEmulation`)."""
    from fidelity.coco.emulation import PatchEmulation  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    ref = (measurement.reference_srgb if measurement.reference_srgb is not None
           else np.asarray(lab_to_srgb(measurement.reference_lab), np.float64))
    return PatchEmulation.fit(ref, measurement.srgb, neutral_patches(measurement))


def gate(
    criterion: Criterion,
    images: Sequence[str | os.PathLike[str]] = (),
    *,
    camera: CameraModel | str | None = None,
    corners: str | None = None,
    read: ReadOptions = DEFAULT_READ,
    reference: str | None = None,
    illuminant: str = "D65",
    renderer: str = "closed-form",
    judge: JudgeOptions = DEFAULT_JUDGE,
    frames: Sequence[int] | None = None,
    cat: str = "Bradford",
    edge_target: EdgeTargetCorners | None = None,
) -> list[GateResult]:
    """Gate ``images`` one by one (or ``camera``) against ``criterion``. An input error of
    one subject (exit code 2) becomes its result's ``error``; the others are still measured.
    ``frames``: one frame index per image (a recording named once per frame it is gated
    on): the subject is then ``IMAGE frame N``.

    ``reference`` defaults to ``scene``. Returns one :class:`~fidelity.pipeline.records.GateResult`
    per subject (its report, or its error, and the time it took);
    :func:`fidelity.pipeline.records.gate_exit_code` turns them into the exit code and
    :func:`fidelity.report.write_chart_report` writes each report.

    Parameters
    ----------
    criterion
        The gate: ``max-delta-e`` (mean ΔE00 <= limit) or ``max-dmap`` (predicted ΔmAP or
        class ΔAP <= limit, in percentage points or % of baseline).
    images
        Image files or recordings to audit, one subject each; empty: gate ``camera``.
    camera
        The camera to render and check when no ``images`` are given (a built-in name, a
        camera file or a :class:`~fidelity.camera.model.CameraModel`); None with no images:
        nothing is gated.
    corners
        Corner-patch centres ``"X1,Y1,...,X4,Y4"`` in image pixels, the same for every image;
        None: each chart is found.
    read
        How each image's pixels are read (:class:`~fidelity.chart.read.ReadOptions`; its
        recording options go to the inputs that are recordings).
    reference
        ``scene`` (None, the default), ``safecolor`` or a chart JSON.
    illuminant
        The scene illuminant (``D65``, ...) of the ``scene`` reference and of the render.
    renderer
        ``closed-form`` (default) or ``mitsuba``: how ``camera`` is rendered.
    judge
        How to judge (:class:`~fidelity.prediction.judge.JudgeOptions`: size class, table,
        bound, decision rule), as for :func:`check_camera`.
    frames
        One frame index per image (negative from the end), for a recording gated on several
        frames; None: ``read``'s frame.
    cat
        The chromatic adaptation of the ``scene`` reference (:func:`check_camera`).
    edge_target
        A slanted-edge target's corners, the same in every image (:func:`audit_image`).

    Returns
    -------
    list of GateResult
        One per subject, in order: its report or its input error's message, and the seconds
        it took; empty without images and camera.

    Raises
    ------
    ValueError
        ``frames`` not one per image.
    """
    if not images:
        cameras = [camera] if camera else []
        return [_subject_result(_camera_subject(cam), partial(
            check_camera, cam, illuminant=illuminant, renderer=renderer,
            reference=reference or "scene", criterion=criterion, judge=judge,
            command="gate", cat=cat), criterion) for cam in cameras]
    return _audit_subjects(images, corners, read, frames, partial(
        audit_image, criterion=criterion, command="gate", reference=reference or "scene",
        illuminant=illuminant, judge=judge, cat=cat, edge_target=edge_target), criterion)


def audit_images(
    images: Sequence[str | os.PathLike[str]],
    corners: str | None = None,
    *,
    read: ReadOptions = DEFAULT_READ,
    reference: str = "scene",
    illuminant: str = "D65",
    judge: JudgeOptions = DEFAULT_JUDGE,
    measure: MeasureRequest | None = None,
    frames: Sequence[int] | None = None,
    cat: str = "Bradford",
    edge_target: EdgeTargetCorners | None = None,
) -> list[GateResult]:
    """:func:`audit_image` of ``images`` one by one (a renderer's frames, say), as
    :func:`gate` measures them but without a criterion: one
    :class:`~fidelity.pipeline.records.GateResult` per subject, an input error of one subject its
    ``error`` while the others are still measured; ``frames`` as for :func:`gate`.

    Parameters
    ----------
    images
        Image files or recordings to audit, one subject each.
    corners
        Corner-patch centres ``"X1,Y1,...,X4,Y4"`` in image pixels, the same for every image;
        None: each chart is found.
    read
        How each image's pixels are read (:class:`~fidelity.chart.read.ReadOptions`; its
        recording options go to the inputs that are recordings).
    reference, illuminant
        ``scene`` (default: the chart's spectra under ``illuminant``, ``D65`` by default),
        ``safecolor`` or a chart JSON.
    judge
        How to judge (:class:`~fidelity.prediction.judge.JudgeOptions`), as for
        :func:`check_camera`; no verdict is made.
    measure
        Also measure each chart's colour rendering on COCO, as :func:`audit_image` does;
        None: not measured.
    frames
        One frame index per image, for a recording audited on several frames; None:
        ``read``'s frame.
    cat
        The chromatic adaptation of the ``scene`` reference, as for :func:`audit_image`.
    edge_target
        A slanted-edge target's corners, the same in every image (:func:`audit_image`).

    Returns
    -------
    list of GateResult
        One per subject, in order, without a criterion: its report or its input error's
        message (exit code 2), and the seconds it took.

    Raises
    ------
    ValueError
        ``frames`` not one per image.
    """
    return _audit_subjects(images, corners, read, frames, partial(
        audit_image, command="audit", reference=reference, illuminant=illuminant, judge=judge,
        cat=cat,
        measure=measure, edge_target=edge_target), None)


def _camera_subject(camera: CameraModel | str) -> str:
    """How a gated camera is named: its file or built-in name."""
    return camera if isinstance(camera, str) else camera.subject


def _audit_subjects(images: Sequence[str | os.PathLike[str]], corners: str | None,
                    read: ReadOptions, frames: Sequence[int] | None,
                    audit: Callable[..., ChartReport], criterion: Criterion | None
                    ) -> list[GateResult]:
    """``audit(path, corners, read=...)`` (:func:`audit_image` with the command's options) of
    each image (or frame), as results."""
    paths = [os.fspath(i) for i in images]
    reads = reads_for(paths, read)
    subjects = list(paths)
    if frames is not None:
        if len(frames) != len(paths):
            raise ValueError(f"{len(frames)} frames for {len(paths)} images")
        reads = [replace(r, frame=k, time=None) for r, k in zip(reads, frames, strict=True)]
        subjects = [f"{p} frame {k}" for p, k in zip(paths, frames, strict=True)]
    return [_subject_result(subject, partial(audit, path, corners, read=r), criterion)
            for subject, path, r in zip(subjects, paths, reads, strict=True)]


def _subject_result(subject: str, run: Callable[[], ChartReport],
                    criterion: Criterion | None) -> GateResult:
    """``run()`` (the subject's check or audit) as its result; an input error (or an
    unreadable file) its ``error``."""
    t0 = time.perf_counter()
    try:
        report = run()
    except (FidelityError, OSError) as exc:
        return GateResult(subject, criterion, error=str(exc),
                          seconds=time.perf_counter() - t0)
    return GateResult(subject, criterion, report=report, seconds=time.perf_counter() - t0)


__all__ = ["AUDIT_CONVENTION", "DEFAULT_CRITERION", "GAMUT_CLIPPED_DELTA_E", "TABLE_REFERENCES",
           "audit_image", "audit_images", "chart_emulation", "check_camera", "evidence_of",
           "explained_find", "gamut_clipped", "gate", "image_diagnosis", "prediction_domain",
           "preprocessing_check", "reference_linear", "render_diagnosis"]
