"""Write the chart scene as Mitsuba 3 XML (a spectral scene) and check it with Mitsuba's loader.

The file keeps what the RGB formats cannot: each patch's reflectance spectrum (``regular``
spectra, 380-780 nm in :data:`fidelity.scene.model.SPECTRAL_STEP_NM` steps) and the
illuminant's SPD on a ``directional`` emitter along -z. The SPD is scaled so that a perfect
white reflector renders at Y = white level on Mitsuba's ``hdrfilm`` in a spectral variant:
Mitsuba turns a spectrum into XYZ as ``mean(xyz(l) L(l) / p(l)) / 106.7502594`` (its
``MI_CIE_Y_NORMALIZATION``), so with L = E_s / pi for a white Lambertian patch,
E_s = E * pi * white * 106.7502594 / sum(E ybar dl). The ``hdrfilm`` writes linear sRGB
(XYZ -> Rec. 709, no chromatic adaptation): under D65 that is the chart's reference, under
another illuminant the un-white-balanced colours (``spectral_linear`` of the manifest).
Integrator ``direct`` (exact for a flat chart under one directional light), ``box`` pixel
filter, ``multijitter`` sampler. The XML is written with the standard library's ElementTree and
loaded back with ``mitsuba.load_file`` before the export counts as done.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from fidelity.colour.spectral import cie_1931_cmfs
from fidelity.scene.model import EDGE_FIELD_Z, FRAME_REFLECTANCE, ChartScene

#: Mitsuba's XYZ normalisation, 1 / MI_CIE_Y_NORMALIZATION (include/mitsuba/core/spectrum.h).
MITSUBA_CIE_Y_INTEGRAL: float = 106.7502593994140625
#: Samples per pixel written into the scene (the sampler is stratified; a flat chart under a
#: directional light is exact per wavelength, the samples only average the spectrum).
DEFAULT_SPP: int = 64
#: Variant a render needs (any spectral one: ``scalar_spectral``, ``llvm_ad_spectral``, ...).
VARIANT_KIND = "spectral"


def _spectrum(parent: ET.Element, name: str, values: np.ndarray, start: float,
              step: float) -> None:
    s = ET.SubElement(parent, "spectrum", type="regular", name=name)
    ET.SubElement(s, "float", name="wavelength_min", value=f"{start:g}")
    ET.SubElement(s, "float", name="wavelength_max", value=f"{start + step * (values.size - 1):g}")
    ET.SubElement(s, "string", name="values", value=", ".join(f"{v:.8g}" for v in values))


def _rectangle(root: ET.Element, ident: str, cx: float, cy: float, hw: float, hh: float,
               z: float, angle_deg: float = 0.0) -> ET.Element:
    shape = ET.SubElement(root, "shape", type="rectangle", id=ident)
    t = ET.SubElement(shape, "transform", name="to_world")
    ET.SubElement(t, "scale", x=f"{hw:.9g}", y=f"{hh:.9g}", z="1")
    if angle_deg:  # counter-clockwise about +z (towards the camera), as seen
        ET.SubElement(t, "rotate", z="1", angle=f"{angle_deg:.9g}")
    ET.SubElement(t, "translate", x=f"{cx:.9g}", y=f"{cy:.9g}", z=f"{z:.9g}")
    return shape


def irradiance_scale(scene: ChartScene) -> float:
    """The factor on the illuminant's relative SPD (see the module docstring)."""
    fine = np.arange(380.0, 781.0)  # the SPD as Mitsuba interpolates it, on the 1 nm CMFs
    spd = np.interp(fine, scene.wavelengths(), scene.illuminant_spd)
    norm = float(spd @ cie_1931_cmfs(1.0)[:, 1])
    return math.pi * scene.white_level * MITSUBA_CIE_Y_INTEGRAL / norm


def scene_xml(scene: ChartScene, spp: int = DEFAULT_SPP, *, rfilter: str = "box",
              stddev: float | None = None) -> ET.ElementTree:
    """The Mitsuba 3 scene document of ``scene``.

    ``rfilter`` the film's reconstruction filter (``box``, the export's; ``gaussian`` with
    Mitsuba's ``stddev`` in pixels, None: Mitsuba's default 0.5).
    """
    root = ET.Element("scene", version="3.0.0")
    ET.SubElement(root, "integrator", type="direct")
    cam = scene.camera
    sensor = ET.SubElement(root, "sensor", type="perspective", id="camera")
    ET.SubElement(sensor, "float", name="fov", value=f"{math.degrees(cam.yfov):.9g}")
    ET.SubElement(sensor, "string", name="fov_axis", value="y")
    ET.SubElement(sensor, "float", name="near_clip", value="0.01")
    ET.SubElement(sensor, "float", name="far_clip", value="100")
    t = ET.SubElement(sensor, "transform", name="to_world")
    ET.SubElement(t, "lookat", origin=f"0, 0, {cam.distance:.9g}", target="0, 0, 0", up="0, 1, 0")
    sampler = ET.SubElement(sensor, "sampler", type="multijitter")
    ET.SubElement(sampler, "integer", name="sample_count", value=str(int(spp)))
    film = ET.SubElement(sensor, "film", type="hdrfilm")
    ET.SubElement(film, "integer", name="width", value=str(cam.width))
    ET.SubElement(film, "integer", name="height", value=str(cam.height))
    ET.SubElement(film, "string", name="pixel_format", value="rgb")
    ET.SubElement(film, "string", name="component_format", value="float32")
    rf = ET.SubElement(film, "rfilter", type=rfilter)
    if stddev is not None:
        ET.SubElement(rf, "float", name="stddev", value=f"{stddev:.9g}")
    emitter = ET.SubElement(root, "emitter", type="directional", id="sun")
    ET.SubElement(emitter, "vector", name="direction", x="0", y="0", z="-1")
    start = float(scene.wavelengths()[0])
    _spectrum(emitter, "irradiance", scene.illuminant_spd * irradiance_scale(scene), start,
              scene.step)
    chart = scene.chart
    for i in range(len(scene.patch_names)):
        cx, cy = chart.patch_centre(i)
        shape = _rectangle(root, f"patch_{i + 1:02d}", cx, cy, chart.patch / 2, chart.patch / 2,
                           0.0)
        bsdf = ET.SubElement(shape, "bsdf", type="diffuse")
        _spectrum(bsdf, "reflectance", scene.reflectance[i], start, scene.step)
    frame = _rectangle(root, "frame", 0.0, 0.0, chart.width / 2, chart.height / 2, -0.0005)
    bsdf = ET.SubElement(frame, "bsdf", type="diffuse")
    ET.SubElement(bsdf, "float", name="reflectance", value=f"{FRAME_REFLECTANCE:g}")
    target = scene.edge_target  # the slanted-edge target beside the chart
    for ident, side, z, angle, refl in (
            ("edge_field", target.field, EDGE_FIELD_Z, 0.0, target.light),
            ("edge_square", target.square, 0.0, target.angle_deg, target.dark)):
        shape = _rectangle(root, ident, target.centre[0], target.centre[1], side / 2, side / 2,
                           z, angle)
        bsdf = ET.SubElement(shape, "bsdf", type="diffuse")
        ET.SubElement(bsdf, "float", name="reflectance", value=f"{refl:g}")
    ET.indent(root)
    return ET.ElementTree(root)


def write_mitsuba(scene: ChartScene, path: Path, spp: int = DEFAULT_SPP) -> None:
    """Write the XML to ``path``."""
    scene_xml(scene, spp).write(path, encoding="utf-8", xml_declaration=True)


def check_loads(path: Path, variant: str = "scalar_spectral") -> None:
    """Load ``path`` with ``mitsuba.load_file`` (raises on a scene Mitsuba rejects)."""
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant(variant)
    mi.load_file(str(path))


__all__ = ["DEFAULT_SPP", "MITSUBA_CIE_Y_INTEGRAL", "check_loads", "irradiance_scale",
           "scene_xml", "write_mitsuba"]
