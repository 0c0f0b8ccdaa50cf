"""The one loss formula (fidelity.coco.loss) against hand-computed numbers and a numpy
re-derivation: points, relative, their paired fold SEs, a zero baseline, equal scores and a
single fold."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from fidelity.coco.loss import (
    LOSS_COLUMNS,
    Losses,
    LossEstimate,
    loss_estimate,
    paired_standard_error,
    score_loss,
)


@dataclass(frozen=True)
class _Fold:
    map: float | None
    person: float | None = None

    def value(self, key: str) -> float | None:
        return {"map": self.map, "person": self.person, "bicycle": None}[key]


def test_points_and_relative_by_hand() -> None:
    # baseline 0.40, cell 0.37: 3 points, 7.5 % of the baseline
    e = loss_estimate(0.40, 0.37)
    assert e.points == pytest.approx(3.0)
    assert e.relative == pytest.approx(7.5)
    assert e.points_se is None and e.relative_se is None


def test_standard_errors_by_hand() -> None:
    # folds: baselines 0.5, 0.4, 0.6, cells 0.45, 0.38, 0.51
    # points 5, 2, 9: mean 16/3, sd sqrt(37/3)... SE = sd / sqrt 3
    # relative 10, 5, 15 %: sd 5, SE 5 / sqrt 3
    e = loss_estimate(0.5, 0.45, [0.5, 0.4, 0.6], [0.45, 0.38, 0.51])
    d = np.array([5.0, 2.0, 9.0])
    sd = math.sqrt(((d - d.mean()) ** 2).sum() / 2)
    assert sd == pytest.approx(math.sqrt(37 / 3))
    assert e.points_se == pytest.approx(sd / math.sqrt(3))
    assert e.relative_se == pytest.approx(5 / math.sqrt(3))
    assert e.points == pytest.approx(5.0)
    assert e.relative == pytest.approx(10.0)


def test_standard_errors_against_numpy() -> None:
    rng = np.random.default_rng(33)
    b = rng.uniform(0.2, 0.6, 5)
    o = b - rng.uniform(-0.01, 0.05, 5)
    e = loss_estimate(float(b.mean()), float(o.mean()), list(b), list(o))
    assert e.points_se == pytest.approx(np.std(100 * (b - o), ddof=1) / np.sqrt(5), rel=1e-12)
    assert e.relative_se == pytest.approx(np.std(100 * (b - o) / b, ddof=1) / np.sqrt(5),
                                          rel=1e-12)


def test_zero_baseline_has_no_relative_loss() -> None:
    # one rule everywhere: relative loss and its SE undefined for a baseline of 0
    e = loss_estimate(0.0, 0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert e == LossEstimate(0.0, None, 0.0, None)
    e = loss_estimate(0.0, 0.01, [0.0, 0.1], [0.0, 0.0])
    assert e.points == pytest.approx(-1.0)
    assert e.relative is None and e.relative_se is None
    assert e.points_se == pytest.approx(5.0)  # fold losses 0 and 10 points: sd 10/sqrt 2


def test_zero_baseline_fold_is_left_out_of_the_relative_se() -> None:
    # relative losses 50 % and 25 % (the zero-baseline fold left out): SE 12.5
    e = loss_estimate(0.4, 0.25, [0.4, 0.4, 0.0], [0.2, 0.3, 0.0])
    assert e.relative_se == pytest.approx(12.5)
    # points 20, 10, 0: sd 10, SE 10 / sqrt 3
    assert e.points_se == pytest.approx(10 / math.sqrt(3))


def test_equal_scores_lose_nothing() -> None:
    e = loss_estimate(0.37, 0.37, [0.3, 0.4, 0.41], [0.3, 0.4, 0.41])
    assert e == LossEstimate(0.0, 0.0, 0.0, 0.0)


def test_single_fold_has_no_standard_error() -> None:
    e = loss_estimate(0.4, 0.3, [0.4], [0.3])
    assert e.points == pytest.approx(10.0)
    assert e.relative == pytest.approx(25.0)
    assert e.points_se is None and e.relative_se is None
    assert paired_standard_error([0.4, None], [0.3, 0.2]) is None


def test_missing_score_gives_no_loss() -> None:
    assert loss_estimate(None, 0.3, [0.4, 0.5], [0.3, 0.4]) == LossEstimate(None, None)
    assert loss_estimate(0.3, None) == LossEstimate(None, None)


def test_score_loss_reads_folds_by_name() -> None:
    base = {"map": 0.5, "person": 0.6}
    cell = {"map": 0.45, "person": 0.3}
    folds_b = [_Fold(0.5, 0.6), _Fold(0.4, 0.5), _Fold(0.6, 0.7)]
    folds_c = [_Fold(0.45, 0.3), _Fold(0.38, 0.25), _Fold(0.51, 0.35)]
    assert score_loss("map", base, cell, folds_b, folds_c) == loss_estimate(
        0.5, 0.45, [0.5, 0.4, 0.6], [0.45, 0.38, 0.51])
    person = score_loss("person", base, cell, folds_b, folds_c)
    assert person.points == pytest.approx(30.0)
    assert person.relative == pytest.approx(50.0)
    assert person.relative_se == pytest.approx(0.0, abs=1e-12)  # every fold loses half
    assert score_loss("bicycle", base, cell, folds_b, folds_c) == LossEstimate(None, None)


def test_losses_by_column() -> None:
    assert LOSS_COLUMNS == {"all": "dmap_points", "all-relative": "dmap_relative",
                            "person": "dap_person_points", "bicycle": "dap_bicycle_points"}
    loss = Losses(1.0, 2.0, 3.0, None)
    assert [loss.get(c) for c in LOSS_COLUMNS.values()] == [1.0, 2.0, 3.0, None]
    assert list(loss.to_json()) == list(LOSS_COLUMNS.values())
    assert Losses.from_json(loss.to_json()) == loss
