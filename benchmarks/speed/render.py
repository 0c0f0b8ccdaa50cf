"""Speed against error of the Mitsuba chart renderer, with the closed form as anchor (issue 3.5).

Sweeps Mitsuba's settings -- variant (llvm_ad_spectral, scalar_spectral), sampler
(independent, multijitter), samples per pixel and pixels per patch -- renders the chart with
each, and measures the mean over patches of ΔE00 between the Mitsuba and the closed-form
measurement (same camera, same ISP, noise and quantisation off so only the renderer differs).
Each setting runs with several sampler seeds; the error of a setting is its worst seed. The
closed-form render is timed in the same run and every time is also given as a ratio to it.

The default chosen is the cheapest setting (median wall time of render_chart on the probed
variant) whose worst-seed error is <= 0.02 ΔE00 for every camera benchmarked and on every
variant, and whose time on the slowest variant is < 30 s.

Also writes index.html, README.md and speed_vs_error.png under reports/render. Resumable: an
interrupted run continues from bench_render.partial.jsonl in that folder.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from fidelity.camera.model import Noise, load_camera
from fidelity.camera.render import render_chart
from fidelity.colour.colorimetry import delta_e_2000

ANCHOR = "the closed-form render of the same camera (render_chart, timed in the same run)"
PARAMETERS = {"seeds": Parameter(3, "sampler seeds per setting (its error: the worst)"),
              "quick": Parameter(False, "a smaller grid (a smoke run)")}
QUICK = {"seeds": 1, "quick": True}
NEEDS = ("mitsuba",)
ARTEFACTS = "reports/render"

if TYPE_CHECKING:
    from fidelity.report.document import Document

TARGET = 0.02
TIME_LIMIT_S = 30.0


def render_environment() -> dict[str, Any]:
    """The machine and software the renders ran on, as the report states them."""
    import drjit
    import mitsuba

    from fidelity.camera import mitsuba as mr

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = round(int(line.split()[1]) / 1024**2, 1)
    except OSError:
        pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    lib = mr.find_libllvm()
    return {
        "cpu": cpu,
        "logical_cpus": os.cpu_count(),
        "memory_gib": mem,
        "load_average_at_start": load,
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "mitsuba": mitsuba.__version__,
        "drjit": getattr(drjit, "__version__", None),
        "numpy": np.__version__,
        "libllvm": str(lib) if lib else None,
        "note": "shared 2-core machine; other jobs may have run at the same time",
    }


def bench_cameras() -> dict[str, Any]:
    """Cameras benchmarked: ideal (negative lobes: 6 film channels) and the default without
    noise and quantisation (so only the renderer differs)."""
    nikon = load_camera("nikon-5100")
    nikon = dataclasses.replace(nikon, noise=Noise(), quantisation_bits=None,
                                name="nikon-5100 (no noise, float)")
    return {"ideal": load_camera("ideal"), "nikon-5100": nikon}


def run(args: Any) -> dict[str, Any]:
    from fidelity.camera import mitsuba as mr

    cameras = bench_cameras()
    probe = mr.probe_variant()
    variants = [probe.variant] + [v for v in ("scalar_spectral",) if v != probe.variant]
    pixels = [8, 16, 32] if args.quick else [8, 16, 32, 64]
    # perfect squares: the multijitter sampler would round other counts up to a w x h grid
    spps = [4, 16, 64] if args.quick else [4, 16, 36, 64, 144, 256]
    seeds = list(range(args.seeds))

    # anchor: closed form (timed in the same run) and the reference measurement per camera
    closed: dict[str, Any] = {}
    for name, cam in cameras.items():
        render_chart(cam, "D65")  # warm caches
        times = []
        for _ in range(5):
            t = time.perf_counter()
            r = render_chart(cam, "D65")
            times.append(time.perf_counter() - t)
        closed[name] = {"lab": r.measurement.lab, "seconds": statistics.median(times)}
    anchor_s = statistics.median(c["seconds"] for c in closed.values())
    print(f"closed form: {anchor_s * 1000:.1f} ms per render (anchor)", flush=True)

    # resumable: finished rows are appended to a JSON-lines file and skipped on a re-run
    partial = args.out / "bench_render.partial.jsonl"
    done: dict[tuple[Any, ...], dict[str, Any]] = {}
    if partial.is_file():
        for line in partial.read_text(encoding="utf-8").splitlines():
            if line.strip():
                r = json.loads(line)
                done[(r["variant"], r["sampler"], r["pixels_per_patch"], r["spp"], r["camera"],
                      r["seeds"])] = r
        print(f"resuming: {len(done)} settings already measured in {partial}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    for variant in variants:
        render_chart("ideal", "D65", "mitsuba", spp=4, pixels_per_patch=8, variant=variant)  # JIT warm-up
        samplers = ["independent", "multijitter"] if variant == probe.variant else ["multijitter"]
        for sampler in samplers:
            for ppp in pixels:
                for spp in spps:
                    for cam_name, cam in cameras.items():
                        if cam_name != "ideal" and sampler != "multijitter":
                            continue
                        key = (variant, sampler, ppp, spp, cam_name, len(seeds))
                        if key in done:
                            rows.append(done[key])
                            continue
                        errs, times, rtimes = [], [], []
                        for seed in seeds:
                            t = time.perf_counter()
                            r = render_chart(cam, "D65", "mitsuba", spp=spp, pixels_per_patch=ppp,
                                             variant=variant, sampler=sampler, seed=seed)
                            times.append(time.perf_counter() - t)
                            rtimes.append(r.conventions["mitsuba"]["render_seconds"])
                            errs.append(float(np.mean(delta_e_2000(r.measurement.lab,
                                                                   closed[cam_name]["lab"]))))
                        row = {
                            "variant": variant, "sampler": sampler, "pixels_per_patch": ppp,
                            "spp": spp, "camera": cam_name, "seeds": len(seeds),
                            "mean_delta_e_vs_closed_form": errs,
                            "worst_delta_e": max(errs), "median_delta_e": statistics.median(errs),
                            "seconds": statistics.median(times),
                            "mitsuba_render_seconds": statistics.median(rtimes),
                            "ratio_to_closed_form": statistics.median(times) / anchor_s,
                        }
                        rows.append(row)
                        with partial.open("a", encoding="utf-8") as fh:
                            fh.write(json.dumps(row) + "\n")
                        print(f"{variant:17s} {sampler:11s} ppp {ppp:3d} spp {spp:4d} "
                              f"{cam_name:10s} ΔE worst {row['worst_delta_e']:.4f} "
                              f"{row['seconds']:7.3f} s  x{row['ratio_to_closed_form']:.0f} "
                              "closed form", flush=True)
    return {"probe": dataclasses.asdict(probe), "variants": variants, "rows": rows,
            "closed_form_seconds": anchor_s, "pixels": pixels, "spps": spps}


def choose_default(result: dict[str, Any], min_pixels: int = 1) -> dict[str, Any] | None:
    """Cheapest (sampler, ppp, spp) with ppp >= ``min_pixels``, within TARGET on every camera
    and variant, < 30 s on every variant; cost = time on the probed (first) variant."""
    rows = result["rows"]
    main_variant = result["variants"][0]
    best = None
    keys = {(r["sampler"], r["pixels_per_patch"], r["spp"]) for r in rows}
    for key in sorted(keys):
        if key[1] < min_pixels:
            continue
        sel = [r for r in rows if (r["sampler"], r["pixels_per_patch"], r["spp"]) == key]
        if {r["variant"] for r in sel} != set(result["variants"]):
            continue
        if len({r["camera"] for r in sel}) < 2:
            continue
        if any(r["worst_delta_e"] > TARGET for r in sel):
            continue
        if any(r["seconds"] >= TIME_LIMIT_S for r in sel):
            continue
        cost = max(r["seconds"] for r in sel if r["variant"] == main_variant)
        if best is None or cost < best["seconds"]:
            best = {"sampler": key[0], "pixels_per_patch": key[1], "spp": key[2],
                    "seconds": cost, "variant": main_variant,
                    "worst_delta_e": max(r["worst_delta_e"] for r in sel),
                    "seconds_by_variant": {v: max(r["seconds"] for r in sel if r["variant"] == v)
                                           for v in result["variants"]}}
    return best


def plot(result: dict[str, Any]) -> bytes:
    """Time against error, one line per (variant, sampler, pixels per patch) along spp (PNG)."""
    from benchmarks.tools.plots import new_figure, png_bytes

    fig, ax = new_figure(9, 6)
    rows = [r for r in result["rows"] if r["camera"] == "ideal"]
    styles = {"llvm_ad_spectral": "-", "scalar_spectral": "--"}
    markers = {8: "o", 16: "s", 32: "^", 64: "D"}
    colors = {"independent": "tab:red", "multijitter": "tab:blue"}
    groups = sorted({(r["variant"], r["sampler"], r["pixels_per_patch"]) for r in rows})
    for variant, sampler, ppp in groups:
        sel = sorted((r for r in rows if (r["variant"], r["sampler"], r["pixels_per_patch"]) ==
                      (variant, sampler, ppp)), key=lambda r: r["spp"])
        ax.plot([r["seconds"] for r in sel], [r["worst_delta_e"] for r in sel],
                linestyle=styles.get(variant, ":"), marker=markers.get(ppp, "x"),
                color=colors.get(sampler, "k"), alpha=0.8,
                label=f"{variant.split('_')[0]} {sampler} {ppp} px")
        for r in sel:
            ax.annotate(str(r["spp"]), (r["seconds"], r["worst_delta_e"]), fontsize=6,
                        xytext=(2, 2), textcoords="offset points")
    ax.axhline(TARGET, color="k", linewidth=0.8)
    ax.text(min(r["seconds"] for r in rows), TARGET * 1.08,
            f"target {TARGET} ΔE00", fontsize=8)
    for key, color, label in (("default", "green", "chosen default"),
                              ("cheapest_any_layout", "orange", "cheapest at any layout")):
        d = result.get(key)
        if d:
            ax.scatter([d["seconds"]], [d["worst_delta_e"]], s=200, facecolors="none",
                       edgecolors=color, linewidths=2, zorder=5,
                       label=f"{label} (worst over cameras, variants)")
    ax.axvline(result["closed_form_seconds"], color="grey", linewidth=0.8, linestyle=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of render_chart (s, median over seeds; dotted: closed form)")
    ax.set_ylabel("mean ΔE00 vs closed form (worst of seeds), ideal camera, D65")
    ax.set_title("Mitsuba 3 spectral chart: time vs error (numbers: spp)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(True, which="both", alpha=0.3)
    return png_bytes(fig, dpi=120)


def table(rows: list[dict[str, Any]], anchor: float) -> list[list[str]]:
    """One row of formatted cells per setting and camera (HEAD's columns)."""
    out = []
    for r in sorted(rows, key=lambda r: (r["camera"], r["variant"], r["sampler"],
                                         r["pixels_per_patch"], r["spp"])):
        out.append([r["camera"], r["variant"], r["sampler"], str(r["pixels_per_patch"]),
                    str(r["spp"]), f"{r['worst_delta_e']:.4f}", f"{r['median_delta_e']:.4f}",
                    f"{r['seconds']:.3f}", f"{r['mitsuba_render_seconds']:.3f}",
                    f"{r['seconds'] / anchor:.0f}"])
    return out


HEAD = ["camera", "variant", "sampler", "px/patch", "spp", "ΔE worst", "ΔE median",
        "time s", "mitsuba s", "x closed form"]

#: File name of the headline figure.
FIGURE = "speed_vs_error.png"


def summary(result: dict[str, Any]) -> str:
    """The default chosen (or that none met the target) and the cheapest setting, in words."""
    d = result["default"]
    text = (
        f"Default chosen: sampler {d['sampler']}, {d['pixels_per_patch']} px per patch, "
        f"{d['spp']} spp: worst mean ΔE00 vs closed form {d['worst_delta_e']:.4f} "
        f"(target {TARGET}); {d['seconds']:.2f} s on {d['variant']}, "
        + ", ".join(f"{v}: {s:.2f} s" for v, s in d["seconds_by_variant"].items())
        if d else "No setting met the target."
    )
    c = result.get("cheapest_any_layout")
    if c:
        text += (f". Cheapest at any layout: {c['sampler']}, {c['pixels_per_patch']} px, "
                 f"{c['spp']} spp ({c['seconds']:.2f} s, worst ΔE00 {c['worst_delta_e']:.4f}); "
                 f"the default keeps the closed form's {result['default_min_pixels_per_patch']}"
                 " px per patch so both renderers share one layout and one camera-noise field")
    return text


def document(result: dict[str, Any]) -> Document:
    """The benchmark report: the default chosen (headline, with the time-against-error plot),
    the method, the machine and every setting measured (folded)."""
    from fidelity.report.document import Document, Facts, Figure, Headline, Text, section
    from fidelity.report.document import table as doc_table
    from fidelity.report.format import listing

    m = result["machine"]
    figure = Figure(plot(result), FIGURE, "time vs error",
                    "Wall time against worst-seed error per setting, ideal camera, D65 "
                    "(numbers: spp; circles: the default chosen and the cheapest setting).")
    machine = Facts((
        ("CPU", f"{m['cpu']}, {m['logical_cpus']} logical CPUs, {m['memory_gib']} GiB"),
        ("platform", str(m["platform"])),
        ("software", f"Python {m['python']}, Mitsuba {m['mitsuba']}, Dr.Jit {m['drjit']}, "
                     f"libLLVM {m['libllvm']}"),
        ("load average at start (1, 5, 15 min)", listing(f"{v:.2f}" for v in m["load_average_at_start"] or [])),
        ("note", str(m["note"])),
    ))
    method = Text(
        "Error: mean over the 24 patches of ΔE00 between the Mitsuba and the closed-form "
        "measurement (same camera, noise and quantisation off), worst of "
        f"{result['seeds']} sampler seeds. Time: median wall time of the whole `render_chart` "
        f"call; the closed form takes {result['closed_form_seconds'] * 1000:.1f} ms (anchor); "
        "'x closed form' is each time over that anchor, measured in the same run.")
    rows = table(result["rows"], result["closed_form_seconds"])
    return Document(
        "Mitsuba render: speed against error (issue 3, item 5)",
        Headline(f"**{summary(result)}**", "pass" if result["default"] else "fail", figure),
        (section("Method", method), section("Machine", machine),
         section(f"Every setting measured ({len(rows)} rows)",
                 doc_table(HEAD, rows, numeric=[False, False, False] + [True] * 7),
                 folded=True)),
        subtitle="Generated by `python -m benchmarks.speed render` "
                 f"on {result['date']}.")


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.camera.render import CLOSED_FORM_PIXELS_PER_PATCH

    args = SimpleNamespace(out=ctx.artefacts, seeds=ctx["seeds"], quick=ctx["quick"])
    environment = render_environment()
    result = run(args)
    result["seeds"] = args.seeds
    result["environment"] = environment
    # Default: same layout as the closed form (its window of 16 x 16 px averages the default
    # camera's sensor noise; with one layout, seeded camera noise falls on the same pixels in
    # both renderers), cheapest spp within the target there.
    result["cheapest_any_layout"] = choose_default(result)
    result["default_min_pixels_per_patch"] = CLOSED_FORM_PIXELS_PER_PATCH
    result["default"] = choose_default(result, min_pixels=CLOSED_FORM_PIXELS_PER_PATCH)
    partial = args.out / "bench_render.partial.jsonl"
    if partial.is_file():
        partial.unlink()  # the complete result is in reports/benchmarks/render.json
    return result


def cases(details: dict[str, Any]) -> list[Case]:
    anchor = figures("closed-form render_chart (median of 5, over the cameras)",
                     details["closed_form_seconds"])
    out = []
    for r in sorted(details["rows"], key=lambda r: (r["camera"], r["variant"], r["sampler"],
                                                    r["pixels_per_patch"], r["spp"])):
        out.append(case(
            f"{r['camera']}, {r['variant']}, {r['sampler']}, {r['pixels_per_patch']} px per "
            f"patch, {r['spp']} spp",
            figures("Mitsuba render_chart", r["seconds"]), anchor, per="render",
            statistic=f"median of {r['seeds']} seeds",
            note=(f"worst mean ΔE00 from the closed form {r['worst_delta_e']:.4f}; Mitsuba's "
                  f"own render {r['mitsuba_render_seconds']:.3f} s")))
    return out


def report(result: dict[str, Any], folder: Path) -> None:
    """index.html and README.md (with speed_vs_error.png) from the result."""
    from fidelity.report.html import write_document

    details = result["details"]
    doc = {**details, "machine": details.get("environment") or result["machine"],
           "date": result["date"]}
    write_document(document(doc), html=folder / "index.html", markdown=folder / "README.md")
