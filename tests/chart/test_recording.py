"""Robot recordings as audit input: ROS 1 bags, ROS 2 bags (sqlite3 and MCAP storage) and MCAP
files, written here with rosbags' own writers, holding a rendered chart in every
sensor_msgs/Image encoding read and as CompressedImage JPEG/PNG.

The reference of each encoding is the same pixels stored as an ordinary file (PNG written by
Pillow, 16-bit PNG by OpenImageIO, EXR by the OpenEXR module): the chart measured from the bag
must equal the chart measured from the file. The raw conversion is also checked against
rosbags-image (OpenCV's conversions), a second implementation, where it is installed.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

pytest.importorskip("rosbags")

import OpenEXR  # noqa: E402
from click.testing import CliRunner  # noqa: E402
from PIL import Image as PILImage  # noqa: E402
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from fidelity.camera.render import render_chart  # noqa: E402
from fidelity.chart.image import write_png  # noqa: E402
from fidelity.chart.read import ReadOptions
from fidelity.chart.recording import message_pixels, supported_encodings  # noqa: E402
from fidelity.cli import main  # noqa: E402
from fidelity.core.errors import FidelityError, InputFileError  # noqa: E402
from fidelity.measure.pixels import measure_image

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000_000_000_000  # ns
STEP = 100_000_000  # 10 frames per second
KINDS = ("ros1", "sqlite3", "mcap", "mcap-file")
STORES = {"ros1": Stores.ROS1_NOETIC, "ros2": Stores.ROS2_HUMBLE}


@pytest.fixture(scope="module")
def chart():
    """A rendered chart: linear float32 and display-encoded sRGB, and its patch corners."""
    render = render_chart("nikon-5100")
    linear = np.asarray(render.linear_image, np.float32)
    display = np.asarray(render.display_image, np.float64)
    return linear, display


def mosaic(linear: np.ndarray, pattern: str) -> np.ndarray:
    """(H, W) Bayer mosaic of ``pattern`` (top-left 2x2 colours) from an RGB image."""
    index = {"R": 0, "G": 1, "B": 2}
    out = np.empty(linear.shape[:2], linear.dtype)
    for k, colour in enumerate(pattern):
        dy, dx = divmod(k, 2)
        out[dy::2, dx::2] = linear[dy::2, dx::2, index[colour]]
    return out


def image_msg(ts, arr: np.ndarray, encoding: str, t: int, *, step_pad: int = 0,
              bigendian: bool = False):
    """A sensor_msgs/Image of ``arr`` (rows padded by ``step_pad`` bytes)."""
    types = ts.types
    h, w = arr.shape[:2]
    a = np.ascontiguousarray(arr.astype(arr.dtype.newbyteorder(">" if bigendian else "<")))
    rows = a.view(np.uint8).reshape(h, -1)
    if step_pad:
        rows = np.concatenate([rows, np.zeros((h, step_pad), np.uint8)], axis=1)
    return types["sensor_msgs/msg/Image"](
        header=header(ts, t), height=h, width=w, encoding=encoding, is_bigendian=int(bigendian),
        step=rows.shape[1], data=np.ascontiguousarray(rows).reshape(-1))


def compressed_msg(ts, data: bytes, fmt: str, t: int):
    return ts.types["sensor_msgs/msg/CompressedImage"](
        header=header(ts, t), format=fmt, data=np.frombuffer(data, np.uint8).copy())


def header(ts, t: int):
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    stamp = Time(sec=t // 10**9, nanosec=t % 10**9)
    if "seq" in Header.__dataclass_fields__:
        return Header(seq=0, stamp=stamp, frame_id="camera")
    return Header(stamp=stamp, frame_id="camera")


def write_recording(folder: Path, kind: str, topics: dict[str, list],
                    compression: str | None = None) -> Path:
    """A recording of ``kind`` holding ``topics``: name -> one message factory per frame
    (called with the typestore and the frame's time), 10 frames per second; plus a
    std_msgs/String topic; a ROS 2 bag compressed by zstd per ``compression`` (message, file,
    storage). Returns the path a user gives."""
    ros1 = kind == "ros1"
    ts = get_typestore(STORES["ros1" if ros1 else "ros2"])
    if ros1:
        path = folder / "drive.bag"
        writer = Writer1(path)
    else:
        path = folder / f"drive_{kind}"
        plugin = StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
        if compression is not None:
            from rosbags.rosbag2 import CompressionFormat, CompressionMode

            writer.set_compression(CompressionMode[compression.upper()],
                                   CompressionFormat.ZSTD)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        text = writer.add_connection("/rosout_text", "std_msgs/msg/String", typestore=ts)
        writer.write(text, T0, serialize(ts.types["std_msgs/msg/String"](data="hello"),
                                          "std_msgs/msg/String"))
        for topic, frames in topics.items():
            first = frames[0](ts, T0)
            msgtype = first.__msgtype__
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for k, make in enumerate(frames):
                t = T0 + k * STEP
                writer.write(conn, t, serialize(make(ts, t), msgtype))
    if kind == "mcap-file":
        return path / f"{path.name}.mcap"
    return path


# --------------------------------------------------------------------------------------------
# Every encoding: the chart measured from the recording equals the chart from the file


def _encodings(chart, folder: Path):
    """(topic, frame factory, reference file, ReadOptions for the file, ReadOptions for the
    recording) per encoding; the file holds the same pixels as the message."""
    linear, display = chart
    rng = np.random.default_rng(1)
    codes8 = np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)
    codes16 = np.clip(np.rint(display * 65535), 0, 65535).astype(np.uint16)
    mos16 = np.clip(np.rint(mosaic(linear, "RGGB") * 65535), 0, 65535).astype(np.uint16)
    mos8 = np.clip(np.rint(mosaic(linear, "GRBG") * 255), 0, 255).astype(np.uint8)
    noise = (rng.random(codes8.shape) * 255).astype(np.uint8)  # other frames: not the chart
    out = []
    png8 = folder / "c8.png"
    PILImage.fromarray(codes8, "RGB").save(png8)
    png16 = write_png(folder / "c16.png", codes16 / 65535.0, 16)
    exr = folder / "c.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION},
                 {c: np.ascontiguousarray(linear[..., i]) for i, c in enumerate("RGB")}
                 ).write(str(exr))
    mono16_png = folder / "m16.png"
    PILImage.fromarray(mos16).save(mono16_png)
    mono8_png = folder / "m8.png"
    PILImage.fromarray(mos8, "L").save(mono8_png)
    jpeg = io.BytesIO()
    PILImage.fromarray(codes8, "RGB").save(jpeg, "JPEG", quality=90)
    jpg = folder / "c.jpg"
    jpg.write_bytes(jpeg.getvalue())

    noise_png = io.BytesIO()
    PILImage.fromarray(noise, "RGB").save(noise_png, "PNG")

    def frames(make, compressed: bool = False):
        """Frame 1 the chart, frames 0 and 2 noise of the same message type."""
        if compressed:
            def other(ts, t):
                return compressed_msg(ts, noise_png.getvalue(), "png", t)
        else:
            def other(ts, t):
                return image_msg(ts, noise, "rgb8", t)
        return [other, make, other]

    plain = ReadOptions()
    for enc, arr in (("rgb8", codes8), ("bgr8", codes8[..., ::-1]),
                     ("rgba8", np.dstack([codes8, np.full(codes8.shape[:2], 255, np.uint8)])),
                     ("bgra8", np.dstack([codes8[..., ::-1],
                                          np.zeros(codes8.shape[:2], np.uint8)]))):
        out.append((f"/cam/{enc}", frames(lambda ts, t, a=arr, e=enc: image_msg(ts, a, e, t,
                                                                                step_pad=8)),
                    png8, plain, ReadOptions(topic=f"/cam/{enc}", frame=1)))
    out.append(("/cam/rgb16", frames(lambda ts, t: image_msg(ts, codes16, "rgb16", t)),
                png16, plain, ReadOptions(topic="/cam/rgb16", frame=1)))
    out.append(("/cam/bgr16_be", frames(lambda ts, t: image_msg(ts, codes16[..., ::-1], "bgr16",
                                                                t, bigendian=True)),
                png16, plain, ReadOptions(topic="/cam/bgr16_be", frame=1)))
    out.append(("/cam/float", frames(lambda ts, t: image_msg(ts, linear, "32FC3", t)),
                exr, plain, ReadOptions(topic="/cam/float", frame=1)))
    out.append(("/cam/bayer16", frames(lambda ts, t: image_msg(ts, mos16, "bayer_rggb16", t)),
                mono16_png, ReadOptions(bayer="RGGB"), ReadOptions(topic="/cam/bayer16",
                                                                   frame=1)))
    out.append(("/cam/mono16", frames(lambda ts, t: image_msg(ts, mos16, "mono16", t)),
                mono16_png, ReadOptions(bayer="RGGB"),
                ReadOptions(topic="/cam/mono16", frame=1, bayer="RGGB")))
    out.append(("/cam/bayer8", frames(lambda ts, t: image_msg(ts, mos8, "bayer_grbg8", t)),
                mono8_png, ReadOptions(bayer="GRBG"), ReadOptions(topic="/cam/bayer8",
                                                                  frame=1)))
    out.append(("/cam/mono32f", frames(lambda ts, t: image_msg(ts, mosaic(linear, "RGGB"),
                                                                 "32FC1", t)),
                None, ReadOptions(bayer="RGGB"),
                ReadOptions(topic="/cam/mono32f", frame=1, bayer="RGGB")))
    out.append(("/cam/jpeg", frames(lambda ts, t: compressed_msg(ts, jpeg.getvalue(), "jpeg",
                                                                  t), True),
                jpg, plain, ReadOptions(topic="/cam/jpeg", frame=1)))
    out.append(("/cam/png", frames(lambda ts, t: compressed_msg(ts, png8.read_bytes(),
                                                                 "rgb8; png compressed rgb8",
                                                                 t), True),
                png8, plain, ReadOptions(topic="/cam/png", frame=1)))
    return out


@pytest.fixture(scope="module")
def recordings(chart, tmp_path_factory):
    folder = tmp_path_factory.mktemp("recordings")
    cases = _encodings(chart, folder)
    topics = {topic: frames for topic, frames, *_ in cases}
    paths = {}
    for kind in KINDS:
        (folder / kind).mkdir()
        paths[kind] = write_recording(folder / kind, kind, topics)
    return paths, cases, folder


@pytest.fixture(scope="module")
def corners(chart):
    """The corner patch centres, found once in the PNG of the chart."""
    linear, _ = chart
    from fidelity.chart.find import find_chart

    return find_chart(linear, encoding="linear").corners


@pytest.mark.parametrize("kind", KINDS)
def test_every_encoding_measures_as_the_same_pixels_in_a_file(recordings, corners, kind):
    paths, cases, _ = recordings
    for topic, _, ref, ref_read, bag_read in cases:
        got = measure_image(paths[kind], corners, read=bag_read)
        rec = got.image.recording
        assert (rec.topic, rec.frame, rec.frames) == (topic, 1, 3)
        assert rec.time_ns == T0 + STEP and rec.offset_s == pytest.approx(0.1)
        assert rec.stamp_ns == T0 + STEP and rec.frame_id == "camera"
        assert got.image.path == str(paths[kind])
        if ref is None:  # 32FC1 mosaic: against the same mosaic in 16-bit codes (1e-5 apart)
            coded = measure_image(recordings[2] / "m16.png", corners, read=ref_read)
            assert got.encoding == "linear"
            assert got.mean_delta_e == pytest.approx(coded.mean_delta_e, abs=1e-3)
            continue
        want = measure_image(ref, corners, read=ref_read)
        assert got.encoding == want.encoding, topic
        assert got.mean_delta_e == pytest.approx(want.mean_delta_e, abs=1e-9), topic
        np.testing.assert_allclose(got.measurement.delta_e, want.measurement.delta_e,
                                   atol=1e-9, err_msg=topic)
        assert got.exposure_ev == pytest.approx(want.exposure_ev, abs=1e-9)


def test_raw_conversion_agrees_with_rosbags_image(chart):
    """message_pixels against rosbags-image (OpenCV's conversions): the same R, G, B codes."""
    image = pytest.importorskip("rosbags.image")
    _, display = chart
    ts = get_typestore(Stores.ROS2_HUMBLE)
    codes = np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)
    codes16 = (codes.astype(np.uint16) * 257)
    for enc, arr in (("rgb8", codes), ("bgr8", codes[..., ::-1]),
                     ("bgra8", np.dstack([codes[..., ::-1], codes[..., :1]])),
                     ("rgb16", codes16), ("bgr16", codes16[..., ::-1])):
        msg = image_msg(ts, arr, enc, T0)
        theirs = image.message_to_cvimage(msg, "rgb16" if "16" in enc else "rgb8")
        ours = message_pixels(msg.height, msg.width, msg.encoding, bool(msg.is_bigendian),
                              msg.step, msg.data)[0]
        scale = 65535 if "16" in enc else 255
        np.testing.assert_array_equal(np.rint(ours * scale).astype(np.int64),
                                      np.asarray(theirs, np.int64), err_msg=enc)
    # YUV 4:2:2 (usb_cam, many GigE cameras): BT.601 studio range as OpenCV converts it, to
    # within one code (OpenCV computes in 20-bit fixed point); every byte value occurs
    yuv = np.random.default_rng(3).integers(0, 256, (64, 96, 2), dtype=np.uint8)
    for enc in ("uyvy", "yuv422", "yuyv", "yuv422_yuy2"):
        msg = image_msg(ts, yuv, enc, T0)
        theirs = np.asarray(image.message_to_cvimage(msg, "rgb8"), np.int64)
        ours = message_pixels(msg.height, msg.width, msg.encoding, False, msg.step, msg.data)
        assert ours[1:4] == ("uint8", ("R", "G", "B"), "srgb")
        diff = np.abs(np.rint(ours[0] * 255).astype(np.int64) - theirs)
        assert diff.max() <= 1 and diff.mean() < 0.05, enc
        assert theirs.min() == 0 and theirs.max() == 255  # the clipping is exercised


def test_time_picks_the_nearest_message_and_the_default_is_the_first(recordings, corners):
    paths, _, _ = recordings
    for kind in KINDS:
        near = measure_image(paths[kind], corners,
                             read=ReadOptions(topic="/cam/rgb8", time=0.13))
        assert near.image.recording.frame == 1
        last = measure_image(paths[kind], corners, read=ReadOptions(topic="/cam/rgb8",
                                                                    frame=-2))
        assert last.image.recording.frame == 1
    from fidelity.chart.recording import Choice, read_frame

    for kind in KINDS:
        image, _ = read_frame(paths[kind], Choice("/cam/png"))
        assert image.recording.frame == 0 and image.recording.time_ns == T0


# --------------------------------------------------------------------------------------------
# The command line: audit, gate, compare; the report names the bag, topic and time


def _run(args: list[str]):
    return CliRunner().invoke(main, args, catch_exceptions=False)


def _corner_text(corners) -> str:
    return ",".join(f"{v:.3f}" for v in np.asarray(corners).ravel())


def test_audit_gate_and_compare_read_a_recording(recordings, corners, tmp_path):
    paths, _, folder = recordings
    c = _corner_text(corners)
    out = tmp_path / "a.json"
    r = _run(["audit", str(paths["mcap"]), "--topic", "/cam/rgb8", "--frame", "1",
              "--corners", c, "--json", str(out), "--html", str(tmp_path / "a.html")])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    rec = doc["source"]["recording"]
    assert doc["source"]["path"] == str(paths["mcap"])
    assert (rec["topic"], rec["frame"], rec["time_ns"]) == ("/cam/rgb8", 1, T0 + STEP)
    assert rec["kind"] == "ROS 2 bag (MCAP)" and rec["ros_encoding"] == "rgb8"
    assert rec["time_utc"] == "2023-11-14T22:13:20.100000000Z"
    png = json.loads(_run_json(["audit", str(folder / "c8.png"), "--corners", c], tmp_path))
    assert doc["mean_delta_e"] == pytest.approx(png["mean_delta_e"], abs=1e-9)
    assert "/cam/rgb8" in (tmp_path / "a.html").read_text()
    limit = json.loads(_run_json(["audit", str(folder / "c.jpg"), "--corners", c],
                                 tmp_path))["mean_delta_e"]
    for bound, code in ((limit + 0.001, 0), (limit - 0.001, 1)):
        g = _run(["gate", str(paths["ros1"]), "--topic", "/cam/jpeg", "--frame", "1",
                  "--corners", c, "--max-delta-e", str(bound), "-q"])
        assert g.exit_code == code, g.output
    # several subjects: --topic and --frame go to the recordings, not to the PNG
    junit = tmp_path / "g.xml"
    g = _run(["gate", str(folder / "c8.png"), str(paths["ros1"]), str(paths["mcap-file"]),
              "--topic", "/cam/bgr8", "--frame", "-2", "--corners", c,
              "--max-delta-e", str(png["mean_delta_e"] + 0.001), "--json", str(tmp_path / "g"),
              "--junit", str(junit), "-q"])
    assert g.exit_code == 0, g.output
    for name in ("drive.bag.json", "drive_mcap-file.mcap.json"):
        each = json.loads((tmp_path / "g" / name).read_text())
        assert each["source"]["recording"]["frame"] == 1
        assert each["mean_delta_e"] == pytest.approx(png["mean_delta_e"], abs=1e-9)
    assert "recording" not in json.loads((tmp_path / "g" / "c8.png.json").read_text())["source"]
    cmp_json = tmp_path / "cmp.json"
    r = _run(["compare", str(folder / "c.exr"), str(paths["sqlite3"]), "--topic", "/cam/rgb8",
              "--time", "0.1", "--sim-corners", c, "--real-corners", c,
              "--json", str(cmp_json)])
    assert r.exit_code == 0, r.output
    cmp = json.loads(cmp_json.read_text())
    assert "/cam/rgb8" in json.dumps(cmp)


def _run_json(args: list[str], tmp_path: Path) -> str:
    out = tmp_path / "x.json"
    r = _run([*args, "--json", str(out), "-q"])
    assert r.exit_code == 0, r.output
    return out.read_text()


# --------------------------------------------------------------------------------------------
# Bad input: exit 2, one line naming the input


def _error(args: list[str]) -> str:
    r = _run([*args, "-q"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1, r.output
    return lines[0]


def test_bad_recordings_are_one_line_errors(recordings, chart, tmp_path):
    paths, _, folder = recordings
    bag = str(paths["ros1"])
    garbage = tmp_path / "broken.bag"
    garbage.write_bytes(b"not a bag at all" * 10)
    line = _error(["audit", str(garbage), "--topic", "/cam/rgb8"])
    assert line.startswith(f"fidelity: error: {garbage}: not a ROS bag")
    truncated = tmp_path / "truncated.bag"
    truncated.write_bytes(Path(bag).read_bytes()[:5000])
    assert _error(["audit", str(truncated)]).startswith(f"fidelity: error: {truncated}: ")
    line = _error(["audit", bag, "--topic", "/nope"])
    assert line.startswith(f"fidelity: error: {bag}: no topic '/nope'; image topics: ")
    assert "/cam/rgb8 (Image, 3 messages)" in line and "/cam/jpeg (CompressedImage" in line
    assert "/rosout_text" not in line
    line = _error(["audit", bag])  # several image topics, none chosen
    assert "choose one with --topic" in line and "/cam/bgr8" in line
    line = _error(["audit", bag, "--topic", "/rosout_text"])
    assert f"{bag}: topic '/rosout_text' holds std_msgs/msg/String" in line
    line = _error(["audit", bag, "--topic", "/cam/rgb8", "--frame", "3"])
    assert f"{bag}: topic '/cam/rgb8' has 3 messages" in line
    line = _error(["audit", bag, "--topic", "/cam/rgb8", "--time", "99"])
    assert f"{bag}: --time 99 s is outside the recording" in line
    line = _error(["audit", bag, "--topic", "/cam/mono16", "--frame", "1"])
    assert "one-channel image (mono16)" in line and "--bayer" in line
    line = _error(["audit", bag, "--topic", "/cam/rgb8", "--bayer", "RGGB"])
    assert "leave out --bayer" in line
    line = _error(["audit", bag, "--topic", "/cam/rgb8", "--frame", "1", "--time", "0.1"])
    assert "--frame" in line and "--time" in line
    # --topic with an image file, and a folder that is no bag
    png = folder / "c8.png"
    line = _error(["audit", str(png), "--topic", "/cam/rgb8"])
    assert line.startswith(f"fidelity: error: {png}: not a ROS bag or MCAP file")
    line = _error(["compare", str(png), str(png), "--topic", "/cam/rgb8"])
    assert line.startswith(f"fidelity: error: {png}: not a ROS bag or MCAP file")
    line = _error(["audit", str(tmp_path)])  # audit and gate: a folder of images
    assert line.startswith(f"fidelity: error: {tmp_path}: a folder with no image in it")
    line = _error(["compare", str(tmp_path), str(png)])
    assert line.startswith(f"fidelity: error: {tmp_path}: a folder, but not a ROS 2 bag")
    # a Bayer mosaic of odd size
    linear, _ = chart
    odd = np.clip(np.rint(mosaic(linear, "RGGB")[:-1] * 65535), 0, 65535).astype(np.uint16)
    oddbag = write_recording(tmp_path, "ros1", {"/raw": [
        lambda ts, t: image_msg(ts, odd, "bayer_rggb16", t)]})
    line = _error(["audit", str(oddbag)])
    assert line.startswith(f"fidelity: error: {oddbag}: topic /raw frame 0: a Bayer mosaic")
    assert "odd size 248x167" in line
    # an encoding not read
    (tmp_path / "nv24").mkdir()
    nv24 = write_recording(tmp_path / "nv24", "ros1", {"/nv24": [lambda ts, t: image_msg(
        ts, np.zeros((6, 4), np.uint8), "nv24", t)]})
    assert "unsupported encoding 'nv24'" in _error(["audit", str(nv24)])


def test_a_short_message_is_an_error_naming_its_size():
    with pytest.raises(FidelityError, match="holds 10 bytes, fewer than its 4x2 rgb8"):
        message_pixels(2, 4, "rgb8", False, 12, np.zeros(10, np.uint8))


# --------------------------------------------------------------------------------------------
# Costs: the index, not the bag; rosbags only for recordings


def _rchar() -> int:
    with open("/proc/self/io") as f:
        return int(next(ln for ln in f if ln.startswith("rchar:")).split()[1])


@pytest.mark.skipif(not Path("/proc/self/io").exists(), reason="needs /proc/self/io (Linux)")
@pytest.mark.parametrize("kind", ("ros1", "sqlite3", "mcap"))
def test_one_frame_reads_the_index_and_one_message_not_the_bag(tmp_path, kind):
    """A 60 MB recording of 200 frames of 300 KB: reading frame 150 reads a few MB."""
    from fidelity.chart.recording import Choice, read_frame

    rng = np.random.default_rng(2)
    frames = [(rng.random((240, 420, 3)) * 255).astype(np.uint8) for _ in range(4)]
    path = write_recording(tmp_path, kind, {"/cam": [
        (lambda ts, t, a=frames[k % 4]: image_msg(ts, a, "rgb8", t)) for k in range(200)]})
    size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))
    assert size > 55e6
    read_frame(path, Choice("/cam", frame=0))  # imports and caches warmed
    before = _rchar()
    image, _ = read_frame(path, Choice("/cam", frame=150))
    read = _rchar() - before
    assert image.recording.frame == 150
    np.testing.assert_array_equal(np.rint(image.pixels * 255).astype(np.uint8), frames[150 % 4])
    assert read < 0.05 * size, f"read {read / 1e6:.1f} MB of a {size / 1e6:.0f} MB recording"


def test_image_inputs_do_not_import_rosbags(tmp_path, chart):
    _, display = chart
    png = tmp_path / "c.png"
    PILImage.fromarray(np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)).save(png)
    code = ("import sys\nfrom fidelity.cli import main\n"
            "try:\n    main(['audit', sys.argv[1], '-q'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'rosbags'))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code, str(png)], capture_output=True,
                         text=True, env=env, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_without_rosbags_a_recording_is_one_line_naming_the_extra(recordings):
    paths, _, _ = recordings
    code = ("import sys\nsys.modules['rosbags'] = None\nfrom fidelity.cli import main\n"
            "main(['audit', sys.argv[1], '--topic', '/cam/rgb8'])\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code, str(paths["ros1"])], capture_output=True,
                         text=True, env=env)
    assert out.returncode == 2
    assert out.stderr.strip() == ("fidelity: error: reading a ROS bag or MCAP file needs "
                                  "rosbags: pip install 'camera-fidelity[ros]'")


def test_a_sqlite3_bag_without_message_definitions_is_read_with_rosbags_types(chart, tmp_path):
    """Older rosbag2 sqlite3 bags hold no message definitions: the reader falls back on
    rosbags' own store of ROS 2 types, and the pixels are the same."""
    import sqlite3

    from fidelity.chart.recording import Choice, read_frame

    _, display = chart
    codes = np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)
    path = write_recording(tmp_path, "sqlite3", {"/cam": [
        lambda ts, t: image_msg(ts, codes, "rgb8", t)]})
    with sqlite3.connect(path / f"{path.name}.db3") as db:
        assert db.execute("SELECT COUNT(*) FROM message_definitions").fetchone()[0] > 0
        db.execute("DELETE FROM message_definitions")
    image, _ = read_frame(path, Choice("/cam"))
    np.testing.assert_array_equal(np.rint(image.pixels * 255).astype(np.uint8), codes)


@pytest.mark.parametrize(("kind", "compression"), [("sqlite3", "message"), ("mcap", "message"),
                                                   ("sqlite3", "file"), ("mcap", "storage")])
def test_zstd_compressed_ros2_bags_are_read(chart, tmp_path, kind, compression):
    """rosbag2's zstd compression (per message, per file, MCAP chunk compression): the frame
    chosen is read, the same pixels."""
    from fidelity.chart.recording import Choice, read_frame

    _, display = chart
    codes = np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)
    other = codes[::-1].copy()
    path = write_recording(tmp_path, kind, {"/cam": [
        lambda ts, t: image_msg(ts, other, "rgb8", t),
        lambda ts, t: image_msg(ts, codes, "rgb8", t)]}, compression)
    if compression == "storage":  # the MCAP file's chunks are compressed
        assert b"zstd" in next(path.glob("*.mcap")).read_bytes()
    else:
        assert f"compression_mode: {compression}" in (path / "metadata.yaml").read_text()
    image, _ = read_frame(path, Choice("/cam", frame=1))
    assert image.recording.frame == 1
    np.testing.assert_array_equal(np.rint(image.pixels * 255).astype(np.uint8), codes)


def _nv(rgb8: np.ndarray, encoding: str) -> np.ndarray:
    """RGB codes as a semi-planar 4:2:0 buffer ((3H/2, W): luma rows, then chroma pairs), by
    OpenCV's BT.601 encoder (I420 planes, interleaved here as NV12 or NV21)."""
    import cv2

    h, w = rgb8.shape[:2]
    i420 = cv2.cvtColor(np.ascontiguousarray(rgb8), cv2.COLOR_RGB2YUV_I420).reshape(-1)
    y = i420[: h * w].reshape(h, w)
    u = i420[h * w: h * w + h * w // 4].reshape(h // 2, w // 2)
    v = i420[h * w + h * w // 4:].reshape(h // 2, w // 2)
    first, second = (u, v) if encoding == "nv12" else (v, u)
    return np.vstack([y, np.stack([first, second], axis=-1).reshape(h // 2, w)])


@pytest.mark.parametrize("encoding", ["nv12", "nv21"])
def test_semi_planar_yuv420_agrees_with_opencv(encoding):
    """nv12 / nv21 (4:2:0, the chroma plane after the luma plane) against OpenCV's own
    conversion of the same buffer: within one code (OpenCV computes in fixed point), every
    byte value occurring; rows padded; ``height`` either the picture's (ROS 2 drivers) or the
    buffer's rows (rosbags-image's reading) gives the same picture."""
    import cv2

    buf = np.random.default_rng(5).integers(0, 256, (96, 128), dtype=np.uint8)  # picture 64
    code = cv2.COLOR_YUV2RGB_NV12 if encoding == "nv12" else cv2.COLOR_YUV2RGB_NV21
    theirs = cv2.cvtColor(buf, code).astype(np.int64)
    assert theirs.shape == (64, 128, 3) and theirs.min() == 0 and theirs.max() == 255
    padded = np.hstack([buf, np.full((96, 8), 77, np.uint8)]).reshape(-1)
    for height, data, step in ((64, buf.reshape(-1), 128), (64, padded, 136),
                               (96, buf.reshape(-1), 128)):
        ours = message_pixels(height, 128, encoding, False, step, data)
        assert ours[1:4] == ("uint8", ("R", "G", "B"), "srgb")
        diff = np.abs(np.rint(ours[0] * 255).astype(np.int64) - theirs)
        assert diff.max() <= 1 and diff.mean() < 0.05, (encoding, height, step)
    with pytest.raises(InputFileError, match="even width and height"):
        message_pixels(63, 128, encoding, False, 128, buf.reshape(-1))
    with pytest.raises(InputFileError, match="fewer than"):
        message_pixels(64, 128, encoding, False, 128, buf.reshape(-1)[:9000])
    assert encoding in supported_encodings()


@pytest.mark.parametrize("encoding", ["nv12", "nv21"])
def test_a_chart_recorded_as_nv12_or_nv21_measures_as_its_decoded_pixels(chart, corners,
                                                                         encoding, tmp_path):
    """A chart in a ROS 2 bag as nv12 / nv21 is audited as the PNG of OpenCV's decoding of the
    same buffer (within the one-code rounding difference), and its ΔE is close to the rgb8
    chart's (4:2:0 chroma is shared by 2 x 2 pixels: the windows inside the patches are
    flat)."""
    import cv2

    _, display = chart
    codes8 = np.clip(np.rint(display * 255), 0, 255).astype(np.uint8)
    h, w = codes8.shape[:2]
    codes8 = codes8[: h - h % 2, : w - w % 2]
    buf = _nv(codes8, encoding)

    def make(ts, t):
        return ts.types["sensor_msgs/msg/Image"](
            header=header(ts, t), height=codes8.shape[0], width=codes8.shape[1],
            encoding=encoding, is_bigendian=0, step=codes8.shape[1], data=buf.reshape(-1))

    bag = write_recording(tmp_path, "mcap", {"/cam/nv": [make, make]})
    got = measure_image(bag, corners, read=ReadOptions(topic="/cam/nv"))
    code = cv2.COLOR_YUV2RGB_NV12 if encoding == "nv12" else cv2.COLOR_YUV2RGB_NV21
    ref = tmp_path / "decoded.png"
    cv2.imwrite(str(ref), cv2.cvtColor(cv2.cvtColor(buf, code), cv2.COLOR_RGB2BGR))
    want = measure_image(ref, corners)
    assert got.mean_delta_e == pytest.approx(want.mean_delta_e, abs=0.02)
    rgb_png = tmp_path / "rgb.png"
    cv2.imwrite(str(rgb_png), cv2.cvtColor(codes8, cv2.COLOR_RGB2BGR))
    assert got.mean_delta_e == pytest.approx(measure_image(rgb_png, corners).mean_delta_e,
                                             abs=0.3)


def test_an_absolute_time_picks_the_nearest_message(recordings, corners, tmp_path):
    """--time as UNIX epoch seconds (@S) or ISO 8601 with its offset picks the message nearest
    to that instant, the same as the offset after the first message; the report's own
    time_utc, given back, names its message; outside the recording or without an offset is one
    line and exit 2."""
    from fidelity.chart.image import utc_text

    paths, _, _ = recordings
    path = paths["mcap"]
    near = T0 + STEP + 30_000_000  # 0.13 s after the first message: frame 1
    for spec in (f"@{near / 1e9:.3f}", utc_text(near), "2023-11-14T23:13:20.13+01:00"):
        got = measure_image(path, corners, read=ReadOptions(topic="/cam/rgb8", time=spec))
        assert got.image.recording.frame == 1, spec
        assert got.image.recording.time_ns == T0 + STEP
    again = measure_image(path, corners, read=ReadOptions(
        topic="/cam/rgb8", time=got.image.recording.to_json()["time_utc"]))
    assert again.image.recording.frame == 1
    out = _run(["audit", str(path), "--topic", "/cam/rgb8", "--time", "@1700000099",
                "--corners", _corner_text(corners), "-q"])
    assert out.exit_code == 2 and "is outside the recording (2023-11-14T22:13:20" in out.output
    err = _error(["audit", str(path), "--topic", "/cam/rgb8", "--time", "2023-11-14T22:13:20",
                  "--corners", _corner_text(corners)])
    assert "give the UTC offset" in err


@pytest.mark.parametrize("topic, colourspace", [("/cam/float", "Linear Rec.709 (sRGB)"),
                                                ("/cam/rgb8", "sRGB - Display")])
def test_a_recordings_frame_is_converted_by_opencolorio(recordings, corners, topic, colourspace):
    """--ocio-colourspace on a message's pixels: the built-in config's own linear sRGB and
    display sRGB convert to themselves, so the chart measures as without the conversion."""
    pytest.importorskip("PyOpenColorIO", reason="pip install 'camera-fidelity[ocio]'")
    paths, _, _ = recordings
    plain = measure_image(paths[KINDS[0]], corners, read=ReadOptions(topic=topic, frame=1))
    got = measure_image(paths[KINDS[0]], corners, read=ReadOptions(
        topic=topic, frame=1, ocio_colourspace=colourspace))
    assert got.image is not None and got.image.ocio is not None
    assert got.encoding == plain.encoding and got.image.recording == plain.image.recording
    np.testing.assert_allclose(got.measurement.delta_e, plain.measurement.delta_e, atol=2e-3)


def test_gate_frames_gates_each_selected_frame(recordings, corners, tmp_path):
    """--frames: each selected frame of the topic is a subject (its JUnit test case, its
    report, its message's SHA-256); frames 0 and 2 of every topic hold noise, not the chart."""
    paths, _, folder = recordings
    c = _corner_text(corners)
    png = json.loads(_run_json(["audit", str(folder / "c8.png"), "--corners", c], tmp_path))
    limit = str(png["mean_delta_e"] + 0.001)
    junit = tmp_path / "f.xml"
    r = _run(["gate", str(paths["ros1"]), "--topic", "/cam/rgb8", "--frames", "0:3",
              "--corners", c, "--max-delta-e", limit, "--junit", str(junit),
              "--json", str(tmp_path / "f"), "--evidence", str(tmp_path / "e.json"),
              "--html", str(tmp_path / "h")])
    assert r.exit_code == 1, r.output  # the noise frames fail
    # the overview page beside the three reports: a row each, linked, and the frames' plot
    page = (tmp_path / "h" / "index.html").read_text()
    assert "1 of 3 passed" in page and page.count('href="drive.bag.frame') == 3
    assert all((tmp_path / "h" / f"drive.bag.frame{k}.html").is_file() for k in range(3))
    assert 'aria-label="chart ΔE over the frames of' in page
    names = [case.get("name") for case in ET.parse(junit).getroot().iter("testcase")]
    assert [n.rsplit(" ", 2)[1:] for n in names] == [["frame", "0"], ["frame", "1"],
                                                     ["frame", "2"]]
    docs = [json.loads((tmp_path / "f" / f"drive.bag.frame{k}.json").read_text())
            for k in range(3)]
    assert [d["source"]["recording"]["frame"] for d in docs] == [0, 1, 2]
    assert docs[1]["mean_delta_e"] == pytest.approx(png["mean_delta_e"], abs=1e-9)
    assert min(d["mean_delta_e"] for d in docs) == docs[1]["mean_delta_e"]
    assert re.search(r"mean ΔE00 over 3 measured frames: min [\d.]+ \(frame 1\)", r.output)
    record = json.loads((tmp_path / "e.json").read_text())
    shas = [s["inputs"][0]["sha256"] for s in record["subjects"]]
    assert len(set(shas)) == 3 and all(len(h) == 64 for h in shas)
    one = _run(["gate", str(paths["mcap"]), "--topic", "/cam/rgb8", "--frames", "-2,1",
                "--corners", c, "--max-delta-e", limit])
    assert one.exit_code == 0 and "frame 1" in one.output  # -2 is 1: gated once


def test_audit_frames_audits_each_selected_frame(recordings, corners, tmp_path):
    """audit --frames: each selected frame its own report, as ``--frame K`` alone gives it;
    the noise frames (0 and 2) one error line each, exit 2; an overview with the frames'
    plot, and the summary over the frames measured."""
    paths, _, _ = recordings
    c = _corner_text(corners)
    out = tmp_path / "a"
    r = CliRunner().invoke(main, ["audit", str(paths["ros1"]), "--topic", "/cam/rgb8",
                                  "--frames", "0:3", "--json", str(out), "--html", str(out)])
    assert r.exit_code == 2, r.output
    assert r.stderr.count("fidelity: error:") == 2
    assert "topic /cam/rgb8 frame 0: no colour chart found" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["drive.bag.frame1.html",
                                                     "drive.bag.frame1.json", "index.html"]
    alone = json.loads(_run_json(["audit", str(paths["ros1"]), "--topic", "/cam/rgb8",
                                  "--frame", "1", "--corners", c], tmp_path))
    got = json.loads((out / "drive.bag.frame1.json").read_text())
    assert got["source"]["recording"]["frame"] == 1
    assert got["mean_delta_e"] == pytest.approx(alone["mean_delta_e"], abs=1e-6)
    assert "audit: 1 of 3 frames measured, 2 could not be" in r.stdout
    assert re.search(r"mean ΔE00 over 1 measured frame: min [\d.]+ \(frame 1\)", r.stdout)
    page = (out / "index.html").read_text()
    assert "1 of 3 frames measured" in page and "2 not measured" in page
    assert page.count('href="drive.bag.frame1.html"') == 1
    assert 'aria-label="chart ΔE over the frames of' in page
    both = CliRunner().invoke(main, ["audit", str(paths["ros1"]), "--topic", "/cam/rgb8",
                                     "--frames", "1", "--frame", "1"])
    assert both.exit_code == 2 and "not both" in both.output


@pytest.mark.parametrize("args, message", [
    (["--frames", "5"], "has 3 messages (frames 0 to 2); there is no frame 5"),
    (["--frames", "1:1"], "--frames 1:1 selects none of topic"),
    (["--frames", "a"], "--frames a: expected frame numbers"),
    (["--frames", "0::0"], "the step must be a whole number above 0"),
    (["--frames", "1", "--frame", "1"], "give --frames, or --frame N or --time T, not both"),
])
def test_gate_frames_bad_selections_are_one_line_exit_2(recordings, args, message):
    paths, _, _ = recordings
    r = CliRunner().invoke(main, ["gate", str(paths["ros1"]), "--topic", "/cam/rgb8",
                                  "--max-delta-e", "3", *args])
    assert r.exit_code == 2, r.output
    assert message in r.output


def test_gate_frames_needs_recordings(recordings):
    _, _, folder = recordings
    r = CliRunner().invoke(main, ["gate", str(folder / "c8.png"), "--frames", "0:2",
                                  "--max-delta-e", "3"])
    assert r.exit_code == 2 and r.stderr.startswith("fidelity: error: ")
    r = CliRunner().invoke(main, ["gate", "--camera", "ideal", "--frames", "0:2"])
    assert r.exit_code == 2 and "--frames applies to recordings" in r.output


def test_an_error_about_a_frame_names_the_topic_and_frame(recordings):
    paths, _, _ = recordings
    r = CliRunner().invoke(main, ["gate", str(paths["ros1"]), "--topic", "/cam/rgb8",
                                  "--frames", "0,1", "--max-delta-e", "3"])
    assert r.exit_code == 2, r.output
    assert f"fidelity: error: {paths['ros1']}: topic /cam/rgb8 frame 0: no colour chart found" \
        in r.stderr
    assert r.stderr.count("fidelity: error:") == 1  # frame 1 holds the chart
