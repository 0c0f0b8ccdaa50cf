"""Read chart images: OpenEXR (half/float, any channel naming, layers and parts), Radiance HDR,
TIFF and PNG (8/16 bit, float TIFF), JPEG, through OpenImageIO.

Every image comes back as an ``(H, W, 3)`` float32 array of R, G, B plus the facts needed to
interpret it: the file format, its pixel type, the channels that were used and whether the values
are most likely scene-linear (floating-point formats: EXR, HDR, float TIFF) or display-encoded
sRGB (integer formats, normalised by OpenImageIO to [0, 1]: ``v / (2**bits - 1)``).

Channel naming: a colour channel is recognised by the last dot-separated component of its name,
case-insensitively: ``R``/``red``, ``G``/``green``, ``B``/``blue`` (so ``R``, ``diffuse.R``,
``beauty.red`` all work). Layers are the dot prefixes (``diffuse`` in ``diffuse.R``) and, in
multi-part EXR files, the part names. Without ``layer`` the unprefixed ``R, G, B`` are used;
if there are none and exactly one layer has all three, that layer is used.

Camera raw frames: a one-channel image holding a Bayer colour filter array mosaic (16-bit or
float PNG/TIFF, e.g. what ``dcraw -D -4 -T`` writes from a DNG or other raw file) is read with
``bayer`` (the CFA pattern of its top-left 2 x 2 pixels, :data:`BAYER_PATTERNS`) and demosaiced
by Malvar, He & Cutler's gradient-corrected linear interpolation (ICASSP 2004) as
colour-demosaicing implements it (``demosaicing_CFA_Bayer_Malvar2004``). Its values are taken as
linear (sensor data; black level already subtracted; camera RGB: give ``--colourspace`` for a
colour-accurate audit). Without ``bayer`` a one-channel image is an error that names the option
(:class:`OneChannelError`; an audit then tries the four patterns itself:
:func:`fidelity.chart.bayer.bayer_pattern`).

Errors (all :class:`fidelity.core.errors.InputFileError`, naming the file): missing, not an image,
truncated or corrupt, one colour channel only (greyscale), channels that are not R, G, B,
an unknown layer or an ambiguous choice of layers.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import math
import os
import re
import tempfile
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.chart.ocio import OcioConversion
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import atomic_output, display_path, require_file, write_error
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.chart.ocio import OcioConversion


class OneChannelError(InputFileError):
    """A one-channel image read without a CFA pattern (a greyscale image, or a camera raw
    mosaic whose pattern was not given)."""


#: Bayer colour filter array patterns (colours of the top-left 2 x 2 pixels, row by row).
BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
#: The demosaicing method used for Bayer mosaics.
DEMOSAICING = "Malvar 2004 (colour-demosaicing)"

#: Pixel types that hold scene-linear data by convention.
FLOAT_PIXEL_TYPES = frozenset({"half", "float", "double"})

#: Largest image :func:`read_image` decodes unless told otherwise, in pixels (width x height),
#: checked from the file's header before any pixel is decoded. An audit holds the image at its
#: decoded depth (3 bytes per pixel for an 8-bit photo, 6 for 16-bit or half, 12 for float)
#: plus about one byte per pixel for the chart finder's reduced copies: measured for 8-bit
#: JPEGs (``benchmarks/speed/memory.py``), 3.1 MB per megapixel above the program's 170 MB
#: between 24 and 108 megapixels (630 MB at 108). A Bayer mosaic is demosaiced in float64
#: (about 60 bytes per pixel). 150 megapixels (a 14142 x 10607 photo, more than any camera
#: sold) then take under 1 GB as an 8-bit photo, about 2 GB as float.
DEFAULT_MAX_PIXELS = 150_000_000

#: Environment variable that sets the pixel limit (like ``--max-pixels``).
MAX_PIXELS_ENV = "FIDELITY_MAX_PIXELS"

#: Most parts (subimages) of a file that are looked at for R, G, B channels.
MAX_PARTS = 1024

#: Pixel types kept as they are when an image is read at its native depth (``native=True``):
#: unsigned integer codes (normalised by :func:`as_float32` when used) and half floats.
NATIVE_PIXEL_TYPES = {"uint8": np.uint8, "uint16": np.uint16, "half": np.float16}


def is_coded(values: np.ndarray) -> bool:
    """Whether ``values`` are 8- or 16-bit unsigned integer codes (an image read at its native
    depth), which stand for ``code / (2**bits - 1)``."""
    return values.dtype in (np.uint8, np.uint16)


def as_float32(values: np.ndarray) -> np.ndarray:
    """``values`` as float32 of the scale :func:`read_image` gives: 8- and 16-bit unsigned
    codes (:func:`is_coded`) times ``1 / (2**bits - 1)`` in single precision, as OpenImageIO
    converts them (so the result equals the float read bit for bit), other values as they are
    (no copy for float32)."""
    a = np.asarray(values)
    if is_coded(a):  # one pass: each code converted to float32, then scaled in float32
        out: np.ndarray = np.multiply(a, np.float32(1.0 / np.iinfo(a.dtype).max),
                                      dtype=np.float32)
        return out
    return a.astype(np.float32, copy=False)

_COLOUR_NAMES = {
    "r": "R", "red": "R",
    "g": "G", "green": "G",
    "b": "B", "blue": "B",
}
_ALPHA_NAMES = {"a", "alpha"}


def utc_text(time_ns: int) -> str:
    """Nanoseconds since the UNIX epoch as ISO 8601 UTC text to the nanosecond
    (``2023-11-14T22:13:20.250000000Z``)."""
    utc = datetime.datetime.fromtimestamp(time_ns // 10**9, datetime.UTC)
    return utc.strftime("%Y-%m-%dT%H:%M:%S") + f".{time_ns % 10**9:09d}Z"


#: Tag names as :meth:`Recording.describe` says them.
_TAG_WORDS = {"bt601": "BT.601", "bt709": "BT.709", "bt2020": "BT.2020", "srgb": "sRGB",
              "smpte170m": "BT.601", "bt2020-10": "BT.2020", "bt2020-12": "BT.2020",
              "bt470bg": "BT.470 B/G", "smpte240m": "SMPTE 240M", "p3-d65": "Display P3"}


@record
class Recording:
    """Where in a robot recording an image message was read (:mod:`fidelity.chart.recording`):
    the recording's ``kind`` (``ROS 1 bag``, ``ROS 2 bag (sqlite3)``, ``ROS 2 bag (MCAP)``,
    ``MCAP file``), the ``topic``, the ``message_type``
    (``sensor_msgs/msg/Image`` or ``sensor_msgs/msg/CompressedImage``), its ``ros_encoding``
    (the Image's ``encoding`` or the CompressedImage's ``format``), the message's index among
    the topic's messages in time order (``frame``, 0-based) of ``frames``, its log time
    (``time_ns``, nanoseconds since the Unix epoch) and ``offset_s`` (seconds after the
    recording's first message), and its header's ``stamp_ns`` and ``frame_id``."""

    kind: str
    topic: str
    message_type: str
    ros_encoding: str
    frame: int
    frames: int
    time_ns: int
    offset_s: float
    stamp_ns: int | None = None
    frame_id: str | None = None
    #: a video's stream facts (:mod:`fidelity.chart.video`): ``codec``, ``pix_fmt``,
    #: ``matrix``, ``range``, ``primaries``, ``transfer``, ``bits`` and ``assumed`` (the
    #: names of the tags assumed, comma-separated); None for a robot recording
    stream: dict[str, str] | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form (``time_utc``: ``time_ns`` as ISO 8601 UTC text, :func:`utc_text`)."""
        text = utc_text(self.time_ns)
        return {"kind": self.kind, "topic": self.topic, "message_type": self.message_type,
                "ros_encoding": self.ros_encoding, "frame": self.frame, "frames": self.frames,
                "time_ns": self.time_ns, "time_utc": text, "offset_s": self.offset_s,
                "stamp_ns": self.stamp_ns, "frame_id": self.frame_id,
                **({} if self.stream is None else {"stream": dict(self.stream)})}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Recording:
        """Inverse of :meth:`to_json`."""
        stamp = data.get("stamp_ns")
        stream = data.get("stream")
        return cls(str(data["kind"]), str(data["topic"]), str(data["message_type"]),
                   str(data["ros_encoding"]), int(data["frame"]), int(data["frames"]),
                   int(data["time_ns"]), float(data["offset_s"]),
                   None if stamp is None else int(stamp), data.get("frame_id"),
                   None if stream is None else {str(k): str(v) for k, v in stream.items()})

    def describe(self) -> str:
        """One line: topic, frame, time and message (``/cam frame 3 of 40 at 1.234 s ...``); for
        a video, frame, time and stream (``frame 0 of 3 at 0.000 s (H.264 yuv420p, BT.709
        matrix, limited range, BT.709 transfer)``)."""
        s = self.stream
        if s is not None:
            assumed = f" ({s['assumed']} assumed)" if s.get("assumed") else ""
            matrix = "RGB" if s["matrix"] == "rgb" else \
                f"{_TAG_WORDS.get(s['matrix'], s['matrix'])} matrix, {s['range']} range"
            prim = s.get("primaries", "bt709")
            primaries = ("" if prim in ("bt709", "unspecified") else
                         f", {_TAG_WORDS.get(prim, prim)} primaries converted to sRGB's")
            return (f"frame {self.frame} of {self.frames} at {self.offset_s:.3f} s "
                    f"({s['codec']} {s['pix_fmt']}, {matrix}, "
                    f"{_TAG_WORDS.get(s['transfer'], s['transfer'])} transfer{primaries}"
                    f"{assumed})")
        return (f"topic {self.topic} frame {self.frame} of {self.frames} at "
                f"{self.offset_s:.3f} s ({self.message_type.rsplit('/', 1)[-1]} "
                f"{self.ros_encoding})")


@record
class Image:
    """An image read from disk.

    ``pixels`` is ``(H, W, 3)`` float32 R, G, B (or, read with ``native=True``, the file's own
    8/16-bit codes or half floats: :func:`as_float32` gives the float32 values). Integer
    formats are normalised to [0, 1] by ``v / (2**bits - 1)``; floating-point formats keep
    their values (NaN, Inf and negative values
    included: the audit counts and excludes them). ``encoding`` is the likely encoding of the
    values: ``"linear"`` for floating-point pixel types, ``"srgb"`` otherwise.
    ``chromaticities`` is OpenEXR's standard attribute of the same name when the file has it:
    ``Rx, Ry, Gx, Gy, Bx, By, Wx, Wy`` of the RGB primaries and white (CIE 1931 xy).
    """

    pixels: np.ndarray
    path: Path
    file_format: str
    pixel_type: str
    channels: tuple[str, str, str]
    layer: str | None
    encoding: str
    colorspace: str | None = None
    all_channels: tuple[str, ...] = field(default_factory=tuple)
    chromaticities: tuple[float, ...] | None = None
    bayer: str | None = None
    recording: Recording | None = None
    bayer_found: bool = False
    #: how OpenColorIO converted the pixels (``--ocio-colourspace``), when it did
    ocio: OcioConversion | None = None

    @property
    def where(self) -> str:
        """What an error about this image names: the file, and for a recording's message its
        topic and frame (``drive.bag: topic /cam frame 3``)."""
        rec = self.recording
        if rec is None:
            return display_path(self.path)
        topic = "" if rec.stream is not None else f" topic {rec.topic}"
        return f"{display_path(self.path)}:{topic} frame {rec.frame}"

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return int(self.pixels.shape[0])

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return int(self.pixels.shape[1])

    def info(self, sha256: str | None = None, encoding: str | None = None) -> ImageInfo:
        """What the image is (without the pixels); ``sha256`` of the file and the ``encoding``
        it is measured in, when known."""
        return ImageInfo(
            path=str(self.path), format=self.file_format, pixel_type=self.pixel_type,
            width=self.width, height=self.height, channels=self.channels, layer=self.layer,
            encoding_guess=self.encoding, colorspace=self.colorspace,
            chromaticities=self.chromaticities, sha256=sha256, encoding=encoding,
            bayer=self.bayer, recording=self.recording, bayer_found=self.bayer_found,
            ocio=self.ocio,
        )


@record
class ImageInfo:
    """An image file as a report states it: ``path``, file ``format``, ``pixel_type``, size,
    the three ``channels`` used, ``layer``, the likely encoding (``encoding_guess``), OpenImageIO's
    ``colorspace`` and OpenEXR's ``chromaticities`` attributes, the file's ``sha256`` and the
    ``encoding`` it was measured in. An image read from a robot recording (``path`` the bag)
    has its :class:`Recording` (topic, frame, time), and ``sha256`` is that of the message's
    serialised bytes (the recording is not read whole)."""

    path: str
    format: str
    pixel_type: str
    width: int
    height: int
    channels: tuple[str, ...]
    layer: str | None
    encoding_guess: str
    colorspace: str | None = None
    chromaticities: tuple[float, ...] | None = None
    sha256: str | None = None
    encoding: str | None = None
    bayer: str | None = None
    recording: Recording | None = None
    bayer_found: bool = False
    ocio: OcioConversion | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form (keys in this order; ``sha256``, ``encoding``, ``bayer`` (with
        ``demosaicing`` and ``bayer_found``: the pattern was found by the chart, not given),
        ``recording`` and ``ocio`` (the OpenColorIO conversion) only when known)."""
        out: dict[str, Any] = {
            "path": self.path, "format": self.format, "pixel_type": self.pixel_type,
            "width": self.width, "height": self.height, "channels": list(self.channels),
            "layer": self.layer, "encoding_guess": self.encoding_guess,
            "colorspace": self.colorspace,
            "chromaticities": list(self.chromaticities) if self.chromaticities else None,
        }
        if self.sha256 is not None:
            out["sha256"] = self.sha256
        if self.encoding is not None:
            out["encoding"] = self.encoding
        if self.bayer is not None:
            out["bayer"] = self.bayer
            out["demosaicing"] = DEMOSAICING
            out["bayer_found"] = self.bayer_found
        if self.recording is not None:
            out["recording"] = self.recording.to_json()
        if self.ocio is not None:
            out["ocio"] = self.ocio.to_json()
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ImageInfo:
        """Inverse of :meth:`to_json`."""
        chroma = data.get("chromaticities")
        return cls(
            path=str(data["path"]), format=str(data["format"]),
            pixel_type=str(data["pixel_type"]), width=int(data["width"]),
            height=int(data["height"]), channels=tuple(data["channels"]),
            layer=data.get("layer"), encoding_guess=str(data["encoding_guess"]),
            colorspace=data.get("colorspace"),
            chromaticities=tuple(float(v) for v in chroma) if chroma else None,
            sha256=data.get("sha256"), encoding=data.get("encoding"), bayer=data.get("bayer"),
            recording=(Recording.from_json(data["recording"]) if data.get("recording")
                       else None),
            bayer_found=bool(data.get("bayer_found", False)),
            ocio=_ocio_from_json(data.get("ocio")),
        )


def _ocio_from_json(data: Mapping[str, Any] | None) -> OcioConversion | None:
    if not data:
        return None

    return OcioConversion(**{k: str(v) for k, v in data.items()})


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence C libraries (libpng, libjpeg) that print to file descriptor 2 while reading.

    Their messages are reported through OpenImageIO's error string instead, as one line.
    """
    try:
        saved = os.dup(2)
    except OSError:  # no usable fd 2: nothing to silence
        yield
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def _one_line(text: str) -> str:
    """Collapse a (possibly multi-line) library message into one line."""
    parts = [p.strip() for p in str(text).splitlines() if p.strip()]
    seen: list[str] = []
    for p in parts:
        if p not in seen:
            seen.append(p)
    return "; ".join(seen)


def _split_channel(name: str) -> tuple[str | None, str]:
    """``"diffuse.R"`` -> ``("diffuse", "R")``; ``"R"`` -> ``(None, "R")``."""
    if "." in name:
        prefix, last = name.rsplit(".", 1)
        return prefix, last
    return None, name


@record
class _Part:
    index: int
    name: str | None
    channels: tuple[str, ...]


def _rgb_of(channels: tuple[str, ...], prefix: str | None) -> dict[str, int]:
    """Indices of R, G, B among ``channels`` whose layer prefix is ``prefix``."""
    found: dict[str, int] = {}
    for idx, ch in enumerate(channels):
        pre, last = _split_channel(ch)
        if pre != prefix:
            continue
        key = _COLOUR_NAMES.get(last.lower())
        if key is not None and key not in found:
            found[key] = idx
    return found


def _layers_of(part: _Part) -> list[str | None]:
    prefixes: list[str | None] = []
    for ch in part.channels:
        pre, _ = _split_channel(ch)
        if pre not in prefixes:
            prefixes.append(pre)
    return prefixes


def _describe_channels(parts: list[_Part]) -> str:
    out = []
    for part in parts:
        names = ", ".join(part.channels)
        out.append(f"part {part.name!r}: {names}" if len(parts) > 1 else names)
    return "; ".join(out)


def _rgb_layers(parts: list[_Part]) -> list[str]:
    """Names of the layers that hold R, G, B (part names and channel prefixes)."""
    names: list[str] = []
    for part in parts:
        for pre in _layers_of(part):
            if len(_rgb_of(part.channels, pre)) == 3:
                label = pre if pre is not None else (part.name or "(unnamed: plain R, G, B)")
                if label not in names:
                    names.append(label)
    return names


def _choose(parts: list[_Part], layer: str | None, path: Path) -> tuple[_Part, str | None, dict[str, int]]:
    """Pick the part, the channel prefix and the R, G, B indices to read."""
    if layer is not None:
        for part in parts:  # a channel prefix
            rgb = _rgb_of(part.channels, layer)
            if len(rgb) == 3:
                return part, layer, rgb
        for part in parts:  # a part name: its unprefixed channels
            if part.name == layer:
                rgb = _rgb_of(part.channels, None)
                if len(rgb) == 3:
                    return part, None, rgb
        known = _rgb_layers(parts)
        raise InputFileError(
            f"{path}: no layer {layer!r} with R, G, B channels; layers with R, G, B: "
            f"{', '.join(known) if known else 'none'} (channels: {_describe_channels(parts)})"
        )
    for part in parts:
        rgb = _rgb_of(part.channels, None)
        if len(rgb) == 3:
            return part, None, rgb
    candidates = [(part, pre) for part in parts for pre in _layers_of(part)
                  if pre is not None and len(_rgb_of(part.channels, pre)) == 3]
    if len(candidates) == 1:
        part, pre = candidates[0]
        return part, pre, _rgb_of(part.channels, pre)
    if len(candidates) > 1:
        names = ", ".join(str(pre) for _, pre in candidates)
        raise InputFileError(f"{path}: several layers hold R, G, B ({names}); choose one with --layer")
    colour = [ch for part in parts for ch in part.channels
              if _split_channel(ch)[1].lower() not in _ALPHA_NAMES]
    if len(colour) == 1 or all(len([c for c in p.channels if _split_channel(c)[1].lower()
                                    not in _ALPHA_NAMES]) == 1 for p in parts):
        raise OneChannelError(
            f"{path}: one-channel image ({_describe_channels(parts)}); a colour chart needs "
            f"R, G, B: for a camera raw Bayer mosaic give --bayer "
            f"{'|'.join(BAYER_PATTERNS)} (its CFA pattern)"
        )
    raise InputFileError(
        f"{path}: unknown channels ({_describe_channels(parts)}); expected R, G, B "
        f"(or <layer>.R, <layer>.G, <layer>.B)"
    )


def _mosaic_channel(parts: list[_Part], path: Path, bayer: str) -> tuple[_Part, int]:
    """The part and index of the one channel of a Bayer mosaic (alpha ignored)."""
    colour = [(part, k) for part in parts for k, ch in enumerate(part.channels)
              if _split_channel(ch)[1].lower() not in _ALPHA_NAMES]
    if len(colour) != 1:
        raise InputFileError(
            f"{path}: --bayer {bayer} needs a one-channel mosaic, but the image has "
            f"{len(colour)} colour channels ({_describe_channels(parts)}); leave out --bayer")
    return colour[0]


def demosaic(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """``(H, W)`` Bayer mosaic -> ``(H, W, 3)`` float32 R, G, B (:data:`DEMOSAICING`).

    ``pattern`` names the colours of the top-left 2 x 2 pixels (:data:`BAYER_PATTERNS`).
    """
    with warnings.catch_warnings():  # it imports scipy.ndimage.filters, deprecated in SciPy
        warnings.simplefilter("ignore", DeprecationWarning)
        from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004

    rgb = demosaicing_CFA_Bayer_Malvar2004(np.asarray(mosaic, dtype=np.float64), pattern)
    return np.asarray(rgb, dtype=np.float32)


def pixel_limit(max_pixels: int | None = None) -> int:
    """The pixel limit in force: ``max_pixels`` when given, else the environment variable
    :data:`MAX_PIXELS_ENV`, else :data:`DEFAULT_MAX_PIXELS`. Raises
    :class:`~fidelity.core.errors.InvalidValueError` for a limit that is not a positive whole number
    (``2e8`` is read as 200000000)."""
    if max_pixels is not None:
        what, value = "--max-pixels", str(max_pixels)
    else:
        what, value = MAX_PIXELS_ENV, os.environ.get(MAX_PIXELS_ENV, "")
        if not value.strip():
            return DEFAULT_MAX_PIXELS
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and number >= 1 and number == int(number)):
        raise InvalidValueError(f"{what}={value}: expected a positive whole number of pixels, "
                                f"e.g. {DEFAULT_MAX_PIXELS}")
    return int(number)


def read_image(path: str | os.PathLike[str], layer: str | None = None,
               bayer: str | None = None, *, max_pixels: int | None = None,
               native: bool = False) -> Image:
    """Read an image as ``(H, W, 3)`` float32 R, G, B.

    Only the channels that hold R, G and B (or the mosaic) are decoded, as float32 (or at
    their native depth), so the pixels of an RGB image are held once.

    Parameters
    ----------
    path
        EXR, HDR, TIFF, PNG, JPEG or any other format OpenImageIO reads.
    layer
        EXR layer (channel prefix such as ``diffuse`` for ``diffuse.R``) or part name.
    bayer
        CFA pattern of a one-channel Bayer mosaic (:data:`BAYER_PATTERNS`): the mosaic is
        demosaiced (:func:`demosaic`) and taken as linear.
    max_pixels
        Refuse an image of more pixels (width x height) than this, from its header, before
        decoding it (:func:`pixel_limit`: default :data:`MAX_PIXELS_ENV` or
        :data:`DEFAULT_MAX_PIXELS`).
    native
        Keep 8- and 16-bit integer codes and half floats as they are in the file
        (:data:`NATIVE_PIXEL_TYPES`; 3 or 6 bytes per RGB pixel instead of 12) rather than
        float32; :func:`as_float32` of any part of them is what ``native=False`` gives.
        Bayer mosaics are demosaiced to float32 either way.

    Returns
    -------
    Image
        ``pixels`` of shape (H, W, 3), float32 (``native``: the file's own 8/16-bit codes or
        half floats): integer formats normalised to [0, 1] by ``v / (2**bits - 1)``,
        floating-point formats as stored (NaN, Inf and negative values kept); with the file's format, pixel type, channels, layer, likely ``encoding``
        (``linear`` for floating-point pixels, ``srgb`` otherwise) and EXR chromaticities.

    Raises
    ------
    InputFileError
        Missing, unreadable, truncated or corrupt file; one-channel image; channels that are not
        R, G, B; unknown or ambiguous layer; more pixels than the limit. The message names the
        file (a name that is not valid UTF-8 is read through a link of a plain name). Exit
        code 2.
    UnknownNameError
        A ``bayer`` pattern not in :data:`BAYER_PATTERNS`. Exit code 2.
    InvalidValueError
        A pixel limit (``max_pixels`` or :data:`MAX_PIXELS_ENV`) that is not a positive whole
        number. Exit code 2.
    """

    if bayer is not None and bayer.upper() not in BAYER_PATTERNS:
        raise unknown_name("--bayer pattern", bayer, BAYER_PATTERNS)
    bayer = bayer.upper() if bayer is not None else None
    limit = pixel_limit(max_pixels)
    p = require_file(path, "image")
    shown = display_path(p)
    try:
        if shown == str(p):
            return _read(p, layer, bayer, limit, native)
        return _read_through_link(p, shown, layer, bayer, limit, native)
    except UnicodeDecodeError:  # OpenImageIO passes on names and messages from the file
        raise InputFileError(f"{shown}: corrupt image (its header holds text that is not "
                             "UTF-8)") from None


def _read_through_link(p: Path, shown: str, layer: str | None, bayer: str | None,
                       limit: int, native: bool = False) -> Image:
    """:func:`_read` of a file whose name is not valid UTF-8 (OpenImageIO takes names as UTF-8
    text): through a symbolic link of a plain name in a temporary folder, the image's path and
    the messages naming the file itself."""
    suffix = "".join(c for c in p.suffix if c.isascii() and (c.isalnum() or c == "."))
    with tempfile.TemporaryDirectory(prefix="fidelity-") as folder:
        link = Path(folder) / f"image{suffix}"
        os.symlink(os.path.abspath(p), link)
        try:
            image = _read(link, layer, bayer, limit, native)
        except InputFileError as exc:
            raise InputFileError(str(exc).replace(str(link), shown)) from None
    return replace(image, path=p)


def stored_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """``(height, width)`` of the first part of the image file at ``path`` as stored (EXIF
    orientation ignored, as :func:`read_image` ignores it), from its header alone
    (OpenImageIO); None where the file cannot be opened or its name is not valid UTF-8. No
    error is raised: :func:`read_image` reports the file's problems."""
    import OpenImageIO as oiio

    p = Path(path)
    if display_path(p) != str(p) or not p.is_file():
        return None
    with _quiet_stderr():
        inp = oiio.ImageInput.open(str(p))
        if inp is None:
            oiio.geterror()  # clear it: the read reports the file's problem
            return None
        try:
            spec = inp.spec()
            return int(spec.height), int(spec.width)
        finally:
            inp.close()


#: OpenImageIO's pseudo-formats, never a frame on disk: their names are not image suffixes.
_PSEUDO_FORMATS = ("null", "term")


def image_suffixes() -> frozenset[str]:
    """The file suffixes (lower case, with the dot) of the formats OpenImageIO reads here
    (its ``extension_list``), without its pseudo-formats."""
    import OpenImageIO as oiio

    out: set[str] = set()
    for entry in str(oiio.get_string_attribute("extension_list")).split(";"):
        fmt, _, exts = entry.partition(":")
        if fmt not in _PSEUDO_FORMATS:
            out.update(f".{e.lower()}" for e in exts.split(",") if e)
    return frozenset(out)


def _natural_key(name: str) -> tuple[tuple[int, int | str], ...]:
    """``frame_2`` before ``frame_10``: runs of digits compare as numbers."""
    return tuple((0, int(part)) if part.isdigit() else (1, part)
                 for part in re.split(r"(\d+)", name) if part)


def folder_images(folder: str | os.PathLike[str]) -> list[Path]:
    """The image files directly in ``folder`` (suffixes of :func:`image_suffixes`; hidden
    files and sub-folders left out), in natural order of their names (``frame_2`` before
    ``frame_10``): the frames a renderer wrote."""
    suffixes = image_suffixes()
    found = [p for p in Path(folder).iterdir()
             if p.suffix.lower() in suffixes and not p.name.startswith(".") and p.is_file()]
    # the name itself breaks ties (frame_1 and frame_01): the order never depends on the disk's
    return sorted(found, key=lambda p: (_natural_key(p.name), p.name))


#: Pixels decoded at a time into the image's array (so that the decoder's own buffer stays
#: small: a whole-image read holds the image twice).
READ_BAND_PIXELS = 1 << 22


def _read_scanlines(inp: Any, spec: Any, part: int, chbegin: int, chend: int, fmt: str
                    ) -> np.ndarray | None:
    """The channels ``chbegin .. chend - 1`` of a scanline image, a band of rows at a time,
    into one ``(H, W, C)`` array of ``fmt``; None when a band cannot be read."""
    width, height = int(spec.width), int(spec.height)
    out: np.ndarray | None = None
    step = max(1, READ_BAND_PIXELS // max(width, 1))
    for y in range(0, height, step):
        rows = min(step, height - y)
        band = inp.read_scanlines(part, 0, spec.y + y, spec.y + y + rows, spec.z, chbegin,
                                  chend, fmt)
        if band is None:
            return None
        band = np.asarray(band)
        if out is None:
            out = np.empty((height, width, chend - chbegin), dtype=band.dtype)
        out[y:y + rows] = band.reshape(rows, width, chend - chbegin)
    return out


def _read(p: Path, layer: str | None, bayer: str | None, limit: int,
          native: bool = False) -> Image:
    """:func:`read_image` of a checked path."""
    import OpenImageIO as oiio

    with _quiet_stderr():
        inp = oiio.ImageInput.open(str(p))
        if inp is None:
            msg = _one_line(oiio.geterror()) or "unknown reason"
            raise InputFileError(f"{p}: cannot read image ({msg})")
        try:
            parts: list[_Part] = []
            k = 0
            while k < MAX_PARTS and inp.seek_subimage(k, 0):
                spec = inp.spec()
                name = spec.getattribute("name")
                parts.append(_Part(k, str(name) if name else None, tuple(spec.channelnames)))
                k += 1
            inp.geterror()  # seeking past the last part sets an error: clear it
            if bayer is not None:
                part, mosaic_index = _mosaic_channel(parts, p, bayer)
                prefix, rgb = None, {"R": mosaic_index, "G": mosaic_index, "B": mosaic_index}
            else:
                part, prefix, rgb = _choose(parts, layer, p)
            if not inp.seek_subimage(part.index, 0):
                raise InputFileError(f"{p}: cannot read part {part.index} ({_one_line(inp.geterror())})")
            spec = inp.spec()
            if spec.width < 1 or spec.height < 1:
                raise InputFileError(f"{p}: empty image ({spec.width}x{spec.height})")
            pixels_declared = int(spec.width) * int(spec.height) * max(int(spec.depth), 1)
            if pixels_declared > limit:
                raise InputFileError(
                    f"{p}: the image is {spec.width}x{spec.height} "
                    f"({pixels_declared / 1e6:.1f} megapixels), more than the limit of "
                    f"{limit / 1e6:g} megapixels; raise it with --max-pixels N or "
                    f"{MAX_PIXELS_ENV}=N if this machine has the memory (an audit needs "
                    "the decoded image plus about 1 byte per pixel: 4 for an 8-bit photo; 60 "
                    "for a Bayer mosaic)")
            first, last = min(rgb.values()), max(rgb.values())
            keep = native and bayer is None and str(spec.format) in NATIVE_PIXEL_TYPES
            fmt = str(spec.format) if keep else "float"
            if spec.tile_width == 0 and int(spec.depth) <= 1:
                data = _read_scanlines(inp, spec, part.index, first, last + 1, fmt)
            else:  # tiled or volume images: whole
                data = inp.read_image(part.index, 0, first, last + 1, fmt)
            err = _one_line(inp.geterror())
            if data is None or err:
                raise InputFileError(f"{p}: truncated or corrupt image ({err or 'read failed'})")
            file_format = str(inp.format_name())
            pixel_type = str(spec.format)
            colorspace = spec.getattribute("oiio:ColorSpace")
            chroma = spec.getattribute("chromaticities")
        finally:
            inp.close()
    arr = np.asarray(data) if keep else np.asarray(data, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim == 4:  # deep / volume: take the first slice
        arr = arr[0]
    order = [rgb["R"] - first, rgb["G"] - first, rgb["B"] - first]
    if bayer is not None:
        pixels = demosaic(arr[:, :, order[0]], bayer)
        channels = tuple(f"{part.channels[rgb['R']]} ({c} of {bayer})" for c in "RGB")
        encoding = "linear"
    else:
        if order == [0, 1, 2] and arr.shape[2] == 3:
            pixels = np.ascontiguousarray(arr)  # already R, G, B: no second copy
        else:
            pixels = np.ascontiguousarray(arr[:, :, order])
        channels = tuple(part.channels[rgb[c]] for c in ("R", "G", "B"))
        encoding = "linear" if pixel_type in FLOAT_PIXEL_TYPES else "srgb"
    return Image(
        pixels=pixels,
        path=p,
        file_format=file_format,
        pixel_type=pixel_type,
        channels=channels,  # type: ignore[arg-type]
        layer=prefix if prefix is not None else (part.name if layer is not None else None),
        encoding=encoding,
        colorspace=str(colorspace) if colorspace else None,
        all_channels=tuple(ch for prt in parts for ch in prt.channels),
        chromaticities=(tuple(float(v) for v in chroma)
                        if isinstance(chroma, (tuple, list)) and len(chroma) == 8 else None),
        bayer=bayer,
    )


def write_exr(path: str | os.PathLike[str], image: np.ndarray,
              content: str = "linear camera RGB (raw, after exposure/noise)") -> Path:
    """Write (H, W, 3) float32 RGB as a zip-compressed scanline EXR (channels R, G, B),
    atomically; ``content`` is stored in the ``fidelity:content`` attribute."""
    import OpenImageIO as oiio

    img = np.ascontiguousarray(image, dtype=np.float32)
    with atomic_output(path) as tmp, _plain_name(tmp) as name:
        out = oiio.ImageOutput.create("openexr")
        if out is None:
            raise InputFileError(f"{path}: cannot create EXR writer ({oiio.geterror()})")
        spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.FLOAT)
        spec.channelnames = ("R", "G", "B")
        spec.attribute("compression", "zip")
        spec.attribute("fidelity:content", content)
        if not out.open(name, spec):
            raise InputFileError(f"{path}: cannot write EXR ({out.geterror()})")
        _finish(out, out.write_image(img), path, "EXR")
    return Path(path)


def write_png(path: str | os.PathLike[str], image: np.ndarray, bits: int) -> Path:
    """Write (H, W, 3) encoded sRGB in [0, 1] as an 8- or 16-bit PNG, atomically."""
    import OpenImageIO as oiio

    if bits > 8:
        data, fmt = np.round(np.clip(image, 0, 1) * 65535).astype(np.uint16), oiio.UINT16
    else:
        data, fmt = np.round(np.clip(image, 0, 1) * 255).astype(np.uint8), oiio.UINT8
    with atomic_output(path) as tmp, _plain_name(tmp) as name:
        out = oiio.ImageOutput.create("png")
        spec = oiio.ImageSpec(data.shape[1], data.shape[0], 3, fmt)
        spec.attribute("oiio:ColorSpace", "sRGB")
        if out is None or not out.open(name, spec):
            raise InputFileError(f"{path}: cannot write PNG ({oiio.geterror()})")
        _finish(out, out.write_image(np.ascontiguousarray(data)), path, "PNG")
    return Path(path)


@contextlib.contextmanager
def _plain_name(path: Path) -> Iterator[str]:
    """A name OpenImageIO can open for ``path`` (it takes names as UTF-8 text): the path
    itself, or, when it is not valid UTF-8, a symbolic link of a plain name to it in a
    temporary folder."""
    if display_path(path) == str(path):
        yield str(path)
        return
    suffix = "".join(c for c in path.suffix if c.isascii() and (c.isalnum() or c == "."))
    with tempfile.TemporaryDirectory(prefix="fidelity-") as folder:
        link = Path(folder) / f"file{suffix}"
        os.symlink(os.path.abspath(path), link)
        yield str(link)


def _finish(out: Any, written: bool, path: str | os.PathLike[str], kind: str) -> None:
    """Close an OpenImageIO writer; a failed write or close (a full disk) is an error naming
    the output, so that :func:`fidelity.core.fileio.atomic_output` removes the partial file."""
    import OpenImageIO as oiio

    closed = out.close()
    if not (written and closed is not False):
        reason = _one_line(out.geterror() or oiio.geterror()) or "write failed"
        raise write_error(path, OSError(errno.EIO, f"{kind} writer: {reason}"))


__all__ = [
    "OneChannelError","BAYER_PATTERNS", "DEFAULT_MAX_PIXELS", "DEMOSAICING", "FLOAT_PIXEL_TYPES",
           "MAX_PIXELS_ENV", "NATIVE_PIXEL_TYPES", "Image", "ImageInfo", "Recording",
           "as_float32", "demosaic", "folder_images", "image_suffixes", "is_coded",
           "pixel_limit",
           "read_image", "write_exr", "write_png"]
