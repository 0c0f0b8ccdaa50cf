"""Plain colour-science implementations of SAFE-COLOR Table I, written straight from the formulas.

The anchor for the transform benchmark and the second method in the transform tests: built only
from colour-science's HSV, sRGB transfer, RGB <-> XYZ and Lab functions, with no shortcuts.
"""

from __future__ import annotations

from collections.abc import Callable

import colour
import numpy as np

D65_XY = np.array([0.3127, 0.3290])
SRGB = colour.RGB_COLOURSPACES["sRGB"].copy()
SRGB.use_derived_transformation_matrices(True)


def _hsv_op(rgb: np.ndarray, channel: int,
            fn: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    hsv = colour.RGB_to_HSV(rgb)
    hsv[..., channel] = fn(hsv[..., channel])
    return colour.HSV_to_RGB(hsv)


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    return colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, SRGB, apply_cctf_decoding=True), D65_XY)


def reference_transform(name: str, rgb: np.ndarray, p: float) -> np.ndarray:
    """Table I transform ``name`` with parameter ``p`` on sRGB ``rgb`` in [0, 1]."""
    if name.startswith("brightness"):
        return np.clip(rgb + p, 0, 1)
    if name.startswith("contrast"):
        return np.clip(0.5 + p * (rgb - 0.5), 0, 1)
    if name.startswith("gamma"):
        lin = colour.models.eotf_sRGB(rgb)
        return np.clip(colour.models.eotf_inverse_sRGB(lin**p), 0, 1)
    if name.startswith("saturation"):
        return _hsv_op(rgb, 1, lambda s: np.clip(s * p, 0, 1))
    if name == "hue":
        return _hsv_op(rgb, 0, lambda h: np.mod(h + p / 360.0, 1.0))
    if name == "pull_mean":
        lab = srgb_to_lab(rgb)
        m = lab.reshape(-1, 3).mean(axis=0)
        xyz = colour.Lab_to_XYZ(m + p * (lab - m), D65_XY)
        return np.clip(colour.XYZ_to_RGB(xyz, SRGB, apply_cctf_encoding=True), 0, 1)
    raise KeyError(name)
