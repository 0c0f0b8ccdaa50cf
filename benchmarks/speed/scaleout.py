"""Scale-out of the COCO sweep: local executor against Ray with 1 and 2 workers, same plan.

One plan (YOLOX-nano, ``images`` images, transforms contrast-inc and gamma-dec at chart
ΔE 3 and 6 plus the baseline: 5 cells), run by ``fidelity.coco.sweep.run_sweep`` into a fresh
store per run with ``--executor local``, ``ray --workers 1`` and ``ray --workers 2`` (Ray
started once in this process, ``num_cpus`` = 2), interleaved, ``repeats`` times each.

Measured per run (from the store's ``meta["last_run"]``, written by the driver):

* throughput: images per second through transform + JPEG round trip + detector (+ the
  driver's store writes and per-cell scoring), over the driver loop (``run_cells``); the
  actors' start (Ray) and the model registration are timed separately (``start_s``);
* scaling efficiency: throughput(N) / (N x throughput(1)) with Ray's 1-worker run as the
  anchor (and against the local run);
* Ray's overhead per work item: (wall x workers - the workers' own seconds) / items, the time a
  worker is not computing per item (scheduling, transfers, the driver's latency).

Other people's work on the machine distorts timings: before each run the benchmark waits (at
most ``max_wait`` s) for the 1-minute load average to fall below ``max_load`` and records
the load it started at. Best of the repeats is reported.

``stages`` only times the stages of a work item on one core (decode, transforms, JPEG round
trip, detector), for the cluster estimate in docs/scaleout.md (``--out
reports/benchmarks/scaleout_stages.json``). Both write reports/scaleout/README.md.
"""

from __future__ import annotations

import json
import os
import secrets
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import RESULTS, Context, Parameter

ANCHOR = "the local executor (one worker process) on the same plan; Ray's 1-worker run"
PARAMETERS = {"images": Parameter(40, "COCO images of the plan"),
              "repeats": Parameter(3, "runs of each executor, interleaved (the best kept)"),
              "max_load": Parameter(0.7, "wait for the 1-minute load average to fall below"),
              "max_wait": Parameter(600.0, "longest wait for it, seconds"),
              "stages": Parameter(False, "only the stages of a work item on one core")}
QUICK = {"images": 8, "repeats": 1, "max_wait": 0.0}
NEEDS = ("shared", "ray", "onnxruntime")
ARTEFACTS = "reports/scaleout"

GRID = (["contrast-inc", "gamma-dec"], [0, 3, 6])
CONFIGS: list[tuple[str, str, int]] = [("local", "local", 1), ("ray-1", "ray", 1),
                                       ("ray-2", "ray", 2)]


def wait_for_quiet(max_load: float, max_wait: float) -> float:
    """Wait until the 1-minute load average is below ``max_load`` (at most ``max_wait`` s);
    returns the load average at the start of the run."""
    deadline = time.time() + max_wait
    while os.getloadavg()[0] >= max_load and time.time() < deadline:
        time.sleep(5)
    return os.getloadavg()[0]


def one_run(kind: str, workers: int, shared: Path, images: int, folder: Path) -> dict[str, Any]:
    from fidelity.coco.executor import ExecutorOptions
    from fidelity.coco.sweep import ModelSpec, run_sweep

    out = Path(tempfile.mkdtemp(dir=folder))
    t0, c0 = time.perf_counter(), time.process_time()
    store = run_sweep([ModelSpec(shared / "models/yolox_nano.onnx", images)],
                      shared / "coco/val2017",
                      shared / "coco/annotations/instances_val2017_subset.json", out, *GRID,
                      executor=ExecutorOptions(kind, workers=workers if kind == "ray" else None),
                      log=lambda s: None)
    wall = time.perf_counter() - t0
    driver_cpu = time.process_time() - c0
    last = store.meta()["last_run"]
    cells = {(c.transform, c.target): (c.map, c.ap) for c in store.cells()}
    store.close()
    loop = last["seconds"]
    busy = last["worker_seconds"]
    return {"wall_s": wall, "loop_s": loop, "start_s": wall - loop, "images": last["images"],
            "items": last["items"], "worker_seconds": busy,
            "throughput": last["images"] / loop,
            "idle_per_item_s": (loop * workers - busy) / last["items"],
            "worker_processes": len(last["workers"]), "cells": cells,
            "worker_cpu_ms_per_image": 1e3 * last["worker_cpu_seconds"] / last["images"],
            # this process: the driver, and for the local executor the worker too
            "driver_cpu_ms_per_image": 1e3 * (driver_cpu - (last["worker_cpu_seconds"]
                                                           if kind == "local" else 0.0))
            / last["images"]}


def stage_costs(shared: Path, n: int = 20, repeats: int = 3) -> dict[str, float]:
    """Milliseconds per image of each stage of a work item on one core (best of ``repeats``
    passes over ``n`` images): decode, transform (channel table, 2^24 table, pull_mean), JPEG
    round trip, YOLOX-nano on the CPU (1 thread)."""
    from fidelity.coco.dataset import PixelMap, calibrated_param
    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import decode_jpeg, roundtrip_jpeg
    from fidelity.coco.scoring import load_annotated_images

    folder, coco, ids = load_annotated_images(
        shared / "coco/val2017", shared / "coco/annotations/instances_val2017_subset.json")
    blobs = [(folder / coco.imgs[i]["file_name"]).read_bytes() for i in ids[:n]]
    decoded = [decode_jpeg(b) for b in blobs]
    maps = {t: PixelMap.build(t, calibrated_param(t, 3)[0])
            for t in ("contrast-inc", "hue", "pull_mean")}
    det = Detector(shared / "models/yolox_nano.onnx", threads=1)

    def best(fn: Any) -> float:
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for item in decoded:
                fn(item)
            times.append(time.perf_counter() - t0)
        return 1e3 * min(times) / len(decoded)

    out = {"decode_ms": 1e3 * min(_timed(lambda: [decode_jpeg(b) for b in blobs])
                                  for _ in range(repeats)) / len(blobs)}
    for t, pm in maps.items():
        out[f"transform_{t}_ms"] = best(lambda d, pm=pm: pm(d[0]))
    out["jpeg_roundtrip_ms"] = best(lambda d: roundtrip_jpeg(d[0], d[1]))
    out["detector_yolox_nano_cpu_1_thread_ms"] = best(lambda d: det(d[0]))
    return out


def _timed(fn: Any) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def measure(ctx: Context) -> dict[str, Any]:
    from types import SimpleNamespace

    from fidelity.core.resources import shared_dir

    args = SimpleNamespace(**ctx.params)
    shared = shared_dir()
    assert shared is not None
    if args.stages:
        load = wait_for_quiet(args.max_load, args.max_wait)
        return {"stages": stage_costs(shared) | {"load1_before": load}}
    work = Path(tempfile.mkdtemp(prefix="bench-scaleout-"))
    token = work / "auth_token"  # a private token: nothing written to ~/.ray
    token.write_text(secrets.token_hex(32))
    os.environ.setdefault("RAY_AUTH_MODE", "token")  # before Ray is imported: read then
    os.environ.setdefault("RAY_AUTH_TOKEN_PATH", str(token))
    import ray

    t0 = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING", log_to_driver=False)
    ray_start = time.perf_counter() - t0
    runs: list[dict[str, Any]] = []
    reference: dict[Any, Any] | None = None
    try:
        for rep in range(args.repeats):
            for name, kind, workers in CONFIGS:
                load = wait_for_quiet(args.max_load, args.max_wait)
                r = one_run(kind, workers, shared, args.images, work)
                cells = r.pop("cells")
                if reference is None:
                    reference = cells
                r |= {"config": name, "executor": kind, "workers": workers, "repeat": rep,
                      "load1_before": load, "load1_after": os.getloadavg()[0],
                      "identical_to_first_run": cells == reference}
                runs.append(r)
                print(f"{name:6s} rep {rep}: {r['throughput']:.2f} img/s over the loop "
                      f"({r['images']} images, {r['items']} items, loop {r['loop_s']:.1f} s, "
                      f"start {r['start_s']:.1f} s), idle/item {r['idle_per_item_s'] * 1e3:.0f}"
                      f" ms, load {load:.2f}", flush=True)
    finally:
        ray.shutdown()
    best = {name: max((r for r in runs if r["config"] == name), key=lambda r: r["throughput"])
            for name, _, _ in CONFIGS}
    thr = {k: v["throughput"] for k, v in best.items()}
    summary = {
        "throughput_img_s": thr,
        "efficiency_2_workers_vs_ray_1": thr["ray-2"] / (2 * thr["ray-1"]),
        "efficiency_2_workers_vs_local": thr["ray-2"] / (2 * thr["local"]),
        "ray_1_vs_local": thr["ray-1"] / thr["local"],
        "ray_overhead_per_item_ms": {k: 1e3 * best[k]["idle_per_item_s"]
                                     for k in ("ray-1", "ray-2")},
        "ray_overhead_per_item_vs_local_ms": 1e3 * (1 / thr["ray-1"] - 1 / thr["local"])
        * best["ray-1"]["images"] / best["ray-1"]["items"],
        "per_image_ms_one_worker": 1e3 / thr["ray-1"],
        "ray_init_s": ray_start,
        "all_runs_identical": all(r["identical_to_first_run"] for r in runs),
        "load1_of_best_runs": {k: v["load1_before"] for k, v in best.items()},
        # CPU per image (less sensitive to other people's load than wall time): the work each
        # worker does per image,
        # and what the driver adds; min over the repeats
        "worker_cpu_ms_per_image": {k: min(r["worker_cpu_ms_per_image"] for r in runs
                                           if r["config"] == k) for k in best},
        "driver_cpu_ms_per_image": {k: min(r["driver_cpu_ms_per_image"] for r in runs
                                           if r["config"] == k) for k in best},
    }
    cpu = summary["worker_cpu_ms_per_image"]
    d2 = summary["driver_cpu_ms_per_image"]["ray-2"]
    # one worker is not one core: its prefetch thread decodes, transforms and JPEG-encodes the
    # next images while the network runs (fidelity.coco.detectors.Detector.detect_stream), so
    # it keeps cpu x throughput cores busy; what two workers and the driver can reach on this
    # machine's cores is cores / (c2 + d2) images per ms, and the run's fraction of that bound
    # says how much of the machine the Ray executor leaves unused
    cores = os.cpu_count() or 1
    summary["cores_busy_one_ray_worker"] = cpu["ray-1"] * thr["ray-1"] / 1e3
    summary["cpu_bound_img_s_2_workers"] = 1e3 * cores / (cpu["ray-2"] + d2)
    summary["fraction_of_cpu_bound_2_workers"] = (thr["ray-2"]
                                                  / summary["cpu_bound_img_s_2_workers"])
    return {"plan": {"model": "yolox_nano.onnx", "images": args.images,
                     "transforms": GRID[0], "targets": GRID[1], "cells": 5},
            "summary": summary, "runs": runs,
            "settings": {"repeats": args.repeats, "max_load": args.max_load,
                         "max_wait": args.max_wait}}


def cases(details: dict[str, Any]) -> list[Case]:
    if "stages" in details:
        return [case(f"stage {k.removesuffix('_ms').replace('_', ' ')} (one core)",
                     figures(k.removesuffix("_ms"), v / 1000), None, per="image",
                     statistic="best of 3 passes over 20 images")
                for k, v in details["stages"].items() if k.endswith("_ms")]
    s = details["summary"]
    thr, cpu = s["throughput_img_s"], s["worker_cpu_ms_per_image"]
    n = details["settings"]["repeats"]
    local = figures("local executor, 1 worker", 1 / thr["local"], cpu_s=cpu["local"] / 1000)
    return [case(f"Ray, {workers} worker{'s' if workers > 1 else ''}, against the local executor",
                 figures(f"ray executor, {workers} worker(s)", 1 / thr[name],
                         cpu_s=cpu[name] / 1000),
                 local, per="image",
                 statistic=(f"best of {n} runs (seconds per image over the driver loop; CPU: "
                            "the workers' own, the least of the runs)"),
                 note=(f"scaling efficiency at 2 workers {s['efficiency_2_workers_vs_ray_1']:.2f}"
                       f" against Ray with 1 worker" if workers == 2 else None))
            for name, workers in (("ray-1", 1), ("ray-2", 2))]


def report(result: dict[str, Any], folder: Path) -> None:
    """reports/scaleout/README.md from the results of both kinds (the runs, the stages)."""
    runs, stages = RESULTS / "scaleout.json", RESULTS / "scaleout_stages.json"
    docs = {}
    for path in (runs, stages):
        if path.is_file():
            doc = json.loads(path.read_text(encoding="utf-8"))
            docs["stages" if "stages" in doc["details"] else "runs"] = doc
    docs["stages" if "stages" in result["details"] else "runs"] = result
    if "runs" in docs:
        write_readme(folder, docs["runs"], docs.get("stages"))


def write_readme(out: Path, runs: dict[str, Any], stages: dict[str, Any] | None) -> None:
    """README.md in ``out`` from the result of the runs (and of the stages, if given)."""
    text = readme({**runs["details"], "machine": runs["machine"]})
    if stages is not None:
        st = stages["details"]["stages"]
        text += "\n".join([
            "Stages of a work item on one core (`--stages`, ms per image, best of 3 over 20 "
            f"images, load {st['load1_before']:.2f}): "
            + ", ".join(f"{k.removesuffix('_ms').replace('_', ' ')} {v:.1f}"
                        for k, v in st.items() if k.endswith("_ms")) + ".", ""])
    (out / "README.md").write_text(text)


def readme(result: dict[str, Any]) -> str:
    """reports/scaleout/README.md: the table of best runs and the summary, from the JSON."""
    s = result["summary"]
    m = result["machine"]
    plan = result["plan"]
    rows = []
    for name, _, workers in CONFIGS:
        runs = [r for r in result["runs"] if r["config"] == name]
        best = max(runs, key=lambda r: r["throughput"])
        every = ", ".join(f"{r['throughput']:.2f}" for r in runs)
        rows.append(f"| {name} | {workers} | {best['throughput']:.2f} | {every} | "
                    f"{best['start_s']:.1f} | {1e3 * best['idle_per_item_s']:.0f} | "
                    f"{best['load1_before']:.2f} |")
    return "\n".join([
        "# Scale-out of the COCO sweep (benchmarks/speed/scaleout.py)",
        "",
        f"Plan: {plan['model']}, {plan['images']} images, transforms "
        f"{', '.join(plan['transforms'])} at ΔE {', '.join(str(t) for t in plan['targets'])} "
        f"({plan['cells']} cells, {plan['cells'] * plan['images']} image-cells per run). "
        f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}. Throughput: images "
        "per second over the driver loop (transform, JPEG round trip, detector, store writes, "
        "scoring), best of the repeats; `start`: executor start and model registration; "
        "`idle/item`: worker time per work item not spent computing (Ray's overhead and "
        "the driver's latency); `load`: 1-minute load average before the best run (other "
        "people's jobs share the machine's cores).",
        "",
        "| executor | workers | img/s (best) | img/s (all runs) | start s | idle/item ms | load |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"- scaling efficiency at 2 workers, throughput(2) / (2 x throughput(1)): "
        f"**{s['efficiency_2_workers_vs_ray_1']:.2f}** against Ray with 1 worker, "
        f"{s['efficiency_2_workers_vs_local']:.2f} against the local executor",
        f"- Ray with 1 worker against the local executor: {s['ray_1_vs_local']:.2f}x",
        f"- Ray's overhead per work item (8 images): "
        f"{s['ray_overhead_per_item_ms']['ray-1']:.0f} ms idle time per item with 1 worker, "
        f"{s['ray_overhead_per_item_vs_local_ms']:.0f} ms per item from the throughputs "
        "(Ray 1 worker against local)",
        f"- one image through transform + JPEG + detector on one worker: "
        f"{s['per_image_ms_one_worker']:.1f} ms",
        f"- CPU per image (min over repeats; less sensitive to other people's load than wall "
        "time, not immune: contention slows a process's own CPU work too): worker "
        f"{s['worker_cpu_ms_per_image']['ray-1']:.1f} ms with 1 Ray worker, "
        f"{s['worker_cpu_ms_per_image']['ray-2']:.1f} ms with 2, "
        f"{s['worker_cpu_ms_per_image']['local']:.1f} ms local; the driver adds "
        f"{s['driver_cpu_ms_per_image']['ray-2']:.1f} ms (Ray, 2 workers), "
        f"{s['driver_cpu_ms_per_image']['local']:.1f} ms (local)",
        *([f"- one Ray worker keeps {s['cores_busy_one_ray_worker']:.2f} cores busy "
           "(worker CPU per image x its throughput: its prefetch thread decodes, transforms "
           "and JPEG-encodes the next images while the network runs), so on this machine "
           "throughput(2) cannot reach 2 x throughput(1); the CPU bound for two workers and "
           f"the driver, cores / (c2 + driver), is {s['cpu_bound_img_s_2_workers']:.1f} img/s "
           f"and Ray with 2 workers reaches **{s['fraction_of_cpu_bound_2_workers']:.2f}** of "
           "it"] if "cpu_bound_img_s_2_workers" in s else []),
        f"- every run's cells identical to the first run's: {s['all_runs_identical']}",
        "",
    ])

