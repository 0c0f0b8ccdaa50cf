"""Benchmark: ``fidelity dataset --transforms pull_mean`` as whole processes, its marginal time
per image against the JPEG decode + re-encode floor (issue 30, requirement 6).

Two folders of COCO val2017 photos (links to the first ``--small`` and ``--large`` JPEGs of
``$FIDELITY_SHARED/coco/val2017``, or ``--coco``) are written by whole processes, one after the
other in the same run:

``floor`` (the anchor)
    ``python -m fidelity dataset --transforms pull_mean --targets 0``: the baseline subset,
    every photo decoded and re-encoded with its own quantisation tables, nothing else;
``pull_mean``
    ``python -m fidelity dataset --transforms pull_mean --targets 3``.

each with the default workers (one per core) and with ``--workers 1``. The marginal time per
image is ``(T_large - T_small) / (large - small)`` (the start-up, the imports, the pool and the
numba kernels cancel), quoted as its ratio to the floor's, in wall time and in CPU time (of the
process and its workers: less sensitive to other jobs on the machine); the fixed cost is ``T_small`` minus
``small`` marginal times. Each process is run ``--repeats`` times, the fastest kept (other jobs
share the machine). The checkout's own runs are repeated with the numba kernel forced
(``FIDELITY_PULL_MEAN_KERNEL=numba``; a run of fewer than
:data:`fidelity.coco.dataset.NUMBA_MIN_IMAGES` photos takes the numpy kernel by itself).
``--source DIR`` runs the same with the ``fidelity`` package of another checkout (before/after
in one run). Writes reports/benchmarks/dataset.json. Run:
python -m benchmarks.bench_dataset [--source /work/main]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.bench_memory import run_process

ROOT = Path(__file__).resolve().parents[1]


def coco_folder(given: Path | None) -> Path:
    """The COCO val2017 photos: ``given``, else under $FIDELITY_SHARED or ../shared."""
    if given is not None:
        return given
    shared = Path(os.environ.get("FIDELITY_SHARED", ROOT.parent / "shared"))
    return shared / "coco" / "val2017"


def dataset_run(source: Path, images: Path, out: Path, target: str, workers: int | None,
                repeats: int, kernel: str | None = None) -> dict[str, Any]:
    """The fastest of ``repeats`` whole ``fidelity dataset`` processes (fresh output each);
    ``kernel``: the pull_mean kernel forced (``FIDELITY_PULL_MEAN_KERNEL``)."""
    env = {k: v for k, v in os.environ.items() if k != "FIDELITY_PULL_MEAN_KERNEL"}
    env["PYTHONPATH"] = str(source)
    if kernel is not None:
        env["FIDELITY_PULL_MEAN_KERNEL"] = kernel
    args = [sys.executable, "-m", "fidelity", "dataset", "--images", str(images), "--out",
            str(out), "--transforms", "pull_mean", "--targets", target, "--no-progress"]
    if workers is not None:
        args += ["--workers", str(workers)]
    best: dict[str, Any] | None = None
    for _ in range(repeats):
        shutil.rmtree(out, ignore_errors=True)
        row = run_process(args, env, cwd=source)
        if row["exit"] != 0:
            raise RuntimeError(f"{' '.join(args)}: exit {row['exit']}: {row['stderr']}")
        if best is None or row["seconds"] < best["seconds"]:
            best = row
    assert best is not None
    return best


def main() -> int:
    from benchmarks.machine import machine_info
    from fidelity.core.fileio import write_json_atomic
    from fidelity.pipeline.environment import available_cpus

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--coco", type=Path, default=None, help="Folder of COCO JPEGs.")
    ap.add_argument("--small", type=int, default=8, help="Photos in the small folder.")
    ap.add_argument("--large", type=int, default=48, help="Photos in the large folder.")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--source", type=Path, default=None,
                    help="Another checkout whose fidelity package is run too (before).")
    ap.add_argument("--label", default="before", help="Name of --source's runs.")
    ap.add_argument("--out", type=Path, default=ROOT / "reports/benchmarks/dataset.json")
    args = ap.parse_args()
    coco = coco_folder(args.coco)
    photos = sorted(coco.glob("*.jpg"))[:args.large]
    if len(photos) < args.large:
        sys.exit(f"bench_dataset: need {args.large} JPEGs in {coco} (found {len(photos)})")
    sources: list[tuple[str, Path, str | None]] = [("this checkout", ROOT, None),
                                                    ("this checkout, numba", ROOT, "numba")]
    if args.source is not None:
        sources.append((args.label, args.source, None))
    rows: list[dict[str, Any]] = []
    summary: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-dataset-") as tmp:
        folders = {}
        for n in (args.small, args.large):
            folder = Path(tmp) / f"images-{n}"
            folder.mkdir()
            for p in photos[:n]:
                (folder / p.name).symlink_to(p)
            folders[n] = folder
        print(f"{'source':>21s} {'workers':>8s} {'subset':>10s} {'images':>6s} {'s':>7s}")
        for label, source, kernel in sources:
            for workers in (None, 1):
                times: dict[tuple[str, int], float] = {}
                cpu: dict[tuple[str, int], float] = {}
                for target, subset in (("0", "floor"), ("3", "pull_mean")):
                    for n, folder in folders.items():
                        row = dataset_run(source, folder, Path(tmp) / "out", target, workers,
                                          args.repeats, kernel)
                        times[(subset, n)] = row["seconds"]
                        cpu[(subset, n)] = row["cpu_seconds"]
                        rows.append({"source": label, "workers": workers or available_cpus(),
                                     "default_workers": workers is None, "subset": subset,
                                     "images": n, **row})
                        print(f"{label:>21s} {workers or 'default':>8} {subset:>10s} {n:>6d} "
                              f"{row['seconds']:>7.2f}", flush=True)
                span = args.large - args.small
                marginal = {k: (times[(k, args.large)] - times[(k, args.small)]) / span
                            for k in ("floor", "pull_mean")}
                fixed = {k: times[(k, args.small)] - args.small * marginal[k]
                         for k in ("floor", "pull_mean")}
                marginal_cpu = {k: (cpu[(k, args.large)] - cpu[(k, args.small)]) / span
                                for k in ("floor", "pull_mean")}
                key = f"{label}, {'default workers' if workers is None else '--workers 1'}"
                summary[key] = {
                    "workers": workers or available_cpus(),
                    "marginal_ms_per_image": {k: 1000 * v for k, v in marginal.items()},
                    "fixed_seconds": fixed,
                    "pull_mean_marginal_ratio_to_floor": marginal["pull_mean"] / marginal["floor"],
                    "marginal_cpu_ms_per_image": {k: 1000 * v for k, v in marginal_cpu.items()},
                    "pull_mean_marginal_cpu_ratio_to_floor": (marginal_cpu["pull_mean"]
                                                              / marginal_cpu["floor"]),
                    f"seconds_for_{args.small}_images": {k: times[(k, args.small)]
                                                         for k in ("floor", "pull_mean")},
                }
    print()
    for key, s in summary.items():
        m = s["marginal_ms_per_image"]
        print(f"{key:>40s}: pull_mean {m['pull_mean']:6.1f} ms/image, floor "
              f"{m['floor']:6.1f} ms/image: {s['pull_mean_marginal_ratio_to_floor']:.2f}x "
              f"(CPU {s['pull_mean_marginal_cpu_ratio_to_floor']:.2f}x); "
              f"fixed {s['fixed_seconds']['pull_mean']:.2f} s (floor "
              f"{s['fixed_seconds']['floor']:.2f} s)")
    write_json_atomic(args.out, {
        "benchmark": "fidelity dataset --transforms pull_mean, whole processes, marginal time "
                     "per image against the decode + re-encode floor",
        "method": (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "date": time.strftime("%Y-%m-%d"), "small": args.small, "large": args.large,
        "summary": summary, "rows": rows, "machine": machine_info()})
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
