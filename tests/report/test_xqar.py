"""The credibility record as an ASAM Quality Checker result (issue 32): ``--evidence run.xqar``
is read back with ASAM's own library (``qc_baselib.Result``, whose pydantic-xml models check
the rule UID pattern and the status and level values of the XQAR format), its values equal
the JSON record of the same run, a failed verdict is an ERROR issue, an undecided one a
WARNING, an answer outside the validity domain an INFORMATION issue, and odd file names
still make a well-formed file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main

qc = pytest.importorskip("qc_baselib", reason="the qc extra (asam-qc-baselib) is not installed")

REPO = Path(__file__).resolve().parents[2]


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def read(path):
    result = qc.Result()
    result.load_from_file(str(path))
    return result


def params(result, checker=None):
    from fidelity.report.xqar import BUNDLE

    bundle = result.get_checker_bundle_result(BUNDLE)
    owner = bundle if checker is None else result.get_checker_result(BUNDLE, checker)
    return {p.name: p.value for p in owner.params}


def test_check_xqar_values_equal_the_json_record(tmp_path):
    from fidelity.report.xqar import BUNDLE, RULES

    xqar, js = tmp_path / "run.xqar", tmp_path / "run.json"
    r = run("check", "--camera", "nikon-5100", "--no-report", "--evidence", xqar,
            "--evidence", js)
    assert r.exit_code == 0, r.output
    record = json.loads(js.read_text())
    result = read(xqar)
    assert result.get_checker_bundle_names() == [BUNDLE]
    bundle = result.get_checker_bundle_result(BUNDLE)
    assert bundle.version == record["tool"]["version"]
    top = params(result)
    assert top["command"] == "check" and str(top["exit_code"]) == "0"
    assert top["commit"] == record["tool"]["commit"]
    (checker,) = result.get_checker_ids(BUNDLE)
    assert result.get_checker_status(checker) == qc.StatusType.COMPLETED
    subject = record["subjects"][0]
    got = params(result, checker)
    u = subject["measurement"]["uncertainty"]["standard_uncertainty"]
    assert float(got["value"]) == subject["measurement"]["value"]  # repr round-trips exactly
    assert float(got["standard_uncertainty"]) == u
    assert float(got["expanded_uncertainty"]) == subject["verdict"]["expanded_uncertainty"]
    assert float(got["limit"]) == 3.0 and got["verdict"] == "PASS"
    lo, hi = map(float, got["predicted_dmap_points_interval"].split())
    assert [lo, hi] == subject["prediction"]["interval"]["interval"]
    camera = subject["inputs"][0]
    assert got[f"sha256 {camera['role']}: {camera['path']}"] == camera["sha256"]
    rules = [r.rule_uid for r in result.get_checker_result(BUNDLE, checker).addressed_rule]
    assert [u.rsplit(":", 1)[1] for u in rules] == [RULES["max-delta-e"], RULES["validity"]]
    # a passing verdict is no issue; the validity domain is one exactly when it says outside
    issues = result.get_issues(BUNDLE, checker)
    assert not any(i.level == qc.IssueSeverity.ERROR for i in issues)
    assert len(issues) == (0 if subject["validity"]["inside"] else 1)


def test_an_audit_without_a_gate_writes_a_record_with_no_rule(tmp_path):
    """An audit has no decision rule: its XQAR says so by leaving the parameter out."""
    image, xqar = tmp_path / "developed.png", tmp_path / "audit.xqar"
    r = run("render", "--out", tmp_path)
    assert r.exit_code == 0, r.output
    r = run("audit", image, "--evidence", xqar)
    assert r.exit_code == 0, r.output
    top = params(read(xqar))
    assert top["command"] == "audit" and "decision_rule" not in top


def test_failed_and_undecided_verdicts_are_issues(tmp_path):
    from fidelity.report.xqar import BUNDLE, RULES

    image = tmp_path / "chart.png"
    assert run("render", "--camera", "nikon-5100", "--out", tmp_path / "r").exit_code == 0
    (tmp_path / "r" / "developed.png").rename(image)
    fail = tmp_path / "fail.xqar"
    r = run("gate", image, "--max-delta-e", "0.5", "--evidence", fail)
    assert r.exit_code == 1, r.output
    result = read(fail)
    (checker,) = result.get_checker_ids(BUNDLE)
    errors = [i for i in result.get_issues(BUNDLE, checker)
              if i.level == qc.IssueSeverity.ERROR]
    assert len(errors) == 1 and "FAIL" in errors[0].description
    assert errors[0].rule_uid.endswith(":" + RULES["max-delta-e"])
    (loc,) = errors[0].locations  # where: the chart's centre in the audited image
    assert loc.description == f"{image}: the chart's centre (pixels)"
    # the rendered chart's corners are (23.5, 23.5) and (223.5, 143.5)
    assert [(f.row, f.column) for f in loc.file_location] == [(84, 124)]
    (info,) = errors[0].domain_specific_info
    assert info.get("name") == "fidelity"
    (meas,) = info
    assert meas.tag == "Measurement" and meas.get("verdict") == "FAIL"
    assert float(meas.get("limit")) == 0.5
    assert result.get_checker_bundle_result(BUNDLE).summary == "gate: fail (exit 1)"
    # undecided under the guarded rule: the limit inside value ± U
    js, undecided = tmp_path / "u.json", tmp_path / "u.xqar"
    r = run("gate", image, "--max-delta-e", "0.5", "--evidence", js)
    value = json.loads(js.read_text())["subjects"][0]["measurement"]["value"]
    r = run("gate", image, "--max-delta-e", f"{value + 1e-3:.6f}", "--decision", "guarded",
            "--evidence", undecided)
    assert r.exit_code not in (0, 1, 2, 3), r.output  # undecided has its own exit code
    result = read(undecided)
    (checker,) = result.get_checker_ids(BUNDLE)
    levels = [i.level for i in result.get_issues(BUNDLE, checker)
              if i.rule_uid.endswith(RULES["max-delta-e"])]
    assert levels == [qc.IssueSeverity.WARNING]


def test_subject_errors_and_the_validity_domain_by_hand(tmp_path):
    """Records made by hand: an unmeasured subject is a checker with status error; a subject
    inside its validity domain with a passing verdict has no issue; one outside names the
    checks outside; control characters in a file name still give a well-formed file."""
    from fidelity.report.xqar import BUNDLE, write_xqar

    verdict = {"passed": True, "label": "PASS", "message": "PASS: mean ΔE00 1 <= 3",
               "criterion": {"kind": "max-delta-e"}, "limit": 3.0,
               "expanded_uncertainty": 0.2, "decision": {"k": 2.0}}

    def subject(name, *, error=None, inside=True):
        return {"subject": name, "command": "audit", "error": error,
                "inputs": [{"role": "image", "path": f"/data/{name}\x01.png", "sha256": "ab",
                            "provenance": {"corners": [[0, 0], [10, 0], [10, 6], [0, 6]],
                                           "recording": {"frame": 7, "topic": "/cam",
                                                         "time_ns": 1_500_000_000}}}],
                "measurement": {"quantity": "mean ΔE00", "value": 1.0,
                                "uncertainty": {"standard_uncertainty": 0.1}},
                "prediction": None, "verdict": None if error else verdict,
                "validity": {"inside": inside, "checks": [
                    {"name": "table ΔE range", "inside": inside, "detail": "ΔE 1 in [0, 24]"}]}}

    record = {"record": {"created": "2026-11-26T00:00:00Z", "command": "audit",
                         "exit_code": 2, "outcome": "error", "schema_version": "1.0"},
              "tool": {"version": "0.1.0", "commit": None},
              "decision_rule": {"description": "simple"},
              "subjects": [subject("good"), subject("bad", error="no chart found"),
                           subject("far", inside=False)]}
    path = write_xqar(tmp_path / "hand.xqar", record)
    result = read(path)
    good, bad, far = result.get_checker_ids(BUNDLE)
    assert (good, bad, far) == ("subject_0_good", "subject_1_bad", "subject_2_far")
    assert result.get_issues(BUNDLE, good) == []
    assert result.get_checker_status(bad) == qc.StatusType.ERROR
    assert result.get_checker_result(BUNDLE, bad).summary == "no chart found"
    (issue,) = result.get_issues(BUNDLE, far)
    assert issue.level == qc.IssueSeverity.INFORMATION
    assert "table ΔE range: ΔE 1 in [0, 24]" in issue.description
    message, file = issue.locations  # a recording's frame: its message and the chart in it
    assert "\\x01" in message.description  # the control character, escaped
    m = message.message_location[0]
    assert (m.index, m.channel, m.time) == (7, "/cam", 1.5)
    assert [(f.row, f.column) for f in file.file_location] == [(3, 5)]


def test_missing_library_is_one_line_before_the_run(tmp_path):
    code = ("import sys\nsys.modules['qc_baselib'] = None\nfrom fidelity.cli import main\n"
            "main(sys.argv[1:])\n")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", code, "check", "--no-report", "--evidence",
                        str(tmp_path / "x.xqar")], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "camera-fidelity[qc]" in lines[0], r.stderr
    assert not (tmp_path / "x.xqar").exists()
