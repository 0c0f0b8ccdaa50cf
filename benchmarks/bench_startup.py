"""Start-up time of the command line against the Python interpreter's own (``python -c pass``).

Each command is run as a fresh process, ``--repeats`` times, interleaved (so a busy moment of
the machine hits every command alike); the result is the median wall time and the time above
the interpreter's. Targets (issue 22): ``fidelity --help`` under 0.5 s, ``fidelity predict
--delta-e 3`` under 1 s.

    python -m benchmarks.bench_startup --repeats 15     # -> reports/benchmarks/startup.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.machine import machine_info

#: Name -> command line; ``python -c pass`` is the anchor.
COMMANDS: dict[str, list[str]] = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "python -c 'import fidelity'": [sys.executable, "-c", "import fidelity"],
    "fidelity --help": ["fidelity", "--help"],
    "fidelity predict --delta-e 3": ["fidelity", "predict", "--delta-e", "3"],
    "fidelity check (closed form, no report)": ["fidelity", "check", "--no-report", "-q"],
}
#: The targets of issue 22, in seconds.
TARGETS = {"fidelity --help": 0.5, "fidelity predict --delta-e 3": 1.0}


def run_once(argv: list[str], cwd: str) -> float:
    """Wall time of one run of ``argv`` (it must exit 0)."""
    t0 = time.perf_counter()
    subprocess.run(argv, cwd=cwd, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--out", type=Path, default=Path("reports/benchmarks/startup.json"))
    args = ap.parse_args(argv)
    if shutil.which("fidelity") is None:
        print("the fidelity command is not on PATH (pip install -e .)", file=sys.stderr)
        return 2
    load = os.getloadavg()[0]
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    with tempfile.TemporaryDirectory() as cwd:  # no settings file is found from here
        for cmd in COMMANDS.values():  # warm the file cache once
            run_once(cmd, cwd)
        for _ in range(args.repeats):
            for name, cmd in COMMANDS.items():
                times[name].append(run_once(cmd, cwd))
    anchor = statistics.median(times["python -c pass"])
    rows = []
    for name, ts in times.items():
        median = statistics.median(ts)
        row = {"command": name, "median_s": round(median, 4), "min_s": round(min(ts), 4),
               "above_python_s": round(median - anchor, 4),
               "ratio_to_python": round(median / anchor, 2)}
        if name in TARGETS:
            row["target_s"] = TARGETS[name]
            row["meets_target"] = median < TARGETS[name]
        rows.append(row)
        print(f"{name:<42} median {median * 1000:7.1f} ms  min {min(ts) * 1000:7.1f} ms  "
              f"{median / anchor:5.2f}x python -c pass"
              + (f"  (target {TARGETS[name]:g} s: {'met' if median < TARGETS[name] else 'MISSED'})"
                 if name in TARGETS else ""))
    result = {"benchmark": "startup", "repeats": args.repeats, "rows": rows,
              "load_average_at_start": round(load, 2), "machine": machine_info(),
              "date": time.strftime("%Y-%m-%d")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
