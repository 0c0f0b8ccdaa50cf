"""The result records of the chart pipeline: what ``check``, ``audit``, ``gate`` and ``compare``
return (:mod:`fidelity.pipeline.check`, :mod:`fidelity.pipeline.compare`), with their JSON forms.

:class:`ChartReport` is one chart measured (an image audit or a camera render), the detection loss
predicted from its chart ΔE and the verdict of a gate. Its JSON form (``schema_version``
:data:`SCHEMA_VERSION`) is described by the JSON Schema
``fidelity/data/schemas/report.schema.json`` (:func:`report_schema`); keys that do not apply are
``null``:

- ``mean_delta_e``, ``max_delta_e``, ``worst_patch``, ``patches`` (per patch ``delta_e``,
  ``delta_l``, ``delta_c``, ``delta_h``, ``lab``, ``reference_lab``, ``srgb``, ...): the chart
  measurement (CIEDE2000, Lab D65);
- ``exposure_ev``, ``bad_pixels``: the audit of an image (``null`` for a render);
- ``exposure``: the image's exposure judged against the expected one, where a fixed exposure
  was given (scene manifest or ``--exposure``;
  :class:`fidelity.prediction.exposure.ExposureJudgement`);
- ``source``: the image (:class:`ImageSource`) or the render (:class:`RenderSource`);
- ``prediction``: ΔE -> ΔmAP (:meth:`fidelity.prediction.table.Prediction.to_json`, with the
  notes in words);
- ``verdict``: pass/fail of the criterion (:meth:`fidelity.prediction.verdict.Verdict.to_json`,
  with the message);
- ``details``: where the patches were sampled (image) or the camera and render settings;
- ``prediction_interval``: the predicted ΔmAP with its standard uncertainty (the table's
  sampling error and the ΔE's uncertainty through the table's slope,
  :class:`fidelity.prediction.interval.PredictionInterval`);
- ``validity``: whether the answer lies inside its evidence's domain (table ΔE range, detector
  sizes, table kind, reference chart: :class:`fidelity.prediction.interval.ValidityDomain`);
- ``diagnosis``: the likely cause of the chart's error, from a small camera pipeline fitted to
  the patch means (:class:`fidelity.colour.diagnosis.Diagnosis`: exposure, black offset,
  white balance, saturation, tone curve, each in words with its values);
- ``uncertainty``: the standard uncertainty budget of the mean ΔE00
  (:class:`fidelity.measure.uncertainty.UncertaintyBudget`: each component, its value, type and
  method; the combined ``standard_uncertainty`` with ``k`` = 1);
- ``provenance``: tool version, Python and libraries, input sha256, tables (name, path,
  sha256), conventions.

:class:`ComparisonReport` is a sim-to-real comparison (two audits, the :class:`Normalisation`,
the sim-to-real measurement, prediction and verdict); :class:`GateResult` one gated subject
(its report or its input error). :mod:`fidelity.report` turns these records into JSON files,
HTML, JUnit and terminal text (the JSON report: :func:`fidelity.report.jsonform.chart_report_json`
and :func:`~fidelity.report.jsonform.comparison_json`); nothing here writes a file or a
sentence of a report. Each record reads its report back with ``from_json``.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import threading
from collections.abc import Mapping, Sequence
from dataclasses import field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.result import ChartChecks, FoundChart
from fidelity.chart.image import ImageInfo
from fidelity.chart.locate import ChartLocation, locate_chart
from fidelity.colour.diagnosis import Diagnosis
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import JSONObject, file_sha256
from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.core.version import __version__, installed_version
from fidelity.correction.normalise import Normalisation
from fidelity.measure.blindspots import BlindSpot
from fidelity.measure.chartnoise import ChartNoise
from fidelity.measure.chartsharpness import ChartSharpness
from fidelity.measure.colour import ChartMeasurement
from fidelity.measure.pixels import BadPixels
from fidelity.measure.uncertainty import UncertaintyBudget
from fidelity.pipeline.simreal import TextureComparison
from fidelity.prediction.directional import DirectionalPrediction
from fidelity.prediction.exposure import ExposureJudgement
from fidelity.prediction.interval import PredictionInterval, ValidityDomain
from fidelity.prediction.properties import PropertyJudgement
from fidelity.prediction.table import Prediction
from fidelity.prediction.verdict import EXIT_ERROR, Criterion, Verdict, worst_exit_code

if TYPE_CHECKING:
    from fidelity.chart.find.result import ChartChecks, FoundChart
    from fidelity.coco.measure import MeasuredLoss
    from fidelity.pipeline.context import ContextAssessment

#: Version of the JSON report layout (bump on incompatible change).
SCHEMA_VERSION = "1.0"
#: Commands that write a chart report.
COMMANDS = ("audit", "check", "compare", "gate")


def report_schema_path() -> Path:
    """Path of the JSON Schema of the report."""
    return resource_dir("data") / "schemas" / "report.schema.json"


def report_schema() -> JSONObject:
    """The JSON Schema (draft 2020-12) of the JSON report."""
    schema: JSONObject = json.loads(report_schema_path().read_text(encoding="utf-8"))
    return schema


@record
class ImageSource:
    """An image whose chart was measured: the file (:class:`~fidelity.chart.image.ImageInfo`),
    the corner patch centres used (``corners``, (4, 2) image x, y), how the chart was found
    (``found``; None when the corners were given), where each patch was sampled
    (``location``), the RGB ``colourspace`` the pixels were taken in, the ``exposure_mode``
    (auto or fixed), the reference's name, the patches clipped in sRGB and the pixel
    ``encoding`` measured."""

    image: ImageInfo
    corners: NDArray[np.float64]
    location: ChartLocation
    colourspace: str
    exposure_mode: str
    reference: str
    encoding: str
    clipped_patches: tuple[str, ...] = ()
    found: FoundChart | None = None
    corner_checks: ChartChecks | None = None

    def to_json(self) -> JSONObject:
        """The report's ``source`` object."""
        return {"type": "image", **self.image.to_json(), "corners": self.corners.tolist(),
                "corners_found": self.found.to_json() if self.found else None,
                "corner_checks": (self.corner_checks.to_json() if self.corner_checks
                                  else None),
                "colourspace": self.colourspace, "exposure_mode": self.exposure_mode,
                "reference": self.reference}

    def details(self) -> JSONObject:
        """The report's ``details`` object for an image."""
        return {"location": self.location.to_json(),
                "clipped_patches": list(self.clipped_patches), "encoding": self.encoding}

    @classmethod
    def from_json(cls, source: Mapping[str, Any], details: Mapping[str, Any]) -> ImageSource:
        """The source of a report's ``source`` and ``details``; the sampling windows are
        located again from the corners (:func:`fidelity.chart.locate.locate_chart`)."""
        info = ImageInfo.from_json(source)
        corners = np.asarray(source["corners"], dtype=np.float64)
        loc = details["location"]
        rows_cols = (4, 6) if len(loc["centres"]) == 24 else (1, len(loc["centres"]))
        location = locate_chart(corners, (info.height, info.width), rows=rows_cols[0],
                                cols=rows_cols[1], window=float(loc["window_pitch_fraction"]),
                                min_pixels=1)

        found = source.get("corners_found")
        checks = source.get("corner_checks")
        return cls(info, corners, location, str(source.get("colourspace", "sRGB")),
                   str(source.get("exposure_mode", "")), str(source.get("reference", "")),
                   str(details.get("encoding", info.encoding or "")),
                   tuple(details.get("clipped_patches", ())),
                   FoundChart.from_json(found) if found else None,
                   ChartChecks.from_json(checks) if checks else None)

    @property
    def title(self) -> str:
        """How a report names this source: the file, and for a recording the topic, frame and
        time of the message read."""
        return self.image.path + self._recording_suffix()

    @property
    def name(self) -> str:
        """:attr:`title` with the file's name only (no folders)."""
        return Path(self.image.path).name + self._recording_suffix()

    def _recording_suffix(self) -> str:
        rec = self.image.recording
        if rec is None:
            return ""
        return f" ({rec.topic}, frame {rec.frame}, {rec.offset_s:.3f} s)"

    @property
    def reference_description(self) -> str:
        """The reference the chart was compared with, in words (its illuminant included)."""
        return self.reference


@record
class RenderSource:
    """A camera model's render of the spectral chart: the ``camera`` name, ``illuminant``,
    ``renderer`` and Mitsuba ``variant`` (None for the closed form), the render's wall time
    in ``seconds``, the ``reference`` it was compared with, and the camera's and the render's
    settings (JSON, as :meth:`fidelity.camera.render.ChartRender.to_json` gives them)."""

    camera: str
    illuminant: str
    renderer: str
    variant: str | None
    seconds: float
    reference: str
    camera_settings: Mapping[str, Any] = field(default_factory=dict)
    render_settings: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> JSONObject:
        """The report's ``source`` object."""
        return {"type": "render", "camera": self.camera, "illuminant": self.illuminant,
                "renderer": self.renderer, "variant": self.variant, "seconds": self.seconds,
                "reference": self.reference}

    def details(self) -> JSONObject:
        """The report's ``details`` object for a render."""
        return {"camera": dict(self.camera_settings), "settings": dict(self.render_settings)}

    @classmethod
    def from_json(cls, source: Mapping[str, Any], details: Mapping[str, Any]) -> RenderSource:
        """Inverse of :meth:`to_json` and :meth:`details`."""
        return cls(str(source["camera"]), str(source["illuminant"]), str(source["renderer"]),
                   source.get("variant"), float(source["seconds"]), str(source["reference"]),
                   dict(details.get("camera") or {}), dict(details.get("settings") or {}))

    @property
    def title(self) -> str:
        """How a report names this source."""
        return self.camera

    @property
    def name(self) -> str:
        """How a report names this source in short: the camera."""
        return self.camera

    @property
    def reference_description(self) -> str:
        """The reference the chart was compared with, in words (its illuminant included)."""
        if self.reference != "scene":
            return self.reference
        spectra = self.render_settings.get("spectra", "BabelColor Average")
        return f"scene ({spectra} under {self.illuminant})"


Source = ImageSource | RenderSource


@record
class TableRef:
    """A data table a result depends on: ``name``, ``kind`` (prediction tables), ``path`` and
    the file's ``sha256``."""

    name: str
    path: str | None
    sha256: str | None
    kind: str | None = None

    def to_json(self) -> JSONObject:
        """JSON form (``kind`` only for tables that have one)."""
        out: JSONObject = {"name": self.name}
        if self.kind is not None:
            out["kind"] = self.kind
        return out | {"path": self.path, "sha256": self.sha256}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TableRef:
        """Inverse of :meth:`to_json`."""
        return cls(str(data["name"]), data.get("path"), data.get("sha256"), data.get("kind"))

    @classmethod
    def of_file(cls, name: str, path: str | os.PathLike[str] | None,
                kind: str | None = None) -> TableRef:
        """The reference of a table file (its sha256 read now; None when unreadable)."""
        digest = None
        if path:
            try:
                digest = file_sha256(path)
            except OSError:
                digest = None
        return cls(name, str(path) if path else None, digest, kind)


#: Conventions every chart report states.
BASE_CONVENTIONS: Mapping[str, str] = {
    "delta_e": "CIEDE2000 (kL = kC = kH = 1), CIE 1976 L*a*b* relative to D65, CIE 1931 2° "
               "observer; chart ΔE = mean over the 24 patches",
    "srgb": "IEC 61966-2-1 (piecewise transfer, 0.04045 / 0.0031308, exponent 2.4)",
    "dmap_points": "percentage points of mAP@[.50:.95] (100*(baseline-transformed))",
    "dmap_relative": "percent of the baseline mAP",
}

#: Libraries whose versions a report records.
_LIBRARIES = ("numpy", "scipy", "colour-science", "OpenImageIO", "OpenEXR", "mitsuba")


@record
class Provenance:
    """Where a report's numbers come from: the tool ``version``, ``python``, ``platform``,
    library versions, the input's sha256, the tables used and the conventions."""

    version: str
    python: str
    platform: str
    libraries: Mapping[str, str]
    input_sha256: str | None
    tables: Mapping[str, TableRef]
    conventions: Mapping[str, Any]
    tool: str = "fidelity"

    def to_json(self) -> JSONObject:
        """The report's ``provenance`` object."""
        return {"tool": self.tool, "version": self.version, "python": self.python,
                "platform": self.platform, "libraries": dict(self.libraries),
                "input_sha256": self.input_sha256,
                "tables": {k: t.to_json() for k, t in self.tables.items()},
                "conventions": dict(self.conventions)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Provenance:
        """Inverse of :meth:`to_json`."""
        return cls(str(data["version"]), str(data["python"]), str(data["platform"]),
                   dict(data["libraries"]), data.get("input_sha256"),
                   {k: TableRef.from_json(v) for k, v in data["tables"].items()},
                   dict(data["conventions"]), str(data.get("tool", "fidelity")))

    @classmethod
    def collect(cls, input_sha256: str | None, prediction: Prediction | None,
                conventions: Mapping[str, Any]) -> Provenance:
        """The provenance of a report made now, on this machine."""
        libraries: dict[str, str] = {}
        for name in _LIBRARIES:
            found = installed_version(name)
            if found is not None:
                libraries[name] = found
        tables: dict[str, TableRef] = {}
        if prediction is not None:
            t = prediction.table
            tables["prediction"] = TableRef.of_file(t.name, t.path, t.kind)
            tables["calibration"] = TableRef.of_file(
                "calibration-safecolor", resource_dir("data") / "calibration-safecolor.json")
        return cls(__version__, sys.version.split()[0], machine_platform(), libraries,
                   input_sha256, tables, {**BASE_CONVENTIONS, **conventions})


@record
class ChartReport:
    """One chart measured (an image audit or a camera render), the detection loss predicted
    from its chart ΔE and the verdict of a gate (see the module docstring).

    Attributes
    ----------
    command
        The command that made it: ``audit``, ``check``, ``compare`` or ``gate``
        (:data:`COMMANDS`).
    created
        When it was made, UTC, ``YYYY-MM-DDThh:mm:ssZ`` (:func:`utc_now`).
    measurement
        The chart's ΔE00 per patch (CIEDE2000, Lab D65); ``mean_delta_e`` is the chart ΔE.
    source
        The image (:class:`ImageSource`) or the camera render (:class:`RenderSource`).
    provenance
        Tool and library versions, the input's sha256, the tables used and the conventions.
    prediction
        The worst-case detection loss (ΔmAP) predicted from the chart ΔE; None when not
        predicted.
    verdict
        Pass/fail of the criterion; None without a criterion.
    exposure_ev
        The exposure correction applied to an image, in EV; None for a render.
    bad_pixels
        NaN, Inf and negative pixel counts of an image; None for a render.
    valid_pixels
        Pixels averaged per patch, in chart order; None for a render.
    schema_version
        Version of the JSON report layout (:data:`SCHEMA_VERSION`).
    directional
        The direction-aware prediction (:mod:`fidelity.prediction.directional`); None when
        not made.
    bound
        Which prediction decided a ``max-dmap`` verdict: ``classic`` or ``directional``.
    blind_spots
        The blind-spot checks (:mod:`fidelity.measure.blindspots`), in report order.
    measured
        Losses measured on COCO (``--measure``; :class:`fidelity.coco.measure.MeasuredLoss`),
        one per detector; empty when not measured.
    uncertainty
        The standard uncertainty budget of the chart ΔE (k = 1); None when not evaluated.
    interval
        The predicted ΔmAP with its standard uncertainty
        (:class:`fidelity.prediction.interval.PredictionInterval`); None when not evaluated.
    intervals
        Every loss column's predicted value with its own standard uncertainty (points,
        relative, person, bicycle: the table's SE of that column and the ΔE's through its
        slope), in :data:`fidelity.prediction.tablefile.COLUMNS` order; empty when not
        evaluated.
    validity
        Whether the answer lies inside its evidence's domain
        (:class:`fidelity.prediction.interval.ValidityDomain`); None when not judged.
    noise
        The chart's neutral-patch noise, photon transfer and SNR at the 18 % grey
        (:class:`fidelity.measure.chartnoise.ChartNoise`); None when not measured (a render).
    sharpness
        The MTF of the chart's patch edges (:class:`fidelity.measure.chartsharpness.
        ChartSharpness`); None when not measured.
    properties
        Colour, sharpness and noise judged together, each property's predicted loss and
        which were not judged (:class:`fidelity.prediction.properties.PropertyJudgement`);
        None when not judged.
    exposure
        The image's exposure judged against the expected one (a fixed exposure from the
        scene manifest or ``--exposure``;
        :class:`fidelity.prediction.exposure.ExposureJudgement`); None when not judged.
    neutral_ev
        The exposure correction an image's neutral patches ask for, in EV (equal to
        ``exposure_ev`` when auto); None for a render or black neutral patches.
    diagnosis
        The likely cause of the chart's error (:class:`fidelity.colour.diagnosis.Diagnosis`:
        the causes in words and numbers, or none); None when not made.
    context
        The context of use's credibility assessment (``--context``;
        :class:`fidelity.pipeline.context.ContextAssessment`); None without a context.
    """

    command: str
    created: str
    measurement: ChartMeasurement
    source: Source
    provenance: Provenance
    prediction: Prediction | None = None
    verdict: Verdict | None = None
    exposure_ev: float | None = None
    bad_pixels: BadPixels | None = None
    valid_pixels: tuple[int, ...] | None = None
    schema_version: str = SCHEMA_VERSION
    #: the direction-aware prediction (:mod:`fidelity.prediction.directional`)
    directional: DirectionalPrediction | None = None
    #: which prediction decided a max-dmap verdict: ``classic`` or ``directional``
    bound: str = "classic"
    #: the blind-spot checks (:mod:`fidelity.measure.blindspots`)
    blind_spots: tuple[BlindSpot, ...] = ()
    #: losses measured on COCO (``--measure``; :class:`fidelity.coco.measure.MeasuredLoss`)
    measured: tuple[MeasuredLoss, ...] = ()
    #: the standard uncertainty of the chart ΔE (:mod:`fidelity.measure.uncertainty`)
    uncertainty: UncertaintyBudget | None = None
    #: the predicted ΔmAP with its uncertainty (:mod:`fidelity.prediction.interval`)
    interval: PredictionInterval | None = None
    #: whether the answer lies inside its evidence's domain
    validity: ValidityDomain | None = None
    #: the neutral patches' noise (:mod:`fidelity.measure.chartnoise`)
    noise: ChartNoise | None = None
    #: the MTF of the patch edges (:mod:`fidelity.measure.chartsharpness`)
    sharpness: ChartSharpness | None = None
    #: colour, sharpness and noise judged together
    #: (:class:`fidelity.prediction.properties.PropertyJudgement`)
    properties: PropertyJudgement | None = None
    #: the image's exposure judged (:class:`fidelity.prediction.exposure.ExposureJudgement`)
    exposure: ExposureJudgement | None = None
    #: the exposure correction the neutral patches ask for, in EV (an image; None: none)
    neutral_ev: float | None = None
    #: the likely cause of the chart's error (:mod:`fidelity.colour.diagnosis`)
    diagnosis: Diagnosis | None = None
    #: the context of use's credibility assessment (``--context``;
    #: :class:`fidelity.pipeline.context.ContextAssessment`)
    context: ContextAssessment | None = None
    #: every loss column with its own standard uncertainty (:mod:`fidelity.prediction.interval`)
    intervals: tuple[PredictionInterval, ...] = ()

    @property
    def exposure_auto(self) -> bool:
        """Whether an image's audit normalised its exposure on the neutral patches (auto):
        the image's own exposure then is neither in the chart ΔE nor judged."""
        return isinstance(self.source, ImageSource) and self.source.exposure_mode == "auto"

    @property
    def warnings(self) -> list[BlindSpot]:
        """The blind-spot checks that found a risk."""
        return [s for s in self.blind_spots if s.at_risk]

    @property
    def mean_delta_e(self) -> float:
        """The chart ΔE: mean ΔE00 over the patches."""
        return self.measurement.mean_delta_e

    @property
    def max_delta_e(self) -> float:
        """Largest per-patch ΔE00."""
        return self.measurement.max_delta_e

    @property
    def worst_patch(self) -> str:
        """The patch with the largest ΔE00."""
        return self.measurement.worst_patch

    @property
    def exit_code(self) -> int:
        """0 pass (or no verdict), 1 fail."""
        return self.verdict.exit_code if self.verdict is not None else 0

    @classmethod
    def from_json(cls, data: Mapping[str, Any], *, validate: bool = True) -> ChartReport:
        """The report of a JSON document, checked against :func:`report_schema` first
        (``validate``; needs the ``jsonschema`` package)."""
        if validate:
            validate_report(data)
        src, details = data["source"], data.get("details") or {}
        source: Source = (ImageSource.from_json(src, details) if src["type"] == "image"
                          else RenderSource.from_json(src, details))
        patches = data["patches"]
        valid = (tuple(int(p["valid_pixels"]) for p in patches)
                 if all("valid_pixels" in p for p in patches) else None)
        return cls(
            command=str(data["command"]), created=str(data["created"]),
            measurement=ChartMeasurement.from_json(data), source=source,
            provenance=Provenance.from_json(data["provenance"]),
            prediction=Prediction.from_json(data["prediction"]) if data["prediction"] else None,
            verdict=(Verdict.from_json(data["verdict"], float(data["mean_delta_e"]))
                     if data["verdict"] else None),
            exposure_ev=data.get("exposure_ev"),
            bad_pixels=BadPixels.from_json(data["bad_pixels"]) if data["bad_pixels"] else None,
            valid_pixels=valid, schema_version=str(data["schema_version"]),
            directional=(DirectionalPrediction.from_json(data["directional_prediction"])
                         if data.get("directional_prediction") else None),
            bound=str(data.get("bound") or "classic"),
            blind_spots=tuple(BlindSpot.from_json(b) for b in data.get("blind_spots") or ()),
            measured=_measured_from_json(data.get("measured_loss") or ()),
            uncertainty=(UncertaintyBudget.from_json(data["uncertainty"])
                         if data.get("uncertainty") else None),
            interval=(PredictionInterval.from_json(data["prediction_interval"])
                      if data.get("prediction_interval") else None),
            intervals=tuple(PredictionInterval.from_json(i)
                            for i in data.get("prediction_intervals") or ()),
            validity=(ValidityDomain.from_json(data["validity"])
                      if data.get("validity") else None),
            noise=ChartNoise.from_json(data["noise"]) if data.get("noise") else None,
            sharpness=(ChartSharpness.from_json(data["sharpness"])
                       if data.get("sharpness") else None),
            properties=(PropertyJudgement.from_json(data["properties"])
                        if data.get("properties") else None),
            exposure=(ExposureJudgement.from_json(data["exposure"])
                      if data.get("exposure") else None),
            neutral_ev=data.get("neutral_ev"),
            diagnosis=(Diagnosis.from_json(data["diagnosis"])
                       if data.get("diagnosis") else None),
        )


def _measured_from_json(items: Sequence[Mapping[str, Any]]) -> tuple[MeasuredLoss, ...]:
    if not items:
        return ()
    from fidelity.coco.measure import MeasuredLoss  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    return tuple(MeasuredLoss.from_json(m) for m in items)


def validate_report(data: Mapping[str, Any]) -> None:
    """Check a JSON report against :func:`report_schema`; raises
    :class:`~fidelity.core.errors.InvalidValueError` naming the first violation."""
    import jsonschema

    try:
        jsonschema.validate(dict(data), report_schema())
    except jsonschema.ValidationError as exc:
        where = "/".join(str(p) for p in exc.absolute_path) or "(top level)"
        raise InvalidValueError(f"not a fidelity report: {where}: {exc.message}") from None


#: The background thread of :func:`start_platform_lookup`, once started.
_platform_lookup: list[threading.Thread] = []


def start_platform_lookup() -> None:
    """Start :func:`platform.platform` in a background thread, so that a report's
    :meth:`Provenance.collect` finds it done: on Linux its first call runs ``uname -p`` (a
    subprocess, some 20 ms), which then overlaps the measurement. The answer is the same
    (:func:`platform.platform` caches it); a second call starts nothing."""
    if not _platform_lookup:
        thread = threading.Thread(target=platform.platform, name="platform", daemon=True)
        _platform_lookup.append(thread)
        thread.start()


def machine_platform() -> str:
    """:func:`platform.platform`, after the lookup :func:`start_platform_lookup` started."""
    for thread in _platform_lookup:
        thread.join()
    return platform.platform()


def utc_now() -> str:
    """The current UTC time as the report writes it (``YYYY-MM-DDThh:mm:ssZ``)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


#: JSON layout version of a comparison report.
COMPARE_SCHEMA_VERSION = "1.0"


@record
class ComparisonReport:
    """A sim-to-real comparison (module docstring): the two audits (``sim``, ``real``:
    :class:`ChartReport`), the :class:`Normalisation`, the sim-to-real
    ``measurement`` (the normalised simulated chart against the real chart as reference), the
    classic ``prediction`` and the ``directional`` one at the sim-to-real ΔE, the
    ``verdict``, which ``bound`` decided it, the losses ``measured`` on COCO, the mapping's
    description (``emulation``), when and with what it was made.

    Attributes
    ----------
    created
        When it was made, UTC, ``YYYY-MM-DDThh:mm:ssZ`` (:func:`utc_now`).
    sim
        The audit of the simulated image (a :class:`ChartReport` against the chart's
        reference).
    real
        The audit of the real image (a :class:`ChartReport` against the chart's reference).
    normalisation
        What was matched before comparing: the mode (``none``, ``exposure`` or
        ``exposure+wb``), the simulated chart's exposure change in EV and per-channel gains.
    measurement
        The normalised simulated chart against the real chart as reference: ΔE00 per patch;
        ``mean_delta_e`` is the sim-to-real chart ΔE.
    prediction
        The classic worst-case ΔmAP predicted at the sim-to-real ΔE.
    directional
        The direction-aware prediction at the sim-to-real ΔE; None when not made.
    verdict
        Pass/fail of the criterion; None without a criterion.
    provenance
        Tool and library versions, the inputs' sha256, the tables used and the conventions.
    bound
        Which prediction decided a ``max-dmap`` verdict: ``classic`` or ``directional``.
    measured
        Losses of the sim-to-real mapping measured on COCO (``--measure``), one per detector;
        empty when not measured.
    emulation
        Description of the sim-to-real colour mapping measured on COCO (JSON-ready); None
        when not measured.
    command
        The command that made it (``compare``).
    schema_version
        Version of the comparison's JSON layout (:data:`COMPARE_SCHEMA_VERSION`).
    uncertainty
        The standard uncertainty budget of the sim-to-real ΔE
        (:func:`fidelity.pipeline.compare.sim_to_real_uncertainty`); None when not evaluated.
    interval
        The predicted ΔmAP with its standard uncertainty; None when not evaluated.
    validity
        Whether the answer lies inside its evidence's domain; None when not judged.
    intervals
        Every loss column of the prediction with its own standard uncertainty
        (:func:`fidelity.pipeline.check.column_intervals`); empty when not evaluated.
    texture
        Sharpness and noise, simulation against real camera: each side's luminance MTF curve
        and neutral-patch noise points, the MTF50 ratio and the SNR difference
        (:class:`fidelity.pipeline.simreal.TextureComparison`); None when not made.
    """

    created: str
    sim: ChartReport
    real: ChartReport
    normalisation: Normalisation
    measurement: ChartMeasurement
    prediction: Prediction
    directional: DirectionalPrediction | None
    verdict: Verdict | None
    provenance: Provenance
    bound: str = "classic"
    measured: tuple[MeasuredLoss, ...] = ()
    emulation: Mapping[str, Any] | None = None
    command: str = "compare"
    schema_version: str = COMPARE_SCHEMA_VERSION
    #: the sim-to-real ΔE's uncertainty (:func:`fidelity.pipeline.compare.sim_to_real_uncertainty`)
    uncertainty: UncertaintyBudget | None = None
    interval: PredictionInterval | None = None
    validity: ValidityDomain | None = None
    #: every loss column of the prediction with its own standard uncertainty
    #: (:func:`fidelity.pipeline.check.column_intervals`)
    intervals: tuple[PredictionInterval, ...] = ()
    #: sharpness and noise side by side (:func:`fidelity.pipeline.simreal.texture_comparison`)
    texture: TextureComparison | None = None

    @property
    def mean_delta_e(self) -> float:
        """The sim-to-real chart ΔE: mean ΔE00 over the patches."""
        return self.measurement.mean_delta_e

    @property
    def max_delta_e(self) -> float:
        """Largest sim-to-real ΔE00 of a patch."""
        return self.measurement.max_delta_e

    @property
    def worst_patch(self) -> str:
        """The patch whose simulated colour is farthest from the real one."""
        return self.measurement.worst_patch

    @property
    def exit_code(self) -> int:
        """0 pass (or no verdict), 1 fail."""
        return self.verdict.exit_code if self.verdict is not None else 0

    def as_chart_report(self) -> ChartReport:
        """The sim-to-real result as a :class:`ChartReport` of the
        simulated image whose reference is the real chart (for JUnit and the verdict line)."""

        src = self.sim.source
        assert isinstance(src, ImageSource)
        real_src = self.real.source
        real_name = real_src.title
        return ChartReport(
            command=self.command, created=self.created, measurement=self.measurement,
            source=replace(src, reference=f"the real camera's chart ({real_name})"),
            provenance=self.provenance, prediction=self.prediction, verdict=self.verdict,
            directional=self.directional, bound=self.bound, measured=self.measured,
            uncertainty=self.uncertainty, interval=self.interval, validity=self.validity,
            intervals=self.intervals)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ComparisonReport:
        """Inverse of :meth:`to_json`."""
        from fidelity.coco.measure import MeasuredLoss  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        s2r = d["sim_to_real"]
        return cls(
            created=str(d["created"]), sim=ChartReport.from_json(d["sim"]),
            real=ChartReport.from_json(d["real"]),
            normalisation=Normalisation.from_json(s2r["normalisation"]),
            measurement=ChartMeasurement.from_json(s2r),
            prediction=Prediction.from_json(d["prediction"]),
            directional=(DirectionalPrediction.from_json(d["directional_prediction"])
                         if d.get("directional_prediction") else None),
            verdict=(Verdict.from_json(d["verdict"], float(s2r["mean_delta_e"]))
                     if d.get("verdict") else None),
            provenance=Provenance.from_json(d["provenance"]), bound=str(d.get("bound", "classic")),
            measured=tuple(MeasuredLoss.from_json(x) for x in d.get("measured_loss") or ()),
            emulation=d.get("emulation"), command=str(d.get("command", "compare")),
            schema_version=str(d.get("schema_version", COMPARE_SCHEMA_VERSION)),
            uncertainty=(UncertaintyBudget.from_json(s2r["uncertainty"])
                         if s2r.get("uncertainty") else None),
            interval=(PredictionInterval.from_json(d["prediction_interval"])
                      if d.get("prediction_interval") else None),
            validity=ValidityDomain.from_json(d["validity"]) if d.get("validity") else None,
            intervals=tuple(PredictionInterval.from_json(i)
                            for i in d.get("prediction_intervals") or ()),
            texture=(TextureComparison.from_json(d["sharpness_noise"])
                     if d.get("sharpness_noise") else None))


@record
class GateResult:
    """One subject of a gate (:func:`fidelity.pipeline.check.gate`) or of an audit of several images
    (:func:`fidelity.pipeline.check.audit_images`, no ``criterion``): its ``subject`` (image path,
    ``IMAGE frame N`` or camera), the ``criterion``, the ``report`` (None on error), the
    ``error`` message (exit code 2) and the ``seconds`` it took.

    Attributes
    ----------
    subject
        What was gated: the image path, ``IMAGE frame N`` for a frame of a recording, or the
        camera.
    criterion
        The gate's criterion; None for an audit of several images.
    report
        The subject's report; None when it could not be measured.
    error
        The input error's message (a :class:`~fidelity.core.errors.FidelityError`: exit code
        2); None when measured.
    seconds
        Wall-clock seconds the subject took, >= 0.
    """

    subject: str
    criterion: Criterion | None = None
    report: ChartReport | None = None
    error: str | None = None
    seconds: float = 0.0

    @property
    def exit_code(self) -> int:
        """0 pass, 1 fail, 2 error, 4 undecided (guarded decision rule)."""
        if self.error is not None or self.report is None:
            return EXIT_ERROR
        return self.report.exit_code


def gate_exit_code(results: Sequence[GateResult]) -> int:
    """The exit code of a gate over ``results``: 2 if any could not be measured, else 1 if any
    failed, else 4 if any was undecided, else 0
    (:func:`fidelity.prediction.verdict.worst_exit_code`)."""
    return worst_exit_code(r.exit_code for r in results)


__all__ = [
    "BASE_CONVENTIONS",
    "COMMANDS",
    "COMPARE_SCHEMA_VERSION",
    "SCHEMA_VERSION",
    "ChartReport",
    "ComparisonReport",
    "GateResult",
    "ImageSource",
    "Provenance",
    "RenderSource",
    "Source",
    "TableRef",
    "gate_exit_code",
    "machine_platform",
    "report_schema",
    "report_schema_path",
    "start_platform_lookup",
    "utc_now",
    "validate_report",
]
