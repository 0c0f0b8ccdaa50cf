"""The chart's surroundings: the region around it, patch charts beside it (a Passport's other
page) and patches that continue its grid (a ColorChecker SG or a digital target, refused).
"""

from __future__ import annotations

import numpy as np

from fidelity.chart.find.lattice import ASSIGN_TOLERANCE, Lattice, patch_lattices
from fidelity.chart.find.outlines import Quads, patch_quads
from fidelity.chart.find.placement import ring_cells
from fidelity.chart.find.reference import COLS, ROWS, corner_centres, grid_cells
from fidelity.chart.find.view import Pyramid, make_view
from fidelity.chart.locate import apply_homography
from fidelity.core.errors import InvalidValueError

#: Patch-like outlines in the ring of cells just outside the 4 x 6 chart that make it part of a
#: larger patch grid (a ColorChecker SG, a digital target).
LARGER_GRID_RING = 4
#: Fewest patches of a lattice beside the chart that make it another patch chart (a
#: Passport's other page).
OTHER_CHART_PATCHES = 12
#: How far beside the chart other charts are looked for, in patch pitches, and the long side
#: of the view they are looked for in.
BESIDE_PITCHES = 8.0
#: Long side, in pixels, of the view of the chart's surroundings other charts are looked for in.
BESIDE_SIDE = 700
#: Distance (in patch pitches) from a cell just outside the chart within which a patch outline
#: of the chart's own size makes the chart part of a larger grid, once the fit is refined (an
#: SG's patches continue the grid exactly; objects beside a framed chart lie beyond its frame).
RING_TOLERANCE = 0.15


def chart_pitch(corners: np.ndarray) -> float:
    """Smallest patch pitch along the chart's edges, in pixels, from the corner centres."""
    c = np.asarray(corners)
    return float(min(np.linalg.norm(c[1] - c[0]) / (COLS - 1), np.linalg.norm(c[2] - c[1]) /
                     (ROWS - 1), np.linalg.norm(c[2] - c[3]) / (COLS - 1),
                     np.linalg.norm(c[3] - c[0]) / (ROWS - 1)))


def chart_region(corners: np.ndarray, width: int, height: int, margin_pitches: float = 2.0
                 ) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` around the chart: corner centres plus ``margin_pitches``."""
    margin = margin_pitches * max(chart_pitch(corners), 1.0)
    x0 = max(int(np.floor(corners[:, 0].min() - margin)), 0)
    y0 = max(int(np.floor(corners[:, 1].min() - margin)), 0)
    x1 = min(int(np.ceil(corners[:, 0].max() + margin)) + 1, width)
    y1 = min(int(np.ceil(corners[:, 1].max() + margin)) + 1, height)
    return x0, y0, x1, y1


def ring_patches(quads: Quads, h_view: np.ndarray, refined: bool = False) -> int:
    """Patch outlines of the chart's size centred on the cells just outside its 4 x 6 grid.

    ``refined``: the grid was fitted to the chart's own patch outlines, so an outline counts
    only within :data:`RING_TOLERANCE` of a cell and of the patches' size (0.5-1.6 times their
    area): an SG's patches continue the grid exactly, tiles or cards beside a framed chart lie
    beyond its frame. Otherwise :data:`~fidelity.chart.find.lattice.ASSIGN_TOLERANCE` and
    0.3-2 times the area."""
    if not len(quads.centres):
        return 0
    pitch = chart_pitch(corner_centres(h_view))
    expected = (0.84 * pitch) ** 2
    uv = apply_homography(np.linalg.inv(h_view), quads.centres)
    near = np.rint(uv)
    dist = np.linalg.norm(uv - near, axis=-1)
    tolerance, lo, hi = (RING_TOLERANCE, 0.5, 1.6) if refined else (ASSIGN_TOLERANCE, 0.3, 2.0)
    ok = (dist <= tolerance) & (quads.areas >= lo * expected) & (quads.areas <= hi * expected)
    ring = ring_cells(grid_cells().astype(np.int64))
    return len({(int(a), int(b)) for a, b in near[ok]} & ring)


def other_charts(image: np.ndarray | Pyramid, grid_to_image: np.ndarray, encoding: str) -> int:
    """Patch charts beside the chart found: a Passport's other page, say.

    The chart's surroundings (its corner centres plus :data:`BESIDE_PITCHES` pitches each way)
    are segmented for patches lighter and darker than their surroundings
    (:func:`~fidelity.chart.find.outlines.patch_quads`,
    :func:`~fidelity.chart.find.lattice.patch_lattices`); a lattice of at least
    :data:`OTHER_CHART_PATCHES` patches with a pitch within a factor 2 of the chart's and
    under a fifth of its patches on the chart counts as another chart.
    """
    pyramid = image if isinstance(image, Pyramid) else Pyramid(image)
    corners = corner_centres(grid_to_image)
    region = chart_region(corners, pyramid.width, pyramid.height, BESIDE_PITCHES)
    view, _ = make_view(pyramid, region, BESIDE_SIDE, encoding)
    h_view = np.linalg.inv(view.to_image) @ grid_to_image
    pitch = chart_pitch(corner_centres(h_view))
    quads = patch_quads(view.bgr8, blocks=(round(0.25 * pitch), round(0.5 * pitch)))
    inv = np.linalg.inv(h_view)
    count = 0
    for lattice in patch_lattices(quads, min_patches=OTHER_CHART_PATCHES):
        centres = apply_homography(lattice.homography, lattice.cells.astype(float))
        ends = apply_homography(lattice.homography, np.array([[0.0, 0.0], [1.0, 0.0]]))
        step = float(np.linalg.norm(ends[1] - ends[0]))
        uv = apply_homography(inv, centres)
        inside = ((uv[:, 0] > -0.5) & (uv[:, 0] < COLS - 0.5) & (uv[:, 1] > -0.5)
                  & (uv[:, 1] < ROWS - 0.5))
        if inside.mean() < 0.2 and 0.5 * pitch <= step <= 2.0 * pitch:
            count += 1
    return count


def larger_grid_error(lattices: list[Lattice]) -> InvalidValueError | None:
    """The error that refuses a patch grid larger than the chart (an SG, a digital target):
    the largest of ``lattices`` with more than 28 patches, named; None when there is none."""
    big = [lt for lt in lattices if len(lt.cells) > ROWS * COLS + 4]
    if not big:
        return None
    lt = max(big, key=lambda x: len(x.cells))
    span = lt.cells.max(axis=0) - lt.cells.min(axis=0) + 1
    return InvalidValueError(
        f"the chart in the image is a grid of {len(lt.cells)}+ patches ({span[1]} x {span[0]}), "
        f"not the 24-patch ColorChecker (an SG or digital target?): fidelity measures the "
        f"24-patch layout only (Classic, Mini, Passport); give --corners of a 24-patch chart")


__all__ = [
    "BESIDE_PITCHES",
    "BESIDE_SIDE",
    "LARGER_GRID_RING",
    "OTHER_CHART_PATCHES",
    "RING_TOLERANCE",
    "chart_pitch",
    "chart_region",
    "larger_grid_error",
    "other_charts",
    "ring_patches",
]
