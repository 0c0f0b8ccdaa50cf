"""COCO-C's noise and blur corruptions on the measured SNR and MTF50 scales.

The colour corruptions of COCO-C go on the chart ΔE scale (:mod:`fidelity.coco.corruptions`).
Four of its other corruptions change one property an audit measures, so they go on that
property's axis the same way (issue 56, requirement 4):

=================  ==========  =========================================================
corruption         axis        what ``imagecorruptions`` 1.1.2 does (x = image / 255)
=================  ==========  =========================================================
gaussian_noise     SNR         ``clip(x + N(0, c), 0, 1)``, c = .08, .12, .18, .26, .38
shot_noise         SNR         ``clip(Poisson(x c) / c, 0, 1)``, c = 60, 25, 12, 5, 3
defocus_blur       MTF50       a disc of radius r, antialiased by a Gaussian of sigma a,
                               (r, a) = (3, .1), (4, .5), (6, .5), (8, .5), (10, .5)
gaussian_blur      MTF50       ``skimage.filters.gaussian`` of sigma 1, 2, 3, 4, 6 px
=================  ==========  =========================================================

all on the *encoded* sRGB values, then ``np.uint8(clip(y, 0, 1) * 255)`` (truncation). They
are applied by the package itself (:func:`apply_corruption`; an optional dependency:
``pip install --no-deps imagecorruptions==1.1.2``, with scikit-image and opencv). Its
``gaussian_blur`` calls ``skimage.filters.gaussian(..., multichannel=True)``, an argument
scikit-image removed in 0.19; where the package's call fails for that reason the same filter
is called with ``channel_axis=-1`` (the same operation: each channel filtered alone).

The noise is random and the package draws it from numpy's global generator. Every draw here is
seeded (:func:`corruption_seed`): ``np.random.seed`` with the first four bytes of
``sha256("imagecorruptions:<name>:<severity>:<image>")`` (big-endian), the image being the
COCO image id or ``chart-<k>`` for the k-th chart draw, and the global generator's state put
back afterwards. So a corrupted COCO image is the same in every run, resumed or not.

A corruption's value on its axis (:func:`chart_axis_value`) is measured as the tables'
levels are (:func:`fidelity.coco.tables.degradation.calibrate_level`): the calibration chart
(:func:`~fidelity.coco.tables.degradation.calibration_chart`, 640 x 480, the detector's input
size) corrupted and measured by the audit's own measurement
(:func:`~fidelity.coco.tables.degradation.chart_value`): the softer edge's luminance MTF50
(cy/px) for blur, the 18 % grey patch's luminance SNR in linear light for noise. A blur is
deterministic: one chart, the uncertainty the measurement's own. A noise is averaged over
:data:`CHART_DRAWS` seeded draws: x is their mean, ``u`` its standard error (the draws'
standard deviation over sqrt(n)) and ``spread`` the standard deviation of one draw.

The predicted loss is the property table's worst case at x
(:func:`fidelity.prediction.properties.predict_property`, what ``fidelity predict --mtf50`` /
``--snr`` prints) with x's uncertainty propagated.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.coco.tables.degradation import calibration_chart, chart_value
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.fileio import optional_float
from fidelity.core.record import record

__all__ = [
    "AXIS_LABELS",
    "CHART_DRAWS",
    "PARAMETERS",
    "PROPERTY",
    "SPATIAL_CORRUPTIONS",
    "AxisValue",
    "SpatialCorruption",
    "apply_corruption",
    "chart_axis_value",
    "check_severity",
    "check_spatial",
    "corruption_seed",
    "seeded",
]

U8 = NDArray[np.uint8]

#: The noise and blur corruptions of COCO-C measured here, in the package's order.
SPATIAL_CORRUPTIONS: tuple[str, ...] = ("gaussian_noise", "shot_noise", "defocus_blur",
                                        "gaussian_blur")
#: The property (axis) each corruption changes.
PROPERTY: Mapping[str, str] = {"gaussian_noise": "noise", "shot_noise": "noise",
                               "defocus_blur": "sharpness", "gaussian_blur": "sharpness"}
#: Axis labels of the properties: (name, unit).
AXIS_LABELS: Mapping[str, tuple[str, str]] = {"sharpness": ("MTF50", "cy/px"),
                                              "noise": ("SNR", "ratio")}
#: Parameters per severity 1-5 (imagecorruptions 1.1.2, ``corruptions.py``).
PARAMETERS: Mapping[str, tuple[Any, ...]] = {
    "gaussian_noise": (0.08, 0.12, 0.18, 0.26, 0.38),
    "shot_noise": (60, 25, 12, 5, 3),
    "defocus_blur": ((3, 0.1), (4, 0.5), (6, 0.5), (8, 0.5), (10, 0.5)),
    "gaussian_blur": (1, 2, 3, 4, 6),
}
#: Seeded draws of the chart a noise corruption's axis value averages.
CHART_DRAWS = 8
#: Severities of COCO-C.
SEVERITIES: tuple[int, ...] = (1, 2, 3, 4, 5)
#: Version of the package the corruptions come from: the noise and blur ones called here, the
#: colour ones that :func:`fidelity.coco.corruptions.corrupt` implements.
IMAGECORRUPTIONS_VERSION = "1.1.2"


def check_severity(name: str, severity: int) -> None:
    """An error unless ``severity`` is a COCO-C severity (:data:`SEVERITIES`, 1-5)."""
    if severity not in SEVERITIES:
        raise InvalidValueError(f"{name}: severity {severity!r} must be an integer 1-5")


def check_spatial(name: str, severity: int) -> None:
    """An error unless ``name`` is a spatial corruption and ``severity`` 1-5."""
    if name not in SPATIAL_CORRUPTIONS:
        raise unknown_name("noise or blur corruption", name, SPATIAL_CORRUPTIONS)
    check_severity(name, severity)


def corruption_seed(name: str, severity: int, image: int | str) -> int:
    """The seed of one corrupted image (module docstring): the first four bytes, big-endian,
    of ``sha256("imagecorruptions:<name>:<severity>:<image>")``, in [0, 2^32)."""
    text = f"imagecorruptions:{name}:{severity}:{image}".encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:4], "big")


@contextmanager
def seeded(seed: int) -> Iterator[None]:
    """numpy's global generator seeded with ``seed`` inside, its state put back after."""
    state = np.random.get_state()  # noqa: NPY002 (the package draws from the global one)
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def _package() -> Any:
    try:
        with warnings.catch_warnings():
            # its scipy.ndimage.interpolation import is deprecated in SciPy, not ours to fix
            warnings.simplefilter("ignore", DeprecationWarning)
            import imagecorruptions
    except ImportError:
        raise InvalidValueError(
            "imagecorruptions: not installed; the noise and blur corruptions need it "
            f"(pip install --no-deps imagecorruptions=={IMAGECORRUPTIONS_VERSION} "
            "scikit-image opencv-python-headless)") from None
    return imagecorruptions


def _gaussian_blur(rgb8: U8, sigma: float) -> U8:
    """imagecorruptions' ``gaussian_blur`` with ``channel_axis=-1`` for the removed
    ``multichannel=True`` (module docstring)."""
    from skimage import filters

    gaussian: Callable[..., Any] = filters.gaussian
    y = np.asarray(gaussian(np.asarray(rgb8) / 255.0, sigma=sigma, channel_axis=-1))
    out: U8 = (np.clip(y, 0, 1) * 255).astype(np.uint8)
    return out


def apply_corruption(rgb8: U8, name: str, severity: int, seed: int | None = None) -> U8:
    """One image corrupted by ``imagecorruptions`` (module docstring).

    Parameters
    ----------
    rgb8
        The image: (H, W, 3) uint8 sRGB codes, H and W >= 32.
    name
        A corruption of :data:`SPATIAL_CORRUPTIONS`.
    severity
        COCO-C severity, 1-5 (:data:`PARAMETERS`).
    seed
        Seed of numpy's global generator for the draw (:func:`seeded`); None: the generator
        as it is (the package's own behaviour).

    Returns
    -------
    numpy.ndarray
        The corrupted image, (H, W, 3) uint8.

    Raises
    ------
    InvalidValueError
        An unknown name, a severity not 1-5, an image not (H, W, 3) uint8, or the package not
        installed. Exit code 2.
    """
    check_spatial(name, severity)
    a = np.asarray(rgb8)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3) uint8, got {a.shape} {a.dtype}")
    ic = _package()
    if seed is None:
        return _apply(ic, a, name, severity)
    with seeded(seed):
        return _apply(ic, a, name, severity)


def _apply(ic: Any, a: U8, name: str, severity: int) -> U8:
    try:
        got: U8 = np.asarray(ic.corrupt(a, severity=severity, corruption_name=name))
    except TypeError as exc:
        if name != "gaussian_blur" or "multichannel" not in str(exc):
            raise
        return _gaussian_blur(a, float(PARAMETERS[name][severity - 1]))
    return got


@record
class SpatialCorruption:
    """One (corruption, severity) as a measurement's mapping
    (:func:`fidelity.coco.measure.measure_mapping`): :meth:`for_image` gives the image's own
    seeded corruption (module docstring)."""

    name: str
    severity: int

    def __post_init__(self) -> None:
        check_spatial(self.name, self.severity)

    def for_image(self, image_id: int) -> Callable[[U8], U8]:
        """The corruption of COCO image ``image_id``, seeded by :func:`corruption_seed`."""
        seed = corruption_seed(self.name, self.severity, int(image_id))

        def mapped(rgb8: U8) -> U8:
            return apply_corruption(rgb8, self.name, self.severity, seed)

        return mapped

    def __call__(self, rgb8: U8) -> U8:
        """Unseeded: the package's draw from the global generator as it stands."""
        return apply_corruption(rgb8, self.name, self.severity)

    @property
    def key(self) -> str:
        """The mapping key of the measurement store (the seeding rule is part of it)."""
        return (f"coco-c:{self.name}:{self.severity}:imagecorruptions-"
                f"{IMAGECORRUPTIONS_VERSION}:seed-sha256-image-id")

    @property
    def parameter(self) -> Any:
        """The package's parameter at this severity (:data:`PARAMETERS`)."""
        return PARAMETERS[self.name][self.severity - 1]

    @property
    def property(self) -> str:  # noise or sharpness (no docstring: no second API target of
        # that name, which the tables' "property" attributes would refer to ambiguously)
        return PROPERTY[self.name]


@record
class AxisValue:
    """A corruption's value on its property's axis (:func:`chart_axis_value`).

    Attributes
    ----------
    property
        ``sharpness`` (x: MTF50, cy/px) or ``noise`` (x: SNR at 18 % grey, a ratio).
    x
        The value: one chart's for a blur, the mean over the draws for a noise; None where the
        chart could not be measured.
    u
        Its standard uncertainty: the measurement's own for a blur (None: not stated), the
        draws' standard error for a noise.
    spread
        The standard deviation of one draw (noise; None for a blur).
    draws
        The values of the draws, in seed order (one for a blur).
    seeds
        Their seeds (:func:`corruption_seed` of ``chart-<k>``); empty for a blur.
    """

    property: str
    x: float | None
    u: float | None
    spread: float | None
    draws: tuple[float, ...]
    seeds: tuple[int, ...]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"property": self.property, "x": self.x, "u": self.u, "spread": self.spread,
                "draws": list(self.draws), "seeds": list(self.seeds)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> AxisValue:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["property"]), optional_float(d.get("x")), optional_float(d.get("u")),
                   optional_float(d.get("spread")), tuple(float(v) for v in d.get("draws") or ()),
                   tuple(int(s) for s in d.get("seeds") or ()))



def chart_axis_value(name: str, severity: int, draws: int = CHART_DRAWS,
                     chart: tuple[np.ndarray, np.ndarray] | None = None) -> AxisValue:
    """The axis value of a corruption on the calibration chart (module docstring).

    Parameters
    ----------
    name, severity
        The corruption (:data:`SPATIAL_CORRUPTIONS`) and its severity, 1-5.
    draws
        Seeded draws a noise is averaged over, >= 1 (a blur is measured once).
    chart
        ``(image, corners)`` of the calibration chart; None:
        :func:`fidelity.coco.tables.degradation.calibration_chart`.

    Returns
    -------
    AxisValue
        x (MTF50 in cy/px or SNR), its uncertainty and the draws.
    """
    check_spatial(name, severity)
    if draws < 1:
        raise InvalidValueError(f"draws {draws!r}: must be >= 1")
    image, corners = chart if chart is not None else calibration_chart()
    prop = PROPERTY[name]
    if prop == "sharpness":
        got = chart_value(apply_corruption(image, name, severity), corners, prop)
        if got is None:
            return AxisValue(prop, None, None, None, (), ())
        return AxisValue(prop, got[0], got[1], None, (got[0],), ())
    seeds = tuple(corruption_seed(name, severity, f"chart-{k}") for k in range(draws))
    values: list[float] = []
    for s in seeds:
        got = chart_value(apply_corruption(image, name, severity, s), corners, prop)
        if got is None or not math.isfinite(got[0]):
            return AxisValue(prop, None, None, None, tuple(values), seeds)
        values.append(got[0])
    v = np.asarray(values)
    spread = float(v.std(ddof=1)) if len(v) > 1 else None
    u = spread / math.sqrt(len(v)) if spread is not None else None
    return AxisValue(prop, float(v.mean()), u, spread, tuple(values), seeds)


def split_names(names: Sequence[str]) -> tuple[list[str], list[str]]:
    """``names`` as (colour corruptions, noise and blur corruptions), each in the order given."""
    return ([n for n in names if n not in SPATIAL_CORRUPTIONS],
            [n for n in names if n in SPATIAL_CORRUPTIONS])
