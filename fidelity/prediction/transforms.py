"""The SAFE-COLOR single-parameter colour transforms (Table I of the paper).

Each transform maps encoded sRGB in [0, 1]^3 to encoded sRGB in [0, 1]^3 (``shared/reference/
safecolor.md``, "The single-parameter transforms"):

=================  ===========================================================  =============
transform           formula                                                      range
=================  ===========================================================  =============
brightness(p, β)    clip(p + β)                                                  [-1, 1]
contrast(p, c)      clip(0.5 + c (p - 0.5))                                      [0, 50]
saturation(p, s)    HSV2RGB(H, clip(s S), V)                                     [0, 50]
gamma(p, γ)         clip(delinearize_srgb(linearize_srgb(p)^γ))                  [0.01, 10]
hue(p, h)           HSV2RGB((H + h/360) mod 1, S, V)                             [-180, 180]
pull_mean(p, α)     clip(Lab2RGB(mean_Lab + α (RGB2Lab(p) - mean_Lab)))          [0, 1]
=================  ===========================================================  =============

clip() is channel-wise to [0, 1]; HSV is the hexcone model (Smith 1978). ``mean_Lab`` is the
mean CIELAB colour of the whole image (all pixels; for the chart, all patches). The Lab2RGB
result of pull_mean is clipped to [0, 1] like every other transform's output, so that every
transform yields a displayable image.

The registry :data:`TRANSFORMS` holds the ten directional transforms of the paper (one
parameter interval per direction). All functions are pure: inputs are never modified; float32
input gives float32 output. ``param`` may be a scalar or an array broadcastable to
``rgb.shape[:-1]`` (used to evaluate many parameters at once).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.colorimetry import delinearize_srgb, lab_to_srgb, linearize_srgb, srgb_to_lab
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

__all__ = [
    "TRANSFORMS",
    "TransformSpec",
    "apply_transform",
    "brightness",
    "contrast",
    "gamma",
    "get_transform",
    "hsv_to_rgb",
    "hue",
    "pull_mean",
    "rgb_to_hsv",
    "saturation",
    "validate_rgb",
]

FloatArray = NDArray[np.floating[Any]]


def _float_rgb(rgb: ArrayLike) -> FloatArray:
    a = np.asarray(rgb)
    if a.dtype not in (np.float32, np.float64):
        a = a.astype(np.float64)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise InvalidValueError(f"rgb must have shape (..., 3), got {a.shape}")
    return a


def _param(param: ArrayLike, dtype: Any) -> FloatArray:
    """The parameter with a trailing axis, so it broadcasts against (..., 3)."""
    return np.asarray(param, dtype=dtype)[..., None]


def validate_rgb(rgb: ArrayLike, name: str = "rgb") -> FloatArray:
    """Return ``rgb`` as a float array after checking shape (..., 3), finiteness and [0, 1] range."""
    a = _float_rgb(rgb)
    if a.size and not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{name} contains NaN or Inf values")
    if a.size and (a.min() < 0.0 or a.max() > 1.0):
        raise InvalidValueError(
            f"{name} has values outside [0, 1] (min {float(a.min()):.6g}, max {float(a.max()):.6g}); "
            "transforms take encoded sRGB in [0, 1]"
        )
    return a


# --------------------------------------------------------------------------------------------
# HSV (hexcone model)
# --------------------------------------------------------------------------------------------


def rgb_to_hsv(rgb: ArrayLike) -> FloatArray:
    """RGB in [0, 1] (..., 3) -> HSV (..., 3) with H, S, V in [0, 1] (Smith 1978 hexcone).

    V = max, S = (max - min)/max, H from the sector of the largest channel. Grey pixels
    (max = min) get H = 0, S = 0; black (V = 0) gets H = S = 0.
    """
    a = _float_rgb(rgb)
    dt = a.dtype.type
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    v = np.maximum(np.maximum(r, g), b)
    c = v - np.minimum(np.minimum(r, g), b)
    chromatic = c > 0
    safe_c = np.where(chromatic, c, dt(1.0))
    safe_v = np.where(v > 0, v, dt(1.0))
    s = np.where(v > 0, c / safe_v, dt(0.0))
    # Sector formulas; the first maximum in R, G, B order wins, as in the usual definition.
    h = np.where(
        v == r,
        np.mod((g - b) / safe_c, dt(6.0)),
        np.where(v == g, (b - r) / safe_c + dt(2.0), (r - g) / safe_c + dt(4.0)),
    )
    h = np.where(chromatic, h / dt(6.0), dt(0.0))
    return np.stack([h, s, v], axis=-1)


def hsv_to_rgb(hsv: ArrayLike) -> FloatArray:
    """HSV (..., 3), H in [0, 1) (any real, taken mod 1), S and V in [0, 1] -> RGB (..., 3).

    Branch-free hexcone inverse: channel n in {R: 5, G: 3, B: 1} is
    V - V S max(0, min(k, 4 - k, 1)) with k = (n + 6 H) mod 6.
    """
    a = _float_rgb(hsv)
    dt = a.dtype.type
    h6 = np.mod(a[..., 0], dt(1.0)) * dt(6.0)
    vs = a[..., 2] * a[..., 1]
    out = np.empty(a.shape, dtype=a.dtype)
    for channel, n in enumerate((5.0, 3.0, 1.0)):
        k = np.mod(h6 + dt(n), dt(6.0))
        out[..., channel] = a[..., 2] - vs * np.clip(np.minimum(k, dt(4.0) - k), dt(0.0), dt(1.0))
    return out


# --------------------------------------------------------------------------------------------
# The transforms (Table I)
# --------------------------------------------------------------------------------------------


def _stack_broadcast(*channels: FloatArray) -> FloatArray:
    """Stack channel arrays on a new last axis after broadcasting them to one shape."""
    return np.stack(np.broadcast_arrays(*channels), axis=-1)


def brightness(rgb: ArrayLike, beta: ArrayLike) -> FloatArray:
    """Brightness shift clip(p + β); β in [-1, 1] (β = 0 is the identity)."""
    a = _float_rgb(rgb)
    return np.clip(a + _param(beta, a.dtype), 0.0, 1.0)


def contrast(rgb: ArrayLike, c: ArrayLike) -> FloatArray:
    """Contrast about mid-grey clip(0.5 + c (p - 0.5)); c in [0, 50] (c = 1 is the identity)."""
    a = _float_rgb(rgb)
    dt = a.dtype.type
    return np.clip(dt(0.5) + _param(c, a.dtype) * (a - dt(0.5)), 0.0, 1.0)


def saturation(rgb: ArrayLike, s: ArrayLike) -> FloatArray:
    """HSV saturation scaling HSV2RGB(H, clip(s S), V); s in [0, 50] (s = 1 is the identity)."""
    hsv = rgb_to_hsv(rgb)
    sat = np.clip(hsv[..., 1] * np.asarray(s, dtype=hsv.dtype), 0.0, 1.0)
    return hsv_to_rgb(_stack_broadcast(hsv[..., 0], sat, hsv[..., 2]))


def gamma(rgb: ArrayLike, g: ArrayLike) -> FloatArray:
    """Gamma on linear light clip(delinearize(linearize(p)^γ)); γ in [0.01, 10] (γ = 1: identity)."""
    a = _float_rgb(rgb)
    lin = np.clip(linearize_srgb(a), 0.0, 1.0)
    return np.clip(delinearize_srgb(np.power(lin, _param(g, a.dtype))), 0.0, 1.0)


def hue(rgb: ArrayLike, degrees: ArrayLike) -> FloatArray:
    """HSV hue rotation HSV2RGB((H + h/360) mod 1, S, V); h in [-180, 180] degrees (0: identity)."""
    hsv = rgb_to_hsv(rgb)
    dt = hsv.dtype.type
    h = np.mod(hsv[..., 0] + np.asarray(degrees, dtype=hsv.dtype) / dt(360.0), dt(1.0))
    return hsv_to_rgb(_stack_broadcast(h, hsv[..., 1], hsv[..., 2]))


def pull_mean(rgb: ArrayLike, alpha: ArrayLike) -> FloatArray:
    """Pull every colour towards the image's mean CIELAB colour; α in [0, 1] (α = 1: identity).

    clip(Lab2RGB(m + α (RGB2Lab(p) - m))) with m the mean Lab over all pixels of ``rgb``
    (every leading axis). α = 0 gives a uniform image of the mean colour.
    """
    a = _float_rgb(rgb)
    lab = srgb_to_lab(a)
    mean = lab.reshape(-1, 3).mean(axis=0)
    pulled = mean + _param(alpha, a.dtype) * (lab - mean)
    return np.clip(lab_to_srgb(pulled.astype(a.dtype, copy=False)), 0.0, 1.0)


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------


@record
class TransformSpec:
    """One directional SAFE-COLOR transform.

    ``param_range`` is the searched interval on the side of the direction, (near, far) ordered
    from the identity outwards for one-sided transforms; ``identity`` is the parameter that
    leaves images unchanged. ``scale`` ("linear" or "log") says how to scan the interval.
    """

    name: str
    function: Callable[[ArrayLike, ArrayLike], FloatArray]
    param_range: tuple[float, float]
    identity: float
    parameter: str
    scale: str = "linear"
    description: str = ""

    def __call__(self, rgb: ArrayLike, param: ArrayLike) -> FloatArray:
        return self.function(rgb, param)


#: The ten directional transforms of SAFE-COLOR Table I, keyed by name.
TRANSFORMS: dict[str, TransformSpec] = {
    spec.name: spec
    for spec in (
        TransformSpec("brightness-dec", brightness, (0.0, -1.0), 0.0, "beta",
                      description="darker: clip(p + β), β < 0"),
        TransformSpec("brightness-inc", brightness, (0.0, 1.0), 0.0, "beta",
                      description="brighter: clip(p + β), β > 0"),
        TransformSpec("contrast-dec", contrast, (1.0, 0.0), 1.0, "c",
                      description="flatter: clip(0.5 + c (p - 0.5)), c < 1"),
        TransformSpec("contrast-inc", contrast, (1.0, 50.0), 1.0, "c", scale="log",
                      description="harder: clip(0.5 + c (p - 0.5)), c > 1"),
        TransformSpec("gamma-dec", gamma, (1.0, 0.01), 1.0, "gamma", scale="log",
                      description="lighter mid-tones: linear^γ, γ < 1"),
        TransformSpec("gamma-inc", gamma, (1.0, 10.0), 1.0, "gamma", scale="log",
                      description="darker mid-tones: linear^γ, γ > 1"),
        TransformSpec("hue", hue, (-180.0, 180.0), 0.0, "degrees",
                      description="HSV hue rotation by h degrees"),
        TransformSpec("pull_mean", pull_mean, (1.0, 0.0), 1.0, "alpha",
                      description="colours pulled towards the mean Lab: m + α (Lab - m)"),
        TransformSpec("saturation-dec", saturation, (1.0, 0.0), 1.0, "s",
                      description="less saturated: HSV S scaled by s < 1"),
        TransformSpec("saturation-inc", saturation, (1.0, 50.0), 1.0, "s", scale="log",
                      description="more saturated: HSV S scaled by s > 1, clipped at 1"),
    )
}


def get_transform(name: str) -> TransformSpec:
    """The :class:`TransformSpec` registered under ``name``."""
    try:
        return TRANSFORMS[name]
    except KeyError:
        raise unknown_name("transform", name, TRANSFORMS) from None


def apply_transform(rgb: ArrayLike, name: str, param: float) -> FloatArray:
    """Apply the registered transform ``name`` with parameter ``param`` to sRGB in [0, 1].

    Checks the input (shape, NaN/Inf, [0, 1] range) and the parameter (finite, inside the
    transform's range) and raises :class:`~fidelity.core.errors.InvalidValueError` otherwise.

    Parameters
    ----------
    rgb
        sRGB-encoded values in [0, 1], shape (..., 3), finite (an image, or the chart's
        patches).
    name
        A transform of :data:`TRANSFORMS`: ``brightness-dec``, ``brightness-inc``,
        ``contrast-dec``, ``contrast-inc``, ``gamma-dec``, ``gamma-inc``, ``hue``,
        ``pull_mean``, ``saturation-dec``, ``saturation-inc``.
    param
        The transform's parameter, a finite number inside its ``param_range`` (either end
        included): β in [-1, 0] or [0, 1]; c in [0, 1] or [1, 50]; γ in [0.01, 1] or
        [1, 10]; hue degrees in [-180, 180]; α in [0, 1]; s in [0, 1] or [1, 50]. The
        transform's ``identity`` (0 or 1) leaves the input unchanged (up to rounding).

    Returns
    -------
    numpy.ndarray
        The transformed sRGB-encoded values in [0, 1], the shape of ``rgb``; float32 for
        float32 input, else float64. The input is not modified.

    Raises
    ------
    UnknownNameError
        ``name`` not in :data:`TRANSFORMS`. Exit code 2.
    InvalidValueError
        ``rgb`` not of shape (..., 3), with NaN/Inf or values outside [0, 1]; ``param``
        not finite or outside the transform's range. Exit code 2.

    References
    ----------
    Damschen, Avula, Mohamad, SAFE-COLOR, IEEE IV 2025, Table I (``shared/reference/
    safecolor.md``, "The single-parameter transforms").
    """
    spec = get_transform(name)
    a = validate_rgb(rgb)
    p = float(param)
    lo, hi = sorted(spec.param_range)
    if not np.isfinite(p) or not lo <= p <= hi:
        raise InvalidValueError(
            f"{name}: parameter {spec.parameter}={param} outside its range [{lo:g}, {hi:g}]"
        )
    return spec.function(a, p)
