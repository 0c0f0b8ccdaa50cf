"""The chart report: one measured chart, its predicted detection loss and its verdict.

:class:`ChartReport` is what ``fidelity check``, ``audit`` and ``gate`` produce
(:mod:`fidelity.check`). Its JSON form (``schema_version`` :data:`SCHEMA_VERSION`) is described by
the JSON Schema ``fidelity/data/schemas/report.schema.json`` (:func:`report_schema`); keys that do
not apply are ``null``:

- ``mean_delta_e``, ``max_delta_e``, ``worst_patch``, ``patches`` (per patch ``delta_e``,
  ``delta_l``, ``delta_c``, ``delta_h``, ``lab``, ``reference_lab``, ``srgb``, ...): the chart
  measurement (CIEDE2000, Lab D65);
- ``exposure_ev``, ``bad_pixels``: the audit of an image (``null`` for a render);
- ``source``: the image (:class:`ImageSource`) or the render (:class:`RenderSource`);
- ``prediction``: ΔE -> ΔmAP (:meth:`fidelity.prediction.table.Prediction.to_json`);
- ``verdict``: pass/fail of the criterion (:meth:`fidelity.prediction.verdict.Verdict.to_json`);
- ``details``: where the patches were sampled (image) or the camera and render settings;
- ``provenance``: tool version, Python and libraries, input sha256, tables (name, path,
  sha256), conventions.

The HTML report (:func:`chart_document`, written by :mod:`fidelity.report.html`) puts the
verdict and the chart first, then the figures a colour scientist expects (ΔE heat map on the
chart, a*b* arrows, the neutral tone curve, ΔE per patch, the prediction curve with the limit)
and folds the patch table, the transforms and the provenance away.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.blindspots import BlindSpot
from fidelity.chart.find import ChartChecks, FoundChart
from fidelity.chart.image import ImageInfo
from fidelity.chart.locate import ChartLocation
from fidelity.chart.measure import BadPixels, ChartMeasurement
from fidelity.fileio import JSONObject, json_ready
from fidelity.prediction.directional import DirectionalPrediction
from fidelity.prediction.table import Prediction
from fidelity.prediction.verdict import Verdict
from fidelity.report.document import (
    Code,
    Document,
    Facts,
    Figure,
    Headline,
    Section,
    Text,
    section,
    table,
)

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasuredLoss

#: Version of the JSON report layout (bump on incompatible change).
SCHEMA_VERSION = "1.0"
#: Commands that write a chart report.
COMMANDS = ("audit", "check", "compare", "gate")


def report_schema_path() -> Path:
    """Path of the JSON Schema of the report."""
    from fidelity.resources import resource_dir

    return resource_dir("data") / "schemas" / "report.schema.json"


def report_schema() -> JSONObject:
    """The JSON Schema (draft 2020-12) of the JSON report."""
    schema: JSONObject = json.loads(report_schema_path().read_text(encoding="utf-8"))
    return schema


# ------------------------------------------------------------------------------- records

@dataclass(frozen=True)
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
        from fidelity.chart.locate import locate_chart

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
        """How a report names this source."""
        return self.image.path

    @property
    def reference_description(self) -> str:
        """The reference the chart was compared with, in words (its illuminant included)."""
        return self.reference


@dataclass(frozen=True)
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
    def reference_description(self) -> str:
        """The reference the chart was compared with, in words (its illuminant included)."""
        if self.reference != "scene":
            return self.reference
        spectra = self.render_settings.get("spectra", "BabelColor Average")
        return f"scene ({spectra} under {self.illuminant})"


Source = ImageSource | RenderSource


@dataclass(frozen=True)
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
        from fidelity.fileio import file_sha256

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
_LIBRARIES = ("numpy", "scipy", "colour-science", "OpenImageIO", "OpenEXR", "matplotlib",
              "mitsuba")


@dataclass(frozen=True)
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
        from importlib.metadata import PackageNotFoundError, version

        from fidelity import __version__
        from fidelity.resources import resource_dir

        libraries: dict[str, str] = {}
        for name in _LIBRARIES:
            try:
                libraries[name] = version(name)
            except PackageNotFoundError:
                continue
        tables: dict[str, TableRef] = {}
        if prediction is not None:
            t = prediction.table
            tables["prediction"] = TableRef.of_file(t.name, t.path, t.kind)
            tables["calibration"] = TableRef.of_file(
                "calibration-safecolor", resource_dir("data") / "calibration-safecolor.json")
        return cls(__version__, sys.version.split()[0], platform.platform(), libraries,
                   input_sha256, tables, {**BASE_CONVENTIONS, **conventions})


@dataclass(frozen=True)
class ChartReport:
    """One chart measured (an image audit or a camera render), the detection loss predicted
    from its chart ΔE and the verdict of a gate (see the module docstring)."""

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
    #: the blind-spot checks (:mod:`fidelity.chart.blindspots`)
    blind_spots: tuple[BlindSpot, ...] = ()
    #: losses measured on COCO (``--measure``; :class:`fidelity.coco.measure.MeasuredLoss`)
    measured: tuple[MeasuredLoss, ...] = ()

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

    def to_json(self) -> JSONObject:
        """The JSON report (strict JSON values; see the module docstring)."""
        m = self.measurement.to_json()
        patches = m["patches"]
        if self.valid_pixels is not None:
            per_patch = self.bad_pixels.per_patch if self.bad_pixels else {}
            for p, n in zip(patches, self.valid_pixels, strict=True):
                p.update(valid_pixels=int(n), bad_pixels=int(per_patch.get(p["name"], 0)))
        out: JSONObject = json_ready({
            "schema_version": self.schema_version,
            "command": self.command,
            "created": self.created,
            "mean_delta_e": m["mean_delta_e"],
            "max_delta_e": m["max_delta_e"],
            "worst_patch": m["worst_patch"],
            "patches": patches,
            "exposure_ev": self.exposure_ev,
            "bad_pixels": self.bad_pixels.to_json() if self.bad_pixels else None,
            "source": self.source.to_json(),
            "prediction": self.prediction.to_json() if self.prediction else None,
            "verdict": self.verdict.to_json() if self.verdict else None,
            "details": self.source.details(),
            "provenance": self.provenance.to_json(),
            "bound": self.bound,
            "directional_prediction": (self.directional.to_json()
                                       if self.directional else None),
            "blind_spots": [b.to_json() for b in self.blind_spots],
            "measured_loss": [m.to_json() for m in self.measured],
        })
        return out

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
            verdict=Verdict.from_json(data["verdict"]) if data["verdict"] else None,
            exposure_ev=data.get("exposure_ev"),
            bad_pixels=BadPixels.from_json(data["bad_pixels"]) if data["bad_pixels"] else None,
            valid_pixels=valid, schema_version=str(data["schema_version"]),
            directional=(DirectionalPrediction.from_json(data["directional_prediction"])
                         if data.get("directional_prediction") else None),
            bound=str(data.get("bound") or "classic"),
            blind_spots=tuple(BlindSpot.from_json(b) for b in data.get("blind_spots") or ()),
            measured=_measured_from_json(data.get("measured_loss") or ()),
        )


def _measured_from_json(items: Sequence[Mapping[str, Any]]) -> tuple[MeasuredLoss, ...]:
    if not items:
        return ()
    from fidelity.coco.measure import MeasuredLoss

    return tuple(MeasuredLoss.from_json(m) for m in items)


def validate_report(data: Mapping[str, Any]) -> None:
    """Check a JSON report against :func:`report_schema`; raises
    :class:`~fidelity.errors.InvalidValueError` naming the first violation."""
    import jsonschema

    from fidelity.errors import InvalidValueError

    try:
        jsonschema.validate(dict(data), report_schema())
    except jsonschema.ValidationError as exc:
        where = "/".join(str(p) for p in exc.absolute_path) or "(top level)"
        raise InvalidValueError(f"not a fidelity report: {where}: {exc.message}") from None


def utc_now() -> str:
    """The current UTC time as the report writes it (``YYYY-MM-DDThh:mm:ssZ``)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


# ---------------------------------------------------------------------- the HTML document

def _num(v: float | None, nd: int = 2) -> str:
    return "–" if v is None else f"{v:.{nd}f}"


def _headline(report: ChartReport) -> Headline:
    from fidelity.report import plots

    figure = Figure(plots.swatches(report.measurement), "swatches.png",
                    "the chart: reference against measured",
                    "Each patch: reference colour (left half) and measured colour (right half).")
    v = report.verdict
    warn = "".join(f"\n\n**warning**: {w.reason}" for w in report.warnings)
    if v is not None:
        return Headline(f"**{v.label}**: {v.message.split(': ', 1)[-1]}{warn}",
                        "pass" if v.passed else "fail", figure)
    return Headline(f"mean ΔE00 {report.mean_delta_e:.2f}, max {report.max_delta_e:.2f} "
                    f"({report.worst_patch}); no gate applied{warn}", "info", figure)


def _summary_facts(report: ChartReport) -> Facts:
    from fidelity.chart.measure import chart_statistics

    items = [("mean ΔE00 (chart ΔE)", _num(report.mean_delta_e)),
             ("max ΔE00", f"{_num(report.max_delta_e)} ({report.worst_patch})")]
    stats = chart_statistics(report.measurement)
    items += [("saturation (mean chroma of the colour patches)",
               f"{stats.saturation_percent:.1f} % of the reference"),
              ("white balance error (mean a*, b* of the neutral patches)",
               f"a\\* {stats.neutral_ab[0]:+.2f}, b\\* {stats.neutral_ab[1]:+.2f} "
               f"(ΔC\\*ab {stats.neutral_chroma:.2f})"),
              ("mean ΔL* of the neutral patches", f"{stats.neutral_delta_l:+.2f}")]
    if stats.snr_db is not None:
        items.append(("noise: signal-to-noise of the neutral patches (encoded sRGB)",
                      f"{stats.snr_db:.1f} dB (worst {stats.worst_snr_db:.1f} dB)"))
    if report.exposure_ev is not None:
        items.append(("exposure correction", f"{report.exposure_ev:+.3f} EV"))
    if report.bad_pixels is not None:
        w = report.bad_pixels.window
        items.append(("bad pixels in windows (NaN/Inf/negative)",
                      f"{w.total} ({w.nan}/{w.inf}/{w.negative})"))
    p = report.prediction
    if p is not None:
        b = "≤ " if p.table.kind == "published-bounds" else ""
        items += [("predicted ΔmAP, percentage points", b + _num(p.dmap_points)),
                  ("predicted ΔmAP, % of baseline", b + _num(p.dmap_relative)),
                  ("predicted person ΔAP, points", b + _num(p.dap_person_points)),
                  ("predicted bicycle ΔAP, points", b + _num(p.dap_bicycle_points)),
                  ("prediction table", f"{p.table.name} ({p.table.kind}), detector size "
                                       f"{p.size_used}")]
    d = report.directional
    if d is not None:
        items += [("direction-aware predicted ΔmAP, points", _num(d.dmap_points)),
                  ("direction-aware predicted person / bicycle ΔAP, points",
                   f"{_num(d.dap_person_points)} / {_num(d.dap_bicycle_points)}"),
                  ("bound of the verdict", _bound_words(report))]
    for m in report.measured:
        items.append((f"measured ΔmAP on COCO, {m.model}", m.summary().removeprefix(
            "measured ΔmAP ")))
    for spot in report.warnings:
        items.append(("blind-spot warning", spot.reason))
    src = report.source
    if isinstance(src, RenderSource):
        variant = f" ({src.variant})" if src.variant else ""
        items += [("camera", src.camera), ("illuminant", src.illuminant),
                  ("renderer", f"{src.renderer}{variant}, {src.seconds:.2f} s")]
    else:
        items += [("image", f"`{src.image.path}` ({src.image.format}, {src.image.pixel_type}, "
                            f"{src.image.width}x{src.image.height}, {src.encoding} pixels)")]
    items.append(("reference", src.reference))
    return Facts(tuple(items))


def _bound_words(report: ChartReport) -> str:
    v = report.verdict
    if v is None:
        return "no verdict"
    if v.criterion.kind != "max-dmap":
        return "neither: the verdict is on the chart ΔE"
    return ("direction-aware" if report.bound == "directional" else
            "classic (worst case over every transform)")


def _directional_section(report: ChartReport) -> Section | None:
    from fidelity.report import plots

    d = report.directional
    if d is None:
        return None
    pr = d.parts
    sh = pr.shares()
    facts = [("chart ΔE split by direction (ΔE00 units)",
              f"lightness {pr.lightness:.2f} ({100 * sh['lightness']:.0f} %), chroma "
              f"{pr.chroma:.2f} ({100 * sh['chroma']:.0f} %), hue {pr.hue:.2f} "
              f"({100 * sh['hue']:.0f} %)")]
    if d.fit is not None:
        facts.append(("best-fitting transform", f"{d.fit.fit} {d.fit.param:.4g}: explains "
                                                f"{100 * d.fit.explained:.0f} % of the error "
                                                f"(mean ΔE00 {d.fit.error:.2f} -> "
                                                f"{d.fit.residual:.2f})"))
    else:
        facts.append(("best-fitting transform", "none explains the error"))
    p = report.prediction
    facts.append(("predicted ΔmAP, classic / direction-aware",
                  f"{_num(p.dmap_points if p else None)} / {_num(d.dmap_points)} points"))
    rows = [(t.family, f"{100 * t.weight:.1f} %", _num(t.values.get("dmap_points")),
             t.sources.get("dmap_points", ""), t.reason) for t in d.terms]
    return section(
        "Direction-aware prediction",
        Text("Each part of the chart error is charged the worst loss of the SAFE-COLOR "
             "transforms that move the chart that way (`fidelity.prediction.directional`): "
             "loss = x·f(fitted family) + (1 − x)·Σ share·f(direction's family), every curve "
             "read at the chart ΔE. An empirical worst case validated on 30 camera models, "
             "not a guarantee."),
        Facts(tuple(facts)),
        table(("family", "weight", "its ΔmAP at this ΔE", "curve", "why"), rows,
              numeric=(False, True, True, False, False)),
        Figure(plots.family_curves(d, p), "family_curves.png",
               "worst case per transform family and the classic curve"),
        Text("\n".join(f"- {n}" for n in d.notes)))


def _blind_spot_section(report: ChartReport) -> Section | None:
    if not report.blind_spots:
        return None
    rows = [(b.kind, {True: "**at risk**", False: "no", None: "not judged"}[b.at_risk],
             _num(b.value, 3), b.reason) for b in report.blind_spots]
    return section("Blind spots of the chart ΔE", Text(
        "What a mean over 24 flat patches cannot see (`fidelity.chart.blindspots`): the tone "
        "of the deep shadows below the black patch, and posterisation (banding) of smooth "
        "gradients."), table(("check", "at risk", "value", "reason"), rows,
                             numeric=(False, False, True, False)))


def _measured_section(report: ChartReport) -> Section | None:
    if not report.measured:
        return None
    rows = []
    for m in report.measured:
        rows.append((m.model, str(m.images), f"{100 * m.baseline_map:.2f}",
                     f"{m.dmap_points:.2f} ± {_num(m.dmap_points_se)}",
                     f"{m.dmap_relative:.2f} ± {_num(m.dmap_relative_se)}",
                     f"{_num(m.dap_person_points)} ± {_num(m.dap_person_points_se)}",
                     f"{m.seconds:.0f} s" + ("" if m.inferred else " (cached)")))
    p, d = report.prediction, report.directional
    return section("Measured on COCO", Text(
        "The camera's colour rendering applied to COCO images (emulated: a colour mapping "
        "fitted to the camera or to the chart's patches), the same JPEG round trip as the "
        "ΔE = 0 baseline, ΔmAP against that baseline with the paired standard error of 5 "
        f"image folds (`fidelity.coco.measure`). Predicted: classic "
        f"{_num(p.dmap_points if p else None)}, direction-aware "
        f"{_num(d.dmap_points if d else None)} points."),
        table(("detector", "images", "baseline mAP (%)", "ΔmAP points ± SE",
               "ΔmAP % of baseline ± SE", "person ΔAP ± SE", "time"), rows))


def _limits(report: ChartReport) -> tuple[float | None, float | None]:
    """(ΔE limit, ΔmAP-points limit) of the report's verdict, where it has one."""
    if report.verdict is None:
        return None, None
    c = report.verdict.criterion
    if c.kind == "max-delta-e":
        return c.limit, None
    return None, (c.limit if c.cls == "all" and c.unit == "points" else None)


def _patch_table(report: ChartReport) -> Section:
    m = report.measurement
    rows = []
    for k, name in enumerate(m.patch_names):
        rows.append((name, _num(float(m.delta_e[k])), _num(float(m.delta_l[k])),
                     _num(float(m.delta_c[k])), _num(float(m.delta_h[k])),
                     *(_num(float(v)) for v in m.lab[k]),
                     *(_num(float(v)) for v in m.reference_lab[k])))
    return section("Patches", table(
        ("patch", "ΔE00", "ΔL'", "ΔC'", "ΔH'", "L*", "a*", "b*", "ref L*", "ref a*", "ref b*"),
        rows), folded=True)


def _prediction_sections(report: ChartReport, limit_de: float | None,
                         limit_dmap: float | None) -> list[Section]:
    from fidelity.report import plots

    p = report.prediction
    if p is None:
        return []
    blocks: list[Any] = []
    if p.table.curves:
        blocks.append(Figure(plots.prediction_curve(p, limit_dmap, limit_de),
                             "prediction.png", "predicted loss against chart ΔE"))
    notes = [f"- {n}" for n in p.notes]
    notes += [f"- {col}: {c.status}: {c.note}" for col, c in p.columns.items()]
    blocks.append(Text("\n".join(notes)))
    out = [section("ΔE → predicted detection loss", *blocks)]
    if p.transforms:
        out.append(section(
            f"SAFE-COLOR transforms that give ΔE {p.delta_e:.2f} on the chart",
            table(("transform", "parameter", "how"),
                  [(t.transform, _num(t.param, 4), str(t.method)) for t in p.transforms],
                  numeric=(False, True, False)), folded=True))
    return out


def chart_document(report: ChartReport, pixels: NDArray[Any] | None = None) -> Document:
    """The chart report as a :class:`~fidelity.report.document.Document`: the verdict and the
    chart first, then where the patches were sampled (an image, given its ``pixels``), the ΔE
    heat map, a*b* arrows, the neutral tone curve and ΔE per patch, the prediction; the patch
    table, transforms and provenance folded away."""
    from fidelity.chart.measure import neutral_patches
    from fidelity.report import plots

    m = report.measurement
    limit_de, limit_dmap = _limits(report)
    sections = [section("Summary", _summary_facts(report))]
    src = report.source
    if isinstance(src, ImageSource) and pixels is not None:
        sections.append(section("Where the patches were sampled", Figure(
            plots.chart_location(pixels, src.location, encoding=src.encoding,
                                 exposure_ev=report.exposure_ev or 0.0,
                                 found=src.found is not None),
            "location.png", "sampling windows")))
    neutral = neutral_patches(m)
    figures: list[Any] = [
        Figure(plots.delta_e_map(m, limit_de), "delta_e_map.png", "ΔE00 on the chart layout"),
        Figure(plots.ab_arrows(m), "ab_arrows.png", "a*b* errors",
               "Arrows from the reference colour to the measured one in the a\\*b\\* plane."),
    ]
    if neutral:
        figures.append(Figure(plots.tone_curve(m, neutral), "tone_curve.png",
                              "tone curve of the neutral patches"))
    figures.append(Figure(plots.delta_e_bars(m, limit_de), "delta_e_bars.png",
                          "ΔE00 per patch"))
    sections.append(section("Colour errors", *figures, gallery=True))
    sections += _prediction_sections(report, limit_de, limit_dmap)
    sections += [x for x in (_directional_section(report), _measured_section(report),
                             _blind_spot_section(report)) if x is not None]
    sections.append(_patch_table(report))
    prov = report.provenance
    sections.append(section("Provenance", Facts((
        ("tool", f"fidelity {prov.version}"), ("created", report.created),
        ("input sha256", prov.input_sha256 or "–"), ("python", prov.python),
        ("platform", prov.platform),
        ("libraries", ", ".join(f"{k} {v}" for k, v in prov.libraries.items())))),
        Code(json.dumps(json_ready(report.source.to_json()), indent=1, ensure_ascii=False)),
        Code(json.dumps(json_ready({k: t.to_json() for k, t in prov.tables.items()}), indent=1,
                        ensure_ascii=False)),
        Code(json.dumps(json_ready(dict(prov.conventions)), indent=1, ensure_ascii=False)),
        folded=True))
    return Document(f"Colour fidelity report: {src.title}", _headline(report),
                    tuple(sections),
                    footer=f"JSON schema: fidelity/data/schemas/report.schema.json "
                           f"(version {report.schema_version}).")


def write_chart_report(report: ChartReport, *, json_path: str | os.PathLike[str] | None = None,
                       html_path: str | os.PathLike[str] | None = None,
                       protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML report, atomically, refusing to write over any path in
    ``protect`` (the inputs). The HTML of an image report reads the image again to show where
    the patches were sampled. Returns the paths written."""
    from fidelity.fileio import check_outputs, write_json_atomic

    inputs = {f"input {i + 1}": p for i, p in enumerate(protect) if p}
    written: list[Path] = []
    if json_path is not None:
        check_outputs({"report": json_path}, inputs)
        written.append(write_json_atomic(json_path, report.to_json()))
    if html_path is not None:
        from fidelity.report.html import write_document

        check_outputs({"report": html_path}, inputs)
        pixels = None
        if isinstance(report.source, ImageSource):
            from fidelity.chart.image import read_image

            pixels = read_image(report.source.image.path, layer=report.source.image.layer,
                                bayer=report.source.image.bayer).pixels
        written += write_document(chart_document(report, pixels), html=html_path)
    return written


__all__ = [
    "BASE_CONVENTIONS",
    "COMMANDS",
    "SCHEMA_VERSION",
    "ChartReport",
    "ImageSource",
    "Provenance",
    "RenderSource",
    "Source",
    "TableRef",
    "chart_document",
    "report_schema",
    "report_schema_path",
    "utc_now",
    "validate_report",
    "write_chart_report",
]
