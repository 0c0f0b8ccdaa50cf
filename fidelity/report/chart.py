"""The chart report as a document: a :class:`~fidelity.records.ChartReport` turned into HTML.

The HTML report (:func:`chart_document`, written by :mod:`fidelity.report.html`) puts the
verdict and the chart first, then the figures a colour scientist expects (ΔE heat map on the
chart, a*b* arrows, the neutral tone curve, ΔE per patch, the prediction curve with the limit)
and folds the patch table, the transforms and the provenance away. The section builders are
public: the sim-to-real report (:mod:`fidelity.report.compare`) uses them too.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from numpy.typing import NDArray

from fidelity.fileio import JSONObject, json_ready
from fidelity.records import ChartReport, ImageSource, RenderSource
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
from fidelity.report.jsonform import chart_report_json
from fidelity.report.words import column_note, prediction_notes, verdict_message

# ---------------------------------------------------------------------- the HTML document

def _num(v: float | None, nd: int = 2) -> str:
    return "–" if v is None else f"{v:.{nd}f}"


def headline(report: ChartReport) -> Headline:
    from fidelity.report import plots

    figure = Figure(plots.swatches(report.measurement), "swatches.png",
                    "the chart: reference against measured",
                    "Each patch: reference colour (left half) and measured colour (right half).")
    v = report.verdict
    warn = "".join(f"\n\n**warning**: {w.reason}" for w in report.warnings)
    if v is not None:
        return Headline(f"**{v.label}**: {verdict_message(v).split(': ', 1)[-1]}{warn}",
                        "pass" if v.passed else "fail", figure)
    return Headline(f"mean ΔE00 {report.mean_delta_e:.2f}, max {report.max_delta_e:.2f} "
                    f"({report.worst_patch}); no gate applied{warn}", "info", figure)


def summary_facts(report: ChartReport) -> Facts:
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
        b = "≤ " if p.table.kind.upper_bound else ""
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
                  ("bound of the verdict", bound_words(report))]
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


def bound_words(report: ChartReport) -> str:
    v = report.verdict
    if v is None:
        return "no verdict"
    if v.criterion.kind != "max-dmap":
        return "neither: the verdict is on the chart ΔE"
    return ("direction-aware" if report.bound == "directional" else
            "classic (worst case over every transform)")


def directional_section(report: ChartReport) -> Section | None:
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


def blind_spot_section(report: ChartReport) -> Section | None:
    if not report.blind_spots:
        return None
    rows = [(b.kind, {True: "**at risk**", False: "no", None: "not judged"}[b.at_risk],
             _num(b.value, 3), b.reason) for b in report.blind_spots]
    return section("Blind spots of the chart ΔE", Text(
        "What a mean over 24 flat patches cannot see (`fidelity.chart.blindspots`): the tone "
        "of the deep shadows below the black patch, and posterisation (banding) of smooth "
        "gradients."), table(("check", "at risk", "value", "reason"), rows,
                             numeric=(False, False, True, False)))


def measured_section(report: ChartReport) -> Section | None:
    if not report.measured:
        return None
    rows = []
    for m in report.measured:
        rows.append((m.model, str(m.images), f"{100 * m.baseline_map:.2f}",
                     f"{m.dmap_points:.2f} ± {_num(m.dmap_points_se)}",
                     f"{_num(m.dmap_relative)} ± {_num(m.dmap_relative_se)}",
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


def verdict_limits(report: ChartReport) -> tuple[float | None, float | None]:
    """(ΔE limit, ΔmAP-points limit) of the report's verdict, where it has one."""
    if report.verdict is None:
        return None, None
    c = report.verdict.criterion
    if c.kind == "max-delta-e":
        return c.limit, None
    return None, (c.limit if c.cls == "all" and c.unit == "points" else None)


def patch_section(report: ChartReport) -> Section:
    m = report.measurement
    rows = []
    for k, name in enumerate(m.patch_names):
        why = m.excluded.get(name)
        shown = f"{name} (left out: {why.split(':')[0]})" if why else name
        rows.append((shown, _num(float(m.delta_e[k])), _num(float(m.delta_l[k])),
                     _num(float(m.delta_c[k])), _num(float(m.delta_h[k])),
                     *(_num(float(v)) for v in m.lab[k]),
                     *(_num(float(v)) for v in m.reference_lab[k])))
    return section("Patches", table(
        ("patch", "ΔE00", "ΔL'", "ΔC'", "ΔH'", "L*", "a*", "b*", "ref L*", "ref a*", "ref b*"),
        rows), folded=True)


def prediction_sections(report: ChartReport, limit_de: float | None,
                         limit_dmap: float | None) -> list[Section]:
    from fidelity.report import plots

    p = report.prediction
    if p is None:
        return []
    blocks: list[Any] = []
    if p.table.curves:
        blocks.append(Figure(plots.prediction_curve(p, limit_dmap, limit_de),
                             "prediction.png", "predicted loss against chart ΔE"))
    notes = [f"- {n}" for n in prediction_notes(p)]
    notes += [f"- {col}: {c.status}: {column_note(p, col)}" for col, c in p.columns.items()]
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
    limit_de, limit_dmap = verdict_limits(report)
    sections = [section("Summary", summary_facts(report))]
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
    sections += prediction_sections(report, limit_de, limit_dmap)
    sections += [x for x in (directional_section(report), measured_section(report),
                             blind_spot_section(report)) if x is not None]
    sections.append(patch_section(report))
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
    return Document(f"Colour fidelity report: {src.title}", headline(report),
                    tuple(sections),
                    footer=f"JSON schema: fidelity/data/schemas/report.schema.json "
                           f"(version {report.schema_version}).")


def source_pixels(report: ChartReport) -> NDArray[Any] | None:
    """The pixels of an image report's image, read again as the audit read it (None for a
    render): the HTML shows where the patches were sampled."""
    from fidelity.chart.measure import read_again

    src = report.source
    if not isinstance(src, ImageSource):
        return None
    return read_again(src.image).pixels


def write_report_files(json_document: Callable[[], JSONObject],
                       html_document: Callable[[], Document], *,
                       json_path: str | os.PathLike[str] | None = None,
                       html_path: str | os.PathLike[str] | None = None,
                       protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write a report's JSON and/or HTML atomically, refusing to write over any path in
    ``protect`` (the inputs); each document is made only when its file is asked for. Returns
    the paths written."""
    from fidelity.fileio import check_outputs, write_json_atomic

    inputs = {f"input {i + 1}": p for i, p in enumerate(protect) if p}
    written: list[Path] = []
    if json_path is not None:
        check_outputs({"report": json_path}, inputs)
        written.append(write_json_atomic(json_path, json_document()))
    if html_path is not None:
        from fidelity.report.html import write_document

        check_outputs({"report": html_path}, inputs)
        written += write_document(html_document(), html=html_path)
    return written


def write_chart_report(report: ChartReport, *, json_path: str | os.PathLike[str] | None = None,
                       html_path: str | os.PathLike[str] | None = None,
                       protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML report, atomically, refusing to write over any path in
    ``protect`` (the inputs). The HTML of an image report reads the image again to show where
    the patches were sampled. Returns the paths written."""
    return write_report_files(lambda: chart_report_json(report),
                              lambda: chart_document(report, source_pixels(report)),
                              json_path=json_path, html_path=html_path, protect=protect)


__all__ = [
    "blind_spot_section",
    "bound_words",
    "chart_document",
    "directional_section",
    "headline",
    "measured_section",
    "patch_section",
    "prediction_sections",
    "source_pixels",
    "summary_facts",
    "verdict_limits",
    "write_chart_report",
    "write_report_files",
]
