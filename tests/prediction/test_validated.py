"""The validated bound (:mod:`fidelity.prediction.validated`, issue 58): the predicted ΔmAP's
upper bound with the model's own error, fitted on the committed validation cells; checked here
by an independent computation from those cells, and in what check prints and writes."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity import check_camera
from fidelity.cli import main
from fidelity.prediction.table import predict
from fidelity.prediction.validated import ValidatedBound, load_validated_bound, validated_upper

REPO = Path(__file__).resolve().parents[2]
CELLS = REPO / "reports" / "validation" / "directional.json"


def _cells() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rows = json.loads(CELLS.read_text(encoding="utf-8"))["rows"]
    return (np.array([r["camera"] for r in rows]),
            np.array([r["cells"]["all"]["measured"] for r in rows]),
            np.array([r["cells"]["all"]["se"] for r in rows]),
            np.array([r["cells"]["all"]["classic"] for r in rows]))


def _fit(m: np.ndarray, p: np.ndarray, alpha: float) -> tuple[float, float]:
    """Least squares through the origin, then the ceil((n+1)(1-alpha))-th smallest residual."""
    a = float(np.dot(m, p) / np.dot(p, p))
    k = math.ceil((len(m) + 1) * (1 - alpha))
    return a, float(sorted(m - a * p)[k - 1])


def test_the_shipped_bound_is_the_validation_cells_fit():
    bound = load_validated_bound()
    assert bound is not None
    assert bound.source == "reports/validation/directional.json"
    assert bound.source_sha256 == hashlib.sha256(CELLS.read_bytes()).hexdigest()
    camera, m, se, p = _cells()
    assert (bound.cells, bound.cameras) == (len(m), len(set(camera))) == (60, 30)
    a, q = _fit(m, p, bound.alpha)
    assert (bound.a, bound.q) == pytest.approx((a, q), rel=1e-12)
    # leaving each camera out: both its cells judged by constants fitted on the others
    upper = np.empty_like(m)
    for c in set(camera):
        out = camera == c
        ac, qc = _fit(m[~out], p[~out], bound.alpha)
        upper[out] = ac * np.maximum(p[out], 0) + qc
    held = m <= upper
    assert bound.cells_covered == int(held.sum()) == 58
    assert bound.cameras_covered == sum(bool(held[camera == c].all()) for c in set(camera))
    pos, sig = m > 0, m > 2 * se
    assert bound.median_ratio == pytest.approx(float(np.median(upper[pos] / m[pos])))
    assert bound.median_ratio_significant == pytest.approx(
        float(np.median(upper[sig] / m[sig])))
    assert bound.significant_cells == int(sig.sum())
    assert ValidatedBound.from_json(bound.to_json()) == bound


def test_it_applies_to_the_validated_table_and_size_only():
    bound = load_validated_bound()
    assert bound is not None
    p = predict(2.0, size="n")
    got = validated_upper(p)
    assert got is not None and got[0] == pytest.approx(bound.a * p.dmap_points + bound.q)
    assert bound.upper(-0.3) == bound.q  # a loss measured below 0 predicts none
    assert validated_upper(p, "dmap_relative") is None
    assert validated_upper(predict(2.0, size="n", table="safecolor-2025")) is None


def test_check_prints_and_writes_the_bound(tmp_path):
    """The terminal's line, the JSON's interval and the HTML's summary give the same
    ``a p + q`` of the printed prediction."""
    bound = load_validated_bound()
    assert bound is not None
    report = check_camera("nikon-5100")
    assert report.interval is not None and report.prediction is not None
    upper = bound.upper(report.prediction.dmap_points or 0.0)
    assert report.interval.validated_upper == pytest.approx(upper)
    r = CliRunner().invoke(main, ["--no-config", "check", "--json", str(tmp_path / "r.json"),
                                  "--html", str(tmp_path / "r.html")])
    assert r.exit_code == 0, r.output
    line = next(ln.strip() for ln in r.output.splitlines() if "validated bound" in ln)
    assert line == (f"validated bound: ΔmAP <= {upper:.2f} points with the model's own error "
                    f"({bound.a:.3g} p + {bound.q:.3g}, calibrated split-conformal at 95 % on "
                    f"the validation's 60 cells; leaving each camera out it held 58 of 60)")
    # docs/validation.md quotes the line the default check prints
    page = " ".join((REPO / "docs" / "validation.md").read_text(encoding="utf-8").split())
    assert f"`{line}`" in page
    doc = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    assert doc["prediction_interval"]["validated_upper"] == pytest.approx(upper)
    assert f"≤ {upper:.2f} points" in (tmp_path / "r.html").read_text(encoding="utf-8")
