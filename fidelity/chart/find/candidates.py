"""Candidate detectors: each proposes where the chart may lie in a view, verified by
:func:`~fidelity.chart.find.placement.placement_scores`.

``segmentation`` (our own patch outlines chained into lattices,
:func:`segmentation_candidates`) and ``mcc`` (OpenCV's Macbeth chart detector,
:func:`mcc_charts`), by name in :data:`DETECTORS`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.lattice import Lattice, patch_lattices, robust_homography
from fidelity.chart.find.outlines import Quads, patch_quads
from fidelity.chart.find.placement import Placement, placement_scores
from fidelity.chart.find.reference import COLS, ROWS, grid_cells
from fidelity.chart.find.view import View, opencv
from fidelity.core.errors import FidelityError

F64 = NDArray[np.float64]

#: Whether the search also looks for patches darker than their surroundings.
SEARCH_INVERSE = False


def _mcc_module() -> Any:
    cv2 = opencv()
    if not hasattr(cv2, "mcc"):
        raise FidelityError(
            f"chart detection needs OpenCV's contrib modules (cv2.mcc), but this OpenCV "
            f"({getattr(cv2, '__version__', '?')}, {getattr(cv2, '__file__', '?')}) is a build "
            f"without them: install opencv-contrib-python-headless (and no other OpenCV build) "
            f"or give --corners")
    return cv2


def mcc_charts(bgr8: np.ndarray, charts: int = 2) -> list[F64]:
    """OpenCV's MCC detector (``cv2.mcc``, chart type ``MCC24``): the ``(24, 2)`` patch
    centres of each chart it finds (in its patch order: dark skin first, row by row)."""
    cv2 = _mcc_module()
    detector = cv2.mcc.CCheckerDetector_create()
    if hasattr(detector, "setColorChartType"):  # OpenCV 5 API
        detector.setColorChartType(cv2.mcc.MCC24)
        ok = detector.process(bgr8, charts)
    else:
        ok = detector.process(bgr8, cv2.mcc.MCC24, charts)
    if not ok:
        return []
    out = []
    for checker in detector.getListColorChecker():
        pts = np.asarray(checker.getColorCharts(), dtype=np.float64).reshape(-1, 4, 2)
        if len(pts) == ROWS * COLS:
            out.append(pts.mean(axis=1))
    return out


def _mcc_candidates(view: View) -> list[Placement]:
    found = []
    grid = grid_cells()
    for centres in mcc_charts(view.bgr8):
        fit = robust_homography(grid, centres)
        if fit is None:
            continue
        p = placement_scores(view, fit[0], grid.astype(np.int64), "mcc")
        if p is not None:
            found.append(p)
    return found


def segmentation_candidates(view: View, quads: Quads | None = None
                            ) -> tuple[list[Placement], list[Lattice]]:
    """Verified placements on the lattices of the view's patch outlines (``quads``, default
    :func:`~fidelity.chart.find.outlines.patch_quads` with :data:`SEARCH_INVERSE`), and the
    lattices."""
    quads = patch_quads(view.bgr8, inverse=SEARCH_INVERSE) if quads is None else quads
    lattices = patch_lattices(quads)
    found = []
    for lattice in lattices:
        p = placement_scores(view, lattice.homography, lattice.cells, "segmentation")
        if p is not None:
            found.append(p)
    return found, lattices


#: Detectors by name: a view -> verified candidates.
DETECTORS: dict[str, Callable[[View], list[Placement]]] = {
    "mcc": _mcc_candidates,
    "segmentation": lambda view: segmentation_candidates(view)[0],
}


__all__ = [
    "DETECTORS",
    "SEARCH_INVERSE",
    "mcc_charts",
    "segmentation_candidates",
]
