"""The credibility record in the SSP Traceability formats (issue 32): ``--evidence run.srmd``
and ``--evidence run.stmd`` validate against the shipped XSD 1.1 schemas of SSP Traceability
1.0-rc.2 (xmlschema, offline), every file's checksum is its SHA3-256 (hashlib, computed here),
the values equal the JSON record's of the same run (read back with pyssp-standard, the SSP
library), and a bad suffix or an input named as --evidence is one line, exit 2."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote, unquote_to_bytes, urlparse

import pytest
from click.testing import CliRunner

from fidelity.cli import main

xmlschema = pytest.importorskip("xmlschema")
etree = pytest.importorskip("lxml.etree")

REPO = Path(__file__).resolve().parents[2]
NS = {"srmd": "http://ssp-standard.org/SSPTraceability1/SimulationResourceMetaData",
      "stmd": "http://ssp-standard.org/SSPTraceability1/SimulationTaskMetaData",
      "stc": "http://ssp-standard.org/SSPTraceability1/SSPTraceabilityCommon",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "xlink": "http://www.w3.org/1999/xlink"}


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def schemas():
    from fidelity.report.ssp import ssp_schema_path

    return {name: xmlschema.XMLSchema11(str(ssp_schema_path(f"{name}.xsd")), allow="local")
            for name in ("SRMD", "STMD")}


@pytest.fixture(scope="module")
def check_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ssp-check")
    paths = {s: folder / f"run.{s}" for s in ("json", "srmd", "stmd")}
    r = run("check", "--camera", "nikon-5100", "--out", folder / "out",
            "--evidence", paths["stmd"], "--evidence", paths["srmd"], "--evidence", paths["json"])
    assert r.exit_code == 0, r.output
    return folder, paths


@pytest.fixture(scope="module")
def audit_run(tmp_path_factory):
    """An audit of a rendered chart whose file name needs percent-encoding in a URI."""
    folder = tmp_path_factory.mktemp("ssp-audit")
    assert run("render", "--camera", "nikon-5100", "--out", folder / "r").exit_code == 0
    image = folder / "images" / "chart ü #1.png"
    image.parent.mkdir()
    shutil.copy(folder / "r" / "developed.png", image)
    srmd, js = folder / "audit.srmd", folder / "audit.json"
    r = run("audit", image, "--json", folder / "a.json", "--evidence", srmd, "--evidence", js)
    assert r.exit_code == 0, r.output
    return folder, image, srmd, js


def file_srmds(path):
    """Each file's own SRMD (data, checksum) inside a document, with the document's folder."""
    return etree.parse(str(path)).getroot().iterfind(".//srmd:SimulationResourceMetaData", NS)


def resolve(uri, base):
    parsed = urlparse(uri)
    if parsed.scheme == "file":
        return Path(os.fsdecode(unquote_to_bytes(parsed.path)))
    return base / os.fsdecode(unquote_to_bytes(uri))


# ------------------------------------------------------------------ the schemas

def test_check_srmd_and_stmd_validate_against_the_shipped_schemas(check_run, schemas):
    _, paths = check_run
    schemas["SRMD"].validate(str(paths["srmd"]))
    schemas["STMD"].validate(str(paths["stmd"]))
    # the files' SRMDs inside the STMD's MetaData (lax content there) are SRMDs themselves
    for element in file_srmds(paths["stmd"]):
        schemas["SRMD"].validate(etree.tostring(element).decode())
    # and the validation can fail: an SRMD without its mandatory version
    broken = etree.parse(str(paths["srmd"])).getroot()
    del broken.attrib["version"]
    assert not schemas["SRMD"].is_valid(etree.tostring(broken).decode())


def test_stmd_is_an_evaluation_phase_referencing_the_srmd_and_the_results(check_run):
    folder, paths = check_run
    root = etree.parse(str(paths["stmd"])).getroot()
    assert root.tag == f"{{{NS['stmd']}}}SimulationTaskMetaData" and root.get("GUID")
    phases = [etree.QName(c).localname for c in root if etree.QName(c).localname.endswith("Phase")]
    assert phases == ["EvaluationPhase"]
    outputs = root.find("stmd:EvaluationPhase/stmd:DeriveSimulationQualityVerdict/stc:Output", NS)
    sources = [r.get("source") for r in outputs.iterfind("stc:Resource", NS)]
    assert "run.srmd" in sources
    written = root.find("stmd:EvaluationPhase/stmd:EvaluateSimulationResults/stc:Output", NS)
    assert {r.get("source") for r in written.iterfind("stc:Resource", NS)} == {
        "out/report.json", "out/report.html", "run.json"}


# ------------------------------------------------------------------ the checksums

def test_every_checksum_is_the_sha3_256_of_its_file(check_run, audit_run):
    folder, paths = check_run
    _, image, audit_srmd, _ = audit_run
    seen = set()
    for doc in (paths["srmd"], paths["stmd"], audit_srmd):
        for element in file_srmds(doc):
            target = resolve(element.get("data"), doc.parent)
            assert element.get("checksumType") == "SHA3-256"
            assert element.get("checksum") == hashlib.sha3_256(target.read_bytes()).hexdigest()
            seen.add(target.resolve())
    names = {p.name for p in seen}
    # inputs: the camera file, the prediction and calibration tables, the image; results: the
    # reports, the JSON record (in the SRMD and the STMD) and the SRMD (in the STMD)
    assert {"nikon-5100.toml", "coco1000-measured.json", "calibration-safecolor.json",
            "report.json", "report.html", "run.json", "run.srmd", image.name, "a.json",
            "audit.json"} <= names
    assert image.resolve() in seen


# ------------------------------------------------------------------ the values

def test_srmd_values_equal_the_json_records(check_run, audit_run):
    """Read back with pyssp-standard (the SSP library), compared with the JSON record."""
    srmd_module = pytest.importorskip("pyssp_standard.srmd")
    _, paths = check_run
    _, _, audit_srmd, audit_json = audit_run
    for srmd_path, json_path in ((paths["srmd"], paths["json"]), (audit_srmd, audit_json)):
        record = json.loads(json_path.read_text())
        doc = srmd_module.SRMD(srmd_path, "r")
        by_type = {c.classification_type: {e.keyword: e.text for e in c.classification_entries}
                   for c in doc.classifications}
        subject = record["subjects"][0]
        got = by_type["org.camera-fidelity.fidelity.subject"]
        assert float(got["mean_delta_e"]) == subject["measurement"]["value"]
        assert (float(got["mean_delta_e_standard_uncertainty"])
                == subject["measurement"]["uncertainty"]["standard_uncertainty"])
        assert float(got["predicted_dmap_points"]) == subject["prediction"]["dmap_points"]
        interval = subject["prediction"]["interval"]
        assert float(got["prediction_standard_uncertainty"]) == interval["standard_uncertainty"]
        assert [float(got["prediction_interval_low"]),
                float(got["prediction_interval_high"])] == interval["interval"]
        assert got["validity_inside"] == str(subject["validity"]["inside"]).lower()
        for c in subject["validity"]["checks"]:
            assert got[f"validity: {c['name']}"].endswith(c["detail"])
        verdict = subject["verdict"]
        if verdict is None:  # an audit states no verdict
            assert "verdict" not in got
        else:
            assert got["verdict"] == verdict["label"]
            assert float(got["verdict_value"]) == verdict["value"]
            assert float(got["limit"]) == verdict["limit"]
        tool = by_type["org.camera-fidelity.fidelity.tool"]
        assert tool["version"] == record["tool"]["version"]
        assert tool["code_sha256"] == record["tool"]["code_sha256"]
        assert tool.get("commit") == record["tool"]["commit"]
        run_ = by_type["org.camera-fidelity.fidelity.run"]
        assert int(run_["exit_code"]) == record["record"]["exit_code"]
        assert run_["command"] == record["record"]["command"]


# ------------------------------------------------------------------ errors and inputs

@pytest.mark.parametrize("name", ["run.xml", "run", "run.srmd.bak"])
def test_an_unknown_suffix_is_one_line_exit_2(tmp_path, name):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "fidelity", "check", "--no-report",
                        "--evidence", str(tmp_path / name)], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fidelity: error: {tmp_path / name}: ")
    assert not (tmp_path / name).exists()


def test_an_input_given_as_evidence_is_refused_and_left_alone(tmp_path):
    import fidelity

    table = tmp_path / "table.json"
    shutil.copy(Path(fidelity.__file__).parent / "data" / "prediction" / "coco1000-measured.json",
                table)
    before = table.read_bytes()
    r = run("check", "--no-report", "--table", table, "--evidence", table,
            "--evidence", tmp_path / "run.srmd")
    assert r.exit_code == 2
    assert table.read_bytes() == before and not (tmp_path / "run.srmd").exists()
    srmd = tmp_path / "table.srmd"  # an input with the SRMD's suffix: the same refusal
    srmd.write_bytes(b"<not an srmd/>")
    r = run("check", "--no-report", "--table", srmd, "--evidence", srmd)
    assert r.exit_code == 2 and srmd.read_bytes() == b"<not an srmd/>"


def test_a_settings_file_names_several_evidence_files(tmp_path):
    settings = tmp_path / "fidelity.toml"
    settings.write_text('evidence = ["e.json", "e.srmd"]\n')
    r = run("--config", settings, "check", "--no-report")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "e.json").is_file() and (tmp_path / "e.srmd").is_file()
    # the SRMD traces the settings file read (its SHA3-256, computed here) and the command line
    text = (tmp_path / "e.srmd").read_text(encoding="utf-8")
    assert hashlib.sha3_256(settings.read_bytes()).hexdigest().upper() in text.upper()
    assert f'keyword="command_line">fidelity --config {settings} check --no-report<' in text


def test_default_paths_import_no_xml_library_and_a_missing_one_is_one_line(tmp_path,
                                                                           audit_run):
    """check and audit without --evidence, or with the JSON record, import neither lxml nor
    xmlschema; with lxml missing, --evidence x.srmd is one line naming the extra, before the
    run."""
    code = ("import sys\nfrom fidelity.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    code = e.code\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            "('lxml', 'xmlschema', 'pyssp_standard'))\n"
            "print('IMPORTED', bad)\nsys.exit(code)\n")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    image = str(audit_run[1])
    for args in (["check", "--no-report"], ["audit", image],
                 ["check", "--no-report", "--evidence", str(tmp_path / "e.json")],
                 ["audit", image, "--evidence", str(tmp_path / "a.json")]):
        r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                           env=env, timeout=300)
        assert r.returncode == 0, r.stderr
        assert "IMPORTED []" in r.stdout, r.stdout[-2000:]
    blocked = "import sys\nsys.modules['lxml'] = None\n" + code
    r = subprocess.run([sys.executable, "-c", blocked, "check", "--no-report", "--evidence",
                        str(tmp_path / "x.srmd")], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "camera-fidelity[ssp]" in lines[0], r.stderr
    assert not (tmp_path / "x.srmd").exists()


def test_file_uri_is_relative_below_the_document_and_absolute_elsewhere(tmp_path):
    from fidelity.report.ssp import file_uri

    inside = tmp_path / "a b" / "c#ü.json"
    assert file_uri(inside, tmp_path) == "a%20b/c%23%C3%BC.json"
    assert unquote(file_uri(inside, tmp_path)) == "a b/c#ü.json"
    outside = file_uri(tmp_path / "x.json", tmp_path / "sub")
    assert outside.startswith("file:///") and resolve(outside, tmp_path) == tmp_path / "x.json"


def test_gate_lists_its_junit_file_and_a_fail_is_recorded(tmp_path, schemas):
    """A failing gate (exit 1) still writes its evidence; the JUnit XML is among the results."""
    srmd, stmd, junit = tmp_path / "g.srmd", tmp_path / "g.stmd", tmp_path / "g.xml"
    r = run("gate", "--camera", "nikon-5100", "--max-delta-e", "0.5", "--junit", junit,
            "--evidence", srmd, "--evidence", stmd)
    assert r.exit_code == 1, r.output
    schemas["SRMD"].validate(str(srmd))
    schemas["STMD"].validate(str(stmd))
    results = {e.get("data"): e.get("checksum") for e in file_srmds(srmd)}
    assert results["g.xml"] == hashlib.sha3_256(junit.read_bytes()).hexdigest()
    root = etree.parse(str(srmd)).getroot()
    entries = {e.get("keyword"): e.text for e in root.iterfind(
        "stc:Classification[@type='org.camera-fidelity.fidelity.subject']/"
        "stc:ClassificationEntry", NS)}
    assert entries["verdict"] == "FAIL" and entries["verdict_passed"] == "false"
    run_entries = {e.get("keyword"): e.text for e in root.iterfind(
        "stc:Classification[@type='org.camera-fidelity.fidelity.run']/stc:ClassificationEntry",
        NS)}
    assert run_entries["exit_code"] == "1" and run_entries["outcome"] == "fail"


def test_fit_lists_its_correction_files_with_their_checksums(tmp_path, schemas):
    for camera in ("nikon-5100", "sigma-sdmerrill"):
        assert run("render", "--camera", camera, "--out", tmp_path / camera).exit_code == 0
    srmd, stmd = tmp_path / "fit.srmd", tmp_path / "fit.stmd"
    r = run("fit", tmp_path / "nikon-5100" / "developed.png",
            tmp_path / "sigma-sdmerrill" / "developed.png", "--out", tmp_path / "f",
            "--evidence", srmd, "--evidence", stmd, "--accept-warnings")
    # a matrix cannot express Nikon -> Sigma: warned, exit 0 only with --accept-warnings
    assert r.exit_code == 0, r.output
    assert "fidelity: warning: the matrix model does not express" in r.output
    schemas["SRMD"].validate(str(srmd))
    schemas["STMD"].validate(str(stmd))
    checksums = {e.get("data"): e.get("checksum") for e in file_srmds(srmd)}
    for name in ("correction.cube", "correction.ocio", "correction.json", "report.json",
                 "report.html"):
        path = tmp_path / "f" / name
        assert checksums[f"f/{name}"] == hashlib.sha3_256(path.read_bytes()).hexdigest()
    image = tmp_path / "nikon-5100" / "developed.png"
    assert (checksums["nikon-5100/developed.png"]
            == hashlib.sha3_256(image.read_bytes()).hexdigest())


def test_odd_file_names_are_written_and_found_again(tmp_path, schemas):
    """A result whose name holds a control character and an undecodable byte: the documents
    stay valid XML (the name shown as \\xNN), its URI percent-encodes the raw bytes and leads
    back to the file."""
    odd = tmp_path / os.fsdecode(b"odd \x01\xff.json")
    srmd = tmp_path / "odd.srmd"
    r = run("check", "--camera", "nikon-5100", "--out", tmp_path / "out", "--json", odd,
            "--evidence", srmd, "--evidence", tmp_path / "odd.stmd")
    assert r.exit_code == 0, r.output
    schemas["SRMD"].validate(str(srmd))
    schemas["STMD"].validate(str(tmp_path / "odd.stmd"))
    entry = next(e for e in etree.parse(str(srmd)).getroot().iterfind(
        ".//stc:ClassificationEntry[@linkedType='application/json']", NS)
        if e.get("keyword").startswith("odd"))
    assert entry.get("keyword") == "odd \\x01\\xff.json"
    assert entry.get(f"{{{NS['xlink']}}}href") == "odd%20%01%FF.json"
    inner = entry.find("srmd:SimulationResourceMetaData", NS)
    assert resolve(inner.get("data"), tmp_path) == odd
    assert inner.get("checksum") == hashlib.sha3_256(odd.read_bytes()).hexdigest()


@pytest.fixture
def ssp_run(tmp_path, monkeypatch):
    """A check writing its JSON record, SRMD and STMD in ``tmp_path`` (relative names)."""
    monkeypatch.chdir(tmp_path)
    r = run("--no-config", "check", "--camera", "nikon-5100", "--no-report", "-q",
            "--evidence", "run.json", "--evidence", "run.srmd", "--evidence", "run.stmd")
    assert r.exit_code == 0, r.output
    return tmp_path


def _verify_json(folder):
    r = run("verify", folder / "run.json", "--json", folder / "v.json")
    found = {f["kind"]: f for f in json.loads((folder / "v.json").read_text())["findings"]
             if f["kind"] in ("srmd", "stmd")}
    return r, found


def test_verify_checks_the_srmd_sha3_checksums_and_content(ssp_run):
    """Issue 58: verify reads the SRMD the run wrote: each file's SHA3-256 (computed here
    with hashlib) and its content against the JSON record; and the STMD's checksums."""
    r, found = _verify_json(ssp_run)
    assert r.exit_code == 0, r.output
    assert found["srmd"]["status"] == "intact" and found["stmd"]["status"] == "intact"
    n = sum(e.get("checksum") is not None for e in file_srmds(ssp_run / "run.srmd"))
    assert found["srmd"]["detail"].startswith(f"{n} SHA3-256 checksums")
    listed = {e.get("data"): e.get("checksum") for e in file_srmds(ssp_run / "run.srmd")}
    assert listed["run.json"] == hashlib.sha3_256((ssp_run / "run.json").read_bytes()
                                                  ).hexdigest()
    assert r.output.splitlines()[-2].endswith("record intact, SRMD intact, STMD intact")


def test_an_edited_srmd_fails_verify(ssp_run):
    srmd = ssp_run / "run.srmd"
    text = srmd.read_text(encoding="utf-8")
    edited = re.sub(r'(keyword="mean_delta_e">)[0-9.]+', r"\g<1>0.5", text)
    assert edited != text
    srmd.write_text(edited, encoding="utf-8")
    r, found = _verify_json(ssp_run)
    assert r.exit_code == 1, r.output
    assert found["srmd"]["status"] == "edited"
    assert found["stmd"]["status"] == "changed"  # the STMD lists the SRMD's SHA3-256
    assert "run.srmd" in found["stmd"]["detail"]


def test_an_srmd_checksum_that_is_not_the_files_fails_verify(ssp_run):
    """A file the SRMD lists changed after the run (here the JSON record's bytes, its content
    the same: the keys reordered) fails on its SHA3-256."""
    record = ssp_run / "run.json"
    doc = json.loads(record.read_text())
    record.write_text(json.dumps(doc, indent=1), encoding="utf-8")  # same content, new bytes
    r, found = _verify_json(ssp_run)
    assert r.exit_code == 1, r.output
    assert found["srmd"]["status"] == "changed"
    assert "run.json" in found["srmd"]["detail"] and "SHA3-256" in found["srmd"]["detail"]


def test_an_srmd_the_run_wrote_but_not_handed_over_is_reported_not_failed(ssp_run):
    (ssp_run / "run.srmd").unlink()
    (ssp_run / "run.stmd").unlink()
    r, found = _verify_json(ssp_run)
    assert r.exit_code == 0, r.output
    assert found["srmd"]["status"] == "not here"


CONTEXT = """\
name = "AEB pedestrian detection, urban, day and dusk"
[detectors]
models = ["yolox_nano"]
[conditions]
illuminants = ["D65", "A"]
exposures_ev = [0.0, -1.0]
[acceptance]
max_delta_e = 2.5
max_dmap = 1.2
[risk]
model_influence = "medium"
decision_consequence = "high"
"""


def test_the_stmd_requirements_come_from_the_context_of_use(tmp_path, monkeypatch, schemas):
    """Issue 58: with --context, the STMD has a RequirementsPhase whose acceptance criteria,
    operating conditions and model risk are the context file's (read here with tomllib),
    the file itself with its SHA3-256 as input; it validates against the STMD schema; the
    JSON record holds the context of use with the file's SHA-256, and verify checks it."""
    import tomllib

    monkeypatch.chdir(tmp_path)
    (tmp_path / "context.toml").write_text(CONTEXT, encoding="utf-8")
    want = tomllib.loads(CONTEXT)
    r = run("--no-config", "check", "--camera", "nikon-5100", "--no-report", "-q",
            "--context", "context.toml", "--evidence", "run.json", "--evidence", "run.stmd")
    assert r.exit_code == 0, r.output
    stmd = tmp_path / "run.stmd"
    schemas["STMD"].validate(str(stmd))
    root = etree.parse(str(stmd)).getroot()
    phase = root.find("stmd:RequirementsPhase", NS)
    assert phase is not None
    assert [e.tag.split("}")[1] for e in root][:2] == ["RequirementsPhase", "EvaluationPhase"]

    def entries(step, kind):
        found = phase.find(f"stmd:{step}", NS).iterfind(
            f".//stc:Classification[@type='org.camera-fidelity.fidelity.{kind}']", NS)
        return [{e.get("keyword"): e.text for e in c} for c in found]

    assert entries("DefineModelRequirements", "acceptance") == [
        {"criterion": k, "limit": repr(float(v))} for k, v in want["acceptance"].items()]
    conditions, = entries("DefineTestCaseRequirements", "conditions")
    assert conditions == {"detectors": "yolox_nano", "illuminants": "D65, A",
                          "exposures_ev": "0.0, -1.0"}
    risk, = entries("DefineQualityAssuranceRequirements", "risk")
    assert risk == {"model_influence": "medium", "decision_consequence": "high",
                    "risk_level": "4", "required_level": "4"}  # 1 + medium 1 + high 2
    source = phase.find("stmd:DefineModelRequirements/stc:Input/stc:Resource", NS)
    assert source.get("source") == "context.toml"
    inner = source.find(".//srmd:SimulationResourceMetaData", NS)
    assert inner.get("checksum") == hashlib.sha3_256(
        (tmp_path / "context.toml").read_bytes()).hexdigest()

    doc = json.loads((tmp_path / "run.json").read_text())
    assert doc["context_of_use"]["file"]["sha256"] == hashlib.sha256(
        (tmp_path / "context.toml").read_bytes()).hexdigest()
    assert doc["context_of_use"]["context"]["max_delta_e"] == 2.5
    r, found = _verify_json(tmp_path)
    assert r.exit_code == 0 and found["stmd"]["status"] == "intact", r.output
    assert "context file" in r.output and "unchanged" in r.output
    (tmp_path / "context.toml").write_text(CONTEXT.replace("2.5", "5.0"), encoding="utf-8")
    r, found = _verify_json(tmp_path)
    assert r.exit_code == 1 and found["stmd"]["status"] == "changed", r.output


def test_without_a_context_the_stmd_has_no_requirements_phase(check_run):
    _, paths = check_run
    root = etree.parse(str(paths["stmd"])).getroot()
    assert root.find("stmd:RequirementsPhase", NS) is None
