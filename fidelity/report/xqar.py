"""The credibility record as an ASAM Quality Checker result (``--evidence run.xqar``).

Source: ASAM e.V., *ASAM Quality Checker Framework* (the public repository
``asam-ev/qc-framework``): the result report format XQAR (``doc/schema/xqar_result_format.xsd``)
and its rule UID schema (``doc/manual/rule_uid_schema.md``:
``emanating_entity:standard:definition_setting:rule_full_name``), written with ASAM's own
Python library for it, ``asam-qc-baselib`` (``qc_baselib.Result``; the ``qc`` extra). A QC
Framework run (its result pooling, report viewers, CI gates on ``Result`` files) then shows
the camera's colour check beside its OpenDRIVE and OpenSCENARIO checks.

The mapping, built from the JSON credibility record (:mod:`fidelity.report.evidence`), so
every value equals the record's:

- one **checker bundle** ``fidelity``: the tool's version, the record's date as
  ``build_date``, the run's outcome as summary; parameters: the command, its exit code, the
  commit and code hash, the decision rule;
- one **checker** per subject (a camera, an image, a sim-real pair): status ``completed``
  (``error`` where the subject could not be measured, with the error as summary); the
  verdict as summary; parameters: the measured value, its standard and expanded uncertainty
  and coverage factor, the limit, the predicted ΔmAP and its interval, every input's SHA-256;
  the rules it checks (:data:`RULES`);
- **issues**: a failed verdict is an ``ERROR`` of the verdict's rule, an undecided one
  (``--decision guarded``) a ``WARNING``, an answer outside the evidence's validity domain an
  ``INFORMATION`` of :data:`RULES` ``validity`` naming the checks outside; each issue's
  locations are, per measured file, the chart's centre in the picture (row, column) and, for
  a recording, the message it was read from (index, topic, time); its domain-specific information
  ``fidelity`` holds the measurement (value, uncertainty, limit) as XML attributes.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fidelity.core.fileio import JSONObject, write_bytes_atomic
from fidelity.report.ssp import xml_safe, xml_value

#: Rule UIDs (QC Framework rule UID schema): emanating entity, standard, definition setting
#: (the evidence record's schema version), rule name.
EMANATING_ENTITY = "camera_fidelity.org"
STANDARD = "camera"
RULES: Mapping[str, str] = {
    "max-delta-e": "colour.chart_mean_delta_e00",
    "max-dmap": "detection.predicted_map_loss",
    "validity": "evidence.validity_domain",
}

#: The checker bundle's name.
BUNDLE = "fidelity"


def rule_uid(name: str, version: str) -> str:
    """The rule UID of one of :data:`RULES` (``name``) at the record's schema ``version``."""
    setting = version if re.fullmatch(r"[0-9]+(\.[0-9]+)+", version) else f"{version}.0"
    return f"{EMANATING_ENTITY}:{STANDARD}:{setting}:{RULES[name]}"


def _checker_id(index: int, subject: str) -> str:
    """A unique checker id: the subject's position and name in word characters."""
    word = re.sub(r"\W+", "_", subject, flags=re.ASCII).strip("_")[:48]
    return f"subject_{index}" + (f"_{word}" if word else "")


def _locate(result: Any, cid: str, issue: int, subject: Mapping[str, Any]) -> None:
    """The issue's locations: per measured file of the subject (an image, a render, a sim or
    real picture), the recording message it was read from (index, topic, time in seconds) or
    the chart's centre in the picture (row, column in pixels, from its corners)."""
    for item in subject.get("inputs") or ():
        prov = item.get("provenance") or {}
        if not item.get("path") or "corners" not in prov and "recording" not in prov:
            continue
        where = xml_safe(str(item["path"]))
        rec = prov.get("recording")
        if rec:
            time = rec.get("time_ns")
            result.add_message_location(
                BUNDLE, cid, issue, index=int(rec["frame"]), channel=xml_safe(str(rec["topic"])),
                time=None if time is None else time / 1e9,
                description=f"{where}: the frame measured")
        corners = prov.get("corners")
        if corners:
            xs, ys = [float(c[0]) for c in corners], [float(c[1]) for c in corners]
            result.add_file_location(BUNDLE, cid, issue, row=round(sum(ys) / len(ys)),
                                     column=round(sum(xs) / len(xs)),
                                     description=f"{where}: the chart's centre (pixels)")


def xqar_result(record: JSONObject) -> Any:
    """The ``qc_baselib.Result`` of a credibility ``record`` (see the module's mapping)."""
    from qc_baselib import IssueSeverity, Result, StatusType

    rec, tool = record["record"], record["tool"]
    rule = record.get("decision_rule") or {}  # an audit without a gate has no rule
    version = str(rec.get("schema_version") or "1.0")
    result = Result()
    result.register_checker_bundle(
        name=BUNDLE, version=str(tool.get("version")), build_date=str(rec["created"])[:10],
        description="fidelity: a camera model's colour fidelity (CIEDE2000 on the ColorChecker, "
                    "with its uncertainty) and the detection loss it predicts",
        summary=xml_safe(f"{rec['command']}: {rec['outcome']} (exit {rec['exit_code']})"))
    for name, value in (("command", rec["command"]), ("exit_code", rec["exit_code"]),
                        ("outcome", rec["outcome"]), ("created", rec["created"]),
                        ("commit", tool.get("commit")), ("code_sha256", tool.get("code_sha256")),
                        ("decision_rule", rule.get("description"))):
        if value is not None:
            result.add_param_to_checker_bundle(BUNDLE, name, xml_value(value))
    for i, subject in enumerate(record["subjects"]):
        _add_subject(result, i, subject, version, IssueSeverity, StatusType)
    return result


def _add_subject(result: Any, index: int, subject: Mapping[str, Any], version: str,
                 severity: Any, status: Any) -> None:
    cid = _checker_id(index, str(subject["subject"]))
    verdict = subject.get("verdict") or {}
    meas = subject.get("measurement") or {}
    u = meas.get("uncertainty") or {}
    result.register_checker(
        BUNDLE, cid, description=xml_safe(f"{subject['command']} of {subject['subject']}"),
        summary=xml_safe(subject.get("error") or verdict.get("message") or
                          f"{meas.get('quantity', 'mean ΔE00')} {meas.get('value')}"))
    kind = str((verdict.get("criterion") or {}).get("kind"))
    uids = {name: rule_uid(name, version) for name in RULES}
    for name in (kind, "validity"):
        if name in RULES:
            result.register_rule_by_uid(BUNDLE, cid, uids[name])
    pred = subject.get("prediction") or {}
    interval = (pred.get("interval") or {}).get("interval")
    params: dict[str, Any] = {
        "quantity": meas.get("quantity"), "value": meas.get("value"),
        "standard_uncertainty": u.get("standard_uncertainty"),
        "expanded_uncertainty": verdict.get("expanded_uncertainty"),
        "coverage_factor": (verdict.get("decision") or {}).get("k"),
        "limit": verdict.get("limit"), "verdict": verdict.get("label"),
        "predicted_dmap_points": pred.get("dmap_points"),
        "predicted_dmap_points_interval": (f"{interval[0]!r} {interval[1]!r}"
                                           if interval else None),
        "validity_inside": (subject.get("validity") or {}).get("inside"),
    }
    for item in subject.get("inputs") or ():
        if item.get("sha256"):
            params[f"sha256 {item.get('role')}: {item.get('path')}"] = item["sha256"]
    for name, value in params.items():
        if value is not None:
            result.add_param_to_checker(BUNDLE, cid, xml_safe(name), xml_value(value))
    if subject.get("error"):
        result.set_checker_status(BUNDLE, cid, status.ERROR)
        return
    result.set_checker_status(BUNDLE, cid, status.COMPLETED)
    issues: list[tuple[str, Any, str]] = []
    if verdict and kind in RULES and verdict.get("passed") is False:
        undecided = verdict.get("reason") == "undecided"
        issues.append((verdict.get("message") or verdict.get("label") or "failed",
                       severity.WARNING if undecided else severity.ERROR, uids[kind]))
    validity = subject.get("validity") or {}
    if validity.get("inside") is False:
        outside = [f"{c['name']}: {c['detail']}" for c in validity.get("checks") or ()
                   if not c.get("inside")]
        issues.append(("outside the evidence's validity domain: " + "; ".join(outside),
                       severity.INFORMATION, uids["validity"]))
    for description, level, uid in issues:
        issue = result.register_issue(BUNDLE, cid, xml_safe(description), level, uid)
        _locate(result, cid, issue, subject)
        result.add_domain_specific_info(BUNDLE, cid, issue, "fidelity",
                                        [_measurement_element(meas, u, verdict)])


def _measurement_element(meas: Mapping[str, Any], u: Mapping[str, Any],
                         verdict: Mapping[str, Any]) -> Any:
    from lxml import etree

    attrs = {"quantity": meas.get("quantity"), "value": meas.get("value"),
             "standardUncertainty": u.get("standard_uncertainty"),
             "expandedUncertainty": verdict.get("expanded_uncertainty"),
             "limit": verdict.get("limit"), "verdict": verdict.get("label")}
    return etree.Element("Measurement", {k: xml_value(v) for k, v in attrs.items()
                                         if v is not None})


def write_xqar(path: str | os.PathLike[str], record: JSONObject,
               results: Sequence[str | os.PathLike[str]] = ()) -> Path:
    """Write the XQAR result of ``record`` to ``path`` atomically (``results`` are not listed:
    XQAR has no place for a run's output files; the SSP formats list them)."""
    out = Path(path)
    with tempfile.TemporaryDirectory(prefix=".fidelity-xqar-") as tmp:
        scratch = Path(tmp) / "result.xqar"  # qc_baselib writes to a path of its own choosing
        xqar_result(record).write_to_file(str(scratch))
        return write_bytes_atomic(out, scratch.read_bytes())


__all__ = ["BUNDLE", "EMANATING_ENTITY", "RULES", "STANDARD", "rule_uid", "write_xqar",
           "xqar_result"]
