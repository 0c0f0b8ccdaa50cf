"""A synthetic chart for the chart noise and sharpness tests: the reference chart's linear
colours on a dark frame, turned by a known angle, blurred by a Gaussian of known sigma in
linear light (4x supersampled, box-averaged to the pixel aperture), with Poisson-Gaussian noise
of known read noise and gain."""

from __future__ import annotations

import math

import numpy as np

from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference

SUPERSAMPLE = 4


def chart_linear() -> np.ndarray:
    """The reference chart's 24 patch colours in linear sRGB, ``(24, 3)``."""
    return np.asarray(cm.linearize_srgb(load_reference("safecolor").srgb), np.float64)


def homography(angle_deg: float, pitch: float, centre: tuple[float, float]) -> np.ndarray:
    """Grid -> image: the chart's centre (u 2.5, v 1.5) at ``centre``, turned ``angle_deg``."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    rot = np.array([[c * pitch, -s * pitch], [s * pitch, c * pitch]])
    t = np.array(centre) - rot @ np.array([2.5, 1.5])
    return np.array([[rot[0, 0], rot[0, 1], t[0]], [rot[1, 0], rot[1, 1], t[1]], [0, 0, 1.0]])


def corners(h: np.ndarray) -> np.ndarray:
    """The corner-patch centres ``(4, 2)`` (dark skin, bluish green, black, white)."""
    uv = np.array([[0, 0], [5, 0], [5, 3], [0, 3]], float)
    p = np.c_[uv, np.ones(4)] @ h.T
    return p[:, :2] / p[:, 2:]


def render(*, angle_deg: float = 5.0, sigma: float = 1.0, pitch: float = 100.0,
           size: tuple[int, int] = (560, 760), patch_fraction: float = 0.84,
           frame: float = 0.03, read_noise: float = 0.0, gain: float = 0.0,
           seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``(image (H, W, 3) float64 linear, homography)``."""
    from scipy.ndimage import gaussian_filter  # noqa: PLC0415 (scipy at the call)

    height, width = size
    h = homography(angle_deg, pitch, ((width - 1) / 2, (height - 1) / 2))
    n = SUPERSAMPLE
    # sub-pixel centres of the supersampled grid, in image pixels
    ys = (np.arange(height * n) + 0.5) / n - 0.5
    xs = (np.arange(width * n) + 0.5) / n - 0.5
    xx, yy = np.meshgrid(xs, ys)
    hi = np.linalg.inv(h)
    w = hi[2, 0] * xx + hi[2, 1] * yy + hi[2, 2]
    u = (hi[0, 0] * xx + hi[0, 1] * yy + hi[0, 2]) / w
    v = (hi[1, 0] * xx + hi[1, 1] * yy + hi[1, 2]) / w
    col, row = np.rint(u), np.rint(v)
    inside = ((np.abs(u - col) <= patch_fraction / 2) & (np.abs(v - row) <= patch_fraction / 2)
              & (col >= 0) & (col <= 5) & (row >= 0) & (row <= 3))
    idx = np.where(inside, row * 6 + col, 0).astype(int)
    rgb = chart_linear()
    img = np.empty((height, width, 3))
    for ch in range(3):
        plane = np.where(inside, rgb[idx, ch], frame)
        if sigma > 0:
            plane = gaussian_filter(plane, sigma * n, mode="nearest", truncate=5.0)
        img[..., ch] = plane.reshape(height, n, width, n).mean(axis=(1, 3))
    rng = np.random.default_rng(seed)
    if gain > 0:
        img = gain * rng.poisson(np.clip(img, 0, None) / gain)
    if read_noise > 0:
        img = img + rng.normal(0.0, read_noise, img.shape)
    return img, h
