"""Blender renders of the known mistakes, diagnosed (issue 57): the exported chart (glTF)
rendered with Blender 5.0.1's Cycles as a user gets it wrong. The view transforms AgX, Filmic,
Filmic with Medium High Contrast and Standard with Medium High Contrast (in the PNG; Blender
writes the EXR without them), every light x4 (+2 EV), a grey world background (ambient light)
and the base colours' sRGB values written as linear factors. Each is audited at the
manifest's corners with its exposure fixed (the manifest's) and the diagnosis names the cause,
with the exposure within 0.05 EV of the truth: log2 of the light's factor, 0 for the view
transforms, and for the grey world the ratio of its neutral patches to the correct render's
(measured here from the pixels, at the manifest's patch centres).

The correct renders (glTF and USD; EXR, 8-bit and 16-bit PNG) raise no alarm: no warning
line, no cause, with the chart found or at the corners. Small renders, 4 samples: about 15 s
in all. Skipped, saying why, without Blender (``.venv-blender`` with ``bpy==5.0.1``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fidelity.chart.image import read_image
from fidelity.chart.read import ReadOptions
from fidelity.pipeline.check import audit_image
from fidelity.scene.export import MissingExtraError, export_scene, wrongly_encoded
from fidelity.scene.model import build_scene
from fidelity.scene.verify import (
    patch_linear_means,
    render_with_blender,
)
from tests.fixtures.blender import require_blender
from tests.pipeline.test_no_false_alarms import audit, no_alarm

SIZE = (160, 120)
SAMPLES = 4
#: The grey world's strength (a uniform background of radiance 0.05 x white around the chart).
WORLD = 0.05
#: How close the diagnosed exposure must be to the truth.
EV_TOLERANCE = 0.05


#: name -> (scene format, image kind, render settings, wrongly encoded base colours)
RENDERS: dict[str, tuple[str, str, dict[str, object], bool]] = {
    "gltf": ("gltf", "exr", {}, False),
    "gltf-png8": ("gltf", "png", {}, False),
    "gltf-png16": ("gltf", "png", {"png_depth": 16}, False),
    "usd": ("usd", "exr", {}, False),
    "usd-png8": ("usd", "png", {}, False),
    "usd-png16": ("usd", "png", {"png_depth": 16}, False),
    "agx": ("gltf", "png", {"view": "AgX"}, False),
    "filmic": ("gltf", "png", {"view": "Filmic"}, False),
    "filmic-mhc": ("gltf", "png", {"view": "Filmic", "look": "Medium High Contrast"}, False),
    "standard-mhc": ("gltf", "png", {"look": "Medium High Contrast"}, False),
    "light-x4": ("gltf", "exr", {"light_scale": 4.0}, False),
    "grey-world": ("gltf", "exr", {"world": WORLD}, False),
    "srgb-as-linear": ("gltf", "exr", {}, True),
}


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> tuple[dict[str, Path], dict]:
    require_blender()
    pytest.importorskip("pygltflib", reason="the [scene] extra (pygltflib)")
    tmp = tmp_path_factory.mktemp("blender")
    scene = build_scene("D65", resolution=SIZE)
    exports = {"gltf": export_scene(scene, "gltf", tmp / "gltf")}
    try:
        exports["usd"] = export_scene(scene, "usd", tmp / "usd")
    except MissingExtraError as exc:
        pytest.skip(str(exc))
    from fidelity.scene.gltf import write_gltf

    wrong = tmp / "wrong.glb"
    write_gltf(scene, wrong, linear_factors=wrongly_encoded(scene))
    out: dict[str, Path] = {}
    for name, (fmt, kind, settings, wrongly) in RENDERS.items():
        source = wrong if wrongly else exports[fmt].scene_file
        png = tmp / f"{name}.png"
        done = render_with_blender(source, tmp / f"{name}.exr", *SIZE, samples=SAMPLES,
                                   png=png if kind == "png" else None, **settings)
        out[name] = png if kind == "png" else done.image
    return out, exports["gltf"].manifest


def _truth_world(renders: tuple[dict[str, Path], dict]) -> float:
    """The grey world's exposure: log2 of its neutral patches' mean luminance over the
    correct render's, at the manifest's patch centres."""
    files, manifest = renders
    scene = build_scene("D65", resolution=SIZE)
    y = np.array([0.2126, 0.7152, 0.0722])

    def neutrals(path: Path) -> np.ndarray:
        means = patch_linear_means(read_image(path).pixels, scene.patch_centres_px(),
                                   scene.patch_size_px())
        return means[18:] @ y

    return float(np.mean(np.log2(neutrals(files["grey-world"]) / neutrals(files["gltf"]))))


#: name -> (the cause's kind, its tone curve or None, the truth's exposure in EV or None: the
#: grey world's, measured)
MISTAKES: dict[str, tuple[str, str | None, float | None]] = {
    "agx": ("tone", "AgX", 0.0),
    "filmic": ("tone", "Filmic", 0.0),
    "filmic-mhc": ("tone", "Filmic, Medium High Contrast", 0.0),
    "standard-mhc": ("tone", "Standard, Medium High Contrast", 0.0),
    "light-x4": ("exposure", None, math.log2(4.0)),
    "grey-world": ("exposure", None, None),
    "srgb-as-linear": ("tone", "sRGB-encoded values used as linear", 0.0),
}


@pytest.mark.parametrize("name", sorted(MISTAKES))
def test_each_mistake_is_diagnosed(renders, name):
    files, manifest = renders
    kind, curve, ev = MISTAKES[name]
    truth = _truth_world(renders) if ev is None else ev
    report = audit_image(files[name], manifest["corners"], illuminant=manifest["illuminant"],
                         reference=manifest["reference"], read=ReadOptions(
                             exposure=manifest["expected_exposure"]["gate_exposure_ev"]))
    d = report.diagnosis
    assert d is not None and d.causes, (name, d)
    assert [c.kind for c in d.causes] == [kind], d.summary()
    cause = d.causes[0]
    if curve is not None:
        assert cause.tone_curve == curve, d.summary()
    if name in ("agx", "filmic", "filmic-mhc"):
        assert cause.text.startswith("tone mapping: highlights compressed (a view transform "
                                     "such as Filmic or AgX")
    assert d.exposure_ev == pytest.approx(truth, abs=EV_TOLERANCE), d.summary()
    if name == "grey-world":
        assert truth > 0.03  # an ambient light the gate must see: about +0.07 EV
    # the model explains the error
    assert d.residual_delta_e < 0.25 * report.mean_delta_e


@pytest.mark.parametrize("name", ["gltf", "gltf-png8", "gltf-png16", "usd", "usd-png8",
                                  "usd-png16"])
@pytest.mark.parametrize("found", [False, True], ids=["corners", "found"])
def test_correct_renders_raise_no_alarm(renders, name, found, tmp_path):
    files, manifest = renders
    args = [] if found else ["--corners", manifest["corners"], "--exposure", "0"]
    lines, doc = audit(files[name], tmp_path, *args)
    no_alarm(lines, doc)
