"""Several frames of a video: each frame audited (``--frames`` reads frame N by seeking), and the
temporal and fixed-pattern noise of the stack (EMVA 1288 4.0) against the noise injected into
the frames. Clips are FFV1 16-bit RGB written by Debian's ffmpeg from the calibration chart
with known per-frame (temporal) and per-pixel (fixed-pattern) noise added in linear light, the
same noise on R, G and B, so that the luminance's noise is the injected one."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fidelity.chart.read import ReadOptions
from fidelity.coco.tables.degradation import calibration_chart
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference
from fidelity.core.resources import resource_dir
from fidelity.pipeline.check import audit_images
from fidelity.pipeline.frames import MAX_CORNER_SHIFT, frames_noise

pytest.importorskip("av", reason="PyAV (the video extra) is not installed")
FFMPEG = shutil.which("ffmpeg")
pytestmark = pytest.mark.skipif(FFMPEG is None, reason="ffmpeg is not installed")

FRAMES = 5


def _clip(out: Path, *, sigma: float = 0.0, fpn: float = 0.0, gain: float = 0.0,
          move: int | None = None) -> np.ndarray:
    """An FFV1 gbrp16le clip of :data:`FRAMES` frames of the chart with noise in linear light:
    temporal variance ``sigma**2 + gain * mu`` (fresh each frame), fixed pattern ``fpn`` (the
    same each frame); frame ``move`` shifted 2 px right. Returns the chart's corners."""
    image, corners = calibration_chart()
    lin = cm.linearize_srgb(image.astype(np.float64) / 255.0)
    pattern = np.random.default_rng(1).normal(0.0, 1.0, lin.shape[:2])[..., None] * fpn
    data = []
    for k in range(FRAMES):
        z = np.random.default_rng(100 + k).normal(0.0, 1.0, lin.shape[:2])[..., None]
        sd = np.sqrt(sigma ** 2 + gain * lin.mean(axis=2, keepdims=True))
        f = np.clip(lin + pattern + z * sd, 0.0, 1.0)
        if k == move:
            f = np.roll(f, 2, axis=1)
        data.append(np.round(cm.delinearize_srgb(f) * 65535).astype("<u2").tobytes())
    h, w = lin.shape[:2]
    assert FFMPEG is not None
    run = subprocess.run([FFMPEG, "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb48le",
                          "-s", f"{w}x{h}", "-framerate", "25", "-i", "-", "-c:v", "ffv1",
                          "-pix_fmt", "gbrp16le", str(out)], input=b"".join(data),
                         capture_output=True, check=False)
    if run.returncode != 0:
        pytest.skip(f"ffmpeg cannot write FFV1 gbrp16le: {run.stderr.decode().strip()}")
    return np.asarray(corners)


def _noise(clip: Path, corners: str | None = None):  # type: ignore[no-untyped-def]
    frames = list(range(FRAMES))
    cases = audit_images([clip] * FRAMES, corners, read=ReadOptions(), frames=frames)
    assert all(c.report is not None for c in cases), [c.error for c in cases]
    return frames_noise(clip, frames, [c.report for c in cases], ReadOptions(),
                        load_reference("scene"))


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fidelity", "--no-config", *args],
                          capture_output=True, text=True, check=False, timeout=300)


def test_audit_frames_of_a_video_separates_temporal_noise(tmp_path: Path) -> None:
    clip = tmp_path / "noisy.mkv"
    sigma = 0.01
    _clip(clip, sigma=sigma)
    run = _cli("audit", str(clip), "--frames", "0:5", "--json", str(tmp_path / "j") + "/",
               "--html", str(tmp_path / "j") + "/")
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""
    doc = json.loads((tmp_path / "j" / "noisy.mkv.frames.json").read_text())
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(doc, json.loads((resource_dir("data") / "schemas" /
                                         "frames.schema.json").read_text()))
    data = doc["frames_noise"]
    assert data["stacked"] and data["frames"] == list(range(FRAMES))
    assert data["corner_shift_px"] < MAX_CORNER_SHIFT  # the chart found in each frame
    assert len(data["patches"]) == 6
    for p in data["patches"]:
        # the injected temporal σ within 3 standard uncertainties (u(σ) = u(σ²) / 2σ)
        u = p["u_temporal_variance"] / (2 * p["temporal_noise"])
        assert abs(p["temporal_noise"] - sigma) < 3 * u, p
        # no fixed pattern injected: its variance is 0 within 3 u
        assert abs(p["spatial_variance"]) < 3 * p["u_spatial_variance"], p
    grey = next(p for p in data["patches"] if p["patch"] == data["grey_patch"])
    assert grey["snr"] == pytest.approx(grey["mean"] / grey["temporal_noise"])
    assert (tmp_path / "j" / "noisy.mkv.frame4.json").is_file()  # each frame its own report
    assert "noise over 5 frames at neutral 5" in run.stdout
    page = (tmp_path / "j" / "index.html").read_text()
    assert "Noise over the frames" in page and page.count("(0 within 2u)") == 6


def test_fixed_pattern_noise_is_separated(tmp_path: Path) -> None:
    clip = tmp_path / "fpn.mkv"
    corners = _clip(clip, sigma=0.01, fpn=0.005)
    noise = _noise(clip, ",".join(f"{v:.3f}" for v in corners.ravel()))
    assert noise.stacked and noise.corner_shift == 0.0
    for p in noise.patches:
        if p.noise.mean < 0.05:  # black: the pattern clipped at 0
            continue
        u_t = p.noise.u_temporal_variance / (2 * p.noise.temporal_noise)
        assert abs(p.noise.temporal_noise - 0.01) < 3 * u_t
        u_f = p.noise.u_spatial_variance / (2 * p.noise.fixed_pattern_noise)
        # the realised pattern's σ over ~1700 pixels is 0.005 within 0.005 * sqrt(1/2n) ~ 1 %
        assert abs(p.noise.fixed_pattern_noise - 0.005) < 3 * math.hypot(u_f, 0.005 * 0.02)


def test_photon_transfer_on_temporal_variance(tmp_path: Path) -> None:
    clip = tmp_path / "shot.mkv"
    read_var, gain = 1e-5, 2e-4
    corners = _clip(clip, sigma=math.sqrt(read_var), gain=gain, fpn=0.004)
    noise = _noise(clip, ",".join(f"{v:.3f}" for v in corners.ravel()))
    t = noise.transfer
    assert t is not None, noise.transfer_refusal
    # the line on the temporal variances recovers the injected slope and intercept; the fixed
    # pattern (which a one-frame estimate would count) is not in it
    assert abs(t.gain - gain) < 3 * t.u_gain and t.u_gain < 0.1 * gain
    assert abs(t.read_variance - read_var) < 3 * t.u_read_variance


def test_frames_where_the_chart_moved_are_not_stacked(tmp_path: Path) -> None:
    clip = tmp_path / "moved.mkv"
    _clip(clip, sigma=0.005, move=3)
    noise = _noise(clip)
    assert not noise.stacked and not noise.patches
    assert noise.corner_shift is not None and noise.corner_shift > 1.5
    assert noise.reason is not None and "moved" in noise.reason
    run = _cli("gate", str(clip), "--frames", "0:5", "--max-delta-e", "5")
    assert run.returncode in (0, 1), run.stderr  # each frame gated; the stack refused
    assert "moved.mkv: noise over the frames not measured: the chart moved" in run.stdout


def test_frames_out_of_range_of_a_video_is_one_line_exit_2(tmp_path: Path) -> None:
    clip = tmp_path / "short.mkv"
    _clip(clip)
    for sel, words in (("0,7", "the video has 5 frames (frames 0 to 4); there is no frame 7"),
                       ("9:", "--frames 9: selects none of the video's 5 frames")):
        run = _cli("audit", str(clip), "--frames", sel)
        assert run.returncode == 2
        assert run.stderr.startswith("fidelity: error: ") and words in run.stderr
        assert len(run.stderr.strip().splitlines()) == 1
