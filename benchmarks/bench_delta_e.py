"""Benchmark: fidelity.colour.colorimetry.delta_e_2000 against colour.delta_E(method="CIE 2000").

Same inputs, same run, best of N repeats; prints the speed ratio and the largest difference.
Writes reports/benchmarks/delta_e.json.  Run:  python -m benchmarks.bench_delta_e [--pairs N]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import colour
import numpy as np

from benchmarks.machine import best_time, machine_info
from fidelity.colour.colorimetry import delta_e_2000
from fidelity.core.fileio import write_json_atomic


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--pairs", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=Path(__file__).parents[1] / "reports/benchmarks/delta_e.json")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.pairs
    lab1 = np.stack([rng.uniform(0, 100, n), rng.uniform(-128, 128, n), rng.uniform(-128, 128, n)], -1)
    lab2 = lab1 + rng.normal(0, 5, (n, 3))
    ours = delta_e_2000(lab1, lab2)
    ref = colour.delta_E(lab1, lab2, method="CIE 2000")
    max_diff = float(np.max(np.abs(ours - ref)))
    t_ours = best_time(lambda: delta_e_2000(lab1, lab2), args.repeats)
    t_ref = best_time(lambda: colour.delta_E(lab1, lab2, method="CIE 2000"), args.repeats)
    lab1_32, lab2_32 = lab1.astype(np.float32), lab2.astype(np.float32)
    t_ours32 = best_time(lambda: delta_e_2000(lab1_32, lab2_32), args.repeats)
    result = {
        "benchmark": "CIEDE2000 on random Lab pairs",
        "pairs": n,
        "repeats": args.repeats,
        "seconds_fidelity": t_ours,
        "seconds_fidelity_float32_input": t_ours32,
        "seconds_colour_science": t_ref,
        "speedup": t_ref / t_ours,
        "max_abs_difference": max_diff,
        "machine": machine_info(),
    }
    print(f"CIEDE2000, {n:,} pairs, best of {args.repeats}:")
    print(f"  fidelity.delta_e_2000        {t_ours:8.3f} s   ({n / t_ours / 1e6:.1f} M pairs/s)")
    print(f"  colour.delta_E('CIE 2000')   {t_ref:8.3f} s   ({n / t_ref / 1e6:.1f} M pairs/s)")
    print(f"  speed-up {t_ref / t_ours:.2f}x, largest difference {max_diff:.2e}")
    write_json_atomic(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
