"""Spectral data and spectral integration for the rendered chart.

Everything spectral in fidelity lives on one documented wavelength grid,
:data:`WAVELENGTHS_NM` = 380, 381, ..., 780 nm (1 nm steps, 401 samples). 380-780 nm is the
range of CIE 15:2018 for colorimetric computations and the range every shipped data set covers
(the CIE 1931 colour-matching functions extend to 360-830 nm, but their values outside
380-780 nm change tristimulus values by less than 1e-4). A coarser grid (e.g. 10 nm, to show the
sampling error of line spectra) is obtained with ``step=``.

Resampling rule (one rule, no hidden smoothing): tabulated data are linearly interpolated onto
the grid (``numpy.interp``). Outside their tabulated range, *reflectances* are held constant at
their end values (the nearest measured value, the usual practice of CIE 15 and ASTM E308;
BabelColor data stop at 730 nm), while *illuminants* and *sensitivities* are zero (no light,
no response).

Integration rule: a Riemann sum on the uniform grid (the summation of CIE 15:2018 section 7,
as in ASTM E308 with 1 nm tables), ``sum_i f(lambda_i) * dlambda``. Tristimulus values are normalised so that the
perfect reflecting diffuser under the illuminant has Y = 1 (not 100):

    X = k * sum_i R(l_i) E(l_i) xbar(l_i) dl,   k = 1 / sum_i E(l_i) ybar(l_i) dl.

Scene-consistent reference (issue 3, requirement 2): the colour of each patch under the scene
illuminant, adapted from the illuminant's white to the sRGB D65 white by a named chromatic
adaptation transform (von Kries-type, :data:`CHROMATIC_ADAPTATION_METHODS`), expressed as CIELAB
(D65) and sRGB. See :func:`scene_reference`.
"""

from __future__ import annotations

import json
import re
from dataclasses import field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour import colorimetry as cm
from fidelity.colour import datasets
from fidelity.colour.colorimetry import matrix_chromatic_adaptation
from fidelity.colour.datasets import cmfs_1931
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import require_file
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

FloatArray = NDArray[np.float64]

#: First, last wavelength and step of the default integration grid (nm).
GRID_START_NM: float = 380.0
GRID_END_NM: float = 780.0
GRID_STEP_NM: float = 1.0


def wavelength_grid(step: float = GRID_STEP_NM) -> FloatArray:
    """The integration grid 380..780 nm with spacing ``step`` nm (default 1 nm).

    ``step`` must divide 400 nm into whole steps (1, 2, 4, 5, 10, 20 ... nm).
    """
    ok = isinstance(step, int | float) and np.isfinite(step) and step > 0
    n = (GRID_END_NM - GRID_START_NM) / float(step) if ok else np.nan
    if not np.isfinite(n) or abs(n - round(n)) > 1e-9:
        raise InvalidValueError(
            f"wavelength step {step!r} nm must be positive and divide {GRID_END_NM - GRID_START_NM:g} nm"
        )
    return GRID_START_NM + float(step) * np.arange(round(n) + 1, dtype=np.float64)


#: The default grid, 380..780 nm at 1 nm (401 samples).
WAVELENGTHS_NM: FloatArray = wavelength_grid()
WAVELENGTHS_NM.setflags(write=False)


def resample(
    wavelengths: ArrayLike, values: ArrayLike, grid: ArrayLike, *, extrapolation: str = "zero"
) -> FloatArray:
    """Linearly interpolate tabulated spectra onto ``grid``.

    ``values`` has shape (N,) or (N, k) (one column per channel) for N ``wavelengths``
    (strictly increasing, nm). ``extrapolation`` is ``"zero"`` (illuminants, sensitivities) or
    ``"constant"`` (reflectances: end values held). Returns shape (len(grid),) or (len(grid), k).
    """
    wl = np.asarray(wavelengths, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    g = np.asarray(grid, dtype=np.float64)
    if extrapolation not in ("zero", "constant"):
        raise unknown_name("extrapolation", extrapolation, ("zero", "constant"))
    one_d = v.ndim == 1
    v2 = v[:, None] if one_d else v
    out = np.empty((g.size, v2.shape[1]), dtype=np.float64)
    for c in range(v2.shape[1]):
        if extrapolation == "zero":
            out[:, c] = np.interp(g, wl, v2[:, c], left=0.0, right=0.0)
        else:
            out[:, c] = np.interp(g, wl, v2[:, c])
    return out[:, 0] if one_d else out


# --------------------------------------------------------------------------------------------
# Patch reflectances (charts/spectra/*.json)
# --------------------------------------------------------------------------------------------

#: Reflectance sets: name -> file in ``charts/spectra``.
SPECTRA_SETS: dict[str, str] = {
    "BabelColor Average": "babelcolor-average.json",
    "ColorChecker N Ohta": "colorchecker-n-ohta.json",
}


@record
class PatchSpectra:
    """Measured reflectance spectra of the 24 chart patches (row-major, 4 x 6).

    ``wavelengths`` (N,) nm as tabulated; ``reflectance`` (24, N) in [0, 1]; ``provenance``
    the source record from the data file.
    """

    name: str
    patch_names: tuple[str, ...]
    wavelengths: FloatArray
    reflectance: FloatArray
    provenance: dict[str, Any] = field(default_factory=dict)

    def on_grid(self, step: float = GRID_STEP_NM) -> FloatArray:
        """Reflectances (24, M) on :func:`wavelength_grid` (linear, end values held)."""
        return resample(
            self.wavelengths, self.reflectance.T, wavelength_grid(step), extrapolation="constant"
        ).T


@lru_cache(maxsize=8)
def _load_spectra_file(path: str) -> PatchSpectra:
    p = require_file(path, "reflectance spectra file")
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
        wl = np.asarray(obj["wavelengths_nm"], dtype=np.float64)
        names = tuple(str(q["name"]) for q in obj["patches"])
        refl = np.asarray([q["reflectance"] for q in obj["patches"]], dtype=np.float64)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputFileError(f"{p}: not a reflectance spectra file ({exc})") from exc
    if refl.shape != (24, wl.size) or not np.all(np.diff(wl) > 0) or not np.all(np.isfinite(refl)):
        raise InputFileError(f"{p}: expected 24 finite spectra on increasing wavelengths")
    refl.setflags(write=False)
    wl.setflags(write=False)
    return PatchSpectra(str(obj.get("name", p.stem)), names, wl, refl, dict(obj.get("provenance", {})))


def load_patch_spectra(name: str = "BabelColor Average") -> PatchSpectra:
    """The 24 patch reflectances of the named set (:data:`SPECTRA_SETS`) or of a JSON file path.

    Source: colour-science ``SDS_COLOURCHECKERS`` (BabelColor 2012 average; N. Ohta 1997),
    copied into ``charts/spectra/`` with provenance (see ``charts/spectra/README.md``).
    """
    key = _match_name(name, SPECTRA_SETS)
    if key is not None:
        return _load_spectra_file(str(resource_dir("charts") / "spectra" / SPECTRA_SETS[key]))
    if Path(name).suffix.lower() == ".json":
        return _load_spectra_file(str(Path(name)))
    raise unknown_name("reflectance set", name, SPECTRA_SETS)


def available_spectra() -> list[str]:
    """Names of the shipped reflectance sets."""
    return sorted(SPECTRA_SETS)


def _match_name(name: str, registry: dict[str, str]) -> str | None:
    canon = re.sub(r"[\s_-]+", " ", name.strip().lower())
    for key in registry:
        if re.sub(r"[\s_-]+", " ", key.lower()) == canon:
            return key
    return None


# --------------------------------------------------------------------------------------------
# Illuminants
# --------------------------------------------------------------------------------------------

#: Named illuminants -> key in ``colour.SDS_ILLUMINANTS`` (CIE 15:2018 tables).
#: "LED" is CIE LED-B4, a phosphor-converted blue LED of about 5200 K (CIE 15:2018 table 12).
ILLUMINANTS: dict[str, str] = {
    "D65": "D65",
    "D50": "D50",
    "A": "A",
    "F2": "FL2",
    "F11": "FL11",
    "LED": "LED-B4",
}


@record
class Illuminant:
    """A relative spectral power distribution: ``wavelengths`` (N,) nm, ``values`` (N,) >= 0."""

    name: str
    wavelengths: FloatArray
    values: FloatArray
    source: str

    def on_grid(self, step: float = GRID_STEP_NM) -> FloatArray:
        """Relative SPD on :func:`wavelength_grid` (linear interpolation, zero outside)."""
        return resample(self.wavelengths, self.values, wavelength_grid(step), extrapolation="zero")


def load_illuminant(name_or_path: str) -> Illuminant:
    """An illuminant by name (:data:`ILLUMINANTS`, or any ``colour.SDS_ILLUMINANTS`` key) or file.

    A user SPD file is CSV (``.csv``/``.txt``/``.spd``): two columns, wavelength in nm and
    relative power, optional header line, ``,``/``;``/whitespace separated. It must have at
    least 2 rows, strictly increasing wavelengths, finite non-negative power that is not all
    zero, and cover 400-700 nm; light outside its range is taken as zero.
    """
    key = _match_name(name_or_path, ILLUMINANTS)
    shipped = datasets.illuminant(ILLUMINANTS[key]) if key is not None else None
    if key is not None and shipped is not None:
        return Illuminant(key, shipped[0], shipped[1],
                          f"CIE 15:2018 illuminant {ILLUMINANTS[key]} (colour.SDS_ILLUMINANTS)")
    import colour

    if key is not None:
        sd = colour.SDS_ILLUMINANTS[ILLUMINANTS[key]]
        return Illuminant(key, np.asarray(sd.wavelengths, float), np.asarray(sd.values, float),
                          f"CIE 15:2018 illuminant {ILLUMINANTS[key]} (colour.SDS_ILLUMINANTS)")
    if name_or_path in colour.SDS_ILLUMINANTS:
        sd = colour.SDS_ILLUMINANTS[name_or_path]
        return Illuminant(name_or_path, np.asarray(sd.wavelengths, float),
                          np.asarray(sd.values, float), f"colour.SDS_ILLUMINANTS[{name_or_path!r}]")
    p = Path(name_or_path)
    if p.suffix.lower() in (".csv", ".txt", ".spd") or p.exists():
        wl, values = read_spectral_csv(p, columns=1, what="illuminant SPD file")
        v = values[:, 0]
        if np.any(v < 0) or not np.any(v > 0):
            raise InputFileError(f"{p}: illuminant SPD must be non-negative and not all zero")
        if wl[0] > 400 or wl[-1] < 700:
            raise InputFileError(
                f"{p}: illuminant SPD covers {wl[0]:g}-{wl[-1]:g} nm; it must cover 400-700 nm"
            )
        return Illuminant(p.stem, wl, v, f"user SPD file {p}")
    raise unknown_name("illuminant", name_or_path, ILLUMINANTS)


def available_illuminants() -> list[str]:
    """Names of the built-in illuminants (any ``colour.SDS_ILLUMINANTS`` key also works)."""
    return list(ILLUMINANTS)


def read_spectral_csv(
    path: str | Path, columns: int, what: str = "spectral CSV file"
) -> tuple[FloatArray, FloatArray]:
    """Read ``wavelength, v1..v_columns`` rows; return (wavelengths (N,), values (N, columns)).

    Accepts an optional header line and ``,``, ``;``, tab or space separators. Raises
    :class:`InputFileError` naming the file, line and problem.
    """
    p = require_file(path, what)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{p}: cannot read {what} ({exc})") from exc
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        fields = [f for f in re.split(r"[,;\s]+", s) if f]
        try:
            nums = [float(f) for f in fields]
        except ValueError:
            if not rows:  # header
                continue
            raise InputFileError(f"{p}: line {lineno}: not numbers: {s!r}") from None
        if len(nums) != columns + 1:
            raise InputFileError(
                f"{p}: line {lineno}: expected {columns + 1} columns (wavelength + {columns}),"
                f" got {len(nums)}"
            )
        rows.append(nums)
    if len(rows) < 2:
        raise InputFileError(f"{p}: {what} needs at least 2 data rows")
    arr = np.asarray(rows, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise InputFileError(f"{p}: {what} contains NaN or infinite values")
    if not np.all(np.diff(arr[:, 0]) > 0):
        raise InputFileError(f"{p}: wavelengths must be strictly increasing")
    return arr[:, 0], arr[:, 1:]


# --------------------------------------------------------------------------------------------
# Colour-matching functions and integration
# --------------------------------------------------------------------------------------------


def cie_1931_cmfs(step: float = GRID_STEP_NM) -> FloatArray:
    """CIE 1931 2° standard observer xbar, ybar, zbar (N, 3) on :func:`wavelength_grid`.

    Source: CIE 018:2019 / CIE 15:2018 table (1 nm), via colour-science
    ``MSDS_CMFS['CIE 1931 2 Degree Standard Observer']``.
    """
    return _cmfs(float(step)).copy()


@lru_cache(maxsize=8)
def _cmfs(step: float) -> FloatArray:
    wavelengths, values = cmfs_1931()
    return resample(wavelengths, values, wavelength_grid(step), extrapolation="zero")


def integrate(spectra: ArrayLike, weights: ArrayLike, step: float = GRID_STEP_NM) -> FloatArray:
    """Riemann sum ``sum_i spectra[..., i] * weights[i, c] * step`` on the uniform grid.

    ``spectra`` (..., N), ``weights`` (N, k) -> (..., k). Both sampled on the same grid.
    """
    return np.asarray(spectra, dtype=np.float64) @ np.asarray(weights, dtype=np.float64) * step


def tristimulus(
    reflectance: ArrayLike, illuminant: ArrayLike, step: float = GRID_STEP_NM
) -> tuple[FloatArray, FloatArray]:
    """CIE XYZ of reflectances under an illuminant and of the illuminant's white (Y_white = 1).

    ``reflectance`` (..., N) and ``illuminant`` (N,) on :func:`wavelength_grid` (``step``).
    Returns (XYZ (..., 3), XYZ_white (3,)); CIE 15:2018 section 7 with k = 1/sum(E ybar dl).
    """
    e = np.asarray(illuminant, dtype=np.float64)
    cmfs = _cmfs(float(step))
    weights = e[:, None] * cmfs
    white = integrate(np.ones_like(e), weights, step)
    k = 1.0 / white[1]
    return integrate(reflectance, weights, step) * k, white * k


# --------------------------------------------------------------------------------------------
# Chromatic adaptation and the scene-consistent reference
# --------------------------------------------------------------------------------------------


@record
class SceneReference:
    """Reference colours of the 24 patches for a rendered scene.

    ``xyz_scene`` (24, 3): XYZ under the scene illuminant (Y_white = 1); ``white_xyz`` (3,) of
    the illuminant; ``xyz`` (24, 3) adapted to the sRGB D65 white; ``lab`` (24, 3) CIELAB D65;
    ``linear_srgb`` and ``srgb`` (24, 3), unclipped (out-of-gamut patches keep values < 0 or
    > 1); ``conventions`` records every choice.
    """

    patch_names: tuple[str, ...]
    xyz_scene: FloatArray
    white_xyz: FloatArray
    xyz: FloatArray
    lab: FloatArray
    linear_srgb: FloatArray
    srgb: FloatArray
    conventions: dict[str, Any]


def scene_reference(
    illuminant: str | Illuminant = "D65",
    spectra: str = "BabelColor Average",
    *,
    cat: str = "Bradford",
    step: float = GRID_STEP_NM,
) -> SceneReference:
    """Scene-consistent reference: each patch's colour under the scene illuminant, seen by the
    CIE 1931 2° observer, adapted to D65 by ``cat`` and expressed as CIELAB (D65) and sRGB.

    XYZ = k sum R E xbar dl (Y_white = 1); XYZ_D65 = M_cat(white_E -> D65_sRGB) XYZ; Lab from
    CIE 15:2018 with the sRGB D65 white (x, y = 0.3127, 0.3290); sRGB per IEC 61966-2-1, unclipped.
    Under D65 the adaptation only corrects the 1e-4 difference between the tabulated D65
    white and the sRGB white point, so the white patch lands on a* = b* = 0.
    """
    ill = illuminant if isinstance(illuminant, Illuminant) else load_illuminant(illuminant)
    ps = load_patch_spectra(spectra)
    xyz_scene, white = tristimulus(ps.on_grid(step), ill.on_grid(step), step)
    m = matrix_chromatic_adaptation(white, cm.WHITEPOINT_D65_XYZ, cat)
    xyz = xyz_scene @ m.T
    lin = cm.xyz_to_linear_srgb(xyz)
    conventions = {
        "observer": "CIE 1931 2 degree",
        "wavelengths_nm": f"{GRID_START_NM:g}-{GRID_END_NM:g} step {step:g}",
        "integration": "Riemann sum on the uniform grid; Y of the perfect white = 1",
        "resampling": "linear interpolation; reflectance held constant outside its data, light zero",
        "illuminant": ill.name,
        "illuminant_source": ill.source,
        "illuminant_white_xyz": [float(v) for v in white],
        "reflectances": ps.name,
        "chromatic_adaptation": cat if ill.name != "D65" else f"{cat} (tabulated D65 -> sRGB D65 white)",
        "reference_white": "sRGB D65, x=0.3127 y=0.3290, Y=1",
        "lab": "CIE 1976 L*a*b* relative to the sRGB D65 white",
        "srgb": "IEC 61966-2-1, unclipped (out-of-gamut patches may fall outside [0, 1])",
    }
    return SceneReference(
        ps.patch_names, xyz_scene, white, xyz, np.asarray(cm.xyz_to_lab(xyz), np.float64),
        np.asarray(lin, np.float64), np.asarray(cm.delinearize_srgb(lin), np.float64),
        conventions,
    )


__all__ = [
    "GRID_END_NM",
    "GRID_START_NM",
    "GRID_STEP_NM",
    "ILLUMINANTS",
    "SPECTRA_SETS",
    "WAVELENGTHS_NM",
    "Illuminant",
    "PatchSpectra",
    "SceneReference",
    "available_illuminants",
    "available_spectra",
    "cie_1931_cmfs",
    "integrate",
    "load_illuminant",
    "load_patch_spectra",
    "read_spectral_csv",
    "resample",
    "scene_reference",
    "tristimulus",
    "wavelength_grid",
]
