"""``fidelity verify --chain``: record -> table -> scores file -> rows rebuilt from it.

The references are the files themselves: SHA-256 computed here with hashlib, and the rows
of the shipped tables against the rows the committed scores files make again. Each broken
link is made on copies in a temporary folder (the repository is not touched)."""

from __future__ import annotations

import gzip
import hashlib
import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.coco.tables.rebuild import row_differences, table_rows
from fidelity.report.chain import chain_tables, table_chain

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "fidelity" / "data"
MEASURED = DATA / "prediction" / "coco1000-measured.json"
DIRECTIONAL = DATA / "prediction" / "coco1000-directional.json"


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def statuses(findings) -> dict[str, str]:
    return {f.name: f.status for f in findings}


@pytest.mark.parametrize("table", ["prediction/coco1000-measured.json",
                                   "prediction/coco1000-directional.json",
                                   "properties/coco1000-sharpness.json",
                                   "properties/coco1000-noise.json"])
def test_every_shipped_table_names_committed_scores_files_by_path_and_hash(table):
    """Issue 58: a measured table's provenance names the scores files it is rebuilt from by
    their path in the repository and SHA-256, and each is there with that hash; nothing is
    named that only git history holds."""
    doc = json.loads((DATA / table).read_text())
    entries = doc["provenance"]["scores_files"]
    assert entries
    for e in entries:
        path = REPO / e["path"]
        assert path.is_file() and e["path"].startswith("reports/coco/")
        assert sha256(path) == e["sha256"]
    named = {e["path"] for e in entries}
    assert named == ({"reports/coco/degradations/degradations.scores.json.gz"}
                     if table.startswith("properties") else
                     {f"reports/coco/resweep/{m}.scores.json.gz"
                      for m in doc["provenance"]["models"]})
    assert "earlier" not in doc["provenance"]
    assert "reports-coco-tables-at" not in json.dumps(doc["provenance"])


def test_a_check_record_names_every_table_and_the_chain_holds(tmp_path, monkeypatch):
    """A check's record: the prediction table and the sharpness and noise tables, each with
    its SHA-256; verify --chain walks each to its rows, exit 0."""
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", "nikon-5100", "-q",
                                  "--out", "rep", "--evidence", "r.json"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "r.json").read_text())
    tables = {t["name"]: t for t in chain_tables(doc)}
    assert set(tables) == {"coco1000-measured", "coco1000-sharpness", "coco1000-noise",
                           "coco1000-directional"}
    for t in tables.values():
        assert t["sha256"] == sha256(Path(t["path"]))
    props = {p["name"]: p for p in doc["subjects"][0]["property_tables"]}
    assert props["coco1000-noise"]["scores_files"][0]["path"] == \
        "reports/coco/degradations/degradations.scores.json.gz"
    r = CliRunner().invoke(main, ["verify", "--chain", "r.json", "--json", "v.json"])
    assert r.exit_code == 0, r.output
    chain = [f for f in json.loads((tmp_path / "v.json").read_text())["findings"]
             if f["kind"] == "chain"]
    assert {f["status"] for f in chain} == {"linked"}
    # measured: table, 4 scores files, rows; sharpness and noise: table, scores file, rows;
    # directional: table, the same 4 scores files, rows
    assert len(chain) == 6 + 3 + 3 + 6
    assert "chain: 18 links hold" in r.output


def _entry(path: Path) -> dict[str, str]:
    return {"name": "coco1000-measured", "path": str(path), "sha256": sha256(path)}


def test_an_edited_table_row_breaks_the_rows_link(tmp_path):
    doc = json.loads(MEASURED.read_text())
    curve = next(c for c in doc["curves"] if c["model"] == "yolox_nano")
    point = next(p for p in curve["points"] if p["delta_e"] == 3.0)
    point["dmap_points"] = round(point["dmap_points"] - 0.1, 4)  # a smaller loss, forged
    copy = tmp_path / "edited.json"
    copy.write_text(json.dumps(doc), encoding="utf-8")
    found = table_chain(_entry(copy), None, tmp_path)
    assert [f.status for f in found] == ["linked"] * 5 + ["broken"]
    rows = found[-1]
    assert rows.name == "coco1000-measured -> rows"
    assert "1 of 74 rows differ" in rows.detail and "yolox_nano ΔE 3: dmap_points" in rows.detail


def test_a_table_changed_after_the_record_breaks_the_table_link(tmp_path):
    copy = tmp_path / "t.json"
    shutil.copyfile(MEASURED, copy)
    entry = _entry(copy) | {"sha256": "0" * 64}
    found = table_chain(entry, None, tmp_path)
    assert [(f.name, f.status) for f in found] == [("coco1000-measured -> table", "broken")]


def _edited_scores(src: Path, dst: Path, model: str) -> None:
    """A copy of the scores file ``src`` with one finished cell's mAP of ``model`` lowered."""
    doc = json.loads(gzip.decompress(src.read_bytes()))
    cells = doc["tables"]["cells"]
    i_model, i_map, i_status, i_t = (cells["columns"].index(c)
                                     for c in ("model", "map", "status", "transform"))
    row = next(r for r in cells["rows"] if r[i_model] == model and r[i_status] == "done"
               and r[i_t] != "baseline" and r[i_map] is not None)
    row[i_map] -= 0.05
    dst.write_bytes(gzip.compress(json.dumps(doc).encode()))


def test_an_edited_scores_file_breaks_its_link_or_the_rows(tmp_path):
    """A table whose scores files are copies here: an edited copy fails on its hash; a table
    that names the edited copy with its new hash (forged with it) fails on its rows."""
    doc = json.loads(MEASURED.read_text())
    for e in doc["provenance"]["scores_files"]:
        copy = tmp_path / Path(e["path"]).name
        shutil.copyfile(REPO / e["path"], copy)
        e["path"] = str(copy)
    table = tmp_path / "t.json"
    table.write_text(json.dumps(doc), encoding="utf-8")
    assert {f.status for f in table_chain(_entry(table), None, tmp_path)} == {"linked"}

    edited = tmp_path / "yolox_nano.scores.json.gz"
    _edited_scores(REPO / "reports/coco/resweep/yolox_nano.scores.json.gz", edited,
                   "yolox_nano")
    found = table_chain(_entry(table), None, tmp_path)
    assert found[-1].status == "broken"
    assert found[-1].name == "coco1000-measured -> scores file yolox_nano.scores.json.gz"
    assert f"SHA-256 {sha256(edited)[:12]}" in found[-1].detail

    for e in doc["provenance"]["scores_files"]:
        if e["path"] == str(edited):
            e["sha256"] = sha256(edited)
    table.write_text(json.dumps(doc), encoding="utf-8")
    found = table_chain(_entry(table), None, tmp_path)
    assert [f.status for f in found] == ["linked"] * 5 + ["broken"]
    assert "rows differ" in found[-1].detail


def test_verify_chain_exits_1_naming_the_broken_link(tmp_path, monkeypatch):
    """The command line: a check with an edited copy of the table, verify --chain exit 1."""
    doc = json.loads(MEASURED.read_text())
    doc["curves"][0]["points"][3]["dmap_relative"] += 1.0
    copy = tmp_path / "coco1000-measured.json"
    copy.write_text(json.dumps(doc), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", "nikon-5100", "-q",
                                  "--table", str(copy), "--no-report",
                                  "--evidence", "r.json"])
    assert r.exit_code in (0, 1), r.output
    r = CliRunner().invoke(main, ["verify", "r.json"])
    assert r.exit_code == 0, r.output  # every file as recorded: only the chain sees it
    r = CliRunner().invoke(main, ["verify", "--chain", "r.json"])
    assert r.exit_code == 1, r.output
    assert "chain coco1000-measured -> rows: broken; 1 of 74 rows differ" in r.output
    assert "NOT VERIFIED" in r.output and "chain broken at coco1000-measured -> rows" in \
        r.output


def test_annotations_without_chain_is_an_input_error(tmp_path):
    record = tmp_path / "r.json"
    record.write_text("{}", encoding="utf-8")
    r = CliRunner().invoke(main, ["verify", str(record), "--annotations", str(record)])
    assert r.exit_code == 2


def test_row_differences_names_each_row_and_can_leave_out_the_standard_errors():
    doc = json.loads(MEASURED.read_text())
    other = json.loads(MEASURED.read_text())
    point = other["curves"][0]["points"][2]
    point["dmap_points_se"] = 9.0
    point["source"] = "other words"  # words are not compared
    n, differ = row_differences(doc, other)
    assert n == len(table_rows(doc)) and len(differ) == 1 and "dmap_points_se" in differ[0]
    assert row_differences(doc, other, standard_errors=False)[1] == []


def test_row_differences_allow_another_processors_last_bits_only():
    """A chart calibration measured again on another CPU differs in its last bits (seen:
    0.11865259369943015 against ...014): the same number; a change in the 11th digit is not."""
    doc = json.loads(MEASURED.read_text())
    other = json.loads(MEASURED.read_text())
    point = other["curves"][0]["points"][2]
    value = point["dmap_points"]
    assert isinstance(value, float) and value != 0
    point["dmap_points"] = value * (1 + 4e-16)
    assert row_differences(doc, other)[1] == []
    point["dmap_points"] = value * (1 + 1e-10)
    differ = row_differences(doc, other)[1]
    assert len(differ) == 1 and "dmap_points" in differ[0]


@pytest.mark.shared
def test_fidelity_tables_of_the_committed_scores_files_writes_the_shipped_tables(shared,
                                                                                 tmp_path):
    """The shipped colour tables are what ``fidelity tables`` makes of the four committed
    scores files, provenance and all (so nothing in them is reachable only through git
    history)."""
    named = json.loads(MEASURED.read_text())["provenance"]["scores_files"]
    files = [str(REPO / e["path"]) for e in named]  # in the order the table names them
    out = {k: tmp_path / f"{k}.json" for k in ("measured", "directional")}
    r = CliRunner().invoke(main, ["tables", *files, "--no-progress", "--out", str(tmp_path / "r"),
                                  "--annotations", str(shared / "coco" / "annotations"
                                                       / "instances_val2017_subset.json"),
                                  "--prediction", str(out["measured"]),
                                  "--directional", str(out["directional"])])
    assert r.exit_code == 0, r.output
    for k, path in out.items():
        assert json.loads(path.read_text()) == json.loads(
            (DATA / "prediction" / f"coco1000-{k}.json").read_text()), k


def test_several_store_arguments_must_all_be_scores_files(tmp_path):
    scores = REPO / "reports/coco/resweep/yolox_nano.scores.json.gz"
    r = CliRunner().invoke(main, ["tables", str(scores), str(tmp_path), "--out",
                                  str(tmp_path / "r")])
    assert r.exit_code == 2
    assert f"{tmp_path}: not a scores file" in r.output


def test_an_edited_directional_standard_error_breaks_the_rows_link(tmp_path, shared):
    """The direction-aware table's per-column SEs are rebuilt from the committed scores files
    (with the COCO annotations): one forged SE breaks the rows link, naming the row."""
    doc = json.loads(DIRECTIONAL.read_text())
    curve = next(c for c in doc["families"]["hue"]["curves"] if c["model"] == "yolox_nano")
    point = next(p for p in curve["points"] if p["delta_e"] == 3.0)
    point["dap_person_points_se"] = round(point["dap_person_points_se"] / 2, 4)  # forged
    copy = tmp_path / "edited.json"
    copy.write_text(json.dumps(doc), encoding="utf-8")
    entry = {"name": "coco1000-directional", "path": str(copy), "sha256": sha256(copy)}
    found = table_chain(entry, None, tmp_path)
    assert [f.status for f in found] == ["linked"] * 5 + ["broken"]
    assert "family hue yolox_nano ΔE 3: dap_person_points_se" in found[-1].detail
