"""The one loss formula (fidelity.coco.loss) against hand-computed numbers and a numpy
re-derivation: points, relative, their paired fold SEs and jackknife SEs (against the closed
form a jackknife of a mean has), a zero baseline, equal scores and a single fold."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from fidelity.coco.loss import (
    LOSS_COLUMNS,
    Losses,
    LossEstimate,
    jackknife_standard_error,
    loss_estimate,
    paired_standard_error,
    score_loss,
)


@dataclass(frozen=True)
class _Fold:
    map: float | None
    person: float | None = None
    rest_map: float | None = None

    def value(self, key: str) -> float | None:
        return {"map": self.map, "person": self.person, "bicycle": None}[key]

    def rest_value(self, key: str) -> float | None:
        return {"map": self.rest_map, "person": None, "bicycle": None}[key]


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
    assert e == LossEstimate(0.0, None, 0.0, None, "folds")
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
    assert e == LossEstimate(0.0, 0.0, 0.0, 0.0, "folds")


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


def _additive_scores(rng: np.random.Generator, n: int, k: int
                     ) -> tuple[float, list[float], list[float]]:
    """A score that is the mean of per-image values: whole run, per fold, run without fold."""
    x = rng.normal(0.4, 0.1, n)
    folds = [x[j::k] for j in range(k)]
    rest = [np.concatenate([f for i, f in enumerate(folds) if i != j]) for j in range(k)]
    return float(x.mean()), [float(f.mean()) for f in folds], [float(r.mean()) for r in rest]


@pytest.mark.parametrize(("n", "k"), [(50, 5), (1000, 5), (12, 3)])
def test_jackknife_of_a_mean_is_the_fold_se(n: int, k: int) -> None:
    # closed form: for a statistic that is a mean over images, folds of equal size, the
    # delete-a-group jackknife SE equals sd(fold means)/sqrt(K) (Efron & Tibshirani 11.5)
    rng = np.random.default_rng(n)
    b, bf, br = _additive_scores(rng, n, k)
    o, of, orr = _additive_scores(rng, n, k)
    jk = jackknife_standard_error(br, orr)
    assert jk == pytest.approx(paired_standard_error(bf, of), rel=1e-9)
    e = loss_estimate(b, o, bf, of, br, orr)
    assert (e.points_se, e.se_method) == (pytest.approx(jk), "jackknife")


def test_jackknife_by_hand() -> None:
    # leave-out losses 2, 4, 6 points: mean 4, sum of squares 8, (K-1)/K = 2/3
    se = jackknife_standard_error([0.50, 0.50, 0.50], [0.48, 0.46, 0.44])
    assert se == pytest.approx(math.sqrt(2 / 3 * 8))
    # relative: losses 4 %, 8 %, 12 % of 0.5
    rel = jackknife_standard_error([0.50, 0.50, 0.50], [0.48, 0.46, 0.44], relative=True)
    assert rel == pytest.approx(math.sqrt(2 / 3 * 32))


def test_jackknife_needs_every_fold() -> None:
    # a fold without its leave-out score is no jackknife: None, and the loss falls back to
    # the paired fold SE
    assert jackknife_standard_error([0.5, None, 0.5], [0.4, 0.4, 0.4]) is None
    assert jackknife_standard_error([0.5], [0.4]) is None
    assert jackknife_standard_error([], []) is None
    assert jackknife_standard_error([0.0, 0.5], [0.0, 0.4], relative=True) is None
    with pytest.raises(ValueError, match="length"):
        jackknife_standard_error([0.5, 0.5], [0.4])
    e = loss_estimate(0.5, 0.45, [0.5, 0.4, 0.6], [0.45, 0.38, 0.51], [0.5, None, 0.5],
                      [0.45, 0.4, 0.45])
    assert e.se_method == "folds"
    assert e.points_se == paired_standard_error([0.5, 0.4, 0.6], [0.45, 0.38, 0.51])


def test_jackknife_zero_and_tiny_scores() -> None:
    # equal leave-out losses: SE exactly 0; denormal scores give finite numbers, never NaN
    assert jackknife_standard_error([0.3, 0.4], [0.3, 0.4]) == 0.0
    tiny = 5e-324
    se = jackknife_standard_error([tiny, 2 * tiny, tiny], [0.0, 0.0, tiny])
    assert se is not None and math.isfinite(se)
    rel = jackknife_standard_error([tiny, 2 * tiny], [0.0, tiny], relative=True)
    assert rel is not None and math.isfinite(rel)


def test_score_loss_uses_the_rest_scores() -> None:
    base, cell = {"map": 0.5}, {"map": 0.45}
    folds_b = [_Fold(0.5, rest_map=0.50), _Fold(0.4, rest_map=0.55), _Fold(0.6, rest_map=0.45)]
    folds_c = [_Fold(0.45, rest_map=0.44), _Fold(0.38, rest_map=0.50), _Fold(0.51, rest_map=0.41)]
    e = score_loss("map", base, cell, folds_b, folds_c)
    assert e.se_method == "jackknife"
    assert e.points_se == pytest.approx(jackknife_standard_error([0.50, 0.55, 0.45],
                                                                 [0.44, 0.50, 0.41]))


def test_fold_score_json_with_and_without_rest() -> None:
    from fidelity.coco.scoring import FoldScore

    f = FoldScore(0.4, 0.5, None, 200, 0.41, 0.52, None)
    assert f.has_rest and FoldScore.from_json(f.to_json()) == f
    old = {"map": 0.4, "person": 0.5, "bicycle": None, "images": 200}  # stored before
    g = FoldScore.from_json(old)
    assert not g.has_rest and g.rest_value("map") is None and g.to_json() == old
    assert FoldScore(0.4, None, None, 1, 0.0).has_rest  # a rest score of 0 is a score


def test_bootstrap_se_by_hand_and_against_numpy() -> None:
    from fidelity.coco.loss import bootstrap_standard_error

    base, other = [0.5, 0.4, 0.45], [0.4, 0.4, 0.42]
    d = np.array([10.0, 0.0, 3.0])
    assert bootstrap_standard_error(base, other) == pytest.approx(np.std(d, ddof=1), abs=1e-12)
    rel = d / np.array(base)
    assert bootstrap_standard_error(base, other, relative=True) == pytest.approx(
        np.std(rel, ddof=1), abs=1e-12)
    rng = np.random.default_rng(3)
    b, o = rng.uniform(0.2, 0.5, 200), rng.uniform(0.2, 0.5, 200)
    assert bootstrap_standard_error(list(b), list(o)) == pytest.approx(
        np.std(100 * (b - o), ddof=1), rel=1e-12)


def test_bootstrap_se_hard_cases() -> None:
    from fidelity.coco.loss import bootstrap_standard_error

    # a draw without the class (None) is left out; fewer than 2 usable draws: no SE
    assert bootstrap_standard_error([0.5, None, 0.4], [0.4, 0.3, 0.4]) == pytest.approx(
        np.std([10.0, 0.0], ddof=1))
    assert bootstrap_standard_error([0.5, None], [0.4, 0.3]) is None
    assert bootstrap_standard_error([], []) is None
    assert bootstrap_standard_error([0.5, 0.4], [0.4]) is None  # unequal: not paired
    # a zero baseline draw is left out of the relative SE only
    assert bootstrap_standard_error([0.0, 0.5, 0.4], [0.0, 0.4, 0.4], relative=True) == \
        pytest.approx(np.std([20.0, 0.0], ddof=1))
    # identical runs: SE 0, never NaN; denormal scores stay finite
    assert bootstrap_standard_error([0.3] * 5, [0.3] * 5) == 0.0
    tiny = bootstrap_standard_error([5e-324, 1e-310, 0.0], [0.0, 0.0, 5e-324])
    assert tiny is not None and math.isfinite(tiny)


def test_loss_estimate_takes_the_larger_of_bootstrap_and_jackknife() -> None:
    folds_b, folds_o = [0.5, 0.4, 0.45], [0.45, 0.4, 0.4]
    rest_b, rest_o = [0.44, 0.47, 0.45], [0.41, 0.42, 0.43]
    jk = jackknife_standard_error(rest_b, rest_o)
    wide, narrow = ([0.45, 0.50, 0.40], [0.42, 0.41, 0.43]), ([0.45, 0.46, 0.44],
                                                               [0.42, 0.43, 0.41])
    for draws in (wide, narrow):
        both = loss_estimate(0.45, 0.42, folds_b, folds_o, rest_b, rest_o, *draws)
        boot = float(np.std(100 * (np.array(draws[0]) - draws[1]), ddof=1))
        assert both.se_method == "larger"
        assert both.points_se == pytest.approx(max(boot, jk))
    assert boot < jk < float(np.std(100 * (np.array(wide[0]) - wide[1]), ddof=1))
    only = loss_estimate(0.45, 0.42, (), (), (), (), *wide)
    assert only.se_method == "bootstrap"
    assert loss_estimate(0.45, 0.42, folds_b, folds_o, rest_b, rest_o).se_method == "jackknife"
    # draws that give no SE (one usable draw) fall back to the jackknife
    assert loss_estimate(0.45, 0.42, folds_b, folds_o, rest_b, rest_o, [0.45, None],
                         [0.42, 0.4]).se_method == "jackknife"


def test_score_loss_pairs_draws_only_of_the_same_images() -> None:
    from fidelity.coco.bootstrap import Draws

    base = Draws(3, 1, 10, (0.5, 0.4, 0.45), (0.6, None, 0.5), (None, None, None))
    cell = Draws(3, 1, 10, (0.4, 0.4, 0.42), (0.5, 0.5, 0.5), (None, None, None))
    other_seed = Draws(3, 2, 10, cell.map, cell.person, cell.bicycle)
    scores = {"map": 0.45, "person": 0.55, "bicycle": None}
    got = score_loss("map", scores, {"map": 0.42, "person": 0.5}, (), (), base, cell)
    assert got.se_method == "bootstrap"
    assert got.points_se == pytest.approx(np.std([10.0, 0.0, 3.0], ddof=1))
    person = score_loss("person", scores, {"map": 0.42, "person": 0.5}, (), (), base, cell)
    assert person.points_se == pytest.approx(np.std([10.0, 0.0], ddof=1))
    unpaired = score_loss("map", scores, {"map": 0.42}, (), (), base, other_seed)
    assert unpaired.points_se is None and unpaired.se_method is None
    assert Draws.from_json(base.to_json()) == base
    from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED

    assert not base.current  # 3 draws, seed 1: a store scores such a cell again
    assert Draws(BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, 10, (), (), ()).current
