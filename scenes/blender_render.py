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

The settings users get wrong can be set on purpose, to render the known mistakes: ``--view
AgX --look "AgX - Medium High Contrast"`` (the view transform and look of the ``--png``;
Blender writes the EXR without them), ``--light-scale 4`` (every light's strength x4: +2 EV),
``--world 0.05`` (a grey world background of that strength instead of black: ambient light)
and ``--png-depth 16``.
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
    p.add_argument("--png-depth", choices=("8", "16"), default="8", help="bits of the PNG")
    p.add_argument("--view", default="Standard", help="view transform (Standard, AgX, Filmic)")
    p.add_argument("--look", default="None", help="look of the view transform")
    p.add_argument("--light-scale", type=float, default=1.0,
                   help="multiply every light's strength (4: +2 EV)")
    p.add_argument("--filter", default="BOX", choices=("BOX", "GAUSSIAN", "BLACKMAN_HARRIS"),
                   help="Cycles' pixel filter (default BOX, width 1: the pixel's area)")
    p.add_argument("--filter-width", type=float, default=1.0, help="its width, pixels")
    p.add_argument("--border", default=None,
                   help="X0,Y0,X1,Y1: render only these pixels (top left origin, X1/Y1 "
                        "exclusive), the output cropped to them")
    p.add_argument("--world", type=float, default=0.0,
                   help="strength of a grey (1, 1, 1) world background (0: black)")
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
    grey = (1.0, 1.0, 1.0, 1.0) if a.world > 0 else (0.0, 0.0, 0.0, 1.0)
    world.node_tree.nodes["Background"].inputs["Color"].default_value = grey
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = a.world
    scene.world = world
    for light in (o for o in scene.objects if o.type == "LIGHT"):
        light.data.energy *= a.light_scale

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = a.samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.pixel_filter_type = a.filter
    scene.cycles.filter_width = a.filter_width
    scene.cycles.seed = 0
    if a.threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = a.threads
    scene.render.resolution_x = a.width
    scene.render.resolution_y = a.height
    scene.render.resolution_percentage = 100
    if a.border:
        x0, y0, x1, y1 = (int(v) for v in a.border.split(","))
        scene.render.use_border = True
        scene.render.use_crop_to_border = True
        # Blender's border: fractions of the image, y from the bottom
        scene.render.border_min_x = x0 / a.width
        scene.render.border_max_x = x1 / a.width
        scene.render.border_min_y = 1.0 - y1 / a.height
        scene.render.border_max_y = 1.0 - y0 / a.height
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.render.film_transparent = False
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = a.view
    scene.view_settings.look = a.look
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
        settings.color_depth = a.png_depth
        png.save_render(a.png, scene=scene)
    lights = [{"type": o.data.type, "energy": o.data.energy} for o in scene.objects
              if o.type == "LIGHT"]
    print(json.dumps({"blender": bpy.app.version_string, "seconds_import": seconds_import,
                      "seconds_render": seconds_render, "samples": a.samples,
                      "view_transform": scene.view_settings.view_transform,
                      "look": scene.view_settings.look, "world": a.world,
                      "pixel_filter_type": scene.cycles.pixel_filter_type,
                      "filter_width": scene.cycles.filter_width, "border": a.border,
                      "light_scale": a.light_scale,
                      "lights": lights, "camera_sensor_fit": scene.camera.data.sensor_fit,
                      "camera_angle_y": scene.camera.data.angle_y}))
    return 0


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(args))
