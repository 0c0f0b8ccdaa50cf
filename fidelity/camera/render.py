"""Render the spectral Macbeth chart through a camera model and measure it.

Two renderers give one result (:data:`RENDERERS`):

- ``"closed-form"`` (default, the ground truth): per patch the Riemann sum
  ``sum R E S dl / sum E ybar dl`` (:func:`fidelity.camera.model.camera_response`), painted into a
  chart image. A flat Lambertian chart under uniform light needs nothing more.
- ``"mitsuba"``: Mitsuba 3 renders the same chart spectrally
  (:mod:`fidelity.camera.mitsuba`), in the same units.

Both images then go through the same camera pipeline in numpy (exposure, vignetting, the
lens's point-spread function (:mod:`fidelity.camera.optics`, in linear light), noise, white
balance, CCM, tone curve, quantisation; :mod:`fidelity.camera.model`) and the same patch
sampling (:func:`patch_means`): the central window (half the patch side) of each patch,
averaged with a 10 % trimmed mean per channel (robust to hot pixels and Monte Carlo
fireflies), with the per-patch standard deviation of the window reported as noise.

Reference (``reference=``): ``"scene"`` (default) is the scene-consistent reference of
:func:`fidelity.colour.spectral.scene_reference`; ``"safecolor"`` is the SAFE-COLOR Lab table (old
D50-era chart data, about 2 ΔE00 from a correct D65 render; offered for comparison only).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.camera.model import (
    CameraModel,
    add_sensor_noise,
    camera_response,
    develop,
    exposure_gain,
    load_camera,
    vignetting_gain,
    white_balance_gains,
)
from fidelity.chart.turned import (
    CALIBRATION_GEOMETRY,
    CHECK_EDGE_TARGET,
    PaintedEdgeTarget,
    TurnedChart,
)
from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import linearize_srgb
from fidelity.colour.spectral import (
    GRID_STEP_NM,
    load_illuminant,
    load_patch_spectra,
    scene_reference,
)
from fidelity.core.errors import FidelityError, InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.measure import uncertainty as unc
from fidelity.measure.chartnoise import ChartNoise
from fidelity.measure.chartsharpness import ChartSharpness, painted_target_sharpness
from fidelity.measure.colour import ChartMeasurement, measure_chart
from fidelity.measure.pixels import measure_pixels
from fidelity.measure.uncertainty import UncertaintyBudget

FloatArray = NDArray[np.float64]

RENDERERS: tuple[str, ...] = ("closed-form", "mitsuba")
#: Reflectance of the turned chart's frame (:class:`FrameRender`): flat, 3 % (the calibration
#: chart's frame is linear 0.03).
FRAME_REFLECTANCE = 0.03
REFERENCES: tuple[str, ...] = ("scene", "safecolor")

#: Pixels per patch side of the closed-form image (its values are exact at any size).
CLOSED_FORM_PIXELS_PER_PATCH: int = 32
#: Fraction of the patch side used as the central sampling window.
WINDOW_FRACTION: float = 0.5
#: Proportion cut from each end of the sorted window values (per channel) by the robust mean.
TRIM_PROPORTION: float = 0.1


@record
class ChartLayout:
    """Pixel layout of a rows x cols chart: square patches of ``patch_px`` separated and
    framed by ``gap_px`` of black background. Patch i is row-major (i = row * cols + col)."""

    patch_px: int
    gap_px: int
    rows: int = 4
    cols: int = 6

    @classmethod
    def for_patch_size(cls, patch_px: int) -> ChartLayout:
        """Layout with gaps of a quarter patch (at least 1 px)."""
        if patch_px < 2:
            raise InvalidValueError(f"pixels per patch must be >= 2, got {patch_px}")
        return cls(int(patch_px), max(1, int(patch_px) // 4))

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return self.cols * self.patch_px + (self.cols + 1) * self.gap_px

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return self.rows * self.patch_px + (self.rows + 1) * self.gap_px

    def patch_box(self, i: int) -> tuple[int, int, int, int]:
        """(y0, y1, x0, x1), half-open pixel bounds of patch ``i``."""
        r, c = divmod(i, self.cols)
        y0 = self.gap_px + r * (self.patch_px + self.gap_px)
        x0 = self.gap_px + c * (self.patch_px + self.gap_px)
        return y0, y0 + self.patch_px, x0, x0 + self.patch_px

    def window(self, i: int, fraction: float = WINDOW_FRACTION) -> tuple[int, int, int, int]:
        """Central window of patch ``i`` (side = max(1, round(fraction * patch_px)))."""
        y0, _, x0, _ = self.patch_box(i)
        side = max(1, round(fraction * self.patch_px))
        off = (self.patch_px - side) // 2
        return y0 + off, y0 + off + side, x0 + off, x0 + off + side

    def paint(self, values: ArrayLike, background: float = 0.0) -> FloatArray:
        """Image (H, W, C) with each patch filled with ``values[i]`` (24, C)."""
        v = np.asarray(values, dtype=np.float64)
        img = np.full((self.height, self.width, v.shape[1]), background, dtype=np.float64)
        for i in range(self.rows * self.cols):
            y0, y1, x0, x1 = self.patch_box(i)
            img[y0:y1, x0:x1] = v[i]
        return img


def trimmed_mean(values: ArrayLike, proportion: float) -> FloatArray:
    """Mean along axis 0 of (N, C) ``values`` after cutting ``int(proportion * N)`` values at
    each end of every column.

    The same steps as ``scipy.stats.trim_mean(values, proportion, axis=0)`` (the same
    ``np.partition`` and mean, so the same bits) without importing scipy.stats (about 0.3 s at
    start-up). ``proportion`` in [0, 0.5).
    """
    a = np.asarray(values, dtype=np.float64)
    if not 0.0 <= proportion < 0.5:
        raise ValueError(f"trim proportion {proportion} outside [0, 0.5)")
    low = int(proportion * a.shape[0])
    high = a.shape[0] - low
    part = np.partition(a, (low, high - 1), axis=0)
    out: FloatArray = np.mean(part[low:high], axis=0)
    return out


def patch_means(
    image: ArrayLike, layout: ChartLayout, fraction: float = WINDOW_FRACTION,
    trim: float = TRIM_PROPORTION,
) -> tuple[FloatArray, FloatArray]:
    """Robust patch means and standard deviations, each (24, C), from central windows.

    Mean: per-channel trimmed mean cutting ``trim`` of the values at each end
    (:func:`trimmed_mean`). Std: sample standard deviation (ddof = 1; 0 for a 1-pixel window).
    """
    img = np.asarray(image, dtype=np.float64)
    n = layout.rows * layout.cols
    means = np.empty((n, img.shape[-1]))
    stds = np.empty((n, img.shape[-1]))
    for i in range(n):
        y0, y1, x0, x1 = layout.window(i, fraction)
        px = img[y0:y1, x0:x1].reshape(-1, img.shape[-1])
        means[i] = trimmed_mean(px, trim)
        stds[i] = px.std(axis=0, ddof=1) if px.shape[0] > 1 else 0.0
    return means, stds


@record
class FrameRender:
    """The chart turned on the pixel grid (:class:`fidelity.chart.turned.TurnedChart`) and
    rendered through the camera, for the sharpness and noise measurements.

    The camera's raw patch values (closed form, whatever the chart's renderer) are painted on
    ``geometry`` with a flat :data:`FRAME_REFLECTANCE` frame, then go through the same stages
    as the chart: exposure gain, vignetting, optics, sensor noise, and development with the
    chart's white-balance gains and colour correction matrix. ``srgb``: ``(H, W, 3)`` encoded
    sRGB (unclipped for a linear-output camera, as :func:`fidelity.camera.model.develop`
    gives it); ``corners``: the ``(4, 2)`` image centres of the dark skin, bluish green, black
    and white patches.

    Beside it, the ISO 12233 slanted-edge target (``target``,
    :data:`fidelity.chart.turned.CHECK_EDGE_TARGET`: a 0.2 square turned 5 degrees on a 0.8
    field, spectrally flat) through the same stages: ``target_srgb`` ``(H, W, 3)`` encoded
    sRGB, painted in closed form (``target_renderer`` ``closed-form``) or rendered by Mitsuba
    where the chart was (``mitsuba``); None where not rendered.
    """

    srgb: FloatArray
    corners: FloatArray
    geometry: TurnedChart
    target_srgb: FloatArray | None = None
    target: PaintedEdgeTarget | None = None
    target_renderer: str = "closed-form"


@record
class ChartRender:
    """A rendered and measured chart (see :func:`render_chart`).

    Attributes
    ----------
    measurement
        The chart's ΔE00 per patch against the reference (:class:`ChartMeasurement`).
    linear_image
        The raw camera image after exposure, vignetting, optics and noise, float32, shape
        (H, W, 3), in camera raw units (the ideal camera gives linear sRGB, Y(perfect white) = 1).
    display_image
        The developed image as encoded sRGB clipped to [0, 1], float32, shape (H, W, 3).
    renderer
        The renderer used, one of :data:`RENDERERS`.
    variant
        The Mitsuba variant rendered with; None for the closed form.
    seconds
        Wall-clock seconds of the whole :func:`render_chart` call, >= 0.
    conventions
        JSON-ready description of the reference, spectral grid, units, exposure gain,
        white-balance gains, CCM, encoding, clipping, patch sampling and layout.
    camera
        The camera model rendered.
    camera_rgb
        Raw patch means (trimmed, central window), shape (24, 3), camera raw units.
    camera_noise
        Standard deviation of each raw patch window, shape (24, 3), camera raw units.
    settings
        Illuminant, reflectance set, reference, seed, renderer, pixels per patch, image size
        ``[H, W]`` and Mitsuba samples per pixel (None for the closed form).
    uncertainty
        The standard uncertainty budget of the chart ΔE (:func:`render_uncertainty`); None
        when not computed.
    frame
        The chart turned on the pixel grid through the same camera, for sharpness and noise
        (:class:`FrameRender`); None when not asked for (``render_chart(frame=False)``).
    """

    measurement: ChartMeasurement
    linear_image: NDArray[np.float32]
    display_image: NDArray[np.float32]
    renderer: str
    variant: str | None
    seconds: float
    conventions: dict[str, Any]
    camera: CameraModel
    camera_rgb: FloatArray
    camera_noise: FloatArray
    settings: dict[str, Any] = field(default_factory=dict)
    #: the standard uncertainty of the chart ΔE (:func:`render_uncertainty`)
    uncertainty: UncertaintyBudget | None = None
    #: the chart turned on the pixel grid through the same camera, for sharpness and noise
    #: (:class:`FrameRender`; None when not asked for)
    frame: FrameRender | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON-ready result: ΔE summary, renderer, variant, seconds, conventions, patches."""
        m = self.measurement.to_json()
        for i, p in enumerate(m["patches"]):
            p["camera_rgb"] = [float(v) for v in self.camera_rgb[i]]
            p["camera_rgb_noise"] = [float(v) for v in self.camera_noise[i]]
        return {
            "mean_delta_e": m["mean_delta_e"],
            "max_delta_e": m["max_delta_e"],
            "worst_patch": m.get("worst_patch"),
            "renderer": self.renderer,
            "variant": self.variant,
            "seconds": self.seconds,
            "camera": self.camera.to_json(),
            "settings": self.settings,
            "conventions": self.conventions,
            "patches": m["patches"],
        }


#: Accepted spectral grid steps, nm (the grid spans 380-780 nm: 4001 to 21 samples).
STEP_RANGE_NM: tuple[float, float] = (0.1, 20.0)
#: Largest patch side in pixels (a 6 x 4 chart of 512 px patches is 3.7k x 2.5k pixels).
MAX_PIXELS_PER_PATCH: int = 512
#: Most Mitsuba samples per pixel (the benchmarked default is 144).
MAX_SPP: int = 1 << 20
#: Largest seed (numpy's generators take any non-negative integer; 64 bits is plenty).
MAX_SEED: int = 2**63 - 1


def check_render_settings(*, step: float = GRID_STEP_NM, pixels_per_patch: int | None = None,
                          spp: int | None = None, seed: int | None = None) -> None:
    """Refuse render settings outside their domain (:data:`STEP_RANGE_NM`,
    :data:`MAX_PIXELS_PER_PATCH`, :data:`MAX_SPP`, :data:`MAX_SEED`) with an
    :class:`~fidelity.core.errors.InvalidValueError` naming the option."""
    lo, hi = STEP_RANGE_NM
    if not (isinstance(step, int | float) and math.isfinite(step) and lo <= step <= hi):
        raise InvalidValueError(f"--step {step!r}: the spectral step must be between {lo:g} "
                                f"and {hi:g} nm and divide 400 nm (e.g. 1, 2, 5, 10)")
    if pixels_per_patch is not None and not 2 <= pixels_per_patch <= MAX_PIXELS_PER_PATCH:
        raise InvalidValueError(f"--pixels-per-patch {pixels_per_patch}: must be between 2 and "
                                f"{MAX_PIXELS_PER_PATCH}")
    if spp is not None and not 1 <= spp <= MAX_SPP:
        raise InvalidValueError(f"--spp {spp}: must be between 1 and {MAX_SPP}")
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise InvalidValueError(f"--seed {seed}: must be between 0 and {MAX_SEED}")


def camera_context(camera: CameraModel, message: str) -> str:
    """``message`` prefixed with the camera it concerns (``camera file <path>`` for a camera
    file, ``camera <name>`` for a built-in one), unless it names it already."""
    if camera.source in message:
        return message
    where = (f"camera {camera.name}" if camera.source.startswith("built-in")
             else f"camera file {camera.source}")
    return f"{where}: {message}"


@contextlib.contextmanager
def _about(camera: CameraModel) -> Iterator[None]:
    """Errors raised inside name the camera (:func:`camera_context`)."""
    try:
        yield
    except FidelityError as exc:
        raise type(exc)(camera_context(camera, str(exc))) from None


def _require_finite(values: np.ndarray, what: str) -> None:
    if not np.all(np.isfinite(values)):
        raise InvalidValueError(f"{what} is not finite (a value beyond the floating-point "
                                "range): check the camera's gains, matrix and noise")


def render_chart(
    camera: CameraModel | str,
    illuminant: str = "D65",
    renderer: str = "closed-form",
    *,
    spp: int | None = None,
    reference: str = "scene",
    spectra: str = "BabelColor Average",
    seed: int | None = None,
    pixels_per_patch: int | None = None,
    cat: str = "Bradford",
    step: float = GRID_STEP_NM,
    variant: str | None = None,
    sampler: str | None = None,
    frame: bool = False,
) -> ChartRender:
    """Render the spectral chart through ``camera`` under ``illuminant`` and measure ΔE00.

    ``renderer`` in :data:`RENDERERS`; ``spp`` (Mitsuba samples per pixel, default
    :data:`fidelity.camera.mitsuba.DEFAULT_SPP`); ``reference`` in :data:`REFERENCES`;
    ``spectra`` a reflectance set; ``seed`` overrides the camera's noise seed (Mitsuba's sampler
    uses it too, default 0); ``pixels_per_patch`` the patch side in pixels; ``cat`` the
    chromatic adaptation of the scene reference; ``step`` the spectral grid step (nm);
    ``variant`` forces a Mitsuba variant (else probed); ``sampler`` a Mitsuba sampler (default
    from the scene template). ``seconds`` covers the whole call.

    Parameters
    ----------
    camera
        A camera model, or a built-in camera name or camera file
        (:func:`fidelity.camera.model.load_camera`).
    illuminant
        Scene illuminant: a name (``D65``, ``D50``, ``A``, ``F2``, ``F11``, ``LED``, or a
        ``colour.SDS_ILLUMINANTS`` key) or an SPD file
        (:func:`fidelity.colour.spectral.load_illuminant`).
    renderer
        ``closed-form`` (default) or ``mitsuba`` (:data:`RENDERERS`).
    spp
        Mitsuba samples per pixel, in [1, :data:`MAX_SPP`]; None:
        :data:`fidelity.camera.mitsuba.DEFAULT_SPP` (144). Only Mitsuba reads it.
    reference
        ``scene`` (default: the chart's spectra under ``illuminant``, adapted to D65) or
        ``safecolor`` (the paper's Lab table) (:data:`REFERENCES`).
    spectra
        The patch reflectance set: ``BabelColor Average`` (default), ``ColorChecker N Ohta``
        or a JSON file (:func:`fidelity.colour.spectral.load_patch_spectra`).
    seed
        Seed of the sensor noise, in [0, :data:`MAX_SEED`], overriding the camera's own;
        Mitsuba's sampler uses it too (None: 0).
    pixels_per_patch
        Patch side in pixels, in [2, :data:`MAX_PIXELS_PER_PATCH`]; None:
        :data:`CLOSED_FORM_PIXELS_PER_PATCH` (closed form) or
        :data:`fidelity.camera.mitsuba.DEFAULT_PIXELS_PER_PATCH` (Mitsuba), 32 each.
    cat
        Chromatic adaptation transform of the scene reference to D65 (``Bradford``, or another
        of :data:`fidelity.colour.colorimetry.CHROMATIC_ADAPTATION_METHODS`).
    step
        Spectral grid step in nm, in :data:`STEP_RANGE_NM` ([0.1, 20]), dividing 400 nm.
    variant
        Mitsuba variant to use; None: probed. Only Mitsuba reads it.
    sampler
        Mitsuba sampler plugin; None: the scene template's. Only Mitsuba reads it.
    frame
        Also render the chart turned on the pixel grid through the same camera
        (:class:`FrameRender`, :data:`fidelity.chart.turned.CALIBRATION_GEOMETRY`), for the
        sharpness and noise measurements.

    Returns
    -------
    ChartRender
        The raw and display images, the chart measurement (ΔE00 per patch), the raw patch
        means, the settings and conventions, and the ΔE's uncertainty budget.

    Raises
    ------
    UnknownNameError
        An unknown renderer, reference, camera, illuminant, reflectance set or adaptation
        transform. Exit code 2.
    InvalidValueError
        A setting outside its domain (``step``, ``pixels_per_patch``, ``spp``, ``seed``), or a
        camera whose stages give non-finite values; the message names the camera. Exit code 2.
    InputFileError
        A camera, illuminant or spectra file that is missing or invalid. Exit code 2.
    """
    t0 = time.perf_counter()
    if renderer not in RENDERERS:
        raise unknown_name("renderer", renderer, RENDERERS)
    if reference not in REFERENCES:
        raise unknown_name("reference", reference, REFERENCES)
    cam = load_camera(camera) if not isinstance(camera, CameraModel) else camera
    check_render_settings(step=step, pixels_per_patch=pixels_per_patch, spp=spp, seed=seed)
    ill = load_illuminant(illuminant)
    ps = load_patch_spectra(spectra)
    refl, e = ps.on_grid(step), ill.on_grid(step)
    with _about(cam):
        sens = cam.sensitivities.on_grid(step)
        closed = camera_response(refl, e, sens, step)

    settings: dict[str, Any] = {"illuminant": ill.name, "spectra": ps.name,
                                "reference": reference, "seed": seed}
    mitsuba_info: dict[str, Any] = {}
    target_raw: FloatArray | None = None
    if renderer == "closed-form":
        ppp = pixels_per_patch or CLOSED_FORM_PIXELS_PER_PATCH
        layout = ChartLayout.for_patch_size(ppp)
        raw = layout.paint(closed)
        used_variant = None
    else:
        import fidelity.camera.mitsuba as mr  # noqa: PLC0415 (the renderer of an extra)

        ppp = pixels_per_patch or mr.DEFAULT_PIXELS_PER_PATCH
        layout = ChartLayout.for_patch_size(ppp)
        spp = mr.DEFAULT_SPP if spp is None else spp
        mimg = mr.render_raw(refl, e, sens, layout, spp=spp, step=step, variant=variant,
                             seed=0 if seed is None else seed, sampler=sampler)
        raw = mimg.image
        used_variant = mimg.variant
        if frame:  # the edge target through the same renderer
            target_raw = mr.render_target_raw(CHECK_EDGE_TARGET, e, sens, spp=spp, step=step,
                                              variant=mimg.variant,
                                              seed=0 if seed is None else seed,
                                              sampler=sampler).image
        mitsuba_info = {"spp": mimg.spp, "sampler": mimg.sampler, "variant": mimg.variant, "libllvm": mimg.libllvm,
                        "render_seconds": mimg.seconds_render, "probe": list(mimg.probe_notes)}
    settings.update(renderer=renderer, pixels_per_patch=layout.patch_px,
                    image_size=[layout.height, layout.width], spp=mitsuba_info.get("spp"))

    with _about(cam), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        gain = exposure_gain(cam.exposure, closed)
        raw = raw * gain
        if cam.vignetting_fov_deg is not None:
            raw = raw * vignetting_gain(layout.height, layout.width, cam.vignetting_fov_deg)[..., None]
        if cam.optics.kind != "none":  # the lens's PSF, in linear light, before the noise
            raw = cam.optics.apply(raw)
        raw = add_sensor_noise(raw, cam.noise, seed)
        _require_finite(raw, "the raw image (exposure, vignetting, optics, noise)")
        cam_rgb, cam_std = patch_means(raw, layout)
        dev = develop(cam, raw, cam_rgb, ill, spectra=spectra, step=step)
        _require_finite(dev.srgb, "the developed image (white balance, colour correction, tone "
                                  "curve)")
        srgb, srgb_std = patch_means(dev.srgb, layout)
        turned = None
        if frame:
            flat = np.full((1, refl.shape[-1]), FRAME_REFLECTANCE)
            white = camera_response(np.ones((1, refl.shape[-1])), e, sens, step)[0]
            turned = _render_frame(cam, closed, camera_response(flat, e, sens, step)[0], gain,
                                   seed, lambda img: develop(cam, img, cam_rgb, ill, ccm=dev.ccm,
                                                             spectra=spectra, step=step).srgb,
                                   white, target_raw)

    if reference == "scene":
        ref = scene_reference(ill, spectra, cat=cat, step=step)
        ref_lab, ref_srgb, ref_conv = ref.lab, ref.srgb, ref.conventions
    else:
        chart = load_chart("safecolor")
        ref_lab, ref_srgb = chart.lab, chart.srgb_unclipped
        ref_conv = {"reference": "SAFE-COLOR Lab table (D50-era chart data, not scene-consistent)",
                    "provenance": str(getattr(chart, "provenance", ""))}
    measurement = measure_chart(srgb, ref_lab, ps.patch_names, reference_srgb=ref_srgb,
                                noise=srgb_std)
    with _about(cam), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        budget = render_uncertainty(
            raw, dev.srgb, layout, cam_rgb, srgb, ref_lab, measurement.mean_delta_e,
            cam.quantisation_bits, ps.patch_names, cam,
            _white_balance_developer(cam, ill, dev.ccm, spectra, step, cam_rgb))
    if reference == "scene" and ill.name != "D65" and budget is not None:
        # the adaptation of the reference to D65 is a method choice: its spread, type B
        by_cat = {c: measure_chart(srgb, scene_reference(ill, spectra, cat=c, step=step).lab,
                                   ps.patch_names).mean_delta_e
                  for c in unc.ADAPTATION_SPREAD}
        budget = replace(budget, components=(*budget.components,
                                             unc.adaptation_component(by_cat, cat)))
    conventions = {
        "reference": ref_conv,
        "spectral_grid_nm": f"380-780 step {step:g}",
        "camera_raw_units": "sum(R E S dl) / sum(E ybar dl): ideal camera = linear sRGB, Y(white)=1",
        "exposure_gain": gain,
        "white_balance_gains": [float(v) for v in dev.white_balance_gains],
        "ccm": [[float(v) for v in row] for row in dev.ccm],
        "output_encoding": cam.output_encoding,
        "clipping": ("output clipped to [0, 1] (display-referred or quantised)" if cam.clips else
                     "float linear output measured unclipped (delinearize_srgb, no clip)"),
        "patch_sampling": (f"central {WINDOW_FRACTION:g} x patch side window, "
                           f"{TRIM_PROPORTION:g} trimmed mean per channel; noise = window std"),
        "layout": {"rows": layout.rows, "cols": layout.cols, "patch_px": layout.patch_px,
                   "gap_px": layout.gap_px},
        "delta_e": "CIEDE2000, kL = kC = kH = 1, Lab D65",
        "display_image": "encoded sRGB clipped to [0, 1]",
    }
    if mitsuba_info:
        conventions["mitsuba"] = mitsuba_info
    return ChartRender(
        measurement=measurement,
        linear_image=raw.astype(np.float32),
        display_image=np.clip(dev.srgb, 0.0, 1.0).astype(np.float32),
        renderer=renderer,
        variant=used_variant,
        seconds=time.perf_counter() - t0,
        conventions=conventions,
        camera=cam,
        camera_rgb=cam_rgb,
        camera_noise=cam_std,
        settings=settings,
        uncertainty=budget,
        frame=turned,
    )


def _render_frame(cam: CameraModel, patches: FloatArray, flat: FloatArray, gain: float,
                  seed: int | None, developed: Callable[[FloatArray], FloatArray],
                  white: FloatArray, target_raw: FloatArray | None = None) -> FrameRender:
    """The turned chart through ``cam`` (:class:`FrameRender`): raw ``patches`` (24, 3) and the
    frame's raw ``flat`` (3,) painted, then the chart's own stages; and the edge target
    (:data:`~fidelity.chart.turned.CHECK_EDGE_TARGET`) painted from the raw response to a
    perfect white ``white`` (3,), or ``target_raw`` where a renderer gave it (before the
    exposure gain), through the same stages."""
    geometry = CALIBRATION_GEOMETRY
    srgb = developed(_camera_stages(cam, geometry.paint(patches, flat) * gain, seed,
                                    "the turned chart"))
    _require_finite(srgb, "the turned chart's developed image")
    target = CHECK_EDGE_TARGET
    painted = target.paint(white) if target_raw is None else target_raw
    target_srgb = developed(_camera_stages(cam, painted * gain, seed, "the edge target"))
    _require_finite(target_srgb, "the edge target's developed image")
    return FrameRender(srgb=srgb, corners=geometry.corners(), geometry=geometry,
                       target_srgb=target_srgb, target=target,
                       target_renderer="closed-form" if target_raw is None else "mitsuba")


def _camera_stages(cam: CameraModel, raw: FloatArray, seed: int | None, what: str
                   ) -> FloatArray:
    """``raw`` (exposed) through ``cam``'s vignetting, optics and sensor noise."""
    if cam.vignetting_fov_deg is not None:
        raw = raw * vignetting_gain(raw.shape[0], raw.shape[1], cam.vignetting_fov_deg)[..., None]
    if cam.optics.kind != "none":
        raw = cam.optics.apply(raw)
    raw = add_sensor_noise(raw, cam.noise, seed)
    _require_finite(raw, f"{what}'s raw image")
    return raw


def _white_balance_developer(cam: CameraModel, illuminant: Any, ccm: FloatArray, spectra: str,
                             step: float, raw_means: FloatArray) -> Any:
    """(raw window pixels ``(N, 3)``, drawn raw patch means ``(B, n, 3)``) -> the pixels
    ``(B, N, 3)`` developed by the camera with its white balance estimated on each draw's
    patch means (its CCM as rendered): one :func:`develop` of the pixels scaled by each draw's
    gains over the rendered ones."""
    def gains(means: FloatArray) -> FloatArray:
        return white_balance_gains(cam.white_balance, means, cam.sensitivities, illuminant, step)

    base = gains(raw_means)

    def developed(pixels: FloatArray, drawn: FloatArray) -> FloatArray:
        ratio = np.array([gains(m) for m in drawn]) / base
        d = develop(cam, pixels[None] * ratio[:, None, :], raw_means, illuminant, ccm=ccm,
                    spectra=spectra, step=step)
        out: FloatArray = d.srgb
        return out

    return developed


#: Monte Carlo draws of the white-balance component (each develops the windows' pixels).
WHITE_BALANCE_DRAWS = 100
#: Pixels of each window developed per white-balance draw: a seeded random subsample (the same
#: in every draw, so the spread over draws is the gains'; developing whole windows cost 0.25 s
#: of every ``check``). The subsample gives each draw's change of a window's mean, added to the
#: measured mean: its own mean is not the window's, and a draw taken about it under-states the
#: component (by a quarter on average over 100 seeds of a noisy camera, with an even
#: subsample).
WHITE_BALANCE_PIXELS = 64


def render_uncertainty(raw_image: ArrayLike, srgb_image: ArrayLike, layout: ChartLayout,
                       raw_means: FloatArray, srgb_means: FloatArray,
                       reference_lab: FloatArray, value: float, bits: int | None,
                       patch_names: tuple[str, ...] | list[str], camera: CameraModel,
                       developed: Any) -> UncertaintyBudget:
    """The uncertainty budget of a render's chart ΔE (:mod:`fidelity.measure.uncertainty`):
    the pixel noise of each developed window's trimmed mean; the camera's white balance when
    the camera estimates it on the noisy chart (``white-patch``, ``grey-world``): its gains
    drawn from the raw patch means' standard errors and the windows' pixels developed with
    them (``developed``: pixels, raw means -> developed pixels), :data:`WHITE_BALANCE_DRAWS`
    draws; the rounding of the output codes (a ``bits``-bit camera). The windows are the
    layout's own (no placement uncertainty) and a render has no exposure normalisation."""
    def windows(image: ArrayLike) -> list[FloatArray]:
        img = np.asarray(image, np.float64)
        out = []
        for i in range(layout.rows * layout.cols):
            y0, y1, x0, x1 = layout.window(i, WINDOW_FRACTION)
            out.append(img[y0:y1, x0:x1].reshape(-1, img.shape[-1]))
        return out

    f = unc.srgb_chart_function(reference_lab)
    srgb_windows = windows(srgb_image)
    noise, notes = unc.noise_component(srgb_windows, srgb_means, f, trim=TRIM_PROPORTION,
                                       patch_names=patch_names)
    if camera.white_balance.method in ("white-patch", "grey-world") and camera.noise.enabled:
        raw_windows = windows(raw_image)
        covs, _ = unc.patch_covariances(raw_windows, trim=TRIM_PROPORTION)
        vals, vecs = np.linalg.eigh(covs)
        root = vecs * np.sqrt(np.maximum(vals, 0.0))[:, None, :]
        rng = np.random.default_rng(unc.SEED + 4)
        drawn = raw_means[None] + np.einsum(
            "kij,bkj->bki", root, rng.standard_normal((WHITE_BALANCE_DRAWS, *raw_means.shape)))
        pick = np.random.default_rng(unc.SEED + 5)
        kept = [w[np.sort(pick.choice(len(w), min(len(w), WHITE_BALANCE_PIXELS),
                                      replace=False))] for w in raw_windows]
        edges = np.cumsum([0] + [len(w) for w in kept])
        dev = developed(np.concatenate(kept), np.concatenate([raw_means[None], drawn]))

        def window_means(d: FloatArray) -> FloatArray:  # (B, N, 3) -> (B, windows, 3)
            return np.stack([trimmed_mean(np.swapaxes(d[:, edges[k]:edges[k + 1]], 0, 1),
                                          TRIM_PROPORTION) for k in range(len(kept))], axis=1)

        sub = window_means(dev)
        # the subsample gives each draw's change of the window means; the draws are taken
        # about the measured means (the subsample's own means are not those of the window)
        means = np.asarray(srgb_means, np.float64)[None] + (sub[1:] - sub[:1])
        wb = unc.UncertaintyComponent(
            "camera white balance", float(np.std(f(means), ddof=1)), "A",
            f"the camera's {camera.white_balance.method} white balance is estimated on the "
            f"noisy chart: its gains drawn from the raw patch means' standard errors "
            f"(winsorised covariance of each raw window), the windows' pixels developed with "
            f"them (a seeded random {WHITE_BALANCE_PIXELS} pixels of each window, each draw's "
            f"change of a window's mean added to the measured mean), {WHITE_BALANCE_DRAWS} "
            f"Monte Carlo draws")
    else:
        wb = unc.UncertaintyComponent(
            "camera white balance", 0.0, "B",
            "the camera's white balance does not depend on the noisy chart")
    step = 1.0 / (2 ** bits - 1) if bits else None
    rounding = unc.rounding_component(srgb_windows, srgb_means, f, step)
    placement = unc.UncertaintyComponent(
        "placement", 0.0, "B", "a render's windows are its layout's own: no placement error")
    exposure = unc.UncertaintyComponent(
        "exposure normalisation", 0.0, "B",
        "a render is measured as the camera exposed it: no normalisation")
    return unc.UncertaintyBudget(float(value), (noise, wb, rounding, placement, exposure),
                                 notes=notes)


#: The detector's letterbox factor for the turned chart a check renders
#: (:class:`fidelity.camera.render.FrameRender`): it has COCO's size, 640 x 480, so a camera
#: model's pixels are taken at the detector's input (its optics in pixels of that image).
FRAME_SCALE = 1.0


def frame_properties(frame: FrameRender | None, reference: str, illuminant: str
                     ) -> tuple[ChartSharpness | None, ChartNoise | None]:
    """The sharpness and noise of a check's render (``frame``), measured as an audit
    measures them (the images decoded from sRGB): the noise of the turned chart's neutral
    patches (:func:`fidelity.measure.pixels.measure_pixels` at the known corners) and the
    e-SFR of the slanted-edge target rendered beside it
    (:func:`fidelity.measure.chartsharpness.painted_target_sharpness`; the turned chart's
    patch edges where the frame has no target, or where no edge of the target gave a
    luminance MTF50 and a patch edge did: a target clipped by an over-exposed camera).

    Parameters
    ----------
    frame
        The turned chart of :func:`render_chart` (``frame=True``), or None.
    reference
        The colour reference of the measurement (:data:`REFERENCES`).
    illuminant
        The scene illuminant.

    Returns
    -------
    tuple
        The :class:`~fidelity.measure.chartsharpness.ChartSharpness` and
        :class:`~fidelity.measure.chartnoise.ChartNoise` (each None where not measured;
        both None without a frame).
    """
    if frame is None:
        return None, None
    target = None
    if frame.target_srgb is not None and frame.target is not None:
        target = painted_target_sharpness(
            frame.target_srgb, frame.target, linearise=_decode_srgb,
            linearisation="sRGB transfer function decoded (IEC 61966-2-1)", saturation=1.0,
            black=0.0, source=f"the check's edge target ({frame.target_renderer})")
    measured = _luminance_measured(target)
    # the patch edges only where the target gave no luminance MTF50 (none, or clipped)
    got = measure_pixels(frame.srgb, frame.corners, encoding="srgb", reference=reference,
                         illuminant=illuminant, uncertainty=False, corner_checks=False,
                         sharpness=not measured)
    if measured or not _luminance_measured(got.sharpness):
        return (target if target is not None else got.sharpness), got.noise
    return got.sharpness, got.noise  # the target refused (clipped, say): the patch edges


def _luminance_measured(sharpness: ChartSharpness | None) -> bool:
    """Whether some edge of ``sharpness`` gave a luminance MTF50 above 0."""
    if sharpness is None:
        return False
    for edge in sharpness.edges:
        y = edge.channel("Y") if edge.refusal is None else None
        if y is not None and y.refusal is None and y.mtf50 is not None and y.mtf50 > 0:
            return True
    return False


def _decode_srgb(v: np.ndarray) -> np.ndarray:
    return np.asarray(linearize_srgb(v), np.float64)


__all__ = [
    "CLOSED_FORM_PIXELS_PER_PATCH",
    "FRAME_SCALE",
    "MAX_PIXELS_PER_PATCH",
    "MAX_SEED",
    "MAX_SPP",
    "STEP_RANGE_NM",
    "camera_context",
    "check_render_settings",
    "REFERENCES",
    "RENDERERS",
    "ChartLayout",
    "ChartRender",
    "FrameRender",
    "frame_properties",
    "render_chart",
    "patch_means",
    "render_uncertainty",
    "trimmed_mean",
]
