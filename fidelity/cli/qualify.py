"""``fidelity qualify``: run the tool's reference checks on this installation."""

from __future__ import annotations

import sys

import click

from fidelity.cli.context import write_json_output
from fidelity.cli.options import common_options, json_option
from fidelity.core.errors import UnknownNameError
from fidelity.core.fileio import check_outputs
from fidelity.pipeline.qualify import QUALIFICATION_CHECKS
from fidelity.pipeline.qualify import qualify as run
from fidelity.report.qualify import qualification_lines, qualification_record


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = list(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))  # each once
    unknown = [n for n in names if n not in QUALIFICATION_CHECKS]
    if unknown or not names:
        raise UnknownNameError(f"--checks {text}: no check named {', '.join(unknown) or 'at all'}"
                               f"; the checks are {', '.join(QUALIFICATION_CHECKS)}")
    return names


@click.command()
@click.option("--checks", "names", default=None, metavar="NAME,...",
              help="Run only these checks (default: all; `fidelity qualify` lists them).")
@json_option("Write the qualification record as JSON")
@common_options
def qualify(names: str | None, json_path: str | None) -> None:
    """Check this installation against independent references (tool qualification).

    Runs the tool's computations against published data and closed forms: CIEDE2000 (Sharma,
    Wu & Dalal 2005), the sRGB matrix (IEC 61966-2-1), illuminant whites (CIE 15:2018), the
    SAFE-COLOR calibration (the paper's parameters), the closed-form render (an ideal camera;
    Mitsuba 3), the chart finder and the image audit (synthetic photos under known
    homographies), COCO box AP (hand-computed cases), the OpenColorIO input conversion (ACES
    S-2016-001), and the installed files (the wheel's RECORD). Each line states the
    reference, the tolerance and what was measured. Exit 0: every check that ran passed; 1: one
    failed. A check that cannot run here (no Mitsuba, an editable install) is named, not failed.
    """
    check_outputs({"--json": json_path})
    result = run(_names(names))
    record = qualification_record(result)
    for line in qualification_lines(result, record["tool"]):
        click.echo(line)
    if json_path:
        where = write_json_output(json_path, record)
        if where != "standard output":
            click.echo(f"wrote {where}")
    sys.exit(0 if result.qualified else 1)
