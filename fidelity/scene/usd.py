"""Write the chart scene as OpenUSD (``.usda``) with ``usd-core``'s ``pxr``.

Stage: metres (``metersPerUnit`` 1), +y up, as the scene model. One ``Mesh`` per patch and the
frame, each bound to a ``UsdPreviewSurface`` material: ``diffuseColor`` the linear albedo
(UsdPreviewSurface colours are linear), ``metallic`` 0, ``roughness`` 1 and ``ior`` 1 (a
dielectric's F0 = ((ior - 1) / (ior + 1))^2 = 0: no specular reflection, as the chart's 45/0
reference); with ``base_colour="texture"`` the patches read their colour from an 8-bit
sRGB-encoded texture instead (a ``UsdUVTexture``, ``sourceColorSpace`` ``sRGB``). Light: a ``UsdLux.DistantLight`` along -z with ``normalize`` on, so that (UsdLux)
its ``intensity`` is the illuminance it gives a surface facing it: the irradiance in renderer
units, pi * white level. (Blender's USD importer multiplies a DistantLight's intensity by 4,
"approximately matches Karma" in its source, usd_reader_light.cc: import with Light Intensity
Scale 0.25.) Camera: ``UsdGeom.Camera`` (looks along -z) with apertures
giving the model's fields of view.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fidelity.scene.gltf import texture_texels, write_texture_png
from fidelity.scene.model import EDGE_FIELD_Z, FRAME_REFLECTANCE, ChartScene

EXTRA = "scene"


#: The texture file written beside the ``.usda`` with ``base_colour="texture"``.
TEXTURE_FILE = "albedo.png"


def write_usd(scene: ChartScene, path: Path, *, linear_factors: np.ndarray | None = None,
              base_colour: str = "factor", texels: np.ndarray | None = None) -> None:
    """Write ``scene`` to ``path`` (.usda); ``linear_factors`` (24, 3) replaces the albedos.

    ``base_colour="texture"``: the patches' ``diffuseColor`` comes from one 8-bit
    sRGB-encoded texture (:data:`TEXTURE_FILE` beside the stage, one texel per patch:
    :func:`fidelity.scene.gltf.texture_texels`, or ``texels`` (24, 3) uint8) through a
    ``UsdUVTexture`` with ``sourceColorSpace`` ``sRGB`` (the UsdPreviewSurface specification's
    rule for 8-bit colour textures) and a ``UsdPrimvarReader_float2`` of the mesh's ``st``,
    every vertex at its patch's texel centre; the frame keeps its linear factor."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

    factors = scene.albedo if linear_factors is None else np.asarray(linear_factors)
    textured = base_colour == "texture"
    n_tex = len(scene.patch_names)
    if textured:
        texels = texture_texels(scene.albedo) if texels is None else texels
        write_texture_png(np.asarray(texels, np.uint8), path.parent / TEXTURE_FILE)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.Xform.Define(stage, "/World/Chart")
    UsdGeom.Scope.Define(stage, "/World/Looks")
    chart = scene.chart

    def quad(name: str, cx: float, cy: float, hw: float, hh: float, z: float,
             colour: list[float], texel: int | None = None,
             corners: np.ndarray | None = None) -> None:
        mesh = UsdGeom.Mesh.Define(stage, f"/World/Chart/{name}")
        pts = [Gf.Vec3f(cx - hw, cy - hh, z), Gf.Vec3f(cx + hw, cy - hh, z),
               Gf.Vec3f(cx + hw, cy + hh, z), Gf.Vec3f(cx - hw, cy + hh, z)]
        if corners is not None:  # top left, top right, bottom right, bottom left as seen
            pts = [Gf.Vec3f(float(x), float(y), z) for x, y in corners[[3, 2, 1, 0]]]
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            cx, cy = float(lo[0] + hi[0]) / 2, float(lo[1] + hi[1]) / 2
            hw, hh = float(hi[0] - lo[0]) / 2, float(hi[1] - lo[1]) / 2
        mesh.CreatePointsAttr(pts)
        mesh.CreateFaceVertexCountsAttr([4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        mesh.CreateNormalsAttr([Gf.Vec3f(0, 0, 1)] * 4)
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr([Gf.Vec3f(cx - hw, cy - hh, z), Gf.Vec3f(cx + hw, cy + hh, z)])
        material = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
        shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/PreviewSurface")
        shader.CreateIdAttr("UsdPreviewSurface")
        diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
        if texel is None:
            diffuse.Set(Gf.Vec3f(*colour))
        else:
            st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
            st.Set([Gf.Vec2f((texel + 0.5) / n_tex, 0.5)] * 4)
            reader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/st")
            reader.CreateIdAttr("UsdPrimvarReader_float2")
            reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
            tex = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/albedo")
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{TEXTURE_FILE}")
            tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
            tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
            tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
            tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
                reader.ConnectableAPI(), "result")
            diffuse.ConnectToSource(tex.ConnectableAPI(), "rgb")
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
        shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(1.0)
        shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)

    for i, name in enumerate(scene.patch_names):
        cx, cy = chart.patch_centre(i)
        quad(f"patch_{i + 1:02d}_{_identifier(name)}", cx, cy, chart.patch / 2, chart.patch / 2,
             0.0, [float(v) for v in factors[i]], i if textured else None)
    quad("frame", 0.0, 0.0, chart.width / 2, chart.height / 2, -0.0005, [FRAME_REFLECTANCE] * 3)
    target = scene.edge_target  # the slanted-edge target beside the chart
    quad("edge_field", 0.0, 0.0, 0.0, 0.0, EDGE_FIELD_Z, [target.light] * 3,
         corners=target.field_corners())
    quad("edge_square", 0.0, 0.0, 0.0, 0.0, 0.0, [target.dark] * 3,
         corners=target.square_corners())

    light = UsdLux.DistantLight.Define(stage, "/World/Sun")
    light.CreateIntensityAttr(float(scene.irradiance))
    light.CreateExposureAttr(0.0)
    light.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    light.CreateAngleAttr(0.0)
    light.CreateNormalizeAttr(True)

    cam = scene.camera
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    focal = 50.0
    vertical = 2 * focal * math.tan(cam.yfov / 2)
    camera.CreateFocalLengthAttr(focal)
    camera.CreateVerticalApertureAttr(vertical)
    camera.CreateHorizontalApertureAttr(vertical * cam.width / cam.height)
    camera.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.01, 100.0))
    UsdGeom.Xformable(camera).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, cam.distance))
    stage.SetMetadata("comment", "fidelity chart scene: linear sRGB albedos, see manifest.json")
    stage.GetRootLayer().Save()


def _identifier(name: str) -> str:
    out = "".join(c if c.isalnum() else "_" for c in name)
    return out if out and not out[0].isdigit() else f"_{out}"


__all__ = ["EXTRA", "TEXTURE_FILE", "write_usd"]
