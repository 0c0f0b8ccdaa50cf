"""The sharpness and noise tables (fidelity.prediction.properties) on hand-built tables whose
answers follow by hand: linear interpolation in 1/x between a family's cells and the
undegraded chart, the worst case over families and detectors, the running maximum, the
ceiling beyond the table, the threshold as the inverse, the sum as the combination; and the
shipped tables: every cell's x is what the audit's measurement reads on the degraded
calibration chart."""

from __future__ import annotations

import json
import math

import pytest

from fidelity.chart.image import write_png
from fidelity.coco.degradations import Degradation
from fidelity.coco.tables.degradation import calibrate_level, calibration_chart
from fidelity.core.errors import InputFileError, InvalidValueError, UnknownNameError
from fidelity.pipeline.check import audit_image
from fidelity.prediction.properties import (
    DOMINANCE_ORDER,
    INTERACTION,
    PropertyCell,
    PropertyTable,
    combine,
    detector_scale,
    dominant_property,
    load_property_table,
    parse_property_table,
    predict_property,
    property_threshold,
    worst_case_losses,
)
from fidelity.prediction.verdict import Criterion


def _cell(family: str, x: float, loss: float, se: float = 0.1) -> PropertyCell:
    return PropertyCell(family, x, x, {"dmap_points": loss}, {"dmap_points": se})


def _table(baseline: float = 0.5) -> PropertyTable:
    cells = {"a_n": (_cell("blur", 0.25, 2.0), _cell("blur", 0.125, 6.0),
                     _cell("disc", 0.2, 1.0), _cell("disc", 0.1, 8.0)),
             "b_s": (_cell("blur", 0.25, 3.0, 0.2),)}
    return PropertyTable("t", "sharpness", baseline, {"a_n": "n", "b_s": "s"}, cells,
                         {"a_n": 100, "b_s": 100})


def test_linear_in_one_over_x_to_the_undegraded_chart():
    t = _table()
    # u = 1/x: baseline 2, blur (4, 2.0), (8, 6.0); at x = 1/3 (u = 3): half way to blur's 2.0
    p = predict_property(t, 1 / 3, size="n")
    assert p.loss == pytest.approx(1.0) and p.family == "blur" and p.status == "in-range"
    # u = 6: blur 4.0, disc between (5, 1.0) and (10, 8.0): 2.4 -> blur
    p = predict_property(t, 1 / 6, size="n")
    assert p.loss == pytest.approx(4.0) and p.family == "blur"
    # u = 9: blur is past its harshest (6.0, a lower bound), disc 6.6
    p = predict_property(t, 1 / 9, size="n")
    assert p.loss == pytest.approx(1.0 + 0.8 * 7.0) and p.family == "disc"


def test_worst_case_over_detectors_of_the_size_class():
    t = _table()
    assert predict_property(t, 0.25, size="n").loss == pytest.approx(2.0)
    p = predict_property(t, 0.25, size="any")
    assert p.loss == pytest.approx(3.0) and p.detector == "b_s"
    with pytest.raises(InvalidValueError, match="size class"):
        predict_property(t, 0.25, size="x")


def test_baseline_and_beyond():
    t = _table()
    assert predict_property(t, 0.5).status == "baseline"
    assert predict_property(t, 0.9).loss == 0.0
    p = predict_property(t, 0.05)
    assert p.status == "beyond" and p.loss == 8.0 and p.u_loss is None


def test_running_maximum_never_lets_the_loss_fall():
    cells = {"m": (_cell("f", 0.3, 3.0), _cell("f", 0.2, 1.0), _cell("f", 0.1, 5.0))}
    t = PropertyTable("t", "sharpness", 0.6, {"m": "n"}, cells, {"m": 1})
    assert predict_property(t, 0.2).loss == pytest.approx(3.0)
    assert predict_property(t, 0.25).loss == pytest.approx(3.0)


@pytest.mark.parametrize("name", ["sharpness", "noise", "small"])
def test_a_whole_curve_at_once_is_the_prediction_point_by_point(name):
    """worst_case_losses (the report's curve) equals predict_property's loss at every x: the
    shipped tables (every column) and a small one, below, inside and beyond the cells."""
    tables = ([load_property_table(name)] if name != "small" else
              [_table(), PropertyTable("r", "sharpness", 0.6, {"m": "n"}, {"m": (
                  _cell("f", 0.3, 3.0), _cell("f", 0.2, 1.0), _cell("f", 0.1, 5.0))},
                  {"m": 1})])
    for t in tables:
        xs = [c.x for m in t.models for c in t.cells[m]]
        top = t.baseline_x * 1.2 if math.isfinite(t.baseline_x) else max(xs) * 3
        grid = [min(xs) / 3, *xs, *[min(xs) + k * (top - min(xs)) / 97 for k in range(98)]]
        if not math.isfinite(t.baseline_x):
            grid.append(math.inf)
        for column in sorted({k for m in t.models for c in t.cells[m] for k in c.losses}):
            for size in ("any", *sorted(set(t.models.values()))):
                point = [predict_property(t, x, column=column, size=size).loss for x in grid]
                curve = worst_case_losses(t, grid, column=column, size=size)
                assert curve == pytest.approx(point, abs=1e-12), (t.name, column, size)
    with pytest.raises(InvalidValueError):
        worst_case_losses(_table(), [0.2, float("nan")])
    with pytest.raises(UnknownNameError):
        worst_case_losses(_table(), [0.2], column="nope")


def test_noise_table_baseline_is_noiseless():
    cells = {"m": (PropertyCell("n", 1, 10.0, {"dmap_points": 2.0}, {}),)}
    t = PropertyTable("t", "noise", math.inf, {"m": "n"}, cells, {"m": 1})
    # u = 1/20 is half way from u0 = 0 to 1/10
    assert predict_property(t, 20.0).loss == pytest.approx(1.0)
    assert predict_property(t, math.inf).status == "baseline"
    assert property_threshold(t, 1.0) == pytest.approx(20.0, rel=1e-6)


def test_threshold_is_the_inverse_of_the_prediction():
    t = _table()
    for loss in (0.5, 2.0, 5.0):
        x = property_threshold(t, loss)
        assert x is not None
        assert predict_property(t, x).loss == pytest.approx(loss, abs=1e-6)
    assert property_threshold(t, 50.0) is None


def test_uncertainty_adds_the_slope_times_u_x():
    t = _table()
    bare = predict_property(t, 1 / 3, size="n")
    wide = predict_property(t, 1 / 3, size="n", u_x=0.02)
    assert bare.u_loss == pytest.approx(0.05)  # half way between SE 0 and 0.1
    assert wide.u_loss is not None and wide.u_loss > bare.u_loss


@pytest.mark.parametrize("x", [0.0, -1.0, math.nan])
def test_bad_values(x):
    with pytest.raises(InvalidValueError, match="mtf50"):
        predict_property(_table(), x)


def test_json_round_trip_and_malformed_files():
    t = _table()
    back = parse_property_table(json.loads(json.dumps(t.to_json())), "t.json")
    assert back.cells == t.cells and back.models == t.models and back.baseline_x == 0.5
    d = t.to_json()
    d["models"]["a_n"]["cells"][0]["x"] = -1
    with pytest.raises(InputFileError, match=r"t.json: models.a_n.cells\[0\].x"):
        parse_property_table(d, "t.json")
    with pytest.raises(InputFileError, match="kind"):
        parse_property_table({"kind": "other"}, "t.json")


def test_combination_is_the_sum_with_the_dominant_property():
    c = combine({"colour": (0.5, 0.1), "sharpness": (3.0, 0.2), "noise": None})
    assert c.loss == pytest.approx(3.5) and c.dominant == "sharpness"
    assert c.u_loss == pytest.approx(math.hypot(0.1, 0.2)) and c.missing == ("noise",)


def test_a_tie_for_the_dominant_property_is_broken_in_a_fixed_order():
    """Equal losses (both at the baseline's 0, or apart by a processor's last bits) name the
    first of DOMINANCE_ORDER whatever the parts' order; a loss larger beyond the tolerance
    wins."""
    assert DOMINANCE_ORDER == ("colour", "sharpness", "noise")
    for order in (("noise", "sharpness", "colour"), ("sharpness", "colour", "noise")):
        zeros = {k: (0.0, 0.1) for k in order}
        assert combine(zeros).dominant == "colour"
        near = {k: (0.45 * (1 + 1e-12 * i), 0.1) for i, k in enumerate(order)}
        assert combine(near).dominant == "colour"
    assert dominant_property({"noise": 0.3, "sharpness": 0.3}) == "sharpness"
    assert dominant_property({"colour": 0.45, "noise": 0.45 * (1 + 1e-4)}) == "noise"
    assert dominant_property({"zeta": 1.0, "alpha": 1.0}) == "alpha"


def test_blur_and_noise_add_their_interaction_with_its_uncertainty_propagated():
    """sum + sqrt(l_s l_n) (INTERACTION 1): 4 + 1 + 2 = 7; the first-order uncertainty
    equals a central finite-difference propagation (a second method)."""
    parts = {"colour": (0.5, 0.05), "sharpness": (4.0, 0.3), "noise": (1.0, 0.2)}
    c = combine(parts)
    assert INTERACTION == 1.0
    assert c.loss == pytest.approx(7.5) and c.interaction == pytest.approx(2.0)
    h, grads = 1e-6, []
    for k in parts:
        up = {q: ((v[0] + h, v[1]) if q == k else v) for q, v in parts.items()}
        dn = {q: ((v[0] - h, v[1]) if q == k else v) for q, v in parts.items()}
        grads.append((combine(up).loss - combine(dn).loss) / (2 * h) * parts[k][1])
    assert c.u_loss == pytest.approx(math.sqrt(sum(g * g for g in grads)), rel=1e-6)
    # a zero part: no interaction, no division by zero; a negative loss counts as none
    for zero in (0.0, -0.3):
        z = combine({"sharpness": (zero, 0.1), "noise": (2.0, 0.1)})
        assert z.interaction == 0.0 and z.loss == pytest.approx(2.0 + zero)
        assert z.u_loss == pytest.approx(math.hypot(0.1, 0.1))
    assert combine(parts, interaction=0.0).loss == pytest.approx(5.5)


def test_detector_scale():
    assert detector_scale(1280, 960) == 0.5 and detector_scale(640, 480) == 1.0
    with pytest.raises(InvalidValueError):
        detector_scale(0, 10)


@pytest.mark.parametrize("prop", ["sharpness", "noise"])
def test_shipped_tables_axis_is_the_chart_measurement(prop):
    t = load_property_table(prop)
    chart = calibration_chart()
    cells = [c for m in t.models for c in t.cells[m]]
    assert len(cells) >= 10
    for c in cells[:: max(1, len(cells) // 4)]:
        level = calibrate_level(c.family, c.level, chart)
        assert level.x == pytest.approx(c.x, rel=1e-9), c


def test_the_same_camera_at_1280_and_640_px_predicts_the_same_loss(tmp_path):
    """Issue 56, requirement 2: a blur of sigma 2 px on a 1280 px image is a blur of 1 px at
    the detector's 640 px input; the audit converts the native MTF50 by the letterbox factor
    and predicts the same loss as for the 640 px image blurred by 1 px."""
    results = []
    for scale, sigma in ((1, 1.0), (2, 2.0)):
        img, _ = calibration_chart(scale)
        path = tmp_path / f"chart{scale}.png"
        write_png(path, Degradation("gaussian-blur", sigma)(img) / 255.0, 8)
        report = audit_image(path, criterion=Criterion("max-dmap", 100.0))
        assert report.properties is not None
        p = report.properties.prediction("sharpness")
        assert p is not None and p.u_loss is not None
        results.append(p)
    small, large = results
    assert large.scale == pytest.approx(0.5) and small.scale == 1.0
    assert large.native_x == pytest.approx(small.x / 2, rel=0.05)
    assert abs(large.loss - small.loss) <= 2 * math.hypot(small.u_loss, large.u_loss) + 0.05
