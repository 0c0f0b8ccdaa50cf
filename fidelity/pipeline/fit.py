"""Fix, not only flag: fit the correction that makes the simulated camera match the real one.

:func:`fit_correction` reads the same chart rendered by the simulator (SIM) and photographed by
the real camera (REAL), exactly as ``fidelity compare`` does (the same
:class:`~fidelity.chart.read.ReadOptions`, corners and normalisation), and fits a colour
correction from the simulated patch colours onto the real ones
(:mod:`fidelity.correction.models`):

1. Both charts are audited (:func:`fidelity.measure.pixels.measure_pixels`); the *fit space* is
   each chart's linear sRGB as audited (auto exposure for linear pixels), the simulated chart
   scaled by the normalisation (:func:`fidelity.correction.normalise.normalise`: ``exposure`` default,
   ``exposure+wb``, ``none``). What the normalisation matches is left out of the correction
   (the correction is conjugated by it): with ``exposure`` the correction keeps the
   simulator's exposure; with ``none`` it corrects the exposure too.
2. Patches clipped or saturated in either chart are excluded and named
   (:func:`fidelity.correction.models.usable_patches`); a nearly grey real chart (mean chroma
   of its colour patches below :data:`GREY_CHROMA`) is refused.
3. The model is fitted (conditioning checked, regularised or refused with a reason) and
   cross-validated (leave-3-patches-out).

The result is a :class:`Correction` on the simulator's *pixel values* (its encoding and
colourspace): ``apply(pixels)``, ``to_cube(path)`` (OpenColorIO's Baker,
:mod:`fidelity.correction.lut`), ``to_json()``.

:func:`fit_and_verify` checks the correction instead of assuming it: the ``.cube`` through
OpenColorIO's processor against the model itself, over the chart and a dense lattice
(:class:`LutCheck`; the smallest cube size of :data:`~fidelity.correction.lut.CUBE_SIZES`
within :data:`LUT_TOLERANCE` ΔE00), then the SIM pixels in the audit's sampling windows through
the cube by OpenColorIO (loaded from ``correction.ocio``), measured again (:func:`remeasure`:
the patch means of the whole corrected image in the same windows, at the windows' cost) and
compared with REAL: the sim-to-real ΔE00 and its predicted ΔmAP before and after
(:class:`FitReport`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.camera.model import colour_correction_matrix, read_camera_file
from fidelity.camera.render import ChartLayout, render_chart
from fidelity.chart.image import write_exr, write_png
from fidelity.chart.locate import window_pixels
from fidelity.chart.read import DEFAULT_READ, ReadOptions, read_input, reads_with_own_ocio
from fidelity.colour.colorimetry import (
    delinearize_srgb,
    delta_e_2000,
    linearize_srgb,
    matrix_rgb_to_linear_srgb,
)
from fidelity.colour.spectral import load_illuminant
from fidelity.core.errors import FidelityError, InvalidValueError
from fidelity.core.fileio import write_json_atomic, write_text_atomic
from fidelity.core.schema import load_document
from fidelity.correction.lut import (
    CUBE_SIZES,
    apply_processor,
    bake_cube,
    config_processor,
    cube_processor,
    lattice_inputs,
    ocio,
    ocio_config,
)
from fidelity.correction.models import (
    DEFAULT_OBJECTIVE,
    ColourModel,
    Conditioning,
    cross_validate,
    cross_validate_shared,
    fit_model,
    fit_shared_matrix,
    linear_to_lab,
    patch_delta_e,
    usable_patches,
)
from fidelity.correction.normalise import Normalisation, normalise
from fidelity.measure.colour import ChartMeasurement, measure_chart, neutral_patches
from fidelity.measure.pixels import ImageMeasurement, exposure_from_neutrals, measure_pixels
from fidelity.pipeline.records import utc_now
from fidelity.prediction.judge import DEFAULT_JUDGE, JudgeOptions, judge_chart
from fidelity.prediction.table import Prediction

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasuredLoss, MeasureRequest

F64 = NDArray[np.float64]

#: The model ``fit`` uses unless told.
DEFAULT_MODEL = "matrix"
#: Mean chroma C*ab of the real chart's colour patches below which it is refused as nearly grey
#: (the Macbeth chart's colour patches average about 40).
GREY_CHROMA = 5.0
#: Largest ΔE00 between the ``.cube`` through OpenColorIO and the model itself (issue 29).
LUT_TOLERANCE = 0.1
#: Cross-validated ΔE00 above which the model is said not to express the difference (issue
#: 29's "corrected ΔE00 below 0.5 where the model family can express the error").
EXPRESSED_DELTA_E = 0.5
#: The models affine in light: their ``.cube`` is sampled on a lattice even in light.
AFFINE_MODELS: tuple[str, ...] = ("gains", "matrix")
#: Points per axis of the dense lattice the ``.cube`` is checked on (not a divisor of the cube
#: sizes' spacing, so that most points fall between the cube's nodes).
CHECK_GRID = 41


def _to_linear(pixels: NDArray[Any], encoding: str) -> NDArray[Any]:
    return np.asarray(linearize_srgb(pixels)) if encoding == "srgb" else pixels


@dataclass(frozen=True)
class Correction:
    """A fitted correction of the simulator's pixel values (module docstring).

    ``model`` acts in the fit space; ``to_fit`` (3 x 3) takes the simulator's linear pixel
    values there (its colourspace -> linear sRGB, its audit exposure, the normalisation);
    ``encoding`` is the simulator's pixel encoding (``srgb``: encoded values in [0, 1];
    ``linear``: scene-linear); the output is not clipped (a clip inside a LUT is a kink that
    its interpolation cannot follow: whoever stores the corrected image clips it); ``domain_max`` is the largest
    linear pixel value a ``.cube`` covers (the perfect white's). The rest is the fit's
    evidence: per patch (chart order) the fit-space colours, the excluded patches with their
    reason, the in-sample and cross-validated ΔE00.

    Attributes
    ----------
    model
        The fitted colour model (``gains``, ``matrix``, ``matrix+curve`` or
        ``root-polynomial``), acting on fit-space linear sRGB.
    objective
        What the fit minimised: ``linear`` (least squares in linear light) or ``ciede2000``.
    conditioning
        How well the chart determines the fit: the condition number, its limit, the Tikhonov
        weight used (0: none) and why.
    encoding
        The simulator's pixel encoding: ``srgb`` (encoded values in [0, 1]) or ``linear``
        (scene-linear).
    to_fit
        3 x 3 matrix taking the simulator's linear pixel values to the fit space (its
        colourspace -> linear sRGB, its audit exposure, the normalisation).
    domain_max
        The largest linear pixel value a ``.cube`` covers (the perfect white's; 1 for sRGB
        pixels), > 0.
    normalisation
        What was matched before the fit (``exposure``, ``exposure+wb`` or ``none``) and by how
        much.
    patch_names
        The patch names, chart order (the order of every per-patch array).
    excluded
        Patch name -> why it was left out of the fit (clipped or saturated in either chart).
    sim_fit
        The simulated patches in the fit space, linear sRGB, shape (n, 3).
    real_fit
        The real patches in the fit space, linear sRGB, shape (n, 3).
    before_delta_e
        ΔE00 of each simulated patch against the real one before the correction, shape (n,).
    fitted_delta_e
        ΔE00 of each corrected simulated patch against the real one (in-sample), shape (n,).
    cv_delta_e
        Cross-validated ΔE00 of each patch (leave-3-patches-out), shape (n,); NaN for
        excluded patches.
    sim_pixels
        The simulated patches as the simulator's pixel values (its encoding and
        colourspace), shape (n, 3); empty (0, 3) when not known.
    """

    model: ColourModel
    objective: str
    conditioning: Conditioning
    encoding: str
    to_fit: F64
    domain_max: float
    normalisation: Normalisation
    patch_names: tuple[str, ...]
    excluded: dict[str, str]
    sim_fit: F64
    real_fit: F64
    before_delta_e: F64
    fitted_delta_e: F64
    cv_delta_e: F64
    sim_pixels: F64 = field(repr=False, default_factory=lambda: np.zeros((0, 3)))

    def apply(self, pixels: ArrayLike) -> F64:
        """Corrected pixel values of the simulator's pixel values ``(..., 3)`` (same encoding)."""
        out = self.apply_linear(pixels)
        if self.encoding == "srgb":
            return np.asarray(delinearize_srgb(out), np.float64)
        return out

    def apply_linear(self, pixels: ArrayLike) -> F64:
        """Corrected scene-linear values (the simulator's colourspace and scale, unclipped) of
        the simulator's pixel values ``(..., 3)``: what the ``.cube`` holds."""
        a = np.asarray(pixels, np.float64)
        if a.shape[-1:] != (3,):
            raise InvalidValueError(f"pixels must be (..., 3), got shape {a.shape}")
        fit = _to_linear(a, self.encoding) @ self.to_fit.T
        return np.asarray(self.model.apply(fit) @ np.linalg.inv(self.to_fit).T, np.float64)

    @property
    def lattice(self) -> str:
        """How the ``.cube``'s lattice is spaced (:data:`fidelity.correction.lut.LATTICES`):
        ``linear`` for the models affine in light (gains, matrix: interpolated exactly),
        ``encoded`` for those that bend (a tone curve, a root-polynomial)."""
        return "linear" if self.model.name in AFFINE_MODELS else "encoded"

    def display_lab(self, pixels: ArrayLike) -> F64:
        """CIELAB of pixel values as the fit space shows them (sRGB clipped to [0, 1]): what
        a ΔE00 between two outputs of the correction is measured on."""
        fit = _to_linear(np.asarray(pixels, np.float64), self.encoding) @ self.to_fit.T
        return linear_to_lab(np.clip(fit, 0.0, 1.0))

    @property
    def used(self) -> tuple[str, ...]:
        """The patches the fit used."""
        return tuple(n for n in self.patch_names if n not in self.excluded)

    @property
    def expressed(self) -> bool:
        """Whether the model expresses the difference: its cross-validated mean ΔE00 is at
        most :data:`EXPRESSED_DELTA_E`."""
        return bool(self.cv_mean <= EXPRESSED_DELTA_E)

    @property
    def cv_mean(self) -> float:
        """Mean cross-validated ΔE00 over the used patches."""
        return float(np.nanmean(self.cv_delta_e))

    def cube_comments(self, size: int) -> list[str]:
        """The header comments of the ``.cube``: what goes in and what comes out."""
        space = ("sRGB-encoded values (IEC 61966-2-1) in [0, 1]" if self.encoding == "srgb"
                 else f"scene-linear values 0 .. {self.domain_max:.6g} (values beyond are "
                 "clamped)")
        shaper = {("srgb", "encoded"): "the 3D LUT directly",
                  ("srgb", "linear"): "a 1D shaper (the sRGB decoding) then the 3D LUT",
                  ("linear", "encoded"): "a 1D shaper (the sRGB encoding of v / max) then the "
                                         "3D LUT",
                  ("linear", "linear"): "a 1D shaper (v / max) then the 3D LUT"}
        post = ("; apply the sRGB encoding (IEC 61966-2-1) after it to get corrected "
                "sRGB-encoded pixels (correction.ocio does)" if self.encoding == "srgb" else "")
        return [f"fidelity fit: {self.model.name} correction ({self.objective} objective), "
                f"{size}^3 lattice even in {'light' if self.lattice == 'linear' else 'sRGB'}",
                f"input: the simulator's pixels, {space}, through "
                f"{shaper[(self.encoding, self.lattice)]}",
                f"output: corrected scene-linear values, the simulator's colourspace and "
                f"scale, unclipped{post}",
                "apply with tetrahedral interpolation"]

    def to_cube(self, path: str | os.PathLike[str], size: int = 33) -> Path:
        """Write the ``.cube`` (OpenColorIO's Baker, :func:`fidelity.correction.lut.bake_cube`)
        of :meth:`apply_linear` atomically; returns the path."""
        return write_text_atomic(path, bake_cube(self.apply_linear, size, self.encoding,
                                                 self.domain_max, self.cube_comments(size),
                                                 self.lattice))

    def to_json(self) -> dict[str, Any]:
        """``model`` (gains, matrix, curve: :meth:`ColourModel.to_json`), ``objective``,
        ``conditioning``, the pixel ``encoding``, ``to_fit``, ``domain_max``,
        ``normalisation``, ``excluded`` and per patch the fit-space colours and the ΔE00
        before, fitted and cross-validated."""
        def f(v: float) -> float | None:
            return None if not np.isfinite(v) else float(v)

        return {
            **self.model.to_json(), "objective": self.objective,
            "conditioning": self.conditioning.to_json(), "encoding": self.encoding,
            "to_fit": self.to_fit.tolist(), "domain_max": self.domain_max,
            "cube_lattice": self.lattice, "cube_output": "scene-linear",
            "normalisation": self.normalisation.to_json(), "excluded": dict(self.excluded),
            "fitted_mean_delta_e": float(np.mean(self.fitted_delta_e[self._used_mask])),
            "cross_validated_mean_delta_e": f(self.cv_mean),
            "expressed": self.expressed, "expressed_limit": EXPRESSED_DELTA_E,
            "patches": [{"name": n, "used": n not in self.excluded,
                         "excluded_because": self.excluded.get(n),
                         "sim_linear": self.sim_fit[k].tolist(),
                         "real_linear": self.real_fit[k].tolist(),
                         "delta_e_before": float(self.before_delta_e[k]),
                         "delta_e_fitted": float(self.fitted_delta_e[k]),
                         "delta_e_cross_validated": f(float(self.cv_delta_e[k]))}
                        for k, n in enumerate(self.patch_names)]}

    @property
    def _used_mask(self) -> NDArray[np.bool_]:
        return np.array([n not in self.excluded for n in self.patch_names])


@dataclass(frozen=True)
class _Chart:
    path: str
    pixels: NDArray[Any]
    audit: ImageMeasurement


def sim_ocio_refused(flag: str, name: str) -> InvalidValueError:
    """The error of an OpenColorIO colourspace given for SIM: the ``.cube`` maps SIM's own
    pixel values, which a conversion before the fit would hide."""
    return InvalidValueError(
        f"{flag} {name}: fit writes its correction for the simulator's own pixel values; give "
        "them as --encoding and --colourspace, or convert the images first (REAL may have its "
        "own: --real-ocio-colourspace)")


def _read(path: str | os.PathLike[str], corners: str | Sequence[float] | None,
          read: ReadOptions, reference: str, illuminant: str, *, sim: bool) -> _Chart:
    if sim and read.ocio_colourspace is not None:
        raise sim_ocio_refused("--ocio-colourspace", read.ocio_colourspace)
    img, sha256 = read_input(path, read)
    enc = read.encoding or img.encoding
    info = img.info(sha256=sha256, encoding=enc)
    try:
        audit = measure_pixels(img.pixels, corners, encoding=enc, exposure=read.exposure,
                               reference=reference, illuminant=illuminant, image=info,
                               negatives=read.negatives,
                               colourspace=(read.colourspace if read.colourspace is not None
                                            else img.chromaticities or "sRGB"))
    except FidelityError as exc:
        raise type(exc)(f"{img.where}: {exc}") from None
    return _Chart(str(path), img.pixels, audit)


def _colourspace_matrix(audit: ImageMeasurement) -> F64:
    name = audit.colourspace
    if name.startswith("chromaticities "):
        return matrix_rgb_to_linear_srgb([float(v) for v in name.split(" ", 1)[1].split(",")])
    return matrix_rgb_to_linear_srgb(name)


@dataclass(frozen=True)
class _Prepared:
    """One pair of charts ready to fit: the fit-space colours, the weights, what was
    excluded and what turns the simulator's pixels into the fit space."""

    names: tuple[str, ...]
    norm: Normalisation
    sim_fit: F64
    real_fit: F64
    weights: F64
    excluded: dict[str, str]
    encoding: str
    to_fit: F64
    domain_max: float
    sim_pixels: F64


def _prepare(sim: _Chart, real: _Chart, normalise_mode: str,
             weights: ArrayLike | None) -> _Prepared:
    sm, rm = sim.audit.measurement, real.audit.measurement
    if sm.patch_names != rm.patch_names:
        raise InvalidValueError(f"{sim.path} and {real.path}: the charts have different patches")
    names = rm.patch_names
    neutral = neutral_patches(rm)
    _, norm = normalise(sm.srgb, rm.srgb, neutral, normalise_mode)
    d = (np.asarray(norm.gains) if norm.gains is not None
         else np.full(3, 2.0 ** norm.exposure_ev))
    sim_fit = np.asarray(linearize_srgb(sm.srgb), np.float64) * d
    real_fit = np.asarray(linearize_srgb(rm.srgb), np.float64)
    colour = [k for k in range(len(names)) if k not in neutral]
    if colour:
        lab = linear_to_lab(real_fit[colour])
        chroma = float(np.mean(np.hypot(lab[:, 1], lab[:, 2])))
        ref_chroma = float(np.mean(np.hypot(rm.reference_lab[colour, 1],
                                            rm.reference_lab[colour, 2])))
        if chroma < GREY_CHROMA:
            raise InvalidValueError(
                f"{real.path}: the real chart is nearly grey (mean chroma C*ab {chroma:.2f} of "
                f"its colour patches, the reference's {ref_chroma:.1f}): it cannot determine a "
                f"colour correction; is it the same chart, lit like the simulated one?")
    excluded = usable_patches(sm.srgb, rm.srgb, names, sim.audit.clipped_patches,
                              real.audit.clipped_patches)
    w = np.array([0.0 if n in excluded else 1.0 for n in names])
    if weights is not None:
        w = w * np.asarray(weights, np.float64)
    p = _colourspace_matrix(sim.audit)
    to_fit = np.diag(d) @ (2.0 ** sim.audit.exposure_ev * p)
    sim_lin_pixels = np.asarray(linearize_srgb(sm.srgb), np.float64) @ np.linalg.inv(
        np.diag(2.0 ** sim.audit.exposure_ev * np.ones(3)) @ p).T
    enc = sim.audit.encoding
    sim_pixels = (np.asarray(delinearize_srgb(sim_lin_pixels), np.float64) if enc == "srgb"
                  else sim_lin_pixels)
    domain_max = (1.0 if enc == "srgb" else
                  float(np.max(np.linalg.solve(to_fit, np.ones(3)))))
    return _Prepared(names, norm, sim_fit, real_fit, w, excluded, enc, to_fit, domain_max,
                     sim_pixels)


def _correction(pp: _Prepared, fitted: ColourModel, objective: str, cond: Conditioning,
                cv: F64) -> Correction:
    return Correction(fitted, objective, cond, pp.encoding, pp.to_fit, pp.domain_max, pp.norm,
                      pp.names, pp.excluded, pp.sim_fit, pp.real_fit,
                      patch_delta_e(pp.sim_fit, pp.real_fit),
                      patch_delta_e(fitted.apply(pp.sim_fit), pp.real_fit), cv, pp.sim_pixels)


def _fit_charts(sim: _Chart, real: _Chart, model: str, objective: str | None,
                normalise_mode: str, weights: ArrayLike | None) -> Correction:
    pp = _prepare(sim, real, normalise_mode, weights)
    objective = DEFAULT_OBJECTIVE if objective is None else objective
    fitted, cond = fit_model(pp.sim_fit, pp.real_fit, model, weights=pp.weights,
                             objective=objective)
    cv = cross_validate(pp.sim_fit, pp.real_fit, model, weights=pp.weights,
                        objective=objective, start=fitted)
    return _correction(pp, fitted, objective, cond, cv)


def fit_correction(
    sim: str | os.PathLike[str],
    real: str | os.PathLike[str],
    *,
    model: str = DEFAULT_MODEL,
    objective: str | None = None,
    sim_corners: str | Sequence[float] | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    read: ReadOptions = DEFAULT_READ,
    real_ocio_colourspace: str | None = None,
    reference: str = "scene",
    illuminant: str = "D65",
    weights: ArrayLike | None = None,
) -> Correction:
    """Fit the correction from the chart in ``sim`` onto the chart in ``real`` (module
    docstring).

    Parameters
    ----------
    sim, real
        Images of the same chart: the simulator's render and the real camera's photo.
    model
        ``gains``, ``matrix`` (default), ``matrix+curve`` or ``root-polynomial``
        (:data:`fidelity.correction.models.MODELS`).
    objective
        ``linear`` or ``ciede2000``; None: the measured better one
        (:data:`fidelity.correction.models.DEFAULT_OBJECTIVE`).
    sim_corners, real_corners, normalise_mode, read, real_ocio_colourspace, reference, illuminant
        As :func:`fidelity.pipeline.compare.compare_charts` (``sim`` has no OpenColorIO colourspace:
        the correction maps its own pixel values).
    weights
        ``(24,)`` patch weights (default 1; excluded patches get 0 whatever their weight).

    Returns
    -------
    Correction
        The fitted correction of the simulator's pixel values, with its conditioning, the
        excluded patches and the per-patch ΔE00 before, after (in-sample) and
        cross-validated.

    Raises
    ------
    InputFileError
        A missing, unreadable or corrupt image. Exit code 2.
    InvalidValueError
        No chart found in either image, a nearly grey real chart, too few usable patches or
        an unstable fit, an OpenColorIO colourspace given for ``sim``. Exit code 2.
    UnknownNameError
        An unknown model, objective, normalisation, reference or illuminant. Exit code 2.
    """
    sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                              (None, real_ocio_colourspace))
    s = _read(sim, sim_corners, sim_read, reference, illuminant, sim=True)
    r = _read(real, real_corners, real_read, reference, illuminant, sim=False)
    return _fit_charts(s, r, model, objective, normalise_mode, weights)


@dataclass(frozen=True)
class LutCheck:
    """The ``.cube`` through OpenColorIO against the model itself: the cube ``size``, the
    largest and mean ΔE00 over the chart's patches (``chart_max``, ``chart_mean``) and over a
    ``grid_points``-point lattice of the input range (``grid_max``, ``grid_mean``, the 99th
    percentile ``grid_p99`` and the ``grid_within`` fraction of points within
    ``tolerance``), and whether all is within ``tolerance``."""

    size: int
    chart_max: float
    chart_mean: float
    grid_max: float
    grid_mean: float
    grid_points: int
    tolerance: float
    grid_p99: float = 0.0
    grid_within: float = 1.0

    @property
    def passed(self) -> bool:
        """Both maxima within the tolerance."""
        return self.chart_max <= self.tolerance and self.grid_max <= self.tolerance

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"size": self.size, "chart_max_delta_e": self.chart_max,
                "chart_mean_delta_e": self.chart_mean, "grid_max_delta_e": self.grid_max,
                "grid_mean_delta_e": self.grid_mean, "grid_p99_delta_e": self.grid_p99,
                "grid_fraction_within": self.grid_within, "grid_points": self.grid_points,
                "tolerance": self.tolerance, "passed": self.passed}


def check_points(correction: Correction) -> tuple[tuple[F64, F64], tuple[F64, F64]]:
    """The points a ``.cube`` is checked on (the chart's SIM pixel values, a
    :data:`CHECK_GRID`^3 lattice of the input range, most points between the cube's nodes)
    and the model's own output there as CIELAB (:meth:`Correction.display_lab`): what
    :func:`check_cube` compares with, computed once for every cube size tried."""
    grid = lattice_inputs(CHECK_GRID, correction.encoding, correction.domain_max).reshape(-1, 3)
    points = (correction.sim_pixels, grid)
    return points, (correction.display_lab(correction.apply(points[0])),
                    correction.display_lab(correction.apply(points[1])))


def check_cube(correction: Correction, path: str | os.PathLike[str], size: int,
               points: tuple[tuple[F64, F64], tuple[F64, F64]] | None = None) -> LutCheck:
    """Apply the ``.cube`` at ``path`` (and the output encoding) with OpenColorIO's processor
    and compare it with :meth:`Correction.apply` on the chart's patches and on a dense lattice
    (:class:`LutCheck`); ``points``: :func:`check_points` of ``correction``, if computed."""
    proc = cube_processor(path, correction.encoding)
    (chart, grid), (chart_lab, grid_lab) = points or check_points(correction)
    out = []
    for pts, direct in ((chart, chart_lab), (grid, grid_lab)):
        lut = apply_processor(proc, pts).astype(np.float64)
        out.append(np.asarray(delta_e_2000(correction.display_lab(lut), direct), np.float64))
    return LutCheck(size, float(out[0].max()), float(out[0].mean()), float(out[1].max()),
                    float(out[1].mean()), len(grid), LUT_TOLERANCE,
                    float(np.percentile(out[1], 99)),
                    float(np.mean(out[1] <= LUT_TOLERANCE)))


@dataclass(frozen=True)
class FitReport:
    """A fit and its verification: the inputs, the :class:`Correction`, the sim-to-real
    measurement before (``before``) and after, the latter of the SIM image through the
    ``.cube`` by OpenColorIO, measured again in the audit's windows (``after``), their predicted losses, the
    ``.cube``'s :class:`LutCheck` (one per size tried, the last one kept) and the seconds
    spent (``seconds``: ``read``, ``fit``, ``verify``; ``cpu_seconds`` the same in this
    process's CPU time); with ``measure``, the loss measured on COCO of the simulator's
    colours before and after the correction (``measured_before``, ``measured_after``: the
    emulation of each on the images, as ``fidelity compare --measure`` makes it).

    Attributes
    ----------
    created
        When it was made, UTC, ``YYYY-MM-DDThh:mm:ssZ``.
    sim
        The simulated image's path, as given.
    real
        The real image's path, as given.
    correction
        The fitted correction.
    before
        The sim-to-real measurement before the correction (the normalised SIM chart against
        the REAL chart as reference).
    after
        The same after it: the SIM pixels through the ``.cube`` by OpenColorIO, measured
        again in the audit's windows.
    prediction_before
        The predicted detection loss at the sim-to-real ΔE before the correction.
    prediction_after
        The predicted detection loss at the sim-to-real ΔE after it.
    lut_checks
        The ``.cube``'s checks against the model, one per cube size tried (the last: the
        cube written).
    files
        The files written: ``cube``, ``ocio``, ``json`` and, with ``corrected``, the
        ``corrected`` image, each a path.
    seconds
        Wall-clock seconds of ``read``, ``fit`` and ``verify``.
    cpu_seconds
        This process's CPU seconds of the same steps.
    measured_before
        With ``measure``: the loss measured on COCO of the simulator's colours before the
        correction, one per detector; else empty.
    measured_after
        The same after the correction.
    """

    created: str
    sim: str
    real: str
    correction: Correction
    before: ChartMeasurement
    after: ChartMeasurement
    prediction_before: Prediction
    prediction_after: Prediction
    lut_checks: tuple[LutCheck, ...]
    files: dict[str, str]
    seconds: dict[str, float]
    cpu_seconds: dict[str, float] = field(default_factory=dict)
    measured_before: tuple[MeasuredLoss, ...] = ()
    measured_after: tuple[MeasuredLoss, ...] = ()

    @property
    def lut(self) -> LutCheck:
        """The check of the ``.cube`` written."""
        return self.lut_checks[-1]


def fit_and_verify(
    sim: str | os.PathLike[str],
    real: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    model: str = DEFAULT_MODEL,
    objective: str | None = None,
    sim_corners: str | Sequence[float] | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    read: ReadOptions = DEFAULT_READ,
    real_ocio_colourspace: str | None = None,
    reference: str = "scene",
    illuminant: str = "D65",
    judge: JudgeOptions = DEFAULT_JUDGE,
    corrected: bool = False,
    measure: MeasureRequest | None = None,
) -> FitReport:
    """:func:`fit_correction`, then write ``correction.cube`` (the smallest cube size within
    :data:`LUT_TOLERANCE`), ``correction.ocio`` and ``correction.json`` into the folder
    ``out`` and verify them (module docstring).

    The verification puts through OpenColorIO only the SIM pixels that the audit measures (its
    patch windows); ``corrected=True`` puts the whole SIM image through and writes it
    (:func:`corrected_name`: a 16-bit PNG for sRGB-encoded SIM, clipped as a camera stores it;
    a float EXR for scene-linear SIM), measuring the whole corrected image instead (the same
    patch means; it costs the whole image's transform and writing)."""
    ocio()
    c0, t0 = time.process_time(), time.perf_counter()

    sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                              (None, real_ocio_colourspace))
    s = _read(sim, sim_corners, sim_read, reference, illuminant, sim=True)
    r = _read(real, real_corners, real_read, reference, illuminant, sim=False)
    c1, t1 = time.process_time(), time.perf_counter()
    corr = _fit_charts(s, r, model, objective, normalise_mode, None)
    c2, t2 = time.process_time(), time.perf_counter()
    return _verify(s, r, corr, Path(out), normalise_mode=normalise_mode, judge=judge,
                   corrected=corrected, seconds=(t1 - t0, t2 - t1),
                   cpu=(c1 - c0, c2 - c1), measure=measure)


def _verify(s: _Chart, r: _Chart, corr: Correction, folder: Path, *, normalise_mode: str,
            judge: JudgeOptions, corrected: bool, seconds: tuple[float, float],
            cpu: tuple[float, float], measure: MeasureRequest | None = None) -> FitReport:
    """Write the cube, the config and ``correction.json`` of ``corr`` into ``folder`` and
    verify them on the SIM chart ``s`` against the REAL chart ``r`` (module docstring)."""
    c2, t2 = time.process_time(), time.perf_counter()
    folder.mkdir(parents=True, exist_ok=True)
    cube = folder / "correction.cube"
    checks: list[LutCheck] = []
    points = check_points(corr)
    for n in CUBE_SIZES:
        corr.to_cube(cube, n)
        checks.append(check_cube(corr, cube, n, points))
        if checks[-1].passed:
            break
    config = folder / "correction.ocio"
    write_text_atomic(config, ocio_config(cube, f"fidelity fit: {corr.model.name} correction "
                                                f"of {Path(s.path).name} towards "
                                                f"{Path(r.path).name}", corr.encoding))
    sa, ra = s.audit, r.audit
    files = {"cube": str(cube), "ocio": str(config), "json": str(folder / "correction.json")}
    if corrected:
        whole = apply_processor(config_processor(config), np.asarray(s.pixels)[..., :3])
        files["corrected"] = str(_write_corrected(folder, whole, corr.encoding))
        after_srgb_audit = remeasure(whole, sa)
    else:
        # the cube alone through OpenColorIO (scene-linear out): the sRGB encoding that
        # correction.ocio applies after it would be undone by the measurement at once
        cube_only = cube_processor(cube, reload=False)  # the file check_cube just read
        after_srgb_audit = remeasure(s.pixels, sa, lambda v: apply_processor(cube_only, v),
                                     linear_output=True)
    rm = ra.measurement
    ref_srgb = np.clip(rm.srgb, 0, 1)
    neutral = neutral_patches(rm)
    before_srgb, _ = normalise(sa.measurement.srgb, rm.srgb, neutral, normalise_mode)
    after_srgb, _ = normalise(after_srgb_audit, rm.srgb, neutral, normalise_mode)
    before = measure_chart(before_srgb, rm.lab, rm.patch_names, reference_srgb=ref_srgb)
    after = measure_chart(after_srgb, rm.lab, rm.patch_names, reference_srgb=ref_srgb)
    c3, t3 = time.process_time(), time.perf_counter()
    pb = judge_chart(before.mean_delta_e, judge).prediction
    pa = judge_chart(after.mean_delta_e, judge).prediction
    write_json_atomic(folder / "correction.json", corr.to_json())
    measured: list[tuple[MeasuredLoss, ...]] = [(), ()]
    if measure is not None:
        from fidelity.coco.emulation import PatchEmulation  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        # as compare --measure: the real camera's colours -> the simulator's, on COCO photos
        for k, (side, colours) in enumerate((("before", before_srgb), ("after", after_srgb))):
            emu = PatchEmulation.fit(ref_srgb, colours, neutral)
            measured[k] = tuple(measure.run(emu.apply_uint8, emu.key(), {
                "sim": s.path, "real": r.path, "fit": side, "model": corr.model.name,
                "emulation": emu.describe()}))
    return FitReport(utc_now(), s.path, r.path, corr, before, after, pb, pa,
                     tuple(checks), files,
                     {"read": seconds[0], "fit": seconds[1], "verify": t3 - t2},
                     {"read": cpu[0], "fit": cpu[1], "verify": c3 - c2},
                     measured[0], measured[1])


@dataclass(frozen=True)
class SharedFit:
    """One colour matrix fitted over several pairs of charts (the same cameras under several
    illuminants) with per-pair gains (:func:`fidelity.correction.models.fit_shared_matrix`):
    the shared ``matrix`` (a ``matrix`` :class:`~fidelity.correction.models.ColourModel`),
    each pair's ``gains`` (the first pair's fixed at 1), the ``conditioning`` and, per pair,
    the :class:`FitReport` of its correction ``matrix @ diag(gains)`` (its cube, config and
    verification; its cross-validated ΔE00 from folds that hold the same patches out of every
    pair); ``seconds`` for the whole."""

    created: str
    matrix: ColourModel
    gains: tuple[F64, ...]
    conditioning: Conditioning
    reports: tuple[FitReport, ...]
    seconds: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        """The shared matrix (rows = output R, G, B), the conditioning and per pair the files,
        the gains and the ΔE00 before, after, fitted and cross-validated."""
        return {"model": "matrix", "objective": "linear", "matrix": self.matrix.matrix.tolist(),
                "conditioning": self.conditioning.to_json(),
                "pairs": [{"sim": r.sim, "real": r.real, "gains": g.tolist(),
                           "before_mean_delta_e": r.before.mean_delta_e,
                           "after_mean_delta_e": r.after.mean_delta_e,
                           "after_max_delta_e": r.after.max_delta_e,
                           "fitted_mean_delta_e": r.correction.to_json()["fitted_mean_delta_e"],
                           "cross_validated_mean_delta_e": r.correction.cv_mean,
                           "files": dict(r.files)}
                          for r, g in zip(self.reports, self.gains, strict=True)]}


def fit_pairs_and_verify(
    pairs: Sequence[tuple[str | os.PathLike[str], str | os.PathLike[str]]],
    out: str | os.PathLike[str],
    *,
    sim_corners: str | Sequence[float] | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    read: ReadOptions = DEFAULT_READ,
    real_ocio_colourspace: str | None = None,
    reference: str = "scene",
    illuminant: str = "D65",
    judge: JudgeOptions = DEFAULT_JUDGE,
    corrected: bool = False,
) -> SharedFit:
    """Fit one matrix and per-pair gains over ``pairs`` of (SIM, REAL) charts, the same
    cameras under different illuminants (:class:`SharedFit`), and write and verify each pair's
    correction ``matrix @ diag(gains)`` as :func:`fit_and_verify` does, into
    ``out/pair-<k>`` (k from 1). The fit is weighted least squares in linear RGB over the
    patches usable in each pair; corners and the other options apply to every pair."""
    ocio()
    if len(pairs) < 2:
        raise InvalidValueError("a fit over illuminants needs at least two pairs (--pair SIM "
                                "REAL, given twice or more)")
    t0 = time.perf_counter()
    charts = []
    for sim, real in pairs:
        sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                                  (None, real_ocio_colourspace))
        charts.append((_read(sim, sim_corners, sim_read, reference, illuminant, sim=True),
                       _read(real, real_corners, real_read, reference, illuminant, sim=False)))
    t1 = time.perf_counter()
    prepared = [_prepare(s, r, normalise_mode, None) for s, r in charts]
    xs = [pp.sim_fit for pp in prepared]
    ys = [pp.real_fit for pp in prepared]
    ws = [pp.weights for pp in prepared]
    matrix, gains, cond = fit_shared_matrix(xs, ys, weights=ws)
    cvs = cross_validate_shared(xs, ys, weights=ws)
    t2 = time.perf_counter()
    reports = []
    for k, ((s, r), pp, g, cv) in enumerate(zip(charts, prepared, gains, cvs, strict=True)):
        model = ColourModel("matrix", np.asarray((matrix.matrix @ np.diag(g)).T, np.float64))
        reports.append(_verify(s, r, _correction(pp, model, "linear", cond, cv),
                               Path(out) / f"pair-{k + 1}", normalise_mode=normalise_mode,
                               judge=judge, corrected=corrected,
                               seconds=(0.0, 0.0), cpu=(0.0, 0.0)))
    t3 = time.perf_counter()
    return SharedFit(utc_now(), matrix, gains, cond, tuple(reports),
                     {"read": t1 - t0, "fit": t2 - t1, "verify": t3 - t2})


#: Pixels per patch of the chart rendered from a camera file (``--camera``).
CAMERA_PIXELS_PER_PATCH = 32


def _absolute_paths(value: Any, base: Path) -> Any:
    """``value`` (a parsed camera file) with every string naming a file relative to ``base``
    made absolute, so that the corrected camera file finds them from anywhere."""
    if isinstance(value, dict):
        return {k: _absolute_paths(v, base) for k, v in value.items()}
    if isinstance(value, list):
        return [_absolute_paths(v, base) for v in value]
    if isinstance(value, str) and value and not Path(value).is_absolute() and (
            base / value).is_file():
        return str((base / value).resolve())
    return value


def fit_camera_and_verify(
    camera: str | os.PathLike[str],
    real: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    model: str = DEFAULT_MODEL,
    objective: str | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    read: ReadOptions = DEFAULT_READ,
    real_ocio_colourspace: str | None = None,
    reference: str = "scene",
    illuminant: str = "D65",
    judge: JudgeOptions = DEFAULT_JUDGE,
    corrected: bool = False,
    measure: MeasureRequest | None = None,
) -> tuple[FitReport, Path]:
    """Render the chart through the camera model file ``camera`` in closed form (under
    ``illuminant``; ``out/sim_render.png`` or ``.exr``), fit and verify the correction onto
    ``real`` as :func:`fit_and_verify` does, and write ``out/corrected.toml``: the camera
    file with its colour-correction matrix replaced by the corrected one,
    ``inv(T) M T @ CCM`` (``M`` the fitted matrix in the fit space, ``T`` the simulator's
    pixels -> fit space, ``CCM`` the camera's own matrix, resolved).

    The correction of a camera file is a 3x3 matrix in the camera's linear output (before its
    tone curve): ``model`` ``gains`` or ``matrix``, and the camera's tone curve ``srgb`` or
    ``linear`` (the encodings the audit reads exactly). Returns the report and the path of
    ``corrected.toml``."""
    import tomli_w

    path = Path(camera)
    cam = read_camera_file(path)
    if model not in AFFINE_MODELS:
        raise InvalidValueError(f"{path}: a camera file is corrected through its 3x3 colour "
                                f"matrix: --correction gains or matrix, not {model}")
    if cam.tone.curve not in ("srgb", "linear"):
        raise InvalidValueError(f"{path}: tone curve {cam.tone.curve!r}: a corrected camera "
                                "file is written for the srgb and linear tone curves (the "
                                "encodings the audit reads exactly)")
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    render = render_chart(cam, illuminant, pixels_per_patch=CAMERA_PIXELS_PER_PATCH)
    layout = ChartLayout.for_patch_size(CAMERA_PIXELS_PER_PATCH)
    centres = []
    for k in (0, 5, 23, 18):
        y0, y1, x0, x1 = layout.patch_box(k)
        centres += [(x0 + x1) / 2 - 0.5, (y0 + y1) / 2 - 0.5]
    if cam.output_encoding == "linear":
        sim = write_exr(folder / "sim_render.exr", render.linear_image,
                        f"fidelity fit --camera: {cam.name} under {illuminant}")
    else:
        sim = write_png(folder / "sim_render.png", render.display_image, 16)
    rep = fit_and_verify(sim, real, folder, model=model, objective=objective,
                         sim_corners=",".join(f"{v:g}" for v in centres),
                         real_corners=real_corners,
                         normalise_mode=normalise_mode, read=read,
                         real_ocio_colourspace=real_ocio_colourspace, reference=reference,
                         illuminant=illuminant, judge=judge, corrected=corrected,
                         measure=measure)
    c = rep.correction
    t = c.to_fit
    ccm = colour_correction_matrix(cam, load_illuminant(illuminant))
    new = np.linalg.inv(t) @ c.model.matrix @ t @ np.asarray(ccm, np.float64)
    data = _absolute_paths(load_document(path, str(path)), path.parent.resolve())
    data["name"] = f"{data.get('name', cam.name)}-corrected"
    data["description"] = (f"{data.get('description', cam.name)}, corrected by fidelity fit "
                           f"({c.model.name}) towards {Path(real).name}")
    data["ccm"] = {"method": "matrix", "matrix": new.tolist()}
    toml = folder / "corrected.toml"
    write_text_atomic(toml, f"# fidelity fit --camera {path.name}: the colour matrix "
                            f"corrected towards {Path(real).name} (ΔE00 after "
                            f"{rep.after.mean_delta_e:.3f})\n" + tomli_w.dumps(data))
    return rep, toml


def corrected_name(encoding: str) -> str:
    """The file name of the corrected SIM image: ``corrected.png`` (sRGB-encoded) or
    ``corrected.exr`` (scene-linear)."""
    return "corrected.png" if encoding == "srgb" else "corrected.exr"


def _write_corrected(folder: Path, pixels: NDArray[Any], encoding: str) -> Path:
    path = folder / corrected_name(encoding)
    if encoding == "srgb":
        return write_png(path, pixels, 16)
    return write_exr(path, pixels, "the simulator's linear RGB corrected by fidelity fit")


def remeasure(pixels: NDArray[Any], audit: ImageMeasurement,
              transform: Callable[[NDArray[Any]], NDArray[Any]] | None = None, *,
              linear_output: bool = False) -> F64:
    """The encoded sRGB patch colours ``(n, 3)`` of ``pixels`` (an image of the size of the
    audited one), each pixel first through ``transform`` (``(m, 3)`` -> ``(m, 3)``, e.g. the
    correction through OpenColorIO's processor), measured as ``audit`` measured its image: the
    same sampling windows, encoding, colourspace and exposure rule (auto exposure fitted again
    on the neutral patches, a fixed one kept), pixels with NaN or Inf excluded, clipped to
    [0, 1]. ``linear_output``: the transform gives scene-linear values (the ``.cube`` without
    its output encoding), averaged as they are instead of decoded from the audit's encoding.

    Only the windows' pixels are read and transformed: the patch means are those of the whole
    image through ``transform`` measured in the same windows (``tests/pipeline/test_fit.py`` checks
    both ways), at the cost of the windows, not of the image."""
    p = _colourspace_matrix(audit)
    windows = [np.asarray(v, np.float32).reshape(-1, 3)  # float32 like the pixels: 2x faster
               for v in window_pixels(pixels, audit.location)]
    if transform is not None:
        counts = np.cumsum([len(v) for v in windows])[:-1]
        joined = np.asarray(transform(np.concatenate(windows)), np.float32)
        windows = np.split(joined, counts)
    encoding = "linear" if linear_output else audit.encoding
    means = []
    for v in windows:
        finite = np.isfinite(v).all(axis=1)
        if not finite.all():
            v = v[finite]
        if len(v) == 0:
            raise InvalidValueError("the corrected image has no finite pixel in a patch window")
        means.append(p @ np.asarray(_to_linear(v, encoding)).mean(axis=0, dtype=np.float64))
    lin = np.array(means)
    ref = audit.reference
    ev = (exposure_from_neutrals(lin, ref.lab, ref.neutral_indices, ref.patch_names)
          if audit.exposure_mode == "auto" else audit.exposure_ev)
    return np.clip(np.asarray(delinearize_srgb(lin * 2.0 ** ev), np.float64), 0.0, 1.0)


__all__ = ["AFFINE_MODELS", "CHECK_GRID", "Correction", "DEFAULT_MODEL", "EXPRESSED_DELTA_E",
           "FitReport", "GREY_CHROMA", "LUT_TOLERANCE", "LutCheck", "check_cube", "check_points",
           "CAMERA_PIXELS_PER_PATCH", "corrected_name", "fit_and_verify", "fit_camera_and_verify", "fit_correction", "fit_pairs_and_verify",
           "remeasure", "SharedFit"]
