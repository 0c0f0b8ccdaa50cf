"""Write the chart scene as glTF 2.0 binary (``.glb``) with ``pygltflib``.

glTF's encoding rules (glTF 2.0 specification, 3.9.2 "Metallic-Roughness Material"):
``baseColorFactor`` is *linear*; only a ``baseColorTexture`` is sRGB-encoded. So every patch
gets its linear albedo as a factor and no texture. ``metallicFactor`` 0 and
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

from fidelity.scene.model import FRAME_REFLECTANCE, ChartScene

#: The extra that provides this writer.
EXTRA = "scene"

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT = 5126
_UNSIGNED_SHORT = 5123


def _quad(cx: float, cy: float, hw: float, hh: float, z: float) -> np.ndarray:
    return np.array([[cx - hw, cy - hh, z], [cx + hw, cy - hh, z], [cx + hw, cy + hh, z],
                     [cx - hw, cy + hh, z]], dtype=np.float32)


def write_gltf(scene: ChartScene, path: Path, *, linear_factors: np.ndarray | None = None) -> None:
    """Write ``scene`` to ``path`` (.glb). ``linear_factors`` (24, 3) replaces the patches'
    base colour factors (tests use it to write a wrongly encoded chart)."""
    import pygltflib as g

    factors = scene.albedo if linear_factors is None else np.asarray(linear_factors)
    chart = scene.chart
    quads: list[tuple[str, np.ndarray, list[float]]] = []
    for i, name in enumerate(scene.patch_names):
        cx, cy = chart.patch_centre(i)
        quads.append((f"patch_{i + 1:02d}_{name}", _quad(cx, cy, chart.patch / 2, chart.patch / 2,
                                                         0.0), [float(v) for v in factors[i]]))
    quads.append(("frame", _quad(0.0, 0.0, chart.width / 2, chart.height / 2, -0.0005),
                  [FRAME_REFLECTANCE] * 3))

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
    for k, (name, pos, colour) in enumerate(quads):
        data = pos.tobytes()
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data),
                                  target=_ARRAY_BUFFER))
        blob += data
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=_FLOAT, count=4,
                                    type=g.VEC3, min=pos.min(0).tolist(), max=pos.max(0).tolist()))
        materials.append(g.Material(
            name=name,
            pbrMetallicRoughness=g.PbrMetallicRoughness(baseColorFactor=[*colour, 1.0],
                                                        metallicFactor=0.0, roughnessFactor=1.0),
            extensions={"KHR_materials_specular": {"specularFactor": 0.0}},
        ))
        meshes.append(g.Mesh(name=name, primitives=[g.Primitive(
            attributes=g.Attributes(POSITION=len(accessors) - 1, NORMAL=1), indices=0,
            material=k)]))
        nodes.append(g.Node(name=name, mesh=k))
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
        accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
        extensionsUsed=["KHR_lights_punctual", "KHR_materials_specular"],
        extensions={"KHR_lights_punctual": {"lights": [{
            "name": "sun", "type": "directional", "color": [1.0, 1.0, 1.0],
            "intensity": scene.illuminance_lux}]}},
    )
    gltf.set_binary_blob(bytes(blob))
    gltf.save_binary(str(path))


__all__ = ["EXTRA", "write_gltf"]
