"""`fidelity evaluate`'s detection loop against the bare onnxruntime floor, per model and stage.

For each model, on the same N shared COCO images, timed in one run (best of ``repeats``,
the floor and the loops interleaved so that they see the same machine load):

* floor: ``session.run`` alone on model inputs prepared beforehand (the network, nothing else);
* stream: what ``fidelity evaluate`` runs, ``Detector.detect_stream`` from the JPEG files
  (read + decode + preprocess on a worker thread ahead of the network, decode/NMS behind it);
* serial: the same four steps one after the other on one thread (no overlap);
* stages: read + decode (Pillow), preprocess (:meth:`Detector.prepare`), network, decode/NMS
  (:meth:`Detector.finish`), each alone; and COCO scoring of the N images (faster-coco-eval).

Each is timed in wall clock and in CPU time (the calling thread's and the process's). With one
onnxruntime intra-op thread the network runs on the calling thread, so in the streamed loop the
main thread's CPU time is the network plus the loop's own work, and the rest of the process's
CPU time is the worker thread's (decode, preprocess, NMS). On a machine with a core free for
the worker the loop runs at max(main, worker) / floor ("idle" ratio); the wall ratio is what
this machine gave as loaded by whatever else ran (best of N, interleaved).

Requirement (issue 24): stream <= 1.2x the floor for every model.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter

ANCHOR = "the bare onnxruntime session.run on model inputs prepared beforehand (the floor)"
PARAMETERS = {"images": Parameter(60, "shared COCO images"),
              "repeats": Parameter(5, "best of N, the floor and the loops interleaved"),
              "threads": Parameter(1, "onnxruntime intra-op threads"),
              "models": Parameter("", "comma-separated model stems (default: all shared)"),
              "note": Parameter("", "conditions to record with the machine")}
QUICK = {"images": 4, "repeats": 1, "models": "yolox_nano"}
NEEDS = ("shared", "onnxruntime")

REQUIREMENT = 1.2


def per_image(fn: Callable[[], object], n: int) -> tuple[float, float, float]:
    """(wall, calling thread's CPU, process CPU) of one call of ``fn``, ms per image."""
    w, c, p = time.perf_counter(), time.thread_time(), time.process_time()
    fn()
    return (1000 * (time.perf_counter() - w) / n, 1000 * (time.thread_time() - c) / n,
            1000 * (time.process_time() - p) / n)


def bench_model(path: Path, files: list[Path], threads: int, repeats: int,
                coco: Any, ids: list[int]) -> dict[str, Any]:
    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import read_jpeg
    from fidelity.coco.scoring import evaluate_detections, resolve_scorer

    det = Detector(path, threads=threads, provider="cpu")
    n = len(files)
    rgbs = [read_jpeg(f)[0] for f in files]
    prepared = [det.prepare(im) for im in rgbs]
    outs = det.infer([p.tensor for p in prepared])
    sess, name_in, name_out = det.session, det.layout.input_name, det.layout.output_name
    inputs = [p.tensor[None] for p in prepared]

    def floor() -> None:
        for x in inputs:
            sess.run([name_out], {name_in: x})

    def load(f: Path) -> np.ndarray:
        return read_jpeg(f)[0]

    def stream() -> None:
        for _ in det.detect_stream(files, load):
            pass

    def serial() -> None:
        for f in files:
            det(load(f))

    stages: dict[str, Callable[[], object]] = {
        "decode": lambda: [load(f) for f in files],
        "preprocess": lambda: [det.prepare(im) for im in rgbs],
        "network": floor,
        "postprocess": lambda: [det.finish(o, p) for o, p in zip(outs, prepared, strict=True)],
    }
    dets = {i: det.finish(o, p) for i, o, p in zip(ids, outs, prepared, strict=True)}
    method = resolve_scorer("auto")
    stages["scoring"] = lambda: evaluate_detections(coco, dets, ids, method=method)
    floor()  # warm up
    best: dict[str, list[float]] = {}
    for _ in range(repeats):  # interleaved: the three see the same machine
        for key, fn in (("floor", floor), ("stream", stream), ("serial", serial)):
            t = per_image(fn, n)
            best[key] = [min(a, b) for a, b in zip(best.get(key, [float("inf")] * 3), t,
                                                    strict=True)]
    stage_cpu = {k: min(per_image(fn, n)[2] for _ in range(repeats))
                 for k, fn in stages.items()}
    floor_cpu = best["floor"][2]
    main_cpu = best["stream"][1]  # network (1 intra-op thread runs on the caller) + loop
    worker_cpu = max(best["stream"][2] - best["stream"][1], 0.0)
    idle_ratio = max(main_cpu, worker_cpu) / floor_cpu
    return {
        "model": det.name, "layout": det.layout.kind, "input_size": list(det.layout.input_size),
        "batch": det.batch, "images": n,
        "wall_ms": {k: v[0] for k, v in best.items()},
        "cpu_ms": {k: v[2] for k, v in best.items()},
        "stream_main_thread_cpu_ms": main_cpu, "stream_worker_cpu_ms": worker_cpu,
        "wall_ratio": best["stream"][0] / best["floor"][0],
        "serial_wall_ratio": best["serial"][0] / best["floor"][0],
        "serial_cpu_ratio": best["serial"][2] / floor_cpu,
        "critical_path_ratio": main_cpu / floor_cpu,
        "idle_machine_ratio": idle_ratio,
        "stages_cpu_ms": stage_cpu, "scorer": method,
        "with_scoring_idle_machine_ratio": (max(main_cpu, worker_cpu) + stage_cpu["scoring"])
        / floor_cpu,
        "ok_wall": best["stream"][0] / best["floor"][0] <= REQUIREMENT,
        "ok_idle_machine": idle_ratio <= REQUIREMENT,
    }


def measure(ctx: Context) -> dict[str, Any]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    from fidelity.coco.scoring import load_annotations
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    if shared is None:
        raise SystemExit("evaluate: ../shared (COCO images, models) not present")
    coco = load_annotations(shared / "coco/annotations/instances_val2017_subset.json")
    ids = sorted(coco.getImgIds())[: ctx["images"]]
    files = [shared / "coco/val2017" / coco.imgs[i]["file_name"] for i in ids]
    wanted = [m for m in ctx["models"].split(",") if m]
    models = [p for p in sorted((shared / "models").glob("*.onnx"))
              if not wanted or p.stem in wanted]
    if not models:
        raise SystemExit(f"evaluate: no model {wanted} in {shared / 'models'}")
    rows = [bench_model(path, files, ctx["threads"], ctx["repeats"], coco, ids)
            for path in models]
    return {"models": rows, "images": len(ids), "threads": ctx["threads"],
            "repeats": ctx["repeats"], "requirement_ratio": REQUIREMENT,
            "all_ok_wall": all(r["ok_wall"] for r in rows),
            "all_ok_idle_machine": all(r["ok_idle_machine"] for r in rows),
            "note": ctx["note"]}


def cases(details: dict[str, Any]) -> list[Case]:
    stat = (f"best of {details['repeats']}, interleaved, over {details['images']} images; "
            f"{details['threads']} onnxruntime thread(s)")
    out = []
    for r in details["models"]:
        w, c = r["wall_ms"], r["cpu_ms"]
        floor = figures("session.run alone", w["floor"] / 1000, cpu_s=c["floor"] / 1000)
        out.append(case(f"{r['model']}: the streamed loop (fidelity evaluate)",
                        figures("Detector.detect_stream from the JPEG files", w["stream"] / 1000,
                                cpu_s=c["stream"] / 1000),
                        floor, per="image", statistic=stat, target_s=None,
                        note=(f"requirement: at most {details['requirement_ratio']}x the floor; "
                              f"on a machine with a core free for the worker "
                              f"{r['idle_machine_ratio']:.3f}x")))
        out.append(case(f"{r['model']}: the same steps on one thread",
                        figures("read, preprocess, network, NMS one after the other",
                                w["serial"] / 1000, cpu_s=c["serial"] / 1000),
                        floor, per="image", statistic=stat))
    return out
