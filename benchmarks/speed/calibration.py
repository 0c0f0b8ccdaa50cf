"""The whole default SAFE-COLOR calibration table (10 transforms x 23 ΔE targets).

No library anchor: the target is the issue's 2 s. Best of ``repeats`` builds, with the largest
|ΔE - target| of the reachable entries.
"""

from __future__ import annotations

import time
from typing import Any

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter

ANCHOR = "none (the target: under 2 s)"
PARAMETERS = {"repeats": Parameter(5, "best of N builds")}
QUICK = {"repeats": 1}
#: The issue's target, seconds.
TARGET_S = 2.0


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.prediction.calibration import calibration_table

    times = []
    for _ in range(ctx["repeats"]):
        t = time.perf_counter()
        table = calibration_table()
        times.append(time.perf_counter() - t)
    worst = max(abs(e.delta_e - e.target) for e in table.entries if e.reachable)
    unreachable = sum(not e.reachable for e in table.entries)
    return {"benchmark": "default calibration table", "entries": len(table.entries),
            "unreachable": unreachable, "seconds_best": min(times), "seconds_all": times,
            "largest_abs_error": worst}


def cases(details: dict[str, Any]) -> list[Case]:
    runs = details["seconds_all"]
    return [case(f"default calibration table ({details['entries']} entries, "
                 f"{details['unreachable']} unreachable)",
                 figures("fidelity.prediction.calibration.calibration_table()",
                         details["seconds_best"], best_s=min(runs), runs_s=runs),
                 None, per="table", statistic=f"best of {len(runs)}", target_s=TARGET_S,
                 note=f"largest |ΔE - target| {details['largest_abs_error']:.1e}")]
