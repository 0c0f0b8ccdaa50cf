"""CUDA against CPU: ``fidelity evaluate`` of the same detectors on the same COCO images with
``--provider cpu`` and ``--provider cuda``, as whole processes, one after the other.

What it answers (issue 32): do the two execution providers give the same COCO mAP to the digits
the tool prints (4 decimals of a fraction: ``mAP 0.3119``), and how fast is each. Detections on
a GPU differ from the CPU's in the last bits of their boxes and scores (other kernels, other
orders of summation); the check is on the printed scores and on the number of detections.
Dynamically quantised (int8 ``ConvInteger``) models have no CUDA kernel for that operator in
onnxruntime (microsoft/onnxruntime#5127): those nodes run on the CPU inside a CUDA session.

    python -m benchmarks.speed providers -p models=M1.onnx,M2.onnx -p images=DIR \\
        -p annotations=A.json

Run where a CUDA device and ``onnxruntime-gpu`` are present (the device machine of the
workplace); on a machine without CUDA the ``cuda`` rows fail with the tool's own error.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter

ANCHOR = "fidelity evaluate of the same detectors on the same images with --provider cpu"
PARAMETERS = {"models": Parameter("", "comma-separated ONNX files (default: the shared models)"),
              "images": Parameter(None, "COCO images (default: the shared val2017)"),
              "annotations": Parameter(None, "COCO annotations (default: the shared subset)")}
NEEDS = ("shared", "cuda")

PROVIDERS = ("cpu", "cuda")


def evaluate(model: Path, images: Path, annotations: Path, provider: str, out: Path
             ) -> dict[str, Any]:
    """One ``fidelity evaluate`` process: its exit code, wall seconds and JSON report."""
    argv = [sys.executable, "-m", "fidelity", "evaluate", "--models", str(model), "--images",
            str(images), "--annotations", str(annotations), "--provider", provider,
            "--no-progress", "-q", "--json", str(out)]
    env = dict(os.environ, FIDELITY_CACHE=str(out.parent / f"cache-{out.stem}"))  # no reuse
    from benchmarks.speed.timing import run_process

    res = run_process(argv, env=env)
    row: dict[str, Any] = {"model": model.name, "provider": provider, "exit": res["exit"],
                           "wall_s": round(res["seconds"], 2), "max_rss_mb": res["max_rss_mb"]}
    if res["exit"]:
        row["stderr"] = res["stderr"]
        return row
    doc = json.loads(out.read_text(encoding="utf-8"))
    row.update(map=doc["map"], map50=doc["map50"], map75=doc["map75"], images=doc["images"],
               detections=doc["detections"], detect_s=round(doc["detect_seconds"], 2),
               sessions=doc["detector"]["providers"], ap=doc["ap"])
    return row


def compare(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per model: the CPU and CUDA scores side by side, equal to 4 decimals or not."""
    out = []
    for model in dict.fromkeys(r["model"] for r in rows):
        by = {r["provider"]: r for r in rows if r["model"] == model}
        cpu, cuda = by.get("cpu"), by.get("cuda")
        if not cpu or not cuda or cpu["exit"] or cuda["exit"]:
            out.append({"model": model, "compared": False})
            continue
        keys = ("map", "map50", "map75")
        ap_diff = max((abs(cpu["ap"][c] - cuda["ap"][c]) for c in cpu["ap"]
                       if cpu["ap"][c] is not None and cuda["ap"].get(c) is not None),
                      default=0.0)
        out.append({
            "model": model, "compared": True,
            "equal_to_printed_digits": all(f"{cpu[k]:.4f}" == f"{cuda[k]:.4f}" for k in keys),
            "abs_difference": {k: abs(cpu[k] - cuda[k]) for k in keys},
            "largest_class_ap_difference": ap_diff,
            "detections": {"cpu": cpu["detections"], "cuda": cuda["detections"]},
            "detect_speedup_cuda": round(cpu["detect_s"] / cuda["detect_s"], 2)
            if cuda["detect_s"] else None,
        })
    return out


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.core.resources import shared_dir

    shared = shared_dir()
    assert shared is not None
    models = ([Path(m) for m in ctx["models"].split(",") if m]
              or sorted((shared / "models").glob("*.onnx")))
    images = Path(ctx["images"] or shared / "coco" / "val2017")
    annotations = Path(ctx["annotations"] or
                       shared / "coco" / "annotations" / "instances_val2017_subset.json")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for model in models:
            for provider in PROVIDERS:
                row = evaluate(model, images, annotations, provider,
                               Path(tmp) / f"{model.stem}-{provider}.json")
                rows.append(row)
                ctx.log(f"{row['model']:<24} {provider:<5} exit {row['exit']}  "
                        + (f"mAP {row['map']:.4f}  {row['detections']} detections  detect "
                           f"{row['detect_s']} s  wall {row['wall_s']} s"
                           if not row["exit"] else row.get("stderr", "")))
    out: dict[str, Any] = {"benchmark": "providers", "images": str(images), "rows": rows,
                           "comparison": compare(rows)}
    try:
        import onnxruntime

        out["providers_available"] = onnxruntime.get_available_providers()
    except ImportError:
        pass
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader"],
                         capture_output=True, text=True, check=False) if _has("nvidia-smi") else None
    if gpu is not None and gpu.returncode == 0:
        out["gpu"] = gpu.stdout.strip()
    return out


def _run_cases(run: dict[str, Any], tag: str) -> list[Case]:
    out = []
    for model in dict.fromkeys(r["model"] for r in run["rows"]):
        by = {r["provider"]: r for r in run["rows"] if r["model"] == model}
        cpu, cuda = by.get("cpu"), by.get("cuda")
        if not cpu or not cuda or cpu["exit"] or cuda["exit"]:
            continue
        comparison = next((c for c in run.get("comparison", ()) if c["model"] == model), {})
        note = (f"mAP {cuda['map']:.4f} against {cpu['map']:.4f}, {cuda['detections']} "
                f"detections against {cpu['detections']}; equal to the printed digits: "
                f"{comparison.get('equal_to_printed_digits')}")
        for what, key in (("the whole process", "wall_s"), ("the detection loop", "detect_s")):
            out.append(case(f"{model}{tag}: {what}",
                            figures("--provider cuda", cuda[key],
                                    max_rss_mb=cuda.get("max_rss_mb") if key == "wall_s" else None),
                            figures("--provider cpu", cpu[key],
                                    max_rss_mb=cpu.get("max_rss_mb") if key == "wall_s" else None),
                            per="run", statistic="one run each, one after the other",
                            process=key == "wall_s", note=note))
    return out


def cases(details: dict[str, Any]) -> list[Case]:
    if "runs" in details:  # several runs recorded together (e.g. CUDA settings)
        return [c for tag, run in details["runs"].items() for c in _run_cases(run, f" ({tag})")]
    return _run_cases(details, "")


def _has(cmd: str) -> bool:
    from shutil import which

    return which(cmd) is not None

