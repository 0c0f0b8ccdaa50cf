"""Benchmark: each SAFE-COLOR transform on a 640x480 image, fidelity vs plain colour-science.

The anchor is benchmarks/colour_reference.py (Table I written with colour-science building
blocks). Same image, same run, best of N repeats; prints per-transform times and ratios, and the
largest difference between the two results. Writes reports/benchmarks/transforms.json.
Run:  python -m benchmarks.bench_transforms
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks.machine import best_time, machine_info
from fidelity.core.fileio import write_json_atomic
from fidelity.prediction.calibration import load_calibration_table
from fidelity.prediction.transforms import TRANSFORMS
from tests.fixtures.colour_reference import reference_transform


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parents[1] / "reports/benchmarks/transforms.json")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    # A smooth synthetic photo-like image: gradients plus noise, 8-bit levels.
    y, x = np.mgrid[0:480, 0:640] / np.array([480.0, 640.0])[:, None, None]
    img = np.stack([x, y, 0.5 + 0.5 * np.sin(6 * x * y)], -1) + rng.normal(0, 0.05, (480, 640, 3))
    img = np.round(np.clip(img, 0, 1) * 255) / 255
    table = load_calibration_table()
    rows = []
    print(f"640x480 image, parameter at ΔE 6 (best of {args.repeats}):")
    print(f"  {'transform':16s} {'fidelity f64':>12s} {'fidelity f32':>12s} {'colour':>9s} {'ratio':>6s} {'max diff':>9s}")
    img32 = img.astype(np.float32)
    for name in TRANSFORMS:
        p = table.param(name, 6.0)
        assert p is not None
        t64 = best_time(lambda n=name, q=p: TRANSFORMS[n](img, q), args.repeats)
        t32 = best_time(lambda n=name, q=p: TRANSFORMS[n](img32, q), args.repeats)
        tref = best_time(lambda n=name, q=p: reference_transform(n, img, q), args.repeats)
        diff = float(np.max(np.abs(TRANSFORMS[name](img, p) - reference_transform(name, img, p))))
        rows.append({"transform": name, "param": p, "seconds_fidelity_float64": t64,
                     "seconds_fidelity_float32": t32, "seconds_colour_science": tref,
                     "speedup_float64": tref / t64, "speedup_float32": tref / t32,
                     "max_abs_difference": diff})
        print(f"  {name:16s} {t64 * 1e3:10.1f}ms {t32 * 1e3:10.1f}ms {tref * 1e3:7.1f}ms "
              f"{tref / t64:5.1f}x {diff:9.1e}")
    write_json_atomic(args.out, {"benchmark": "SAFE-COLOR transforms on 640x480", "results": rows,
                                 "machine": machine_info()})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
