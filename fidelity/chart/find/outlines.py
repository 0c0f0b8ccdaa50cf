"""Patch outlines: the convex quadrilaterals of the chart finder's own segmentation.

:func:`patch_quads` thresholds an 8-bit view against its local mean and keeps the contours
that simplify to convex, nearly square quadrilaterals (:class:`Quads`); the lattice they form
is found by :func:`fidelity.chart.find.lattice.patch_lattices`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.view import opencv
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Adaptive-threshold block sizes, as fractions of the image's short side (odd, at least 7 px).
BLOCK_FRACTIONS = (0.025, 0.06)
#: Offsets of the adaptive threshold (grey levels below the local mean).
THRESHOLD_OFFSETS = (2.0,)
#: Smallest patch outline, in pixels of area, that counts (a patch side of about 5 px).
MIN_QUAD_AREA = 25.0


@record
class Quads:
    """Convex four-sided patch outlines: ``corners`` ``(n, 4, 2)``, ``centres`` ``(n, 2)``
    (contour centroids), ``areas`` ``(n,)`` pixels."""

    corners: F64
    centres: F64
    areas: F64


def patch_quads(bgr8: np.ndarray, blocks: tuple[int, ...] | None = None,
                inverse: bool = True) -> Quads:
    """Patch-like outlines in an 8-bit image: convex quadrilaterals of similar sides.

    The grey image is thresholded against its local mean (``cv2.adaptiveThreshold``, block
    sizes ``blocks`` in pixels, default :data:`BLOCK_FRACTIONS` of the short side,
    :data:`THRESHOLD_OFFSETS`), for patches lighter than their surroundings and, with
    ``inverse``, darker; each outer and inner contour is simplified (Douglas-Peucker, 6 % of its perimeter) and kept
    when it has four corners, is convex, fills at least 80 % of its quadrilateral, has
    opposite sides within a factor 3 and an area between :data:`MIN_QUAD_AREA` and 1/20 of
    the image. Outlines found twice (centres within a fifth of a side) are kept once.
    """
    cv2 = opencv()
    grey = cv2.cvtColor(bgr8, cv2.COLOR_BGR2GRAY)
    height, width = grey.shape
    max_area = height * width / 20.0
    min_box = MIN_QUAD_AREA
    found: list[tuple[np.ndarray, np.ndarray, float]] = []
    if blocks is None:
        blocks = tuple(int(min(height, width) * fraction) for fraction in BLOCK_FRACTIONS)
    for size in blocks:
        block = max(7, int(size) | 1)
        for offset in THRESHOLD_OFFSETS:
            binary = cv2.adaptiveThreshold(grey, 255, cv2.ADAPTIVE_THRESH_MEAN_C,
                                           cv2.THRESH_BINARY, block, -offset)
            for mask in (binary, 255 - binary) if inverse else (binary,):
                contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
                for contour in contours:
                    if len(contour) < 4:
                        continue
                    _, _, bw, bh = cv2.boundingRect(contour)
                    if bw * bh < min_box or bw > 5 * bh or bh > 5 * bw:
                        continue
                    area = cv2.contourArea(contour)
                    if not MIN_QUAD_AREA <= area <= max_area:
                        continue
                    poly = cv2.approxPolyDP(contour, 0.06 * cv2.arcLength(contour, True), True)
                    if len(poly) != 4 or not cv2.isContourConvex(poly):
                        continue
                    quad_area = cv2.contourArea(poly)
                    if quad_area <= 0 or area < 0.8 * quad_area:
                        continue
                    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = poly.reshape(4, 2).tolist()
                    sides = (math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x1, y2 - y1),
                             math.hypot(x3 - x2, y3 - y2), math.hypot(x0 - x3, y0 - y3))
                    if min(sides) <= 0 or max(sides) > 3.0 * min(sides):
                        continue
                    m = cv2.moments(contour)
                    found.append((poly.reshape(4, 2), np.array([m["m10"] / m["m00"],
                                                                m["m01"] / m["m00"]]), area))
    if not found:
        return Quads(np.empty((0, 4, 2)), np.empty((0, 2)), np.empty(0))
    corners = np.stack([f[0] for f in found]).astype(np.float64)
    centres = np.stack([f[1] for f in found])
    areas = np.array([f[2] for f in found])
    # keep one of each outline found twice (largest first)
    order = np.argsort(-areas)
    keep: list[int] = []
    near_to = PointIndex(centres)
    taken = np.zeros(len(centres), dtype=bool)
    for k in order:
        if taken[k]:
            continue
        keep.append(int(k))
        for j in near_to(centres[k], 0.2 * math.sqrt(areas[k])):
            if 0.5 < areas[j] / areas[k] <= 1.0:
                taken[j] = True
    idx = np.array(sorted(keep))
    return Quads(corners[idx], centres[idx], areas[idx])


def quad_areas_centroids(points: np.ndarray) -> tuple[F64, F64]:
    """``(n, 4, 2)`` quadrilaterals -> their signed areas ``(n,)`` and area centroids
    ``(n, 2)`` (NaN for a zero area), over the triangles p0 p1 p2 and p0 p2 p3."""
    p0, p1, p2, p3 = points[:, 0], points[:, 1], points[:, 2], points[:, 3]
    a1 = 0.5 * ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1])
                - (p2[:, 0] - p0[:, 0]) * (p1[:, 1] - p0[:, 1]))
    a2 = 0.5 * ((p2[:, 0] - p0[:, 0]) * (p3[:, 1] - p0[:, 1])
                - (p3[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]))
    area = a1 + a2
    with np.errstate(divide="ignore", invalid="ignore"):
        centroid = ((a1[:, None] * (p0 + p1 + p2) + a2[:, None] * (p0 + p2 + p3))
                    / (3.0 * area[:, None]))
    return np.asarray(area, np.float64), np.asarray(centroid, np.float64)


class PointIndex:
    """Points sorted along x, for finding those within a radius of a point."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, np.float64)
        self.order = np.argsort(self.points[:, 0], kind="stable")
        self.xs = self.points[self.order, 0]

    def __call__(self, centre: np.ndarray, radius: float) -> list[int]:
        """Indices of the points within ``radius`` of ``centre`` (in order along x)."""
        lo = int(np.searchsorted(self.xs, centre[0] - radius, "left"))
        hi = int(np.searchsorted(self.xs, centre[0] + radius, "right"))
        cand = self.order[lo:hi]
        d = self.points[cand] - centre
        return [int(j) for j in cand[(d * d).sum(axis=1) <= radius * radius]]


__all__ = [
    "BLOCK_FRACTIONS",
    "MIN_QUAD_AREA",
    "THRESHOLD_OFFSETS",
    "PointIndex",
    "Quads",
    "patch_quads",
    "quad_areas_centroids",
]
