"""The sim-to-real comparison as terminal lines, an HTML document and report files.

Renders a :class:`~fidelity.pipeline.records.ComparisonReport` (:func:`fidelity.pipeline.compare.compare_charts`):
:func:`comparison_lines` for the terminal, :func:`comparison_document` for the HTML report (the
chart report's section builders, :mod:`fidelity.report.chart`, for the parts the two share) and
:func:`write_comparison_report` for the files.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.core.fileio import json_ready
from fidelity.pipeline.records import ComparisonReport, ImageSource
from fidelity.pipeline.simreal import TextureComparison
from fidelity.report import chartfigures
from fidelity.report.chart import (
    blind_spot_section,
    directional_section,
    measured_section,
    source_pixels,
    write_report_files,
)
from fidelity.report.document import (
    Code,
    Document,
    Facts,
    Headline,
    Section,
    Text,
    section,
    svg_figure,
    table,
)
from fidelity.report.jsonform import comparison_json
from fidelity.report.terminal import directional_lines, outside_line
from fidelity.report.words import verdict_message


def comparison_lines(report: ComparisonReport) -> list[str]:
    """The comparison on a terminal: each chart's ΔE, the normalisation, the sim-to-real ΔE
    with its direction, the predicted (and measured) loss, warnings and the verdict."""
    sim, real = report.sim, report.real
    m = report.measurement
    lines = [f"simulation {sim.source.title}: chart ΔE00 {sim.mean_delta_e:.2f} against the "
             f"reference ({sim.source.reference_description})",
             f"real camera {real.source.title}: chart ΔE00 {real.mean_delta_e:.2f} against "
             "the reference",
             f"normalisation: {report.normalisation.describe()}",
             *([f"exposure: {w}"] if (w := report.normalisation.difference_words()) else []),
             f"sim-to-real ΔE00: mean {m.mean_delta_e:.2f}, max {m.max_delta_e:.2f} "
             f"({m.worst_patch}); mean ΔL' {float(np.mean(m.delta_l)):+z.2f}, ΔC' "
             f"{float(np.mean(m.delta_c)):+z.2f}, |ΔH'| {float(np.mean(np.abs(m.delta_h))):.2f} "
             "(simulation relative to the real camera)"]
    if report.uncertainty is not None:
        lines.append(report.uncertainty.text())
    p = report.prediction

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f}"

    pm = report.interval.plus_minus() if report.interval is not None else ""
    lines.append(f"predicted ΔmAP of the difference: {f(p.dmap_points)}{pm} points, "
                 f"{f(p.dmap_relative)}{column_pm(report, 'dmap_relative')} % of baseline "
                 f"(classic, table {p.table.name}, detector size {p.size_used})")
    lines.append(f"predicted ΔAP of the difference: person {f(p.dap_person_points)}"
                 f"{column_pm(report, 'dap_person_points')} points, bicycle "
                 f"{f(p.dap_bicycle_points)}{column_pm(report, 'dap_bicycle_points')} points"
                 + swamped_note(report))
    if report.validity is not None and not report.validity.inside:
        lines.append(outside_line(report.validity))
    lines += directional_lines(report.as_chart_report())
    lines += property_comparison_lines(sim.properties, real.properties)
    lines += [f"measured on COCO (real -> simulated colours): {x.summary()}"
              for x in report.measured]
    for who, r in (("simulation", sim), ("real camera", real)):
        lines += [f"warning ({who}): {w.reason}" for w in r.warnings]
    if report.verdict is not None:
        lines.append(verdict_message(report.verdict, "sim-to-real ΔE00"))
    return lines


def column_pm(report: ComparisonReport, column: str) -> str:
    """``" ± 0.69"``: the standard uncertainty (k = 1) of one loss column of a comparison's
    prediction (its own table SE and the sim-to-real ΔE's uncertainty through that column's
    slope, :func:`fidelity.pipeline.check.column_intervals`); empty without one."""
    i = next((i for i in report.intervals if i.column == column), None)
    return "" if i is None else f" ± {i.standard_uncertainty:.2f}"


#: The loss columns besides the ΔmAP in points, by the name the reports give them.
OTHER_COLUMNS = (("% of baseline", "dmap_relative"), ("person", "dap_person_points"),
                 ("bicycle", "dap_bicycle_points"))


def swamped_note(report: ComparisonReport) -> str:
    """`` (k=1; bicycle: u >= the value, mostly noise)``: the coverage factor of the ± and
    the columns whose uncertainty swamps their value; empty without intervals."""
    if not report.intervals:
        return ""
    swamped = [name for name, column in OTHER_COLUMNS
               if any(i.column == column and i.swamped for i in report.intervals)]
    return " (k=1" + (f"; {', '.join(swamped)}: u >= the value, mostly noise"
                      if swamped else "") + ")"


def property_comparison_lines(sim: Any, real: Any) -> list[str]:
    """Sharpness and noise, simulation against real camera, where both were judged
    (:class:`fidelity.prediction.properties.PropertyJudgement` of each chart): the MTF50
    ratio and the SNR difference in dB at the detector's input, and each one's predicted
    loss."""
    if sim is None or real is None:
        return []
    lines = []
    for prop in ("sharpness", "noise"):
        a, b = sim.prediction(prop), real.prediction(prop)
        if a is None or b is None:
            continue
        if prop == "sharpness":
            how = (f"MTF50 {a.x:.3g} against {b.x:.3g} cy/px (ratio {a.x / b.x:.2f})")
        else:
            db = ("" if math.isinf(a.x) or math.isinf(b.x)
                  else f", {20 * math.log10(a.x / b.x):+z.1f} dB")
            how = f"SNR {a.x:.3g} against {b.x:.3g}{db}"
        lines.append(f"{prop}, simulation against real camera at the detector's input: {how}; "
                     f"predicted ΔmAP {a.loss:.2f} against {b.loss:.2f} points")
    return lines


#: Title of the comparison's sharpness and noise section (:func:`texture_section`).
TEXTURE_TITLE = "Sharpness and noise, simulation against real camera"


def texture_lines(t: TextureComparison) -> list[str]:
    """The MTF50 ratio and the SNR difference of a
    :class:`~fidelity.pipeline.simreal.TextureComparison` in words, or why each was not
    compared."""
    lines = []
    a, b = t.sim, t.real
    if t.mtf50_ratio is not None and a.mtf50 is not None and b.mtf50 is not None:
        lines.append(f"sharpness: luminance MTF50 {a.mtf50:.3g} cy/px (simulation, "
                     f"{a.direction} edge, {a.method}) against {b.mtf50:.3g} cy/px (real "
                     f"camera, {b.direction} edge, {b.method}): ratio {t.mtf50_ratio:.2f} "
                     "(each chart's softer edge at its own resolution)")
    if t.snr_difference_db is not None and a.grey_snr_db is not None \
            and b.grey_snr_db is not None:
        lines.append(f"noise: SNR at the 18 % grey {a.grey_snr_db:.1f} dB (simulation) "
                     f"against {b.grey_snr_db:.1f} dB (real camera): "
                     f"{t.snr_difference_db:+z.1f} dB")
    lines += [f"{prop} not compared: {why}" for prop, why in t.not_compared]
    return lines


def texture_section(report: ComparisonReport) -> Section | None:
    """Sharpness and noise, simulation against real camera (:data:`TEXTURE_TITLE`): the two
    luminance MTF curves with each one's MTF50 where both were measured, the two charts'
    neutral-patch noise against signal with each one's photon-transfer line where both were
    measured, and :func:`texture_lines`; None where neither could be drawn (the reason is
    then a line of the summary, :func:`texture_facts`)."""
    t = report.texture
    if t is None:
        return None
    a, b = t.sim, t.real
    blocks: list[Any] = []
    if a.mtf50 is not None and b.mtf50 is not None and a.frequencies and b.frequencies:
        xmax = 0.5 if max(a.mtf50, b.mtf50) <= 0.45 else 1.0
        blocks.append(svg_figure(chartfigures.mtf_curves(
            (("simulation", a.frequencies, a.mtf, a.mtf50),
             ("real camera", b.frequencies, b.mtf, b.mtf50)), xmax),
            "mtf_curves.svg", "luminance MTF of each chart's softer edge, MTF50 marked"))
    if a.noise_missing is None and b.noise_missing is None and a.mu and b.mu:
        def fit(s: Any) -> tuple[float, float] | None:
            return None if s.read_variance is None else (s.read_variance, s.gain)
        blocks.append(svg_figure(chartfigures.noise_curves(
            (("simulation", a.mu, a.sigma, fit(a)), ("real camera", b.mu, b.sigma, fit(b)))),
            "noise_curves.svg", "neutral patches: σ against μ with each photon-transfer fit"))
        rows = [(who, name, f"{mu:.4g}", f"{sg:.3g}",
                 "∞" if sg == 0 else f"{mu / sg:.1f}")
                for who, s in (("simulation", a), ("real camera", b))
                for name, mu, sg in zip(s.patches, s.mu, s.sigma, strict=True)]
        refused = "; ".join(f"{who}: photon transfer refused, {s.fit_refusal}"
                            for who, s in (("simulation", a), ("real camera", b))
                            if s.fit_refusal)
        blocks.append(table(("chart", "patch", "μ", "σ", "SNR μ/σ"), rows,
                            numeric=(False, False, True, True, True), caption=refused))
    if not blocks:
        return None
    return section(TEXTURE_TITLE, Text("\n\n".join(texture_lines(t))), *blocks)


def texture_facts(report: ComparisonReport, drawn: Section | None) -> list[tuple[str, str]]:
    """The summary row that says why sharpness and noise were not compared at all (none
    where :func:`texture_section` drew them, ``drawn``)."""
    t = report.texture
    if t is None or drawn is not None:
        return []
    return [(TEXTURE_TITLE.lower(), "; ".join(texture_lines(t)))]


def comparison_document(report: ComparisonReport, sim_pixels: NDArray[Any] | None = None,
                        real_pixels: NDArray[Any] | None = None) -> Document:
    """The comparison as a :class:`~fidelity.report.document.Document`: the verdict first,
    then the two charts side by side, the sim-to-real ΔE map, the a*b* arrows from the
    simulated to the real colours, the two charts' sharpness and noise
    (:func:`texture_section`), the direction of each difference, the predictions, each
    chart's own audit and the provenance."""
    m = report.measurement
    v = report.verdict
    swatch = svg_figure(chartfigures.swatches(m, ("real camera", "simulation")),
                        "swatches.svg", "real camera (left half) against simulation (right half)")
    warn = "".join(f"\n\n**warning** ({who}): {w.reason}"
                   for who, r in (("simulation", report.sim), ("real camera", report.real))
                   for w in r.warnings)
    validity = report.validity
    outside = validity is not None and not validity.inside
    if validity is not None and outside:
        warn = f"\n\n**{outside_line(validity)}**{warn}"
    if v is not None:
        message = verdict_message(v, "sim-to-real ΔE00").split(": ", 1)[-1]
        label = f"{v.label} — outside the validity domain" if outside else v.label
        head = Headline(f"**{label}**: {message}{warn}",
                        "fail" if not v.passed else "outside" if outside else "pass", swatch)
    else:
        head = Headline(f"sim-to-real ΔE00 mean {m.mean_delta_e:.2f}, max "
                        f"{m.max_delta_e:.2f} ({m.worst_patch}); no gate applied{warn}",
                        "info", swatch)
    p, d = report.prediction, report.directional

    def n2(x: float | None) -> str:
        return "–" if x is None else f"{x:.2f}"

    u = report.uncertainty
    ts = texture_section(report)
    mean = f"{m.mean_delta_e:.2f}" if u is None else u.value_text()
    pm = report.interval.plus_minus() if report.interval is not None else ""
    facts = Facts((
        ("simulation", f"`{report.sim.source.title}`: chart ΔE00 {report.sim.mean_delta_e:.2f}"),
        ("real camera", f"`{report.real.source.title}`: chart ΔE00 "
                        f"{report.real.mean_delta_e:.2f}"),
        ("reference of each chart", report.sim.source.reference_description),
        ("normalisation", report.normalisation.describe()),
        *([("exposure difference", w)] if (w := report.normalisation.difference_words())
          else []),
        ("sim-to-real ΔE00", f"mean {mean}, max {m.max_delta_e:.2f} ({m.worst_patch})"),
        ("mean direction (simulation − real)",
         f"ΔL' {float(np.mean(m.delta_l)):+z.2f}, ΔC' {float(np.mean(m.delta_c)):+z.2f}, "
         f"|ΔH'| {float(np.mean(np.abs(m.delta_h))):.2f}"),
        ("predicted ΔmAP of the difference, classic", f"{n2(p.dmap_points)}{pm} points, "
                                                      f"{n2(p.dmap_relative)}"
                                                      f"{column_pm(report, 'dmap_relative')} "
                                                      f"% of baseline ({p.table.name})"),
        ("predicted ΔAP of the difference, classic",
         f"person {n2(p.dap_person_points)}{column_pm(report, 'dap_person_points')} points, "
         f"bicycle {n2(p.dap_bicycle_points)}{column_pm(report, 'dap_bicycle_points')} points"
         + swamped_note(report)),
        ("predicted ΔmAP of the difference, direction-aware",
         f"{n2(d.dmap_points if d else None)} points"),
        *((f"measured ΔmAP on COCO, {x.model}", x.summary().removeprefix("measured ΔmAP "))
          for x in report.measured),
        *texture_facts(report, ts)))
    sections = [section("Summary", facts)]
    ss, rs = report.sim.source, report.real.source
    if (sim_pixels is not None and real_pixels is not None and isinstance(ss, ImageSource)
            and isinstance(rs, ImageSource)):
        sections.append(section("The two charts", svg_figure(chartfigures.chart_pair(
            (sim_pixels, ss.location, ss.encoding, report.sim.exposure_ev or 0.0),
            (real_pixels, rs.location, rs.encoding, report.real.exposure_ev or 0.0),
            (f"simulation: {ss.name}", f"real camera: {rs.name}")),
            "charts.svg", "the simulated and the real chart, sampling windows outlined")))
    reversed_m = replace(m, lab=m.reference_lab, reference_lab=m.lab, srgb=m.reference_srgb
                         if m.reference_srgb is not None else m.srgb, reference_srgb=m.srgb)
    limit = (v.criterion.limit if v is not None and v.criterion.kind == "max-delta-e"
             else None)
    rows = [(name, f"{m.delta_e[k]:.2f}", f"{m.delta_l[k]:+z.2f}", f"{m.delta_c[k]:+z.2f}",
             f"{m.delta_h[k]:+z.2f}", f"{report.sim.measurement.delta_e[k]:.2f}",
             f"{report.real.measurement.delta_e[k]:.2f}")
            for k, name in enumerate(m.patch_names)]
    sections.append(section(
        "Sim-to-real differences",
        svg_figure(chartfigures.delta_e_map(m, limit), "delta_e_map.svg",
                   "sim-to-real ΔE00 per patch"),
        svg_figure(chartfigures.ab_arrows(reversed_m, ("simulation", "real camera")),
                   "ab_arrows.svg", "a*b*: arrows from the simulated colour to the real one"),
        table(("patch", "sim-to-real ΔE00", "ΔL'", "ΔC'", "ΔH'", "sim ΔE00 to reference",
               "real ΔE00 to reference"), rows)))
    if ts is not None:
        sections.append(ts)
    chart_view = report.as_chart_report()
    sections += [s for s in (directional_section(chart_view), measured_section(chart_view))
                 if s is not None]
    for who, r in (("simulation", report.sim), ("real camera", report.real)):
        bs = blind_spot_section(r)
        if bs is not None:
            sections.append(replace(bs, title=f"Blind spots: {who}", folded=True))
    if report.emulation:
        sections.append(section("The fitted mapping (real -> simulated colours)",
                                Code(_json(report.emulation)), folded=True))
    sections.append(section("Provenance", Text(f"Created {report.created}; fidelity "
                                               f"{report.provenance.version}."),
                            Code(_json(dict(report.provenance.conventions))), folded=True))
    return Document(f"Sim against real: {ss.name} vs {rs.name}", head,
                    tuple(sections))


def _json(obj: Any) -> str:
    return json.dumps(json_ready(obj), indent=1, ensure_ascii=False)


def write_comparison_report(report: ComparisonReport, *,
                            json_path: str | os.PathLike[str] | None = None,
                            html_path: str | os.PathLike[str] | None = None,
                            protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML comparison report atomically, never over an input.

    The HTML reads both images again to show where their patches were sampled.

    Parameters
    ----------
    report
        The comparison of a simulated and a real chart
        (:func:`fidelity.pipeline.compare.compare_charts`).
    json_path
        Where to write the JSON report; None: no JSON.
    html_path
        Where to write the self-contained HTML report; None: no HTML.
    protect
        Paths that must not be written over (the command's inputs: both images, tables);
        empty entries are skipped.

    Returns
    -------
    list of pathlib.Path
        The files written, JSON first; empty when neither path is given.

    Raises
    ------
    InputFileError
        An output path that is an input or inside an input folder, or an existing folder
        (each output is checked just before it is written). Exit code 2.
    """
    return write_report_files(
        lambda: comparison_json(report),
        lambda: comparison_document(report, source_pixels(report.sim),
                                    source_pixels(report.real)),
        json_path=json_path, html_path=html_path, protect=protect)


__all__ = ["TEXTURE_TITLE", "comparison_document", "comparison_lines", "texture_facts",
           "texture_lines", "texture_section", "write_comparison_report"]
