"""Camera response model: spectral sensitivities and a small, documented image pipeline (ISP).

A :class:`CameraModel` is read from a TOML or YAML camera file (:func:`load_camera`); built-in
cameras live in ``fidelity/data/cameras/<name>.toml``. Every stage is optional:

1. **Sensitivities** (``[sensitivities] source``): ``"ideal"`` = M(XYZ->linear sRGB) @ CIE 1931
   CMFs (IEC 61966-2-1 matrix), which makes camera RGB equal to linear sRGB exactly; a camera in
   ``colour.MSDS_CAMERA_SENSITIVITIES`` (``"Nikon 5100 (NPL)"``, ``"Sigma SDMerrill (NPL)"``);
   or ``"file"`` with ``path`` to a CSV (wavelength nm, r, g, b).
   Camera (raw) signal of a surface R under illuminant E (Riemann sum on the spectral grid):
   ``raw_c = sum R E S_c dl / sum E ybar dl`` -- for the ideal camera this is linear sRGB with
   the perfect white at Y = 1.
2. **Exposure** (``[exposure]``): ``mode = "none" | "gain" | "auto"``; ``gain`` (linear factor)
   or ``ev`` (stops, gain = 2^ev); ``auto`` meters the noise-free chart so that the brightest
   patch's largest raw channel equals ``target`` (default 0.9), like highlight metering.
3. **Vignetting** (``[vignetting] diagonal_fov_deg``): natural cos^4 fall-off (Slama, Manual of
   Photogrammetry) of a lens whose diagonal field of view is given; gain = cos^4(theta) with
   tan(theta) = (r / r_corner) tan(fov / 2).
4. **Noise** (``[noise]``): ``full_well`` electrons at raw = 1 and ``read_noise`` electrons
   rms. Shot noise is Poisson, drawn as its Gaussian approximation N(e, e) (exact enough above
   ~20 e-, and defined for the small negative raw values of negative-lobed sensitivities);
   read noise is N(0, read_noise^2). ``seed`` (default 0) makes it reproducible.
5. **White balance** (``[white_balance] method``): ``none``; ``gains = [r, g, b]``;
   ``white-patch`` (the "white 9.5" patch becomes neutral); ``grey-world`` (the mean of the 24
   patches becomes neutral); ``illuminant`` (the camera's response to the perfect white under
   ``illuminant``, a name or ``"scene"``, becomes (1, 1, 1)). Other gains are normalised to
   g = 1.
6. **Colour correction** (``[ccm] method``): ``none``; ``matrix = [[...] x3]`` (camera RGB after
   white balance -> linear sRGB); ``fit``: a 3x3 matrix fitted on the chart by
   ``colour.characterisation.matrix_colour_correction`` with ``fit_method`` (``"Cheung 2004"``,
   3 terms; or ``"Finlayson 2015"``, degree 1), from the noise-free white-balanced patches under
   ``fit_illuminant`` (default ``"D65"``, or ``"scene"``) to the scene-consistent linear sRGB
   reference of that illuminant (:func:`fidelity.colour.spectral.scene_reference`).
7. **Tone curve** (``[tone] curve``): ``linear`` (output stays scene-linear float),
   ``srgb`` (IEC 61966-2-1 encoding), ``gamma`` (V^(1/gamma), ``gamma`` default 2.2) or ``lut``
   (``lut = "file.csv"`` or inline ``[[x, y], ...]``, linear input -> encoded output, linearly
   interpolated). Display curves (all but ``linear``) clip their input to [0, 1].
8. **Quantisation** (``[quantisation] bits``): round(v (2^N - 1)) / (2^N - 1) after clipping
   to [0, 1].

**Optics** (``[optics] kind``, :mod:`fidelity.camera.optics`): the lens's point-spread function
(``none``; ``gaussian`` with ``sigma_px``; ``defocus`` with ``radius_px``; ``diffraction`` with
``f_number``, ``wavelength_nm``, ``pixel_pitch_um``; ``mtf`` with an inline ``mtf = [[f, v],
...]`` table or ``mtf_file``; ``psf`` with ``psf_file``), convolved with the linear raw image
after exposure and vignetting and before noise (so before white balance and the tone curve).

Clipping rule: a display-referred output (tone curve other than ``linear``) or a quantised
output is clipped to [0, 1], as a real encoded image is. A camera with a ``linear`` tone curve
and no quantisation outputs unclipped float linear sRGB (an EXR-like output); it is measured as
:func:`fidelity.colour.colorimetry.delinearize_srgb` of those values, unclipped, so out-of-gamut patches
(e.g. cyan) are measured exactly and an ideal camera measures ΔE00 ~ 0.

Measurement rule: a display-referred output is read as encoded sRGB, which is what a viewer or
a detector assumes; a ``gamma`` or ``lut`` curve that differs from the sRGB encoding therefore
shows up as colour error, as it should.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import asdict, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.camera.optics import (
    OPTICS_KINDS,
    Optics,
    mtf_table_problem,
    psf_problem,
    read_mtf_file,
    read_psf_file,
)
from fidelity.colour.colorimetry import MATRIX_XYZ_TO_LINEAR_SRGB, delinearize_srgb
from fidelity.colour.datasets import camera_sensitivities
from fidelity.colour.spectral import (
    GRID_STEP_NM,
    Illuminant,
    cie_1931_cmfs,
    load_illuminant,
    load_patch_spectra,
    read_spectral_csv,
    resample,
    scene_reference,
    wavelength_grid,
)
from fidelity.core import schema as sc
from fidelity.core.errors import FidelityError, InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import display_path, require_file
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

FloatArray = NDArray[np.float64]

#: Default built-in camera used by ``fidelity check`` and ``fidelity render`` without --camera.
DEFAULT_CAMERA: str = "nikon-5100"

#: Index of the "white 9.5" patch in chart order (row 4, column 1).
WHITE_PATCH_INDEX: int = 18

#: Spectral-sensitivity sources in colour-science (aliases -> colour key).
COLOUR_CAMERAS: dict[str, str] = {
    "Nikon 5100 (NPL)": "Nikon 5100 (NPL)",
    "Sigma SDMerrill (NPL)": "Sigma SDMerill (NPL)",  # colour-science spells it "SDMerill"
    "Sigma SDMerill (NPL)": "Sigma SDMerill (NPL)",
}

EXPOSURE_MODES = ("none", "gain", "auto")
WHITE_BALANCE_METHODS = ("none", "gains", "white-patch", "grey-world", "illuminant")
CCM_METHODS = ("none", "matrix", "fit")
#: colour.characterisation methods that give a 3x3 matrix, with the keyword that makes them so.
CCM_FIT_METHODS: dict[str, dict[str, int]] = {
    "Cheung 2004": {"terms": 3},
    "Finlayson 2015": {"degree": 1},
}
TONE_CURVES = ("linear", "srgb", "gamma", "lut")


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------


@record
class Sensitivities:
    """Camera spectral sensitivities: ``wavelengths`` (N,) nm, ``values`` (N, 3) r, g, b."""

    name: str
    wavelengths: FloatArray
    values: FloatArray

    def on_grid(self, step: float = GRID_STEP_NM) -> FloatArray:
        """Sensitivities (M, 3) on :func:`fidelity.colour.spectral.wavelength_grid` (zero outside)."""
        return resample(self.wavelengths, self.values, wavelength_grid(step), extrapolation="zero")


@record
class Exposure:
    """Exposure stage: ``mode`` in :data:`EXPOSURE_MODES`; ``gain``; ``target`` for auto."""

    mode: str = "none"
    gain: float = 1.0
    target: float = 0.9


@record
class WhiteBalance:
    """White balance: ``method`` in :data:`WHITE_BALANCE_METHODS`; ``gains``; ``illuminant``."""

    method: str = "none"
    gains: tuple[float, float, float] | None = None
    illuminant: str = "scene"


@record
class ColourCorrection:
    """3x3 CCM: ``method`` in :data:`CCM_METHODS`; ``matrix`` (given); ``fit_method``."""

    method: str = "none"
    matrix: tuple[tuple[float, float, float], ...] | None = None
    fit_method: str = "Cheung 2004"
    fit_illuminant: str = "D65"


@record
class ToneCurve:
    """Tone curve: ``curve`` in :data:`TONE_CURVES`; ``gamma``; ``lut`` (K, 2) pairs."""

    curve: str = "linear"
    gamma: float = 2.2
    lut: tuple[tuple[float, float], ...] | None = None


@record
class Noise:
    """Sensor noise: ``full_well`` electrons at raw 1, ``read_noise`` e- rms, ``seed``."""

    full_well: float | None = None
    read_noise: float = 0.0
    seed: int = 0

    @property
    def enabled(self) -> bool:
        """True when the stage adds noise."""
        return self.full_well is not None


@record
class CameraModel:
    """A simulated camera: sensitivities plus the optional ISP stages (module docstring).

    Attributes
    ----------
    name
        The camera's name (a camera file's ``name``, else the file's stem).
    sensitivities
        Spectral sensitivities r, g, b (stage 1): ``wavelengths`` (N,) in nm, ``values``
        (N, 3).
    description
        Free text from the camera file ("" when none).
    exposure
        Exposure stage (stage 2): ``mode`` in :data:`EXPOSURE_MODES`, linear ``gain`` > 0,
        ``target`` in (0, 1] for ``auto``.
    white_balance
        White-balance stage (stage 5): ``method`` in :data:`WHITE_BALANCE_METHODS`.
    ccm
        Colour-correction stage (stage 6): ``method`` in :data:`CCM_METHODS`.
    tone
        Tone curve (stage 7): ``curve`` in :data:`TONE_CURVES`.
    noise
        Sensor noise (stage 4): ``full_well`` electrons at raw 1 (None: no noise),
        ``read_noise`` electrons rms, ``seed``.
    quantisation_bits
        Output bit depth in [1, 16] (stage 8); None: not quantised.
    vignetting_fov_deg
        Diagonal field of view in degrees, in (0, 179], of the cos^4 fall-off (stage 3);
        None: no vignetting.
    source
        Where it was read from: ``built-in <name>``, the camera file's path, or
        ``built-in`` (default, one built in code).
    optics
        The lens's point-spread function (:class:`fidelity.camera.optics.Optics`), applied to
        the linear raw image before noise; kind ``none`` (the default) changes nothing.
    named
        What it was loaded by: a built-in name or the camera file's path as given ("" when
        built in code); not compared.
    files
        The files it was read from: the camera file and the sensitivity CSV and tone LUT file
        it names (empty for a built-in camera); not compared.
    """

    name: str
    sensitivities: Sensitivities
    description: str = ""
    exposure: Exposure = field(default_factory=Exposure)
    white_balance: WhiteBalance = field(default_factory=WhiteBalance)
    ccm: ColourCorrection = field(default_factory=ColourCorrection)
    tone: ToneCurve = field(default_factory=ToneCurve)
    noise: Noise = field(default_factory=Noise)
    quantisation_bits: int | None = None
    vignetting_fov_deg: float | None = None
    source: str = "built-in"
    optics: Optics = field(default_factory=Optics)
    #: What it was loaded by: a built-in name or the camera file's path as given ("" when
    #: built in code); :attr:`subject`.
    named: str = field(default="", compare=False)
    #: The files it was read from: the camera file, and the sensitivity CSV and tone LUT file
    #: it names (none for a built-in camera), for the overwrite check of outputs
    #: (:func:`fidelity.core.fileio.check_outputs`).
    files: tuple[Path, ...] = field(default=(), compare=False)

    @property
    def subject(self) -> str:
        """How a command names this camera: what it was loaded by, else its name."""
        return self.named or self.name

    @property
    def output_encoding(self) -> str:
        """``"linear"`` (float linear sRGB) or ``"display"`` (encoded, clipped to [0, 1])."""
        return "linear" if self.tone.curve == "linear" else "display"

    @property
    def clips(self) -> bool:
        """True when the output is clipped to [0, 1] (display curve or quantisation)."""
        return self.output_encoding == "display" or self.quantisation_bits is not None

    def stage_kinds(self) -> dict[str, str]:
        """The kind of each processing stage, the terms a validation domain is stated in
        (:class:`fidelity.prediction.interval.ValidatedCameras`): ``exposure`` (mode), ``white
        balance`` and ``colour correction`` (method), ``tone curve`` and ``bit depth`` (the
        quantisation bits, ``"float"`` without quantisation). The optics is not a stage
        kind here: the validated cameras' record (``validation-domain.json``) and
        :func:`fidelity.coco.validate.colour.validated_cameras` know only these five stages,
        and the validation emulates colour alone (the optics is in :attr:`optics`)."""
        return {"exposure": self.exposure.mode, "white balance": self.white_balance.method,
                "colour correction": self.ccm.method, "tone curve": self.tone.curve,
                "bit depth": ("float" if self.quantisation_bits is None
                              else str(self.quantisation_bits))}

    def degradations(self) -> dict[str, tuple[str, dict[str, float]]]:
        """The kind and numeric parameters of each image degradation, the terms the
        validity domain states noise, optics and vignetting in
        (:meth:`fidelity.prediction.interval.ValidatedCameras.camera_checks`).

        Returns
        -------
        dict
            ``noise``: ``("none", {})`` or ``("shot+read", {"full_well": e-, "read_noise":
            e- rms})``; ``optics``: ``(kind, {...})`` with ``sigma_px`` (gaussian),
            ``radius_px`` (defocus) or ``f_number`` (diffraction), no numbers for a measured
            ``mtf`` or ``psf``; ``vignetting``: ``("none", {})`` or ``("cos4",
            {"diagonal_fov_deg": degrees})``.
        """
        n = self.noise
        noise: tuple[str, dict[str, float]] = (
            ("shot+read", {"full_well": float(n.full_well), "read_noise": n.read_noise})
            if n.full_well is not None else ("none", {}))
        o = self.optics
        numbers = {"gaussian": {"sigma_px": o.sigma_px}, "defocus": {"radius_px": o.radius_px},
                   "diffraction": {"f_number": float(o.f_number or 0.0)}}.get(o.kind, {})
        fov = self.vignetting_fov_deg
        vignetting: tuple[str, dict[str, float]] = (
            ("cos4", {"diagonal_fov_deg": float(fov)}) if fov is not None else ("none", {}))
        return {"noise": noise, "optics": (o.kind, numbers), "vignetting": vignetting}

    def to_json(self) -> dict[str, Any]:
        """JSON-ready description of every stage (sensitivity data summarised)."""
        d: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "source": self.source,
            "sensitivities": self.sensitivities.name,
            "exposure": asdict(self.exposure),
            "white_balance": asdict(self.white_balance),
            "ccm": asdict(self.ccm),
            "tone": {"curve": self.tone.curve, "gamma": self.tone.gamma,
                     "lut_points": None if self.tone.lut is None else len(self.tone.lut)},
            "noise": asdict(self.noise),
            "quantisation_bits": self.quantisation_bits,
            "vignetting_fov_deg": self.vignetting_fov_deg,
            "output_encoding": self.output_encoding,
            "clipped": self.clips,
        }
        if self.optics.kind != "none":  # absent without optics: the records stay as they were
            d["optics"] = optics_json(self.optics)
        return d


def optics_json(optics: Optics) -> dict[str, Any]:
    """JSON-ready description of an :class:`~fidelity.camera.optics.Optics`: its kind and the
    parameters that kind reads (an MTF table's and a PSF image's size, not their values).

    Parameters
    ----------
    optics
        The optics.

    Returns
    -------
    dict
        ``kind`` and, by kind: ``sigma_px``; ``radius_px``; ``f_number``, ``wavelength_nm``,
        ``pixel_pitch_um``, ``cutoff_cy_per_px``; ``mtf_points``; ``psf_size`` ``[h, w]``;
        with ``source`` (the file read) for a measured MTF or PSF.
    """
    d: dict[str, Any] = {"kind": optics.kind}
    if optics.kind == "gaussian":
        d["sigma_px"] = optics.sigma_px
    elif optics.kind == "defocus":
        d["radius_px"] = optics.radius_px
    elif optics.kind == "diffraction":
        d.update(f_number=optics.f_number, wavelength_nm=optics.wavelength_nm,
                 pixel_pitch_um=optics.pixel_pitch_um, cutoff_cy_per_px=optics.cutoff)
    elif optics.kind == "mtf":
        d["mtf_points"] = len(optics.mtf_table or ())
    elif optics.kind == "psf":
        d["psf_size"] = [len(optics.psf or ()), len((optics.psf or ((),))[0])]
    if optics.source:
        d["source"] = optics.source
    return d


# --------------------------------------------------------------------------------------------
# Sensitivities
# --------------------------------------------------------------------------------------------


def ideal_sensitivities() -> Sensitivities:
    """M(XYZ -> linear sRGB) @ CIE 1931 2° CMFs on the 1 nm grid (has negative lobes).

    With these, camera RGB = M @ XYZ exactly, so the camera reproduces sRGB colorimetrically.
    """
    values = cie_1931_cmfs() @ np.asarray(MATRIX_XYZ_TO_LINEAR_SRGB).T
    return Sensitivities("ideal (M_XYZ->sRGB @ CIE 1931 2 degree CMFs)", wavelength_grid(), values)


def colour_camera_sensitivities(name: str) -> Sensitivities:
    """Sensitivities of a camera in ``colour.MSDS_CAMERA_SENSITIVITIES`` (peak-normalised)."""
    key = COLOUR_CAMERAS.get(name)
    if key is None:
        raise unknown_name("camera sensitivities", name, ["ideal", "file", *COLOUR_CAMERAS])
    shipped = camera_sensitivities(key)
    if shipped is None:
        import colour

        msds = colour.MSDS_CAMERA_SENSITIVITIES[key]
        shipped = np.asarray(msds.wavelengths, float), np.asarray(msds.values, float)
    return Sensitivities(f"{name} (colour.MSDS_CAMERA_SENSITIVITIES)", *shipped)


def camera_response(
    reflectance: ArrayLike, illuminant: ArrayLike, sensitivities: ArrayLike,
    step: float = GRID_STEP_NM,
) -> FloatArray:
    """Raw camera signal ``sum R E S_c dl / sum E ybar dl`` (closed form, Riemann sum).

    ``reflectance`` (..., N), ``illuminant`` (N,), ``sensitivities`` (N, 3) on the same grid.
    Returns (..., 3). For the ideal camera this is linear sRGB with Y(perfect white) = 1.
    """
    e = np.asarray(illuminant, dtype=np.float64)
    norm = float(e @ cie_1931_cmfs(step)[:, 1]) * step
    if norm <= 0:
        raise InvalidValueError("illuminant has no power in the visible range")
    weights = e[:, None] * np.asarray(sensitivities, dtype=np.float64)
    return np.asarray(reflectance, dtype=np.float64) @ weights * step / norm


# --------------------------------------------------------------------------------------------
# ISP stages (pure functions)
# --------------------------------------------------------------------------------------------


def exposure_gain(exposure: Exposure, metered_patches: ArrayLike) -> float:
    """Linear exposure gain; ``auto`` makes max over patches and channels = ``target``."""
    if exposure.mode == "none":
        return 1.0
    if exposure.mode == "gain":
        return float(exposure.gain)
    peak = float(np.max(np.asarray(metered_patches, dtype=np.float64)))
    if peak <= 0:
        raise InvalidValueError("auto exposure: the chart gives no positive camera signal")
    return exposure.target / peak


def vignetting_gain(height: int, width: int, diagonal_fov_deg: float) -> FloatArray:
    """cos^4 fall-off (H, W): tan(theta) = (r / r_corner) tan(fov/2), r from the image centre."""
    y = np.arange(height, dtype=np.float64) + 0.5 - height / 2
    x = np.arange(width, dtype=np.float64) + 0.5 - width / 2
    r = np.hypot(*np.meshgrid(x, y, indexing="xy"))
    r_corner = math.hypot(width / 2, height / 2)
    theta = np.arctan(r / r_corner * math.tan(math.radians(diagonal_fov_deg) / 2))
    return np.cos(theta) ** 4


def add_sensor_noise(image: ArrayLike, noise: Noise, seed: int | None = None) -> FloatArray:
    """Shot + read noise in raw units (Gaussian approximation of Poisson; module docstring).

    var(raw) = max(raw, 0) / full_well + (read_noise / full_well)^2. ``seed`` overrides
    ``noise.seed``. Returns a new array; the input is unchanged.
    """
    img = np.asarray(image, dtype=np.float64)
    if not noise.enabled:
        return img.copy()
    rng = np.random.default_rng(noise.seed if seed is None else seed)
    fw = float(noise.full_well)  # type: ignore[arg-type]
    with np.errstate(over="ignore", invalid="ignore"):
        sigma = np.sqrt(np.maximum(img, 0.0) / fw + np.square(noise.read_noise / fw))
        # img + sigma * z, in place in z's array (the same values, two arrays less)
        noisy: FloatArray = rng.standard_normal(img.shape)
        noisy *= sigma
        noisy += img
    if not np.all(np.isfinite(noisy)):
        raise InvalidValueError(f"[noise]: read_noise {noise.read_noise:g} e- on a full well of "
                                f"{fw:g} e- makes the noise beyond the floating-point range")
    return noisy


def white_balance_gains(
    wb: WhiteBalance,
    patches: ArrayLike,
    sensitivities: Sensitivities,
    scene_illuminant: Illuminant,
    step: float = GRID_STEP_NM,
) -> FloatArray:
    """Per-channel gains (3,) for the white-balance stage ``wb``.

    ``gains``, ``white-patch`` and ``grey-world`` are normalised to g = 1 (exposure sets the
    level); ``illuminant`` maps the perfect white under that illuminant to (1, 1, 1), which in
    camera units (Y(perfect white) = 1) preserves exposure.

    ``patches`` (24, 3) are the camera's raw patch values (used by white-patch, grey-world).
    """
    p = np.asarray(patches, dtype=np.float64)
    if wb.method == "none":
        return np.ones(3)
    if wb.method == "gains":
        g = np.asarray(wb.gains, dtype=np.float64)
        gains: FloatArray = g / g[1]
        return gains
    if wb.method == "white-patch":
        white = p[WHITE_PATCH_INDEX]
    elif wb.method == "grey-world":
        white = p.mean(axis=0)
    else:  # illuminant
        ill = scene_illuminant if wb.illuminant.lower() == "scene" else load_illuminant(wb.illuminant)
        white = camera_response(np.ones(wavelength_grid(step).size), ill.on_grid(step),
                                sensitivities.on_grid(step), step)
    if np.any(white <= 0):
        raise InvalidValueError(f"white balance {wb.method}: non-positive white {white.tolist()}")
    if wb.method == "illuminant":
        # camera units put the perfect white at luminance 1 (camera_response), so mapping it to
        # (1, 1, 1) keeps exposure: an ideal camera then renders the white patch at its own Y.
        return np.asarray(1.0 / white, dtype=np.float64)
    return np.asarray(white[1] / white, dtype=np.float64)


def fit_colour_correction(
    camera_rgb: ArrayLike, target_linear_srgb: ArrayLike, method: str = "Cheung 2004"
) -> FloatArray:
    """3x3 matrix M minimising ||camera_rgb @ M.T - target||^2.

    ``method`` in :data:`CCM_FIT_METHODS` (Cheung, Westland, Connah, Ripamonti 2004, 3 terms;
    Finlayson, Mackiewicz, Hurlbert 2015, degree 1). Inputs (K, 3), K >= 3. With 3 terms and
    degree 1 both expand RGB to itself, so both are the Moore-Penrose least-squares mapping
    ``M = target.T @ pinv(camera_rgb.T)``, computed as colour-science's
    ``colour.characterisation.matrix_colour_correction`` computes it (tested equal).
    """
    key = next((k for k in CCM_FIT_METHODS if k.lower() == method.lower()), None)
    if key is None:
        raise unknown_name("colour-correction fit method", method, CCM_FIT_METHODS)
    rgb = np.atleast_2d(np.asarray(camera_rgb, dtype=np.float64))
    target = np.atleast_2d(np.asarray(target_linear_srgb, dtype=np.float64))
    m = np.dot(np.transpose(target), np.linalg.pinv(np.transpose(rgb)))
    return np.asarray(m, dtype=np.float64).reshape(3, 3)


def colour_correction_matrix(
    camera: CameraModel,
    scene_illuminant: Illuminant,
    spectra: str = "BabelColor Average",
    step: float = GRID_STEP_NM,
) -> FloatArray:
    """The camera's 3x3 CCM: identity, the given matrix, or fitted (module docstring, stage 6).

    The fit uses a noise-free closed-form capture of the chart under ``fit_illuminant`` with
    the camera's own exposure and white balance, and the scene-consistent reference of that
    illuminant (Bradford-adapted to D65) as target.
    """
    c = camera.ccm
    if c.method == "none":
        return np.eye(3)
    if c.method == "matrix":
        return np.asarray(c.matrix, dtype=np.float64)
    ill = scene_illuminant if c.fit_illuminant.lower() == "scene" else load_illuminant(c.fit_illuminant)
    sens = camera.sensitivities.on_grid(step)
    raw = camera_response(load_patch_spectra(spectra).on_grid(step), ill.on_grid(step), sens, step)
    raw = raw * exposure_gain(camera.exposure, raw)
    balanced = raw * white_balance_gains(camera.white_balance, raw, camera.sensitivities, ill, step)
    target = scene_reference(ill, spectra, step=step).linear_srgb
    return fit_colour_correction(balanced, target, c.fit_method)


def apply_tone_curve(linear: ArrayLike, tone: ToneCurve) -> FloatArray:
    """Linear -> output values. Display curves clip to [0, 1] first; ``linear`` is identity."""
    x = np.asarray(linear, dtype=np.float64)
    if tone.curve == "linear":
        return x.copy()
    x = np.clip(x, 0.0, 1.0)
    if tone.curve == "srgb":
        return np.asarray(delinearize_srgb(x), dtype=np.float64)
    if tone.curve == "gamma":
        return np.power(x, 1.0 / tone.gamma)
    lut = np.asarray(tone.lut, dtype=np.float64)
    return np.interp(x, lut[:, 0], lut[:, 1])


def quantise(values: ArrayLike, bits: int) -> FloatArray:
    """round(clip(v, 0, 1) (2^bits - 1)) / (2^bits - 1)."""
    levels = float(2**bits - 1)
    return np.round(np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0) * levels) / levels


@record
class Developed:
    """Result of :func:`develop`: output image (H, W, 3), the encoded-sRGB view used for
    measurement (unclipped for linear outputs), and the stage parameters that were used."""

    output: FloatArray
    srgb: FloatArray
    white_balance_gains: FloatArray
    ccm: FloatArray


def develop(
    camera: CameraModel,
    raw_image: ArrayLike,
    raw_patches: ArrayLike,
    scene_illuminant: Illuminant,
    *,
    ccm: ArrayLike | None = None,
    spectra: str = "BabelColor Average",
    step: float = GRID_STEP_NM,
) -> Developed:
    """Stages 5-8 on a captured raw image (H, W, 3): white balance, CCM, tone, quantisation.

    ``raw_patches`` (24, 3) are the patch values measured on the raw image (white-patch and
    grey-world balance use them). Returns the output image and its encoded sRGB view.
    """
    img = np.asarray(raw_image, dtype=np.float64)
    gains = white_balance_gains(camera.white_balance, raw_patches, camera.sensitivities,
                                scene_illuminant, step)
    m = colour_correction_matrix(camera, scene_illuminant, spectra, step) if ccm is None else (
        np.asarray(ccm, dtype=np.float64))
    linear = (img * gains) @ m.T
    out = apply_tone_curve(linear, camera.tone)
    if camera.quantisation_bits is not None:
        out = quantise(out, camera.quantisation_bits)
    srgb = (np.asarray(delinearize_srgb(out), dtype=np.float64)
            if camera.output_encoding == "linear" else out)
    return Developed(out, srgb, gains, m)


# --------------------------------------------------------------------------------------------
# Camera files
# --------------------------------------------------------------------------------------------

#: Largest camera file read, in bytes (the built-in ones are under 2 kB).
MAX_CAMERA_FILE_BYTES = 1 << 20
#: Most points of a tone-curve LUT.
MAX_LUT_POINTS = 65536
#: Most points of an optics MTF table.
MAX_MTF_POINTS = 4096
#: Largest Gaussian sigma or defocus radius, pixels.
MAX_BLUR_PX = 256.0
#: Largest side of a PSF image, pixels.
MAX_PSF_PX = 1025


def _illuminant_problem(name: str) -> str | None:
    """Why ``name`` is not an illuminant (None: it is one)."""
    try:
        load_illuminant(name)
    except FidelityError as exc:
        return str(exc)
    return None


def _named_illuminant(key: str, method: str, method_value: str
                      ) -> Callable[[Mapping[str, Any]], tuple[str, str] | None]:
    """Rule: ``key`` names a known illuminant (or ``scene``) when ``method`` is
    ``method_value``."""

    def test(t: Mapping[str, Any]) -> tuple[str, str] | None:
        name = t.get(key) or ""
        if t.get(method) != method_value or not name or name.lower() == "scene":
            return None
        problem = _illuminant_problem(name)
        return None if problem is None else (key, problem)

    return test


def lut_problem(lut: NDArray[np.float64]) -> str | None:
    """Why ``(K, 2)`` tone-curve points (linear input, encoded output) are not a tone curve:
    at least 2 points, strictly increasing inputs spanning [0, 1], outputs in [0, 1]."""
    if lut.shape[0] < 2 or not np.all(np.diff(lut[:, 0]) > 0):
        return "needs >= 2 points with strictly increasing inputs"
    if lut[0, 0] > 0 or lut[-1, 0] < 1:
        return "inputs must span [0, 1]"
    if np.any(lut[:, 1] < 0) or np.any(lut[:, 1] > 1):
        return "outputs must lie in [0, 1]"
    return None


#: What a camera file without its spectral sensitivities is told (it would otherwise be read
#: as the ideal camera without saying so).
SENSITIVITIES_REQUIRED = ("required: the camera's spectral sensitivities, source = 'ideal' "
                          "(the colorimetrically exact camera), 'file' with a CSV path, or "
                          f"one of {', '.join(COLOUR_CAMERAS)}")


def _sensitivities_given(t: Mapping[str, Any]) -> tuple[str, str] | None:
    """Rule: a camera file names its sensitivities (a file holding only ``name`` is no
    camera, not silently the ideal one)."""
    return None if "sensitivities" in t else ("sensitivities", SENSITIVITIES_REQUIRED)


def _source_given(t: Mapping[str, Any]) -> tuple[str, str] | None:
    """Rule: ``[sensitivities]`` says its ``source`` (``"ideal"`` explicitly for the ideal
    camera)."""
    return None if t.get("source") is not None else ("source", SENSITIVITIES_REQUIRED)


def _sensitivity_source(t: Mapping[str, Any]) -> tuple[str, str] | None:
    src = t.get("source")
    if src is None or src.lower() in ("ideal", "file") or src in COLOUR_CAMERAS:
        return None
    return ("source", f"must be 'ideal', 'file' or one of {', '.join(COLOUR_CAMERAS)}, "
                      f"got {src!r}")


def _fit_method(t: Mapping[str, Any]) -> tuple[str, str] | None:
    m = t.get("fit_method")
    if not m or any(m.lower() == k.lower() for k in CCM_FIT_METHODS):
        return None
    return "fit_method", f"must be one of {', '.join(CCM_FIT_METHODS)}, got {m!r}"


def _inline_lut(t: Mapping[str, Any]) -> tuple[str, str] | None:
    lut = t.get("lut")
    if not isinstance(lut, list):
        return None
    problem = lut_problem(np.asarray(lut, dtype=np.float64).reshape(-1, 2))
    return None if problem is None else ("lut", problem)


def _noise_needs_full_well(t: Mapping[str, Any]) -> tuple[str, str] | None:
    if t.get("full_well") is None and "read_noise" in t:
        return "full_well", "required when read_noise is given"
    return None


def _inline_mtf(t: Mapping[str, Any]) -> tuple[str, str] | None:
    table = t.get("mtf")
    if not isinstance(table, list):
        return None
    problem = mtf_table_problem(np.asarray(table, dtype=np.float64).reshape(-1, 2))
    return None if problem is None else ("mtf", problem)


def _mtf_given(t: Mapping[str, Any]) -> tuple[str, str] | None:
    if t.get("kind") == "mtf" and t.get("mtf") is None and t.get("mtf_file") is None:
        return "mtf", "required when kind = 'mtf' (or mtf_file)"
    return None


def _finite_row(n: int) -> sc.ListOf:
    return sc.ListOf(sc.Number(), min_items=n, max_items=n)


#: The schema of a camera file (TOML or YAML; the module docstring says what each stage does).
#: A field that only one method reads (``gains``, ``matrix``, ``lut``, ``path``) is checked
#: only when that method is chosen.
CAMERA_SCHEMA = sc.Table(fields=(
    sc.Field("name", sc.String(nonempty=True)),
    sc.Field("description", sc.String(), default=""),
    sc.Field("sensitivities", sc.Table(fields=(
        sc.Field("source", sc.String(nullable=True), default="ideal"),
        sc.Field("path", sc.String(nonempty=True), when=("source", ("file",))),
    ), rules=(sc.Check(_source_given), sc.Check(_sensitivity_source),
              sc.RequiredWhen("path", "source", ("file",)))),
        default={}),
    sc.Field("exposure", sc.Table(fields=(
        sc.Field("mode", sc.String(choices=EXPOSURE_MODES, lower=True), default="none"),
        sc.Field("gain", sc.Number(lo=0.0, lo_open=True), default=1.0),
        sc.Field("ev", sc.Number(lo=-30, hi=30, nullable=True)),
        sc.Field("target", sc.Number(lo=0.0, hi=1.0, lo_open=True), default=0.9),
    ), rules=(sc.Exclusive("gain", "ev"),)), default={}),
    sc.Field("white_balance", sc.Table(fields=(
        sc.Field("method", sc.String(choices=WHITE_BALANCE_METHODS, lower=True),
                 default="none"),
        sc.Field("gains", sc.ListOf(sc.Number(lo=0.0, lo_open=True), min_items=3, max_items=3,
                                    describe="3 positive numbers"),
                 when=("method", ("gains",))),
        sc.Field("illuminant", sc.String(nullable=True), default="scene"),
    ), rules=(sc.RequiredWhen("gains", "method", ("gains",)),
              sc.Check(_named_illuminant("illuminant", "method", "illuminant")))),
        default={}),
    sc.Field("ccm", sc.Table(fields=(
        sc.Field("method", sc.String(choices=CCM_METHODS, lower=True), default="none"),
        sc.Field("matrix", sc.ListOf(_finite_row(3), min_items=3, max_items=3,
                                     describe="a 3x3 array of finite numbers"),
                 when=("method", ("matrix",))),
        sc.Field("fit_method", sc.String(nullable=True), default="Cheung 2004"),
        sc.Field("fit_illuminant", sc.String(nullable=True), default="D65"),
    ), rules=(sc.RequiredWhen("matrix", "method", ("matrix",)), sc.Check(_fit_method),
              sc.Check(_named_illuminant("fit_illuminant", "method", "fit")))), default={}),
    sc.Field("tone", sc.Table(fields=(
        sc.Field("curve", sc.String(choices=TONE_CURVES, lower=True), default="linear"),
        sc.Field("gamma", sc.Number(lo=0.0, hi=10.0, lo_open=True), default=2.2),
        sc.Field("lut", sc.OneOf(options=(
            sc.String(), sc.ListOf(_finite_row(2), max_items=MAX_LUT_POINTS)),
            describe=f"a CSV path or [[x, y], ...] of finite numbers (at most "
                     f"{MAX_LUT_POINTS} points)"),
            when=("curve", ("lut",))),
    ), rules=(sc.RequiredWhen("lut", "curve", ("lut",)), sc.Check(_inline_lut))), default={}),
    sc.Field("noise", sc.Table(fields=(
        sc.Field("full_well", sc.Number(lo=1.0, nullable=True)),
        sc.Field("read_noise", sc.Number(lo=0.0), default=0.0),
        sc.Field("seed", sc.Integer(lo=0, hi=2**63 - 1), default=0),
    ), rules=(sc.Check(_noise_needs_full_well),)), default={}),
    sc.Field("quantisation", sc.Table(fields=(
        sc.Field("bits", sc.Integer(lo=1, hi=16, nullable=True)),)), default={}),
    sc.Field("vignetting", sc.Table(fields=(
        sc.Field("diagonal_fov_deg", sc.Number(lo=0.0, hi=179.0, lo_open=True,
                                               nullable=True)),)), default={}),
    sc.Field("optics", sc.Table(fields=(
        sc.Field("kind", sc.String(choices=OPTICS_KINDS, lower=True), default="none"),
        sc.Field("sigma_px", sc.Number(lo=0.0, hi=MAX_BLUR_PX), when=("kind", ("gaussian",))),
        sc.Field("radius_px", sc.Number(lo=0.0, hi=MAX_BLUR_PX), when=("kind", ("defocus",))),
        sc.Field("f_number", sc.Number(lo=0.0, hi=1000.0, lo_open=True),
                 when=("kind", ("diffraction",))),
        sc.Field("wavelength_nm", sc.Number(lo=100.0, hi=20000.0), default=550.0),
        sc.Field("pixel_pitch_um", sc.Number(lo=0.0, hi=1000.0, lo_open=True),
                 when=("kind", ("diffraction",))),
        sc.Field("mtf", sc.ListOf(_finite_row(2), max_items=MAX_MTF_POINTS,
                                  describe=f"[[frequency cy/px, MTF], ...] of finite numbers "
                                           f"(at most {MAX_MTF_POINTS} points)"),
                 when=("kind", ("mtf",))),
        sc.Field("mtf_file", sc.String(nonempty=True), when=("kind", ("mtf",))),
        sc.Field("psf_file", sc.String(nonempty=True), when=("kind", ("psf",))),
    ), rules=(sc.RequiredWhen("sigma_px", "kind", ("gaussian",)),
              sc.RequiredWhen("radius_px", "kind", ("defocus",)),
              sc.RequiredWhen("f_number", "kind", ("diffraction",)),
              sc.RequiredWhen("pixel_pitch_um", "kind", ("diffraction",)),
              sc.RequiredWhen("psf_file", "kind", ("psf",)),
              sc.Exclusive("mtf", "mtf_file"), sc.Check(_mtf_given), sc.Check(_inline_mtf))),
        default={}),
), rules=(sc.Check(_sensitivities_given),))


def camera_from_dict(data: Any, origin: str = "<dict>", base_dir: Path | None = None) -> CameraModel:
    """Build and validate a :class:`CameraModel` from a parsed camera file (module docstring).

    The file is checked against :data:`CAMERA_SCHEMA`; ``base_dir`` resolves relative paths
    (sensitivity CSV, LUT file). Raises :class:`InputFileError` naming the file, the field and
    the problem (``camera file <origin>: [section].field: problem``).
    """
    where = f"camera file {origin}"
    v = sc.validate(data, CAMERA_SCHEMA, where, sections=True)
    base = base_dir or Path.cwd()

    def error(section: str, key: str, problem: str) -> InputFileError:
        return sc.SchemaError(f"{where}: [{section}].{key}: {problem}")

    def file_in(section: str, key: str, spec: str) -> Path:
        return Path(spec) if Path(spec).is_absolute() else base / spec

    name = v.get("name", Path(origin).stem)
    sv = v["sensitivities"]
    src = sv["source"]
    if src is None or src.lower() == "ideal":
        sens = ideal_sensitivities()
    elif src.lower() == "file":
        p = file_in("sensitivities", "path", sv["path"])
        try:
            wl, vals = read_spectral_csv(p, columns=3, what="sensitivity CSV")
        except FidelityError as exc:
            raise error("sensitivities", "path", str(exc)) from None
        if np.any(vals < 0) or not np.all(vals.max(axis=0) > 0):
            raise error("sensitivities", "path",
                        f"{p}: sensitivities must be >= 0 with a positive peak per channel")
        sens = Sensitivities(f"file {p}", wl, vals)
    else:
        sens = colour_camera_sensitivities(src)

    ev = v["exposure"]
    gain = 2.0 ** ev["ev"] if ev.get("ev") is not None else ev["gain"]
    exposure = Exposure(ev["mode"], float(gain), float(ev["target"]))

    wv = v["white_balance"]
    gains = tuple(wv["gains"]) if wv["method"] == "gains" else None
    wb = WhiteBalance(wv["method"], gains, wv["illuminant"] or "scene")

    cv = v["ccm"]
    matrix = (tuple(tuple(row) for row in cv["matrix"]) if cv["method"] == "matrix" else None)
    ccm = ColourCorrection(cv["method"], matrix,
                           cv["fit_method"] or "Cheung 2004", cv["fit_illuminant"] or "D65")

    tv = v["tone"]
    lut = None
    if tv["curve"] == "lut":
        spec = tv["lut"]
        if isinstance(spec, str):
            p = file_in("tone", "lut", spec)
            try:
                wl, vals = read_spectral_csv(p, columns=1, what="tone LUT file")
            except FidelityError as exc:
                raise error("tone", "lut", str(exc)) from None
            arr = np.column_stack([wl, vals[:, 0]])
            problem = lut_problem(arr)
            if problem:
                raise error("tone", "lut", problem)
        else:
            arr = np.asarray(spec, dtype=np.float64).reshape(-1, 2)
        lut = tuple((float(a), float(b)) for a, b in arr)
    tone = ToneCurve(tv["curve"], float(tv["gamma"]), lut)

    nv = v["noise"]
    noise = Noise(nv.get("full_well"), float(nv["read_noise"]), int(nv["seed"]))
    bits = v["quantisation"].get("bits")
    fov = v["vignetting"].get("diagonal_fov_deg")
    optics = _optics(v["optics"], lambda key, spec: file_in("optics", key, spec),
                     lambda key, problem: error("optics", key, problem))
    return CameraModel(name, sens, v["description"], exposure, wb, ccm, tone, noise, bits, fov,
                       origin, optics)


def _optics(ov: Mapping[str, Any], file_in: Callable[[str, str], Path],
            error: Callable[[str, str], InputFileError]) -> Optics:
    """The :class:`Optics` of a validated ``[optics]`` section (its files read here)."""
    kind = ov["kind"]
    wavelength = float(ov["wavelength_nm"])
    if kind == "gaussian":
        return Optics(kind, sigma_px=float(ov["sigma_px"]), wavelength_nm=wavelength)
    if kind == "defocus":
        return Optics(kind, radius_px=float(ov["radius_px"]), wavelength_nm=wavelength)
    if kind == "diffraction":
        return Optics(kind, f_number=float(ov["f_number"]), wavelength_nm=wavelength,
                      pixel_pitch_um=float(ov["pixel_pitch_um"]))
    if kind == "mtf":
        source = ""
        if ov.get("mtf_file") is not None:
            p = file_in("mtf_file", ov["mtf_file"])
            if not p.is_file():
                raise error("mtf_file", f"{display_path(p)}: no such file")
            try:
                table = read_mtf_file(str(p))
            except FidelityError as exc:
                raise error("mtf_file", str(exc)) from None
            problem = mtf_table_problem(table)
            if problem:
                raise error("mtf_file", f"{display_path(p)}: {problem}")
            source = display_path(p)
        else:
            table = np.asarray(ov["mtf"], dtype=np.float64).reshape(-1, 2)
        return Optics(kind, wavelength_nm=wavelength, source=source,
                      mtf_table=tuple((float(a), float(b)) for a, b in table))
    if kind == "psf":
        p = file_in("psf_file", ov["psf_file"])
        if not p.is_file():
            raise error("psf_file", f"{display_path(p)}: no such file")
        try:
            psf = read_psf_file(str(p))
        except FidelityError as exc:
            raise error("psf_file", str(exc)) from None
        problem = psf_problem(psf)
        if problem is None and max(psf.shape) > MAX_PSF_PX:
            problem = f"at most {MAX_PSF_PX} x {MAX_PSF_PX} pixels, got {psf.shape[0]} x " \
                      f"{psf.shape[1]}"
        if problem:
            raise error("psf_file", f"{display_path(p)}: {problem}")
        return Optics(kind, wavelength_nm=wavelength, source=display_path(p),
                      psf=tuple(tuple(float(x) for x in row) for row in psf / psf.sum()))
    return Optics()


def camera_files(name_or_path: str | os.PathLike[str]) -> list[Path]:
    """The files reading a camera touches: the camera file and the sensitivity CSV, tone
    LUT file and optics MTF or PSF file it names (none for a built-in camera name; only the camera file itself when it
    cannot be parsed). For the overwrite check of a command whose camera could not be loaded;
    a loaded camera knows its :attr:`CameraModel.files`."""
    p = Path(name_or_path)
    if str(name_or_path) in available_cameras() or not p.is_file():
        return []
    try:
        data = sc.load_document(p, max_bytes=MAX_CAMERA_FILE_BYTES)
    except FidelityError:
        return [p]
    return [p, *_named_files(data, p)]


def _named_files(data: Any, path: Path) -> list[Path]:
    """The sensitivity CSV, tone LUT file and optics MTF or PSF file a parsed camera file at
    ``path`` names."""
    files = []
    for section, key in (("sensitivities", "path"), ("tone", "lut"), ("optics", "mtf_file"),
                         ("optics", "psf_file")):
        table = data.get(section) if isinstance(data, dict) else None
        spec = table.get(key) if isinstance(table, dict) else None
        if isinstance(spec, str) and spec:
            files.append(Path(spec) if Path(spec).is_absolute() else path.parent / spec)
    return files


def read_camera_file(path: str | Path) -> CameraModel:
    """Parse and validate a TOML (``.toml``) or YAML (``.yaml``/``.yml``) camera file."""
    p = require_file(path, "camera file")
    suffix = p.suffix.lower()
    if suffix not in (".toml", ".yaml", ".yml"):
        raise InputFileError(f"camera file {display_path(p)}: expected a .toml, .yaml or "
                             ".yml file")
    data = sc.load_document(p, f"camera file {display_path(p)}",
                            max_bytes=MAX_CAMERA_FILE_BYTES, what="camera file")
    return replace(camera_from_dict(data, display_path(p), p.parent), named=str(path),
                   files=(p, *_named_files(data, p)))


def _builtin_dir() -> Path:
    return resource_dir("data") / "cameras"


def available_cameras() -> list[str]:
    """Names of the built-in cameras (``fidelity/data/cameras/*.toml``)."""
    return sorted(p.stem for p in _builtin_dir().glob("*.toml"))


def camera_file(camera: CameraModel) -> Path | None:
    """The file ``camera`` was read from: its camera file, or the shipped file of a built-in
    camera (``fidelity/data/cameras/NAME.toml``); None for a camera made in code."""
    if camera.files:
        return camera.files[0]
    if camera.named in available_cameras():
        return _builtin_dir() / f"{camera.named}.toml"
    return None


@lru_cache(maxsize=16)
def _load_builtin(name: str) -> CameraModel:
    cam = read_camera_file(_builtin_dir() / f"{name}.toml")
    return replace(cam, source=f"built-in {name}", named=name, files=())


def load_camera(name_or_path: str | Path) -> CameraModel:
    """A built-in camera by name (:func:`available_cameras`) or a TOML/YAML camera file.

    A camera file is validated against :data:`CAMERA_SCHEMA` (:func:`camera_from_dict`;
    relative sensitivity-CSV and LUT paths are relative to the file's folder).

    Parameters
    ----------
    name_or_path
        A built-in camera's name (``nikon-5100``, ...), or the path of a ``.toml``,
        ``.yaml`` or ``.yml`` camera file (at most :data:`MAX_CAMERA_FILE_BYTES` bytes).

    Returns
    -------
    CameraModel
        The camera, frozen (a built-in one is read once a process).

    Raises
    ------
    InputFileError
        A camera file that is missing, of another suffix, unreadable, or whose content does
        not fit the schema (the message names the file, the ``[section].field`` and the
        problem). Exit code 2.
    UnknownNameError
        Neither a built-in name nor a camera file path. Exit code 2.
    """
    s = str(name_or_path)
    if s in available_cameras():
        return _load_builtin(s)
    p = Path(s)
    if p.suffix.lower() in (".toml", ".yaml", ".yml") or p.exists():
        return read_camera_file(p)
    raise unknown_name("camera", s, available_cameras())


__all__ = [
    "camera_file",
    "CCM_FIT_METHODS",
    "CCM_METHODS",
    "DEFAULT_CAMERA",
    "EXPOSURE_MODES",
    "TONE_CURVES",
    "WHITE_BALANCE_METHODS",
    "CameraModel",
    "ColourCorrection",
    "Developed",
    "Exposure",
    "Noise",
    "Sensitivities",
    "ToneCurve",
    "WhiteBalance",
    "add_sensor_noise",
    "apply_tone_curve",
    "available_cameras",
    "camera_from_dict",
    "CAMERA_SCHEMA",
    "camera_files",
    "camera_response",
    "lut_problem",
    "colour_camera_sensitivities",
    "colour_correction_matrix",
    "develop",
    "exposure_gain",
    "fit_colour_correction",
    "ideal_sensitivities",
    "load_camera",
    "optics_json",
    "quantise",
    "read_camera_file",
    "vignetting_gain",
    "white_balance_gains",
]
