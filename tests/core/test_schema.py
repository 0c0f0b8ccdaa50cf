"""The declarative schemas (fidelity.core.schema) and the input-file rules built on them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from fidelity.core import schema as sc
from fidelity.core.errors import InputFileError, InvalidValueError

SCHEMA = sc.Table(fields=(
    sc.Field("name", sc.String(nonempty=True), required=True),
    sc.Field("mode", sc.String(choices=("none", "gains"), lower=True), default="none"),
    sc.Field("gains", sc.ListOf(sc.Number(lo=0, lo_open=True), min_items=3, max_items=3,
                                describe="3 positive numbers"), when=("mode", ("gains",))),
    sc.Field("gain", sc.Number(lo=0, hi=10)),
    sc.Field("ev", sc.Number(nullable=True)),
    sc.Field("bits", sc.Integer(lo=1, hi=16)),
    sc.Field("section", sc.Table(fields=(sc.Field("x", sc.Number(), default=1.0),)),
             default={}),
), rules=(sc.RequiredWhen("gains", "mode", ("gains",)), sc.Exclusive("gain", "ev"),
          sc.Check(lambda t: ("bits", "must be even") if t.get("bits", 2) % 2 else None)))


def problem(doc: object, **kw: bool) -> str:
    with pytest.raises(sc.SchemaError) as info:
        sc.validate(doc, SCHEMA, "f.toml", **kw)
    return str(info.value)


def test_valid_documents_get_their_defaults() -> None:
    v = sc.validate({"name": "a", "mode": "GAINS", "gains": [1, 2, 3]}, SCHEMA, "f")
    assert v == {"name": "a", "mode": "gains", "gains": [1.0, 2.0, 3.0],
                 "section": {"x": 1.0}}
    # a field read only for another mode is ignored, whatever it holds
    assert "gains" not in sc.validate({"name": "a", "gains": "junk"}, SCHEMA, "f")


@pytest.mark.parametrize(("doc", "where", "what"), [
    (None, "top level", "must be a table, got null"),
    ({}, "name", "required"),
    ({"name": ""}, "name", "non-empty"),
    ({"name": "a", "nope": 1}, "nope", "unknown field; known: name, mode"),
    ({"name": "a", "mode": "x"}, "mode", "must be one of none, gains, got 'x'"),
    ({"name": "a", "mode": "gains"}, "gains", "required when mode = 'gains'"),
    ({"name": "a", "mode": "gains", "gains": [1, 2]}, "gains", "expected 3 positive numbers"),
    ({"name": "a", "mode": "gains", "gains": [1, 2, -3]}, "gains", "expected 3 positive"),
    ({"name": "a", "gain": math.nan}, "gain", "must be a finite number, got nan"),
    ({"name": "a", "gain": True}, "gain", "must be a finite number, got True"),
    ({"name": "a", "gain": 10**400}, "gain", "must be a finite number"),
    ({"name": "a", "gain": 11}, "gain", "must be <= 10, got 11"),
    ({"name": "a", "gain": -1}, "gain", "must be >= 0, got -1"),
    ({"name": "a", "gain": 1, "ev": 2}, "ev", "give either gain or ev, not both"),
    ({"name": "a", "bits": 2.0}, "bits", "must be an integer in [1, 16], got 2.0"),
    ({"name": "a", "bits": 3}, "bits", "must be even"),
    ({"name": "a", "section": {"x": "y"}}, "section.x", "must be a finite number, got 'y'"),
    ({"name": "a", "section": []}, "section", "must be a table, got a list"),
])
def test_problems_name_the_file_the_field_and_the_problem(doc: object, where: str,
                                                          what: str) -> None:
    msg = problem(doc)
    assert msg.startswith(f"f.toml: {where}: "), msg
    assert what in msg, msg


def test_sections_and_lists_in_locations() -> None:
    assert sc.format_location(("curves", 2, "points", 0, "delta_e")) == \
        "curves[2].points[0].delta_e"
    assert sc.format_location(("noise", "read_noise"), sections=True) == "[noise].read_noise"
    assert problem({"name": "a", "section": {"x": None}}, sections=True).startswith(
        "f.toml: [section].x: ")


def test_schema_errors_are_input_and_value_errors() -> None:
    assert issubclass(sc.SchemaError, InputFileError)
    assert issubclass(sc.SchemaError, InvalidValueError)


def test_depth_is_bounded_without_recursion() -> None:
    deep: object = 1
    for _ in range(100_000):  # far beyond Python's recursion limit
        deep = [deep]
    with pytest.raises(sc.SchemaError, match="nested more than 32 levels deep"):
        sc.check_depth(deep, "x.json")
    shared: list[object] = []
    wide = [shared] * 10_000  # a node shared by YAML aliases is walked once
    sc.check_depth(wide, "x.yaml")


@pytest.mark.parametrize(("name", "text", "what"), [
    ("a.json", "{", "not valid JSON"),
    ("a.json", '{"x": NaN}', "NaN is not a JSON number"),
    ("a.json", '{"x": -Infinity}', "-Infinity is not a JSON number"),
    ("a.json", '{"x": 1e400}', "beyond the range"),
    ("a.json", '{"x": ' + "9" * 5000 + "}", "not valid JSON"),
    ("a.json", "[" * 5000 + "]" * 5000, "nested"),
    ("a.toml", "x = " + "[" * 3000 + "]" * 3000, "nested"),
    ("a.toml", "x = ", "invalid TOML"),
    ("a.yaml", "x: [1", "invalid YAML"),
    ("a.yaml", "x: " + "[" * 1200 + "]" * 1200, "nested"),
    ("a.txt", "{}", "expected a .json, .toml, .yaml, .yml file"),
], ids=lambda v: str(v)[:20])
def test_documents_that_cannot_be_read(tmp_path: Path, name: str, text: str,
                                       what: str) -> None:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(sc.SchemaError) as info:
        sc.load_document(path)
    assert str(info.value).startswith(str(path)) and what in str(info.value), info.value


def test_load_document_limits_and_encodings(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    path.write_bytes(b'{"x": "caf\xe9"}')
    with pytest.raises(sc.SchemaError, match="not UTF-8 text"):
        sc.load_document(path)
    path.write_text(json.dumps({"x": list(range(1000))}))
    with pytest.raises(sc.SchemaError, match="MiB, more than"):
        sc.load_document(path, max_bytes=100)
    with pytest.raises(sc.SchemaError, match="does not exist"):
        sc.load_document(tmp_path / "missing.json")
    assert sc.load_document(path)["x"][-1] == 999


def test_mitsuba_template_schema(tmp_path: Path) -> None:
    from fidelity.camera.mitsuba import load_template

    assert load_template()["type"] == "scene"
    doc = load_template()
    del doc["patch"]["bsdf"]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(sc.SchemaError, match=r"Mitsuba scene template\): patch.bsdf: required"):
        load_template(path)


def test_coco_annotations_schema(tmp_path: Path) -> None:
    pytest.importorskip("pycocotools")
    from fidelity.coco.scoring import load_annotations

    doc = {"images": [{"id": 1, "file_name": "a.jpg"}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 3, "bbox": [0, 0, 2, 2],
                            "area": 4}],
           "categories": [{"id": 3, "name": "car"}]}
    path = tmp_path / "a.json"
    path.write_text(json.dumps(doc))
    assert len(load_annotations(path).anns) == 1
    for change, where in ((lambda d: d["annotations"][0].update(image_id=2),
                           "annotations[0].image_id: 2 is not an image id"),
                          (lambda d: d["annotations"][0].update(category_id=1),
                           "annotations[0].category_id: 1 is not a category id"),
                          (lambda d: d.update(categories=[]),
                           "categories: must have at least 1 item, got 0"),
                          (lambda d: d.update(annotations=[]),
                           "annotations: must have at least 1 item, got 0"),
                          (lambda d: d["images"][0].pop("file_name"),
                           "images[0].file_name: required")):
        bad = json.loads(json.dumps(doc))
        change(bad)
        path.write_text(json.dumps(bad))
        with pytest.raises(sc.SchemaError, match=f"{path}: {where}".replace("[", r"\[")
                           .replace("]", r"\]")):
            load_annotations(path)


def test_store_provenance_schema(tmp_path: Path) -> None:
    import sqlite3

    from fidelity.coco.tables.provenance import check_store_meta

    db = sqlite3.connect(tmp_path / "s.sqlite")
    db.execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
    db.execute("INSERT INTO meta VALUES ('grid', ?)",
               (json.dumps({"transforms": ["hue"], "targets": [0, 3]}),))
    check_store_meta(db, "s.sqlite")
    db.execute("INSERT OR REPLACE INTO meta VALUES ('grid', '3')")
    with pytest.raises(sc.SchemaError, match=r"s.sqlite \(provenance\): grid: must be a table"):
        check_store_meta(db, "s.sqlite")
    db.execute("INSERT OR REPLACE INTO meta VALUES ('data', 'not json')")
    with pytest.raises(sc.SchemaError, match="data: not valid JSON"):
        check_store_meta(db, "s.sqlite")
