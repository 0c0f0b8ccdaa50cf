"""The validation report: predicted against measured detection loss for a suite of cameras.

Built as one :class:`~fidelity.report.document.Document` from
:class:`~fidelity.coco.validate.colour.ValidationResults` (:func:`validation_document`) and
written as ``validation.html`` and ``validation.md`` with ``validation.json`` and the SVG figures
(:func:`write_validation_report`). Reading order: the headline (does the worst-case table
bound the measured loss, with the predicted-against-measured plot), the bound per class, the
written analysis, the plots, every failure with its data-derived reason, then the per-camera
tables (folded), emulation accuracy, cameras, baselines and what was run.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.loss import LOSS_COLUMNS
from fidelity.coco.tables.provenance import STANDARD_ERROR_WORDS
from fidelity.core.fileio import portable_paths, write_json_atomic
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E
from fidelity.report import validationfigures as vf
from fidelity.report.coco import conventions_words
from fidelity.report.document import (
    Block,
    Document,
    Figure,
    Headline,
    Section,
    Text,
    Tone,
    section,
    svg_figure,
    table,
)
from fidelity.report.format import number, words
from fidelity.report.html import write_document
from fidelity.report.validationfigures import PLOTTED

if TYPE_CHECKING:
    from fidelity.coco.validate.camera import CameraRecord
    from fidelity.coco.validate.checks import ValidationRow, ValidationSummary
    from fidelity.coco.validate.colour import ValidationResults

#: Title of the validation report.
TITLE = "Validation: predicted against measured detection loss for realistic camera models"

#: The classes by :data:`fidelity.coco.loss.LOSS_COLUMNS` key, as the report names them.
CLASS_TITLES: dict[str, str] = {**PLOTTED, "all-relative": "mAP relative to baseline"}

#: File names of the figures.
VS_DELTA_E_FIGURE = "loss-vs-chart-delta-e.svg"
EMULATION_FIGURE = "emulation-accuracy.svg"
BOUNDS_FIGURE = "classic-vs-directional.svg"


def scatter_figure(table_name: str) -> str:
    """File name of the predicted-against-measured plot of one prediction table."""
    return f"predicted-vs-measured-{table_name}.svg"


# --------------------------------------------------------------------------------------------
# Figures (drawn by fidelity.report.validationfigures)
# --------------------------------------------------------------------------------------------


def validation_figures(results: ValidationResults) -> dict[str, Figure]:
    """Every figure by file name: predicted against measured per table (the bound table
    first), measured loss against chart ΔE, both bounds, emulation accuracy (SVG,
    :mod:`fidelity.report.validationfigures`)."""
    rows, summ = results.rows, results.summary
    out: dict[str, Figure] = {}
    if rows:
        for t in _table_order(summ):
            out[scatter_figure(t)] = svg_figure(
                vf.scatter_plot(rows, t), scatter_figure(t),
                f"predicted against measured loss, {t}",
                f"Measured loss (points, ±2 SE) against the loss `{t}` predicts, per class; "
                "dashed: identity (measured = predicted); the bound holds below it.")
        out[VS_DELTA_E_FIGURE] = svg_figure(
            vf.vs_delta_e_plot(rows, _table_order(summ)), VS_DELTA_E_FIGURE,
            "measured loss against chart ΔE with the worst-case curves",
            "Measured loss (points, ±2 SE) against the camera's chart ΔE00, with each table's "
            "worst-case curve (detector size n).")
    if results.directional is not None and results.directional.rows:
        out[BOUNDS_FIGURE] = svg_figure(
            vf.bounds_plot(results), BOUNDS_FIGURE, "both bounds against the measured loss",
            "Measured ΔmAP (points, ±2 SE) against the classic worst case (left) and the "
            "direction-aware prediction (right); each bound holds below the dashed line.")
    if results.cameras:
        out[EMULATION_FIGURE] = svg_figure(
            vf.emulation_plot(results.cameras), EMULATION_FIGURE,
            "emulation accuracy per camera",
            "Mean and largest ΔE00 between the emulated and the camera's own rendered chart, "
            "cameras by chart ΔE.")
    return out


def _table_order(summ: ValidationSummary) -> list[str]:
    return [summ.bound_table] + [t for t in summ.tables if t != summ.bound_table]


# --------------------------------------------------------------------------------------------
# Words
# --------------------------------------------------------------------------------------------


def spearman(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Spearman rank correlation (scipy.stats.spearmanr); None for fewer than 3 pairs."""
    if len(x) < 3:
        return None
    from scipy.stats import spearmanr

    r = spearmanr(x, y).statistic
    return None if not np.isfinite(r) else float(r)


def failure_reason(row: ValidationRow, cls: str, camera: CameraRecord) -> str:
    """One-paragraph, data-derived explanation of a bound failure (for the report).

    Combines: the excess over the bound in units of the measurement's standard error; where on
    the table the prediction came from (status); the direction of the chart error (shares of
    ``|ΔL'|``, ``|ΔC'|``, ``|ΔH'|``, signed mean ΔL' and ΔC', lightness contrast ratio, neutral
    cast); and
    the image-level ΔE00 of the emulation compared with the chart ΔE.
    """
    b = row.bound[cls]
    prof = camera.profile
    excess = b.excess or 0.0
    parts = [f"measured {number(b.measured)} > predicted {number(b.predicted)} "
             f"(excess {excess:.2f}"]
    se = b.se
    if se:
        parts[0] += f", {excess / se:.1f} SE; SE {se:.2f})"
        parts.append("inside sampling noise (excess < 2 SE)" if excess < 2 * se else
                     "larger than the sampling noise (excess >= 2 SE)")
    else:
        parts[0] += ")"
    if b.status == "below-range":
        parts.append("the chart ΔE lies below the table's first point, so the bound there is the "
                     "first point's value")
    parts.append(f"chart error mostly {prof.dominant} (|ΔL'| {prof.share_l:.0%}, "
                 f"|ΔC'| {prof.share_c:.0%}, |ΔH'| {prof.share_h:.0%}; mean ΔL' "
                 f"{prof.mean_dl:+z.1f}, mean ΔC' {prof.mean_dc:+z.1f}, contrast ratio "
                 f"{prof.contrast_ratio:.2f}, neutral cast a*,b* "
                 f"{prof.neutral_cast_ab[0]:+z.1f},{prof.neutral_cast_ab[1]:+z.1f})")
    ide = camera.image_delta_e
    if ide is not None:
        parts.append(f"on photos the emulation moves colours by ΔE00 {ide.mean:.1f} on average "
                     f"(p95 {ide.p95:.1f}) against chart ΔE {camera.chart_delta_e:.1f}")
    return "; ".join(parts) + "."


def _conventions_words(conv: Mapping[str, Any]) -> str:
    extra = [str(conv[k]) for k in ("source", "preprocess") if conv.get(k)]
    return "; ".join([conventions_words(conv), *extra])


def _photo_delta_e(camera: CameraRecord) -> float:
    return camera.image_delta_e.mean if camera.image_delta_e is not None else float("nan")


# --------------------------------------------------------------------------------------------
# Document
# --------------------------------------------------------------------------------------------


def headline(results: ValidationResults, figure: Figure | None = None) -> Headline:
    """Does the bound table bound the measured loss: cells and cameras within it, per class.

    Tone: pass when every judged cell is within the bound, fail when some cell exceeds it by
    more than 2 standard errors, info otherwise (exceedances within the sampling noise).
    """
    summ = results.summary
    if not results.rows:
        return Headline("No finished (camera, model) cell yet: nothing to compare.", "info",
                        figure)
    lines = [f"**Does the worst-case table `{summ.bound_table}` bound the measured loss?**", ""]
    for cls, s in summ.classes.items():
        if not s.cells:
            lines.append(f"- {CLASS_TITLES[cls]}: no cell with a value to compare.")
            continue
        lines.append(f"- {CLASS_TITLES[cls]}: within the bound in **{s.within} of {s.cells}** "
                     f"cells ({s.within_2se} of {s.cells} up to 2 SE); cameras within (all "
                     f"models) {s.cameras_within} of {s.cameras}"
                     + (f" ({100 * s.share_cameras_within:.0f} %)"
                        if s.share_cameras_within is not None else "") + ".")
    dv = results.directional
    if dv is not None and "all" in dv.summary and dv.summary["all"].cells:
        d = dv.summary["all"]
        lines.append(f"- Direction-aware bound (`{dv.table}`), mAP: within in **{d.directional_within}"
                     f" of {d.cells}** cells ({d.directional_within_2se} of {d.cells} up to 2 "
                     f"SE); median over-prediction {number(d.directional_median_ratio, 1)}× "
                     f"against {number(d.classic_median_ratio, 1)}× for the classic bound.")
        warned = sorted(c.camera for c in dv.cameras.values() if c.warnings)
        if warned:
            lines.append(f"- Blind-spot warnings for {len(warned)} of {len(dv.cameras)} "
                         f"cameras: {', '.join(warned)}.")
    judged = [s for s in summ.classes.values() if s.cells]
    tone: Tone = "pass"
    if any(s.within < s.cells for s in judged):
        tone = "fail" if any(s.within_2se < s.cells for s in judged) else "info"
    return Headline("\n".join(lines), tone, figure)


def _bound_section(results: ValidationResults) -> Section:
    rows, summ, cams = results.rows, results.summary, results.cameras
    body = []
    for cls in LOSS_COLUMNS:
        s = summ.classes[cls]
        share = number(None) if s.share_cameras_within is None else \
            f"{100 * s.share_cameras_within:.0f} %"
        body.append([cls, f"{s.within}/{s.cells}", f"{s.within_2se}/{s.cells}",
                     f"{s.cameras_within}/{s.cameras}", share])
    notes = []
    for t in summ.tables:
        xs = [(pv, mv) for r in rows if (pv := r.predicted[t].losses.dmap_points) is not None
              and (mv := r.measured.dmap_points) is not None]
        if xs:
            pred = [x[0] for x in xs]
            meas = [x[1] for x in xs]
            err = np.array(meas) - np.array(pred)
            notes.append(f"- `{t}` ({rows[0].predicted[t].kind}): mAP measured − predicted: "
                         f"median {np.median(err):+z.2f} points, max {err.max():+z.2f}; Spearman "
                         f"ρ(predicted, measured) = {number(spearman(pred, meas))}; within for "
                         f"{int(np.sum(err <= 0))}/{len(err)} cells.")
    if rows:
        de = [r.chart_delta_e for r in rows]
        loss = [_points(r) for r in rows]
        photo = [_photo_delta_e(cams[r.camera]) for r in rows]
        notes.append(f"- Spearman ρ(chart ΔE, measured ΔmAP) = {number(spearman(de, loss))}; "
                     "ρ(photo ΔE00 of the emulation on COCO images, measured ΔmAP) = "
                     f"{number(spearman(photo, loss))} (all cells, both models).")
        for m in sorted({r.model for r in rows}):
            mr = [r for r in rows if r.model == m]
            rho = spearman([r.chart_delta_e for r in mr], [_points(r) for r in mr])
            notes.append(f"  - `{m}`: ρ(chart ΔE, ΔmAP) = {number(rho)} over {len(mr)} "
                         f"cameras; largest measured ΔmAP {max(_points(r) for r in mr):.2f} "
                         "points.")
    return section(
        f"Within the bound of {summ.bound_table}, per class",
        table(["class", "cells within bound", "within bound up to 2 SE",
               "cameras within bound (all models)", "share"], body),
        Text("\n".join(notes)) if notes else None)


def _analysis_section(results: ValidationResults) -> Section | None:
    """The written answer of the validation, every number computed from ``results``: where the
    bound table fails (and how many of those cells a verdict at the default ΔE limit passes),
    how many measured losses the measurement resolves, and how far the bound over-predicts
    where it does."""
    rows, summ = results.rows, results.summary
    judged = [r for r in rows if r.bound["all"].within is not None]
    if not judged:
        return None
    t = summ.bound_table
    lines = ["mAP@[.50:.95] losses in points, generated from the cells below.", ""]
    misses = sorted((r for r in judged if not r.bound["all"].within),
                    key=lambda r: -(r.bound["all"].excess or 0.0))
    lines.append(f"- `{t}` bounds the measured loss in **{len(judged) - len(misses)} of "
                 f"{len(judged)}** cells"
                 + (f"; it is exceeded in {len(misses)}:" if misses else "."))
    for r in misses:
        b = r.bound["all"]
        z = "" if not b.se else f", {b.excess / b.se:.1f} SE" if b.excess is not None else ""
        lines.append(f"  - `{r.camera}` / {r.model} ({r.illuminant}, chart ΔE "
                     f"{r.chart_delta_e:.2f}): measured {b.measured:.2f} ± "
                     f"{number(b.se)} against {b.predicted:.2f} (excess {b.excess:.2f}{z})")
    if misses:
        low = [r for r in misses if r.chart_delta_e <= DEFAULT_MAX_DELTA_E]
        inside = sum(1 for r in misses if r.bound["all"].within_2se)
        lines.append(f"- {len(low)} of these {len(misses)} cells have chart ΔE ≤ "
                     f"{DEFAULT_MAX_DELTA_E:g} (the default `--max-delta-e` of `check` and "
                     "`gate`), which a verdict on ΔE alone passes; "
                     f"{inside} of {len(misses)} excesses are within 2 SE of the bound.")
    resolved = [r for r in judged if r.bound["all"].se and
                r.bound["all"].measured is not None and
                r.bound["all"].measured > 2 * r.bound["all"].se]
    ses = {m: [r.bound["all"].se for r in judged if r.model == m and r.bound["all"].se]
           for m in sorted({r.model for r in judged})}
    lines.append(f"- The measurement resolves {len(resolved)} of {len(judged)} losses (more "
                 "than 2 SE above zero); median SE "
                 + ", ".join(f"{m} {float(np.median(v)):.2f} points on "
                             f"{max(r.images for r in judged if r.model == m)} images"
                             for m, v in ses.items() if v) + ".")
    ratios = sorted((r.bound["all"].predicted / r.bound["all"].measured, r) for r in resolved
                    if r.bound["all"].predicted is not None and r.bound["all"].measured)
    if ratios:
        worst = ratios[-1][1]
        lines.append(f"- Where a loss is resolved, `{t}` predicts a median "
                     f"{float(np.median([x for x, _ in ratios])):.1f}× the measured loss "
                     f"({ratios[0][0]:.1f}-{ratios[-1][0]:.1f}×); the largest over-prediction "
                     f"is `{worst.camera}` / {worst.model} (chart ΔE "
                     f"{worst.chart_delta_e:.2f}): {worst.bound['all'].predicted:.2f} predicted "
                     f"against {worst.bound['all'].measured:.2f} ± "
                     f"{number(worst.bound['all'].se)} measured.")
    return section("Answer", Text("\n".join(lines)))


def _points(r: ValidationRow) -> float:
    v = r.measured.dmap_points
    return float("nan") if v is None else v


def _plots_section(results: ValidationResults, figures: Mapping[str, Figure]) -> Section | None:
    summ = results.summary
    others = [figures[n] for t in _table_order(summ)[1:] if (n := scatter_figure(t)) in figures]
    blocks: list[Block | None] = [*others, figures.get(VS_DELTA_E_FIGURE)]
    if not any(blocks):
        return None
    return section("Predicted and measured loss", *blocks)


def _failures_sections(results: ValidationResults) -> list[Section]:
    rows, cams = results.rows, results.cameras
    out = []
    for cls in ("all", "all-relative", "person", "bicycle"):
        fails = [r for r in rows if r.bound[cls].within is False]
        if not fails:
            continue
        items = [f"- **{r.camera}** / {r.model} ({r.illuminant}, chart ΔE "
                 f"{r.chart_delta_e:.2f}): {failure_reason(r, cls, cams[r.camera])}"
                 for r in sorted(fails, key=lambda r: -(r.bound[cls].excess or 0.0))]
        out.append(section(CLASS_TITLES[cls], Text("\n".join(items)), level=3))
    if not out:
        return [section("Every case where the bound fails",
                        Text("None: every finished cell is within the bound."))]
    return [section("Every case where the bound fails",
                    Text("Every (camera, model) cell whose measured loss is above the "
                         "worst-case prediction, per class, largest excess first, with what "
                         "the data say about it."))] + out


def _directional_sections(results: ValidationResults, figures: Mapping[str, Figure]
                          ) -> list[Section]:
    """Both bounds on every cell (summary, figure, per cell with over-prediction ratios)."""
    dv = results.directional
    if dv is None:
        return []
    summ = dv.summary
    body = []
    for cls, s in summ.items():
        body.append([CLASS_TITLES.get(cls, cls), f"{s.classic_within}/{s.cells}",
                     f"{s.classic_within_2se}/{s.cells}", f"{s.directional_within}/{s.cells}",
                     f"{s.directional_within_2se}/{s.cells}",
                     number(s.classic_median_ratio), number(s.directional_median_ratio),
                     f"{number(s.classic_median_ratio_significant)} / "
                     f"{number(s.directional_median_ratio_significant)} "
                     f"({s.significant_cells})"])
    intro = Text(
        f"The direction-aware prediction (`fidelity.prediction.directional`, table "
        f"`{dv.table}`) charges each part of a camera's chart error the worst loss of the "
        "SAFE-COLOR transforms that move the chart that way: the share a fitted transform "
        "explains at that transform family's curve, the rest split into lightness, chroma and "
        "hue at the curves of tone (brightness, gamma), saturation and hue transforms, every "
        "curve read at the camera's chart ΔE. Each camera's chart is rendered again (closed "
        "form). Over-prediction ratio = predicted / measured, over the cells with a positive "
        "measured loss (in brackets: over the cells measured more than 2 SE above 0, and "
        "their number).")
    rows = []
    for r in sorted(dv.rows, key=lambda r: (r.chart_delta_e, r.model)):
        c = r.cells["all"]
        cam = dv.cameras[r.camera]
        rows.append([r.camera, r.model, f"{r.chart_delta_e:.2f}",
                     number(c.measured) + (f" ± {c.se:.2f}" if c.se else ""),
                     number(c.classic), number(c.ratio(c.classic), 1),
                     number(c.directional), number(c.ratio(c.directional), 1),
                     "yes" if c.directional_within_2se else "**no**",
                     cam.prediction.explanation()])
    return [
        section("Direction-aware bound against the classic one", intro,
                table(["class", "classic within", "classic within 2 SE",
                       "direction-aware within", "direction-aware within 2 SE",
                       "classic median ratio", "direction-aware median ratio",
                       "median ratios, cells > 2 SE (n)"], body),
                figures.get(BOUNDS_FIGURE)),
        section("Over-prediction per camera (ΔmAP, points)", table(
            ["camera", "model", "chart ΔE", "measured", "classic", "ratio",
             "direction-aware", "ratio", "within 2 SE", "charged as"], rows,
            numeric=[False, False] + [True] * 6 + [False, False]), folded=True),
    ]


def _blind_spot_sections(results: ValidationResults) -> list[Section]:
    """The blind-spot checks of every camera: the warnings, then every check (folded)."""
    dv = results.directional
    if dv is None:
        return []
    meas = {(r.camera, r.model): r.cells["all"] for r in dv.rows}
    warned = [c for c in dv.cameras.values() if c.warnings]
    lines = []
    for c in sorted(warned, key=lambda c: c.chart_delta_e):
        got = "; ".join(f"{m}: measured {number(x.measured)} ± {number(x.se)}, classic "
                        f"{number(x.classic)}, direction-aware {number(x.directional)}"
                        for (k, m), x in sorted(meas.items()) if k == c.camera)
        for w in c.warnings:
            lines.append(f"- **{c.camera}** (chart ΔE {c.chart_delta_e:.2f}): {w.reason}. "
                         f"ΔmAP {got}.")
    text = (f"{len(warned)} of {len(dv.cameras)} cameras get a warning "
            "(`fidelity.measure.blindspots`: shadow tone of the neutral patches, the camera's "
            "bit depth):\n\n" + "\n".join(lines)) if warned else \
        f"None of the {len(dv.cameras)} cameras gets a warning."
    rows = [[c.camera, b.kind, {True: "**at risk**", False: "no", None: "not judged"}[b.at_risk],
             number(b.value, 3), b.reason]
            for c in sorted(dv.cameras.values(), key=lambda c: c.camera) for b in c.blind_spots]
    return [section("Blind-spot warnings", Text(text)),
            section("Blind-spot checks per camera", table(
                ["camera", "check", "at risk", "value", "reason"], rows,
                numeric=[False, False, False, True, False]), folded=True)]


def _per_camera_section(results: ValidationResults) -> Section:
    rows, cams, bound = results.rows, results.cameras, results.summary.bound_table

    def cell(r: ValidationRow, k: str) -> str:
        v = r.bound[k]
        if v.measured is None:
            return number(None)
        s = f"{v.measured:.2f}" + (f" ± {v.se:.2f}" if v.se else "")
        return f"**{s}**" if v.within is False else s

    body = []
    for r in sorted(rows, key=lambda r: (r.chart_delta_e, r.model)):
        c = cams[r.camera]
        pr = c.profile
        b = r.bound
        body.append([r.camera, r.illuminant, f"{r.chart_delta_e:.2f}",
                     f"{pr.dominant} ({pr.share_l:.2f}/{pr.share_c:.2f}/{pr.share_h:.2f})",
                     f"{pr.contrast_ratio:.2f}",
                     number(c.image_delta_e.mean if c.image_delta_e else None, 1), r.model,
                     cell(r, "all"), number(b["all"].predicted), cell(r, "person"),
                     number(b["person"].predicted), cell(r, "bicycle"),
                     number(b["bicycle"].predicted)])
    return section(
        "Per camera",
        Text("Losses in percentage points (positive = worse than the baseline), measured ± SE; "
             f"predicted = `{bound}`. Bold: measured loss above the worst-case prediction."),
        table(["camera", "illuminant", "chart ΔE", "dominant error (L/C/H share)", "contrast",
               "photo ΔE00", "model", "ΔmAP meas.", "ΔmAP pred.", "Δperson meas.",
               "Δperson pred.", "Δbicycle meas.", "Δbicycle pred."], body,
              numeric=[False, False, True, False, True, True, False] + [True] * 6),
        folded=True)


def _other_tables_section(results: ValidationResults) -> Section | None:
    summ = results.summary
    other = [t for t in summ.tables if t != summ.bound_table]
    if not other or not results.rows:
        return None
    body = [[r.camera, r.model, f"{r.chart_delta_e:.2f}", number(r.measured.dmap_points)]
            + [number(r.predicted[t].losses.dmap_points) for t in other]
            for r in sorted(results.rows, key=lambda r: (r.chart_delta_e, r.model))]
    return section("Other tables' predictions of ΔmAP (points)",
                   table(["camera", "model", "chart ΔE", "measured", *other], body,
                         numeric=[False, False] + [True] * (2 + len(other))),
                   folded=True)


def _emulation_sections(results: ValidationResults, figures: Mapping[str, Figure]
                        ) -> list[Section]:
    cams = results.cameras
    names = sorted(cams, key=lambda k: cams[k].chart_delta_e)
    accs = [cams[n].emulation.accuracy for n in names]
    summary = None
    if accs:
        means = np.array([a.chart_mean_delta_e for a in accs])
        maxes = np.array([a.chart_max_delta_e for a in accs])
        gap = np.array([abs(a.emulated_chart_delta_e - a.camera_chart_delta_e) for a in accs])
        text = (f"Over {len(accs)} cameras: chart mean ΔE00 (emulated vs camera) at most "
                f"{means.max():.2f} (median {np.median(means):.2f}); worst single patch "
                f"{maxes.max():.2f}; the emulated chart's ΔE differs from the camera's by at "
                f"most {gap.max():.2f}.")
        hs = [h for n in cams if (h := cams[n].emulation.holdout) is not None]
        if hs:
            hm = np.array([h.chart_mean_delta_e for h in hs])
            text += (f" Held out (chart spectra not in the fit): chart mean ΔE00 at most "
                     f"{hm.max():.2f} (median {np.median(hm):.2f}); worst single patch "
                     f"{max(h.chart_max_delta_e for h in hs):.2f}.")
        summary = Text(text)
    intro = Text(
        "The fitted mapping is applied to the reference chart as an 8-bit image (the same 256³ "
        "table used on COCO) and compared with the camera's own rendered chart (CIEDE2000 per "
        "patch). Training: mean and 95th percentile over all training colours (in-sample). "
        "Chart ΔE columns: the camera's chart ΔE and the emulated chart's, both against the "
        "reference. Held out: the same method fitted without the 24 chart spectra, checked on "
        "the chart (out of sample).")
    body = []
    for name in names:
        c = cams[name]
        a = c.emulation.accuracy
        h = c.emulation.holdout
        hold = number(None) if not h else \
            f"{h.chart_mean_delta_e:.2f} / {h.chart_max_delta_e:.2f}"
        oth = "; ".join(f"{k}: {v.chart_mean_delta_e:.2f} / {v.chart_max_delta_e:.2f}"
                        for k, v in c.emulation.other_methods.items())
        body.append([name, c.illuminant, f"{a.camera_chart_delta_e:.2f}",
                     f"{a.emulated_chart_delta_e:.2f}", f"{a.chart_mean_delta_e:.2f}",
                     f"{a.chart_max_delta_e:.2f} ({a.chart_worst_patch})", hold,
                     f"{a.training_mean_delta_e:.2f}", f"{a.training_p95_delta_e:.2f}", oth])
    return [
        section("Emulation accuracy", summary, figures.get(EMULATION_FIGURE), intro),
        section("Emulation accuracy per camera", table(
            ["camera", "illuminant", "chart ΔE camera", "chart ΔE emulated", "chart mean",
             "chart max (patch)", "held-out chart mean / max", "training mean", "training p95",
             "other method chart mean / max"], body,
            numeric=[False, False] + [True] * 7 + [False]), folded=True),
    ]


def _cameras_section(results: ValidationResults) -> Section:
    cams = results.cameras
    return section("Cameras", table(
        ["camera", "illuminant", "chromatic adaptation", "description"],
        [[n, cams[n].illuminant, cams[n].cat, cams[n].description] for n in sorted(cams)],
        numeric=[False, False, False, False]), folded=True)


def adaptation_words(results: ValidationResults) -> str:
    """``the scene reference adapted to D65 with Bradford (28 cameras) and CAT02 (2)``: the
    chromatic adaptation transforms of the cameras' chart ΔE, counted from their records."""
    counts = sorted(Counter(c.cat for c in results.cameras.values()).items(),
                    key=lambda kv: (-kv[1], kv[0]))
    if not counts:
        return "no camera recorded"
    parts = [f"{cat} ({n})" for cat, n in counts]
    parts[0] = f"{counts[0][0]} ({counts[0][1]} camera{'s' if counts[0][1] != 1 else ''})"
    listed = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return f"the scene reference adapted to D65 with {listed}"


def _baselines_section(results: ValidationResults) -> Section:
    rows = [[f"`{m}`", f"{b.map:.4f}", f"{b.map50:.4f}", number(b.ap.get("person"), 4),
             number(b.ap.get("bicycle"), 4), str(b.images)]
            for m, b in sorted(results.baselines.items())]
    return section("Baselines (ΔE = 0: JPEG round trip only)", table(
        ["model", "mAP", "AP50", "AP person", "AP bicycle", "images"], rows))


def _run_section(results: ValidationResults) -> Section:
    meta, summ, cams = results.meta, results.summary, results.cameras
    data = portable_paths(meta.get("data", {}))
    lines = [f"- Images: COCO val2017 subset at `{data.get('images')}` "
             f"({data.get('image_count')} annotated images), annotations "
             f"`{data.get('annotations')}`."]
    for m, info in sorted(results.models.items()):
        n = info.limit_images or data.get("image_count")
        st = info.settings
        size = st.get("input_size")
        lines.append(
            f"- Model `{m}` (`{info.file}`, sha256 {info.sha256[:16]}…): first {n} images by "
            f"id; layout {st.get('layout')}, input "
            + ("×".join(map(str, size)) if isinstance(size, list) else str(size))
            + f", conventions {_conventions_words(st.get('conventions') or {})}, threads "
            f"{st.get('threads')}.")
    lines.append(f"- Cameras: {len(cams)} camera files from `cameras/` (listed below with "
                 "their scene illuminants and chromatic adaptation transforms); chart rendered "
                 "in closed form; ΔE = mean CIEDE2000 over the 24 patches against the "
                 f"scene-consistent reference ({adaptation_words(results)}"
                 "; the emulation's training reference: Bradford).")
    if summ.not_in_suite:
        lines.append(f"- Left out: {len(summ.not_in_suite)} camera(s) in the store but not in "
                     "the suite given (renamed or removed camera files): "
                     f"{', '.join(summ.not_in_suite)}.")
    st = meta.get("settings", {})
    lines.append(f"- Emulation: `{st.get('emulation_method')}` fitted on `{st.get('training')}` "
                 "reflectances (chart + colour-science spectral data); JPEG: "
                 f"{st.get('jpeg')}. ΔE = 0 baseline: the same round trip without colour "
                 "change.")
    lines.append("- Prediction: `fidelity.prediction.table.predict(chart ΔE, size='n', "
                 "baseline_map=...)` with tables "
                 f"{', '.join(f'`{t}`' for t in summ.tables)}; the bound tested is "
                 f"`{summ.bound_table}`.")

    lines.append(f"- Standard errors: {STANDARD_ERROR_WORDS[summ.standard_error]}"
                 + (" (rebuild with `--annotations` to score the bootstrap's draws)"
                    if summ.standard_error not in ("larger", "bootstrap") else "") + ".")
    lines.append(f"- Versions: {words(meta.get('versions'))}; machine: "
                 f"{words(meta.get('machine'))}.")
    finished = sorted({r.camera for r in results.rows})
    lines.append(f"- Finished: {len(results.rows)} (camera, model) cells, {len(finished)} of "
                 f"{len(cams)} cameras with at least one model.")
    return section("What was run", Text("\n".join(lines)))


def validation_document(results: ValidationResults, notes: str | None = None,
                        figures: Mapping[str, Figure] | None = None) -> Document:
    """The validation report of ``results``; ``notes`` (Markdown) is the "Analysis" section;
    figures: :func:`validation_figures`, made when not given."""
    figs = dict(figures) if figures is not None else validation_figures(results)
    bound_fig = figs.get(scatter_figure(results.summary.bound_table))
    sections: list[Section | None] = [
        _bound_section(results),
        _analysis_section(results),
        section("Notes", Text(notes.strip())) if notes else None,
        _plots_section(results, figs),
        *_directional_sections(results, figs),
        *_blind_spot_sections(results),
        *_failures_sections(results),
        _per_camera_section(results),
        _other_tables_section(results),
        *_emulation_sections(results, figs),
        _cameras_section(results),
        _baselines_section(results),
        _run_section(results),
    ]
    return Document(
        TITLE, headline(results, bound_fig), tuple(s for s in sections if s is not None),
        subtitle="Generated by `fidelity validate` (fidelity/coco/validate/) from the results "
                 "store; every number below is computed from stored detections and chart "
                 "renders.")


def write_validation_document(results: ValidationResults, out_dir: str | os.PathLike[str],
                              notes: str | None = None) -> list[Path]:
    """Write ``validation.html`` and ``validation.md`` with its SVG figures (atomically); the
    report alone, e.g. rebuilt from a ``validation.json`` (:meth:`ValidationResults.from_json`).

    Figures: predicted against measured with the identity line per class (all, person,
    bicycle), one per prediction table; measured loss against chart ΔE with the tables'
    worst-case curves; emulation accuracy per camera.
    """
    out = Path(out_dir)
    return write_document(validation_document(results, notes), html=out / "validation.html",
                          markdown=out / "validation.md")


def write_validation_report(results: ValidationResults, out_dir: str | os.PathLike[str],
                            notes: str | None = None) -> list[Path]:
    """Write the report (:func:`write_validation_document`), ``validation.json`` and, when
    the results carry both bounds (:mod:`fidelity.coco.bounds`), ``directional.json``
    (derived from ``validation.json``, the camera files and the shipped tables, so kept
    apart); atomically; returns the paths written."""
    written = write_validation_document(results, out_dir, notes)
    doc = results.to_json()
    directional = doc.pop("directional", None)
    written.append(write_json_atomic(Path(out_dir) / "validation.json", doc))
    if directional is not None:
        written.append(write_json_atomic(Path(out_dir) / "directional.json", directional))
    return written


__all__ = [
    "BOUNDS_FIGURE",
    "CLASS_TITLES",
    "EMULATION_FIGURE",
    "TITLE",
    "VS_DELTA_E_FIGURE",
    "adaptation_words",
    "failure_reason",
    "headline",
    "scatter_figure",
    "spearman",
    "validation_document",
    "validation_figures",
    "write_validation_document",
    "write_validation_report",
]
