"""Patch lattices: patch outlines one pitch apart chained into a grid, and the homographies
fitted to them.

:func:`patch_lattices` groups the outlines of :func:`fidelity.chart.find.outlines.patch_quads`
into lattices of integer cells (:class:`Lattice`) with a lattice -> view homography
(:func:`robust_homography`); :func:`perspective_bias` and :func:`patch_side` correct the
outlines' centroids for perspective before the last fit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.outlines import PointIndex, Quads, quad_areas_centroids
from fidelity.chart.locate import apply_homography, homography_from_points
from fidelity.core.errors import InvalidValueError
from fidelity.core.numeric import median
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Largest distance (in patch pitches) between a patch centre and the grid cell it is assigned
#: to.
ASSIGN_TOLERANCE = 0.3
#: Fewest patch outlines for a refined fit.
MIN_REFINE_SWATCHES = 6
#: A patch centre farther from the fitted grid than this many times the median distance is
#: left out of the fit.
OUTLIER_FACTOR = 3.0


@record
class Lattice:
    """Patch outlines on one grid: ``homography`` lattice ``(i, j)`` -> view ``(x, y)`` (one
    unit = one patch pitch), ``cells`` ``(n, 2)`` integer lattice cells occupied, ``quads``
    their indices into the :class:`~fidelity.chart.find.outlines.Quads`."""

    homography: F64
    cells: NDArray[np.int64]
    quads: NDArray[np.int64]


def _axes(quad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two mean edge vectors of a quadrilateral (one side of the patch each)."""
    a = ((quad[1] - quad[0]) + (quad[2] - quad[3])) / 2.0
    b = ((quad[3] - quad[0]) + (quad[2] - quad[1])) / 2.0
    return a, b


def patch_lattices(quads: Quads, min_patches: int = 4) -> list[Lattice]:
    """Group patch outlines into lattices of patches one pitch apart.

    Two outlines are neighbours when their areas are within a factor 2.5, their edges nearly
    parallel, and the second's centre lies 1 to 1.8 sides from the first's along one of its
    edges (within 0.35 sides across). Connected outlines get integer lattice cells by walking
    the neighbours (their edges relabelled to a common frame); a homography lattice -> view is
    fitted to the cells (least squares, outliers left out), every outline of a similar size
    whose centre maps within :data:`ASSIGN_TOLERANCE` of a free cell is added, and the fit
    repeated. Lattices with fewer than ``min_patches`` outlines, or all on one line, are
    dropped.
    """
    n = len(quads.centres)
    if n < min_patches:
        return []
    axes = [_axes(q) for q in quads.corners]
    # each outline's edge lengths, once (the pairs below read them many times)
    lengths = [(np.linalg.norm(a), np.linalg.norm(b)) for a, b in axes]
    sides = np.sqrt(quads.areas)
    near_to = PointIndex(quads.centres)
    # neighbour steps in each outline's own frame: (j, step along a, step along b)
    steps: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]
    for i in range(n):
        a, b = axes[i]
        basis = np.column_stack([a, b])
        if abs(np.linalg.det(basis)) < 1e-9:
            continue
        inv = np.linalg.inv(basis)
        for j in near_to(quads.centres[i], 2.0 * sides[i]):
            if j == i or not 0.4 <= quads.areas[j] / quads.areas[i] <= 2.5:
                continue
            s, t = inv @ (quads.centres[j] - quads.centres[i])
            if 1.0 <= abs(s) <= 1.8 and abs(t) <= 0.35:
                step = (int(np.sign(s)), 0)
            elif 1.0 <= abs(t) <= 1.8 and abs(s) <= 0.35:
                step = (0, int(np.sign(t)))
            else:
                continue
            aj, bj = axes[j]
            # edges nearly parallel: one of j's edges along each of i's
            cos_a = abs(a @ aj) / (lengths[i][0] * lengths[j][0] + 1e-12)
            cos_b = abs(a @ bj) / (lengths[i][0] * lengths[j][1] + 1e-12)
            if max(cos_a, cos_b) < 0.85:
                continue
            steps[i].append((j, *step))
    lattices: list[Lattice] = []
    seen = np.zeros(n, dtype=bool)
    for seed in np.argsort(-quads.areas):
        if seen[seed] or not steps[seed]:
            continue
        # frame[k]: 2 x 2 signed permutation from k's own (a, b) steps to the lattice's
        frame: dict[int, np.ndarray] = {int(seed): np.eye(2)}
        cell: dict[int, np.ndarray] = {int(seed): np.zeros(2)}
        queue = [int(seed)]
        while queue:
            i = queue.pop()
            a_i, b_i = axes[i]
            for j, s, t in steps[i]:
                if j in cell or seen[j]:
                    continue
                cell[j] = cell[i] + frame[i] @ np.array([s, t], dtype=float)
                a_j, b_j = axes[j]
                # express j's edges in i's frame
                q = np.zeros((2, 2))
                for col, e in enumerate((a_j, b_j)):
                    ca, cb = e @ a_i, e @ b_i
                    na = ca / (lengths[i][0] ** 2)
                    nb = cb / (lengths[i][1] ** 2)
                    if abs(na) >= abs(nb):
                        q[0, col] = np.sign(na)
                    else:
                        q[1, col] = np.sign(nb)
                if abs(np.linalg.det(q)) < 0.5:
                    continue
                frame[j] = frame[i] @ q
                queue.append(j)
        members = np.array(sorted(cell))
        seen[members] = True
        if len(members) < min_patches:
            continue
        lattice = _fit_lattice(quads, members, np.array([cell[int(k)] for k in members]))
        if lattice is not None and len(lattice.quads) >= min_patches:
            lattices.append(lattice)
            seen[lattice.quads] = True
    return lattices


def _spanning_homography(cells: np.ndarray, points: np.ndarray
                         ) -> tuple[F64, np.ndarray] | None:
    """:func:`robust_homography` from lattice ``cells`` (n, 2) to image ``points`` (n, 2);
    None unless the cells span at least two rows and two columns (a line fixes no plane)."""
    if len(set(cells[:, 0].tolist())) < 2 or len(set(cells[:, 1].tolist())) < 2:
        return None
    return robust_homography(cells, points)


def _fit_lattice(quads: Quads, members: np.ndarray, cells: np.ndarray) -> Lattice | None:
    """Fit lattice -> view to the walked cells, then collect all outlines on the lattice."""
    fit = _spanning_homography(cells, quads.centres[members])
    if fit is None:
        return None
    h, keep = fit
    area = median(quads.areas[members[keep]])
    for _ in range(2):
        uv = apply_homography(np.linalg.inv(h), quads.centres)
        near = np.rint(uv)
        dist = np.linalg.norm(uv - near, axis=-1)
        lo, hi = near[members].min(axis=0) - 1, near[members].max(axis=0) + 1
        ok = ((dist <= ASSIGN_TOLERANCE) & (quads.areas >= 0.4 * area)
              & (quads.areas <= 2.5 * area) & np.all(near >= lo, axis=1)
              & np.all(near <= hi, axis=1))
        best: dict[tuple[int, int], int] = {}
        for k in np.flatnonzero(ok):
            key = (int(near[k, 0]), int(near[k, 1]))
            if key not in best or dist[k] < dist[best[key]]:
                best[key] = int(k)
        if len(best) < 4:
            return None
        members = np.array(list(best.values()))
        cells = np.array(list(best.keys()), dtype=float)
        fit = _spanning_homography(cells, quads.centres[members])
        if fit is None:
            return None
        h, keep = fit
        members, cells = members[keep], cells[keep]
    return Lattice(homography=h, cells=cells.astype(np.int64), quads=members.astype(np.int64))


def robust_homography(src: np.ndarray, dst: np.ndarray) -> tuple[F64, np.ndarray] | None:
    """Least-squares homography ``src -> dst`` that leaves out points which do not fit.

    Fit (normalised DLT), drop the points whose distance to the fit exceeds
    :data:`OUTLIER_FACTOR` times the median distance (and 0.5 px), refit; up to three rounds,
    never below 4 points. Returns the map and the mask of points kept (``None`` when
    degenerate).
    """
    keep = np.ones(len(src), dtype=bool)
    h = None
    for _ in range(3):
        try:
            h = homography_from_points(src[keep], dst[keep])
        except InvalidValueError:
            return None
        dist = np.linalg.norm(apply_homography(h, src) - dst, axis=-1)
        limit = max(OUTLIER_FACTOR * median(dist[keep]), 0.5)
        new = keep & (dist <= limit)
        if new.sum() == keep.sum() or new.sum() < max(4, MIN_REFINE_SWATCHES // 2):
            break
        keep = new
    if h is None or not np.all(np.isfinite(h)) or np.linalg.cond(h) > 1e12:
        return None
    return h, keep


def perspective_bias(homography: np.ndarray, cells: np.ndarray, side: float) -> F64:
    """``(n, 2)``: where the image of each cell's square patch (``side`` grid units, centred on
    the cell ``(n, 2)``) has its area centroid, minus the image of the patch's centre.

    A homography maps a square's centre to the crossing of its image's diagonals, not to the
    image's centroid, which leans towards the nearer (larger) side: on an oblique chart the
    centroids of the patch outlines put the corner patches a few per cent of a pitch off."""
    half = 0.5 * float(side)
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    cells = np.asarray(cells, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        corners = apply_homography(homography, (cells[:, None, :] + square).reshape(-1, 2))
        _, centroid = quad_areas_centroids(corners.reshape(-1, 4, 2))
        bias = centroid - apply_homography(homography, cells)
    return np.where(np.isfinite(bias), bias, 0.0)


def patch_side(homography: np.ndarray, quads: Quads, members: np.ndarray) -> float:
    """The patches' side in grid units (pitches): the square root of the median area of the
    outlines ``members`` mapped back onto the grid, within 0.3-1."""
    corners = apply_homography(np.linalg.inv(homography),
                               np.asarray(quads.corners[members], np.float64).reshape(-1, 2))
    area = np.abs(quad_areas_centroids(corners.reshape(-1, 4, 2))[0])
    return float(np.clip(np.sqrt(median(area)), 0.3, 1.0)) if len(area) else 0.8


__all__ = [
    "ASSIGN_TOLERANCE",
    "MIN_REFINE_SWATCHES",
    "OUTLIER_FACTOR",
    "Lattice",
    "patch_lattices",
    "patch_side",
    "perspective_bias",
    "robust_homography",
]
