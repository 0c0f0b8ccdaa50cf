"""Blind spots of the chart ΔE: camera errors a mean over 24 flat patches cannot see.

The chart ΔE averages 24 patches, 18 of them coloured and none darker than the black patch
(L* ≈ 20). Two kinds of camera error hide from it (``reports/validation/analysis.md``):

- **Shadow tones.** A tone curve that bends below the darkest patch (a gamma-2.2 power law
  instead of the sRGB curve, crushed or lifted blacks) changes what fills a large part of real
  photographs, while the chart sees it in one patch. :func:`shadow_tone` reads the tone curve
  of the neutral patches at its dark end: the slope of measured against reference luminance
  between the two darkest neutral patches on log-log axes (the local gamma; 1 when the tone
  is right, and unchanged by an exposure error, which scales every luminance alike). A slope
  off 1 by more than :data:`SHADOW_SLOPE_TOLERANCE` bends the shadows: the warning gives the
  error that slope means at reference L* 10 (:data:`SHADOW_PROBE_L`) when extrapolated, next to
  the error at the black patch.
- **Posterisation.** Few output levels turn smooth gradients into bands (false contours); a
  flat patch is rounded to a nearby level and barely moves. :func:`bit_depth` warns for a
  camera model that quantises to at most :data:`MIN_BITS` bits (64 levels per channel);
  :func:`banding` estimates the levels an integer-coded image really uses from its smooth
  regions: between neighbouring pixels that differ a little (at most
  :data:`SMOOTH_STEP_FRACTION` of the code range, so not across patch or object edges), the
  quantisation step ``q`` is the largest step of which nearly all of them
  (:data:`MULTIPLE_SHARE`) are multiples; effective bits = log2(code range / q + 1). A
  posterised image steps only by multiples of its level spacing; a clean image's steps take
  every value, whatever the one most common among them (a noise-free 16-bit render's few
  antialiased edges), so it keeps its full depth. An image without enough such pairs (only
  flat patches and sharp edges, as a closed-form chart render) cannot be judged, and says so.

Each check returns a :class:`BlindSpot`: whether the camera is at risk, the value measured, the
threshold and a one-line reason; :func:`warnings` keeps those at risk.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.colour.colorimetry import lab_to_xyz, xyz_to_lab
from fidelity.core.record import record
from fidelity.measure.colour import neutral_patches

if TYPE_CHECKING:
    from fidelity.measure.colour import ChartMeasurement

#: Largest difference of the shadow end's local gamma from 1 that is not a warning (5 % more or less
#: shadow contrast; the 30 cameras of the validation suite without a tone error stay within
#: 0.035, gamma 2.2 reads 0.90).
SHADOW_SLOPE_TOLERANCE = 0.05
#: Reference L* at which the extrapolated shadow error is stated.
SHADOW_PROBE_L = 10.0
#: Bit depths at or below this are posterisation risks (64 levels per channel).
MIN_BITS = 6
#: Neighbour differences up to this share of the code range count as smooth (not an edge).
SMOOTH_STEP_FRACTION = 0.08
#: Share of the smooth neighbour steps that must be multiples of the quantisation step
#: (the rest: edges and gradients between the levels, JPEG's rounding).
MULTIPLE_SHARE = 0.9
#: Smallest most common step (codes) whose levels may lie between codes (see
#: :func:`quantisation_step`).
MIN_SPACING = 4
#: Fewest smooth neighbour pairs (per channel, summed) needed to judge banding.
MIN_SMOOTH_PAIRS = 2000
#: Kinds of check, in report order.
KINDS: tuple[str, ...] = ("shadow-tone", "bit-depth", "banding")


@record
class BlindSpot:
    """One blind-spot check: its ``kind`` (:data:`KINDS`), whether the camera is ``at_risk``
    (None: could not be judged), the ``value`` measured and its ``threshold`` (units in
    ``reason``), and a one-line ``reason``.

    Attributes
    ----------
    kind
        ``shadow-tone``, ``bit-depth`` or ``banding`` (:data:`KINDS`).
    at_risk
        True: the camera is at risk of an error the chart ΔE cannot see; False: not; None:
        could not be judged.
    value
        What was measured: the local gamma of the shadow end (1 is right), the camera's
        quantisation bits, or the image's effective bits; None when not measured (float
        output, not judged).
    threshold
        The limit ``value`` is judged against: the shadow slope's tolerance (±, default
        :data:`SHADOW_SLOPE_TOLERANCE`) or the bit depth at or below which banding is a risk
        (:data:`MIN_BITS`).
    reason
        One line saying what was found, for the report.
    """

    kind: str
    at_risk: bool | None
    value: float | None
    threshold: float | None
    reason: str

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"kind": self.kind, "at_risk": self.at_risk, "value": self.value,
                "threshold": self.threshold, "reason": self.reason}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BlindSpot:
        """Inverse of :meth:`to_json`."""
        value, threshold = d.get("value"), d.get("threshold")
        return cls(str(d["kind"]), d.get("at_risk"),
                   None if value is None else float(value),
                   None if threshold is None else float(threshold), str(d["reason"]))

    @property
    def warning(self) -> str:
        """``"warning: <reason>"``."""
        return f"warning: {self.reason}"


def _lab_l(y: float) -> float:
    return float(xyz_to_lab(np.array([y * 0.95047, y, y * 1.08883]))[0])


def _y_of_l(lightness: float) -> float:
    return float(lab_to_xyz(np.array([lightness, 0.0, 0.0]))[1])


def shadow_tone(measurement: ChartMeasurement,
                tolerance: float = SHADOW_SLOPE_TOLERANCE) -> BlindSpot:
    """The dark end of the neutral patches' tone curve (module docstring)."""
    idx = list(neutral_patches(measurement))
    if len(idx) < 2:
        return BlindSpot("shadow-tone", None, None, tolerance,
                         "shadow tones not judged: the chart has fewer than two neutral patches")
    y_ref = lab_to_xyz(measurement.reference_lab[idx])[:, 1]
    y_meas = lab_to_xyz(measurement.lab[idx])[:, 1]
    order = np.argsort(y_ref)
    (r1, r2), (m1, m2) = y_ref[order[:2]], y_meas[order[:2]]
    names = [measurement.patch_names[idx[k]] for k in order[:2]]
    if not (np.isfinite(r1) and np.isfinite(r2) and r1 > 0 and r2 > r1 * (1 + 1e-6)):
        return BlindSpot("shadow-tone", None, None, tolerance,
                         f"shadow tones not judged: the reference's darkest neutral patches "
                         f"({names[0]}, {names[1]}) do not differ in luminance")
    if not (np.isfinite(m1) and np.isfinite(m2)) or m1 <= 0 or m2 <= 0 or m2 <= m1:
        return BlindSpot("shadow-tone", True, None, tolerance,
                         f"shadow tones: the darkest neutral patches ({names[0]}, {names[1]}) "
                         "are clipped to black or out of order; the tone curve's dark end is "
                         "lost, which a mean over 24 patches barely sees")
    slope = float(math.log(m2 / m1) / math.log(r2 / r1))
    dl_black = _lab_l(float(m1)) - _lab_l(float(r1))
    y_probe = _y_of_l(SHADOW_PROBE_L)
    dl_probe = _lab_l(float(m1) * (y_probe / float(r1)) ** slope) - SHADOW_PROBE_L
    off = abs(slope - 1.0)
    at_risk = off > tolerance
    if at_risk:
        more = (f"; extrapolated to L* {SHADOW_PROBE_L:g} it is ΔL* {dl_probe:+z.1f}, more than "
                f"the ΔL* {dl_black:+z.1f} at the {names[0]} patch"
                if abs(dl_probe) > abs(dl_black) + 0.25 else
                f" (ΔL* {dl_black:+z.1f} at the {names[0]} patch, {dl_probe:+z.1f} extrapolated "
                f"to L* {SHADOW_PROBE_L:g})")
        reason = (f"shadow tones: the dark end of the tone curve has local gamma {slope:.3f} "
                  f"({names[0]} to {names[1]}; 1 is right, tolerance ±{tolerance:g}), "
                  f"{100 * (slope - 1):+z.0f} % shadow contrast{more}; the chart ΔE weights "
                  "the deep shadows that fill photographs by one patch of 24")
    else:
        reason = (f"shadow tones: local gamma of the dark end {slope:.3f} (within "
                  f"±{tolerance:g} of 1)")
    return BlindSpot("shadow-tone", at_risk, slope, tolerance, reason)


def bit_depth(bits: int | None, min_bits: int = MIN_BITS) -> BlindSpot:
    """A camera model's output bit depth (None: float output, no quantisation)."""
    if bits is None:
        return BlindSpot("bit-depth", False, None, float(min_bits),
                         "bit depth: float output, not quantised")
    at_risk = bits <= min_bits
    if at_risk:
        reason = (f"posterisation: the camera quantises to {bits} bits ({2 ** bits} levels per "
                  f"channel, at most {min_bits} bits is a risk); smooth gradients band into "
                  "false contours, which flat patches cannot show")
    else:
        reason = f"bit depth: {bits} bits ({2 ** bits} levels per channel)"
    return BlindSpot("bit-depth", at_risk, float(bits), float(min_bits), reason)


#: Code range of an integer pixel type (OpenImageIO's format names).
_CODE_RANGE: dict[str, int] = {"uint8": 255, "int8": 127, "uint16": 65535, "int16": 32767}


#: Pixels of an image whose neighbour steps are counted at a time (bounded memory).
STEP_BLOCK_PIXELS = 1 << 20
#: Most pixels whose neighbour steps are counted: a larger image's steps are counted in every
#: ``s``-th block of :data:`STEP_BLOCK_PIXELS` (whole rows, spread over its height), the least
#: ``s`` that leaves at most this many (millions of neighbour pairs still: the most common step
#: is as sure as in the whole image).
STEP_SAMPLE_PIXELS = 1 << 22


def step_stride(shape: tuple[int, ...], limit: int = STEP_SAMPLE_PIXELS) -> int:
    """Every how many blocks of rows :func:`effective_bits` counts the steps of an image of
    ``shape`` (1: all of them)."""
    pixels = int(np.prod(shape[:2]))
    return max(1, math.ceil(pixels / limit))


def _numpy_steps(a: np.ndarray, b: np.ndarray, limit: int) -> np.ndarray:
    """Counts of ``|b - a|`` = 0 .. ``limit`` over integer arrays of one shape (0 left at 0)."""
    steps = np.abs(b.astype(np.int64) - a.astype(np.int64)).ravel()
    out: np.ndarray = np.bincount(steps[(steps > 0) & (steps <= limit)], minlength=limit + 1)
    return out[:limit + 1]


def _opencv_steps(a: np.ndarray, b: np.ndarray, limit: int) -> np.ndarray:
    """:func:`_numpy_steps` of 8- or 16-bit codes by OpenCV (``absdiff``, ``calcHist``: exact
    integer counts while a block holds under 2**24 values), several times faster."""
    try:
        import cv2
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        return _numpy_steps(a, b, limit)
    if a.size == 0:
        return np.zeros(limit + 1, dtype=np.int64)
    d = cv2.absdiff(a, b)
    hist = cv2.calcHist([d.reshape(d.shape[0], -1)], [0], None, [limit + 1], [0, limit + 1])
    out = np.rint(hist.ravel()).astype(np.int64)
    out[0] = 0
    return out


def effective_bits(codes: np.ndarray, code_range: int,
                   smooth_fraction: float = SMOOTH_STEP_FRACTION,
                   min_pairs: int = MIN_SMOOTH_PAIRS) -> tuple[float | None, float, int]:
    """(effective bits or None, the quantisation step ``q`` in codes
    (:func:`quantisation_step`; 0 when not judged), smooth pairs found) of integer codes
    (H, W, C) (module docstring). The steps are counted a block of rows at a time, so that memory stays
    a few MB whatever the image's size; of an image over :data:`STEP_SAMPLE_PIXELS`, in every
    :func:`step_stride`-th block only."""
    a = np.asarray(codes)
    limit = max(1, int(round(smooth_fraction * code_range)))
    counts = np.zeros(limit + 1, dtype=np.int64)
    rows = max(1, STEP_BLOCK_PIXELS // max(int(np.prod(a.shape[1:])), 1))
    count = _opencv_steps if a.dtype in (np.uint8, np.uint16) else _numpy_steps
    for y in range(0, max(a.shape[0], 1), rows * step_stride(a.shape)):
        block = a[y:y + rows + 1]  # one row of overlap: the steps down
        counts += count(block[:-1], block[1:], limit) if len(block) > 1 else 0
        counts += count(block[:rows, :-1], block[:rows, 1:], limit)
    pairs = int(counts.sum())
    if pairs < min_pairs:
        return None, 0, pairs
    q = quantisation_step(counts)
    return float(math.log2(code_range / q + 1.0)), q, pairs


def quantisation_step(counts: np.ndarray, share: float = MULTIPLE_SHARE) -> float:
    """The quantisation step of a histogram of neighbour steps (``counts[d]``: pairs that
    differ by ``d`` codes, ``d`` >= 1; ``counts[0]`` ignored), in codes (>= 1).

    The levels of a posterised image are ``round(k Δ)``: every step lies within one code of a
    multiple of the spacing ``Δ``. The most common step ``q`` is a multiple of it: ``Δ`` is the
    largest divisor of ``q`` of which at least ``share`` of the steps are multiples (levels
    on whole codes), else the mean of the steps ``q - 1`` to ``q + 1`` when ``share`` of them
    lie within one code of its multiples (levels between codes: 5 bits in 8 step by 8 and 9;
    only for a most common step of :data:`MIN_SPACING` codes or more, where one code is a
    small part of the spacing); else the image is not posterised and the step is 1 code.
    """
    c = np.asarray(counts, np.int64).copy()
    c[0] = 0
    total = int(c.sum())
    if total <= 0:
        return 1.0
    mode = int(np.argmax(c))
    for q in range(mode, 1, -1):
        if mode % q == 0 and int(c[q::q].sum()) >= share * total:
            return float(q)
    if mode < MIN_SPACING:
        return 1.0
    near = np.arange(mode - 1, min(mode + 2, len(c)))
    spacing = float(np.average(near, weights=c[near]))
    steps = np.arange(len(c))
    multiple = np.maximum(np.rint(steps / spacing), 1.0)
    if int(c[np.abs(steps - multiple * spacing) < 1.0].sum()) >= share * total:
        return spacing
    return 1.0


def _codes(pixels: np.ndarray, code_range: int) -> np.ndarray:
    """Integer codes (int32) of values scaled to [0, 1], a block of rows at a time."""
    out = np.empty(pixels.shape, dtype=np.int32)
    rows = max(1, STEP_BLOCK_PIXELS // max(int(np.prod(pixels.shape[1:])), 1))
    for y in range(0, pixels.shape[0], rows):
        block = np.asarray(pixels[y:y + rows], np.float64)
        out[y:y + rows] = np.rint(np.clip(block, 0.0, 1.0) * code_range)
    return out


def banding(pixels: np.ndarray, pixel_type: str, *, min_bits: int = MIN_BITS) -> BlindSpot:
    """Posterisation of an image from its smooth regions (module docstring); ``pixels``
    (H, W, 3) as read (:func:`fidelity.chart.image.read_image`: integer codes scaled to
    [0, 1], or the codes themselves when read at their native depth) and the file's
    ``pixel_type``."""
    rng = _CODE_RANGE.get(str(pixel_type).lower())
    if rng is None:
        return BlindSpot("banding", None, None, float(min_bits),
                         f"banding not judged: {pixel_type} pixels are not integer codes")
    arr = np.asarray(pixels)
    if arr.dtype in (np.uint8, np.uint16) and np.iinfo(arr.dtype).max == rng:  # codes
        codes = arr
    else:
        codes = _codes(arr, rng)
    bits, q, pairs = effective_bits(codes, rng)
    sampled = step_stride(codes.shape)
    of = f" in every {sampled}th block of rows" if sampled > 1 else ""
    if bits is None:
        return BlindSpot("banding", None, None, float(min_bits),
                         f"banding not judged: only {pairs} small steps{of} between neighbouring "
                         "pixels (the image has no smooth gradients, e.g. flat patches only)")
    at_risk = bits <= min_bits + 0.5
    if at_risk:
        reason = (f"posterisation: smooth regions of the image step by {q:.4g} codes of "
                  f"{rng} ({pairs} neighbour pairs{of}), about {bits:.1f} effective bits (at most "
                  f"{min_bits} is a risk); gradients band into false contours, which flat "
                  "patches cannot show")
    else:
        reason = (f"banding: smooth regions step by {q:.4g} code(s) of {rng}, about {bits:.1f} "
                  "effective bits")
    return BlindSpot("banding", at_risk, bits, float(min_bits), reason)


def chart_blind_spots(measurement: ChartMeasurement, *, bits: int | None | bool = False,
                      pixels: np.ndarray | None = None, pixel_type: str | None = None
                      ) -> tuple[BlindSpot, ...]:
    """Every check that applies: the shadow tone of the chart; the bit depth of a camera
    model (``bits``: its quantisation bits, None for float output; False: not a camera
    model); the banding of an image (``pixels`` and ``pixel_type``).

    Parameters
    ----------
    measurement
        The chart measured; its neutral patches' tone curve is read (:func:`shadow_tone`).
    bits
        The camera model's quantisation bits (an int, :func:`bit_depth`); None: a camera with
        float output; False (default): not a camera model, no bit-depth check.
    pixels
        The image's pixels, shape (H, W, 3), as read (integer codes scaled to [0, 1], or the
        8/16-bit codes themselves); None: no banding check.
    pixel_type
        The file's pixel type (``uint8``, ``uint16``, ``half``, ...); banding is checked only
        when both ``pixels`` and ``pixel_type`` are given, and judged only for integer types.

    Returns
    -------
    tuple of BlindSpot
        The shadow-tone check, then the bit-depth check (when ``bits`` is not False), then
        the banding check (when ``pixels`` and ``pixel_type`` are given), in that order.
    """
    out = [shadow_tone(measurement)]
    if bits is not False:
        out.append(bit_depth(None if bits is None or bits is True else int(bits)))
    if pixels is not None and pixel_type is not None:
        out.append(banding(pixels, pixel_type))
    return tuple(out)


def warnings(spots: Sequence[BlindSpot]) -> list[BlindSpot]:
    """The checks that found a risk."""
    return [s for s in spots if s.at_risk]


__all__ = [
    "KINDS",
    "MIN_BITS",
    "MIN_SMOOTH_PAIRS",
    "MIN_SPACING",
    "MULTIPLE_SHARE",
    "SHADOW_PROBE_L",
    "SHADOW_SLOPE_TOLERANCE",
    "SMOOTH_STEP_FRACTION",
    "STEP_BLOCK_PIXELS",
    "BlindSpot",
    "banding",
    "bit_depth",
    "chart_blind_spots",
    "effective_bits",
    "quantisation_step",
    "shadow_tone",
    "warnings",
]
