"""A module of an extra that is not installed is one line naming the extra (exit 2), not an
internal error: the map from import names to requirements cannot drift from pyproject.toml."""

from __future__ import annotations

import sys
from importlib import metadata

import pytest
from click.testing import CliRunner

from fidelity.cli import environment_error, main
from fidelity.pipeline.environment import DISTRIBUTION, IMPORT_NAMES, RUNTIME_EXTRAS, missing_extra


def test_every_runtime_requirement_has_its_import_name():
    declared = set()
    for req in metadata.requires(DISTRIBUTION) or []:
        for extra in RUNTIME_EXTRAS:
            if f'extra == "{extra}"' in req.replace("'", '"'):
                name = req.split(";")[0].strip()
                for stop in "<>=!~[ ":
                    name = name.split(stop)[0]
                declared.add(name.lower())
    assert declared, "no runtime extra is declared in the installed metadata"
    assert declared <= {v.lower() for v in IMPORT_NAMES.values()}


@pytest.mark.parametrize(("module", "requirement", "extra"), [
    ("onnxruntime", "onnxruntime", "coco"),
    ("faster_coco_eval.core", "faster-coco-eval", "coco"),
    ("pxr", "usd-core", "scene"),
    ("PyOpenColorIO", "opencolorio", "ocio"),  # fit installs it too; ocio has fewer packages
    ("tomli_w", "tomli-w", "fit"),
    ("rosbags.highlevel", "rosbags", "ros"),
])
def test_a_missing_module_names_the_smallest_extra_that_installs_it(module, requirement, extra):
    assert missing_extra(module) == (requirement, extra)


@pytest.mark.parametrize("module", [None, "", "numpy", "no_such_module", "fidelity.coco"])
def test_other_missing_modules_are_not_blamed_on_an_extra(module):
    assert missing_extra(module) is None
    assert environment_error(ModuleNotFoundError("x", name=module)) is None


def test_a_command_without_its_extra_is_one_line_and_exit_2(tmp_path, monkeypatch):
    model = tmp_path / "m.onnx"
    model.write_bytes(b"")
    (tmp_path / "images").mkdir()
    annotations = tmp_path / "a.json"
    annotations.write_text("{}")
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # import onnxruntime: not installed
    result = CliRunner().invoke(main, [
        "sweep", "--models", str(model), "--images", str(tmp_path / "images"),
        "--annotations", str(annotations), "--out", str(tmp_path / "store"), "--no-progress"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert lines == ["fidelity: error: onnxruntime: not installed; this command needs the [coco] "
                     "extra: pip install 'camera-fidelity[coco]'"]
