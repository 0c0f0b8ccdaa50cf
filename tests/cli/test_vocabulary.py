"""The command line as a whole: one vocabulary, the help listing, settings files, stdout JSON."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import click
import pytest
from click.testing import CliRunner

from fidelity.cli import COMMANDS, main

#: Flags that were renamed for one vocabulary; none may come back.
RETIRED = {"--transform", "--model", "--no-progress"}


def _command(name: str) -> click.Command:
    command = main.get_command(click.Context(main), name)
    assert command is not None
    return command


def _flags(command: click.Command) -> set[str]:
    return {o for p in command.params for o in p.opts}


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_speaks_the_one_vocabulary(name):
    command = _command(name)
    flags = _flags(command)
    assert {"-q", "--quiet", "-v", "--verbose"} <= flags, name
    assert not flags & RETIRED, name
    # a chart's measured ΔE is --delta-e; a transform's ΔE is --targets
    assert "--delta-e" not in flags or name == "predict"
    # the listing in `fidelity --help` is the command's own first line
    assert COMMANDS[name][1] == command.get_short_help_str(limit=500), name
    images = next((p for p in command.params if "--images" in p.opts), None)
    if images is not None:  # always a folder
        assert isinstance(images.type, click.Path) and not images.type.file_okay, name


def test_fit_offers_no_sim_colourspace_it_would_refuse():
    """fit refuses --sim-ocio-colourspace (its cube maps SIM's own pixel values): its help does
    not list it (issue 57), compare's does; REAL's is offered by both."""
    helps = {name: CliRunner().invoke(main, [name, "--help"], terminal_width=200).stdout
             for name in ("fit", "compare")}
    assert "--sim-ocio-colourspace" not in helps["fit"]
    assert "--sim-ocio-colourspace" in helps["compare"]
    assert all("--real-ocio-colourspace" in h for h in helps.values())


def test_help_imports_no_command_module():
    code = ("import sys; from fidelity.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith('fidelity.cli.') or m in "
            "('numpy', 'scipy', 'matplotlib', 'colour')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_json_dash_writes_only_json_to_stdout(tmp_path):
    r = CliRunner().invoke(main, ["predict", "--delta-e", "3", "--json", "-"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)  # nothing but the JSON on stdout
    assert doc["delta_e"] == 3.0 and not (tmp_path / "-").exists()
    r = CliRunner().invoke(main, ["check", "--camera", "ideal", "--out", str(tmp_path / "o"),
                                  "--json", "-"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["source"]["camera"] == "ideal"
    assert not (tmp_path / "o" / "report.json").exists()
    assert (tmp_path / "o" / "report.html").is_file()


def test_quiet_prints_nothing_but_errors(tmp_path):
    r = CliRunner().invoke(main, ["check", "--camera", "ideal", "-q", "--out", str(tmp_path)])
    assert r.exit_code == 0 and r.stdout == ""
    r = CliRunner().invoke(main, ["predict", "--delta-e", "-1", "-q"])
    assert r.exit_code == 2 and r.stdout == "" and r.stderr.startswith("fidelity: error:")


@pytest.mark.parametrize("value", ["-1", "nan", "1e400", "-inf"])
def test_predict_names_the_flag_of_a_bad_delta_e(value):
    r = CliRunner().invoke(main, ["predict", f"--delta-e={value}"])
    assert r.exit_code == 2 and r.stdout == ""
    assert r.stderr.startswith("fidelity: error: --delta-e ") and r.stderr.count("\n") == 1


def _settings(folder: Path, text: str, name: str = "pyproject.toml") -> None:
    (folder / name).write_text(text, encoding="utf-8")


def test_settings_file_sets_defaults_and_the_command_line_wins(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _settings(tmp_path, '[project]\nname = "sim"\n\n[tool.fidelity]\ncamera = "ideal"\n'
                        'max_delta_e = 0.5\n\n[tool.fidelity.check]\nout = "reports"\n')
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "sub")  # found from a folder below
    def report(folder: Path) -> dict:
        return json.loads((folder / "report.json").read_text())

    r = CliRunner().invoke(main, ["check"])
    assert r.exit_code == 0, r.output
    doc = report(tmp_path / "reports")  # relative to the settings file
    assert doc["source"]["camera"] == "ideal"
    assert doc["verdict"]["criterion"]["kind"] == "max-delta-e"
    assert doc["verdict"]["limit"] == 0.5 and doc["verdict"]["passed"] is True
    r = CliRunner().invoke(main, ["check", "--max-delta-e", "0.0001", "--out", "x"])
    assert r.exit_code == 1, r.output
    verdict = report(tmp_path / "sub" / "x")["verdict"]
    assert (verdict["limit"], verdict["passed"], verdict["reason"]) == (0.0001, False,
                                                                        "over-limit")
    assert verdict["value"] > 0.0001
    r = CliRunner().invoke(main, ["--no-config", "check", "--out", "y"])
    assert report(tmp_path / "sub" / "y")["source"]["camera"] == "nikon-5100"


@pytest.mark.parametrize("text, where", [
    ("max_delta_e = 'x'\n", ": max_delta_e: "),
    ("max_delta = 3\n", ": max_delta: "),
    ("[nosuch]\ncamera = 'ideal'\n", ": nosuch: "),
    ("[gate]\nmax_dmap = true\n", ": gate.max_dmap: "),
    ("camera = \n", "fidelity.toml: "),  # not TOML: no key to name, the file is named
])
def test_a_bad_settings_file_is_one_line_naming_file_and_key(tmp_path, monkeypatch, text, where):
    monkeypatch.chdir(tmp_path)
    _settings(tmp_path, text, "fidelity.toml")
    r = CliRunner().invoke(main, ["predict", "--delta-e", "1"])
    assert r.exit_code == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(tmp_path / "fidelity.toml") in lines[0] and where in lines[0]


def test_a_ci_line_shrinks_to_gate_image(tmp_path, monkeypatch):
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_png

    monkeypatch.chdir(tmp_path)
    write_png(tmp_path / "render.png", render_chart("nikon-5100").display_image, 16)
    _settings(tmp_path, "camera = 'nikon-5100'\nmax_delta_e = 3\n"
                        "[gate]\njunit = 'colour.xml'\n", "fidelity.toml")
    def junit() -> tuple[str, dict[str, str]]:
        """The JUnit file's failure count and its recorded properties."""
        root = ElementTree.parse(tmp_path / "colour.xml").getroot()
        props = {p.get("name"): p.get("value") for p in root.iter("property")}
        return root.get("failures"), props

    r = CliRunner().invoke(main, ["gate", "render.png"])  # the image wins over the camera
    assert r.exit_code == 0, r.output
    failures, props = junit()
    assert failures == "0" and props["criterion"] == "max-delta-e"
    assert float(props["limit"]) == 3.0 and float(props["mean_delta_e"]) <= 3.0
    r = CliRunner().invoke(main, ["gate", "render.png", "--max-dmap", "0.01"])
    assert r.exit_code == 1, r.output
    failures, props = junit()  # --max-dmap replaces the ΔE gate
    assert failures == "1" and props["criterion"] == "max-dmap"
    assert float(props["limit"]) == 0.01
    # the verdict's value: the colour, sharpness and noise losses combined (their sum)
    assert float(props["value"]) == pytest.approx(float(props["combined_dmap_points"]))
    judged = [float(props[f"{k}_dmap_points"]) for k in ("sharpness", "noise")
              if f"{k}_not_judged" not in props]
    assert float(props["value"]) == pytest.approx(float(props["dmap_points"]) + sum(judged))
    assert float(props["value"]) > 0.01


def test_the_light_core_gates_an_exr_without_the_extras(tmp_path):
    """The core install (no [render], no [coco]) renders in closed form, audits and gates an
    EXR: run with Mitsuba, onnxruntime and the COCO scorers made unimportable."""
    r = CliRunner().invoke(main, ["render", "--camera", "ideal", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    exr = tmp_path / "raw_camera.exr"
    blocked = ("mitsuba", "drjit", "onnxruntime", "pycocotools", "faster_coco_eval", "ray")
    code = ("import sys\n"
            f"for m in {blocked!r}:\n    sys.modules[m] = None  # import fails\n"
            "from fidelity.cli import main\n"
            f"main(['gate', {str(exr)!r}, '--max-delta-e', '1', '--json', '-'])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["verdict"]["passed"] and doc["mean_delta_e"] < 1
