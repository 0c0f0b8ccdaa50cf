"""The property validation (fidelity.coco.validate.properties): the verdict's losses of a
camera, the combination rules, the summary's counts and misses, and a real run on a few
images (skipped without ../shared)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.coco.validate.checks import bound_check
from fidelity.coco.validate.properties import (
    RULES,
    SHIPPED_RULE,
    PropertyResults,
    PropertyRow,
    camera_prediction,
    combine_rule,
    property_summary,
)
from fidelity.coco.validate.store import ValidationStore
from fidelity.coco.validate.suite import BASELINE, load_suite
from fidelity.pipeline.check import check_camera
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.properties import combine

SUITE = Path(__file__).resolve().parents[2] / "cameras" / "properties"


def test_the_suite_spans_the_issues_cases() -> None:
    """At least 30 cameras: Gaussian sigma 0.5-3 px, defocus, full well 5k-30k e-, read noise
    2-10 e-, low light, each with and without colour error; written by the committed script
    (the files are what it writes)."""
    from benchmarks.studies.property_cameras import COLOUR_CONFIGS, camera_toml

    cases = load_suite(SUITE)
    assert len(cases) >= 30
    for colour, configs in COLOUR_CONFIGS.items():
        for config in configs:
            name, text = camera_toml(colour, config)
            assert (SUITE / name).read_text() == text, name
    from fidelity.camera.model import read_camera_file

    cams = [read_camera_file(c.path) for c in cases]
    sigmas = {c.optics.sigma_px for c in cams if c.optics.kind == "gaussian"}
    assert min(sigmas) == 0.5 and max(sigmas) == 3.0
    assert any(c.optics.kind == "defocus" for c in cams)
    wells = {c.noise.full_well for c in cams if c.noise.enabled}
    reads = {c.noise.read_noise for c in cams if c.noise.enabled}
    assert {5000.0, 30000.0} <= wells and min(reads) == 2.0 and max(reads) == 10.0
    assert any("low light" in c.description for c in cams)
    for base in ("gauss1.5", "fw5k-rn10", "lowlight-iso8"):
        assert {f"ideal-{base}", f"nikon-{base}"} <= {c.name for c in cams}


def test_rules_closed_forms() -> None:
    parts = {"colour": 1.0, "sharpness": 4.0, "noise": 9.0}
    assert combine_rule("sum", parts) == pytest.approx(14.0)
    assert combine_rule(SHIPPED_RULE, parts) == pytest.approx(14.0 + 6.0)  # + sqrt(4 * 9)
    # the shipped rule is the verdict's combine()
    assert combine_rule(SHIPPED_RULE, parts) == pytest.approx(
        combine({k: (v, None) for k, v in parts.items()}).loss)
    assert combine_rule("probabilistic", parts) == pytest.approx(
        100 * (1 - 0.99 * 0.96 * 0.91))
    assert combine_rule("max", parts) == 9.0
    assert combine_rule("max", {"colour": -1.0}) == 0.0  # a gain counts as no loss
    with pytest.raises(ValueError, match="unknown"):
        combine_rule("median", parts)


def test_camera_prediction_is_the_check_verdicts() -> None:
    """What the validation predicts for a camera is what `fidelity check --camera FILE --size
    n` reports: its chart ΔE, MTF50, SNR, per-property losses and combined loss."""
    case = next(c for c in load_suite(SUITE) if c.name == "nikon-gauss2.0-fw5k")
    got = camera_prediction(case)
    report = check_camera(str(case.path), illuminant=case.illuminant,
                          judge=JudgeOptions(size="n"))
    j = report.properties
    assert j is not None and j.combined is not None
    assert got.chart_delta_e == pytest.approx(report.mean_delta_e, rel=1e-12)
    # the rule's loss: the validated margin is fitted on it, and check adds it
    assert got.combined["dmap_points"] == pytest.approx(j.combined.rule_loss, rel=1e-12)
    assert j.combined.margin > 0
    assert got.parts["dmap_points"] == pytest.approx(dict(j.combined.parts), rel=1e-12)
    sharp, noise = j.prediction("sharpness"), j.prediction("noise")
    assert sharp is not None and noise is not None
    assert (got.mtf50, got.snr) == pytest.approx((sharp.x, noise.x), rel=1e-12)
    assert got.group == ("colour", "sharpness", "noise")
    assert got.dominant == j.combined.dominant
    assert 0 < got.parts["dmap_points"]["noise"] and 0 < got.parts["dmap_points"]["sharpness"]
    again = type(got).from_json(json.loads(json.dumps(got.to_json())))
    assert again == got


def _row(camera: str, group: tuple[str, ...], measured: float, se: float,
         parts: dict[str, float]) -> PropertyRow:
    cols = ("dmap_points", "dmap_relative", "dap_person_points", "dap_bicycle_points")
    predicted = {r: dict.fromkeys(cols, combine_rule(r, parts)) for r in RULES}
    return PropertyRow(camera, "m", group, 100, 0.3, 0.3 - measured / 100,
                       dict.fromkeys(cols, measured), dict.fromkeys(cols, se), predicted,
                       {c: bound_check(predicted[SHIPPED_RULE][c], measured, se, "in-range")
                        for c in cols})


def test_summary_counts_ratios_misses_and_the_best_rule() -> None:
    rows = [_row("a", ("sharpness",), 1.0, 0.2, {"colour": 0.0, "sharpness": 2.0, "noise": 0.0}),
            _row("b", ("sharpness",), 3.0, 0.4, {"colour": 0.0, "sharpness": 2.0, "noise": 0.0}),
            _row("c", ("noise",), -0.1, 0.3, {"colour": 0.0, "sharpness": 0.0, "noise": 1.0}),
            # joint: sum 2 + 2 = 4, shipped 4 + 2 = 6, max 2, probabilistic 3.96
            _row("d", ("sharpness", "noise"), 3.0, 0.4,
                 {"colour": 0.0, "sharpness": 2.0, "noise": 2.0}),
            _row("e", ("sharpness", "noise"), 1.0, 0.4,
                 {"colour": 0.0, "sharpness": 2.0, "noise": 2.0})]
    s = property_summary(rows)["dmap_points"]
    a = s["all"]
    assert (a["cells"], a["within"], a["within_2se"]) == (5, 4, 4)
    # ratios predicted / measured over the cells measured above 0: 2, 2/3, 6/3, 6/1
    assert a["median_ratio"] == pytest.approx(2.0) and a["cells_above_zero"] == 4
    assert [(m["camera"], m["excess"], m["se"], m["within_2se"]) for m in a["misses"]] == \
        [("b", pytest.approx(1.0), 0.4, False)]
    assert not a["meets_target"]  # 4 of 5 within
    assert s["groups"]["sharpness"]["cells"] == 2 and s["groups"]["noise"]["within"] == 1
    assert s["groups"]["sharpness+noise"]["meets_target"] is False  # median 4x
    assert s["joint_cells"] == 2
    rules = s["rules"]
    # on the joint cells (measured 3 and 1): shipped 6, sum 4, 1 - (1 - 0.02)^2 = 3.96, max 2
    assert [rules[k]["within"] for k in (SHIPPED_RULE, "sum", "probabilistic", "max")] == \
        [2, 2, 2, 1]
    assert rules[SHIPPED_RULE]["median_ratio"] == pytest.approx((6 / 3 + 6) / 2)
    assert rules["sum"]["median_ratio"] == pytest.approx((4 / 3 + 4) / 2)
    assert rules["probabilistic"]["median_ratio"] == pytest.approx((3.96 / 3 + 3.96) / 2)
    assert s["best_rule"] == "probabilistic"  # bounds both with the least over-prediction


def test_results_round_trip() -> None:
    rows = (_row("a", ("noise",), 0.5, 0.2, {"colour": 0.1, "sharpness": 0.0, "noise": 1.0}),)
    res = PropertyResults({}, rows, property_summary(rows), {"m": {"map": 0.3, "images": 100}},
                          {})
    again = PropertyResults.from_json(json.loads(json.dumps(res.to_json())))
    assert again.rows == res.rows and again.summary == res.summary


@pytest.mark.shared
@pytest.mark.slow
def test_a_tiny_real_property_run(shared: Path, tmp_path: Path) -> None:
    """Two cameras with a lens and a sensor, YOLOX-nano, 4 images: `validate --properties`
    writes properties.{md,html,json} whose rows pair each camera's measured loss with the
    check verdict's combined loss; a rerun does no new work."""
    from fidelity.cli import main

    model = shared / "models" / "yolox_nano.onnx"
    images = shared / "coco" / "val2017"
    ann = shared / "coco" / "annotations" / "instances_val2017_subset.json"
    if not (model.is_file() and images.is_dir() and ann.is_file()):
        pytest.skip("shared COCO slice or yolox_nano.onnx missing")
    suite = tmp_path / "cams"
    suite.mkdir()
    for n in ("ideal-gauss3.0", "nikon-gauss2.0-fw5k"):
        shutil.copy(SUITE / f"{n}.toml", suite)
    args = ["validate", "--properties", "--cameras", str(suite), "--models", str(model),
            "--images", str(images), "--annotations", str(ann), "--out", str(tmp_path / "rep"),
            "--store", str(tmp_path / "st"), "--limit", "4", "--no-progress"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    st = ValidationStore(tmp_path / "st", create=False)
    cells = {c.camera: c for c in st.cells()}
    assert set(cells) == {BASELINE, "ideal-gauss3.0", "nikon-gauss2.0-fw5k"}
    assert all(c.images == 4 for c in cells.values())
    # the blur and the noise change the detections: not the baseline's mAP
    assert cells["ideal-gauss3.0"].map != cells[BASELINE].map
    doc = json.loads((tmp_path / "rep" / "properties.json").read_text())
    assert doc["kind"] == "property-validation" and len(doc["rows"]) == 2
    for row in doc["rows"]:
        cam = doc["cameras"][row["camera"]]
        assert row["predicted"][SHIPPED_RULE]["dmap_points"] == cam["combined"]["dmap_points"]
        want = 100 * (cells[BASELINE].map - cells[row["camera"]].map)
        assert row["measured"]["dmap_points"] == pytest.approx(want, abs=1e-9)
        assert math.isfinite(row["se"]["dmap_points"])
    assert doc["cameras"]["nikon-gauss2.0-fw5k"]["group"] == ["colour", "sharpness", "noise"]
    md = (tmp_path / "rep" / "properties.md").read_text()
    assert "nikon-gauss2.0-fw5k" in md and "Combination rules" in md
    assert (tmp_path / "rep" / "properties.html").is_file()
    assert not (tmp_path / "rep" / "validation.json").exists()
    domain = json.loads((tmp_path / "rep" / "properties-domain.json").read_text())
    assert (domain["cameras"], domain["cells"]) == (2, 2)
    assert domain["degradations"]["noise"] == {"kinds": ["none", "shot+read"],
                                               "ranges": {"full_well": [5000.0, 5000.0],
                                                          "read_noise": [10.0, 10.0]}}
    assert domain["degradations"]["optics"]["ranges"] == {"sigma_px": [2.0, 3.0]}
    before = {k: c.finished for k, c in cells.items()}
    r2 = CliRunner().invoke(main, args)
    assert r2.exit_code == 0, r2.output
    assert {c.camera: c.finished for c in st.cells()} == before


REPORTS = Path(__file__).resolve().parents[2] / "reports" / "validation"


@pytest.mark.slow
def test_committed_scores_rebuild_the_shipped_property_report(tmp_path: Path) -> None:
    """reports/validation/properties.json is what this code makes of the committed scores
    file and the camera files: every row (measured and predicted) and the summary exactly,
    the cameras' predictions (rendered again) to another CPU's last bits."""
    from fidelity.coco.scores import import_scores, read_scores
    from fidelity.coco.validate.properties import collect_property_results
    from tests.jsondiff import differences

    path = REPORTS / "properties.scores.json.gz"
    store = ValidationStore(tmp_path / "store")
    import_scores(store, path, read_scores(path, ValidationStore))
    rebuilt = collect_property_results(store, load_suite(SUITE)).to_json()
    shipped = json.loads((REPORTS / "properties.json").read_text())
    assert not differences(shipped["cameras"], rebuilt["cameras"], "cameras")
    for part in ("rows", "summary", "baselines"):
        assert not differences(shipped[part], rebuilt[part], part), part
    assert len(shipped["rows"]) == 2 * len(shipped["cameras"])
