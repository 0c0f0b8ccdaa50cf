"""This checkout against an earlier commit of it, as whole processes: the speed-up (or cost) of
a change, measured side by side so that a busy moment of the machine hits both alike.

The anchor is the package of the commit ``anchor`` (exported with ``git archive``: ``fidelity``
and the data folders it reads), run with ``python -m fidelity`` from that folder; this checkout
is run the same way from the repository. Command sets (``set``): ``startup``, ``fidelity audit
PHOTO.jpg --json F`` of :func:`benchmarks.speed.startup.make_photo`'s 12-megapixel photo and
``fidelity check`` with its default HTML + JSON report; ``validate``, a quick look with
``fidelity validate --limit 8`` (three cameras of ``cameras/``, YOLOX-nano; the shared data of
``$FIDELITY_SHARED``, default ``../shared``), each run from an empty store; ``reports``, the COCO
pipeline's three reports from committed data (:func:`report_commands`). Each is run
``repeats`` times per side, the sides alternating, after a warm-up run of each; the figures
are the median and best wall time and the median max RSS, the ratio that of the medians.

    python -m benchmarks.speed versions -p anchor=8913577 -p repeats=15
    python -m benchmarks.speed versions -p anchor=82d4032 -p set=validate -p repeats=5 \
        --out reports/benchmarks/versions_validate.json
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.machine import REPO
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter

ANCHOR = "the same commands with the package of an earlier commit (git archive), sides alternating"
PARAMETERS = {"anchor": Parameter(None, "the commit to compare this checkout with (required)"),
              "repeats": Parameter(15, "runs per side, alternating"),
              "set": Parameter("startup", "the commands: startup, validate or reports")}
QUICK = {"repeats": 1}
NEEDS = ("git",)


def export(rev: str, into: Path,
           folders: tuple[str, ...] = ("fidelity", "charts", "scenes", "cameras")) -> None:
    """The package and data ``folders`` of commit ``rev`` under ``into``."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev, *folders], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)


#: The cameras of the ``validate`` set (files of ``cameras/``).
VALIDATE_CAMERAS = ("ideal-srgb8", "bad-hue-rotation", "nikon5100-gamma22")


def commands(photo: Path, out: Path, which: str = "startup",
             shared: Path | None = None) -> dict[str, list[str]]:
    """Name -> command line of the set ``which`` (module docstring); ``out``: a scratch folder."""
    py = [sys.executable, "-m", "fidelity"]
    if which == "reports":
        return report_commands(out)
    if which == "validate":
        s = shared or Path(os.environ.get("FIDELITY_SHARED") or REPO.parent / "shared")
        cams = out / "cameras"
        cams.mkdir(exist_ok=True)
        for name in VALIDATE_CAMERAS:
            (cams / f"{name}.toml").write_bytes((REPO / "cameras" / f"{name}.toml").read_bytes())
        return {f"fidelity validate --limit 8 ({len(VALIDATE_CAMERAS)} cameras, YOLOX-nano)":
                [*py, "validate", "--cameras", str(cams), "--models",
                 str(s / "models" / "yolox_nano.onnx"), "--images", str(s / "coco" / "val2017"),
                 "--annotations", str(s / "coco" / "annotations" /
                                      "instances_val2017_subset.json"),
                 "--limit", "8", "--threads", "1", "--out", str(out / "validation"),
                 "--store", str(out / "store"), "--no-progress", "-q"]}
    return {"fidelity audit PHOTO.jpg --json F (12 MP)":
            [*py, "audit", str(photo), "-q", "--json", str(out / "audit.json")],
            "fidelity check (default HTML + JSON report)":
            [*py, "check", "-q", "--out", str(out / "check")]}


def report_commands(out: Path) -> dict[str, list[str]]:
    """The ``reports`` set: the COCO pipeline's three reports from committed data, no detector
    run: ``tables`` of the YOLOv8n re-sweep's scores file (no standard errors: those come
    from stored detections), ``validate --report-only`` of a store imported once from the
    validation's scores file, ``coco-c --report-only`` of the committed ``cococ.json``."""
    import shutil

    py = [sys.executable, "-m", "fidelity"]
    store = out / "vstore"
    if not store.exists():
        subprocess.run([*py, "validate", "--import-scores",
                        str(REPO / "reports/validation/validation.scores.json.gz"),
                        "--store", str(store), "-q"], check=True, cwd=REPO)
    (out / "cococ").mkdir(exist_ok=True)
    shutil.copyfile(REPO / "reports/cococ/cococ.json", out / "cococ" / "cococ.json")
    return {
        "fidelity tables SCORES --out DIR (YOLOv8n, 1000 images)": [
            *py, "tables", str(REPO / "reports/coco/resweep/yolov8n-int8dyn.scores.json.gz"),
            "--no-standard-errors", "--out", str(out / "tables"), "--no-progress", "-q"],
        "fidelity validate --report-only (30 cameras, 2 detectors)": [
            *py, "validate", "--cameras", str(REPO / "cameras"), "--store", str(store),
            "--report-only", "--notes", str(REPO / "reports/validation/analysis.md"),
            "--out", str(out / "validation"), "-q"],
        "fidelity coco-c --report-only": [*py, "coco-c", "--report-only", "--out",
                                          str(out / "cococ"), "-q"],
    }


def run(argv: list[str], source: Path) -> tuple[float, float]:
    """Wall seconds and max RSS (MB) of ``argv`` with the package of ``source``; every run
    starts afresh: a ``--store`` in ``argv`` is removed first (not one a ``--report-only``
    reads), and so is the report folder of ``tables`` (an earlier version refuses an existing
    one when reading a scores file)."""
    import shutil

    from benchmarks.speed.timing import run_process, user_environment

    if "--store" in argv and "--report-only" not in argv:
        shutil.rmtree(argv[argv.index("--store") + 1], ignore_errors=True)
    if "tables" in argv:
        shutil.rmtree(argv[argv.index("--out") + 1], ignore_errors=True)
    env = dict(user_environment(), PYTHONPATH=str(source))
    row = run_process(argv, env=env, cwd=source, digits=4)  # python -m puts the working folder first
    if row["exit"] not in (0, 1):
        raise RuntimeError(f"{argv} ({source}): exit {row['exit']}: {row['stderr']}")
    return float(row["seconds"]), float(row["max_rss_mb"])


def measure(ctx: Context) -> dict[str, Any]:
    from benchmarks.speed.startup import make_photo

    which, repeats = ctx["set"], ctx["repeats"]
    if not ctx["anchor"]:
        raise SystemExit("versions: give the commit to compare with, -p anchor=REV")
    if which not in ("startup", "validate", "reports"):
        raise SystemExit(f"versions: set {which!r}: startup, validate or reports")
    anchor = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", ctx["anchor"]],
                            check=True, capture_output=True, text=True).stdout.strip()
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                          check=True, capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "fidelity"],
                                check=True, capture_output=True, text=True).stdout.strip())
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "anchor"
        base.mkdir()
        export(anchor, base)
        photo = Path(tmp) / "photo.jpg"
        make_photo(photo)
        cmds = commands(photo, Path(tmp), which)
        sides = {"anchor": base, "this": REPO}
        times: dict[str, dict[str, list[tuple[float, float]]]] = {
            n: {s: [] for s in sides} for n in cmds}
        for cmd in cmds.values():  # warm the file cache and write the .pyc files once
            for src in sides.values():
                run(cmd, src)
        for _ in range(repeats):
            for name, cmd in cmds.items():
                for side, src in sides.items():
                    times[name][side].append(run(cmd, src))
    rows: list[dict[str, Any]] = []
    for name, t in times.items():
        row: dict[str, Any] = {"command": name}
        for side in sides:
            walls = [w for w, _ in t[side]]
            row[side] = {"median_s": round(statistics.median(walls), 3),
                         "min_s": round(min(walls), 3),
                         "max_rss_mb": round(statistics.median(m for _, m in t[side]), 1),
                         "runs_s": walls}
        row["ratio_of_medians"] = round(row["this"]["median_s"] / row["anchor"]["median_s"], 3)
        row["ratio_of_best"] = round(row["this"]["min_s"] / row["anchor"]["min_s"], 3)
        rows.append(row)
    return {"benchmark": "versions", "set": which, "anchor": anchor,
            "this": head + (" with uncommitted changes" if dirty else ""),
            "repeats": repeats, "rows": rows,
            "bytecode": "compiled .pyc files (PYTHONDONTWRITEBYTECODE unset)"}


def cases(details: dict[str, Any]) -> list[Case]:
    stat = f"median of {details['repeats']} processes per side, alternating"
    out = []
    for r in details["rows"]:
        sides = {side: figures(f"{r['command']} ({label})", r[side]["median_s"],
                               best_s=r[side]["min_s"], max_rss_mb=r[side]["max_rss_mb"],
                               runs_s=r[side].get("runs_s"))
                 for side, label in (("this", details["this"]),
                                     ("anchor", f"commit {details['anchor']}"))}
        out.append(case(r["command"], sides["this"], sides["anchor"], per="process",
                        statistic=stat, process=True))
    return out
