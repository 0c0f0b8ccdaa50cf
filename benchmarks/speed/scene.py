"""Export the chart scene in every format, as whole processes against the command line's start,
render it with third-party renderers, measure it.

1. Export time as whole processes (``python -m fidelity scene --format F``: wall time and max
   RSS, best of ``repeats``), beside the anchor ``python -m fidelity --help`` (the CLI's start)
   in the same run, as ratios; and the ``export_scene`` call alone, in one process.
2. Renders: Blender Cycles (``scenes/blender_render.py``, the bpy wheel in its own
   environment) of the .glb and the .usda, and of a .glb written with the sRGB-encoded values
   as linear factors (the common mistake); Mitsuba 3 (``scalar_spectral``) of the XML under
   D65 and A. Render seconds of each.
3. Measurements: ``fidelity.pipeline.check.audit_image`` (the library under ``fidelity gate``) with the
   manifest's corners and exposure against the reference (RGB renders); the linear patch means
   at the manifest's centres against the albedos (RGB) or the closed form of the same spectra
   (Mitsuba), ΔE00.
4. A PNG of each render (encoded sRGB, clipped) and README.md in reports/scene.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import REPO as ROOT
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from fidelity.chart.image import read_image, write_png
from fidelity.chart.read import ReadOptions
from fidelity.colour.colorimetry import delinearize_srgb
from fidelity.pipeline.check import audit_image
from fidelity.scene.export import export_scene, wrongly_encoded
from fidelity.scene.gltf import write_gltf
from fidelity.scene.model import ChartScene, build_scene
from fidelity.scene.verify import delta_e_linear, patch_linear_means, render_with_blender

ANCHOR = "python -m fidelity --help (the command line's start), whole processes in the same run"
PARAMETERS = {"size": Parameter("640x480", "render size"),
              "samples": Parameter(16, "Blender Cycles samples"),
              "spp": Parameter(64, "Mitsuba samples per pixel"),
              "repeats": Parameter(3, "best of N export processes")}
QUICK = {"size": "160x120", "samples": 4, "spp": 4, "repeats": 1}
NEEDS = ("blender", "mitsuba")
ARTEFACTS = "reports/scene"


def process(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and max RSS (MiB, the process's own: :func:`run_process`) of one child
    process; it must exit 0."""
    from benchmarks.speed.timing import run_process

    row = run_process(cmd, env=dict(os.environ, PYTHONPATH=str(ROOT)), digits=4)
    if row["exit"] != 0:
        raise RuntimeError(f"{cmd}: exit {row['exit']}: {row['stderr']}")
    return float(row["seconds"]), row["max_rss_mb"] * 1e6 / 2**20


def export_times(tmp: Path, repeats: int) -> dict[str, Any]:
    anchors = [process([sys.executable, "-m", "fidelity", "--help"]) for _ in range(repeats)]
    anchor = min(r[0] for r in anchors)
    out: dict[str, Any] = {"anchor": "python -m fidelity --help", "anchor_seconds": anchor,
                           "anchor_max_rss_mib": max(r[1] for r in anchors),
                           "rss_of": "each process's own (os.wait4), the largest of the runs"}
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


def readme(r: dict[str, Any]) -> str:
    """reports/scene/README.md from the results."""
    e, rd, m = r["export"], r["renders"], r["machine"]
    w, h = r["size"]
    floor = r["albedo_clipping_delta_e"]
    lines = [
        "# Chart scene exports rendered by third-party renderers (issue 28)", "",
        f"Generated by `python -m benchmarks.speed scene` on {r['date']}; "
        f"machine: {m['cpu']}, {m['cores']} cores, load average at start "
        f"{', '.join(f'{v:.2f}' for v in r['load_average'])} (shared with other jobs).", "",
        "## Export time", "",
        f"Whole processes `python -m fidelity scene --format F --out DIR` (best of "
        f"{r['repeats']}), beside the anchor `{e['anchor']}` ({e['anchor_seconds']:.2f} s) "
        "in the same run; and the `export_scene` call alone (640 x 480) in a warm process.", "",
        "| format | process s | x anchor | max RSS MiB | export call s |", "|---|---|---|---|---|"]
    for fmt in ("gltf", "usd", "mitsuba"):
        x = e[fmt]
        lines.append(f"| {fmt} | {x['process_seconds']:.2f} | {x['ratio_to_anchor']:.1f} | "
                     f"{x['process_max_rss_mib']:.0f} | {x['export_call_seconds']:.3f} |")
    lines += [
        "", "The Mitsuba process includes importing Mitsuba (about 0.5 s) to load the XML back "
        "with `mitsuba.load_file`; the USD one importing `pxr`.", "",
        f"## Renders ({w} x {h})", "",
        "RGB renders: Blender Cycles (CPU, View Transform Standard, box filter) of the exported "
        "file, measured with `fidelity.pipeline.check.audit_image` (the library under `fidelity gate`) at "
        "the manifest's corners with exposure 0, against the scene reference (BabelColor under "
        "D65); and the linear patch means at the manifest's centres against the albedos. The "
        f"floor is the clipping of the out-of-gamut cyan albedo: mean {floor['mean']:.4f}, "
        f"cyan {floor['max']:.2f} ΔE00.", "",
        "| render | renderer | render s | gate mean ΔE00 | gate max ΔE00 | linear vs albedo "
        "mean ΔE00 |", "|---|---|---|---|---|---|"]
    for name in ("blender-gltf", "blender-usd", "blender-gltf-texture",
                 "blender-gltf-srgb-as-linear"):
        x = rd[name]
        lines.append(f"| {name} | {x['renderer']}, {x['samples']} samples | "
                     f"{x['render_seconds']:.1f} | {x['gate_mean_delta_e']:.4f} | "
                     f"{x['gate_max_delta_e']:.2f} ({x['gate_worst_patch']}) | "
                     f"{x['linear_vs_albedo_mean_delta_e']:.2g} |")
    lines += [
        "", "`blender-gltf-texture` is `--base-colour texture` (8-bit sRGB-encoded texels; its "
        "linear column is against the decoded 8-bit albedos of its manifest). "
        "`blender-gltf-srgb-as-linear` is the common mistake (the sRGB-encoded values "
        "written as linear `baseColorFactor`s): it fails the 0.5 gate by a factor of "
        f"{rd['blender-gltf-srgb-as-linear']['gate_mean_delta_e'] / 0.5:.0f}.",
        "", "Mitsuba 3 renders the spectral XML; its linear patch means at the manifest's "
        "centres are compared with the closed form of the same spectra (1 nm integral of the "
        "5 nm spectra the XML holds, CIE 1931 2 degree, linear sRGB, no white balance):", "",
        "| render | renderer | render s | mean ΔE00 vs closed form | max |", "|---|---|---|---|---|"]
    for name in ("mitsuba-D65", "mitsuba-A"):
        x = rd[name]
        lines.append(f"| {name} | {x['renderer']}, {x['spp']} spp | {x['render_seconds']:.1f} | "
                     f"{x['closed_form_mean_delta_e']:.4f} | {x['closed_form_max_delta_e']:.4f} |")
    lines += ["", "## Pictures (encoded sRGB, clipped)", ""]
    for name in ("blender-gltf", "blender-usd", "blender-gltf-texture",
                 "blender-gltf-srgb-as-linear", "mitsuba-D65", "mitsuba-A"):
        lines += [f"**{name}**", "", f"![{name}]({name}.png)", ""]
    lines += ["Raw numbers: `reports/benchmarks/scene.json`.", ""]
    return "\n".join(lines)


def measure(ctx: Context) -> dict[str, Any]:
    from types import SimpleNamespace

    a = SimpleNamespace(**ctx.params)
    width, height = (int(v) for v in a.size.lower().split("x"))
    out = ctx.artefacts
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"size": [width, height], "repeats": a.repeats,
                               "load_average": list(os.getloadavg())}
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
        done = export_scene(scene, "gltf", tmp / "tex", base_colour="texture")
        exr = tmp / "blender-gltf-texture.exr"
        r = render_with_blender(done.scene_file, exr, width, height, samples=a.samples)
        png_of(read_image(exr).pixels, out / "blender-gltf-texture.png")
        tex_scene = replace(scene, albedo=np.array([p["albedo_linear_srgb"]
                                                    for p in done.manifest["patches"]]))
        renders["blender-gltf-texture"] = {"renderer": f"Blender {r.info['blender']} Cycles CPU",
                                           "samples": a.samples,
                                           "render_seconds": r.info["seconds_render"],
                                           "process_seconds": r.seconds,
                                           **measure_rgb(tex_scene, exr, done.manifest)}
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
    return results


def cases(details: dict[str, Any]) -> list[Case]:
    e = details["export"]
    own = "rss_of" in e  # earlier runs recorded the largest RSS of any child so far: left out
    mib = 2**20 / 1e6
    anchor = figures(e["anchor"], e["anchor_seconds"],
                     max_rss_mb=e["anchor_max_rss_mib"] * mib if own else None)
    return [case(f"python -m fidelity scene --format {fmt}",
                 figures(f"fidelity scene --format {fmt}", e[fmt]["process_seconds"],
                         max_rss_mb=e[fmt]["process_max_rss_mib"] * mib if own else None),
                 anchor, per="process", statistic=f"best of {details['repeats']}",
                 process=True,
                 note=f"the export_scene call alone {e[fmt]['export_call_seconds']:.3f} s")
            for fmt in ("gltf", "usd", "mitsuba")]


def report(result: dict[str, Any], folder: Path) -> None:
    """README.md from the result (the PNGs are written by the run)."""
    doc = {**result["details"], "machine": result["machine"], "date": result["date"]}
    (folder / "README.md").write_text(readme(doc), encoding="utf-8")
