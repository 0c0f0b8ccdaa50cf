"""The slanted-edge target beside the chart in the exported scenes (issue 55): ISO 12233:2017
e-SFR square at 4:1 contrast, turned 5 degrees; its corners in the manifest; gate/audit
--manifest measure the sharpness on it; Mitsuba's reconstruction filters give the MTF50 of
their closed forms (Mitsuba's own filter definitions, src/rfilters/box.cpp, gaussian.cpp).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.core.errors import InputFileError
from fidelity.measure.chartsharpness import EdgeTargetCorners, target_sharpness
from fidelity.scene.export import export_scene
from fidelity.scene.manifest import read_manifest
from fidelity.scene.mitsuba import scene_xml
from fidelity.scene.model import build_scene

ROOT = Path(__file__).resolve().parents[2]
#: The default export's resolution: the target's square is 37 px wide there.
SIZE = (640, 480)
#: Mitsuba's MTF50 against its filter's closed form (issue 55: 3 %).
MITSUBA_TOLERANCE = 0.03


def _process(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fidelity", *args], capture_output=True,
                          text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), check=False)


def _mtf50(curve, freq: np.ndarray) -> float:
    """First 0.5 crossing of ``curve`` on ``freq`` (linear interpolation)."""
    i = int(np.flatnonzero(curve < 0.5)[0])
    return float(freq[i - 1] + (curve[i - 1] - 0.5) / (curve[i - 1] - curve[i])
                 * (freq[i] - freq[i - 1]))


def box_mtf50() -> float:
    """Mitsuba's ``box`` filter (radius 0.5 px, every sample splatted into its own pixel):
    the pixel is the mean of the radiance over its area, MTF |sinc(f)|."""
    f = np.linspace(0.0, 1.0, 200001)
    return _mtf50(np.abs(np.sinc(f)), f)


def gaussian_mtf50(stddev: float, discretised: bool = True) -> float:
    """Mitsuba's ``gaussian`` filter (src/rfilters/gaussian.cpp): w(x) = max(0,
    exp(-x^2 / (2 s^2)) - exp(-(4 s)^2 / (2 s^2))), radius r = 4 s, separable. A scalar
    variant splats each sample with its tabulated form (src/render/imageblock.cpp:
    ``eval_discretized``; src/core/rfilter.cpp: 31 values w(r i / 31), looked up at
    floor(|x| 31 / r), 0 from r on). A pixel is the weighted mean of the samples about its
    centre (samples uniform over the image plane), so the line-spread function is that
    staircase normalised and the MTF its Fourier transform."""
    r = 4 * stddev
    x = np.linspace(-r, r, 62001)
    if discretised:
        x_eval = r * np.floor(np.abs(x) * 31 / r) / 31
    else:
        x_eval = x
    w = np.maximum(0.0, np.exp(-x_eval ** 2 / (2 * stddev ** 2)) - math.exp(-8.0))
    w[np.abs(x) >= r] = 0.0
    f = np.linspace(0.0, 1.0, 2001)
    mtf = np.trapezoid(w[None, :] * np.cos(2 * np.pi * f[:, None] * x[None, :]), x, axis=1)
    return _mtf50(mtf / mtf[0], f)


# -------------------------------------------------------------------------------------------
# The target in the model and the manifest
# -------------------------------------------------------------------------------------------

def test_target_is_a_4_to_1_square_turned_5_degrees_beside_the_chart():
    scene = build_scene("D65", resolution=SIZE)
    t = scene.edge_target
    assert (t.dark, t.light) == (0.2, 0.8) and t.luminance_ratio == pytest.approx(4.0)
    px = scene.edge_target_px()
    sq, fld = np.array(px["square_corners_px"]), np.array(px["field_corners_px"])
    assert px["in_image"]
    # every edge of the square 5 degrees off the image axes (the pinhole keeps angles of a
    # plane facing it)
    for a, b in ((0, 1), (1, 2), (2, 3), (3, 0)):
        d = sq[b] - sq[a]
        off = math.degrees(math.atan2(min(abs(d[0]), abs(d[1])), max(abs(d[0]), abs(d[1]))))
        assert off == pytest.approx(5.0, abs=1e-6)
    # beside the chart (right of its frame), inside its light field, inside the image
    right_of_chart = scene.camera.project(scene.chart.width / 2, 0.0)[0]
    assert fld[:, 0].min() > right_of_chart and fld[:, 0].max() < SIZE[0] - 0.5
    assert np.all(sq[:, 0] > fld[:, 0].min()) and np.all(sq[:, 0] < fld[:, 0].max())
    assert np.all(sq[:, 1] > fld[:, 1].min()) and np.all(sq[:, 1] < fld[:, 1].max())
    # the square's side in pixels by the pinhole formula: f x side / distance
    side = np.hypot(*(sq[1] - sq[0]))
    assert side == pytest.approx(scene.camera.focal_px * t.square / scene.camera.distance)


def test_manifest_gives_the_corners_and_read_manifest_takes_them(tmp_path):
    scene = build_scene("D65", resolution=SIZE)
    done = export_scene(scene, "mitsuba", tmp_path / "m", check=False)
    doc = json.loads((done.folder / "manifest.json").read_text())
    target = doc["edge_target"]
    assert target["reflectance"]["square"] == 0.2 and target["reflectance"]["field"] == 0.8
    assert target["luminance_ratio"] == 4.0 and target["angle_deg"] == 5.0
    m = read_manifest(done.folder)
    assert m.edge_target is not None
    np.testing.assert_allclose(m.edge_target.square, target["square_corners_px"])
    np.testing.assert_allclose(m.edge_target.field, target["field_corners_px"])
    # a manifest written before the scenes carried the target still reads (no target)
    del doc["edge_target"]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    assert read_manifest(tmp_path / "old.json").edge_target is None
    # a target outside the image is none to measure
    doc["edge_target"] = dict(target, in_image=False)
    (tmp_path / "out.json").write_text(json.dumps(doc))
    assert read_manifest(tmp_path / "out.json").edge_target is None


@pytest.mark.parametrize("bad", [{"square_corners_px": [[1, 2]] * 3},
                                 {"square_corners_px": [[1, "x"]] * 4}, "square"])
def test_a_malformed_edge_target_is_exit_2_naming_the_file(bad, tmp_path):
    done = export_scene(build_scene("D65", resolution=(160, 120)), "mitsuba", tmp_path / "m",
                        check=False)
    doc = json.loads((done.folder / "manifest.json").read_text())
    doc["edge_target"] = bad if isinstance(bad, str) else {**doc["edge_target"], **bad}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="edge_target"):
        read_manifest(path)
    image = tmp_path / "x.png"
    image.write_bytes(b"")
    r = CliRunner().invoke(main, ["gate", str(image), "--manifest", str(path),
                                  "--max-delta-e", "3"])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "bad.json" in lines[0] and "edge_target" in lines[0]


@pytest.mark.parametrize(("width", "refused"), [(576, False), (572, True), (160, True)])
def test_a_target_too_small_for_the_esfr_is_refused_with_its_reason(width, refused):
    """The ROIs' floors (20 px along, 16 across): at the default fill a 4:3 image from 576 px
    wide gets both edges measured, a smaller one both refused as ``too-short``."""
    scene = build_scene("D65", resolution=(width, width * 3 // 4))
    px = scene.edge_target_px()
    target = EdgeTargetCorners(tuple(map(tuple, px["square_corners_px"])),
                               tuple(map(tuple, px["field_corners_px"])))
    img = np.full((width * 3 // 4, width, 3), 0.8)
    sharp = target_sharpness(img, target, linearise=lambda v: np.asarray(v, np.float64),
                             linearisation="linear")
    assert [e.direction for e in sharp.edges] == ["horizontal", "vertical"]
    if refused:
        assert all(e.refusal is not None and e.refusal[0] == "too-short" for e in sharp.edges)
    else:
        assert all(e.refusal is None and e.roi is not None for e in sharp.edges)


def test_gltf_and_usd_carry_the_target(tmp_path):
    pygltflib = pytest.importorskip("pygltflib", reason="the [scene] extra (pygltflib)")
    pytest.importorskip("pxr", reason="the [scene] extra (usd-core)")
    from pxr import Usd, UsdGeom, UsdShade

    scene = build_scene("D65", resolution=SIZE)
    t = scene.edge_target
    g = pygltflib.GLTF2().load(str(export_scene(scene, "gltf", tmp_path / "g").scene_file))
    mats = {m.name: m.pbrMetallicRoughness.baseColorFactor[:3] for m in g.materials}
    assert mats["edge_square"] == pytest.approx([0.2] * 3)
    assert mats["edge_field"] == pytest.approx([0.8] * 3)
    mesh = next(m for m in g.meshes if m.name == "edge_square")
    acc = g.accessors[mesh.primitives[0].attributes.POSITION]
    view = g.bufferViews[acc.bufferView]
    blob = g.binary_blob()
    pos = np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength],
                        np.float32).reshape(4, 3)
    np.testing.assert_allclose(np.sort(pos[:, :2], axis=0), np.sort(t.square_corners(), axis=0),
                               atol=1e-7)
    stage = Usd.Stage.Open(str(export_scene(scene, "usd", tmp_path / "u").scene_file))
    pts = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Chart/edge_square"))
                   .GetPointsAttr().Get())
    np.testing.assert_allclose(np.sort(pts[:, :2], axis=0), np.sort(t.square_corners(), axis=0),
                               atol=1e-7)
    shader = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/edge_field/PreviewSurface"))
    assert shader.GetInput("diffuseColor").Get() == pytest.approx((0.8, 0.8, 0.8))


# -------------------------------------------------------------------------------------------
# Mitsuba renders
# -------------------------------------------------------------------------------------------

def _render(xml: ET.ElementTree, path: Path, spp: int, crop: tuple[int, int, int, int] | None
            = None) -> np.ndarray:
    mi = pytest.importorskip("mitsuba", reason="the [render] extra (mitsuba)")
    mi.set_variant("scalar_spectral")
    if crop is not None:
        film = xml.getroot().find("sensor/film")
        assert film is not None
        for name, v in zip(("crop_offset_x", "crop_offset_y", "crop_width", "crop_height"), crop,
                           strict=True):
            ET.SubElement(film, "integer", name=name, value=str(v))
    xml.write(path)
    img = mi.render(mi.load_file(str(path)), spp=spp, seed=0)
    return np.asarray(img, np.float64)


def test_mitsuba_render_audit_finds_the_chart_and_gate_measures_the_target(tmp_path):
    """The export rendered by Mitsuba (box filter): audit still finds the chart with the target
    beside it; gate --manifest measures the e-SFR on the target: MTF50 within 3 % of the box
    filter's closed form |sinc| (0.603 cy/px)."""
    pytest.importorskip("mitsuba", reason="the [render] extra (mitsuba)")
    import mitsuba as mi

    scene = build_scene("D65", resolution=SIZE)
    done = export_scene(scene, "mitsuba", tmp_path / "m")
    img = _render(ET.parse(done.scene_file), tmp_path / "chart.xml", 16)
    exr = tmp_path / "render.exr"
    mi.Bitmap(img.astype(np.float32)).write(str(exr))
    found = tmp_path / "audit.json"
    proc = _process("audit", str(exr), "--json", str(found))
    assert proc.returncode == 0, proc.stderr
    corners = np.array(json.loads(found.read_text())["source"]["corners"], np.float64)
    assert np.abs(corners - scene.corners_px()).max() < 1.0
    out = tmp_path / "gate.json"
    proc = _process("gate", str(exr), "--manifest", str(done.folder), "--max-delta-e", "0.5",
                    "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    sharp = json.loads(out.read_text())["sharpness"]
    assert [e["patches"][0] for e in sharp["edges"]] == ["edge target square"] * 2
    expected = box_mtf50()
    assert expected == pytest.approx(0.6034, abs=1e-4)
    for edge in sharp["edges"]:
        assert edge["method"] == "e-SFR" and edge["angle"] == pytest.approx(5.0, abs=0.01)
        y = next(c for c in edge["channels"] if c["channel"] == "Y")
        assert y["mtf50"] == pytest.approx(expected, rel=MITSUBA_TOLERANCE), edge["direction"]


@pytest.mark.parametrize("stddev", [0.5, 1.0])
def test_mitsuba_gaussian_filter_mtf50_within_3_percent_of_its_closed_form(stddev, tmp_path):
    """The exported scene with Mitsuba's gaussian reconstruction filter of ``stddev`` pixels,
    at 1280 x 960 (the square 75 px wide), rendered over the target's field only (a film
    crop): the e-SFR MTF50 of the square's edges within 3 % of the filter's closed form."""
    scene = build_scene("D65", resolution=(1280, 960))
    px = scene.edge_target_px()
    fld = np.array(px["field_corners_px"])
    x0, y0 = (int(v) for v in np.floor(fld.min(axis=0)))
    x1, y1 = (int(v) for v in np.ceil(fld.max(axis=0)))
    img = _render(scene_xml(scene, rfilter="gaussian", stddev=stddev), tmp_path / "g.xml", 64,
                  (x0, y0, x1 - x0 + 1, y1 - y0 + 1))
    shift = np.array([x0, y0], np.float64)
    target = EdgeTargetCorners(tuple(map(tuple, np.array(px["square_corners_px"]) - shift)),
                               tuple(map(tuple, fld - shift)), "test")
    sharp = target_sharpness(img, target, linearise=lambda v: np.asarray(v, np.float64),
                             linearisation="linear")
    expected = gaussian_mtf50(stddev)
    # the Gaussian's MTF50, sqrt(2 ln 2) / (2 pi s), without the cut-off and the table
    assert gaussian_mtf50(stddev, discretised=False) == pytest.approx(
        math.sqrt(2 * math.log(2)) / (2 * math.pi * stddev), rel=2e-3)
    for edge in sharp.edges:
        y = edge.channel("Y")
        assert y is not None and y.mtf50 is not None, edge.refusal
        assert y.mtf50 == pytest.approx(expected, rel=MITSUBA_TOLERANCE), edge.direction


# -------------------------------------------------------------------------------------------
# Blender Cycles
# -------------------------------------------------------------------------------------------

#: Cycles' MTF50 against its pixel filter's prediction (issue 55: 3-5 %; stated: 4 %).
CYCLES_TOLERANCE = 0.04


def blackman_harris_mtf50(filter_width: float) -> float:
    """Cycles' Blackman-Harris pixel filter (intern/cycles/scene/film.cpp,
    ``filter_func_blackman_harris`` and ``filter_table``): the table is built over a width
    W = 2 x filter_width, f(x) = 0.35875 - 0.48829 cos(v) + 0.14128 cos(2 v) - 0.01168
    cos(3 v) with v = 2 pi (x / W + 1/2), for |x| up to W / 2 = filter_width (1 at x = 0,
    ~0 at the ends). Cycles importance-samples each camera ray's offset from the pixel centre
    from this filter (x and y alike, independently) and averages the samples with weight 1, so
    the pixel's line-spread function is f normalised, with no pixel box beside it (assumed:
    the box filter of width 1 is the pixel's area, MTF |sinc|, tested too), and the MTF its
    Fourier transform."""
    w = filter_width
    x = np.linspace(-w, w, 20001)
    v = 2 * np.pi * (x / (2 * w) + 0.5)
    f = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
    freq = np.linspace(0.0, 1.0, 4001)
    mtf = np.trapezoid(f[None, :] * np.cos(2 * np.pi * freq[:, None] * x[None, :]), x, axis=1)
    return _mtf50(mtf / mtf[0], freq)


@pytest.mark.parametrize(("pixel_filter", "width"), [("BLACKMAN_HARRIS", 1.5), ("BOX", 1.0)])
def test_blender_cycles_pixel_filter_predicts_the_targets_mtf50(pixel_filter, width, tmp_path):
    """Cycles renders the exported .glb (1280 x 960, only the target's field: a border crop;
    256 samples, the noise of fewer raising MTF50 by 5-10 %) with its default Blackman-Harris
    pixel filter of 1.5 px: the e-SFR MTF50 of the square's edges within 4 % of the filter's
    prediction (0.444 cy/px); the box of 1 px within 3 % of |sinc| (0.603)."""
    pytest.importorskip("pygltflib", reason="the [scene] extra (pygltflib)")
    from fidelity.chart.image import read_image
    from fidelity.scene.verify import render_with_blender
    from tests.fixtures.blender import require_blender

    require_blender()
    size = (1280, 960)
    scene = build_scene("D65", resolution=size)
    done = export_scene(scene, "gltf", tmp_path / "g")
    px = scene.edge_target_px()
    fld = np.array(px["field_corners_px"])
    x0, y0 = (int(v) for v in np.floor(fld.min(axis=0)))
    x1, y1 = (int(v) + 1 for v in np.ceil(fld.max(axis=0)))
    render = render_with_blender(done.scene_file, tmp_path / "t.exr", *size, samples=256,
                                 pixel_filter=pixel_filter, filter_width=width,
                                 border=(x0, y0, x1, y1))
    assert render.info["pixel_filter_type"] == pixel_filter
    img = np.asarray(read_image(render.image).pixels, np.float64)
    assert img.shape[:2] == (y1 - y0, x1 - x0)
    shift = np.array([x0, y0], np.float64)
    target = EdgeTargetCorners(tuple(map(tuple, np.array(px["square_corners_px"]) - shift)),
                               tuple(map(tuple, fld - shift)), "test")
    sharp = target_sharpness(img, target, linearise=lambda v: np.asarray(v, np.float64),
                             linearisation="linear")
    if pixel_filter == "BOX":
        expected, tolerance = box_mtf50(), MITSUBA_TOLERANCE
    else:
        expected, tolerance = blackman_harris_mtf50(width), CYCLES_TOLERANCE
        assert expected == pytest.approx(0.4444, abs=1e-4)
    for edge in sharp.edges:
        y = edge.channel("Y")
        assert y is not None and y.mtf50 is not None, edge.refusal
        assert y.mtf50 == pytest.approx(expected, rel=tolerance), edge.direction


def test_audit_with_the_manifest_measures_the_target_and_without_it_the_chart(tmp_path):
    """audit --manifest: the sharpness (and so the verdict's) comes from the target's square at
    the manifest's corners; the same image without the manifest: from the chart's own edges
    (at 640 x 480 the chart's ROIs are too short: stated refusals)."""
    from fidelity.chart.image import write_exr
    from tests.fixtures.chart_scenes import closed_form_render

    scene = build_scene("D65", resolution=SIZE)
    done = export_scene(scene, "gltf" if _has("pygltflib") else "mitsuba", tmp_path / "s",
                        check=False)
    exr = tmp_path / "render.exr"
    write_exr(exr, closed_form_render(scene).astype(np.float32))
    reports = {}
    for name, extra in (("manifest", ["--manifest", str(done.folder)]), ("none", [])):
        out = tmp_path / f"{name}.json"
        r = CliRunner().invoke(main, ["audit", str(exr), "--json", str(out), *extra])
        assert r.exit_code == 0, r.output
        reports[name] = json.loads(out.read_text())["sharpness"]
    edges = reports["manifest"]["edges"]
    assert [e["patches"] for e in edges] == [["edge target square", "edge target field"]] * 2
    assert all(e["method"] == "e-SFR" and e["refusal"] is None for e in edges)
    assert "slanted-edge target" in reports["manifest"]["method"]
    assert all(e["patches"][0] != "edge target square" for e in reports["none"]["edges"])


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None
