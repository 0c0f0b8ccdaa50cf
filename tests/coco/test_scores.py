"""A sweep's scores file (fidelity.coco.scores): exported from one store, imported into a new
one on another machine, resumed there, and reported as if the sweep had never moved. (The
validation store's: tests/coco/test_validate.py, on a real run.)"""

from __future__ import annotations

import gzip
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.coco.sweep import ModelSpec, SweepStore
from fidelity.core.errors import InputFileError
from tests.coco.test_sweep import FakeDetector, one_line_error, synthetic_coco

GRID = (["contrast-inc", "contrast-dec"], [0, 3, 6])


@pytest.fixture
def data(tmp_path, monkeypatch):
    from fidelity.coco import executor

    monkeypatch.setattr(executor, "Detector", FakeDetector)  # where the runner makes one
    return synthetic_coco(tmp_path / "data", n=6)


def sweep(data, out: Path, transforms: list[str], targets: list[float]) -> SweepStore:
    from fidelity.coco.sweep import run_sweep

    images, ann, model = data
    return run_sweep([ModelSpec(model, None)], images, ann, out, transforms, targets,
                     log=lambda s: None)


def tables_json(store: SweepStore, ann: Path) -> dict:
    from fidelity.coco.scoring import load_annotations
    from fidelity.coco.tables.build import build_tables

    t = build_tables(store, load_annotations(ann)).to_json()
    return {k: v for k, v in t.items() if k != "meta"}


def test_export_import_resume_reports_as_one_uninterrupted_run(data, tmp_path):
    images, ann, model = data
    first = sweep(data, tmp_path / "first", *GRID)
    scores = tmp_path / "run.scores.json.gz"
    r = CliRunner().invoke(main, ["sweep", "--export-scores", str(scores), "--annotations",
                                  str(ann), "--out", str(tmp_path / "first")])
    assert r.exit_code == 0, r.output
    assert "5 cells of a sweep store (fake 5) exported" in r.output
    doc = json.loads(gzip.decompress(scores.read_bytes()))
    assert doc["format"] == "fidelity-scores" and doc["kind"] == "sweep"
    assert len(doc["tables"]["images"]["rows"]) == 6
    assert not {"detections", "owners", "leases"} & set(doc["tables"])
    assert len(doc["tables"]["folds"]["rows"]) == len(doc["tables"]["draws"]["rows"]) == 5
    # the digest: the stored detections, hashed here as the docstring says
    base = first.detections("fake", "baseline", 0)
    h = hashlib.sha256()
    for i in sorted(base):
        h.update(np.array([i, len(base[i])], "<i8").tobytes() + base[i].astype("<f4").tobytes())
    assert doc["detections_sha256"]['["fake", "baseline", 0.0]'] == h.hexdigest()

    moved = tmp_path / "moved"
    r = CliRunner().invoke(main, ["sweep", "--import-scores", str(scores), "--out", str(moved)])
    assert r.exit_code == 0, r.output
    assert "5 cells of a sweep store (fake 5) imported" in r.output
    r = CliRunner().invoke(main, ["sweep", "--import-scores", str(scores), "--out", str(moved)])
    assert r.exit_code == 0 and "already imported" in r.output, r.output
    store = SweepStore(moved)
    assert tables_json(store, ann) == tables_json(first, ann)
    digest = hashlib.sha256(scores.read_bytes()).hexdigest()
    assert store.meta()["imported"][0]["sha256"] == digest
    # the report says where its cells came from; the prediction table it writes loads
    r = CliRunner().invoke(main, ["tables", str(moved), "--out", str(tmp_path / "rep"),
                                  "--prediction", str(tmp_path / "p.json"), "--no-progress"])
    assert r.exit_code == 0, r.output
    from fidelity.prediction.tablefile import load_prediction_table

    table = load_prediction_table(tmp_path / "p.json")
    imported = json.loads((tmp_path / "p.json").read_text())["provenance"]["imported"]
    assert [(i["file"], i["sha256"]) for i in imported] == [(scores.name, digest)]
    assert table is not None
    # a sweep without hue cells: the paper's "hue hurts least" is not enough data, not a crash
    found = json.loads((tmp_path / "rep" / "tables.json").read_text())["comparison"]
    hue = next(f for f in found if f["claim"] == "hue changes hurt least")
    assert hue["verdict"] == "not enough data" and "no hue cells" in hue["evidence"]

    # the report straight from the scores file (a temporary store): the same tables
    r = CliRunner().invoke(main, ["tables", str(scores), "--out", str(tmp_path / "from-file"),
                                  "--annotations", str(ann), "--no-progress"])
    assert r.exit_code == 0, r.output
    from_file = json.loads((tmp_path / "from-file" / "tables.json").read_text())["tables"]
    from_store = json.loads((tmp_path / "rep" / "tables.json").read_text())["tables"]
    assert {k: v for k, v in from_file.items() if k != "meta"} == \
        {k: v for k, v in from_store.items() if k != "meta"}
    # again into the same report folder: the report is written anew (the folder is no
    # output file to refuse)
    r = CliRunner().invoke(main, ["tables", str(scores), "--out", str(tmp_path / "from-file"),
                                  "--annotations", str(ann), "--no-progress"])
    assert r.exit_code == 0, r.output
    for bad, words in ((["--explain", "fake:contrast-inc:3"], ("--explain", "detections")),
                       ([], ("give --out",)),
                       (["--out", str(tmp_path / "x"), "--prediction", str(scores)],
                        ("--prediction", "input"))):
        one_line_error(CliRunner().invoke(main, ["tables", str(scores), *bad]), *words)

    # where the run stands, from the file alone: the store's counts; the file is no store folder
    status = {}
    for where in (tmp_path / "first", scores):
        r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(where)])
        assert r.exit_code == 0, r.output
        status[where] = next(ln.split()[1:5] for ln in r.output.splitlines()
                             if ln.startswith("fake "))
    assert status[scores] == status[tmp_path / "first"] == ["6", "5/5", "0", "0"]
    assert f"scores file {scores} (a store's finished cells" in r.output
    r = CliRunner().invoke(main, ["sweep", "--rescore", "--annotations", str(ann), "--out",
                                  str(scores)])
    one_line_error(r, "--out", "is a file", "--import-scores")

    # resumed with a wider grid: only the new cells run, and the report equals a run that never
    # moved
    finished = {(c.transform, c.target): c.finished for c in store.cells()}
    wider = (["contrast-inc", "contrast-dec", "brightness-inc"], [0, 3, 6])
    resumed = sweep(data, moved, *wider)
    again = {(c.transform, c.target): c.finished for c in resumed.cells()}
    assert len(again) == 7 and all(again[k] == v for k, v in finished.items())
    whole = sweep(data, tmp_path / "whole", *wider)
    assert tables_json(resumed, ann) == tables_json(whole, ann)


def test_an_imported_cells_detections_are_an_error_naming_the_file(data, tmp_path):
    images, ann, model = data
    sweep(data, tmp_path / "a", ["contrast-inc"], [0, 3])
    scores = tmp_path / "a.scores.json"
    assert CliRunner().invoke(main, ["sweep", "--export-scores", str(scores), "--annotations",
                                     str(ann), "--out", str(tmp_path / "a")]).exit_code == 0
    assert scores.read_bytes()[:1] == b"{"  # plain JSON without .gz
    assert CliRunner().invoke(main, ["sweep", "--import-scores", str(scores), "--out",
                                     str(tmp_path / "b")]).exit_code == 0
    store = SweepStore(tmp_path / "b")
    with pytest.raises(InputFileError, match="imported from a.scores.json without its detect"):
        store.detections("fake", "contrast-inc", 3)
    r = CliRunner().invoke(main, ["sweep", "--rescore", "--annotations", str(ann), "--out",
                                  str(tmp_path / "b")])
    one_line_error(r, "a.scores.json", "imported")
    # the store it came from holds every cell already
    r = CliRunner().invoke(main, ["sweep", "--import-scores", str(scores), "--out",
                                  str(tmp_path / "a")])
    assert r.exit_code == 0 and "holds every cell" in r.output, r.output
    assert "imported" not in SweepStore(tmp_path / "a").meta()
    # exported again from the imported store: the same cells, the recorded digests kept
    again = tmp_path / "again.scores.json"
    assert CliRunner().invoke(main, ["sweep", "--export-scores", str(again), "--annotations",
                                     str(ann), "--out", str(tmp_path / "b")]).exit_code == 0
    one, two = json.loads(scores.read_text()), json.loads(again.read_text())
    for name in ("cells", "folds", "draws", "images", "models"):
        assert one["tables"][name] == two["tables"][name], name
    assert one["detections_sha256"] == two["detections_sha256"]
    meta = {k: json.loads(v) for k, v in two["tables"]["meta"]["rows"]}
    assert [i["file"] for i in meta["imported"]] == ["a.scores.json"]
    # a sweep's scores are no validation store's
    r = CliRunner().invoke(main, ["validate", "--import-scores", str(scores), "--store",
                                  str(tmp_path / "v")])
    one_line_error(r, "a.scores.json", "not of a validation store")


HEAD = b'{"format": "fidelity-scores", "version": 1, "kind": "sweep", '


@pytest.mark.parametrize(("content", "problem"), [
    (b"", "not a scores file"),
    (b"\x1f\x8b\x08\x00trunc", "not a scores file"),
    (b'{"format": "other"}', "not a scores file"),
    (b'{"format": "fidelity-scores", "version": 99}', "version 99"),
    (HEAD + b'"tables": {}}', "no cells and meta tables"),
    (HEAD + b'"tables": {"meta": {"columns": ["key", "value"], "rows": []}, "cells": '
     b'{"columns": ["model"], "rows": [["m", 1]]}}}', "table 'cells' is not columns and rows"),
    (HEAD + b'"tables": {"meta": {"columns": ["key", "value"], "rows": []}, "cells": '
     b'{"columns": ["model"], "rows": [["m"]]}}, "detections_sha256": {}}',
     "table 'cells' has columns model"),
    (HEAD + b'"tables": {"nonsense": {"columns": [], "rows": []}, "meta": {"columns": '
     b'["key", "value"], "rows": []}, "cells": {"columns": ["model"], "rows": []}}, '
     b'"detections_sha256": {}}', "table 'nonsense' is not one of a sweep store"),
])
def test_a_bad_scores_file_is_one_line(tmp_path, content, problem):
    bad = tmp_path / "bad file.json"
    bad.write_bytes(content)
    r = CliRunner().invoke(main, ["sweep", "--import-scores", str(bad), "--out",
                                  str(tmp_path / "s")])
    one_line_error(r, "bad file.json", problem)
    assert not (tmp_path / "s").exists()  # the file is read before a store is made


def test_export_needs_a_store_and_annotations_and_never_writes_over_them(data, tmp_path):
    images, ann, model = data
    r = CliRunner().invoke(main, ["sweep", "--export-scores", str(tmp_path / "x.json"),
                                  "--annotations", str(ann), "--out", str(tmp_path / "none")])
    one_line_error(r, "none", "no sweep store")
    sweep(data, tmp_path / "a", ["contrast-inc"], [0])
    r = CliRunner().invoke(main, ["sweep", "--export-scores", str(ann), "--annotations",
                                  str(ann), "--out", str(tmp_path / "a")])
    one_line_error(r, "ann.json")
    r = CliRunner().invoke(main, ["sweep", "--export-scores", str(tmp_path / "x.json"),
                                  "--out", str(tmp_path / "a")])
    one_line_error(r, "--annotations")


def test_a_store_resumed_with_other_versions_records_both(data, tmp_path, monkeypatch):
    import onnxruntime

    first = sweep(data, tmp_path / "s", ["contrast-inc"], [0]).meta()["versions"]
    monkeypatch.setattr(onnxruntime, "__version__", "0.0-elsewhere")
    meta = sweep(data, tmp_path / "s", ["contrast-inc"], [0, 3]).meta()
    assert meta["versions"]["onnxruntime"] == "0.0-elsewhere"
    assert meta["versions_seen"] == [first, meta["versions"]]
    again = sweep(data, tmp_path / "s", ["contrast-inc"], [0, 3]).meta()["versions_seen"]
    assert len(again) == 2
    assert first["opencv"]  # OpenCV resizes the images for the detector
    # a store whose runs were recorded before OpenCV was named: resumed with the same
    # libraries, it does not gain a second set
    older = sweep(data, tmp_path / "o", ["contrast-inc"], [0])
    before = {k: v for k, v in older.meta()["versions"].items() if k != "opencv"}
    older.set_meta("versions", before)
    older.set_meta("versions_seen", [before])
    older.close()
    assert sweep(data, tmp_path / "o", ["contrast-inc"], [0, 3]).meta()["versions_seen"] \
        == [before]


def test_versions_recorded_before_a_library_was_named_are_the_same_set():
    from fidelity.coco.sweep import same_versions

    old = {"python": "3.11.7", "onnxruntime": "1.32.0"}
    assert same_versions(old, {**old, "opencv": "4.14.0"})
    assert not same_versions(old, {**old, "onnxruntime": "1.30.0", "opencv": "4.14.0"})
    assert same_versions({}, old)


def test_two_machines_shares_of_one_sweep_join_into_one_store(data, tmp_path):
    """Machine A runs contrast-inc, machine B contrast-dec (both the baseline), no shared
    disk: B's scores join A's store, which then reports what one run of both gives."""
    images, ann, model = data
    a = sweep(data, tmp_path / "a", ["contrast-inc"], [0, 3, 6])
    sweep(data, tmp_path / "b", ["contrast-dec"], [0, 3, 6])
    b_scores = tmp_path / "b.scores.json.gz"
    assert CliRunner().invoke(main, ["sweep", "--export-scores", str(b_scores), "--annotations",
                                     str(ann), "--out", str(tmp_path / "b")]).exit_code == 0
    r = CliRunner().invoke(main, ["sweep", "--import-scores", str(b_scores), "--out",
                                  str(tmp_path / "a")])
    assert r.exit_code == 0 and "2 cells of a sweep store (fake 2) imported" in r.output, \
        r.output
    joined = SweepStore(tmp_path / "a")
    assert len(joined.cells()) == 5
    status = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path / "a")])
    assert status.exit_code == 0 and "imported b.scores.json.gz (sha256 " in status.output
    assert ", 2 cells;" in status.output
    assert [i["cells"] for i in joined.meta()["imported"]] == [2]
    whole = sweep(data, tmp_path / "whole", ["contrast-inc", "contrast-dec"], [0, 3, 6])
    assert tables_json(joined, ann) == tables_json(whole, ann)
    # A's own baseline stays A's: its detections are still there
    assert joined.detections("fake", "baseline", 0) and a.cell("fake", "baseline", 0)


def test_shares_of_different_runs_do_not_join(data, tmp_path):
    images, ann, model = data
    sweep(data, tmp_path / "a", ["contrast-inc"], [0, 3])
    sweep(data, tmp_path / "b", ["contrast-dec"], [0, 3])
    export = ["sweep", "--export-scores", str(tmp_path / "b.json"), "--annotations", str(ann),
              "--out", str(tmp_path / "b")]
    join = ["sweep", "--import-scores", str(tmp_path / "b.json"), "--out", str(tmp_path / "a")]
    b = SweepStore(tmp_path / "b")
    sha = b.models()["fake"].sha256
    # the same model name from another file
    with b.db as db:
        db.execute("UPDATE models SET sha256='0000' WHERE model='fake'")
    assert CliRunner().invoke(main, export).exit_code == 0
    one_line_error(CliRunner().invoke(main, join), "b.json", "model 'fake'", "different file")
    # other annotations
    with b.db as db:
        db.execute("UPDATE models SET sha256=? WHERE model='fake'", (sha,))
    inputs = b.meta()["inputs"]
    b.set_meta("inputs", inputs | {"annotations": {"file": "other.json", "sha256": "ab" * 32}})
    assert CliRunner().invoke(main, export).exit_code == 0
    one_line_error(CliRunner().invoke(main, join), "annotations", "differ")
    # other images under the same ids
    b.set_meta("inputs", inputs)
    with b.db as db:
        db.execute("UPDATE images SET sha256='ff' WHERE image_id=1")
    assert CliRunner().invoke(main, export).exit_code == 0
    one_line_error(CliRunner().invoke(main, join), "images", "differ")
    assert len(SweepStore(tmp_path / "a").cells()) == 2  # nothing joined


def test_a_cell_finished_during_the_export_waits_for_the_next(data, tmp_path, monkeypatch):
    """A run going on finishes a cell after the export completed the fold and draw scores:
    the file leaves it out (its scores would be missing where it is imported)."""
    from fidelity.coco.scores import export_scores
    from fidelity.coco.scoring import load_annotations

    images, ann, model = data
    store = sweep(data, tmp_path / "s", ["contrast-inc"], [0, 3, 6])
    original = SweepStore.complete_scores

    def then_a_cell_finishes(self, coco, method="auto"):
        n = original(self, coco, method)
        with self.db:  # as if contrast-inc 6 had finished just now
            self.db.execute("DELETE FROM draws WHERE transform='contrast-inc' AND target=6")
        return n

    monkeypatch.setattr(SweepStore, "complete_scores", then_a_cell_finishes)
    t = export_scores(store, load_annotations(ann), tmp_path / "s.json")
    doc = json.loads((tmp_path / "s.json").read_text())
    assert t.cells == 2 and sorted(r[1:3] for r in doc["tables"]["cells"]["rows"]) == [
        ["baseline", 0.0], ["contrast-inc", 3.0]]
    assert '["fake", "contrast-inc", 6.0]' not in doc["detections_sha256"]


def test_cross_machine_digest_reads_a_store_folder_or_its_sqlite_file(data, tmp_path):
    """benchmarks.tools.cross_machine digest: per cell, one digest per image of its detections; the
    store's folder and its sqlite file (a copy brought back from a lent machine) read alike."""
    from benchmarks.tools.cross_machine import digest_store

    store = sweep(data, tmp_path / "s", ["contrast-inc"], [0, 3])
    images = store.db.execute("SELECT COUNT(*) FROM images").fetchone()[0]
    store.close()
    doc = digest_store(tmp_path / "s")
    assert sorted(doc["digests"]) == ["baseline:0", "contrast-inc:3"]
    assert all(len(d) == images for d in doc["digests"].values())
    assert doc["versions"]["opencv"] and len(doc["cells"]) == 2
    assert digest_store(tmp_path / "s" / "sweep.sqlite") == doc
