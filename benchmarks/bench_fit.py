"""Benchmark: ``fidelity fit``: which objective generalises better, and how fast a fit is.

1. **Objective** (issue 29, requirement 6): for pairs of the suite's cameras (``cameras/``,
   closed-form renders under D65: the "simulated" camera's chart fitted onto the "real"
   camera's), the mean leave-3-patches-out cross-validated ΔE00 of every model, fitted in
   linear RGB (``linear``) and by CIEDE2000 (``ciede2000``); the lower mean is the default
   (:data:`fidelity.correction.models.DEFAULT_OBJECTIVE`).
2. **Speed** (requirement 5): two 12 MP chart images (4000 x 3000, 8-bit PNG, corners given),
   :func:`fidelity.fit.fit_and_verify`'s own timers: reading, fitting (fit and
   cross-validation) and verifying (baking the .cube, checking it through OpenColorIO over the
   chart and 68921 lattice points, the config, the 12 MP SIM image through OpenColorIO and its
   audit). Best of N.

Writes reports/benchmarks/fit.json. Run:  python -m benchmarks.bench_fit
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import machine_info
from fidelity.fileio import write_json_atomic

ROOT = Path(__file__).parents[1]
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


def speed(repeats: int, model: str) -> dict[str, Any]:
    from fidelity.chart.image import write_png
    from fidelity.colour.charts import load_reference
    from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
    from fidelity.fit import fit_and_verify

    h, w, patch = 3000, 4000, 560
    gap = (w - 6 * patch) // 7
    gy = (h - 4 * patch) // 5
    real = np.clip(load_reference("scene").srgb, 0, 1)
    hue = np.array([[0.95, 0.08, -0.03], [-0.03, 0.95, 0.08], [0.08, -0.03, 0.95]])
    sim = np.clip(delinearize_srgb(np.clip(linearize_srgb(real) @ hue.T, 0, 1)), 0, 1)
    centres = []
    with tempfile.TemporaryDirectory() as d:
        paths = []
        for name, colours in (("sim", sim), ("real", real)):
            img = np.full((h, w, 3), 0.1)
            for i, rgb in enumerate(colours):
                r, c = divmod(i, 6)
                y, x = gy + r * (patch + gy), gap + c * (patch + gap)
                img[y:y + patch, x:x + patch] = rgb
                if name == "sim":
                    centres.append((x + patch / 2 - 0.5, y + patch / 2 - 0.5))
            paths.append(write_png(Path(d) / f"{name}.png", img, 8))
        corners = ",".join(f"{v:g}" for i in (0, 5, 23, 18) for v in centres[i])
        runs = []
        for k in range(repeats):
            rep = fit_and_verify(paths[0], paths[1], Path(d) / f"out{k}", model=model,
                                 sim_corners=corners, real_corners=corners)
            runs.append(dict(rep.seconds))
    best = {key: min(r[key] for r in runs) for key in runs[0]}
    fv = min(r["fit"] + r["verify"] for r in runs)
    print(f"two 12 MP images ({w}x{h}), model {model}, best of {repeats}: read "
          f"{best['read']:.2f} s, fit {best['fit']:.2f} s, verify {best['verify']:.2f} s, "
          f"fit + verify {fv:.2f} s")
    return {"width": w, "height": h, "model": model, "repeats": repeats, "runs": runs,
            "best": best, "fit_plus_verify_s": fv}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "reports/benchmarks/fit.json")
    args = ap.parse_args()
    import os

    result = {"machine": machine_info(), "load_average_at_start": list(os.getloadavg()),
              "objective": objectives(),
              "speed": {m: speed(args.repeats, m) for m in ("matrix", "root-polynomial")}}
    result["load_average_at_end"] = list(os.getloadavg())
    write_json_atomic(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
