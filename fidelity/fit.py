"""Fix, not only flag: fit the correction that makes the simulated camera match the real one.

:func:`fit_correction` reads the same chart rendered by the simulator (SIM) and photographed by
the real camera (REAL), exactly as ``fidelity compare`` does (the same
:class:`~fidelity.chart.measure.ReadOptions`, corners and normalisation), and fits a colour
correction from the simulated patch colours onto the real ones
(:mod:`fidelity.correction.models`):

1. Both charts are audited (:func:`fidelity.chart.measure.measure_pixels`); the *fit space* is
   each chart's linear sRGB as audited (auto exposure for linear pixels), the simulated chart
   scaled by the normalisation (:func:`fidelity.compare.normalise`: ``exposure`` default,
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

:func:`verify_correction` checks the correction instead of assuming it: the ``.cube`` through
OpenColorIO's processor against the model itself, over the chart and a dense lattice
(:class:`LutCheck`; the smallest cube size of :data:`~fidelity.correction.lut.CUBE_SIZES`
within :data:`LUT_TOLERANCE` ΔE00), then the whole SIM image through the cube by OpenColorIO
(loaded from ``correction.ocio``), measured again in the audit's sampling windows
(:func:`remeasure`) and compared with REAL: the sim-to-real ΔE00 and its predicted ΔmAP before
and after (:class:`FitReport`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.chart.measure import DEFAULT_READ, ChartMeasurement, ImageMeasurement, ReadOptions
from fidelity.correction.models import ColourModel, Conditioning
from fidelity.errors import InvalidValueError
from fidelity.prediction.table import Prediction
from fidelity.records import Normalisation, utc_now

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
#: Points per axis of the dense lattice the ``.cube`` is checked on (not a divisor of the cube
#: sizes' spacing, so that most points fall between the cube's nodes).
CHECK_GRID = 41


def _to_linear(pixels: NDArray[Any], encoding: str) -> NDArray[Any]:
    from fidelity.colour.colorimetry import linearize_srgb

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
    reason, the in-sample and cross-validated ΔE00."""

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
        from fidelity.colour.colorimetry import delinearize_srgb

        a = np.asarray(pixels, np.float64)
        if a.shape[-1:] != (3,):
            raise InvalidValueError(f"pixels must be (..., 3), got shape {a.shape}")
        fit = _to_linear(a, self.encoding) @ self.to_fit.T
        out = self.model.apply(fit) @ np.linalg.inv(self.to_fit).T
        if self.encoding == "srgb":
            return np.asarray(delinearize_srgb(out), np.float64)
        return np.asarray(out, np.float64)

    def display_lab(self, pixels: ArrayLike) -> F64:
        """CIELAB of pixel values as the fit space shows them (sRGB clipped to [0, 1]): what
        a ΔE00 between two outputs of the correction is measured on."""
        from fidelity.correction.models import linear_to_lab

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
        enc = ("sRGB-encoded values (IEC 61966-2-1) in [0, 1]" if self.encoding == "srgb" else
               f"scene-linear values 0 .. {self.domain_max:.6g} through a 1D shaper (sRGB "
               "encoding of v / max); values beyond are clamped")
        return [f"fidelity fit: {self.model.name} correction ({self.objective} objective), "
                f"{size}^3 lattice",
                f"input: the simulator's pixels, {enc}",
                "output: corrected pixels, same encoding and colourspace as the input",
                "apply with tetrahedral interpolation"]

    def to_cube(self, path: str | os.PathLike[str], size: int = 33) -> Path:
        """Write the ``.cube`` (OpenColorIO's Baker, :func:`fidelity.correction.lut.bake_cube`)
        atomically; returns the path."""
        from fidelity.correction.lut import bake_cube
        from fidelity.fileio import write_text_atomic

        return write_text_atomic(path, bake_cube(self.apply, size, self.encoding,
                                                 self.domain_max, self.cube_comments(size)))

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


def _read(path: str | os.PathLike[str], corners: str | Sequence[float] | None,
          read: ReadOptions, reference: str, illuminant: str) -> _Chart:
    from fidelity.chart.measure import measure_pixels, read_input
    from fidelity.errors import FidelityError

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
        raise type(exc)(f"{img.path}: {exc}") from None
    return _Chart(str(path), img.pixels, audit)


def _colourspace_matrix(audit: ImageMeasurement) -> F64:
    from fidelity.colour.colorimetry import matrix_rgb_to_linear_srgb

    name = audit.colourspace
    if name.startswith("chromaticities "):
        return matrix_rgb_to_linear_srgb([float(v) for v in name.split(" ", 1)[1].split(",")])
    return matrix_rgb_to_linear_srgb(name)


def _fit_charts(sim: _Chart, real: _Chart, model: str, objective: str | None,
                normalise_mode: str, weights: ArrayLike | None) -> Correction:
    from fidelity.chart.measure import neutral_patches
    from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
    from fidelity.compare import normalise
    from fidelity.correction.models import (
        DEFAULT_OBJECTIVE,
        cross_validate,
        fit_model,
        linear_to_lab,
        patch_delta_e,
        usable_patches,
    )

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
    objective = DEFAULT_OBJECTIVE if objective is None else objective
    fitted, cond = fit_model(sim_fit, real_fit, model, weights=w, objective=objective)
    cv = cross_validate(sim_fit, real_fit, model, weights=w, objective=objective, start=fitted)
    p = _colourspace_matrix(sim.audit)
    to_fit = np.diag(d) @ (2.0 ** sim.audit.exposure_ev * p)
    sim_lin_pixels = np.asarray(linearize_srgb(sm.srgb), np.float64) @ np.linalg.inv(
        np.diag(2.0 ** sim.audit.exposure_ev * np.ones(3)) @ p).T
    enc = sim.audit.encoding
    sim_pixels = (np.asarray(delinearize_srgb(sim_lin_pixels), np.float64) if enc == "srgb"
                  else sim_lin_pixels)
    domain_max = (1.0 if enc == "srgb" else
                  float(np.max(np.linalg.solve(to_fit, np.ones(3)))))
    return Correction(fitted, objective, cond, enc, to_fit, domain_max, norm, names, excluded,
                      sim_fit, real_fit, patch_delta_e(sim_fit, real_fit),
                      patch_delta_e(fitted.apply(sim_fit), real_fit), cv, sim_pixels)


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
    sim_corners, real_corners, normalise_mode, read, reference, illuminant
        As :func:`fidelity.compare.compare_charts`.
    weights
        ``(24,)`` patch weights (default 1; excluded patches get 0 whatever their weight).

    Returns
    -------
    Correction
    """
    from fidelity.chart.measure import reads_for

    sim_read, real_read = reads_for((sim, real), read)
    s = _read(sim, sim_corners, sim_read, reference, illuminant)
    r = _read(real, real_corners, real_read, reference, illuminant)
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


def check_cube(correction: Correction, path: str | os.PathLike[str], size: int) -> LutCheck:
    """Apply the ``.cube`` at ``path`` with OpenColorIO's processor and compare it with
    :meth:`Correction.apply` on the chart's patches and on a dense lattice (:class:`LutCheck`)."""
    from fidelity.colour.colorimetry import delta_e_2000
    from fidelity.correction.lut import apply_processor, cube_processor, lattice_inputs

    proc = cube_processor(path)
    grid = lattice_inputs(CHECK_GRID, correction.encoding, correction.domain_max).reshape(-1, 3)
    out = []
    for pts in (correction.sim_pixels, grid):
        lut = apply_processor(proc, pts).astype(np.float64)
        direct = correction.apply(pts)
        out.append(np.asarray(delta_e_2000(correction.display_lab(lut),
                                           correction.display_lab(direct)), np.float64))
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
    spent (``seconds``: ``read``, ``fit``, ``verify``)."""

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
    reference: str = "scene",
    illuminant: str = "D65",
    size: str = "any",
    table: str | None = None,
) -> FitReport:
    """:func:`fit_correction`, then write ``correction.cube`` (the smallest cube size within
    :data:`LUT_TOLERANCE`), ``correction.ocio`` and ``correction.json`` into the folder
    ``out`` and verify them (module docstring)."""
    from fidelity.chart.measure import measure_chart, neutral_patches
    from fidelity.compare import normalise
    from fidelity.correction.lut import (
        CUBE_SIZES,
        apply_processor,
        config_processor,
        ocio,
        ocio_config,
    )
    from fidelity.fileio import write_json_atomic, write_text_atomic
    from fidelity.prediction.judge import judge

    ocio()
    t0 = time.perf_counter()
    from fidelity.chart.measure import reads_for

    sim_read, real_read = reads_for((sim, real), read)
    s = _read(sim, sim_corners, sim_read, reference, illuminant)
    r = _read(real, real_corners, real_read, reference, illuminant)
    t1 = time.perf_counter()
    corr = _fit_charts(s, r, model, objective, normalise_mode, None)
    t2 = time.perf_counter()
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    cube = folder / "correction.cube"
    checks: list[LutCheck] = []
    for n in CUBE_SIZES:
        corr.to_cube(cube, n)
        checks.append(check_cube(corr, cube, n))
        if checks[-1].passed:
            break
    config = folder / "correction.ocio"
    write_text_atomic(config, ocio_config(cube, f"fidelity fit: {corr.model.name} correction "
                                                f"of {Path(sim).name} towards {Path(real).name}"))
    corrected = apply_processor(config_processor(config), s.pixels)
    sa, ra = s.audit, r.audit
    after_srgb_audit = remeasure(corrected, sa)
    rm = ra.measurement
    ref_srgb = np.clip(rm.srgb, 0, 1)
    neutral = neutral_patches(rm)
    before_srgb, _ = normalise(sa.measurement.srgb, rm.srgb, neutral, normalise_mode)
    after_srgb, _ = normalise(after_srgb_audit, rm.srgb, neutral, normalise_mode)
    before = measure_chart(before_srgb, rm.lab, rm.patch_names, reference_srgb=ref_srgb)
    after = measure_chart(after_srgb, rm.lab, rm.patch_names, reference_srgb=ref_srgb)
    t3 = time.perf_counter()
    pb = judge(before.mean_delta_e, size, table)[0]
    pa = judge(after.mean_delta_e, size, table)[0]
    write_json_atomic(folder / "correction.json", corr.to_json())
    files = {"cube": str(cube), "ocio": str(config), "json": str(folder / "correction.json")}
    return FitReport(utc_now(), str(sim), str(real), corr, before, after, pb, pa,
                     tuple(checks), files,
                     {"read": t1 - t0, "fit": t2 - t1, "verify": t3 - t2})


def remeasure(pixels: NDArray[Any], audit: ImageMeasurement) -> F64:
    """The encoded sRGB patch colours ``(n, 3)`` of ``pixels`` (an image of the same size as
    the audited one: its correction) measured as ``audit`` measured its image: the same
    sampling windows, encoding, colourspace and exposure rule (auto exposure fitted again on
    the neutral patches, a fixed one kept), pixels with NaN or Inf excluded, clipped to
    [0, 1]. Only the windows are read, so that verifying a 12 MP image costs what its windows
    cost."""
    from fidelity.chart.locate import window_pixels
    from fidelity.chart.measure import exposure_from_neutrals
    from fidelity.colour.colorimetry import delinearize_srgb

    p = _colourspace_matrix(audit)
    means = []
    for vals in window_pixels(pixels, audit.location):
        v = np.asarray(vals, np.float32).reshape(-1, 3)  # float32 like the pixels: 2x faster
        v = v[np.all(np.isfinite(v), axis=1)]
        if len(v) == 0:
            raise InvalidValueError("the corrected image has no finite pixel in a patch window")
        mean = np.asarray(_to_linear(v, audit.encoding), np.float64).mean(axis=0)
        means.append(p @ mean)
    lin = np.array(means)
    ref = audit.reference
    ev = (exposure_from_neutrals(lin, ref.lab, ref.neutral_indices, ref.patch_names)
          if audit.exposure_mode == "auto" else audit.exposure_ev)
    return np.clip(np.asarray(delinearize_srgb(lin * 2.0 ** ev), np.float64), 0.0, 1.0)


__all__ = ["CHECK_GRID", "Correction", "DEFAULT_MODEL", "EXPRESSED_DELTA_E", "FitReport", "GREY_CHROMA",
           "LUT_TOLERANCE", "LutCheck", "check_cube", "fit_and_verify", "fit_correction",
           "remeasure"]
