"""The chart report on a terminal: a few lines a person reads at a glance."""

from __future__ import annotations

import math

from fidelity.measure.chartsharpness import TARGET_METHOD
from fidelity.pipeline.records import ChartReport, ImageSource
from fidelity.prediction.interval import ValidityDomain
from fidelity.prediction.tablefile import TableKind
from fidelity.report.words import exposure_words, property_lines, verdict_message


def summary_lines(report: ChartReport) -> list[str]:
    """How the chart was found (image), the chart ΔE, exposure and bad pixels (image), the
    predicted loss and the verdict, one line each."""
    lines = []
    src = report.source
    if isinstance(src, ImageSource):
        rec = src.image.recording
        if rec is not None and rec.stream is not None:
            lines.append(f"{rec.kind}: {rec.describe()}")
        elif rec is not None:
            lines.append(f"{rec.kind}: {rec.describe()}, log time "
                         f"{rec.to_json()['time_utc']}")
        found = src.found
        if found is not None:
            conf = "" if found.confidence != found.confidence else \
                f", confidence {found.confidence:.2f}"
            lines.append(f"chart found ({found.method}{conf}, {found.swatches} of 24 patch "
                         f"outlines fitted, orientation {found.orientation}): --corners "
                         f"{found.corners_text()}")
            lines.extend(f"chart: {found.chart}; {note}" for note in found.notes)
        elif src.corner_checks is not None and src.corner_checks.margin < 0:
            lines.append(f"warning: the patches at --corners match the chart layout less well "
                         f"than another row, column or orientation would (colour order "
                         f"{src.corner_checks.colour_order:.2f}); check --corners")
        how = src.image.ocio
        if how is not None:
            lines.append(f"OpenColorIO: {how.colourspace} of {how.config_name or how.config} "
                         f"-> {how.target} ({how.encoding} pixels)")
        elif src.colourspace and src.colourspace != "sRGB":
            lines.append(f"RGB primaries: {src.colourspace}, converted to linear sRGB")
    lines.append(f"chart ΔE00: mean {report.mean_delta_e:.2f}, max "
                 f"{report.max_delta_e:.2f} ({report.worst_patch}); reference "
                 f"{src.reference_description}")
    if report.uncertainty is not None:
        lines.append(uncertainty_line(report))
    if report.exposure_ev is not None:
        bp = report.bad_pixels
        kept = ""
        if bp is not None and bp.window.negative and bp.negatives == "keep":
            kept = f"; pixels with a negative channel kept in the mean: {bp.window.negative}"
        lines.append(f"{exposure_line(report)}; bad pixels excluded: "
                     f"{bp.window.total if bp else 0}{kept}")
        if report.measurement.excluded:
            reasons: dict[str, list[str]] = {}
            for name, why in report.measurement.excluded.items():
                reasons.setdefault(why, []).append(name)
            lines.extend(f"left out of the chart ΔE: {', '.join(names)}: {why}"
                         for why, names in reasons.items())
        if isinstance(src, ImageSource) and src.clipped_patches:
            lines.append("outside [0, 1] in sRGB, clipped like a stored image: "
                         + ", ".join(src.clipped_patches))
    lines += diagnosis_lines(report)
    lines += texture_lines(report)
    p = report.prediction
    if p is not None:
        bound = p.table.kind.upper_bound
        b = "<= " if bound else ""

        def f(v: float | None) -> str:
            return "n/a" if v is None else f"{b}{v:.2f}"

        kind = ("upper bound, " if bound else
                "measured worst case, " if p.table.kind is TableKind.MEASURED else "")
        pm = ""
        if report.interval is not None:
            pm = report.interval.plus_minus()
        by = {i.column: i for i in report.intervals}

        def u(column: str) -> str:
            i = by.get(column)
            return "" if i is None else f" ± {i.standard_uncertainty:.2f}"

        swamped = [name for name, column in (("% of baseline", "dmap_relative"),
                                             ("person", "dap_person_points"),
                                             ("bicycle", "dap_bicycle_points"))
                   if column in by and by[column].swamped]
        noise = (f"; {', '.join(swamped)}: u >= the value, mostly noise" if swamped else "")
        lines.append(f"predicted ΔmAP: {f(p.dmap_points)}{pm} percentage points, "
                     f"{f(p.dmap_relative)}{u('dmap_relative')} % of baseline ({kind}table "
                     f"{p.table.name}, detector size {p.size_used})")
        lines.append(f"predicted ΔAP: person {f(p.dap_person_points)}{u('dap_person_points')} "
                     f"points, bicycle {f(p.dap_bicycle_points)}{u('dap_bicycle_points')} "
                     f"points" + (" (k=1" + noise + ")" if by else ""))
        i = report.interval
        if i is not None and i.validated_upper is not None:
            lines.append(f"validated bound: ΔmAP <= {i.validated_upper:.2f} points with the "
                         f"model's own error ({i.validated_method})")
        if p.out_of_range:
            lines.append("note: ΔE beyond the table's range; conservative ceiling used")
        if report.validity is not None and not report.validity.inside:
            lines.append(outside_line(report.validity))
    lines += directional_lines(report)
    lines += property_lines(report.properties, not_judged=report.verdict is None)
    lines += [f"measured on COCO: {m.summary()}" for m in report.measured]
    lines += [w.warning for w in report.warnings]
    if report.verdict is not None:
        lines.append(verdict_message(report.verdict))
    return lines


def outside_line(validity: ValidityDomain) -> str:
    """One line naming every check of ``validity`` that is outside (each with the value
    against the range its evidence covers): ``outside the validity domain: noise shot+read
    (full_well 500 e-, read_noise 3 e- rms): not validated (...); detector size l ...``."""
    return "outside the validity domain: " + "; ".join(c.detail for c in validity.outside)


def diagnosis_lines(report: ChartReport) -> list[str]:
    """The likely cause of the chart's error in one line (``diagnosis: exposure +2.00 EV:
    ...``) when it has a systematic cause; none otherwise (a correct render, or an error no
    part of the pipeline model explains: the JSON and HTML reports say which)."""
    d = report.diagnosis
    if d is None or not d.systematic:
        return []
    return [f"diagnosis: {d.summary()}"]


def uncertainty_line(report: ChartReport) -> str:
    """``mean ΔE00 2.41 ± 0.06 (k=1)`` and its largest component."""
    u = report.uncertainty
    assert u is not None
    top = max(u.components, key=lambda c: c.value)
    largest = f"; largest component: {top.name} {top.value:.3f}" if top.value > 0 else ""
    notes = "".join(f"; {n}" for n in u.notes)
    return f"{u.text()}{largest}{notes}"


def plus_minus(value: float, u: float | None) -> str:
    """``value ± u`` to the uncertainty's second significant digit (``value`` to 3 digits
    without one); scientific notation for small numbers."""
    if u is None or not (math.isfinite(u) and u > 0):
        return f"{value:.3g}"
    digits = max(0, 1 - math.floor(math.log10(u)))
    if value == 0 and digits > 4:
        return f"0 ± {u:.1e}"
    if abs(value) < 0.01 and digits > 4:
        return f"{value:.2e} ± {u:.1e}"
    digits = min(digits, 4)
    if u < 0.5 * 10.0 ** -digits:
        return f"{value:.{digits}f} ± <{10.0 ** -digits:.{digits}f}"
    return f"{value:.{digits}f} ± {u:.{digits}f}"


def texture_lines(report: ChartReport) -> list[str]:
    """The chart's noise (SNR at the 18 % grey, the photon transfer's read noise and gain, or
    why it was refused) and sharpness (luminance MTF50 per direction and the method; an MTF50
    above the Nyquist frequency said to be aliased; a refused direction by its reason code,
    the message in the chart report's table), one line each; none when not measured."""
    lines = []
    n = report.noise
    if n is not None:
        snr = ("noiseless" if not math.isfinite(n.grey_snr_db)
               else f"SNR {n.grey_snr_db:.1f} dB")
        t = n.transfer
        if t is not None:
            how = (f"read noise {plus_minus(t.read_noise, t.u_read_noise)}, gain "
                   f"{plus_minus(t.gain, t.u_gain)} per electron, G channel, linear units")
        else:
            assert n.refusal is not None
            how = f"photon transfer refused, {n.refusal[0]}: {n.refusal[1]}"
        lines.append(f"noise: {snr} at the 18 % grey ({n.grey_patch}; {how})")
    s = report.sharpness
    if s is not None and s.edges:
        parts, methods = [], []
        for k, e in enumerate(s.edges):
            y = e.channel("Y")
            unit = " cy/px" if k == 0 else ""
            if e.refusal is not None or y is None or y.mtf50 is None:
                reason = e.refusal or (y.refusal if y is not None else None)
                parts.append(f"{e.direction} refused ({reason[0] if reason else 'not measured'})")
            else:
                alias = (" (above Nyquist)"
                         if y.above_nyquist else "")
                parts.append(f"{plus_minus(y.mtf50, y.u_mtf50)}{unit} {e.direction}{alias}")
            if e.method is not None and e.method not in methods:
                methods.append(e.method)
        where = ["edge target"] if s.method == TARGET_METHOD else []
        how = ", ".join([*methods, "luminance", *where])
        lines.append(f"sharpness: MTF50 {', '.join(parts)} ({how})")
    return lines


def directional_lines(report: ChartReport) -> list[str]:
    """The direction-aware prediction in one line, and which bound a ``max-dmap`` verdict
    used."""
    d = report.directional
    if d is None:
        return []

    def f(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f}"

    used = ""
    if report.verdict is not None and report.verdict.criterion.kind == "max-dmap":
        used = ("; the verdict uses this bound" if report.bound == "directional" else
                "; the verdict uses the classic bound (--bound directional: this one)")
    by = {i.column: i for i in report.intervals}
    own = {c: d.uncertainty(c, by[c].propagated if c in by else 0.0)
           for c in ("dmap_points", "dmap_relative")}
    mine = all(v is not None for v in own.values())

    def u(column: str) -> str:
        if mine:
            return f" ± {own[column]:.2f}"
        i = by.get(column)
        return "" if i is None else f" ± {i.standard_uncertainty:.2f}"

    whose = (" (k=1: its own table SE and u(ΔE) through the classic slope)" if mine else
             " (± the classic column's u: the directional table states no SE)" if by else "")
    return [f"direction-aware ΔmAP: {f(d.dmap_points)}{u('dmap_points')} points, "
            f"{f(d.dmap_relative)}{u('dmap_relative')} % of baseline{whose} "
            f"({d.explanation()}){used}"]


__all__ = ["diagnosis_lines", "directional_lines", "outside_line", "plus_minus", "summary_lines", "texture_lines",
           "uncertainty_line"]


def exposure_line(report: ChartReport) -> str:
    """The exposure an image was measured at, and how it was judged: ``exposure normalised:
    -2.00 EV on the neutral patches (auto: the image's own exposure is not judged; --manifest
    or --exposure judges it)``, or ``exposure correction fixed at -0.27 EV; the image +2.00 EV
    from the expected exposure (4 x as bright; limit ±0.3 EV, ...): over the limit``."""
    ev = report.exposure_ev or 0.0
    if report.exposure_auto:
        return (f"exposure normalised: {ev:+z.2f} EV on the neutral patches (auto: the "
                f"image's own exposure is not judged; --manifest or --exposure EV judges it)")
    e = report.exposure
    if e is None:
        return f"exposure correction {ev:+z.2f} EV"
    return (f"exposure correction fixed at {ev:+z.2f} EV; {exposure_words(e)}: "
            f"{'within' if e.passed else 'over'} the limit")
