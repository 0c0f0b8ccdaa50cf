"""Blur and noise at measured levels: the sharpness and noise families of the COCO sweep.

SAFE-COLOR changes colour with single-parameter transforms calibrated on the chart
(:mod:`fidelity.prediction.transforms`). These families change sharpness and noise the same
way, one parameter each, applied to an 8-bit sRGB image in linear light (decode sRGB, apply,
encode, round to 8 bits), before the sweep's JPEG round trip:

=================  ====================================================  ======================
family             what it does                                          parameter (unit)
=================  ====================================================  ======================
gaussian-blur      the camera's ``gaussian`` PSF                         σ (px)
defocus-blur       the camera's ``defocus`` PSF (a uniform disc)         radius (px)
sensor-noise       Poisson-Gaussian noise: shot noise of a full well of  full well at white
                   N electrons at white plus 5 e⁻ read noise             (electrons)
gaussian-noise     COCO-C's ``gaussian_noise`` (Hendrycks & Dietterich   σ (of full scale,
                   2019): normal noise on the *encoded* values, clipped  encoded)
=================  ====================================================  ======================

The PSFs are :class:`fidelity.camera.optics.Optics`' own kernels (what ``[optics]`` in a camera
TOML applies), convolved with reflected edges; the sensor noise is the camera model's
(:func:`fidelity.camera.model.add_sensor_noise`: var = max(x, 0)/N + (5/N)², x linear in
[0, 1]). ``gaussian-noise`` is kept for comparison with the literature's COCO-C numbers.

The noise of an image is seeded from the image itself and the family and level
(:func:`noise_seed`), so that a rerun, a resumed sweep and another executor all draw the same
noise. The level's x value on a table's axis is not the parameter: it is what an audit measures
on the chart degraded the same way (MTF50 for blur, SNR at 18 % grey for noise;
:mod:`fidelity.coco.tables.degradation`).
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.camera.model import Noise, add_sensor_noise
from fidelity.camera.optics import Optics
from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

__all__ = [
    "DEGRADATIONS",
    "PROPERTIES",
    "READ_NOISE_E",
    "Degradation",
    "DegradationFamily",
    "apply_optics",
    "decode_srgb8",
    "degrade_linear",
    "encode_srgb8",
    "family",
    "noise_seed",
]

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

#: Read noise of the ``sensor-noise`` family, electrons (a typical CMOS sensor's 2-10 e⁻).
READ_NOISE_E = 5.0

#: The camera properties the families degrade, in report order.
PROPERTIES: tuple[str, ...] = ("sharpness", "noise")


@record
class DegradationFamily:
    """One family of the sweep: its camera ``property`` (:data:`PROPERTIES`), the
    ``parameter`` and its ``unit``, and the sweep's ``levels`` (mildest first)."""

    name: str
    property: str
    parameter: str
    unit: str
    levels: tuple[float, ...]
    #: Whether it works in linear light (False: on the encoded values, as COCO-C does).
    linear: bool = True

    def check(self, level: float) -> None:
        """Raise :class:`InvalidValueError` for a level the family cannot apply."""
        if not np.isfinite(level) or level <= 0:
            raise InvalidValueError(f"{self.name}: {self.parameter} {level!r} must be a "
                                    f"finite number > 0 ({self.unit})")


#: The families, by name (module docstring).
DEGRADATIONS: Mapping[str, DegradationFamily] = {
    f.name: f for f in (
        DegradationFamily("gaussian-blur", "sharpness", "sigma", "px",
                          (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)),
        DegradationFamily("defocus-blur", "sharpness", "radius", "px",
                          (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)),
        DegradationFamily("sensor-noise", "noise", "full_well", "e-",
                          (20000.0, 10000.0, 5000.0, 2500.0, 1200.0, 600.0, 300.0, 150.0,
                           80.0, 40.0)),
        DegradationFamily("gaussian-noise", "noise", "sigma", "of full scale",
                          (0.01, 0.02, 0.03, 0.04, 0.06, 0.08, 0.10, 0.13, 0.18, 0.26),
                          linear=False),
    )
}


def family(name: str) -> DegradationFamily:
    """The family ``name`` (:data:`DEGRADATIONS`); an unknown one is an
    :class:`InvalidValueError` naming the known ones."""
    try:
        return DEGRADATIONS[name]
    except KeyError:
        raise unknown_name("degradation", name, list(DEGRADATIONS)) from None


def noise_seed(image: NDArray[Any], name: str, level: float) -> int:
    """The noise seed of ``image`` under family ``name`` at ``level``: CRC-32 of the pixels,
    the name and the level, so the same image always gets the same noise (module docstring)."""
    crc = zlib.crc32(np.ascontiguousarray(image).data)
    crc = zlib.crc32(f"{name}@{level!r}".encode(), crc)
    return int(crc)


def _psf(name: str, level: float) -> Optics:
    if name == "gaussian-blur":
        return Optics(kind="gaussian", sigma_px=level)
    return Optics(kind="defocus", radius_px=level)


def degrade_linear(linear: NDArray[Any], name: str, level: float, seed: int = 0) -> F64:
    """A linear image degraded by family ``name`` at ``level`` (the linear-light families).

    Parameters
    ----------
    linear
        Linear RGB or grey values, shape ``(H, W)`` or ``(H, W, C)``, 1 = white.
    name
        A family of :data:`DEGRADATIONS` with ``linear`` True.
    level
        The family's parameter (its ``unit``), > 0.
    seed
        The noise seed (``sensor-noise``).

    Returns
    -------
    numpy.ndarray
        float64, the shape of ``linear``; blur keeps the mean; noise is unclipped.
    """
    fam = family(name)
    fam.check(level)
    if not fam.linear:
        raise InvalidValueError(f"{name}: works on encoded values, not linear light")
    img = np.asarray(linear, dtype=np.float64)
    if fam.property == "sharpness":
        psf = _psf(name, level)
        if psf.kind == "gaussian":
            return apply_optics(img, psf)
        import cv2

        # the sweep's defocus levels were measured with the disc's sampled kernel (within
        # 6e-4 of Optics.apply at 2 px): kept so that its tables' cells stay as measured
        out = cv2.filter2D(img, cv2.CV_64F, psf.kernel(), borderType=cv2.BORDER_REFLECT)
        blurred: F64 = np.asarray(out, dtype=np.float64).reshape(img.shape)
        return blurred
    noise = Noise(full_well=level, read_noise=READ_NOISE_E, seed=seed)
    return add_sensor_noise(img, noise, seed=seed)


def apply_optics(linear: NDArray[Any], optics: Optics) -> F64:
    """A linear image through a lens's point-spread function, as a camera's render applies it.

    The result of :meth:`fidelity.camera.optics.Optics.apply` (what
    :func:`fidelity.camera.render.render_chart` calls on the camera's raw image), a Gaussian
    through OpenCV's separable filter with the same kernel
    (:meth:`~fidelity.camera.optics.Optics.kernel_1d`) and the same reflected edges: equal
    within 1e-15 and about 6 ms for a 640 x 480 image against 35-90 ms.

    Parameters
    ----------
    linear
        Linear values, shape ``(H, W)`` or ``(H, W, C)``, finite.
    optics
        The lens (any kind of :data:`fidelity.camera.optics.OPTICS_KINDS`).

    Returns
    -------
    numpy.ndarray
        float64, the shape of ``linear``; for ``none`` the image unchanged.
    """
    img = np.asarray(linear, dtype=np.float64)
    if optics.kind != "gaussian" or img.ndim not in (2, 3):
        return optics.apply(img)
    import cv2

    g = optics.kernel_1d()
    out = cv2.sepFilter2D(img, cv2.CV_64F, g, g, borderType=cv2.BORDER_REFLECT)
    blurred: F64 = np.asarray(out, dtype=np.float64).reshape(img.shape)
    return blurred


def decode_srgb8(rgb8: NDArray[np.uint8]) -> F64:
    """8-bit sRGB codes -> linear values (IEC 61966-2-1), by a 256-entry lookup."""
    out: F64 = np.asarray(_DECODE[rgb8], dtype=np.float64)
    return out


_DECODE = linearize_srgb(np.arange(256) / 255.0)
#: Linear values quantised to 16 bits -> the nearest 8-bit sRGB code (a lookup in place of
#: the encoding's power law per pixel; codes differ from the exact rounding only where a
#: value falls within 1/65535 of a code boundary).
_ENCODE_BITS = 16
_ENCODE = np.rint(delinearize_srgb(np.arange(1 << _ENCODE_BITS) / ((1 << _ENCODE_BITS) - 1))
                  * 255.0).astype(np.uint8)


def encode_srgb8(linear: NDArray[Any]) -> U8:
    """Linear values (any shape; clipped to [0, 1]) -> 8-bit sRGB codes, through a 16-bit
    lookup table (:data:`_ENCODE`)."""
    top = (1 << _ENCODE_BITS) - 1
    idx = np.rint(np.clip(linear, 0.0, 1.0) * top).astype(np.uint32)
    out: U8 = _ENCODE[idx]
    return out


@record
class Degradation:
    """The callable a sweep cell applies: family ``name`` at ``level`` on an (H, W, 3) uint8
    sRGB image, returning uint8 (module docstring)."""

    name: str
    level: float

    def __post_init__(self) -> None:
        family(self.name).check(self.level)

    def __call__(self, rgb8: U8) -> U8:
        fam = DEGRADATIONS[self.name]
        seed = noise_seed(rgb8, self.name, self.level) if fam.property == "noise" else 0
        if not fam.linear:  # COCO-C gaussian_noise: clip(x/255 + N(0, c)) x 255, truncated
            rng = np.random.default_rng(seed)
            x = rgb8 / 255.0 + rng.normal(size=rgb8.shape, scale=self.level)
            return (np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)
        return encode_srgb8(degrade_linear(decode_srgb8(rgb8), self.name, self.level, seed))
