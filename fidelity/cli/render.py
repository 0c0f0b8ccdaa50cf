"""``fidelity render``: render the spectral chart through a camera model and measure ΔE00."""

from __future__ import annotations

from pathlib import Path

import click

from fidelity.camera.model import DEFAULT_CAMERA, available_cameras, load_camera
from fidelity.camera.render import REFERENCES, RENDERERS, ChartRender, render_chart
from fidelity.chart.image import write_exr, write_png
from fidelity.cli.context import write_json_output
from fidelity.cli.options import common_options, json_option
from fidelity.colour.colorimetry import CHROMATIC_ADAPTATION_METHODS
from fidelity.colour.spectral import GRID_STEP_NM, SPECTRA_SETS
from fidelity.core.fileio import check_outputs, display_path


def format_report(r: ChartRender) -> str:
    """Human-readable per-patch table and summary."""
    m = r.measurement
    lines = [
        f"{'#':>2} {'patch':<14} {'camera RGB':^26} {'sRGB':^20} {'Lab':^20} {'ref Lab':^20} {'ΔE00':>6}"
    ]
    for i, name in enumerate(m.patch_names):
        cam = " ".join(f"{v:8.4f}" for v in r.camera_rgb[i])
        srgb = " ".join(f"{v:6.3f}" for v in m.srgb[i])
        lab = " ".join(f"{v:6.1f}" for v in m.lab[i])
        ref = " ".join(f"{v:6.1f}" for v in m.reference_lab[i])
        lines.append(f"{i + 1:>2} {name:<14} {cam} {srgb} {lab} {ref} {m.delta_e[i]:6.2f}")
    variant = f" ({r.variant}, spp {r.settings.get('spp')})" if r.variant else ""
    lines.append(
        f"camera {r.camera.name}, illuminant {r.settings['illuminant']}, reference "
        f"{r.settings['reference']}, renderer {r.renderer}{variant}: mean ΔE00 "
        f"{m.mean_delta_e:.3f}, max {m.max_delta_e:.3f} ({m.worst_patch}), {r.seconds:.2f} s"
    )
    return "\n".join(lines)


#: What ``render --out`` writes: the raw camera RGB and the developed image.
RAW_FILE = "raw_camera.exr"
DEVELOPED_FILE = "developed.png"


@click.command()
@click.option("--camera", default=DEFAULT_CAMERA, show_default=True,
              help="Built-in camera name (see --list-cameras) or a TOML/YAML camera file.")
@click.option("--illuminant", default="D65", show_default=True,
              help="D65, D50, A, F2, F11, LED (CIE LED-B4), any colour-science illuminant "
                   "name, or a CSV SPD file (wavelength nm, power).")
@click.option("--renderer", type=click.Choice(RENDERERS), default="closed-form",
              show_default=True)
@click.option("--spp", type=click.IntRange(min=1), default=None,
              help="Mitsuba samples per pixel (default: the benchmarked default).")
@click.option("--pixels-per-patch", type=click.IntRange(min=2), default=None,
              help="Patch side in pixels (default: 32, Mitsuba's benchmarked default).")
@click.option("--reference", type=click.Choice(REFERENCES), default="scene", show_default=True,
              help="scene: the chart's colours under this illuminant, adapted to D65; "
                   "safecolor: the SAFE-COLOR Lab table (not scene-consistent).")
@click.option("--spectra", type=click.Choice(sorted(SPECTRA_SETS)), default="BabelColor Average",
              show_default=True, help="Patch reflectance set.")
@click.option("--cat", type=click.Choice(CHROMATIC_ADAPTATION_METHODS), default="Bradford",
              show_default=True, help="Chromatic adaptation of the scene reference to D65.")
@click.option("--step", type=float, default=GRID_STEP_NM, show_default=True,
              help="Spectral grid step in nm (380-780 nm).")
@click.option("--seed", type=int, default=None, help="Noise/sampler seed (default: camera's).")
@click.option("--variant", default=None, help="Force a Mitsuba variant (default: probed).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for raw_camera.exr (raw camera RGB before white balance and colour "
                   "correction, float32: not an image to audit) and developed.png (the developed "
                   "sRGB image: audit this one to check the render).")
@json_option("Write the full result as JSON")
@click.option("--list-cameras", is_flag=True, help="List the built-in cameras and exit.")
@common_options
def render(camera: str, illuminant: str, renderer: str, spp: int | None,
           pixels_per_patch: int | None, reference: str, spectra: str, cat: str, step: float,
           seed: int | None, variant: str | None, out_dir: Path | None, json_path: str | None,
           list_cameras: bool) -> None:
    """Render the spectral Macbeth chart through a camera model and measure ΔE00 per patch.

    The closed form (default) integrates reflectance x illuminant x sensitivity per patch;
    --renderer mitsuba renders the same scene with Mitsuba 3 (llvm_ad_spectral when libLLVM >= 16
    is found, else scalar_spectral). Both go through the camera's ISP and are measured against
    the scene-consistent reference (or --reference safecolor).
    """
    if list_cameras:
        for name in available_cameras():
            click.echo(f"{name:<18} {load_camera(name).description}")
        return

    files = {} if out_dir is None else {f"--out ({name})": out_dir / name for name in
                                        (RAW_FILE, DEVELOPED_FILE)}

    model = load_camera(camera)  # parsed once, passed down
    check_outputs({**files, "--json": json_path},
                  {"--camera": camera, "--illuminant": illuminant}
                  | {f"--camera ({f.name})": f for f in model.files})
    result = render_chart(model, illuminant, renderer, spp=spp, reference=reference,
                          spectra=spectra, seed=seed, pixels_per_patch=pixels_per_patch,
                          cat=cat, step=step, variant=variant)
    report = result.to_json()
    if out_dir is not None:
        exr = write_exr(out_dir / RAW_FILE, result.linear_image)
        bits = result.camera.quantisation_bits or 16
        png = write_png(out_dir / DEVELOPED_FILE, result.display_image, bits)
        report["files"] = {"raw_exr": str(exr), "developed_png": str(png)}
    if json_path is not None:
        write_json_output(json_path, report)
    click.echo(format_report(result))
    if out_dir is not None:
        click.echo(f"wrote {display_path(png)} (the developed sRGB image: audit this one)")
        click.echo(f"wrote {display_path(exr)} (raw camera RGB before white balance and colour "
                   "correction)")
