"""``fidelity scene``: export the chart scene for a simulator (glTF, OpenUSD, Mitsuba 3)."""

from __future__ import annotations

import shlex
from pathlib import Path

import click

from fidelity.cli.options import Resolution, common_options
from fidelity.scene.export import BASE_COLOURS, FORMATS, MANIFEST, export_scene
from fidelity.scene.model import CHARTS, REFERENCES, build_scene


@click.command()
@click.option("--format", "fmt", type=click.Choice(list(FORMATS)), required=True,
              help="gltf: chart.glb (Unreal/CARLA, Unity, Blender, Omniverse); usd: chart.usda "
                   "(Omniverse, Isaac Sim, Blender); mitsuba: chart.xml (spectral).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Folder to write (new, empty or an earlier export, which is replaced).")
@click.option("--reference", type=click.Choice(REFERENCES), default="scene", show_default=True,
              help="scene: the chart's spectra under --illuminant, adapted to D65; safecolor: "
                   "the paper's Lab table (RGB formats only).")
@click.option("--illuminant", default="D65", show_default=True,
              help="D65, D50, A, F2, F11, LED, any colour-science illuminant name, or a CSV "
                   "SPD file.")
@click.option("--chart", type=click.Choice(CHARTS), default="classic", show_default=True,
              help="ColorChecker Classic (279.4 x 215.9 mm) or Classic Mini (82.55 x 57.15 mm): "
                   "the same 24 patches.")
@click.option("--resolution", type=Resolution(), default="640x480", show_default=True,
              help="Camera image size, WIDTHxHEIGHT pixels.")
@click.option("--fov", "yfov", type=float, default=40.0, show_default=True,
              help="Vertical field of view, degrees.")
@click.option("--fill", type=float, default=None,
              help="Share of the image the chart spans along its tighter side, width or height "
                   "(default 0.8).")
@click.option("--distance", type=float, default=None,
              help="Camera distance from the chart in metres (instead of --fill).")
@click.option("--white-level", type=float, default=1.0, show_default=True,
              help="Linear value a perfect white reflector renders at (sets the light).")
@click.option("--base-colour", type=click.Choice(BASE_COLOURS), default="factor",
              show_default=True,
              help="gltf and usd: the patches' linear colour factors, or an 8-bit "
                   "sRGB-encoded texture, one texel per patch (gltf: baseColorTexture; usd: "
                   "albedo.png through a UsdUVTexture).")
@common_options
def scene(fmt: str, out_dir: Path, reference: str, illuminant: str, chart: str,
          resolution: tuple[int, int], yfov: float, fill: float | None,
          distance: float | None, white_level: float, base_colour: str) -> None:
    """Export the chart scene for a simulator: glTF, OpenUSD or Mitsuba 3, with a manifest.

    The scene is written in the format the simulator loads, with manifest.json and README.md.

    \b
    fidelity scene --format gltf --out chart-gltf
    fidelity scene --format usd --out chart-usd --resolution 1920x1080 --fill 0.5
    fidelity scene --format mitsuba --out chart-mitsuba --illuminant A

    The manifest holds the patch references, the patch corners in the camera's image (for
    ``fidelity gate render.exr --manifest OUT/manifest.json``), the light, the expected exposure and the
    renderer settings; README.md names them for CARLA/Unreal, Omniverse and Blender.
    """
    if reference != "scene" and fmt == "mitsuba":
        raise click.UsageError("--reference safecolor has no spectra; the mitsuba format "
                               "needs --reference scene")
    model = build_scene(illuminant, reference, chart, resolution=resolution, yfov_deg=yfov,
                        fill=fill, distance=distance, white_level=white_level)
    done = export_scene(model, fmt, out_dir, base_colour=base_colour)
    click.echo(f"wrote {done.scene_file}, manifest.json, README.md ({done.seconds:.2f} s)")
    click.echo("gate the render: " + done.manifest["gate_command"].replace(
        f"--manifest {MANIFEST}", f"--manifest {shlex.quote(str(done.folder / MANIFEST))}"))
