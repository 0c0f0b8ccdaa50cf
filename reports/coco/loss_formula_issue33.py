"""How the unified loss formula (issue 33, ``fidelity.coco.loss``) moves shipped numbers.

Only the validation's relative-ΔmAP standard error changes: it was ``se_points / baseline_mAP``
and is now the paired SE of each fold's ΔmAP as a share of that fold's own baseline (what the
sweep tables and ``--measure`` already computed). ``validation.json`` keeps the baselines'
fold scores but not the cells', so the new SE is bounded, not recomputed:

    |SE_new - SE_old| <= M * sqrt(sum_k (1/b_k - 1/B)^2 / (K - 1)) / sqrt(K)

(sd is a seminorm; ``r_k = x_k / b_k = x_k / B + x_k (1/b_k - 1/B)``), with ``x_k`` the
fold losses in points, ``|x_k| <= M = |x| + sd(x) (K - 1) / sqrt(K)`` and the full-set loss
``x`` standing in for the fold mean. The sweep (``tables.json``) holds both SEs of 496 cells,
the ratio new / old there is exact. Run from the repository root:
``python3 reports/coco/loss_formula_issue33.py``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

K = 5


def main() -> None:
    """Print the sweep's exact ratios and the validation's bounds."""
    t = json.loads(Path("reports/coco/tables.json").read_text())["tables"]
    ratios: list[tuple[float, str]] = []
    for m, rows in t["cells"].items():
        b = t["models"][m]["baseline_map"]
        for r in rows:
            if r["status"] == "done" and r.get("dmap_relative_se") is not None:
                ratios.append((r["dmap_relative_se"] / (r["dmap_points_se"] / b), m))
    q = np.array([x for x, _ in ratios])
    print(f"sweep: {len(q)} cells, SE_new / SE_old median {np.median(q):.3f}, "
          f"5-95 % {np.percentile(q, 5):.3f}-{np.percentile(q, 95):.3f}")
    for m in sorted({m for _, m in ratios}):
        qm = np.array([x for x, mm in ratios if mm == m])
        print(f"  {m}: median {np.median(qm):.3f}, 5 % {np.percentile(qm, 5):.3f}")
    v = json.loads(Path("reports/validation/validation.json").read_text())
    bounds: dict[tuple[str, str], tuple[float, float]] = {}
    for r in v["rows"]:
        base = v["baselines"][r["model"]]
        bk = np.array([f["map"] for f in base["folds"]])
        sp, old = r["se"]["dmap_points"], r["se"]["dmap_relative"]
        sd = sp * math.sqrt(K)
        big = abs(r["measured"]["dmap_points"]) + sd * (K - 1) / math.sqrt(K)
        c = np.abs(1 / bk - 1 / base["map"])
        bounds[(r["camera"], r["model"])] = (old, big * math.sqrt(float((c ** 2).sum()) / (K - 1))
                                             / math.sqrt(K))
    rel = [d / o for o, d in bounds.values() if o > 0]
    print(f"validation: {len(bounds)} rows, bound |SE_new - SE_old| / SE_old median "
          f"{np.median(rel):.2f}, max {max(rel):.2f}")
    d: dict[str, Any] = json.loads(Path("reports/validation/directional.json").read_text())
    for r in d["rows"]:
        cell = r["cells"]["all-relative"]
        old, delta = bounds[(r["camera"], r["model"])]
        for key in ("classic", "directional"):
            meas, pred = cell["measured"], cell[key]
            if (meas - 2 * (old + delta) <= pred) != (meas - 2 * max(old - delta, 0) <= pred):
                print(f"  open: {r['camera']} / {r['model']} {key} within 2 SE turns false "
                      f"if SE_new / SE_old < {(meas - pred) / 2 / old:.2f}")


if __name__ == "__main__":
    main()
