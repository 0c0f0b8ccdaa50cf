"""COCO-C colour corruptions: equal to imagecorruptions, their chart ΔE, predict --coco-c."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.coco import corruptions as cc
from fidelity.prediction.directional import predict_chart
from fidelity.prediction.table import predict
from tests.jsondiff import differences


def _images(shared=None):
    rng = np.random.default_rng(7)
    out = [(rng.random((37, 45, 3)) * 256).astype(np.uint8)]
    grey = (rng.random((40, 40)) * 256).astype(np.uint8)
    out.append(np.repeat(grey[:, :, None], 3, axis=2))  # a grey image: saturate gives it a hue
    ties = np.zeros((32, 32, 3), np.uint8)
    ties[..., 0] = ties[..., 1] = 200  # R = G = max: skimage's tie rule sets the hue
    ties[..., 2] = np.arange(32, dtype=np.uint8)[None, :] * 3
    out.append(ties)
    if shared is not None:
        from fidelity.coco.jpeg import read_jpeg

        files = sorted((shared / "coco" / "val2017").glob("*.jpg"))[:3]
        out += [read_jpeg(f)[0] for f in files]
    return out


@pytest.mark.parametrize("name", cc.CORRUPTIONS)
def test_equal_to_imagecorruptions(name):
    ic = pytest.importorskip("imagecorruptions")
    for img in _images():
        for sev in cc.SEVERITIES:
            assert np.array_equal(cc.corrupt(img, name, sev), ic.corrupt(img, sev, name)), sev


def test_equal_to_imagecorruptions_on_coco(shared):
    ic = pytest.importorskip("imagecorruptions")
    for img in _images(shared)[3:]:
        for name in cc.CORRUPTIONS:
            for sev in (1, 3, 5):
                fast = cc.CorruptionMap(name, sev) if name == "contrast" else None
                want = ic.corrupt(img, sev, name)
                assert np.array_equal(cc.corrupt(img, name, sev), want)
                if fast is not None:
                    assert np.array_equal(fast(img), want)


def test_the_fast_table_equals_the_definition():
    m = cc.CorruptionMap("saturate", 4)
    m._cube = None
    img = _images()[0]
    # build only what this image needs: the table's rows are the definition on each colour
    idx = (img[..., 0].astype(np.uint32) << 16) | (img[..., 1].astype(np.uint32) << 8) | img[..., 2]
    rows = np.stack([(idx >> 16) & 255, (idx >> 8) & 255, idx & 255], axis=-1)
    direct = cc.corrupt(rows.astype(np.uint8), "saturate", 4)
    assert np.array_equal(direct, cc.corrupt(img, "saturate", 4))
    c = cc.CorruptionMap("contrast", 2)
    assert np.array_equal(c(img), cc.corrupt(img, "contrast", 2))


def test_chart_delta_e_grows_with_severity():
    cells = cc.chart_cells()
    by = {(c.corruption, c.severity): c.chart_delta_e for c in cells}
    for name in ("brightness", "contrast"):
        assert all(by[(name, s)] < by[(name, s + 1)] for s in range(1, 5)), name
    # saturate's severities 1-2 desaturate, 3-5 saturate more
    assert by[("saturate", 2)] > by[("saturate", 1)] and by[("saturate", 3)] < by[("saturate", 4)]
    floor = cc.uncorrupted_chart_delta_e()
    assert 0 < floor < min(by.values())
    for c in cells:  # the parts add up to the chart ΔE
        assert c.parts["lightness"] + c.parts["chroma"] + c.parts["hue"] == pytest.approx(
            c.chart_delta_e)
    bright = next(c for c in cells if c.corruption == "brightness" and c.severity == 3)
    assert bright.parts["lightness"] / bright.chart_delta_e > 0.9


def test_predict_coco_c_prints_equivalent_delta_e_and_losses(tmp_path):
    r = CliRunner().invoke(main, ["predict", "--coco-c", "contrast:3", "--json",
                                  str(tmp_path / "c.json")])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "c.json").read_text())
    m = cc.corruption_chart("contrast", 3)
    assert doc["chart_delta_e"] == pytest.approx(m.mean_delta_e)
    assert doc["chart_max_delta_e"] == pytest.approx(m.max_delta_e)
    assert doc["worst_patch"] == m.worst_patch
    # both predictions are made at the corruption's chart ΔE, from the shipped tables
    classic = predict(m.mean_delta_e, transforms=False)
    directional = predict_chart(m)
    assert doc["prediction"]["delta_e"] == doc["directional_prediction"]["delta_e"] == (
        pytest.approx(m.mean_delta_e))
    assert doc["prediction"]["dmap_points"] == pytest.approx(classic.dmap_points)
    assert doc["prediction"]["dmap_relative"] == pytest.approx(classic.dmap_relative)
    assert doc["directional_prediction"]["dmap_points"] == pytest.approx(directional.dmap_points)
    assert doc["directional_prediction"]["dmap_points"] < doc["prediction"]["dmap_points"]
    table = cc.load_coco_c()
    measured = table.cell("contrast", 3).measured
    assert measured and [x["dmap_points"] for x in doc["measured"]] == [
        x.dmap_points for x in measured]
    r = CliRunner().invoke(main, ["predict", "--coco-c", "fog:3"])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("fidelity: error: ")
    assert "fog: unknown COCO-C corruption; known: " in lines[0]
    r = CliRunner().invoke(main, ["predict", "--coco-c", "contrast:9"])
    assert r.exit_code == 2


def test_shipped_table_equals_the_report(tmp_path):
    """fidelity/data/coco-c.json and reports/cococ/cococ.json hold the same run (the shipped
    one names its inputs without the measuring machine's paths), and its chart side is what
    the code computes now."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    text = (root / "fidelity/data/coco-c.json").read_text()
    shipped = json.loads(text)
    report = json.loads((root / "reports/cococ/cococ.json").read_text())
    assert shipped == cc.CocoCResults.from_json(report).without_locations().to_json()
    assert shipped != report and "/coco/" not in text
    res = cc.CocoCResults.from_json(shipped)
    for c in res.cells:
        chart = cc.corruption_chart(c.corruption, c.severity)
        assert c.chart_delta_e == pytest.approx(chart.mean_delta_e)
        # the report's predictions are recorded, and equal what the shipped tables give now
        # (the direction-aware fit's minimiser stops within 1e-10 of the parameter range)
        now = cc.predict_cell(chart)
        assert c.prediction is not None and now is not None
        assert c.prediction.size == now.size
        for key, value in now.to_json().items():
            if isinstance(value, float):
                assert c.prediction.to_json()[key] == pytest.approx(value, rel=1e-6, abs=1e-9)
            else:
                assert c.prediction.to_json()[key] == value
    assert res.to_json() == shipped


def test_coco_c_report_only_rebuilds(tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    (tmp_path / "cococ.json").write_text((root / "reports/cococ/cococ.json").read_text())
    r = CliRunner().invoke(main, ["coco-c", "--out", str(tmp_path), "--report-only"])
    assert r.exit_code == 0, r.output
    html = (tmp_path / "cococ.html").read_text()
    assert '<svg' in html and 'aria-label="chart ΔE against COCO-C severity"' in html
    assert (tmp_path / "cococ-chart-delta-e.svg").is_file()


def test_reports_are_made_without_matplotlib_or_colour_science(tmp_path):
    """Neither matplotlib nor colour-science is needed for the COCO pipeline's reports: the
    COCO-C report and the validation report (its emulations fitted again for their hold-out
    accuracy, from the shipped training reflectances), figures included, are written with both
    made unimportable."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    (tmp_path / "cococ.json").write_text((root / "reports/cococ/cococ.json").read_text())
    code = (
        "import sys\n"
        "sys.modules['matplotlib'] = sys.modules['colour'] = None\n"
        "from fidelity.cli import main\n"
        "def run(*argv):\n"
        "    try:\n"
        "        main(list(argv))\n"
        "    except SystemExit as e:\n"
        "        assert not e.code, (argv, e.code)\n"
        f"out = {str(tmp_path)!r}\n"
        "run('coco-c', '--out', out, '--report-only', '-q')\n"
        f"run('validate', '--import-scores', {str(root / 'reports/validation/validation.scores.json.gz')!r},"
        " '--store', out + '/vstore', '-q')\n"
        f"run('validate', '--cameras', {str(root / 'cameras')!r}, '--store', out + '/vstore',"
        " '--report-only', '--out', out + '/v', '-q')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "cococ-loss-vs-delta-e.svg").is_file()
    assert (tmp_path / "v" / "classic-vs-directional.svg").is_file()
    shipped = json.loads((root / "reports/validation/validation.json").read_text())
    made = json.loads((tmp_path / "v" / "validation.json").read_text())
    # the emulations' accuracy, fitted again (to another CPU's last bits: jsondiff)
    assert not differences(shipped["cameras"], made["cameras"], "cameras")


def test_shipped_measurements_come_from_this_versions_detectors():
    """Every measured COCO-C loss that `predict --coco-c` reads was measured with this
    version's detector preprocessing and states this version's SE rule (issue 32)."""
    from pathlib import Path

    from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
    from fidelity.coco.detectors import PREPROCESSING

    root = Path(__file__).resolve().parents[2]
    res = cc.CocoCResults.from_json(json.loads((root / "fidelity/data/coco-c.json").read_text()))
    current = {p.describe() for p in PREPROCESSING.values()}
    measured = [m for c in res.cells for m in c.measured]
    assert len(measured) >= len(res.cells) >= 15
    for m in measured:
        assert m.settings.get("preprocess") in current, (m.model, m.mapping)
        assert m.settings.get("standard_error") == {
            "method": "larger", "draws": BOOTSTRAP_RESAMPLES, "seed": BOOTSTRAP_SEED}


def _shipped_json() -> dict:
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    return json.loads((root / "reports/cococ/cococ.json").read_text())


def test_bounds_count_the_cells_each_prediction_bounds():
    """CocoCResults.bounds against a count written here from the report's JSON: measured <=
    predicted, measured − 2 SE <= predicted, median of predicted / measured over the cells
    measured above 0."""
    doc = _shipped_json()
    s = cc.CocoCResults.from_json(doc).bounds()
    rows = [(m["dmap_points"], m["dmap_points_se"], c["prediction"])
            for c in doc["cells"] for m in c["measured"]]
    assert s.cells == len(rows) == 30
    for key in ("classic", "directional"):
        assert getattr(s, f"{key}_within") == sum(x <= p[key] for x, _, p in rows)
        assert getattr(s, f"{key}_within_2se") == sum(x - 2 * e <= p[key] for x, e, p in rows)
        assert getattr(s, f"{key}_median_ratio") == pytest.approx(
            float(np.median([p[key] / x for x, _, p in rows if x > 0])))


def test_the_report_headline_names_the_cells_beyond_the_direction_aware_bound():
    from dataclasses import replace

    from fidelity.report.cococ import _bound_lines

    res = cc.CocoCResults.from_json(_shipped_json())
    cell = res.cells[0]
    m = cell.measured[0]
    pred = cc.CellPrediction(classic=2.0, directional=1.0, classic_relative=None,
                             directional_relative=None)
    one = replace(res, cells=(replace(cell, prediction=pred, measured=(
        replace(m, dmap_points=1.5, dmap_points_se=0.25),
        replace(m, model="zero-se", dmap_points=1.2, dmap_points_se=0.0))),))
    lines = _bound_lines(one)
    assert "**2 of 2**" in lines[0] and "(2 within 2 SE)" in lines[0]
    assert "**0 of 2**" in lines[1] and "(1 within 2 SE)" in lines[1]
    assert f"{m.model} {cell.corruption} {cell.severity} by 0.50 points (2.00 SE)" in lines[1]
    assert "zero-se" in lines[1] and "by 0.20 points (no SE)" in lines[1]
    assert "median over-prediction 1.5×" in lines[0]  # median of 2/1.5 and 2/1.2
    # a table without predictions or measurements has no such lines
    assert _bound_lines(replace(res, cells=tuple(replace(c, prediction=None)
                                                 for c in res.cells))) == []
