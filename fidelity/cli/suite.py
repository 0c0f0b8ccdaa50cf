"""``fidelity suite``: check every camera of a suite file under its case's illuminant and
chromatic adaptation transform; and for ``check``, the suite file given as a camera
(:func:`run_suite_command`) and ``--context`` (:func:`read_context`,
:func:`assess_context`). ``check`` imports this module only for those: a plain check loads
neither the suite runner nor the qualification run."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.options import common_options, context_option, judge_options, suite_cat_option
from fidelity.core.fileio import display_path
from fidelity.pipeline.context import Context, assess, context_lines, load_context
from fidelity.pipeline.qualify import qualify
from fidelity.pipeline.suite import run_suite, suite_cases
from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E, Criterion
from fidelity.report.chart import write_chart_report
from fidelity.report.suite import suite_lines, write_suite_summary

if TYPE_CHECKING:
    from collections.abc import Sequence

    from fidelity.pipeline.context import ContextAssessment
    from fidelity.pipeline.records import ChartReport
    from fidelity.prediction.judge import JudgeOptions


def read_context(path: Path) -> Context:
    """The context of use of ``--context FILE``."""
    return load_context(path)


def assess_context(context: Context, reports: Sequence[tuple[str, ChartReport]]
                   ) -> tuple[ContextAssessment, list[str]]:
    """The credibility of the evidence of ``reports`` (camera name, report) for ``context``,
    with the qualification run, and the lines that state it."""
    assessment = assess(context, list(reports), run=qualify)
    return assessment, list(context_lines(assessment))


def run_suite_command(suite: str, cameras: Sequence[str], *, out_dir: Path, report: bool,
                      renderer: str, reference: str, criterion: Criterion,
                      judge: JudgeOptions, context: Context | None,
                      default_cat: str | None = None) -> int:
    """Check the cases, write a record per case (``OUT/CASE/report.json`` and ``.html``) and
    the summary (``OUT/summary.json``, ``OUT/index.html``), print the table; the exit
    code. ``default_cat``: the chromatic adaptation transform of the cases the suite file
    gives none of their own (None: the file's ``default_cat``, else Bradford)."""
    cases = suite_cases(suite, cameras, default_cat)
    result = run_suite(cases, suite=suite, renderer=renderer, reference=reference,
                       criterion=criterion, judge=judge)
    if context is not None:
        a = assess(context, [(c.case.name, c.report) for c in result.cases], run=qualify)
        result = replace(result, assessment=a,
                         cases=tuple(replace(c, report=replace(c.report, context=a))
                                     for c in result.cases))
    links = {}
    if report:
        for c in result.cases:
            folder = out_dir / c.case.name
            write_chart_report(c.report, json_path=folder / "report.json",
                               html_path=folder / "report.html")
            links[c.case.name] = f"{c.case.name}/report.html"
        write_suite_summary(result, out_dir, links=links)
    click.echo(f"fidelity suite: {suite}, {len(result.cases)} cases, {renderer} renderer, "
               f"{reference} reference")
    for line in suite_lines(result):
        click.echo("  " + line)
    if result.assessment is not None:
        for line in context_lines(result.assessment):
            click.echo("  " + line)
    if report:
        click.echo(f"  summary: {display_path(out_dir / 'index.html')} (JSON: "
                   f"{display_path(out_dir / 'summary.json')})")
    return result.exit_code


@click.command()
@click.argument("suite_file", metavar="SUITE")
@click.option("--renderer", default="closed-form", show_default=True,
              help="closed-form (exact, fast) or mitsuba (spectral path tracer).")
@click.option("--reference", type=click.Choice(["scene", "safecolor"]), default="scene",
              show_default=True, help="Reference colours: the scene's spectra or the paper's Lab.")
@click.option("--max-delta-e", type=float, default=None,
              help="Pass when the mean ΔE00 <= X (default: the context's max_delta_e, else "
                   f"{DEFAULT_MAX_DELTA_E:g}).")
@judge_options()
@suite_cat_option("Under an illuminant other than D65 the spread over the transforms enters "
                  "the ΔE's uncertainty as a type-B component.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default="fidelity-report", show_default=True,
              help="Folder for the summary and a subfolder of reports per case.")
@click.option("--report/--no-report", default=True, show_default=True,
              help="Write the reports and the summary.")
@context_option
@common_options
def suite(suite_file: str, renderer: str, reference: str, max_delta_e: float | None,
          judge: JudgeOptions, cat: str | None, out_dir: Path, report: bool,
          context_path: Path | None) -> None:
    """Check every camera of a suite file under its own illuminant and chromatic adaptation.

    SUITE is a camera folder's suite.toml (as fidelity validate reads it): each case's
    illuminant (default_illuminant, [illuminant]) and chromatic adaptation transform
    (default_cat, [cat]). Exit 0 when every case passes, 1 when one fails, 2 on bad input.

    \b
    fidelity suite cameras/suite.toml
    fidelity suite cameras/suite.toml --context context.toml
    """
    context = load_context(context_path) if context_path is not None else None
    limit = max_delta_e if max_delta_e is not None else (
        context.max_delta_e if context is not None and context.max_delta_e is not None
        else DEFAULT_MAX_DELTA_E)
    sys.exit(run_suite_command(suite_file, (), out_dir=out_dir, report=report,
                               renderer=renderer, reference=reference,
                               criterion=Criterion("max-delta-e", limit), judge=judge,
                               context=context, default_cat=cat))


__all__ = ["assess_context", "read_context", "run_suite_command", "suite"]
