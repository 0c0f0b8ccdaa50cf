"""Placements of the 4 x 6 chart on a candidate lattice, and their verification.

Every orientation and offset of the chart on a lattice found by a detector is sampled
(:func:`sample_cells`) and scored against the reference layout
(:func:`~fidelity.chart.find.reference.colour_order`); :func:`placement_scores` returns the
best (:class:`Placement`) with its :class:`~fidelity.chart.find.result.ChartChecks`, so that a
detector's answer one row or column off, turned or mirrored is corrected, never measured.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.reference import (
    COLS,
    NEUTRALS,
    ROWS,
    colour_order,
    grid_cells,
    neutral_order,
    occluded_patches,
)
from fidelity.chart.find.result import ChartChecks
from fidelity.chart.find.view import View
from fidelity.chart.locate import apply_homography
from fidelity.core.numeric import median
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Patches left out of the rank correlation (those that disagree most: covered, glared).
TRIM = 2
#: Most patches judged covered (:func:`~fidelity.chart.find.reference.occluded_patches`) that
#: a chart may have and still be measured without them; with more, none is left out and the
#: checks decide.
MAX_OCCLUDED = 4
#: Side of the sampling window used for verification, in patch pitches.
VERIFY_WINDOW = 0.35
#: Number of sample points along each side of the verification window.
VERIFY_SAMPLES = 5
#: The 8 orientations of a grid: chart ``(u, v)`` -> lattice direction, as 2 x 2 matrices
#: (identity, turns, mirror images, transposes).
ORIENTATIONS = tuple(np.array(m, dtype=float) for m in (
    [[1, 0], [0, 1]], [[-1, 0], [0, -1]], [[-1, 0], [0, 1]], [[1, 0], [0, -1]],
    [[0, 1], [1, 0]], [[0, -1], [-1, 0]], [[0, -1], [1, 0]], [[0, 1], [-1, 0]]))


def sample_cells(view: View, homography: np.ndarray, cells: np.ndarray,
                 window: float = VERIFY_WINDOW, structured: bool = False) -> tuple[F64, ...]:
    """Mean and relative spread of the linear view in a ``window``-pitch square about each
    lattice cell (``VERIFY_SAMPLES``\\ :sup:`2` points, bilinear); ``structured``: also the
    relative spread beyond white noise (:func:`structured_spread`), a third array. Cells whose
    window leaves the view get NaN."""
    k = VERIFY_SAMPLES
    offs = (np.arange(k) + 0.5) / k - 0.5
    oy, ox = np.meshgrid(offs * window, offs * window, indexing="ij")
    pts = cells[:, None, :] + np.stack([ox.ravel(), oy.ravel()], axis=-1)[None]
    xy = apply_homography(homography, pts.reshape(-1, 2)).reshape(len(cells), k * k, 2)
    height, width = view.linear.shape[:2]
    inside = ((xy[..., 0] >= 0) & (xy[..., 0] <= width - 1) & (xy[..., 1] >= 0)
              & (xy[..., 1] <= height - 1)).all(axis=1)
    x = np.clip(xy[..., 0], 0, width - 1.001)
    y = np.clip(xy[..., 1], 0, height - 1.001)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    img = view.linear
    vals = (img[y0, x0] * (1 - fx) * (1 - fy) + img[y0, x0 + 1] * fx * (1 - fy)
            + img[y0 + 1, x0] * (1 - fx) * fy + img[y0 + 1, x0 + 1] * fx * fy)
    mean = vals.mean(axis=1)
    scale = mean.mean(axis=-1) + 0.02
    spread = vals.std(axis=1).mean(axis=-1) / scale
    mean[~inside] = np.nan
    spread[~inside] = np.nan
    if not structured:
        return mean.astype(np.float64), spread.astype(np.float64)
    beyond_noise = structured_spread(vals.reshape(len(cells), k, k, -1)).mean(axis=-1) / scale
    beyond_noise[~inside] = np.nan
    return mean.astype(np.float64), spread.astype(np.float64), beyond_noise.astype(np.float64)


def structured_spread(samples: F64) -> F64:
    """Per window and channel, the standard deviation of a ``(n, k, k, c)`` grid of samples
    with its white noise taken out: ``sqrt(max(0, s^2 - d^2 / 2))``, ``d^2`` the smaller of the
    mean squared differences between neighbouring samples across and down (von Neumann's
    successive-difference estimator of the noise variance: ``2 sigma^2`` for independent
    noise). A window that straddles a patch edge keeps its spread (the differences along the
    edge are small), a flat patch under noise loses it, so heavy noise (sigma 0.08 of full
    scale) does not pass for a grid off the patches. ``(n, c)``."""
    x = np.asarray(samples, np.float64)
    n, k = x.shape[0], x.shape[1]
    var = x.reshape(n, k * k, -1).var(axis=1)
    across = np.mean(np.diff(x, axis=2) ** 2, axis=(1, 2))
    down = np.mean(np.diff(x, axis=1) ** 2, axis=(1, 2))
    out: F64 = np.sqrt(np.maximum(var - np.minimum(across, down) / 2.0, 0.0))
    return out


@record
class Placement:
    """The best placement of the 4 x 6 chart on a candidate lattice.

    ``homography`` maps chart grid ``(u, v)`` to view ``(x, y)``; ``checks`` its scores;
    ``cells`` the lattice cells of its 24 patches (chart order); ``view_index`` which view.
    """

    homography: F64
    checks: ChartChecks
    cells: NDArray[np.int64]
    source: str
    ring_patches: int = 0
    occluded: tuple[int, ...] = ()


def placement_scores(view: View, lattice_h: np.ndarray, occupied: np.ndarray, source: str,
                     trim: int = TRIM, given: bool = False) -> Placement | None:
    """Verify every placement of the 4 x 6 chart on a lattice and return the best.

    Placements: the 8 orientations (:data:`ORIENTATIONS`) and every offset whose 4 x 6 window
    holds at least half of the ``occupied`` cells (or 12 of them), so that a detector's answer
    one row or column off is corrected. Each is scored
    by :func:`~fidelity.chart.find.reference.colour_order` of its sampled patches; the best, with its margin over the next
    best and its neutral order and uniformity, is returned (``None``: no placement lies in the
    view).
    """
    occ = np.asarray(occupied, dtype=np.int64)
    lo, hi = occ.min(axis=0), occ.max(axis=0)
    grid = grid_cells()
    occ_set = {(int(a), int(b)) for a, b in occ}
    # occupancy as an image of the lattice (one cell border), to count cells held by a window
    occupancy = np.zeros((int(hi[1] - lo[1]) + 3, int(hi[0] - lo[0]) + 3), dtype=np.int64)
    occupancy[occ[:, 1] - lo[1] + 1, occ[:, 0] - lo[0] + 1] = 1
    need = max(min(len(occ_set) * 0.5, 12), min(4, len(occ_set)))
    chunks: list[np.ndarray] = []
    for m in ORIENTATIONS:
        rel = np.rint(grid @ m.T).astype(np.int64)  # offsets of the 24 cells from the origin
        rmin, rmax = rel.min(axis=0), rel.max(axis=0)
        ox, oy = np.meshgrid(np.arange(lo[0] - rmax[0], hi[0] - rmin[0] + 1),
                             np.arange(lo[1] - rmax[1], hi[1] - rmin[1] + 1), indexing="ij")
        origins = np.stack([ox.ravel(), oy.ravel()], axis=-1)
        cells = origins[:, None, :] + rel[None]  # (o, 24, 2)
        cx = cells[..., 0] - lo[0] + 1
        cy = cells[..., 1] - lo[1] + 1
        inside = (cx >= 0) & (cx < occupancy.shape[1]) & (cy >= 0) & (cy < occupancy.shape[0])
        held = np.where(inside, occupancy[np.clip(cy, 0, occupancy.shape[0] - 1),
                                          np.clip(cx, 0, occupancy.shape[1] - 1)], 0).sum(-1)
        chunks.append(cells[held >= need])
    cells_all = np.concatenate(chunks)  # (p, 24, 2)
    if not len(cells_all):
        return None
    placements = list(cells_all)
    uniq, inverse = np.unique(cells_all.reshape(-1, 2), axis=0, return_inverse=True)
    means, spread, beyond_noise = sample_cells(view, lattice_h, uniq.astype(float),
                                               structured=True)
    pm = means[inverse.ravel()].reshape(len(placements), ROWS * COLS, 3)
    ps = spread[inverse.ravel()].reshape(len(placements), ROWS * COLS)
    pu = beyond_noise[inverse.ravel()].reshape(len(placements), ROWS * COLS)
    valid = np.all(np.isfinite(pm), axis=(1, 2))
    if not valid.any():
        return None
    scores = np.full(len(placements), -np.inf)
    scores[valid] = colour_order(pm[valid], trim=trim)
    order = np.argsort(-scores)
    best = int(order[0])
    second = float(scores[order[1]]) if len(order) > 1 and np.isfinite(scores[order[1]]) else 0.0
    if given:  # the placement of the occupied cells themselves, against the best other one
        same = np.flatnonzero(np.all(cells_all == occ[None], axis=(1, 2)))
        if not len(same) or not np.isfinite(scores[same[0]]):
            return None
        best = int(same[0])
        others = np.delete(scores, best)
        second = float(others.max()) if len(others) and np.isfinite(others.max()) else 0.0
    cells = cells_all[best]
    h = lattice_h @ _cell_map(cells)
    box = {(int(a), int(b)) for a, b in cells}
    ring = ring_cells(cells)
    ring_patches = sum(c in occ_set and c not in box for c in ring)
    # patches judged covered are left out of the checks (and named), the rest must pass them;
    # with more than MAX_OCCLUDED none is left out (the checks decide) but all are named
    flagged = occluded_patches(pm[best], ps[best])
    many = int(np.count_nonzero(flagged)) > MAX_OCCLUDED
    covered = np.zeros_like(flagged) if many else flagged
    score = float(scores[best])
    if covered.any():
        score = float(colour_order(pm[best], exclude=covered))
    clear = ~covered
    kept_neutrals = clear[NEUTRALS]
    checks = ChartChecks(colour_order=score,
                         neutral_order=float(neutral_order(pm[best], kept_neutrals)),
                         margin=score - second,
                         uniformity=median(pu[best][clear]))
    return Placement(homography=h, checks=checks, cells=cells, source=source,
                     ring_patches=ring_patches,
                     occluded=tuple(int(k) for k in np.flatnonzero(flagged)))


def _cell_map(cells: np.ndarray) -> F64:
    """The affine map chart grid ``(u, v)`` -> lattice cell of a placement (3 x 3)."""
    grid = grid_cells()
    a = np.c_[grid, np.ones(len(grid))]
    sol, *_ = np.linalg.lstsq(a, cells.astype(float), rcond=None)
    m = np.eye(3)
    m[:2, :] = sol.T
    return m


def ring_cells(cells: np.ndarray) -> set[tuple[int, int]]:
    """Lattice cells just outside the placement's 4 x 6 box (the 24 cells around it)."""
    lo, hi = cells.min(axis=0), cells.max(axis=0)
    ring: set[tuple[int, int]] = set()
    for x in range(int(lo[0]) - 1, int(hi[0]) + 2):
        for y in range(int(lo[1]) - 1, int(hi[1]) + 2):
            if not (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]):
                ring.add((x, y))
    return ring


__all__ = [
    "MAX_OCCLUDED",
    "ORIENTATIONS",
    "TRIM",
    "VERIFY_SAMPLES",
    "VERIFY_WINDOW",
    "Placement",
    "placement_scores",
    "ring_cells",
    "sample_cells",
]
