"""CUDA against CPU: ``fidelity evaluate`` of the same detectors on the same COCO images with
``--provider cpu`` and ``--provider cuda``, as whole processes, one after the other.

What it answers (issue 32): do the two execution providers give the same COCO mAP to the digits
the tool prints (4 decimals of a fraction: ``mAP 0.3119``), and how fast is each. Detections on
a GPU differ from the CPU's in the last bits of their boxes and scores (other kernels, other
orders of summation); the check is on the printed scores and on the number of detections.
Dynamically quantised (int8 ``ConvInteger``) models have no CUDA kernel for that operator in
onnxruntime (microsoft/onnxruntime#5127): those nodes run on the CPU inside a CUDA session.

    python -m benchmarks.bench_providers --models M1.onnx,M2.onnx --images DIR \\
        --annotations A.json --json reports/coco/providers.json

Run where a CUDA device and ``onnxruntime-gpu`` are present (the device machine of the
workplace); on a machine without CUDA the ``cuda`` rows fail with the tool's own error.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

PROVIDERS = ("cpu", "cuda")


def evaluate(model: Path, images: Path, annotations: Path, provider: str, out: Path
             ) -> dict[str, Any]:
    """One ``fidelity evaluate`` process: its exit code, wall seconds and JSON report."""
    argv = [sys.executable, "-m", "fidelity", "evaluate", "--models", str(model), "--images",
            str(images), "--annotations", str(annotations), "--provider", provider,
            "--no-progress", "-q", "--json", str(out)]
    env = dict(os.environ, FIDELITY_CACHE=str(out.parent / f"cache-{out.stem}"))  # no reuse
    t0 = time.perf_counter()
    res = subprocess.run(argv, capture_output=True, text=True, check=False, env=env)
    wall = time.perf_counter() - t0
    row: dict[str, Any] = {"model": model.name, "provider": provider, "exit": res.returncode,
                           "wall_s": round(wall, 2)}
    if res.returncode:
        row["stderr"] = res.stderr.strip()[-2000:]
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", required=True, help="comma-separated ONNX files")
    ap.add_argument("--images", type=Path, required=True)
    ap.add_argument("--annotations", type=Path, required=True)
    ap.add_argument("--json", type=Path, default=Path("reports/coco/providers.json"))
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for model in (Path(m) for m in args.models.split(",")):
            for provider in PROVIDERS:
                row = evaluate(model, args.images, args.annotations, provider,
                               Path(tmp) / f"{model.stem}-{provider}.json")
                rows.append(row)
                print(f"{row['model']:<24} {provider:<5} exit {row['exit']}  "
                      + (f"mAP {row['map']:.4f}  mAP50 {row['map50']:.4f}  "
                         f"{row['detections']} detections  detect {row['detect_s']} s  "
                         f"wall {row['wall_s']} s  sessions {row['sessions']}"
                         if not row["exit"] else row.get("stderr", "")), flush=True)
    import platform

    machine = {"platform": platform.platform(), "python": platform.python_version(),
               "cpu_count": os.cpu_count()}
    try:
        import onnxruntime

        machine["onnxruntime"] = onnxruntime.__version__
        machine["providers_available"] = onnxruntime.get_available_providers()
    except ImportError:
        pass
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader"],
                         capture_output=True, text=True, check=False) if _has("nvidia-smi") else None
    if gpu is not None and gpu.returncode == 0:
        machine["gpu"] = gpu.stdout.strip()
    result = {"benchmark": "providers", "date": time.strftime("%Y-%m-%d %H:%M"),
              "machine": machine, "images": str(args.images), "rows": rows,
              "comparison": compare(rows)}
    for c in result["comparison"]:
        print(json.dumps(c))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.json}")
    return 0


def _has(cmd: str) -> bool:
    from shutil import which

    return which(cmd) is not None


if __name__ == "__main__":
    raise SystemExit(main())
