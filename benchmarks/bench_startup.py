"""Start-up time of the command line against the Python interpreter's own (``python -c pass``).

Each command is run as a fresh process, ``--repeats`` times, interleaved (so a busy moment of
the machine hits every command alike); the result is the median wall time, the time above the
interpreter's and the median max RSS of the process (through ``bench_memory``'s launcher).
Targets: ``fidelity --help`` under 0.5 s, ``fidelity predict --delta-e 3`` under 1 s (issue
22); ``fidelity check`` with its default HTML + JSON report under 1.0 s and ``fidelity audit
PHOTO.jpg --json F`` of a 12-megapixel chart photo under 0.9 s, the anchor there being OpenCV's
mcc detector as a whole Python process on the same photo (issue 30).

    python -m benchmarks.bench_startup --repeats 15     # -> reports/benchmarks/startup.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.machine import machine_info

#: A whole Python process that finds the chart with OpenCV's mcc detector (the anchor of the
#: audit): read the photo, detect one Classic chart, print its centre count.
MCC = ("import sys, cv2\n"
       "img = cv2.imread(sys.argv[1])\n"
       "d = cv2.mcc.CCheckerDetector_create()\n"
       "ok = d.process(img, cv2.mcc.MCC24, 1)\n"
       "print(len(d.getListColorChecker()) if ok else 0)\n")


def commands(photo: Path, out: Path) -> dict[str, list[str]]:
    """Name -> command line; ``python -c pass`` is the anchor of start-up, the mcc process
    the anchor of the audit."""
    fidelity = shutil.which("fidelity") or "fidelity"
    return {
        "python -c pass": [sys.executable, "-c", "pass"],
        "python -c 'import fidelity'": [sys.executable, "-c", "import fidelity"],
        "fidelity --help": [fidelity, "--help"],
        "fidelity predict --delta-e 3": [fidelity, "predict", "--delta-e", "3"],
        "fidelity check (closed form, no report)": [fidelity, "check", "--no-report", "-q"],
        "fidelity check (default HTML + JSON report)": [fidelity, "check", "-q", "--out",
                                                        str(out / "check")],
        "OpenCV mcc on the 12 MP photo (python process)": [sys.executable, "-c", MCC,
                                                           str(photo)],
        "fidelity audit PHOTO.jpg --json F (12 MP)": [fidelity, "audit", str(photo), "-q",
                                                      "--json", str(out / "audit.json")],
    }


#: Targets in seconds (issues 22 and 30).
TARGETS = {"fidelity --help": 0.5, "fidelity predict --delta-e 3": 1.0,
           "fidelity check (default HTML + JSON report)": 1.0,
           "fidelity audit PHOTO.jpg --json F (12 MP)": 0.9}
#: Each row's anchor (the ratio column): the interpreter, or mcc for the audit.
ANCHORS = {"fidelity audit PHOTO.jpg --json F (12 MP)":
           "OpenCV mcc on the 12 MP photo (python process)"}


def user_environment() -> dict[str, str]:
    """The environment of the runs: this one without ``PYTHONDONTWRITEBYTECODE``, so that the
    modules run from their compiled ``.pyc`` files, as after ``pip install`` (which compiles
    them) or any earlier run; with the variable set, every process compiles fidelity's modules
    from source again (about 0.4 s of each ``check``)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def run_once(argv: list[str], cwd: str) -> tuple[float, float]:
    """Wall seconds and max RSS (MB) of one run of ``argv`` (it must exit 0 or 1)."""
    from benchmarks.bench_memory import run_process

    row = run_process(argv, env=user_environment(), cwd=Path(cwd))
    if row["exit"] not in (0, 1):
        raise RuntimeError(f"{argv}: exit {row['exit']}: {row['stderr']}")
    return float(row["seconds"]), float(row["max_rss_mb"])


def make_photo(path: Path) -> None:
    """A 4000 x 3000 JPEG: a COCO-like scene with the chart on it (bench_memory's photo)."""
    from benchmarks.bench_memory import photo, write_image

    write_image(path, photo(4000, 3000, seed=3))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--out", type=Path, default=Path("reports/benchmarks/startup.json"))
    args = ap.parse_args(argv)
    if shutil.which("fidelity") is None:
        print("the fidelity command is not on PATH (pip install -e .)", file=sys.stderr)
        return 2
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as cwd:  # no settings file is found from here
        photo = Path(cwd) / "photo.jpg"
        make_photo(photo)
        cmds = commands(photo, Path(cwd))
        times: dict[str, list[float]] = {name: [] for name in cmds}
        rss: dict[str, list[float]] = {name: [] for name in cmds}
        for cmd in cmds.values():  # warm the file cache (and write the .pyc files) once
            run_once(cmd, cwd)
        for _ in range(args.repeats):
            for name, cmd in cmds.items():
                t, m = run_once(cmd, cwd)
                times[name].append(t)
                rss[name].append(m)
    medians = {name: statistics.median(ts) for name, ts in times.items()}
    anchor = medians["python -c pass"]
    rows = []
    for name, ts in times.items():
        median = medians[name]
        row: dict[str, object] = {
            "command": name, "median_s": round(median, 4), "min_s": round(min(ts), 4),
            "above_python_s": round(median - anchor, 4),
            "ratio_to_python": round(median / anchor, 2),
            "max_rss_mb": round(statistics.median(rss[name]), 1)}
        other = ANCHORS.get(name)
        if other:
            row["anchor"] = other
            row["ratio_to_anchor"] = round(median / medians[other], 2)
        if name in TARGETS:
            row["target_s"] = TARGETS[name]
            row["meets_target"] = median < TARGETS[name]
        rows.append(row)
        ratio = (f"{median / medians[other]:5.2f}x mcc" if other else
                 f"{median / anchor:5.2f}x python -c pass")
        print(f"{name:<48} median {median * 1000:7.1f} ms  min {min(ts) * 1000:7.1f} ms  "
              f"{ratio}  max RSS {row['max_rss_mb']} MB"
              + (f"  (target {TARGETS[name]:g} s: {'met' if median < TARGETS[name] else 'MISSED'})"
                 if name in TARGETS else ""))
    result = {"benchmark": "startup", "repeats": args.repeats, "rows": rows,
              "load_average_at_start": round(load, 2), "machine": machine_info(),
              "bytecode": "compiled .pyc files (PYTHONDONTWRITEBYTECODE unset), as installed",
              "date": time.strftime("%Y-%m-%d")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
