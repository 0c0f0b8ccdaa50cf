"""The qualification record of an installation (:mod:`fidelity.pipeline.qualify`): terminal lines and
the JSON document ``fidelity qualify --json`` writes.

The JSON holds the tool and environment as a credibility record states them
(:func:`fidelity.report.evidence.tool_record`, :func:`~fidelity.report.evidence.
environment_record`: the same ``code_sha256`` ties a qualification to the records made with
the same code) and every check with its reference, tolerance and measured deviation.
"""

from __future__ import annotations

from typing import Any

from fidelity.pipeline.qualify import NOT_RUN, Qualification, QualificationCheck
from fidelity.pipeline.records import utc_now
from fidelity.report.evidence import environment_record, tool_record

#: Layout version of the qualification record.
QUALIFICATION_LAYOUT = "1.0"


def qualification_record(result: Qualification) -> dict[str, Any]:
    """The JSON document: layout, created, tool, environment, qualified, seconds, checks."""
    return {"kind": "fidelity qualification", "layout": QUALIFICATION_LAYOUT,
            "created": utc_now(), "tool": tool_record(), "environment": environment_record(),
            "qualified": result.qualified, "seconds": result.seconds,
            "checks": [c.to_json() for c in result.checks]}


def _number(value: float) -> str:
    return f"{value:.2g}" if value and abs(value) < 1e-2 else f"{value:.3g}"


def check_lines(check: QualificationCheck) -> list[str]:
    """``STATUS NAME QUANTITY DEVIATION (tolerance T), N cases; detail`` and, indented, the
    reference (one line with the reason for a check not run)."""
    head = f"{check.status:<8} {check.name:<17} "
    if check.status == NOT_RUN:
        return [f"{head}{check.detail}"]
    unit = f" {check.unit}" if check.unit else ""
    value = "not finite" if check.deviation is None else _number(check.deviation)
    line = (f"{head}{check.quantity} {value}{unit} (tolerance {_number(check.tolerance)}{unit}), "
            f"{check.cases} cases")
    return [f"{line}; {check.detail}" if check.detail else line,
            f"{'':27}against {check.reference}"]


def qualification_lines(result: Qualification, tool: dict[str, Any]) -> list[str]:
    """What ``fidelity qualify`` prints: the installation, a line per check, the outcome."""
    commit = tool.get("commit")
    state = "" if commit is None else (f", commit {commit[:10]}"
                                       + (" with uncommitted changes" if tool.get("dirty")
                                          else ""))
    lines = [f"qualification of fidelity {tool.get('version')}{state}, code SHA-256 "
             f"{str(tool.get('code_sha256'))[:16]}..."]
    lines += [line for c in result.checks for line in check_lines(c)]
    ran = len(result.checks) - len(result.not_run)
    passed = ran - len(result.failed)
    skipped = f", {len(result.not_run)} not run" if result.not_run else ""
    outcome = "qualified" if result.qualified else "NOT qualified"
    lines.append(f"{outcome}: {passed} of {ran} checks pass on this installation{skipped} "
                 f"({result.seconds:.1f} s)")
    return lines


__all__ = ["QUALIFICATION_LAYOUT", "check_lines", "qualification_lines", "qualification_record"]
