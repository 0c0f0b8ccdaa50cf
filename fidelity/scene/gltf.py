"""Write the chart scene as glTF 2.0 binary (``.glb``) with ``pygltflib``.

glTF's encoding rules (glTF 2.0 specification, 3.9.2 "Metallic-Roughness Material"):
``baseColorFactor`` is *linear*; a ``baseColorTexture`` is sRGB-encoded. By default every patch
gets its linear albedo as a factor and no texture; ``base_colour="texture"`` writes instead one
8-bit PNG texel per patch, sRGB-encoded, with factor 1 (the albedo a renderer decodes is then
the 8-bit quantised one, :func:`texture_albedo`, which the manifest gives). ``metallicFactor`` 0 and
``roughnessFactor`` 1 make a dielectric, and ``KHR_materials_specular`` with
``specularFactor`` 0 removes the dielectric's specular reflection (F0 = 0.04 by default, which
would add about 0.01 to every patch, several ΔE00 on the dark ones): the chart's reference is a
45/0 (specular-excluded) measurement. The light is ``KHR_lights_punctual`` ``directional``
(points along the node's -z) in lux; the camera a ``perspective`` one (looks along -z).
glTF is +y up, metres, as the scene model.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fidelity.chart.image import write_png
from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.scene.model import EDGE_FIELD_Z, FRAME_REFLECTANCE, ChartScene

#: The extra that provides this writer.
EXTRA = "scene"
#: How the patches' base colour is written: ``factor`` (linear ``baseColorFactor``) or
#: ``texture`` (an 8-bit sRGB-encoded ``baseColorTexture``, one texel per patch).
BASE_COLOURS: tuple[str, ...] = ("factor", "texture")
_NEAREST = 9728
_CLAMP = 33071

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT = 5126
_UNSIGNED_SHORT = 5123


def _quad(cx: float, cy: float, hw: float, hh: float, z: float) -> np.ndarray:
    return np.array([[cx - hw, cy - hh, z], [cx + hw, cy - hh, z], [cx + hw, cy + hh, z],
                     [cx - hw, cy + hh, z]], dtype=np.float32)


def _polygon(corners: np.ndarray, z: float) -> np.ndarray:
    """The quad of world (x, y) ``corners`` (top left, top right, bottom right, bottom left as
    seen) at depth ``z``, in :func:`_quad`'s vertex order (counter-clockwise from +z)."""
    c = np.asarray(corners, np.float64)[[3, 2, 1, 0]]
    return np.column_stack([c, np.full(4, z)]).astype(np.float32)


def edge_target_quads(scene: ChartScene) -> list[tuple[str, np.ndarray, list[float]]]:
    """The edge target's light field and dark square as (name, (4, 3) vertices, grey
    linear factor) quads (:class:`fidelity.scene.model.EdgeTarget`)."""
    t = scene.edge_target
    return [("edge_field", _polygon(t.field_corners(), EDGE_FIELD_Z), [t.light] * 3),
            ("edge_square", _polygon(t.square_corners(), 0.0), [t.dark] * 3)]


def texture_texels(albedo: np.ndarray) -> np.ndarray:
    """The 8-bit sRGB-encoded texels (n, 3) of linear ``albedo`` (n, 3) in [0, 1]."""
    return np.asarray(np.round(np.clip(delinearize_srgb(albedo), 0, 1) * 255), dtype=np.uint8)


def texture_albedo(albedo: np.ndarray) -> np.ndarray:
    """The linear albedo a renderer decodes from :func:`texture_texels` (8-bit quantised)."""
    return np.asarray(linearize_srgb(texture_texels(albedo) / 255.0), dtype=np.float64)


def write_texture_png(texels: np.ndarray, path: Path) -> None:
    """The texels (n, 3) uint8 as a one-row 8-bit PNG of n pixels (texel k: patch k)."""
    write_png(path, texels[None, :, :] / 255.0, 8)


def _png_bytes(texels: np.ndarray, folder: Path) -> bytes:
    png = folder / ".albedo.png"
    write_texture_png(texels, png)
    data = png.read_bytes()
    png.unlink()
    return data


def write_gltf(scene: ChartScene, path: Path, *, linear_factors: np.ndarray | None = None,
               base_colour: str = "factor", texels: np.ndarray | None = None) -> None:
    """Write ``scene`` to ``path`` (.glb). ``base_colour`` in :data:`BASE_COLOURS`.
    ``linear_factors`` (24, 3) replaces the factors, ``texels`` (24, 3) uint8 the texture
    (tests use them to write wrongly encoded charts)."""
    import pygltflib as g

    factors = scene.albedo if linear_factors is None else np.asarray(linear_factors)
    textured = base_colour == "texture"
    if textured:
        texels = texture_texels(scene.albedo) if texels is None else texels
        factors = np.ones_like(scene.albedo)
    chart = scene.chart
    quads: list[tuple[str, np.ndarray, list[float]]] = []
    for i, name in enumerate(scene.patch_names):
        cx, cy = chart.patch_centre(i)
        quads.append((f"patch_{i + 1:02d}_{name}", _quad(cx, cy, chart.patch / 2, chart.patch / 2,
                                                         0.0), [float(v) for v in factors[i]]))
    quads.append(("frame", _quad(0.0, 0.0, chart.width / 2, chart.height / 2, -0.0005),
                  [FRAME_REFLECTANCE] * 3))
    quads += edge_target_quads(scene)

    indices = np.array([0, 1, 2, 0, 2, 3], dtype=np.uint16).tobytes()
    normals = np.tile(np.array([0, 0, 1], np.float32), (4, 1)).tobytes()
    blob = bytearray(indices + normals)  # shared by every quad (both multiples of 4 bytes)
    views: list[Any] = [g.BufferView(buffer=0, byteOffset=0, byteLength=len(indices),
                                     target=_ELEMENT_ARRAY_BUFFER),
                        g.BufferView(buffer=0, byteOffset=len(indices), byteLength=len(normals),
                                     target=_ARRAY_BUFFER)]
    accessors: list[Any] = [
        g.Accessor(bufferView=0, componentType=_UNSIGNED_SHORT, count=6, type=g.SCALAR,
                   min=[0], max=[3]),
        g.Accessor(bufferView=1, componentType=_FLOAT, count=4, type=g.VEC3),
    ]
    meshes, materials, nodes = [], [], []
    n_tex = len(scene.patch_names)
    for k, (name, pos, colour) in enumerate(quads):
        data = pos.tobytes()
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data),
                                  target=_ARRAY_BUFFER))
        blob += data
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=_FLOAT, count=4,
                                    type=g.VEC3, min=pos.min(0).tolist(), max=pos.max(0).tolist()))
        attributes = g.Attributes(POSITION=len(accessors) - 1, NORMAL=1)
        texture = None
        if textured and k < n_tex:
            # every vertex at the patch's texel centre: the whole quad samples that texel
            uv = np.tile(np.array([(k + 0.5) / n_tex, 0.5], np.float32), (4, 1)).tobytes()
            views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(uv),
                                      target=_ARRAY_BUFFER))
            blob += uv
            accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=_FLOAT,
                                        count=4, type=g.VEC2))
            attributes.TEXCOORD_0 = len(accessors) - 1
            texture = g.TextureInfo(index=0)
        materials.append(g.Material(
            name=name,
            pbrMetallicRoughness=g.PbrMetallicRoughness(baseColorFactor=[*colour, 1.0],
                                                        baseColorTexture=texture,
                                                        metallicFactor=0.0, roughnessFactor=1.0),
            extensions={"KHR_materials_specular": {"specularFactor": 0.0}},
        ))
        meshes.append(g.Mesh(name=name, primitives=[g.Primitive(
            attributes=attributes, indices=0, material=k)]))
        nodes.append(g.Node(name=name, mesh=k))
    images, textures, samplers = [], [], []
    if textured:
        assert texels is not None
        png = _png_bytes(np.asarray(texels, np.uint8), path.parent)
        pad = (-len(blob)) % 4
        blob += b"\0" * pad
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(png)))
        blob += png
        images.append(g.Image(name="albedo (sRGB-encoded, one texel per patch)",
                              bufferView=len(views) - 1, mimeType="image/png"))
        samplers.append(g.Sampler(magFilter=_NEAREST, minFilter=_NEAREST, wrapS=_CLAMP,
                                  wrapT=_CLAMP))
        textures.append(g.Texture(sampler=0, source=0))
    cam = scene.camera
    cameras = [g.Camera(name="camera", type="perspective", perspective=g.Perspective(
        yfov=cam.yfov, aspectRatio=cam.width / cam.height, znear=0.01, zfar=100.0))]
    nodes.append(g.Node(name="camera", camera=0, translation=[0.0, 0.0, cam.distance]))
    nodes.append(g.Node(name="sun", translation=[0.0, 0.0, 1.0],
                        extensions={"KHR_lights_punctual": {"light": 0}}))
    gltf = g.GLTF2(
        asset=g.Asset(version="2.0", generator="fidelity scene"),
        scene=0,
        scenes=[g.Scene(name="chart", nodes=list(range(len(nodes))))],
        nodes=nodes, meshes=meshes, materials=materials, cameras=cameras,
        images=images, textures=textures, samplers=samplers,
        accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
        extensionsUsed=["KHR_lights_punctual", "KHR_materials_specular"],
        extensions={"KHR_lights_punctual": {"lights": [{
            "name": "sun", "type": "directional", "color": [1.0, 1.0, 1.0],
            "intensity": scene.illuminance_lux}]}},
    )
    blob += b"\0" * ((-len(blob)) % 4)
    gltf.buffers[0].byteLength = len(blob)
    gltf.set_binary_blob(bytes(blob))
    gltf.save_binary(str(path))


__all__ = ["BASE_COLOURS", "EXTRA", "texture_albedo", "texture_texels", "write_gltf",
           "write_texture_png"]
