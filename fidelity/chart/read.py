"""Read an image or a recording's frame for measuring its chart, as :class:`ReadOptions` say.

An image file is read by :func:`fidelity.chart.image.read_image` (EXR layers and chromaticities,
camera raw mosaics demosaiced), a robot recording's message by
:func:`fidelity.chart.recording.read_frame`, and pixels in an OpenColorIO colourspace are
converted by :mod:`fidelity.chart.ocio`. Errors name the file.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from fidelity.chart import recording, video
from fidelity.chart.bayer import BAYER_MARGIN, bayer_pattern
from fidelity.chart.image import Image, ImageInfo, OneChannelError, as_float32, read_image
from fidelity.chart.ocio import convert
from fidelity.chart.recording import is_recording_path
from fidelity.core.errors import FidelityError, InvalidValueError
from fidelity.core.fileio import file_sha256
from fidelity.core.record import record

F64 = NDArray[np.float64]


@record
class ReadOptions:
    """How an image's pixels are read for measuring its chart (``audit``, ``gate``,
    ``compare`` and their library functions take one as ``read=``).

    Attributes
    ----------
    layer
        EXR layer or part name (None: the first RGB layer).
    encoding
        ``linear`` or ``srgb``; None: the file's likely encoding (linear for floating-point
        pixels: EXR, HDR, float TIFF; sRGB for integer pixels: PNG, JPEG, 8/16-bit TIFF).
    exposure
        ``"auto"`` (fitted on the neutral patches), a fixed EV, or None: auto for linear
        pixels, 0 for sRGB-encoded ones.
    negatives
        Pixels with a negative channel: ``keep`` them in the linear mean or ``exclude`` them
        like NaN/Inf (:data:`NEGATIVE_RULES`).
    colourspace
        RGB primaries of the pixels (a colour-science name); None: the EXR's
        ``chromaticities`` attribute, else sRGB.
    bayer
        CFA pattern of a one-channel camera raw mosaic (``RGGB``, ``BGGR``, ``GRBG``,
        ``GBRG``): demosaiced, taken as linear (:func:`fidelity.chart.image.read_image`).
    max_pixels
        Refuse a larger image (width x height) before decoding it; None:
        :func:`fidelity.chart.image.pixel_limit`.
    ocio_colourspace
        The pixels are in this colourspace of an OpenColorIO config (``ocio_config``):
        OpenColorIO converts them to linear or display sRGB (:mod:`fidelity.chart.ocio`);
        instead of ``encoding`` and ``colourspace``.
    ocio_config
        The OpenColorIO config of ``ocio_colourspace``: a file or an ``ocio://`` URI; None:
        ``$OCIO``, else OpenColorIO's built-in default config.
    topic
        The input is a robot recording (ROS 1 bag, ROS 2 bag, MCAP file:
        :mod:`fidelity.chart.recording`): the image topic (None: its only image topic).
    frame
        The message's index on ``topic`` (negative from the end); with neither ``frame``
        nor ``time``: the first message.
    time
        The message nearest to ``time``: seconds after the recording's first message, or an
        absolute time as text (:func:`fidelity.chart.recording.absolute_time_ns`); for a
        video, seconds after its first frame.
    video_matrix
        A video's Y'CbCr matrix (``bt601``, ``bt709``, ``bt2020``) instead of its stream's tag
        (:mod:`fidelity.chart.video`).
    video_range
        A video's Y'CbCr range (``limited``, ``full``) instead of its stream's tag.
    """

    layer: str | None = None
    encoding: str | None = None
    exposure: float | str | None = None
    negatives: str = "keep"
    colourspace: str | None = None
    bayer: str | None = None
    max_pixels: int | None = None
    topic: str | None = None
    frame: int | None = None
    #: seconds after the recording's first message, or an absolute time (text:
    #: :func:`fidelity.chart.recording.absolute_time_ns`)
    time: float | str | None = None
    ocio_colourspace: str | None = None
    ocio_config: str | None = None
    video_matrix: str | None = None
    video_range: str | None = None

    def given(self) -> list[str]:
        """The options set away from their defaults that describe the pixels of an image
        (``layer``, ``encoding``, ``exposure``, ``bayer``, ``colourspace``, ``topic``,
        ``frame``, ``time``, ``ocio_colourspace``, ``ocio_config``), by name."""
        return [name for name in ("layer", "encoding", "exposure", "bayer", "colourspace",
                                  "topic", "frame", "time", "ocio_colourspace", "ocio_config",
                                  "video_matrix", "video_range")
                if getattr(self, name) is not None]

    def names_message(self) -> bool:
        """Whether these options name a message of a recording or a frame of a video
        (``topic``, ``frame`` or ``time`` given)."""
        return any(v is not None for v in (self.topic, self.frame, self.time))


#: Every image-reading option at its default.
DEFAULT_READ = ReadOptions()


def read_input(path: str | os.PathLike[str], read: ReadOptions = DEFAULT_READ, *,
               native: bool = False) -> tuple[Image, str]:
    """Read an image file (:func:`fidelity.chart.image.read_image`; ``native``: 8/16-bit codes
    and half floats kept as they are) or, for a recording (a ``.bag``, ``.mcap`` or ``.db3``
    file, a folder, or ``topic``/``frame``/``time`` given), the message ``read`` names
    (:func:`fidelity.chart.recording.read_frame`). Returns the image and a sha256: the file's,
    or the message's serialised bytes'."""
    image, sha256 = _read_input(path, read, digest=True, native=native)
    assert sha256 is not None
    return image, sha256


def reads_for(paths: Sequence[str | os.PathLike[str]], read: ReadOptions
              ) -> list[ReadOptions]:
    """How each of several inputs is read: ``read``'s recording options (``topic``, ``frame``,
    ``time``) go to the inputs that are recordings by their form (a folder, a ``.bag``,
    ``.mcap`` or ``.db3`` file: :func:`fidelity.chart.recording.is_recording_path`), the other
    options to all; when none looks like a recording, all get them (and the reader says which
    input is not one)."""
    if not read.names_message():
        return [read for _ in paths]
    plain = replace(read, topic=None, frame=None, time=None)
    is_rec = [is_recording_path(p) or video.is_video_path(p) for p in paths]
    if not any(is_rec):
        return [read for _ in paths]
    return [read if r else plain for r in is_rec]


def reads_with_own_ocio(paths: Sequence[str | os.PathLike[str]], read: ReadOptions,
                        ocio_colourspaces: Sequence[str | None]) -> list[ReadOptions]:
    """:func:`reads_for`, then each input that names its own OpenColorIO colourspace
    (``--sim-ocio-colourspace``, ``--real-ocio-colourspace``) read in it: it replaces the
    shared ``ocio_colourspace``, and the shared ``encoding`` and ``colourspace`` (which then
    describe the other inputs) are left out for it."""
    return [r if own is None else replace(r, ocio_colourspace=own, encoding=None,
                                          colourspace=None)
            for r, own in zip(reads_for(paths, read), ocio_colourspaces, strict=True)]


def _read_input(path: str | os.PathLike[str], read: ReadOptions, *, digest: bool,
                native: bool = False) -> tuple[Image, str | None]:
    _check_ocio_options(read)
    if video.is_video_path(path):
        return _read_video(path, read)
    if read.video_matrix is not None or read.video_range is not None:
        raise InvalidValueError(f"{path}: --video-matrix and --video-range describe a video "
                                f"(a file ending in {', '.join(video.VIDEO_SUFFIXES)})")
    if read.names_message() or recording.is_recording_path(path):
        if read.layer is not None:
            raise InvalidValueError(f"{path}: --layer names an EXR layer; a recording has none")
        img, sha = recording.read_frame(
            path, recording.Choice(read.topic, read.frame, read.time), bayer=read.bayer,
            max_pixels=read.max_pixels)
        return _ocio_converted(img, read), sha

    try:
        img = read_image(path, layer=read.layer, bayer=read.bayer, max_pixels=read.max_pixels,
                         native=native)
    except OneChannelError as exc:
        if read.bayer is not None:
            raise
        img = _read_mosaic(path, read, exc)
    return _ocio_converted(img, read), (file_sha256(img.path) if digest else None)


def _read_video(path: str | os.PathLike[str], read: ReadOptions) -> tuple[Image, str]:
    """A video's frame (:func:`fidelity.chart.video.read_frame`) as ``read`` names it."""
    for name in ("layer", "topic", "bayer"):
        if getattr(read, name) is not None:
            raise InvalidValueError(f"{path}: --{name} does not apply to a video")
    time = read.time
    if isinstance(time, str):
        raise InvalidValueError(f"{path}: --time {time}: give seconds after the video's first "
                                "frame (a number)")
    img, sha = video.read_frame(path, read.frame, time, read.video_matrix, read.video_range,
                                max_pixels=read.max_pixels)
    return _ocio_converted(img, read), sha


def _check_ocio_options(read: ReadOptions) -> None:
    """``--ocio-colourspace`` says what ``--encoding`` and ``--colourspace`` say, and more;
    ``--ocio-config`` needs it."""
    if read.ocio_colourspace is None:
        if read.ocio_config is not None:
            raise InvalidValueError(f"--ocio-config {read.ocio_config}: give the pixels' "
                                    "colourspace in it with --ocio-colourspace NAME")
        return
    both = [f"--{name}" for name in ("encoding", "colourspace")
            if getattr(read, name) is not None]
    if both:
        raise InvalidValueError(f"--ocio-colourspace {read.ocio_colourspace}: names the pixels' "
                                f"encoding and primaries; leave out {' and '.join(both)}")


def _ocio_converted(img: Image, read: ReadOptions) -> Image:
    """The image with its pixels converted from ``read.ocio_colourspace`` by OpenColorIO
    (:func:`fidelity.chart.ocio.convert`), or as it is when none is given."""
    if read.ocio_colourspace is None:
        return img

    try:
        # the image is this function's own: converted in place (as_float32 copies codes)
        pixels, how = convert(as_float32(img.pixels), read.ocio_colourspace, read.ocio_config,
                              copy=False)
    except FidelityError as exc:
        raise type(exc)(f"{img.where}: {exc}") from None
    return replace(img, pixels=pixels, encoding=how.encoding, chromaticities=None, ocio=how)


#: Smallest side (pixels) of a one-channel image in which a chart is looked for without --bayer.
MIN_MOSAIC_SIDE = 24


def _read_mosaic(path: str | os.PathLike[str], read: ReadOptions, error: OneChannelError
                 ) -> Image:
    """A one-channel image read without ``--bayer``: the CFA pattern the chart in it fits
    unambiguously (:func:`fidelity.chart.bayer.bayer_pattern`), or ``error`` (the reader's
    message that names ``--bayer``) with how the four patterns fit."""
    # the demosaiced image keeps every sample of the mosaic at its site: take them back
    try:
        first = read_image(path, layer=read.layer, bayer="RGGB", max_pixels=read.max_pixels)
    except (IndexError, ValueError):  # the demosaicing refuses a mosaic of a few pixels
        raise OneChannelError(f"{error} (too small to look for a chart in it)") from None
    px = first.pixels
    if min(px.shape[:2]) < MIN_MOSAIC_SIDE:
        raise OneChannelError(f"{error} (too small to look for a chart in it)")
    mosaic = np.empty(px.shape[:2], np.float32)
    mosaic[0::2, 0::2] = px[0::2, 0::2, 0]
    mosaic[0::2, 1::2] = px[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = px[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = px[1::2, 1::2, 2]
    fit = bayer_pattern(mosaic)
    if fit.pattern is None:
        raise OneChannelError(
            f"{error} (no CFA pattern fits a 24-patch chart in it unambiguously, by a lead of "
            f"{BAYER_MARGIN:g} in confidence: {fit.describe()})") from None
    img = first if fit.pattern == "RGGB" else read_image(
        path, layer=read.layer, bayer=fit.pattern, max_pixels=read.max_pixels)
    return replace(img, bayer_found=True)


def read_again(info: ImageInfo, max_pixels: int | None = None) -> Image:
    """The image an audit described by ``info`` read again as it was read (the same file, layer
    and Bayer pattern, or the same message of the same recording; converted by OpenColorIO as
    it was), for a report that shows or checks its pixels."""
    rec = info.recording
    if rec is not None and rec.stream is not None:  # a video: the same frame, matrix, range
        again = ReadOptions(max_pixels=max_pixels, frame=rec.frame,
                            video_matrix=None if rec.stream["matrix"] == "rgb"
                            else rec.stream["matrix"],
                            video_range=None if rec.stream["matrix"] == "rgb"
                            else rec.stream["range"])
    elif rec is not None:
        again = ReadOptions(bayer=info.bayer, max_pixels=max_pixels, topic=rec.topic,
                            frame=rec.frame)
    else:
        again = ReadOptions(layer=info.layer, bayer=info.bayer, max_pixels=max_pixels)
    if info.ocio is not None:
        again = replace(again, ocio_colourspace=info.ocio.colourspace,
                        ocio_config=info.ocio.config)
    return _read_input(info.path, again, digest=False)[0]


__all__ = [
    "DEFAULT_READ",
    "ReadOptions",
    "read_again",
    "read_input",
    "reads_for",
    "reads_with_own_ocio",
]
