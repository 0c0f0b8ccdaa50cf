"""The colour of a chart: per-patch CIEDE2000 of measured sRGB against reference CIELAB.

The SAFE-COLOR chart ΔE of an image is the mean ΔE00 over the chart's patches, each patch's
encoded sRGB converted to CIELAB (D65) and compared with the reference Lab
(``shared/reference/safecolor.md``, "Colour difference"): :func:`measure_chart`. The chart's
statistics (neutral patches, per-patch SNR, the tone curve of the neutrals) are derived from the
same :class:`ChartMeasurement`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour import colorimetry as cm
from fidelity.colour.colorimetry import delta_e_2000, delta_e_2000_components, srgb_to_lab
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

F64 = NDArray[np.float64]


def _patch_array(values: ArrayLike, name: str, n: int | None = None) -> F64:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise InvalidValueError(f"{name} must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = sorted({int(i) + 1 for i in np.argwhere(~np.isfinite(a))[:, 0]})
        raise InvalidValueError(f"{name} has NaN or Inf values (patches {bad})")
    return a


def chart_delta_e(srgb: ArrayLike, reference_lab: ArrayLike) -> float:
    """Mean ΔE00 of encoded sRGB patches (n, 3) against reference CIELAB D65 (n, 3).

    The SAFE-COLOR chart ΔE. Domain: finite sRGB (values outside [0, 1] are taken as they are).
    """
    return float(np.mean(delta_e_2000(srgb_to_lab(srgb), reference_lab)))


@record
class ChartMeasurement:
    """Measured chart colours and their CIEDE2000 differences from the reference.

    ``delta_l``, ``delta_c``, ``delta_h`` are the unweighted CIEDE2000 differences ΔL', ΔC', ΔH'
    of the measured colour relative to the reference (positive ΔL': lighter than reference).
    ``noise`` is the per-patch standard deviation of the sampled pixels (encoded sRGB), if known.
    ``excluded`` names the patches left out of the chart's statistics (mean, max, worst
    patch), with why (a patch the chart finder judged covered: a leaf, a hand); they keep
    their own measurement.

    Attributes
    ----------
    patch_names
        The n patch names, in chart order (the order of every array below).
    srgb
        Measured encoded sRGB of each patch, shape (n, 3), finite (values outside [0, 1]
        kept as measured).
    lab
        CIELAB (D65) of ``srgb``, shape (n, 3).
    reference_lab
        Reference CIELAB (D65) of each patch, shape (n, 3).
    delta_e
        CIEDE2000 ΔE00 of each patch, >= 0, shape (n,).
    delta_l
        Unweighted CIEDE2000 lightness difference ΔL' of the measured colour relative to the
        reference, shape (n,), signed (positive: lighter).
    delta_c
        Unweighted CIEDE2000 chroma difference ΔC', shape (n,), signed (positive: more
        chromatic).
    delta_h
        Unweighted CIEDE2000 hue difference ΔH', shape (n,), signed.
    reference_srgb
        Encoded sRGB of the reference, shape (n, 3); None when not given.
    noise
        Standard deviation of each patch's sampled pixels (encoded sRGB), shape (n, 3);
        None when unknown.
    excluded
        Patch name -> why it is left out of the statistics; empty: every patch counts.
    """

    patch_names: tuple[str, ...]
    srgb: F64
    lab: F64
    reference_lab: F64
    delta_e: F64
    delta_l: F64
    delta_c: F64
    delta_h: F64
    reference_srgb: F64 | None = None
    noise: F64 | None = None
    excluded: Mapping[str, str] = field(default_factory=dict)

    @property
    def used(self) -> NDArray[np.bool_]:
        """``(n,)`` whether each patch counts in the chart's statistics (not ``excluded``)."""
        return np.array([n not in self.excluded for n in self.patch_names], dtype=bool)

    @property
    def mean_delta_e(self) -> float:
        """Mean ΔE00 over the patches used: the chart ΔE."""
        return float(np.mean(self.delta_e[self.used]))

    @property
    def max_delta_e(self) -> float:
        """Largest ΔE00 of the patches used."""
        return float(np.max(self.delta_e[self.used]))

    @property
    def worst_patch(self) -> str:
        """Name of the patch used with the largest ΔE00."""
        de = np.where(self.used, self.delta_e, -np.inf)
        return self.patch_names[int(np.argmax(de))]

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``mean_delta_e``, ``max_delta_e``, ``worst_patch`` and one entry per
        patch in chart order (``name``, ``delta_e``, ``delta_l``, ``delta_c``, ``delta_h``,
        ``lab``, ``reference_lab``, ``srgb``, ``reference_srgb``, ``noise``, ``used`` and
        ``excluded_because``: null, or why the patch is left out of the statistics)."""

        def vec(a: F64 | None, i: int) -> list[float] | None:
            return None if a is None else [float(v) for v in a[i]]

        return {
            "mean_delta_e": self.mean_delta_e,
            "max_delta_e": self.max_delta_e,
            "worst_patch": self.worst_patch,
            "patches": [
                {
                    "name": name,
                    "delta_e": float(self.delta_e[i]),
                    "delta_l": float(self.delta_l[i]),
                    "delta_c": float(self.delta_c[i]),
                    "delta_h": float(self.delta_h[i]),
                    "lab": vec(self.lab, i),
                    "reference_lab": vec(self.reference_lab, i),
                    "srgb": vec(self.srgb, i),
                    "reference_srgb": vec(self.reference_srgb, i),
                    "noise": vec(self.noise, i),
                    "used": name not in self.excluded,
                    "excluded_because": self.excluded.get(name),
                }
                for i, name in enumerate(self.patch_names)
            ],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ChartMeasurement:
        """The measurement of a :meth:`to_json` document (its ``patches``; the summary values
        are derived from them again)."""
        patches = data["patches"]

        def rows(key: str) -> F64 | None:
            if any(p.get(key) is None for p in patches):
                return None
            return np.array([p[key] for p in patches], dtype=np.float64)

        def col(key: str) -> F64:
            return np.array([p[key] for p in patches], dtype=np.float64)

        srgb, lab, ref = rows("srgb"), rows("lab"), rows("reference_lab")
        if srgb is None or lab is None or ref is None:
            raise InvalidValueError("a chart measurement needs srgb, lab and reference_lab "
                                    "of every patch")
        return cls(
            patch_names=tuple(str(p["name"]) for p in patches), srgb=srgb, lab=lab,
            reference_lab=ref, delta_e=col("delta_e"), delta_l=col("delta_l"),
            delta_c=col("delta_c"), delta_h=col("delta_h"),
            reference_srgb=rows("reference_srgb"), noise=rows("noise"),
            excluded={str(p["name"]): str(p["excluded_because"]) for p in patches
                      if p.get("excluded_because")},
        )


def measure_chart(
    srgb: ArrayLike,
    reference_lab: ArrayLike,
    patch_names: Sequence[str],
    *,
    reference_srgb: ArrayLike | None = None,
    noise: ArrayLike | None = None,
    excluded: Mapping[str, str] | None = None,
) -> ChartMeasurement:
    """Measure chart patches: encoded sRGB (n, 3) against reference CIELAB D65 (n, 3).

    ``excluded``: patches (by name) left out of the statistics, with why; at least one must
    be left.

    Raises :class:`~fidelity.core.errors.InvalidValueError` for wrong shapes or NaN/Inf values,
    naming the patches concerned.

    Parameters
    ----------
    srgb
        Measured encoded sRGB of the patches, shape (n, 3), finite (nominally in [0, 1];
        values outside are converted as they are).
    reference_lab
        Reference CIELAB (D65) of the patches, shape (n, 3), finite.
    patch_names
        The n patch names, in the order of the rows of ``srgb``.
    reference_srgb
        Encoded sRGB of the reference, shape (n, 3), finite; kept for the report only.
    noise
        Standard deviation of each patch's pixels (encoded sRGB), shape (n, 3); kept as given.
    excluded
        Patch name -> why it is left out of the mean, max and worst patch; the names must be
        patches of the chart and at least one patch must be left.

    Returns
    -------
    ChartMeasurement
        Per patch the measured Lab, ΔE00 (>= 0) and ΔL', ΔC', ΔH' against the reference;
        ``mean_delta_e`` is the SAFE-COLOR chart ΔE.

    Raises
    ------
    InvalidValueError
        ``srgb``, ``reference_lab`` or ``reference_srgb`` not of shape (n, 3) or with NaN/Inf
        values (the message names the patches); ``excluded`` names that are not patches, or
        every patch excluded. Exit code 2.
    """
    names = tuple(str(n) for n in patch_names)
    n = len(names)
    rgb = _patch_array(srgb, "measured sRGB", n)
    ref = _patch_array(reference_lab, "reference Lab", n)
    lab = srgb_to_lab(rgb)
    dl, dc, dh = delta_e_2000_components(ref, lab)
    return ChartMeasurement(
        patch_names=names,
        srgb=rgb,
        lab=np.asarray(lab, np.float64),
        reference_lab=ref,
        delta_e=np.asarray(delta_e_2000(lab, ref), np.float64),
        delta_l=np.asarray(dl, np.float64),
        delta_c=np.asarray(dc, np.float64),
        delta_h=np.asarray(dh, np.float64),
        reference_srgb=None if reference_srgb is None else _patch_array(reference_srgb, "reference sRGB", n),
        noise=None if noise is None else np.asarray(noise, dtype=np.float64),
        excluded=_excluded(excluded, names),
    )


def _excluded(excluded: Mapping[str, str] | None, names: tuple[str, ...]) -> dict[str, str]:
    out = {str(k): str(v) for k, v in (excluded or {}).items()}
    unknown = sorted(set(out) - set(names))
    if unknown:
        raise InvalidValueError(f"excluded patches {unknown} are not patches of the chart")
    if len(out) >= len(names):
        raise InvalidValueError("every patch is excluded: nothing left to measure")
    return out


#: Why a patch the chart finder judged covered is left out (:attr:`ChartMeasurement.excluded`).
OCCLUDED_REASON = ("covered (a leaf, a hand, a glare?): its colour is far from the camera's "
                   "fit to the other patches, or its window is textured and out of order")

#: Largest exposure correction, in EV, either way: 2**128 spans float32's whole range, so a
#: larger one takes every patch to 0 or beyond any floating-point value.
MAX_EXPOSURE_EV = 128.0

#: Reference chroma C*ab below which a patch counts as neutral (the Macbeth chart's six greys
#: have C*ab < 2; its least chromatic colour patch about 20).
NEUTRAL_CHROMA = 5.0


def neutral_patches(m: ChartMeasurement) -> tuple[int, ...]:
    """Indices of the neutral patches: reference chroma C*ab below :data:`NEUTRAL_CHROMA`."""
    chroma = np.hypot(m.reference_lab[:, 1], m.reference_lab[:, 2])
    return tuple(int(i) for i in np.flatnonzero(chroma < NEUTRAL_CHROMA))


@record
class ChartStatistics:
    """What a chart says beyond ΔE, as Imatest's Colorcheck reports it.

    ``saturation_percent``: mean measured chroma C*ab of the colour (non-neutral) patches in
    percent of their mean reference chroma (100: right saturation, > 100 oversaturated).
    ``neutral_ab``: mean (a*, b*) error, measured minus reference, of the neutral patches (the
    white-balance error, a colour cast); ``neutral_chroma`` its length. ``neutral_delta_l``:
    mean L* error of the neutral patches (exposure and tone). ``snr_db``: mean over the neutral
    patches of 20 log10(mean / standard deviation) of their encoded sRGB values, and
    ``worst_snr_db`` the lowest, over the patches with noise above :data:`NOISE_FLOOR`; None
    when the noise is unknown or below the floor. ``noise_free``: the noise is known and every
    neutral patch's is below :data:`NOISE_FLOOR` (a noise-free render: report "no noise", not
    the SNR of floating-point rounding). ``worst_patch`` / ``worst_patch_snr_db``: the patch of
    the whole chart with the lowest SNR (:func:`patch_snr_db`), None when none has a finite one.
    """

    saturation_percent: float
    neutral_ab: tuple[float, float]
    neutral_chroma: float
    neutral_delta_l: float
    snr_db: float | None
    worst_snr_db: float | None
    noise_free: bool = False
    worst_patch: str | None = None
    worst_patch_snr_db: float | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"saturation_percent": self.saturation_percent,
                "neutral_ab": list(self.neutral_ab), "neutral_chroma": self.neutral_chroma,
                "neutral_delta_l": self.neutral_delta_l, "snr_db": self.snr_db,
                "worst_snr_db": self.worst_snr_db, "noise_free": self.noise_free,
                "worst_patch": self.worst_patch,
                "worst_patch_snr_db": self.worst_patch_snr_db}


#: Standard deviation (encoded sRGB, 0..1) below which a patch counts as noise-free: the
#: quantisation noise of a 16-bit encoding, 1 / (65535 sqrt(12)) (a uniform rounding error's
#: standard deviation). A render without noise has a standard deviation of ~1e-16 (rounding),
#: whose "SNR" of ~290 dB means nothing.
NOISE_FLOOR: float = 1.0 / (65535.0 * math.sqrt(12.0))


def patch_snr_db(m: ChartMeasurement) -> F64 | None:
    """Signal-to-noise ratio of every patch, dB: ``20 log10(mean / standard deviation)`` of its
    encoded sRGB values (means over the three channels), as Imatest's Colorcheck reports it.

    ``+inf`` where the standard deviation is below :data:`NOISE_FLOOR` (no noise), NaN where the
    patch has no signal (mean <= 0 with noise) or a value is not finite; None when the
    measurement has no noise (an image without per-patch spread). Shape (n,).
    """
    if m.noise is None:
        return None
    mean = np.asarray(m.srgb, np.float64).reshape(len(m.patch_names), -1).mean(axis=1)
    sd = np.asarray(m.noise, np.float64).reshape(len(m.patch_names), -1).mean(axis=1)
    out = np.full(mean.shape, np.nan)
    quiet = np.isfinite(sd) & (sd < NOISE_FLOOR)
    ok = np.isfinite(sd) & np.isfinite(mean) & ~quiet & (mean > 0)
    out[ok] = 20.0 * np.log10(mean[ok] / sd[ok])
    out[quiet] = np.inf
    return out


@record
class ToneFit:
    """The neutral patches' tone curve fitted with a power law about mid grey.

    ``Y_meas = 0.18 * 2**offset_ev * (Y_ref / 0.18)**gamma`` (CIE Y, white = 1): ``gamma`` is
    the slope of log Y_meas against log Y_ref (1: the reference's tone, > 1: more contrast),
    ``offset_ev`` the exposure error at 18 % grey in EV (positive: measured brighter),
    ``rms_ev`` the root-mean-square residual in EV over the ``patches`` fitted (the neutral
    patches with light in both).
    """

    gamma: float
    offset_ev: float
    rms_ev: float
    patches: int

    def predict(self, y_ref: NDArray[np.float64]) -> NDArray[np.float64]:
        """Measured Y the fit gives for reference Y ``y_ref`` (any shape, >= 0)."""
        y = np.clip(np.asarray(y_ref, np.float64), 0.0, None)
        return np.asarray(0.18 * 2.0 ** self.offset_ev * (y / 0.18) ** self.gamma, np.float64)

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"gamma": self.gamma, "offset_ev": self.offset_ev, "rms_ev": self.rms_ev,
                "patches": self.patches}


def fit_tone(m: ChartMeasurement, neutral_indices: Sequence[int] | None = None
             ) -> ToneFit | None:
    """Least-squares fit of :class:`ToneFit` to the neutral patches (default
    :func:`neutral_patches`) in log2 Y; None when fewer than two of them have light in both
    the measurement and the reference, or all at one reference level. A patch clipped at
    white (an encoded channel at 1 or above: the image holds no more light there) is left
    out, so that an over-exposed chart reads its exposure, not a flatter gamma."""
    idx = list(neutral_patches(m) if neutral_indices is None else neutral_indices)
    if len(idx) < 2:
        return None
    y_ref = cm.lab_to_xyz(np.asarray(m.reference_lab, np.float64)[idx])[:, 1]
    y_meas = cm.lab_to_xyz(np.asarray(m.lab, np.float64)[idx])[:, 1]
    white = float(cm.WHITEPOINT_D65_XYZ[1])
    clipped = np.any(np.asarray(m.srgb, np.float64)[idx] >= 1.0, axis=1)
    ok = (np.isfinite(y_ref) & np.isfinite(y_meas) & (y_ref > 0) & (y_meas > 0) & ~clipped)
    if int(ok.sum()) < 2:
        return None
    x = np.log2(y_ref[ok] / white / 0.18)
    y = np.log2(y_meas[ok] / white / 0.18)
    if float(np.ptp(x)) < 1e-9:
        return None
    gamma, offset = np.polyfit(x, y, 1)
    resid = y - (gamma * x + offset)
    return ToneFit(gamma=float(gamma), offset_ev=float(offset),
                   rms_ev=float(np.sqrt(np.mean(resid ** 2))), patches=int(ok.sum()))


def chart_statistics(m: ChartMeasurement) -> ChartStatistics:
    """Saturation, white balance, neutral lightness and noise of a measured chart
    (:class:`ChartStatistics`). Raises when the chart has no neutral or no colour patch."""
    neutral = list(neutral_patches(m))
    colour = [k for k in range(len(m.patch_names)) if k not in neutral]
    if not neutral or not colour:
        raise InvalidValueError("chart statistics need neutral and colour patches")
    c_meas = np.hypot(m.lab[colour, 1], m.lab[colour, 2])
    c_ref = np.hypot(m.reference_lab[colour, 1], m.reference_lab[colour, 2])
    d_ab = (m.lab[neutral, 1:] - m.reference_lab[neutral, 1:]).mean(axis=0)
    per_patch = patch_snr_db(m)
    snr: list[float] = []
    noise_free = False
    worst: tuple[str, float] | None = None
    if per_patch is not None:
        snr = [float(per_patch[k]) for k in neutral if np.isfinite(per_patch[k])]
        noise_free = bool(np.all(np.isposinf(per_patch[neutral])))
        finite = np.flatnonzero(np.isfinite(per_patch))
        if finite.size:
            k_worst = int(finite[np.argmin(per_patch[finite])])
            worst = (m.patch_names[k_worst], float(per_patch[k_worst]))
    return ChartStatistics(
        saturation_percent=float(100.0 * c_meas.mean() / c_ref.mean()),
        neutral_ab=(float(d_ab[0]), float(d_ab[1])), neutral_chroma=float(np.hypot(*d_ab)),
        neutral_delta_l=float((m.lab[neutral, 0] - m.reference_lab[neutral, 0]).mean()),
        snr_db=float(np.mean(snr)) if snr else None,
        worst_snr_db=float(np.min(snr)) if snr else None,
        noise_free=noise_free, worst_patch=worst[0] if worst else None,
        worst_patch_snr_db=worst[1] if worst else None,
    )


__all__ = [
    "MAX_EXPOSURE_EV",
    "ChartMeasurement",
    "NOISE_FLOOR",
    "ChartStatistics",
    "ToneFit",
    "NEUTRAL_CHROMA",
    "OCCLUDED_REASON",
    "chart_delta_e",
    "chart_statistics",
    "fit_tone",
    "patch_snr_db",
    "neutral_patches",
    "measure_chart",
]
