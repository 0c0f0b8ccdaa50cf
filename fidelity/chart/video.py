"""Read one frame of a video recording (``.mp4``, ``.mkv``, ``.mov``, ``.avi``, ``.webm``,
``.m4v``) through PyAV (``pip install 'camera-fidelity[video]'``), converting its Y'CbCr
planes to R'G'B' by the matrix and range its stream is tagged with.

The frame is chosen by its index (``frame``, 0-based from the stream's first frame, negative
from the end) or as the frame nearest to ``time`` seconds after the first frame; the reader
seeks to the keyframe before it and decodes forward to it.

Pixels (:func:`ycbcr_to_rgb`): planar Y'CbCr ``yuv420p``, ``yuv422p``, ``yuv444p`` (and their
``yuvj*`` full-range forms) at 8, 10 or 12 bits, chroma upsampled by replicating each sample
over the pixels it covers (nearest, no filter), converted in floating point by the matrix
(ITU-R BT.601: Kr 0.299, Kb 0.114; BT.709: 0.2126, 0.0722; BT.2020 non-constant luminance:
0.2627, 0.0593) and range (limited: Y' 16-235, Cb/Cr 16-240, times ``2**(bits-8)``; full:
0 to ``2**bits - 1``) to R'G'B' clipped to [0, 1]; planar RGB ``gbrp`` (8-16 bits) and packed
RGB (``rgb24``, ``bgr24``, ``rgb0``, ``bgr0``, ``rgba``, ``bgra``, ``rgb48le``) as they are,
normalised by ``2**bits - 1``. The values are taken as sRGB-encoded, like a PNG's, for the
transfers BT.709, sRGB, BT.601 (smpte170m), BT.2020 and unspecified; a PQ (smpte2084) or HLG
(arib-std-b67) stream is refused. Primaries: BT.709 and unspecified are sRGB's; BT.470 B/G,
SMPTE 170M/240M, BT.2020 and Display P3 (:data:`PRIMARIES`) are the image's
``chromaticities``, so that its linear values are converted to linear sRGB by the 3 x 3 of
those primaries (:func:`fidelity.colour.colorimetry.matrix_rgb_to_linear_srgb`), as an EXR's
are; others are refused.

An untagged matrix is taken as BT.601 below 720 lines and BT.709 from 720 lines; an untagged
range as limited. ``matrix`` and ``range_`` override the tags. The frame's
:class:`fidelity.chart.image.Recording` (``kind`` ``video``) names which were assumed.

Errors (:class:`fidelity.core.errors.InputFileError`, one line naming the file): not a video
(or no video stream), an unsupported codec or pixel format (named), a frame out of range
(the count said), a time before the first frame or after the last, HDR transfers, more pixels
than the limit.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.chart.image import Image, Recording, pixel_limit
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.extras import optional_module
from fidelity.core.fileio import display_path
from fidelity.core.record import record

#: The extra that installs the video reader.
EXTRA = "video"
#: File name endings read as videos.
VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi", ".webm", ".m4v")
#: Y'CbCr matrices: name -> (Kr, Kb) (ITU-R BT.601-7, BT.709-6, BT.2020-2 non-constant).
MATRICES = {"bt601": (0.299, 0.114), "bt709": (0.2126, 0.0722), "bt2020": (0.2627, 0.0593)}
#: Y'CbCr ranges.
RANGES = ("limited", "full")
#: Lines from which an untagged matrix is taken as BT.709 (below: BT.601).
HD_LINES = 720

#: FFmpeg's AVColorSpace codes -> matrix names (0 is RGB).
_AV_MATRIX = {1: "bt709", 5: "bt601", 6: "bt601", 9: "bt2020"}
_AV_MATRIX_NAME = {0: "rgb", 1: "bt709", 2: "unspecified", 4: "fcc", 5: "bt470bg",
                   6: "smpte170m", 7: "smpte240m", 8: "ycgco", 9: "bt2020nc", 10: "bt2020c"}
#: AVColorRange codes -> range names.
_AV_RANGE = {1: "limited", 2: "full"}
#: AVColorTransferCharacteristic codes -> names (refused: PQ, HLG).
_AV_TRANSFER = {1: "bt709", 2: "unspecified", 4: "gamma22", 5: "gamma28", 6: "smpte170m",
                7: "smpte240m", 8: "linear", 13: "srgb", 14: "bt2020-10", 15: "bt2020-12",
                16: "smpte2084", 18: "arib-std-b67"}
_HDR_TRANSFERS = ("smpte2084", "arib-std-b67")
#: AVColorPrimaries codes -> names.
_AV_PRIMARIES = {1: "bt709", 2: "unspecified", 4: "bt470m", 5: "bt470bg", 6: "smpte170m",
                 7: "smpte240m", 8: "film", 9: "bt2020", 10: "smpte428", 11: "smpte431",
                 12: "p3-d65", 22: "ebu3213"}
#: Primaries other than BT.709's that are converted: name -> ``Rx, Ry, Gx, Gy, Bx, By, Wx,
#: Wy`` (CIE 1931 xy; ITU-R BT.470-6 System B/G, SMPTE 170M and 240M, ITU-R BT.2020-2,
#: SMPTE EG 432-1 Display P3), all with the D65 white.
PRIMARIES = {"bt470bg": (0.640, 0.330, 0.290, 0.600, 0.150, 0.060, 0.3127, 0.3290),
             "smpte170m": (0.630, 0.340, 0.310, 0.595, 0.155, 0.070, 0.3127, 0.3290),
             "smpte240m": (0.630, 0.340, 0.310, 0.595, 0.155, 0.070, 0.3127, 0.3290),
             "bt2020": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
             "p3-d65": (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290)}
#: Primaries taken as sRGB's (BT.709's) as they are.
_SRGB_PRIMARIES = ("bt709", "unspecified")
#: Packed RGB formats: PyAV's format to take the frame out in, and its bits.
_PACKED_RGB = {"rgb24": ("rgb24", 8), "bgr24": ("rgb24", 8), "rgb0": ("rgb24", 8),
               "bgr0": ("rgb24", 8), "0rgb": ("rgb24", 8), "0bgr": ("rgb24", 8),
               "rgba": ("rgb24", 8), "bgra": ("rgb24", 8), "argb": ("rgb24", 8),
               "abgr": ("rgb24", 8), "rgb48le": ("rgb48le", 16), "rgb48be": ("rgb48le", 16)}
#: Codec names as the description says them.
_CODEC_NAMES = {"h264": "H.264", "hevc": "H.265", "av1": "AV1", "vp9": "VP9", "vp8": "VP8",
                "ffv1": "FFV1", "mpeg4": "MPEG-4", "prores": "ProRes", "mjpeg": "MJPEG"}


def is_video_path(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a video by its name alone (it ends in :data:`VIDEO_SUFFIXES`)."""
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


@record
class Planes:
    """A decoded frame's pixel planes at their native depth: ``kind`` ``ycbcr`` (``planes`` Y',
    Cb, Cr, chroma possibly subsampled) or ``rgb`` (``planes`` R, G, B), integer codes of
    ``bits`` bits."""

    kind: str
    planes: tuple[np.ndarray, np.ndarray, np.ndarray]
    bits: int


def ycbcr_to_rgb(y: np.ndarray, cb: np.ndarray, cr: np.ndarray, *, bits: int, matrix: str,
                 range_: str) -> np.ndarray:
    """Y'CbCr integer codes to R'G'B' in [0, 1].

    Parameters
    ----------
    y, cb, cr
        Code planes of the same ``(H, W)`` shape (chroma already upsampled), 0 to
        ``2**bits - 1``.
    bits
        Bit depth of the codes (8 to 16).
    matrix
        ``bt601``, ``bt709`` or ``bt2020`` (:data:`MATRICES`: Kr, Kb of ITU-R BT.601-7,
        BT.709-6, BT.2020-2 non-constant luminance).
    range_
        ``limited`` (Y' 16-235 and Cb/Cr 16-240 scaled by ``2**(bits-8)``, ITU-R BT.601/709)
        or ``full`` (0 to ``2**bits - 1``, Cb/Cr centred on ``2**(bits-1)``).

    Returns
    -------
    numpy.ndarray
        ``(H, W, 3)`` float32 R', G', B' (the same encoding as the source's), clipped to
        [0, 1]. ``R' = Y' + 2(1-Kr) Cr``, ``B' = Y' + 2(1-Kb) Cb``,
        ``G' = (Y' - Kr R' - Kb B') / (1 - Kr - Kb)``.
    """
    kr, kb = MATRICES[matrix]
    kg = 1.0 - kr - kb
    scale = float(2 ** (bits - 8))
    if range_ == "limited":
        luma = (y.astype(np.float64) - 16.0 * scale) / (219.0 * scale)
        pb = (cb.astype(np.float64) - 128.0 * scale) / (224.0 * scale)
        pr = (cr.astype(np.float64) - 128.0 * scale) / (224.0 * scale)
    else:
        top = float(2 ** bits - 1)
        mid = float(2 ** (bits - 1))
        luma = y.astype(np.float64) / top
        pb = (cb.astype(np.float64) - mid) / top
        pr = (cr.astype(np.float64) - mid) / top
    r = luma + 2.0 * (1.0 - kr) * pr
    b = luma + 2.0 * (1.0 - kb) * pb
    g = (luma - kr * r - kb * b) / kg
    return np.clip(np.stack([r, g, b], axis=-1), 0.0, 1.0).astype(np.float32)


def upsample(plane: np.ndarray, height: int, width: int) -> np.ndarray:
    """A subsampled chroma plane at ``(height, width)``: each sample replicated over the
    pixels it covers (nearest neighbour; 2x for 4:2:0 rows and columns, 4:2:2 columns)."""
    fy = -(-height // plane.shape[0])
    fx = -(-width // plane.shape[1])
    out = plane
    if fy > 1:
        out = np.repeat(out, fy, axis=0)
    if fx > 1:
        out = np.repeat(out, fx, axis=1)
    return out[:height, :width]


def _av(shown: str) -> Any:
    """PyAV, or one line naming the extra."""
    try:
        return optional_module("av", "reading a video needs PyAV",
                               f"pip install 'camera-fidelity[{EXTRA}]'")
    except InvalidValueError as exc:
        raise InputFileError(f"{shown}: {exc}") from None


def _plane(p: Any, dtype: str) -> np.ndarray:
    """One plane of a PyAV frame as a 2-D code array (its row padding dropped)."""
    item = np.dtype(dtype).itemsize
    a = np.frombuffer(memoryview(p), dtype=dtype)
    return a.reshape(p.height, p.line_size // item)[:, :p.width]


def _planes(frame: Any, shown: str) -> Planes:
    """The frame's planes at native depth (:class:`Planes`)."""
    name = str(frame.format.name)
    if name in _PACKED_RGB:
        fmt, bits = _PACKED_RGB[name]
        rgb = frame.to_ndarray(format=fmt)
        return Planes("rgb", (rgb[..., 0], rgb[..., 1], rgb[..., 2]), bits)
    base, _, depth = name.partition("p")
    bits = 8
    if depth:
        if not depth.endswith("le") or not depth[:-2].isdigit():
            raise InputFileError(f"{shown}: pixel format {name} is not read (planar Y'CbCr "
                                 "yuv420p/422p/444p at 8-12 bits, gbrp, packed RGB)")
        bits = int(depth[:-2])
    dtype = "u1" if bits == 8 else "<u2"
    if base in ("yuv420", "yuv422", "yuv444", "yuvj420", "yuvj422", "yuvj444") and bits <= 12:
        y, u, v = (_plane(frame.planes[i], dtype) for i in range(3))
        return Planes("ycbcr", (y, u, v), bits)
    if base == "gbr" and bits <= 16:
        g, b, r = (_plane(frame.planes[i], dtype) for i in range(3))
        return Planes("rgb", (r, g, b), bits)
    raise InputFileError(f"{shown}: pixel format {name} is not read (planar Y'CbCr "
                         "yuv420p/422p/444p at 8-12 bits, gbrp, packed RGB)")


def _frame_index(pts: int, start: int, time_base: Fraction, rate: Fraction) -> int:
    """A frame's index from its presentation time (the stream's time base and frame rate)."""
    return round((pts - start) * time_base * rate)


def _decode_to(container: Any, stream: Any, index: int, start: int, time_base: Fraction,
               rate: Fraction) -> Any | None:
    """The frame of ``index``: seek to the keyframe before it, then decode forward."""
    target = start + int(math.floor(index / (rate * time_base)))
    container.seek(target, stream=stream, backward=True, any_frame=False)
    for frame in container.decode(stream):
        if frame.pts is None:
            continue
        k = _frame_index(int(frame.pts), start, time_base, rate)
        if k == index:
            return frame
        if k > index:
            return None
    return None


def read_frame(path: str | os.PathLike[str], frame: int | None = None,
               time: float | None = None, matrix: str | None = None,
               range_: str | None = None, *, max_pixels: int | None = None
               ) -> tuple[Image, str]:
    """Read one frame of the video at ``path``.

    Parameters
    ----------
    path
        A video file (:data:`VIDEO_SUFFIXES`).
    frame
        0-based frame index (negative: from the end); with neither ``frame`` nor ``time``: 0.
    time
        Seconds after the first frame: the frame nearest to it.
    matrix, range_
        Override the stream's Y'CbCr matrix (:data:`MATRICES`) and range (:data:`RANGES`).
    max_pixels
        Pixel limit (:func:`fidelity.chart.image.pixel_limit`).

    Returns
    -------
    tuple
        The :class:`fidelity.chart.image.Image` (``(H, W, 3)`` float32 R'G'B' in [0, 1],
        sRGB-encoded; ``recording`` its frame, time and stream facts) and the sha256 of the
        frame's decoded planes.
    """
    if matrix is not None and matrix not in MATRICES:
        raise unknown_name("--video-matrix", matrix, list(MATRICES))
    if range_ is not None and range_ not in RANGES:
        raise unknown_name("--video-range", range_, list(RANGES))
    if frame is not None and time is not None:
        raise InvalidValueError("--frame and --time both choose a frame; give one")
    p = Path(path)
    shown = display_path(p)
    av = _av(shown)
    with _open_video(p, shown) as (container, stream, rate):
        cc = stream.codec_context
        codec = str(cc.name)
        time_base = Fraction(stream.time_base)
        start = int(stream.start_time or 0)
        frames = _frame_count(container, stream, time_base, rate)
        if time is not None:
            if not math.isfinite(time) or time < 0:
                raise InputFileError(f"{shown}: --time {time:g} s is before the first frame "
                                     "(0 s)")
            last_s = (frames - 1) / rate
            if time > float(frames / rate):
                raise InputFileError(f"{shown}: --time {time:g} s is after the last frame "
                                     f"({float(last_s):.3f} s)")
            index = min(round(time * rate), frames - 1)
        else:
            index = 0 if frame is None else frame
            if index < 0:
                index += frames
            if not 0 <= index < frames:
                raise InputFileError(f"{shown}: frame {frame} is out of range (the video has "
                                     f"{frames} frames: 0 to {frames - 1})")
        width, height = int(cc.width), int(cc.height)
        limit = pixel_limit(max_pixels)
        if width * height > limit:
            raise InputFileError(f"{shown}: {width}x{height} pixels is more than the limit "
                                 f"of {limit} (--max-pixels)")
        try:
            got = _decode_to(container, stream, index, start, time_base, rate)
        except av.error.FFmpegError as exc:
            raise InputFileError(f"{shown}: frame {index}: codec {codec} cannot be decoded "
                                 f"({_reason(exc)})") from None
        if got is None:
            raise InputFileError(f"{shown}: frame {index} is out of range (the video's frames "
                                 f"end before it; {frames} counted from its header)")
        planes = _planes(got, shown)
        facts, pixels = _convert(got, planes, matrix, range_, shown)
        pts_s = float((int(got.pts) - start) * time_base)
        desc = stream.codec.long_name if stream.codec is not None else codec
    digest = hashlib.sha256()
    for plane in planes.planes:
        digest.update(np.ascontiguousarray(plane).tobytes())
    facts["codec"] = _CODEC_NAMES.get(codec, codec)
    facts["codec_name"] = str(desc)
    facts["pix_fmt"] = str(got.format.name)
    record = Recording(kind="video", topic=f"stream {stream.index}",
                       message_type=facts["codec"], ros_encoding=facts["pix_fmt"],
                       frame=index, frames=frames, time_ns=round(pts_s * 1e9), offset_s=pts_s,
                       stream=facts)
    pixel_type = "uint8" if planes.bits == 8 else "uint16"
    image = Image(pixels=pixels, path=p, file_format="video", pixel_type=pixel_type,
                  channels=("R", "G", "B"), layer=None, encoding="srgb",
                  all_channels=("R", "G", "B"), recording=record,
                  chromaticities=PRIMARIES.get(facts["primaries"]))
    return image, digest.hexdigest()


def frame_count(path: str | os.PathLike[str]) -> int:
    """The number of frames of the video at ``path``'s first video stream, from its header (or
    its duration times its frame rate); no frame is decoded (``audit --frames``). Errors as
    :func:`read_frame`'s: not a video, no video stream, no frame rate."""
    p = Path(path)
    shown = display_path(p)
    with _open_video(p, shown) as (container, stream, rate):
        return _frame_count(container, stream, Fraction(stream.time_base), rate)


@contextmanager
def _open_video(p: Path, shown: str) -> Iterator[tuple[Any, Any, Fraction]]:
    """The open container of the video at ``p`` (``shown`` in messages), its first video
    stream and that stream's frame rate; closed on leaving. Not a file, not a video (FFmpeg
    cannot open it, reads it as an image, or finds no video stream) or no frame rate: an
    :class:`~fidelity.core.errors.InputFileError`."""
    av = _av(shown)
    if not p.is_file():
        raise InputFileError(f"{shown}: no such file")
    try:
        container = av.open(str(p))
    except Exception as exc:  # PyAV raises its own error types for every kind of bad file
        raise InputFileError(f"{shown}: not a video ({_reason(exc)})") from None
    with container:
        demuxer = str(container.format.name)
        if demuxer.endswith("_pipe") or demuxer.startswith("image2"):
            raise InputFileError(f"{shown}: not a video (FFmpeg reads it as an image, "
                                 f"{demuxer})")
        if not container.streams.video:
            raise InputFileError(f"{shown}: not a video (no video stream)")
        stream = container.streams.video[0]
        rate = stream.average_rate or stream.guessed_rate
        if not rate:
            raise InputFileError(f"{shown}: the video stream has no frame rate")
        yield container, stream, Fraction(rate)


def _frame_count(container: Any, stream: Any, time_base: Fraction, rate: Fraction) -> int:
    """The stream's frame count: its header's, else from its (or the file's) duration."""
    if stream.frames:
        return int(stream.frames)
    if stream.duration:
        return max(1, round(Fraction(int(stream.duration)) * time_base * rate))
    if container.duration:
        return max(1, round(Fraction(int(container.duration), 1_000_000) * rate))
    return 1


def _convert(frame: Any, planes: Planes, matrix: str | None, range_: str | None, shown: str
             ) -> tuple[dict[str, str], np.ndarray]:
    """The frame's stream facts (matrix, range, primaries, transfer, which were assumed) and
    its R'G'B' pixels."""
    transfer = _AV_TRANSFER.get(int(frame.color_trc), str(int(frame.color_trc)))
    if transfer in _HDR_TRANSFERS:
        raise InputFileError(f"{shown}: transfer {transfer} (HDR) is not read; only SDR "
                             "video (BT.709, sRGB, BT.601, BT.2020 SDR transfers)")
    primaries = _AV_PRIMARIES.get(int(frame.color_primaries),
                                  str(int(frame.color_primaries)))
    if primaries not in _SRGB_PRIMARIES and primaries not in PRIMARIES:
        raise InputFileError(f"{shown}: primaries {primaries} are not read (bt709, "
                             f"{', '.join(PRIMARIES)})")
    facts = {"primaries": primaries, "transfer": transfer}
    assumed: list[str] = []
    if planes.kind == "rgb":
        facts["matrix"] = "rgb"
        facts["range"] = "full"
        top = np.float32(1.0 / (2 ** planes.bits - 1))
        pixels = np.stack(planes.planes, axis=-1).astype(np.float32) * top
    else:
        y, cb, cr = planes.planes
        h, w = y.shape
        tag_m = _AV_MATRIX.get(int(frame.colorspace))
        if matrix is not None:
            used_m = matrix
        elif tag_m is not None:
            used_m = tag_m
        else:
            if int(frame.colorspace) not in (2, 0):
                raise InputFileError(
                    f"{shown}: matrix {_AV_MATRIX_NAME.get(int(frame.colorspace), '?')} is not "
                    "read (bt601, bt709, bt2020; give --video-matrix)")
            used_m = "bt709" if h >= HD_LINES else "bt601"
            assumed.append("matrix")
        name = str(frame.format.name)
        tag_r = "full" if name.startswith("yuvj") else _AV_RANGE.get(int(frame.color_range))
        if range_ is not None:
            used_r = range_
        elif tag_r is not None:
            used_r = tag_r
        else:
            used_r = "limited"
            assumed.append("range")
        facts["matrix"], facts["range"] = used_m, used_r
        pixels = ycbcr_to_rgb(y, upsample(cb, h, w), upsample(cr, h, w), bits=planes.bits,
                              matrix=used_m, range_=used_r)
    facts["bits"] = str(planes.bits)
    facts["assumed"] = ", ".join(assumed)
    return facts, pixels


def _reason(exc: BaseException) -> str:
    strerror = getattr(exc, "strerror", None)
    if strerror:
        return str(strerror)
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


__all__ = [
    "MATRICES",
    "PRIMARIES",
    "RANGES",
    "VIDEO_SUFFIXES",
    "frame_count",
    "is_video_path",
    "read_frame",
    "upsample",
    "ycbcr_to_rgb",
]
