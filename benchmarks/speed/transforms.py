"""Each SAFE-COLOR transform on a 640x480 image: fidelity against Table I written with plain
colour-science.

The anchor is :mod:`tests.fixtures.colour_reference` (Table I from colour-science's building
blocks). Same image (a smooth synthetic photo-like image, 8-bit levels), the parameter at ΔE 6,
best of ``repeats`` calls each, float64 and float32 input for ours; the largest difference of
the two results per transform is recorded.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import best_time

ANCHOR = "Table I written with colour-science (tests/fixtures/colour_reference.py), 640x480"
PARAMETERS = {"repeats": Parameter(5, "best of N calls")}
QUICK = {"repeats": 1}


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.prediction.calibration import load_calibration_table
    from fidelity.prediction.transforms import TRANSFORMS
    from tests.fixtures.colour_reference import reference_transform

    repeats = ctx["repeats"]
    rng = np.random.default_rng(0)
    # A smooth synthetic photo-like image: gradients plus noise, 8-bit levels.
    y, x = np.mgrid[0:480, 0:640] / np.array([480.0, 640.0])[:, None, None]
    img = np.stack([x, y, 0.5 + 0.5 * np.sin(6 * x * y)], -1) + rng.normal(0, 0.05, (480, 640, 3))
    img = np.round(np.clip(img, 0, 1) * 255) / 255
    table = load_calibration_table()
    rows = []
    img32 = img.astype(np.float32)
    for name in TRANSFORMS:
        p = table.param(name, 6.0)
        assert p is not None
        t64 = best_time(lambda n=name, q=p: TRANSFORMS[n](img, q), repeats)
        t32 = best_time(lambda n=name, q=p: TRANSFORMS[n](img32, q), repeats)
        tref = best_time(lambda n=name, q=p: reference_transform(n, img, q), repeats)
        diff = float(np.max(np.abs(TRANSFORMS[name](img, p) - reference_transform(name, img, p))))
        rows.append({"transform": name, "param": p, "seconds_fidelity_float64": t64,
                     "seconds_fidelity_float32": t32, "seconds_colour_science": tref,
                     "speedup_float64": tref / t64, "speedup_float32": tref / t32,
                     "max_abs_difference": diff})
        ctx.log(f"  {name:16s} {t64 * 1e3:8.1f} ms {t32 * 1e3:8.1f} ms (float32) "
                f"{tref * 1e3:8.1f} ms colour-science, difference {diff:.1e}")
    return {"benchmark": "SAFE-COLOR transforms on 640x480", "repeats": repeats, "results": rows}


def cases(details: dict[str, Any]) -> list[Case]:
    stat = (f"best of {details['repeats']}" if "repeats" in details
            else "best of N (N not recorded)")
    out = []
    for r in details["results"]:
        anchor = figures(f"colour-science Table I {r['transform']}, float64",
                         r["seconds_colour_science"])
        for bits in ("64", "32"):
            out.append(case(f"{r['transform']} (parameter {r['param']:.4g}), float{bits}",
                            figures(f"fidelity {r['transform']}, float{bits}",
                                    r[f"seconds_fidelity_float{bits}"]),
                            anchor, per="call", statistic=stat,
                            note=(f"largest difference {r['max_abs_difference']:.1e}"
                                  if bits == "64" else None)))
    return out
