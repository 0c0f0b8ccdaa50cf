"""benchmarks/studies/combination.py: the composite applies its steps in order, the
prediction is the calibration chart's as an audit reads it, and the page's counts come from
the numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.studies.combination import composite, markdown, predicted
from fidelity.coco.degradations import Degradation
from fidelity.coco.tables.degradation import calibration_chart, chart_value


def test_the_composite_is_blur_then_noise():
    image, _ = calibration_chart()
    blur, noise = Degradation("gaussian-blur", 1.5), Degradation("gaussian-noise", 0.06)
    np.testing.assert_array_equal(composite(blur, noise)(image), noise(blur(image)))
    assert not np.array_equal(composite(noise, blur)(image), noise(blur(image)))


def test_the_prediction_sums_what_the_chart_reads():
    blur, noise = Degradation("gaussian-blur", 1.5), Degradation("gaussian-noise", 0.06)
    p = predicted(blur, noise)
    image, corners = calibration_chart()
    mtf = chart_value(noise(blur(image)), corners, "sharpness")
    assert mtf is not None and p["sharpness"]["x"] == pytest.approx(mtf[0])
    assert p["sum"] == pytest.approx(p["sharpness"]["loss"] + p["noise"]["loss"])
    assert p["combined"] == pytest.approx(
        p["sum"] + math.sqrt(p["sharpness"]["loss"] * p["noise"]["loss"]))
    # each alone predicts less than the composite's sum
    assert predicted(blur)["sum"] < p["sum"] and predicted(noise)["sum"] < p["sum"]


def test_the_page_counts_from_the_numbers():
    def m(joint: float, covered: bool) -> dict:
        return {"blur": {"loss": 1.0, "se": 0.1}, "noise": {"loss": 2.0, "se": 0.1},
                "joint": {"loss": joint, "se": 0.1}, "measured_sum": 3.0,
                "interaction": joint - 3.0, "interaction_se": 0.17, "covered": covered}
    doc = {"cases": [{"blur": {"family": "gaussian-blur", "level": 1.5},
                      "noise": {"family": "gaussian-noise", "level": 0.06},
                      "predicted": {"sharpness": {"loss": 1.5}, "noise": {"loss": 2.5},
                                    "sum": 4.0},
                      "models": {"a": m(3.1, True), "b": m(5.0, False)}}]}
    page = markdown(doc)
    # the sum (4) covers 3.1 only; the rule, 4 + sqrt(1.5 x 2.5) = 5.94, both
    assert "the joint loss measured in 1 of 2 cases, the combined loss by the rule in 2 of 2" \
        in page
    assert "| 5.94 |" in page and "in 1 of 2;" in page
    assert "the largest interaction is 1.41 sqrt" in page  # (5 - 3) / sqrt(1 x 2)


def test_the_docs_quote_the_committed_studies():
    """docs/sharpness_noise.md quotes each committed study's summary as the page makes it
    from the numbers, and its words about the one miss hold: the rule's shortfall is below a
    tenth of the joint loss's standard error, on the first study only."""
    import json
    from pathlib import Path

    from benchmarks.studies.combination import predicted_combined

    repo = Path(__file__).resolve().parents[1]
    docs = (repo / "docs" / "sharpness_noise.md").read_text()
    misses = {}
    for name in ("combination", "combination-holdout"):
        doc = json.loads((repo / "reports" / "validation" / f"{name}.json").read_text())
        assert markdown(doc).strip().split("\n")[-1] in docs
        misses[name] = [(predicted_combined(c["predicted"]), m["joint"])
                        for c in doc["cases"] for m in c["models"].values()
                        if predicted_combined(c["predicted"]) < m["joint"]["loss"]]
    assert misses["combination-holdout"] == [] and len(misses["combination"]) == 1
    (pred, joint), = misses["combination"]
    assert (joint["loss"] - pred) < 0.1 * joint["se"]
