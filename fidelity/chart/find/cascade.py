"""The chart finder's cascade: search a reduced view, verify, refine at full size.

:func:`find_chart` runs one of :data:`CHART_FINDERS` (the package's docstring,
:mod:`fidelity.chart.find`, describes the steps); :func:`check_corners` verifies corners given
by hand the same way. The thresholds a candidate must pass to be taken for the chart
(:data:`MIN_CONFIDENCE`, :data:`MIN_NEUTRAL_ORDER`, :data:`MIN_MARGIN`,
:data:`MAX_UNIFORMITY`) and the sizes the search and the refinement work at live here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.find.candidates import DETECTORS, segmentation_candidates
from fidelity.chart.find.lattice import (
    ASSIGN_TOLERANCE,
    MIN_REFINE_SWATCHES,
    Lattice,
    patch_side,
    perspective_bias,
    robust_homography,
)
from fidelity.chart.find.outlines import Quads, patch_quads
from fidelity.chart.find.placement import MAX_OCCLUDED, Placement, placement_scores, sample_cells
from fidelity.chart.find.reference import (
    COLS,
    ROWS,
    corner_centres,
    grid_cells,
    occluded_patches,
    off_the_camera_fit,
)
from fidelity.chart.find.result import ChartChecks, FoundChart, flat_off_fit_note
from fidelity.chart.find.surroundings import (
    LARGER_GRID_RING,
    chart_pitch,
    chart_region,
    larger_grid_error,
    other_charts,
    ring_patches,
)
from fidelity.chart.find.view import Pyramid, View, make_view
from fidelity.chart.locate import DEFAULT_WINDOW, apply_homography, homography_from_points
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Long side, in pixels, of the reduced image the chart is searched in.
SEARCH_SIDE = 1600
#: Long side, in pixels, of the chart's surroundings in which the fit is refined (full size
#: when smaller).
REFINE_SIDE = 1000
#: Fewest mean rank correlation (of 1) a placement needs to be taken for the chart.
MIN_CONFIDENCE = 0.7
#: A candidate accepted with at least this confidence ends the search (the next detector in
#: the cascade is not run).
SURE_CONFIDENCE = 0.9
#: Below this mean rank correlation nothing chart-like was found at all.
NO_CHART_CONFIDENCE = 0.5
#: Fewest fraction of the 15 pairs of neutral patches in order of lightness.
MIN_NEUTRAL_ORDER = 0.8
#: Smallest lead of the best placement of a candidate over its next-best placement.
MIN_MARGIN = 0.15
#: Largest median spread of the sampled values within a patch beyond their white noise
#: (relative to their mean; :func:`~fidelity.chart.find.placement.structured_spread`): a
#: placement whose windows straddle patch edges is not the chart, a noisy chart still is.
MAX_UNIFORMITY = 0.15
#: Side of the audit's sampling window, in patch pitches, in which covered patches are looked
#: for again once the chart is found (:data:`fidelity.chart.locate.DEFAULT_WINDOW`).
AUDIT_WINDOW = DEFAULT_WINDOW
#: Shortest image side, in pixels, that can hold a measurable chart: an audit samples at least
#: 9 pixels in a window of half a pitch (:data:`fidelity.chart.locate.MIN_WINDOW_PIXELS`), so a
#: pitch of 6 pixels or more, and the chart's short side spans its 4 rows of patches. Smaller
#: images are not searched (OpenCV's detector takes gigabytes and seconds on a 1-pixel-wide one).
MIN_IMAGE_SIDE = 4 * 6


def _accepted(p: Placement) -> bool:
    c = p.checks
    return (c.colour_order >= MIN_CONFIDENCE and c.neutral_order >= MIN_NEUTRAL_ORDER
            and c.margin >= MIN_MARGIN and c.uniformity <= MAX_UNIFORMITY)


@record
class _Search:
    best: Placement | None
    view: View
    candidates: int
    lattices: list[Lattice]


def _search(view: View, detectors: tuple[str, ...]) -> _Search:
    candidates: list[Placement] = []
    lattices: list[Lattice] = []
    for name in detectors:
        if any(_accepted(p) and p.checks.colour_order >= SURE_CONFIDENCE for p in candidates):
            break  # the next detector could not do better
        if name == "segmentation":
            found, lattices = segmentation_candidates(view)
        else:
            found = DETECTORS[name](view)
        candidates.extend(found)
    best = max(candidates, key=lambda p: p.checks.colour_order, default=None)
    accepted = [p for p in candidates if _accepted(p)]
    if accepted:
        best = max(accepted, key=lambda p: p.checks.colour_order)
    return _Search(best=best, view=view, candidates=len(candidates), lattices=lattices)


def _quarters(width: int, height: int) -> list[tuple[int, int, int, int]]:
    """Four overlapping quarters (each 5/8 of the side): a chart smaller than 1/4 of the
    image lies whole in one of them."""
    tw, th = (width * 5 + 7) // 8, (height * 5 + 7) // 8
    return [(x, y, x + tw, y + th) for y in (0, height - th) for x in (0, width - tw)]


def _refine(view: View, h_view: np.ndarray) -> tuple[F64, int, float, Quads]:
    """Fit the grid to the patch outlines found in ``view`` near their cells.

    Returns the grid -> view homography (the given one when too few outlines fit), the number
    of outlines used, their RMS residual (view pixels; NaN without refinement) and the
    outlines. The threshold blocks are a quarter and half the patch pitch. The grid is fitted
    twice: to the outlines' centroids, then to the centroids less their perspective bias under
    that fit (:func:`~fidelity.chart.find.lattice.perspective_bias`; on an oblique chart the corner patches moved by up to
    3 % of a pitch, the median error over the photos of ``benchmarks.speed.find_chart`` fell
    from 1.7 % to 0.9 % of a pitch)."""
    corners = corner_centres(h_view)
    pitch = chart_pitch(corners)
    quads = patch_quads(view.bgr8, blocks=(round(0.25 * pitch), round(0.5 * pitch)), inverse=False)
    if not len(quads.centres):
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    uv = apply_homography(np.linalg.inv(h_view), quads.centres)
    near = np.rint(uv)
    dist = np.linalg.norm(uv - near, axis=-1)
    expected = (0.84 * pitch) ** 2
    ok = ((dist <= ASSIGN_TOLERANCE) & (near[:, 0] >= 0) & (near[:, 0] < COLS)
          & (near[:, 1] >= 0) & (near[:, 1] < ROWS) & (quads.areas >= 0.25 * expected)
          & (quads.areas <= 2.5 * expected))
    best: dict[tuple[int, int], int] = {}
    for k in np.flatnonzero(ok):
        key = (int(near[k, 0]), int(near[k, 1]))
        if key not in best or dist[k] < dist[best[key]]:
            best[key] = int(k)
    if len(best) < MIN_REFINE_SWATCHES or len({u for u, _ in best}) < 2 \
            or len({v for _, v in best}) < 2:
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    src = np.array(list(best.keys()), dtype=float)
    members = np.array(list(best.values()))
    fit = robust_homography(src, quads.centres[members])
    if fit is None:
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    # The outlines' centroids lean towards the nearer side of an oblique chart: refit to the
    # centroids less the bias this fit predicts for patches of their size.
    h, keep = fit
    dst = quads.centres[members] - perspective_bias(h, src, patch_side(h, quads, members[keep]))
    fit = robust_homography(src, dst)
    if fit is None:
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    h, keep = fit
    if np.linalg.norm(corner_centres(h) - corners, axis=-1).max() > 0.35 * pitch:
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    residual = float(np.sqrt(np.mean(np.sum((apply_homography(h, src[keep]) - dst[keep]) ** 2,
                                            axis=-1))))
    return h, int(keep.sum()), residual, quads


def _orientation(h_image: np.ndarray) -> str:
    c = corner_centres(h_image)
    top = c[1] - c[0]
    side = c[3] - c[0]
    angle = math.degrees(math.atan2(top[1], top[0]))
    mirrored = top[0] * side[1] - top[1] * side[0] < 0
    return f"turned {angle:z.0f} degrees" + (", mirrored" if mirrored else "")


def _cascade(image: np.ndarray, encoding: str, refine: bool, detectors: tuple[str, ...],
             levels: Mapping[int, np.ndarray] | None = None) -> FoundChart:
    t0 = time.perf_counter()
    height, width = image.shape[:2]
    whole = (0, 0, width, height)
    pyramid = Pyramid(image, levels)
    view, peak = make_view(pyramid, whole, SEARCH_SIDE, encoding)
    search = _search(view, detectors)
    searches = [search]
    if (search.best is None or not _accepted(search.best)) \
            and max(width, height) > 1.5 * SEARCH_SIDE:
        for quarter in _quarters(width, height):
            tile, _ = make_view(pyramid, quarter, SEARCH_SIDE, encoding, peak)
            s = _search(tile, detectors)
            searches.append(s)
            if s.best is not None and _accepted(s.best):
                search = s
                break
    candidates = sum(s.candidates for s in searches)
    lattices_all = [(s, lt) for s in searches for lt in s.lattices]
    best = search.best
    if best is None or not _accepted(best):
        tried = [s.best for s in searches if s.best is not None]
        closest = max(tried, key=lambda p: p.checks.colour_order, default=None)
        larger = larger_grid_error([lt for _, lt in lattices_all])
        if larger is not None:
            raise larger
        if closest is None or closest.checks.colour_order < NO_CHART_CONFIDENCE:
            raise InvalidValueError("no colour chart found; give --corners X1,Y1,...,X4,Y4 "
                                    "(centres of the dark skin, bluish green, black and white "
                                    "patches)")
        owner = next(s for s in searches if s.best is closest)
        corners = corner_centres(owner.view.to_image @ closest.homography)
        c = closest.checks
        raise InvalidValueError(
            f"a chart-like patch grid was found but does not match the 24-patch ColorChecker "
            f"clearly (confidence {c.colour_order:.2f}, neutral order {c.neutral_order:.2f}, "
            f"margin {c.margin:.2f}, uniformity {c.uniformity:.2f}; need {MIN_CONFIDENCE:g}, "
            f"{MIN_NEUTRAL_ORDER:g}, {MIN_MARGIN:g}, <= {MAX_UNIFORMITY:g}); if it is the chart, check and give --corners "
            + ",".join(f"{v:.1f}" for v in corners.ravel()))
    if best.ring_patches >= LARGER_GRID_RING and not refine:
        raise larger_grid_error(search.lattices) or InvalidValueError(
            "the 24 patches found continue into a larger grid of patches (an SG or digital "
            "target?): fidelity measures the 24-patch layout only; give --corners")
    h_image = search.view.to_image @ best.homography
    checks = best.checks
    occluded = best.occluded
    flat_far: tuple[int, ...] = ()
    swatches, residual = 0, math.nan
    region = None
    notes: list[str] = []
    if refine:
        corners0 = corner_centres(h_image)
        region = chart_region(corners0, width, height)
        crop, _ = make_view(pyramid, region, REFINE_SIDE, encoding)
        to_crop = np.linalg.inv(crop.to_image)
        h_crop0 = to_crop @ h_image
        h_crop, swatches, residual_view, quads = _refine(crop, h_crop0)
        # patches on the cells around the chart: with the fit refined on the chart's own
        # patches, only those that continue its grid exactly (an SG), not objects beside it
        ring = ring_patches(quads, h_crop, refined=swatches > 0)
        if ring >= LARGER_GRID_RING:
            raise InvalidValueError(
                f"the 24 patches found continue into a larger grid of patches ({ring} patch "
                f"outlines on the cells around them; an SG or digital target?): fidelity "
                f"measures the 24-patch ColorChecker only (Classic, Mini, Passport); give "
                f"--corners of a 24-patch chart")
        # verified again at full size: the refined placement, or a row / column / orientation
        # that fits better there; kept only if it passes the same checks
        again = placement_scores(crop, h_crop, grid_cells().astype(np.int64), best.source)
        if again is not None and _accepted(again) \
                and again.checks.colour_order >= checks.colour_order - 0.1:
            h_image = crop.to_image @ again.homography
            checks = again.checks
            # covered patches again in the audit's own window (half a pitch): an object over
            # its edge outside the verification window would still spoil its mean
            wide_m, wide_s = sample_cells(crop, again.homography, grid_cells(), AUDIT_WINDOW)
            wide = (occluded_patches(wide_m, wide_s, strict=True)
                    if np.all(np.isfinite(wide_m)) else None)
            occluded = again.occluded
            if wide is not None and wide.any():
                occluded = tuple(sorted(set(occluded) | {int(k) for k in np.flatnonzero(wide)}))
            if np.all(np.isfinite(wide_m)):
                flat_far = tuple(int(k) for k in np.flatnonzero(off_the_camera_fit(wide_m))
                                 if int(k) not in occluded)
            residual = residual_view / crop.scale if swatches else math.nan
        else:
            swatches = 0
    corners = corner_centres(h_image)
    if len(occluded) > MAX_OCCLUDED:
        raise InvalidValueError(
            f"the chart was found but {len(occluded)} of its patches look covered (numbers "
            f"{', '.join(str(k + 1) for k in occluded)} in chart order; at most "
            f"{MAX_OCCLUDED} are left out): not measured; to measure all 24 anyway, check and "
            f"give --corners " + ",".join(f"{v:.1f}" for v in corners.ravel()))
    others = other_charts(pyramid, h_image, encoding) if refine else 0
    chart = "24-patch ColorChecker"
    if others:
        notes.append(f"{others} other patch chart(s) beside it, not the 24-patch layout "
                     f"(a ColorChecker Passport's other page? tiles?), not measured")
        chart += " (the 24-patch one of several charts: Passport?)"
    if occluded:
        notes.append(f"{len(occluded)} patch(es) covered (numbers "
                     f"{', '.join(str(k + 1) for k in occluded)} in chart order), left out")
    if flat_far:
        notes.append(flat_off_fit_note(flat_far))
    return FoundChart(corners=corners, method=best.source, candidates=candidates,
                      swatches=swatches, residual_px=residual, orientation=_orientation(h_image),
                      region=region, confidence=float(max(checks.colour_order, 0.0)),
                      checks=checks, chart=chart, other_charts=others,
                      seconds=time.perf_counter() - t0, notes=tuple(notes), occluded=occluded,
                      flat_off_fit=flat_far)


def check_corners(pixels: np.ndarray, corners: np.ndarray, *, encoding: str = "linear"
                  ) -> ChartChecks | None:
    """How well the 24 patches at given corner centres match the reference layout.

    The :class:`~fidelity.chart.find.result.ChartChecks` of the placement the corners give (sampled at up to
    :data:`REFINE_SIDE` pixels), its ``margin`` taken over the best other placement (another
    row, column or orientation: negative when one fits better, i.e. the corners are probably
    off). ``None`` when the chart cannot be sampled.
    """
    arr = np.asarray(pixels)
    pts = np.asarray(corners, dtype=np.float64)
    try:
        grid_to_image = homography_from_points(corner_centres(np.eye(3)), pts)
        region = chart_region(pts, arr.shape[1], arr.shape[0])
        view, _ = make_view(arr, region, REFINE_SIDE, encoding)
    except InvalidValueError:
        return None
    h_view = np.linalg.inv(view.to_image) @ grid_to_image
    placement = placement_scores(view, h_view, grid_cells().astype(np.int64), "given",
                                 given=True)
    return placement.checks if placement is not None else None


def _finder(detectors: tuple[str, ...]) -> Callable[..., FoundChart]:
    def find(image: np.ndarray, encoding: str = "linear", refine: bool = True,
             levels: Mapping[int, np.ndarray] | None = None) -> FoundChart:
        return _cascade(image, encoding, refine, detectors, levels)
    return find


#: Chart finders by name: the cascade (both detectors, the default) or one detector alone
#: (with the same verification and refinement).
CHART_FINDERS: dict[str, Callable[..., FoundChart]] = {
    "cascade": _finder(("segmentation", "mcc")),
    "mcc": _finder(("mcc",)),
    "segmentation": _finder(("segmentation",)),
}


def find_chart(
    pixels: np.ndarray,
    *,
    encoding: str = "linear",
    method: str = "cascade",
    rows: int = 4,
    cols: int = 6,
    refine: bool = True,
    levels: Mapping[int, np.ndarray] | None = None,
) -> FoundChart:
    """Find the 24-patch chart in an ``(H, W, 3)`` image and return its corner-patch centres.

    Parameters
    ----------
    pixels
        Linear or sRGB-encoded RGB (``encoding``), any scale; NaN/Inf/negative count as black.
        Shape (H, W, 3), at least :data:`MIN_IMAGE_SIDE` pixels on the short side.
    encoding
        ``linear`` (default) or ``srgb``: how the pixel values are encoded.
    method
        A key of :data:`CHART_FINDERS`: ``cascade`` (default: both detectors), ``mcc`` or
        ``segmentation`` (one detector alone, the same verification and refinement).
    rows, cols
        The chart's layout; only the 4 x 6 ColorChecker is known.
    refine
        Refine the fit at full size (default); ``False`` keeps the search's fit.
    levels
        Reductions of the image made already (factor -> ``(H // factor, W // factor, 3)``
        float32, :class:`~fidelity.chart.find.view.Pyramid`): a large JPEG's decoded at a
        quarter of its size (:func:`~fidelity.chart.find.view.jpeg_level`); None: computed
        from ``pixels``.

    Returns
    -------
    FoundChart
        The corner-patch centres (4, 2) in image pixels ``(x, y)``, the detector that won,
        the verification's confidence and checks, the refinement's residual, the covered
        patches, notes and the time taken.

    Raises
    ------
    InvalidValueError
        No chart found, a chart that does not match the 24-patch layout clearly (the message
        gives the corners of the best guess, to check and pass as ``--corners``), a chart of
        another kind (SG, digital target), or a black image; a layout other than 4 x 6, an
        image not of shape (H, W, 3) or too small; too many patches covered. Exit code 2.
    UnknownNameError
        An unknown ``method`` or ``encoding``. Exit code 2.
    FidelityError
        OpenCV without its contrib modules. Exit code 2.
    """
    if method not in CHART_FINDERS:
        raise unknown_name("chart detection method", method, CHART_FINDERS)
    if encoding not in ("linear", "srgb"):
        raise unknown_name("encoding", encoding, ("linear", "srgb"))
    if (rows, cols) != (ROWS, COLS):
        raise InvalidValueError(f"chart detection knows the 4 x 6 ColorChecker only, not "
                                f"{rows} x {cols}")
    arr = np.asarray(pixels)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    if min(arr.shape[:2]) < MIN_IMAGE_SIDE:
        raise InvalidValueError(
            f"no colour chart found: the image is {arr.shape[1]}x{arr.shape[0]} pixels, too "
            f"small to hold a measurable 24-patch chart (at least {MIN_IMAGE_SIDE} pixels on "
            f"its short side)")
    return CHART_FINDERS[method](arr, encoding=encoding, refine=refine, levels=levels)


__all__ = [
    "AUDIT_WINDOW",
    "CHART_FINDERS",
    "MAX_UNIFORMITY",
    "MIN_CONFIDENCE",
    "MIN_IMAGE_SIDE",
    "MIN_MARGIN",
    "MIN_NEUTRAL_ORDER",
    "NO_CHART_CONFIDENCE",
    "REFINE_SIDE",
    "SEARCH_SIDE",
    "SURE_CONFIDENCE",
    "check_corners",
    "find_chart",
]
