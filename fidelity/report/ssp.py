"""The credibility record in the SSP Traceability formats: SRMD and STMD (``--evidence
run.srmd``, ``--evidence run.stmd``).

Source: Modelica Association Project SSP, *SSP Layered Standard Traceability*, version
1.0-rc.2 (the public repository ``modelica/ssp-ls-traceability``, commit ``b277def``): the
Simulation Resource Meta Data format (SRMD, section 8; MIME type
``application/x-srmd-meta-data``) and the Simulation Task Meta Data format (STMD, section 7;
``application/x-stmd-simulationtask``), over the common elements of section 5 (STC). Their XML
Schemas (XSD 1.1) ship with the package, :func:`ssp_schema_path`.

- **SRMD**: the run as a resource. No ``data`` attribute (the run is not one file: the SRMD is
  tied to the run's files through its entries, section 8.1). Classifications hold what an
  assessor asks: ``…fidelity.tool`` (name, version, commit, code hash), ``…fidelity.run``
  (command, time, exit code, outcome, decision rule), one ``…fidelity.subject`` per camera or
  image (verdict, mean ΔE00 and its standard uncertainty, the predicted ΔmAP and its interval,
  the validity domain and each of its checks), and ``…fidelity.inputs`` /
  ``…fidelity.results`` with one entry per file: ``xlink:href`` its URI (relative to the SRMD's
  folder), ``linkedType`` its MIME type, and as content an SRMD of that file alone, whose
  ``data`` and ``checksum`` (SHA3-256, FIPS 202, over the file's raw bytes; ``checksumType``)
  are the attributes the SRMD schema defines for a resource's checksum.
- **STMD**: a fragment of a Simulation Task for the validation phase of a Credible Simulation
  Process. STMD's phases are analysis, requirements, design, implementation, execution,
  evaluation and fulfillment; validating a camera model's colour against its reference is the
  evaluation phase's work (section 7: "the simulation results are evaluated and quality
  assurance measures are implemented ... a quality verdict"), so the fragment has one
  ``EvaluationPhase`` with the steps ``EvaluateSimulationResults`` (inputs, the tool as
  procedure, the results) and ``DeriveSimulationQualityVerdict`` (the decision rule as
  procedure, the verdict and the SRMD of the same run as output, the validity domain as
  rationale). Every file is a ``Resource`` whose ``MetaData`` holds its SRMD with the
  SHA3-256 checksum (section 9.2: SRMD "contained in the MetaData elements for the resource").

The documents are built from the JSON credibility record (:mod:`fidelity.report.evidence`),
so every value equals the record's; floats are written as Python's shortest round-trip
decimal. Only the checksums are computed here, at the edge (:func:`traced_files`).
"""

from __future__ import annotations

import os
import re
import shlex
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

from lxml import etree  # noqa: TID253 (this module writes the [ssp] extra's formats; loaded at the call)

from fidelity.core.fileio import JSONObject, file_sha3_256, printable, write_bytes_atomic
from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.report.recordfiles import record_files

#: The SSP Traceability version the documents follow (``version`` of SRMD and STMD).
SSP_TRACEABILITY_VERSION = "1.0.0-rc.2"

#: XML namespaces of SSP Traceability 1.x and XLink.
NAMESPACES: Mapping[str, str] = {
    "srmd": "http://ssp-standard.org/SSPTraceability1/SimulationResourceMetaData",
    "stmd": "http://ssp-standard.org/SSPTraceability1/SimulationTaskMetaData",
    "stc": "http://ssp-standard.org/SSPTraceability1/SSPTraceabilityCommon",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "xlink": "http://www.w3.org/1999/xlink",
}

#: The checksum algorithm SSP Traceability 1.0 prescribes (``checksumType``).
CHECKSUM_TYPE = "SHA3-256"

#: Prefix of the classification types (reverse domain name notation, STC section 5).
CLASSIFICATION = "org.camera-fidelity.fidelity"

#: MIME types by suffix (the SSP Traceability ones from its section 9); others are
#: ``application/octet-stream``, as STC prescribes when none can be named.
MIME_TYPES: Mapping[str, str] = {
    ".json": "application/json", ".html": "text/html", ".xml": "application/xml",
    ".toml": "application/toml", ".png": "image/png", ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg", ".tif": "image/tiff", ".tiff": "image/tiff", ".exr": "image/x-exr",
    ".cube": "text/plain", ".ocio": "application/x-yaml", ".csv": "text/csv",
    ".srmd": "application/x-srmd-meta-data", ".stmd": "application/x-stmd-simulationtask",
}

#: The STC resource ``kind`` of an input's role (others: ``document``).
INPUT_KINDS: Mapping[str, str] = {
    "camera (built-in)": "model", "camera file": "model", "camera data": "parameter",
    "image": "result", "real image": "document", "simulated image": "result",
    "prediction table": "specification", "calibration table": "parameter",
    "context file": "requirement",
}

#: The words of an acceptance criterion of the context of use (``[acceptance]``).
ACCEPTANCE_WORDS: Mapping[str, str] = {
    "max_delta_e": "mean chart ΔE00 at most {limit}",
    "max_dmap": "predicted ΔmAP at most {limit} percentage points",
}


@record
class TracedFile:
    """One file of a run as the SSP Traceability documents name it.

    ``kind`` is ``"input"`` or ``"result"``, ``role`` what it is to the run (``"image"``,
    ``"prediction table"``, ``"report.json"``...), ``path`` the file (as the run named it),
    ``sha3_256`` the SHA3-256 hex digest of its bytes (None when it could not be read) and
    ``mime`` its MIME type.
    """

    kind: str
    role: str
    path: Path
    sha3_256: str | None
    mime: str


def ssp_schema_path(name: str) -> Path:
    """The shipped XML Schema ``name`` (``"SRMD.xsd"``, ``"STMD.xsd"``, ``"STC.xsd"``) of SSP
    Traceability 1.0-rc.2, with what it imports beside it."""
    return resource_dir("data") / "schemas" / "ssp-traceability" / name


def mime_type(path: str | os.PathLike[str]) -> str:
    """The MIME type of ``path`` by its suffix (:data:`MIME_TYPES`)."""
    return MIME_TYPES.get(Path(path).suffix.lower(), "application/octet-stream")


#: Characters XML 1.0 cannot hold, even escaped (C0 controls but tab, newline, return).
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")


def xml_safe(text: str) -> str:
    """``text`` that XML 1.0 can hold: undecodable bytes of file names as ``\\xNN``
    (:func:`fidelity.core.fileio.printable`), control characters as ``\\xNN`` too."""
    return _NOT_XML.sub(lambda m: f"\\x{ord(m.group()):02x}" if ord(m.group()) < 256
                        else f"\\u{ord(m.group()):04x}", printable(text))


def _traced(kind: str, role: str, path: str | os.PathLike[str]) -> TracedFile:
    try:
        digest: str | None = file_sha3_256(path)
    except OSError:
        digest = None
    return TracedFile(kind, xml_safe(role), Path(path), digest, mime_type(path))


def traced_files(record: JSONObject, results: Sequence[str | os.PathLike[str]]
                 ) -> list[TracedFile]:
    """The run's files: every file the record names
    (:func:`fidelity.report.recordfiles.record_files`: the subjects' images, camera files,
    prediction and calibration tables and the settings file read, then a fit's correction
    files, as results), then ``results`` (the files the run wrote), each once, with its
    SHA3-256 read now."""
    seen: set[Path] = set()
    out: list[TracedFile] = []

    def add(kind: str, role: str, path: Any) -> None:
        if not path:
            return
        key = Path(path).resolve()
        if key not in seen:
            seen.add(key)
            out.append(_traced(kind, role, path))

    roles = {"prediction table": "prediction table", "calibration table": "calibration table",
             "settings": "settings file", "context": "context file"}
    for kind, name, item in record_files(record):
        path = item.get("path")
        if kind == "output":  # a fit's correction files
            add("result", Path(path or name).name, path)
        else:
            add("input", roles.get(kind, name), path)
    for path in results:
        add("result", Path(path).name, path)
    return out


def file_uri(path: str | os.PathLike[str], base: str | os.PathLike[str]) -> str:
    """The URI of ``path``: relative to the folder ``base`` when the file lies in or below it
    (SSP resolves a relative URI against the document's own URI), percent-encoded; else its
    absolute ``file:`` URI."""
    target = Path(path).resolve()
    try:
        rel = Path(os.path.relpath(target, Path(base).resolve()))
    except ValueError:  # another drive
        rel = Path("..")
    if rel.parts and rel.parts[0] == "..":
        return "file://" + quote(os.fsencode(target.as_posix()), safe="/")
    return quote(os.fsencode(rel.as_posix()), safe="/")


def _q(prefix: str, name: str) -> str:
    return f"{{{NAMESPACES[prefix]}}}{name}"


def xml_value(value: Any) -> str:
    """A value as classification text: floats as the shortest round-trip decimal, booleans
    ``true``/``false`` (XML Schema)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else xml_safe(str(value))


def _classification(kind: str, entries: Sequence[tuple[str, Any]],
                    description: str | None = None) -> etree._Element:
    """A classification ``{CLASSIFICATION}.{kind}`` of the entries whose value is not None."""
    element = etree.Element(_q("stc", "Classification"), type=f"{CLASSIFICATION}.{kind}")
    if description:
        element.set("description", xml_safe(description))
    for keyword, value in ((k, v) for k, v in entries if v is not None):
        etree.SubElement(element, _q("stc", "ClassificationEntry"),
                         keyword=xml_safe(keyword)).text = xml_value(value)
    return element


def file_srmd(file: TracedFile, base: str | os.PathLike[str]) -> etree._Element:
    """An SRMD of one file: ``name`` its role, ``data`` its URI, ``checksum`` its SHA3-256."""
    element = etree.Element(_q("srmd", "SimulationResourceMetaData"), nsmap=_nsmap("srmd"),
                            version=SSP_TRACEABILITY_VERSION, name=file.role,
                            data=file_uri(file.path, base))
    if file.sha3_256 is not None:
        element.set("checksum", file.sha3_256)
        element.set("checksumType", CHECKSUM_TYPE)
    return element


def _nsmap(root: str) -> dict[str, str]:
    keep = {"srmd": ("srmd", "stc", "xlink"), "stmd": ("stmd", "stc", "ssc", "xlink")}[root]
    return {k: NAMESPACES[k] for k in keep}


def _tool_entries(record: JSONObject) -> list[tuple[str, Any]]:
    tool, env = record["tool"], record.get("environment") or {}
    return [("name", tool.get("name")), ("distribution", tool.get("distribution")),
            ("version", tool.get("version")), ("commit", tool.get("commit")),
            ("dirty", tool.get("dirty")), ("code_sha256", tool.get("code_sha256")),
            ("python", env.get("python")), ("platform", env.get("platform"))]


def _run_entries(record: JSONObject) -> list[tuple[str, Any]]:
    run, rule = record["record"], record.get("decision_rule") or {}
    invocation = record.get("invocation") or {}
    argv = invocation.get("argv")
    return [("command", run.get("command")),
            ("command_line", shlex.join(["fidelity", *argv]) if argv else None),
            ("working_folder", invocation.get("cwd")), ("created", run.get("created")),
            ("exit_code", run.get("exit_code")), ("outcome", run.get("outcome")),
            ("decision_rule", rule.get("rule")), ("coverage_factor", rule.get("k")),
            ("strict", rule.get("strict")), ("decision_rule_description",
                                             rule.get("description"))]


def subject_entries(subject: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The classification entries of one subject of the record: its verdict, measurement,
    prediction with interval, and validity domain (each check as ``validity: NAME``)."""
    m = subject.get("measurement") or {}
    u = m.get("uncertainty") or {}
    p = subject.get("prediction") or {}
    iv = p.get("interval") or {}
    lo, hi = (iv.get("interval") or [None, None])[:2]
    v = subject.get("verdict") or {}
    validity = subject.get("validity") or {}
    entries: list[tuple[str, Any]] = [
        ("subject", subject.get("subject")), ("error", subject.get("error")),
        ("verdict", v.get("label")), ("verdict_passed", v.get("passed")),
        ("verdict_reason", v.get("reason")),
        ("criterion", (v.get("criterion") or {}).get("description")),
        ("verdict_value", v.get("value")), ("limit", v.get("limit")),
        ("expanded_uncertainty", v.get("expanded_uncertainty")),
        ("quantity", m.get("quantity")), ("mean_delta_e", m.get("value")),
        ("mean_delta_e_standard_uncertainty", u.get("standard_uncertainty")),
        ("max_delta_e", m.get("max_delta_e")), ("worst_patch", m.get("worst_patch")),
        ("predicted_dmap_points", p.get("dmap_points")),
        ("prediction_standard_uncertainty", iv.get("standard_uncertainty")),
        ("prediction_coverage_factor", iv.get("k")),
        ("prediction_interval_low", lo), ("prediction_interval_high", hi),
        ("prediction_upper_bound", p.get("upper_bound")),
        ("validity_inside", validity.get("inside"))]
    entries += [(f"validity: {c['name']}", f"{xml_value(c['inside'])}: {c['detail']}")
                for c in validity.get("checks") or []]
    return entries


def _file_entries(kind: str, files: Sequence[TracedFile], base: Path) -> etree._Element:
    element = etree.Element(_q("stc", "Classification"), type=f"{CLASSIFICATION}.{kind}s")
    for f in (f for f in files if f.kind == kind):
        entry = etree.SubElement(element, _q("stc", "ClassificationEntry"), keyword=f.role,
                                 linkedType=f.mime)
        entry.set(_q("xlink", "href"), file_uri(f.path, base))
        entry.append(file_srmd(f, base))
    return element


def _title(record: JSONObject) -> str:
    names = [str(s.get("subject")) for s in record.get("subjects", [])]
    return xml_safe(f"fidelity {record['record']['command']}: " + ", ".join(names))


def _top_level(element: etree._Element, record: JSONObject) -> None:
    element.set("generationTool", f"fidelity {record['tool'].get('version')}")
    element.set("generationDateAndTime", str(record["record"]["created"]))


def srmd_element(record: JSONObject, files: Sequence[TracedFile],
                 base: str | os.PathLike[str]) -> etree._Element:
    """The SRMD of a run (module docstring) from its credibility ``record`` and its ``files``;
    URIs relative to the folder ``base`` (where the SRMD is written)."""
    root = etree.Element(_q("srmd", "SimulationResourceMetaData"), nsmap=_nsmap("srmd"),
                         version=SSP_TRACEABILITY_VERSION, name=_title(record))
    root.set("description", "a fidelity run (camera-model colour fidelity): its tool, "
             "decision rule, verdicts, measurements with their uncertainty, predictions with "
             "their interval, validity domain, and every input and result with its SHA3-256")
    _top_level(root, record)
    root.append(_classification("tool", _tool_entries(record)))
    root.append(_classification("run", _run_entries(record)))
    for subject in record.get("subjects", []):
        root.append(_classification("subject", subject_entries(subject),
                                    str(subject.get("subject"))))
    root.append(_file_entries("input", files, Path(base)))
    root.append(_file_entries("result", files, Path(base)))
    return root


def _resource(parent: etree._Element, kind: str, type_: str, *, source: str | None = None,
              description: str | None = None) -> etree._Element:
    element = etree.SubElement(parent, _q("stc", "Resource"), kind=kind, type=type_)
    if source is not None:
        element.set("source", source)
    if description:
        element.set("description", xml_safe(description))
    return element


def _file_resource(parent: etree._Element, file: TracedFile, kind: str,
                   base: Path) -> etree._Element:
    element = _resource(parent, kind, file.mime, source=file_uri(file.path, base),
                        description=file.role)
    meta = etree.SubElement(element, _q("ssc", "MetaData"), kind="general",
                            type=MIME_TYPES[".srmd"])
    etree.SubElement(meta, _q("ssc", "Content")).append(file_srmd(file, base))
    return element


def _result_kind(file: TracedFile) -> str:
    return "report" if file.mime == "text/html" else "result"


def stmd_element(record: JSONObject, files: Sequence[TracedFile],
                 base: str | os.PathLike[str], guid: str) -> etree._Element:
    """The STMD fragment of a run (module docstring): one ``EvaluationPhase``; ``files`` as
    :func:`srmd_element`, a ``.srmd`` among the results is the verdict's SRMD."""
    where = Path(base)
    root = etree.Element(_q("stmd", "SimulationTaskMetaData"), nsmap=_nsmap("stmd"),
                         version=SSP_TRACEABILITY_VERSION, name=_title(record), GUID=guid)
    _top_level(root, record)
    context = record.get("context_of_use")
    if context:
        root.append(requirements_phase(context, files, where))
    phase = etree.SubElement(root, _q("stmd", "EvaluationPhase"), description=(
        "validation of the camera model's colour rendering against its reference chart "
        "(Credible Simulation Process: the evaluation phase)"))
    evaluate = etree.SubElement(phase, _q("stmd", "EvaluateSimulationResults"), description=(
        "measure the chart's CIEDE2000 colour difference with its uncertainty and predict the "
        "detection loss from the prediction table"))
    given = etree.SubElement(evaluate, _q("stc", "Input"))
    for f in (f for f in files if f.kind == "input"):
        _file_resource(given, f, INPUT_KINDS.get(f.role, "document"), where)
    procedure = etree.SubElement(evaluate, _q("stc", "Procedure"))
    tool = _resource(procedure, "executable", "application/octet-stream",
                     description="the tool that ran")
    tool.append(_classification("tool", _tool_entries(record)))
    out = etree.SubElement(evaluate, _q("stc", "Output"))
    srmd = [f for f in files if f.kind == "result" and f.path.suffix.lower() == ".srmd"]
    for f in (f for f in files if f.kind == "result" and f not in srmd):
        _file_resource(out, f, _result_kind(f), where)

    verdict = etree.SubElement(phase, _q("stmd", "DeriveSimulationQualityVerdict"),
                               description="apply the decision rule to each subject")
    procedure = etree.SubElement(verdict, _q("stc", "Procedure"))
    rule = record.get("decision_rule") or {}
    method = _resource(procedure, "method", "text/plain", description="the decision rule")
    etree.SubElement(method, _q("stc", "Content")).text = xml_value(
        rule.get("description") or "no decision rule: the run states no verdict")
    method.append(_classification("run", _run_entries(record)))
    out = etree.SubElement(verdict, _q("stc", "Output"))
    for f in srmd:
        _file_resource(out, f, "result", where)
    for subject in record.get("subjects", []):
        result = _resource(out, "result", "text/plain",
                           description=f"verdict: {subject.get('subject')}")
        etree.SubElement(result, _q("stc", "Content")).text = xml_value(
            (subject.get("verdict") or {}).get("message") or subject.get("error")
            or "no verdict")
        result.append(_classification("subject", subject_entries(subject),
                                      str(subject.get("subject"))))
    if context:
        accepted = context.get("acceptance") or []
        met = sum(bool(a.get("passed")) for a in accepted)
        result = _resource(out, "result", "text/plain",
                           description="the context of use: acceptance and credibility")
        etree.SubElement(result, _q("stc", "Content")).text = xml_safe(
            f"acceptance: {met} of {len(accepted)} criteria met; credibility level "
            f"{context.get('credibility_level')} of the {context.get('required_level')} the "
            f"model risk requires ({'sufficient' if context.get('sufficient') else 'not sufficient'})")
        result.append(_classification("acceptance", [
            (f"{a.get('subject')}: {a.get('criterion')}",
             f"{xml_value(a.get('value'))} against {xml_value(a.get('limit'))}: "
             f"{'met' if a.get('passed') else 'not met'}") for a in accepted]
            + [("accepted", context.get("accepted")),
               ("credibility_level", context.get("credibility_level")),
               ("required_level", context.get("required_level")),
               ("sufficient", context.get("sufficient"))]))
    rationale = etree.SubElement(verdict, _q("stc", "Rationale"))
    for subject in record.get("subjects", []):
        validity = subject.get("validity") or {}
        text = _resource(rationale, "rationale", "text/plain",
                         description=f"validity domain: {subject.get('subject')}")
        etree.SubElement(text, _q("stc", "Content")).text = xml_safe("\n".join(
            f"{c['name']}: {'inside' if c['inside'] else 'outside'}: {c['detail']}"
            for c in validity.get("checks") or []) or "no validity domain stated")
    return root


def _requirement(parent: etree._Element, text: str, description: str, kind: str,
                 entries: Sequence[tuple[str, Any]]) -> None:
    element = _resource(parent, "requirement", "text/plain", description=description)
    etree.SubElement(element, _q("stc", "Content")).text = xml_safe(text)
    element.append(_classification(kind, entries))


def requirements_phase(context: Mapping[str, Any], files: Sequence[TracedFile],
                       base: Path) -> etree._Element:
    """The STMD's ``RequirementsPhase`` from the record's context of use
    (``context_of_use``, ``--context``): ``DefineModelRequirements`` holds the acceptance
    criteria (``[acceptance]``), ``DefineTestCaseRequirements`` the detectors and operating
    conditions, ``DefineQualityAssuranceRequirements`` the V&V 40 model risk and the
    credibility level it requires, with each credibility factor's level and reason as
    rationale; the context file (with its SHA3-256) is each step's input."""
    c = context.get("context") or {}
    phase = etree.Element(_q("stmd", "RequirementsPhase"), description=xml_safe(
        f"the context of use: {c.get('name') or 'unnamed'}"
        + (f" ({c.get('question')})" if c.get("question") else "")))
    given = [f for f in files if f.role == "context file"]

    def step(tag: str, description: str) -> tuple[etree._Element, etree._Element]:
        element = etree.SubElement(phase, _q("stmd", tag), description=description)
        if given:
            source = etree.SubElement(element, _q("stc", "Input"))
            for f in given:
                _file_resource(source, f, "requirement", base)
        return element, etree.SubElement(element, _q("stc", "Output"))

    _, out = step("DefineModelRequirements", "the acceptance criteria the camera model must "
                  "meet in this context")
    for key, words in ACCEPTANCE_WORDS.items():
        limit = c.get(key)
        if limit is not None:
            _requirement(out, words.format(limit=xml_value(limit)), f"acceptance criterion: "
                         f"{key}", "acceptance", [("criterion", key), ("limit", limit)])
    if not any(c.get(k) is not None for k in ACCEPTANCE_WORDS):
        _requirement(out, "no acceptance criterion stated: the run's decision rule decides",
                     "acceptance criterion: none", "acceptance", [])
    _, out = step("DefineTestCaseRequirements", "the detectors under test and the operating "
                  "conditions")
    detectors = ", ".join(str(d) for d in c.get("detectors") or []) or None
    illuminants = ", ".join(str(i) for i in c.get("illuminants") or [])
    exposures = ", ".join(xml_value(e) for e in c.get("exposures_ev") or [])
    _requirement(out, f"detectors: {detectors or 'any'}; illuminants: {illuminants}; "
                 f"exposure offsets (EV): {exposures or 'none stated'}",
                 "operating conditions", "conditions",
                 [("detectors", detectors), ("illuminants", illuminants),
                  ("exposures_ev", exposures or None)])
    element, out = step("DefineQualityAssuranceRequirements", "the model risk (ASME V&V "
                        "40) and the credibility level it requires")
    _requirement(out, f"model risk level {c.get('risk_level')} (model influence "
                 f"{c.get('model_influence')}, decision consequence "
                 f"{c.get('decision_consequence')}): the evidence must reach credibility "
                 f"level {context.get('required_level')}", "model risk", "risk",
                 [("model_influence", c.get("model_influence")),
                  ("decision_consequence", c.get("decision_consequence")),
                  ("risk_level", c.get("risk_level")),
                  ("required_level", context.get("required_level"))])
    rationale = etree.SubElement(element, _q("stc", "Rationale"))
    for factor in context.get("factors") or []:
        text = _resource(rationale, "rationale", "text/plain",
                         description=f"credibility factor: {factor.get('name')}")
        etree.SubElement(text, _q("stc", "Content")).text = xml_safe(
            f"level {factor.get('level')}: {factor.get('reason')}")
    for outside in context.get("outside_domain") or []:
        text = _resource(rationale, "rationale", "text/plain",
                         description="outside the validity domain")
        etree.SubElement(text, _q("stc", "Content")).text = xml_safe(str(outside))
    return phase


def _xml(element: etree._Element) -> bytes:
    return bytes(etree.tostring(element, xml_declaration=True, encoding="UTF-8",
                                pretty_print=True))


def read_ssp_document(raw: bytes) -> etree._Element:
    """The root element of an SRMD or STMD document's bytes (entities not resolved, nothing
    fetched); raises ValueError naming the XML problem."""
    try:
        parser = etree.XMLParser(resolve_entities=False, no_network=True)
        return etree.fromstring(raw, parser)
    except etree.XMLSyntaxError as exc:
        raise ValueError(str(exc)) from None


def srmd_bytes(record: JSONObject, files: Sequence[TracedFile],
               base: str | os.PathLike[str]) -> bytes:
    """The SRMD document of a run (:func:`srmd_element`) as the bytes :func:`write_srmd`
    writes: what ``fidelity verify`` makes again to compare with an SRMD."""
    return _xml(srmd_element(record, files, base))


def write_srmd(path: str | os.PathLike[str], record: JSONObject,
               results: Sequence[str | os.PathLike[str]] = ()) -> Path:
    """Write the run's SRMD atomically (:func:`srmd_element`); ``results`` are the files the
    run wrote."""
    files = traced_files(record, results)
    return write_bytes_atomic(path, srmd_bytes(record, files, Path(path).parent))


def write_stmd(path: str | os.PathLike[str], record: JSONObject,
               results: Sequence[str | os.PathLike[str]] = ()) -> Path:
    """Write the run's STMD fragment atomically (:func:`stmd_element`, a new random GUID)."""
    files = traced_files(record, results)
    element = stmd_element(record, files, Path(path).parent, str(uuid.uuid4()))
    return write_bytes_atomic(path, _xml(element))


__all__ = ["ACCEPTANCE_WORDS", "CHECKSUM_TYPE", "CLASSIFICATION", "INPUT_KINDS", "MIME_TYPES", "NAMESPACES",
           "SSP_TRACEABILITY_VERSION", "TracedFile", "file_srmd", "file_uri", "mime_type",
           "read_ssp_document", "requirements_phase", "srmd_bytes", "srmd_element", "ssp_schema_path", "stmd_element", "subject_entries",
           "traced_files", "write_srmd", "write_stmd", "xml_safe", "xml_value"]
