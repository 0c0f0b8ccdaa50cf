"""Measure the chart in an image's pixels: bad pixels, linear patch means, exposure, the
colour (:mod:`fidelity.measure.colour`) and its uncertainty.

Measuring a chart in an image (:func:`measure_pixels`; :func:`measure_image` adds the file
reading), step by step (each a pure function of arrays):

1. Locate the 24 patches from the four corner-patch centres (:mod:`fidelity.chart.locate`) and take
   the pixels of each patch's central sampling window. Without given corners the chart is
   found first (:func:`fidelity.chart.find.cascade.find_chart`); everything after that is the same.
2. Exclude bad pixels: a pixel with NaN or +-Inf in any channel. They are counted (per kind,
   per patch, and over the whole image). Pixels with a negative channel are counted too and by
   default kept (:data:`NEGATIVE_RULES`: scene-linear renders of out-of-gamut colours have
   them), or excluded with ``negatives="exclude"``. A patch keeps its measurement only
   if at least ``min_valid_fraction`` of its window (and at least ``MIN_VALID_PIXELS``) is
   valid; otherwise the audit fails with an error naming the patch.
3. Average each patch in linear light: linear input as it is, sRGB-encoded input decoded with
   the IEC 61966-2-1 transfer function first. (For a flat patch this equals averaging the
   encoded values; for a noisy patch it is the physically meaningful mean.)
4. Exposure: linear input is scaled by ``2**EV`` with ``EV`` chosen so that the achromatic
   (neutral) patches match the reference luminance on average in log space,
   ``EV = mean_k log2(Y_ref,k / Y_meas,k)`` over the neutral patches with ``Y_meas > 0``, where
   ``Y`` is CIE Y of linear sRGB (IEC 61966-2-1 matrix) and ``Y_ref`` the Y of the reference
   Lab. A fixed EV can be given instead; sRGB-encoded input keeps its exposure (EV 0) unless
   asked. A pure exposure scale ``s`` is thus recovered as ``EV = -log2(s)`` exactly. Note that
   auto exposure removes any overall brightness error of the camera along with the exposure.
5. Encode as sRGB (IEC 61966-2-1), clip to [0, 1] like any stored image (the patches that
   clipped are listed), convert to CIELAB D65 and compare with the reference by CIEDE2000
   (:func:`measure_chart`); the chart ΔE is the mean over the 24 patches.

Input pixels are taken as linear or encoded sRGB (Rec. 709 primaries, D65 white), or in another
RGB colourspace (``colourspace``: ACEScg, ITU-R BT.2020, ... or an EXR's chromaticities), whose
linear patch means are converted to linear sRGB first
(:func:`fidelity.colour.colorimetry.matrix_rgb_to_linear_srgb`; encoded input is decoded with the sRGB
transfer function whatever its primaries). A camera's native RGB must be converted before
auditing.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.image import Image, ImageInfo, as_float32, is_coded, stored_size
from fidelity.chart.locate import (
    DEFAULT_WINDOW,
    ChartLocation,
    PatchWindow,
    grid_centres,
    homography_from_points,
    locate_chart,
)
from fidelity.chart.read import DEFAULT_READ, ReadOptions, read_input
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import DEFAULT_REFERENCE, Reference, load_reference
from fidelity.core.errors import FidelityError, InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.measure import uncertainty as unc
from fidelity.measure.chartnoise import METHOD as CHART_NOISE_METHOD
from fidelity.measure.chartnoise import ChartNoise, chart_noise, grey_index
from fidelity.measure.chartsharpness import (
    ChartSharpness,
    EdgeTargetCorners,
    chart_sharpness,
    target_sharpness,
)
from fidelity.measure.colour import (
    MAX_EXPOSURE_EV,
    OCCLUDED_REASON,
    ChartMeasurement,
    measure_chart,
)
from fidelity.measure.noise import RefusedFit
from fidelity.measure.uncertainty import (
    PatchSpread,
    UncertaintyBudget,
    block_lattice,
    block_sample,
    coded_patch_spread,
    image_blocks,
    patch_spread,
)

if TYPE_CHECKING:  # the finder is imported where a chart is found (not by check)
    from fidelity.chart.find.result import ChartChecks, FoundChart

F64 = NDArray[np.float64]

#: Encodings of input pixel values.
ENCODINGS = ("linear", "srgb")
#: What a finite negative channel value does: ``keep`` it in the linear-light mean (an
#: out-of-gamut colour rendered into sRGB primaries, such as the chart's cyan in a spectral
#: render, has one; the encoded mean is clipped like any stored image), or ``exclude`` the pixel.
NEGATIVE_RULES = ("keep", "exclude")
#: Fewest valid pixels a patch needs, whatever its window size.
MIN_VALID_PIXELS = 4
#: Default fraction of a window's pixels that must be valid.
MIN_VALID_FRACTION = 0.5


def luminance_linear_srgb(rgb: np.ndarray) -> np.ndarray:
    """CIE Y (white = 1) of linear sRGB ``(..., 3)``: the middle row of the IEC 61966-2-1 matrix."""
    y: np.ndarray = np.asarray(rgb, np.float64) @ cm.MATRIX_LINEAR_SRGB_TO_XYZ[1]
    return y


def exposure_from_neutrals(
    linear_rgb: np.ndarray, reference_lab: np.ndarray, neutral_indices: Sequence[int],
    patch_names: Sequence[str] | None = None,
) -> float:
    """Exposure correction in EV that makes the neutral patches match the reference.

    ``EV = mean_k log2(Y_ref,k / Y_meas,k)`` over neutral patches ``k`` with ``Y_meas > 0``
    (the geometric-mean luminance ratio). ``linear_rgb`` (n, 3) patch means in linear sRGB;
    ``reference_lab`` (n, 3) CIELAB D65. Raises when no neutral patch has light.
    """
    idx = np.asarray(list(neutral_indices), dtype=int)
    if idx.size == 0:
        raise InvalidValueError("the reference chart has no neutral patches to set the exposure on")
    y_meas = luminance_linear_srgb(np.asarray(linear_rgb)[idx])
    y_ref = cm.lab_to_xyz(np.asarray(reference_lab, np.float64)[idx])[:, 1]
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        ratio = y_ref / y_meas
    ok = (y_meas > 0) & np.isfinite(y_meas) & np.isfinite(ratio) & (ratio > 0)
    if not np.any(ok):
        names = ", ".join(patch_names[i] for i in idx) if patch_names else str(idx.tolist())
        raise InvalidValueError(
            f"cannot set the exposure automatically: the neutral patches ({names}) are black; "
            f"give --exposure EV"
        )
    ev = float(np.mean(np.log2(ratio[ok])))
    if not abs(ev) <= MAX_EXPOSURE_EV:
        raise InvalidValueError(
            f"cannot set the exposure automatically: the neutral patches would need "
            f"{ev:+.4g} EV, beyond +-{MAX_EXPOSURE_EV:g}; give --exposure EV")
    return ev


@record
class PixelCounts:
    """Pixels with a NaN, a +-Inf or a negative channel, and how many were ``excluded``
    (``total``)."""

    nan: int
    inf: int
    negative: int
    total: int

    def to_json(self) -> dict[str, int]:
        """JSON form."""
        return {"nan": self.nan, "inf": self.inf, "negative": self.negative, "total": self.total}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PixelCounts:
        """Inverse of :meth:`to_json`."""
        return cls(int(data["nan"]), int(data["inf"]), int(data["negative"]), int(data["total"]))


@record
class BadPixels:
    """Bad pixels of an audited image: ``window`` counts over the sampling windows,
    ``per_patch`` the excluded pixels of each patch that has any, ``image`` the counts over the
    whole image, the ``negatives`` rule (:data:`NEGATIVE_RULES`) and the ``rule`` in words."""

    window: PixelCounts
    per_patch: Mapping[str, int]
    image: PixelCounts
    negatives: str
    rule: str

    def to_json(self) -> dict[str, Any]:
        """JSON form (the window counts at the top level, as the report schema has them)."""
        return {**self.window.to_json(), "per_patch": dict(self.per_patch),
                "image": self.image.to_json(), "negatives": self.negatives, "rule": self.rule}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> BadPixels:
        """Inverse of :meth:`to_json`."""
        return cls(PixelCounts.from_json(data), {str(k): int(v) for k, v in
                                                 data["per_patch"].items()},
                   PixelCounts.from_json(data["image"]), str(data.get("negatives", "keep")),
                   str(data.get("rule", "")))


@record
class ImageMeasurement:
    """An audited chart: the :class:`ChartMeasurement` plus how it was obtained.

    Attributes
    ----------
    measurement
        The chart's colour: per patch the exposed, clipped encoded sRGB, its CIELAB and ΔE00
        against the reference.
    exposure_ev
        The exposure correction applied to the linear patch means, in EV (scale ``2**EV``),
        within +-:data:`fidelity.measure.colour.MAX_EXPOSURE_EV`.
    exposure_mode
        ``auto`` (fitted on the neutral patches) or ``fixed``.
    encoding
        How the pixels were read: ``linear`` or ``srgb`` (:data:`ENCODINGS`).
    bad_pixels
        NaN, Inf and negative pixel counts in the sampling windows (total and per patch) and
        over the whole image, with the rule applied.
    valid_pixels
        Pixels averaged in each patch's window, in chart order.
    clipped_patches
        Names of the patches whose encoded sRGB was clipped to [0, 1].
    location
        Where the patches lie: the corners, homography and sampling windows.
    reference
        The reference chart the patches are compared with.
    image
        The image file as the report states it (path, format, pixel type, sha256...); None
        for an array measured without one.
    detection
        What the chart finder found (None: corners given).
    colourspace
        RGB primaries the pixels were taken in: a colour-science name or
        ``chromaticities x,y,...``.
    corner_checks
        How well the measured patches match the reference layout (None for a chart other
        than 4 x 6 given by its corners).
    uncertainty
        The standard uncertainty budget of the chart ΔE (None: not evaluated).
    noise
        The neutral patches' noise, photon transfer and SNR at the 18 % grey, in linear light
        (:func:`fidelity.measure.chartnoise.chart_noise`; None: not measured).
    sharpness
        The MTF of the chart's vertical and horizontal patch edges per channel
        (:func:`fidelity.measure.chartsharpness.chart_sharpness`; None: not measured).
    neutral_ev
        The exposure correction the neutral patches ask for (:func:`exposure_from_neutrals`),
        in EV: ``exposure_ev`` itself when auto; with a fixed exposure, how far the image's own
        exposure is from it (:func:`fidelity.prediction.exposure.judge_exposure`). None where
        the neutral patches set none (black, or beyond the range).
    linear_means
        The patches' mean linear sRGB, shape (n, 3), as read: before the exposure correction
        and the clipping (what :mod:`fidelity.colour.diagnosis` fits); None: not kept.
    """

    measurement: ChartMeasurement
    exposure_ev: float
    exposure_mode: str
    encoding: str
    bad_pixels: BadPixels
    valid_pixels: tuple[int, ...]
    clipped_patches: tuple[str, ...]
    location: ChartLocation
    reference: Reference
    image: ImageInfo | None = None
    detection: FoundChart | None = None
    colourspace: str = "sRGB"
    corner_checks: ChartChecks | None = None
    #: the standard uncertainty of the chart ΔE (:mod:`fidelity.measure.uncertainty`)
    uncertainty: UncertaintyBudget | None = None
    #: the neutral patches' noise and photon transfer (:mod:`fidelity.measure.chartnoise`)
    noise: ChartNoise | None = None
    #: the MTF of the chart's patch edges (:mod:`fidelity.measure.chartsharpness`)
    sharpness: ChartSharpness | None = None
    #: the exposure correction the neutral patches ask for, in EV (None: they set none)
    neutral_ev: float | None = None
    #: the patches' mean linear sRGB as read (before exposure correction and clipping)
    linear_means: np.ndarray | None = None

    @property
    def mean_delta_e(self) -> float:
        """The chart ΔE: mean ΔE00 over the patches."""
        return self.measurement.mean_delta_e

    @property
    def max_delta_e(self) -> float:
        """Largest per-patch ΔE00."""
        return self.measurement.max_delta_e

    def to_json(self) -> dict[str, Any]:
        """JSON form: the measurement (:meth:`ChartMeasurement.to_json`, each patch with its
        ``valid_pixels`` and ``bad_pixels``), ``exposure_ev``, ``exposure_mode``, ``neutral_ev``,
        ``encoding``,
        ``bad_pixels``, ``clipped_patches``, ``reference``, ``location``, ``detection``,
        ``corner_checks``, ``colourspace``, ``image``, ``uncertainty``, ``noise`` and
        ``sharpness``."""
        d = self.measurement.to_json()
        for patch, n in zip(d["patches"], self.valid_pixels, strict=True):
            patch["valid_pixels"] = int(n)
            patch["bad_pixels"] = int(self.bad_pixels.per_patch.get(patch["name"], 0))
        d.update(
            exposure_ev=self.exposure_ev,
            exposure_mode=self.exposure_mode,
            neutral_ev=self.neutral_ev,
            encoding=self.encoding,
            bad_pixels=self.bad_pixels.to_json(),
            clipped_patches=list(self.clipped_patches),
            reference=self.reference.name,
            location=self.location.to_json(),
            detection=self.detection.to_json() if self.detection else None,
            corner_checks=self.corner_checks.to_json() if self.corner_checks else None,
            colourspace=self.colourspace,
            image=self.image.to_json() if self.image else None,
            uncertainty=self.uncertainty.to_json() if self.uncertainty else None,
            noise=self.noise.to_json() if self.noise else None,
            sharpness=self.sharpness.to_json() if self.sharpness else None,
        )
        return d


def _bad_counts(values: np.ndarray, negatives: str = "exclude"
                ) -> tuple[np.ndarray, dict[str, int]]:
    """Mask of excluded pixels of ``(n, 3)`` values and counts.

    A pixel with a NaN or +-Inf channel is always excluded; one with a negative channel is
    counted, and excluded only for ``negatives="exclude"``. ``total`` counts the excluded."""
    nan = np.isnan(values).any(axis=-1)
    inf = np.isinf(values).any(axis=-1)
    with np.errstate(invalid="ignore"):
        neg = (values < 0).any(axis=-1)
    bad = nan | inf | neg if negatives == "exclude" else nan | inf
    return bad, {"nan": int(nan.sum()), "inf": int(inf.sum()), "negative": int(neg.sum()),
                 "total": int(bad.sum())}


#: Rows of an image counted at a time by :func:`_whole_image_counts` (bounded memory).
COUNT_BLOCK_PIXELS = 1 << 20


def _whole_image_counts(arr: np.ndarray, negatives: str) -> dict[str, int]:
    """:func:`_bad_counts` over a whole ``(H, W, 3)`` image, a block of rows at a time, so that
    its masks take a few MB whatever the image's size."""
    rows = max(1, COUNT_BLOCK_PIXELS // max(arr.shape[1], 1))
    totals = {"nan": 0, "inf": 0, "negative": 0, "total": 0}
    if is_coded(arr):  # integer codes: never NaN, Inf or negative
        return totals
    for y in range(0, arr.shape[0], rows):
        block = arr[y:y + rows]
        lo, hi = float(block.min(initial=0.0)), float(block.max(initial=0.0))
        if math.isfinite(lo) and math.isfinite(hi) and lo >= 0:
            continue  # min and max propagate NaN: no NaN, no Inf, nothing negative here
        _, counts = _bad_counts(block.reshape(-1, 3), negatives)
        for key in totals:
            totals[key] += counts[key]
    return totals


@functools.lru_cache(maxsize=4)
def _code_linear(dtype: str, encoding: str) -> np.ndarray:
    """Linear value (float64) of every code of an unsigned integer ``dtype``, as the float
    path computes it from the float32 value of the code (:func:`as_float32`)."""
    codes = as_float32(np.arange(np.iinfo(dtype).max + 1, dtype=dtype)).astype(np.float64)
    table: np.ndarray = codes if encoding == "linear" else cm.linearize_srgb(codes)
    table.flags.writeable = False
    return table


def _to_linear(values: np.ndarray, encoding: str, to_srgb: np.ndarray, identity: bool
               ) -> np.ndarray:
    """Pixel values ``(..., 3)`` (any dtype: integer codes are looked up in
    :func:`_code_linear`) in linear sRGB, float64."""
    if is_coded(values):
        lin = _code_linear(values.dtype.str, encoding)[values]
    else:
        f = np.asarray(values, np.float64)
        lin = f if encoding == "linear" else cm.linearize_srgb(f)
    out: np.ndarray = lin if identity else lin @ to_srgb.T
    return out


def window_linear(values: np.ndarray, encoding: str, to_srgb: np.ndarray
                  ) -> tuple[np.ndarray, str]:
    """Pixel values ``(..., 3)`` in linear sRGB (float64), as the one-frame noise measurement
    makes them (:func:`noise_and_sharpness`), and how.

    Parameters
    ----------
    values
        Pixel values as stored: 8/16-bit codes (``code / (2**bits - 1)``) or floats.
    encoding
        ``linear`` or ``srgb`` (decoded with the IEC 61966-2-1 transfer function).
    to_srgb
        The ``3 x 3`` matrix from the pixels' primaries to linear sRGB.

    Returns
    -------
    tuple
        The linear values (same shape) and the linearisation as the noise record names it.
    """
    identity = bool(np.array_equal(to_srgb, np.eye(3)))
    how = ("none (linear input)" if encoding == "linear"
           else "sRGB transfer function decoded (IEC 61966-2-1)")
    if is_coded(values):
        how += f", {values.dtype} codes / {np.iinfo(values.dtype).max}"
    if not identity:
        how += ", primaries converted to linear sRGB"
    return _to_linear(np.asarray(values), encoding, to_srgb, identity), how


def _patch_linear(vals: np.ndarray, encoding: str, negatives: str, to_srgb: np.ndarray,
                  identity: bool) -> tuple[np.ndarray, dict[str, int]]:
    """The valid pixels of one window's values ``(n, 3)`` in linear sRGB, float64
    (:func:`_to_linear`), and the bad-pixel counts."""
    if is_coded(vals):  # integer codes: never NaN, Inf or negative
        return _to_linear(vals, encoding, to_srgb, identity), dict(_NO_BAD)
    vals64 = vals.astype(np.float64)
    bad, counts = _bad_counts(vals64, negatives)
    return _to_linear(_rows(vals64, ~bad) if counts["total"] else vals64, encoding, to_srgb,
                      identity), counts


_NO_BAD = {"nan": 0, "inf": 0, "negative": 0, "total": 0}


def _rows(values: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``values[keep]`` of ``(n, ...)`` values and a boolean ``(n,)`` mask: the same rows, in
    order, picked by ``numpy.compress`` (several times faster than boolean indexing of rows of
    a few channels)."""
    out: np.ndarray = np.compress(keep, values, axis=0)
    return out


def _code_histogram(vals: np.ndarray) -> np.ndarray:
    """``(3, codes)`` counts (int64) of each integer code per channel of ``(n, 3)`` values:
    OpenCV's ``calcHist`` (exact counts below 2**24 pixels, about twice as fast as numpy's
    ``bincount`` of a channel's strided codes), numpy's beyond."""
    levels = np.iinfo(vals.dtype).max + 1
    if 0 < len(vals) < 1 << 24:
        import cv2

        image = np.ascontiguousarray(vals).reshape(-1, 1, 3)
        return np.stack([np.rint(cv2.calcHist([image], [c], None, [levels], [0, levels])
                                 .ravel()).astype(np.int64) for c in range(3)])
    return np.stack([np.bincount(vals[:, c], minlength=levels) for c in range(3)])


def _histogram_noise(hist: np.ndarray, linear: np.ndarray, scale: float) -> np.ndarray:
    """Standard deviation per channel of the encoded, exposed, clipped values of a patch of
    integer codes from its histogram ``(3, codes)`` (``linear``: the linear value of each
    code): ``sqrt(sum_i n_i (v_i - mean)^2 / n)``, as ``numpy.std`` of the pixels."""
    encoded = np.clip(cm.delinearize_srgb(linear * scale), 0, 1)
    n = hist.sum(axis=1)
    mean = hist @ encoded / n
    out: np.ndarray = np.sqrt(np.einsum("ci,ci->c", hist, (encoded[None, :] - mean[:, None])
                                        ** 2) / n)
    return out


def _patch_noise(vals: np.ndarray, scale: float, encoding: str, negatives: str,
                 to_srgb: np.ndarray, identity: bool) -> np.ndarray:
    """Standard deviation per channel of one window's valid pixels, exposed by ``scale`` and
    sRGB-encoded, clipped to [0, 1] (as a stored image holds them)."""
    lin, _ = _patch_linear(vals, encoding, negatives, to_srgb, identity)
    out: np.ndarray = np.clip(cm.delinearize_srgb(lin * scale), 0, 1).std(axis=0)
    return out


def _window_spread(vals: np.ndarray, linear: np.ndarray | None, encoding: str, negatives: str,
                   to_srgb: np.ndarray, identity: bool, step: float | None,
                   window: PatchWindow, width: int) -> PatchSpread:
    """The :class:`~fidelity.measure.uncertainty.PatchSpread` of one window's values ``vals``
    ``(n, 3)``: ``linear`` its valid pixels in linear sRGB when already computed, the code
    values (:func:`as_float32`) when the pixels are integer codes (``step``); the design
    effect of correlated neighbours from the image's blocks the ``window`` touches (an image
    ``width`` pixels wide), when every pixel of it is valid. A window of more than
    :data:`~fidelity.measure.uncertainty.SPREAD_SAMPLE_PIXELS` pixels: its statistics from a
    lattice of its whole blocks (:func:`~fidelity.measure.uncertainty.block_sample`), over its
    own count of valid pixels. Integer codes in sRGB primaries: :func:`_coded_window_spread`
    (the same statistics, bit for bit)."""
    if step and identity and linear is None and is_coded(vals):
        return _coded_window_spread(vals, encoding, window, width)
    keep = block_sample(window.y0, window.x0, window.mask)
    # the statistics are the sample's (all of the window without one), the count of valid
    # pixels the window's (no linear pixels given: integer codes, every pixel valid)
    valid = len(linear) if linear is not None else len(vals)
    sub = vals if keep is None else _rows(vals, keep)
    lin = (linear if keep is None and linear is not None
           else _patch_linear(sub, encoding, negatives, to_srgb, identity)[0])
    codes = None
    if step:
        v = as_float32(sub).astype(np.float64)
        codes = v if is_coded(sub) else v[~_bad_counts(v, negatives)[0]]
    blocks = None
    if valid == len(vals) and len(lin) == len(sub):
        if keep is None:
            rows, cols = window.indices()
        else:  # the kept pixels' indices alone (row-major, as rows[keep], cols[keep])
            kept = np.zeros(window.mask.shape, bool)
            kept[window.mask] = keep
            r, c = np.nonzero(kept)
            rows, cols = r.astype(np.int64) + window.y0, c.astype(np.int64) + window.x0
        blocks = image_blocks(rows, cols, width)
    return patch_spread(lin, codes, blocks, count=valid)


@functools.lru_cache(maxsize=4)
def _code_table(dtype: str, encoding: str) -> np.ndarray:
    """``(levels, 2)``: each code of an unsigned integer ``dtype`` as its linear value
    (:func:`_code_linear`) and its code value (:func:`as_float32`, in float64)."""
    codes = np.arange(np.iinfo(dtype).max + 1, dtype=dtype)
    table = np.stack([_code_linear(dtype, encoding), as_float32(codes).astype(np.float64)],
                     axis=1)
    table.flags.writeable = False
    return table


def _coded_window_spread(vals: np.ndarray, encoding: str, window: PatchWindow, width: int
                         ) -> PatchSpread:
    """:func:`_window_spread` of a window of integer codes in sRGB primaries (every pixel
    valid): its lattice sample (:func:`~fidelity.measure.uncertainty.block_sample`) picked
    whole pixels at a time, located from its positions in the window's box, and gathered with
    its codes' values at once (:func:`~fidelity.measure.uncertainty.coded_patch_spread`):
    the same statistics, bit for bit."""
    table = _code_table(vals.dtype.str, encoding)
    lattice = block_lattice(window.y0, window.x0, window.mask)
    if lattice is None:
        rows, cols = window.indices()
        return coded_patch_spread(vals, table, image_blocks(rows, cols, width))
    down, across = lattice
    kept = window.mask & down[:, None] & across[None, :]
    keep = kept[window.mask]
    codes = np.ascontiguousarray(vals)
    pixel = np.dtype((np.void, codes.dtype.itemsize * 3))  # a pixel's three codes as one item
    sub = codes.view(pixel).reshape(-1)[keep].view(codes.dtype).reshape(-1, 3)
    where = np.flatnonzero(kept)  # row-major in the box, as the window lists its pixels
    rows, cols = np.divmod(where, window.mask.shape[1])
    blocks = image_blocks(rows + window.y0, cols + window.x0, width)
    return coded_patch_spread(sub, table, blocks, count=len(vals))


def measure_pixels(
    pixels: np.ndarray,
    corners: np.ndarray | str | Sequence[float] | None = None,
    *,
    encoding: str = "linear",
    exposure: float | str | None = None,
    reference: str | Reference = DEFAULT_REFERENCE,
    illuminant: str = "D65",
    window: float = DEFAULT_WINDOW,
    min_valid_fraction: float = MIN_VALID_FRACTION,
    image: ImageInfo | None = None,
    detection: str = "cascade",
    negatives: str = "keep",
    colourspace: str | Sequence[float] = "sRGB",
    uncertainty: bool = True,
    texture: bool = True,
    sharpness: bool = True,
    corner_checks: bool = True,
    edge_target: EdgeTargetCorners | None = None,
    levels: Mapping[int, np.ndarray] | None = None,
) -> ImageMeasurement:
    """Audit a chart in an ``(H, W, 3)`` image array (see the module docstring).

    Parameters
    ----------
    pixels
        ``(H, W, 3)`` values, linear or encoded sRGB (``encoding``): 8- or 16-bit unsigned
        codes stand for ``code / (2**bits - 1)`` (:func:`fidelity.chart.image.as_float32`; an
        image read at its native depth), other values for themselves.
    corners
        Centres of the dark skin, bluish green, black and white patches, ``(4, 2)`` image
        ``(x, y)`` or ``"X1,Y1,...,X4,Y4"``; ``None``: find the chart
        (:func:`fidelity.chart.find.cascade.find_chart` with ``detection``; a chart found with low
        confidence, or of another kind, is an error). Given corners are measured as given;
        how well their patches match the reference layout is reported
        (``corner_checks``, :func:`fidelity.chart.find.cascade.check_corners`).
    encoding
        ``linear`` (default) or ``srgb`` (:data:`ENCODINGS`): how the values are decoded
        before the linear patch means.
    exposure
        ``"auto"`` (fit on the neutral patches), a fixed EV (scale ``2**EV``), or ``None``:
        auto for linear input, 0 for sRGB-encoded input.
    reference
        ``"safecolor"`` (the paper's chart), ``"scene"`` or a chart name/path.
    illuminant
        Scene illuminant of the ``scene`` reference (``D65``, ...).
    window
        Side of each patch's central sampling square, in patch pitches, in (0, 1].
    min_valid_fraction
        Fraction of a window's pixels, in [0, 1], that must be valid (and at least
        :data:`MIN_VALID_PIXELS`), else the patch is an error.
    image
        The image file's description, kept in the result; None for a bare array.
    detection
        Chart-finding method when ``corners`` is None (``cascade``, ``mcc``,
        ``segmentation``).
    negatives
        Pixels with a negative channel: ``keep`` (default) in the linear mean, or
        ``exclude`` like NaN/Inf (:data:`NEGATIVE_RULES`).
    colourspace
        RGB primaries of the pixels: a colour-science name or 8 chromaticities (see
        :func:`fidelity.colour.colorimetry.matrix_rgb_to_linear_srgb`).
    uncertainty
        Also evaluate the standard uncertainty of the chart ΔE (:func:`image_uncertainty`).
    texture
        Also measure the chart's noise and sharpness in linear light
        (:func:`noise_and_sharpness`).
    sharpness
        With ``texture``, also measure the sharpness; False: the noise only (a caller that
        measures the sharpness elsewhere, :func:`fidelity.camera.render.frame_properties`).
    edge_target
        A slanted-edge target's corners in the image (a chart scene's manifest gives them):
        the sharpness is measured on its square's edges instead of the chart's; None: on the
        chart's.
    corner_checks
        Check given ``corners`` against the reference layout
        (:func:`fidelity.chart.find.cascade.check_corners`); False for corners known exactly
        (a chart the caller painted), which are then not checked.
    levels
        Reductions of the image the finder may use instead of computing them
        (:func:`fidelity.chart.find.cascade.find_chart`; a large JPEG's quarter-size decode,
        :func:`measure_image`); None: computed from ``pixels``.
    """
    to_srgb = cm.matrix_rgb_to_linear_srgb(colourspace)
    if encoding not in ENCODINGS:
        raise unknown_name("encoding", encoding, ENCODINGS)
    if negatives not in NEGATIVE_RULES:
        raise unknown_name("rule for negative values", negatives, NEGATIVE_RULES)
    arr = np.asarray(pixels)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    ref = reference if isinstance(reference, Reference) else load_reference(reference, illuminant)
    if exposure is None:
        exposure = "auto" if encoding == "linear" else 0.0
    if isinstance(exposure, str):
        if exposure.strip().lower() == "auto":
            mode = "auto"
        else:
            try:
                exposure = float(exposure)
            except ValueError:
                raise InvalidValueError(
                    f"--exposure {exposure!r}: expected 'auto' or a number of EV") from None
    if not isinstance(exposure, str):
        if not math.isfinite(float(exposure)) or abs(float(exposure)) > MAX_EXPOSURE_EV:
            raise InvalidValueError(f"--exposure {exposure!r}: must be a finite number of EV "
                                    f"within +-{MAX_EXPOSURE_EV:g}")
        mode = "fixed"
    found = None
    checks = None
    # the finder: loaded where a chart is found or its given corners are checked, not by check
    if corners is None:
        from fidelity.chart.find.cascade import find_chart  # noqa: PLC0415 (the finder)

        found = find_chart(arr, encoding=encoding, method=detection, rows=ref.rows,
                           cols=ref.cols, levels=levels)
        corners = found.corners
        checks = found.checks
    loc = locate_chart(corners, arr.shape, rows=ref.rows, cols=ref.cols, window=window,
                       patch_names=ref.patch_names)
    if found is None and corner_checks and (ref.rows, ref.cols) == (4, 6):
        from fidelity.chart.find.cascade import check_corners  # noqa: PLC0415 (the same)

        checks = check_corners(arr, loc.corners, encoding=encoding)
    # patches the finder judged covered (a leaf, a hand) are measured but left out of the
    # exposure fit and the chart's statistics, and named
    excluded = {ref.patch_names[k]: OCCLUDED_REASON for k in
                (found.occluded if found is not None and len(ref.patch_names) == 24 else ())}
    n = len(loc.windows)
    means = np.empty((n, 3))
    valid_counts: list[int] = []
    per_patch: dict[str, int] = {}
    totals = {"nan": 0, "inf": 0, "negative": 0, "total": 0}
    identity = bool(np.array_equal(to_srgb, np.eye(3)))
    coded = is_coded(arr) and identity
    histograms: list[np.ndarray] = []
    spreads: list[PatchSpread] = []
    neutral_lin: dict[int, np.ndarray] = {}  # the neutral windows' linear pixels, for the noise
    neutral_set = set(ref.neutral_indices) if texture else set()
    step = _CODE_STEPS.get(str(image.pixel_type if image is not None else arr.dtype).lower())
    for k, win in enumerate(loc.windows):
        vals = win.values(arr)
        if coded:  # integer codes: a histogram per channel holds all the patch has to say
            histograms.append(_code_histogram(vals))
            counts, valid = dict(_NO_BAD), len(vals)
        else:
            lin, counts = _patch_linear(vals, encoding, negatives, to_srgb, identity)
            valid = len(lin)
            if k in neutral_set:
                neutral_lin[k] = lin
        if uncertainty:  # one window's spread at a time: never every window's pixels at once
            spreads.append(_window_spread(vals, lin if not coded else None, encoding,
                                          negatives, to_srgb, identity, step, win,
                                          arr.shape[1]))
        for key in totals:
            totals[key] += counts[key]
        if counts["total"]:
            per_patch[ref.patch_names[k]] = counts["total"]
        need = max(MIN_VALID_PIXELS, int(math.ceil(min_valid_fraction * len(vals))))
        if valid < need:
            negative = (f", {counts['negative']} negative" if negatives == "exclude" else "")
            raise InvalidValueError(
                f"patch {ref.patch_names[k]!r}: only {valid} of {len(vals)} pixels are "
                f"valid ({counts['nan']} NaN, {counts['inf']} Inf{negative}); need at least "
                f"{need}"
            )
        means[k] = (histograms[-1] @ _code_linear(arr.dtype.str, encoding) / valid if coded
                    else lin.mean(axis=0))
        valid_counts.append(valid)
    neutrals = [k for k in ref.neutral_indices if ref.patch_names[k] not in excluded]
    if mode == "auto":
        ev = exposure_from_neutrals(means, ref.lab, neutrals or ref.neutral_indices,
                                    ref.patch_names)
        neutral_ev: float | None = ev
    else:
        ev = float(exposure)
        try:  # what the neutral patches ask for: the fixed exposure's error
            neutral_ev = exposure_from_neutrals(means, ref.lab, neutrals or ref.neutral_indices,
                                                ref.patch_names)
        except InvalidValueError:  # black neutrals, or beyond the range: no error to judge
            neutral_ev = None
    scale = 2.0 ** ev
    with np.errstate(over="ignore", invalid="ignore"):
        exposed = means * scale
    if not np.all(np.isfinite(exposed)):
        beyond = [ref.patch_names[k] for k in range(n) if not np.all(np.isfinite(exposed[k]))]
        raise InvalidValueError(
            f"exposure {ev:+.4g} EV takes the patch values beyond the floating-point range "
            f"(patches {', '.join(beyond)}); give a smaller --exposure")
    srgb_unclipped = cm.delinearize_srgb(exposed)
    srgb = np.clip(srgb_unclipped, 0.0, 1.0)
    clipped = tuple(ref.patch_names[k] for k in range(n)
                    if np.any(np.abs(srgb_unclipped[k] - srgb[k]) > 1e-12))
    if coded:
        noise = np.array([_histogram_noise(hist, _code_linear(arr.dtype.str, encoding), scale)
                          for hist in histograms])
    else:
        noise = np.array([_patch_noise(win.values(arr), scale, encoding, negatives, to_srgb,
                                       identity) for win in loc.windows])
    whole = _whole_image_counts(arr, negatives)
    rule = ("a pixel with NaN, +-Inf or a negative value in any channel is excluded"
            if negatives == "exclude" else
            "a pixel with NaN or +-Inf in any channel is excluded; negative values are counted "
            "and kept in the linear mean")
    bad_pixels = BadPixels(PixelCounts(**totals), per_patch, PixelCounts(**whole), negatives,
                           f"{rule}; counts in sampling windows (image: whole image); total: "
                           f"pixels excluded")
    measurement = measure_chart(srgb, ref.lab, ref.patch_names, reference_srgb=ref.srgb,
                                noise=noise, excluded=excluded)
    budget = None
    if uncertainty:
        budget = image_uncertainty(
            arr, loc, spreads, means, ref, measurement.mean_delta_e,
            exposure_ev=None if mode == "auto" else ev, fitted_ev=ev, encoding=encoding,
            negatives=negatives, to_srgb=to_srgb, found=found, step=step,
            excluded=tuple(excluded))
    chart_noise_, chart_sharpness = (
        noise_and_sharpness(arr, loc, means, ref, encoding=encoding, negatives=negatives,
                            to_srgb=to_srgb, neutral_samples=neutral_lin,
                            edge_target=edge_target, sharpness=sharpness)
        if texture else (None, None))
    return ImageMeasurement(
        measurement=measurement, exposure_ev=ev, exposure_mode=mode, encoding=encoding,
        bad_pixels=bad_pixels, valid_pixels=tuple(valid_counts), clipped_patches=clipped,
        location=loc, reference=ref, image=image, detection=found,
        colourspace=_colourspace_name(colourspace), corner_checks=checks,
        uncertainty=budget, noise=chart_noise_, sharpness=chart_sharpness, neutral_ev=neutral_ev,
        linear_means=means,
    )


#: Most pixels of a neutral window its noise statistics are computed from
#: (:func:`_noise_sample`): a 12 MP photo's windows (about 115 000 pixels) from every second
#: pixel down and across, a 108 MP photo's (about a million) from every sixth. The variance of
#: 32 768 pixels is within about ``1 / sqrt(2 n)`` = 0.4 % of the whole window's for white
#: noise, and its stated u (from ``n``, the sample's) says so; the same holds for noise
#: correlated over more than the stride (texture, demosaicing, compression). On the
#: audit_speed photos the sigmas are within 0.41 % (12 MP) and 0.60 % (108 MP) of the whole
#: windows'. A 12 MP audit: about 7 % faster than from 131 072.
NOISE_SAMPLE_PIXELS = 1 << 15
#: How a chart's noise is measured where every neutral window is read whole.
NOISE_METHOD = CHART_NOISE_METHOD
#: ... and where a window has more than :data:`NOISE_SAMPLE_PIXELS` valid pixels.
NOISE_SAMPLED_METHOD = (CHART_NOISE_METHOD + f"; a window over {NOISE_SAMPLE_PIXELS} pixels: "
                        "from every s-th pixel down and across (the least s leaving at most "
                        "that many), n the sample's")


def _noise_sample(y0: int, x0: int, mask: np.ndarray, limit: int = NOISE_SAMPLE_PIXELS
                  ) -> np.ndarray | None:
    """Which of a window's pixels (``mask`` ``(h, w)`` over the box from row ``y0``, column
    ``x0``, row-major as :meth:`PatchWindow.values` lists them) its noise is computed from when
    it has more than ``limit``: those whose image row and column are multiples of the least
    stride ``s`` leaving at most about ``limit``, an even lattice over the whole window. None:
    every pixel."""
    count = int(np.count_nonzero(mask))
    if count <= limit:
        return None
    stride = math.ceil(math.sqrt(count / limit))
    h, w = mask.shape
    down = (np.arange(h) + y0) % stride == 0
    across = (np.arange(w) + x0) % stride == 0
    keep: np.ndarray = (mask & down[:, None] & across[None, :])[mask]
    return keep


def noise_and_sharpness(pixels: np.ndarray, location: ChartLocation, means: np.ndarray,
                        reference: Reference, *, encoding: str, negatives: str,
                        to_srgb: np.ndarray,
                        neutral_samples: Mapping[int, np.ndarray] | None = None,
                        edge_target: EdgeTargetCorners | None = None,
                        sharpness: bool = True,
                        ) -> tuple[ChartNoise | None, ChartSharpness | None]:
    """The chart's noise and sharpness in LINEAR light (before any exposure correction).

    Linear input as it is, sRGB-encoded input decoded with the IEC 61966-2-1 transfer function
    (integer codes as ``code / (2**bits - 1)``), other primaries converted to linear sRGB, as
    the patch means are; the record names the linearisation.

    Parameters
    ----------
    pixels
        The ``(H, W, 3)`` image as stored.
    location
        The chart's location.
    means
        The patches' linear means ``(n, 3)`` (linear sRGB), chart order.
    reference
        The reference chart (patch names, neutral patches).
    encoding
        ``linear`` or ``srgb``.
    negatives
        The rule for negative values (:data:`NEGATIVE_RULES`).
    to_srgb
        The ``3 x 3`` matrix from the pixels' primaries to linear sRGB.
    neutral_samples
        Patch index -> its window's valid pixels in linear sRGB ``(n, 3)``, where the caller
        has them already (:func:`measure_pixels`); the others are read from ``pixels``.
    edge_target
        A slanted-edge target's corners in the image: the sharpness is measured on its square
        (:func:`fidelity.measure.chartsharpness.target_sharpness`); None: on the chart's own
        edges (:func:`fidelity.measure.chartsharpness.chart_sharpness`).
    sharpness
        False: the noise only (the sharpness None).

    Returns
    -------
    tuple
        ``(ChartNoise or None, ChartSharpness or None)``: None where the noise could not be
        measured (a neutral patch with fewer than 2 valid pixels) or the chart is not 4 x 6.
    """
    identity = bool(np.array_equal(to_srgb, np.eye(3)))
    how = ("none (linear input)" if encoding == "linear"
           else "sRGB transfer function decoded (IEC 61966-2-1)")
    if is_coded(pixels):
        how += f", {pixels.dtype} codes / {np.iinfo(pixels.dtype).max}"
    if not identity:
        how += ", primaries converted to linear sRGB"
    bounded = identity and (is_coded(pixels) or encoding == "srgb")
    saturation, black = (1.0, 0.0) if bounded else (None, None)

    def linearise(v: np.ndarray) -> np.ndarray:
        return _to_linear(np.asarray(v), encoding, to_srgb, identity)

    names = reference.patch_names
    neutral = list(reference.neutral_indices)
    noise: ChartNoise | None = None
    if neutral:
        ref_y = cm.lab_to_xyz(np.asarray(reference.lab, np.float64))[:, 1]
        grey = names[grey_index(names, neutral, ref_y)]
        samples = []
        sampled = False
        for k in neutral:
            window = location.windows[k]
            keep = _noise_sample(window.y0, window.x0, window.mask)
            if keep is not None:  # a large window: its noise from a lattice of its pixels
                sampled = True
                samples.append(_patch_linear(_rows(window.values(pixels), keep), encoding,
                                             negatives, to_srgb, identity)[0])
            elif neutral_samples is not None and k in neutral_samples:
                samples.append(neutral_samples[k])
            else:
                samples.append(_patch_linear(window.values(pixels), encoding, negatives,
                                             to_srgb, identity)[0])
        try:
            noise = chart_noise(samples, [names[k] for k in neutral], grey, linearisation=how,
                                saturation=saturation,
                                method=NOISE_SAMPLED_METHOD if sampled else NOISE_METHOD)
        except RefusedFit:
            noise = None
    edges: ChartSharpness | None = None
    if not sharpness:
        pass
    elif edge_target is not None:
        edges = target_sharpness(pixels, edge_target, linearise=linearise,
                                     linearisation=how, saturation=saturation, black=black)
    elif (location.rows, location.cols) == (reference.rows, reference.cols):
        edges = chart_sharpness(pixels, location, luminance_linear_srgb(means), names,
                                linearise=linearise, linearisation=how,
                                saturation=saturation, black=black)
    return noise, edges


#: Code steps of integer pixel types (pixels read as [0, 1]).
_CODE_STEPS = {"uint8": 1.0 / 255.0, "int8": 1.0 / 127.0, "uint16": 1.0 / 65535.0,
               "int16": 1.0 / 32767.0}


#: Candidate pixels beyond which the placement component re-measures the windows on a regular
#: lattice of them (about 28 MB while its draws run; an 8 MP chart's windows hold about 1.7
#: million, and their placement term is of the order of 1e-4 ΔE00 either way).
PLACEMENT_CANDIDATES = 500_000


def _window_remeasurer(pixels: np.ndarray, location: ChartLocation, sigma: float,
                       negatives: str, linear: Any, table: np.ndarray | None = None) -> Any:
    """A function of jittered corners ``(4, 2)`` -> the linear patch means ``(n, 3)`` measured
    with the windows they give (the membership rule of :func:`fidelity.chart.locate.locate_chart`: a pixel
    belongs to a patch's window when its centre maps inside it), or None when a window is
    empty. The candidate pixels (each window's box grown by ``4 sigma + 2`` px), without the
    bad ones (``negatives`` rule), are read and converted to linear sRGB (``linear``; integer
    codes by ``table``, the linear value of each code, when given) once; a draw maps them
    through its homography."""
    rows, cols = location.rows, location.cols
    height, width = pixels.shape[:2]
    grow = int(math.ceil(4.0 * sigma)) + 2
    boxes = []
    for k, win in enumerate(location.windows):
        if win.count == 0:
            continue
        h, w = win.mask.shape
        boxes.append((k, max(win.y0 - grow, 0), min(win.y0 + h - 1 + grow, height - 1),
                      max(win.x0 - grow, 0), min(win.x0 + w - 1 + grow, width - 1)))
    total = sum((y1 - y0 + 1) * (x1 - x0 + 1) for _, y0, y1, x0, x1 in boxes)
    # every candidate pixel costs about 56 bytes while the draws run: above
    # PLACEMENT_CANDIDATES, a regular lattice of them (the same for every draw) stands for all
    stride = max(1, math.ceil(math.sqrt(total / PLACEMENT_CANDIDATES)))
    half = location.window / 2.0 + 1e-9
    n = rows * cols
    grid_corners = np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], float)
    # Only the pixels near a window's edge can change sides when the corners move by up to
    # ``grow`` px: those farther in are counted once (``fixed``), those farther out dropped.
    # A corner shift of d px moves a grid position by at most about d / pitch (the smallest
    # pitch along the chart's sides), taken 1.5 times over for safety; a draw moving a corner
    # farther than ``grow`` px (beyond 4 sigma) is not measured (it would need pixels
    # outside the boxes read).
    c0 = np.asarray(location.corners, np.float64)
    sides = [float(np.linalg.norm(c0[1] - c0[0])) / max(cols - 1, 1),
             float(np.linalg.norm(c0[2] - c0[3])) / max(cols - 1, 1),
             float(np.linalg.norm(c0[3] - c0[0])) / max(rows - 1, 1),
             float(np.linalg.norm(c0[2] - c0[1])) / max(rows - 1, 1)]
    margin = 1.5 * grow / max(min(sides), 1e-9)
    g0 = np.linalg.inv(homography_from_points(grid_corners, c0))
    centres = grid_centres(rows, cols)
    fixed_counts = np.zeros(n)
    fixed_sums = np.zeros((n, 3))
    # one window's candidates at a time, as columns (no (N, 2) or (N, 3) temporaries over all
    # of them): the grid position of each (the homography as apply_homography computes it),
    # its reach from the window's centre; the inner ones summed, the band's kept
    bx, by, bu, bv, bvals, bwho = [], [], [], [], [], []
    for k, y0, y1, x0, x1 in boxes:
        ys = np.arange(y0, y1 + 1, stride, dtype=np.float64)
        xs = np.arange(x0, x1 + 1, stride, dtype=np.float64)
        box = pixels[y0:y1 + 1:stride, x0:x1 + 1:stride].reshape(-1, 3)
        coded = table is not None and is_coded(box)
        v = box if coded else as_float32(box).astype(np.float64)
        keep = np.ones(len(v), bool) if coded else ~_bad_counts(v, negatives)[0]
        gx = np.broadcast_to(xs[None, :], (ys.size, xs.size)).reshape(-1)[keep]
        gy = np.broadcast_to(ys[:, None], (ys.size, xs.size)).reshape(-1)[keep]
        w = g0[2, 0] * gx + g0[2, 1] * gy + g0[2, 2]
        cu0, cv0 = centres[k]
        reach = np.maximum(np.abs((g0[0, 0] * gx + g0[0, 1] * gy + g0[0, 2]) / w - cu0),
                           np.abs((g0[1, 0] * gx + g0[1, 1] * gy + g0[1, 2]) / w - cv0))
        inner = reach <= half - margin
        band = (reach > half - margin) & (reach <= half + margin)
        near = _rows(v if coded else _rows(v, keep), inner | band)
        lin = table[near] if coded and table is not None else linear(near)
        within = inner[inner | band]
        fixed_counts[k] = float(np.count_nonzero(inner))
        fixed_sums[k] = _rows(lin, within).sum(axis=0)
        bx.append(gx[band])
        by.append(gy[band])
        bu.append(np.full(bx[-1].size, cu0))
        bv.append(np.full(bx[-1].size, cv0))
        bvals.append(_rows(lin, ~within))
        bwho.append(np.full(bx[-1].size, k))
    # the band's coordinates, centres and colours as contiguous columns: a draw's pass over
    # them is a few vector operations on each (no (N, 3) temporaries)
    px, py = np.concatenate(bx), np.concatenate(by)
    cu, cv = np.concatenate(bu), np.concatenate(bv)
    band_vals = np.concatenate(bvals) if bvals else np.zeros((0, 3))
    channels = [np.ascontiguousarray(band_vals[:, c]) for c in range(3)]
    who = np.concatenate(bwho).astype(np.int64)

    def remeasure(corners: np.ndarray) -> np.ndarray | None:
        if float(np.max(np.abs(np.asarray(corners, np.float64) - c0))) > grow:
            return None
        try:
            g = np.linalg.inv(homography_from_points(grid_corners, corners))  # image -> grid
        except (InvalidValueError, np.linalg.LinAlgError):
            return None
        w = g[2, 0] * px + g[2, 1] * py + g[2, 2]
        u = (g[0, 0] * px + g[0, 1] * py + g[0, 2]) / w
        inside = np.abs(u - cu) <= half
        v = (g[1, 0] * px + g[1, 1] * py + g[1, 2]) / w
        inside &= np.abs(v - cv) <= half
        who_in = who[inside]
        counts = fixed_counts + np.bincount(who_in, minlength=n)
        if np.any(counts == 0):
            return None
        sums = fixed_sums + np.stack([np.bincount(who_in, weights=ch[inside], minlength=n)
                                      for ch in channels], axis=-1)
        means: np.ndarray = sums / counts[:, None]
        return means

    return remeasure


def image_uncertainty(
    pixels: np.ndarray, location: ChartLocation, spreads: Sequence[PatchSpread],
    linear_means: np.ndarray, reference: Reference, value: float, *,
    exposure_ev: float | None, fitted_ev: float, encoding: str, negatives: str,
    to_srgb: np.ndarray, found: FoundChart | None, step: float | None,
    excluded: Sequence[str] = (),
) -> UncertaintyBudget:
    """The uncertainty budget of an audited chart's ΔE (:mod:`fidelity.measure.uncertainty`):
    pixel noise and rounding of integer codes (of ``step``, None for float pixels) from each
    window's :class:`~fidelity.measure.uncertainty.PatchSpread`, placement of the corners and
    the exposure normalisation (``exposure_ev`` None: auto, fitted at ``fitted_ev``)."""
    ref_lab = np.asarray(reference.lab, np.float64)
    # the patches left out of the measurement (covered ones) are left out here too: of the
    # mean ΔE and of the exposure's neutrals, as measure_pixels leaves them out
    used = np.array([n not in excluded for n in reference.patch_names], dtype=bool)
    neutral = ([k for k in reference.neutral_indices if used[k]]
               or list(reference.neutral_indices))
    f = unc.linear_chart_function(ref_lab, neutral, exposure_ev, used=used)
    covs, notes = unc.spread_covariances(spreads, patch_names=reference.patch_names)
    noise, _ = unc.noise_component((), linear_means, f, covariances=covs,
                                   designs=[sp.design for sp in spreads],
                                   sampled=[sp.sampled for sp in spreads])
    identity = np.array_equal(to_srgb, np.eye(3))

    def to_linear(v: np.ndarray) -> np.ndarray:
        lin = v if encoding == "linear" else cm.linearize_srgb(v)
        return lin if identity else lin @ to_srgb.T

    to_measured = None
    code_std = None
    if step:
        code_mean = np.array([s.code_mean if s.code_mean is not None else np.zeros(3)
                              for s in spreads])
        code_std = np.array([s.code_std if s.code_std is not None and s.count else
                             np.zeros(3) for s in spreads])
        if encoding == "srgb":
            h = step / 2
            slope = (cm.linearize_srgb(code_mean + h) - cm.linearize_srgb(code_mean - h)) / (2 * h)
        else:
            slope = np.ones_like(linear_means)

        def to_measured(e: np.ndarray) -> np.ndarray:
            lin = e * slope[None]
            return lin if identity else lin @ to_srgb.T

    rounding = unc.rounding_component((), linear_means, f, step, code_std=code_std,
                                      to_measured=to_measured)

    if found is not None and math.isfinite(found.residual_px):
        sigma = max(found.residual_px / math.sqrt(2.0), unc.UNREFINED_PLACEMENT_PX)
        how = ("the RMS residual of the finder's refined fit / sqrt(2), at least a "
               "rectangular half pixel")
    elif found is not None:
        sigma, how = 1.0, "found without refinement: one pixel assumed"
    else:
        sigma, how = unc.UNREFINED_PLACEMENT_PX, "corners given: a rectangular half pixel"
    table = (_code_linear(pixels.dtype.str, encoding) if is_coded(pixels) and identity
             else None)  # the linear value of each code, as to_linear gives it
    remeasure = _window_remeasurer(pixels, location, sigma, negatives, to_linear, table)
    placement = unc.placement_component(remeasure, location.corners, sigma, how, f)
    if exposure_ev is None:
        exposure = unc.exposure_component(
            linear_means, ref_lab, neutral, fitted_ev,
            unc.linear_chart_function(ref_lab, neutral, 0.0, used=used), covs)
    else:
        exposure = unc.UncertaintyComponent("exposure normalisation", 0.0, "B",
                                            "exposure fixed: no normalisation")
    return unc.UncertaintyBudget(float(value), (noise, rounding, placement, exposure),
                                 notes=notes)


def _colourspace_name(colourspace: str | Sequence[float]) -> str:
    if isinstance(colourspace, str):
        return colourspace
    return "chromaticities " + ",".join(f"{float(v):.5g}" for v in colourspace)



def measure_image(
    path: str | os.PathLike[str],
    corners: np.ndarray | str | Sequence[float] | None = None,
    *,
    read: ReadOptions = DEFAULT_READ,
    reference: str | Reference = DEFAULT_REFERENCE,
    illuminant: str = "D65",
    window: float = DEFAULT_WINDOW,
    detection: str = "cascade",
    inspect_image: Callable[[Image], object] | None = None,
    edge_target: EdgeTargetCorners | None = None,
) -> ImageMeasurement:
    """Read an image (:func:`fidelity.chart.image.read_image`, as ``read`` says:
    :class:`ReadOptions`; an image file at its native depth) and audit its chart
    (:func:`measure_pixels`). Errors name the file. ``inspect_image`` is called with the image
    once it is read, before its chart is measured, so that a caller can look at more of it
    without reading it again, meanwhile if it likes (the audit's banding check, in a thread
    beside the chart's measurement); it must not change the pixels.

    Parameters
    ----------
    path
        An image file (EXR, HDR, TIFF, PNG, JPEG, camera raw mosaic, ...) or a robot
        recording (ROS 1/2 bag, MCAP) whose message ``read`` names.
    corners
        Centres of the dark skin, bluish green, black and white patches: ``(4, 2)`` image
        ``(x, y)`` in pixels or ``"X1,Y1,...,X4,Y4"``; None: find the chart
        (:func:`fidelity.chart.find.cascade.find_chart` with ``detection``).
    read
        How the pixels are read: layer, encoding, exposure, negatives rule, colourspace,
        Bayer pattern, pixel limit, OpenColorIO colourspace, recording message
        (:class:`ReadOptions`; default: the file's own encoding and primaries, auto exposure
        for linear pixels).
    reference
        The reference colours: ``scene`` (default: the chart's spectra under ``illuminant``),
        ``safecolor`` or a chart name/path, or a loaded :class:`Reference`.
    illuminant
        Scene illuminant of the ``scene`` reference (``D65``, ``D50``, ``A``, ``F2``,
        ``F11``, ``LED`` or an SPD file).
    window
        Side of each patch's central sampling square, in patch pitches, in (0, 1]
        (default 0.5).
    detection
        Chart-finding method when ``corners`` is None: ``cascade`` (default), ``mcc`` or
        ``segmentation`` (:data:`fidelity.chart.find.cascade.CHART_FINDERS`).
    inspect_image
        Called with the :class:`Image` read once its chart is measured; None: not called.
    edge_target
        A slanted-edge target's corners in the image (:func:`measure_pixels`); None: the
        sharpness is measured on the chart's edges.

    Returns
    -------
    ImageMeasurement
        The chart's ΔE00 per patch, exposure, bad-pixel counts, location, detection, the
        image file's description and the ΔE's uncertainty budget.

    Raises
    ------
    InputFileError
        A missing, unreadable or corrupt image or recording. Exit code 2.
    InvalidValueError
        No chart found (or found with low confidence, or of another kind), corners outside
        the image or degenerate, a window outside (0, 1], too few valid pixels in a patch, an
        exposure out of range or that overflows. The message names the file. Exit code 2.
    UnknownNameError
        An unknown encoding, negatives rule, colourspace, reference, illuminant or detection
        method. Exit code 2.
    """
    from concurrent.futures import ThreadPoolExecutor  # 6 ms, only where an image is measured

    # a large JPEG's search level is decoded in a thread while the full image is read
    with ThreadPoolExecutor(max_workers=1) as pool:
        early = _search_level(path) if corners is None else None
        pending = pool.submit(_decode_search_level, path, early) if early is not None else None
        img, sha256 = read_input(path, read, native=True)
        levels = (_decoded_levels(img, early, pending.result() if pending else None)
                  if corners is None else None)
    enc = read.encoding or img.encoding
    info = img.info(sha256=sha256, encoding=enc)
    if inspect_image is not None:
        inspect_image(img)
    try:
        result = measure_pixels(img.pixels, corners, encoding=enc, exposure=read.exposure,
                                levels=levels,
                                reference=reference, illuminant=illuminant, window=window,
                                image=info, detection=detection, negatives=read.negatives,
                                colourspace=(read.colourspace if read.colourspace is not None
                                             else img.chromaticities or "sRGB"),
                                edge_target=edge_target)
    except FidelityError as exc:
        raise type(exc)(f"{img.where}: {exc}") from None
    return result


def _search_level(path: str | os.PathLike[str]) -> int | None:
    """The level factor the finder's search view reads of the JPEG at ``path``
    (:func:`fidelity.chart.find.view.level_factor` at
    :data:`~fidelity.chart.find.cascade.SEARCH_SIDE`, from the file's header), where libjpeg
    decodes it (:data:`~fidelity.chart.find.view.JPEG_LEVEL_FACTORS`); None for other files."""
    from fidelity.chart.find import view  # noqa: PLC0415 (the finder, loaded where a chart is found)
    from fidelity.chart.find.cascade import SEARCH_SIDE  # noqa: PLC0415 (the same)

    if Path(path).suffix.lower() not in (".jpg", ".jpeg"):
        return None
    size = stored_size(path)
    if size is None:
        return None
    height, width = size
    factor = view.level_factor(height, width, min(1.0, SEARCH_SIDE / max(height, width)))
    return factor if factor in view.JPEG_LEVEL_FACTORS else None


def _decode_search_level(path: str | os.PathLike[str], factor: int) -> np.ndarray | None:
    """:func:`fidelity.chart.find.view.decode_jpeg_level` (run in a thread beside the read)."""
    from fidelity.chart.find import view  # noqa: PLC0415 (the finder, loaded where a chart is found)

    return view.decode_jpeg_level(path, factor)


def _decoded_levels(img: Image, early: int | None = None,
                    decoded: np.ndarray | None = None) -> dict[int, np.ndarray] | None:
    """The level of a large JPEG that the finder's search view reads
    (:func:`fidelity.chart.find.view.level_factor` at
    :data:`~fidelity.chart.find.cascade.SEARCH_SIDE`: half size at 12 MP, a quarter at 108
    MP), decoded by libjpeg's DCT scaling (:func:`fidelity.chart.find.view.jpeg_level`)
    instead of averaged down from the full image, where ``img`` is that file's own 8-bit
    pixels (no recording, Bayer mosaic or OpenColorIO conversion) and the view reads a
    reduced level; else None. Only the finder reads it: the windows are read from the full
    image. ``decoded``: :func:`_decode_search_level`'s level ``early`` of the same file, decoded
    meanwhile (:func:`measure_image`); used where ``early`` is the level the view reads."""
    from fidelity.chart.find import view  # noqa: PLC0415 (the finder, loaded where a chart is found)
    from fidelity.chart.find.cascade import SEARCH_SIDE  # noqa: PLC0415 (the same)

    px = img.pixels
    if (img.file_format.lower() not in ("jpeg", "jpg") or img.recording is not None
            or img.bayer is not None or img.ocio is not None or px.dtype != np.uint8
            or px.ndim != 3):
        return None
    height, width = px.shape[:2]
    factor = view.level_factor(height, width, min(1.0, SEARCH_SIDE / max(height, width)))
    if factor not in view.JPEG_LEVEL_FACTORS:
        return None
    level = view.jpeg_level(img.path, px, factor, decoded if factor == early else None)
    return None if level is None else {factor: level}


__all__ = [
    "ENCODINGS",
    "BadPixels",
    "PixelCounts",
    "MIN_VALID_FRACTION",
    "MIN_VALID_PIXELS",
    "NEGATIVE_RULES",
    "ImageMeasurement",
    "exposure_from_neutrals",
    "luminance_linear_srgb",
    "noise_and_sharpness",
    "measure_image",
    "window_linear",
    "measure_pixels",
    "image_uncertainty",
]
