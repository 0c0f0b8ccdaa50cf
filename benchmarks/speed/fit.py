"""``fidelity fit``: how fast a fit is against its anchors, which objective generalises better,
and how exact the .cube is.

1. **Objective** (issue 29, requirement 6): for pairs of the suite's cameras (``cameras/``,
   closed-form renders under D65: the "simulated" camera's chart fitted onto the "real"
   camera's), the mean leave-3-patches-out cross-validated ΔE00 of every model, fitted in
   linear RGB (``linear``) and by CIEDE2000 (``ciede2000``); the lower mean is the default
   (:data:`fidelity.correction.models.DEFAULT_OBJECTIVE`).
2. **The cube** (requirement 3): the suite's exact camera with a known error (a 20 degree hue
   rotation, white-balance gains, a gamma 2.2 encoding read as sRGB), rendered in closed form,
   as a 16-bit PNG (sRGB-encoded SIM) and a float EXR (scene-linear SIM), fitted with each
   model that expresses it: the cube sizes tried and, for each, the largest and 99th-percentile
   ΔE00 between the .cube through OpenColorIO and the model over the chart and a 41^3 lattice.
3. **Speed** (requirement 5): two 12 MP chart images (4000 x 3000, 8-bit PNG, corners given).
   In process, :func:`fidelity.pipeline.fit.fit_and_verify`'s own timers (wall and CPU): reading,
   fitting (fit and cross-validation) and verifying (baking the .cube, checking it through
   OpenColorIO over the chart and 68921 lattice points, the config, the SIM's patch windows
   through the cube by OpenColorIO and their measurement), side by side with the anchor, the
   same verification with the whole 12 MP SIM image through OpenColorIO and written
   (``corrected=True``, the path before the windows-only verification). As whole processes
   (wall, CPU, max RSS): ``python -m fidelity fit`` of this checkout and of ``source`` (the
   anchor: another checkout). Best of ``repeats``; the ratios are to the anchors.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import REPO as ROOT
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import RESULTS, Context, Parameter

ANCHOR = ("the verification with the whole 12 MP SIM image through OpenColorIO (the path before "
          "the windows-only verification); fidelity fit of another checkout, whole processes")
PARAMETERS = {"repeats": Parameter(3, "best of N"),
              "source": Parameter(None, "the anchor checkout of the whole-process runs"),
              "skip_objective": Parameter(False, "keep the objective study of the last result")}
QUICK = {"repeats": 1, "skip_objective": True}
NEEDS = ("opencolorio",)
#: (simulated camera, real camera) pairs of the suite.
PAIRS: tuple[tuple[str, str], ...] = (
    ("ideal-srgb8", "nikon5100-cheung-d65"),
    ("nikon5100-cheung-d65", "sigma-cheung-d65"),
    ("sigma-cheung-d65", "nikon5100-cheung-d65"),
    ("nikon5100-gamma22", "nikon5100-cheung-d65"),
    ("nikon5100-flat-log", "nikon5100-cheung-d65"),
    ("nikon5100-wb-d50", "nikon5100-cheung-d65"),
    ("nikon5100-finlayson-d65", "sigma-led-finlayson"),
    ("bad-desaturated", "ideal-srgb8"),
    ("bad-oversaturated", "ideal-srgb8"),
    ("nikon5100-ccm-de2000", "ideal-srgb8"),
)


def objectives() -> dict[str, Any]:
    from fidelity.camera.model import load_camera
    from fidelity.camera.render import render_chart
    from fidelity.colour.colorimetry import linearize_srgb
    from fidelity.correction.models import MODELS, OBJECTIVES, cross_validate, usable_patches

    charts = {}
    for name in {n for p in PAIRS for n in p}:
        m = render_chart(load_camera(ROOT / "cameras" / f"{name}.toml"),
                         pixels_per_patch=8).measurement
        charts[name] = m
    rows = []
    for sim, real in PAIRS:
        s, r = charts[sim], charts[real]
        ex = usable_patches(s.srgb, r.srgb, r.patch_names)
        w = np.array([0.0 if n in ex else 1.0 for n in r.patch_names])
        xs, xr = np.asarray(linearize_srgb(s.srgb)), np.asarray(linearize_srgb(r.srgb))
        for model in MODELS:
            for objective in OBJECTIVES:
                cv = cross_validate(xs, xr, model, weights=w, objective=objective)
                rows.append({"sim": sim, "real": real, "model": model, "objective": objective,
                             "cv_mean_delta_e": float(np.nanmean(cv))})
    summary: dict[str, dict[str, float]] = {}
    for model in MODELS:
        summary[model] = {o: float(np.mean([x["cv_mean_delta_e"] for x in rows
                                            if x["model"] == model and x["objective"] == o]))
                          for o in OBJECTIVES}
    overall = {o: float(np.mean([x["cv_mean_delta_e"] for x in rows if x["objective"] == o]))
               for o in OBJECTIVES}
    print("mean cross-validated ΔE00 over", len(PAIRS), "camera pairs:")
    for model, d in summary.items():
        print(f"  {model:16s} " + "  ".join(f"{o} {v:.3f}" for o, v in d.items()))
    print("  all models       " + "  ".join(f"{o} {v:.3f}" for o, v in overall.items()))
    return {"pairs": [list(p) for p in PAIRS], "rows": rows, "by_model": summary,
            "overall": overall, "better": min(overall, key=lambda o: overall[o])}


def _chart_image(colours: np.ndarray, h: int, w: int, patch: int, background: float
                 ) -> tuple[np.ndarray, str]:
    """A chart of ``colours`` (24, 3) in a ``h`` x ``w`` image, and its corners string."""
    gap, gy = (w - 6 * patch) // 7, (h - 4 * patch) // 5
    img = np.full((h, w, 3), background, np.float32)
    centres = []
    for i, rgb in enumerate(colours):
        r, c = divmod(i, 6)
        y, x = gy + r * (patch + gy), gap + c * (patch + gap)
        img[y:y + patch, x:x + patch] = rgb
        centres.append((x + patch / 2 - 0.5, y + patch / 2 - 0.5))
    return img, ",".join(f"{v:g}" for i in (0, 5, 23, 18) for v in centres[i])


def lut_accuracy() -> list[dict[str, Any]]:
    import copy
    import math

    from fidelity.camera.model import camera_from_dict
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_exr, write_png
    from fidelity.colour.colorimetry import linearize_srgb
    from fidelity.pipeline.fit import fit_and_verify

    exact = {"name": "exact", "sensitivities": {"source": "ideal"},
             "exposure": {"mode": "gain", "gain": 1.0},
             "white_balance": {"method": "illuminant", "illuminant": "scene"},
             "ccm": {"method": "none"}, "tone": {"curve": "srgb"}}
    k = np.ones(3) / math.sqrt(3)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = math.radians(-20.0)
    hue = np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * kx @ kx
    errors = {"hue 20 deg": {"ccm": {"method": "matrix", "matrix": hue.tolist()}},
              "wb gains": {"white_balance": {"method": "gains", "gains": [1.25, 1.0, 0.8]}},
              "gamma 2.2": {"tone": {"curve": "gamma", "gamma": 2.2}}}
    cases = (("hue 20 deg", "matrix"), ("hue 20 deg", "root-polynomial"), ("wb gains", "gains"),
             ("gamma 2.2", "matrix+curve"), ("gamma 2.2", "root-polynomial"))

    def srgb(changes: dict[str, Any]) -> np.ndarray:
        d = copy.deepcopy(exact)
        d.update(changes)
        return np.clip(render_chart(camera_from_dict(d), pixels_per_patch=8).measurement.srgb,
                       0, 1)

    rows = []
    print("the .cube through OpenColorIO against the model (ΔE00, 41^3 lattice and chart):")
    with tempfile.TemporaryDirectory() as d:
        real_img, corners = _chart_image(srgb({}), 168, 247, 32, 0.05)
        real = write_png(Path(d) / "real.png", real_img, 16)
        for error, model in cases:
            colours = srgb(errors[error])
            img, _ = _chart_image(colours, 168, 247, 32, 0.05)
            for enc, path in (("srgb", write_png(Path(d) / "sim.png", img, 16)),
                              ("linear", write_exr(Path(d) / "sim.exr",
                                                   np.asarray(linearize_srgb(img)) * 0.5))):
                rep = fit_and_verify(path, real, Path(d) / "out", model=model,
                                     sim_corners=corners, real_corners=corners)
                checks = [c.to_json() for c in rep.lut_checks]
                rows.append({"error": error, "model": model, "sim_encoding": enc,
                             "cube_output": rep.output, "size": rep.lut.size,
                             "passed": rep.lut.passed, "checks": checks})
                print(f"  {error:11s} {model:16s} {enc:6s} output {rep.output:7s} "
                      + "; ".join(f"{c['size']}^3 max {c['grid_max_delta_e']:.3f} p99 "
                                  f"{c['grid_p99_delta_e']:.3f} chart "
                                  f"{c['chart_max_delta_e']:.3f}" for c in checks)
                      + f" -> {rep.lut.size}^3 {'met' if rep.lut.passed else 'NOT met'}")
    return rows


def _big_pair(folder: Path) -> tuple[Path, Path, str]:
    from fidelity.chart.image import write_png
    from fidelity.colour.charts import load_reference
    from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb

    real = np.clip(load_reference("scene").srgb, 0, 1)
    hue = np.array([[0.95, 0.08, -0.03], [-0.03, 0.95, 0.08], [0.08, -0.03, 0.95]])
    sim = np.clip(delinearize_srgb(np.clip(linearize_srgb(real) @ hue.T, 0, 1)), 0, 1)
    paths = []
    for name, colours in (("sim", sim), ("real", real)):
        img, corners = _chart_image(colours, 3000, 4000, 560, 0.1)
        paths.append(write_png(folder / f"{name}.png", img, 8))
    return paths[0], paths[1], corners


def speed(repeats: int, model: str, folder: Path, pair: tuple[Path, Path, str]
          ) -> dict[str, Any]:
    from fidelity.pipeline.fit import fit_and_verify

    sim, real, corners = pair
    out: dict[str, Any] = {"width": 4000, "height": 3000, "model": model, "repeats": repeats}
    for mode, whole in (("windows", False), ("whole image (anchor)", True)):
        runs = []
        for k in range(repeats):
            rep = fit_and_verify(sim, real, folder / f"out-{model}-{k}", model=model,
                                 sim_corners=corners, real_corners=corners, corrected=whole)
            runs.append({"wall": dict(rep.seconds), "cpu": dict(rep.cpu_seconds),
                         "after_mean_delta_e": rep.after.mean_delta_e})
        best = {clock: {key: min(r[clock][key] for r in runs) for key in runs[0][clock]}
                for clock in ("wall", "cpu")}
        fv = {clock: min(r[clock]["fit"] + r[clock]["verify"] for r in runs)
              for clock in ("wall", "cpu")}
        out[mode] = {"runs": runs, "best": best, "fit_plus_verify_s": fv}
        print(f"two 12 MP images, {model}, verification on {mode}, best of {repeats}: "
              f"read {best['wall']['read']:.2f} s, fit {best['wall']['fit']:.2f} s "
              f"({best['cpu']['fit']:.2f} CPU), verify {best['wall']['verify']:.2f} s "
              f"({best['cpu']['verify']:.2f} CPU), fit + verify {fv['wall']:.2f} s "
              f"({fv['cpu']:.2f} CPU)")
    a, w = out["whole image (anchor)"], out["windows"]
    out["verify_ratio_anchor_over_windows"] = {
        c: a["best"][c]["verify"] / w["best"][c]["verify"] for c in ("wall", "cpu")}
    return out


def processes(repeats: int, folder: Path, pair: tuple[Path, Path, str],
              sources: dict[str, Path]) -> dict[str, Any]:
    from benchmarks.speed.timing import run_process

    sim, real, corners = pair
    out: dict[str, Any] = {}
    for label, source in sources.items():
        env = dict(os.environ, PYTHONPATH=str(source))
        runs = []
        for k in range(repeats):
            o = folder / f"proc-{label}-{k}"
            runs.append(run_process([sys.executable, "-m", "fidelity", "fit", str(sim),
                                     str(real), "--out", str(o), "--sim-corners", corners,
                                     "--real-corners", corners], env, cwd=source))
            if runs[-1]["exit"] != 0:
                raise RuntimeError(f"{label}: fidelity fit failed: {runs[-1]['stderr']}")
        best = {key: min(r[key] for r in runs) for key in ("seconds", "cpu_seconds",
                                                           "max_rss_mb")}
        out[label] = {"source": str(source), "runs": runs, "best": best}
        print(f"whole process, {label} ({source}): {best['seconds']:.2f} s wall, "
              f"{best['cpu_seconds']:.2f} s CPU, max RSS {best['max_rss_mb']:.0f} MB")
    if "anchor" in out:
        out["ratio_checkout_over_anchor"] = {
            key: out["checkout"]["best"][key] / out["anchor"]["best"][key]
            for key in ("seconds", "cpu_seconds", "max_rss_mb")}
        print("checkout / anchor: " + ", ".join(
            f"{k} {v:.2f}" for k, v in out["ratio_checkout_over_anchor"].items()))
    return out


def measure(ctx: Context) -> dict[str, Any]:
    repeats = ctx["repeats"]
    result: dict[str, Any] = {"repeats": repeats}
    last = RESULTS / "fit.json"
    if not ctx["skip_objective"]:
        result["objective"] = objectives()
    elif last.is_file():
        result["objective"] = json.loads(last.read_text(encoding="utf-8"))["details"].get(
            "objective")
    result["lut"] = lut_accuracy()
    sources = {"checkout": ROOT}
    if ctx["source"]:
        sources["anchor"] = Path(ctx["source"]).resolve()
    with tempfile.TemporaryDirectory() as d:
        pair = _big_pair(Path(d))
        result["speed"] = {m: speed(repeats, m, Path(d), pair)
                           for m in ("matrix", "root-polynomial")}
        result["processes"] = processes(repeats, Path(d), pair, sources)
    result["load_average_at_end"] = list(os.getloadavg())
    return result


def cases(details: dict[str, Any]) -> list[Case]:
    out = []
    for model, sp in details["speed"].items():
        ours, anchor = sp["windows"], sp["whole image (anchor)"]
        n = len(ours["runs"])
        for step in ("verify", "fit"):
            out.append(case(
                f"{model}: {step} of two 12 MP images (in process)",
                figures(f"fit_and_verify, {step}, the patch windows through the cube",
                        ours["best"]["wall"][step], cpu_s=ours["best"]["cpu"][step]),
                figures(f"fit_and_verify(corrected=True), {step}, the whole image through the "
                        "cube", anchor["best"]["wall"][step], cpu_s=anchor["best"]["cpu"][step]),
                per="fit", statistic=f"best of {n} (fit_and_verify's own timers)"))
    procs = details["processes"]
    if "anchor" in procs:
        b, a = procs["checkout"]["best"], procs["anchor"]["best"]
        out.append(case(
            "python -m fidelity fit of two 12 MP images",
            figures("this checkout", b["seconds"], cpu_s=b["cpu_seconds"],
                    max_rss_mb=b["max_rss_mb"]),
            figures(f"the anchor checkout ({procs['anchor']['source']})", a["seconds"],
                    cpu_s=a["cpu_seconds"], max_rss_mb=a["max_rss_mb"]),
            per="process", statistic=f"best of {len(procs['checkout']['runs'])} (each figure)",
            process=True))
    else:
        b = procs["checkout"]["best"]
        out.append(case("python -m fidelity fit of two 12 MP images",
                        figures("this checkout", b["seconds"], cpu_s=b["cpu_seconds"],
                                max_rss_mb=b["max_rss_mb"]),
                        None, per="process",
                        statistic=f"best of {len(procs['checkout']['runs'])} (each figure)",
                        process=True, note="no anchor checkout given (source)"))
    return out
