"""``fidelity dataset --transforms pull_mean`` as whole processes: its marginal time per image
against the JPEG decode + re-encode floor (issue 30, requirement 6).

Two folders of COCO val2017 photos (links to the first ``small`` and ``large`` JPEGs of
``$FIDELITY_SHARED/coco/val2017``, or ``coco``) are written by whole processes, one after the
other in the same run: ``floor`` (the anchor), ``python -m fidelity dataset --transforms
pull_mean --targets 0``, the baseline subset, every photo decoded and re-encoded with its own
quantisation tables, nothing else; ``pull_mean``, ``python -m fidelity dataset --transforms
pull_mean --targets 3``; each with the default workers (one per core) and with ``--workers 1``.
The marginal time per image is ``(T_large - T_small) / (large - small)`` (the start-up, the
imports, the pool and the numba kernels cancel), quoted as its ratio to the floor's, in wall
time and in CPU time (of the process and its workers: less sensitive to other jobs on the
machine); the fixed cost is ``T_small`` minus ``small`` marginal times. Each process is run
``repeats`` times, the fastest kept (other jobs share the machine). The checkout's own runs
are repeated with the numba kernel forced (``FIDELITY_PULL_MEAN_KERNEL=numba``; a run of fewer
than :data:`fidelity.coco.dataset.NUMBA_MIN_IMAGES` photos takes the numpy kernel by itself).
``source`` runs the same with the ``fidelity`` package of another checkout (before/after in one
run).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.machine import REPO as ROOT
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import run_process

ANCHOR = ("the baseline subset (fidelity dataset --targets 0: decode + re-encode), whole "
          "processes; marginal time per image")
PARAMETERS = {"coco": Parameter(None, "folder of COCO JPEGs (default: the shared val2017)"),
              "small": Parameter(8, "photos in the small folder"),
              "large": Parameter(48, "photos in the large folder"),
              "repeats": Parameter(2, "runs of each process, the fastest kept"),
              "source": Parameter(None, "another checkout whose fidelity package runs too"),
              "label": Parameter("before", "name of source's runs")}
QUICK = {"small": 2, "large": 4, "repeats": 1}
NEEDS = ("shared",)


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


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.pipeline.environment import available_cpus

    small, large, repeats = ctx["small"], ctx["large"], ctx["repeats"]
    coco = coco_folder(Path(ctx["coco"]) if ctx["coco"] else None)
    photos = sorted(coco.glob("*.jpg"))[:large]
    if len(photos) < large:
        raise SystemExit(f"dataset: need {large} JPEGs in {coco} (found {len(photos)})")
    sources: list[tuple[str, Path, str | None]] = [("this checkout", ROOT, None),
                                                    ("this checkout, numba", ROOT, "numba")]
    if ctx["source"]:
        sources.append((ctx["label"], Path(ctx["source"]), None))
    rows: list[dict[str, Any]] = []
    summary: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-dataset-") as tmp:
        folders = {}
        for n in (small, large):
            folder = Path(tmp) / f"images-{n}"
            folder.mkdir()
            for p in photos[:n]:
                (folder / p.name).symlink_to(p)
            folders[n] = folder
        for label, source, kernel in sources:
            for workers in (None, 1):
                times: dict[tuple[str, int], float] = {}
                cpu: dict[tuple[str, int], float] = {}
                for target, subset in (("0", "floor"), ("3", "pull_mean")):
                    for n, folder in folders.items():
                        row = dataset_run(source, folder, Path(tmp) / "out", target, workers,
                                          repeats, kernel)
                        times[(subset, n)] = row["seconds"]
                        cpu[(subset, n)] = row["cpu_seconds"]
                        rows.append({"source": label, "workers": workers or available_cpus(),
                                     "default_workers": workers is None, "subset": subset,
                                     "images": n, **row})
                        ctx.log(f"{label:>21s} {workers or 'default':>8} {subset:>10s} "
                                f"{n:>6d} {row['seconds']:>7.2f} s")
                span = large - small
                marginal = {k: (times[(k, large)] - times[(k, small)]) / span
                            for k in ("floor", "pull_mean")}
                fixed = {k: times[(k, small)] - small * marginal[k]
                         for k in ("floor", "pull_mean")}
                marginal_cpu = {k: (cpu[(k, large)] - cpu[(k, small)]) / span
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
                    f"seconds_for_{small}_images": {k: times[(k, small)]
                                                    for k in ("floor", "pull_mean")},
                }
    return {"benchmark": "fidelity dataset --transforms pull_mean, whole processes, marginal "
                         "time per image against the decode + re-encode floor",
            "small": small, "large": large, "repeats": repeats, "summary": summary,
            "rows": rows}


def cases(details: dict[str, Any]) -> list[Case]:
    repeats = details.get("repeats")
    best = f"best of {repeats}" if repeats else "best of N (N not recorded)"
    out = []
    for key, s in details["summary"].items():
        m, c = s["marginal_ms_per_image"], s["marginal_cpu_ms_per_image"]
        out.append(case(
            f"marginal time per image, {key}",
            figures("pull_mean", m["pull_mean"] / 1000, cpu_s=c["pull_mean"] / 1000),
            figures("floor (decode + re-encode)", m["floor"] / 1000, cpu_s=c["floor"] / 1000),
            per="image", statistic=f"(T_large - T_small) / (large - small), each T the {best}",
            process=True))
    rows = details["rows"]
    for r in rows:
        if r["subset"] != "pull_mean":
            continue
        floor = next(f for f in rows if f["subset"] == "floor" and f["source"] == r["source"]
                     and f["default_workers"] == r["default_workers"]
                     and f["images"] == r["images"])
        workers = "default workers" if r["default_workers"] else "--workers 1"

        def fig(row: dict[str, Any], label: str) -> Any:
            return figures(label, row["seconds"], cpu_s=row["cpu_seconds"],
                           max_rss_mb=row["max_rss_mb"], exit=row["exit"])

        out.append(case(f"{r['images']} photos, {r['source']}, {workers}",
                        fig(r, "fidelity dataset --transforms pull_mean --targets 3"),
                        fig(floor, "fidelity dataset --transforms pull_mean --targets 0"),
                        per="process", statistic=best, process=True))
    return out
