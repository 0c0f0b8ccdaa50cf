"""The validated bound (:mod:`fidelity.prediction.validated`, issue 58): the predicted ΔmAP's
upper bound with the model's own error, fitted on the committed validation cells; checked here
by an independent computation from those cells, and in what check prints and writes."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity import check_camera
from fidelity.cli import main
from fidelity.prediction.properties import Combined, combine, load_property_table
from fidelity.prediction.table import predict
from fidelity.prediction.validated import (
    PropertyMargin,
    ValidatedBound,
    load_property_margin,
    load_validated_bound,
    validated_upper,
    with_margin,
)

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


# --------------------------------------------------------------------------------------------
# The margin of the combined property loss (issue 56)

PROPERTY_CELLS = REPO / "reports" / "validation" / "properties.json"
COLUMNS = ("dmap_points", "dmap_relative", "dap_person_points", "dap_bicycle_points")


def _property_cells(column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rows = json.loads(PROPERTY_CELLS.read_text(encoding="utf-8"))["rows"]
    return (np.array([r["camera"] for r in rows]),
            np.array([r["measured"][column] for r in rows]),
            np.array([r["se"][column] for r in rows]),
            np.array([r["predicted"]["sum+interaction"][column] for r in rows]))


def _log_ratio_q(m: np.ndarray, p: np.ndarray, alpha: float, c: float) -> float:
    """The ceil((n+1)(1-alpha))-th smallest of log((m + c) / (p + c))."""
    scores = sorted(math.log((mi + c) / (pi + c)) if mi + c > 0 else -math.inf
                    for mi, pi in zip(m, p, strict=True))
    return scores[math.ceil((len(m) + 1) * (1 - alpha)) - 1]


@pytest.mark.parametrize("column", COLUMNS)
def test_the_shipped_margin_is_the_property_cells_fit(column):
    """Each column's q is the log-ratio quantile of the 78 cells, and its camera-left-out
    figures are those of the clamped bound (q < 0 counts as 0) the verdict applies."""
    margin = load_property_margin()
    assert margin is not None
    assert margin.source == "reports/validation/properties.json"
    assert margin.source_sha256 == hashlib.sha256(PROPERTY_CELLS.read_bytes()).hexdigest()
    assert margin.tables == {"colour": "coco1000-measured", "sharpness": "coco1000-sharpness",
                             "noise": "coco1000-noise"}
    camera, m, se, p = _property_cells(column)
    got = margin.columns[column]
    assert (got.cells, got.cameras) == (len(m), len(set(camera))) == (78, 39)
    assert got.q == pytest.approx(_log_ratio_q(m, p, margin.alpha, margin.offset), rel=1e-12)
    c = margin.offset
    upper = np.empty_like(m)
    for name in set(camera):
        out = camera == name
        q = max(_log_ratio_q(m[~out], p[~out], margin.alpha, c), 0.0)
        upper[out] = (np.maximum(p[out], 0) + c) * math.exp(q) - c
    held = m <= upper
    assert got.cells_covered == int(held.sum())
    assert got.cameras_covered == sum(bool(held[camera == n].all()) for n in set(camera))
    pos, sig = m > 0, m > 2 * se
    assert got.median_ratio == pytest.approx(float(np.median(upper[pos] / m[pos])))
    assert got.median_ratio_significant == pytest.approx(float(np.median(upper[sig] / m[sig])))
    assert PropertyMargin.from_json(margin.to_json()) == margin


def test_the_margin_meets_the_issues_target_on_mean_ap():
    """Issue 56: >= 95 % of the cells bounded with a median over-prediction <= 2x, leaving
    each camera out (the rule alone bounds 74 of 78)."""
    margin = load_property_margin()
    assert margin is not None
    got = margin.columns["dmap_points"]
    assert got.cells_covered / got.cells >= 0.95 and got.median_ratio <= 2.0
    camera, m, se, p = _property_cells("dmap_points")
    assert int((m <= p).sum()) < got.cells_covered


def _combined(sharp: float = 3.0, noise: float = 1.0, u: float | None = 0.5) -> Combined:
    return combine({"colour": (0.5, 0.1), "sharpness": (sharp, u), "noise": (noise, 0.2)})


def test_with_margin_where_it_was_validated_only():
    margin = load_property_margin()
    assert margin is not None
    tables = {p: load_property_table(p) for p in ("sharpness", "noise")}
    raw = _combined()
    got = with_margin(raw, "dmap_points", tables, "any")
    q = margin.columns["dmap_points"].q
    assert got.loss == pytest.approx((raw.loss + 0.5) * math.exp(q) - 0.5, rel=1e-12)
    assert got.margin == pytest.approx(got.loss - raw.loss) and got.margin > 0
    assert got.rule_loss == pytest.approx(raw.loss, rel=1e-12)
    assert got.u_loss == pytest.approx(raw.u_loss * math.exp(q))
    assert (got.dominant, got.parts, got.interaction) == (raw.dominant, raw.parts,
                                                          raw.interaction)
    assert with_margin(got, "dmap_points", tables, "any") == got  # never twice
    assert Combined.from_json(json.loads(json.dumps(got.to_json()))) == got
    # size n: the same detectors; u unknown stays unknown
    assert with_margin(raw, "dmap_points", tables, "n").loss == got.loss
    assert with_margin(_combined(u=None), "dmap_points", tables, "n").u_loss is None
    # not where it was not validated: a property not judged, another table, another size
    colour_sharp = combine({"colour": (0.5, 0.1), "sharpness": (3.0, 0.5), "noise": None})
    assert with_margin(colour_sharp, "dmap_points", tables, "any") == colour_sharp
    other = {**tables, "noise": replace(tables["noise"], name="my-noise")}
    assert with_margin(raw, "dmap_points", other, "any") == raw
    assert with_margin(raw, "dmap_points", tables, "s") == raw
    assert with_margin(raw, "other_column", tables, "any") == raw
    # a fitted q below 0 never lowers the rule's loss
    low = replace(margin, columns={"dmap_points": replace(margin.columns["dmap_points"],
                                                          q=-0.2)})
    assert with_margin(raw, "dmap_points", tables, "any", low).loss == raw.loss


def test_check_and_gate_judge_the_loss_with_its_margin(tmp_path):
    """The margin is in the combined loss that check prints and writes, and in the value a
    max-dmap gate compares with its limit."""
    camera = REPO / "cameras" / "properties" / "nikon-gauss2.0-fw5k.toml"
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", str(camera), "--size", "n",
                                  "--json", str(tmp_path / "r.json"),
                                  "--html", str(tmp_path / "r.html")])
    assert r.exit_code == 1, r.output
    doc = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    c = Combined.from_json(doc["properties"]["combined"])
    margin = load_property_margin()
    assert margin is not None and c.margin > 0
    assert c.loss == pytest.approx(margin.upper(c.rule_loss), rel=1e-12)
    line = next(ln.strip() for ln in r.output.splitlines() if ln.strip().startswith("combined"))
    assert f"{c.loss:.2f}" in line and f"+ {c.margin:.2f} validated margin" in line
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert f"<td>combined ({c.rule}, + {c.margin:.2f} validated margin)</td>" in html
    limit = c.rule_loss + c.margin / 2  # the rule alone passes it, the margin fails it
    g = CliRunner().invoke(main, ["--no-config", "check", "--camera", str(camera), "--size", "n",
                                  "--max-dmap", f"{limit:.6f}", "--json",
                                  str(tmp_path / "g.json")])
    assert g.exit_code == 1, g.output
    verdict = json.loads((tmp_path / "g.json").read_text(encoding="utf-8"))["verdict"]
    assert verdict["value"] == pytest.approx(c.loss, rel=1e-9)


def test_the_docs_quote_the_shipped_margin():
    margin = load_property_margin()
    assert margin is not None
    got = margin.columns["dmap_points"]
    page = " ".join((REPO / "docs" / "validation.md").read_text(encoding="utf-8").split())
    share = 100 * got.cells_covered / got.cells
    assert (f"{got.cells_covered} of {got.cells} cells ({share:.1f} %) leaving each camera out, "
            f"at a median over-prediction of {got.median_ratio:.2f}x") in page
    assert f"`q` = {got.q:.3g} for ΔmAP in points" in page
    sharp = " ".join((REPO / "docs" / "sharpness_noise.md").read_text(encoding="utf-8").split())
    assert (f"bounds the measured loss of {got.cells_covered} of the {got.cells} validation "
            "cells judged camera left out") in sharp
