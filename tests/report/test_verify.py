"""``fidelity verify``: a credibility record checked against the files it names (SHA-256 of
each, computed here with hashlib), the code and environment, and the run repeated (--rerun)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.cli.verify import rerun_argv
from fidelity.report.evidence import seal_record
from fidelity.report.verify import STATUSES, rerun_finding, verify_record

REPO = Path(__file__).resolve().parents[2]
CAMERA = REPO / "fidelity" / "data" / "cameras" / "nikon-5100.toml"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def findings(result) -> dict[tuple[str, str], str]:
    return {(f.kind, f.name): f.status for f in result.findings}


@pytest.fixture
def checked(tmp_path, monkeypatch):
    """A check of a camera file (an odd name) with its record, run in ``tmp_path``."""
    monkeypatch.chdir(tmp_path)
    camera = tmp_path / "my cam é.toml"
    shutil.copyfile(CAMERA, camera)
    r = run("check", "--camera", camera.name, "--max-delta-e", "0.5", "--out", "report",
            "--evidence", "record.json")
    assert r.exit_code == 1, r.output  # ΔE ~1.0 > 0.5: a failed verdict, recorded as such
    return tmp_path, camera, tmp_path / "record.json"


def test_record_holds_the_command_line_and_settings_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    settings = tmp_path / "fidelity.toml"
    settings.write_text("max_delta_e = 2.5\n", encoding="utf-8")
    r = run("check", "-q", "--evidence", "e.json", "--out", "rep")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "e.json").read_text())
    assert doc["record"]["schema_version"] == "1.2"
    inv = doc["invocation"]
    assert inv["argv"] == ["check", "-q", "--evidence", "e.json", "--out", "rep"]
    assert Path(inv["cwd"]) == tmp_path
    assert inv["settings"] == {"path": str(settings), "sha256": sha256(settings)}
    assert doc["subjects"][0]["verdict"]["limit"] == 2.5  # the settings file was read
    r = run("--no-config", "check", "-q", "--evidence", "f.json", "--out", "rep2")
    assert json.loads((tmp_path / "f.json").read_text())["invocation"]["settings"] is None


def test_a_camera_file_is_not_also_listed_as_the_built_in_camera(checked):
    _, camera, record = checked
    inputs = json.loads(record.read_text())["subjects"][0]["inputs"]
    assert [(i["role"], i["sha256"]) for i in inputs if i["path"]] == [
        ("camera file", sha256(camera))]  # the file's name is nikon-5100 inside: not built-in


def test_verify_finds_every_file_unchanged(checked):
    folder, camera, record = checked
    r = run("verify", record, "--json", folder / "v.json")
    assert r.exit_code == 0, r.output
    doc = json.loads((folder / "v.json").read_text())
    assert doc["verified"] is True
    got = {(f["kind"], f["name"]): f for f in doc["findings"]}
    cam = got[("input", "camera file")]
    assert cam["status"] == "unchanged" and Path(cam["path"]).resolve() == camera.resolve()
    assert cam["detail"] == f"SHA-256 {sha256(camera)[:12]}"
    assert got[("prediction table", "coco1000-measured")]["status"] == "unchanged"
    assert got[("calibration table", "calibration-safecolor")]["status"] == "unchanged"
    assert got[("code", "fidelity")]["status"] == "same"
    assert got[("environment", "Python and libraries")]["status"] == "same"
    # the camera, the prediction, calibration, sharpness and noise tables, the validated
    # cameras, the validated bound, the validated margin of the combined loss, and the five
    # scores files the tables rebuild from (four detectors' colour sweeps, one blur and noise
    # sweep)
    for name in ("coco1000-sharpness", "coco1000-noise"):
        assert got[("property table", name)]["status"] == "unchanged"
    assert got[("validated bound", "validated-bound")]["status"] == "unchanged"
    assert got[("property margin", "property-margin")]["status"] == "unchanged"
    assert sum(k[0] == "scores file" for k in got) == 5
    assert r.output.splitlines()[-2] == "VERIFIED: 14 of 14 files unchanged, record intact"


def test_verify_fails_on_a_changed_or_missing_file_and_looks_in_inputs(checked, tmp_path):
    folder, camera, record = checked
    original = camera.read_bytes()
    camera.write_bytes(original + b"# one more line\n")
    r = run("verify", record)
    assert r.exit_code == 1, r.output
    assert f"changed; SHA-256 {sha256(camera)[:12]}, recorded " \
           f"{hashlib.sha256(original).hexdigest()[:12]}" in r.output
    assert r.output.splitlines()[-1] == "NOT VERIFIED: 1 changed of 14 files, record intact"
    handed = folder / "handed over"
    handed.mkdir()
    (handed / camera.name).write_bytes(original)
    camera.unlink()
    assert findings(verify_record(record))[("input", "camera file")] == "missing"
    found = verify_record(record, inputs=handed)
    assert findings(found)[("input", "camera file")] == "unchanged" and found.verified
    assert run("verify", record, "--inputs", handed).exit_code == 0


def test_shipped_data_named_by_another_installation_is_read_from_this_one(checked):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    table = doc["subjects"][0]["prediction_table"]
    table["path"] = "/elsewhere/lib/python3.12/site-packages/fidelity/data/prediction/" \
                    "coco1000-measured.json"
    moved = folder / "moved.json"
    moved.write_text(json.dumps(seal_record(doc)), encoding="utf-8")
    f = next(f for f in verify_record(moved).findings if f.kind == "prediction table")
    assert f.status == "unchanged"
    assert Path(f.path or "").resolve() == (
        REPO / "fidelity" / "data" / "prediction" / "coco1000-measured.json").resolve()
    table["sha256"] = "0" * 64  # the table this installation ships is not the recorded one
    moved.write_text(json.dumps(seal_record(doc)), encoding="utf-8")
    assert findings(verify_record(moved))[("prediction table", "coco1000-measured")] == "changed"


def test_other_code_and_libraries_are_reported_not_failed(checked):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["tool"]["code_sha256"] = "1" * 64
    doc["tool"]["dirty"] = True
    deps = doc["environment"]["dependencies"]
    deps["numpy"] = "1.0.0"
    deps["no-such-library"] = "9.9"
    other = folder / "other.json"
    other.write_text(json.dumps(seal_record(doc)), encoding="utf-8")  # another installation's
    r = run("verify", other)
    assert r.exit_code == 0, r.output
    got = {f.kind: f for f in verify_record(other).findings}
    assert got["code"].status == "differs" and "1111111111" in got["code"].detail
    assert "with uncommitted changes" in got["code"].detail
    import numpy

    env = got["environment"]
    assert env.status == "differs"
    assert f"numpy 1.0.0 -> {numpy.__version__}" in env.detail
    assert "no-such-library 9.9 -> absent" in env.detail


@pytest.mark.parametrize(("content", "suffix", "problem"), [
    ("{}", ".json", "record: required"),
    ("[1, 2]", ".json", "must be a table"),
    ("{not json", ".json", "json"),
    ('{"record": {"schema": "fidelity credibility record", "schema_version": "9.0"}}', ".json",
     "newer than this fidelity reads"),
    ("<SRMD/>", ".srmd", "reads the JSON credibility record"),
])
def test_a_file_that_is_not_a_readable_record_is_one_error_line(tmp_path, content, suffix,
                                                               problem):
    bad = tmp_path / f"odd name é{suffix}"
    bad.write_text(content, encoding="utf-8")
    r = run("verify", bad)
    assert r.exit_code == 2, r.output
    line, = r.output.strip().splitlines()
    assert line.startswith("fidelity: error: ") and "odd name é" in line
    assert problem.lower() in line.lower()


def test_a_digest_that_is_not_sha256_is_named(checked):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["subjects"][0]["inputs"][0]["sha256"] = "XYZ"
    bad = folder / "bad.json"
    bad.write_text(json.dumps(doc), encoding="utf-8")
    r = run("verify", bad)
    assert r.exit_code == 2 and "subjects[0].inputs[0].sha256: must be 64" in r.output


def test_rerun_reproduces_the_run_without_writing_over_its_outputs(checked):
    folder, _, record = checked
    before = {p: (p.read_bytes(), p.stat().st_mtime_ns)
              for p in [record, *sorted((folder / "report").iterdir())]}
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "fidelity", "verify", str(record), "--rerun",
                           "--json", str(folder / "v.json")], cwd=folder, env=env,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads((folder / "v.json").read_text())
    rerun = next(f for f in doc["findings"] if f["kind"] == "rerun")
    assert rerun["status"] == "reproduced"
    assert "exit 1 as recorded" in rerun["detail"] and "mean ΔE00 identical" in rerun["detail"]
    after = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in before}
    assert after == before  # the repeat wrote into a folder of its own
    assert not (folder / "fidelity-report").exists()


def test_rerun_finding_compares_exit_code_verdict_and_value_within_u():
    def record(code, value, label="PASS", u=0.02):
        return {"record": {"command": "check", "exit_code": code},
                "subjects": [{"subject": "cam", "error": None, "verdict": {"label": label},
                              "measurement": {"quantity": "mean ΔE00", "value": value,
                                              "uncertainty": {"standard_uncertainty": u}}}]}

    same = rerun_finding(record(0, 1.0), record(0, 1.0), 0)
    assert same.status == "reproduced" and "mean ΔE00 identical" in same.detail
    close = rerun_finding(record(0, 1.0), record(0, 1.01), 0)
    assert close.status == "reproduced" and "1.01, recorded 1 (0.50 u)" in close.detail
    far = rerun_finding(record(0, 1.0), record(0, 1.03), 0)
    assert far.status == "not reproduced" and far.detail == "cam: mean ΔE00 1.03, recorded 1 " \
                                                           "(1.50 u)"
    assert rerun_finding(record(0, 1.0), record(1, 1.0, "FAIL"), 1).status == "not reproduced"
    exact = rerun_finding(record(0, 1.0, u=0.0), record(0, 1.0 + 1e-6, u=0.0), 0)
    assert exact.status == "not reproduced"  # no uncertainty recorded: equal within 1e-9
    cube = record(0, 1.0)
    cube["subjects"][0]["correction"] = {"files": {"cube": {"path": "c", "sha256": "a" * 64}}}
    assert "cube the same bytes" in rerun_finding(cube, cube, 0).detail
    other = json.loads(json.dumps(cube))
    other["subjects"][0]["correction"]["files"]["cube"]["sha256"] = "b" * 64
    moved = rerun_finding(cube, other, 0)
    assert moved.status == "not reproduced" and "cube other bytes" in moved.detail
    none = rerun_finding(record(0, 1.0), None, 2, "fidelity: error: x: gone")
    assert none.status == "not reproduced" and "exit 2" in none.detail and "gone" in none.detail
    assert STATUSES["not reproduced"] and not STATUSES["reproduced"]


def test_rerun_argv_sends_every_output_elsewhere_and_keeps_the_rest(tmp_path):
    argv = ["-v", "--config", "ci.toml", "gate", "a.png", "b.exr", "--junit", "j.xml",
            "--evidence", "e.json", "--evidence", "e.srmd", "--json=r.json", "-q",
            "--max-delta-e", "3", "--corners", "1,2,3,4,5,6,7,8"]
    got = rerun_argv(argv, tmp_path)
    assert got[:4] == ["-v", "--config", "ci.toml", "gate"]
    assert got[4:11] == ["a.png", "b.exr", "-q", "--max-delta-e", "3", "--corners",
                         "1,2,3,4,5,6,7,8"]
    outputs = got[11:]
    assert dict(zip(outputs[::2], outputs[1::2], strict=True)) == {
        "--junit": str(tmp_path / "junit.xml"), "--json": str(tmp_path / "run.json"),
        "--evidence": str(tmp_path / "record.json")}  # --html: not asked for, not written
    # what the settings file sends somewhere is sent into the folder too
    assert "--html" in rerun_argv(argv, tmp_path, "ci.toml", configured={"html_path"})
    # the recorded settings file is named again, or none read when none was
    assert rerun_argv(["check"], tmp_path)[:2] == ["--no-config", "check"]
    assert rerun_argv(["check"], tmp_path, "/a/fidelity.toml")[:3] == [
        "--config", "/a/fidelity.toml", "check"]
    assert "--out" in rerun_argv(["check", "--no-report"], tmp_path)
    with pytest.raises(Exception, match="--rerun repeats"):
        rerun_argv(["sweep", "--out", "x"], tmp_path)


def test_rerun_needs_the_recorded_command_line(tmp_path):
    import fidelity
    from fidelity.report.evidence import write_evidence

    report = fidelity.check_camera("nikon-5100")
    record = tmp_path / "api.json"
    write_evidence(record, "check", [("nikon-5100", report, None)], 0)
    assert json.loads(record.read_text())["invocation"] is None
    assert run("verify", record).exit_code == 0
    r = run("verify", record, "--rerun")
    assert r.exit_code == 2 and "holds no command line" in r.output


@pytest.mark.parametrize("path", ["a\u0000b.png", "x" * 5000, "/", ""])
def test_a_path_that_cannot_name_a_file_here_is_missing_not_an_error(checked, path):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["subjects"][0]["inputs"][0]["path"] = path
    doc["invocation"]["cwd"] = path
    odd = folder / "odd.json"
    odd.write_text(json.dumps(doc), encoding="utf-8")
    r = run("verify", odd)
    assert r.exit_code == 1, r.output
    assert "input camera file: missing;" in r.output
    r = run("verify", odd, "--rerun")
    if path == "/":  # a folder that is here: the repeat runs there and cannot find its camera
        assert r.exit_code == 1 and "rerun: not reproduced; the run ended with exit 2" in r.output
    else:
        assert r.exit_code == 2 and "the folder the run started in is not here" in r.output


def _edited(folder: Path, record: Path, edit) -> Path:
    """A copy of ``record`` with ``edit`` applied to its content and not sealed again."""
    doc = json.loads(record.read_text())
    edit(doc)
    out = folder / "edited.json"
    out.write_text(json.dumps(doc, indent=2), encoding="utf-8")
    return out


def test_the_record_holds_the_sha256_of_its_canonical_content(checked):
    """The canonical form computed here by hand: the record without the field, keys sorted,
    compact separators, non-ASCII as \\u escapes, UTF-8."""
    _, _, record = checked
    doc = json.loads(record.read_text())
    recorded = doc["record"].pop("content_sha256")
    canonical = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    assert recorded == hashlib.sha256(canonical.encode("utf-8")).hexdigest()
    assert findings(verify_record(record))[("content", "record")] == "intact"


@pytest.mark.parametrize(("what", "edit"), [
    ("tool.version", lambda d: d["tool"].update(version="0.2.0")),
    ("a measured value", lambda d: d["subjects"][0]["measurement"].update(
        value=d["subjects"][0]["measurement"]["value"] - 0.5)),
    ("the verdict", lambda d: d["subjects"][0]["verdict"].update(passed=True)),
    ("the hash removed", lambda d: d["record"].pop("content_sha256")),
])
def test_an_edited_record_fails_without_rerun(checked, what, edit):
    folder, _, record = checked
    r = run("verify", _edited(folder, record, edit))
    assert r.exit_code == 1, (what, r.output)
    line = next(x for x in r.output.splitlines() if x.startswith("  content:"))
    assert line.startswith("  content: edited; the record's content hash ")
    assert "the record was edited" in line
    assert r.output.splitlines()[-1].startswith("NOT VERIFIED: ")


def test_an_edited_input_file_fails_and_an_untouched_record_verifies(checked):
    folder, camera, record = checked
    assert run("verify", record).exit_code == 0
    camera.write_bytes(camera.read_bytes().replace(b"=", b" = ", 1))
    r = run("verify", record)
    assert r.exit_code == 1 and "input camera file" in r.output and ": changed;" in r.output


def test_a_version_edited_and_sealed_again_is_inconsistent_with_its_code(checked):
    """The version lives in the code the code SHA-256 covers: the same code under another
    version is an edit even when the content hash was recomputed."""
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["tool"]["version"] = "0.2.0"
    resealed = folder / "resealed.json"
    resealed.write_text(json.dumps(seal_record(doc)), encoding="utf-8")
    r = run("verify", resealed)
    assert r.exit_code == 1, r.output
    got = {f.kind: f for f in verify_record(resealed).findings}
    assert got["content"].status == "intact"
    assert got["code"].status == "inconsistent" and "fidelity 0.2.0" in got["code"].detail
    assert got["version"].status == "other version"


def test_another_versions_record_is_reported_as_such(checked):
    """Another version with other code: reported (the files are still checked), not failed."""
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["tool"].update(version="0.2.0", code_sha256="2" * 64)
    other = folder / "other-version.json"
    other.write_text(json.dumps(seal_record(doc)), encoding="utf-8")
    r = run("verify", other)
    assert r.exit_code == 0, r.output
    assert "  version: other version; made by fidelity 0.2.0, verified with fidelity" in r.output
    assert ", version other version" in r.output.splitlines()[-1]


def test_a_layout_1_1_record_without_content_hash_is_not_hashed(checked):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    doc["record"].pop("content_sha256")
    doc["record"]["schema_version"] = "1.1"
    old = folder / "old.json"
    old.write_text(json.dumps(doc), encoding="utf-8")
    assert findings(verify_record(old))[("content", "record")] == "not hashed"


def test_the_validated_cameras_file_is_hashed_and_checked(checked):
    folder, _, record = checked
    doc = json.loads(record.read_text())
    cameras = doc["subjects"][0]["validity"]["validated_cameras"]
    shipped = REPO / "fidelity" / "data" / "validation-domain.json"
    assert cameras["sha256"] == sha256(shipped)
    assert findings(verify_record(record))[("validated cameras", "validation-domain")] == \
        "unchanged"
    cameras["sha256"] = "3" * 64
    edited = folder / "cams.json"
    edited.write_text(json.dumps(seal_record(doc)), encoding="utf-8")
    assert findings(verify_record(edited))[("validated cameras", "validation-domain")] == \
        "changed"
