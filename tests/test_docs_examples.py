"""What the documentation promises, run as written (issue 31): the pytest plugin's snippet of
docs/ci.md (under pytest's default JUnit family, with no warning), every command's ``--help``,
the shell commands and Python snippets of README.md and docs/*.md that run offline against real
inputs, the pre-commit hook through ``pre-commit try-repo``, and every command saying which
settings file it read."""

from __future__ import annotations

import importlib.util
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
from click.testing import CliRunner

from fidelity.cli import COMMANDS, main

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("FIDELITY_SHARED", REPO.parent / "shared"))


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO))


def _python_block(page: str, heading: str) -> str:
    """The first ```python block after ``heading`` in ``page``."""
    text = (REPO / page).read_text(encoding="utf-8")
    tail = text[text.index(heading):]
    block = re.search(r"```python\n(.*?)```", tail, re.S)
    assert block, f"{page}: no python block after {heading!r}"
    return block.group(1)


def _studio_photo(path: Path, corners: str) -> None:
    """A JPEG of the chart (the safecolor reference colours) whose corner patches' centres lie
    at ``corners`` (dark skin, bluish green, black, white), on a dark background."""
    import cv2

    from fidelity.colour.charts import load_reference

    srgb = load_reference("safecolor").srgb
    pts = np.array([float(v) for v in corners.split(",")]).reshape(4, 2)
    grid = np.array([[0, 0], [5, 0], [5, 3], [0, 3]], np.float64)
    h = cv2.getPerspectiveTransform(grid.astype(np.float32), pts.astype(np.float32))
    height, width = 520, 720
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    uvw = np.linalg.inv(h) @ np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)])
    u, v = uvw[0] / uvw[2], uvw[1] / uvw[2]
    col, row = np.rint(u), np.rint(v)
    inside = ((np.abs(u - col) <= 0.42) & (np.abs(v - row) <= 0.42) & (col >= 0) & (col <= 5)
              & (row >= 0) & (row <= 3))
    img = np.full((xx.size, 3), 0.06)
    img[inside] = srgb[(row[inside] * 6 + col[inside]).astype(int)]
    bgr = np.rint(np.clip(img.reshape(height, width, 3), 0, 1) * 255).astype(np.uint8)[..., ::-1]
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), bgr, [cv2.IMWRITE_JPEG_QUALITY, 97])


def _day_render(path: Path) -> None:
    """A linear EXR of the default camera's developed chart render."""
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_exr
    from fidelity.colour.colorimetry import linearize_srgb

    path.parent.mkdir(parents=True, exist_ok=True)
    write_exr(path, np.asarray(linearize_srgb(render_chart("nikon-5100").display_image),
                               np.float32))


@pytest.fixture(scope="module")
def plugin_inputs(tmp_path_factory) -> tuple[Path, str]:
    """The folder holding the files docs/ci.md's plugin snippet names, and the snippet."""
    snippet = _python_block("docs/ci.md", "## pytest plugin")
    folder = tmp_path_factory.mktemp("sim")
    exr = re.search(r'colour_fidelity\("([^"]+\.exr)"\)', snippet).group(1)
    jpg = re.search(r'colour_fidelity\("([^"]+\.jpg)"\)', snippet).group(1)
    corners = re.search(r'corners="([0-9,]+)"', snippet).group(1)
    _day_render(folder / exr)
    _studio_photo(folder / jpg, corners)
    return folder, snippet


def _properties(xml: Path) -> tuple[dict[str, str], dict[str, str]]:
    """(the suite's properties, every test case's) of a JUnit file, name -> value."""
    root = ET.parse(xml).getroot()
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    own = suite.find("properties")
    suite_props = {p.get("name"): p.get("value") for p in own} if own is not None else {}
    case_props = {p.get("name"): p.get("value") for case in suite.iter("testcase")
                  for p in case.iter("property")}
    return suite_props, case_props


def test_pytest_plugin_snippet_runs_as_written_without_a_warning(plugin_inputs, pytester):
    folder, snippet = plugin_inputs
    for f in folder.iterdir():
        shutil.copytree(f, pytester.path / f.name) if f.is_dir() else shutil.copy(f, pytester.path)
    pytester.makepyfile(test_doc=snippet)
    # pytest's default junit_family is xunit2; a warning of the plugin is an error here
    # (in a fresh process: pytester's in-process run drops the modules it imported, and
    # numpy's extension modules load once per process)
    result = pytester.runpytest_subprocess("--junitxml=out.xml", "-W",
                                           "error::pytest.PytestWarning")
    result.assert_outcomes(passed=2)
    assert "PytestWarning" not in result.stdout.str()
    suite, cases = _properties(pytester.path / "out.xml")
    assert not cases  # xunit2 has no properties on test cases
    day = float(suite["test_doc.py::test_day_render_keeps_colour:renders/day.exr:mean_delta_e"])
    assert 0 < day <= 3
    assert "test_doc.py::test_studio_photo:photos/studio.jpg:dmap_points" in suite
    # under xunit1 the same values are the test cases' own properties
    # (a second run in a fresh process: numpy's extension modules load once per process)
    result = pytester.runpytest_subprocess("--junitxml=out1.xml", "-o", "junit_family=xunit1",
                                           "-W", "error::pytest.PytestWarning")
    result.assert_outcomes(passed=2)
    suite, cases = _properties(pytester.path / "out1.xml")
    assert float(cases["renders/day.exr:mean_delta_e"]) == pytest.approx(day)
    assert not any(k.endswith("mean_delta_e") for k in suite)


# ------------------------------------------------------------------ help and documented examples

def test_every_command_help_and_its_examples_parse():
    """``fidelity --help`` and every command's ``--help`` print and exit 0; every example line
    a command's help shows (``fidelity NAME ...``) names that command and only its options."""
    top = CliRunner().invoke(main, ["--help"])
    assert top.exit_code == 0 and all(name in top.output for name in COMMANDS)
    # the check below can fail
    assert _unknown_options(["fidelity", "check", "--bogus", "--camera", "x"]) == ["--bogus"]
    assert _unknown_options(["fidelity", "chekc"]) == ["command chekc"]
    examples = 0
    for name in COMMANDS:
        r = CliRunner().invoke(main, [name, "--help"])
        assert r.exit_code == 0, (name, r.output)
        assert f"{name} [OPTIONS]" in r.output.splitlines()[0], name
        for line in re.sub(r"\\\n\s*", " ", r.output).splitlines():
            text = line.strip()
            if text.startswith(f"fidelity {name}"):
                assert _unknown_options(shlex.split(text, comments=True)) == [], (name, text)
                examples += 1
    assert examples >= 10


#: Every command's options (all spellings), and the top-level ones.
def _options(name: str | None) -> set[str]:
    import click

    cmd = main if name is None else main.get_command(click.Context(main), name)
    assert cmd is not None, name
    opts = {"--help", "-h"}
    for p in cmd.params:
        opts |= set(p.opts) | set(p.secondary_opts)
    return opts


def _unknown_options(argv: list[str]) -> list[str]:
    """The options of a ``fidelity ...`` command line its command does not have (an unknown
    command is reported as such)."""
    assert argv[0] == "fidelity"
    args = argv[1:]
    top = _options(None)
    while args and args[0].startswith("-"):
        if args[0] not in top:
            return [args[0]]
        args = args[1 + (args[0] == "--config"):]
    if not args or args[0] not in COMMANDS:
        return [f"command {args[0] if args else '(none)'}"]
    known = _options(args[0])
    return [a.split("=", 1)[0] for a in args[1:]
            if a.startswith("-") and a not in ("-",) and a.split("=", 1)[0] not in known
            and not re.fullmatch(r"-?\d[\d.,-]*", a)]


def _doc_pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def doc_commands() -> list[tuple[str, str]]:
    """(page, command line) of every ``fidelity ...`` line in the shell blocks of README.md and
    docs/*.md (``$ fidelity`` lines of text and console blocks), continuation lines joined,
    comments dropped."""
    out = []
    for page in _doc_pages():
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S):
            lang, body = m.group(1), m.group(2).replace("\\\n", " ")
            for line in body.splitlines():
                s = line.strip()
                if lang in ("text", "console"):
                    if not s.startswith("$ fidelity "):
                        continue
                    s = s[2:]
                elif lang not in ("sh", "bash", "shell") or not s.startswith(
                        "fidelity "):
                    continue
                out.append((page.relative_to(REPO).as_posix(), " ".join(s.split())))
    return out


DOC_COMMANDS = doc_commands()

#: Commands that run detectors over COCO for minutes (their own tests run them on a few
#: images: tests/coco/test_sweep.py, test_evaluate.py, test_validate.py, ...).
LONG_COMMANDS = {"sweep", "evaluate", "dataset", "coco-c", "validate"}
#: Placeholders a documented line uses for "your own" values.
PLACEHOLDERS = ("...", "DIR", "STORE", "HEAD", "[")
#: Options whose value is written, not read.
OUTPUTS = {"--out", "--json", "--html", "--junit", "--csv", "--markdown", "--notes-out",
           "--prediction", "--directional", "--evidence", "--export-scores", "--data",
           "--write-corrected", "--sharpness", "--noise"}


def test_the_docs_have_commands_to_run():
    pages = {p for p, _ in DOC_COMMANDS}
    assert {"README.md", "docs/check.md", "docs/audit.md", "docs/compare.md",
            "docs/predict.md"} <= pages
    assert len(DOC_COMMANDS) >= 40


@pytest.mark.parametrize("page,line", DOC_COMMANDS)
def test_documented_command_names_real_options(page, line):
    argv = shlex.split(line, comments=True)
    argv = [a for a in argv if a != "\\"]
    bad = [u for u in _unknown_options(argv) if u not in PLACEHOLDERS and "[" not in u]
    assert not bad, f"{page}: `{line}` uses {bad}"


def _layered_exr(path: Path, layer: str) -> None:
    """Rewrite the EXR at ``path`` with its R, G, B as the channels of ``layer`` and a
    ``depth`` channel beside them, as a renderer writes its passes."""
    import OpenEXR

    from fidelity.chart.image import read_image

    px = np.asarray(read_image(path).pixels, np.float32)
    channels = {f"{layer}.{c}": np.ascontiguousarray(px[..., i]) for i, c in enumerate("RGB")}
    channels["depth.Z"] = np.ones(px.shape[:2], np.float32)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, channels).write(str(path))


def _scene_render(path: Path) -> None:
    """What a simulator renders of the default chart scene (``fidelity scene``), in closed
    form (:func:`tests.fixtures.chart_scenes.closed_form_render`)."""
    from fidelity.chart.image import write_exr
    from fidelity.scene.model import build_scene
    from tests.fixtures.chart_scenes import closed_form_render

    write_exr(path, closed_form_render(build_scene("D65")).astype(np.float32))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory, plugin_inputs) -> Path:
    """A folder holding the files the documented commands read, under the names they use:
    renders and photos of the chart (found by the audit), cameras, settings."""
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_png

    ws = tmp_path_factory.mktemp("docs")
    sim, _ = plugin_inputs
    exr = sim / "renders" / "day.exr"
    shutil.copy(exr, ws / "sim.exr")
    # a simulator's renders of the exported chart scene (closed form, the default export's
    # geometry), with the exports beside them, as the gate's --manifest examples name them
    scene_render = ws / "render.exr"
    _scene_render(scene_render)
    for name in ("day.exr", "dusk.exr", "tunnel.exr",
                 "renders/day.exr", "renders/dusk.exr", "renders/tunnel.exr"):
        (ws / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(scene_render, ws / name)
    from fidelity.scene.export import export_scene
    from fidelity.scene.model import build_scene

    for folder in ("chart", "chart-gltf"):
        export_scene(build_scene("D65"), "gltf", ws / folder)
    photo = sim / "photos" / "studio.jpg"
    for name in ("photo.jpg", "photos/studio.jpg"):
        (ws / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(photo, ws / name)
    import cv2

    cv2.imwrite(str(ws / "photo.png"), cv2.imread(str(photo)))
    for name, camera in (("nikon.png", "nikon-5100"), ("render.png", "nikon-5100"),
                         ("sim.png", "nikon-5100"),
                         ("sigma.png", "sigma-sdmerrill")):
        # as `fidelity render --out` writes its developed.png: at the camera's own bit depth
        rendered = render_chart(camera)
        write_png(ws / name, rendered.display_image, rendered.camera.quantisation_bits or 16)
    if (SHARED / "coco" / "val2017").is_dir():  # docs/find_chart.md's example: the benchmark's
        from tests.fixtures.chart_photos import generate, scene_specs  # image 0, made here

        made = generate(scene_specs(False)[:1], SHARED / "coco" / "val2017", ws / "scenes", 19)
        shutil.copy(made[0]["path"], ws / "scene_000.jpg")
    shutil.copytree(REPO / "cameras", ws / "cameras")
    for name in ("my.toml", "my-camera.toml", "cameras/my-camera.toml"):
        shutil.copy(REPO / "cameras" / "nikon5100-gamma22.toml", ws / name)
    return ws


def _skip_reason(argv: list[str], ws: Path) -> str | None:
    """Why a documented command is not run here, or None."""
    if argv[1] in LONG_COMMANDS or "--measure" in argv:
        return "runs detectors over COCO for minutes (tested on a few images elsewhere)"
    if any(p in a for a in argv for p in PLACEHOLDERS):
        return "a placeholder stands for the user's own value"
    if any(a.startswith("$") for a in argv):
        return "needs the shared COCO data"
    if "mitsuba" in argv:
        try:
            import mitsuba  # noqa: F401
        except ImportError:
            return "Mitsuba is not installed"
    if any(a.split(":")[0] in ("gaussian_noise", "shot_noise", "defocus_blur", "gaussian_blur")
           for a in argv):
        if importlib.util.find_spec("imagecorruptions") is None:  # found, not imported
            return "imagecorruptions is not installed (the noise and blur corruptions)"
    for i, a in enumerate(argv[2:], start=2):
        if a.startswith("-") or argv[i - 1] in OUTPUTS:
            continue
        looks_like_file = "/" in a or re.search(r"\.(exr|png|jpg|jpeg|tiff?|json|csv|toml|md|"
                                                 r"onnx|gz|mp4|mkv|mov|avi|webm|m4v)$", a)
        if looks_like_file and not (ws / a).exists() and not (REPO / a).exists():
            return f"needs {a}, which the docs mean as the user's own file"
    return None


@pytest.mark.slow
@pytest.mark.parametrize("page,line", DOC_COMMANDS)
def test_documented_command_runs(page, line, workspace, monkeypatch):
    """Every documented command whose inputs exist runs: exit 0 (pass) or 1 (a failed
    verdict), never 2 (an input it refuses) or 3."""
    argv = [a for a in shlex.split(line, comments=True) if a != "\\"]
    reason = _skip_reason(argv, workspace)
    if reason:
        pytest.skip(reason)
    # a shipped file the docs name as an input (fidelity/data/..., cameras/...) is read from
    # the checkout; every output stays in the scratch folder (never the checkout's files)
    args = [a if (workspace / a).exists() or not (REPO / a).is_file() or argv[i] in OUTPUTS
            else str(REPO / a) for i, a in enumerate(argv[1:])]
    folder, config = workspace, ["--no-config"]
    settings = _settings_block(page)
    if settings is not None:  # the page's commands read the settings file it shows
        folder, config = workspace / "with-settings", []
        folder.mkdir(exist_ok=True)
        (folder / "pyproject.toml").write_text(settings, encoding="utf-8")
        for rel in re.findall(r'= "([^"]+\.toml)"', settings):
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(REPO / "cameras" / "nikon5100-gamma22.toml", folder / rel)
        for f in workspace.iterdir():
            if f.is_file():
                shutil.copy(f, folder / f.name)
    r = subprocess.run([sys.executable, "-m", "fidelity", *config, *args], cwd=folder,
                       env=_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode in (0, 1), (f"{page}: `{line}` exited {r.returncode}: "
                                    f"{(r.stdout + r.stderr)[-800:]}")


def doc_outputs() -> list[tuple[str, str, tuple[str, ...]]]:
    """(page, command, printed lines) of every ```text block of README.md and docs/*.md that
    shows one ``$ fidelity ...`` command and what it printed."""
    out = []
    for page in _doc_pages():
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"```text\n\$ (fidelity [^\n]*)\n(.*?)```", text, re.S):
            command, printed = m.group(1), m.group(2).rstrip("\n").split("\n")
            while command.endswith("\\") and printed:  # a command continued on the next line
                command = command[:-1] + " " + printed.pop(0).strip()
            out.append((page.relative_to(REPO).as_posix(), command, tuple(printed)))
    return out


DOC_OUTPUTS = doc_outputs()


def test_the_docs_show_outputs_to_compare():
    runnable = [(p, c) for p, c, _ in DOC_OUTPUTS if c == "fidelity check"]
    assert len(DOC_OUTPUTS) >= 5 and len(runnable) >= 3, DOC_OUTPUTS


@pytest.mark.slow
@pytest.mark.parametrize("page,line,printed", DOC_OUTPUTS, ids=lambda v: str(v)[:40])
def test_documented_output_is_what_the_command_prints(page, line, printed, workspace):
    """A documented run shows what the command prints today, line for line: an example
    whose numbers the code no longer gives (after a table is re-measured, say) fails here."""
    argv = [a for a in shlex.split(line, comments=True) if a != "\\"]
    reason = _skip_reason(argv, workspace)
    if reason:
        pytest.skip(reason)
    if any(p.strip() in ("...", "…") for p in printed):
        pytest.skip("an excerpt of what the command prints")
    args = [a if (workspace / a).exists() or not (REPO / a).is_file() or argv[i] in OUTPUTS
            else str(REPO / a) for i, a in enumerate(argv[1:])]
    r = subprocess.run([sys.executable, "-m", "fidelity", "--no-config", *args],
                       cwd=workspace, env=_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode in (0, 1), (r.stdout + r.stderr)[-800:]
    now = tuple(_steady(x) for x in r.stdout.rstrip("\n").split("\n"))
    assert now == tuple(_steady(x) for x in printed), \
        f"{page}: `{line}` now prints:\n{r.stdout}"


#: What a documented run prints that changes from run to run of the same command: when it ran
#: (UTC), the folders its files lie in (the scratch folder, the checkout), from which commit
#: and code, and the digests of files written at run time. Compared as these placeholders.
_VOLATILE = ((re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ"), "<time>"),
             (re.compile(r"(?<![\w.<>])/(?:[^\s/]+/)+"), "<folder>/"),
             (re.compile(r"\([0-9a-f]{7,40}(?:[ ,][^)]*)?\)"), "(<commit>)"),
             (re.compile(r"SHA-256 [0-9a-f]{12}\b"), "SHA-256 <digest>"))


def _steady(line: str) -> str:
    """``line`` with its :data:`_VOLATILE` parts replaced."""
    for pattern, placeholder in _VOLATILE:
        line = pattern.sub(placeholder, line)
    return line


def _settings_block(page: str) -> str | None:
    """The ``[tool.fidelity]`` settings a page shows (its first such toml block), if any."""
    text = (REPO / page).read_text(encoding="utf-8")
    m = re.search(r"```toml\n(\[tool\.fidelity\].*?)```", text, re.S)
    return m.group(1) if m else None


def doc_snippets() -> list[tuple[str, int, str]]:
    """(page, number, code) of every ```python block of README.md and docs/*.md."""
    out = []
    for page in _doc_pages():
        text = page.read_text(encoding="utf-8")
        for k, m in enumerate(re.finditer(r"```python\n(.*?)```", text, re.S)):
            out.append((page.relative_to(REPO).as_posix(), k, m.group(1)))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("page,k,code", doc_snippets(), ids=lambda v: str(v)[:30])
def test_documented_python_snippet_runs(page, k, code, workspace, tmp_path):
    if "def test_" in code:
        pytest.skip("a pytest module: run by test_pytest_plugin_snippet_runs_as_written_...")
    names = re.findall(r'"([^"\s]+)"', code)
    for name in names:
        if re.fullmatch(r"[A-Z]{3,}", name):
            pytest.skip(f"{name} is a placeholder for the user's own sweep store")
        if name.endswith((".bag", ".mcap", ".db3", ".mp4", ".mkv", ".mov")):
            pytest.skip(f"{name} stands for the user's own recording (recordings are read in "
                        "tests/chart/test_recording.py)")
    # the report snippets rewrite the recorded results of the checkout: run on copies
    for rel in re.findall(r'Path\("([^"]+)"\)', code):
        src = REPO / rel
        if not src.exists():
            pytest.skip(f"needs {rel}, made by a COCO run")
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src, tmp_path / rel)
    for f in workspace.iterdir():
        if f.is_file():
            shutil.copy(f, tmp_path / f.name)
    layer = re.search(r'layer="(\w+)"', code)
    if layer:  # the EXR it reads has that layer (a renderer's AOVs)
        _layered_exr(tmp_path / "render.exr", layer.group(1))
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(),
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"{page} block {k}: {r.stderr[-1500:]}"


# ------------------------------------------------------------------ the pre-commit hook

@pytest.mark.slow
def test_pre_commit_try_repo_runs_the_hook_of_this_checkout(tmp_path):
    """``pre-commit try-repo`` on this checkout, as a simulator repository would use the hook:
    pre-commit builds the hook's environment from the checkout (offline here: the virtualenv
    sees the installed dependencies, pip uses no index), then gates the changed camera files:
    exit 1 when one fails, 0 when all pass."""
    if shutil.which("pre-commit") is None or shutil.which("git") is None:
        pytest.skip("pre-commit or git is not installed")
    pytest.importorskip("hatchling", reason="the build backend is needed to install the "
                                            "checkout offline (pip install hatchling)")
    repo = tmp_path / "sim"
    (repo / "cameras").mkdir(parents=True)
    for name in ("ideal-srgb8.toml", "bad-oversaturated.toml"):
        shutil.copy(REPO / "cameras" / name, repo / "cameras" / name)
    (repo / "notes.md").write_text("not a camera\n")
    git = ["git", "-c", "user.email=ci@example.com", "-c", "user.name=ci"]
    subprocess.run(["git", "init", "-q"], cwd=repo, check=True)
    subprocess.run(["git", "add", "-A"], cwd=repo, check=True)
    subprocess.run([*git, "commit", "-qm", "cameras"], cwd=repo, check=True)
    env = dict(os.environ, PRE_COMMIT_HOME=str(tmp_path / "pc-home"),
               VIRTUALENV_SYSTEM_SITE_PACKAGES="1", PIP_NO_INDEX="1",
               PIP_NO_BUILD_ISOLATION="0")
    env.pop("PYTHONPATH", None)  # the hook runs the code pre-commit installed from REPO

    def try_repo(*files: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["pre-commit", "try-repo", str(REPO), "fidelity-camera",
                               "--files", *files], cwd=repo, env=env, capture_output=True,
                              text=True, timeout=900)

    both = try_repo("cameras/ideal-srgb8.toml", "cameras/bad-oversaturated.toml", "notes.md")
    out = both.stdout + both.stderr
    if "Installing environment" in out and "error" in out.lower() and "FAIL" not in out:
        pytest.skip(f"pre-commit could not build the hook's environment offline: {out[-500:]}")
    assert both.returncode == 1, out[-2000:]
    assert "FAIL: mean ΔE00" in out and "PASS: mean ΔE00" in out
    assert "notes.md" not in out  # not a camera file: the hook's `files` pattern leaves it
    good = try_repo("cameras/ideal-srgb8.toml")
    assert good.returncode == 0, (good.stdout + good.stderr)[-2000:]
    assert not (repo / "fidelity-report").exists()  # a hook writes no reports


# ------------------------------------------------------------------ settings said

def test_every_command_says_which_settings_file_it_read(tmp_path, monkeypatch):
    import json

    settings = tmp_path / "fidelity.toml"
    settings.write_text('camera = "ideal"\nmax_delta_e = 2.5\n[gate]\njunit = "j.xml"\n')
    monkeypatch.chdir(tmp_path)

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "fidelity", *args], cwd=tmp_path,
                              env=_env(), capture_output=True, text=True, timeout=300)

    r = run("check", "--no-report")
    assert r.returncode == 0, r.stderr
    first = r.stdout.splitlines()[0]
    # the file, and the options it set (by their flags); the camera it set is the one checked
    assert str(settings) in first and "--camera" in first and "--max-delta-e" in first
    assert "camera ideal" in r.stdout and "<= 2.5" in r.stdout
    r = run("predict", "--delta-e", "3")
    assert str(settings) in r.stdout.splitlines()[0] and "--" not in r.stdout.splitlines()[0]
    # a command's own table: gate's junit
    r = run("gate", "--camera", "nikon-5100")
    assert r.returncode in (0, 1) and "--junit" in r.stdout.splitlines()[0], r.stderr
    assert (tmp_path / "j.xml").is_file()
    # with --json - it goes to stderr, with -q nowhere, with --no-config there is none
    r = run("predict", "--delta-e", "3", "--json", "-")
    assert json.loads(r.stdout)["delta_e"] == 3.0 and str(settings) in r.stderr
    r = run("check", "--no-report", "-q")
    assert str(settings) not in r.stdout + r.stderr
    r = run("--no-config", "check", "--no-report")
    assert str(settings) not in r.stdout and "camera nikon-5100" in r.stdout
    # every command prints it through the options they all share (-q/-v)
    for name in COMMANDS:
        import click

        cmd = main.get_command(click.Context(main), name)
        assert {"-q", "-v"} <= {o for p in cmd.params for o in p.opts}, name


def test_audit_writes_into_a_new_folder_named_with_a_trailing_slash(plugin_inputs, tmp_path):
    """docs/audit.md: ``--json out/ --html out/`` writes out/IMAGE.json and out/IMAGE.html
    although out/ does not exist yet; without the slash ``out`` is one file, and naming it
    for both outputs is refused."""
    sim, _ = plugin_inputs
    image = sim / "renders" / "day.exr"
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["--no-config", "audit", str(image), "--json", f"{out}/",
                                  "--html", f"{out}/"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["day.exr.html", "day.exr.json"]
    r = CliRunner().invoke(main, ["--no-config", "audit", str(image), "--json",
                                  str(tmp_path / "x"), "--html", str(tmp_path / "x")])
    assert r.exit_code == 2 and "--json" in r.output and "--html" in r.output
