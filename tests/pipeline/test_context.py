"""Tests for fidelity.pipeline.context: the context file's schema, risk and credibility."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.core.errors import InputFileError
from fidelity.pipeline.check import check_camera
from fidelity.pipeline.context import assess, load_context
from fidelity.prediction.interval import ValidatedCameras

GOOD = """name = "urban AEB"
[detectors]
models = ["yolox_nano"]
[conditions]
illuminants = ["D65", "A"]
[acceptance]
max_delta_e = 3.0
max_dmap = 1.0
[risk]
model_influence = "medium"
decision_consequence = "high"
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "context.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(("influence", "consequence", "level"), [
    ("low", "low", 1), ("low", "high", 3), ("medium", "high", 4), ("high", "high", 5)])
def test_risk_level_is_the_vv40_matrix(tmp_path: Path, influence: str, consequence: str,
                                       level: int) -> None:
    text = GOOD.replace('"medium"', f'"{influence}"').replace('"high"', f'"{consequence}"')
    assert load_context(write(tmp_path, text)).risk_level == level


@pytest.mark.parametrize(("old", "new", "match"), [
    ('"high"', '"hgih"', r"risk\.decision_consequence: must be one of low, medium, high"),
    ("max_dmap", "max_dmapp", r"acceptance\.max_dmapp: unknown field; known: max_delta_e"),
    ("[detectors]", "[detector]", r"detector: unknown field; known: .*detectors"),
    ('"A"]', '"Q9"]', r"conditions\.illuminants: Q9"),
    ("3.0", "-1", r"acceptance\.max_delta_e: must be number > 0"),
    ('model_influence = "medium"', "", r"risk\.model_influence: missing"),
])
def test_bad_field_names_file_field_and_allowed(tmp_path: Path, old: str, new: str,
                                                match: str) -> None:
    p = write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(InputFileError, match=match) as info:
        load_context(p)
    assert str(p) in str(info.value)


def fake_qualify(statuses: list[str]) -> Any:
    return lambda names: SimpleNamespace(checks=[SimpleNamespace(name=n, status=s)
                                                 for n, s in zip(names, statuses, strict=True)])


VALIDATED = ValidatedCameras(30, ("A", "D65"), {}, (), ("yolox_nano",), 60, 60, 60)


def test_factors_follow_the_facts(tmp_path: Path) -> None:
    ctx = load_context(write(tmp_path, GOOD.replace('"A"]', '"F11"]')))
    report = check_camera("ideal")
    a = assess(ctx, [("ideal", report)], validated=VALIDATED,
               run=fake_qualify(["pass"] * 5 + ["fail"]))
    f = {x.name: x for x in a.factors}
    assert f["code verification"].score == pytest.approx(5 / 6)
    assert f["code verification"].level == 1 + round(4 * 5 / 6)
    # F11 is not validated: half the illuminants, all cells within
    assert f["validation coverage"].score == pytest.approx(0.5)
    assert f["validation coverage"].level == 3
    assert any("illuminant F11" in o for o in a.outside)
    assert a.credibility_level == 3 and a.required_level == 4 and not a.sufficient
    assert a.exit_code == 1


def test_acceptance_judged_on_the_report(tmp_path: Path) -> None:
    ctx = load_context(write(tmp_path, GOOD.replace("3.0", "0.1")))
    report = check_camera("ideal")
    a = assess(ctx, [("ideal", report)], validated=VALIDATED, run=fake_qualify(["pass"] * 6))
    de = next(x for x in a.acceptance if x.criterion == "max_delta_e")
    assert de.value == pytest.approx(report.mean_delta_e)
    assert de.passed is (report.mean_delta_e <= 0.1)


def test_cli_check_with_context_writes_it_in_the_record(tmp_path: Path) -> None:
    p = write(tmp_path, GOOD)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["check", "--camera", "ideal", "--context", str(p),
                                  "--out", str(out)])
    assert r.exit_code in (0, 1), r.output
    rec = json.loads((out / "report.json").read_text())["context"]
    assert rec["required_level"] == 4
    assert rec["credibility_level"] == min(f["level"] for f in rec["factors"])
    assert "Context of use" in (out / "report.html").read_text()
    r2 = CliRunner().invoke(main, ["check", "--camera", "ideal", "--context",
                                   str(tmp_path / "missing.toml"), "--no-report"])
    assert r2.exit_code == 2 and "missing.toml" in r2.output
