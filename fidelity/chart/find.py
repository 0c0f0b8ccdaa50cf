"""Find a 24-patch colour chart in an image, so that an audit needs no hand-given corners.

The result is the same four numbers a user would give with ``--corners``: the image centres of
the dark skin, bluish green, black and white patches (:mod:`fidelity.chart.locate` conventions:
``x`` along a row, ``y`` down, pixel ``(i, j)`` at ``x = j, y = i``), with a detection
confidence. Everything after that, sampling windows, bad pixels, exposure and ΔE00, is the
audit's own and does not depend on how the corners were found.

The finder is a cascade (:func:`find_chart`, method ``cascade``):

1. **Search at a reduced size.** The image is shrunk (area average) to at most
   :data:`SEARCH_SIDE` pixels on its long side, its 99th percentile of the brightest channel
   scaled to 1, and sRGB-encoded to 8 bits (the detectors' domain).
2. **Candidates** from two detectors:

   ``mcc``
       OpenCV's Macbeth chart detector (``cv2.mcc``, opencv-contrib; Ch. Pardo et al.'s MCC
       method): each chart it finds gives its 24 patch centres, to which a grid -> image
       homography is fitted.
   ``segmentation``
       our own patch segmentation: adaptive thresholds of the grey image at
       :data:`BLOCK_FRACTIONS` of the image size, contours simplified to convex quadrilaterals
       (:func:`patch_quads`), and quadrilaterals of similar size that sit one patch pitch apart
       along each other's edges chained into a lattice (:func:`patch_lattices`); a homography
       lattice -> image is fitted to their centres. Any 4 x 6 window of the lattice, in any of
       the 8 orientations of a grid (turns, mirror images), is a candidate placement.

   Segmentation runs first; OpenCV's detector runs only when no candidate was accepted with a
   confidence of at least :data:`SURE_CONFIDENCE`.

3. **Verification** (:func:`placement_scores`): each placement of the 4 x 6 chart, including
   the detector's own answer moved one row or column either way and every orientation, samples
   its 24 patches (central 0.35 x 0.35 pitch) and is scored against the reference layout: the
   rank correlation (Spearman) between the measured and the reference patches of R, G, B,
   log(R/G) and log(B/G), averaged (:func:`colour_order`). Ranks do not change under a
   per-channel gain (coloured light, white balance, exposure) or a monotone tone curve, and a
   chart placed a row off, turned or mirrored mixes dark with light and grey with colour.
   The best placement is kept when its **confidence** (that mean rank correlation) is at
   least :data:`MIN_CONFIDENCE`, its neutral row is in order of lightness (at least
   :data:`MIN_NEUTRAL_ORDER` of the 15 pairs), the next-best placement of the same candidate
   scores at least :data:`MIN_MARGIN` lower and its patches are flat (median relative spread
   at most :data:`MAX_UNIFORMITY`); so a chart found one row or column off is corrected, never
   measured. The thresholds were chosen on a tuning set of the benchmark
   (``benchmarks/bench_find_chart.py --seed 7``) and checked on another (seed 19).
4. **Refinement at full size**: the chart's surroundings (corners plus 2 pitches) are cut from
   the full-size image (shrunk only if still larger than :data:`REFINE_SIDE`), segmented
   again, each patch outline assigned to its grid cell, and the homography fitted to all
   assigned centres by the normalised DLT (:func:`fidelity.chart.locate.homography_from_points`),
   leaving out centres more than three times the median distance off the fit. The placement
   is verified again there and kept only if it passes the same checks.
5. **Small charts in large images**: when the whole image shows no chart and it is larger than
   1.5 x :data:`SEARCH_SIDE`, four overlapping quarters are searched, each at up to
   :data:`SEARCH_SIDE` pixels.

Chart types: the 24-patch ColorChecker layout (Classic, Mini, the 24-patch page of a Passport:
one layout, whose physical sizes one photo cannot tell apart). Other patch grids found beside
the chart (a Passport's other page) are counted in ``other_charts`` and not measured. A chart
whose 24 patches continue into a larger grid of patches (a ColorChecker SG or a digital
target), or a large patch grid with no 24-patch chart, is refused with
:class:`~fidelity.core.errors.InvalidValueError` rather than measured wrongly.

Input: ``(H, W, 3)`` linear or sRGB-encoded RGB of any scale (HDR welcome). NaN, Inf and
negative values count as black for finding the chart only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.image import BAYER_PATTERNS, as_float32, is_coded
from fidelity.chart.locate import (
    CORNER_PATCHES,
    DEFAULT_WINDOW,
    apply_homography,
    homography_from_points,
)
from fidelity.colour import colorimetry as cm
from fidelity.core.errors import FidelityError, InvalidValueError, unknown_name

F64 = NDArray[np.float64]

#: Long side, in pixels, of the reduced image the chart is searched in.
SEARCH_SIDE = 1600
#: Long side, in pixels, of the chart's surroundings in which the fit is refined (full size
#: when smaller).
REFINE_SIDE = 1000
#: Adaptive-threshold block sizes, as fractions of the image's short side (odd, at least 7 px).
BLOCK_FRACTIONS = (0.025, 0.06)
#: Whether the search also looks for patches darker than their surroundings.
SEARCH_INVERSE = False
#: Offsets of the adaptive threshold (grey levels below the local mean).
THRESHOLD_OFFSETS = (2.0,)
#: Smallest patch outline, in pixels of area, that counts (a patch side of about 5 px).
MIN_QUAD_AREA = 25.0
#: Largest distance (in patch pitches) between a patch centre and the grid cell it is assigned
#: to.
ASSIGN_TOLERANCE = 0.3
#: Fewest patch outlines for a refined fit.
MIN_REFINE_SWATCHES = 6
#: A patch centre farther from the fitted grid than this many times the median distance is
#: left out of the fit.
OUTLIER_FACTOR = 3.0
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
#: Largest median spread of the sampled values within a patch (relative to their mean): a
#: placement whose windows straddle patch edges is not the chart.
MAX_UNIFORMITY = 0.15
#: Patch-like outlines in the ring of cells just outside the 4 x 6 chart that make it part of a
#: larger patch grid (a ColorChecker SG, a digital target).
LARGER_GRID_RING = 4
#: Fewest patches of a lattice beside the chart that make it another patch chart (a
#: Passport's other page).
OTHER_CHART_PATCHES = 12
#: How far beside the chart other charts are looked for, in patch pitches, and the long side
#: of the view they are looked for in.
BESIDE_PITCHES = 8.0
BESIDE_SIDE = 700
#: Patches left out of the rank correlation (those that disagree most: covered, glared).
TRIM = 2
#: Most patches judged covered (:func:`occluded_patches`) that a chart may have and still be
#: measured without them; with more, none is left out and the checks decide.
MAX_OCCLUDED = 4
#: A patch whose colour is this many times the chart's median distance from the best 3 x 3
#: camera matrix fitted to its patches is covered (a leaf, a hand, a glare).
OCCLUDED_RESIDUAL = 8.0
#: ... or whose rank disagreement (summed over the five features) is at least this and three
#: times the median, while its window is textured (relative spread at least
#: :data:`OCCLUDED_SPREAD` and five times the median).
OCCLUDED_RANKS = 15.0
OCCLUDED_SPREAD = 0.03
#: Distance (in patch pitches) from a cell just outside the chart within which a patch outline
#: of the chart's own size makes the chart part of a larger grid, once the fit is refined (an
#: SG's patches continue the grid exactly; objects beside a framed chart lie beyond its frame).
RING_TOLERANCE = 0.15
#: Side of the audit's sampling window, in patch pitches, in which covered patches are looked
#: for again once the chart is found (:data:`fidelity.chart.locate.DEFAULT_WINDOW`).
AUDIT_WINDOW = DEFAULT_WINDOW
#: Side of the sampling window used for verification, in patch pitches.
VERIFY_WINDOW = 0.35
#: Number of sample points along each side of the verification window.
VERIFY_SAMPLES = 5
#: Reference chart rows and columns: the finder knows the 24-patch layout only.
ROWS, COLS = 4, 6
#: Shortest image side, in pixels, that can hold a measurable chart: an audit samples at least
#: 9 pixels in a window of half a pitch (:data:`fidelity.chart.locate.MIN_WINDOW_PIXELS`), so a
#: pitch of 6 pixels or more, and the chart's short side spans its 4 rows of patches. Smaller
#: images are not searched (OpenCV's detector takes gigabytes and seconds on a 1-pixel-wide one).
MIN_IMAGE_SIDE = 4 * 6


@dataclass(frozen=True)
class ChartChecks:
    """How well the chart found matches the 24-patch reference layout.

    ``colour_order`` the mean Spearman rank correlation of R, G, B, log(R/G), log(B/G) between
    measured and reference patches (1: same order); ``neutral_order`` the fraction of the 15
    pairs of neutral patches in order of lightness; ``margin`` the lead of ``colour_order``
    over the next-best placement (another row, column or orientation) of the same candidate;
    ``uniformity`` the median over the patches of the standard deviation of the sampled
    linear values relative to their mean (0: flat patches).
    """

    colour_order: float
    neutral_order: float
    margin: float
    uniformity: float

    def to_json(self) -> dict[str, float]:
        """JSON form: the four numbers, rounded to 1e-4."""
        return {k: round(float(v), 4) for k, v in vars(self).items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ChartChecks:
        """Inverse of :meth:`to_json`."""
        return cls(colour_order=float(data["colour_order"]),
                   neutral_order=float(data["neutral_order"]), margin=float(data["margin"]),
                   uniformity=float(data["uniformity"]))


@dataclass(frozen=True)
class FoundChart:
    """A chart found in an image.

    ``corners`` is ``(4, 2)`` image ``(x, y)`` of the dark skin, bluish green, black and white
    patch centres; ``method`` the detector whose candidate won (``mcc`` or ``segmentation``);
    ``candidates`` the number of candidates verified; ``swatches`` the number of patch outlines
    that refined the fit at full size (0: the search's fit answered); ``residual_px`` the RMS
    distance, in image pixels, between those outlines' centres and the fitted grid (NaN
    without refinement); ``orientation`` how the chart lies in the image (its top edge's turn
    from the image's x axis, and whether it is seen mirrored); ``region`` the ``(x0, y0, x1,
    y1)`` part of the image the final fit was made in; ``confidence`` the verification's mean
    rank correlation (0-1, :class:`ChartChecks`); ``chart`` the chart type found;
    ``other_charts`` patch charts found beside it that are not the 24-patch layout (a
    Passport's other page) and were not measured; ``seconds`` the time taken; ``occluded``
    the patches (0-based, chart order: dark skin first, row by row) judged covered
    (:func:`occluded_patches`), left out of the checks and of the audit's statistics;
    ``flat_off_fit`` the patches far from what the others predict (:func:`off_the_camera_fit`)
    whose window is flat: the camera's own error or a flat cover, measured and named in a
    note, never left out (a camera's error is not hidden).
    """

    corners: np.ndarray
    method: str
    candidates: int
    swatches: int
    residual_px: float
    orientation: str = "as found"
    region: tuple[int, int, int, int] | None = None
    confidence: float = math.nan
    checks: ChartChecks | None = None
    chart: str = "24-patch ColorChecker"
    other_charts: int = 0
    seconds: float = math.nan
    notes: tuple[str, ...] = field(default_factory=tuple)
    occluded: tuple[int, ...] = ()
    flat_off_fit: tuple[int, ...] = ()

    def corners_text(self) -> str:
        """The corners as ``--corners`` takes them: ``X1,Y1,...,X4,Y4`` (0.1 px)."""
        return ",".join(f"{v:.1f}" for v in self.corners.ravel())

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``method``, ``corners``, ``corner_patches``, ``corners_text``,
        ``candidates``, ``swatches``, ``residual_px`` (null without refinement),
        ``orientation``, ``region``, ``confidence``, ``checks``, ``chart``, ``other_charts``,
        ``seconds``, ``notes``, ``occluded``, ``flat_off_fit``."""
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
            "confidence": None if math.isnan(self.confidence) else round(self.confidence, 4),
            "checks": self.checks.to_json() if self.checks else None,
            "chart": self.chart,
            "other_charts": self.other_charts,
            "seconds": None if math.isnan(self.seconds) else round(self.seconds, 4),
            "notes": list(self.notes),
            "occluded": list(self.occluded),
            "flat_off_fit": list(self.flat_off_fit),
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FoundChart:
        """Inverse of :meth:`to_json` (corners as stored, to 0.001 px; keys added since are
        optional)."""
        residual = data.get("residual_px")
        region = data.get("region")
        confidence = data.get("confidence")
        seconds = data.get("seconds")
        checks = data.get("checks")
        return cls(
            corners=np.asarray(data["corners"], dtype=np.float64), method=str(data["method"]),
            candidates=int(data["candidates"]), swatches=int(data["swatches"]),
            residual_px=math.nan if residual is None else float(residual),
            orientation=str(data.get("orientation", "as found")),
            region=(int(region[0]), int(region[1]), int(region[2]), int(region[3]))
            if region else None,
            confidence=math.nan if confidence is None else float(confidence),
            checks=ChartChecks.from_json(checks) if checks else None,
            chart=str(data.get("chart", "24-patch ColorChecker")),
            other_charts=int(data.get("other_charts", 0)),
            seconds=math.nan if seconds is None else float(seconds),
            notes=tuple(str(n) for n in data.get("notes", ())),
            occluded=tuple(int(k) for k in data.get("occluded", ())),
        )


# --------------------------------------------------------------------------------------------
# Views: part of the image, shrunk, in the detectors' domain


@dataclass(frozen=True)
class View:
    """Part of the image as the detectors see it.

    ``linear`` ``(h, w, 3)`` float32 linear RGB scaled to [0, 1]; ``bgr8`` the same,
    sRGB-encoded, 8-bit, in OpenCV's B, G, R order; ``to_image`` the 3 x 3 map of view
    ``(x, y)`` to image ``(x, y)`` (pixel centres at integers in both).
    """

    linear: np.ndarray
    bgr8: np.ndarray
    to_image: F64

    @property
    def scale(self) -> float:
        """View pixels per image pixel (along x)."""
        return float(1.0 / self.to_image[0, 0])


def _cv2() -> Any:
    """The OpenCV module, or an error that says what to install (or to give --corners)."""
    try:
        import cv2
    except ImportError as exc:  # OpenCV missing: say so rather than a bare ImportError
        raise FidelityError(f"chart detection needs OpenCV with its contrib modules "
                            f"(opencv-contrib-python-headless; {exc}); install it or give "
                            f"--corners") from None
    return cv2


_ENCODE_LUT = np.clip(np.rint(cm.delinearize_srgb(np.linspace(0.0, 1.0, 4096)) * 255), 0,
                      255).astype(np.uint8)
_DECODE_LUT = cm.linearize_srgb(np.linspace(0.0, 1.0, 65536)).astype(np.float32)


class Pyramid:
    """An image and its reductions by 2 x 2 area averages (computed when first asked for), so
    that views of any part at any reduced size cost one pass over the full image at most.

    The image is kept as given (8/16-bit codes, half or single floats: whatever
    :func:`fidelity.chart.image.read_image` decoded); a reduction is computed from it a band of
    rows at a time (:data:`PYRAMID_BAND_PIXELS`), each band converted to float32
    (:func:`fidelity.chart.image.as_float32`) and halved repeatedly, so that no full-size float
    copy is made. The result equals halving the whole float32 image level by level."""

    def __init__(self, pixels: np.ndarray) -> None:
        self.levels: dict[int, np.ndarray] = {1: np.asarray(pixels)}
        self.height, self.width = self.levels[1].shape[:2]

    def level(self, factor: int) -> np.ndarray:
        """The image averaged over ``factor`` x ``factor`` blocks (``factor`` a power of 2):
        float32 for ``factor`` > 1, the image as given for 1."""
        if factor not in self.levels:
            finer = max((f for f in self.levels if 1 < f < factor), default=1)
            source = self.levels[finer]
            step = factor // finer
            out_h, out_w = source.shape[0] // step, source.shape[1] // step
            band = max(1, PYRAMID_BAND_PIXELS // max(source.shape[1] * step, 1)) * step
            out = np.empty((out_h, out_w) + source.shape[2:], np.float32)
            for y in range(0, out_h * step, band):
                block = source[y:min(y + band, out_h * step), :out_w * step]
                out[y // step:(y + block.shape[0]) // step] = _halvings(
                    block, step, finer == 1 and not is_coded(block))
            self.levels[factor] = out
        return self.levels[factor]


#: Pixels of the image converted to float at a time when a :class:`Pyramid` level is computed.
PYRAMID_BAND_PIXELS = 1 << 20


def _halvings(block: np.ndarray, step: int, first: bool) -> np.ndarray:
    """``block`` (rows and columns multiples of ``step``) as float32, halved by 2 x 2 area
    averages until ``step`` x ``step`` blocks are averaged; ``first``: the block is of the
    image itself, whose NaN and Inf spread over their 2 x 2 block only and count as black (8-
    and 16-bit codes have none)."""

    cv2 = _cv2()
    arr = np.ascontiguousarray(as_float32(block))
    while step > 1:
        h, w = arr.shape[0] // 2, arr.shape[1] // 2
        arr = cv2.resize(arr, (w, h), interpolation=cv2.INTER_AREA)
        if first:
            arr = np.nan_to_num(arr, nan=0.0, posinf=0.0, neginf=0.0)
            first = False
        step //= 2
    if arr.ndim < block.ndim:  # OpenCV drops a last axis of length 1
        arr = arr[..., None]
    return arr


def _prepare(pyramid: Pyramid, region: tuple[int, int, int, int], max_side: int, encoding: str
             ) -> tuple[np.ndarray, F64]:
    """The region shrunk (area average) to ``max_side``, finite, non-negative, linear; with the
    3 x 3 map of its pixel coordinates to the image's."""
    cv2 = _cv2()
    x0, y0, x1, y1 = region
    s = min(1.0, max_side / max(x1 - x0, y1 - y0))
    factor = 1
    while factor * 2 * s <= 1.0 and min(pyramid.height, pyramid.width) // (factor * 2) >= 8:
        factor *= 2
    level = pyramid.level(factor)
    lx0, ly0 = x0 // factor, y0 // factor
    lx1 = min(-(-x1 // factor), level.shape[1])
    ly1 = min(-(-y1 // factor), level.shape[0])
    arr = np.ascontiguousarray(level[ly0:ly1, lx0:lx1])
    finite = factor > 1 or is_coded(arr)  # levels and 8/16-bit codes hold no NaN or Inf
    if factor == 1:
        arr = np.ascontiguousarray(as_float32(arr))
    height, width = arr.shape[:2]
    target = (max(1, round((x1 - x0) * s)), max(1, round((y1 - y0) * s)))
    if target[0] < width or target[1] < height:
        arr = cv2.resize(arr, (min(target[0], width), min(target[1], height)),
                         interpolation=cv2.INTER_AREA)
    sx, sy = arr.shape[1] / width, arr.shape[0] / height
    if not finite:
        arr = np.nan_to_num(arr, nan=0.0, posinf=0.0, neginf=0.0)
    if encoding == "srgb":  # codes in [0, 1] -> the nearest of 65536 steps -> linear
        arr = _DECODE_LUT[_codes(arr, 65535)]
    else:
        np.maximum(arr, 0.0, out=arr)
    # view -> level crop (OpenCV's pixel-centre convention) -> level -> image
    to_level = np.array([[1.0 / sx, 0.0, lx0 + 0.5 / sx - 0.5],
                         [0.0, 1.0 / sy, ly0 + 0.5 / sy - 0.5], [0.0, 0.0, 1.0]])
    level_to_image = np.array([[factor, 0.0, (factor - 1) / 2.0],
                               [0.0, factor, (factor - 1) / 2.0], [0.0, 0.0, 1.0]])
    return arr, level_to_image @ to_level


def make_view(pixels: np.ndarray | Pyramid, region: tuple[int, int, int, int], max_side: int,
              encoding: str, peak: float | None = None) -> tuple[View, float]:
    """A :class:`View` of ``pixels[y0:y1, x0:x1]`` at most ``max_side`` pixels on its long side.

    The values are divided by ``peak`` (default: the 99th percentile of the view's brightest
    channel) and clipped to [0, 1]. Returns the view and the peak used.
    """
    pyramid = pixels if isinstance(pixels, Pyramid) else Pyramid(pixels)
    arr, to_image = _prepare(pyramid, region, max_side, encoding)
    if peak is None:
        step = max(1, int(math.sqrt(arr.shape[0] * arr.shape[1] / 250_000)))
        sample = arr[::step, ::step]
        brightest = np.maximum(np.maximum(sample[..., 0], sample[..., 1]), sample[..., 2])
        peak = float(np.percentile(brightest, 99.0))
    if not peak > 0.0:
        raise InvalidValueError("no colour chart found: the image is black")
    with np.errstate(over="ignore"):
        scale = np.float32(1.0 / peak)
    if np.isfinite(scale):
        linear = np.multiply(arr, scale)
        np.clip(linear, 0.0, 1.0, out=linear)
    else:  # a denormal peak (values ~1e-40): 1/peak overflows single precision
        linear = np.clip(arr.astype(np.float64) / peak, 0.0, 1.0).astype(np.float32)
    steps = np.multiply(linear, np.float32(4095))  # linear in [0, 1] -> 4096 steps, rounded
    steps += np.float32(0.5)
    bgr8 = np.ascontiguousarray(_ENCODE_LUT[steps.astype(np.uint16)][..., ::-1])
    return View(linear=linear, bgr8=bgr8, to_image=to_image), peak


def _codes(values: np.ndarray, top: int) -> np.ndarray:
    """``rint(clip(values, 0, 1) * top)`` (``values`` NaN-free, ``top`` < 65536) as
    ``uint16`` indices into a lookup table, with one float temporary."""
    scaled: np.ndarray = np.clip(values, 0.0, 1.0)
    scaled *= np.float32(top)
    np.rint(scaled, out=scaled)
    codes: np.ndarray = scaled.astype(np.uint16)
    return codes


def detection_image(pixels: np.ndarray, encoding: str = "linear") -> np.ndarray:
    """The float32 linear image in [0, 1] that the detectors see, at full size."""
    arr = np.asarray(pixels)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    view, _ = make_view(arr, (0, 0, arr.shape[1], arr.shape[0]), max(arr.shape[:2]), encoding)
    return view.linear


# --------------------------------------------------------------------------------------------
# Patch outlines and lattices (our own segmentation)


@dataclass(frozen=True)
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
    cv2 = _cv2()
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
    near_to = _PointIndex(centres)
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


def _quad_areas_centroids(points: np.ndarray) -> tuple[F64, F64]:
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
        _, centroid = _quad_areas_centroids(corners.reshape(-1, 4, 2))
        bias = centroid - apply_homography(homography, cells)
    return np.where(np.isfinite(bias), bias, 0.0)


def patch_side(homography: np.ndarray, quads: Quads, members: np.ndarray) -> float:
    """The patches' side in grid units (pitches): the square root of the median area of the
    outlines ``members`` mapped back onto the grid, within 0.3-1."""
    corners = apply_homography(np.linalg.inv(homography),
                               np.asarray(quads.corners[members], np.float64).reshape(-1, 2))
    area = np.abs(_quad_areas_centroids(corners.reshape(-1, 4, 2))[0])
    return float(np.clip(np.sqrt(np.median(area)), 0.3, 1.0)) if len(area) else 0.8


class _PointIndex:
    """Points sorted along x, for finding those within a radius of a point."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, np.float64)
        self.order = np.argsort(self.points[:, 0], kind="stable")
        self.xs = self.points[self.order, 0]

    def __call__(self, centre: np.ndarray, radius: float) -> list[int]:
        lo = int(np.searchsorted(self.xs, centre[0] - radius, "left"))
        hi = int(np.searchsorted(self.xs, centre[0] + radius, "right"))
        cand = self.order[lo:hi]
        d = self.points[cand] - centre
        return [int(j) for j in cand[(d * d).sum(axis=1) <= radius * radius]]


@dataclass(frozen=True)
class Lattice:
    """Patch outlines on one grid: ``homography`` lattice ``(i, j)`` -> view ``(x, y)`` (one
    unit = one patch pitch), ``cells`` ``(n, 2)`` integer lattice cells occupied, ``quads``
    their indices into the :class:`Quads`."""

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
    sides = np.sqrt(quads.areas)
    near_to = _PointIndex(quads.centres)
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
            cos_a = abs(a @ aj) / (np.linalg.norm(a) * np.linalg.norm(aj) + 1e-12)
            cos_b = abs(a @ bj) / (np.linalg.norm(a) * np.linalg.norm(bj) + 1e-12)
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
                    na = ca / (np.linalg.norm(a_i) ** 2)
                    nb = cb / (np.linalg.norm(b_i) ** 2)
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
    area = float(np.median(quads.areas[members[keep]]))
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
        limit = max(OUTLIER_FACTOR * float(np.median(dist[keep])), 0.5)
        new = keep & (dist <= limit)
        if new.sum() == keep.sum() or new.sum() < max(4, MIN_REFINE_SWATCHES // 2):
            break
        keep = new
    if h is None or not np.all(np.isfinite(h)) or np.linalg.cond(h) > 1e12:
        return None
    return h, keep


# --------------------------------------------------------------------------------------------
# Verification against the reference layout


def _reference_linear() -> F64:
    from fidelity.colour.charts import load_chart

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


#: Indices of the neutral patches, white to black, in the 24-patch layout.
NEUTRALS = np.arange(18, 24)


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
    return np.asarray(residual > OCCLUDED_RESIDUAL * max(float(np.median(residual)), 1e-3))


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
    object over two patches moves those alone. ``(24, 3)`` means and ``(24,)`` spreads (:func:`sample_cells`) -> ``(24,)``
    bool (more than :data:`MAX_OCCLUDED`: a placement that is not the chart, or a chart too
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
    textured = texture >= max(OCCLUDED_SPREAD, 5.0 * float(np.median(texture)))
    disordered = ranks >= max(OCCLUDED_RANKS, 3.0 * float(np.median(ranks)))
    if strict:  # both: far off the camera's fit and textured
        return np.asarray(far & textured, dtype=bool)
    # a flat window is never judged covered: a camera's own error can put one patch far off
    # any 3 x 3 fit (a Foveon sensor's raw red, say), and leaving it out would hide the error
    return np.asarray((far | disordered) & textured, dtype=bool)


#: The 8 orientations of a grid: chart ``(u, v)`` -> lattice direction, as 2 x 2 matrices
#: (identity, turns, mirror images, transposes).
ORIENTATIONS = tuple(np.array(m, dtype=float) for m in (
    [[1, 0], [0, 1]], [[-1, 0], [0, -1]], [[-1, 0], [0, 1]], [[1, 0], [0, -1]],
    [[0, 1], [1, 0]], [[0, -1], [-1, 0]], [[0, -1], [1, 0]], [[0, 1], [-1, 0]]))


def _grid_cells() -> F64:
    r, c = np.mgrid[0:ROWS, 0:COLS]
    return np.stack([c.ravel(), r.ravel()], axis=-1).astype(np.float64)


def sample_cells(view: View, homography: np.ndarray, cells: np.ndarray,
                 window: float = VERIFY_WINDOW) -> tuple[F64, F64]:
    """Mean and relative spread of the linear view in a ``window``-pitch square about each
    lattice cell (``VERIFY_SAMPLES``\\ :sup:`2` points, bilinear). Cells whose window leaves the
    view get NaN."""
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
    spread = vals.std(axis=1).mean(axis=-1) / (mean.mean(axis=-1) + 0.02)
    mean[~inside] = np.nan
    spread[~inside] = np.nan
    return mean.astype(np.float64), spread.astype(np.float64)


@dataclass(frozen=True)
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
    by :func:`colour_order` of its sampled patches; the best, with its margin over the next
    best and its neutral order and uniformity, is returned (``None``: no placement lies in the
    view).
    """
    occ = np.asarray(occupied, dtype=np.int64)
    lo, hi = occ.min(axis=0), occ.max(axis=0)
    grid = _grid_cells()
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
    means, spread = sample_cells(view, lattice_h, uniq.astype(float))
    pm = means[inverse.ravel()].reshape(len(placements), ROWS * COLS, 3)
    ps = spread[inverse.ravel()].reshape(len(placements), ROWS * COLS)
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
    ring = _ring(cells)
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
                         uniformity=float(np.median(ps[best][clear])))
    return Placement(homography=h, checks=checks, cells=cells, source=source,
                     ring_patches=ring_patches,
                     occluded=tuple(int(k) for k in np.flatnonzero(flagged)))


def _cell_map(cells: np.ndarray) -> F64:
    """The affine map chart grid ``(u, v)`` -> lattice cell of a placement (3 x 3)."""
    grid = _grid_cells()
    a = np.c_[grid, np.ones(len(grid))]
    sol, *_ = np.linalg.lstsq(a, cells.astype(float), rcond=None)
    m = np.eye(3)
    m[:2, :] = sol.T
    return m


def _ring(cells: np.ndarray) -> set[tuple[int, int]]:
    """Lattice cells just outside the placement's 4 x 6 box (the 24 cells around it)."""
    lo, hi = cells.min(axis=0), cells.max(axis=0)
    ring: set[tuple[int, int]] = set()
    for x in range(int(lo[0]) - 1, int(hi[0]) + 2):
        for y in range(int(lo[1]) - 1, int(hi[1]) + 2):
            if not (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]):
                ring.add((x, y))
    return ring


def _accepted(p: Placement) -> bool:
    c = p.checks
    return (c.colour_order >= MIN_CONFIDENCE and c.neutral_order >= MIN_NEUTRAL_ORDER
            and c.margin >= MIN_MARGIN and c.uniformity <= MAX_UNIFORMITY)


# --------------------------------------------------------------------------------------------
# Detectors: candidates in one view


def _mcc_module() -> Any:
    cv2 = _cv2()
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
    grid = _grid_cells()
    for centres in mcc_charts(view.bgr8):
        fit = robust_homography(grid, centres)
        if fit is None:
            continue
        p = placement_scores(view, fit[0], grid.astype(np.int64), "mcc")
        if p is not None:
            found.append(p)
    return found


def _segmentation_candidates(view: View, quads: Quads | None = None
                             ) -> tuple[list[Placement], list[Lattice]]:
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
    "segmentation": lambda view: _segmentation_candidates(view)[0],
}


# --------------------------------------------------------------------------------------------
# The finder


@dataclass(frozen=True)
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
            found, lattices = _segmentation_candidates(view)
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


def _corners(h: np.ndarray) -> F64:
    return apply_homography(h, np.array([[0, 0], [COLS - 1, 0], [COLS - 1, ROWS - 1],
                                         [0, ROWS - 1]], dtype=float))


def chart_pitch(corners: np.ndarray) -> float:
    """Smallest patch pitch along the chart's edges, in pixels, from the corner centres."""
    c = np.asarray(corners)
    return float(min(np.linalg.norm(c[1] - c[0]) / (COLS - 1), np.linalg.norm(c[2] - c[1]) /
                     (ROWS - 1), np.linalg.norm(c[2] - c[3]) / (COLS - 1),
                     np.linalg.norm(c[3] - c[0]) / (ROWS - 1)))


def _chart_region(corners: np.ndarray, width: int, height: int, margin_pitches: float = 2.0
                  ) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` around the chart: corner centres plus ``margin_pitches``."""
    margin = margin_pitches * max(chart_pitch(corners), 1.0)
    x0 = max(int(np.floor(corners[:, 0].min() - margin)), 0)
    y0 = max(int(np.floor(corners[:, 1].min() - margin)), 0)
    x1 = min(int(np.ceil(corners[:, 0].max() + margin)) + 1, width)
    y1 = min(int(np.ceil(corners[:, 1].max() + margin)) + 1, height)
    return x0, y0, x1, y1


def _refine(view: View, h_view: np.ndarray) -> tuple[F64, int, float, Quads]:
    """Fit the grid to the patch outlines found in ``view`` near their cells.

    Returns the grid -> view homography (the given one when too few outlines fit), the number
    of outlines used, their RMS residual (view pixels; NaN without refinement) and the
    outlines. The threshold blocks are a quarter and half the patch pitch. The grid is fitted
    twice: to the outlines' centroids, then to the centroids less their perspective bias under
    that fit (:func:`perspective_bias`; on an oblique chart the corner patches moved by up to
    3 % of a pitch, the median error over the photos of ``benchmarks.bench_find_chart`` fell
    from 1.7 % to 0.9 % of a pitch)."""
    corners = _corners(h_view)
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
    if np.linalg.norm(_corners(h) - corners, axis=-1).max() > 0.35 * pitch:
        return np.asarray(h_view, np.float64), 0, math.nan, quads
    residual = float(np.sqrt(np.mean(np.sum((apply_homography(h, src[keep]) - dst[keep]) ** 2,
                                            axis=-1))))
    return h, int(keep.sum()), residual, quads


def _ring_patches(quads: Quads, h_view: np.ndarray, refined: bool = False) -> int:
    """Patch outlines of the chart's size centred on the cells just outside its 4 x 6 grid.

    ``refined``: the grid was fitted to the chart's own patch outlines, so an outline counts
    only within :data:`RING_TOLERANCE` of a cell and of the patches' size (0.5-1.6 times their
    area): an SG's patches continue the grid exactly, tiles or cards beside a framed chart lie
    beyond its frame. Otherwise :data:`ASSIGN_TOLERANCE` and 0.3-2 times the area."""
    if not len(quads.centres):
        return 0
    pitch = chart_pitch(_corners(h_view))
    expected = (0.84 * pitch) ** 2
    uv = apply_homography(np.linalg.inv(h_view), quads.centres)
    near = np.rint(uv)
    dist = np.linalg.norm(uv - near, axis=-1)
    tolerance, lo, hi = (RING_TOLERANCE, 0.5, 1.6) if refined else (ASSIGN_TOLERANCE, 0.3, 2.0)
    ok = (dist <= tolerance) & (quads.areas >= lo * expected) & (quads.areas <= hi * expected)
    ring = _ring(_grid_cells().astype(np.int64))
    return len({(int(a), int(b)) for a, b in near[ok]} & ring)


def _orientation(h_image: np.ndarray) -> str:
    c = _corners(h_image)
    top = c[1] - c[0]
    side = c[3] - c[0]
    angle = math.degrees(math.atan2(top[1], top[0]))
    mirrored = top[0] * side[1] - top[1] * side[0] < 0
    return f"turned {angle:z.0f} degrees" + (", mirrored" if mirrored else "")


def other_charts(image: np.ndarray | Pyramid, grid_to_image: np.ndarray, encoding: str) -> int:
    """Patch charts beside the chart found: a Passport's other page, say.

    The chart's surroundings (its corner centres plus :data:`BESIDE_PITCHES` pitches each way)
    are segmented for patches lighter and darker than their surroundings
    (:func:`patch_quads`, :func:`patch_lattices`); a lattice of at least
    :data:`OTHER_CHART_PATCHES` patches with a pitch within a factor 2 of the chart's and
    under a fifth of its patches on the chart counts as another chart.
    """
    pyramid = image if isinstance(image, Pyramid) else Pyramid(image)
    corners = _corners(grid_to_image)
    region = _chart_region(corners, pyramid.width, pyramid.height, BESIDE_PITCHES)
    view, _ = make_view(pyramid, region, BESIDE_SIDE, encoding)
    h_view = np.linalg.inv(view.to_image) @ grid_to_image
    pitch = chart_pitch(_corners(h_view))
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


def _larger_grid_error(lattices: list[Lattice]) -> InvalidValueError | None:
    big = [lt for lt in lattices if len(lt.cells) > ROWS * COLS + 4]
    if not big:
        return None
    lt = max(big, key=lambda x: len(x.cells))
    span = lt.cells.max(axis=0) - lt.cells.min(axis=0) + 1
    return InvalidValueError(
        f"the chart in the image is a grid of {len(lt.cells)}+ patches ({span[1]} x {span[0]}), "
        f"not the 24-patch ColorChecker (an SG or digital target?): fidelity measures the "
        f"24-patch layout only (Classic, Mini, Passport); give --corners of a 24-patch chart")


def _cascade(image: np.ndarray, encoding: str, refine: bool, detectors: tuple[str, ...]
             ) -> FoundChart:
    t0 = time.perf_counter()
    height, width = image.shape[:2]
    whole = (0, 0, width, height)
    pyramid = Pyramid(image)
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
        larger = _larger_grid_error([lt for _, lt in lattices_all])
        if larger is not None:
            raise larger
        if closest is None or closest.checks.colour_order < NO_CHART_CONFIDENCE:
            raise InvalidValueError("no colour chart found; give --corners X1,Y1,...,X4,Y4 "
                                    "(centres of the dark skin, bluish green, black and white "
                                    "patches)")
        owner = next(s for s in searches if s.best is closest)
        corners = _corners(owner.view.to_image @ closest.homography)
        c = closest.checks
        raise InvalidValueError(
            f"a chart-like patch grid was found but does not match the 24-patch ColorChecker "
            f"clearly (confidence {c.colour_order:.2f}, neutral order {c.neutral_order:.2f}, "
            f"margin {c.margin:.2f}, uniformity {c.uniformity:.2f}; need {MIN_CONFIDENCE:g}, "
            f"{MIN_NEUTRAL_ORDER:g}, {MIN_MARGIN:g}, <= {MAX_UNIFORMITY:g}); if it is the chart, check and give --corners "
            + ",".join(f"{v:.1f}" for v in corners.ravel()))
    if best.ring_patches >= LARGER_GRID_RING and not refine:
        raise _larger_grid_error(search.lattices) or InvalidValueError(
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
        corners0 = _corners(h_image)
        region = _chart_region(corners0, width, height)
        crop, _ = make_view(pyramid, region, REFINE_SIDE, encoding)
        to_crop = np.linalg.inv(crop.to_image)
        h_crop0 = to_crop @ h_image
        h_crop, swatches, residual_view, quads = _refine(crop, h_crop0)
        # patches on the cells around the chart: with the fit refined on the chart's own
        # patches, only those that continue its grid exactly (an SG), not objects beside it
        ring = _ring_patches(quads, h_crop, refined=swatches > 0)
        if ring >= LARGER_GRID_RING:
            raise InvalidValueError(
                f"the 24 patches found continue into a larger grid of patches ({ring} patch "
                f"outlines on the cells around them; an SG or digital target?): fidelity "
                f"measures the 24-patch ColorChecker only (Classic, Mini, Passport); give "
                f"--corners of a 24-patch chart")
        # verified again at full size: the refined placement, or a row / column / orientation
        # that fits better there; kept only if it passes the same checks
        again = placement_scores(crop, h_crop, _grid_cells().astype(np.int64), best.source)
        if again is not None and _accepted(again) \
                and again.checks.colour_order >= checks.colour_order - 0.1:
            h_image = crop.to_image @ again.homography
            checks = again.checks
            # covered patches again in the audit's own window (half a pitch): an object over
            # its edge outside the verification window would still spoil its mean
            wide_m, wide_s = sample_cells(crop, again.homography, _grid_cells(), AUDIT_WINDOW)
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
    corners = _corners(h_image)
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
        notes.append(f"patch(es) {', '.join(str(k + 1) for k in flat_far)} (in chart order) "
                     f"far from what the other patches predict but flat: the camera's own "
                     f"error or a flat cover; measured (check the image)")
    return FoundChart(corners=corners, method=best.source, candidates=candidates,
                      swatches=swatches, residual_px=residual, orientation=_orientation(h_image),
                      region=region, confidence=float(max(checks.colour_order, 0.0)),
                      checks=checks, chart=chart, other_charts=others,
                      seconds=time.perf_counter() - t0, notes=tuple(notes), occluded=occluded,
                      flat_off_fit=flat_far)


def check_corners(pixels: np.ndarray, corners: np.ndarray, *, encoding: str = "linear"
                  ) -> ChartChecks | None:
    """How well the 24 patches at given corner centres match the reference layout.

    The :class:`ChartChecks` of the placement the corners give (sampled at up to
    :data:`REFINE_SIDE` pixels), its ``margin`` taken over the best other placement (another
    row, column or orientation: negative when one fits better, i.e. the corners are probably
    off). ``None`` when the chart cannot be sampled.
    """
    arr = np.asarray(pixels)
    pts = np.asarray(corners, dtype=np.float64)
    try:
        grid_to_image = homography_from_points(_corners(np.eye(3)), pts)
        region = _chart_region(pts, arr.shape[1], arr.shape[0])
        view, _ = make_view(arr, region, REFINE_SIDE, encoding)
    except InvalidValueError:
        return None
    h_view = np.linalg.inv(view.to_image) @ grid_to_image
    placement = placement_scores(view, h_view, _grid_cells().astype(np.int64), "given",
                                 given=True)
    return placement.checks if placement is not None else None


def _finder(detectors: tuple[str, ...]) -> Callable[..., FoundChart]:
    def find(image: np.ndarray, encoding: str = "linear", refine: bool = True) -> FoundChart:
        return _cascade(image, encoding, refine, detectors)
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
) -> FoundChart:
    """Find the 24-patch chart in an ``(H, W, 3)`` image and return its corner-patch centres.

    Parameters
    ----------
    pixels
        Linear or sRGB-encoded RGB (``encoding``), any scale; NaN/Inf/negative count as black.
    method
        A key of :data:`CHART_FINDERS`.
    rows, cols
        The chart's layout; only the 4 x 6 ColorChecker is known.
    refine
        Refine the fit at full size (default); ``False`` keeps the search's fit.

    Raises
    ------
    InvalidValueError
        No chart found, a chart that does not match the 24-patch layout clearly (the message
        gives the corners of the best guess, to check and pass as ``--corners``), a chart of
        another kind (SG, digital target), or a black image.
    FidelityError
        OpenCV without its contrib modules.
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
    return CHART_FINDERS[method](arr, encoding=encoding, refine=refine)


#: Least lead in confidence of the best-fitting CFA pattern over the next one (a pattern the
#: finder refuses counts as 0) for a one-channel mosaic's pattern to be taken as found.
BAYER_MARGIN = 0.15


@dataclass(frozen=True)
class BayerFit:
    """How each CFA pattern fits a one-channel mosaic: ``confidence`` per pattern (the
    chart finder's, 0 where it found no chart), the ``pattern`` taken (None: none fits
    unambiguously) and the ``margin`` of the best over the next."""

    confidence: Mapping[str, float]
    pattern: str | None
    margin: float

    def describe(self) -> str:
        """The confidences in words: ``RGGB 0.99, BGGR 0.00, ...``."""
        return ", ".join(f"{k} {v:.2f}" for k, v in self.confidence.items())


def superpixels(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """``(H, W)`` Bayer mosaic -> ``(H // 2, W // 2, 3)`` float32 R, G, B: each 2 x 2 block's
    red and blue sample and the mean of its two green ones, for CFA ``pattern``
    (:data:`BAYER_PATTERNS`). No interpolation: enough to find a chart, cheap for all four."""
    arr = np.asarray(mosaic, dtype=np.float32)
    h, w = arr.shape[0] // 2 * 2, arr.shape[1] // 2 * 2
    if pattern.upper() not in BAYER_PATTERNS:
        raise unknown_name("CFA pattern", pattern, BAYER_PATTERNS)
    sites = {(dy, dx): arr[dy:h:2, dx:w:2] for dy in (0, 1) for dx in (0, 1)}
    where = {c: [divmod(k, 2) for k, x in enumerate(pattern.upper()) if x == c] for c in "RGB"}
    out = np.empty((h // 2, w // 2, 3), np.float32)
    out[..., 0] = sites[where["R"][0]]
    out[..., 1] = (sites[where["G"][0]] + sites[where["G"][1]]) / 2.0
    out[..., 2] = sites[where["B"][0]]
    return out


def bayer_pattern(mosaic: np.ndarray) -> BayerFit:
    """Which CFA pattern a one-channel raw mosaic holding a 24-patch chart was taken with.

    The chart is searched in the half-size image of each of the four patterns
    (:func:`superpixels`, linear); a pattern is taken when the finder accepts the chart in it
    and its confidence leads every other pattern's by at least :data:`BAYER_MARGIN`. A wrong
    pattern swaps red with blue (the chart's colours out of order) or takes green from the red
    and blue sites (greys for colours), so a chart tells them apart; a mosaic with no chart,
    or one in which two patterns fit nearly as well, gives ``pattern`` None."""
    arr = np.asarray(mosaic)
    if arr.ndim != 2:
        raise InvalidValueError(f"a mosaic must be (H, W), got shape {arr.shape}")
    confidence: dict[str, float] = {}
    for pattern in BAYER_PATTERNS:
        try:
            found = find_chart(superpixels(arr, pattern), encoding="linear", refine=False)
            confidence[pattern] = float(found.confidence)
        except InvalidValueError:
            confidence[pattern] = 0.0
    ranked = sorted(confidence.values(), reverse=True)
    margin = ranked[0] - ranked[1]
    best = max(confidence, key=lambda k: confidence[k])
    chosen = best if ranked[0] > 0.0 and margin >= BAYER_MARGIN else None
    return BayerFit(confidence=confidence, pattern=chosen, margin=margin)


__all__ = [
    "ASSIGN_TOLERANCE",
    "BAYER_MARGIN",
    "BayerFit",
    "bayer_pattern",
    "superpixels",
    "CHART_FINDERS",
    "DETECTORS",
    "MIN_CONFIDENCE",
    "MIN_IMAGE_SIDE",
    "MAX_UNIFORMITY",
    "MIN_MARGIN",
    "MIN_NEUTRAL_ORDER",
    "MAX_OCCLUDED",
    "ORIENTATIONS",
    "Pyramid",
    "REFINE_SIDE",
    "SEARCH_SIDE",
    "SURE_CONFIDENCE",
    "ChartChecks",
    "FoundChart",
    "Lattice",
    "Placement",
    "Quads",
    "View",
    "chart_pitch",
    "check_corners",
    "colour_order",
    "detection_image",
    "find_chart",
    "make_view",
    "mcc_charts",
    "neutral_order",
    "occluded_patches",
    "other_charts",
    "patch_lattices",
    "patch_quads",
    "placement_scores",
    "robust_homography",
    "sample_cells",
]
