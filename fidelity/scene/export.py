"""Export the chart scene to a folder: the scene file, ``manifest.json`` and ``README.md``.

Formats (:data:`FORMATS`): ``gltf`` (``chart.glb``, :mod:`fidelity.scene.gltf`), ``usd``
(``chart.usda``, :mod:`fidelity.scene.usd`), ``mitsuba`` (``chart.xml``,
:mod:`fidelity.scene.mitsuba`). The folder is written as a whole: into a temporary folder beside
the destination, renamed into place when every file is written (and the Mitsuba XML loaded back
by Mitsuba when it is installed), so an error leaves nothing half-written. An existing
destination is replaced only when it is empty or an earlier export (it has this module's
``manifest.json``); a destination that is a symbolic link replaces the folder it leads to (the
link is kept).
"""

from __future__ import annotations

import errno
import importlib
import importlib.util
import json
import math
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.core.errors import FidelityError, InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import WRITE_ERRNOS, display_path, json_ready, write_error
from fidelity.core.record import record
from fidelity.scene.gltf import texture_albedo, write_gltf
from fidelity.scene.manifest import MANIFEST_KIND
from fidelity.scene.mitsuba import DEFAULT_SPP, check_loads, irradiance_scale, write_mitsuba
from fidelity.scene.model import EDGE_FIELD_Z, LUMENS_PER_WATT, ChartScene
from fidelity.scene.usd import write_usd
from fidelity.scene.verify import delta_e_linear

#: glTF base colour encodings (:data:`fidelity.scene.gltf.BASE_COLOURS`, without importing it).
BASE_COLOURS: tuple[str, ...] = ("factor", "texture")

#: format -> (scene file name, Python module it needs, extra that provides it)
FORMATS: dict[str, tuple[str, str, str]] = {
    "gltf": ("chart.glb", "pygltflib", "scene"),
    "usd": ("chart.usda", "pxr", "scene"),
    "mitsuba": ("chart.xml", "", ""),
}
#: ``kind`` of the manifest (:data:`fidelity.scene.manifest.MANIFEST_KIND`) marks a folder as an
#: export that may be replaced.
MANIFEST = "manifest.json"
#: Version of the manifest's layout (``fidelity/data/schemas/scene-manifest.schema.json``).
MANIFEST_SCHEMA_VERSION = "1.0"
README = "README.md"


class MissingExtraError(FidelityError):
    """The format's writer needs an optional package that is not installed."""


@record
class Export:
    """What :func:`export_scene` wrote: the ``folder``, the ``scene_file`` in it, the manifest
    (as written) and the seconds the export took."""

    folder: Path
    scene_file: Path
    manifest: dict[str, Any]
    seconds: float


#: Settings every renderer must use to produce a measurable image.
RENDERER_SETTINGS: dict[str, str] = {
    "view_transform": "none / Standard (no Filmic, AgX, ACES or other tone mapping; look None, "
                      "exposure 0, gamma 1)",
    "auto_exposure": "off (fixed exposure, see expected_exposure)",
    "bloom": "off", "vignetting": "off", "lens_flare": "off", "chromatic_aberration": "off",
    "motion_blur": "off", "depth_of_field": "off", "film_grain": "off",
    "sky_and_ambient_light": "off (the scene's one light only; black background/world)",
    "output": "linear float (EXR), Rec. 709 / sRGB primaries, before any display transform",
    "denoiser": "off or any; the chart is flat, few samples suffice",
}


def _check_format(fmt: str) -> tuple[str, str, str]:
    if fmt not in FORMATS:
        raise unknown_name("scene format", fmt, FORMATS)
    name, module, extra = FORMATS[fmt]
    if module and not _importable(module):
        package = {"pxr": "usd-core"}.get(module, module)
        raise MissingExtraError(f"--format {fmt}: needs {package}; install the [{extra}] extra "
                                f"(pip install 'camera-fidelity[{extra}]')")
    return name, module, extra


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def _patches(scene: ChartScene) -> list[dict[str, Any]]:
    centres = scene.patch_centres_px()
    return [{"index": i + 1, "name": name,
             "reference_lab": scene.reference_lab[i].tolist(),
             "reference_linear_srgb": scene.reference_linear[i].tolist(),
             "reference_srgb": scene.reference_srgb[i].tolist(),
             "albedo_linear_srgb": scene.albedo[i].tolist(),
             "albedo_clipped": bool(scene.clipped[i]),
             "expected_linear_rgb": (scene.albedo[i] * scene.white_level).tolist(),
             "spectral_linear_srgb": scene.spectral_linear[i].tolist(),
             "centre_px": centres[i].tolist()}
            for i, name in enumerate(scene.patch_names)]


def edge_target_json(scene: ChartScene) -> dict[str, Any]:
    """The manifest's ``edge_target``: the slanted-edge target's corners in the camera's image,
    its reflectances, contrast, turn and size (:class:`fidelity.scene.model.EdgeTarget`)."""
    t = scene.edge_target
    return {
        "standard": "ISO 12233:2017 e-SFR slanted edges: a dark square on a light field",
        **scene.edge_target_px(),
        "corners_note": ("square_corners_px: the dark square's corners, top left, top right, "
                         "bottom right, bottom left as seen (before its turn); "
                         "field_corners_px: the light field's, same order; pixel (row i, "
                         "column j) at x=j, y=i; fidelity gate/audit --manifest measures the "
                         "e-SFR of the square's edges there"),
        "reflectance": {"square": t.dark, "field": t.light,
                        "note": "spectrally flat (RGB formats: grey linear albedo)"},
        "luminance_ratio": t.luminance_ratio,
        "angle_deg": t.angle_deg,
        "angle_note": "the square turned counter-clockwise as seen: its edges run this far "
                      "off the image axes",
        "square_mm": t.square * 1e3, "field_mm": t.field * 1e3,
        "centre_m": [t.centre[0], t.centre[1], 0.0], "field_z_m": EDGE_FIELD_Z,
    }


def manifest(scene: ChartScene, fmt: str, scene_file: str) -> dict[str, Any]:
    """The manifest of an export (JSON-ready)."""
    rgb = fmt != "mitsuba"
    corners = scene.corners_option()
    ev = scene.exposure_ev + 0.0 if scene.white_level != 1 else 0.0
    gate = f"fidelity gate render.exr --manifest {MANIFEST} --max-delta-e 0.5"
    if rgb:
        light = {"type": "directional", "direction": [0.0, 0.0, -1.0], "colour": [1.0, 1.0, 1.0],
                 "irradiance": scene.irradiance,
                 "irradiance_unit": "renderer units (Blender W/m^2): pi x white_level",
                 "illuminance_lux": scene.illuminance_lux,
                 "lux_convention": "683 lm/W (glTF importers' photometric conversion)"}
        expected = ("pixel = albedo x white_level: the white patch lands at "
                    f"{[round(float(v * scene.white_level), 6) for v in scene.albedo[18]]}")
    else:
        light = {"type": "directional", "direction": [0.0, 0.0, -1.0],
                 "spectrum": f"{scene.illuminant} relative SPD x {irradiance_scale(scene):.6g}",
                 "note": "a perfect white reflector renders at Y = white_level"}
        expected = ("pixel = the closed form's linear sRGB of the spectral scene "
                    "(spectral_linear_srgb, not white balanced; equal to the reference under "
                    "D65)")
        doc_note = ("the hdrfilm is not white balanced: under an illuminant other than D65 "
                    "white-balance the render before gating, or compare with "
                    "spectral_linear_srgb")
    doc: dict[str, Any] = {
        "schema_version": MANIFEST_SCHEMA_VERSION,
        "kind": MANIFEST_KIND,
        "format": fmt,
        "scene_file": scene_file,
        "chart": scene.chart.to_json(),
        "illuminant": scene.illuminant,
        "reference": scene.reference,
        "white_level": scene.white_level,
        "units": "metres, +y up, chart in z = 0 facing +z, centred on the origin",
        "camera": scene.camera.to_json(),
        "light": light,
        "corners": corners,
        "corners_note": ("centres (x, y) of the dark skin, bluish green, black and white "
                         "patches in the camera's image; pixel (row i, column j) is at x=j, y=i"),
        "patch_size_px": scene.patch_size_px(),
        "edge_target": edge_target_json(scene),
        "expected_exposure": {"gate_exposure_ev": ev, "white_level": scene.white_level,
                              "rule": expected,
                              "white_luminance_cd_m2": LUMENS_PER_WATT * scene.white_level,
                              "ev100_for_unit_scale": math.log2(LUMENS_PER_WATT / 1.2),
                              "photometric": "a white Lambertian surface has 683 x white_level "
                                             "cd/m^2 under the light (683 lm/W); exposure "
                                             "1 / (1.2 x 2^EV100) (Unreal manual exposure) "
                                             "maps it to white_level at EV100 = log2(683/1.2)"},
        "renderer_settings": RENDERER_SETTINGS,
        "gate_command": gate,
        "patches": _patches(scene),
        "conventions": scene.conventions,
    }
    if not rgb:
        doc["gate_note"] = doc_note
        doc["mitsuba"] = {"variant": "any spectral variant (scalar_spectral, llvm_ad_spectral)",
                          "spp": DEFAULT_SPP, "integrator": "direct", "film": "hdrfilm rgb"}
    return doc


_README_COMMON = """
## Render settings (every renderer)

The chart is measured, not looked at: the image must be the renderer's linear scene values.

- Tone mapping / view transform off (Blender: View Transform *Standard*, Look *None*, Exposure
  0, Gamma 1; never Filmic or AgX for PNG or JPEG output: Blender writes an OpenEXR file
  without its view transform, so only its PNG and JPEG files are tone-mapped). Auto-exposure,
  bloom, vignetting, lens flare, chromatic aberration, motion blur, depth of field, film
  grain: off.
- No sky, environment or ambient light: only the scene's light (black world/background).
- Fixed exposure such that a pixel value equals albedo x white level ({white}): the white patch
  lands at {white_rgb}.
- Output a linear float EXR with Rec. 709/sRGB primaries at {width} x {height} pixels.

Then gate it (the corners are those of this camera's image; nothing has to find the chart):

    {gate}

## CARLA / Unreal Engine

Post Process Volume (unbound) or the camera's post-process settings: Metering Mode *Manual*,
a fixed exposure of EV100 = log2(683 / 1.2) = 9.15 (Unreal's manual exposure scales luminance by
1 / (1.2 x 2^EV100); a white Lambertian surface under this light has 683 x white level cd/m^2,
the glTF light being {lux:.6g} lux), Exposure Compensation 0; Bloom 0, Vignette 0, Lens Flares
0, Chromatic Aberration 0, Film Grain 0, Motion Blur 0; no tone curve (capture *SceneColor
(HDR)* with a SceneCapture2D; a CARLA `sensor.camera.rgb` is tone-mapped 8-bit output: set
`enable_postprocess_effects` False and gamma 1, or capture the HDR scene colour). Disable the
sky light and sky atmosphere. Import the .glb with lights and cameras; if the importer drops
`KHR_materials_specular`, set each material's Specular to 0.

## NVIDIA Omniverse RTX (Isaac Sim)

RTX - Real-Time or Path Traced; UsdLux units (1 nit renders at 1.0 at exposure 0, so the
white patch lands at its albedo x white level with no exposure change); Post Processing:
Tonemapping operator *Linear* (or off), cm2 factor 1, white scale 1, Auto Exposure off, Bloom off, Lens Flare off, Chromatic
Aberration off, Motion Blur off, Film Grain off; remove the default dome/sky light and
lighting rig (Stage *Lights*: only this scene's light). Write the *HdrColor* AOV (linear EXR).

## Blender / BlenderProc

Render engine Cycles; Color Management: Display sRGB, View Transform *Standard*, Look *None*,
Exposure 0, Gamma 1; World colour black, strength 0; Output OpenEXR 32-bit float. glTF:
import with *Lighting Mode: Standard* (physical, 683 lm/W; the default). USD: import with
*Light Intensity Scale* 0.25 (Blender's USD importer multiplies a DistantLight's intensity by
4; UsdLux makes a normalized DistantLight's intensity its illuminance). BlenderProc:
`bproc.renderer.set_output_format("OPEN_EXR")`, `bproc.world.set_world_background([0, 0, 0])`,
and `bpy.context.scene.view_settings.view_transform = "Standard"`.
The project's own proof renders this file headless in Cycles: `scenes/blender_render.py`.
"""

_README_BY_FORMAT = {
    "gltf": """# Chart scene: glTF 2.0 binary (`chart.glb`)

The X-Rite ColorChecker Classic at its physical size (279.4 x 215.9 mm; 24 patches and a black
frame) and, beside it, an ISO 12233 slanted-edge target (a 0.2 grey square turned 5 degrees on
a 0.8 grey field; `edge_target` in manifest.json), metres, +y up, lit by one `KHR_lights_punctual` directional light of {lux:.6g} lux
along -z (every patch gets the same irradiance), seen by the `camera` node ({width} x {height},
vertical field of view {yfov:.4g} degrees, {distance:.4g} m from the chart).

Encoding (glTF 2.0 specification): each patch's `baseColorFactor` is its **linear** sRGB albedo
(no texture; glTF textures would be sRGB-encoded, factors never are). `metallicFactor` 0,
`roughnessFactor` 1, `KHR_materials_specular` `specularFactor` 0 (no specular reflection: the
reference is a 45/0 measurement). An importer that ignores `KHR_materials_specular` adds a
dielectric specular of about 4 % (F0 = 0.04): set the material's specular to 0 by hand.
Base colour here: **{base_colour}** (`fidelity scene --base-colour texture` writes one 8-bit
sRGB-encoded texel per patch instead, factor 1, nearest filtering: an importer must decode it
as sRGB, and the manifest's albedos are the decoded 8-bit values).
""",
    "usd": """# Chart scene: OpenUSD (`chart.usda`)

The X-Rite ColorChecker Classic at its physical size (279.4 x 215.9 mm; 24 patches and a black
frame) and, beside it, an ISO 12233 slanted-edge target (a 0.2 grey square turned 5 degrees on
a 0.8 grey field; `edge_target` in manifest.json), metres (`metersPerUnit` 1), +y up, one `UsdPreviewSurface` per patch (`diffuseColor`
the **linear** sRGB albedo, metallic 0, roughness 1, ior 1: no specular reflection), a
`DistantLight` (`/World/Sun`) of intensity {irradiance:.6g} along -z (every patch gets the same
irradiance), and `/World/Camera` ({width} x {height}, vertical field of view {yfov:.4g} degrees,
{distance:.4g} m from the chart).
Base colour here: **{base_colour}** (`fidelity scene --format usd --base-colour texture`
writes instead `albedo.png` beside the stage, one 8-bit sRGB-encoded texel per patch, read by a
`UsdUVTexture` with `sourceColorSpace` sRGB at each patch's texel centre: an importer must
decode it as sRGB, and the manifest's albedos are the decoded 8-bit values).
""",
    "mitsuba": """# Chart scene: Mitsuba 3 (`chart.xml`)

The spectral scene: each patch's measured reflectance spectrum (`regular`, 380-780 nm) on a
`diffuse` BSDF, the slanted-edge target beside the chart (a 0.2 square turned 5 degrees on a
0.8 field, flat spectra; `edge_target` in manifest.json), the {illuminant} SPD on a `directional` emitter along -z, a `perspective`
sensor ({width} x {height}, vertical field of view {yfov:.4g} degrees) with an `hdrfilm` (linear
sRGB, float32) and a `box` filter, the `direct` integrator. Render with any spectral variant:

    python -c "import mitsuba as mi; mi.set_variant('scalar_spectral'); \\
        mi.util.write_bitmap('render.exr', mi.render(mi.load_file('chart.xml')))"

The film gives XYZ -> linear sRGB without white balance: under D65 that is the reference;
under another illuminant compare with `spectral_linear_srgb` in manifest.json (the closed form
of the same spectra) or white-balance before gating.
""",
}


def readme(scene: ChartScene, fmt: str, doc: dict[str, Any]) -> str:
    """The README.md of an export."""
    cam = scene.camera
    values = {"lux": scene.illuminance_lux, "irradiance": scene.irradiance, "width": cam.width,
              "height": cam.height, "yfov": math.degrees(cam.yfov), "distance": cam.distance,
              "illuminant": scene.illuminant, "white": f"{scene.white_level:g}",
              "white_rgb": ", ".join(f"{v * scene.white_level:.4f}" for v in scene.albedo[18]),
              "gate": doc["gate_command"], "base_colour": doc.get("base_colour", "factor")}
    return (_README_BY_FORMAT[fmt] + _README_COMMON).format(**values)


def _writer(fmt: str, base_colour: str = "factor") -> Callable[[ChartScene, Path], None]:
    if fmt == "gltf":
        return lambda scene, path: write_gltf(scene, path, base_colour=base_colour)
    if fmt == "usd":
        return lambda scene, path: write_usd(scene, path, base_colour=base_colour)

    return write_mitsuba


def _replaceable(out: Path) -> bool:
    """True when ``out`` does not exist, is an empty folder or holds an earlier export."""
    if not out.exists() and not out.is_symlink():
        return True
    if not out.is_dir() or out.is_symlink():
        return False
    entries = list(out.iterdir())
    if not entries:
        return True
    try:
        doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("kind") == MANIFEST_KIND


def export_scene(scene: ChartScene, fmt: str, out: str | os.PathLike[str], *,
                 check: bool = True, base_colour: str = "factor") -> Export:
    """Write ``scene`` in ``fmt`` to the folder ``out`` (see the module docstring).

    ``check`` loads the Mitsuba XML back with ``mitsuba.load_file`` when Mitsuba is installed.
    ``base_colour`` (glTF and USD): ``factor`` (linear factors) or ``texture`` (an 8-bit
    sRGB-encoded texture; the manifest's albedos are then the quantised ones it decodes to).
    Raises :class:`~fidelity.core.errors.UnknownNameError` (format), :class:`MissingExtraError`,
    :class:`~fidelity.core.errors.InputFileError` (a destination that cannot be written or holds
    something else).
    """
    t0 = time.perf_counter()
    name, _, _ = _check_format(fmt)
    if base_colour not in BASE_COLOURS:
        raise unknown_name("base colour", base_colour, BASE_COLOURS)
    if base_colour != "factor":
        if fmt not in ("gltf", "usd"):
            raise InvalidValueError(f"--base-colour {base_colour}: the gltf and usd formats "
                                    "have textures (Mitsuba reads spectra); give --base-colour "
                                    "factor")

        quantised = texture_albedo(scene.albedo)
        scene = replace(scene, albedo=quantised, conventions={
            **scene.conventions,
            "rgb_materials": (
                "8-bit sRGB-encoded baseColorTexture (one texel per patch, nearest filtering), "
                "factor 1; albedo = the decoded 8-bit texel" if fmt == "gltf" else
                "8-bit sRGB-encoded UsdUVTexture albedo.png (sourceColorSpace sRGB, one texel "
                "per patch, st at the texel centre) as diffuseColor; albedo = the decoded "
                "8-bit texel"),
            "albedo_quantisation_delta_e_max": float(_max_de(quantised, scene.albedo))})
    given = Path(out)
    where = display_path(given)
    target = Path(os.path.realpath(given))  # a link to a folder: the folder it names is replaced
    if not _replaceable(target):
        raise InputFileError(f"{where}: --out exists and is not an earlier scene export (no "
                             f"{MANIFEST} of fidelity scene); give a new or empty folder")
    tmp: Path | None = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp",
                                    dir=target.parent))
        scene_path = tmp / name
        _writer(fmt, base_colour)(scene, scene_path)
        if fmt == "mitsuba" and check and importlib.util.find_spec("mitsuba") is not None:
            check_loads(scene_path)
        doc = manifest(scene, fmt, name)
        doc["base_colour"] = base_colour if fmt in ("gltf", "usd") else "factor"
        doc["checked_with"] = _checked_with(fmt, check)
        (tmp / MANIFEST).write_text(json.dumps(json_ready(doc), indent=1) + "\n",
                                    encoding="utf-8")
        (tmp / README).write_text(readme(scene, fmt, doc), encoding="utf-8")
        os.chmod(tmp, 0o777 & ~_umask())
        old: Path | None = None
        if target.exists():
            old = target.with_name(f".{target.name}.{os.getpid()}.old")
            os.replace(target, old)
        os.replace(tmp, target)
        tmp = None
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except OSError as exc:
        if exc.errno in WRITE_ERRNOS or exc.errno in (errno.ENOENT, errno.EEXIST):
            raise write_error(given, exc) from None
        raise
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return Export(given, given / name, doc, time.perf_counter() - t0)


def _checked_with(fmt: str, check: bool) -> str | None:
    if fmt == "mitsuba":
        if not check or importlib.util.find_spec("mitsuba") is None:
            return None
        import mitsuba as mi

        return f"mitsuba {mi.__version__} load_file ({mi.variant()})"
    if fmt == "usd":
        from pxr import Usd

        return f"usd-core {'.'.join(map(str, Usd.GetVersion()))}"
    import pygltflib

    return f"pygltflib {getattr(pygltflib, '__version__', '')}".strip()


def _max_de(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(delta_e_linear(a, b)))


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def wrongly_encoded(scene: ChartScene) -> np.ndarray:
    """The albedos a common mistake writes: the sRGB-*encoded* values used as linear factors
    (tests export them to show the round trip catches it)."""
    return np.clip(scene.reference_srgb, 0.0, 1.0)


__all__ = ["BASE_COLOURS", "FORMATS", "MANIFEST", "MANIFEST_KIND", "MANIFEST_SCHEMA_VERSION", "README", "RENDERER_SETTINGS", "Export",
           "MissingExtraError", "edge_target_json", "export_scene", "manifest", "readme", "wrongly_encoded"]
