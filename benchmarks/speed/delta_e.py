"""CIEDE2000 of random Lab pairs: fidelity.colour.colorimetry.delta_e_2000 against
colour.delta_E(method="CIE 2000").

Same inputs, same run, best of ``repeats`` calls each (float64 input, and float32 input for
ours); the largest difference of the two results is recorded.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import best_time

ANCHOR = 'colour.delta_E(method="CIE 2000") on the same pairs'
PARAMETERS = {"pairs": Parameter(2_000_000, "random Lab pairs"),
              "repeats": Parameter(5, "best of N calls")}
QUICK = {"pairs": 100_000, "repeats": 2}


def measure(ctx: Context) -> dict[str, Any]:
    import colour

    from fidelity.colour.colorimetry import delta_e_2000

    rng = np.random.default_rng(0)
    n, repeats = ctx["pairs"], ctx["repeats"]
    lab1 = np.stack([rng.uniform(0, 100, n), rng.uniform(-128, 128, n),
                     rng.uniform(-128, 128, n)], -1)
    lab2 = lab1 + rng.normal(0, 5, (n, 3))
    ours = delta_e_2000(lab1, lab2)
    ref = colour.delta_E(lab1, lab2, method="CIE 2000")
    max_diff = float(np.max(np.abs(ours - ref)))
    t_ours = best_time(lambda: delta_e_2000(lab1, lab2), repeats)
    t_ref = best_time(lambda: colour.delta_E(lab1, lab2, method="CIE 2000"), repeats)
    lab1_32, lab2_32 = lab1.astype(np.float32), lab2.astype(np.float32)
    t_ours32 = best_time(lambda: delta_e_2000(lab1_32, lab2_32), repeats)
    return {"benchmark": "CIEDE2000 on random Lab pairs", "pairs": n, "repeats": repeats,
            "seconds_fidelity": t_ours, "seconds_fidelity_float32_input": t_ours32,
            "seconds_colour_science": t_ref, "speedup": t_ref / t_ours,
            "max_abs_difference": max_diff}


def cases(details: dict[str, Any]) -> list[Case]:
    n, stat = details["pairs"], f"best of {details['repeats']}"
    anchor = figures('colour.delta_E(method="CIE 2000"), float64',
                     details["seconds_colour_science"])
    return [case(f"{n:,} pairs, float64", figures("fidelity delta_e_2000, float64",
                                                   details["seconds_fidelity"]),
                 anchor, per="call", statistic=stat,
                 note=f"largest difference {details['max_abs_difference']:.1e}"),
            case(f"{n:,} pairs, float32 input",
                 figures("fidelity delta_e_2000, float32 input",
                         details["seconds_fidelity_float32_input"]),
                 anchor, per="call", statistic=stat)]
