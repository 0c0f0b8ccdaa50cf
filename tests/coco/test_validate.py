"""Tests for fidelity.coco.validate: suite loading, error profiles, scoring logic, a tiny real run."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.coco.emulation import AccuracySummary
from fidelity.coco.scoring import FOLDS, FoldScore
from fidelity.coco.validate.camera import (
    CameraRecord,
    EmulationRecord,
    ErrorProfile,
    ImageDeltaE,
    case_chart,
    chart_error_profile,
)
from fidelity.coco.validate.colour import ValidationResults, collect_results
from fidelity.coco.validate.store import ValidationStore
from fidelity.coco.validate.suite import BASELINE, load_suite
from fidelity.core.errors import InputFileError
from fidelity.report.document import Table
from fidelity.report.validation import validation_document, write_validation_report

# among the longest files of the suite: started first, so that a parallel run does not end on it
pytestmark = pytest.mark.early

REPO = Path(__file__).resolve().parents[2]
CAMERAS = REPO / "cameras"

IDEAL = """name = "{name}"
[sensitivities]
source = "ideal"
[white_balance]
method = "illuminant"
[tone]
curve = "srgb"
"""


def make_suite(folder: Path, names: list[str], suite: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for n in names:
        (folder / f"{n}.toml").write_text(IDEAL.format(name=n))
    if suite is not None:
        (folder / "suite.toml").write_text(suite)
    return folder


# --------------------------------------------------------------------------------- suite


def test_repository_suite_spans_the_required_cases() -> None:
    cases = load_suite(CAMERAS)
    assert len(cases) >= 20
    ills = {c.illuminant for c in cases}
    assert {"D65", "A", "F11", "LED"} <= ills
    text = {c.name: c.path.read_text() for c in cases}
    assert any("Nikon 5100" in t for t in text.values())
    assert any("Sigma SDMerrill" in t for t in text.values())
    assert any('fit_method = "Finlayson 2015"' in t for t in text.values())
    assert any('curve = "lut"' in t or 'curve = "gamma"' in t for t in text.values())
    assert sum(n.startswith("bad-") for n in text) >= 3
    for n, t in text.items():  # every file documents what it models
        assert t.startswith("#") and "description" in t, n
    assert (CAMERAS / "README.md").is_file()


def test_suite_illuminants_and_default(tmp_path: Path) -> None:
    d = make_suite(tmp_path / "s", ["a", "b"], 'default_illuminant = "F11"\n[illuminant]\na = "A"\n')
    cases = {c.name: c.illuminant for c in load_suite(d)}
    assert cases == {"a": "A", "b": "F11"}
    d2 = make_suite(tmp_path / "s2", ["c"])
    assert load_suite(d2)[0].illuminant == "D65"


@pytest.mark.parametrize("suite, match", [
    ('[illuminant]\nghost = "A"\n', "ghost"),
    ('colour = 1\n', "unknown field"),
    ('[illuminant]\na = "sunset"\n', "sunset"),
    ('[illuminant\n', "invalid TOML"),
])
def test_bad_suite_files_are_named(tmp_path: Path, suite: str, match: str) -> None:
    d = make_suite(tmp_path / "s", ["a"], suite)
    with pytest.raises(InputFileError, match=match):
        load_suite(d)


def test_bad_folders(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="does not exist"):
        load_suite(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match="no camera files"):
        load_suite(tmp_path / "empty")
    d = make_suite(tmp_path / "r", [BASELINE])
    with pytest.raises(InputFileError, match="reserved"):
        load_suite(d)
    d = make_suite(tmp_path / "x", ["a"])
    (d / "b.toml").write_text('name = "b"\n[tone]\ncurve = "sigmoid"\n')
    with pytest.raises(InputFileError, match="b.toml"):
        load_suite(d)


def test_validate_measures_each_chart_with_its_cases_chromatic_adaptation(tmp_path: Path) -> None:
    """Under illuminant A a camera whose suite file sets ``[cat]`` = "cat02" gets its chart ΔE
    with CAT02, not the default: another ΔE than von Kries' (and Bradford's), each equal to the
    render that ``fidelity suite`` makes with that transform; ``--cat`` sets the cases without a
    ``[cat]`` of their own."""
    from fidelity.camera.render import render_chart

    d = tmp_path / "s"
    d.mkdir()
    for n in ("c", "v", "b"):
        shutil.copy(CAMERAS / "nikon5100-a-awb.toml", d / f"{n}.toml")
    (d / "suite.toml").write_text('default_illuminant = "A"\n[cat]\nc = "cat02"\n'
                                  'v = "von kries"\n')
    cases = {c.name: c for c in load_suite(d)}
    assert {k: c.cat for k, c in cases.items()} == {"b": "Bradford", "c": "CAT02",
                                                    "v": "Von Kries"}
    de = {k: float(case_chart(c).measurement.mean_delta_e) for k, c in cases.items()}
    assert abs(de["c"] - de["v"]) > 0.05 and abs(de["c"] - de["b"]) > 0.05
    for k, c in cases.items():
        ref = render_chart(str(c.path), "A", cat=c.cat).measurement.mean_delta_e
        assert de[k] == pytest.approx(float(ref), rel=1e-12)
    assert de["b"] == pytest.approx(
        float(render_chart(str(cases["b"].path), "A").measurement.mean_delta_e), rel=1e-12)
    assert {c.name: c.cat for c in load_suite(d, "cat16")} == {"b": "CAT16", "c": "CAT02",
                                                               "v": "Von Kries"}


def test_validate_accepts_cat_and_records_it(tmp_path: Path) -> None:
    """``validate --cat`` is parsed as ``suite --cat`` (any case; an unknown name is refused
    naming the option); a camera record keeps its transform (Bradford where a store written
    before it has none), and the report lists it beside the illuminant and counts it."""
    from fidelity.cli import main

    d = make_suite(tmp_path / "s", ["a"])
    r = CliRunner().invoke(main, ["validate", "--cameras", str(d), "--cat", "cat02",
                                  "--out", str(tmp_path / "o"), "--store",
                                  str(tmp_path / "none"), "--report-only"])
    one_line_error(r, str(tmp_path / "none"))
    r = CliRunner().invoke(main, ["validate", "--cameras", str(d), "--cat", "sunset",
                                  "--out", str(tmp_path / "o"), "--report-only"])
    assert r.exit_code == 2 and "--cat" in r.output
    rec = replace(_camera("cam", 2.0), cat="CAT02")
    assert rec.to_json()["cat"] == "CAT02" and CameraRecord.from_json(rec.to_json()) == rec
    bradford = _camera("cam", 2.0).to_json()  # written as before the transform was recorded
    assert "cat" not in bradford and CameraRecord.from_json(bradford).cat == "Bradford"


# --------------------------------------------------------------------------------- profile


def test_error_profile_of_a_pure_lightness_shift() -> None:
    """A pure L* shift: CIEDE2000's ΔL' is exactly the shift, ΔC' = ΔH' = 0 (Sharma 2005)."""
    from fidelity.colour.charts import load_chart
    from fidelity.colour.colorimetry import lab_to_srgb
    from fidelity.measure.colour import measure_chart

    chart = load_chart()
    lab = chart.lab + np.array([3.0, 0.0, 0.0])
    m = measure_chart(lab_to_srgb(lab), chart.lab, chart.patch_names)
    p = chart_error_profile(m)
    assert p.dominant == "lightness"
    assert p.mean_dl == pytest.approx(3.0, abs=1e-6)
    assert p.share_l == pytest.approx(1.0, abs=1e-6)
    assert p.contrast_ratio == pytest.approx(1.0, abs=1e-9)


def test_error_profile_of_a_chroma_scaling() -> None:
    from fidelity.colour.charts import load_chart
    from fidelity.colour.colorimetry import lab_to_srgb
    from fidelity.measure.colour import measure_chart

    chart = load_chart()
    lab = chart.lab * np.array([1.0, 0.6, 0.6])  # less chroma, same hue and lightness
    p = chart_error_profile(measure_chart(lab_to_srgb(lab), chart.lab, chart.patch_names))
    assert p.dominant == "chroma" and p.mean_dc < 0
    assert p.share_h < 1e-6


# --------------------------------------------------------------------------------- scoring


def _score(m: float, person: float, bicycle: float | None, images: int = 10) -> SimpleNamespace:
    return SimpleNamespace(images=images, map=m, map50=m, ap={"person": person, "bicycle": bicycle})


def _accuracy(mean: float, worst: float, camera_de: float, emulated_de: float
              ) -> AccuracySummary:
    return AccuracySummary(mean, worst, "cyan", 0.4, 1.0, 10, camera_de, emulated_de,
                           {"cyan": worst})


def _camera(name: str, chart_de: float, dominant: str = "hue") -> CameraRecord:
    profile = ErrorProfile(0.1, 0.1, 0.3, 0.2, 0.2, 0.6, 0.0, 0.0, 1.0, (0.0, 0.0), dominant,
                           "cyan", 0.9)
    emulation = EmulationRecord({"method": "root-polynomial"},
                                _accuracy(0.3, 0.9, chart_de, chart_de + 0.1),
                                {"lut3d": _accuracy(0.2, 0.5, chart_de, chart_de)})
    return CameraRecord(name, f"{name}.toml", "0" * 64, "test", "D65", chart_de, 2 * chart_de,
                        profile, {"renderer": "closed-form"}, (), emulation,
                        ImageDeltaE(1.5, 4.0, 2, 4), 0.1)


@pytest.fixture
def one_camera_store(tmp_path: Path) -> ValidationStore:
    """One detector, its baseline and one camera 2 points of mAP worse (folds by hand)."""
    st = ValidationStore(tmp_path / "store")
    st.register_model("det", "det.onnx", "0" * 64, None, {"conventions": {"conf": 0.001}})
    base_folds = [FoldScore(0.40, 0.5, 0.3, 2)] * FOLDS
    st.finish_cell("det", BASELINE, _score(0.40, 0.50, 0.30), base_folds, 1.0)
    folds = [FoldScore(v, 0.5, 0.3, 2) for v in FOLD_MAPS]
    st.finish_cell("det", "cam", _score(0.38, 0.45, 0.30), folds, 1.0)
    st.set_case("cam", "k", _camera("cam", 2.0))
    return st


FOLD_MAPS = [0.39, 0.38, 0.40, 0.37, 0.36]


def test_collect_results_losses_standard_errors_and_bound(one_camera_store, tmp_path) -> None:
    st = one_camera_store
    res = collect_results(st, tables=["safecolor-2025"], bound_table="safecolor-2025")
    (row,) = res.rows
    assert row.measured.dmap_points == pytest.approx(2.0)
    assert row.measured.dmap_relative == pytest.approx(5.0)
    assert row.measured.dap_person_points == pytest.approx(5.0)
    assert row.measured.dap_bicycle_points == pytest.approx(0.0)
    d = 100 * (0.40 - np.array(FOLD_MAPS))
    assert row.se.dmap_points == pytest.approx(d.std(ddof=1) / np.sqrt(FOLDS))
    # safecolor-2025 (linear): ΔE 2 lies between (0, 0) and (3, 1 point): 2/3 point for mAP
    assert row.bound["all"].predicted == pytest.approx(2 / 3)
    assert row.bound["all"].within is False
    assert row.bound["all"].excess == pytest.approx(2.0 - 2 / 3)
    assert row.bound["bicycle"].within is True
    s = res.summary.classes
    assert s["all"].cameras == 1 and s["all"].cameras_within == 0
    assert s["all"].failures == (("cam", "det"),)
    paths = write_validation_report(res, tmp_path / "report")
    assert {p.name for p in paths} >= {"validation.md", "validation.html", "validation.json",
                                       "predicted-vs-measured-safecolor-2025.svg"}
    # validation.json is the results' to_json and reads back to the same records
    data = json.loads((tmp_path / "report" / "validation.json").read_text())
    assert data == res.to_json() and ValidationResults.from_json(data) == res
    assert data["summary"]["all"]["failures"] == [["cam", "det"]]
    assert set(data["rows"][0]["bound"]["all"]) == {"predicted", "measured", "se", "within",
                                                    "excess", "within_2se", "status"}
    # the failure is explained from the data: excess in SE units, inside the noise
    bound = data["rows"][0]["bound"]["all"]
    assert (data["rows"][0]["camera"], data["rows"][0]["model"]) == ("cam", "det")
    assert bound["excess"] == pytest.approx(2.0 - 2 / 3)
    assert bound["se"] == pytest.approx(row.se.dmap_points)
    assert bound["excess"] / bound["se"] < 2 and bound["within_2se"] is True
    # a stored camera that is not in the suite given (renamed or removed) is left out, and said
    from fidelity.coco.validate.suite import CameraCase

    other = CameraCase("other", tmp_path / "other.toml", "D65", "0" * 64)
    res = collect_results(st, tables=["safecolor-2025"], bound_table="safecolor-2025",
                          suite=[other])
    assert res.rows == () and res.summary.not_in_suite == ("cam",)
    assert "cam" not in res.cameras
    doc = validation_document(res, figures={})
    assert doc.headline.tone == "info" and doc.headline.figure is None


def _symlog(v: float) -> float:
    """matplotlib's symlog with linthresh 1 in closed form: linear below 1, 1 + log10 above."""
    return v if abs(v) <= 1 else float(np.sign(v)) * (1 + np.log10(abs(v)))


def test_figures_put_each_cell_where_the_axes_say(one_camera_store) -> None:
    """The SVG figures drawn from the numbers: in each panel of predicted against measured,
    the cell's marker lies where the panel's labelled ticks 0 and 1 put its (predicted,
    measured) on symlog axes, its error bar spans ±2 SE, and the identity line runs through
    (0, 0) and (1, 1); the chart-ΔE panel puts the camera at its chart ΔE."""
    import xml.etree.ElementTree as ET

    from fidelity.report.validationfigures import (
        GAP,
        LEFT,
        MODEL_COLOURS,
        PANEL_W,
        PLOTTED,
        scatter_plot,
        vs_delta_e_plot,
    )

    ns = "{http://www.w3.org/2000/svg}"
    res = collect_results(one_camera_store, tables=["safecolor-2025"],
                          bound_table="safecolor-2025")
    (row,) = res.rows

    def ticks(root: ET.Element, panel: int) -> tuple[dict[str, float], dict[str, float]]:
        """Tick label -> pixel along x (labels under the panel) and along y (left of it)."""
        x0 = LEFT + panel * (PANEL_W + GAP)
        xs, ys = {}, {}
        for t in root.iter(ns + "text"):
            x, y = float(t.get("x")), float(t.get("y"))
            if t.get("text-anchor") == "middle" and x0 - 1 <= x <= x0 + PANEL_W + 1 \
                    and t.get("font-size") == "12":
                xs[t.text] = x
            elif t.get("text-anchor") == "end" and abs(x - (x0 - 7)) < 0.01:
                ys[t.text] = y
        return xs, ys

    from fidelity.coco.loss import LOSS_COLUMNS

    root = ET.fromstring(scatter_plot(res.rows, "safecolor-2025"))
    markers = [c for c in root.iter(ns + "circle") if c.get("fill") == MODEL_COLOURS[0]]
    assert len(markers) == len(PLOTTED) + 1  # one per panel, one in the legend
    for panel, cls in enumerate(PLOTTED):
        col = LOSS_COLUMNS[cls]
        pred = row.predicted["safecolor-2025"].losses.get(col)
        meas = row.measured.get(col)
        assert pred is not None and meas is not None
        xs, ys = ticks(root, panel)
        m = markers[panel]
        want_x = xs["0"] + (xs["1"] - xs["0"]) * _symlog(pred)
        want_y = ys["0"] + (ys["1"] - ys["0"]) * _symlog(meas)
        assert float(m.get("cx")) == pytest.approx(want_x, abs=0.02)
        assert float(m.get("cy")) == pytest.approx(want_y, abs=0.02)
        se = row.se.get(col) or 0.0
        bars = [ln for ln in root.iter(ns + "line") if ln.get("stroke") == MODEL_COLOURS[0]
                and ln.get("x1") == ln.get("x2") == m.get("cx")]
        if se > 0:
            (bar,) = bars
            lo, hi = sorted(float(bar.get(k)) for k in ("y1", "y2"))
            unit = ys["0"] - ys["1"]
            assert hi == pytest.approx(ys["0"] - unit * _symlog(meas - 2 * se), abs=0.02)
            assert lo == pytest.approx(ys["0"] - unit * _symlog(meas + 2 * se), abs=0.02)
    # the identity line passes through (0, 0) and (1, 1) of the first panel
    xs, ys = ticks(root, 0)
    ident = next(p for p in root.iter(ns + "polyline") if p.get("stroke-dasharray") == "5 3")
    pts = np.array([[float(v) for v in q.split(",")] for q in ident.get("points").split()])
    for v in (0.0, 1.0):
        px = xs["0"] + (xs["1"] - xs["0"]) * v
        py = np.interp(px, pts[:, 0], pts[:, 1])
        assert py == pytest.approx(ys["0"] + (ys["1"] - ys["0"]) * v, abs=0.2)
    # measured loss against chart ΔE: the camera at its chart ΔE (linear axis)
    root = ET.fromstring(vs_delta_e_plot(res.rows, ["safecolor-2025"]))
    xs, ys = ticks(root, 0)
    (m, *_) = [c for c in root.iter(ns + "circle") if c.get("fill") == MODEL_COLOURS[0]]
    far = max(xs, key=float)
    scale = (xs[far] - xs["0"]) / float(far)
    assert float(m.get("cx")) == pytest.approx(xs["0"] + scale * row.chart_delta_e, abs=0.02)
    assert float(m.get("cy")) == pytest.approx(
        ys["0"] + (ys["1"] - ys["0"]) * _symlog(row.measured.dmap_points), abs=0.02)


def test_symlog_ticks_either_side_of_zero() -> None:
    from fidelity.report.svg import Scale, symlog_ticks

    assert symlog_ticks(5, -12) == [-10, -5, -2, -1, 0, 1, 2, 5]
    assert Scale(-0.5, 3.0, "symlog").ticks() == [0, 1, 2]
    assert Scale(-2.5, 3.0, "symlog").ticks() == [-2, -1, 0, 1, 2]


def test_validation_report_structure(one_camera_store) -> None:
    """Headline (the bound, with the bound table's plot) before any table, every figure
    embedded, the per-camera tables folded, Markdown and HTML from one document, the tone
    from the data, no Python dict text."""
    import re

    from fidelity.report.html import markdown_inline, render_html, render_markdown

    res = collect_results(one_camera_store, tables=["safecolor-2025"],
                          bound_table="safecolor-2025")
    doc = validation_document(res, notes="Some *analysis*.")
    html, md = render_html(doc), render_markdown(doc)
    assert doc.headline.figure is not None
    assert doc.headline.figure.name == "predicted-vs-measured-safecolor-2025.svg"
    # mAP is 1.33 points over the bound, within 2 SE (0.74); person 5 points over with no
    # spread over the folds (SE 0): beyond 2 SE, so the headline says fail
    (row,) = res.rows
    assert row.bound["all"].within_2se is True and row.bound["person"].within_2se is False
    assert doc.headline.tone == "fail"
    assert html.index('class="headline') < html.index("<svg") < html.index("<table")
    names = [f.name for f in doc.figures()]
    assert names == ["predicted-vs-measured-safecolor-2025.svg", "loss-vs-chart-delta-e.svg",
                     "emulation-accuracy.svg"]
    # every figure inlined as SVG, none as a picture; Markdown links the files
    assert html.count("<svg") == len(names) and "<img" not in html
    assert all(f"]({n})" in md for n in names)
    folded = {s.title for s in doc.sections if s.folded}
    assert {"Per camera", "Emulation accuracy per camera", "Cameras"} <= folded
    assert html.count("<details>") == len(folded)
    assert [s.title for s in doc.sections][1:3] == ["Answer", "Notes"]
    for s in doc.sections:
        for b in s.blocks:
            if isinstance(b, Table):
                for row in b.rows:
                    assert "| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" in md
                    assert all(str(markdown_inline(c)) in html for c in row)
    assert not re.search(r"\{'|': ", md) and "{&#39;" not in html
    # the chart's chromatic adaptation, per camera and counted in "What was run"
    assert "| camera | illuminant | chromatic adaptation | description |" in md
    assert "| cam | D65 | Bradford | test |" in md
    assert "the scene reference adapted to D65 with Bradford (1 camera);" in md
    # the detector's settings, as validation.json carries them for the report
    assert res.to_json()["models"]["det"]["settings"]["conventions"] == {"conf": 0.001}


def test_cli_needs_models_unless_report_only(tmp_path: Path) -> None:
    from fidelity.cli import main

    d = make_suite(tmp_path / "s", ["a"])
    r = CliRunner().invoke(main, ["validate", "--cameras", str(d), "--out", str(tmp_path / "o"),
                                  "--store", str(tmp_path / "st")])
    one_line_error(r, "--models")
    r = CliRunner().invoke(main, ["validate", "--cameras", str(d), "--out", str(tmp_path / "o"),
                                  "--store", str(tmp_path / "none"), "--report-only"])
    one_line_error(r, str(tmp_path / "none"))


def one_line_error(r, *names: str) -> None:  # type: ignore[no-untyped-def]
    """Exit code 2 and one line ``fidelity: error: ...`` that names each of ``names``."""
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), r.output
    assert all(n in lines[0] for n in names) and "Traceback" not in r.output, (names, r.output)


# --------------------------------------------------------------------------------- real slice


@pytest.mark.shared
@pytest.mark.slow
def test_tiny_real_run_is_resumable(shared: Path, tmp_path: Path) -> None:
    """Two cameras, YOLOX-nano, 4 images: a full run, then a rerun that does no new work."""
    from fidelity.cli import main

    model = shared / "models" / "yolox_nano.onnx"
    images = shared / "coco" / "val2017"
    ann = shared / "coco" / "annotations" / "instances_val2017_subset.json"
    if not (model.is_file() and images.is_dir() and ann.is_file()):
        pytest.skip("shared COCO slice or yolox_nano.onnx missing")
    suite = tmp_path / "cams"
    suite.mkdir()
    for n in ("ideal-srgb8", "bad-hue-rotation"):
        shutil.copy(CAMERAS / f"{n}.toml", suite)
    args = ["validate", "--cameras", str(suite), "--models", str(model), "--images", str(images),
            "--annotations", str(ann), "--out", str(tmp_path / "rep"), "--store",
            str(tmp_path / "st"), "--limit", "4", "--no-progress"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    st = ValidationStore(tmp_path / "st", create=False)
    cells = {c.camera: c for c in st.cells()}
    assert set(cells) == {BASELINE, "ideal-srgb8", "bad-hue-rotation"}
    assert all(c.images == 4 for c in cells.values())
    info = st.cases()["ideal-srgb8"]
    assert info.chart_delta_e < 0.5
    assert info.emulation.accuracy.chart_max_delta_e < 1.5
    before = {k: c.finished for k, c in cells.items()}
    r2 = CliRunner().invoke(main, args)
    assert r2.exit_code == 0, r2.output
    assert {c.camera: c.finished for c in st.cells()} == before
    md = (tmp_path / "rep" / "validation.md").read_text()
    assert "bad-hue-rotation" in md and "yolox_nano" in md
    # every cell carries the rest-of-run scores and the bootstrap draws, and the report says
    # the SEs are the larger of the two estimators
    assert all(f.has_rest for c in st.cells() for f in c.folds)
    assert all(c.draws is not None and c.draws.images == 4 for c in st.cells())
    doc = json.loads((tmp_path / "rep" / "validation.json").read_text())
    assert doc["summary"]["standard_error"] == "larger"
    # the validated cameras beside the report: the two cameras' illuminants and stages
    domain = json.loads((tmp_path / "rep" / "domain.json").read_text())
    assert domain["cameras"] == 2 and domain["illuminants"] == ["D65"]
    assert domain["cells"] == doc["summary"]["all"]["cells"] == 2
    assert domain["stages"]["bit depth"] == ["8"] and domain["models"] == ["yolox_nano"]
    # a store of an earlier version (no draws, folds without rest scores) reports the fold SE;
    # --report-only with --annotations scores it again from its detections: the same SEs as
    # the run's own
    se = {(r["camera"], r["model"]): r["bound"]["all"]["se"] for r in doc["rows"]}
    with st.db:
        st.db.execute("DELETE FROM draws")
        for c in st.cells():
            st.db.execute("UPDATE cells SET folds=? WHERE model=? AND camera=?",
                          (json.dumps([{k: v for k, v in f.to_json().items() if k != "rest"}
                                       for f in c.folds]), c.model, c.camera))
    old = CliRunner().invoke(main, ["validate", "--cameras", str(suite), "--report-only",
                                    "--store", str(tmp_path / "st"), "--out",
                                    str(tmp_path / "old")])
    assert old.exit_code == 0, old.output
    assert json.loads((tmp_path / "old" / "validation.json").read_text())["summary"][
        "standard_error"] == "folds"
    again = CliRunner().invoke(main, ["validate", "--cameras", str(suite), "--report-only",
                                      "--annotations", str(ann), "--store", str(tmp_path / "st"),
                                      "--out", str(tmp_path / "again")])
    assert again.exit_code == 0, again.output
    doc2 = json.loads((tmp_path / "again" / "validation.json").read_text())
    assert doc2["summary"]["standard_error"] == "larger"
    assert {(r["camera"], r["model"]): r["bound"]["all"]["se"] for r in doc2["rows"]} == \
        pytest.approx(se)
    # carried to another machine as a scores file: the report of the imported store is the
    # same, and a rerun there does no new work
    scores = tmp_path / "v.scores.json.gz"
    r = CliRunner().invoke(main, ["validate", "--export-scores", str(scores), "--annotations",
                                  str(ann), "--store", str(tmp_path / "st")])
    assert r.exit_code == 0 and "3 cells of a validation store (yolox_nano 3)" in r.output, \
        r.output
    r = CliRunner().invoke(main, ["validate", "--import-scores", str(scores), "--store",
                                  str(tmp_path / "moved")])
    assert r.exit_code == 0, r.output
    moved = CliRunner().invoke(main, ["validate", "--cameras", str(suite), "--report-only",
                                      "--store", str(tmp_path / "moved"), "--out",
                                      str(tmp_path / "moved-rep")])
    assert moved.exit_code == 0, moved.output
    doc3 = json.loads((tmp_path / "moved-rep" / "validation.json").read_text())
    assert (doc3["rows"], doc3["summary"]) == (doc2["rows"], doc2["summary"])
    r = CliRunner().invoke(main, [*args[:-4], str(tmp_path / "moved"), *args[-3:]])
    assert r.exit_code == 0, r.output
    st2 = ValidationStore(tmp_path / "moved", create=False)
    assert {c.camera: c.finished for c in st2.cells()} == before


def test_a_run_on_a_few_images_tables_their_colours_only(monkeypatch) -> None:
    """Up to DIRECT_IMAGES images: the camera's table holds the images' own colours (the
    2^24-entry table is never built) and maps them as the full table does; above: the full
    table. Tables are kept one camera at a time; the images' colours are found once."""
    import fidelity.coco.validate.colour as validate
    from fidelity.camera.model import load_camera
    from fidelity.coco.dataset import PixelMap

    rng = np.random.default_rng(5)
    images = {i: rng.integers(0, 256, (6, 7, 3), dtype=np.uint8) for i in range(1, 5)}
    decoded: list[int] = []

    class Cache:
        def get(self, i: int) -> tuple[np.ndarray, None]:
            decoded.append(i)
            return images[i], None

    def mapping(rgb: np.ndarray) -> np.ndarray:  # any fixed 8-bit colour change
        return (rgb.astype(np.uint16) * 7 // 5 % 256).astype(np.uint8)

    cubes: list[str] = []

    class Emu:
        camera = load_camera("ideal")  # no optics, noise or vignetting: a colour table

        def __init__(self, name: str) -> None:
            self.name = name

        def map_codes(self, codes: np.ndarray) -> np.ndarray:
            rgb = np.stack([(codes >> 16) & 255, (codes >> 8) & 255, codes & 255], -1)
            return mapping(rgb.astype(np.uint8))

        def cube(self) -> np.ndarray:
            cubes.append(self.name)
            return self.map_codes(np.arange(1 << 24, dtype=np.uint32))

    accuracy = SimpleNamespace(chart_mean_delta_e=0.1, chart_max_delta_e=0.2)
    info = SimpleNamespace(chart_delta_e=1.0, emulation=SimpleNamespace(accuracy=accuracy))
    monkeypatch.setattr(validate, "prepare_case", lambda case, *a: (Emu(case.name), info))
    cases = [SimpleNamespace(name=n, illuminant="D65") for n in ("cam-a", "cam-b")]
    lines: list[str] = []
    small = validate.EmulationTables(None, "root-polynomial", "chart", Cache(), [1, 2, 3, 4],
                                     lines.append)
    for case in cases:
        table = small.get(case)
        assert isinstance(table, PixelMap) and table.kind == "codes"
        for img in images.values():
            np.testing.assert_array_equal(table(img), mapping(img))
    assert small.get(cases[1]) is table and list(small.built) == ["cam-b"]
    assert not cubes and sorted(decoded) == [1, 2, 3, 4] and len(lines) == 2
    monkeypatch.setattr(validate, "DIRECT_IMAGES", 3)  # the executor's, as validate reads it
    full = validate.EmulationTables(None, "root-polynomial", "chart", Cache(), [1, 2, 3, 4],
                                    lines.append).get(cases[0])
    assert full.kind == "cube" and cubes == ["cam-a"]
    np.testing.assert_array_equal(full(images[1]), mapping(images[1]))
    # the images the cells run on decide (a --limit below the images the case is prepared on)
    decoded.clear()
    limited = validate.EmulationTables(None, "root-polynomial", "chart", Cache(), [1, 2, 3, 4],
                                       lines.append, [1, 2]).get(cases[1])
    assert limited.kind == "codes" and sorted(decoded) == [1, 2] and cubes == ["cam-a"]
    np.testing.assert_array_equal(limited(images[2]), mapping(images[2]))
