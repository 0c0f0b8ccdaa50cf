"""Render an exported chart scene (``chart.glb`` or ``chart.usda``) with Blender Cycles, headless.

Run with a Python that has the ``bpy`` wheel (it needs numpy < 2, so it lives in its own
environment, not fidelity's), or with Blender itself::

    python blender_render.py chart.glb render.exr --width 640 --height 480 --samples 4
    blender -b --factory-startup --python blender_render.py -- chart.glb render.exr

It imports the file with Blender's own importers (glTF: Lighting Mode *Standard*, the
physical 683 lm/W conversion; USD: Blender's USD importer with Light Intensity Scale 0.25,
which undoes the factor 4 it puts on a DistantLight's intensity), makes the world black, sets Cycles
on the CPU, View Transform *Standard* (no Filmic/AgX), Look None, Exposure 0, Gamma 1, a box
pixel filter of one pixel, and writes a 32-bit float OpenEXR of the scene's linear values.
Prints one JSON line: the render seconds, the Blender version and the settings used.
Nothing here imports fidelity.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

#: Blender's USD import multiplies a DistantLight's intensity by 4; this undoes it.
USD_SUN_SCALE = 0.25


def main(argv: list[str]) -> int:
    import bpy

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("output")
    p.add_argument("--width", type=int, required=True)
    p.add_argument("--height", type=int, required=True)
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--png", default=None, help="also save the view-transformed image as PNG")
    a = p.parse_args(argv)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    t0 = time.perf_counter()
    if a.scene.lower().endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=a.scene,
                                  export_import_convert_lighting_mode="SPEC")
    elif a.scene.lower().endswith((".usd", ".usda", ".usdc", ".usdz")):
        # Blender's USD importer sets a sun's strength to 4 x the DistantLight's intensity
        # (usd_reader_light.cc: "approximately matches Karma"); UsdLux defines a normalized
        # DistantLight's intensity as the illuminance, so scale it back.
        bpy.ops.wm.usd_import(filepath=a.scene, light_intensity_scale=USD_SUN_SCALE)
    else:
        print(f"blender_render: {a.scene}: not a .glb/.gltf/.usd* file", file=sys.stderr)
        return 2
    seconds_import = time.perf_counter() - t0
    scene = bpy.context.scene
    cameras = [o for o in scene.objects if o.type == "CAMERA"]
    if len(cameras) != 1:
        print(f"blender_render: {a.scene}: expected one camera, found {len(cameras)}",
              file=sys.stderr)
        return 2
    scene.camera = cameras[0]
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = a.samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.cycles.seed = 0
    if a.threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = a.threads
    scene.render.resolution_x = a.width
    scene.render.resolution_y = a.height
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.render.film_transparent = False
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGB"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    scene.render.filepath = a.output
    t1 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds_render = time.perf_counter() - t1
    if a.png:
        png = bpy.data.images["Render Result"]
        settings.file_format = "PNG"
        settings.color_depth = "8"
        png.save_render(a.png, scene=scene)
    lights = [{"type": o.data.type, "energy": o.data.energy} for o in scene.objects
              if o.type == "LIGHT"]
    print(json.dumps({"blender": bpy.app.version_string, "seconds_import": seconds_import,
                      "seconds_render": seconds_render, "samples": a.samples,
                      "view_transform": scene.view_settings.view_transform,
                      "lights": lights, "camera_sensor_fit": scene.camera.data.sensor_fit,
                      "camera_angle_y": scene.camera.data.angle_y}))
    return 0


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(args))
