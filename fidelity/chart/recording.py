"""Read one image message of a robot recording: a ROS 1 bag, a ROS 2 bag (a folder with
``metadata.yaml``, sqlite3 or MCAP storage, or one of its ``.db3``/``.mcap`` files) or an MCAP
file (ROS 2 profile), through ``rosbags`` (``pip install 'camera-fidelity[ros]'``; no ROS
installation).

The message is chosen on a ``topic`` (default: the recording's only image topic) by its index
among the topic's messages in log-time order (``frame``, 0-based; negative counts from the end;
default the first) or by the time nearest to ``time`` seconds after the recording's first
message. Only the recording's index is read to find it (ROS 1 bag: the chunks' index records;
sqlite3: the timestamp column; MCAP: the chunks' message indexes), then the one message: a
frame of a large bag costs a few of its chunks, not the bag.

Messages (:func:`message_pixels`):

- ``sensor_msgs/Image``: ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``rgb16``, ``bgr16``,
  ``rgba16``, ``bgra16`` (integer codes normalised to [0, 1] by ``v / (2**bits - 1)`` as
  :func:`fidelity.chart.image.read_image` does for a PNG; likely sRGB-encoded), ``32FC3``,
  ``32FC4``, ``64FC3`` (floats as they are, channels taken as R, G, B; likely linear), the
  generic ``8UC3``/``16UC3`` (and 4-channel) codes taken as R, G, B; YUV 4:2:2 ``uyvy``
  (``yuv422``) and ``yuyv`` (``yuv422_yuy2``), and semi-planar YUV 4:2:0 ``nv12`` and ``nv21``
  (``height`` the picture's; the chroma rows follow the luma rows), converted by ITU-R BT.601
  in studio range to 8-bit R'G'B' as OpenCV (and so cv_bridge) converts them; ``bayer_rggb8`` and the
  other ``bayer_*`` 8/16-bit mosaics demosaiced (:func:`fidelity.chart.image.demosaic`, the
  pattern from the encoding; linear); one-channel ``mono8``, ``mono16``, ``8UC1``, ``16UC1``,
  ``32FC1`` images only as a Bayer mosaic of a pattern given (``bayer``), as for a one-channel
  PNG. Rows may be padded (``step``); big-endian data is swapped.
- ``sensor_msgs/CompressedImage``: JPEG or PNG (told by their bytes), decoded as the same file
  would be (:func:`fidelity.chart.image.read_image`); a ``bayer_*`` format names the pattern
  of a PNG-compressed mosaic.

Errors (:class:`fidelity.core.errors.InputFileError`, one line naming the recording): not a
recording, unreadable or damaged, no such topic (the image topics are listed), a topic that is
not an image, a frame or time outside the topic, an encoding not listed here, a Bayer mosaic
of odd size, a message shorter than its size says, more pixels than the limit.
"""

from __future__ import annotations

import bisect
import contextlib
import datetime as dt
import hashlib
import math
import os
import re
import struct
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import replace
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.chart.image import (
    BAYER_PATTERNS,
    Image,
    Recording,
    demosaic,
    pixel_limit,
    read_image,
    utc_text,
)
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import display_path
from fidelity.core.record import record

#: The extra that installs the recording reader.
EXTRA = "ros"
#: File name endings of recordings (a ROS 2 bag is also a folder with ``metadata.yaml``).
RECORDING_SUFFIXES = (".bag", ".mcap", ".db3")
#: Message types read as images.
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")

#: The first bytes of each kind of recording file, and the suffix its reader expects.
_MAGIC = ((b"#ROSBAG V2.0\n", ".bag"), (b"\x89MCAP0\r\n", ".mcap"),
          (b"SQLite format 3\x00", ".db3"))

#: Packed encodings: numpy type, channels, which of them are R, G, B.
_PACKED: dict[str, tuple[str, int, tuple[int, int, int]]] = {
    "rgb8": ("u1", 3, (0, 1, 2)), "bgr8": ("u1", 3, (2, 1, 0)),
    "rgba8": ("u1", 4, (0, 1, 2)), "bgra8": ("u1", 4, (2, 1, 0)),
    "rgb16": ("u2", 3, (0, 1, 2)), "bgr16": ("u2", 3, (2, 1, 0)),
    "rgba16": ("u2", 4, (0, 1, 2)), "bgra16": ("u2", 4, (2, 1, 0)),
    "mono8": ("u1", 1, (0, 0, 0)), "mono16": ("u2", 1, (0, 0, 0)),
}
#: YUV 4:2:2 encodings: the byte offsets of Y0, U, Y1, V in each 4-byte pair of pixels.
_YUV422 = {"uyvy": (1, 0, 3, 2), "yuv422": (1, 0, 3, 2), "yuyv": (0, 1, 2, 3),
           "yuv422_yuy2": (0, 1, 2, 3)}
#: ITU-R BT.601 studio range (Y 16-235, Cb/Cr 16-240) Y'CbCr -> R'G'B' in 8-bit codes, the
#: conversion OpenCV's ``COLOR_YUV2RGB_UYVY``/``_YUYV`` (and so cv_bridge) applies.
#: Semi-planar YUV 4:2:0 encodings: the positions of Cb and Cr in each chroma pair.
_YUV420SP = {"nv12": (0, 1), "nv21": (1, 0)}
_BT601 = np.array([[255 / 219, 0.0, 255 / 224 * 1.402],
                   [255 / 219, -255 / 224 * 1.772 * 0.114 / 0.587,
                    -255 / 224 * 1.402 * 0.299 / 0.587],
                   [255 / 219, 255 / 224 * 1.772, 0.0]])

#: OpenCV-style generic codes: depth -> numpy type (channels 1, 3 or 4; 3 and 4 as R, G, B).
_GENERIC = {"8U": "u1", "16U": "u2", "32F": "f4", "64F": "f8"}
#: Pixel types as :class:`fidelity.chart.image.Image` names them.
_PIXEL_TYPE = {"u1": "uint8", "u2": "uint16", "f4": "float", "f8": "double"}


def supported_encodings() -> list[str]:
    """The ``sensor_msgs/Image`` encodings :func:`message_pixels` reads."""
    bayer = [f"bayer_{p.lower()}{bits}" for p in BAYER_PATTERNS for bits in (8, 16)]
    generic = [f"{d}C{c}" for d in _GENERIC for c in (1, 3, 4)]
    return [*_PACKED, *_YUV422, *_YUV420SP, *bayer, *generic]


def is_recording_path(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a recording by its form alone (a folder, or a file ending in
    :data:`RECORDING_SUFFIXES`), without reading it."""
    p = Path(path)
    return p.suffix.lower() in RECORDING_SUFFIXES or p.is_dir()


def _sniff(p: Path, shown: str) -> str:
    """The reader suffix of a recording file or folder; an error naming ``shown`` when it is
    not one."""
    if p.is_dir():
        if not (p / "metadata.yaml").is_file():
            raise InputFileError(f"{shown}: a folder, but not a ROS 2 bag (no metadata.yaml in "
                                 "it)")
        return ""
    try:
        with open(p, "rb") as f:
            head = f.read(16)
    except FileNotFoundError:
        raise InputFileError(f"{shown}: no such file") from None
    except OSError as exc:
        raise InputFileError(f"{shown}: cannot read ({exc.strerror})") from None
    for magic, suffix in _MAGIC:
        if head.startswith(magic):
            return suffix
    raise InputFileError(
        f"{shown}: not a ROS bag or MCAP file (a ROS 1 bag starts with '#ROSBAG V2.0', an MCAP "
        "file with '\\x89MCAP0', a ROS 2 bag is a folder with metadata.yaml or its .db3/.mcap "
        "file); --topic, --frame, --frames and --time read recordings only")


@contextlib.contextmanager
def _named(p: Path, suffix: str) -> Iterator[Path]:
    """``p`` under a name rosbags takes for what it is (it chooses its reader by the suffix):
    itself, or a link of a plain name with ``suffix`` in a temporary folder."""
    if not suffix or p.suffix == suffix:
        yield p
        return
    with tempfile.TemporaryDirectory(prefix="fidelity-") as folder:
        link = Path(folder) / f"recording{suffix}"
        os.symlink(os.path.abspath(p), link)
        yield link


def _rosbags() -> Any:
    """The rosbags modules used here; a missing package is one line naming the extra."""
    try:
        from rosbags import highlevel, typesys
    except ImportError:
        raise InputFileError(
            "reading a ROS bag or MCAP file needs rosbags: pip install "
            f"'camera-fidelity[{EXTRA}]'") from None
    return highlevel, typesys


@record
class Choice:
    """Which message of a topic to read: ``frame`` (an index; negative from the end) or
    ``time`` (the nearest message to: a number of seconds after the recording's first
    message, or an absolute time as :func:`absolute_time_ns` reads it). Neither: the first
    message."""

    topic: str | None = None
    frame: int | None = None
    time: float | str | None = None


def absolute_time_ns(text: str) -> int:
    """An absolute ``--time``: UNIX epoch seconds after ``@`` (``@1700000000.25``, as GNU
    ``date`` writes them; what ``ros2 bag info`` and the header stamps count), or an ISO 8601
    date and time with its UTC offset (``2023-11-14T22:13:20.25Z``, ``...+01:00``), to
    nanoseconds since the epoch. A time without an offset is refused: a recording's clock is
    UTC and a local reading would shift it."""
    t = text.strip()
    if t.startswith("@"):
        try:
            seconds = Decimal(t[1:])
        except InvalidOperation:
            raise InvalidValueError(f"--time {text!r}: expected @SECONDS since the epoch") \
                from None
        if not seconds.is_finite() or seconds < 0:
            raise InvalidValueError(f"--time {text!r}: expected @SECONDS since the epoch")
        return int(seconds * 10**9)

    # the fraction of a second read here, to the nanosecond (datetime keeps microseconds)
    m = re.fullmatch(r"(.+?[T ]\d\d:\d\d:\d\d)(?:[.,](\d+))?(.*)", t)
    base, fraction, offset = (m.group(1), m.group(2) or "", m.group(3)) if m else (t, "", "")
    try:
        when = dt.datetime.fromisoformat((base + offset).replace("Z", "+00:00")
                                         .replace("z", "+00:00"))
    except ValueError:
        raise InvalidValueError(
            f"--time {text!r}: expected seconds after the first message (0.5), @SECONDS since "
            f"the epoch or an ISO 8601 time with its offset (2023-11-14T22:13:20.25Z)") from None
    if when.tzinfo is None:
        raise InvalidValueError(f"--time {text!r}: give the UTC offset (Z or +HH:MM): a "
                                f"recording's times are UTC")
    delta = when - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)
    nanos = int((fraction + "000000000")[:9]) if fraction else 0
    return (delta.days * 86400 + delta.seconds) * 10**9 + nanos


def _kind(reader: Any, suffix: str) -> str:
    """How a report names the recording."""
    if suffix == ".bag":
        return "ROS 1 bag"
    storage = getattr(reader.readers[0], "storage", None)
    inner = getattr(storage, "storages", None)
    if inner:  # a folder with metadata.yaml
        name = type(inner[0]).__name__.lower()
        return "ROS 2 bag (MCAP)" if "mcap" in name else "ROS 2 bag (sqlite3)"
    return "MCAP file" if suffix == ".mcap" else "ROS 2 bag (sqlite3)"


def _image_topics(reader: Any) -> dict[str, tuple[str, int]]:
    """Image topics of an open reader: name -> (message type, message count)."""
    return {name: (str(info.msgtype), int(info.msgcount))
            for name, info in sorted(reader.topics.items()) if info.msgtype in IMAGE_TYPES}


def _list(topics: dict[str, tuple[str, int]]) -> str:
    if not topics:
        return "none"
    return ", ".join(f"{name} ({kind.rsplit('/', 1)[-1]}, {n} messages)"
                     for name, (kind, n) in topics.items())


def _select_topic(reader: Any, topic: str | None, shown: str) -> str:
    images = _image_topics(reader)
    if topic is None:
        if len(images) == 1:
            return next(iter(images))
        raise InputFileError(f"{shown}: {'several' if images else 'no'} image topics; "
                             f"choose one with --topic (image topics: {_list(images)})")
    topics = reader.topics
    if topic not in topics:
        raise InputFileError(f"{shown}: no topic {topic!r}; image topics: {_list(images)}")
    if topic not in images:
        raise InputFileError(
            f"{shown}: topic {topic!r} holds {topics[topic].msgtype} messages, not "
            f"sensor_msgs/Image or CompressedImage; image topics: {_list(images)}")
    return topic


def _mcap_times(storage: Any, topic: str) -> list[int] | None:
    """Log times of ``topic``'s messages in an MCAP file from its chunks' message index
    records (the chunks themselves are not read); None without chunk indexes."""
    chunks = getattr(storage, "chunks", None)
    bio = getattr(storage, "bio", None)
    channels = {c.id for c in getattr(storage, "connections", ()) if c.topic == topic}
    if not chunks or bio is None:
        return None
    times: list[int] = []
    for chunk in chunks:
        for cid, offset in chunk.message_index_offsets.items():
            if cid not in channels:
                continue
            bio.seek(offset)
            head = bio.read(15)  # opcode 0x07, record length, channel id, array length
            if len(head) < 15 or head[0] != 0x07:
                return None
            (size,) = struct.unpack_from("<I", head, 11)
            body = bio.read(size)
            if len(body) != size or size % 16:
                return None
            times.extend(t for t, _ in struct.iter_unpack("<QQ", body))
    return sorted(times)


def _sqlite_times(storage: Any, topic: str) -> list[int] | None:
    """Log times of ``topic``'s messages in a rosbag2 sqlite3 file (its timestamp column; the
    message data is not read)."""
    conn = getattr(storage, "dbconn", None)
    ids = [c.id for c in getattr(storage, "connections", ()) if c.topic == topic]
    if conn is None:
        return None
    if not ids:
        return []
    marks = ",".join("?" for _ in ids)
    rows = conn.execute(f"SELECT timestamp FROM messages WHERE topic_id IN ({marks}) "
                        "ORDER BY timestamp", ids)
    return [int(r[0]) for r in rows]


def topic_times(reader: Any, topic: str) -> list[int]:
    """Log times (ns) of ``topic``'s messages in time order, from the recording's index: a
    ROS 1 bag's index records, a sqlite3 file's timestamp column, an MCAP file's message
    indexes. A recording without an index (an unindexed MCAP file) is read through."""
    conns = [c for c in reader.connections if c.topic == topic]
    times: list[int] = []
    for sub in reader.readers:
        indexes = getattr(sub, "indexes", None)
        if isinstance(indexes, dict):  # ROS 1
            times.extend(e.time for c in conns if c.owner is sub for e in indexes.get(c.id, ()))
            continue
        storage = getattr(sub, "storage", None)
        storages = getattr(storage, "storages", None) or [storage]
        for st in storages:
            got = _mcap_times(st, topic) if hasattr(st, "chunks") else _sqlite_times(st, topic)
            if got is None:  # no index: read the topic through
                return _read_through(reader, conns)
            times.extend(got)
    counted = sum(int(c.msgcount) for c in conns)
    if counted and counted != len(times):  # an index that disagrees with the statistics
        return _read_through(reader, conns)
    return sorted(times)


def _read_through(reader: Any, conns: Sequence[Any]) -> list[int]:
    """Log times of the messages of ``conns`` read message by message (no usable index)."""
    return sorted(t for _, t, _ in reader.messages(connections=conns))


def _choose_frame(times: Sequence[int], start_ns: int, end_ns: int, choice: Choice,
                  shown: str, topic: str) -> int:
    """The index of the message ``choice`` names among ``times``."""
    n = len(times)
    if n == 0:
        raise InputFileError(f"{shown}: topic {topic!r} has no messages")
    if choice.frame is not None and choice.time is not None:
        raise InvalidValueError("give --frame N or --time T, not both")
    if isinstance(choice.time, str):
        target = absolute_time_ns(choice.time)
        if not start_ns <= target <= end_ns:
            raise InputFileError(
                f"{shown}: --time {choice.time} is outside the recording ({utc_text(start_ns)} to "
                f"{utc_text(end_ns)})")
    elif choice.time is not None:
        t = float(choice.time)
        span = (end_ns - start_ns) / 1e9
        if not math.isfinite(t) or t < 0 or t > span:
            raise InputFileError(f"{shown}: --time {choice.time:g} s is outside the recording "
                                 f"(0 to {span:.3f} s after its first message)")
        target = start_ns + round(t * 1e9)
    if choice.time is not None:
        k = bisect.bisect_left(times, target)
        if k == n or (k > 0 and target - times[k - 1] <= times[k] - target):
            k -= 1
        return k
    k = 0 if choice.frame is None else int(choice.frame)
    if not -n <= k < n:
        raise InputFileError(f"{shown}: topic {topic!r} has {n} messages (frames 0 to {n - 1}); "
                             f"there is no frame {k}")
    return k % n


@record
class FrameSelection:
    """Several messages of a topic (``gate --frames``): the ``indices`` listed, or the slice
    ``start:stop:step`` in Python's sense (negative indices from the end, ``stop`` left out),
    as ``text`` wrote it."""

    text: str
    indices: tuple[int, ...] = ()
    start: int | None = None
    stop: int | None = None
    step: int | None = None

    def resolve(self, count: int, shown: str, topic: str | None) -> list[int]:
        """The frame indices (0 to ``count - 1``, in order, each once) on a topic of ``count``
        messages (``topic`` None: a video of ``count`` frames); an index past the end or a
        selection of none is an error naming ``shown``."""
        has = (f"the video has {count} frames" if topic is None
               else f"topic {topic!r} has {count} messages")
        if self.indices:
            bad = [k for k in self.indices if not -count <= k < count]
            if bad:
                raise InputFileError(f"{shown}: {has} (frames 0 to {count - 1}); there is no "
                                     f"frame {bad[0]}")
            return list(dict.fromkeys(k % count for k in self.indices))
        picked = list(range(count))[self.start:self.stop:self.step]
        if not picked:
            of = (f"the video's {count} frames" if topic is None
                  else f"topic {topic!r}'s {count} messages")
            raise InputFileError(f"{shown}: --frames {self.text} selects none of {of}")
        return picked


def parse_frames(text: str) -> FrameSelection:
    """``N,M,...`` or ``START:STOP[:STEP]`` (Python slice, parts may be left out) as a
    :class:`FrameSelection`; anything else is an error naming ``--frames``."""
    t = text.strip()
    try:
        if ":" in t:
            parts = [p.strip() for p in t.split(":")]
            if len(parts) > 3:
                raise ValueError
            nums = [int(p) if p else None for p in parts] + [None] * (3 - len(parts))
            if nums[2] is not None and nums[2] <= 0:
                raise InvalidValueError(f"--frames {text}: the step must be a whole number "
                                        "above 0")
            return FrameSelection(text, start=nums[0], stop=nums[1], step=nums[2])
        indices = tuple(int(p) for p in t.split(","))
    except ValueError:
        raise InvalidValueError(f"--frames {text}: expected frame numbers N,M,... or a range "
                                "START:STOP[:STEP] (negative from the end)") from None
    return FrameSelection(text, indices=indices)


@contextlib.contextmanager
def _opened(path: str | os.PathLike[str]) -> Iterator[tuple[Any, str, str]]:
    """The recording at ``path`` open: ``(reader, its name as shown, its kind's suffix)``;
    closed after. Whatever rosbags' parser meets in a damaged recording, opening it or reading
    its index or messages, is one :class:`InputFileError` naming it."""
    p = Path(path)
    shown = display_path(p)
    if not p.exists():
        raise InputFileError(f"{shown}: no such file or folder")
    suffix = _sniff(p, shown)
    highlevel, typesys = _rosbags()
    with _named(p, suffix) as name:
        try:
            reader = _open(highlevel, typesys, name)
        except Exception as exc:
            raise InputFileError(f"{shown}: cannot read the recording ({_reason(exc)})") from None
        try:
            yield reader, shown, suffix
        except (InputFileError, InvalidValueError):
            raise
        except Exception as exc:
            raise InputFileError(f"{shown}: cannot read the recording ({_reason(exc)})") from None
        finally:
            with contextlib.suppress(Exception):
                reader.close()


def topic_frames(path: str | os.PathLike[str], topic: str | None = None) -> tuple[str, int]:
    """The image topic of the recording at ``path`` (``topic``, or its only image topic) and
    its number of messages, from the recording's index (no message is read)."""
    with _opened(path) as (reader, shown, _):
        chosen = _select_topic(reader, topic, shown)
        return chosen, len(topic_times(reader, chosen))


def read_frame(path: str | os.PathLike[str], choice: Choice = Choice(), *,
               bayer: str | None = None, max_pixels: int | None = None
               ) -> tuple[Image, str]:
    """Read the image message ``choice`` names from the recording at ``path``.

    Returns the :class:`fidelity.chart.image.Image` (``(H, W, 3)`` float32 R, G, B; ``path``
    the recording, ``recording`` its topic, frame and time) and the sha256 of the message's
    serialised bytes. ``bayer``: the CFA pattern of a one-channel mosaic (a ``bayer_*``
    encoding names its own); ``max_pixels``: the pixel limit
    (:func:`fidelity.chart.image.pixel_limit`). Errors: module docstring."""
    if bayer is not None and bayer.upper() not in BAYER_PATTERNS:
        raise unknown_name("--bayer pattern", bayer, BAYER_PATTERNS)
    limit = pixel_limit(max_pixels)
    p = Path(path)
    with _opened(p) as (reader, shown, suffix):
        topic = _select_topic(reader, choice.topic, shown)
        times = topic_times(reader, topic)
        start, end = int(reader.start_time), int(reader.end_time)
        k = _choose_frame(times, start, end, choice, shown, topic)
        t = times[k]
        same = k - bisect.bisect_left(times, t)  # messages before it at the same time
        conns = [c for c in reader.connections if c.topic == topic]
        raw: bytes | None = None
        msgtype = ""
        for i, (found, _, data) in enumerate(reader.messages(connections=conns, start=t,
                                                              stop=t + 1)):
            if i == same:
                raw, msgtype = bytes(data), str(found.msgtype)
                break
        if raw is None:
            raise InputFileError(f"{shown}: topic {topic!r} frame {k}: the index names a "
                                 "message the recording does not hold (damaged)")
        try:
            msg = reader.deserialize(raw, msgtype)
        except Exception as exc:
            raise InputFileError(f"{shown}: topic {topic!r} frame {k}: cannot decode the "
                                 f"message ({_reason(exc)})") from None
        kind = _kind(reader, suffix)
    where = f"{shown}: topic {topic} frame {k}"
    compressed = msgtype.endswith("CompressedImage")
    ros_encoding = str(msg.format if compressed else msg.encoding)
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    record = Recording(
        kind=kind, topic=topic, message_type=msgtype, ros_encoding=ros_encoding,
        frame=k, frames=len(times), time_ns=t, offset_s=(t - start) / 1e9,
        stamp_ns=(int(stamp.sec) * 10**9 + int(stamp.nanosec)) if stamp is not None else None,
        frame_id=str(header.frame_id) if header is not None else None)
    if compressed:
        image = _decompress(np.asarray(msg.data, np.uint8).tobytes(), ros_encoding, bayer,
                            limit, where)
    else:
        pixels, pixel_type, channels, encoding, pattern = message_pixels(
            int(msg.height), int(msg.width), ros_encoding, bool(msg.is_bigendian),
            int(msg.step), np.asarray(msg.data, np.uint8), bayer=bayer, limit=limit,
            where=where)
        image = Image(pixels=pixels, path=p, file_format=kind, pixel_type=pixel_type,
                      channels=channels, layer=None, encoding=encoding, bayer=pattern)
    return replace(image, path=p, file_format=kind, recording=record,
                   all_channels=image.channels), hashlib.sha256(raw).hexdigest()


def _open(highlevel: Any, typesys: Any, name: Path) -> Any:
    """An open rosbags reader of ``name``, its message types from the recording's own
    definitions, or, for a recording without them (older sqlite3 bags), from rosbags' store of
    the latest ROS 2 types (built only then: it takes most of a second)."""
    reader = highlevel.AnyReader([name])
    try:
        reader.open()
    except highlevel.AnyReaderError as exc:
        if "default_typestore" not in str(exc):
            raise
        reader = highlevel.AnyReader(
            [name], default_typestore=typesys.get_typestore(typesys.Stores.LATEST))
        reader.open()
    return reader


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def _bayer_of(encoding: str) -> str | None:
    """The CFA pattern a ``bayer_*`` encoding names (``bayer_rggb8`` -> ``RGGB``)."""
    head = encoding.strip().lower()
    if head.startswith("bayer_") and head[6:10].upper() in BAYER_PATTERNS:
        return head[6:10].upper()
    return None


def message_pixels(height: int, width: int, encoding: str, bigendian: bool, step: int,
                   data: np.ndarray, *, bayer: str | None = None, limit: int | None = None,
                   where: str = "message"
                   ) -> tuple[np.ndarray, str, tuple[str, str, str], str, str | None]:
    """The pixels of a ``sensor_msgs/Image``'s fields (module docstring).

    Returns ``(H, W, 3)`` float32 R, G, B, the pixel type (``uint8``, ``uint16``, ``float``,
    ``double``), the three channels' names, the likely encoding (``srgb`` for integer codes,
    ``linear`` for floats and demosaiced mosaics) and the Bayer pattern used (or None).
    Errors name ``where``.
    """
    enc = encoding.strip()
    pattern = _bayer_of(enc)
    if enc in _YUV422:
        return _yuv422(height, width, enc, step, data, bayer=bayer, limit=limit, where=where)
    if enc in _YUV420SP:
        return _yuv420sp(height, width, enc, step, data, bayer=bayer, limit=limit, where=where)
    if pattern is not None:
        bits = enc[10:]
        if bits not in ("8", "16"):
            raise InputFileError(f"{where}: unsupported encoding {encoding!r}; supported: "
                                 f"{', '.join(supported_encodings())}")
        dtype, nch, order = ("u1" if bits == "8" else "u2"), 1, (0, 0, 0)
        if bayer is not None and bayer.upper() != pattern:
            raise InputFileError(f"{where}: the encoding {encoding} names the Bayer pattern "
                                 f"{pattern}, not --bayer {bayer.upper()}")
    elif enc in _PACKED:
        dtype, nch, order = _PACKED[enc]
    elif enc.upper()[:-2] in _GENERIC and enc.upper()[-2:] in ("C1", "C3", "C4"):
        dtype, nch = _GENERIC[enc.upper()[:-2]], int(enc[-1])
        order = (0, 0, 0) if nch == 1 else (0, 1, 2)
    else:
        raise InputFileError(f"{where}: unsupported encoding {encoding!r}; supported: "
                             f"{', '.join(supported_encodings())}")
    if height < 1 or width < 1:
        raise InputFileError(f"{where}: empty image ({width}x{height})")
    _check_size(height, width, limit, where)
    if nch == 1:
        pattern = pattern or (bayer.upper() if bayer is not None else None)
        if pattern is None:
            raise InputFileError(
                f"{where}: one-channel image ({encoding}); a colour chart needs R, G, B: for a "
                f"camera raw Bayer mosaic give --bayer {'|'.join(BAYER_PATTERNS)} (its CFA "
                "pattern)")
        if height % 2 or width % 2:
            raise InputFileError(f"{where}: a Bayer mosaic ({encoding}, {pattern}) of odd size "
                                 f"{width}x{height}: its 2x2 pattern does not tile it")
    elif bayer is not None:
        raise InputFileError(f"{where}: --bayer {bayer.upper()} needs a one-channel mosaic, "
                             f"but the image is {encoding} ({nch} channels); leave out --bayer")
    dt = np.dtype(dtype).newbyteorder(">" if bigendian else "<")
    row = width * nch * dt.itemsize
    if step < row or data.size < step * (height - 1) + row:
        raise InputFileError(f"{where}: the message holds {data.size} bytes, fewer than its "
                             f"{width}x{height} {encoding} pixels need (step {step})")
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, row), strides=(step, 1))
    values = np.ascontiguousarray(rows).view(dt).reshape(height, width, nch)
    if dt.kind == "u":
        scale = np.float32(1.0 / np.iinfo(dt).max)
        as_float = values.astype(np.float32) * scale
    else:
        as_float = values.astype(np.float32)
    pixel_type = _PIXEL_TYPE[dtype]
    if nch == 1:
        assert pattern is not None
        rgb = demosaic(as_float[:, :, 0], pattern)
        return (rgb, pixel_type, tuple(f"{enc} ({c} of {pattern})" for c in "RGB"),  # type: ignore[return-value]
                "linear", pattern)
    names = ("R", "G", "B") if enc in _PACKED else tuple(f"{enc}[{i}]" for i in order)
    rgb = np.ascontiguousarray(as_float[:, :, list(order)])
    return (rgb, pixel_type, names, "srgb" if dt.kind == "u" else "linear",  # type: ignore[return-value]
            None)


def _check_size(height: int, width: int, limit: int | None, where: str) -> None:
    """The pixel limit (``--max-pixels``) of a message's picture."""
    if limit is not None and height * width > limit:
        raise InputFileError(
            f"{where}: the image is {width}x{height} ({height * width / 1e6:.1f} megapixels), "
            f"more than the limit of {limit / 1e6:g} megapixels; raise it with --max-pixels N")


def _no_bayer(bayer: str | None, encoding: str, where: str) -> None:
    """``--bayer`` is for one-channel mosaics, not for a colour ``encoding``."""
    if bayer is not None:
        raise InputFileError(f"{where}: --bayer {bayer.upper()} needs a one-channel mosaic, "
                             f"but the image is {encoding}; leave out --bayer")


def _yuv422(height: int, width: int, encoding: str, step: int, data: np.ndarray, *,
            bayer: str | None, limit: int | None, where: str
            ) -> tuple[np.ndarray, str, tuple[str, str, str], str, str | None]:
    """A YUV 4:2:2 image (``uyvy``/``yuv422``, ``yuyv``/``yuv422_yuy2``) as R'G'B': BT.601
    studio range (:data:`_BT601`), each chroma pair shared by its two pixels, rounded and
    clipped to 8-bit codes as OpenCV converts it, normalised like ``rgb8``."""
    _no_bayer(bayer, encoding, where)
    if height < 1 or width < 2 or width % 2:
        raise InputFileError(f"{where}: a {encoding} image needs an even width, not "
                             f"{width}x{height}")
    _check_size(height, width, limit, where)
    row = width * 2
    if step < row or data.size < step * (height - 1) + row:
        raise InputFileError(f"{where}: the message holds {data.size} bytes, fewer than its "
                             f"{width}x{height} {encoding} pixels need (step {step})")
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, row), strides=(step, 1))
    quads = np.ascontiguousarray(rows).reshape(height, width // 2, 4).astype(np.float64)
    y0, u, y1, v = (quads[:, :, i] for i in _YUV422[encoding])
    y = np.stack([y0, y1], axis=2).reshape(height, width)
    return _bt601(y, np.repeat(u, 2, axis=1), np.repeat(v, 2, axis=1))


def _bt601(y: np.ndarray, u: np.ndarray, v: np.ndarray
           ) -> tuple[np.ndarray, str, tuple[str, str, str], str, str | None]:
    """Y'CbCr codes (float, full size) to R'G'B' by BT.601 in studio range (:data:`_BT601`),
    rounded and clipped to 8-bit codes as OpenCV converts them, normalised like ``rgb8``."""
    luma = np.maximum(y - 16.0, 0.0)  # as OpenCV
    rgb = np.stack([luma, u - 128.0, v - 128.0], axis=-1) @ _BT601.T
    codes = np.clip(np.rint(rgb), 0, 255)
    pixels = codes.astype(np.float32) * np.float32(1.0 / 255)
    return pixels, "uint8", ("R", "G", "B"), "srgb", None


def _yuv420sp(height: int, width: int, encoding: str, step: int, data: np.ndarray, *,
              bayer: str | None, limit: int | None, where: str
              ) -> tuple[np.ndarray, str, tuple[str, str, str], str, str | None]:
    """A semi-planar YUV 4:2:0 image (``nv12``: Cb, Cr pairs; ``nv21``: Cr, Cb) as R'G'B':
    the luma plane (``height`` rows of ``step`` bytes) then the interleaved chroma plane
    (``height / 2`` rows), each chroma pair shared by a 2 x 2 block of pixels, converted by
    :func:`_bt601`. ``height`` is the picture's (as ROS 2 drivers and ffmpeg_image_transport
    write it); a message whose ``height`` counts the chroma rows too (``data`` exactly
    ``height * step`` bytes, ``height`` a multiple of 3, as rosbags-image reads it) is read
    with a picture two thirds as high."""
    _no_bayer(bayer, encoding, where)
    if data.size < step * (height + height // 2) and data.size == step * height \
            and height % 3 == 0:
        height = height * 2 // 3
    if height < 2 or width < 2 or height % 2 or width % 2:
        raise InputFileError(f"{where}: a {encoding} image needs an even width and height, "
                             f"not {width}x{height}")
    _check_size(height, width, limit, where)
    rows_in_all = height + height // 2
    if step < width or data.size < step * (rows_in_all - 1) + width:
        raise InputFileError(f"{where}: the message holds {data.size} bytes, fewer than its "
                             f"{width}x{height} {encoding} planes need (step {step})")
    rows = np.lib.stride_tricks.as_strided(data, shape=(rows_in_all, width), strides=(step, 1))
    planes = np.ascontiguousarray(rows).astype(np.float64)
    y = planes[:height]
    pairs = planes[height:].reshape(height // 2, width // 2, 2)
    iu, iv = _YUV420SP[encoding]

    def full(c: np.ndarray) -> np.ndarray:
        return np.repeat(np.repeat(c, 2, axis=0), 2, axis=1)

    return _bt601(y, full(pairs[:, :, iu]), full(pairs[:, :, iv]))


def _decompress(data: bytes, fmt: str, bayer: str | None, limit: int, where: str) -> Image:
    """A ``sensor_msgs/CompressedImage``'s JPEG or PNG bytes, read as the file would be."""
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        suffix = ".png"
    elif data.startswith(b"\xff\xd8"):
        suffix = ".jpg"
    else:
        raise InputFileError(f"{where}: CompressedImage ({fmt!r}) holds neither JPEG nor PNG "
                             "data")
    pattern = _bayer_of(fmt)
    if pattern is not None and bayer is not None and bayer.upper() != pattern:
        raise InputFileError(f"{where}: the format {fmt!r} names the Bayer pattern {pattern}, "
                             f"not --bayer {bayer.upper()}")
    with tempfile.TemporaryDirectory(prefix="fidelity-") as folder:
        file = Path(folder) / f"message{suffix}"
        file.write_bytes(data)
        try:
            image = read_image(file, bayer=pattern or bayer, max_pixels=limit)
        except InputFileError as exc:
            raise InputFileError(str(exc).replace(str(file), where)) from None
    if image.bayer is not None and (image.height % 2 or image.width % 2):
        raise InputFileError(f"{where}: a Bayer mosaic ({fmt}, {image.bayer}) of odd size "
                             f"{image.width}x{image.height}: its 2x2 pattern does not tile it")
    return image


__all__ = ["EXTRA", "IMAGE_TYPES", "RECORDING_SUFFIXES", "Choice", "FrameSelection",
           "is_recording_path", "message_pixels", "parse_frames", "read_frame",
           "supported_encodings", "topic_frames", "topic_times"]
