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
import tomllib
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

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
from fidelity.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.fileio import require_file
from fidelity.resources import resource_dir

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


@dataclass(frozen=True)
class Sensitivities:
    """Camera spectral sensitivities: ``wavelengths`` (N,) nm, ``values`` (N, 3) r, g, b."""

    name: str
    wavelengths: FloatArray
    values: FloatArray

    def on_grid(self, step: float = GRID_STEP_NM) -> FloatArray:
        """Sensitivities (M, 3) on :func:`fidelity.colour.spectral.wavelength_grid` (zero outside)."""
        return resample(self.wavelengths, self.values, wavelength_grid(step), extrapolation="zero")


@dataclass(frozen=True)
class Exposure:
    """Exposure stage: ``mode`` in :data:`EXPOSURE_MODES`; ``gain``; ``target`` for auto."""

    mode: str = "none"
    gain: float = 1.0
    target: float = 0.9


@dataclass(frozen=True)
class WhiteBalance:
    """White balance: ``method`` in :data:`WHITE_BALANCE_METHODS`; ``gains``; ``illuminant``."""

    method: str = "none"
    gains: tuple[float, float, float] | None = None
    illuminant: str = "scene"


@dataclass(frozen=True)
class ColourCorrection:
    """3x3 CCM: ``method`` in :data:`CCM_METHODS`; ``matrix`` (given); ``fit_method``."""

    method: str = "none"
    matrix: tuple[tuple[float, float, float], ...] | None = None
    fit_method: str = "Cheung 2004"
    fit_illuminant: str = "D65"


@dataclass(frozen=True)
class ToneCurve:
    """Tone curve: ``curve`` in :data:`TONE_CURVES`; ``gamma``; ``lut`` (K, 2) pairs."""

    curve: str = "linear"
    gamma: float = 2.2
    lut: tuple[tuple[float, float], ...] | None = None


@dataclass(frozen=True)
class Noise:
    """Sensor noise: ``full_well`` electrons at raw 1, ``read_noise`` e- rms, ``seed``."""

    full_well: float | None = None
    read_noise: float = 0.0
    seed: int = 0

    @property
    def enabled(self) -> bool:
        """True when the stage adds noise."""
        return self.full_well is not None


@dataclass(frozen=True)
class CameraModel:
    """A simulated camera: sensitivities plus the optional ISP stages (module docstring)."""

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

    @property
    def output_encoding(self) -> str:
        """``"linear"`` (float linear sRGB) or ``"display"`` (encoded, clipped to [0, 1])."""
        return "linear" if self.tone.curve == "linear" else "display"

    @property
    def clips(self) -> bool:
        """True when the output is clipped to [0, 1] (display curve or quantisation)."""
        return self.output_encoding == "display" or self.quantisation_bits is not None

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
        return d


# --------------------------------------------------------------------------------------------
# Sensitivities
# --------------------------------------------------------------------------------------------


def ideal_sensitivities() -> Sensitivities:
    """M(XYZ -> linear sRGB) @ CIE 1931 2° CMFs on the 1 nm grid (has negative lobes).

    With these, camera RGB = M @ XYZ exactly, so the camera reproduces sRGB colorimetrically.
    """
    from fidelity.colour.colorimetry import MATRIX_XYZ_TO_LINEAR_SRGB

    values = cie_1931_cmfs() @ np.asarray(MATRIX_XYZ_TO_LINEAR_SRGB).T
    return Sensitivities("ideal (M_XYZ->sRGB @ CIE 1931 2 degree CMFs)", wavelength_grid(), values)


def colour_camera_sensitivities(name: str) -> Sensitivities:
    """Sensitivities of a camera in ``colour.MSDS_CAMERA_SENSITIVITIES`` (peak-normalised)."""
    import colour

    key = COLOUR_CAMERAS.get(name)
    if key is None:
        raise unknown_name("camera sensitivities", name, ["ideal", "file", *COLOUR_CAMERAS])
    msds = colour.MSDS_CAMERA_SENSITIVITIES[key]
    return Sensitivities(f"{name} (colour.MSDS_CAMERA_SENSITIVITIES)",
                         np.asarray(msds.wavelengths, float), np.asarray(msds.values, float))


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
    sigma = np.sqrt(np.maximum(img, 0.0) / fw + (noise.read_noise / fw) ** 2)
    return img + sigma * rng.standard_normal(img.shape)


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
    """3x3 matrix M minimising ||camera_rgb @ M.T - target||^2 (colour.characterisation).

    ``method`` in :data:`CCM_FIT_METHODS` (Cheung, Westland, Connah, Ripamonti 2004, 3 terms;
    Finlayson, Mackiewicz, Hurlbert 2015, degree 1). Inputs (K, 3), K >= 3.
    """
    import colour

    key = next((k for k in CCM_FIT_METHODS if k.lower() == method.lower()), None)
    if key is None:
        raise unknown_name("colour-correction fit method", method, CCM_FIT_METHODS)
    m = colour.characterisation.matrix_colour_correction(
        np.asarray(camera_rgb, float), np.asarray(target_linear_srgb, float), method=key,
        **CCM_FIT_METHODS[key],
    )
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
    from fidelity.colour.colorimetry import delinearize_srgb

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


@dataclass(frozen=True)
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
    from fidelity.colour.colorimetry import delinearize_srgb

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

_SECTIONS: dict[str, tuple[str, ...]] = {
    "sensitivities": ("source", "path"),
    "exposure": ("mode", "gain", "ev", "target"),
    "white_balance": ("method", "gains", "illuminant"),
    "ccm": ("method", "matrix", "fit_method", "fit_illuminant"),
    "tone": ("curve", "gamma", "lut"),
    "noise": ("full_well", "read_noise", "seed"),
    "quantisation": ("bits",),
    "vignetting": ("diagonal_fov_deg",),
}
_TOP = ("name", "description", *_SECTIONS)


class _Reader:
    """Typed access to one camera-file table with errors naming file, field and problem."""

    def __init__(self, origin: str, section: str, table: Any) -> None:
        self.origin, self.section = origin, section
        if not isinstance(table, dict):
            raise self.error("", f"must be a table, got {type(table).__name__}")
        unknown = set(table) - set(_SECTIONS[section])
        if unknown:
            raise self.error(sorted(unknown)[0],
                             f"unknown field; known: {', '.join(_SECTIONS[section])}")
        self.table = table

    def error(self, key: str, msg: str) -> InputFileError:
        where = f"[{self.section}]" + (f".{key}" if key else "")
        return InputFileError(f"camera file {self.origin}: {where}: {msg}")

    def choice(self, key: str, choices: tuple[str, ...], default: str) -> str:
        v = self.table.get(key, default)
        if not isinstance(v, str) or v.lower() not in choices:
            raise self.error(key, f"must be one of {', '.join(choices)}, got {v!r}")
        return v.lower()

    def string(self, key: str, default: str | None = None) -> str | None:
        v = self.table.get(key, default)
        if v is not None and not isinstance(v, str):
            raise self.error(key, f"must be a string, got {v!r}")
        return v

    @overload
    def number(self, key: str, default: float, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float: ...

    @overload
    def number(self, key: str, default: None, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float | None: ...

    def number(self, key: str, default: float | None, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float | None:
        v = self.table.get(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise self.error(key, f"must be a finite number, got {v!r}")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise self.error(key, f"must be {'>' if lo_open else '>='} {lo:g}, got {v!r}")
        if hi is not None and v > hi:
            raise self.error(key, f"must be <= {hi:g}, got {v!r}")
        return float(v)

    @overload
    def integer(self, key: str, default: int, lo: int, hi: int) -> int: ...

    @overload
    def integer(self, key: str, default: None, lo: int, hi: int) -> int | None: ...

    def integer(self, key: str, default: int | None, lo: int, hi: int) -> int | None:
        v = self.table.get(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.error(key, f"must be an integer in [{lo}, {hi}], got {v!r}")
        return int(v)

    def matrix(self, key: str, rows: int | None, cols: int) -> FloatArray:
        v = self.table.get(key)
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.empty(0)
        if a.ndim != 2 or a.shape[1] != cols or (rows is not None and a.shape[0] != rows) or (
            not np.all(np.isfinite(a))
        ):
            shape = f"{rows}x{cols}" if rows else f"Kx{cols}"
            raise self.error(key, f"must be a {shape} array of finite numbers, got {v!r}")
        return a


def camera_from_dict(data: Any, origin: str = "<dict>", base_dir: Path | None = None) -> CameraModel:
    """Build and validate a :class:`CameraModel` from a parsed camera file (module docstring).

    ``base_dir`` resolves relative paths (sensitivity CSV, LUT file). Raises
    :class:`InputFileError` naming the file, the field and the problem.
    """
    if not isinstance(data, dict):
        raise InputFileError(f"camera file {origin}: top level must be a table")
    unknown = set(data) - set(_TOP)
    if unknown:
        raise InputFileError(f"camera file {origin}: unknown field {sorted(unknown)[0]!r}; "
                             f"known: {', '.join(_TOP)}")
    name = data.get("name", Path(origin).stem)
    if not isinstance(name, str) or not name:
        raise InputFileError(f"camera file {origin}: name must be a non-empty string")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise InputFileError(f"camera file {origin}: description must be a string")
    base = base_dir or Path.cwd()

    def sec(s: str) -> _Reader:
        return _Reader(origin, s, data.get(s, {}))

    # sensitivities
    r = sec("sensitivities")
    src = r.string("source", "ideal")
    if src is None or src.lower() == "ideal":
        sens = ideal_sensitivities()
    elif src.lower() == "file":
        path = r.string("path")
        if not path:
            raise r.error("path", "required when source = 'file'")
        p = Path(path) if Path(path).is_absolute() else base / path
        wl, vals = read_spectral_csv(p, columns=3, what="sensitivity CSV")
        if np.any(vals < 0) or not np.all(vals.max(axis=0) > 0):
            raise r.error("path", f"{p}: sensitivities must be >= 0 with a positive peak per channel")
        sens = Sensitivities(f"file {p}", wl, vals)
    elif src in COLOUR_CAMERAS:
        sens = colour_camera_sensitivities(src)
    else:
        raise r.error("source", f"must be 'ideal', 'file' or one of {', '.join(COLOUR_CAMERAS)},"
                                f" got {src!r}")

    r = sec("exposure")
    mode = r.choice("mode", EXPOSURE_MODES, "none")
    gain = r.number("gain", 1.0, lo=0.0, lo_open=True)
    ev = r.number("ev", None, lo=-30, hi=30)
    if ev is not None:
        if "gain" in r.table:
            raise r.error("ev", "give either gain or ev, not both")
        gain = 2.0**ev
    exposure = Exposure(mode, float(gain), float(r.number("target", 0.9, lo=0.0, hi=1.0,
                                                            lo_open=True)))

    r = sec("white_balance")
    method = r.choice("method", WHITE_BALANCE_METHODS, "none")
    gains = None
    if method == "gains":
        if "gains" not in r.table:
            raise r.error("gains", "required when method = 'gains'")
        raw_gains = r.table["gains"]
        ok = isinstance(raw_gains, list) and len(raw_gains) == 3 and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) and x > 0
            for x in raw_gains
        )
        if not ok:
            raise r.error("gains", f"must be 3 positive numbers, got {raw_gains!r}")
        gains = (float(raw_gains[0]), float(raw_gains[1]), float(raw_gains[2]))
    wb_ill = r.string("illuminant", "scene") or "scene"
    if method == "illuminant" and wb_ill.lower() != "scene":
        _check_illuminant(r, "illuminant", wb_ill)
    wb = WhiteBalance(method, gains, wb_ill)

    r = sec("ccm")
    method = r.choice("method", CCM_METHODS, "none")
    matrix = None
    if method == "matrix":
        if "matrix" not in r.table:
            raise r.error("matrix", "required when method = 'matrix'")
        m = r.matrix("matrix", 3, 3)
        matrix = tuple(tuple(float(x) for x in row) for row in m)
    fit_method = r.string("fit_method", "Cheung 2004") or "Cheung 2004"
    if not any(fit_method.lower() == k.lower() for k in CCM_FIT_METHODS):
        raise r.error("fit_method", f"must be one of {', '.join(CCM_FIT_METHODS)}, got {fit_method!r}")
    fit_ill = r.string("fit_illuminant", "D65") or "D65"
    if method == "fit" and fit_ill.lower() != "scene":
        _check_illuminant(r, "fit_illuminant", fit_ill)
    ccm = ColourCorrection(method, matrix, fit_method, fit_ill)  # type: ignore[arg-type]

    r = sec("tone")
    curve = r.choice("curve", TONE_CURVES, "linear")
    gamma = float(r.number("gamma", 2.2, lo=0.0, hi=10.0, lo_open=True))
    lut = None
    if curve == "lut":
        spec = r.table.get("lut")
        if isinstance(spec, str):
            p = Path(spec) if Path(spec).is_absolute() else base / spec
            wl, vals = read_spectral_csv(p, columns=1, what="tone LUT file")
            arr = np.column_stack([wl, vals[:, 0]])
        elif spec is None:
            raise r.error("lut", "required when curve = 'lut' (a CSV path or [[x, y], ...])")
        else:
            arr = r.matrix("lut", None, 2)
        if arr.shape[0] < 2 or not np.all(np.diff(arr[:, 0]) > 0):
            raise r.error("lut", "needs >= 2 points with strictly increasing inputs")
        if arr[0, 0] > 0 or arr[-1, 0] < 1:
            raise r.error("lut", "inputs must span [0, 1]")
        if np.any(arr[:, 1] < 0) or np.any(arr[:, 1] > 1):
            raise r.error("lut", "outputs must lie in [0, 1]")
        lut = tuple((float(a), float(b)) for a, b in arr)
    tone = ToneCurve(curve, gamma, lut)

    r = sec("noise")
    fw = r.number("full_well", None, lo=1.0)
    noise = Noise(fw, float(r.number("read_noise", 0.0, lo=0.0)),
                  int(r.integer("seed", 0, 0, 2**63 - 1)))
    if fw is None and "read_noise" in r.table:
        raise r.error("full_well", "required when read_noise is given")

    bits = sec("quantisation").integer("bits", None, 1, 16)
    fov = sec("vignetting").number("diagonal_fov_deg", None, lo=0.0, hi=179.0, lo_open=True)
    return CameraModel(name, sens, desc, exposure, wb, ccm, tone, noise, bits, fov, origin)


def _check_illuminant(r: _Reader, key: str, name: str) -> None:
    try:
        load_illuminant(name)
    except Exception as exc:  # noqa: BLE001 - re-raised with the field named
        raise r.error(key, str(exc)) from None


def read_camera_file(path: str | Path) -> CameraModel:
    """Parse and validate a TOML (``.toml``) or YAML (``.yaml``/``.yml``) camera file."""
    p = require_file(path, "camera file")
    suffix = p.suffix.lower()
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"camera file {p}: cannot read ({exc})") from exc
    if suffix == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputFileError(f"camera file {p}: invalid TOML ({exc})") from exc
    elif suffix in (".yaml", ".yml"):
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            msg = str(exc).replace("\n", " ")
            raise InputFileError(f"camera file {p}: invalid YAML ({msg})") from exc
    else:
        raise InputFileError(f"camera file {p}: expected a .toml, .yaml or .yml file")
    return camera_from_dict(data, str(p), p.parent)


def _builtin_dir() -> Path:
    return resource_dir("data") / "cameras"


def available_cameras() -> list[str]:
    """Names of the built-in cameras (``fidelity/data/cameras/*.toml``)."""
    return sorted(p.stem for p in _builtin_dir().glob("*.toml"))


@lru_cache(maxsize=16)
def _load_builtin(name: str) -> CameraModel:
    cam = read_camera_file(_builtin_dir() / f"{name}.toml")
    return replace(cam, source=f"built-in {name}")


def load_camera(name_or_path: str | Path) -> CameraModel:
    """A built-in camera by name (:func:`available_cameras`) or a TOML/YAML camera file."""
    s = str(name_or_path)
    if s in available_cameras():
        return _load_builtin(s)
    p = Path(s)
    if p.suffix.lower() in (".toml", ".yaml", ".yml") or p.exists():
        return read_camera_file(p)
    raise unknown_name("camera", s, available_cameras())


__all__ = [
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
    "camera_response",
    "colour_camera_sensitivities",
    "colour_correction_matrix",
    "develop",
    "exposure_gain",
    "fit_colour_correction",
    "ideal_sensitivities",
    "load_camera",
    "quantise",
    "read_camera_file",
    "vignetting_gain",
    "white_balance_gains",
]
