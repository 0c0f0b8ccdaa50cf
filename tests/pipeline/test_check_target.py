"""``fidelity check`` measures sharpness on an ISO 12233 slanted-edge target it renders beside
its turned chart (0.2 on 0.8, 5 degrees, a 176 px square), and judges it on the tables'
patch-edge axis through a computed map (:class:`fidelity.prediction.properties.TargetAxis`).

References, none of them this package's output:

- the closed-form MTF of a Gaussian PSF with the pixel aperture,
  ``exp(-2 pi^2 sigma^2 f^2) |sinc f|``, solved for MTF50 by SciPy's ``brentq``;
- the sharpness table's own ``gaussian-blur`` cells, whose x values were measured on the
  calibration chart when the table was built (``fidelity/data/properties``);
- the shipped target axis, computed again here from the blurred images.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from fidelity.camera.model import Noise, load_camera
from fidelity.camera.optics import Optics
from fidelity.chart.turned import CHECK_EDGE_TARGET, PaintedEdgeTarget
from fidelity.core.errors import InputFileError
from fidelity.measure.chartsharpness import TARGET_METHOD
from fidelity.pipeline.check import check_camera
from fidelity.prediction.properties import (
    TARGET_AXIS_FILE,
    load_property_table,
    load_target_axis,
    parse_target_axis,
)
from tests import jsondiff

CAMERAS = Path(__file__).resolve().parents[2] / "cameras"


def closed_form_mtf50(sigma: float) -> float:
    """MTF50 of exp(-2 pi^2 sigma^2 f^2) |sinc f| (SciPy's root finder; numpy's sinc)."""
    return float(brentq(lambda f: math.exp(-2 * math.pi ** 2 * sigma ** 2 * f * f)
                        * abs(np.sinc(f)) - 0.5, 1e-6, 0.99, xtol=1e-12))


def quiet_camera(sigma: float):
    """The default camera without noise, with a Gaussian PSF of ``sigma`` px (none at 0)."""
    cam = load_camera("nikon-5100")
    optics = Optics("gaussian", sigma_px=sigma) if sigma > 0 else Optics()
    return dataclasses.replace(cam, noise=Noise(None), optics=optics)


# the target's MTF50 against the closed form: (sigma px, relative bound)
CLOSED_FORM = [(0.0, 0.005), (1.0, 0.005), (1.5, 0.006), (2.5, 0.01), (4.0, 0.02)]


@pytest.mark.parametrize(("sigma", "bound"), CLOSED_FORM)
def test_check_measures_the_edge_target_within_the_closed_form(sigma, bound):
    report = check_camera(quiet_camera(sigma), criterion=None)
    s = report.sharpness
    assert s is not None and s.method == TARGET_METHOD
    assert [e.direction for e in s.edges] == ["horizontal", "vertical"]
    ref = closed_form_mtf50(sigma)
    for e in s.edges:
        assert e.method == "e-SFR" and e.refusal is None
        assert abs(e.angle - CHECK_EDGE_TARGET.angle_deg) < 0.05
        y = e.channel("Y")
        assert y is not None and y.mtf50 is not None
        assert abs(y.mtf50 / ref - 1) <= bound, (sigma, e.direction, y.mtf50, ref)


def test_the_verdict_reads_the_target_on_the_tables_axis():
    """A camera blurred as the table's gaussian-blur 1.5 px cell is judged at that cell's x
    (measured on the calibration chart's patch edges when the table was built), not at the
    target's own, lower MTF50."""
    report = check_camera(quiet_camera(1.5))
    table = load_property_table("sharpness")
    cell_x = [c.x for cells in table.cells.values() for c in cells
              if c.family == "gaussian-blur" and c.level == 1.5]
    assert cell_x
    pred = next(p for p in report.properties.predictions if p.property == "sharpness")
    assert pred.target_x is not None and pred.native_x is not None
    assert pred.target_x < pred.native_x
    # the target's MTF50 is the softer edge's; the cell's x the calibration chart's
    assert abs(pred.x / cell_x[0] - 1) < 0.01, (pred.x, cell_x[0])
    # and the factor is not one number: 1.03 sharp, larger as the blur grows
    axis = load_target_axis()
    ratios = [a / t for _, t, a in axis.points]
    assert 1.02 < ratios[0] < 1.04 and ratios[-1] > 1.3


def test_the_shipped_target_axis_is_what_the_blurred_images_measure():
    from fidelity.coco.tables.degradation import target_axis

    shipped = json.loads(TARGET_AXIS_FILE.read_text())
    assert jsondiff.differences(target_axis().to_json(), shipped) == []


def test_the_axis_map_passes_through_its_points_and_keeps_its_end_ratios():
    axis = load_target_axis()
    for _, t, a in axis.points:
        assert axis.on_table_axis(t) == pytest.approx(a, rel=1e-12)
    (_, t0, a0), (_, t1, a1) = axis.points[0], axis.points[-1]
    assert axis.on_table_axis(0.7) == pytest.approx(0.7 * a0 / t0)
    assert axis.on_table_axis(0.01) == pytest.approx(0.01 * a1 / t1)
    # monotone: a softer target is a softer chart
    xs = np.linspace(0.02, 0.7, 200)
    ys = [axis.on_table_axis(float(x)) for x in xs]
    assert np.all(np.diff(ys) > 0)


@pytest.mark.parametrize("doc", [{}, {"points": [{"sigma_px": 0, "target_mtf50": 0.6}]},
                                 {"points": [{"sigma_px": 0, "target_mtf50": 0.6,
                                              "table_mtf50": 0.62},
                                             {"sigma_px": 1, "target_mtf50": 0.7,
                                              "table_mtf50": 0.5}]}])
def test_a_broken_target_axis_file_is_refused(doc):
    with pytest.raises(InputFileError, match="x.json: not a target axis file"):
        parse_target_axis(doc, "x.json")


def test_the_painted_square_covers_its_area():
    t = PaintedEdgeTarget()
    cov = t.coverage()
    assert cov.min() == 0.0 and cov.max() == 1.0
    assert cov.sum() == pytest.approx(t.side_px ** 2, rel=2e-4)
    img = t.paint([1.0, 0.5, 0.25])
    assert img[0, 0].tolist() == [0.8, 0.4, 0.2]
    c = t.size[0] // 2
    assert img[c, c].tolist() == pytest.approx([0.2, 0.1, 0.05])
    with pytest.raises(ValueError, match="out of its domain"):
        PaintedEdgeTarget(size=(100, 100))


def test_mitsuba_renders_the_check_target_as_the_closed_form():
    pytest.importorskip("mitsuba")
    from fidelity.camera.render import render_chart

    cam = quiet_camera(0.0)
    mits = render_chart(cam, renderer="mitsuba", frame=True, spp=64).frame
    closed = render_chart(cam, frame=True).frame
    assert mits is not None and closed is not None
    assert mits.target_renderer == "mitsuba" and closed.target_renderer == "closed-form"
    from fidelity.pipeline.check import frame_properties

    a = frame_properties(mits, "scene", "D65")[0]
    b = frame_properties(closed, "scene", "D65")[0]
    assert a is not None and b is not None
    ref = closed_form_mtf50(0.0)
    for ea, eb in zip(a.edges, b.edges, strict=True):
        ya, yb = ea.channel("Y"), eb.channel("Y")
        assert abs(ya.mtf50 / ref - 1) < 0.03, ya.mtf50
        assert abs(ya.mtf50 / yb.mtf50 - 1) < 0.03


def test_the_frame_reads_its_patch_edges_only_where_the_target_refuses():
    """A measured target spares the patch edges (their sharpness is not computed, the noise is
    the same); a camera whose target clips (over-exposed) is read on the patch edges."""
    from fidelity.camera.render import frame_properties, render_chart
    from fidelity.measure.pixels import measure_pixels

    frame = render_chart(load_camera("nikon-5100"), frame=True).frame
    assert frame is not None
    sharpness, noise = frame_properties(frame, "scene", "D65")
    assert sharpness is not None and sharpness.method.startswith("the slanted-edge target")
    kw = dict(encoding="srgb", reference="scene", illuminant="D65", uncertainty=False,
              corner_checks=False)
    full = measure_pixels(frame.srgb, frame.corners, **kw)
    bare = measure_pixels(frame.srgb, frame.corners, sharpness=False, **kw)
    assert full.sharpness is not None and bare.sharpness is None
    assert bare.noise == full.noise == noise
    over = render_chart(load_camera(str(CAMERAS / "nikon5100-overexposed.toml")), frame=True).frame
    assert over is not None
    edges = frame_properties(over, "scene", "D65")[0]
    assert edges is not None and edges.method.startswith("the brightest-contrast")
