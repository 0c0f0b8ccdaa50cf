"""Find a 4 x 6 colour chart in an image, so that an audit needs no hand-given corners.

The result is the same four numbers a user would give with ``--corners``: the image centres of
the dark skin, bluish green, black and white patches (:mod:`fidelity.chart.locate` conventions:
``x`` along a row, ``y`` down, pixel ``(i, j)`` at ``x = j, y = i``). Everything after that,
sampling windows, bad pixels, exposure and ΔE00, is the audit's own and does not depend on how
the corners were found.

Methods (:data:`CHART_FINDERS`):

``segmentation``
    colour-checker-detection's segmentation detector (Colour Developers, *Colour - Checker
    Detection*, ``detect_colour_checkers_segmentation``): adaptive thresholding at a working
    width of 1440 px, square swatch contours, clusters of swatches with the chart's 3:2 aspect
    ratio; the chart's orientation (which corner is dark skin) is the rotation whose sampled
    colours are closest to the ColorChecker reference. Its chart outline is coarse (it encloses
    the swatches and part of the gaps), so the corners are refined here: every swatch contour
    the detector found is assigned to the grid cell its centre falls in (within 0.3 patch
    pitches of the cell centre, through the coarse outline), and a homography grid -> image is
    fitted to all assigned swatch centres by the normalised DLT
    (:func:`fidelity.chart.locate.homography_from_points`), leaving out swatches whose centre lies
    more than three times the median distance off the fit (a contour merged with a dark
    frame). With fewer than six assigned swatches the coarse outline answers. The detector
    keeps only clusters of swatches with about the chart's aspect ratio
    (:data:`ASPECT_RATIO_RANGE`, wider than its own default) and square-ish swatches, so a
    chart under strong perspective is not found; give ``--corners`` for it. A mirrored chart (seen from behind a mirror) is not recognised
    as such; give ``--corners`` for it.

Passes (:func:`find_chart`, any method): the whole image first; when that finds nothing and
the image is large (:data:`TILED_SEARCH_SIDE`), nine half-size tiles overlapping by half; then,
with refinement, once more on the chart's surroundings (corner centres plus 1.5 patch pitches)
when they are under half an image larger than the detector's working width
(:data:`CROP_PASS_MIN_SIDE`), since the detector works at a fixed width and a small chart
gains resolution there (a 4000 x 3000 synthetic photo: corner error 4.2 % of a pitch from the
whole frame, 0.3 % from the crop). The crop's answer is kept only if it agrees with the first
within a quarter pitch. Found this way: charts down to about 7.5 % of the image width.

Input: ``(H, W, 3)`` linear or sRGB-encoded RGB of any scale (HDR welcome). NaN, Inf and
negative values count as black for finding the chart only; the image is scaled so that its 99th
percentile of the brightest channel is 1 and clipped to [0, 1] (the detector's domain).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fidelity.chart.locate import CORNER_PATCHES, apply_homography, homography_from_points
from fidelity.colour import colorimetry as cm
from fidelity.errors import FidelityError, InvalidValueError, unknown_name

#: Largest distance (in patch pitches) between a swatch centre and the grid cell centre it is
#: assigned to when the coarse outline is refined.
ASSIGN_TOLERANCE = 0.3
#: Aspect ratios (long / short side of the swatch cluster's smallest enclosing rectangle) that
#: can be a 3:2 chart. The detector's default, 1.35-1.65, loses a chart seen under a little
#: perspective (a 5 % keystone gives 1.30); false clusters are caught by the orientation check.
ASPECT_RATIO_RANGE = (1.1, 2.0)
#: The best orientation's score must be below this fraction of the next best, else what was
#: found is not taken for a ColorChecker (a real chart, even with ΔE 20 of colour error, scores
#: at most 0.56 of its next orientation in the tests).
ORIENTATION_MARGIN = 0.8
#: Images at least this many pixels on their long side are searched in tiles when the whole
#: frame shows no chart (the detector works at 1440 px width, where a small chart in a large
#: image has patches too small to segment).
TILED_SEARCH_SIDE = 2400
#: The crop pass runs only on images wider (long side) than the detector's working width of
#: 1440 px: a smaller image is already seen at full resolution, and a crop would add time only.
CROP_PASS_MIN_SIDE = 1440
#: Fewest assigned swatches for the refined fit (else the detector's outline answers).
MIN_REFINE_SWATCHES = 6
#: A swatch centre farther from the fitted grid than this many times the median distance is
#: left out of the refined fit.
OUTLIER_FACTOR = 3.0


@dataclass(frozen=True)
class FoundChart:
    """A chart found in an image.

    ``corners`` is ``(4, 2)`` image ``(x, y)`` of the dark skin, bluish green, black and white
    patch centres; ``candidates`` the number of charts the detector found (the first answers);
    ``swatches`` the number of patches whose own contour refined the fit (0: the detector's
    outline answered); ``residual_px`` the RMS distance, in image pixels, between those swatch
    centres and the fitted grid (NaN without refinement); ``orientation`` the grid symmetry
    (:data:`GRID_SYMMETRIES`) that put the patches in order, relative to the detector's own
    answer; ``region`` the ``(x0, y0, x1, y1)`` part of the image the answer was found in.
    """

    corners: np.ndarray
    method: str
    candidates: int
    swatches: int
    residual_px: float
    orientation: str = "as found"
    region: tuple[int, int, int, int] | None = None

    def corners_text(self) -> str:
        """The corners as ``--corners`` takes them: ``X1,Y1,...,X4,Y4`` (0.1 px)."""
        return ",".join(f"{v:.1f}" for v in self.corners.ravel())

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``method``, ``corners``, ``corner_patches``, ``corners_text``,
        ``candidates``, ``swatches``, ``residual_px`` (null without refinement),
        ``orientation``, ``region``."""
        return {
            "method": self.method,
            "corners": np.round(self.corners, 3).tolist(),
            "corner_patches": list(CORNER_PATCHES),
            "corners_text": self.corners_text(),
            "candidates": self.candidates,
            "swatches": self.swatches,
            "residual_px": None if math.isnan(self.residual_px) else round(self.residual_px, 3),
            "orientation": self.orientation,
            "region": list(self.region) if self.region else None,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FoundChart:
        """Inverse of :meth:`to_json` (corners as stored, to 0.001 px)."""
        residual = data.get("residual_px")
        region = data.get("region")
        return cls(
            corners=np.asarray(data["corners"], dtype=np.float64), method=str(data["method"]),
            candidates=int(data["candidates"]), swatches=int(data["swatches"]),
            residual_px=math.nan if residual is None else float(residual),
            orientation=str(data.get("orientation", "as found")),
            region=(int(region[0]), int(region[1]), int(region[2]), int(region[3]))
            if region else None,
        )


def detection_image(pixels: np.ndarray, encoding: str = "linear") -> np.ndarray:
    """The float32 linear image in [0, 1] that the detector sees (see the module docstring)."""
    arr = np.asarray(pixels, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    arr = np.where(np.isfinite(arr), arr, 0.0)
    arr = np.maximum(arr, 0.0)
    if encoding == "srgb":
        arr = cm.linearize_srgb(np.clip(arr, 0.0, 1.0))
    peak = float(np.percentile(arr.max(axis=-1), 99.0))
    if peak <= 0.0:
        raise InvalidValueError("no colour chart found: the image is black")
    return np.clip(arr / peak, 0.0, 1.0).astype(np.float32)


def _working_to_image(points: np.ndarray, shape: tuple[int, int], working_width: int
                      ) -> np.ndarray:
    """Map working-image ``(x, y)`` back to the original image.

    colour-checker-detection turns a portrait image 90 degrees clockwise, then resizes it to
    ``working_width`` (OpenCV pixel-centre convention ``x_src = (x_dst + 0.5) / s - 0.5``).
    """
    height, width = shape
    rotated = width < height
    w2, h2 = (height, width) if rotated else (width, height)
    working_height = int(h2 / (w2 / working_width))
    x = (points[:, 0] + 0.5) * w2 / working_width - 0.5
    y = (points[:, 1] + 0.5) * h2 / working_height - 0.5
    if rotated:  # clockwise turn: x' = (H - 1) - y, y' = x
        x, y = y, (height - 1) - x
    return np.stack([x, y], axis=-1)


def _detect_segmentation(image: np.ndarray, rows: int, cols: int, refine: bool = True
                         ) -> FoundChart:
    try:
        import colour_checker_detection as ccd
        from colour_checker_detection.detection.segmentation import (
            SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC as settings,
        )
    except ImportError as exc:  # OpenCV needs libGL; say so rather than a bare ImportError
        raise FidelityError(
            f"chart detection needs colour-checker-detection and OpenCV ({exc}); install them "
            f"(and libgl1) or give --corners") from None
    if (rows, cols) != (settings["swatches_vertical"], settings["swatches_horizontal"]):
        raise InvalidValueError(f"chart detection knows the 4 x 6 ColorChecker only, not "
                                f"{rows} x {cols}")
    found: dict[str, Any] = {}

    def segmenter(img: np.ndarray, **kwargs: Any) -> Any:
        data = ccd.segmenter_default(img, **kwargs)
        found["swatches"] = np.asarray(data.swatches, dtype=np.float64)
        return data

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        charts = ccd.detect_colour_checkers_segmentation(
            image, segmenter=segmenter, additional_data=True,
            aspect_ratio_minimum=ASPECT_RATIO_RANGE[0], aspect_ratio_maximum=ASPECT_RATIO_RANGE[1])
    if not charts:
        raise InvalidValueError("no colour chart found (segmentation); give --corners "
                                "X1,Y1,...,X4,Y4")
    ww, wh = int(settings["working_width"]), int(settings["working_height"])
    quad = np.asarray(charts[0].quadrilateral, dtype=np.float64)
    # Outline corner k goes to rectangle corner k (below), so edge 1 -> 2 must be a long side;
    # the detector's orientation check knows rotations only, and for a mirrored chart it can
    # answer with a quarter turn. The patch order is decided in _oriented_corners.
    if np.linalg.norm(quad[2] - quad[1]) < np.linalg.norm(quad[1] - quad[0]):
        quad = np.roll(quad, 1, axis=0)
    # The detector samples swatch (c, r) at ((c + 0.5) ww / cols, (r + 0.5) wh / rows) of the
    # rectangle its outline is warped onto, outline corner k going to rectangle corner k.
    rect = np.array([[ww, 0], [ww, wh], [0, wh], [0, 0]], dtype=np.float64)
    rect_to_working = homography_from_points(rect, quad)
    pitch = np.array([ww / cols, wh / rows])
    grid_to_rect = np.array([[pitch[0], 0, 0.5 * pitch[0]], [0, pitch[1], 0.5 * pitch[1]],
                             [0, 0, 1.0]])
    coarse = rect_to_working @ grid_to_rect  # grid (u, v) -> working image
    swatches = found.get("swatches", np.empty((0, 4, 2)))
    matched_grid, matched_img = _assign_swatches(swatches.reshape(-1, 4, 2).mean(axis=1),
                                                 coarse, rows, cols)
    n = len(matched_grid)
    shape = image.shape[:2]
    cells = _corner_cells(rows, cols)
    # the coarse outline as a grid -> image map (through the four corner cells)
    grid_to_image = homography_from_points(
        cells, _working_to_image(apply_homography(coarse, cells), shape, ww))
    residual, used = math.nan, 0
    if refine and n >= MIN_REFINE_SWATCHES and len({u for u, _ in matched_grid}) >= 2 \
            and len({v for _, v in matched_grid}) >= 2:
        src = np.asarray(matched_grid)
        dst = _working_to_image(np.asarray(matched_img), shape, ww)
        refined = _robust_homography(src, dst)
        if refined is not None:
            grid_to_image, keep = refined
            used = int(keep.sum())
            residual = float(np.sqrt(np.mean(np.sum(
                (apply_homography(grid_to_image, src[keep]) - dst[keep]) ** 2, axis=-1))))
    corners, symmetry = _oriented_corners(image, grid_to_image, rows, cols)
    return FoundChart(corners=corners, method="segmentation", candidates=len(charts),
                          swatches=used, residual_px=residual, orientation=symmetry)


def _assign_swatches(centres: np.ndarray, grid_to_working: np.ndarray, rows: int, cols: int
                     ) -> tuple[list[tuple[float, float]], list[np.ndarray]]:
    """Swatch centres assigned to grid cells: ``(u, v)`` cells and the centres that sit there.

    A centre belongs to the cell nearest to where the coarse outline puts it, if within
    :data:`ASSIGN_TOLERANCE` patch pitches; of several in one cell the nearest is kept.
    """
    if not len(centres):
        return [], []
    uv = apply_homography(np.linalg.inv(grid_to_working), centres)
    cell = np.rint(uv)
    dist = np.linalg.norm(uv - cell, axis=-1)
    ok = ((dist <= ASSIGN_TOLERANCE) & (cell[:, 0] >= 0) & (cell[:, 0] < cols)
          & (cell[:, 1] >= 0) & (cell[:, 1] < rows))
    best: dict[tuple[int, int], int] = {}
    for k in np.flatnonzero(ok):
        key = (int(cell[k, 0]), int(cell[k, 1]))
        if key not in best or dist[k] < dist[best[key]]:
            best[key] = int(k)
    return [(float(u), float(v)) for u, v in best], [centres[k] for k in best.values()]


def _robust_homography(src: np.ndarray, dst: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """Least-squares grid -> image homography that leaves out swatches which do not fit.

    A swatch whose contour merged with its surroundings (the black patch with a dark frame,
    say) has a displaced centre. Fit, drop the points whose distance to the fit exceeds
    ``OUTLIER_FACTOR`` times the median distance (and 0.5 px), refit; up to three rounds, never
    below :data:`MIN_REFINE_SWATCHES` points. Returns the map and the mask of points kept.
    """
    keep = np.ones(len(src), dtype=bool)
    h = None
    for _ in range(3):
        try:
            h = homography_from_points(src[keep], dst[keep])
        except InvalidValueError:
            return None
        dist = np.linalg.norm(apply_homography(h, src) - dst, axis=-1)
        limit = max(OUTLIER_FACTOR * float(np.median(dist[keep])), 0.5)
        new = keep & (dist <= limit)
        if new.sum() == keep.sum() or new.sum() < MIN_REFINE_SWATCHES:
            break
        keep = new
    return (h, keep) if h is not None else None


#: The symmetries of a rows x cols grid that keep its shape, as maps of grid ``(u, v)``.
GRID_SYMMETRIES: dict[str, Callable[[np.ndarray, int, int], np.ndarray]] = {
    "as found": lambda g, rows, cols: g,
    "turned 180 degrees": lambda g, rows, cols: np.stack(
        [cols - 1 - g[:, 0], rows - 1 - g[:, 1]], axis=-1),
    "mirrored left-right": lambda g, rows, cols: np.stack([cols - 1 - g[:, 0], g[:, 1]], axis=-1),
    "mirrored top-bottom": lambda g, rows, cols: np.stack([g[:, 0], rows - 1 - g[:, 1]], axis=-1),
}


def orientation_score(measured: np.ndarray, reference: np.ndarray) -> float:
    """How far ``(n, 3)`` measured linear RGB is from the reference, whatever the exposure.

    The mean squared difference of ``log(rgb + 1e-3)`` after removing the best common offset
    (a global exposure scale); a wrong patch order mixes dark with light and grey with colour,
    and scores far worse than any plausible camera error.
    """
    d = np.log(np.maximum(measured, 0.0) + 1e-3) - np.log(np.maximum(reference, 0.0) + 1e-3)
    return float(np.mean((d - d.mean()) ** 2))


def _oriented_corners(image: np.ndarray, grid_to_image: np.ndarray, rows: int, cols: int
                      ) -> tuple[np.ndarray, str]:
    """Corner-patch centres under the grid symmetry whose patch colours fit the reference best.

    The detector tells rotations apart by its own reference, not mirror images; the four
    symmetries of the grid (:data:`GRID_SYMMETRIES`) are scored here by
    :func:`orientation_score` of the patch means (central 0.3 x 0.3 patch pitch) against the
    default chart's linear sRGB. A best score above :data:`ORIENTATION_MARGIN` times the next
    one means the swatches found are not a ColorChecker: an error.
    """
    from fidelity.chart.locate import grid_centres, locate_chart, window_pixels
    from fidelity.colour.charts import load_chart

    reference = cm.linearize_srgb(load_chart().srgb)
    cells = _corner_cells(rows, cols)
    # Every symmetry maps the grid onto itself, so its patches are the ones found, reordered:
    # sample once, then score each order.
    try:
        location = locate_chart(apply_homography(grid_to_image, cells), image.shape, rows=rows,
                                cols=cols, window=0.3, min_pixels=1)
    except InvalidValueError:
        raise InvalidValueError("no colour chart found: the chart found lies partly outside "
                                "the image; give --corners X1,Y1,...,X4,Y4") from None
    means = np.array([s.mean(axis=0) for s in window_pixels(image, location)])
    grid = grid_centres(rows, cols)
    best: tuple[float, str, np.ndarray] | None = None
    scores: list[float] = []
    for name, symmetry in GRID_SYMMETRIES.items():
        moved = np.rint(symmetry(grid, rows, cols)).astype(int)
        order = moved[:, 1] * cols + moved[:, 0]  # patch k is seen where grid cell order[k] is
        score = orientation_score(means[order], reference)
        scores.append(score)
        if best is None or score < best[0]:
            best = (score, name, apply_homography(grid_to_image, symmetry(cells, rows, cols)))
    assert best is not None
    ranked = sorted(scores)
    if len(ranked) > 1 and ranked[0] > ORIENTATION_MARGIN * ranked[1]:
        raise InvalidValueError(
            f"no colour chart found: the patches of what looked like a chart match no "
            f"orientation of the ColorChecker clearly (scores {ranked[0]:.2f} and "
            f"{ranked[1]:.2f}); give --corners X1,Y1,...,X4,Y4")
    return best[2], best[1]


def _corner_cells(rows: int, cols: int) -> np.ndarray:
    """Grid ``(u, v)`` of the corner patches in :data:`CORNER_PATCHES` order."""
    return np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], dtype=float)


#: Chart detection methods by name.
CHART_FINDERS: dict[str, Callable[..., FoundChart]] = {
    "segmentation": _detect_segmentation,
}


def find_chart(
    pixels: np.ndarray,
    *,
    encoding: str = "linear",
    method: str = "segmentation",
    rows: int = 4,
    cols: int = 6,
    refine: bool = True,
) -> FoundChart:
    """Find the chart in an ``(H, W, 3)`` image and return its corner-patch centres.

    Parameters
    ----------
    pixels
        Linear or sRGB-encoded RGB (``encoding``), any scale; NaN/Inf/negative count as black.
    method
        A key of :data:`CHART_FINDERS`.
    refine
        Fit the grid to the patch outlines found (default); ``False`` keeps the detector's
        chart outline (the benchmark's anchor).

    Raises
    ------
    InvalidValueError
        No chart found (the message suggests ``--corners``), or a black image.
    """
    if method not in CHART_FINDERS:
        raise unknown_name("chart detection method", method, CHART_FINDERS)
    if encoding not in ("linear", "srgb"):
        raise unknown_name("encoding", encoding, ("linear", "srgb"))
    image = detection_image(pixels, encoding)
    find = CHART_FINDERS[method]
    height, width = image.shape[:2]

    def within(region: tuple[int, int, int, int]) -> FoundChart:
        x0, y0, x1, y1 = region
        found = find(image[y0:y1, x0:x1], rows, cols, refine=refine)
        return replace(found, corners=found.corners + (x0, y0), region=region)

    whole = (0, 0, width, height)
    try:
        found = within(whole)
    except InvalidValueError as exc:
        found = None
        for region in _tiles(width, height) if max(width, height) >= TILED_SEARCH_SIDE else []:
            try:
                found = within(region)
                break
            except InvalidValueError:
                continue
        if found is None:
            raise exc from None
    if not refine:
        return found
    # Second pass on the chart's surroundings: the detector works at a fixed width, so a chart
    # that fills a small part of the image gains resolution (and the fit accuracy) here.
    crop = _chart_region(found.corners, width, height)
    if (max(width, height) <= CROP_PASS_MIN_SIDE
            or (crop[2] - crop[0]) * (crop[3] - crop[1]) > 0.5 * width * height):
        return found  # the detector already saw the chart at full resolution or better
    try:
        closer = within(crop)
    except InvalidValueError:
        return found
    pitch = _pitch(found.corners, rows, cols)
    if np.linalg.norm(closer.corners - found.corners, axis=-1).max() > 0.25 * pitch:
        return found  # the passes disagree on the chart: keep the first
    return closer


def _pitch(corners: np.ndarray, rows: int, cols: int) -> float:
    """Smallest patch pitch along the chart's edges, in pixels, from the corner centres."""
    c = np.asarray(corners)
    return float(min(np.linalg.norm(c[1] - c[0]) / (cols - 1), np.linalg.norm(c[2] - c[1]) /
                     (rows - 1), np.linalg.norm(c[2] - c[3]) / (cols - 1),
                     np.linalg.norm(c[3] - c[0]) / (rows - 1)))


def _chart_region(corners: np.ndarray, width: int, height: int, rows: int = 4, cols: int = 6
                  ) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` around the chart: corner centres plus 1.5 patch pitches."""
    margin = 1.5 * max(_pitch(corners, rows, cols), 1.0)
    x0 = max(int(np.floor(corners[:, 0].min() - margin)), 0)
    y0 = max(int(np.floor(corners[:, 1].min() - margin)), 0)
    x1 = min(int(np.ceil(corners[:, 0].max() + margin)) + 1, width)
    y1 = min(int(np.ceil(corners[:, 1].max() + margin)) + 1, height)
    return x0, y0, x1, y1


def _tiles(width: int, height: int) -> list[tuple[int, int, int, int]]:
    """Half-size tiles overlapping by half (3 x 3): any chart smaller than a quarter of the
    image lies whole in one of them."""
    tw, th = (width + 1) // 2, (height + 1) // 2
    xs = [0, (width - tw) // 2, width - tw]
    ys = [0, (height - th) // 2, height - th]
    return [(x, y, x + tw, y + th) for y in ys for x in xs]


__all__ = [
    "ASPECT_RATIO_RANGE",
    "ASSIGN_TOLERANCE",
    "CROP_PASS_MIN_SIDE",
    "CHART_FINDERS",
    "MIN_REFINE_SWATCHES",
    "ORIENTATION_MARGIN",
    "OUTLIER_FACTOR",
    "TILED_SEARCH_SIDE",
    "FoundChart",
    "find_chart",
    "detection_image",
]
