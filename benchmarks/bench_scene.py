"""Export the chart scene in every format, render it with third-party renderers, measure it.

    PYTHONPATH=. python3 benchmarks/bench_scene.py [--out reports/scene] [--size 640x480]

1. Export time as whole processes (``python -m fidelity scene --format F``: wall time and max
   RSS, best of ``--repeats``), beside the anchor ``python -m fidelity --help`` (the CLI's start)
   in the same run, as ratios; and the ``export_scene`` call alone, in one process.
2. Renders: Blender Cycles (``scenes/blender_render.py``, the bpy wheel in its own
   environment) of the .glb and the .usda, and of a .glb written with the sRGB-encoded values
   as linear factors (the common mistake); Mitsuba 3 (``scalar_spectral``) of the XML under
   D65 and A. Render seconds of each.
3. Measurements: ``fidelity.check.audit_image`` (the library under ``fidelity gate``) with the
   manifest's corners and exposure against the reference (RGB renders); the linear patch means
   at the manifest's centres against the albedos (RGB) or the closed form of the same spectra
   (Mitsuba), ΔE00.
4. A PNG of each render (encoded sRGB, clipped) and results.json + README.md in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.machine import machine_info  # noqa: E402
from fidelity.chart.image import read_image, write_png  # noqa: E402
from fidelity.chart.measure import ReadOptions  # noqa: E402
from fidelity.check import audit_image  # noqa: E402
from fidelity.colour.colorimetry import delinearize_srgb  # noqa: E402
from fidelity.scene.export import export_scene, wrongly_encoded  # noqa: E402
from fidelity.scene.gltf import write_gltf  # noqa: E402
from fidelity.scene.model import ChartScene, build_scene  # noqa: E402
from fidelity.scene.verify import (  # noqa: E402
    delta_e_linear,
    patch_linear_means,
    render_with_blender,
)


def process(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and max RSS (MiB) of one child process."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    wall = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(rss, before) / 1024


def export_times(tmp: Path, repeats: int) -> dict[str, Any]:
    anchor = min(process([sys.executable, "-m", "fidelity", "--help"])[0]
                 for _ in range(repeats))
    out: dict[str, Any] = {"anchor": "python -m fidelity --help", "anchor_seconds": anchor}
    for fmt in ("gltf", "usd", "mitsuba"):
        runs = [process([sys.executable, "-m", "fidelity", "scene", "--format", fmt, "--out",
                         str(tmp / f"proc-{fmt}")]) for _ in range(repeats)]
        wall = min(r[0] for r in runs)
        scene = build_scene("D65")
        export_scene(scene, fmt, tmp / f"warm-{fmt}")
        t0 = time.perf_counter()
        export_scene(scene, fmt, tmp / f"call-{fmt}")
        out[fmt] = {"process_seconds": wall, "process_max_rss_mib": max(r[1] for r in runs),
                    "ratio_to_anchor": wall / anchor,
                    "export_call_seconds": time.perf_counter() - t0}
    return out


def png_of(linear: np.ndarray, path: Path) -> None:
    write_png(path, np.clip(delinearize_srgb(np.clip(linear, 0, None)), 0, 1), 8)


def measure_rgb(scene: ChartScene, exr: Path, manifest: dict[str, Any]) -> dict[str, Any]:
    report = audit_image(exr, manifest["corners"], read=ReadOptions(exposure=0.0),
                         illuminant=scene.illuminant)
    m = report.measurement
    pixels = read_image(exr).pixels
    lin = patch_linear_means(pixels, scene.patch_centres_px(), scene.patch_size_px())
    de = delta_e_linear(lin, scene.albedo)
    return {"gate_mean_delta_e": float(m.mean_delta_e), "gate_max_delta_e": float(m.max_delta_e),
            "gate_worst_patch": m.worst_patch,
            "linear_vs_albedo_mean_delta_e": float(de.mean()),
            "linear_vs_albedo_max_delta_e": float(de.max()),
            "white_patch_linear": lin[18].tolist()}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(ROOT / "reports" / "scene"))
    p.add_argument("--size", default="640x480")
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    width, height = (int(v) for v in a.size.lower().split("x"))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"machine": machine_info(), "size": [width, height]}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        results["export"] = export_times(tmp, a.repeats)
        scene = build_scene("D65", resolution=(width, height))
        floor = scene.conventions["albedo_clipping_delta_e"]
        results["albedo_clipping_delta_e"] = floor
        renders: dict[str, Any] = {}
        for fmt in ("gltf", "usd"):
            done = export_scene(scene, fmt, tmp / fmt)
            exr = tmp / f"blender-{fmt}.exr"
            r = render_with_blender(done.scene_file, exr, width, height, samples=a.samples)
            png_of(read_image(exr).pixels, out / f"blender-{fmt}.png")
            renders[f"blender-{fmt}"] = {"renderer": f"Blender {r.info['blender']} Cycles CPU",
                                         "samples": a.samples,
                                         "render_seconds": r.info["seconds_render"],
                                         "process_seconds": r.seconds,
                                         **measure_rgb(scene, exr, done.manifest)}
        wrong = tmp / "wrong.glb"
        write_gltf(scene, wrong, linear_factors=wrongly_encoded(scene))
        exr = tmp / "blender-wrong.exr"
        r = render_with_blender(wrong, exr, width, height, samples=a.samples)
        png_of(read_image(exr).pixels, out / "blender-gltf-srgb-as-linear.png")
        renders["blender-gltf-srgb-as-linear"] = {
            "renderer": f"Blender {r.info['blender']} Cycles CPU", "samples": a.samples,
            "render_seconds": r.info["seconds_render"], "process_seconds": r.seconds,
            **measure_rgb(scene, exr, export_scene(scene, "gltf", tmp / "g2").manifest)}
        import mitsuba as mi

        mi.set_variant("scalar_spectral")
        for ill in ("D65", "A"):
            sc = build_scene(ill, resolution=(width, height))
            done = export_scene(sc, "mitsuba", tmp / f"mitsuba-{ill}")
            t0 = time.perf_counter()
            img = np.asarray(mi.render(mi.load_file(str(done.scene_file)), seed=0, spp=a.spp),
                             np.float64)
            seconds = time.perf_counter() - t0
            png_of(img, out / f"mitsuba-{ill}.png")
            lin = patch_linear_means(img, sc.patch_centres_px(), sc.patch_size_px())
            de = delta_e_linear(lin, sc.spectral_linear)
            renders[f"mitsuba-{ill}"] = {
                "renderer": f"Mitsuba {mi.__version__} scalar_spectral", "spp": a.spp,
                "render_seconds": seconds,
                "closed_form_mean_delta_e": float(de.mean()),
                "closed_form_max_delta_e": float(de.max())}
        results["renders"] = renders
    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
