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
:mod:`fidelity.correction.lut`), ``to_json()``. A scene-linear SIM is fitted on its patch values
as they are, above 1 included (a render exposed brighter than the chart's white is light, not
clipping), and its ``.cube`` covers its largest value.

:func:`fit_and_verify` checks the correction instead of assuming it: the ``.cube`` through
OpenColorIO's processor against the model itself, over the chart and a dense lattice
(:class:`LutCheck`; the smallest cube size of :data:`~fidelity.correction.lut.CUBE_SIZES`
that passes: the chart and 99 % of the lattice within :data:`LUT_TOLERANCE` ΔE00, all of it
within :data:`LUT_MAX_TOLERANCE`), then the SIM pixels in the audit's sampling windows through
the cube by OpenColorIO (loaded from ``correction.ocio``), measured again (:func:`remeasure`:
the patch means of the whole corrected image in the same windows, at the windows' cost) and
compared with REAL: the sim-to-real ΔE00 and its predicted ΔmAP before and after
(:class:`FitReport`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.camera.model import (
    MAX_BLUR_PX,
    CameraModel,
    Noise,
    colour_correction_matrix,
    read_camera_file,
)
from fidelity.camera.optics import Optics
from fidelity.camera.render import ChartLayout, frame_properties, render_chart
from fidelity.chart.image import FLOAT_PIXEL_TYPES, write_exr, write_png
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
from fidelity.core.record import record
from fidelity.core.schema import load_document
from fidelity.correction.lut import (
    CUBE_SIZES,
    apply_processor,
    bake_cube,
    check_output,
    config_processor,
    cube_processor,
    default_output,
    input_domain,
    lattice_inputs,
    ocio,
    ocio_config,
    output_linear,
    output_values,
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
from fidelity.measure.chartsharpness import TARGET_METHOD
from fidelity.measure.colour import ChartMeasurement, measure_chart, neutral_patches
from fidelity.measure.pixels import ImageMeasurement, exposure_from_neutrals, measure_pixels
from fidelity.pipeline.records import utc_now
from fidelity.prediction.judge import (
    DEFAULT_JUDGE,
    JudgeOptions,
    judge_chart,
    judge_properties,
)
from fidelity.prediction.properties import (
    PropertyJudgement,
    chart_mtf50,
    chart_snr,
    detector_scale,
    target_on_table_axis,
)
from fidelity.prediction.table import Prediction

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasuredLoss, MeasureRequest

F64 = NDArray[np.float64]

#: The model ``fit`` uses unless told.
DEFAULT_MODEL = "matrix"
#: Mean chroma C*ab of the real chart's colour patches below which it is refused as nearly grey
#: (the Macbeth chart's colour patches average about 40).
GREY_CHROMA = 5.0
#: Largest ΔE00 between the ``.cube`` through OpenColorIO and the model itself over the chart,
#: and the 99th percentile of it over the dense lattice allowed (issue 29).
LUT_TOLERANCE = 0.1
#: Largest ΔE00 between the ``.cube`` and the model allowed anywhere on the dense lattice
#: (issue 57): a cube without a shaper, sRGB in and sRGB out, cannot follow the encoding's toe
#: between its nodes where an output channel passes 0.0031 while the others are bright (a 20
#: degree hue matrix: 0.27 at 65^3 on the lattice's most saturated colours, 0.04 at its 99th
#: percentile); half a ΔE00, well below a just-noticeable difference, bounds that.
LUT_MAX_TOLERANCE = 0.5
#: Cross-validated ΔE00 above which the model is said not to express the difference (issue
#: 29's "corrected ΔE00 below 0.5 where the model family can express the error").
EXPRESSED_DELTA_E = 0.5
#: The models affine in light: a ``.cube`` even in light interpolates them exactly, and a
#: camera file's 3x3 colour matrix can hold them.
AFFINE_MODELS: tuple[str, ...] = ("gains", "matrix")
#: Points per axis of the dense lattice the ``.cube`` is checked on (not a divisor of the cube
#: sizes' spacing, so that most points fall between the cube's nodes).
CHECK_GRID = 41


def _to_linear(pixels: NDArray[Any], encoding: str) -> NDArray[Any]:
    return np.asarray(linearize_srgb(pixels)) if encoding == "srgb" else pixels


@record
class Correction:
    """A fitted correction of the simulator's pixel values (module docstring).

    ``model`` acts in the fit space; ``to_fit`` (3 x 3) takes the simulator's linear pixel
    values there (its colourspace -> linear sRGB, its audit exposure, the normalisation);
    ``encoding`` is the simulator's pixel encoding (``srgb``: encoded values in [0, 1];
    ``linear``: scene-linear); the output is not clipped (a clip inside a LUT is a kink that
    its interpolation cannot follow: whoever stores the corrected image clips it); ``domain_max`` is the largest
    linear pixel value a ``.cube`` covers (the perfect white's, or the SIM image's largest
    value where that is larger). The rest is the fit's
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
        The largest linear pixel value a ``.cube`` of scene-linear pixels covers (the
        perfect white's, or the SIM image's largest finite value where that is larger,
        rounded up to 3 significant digits; 1 for sRGB pixels), > 0.
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

    def cube_values(self, pixels: ArrayLike, output: str) -> F64:
        """What a ``.cube`` with ``output`` (:data:`fidelity.correction.lut.CUBE_OUTPUTS`)
        holds for the simulator's pixel values ``(..., 3)``: the corrected values
        sRGB-encoded (unclipped) or scene-linear."""
        return output_values(self.apply_linear(pixels), output)

    def display_lab(self, pixels: ArrayLike) -> F64:
        """CIELAB of pixel values as the fit space shows them (sRGB clipped to [0, 1]): what
        a ΔE00 between two outputs of the correction is measured on."""
        fit = _to_linear(np.asarray(pixels, np.float64), self.encoding) @ self.to_fit.T
        return linear_to_lab(np.clip(fit, 0.0, 1.0))

    def output_lab(self, values: ArrayLike, output: str) -> F64:
        """:meth:`display_lab` of a ``.cube``'s output values (``output``: their encoding,
        :meth:`cube_values`)."""
        fit = output_linear(np.asarray(values, np.float64), output) @ self.to_fit.T
        return linear_to_lab(np.clip(fit, 0.0, 1.0))

    def cube_convention(self, output: str) -> tuple[str, str]:
        """What a ``.cube`` with ``output`` takes and gives, in words: the input (encoding and
        domain) and the output."""
        check_output(output)
        inp = ("sRGB-encoded (IEC 61966-2-1) 0 .. 1" if self.encoding == "srgb" else
               f"scene-linear 0 .. {self.domain_max:.6g} (DOMAIN_MAX; beyond, clamped to it)")
        out = "sRGB-encoded (IEC 61966-2-1)" if output == "encoded" else "scene-linear"
        return inp, out

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

    def cube_title(self, output: str) -> str:
        """The ``TITLE`` of the ``.cube``: the model and the convention, in one line."""
        inp = ("sRGB-encoded 0..1" if self.encoding == "srgb"
               else f"scene-linear 0..{self.domain_max:.6g}")
        out = "sRGB-encoded" if check_output(output) == "encoded" else "scene-linear"
        return f"fidelity fit: {self.model.name} correction; {inp} in, {out} out"

    def cube_comments(self, size: int, output: str | None = None) -> list[str]:
        """The header comments of the ``.cube``: what goes in and what comes out
        (``output``: :data:`fidelity.correction.lut.CUBE_OUTPUTS`; None: the input's
        encoding)."""
        output = default_output(self.encoding) if output is None else output
        inp, out = self.cube_convention(output)
        same = output == default_output(self.encoding)
        return [f"fidelity fit: {self.model.name} correction ({self.objective} objective), "
                f"{size}^3 lattice even in the input's values, no shaper",
                f"input: the simulator's pixels, {inp}",
                f"output: corrected {out} values, the simulator's colourspace and scale, "
                f"unclipped ({'the input' if same else 'not the input'}'s encoding)",
                "apply with tetrahedral interpolation (ffmpeg lut3d, oiiotool "
                "--ociofiletransform, OpenColorIO FileTransform)"]

    def to_cube(self, path: str | os.PathLike[str], size: int = 33,
                output: str | None = None) -> Path:
        """Write the ``.cube`` (OpenColorIO's Baker, :func:`fidelity.correction.lut.bake_cube`)
        of :meth:`cube_values` atomically; ``output``: the cube's output convention
        (:data:`fidelity.correction.lut.CUBE_OUTPUTS`; None: the input's encoding). Returns
        the path."""
        output = check_output(default_output(self.encoding) if output is None else output)
        return write_text_atomic(path, bake_cube(lambda v: self.cube_values(v, output), size,
                                                 self.encoding, self.domain_max,
                                                 self.cube_comments(size, output),
                                                 self.cube_title(output)))

    def to_json(self, cube_output: str | None = None) -> dict[str, Any]:
        """``model`` (gains, matrix, curve: :meth:`ColourModel.to_json`), ``objective``,
        ``conditioning``, the pixel ``encoding``, ``to_fit``, ``domain_max``, the ``.cube``'s
        convention (``cube_input``, ``cube_domain``, ``cube_output``: ``cube_output``, None:
        the input's encoding), ``normalisation``, ``excluded`` and per patch the fit-space
        colours and the ΔE00 before, fitted and cross-validated."""
        def f(v: float) -> float | None:
            return None if not np.isfinite(v) else float(v)

        output = default_output(self.encoding) if cube_output is None else cube_output
        return {
            **self.model.to_json(), "objective": self.objective,
            "conditioning": self.conditioning.to_json(), "encoding": self.encoding,
            "to_fit": self.to_fit.tolist(), "domain_max": self.domain_max,
            "cube_input": "srgb-encoded" if self.encoding == "srgb" else "scene-linear",
            "cube_domain": [0.0, input_domain(self.encoding, self.domain_max)],
            "cube_output": "srgb-encoded" if check_output(output) == "encoded"
                           else "scene-linear",
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


@record
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


def _refuse_sim_ocio(read: ReadOptions) -> None:
    """SIM's read options with an OpenColorIO colourspace are refused before anything is
    read (:func:`sim_ocio_refused`)."""
    if read.ocio_colourspace is not None:
        raise sim_ocio_refused("--ocio-colourspace", read.ocio_colourspace)


def _read(path: str | os.PathLike[str], corners: str | Sequence[float] | None,
          read: ReadOptions, reference: str, illuminant: str, *, sim: bool,
          keep_exposure_of: _Chart | None = None) -> _Chart:
    """Read and audit one chart; ``keep_exposure_of`` (the REAL chart, for ``--normalise
    none``): a SIM whose exposure would be auto is measured at REAL's exposure correction
    instead, so that the exposure difference stays for the correction to correct."""
    if sim and read.ocio_colourspace is not None:
        raise sim_ocio_refused("--ocio-colourspace", read.ocio_colourspace)
    img, sha256 = read_input(path, read)
    enc = read.encoding or img.encoding
    info = img.info(sha256=sha256, encoding=enc)
    exposure = read.exposure
    if exposure is None and enc == "linear" and keep_exposure_of is not None:
        exposure = keep_exposure_of.audit.exposure_ev
    try:
        audit = measure_pixels(img.pixels, corners, encoding=enc, exposure=exposure,
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


@record
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


def _is_float(chart: _Chart) -> bool:
    """Whether the chart's image holds floating-point pixels (values above 1 are light)."""
    info = chart.audit.image
    return info is None or info.pixel_type in FLOAT_PIXEL_TYPES


def _round_up(value: float, digits: int = 3) -> float:
    """``value`` > 0 rounded up to ``digits`` significant digits (a ``.cube``'s domain)."""
    step = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
    return float(f"{math.ceil(value / step - 1e-9) * step:.{digits}g}")


def _largest_value(pixels: NDArray[Any]) -> float:
    """The largest finite value of the R, G, B ``pixels`` (0 where none is)."""
    px = np.asarray(pixels)[..., :3]
    top = float(np.max(px)) if px.size else 0.0
    if not math.isfinite(top):
        finite = px[np.isfinite(px)]
        top = float(finite.max()) if finite.size else 0.0
    return top


def _prepare(sim: _Chart, real: _Chart, normalise_mode: str,
             weights: ArrayLike | None) -> _Prepared:
    sm, rm = sim.audit.measurement, real.audit.measurement
    if sm.patch_names != rm.patch_names:
        raise InvalidValueError(f"{sim.path} and {real.path}: the charts have different patches")
    names = rm.patch_names
    neutral = neutral_patches(rm)
    enc = sim.audit.encoding
    # a scene-linear SIM: its patches as exposed linear sRGB, unclipped (the audit's encoded
    # colours stop at 1, where a render brighter than the chart's white goes on)
    sim_lin = (patch_linear(sim.pixels, sim.audit) * 2.0 ** sim.audit.exposure_ev
               if enc == "linear" else np.asarray(linearize_srgb(sm.srgb), np.float64))
    _, norm = normalise(sm.srgb, rm.srgb, neutral, normalise_mode,
                        sim_linear=sim_lin if enc == "linear" else None)
    if sim.audit.neutral_ev is not None and real.audit.neutral_ev is not None:
        norm = replace(norm, neutral_ev=(sim.audit.neutral_ev, real.audit.neutral_ev),
                       audit_auto=(sim.audit.exposure_mode == "auto",
                                   real.audit.exposure_mode == "auto"))
    d = (np.asarray(norm.gains) if norm.gains is not None
         else np.full(3, 2.0 ** norm.exposure_ev))
    sim_fit = sim_lin * d
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
    sim_float = enc == "linear" and _is_float(sim)
    excluded = usable_patches(
        np.asarray(delinearize_srgb(sim_lin), np.float64) if enc == "linear" else sm.srgb,
        rm.srgb, names, () if sim_float else sim.audit.clipped_patches,
        real.audit.clipped_patches, sim_float=sim_float)
    w = np.array([0.0 if n in excluded else 1.0 for n in names])
    if weights is not None:
        w = w * np.asarray(weights, np.float64)
    p = _colourspace_matrix(sim.audit)
    to_fit = np.diag(d) @ (2.0 ** sim.audit.exposure_ev * p)
    sim_lin_pixels = sim_lin @ np.linalg.inv(
        np.diag(2.0 ** sim.audit.exposure_ev * np.ones(3)) @ p).T
    sim_pixels = (np.asarray(delinearize_srgb(sim_lin_pixels), np.float64) if enc == "srgb"
                  else sim_lin_pixels)
    domain_max = (1.0 if enc == "srgb" else
                  _round_up(max(float(np.max(np.linalg.solve(to_fit, np.ones(3)))),
                                _largest_value(sim.pixels))))
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
    _refuse_sim_ocio(sim_read)
    r = _read(real, real_corners, real_read, reference, illuminant, sim=False)
    s = _read(sim, sim_corners, sim_read, reference, illuminant, sim=True,
              keep_exposure_of=r if normalise_mode == "none" else None)
    return _fit_charts(s, r, model, objective, normalise_mode, weights)


@record
class LutCheck:
    """The ``.cube`` through OpenColorIO against the model itself: the cube ``size``, the
    largest and mean ΔE00 over the chart's patches (``chart_max``, ``chart_mean``) and over a
    ``grid_points``-point lattice of the input range (``grid_max``, ``grid_mean``, the 99th
    percentile ``grid_p99`` and the ``grid_within`` fraction of points within
    ``tolerance``), and whether it passed (:attr:`passed`: the chart's maximum and the
    lattice's 99th percentile within ``tolerance``, the lattice's maximum within
    ``max_tolerance``)."""

    size: int
    chart_max: float
    chart_mean: float
    grid_max: float
    grid_mean: float
    grid_points: int
    tolerance: float
    grid_p99: float = 0.0
    grid_within: float = 1.0
    max_tolerance: float = LUT_MAX_TOLERANCE

    @property
    def passed(self) -> bool:
        """The chart's maximum and the lattice's 99th percentile within ``tolerance``, the
        lattice's maximum within ``max_tolerance``."""
        return (self.chart_max <= self.tolerance and self.grid_p99 <= self.tolerance
                and self.grid_max <= self.max_tolerance)

    def limit(self) -> str:
        """The check's limit in words."""
        return (f"chart max and lattice 99th percentile <= {self.tolerance:g}, lattice max <= "
                f"{self.max_tolerance:g}")

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"size": self.size, "chart_max_delta_e": self.chart_max,
                "chart_mean_delta_e": self.chart_mean, "grid_max_delta_e": self.grid_max,
                "grid_mean_delta_e": self.grid_mean, "grid_p99_delta_e": self.grid_p99,
                "grid_fraction_within": self.grid_within, "grid_points": self.grid_points,
                "tolerance": self.tolerance, "max_tolerance": self.max_tolerance,
                "passed": self.passed}


def check_points(correction: Correction) -> tuple[tuple[F64, F64], tuple[F64, F64]]:
    """The points a ``.cube`` is checked on (the chart's SIM pixel values, a
    :data:`CHECK_GRID`^3 lattice of the input range, most points between the cube's nodes)
    and the model's own output there as CIELAB (:meth:`Correction.display_lab`): what
    :func:`check_cube` compares with, computed once for every cube size tried."""
    grid = lattice_inputs(CHECK_GRID, correction.encoding, correction.domain_max,
                          "encoded").reshape(-1, 3)
    points = (correction.sim_pixels, grid)
    return points, (correction.display_lab(correction.apply(points[0])),
                    correction.display_lab(correction.apply(points[1])))


def check_cube(correction: Correction, path: str | os.PathLike[str], size: int,
               points: tuple[tuple[F64, F64], tuple[F64, F64]] | None = None,
               output: str | None = None) -> LutCheck:
    """Apply the ``.cube`` at ``path`` with OpenColorIO's processor and compare it with
    :meth:`Correction.apply` on the chart's patches and on a dense lattice
    (:class:`LutCheck`); ``points``: :func:`check_points` of ``correction``, if computed;
    ``output``: the cube's output convention (None: the input's encoding)."""
    output = default_output(correction.encoding) if output is None else output
    proc = cube_processor(path)
    (chart, grid), (chart_lab, grid_lab) = points or check_points(correction)
    out = []
    for pts, direct in ((chart, chart_lab), (grid, grid_lab)):
        lut = apply_processor(proc, pts).astype(np.float64)
        out.append(np.asarray(delta_e_2000(correction.output_lab(lut, output), direct),
                              np.float64))
    return LutCheck(size, float(out[0].max()), float(out[0].mean()), float(out[1].max()),
                    float(out[1].mean()), len(grid), LUT_TOLERANCE,
                    float(np.percentile(out[1], 99)),
                    float(np.mean(out[1] <= LUT_TOLERANCE)), LUT_MAX_TOLERANCE)


@record
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
    cube_output
        The ``.cube``'s output convention (:data:`fidelity.correction.lut.CUBE_OUTPUTS`;
        empty: the input's encoding, :attr:`output`).
    sim_properties
        The SIM chart's sharpness and noise with their predicted losses at the detector's
        input (:class:`fidelity.prediction.properties.PropertyJudgement`; None: not judged).
        The ``.cube`` corrects colour only: they stay as they are.
    real_properties
        The same of the REAL chart.
    camera_fits
        ``fit --camera`` only: the camera file's optics and noise fitted to REAL's sharpness
        and noise (:class:`PropertyFit`, one per property); empty otherwise.
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
    cube_output: str = ""
    sim_properties: PropertyJudgement | None = None
    real_properties: PropertyJudgement | None = None
    camera_fits: tuple[PropertyFit, ...] = ()

    @property
    def lut(self) -> LutCheck:
        """The check of the ``.cube`` written."""
        return self.lut_checks[-1]

    @property
    def output(self) -> str:
        """The ``.cube``'s output convention: ``encoded`` or ``linear``."""
        return self.cube_output or default_output(self.correction.encoding)

    @property
    def warnings(self) -> list[str]:
        """What makes the correction unfit to apply as it is, one sentence each (empty: none):
        a model that does not express the difference (cross-validated ΔE00 above
        :data:`EXPRESSED_DELTA_E`, or no lower than before), a correction that does not lower
        the sim-to-real ΔE00 (or raises it above :data:`EXPRESSED_DELTA_E` where the
        simulation already matched), a ``.cube`` that misses its check."""
        c, lut, b, a = self.correction, self.lut, self.before, self.after
        out = []
        if not c.expressed:
            out.append(f"the {c.model.name} model does not express this difference: "
                       f"{c.cv_mean:.2f} ΔE00 remains on patches held out of the fit (above "
                       f"{EXPRESSED_DELTA_E:g}); what is left is not a colour mapping of this "
                       "family (quantisation, noise, a spatial effect, or a model too simple)")
        if b.mean_delta_e <= EXPRESSED_DELTA_E:  # nothing to lower: near the identity
            if a.mean_delta_e > EXPRESSED_DELTA_E:
                out.append(f"the correction raises the sim-to-real ΔE00 above "
                           f"{EXPRESSED_DELTA_E:g} (mean {b.mean_delta_e:.2f} -> "
                           f"{a.mean_delta_e:.2f}): do not apply it")
        elif c.cv_mean > 0 and a.mean_delta_e >= b.mean_delta_e:
            out.append(f"the correction does not lower the sim-to-real ΔE00 (mean "
                       f"{b.mean_delta_e:.2f} -> {a.mean_delta_e:.2f}): the {c.model.name} "
                       "model cannot express this difference")
        elif np.isfinite(c.cv_mean) and c.cv_mean >= b.mean_delta_e:
            out.append("the cross-validated ΔE00 is no lower than before: the fit memorises "
                       "the patches rather than expressing the difference")
        if not lut.passed:
            hint = ""
            if c.encoding == "linear" and self.output == "encoded":
                hint = ("; sRGB-encoded output of scene-linear input puts the encoding's curve "
                        "inside a lattice even in light, whose first nodes skip the shadows: "
                        "--cube-output linear (exact for gains and matrix), then encode")
            elif c.encoding == "linear" and c.model.name not in AFFINE_MODELS:
                hint = "; a gains or matrix correction is exact on a lattice even in light"
            out.append(f"the .cube ({lut.size}^3, the largest tried) misses its check: ΔE00 "
                       f"against the model max {lut.chart_max:.3f} over the chart, 99th "
                       f"percentile {lut.grid_p99:.3f} and max {lut.grid_max:.3f} over "
                       f"{lut.grid_points} lattice points (limit: {lut.limit()}): between its "
                       f"nodes it is not the model{hint}")
        for f in self.camera_fits:
            if f.value is not None and not f.matched():
                what = "MTF50" if f.property == "sharpness" else "SNR at 18 % grey"
                out.append(f"the corrected camera's {what} ({f.after}) is not REAL's "
                           f"({f.real}): {f.note or 'the fit did not converge'}")
        return out


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
    cube_output: str | None = None,
) -> FitReport:
    """:func:`fit_correction`, then write ``correction.cube`` (the smallest cube size whose
    :class:`LutCheck` passes), ``correction.ocio`` and ``correction.json`` into the folder
    ``out`` and verify them (module docstring).

    ``cube_output`` is the cube's output convention (:data:`fidelity.correction.lut.CUBE_OUTPUTS`:
    ``encoded``, sRGB-encoded; ``linear``, scene-linear; None: the SIM's own encoding). The
    verification puts through OpenColorIO only the SIM pixels that the audit measures (its
    patch windows); ``corrected=True`` puts the whole SIM image through and writes it
    (:func:`corrected_name`: a 16-bit PNG for sRGB-encoded output, clipped as a camera
    stores it; a float EXR for scene-linear output), measuring the whole corrected image
    instead (the same patch means; it costs the whole image's transform and writing)."""
    ocio()
    c0, t0 = time.process_time(), time.perf_counter()

    sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                              (None, real_ocio_colourspace))
    _refuse_sim_ocio(sim_read)
    r = _read(real, real_corners, real_read, reference, illuminant, sim=False)
    s = _read(sim, sim_corners, sim_read, reference, illuminant, sim=True,
              keep_exposure_of=r if normalise_mode == "none" else None)
    c1, t1 = time.process_time(), time.perf_counter()
    corr = _fit_charts(s, r, model, objective, normalise_mode, None)
    c2, t2 = time.process_time(), time.perf_counter()
    return _verify(s, r, corr, Path(out), normalise_mode=normalise_mode, judge=judge,
                   corrected=corrected, seconds=(t1 - t0, t2 - t1),
                   cpu=(c1 - c0, c2 - c1), measure=measure, cube_output=cube_output)


def _verify(s: _Chart, r: _Chart, corr: Correction, folder: Path, *, normalise_mode: str,
            judge: JudgeOptions, corrected: bool, seconds: tuple[float, float],
            cpu: tuple[float, float], measure: MeasureRequest | None = None,
            cube_output: str | None = None) -> FitReport:
    """Write the cube, the config and ``correction.json`` of ``corr`` into ``folder`` and
    verify them on the SIM chart ``s`` against the REAL chart ``r`` (module docstring)."""
    c2, t2 = time.process_time(), time.perf_counter()
    output = check_output(default_output(corr.encoding) if cube_output is None
                          else cube_output)
    out_encoding = "srgb" if output == "encoded" else "linear"
    folder.mkdir(parents=True, exist_ok=True)
    cube = folder / "correction.cube"
    checks: list[LutCheck] = []
    points = check_points(corr)
    for n in CUBE_SIZES:
        corr.to_cube(cube, n, output)
        checks.append(check_cube(corr, cube, n, points, output))
        if checks[-1].passed:
            break
    inp, out_words = corr.cube_convention(output)
    config = folder / "correction.ocio"
    write_text_atomic(config, ocio_config(cube, f"fidelity fit: {corr.model.name} correction "
                                                f"of {Path(s.path).name} towards "
                                                f"{Path(r.path).name}; sim: {inp}; sim "
                                                f"corrected: {out_words}"))
    sa, ra = s.audit, r.audit
    files = {"cube": str(cube), "ocio": str(config), "json": str(folder / "correction.json")}
    if corrected:
        whole = apply_processor(config_processor(config), np.asarray(s.pixels)[..., :3])
        files["corrected"] = str(_write_corrected(folder, whole, out_encoding))
        after_srgb_audit = remeasure(whole, sa, output_encoding=out_encoding)
    else:
        cube_only = cube_processor(cube, reload=False)  # the file check_cube just read
        after_srgb_audit = remeasure(s.pixels, sa, lambda v: apply_processor(cube_only, v),
                                     output_encoding=out_encoding)
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
    write_json_atomic(folder / "correction.json", corr.to_json(output))
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
                     measured[0], measured[1], output,
                     chart_properties(sa, pb, judge), chart_properties(ra, pb, judge))


def chart_properties(audit: ImageMeasurement, prediction: Prediction, judge: JudgeOptions
                     ) -> PropertyJudgement | None:
    """The sharpness and noise of an audited chart judged at the detector's input, as an
    audit judges them (:func:`fidelity.prediction.judge.judge_properties`, no verdict;
    ``prediction`` a colour prediction, for the limits equivalent to ΔE00 3); None for an
    audit that does not describe its image's size."""
    info = audit.image
    if info is None:
        return None
    judged, _ = judge_properties(None, prediction, None, size=judge.size,
                                 sharpness=audit.sharpness, noise=audit.noise,
                                 scale=detector_scale(info.width, info.height))
    return judged


@record
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
    cube_output: str | None = None,
) -> SharedFit:
    """Fit one matrix and per-pair gains over ``pairs`` of (SIM, REAL) charts, the same
    cameras under different illuminants (:class:`SharedFit`), and write and verify each pair's
    correction ``matrix @ diag(gains)`` as :func:`fit_and_verify` does, into
    ``out/pair-<k>`` (k from 1). The fit is weighted least squares in linear RGB over the
    patches usable in each pair; corners and the other options (``cube_output`` too) apply
    to every pair."""
    ocio()
    if len(pairs) < 2:
        raise InvalidValueError("a fit over illuminants needs at least two pairs (--pair SIM "
                                "REAL, given twice or more)")
    t0 = time.perf_counter()
    charts = []
    for sim, real in pairs:
        sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                                  (None, real_ocio_colourspace))
        _refuse_sim_ocio(sim_read)
        r = _read(real, real_corners, real_read, reference, illuminant, sim=False)
        charts.append((_read(sim, sim_corners, sim_read, reference, illuminant, sim=True,
                             keep_exposure_of=r if normalise_mode == "none" else None), r))
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
                               seconds=(0.0, 0.0), cpu=(0.0, 0.0), cube_output=cube_output))
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


#: Most render-and-measure steps of one property's fit (:func:`fit_optics`, :func:`fit_noise`).
PROPERTY_FIT_STEPS = 8
#: Relative tolerance of the fitted MTF50 (the e-SFR of a noiseless turned chart repeats
#: exactly, so this is the search's, not the measurement's).
MTF50_TOLERANCE = 0.005
#: Relative tolerance of the fitted SNR at 18 % grey (the noise is seeded, so the measured SNR
#: is a deterministic function of the full well; 1 % is about the sampling error of the grey
#: patch's SNR on the turned chart).
SNR_TOLERANCE = 0.01


@record
class PropertyFit:
    """A camera file's optics or noise fitted to REAL's sharpness or noise (``fit --camera``).

    Each value is measured as ``fidelity check`` measures a camera: on its turned chart
    (:class:`fidelity.camera.render.FrameRender`), at the camera's own pixels, which are taken
    to be REAL's (a sensor model renders the real sensor's pixel grid).

    Attributes
    ----------
    property
        ``sharpness`` (the luminance MTF50 of the softer edge, cycles per pixel) or ``noise``
        (the SNR at the 18 % grey patch, a ratio).
    real
        REAL's value at its own resolution; None: not measured (then nothing is fitted).
    u_real
        Its standard uncertainty (None: unknown).
    before
        The camera file's own value; None: not measured (a noiseless camera's SNR is inf).
    after
        The corrected camera file's value, measured on its own render; None: not measured.
    parameter
        The camera-file field fitted: ``optics.sigma_px`` (a Gaussian PSF's standard
        deviation, pixels) or ``noise.full_well`` (electrons at raw 1; the read noise is kept).
    value
        The fitted value; None: the field was not changed.
    steps
        Render-and-measure steps the search took.
    note
        Why nothing was fitted, or what the fit could not express ("" when it matched).
    """

    property: str
    real: float | None
    u_real: float | None
    before: float | None
    after: float | None
    parameter: str
    value: float | None
    steps: int
    note: str = ""

    def matched(self) -> bool:
        """Whether the corrected camera's value is REAL's within the fit's tolerance (twice
        the search's relative tolerance, or twice REAL's standard uncertainty)."""
        if self.real is None or self.after is None:
            return False
        if math.isinf(self.real) or math.isinf(self.after):
            return self.real == self.after
        tol = MTF50_TOLERANCE if self.property == "sharpness" else SNR_TOLERANCE
        return abs(self.after - self.real) <= max(2 * tol * self.real, 2 * (self.u_real or 0))

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, with ``matched``; infinities as None."""
        def fin(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else v
        return {"property": self.property, "real": fin(self.real),
                "u_real": fin(self.u_real), "before": fin(self.before),
                "after": fin(self.after), "parameter": self.parameter, "value": self.value,
                "steps": self.steps, "note": self.note, "matched": self.matched()}


def turned_chart_values(camera: CameraModel, illuminant: str, reference: str = "scene"
                        ) -> tuple[float | None, float | None]:
    """The MTF50 (cycles per pixel, the softer edge's luminance) and the SNR at 18 % grey of
    ``camera``'s render under ``illuminant``, measured as ``fidelity check`` measures
    them (:func:`fidelity.camera.render.frame_properties`), the MTF50 on the tables' axis as
    a verdict judges it (a slanted-edge target's through
    :func:`fidelity.prediction.properties.target_on_table_axis`: the axis REAL's is on);
    None where not measured."""
    frame = render_chart(camera, illuminant, reference=reference, frame=True).frame
    sharpness, noise = frame_properties(frame, reference, illuminant)
    mtf, snr = chart_mtf50(sharpness), chart_snr(noise)
    if mtf is not None and sharpness is not None and sharpness.method == TARGET_METHOD:
        mtf = target_on_table_axis(*mtf)
    return (None if mtf is None else mtf[0]), (None if snr is None else snr[0])


def _gaussian_sigma(mtf50: float) -> float:
    """The Gaussian PSF whose MTF times the pixel aperture's is 1/2 at ``mtf50`` cycles per
    pixel: ``exp(-2 pi^2 sigma^2 f^2) |sinc f| = 1/2`` (the search's first guess)."""
    f = min(max(mtf50, 1e-3), 0.6)
    x = math.log(2.0 * abs(math.sin(math.pi * f) / (math.pi * f)))
    return math.sqrt(x / (2 * math.pi ** 2 * f * f)) if x > 0 else 0.3


def fit_optics(camera: CameraModel, real: tuple[float, float | None] | None, illuminant: str,
               reference: str = "scene") -> tuple[CameraModel, PropertyFit]:
    """The camera with a Gaussian PSF whose turned chart has REAL's MTF50.

    A secant search on ``sigma`` (pixels) over the noiseless camera's measured MTF50 (the
    same e-SFR that measured REAL), from the closed form's guess (:func:`_gaussian_sigma`),
    until the MTF50 is within :data:`MTF50_TOLERANCE` (relative). ``real``: REAL's MTF50 and
    its standard uncertainty (None: not measured). REAL at least as sharp as the camera
    without a lens, within twice its uncertainty (or sharper: sharpening, which the model has
    not), gets no PSF; REAL softer
    than :data:`fidelity.camera.model.MAX_BLUR_PX` allows gets that limit, and the note says
    so. Returns the camera (unchanged where nothing is fitted) and the :class:`PropertyFit`
    (``after`` still None: :func:`fit_camera_and_verify` measures the written file)."""
    before, _ = turned_chart_values(camera, illuminant, reference)
    param = "optics.sigma_px"
    if real is None:
        return camera, PropertyFit("sharpness", None, None, before, None, param, None, 0,
                                   "REAL's edges were not measured: optics unchanged")
    real_mtf50, u_real = real
    quiet = replace(camera, noise=Noise(None))

    def mtf(sigma: float) -> float | None:
        optics = Optics("gaussian", sigma_px=sigma) if sigma > 0 else Optics()
        return turned_chart_values(replace(quiet, optics=optics), illuminant, reference)[0]

    sharpest = mtf(0.0)
    steps = 1
    if sharpest is None:
        return camera, PropertyFit("sharpness", real_mtf50, u_real, before, None, param, None, steps,
                                   "the camera's own edges were not measured: optics unchanged")
    if real_mtf50 >= sharpest - max(MTF50_TOLERANCE * sharpest, 2 * (u_real or 0.0)):
        removed = 0.0 if camera.optics.kind != "none" else None
        return (replace(camera, optics=Optics()),
                PropertyFit("sharpness", real_mtf50, u_real, before, None, param, removed, steps,
                            f"REAL (MTF50 {real_mtf50:.3g} cy/px) is as sharp as the camera "
                            f"without lens blur ({sharpest:.3g}) within twice its uncertainty, "
                            "or sharper (sharpening, which the camera model does not "
                            "express): no PSF"))
    points: list[tuple[float, float]] = []
    sigma = _gaussian_sigma(real_mtf50)
    note = ""
    while steps < PROPERTY_FIT_STEPS:
        got = mtf(sigma)
        steps += 1
        if got is None:  # too soft to measure: step back towards the sharp side
            sigma *= 0.7
            continue
        points.append((sigma, got / real_mtf50 - 1.0))
        if abs(points[-1][1]) <= MTF50_TOLERANCE:
            break
        if len(points) >= 2 and points[-1][1] != points[-2][1]:
            (s0, g0), (s1, g1) = points[-2], points[-1]
            nxt = s1 - g1 * (s1 - s0) / (g1 - g0)
        else:  # MTF50 falls roughly as 1/sigma: one proportional step
            nxt = sigma * (1.0 + points[-1][1])
        sigma = min(max(nxt, 0.05), MAX_BLUR_PX)
        if sigma == MAX_BLUR_PX and points[-1][1] > 0:
            note = f"REAL is softer than a {MAX_BLUR_PX:g} px Gaussian, the model's limit"
            break
    else:
        closest = min(points, key=lambda p: abs(p[1])) if points else None
        note = (f"the search stopped after {steps} steps at MTF50 "
                f"{real_mtf50 * (1 + closest[1]):.4g} cy/px" if closest else
                "the blurred camera's edges were not measured")
    if not points:
        return camera, PropertyFit("sharpness", real_mtf50, u_real, before, None, param, None, steps,
                                   note)
    best = min(points, key=lambda p: abs(p[1]))[0]
    return (replace(camera, optics=Optics("gaussian", sigma_px=best)),
            PropertyFit("sharpness", real_mtf50, u_real, before, None, param, best, steps, note))


def fit_noise(camera: CameraModel, real: tuple[float, float | None] | None, illuminant: str,
              reference: str = "scene") -> tuple[CameraModel, PropertyFit]:
    """The camera with the full well whose turned chart has REAL's SNR at 18 % grey.

    Shot noise dominates at grey, so the SNR grows as the square root of the full well: each
    step scales it by ``(SNR_real / SNR)^2`` (the read noise in electrons kept), until the SNR
    is within :data:`SNR_TOLERANCE`. ``real``: REAL's SNR and its standard uncertainty (None:
    not measured). A noiseless REAL grey (SNR inf) removes the camera's
    noise. Returns the camera and the :class:`PropertyFit` (``after`` None, as
    :func:`fit_optics`)."""
    _, before = turned_chart_values(camera, illuminant, reference)
    param = "noise.full_well"
    if real is None:
        return camera, PropertyFit("noise", None, None, before, None, param, None, 0,
                                   "REAL's grey patch noise was not measured: noise unchanged")
    real_snr, u_real = real
    if math.isinf(real_snr) and not camera.noise.enabled:
        return camera, PropertyFit("noise", real_snr, u_real, before, None, param, None, 0,
                                   "REAL's grey patch is noiseless, as the camera's: noise "
                                   "unchanged")
    if math.isinf(real_snr):
        return (replace(camera, noise=Noise(None, 0.0, camera.noise.seed)),
                PropertyFit("noise", real_snr, u_real, before, None, param, None, 0,
                            "REAL's grey patch is noiseless: the camera's noise removed"))
    read_noise, seed = camera.noise.read_noise, camera.noise.seed
    well = camera.noise.full_well or max(real_snr * real_snr / 0.18, 1.0)
    steps, best, note = 0, (well, math.inf), ""
    while steps < PROPERTY_FIT_STEPS:
        try:
            _, snr = turned_chart_values(replace(camera, noise=Noise(well, read_noise, seed)),
                                         illuminant, reference)
        except InvalidValueError as exc:  # a read noise too large for this well
            note = str(exc)
            break
        steps += 1
        if snr is None or not math.isfinite(snr) or snr <= 0:
            note = "the noisy camera's grey patch SNR was not measured"
            break
        err = snr / real_snr - 1.0
        if abs(err) < abs(best[1]):
            best = (well, err)
        if abs(err) <= SNR_TOLERANCE:
            break
        well = max(well * (real_snr / snr) ** 2, 1.0)
    else:
        note = (f"the search stopped after {steps} steps at SNR "
                f"{real_snr * (1 + best[1]):.4g}")
    if math.isinf(best[1]):
        return camera, PropertyFit("noise", real_snr, u_real, before, None, param, None, steps, note)
    return (replace(camera, noise=Noise(best[0], read_noise, seed)),
            PropertyFit("noise", real_snr, u_real, before, None, param, best[0], steps, note))


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
    cube_output: str | None = None,
    properties: bool = True,
) -> tuple[FitReport, Path]:
    """Render the chart through the camera model file ``camera`` in closed form (under
    ``illuminant``; ``out/sim_render.png`` or ``.exr``), fit and verify the correction onto
    ``real`` as :func:`fit_and_verify` does, and write ``out/corrected.toml``: the camera
    file with its colour-correction matrix replaced by the corrected one,
    ``inv(T) M T @ CCM`` (``M`` the fitted matrix in the fit space, ``T`` the simulator's
    pixels -> fit space, ``CCM`` the camera's own matrix, resolved).

    The correction of a camera file is a 3x3 matrix in the camera's linear output (before its
    tone curve): ``model`` ``gains`` or ``matrix``, and the camera's tone curve ``srgb`` or
    ``linear`` (the encodings the audit reads exactly).

    With ``properties`` (the default), the camera file's optics and noise are fitted too
    (:func:`fit_optics`, :func:`fit_noise`): ``corrected.toml`` gets the Gaussian PSF and the
    full well whose turned chart has REAL's MTF50 and SNR at 18 % grey, and the report's
    :attr:`FitReport.camera_fits` gives each before, after (measured on the written file)
    and REAL's. Returns the report and the path of ``corrected.toml``."""
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
                         measure=measure, cube_output=cube_output)
    c = rep.correction
    t = c.to_fit
    ccm = colour_correction_matrix(cam, load_illuminant(illuminant))
    new = np.linalg.inv(t) @ c.model.matrix @ t @ np.asarray(ccm, np.float64)
    data = _absolute_paths(load_document(path, str(path)), path.parent.resolve())
    data["name"] = f"{data.get('name', cam.name)}-corrected"
    data["description"] = (f"{data.get('description', cam.name)}, corrected by fidelity fit "
                           f"({c.model.name}) towards {Path(real).name}")
    data["ccm"] = {"method": "matrix", "matrix": new.tolist()}
    fits: list[PropertyFit] = []
    if properties:
        rp = rep.real_properties

        def native(prop: str) -> tuple[float, float | None] | None:
            got = rp.prediction(prop) if rp is not None else None
            if got is None or got.native_x is None:
                return None
            return got.native_x, None if got.u_x is None else got.u_x * got.scale

        fitted, sharp = fit_optics(cam, native("sharpness"), illuminant, reference)
        fitted, noisy = fit_noise(fitted, native("noise"), illuminant, reference)
        fits = [sharp, noisy]
        if fitted.optics != cam.optics:
            data["optics"] = ({"kind": "gaussian", "sigma_px": round(fitted.optics.sigma_px, 4)}
                              if fitted.optics.kind == "gaussian" else {"kind": "none"})
        if fitted.noise != cam.noise:
            n = fitted.noise
            if n.full_well is None:
                data.pop("noise", None)
            else:
                data["noise"] = {"full_well": round(n.full_well, 1),
                                 "read_noise": n.read_noise, "seed": n.seed}
    what = "the colour matrix" + (", optics and noise" if properties else "")
    toml = folder / "corrected.toml"
    write_text_atomic(toml, f"# fidelity fit --camera {path.name}: {what} corrected towards "
                            f"{Path(real).name} (ΔE00 after {rep.after.mean_delta_e:.3f})\n"
                      + tomli_w.dumps(data))
    if fits:
        mtf, snr = turned_chart_values(read_camera_file(toml), illuminant, reference)
        rep = replace(rep, camera_fits=(replace(fits[0], after=mtf), replace(fits[1], after=snr)))
    return rep, toml


def corrected_name(encoding: str) -> str:
    """The file name of the corrected SIM image, by the encoding of the ``.cube``'s output:
    ``corrected.png`` (``srgb``) or ``corrected.exr`` (``linear``)."""
    return "corrected.png" if encoding == "srgb" else "corrected.exr"


def _write_corrected(folder: Path, pixels: NDArray[Any], encoding: str) -> Path:
    path = folder / corrected_name(encoding)
    if encoding == "srgb":
        return write_png(path, pixels, 16)
    return write_exr(path, pixels, "the simulator's linear RGB corrected by fidelity fit")


def patch_linear(pixels: NDArray[Any], audit: ImageMeasurement,
                 transform: Callable[[NDArray[Any]], NDArray[Any]] | None = None,
                 encoding: str | None = None) -> F64:
    """The linear sRGB patch means ``(n, 3)`` of ``pixels`` (an image of the size of the
    audited one) in ``audit``'s sampling windows, before any exposure and unclipped: each
    pixel first through ``transform`` (``(m, 3)`` -> ``(m, 3)``), decoded from ``encoding``
    (None: the audit's), in the audit's colourspace, pixels with NaN or Inf excluded."""
    p = _colourspace_matrix(audit)
    windows = [np.asarray(v, np.float32).reshape(-1, 3)  # float32 like the pixels: 2x faster
               for v in window_pixels(pixels, audit.location)]
    if transform is not None:
        counts = np.cumsum([len(v) for v in windows])[:-1]
        joined = np.asarray(transform(np.concatenate(windows)), np.float32)
        windows = np.split(joined, counts)
    encoding = audit.encoding if encoding is None else encoding
    means = []
    for v in windows:
        finite = np.isfinite(v).all(axis=1)
        if not finite.all():
            v = v[finite]
        if len(v) == 0:
            raise InvalidValueError("the corrected image has no finite pixel in a patch window")
        means.append(p @ np.asarray(_to_linear(v, encoding)).mean(axis=0, dtype=np.float64))
    return np.array(means)


def remeasure(pixels: NDArray[Any], audit: ImageMeasurement,
              transform: Callable[[NDArray[Any]], NDArray[Any]] | None = None, *,
              output_encoding: str | None = None) -> F64:
    """The encoded sRGB patch colours ``(n, 3)`` of ``pixels`` (an image of the size of the
    audited one), each pixel first through ``transform`` (``(m, 3)`` -> ``(m, 3)``, e.g. the
    correction through OpenColorIO's processor), measured as ``audit`` measured its image: the
    same sampling windows, colourspace and exposure rule (auto exposure fitted again on the
    neutral patches, a fixed one kept), pixels with NaN or Inf excluded, clipped to [0, 1].
    ``output_encoding``: the encoding of what ``transform`` gives (``srgb`` or ``linear``, a
    ``.cube``'s output; None: the audit's), decoded by it.

    Only the windows' pixels are read and transformed: the patch means are those of the whole
    image through ``transform`` measured in the same windows (``tests/pipeline/test_fit.py`` checks
    both ways), at the cost of the windows, not of the image."""
    lin = patch_linear(pixels, audit, transform, output_encoding)
    ref = audit.reference
    ev = (exposure_from_neutrals(lin, ref.lab, ref.neutral_indices, ref.patch_names)
          if audit.exposure_mode == "auto" else audit.exposure_ev)
    return np.clip(np.asarray(delinearize_srgb(lin * 2.0 ** ev), np.float64), 0.0, 1.0)


__all__ = ["AFFINE_MODELS", "CHECK_GRID", "Correction", "DEFAULT_MODEL", "EXPRESSED_DELTA_E",
           "FitReport", "GREY_CHROMA", "MTF50_TOLERANCE", "PROPERTY_FIT_STEPS", "PropertyFit", "SNR_TOLERANCE",
           "chart_properties", "fit_noise", "fit_optics", "turned_chart_values", "LUT_MAX_TOLERANCE", "LUT_TOLERANCE", "LutCheck", "check_cube", "check_points",
           "CAMERA_PIXELS_PER_PATCH", "corrected_name", "fit_and_verify", "fit_camera_and_verify", "fit_correction", "fit_pairs_and_verify",
           "patch_linear", "remeasure", "SharedFit"]
