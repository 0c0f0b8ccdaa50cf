"""Benchmark: time to compute the whole default SAFE-COLOR calibration table (10 x 23 entries).

The issue asks for under 2 s. Reports the best of N runs and the largest |ΔE - target|.
Writes reports/benchmarks/calibration.json.  Run:  python -m benchmarks.bench_calibration
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from benchmarks.machine import machine_info
from fidelity.core.fileio import write_json_atomic
from fidelity.prediction.calibration import calibration_table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parents[1] / "reports/benchmarks/calibration.json")
    args = ap.parse_args()
    times = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        table = calibration_table()
        times.append(time.perf_counter() - t)
    worst = max(abs(e.delta_e - e.target) for e in table.entries if e.reachable)
    unreachable = sum(not e.reachable for e in table.entries)
    print(f"default calibration table: {len(table.entries)} entries ({unreachable} unreachable), "
          f"best {min(times):.3f} s of {args.repeats}, largest |ΔE - target| {worst:.1e}")
    write_json_atomic(args.out, {"benchmark": "default calibration table", "entries": len(table.entries),
                                 "unreachable": unreachable, "seconds_best": min(times),
                                 "seconds_all": times, "largest_abs_error": worst,
                                 "machine": machine_info()})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
