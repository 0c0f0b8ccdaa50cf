"""The pieces a simulator team drops into its CI: JUnit XML, the GitHub Action, the GitLab
CI/CD component, the pre-commit hook, the pytest plugin and the container."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.core.resources import resource_dir

REPO = Path(__file__).resolve().parents[2]
JUNIT_XSD = resource_dir("data") / "schemas" / "junit.xsd"


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> dict[str, Path]:
    """Display PNGs of two cameras' renders (the chart, found by the audit)."""
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_png

    folder = tmp_path_factory.mktemp("renders")
    out = {}
    for name, camera in (("good", "nikon-5100"), ("bad", str(REPO / "cameras" /
                                                              "bad-oversaturated.toml"))):
        r = render_chart(camera)
        out[name] = write_png(folder / f"{name}.png", r.display_image, 16)
    return out


def _valid_junit(path: Path) -> ET.Element:
    lxml = pytest.importorskip("lxml.etree")
    schema = lxml.XMLSchema(lxml.parse(str(JUNIT_XSD)))
    doc = lxml.parse(str(path))
    assert schema.validate(doc), schema.error_log
    return ET.parse(path).getroot()


def test_junit_is_valid_with_stable_names_timestamp_hostname_and_threshold(renders, tmp_path):
    junit = tmp_path / "j.xml"
    for limit in ("3", "1.5"):  # changing the threshold keeps the test name
        r = CliRunner().invoke(main, ["gate", str(renders["good"]), "--max-delta-e", limit,
                                      "--junit", str(junit)])
        assert r.exit_code in (0, 1), r.output
        root = _valid_junit(junit)
        suite = root.find("testsuite")
        assert suite is not None
        case = suite.find("testcase")
        assert case is not None and case.get("name") == f"colour fidelity of {renders['good']}"
        assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d", suite.get("timestamp", ""))
        assert suite.get("hostname")
        # one image's values are its test case's properties, as for several (issue 57); the
        # suite's own describe the run
        props = {p.get("name"): p.get("value") for p in case.iter("property")}
        assert props["limit"] == str(float(limit)) and props["criterion"] == "max-delta-e"
        assert [p.get("name") for p in suite.findall("properties/property")] == [
            "fidelity_version"]
        assert case.get("classname") == "fidelity.gate"
    # several images, one of them unreadable: a failure, an error, properties per case
    (tmp_path / "broken.png").write_bytes(b"not a png")
    r = CliRunner().invoke(main, ["gate", str(renders["good"]), str(renders["bad"]),
                                  str(tmp_path / "broken.png"), "--max-delta-e", "3",
                                  "--junit", str(junit)])
    assert r.exit_code == 2
    root = _valid_junit(junit)
    assert (root.get("tests"), root.get("failures"), root.get("errors")) == ("3", "1", "1")
    for case in root.iter("testcase"):
        assert case.find("properties/property[@name='limit']") is not None


def test_pytest_plugin_fixture_asserts_an_images_colour(renders, pytester):
    pytester.makepyfile(f"""
        import pytest

        def test_good(colour_fidelity):
            assert colour_fidelity({str(renders['good'])!r}) <= 3

        def test_bad(colour_fidelity):
            assert colour_fidelity({str(renders['bad'])!r}) <= 3

        @pytest.mark.colour_fidelity(reference="safecolor")
        def test_marker_sets_the_reference(colour_fidelity):
            result = colour_fidelity({str(renders['good'])!r})
            assert result.report.source.reference == "safecolor" and result > 1
    """)
    # loaded by its pytest11 entry point, in a fresh process (an in-process run drops the
    # modules it imported, and numpy's extension modules load once per process)
    result = pytester.runpytest_subprocess("--junitxml=out.xml")
    result.assert_outcomes(passed=2, failed=1)
    props = {p.get("name"): p.get("value")
             for p in ET.parse(pytester.path / "out.xml").getroot().iter("property")}
    # the chart ΔE each test compared with 3, recorded per image: the good one within, the
    # bad one beyond (the failed test)
    mean = {name: float(v) for k, v in props.items()
            for name in ("good.png", "bad.png") if k.endswith(f"{name}:mean_delta_e")}
    assert mean["good.png"] <= 3 < mean["bad.png"]


def test_pre_commit_hook_manifest_and_entry(tmp_path):
    clientlib = pytest.importorskip("pre_commit.clientlib")
    (hook,) = clientlib.load_manifest(str(REPO / ".pre-commit-hooks.yaml"))
    files = re.compile(hook["files"])
    exclude = re.compile(hook["exclude"])

    def selected(path: str) -> bool:
        return bool(files.search(path)) and not exclude.search(path)

    assert selected("sim/cameras/front.toml") and selected("cameras/wide.yaml")
    assert not selected("pyproject.toml") and not selected("cameras/suite.toml")
    assert not selected("sim/cameras/notes.md")
    cameras = tmp_path / "cameras"
    cameras.mkdir()
    for name in ("ideal-srgb8.toml", "bad-oversaturated.toml"):
        shutil.copy(REPO / "cameras" / name, cameras / name)
    entry = shlex.split(hook["entry"])
    ok = subprocess.run([*entry, str(cameras / "ideal-srgb8.toml")], cwd=tmp_path,
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    both = subprocess.run([*entry, "--max-delta-e", "3", str(cameras / "ideal-srgb8.toml"),
                           str(cameras / "bad-oversaturated.toml")], cwd=tmp_path,
                          capture_output=True, text=True)
    assert both.returncode == 1 and "FAIL" in both.stdout
    assert not (tmp_path / "fidelity-report").exists()  # a hook writes no reports


def _action() -> dict:
    return yaml.safe_load((REPO / "action.yml").read_text())


def _gate_script() -> str:
    (step,) = [s for s in _action()["runs"]["steps"] if s.get("id") == "gate"]
    return step["run"]


@pytest.mark.parametrize("images, limit, code", [("good", "3", 0), ("good bad", "3", 1),
                                                 ("good", "0.1", 1)])
def test_github_action_gate_step(renders, tmp_path, images, limit, code):
    action = _action()
    assert action["runs"]["using"] == "composite"
    assert {"images", "camera", "max-delta-e", "max-dmap", "args", "report-dir"} <= set(
        action["inputs"])
    uses = [s["uses"] for s in action["runs"]["steps"] if "uses" in s]
    assert any(u.startswith("actions/upload-artifact@") for u in uses)
    report_dir = tmp_path / "fidelity-report"
    output = tmp_path / "github_output"
    env = {**os.environ, "FIDELITY_IMAGES": " ".join(str(renders[i]) for i in images.split()),
           "FIDELITY_CAMERA": "", "FIDELITY_MAX_DELTA_E": limit, "FIDELITY_MAX_DMAP": "",
           "FIDELITY_ARGS": "", "FIDELITY_REPORT_DIR": str(report_dir),
           "GITHUB_OUTPUT": str(output), "GITHUB_STEP_SUMMARY": str(tmp_path / "summary.md")}
    r = subprocess.run(["bash", "-c", _gate_script()], env=env, capture_output=True, text=True,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr  # the step itself succeeds; the verdict step exits
    assert output.read_text().splitlines()[0] == f"exit-code={code}"
    # the job summary: the outcome, then what the gate printed (also in the log)
    summary = (tmp_path / "summary.md").read_text().splitlines()
    assert summary[0] == f"### camera-fidelity: {('pass', 'fail')[code]} (exit {code})"
    assert summary[2] == "```text" and summary[-1] == "```"
    assert summary[3:-1] == r.stdout.splitlines()
    assert sum(line.lstrip().startswith(("PASS", "FAIL")) for line in summary) == len(images.split())
    _valid_junit(report_dir / "junit.xml")
    htmls = sorted(p.name for p in report_dir.glob("*.html"))
    # one report per image, and with several an overview page beside them
    assert len(htmls) == len(images.split()) + (len(images.split()) > 1)
    assert ("index.html" in htmls) == (len(images.split()) > 1)


def test_dockerfile_installs_what_ci_installs():
    docker = (REPO / "Dockerfile").read_text()
    ci = (REPO / ".ci" / "run").read_text()
    assert "libllvm19" in docker and "libllvm19" in ci  # Mitsuba's llvm_* variants
    # the core by default, the extras CI tests as a build argument; a pinned base; not root
    assert re.search(r'pip install "\.\$\{EXTRAS:\+\[\$\{EXTRAS\}\]\}"', docker)
    assert "--build-arg EXTRAS=render,coco" in docker
    assert re.search(r"^FROM python:\d+\.\d+\.\d+-slim-\w+$", docker, re.M)
    assert re.search(r"^USER (?!root)\w+$", docker, re.M)
    # one OpenCV build, the headless contrib one (cv2.mcc, no libGL)
    import tomllib

    deps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    assert [d for d in deps if d.startswith("opencv")] == [
        d for d in deps if d.startswith("opencv-contrib-python-headless")]


def _docker_engine() -> bool:
    if shutil.which("docker") is None:
        return False
    return subprocess.run(["docker", "info"], capture_output=True).returncode == 0


@pytest.mark.slow
@pytest.mark.skipif(not _docker_engine(), reason="no Docker engine runs here (docker info "
                                                  "fails); the container is built where one does")
def test_container_builds_and_checks_the_default_camera(tmp_path):
    tag = "camera-fidelity:test"
    subprocess.run(["docker", "build", "-t", tag, str(REPO)], check=True)
    r = subprocess.run(["docker", "run", "--rm", tag, "check", "--no-report", "--json", "-"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["command"] == "check" and np.isfinite(doc["mean_delta_e"])
    assert doc["verdict"]["passed"] is True and doc["verdict"]["value"] == doc["mean_delta_e"]


def _step(step_id: str | None = None, name: str | None = None) -> dict:
    (step,) = [s for s in _action()["runs"]["steps"]
               if (step_id and s.get("id") == step_id) or (name and s.get("name") == name)]
    return step


def test_github_action_installs_its_own_checkout(tmp_path):
    """The install step as the runner runs it: in the caller's repository, GITHUB_ACTION_PATH
    the Action's checkout; with no package input it installs that checkout, not the caller."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "pip-args"
    (bin_dir / "python").write_text(f'#!/bin/sh\necho "$@" > {log}\n')
    (bin_dir / "python").chmod(0o755)
    caller = tmp_path / "caller"
    caller.mkdir()
    step = _step(name="Install camera-fidelity")
    assert "${{ github.action_path }}" not in step["run"]  # the runner exports it to the step
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}",
           "GITHUB_ACTION_PATH": str(REPO), "FIDELITY_PACKAGE": ""}
    r = subprocess.run(["bash", "-c", step["run"]], env=env, cwd=caller, capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    assert log.read_text().split()[-1] == str(REPO)
    env["FIDELITY_PACKAGE"] = "camera-fidelity==0.1.0"
    subprocess.run(["bash", "-c", step["run"]], env=env, cwd=caller, check=True)
    assert log.read_text().split()[-1] == "camera-fidelity==0.1.0"


def test_github_action_leaves_thresholds_to_the_project_and_names_its_artifact(renders,
                                                                              tmp_path):
    """Empty thresholds: the caller's [tool.fidelity] settings decide (here a strict 0.1 that
    fails the good render); the artifact is named after the job and matrix entry."""
    action = _action()
    assert action["inputs"]["max-delta-e"]["default"] == ""
    assert action["inputs"]["package"]["default"] == ""
    (upload,) = [s for s in action["runs"]["steps"]
                 if s.get("uses", "").startswith("actions/upload-artifact@")]
    assert upload["with"]["name"] == "${{ steps.gate.outputs.artifact }}"
    caller = tmp_path / "caller"
    caller.mkdir()
    (caller / "pyproject.toml").write_text("[tool.fidelity]\nmax_delta_e = 0.1\n")
    output = tmp_path / "github_output"
    env = {**os.environ, "FIDELITY_IMAGES": str(renders["good"]), "FIDELITY_CAMERA": "",
           "FIDELITY_MAX_DELTA_E": "", "FIDELITY_MAX_DMAP": "", "FIDELITY_ARGS": "",
           "FIDELITY_REPORT_DIR": str(tmp_path / "reports"), "FIDELITY_ARTIFACT": "",
           "FIDELITY_JOB": "colour", "FIDELITY_MATRIX_INDEX": "2",
           "GITHUB_OUTPUT": str(output)}
    r = subprocess.run(["bash", "-c", _step("gate")["run"]], env=env, capture_output=True,
                       text=True, cwd=caller)
    assert r.returncode == 0, r.stderr
    assert output.read_text().split() == ["exit-code=1", "artifact=fidelity-report-colour-2"]
    env.update(FIDELITY_ARTIFACT="mine", FIDELITY_MAX_DELTA_E="3")
    output.unlink()
    subprocess.run(["bash", "-c", _step("gate")["run"]], env=env, cwd=caller, check=True,
                   capture_output=True)
    assert output.read_text().split() == ["exit-code=0", "artifact=mine"]


def test_github_action_qualifies_the_tool_before_gating(renders, tmp_path):
    """qualify: "true" runs ``fidelity qualify`` first and files its record beside the
    reports; a failed qualification is the step's exit code and no gate runs."""
    assert _action()["inputs"]["qualify"]["default"] == "false"
    report_dir = tmp_path / "reports"
    output = tmp_path / "github_output"
    env = {**os.environ, "FIDELITY_IMAGES": str(renders["good"]), "FIDELITY_CAMERA": "",
           "FIDELITY_MAX_DELTA_E": "3", "FIDELITY_MAX_DMAP": "", "FIDELITY_ARGS": "",
           "FIDELITY_REPORT_DIR": str(report_dir), "FIDELITY_QUALIFY": "true",
           "GITHUB_OUTPUT": str(output)}
    r = subprocess.run(["bash", "-c", _gate_script()], env=env, capture_output=True, text=True,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert output.read_text().splitlines()[0] == "exit-code=0"
    doc = json.loads((report_dir / "qualification.json").read_text())
    assert doc["qualified"] is True and (report_dir / "junit.xml").is_file()
    # a qualification that fails (a stand-in fidelity whose qualify exits 1): no gate runs
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    calls = tmp_path / "calls"
    (bin_dir / "fidelity").write_text(f'#!/bin/sh\necho "$1" >> {calls}\n'
                                      '[ "$1" = qualify ] && exit 1\nexit 0\n')
    (bin_dir / "fidelity").chmod(0o755)
    output.unlink()
    env.update(PATH=f"{bin_dir}:{os.environ['PATH']}", FIDELITY_REPORT_DIR=str(tmp_path / "r2"))
    env["GITHUB_STEP_SUMMARY"] = str(tmp_path / "summary.md")
    r = subprocess.run(["bash", "-c", _gate_script()], env=env, capture_output=True, text=True,
                       cwd=tmp_path)
    assert r.returncode == 0 and output.read_text().splitlines()[0] == "exit-code=1"
    assert calls.read_text().split() == ["qualify"]
    summary = (tmp_path / "summary.md").read_text().splitlines()
    assert summary[0] == "### camera-fidelity qualification: fail (exit 1)"


# -- the GitLab CI/CD component (templates/gate.yml) ------------------------------------------

GITLAB_COMPONENT = REPO / "templates" / "gate.yml"
_INPUT = re.compile(r"\$\[\[\s*inputs\.([A-Za-z0-9_-]+)\s*\]\]")


def _gitlab_component() -> tuple[dict, dict]:
    header, jobs = yaml.safe_load_all(GITLAB_COMPONENT.read_text(encoding="utf-8"))
    return header, jobs


def _interpolate(node, values: dict[str, str]):  # type: ignore[no-untyped-def]
    """The jobs with ``$[[ inputs.NAME ]]`` replaced, as GitLab does after parsing the YAML
    (in keys and string values); an input the header does not declare is an error there."""
    if isinstance(node, dict):
        return {_interpolate(k, values): _interpolate(v, values) for k, v in node.items()}
    if isinstance(node, list):
        return [_interpolate(v, values) for v in node]
    if isinstance(node, str):
        return _INPUT.sub(lambda m: values[m.group(1)], node)
    return node


def _component_job(**given: str) -> tuple[str, dict]:
    """The component's one job with the given inputs (the rest at their defaults)."""
    header, jobs = _gitlab_component()
    inputs = header["spec"]["inputs"]
    assert set(given) <= set(inputs), set(given) - set(inputs)
    values = {k: given.get(k, spec["default"]) for k, spec in inputs.items()}
    for k, spec in inputs.items():
        assert values[k] in spec.get("options", [values[k]]), (k, values[k])
    ((name, job),) = _interpolate(jobs, values).items()
    return name, job


def _run_component_script(job: dict, cwd: Path, path: str | None = None
                          ) -> subprocess.CompletedProcess[str]:
    """The job's script after its install line, as the runner runs it (bash -eo pipefail, the
    job's variables in the environment, in the project's checkout)."""
    script = job["script"]
    assert script[0] == 'python -m pip install --quiet "$FIDELITY_PACKAGE"'
    env = {**os.environ, **{k: str(v) for k, v in job["variables"].items()}}
    if path:
        env["PATH"] = f"{path}:{env['PATH']}"
    return subprocess.run(["bash", "-eo", "pipefail", "-c", "\n".join(script[1:])], env=env,
                          cwd=cwd, capture_output=True, text=True)


def test_gitlab_component_is_valid_gitlab_ci(tmp_path):
    """Header and job validate against GitLab's CI schema (as check-jsonschema ships it),
    before and after interpolation; every input is declared, used, documented and optional;
    no keyword a component must not set at the top level."""
    pytest.importorskip("check_jsonschema", reason="check-jsonschema (the test extra) checks "
                        "the component against GitLab's CI schema")
    header, jobs = _gitlab_component()
    inputs = header["spec"]["inputs"]
    for name, spec in inputs.items():
        assert set(spec) <= {"description", "default", "options", "type", "regex"}, name
        assert spec.get("description") and "default" in spec, name
    used = set(_INPUT.findall(GITLAB_COMPONENT.read_text(encoding="utf-8").split("\n---\n")[1]))
    assert used == set(inputs)
    assert not {"default", "variables", "stages", "include"} & set(jobs)
    name, job = _component_job(images="a.exr", **{"max-delta-e": "3"})
    assert name == "fidelity-gate" and job["allow_failure"] == {"exit_codes": [4]}
    assert job["artifacts"]["when"] == "always"
    assert job["artifacts"]["reports"]["junit"] == "fidelity-report/junit.xml"
    for i, doc in enumerate((header, jobs, {name: job})):
        (tmp_path / f"{i}.json").write_text(json.dumps(doc), encoding="utf-8")
        r = subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema",
                            "vendor.gitlab-ci", str(tmp_path / f"{i}.json")],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stdout + r.stderr
    bad = {name: {**job, "allow_failure": {"exit_codes": "four"}}}  # the schema does check
    (tmp_path / "bad.json").write_text(json.dumps(bad), encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema",
                        "vendor.gitlab-ci", str(tmp_path / "bad.json")], capture_output=True)
    assert r.returncode == 1


@pytest.mark.parametrize("images, limit, code, failures", [
    ("good", "3", 0, 0), ("good bad", "3", 1, 1), ("good", "0.1", 1, 1)])
def test_gitlab_component_gates_and_leaves_the_reports(renders, tmp_path, images, limit,
                                                        code, failures):
    _, job = _component_job(images=" ".join(str(renders[i]) for i in images.split()),
                            **{"max-delta-e": limit, "report-dir": "out/colour"})
    r = _run_component_script(job, tmp_path)
    assert r.returncode == code, r.stderr
    junit = tmp_path / job["artifacts"]["reports"]["junit"]
    root = _valid_junit(junit)
    assert sum(int(suite.get("failures")) for suite in root.iter("testsuite")) == failures
    n = len(images.split())
    assert len(list((tmp_path / "out" / "colour").glob("*.html"))) == n + (n > 1)  # + index
    assert job["artifacts"]["paths"] == ["out/colour/"]


def test_gitlab_component_installs_the_package_input_and_qualifies_first(renders, tmp_path):
    """The install line installs what the package input names; qualify "true" files the
    qualification before gating, and a failed qualification is the job's exit code with no
    gate run."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "pip-args"
    (bin_dir / "python").write_text(f'#!/bin/sh\necho "$@" > {log}\n')
    (bin_dir / "python").chmod(0o755)
    _, job = _component_job(package="camera-fidelity==0.1.0")
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}",
           **{k: str(v) for k, v in job["variables"].items()}}
    subprocess.run(["bash", "-eo", "pipefail", "-c", job["script"][0]], env=env, check=True)
    assert log.read_text().split()[-1] == "camera-fidelity==0.1.0"

    # a stand-in fidelity that logs its calls (the real qualification runs in the Action's
    # test): qualify first, with its record in report-dir; then the gate, or not at all
    _, job = _component_job(images=str(renders["good"]), qualify="true",
                            **{"max-delta-e": "3"})
    calls = tmp_path / "calls"
    for qualified, code, ran in ((0, 0, ["qualify", "gate"]), (1, 1, ["qualify"])):
        calls.unlink(missing_ok=True)
        (bin_dir / "fidelity").write_text(f'#!/bin/sh\necho "$@" >> {calls}\n'
                                          f'[ "$1" = qualify ] && exit {qualified}\nexit 0\n')
        (bin_dir / "fidelity").chmod(0o755)
        r = _run_component_script(job, tmp_path, path=str(bin_dir))
        assert r.returncode == code, r.stderr
        lines = calls.read_text().splitlines()
        assert [line.split()[0] for line in lines] == ran
        assert lines[0] == "qualify --json fidelity-report/qualification.json"


@pytest.mark.parametrize("args, code", [("--decision guarded", 4),
                                        ("--decision guarded --strict", 1)])
def test_gitlab_component_lets_an_undecided_verdict_pass_with_a_warning(renders, tmp_path,
                                                                        args, code):
    """A limit inside the guard band (the good render's mean ΔE00 is about 1.005, U about
    0.03): exit 4, which the job allows (a warning in the pipeline); --strict makes it 1."""
    _, job = _component_job(images=str(renders["good"]), args=args, **{"max-delta-e": "1.0"})
    r = _run_component_script(job, tmp_path)
    assert r.returncode == code, r.stdout + r.stderr
    assert (code in job["allow_failure"]["exit_codes"]) == (code == 4)


def test_a_value_with_a_space_reaches_the_gate_through_the_project_settings(renders, tmp_path):
    """The Action's args are split at spaces; an OpenColorIO colourspace with one in it comes
    from the caller's [tool.fidelity] settings, which the gate step reads."""
    pytest.importorskip("PyOpenColorIO", reason="pip install 'camera-fidelity[ocio]'")
    caller = tmp_path / "caller"
    caller.mkdir()
    (caller / "pyproject.toml").write_text(
        '[tool.fidelity]\nocio_colourspace = "sRGB - Display"\n', encoding="utf-8")
    env = {**os.environ, "FIDELITY_IMAGES": str(renders["good"]), "FIDELITY_CAMERA": "",
           "FIDELITY_MAX_DELTA_E": "3", "FIDELITY_MAX_DMAP": "", "FIDELITY_ARGS": "",
           "FIDELITY_REPORT_DIR": str(tmp_path / "reports"),
           "GITHUB_OUTPUT": str(tmp_path / "github_output")}
    r = subprocess.run(["bash", "-c", _gate_script()], env=env, capture_output=True, text=True,
                       cwd=caller)
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "reports" / "report.json").read_text())
    assert doc["source"]["ocio"]["colourspace"] == "sRGB - Display"
