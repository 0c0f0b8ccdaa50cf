"""A camera emulated on photographs with its lens and sensor, not its colour alone.

:mod:`fidelity.coco.emulation` fits a camera's colour rendering as a mapping of colours (an
8-bit table). A camera with ``[optics]``, ``[noise]`` or ``[vignetting]`` also changes an
image in space and at random; :class:`CameraImaging` applies those stages to an 8-bit sRGB
photograph in the order and with the functions :func:`fidelity.camera.render.render_chart`
applies them to the camera's chart:

1. decode sRGB to linear light (:func:`fidelity.coco.degradations.decode_srgb8`): the scene,
   as an ideal camera would have recorded it;
2. vignetting (:func:`fidelity.camera.model.vignetting_gain` on the image's size) and the
   lens's PSF (:func:`fidelity.coco.degradations.apply_optics`, the result of
   :meth:`fidelity.camera.optics.Optics.apply`), in linear light; the exposure, white balance
   and colour correction that :func:`~fidelity.camera.render.render_chart` applies around
   them are linear, so a blur before them is the blur after them;
3. the camera's colour: the root-polynomial mapping of the emulation
   (:class:`fidelity.coco.emulation.Emulation`), reference linear sRGB -> the camera's linear
   signal after white balance and CCM, exposure included;
4. the sensor noise where the camera adds it, on its raw signal: the mapping's output taken
   back through the chart's CCM and white-balance gains (``raw = (linear @ inv(ccm).T) /
   gains``), :func:`fidelity.camera.model.add_sensor_noise` (var = raw / full_well +
   (read_noise / full_well)^2), then the gains and the CCM again, so the noise is amplified
   and mixed between channels as the camera's is;
5. the camera's tone curve and quantisation (:func:`fidelity.coco.emulation.camera_output_srgb`),
   rounded to 8 bits (:func:`fidelity.coco.dataset.to_uint8`).

The noise of an image is seeded from its pixels, the camera's name and seed
(:func:`fidelity.coco.degradations.noise_seed`): a rerun or a resumed validation draws the
same noise. A camera without optics, noise or vignetting needs none of this: its emulation
is the colour table (:func:`camera_imaging` returns None).
"""

from __future__ import annotations

from dataclasses import field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.camera.model import add_sensor_noise, vignetting_gain
from fidelity.coco.dataset import to_uint8
from fidelity.coco.degradations import apply_optics, decode_srgb8, noise_seed
from fidelity.coco.emulation import Emulation, camera_output_srgb, root_polynomial_terms
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

__all__ = ["CameraImaging", "camera_imaging"]

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@record
class CameraImaging:
    """A camera's colour, lens and sensor on 8-bit sRGB images (module docstring).

    Attributes
    ----------
    emulation
        The camera's fitted colour emulation (method ``root-polynomial``).
    name
        What the noise seed names (the camera's name).
    """

    emulation: Emulation
    name: str
    _raw: tuple[F64, F64, F64] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        emu = self.emulation
        if emu.method != "root-polynomial":
            raise InvalidValueError(f"{emu.camera.name}: the optics and noise are emulated "
                                    f"with the root-polynomial colour mapping, not {emu.method}")
        gains, ccm = emu.samples.white_balance_gains, emu.samples.ccm
        if gains is not None and ccm is not None:
            object.__setattr__(self, "_raw", (np.asarray(gains, dtype=np.float64),
                                              np.asarray(ccm, dtype=np.float64),
                                              np.linalg.inv(ccm)))
        elif emu.camera.noise.enabled:
            raise InvalidValueError(f"{emu.camera.name}: the emulation has no white-balance "
                                    "gains and CCM to reach the raw signal")

    def linear(self, rgb8: U8) -> F64:
        """The camera's linear signal (after white balance and CCM, before the tone curve)
        for an ``(H, W, 3)`` uint8 sRGB image: steps 1-4 of the module docstring."""
        img = np.asarray(rgb8)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[-1] != 3:
            raise InvalidValueError(f"image must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
        seed = noise_seed(img, f"{self.name}:{self.emulation.camera.noise.seed}",
                          float(self.emulation.camera.noise.full_well or 0.0))
        return self.develop(decode_srgb8(img), seed)

    def scene(self, linear: F64) -> F64:
        """A linear scene image ``(H, W, 3)`` (1 = white) through the camera's vignetting and
        lens (step 2 of the module docstring)."""
        cam = self.emulation.camera
        lin = np.asarray(linear, dtype=np.float64)
        if cam.vignetting_fov_deg is not None:
            lin = lin * vignetting_gain(lin.shape[0], lin.shape[1],
                                        cam.vignetting_fov_deg)[..., None]
        return apply_optics(lin, cam.optics)

    def develop(self, linear: F64, seed: int) -> F64:
        """The camera's linear signal of a linear scene image ``(H, W, 3)``: :meth:`scene`,
        the colour mapping and the sensor noise drawn with ``seed`` (steps 2-4)."""
        out: F64 = root_polynomial_terms(self.scene(linear)) @ self.emulation.matrix.T
        noise = self.emulation.camera.noise
        if noise.enabled:
            gains, ccm = self._stages()[:2]
            out = (add_sensor_noise(self.raw(out), noise, seed=seed) * gains) @ ccm.T
        return out

    def raw(self, linear_signal: F64) -> F64:
        """The camera's raw signal of a linear signal :meth:`develop` returns: the chart's
        CCM and white-balance gains undone, ``(signal @ inv(ccm).T) / gains``."""
        gains, _, inv = self._stages()
        out: F64 = (np.asarray(linear_signal, dtype=np.float64) @ inv.T) / gains
        return out

    def _stages(self) -> tuple[F64, F64, F64]:
        if self._raw is None:
            raise InvalidValueError(f"{self.name}: the emulation has no white-balance gains "
                                    "and CCM to reach the raw signal")
        return self._raw

    def __call__(self, rgb8: U8) -> U8:
        """The image as the camera records it: :meth:`linear`, then its tone curve and
        quantisation, rounded to 8 bits."""
        return to_uint8(camera_output_srgb(self.emulation.camera, self.linear(rgb8)))

    def describe(self) -> dict[str, Any]:
        """What is emulated besides colour: the optics, noise and vignetting of the camera
        (:meth:`fidelity.camera.model.CameraModel.degradations`) and the order of the stages."""
        return {"stages": "decode sRGB, vignetting, optics (linear light), colour mapping, "
                          "sensor noise on the raw signal, tone curve, quantisation, 8 bits",
                "degradations": {k: {"kind": v[0], **v[1]}
                                 for k, v in self.emulation.camera.degradations().items()}}


def camera_imaging(emulation: Emulation) -> CameraImaging | None:
    """The :class:`CameraImaging` of a fitted emulation whose camera has optics, noise or
    vignetting; None for a camera that changes colours only (its colour table is its
    emulation)."""
    cam = emulation.camera
    if cam.optics.kind == "none" and not cam.noise.enabled and cam.vignetting_fov_deg is None:
        return None
    return CameraImaging(emulation, cam.name)
