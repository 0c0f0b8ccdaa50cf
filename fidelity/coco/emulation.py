"""Emulate a camera's colour rendering on ordinary sRGB images.

A camera model (:mod:`fidelity.camera.model`) is spectral: it needs reflectances, not pixels. To see
what its colour errors cost a detector on COCO photographs we fit a *colour mapping* from the
reference colour of a surface (what an ideal camera would record: the scene-consistent sRGB of
:func:`fidelity.colour.spectral.scene_reference`) to the colour the camera outputs for the same
surface, and apply that mapping to every pixel of an image. Spectral detail the image no longer
has (metamerism) cannot be recovered; the fit is the best colour-to-colour estimate.

Training colours (:data:`TRAINING_SETS`): the 24 chart patches that the camera is measured on,
and, for ``"colour-science"``, every further reflectance that colour-science ships:

* the 190 training reflectances of AMPAS rawtoaces v1
  (``colour.characterisation.read_training_data_rawtoaces_v1``);
* the CIE 13.3 / CIE 2024 test colour samples (``colour.quality.SDS_TCS``) and the NIST CQS
  9.0 and 7.4 samples (``colour.quality.SDS_VS``);
* the other ColorChecker data sets in ``colour.SDS_COLOURCHECKERS`` (N. Ohta, ISO 17321-1, PMC).

For each reflectance R under the test-case illuminant E the reference is
``sRGB(M_cat XYZ(R, E))`` (CIE 1931 2°, Bradford to D65, IEC 61966-2-1), *clipped to [0, 1]*
because an 8-bit image can only hold that; the target is the camera's output for R with the
camera's own exposure, white balance and CCM (metered and fitted on the chart, exactly as
:func:`fidelity.camera.render.render_chart` does, noise-free).

Methods (:data:`EMULATION_METHODS`, ``method=``):

* ``"root-polynomial"`` (default): ``out = Q(T(P(linearize(srgb))))``: ``P`` is a
  root-polynomial colour correction (Finlayson, Mackiewicz & Hurlbert, "Color Correction Using
  Root-Polynomial Regression", IEEE TIP 24(5), 2015), degree 2 (terms R, G, B, sqrt(RG),
  sqrt(GB), sqrt(RB)), fitted by least squares in linear light with
  ``colour.characterisation.matrix_colour_correction(..., method="Finlayson 2015", degree=2,
  root_polynomial_expansion=True)``, from reference linear sRGB to the camera's linear signal
  before its tone curve; ``T`` and ``Q`` are the camera's own tone curve and quantisation
  (:func:`fidelity.camera.model.apply_tone_curve`, :func:`fidelity.camera.model.quantise`). Root-polynomial
  terms are homogeneous of degree 1, so the mapping scales with exposure like the camera does
  (a shaded red maps to a shaded camera-red).
* ``"lut3d"``: a 33^3 3D LUT on encoded sRGB: the root-polynomial mapping sampled on the grid
  plus a Gaussian radial-basis interpolation (``scipy.interpolate.RBFInterpolator``) of its
  residuals at the training colours, so the LUT bends towards every training colour; applied by
  trilinear interpolation, then the camera's quantisation.

Applying to 8-bit images (:meth:`Emulation.apply_uint8`) maps the first images on their
distinct colours and then builds a full 256^3 table (48 MiB), evaluated once per emulation on
all 16,777,216 code triples; both round ``rint(clip(x, 0, 1) * 255)`` like
:func:`fidelity.coco.dataset.to_uint8` and give the same codes; an image then costs one table
look-up per pixel.

Accuracy (:func:`emulation_accuracy`): the chart reference, as an 8-bit image, goes through the
same table; the result is compared patch by patch with the camera's rendered chart
(:func:`fidelity.camera.render.render_chart`) in CIEDE2000.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.camera.model import (
    CameraModel,
    apply_tone_curve,
    camera_response,
    develop,
    exposure_gain,
    load_camera,
    quantise,
)
from fidelity.camera.render import render_chart
from fidelity.coco.dataset import all_triples, code_triples, colour_codes, to_uint8
from fidelity.colour import colorimetry as cm
from fidelity.colour.colorimetry import (
    delinearize_srgb,
    delta_e_2000,
    linearize_srgb,
    matrix_chromatic_adaptation,
    srgb_to_lab,
)
from fidelity.colour.datasets import training_reflectances as shipped
from fidelity.colour.spectral import (
    GRID_STEP_NM,
    load_illuminant,
    load_patch_spectra,
    resample,
    scene_reference,
    tristimulus,
    wavelength_grid,
)
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.measure.pixels import luminance_linear_srgb

FloatArray = NDArray[np.float64]

#: Version of the fitting procedure; stored with results so that a changed fit is not mixed
#: with old detections (bump on any change that alters fitted mappings).
EMULATION_VERSION: int = 2
#: LUT grid size of the ``lut3d`` method (points per axis).
LUT_SIZE: int = 33
#: Gaussian RBF width (encoded sRGB units) and smoothing of the ``lut3d`` residual fit.
LUT_RBF_WIDTH: float = 0.08
LUT_RBF_SMOOTHING: float = 1e-4
#: Degree of the root-polynomial expansion (Finlayson et al. 2015).
ROOT_POLYNOMIAL_DEGREE: int = 2


# --------------------------------------------------------------------------------------------
# Training reflectances
# --------------------------------------------------------------------------------------------


@record
class ReflectanceSet:
    """Reflectances (K, N) on :func:`fidelity.colour.spectral.wavelength_grid` with names and sources."""

    name: str
    names: tuple[str, ...]
    reflectance: FloatArray
    sources: dict[str, int]


def _msds_rows(wavelengths: ArrayLike, values: ArrayLike) -> FloatArray:
    """Resample (N, K) tabulated reflectances to the grid; (K, M); ends held constant."""
    return resample(np.asarray(wavelengths, float), np.asarray(values, float),
                    wavelength_grid(), extrapolation="constant").T


@lru_cache(maxsize=4)
def _colour_science_reflectances(chart_spectra: str) -> ReflectanceSet:
    """The chart's patches, then colour-science's reflectances as shipped
    (:func:`fidelity.colour.datasets.training_reflectances`), resampled to the grid."""
    names: list[str] = []
    rows: list[FloatArray] = []
    sources: dict[str, int] = {}

    def add(label: str, items: list[tuple[str, FloatArray]]) -> None:
        sources[label] = len(items)
        for n, r in items:
            names.append(f"{label}: {n}")
            rows.append(r)

    chart = load_patch_spectra(chart_spectra)
    add(f"chart ({chart.name})", list(zip(chart.patch_names, chart.on_grid(), strict=True)))
    for label, items in shipped().items():
        add(label, [(n, _msds_rows(w, v[:, None])[0]) for n, w, v in items])
    refl = np.clip(np.vstack(rows), 0.0, None)
    refl.setflags(write=False)
    return ReflectanceSet("colour-science", tuple(names), refl, sources)


def _chart_only(chart_spectra: str) -> ReflectanceSet:
    chart = load_patch_spectra(chart_spectra)
    return ReflectanceSet("chart", tuple(chart.patch_names), chart.on_grid(),
                          {f"chart ({chart.name})": 24})


def _without_chart(chart_spectra: str) -> ReflectanceSet:
    full = _colour_science_reflectances(chart_spectra)
    sources = {k: v for k, v in full.sources.items() if not k.startswith("chart")}
    return ReflectanceSet("colour-science-no-chart", full.names[24:], full.reflectance[24:],
                          sources)


#: Training sets by name: function(chart_spectra) -> ReflectanceSet. ``colour-science-no-chart``
#: leaves the 24 measured chart patches out, so that accuracy on the chart is out of sample.
TRAINING_SETS: dict[str, Callable[[str], ReflectanceSet]] = {
    "chart": _chart_only,
    "colour-science": _colour_science_reflectances,
    "colour-science-no-chart": _without_chart,
}


def training_reflectances(name: str = "colour-science",
                          chart_spectra: str = "BabelColor Average") -> ReflectanceSet:
    """The named training set (:data:`TRAINING_SETS`); the chart patches, when in it, first."""
    if name not in TRAINING_SETS:
        raise unknown_name("training set", name, TRAINING_SETS)
    return TRAINING_SETS[name](chart_spectra)


# --------------------------------------------------------------------------------------------
# Reference and camera colours of reflectances
# --------------------------------------------------------------------------------------------


def reference_linear_srgb(reflectance: ArrayLike, illuminant: str = "D65",
                          cat: str = "Bradford") -> FloatArray:
    """Scene-consistent reference linear sRGB (..., 3) of reflectances (..., N) on the grid.

    Same convention as :func:`fidelity.colour.spectral.scene_reference`: XYZ under the illuminant
    (Y_white = 1), adapted by ``cat`` to the sRGB D65 white, IEC 61966-2-1 matrix; unclipped.
    """
    ill = load_illuminant(illuminant)
    xyz, white = tristimulus(reflectance, ill.on_grid())
    m = matrix_chromatic_adaptation(white, cm.WHITEPOINT_D65_XYZ, cat)
    return np.asarray(cm.xyz_to_linear_srgb(xyz @ m.T), dtype=np.float64)


@record
class CameraSamples:
    """Reference and camera colours of a reflectance set under one illuminant.

    ``reference_srgb`` (K, 3) encoded sRGB clipped to [0, 1] (what an 8-bit image holds);
    ``reference_linear`` (K, 3) unclipped linear sRGB (out-of-gamut colours keep components
    < 0 or > 1; the fit uses these, so that an exact camera fits to the identity);
    ``camera_linear`` (K, 3) the camera's linear signal after white balance and CCM, before the
    tone curve; ``camera_srgb`` (K, 3) the camera's output as encoded sRGB (clipped to [0, 1]);
    ``white_balance_gains`` (3,) and ``ccm`` (3, 3): the stages that make ``camera_linear``
    of the camera's raw signal, ``(raw * gains) @ ccm.T``, as metered and fitted on the chart
    (None: not recorded).
    """

    names: tuple[str, ...]
    reference_srgb: FloatArray
    reference_linear: FloatArray
    camera_linear: FloatArray
    camera_srgb: FloatArray
    white_balance_gains: FloatArray | None = None
    ccm: FloatArray | None = None


def camera_samples(camera: CameraModel, illuminant: str, reflectances: ReflectanceSet,
                   chart_spectra: str = "BabelColor Average") -> CameraSamples:
    """Noise-free camera output for every reflectance, metered and balanced on the chart.

    Exposure (auto metering), white balance (white-patch, grey-world) and the fitted CCM use the
    chart exactly as :func:`fidelity.camera.render.render_chart` does; vignetting and noise (spatial
    and random effects, not colour rendering) are left out.
    """
    ill = load_illuminant(illuminant)
    e, sens = ill.on_grid(), camera.sensitivities.on_grid()
    chart_raw = camera_response(load_patch_spectra(chart_spectra).on_grid(), e, sens, GRID_STEP_NM)
    gain = exposure_gain(camera.exposure, chart_raw)
    raw = camera_response(reflectances.reflectance, e, sens, GRID_STEP_NM) * gain
    dev = develop(camera, raw[None], chart_raw * gain, ill, spectra=chart_spectra)
    linear = (raw * dev.white_balance_gains) @ dev.ccm.T
    ref_lin = reference_linear_srgb(reflectances.reflectance, illuminant)
    ref = np.clip(np.asarray(delinearize_srgb(ref_lin), dtype=np.float64), 0.0, 1.0)
    return CameraSamples(reflectances.names, ref, ref_lin, linear, np.clip(dev.srgb[0], 0.0, 1.0),
                         np.asarray(dev.white_balance_gains, dtype=np.float64),
                         np.asarray(dev.ccm, dtype=np.float64))


def camera_output_srgb(camera: CameraModel, linear: ArrayLike) -> FloatArray:
    """The camera's output stage on its linear signal: tone curve, quantisation, then encoded
    sRGB clipped to [0, 1] (a linear-output camera is encoded with the sRGB curve)."""
    out = apply_tone_curve(linear, camera.tone)
    if camera.quantisation_bits is not None:
        out = quantise(out, camera.quantisation_bits)
    if camera.output_encoding == "linear":
        out = np.asarray(delinearize_srgb(out), dtype=np.float64)
    return np.clip(out, 0.0, 1.0)


# --------------------------------------------------------------------------------------------
# Root-polynomial regression
# --------------------------------------------------------------------------------------------


def root_polynomial_terms(rgb: ArrayLike) -> FloatArray:
    """Degree-2 root-polynomial expansion (..., 6): R, G, B, sqrt(RG), sqrt(GB), sqrt(RB).

    Finlayson et al. 2015, eq. 6; the same terms, order and sign convention as colour-science's
    ``polynomial_expansion_Finlayson2015(rgb, 2, root_polynomial_expansion=True)``: the root
    is sign-preserving, ``spow(x, 1/2) = sign(x) sqrt(|x|)`` (matters only for out-of-gamut
    training colours with negative components; image inputs are >= 0).
    """
    a = np.asarray(rgb, dtype=np.float64)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]

    def spow(x: FloatArray) -> FloatArray:
        return np.sign(x) * np.sqrt(np.abs(x))

    return np.stack([r, g, b, spow(r * g), spow(g * b), spow(r * b)], axis=-1)


def fit_root_polynomial(source: ArrayLike, target: ArrayLike) -> FloatArray:
    """Least-squares root-polynomial matrix (3, 6) mapping ``source`` (K, 3) to ``target``.

    Finlayson, Mackiewicz & Hurlbert 2015, degree 2: ``target.T @ pinv(terms(source).T)``
    with :func:`root_polynomial_terms`, the Moore-Penrose solution, as
    ``colour.characterisation.matrix_colour_correction(method="Finlayson 2015", degree=2,
    root_polynomial_expansion=True)`` computes it (tested equal). K must be >= 6.
    """
    s, t = np.asarray(source, float), np.asarray(target, float)
    if s.ndim != 2 or s.shape[1] != 3 or s.shape != t.shape or s.shape[0] < 6:
        raise InvalidValueError(f"root-polynomial fit needs matching (K >= 6, 3) arrays, got "
                                f"{s.shape} and {t.shape}")
    m = np.dot(np.transpose(t), np.linalg.pinv(np.transpose(root_polynomial_terms(s))))
    return np.asarray(m, dtype=np.float64).reshape(3, 6)


# --------------------------------------------------------------------------------------------
# Emulation
# --------------------------------------------------------------------------------------------


class EightBitTable:
    """The 8-bit path of a colour mapping: its :meth:`apply` on all 2^24 triples, tabulated
    once (:meth:`cube`), then any uint8 image mapped by lookup (:meth:`apply_uint8`). Mixed into
    :class:`Emulation` and :class:`PatchEmulation`, which hold the table in ``_cube``."""

    _cube: NDArray[np.uint8] | None
    _direct_colours: int

    def apply(self, srgb: ArrayLike) -> FloatArray:
        """Map encoded sRGB (..., 3) in [0, 1]; defined by the mapping."""
        raise NotImplementedError

    def cube(self, chunk: int = 1 << 20) -> NDArray[np.uint8]:
        """The (2^24, 3) uint8 table of :meth:`apply` on every 8-bit triple (built once)."""
        if self._cube is None:
            table = np.empty((1 << 24, 3), dtype=np.uint8)
            for s in range(0, 1 << 24, chunk):
                e = min(s + chunk, 1 << 24)
                table[s:e] = to_uint8(self.apply_codes(s, e) if hasattr(self, "apply_codes")
                                      else self.apply(all_triples(s, e)))
            self._cube = table
        return self._cube

    def apply_uint8(self, rgb8: ArrayLike) -> NDArray[np.uint8]:
        """Apply to an (H, W, 3) uint8 image; returns a new uint8 image.

        The first images are mapped on their distinct colours (:meth:`apply` on those codes,
        the entries :meth:`cube` would hold); once :data:`CUBE_AFTER_COLOURS` distinct colours
        have been mapped so (a sweep's worth of images), the full table is built and every later
        image is one look-up per pixel. A fit measured on a few images never pays for the
        16.7-million-entry table (about 4 s a mapping)."""
        a = np.asarray(rgb8)
        if a.dtype != np.uint8 or a.shape[-1] != 3:
            raise InvalidValueError(f"image must be (..., 3) uint8, got {a.shape} {a.dtype}")

        idx = colour_codes(a)
        if self._cube is None and self._direct_colours < CUBE_AFTER_COLOURS:
            codes, inverse = np.unique(idx.ravel(), return_inverse=True)
            self._direct_colours += int(codes.size)
            direct: NDArray[np.uint8] = self.map_codes(codes)[inverse].reshape(a.shape)
            return direct
        out: NDArray[np.uint8] = self.cube()[idx]
        return out

    def map_codes(self, codes: ArrayLike) -> NDArray[np.uint8]:
        """(N, 3) uint8: :meth:`apply` on the 24-bit codes ``codes`` ((N,) ``(r << 16) |
        (g << 8) | b``), rounded as :meth:`cube` rounds: the rows the table holds for them."""
        mapped: NDArray[np.uint8] = to_uint8(self.apply(code_triples(np.asarray(codes))))
        return mapped


#: Distinct colours mapped one image at a time before :meth:`EightBitTable.apply_uint8` builds
#: the full 2^24-entry table: a quarter of it (a 640 x 480 photo has 40k-180k distinct colours,
#: so a run of more than about 30 images builds the table, a fit's few images do not).
CUBE_AFTER_COLOURS = 1 << 22


@dataclass
class Emulation(EightBitTable):
    """A fitted colour mapping reference sRGB -> camera output sRGB (see module docstring)."""

    camera: CameraModel
    illuminant: str
    method: str
    training: str
    matrix: FloatArray
    lut: FloatArray | None
    samples: CameraSamples
    fit_seconds: float
    _cube: NDArray[np.uint8] | None = field(default=None, repr=False)
    _direct_colours: int = field(default=0, repr=False, compare=False)

    # float path -------------------------------------------------------------------------------
    def _root_poly(self, srgb: FloatArray) -> FloatArray:
        """Root-polynomial part + camera output stage, without quantisation for the LUT."""
        lin = linearize_srgb(np.clip(srgb, 0.0, 1.0))
        return root_polynomial_terms(lin) @ self.matrix.T

    def apply_codes(self, start: int, stop: int) -> FloatArray:
        """:meth:`apply` on the 8-bit triples with 24-bit codes ``start`` to ``stop - 1``
        (:func:`fidelity.coco.dataset.all_triples`), the rows of :meth:`cube`. For the
        root-polynomial mapping the per-channel steps are looked up: each channel's
        linearisation and each pair's root term take only 256 and 256 x 256 values, computed
        with the same operations as :meth:`apply` (so the same bits), the 3 x 6 matrix and the
        output stage then run on the chunk as :meth:`apply` runs them."""
        if self.method != "root-polynomial":
            return self.apply(all_triples(start, stop))

        lin = linearize_srgb(np.clip(np.arange(256, dtype=np.float64) / 255.0, 0.0, 1.0))
        pair = lin[:, None] * lin[None, :]
        root = np.sign(pair) * np.sqrt(np.abs(pair))  # spow of root_polynomial_terms
        idx = np.arange(start, stop, dtype=np.uint32)
        r, g, b = (idx >> 16) & 255, (idx >> 8) & 255, idx & 255
        terms = np.empty((stop - start, 6), dtype=np.float64)
        terms[:, 0], terms[:, 1], terms[:, 2] = lin[r], lin[g], lin[b]
        terms[:, 3], terms[:, 4], terms[:, 5] = root[r, g], root[g, b], root[r, b]
        return camera_output_srgb(self.camera, terms @ self.matrix.T)

    def apply(self, srgb: ArrayLike) -> FloatArray:
        """Map encoded reference sRGB (..., 3) in [0, 1] to the camera's encoded output sRGB."""
        x = np.asarray(srgb, dtype=np.float64)
        if x.shape[-1] != 3:
            raise InvalidValueError(f"colours must be (..., 3), got {x.shape}")
        if self.method == "root-polynomial":
            return camera_output_srgb(self.camera, self._root_poly(x))
        assert self.lut is not None
        out = _trilinear(self.lut, np.clip(x, 0.0, 1.0))
        if self.camera.quantisation_bits is not None:
            out = quantise(out, self.camera.quantisation_bits)
        return np.clip(out, 0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """JSON-ready description: method, training set, matrix, sizes, fit time."""
        return {"method": self.method, "training": self.training,
                "training_colours": len(self.samples.names), "illuminant": self.illuminant,
                "root_polynomial_matrix": self.matrix.round(6).tolist(),
                "lut_size": None if self.lut is None else int(self.lut.shape[0]),
                "fit_seconds": self.fit_seconds}


def _trilinear(lut: FloatArray, x: FloatArray) -> FloatArray:
    """Trilinear interpolation of an (n, n, n, 3) LUT on [0, 1]^3 at x (..., 3)."""
    n = lut.shape[0]
    p = x * (n - 1)
    i0 = np.clip(np.floor(p).astype(np.int64), 0, n - 2)
    f = p - i0
    out = np.zeros(x.shape, dtype=np.float64)
    for dr in (0, 1):
        wr = f[..., 0] if dr else 1 - f[..., 0]
        for dg in (0, 1):
            wg = f[..., 1] if dg else 1 - f[..., 1]
            for db in (0, 1):
                wb = f[..., 2] if db else 1 - f[..., 2]
                out += (wr * wg * wb)[..., None] * lut[i0[..., 0] + dr, i0[..., 1] + dg,
                                                       i0[..., 2] + db]
    return out


def _fit_lut3d(emu: Emulation) -> FloatArray:
    """33^3 LUT: root-polynomial output + Gaussian-RBF residuals at the training colours."""
    from scipy.interpolate import RBFInterpolator

    s = emu.samples
    base = camera_output_srgb_noquant(emu.camera, emu._root_poly(s.reference_srgb))
    rbf = RBFInterpolator(s.reference_srgb, s.camera_srgb - base, kernel="gaussian",
                          epsilon=1.0 / LUT_RBF_WIDTH, smoothing=LUT_RBF_SMOOTHING, degree=-1)
    g = np.linspace(0.0, 1.0, LUT_SIZE)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    lut: FloatArray = camera_output_srgb_noquant(emu.camera, emu._root_poly(grid)) + rbf(grid)
    return np.clip(lut, 0.0, 1.0).reshape(LUT_SIZE, LUT_SIZE, LUT_SIZE, 3)


def camera_output_srgb_noquant(camera: CameraModel, linear: ArrayLike) -> FloatArray:
    """:func:`camera_output_srgb` without the quantisation stage (for LUT building)."""
    return camera_output_srgb(replace(camera, quantisation_bits=None), linear)


#: Emulation methods (module docstring).
EMULATION_METHODS: tuple[str, ...] = ("root-polynomial", "lut3d")


def fit_emulation(camera: CameraModel | str | Path, illuminant: str = "D65",
                  method: str = "root-polynomial", training: str = "colour-science",
                  chart_spectra: str = "BabelColor Average") -> Emulation:
    """Fit the colour mapping of ``camera`` (a model, a built-in name or a camera file) under
    ``illuminant`` (module docstring).

    ``method`` in :data:`EMULATION_METHODS`; ``training`` in :data:`TRAINING_SETS`.
    """
    if method not in EMULATION_METHODS:
        raise unknown_name("emulation method", method, EMULATION_METHODS)
    t0 = time.perf_counter()
    cam = camera if isinstance(camera, CameraModel) else load_camera(camera)
    refl = training_reflectances(training, chart_spectra)
    samples = camera_samples(cam, illuminant, refl, chart_spectra)
    matrix = fit_root_polynomial(samples.reference_linear, samples.camera_linear)
    emu = Emulation(cam, illuminant, method, training, matrix, None, samples, 0.0)
    if method == "lut3d":
        emu.lut = _fit_lut3d(emu)
    emu.fit_seconds = time.perf_counter() - t0
    return emu


@record
class EmulationAccuracy:
    """How well an emulation reproduces the camera (CIEDE2000, see :func:`emulation_accuracy`).

    ``chart_delta_e`` (24,): ΔE00 between the emulated chart (8-bit reference chart through the
    256^3 table) and the camera's rendered chart, per patch; ``training_delta_e`` (K,): the same
    on every training colour (float path); ``camera_chart_delta_e`` and
    ``emulated_chart_delta_e``: the chart ΔE (mean ΔE00 against the scene reference) of the
    camera and of the emulated chart.
    """

    patch_names: tuple[str, ...]
    chart_delta_e: FloatArray
    training_delta_e: FloatArray
    camera_chart_delta_e: float
    emulated_chart_delta_e: float

    def summary(self) -> AccuracySummary:
        """The summary the validation keeps: means, maxima and per-patch values."""
        return AccuracySummary(
            chart_mean_delta_e=float(self.chart_delta_e.mean()),
            chart_max_delta_e=float(self.chart_delta_e.max()),
            chart_worst_patch=self.patch_names[int(np.argmax(self.chart_delta_e))],
            training_mean_delta_e=float(self.training_delta_e.mean()),
            training_p95_delta_e=float(np.percentile(self.training_delta_e, 95)),
            training_colours=int(self.training_delta_e.size),
            camera_chart_delta_e=self.camera_chart_delta_e,
            emulated_chart_delta_e=self.emulated_chart_delta_e,
            patches={n: float(d) for n, d in zip(self.patch_names, self.chart_delta_e,
                                                 strict=True)},
        )

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary with per-patch values (:meth:`summary` as JSON)."""
        return self.summary().to_json()


@record
class AccuracySummary:
    """The accuracy of an emulation as the validation stores it (ΔE00, see
    :class:`EmulationAccuracy`): chart mean, maximum and worst patch (emulated against the
    camera's chart), training-set mean and 95th percentile over ``training_colours`` colours,
    the chart ΔE of the camera and of the emulated chart, and ΔE00 per patch."""

    chart_mean_delta_e: float
    chart_max_delta_e: float
    chart_worst_patch: str
    training_mean_delta_e: float
    training_p95_delta_e: float
    training_colours: int
    camera_chart_delta_e: float
    emulated_chart_delta_e: float
    patches: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        """The summary as JSON (field names as keys, in field order)."""
        return {"chart_mean_delta_e": self.chart_mean_delta_e,
                "chart_max_delta_e": self.chart_max_delta_e,
                "chart_worst_patch": self.chart_worst_patch,
                "training_mean_delta_e": self.training_mean_delta_e,
                "training_p95_delta_e": self.training_p95_delta_e,
                "training_colours": self.training_colours,
                "camera_chart_delta_e": self.camera_chart_delta_e,
                "emulated_chart_delta_e": self.emulated_chart_delta_e,
                "patches": self.patches}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> AccuracySummary:
        """Inverse of :meth:`to_json`."""
        return cls(d["chart_mean_delta_e"], d["chart_max_delta_e"], d["chart_worst_patch"],
                   d["training_mean_delta_e"], d["training_p95_delta_e"],
                   int(d["training_colours"]), d["camera_chart_delta_e"],
                   d["emulated_chart_delta_e"], dict(d.get("patches") or {}))


def emulation_accuracy(emu: Emulation, chart_spectra: str = "BabelColor Average"
                       ) -> EmulationAccuracy:
    """Check the emulation against the camera's own rendered chart (module docstring)."""
    render = render_chart(emu.camera, emu.illuminant, spectra=chart_spectra)
    cam_srgb = np.clip(render.measurement.srgb, 0.0, 1.0)
    ref = scene_reference(emu.illuminant, chart_spectra)
    # the 8-bit chart through the 8-bit path; apply() on code/255 rounded by to_uint8 is what
    # every entry of cube() holds, so this equals apply_uint8 without building the table
    chart8 = to_uint8(ref.srgb)
    emulated = to_uint8(emu.apply(chart8.astype(np.float64) / 255.0)).astype(np.float64) / 255.0
    d_chart = delta_e_2000(srgb_to_lab(emulated), srgb_to_lab(cam_srgb))
    d_train = delta_e_2000(srgb_to_lab(emu.apply(emu.samples.reference_srgb)),
                           srgb_to_lab(emu.samples.camera_srgb))
    emulated_de = float(delta_e_2000(srgb_to_lab(emulated), ref.lab).mean())
    return EmulationAccuracy(tuple(ref.patch_names), np.asarray(d_chart, dtype=np.float64),
                             np.asarray(d_train, dtype=np.float64),
                             float(render.measurement.mean_delta_e), emulated_de)


__all__ = [
    "EMULATION_METHODS",
    "EMULATION_VERSION",
    "LUT_SIZE",
    "TRAINING_SETS",
    "AccuracySummary",
    "CameraSamples",
    "EightBitTable",
    "Emulation",
    "EmulationAccuracy",
    "PatchEmulation",
    "ReflectanceSet",
    "apply_log_tone",
    "camera_output_srgb",
    "camera_samples",
    "emulation_accuracy",
    "emulation_key",
    "fit_emulation",
    "fit_root_polynomial",
    "reference_linear_srgb",
    "root_polynomial_terms",
    "training_reflectances",
]


# --------------------------------------------------------------------------------------------
# Emulation fitted from measured chart patches (an audited image, a sim-to-real comparison)
# --------------------------------------------------------------------------------------------


def _log_tone_curve(source_y: ArrayLike, target_y: ArrayLike
                    ) -> tuple[FloatArray, FloatArray]:
    """Knots (log Y_source, log Y_target) of a monotone tone curve through neutral patches,
    sorted, with repeated or non-increasing points dropped."""
    s = np.log(np.clip(np.asarray(source_y, float), 1e-6, None))
    t = np.log(np.clip(np.asarray(target_y, float), 1e-6, None))
    order = np.argsort(s)
    s, t = s[order], t[order]
    keep = [0]
    for k in range(1, len(s)):
        if s[k] > s[keep[-1]] + 1e-9 and t[k] > t[keep[-1]]:
            keep.append(k)
    return s[keep], t[keep]


def apply_log_tone(y: ArrayLike, knots: tuple[FloatArray, FloatArray]) -> FloatArray:
    """The tone curve of :func:`_log_tone_curve` on luminances ``y`` (>= 0): piecewise linear
    in log-log between the knots, continued with the end segments' slopes (a power law, the
    local gamma) beyond them; 0 stays 0."""
    xs, ts = knots
    yy = np.asarray(y, float)
    out = np.zeros_like(yy)
    pos = yy > 0
    if len(xs) < 2:
        shift = float(ts[0] - xs[0]) if len(xs) else 0.0
        out[pos] = yy[pos] * math.exp(shift)
        return out
    ly = np.log(yy[pos])
    lo_slope = (ts[1] - ts[0]) / (xs[1] - xs[0])
    hi_slope = (ts[-1] - ts[-2]) / (xs[-1] - xs[-2])
    v = np.interp(ly, xs, ts)
    v = np.where(ly < xs[0], ts[0] + lo_slope * (ly - xs[0]), v)
    v = np.where(ly > xs[-1], ts[-1] + hi_slope * (ly - xs[-1]), v)
    out[pos] = np.exp(v)
    return out


@dataclass
class PatchEmulation(EightBitTable):
    """A colour mapping fitted on measured chart patches alone: from ``source`` colours (the
    chart's reference, or one camera's chart) to ``target`` colours (the measured chart, or
    another camera's), both encoded sRGB (n, 3).

    ``out = encode(clip(P(tone(linearize(x)))))``: ``tone`` scales each colour's linear RGB
    so that its luminance follows the neutral patches' tone curve (target against source
    luminance, piecewise linear on log-log axes, continued with the end slopes);
    ``P`` is a degree-2 root-polynomial (:func:`fit_root_polynomial`, Finlayson et al. 2015)
    fitted by least squares from the toned source to the target in linear light on all
    patches. A target equal to the source gives the identity (up to rounding). 8-bit images go
    through a 256^3 table (:meth:`apply_uint8`), as :class:`Emulation` does.
    """

    source_srgb: FloatArray
    target_srgb: FloatArray
    neutral: tuple[int, ...]
    knots: tuple[FloatArray, FloatArray]
    matrix: FloatArray
    fit_seconds: float = 0.0
    _cube: NDArray[np.uint8] | None = field(default=None, repr=False)
    _direct_colours: int = field(default=0, repr=False, compare=False)

    @classmethod
    def fit(cls, source_srgb: ArrayLike, target_srgb: ArrayLike,
            neutral: tuple[int, ...]) -> PatchEmulation:
        """Fit the mapping from ``source_srgb`` to ``target_srgb`` (n >= 6 patches; the
        ``neutral`` indices carry the tone curve)."""
        t0 = time.perf_counter()
        src = np.clip(np.asarray(source_srgb, float), 0.0, 1.0)
        dst = np.clip(np.asarray(target_srgb, float), 0.0, 1.0)
        if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 6:
            raise InvalidValueError(f"patch emulation needs matching (n >= 6, 3) colours, got "
                                    f"{src.shape} and {dst.shape}")
        ls = np.asarray(linearize_srgb(src), np.float64)
        lt = np.asarray(linearize_srgb(dst), np.float64)
        idx = list(neutral)
        knots = _log_tone_curve(luminance_linear_srgb(ls[idx]), luminance_linear_srgb(lt[idx]))
        toned = _tone_rgb(ls, knots)
        matrix = fit_root_polynomial(toned, lt)
        return cls(src, dst, tuple(int(i) for i in neutral), knots, matrix,
                   time.perf_counter() - t0)

    def apply(self, srgb: ArrayLike) -> FloatArray:
        """Map encoded sRGB (..., 3) in [0, 1] to the target's encoded sRGB, clipped."""
        x = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
        lin = _tone_rgb(np.asarray(linearize_srgb(x), np.float64), self.knots)
        out = root_polynomial_terms(lin) @ self.matrix.T
        return np.clip(np.asarray(delinearize_srgb(np.clip(out, 0.0, 1.0)), np.float64), 0, 1)

    def patch_delta_e(self) -> FloatArray:
        """ΔE00 per patch between the mapped source and the target (the in-sample fit error)."""
        return np.asarray(delta_e_2000(srgb_to_lab(self.apply(self.source_srgb)),
                                       srgb_to_lab(self.target_srgb)), np.float64)

    def key(self) -> str:
        """A key that changes with the mapping (for the measurement store)."""
        h = hashlib.sha256()
        for a in (self.matrix, self.knots[0], self.knots[1]):
            h.update(np.ascontiguousarray(np.round(a, 12)).tobytes())
        h.update(f"patch-emulation-v{EMULATION_VERSION}".encode())
        return f"patch-emulation:{h.hexdigest()[:20]}"

    def describe(self) -> dict[str, Any]:
        """JSON-ready: the method, the patches, the tone knots, the matrix and the fit."""
        d = self.patch_delta_e()
        return {"method": "patch root-polynomial + neutral tone curve",
                "patches": len(self.source_srgb), "neutral": list(self.neutral),
                "tone_knots_log_y": [self.knots[0].round(6).tolist(),
                                     self.knots[1].round(6).tolist()],
                "root_polynomial_matrix": self.matrix.round(6).tolist(),
                "fit_mean_delta_e": float(d.mean()), "fit_max_delta_e": float(d.max()),
                "fit_seconds": self.fit_seconds}


def _tone_rgb(linear: FloatArray, knots: tuple[FloatArray, FloatArray]) -> FloatArray:
    """Scale linear RGB (..., 3) so that its luminance follows the tone curve."""
    lin = np.asarray(linear, float)
    y = np.asarray(luminance_linear_srgb(lin), float)
    ty = apply_log_tone(np.clip(y, 0.0, None), knots)
    scale = np.divide(ty, y, out=np.ones_like(y), where=y > 1e-9)
    out: FloatArray = lin * scale[..., None]
    return out


def emulation_key(emu: Emulation) -> str:
    """A key that changes with a camera emulation's mapping (for the measurement store): the
    fitted matrix, LUT, output stage (tone, quantisation, encoding) and
    :data:`EMULATION_VERSION`."""
    cam = emu.camera
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.round(emu.matrix, 12)).tobytes())
    if emu.lut is not None:
        h.update(np.ascontiguousarray(np.round(emu.lut, 9)).tobytes())
    h.update(json.dumps({"tone": repr(cam.tone), "bits": cam.quantisation_bits,
                         "encoding": cam.output_encoding, "method": emu.method,
                         "version": EMULATION_VERSION}, sort_keys=True).encode())
    return f"camera-emulation:{cam.name}:{h.hexdigest()[:20]}"
