"""A video's frame read by fidelity.chart.video against FFmpeg's own conversion of the same
frame (a second implementation: swscale with accurate rounding and full chroma interpolation,
honouring the tags), on clips FFmpeg encodes from the calibration chart."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fidelity.chart.image import Recording, read_image
from fidelity.chart.read import DEFAULT_READ, ReadOptions, read_again, read_input
from fidelity.chart.video import read_frame, upsample, ycbcr_to_rgb
from fidelity.coco.tables.degradation import calibration_chart
from fidelity.core.errors import InputFileError
from fidelity.measure.pixels import measure_image

pytest.importorskip("av")
FFMPEG = shutil.which("ffmpeg")
pytestmark = pytest.mark.skipif(FFMPEG is None, reason="ffmpeg is not installed")

#: ΔE00 by which fidelity's reading and FFmpeg's may differ (chroma upsampling: nearest here,
#: filtered in swscale; flat patches leave little to differ).
TOLERANCE = 0.05
#: FFmpeg's accurate swscale conversion to 16-bit RGB, with the matrix and range given.
_SWS = "accurate_rnd+full_chroma_int+full_chroma_inp+bitexact"


def _ffmpeg(*args: str) -> None:
    assert FFMPEG is not None
    run = subprocess.run([FFMPEG, "-v", "error", "-y", *args], capture_output=True, text=True,
                         check=False)
    if run.returncode != 0:
        if "Unknown encoder" in run.stderr or "Encoder not found" in run.stderr:
            pytest.skip(f"ffmpeg lacks an encoder: {run.stderr.strip()}")
        raise AssertionError(run.stderr)


@pytest.fixture(scope="module")
def chart(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    image, corners = calibration_chart()
    path = tmp_path_factory.mktemp("video") / "chart.png"
    iio.imwrite(path, image)
    return path, corners


def _encode(chart_png: Path, out: Path, *, codec: str, pix_fmt: str, matrix: str | None,
            range_: str | None, frames: int = 3, tag: str | None = None) -> None:
    """A clip of the chart: RGB -> Y'CbCr by ``matrix``/``range_`` (swscale), tagged with
    ``tag`` (default: ``matrix``; "" for untagged)."""
    vf = [f"scale=out_color_matrix={matrix}:out_range={'tv' if range_ == 'limited' else 'pc'}"
          f":flags={_SWS}"] if matrix else []
    vf.append(f"format={pix_fmt}")
    tags: list[str] = []
    tagged = matrix if tag is None else tag
    if tagged:
        tags = ["-colorspace", tagged, "-color_primaries", "bt709", "-color_trc", "bt709",
                "-color_range", "tv" if range_ == "limited" else "pc"]
    _ffmpeg("-loop", "1", "-i", str(chart_png), "-frames:v", str(frames), "-vf", ",".join(vf),
            "-c:v", codec, *(["-qp", "0"] if codec in ("libx264", "libx265") else []),
            *tags, str(out))


def _reference_png(clip: Path, out: Path, *, matrix: str | None, range_: str | None,
                   select: int = 0) -> None:
    """FFmpeg's decode of frame ``select`` to 16-bit RGB, converted by ``matrix``/``range_``."""
    conv = (f"scale=in_color_matrix={matrix}:in_range={'tv' if range_ == 'limited' else 'pc'}"
            f":out_range=pc:flags={_SWS}," if matrix else "")
    _ffmpeg("-i", str(clip), "-vf", f"select=eq(n\\,{select}),{conv}format=rgb48be",
            "-frames:v", "1", str(out))


def _mean(path: Path, corners: np.ndarray, read: ReadOptions = DEFAULT_READ) -> float:
    return float(measure_image(path, corners, read=read).mean_delta_e)


CASES = [
    # name, suffix, codec, pix_fmt, matrix, range (None: RGB)
    ("h264-709-limited", ".mp4", "libx264", "yuv420p", "bt709", "limited"),
    ("h264-709-full", ".mp4", "libx264", "yuv420p", "bt709", "full"),
    ("h264-601-limited", ".mp4", "libx264", "yuv420p", "bt470bg", "limited"),
    ("h265-10bit", ".mkv", "libx265", "yuv420p10le", "bt709", "limited"),
    ("ffv1-bgr0", ".mkv", "ffv1", "bgr0", None, None),
    ("ffv1-gbrp10", ".mkv", "ffv1", "gbrp10le", None, None),
]


@pytest.mark.parametrize("name,suffix,codec,pix_fmt,matrix,range_", CASES,
                         ids=[c[0] for c in CASES])
def test_frame_agrees_with_ffmpeg(tmp_path: Path, chart: tuple[Path, np.ndarray], name: str,
                                  suffix: str, codec: str, pix_fmt: str, matrix: str | None,
                                  range_: str | None) -> None:
    png, corners = chart
    clip = tmp_path / f"{name}{suffix}"
    _encode(png, clip, codec=codec, pix_fmt=pix_fmt, matrix=matrix, range_=range_)
    ref = tmp_path / "ref.png"
    _reference_png(clip, ref, matrix=matrix, range_=range_)
    ours, theirs = _mean(clip, corners), _mean(ref, corners)
    assert abs(ours - theirs) < TOLERANCE, (ours, theirs)
    image, _ = read_frame(clip)
    rec = image.recording
    assert rec is not None and rec.stream is not None and rec.kind == "video"
    assert rec.stream["assumed"] == ""
    want = {"bt709": "bt709", "bt470bg": "bt601", None: "rgb"}[matrix]
    assert rec.stream["matrix"] == want and rec.stream["range"] == (range_ or "full")
    assert rec.stream["pix_fmt"].replace("yuvj", "yuv") == pix_fmt
    if pix_fmt == "bgr0":  # lossless 8-bit RGB: the chart's own codes
        np.testing.assert_array_equal(np.rint(image.pixels * 255), iio.imread(png))


def test_untagged_clip_assumes_bt601_limited_below_720_lines(
        tmp_path: Path, chart: tuple[Path, np.ndarray]) -> None:
    png, corners = chart
    clip = tmp_path / "untagged.mp4"
    _encode(png, clip, codec="libx264", pix_fmt="yuv420p", matrix="bt470bg", range_="limited",
            tag="")
    ref = tmp_path / "ref.png"
    _reference_png(clip, ref, matrix="bt601", range_="limited")
    assert abs(_mean(clip, corners) - _mean(ref, corners)) < TOLERANCE
    rec = read_frame(clip)[0].recording
    assert rec is not None and rec.stream is not None
    assert rec.stream["assumed"] == "matrix, range"
    assert "(matrix, range assumed)" in rec.describe()


def test_mis_tagged_clip_moves_delta_e_beyond_the_tolerance(
        tmp_path: Path, chart: tuple[Path, np.ndarray]) -> None:
    """BT.601 data tagged BT.709: the tag is obeyed (the result differs from reading it as
    BT.601 by more than the tolerance), and --video-matrix bt601 puts it right."""
    png, corners = chart
    clip = tmp_path / "mistagged.mp4"
    _encode(png, clip, codec="libx264", pix_fmt="yuv420p", matrix="bt470bg", range_="limited",
            tag="bt709")
    as_tagged = _mean(clip, corners)
    overridden = _mean(clip, corners, ReadOptions(video_matrix="bt601"))
    ref = tmp_path / "ref.png"
    _reference_png(clip, ref, matrix="bt601", range_="limited")
    right = _mean(ref, corners)
    assert abs(overridden - right) < TOLERANCE
    assert abs(as_tagged - right) > 10 * TOLERANCE


def test_seek_to_frame_45_of_60_equals_ffmpeg(tmp_path: Path,
                                              chart: tuple[Path, np.ndarray]) -> None:
    png, _ = chart
    clip = tmp_path / "sixty.mp4"
    # a moving frame number makes each frame differ; keyframes every 12 frames
    _ffmpeg("-loop", "1", "-i", str(png), "-frames:v", "60", "-vf",
            "drawtext=text='%{n}':x=10:y=10:fontsize=48:fontcolor=white,format=yuv444p",
            "-g", "12", "-c:v", "libx264", "-qp", "0", "-colorspace", "bt709",
            "-color_range", "tv", str(clip))
    ref = tmp_path / "ref45.png"
    _reference_png(clip, ref, matrix="bt709", range_="limited", select=45)
    image, _ = read_frame(clip, frame=45)
    theirs = read_image(ref).pixels
    assert image.recording is not None and image.recording.frame == 45
    # 4:4:4 (no chroma filter to differ): within swscale's rounding of 16-bit RGB
    assert float(np.abs(image.pixels - theirs).max()) < 2 / 255
    again = read_frame(clip, time=1.79)[0]  # 25 fps (FFmpeg's -loop default): frame 45
    np.testing.assert_array_equal(again.pixels, image.pixels)
    assert not np.array_equal(read_frame(clip, frame=44)[0].pixels, image.pixels)


def test_read_again_reads_the_same_frame(tmp_path: Path, chart: tuple[Path, np.ndarray]
                                         ) -> None:
    png, _ = chart
    clip = tmp_path / "c.mp4"
    _encode(png, clip, codec="libx264", pix_fmt="yuv420p", matrix="bt709", range_="limited")
    image, sha = read_input(clip, ReadOptions(frame=2, video_range="full"))
    info = image.info(sha)
    assert info.recording is not None
    again = read_again(info)
    np.testing.assert_array_equal(again.pixels, image.pixels)
    rec = info.recording
    assert Recording.from_json(rec.to_json()) == rec


def test_conversion_closed_form() -> None:
    """Limited-range BT.709 codes of the 75 % colour bars (ITU-R BT.709 Table; SMPTE RP 219
    8-bit codes: 75 % red Y'Cb'Cr' 51, 109, 212) to R'G'B' (0.75, 0, 0)."""
    rgb = ycbcr_to_rgb(np.array([[51]]), np.array([[109]]), np.array([[212]]), bits=8,
                       matrix="bt709", range_="limited")
    np.testing.assert_allclose(rgb[0, 0], [0.75, 0.0, 0.0], atol=0.004)
    # 10-bit white and black
    rgb10 = ycbcr_to_rgb(np.array([[940, 64]]), np.array([[512, 512]]),
                         np.array([[512, 512]]), bits=10, matrix="bt2020", range_="limited")
    np.testing.assert_allclose(rgb10[0], [[1, 1, 1], [0, 0, 0]], atol=1e-6)
    assert upsample(np.array([[1, 2]]), 2, 4).tolist() == [[1, 1, 2, 2], [1, 1, 2, 2]]


def test_bad_inputs(tmp_path: Path, chart: tuple[Path, np.ndarray]) -> None:
    png, _ = chart
    text = tmp_path / "notes.mp4"
    text.write_text("not a video\n")
    with pytest.raises(InputFileError, match=r"notes\.mp4: not a video"):
        read_frame(text)
    image_named = tmp_path / "still.mkv"
    shutil.copyfile(png, image_named)
    with pytest.raises(InputFileError, match=r"still\.mkv: not a video"):
        read_frame(image_named)
    clip = tmp_path / "three.mp4"
    _encode(png, clip, codec="libx264", pix_fmt="yuv420p", matrix="bt709", range_="limited")
    with pytest.raises(InputFileError, match=r"frame 3 is out of range \(the video has 3 "
                                             r"frames: 0 to 2\)"):
        read_frame(clip, frame=3)
    with pytest.raises(InputFileError, match="after the last frame"):
        read_frame(clip, time=5.0)
    with pytest.raises(InputFileError, match="before the first frame"):
        read_frame(clip, time=-1.0)
    assert read_frame(clip, frame=-1)[0].recording.frame == 2  # type: ignore[union-attr]


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fidelity", "--no-config", *args],
                          capture_output=True, text=True, check=False, timeout=300)


def test_audit_command_reads_a_video_frame(tmp_path: Path,
                                           chart: tuple[Path, np.ndarray]) -> None:
    png, corners = chart
    clip = tmp_path / "c.mp4"
    _encode(png, clip, codec="libx264", pix_fmt="yuv420p", matrix="bt709", range_="limited")
    text = ",".join(f"{v:.3f}" for v in corners.ravel())
    run = _cli("audit", str(clip), "--corners", text, "--frame", "2")
    assert run.returncode == 0, run.stderr
    assert "video: frame 2 of 3 at 0.080 s (H.264 yuv420p, BT.709 matrix, limited range, " \
           "BT.709 transfer)" in run.stdout
    bad = _cli("audit", str(png), "--corners", text, "--video-range", "full")
    assert bad.returncode == 2
    assert bad.stderr.startswith("fidelity: error: ") and "--video-range" in bad.stderr


def _has_filter(name: str) -> bool:
    assert FFMPEG is not None
    run = subprocess.run([FFMPEG, "-hide_banner", "-filters"], capture_output=True, text=True,
                         check=False)
    return any(line.split()[1:2] == [name] for line in run.stdout.splitlines())


@pytest.mark.parametrize("primaries,zimg,matrix,zmatrix", [
    ("bt2020", "2020", "bt2020", "2020_ncl"),
    ("smpte170m", "170m", "bt470bg", "170m"),
])
def test_primaries_are_converted_as_zscale_converts_them(
        tmp_path: Path, chart: tuple[Path, np.ndarray], primaries: str, zimg: str, matrix: str,
        zmatrix: str) -> None:
    """A clip tagged with BT.2020 (or SMPTE 170M) primaries: its frame's linear values are
    converted to sRGB's primaries by the 3 x 3 of the tagged chromaticities. Against zimg
    (ffmpeg's zscale: the same primaries conversion between the sRGB transfers the reader
    takes the values in, in floating point, with the exact transfer functions: zimg's
    approximate ones, its default, are off by up to 1.2e-3, 0.2 ΔE on the near-neutral patches),
    per patch within TOLERANCE; ignoring the tag
    moves a patch's ΔE by more than 5 times that."""
    if not _has_filter("zscale"):
        pytest.skip("ffmpeg has no zscale filter (zimg) to convert the primaries with")
    png, corners = chart
    clip = tmp_path / f"{primaries}.mkv"
    _ffmpeg("-loop", "1", "-i", str(png), "-frames:v", "2", "-vf",
            f"scale=out_color_matrix={matrix}:out_range=tv:flags={_SWS},format=yuv444p10le",
            "-c:v", "ffv1", "-colorspace", "bt2020nc" if matrix == "bt2020" else matrix,
            "-color_primaries", primaries, "-color_trc", "bt709", "-color_range", "tv",
            str(clip))
    ref = tmp_path / "ref.png"
    _ffmpeg("-i", str(clip), "-vf",
            f"zscale=primariesin={zimg}:primaries=709:transferin=iec61966-2-1:"
            f"transfer=iec61966-2-1:matrixin={zmatrix}:matrix=gbr:rangein=limited:range=full:"
            "dither=none:agamma=false,format=gbrp16le,format=rgb48be", "-frames:v", "1", str(ref))
    image, _ = read_frame(clip)
    assert image.recording is not None and image.recording.stream is not None
    assert image.recording.stream["primaries"] == primaries
    assert "primaries converted to sRGB's" in image.recording.describe()
    ours = measure_image(clip, corners)
    theirs = measure_image(ref, corners)
    np.testing.assert_allclose(ours.measurement.delta_e, theirs.measurement.delta_e,
                               atol=TOLERANCE)
    ignored = measure_image(clip, corners, read=ReadOptions(colourspace="sRGB"))
    moved = np.abs(np.asarray(ignored.measurement.delta_e) - np.asarray(ours.measurement.delta_e))
    assert moved.max() > 5 * TOLERANCE
