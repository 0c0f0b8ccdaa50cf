"""JUnit XML for CI: one test case per gated image or camera.

The test-case name is stable (``colour fidelity of SUBJECT``): the criterion and its limit are
properties, so changing a threshold keeps a CI's test history. The test suite carries a
``timestamp`` (UTC) and the ``hostname``. A failed gate is a ``<failure>`` (type ``GateFailure``; an
undecided one of a guarded decision rule, exit code 4, type ``GateUndecided``), an input error
(exit code 2) an ``<error>``; the decision rule, its coverage factor and the expanded
uncertainty it used are properties; the measured values are ``<properties>`` of each test case,
however many there are (the form pytest's ``record_property`` writes, read by Jenkins and
GitLab); the suite's own ``<properties>`` describe the run (``fidelity_version``). The test
cases' ``classname`` names the command (``fidelity.gate``, ``fidelity.compare``).
"""

from __future__ import annotations

import datetime as _dt
import os
import socket
from collections.abc import Sequence
from pathlib import Path
from xml.etree import ElementTree as ET

from fidelity.core.fileio import write_text_atomic
from fidelity.core.version import __version__
from fidelity.pipeline.records import GateResult
from fidelity.report.terminal import summary_lines
from fidelity.report.words import failure_message


def case_name(result: GateResult) -> str:
    """The JUnit test-case name of a gated subject (stable: no threshold in it)."""
    return f"colour fidelity of {result.subject}"


def _properties(case: GateResult) -> list[tuple[str, str]]:
    values: list[tuple[str, object]] = []
    if case.criterion is not None:
        c = case.criterion
        values += [("criterion", c.kind), ("limit", c.limit), ("criterion_description",
                                                               c.describe())]
        if c.kind == "max-dmap":
            values += [("class", c.cls), ("unit", c.unit)]
    r = case.report
    if r is not None:
        p = r.prediction
        values += [("mean_delta_e", r.mean_delta_e), ("max_delta_e", r.max_delta_e),
                   ("worst_patch", r.worst_patch),
                   ("dmap_points", p.dmap_points if p else None),
                   ("dmap_relative", p.dmap_relative if p else None),
                   ("dap_person_points", p.dap_person_points if p else None),
                   ("dap_bicycle_points", p.dap_bicycle_points if p else None),
                   ("prediction_table", p.table.name if p else None),
                   ("reference", r.source.reference),
                   ("input_sha256", r.provenance.input_sha256),
                   ("fidelity_version", r.provenance.version)]
        d = r.directional
        values += [("bound", r.bound),
                   ("directional_dmap_points", d.dmap_points if d else None)]
        values += [(f"measured_dmap_points_{m.model}", m.dmap_points) for m in r.measured]
        j = r.properties
        if j is not None:
            values += [(f"{q.property}_{q.axis}", q.x) for q in j.predictions]
            values += [(f"{q.property}_{j.column}", q.loss) for q in j.predictions]
            values += [(f"{k}_not_judged", why) for k, why in j.not_judged]
            if j.combined is not None:
                values += [(f"combined_{j.column}", j.combined.loss),
                           ("dominant_property", j.combined.dominant)]
        values += [(f"warning_{w.kind}", w.reason) for w in r.warnings]
        if r.uncertainty is not None:
            values.append(("mean_delta_e_standard_uncertainty", r.uncertainty.combined))
        if r.interval is not None:
            values.append(("dmap_points_standard_uncertainty",
                           r.interval.standard_uncertainty))
        if r.validity is not None:
            values.append(("inside_validity_domain", str(r.validity.inside).lower()))
        if r.verdict is not None and r.verdict.value is not None:
            values.append(("value", r.verdict.value))
        if r.verdict is not None:
            v = r.verdict
            values += [("decision_rule", v.decision.rule),
                       ("coverage_factor", v.decision.k),
                       ("strict", str(v.decision.strict).lower()),
                       ("standard_uncertainty", v.uncertainty),
                       ("expanded_uncertainty", v.expanded_uncertainty),
                       ("outcome", v.label.lower())]
    return [(k, "" if v is None else str(v)) for k, v in values]


def junit_xml(cases: Sequence[GateResult], *, timestamp: str | None = None,
              hostname: str | None = None, classname: str = "fidelity.gate") -> str:
    """JUnit XML of ``cases`` (see the module docstring); ``timestamp`` (ISO 8601, UTC) and
    ``hostname`` default to now and this machine; ``classname`` is the test cases' (the
    command that wrote them)."""
    stamp = timestamp or _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%S")
    host = hostname or socket.gethostname()
    total = sum(c.seconds for c in cases)
    suite = ET.Element("testsuite", name="fidelity", tests=str(len(cases)), failures="0",
                       errors="0", skipped="0", time=f"{total:.3f}", timestamp=stamp,
                       hostname=host)
    suite_props = ET.SubElement(suite, "properties")  # JUnit: properties precede test cases
    ET.SubElement(suite_props, "property", name="fidelity_version", value=__version__)
    failures = errors = 0
    for c in cases:
        case = ET.SubElement(suite, "testcase", classname=classname, name=case_name(c),
                             time=f"{c.seconds:.3f}")
        props = ET.SubElement(case, "properties")
        for key, value in _properties(c):
            ET.SubElement(props, "property", name=key, value=value)
        if c.error is not None or c.report is None:
            errors += 1
            message = c.error or "no report"
            ET.SubElement(case, "error", message=message, type="FidelityError").text = message
            continue
        verdict = c.report.verdict
        if verdict is not None and not verdict.passed:
            failures += 1
            message = failure_message(verdict, c.report.diagnosis)
            kind = "GateUndecided" if verdict.undecided else "GateFailure"
            ET.SubElement(case, "failure", message=message, type=kind).text = message
        ET.SubElement(case, "system-out").text = "\n".join(summary_lines(c.report))
    suite.set("failures", str(failures))
    suite.set("errors", str(errors))
    for case in suite.findall("testcase"):  # an empty <properties> is not valid JUnit
        empty = case.find("properties")
        if empty is not None and not len(empty):
            case.remove(empty)
    root = ET.Element("testsuites", name="fidelity", tests=str(len(cases)),
                      failures=str(failures), errors=str(errors), time=f"{total:.3f}")
    root.append(suite)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_junit(path: str | os.PathLike[str], cases: Sequence[GateResult], *,
                classname: str = "fidelity.gate") -> Path:
    """Write JUnit XML atomically (see :func:`junit_xml`; ``classname`` as there)."""
    return write_text_atomic(path, junit_xml(cases, classname=classname))


__all__ = ["case_name", "junit_xml", "write_junit"]
