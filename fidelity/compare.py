"""Sim against real: the same chart photographed by the real camera and rendered by its model.

A simulator camera is credible when it behaves like the real camera it stands for.
:func:`compare_charts` audits both images (:func:`fidelity.check.audit_image`: any format,
the chart found or given by its corners), then compares the two charts patch by patch:

1. **Normalisation** (:data:`NORMALISATIONS`, stated in the report), applied to the simulated
   chart's linear patch colours so that it matches the real one on the neutral patches:
   ``exposure`` (default) scales it by the geometric-mean luminance ratio of the neutral
   patches (the exposure difference, in EV); ``exposure+wb`` also applies per-channel gains
   that make its neutral patches' summed R, G, B equal the real ones (a white-balance
   difference; these gains include the exposure); ``none`` compares the charts as audited.
2. **Sim-to-real ΔE**: CIEDE2000 per patch between the normalised simulated chart and the real
   chart (the real chart is the reference), its mean (the sim-to-real chart ΔE), maximum and
   the direction of each patch's difference (ΔL', ΔC', ΔH' of sim relative to real).
3. **What the difference costs a detector**: the sim-to-real chart ΔE through the prediction
   tables, classic and direction-aware (:mod:`fidelity.prediction.directional`), as if the real
   camera were the reference; with ``measure``, a colour mapping from the real chart's colours
   to the simulated chart's, fitted on the 24 patches
   (:class:`fidelity.coco.emulation.PatchEmulation`), applied to COCO photographs (as the real
   camera's images) and measured with a detector (:mod:`fidelity.coco.measure`).
4. **Verdict** of a criterion: ``max-delta-e`` on the sim-to-real chart ΔE, or ``max-dmap``
   on its predicted loss; exit codes and JUnit as ``fidelity gate``.

Each chart's own ΔE against the reference (its audit) is reported too.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.errors import InvalidValueError, unknown_name

if TYPE_CHECKING:
    from fidelity.chart.measure import ChartMeasurement
    from fidelity.coco.measure import MeasuredLoss, MeasureRequest
    from fidelity.prediction.directional import DirectionalPrediction
    from fidelity.prediction.table import Prediction
    from fidelity.prediction.verdict import Criterion, Verdict
    from fidelity.report.chart import ChartReport, Provenance
    from fidelity.report.document import Document

#: How the simulated chart is matched to the real one before comparing (module docstring).
NORMALISATIONS: tuple[str, ...] = ("exposure", "exposure+wb", "none")
#: JSON layout version of a comparison report.
COMPARE_SCHEMA_VERSION = "1.0"


@dataclass(frozen=True)
class Normalisation:
    """What was matched: the ``mode``, the exposure change applied to the simulated chart
    (``exposure_ev``, EV; 0 for ``none``) and the per-channel ``gains`` (``exposure+wb``:
    R, G, B, including the exposure; None otherwise)."""

    mode: str
    exposure_ev: float
    gains: tuple[float, float, float] | None = None

    def describe(self) -> str:
        """In words, for reports."""
        if self.mode == "none":
            return "none: the charts compared as audited"
        text = f"exposure of the simulation {self.exposure_ev:+.3f} EV (neutral patches)"
        if self.gains is not None:
            g = ", ".join(f"{v:.4f}" for v in self.gains)
            text += f"; white balance gains R, G, B {g} (neutral patches, incl. exposure)"
        return text

    def to_json(self) -> dict[str, Any]:
        """``{"mode", "exposure_ev", "gains", "description"}``."""
        return {"mode": self.mode, "exposure_ev": self.exposure_ev,
                "gains": list(self.gains) if self.gains is not None else None,
                "description": self.describe()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Normalisation:
        """Inverse of :meth:`to_json`."""
        g = d.get("gains")
        return cls(str(d["mode"]), float(d["exposure_ev"]),
                   (float(g[0]), float(g[1]), float(g[2])) if g else None)


def normalise(sim_srgb: NDArray[np.float64], real_srgb: NDArray[np.float64],
              neutral: Sequence[int], mode: str = "exposure"
              ) -> tuple[NDArray[np.float64], Normalisation]:
    """Match simulated patch colours (n, 3 encoded sRGB) to the real ones on the ``neutral``
    patches (module docstring); returns the normalised encoded sRGB (clipped to [0, 1]) and
    what was done."""
    from fidelity.chart.measure import luminance_linear_srgb
    from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb

    if mode not in NORMALISATIONS:
        raise unknown_name("normalisation", mode, NORMALISATIONS)
    sim = np.asarray(linearize_srgb(np.clip(sim_srgb, 0.0, 1.0)), np.float64)
    real = np.asarray(linearize_srgb(np.clip(real_srgb, 0.0, 1.0)), np.float64)
    idx = list(neutral)
    if mode == "none" or not idx:
        if mode != "none":
            raise InvalidValueError("the chart has no neutral patches to normalise on; use "
                                    "--normalise none")
        return np.clip(np.asarray(sim_srgb, np.float64), 0.0, 1.0), Normalisation("none", 0.0)
    ys, yr = luminance_linear_srgb(sim[idx]), luminance_linear_srgb(real[idx])
    ok = (ys > 0) & (yr > 0)
    if not np.any(ok):
        raise InvalidValueError("cannot normalise the exposure: the neutral patches are black "
                                "in one of the charts; use --normalise none")
    ev = float(np.mean(np.log2(yr[ok] / ys[ok])))
    sim = sim * 2.0 ** ev
    gains = None
    if mode == "exposure+wb":
        s, r = sim[idx].sum(axis=0), real[idx].sum(axis=0)
        if np.any(s <= 0):
            raise InvalidValueError("cannot normalise the white balance: a channel of the "
                                    "simulated neutral patches is black")
        g = r / s
        sim = sim * g
        gains = (float(g[0] * 2.0 ** ev), float(g[1] * 2.0 ** ev), float(g[2] * 2.0 ** ev))
    out = np.clip(np.asarray(delinearize_srgb(np.clip(sim, 0.0, None)), np.float64), 0.0, 1.0)
    return out, Normalisation(mode, ev, gains)


@dataclass(frozen=True)
class ComparisonReport:
    """A sim-to-real comparison (module docstring): the two audits (``sim``, ``real``:
    :class:`~fidelity.report.chart.ChartReport`), the :class:`Normalisation`, the sim-to-real
    ``measurement`` (the normalised simulated chart against the real chart as reference), the
    classic ``prediction`` and the ``directional`` one at the sim-to-real ΔE, the
    ``verdict``, which ``bound`` decided it, the losses ``measured`` on COCO, the mapping's
    description (``emulation``), when and with what it was made."""

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
        """The sim-to-real result as a :class:`~fidelity.report.chart.ChartReport` of the
        simulated image whose reference is the real chart (for JUnit and the verdict line)."""
        from dataclasses import replace

        from fidelity.report.chart import ChartReport, ImageSource

        src = self.sim.source
        assert isinstance(src, ImageSource)
        real_src = self.real.source
        real_name = real_src.title
        return ChartReport(
            command=self.command, created=self.created, measurement=self.measurement,
            source=replace(src, reference=f"the real camera's chart ({real_name})"),
            provenance=self.provenance, prediction=self.prediction, verdict=self.verdict,
            directional=self.directional, bound=self.bound, measured=self.measured)

    def to_json(self) -> dict[str, Any]:
        """The comparison as JSON: the sim-to-real summary and patches first, then the two
        audits (their own :meth:`~fidelity.report.chart.ChartReport.to_json`)."""
        from fidelity.fileio import json_ready

        m = self.measurement.to_json()
        out: dict[str, Any] = json_ready({
            "schema_version": self.schema_version, "command": self.command,
            "created": self.created,
            "sim_to_real": {"mean_delta_e": m["mean_delta_e"],
                            "max_delta_e": m["max_delta_e"], "worst_patch": m["worst_patch"],
                            "normalisation": self.normalisation.to_json(),
                            "patches": m["patches"]},
            "sim_delta_e": self.sim.mean_delta_e, "real_delta_e": self.real.mean_delta_e,
            "prediction": self.prediction.to_json(),
            "directional_prediction": (self.directional.to_json() if self.directional
                                       else None),
            "bound": self.bound,
            "verdict": self.verdict.to_json() if self.verdict else None,
            "measured_loss": [x.to_json() for x in self.measured],
            "emulation": dict(self.emulation) if self.emulation else None,
            "sim": self.sim.to_json(), "real": self.real.to_json(),
            "provenance": self.provenance.to_json()})
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ComparisonReport:
        """Inverse of :meth:`to_json`."""
        from fidelity.chart.measure import ChartMeasurement
        from fidelity.coco.measure import MeasuredLoss
        from fidelity.prediction.directional import DirectionalPrediction
        from fidelity.prediction.table import Prediction
        from fidelity.prediction.verdict import Verdict
        from fidelity.report.chart import ChartReport, Provenance

        s2r = d["sim_to_real"]
        return cls(
            created=str(d["created"]), sim=ChartReport.from_json(d["sim"]),
            real=ChartReport.from_json(d["real"]),
            normalisation=Normalisation.from_json(s2r["normalisation"]),
            measurement=ChartMeasurement.from_json(s2r),
            prediction=Prediction.from_json(d["prediction"]),
            directional=(DirectionalPrediction.from_json(d["directional_prediction"])
                         if d.get("directional_prediction") else None),
            verdict=Verdict.from_json(d["verdict"]) if d.get("verdict") else None,
            provenance=Provenance.from_json(d["provenance"]), bound=str(d.get("bound", "classic")),
            measured=tuple(MeasuredLoss.from_json(x) for x in d.get("measured_loss") or ()),
            emulation=d.get("emulation"), command=str(d.get("command", "compare")),
            schema_version=str(d.get("schema_version", COMPARE_SCHEMA_VERSION)))


def compare_charts(
    sim: str | os.PathLike[str],
    real: str | os.PathLike[str],
    *,
    sim_corners: str | Sequence[float] | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    reference: str = "scene",
    illuminant: str = "D65",
    size: str = "any",
    table: str | None = None,
    criterion: Criterion | None = None,
    bound: str = "classic",
    layer: str | None = None,
    encoding: str | None = None,
    exposure: str | None = None,
    negatives: str = "keep",
    colourspace: str | None = None,
    bayer: str | None = None,
    measure: MeasureRequest | None = None,
) -> ComparisonReport:
    """Compare the chart in the simulated image ``sim`` with the chart in the real camera's
    image ``real`` (module docstring).

    Parameters
    ----------
    sim, real
        Images (EXR, HDR, TIFF, PNG, JPEG) of the same chart, rendered by the simulator and
        photographed by the real camera.
    sim_corners, real_corners
        Each image's corner patch centres (see :func:`fidelity.check.audit_image`); None: found.
    normalise_mode
        ``exposure`` (default), ``exposure+wb`` or ``none`` (:data:`NORMALISATIONS`).
    reference, illuminant
        The reference each chart's own ΔE is measured against.
    size, table
        Detector size class and prediction table of the predicted loss.
    criterion
        ``max-delta-e`` on the sim-to-real chart ΔE, or ``max-dmap`` on its predicted loss
        (decided by ``bound``: ``classic`` or ``directional``); None: no verdict.
    layer, encoding, exposure, negatives, colourspace, bayer
        How both images are read (as ``audit``).
    measure
        Also measure the difference's cost on COCO (:class:`fidelity.coco.measure.MeasureRequest`).

    Returns
    -------
    ComparisonReport
    """
    from fidelity.chart.measure import measure_chart, neutral_patches
    from fidelity.check import _predict_and_judge, audit_image
    from fidelity.report.chart import Provenance, utc_now

    if normalise_mode not in NORMALISATIONS:
        raise unknown_name("normalisation", normalise_mode, NORMALISATIONS)
    kw: dict[str, Any] = {"layer": layer, "encoding": encoding, "exposure": exposure,
                          "reference": reference, "illuminant": illuminant, "size": size,
                          "table": table, "negatives": negatives, "colourspace": colourspace,
                          "bayer": bayer}
    sim_report = audit_image(sim, sim_corners, command="compare", **kw)
    real_report = audit_image(real, real_corners, command="compare", **kw)
    sm, rm = sim_report.measurement, real_report.measurement
    if sm.patch_names != rm.patch_names:
        raise InvalidValueError(f"{sim} and {real}: the charts have different patches")
    srgb, norm = normalise(sm.srgb, rm.srgb, neutral_patches(rm), normalise_mode)
    m = measure_chart(srgb, rm.lab, rm.patch_names, reference_srgb=np.clip(rm.srgb, 0, 1))
    prediction, verdict, directional = _predict_and_judge(m.mean_delta_e, size, table,
                                                          criterion, m, bound)
    measured: tuple[MeasuredLoss, ...] = ()
    emulation = None
    if measure is not None:
        from fidelity.coco.emulation import PatchEmulation

        emu = PatchEmulation.fit(np.clip(rm.srgb, 0, 1), srgb, neutral_patches(rm))
        emulation = emu.describe()
        measured = tuple(measure.run(emu.apply_uint8, emu.key(), {
            "sim": str(sim), "real": str(real), "normalisation": norm.to_json(),
            "emulation": emulation}))
    conventions = {"compare": "both images audited as fidelity audit does; simulated patch "
                              "colours normalised to the real ones on the neutral patches ("
                              + norm.describe() + "); sim-to-real ΔE00 with the real chart as "
                              "the reference; the loss predicted from the sim-to-real chart "
                              "ΔE with the same tables as a chart's own ΔE"}
    prov = Provenance.collect(sim_report.provenance.input_sha256, prediction,
                              {**dict(sim_report.provenance.conventions), **conventions})
    return ComparisonReport(utc_now(), sim_report, real_report, norm, m, prediction,
                            directional, verdict, prov, bound, measured, emulation)


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


def comparison_lines(report: ComparisonReport) -> list[str]:
    """The comparison on a terminal: each chart's ΔE, the normalisation, the sim-to-real ΔE
    with its direction, the predicted (and measured) loss, warnings and the verdict."""
    from fidelity.report.terminal import directional_lines

    sim, real = report.sim, report.real
    m = report.measurement
    lines = [f"simulation {sim.source.title}: chart ΔE00 {sim.mean_delta_e:.2f} against the "
             f"reference ({sim.source.reference_description})",
             f"real camera {real.source.title}: chart ΔE00 {real.mean_delta_e:.2f} against "
             "the reference",
             f"normalisation: {report.normalisation.describe()}",
             f"sim-to-real ΔE00: mean {m.mean_delta_e:.2f}, max {m.max_delta_e:.2f} "
             f"({m.worst_patch}); mean ΔL' {float(np.mean(m.delta_l)):+.2f}, ΔC' "
             f"{float(np.mean(m.delta_c)):+.2f}, |ΔH'| {float(np.mean(np.abs(m.delta_h))):.2f} "
             "(simulation relative to the real camera)"]
    p = report.prediction

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f}"

    lines.append(f"predicted ΔmAP of the difference: {f(p.dmap_points)} points, "
                 f"{f(p.dmap_relative)} % of baseline (classic, table {p.table.name}, "
                 f"detector size {p.size_used})")
    lines += directional_lines(report.as_chart_report())
    lines += [f"measured on COCO (real -> simulated colours): {x.summary()}"
              for x in report.measured]
    for who, r in (("simulation", sim), ("real camera", real)):
        lines += [f"warning ({who}): {w.reason}" for w in r.warnings]
    if report.verdict is not None:
        lines.append(report.verdict.message.replace("mean ΔE00", "sim-to-real ΔE00"))
    return lines


def comparison_document(report: ComparisonReport, sim_pixels: NDArray[Any] | None = None,
                        real_pixels: NDArray[Any] | None = None) -> Document:
    """The comparison as a :class:`~fidelity.report.document.Document`: the verdict first,
    then the two charts side by side, the sim-to-real ΔE map, the a*b* arrows from the
    simulated to the real colours, the direction of each difference, the predictions, each
    chart's own audit and the provenance."""
    from dataclasses import replace

    from fidelity.report import plots
    from fidelity.report.chart import (
        ImageSource,
        _blind_spot_section,
        _directional_section,
        _measured_section,
    )
    from fidelity.report.document import (
        Code,
        Document,
        Facts,
        Figure,
        Headline,
        Text,
        section,
        table,
    )

    m = report.measurement
    v = report.verdict
    swatch = Figure(plots.swatches(m, ("real camera", "simulation")), "swatches.png",
                    "real camera (left half) against simulation (right half)")
    warn = "".join(f"\n\n**warning** ({who}): {w.reason}"
                   for who, r in (("simulation", report.sim), ("real camera", report.real))
                   for w in r.warnings)
    if v is not None:
        head = Headline(f"**{v.label}**: {v.message.split(': ', 1)[-1].replace('mean ΔE00', 'sim-to-real ΔE00')}{warn}",
                        "pass" if v.passed else "fail", swatch)
    else:
        head = Headline(f"sim-to-real ΔE00 mean {m.mean_delta_e:.2f}, max "
                        f"{m.max_delta_e:.2f} ({m.worst_patch}); no gate applied{warn}",
                        "info", swatch)
    p, d = report.prediction, report.directional

    def n2(x: float | None) -> str:
        return "–" if x is None else f"{x:.2f}"

    facts = Facts((
        ("simulation", f"`{report.sim.source.title}`: chart ΔE00 {report.sim.mean_delta_e:.2f}"),
        ("real camera", f"`{report.real.source.title}`: chart ΔE00 "
                        f"{report.real.mean_delta_e:.2f}"),
        ("reference of each chart", report.sim.source.reference_description),
        ("normalisation", report.normalisation.describe()),
        ("sim-to-real ΔE00", f"mean {m.mean_delta_e:.2f}, max {m.max_delta_e:.2f} "
                             f"({m.worst_patch})"),
        ("mean direction (simulation − real)",
         f"ΔL' {float(np.mean(m.delta_l)):+.2f}, ΔC' {float(np.mean(m.delta_c)):+.2f}, "
         f"|ΔH'| {float(np.mean(np.abs(m.delta_h))):.2f}"),
        ("predicted ΔmAP of the difference, classic", f"{n2(p.dmap_points)} points "
                                                      f"({p.table.name})"),
        ("predicted ΔmAP of the difference, direction-aware",
         f"{n2(d.dmap_points if d else None)} points"),
        *((f"measured ΔmAP on COCO, {x.model}", x.summary().removeprefix("measured ΔmAP "))
          for x in report.measured)))
    sections = [section("Summary", facts)]
    ss, rs = report.sim.source, report.real.source
    if (sim_pixels is not None and real_pixels is not None and isinstance(ss, ImageSource)
            and isinstance(rs, ImageSource)):
        sections.append(section("The two charts", Figure(plots.chart_pair(
            (sim_pixels, ss.location, ss.encoding, report.sim.exposure_ev or 0.0),
            (real_pixels, rs.location, rs.encoding, report.real.exposure_ev or 0.0),
            (f"simulation: {Path(ss.title).name}", f"real camera: {Path(rs.title).name}")),
            "charts.png", "the simulated and the real chart, sampling windows outlined")))
    reversed_m = replace(m, lab=m.reference_lab, reference_lab=m.lab, srgb=m.reference_srgb
                         if m.reference_srgb is not None else m.srgb, reference_srgb=m.srgb)
    limit = (v.criterion.limit if v is not None and v.criterion.kind == "max-delta-e"
             else None)
    rows = [(name, f"{m.delta_e[k]:.2f}", f"{m.delta_l[k]:+.2f}", f"{m.delta_c[k]:+.2f}",
             f"{m.delta_h[k]:+.2f}", f"{report.sim.measurement.delta_e[k]:.2f}",
             f"{report.real.measurement.delta_e[k]:.2f}")
            for k, name in enumerate(m.patch_names)]
    sections.append(section(
        "Sim-to-real differences",
        Figure(plots.delta_e_map(m, limit), "delta_e_map.png", "sim-to-real ΔE00 per patch"),
        Figure(plots.ab_arrows(reversed_m, ("simulation", "real camera")), "ab_arrows.png",
               "a*b*: arrows from the simulated colour to the real one"),
        table(("patch", "sim-to-real ΔE00", "ΔL'", "ΔC'", "ΔH'", "sim ΔE00 to reference",
               "real ΔE00 to reference"), rows)))
    chart_view = report.as_chart_report()
    sections += [s for s in (_directional_section(chart_view), _measured_section(chart_view))
                 if s is not None]
    for who, r in (("simulation", report.sim), ("real camera", report.real)):
        bs = _blind_spot_section(r)
        if bs is not None:
            sections.append(replace(bs, title=f"Blind spots: {who}", folded=True))
    if report.emulation:
        sections.append(section("The fitted mapping (real -> simulated colours)",
                                Code(_json(report.emulation)), folded=True))
    sections.append(section("Provenance", Text(f"Created {report.created}; fidelity "
                                               f"{report.provenance.version}."),
                            Code(_json(dict(report.provenance.conventions))), folded=True))
    return Document(f"Sim against real: {Path(ss.title).name} vs {Path(rs.title).name}", head,
                    tuple(sections))


def _json(obj: Any) -> str:
    import json

    from fidelity.fileio import json_ready

    return json.dumps(json_ready(obj), indent=1, ensure_ascii=False)


def write_comparison_report(report: ComparisonReport, *,
                            json_path: str | os.PathLike[str] | None = None,
                            html_path: str | os.PathLike[str] | None = None,
                            protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML comparison report atomically, never over an input."""
    from fidelity.fileio import check_outputs, write_json_atomic

    inputs = {f"input {i + 1}": p for i, p in enumerate(protect) if p}
    written: list[Path] = []
    if json_path is not None:
        check_outputs({"report": json_path}, inputs)
        written.append(write_json_atomic(json_path, report.to_json()))
    if html_path is not None:
        from fidelity.chart.image import read_image
        from fidelity.report.chart import ImageSource
        from fidelity.report.html import write_document

        check_outputs({"report": html_path}, inputs)
        pix = []
        for r in (report.sim, report.real):
            src = r.source
            pix.append(read_image(src.image.path, layer=src.image.layer,
                                  bayer=src.image.bayer).pixels
                       if isinstance(src, ImageSource) else None)
        written += write_document(comparison_document(report, pix[0], pix[1]), html=html_path)
    return written


__all__ = [
    "COMPARE_SCHEMA_VERSION",
    "NORMALISATIONS",
    "ComparisonReport",
    "Normalisation",
    "compare_charts",
    "comparison_document",
    "comparison_lines",
    "normalise",
    "write_comparison_report",
]
