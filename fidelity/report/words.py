"""Predictions and verdicts in words: the sentences every report prints, written from the fields.

A :class:`~fidelity.prediction.table.Prediction` and a
:class:`~fidelity.prediction.verdict.Verdict` carry numbers and enums only (the table's kind,
each column's status and range, the sampling error, a verdict's reason); this module is the one
place that says what they mean, for the terminal, the HTML and JUnit reports and the notes of the
JSON report (:mod:`fidelity.report.jsonform`).
"""

from __future__ import annotations

from typing import Any

from fidelity.colour.diagnosis import Diagnosis
from fidelity.prediction.interpolate import ColumnStatus
from fidelity.prediction.table import Prediction
from fidelity.prediction.tablefile import CEILING
from fidelity.prediction.verdict import Verdict, VerdictReason

#: How the notes name each loss column.
COLUMN_LABELS = {"dmap_points": "ΔmAP", "dmap_relative": "ΔmAP",
                 "dap_person_points": "person ΔAP", "dap_bicycle_points": "bicycle ΔAP"}


def ceiling_words(column: str, value: float | None) -> str:
    """How a total-loss ceiling was set: ``100 %`` (relative), the baseline in points, or 100
    points when no baseline is known."""
    if column == "dmap_relative":
        return "100 %"
    if value is None or value >= CEILING:
        return "100 points (no baseline known)"
    return f"{value:.4g} points (the baseline)"


def column_note(prediction: Prediction, column: str) -> str:
    """How one column's answer was obtained (interpolated, below or beyond the range, raised
    to the points reading, no data), in one clause."""
    p, c = prediction, prediction.columns[column]
    if c.status is ColumnStatus.NO_DATA or c.delta_e_range is None:
        return f"table {p.table.name!r} has no {column} data"
    lo, hi = c.delta_e_range
    if c.status is ColumnStatus.INTERPOLATED:
        note = f"{p.method} interpolation inside ΔE {lo:g}..{hi:g}"
    elif c.status is ColumnStatus.BELOW_RANGE:
        note = (f"ΔE {p.delta_e:g} is below the table's range ({lo:g}..{hi:g}); answered "
                f"with the value at ΔE {lo:g} (an upper bound: loss grows with ΔE)")
    else:
        note = (f"ΔE {p.delta_e:g} is beyond the table's range ({lo:g}..{hi:g}); no "
                f"extrapolation: total loss, {ceiling_words(column, c.value)}")
    points = p.columns["dmap_points"].value
    if c.raised_from is not None and points is not None and p.baseline_map:
        note += (f"; raised to 100*{points:.4g}/{p.baseline_map:g} = {c.value:.4g} % "
                 f"(the paper's percent read as points)")
    if p.upper_bound:
        note = "upper bound; " + note
    return note


def _size_note(p: Prediction) -> str | None:
    if p.size_used == "any" and p.size != "any":
        return (f"table {p.table.name!r} has no curve for size {p.size!r}; its 'any' curve "
                f"(worst case over every size) answers")
    if p.size_used != p.size:
        sizes = p.size_used.split(",")
        have = (f"only size {sizes[0]} detectors" if len(sizes) == 1
                else "sizes " + ", ".join(sizes))
        return (f"table {p.table.name!r} has no curve for size {p.size!r} (it has {have}); "
                f"their worst case answers")
    return None


def prediction_notes(prediction: Prediction) -> list[str]:
    """What a prediction's numbers are, in sentences: which size answered, whether the values
    are upper bounds or measured worst cases (with their sampling error), and what a ΔE beyond
    the table's range was answered with."""
    p = prediction
    notes = [n for n in (_size_note(p),) if n]
    if p.upper_bound:
        notes.append("published-bounds table: values are upper bounds (worst case over the "
                     "paper's transforms and detectors), not expectations")
        if p.baseline_map is None:
            notes.append("ΔmAP points vs relative: the paper's '%' is ambiguous; dmap_points is "
                         "safe under both readings, dmap_relative only under the relative "
                         "reading (give the detector's baseline mAP to bound it under both)")
    else:
        notes.append("measured table: values are the worst loss measured over the transforms "
                     "(and models) at each ΔE, with sampling error, not a guaranteed bound")
        se = p.dmap_points_se
        if se is not None:
            notes.append(f"sampling error of the measured ΔmAP points around ΔE {p.delta_e:g}: "
                         "SE " + (f"{se.low:.2f}" if se.low == se.high
                                  else f"{se.low:.2f}-{se.high:.2f}") + " points")
    above = {col: c for col, c in p.columns.items() if c.status is ColumnStatus.ABOVE_RANGE}
    if above:
        rng = next(iter(above.values())).delta_e_range
        assert rng is not None
        notes.append(f"ΔE {p.delta_e:g} is beyond the table's range ({rng[0]:g}..{rng[1]:g}); "
                     "no extrapolation: total loss, " + "; ".join(
                         f"{COLUMN_LABELS[col]} {ceiling_words(col, c.value)}"
                         for col, c in above.items() if c.value is not None))
    return notes


def verdict_message(verdict: Verdict, delta_e_name: str = "mean ΔE00") -> str:
    """The verdict in one line, e.g. ``PASS: mean ΔE00 1.02 <= 3`` or ``FAIL: predicted ΔmAP
    1.40 points > 1 at mean ΔE00 2.41``; ``delta_e_name`` names the chart ΔE (a comparison's
    is the sim-to-real ΔE00). A guarded decision rule adds the expanded uncertainty it used,
    ``UNDECIDED: mean ΔE00 2.98 <= 3 + U (guarded: U = 0.06, k = 2)``."""
    v, c = verdict, verdict.criterion
    exposure = _exposure_over(v)
    if c.kind == "max-delta-e":
        assert v.value is not None
        j = v.properties
        overs = [_over_limit(j, k) for k in j.failed] if j is not None else []
        overs += [exposure] if exposure else []
        if overs:
            colour_ok = v.value <= c.limit
            return (f"{v.label}: {delta_e_name} {v.value:.2f} "
                    f"{'<=' if colour_ok else '>'} {c.limit:g}{_allows(v)}{_guard(v)}, "
                    f"{'but' if colour_ok else 'and'} "
                    f"{'; '.join(overs)}{_not_judged(v)}")
        return (f"{v.label}: {delta_e_name} {v.value:.2f} "
                f"{_relation(v)} {c.limit:g}{_allows(v)}{_guard(v)}{_not_judged(v)}")
    what = c.describe().removeprefix("predicted ").split(" <=")[0]
    directional = v.bound == "directional"
    if v.reason is VerdictReason.NO_PREDICTION or v.value is None:
        source = "no direction-aware" if directional else f"table {v.table!r} has no"
        return f"FAIL: {source} {what} prediction (nothing supports a pass)"
    unit = "points" if c.unit == "points" else "%"
    parts = _combined_words(v)
    if directional:
        qualifier = " (direction-aware bound)"
    else:
        qualifier = " (upper bound)" if v.upper_bound else ""
        if v.conservative and v.status is not None:
            qualifier += f" ({v.status.value}: conservative answer)"
    within = v.passed or v.reason is VerdictReason.UNDECIDED or exposure is None
    relation = _relation(v) if within else ("<=" if v.value <= c.limit else ">")
    return (f"{v.label}: predicted {what} {v.value:.2f} {unit}{parts}{qualifier} "
            f"{relation} {c.limit:g} at {delta_e_name} {v.delta_e:.2f}{_guard(v)}"
            f"{f', {_joiner(v)} {exposure}' if exposure else ''}{_not_judged(v)}")


def _allows(v: Verdict) -> str:
    """`` (up to 2.39 % of baseline for these detectors)``: what a ``max-delta-e`` limit
    allows by the verdict's table (:attr:`Verdict.limit_loss_relative`); nothing unknown."""
    x = v.limit_loss_relative
    return "" if x is None else f" (up to {x:.2f} % of baseline for these detectors)"


def _joiner(v: Verdict) -> str:
    """``but`` after a value within its limit, ``and`` after one over it."""
    return "and" if v.value is not None and v.value > v.criterion.limit else "but"


def exposure_words(e: Any) -> str:
    """``the image +2.00 EV from the expected exposure (4 x as bright; limit ±0.3 EV, the
    expected exposure from the scene manifest)`` for an
    :class:`fidelity.prediction.exposure.ExposureJudgement`."""
    source = "the scene manifest" if e.source == "manifest" else "--exposure"
    return (f"the image {e.error_ev:+z.2f} EV from the expected exposure ({e.factor:.3g} x as "
            f"bright; limit ±{e.limit_ev:g} EV, the expected exposure from {source})")


def _exposure_over(v: Verdict) -> str:
    """The exposure's clause of a verdict it fails (empty otherwise)."""
    e = v.exposure
    if e is None or e.passed:
        return ""
    return f"exposure {e.error_ev:+z.2f} EV from the expected (|error| > {e.limit_ev:g} EV)"


def failure_message(verdict: Verdict, diagnosis: Diagnosis | None = None) -> str:
    """The verdict in one line (:func:`verdict_message`) and, when the chart's error has a
    systematic cause, that cause (``FAIL: mean ΔE00 24.52 > 3; likely cause: exposure +2.00
    EV: ...``): the message of a failed gate's JUnit test case."""
    message = verdict_message(verdict)
    if diagnosis is not None and diagnosis.systematic:
        message += f"; likely cause: {diagnosis.summary()}"
    return message


def _over_limit(j: Any, prop: str) -> str:
    """``sharpness: MTF50 0.127 cy/px < 0.19 (predicted ΔmAP 3.03 > 1.20, the loss at ΔE00
    3)``."""
    p = j.prediction(prop)
    x = j.limits.get(prop)
    axis, unit = ("MTF50", " cy/px") if prop == "sharpness" else ("SNR", "")
    limit = "" if x is None else f" < {x:.3g}{unit}"
    return (f"{prop}: {axis} {p.x:.3g}{unit}{limit} (predicted loss {p.loss:.2f} > "
            f"{j.limit_loss:.2f}, the loss at ΔE00 {j.limit_delta_e:g})")


def _combined_words(v: Verdict) -> str:
    """`` (colour 0.62 + sharpness 3.03 + noise 0.00: sharpness dominates)`` for a verdict on
    the combined loss; nothing for colour alone."""
    j = v.properties
    if j is None or j.combined is None or not j.predictions:
        return ""
    terms = " + ".join(f"{k} {x:.2f}" for k, x in j.combined.parts.items())
    if j.combined.interaction > 0:
        terms += f" + blur-noise interaction {j.combined.interaction:.2f}"
    if j.combined.margin > 0:
        terms += f" + validated margin {j.combined.margin:.2f}"
    return f" ({terms}: {j.combined.dominant} dominates)"


def _margin_words(c: Any) -> str:
    """``, + 0.03 validated margin`` where the combined loss ``c`` (a
    :class:`fidelity.prediction.properties.Combined`) has one; nothing otherwise."""
    return f", + {c.margin:.2f} validated margin" if c.margin > 0 else ""


def combined_rule_words(c: Any) -> str:
    """``sum + sharpness-noise interaction, + 0.03 validated margin``: the rule of a combined
    loss ``c`` (a :class:`fidelity.prediction.properties.Combined`) and its validated margin
    where it has one."""
    return str(c.rule) + _margin_words(c)


def _not_judged(v: Verdict) -> str:
    """``; not judged: sharpness (not measured)`` where a property was left out."""
    j = v.properties
    if j is None or not j.not_judged:
        return ""
    if len({why for _, why in j.not_judged}) == 1:
        return (f"; not judged: {', '.join(k for k, _ in j.not_judged)} "
                f"({j.not_judged[0][1]})")
    return "; not judged: " + ", ".join(f"{k} ({why})" for k, why in j.not_judged)


def property_lines(judgement: Any, not_judged: bool = True) -> list[str]:
    """One line per property judged besides colour, e.g. ``sharpness: MTF50 0.127 cy/px at
    the detector's input -> predicted ΔmAP 3.03 ± 0.21 points (gaussian-blur, yolox_nano;
    table coco1000-sharpness)``, the combined loss with its rule and dominant property, one
    per reason properties were not judged (``not_judged``; a verdict's sentence says it
    otherwise), and the default limits (``judgement``: a
    :class:`fidelity.prediction.properties.PropertyJudgement` or None)."""
    if judgement is None:
        return []
    label = COLUMN_LABELS.get(judgement.column, judgement.column)
    lines = []
    for p in judgement.predictions:
        axis = "MTF50" if p.axis == "mtf50" else "SNR at 18 % grey"
        unit = " cy/px" if p.axis == "mtf50" else ""
        capped = (p.native_x is not None and p.native_x / p.scale > p.x * (1 + 1e-9))
        scaled = ("" if p.scale == 1.0 or p.native_x is None else
                  f" ({p.native_x:.3g}{unit} at the image's resolution, x {1 / p.scale:.3g} "
                  f"for the detector's 640 px input"
                  + (", at most the undegraded chart's" if capped else "") + ")")
        pm = "" if p.u_loss is None else f" ± {p.u_loss:.2f}"
        pm += " points" if judgement.column.endswith("_points") else " %"
        where = {"baseline": "as sharp or clean as the undegraded chart",
                 "beyond": "beyond the table: its ceiling, a conservative answer"}.get(
            p.status, f"{p.family}, {p.detector}")
        if p.target_x is not None and p.native_x is not None:
            scaled += (f" (edge target {p.target_x:.3g} x {p.native_x / p.target_x:.3f} to "
                       f"the tables' axis)")
        lines.append(f"{p.property}: {axis} {p.x:.3g}{unit} at the detector's input{scaled} "
                     f"-> predicted {label} {p.loss:.2f}{pm} ({where}; table {p.table})")
    c = judgement.combined
    if c is not None and judgement.predictions:
        pm = "" if c.u_loss is None else f" ± {c.u_loss:.2f}"
        pm += " points" if judgement.column.endswith("_points") else " %"
        lines.append(f"combined: predicted {label} {c.loss:.2f}{pm} ({c.rule} of "
                     + ", ".join(c.parts) + _margin_words(c) + f"; {c.dominant} dominates)")
    reasons: dict[str, list[str]] = {}
    for k, why in judgement.not_judged if not_judged else ():
        reasons.setdefault(why, []).append(k)
    lines += [f"{', '.join(ks)}: not judged ({why})" for why, ks in reasons.items()]
    if judgement.limit_loss is not None and judgement.predictions:
        limits = []
        for k, x in judgement.limits.items():
            if x is not None:
                limits.append(f"MTF50 >= {x:.3g} cy/px" if k == "sharpness"
                              else f"SNR >= {x:.3g}")
        if limits:
            lines.append(f"limits equivalent to ΔE00 {judgement.limit_delta_e:g} "
                         f"({label} {judgement.limit_loss:.2f}): " + ", ".join(limits))
    return lines


def _relation(v: Verdict) -> str:
    if v.reason is VerdictReason.UNDECIDED:
        return "within U of"
    return "<=" if v.passed else ">"


def _guard(v: Verdict) -> str:
    """`` (guarded: U = 0.06, k = 2)`` for a guarded rule, nothing for the simple one."""
    if v.decision.rule != "guarded":
        return ""
    u = v.expanded_uncertainty
    told = "U unknown, taken as 0" if u is None else f"U = {u:.3g}"
    strict = (", strict: the guard band fails"
              if v.decision.strict and v.reason is VerdictReason.UNDECIDED else "")
    return f" (guarded: {told}, k = {v.decision.k:g}{strict})"


__all__ = ["COLUMN_LABELS", "ceiling_words", "column_note", "combined_rule_words",
           "failure_message",
           "prediction_notes", "property_lines", "verdict_message"]
