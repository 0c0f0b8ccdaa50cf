"""The JSON every command writes stays the same across refactors (issue 33).

Each case runs one command in-process and compares its JSON with the file recorded under
``tests/data/json_outputs/`` before the records moved below the report layer. What is not the
command's answer is normalised away: creation times, the machine (platform, library versions),
and the folders of this run (the test's temporary folder becomes ``<tmp>``, the checkout
``<repo>``). Numbers compare as :mod:`jsondiff` says (1e-6 relative, 1e-9 absolute), so a
change in the order of a sum or another CPU's last bits is not a difference; a changed field, a
lost field or a moved number is (the fields :data:`ADDED` since are new keys beside the
recorded ones).

Record the files again, only when an output is meant to change, with
``FIDELITY_RECORD_JSON=1 python -m pytest tests/cli/test_json_outputs.py`` and say why in the commit.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from tests import jsondiff
from tests.coco.test_tables import make_store

REPO = Path(__file__).resolve().parents[2]
RECORDED = Path(__file__).parents[1] / "data" / "json_outputs"
RECORD = os.environ.get("FIDELITY_RECORD_JSON") == "1"

#: keys whose values describe when or where a run happened (or hash a file that holds it),
#: not what it found
VOLATILE = {"created", "platform", "python", "libraries", "version", "elapsed_s", "seconds",
            "sha256", "input_sha256"}  # an EXR header carries its writing time


def normalise(value: Any, folders: dict[str, str]) -> Any:
    """The JSON value with times, machine and run folders replaced by placeholders."""
    if isinstance(value, dict):
        return {k: ("<volatile>" if k in VOLATILE else normalise(v, folders))
                for k, v in value.items()}
    if isinstance(value, list):
        return [normalise(v, folders) for v in value]
    if isinstance(value, str):
        for folder, name in folders.items():
            value = value.replace(folder, name)
        return value
    return value


#: Fields issue 33 added (a prediction's sampling error, interval and raised values, a verdict's
#: reason and what it was decided on), as (pattern of the parent's path, key): new keys, the
#: recorded ones unchanged.
ADDED = (
    (re.compile(r"(\$|.*\.prediction)$"), {"dmap_points_se", "dmap_points_interval"}),
    (re.compile(r"(\$|.*\.prediction)\.columns\.\w+$"), {"raised_from"}),
    (re.compile(r".*\.verdict$"), {"reason", "delta_e", "bound", "status", "upper_bound",
                                    "table"}),
    # issue 32: the uncertainty budget of the chart ΔE, the prediction's interval, the validity
    # domain, the verdict's decision rule and uncertainty
    (re.compile(r"(\$|.*\.sim|.*\.real|\$\.sim_to_real)$"), {"uncertainty"}),
    (re.compile(r"(\$|.*\.sim|.*\.real)$"), {"prediction_interval", "validity"}),
    (re.compile(r".*\.verdict$"), {"decision", "standard_uncertainty", "expanded_uncertainty"}),
    # issue 30: whether each patch counts in the chart's statistics (covered ones do not)
    (re.compile(r".*\.patches\[\d+\]$"), {"used", "excluded_because"}),
    (re.compile(r".*\.corners_found$"), {"occluded"}),
    # "Beyond colour, part 1": an audited image's noise and sharpness
    (re.compile(r"(\$|.*\.sim|.*\.real|.*\.reports\[\d+\])$"), {"noise", "sharpness"}),
    # "Beyond colour, part 2": colour, sharpness and noise judged together
    (re.compile(r"(\$|.*\.sim|.*\.real|.*\.reports\[\d+\])$"), {"properties"}),
    (re.compile(r".*\.verdict$"), {"properties"}),
    # issue 57: the exposure judged against the expected one (null unless a fixed exposure is
    # given), and the neutral patches' exposure correction
    (re.compile(r"(\$|.*\.sim|.*\.real|.*\.reports\[\d+\])$"), {"exposure", "neutral_ev"}),
    (re.compile(r".*\.normalisation$"), {"neutral_ev", "audit_auto", "difference_ev",
                                          "difference"}),
    # issue 57: the likely cause of the chart's error (fidelity.colour.diagnosis)
    (re.compile(r"(\$|.*\.sim|.*\.real|.*\.reports\[\d+\])$"), {"diagnosis"}),
    # issue 55: sharpness measured on a slanted-edge target keeps the target's own MTF50
    (re.compile(r".*\.predictions\.\w+$"), {"target_x"}),
)



def added(where: str, key: str) -> bool:
    """Whether ``key`` under ``where`` is a field added since the outputs were recorded."""
    return any(pattern.match(where) and key in keys for pattern, keys in ADDED)


def differences(a: Any, b: Any, where: str = "$") -> list[str]:
    """Where two normalised JSON values differ (numbers to :data:`jsondiff.REL_TOL` relative,
    :data:`jsondiff.ABS_TOL` absolute)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}.{k}: only in the recorded output" for k in a.keys() - b.keys()]
        out += [f"{where}.{k}: not in the recorded output" for k in b.keys() - a.keys()
                if not added(where, k)]
        for k in a.keys() & b.keys():
            out += differences(a[k], b[k], f"{where}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if where.endswith(".corners_found.notes") and b[:len(a)] == a:
            # issue 30: a note on a patch far off the camera's fit but flat (measured, named)
            return [f"{where}: new note {n!r}" for n in b[len(a):]
                    if "far from what the other patches predict" not in n]
        if len(a) != len(b):
            return [f"{where}: {len(a)} items recorded, {len(b)} now"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{where}[{i}]")]
    return jsondiff.differences(a, b, where)


def run(args: list[str], ok: tuple[int, ...] = (0, 1)) -> None:
    r = CliRunner().invoke(main, args, catch_exceptions=False)
    assert r.exit_code in ok, (args, r.output)


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> Path:
    """Two closed-form renders: the built-in camera and a second real camera's model."""
    root = tmp_path_factory.mktemp("renders")
    run(["render", "--out", str(root / "nikon"), "-q"], ok=(0,))
    run(["render", "--camera", "sigma-sdmerrill", "--out", str(root / "sigma"), "-q"], ok=(0,))
    return root


def _png(renders: Path, camera: str) -> str:
    return str(renders / camera / "developed.png")


def _exr(renders: Path, camera: str) -> str:
    return str(renders / camera / "raw_camera.exr")


def _tables_store(out: Path) -> str:
    make_store(out / "store")
    return str(out / "store")


#: name -> (arguments given the renders' folder and this case's output folder, the JSON files)
Case = Callable[[Path, Path], list[str]]
CASES: dict[str, tuple[Case, tuple[str, ...]]] = {
    "check-default": (lambda r, o: ["check", "--out", str(o / "c"), "-q"],
                      ("c/report.json",)),
    "check-sigma-safecolor": (
        lambda r, o: ["check", "--camera", "sigma-sdmerrill", "--reference", "safecolor",
                      "--size", "n", "--bound", "directional", "--out", str(o / "c"), "-q"],
        ("c/report.json",)),
    "audit-png": (lambda r, o: ["audit", _png(r, "nikon"), "--json", str(o / "a.json"), "-q"],
                  ("a.json",)),
    "audit-exr": (lambda r, o: ["audit", _exr(r, "sigma"), "--exposure", "0",
                                "--json", str(o / "a.json"), "-q"], ("a.json",)),
    "gate-image": (lambda r, o: ["gate", _png(r, "sigma"),
                                 "--max-dmap", "1", "--bound", "directional",
                                 "--json", str(o / "g.json"), "-q"], ("g.json",)),
    "gate-camera": (lambda r, o: ["gate", "--camera", "nikon-5100", "--max-dmap", "2",
                                  "--unit", "relative", "--json", str(o / "g.json"), "-q"],
                    ("g.json",)),
    "compare": (lambda r, o: ["compare", _png(r, "nikon"), _png(r, "sigma"),
                              "--max-delta-e", "3", "--json", str(o / "c.json"), "-q"],
                ("c.json",)),
    "compare-none-dmap": (lambda r, o: ["compare", _png(r, "sigma"), _png(r, "nikon"),
                                        "--normalise", "none", "--max-dmap", "1",
                                        "--class", "person", "--json", str(o / "c.json"), "-q"],
                          ("c.json",)),
    "predict": (lambda r, o: ["predict", "--delta-e", "2.5", "--json", str(o / "p.json")],
                ("p.json",)),
    "predict-safecolor-s": (lambda r, o: ["predict", "--delta-e", "4", "--table",
                                          "safecolor-2025", "--size", "s", "--baseline-map",
                                          "0.4", "--json", str(o / "p.json")], ("p.json",)),
    "predict-beyond": (lambda r, o: ["predict", "--delta-e", "40", "--json", str(o / "p.json")],
                       ("p.json",)),
    "predict-limit": (lambda r, o: ["predict", "--max-dmap", "1", "--unit", "relative",
                                    "--json", str(o / "p.json")], ("p.json",)),
    "predict-direction": (lambda r, o: ["predict", "--delta-e", "3", "--direction", "hue",
                                        "--json", str(o / "p.json")], ("p.json",)),
    "predict-coco-c": (lambda r, o: ["predict", "--coco-c", "brightness:3",
                                     "--json", str(o / "p.json")], ("p.json",)),
    "tables-store": (lambda r, o: ["tables", _tables_store(o), "--out", str(o / "report"),
                                   "--prediction", str(o / "prediction.json"),
                                   "--directional", str(o / "directional.json"),
                                   "--no-progress"],
                     ("report/tables.json", "prediction.json", "directional.json")),
    "tables-shipped": (lambda r, o: ["tables", str(REPO / "reports" / "coco" / "tables.json"),
                                     "--prediction", str(o / "prediction.json"),
                                     "--directional", str(o / "directional.json")],
                       ("prediction.json", "directional.json")),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_json_output_is_unchanged(name, renders, tmp_path) -> None:
    arguments, files = CASES[name]
    run(arguments(renders, tmp_path))
    for file in files:
        now = normalise(json.loads((tmp_path / file).read_text()),
                        {str(tmp_path): "<tmp>", str(renders): "<renders>", str(REPO): "<repo>"})
        recorded = RECORDED / f"{name}--{file.replace('/', '-')}"
        if RECORD:
            recorded.parent.mkdir(parents=True, exist_ok=True)
            recorded.write_text(json.dumps(now, indent=1, sort_keys=True) + "\n")
            continue
        assert recorded.exists(), f"no recorded output {recorded.name}: record it first"
        found = differences(json.loads(recorded.read_text()), now)
        assert not found, "\n".join(found[:20])
