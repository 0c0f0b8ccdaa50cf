"""The detection loss of a transformed cell against its baseline, and its standard error.

One formula for the sweep tables (:mod:`fidelity.coco.tables`), the validation
(:mod:`fidelity.coco.validate`) and the ``--measure`` runs (:mod:`fidelity.coco.measure`).
Scores are fractions in [0, 1] (COCO mAP@[.50:.95] or a class's AP); with ``scale = 100``:

* loss in points: ``points = 100 * (base - value)`` (percentage points);
* relative loss: ``relative = 100 * (base - value) / base`` (percent of the baseline);
* the standard error of that whole-run loss: the larger of two estimators of it, each
  checked against the spread of losses over disjoint image subsets (the reference that assumes
  nothing about mAP; reports/validation/standard_error.md):

  - the paired image bootstrap, the standard deviation over B draws of the images with
    replacement of ``100 * (b*_b - o*_b)``, both runs scored on the same draw ``b``
    (:func:`fidelity.coco.bootstrap.draw_scores`: B = 200, a fixed seed; one COCO evaluation per
    run, the draws by re-weighting its matches);
  - the leave-one-fold-out (delete-a-group) jackknife over K = 5 disjoint interleaved image
    folds, ``SE = sqrt((K - 1) / K * sum_k (L_(k) - mean L)^2)``, with ``L_(k)`` the loss of
    the run without fold k;

  where only one of them can be computed (stores and tables of earlier versions), that one;
  where neither, the paired fold SE ``std(d_k, ddof=1) / sqrt(K)`` of the per-fold losses
  ``d_k = 100 * (b_k - o_k)`` (relative: ``/ b_k``).

**Why the larger of the two.** mAP pools every image's detections into one precision-recall
curve per class, so the whole-run loss is not the mean of the fold losses, and the fold SE
describes the mean of the fold losses, not it: against the split-sample reference on YOLOX-nano
it is 0.54x at 250 images (55 % of the residuals within 2 SE). Neither whole-run estimator is
right alone on a few hundred images, where rare classes' few boxes dominate the spread: the
bootstrap understates (0.60x at 250 images, 0.72x at 500; 72 % within 2 SE), the jackknife is
of the right size on average (0.94x, 0.83x) but badly shaped (84 % within 2 SE, mean z² 5.4:
small on some cells, large on others; on single 1000-image cells 1.9-2.8x the bootstrap). The
larger of the two per cell is 0.94x and 0.90x with 86 % within 2 SE and mean z² 1.7, the best
calibrated of the four, and errs on the side an assessor can accept.

**Zero baseline.** A relative loss is undefined where the baseline is not positive: the
relative loss is None when ``base <= 0``, and so is its SE; a fold with ``b_k <= 0`` is left
out of the relative SE (a draw with ``b*_b <= 0`` likewise). An SE needs at least 2 usable
folds or draws (None otherwise).

Source: the bootstrap standard error (Efron & Tibshirani, *An Introduction to the Bootstrap*,
1993, ch. 6, algorithm 6.1; paired samples ch. 8); the delete-a-group jackknife (ibid.
ch. 11.5, eq. 11.13 with groups of n/K; Kott, "The delete-a-group jackknife", J. Official
Statistics 17, 2001); the paired-difference SE of K-fold means (ibid. ch. 2). The folds and
their leave-one-out scores are :func:`fidelity.coco.scoring.score_folds`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from fidelity.core.record import record

#: Loss columns compared by class (``all`` = mAP@[.50:.95] over the 80 COCO classes) ->
#: prediction-table column names (:data:`fidelity.prediction.tablefile.COLUMNS`).
LOSS_COLUMNS: dict[str, str] = {
    "all": "dmap_points",
    "all-relative": "dmap_relative",
    "person": "dap_person_points",
    "bicycle": "dap_bicycle_points",
}

#: Percentage points per unit of score (scores are fractions).
SCALE = 100.0


def paired_standard_error(base: Sequence[float | None], other: Sequence[float | None],
                          scale: float = SCALE, relative: bool = False) -> float | None:
    """SE of ``scale * mean(base - other)`` from per-fold values (None where a fold lacks one).

    Parameters
    ----------
    base, other
        Per-fold scores (fractions) of the baseline and the transformed run, fold by fold.
    scale
        Units of the loss per unit of score (100: percentage points).
    relative
        The per-fold loss as a share of that fold's own base, ``d_k = scale * (b_k - o_k) /
        b_k`` (folds with ``b_k <= 0`` left out): the SE of a relative loss (percent of the
        baseline). A loss proportional to the baseline (mAP -> 0 loses 100 % on every fold)
        has no spread there, while its spread in points carries the folds' different
        baselines.

    Returns
    -------
    float or None
        ``std(d_k, ddof=1) / sqrt(K)`` over the K folds where both values exist (and, relative,
        the base is positive); None with fewer than 2 such folds.
    """
    d = [scale * (b - o) / (b if relative else 1.0)
         for b, o in zip(base, other, strict=True)
         if b is not None and o is not None and (not relative or b > 0)]
    if len(d) < 2:
        return None
    return float(np.std(d, ddof=1) / np.sqrt(len(d)))


def jackknife_standard_error(base_rest: Sequence[float | None],
                             other_rest: Sequence[float | None], scale: float = SCALE,
                             relative: bool = False) -> float | None:
    """Leave-one-fold-out jackknife SE of the whole-run loss ``scale * (base - other)``.

    Parameters
    ----------
    base_rest, other_rest
        Per fold k, the score (fraction) of the baseline and of the transformed run on every
        image *but* fold k's (None where not computed or defined).
    scale
        Units of the loss per unit of score (100: percentage points).
    relative
        The loss as a share of the baseline, ``scale * (b_(k) - o_(k)) / b_(k)``.

    Returns
    -------
    float or None
        ``sqrt((K - 1) / K * sum_k (L_(k) - mean L)^2)`` over the K folds; None unless every
        fold has both values (and, relative, a positive baseline) and K >= 2: a jackknife
        with a fold left out is not one.
    """
    if len(base_rest) != len(other_rest):
        raise ValueError("base_rest and other_rest differ in length")
    k = len(base_rest)
    if k < 2:
        return None
    d = []
    for b, o in zip(base_rest, other_rest, strict=True):
        if b is None or o is None or (relative and b <= 0):
            return None
        d.append(scale * (b - o) / (b if relative else 1.0))
    x = np.asarray(d)
    return float(np.sqrt((k - 1) / k * np.sum((x - x.mean()) ** 2)))


def bootstrap_standard_error(base_draws: Sequence[float | None],
                             other_draws: Sequence[float | None], relative: bool = False,
                             scale: float = SCALE) -> float | None:
    """Paired image-bootstrap SE of a whole-run loss: the standard deviation (``ddof=1``) over
    draws ``b`` of ``scale * (base_b - other_b)`` (``/ base_b`` when ``relative``), both runs
    scored on the same drawn images (:func:`fidelity.coco.bootstrap.draw_scores`).

    A draw where either score is None (no ground truth of the class in it) or, relative, the
    baseline is not positive, is left out; None with fewer than 2 usable draws or unequal
    lengths.
    """
    if len(base_draws) != len(other_draws):
        return None
    d = [scale * (b - o) / (b if relative else 1.0)
         for b, o in zip(base_draws, other_draws, strict=True)
         if b is not None and o is not None and (b > 0 or not relative)]
    if len(d) < 2:
        return None
    return float(np.std(np.asarray(d), ddof=1))


@record
class LossEstimate:
    """A loss and its paired fold standard errors (:func:`loss_estimate`).

    ``points``: ``100 * (base - value)`` (percentage points); ``relative``: percent of the
    baseline (None when the baseline is not positive); ``points_se``, ``relative_se``: their
    standard errors (jackknife, else paired fold SE: module docstring; None with fewer than 2
    usable folds, and ``relative_se`` None whenever ``relative`` is); ``se_method``:
    ``"jackknife"``, ``"folds"`` or None (no SE). Every field is None where the baseline or the
    value is missing.
    """

    points: float | None
    relative: float | None
    points_se: float | None = None
    relative_se: float | None = None
    se_method: str | None = None


def loss_estimate(base: float | None, value: float | None,
                  base_folds: Sequence[float | None] = (),
                  folds: Sequence[float | None] = (),
                  base_rest: Sequence[float | None] = (),
                  rest: Sequence[float | None] = (),
                  base_draws: Sequence[float | None] = (),
                  draws: Sequence[float | None] = ()) -> LossEstimate:
    """The loss of ``value`` against ``base`` and its standard errors (module docstring).

    Parameters
    ----------
    base, value
        Scores (fractions in [0, 1]) of the baseline and the transformed cell on the same
        images; None where a score does not exist (a class without ground truth).
    base_folds, folds
        The same scores per image fold (equal lengths; empty: no standard errors).
    base_rest, rest
        The same scores of the run without each fold (equal lengths; empty or with a None:
        the paired fold SE instead of the jackknife).
    base_draws, draws
        The same scores on paired image-bootstrap draws (equal lengths; empty: no bootstrap).
        Where they and the rest scores both give an SE, the larger one is returned
        (``se_method="larger"``); where only the draws do, the bootstrap's.

    Returns
    -------
    LossEstimate
        Points and relative loss (percent of the baseline, None for a baseline <= 0) with
        their SEs and which estimator gave them.
    """
    if base is None or value is None:
        return LossEstimate(None, None)
    points = SCALE * (base - value)
    defined = base > 0
    relative = SCALE * (base - value) / base if defined else None
    boot = bootstrap_standard_error(base_draws, draws) if base_draws or draws else None
    jack = jackknife_standard_error(base_rest, rest) if base_rest or rest else None
    if boot is not None and jack is not None:
        rel = [x for x in (bootstrap_standard_error(base_draws, draws, relative=True),
                           jackknife_standard_error(base_rest, rest, relative=True))
               if x is not None] if defined else []
        return LossEstimate(points=points, relative=relative, points_se=max(boot, jack),
                            relative_se=max(rel) if rel else None, se_method="larger")
    if boot is not None:
        return LossEstimate(
            points=points, relative=relative, points_se=boot,
            relative_se=bootstrap_standard_error(base_draws, draws, relative=True) if defined
            else None, se_method="bootstrap")
    se = jack
    if se is not None:
        return LossEstimate(
            points=points, relative=SCALE * (base - value) / base if defined else None,
            points_se=se,
            relative_se=jackknife_standard_error(base_rest, rest, relative=True) if defined
            else None, se_method="jackknife")
    se = paired_standard_error(base_folds, folds)
    return LossEstimate(
        points=points,
        relative=SCALE * (base - value) / base if defined else None,
        points_se=se,
        relative_se=paired_standard_error(base_folds, folds, relative=True) if defined
        else None, se_method="folds" if se is not None else None)


class FoldValues(Protocol):
    """Scores of one image fold by name (:class:`fidelity.coco.scoring.FoldScore`)."""

    def value(self, key: str) -> float | None:
        """The fold's score ``key`` (``"map"``, ``"person"``, ``"bicycle"``), a fraction."""

    def rest_value(self, key: str) -> float | None:
        """The score ``key`` of the run without this fold (None: not computed)."""


class DrawValues(Protocol):
    """Scores of one run on bootstrap draws (:class:`fidelity.coco.bootstrap.Draws`)."""

    def value(self, key: str) -> Sequence[float | None]:
        """The draws of score ``key``, fractions (None: no ground truth of it in a draw)."""

    def pairs_with(self, other: Any) -> bool:
        """Whether both runs' draw ``b`` drew the same images."""


def score_loss(key: str, base: Mapping[str, float | None], value: Mapping[str, float | None],
               base_folds: Sequence[FoldValues] = (),
               folds: Sequence[FoldValues] = (),
               base_draws: DrawValues | None = None,
               draws: DrawValues | None = None) -> LossEstimate:
    """:func:`loss_estimate` of score ``key`` (``"map"``, ``"person"``, ``"bicycle"``).

    Parameters
    ----------
    key
        The score compared.
    base, value
        Scores by name (fractions) of the baseline and the cell; a missing key is None.
    base_folds, folds
        Per-fold scores of the baseline and the cell (:func:`fidelity.coco.scoring.score_folds`).
    base_draws, draws
        Both runs' scores on paired bootstrap draws (:func:`fidelity.coco.bootstrap.draw_scores`;
        used where both exist and pair, then the SE is the bootstrap's).
    """
    paired = base_draws is not None and draws is not None and base_draws.pairs_with(draws)
    return loss_estimate(base.get(key), value.get(key), [f.value(key) for f in base_folds],
                         [f.value(key) for f in folds], [f.rest_value(key) for f in base_folds],
                         [f.rest_value(key) for f in folds],
                         base_draws.value(key) if paired and base_draws else (),
                         draws.value(key) if paired and draws else ())


@record
class Losses:
    """Losses by prediction-table column (:data:`LOSS_COLUMNS`): ΔmAP in points and relative
    (% of baseline), ΔAP of person and bicycle in points; None where not defined."""

    dmap_points: float | None
    dmap_relative: float | None
    dap_person_points: float | None
    dap_bicycle_points: float | None

    def get(self, column: str) -> float | None:
        """The loss of ``column`` (a value of :data:`LOSS_COLUMNS`)."""
        return {"dmap_points": self.dmap_points, "dmap_relative": self.dmap_relative,
                "dap_person_points": self.dap_person_points,
                "dap_bicycle_points": self.dap_bicycle_points}[column]

    def to_json(self, keys: Sequence[str] = tuple(LOSS_COLUMNS.values())) -> dict[str, Any]:
        """``{column: value}`` in the order ``keys``."""
        return {k: self.get(k) for k in keys}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Losses:
        """Inverse of :meth:`to_json`."""
        return cls(d.get("dmap_points"), d.get("dmap_relative"), d.get("dap_person_points"),
                   d.get("dap_bicycle_points"))


__all__ = [
    "LOSS_COLUMNS",
    "SCALE",
    "FoldValues",
    "LossEstimate",
    "Losses",
    "jackknife_standard_error",
    "loss_estimate",
    "paired_standard_error",
    "score_loss",
]
