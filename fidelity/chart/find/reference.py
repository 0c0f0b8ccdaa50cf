"""The 24-patch reference layout, and how patches sampled from an image are compared with it.

The finder knows one layout (:data:`ROWS` x :data:`COLS`, the ColorChecker's 24 patches):
:func:`grid_cells` and :func:`corner_centres` place it on a grid, :func:`colour_order` and
:func:`neutral_order` score measured patches against the reference by rank (unchanged by a
per-channel gain or a monotone tone curve), and :func:`occluded_patches` names the patches
that look covered (a leaf, a hand, a glare) rather than rendered by the camera.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.locate import apply_homography
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_chart
from fidelity.core.numeric import median

F64 = NDArray[np.float64]

#: Reference chart rows and columns: the finder knows the 24-patch layout only.
ROWS, COLS = 4, 6
#: A patch whose colour is this many times the chart's median distance from the best 3 x 3
#: camera matrix fitted to its patches is covered (a leaf, a hand, a glare).
OCCLUDED_RESIDUAL = 8.0
#: ... or whose rank disagreement (summed over the five features) is at least this and three
#: times the median, while its window is textured (relative spread at least
#: :data:`OCCLUDED_SPREAD` and five times the median).
OCCLUDED_RANKS = 15.0
#: Least relative spread of a patch's window for it to count as textured (and at least five
#: times the median spread): what an object over the patch brings, a printed patch has not.
OCCLUDED_SPREAD = 0.03
#: Indices of the neutral patches, white to black, in the 24-patch layout.
NEUTRALS = np.arange(18, 24)


def grid_cells() -> F64:
    """The 24 cells ``(u, v)`` of the layout, in chart order (dark skin first, row by row)."""
    r, c = np.mgrid[0:ROWS, 0:COLS]
    return np.stack([c.ravel(), r.ravel()], axis=-1).astype(np.float64)


def corner_centres(h: np.ndarray) -> F64:
    """``(4, 2)``: the dark skin, bluish green, black and white cells mapped by the grid
    homography ``h``."""
    return apply_homography(h, np.array([[0, 0], [COLS - 1, 0], [COLS - 1, ROWS - 1],
                                         [0, ROWS - 1]], dtype=float))


def _reference_linear() -> F64:
    """The reference chart's 24 patches as linear sRGB ``(24, 3)``."""
    return np.asarray(cm.linearize_srgb(load_chart().srgb), dtype=np.float64)


def _features(rgb: np.ndarray) -> np.ndarray:
    """``(..., 24, 3)`` linear RGB -> ``(..., 24, 5)``: R, G, B, log(R/G), log(B/G)."""
    lg = np.log(np.maximum(rgb, 0.0) + 2e-3)
    return np.concatenate([rgb, lg[..., :1] - lg[..., 1:2], lg[..., 2:3] - lg[..., 1:2]], axis=-1)


def average_ranks(x: np.ndarray) -> F64:
    """Ranks (0-based) along axis -2, ties given their average rank, of a ``(..., n, f)`` array
    of finite values."""
    a = np.moveaxis(np.asarray(x, np.float64), -2, -1)  # (..., f, n)
    shape = a.shape
    rows = a.reshape(-1, shape[-1])
    span = float(np.ptp(rows)) + 1.0 if rows.size else 1.0
    # put every row in its own range of values, so that one sorted array serves them all
    offset = (np.arange(len(rows)) * 2.0 * span)[:, None] - float(rows.min(initial=0.0))
    flat = (rows + offset).ravel()
    ordered = np.sort(flat)
    less = np.searchsorted(ordered, flat, "left")
    leq = np.searchsorted(ordered, flat, "right")
    start = (np.arange(len(rows)) * shape[-1])[:, None]
    ranks = ((less + leq - 1) / 2.0).reshape(rows.shape) - start
    return np.moveaxis(ranks.reshape(shape), -1, -2)


def colour_order(measured: np.ndarray, reference: np.ndarray | None = None, trim: int = 0,
                 exclude: np.ndarray | None = None) -> F64:
    """Mean Spearman rank correlation of ``(..., 24, 3)`` measured linear RGB with the reference.

    Over the five features R, G, B, log(R/G), log(B/G) of the 24 patches (ties, such as
    clipped patches, get their average rank); 1 when every feature orders the patches as the
    reference does. Ranks are unchanged by a per-channel gain or any increasing tone curve, so
    coloured light, white balance and exposure leave it near 1. ``trim`` leaves out that many
    patches that disagree most (summed absolute rank difference), and ranks the rest again: a
    patch covered by a finger or a glare costs the chart little. ``exclude`` ``(n,)`` leaves
    out those patches instead (known to be covered: :func:`occluded_patches`).
    """
    ref = _reference_linear() if reference is None else np.asarray(reference, np.float64)
    fm = _features(np.asarray(measured, np.float64))
    fr = np.broadcast_to(_features(ref), fm.shape)
    n = fm.shape[-2]
    if exclude is not None and np.any(exclude):
        drop = np.broadcast_to(np.asarray(exclude, dtype=bool), fm.shape[:-1])
        trim = int(np.count_nonzero(exclude))
    elif trim:
        d = np.abs(average_ranks(fm) - average_ranks(fr)).sum(axis=-1)  # (..., n)
        worst = np.argsort(-d, axis=-1, kind="stable")[..., :trim]
        drop = np.zeros(d.shape, dtype=bool)
        np.put_along_axis(drop, worst, True, axis=-1)
    if trim:
        # dropped patches move above every kept one, so the kept are ranked among themselves
        top_m = fm.max(axis=-2, keepdims=True) + 1.0
        top_r = fr.max(axis=-2, keepdims=True) + 1.0
        fm = np.where(drop[..., None], top_m, fm)
        fr = np.where(drop[..., None], top_r, fr)
        diff = np.where(drop[..., None], 0.0, average_ranks(fm) - average_ranks(fr))
        n -= trim
    else:
        diff = average_ranks(fm) - average_ranks(fr)
    rho = 1.0 - 6.0 * np.sum(diff ** 2, axis=-2) / (n * (n * n - 1))
    return np.asarray(rho.mean(axis=-1))


def neutral_order(measured: np.ndarray, use: np.ndarray | None = None) -> np.ndarray:
    """Fraction of the 15 pairs of neutral patches (white ... black) whose measured lightness
    (R + G + B) is in the reference order (ties count as in order); ``use`` ``(6,)``: only
    the pairs of those neutral patches (the others covered; 1 when fewer than 2 are left)."""
    y = np.asarray(measured)[..., NEUTRALS, :].sum(axis=-1)
    i, j = np.triu_indices(len(NEUTRALS), 1)
    if use is not None:
        ok = np.asarray(use, dtype=bool)
        pair = ok[i] & ok[j]
        if not pair.any():
            return np.ones(y.shape[:-1])
        i, j = i[pair], j[pair]
    return np.asarray(np.mean(y[..., i] >= y[..., j] - 1e-6, axis=-1))


def off_the_camera_fit(measured: np.ndarray) -> np.ndarray:
    """``(24,)`` bool: patches whose linear RGB lies far from the best 3 x 3 camera matrix fitted
    to the others (the first cue of :func:`occluded_patches`), textured or not."""
    m = np.asarray(measured, np.float64)
    ref = _reference_linear()
    keep = np.ones(len(m), dtype=bool)
    residual = np.zeros(len(m))
    for _ in range(3):
        matrix, *_ = np.linalg.lstsq(ref[keep], m[keep], rcond=None)
        pred = ref @ matrix
        white = float(np.linalg.norm(pred[NEUTRALS[0]]))
        residual = (np.linalg.norm(m - pred, axis=-1)
                    / (np.linalg.norm(pred, axis=-1) + 0.05 * white + 1e-6))
        keep = residual <= np.sort(residual)[len(m) - 1 - 6]
    return np.asarray(residual > OCCLUDED_RESIDUAL * max(median(residual), 1e-3))


def occluded_patches(measured: np.ndarray, spread: np.ndarray, strict: bool = False
                     ) -> np.ndarray:
    """Which of the 24 patches of a placement are covered (a leaf, a hand, a glare).

    Two cues, each independent of how well the camera renders colour: the patch's linear RGB
    lies far from the best 3 x 3 camera matrix fitted to the chart (reference linear sRGB ->
    measured, least squares over the 18 patches that fit best, three rounds; distance
    relative to the predicted colour plus 5 % of the predicted white) at more than
    :data:`OCCLUDED_RESIDUAL` times the median distance; or it disagrees in rank with the
    reference (:func:`colour_order`'s per-patch disagreement at least :data:`OCCLUDED_RANKS`
    and three times the median) while its window is textured (relative spread at least
    :data:`OCCLUDED_SPREAD` and five times the median); either cue counts only for a textured
    window, so that a camera's own error in one flat patch is never taken for a cover. A
    camera's colour error moves all patches smoothly, a hue rotation or a tone curve too; an
    object over two patches moves those alone. ``(24, 3)`` means and ``(24,)`` spreads (:func:`~fidelity.chart.find.placement.sample_cells`) -> ``(24,)``
    bool (more than :data:`~fidelity.chart.find.placement.MAX_OCCLUDED`: a placement that is not the chart, or a chart too
    covered to measure). ``strict``: only patches both far off the fit and textured (for a
    window near the patch edges, where blur and chroma subsampling bleed in)."""
    m = np.asarray(measured, np.float64)
    sp = np.asarray(spread, np.float64)
    ref = _reference_linear()
    far = off_the_camera_fit(m)
    ranks = np.abs(average_ranks(_features(m)) - average_ranks(_features(ref))).sum(axis=-1)
    # the spread relative to the patch's mean plus a tenth of white: noise in a dark patch
    # is not texture
    level = m.mean(axis=-1)
    texture = sp * (level + 0.02) / (level + 0.1 * float(m[NEUTRALS[0]].mean()) + 0.02)
    textured = texture >= max(OCCLUDED_SPREAD, 5.0 * median(texture))
    disordered = ranks >= max(OCCLUDED_RANKS, 3.0 * median(ranks))
    if strict:  # both: far off the camera's fit and textured
        return np.asarray(far & textured, dtype=bool)
    # a flat window is never judged covered: a camera's own error can put one patch far off
    # any 3 x 3 fit (a Foveon sensor's raw red, say), and leaving it out would hide the error
    return np.asarray((far | disordered) & textured, dtype=bool)


__all__ = [
    "COLS",
    "NEUTRALS",
    "OCCLUDED_RANKS",
    "OCCLUDED_RESIDUAL",
    "OCCLUDED_SPREAD",
    "ROWS",
    "average_ranks",
    "colour_order",
    "corner_centres",
    "grid_cells",
    "neutral_order",
    "occluded_patches",
    "off_the_camera_fit",
]
