"""``fidelity info``: the environment report against independent readings of the same facts."""

from __future__ import annotations

import json
import re
import tomllib
from importlib import metadata
from pathlib import Path

from click.testing import CliRunner

from fidelity.cli import main
from fidelity.core.resources import shared_dir

REPO = Path(__file__).resolve().parents[2]


def test_info_reports_every_declared_dependency_and_the_setup(tmp_path: Path) -> None:
    r = CliRunner().invoke(main, ["info", "--no-probe", "--json", str(tmp_path / "env.json")])
    assert r.exit_code == 0, r.output
    env = json.loads((tmp_path / "env.json").read_text())
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]

    def names(requirements: list[str]) -> set[str]:
        return {re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0].lower() for d in requirements}

    assert {k.lower() for k in env["dependencies"]} == names(project["dependencies"])
    from fidelity.pipeline.environment import RUNTIME_EXTRAS

    extras = project["optional-dependencies"]
    assert set(RUNTIME_EXTRAS) == set(extras) - {"all", "test", "docs"}  # every runtime extra
    for extra in RUNTIME_EXTRAS:
        declared = names(extras[extra])
        assert {k.lower() for k in env["extras"][extra]} == declared, extra
    for name, version in [*env["dependencies"].items(),
                          *(kv for e in env["extras"].values() for kv in e.items())]:
        assert version == metadata.version(name), name
    import onnxruntime

    assert env["onnxruntime"]["available"] == onnxruntime.get_available_providers()
    assert env["onnxruntime"]["used"][-1] == "CPUExecutionProvider"
    assert env["mitsuba"] == {"probed": False}
    assert env["prediction_tables"]["default"] in env["prediction_tables"]["available"]
    folder = shared_dir()
    if folder is None:
        assert env["shared"]["folder"] is None
    else:
        assert env["shared"]["folder"] == str(folder)
        assert env["shared"]["models"] == sorted(p.name for p in folder.glob("models/*.onnx"))
        assert env["shared"]["coco_images"] == len(list(folder.glob("coco/val2017/*.jpg")))


def test_info_says_which_mitsuba_variant_renders() -> None:
    from fidelity.camera.mitsuba import probe_variant
    from fidelity.core.errors import FidelityError
    from fidelity.pipeline.environment import describe_environment

    m = describe_environment(probe=True)["mitsuba"]
    try:
        expect = probe_variant().variant
    except FidelityError:
        expect = None
    assert m["variant"] == expect
    if expect is not None:
        # an llvm_* variant runs on the libLLVM it names; the others need none
        assert (m["libllvm"] is None) is not expect.startswith("llvm")
        # the probe's outcome per variant is only in its notes' words (no field)
        assert any(note.startswith(f"{expect}: ok") for note in m["notes"])
