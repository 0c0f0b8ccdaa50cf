"""Direction-aware prediction: the split of a chart error, the family fits, the table, the
validation on the 30 cameras."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab
from fidelity.pipeline.qualify import sharma_pairs
from fidelity.prediction import directional as dr
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.transforms import TRANSFORMS

ROOT = Path(__file__).resolve().parents[2]
SHARMA = sharma_pairs()


def test_weighted_terms_rebuild_ciede2000_on_sharma_pairs():
    """l² + c² + h² + R_T c h is ΔE00² on Sharma et al.'s 34 pairs (published ΔE00)."""
    lt, c, h, rt = dr.delta_e_2000_terms(SHARMA[:, :3], SHARMA[:, 3:6])
    rebuilt = np.sqrt(lt * lt + c * c + h * h + rt * c * h)
    np.testing.assert_allclose(rebuilt, SHARMA[:, 6], atol=1e-4)


def test_parts_add_up_to_the_chart_delta_e_and_follow_the_direction():
    chart = load_chart()
    ref = chart.lab
    rng = np.random.default_rng(3)
    lab = ref + rng.normal(0, 2, ref.shape)
    parts = dr.error_parts(ref, lab)
    assert parts.delta_e == pytest.approx(float(delta_e_2000(lab, ref).mean()), rel=1e-12)
    lighter = ref + np.array([4.0, 0.0, 0.0])  # pure lightness
    p = dr.error_parts(ref, lighter)
    assert p.shares()["lightness"] > 0.999 and p.dominant == "lightness"
    # a hue rotation in a*b* keeps L* and chroma: (almost) all hue
    ang = np.radians(10)
    rot = ref.copy()
    rot[:, 1] = ref[:, 1] * np.cos(ang) - ref[:, 2] * np.sin(ang)
    rot[:, 2] = ref[:, 1] * np.sin(ang) + ref[:, 2] * np.cos(ang)
    assert dr.error_parts(ref, rot).shares()["hue"] > 0.97


def test_a_zero_error_is_not_split_into_thirds_in_words():
    ref = load_chart().lab
    zero = dr.predict_directional(ref, ref.copy())
    assert zero.dmap_points == 0 and zero.parts.delta_e == 0
    assert zero.explanation() == "no colour error to split by direction"
    tiny = dr.predict_directional(ref, ref + np.array([1e-6, 0.0, 0.0]))
    assert tiny.explanation().startswith("tone 100 %")


@pytest.mark.parametrize("name, param", [("contrast", 1.31), ("saturation", 0.62),
                                         ("hue", -23.0), ("gamma", 1.4),
                                         ("pull_mean", 0.7), ("brightness", -0.08)])
def test_a_transformed_chart_is_explained_by_its_own_family(name, param):
    """Fitting recovers the parameter of a chart made by a transform, and explains it all."""
    chart = load_chart()
    spec = {s.name: s for s in dr._fit_specs().values()}[name]
    lab = srgb_to_lab(spec.function(np.clip(chart.srgb, 0, 1), param))
    fit = dr.fit_family(chart.lab, lab, name)
    assert fit.param == pytest.approx(param, rel=1e-4, abs=1e-4)
    assert fit.explained > 0.999
    assert dr.fit_families(chart.lab, lab)[0].family == spec.family


def test_shipped_table_is_rebuilt_from_tables_json():
    """coco1000-directional.json is what directional_table makes of reports/coco/tables.json,
    and its classic curves are the measured table's."""
    from fidelity.coco.tables.colour import TablesResult
    from fidelity.coco.tables.directional import directional_table
    from fidelity.core.fileio import json_ready
    from fidelity.prediction.tablefile import prediction_dir

    result = TablesResult.from_json(json.loads((ROOT / "reports/coco/tables.json").read_text()))
    built = json_ready(directional_table(result.tables))
    shipped = json.loads((prediction_dir() / "coco1000-directional.json").read_text())
    assert built == shipped
    classic = json.loads((prediction_dir() / "coco1000-measured.json").read_text())
    assert shipped["curves"] == classic["curves"]
    # a family's curve at a ΔE is the worst of its transforms over the four models there
    cells = [c for cs in result.tables.cells.values() for c in cs if c.done
             and c.transform in dr.FAMILIES["chroma"].transforms and c.delta_e == 10.0]
    agg = next(c for c in shipped["families"]["chroma"]["curves"] if c["model"] is None)
    point = next(p for p in agg["points"] if p["delta_e"] == 10.0)
    assert point["dmap_points"] == pytest.approx(max(c.dmap_points for c in cells), abs=1e-4)
    assert point["worst_transform"] == "saturation-inc"


def test_family_membership_matches_what_each_transform_moves():
    """The tone and hue families move what they are named for on the chart (computed)."""
    shares = dr.family_shares()
    for t in dr.FAMILIES["tone"].transforms:
        assert shares[t]["lightness"] > 0.8, t
    assert shares["hue"]["hue"] > 0.75
    for t in dr.FAMILIES["contrast"].transforms + dr.FAMILIES["chroma"].transforms:
        assert shares[t]["lightness"] > 0.2 and shares[t]["chroma"] > 0.3, t


def _sweep_worst(transform: str, target: float) -> float:
    from fidelity.coco.tables.colour import TablesResult

    result = TablesResult.from_json(json.loads((ROOT / "reports/coco/tables.json").read_text()))
    return max(c.dmap_points for cs in result.tables.cells.values() for c in cs
               if c.done and c.transform == transform and c.delta_e == target)


@pytest.mark.parametrize("transform, target", [("contrast-inc", 12.0), ("saturation-inc", 10.0),
                                               ("pull_mean", 21.0), ("hue", 8.0),
                                               ("contrast-dec", 24.0)])
def test_the_sweeps_own_cells_stay_bounded(transform, target):
    """A chart made by a SAFE-COLOR transform is predicted at least its measured worst loss
    (the fast twin of the slow test over every cell)."""
    from fidelity.prediction.calibration import load_calibration_table

    cal = load_calibration_table()
    entry = next(e for e in cal.entries if e.transform == transform and e.target == target)
    chart = load_chart()
    lab = srgb_to_lab(TRANSFORMS[transform](chart.srgb, entry.param))
    p = dr.predict_directional(chart.lab, lab, delta_e=target, size="n")
    # the table holds values rounded to 1e-4 points
    assert p.dmap_points >= _sweep_worst(transform, target) - 2e-4


@pytest.mark.slow
def test_every_sweep_cell_stays_bounded():
    from fidelity.prediction.calibration import load_calibration_table

    chart = load_chart()
    tab = dr.load_directional_table()
    for e in load_calibration_table().entries:
        if not e.reachable or e.target not in (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 18, 21, 24):
            continue
        lab = srgb_to_lab(TRANSFORMS[e.transform](chart.srgb, e.param))
        p = dr.predict_directional(chart.lab, lab, delta_e=e.target, size="n", table=tab)
        assert p.dmap_points >= _sweep_worst(e.transform, e.target) - 2e-4, e


def test_directional_never_exceeds_classic_and_weights_add_up():
    from fidelity.camera.render import render_chart
    from fidelity.prediction.table import predict

    for cam in ("nikon-5100", "sigma-sdmerrill", "cameras/bad-hue-rotation.toml"):
        m = render_chart(ROOT / cam if cam.endswith(".toml") else cam).measurement
        d = dr.predict_chart(m, size="n")
        c = predict(m.mean_delta_e, size="n", transforms=False)
        assert sum(t.weight for t in d.terms) == pytest.approx(1.0)
        for col in dr.COLUMNS:
            assert d.columns[col] <= c.columns[col].value + 1e-9, (cam, col)


def _directional_validation(model: str):  # type: ignore[no-untyped-def]
    from fidelity.coco.validate.colour import ValidationResults, directional_validation

    doc = json.loads((ROOT / "reports/validation/validation.json").read_text())
    doc.pop("directional", None)  # recomputed here, not read back
    doc["rows"] = [r for r in doc["rows"] if r["model"] == model]
    return directional_validation(ValidationResults.from_json(doc))


def test_validation_both_bounds_hold_on_the_30_cameras():
    """On the validation's 30 YOLOX-nano cells (stored measured loss ± SE, charts from the
    stored renders; the tables' YOLOX-nano rows measured with the same preprocessing) the
    direction-aware bound holds within 2 SE for every class and over-predicts mAP far less than
    the classic one."""
    dv = _directional_validation("yolox_nano")
    for cls, s in dv.summary.items():
        assert s.cells == 30 and s.directional_within_2se == 30, cls
    s = dv.summary["all"]
    assert s.directional_median_ratio < s.classic_median_ratio / 2
    warned = {c.camera: [w.kind for w in c.warnings] for c in dv.cameras.values() if c.warnings}
    assert warned["nikon5100-gamma22"] == ["shadow-tone"]
    assert "nikon5100-cheung-d65" not in warned


def test_validation_directional_bound_holds_for_yolo11n():
    """YOLO11n's 30 cells (250 images; its table rows still of the earlier preprocessing): the
    direction-aware bound holds within 2 SE of the loss's SE (the larger of bootstrap and
    jackknife). Held as a strict xfail while the SE was the paired fold SE, which understated
    the SE of a pooled loss 4-5x on these 250 images (reports/validation/standard_error.md);
    with the bootstrap SE alone (0.6x the split-sample reference) bad-5bit would be 2.2 SE
    over."""
    dv = _directional_validation("yolo11n-int8dyn")
    for cls, s in dv.summary.items():
        assert s.cells == 30 and s.directional_within_2se == 30, cls


def test_directional_verdict_and_json_round_trip():
    from fidelity.pipeline.check import check_camera
    from fidelity.pipeline.records import ChartReport
    from fidelity.prediction.verdict import Criterion
    from fidelity.report.jsonform import chart_report_json

    crit = Criterion("max-dmap", 5.0)
    cam = ROOT / "cameras" / "bad-hue-rotation.toml"
    classic = check_camera(cam, criterion=crit)
    directional = check_camera(cam, criterion=crit, judge=JudgeOptions(bound="directional"))
    assert not classic.verdict.passed and directional.verdict.passed
    # the colour part of the verdict is the direction-aware loss; sharpness and noise add to it
    props = directional.properties
    assert props is not None
    assert props.colour == pytest.approx(directional.directional.dmap_points)
    assert props.combined is not None
    assert directional.verdict.value == pytest.approx(
        props.colour + sum(x.loss or 0.0 for x in props.predictions) + props.combined.margin)
    doc = chart_report_json(directional)
    assert doc["bound"] == "directional"
    back = ChartReport.from_json(doc)
    assert chart_report_json(back) == doc


def test_the_families_fitted_together_are_each_fitted_alone():
    """fit_families runs the six Brent searches in lockstep; each fit is fit_family's."""
    ch = load_chart()
    lab = srgb_to_lab(TRANSFORMS["gamma-inc"](ch.srgb, 1.3)) + np.array([0.5, -1.0, 2.0])
    together = {f.fit: f for f in dr.fit_families(ch.lab, lab)}
    assert set(together) == {"brightness", "gamma", "contrast", "saturation", "hue",
                             "pull_mean"}
    for name, fit in together.items():
        assert fit == dr.fit_family(ch.lab, lab, name)
