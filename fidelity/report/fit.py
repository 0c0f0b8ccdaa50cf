"""The fit of a correction (``fidelity fit``) as terminal lines, an HTML document and files.

Renders a :class:`~fidelity.pipeline.fit.FitReport`: :func:`fit_lines` for the terminal,
:func:`fit_document` for the HTML report (before/after swatches and ΔE maps, the per-patch
table, the ``.cube``'s check, the correction) and :func:`write_fit_report` for the files.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fidelity.core.fileio import json_ready
from fidelity.correction.lut import default_output
from fidelity.pipeline.fit import EXPRESSED_DELTA_E, FitReport, PropertyFit, SharedFit
from fidelity.report import chartfigures
from fidelity.report.chart import write_report_files
from fidelity.report.compare import property_comparison_lines
from fidelity.report.document import (
    Code,
    Document,
    Facts,
    Headline,
    section,
    svg_figure,
    table,
)
from fidelity.report.jsonform import fit_json, shared_fit_json


def _n(v: float | None) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v:.2f}"


def cube_line(report: FitReport) -> str:
    """The ``.cube``'s convention in one line: what it takes, what it gives, and whether that
    is the SIM's own encoding (as ffmpeg, oiiotool and OpenColorIO apply a cube)."""
    c = report.correction
    inp, out = c.cube_convention(report.output)
    other = "linear" if report.output == "encoded" else "encoded"
    same = report.output == default_output(c.encoding)
    return (f".cube convention: input the SIM's pixels, {inp}; output corrected {out} pixels, "
            + ("the SIM's own encoding (ffmpeg lut3d, oiiotool --ociofiletransform and an "
               "OpenColorIO FileTransform apply it as it is)" if same else
               "not the SIM's encoding")
            + f"; --cube-output {other} for the other convention")


def fit_lines(report: FitReport) -> list[str]:
    """The fit on a terminal: the model, the excluded patches, the conditioning, the
    sim-to-real ΔE00 before and after with their predicted ΔmAP, the fitted and
    cross-validated ΔE00, the ``.cube``'s check and convention, and a note where the
    simulation already matched (its warnings are :attr:`FitReport.warnings`, which the
    command prints apart)."""
    c, lut = report.correction, report.lut
    b, a = report.before, report.after
    lines = [f"model: {c.model.name} ({c.objective} objective), fitted on {len(c.used)} of "
             f"{len(c.patch_names)} patches; normalisation: {c.normalisation.describe()}"]
    if (words := c.normalisation.difference_words()) is not None:
        lines.append(f"exposure: {words}")
    lines += [f"excluded: {name}: {why}" for name, why in c.excluded.items()]
    if c.conditioning.reason:
        lines.append(f"regularised: {c.conditioning.reason}")
    lines += [
        f"sim-to-real ΔE00 before: mean {b.mean_delta_e:.2f}, max {b.max_delta_e:.2f} "
        f"({b.worst_patch}); predicted ΔmAP {_n(report.prediction_before.dmap_points)} points",
        f"sim-to-real ΔE00 after (SIM through the .cube by OpenColorIO, measured again): mean "
        f"{a.mean_delta_e:.2f}, max {a.max_delta_e:.2f} ({a.worst_patch}); predicted ΔmAP "
        f"{_n(report.prediction_after.dmap_points)} points",
        f"fitted ΔE00 (used patches): mean "
        f"{float(np.mean(c.fitted_delta_e[[n in c.used for n in c.patch_names]])):.2f}; "
        f"cross-validated (leave-3-out): mean {_n(c.cv_mean)}, max "
        f"{_n(float(np.nanmax(c.cv_delta_e)))}",
        f".cube {lut.size}^3 through OpenColorIO against the model: max ΔE00 "
        f"{lut.chart_max:.3f} over the chart, {lut.grid_max:.3f} over {lut.grid_points} "
        f"lattice points (99th percentile {lut.grid_p99:.3f}, "
        f"{100 * lut.grid_within:.2f} % within {lut.tolerance:g}; limit "
        f"{'met' if lut.passed else 'NOT met'}: {lut.limit()})",
        cube_line(report),
    ]
    lines += property_lines(report)
    for side, losses in (("before", report.measured_before), ("after", report.measured_after)):
        lines += [f"COCO, the simulator's colours {side} the correction: {m.summary()}"
                  for m in losses]
    if b.mean_delta_e <= EXPRESSED_DELTA_E:  # nothing to lower: the fit is near the identity
        lines.append(f"note: the simulation already matches the real camera (sim-to-real ΔE00 "
                     f"mean {b.mean_delta_e:.2f}, at most {EXPRESSED_DELTA_E:g}); the "
                     "correction is close to the identity")
    return lines


def _value(v: float | None, u: float | None = None) -> str:
    if v is None:
        return "not measured"
    if math.isinf(v):
        return "inf (noiseless)"
    return f"{v:.4g}" + ("" if u is None else f" ± {u:.2g}")


def camera_fit_line(fit: PropertyFit) -> str:
    """One fitted camera-file property on a line: the field and its value, the measured
    value before, after (the written file's turned chart) and REAL's, or why it was not
    fitted."""
    name = "optics" if fit.property == "sharpness" else "noise"
    if fit.value is None:
        return f"{name} not fitted: {fit.note}"
    what = "MTF50 (cy/px)" if fit.property == "sharpness" else "SNR at 18 % grey"
    values = (f"{what} {_value(fit.before)} -> {_value(fit.after)}, REAL "
              f"{_value(fit.real, fit.u_real)}")
    if fit.property == "sharpness":
        field = (f"Gaussian PSF sigma {fit.value:.4g} px ({fit.parameter})" if fit.value > 0
                 else "no PSF")
    else:
        field = f"full well {fit.value:.5g} e- ({fit.parameter}; read noise kept)"
    tail = f"; {fit.note}" if fit.note else ""
    return (f"{name} fitted: {field}: {values} ({'matched' if fit.matched() else 'NOT matched'},"
            f" {fit.steps} render{'' if fit.steps == 1 else 's'}){tail}")


def property_lines(report: FitReport) -> list[str]:
    """Sharpness and noise of the fit: the two charts compared at the detector's input
    (:func:`fidelity.report.compare.property_comparison_lines`) and, for ``fit --camera``,
    each fitted camera-file property (:func:`camera_fit_line`); else a note that the
    ``.cube`` corrects colour only."""
    lines = property_comparison_lines(report.sim_properties, report.real_properties)
    if report.camera_fits:
        return lines + [camera_fit_line(f) for f in report.camera_fits]
    if lines:
        lines.append("the .cube corrects colour only: sharpness and noise stay as they are "
                     "(fit --camera CAMERA.toml fits a camera file's optics and noise too)")
    return lines


def fit_document(report: FitReport) -> Document:
    """The fit as a :class:`~fidelity.report.document.Document`."""
    c, b, a, lut = report.correction, report.before, report.after, report.lut
    after_fig = svg_figure(chartfigures.swatches(a, ("real camera", "corrected simulation")),
                           "after.svg", "real camera (left half) against the corrected simulation "
                       "(right half)")
    note = ("" if c.expressed else
            f"; the {c.model.name} model does not express the difference (cross-validated "
            f"ΔE00 above {EXPRESSED_DELTA_E:g})")
    head = Headline(f"sim-to-real ΔE00 {b.mean_delta_e:.2f} before, **{a.mean_delta_e:.2f}** "
                    f"after the {c.model.name} correction (cross-validated {_n(c.cv_mean)})"
                    f"{note}", "fail" if report.warnings else "info", after_fig)
    facts = Facts((
        ("simulation", f"`{report.sim}`"), ("real camera", f"`{report.real}`"),
        ("model", f"{c.model.name}, {c.objective} objective"),
        ("normalisation", c.normalisation.describe()),
        *([("exposure difference", w)] if (w := c.normalisation.difference_words()) else []),
        ("patches used", f"{len(c.used)} of {len(c.patch_names)}"),
        ("conditioning", f"condition number {c.conditioning.condition_number:.3g}"
                         + (f"; {c.conditioning.reason}" if c.conditioning.reason else "")),
        ("sim-to-real ΔE00 before", f"mean {b.mean_delta_e:.2f}, max {b.max_delta_e:.2f}"),
        ("sim-to-real ΔE00 after", f"mean {a.mean_delta_e:.2f}, max {a.max_delta_e:.2f}"),
        ("predicted ΔmAP before → after", f"{_n(report.prediction_before.dmap_points)} → "
                                          f"{_n(report.prediction_after.dmap_points)} points"),
        ("cross-validated ΔE00", f"mean {_n(c.cv_mean)}"),
        *[(f"measured on COCO {side}", m.summary())
          for side, losses in (("before", report.measured_before),
                               ("after", report.measured_after)) for m in losses],
        (".cube check", f"{lut.size}³: max ΔE00 {lut.chart_max:.3f} (chart), "
                        f"{lut.grid_max:.3f} ({lut.grid_points} lattice points, 99th "
                        f"percentile {lut.grid_p99:.3f}); limit "
                        f"{'met' if lut.passed else 'not met'} ({lut.limit()})"),
        (".cube convention", "input {}; output {}".format(*c.cube_convention(report.output))),
        *[("warning", w) for w in report.warnings],
        *[(line.split(":", 1)[0], line.split(":", 1)[1].strip())
          for line in property_lines(report)],
    ))
    rows = [(n, f"{b.delta_e[k]:.2f}", f"{a.delta_e[k]:.2f}", f"{c.fitted_delta_e[k]:.2f}",
             _n(float(c.cv_delta_e[k])), c.excluded.get(n, "used"))
            for k, n in enumerate(c.patch_names)]
    sections = [
        section("Summary", facts),
        section("Before and after", svg_figure(chartfigures.swatches(b, ("real camera", "simulation")),
                                               "before.svg", "before: real camera (left half) "
                                           "against the simulation (right half)"),
                after_fig,
                svg_figure(chartfigures.delta_e_map(b), "before_map.svg", "sim-to-real ΔE00 before"),
                svg_figure(chartfigures.delta_e_map(a), "after_map.svg", "sim-to-real ΔE00 after"),
                gallery=True),
        section("Per patch", table(("patch", "ΔE00 before", "ΔE00 after (through the .cube)",
                                    "ΔE00 fitted", "ΔE00 cross-validated", "fit"), rows)),
        section("The correction", Code(json.dumps(json_ready(c.model.to_json()), indent=1))),
        section("Files and timing", Code(json.dumps(json_ready(
            {"files": report.files, "seconds": report.seconds}), indent=1)), folded=True),
    ]
    return Document(f"Fit: {Path(report.sim).name} towards {Path(report.real).name}", head,
                    tuple(sections))


def write_fit_report(report: FitReport, *, json_path: str | os.PathLike[str] | None = None,
                     html_path: str | os.PathLike[str] | None = None,
                     protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML fit report atomically, never over an input."""
    return write_report_files(lambda: fit_json(report), lambda: fit_document(report),
                              json_path=json_path, html_path=html_path, protect=protect)


def shared_fit_lines(shared: SharedFit) -> list[str]:
    """A fit over illuminants on a terminal: the shared matrix, then per pair its gains and
    the sim-to-real ΔE00 before and after (through its own .cube) with the cross-validated
    ΔE00 and the cube's check."""
    m = shared.matrix.matrix
    lines = [f"one matrix over {len(shared.reports)} pairs (linear least squares, per-pair "
             "gains, the first pair's fixed at 1): rows "
             + "; ".join(" ".join(f"{v:+z.4f}" for v in row) for row in m)]
    if shared.conditioning.reason:
        lines.append(f"regularised: {shared.conditioning.reason}")
    for k, (rep, g) in enumerate(zip(shared.reports, shared.gains, strict=True)):
        c, b, a = rep.correction, rep.before, rep.after
        lines.append(
            f"pair {k + 1}: {Path(rep.sim).name} -> {Path(rep.real).name}: gains "
            f"{' '.join(f'{v:.4f}' for v in g)}; ΔE00 before mean {b.mean_delta_e:.2f}, after "
            f"mean {a.mean_delta_e:.2f} (max {a.max_delta_e:.2f}, {a.worst_patch}); "
            f"cross-validated mean {_n(c.cv_mean)}; {len(c.used)} of {len(c.patch_names)} "
            f"patches used; .cube {rep.lut.size}^3 max ΔE00 {rep.lut.grid_max:.3f} "
            f"({'met' if rep.lut.passed else 'NOT met'})")
    return lines


def shared_fit_document(shared: SharedFit) -> Document:
    """A fit over illuminants as a :class:`~fidelity.report.document.Document`: the matrix,
    a table of the pairs, and each pair's before/after swatches."""
    worst = max(shared.reports, key=lambda r: r.after.mean_delta_e)
    head = Headline(f"one matrix over {len(shared.reports)} illuminants: sim-to-real ΔE00 after "
                    f"at most **{worst.after.mean_delta_e:.2f}** (mean over the chart, "
                    f"{Path(worst.sim).name})", "info")
    rows = [(str(k + 1), f"`{Path(r.sim).name}`", f"`{Path(r.real).name}`",
             " ".join(f"{v:.4f}" for v in g), f"{r.before.mean_delta_e:.2f}",
             f"{r.after.mean_delta_e:.2f}", f"{r.after.max_delta_e:.2f}",
             _n(r.correction.cv_mean), f"{len(r.correction.used)}", f"{r.lut.size}³")
            for k, (r, g) in enumerate(zip(shared.reports, shared.gains, strict=True))]
    sections = [
        section("Pairs", table(("pair", "SIM", "REAL", "gains", "ΔE00 before", "ΔE00 after",
                                "max after", "cross-validated", "patches used", "cube"), rows)),
        section("Before and after", *[
            svg_figure(chartfigures.swatches(r.after, ("real camera", "corrected simulation")),
                       f"after_{k + 1}.svg", f"pair {k + 1} after: real camera (left half) "
                       "against the corrected simulation (right half)")
            for k, r in enumerate(shared.reports)], gallery=True),
        section("The shared matrix", Code(json.dumps(json_ready(
            {"matrix": shared.matrix.matrix.tolist(),
             "conditioning": shared.conditioning.to_json()}), indent=1))),
        section("Files and timing", Code(json.dumps(json_ready(
            {"files": [r.files for r in shared.reports], "seconds": shared.seconds}),
            indent=1)), folded=True),
    ]
    return Document("Fit over illuminants", head, tuple(sections))


def write_shared_fit_report(shared: SharedFit, *, json_path: str | os.PathLike[str] | None = None,
                            html_path: str | os.PathLike[str] | None = None,
                            protect: Sequence[str | os.PathLike[str]] = ()) -> list[Path]:
    """Write the JSON and/or HTML report of a fit over illuminants atomically."""
    return write_report_files(lambda: shared_fit_json(shared),
                              lambda: shared_fit_document(shared), json_path=json_path,
                              html_path=html_path, protect=protect)


__all__ = ["fit_document", "fit_lines", "shared_fit_document", "shared_fit_lines",
           "write_fit_report", "write_shared_fit_report"]
