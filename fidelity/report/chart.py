"""The chart report as a document: a :class:`~fidelity.pipeline.records.ChartReport` turned into HTML.

The HTML report (:func:`chart_document`, written by :mod:`fidelity.report.html`) puts the
verdict and the chart first, then the figures a colour scientist expects (ΔE heat map on the
chart, a*b* arrows, the neutral tone curve, ΔE per patch, the prediction curve with the limit)
and folds the patch table, the transforms and the provenance away. The section builders are
public: the sim-to-real report (:mod:`fidelity.report.compare`) uses them too.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from numpy.typing import NDArray

from fidelity.chart.read import read_again
from fidelity.colour.colorimetry import delta_e_1976, delta_e_1994
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import JSONObject, check_outputs, json_ready, write_json_atomic
from fidelity.measure.colour import (
    NOISE_FLOOR,
    chart_statistics,
    fit_tone,
    neutral_patches,
    patch_snr_db,
)
from fidelity.pipeline.records import ChartReport, ImageSource, RenderSource
from fidelity.pipeline.simreal import texture_side
from fidelity.prediction.properties import load_property_table
from fidelity.report import chartfigures
from fidelity.report.context import context_section
from fidelity.report.document import (
    Code,
    Document,
    Facts,
    Headline,
    Section,
    Text,
    Tone,
    section,
    svg_figure,
    table,
)
from fidelity.report.html import write_document
from fidelity.report.jsonform import chart_report_json
from fidelity.report.terminal import outside_line, plus_minus, texture_lines
from fidelity.report.words import (
    COLUMN_LABELS,
    column_note,
    combined_rule_words,
    exposure_words,
    prediction_notes,
    property_lines,
    verdict_message,
)

# ---------------------------------------------------------------------- the HTML document


def _num(v: float | None, nd: int = 2) -> str:
    return "–" if v is None else f"{v:.{nd}f}"


def headline(report: ChartReport) -> Headline:
    figure = svg_figure(chartfigures.swatches(report.measurement), "swatches.svg",
                        "the chart: reference against measured",
                        "Each patch: reference colour (left half) and measured colour (right "
                        "half), numbered in chart order.")
    v = report.verdict
    warn = "".join(f"\n\n**warning**: {w.reason}" for w in report.warnings)
    validity = report.validity
    outside = validity is not None and not validity.inside
    if outside:
        assert validity is not None
        warn = f"\n\n**{outside_line(validity)}**{warn}"
    if v is not None:
        label = f"{v.label} — outside the validity domain" if outside else v.label
        tone: Tone = "fail" if not v.passed else "outside" if outside else "pass"
        return Headline(f"**{label}**: {verdict_message(v).split(': ', 1)[-1]}{warn}",
                        tone, figure)
    return Headline(f"mean ΔE00 {report.mean_delta_e:.2f}, max {report.max_delta_e:.2f} "
                    f"({report.worst_patch}); no gate applied{warn}", "info", figure)


def summary_facts(report: ChartReport) -> Facts:
    u = report.uncertainty
    items = [("mean ΔE00 (chart ΔE)", _num(report.mean_delta_e) if u is None else
              u.value_text()),
             ("max ΔE00", f"{_num(report.max_delta_e)} ({report.worst_patch})")]
    stats = chart_statistics(report.measurement)
    items += [("saturation (mean chroma of the colour patches)",
               f"{stats.saturation_percent:.1f} % of the reference"),
              ("white balance error (mean a*, b* of the neutral patches)",
               f"a\\* {stats.neutral_ab[0]:+z.2f}, b\\* {stats.neutral_ab[1]:+z.2f} "
               f"(ΔC\\*ab {stats.neutral_chroma:.2f})"),
              ("mean ΔL* of the neutral patches", f"{stats.neutral_delta_l:+z.2f}")]
    items += diagnosis_facts(report)
    items += noise_facts(report)
    items += tone_facts(report)
    if report.exposure_ev is not None:
        items.append(("exposure correction",
                      f"{report.exposure_ev:+z.3f} EV"
                      + (" (auto, on the neutral patches: the image's own exposure is not "
                         "judged)" if report.exposure_auto else "")))
    if report.exposure is not None:
        items.append(("exposure error (image against the expected)",
                      f"{exposure_words(report.exposure)}: "
                      f"{'within' if report.exposure.passed else 'over'} the limit"))
    if report.bad_pixels is not None:
        w = report.bad_pixels.window
        items.append(("bad pixels in windows (NaN/Inf/negative)",
                      f"{w.total} ({w.nan}/{w.inf}/{w.negative})"))
    p = report.prediction
    if p is not None:
        b = "≤ " if p.table.kind.upper_bound else ""
        pm = "" if report.interval is None else report.interval.plus_minus()
        by = {i.column: i for i in report.intervals}

        def pm_of(column: str) -> str:
            i = by.get(column)
            return "" if i is None else f" ± {i.standard_uncertainty:.2f} (k=1)" + (
                ", u ≥ the value: mostly noise" if i.swamped else "")

        items += [("predicted ΔmAP, percentage points", b + _num(p.dmap_points) + pm),
                  ("predicted ΔmAP, % of baseline",
                   b + _num(p.dmap_relative) + pm_of("dmap_relative")),
                  ("predicted person ΔAP, points",
                   b + _num(p.dap_person_points) + pm_of("dap_person_points")),
                  ("predicted bicycle ΔAP, points",
                   b + _num(p.dap_bicycle_points) + pm_of("dap_bicycle_points")),
                  *([] if report.interval is None or report.interval.validated_upper is None
                    else [("validated bound of ΔmAP, with the model's own error",
                           f"≤ {report.interval.validated_upper:.2f} points "
                           f"({report.interval.validated_method})")]),
                  ("prediction table", f"{p.table.name} ({p.table.kind}), detector size "
                                       f"{p.size_used}"),
                  ("detectors measured", ", ".join(sorted(
                      {c.model for c in p.table.curves if c.model is not None})) or "–")]
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
        how = src.image.ocio
        if how is not None:
            items.append(("converted by OpenColorIO", f"{how.colourspace} of "
                          f"{how.config_name or how.config} (`{how.config}`) -> {how.target} "
                          f"of its built-in config (OpenColorIO {how.version})"))
    items.append(("reference", src.reference))
    return Facts(tuple(items))


def diagnosis_facts(report: ChartReport) -> list[tuple[str, str]]:
    """The diagnosis rows of the summary (:mod:`fidelity.colour.diagnosis`): the likely cause
    of the chart's error, each cause with the mean ΔE00 it accounts for, what the fitted model
    leaves, and the notes (none without a diagnosis)."""
    d = report.diagnosis
    if d is None:
        return []
    label = "likely cause (a camera pipeline fitted to the patches)"
    if not d.causes:
        rows = [(label, d.summary())]
    else:
        rows = [(label, f"{c.text} (accounts for mean ΔE00 {c.delta_e_removed:.2f})")
                for c in d.causes]
        rows.append(("what the fitted model leaves",
                     f"mean ΔE00 {d.residual_delta_e:.2f} of {d.delta_e:.2f} (against the "
                     f"reference clipped to the sRGB gamut; noise scale σ {d.sigma:.2f} in "
                     f"CIELAB)"))
        if not d.exposure_fixed:
            rows.append(("the image's exposure (normalised away)", f"{d.exposure_ev:+z.2f} EV"))
    rows += [("note", n) for n in d.notes]
    return rows


def noise_facts(report: ChartReport) -> list[tuple[str, str]]:
    """The noise rows of the summary: the neutral patches' SNR and the worst patch of the
    chart, or "no noise" for a noise-free measurement (none when the noise is unknown)."""
    stats = chart_statistics(report.measurement)
    label = "noise: signal-to-noise of the neutral patches (encoded sRGB)"
    if stats.noise_free:
        return [(label, f"no noise (standard deviation below {NOISE_FLOOR:.1e}, the "
                        f"quantisation noise of 16 bits)")]
    if stats.snr_db is None:
        return []
    out = [(label, f"{stats.snr_db:.1f} dB (worst neutral {stats.worst_snr_db:.1f} dB)")]
    if stats.worst_patch is not None and stats.worst_patch_snr_db is not None:
        out.append(("lowest signal-to-noise of any patch",
                    f"{stats.worst_patch_snr_db:.1f} dB ({stats.worst_patch})"))
    return out


def tone_facts(report: ChartReport) -> list[tuple[str, str]]:
    """The tone row of the summary: gamma and exposure fitted to the neutral patches
    (:func:`fidelity.measure.colour.fit_tone`)."""
    fit = fit_tone(report.measurement)
    if fit is None:
        return []
    return [("tone of the neutral patches (fitted power law)",
             f"gamma {fit.gamma:.3f} relative to the reference, exposure {fit.offset_ev:+z.2f} EV "
             f"at 18 % grey (residual {fit.rms_ev:.3f} EV rms over {fit.patches} patches)")]


def bound_words(report: ChartReport) -> str:
    v = report.verdict
    if v is None:
        return "no verdict"
    if v.criterion.kind != "max-dmap":
        return "neither: the verdict is on the chart ΔE"
    return ("direction-aware" if report.bound == "directional" else
            "classic (worst case over every transform)")


def directional_section(report: ChartReport) -> Section | None:
    d = report.directional
    if d is None:
        return None
    pr = d.parts
    sh = pr.shares()
    facts = [("chart ΔE split by direction (ΔE00 units)",
              f"lightness {pr.lightness:.2f} ({100 * sh['lightness']:.0f} %), chroma "
              f"{pr.chroma:.2f} ({100 * sh['chroma']:.0f} %), hue {pr.hue:.2f} "
              f"({100 * sh['hue']:.0f} %)")]
    label = "best-fitting SAFE-COLOR transform (weights the prediction)"
    if d.fit is not None:
        facts.append((label, f"{d.fit.describe()}: explains {100 * d.fit.explained:.0f} % of "
                             f"the error (mean ΔE00 {d.fit.error:.2f} -> "
                             f"{d.fit.residual:.2f})"))
    else:
        facts.append((label, "none explains the error"))
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
        svg_figure(chartfigures.family_curves(d, p), "family_curves.svg",
                   "worst case per transform family and the classic curve"),
        Text("\n".join(f"- {n}" for n in d.notes)))


def blind_spot_section(report: ChartReport) -> Section | None:
    if not report.blind_spots:
        return None
    rows = [(b.kind, {True: "**at risk**", False: "no", None: "not judged"}[b.at_risk],
             _num(b.value, 3), b.reason) for b in report.blind_spots]
    return section("Blind spots of the chart ΔE", Text(
        "What a mean over 24 flat patches cannot see (`fidelity.measure.blindspots`): the tone "
        "of the deep shadows below the black patch, and posterisation (banding) of smooth "
        "gradients."), table(("check", "at risk", "value", "reason"), rows,
                             numeric=(False, False, True, False)))


def properties_section(report: ChartReport) -> Section | None:
    """Colour, sharpness and noise judged together
    (:class:`fidelity.prediction.properties.PropertyJudgement`): per property its value at
    the detector's input and predicted loss, the properties not judged, the combined loss and
    the limits equivalent to the ΔE limit."""
    j = report.properties
    if j is None:
        return None
    rows: list[tuple[str, ...]] = []
    if j.colour is not None:
        rows.append(("colour", f"ΔE00 {report.mean_delta_e:.2f}",
                     plus_minus(max(j.colour, 0.0), j.u_colour), "colour table", "–"))
    for p in j.predictions:
        axis = "MTF50" if p.axis == "mtf50" else "SNR"
        value = "∞" if math.isinf(p.x) else f"{p.x:.3g}"
        rows.append((p.property, f"{axis} {value}" + (" cy/px" if p.axis == "mtf50" else ""),
                     plus_minus(p.loss, p.u_loss),
                     {"baseline": "undegraded chart", "beyond": "beyond: ceiling"}.get(
                         p.status, f"{p.family}, {p.detector}"), p.table))
    rows += [(k, "–", "not judged", why, "–") for k, why in j.not_judged]
    if j.combined is not None:
        rows.append((f"combined ({combined_rule_words(j.combined)})", "–",
                     plus_minus(j.combined.loss, j.combined.u_loss),
                     f"{j.combined.dominant} dominates", "–"))
    words = [line for line in property_lines(j) if line.startswith("limits ")]
    figures = []
    for p in j.predictions:
        t = _table_of(p)
        if t is not None:
            figures.append(svg_figure(
                chartfigures.property_curve(p, t, j.limits.get(p.property)),
                f"{p.property}_curve.svg", f"worst-case loss against {p.axis}, this chart's "
                "point and the limit equivalent to the ΔE limit"))
    return section("Colour, sharpness and noise", table(
        ("property", "at the detector's input",
         f"predicted {COLUMN_LABELS.get(j.column, j.column)}", "worst case",
         "table"), rows, numeric=(False, False, True, False, False),
        caption=words[0] if words else ""), *figures)


def _table_of(p: Any) -> Any:
    """The shipped table a property prediction came from (None: not found)."""
    try:
        return load_property_table(p.table)
    except FidelityError:
        return None


def texture_section(report: ChartReport) -> Section | None:
    """The chart's noise and sharpness (:mod:`fidelity.measure.chartnoise`,
    :mod:`fidelity.measure.chartsharpness`): the terminal's two lines, then per edge and
    channel MTF50, MTF10 and the MTF at half Nyquist, or why refused."""
    lines = texture_lines(report)
    if not lines:
        return None
    blocks: list[Any] = [Text("\n\n".join(lines))]
    s = report.sharpness
    if s is not None and s.edges:
        def pm(v: float | None, u: float | None) -> str:
            return "–" if v is None else plus_minus(v, u)
        rows = []
        for e in s.edges:
            if e.refusal is not None:
                rows.append((e.direction, e.method or "–", "–", "–", "–",
                             f"refused, {e.refusal[0]}: {e.refusal[1]}"))
                continue
            for c in e.channels:
                mtf50 = pm(c.mtf50, c.u_mtf50) + (" (above Nyquist)" if c.above_nyquist else "")
                rows.append((e.direction, e.method or "–", c.channel,
                             mtf50, pm(c.mtf10, c.u_mtf10),
                             pm(c.mtf_half_nyquist, c.u_mtf_half_nyquist)
                             if c.refusal is None else f"refused, {c.refusal[0]}"))
        blocks.append(table(("direction", "method", "channel", "MTF50, cy/px", "MTF10, cy/px",
                             "MTF at 0.25 cy/px"), rows,
                            caption="; ".join([*(f"{e.direction}: the edge of {e.patches[0]} "
                                                 f"facing {e.patches[1]}" for e in s.edges),
                                               f"linearisation: {s.linearisation}"]),
                            numeric=(False, False, False, True, True, True)))
    blocks += texture_figures(report)
    return section("Noise and sharpness", *blocks)


def edge_regions(report: ChartReport) -> list[tuple[str, tuple[int, int, int, int]]]:
    """Each edge's label (``edge horizontal``, with ``refused`` where it was) and its region
    ``(x0, y0, width, height)``, for the image's figure; none without a sharpness record."""
    s = report.sharpness
    if s is None:
        return []
    return [(f"edge {e.direction}" + (" (refused)" if e.refusal is not None else ""), e.roi)
            for e in s.edges if e.roi is not None]


def texture_figures(report: ChartReport) -> list[Any]:
    """The chart's luminance MTF curve with its MTF50 (of the softer edge, the one the
    prediction reads) and its neutral patches' noise against signal with the photon-transfer
    line, where measured (:func:`fidelity.pipeline.simreal.texture_side`)."""
    side = texture_side(report)
    out: list[Any] = []
    if side.mtf50 is not None and side.frequencies:
        out.append(svg_figure(chartfigures.mtf_curves(
            (("this chart", side.frequencies, side.mtf, side.mtf50),),
            0.5 if side.mtf50 <= 0.45 else 1.0), "mtf_curve.svg",
            f"luminance MTF of the softer edge ({side.direction}, {side.method}), MTF50 "
            "marked"))
    if side.noise_missing is None and side.mu:
        fit = (None if side.read_variance is None or side.gain is None
               else (side.read_variance, side.gain))
        out.append(svg_figure(chartfigures.noise_curves(
            (("this chart", side.mu, side.sigma, fit),)), "noise_curve.svg",
            "neutral patches: σ against μ with the photon-transfer fit"
            + (f" (refused: {side.fit_refusal})" if side.fit_refusal else "")))
    return out


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
        "ΔE = 0 baseline, ΔmAP against that baseline with its standard error (the larger of "
        f"the paired image bootstrap and the 5-fold jackknife, `fidelity.coco.measure`). Predicted: classic "
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


def verdict_limits_relative(report: ChartReport) -> float | None:
    """The ``max-dmap`` limit of the report's verdict in % of baseline (mAP), where it has
    one."""
    v = report.verdict
    if v is None or v.criterion.kind != "max-dmap":
        return None
    c = v.criterion
    return c.limit if c.cls == "all" and c.unit == "relative" else None


def uncertainty_section(report: ChartReport) -> Section | None:
    """The uncertainty budget of the chart ΔE (GUM style): each component, its standard
    uncertainty, type and how it was obtained, and the combined standard uncertainty; the
    predicted ΔmAP's interval and the validity domain of the answer."""
    u = report.uncertainty
    if u is None:
        return None
    rows = [(c.name, f"{c.value:.4f}", c.type, c.method) for c in u.components]
    rows.append(("combined (root sum of squares)", f"{u.combined:.4f}", "",
                 f"coverage factor k = {u.k:g}; expanded U (k = 2) = {u.expanded(2.0):.4f}"))
    notes = "".join(f"\n- {n}" for n in u.notes)
    blocks: list[Any] = [
        Text(f"**{u.text()}**: standard uncertainty of the {u.quantity}; Monte Carlo "
             f"propagation (JCGM 101) with {u.draws} draws, seed {u.seed}." + notes),
        table(("component", "standard uncertainty, ΔE00", "type", "how obtained"), rows,
              numeric=(False, True, False, False))]
    iv = report.interval
    if iv is not None:
        se = "unknown" if iv.table_se is None else f"{iv.table_se:.3f}"
        lo, hi = iv.interval()
        blocks.append(Text(
            f"Predicted ΔmAP {iv.value:.2f} ± {iv.standard_uncertainty:.2f} points (k = 1; "
            f"k = {iv.k:g}: {lo:.2f} to {hi:.2f}): the table's sampling error {se}, the "
            f"chart ΔE's uncertainty through the table's slope {iv.slope:.3f} points per "
            f"ΔE00: {iv.propagated:.3f}."))
    if report.validity is not None:
        blocks.append(table(("validity domain", "inside", "detail"),
                            [(c.name, "yes" if c.inside else "**no**", c.detail)
                             for c in report.validity.checks],
                            numeric=(False, False, False)))
    return section("Measurement uncertainty of the chart ΔE", *blocks)


def _snr_cell(v: float) -> str:
    return "no noise" if v == float("inf") else "–" if v != v else f"{v:.1f}"


def patch_section(report: ChartReport) -> Section:
    """Every patch: number and name, ΔE00 and its components, ΔE*ab and ΔE94 (extra
    columns; the verdict is on ΔE00), measured and reference Lab, and the SNR where the noise
    is known."""
    m = report.measurement
    de76 = delta_e_1976(m.reference_lab, m.lab)
    de94 = delta_e_1994(m.reference_lab, m.lab)
    snr = patch_snr_db(m)
    found = getattr(report.source, "found", None)
    flagged = set(found.flat_off_fit) if found is not None else set()
    rows = []
    for k, name in enumerate(m.patch_names):
        why = m.excluded.get(name)
        shown = f"{k + 1} {name}" + (f" (left out: {why.split(':')[0]})" if why else "")
        if k in flagged:
            shown += " (flagged: far from what the other patches predict, but flat)"
        rows.append((shown, _num(float(m.delta_e[k])), _num(float(de76[k])),
                     _num(float(de94[k])), _num(float(m.delta_l[k])),
                     _num(float(m.delta_c[k])), _num(float(m.delta_h[k])),
                     *(_num(float(v)) for v in m.lab[k]),
                     *(_num(float(v)) for v in m.reference_lab[k]),
                     *((_snr_cell(float(snr[k])),) if snr is not None else ())))
    header = ("patch", "ΔE00", "ΔE*ab", "ΔE94", "ΔL'", "ΔC'", "ΔH'", "L*", "a*", "b*",
              "ref L*", "ref a*", "ref b*", *(("SNR (dB)",) if snr is not None else ()))
    note = Text(f"Mean ΔE*ab {float(de76.mean()):.2f}, mean ΔE94 {float(de94.mean()):.2f} "
                f"(graphic arts), mean ΔE00 {m.mean_delta_e:.2f}: the verdict is on ΔE00. "
                "SNR: 20 log10(mean / standard deviation) of the patch's encoded sRGB "
                "values.")
    return section("Patches", note, table(header, rows), folded=True)


def prediction_sections(report: ChartReport, limit_de: float | None,
                         limit_dmap: float | None) -> list[Section]:
    p = report.prediction
    if p is None:
        return []
    blocks: list[Any] = []
    if p.table.curves:
        relative = verdict_limits_relative(report)
        blocks.append(svg_figure(chartfigures.prediction_curve(p, limit_dmap, limit_de),
                                 "prediction.svg",
                                 "predicted loss in percentage points against chart ΔE"))
        blocks.append(svg_figure(chartfigures.prediction_curve(p, relative, limit_de,
                                                               unit="relative"),
                                 "prediction-relative.svg",
                                 "predicted ΔmAP in % of baseline against chart ΔE"))
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
    m = report.measurement
    limit_de, limit_dmap = verdict_limits(report)
    sections = [section("Summary", summary_facts(report))]
    src = report.source
    if isinstance(src, ImageSource) and pixels is not None:
        sections.append(section("Where the patches were sampled", svg_figure(
            chartfigures.chart_location(pixels, src.location, encoding=src.encoding,
                                        exposure_ev=report.exposure_ev or 0.0,
                                        found=src.found is not None,
                                        edges=edge_regions(report)),
            "location.svg", "sampling windows")))
    neutral = neutral_patches(m)
    figures: list[Any] = [
        svg_figure(chartfigures.delta_e_map(m, limit_de), "delta_e_map.svg",
                   "ΔE00 on the chart layout"),
        svg_figure(chartfigures.ab_arrows(m), "ab_arrows.svg", "a*b* errors",
                   "Arrows from the reference colour to the measured one in the a\\*b\\* "
                   "plane; numbers are the patches in chart order."),
    ]
    if neutral:
        figures.append(svg_figure(chartfigures.tone_curve(m, neutral, fit_tone(m, neutral)),
                                  "tone_curve.svg", "tone curve of the neutral patches"))
    figures.append(svg_figure(chartfigures.delta_e_bars(m, limit_de), "delta_e_bars.svg",
                              "ΔE00 per patch"))
    sections.append(section("Colour errors", *figures, gallery=True))
    sections += prediction_sections(report, limit_de, limit_dmap)
    budget = uncertainty_section(report)
    if budget is not None:
        sections.append(budget)
    sections += [x for x in (texture_section(report), properties_section(report),
                             directional_section(report),
                             measured_section(report), blind_spot_section(report))
                 if x is not None]
    if report.context is not None:
        sections.append(context_section(report.context))
    sections.append(patch_section(report))
    prov = report.provenance
    sections.append(section("Provenance", Facts((
        ("tool", f"fidelity {prov.version}"), ("created", report.created),
        (_input_label(report), prov.input_sha256 or "–"), ("python", prov.python),
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
    inputs = {f"input {i + 1}": p for i, p in enumerate(protect) if p}
    written: list[Path] = []
    if json_path is not None:
        check_outputs({"report": json_path}, inputs)
        written.append(write_json_atomic(json_path, json_document()))
    if html_path is not None:
        check_outputs({"report": html_path}, inputs)
        written += write_document(html_document(), html=html_path)
    return written


def write_chart_report(report: ChartReport, *, json_path: str | os.PathLike[str] | None = None,
                       html_path: str | os.PathLike[str] | None = None,
                       protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML report, atomically, refusing to write over any path in
    ``protect`` (the inputs). The HTML of an image report reads the image again to show where
    the patches were sampled. Returns the paths written.

    Parameters
    ----------
    report
        The result of a check or an audit (:func:`fidelity.pipeline.check.check_camera`,
        :func:`fidelity.pipeline.check.audit_image`).
    json_path
        Where to write the JSON report (:func:`fidelity.report.jsonform.chart_report_json`);
        None: no JSON.
    html_path
        Where to write the self-contained HTML report; None: no HTML.
    protect
        Paths that must not be written over (the command's inputs: images, camera files,
        tables); empty entries are skipped.

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
    return write_report_files(lambda: chart_report_json(report),
                              lambda: chart_document(report, source_pixels(report)),
                              json_path=json_path, html_path=html_path, protect=protect)


__all__ = [
    "blind_spot_section",
    "bound_words",
    "chart_document",
    "diagnosis_facts",
    "directional_section",
    "headline",
    "measured_section",
    "properties_section",
    "texture_section",
    "noise_facts",
    "patch_section",
    "prediction_sections",
    "source_pixels",
    "summary_facts",
    "tone_facts",
    "verdict_limits",
    "write_chart_report",
    "write_report_files",
]


def _input_label(report: ChartReport) -> str:
    """What the provenance's input hash is of: the image, or a check's camera file."""
    return "camera file sha256" if isinstance(report.source, RenderSource) else "input sha256"
