"""Is the stated uncertainty of the chart ΔE right? And what does it cost? (issue 32)

Coverage: one camera rendered with ``--trials`` noise seeds; each render states its chart ΔE and
its standard uncertainty ``u`` (k = 1, :mod:`fidelity.measure.uncertainty`). The ΔE values spread
around their mean; a right ``u`` has about 68 % of them within ``±u`` and 95 % within ``±2u``
(normal distribution). Three studies:

- ``render nikon-5100``: the built-in camera (light noise, 12 bit), closed-form render;
- ``render noisy``: the same camera with ten times less full well (3000 e-) and 5 e- read noise;
- ``audit noisy``: the noisy camera's developed image audited as a user would (the chart found,
  corners jittered by the finder's residual, exposure fitted on the neutral patches): the
  budget of an image audit, placement included. This camera's white balance is fixed
  (``illuminant``), so that the seeds change only what an image shows, its pixel noise: a
  camera that estimates its white balance on the noisy chart changes its colours from capture
  to capture, which a render's budget states (``camera white balance``) and an audit of one
  image cannot know.
- ``photo captures``: one synthetic photo (the chart under a homography in a COCO photo,
  :func:`photo_study`) captured again and again: its own sensor noise each time, cropped by up
  to a tenth of each side, stored as PNG or as JPEG of quality 90 and 75, audited from the
  file as a user would. JPEG correlates neighbouring pixels (its 8 x 8 and 16 x 16 blocks):
  the pixel-noise component's design effect (:func:`fidelity.measure.uncertainty.
  block_design_effect`) is what this study checks.

The spread is the sample standard deviation over the trials; the mean ΔE over the trials stands
in for the expectation. With N trials a coverage fraction has a binomial standard error of
about sqrt(p (1 - p) / N) (6.6 % at 68 % and N = 50).

Cost, measured two ways:

- the share: ``fidelity audit IMAGE --json`` as a whole process of this checkout, with the
  time spent in the uncertainty budget (:func:`fidelity.measure.pixels.image_uncertainty`)
  timed inside it; the cost on top of an audit is that time over the rest of the process
  (median over ``--repeats`` runs), for the small render and for the 12-megapixel photo of
  ``benchmarks.speed.startup`` (where the placement draws pass over the most pixels);
- against the anchor: ``fidelity audit IMAGE --json`` and ``fidelity check --json`` as whole
  processes, this checkout against the code before the uncertainty (``--anchor`` commit,
  exported with ``git archive``), interleaved; median wall time and max RSS. Everything else
  that changed since the anchor is in this difference too.

    python -m benchmarks.studies.uncertainty_coverage --trials 100 --repeats 7
    # -> reports/uncertainty/coverage.json and reports/uncertainty/coverage.md
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import machine_info
from benchmarks.speed.versions import export

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "reports" / "uncertainty"


def coverage(delta_e: list[float], u: list[float]) -> dict[str, Any]:
    """Coverage of ``±u`` and ``±2u`` around the mean of ``delta_e``."""
    de, uu = np.asarray(delta_e), np.asarray(u)
    dev = np.abs(de - de.mean())
    n = de.size
    return {"trials": int(n), "mean_delta_e": float(de.mean()),
            "observed_sd": float(de.std(ddof=1)), "mean_u": float(uu.mean()),
            "rms_u": float(np.sqrt(np.mean(uu ** 2))),
            "sd_over_rms_u": float(de.std(ddof=1) / np.sqrt(np.mean(uu ** 2))),
            "within_1u": float(np.mean(dev <= uu)), "within_2u": float(np.mean(dev <= 2 * uu)),
            "binomial_se_at_68": float(np.sqrt(0.68 * 0.32 / n)),
            "binomial_se_at_95": float(np.sqrt(0.95 * 0.05 / n))}


def noisy_camera(fixed_white_balance: bool = False) -> Any:
    from fidelity.camera.model import Noise, load_camera

    cam = load_camera("nikon-5100")
    cam = replace(cam, name="nikon-5100 noisy", noise=Noise(full_well=3000.0, read_noise=5.0))
    if fixed_white_balance:
        cam = replace(cam, white_balance=replace(cam.white_balance, method="illuminant"))
    return cam


def summary(measured: list[tuple[float, Any]]) -> dict[str, Any]:
    """:func:`coverage` of the (chart ΔE, its uncertainty budget) pairs, with each
    component's mean."""
    budgets = [b for _, b in measured]
    assert all(b is not None for b in budgets)
    out = coverage([v for v, _ in measured], [b.combined for b in budgets])
    out["components_mean"] = {c.name: float(np.mean([b.component(c.name).value
                                                     for b in budgets]))
                              for c in budgets[0].components}
    return out


def render_study(camera: Any, trials: int) -> dict[str, Any]:
    from fidelity.camera.render import render_chart

    renders = [render_chart(camera, seed=seed) for seed in range(trials)]
    return summary([(r.measurement.mean_delta_e, r.uncertainty) for r in renders])


def audit_study(camera: Any, trials: int) -> dict[str, Any]:
    from fidelity.camera.render import render_chart
    from fidelity.measure.pixels import measure_pixels

    measured = []
    for seed in range(trials):
        r = render_chart(camera, seed=seed, pixels_per_patch=48)
        m = measure_pixels(r.display_image, None, encoding="srgb", exposure="auto",
                           reference="scene")
        measured.append((m.mean_delta_e, m.uncertainty))
    return summary(measured)


#: Sensor noise of the photo studies (:func:`tests.fixtures.chart_scenes.make_scene`'s scale: the
#: top of the range its photos are drawn from).
PHOTO_NOISE = 0.02


def photo_study(coco: Path, trials: int, noise: float, seed: int = 7, quality: int | None = 90,
                crop: bool = True) -> dict[str, Any]:
    """One synthetic photo (:func:`tests.fixtures.chart_scenes.make_scene`: the chart under a
    homography in a COCO photo, 1600 px) captured ``trials`` times: each capture its own sensor
    noise, cropped by up to a tenth of each side (the chart kept inside, so the finder sees it
    elsewhere in another context and the JPEG's 8 x 8 blocks fall elsewhere on it), encoded as
    a quality-90 JPEG and audited as a user would (``fidelity.audit_image`` of the file: the
    chart found, exposure fitted)."""
    import cv2

    import fidelity
    from fidelity.colour.charts import DEFAULT_CHART, load_chart
    from fidelity.colour.colorimetry import linearize_srgb
    from tests.fixtures.chart_scenes import make_scene

    background = sorted(coco.glob("*.jpg"))[0]
    patches = linearize_srgb(np.clip(load_chart(DEFAULT_CHART).srgb, 0.0, 1.0))
    measured = []
    with tempfile.TemporaryDirectory() as tmp:
        for trial in range(trials):
            scene = make_scene("classic", str(background), patches, seed=seed, long_side=1600,
                               jpeg=False, hard=False, noise_seed=trial, noise_level=noise)
            assert scene.corners is not None
            rng = np.random.default_rng((seed, trial))
            h, w = scene.srgb.shape[:2]
            lo, hi = scene.corners.min(axis=0), scene.corners.max(axis=0)
            x0, y0, x1, y1 = 0, 0, w, h
            if crop:
                x0 = int(min(rng.uniform(0, 0.1) * w, max(lo[0] - 40, 0)))
                y0 = int(min(rng.uniform(0, 0.1) * h, max(lo[1] - 40, 0)))
                x1 = int(max(w - rng.uniform(0, 0.1) * w, min(hi[0] + 40, w)))
                y1 = int(max(h - rng.uniform(0, 0.1) * h, min(hi[1] + 40, h)))
            cut = np.ascontiguousarray(scene.srgb[y0:y1, x0:x1, ::-1])
            path = Path(tmp) / f"capture_{trial:03d}.{'jpg' if quality else 'png'}"
            ok = cv2.imwrite(str(path), cut, [cv2.IMWRITE_JPEG_QUALITY, quality] if quality
                             else [])
            assert ok
            report = fidelity.audit_image(path)
            measured.append((report.mean_delta_e, report.uncertainty))
    return summary(measured) | {"background": background.name}


def _run(cmd: list[str], pythonpath: str, cwd: str) -> tuple[float, float, float]:
    """Wall seconds, max RSS (MiB) and CPU seconds (user + system) of one whole process."""
    env = dict(os.environ, PYTHONPATH=pythonpath)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise RuntimeError(f"{cmd} failed")
    return wall, usage.ru_maxrss / 1024.0, usage.ru_utime + usage.ru_stime


#: A whole ``fidelity audit`` process whose uncertainty budget is timed from inside: the
#: seconds spent in ``image_uncertainty`` go to the file named by the first argument.
TIMED_AUDIT = """
import sys, time
import fidelity.measure.pixels as measure
spent = []
budget = measure.image_uncertainty
def timed(*args, **kwargs):
    t0 = time.perf_counter()
    try:
        return budget(*args, **kwargs)
    finally:
        spent.append(time.perf_counter() - t0)
measure.image_uncertainty = timed
from fidelity.cli import main
try:
    main(sys.argv[2:])
finally:
    open(sys.argv[1], "w").write(repr(sum(spent)))
"""


def share_study(images: dict[str, Path], repeats: int, tmp: Path) -> dict[str, Any]:
    """Per image: the audit's whole-process wall time, the seconds of it in the uncertainty
    budget, and the budget's cost on top of the rest (medians over ``repeats`` runs)."""
    out: dict[str, Any] = {}
    spent_file = tmp / "spent.txt"
    for name, image in images.items():
        walls, spent = [], []
        for _ in range(repeats):
            cmd = [sys.executable, "-c", TIMED_AUDIT, str(spent_file), "audit", str(image),
                   "-q", "--json", str(tmp / "a.json")]
            walls.append(_run(cmd, str(REPO), str(tmp))[0])
            spent.append(float(spent_file.read_text()))
        wall, budget = statistics.median(walls), statistics.median(spent)
        out[name] = {"wall_s": wall, "uncertainty_s": budget,
                     "overhead_percent": 100.0 * budget / (wall - budget)}
    return out


def cost_study(anchor: str, repeats: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "anchor"
        base.mkdir()
        export(anchor, base, ("fidelity", "charts", "scenes"))
        image_dir = Path(tmp) / "render"
        subprocess.run([sys.executable, "-m", "fidelity", "render", "--camera", "nikon-5100",
                        "--out", str(image_dir)], check=True, capture_output=True,
                       env=dict(os.environ, PYTHONPATH=str(REPO)))
        image = str(image_dir / "developed.png")
        from benchmarks.speed.startup import make_photo

        photo = Path(tmp) / "photo.jpg"
        make_photo(photo)
        share = share_study({"render (248x168, 16-bit PNG)": Path(image),
                             "photo (4000x3000 JPEG)": photo}, repeats, Path(tmp))
        commands = {
            "audit": [sys.executable, "-m", "fidelity", "audit", image, "--json",
                      str(Path(tmp) / "a.json")],
            "check": [sys.executable, "-m", "fidelity", "check", "--json",
                      str(Path(tmp) / "c.json")],
        }
        times: dict[str, dict[str, list[tuple[float, float, float]]]] = {
            k: {"anchor": [], "uncertainty": []} for k in commands}
        for _ in range(repeats):
            for name, cmd in commands.items():
                times[name]["anchor"].append(_run(cmd, str(base), tmp))
                times[name]["uncertainty"].append(_run(cmd, str(REPO), tmp))
    out: dict[str, Any] = {"anchor": anchor, "repeats": repeats, "image": "developed.png of "
                           "fidelity render --camera nikon-5100 (248x168, 16-bit PNG)",
                           "share": share}
    for name, t in times.items():
        a = statistics.median(w for w, _, _ in t["anchor"])
        b = statistics.median(w for w, _, _ in t["uncertainty"])
        ca = statistics.median(c for _, _, c in t["anchor"])
        cb = statistics.median(c for _, _, c in t["uncertainty"])
        out[name] = {"anchor_wall_s": a, "uncertainty_wall_s": b,
                     "overhead_percent": 100.0 * (b / a - 1.0),
                     "anchor_cpu_s": ca, "uncertainty_cpu_s": cb,
                     "cpu_overhead_percent": 100.0 * (cb / ca - 1.0),
                     "anchor_max_rss_mib": max(m for _, m, _ in t["anchor"]),
                     "uncertainty_max_rss_mib": max(m for _, m, _ in t["uncertainty"])}
    return out


def markdown(result: dict[str, Any]) -> str:
    lines = ["# Uncertainty of the chart ΔE: coverage and cost (issue 32)", "",
             "Written by `python -m benchmarks.studies.uncertainty_coverage`; numbers from "
             "`coverage.json`.", "",
             "| study | trials | mean ΔE00 | observed sd | RMS stated u | sd / u | within ±u | "
             "within ±2u |", "|---|---|---|---|---|---|---|---|"]
    for name, s in result["coverage"].items():
        lines.append(f"| {name} | {s['trials']} | {s['mean_delta_e']:.3f} | "
                     f"{s['observed_sd']:.4f} | {s['rms_u']:.4f} | {s['sd_over_rms_u']:.2f} | "
                     f"{100 * s['within_1u']:.0f} % | {100 * s['within_2u']:.0f} % |")
    lines += ["", "Expected for a right u: about 68 % within ±u and 95 % within ±2u (binomial "
              "standard error of a fraction over N trials: sqrt(p(1-p)/N)). Mean components "
              "(ΔE00):", ""]
    for name, s in result["coverage"].items():
        comps = ", ".join(f"{k} {v:.4f}" for k, v in s["components_mean"].items())
        lines.append(f"- {name}: {comps}")
    wide = [(name, s) for name, s in result["coverage"].items() if s["sd_over_rms_u"] < 0.7]
    if wide:
        lines += ["", "Where the stated u is wider than the spread (sd / u below 0.7), its largest "
                      "component:", ""]
        for name, s in wide:
            top, value = max(s["components_mean"].items(), key=lambda kv: kv[1])
            share = value ** 2 / sum(v ** 2 for v in s["components_mean"].values())
            kind = ("the type B bound on the rounding of codes that vary by less than one "
                    "step within a window (JPEG's smoothing leaves such channels): a bound "
                    "that a spread over captures does not test" if top == "rounding" else
                    "not tested by a spread over captures")
            lines.append(f"- {name}: {top} {value:.4f}, {100 * share:.0f} % of u², {kind}")
    cost = result.get("cost")
    if cost and cost.get("share"):
        lines += ["", "What the uncertainty costs on top of an audit (requirement: at most 20 %): "
                      "`fidelity audit IMAGE --json` as a whole process of this checkout, the time "
                      f"in the uncertainty budget timed inside it, median of {cost['repeats']} "
                      "runs:", "",
                  "| image | audit wall s | of it the budget, s | cost on top of the rest |",
                  "|---|---|---|---|"]
        for name, c in cost["share"].items():
            lines.append(f"| {name} | {c['wall_s']:.2f} | {c['uncertainty_s']:.3f} | "
                         f"{c['overhead_percent']:+.1f} % |")
    if cost:
        lines += ["", f"Against the code before the uncertainty, whole processes, median of "
                      f"{cost['repeats']} interleaved runs, anchor = commit {cost['anchor']} (every "
                      "other change since then is in this difference too):", "",
                  "| command | wall s anchor / now | wall overhead | CPU s anchor / now | CPU "
                  "overhead | max RSS anchor / now MiB |", "|---|---|---|---|---|---|"]
        for name in ("audit", "check"):
            c = cost[name]
            lines.append(f"| {name} | {c['anchor_wall_s']:.2f} / {c['uncertainty_wall_s']:.2f} | "
                         f"{c['overhead_percent']:+.1f} % | {c['anchor_cpu_s']:.2f} / "
                         f"{c['uncertainty_cpu_s']:.2f} | {c['cpu_overhead_percent']:+.1f} % | "
                         f"{c['anchor_max_rss_mib']:.0f} / {c['uncertainty_max_rss_mib']:.0f} |")
    lines += ["", f"Machine: {result['machine'].get('cpu')}, {result['machine'].get('cores')} "
                  "cores (shared with other jobs)."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--audit-trials", type=int, default=50)
    ap.add_argument("--photo-trials", type=int, default=50)
    ap.add_argument("--coco", type=Path, default=None,
                    help="COCO photos for the photo studies (default: the shared data's)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--anchor", default="38ac479",
                    help="commit of the code before the uncertainty (the cost's anchor)")
    ap.add_argument("--no-cost", action="store_true")
    ap.add_argument("--only-cost", action="store_true",
                    help="measure the cost again, keep the coverage of coverage.json")
    ap.add_argument("--keep-cost", action="store_true",
                    help="measure the coverage again, keep the cost of coverage.json (the "
                         "cost wants a quiet machine, the coverage does not)")
    args = ap.parse_args(argv)
    from fidelity.core.fileio import write_text_atomic

    result: dict[str, Any] = {"machine": machine_info(), "coverage": {}}
    if args.only_cost:
        result["coverage"] = json.loads((OUT / "coverage.json").read_text())["coverage"]
    else:
        result["coverage"]["render nikon-5100"] = render_study("nikon-5100", args.trials)
        result["coverage"]["render noisy"] = render_study(noisy_camera(), args.trials)
        result["coverage"]["audit noisy (fixed white balance)"] = audit_study(
            noisy_camera(fixed_white_balance=True), args.audit_trials)
        coco = args.coco
        if coco is None:
            from fidelity.core.resources import shared_dir

            shared = shared_dir()
            coco = shared / "coco" / "val2017" if shared is not None else None
        if coco is not None and coco.is_dir():
            for name, quality in (("PNG", None), ("JPEG quality 90", 90),
                                  ("JPEG quality 75", 75)):
                result["coverage"][f"photo captures, {name}"] = photo_study(
                    coco, args.photo_trials, PHOTO_NOISE, quality=quality)
    if args.keep_cost:
        result["cost"] = json.loads((OUT / "coverage.json").read_text())["cost"]
    elif not args.no_cost:
        result["cost"] = cost_study(args.anchor, args.repeats)
    OUT.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT / "coverage.json", json.dumps(result, indent=1) + "\n")
    write_text_atomic(OUT / "coverage.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
