"""The tools that rebuild the committed COCO reports after a re-sweep (``benchmarks.
compare_tables``, ``benchmarks.tools.after_resweep``), on the committed tables and small files."""

from __future__ import annotations

import copy
import json
import os
from pathlib import Path

import pytest

from benchmarks.tools import after_resweep, compare_tables
from fidelity.coco.tables.colour import TablesResult

REPO = Path(__file__).resolve().parent.parent


def _tables(doc: dict):
    return TablesResult.from_json(doc).tables


def test_compare_tables_reports_the_re_measured_detector_only_with_its_changes():
    doc = json.loads((REPO / "reports" / "coco" / "tables.json").read_text("utf-8"))
    before = copy.deepcopy(doc)
    model = "yolox_nano"
    before["tables"]["models"][model]["settings"]["conventions"]["preprocess"] = "older"
    cells = [c for c in before["tables"]["cells"][model] if c["status"] == "done"]
    cells[0]["dmap_points"] -= 0.5  # the only cell that moved, by +0.5 points
    cells[1]["se_method"] = "folds"
    result = compare_tables.compare(_tables(before), _tables(doc))
    assert list(result["models"]) == [model]  # the others kept their preprocessing
    d = result["models"][model]
    changes = {(c["transform"], c["delta_e"]): c["change"] for c in d["cells"]}
    assert changes[(cells[0]["transform"], cells[0]["delta_e"])] == pytest.approx(0.5)
    assert sum(abs(v) > 1e-12 for v in changes.values()) == 1
    assert d["summary"]["largest_change"]["change"] == pytest.approx(0.5)
    assert d["preprocessing_before"] == "older"
    assert d["se_before"] == ["larger", "folds"] and d["se_after"] == ["larger"]
    text = compare_tables.markdown(result, "a.json", "b.json")
    assert f"## {model}" in text and "+0.500" in text


def test_after_resweep_replaces_only_existing_files_that_changed(tmp_path):
    src, dst = tmp_path / "new", tmp_path / "report"
    src.mkdir()
    dst.mkdir()
    for name, text in {"same.md": "a", "changed.md": "new", "extra.png": "x"}.items():
        (src / name).write_text(text)
    (dst / "same.md").write_text("a")
    (dst / "changed.md").write_text("old")
    assert after_resweep._replace_existing(src, dst) == ["changed.md"]
    assert (dst / "changed.md").read_text() == "new" and not (dst / "extra.png").exists()


def test_after_resweep_finds_every_prediction_to_recompute():
    doc = {"cells": [{"prediction": {"classic": 1.0}, "x": 1}, {"y": [{"prediction": None}]}],
           "meta": {"n": 2}}
    found = after_resweep._cells(doc)
    assert len(found) == 2 and all("prediction" in c for c in found)


def test_resweep_queue_runs_each_detector_after_the_other_into_its_own_store(tmp_path):
    """benchmarks/tools/resweep_queue.sh: resweep_model.sh once per detector, in order, each with
    its own store; a detector's failure stops the queue (the next would merge on top of it)."""
    import shutil
    import subprocess

    bench = tmp_path / "benchmarks" / "tools"
    bench.mkdir(parents=True)
    shutil.copy(REPO / "benchmarks" / "tools" / "resweep_queue.sh", bench)
    log = tmp_path / "calls"
    stub = bench / "resweep_model.sh"  # stands in for the hours-long sweep: logs its call
    stub.write_text(f'#!/usr/bin/env bash\necho "$*" >> {log}\n[ "$2" != fail.onnx ]\n')
    stub.chmod(0o755)
    stores = tmp_path / "stores"
    env = {"PATH": os.environ["PATH"], "RESWEEP_STORES": str(stores)}
    r = subprocess.run(["bash", str(bench / "resweep_queue.sh")], env=env, capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    assert log.read_text().splitlines() == [
        f"{stores}/resweep-yolox_nano yolox_nano.onnx",
        f"{stores}/resweep-yolo11n yolo11n-int8dyn.onnx"]
    log.unlink()
    r = subprocess.run(["bash", str(bench / "resweep_queue.sh")],
                       env={**env, "RESWEEP_MODELS": "yolox_nano fail yolo11n-int8dyn"},
                       capture_output=True, text=True)
    assert r.returncode != 0
    assert log.read_text().splitlines() == [f"{stores}/resweep-yolox_nano yolox_nano.onnx",
                                            f"{stores}/resweep-fail fail.onnx"]


def test_reproduction_sample_runs_the_same_cells_of_each_detector_and_copies_the_stores(
        tmp_path):
    """benchmarks/tools/reproduction_sample.sh: PROCESSES sweep processes per detector on one store
    (the grid of the sample, CPU provider), one --provider cuda try, and a copy of each
    store in OUT (what comes back from a lent machine)."""
    import sqlite3
    import subprocess
    import sys

    log = tmp_path / "calls"
    py = tmp_path / "python"  # stands in for the interpreter: runs -c, logs and fakes a sweep
    py.write_text(f"""#!{sys.executable}
import sqlite3, subprocess, sys
from pathlib import Path
if sys.argv[1] == "-c":
    sys.exit(subprocess.call([{sys.executable!r}, *sys.argv[1:]]))
with open({str(log)!r}, "a") as f:
    f.write(" ".join(sys.argv[1:]) + "\\n")
out = Path(sys.argv[sys.argv.index("--out") + 1])
out.mkdir(parents=True, exist_ok=True)
db = sqlite3.connect(out / "sweep.sqlite")
db.execute("CREATE TABLE IF NOT EXISTS cells (model TEXT)")
db.execute("INSERT INTO cells VALUES (?)", (out.name,))
db.commit()
""")
    py.chmod(0o755)
    out, stores = tmp_path / "out", tmp_path / "stores"
    r = subprocess.run(["bash", str(REPO / "benchmarks" / "tools" / "reproduction_sample.sh"), "data",
                        str(out), str(py)], capture_output=True, text=True, cwd=tmp_path,
                       env={"PATH": os.environ["PATH"], "PROCESSES": "3",
                            "STORES": str(stores)})
    assert r.returncode == 0, r.stderr
    calls = log.read_text().splitlines()
    for model in ("yolov8n-int8dyn", "yolox_nano"):
        mine = [c for c in calls if f"data/models/{model}.onnx" in c and "cpu" in c]
        assert len(mine) == 3
        assert all("--transforms hue,pull_mean,contrast-dec,gamma-inc --targets 0,6,24" in c
                   and f"--out {stores / model}" in c and "--limit 250" in c for c in mine)
        copy = sqlite3.connect(out / f"{model}.sqlite")
        assert copy.execute("SELECT COUNT(*) FROM cells").fetchone() == (3,)
    cuda = [c for c in calls if "--provider cuda" in c]
    assert len(cuda) == 1 and "yolov8n-int8dyn" in cuda[0]
    assert (out / "cuda.log").read_text().strip().endswith("exit 0")
    assert "cpus:" in (out / "machine.txt").read_text()


def test_after_resweep_requotes_the_manuals_tables_from_their_reports(tmp_path):
    """A quoted row found in its report by its first cell is copied again; a row the report no
    longer has is left (for tests/test_docs_numbers.py to name); the COCO-C README's table is
    rewritten from cococ.json."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "reports" / "cococ").mkdir(parents=True)
    (tmp_path / "README.md").write_text("no quotes\n")
    (tmp_path / "reports" / "r.md").write_text(
        "| k | v |\n|---:|---:|\n| a | 2 |\n| b | 5 |\n- item: new\n")
    page = ("Text, as in `reports/r.md`:\n\n| k | v |\n|---|---|\n| a | 1 |\n| gone | 3 |\n\n"
            "More, as in `reports/r.md` (list):\n\n- item: old\n")
    (tmp_path / "docs" / "p.md").write_text(page)
    cell = {"corruption": "contrast", "severity": 2, "chart_delta_e": 14.921,
            "parts": {"lightness": 5.94, "chroma": 7.94, "hue": 1.05},
            "prediction": {"classic": 13.6449, "directional": 12.07},
            "measured": [{"model": "yolox_nano", "dmap_points": 6.27, "dmap_points_se": 1.35},
                         {"model": "yolo11n-int8dyn", "dmap_points": 8.0, "dmap_points_se": 2}]}
    (tmp_path / "reports" / "cococ" / "cococ.json").write_text(json.dumps({"cells": [cell]}))
    (tmp_path / "reports" / "cococ" / "README.md").write_text(
        "| corruption | severity |\n|---|---|\n| contrast | 2 | 1 | old |\n")
    assert after_resweep.requote(tmp_path) == ["docs/p.md", "reports/cococ/README.md"]
    assert (tmp_path / "docs" / "p.md").read_text() == page.replace(
        "| a | 1 |", "| a | 2 |").replace("- item: old", "- item: new")
    assert (tmp_path / "reports" / "cococ" / "README.md").read_text().split("\n")[2] == (
        "| contrast | 2 | 14.92 | 5.94 / 7.94 / 1.05 | 13.64 | 12.07 | 6.27 ± 1.35 | 8.00 ± 2.00 |")
    assert after_resweep.requote(tmp_path) == []  # nothing left to copy


def test_after_resweep_requotes_from_the_table_the_page_quotes(tmp_path):
    """A report that names the same thing in the first cell of two tables (a model in its
    limits table and in its settings table): a quoted row is copied from the table with the
    quoted header, not from whichever comes last; the COCO report's guide is a quoting page."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "reports" / "coco").mkdir(parents=True)
    (tmp_path / "reports" / "cococ").mkdir()
    (tmp_path / "README.md").write_text("no quotes\n")
    (tmp_path / "reports" / "cococ" / "cococ.json").write_text(json.dumps({"cells": []}))
    (tmp_path / "reports" / "cococ" / "README.md").write_text("no table\n")
    (tmp_path / "reports" / "r.md").write_text(
        "| curve | ≤ 1 pts |\n|---|---:|\n| m1 | 3.38 |\n\nText.\n\n"
        "| model | size |\n|---|---|\n| m1 | n |\n")
    page = "Limits, as in `reports/r.md`:\n\n| curve | ≤ 1 pts |\n|---|---:|\n| m1 | 3.65 |\n"
    (tmp_path / "reports" / "coco" / "README.md").write_text(page)
    assert after_resweep.requote(tmp_path) == ["reports/coco/README.md"]
    assert (tmp_path / "reports" / "coco" / "README.md").read_text() == page.replace(
        "| m1 | 3.65 |", "| m1 | 3.38 |")


def test_prose_numbers_are_computed_from_the_compared_cells_and_the_reports(tmp_path):
    """after_resweep.prose_numbers: a detector's median and largest change, the cells beyond
    one and two SE, the worst case's largest change and the transform it changed to, the
    validation cells over the classic bound in points and SE, and the reports' bound lines."""
    def cell(t, de, before, after, se):
        return {"transform": t, "delta_e": de, "before": before, "after": after,
                "change": after - before, "se_after": se}

    def worst(de, tb, b, ta, a, se):
        return {"delta_e": de, "before_transform": tb, "before": b, "after_transform": ta,
                "after": a, "change": a - b, "se_after": se}

    cells = [cell("hue", 1.0, 0.5, 0.4, 0.2),        # change -0.1, within 1 SE
             cell("gamma-inc", 2.0, 1.0, 1.5, 0.3),  # +0.5: beyond 1 SE, not 2
             cell("contrast-inc", 3.0, 2.0, 2.7, 0.3)]  # +0.7: beyond 2 SE
    doc = {"models": {"m": {"cells": cells, "baseline_map_before": 0.38, "baseline_map_after":
                            0.3812, "worst_case": [
                                worst(1.0, "hue", 0.5, "pull_mean", 0.55, 0.2),
                                worst(2.0, "gamma-inc", 1.0, "gamma-inc", 1.5, 0.25),
                                worst(3.0, "contrast-inc", 2.0, "contrast-inc", 2.7, 1.4)]}}}
    (tmp_path / "reports" / "coco").mkdir(parents=True)
    (tmp_path / "reports" / "coco" / "preprocessing_change_cells.json").write_text(json.dumps(doc))
    (tmp_path / "reports" / "validation").mkdir()
    rows = [{"camera": "a", "model": "m", "bound": {"all": {"within": True, "excess": -1.0,
                                                             "se": 0.5}}},
            {"camera": "b", "model": "m", "bound": {"all": {"within": False, "excess": 0.25,
                                                             "se": 0.5}}}]
    (tmp_path / "reports" / "validation" / "validation.json").write_text(json.dumps(
        {"rows": rows}))
    (tmp_path / "reports" / "validation" / "validation.md").write_text(
        "# v\n> - mAP@[.50:.95] (all classes): within the bound in **1 of 2** cells\nprose\n")
    (tmp_path / "reports" / "cococ").mkdir()
    (tmp_path / "reports" / "cococ" / "cococ.md").write_text(
        "> - Classic bound: **3 of 3**\n> - Direction-aware bound: **2 of 3**\n> - other\n")
    lines = after_resweep.prose_numbers(tmp_path)
    assert lines[0] == ("m: 3 cells, median |change| 0.500, largest +0.700 (contrast-inc ΔE 3: "
                        "2.000 -> 2.700), beyond 1 SE 2, beyond 2 SE 1; baseline mAP 0.3800 -> "
                        "0.3812")
    assert lines[1] == ("  worst case: largest |change| 0.700 (ΔE 3: contrast-inc 2.000 -> "
                        "contrast-inc 2.700); ΔE >= 2: +0.50..+0.70, at most 2.00 SE; worst "
                        "transform changed: ΔE 1 hue -> pull_mean")
    assert lines[2] == ("validation: 1 of 2 cells over the classic bound; b (m) by 0.250 "
                        "points, 0.50 SE")
    assert lines[3:] == ["> - mAP@[.50:.95] (all classes): within the bound in **1 of 2** cells",
                         "> - Classic bound: **3 of 3**", "> - Direction-aware bound: **2 of 3**"]


def test_kept_provenance_walks_the_merge_chain_back_to_the_run_of_each_model(tmp_path):
    """benchmarks.tools.kept_provenance: tables merged twice by an older version, whose record
    named one run for every kept model; each model is recovered with the run that measured it
    (the file, checked by SHA-256 against the commit its name gives, and that file's own meta),
    and the files it passed through since."""
    import hashlib
    import subprocess

    from benchmarks.tools.kept_provenance import recovered_runs

    repo = tmp_path / "repo"
    (repo / "reports" / "coco").mkdir(parents=True)

    def git(*args: str) -> str:
        return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
                              cwd=repo, capture_output=True, text=True, check=True).stdout

    def commit(tables: dict) -> tuple[str, str]:
        path = repo / "reports" / "coco" / "tables.json"
        path.write_text(json.dumps({"tables": tables}))
        git("add", "-A")
        git("commit", "-q", "-m", "x")
        sha = hashlib.sha256(path.read_bytes()).hexdigest()
        return git("rev-parse", "--short", "HEAD").strip(), sha

    git("init", "-q")
    first_run = {"file": "tables.json", "sha256": "0" * 64, "models": ["b"],
                 "machine": {"cpu": "M0"}}
    c1, s1 = commit({"models": {"a": {}, "b": {}},
                     "meta": {"machine": {"cpu": "M1"}, "versions": {"v": 1},
                              "earlier": first_run}})
    c2, s2 = commit({"models": {"a": {}, "b": {}, "c": {}},
                     "meta": {"machine": {"cpu": "M2"}, "imported": [{"file": "c.scores"}],
                              "earlier": {"file": f"reports-coco-tables-at-{c1}.json",
                                          "sha256": s1, "models": ["a", "b"],
                                          "machine": {"cpu": "M1"}}}})
    copy = tmp_path / "copy" / f"reports-coco-tables-at-{c2}.json"  # the merge read a copy
    runs = recovered_runs({"file": str(copy), "sha256": s2}, ["c", "a", "b"], repo=repo)
    by = {m: r for r in runs for m in r["models"]}
    assert by["c"]["machine"] == {"cpu": "M2"} and by["c"]["imported"] == [{"file": "c.scores"}]
    assert by["c"]["file"] == f"reports-coco-tables-at-{c2}.json" and "via" not in by["c"]
    assert by["a"]["machine"] == {"cpu": "M1"} and by["a"]["versions"] == {"v": 1}
    assert [v["file"] for v in by["a"]["via"]] == [f"reports-coco-tables-at-{c2}.json"]
    assert by["b"]["machine"] == {"cpu": "M0"} and by["b"]["file"] == "tables.json"
    assert [v["file"] for v in by["b"]["via"]] == [f"reports-coco-tables-at-{c1}.json",
                                                   f"reports-coco-tables-at-{c2}.json"]
    with pytest.raises(ValueError, match="not the recorded file"):
        recovered_runs({"file": f"reports-coco-tables-at-{c2}.json", "sha256": s1}, ["c"],
                       repo=repo)
