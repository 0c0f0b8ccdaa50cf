"""``fidelity scene``: the chart scene exported as glTF, OpenUSD and Mitsuba XML, proven by
third-party renderers (issue 28).

The proof: Blender's Cycles (the ``bpy`` wheel, run as its own process: bpy pins numpy < 2)
imports the .glb and the .usda with Blender's own importers and renders them; ``fidelity
gate`` measures the render at the manifest's corners with no chart finding and fixed exposure
0: mean ΔE00 against the reference <= 0.5. Mitsuba 3 loads and renders the XML; its patches
match the closed-form render of the same spectra within 0.05 ΔE00. Writing the sRGB-encoded
values as linear factors (the common mistake) fails the same gate by far.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.scene.export import FORMATS, MissingExtraError, export_scene, wrongly_encoded
from fidelity.scene.model import CLASSIC, build_scene
from fidelity.scene.verify import (
    delta_e_linear,
    patch_linear_means,
    render_with_blender,
)
from tests.fixtures.blender import require_blender

ROOT = Path(__file__).resolve().parents[2]
#: Small renders keep the file fast: patches of about 18 pixels.
SIZE = (160, 120)
BOUND_RGB = 0.5
BOUND_MITSUBA = 0.05


@pytest.fixture(scope="module")
def d65():
    return build_scene("D65", resolution=SIZE)


def gate_json(image: Path, manifest: dict, tmp: Path) -> tuple[int, dict]:
    """``fidelity gate`` (a process, as CI runs it) with the manifest's corners and exposure."""
    out = tmp / f"{image.stem}-gate.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-m", "fidelity", "gate", str(image), "--corners", manifest["corners"],
         "--exposure", str(manifest["expected_exposure"]["gate_exposure_ev"]),
         "--illuminant", manifest["illuminant"], "--reference", manifest["reference"],
         "--max-delta-e", str(BOUND_RGB), "--json", str(out)],
        capture_output=True, text=True, env=env, check=False)
    assert out.exists(), proc.stderr
    return proc.returncode, json.loads(out.read_text())


# -------------------------------------------------------------------------------------------
# The model
# -------------------------------------------------------------------------------------------

def test_geometry_and_camera_by_hand(d65):
    # physical size of the Classic; patch 1 top left, patch 24 bottom right as seen
    assert CLASSIC.width == pytest.approx(0.2794) and CLASSIC.height == pytest.approx(0.2159)
    x0, y0 = CLASSIC.patch_centre(0)
    x23, y23 = CLASSIC.patch_centre(23)
    assert x0 < 0 < y0 and x23 > 0 > y23
    cam = d65.camera
    # 4:3 is wider than the chart (279.4:215.9), so its height fills 0.8 of the image
    # (default fill), by the pinhole formula u = W/2 + f x / d
    left = cam.project(-CLASSIC.width / 2, 0)[0]
    right = cam.project(CLASSIC.width / 2, 0)[0]
    top = cam.project(0, CLASSIC.height / 2)[1]
    bottom = cam.project(0, -CLASSIC.height / 2)[1]
    assert (bottom - top) / cam.height == pytest.approx(0.8)
    assert (right - left) / cam.width == pytest.approx(0.8 * 279.4 / 215.9 * 120 / 160)
    # corner order of --corners: dark skin, bluish green, black, white
    c = d65.corners_px()
    assert c[0, 0] < c[1, 0] and c[0, 1] == pytest.approx(c[1, 1])
    assert c[2, 1] > c[1, 1] and c[3, 0] == pytest.approx(c[0, 0])
    # the albedos are the reference's linear sRGB, clipped only where it leaves [0, 1]
    inside = ~d65.clipped
    np.testing.assert_allclose(d65.albedo[inside], d65.reference_linear[inside])
    assert d65.patch_names[int(np.flatnonzero(d65.clipped)[0])] == "cyan"


def test_light_units(d65):
    # pi x white level in renderer units; 683 lm/W for glTF's lux
    assert d65.irradiance == pytest.approx(math.pi)
    assert d65.illuminance_lux == pytest.approx(683 * math.pi)
    half = build_scene("D65", resolution=SIZE, white_level=0.5)
    assert half.exposure_ev == pytest.approx(1.0)


# -------------------------------------------------------------------------------------------
# The files, read back by their own libraries
# -------------------------------------------------------------------------------------------

def test_glb_follows_the_gltf_encoding_rules(d65, tmp_path):
    pygltflib = pytest.importorskip("pygltflib", reason="the [scene] extra (pygltflib)")
    done = export_scene(d65, "gltf", tmp_path / "g")
    g = pygltflib.GLTF2().load(str(done.scene_file))
    mats = {m.name: m for m in g.materials}
    assert len(g.materials) == 27  # 24 patches, the frame, the edge target's field and square
    for i, name in enumerate(d65.patch_names):
        m = mats[f"patch_{i + 1:02d}_{name}"]
        # factors are linear: the albedo, not its sRGB encoding
        np.testing.assert_allclose(m.pbrMetallicRoughness.baseColorFactor[:3], d65.albedo[i],
                                   rtol=1e-6)
        assert m.pbrMetallicRoughness.baseColorTexture is None
        assert m.pbrMetallicRoughness.metallicFactor == 0
        assert m.extensions["KHR_materials_specular"]["specularFactor"] == 0
    light = g.extensions["KHR_lights_punctual"]["lights"][0]
    assert light["type"] == "directional"
    assert light["intensity"] == pytest.approx(683 * math.pi)
    assert g.cameras[0].perspective.yfov == pytest.approx(math.radians(40))
    manifest = json.loads((done.folder / "manifest.json").read_text())
    assert manifest["corners"] == d65.corners_option()
    assert "Standard" in (done.folder / "README.md").read_text()


def test_usda_is_metres_preview_surface_and_distant_light(d65, tmp_path):
    pytest.importorskip("pxr", reason="the [scene] extra (usd-core)")
    from pxr import Usd, UsdGeom, UsdLux, UsdShade

    done = export_scene(d65, "usd", tmp_path / "u")
    stage = Usd.Stage.Open(str(done.scene_file))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    prim = stage.GetPrimAtPath("/World/Looks/patch_19_white_9_5/PreviewSurface")
    shader = UsdShade.Shader(prim)
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    np.testing.assert_allclose(shader.GetInput("diffuseColor").Get(), d65.albedo[18], rtol=1e-6)
    assert shader.GetInput("ior").Get() == 1.0
    light = UsdLux.DistantLight(stage.GetPrimAtPath("/World/Sun"))
    assert light.GetIntensityAttr().Get() == pytest.approx(math.pi)
    assert light.GetNormalizeAttr().Get() is True
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera()
    assert cam.GetFieldOfView(cam.FOVVertical) == pytest.approx(40, rel=1e-5)


def test_mitsuba_xml_loads(d65, tmp_path):
    mi = pytest.importorskip("mitsuba", reason="the [render] extra (mitsuba)")
    done = export_scene(d65, "mitsuba", tmp_path / "m")
    assert done.manifest["checked_with"].startswith("mitsuba")
    mi.set_variant("scalar_spectral")
    scene = mi.load_file(str(done.scene_file))
    assert len(scene.shapes()) == 27 and len(scene.emitters()) == 1  # + the edge target


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_manifest_follows_its_schema(fmt, tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    pytest.importorskip({"gltf": "pygltflib", "usd": "pxr", "mitsuba": "json"}[fmt])
    from fidelity.core.resources import resource_dir

    schema = json.loads((resource_dir("data") / "schemas" / "scene-manifest.schema.json")
                        .read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    scene = build_scene("F11", resolution=(320, 200), white_level=0.25)
    doc = json.loads((export_scene(scene, fmt, tmp_path / fmt).folder / "manifest.json")
                     .read_text(encoding="utf-8"))
    jsonschema.validate(doc, schema)
    assert doc["expected_exposure"]["gate_exposure_ev"] == pytest.approx(2.0)
    np.testing.assert_allclose([p["expected_linear_rgb"] for p in doc["patches"]],
                               scene.albedo * 0.25)


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_manifest_and_readme_print_plain_numbers(fmt, tmp_path):
    """No numpy repr (``np.float64(0.91625)``) in the manifest's text nor the README (issue
    57: the expected exposure's ``rule``)."""
    pytest.importorskip({"gltf": "pygltflib", "usd": "pxr", "mitsuba": "json"}[fmt])
    done = export_scene(build_scene("D65", resolution=SIZE, white_level=0.25), fmt,
                        tmp_path / fmt, check=False)
    for name in ("manifest.json", "README.md"):
        text = (done.folder / name).read_text(encoding="utf-8")
        assert "np." not in text and "float64" not in text, name
    rule = json.loads((done.folder / "manifest.json").read_text())["expected_exposure"]["rule"]
    if fmt != "mitsuba":
        lands = json.loads(rule.split("lands at ")[1])
        np.testing.assert_allclose(lands, done.manifest["patches"][18]["expected_linear_rgb"],
                                   atol=1e-6)


def test_an_out_that_is_a_link_exports_into_its_folder_and_stays_a_link(tmp_path):
    """--out link (-> a folder, there or not yet): the folder it names gets the export and is
    replaced by a later one; the link is never replaced."""
    link = tmp_path / "scene"
    link.symlink_to(Path("exports") / "chart")  # dangling: exports/chart is made
    for res in ((160, 120), (200, 150)):
        done = export_scene(build_scene("D65", resolution=res), "mitsuba", link, check=False)
        assert done.folder == link and link.is_symlink()
        real = tmp_path / "exports" / "chart"
        assert json.loads((real / "manifest.json").read_text())["camera"]["width"] == res[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exports", "scene"]
    assert [p.name for p in (tmp_path / "exports").iterdir()] == ["chart"]  # no temporaries


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_export_takes_under_a_second(fmt, d65, tmp_path):
    module = {"gltf": "pygltflib", "usd": "pxr", "mitsuba": "mitsuba"}[fmt]
    pytest.importorskip(module)
    export_scene(d65, fmt, tmp_path / "warm")  # imports the writer's library once
    t0 = time.perf_counter()
    export_scene(build_scene("D65", resolution=(1920, 1080)), fmt, tmp_path / fmt)
    assert time.perf_counter() - t0 < 1.0


# -------------------------------------------------------------------------------------------
# Bad input: exit 2, one line, nothing half-written
# -------------------------------------------------------------------------------------------

def _one_line(result) -> str:
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("fidelity: error: ")
    return lines[0]


def test_unknown_format(tmp_path):
    r = CliRunner().invoke(main, ["scene", "--format", "fbx", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "fbx" in _one_line(r)
    assert not (tmp_path / "x").exists()


def test_unwritable_out_leaves_nothing(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running as a user who can write into a read-only folder")
        r = CliRunner().invoke(main, ["scene", "--format", "gltf", "--out",
                                      str(locked / "scene")])
        assert r.exit_code == 2 and str(locked / "scene") in _one_line(r)
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o700)


def test_out_under_a_file_is_refused(tmp_path):
    f = tmp_path / "a-file"
    f.write_text("keep me")
    r = CliRunner().invoke(main, ["scene", "--format", "gltf", "--out", str(f / "scene")])
    assert r.exit_code == 2 and str(f / "scene") in _one_line(r)
    assert f.read_text() == "keep me"


def test_existing_folder_kept_but_earlier_export_replaced(tmp_path):
    other = tmp_path / "photos"
    other.mkdir()
    (other / "img.png").write_bytes(b"x")
    r = CliRunner().invoke(main, ["scene", "--format", "gltf", "--out", str(other)])
    assert r.exit_code == 2 and str(other) in _one_line(r)
    assert [p.name for p in other.iterdir()] == ["img.png"]
    pytest.importorskip("pygltflib")
    out = tmp_path / "scene"
    for res in ("200x150", "320x240"):
        r = CliRunner().invoke(main, ["scene", "--format", "gltf", "--out", str(out),
                                      "--resolution", res])
        assert r.exit_code == 0, r.output
    assert json.loads((out / "manifest.json").read_text())["camera"]["width"] == 320
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos", "scene"]  # no temporaries


def test_a_failing_writer_leaves_nothing_and_keeps_the_earlier_export(d65, tmp_path,
                                                                      monkeypatch):
    import errno

    import fidelity.scene.export as export
    from fidelity.core.errors import InputFileError

    pytest.importorskip("pygltflib")
    out = tmp_path / "scene"
    export_scene(d65, "gltf", out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(export, "write_gltf", full_disk)  # the writer the export calls
    with pytest.raises(InputFileError, match="No space left"):
        export_scene(build_scene("A", resolution=SIZE), "gltf", out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene"]


@pytest.mark.parametrize("args", [["--resolution", "8x8"], ["--resolution", "wide"],
                                  ["--fill", "0"], ["--fill", "0.5", "--distance", "1"],
                                  ["--distance", "0.05"], ["--fov", "0"],
                                  ["--illuminant", "no-such-light"],
                                  ["--white-level", "nan"]])
def test_bad_settings(args, tmp_path):
    r = CliRunner().invoke(main, ["scene", "--format", "gltf", "--out", str(tmp_path / "s"),
                                  *args])
    assert r.exit_code == 2
    _one_line(r)
    assert not (tmp_path / "s").exists()


def test_texture_only_for_gltf_and_usd(tmp_path):
    """Mitsuba reads spectra: --base-colour texture is refused there, written for USD (the
    texture beside the stage, moved with the folder)."""
    r = CliRunner().invoke(main, ["scene", "--format", "mitsuba", "--base-colour", "texture",
                                  "--out", str(tmp_path / "m")])
    assert r.exit_code == 2 and "--base-colour" in _one_line(r)
    assert not (tmp_path / "m").exists()
    pytest.importorskip("pxr")
    r = CliRunner().invoke(main, ["scene", "--format", "usd", "--base-colour", "texture",
                                  "--out", str(tmp_path / "u"), "-q"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (tmp_path / "u").iterdir()) == [
        "README.md", "albedo.png", "chart.usda", "manifest.json"]
    assert "UsdUVTexture" in (tmp_path / "u" / "chart.usda").read_text()


def test_usd_without_usd_core_names_the_extra(tmp_path):
    code = ("import sys; sys.modules['pxr'] = None\n"
            "from fidelity.cli import main\n"
            f"sys.argv = ['fidelity', 'scene', '--format', 'usd', '--out', {str(tmp_path / 'u')!r}]\n"
            "main()")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), check=False)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "usd-core" in lines[0] and "[scene]" in lines[0]
    assert not (tmp_path / "u").exists()
    with pytest.raises(MissingExtraError):
        saved = sys.modules.get("pxr")
        sys.modules["pxr"] = None  # type: ignore[assignment]
        try:
            export_scene(build_scene(resolution=SIZE), "usd", tmp_path / "u2")
        finally:
            if saved is None:
                del sys.modules["pxr"]
            else:
                sys.modules["pxr"] = saved


# -------------------------------------------------------------------------------------------
# Third-party renders
# -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", ["gltf", "usd"])
def test_blender_cycles_render_passes_the_gate(fmt, d65, tmp_path):
    pytest.importorskip({"gltf": "pygltflib", "usd": "pxr"}[fmt])
    require_blender()
    done = export_scene(d65, fmt, tmp_path / fmt)
    render = render_with_blender(done.scene_file, tmp_path / f"{fmt}.exr", *SIZE, samples=4)
    assert render.info["view_transform"] == "Standard"
    code, report = gate_json(render.image, done.manifest, tmp_path)
    mean = report["mean_delta_e"] if "mean_delta_e" in report else report["chart"]["mean_delta_e"]
    assert code == 0 and mean <= BOUND_RGB
    # the floor is the clipping of the out-of-gamut cyan albedo, which the manifest states
    floor = d65.conventions["albedo_clipping_delta_e"]["mean"]
    assert mean == pytest.approx(floor, abs=0.05)
    # a second measurement, at the manifest's centres in linear values, against the albedos
    from fidelity.chart.image import read_image

    pixels = read_image(render.image).pixels
    measured = patch_linear_means(pixels, d65.patch_centres_px(), d65.patch_size_px())
    assert delta_e_linear(measured, d65.albedo).mean() < 0.05


def test_blender_render_under_illuminant_a(tmp_path):
    """The RGB materials under A are the chart's colours under A adapted to D65 (what a
    white-balanced camera sees); gated against the scene reference under A."""
    pytest.importorskip("pygltflib")
    require_blender()
    from fidelity.chart.read import ReadOptions
    from fidelity.pipeline.check import audit_image

    scene = build_scene("A", resolution=SIZE)
    done = export_scene(scene, "gltf", tmp_path / "a")
    render = render_with_blender(done.scene_file, tmp_path / "a.exr", *SIZE, samples=1)
    report = audit_image(render.image, done.manifest["corners"],
                         read=ReadOptions(exposure=0.0), illuminant="A")
    floor = scene.conventions["albedo_clipping_delta_e"]
    mean = report.measurement.mean_delta_e
    assert mean <= BOUND_RGB
    assert mean == pytest.approx(0.0 if floor is None else floor["mean"], abs=0.05)


def _audit(image: Path, manifest: dict) -> float:
    from fidelity.chart.read import ReadOptions
    from fidelity.pipeline.check import audit_image

    return float(audit_image(image, manifest["corners"], read=ReadOptions(exposure=0.0),
                             illuminant=manifest["illuminant"]).measurement.mean_delta_e)


def test_blender_decodes_the_srgb_texture(d65, tmp_path):
    """glTF textures are sRGB-encoded: Blender decodes the 8-bit texels to exactly the albedo
    the manifest gives, and the render passes the gate (the 8-bit quantisation and the cyan
    clipping are the only error). Texels holding linear values (not encoded) fail by far."""
    pytest.importorskip("pygltflib")
    require_blender()
    from fidelity.chart.image import read_image
    from fidelity.scene.gltf import write_gltf

    done = export_scene(d65, "gltf", tmp_path / "t", base_colour="texture")
    albedo = np.array([p["albedo_linear_srgb"] for p in done.manifest["patches"]])
    assert done.manifest["base_colour"] == "texture"
    render = render_with_blender(done.scene_file, tmp_path / "t.exr", *SIZE, samples=1)
    measured = patch_linear_means(read_image(render.image).pixels, d65.patch_centres_px(),
                                  d65.patch_size_px())
    assert delta_e_linear(measured, albedo).max() < 0.01
    assert _audit(render.image, done.manifest) <= BOUND_RGB
    wrong = tmp_path / "wrong.glb"
    linear_texels = np.round(np.clip(d65.albedo, 0, 1) * 255).astype(np.uint8)
    write_gltf(d65, wrong, base_colour="texture", texels=linear_texels)
    render = render_with_blender(wrong, tmp_path / "wrong.exr", *SIZE, samples=1)
    assert _audit(render.image, done.manifest) > 10 * BOUND_RGB


def test_blender_decodes_the_usd_srgb_texture(d65, tmp_path):
    """USD with --base-colour texture: a UsdUVTexture (sourceColorSpace sRGB) of albedo.png
    beside the stage; Blender's USD importer decodes the 8-bit texels to the manifest's
    albedos and the render passes the gate. Linear values in the texture fail by far."""
    pytest.importorskip("pxr")
    require_blender()
    from fidelity.chart.image import read_image
    from fidelity.scene.usd import TEXTURE_FILE, write_usd

    done = export_scene(d65, "usd", tmp_path / "u", base_colour="texture")
    assert done.manifest["base_colour"] == "texture"
    assert (tmp_path / "u" / TEXTURE_FILE).is_file()
    albedo = np.array([p["albedo_linear_srgb"] for p in done.manifest["patches"]])
    render = render_with_blender(done.scene_file, tmp_path / "u.exr", *SIZE, samples=1)
    measured = patch_linear_means(read_image(render.image).pixels, d65.patch_centres_px(),
                                  d65.patch_size_px())
    assert delta_e_linear(measured, albedo).max() < 0.01
    assert _audit(render.image, done.manifest) <= BOUND_RGB
    wrong = tmp_path / "w" / "chart.usda"
    wrong.parent.mkdir()
    linear_texels = np.round(np.clip(d65.albedo, 0, 1) * 255).astype(np.uint8)
    write_usd(d65, wrong, base_colour="texture", texels=linear_texels)
    render = render_with_blender(wrong, tmp_path / "w.exr", *SIZE, samples=1)
    assert _audit(render.image, done.manifest) > 10 * BOUND_RGB


def test_srgb_values_as_linear_factors_fail_by_far(d65, tmp_path):
    pytest.importorskip("pygltflib")
    require_blender()
    from fidelity.scene.gltf import write_gltf

    done = export_scene(d65, "gltf", tmp_path / "g")
    wrong = tmp_path / "wrong.glb"
    write_gltf(d65, wrong, linear_factors=wrongly_encoded(d65))
    render = render_with_blender(wrong, tmp_path / "wrong.exr", *SIZE, samples=4)
    code, report = gate_json(render.image, done.manifest, tmp_path)
    mean = report["mean_delta_e"] if "mean_delta_e" in report else report["chart"]["mean_delta_e"]
    assert code == 1 and mean > 10 * BOUND_RGB


@pytest.mark.parametrize("illuminant", ["D65", "A"])
def test_mitsuba_render_matches_the_closed_form(illuminant, tmp_path):
    mi = pytest.importorskip("mitsuba", reason="the [render] extra (mitsuba)")
    scene = build_scene(illuminant, resolution=SIZE)
    done = export_scene(scene, "mitsuba", tmp_path / "m")
    mi.set_variant("scalar_spectral")
    img = np.asarray(mi.render(mi.load_file(str(done.scene_file)), seed=0), dtype=np.float64)
    measured = patch_linear_means(img, scene.patch_centres_px(), scene.patch_size_px())
    de = delta_e_linear(measured, scene.spectral_linear)
    assert de.mean() <= BOUND_MITSUBA, de
    # the frame around the patches is the frame's reflectance (no light leaks onto it)
    y, x = (int(v) for v in scene.camera.project(0.0, CLASSIC.height / 2 - 0.004)[::-1])
    luminance = img[y, x] @ np.array([0.2126, 0.7152, 0.0722])
    assert luminance == pytest.approx(0.03 * scene.white_level, rel=0.05)


def test_mini_chart_is_the_classic_field_at_the_minis_size():
    """--chart mini: 82.55 x 57.15 mm outside (3.25 x 2.25 in), the Classic's patch field
    scaled to that width; the camera moves in so the chart fills the same share of the image,
    so the manifest's corners are the Classic's."""
    from fidelity.scene.model import MINI

    assert (MINI.width, MINI.height) == (pytest.approx(0.08255), pytest.approx(0.05715))
    assert MINI.patch / CLASSIC.patch == pytest.approx(82.55 / 279.4)
    assert 6 * MINI.pitch < MINI.width and 4 * MINI.pitch < MINI.height
    mini = build_scene("D65", chart="mini", resolution=SIZE)
    classic = build_scene("D65", resolution=SIZE)
    assert mini.camera.distance == pytest.approx(classic.camera.distance * 82.55 / 279.4,
                                                 rel=0.05)
    # the same 24 materials; the corners within the aspect-ratio difference of the two charts
    np.testing.assert_array_equal(mini.albedo, classic.albedo)
    assert np.abs(mini.corners_px() - classic.corners_px()).max() < 0.05 * SIZE[0]


def test_blender_renders_the_mini_chart_and_it_passes_the_gate(d65, tmp_path):
    pytest.importorskip("pygltflib")
    require_blender()
    scene = build_scene("D65", chart="mini", resolution=SIZE)
    done = export_scene(scene, "gltf", tmp_path / "mini")
    render = render_with_blender(done.scene_file, tmp_path / "mini.exr", *SIZE, samples=4)
    code, report = gate_json(render.image, done.manifest, tmp_path)
    mean = report["mean_delta_e"] if "mean_delta_e" in report else report["chart"]["mean_delta_e"]
    assert code == 0 and mean <= BOUND_RGB
