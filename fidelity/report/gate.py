"""The overview of a gate or an audit over several subjects (images, or the frames of a
recording): ``index.html`` beside the subjects' own reports when ``fidelity gate --html`` or
``fidelity audit --html`` names a folder.

The page leads with the outcome (how many passed, failed, were undecided or could not be
measured), then a table of every subject (verdict, mean ΔE00 with its standard uncertainty,
the worst patch, the predicted ΔmAP, a link to its report) and, for ``--frames``, a plot per
recording of the chart ΔE over its frames with the expanded uncertainty and the ΔE limit: a
drifting auto exposure or white balance shows as a slope. An audit's page has no verdicts: it
counts the subjects measured, and plots the chart ΔE of each image in the order given.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from fidelity.pipeline.frames import FramesNoise, fixed_pattern_words
from fidelity.pipeline.records import GateResult
from fidelity.report.document import (
    Document,
    Figure,
    Headline,
    Section,
    Table,
    Text,
    Tone,
    section,
    svg_figure,
    table,
)
from fidelity.report.html import write_document
from fidelity.report.svg import COLOURS, Axes, Canvas, Scale, nice_ticks

#: The overview page's name, in the folder of the subjects' HTML reports.
OVERVIEW_NAME = "index.html"

#: What each exit code of a subject is called on the page.
OUTCOMES = {0: "pass", 1: "fail", 2: "not measured", 4: "undecided"}


def _outcome(case: GateResult) -> str:
    return OUTCOMES.get(case.exit_code, f"exit {case.exit_code}")


def _text(s: str) -> str:
    """``s`` as Markdown text that shows as it is (no emphasis, code, link or table cell)."""
    return "".join(f"\\{ch}" if ch in "\\`*_[]()<>#|!~" else ch for ch in s)


def _row(case: GateResult, link: str | None, verdict: bool = True) -> tuple[str, ...]:
    """The table row of a subject; ``verdict``: with the verdict column (a gate's)."""
    # a link's destination in <...> may hold spaces (a report named after "day 2.exr")
    name = f"[{_text(case.subject)}](<{link}>)" if link else _text(case.subject)
    outcome = (_outcome(case),) if verdict else ()
    r = case.report
    if r is None:
        return (name, *outcome, "", "", "", _text(case.error or ""))
    u = r.uncertainty.combined if r.uncertainty is not None else None
    de = f"{r.mean_delta_e:.3f}" + (f" ± {u:.3f}" if u is not None else "")
    dmap = r.prediction.dmap_points if r.prediction is not None else None
    pm = "" if r.interval is None else f" ± {r.interval.standard_uncertainty:.2f}"
    return (name, *outcome, de, f"{r.max_delta_e:.2f} ({r.worst_patch})",
            "" if dmap is None else f"{dmap:.2f}{pm}", "")


def frames_figure(recording: str, frames: Sequence[int], cases: Sequence[GateResult],
                  limit: float | None, what: str = "frame", title: str | None = None
                  ) -> Figure:
    """The chart ΔE of each measured frame of ``recording`` with its expanded uncertainty
    (k = 2) as a bar, coloured by its verdict (black: none); frames not measured as open
    squares on the axis; the ΔE limit as a line. ``what``: what the horizontal axis counts
    (``image``: the images of an audit, numbered in the order given, ``recording`` naming
    them); ``title``: the plot's own (default: the recording's name and what is plotted)."""
    measured = [(k, c) for k, c in zip(frames, cases, strict=True) if c.report is not None]
    values = [c.report.mean_delta_e for _, c in measured if c.report is not None]
    missing = [k for k, case in zip(frames, cases, strict=True) if case.report is None]
    # room above the highest point for the legend of the frames not measured
    top = max([*values, limit or 0.0, 1.0]) * (1.35 if missing else 1.15)
    x0, x1 = min(frames), max(frames)
    if x0 == x1:
        x0, x1 = x0 - 1, x1 + 1
    c = Canvas(680, 320, f"chart ΔE over the {what}s of {recording}")
    c.text(340, 18, title or f"{Path(recording).name}: mean ΔE00 per {what} (bars: ± 2u)", 13,
           anchor="middle", weight="bold")
    ax = Axes(c, 64, 32, 596, 230, Scale(x0 - 0.5, x1 + 0.5), Scale(0.0, top))
    whole = [t for t in nice_ticks(x0, x1) if float(t).is_integer()]  # frames are counted
    ax.frame(what, "mean ΔE00", xticks=whole if len(whole) > 1 else sorted(set(frames)),
             yticks=nice_ticks(0.0, top))
    if limit is not None:
        ax.hline(limit, COLOURS["red"], 1.2, "7 3 2 3", f"limit {limit:.4g}")
    colour = {0: COLOURS["green"], 1: COLOURS["red"], 4: COLOURS["orange"]}
    for k, case in measured:
        r = case.report
        assert r is not None
        u = r.uncertainty.expanded(2.0) if r.uncertainty is not None else 0.0
        px = float(ax.px(float(k)))
        c.line(px, float(ax.py(max(r.mean_delta_e - u, 0.0))), px,
               float(ax.py(r.mean_delta_e + u)), "#808080", 1.2)
        ax.marker(float(k), r.mean_delta_e,
                  colour.get(case.exit_code, "#000") if r.verdict is not None else "#000", 4.5)
    for i, k in enumerate(missing):  # on the axis: no chart measured there
        ax.marker(float(k), 0.0, "#fff", 4.0, "s", "not measured" if i == 0 else None)
    ax.legend("upper right")
    return svg_figure(c.render(), f"{what}s-{Path(recording).name}.svg",
                      f"chart ΔE over the {what}s of {recording}")


def _recordings_figures(cases: Sequence[GateResult], frames: Sequence[int],
                        recordings: Sequence[str], limit: float | None) -> list[Figure]:
    """A :func:`frames_figure` per recording, of its subjects (``frames`` and ``recordings``:
    each subject's frame and recording)."""
    figures = []
    for rec in dict.fromkeys(recordings):
        mine = [(k, c) for k, c, r in zip(frames, cases, recordings, strict=True) if r == rec]
        figures.append(frames_figure(rec, [k for k, _ in mine], [c for _, c in mine], limit))
    return figures


def noise_section(noise: Sequence[FramesNoise]) -> Section | None:
    """The "Noise over the frames" section: per recording, the temporal and fixed-pattern noise
    of each neutral patch (EMVA 1288 4.0), or why its frames were not stacked; None without
    any."""
    if not noise:
        return None
    blocks: list[Text | Table] = []
    for n in noise:
        if not n.stacked:
            blocks.append(Text(f"{n.recording}: not stacked: {n.reason}"))
            continue
        rows = [(p.patch, f"{p.noise.mean:.4f}",
                 f"{p.noise.temporal_noise:.5f} ± "
                 f"{p.noise.u_temporal_variance / (2 * p.noise.temporal_noise):.5f}"
                 if p.noise.temporal_noise > 0 else "0",
                 fixed_pattern_words(p.noise).removeprefix("fixed-pattern σ "),
                 "" if p.snr is None else f"{p.snr:.1f}") for p in n.patches]
        line = (f"photon transfer on the temporal variances: read σ {n.transfer.read_noise:.5f},"
                f" slope K {n.transfer.gain:.3g} ± {n.transfer.u_gain:.2g}"
                if n.transfer is not None else
                f"photon transfer on the temporal variances refused: {n.transfer_refusal}")
        blocks.append(table(("patch", "mean (linear Y)", "temporal σ ± u", "fixed-pattern σ",
                             "temporal SNR"), rows,
                            caption=f"{n.recording}: {len(n.frames)} frames stacked (corners "
                                    f"within {n.corner_shift:.3f} px); {line}. {n.method}.",
                            numeric=(False, True, True, True, True)))
    return section("Noise over the frames", *blocks)


def gate_overview_document(cases: Sequence[GateResult], links: Sequence[str | None],
                           frames: Sequence[int] | None = None,
                           recordings: Sequence[str] | None = None,
                           noise: Sequence[FramesNoise] = ()) -> Document:
    """The overview page of a gate over ``cases`` (``links``: each subject's report, relative
    to the page, or None; ``frames`` and ``recordings``: for ``--frames``, each subject's
    frame and recording; ``noise``: their temporal and fixed-pattern noise,
    :func:`noise_section`)."""
    counts = {name: sum(_outcome(c) == name for c in cases) for name in OUTCOMES.values()}
    n = len(cases)
    message = (f"**{counts['pass']} of {n} passed**, {counts['fail']} failed, "
               f"{counts['undecided']} undecided, {counts['not measured']} not measured")
    criterion = next((c.criterion for c in cases if c.criterion is not None), None)
    if criterion is not None:
        message += f" (gate: {criterion.describe()})"
    outside = sum(c.report is not None and c.report.validity is not None
                  and not c.report.validity.inside for c in cases)
    if outside:
        message += f"; **{outside} of {n} outside the validity domain**"
    tone: Tone = ("fail" if counts["pass"] != n else "outside" if outside else "pass")
    sections: list[Section] = []
    if frames is not None and recordings is not None:
        limit = criterion.limit if criterion is not None and \
            criterion.kind == "max-delta-e" else None
        sections.append(section("Over the frames",
                                *_recordings_figures(cases, frames, recordings, limit)))
    if (noise_part := noise_section(noise)) is not None:
        sections.append(noise_part)
    sections.append(section("Subjects", table(
        ("subject", "verdict", "mean ΔE00 ± u (k=1)", "max ΔE00", "predicted ΔmAP ± u (k=1), points",
         "error"), [_row(c, link) for c, link in zip(cases, links, strict=True)],
        numeric=(False, False, True, True, True, False))))
    return Document("Colour fidelity gate", Headline(message, tone), tuple(sections))


def audit_overview_document(cases: Sequence[GateResult], links: Sequence[str | None],
                            frames: Sequence[int] | None = None,
                            recordings: Sequence[str] | None = None,
                            noise: Sequence[FramesNoise] = ()) -> Document:
    """The overview page of an audit of several images or frames (``cases`` without a
    criterion, in the order given; ``links``, ``frames`` and ``recordings`` as for
    :func:`gate_overview_document`): how many were measured, the chart ΔE of each image over
    their order (or of each frame, per recording), and the table of
    :func:`gate_overview_document` without its verdict column."""
    n = len(cases)
    what = "images" if frames is None else "frames"
    missing = sum(c.report is None for c in cases)
    message = f"**{n - missing} of {n} {what} measured**" + (
        f", {missing} not measured" if missing else "")
    numbers = list(range(1, n + 1))
    if frames is not None and recordings is not None:
        figures = _recordings_figures(cases, frames, recordings, None)
    else:
        figures = [frames_figure("the images audited", numbers, cases, None, what="image",
                                 title="mean ΔE00 of each image, numbered as in the table "
                                       "(bars: ± 2u)")]
    rows = [(str(k), *_row(c, link, verdict=False))
            for k, c, link in zip(numbers, cases, links, strict=True)]
    noise_part = noise_section(noise)
    return Document("Colour fidelity audit", Headline(message, "info" if not missing else "fail"),
                    (section(f"Over the {what}", *figures),
                     *([noise_part] if noise_part is not None else []),
                     section("Subjects", table(
                         ("#", "subject", "mean ΔE00 ± u (k=1)", "max ΔE00",
                          "predicted ΔmAP ± u (k=1), points", "error"), rows,
                         numeric=(True, False, True, True, True, False)))))


def write_gate_overview(path: str | os.PathLike[str], cases: Sequence[GateResult],
                        reports: Sequence[Path | None], frames: Sequence[int] | None = None,
                        recordings: Sequence[str] | None = None, *, audit: bool = False,
                        noise: Sequence[FramesNoise] = ()) -> Path:
    """Write the overview page to ``path`` (atomically), linking each subject's report in
    ``reports`` relative to it; ``audit``: the page of an audit
    (:func:`audit_overview_document`), else a gate's (:func:`gate_overview_document`);
    ``noise``: the frames' temporal and fixed-pattern noise (:func:`noise_section`)."""
    where = Path(path)
    links = [None if p is None else os.path.relpath(p, where.parent) for p in reports]
    doc = (audit_overview_document(cases, links, frames, recordings, noise) if audit
           else gate_overview_document(cases, links, frames, recordings, noise))
    (written,) = write_document(doc, html=where)
    return written


__all__ = ["OUTCOMES", "OVERVIEW_NAME", "audit_overview_document", "frames_figure",
           "gate_overview_document", "noise_section", "write_gate_overview"]
