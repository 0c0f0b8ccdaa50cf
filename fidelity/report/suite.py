"""The summary of a suite of camera checks (:class:`fidelity.pipeline.suite.SuiteResult`): a
terminal table, the summary JSON and an HTML index linking each case's report."""

from __future__ import annotations

import os
from pathlib import Path

from fidelity.core.fileio import write_json_atomic
from fidelity.pipeline.suite import SuiteResult
from fidelity.report.context import context_section
from fidelity.report.document import Document, Headline, Tone, section, table
from fidelity.report.html import write_document


def _verdict(passed: bool | None, code: int) -> str:
    """PASS, FAIL, UNDECIDED or a dash (no verdict)."""
    if passed is None:
        return "UNDECIDED" if code == 4 else "-"
    return "PASS" if passed else "FAIL"


def suite_rows(result: SuiteResult) -> list[list[str]]:
    """One row per case: case, illuminant, chromatic adaptation transform, mean ΔE00 with its
    standard uncertainty (k = 1, the transforms' spread a type-B part under an illuminant
    other than D65), max ΔE00, predicted ΔmAP, verdict."""
    rows = []
    for c in result.cases:
        j = c.to_json()
        dm, u = j["dmap_points"], j["delta_e_uncertainty"]
        rows.append([c.case.name, c.case.illuminant, c.case.cat,
                     f"{j['mean_delta_e']:.2f}" + ("" if u is None else f" ± {u:.2f}"),
                     f"{j['max_delta_e']:.2f}", "-" if dm is None else f"{dm:.2f}",
                     _verdict(j["passed"], c.exit_code)])
    return rows


HEADER = ("case", "illuminant", "CAT", "mean ΔE00 (± u, k=1)", "max ΔE00", "ΔmAP (points)",
          "verdict")
#: Which columns of :data:`HEADER` are numbers (right-aligned).
NUMERIC = (False, False, False, True, True, True, False)


def suite_lines(result: SuiteResult) -> list[str]:
    """The terminal table of the cases and the count of those that failed."""
    rows = [list(HEADER), *suite_rows(result)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    lines = ["  ".join(cell.rjust(w) if NUMERIC[i] else cell.ljust(w)
                       for i, (cell, w) in enumerate(zip(r, widths, strict=True))).rstrip()
             for r in rows]
    n, failed = len(result.cases), len(result.failed)
    lines.append(f"{n - failed} of {n} cases passed" + (
        f"; failed: {', '.join(c.case.name for c in result.failed)}" if failed else ""))
    return lines


def suite_document(result: SuiteResult, links: dict[str, str] | None = None) -> Document:
    """The HTML index of a suite: the table of cases (each linked to its report through
    ``links``: case name -> relative path) and the context assessment."""
    links = links or {}
    rows = [[f"[{r[0]}]({links[r[0]]})" if r[0] in links else r[0], *r[1:]]
            for r in suite_rows(result)]
    n, failed = len(result.cases), len(result.failed)
    tone: Tone = "fail" if result.exit_code else "pass"
    headline = Headline(f"{n - failed} of {n} cases passed"
                        + (f"; failed: {', '.join(c.case.name for c in result.failed)}"
                           if failed else ""), tone)
    sections = [section("Cases", table(HEADER, rows, numeric=NUMERIC))]
    if result.assessment is not None:
        sections.append(context_section(result.assessment))
    return Document(f"fidelity suite: {result.suite}", headline, tuple(sections))


def write_suite_summary(result: SuiteResult, out_dir: str | os.PathLike[str], *,
                        html: bool = True, links: dict[str, str] | None = None) -> list[Path]:
    """Write ``OUT/summary.json`` and (``html``) ``OUT/index.html``, atomically; the paths."""
    d = Path(out_dir)
    written = [write_json_atomic(d / "summary.json", result.to_json())]
    if html:
        written += write_document(suite_document(result, links), html=d / "index.html")
    return written


__all__ = ["HEADER", "NUMERIC", "suite_document", "suite_lines",
           "suite_rows", "write_suite_summary"]
