"""Views of an image for the chart finder: part of it, shrunk, in the detectors' domain.

A :class:`Pyramid` holds the image and its 2 x 2 area-average reductions; :func:`make_view`
cuts a region from the right level, shrinks it to a given long side, scales its brightest
channel's 99th percentile to 1 and gives it both as linear float32 and as the 8-bit sRGB that
OpenCV's detectors read (:class:`View`). :func:`opencv` imports OpenCV or says what to install.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.chart.image import as_float32, is_coded
from fidelity.colour import colorimetry as cm
from fidelity.core.errors import FidelityError, InvalidValueError
from fidelity.core.numeric import percentile
from fidelity.core.record import record

F64 = NDArray[np.float64]


@record
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


def opencv() -> Any:
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

    def __init__(self, pixels: np.ndarray, levels: Mapping[int, np.ndarray] | None = None
                 ) -> None:
        self.levels: dict[int, np.ndarray] = {1: np.asarray(pixels)}
        self.height, self.width = self.levels[1].shape[:2]
        for factor, level in (levels or {}).items():  # reductions the decoder made
            if level.shape[:2] != (self.height // factor, self.width // factor):
                raise InvalidValueError(f"a pyramid level of factor {factor} must be "
                                        f"{self.height // factor} x {self.width // factor}, "
                                        f"got {level.shape[:2]}")
            self.levels[int(factor)] = np.asarray(level, np.float32)

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


#: Reductions libjpeg's DCT scaling decodes (OpenCV's ``IMREAD_REDUCED_COLOR_{2,4,8}``): a JPEG
#: whose finder search view reads one of these levels (:func:`level_factor`: a long side of at
#: least twice the view's) has that level decoded (:func:`jpeg_level`) instead of averaged down
#: from the full image (a fraction of the time: benchmarks/speed/audit_speed.py; 12 MP reads
#: the half-size level, 108 MP the quarter-size one).
JPEG_LEVEL_FACTORS = (2, 4, 8)
#: Largest difference (in code values / 255) between the decoder's reduction and the full
#: image's block means, per channel over the whole image, for the reduction to be used: the
#: same pixels (not a file the reader converted otherwise).
JPEG_LEVEL_TOLERANCE = 2.0 / 255.0


def decode_jpeg_level(path: str | os.PathLike[str], factor: int) -> np.ndarray | None:
    """The JPEG at ``path`` decoded at ``1 / factor`` of its size by libjpeg's DCT scaling
    (OpenCV's ``IMREAD_REDUCED_COLOR_{factor}``, EXIF orientation ignored): ``uint8`` B, G, R
    ``(ceil(H / factor), ceil(W / factor), 3)``; None where OpenCV cannot decode it so or
    ``factor`` is not in :data:`JPEG_LEVEL_FACTORS`. It releases the GIL while it decodes, so
    that it can run in a thread beside the full-size read (:func:`jpeg_level` checks that the
    two are the same pixels)."""
    cv2 = opencv()
    flags = {2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
             8: cv2.IMREAD_REDUCED_COLOR_8}.get(int(factor))
    if flags is None:
        return None
    reduced: np.ndarray | None = cv2.imread(os.fspath(path), flags | cv2.IMREAD_IGNORE_ORIENTATION)
    return reduced


def jpeg_level(path: str | os.PathLike[str], pixels: np.ndarray, factor: int,
               decoded: np.ndarray | None = None) -> np.ndarray | None:
    """The :class:`Pyramid` level ``factor`` of a JPEG's 8-bit ``pixels`` (as read from
    ``path``, ``(H, W, 3)``) decoded by libjpeg's DCT scaling (OpenCV's
    ``IMREAD_REDUCED_COLOR_{factor}``, EXIF orientation ignored as the reader ignores it): the
    image's ``factor`` x ``factor`` block means up to the scaled IDCT's low-pass, float32 in
    [0, 1], ``(H // factor, W // factor, 3)``.

    Parameters
    ----------
    path
        The JPEG file the pixels were read from.
    pixels
        Its ``uint8`` codes ``(H, W, 3)``, R, G, B.
    factor
        2, 4 or 8.
    decoded
        :func:`decode_jpeg_level`'s result for ``path`` and ``factor``, decoded meanwhile;
        None: decoded here.

    Returns
    -------
    numpy.ndarray or None
        The level; None where OpenCV cannot decode the file so, the size differs, or its
        channel means differ from the pixels' over the same bands of rows
        (:func:`_band_means`) by more than :data:`JPEG_LEVEL_TOLERANCE` (not the same
        pixels).
    """
    cv2 = opencv()
    arr = np.asarray(pixels)
    if (int(factor) not in JPEG_LEVEL_FACTORS or arr.dtype != np.uint8 or arr.ndim != 3
            or arr.shape[2] != 3):
        return None
    reduced = decoded if decoded is not None else decode_jpeg_level(path, factor)
    h, w = arr.shape[0] // factor, arr.shape[1] // factor
    if (reduced is None or reduced.shape[0] < h or reduced.shape[1] < w or reduced.ndim != 3
            or h < 1 or w < 1):
        return None
    if reduced.shape[:2] != (h, w):
        reduced = np.ascontiguousarray(reduced[:h, :w])
    # the channel means of both over the same bands of rows (OpenCV's, a pass over the codes
    # as stored)
    full, level = _band_means(arr, reduced, factor)
    if np.max(np.abs(level[::-1] / 255.0 - full / 255.0)) > JPEG_LEVEL_TOLERANCE:
        return None
    # B, G, R -> R, G, B by OpenCV (numpy's copy of a reversed channel axis is several times
    # slower), then the codes' float32 values
    return as_float32(cv2.cvtColor(reduced, cv2.COLOR_BGR2RGB))


#: Rows of a decoded level in each band :func:`jpeg_level` compares with the image's rows.
LEVEL_CHECK_BAND = 16
#: One band in every ``LEVEL_CHECK_STRIDE`` of the level's rows is compared (an eighth of
#: the image's pixels: at 108 MP a whole-image pass cost 0.16 s of the audit).
LEVEL_CHECK_STRIDE = 8


def _band_means(codes: np.ndarray, reduced: np.ndarray, factor: int) -> tuple[F64, F64]:
    """The channel means of ``codes`` ``(H, W, 3)`` and of its level ``reduced`` ``(h, w, 3)``
    (``h = H // factor``) over the same bands of rows: the level's rows ``y0 .. y1 - 1`` of
    every :data:`LEVEL_CHECK_STRIDE`-th band of :data:`LEVEL_CHECK_BAND` (all of a level of
    fewer), the image's ``factor`` times as many (every column of both); each band's means
    weighted by its rows."""
    h = reduced.shape[0]
    full = np.zeros(3)
    level = np.zeros(3)
    rows = 0
    for y0 in range(0, h, LEVEL_CHECK_BAND * LEVEL_CHECK_STRIDE):
        y1 = min(y0 + LEVEL_CHECK_BAND, h)
        full += (y1 - y0) * _channel_means(codes[y0 * factor:y1 * factor])
        level += (y1 - y0) * _channel_means(reduced[y0:y1])
        rows += y1 - y0
    return full / rows, level / rows


def _channel_means(codes: np.ndarray) -> F64:
    """The mean of each channel of ``(H, W, 3)`` codes over every pixel (float64 sums):
    OpenCV's ``mean`` on the array as stored (its channels reversed where they are a reversed
    view, as a BGR decode's RGB is), else numpy's."""
    cv2 = opencv()
    if codes.flags.c_contiguous:
        return np.array(cv2.mean(codes)[:3], np.float64)
    flipped = codes[:, :, ::-1]
    if flipped.flags.c_contiguous:
        return np.array(cv2.mean(flipped)[:3], np.float64)[::-1]
    return np.asarray(codes.reshape(-1, 3).mean(axis=0, dtype=np.float64), np.float64)


#: Pixels of the image converted to float at a time when a :class:`Pyramid` level is computed.
PYRAMID_BAND_PIXELS = 1 << 20


def _halvings(block: np.ndarray, step: int, first: bool) -> np.ndarray:
    """``block`` (rows and columns multiples of ``step``) as float32, halved by 2 x 2 area
    averages until ``step`` x ``step`` blocks are averaged; ``first``: the block is of the
    image itself, whose NaN and Inf spread over their 2 x 2 block only and count as black (8-
    and 16-bit codes have none)."""

    cv2 = opencv()
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


def level_factor(height: int, width: int, scale: float) -> int:
    """The :class:`Pyramid` level a view at ``scale`` (view pixels per image pixel, (0, 1]) of
    an image ``height`` x ``width`` is shrunk from: the largest power of 2 at most ``1 /
    scale`` whose level is at least 8 pixels on its short side (1: the image itself)."""
    factor = 1
    while factor * 2 * scale <= 1.0 and min(height, width) // (factor * 2) >= 8:
        factor *= 2
    return factor


def _prepare(pyramid: Pyramid, region: tuple[int, int, int, int], max_side: int, encoding: str,
             steps: bool = False) -> tuple[np.ndarray, F64]:
    """The region shrunk (area average) to ``max_side``, finite, non-negative, linear; with the
    3 x 3 map of its pixel coordinates to the image's. ``steps`` (sRGB only): the region's
    indices into :data:`_DECODE_LUT` (``uint16``) instead of their linear values."""
    cv2 = opencv()
    x0, y0, x1, y1 = region
    s = min(1.0, max_side / max(x1 - x0, y1 - y0))
    factor = level_factor(pyramid.height, pyramid.width, s)
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
        arr = _codes(arr, 65535) if steps else _take(_codes(arr, 65535), _DECODE_LUT)[0]
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
    srgb = encoding == "srgb"
    # sRGB: the view's indices into the decoding table; every later step is a function of the
    # index alone, so it is applied to the table's 65536 entries, then looked up once for the
    # linear view and once for the 8-bit one (the same values, element for element)
    arr, to_image = _prepare(pyramid, region, max_side, encoding, steps=srgb)
    if peak is None:
        step = max(1, int(math.sqrt(arr.shape[0] * arr.shape[1] / 250_000)))
        sample = _take(arr[::step, ::step], _DECODE_LUT)[0] if srgb else arr[::step, ::step]
        brightest = np.maximum(np.maximum(sample[..., 0], sample[..., 1]), sample[..., 2])
        peak = percentile(brightest, 99.0)  # np.percentile's number, without numpy.ma
    if not peak > 0.0:
        raise InvalidValueError("no colour chart found: the image is black")
    values = _DECODE_LUT if srgb else arr
    with np.errstate(over="ignore"):
        scale = np.float32(1.0 / peak)
    if np.isfinite(scale):
        linear = np.multiply(values, scale)
        np.clip(linear, 0.0, 1.0, out=linear)
    else:  # a denormal peak (values ~1e-40): 1/peak overflows single precision
        linear = np.clip(values.astype(np.float64) / peak, 0.0, 1.0).astype(np.float32)
    steps = np.multiply(linear, np.float32(4095))  # linear in [0, 1] -> 4096 steps, rounded
    steps += np.float32(0.5)
    rgb8 = _ENCODE_LUT[steps.astype(np.uint16)]
    if srgb:  # the same elements as ``linear[arr]`` and ``rgb8[arr]``
        linear, rgb8 = _take(arr, linear, rgb8)
    # R, G, B -> B, G, R by OpenCV (numpy's copy of a reversed channel axis is several times
    # slower; the same bytes)
    bgr8 = opencv().cvtColor(rgb8, opencv().COLOR_RGB2BGR)
    return View(linear=linear, bgr8=bgr8, to_image=to_image), peak


#: Indices :func:`_take` converts to numpy's index type at a time (the conversion of a whole
#: view's indices, a fresh 8-byte array for each table, took most of a lookup's time).
TAKE_BAND = 1 << 16


def _take(index: np.ndarray, *tables: np.ndarray) -> tuple[np.ndarray, ...]:
    """``table[index]`` for each 1-D table of ``tables`` (``index``: unsigned integers below
    every table's length, any shape; each result of its shape and its table's dtype), looked
    up a band of :data:`TAKE_BAND` indices at a time, each band's indices converted once for
    all tables."""
    flat = np.ascontiguousarray(index).reshape(-1)
    outs = tuple(np.empty(index.shape, t.dtype) for t in tables)
    flats = [o.reshape(-1) for o in outs]
    for start in range(0, flat.size, TAKE_BAND):
        band = flat[start:start + TAKE_BAND].astype(np.intp)
        for table, out in zip(tables, flats, strict=True):
            np.take(table, band, out=out[start:start + TAKE_BAND], mode="clip")
    return outs


def _codes(values: np.ndarray, top: int) -> np.ndarray:
    """``rint(clip(values, 0, 1) * top)`` (``values`` floats, NaN-free, ``top`` < 65536) as
    ``uint16`` indices into a lookup table, computed a band of :data:`TAKE_BAND` values at a
    time in one float temporary of the band's size (a whole view's fresh temporary took most
    of the time)."""
    flat = np.ascontiguousarray(values).reshape(-1)
    codes = np.empty(values.shape, np.uint16)
    out = codes.reshape(-1)
    scaled = np.empty(min(TAKE_BAND, flat.size), flat.dtype)
    for start in range(0, flat.size, TAKE_BAND):
        band = flat[start:start + TAKE_BAND]
        tmp = scaled[:len(band)]
        np.clip(band, 0.0, 1.0, out=tmp)
        tmp *= np.float32(top)
        np.rint(tmp, out=tmp)
        out[start:start + len(band)] = tmp
    return codes


def detection_image(pixels: np.ndarray, encoding: str = "linear") -> np.ndarray:
    """The float32 linear image in [0, 1] that the detectors see, at full size."""
    arr = np.asarray(pixels)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    view, _ = make_view(arr, (0, 0, arr.shape[1], arr.shape[0]), max(arr.shape[:2]), encoding)
    return view.linear


__all__ = [
    "PYRAMID_BAND_PIXELS",
    "Pyramid",
    "View",
    "decode_jpeg_level",
    "detection_image",
    "jpeg_level",
    "level_factor",
    "make_view",
    "opencv",
]
