"""The direction-aware prediction's own standard errors (issue 58): each family point's
per-column SE is the SE of the sweep cell whose value the column took, and the prediction's SE
is the weighted sum of its terms' curve SEs (fully correlated: the cells share the images)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fidelity.pipeline.check import check_camera
from fidelity.prediction.directional import (
    COLUMNS,
    FAMILIES,
    combined_standard_error,
    load_directional_table,
)
from fidelity.report.terminal import directional_lines

REPO = Path(__file__).resolve().parents[2]
TABLE = REPO / "fidelity" / "data" / "prediction" / "coco1000-directional.json"
TABLES = REPO / "reports" / "coco" / "tables.json"


def test_combined_standard_error_is_the_weighted_sum() -> None:
    # closed form: sum w se; a zero weight's missing SE does not matter
    assert combined_standard_error([0.5, 0.3, 0.2], [0.1, 0.4, 1.0]) == pytest.approx(
        0.05 + 0.12 + 0.2)
    assert combined_standard_error([1.0, 0.0], [0.3, None]) == pytest.approx(0.3)
    assert combined_standard_error([0.6, 0.4], [0.3, None]) is None
    # never below the uncorrelated combination, equal with one term
    w, se = np.array([0.5, 0.3, 0.2]), np.array([0.1, 0.4, 1.0])
    assert combined_standard_error(list(w), list(se)) >= math.sqrt(float(np.sum((w * se) ** 2)))


def test_family_points_carry_the_se_of_the_cell_each_column_took() -> None:
    """Read independently from the committed tables.json (the sweep's cells with their SEs,
    computed from the per-image scores): for one model's family point, each column's value is
    the largest over the family's cells at that ΔE and its SE is that cell's."""
    cells = json.loads(TABLES.read_text())["tables"]["cells"]
    doc = json.loads(TABLE.read_text())
    checked = 0
    for fam in ("tone", "chroma", "hue"):
        members = set(FAMILIES[fam].transforms)
        for curve in doc["families"][fam]["curves"]:
            model = curve["model"]
            if model is None:
                continue
            for point in curve["points"][1:4]:
                done = [c for c in cells[model] if c["transform"] in members
                        and c["delta_e"] == point["delta_e"] and c["status"] == "done"]
                for col in COLUMNS:
                    top = max(done, key=lambda c: c[col])
                    assert point[col] == pytest.approx(round(top[col], 4), abs=1e-12)
                    assert point[f"{col}_se"] == pytest.approx(round(top[f"{col}_se"], 4),
                                                               abs=1e-12)
                    checked += 1
    assert checked >= 3 * 4 * 3 * 4


def _bracket_se(points: list[dict], col: str, de: float) -> float:
    """The larger SE of the two curve points around ``de`` (as the classic table reads)."""
    xs = [p["delta_e"] for p in points]
    i = int(np.searchsorted(xs, de))
    around = [points[j] for j in (i - 1, i) if 0 <= j < len(points)]
    if any(p["delta_e"] == de for p in around):
        around = [p for p in around if p["delta_e"] == de]
    return max(p[f"{col}_se"] or 0.0 for p in around)


def test_check_states_the_directional_se_from_its_terms() -> None:
    report = check_camera("nikon-5100")
    d = report.directional
    doc = json.loads(TABLE.read_text())
    for col in COLUMNS:
        expected = 0.0
        for t in d.terms:
            assert t.sources[col] == "family"
            curve = next(c for c in doc["families"][t.family]["curves"]
                         if c["size"] == d.size_used and c["model"] is None)
            expected += t.weight * _bracket_se(curve["points"], col, d.delta_e)
        assert d.standard_errors[col] == pytest.approx(expected, rel=1e-12)
        assert d.standard_errors[col] > 0
    # the person column's SE is its own, smaller than the mAP's here
    assert d.standard_errors["dap_person_points"] != d.standard_errors["dmap_points"]
    # the terminal prints it and no longer borrows the classic column's
    line = directional_lines(report)[0]
    by = {i.column: i for i in report.intervals}
    u = math.hypot(d.standard_errors["dmap_points"], by["dmap_points"].propagated)
    assert f"{d.dmap_points:.2f} ± {u:.2f} points" in line
    assert "classic column's u" not in line
    assert load_directional_table().families["tone"].curves
