"""Fuzz: the documents fidelity reads — camera files (TOML, YAML), prediction tables, chart
files and settings — changed field by field (wrong types, missing and unknown fields, NaN, huge
numbers, deep nesting) or damaged byte by byte."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzzkit import (
    CAMERA,
    FAST,
    LONG,
    assert_promise,
    budget,
    damaged_bytes,
    fingerprint,
    json_text,
    mutated,
    run,
    toml_text,
)

EXAMPLES = [FAST, pytest.param(LONG, marks=pytest.mark.fuzz)]


def _camera_file(folder: Path, doc: Any, fmt: str) -> Path | None:
    if fmt == "toml":
        text = toml_text(doc)
        if text is None:
            return None
        path = folder / "camera.toml"
        path.write_text(text, encoding="utf-8")
    else:
        path = folder / "camera.yaml"
        path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return path


def _render_promise(camera: Path, folder: Path) -> None:
    out = folder / "render.json"
    before = fingerprint([camera])
    outcome = run("render", "--camera", camera, "--json", out, "-q")
    assert_promise(outcome, names=[str(camera), camera.name], before=before, outputs=[out],
                   folders=[folder])


@pytest.mark.parametrize("examples", EXAMPLES)
def test_camera_files(examples: int) -> None:
    """A valid camera file with one to three fields changed, as TOML or YAML: rendered, or
    refused in one line naming the file (and the field)."""

    @budget(examples)
    @given(doc=mutated(CAMERA), fmt=st.sampled_from(["toml", "yaml"]))
    def check(doc: Any, fmt: str) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = _camera_file(Path(tmp), doc, fmt)
            if path is not None:
                _render_promise(path, Path(tmp))

    check()


@pytest.mark.parametrize("examples", EXAMPLES)
def test_damaged_camera_files(examples: int) -> None:
    """Camera file text cut short, overwritten or not UTF-8."""
    text = (toml_text(CAMERA) or "").encode()

    @budget(examples)
    @given(data=st.data(), suffix=st.sampled_from([".toml", ".yaml"]))
    def check(data: st.DataObject, suffix: str) -> None:
        raw = data.draw(damaged_bytes(text if suffix == ".toml"
                                      else yaml.safe_dump(CAMERA).encode()))
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"camera{suffix}"
            path.write_bytes(raw)
            _render_promise(path, Path(tmp))

    check()


@pytest.mark.parametrize("text", [
    "a = " + "[" * 5000 + "]" * 5000,                  # TOML nested past Python's recursion
    "noise = " + "{a = " * 200 + "1" + "}" * 200,       # inline tables
    "x: " + "[" * 400 + "]" * 400,                     # YAML
    "[noise]\nfull_well = 1\nread_noise = 1e300\n",   # noise beyond float range
    "[white_balance]\nmethod = 'gains'\ngains = [1e308, 1e-308, 1]\n",
    "[ccm]\nmethod = 'matrix'\nmatrix = [[1e308, 1e308, 1e308], [1, 0, 0], [0, 0, 1]]\n",
    "[sensitivities]\nsource = 'file'\npath = 'missing.csv'\n",
    "[sensitivities]\nsource = 'file'\npath = 'zero.csv'\n",
    "[tone]\ncurve = 'lut'\nlut = 'missing.csv'\n",
    "[noise]\nseed = 99999999999999999999999\n",
    "name = 1\n",
], ids=lambda t: t[:24])
def test_camera_corner_cases(text: str, tmp_path: Path) -> None:
    """Camera files the issue found: deep nesting, huge read noise, overflowing gains and
    matrices, sensitivity files that are missing or give no signal."""
    (tmp_path / "zero.csv").write_text("".join(f"{w},0,0,0\n" for w in range(380, 781, 5)))
    suffix = ".yaml" if text.startswith("x:") else ".toml"
    path = tmp_path / f"camera{suffix}"
    path.write_text(text)
    out = tmp_path / "r.json"
    before = fingerprint([path, tmp_path / "zero.csv"])
    outcome = run("render", "--camera", path, "--json", out, "-q")
    assert_promise(outcome, names=[str(path)], before=before, outputs=[out],
                   folders=[tmp_path], codes=(2,))


@pytest.mark.parametrize("examples", EXAMPLES)
def test_prediction_tables(examples: int, published_table: dict[str, Any]) -> None:
    """A prediction table with fields changed: predicted from, or refused naming the file."""

    @budget(examples)
    @given(doc=mutated(published_table), delta_e=st.sampled_from(["0", "3", "40"]))
    def check(doc: Any, delta_e: str) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "table.json"
            path.write_text(json_text(doc))
            out = Path(tmp) / "p.json"
            before = fingerprint([path])
            outcome = run("predict", "--delta-e", delta_e, "--table", path, "--json", out,
                          "-q")
            assert_promise(outcome, names=[str(path)], before=before, outputs=[out],
                           folders=[Path(tmp)])

    check()


@pytest.mark.parametrize("doc", [
    {"name": "t", "kind": "measured", "curves": []},
    {"name": "t", "kind": "measured", "curves": [{"points": [{"delta_e": 1}]}]},
    {"name": "t", "kind": "measured", "curves": [{"points": [{"dmap_points": 1}]}]},
    {"name": "t", "kind": "measured", "curves": [{"points": [{"delta_e": "x",
                                                              "dmap_points": 1}]}]},
    {"name": "t", "kind": "measured", "curves": [{"points": [{"delta_e": 1, "dmap_points": 1},
                                                             {"delta_e": 1, "dmap_points": 2}]}]},
    {"name": "t", "kind": "measured", "curves": "none"},
    [], None, 3,
])
def test_prediction_table_corner_cases(doc: Any, tmp_path: Path) -> None:
    """Tables without curves, points without ΔE or loss, duplicate ΔE, wrong types."""
    path = tmp_path / "t.json"
    path.write_text(json_text(doc))
    before = fingerprint([path])
    outcome = run("predict", "--delta-e", "3", "--table", path)
    assert_promise(outcome, names=[str(path)], before=before, codes=(2,))


@pytest.mark.parametrize("examples", EXAMPLES)
def test_chart_files(examples: int, safecolor_chart: dict[str, Any]) -> None:
    """A chart file with fields changed: calibrated on and audited against, or refused."""

    @budget(examples)
    @given(doc=mutated(safecolor_chart), command=st.sampled_from(["calibrate", "audit"]))
    def check(doc: Any, command: str) -> None:
        _chart_promise(doc, command)

    check()


def _chart_promise(doc: Any, command: str, image: Path | None = None) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "chart.json"
        path.write_text(json_text(doc))
        out = Path(tmp) / "o.json"
        before = fingerprint([path])
        if command == "calibrate":
            outcome = run("calibrate", "--chart", path, "--transforms", "hue", "--targets", "3",
                          "--json", out, "-q")
        else:
            img = image or _flat_chart(Path(tmp))
            outcome = run("audit", img, "--reference", path, "--corners",
                          "12,12,112,12,112,72,12,72", "--json", out)
        assert_promise(outcome, names=[str(path)], before=before, outputs=[out],
                       folders=[Path(tmp)])


def _flat_chart(folder: Path) -> Path:
    import numpy as np

    from fidelity.colour.charts import load_chart
    from tests.fuzz.fuzzkit import write_image

    img = np.zeros((84, 124, 3), dtype=np.uint8)
    srgb = np.round(load_chart().srgb * 255).astype(np.uint8)
    for k in range(24):
        r, c = divmod(k, 6)
        img[4 + 20 * r:20 + 20 * r, 4 + 20 * c:20 + 20 * c] = srgb[k]
    return write_image(folder / "flat.png", img)


@pytest.mark.parametrize(("doc", "command"), [
    ({"layout": {"rows": 1, "cols": 1}, "patches": [{"name": "a", "lab": [0, 0, 0]}]},
     "calibrate"),
    ({"layout": {"rows": 4, "cols": 6}, "patches": [{"name": "a", "lab": [50, 0, 0]}] * 24},
     "calibrate"),
    ({"layout": {"rows": 4, "cols": 6}, "patches": [{"name": "a", "lab": [0, 0, 0]}] * 24},
     "audit"),
    ({"layout": {"rows": 4, "cols": 6}, "patches": [{"name": "a", "lab": [50, 80, 80]}] * 24},
     "audit"),
    ({"layout": {"rows": 4, "cols": 6}, "patches": [{"name": "a", "lab": [1e300, 0, 0]}] * 24},
     "audit"),
    ({"layout": {"rows": 4, "cols": 6}, "patches": [{"name": "a", "lab": [1e300, 0, 0]}] * 24},
     "calibrate"),
])
def test_degenerate_charts(doc: Any, command: str) -> None:
    """Charts of one patch, of identical patches, without neutral patches, of absurd Lab."""
    _chart_promise(doc, command)


@pytest.mark.parametrize("examples", EXAMPLES)
def test_settings_files(examples: int) -> None:
    """A fidelity.toml settings file with values changed: used, or refused naming it."""
    base = {"predict": {"size": "n", "table": "safecolor-2025"}, "gate": {"max_delta_e": 3.0}}

    @budget(examples)
    @given(doc=mutated(base))
    def check(doc: Any) -> None:
        text = toml_text(doc)
        if text is None:
            return
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "fidelity.toml"
            path.write_text(text)
            before = fingerprint([path])
            from click.testing import CliRunner

            from fidelity.cli import main

            r = CliRunner().invoke(main, ["--config", str(path), "predict", "--delta-e", "3"])
            from tests.fuzz.fuzzkit import Outcome

            outcome = Outcome(("--config", str(path), "predict"), r.exit_code, r.stdout,
                              r.stderr, r.exception)
            assert_promise(outcome, names=[str(path), path.name], before=before,
                           folders=[Path(tmp)])

    check()
