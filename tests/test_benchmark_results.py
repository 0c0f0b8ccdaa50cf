"""The speed benchmarks' one result schema (``benchmarks/speed/result.schema.json``): every
committed ``reports/benchmarks/*.json`` is a result of the runner (``python -m
benchmarks.speed``) that validates against it, names a benchmark module that exists, and
states ratios that are its own figures' ratios; the runner discovers the modules and writes a
valid result of a small run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.speed import record, runner

REPO = Path(__file__).resolve().parent.parent
RESULTS = sorted((REPO / "reports" / "benchmarks").glob("*.json"))


def test_there_are_committed_results():
    assert len(RESULTS) >= 10, RESULTS


@pytest.mark.parametrize("path", RESULTS, ids=[p.name for p in RESULTS])
def test_a_committed_result_validates_against_the_one_schema(path):
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert record.problems(doc) == [], f"{path.name}: not a result of the one schema"
    assert doc["schema"] == record.SCHEMA
    assert doc["benchmark"] in runner.benchmark_names(), doc["benchmark"]
    # the file is the benchmark's own, or a second set of it (versions_validate.json)
    assert path.stem == doc["benchmark"] or path.stem.startswith(doc["benchmark"] + "_")


@pytest.mark.parametrize("path", RESULTS, ids=[p.name for p in RESULTS])
def test_a_committed_ratio_is_ours_over_the_anchor(path):
    """Where a case states its wall ratio as ours / anchor (no ``of``), it is that quotient of
    its own figures, to the 4 significant digits it is written with."""
    for c in json.loads(path.read_text(encoding="utf-8"))["cases"]:
        r, ours, anchor = c["ratio"], c["ours"], c["anchor"]
        if anchor is None:
            assert r is None, c["name"]
            continue
        if "of" in r or not ours["wall_s"] or not anchor["wall_s"]:
            continue
        assert r["wall"] == pytest.approx(ours["wall_s"] / anchor["wall_s"], rel=1e-3), c["name"]


def test_the_schema_check_can_fail():
    doc = json.loads(RESULTS[0].read_text(encoding="utf-8"))
    del doc["cases"][0]["anchor"]
    doc["cases"][0]["ours"]["wall"] = 1.0  # a field of no schema
    wrong = record.problems(doc)
    assert any("anchor" in w for w in wrong) and any("wall" in w for w in wrong), wrong


def test_every_benchmark_module_declares_what_the_runner_needs():
    names = runner.benchmark_names()
    assert {"startup", "delta_e", "memory", "versions", "render"} <= set(names)
    for name in names:
        module = runner.load(name)
        assert module.ANCHOR and runner.title(module)
        for need in getattr(module, "NEEDS", ()):
            assert need in runner.NEEDS, (name, need)
        params = runner.parameters(module, {}, quick=True)
        assert set(params) == set(getattr(module, "PARAMETERS", {})), name


def test_docs_name_every_benchmark():
    text = (REPO / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    missing = [n for n in runner.benchmark_names() if f"`{n}`" not in text]
    assert not missing, f"docs/benchmarks.md: describe {missing}"


def test_the_runner_writes_a_valid_result_of_a_small_run(tmp_path, capsys):
    out = tmp_path / "delta_e.json"
    assert runner.main(["delta_e", "-p", "pairs=2000", "-p", "repeats=1", "--out", str(out)]) == 0
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert record.problems(doc) == []
    assert doc["parameters"] == {"pairs": 2000, "repeats": 1}
    assert doc["machine"]["cpu"] is not None and doc["versions"]["numpy"]
    assert [c["name"] for c in doc["cases"]] == ["2,000 pairs, float64",
                                                 "2,000 pairs, float32 input"]
    assert all(c["ratio"]["wall"] > 0 for c in doc["cases"])
    assert "2,000 pairs, float64" in capsys.readouterr().out
    # formed again from its details (what --report-only does): the same cases
    again = runner.rewrite("delta_e", runner.load("delta_e"), out)
    assert again["cases"] == doc["cases"]


def test_the_runner_refuses_a_parameter_no_benchmark_named_has(capsys):
    with pytest.raises(SystemExit):
        runner.main(["delta_e", "-p", "sizes=1"])
    assert "sizes" in capsys.readouterr().err
