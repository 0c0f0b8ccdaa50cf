"""Worst-case tables, paper comparison and report from a hand-made store (hand-computed values)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from fidelity.coco.sweep import SweepStore
from fidelity.coco.tables.build import build_tables
from fidelity.coco.tables.colour import TablesResult, compare_with_paper, tables_result
from fidelity.coco.tables.grid import model_size
from fidelity.coco.tables.prediction import prediction_table
from fidelity.coco.tables.worst import WorstCaseRow
from fidelity.prediction.tablefile import parse_prediction_table
from fidelity.report.coco import tables_document, write_tables_report
from fidelity.report.document import Document, Table

TRANSFORMS = ["contrast-inc", "hue", "saturation-inc"]


def score(m: float, person: float, bicycle: float) -> SimpleNamespace:
    return SimpleNamespace(map=m, map50=m + 0.2, map75=m, ap={"person": person,
                                                              "bicycle": bicycle})


@pytest.fixture
def store(tmp_path) -> SweepStore:
    return make_store(tmp_path)


def make_store(folder: Path) -> SweepStore:
    """A hand-made sweep store: three models, three transforms, ΔE 0, 3 and 6."""
    s = SweepStore(folder)
    s.set_meta("grid", {"transforms": TRANSFORMS, "targets": [0, 3, 6]})
    for model, base in (("yolo11n", 0.50), ("yolov8n", 0.40), ("yolov8s", 0.45)):
        s.register_model(model, model + ".onnx", model * 4, None, {"conventions": {"conf": 0.001}})
        s.finish_cell(model, "baseline", 0, param=None, status="done", images=10,
                      score=score(base, 0.6, 0.3))
    f = s.finish_cell
    # yolo11n: at ΔE 3 contrast-inc loses 5 points (10 %), hue 0.5 points
    f("yolo11n", "contrast-inc", 3, param=1.1, status="done", images=10,
      score=score(0.45, 0.54, 0.27))
    f("yolo11n", "hue", 3, param=5.0, status="done", images=10, score=score(0.495, 0.5, 0.3))
    f("yolo11n", "saturation-inc", 3, param=1.2, status="done", images=10,
      score=score(0.48, 0.59, 0.2))
    f("yolo11n", "saturation-inc", 6, param=None, status="unreachable", reason="r")
    f("yolo11n", "contrast-inc", 6, param=1.3, status="done", images=10,
      score=score(0.40, 0.50, 0.25))
    # yolov8n: only one transform finished at ΔE 3 (partial row); 2 points = 5 %
    f("yolov8n", "hue", 3, param=5.0, status="done", images=10, score=score(0.38, 0.6, 0.3))
    return s


def test_model_size() -> None:
    assert [model_size(m) for m in ("yolo11n-int8dyn", "yolov8s", "yolox_nano", "yolov10x",
                                    "yolov5mu", "detr")] == ["n", "s", "n", "x", "m", "any"]


def test_worst_case_rows_by_hand(store) -> None:
    t = build_tables(store)
    rows = {r.delta_e: r for r in t.worst_case["yolo11n"]}
    r3 = rows[3.0]
    assert r3.worst_transform == "contrast-inc"
    assert r3.dmap_points == pytest.approx(5.0) and r3.dmap_relative == pytest.approx(10.0)
    # person and bicycle are their own worst cases: hue for person (10 pts), sat for bicycle
    assert r3.dap_person_points == pytest.approx(10.0)
    assert r3.dap_bicycle_points == pytest.approx(10.0)
    assert r3.transforms_done == 3 and not r3.partial
    r6 = rows[6.0]
    assert r6.unreachable == ("saturation-inc",) and r6.transforms_reachable == 2
    assert r6.partial  # hue at ΔE 6 is missing
    v8 = {r.delta_e: r for r in t.worst_case["yolov8n"]}[3.0]
    assert v8.partial and v8.dmap_relative == pytest.approx(5.0)
    # size class n: worst over yolo11n and yolov8n
    n3 = {r.delta_e: r for r in t.size_classes["n"]}[3.0]
    assert n3.worst_model == "yolo11n" and n3.dmap_points == pytest.approx(5.0)
    assert "s" in t.size_classes and t.models["yolov8s"].size == "s"
    # the unreachable cell is kept, without scores
    (unr,) = [c for c in t.cells["yolo11n"] if not c.done]
    assert (unr.transform, unr.delta_e, unr.map) == ("saturation-inc", 6.0, None)


def test_paper_comparison_verdicts(store) -> None:
    claims = {c.claim: c for c in compare_with_paper(build_tables(store))}
    c3 = claims["ΔE ≤ 3 keeps worst-case ΔmAP below 1 %"]
    assert c3.verdict.startswith("disagrees: exceeded in points and as a share")
    assert "10.00 %" in c3.evidence
    person = claims["person is more sensitive than the mean (relative ΔAP > ΔmAP)"]
    # cells with ΔmAP > 0.5 %: 11n c-inc@3 (10 vs 10: not more), sat@3 (1.7 vs 4: no),
    # hue@3 (16.7 vs 1: yes), c-inc@6 (16.7 vs 20: no), v8n hue@3 (0 vs 5: no) -> 1 of 5
    assert person.verdict == "disagrees" and "1 of 5" in person.evidence
    # not every transform has ΔE <= 12 for every model: ranking not claimed
    assert claims["hue changes hurt least"].verdict == "not enough data"


def test_tables_json_round_trips(store, tmp_path) -> None:
    """tables.json is the result's to_json, and reading it back gives the same records."""
    result = tables_result(store)
    written = write_tables_report(result, tmp_path / "rep")
    data = json.loads(written["tables.json"].read_text())
    assert data == result.to_json()
    assert set(data) == {"tables", "comparison", "delta_e_limits"}
    back = TablesResult.from_json(data)
    assert back == result
    # the baseline row has no standard-error keys; the others carry them (None here)
    rows = data["tables"]["worst_case"]["yolo11n"]
    assert "dmap_points_se" not in rows[0] and rows[1]["dmap_points_se"] is None
    # a report rebuilt from the JSON alone is the same document
    assert render_both(tables_document(back, figures={})) == render_both(
        tables_document(result, figures={}))


def one_line_error(res, *names: str) -> None:  # type: ignore[no-untyped-def]
    """Exit code 2 and one line ``fidelity: error: ...`` that names each of ``names``."""
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), res.output
    assert all(n in lines[0] for n in names), (names, res.output)


def render_both(doc: Document) -> tuple[str, str]:
    from fidelity.report.html import render_html, render_markdown

    return render_html(doc), render_markdown(doc)


def tables_of(doc: Document, title: str) -> list[Table]:
    """The tables of the section named ``title``."""
    (sec,) = [s for s in doc.sections if s.title == title]
    return [b for b in sec.blocks if isinstance(b, Table)]


def test_prediction_table_follows_schema(store) -> None:
    obj = prediction_table(build_tables(store))
    table = parse_prediction_table(obj, "test")
    assert obj["kind"] == "measured"
    sizes = {c["size"] for c in obj["curves"] if c["model"] is None}
    assert sizes == {"n", "s"}
    n = next(c for c in obj["curves"] if c["model"] is None and c["size"] == "n")
    # ΔE 6 is partial for every model (hue not measured): a partial row could understate the
    # worst case, so it stays out of the prediction table and provenance lists it.
    assert [p["delta_e"] for p in n["points"]] == [0.0, 3.0]
    assert n["points"][1]["dmap_points"] == pytest.approx(5.0)
    assert "yolo11n" in n["points"][1]["source"] and "yolov8n" not in n["points"][1]["source"]
    omitted = obj["provenance"]["omitted_partial_points"]
    assert "n ΔE 6" in omitted and "yolo11n ΔE 6" in omitted and "yolov8n ΔE 3" in omitted
    assert all(not p["partial"] for c in obj["curves"] for p in c["points"])
    assert table.curves


def test_delta_e_limits_by_hand(store) -> None:
    """yolo11n's curve: ΔE 0 -> 0, ΔE 3 -> 5 points = 10 % (linear between): 1 point at ΔE
    0.6, 3 points at 1.8; 1 % at 0.3, 3 % at 0.9; 10 % and 10 points hold to the end (ΔE 3)."""
    from fidelity.coco.tables.colour import delta_e_limits

    tables = build_tables(store)
    limits = {(r.size, r.model): r.limits for r in delta_e_limits(tables)}
    assert ("n", "yolov8n") not in limits  # its ΔE 3 row is partial: only the baseline left
    got = [(x.delta_e, x.status) for x in limits[("n", "yolo11n")]]
    want = [(0.3, "inside"), (0.9, "inside"), (3.0, "whole-range"),
            (0.6, "inside"), (1.8, "inside"), (3.0, "whole-range")]
    for (de, status), (w, ws) in zip(got, want, strict=True):
        assert de == pytest.approx(w, abs=1e-5) and status == ws
    doc = tables_document(TablesResult(tables, (), tuple(delta_e_limits(tables))),
                          figures={})
    (tab,) = tables_of(doc, "ΔE limits our worst cases imply")
    assert ("yolo11n", "0.30", "0.90", "3.00+", "0.60", "1.80", "3.00+") in tab.rows


def test_report_files(store, tmp_path) -> None:
    out = tmp_path / "rep"
    written = write_tables_report(tables_result(store), out, tmp_path / "pred.json")
    assert set(written) >= {"report.md", "report.html", "tables.json", "prediction",
                            "worst_case.svg", "map_vs_de_yolo11n.svg"}
    md = (out / "report.md").read_text()
    data = json.loads((out / "tables.json").read_text())
    row = {r["delta_e"]: r for r in data["tables"]["worst_case"]["yolo11n"]}[3.0]
    assert row["worst_transform"] == "contrast-inc"
    assert (row["dmap_points"], row["dmap_relative"]) == (pytest.approx(5.0), pytest.approx(10.0))
    for name in ("worst_case.svg", "map_vs_de_yolov8n.svg"):
        assert (out / name).read_text("utf-8").startswith("<svg")
        assert f"]({name})" in md  # the Markdown links its figure files


def test_report_structure(store) -> None:
    """Headline (and its figure) before any table, every figure embedded, plots before the
    long tables, the per-cell tables and the coverage folded, Markdown and HTML from the same
    document, no Python dict text."""
    import re

    from fidelity.report.html import markdown_inline

    doc = tables_document(tables_result(store))
    html, md = render_both(doc)
    figures = doc.figures()
    assert doc.headline.figure is not None and doc.headline.figure.name == "worst_case.svg"
    # one mAP plot per model with transformed cells (yolov8s has only its baseline)
    assert [f.name for f in figures] == ["worst_case.svg", "map_vs_de_yolo11n.svg",
                                         "map_vs_de_yolov8n.svg"]
    assert html.count("<svg") == len(figures) and "<img" not in html
    assert html.index('class="headline') < html.index("<svg") < html.index("<table")
    # the headline names every model's worst case at the paper's thresholds, with its number
    tables = tables_result(store).tables
    lines = {ln.split(":")[0]: ln for ln in doc.headline.message.splitlines()}
    for m, rows in tables.worst_case.items():
        at3 = [r for r in rows if 0 < r.delta_e <= 3]
        if at3:
            worst = max(at3, key=lambda r: r.dmap_relative or 0)
            assert f"**{worst.dmap_relative:.2f} %**" in lines[f"- {m}"], (m, lines)
    w11 = max((r for r in tables.worst_case["yolo11n"] if 0 < r.delta_e <= 3),
              key=lambda r: r.dmap_relative or 0)
    assert (w11.delta_e, w11.worst_transform) == (3.0, "contrast-inc")
    assert w11.dmap_relative == pytest.approx(10.0)
    # plots before the long tables; the tables of every cell are folded away
    titles = [s.title for s in doc.sections]
    assert titles.index("mAP against ΔE, per model") < titles.index("Worst case: yolo11n")
    folded = {s.title for s in doc.sections if s.folded}
    assert folded == {"Coverage (which cells this report is built from)",
                      "All cells: yolo11n", "All cells: yolov8n"}
    assert html.count("<details>") == len(folded)
    assert titles.index("All cells: yolo11n") > titles.index("Method")
    details = html[html.index("<details><summary>All cells: yolo11n"):]
    assert "contrast-inc" in details[:details.index("</details>")]
    # every cell of every table is in both renderings
    for s in doc.sections:
        for b in s.blocks:
            if isinstance(b, Table):
                for row in b.rows:
                    assert "| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" in md
                    for c in row:
                        assert str(markdown_inline(c)) in html
    assert not re.search(r"\{'|': ", md) and "{&#39;" not in html


def test_report_names_every_run_behind_a_models_cells(store, tmp_path) -> None:
    # yolov8n was swept without an image limit (10 cells on 10 images), then registered again
    # for the first 20 with one thread (an extension caught before any new cell finished): the
    # report names both runs and says the cells are reported on 10 images.
    store.register_model("yolov8n", "yolov8n.onnx", "yolov8n" * 4, 20, {"threads": 1})
    written = write_tables_report(tables_result(store), tmp_path / "rep", tmp_path / "pred.json")
    md = (tmp_path / "rep" / "report.md").read_text()
    assert any(x.startswith("- yolov8n: file") for x in md.splitlines())  # its run is named
    models = json.loads(written["tables.json"].read_text())["tables"]["models"]
    v8 = models["yolov8n"]
    assert v8["settings"]["threads"] == 1
    assert (v8["limit_images"], v8["images"]) == (20, 10)
    assert v8["settings"]["earlier"] == [{"limit_images": None, "conventions": {"conf": 0.001}}]
    assert "earlier" not in models["yolo11n"]["settings"]
    prov = json.loads(Path(written["prediction"]).read_text())["provenance"]["models"]
    assert prov["yolov8n"]["earlier_runs"] == [{"limit_images": None,
                                                "conventions": {"conf": 0.001}}]
    assert "earlier_runs" not in prov["yolo11n"]


def _model_at_de6(s: SweepStore, model: str, maps: dict[str, float]) -> None:
    """A model with baseline mAP 0.5 and the given mAP per transform at ΔE 6."""
    s.register_model(model, model + ".onnx", model * 64, None, {})
    s.finish_cell(model, "baseline", 0, param=None, status="done", images=5,
                  score=score(0.5, 0.6, 0.3))
    for t, m in maps.items():
        s.finish_cell(model, t, 6, param=1.0, status="done", images=5, score=score(m, 0.6, 0.3))


def test_ranking_claims_by_hand(tmp_path) -> None:
    s = SweepStore(tmp_path)
    s.set_meta("grid", {"transforms": ["contrast-dec", "contrast-inc", "hue"], "targets": [0, 6]})
    _model_at_de6(s, "m", {"contrast-dec": 0.46, "contrast-inc": 0.45, "hue": 0.495})
    claims = {c.claim: c for c in compare_with_paper(build_tables(s))}
    most = claims["contrast increase and decrease hurt detection most"]
    assert most.verdict == "agrees" and "contrast-inc 10.00 %" in most.evidence
    least = claims["hue changes hurt least"]
    assert least.verdict == "agrees" and "hue (1.00 %)" in least.evidence
    assert "(m at ΔE 6)" in most.evidence
    # two models measured at the same ΔE: said once, for every model
    _model_at_de6(s, "k", {"contrast-dec": 0.40, "contrast-inc": 0.45, "hue": 0.49})
    claims = {c.claim: c for c in compare_with_paper(build_tables(s))}
    most = claims["contrast increase and decrease hurt detection most"]
    assert "(every model at ΔE 6)" in most.evidence
    assert "contrast-dec 14.00 %, contrast-inc 10.00 %, hue 1.50 %" in most.evidence


def _explain_store(tmp_path):  # type: ignore[no-untyped-def]
    """Ground truth: a person box on images 1-3, one bicycle box on image 4 (4 images)."""
    import numpy as np

    from fidelity.coco.detectors import COCO80_CATEGORY_IDS, COCO80_NAMES
    from fidelity.coco.scoring import coco_from_dict

    cats = [{"id": c, "name": n} for c, n in zip(COCO80_CATEGORY_IDS, COCO80_NAMES, strict=True)]
    imgs = [{"id": i, "width": 200, "height": 200, "file_name": f"{i}.jpg"} for i in (1, 2, 3, 4)]
    anns = [{"id": i, "image_id": i, "category_id": 1, "bbox": [10, 10, 50, 80], "area": 4000,
             "iscrowd": 0} for i in (1, 2, 3)]
    anns.append({"id": 4, "image_id": 4, "category_id": 2, "bbox": [20, 20, 60, 60],
                 "area": 3600, "iscrowd": 0})
    coco = coco_from_dict({"images": imgs, "annotations": anns, "categories": cats})

    def d(*rows: tuple[float, ...]) -> np.ndarray:
        return np.array(rows, dtype=np.float32).reshape(-1, 6)

    person = {i: d((10, 10, 60, 90, 0.9, 0)) for i in (1, 2, 3)}
    base = person | {4: d((20, 20, 80, 80, 0.8, 1))}
    # the cell: the bicycle found, but below a false bicycle on image 1 -> AP 1/2
    cell = person | {1: d((10, 10, 60, 90, 0.9, 0), (120, 120, 160, 160, 0.95, 1)),
                     4: d((20, 20, 80, 80, 0.8, 1))}
    from fidelity.coco.scoring import evaluate_detections

    s = SweepStore(tmp_path)
    s.register_model("m", "m.onnx", "m" * 4, None, {})
    for t, e, dets in (("baseline", 0, base), ("hue", 3, cell)):
        s.add_detections("m", t, e, dets.items())
        s.finish_cell("m", t, e, param=None if t == "baseline" else 5.0, status="done",
                      images=4, score=evaluate_detections(coco, dets, [1, 2, 3, 4]))
    return s, coco, base, cell


def test_class_breakdown_by_hand(tmp_path) -> None:
    """One bicycle box ranked below a false positive: bicycle AP 1 -> 1/2, ΔmAP = 50/2 points."""
    from fidelity.coco.scoring import evaluate_detections
    from fidelity.coco.tables.classes import class_breakdown, explain_cell
    from fidelity.core.errors import InvalidValueError

    s, coco, base, cell = _explain_store(tmp_path)
    rows = class_breakdown(coco, base, cell, [1, 2, 3, 4])
    assert [(r.name, r.boxes) for r in rows] == [("bicycle", 1), ("person", 3)]
    assert rows[0].ap_baseline == pytest.approx(1.0) and rows[0].ap == pytest.approx(0.5)
    assert rows[0].dap_points == pytest.approx(50.0)
    assert rows[0].share_points == pytest.approx(25.0) and rows[1].share_points == 0
    direct = evaluate_detections(coco, base, method="pycocotools").map - evaluate_detections(
        coco, cell, method="pycocotools").map
    assert sum(r.share_points for r in rows) == pytest.approx(100 * direct)

    r = explain_cell(s, coco, "m", "hue", 3, rare_boxes=1)
    assert r.images == 4 and r.dmap_points == pytest.approx(25.0)
    assert r.rare.classes == 1 and r.rare.mean_dap_points == pytest.approx(50.0)
    assert r.rare.share_points == pytest.approx(25.0)
    assert r.common.classes == 1 and r.common.share_points == pytest.approx(0.0)
    with pytest.raises(InvalidValueError, match="cell m hue ΔE 6: not in the store"):
        explain_cell(s, coco, "m", "hue", 6)
    # on the first 3 images only persons, found alike: nothing lost
    assert explain_cell(s, coco, "m", "hue", 3, images=3).dmap_points == pytest.approx(0.0)
    with pytest.raises(InvalidValueError, match="--images 5 is not in 1..4"):
        explain_cell(s, coco, "m", "hue", 3, images=5)


def test_tables_explain_command(tmp_path) -> None:
    """`fidelity tables DIR --explain` prints the breakdown and writes it as JSON."""

    from click.testing import CliRunner

    from fidelity.cli import main

    s, coco, _, _ = _explain_store(tmp_path / "store")
    ann = tmp_path / "ann.json"
    ann.write_text(json.dumps(coco.dataset))
    out = tmp_path / "x.json"
    res = CliRunner().invoke(main, ["tables", str(tmp_path / "store"), "--annotations", str(ann),
                                    "--explain", "m:hue:3", "--rare-boxes", "1",
                                    "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "bicycle" in res.output and "person" in res.output  # the per-class rows printed
    data = json.loads(out.read_text())
    assert (data["model"], data["transform"], data["delta_e"]) == ("m", "hue", 3.0)
    assert (data["images"], data["rare_boxes"]) == (4, 1)
    assert [c["name"] for c in data["classes"]] == ["bicycle", "person"]
    assert data["dmap_points"] == pytest.approx(25.0)
    assert data["rare"] == {"classes": 1, "mean_dap_points": pytest.approx(50.0),
                            "share_points": pytest.approx(25.0)}
    assert data["common"] == {"classes": 1, "mean_dap_points": pytest.approx(0.0),
                              "share_points": pytest.approx(0.0)}
    bad = CliRunner().invoke(main, ["tables", str(tmp_path / "store"), "--annotations",
                                    str(ann), "--explain", "m-hue-3"])
    one_line_error(bad, "--explain", "m-hue-3")


def test_worst_case_rows_carry_the_rare_class_share(tmp_path) -> None:
    """With annotations, each worst-case row says how much of its ΔmAP rare classes make."""
    s, coco, _, _ = _explain_store(tmp_path)
    result = tables_result(s, coco)
    row = result.tables.worst_case["m"][1]
    assert row.delta_e == 3 and row.dmap_points == pytest.approx(25.0)
    # person (3 boxes) and bicycle (1 box) are both rare at the default of 5 boxes
    assert row.rare is not None and row.rare.dmap_points_rare == pytest.approx(25.0)
    assert (row.rare.rare_classes, row.rare.classes) == (2, 2)
    (tab,) = tables_of(tables_document(result, figures={}), "Worst case: m")
    assert tab.header[3] == "of which rare" and tab.rows[0][3] == "25.00"
    (plain,) = tables_of(tables_document(tables_result(s), figures={}), "Worst case: m")
    assert "of which rare" not in plain.header  # no annotations: no rare-class column
    (de3,) = [c for c in result.comparison if c.claim.startswith("ΔE ≤ 3")]
    assert "of which 25.00 from the 2 classes with at most 5 boxes" in de3.evidence


def test_model_conventions_are_said_in_words():
    from fidelity.report.coco import conventions_words

    assert conventions_words({"conf": 0.001, "iou": 0.7, "max_det": 300}) == (
        "conf 0.001, NMS IoU 0.7, max_det 300")
    assert conventions_words({"conf": 0.001, "iou": None, "max_det": 300}) == (
        "conf 0.001, no NMS (end-to-end), max_det 300")
    assert conventions_words({"conf": 0.01, "iou": 0.65, "max_det": None}) == (
        "conf 0.01, NMS IoU 0.65, no detection cap")
    assert conventions_words({"conf": 0.001, "iou": 0.7, "max_det": 300, "max_nms": 30000,
                              "multi_label": True}) == (
        "conf 0.001, NMS IoU 0.7, max_det 300, max_nms 30000, multi-label")


def test_image_caps_are_parsed_and_bad_ones_named() -> None:
    from fidelity.coco.tables.grid import parse_image_caps
    from fidelity.core.errors import InvalidValueError

    models = ["a", "b-int8"]
    assert parse_image_caps(None, models) == {}
    assert parse_image_caps("500", models) == {"a": 500, "b-int8": 500}
    assert parse_image_caps("b-int8=250", models) == {"b-int8": 250}
    assert parse_image_caps("1000, b-int8=250", models) == {"a": 1000, "b-int8": 250}
    with pytest.raises(InvalidValueError, match="no model 'c' in the store .it holds a, b-int8"):
        parse_image_caps("c=5", models)
    for bad in ("0", "a=x", "a=-3"):
        with pytest.raises(InvalidValueError, match=f"--images {bad!r}: expected N or MODEL=N"):
            parse_image_caps(bad, models)


def test_tables_images_without_annotations_is_one_line_exit_2(store, tmp_path) -> None:
    from click.testing import CliRunner

    from fidelity.cli import main

    res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--no-standard-errors",
                                    "--limit", "2", "--out", str(tmp_path / "r")])
    one_line_error(res, "--limit", "--no-standard-errors")
    res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--limit", "nope=2",
                                    "--out", str(tmp_path / "r")])
    one_line_error(res, "'nope'")
    assert not (tmp_path / "r").exists()


def test_threshold_verdicts_by_hand() -> None:
    """Both readings of the paper's "%", each exceedance set against 2 standard errors."""
    from fidelity.coco.tables.colour import _threshold_verdict

    def row(pts: float, rel: float, se_pts: float | None = None,
            se_rel: float | None = None) -> WorstCaseRow:
        return WorstCaseRow(3.0, "hue", pts, rel, 0.5, None, None, None, None, 1, 1, (), False,
                            se_pts, se_rel)

    assert _threshold_verdict([row(0.5, 0.9, 0.1, 0.2)], 1.0) == "agrees"
    # 0.76 points but 1.97 % of baseline, SE 1.02: inside 2 SE
    assert _threshold_verdict([row(0.76, 1.97, 0.41, 1.02)], 1.0) == (
        "agrees if read as points; exceeded as a share of baseline (within 2 SE)")
    # one row far above in relative terms decides "beyond", even if not the largest
    rows = [row(3.06, 8.0, 0.64, 1.47), row(2.33, 8.69, 0.91, 2.54), row(2.9, 7.6, 0.34, 0.88)]
    assert _threshold_verdict(rows, 3.0) == (
        "disagrees: exceeded in points (within 2 SE) and as a share of baseline (beyond 2 SE)")
    assert _threshold_verdict([row(3.06, 8.0, 0.01, 4.0)], 3.0) == (
        "disagrees: exceeded in points (beyond 2 SE) and as a share of baseline (within 2 SE)")
    assert _threshold_verdict([row(2.0, 5.0)], 3.0) == (
        "agrees if read as points; exceeded as a share of baseline")


def _earlier_store(folder: Path) -> SweepStore:
    """An earlier sweep: yolo11n measured otherwise (20 points at ΔE 3) and yolox_nano, whose
    recorded preprocessing is an older one."""
    s = SweepStore(folder)
    s.set_meta("grid", {"transforms": TRANSFORMS, "targets": [0, 3]})
    s.set_meta("versions", {"fidelity": "0.0.9"})
    for model, base in (("yolo11n", 0.50), ("yolox_nano", 0.30)):
        s.register_model(model, model + ".onnx", model * 4, None,
                         {"conventions": {"conf": 0.01, "preprocess": "an older one"}})
        s.finish_cell(model, "baseline", 0, param=None, status="done", images=10,
                      score=score(base, 0.6, 0.3))
    f = s.finish_cell
    f("yolo11n", "hue", 3, param=5.0, status="done", images=10, score=score(0.30, 0.6, 0.3))
    # yolox_nano: every transform at ΔE 3; saturation-inc the worst, 9 points (30 %)
    f("yolox_nano", "contrast-inc", 3, param=1.1, status="done", images=10,
      score=score(0.25, 0.5, 0.3))
    f("yolox_nano", "hue", 3, param=5.0, status="done", images=10, score=score(0.29, 0.6, 0.3))
    f("yolox_nano", "saturation-inc", 3, param=1.2, status="done", images=10,
      score=score(0.21, 0.6, 0.1))
    return s


def test_merge_keeps_the_earlier_models_the_store_does_not_hold(store, tmp_path) -> None:
    """The store's models replace their namesakes; the others come with their own rows,
    registration and preprocessing; the size class is the worst over the merged models."""
    from fidelity.coco.detectors import stale_preprocessing
    from fidelity.coco.tables.build import merge_tables

    new = build_tables(store)
    earlier = build_tables(_earlier_store(tmp_path / "earlier"))
    merged = merge_tables(new, earlier, {"file": "old/tables.json", "sha256": "ab" * 32})
    assert list(merged.models) == ["yolo11n", "yolov8n", "yolov8s", "yolox_nano"]
    assert merged.worst_case["yolo11n"] == new.worst_case["yolo11n"]  # the store's, not 20 pts
    assert merged.worst_case["yolox_nano"] == earlier.worst_case["yolox_nano"]
    n3 = {r.delta_e: r for r in merged.size_classes["n"]}[3.0]
    # yolo11n loses 5 points at ΔE 3, yolox_nano 9 (yolov8n's row is partial): yolox_nano
    assert (n3.worst_model, n3.worst_transform) == ("yolox_nano", "saturation-inc")
    assert n3.dmap_points == pytest.approx(9.0) and n3.dmap_relative == pytest.approx(30.0)
    assert n3.model_names == ("yolo11n", "yolox_nano")
    # cells: the store's 9 (3 baselines, 6 rows) and yolox_nano's baseline and three rows
    assert (new.cells_done, new.cells_unreachable) == (8, 1)
    assert (merged.cells_done, merged.cells_unreachable) == (12, 1)
    assert merged.meta["earlier"]["models"] == ["yolox_nano"]
    (run,) = merged.meta["earlier"]["runs"]
    assert run["models"] == ["yolox_nano"] and run["versions"] == {"fidelity": "0.0.9"}
    assert run["file"] == "tables.json" and run["sha256"] == "ab" * 32  # the file by name
    doc = prediction_table(merged)
    parse_prediction_table(doc)
    prov = doc["provenance"]
    assert prov["earlier"]["file"] == "old/tables.json" and prov["earlier"]["sha256"] == "ab" * 32
    assert prov["models"]["yolox_nano"]["conventions"]["preprocess"] == "an older one"
    assert set(stale_preprocessing(prov)) >= {"yolox_nano"}
    # merged again into a re-measured store (the same one here): the kept rows keep the record
    # of where they were measured, and name the file they passed through
    twice = merge_tables(new, merged, {"file": "mid/tables.json", "sha256": "cd" * 32})
    (run,) = twice.meta["earlier"]["runs"]
    assert run["file"] == "tables.json" and run["versions"] == {"fidelity": "0.0.9"}
    assert run["via"] == [{"file": "tables.json", "sha256": "cd" * 32}]  # mid/, by name
    assert twice.worst_case == merged.worst_case
    # nothing to keep: the store's tables as they are
    assert merge_tables(new, build_tables(store), {"file": "x"}) == new


def test_a_model_kept_through_several_merges_keeps_the_machine_that_measured_it(
        store, tmp_path) -> None:
    """Three runs on three machines, merged twice: each kept model is named with its own run's
    machine and versions, not those of the tables it was last kept in."""
    from dataclasses import replace

    from fidelity.coco.tables.build import merge_tables

    def run(t, models, machine):
        return replace(t, models={m: t.models[m] for m in models},
                       cells={m: t.cells[m] for m in models if m in t.cells},
                       worst_case={m: t.worst_case[m] for m in models if m in t.worst_case},
                       aligned={m: t.aligned[m] for m in models if m in t.aligned},
                       meta=t.meta | {"machine": {"cpu": machine},
                                      "versions": {"fidelity": machine}})

    new = build_tables(store)
    first = run(build_tables(_earlier_store(tmp_path / "earlier")), ["yolox_nano"], "M1")
    second = merge_tables(run(new, ["yolo11n"], "M2"), first, {"file": "a/t1.json",
                                                                "sha256": "1" * 64})
    third = merge_tables(run(new, ["yolov8n"], "M3"), second, {"file": "b/t2.json",
                                                                "sha256": "2" * 64})
    kept = third.meta["earlier"]
    assert (kept["file"], kept["models"]) == ("b/t2.json", ["yolo11n", "yolox_nano"])
    by_model = {m: r for r in kept["runs"] for m in r["models"]}
    assert by_model["yolo11n"]["machine"] == {"cpu": "M2"}
    assert by_model["yolo11n"]["file"] == "t2.json" and "via" not in by_model["yolo11n"]
    assert by_model["yolox_nano"]["machine"] == {"cpu": "M1"}  # not M2, where it was kept
    assert by_model["yolox_nano"]["versions"] == {"fidelity": "M1"}
    assert by_model["yolox_nano"]["file"] == "t1.json"
    assert by_model["yolox_nano"]["via"] == [{"file": "t2.json", "sha256": "2" * 64}]
    # the report's Run section names each run's machine
    from fidelity.report.coco import _run_section

    text = str(_run_section(third))
    assert "M1" in text and "M2" in text


def test_merge_refuses_tables_of_other_images(store, tmp_path) -> None:
    from fidelity.coco.tables.build import merge_tables
    from fidelity.core.errors import InvalidValueError

    other = _earlier_store(tmp_path / "earlier")
    other.set_meta("data", {"images": "/a/coco/val2017", "annotations": "/a/ann.json",
                            "image_count": 500})
    with pytest.raises(InvalidValueError, match="old.json: measured on other images"):
        merge_tables(build_tables(store), build_tables(other), {"file": "old.json"})


def test_tables_earlier_command(store, tmp_path) -> None:
    """`fidelity tables STORE --earlier TABLES_JSON`: the report and the prediction table hold
    the kept model and say where it came from; the earlier file is never written over."""
    from click.testing import CliRunner

    from fidelity.cli import main

    old = tmp_path / "old"
    _earlier_store(tmp_path / "earlier")
    res = CliRunner().invoke(main, ["tables", str(tmp_path / "earlier"), "--out", str(old),
                                    "--no-standard-errors"])
    assert res.exit_code == 0, res.output
    before = (old / "tables.json").read_bytes()
    out, pred = tmp_path / "new", tmp_path / "new" / "pred.json"  # (the store is tmp_path)
    res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--no-standard-errors",
                                    "--earlier", str(old / "tables.json"), "--out", str(out),
                                    "--prediction", str(pred)])
    assert res.exit_code == 0, res.output
    data = json.loads((out / "tables.json").read_text())
    assert sorted(data["tables"]["models"]) == ["yolo11n", "yolov8n", "yolov8s", "yolox_nano"]
    doc = json.loads(pred.read_text())
    assert doc["provenance"]["earlier"]["models"] == ["yolox_nano"]
    # the earlier file by its name and SHA-256, not where it lay on this machine
    assert doc["provenance"]["earlier"]["file"] == "tables.json"
    assert str(tmp_path) not in pred.read_text()
    assert "kept from earlier tables" in (out / "report.md").read_text()
    # merged again from tables an older version wrote (the first record named a path on its
    # machine): the kept record names the first file by name, and the file it passed through
    first = json.loads((out / "tables.json").read_text())
    older = first["tables"]["meta"]["earlier"]  # the record as versions before "runs" wrote it
    older |= {"file": str(tmp_path / "X1" / "reports-coco-tables-at-abc.json")} | {
        k: v for k, v in older.pop("runs")[0].items() if k not in ("file", "sha256")}
    (tmp_path / "twice.json").write_text(json.dumps(first))
    res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--no-standard-errors",
                                    "--earlier", str(tmp_path / "twice.json"), "--out",
                                    str(tmp_path / "again")])
    assert res.exit_code == 0, res.output
    kept = json.loads((tmp_path / "again" / "tables.json").read_text())["tables"]["meta"][
        "earlier"]
    assert kept["file"] == "twice.json" and kept["models"] == ["yolox_nano"]
    (run,) = kept["runs"]  # where yolox_nano was measured: the first file, by name
    assert run["file"] == "reports-coco-tables-at-abc.json" and run["models"] == ["yolox_nano"]
    assert [v["file"] for v in run["via"]] == ["twice.json"] and "versions" in run
    assert str(tmp_path / "X1") not in (tmp_path / "again" / "tables.json").read_text()
    # writing the merged tables over the earlier ones is refused before any work
    res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--no-standard-errors",
                                    "--earlier", str(old / "tables.json"), "--out", str(old)])
    one_line_error(res, "tables.json", "--earlier")
    assert (old / "tables.json").read_bytes() == before
    for bad in (pred, tmp_path / "missing.json"):  # a prediction table is not a tables.json
        res = CliRunner().invoke(main, ["tables", str(store.path.parent), "--earlier",
                                        str(bad), "--no-standard-errors",
                                        "--out", str(tmp_path / "r2")])
        one_line_error(res, str(bad))
    assert not (tmp_path / "r2").exists()


def test_worst_case_figure_puts_each_point_where_the_axes_say(store) -> None:
    """The worst-case figure drawn from the numbers: on the linear panel each model's point
    lies where the labelled ticks put its (ΔE, relative ΔmAP); on the log panel where
    log10 between two labelled ticks puts it; SAFE-COLOR's step runs through the paper's
    thresholds (1 % to ΔE 3, 3 % to 6, 10 % to 12)."""
    import math
    import xml.etree.ElementTree as ET

    from fidelity.report.cocofigures import TAB10, paper_step, worst_case_plot

    ns = "{http://www.w3.org/2000/svg}"
    tables = tables_result(store).tables
    root = ET.fromstring(worst_case_plot(tables))
    texts = list(root.iter(ns + "text"))

    def ticks(x_lo: float, x_hi: float) -> tuple[dict[str, float], dict[str, float]]:
        xs = {t.text: float(t.get("x")) for t in texts if t.get("text-anchor") == "middle"
              and t.get("font-size") == "12" and x_lo <= float(t.get("x")) <= x_hi}
        ys = {t.text: float(t.get("y")) for t in texts if t.get("text-anchor") == "end"
              and abs(float(t.get("x")) - (x_lo - 7)) < 0.01}
        return xs, ys

    step_x, step_y = paper_step()
    assert list(zip(step_x, step_y, strict=True)) == [
        (0, 1), (3, 1), (3, 3), (6, 3), (6, 10), (12, 10)]
    panel_w, checked = 380.0, 0
    for i, rows in enumerate(tables.worst_case.values()):
        colour = TAB10[i]
        dots = [(float(c.get("cx")), float(c.get("cy"))) for c in root.iter(ns + "circle")
                if c.get("fill") == colour and c.get("r") == "3"]
        pts = [(r.delta_e, r.dmap_relative) for r in rows if r.dmap_relative is not None]
        lin = dots[:len(pts)]
        xs, ys = ticks(64, 64 + panel_w)
        x_far, y_far = max(xs, key=float), max(ys, key=float)
        for (de, rel), (cx, cy) in zip(pts, lin, strict=True):
            assert cx == pytest.approx(xs["0"] + (xs[x_far] - xs["0"]) * de / float(x_far),
                                       abs=0.02)
            assert cy == pytest.approx(ys["0"] + (ys[y_far] - ys["0"]) * rel / float(y_far),
                                       abs=0.02)
        logs = dots[len(pts):]
        positive = [(de, rel) for de, rel in pts if rel > 0]
        assert len(logs) == len(positive)
        checked += len(positive)
        lx, ly = ticks(64 + panel_w + 86, 64 + 2 * panel_w + 86)
        labels = sorted((float(k) for k in ly), key=float)
        a, b = labels[0], labels[-1]
        ya, yb = ly[f"{a:g}"], ly[f"{b:g}"]
        lx_far = max(lx, key=float)
        for (de, rel), (cx, cy) in zip(positive, logs, strict=True):
            want = ya + (yb - ya) * (math.log10(rel) - math.log10(a)) / (
                math.log10(b) - math.log10(a))
            assert cy == pytest.approx(want, abs=0.02)
            assert cx == pytest.approx(lx["0"] + (lx[lx_far] - lx["0"]) * de / float(lx_far),
                                       abs=0.02)
    assert checked >= 2


def test_the_committed_scores_rebuild_every_shipped_sharpness_and_noise_row(shared, tmp_path):
    """Issue 56: the blur/noise sweep's scores file (reports/coco/degradations) rebuilds every
    cell of the shipped sharpness and noise tables, losses and standard errors, exactly."""
    from fidelity.coco.scores import import_scores, read_scores
    from fidelity.coco.scoring import load_annotations
    from fidelity.coco.tables.degradation import property_tables
    from fidelity.prediction.properties import load_property_table

    root = Path(__file__).resolve().parents[2]
    path = root / "reports" / "coco" / "degradations" / "degradations.scores.json.gz"
    store = SweepStore(tmp_path / "store")
    import_scores(store, path, read_scores(path, SweepStore))
    coco = load_annotations(shared / "coco" / "annotations" / "instances_val2017_subset.json")
    rebuilt = property_tables(store, coco)
    for prop in ("sharpness", "noise"):
        shipped = load_property_table(prop)
        for model, cells in shipped.cells.items():
            got = {(c.family, c.level): c for c in rebuilt[prop].cells[model]}
            for c in cells:
                r = got[(c.family, c.level)]
                assert r.x == pytest.approx(c.x, rel=1e-9)
                for col in ("dmap_points", "dmap_relative", "dap_person_points"):
                    assert r.losses[col] == pytest.approx(c.losses[col], abs=1e-9), (prop, c)
                    assert (r.se[col] or 0) == pytest.approx(c.se[col] or 0, abs=1e-9)
