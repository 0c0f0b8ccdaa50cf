"""Noise of a camera model in linear light: per patch, the photon transfer of one chart frame, and
the temporal and fixed-pattern noise of a stack of frames (EMVA 1288 Release 4.0).

:func:`patch_noise`
    One patch's pixels ``(n, 3)`` (linear R, G, B): per channel and for the luminance
    ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` the mean, the sample variance with its standard
    uncertainty, the SNR (``mu / sigma`` and ``20 log10`` of it, dB); the chroma noise.
:func:`photon_transfer`
    The one-frame photon-transfer estimate on the chart's neutral patches: the weighted
    least-squares line ``sigma^2(mu) = sigma_read^2 + K mu`` through their means and variances,
    which gives the read noise and the conversion gain ``K``; from the line, the SNR of the
    18 % grey patch and the dynamic range.
:func:`temporal_and_fixed_pattern`
    Several frames of one flat region: the temporal noise from their differences and the
    fixed-pattern (spatial) noise of their mean with the temporal part removed, as EMVA 1288
    does, with its row, column and pixel parts.

Units: whatever the values are in (DN of a raw frame, or normalised linear values);
variances are in those units squared. With ``mu`` in DN and the photon-transfer model of EMVA
1288 (``sigma_y^2 = K^2 sigma_d^2 + sigma_q^2 + K (mu_y - mu_y.dark)``, shot noise of the
electrons), ``K`` is the overall system gain in DN per electron and ``sigma_read`` the dark
temporal noise in DN (quantisation included); in normalised units ``K`` is the value of one
electron in those units. Note that the shot-noise slope is ``K`` itself (DN/e-): ``1 / K``
(electrons per DN, the "conversion gain" of photon-transfer papers) is reported beside it.

A one-frame estimate counts every spatial variation within a patch as noise: fixed-pattern
noise (PRNU grows as ``mu^2``) and illumination shading raise the variances of the bright
patches and so the fitted ``K``; :func:`temporal_and_fixed_pattern` separates the two where
several frames exist.

Refusals raise :class:`RefusedFit` (an :class:`~fidelity.core.errors.InvalidValueError`)
whose message names the problem and whose ``reason`` is one of :data:`REFUSALS`.

References
----------
EMVA Standard 1288, Standard for Characterization of Image Sensors and Cameras, Release 4.0
(2021): the photon transfer method, the temporal noise of two frames, the spatial variance of a
stack of L frames (``s^2_y = s^2_y.measured - sigma^2_y.stack / L``) and its row, column and
pixel parts.
ISO 15739:2013, Photography -- Electronic still-picture imaging -- Noise measurements (SNR of
a patch).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.core.errors import InvalidValueError, RefusedMeasurement
from fidelity.core.fileio import finite_or_none
from fidelity.core.numeric import median
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Luminance weights (ITU-R BT.709 / sRGB Y from linear R, G, B).
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
#: Channel names of :class:`PatchNoise`, in order.
CHANNELS: tuple[str, ...] = ("R", "G", "B", "Y")
#: Smallest SNR of G at which the chroma noise (ratios to G) is stated.
MIN_CHROMA_SNR = 3.0
#: Reflectance of the grey patch whose SNR :func:`photon_transfer` states by default.
GREY_REFLECTANCE = 0.18
#: IRLS passes of the photon-transfer fit (weights from the fitted line).
PTC_ITERATIONS = 5
#: A predicted variance weighs as at least this share of the median positive measured one (a
#: line through 0 at a dark patch would otherwise weigh it without bound).
WEIGHT_FLOOR = 0.01
#: Variances at or below this share of the largest squared mean count as 0 (rounding).
ZERO_VARIANCE = 1e-24
#: The ``reason`` codes of :class:`RefusedFit`.
REFUSALS: tuple[str, ...] = ("shape", "non-finite", "too-few", "singular", "zero-variance",
                             "negative-slope")

PATCH_METHOD = ("per-pixel sample statistics in linear light; chroma noise = relative standard "
                "deviations of the per-pixel ratios R/G and B/G")
PTC_METHOD = ("one-frame photon transfer: iteratively reweighted least squares of patch "
              "variance on mean, weights (n - 1) / (2 sigma^4 deff) from the fitted line, "
              "covariance scaled by the reduced chi-squared where above 1")
FRAME_METHOD = ("EMVA 1288 Release 4.0: temporal variance from the frames' differences (each "
                "frame's mean offset removed), spatial variance of the mean frame less "
                "sigma^2_temp / L, with its column, row and pixel parts")


class RefusedFit(RefusedMeasurement):
    """Input the noise measurement cannot use: the message names the problem.

    Parameters
    ----------
    reason
        One of :data:`REFUSALS` (machine-readable).
    message
        The one-line message (``<input>: <problem>``).

    Attributes
    ----------
    reason
        One of :data:`REFUSALS`.
    """



def _snr(mean: float, sigma: float) -> float:
    """``mean / sigma``: inf for a noiseless non-zero mean, NaN for a noiseless zero."""
    if sigma > 0:
        return mean / sigma
    return math.nan if mean == 0 else math.copysign(math.inf, mean)


def _db(ratio: float) -> float:
    """``20 log10(ratio)``: -inf for 0, NaN for a negative or NaN ratio."""
    if not ratio >= 0:
        return math.nan
    return -math.inf if ratio == 0 else 20.0 * math.log10(ratio)


def variance_uncertainty(x: ArrayLike, *, design_effect: float = 1.0) -> tuple[float, float]:
    """The sample variance of ``x`` and its standard uncertainty.

    ``u^2(s^2) = deff (m4 - (n - 3) / (n - 1) s^4) / n``, with ``m4`` the sample fourth central
    moment: the variance of a sample variance (``2 s^4 / (n - 1)`` for normal data), times the
    design effect ``deff`` of correlated pixels (``n / deff`` independent ones).

    Parameters
    ----------
    x
        The samples, shape ``(n,)``, n >= 2, finite.
    design_effect
        ``deff`` >= 1 (1: independent pixels; demosaicing, denoising or compression raise it).

    Returns
    -------
    tuple of float
        ``(s^2, u(s^2))`` in the samples' units squared, both >= 0.

    Raises
    ------
    RefusedFit
        Fewer than 2 samples or non-finite values.
    fidelity.core.errors.InvalidValueError
        ``design_effect`` below 1 or not finite.

    References
    ----------
    EMVA 1288 Release 4.0 (the variance of a variance estimate); H. Cramér, Mathematical
    Methods of Statistics (1946), 27.4 (the variance of the sample variance).
    """
    a = np.asarray(x, dtype=np.float64).ravel()
    _check_deff(design_effect)
    n = a.size
    if n < 2:
        raise RefusedFit("too-few", f"samples: {n} values; a variance needs at least 2")
    if not np.all(np.isfinite(a)):
        raise RefusedFit("non-finite", "samples: NaN or Inf values")
    if a.min() == a.max():  # exactly 0, not the rounding of a mean of equal values
        return 0.0, 0.0
    d = a - a.mean()
    d2 = d * d
    s2 = float(d2.sum()) / (n - 1)
    # the fourth moment by numpy's own summation, not a BLAS dot product: OpenBLAS splits a
    # long dot product over its threads (its last digits then depend on the machine's core
    # count) and waking them costs more than the sum on a busy machine (issue 59)
    m4 = float((d2 * d2).sum()) / n
    var = design_effect * (m4 - (n - 3) / (n - 1) * s2 * s2) / n
    return s2, float(math.sqrt(max(0.0, var)))


def _check_deff(design_effect: float) -> None:
    if not (math.isfinite(design_effect) and design_effect >= 1.0):
        raise InvalidValueError(f"{design_effect}: design effect must be finite and >= 1")


@record
class ChannelNoise:
    """One channel's noise in a patch (:func:`patch_noise`).

    Attributes
    ----------
    channel
        ``"R"``, ``"G"``, ``"B"`` or ``"Y"`` (luminance).
    mean
        Mean of the pixels (the values' units).
    variance
        Sample variance (``ddof = 1``; units squared).
    u_variance
        Standard uncertainty of ``variance`` (:func:`variance_uncertainty`).
    sigma
        ``sqrt(variance)``.
    snr
        ``mean / sigma`` (inf for a noiseless patch, NaN for a noiseless zero).
    snr_db
        ``20 log10(snr)`` (dB).
    """

    channel: str
    mean: float
    variance: float
    u_variance: float
    sigma: float
    snr: float
    snr_db: float

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; non-finite SNRs as None."""
        return {"channel": self.channel, "mean": self.mean, "variance": self.variance,
                "u_variance": self.u_variance, "sigma": self.sigma,
                "snr": finite_or_none(self.snr), "snr_db": finite_or_none(self.snr_db)}


@record
class PatchNoise:
    """The noise of one patch in linear light (:func:`patch_noise`).

    Attributes
    ----------
    channels
        R, G, B and Y (:data:`CHANNELS`), one :class:`ChannelNoise` each.
    chroma_r
        Relative standard deviation of the per-pixel ratio R/G (unitless); None where G's SNR
        is below :data:`MIN_CHROMA_SNR` or a mean ratio is not positive.
    chroma_b
        The same of B/G.
    chroma
        ``sqrt(chroma_r^2 + chroma_b^2)``, the chroma noise (None as above).
    n
        Pixels measured.
    design_effect
        The design effect the variances' uncertainties carry.
    method
        :data:`PATCH_METHOD`.
    """

    channels: tuple[ChannelNoise, ...]
    chroma_r: float | None
    chroma_b: float | None
    chroma: float | None
    n: int
    design_effect: float
    method: str = PATCH_METHOD

    def channel(self, name: str) -> ChannelNoise:
        """The :class:`ChannelNoise` of ``name`` (``"R"``, ``"G"``, ``"B"``, ``"Y"``).

        Parameters
        ----------
        name
            A name of :data:`CHANNELS`.

        Returns
        -------
        ChannelNoise
            That channel's noise.

        Raises
        ------
        KeyError
            Not a channel name.
        """
        for c in self.channels:
            if c.channel == name:
                return c
        raise KeyError(name)

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, ``channels`` as a list of :meth:`ChannelNoise.to_json`."""
        return {"channels": [c.to_json() for c in self.channels],
                "chroma_r": finite_or_none(self.chroma_r), "chroma_b": finite_or_none(self.chroma_b),
                "chroma": finite_or_none(self.chroma), "n": self.n,
                "design_effect": self.design_effect, "method": self.method}


def patch_noise(samples: ArrayLike, *, design_effect: float = 1.0) -> PatchNoise:
    """The noise of one patch's pixels in linear light.

    Per channel and for the luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` (per pixel): the
    mean, the sample variance (``ddof = 1``) and its standard uncertainty
    (:func:`variance_uncertainty`), ``sigma``, the SNR ``mu / sigma`` and ``20 log10`` of it.
    The chroma noise is measured on the per-pixel ratios ``R/G`` and ``B/G`` (white balance and
    exposure free, in linear light, as Imatest's chroma noise measures the spread of the
    pixels' colour without their lightness): the standard deviation of each ratio over its
    mean, and their root sum of squares. It is not stated (None) where G's SNR is below
    :data:`MIN_CHROMA_SNR` (a ratio to a noisy G has no useful spread) or a mean ratio is not
    positive.

    Parameters
    ----------
    samples
        The patch's pixels, shape ``(n, 3)``: linear R, G, B (any unit; an encoded image must
        be decoded first), n >= 2, finite.
    design_effect
        ``deff`` >= 1 of correlated pixels (:func:`variance_uncertainty`).

    Returns
    -------
    PatchNoise
        R, G, B and Y's :class:`ChannelNoise`, the chroma noise, ``n``.

    Raises
    ------
    RefusedFit
        Not ``(n, 3)``, fewer than 2 pixels, non-finite values.
    fidelity.core.errors.InvalidValueError
        ``design_effect`` below 1.

    References
    ----------
    ISO 15739:2013 (the SNR of a patch); EMVA 1288 Release 4.0 (variances in linear light).
    """
    a = np.asarray(samples, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise RefusedFit("shape", f"samples: must have shape (n, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise RefusedFit("non-finite", f"samples: {int(np.sum(~np.isfinite(a)))} NaN or Inf "
                                       "values")
    _check_deff(design_effect)
    if a.shape[0] < 2:
        raise RefusedFit("too-few", f"samples: {a.shape[0]} pixels; a variance needs 2")
    wr, wg, wb = LUMINANCE_WEIGHTS
    columns = [a[:, 0], a[:, 1], a[:, 2], wr * a[:, 0] + wg * a[:, 1] + wb * a[:, 2]]
    channels = []
    for name, x in zip(CHANNELS, columns, strict=True):
        s2, u = variance_uncertainty(x, design_effect=design_effect)
        mean = float(x.mean())
        sigma = math.sqrt(s2)
        snr = _snr(mean, sigma)
        channels.append(ChannelNoise(name, mean, s2, u, sigma, snr, _db(snr)))
    chroma_r = chroma_b = chroma = None
    g = channels[1]
    if g.mean > 0 and not g.snr < MIN_CHROMA_SNR:
        ok = a[:, 1] > 0
        if int(ok.sum()) >= 2:
            rr, bb = a[ok, 0] / a[ok, 1], a[ok, 2] / a[ok, 1]
            if rr.mean() > 0 and bb.mean() > 0:
                chroma_r = float(rr.std(ddof=1) / rr.mean())
                chroma_b = float(bb.std(ddof=1) / bb.mean())
                chroma = math.hypot(chroma_r, chroma_b)
    return PatchNoise(tuple(channels), chroma_r, chroma_b, chroma, int(a.shape[0]),
                      float(design_effect))


# --------------------------------------------------------------------------------------------
# photon transfer


@record
class PhotonTransfer:
    """The one-frame photon-transfer estimate (:func:`photon_transfer`).

    All values in the input's units (module docstring: with DN, ``gain`` is EMVA 1288's ``K``
    in DN per electron). Standard uncertainties are k = 1, from the fit's covariance.

    Attributes
    ----------
    read_variance
        The line's intercept ``sigma_read^2`` (units squared; may be negative within its
        uncertainty when the read noise is small).
    u_read_variance
        Its standard uncertainty.
    read_noise
        ``sqrt(max(read_variance, 0))``: the read (dark temporal) noise, quantisation included.
    u_read_noise
        Its standard uncertainty, ``u(sigma_read^2) / (2 sigma_read)``; ``sqrt(u(sigma^2))``
        where ``sigma_read`` is 0.
    gain
        The slope ``K``: the value of one electron (DN/e- for DN).
    u_gain
        Its standard uncertainty.
    electrons_per_unit
        ``1 / K`` (e-/DN for DN).
    read_noise_electrons
        ``read_noise / K``: the read noise in electrons.
    covariance
        The fit's covariance of (intercept, slope), row by row.
    chi2
        The fit's chi-squared with its weights.
    dof
        Degrees of freedom (patches - 2).
    patches
        Patches fitted.
    black_level
        The black level taken off the means.
    grey_mean
        The mean (black level off) at which ``snr_grey`` is stated; None: not stated.
    snr_grey
        SNR on the line at ``grey_mean``, ``mu / sqrt(sigma_read^2 + K mu)``.
    snr_grey_db
        ``20 log10(snr_grey)``.
    saturation
        The saturation level (black level off) of the dynamic range; None: not given.
    mu_min
        The mean where the line's SNR is 1: ``mu = sigma(mu)``,
        ``(K + sqrt(K^2 + 4 sigma_read^2)) / 2`` (EMVA 1288's absolute sensitivity threshold,
        in the values' units).
    u_mu_min
        Its standard uncertainty (first-order propagation of the covariance).
    dynamic_range
        ``saturation / mu_min``; None without a saturation level.
    dynamic_range_db
        ``20 log10(dynamic_range)``.
    dynamic_range_stops
        ``log2(dynamic_range)``.
    u_dynamic_range_db
        Standard uncertainty of ``dynamic_range_db``.
    method
        :data:`PTC_METHOD`.
    """

    read_variance: float
    u_read_variance: float
    read_noise: float
    u_read_noise: float
    gain: float
    u_gain: float
    electrons_per_unit: float
    read_noise_electrons: float
    covariance: tuple[tuple[float, float], tuple[float, float]]
    chi2: float
    dof: int
    patches: int
    black_level: float
    grey_mean: float | None
    snr_grey: float | None
    snr_grey_db: float | None
    saturation: float | None
    mu_min: float
    u_mu_min: float
    dynamic_range: float | None
    dynamic_range_db: float | None
    dynamic_range_stops: float | None
    u_dynamic_range_db: float | None
    method: str = PTC_METHOD

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, ``covariance`` as a nested list; non-finite values as None."""
        out: dict[str, Any] = {}
        for key, value in self.__dict__.items():
            if key == "covariance":
                out[key] = [list(row) for row in value]
            elif isinstance(value, float):
                out[key] = finite_or_none(value)
            else:
                out[key] = value
        return out


def _vector(values: ArrayLike, name: str) -> F64:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 1:
        raise RefusedFit("shape", f"{name}: must be 1-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise RefusedFit("non-finite", f"{name}: NaN or Inf values")
    return a


def photon_transfer(means: ArrayLike, variances: ArrayLike, counts: ArrayLike, *,
                    black_level: float = 0.0, saturation: float | None = None,
                    grey_mean: float | None = None,
                    design_effect: float = 1.0) -> PhotonTransfer:
    """The one-frame photon-transfer estimate on a chart's neutral patches.

    Fits ``sigma^2(mu) = sigma_read^2 + K mu`` (``mu`` the patch mean less the black level) by
    iteratively reweighted least squares: each patch weighted by the inverse variance of its
    sample variance, ``(n - 1) / (2 sigma^4(mu) deff)``, ``sigma^2(mu)`` from the fitted line
    (:data:`PTC_ITERATIONS` passes after an unweighted first one; a predicted variance is
    taken as at least :data:`WEIGHT_FLOOR` of the median positive measured one). The
    parameters' covariance is the weighted fit's ``(X^T W X)^-1``, scaled by the reduced
    chi-squared where that exceeds 1 (a line that does not fit widens its uncertainty).

    From the line: the SNR at the grey patch ``grey_mean / sigma(grey_mean)``, and the dynamic
    range from ``mu_min``, where the SNR is 1 (``mu = sigma(mu)``: EMVA 1288's absolute
    sensitivity threshold in the values' units, ``(K + sqrt(K^2 + 4 sigma_read^2)) / 2`` with
    a negative intercept taken as 0), to the saturation level: ``saturation / mu_min``, in dB
    (``20 log10``) and stops (``log2``).

    Parameters
    ----------
    means
        The patches' means, shape ``(k,)``, in the values' units (DN of a raw frame, or
        normalised linear values), black level included unless ``black_level`` is 0.
    variances
        The patches' sample variances, shape ``(k,)``, units squared, >= 0 (one frame: each
        patch's spatial variance, :func:`patch_noise`).
    counts
        Pixels per patch, shape ``(k,)``, each >= 2.
    black_level
        Subtracted from ``means`` (and ``saturation``): the signal of no light. The intercept
        confounds it with the read noise, so it must be known (the camera's metadata, a dark
        frame).
    saturation
        The saturation level in the ``means``' units (black level included); None: no
        dynamic range, and no default grey.
    grey_mean
        The grey patch's mean (black level included) for ``snr_grey``; None:
        :data:`GREY_REFLECTANCE` of the range from black level to ``saturation`` (none without
        a saturation level).
    design_effect
        ``deff`` >= 1 of correlated pixels (the variances' weights).

    Returns
    -------
    PhotonTransfer
        Read noise and gain with their uncertainties, the grey patch's SNR, the dynamic range.

    Raises
    ------
    RefusedFit
        Shapes that differ or are not 1-D, non-finite values, fewer than 2 patches or a count
        below 2 (``too-few``), fewer than 2 distinct means (``singular``), every variance 0
        (``zero-variance``: a noiseless or posterised chart), a slope that is not positive
        (``negative-slope``: the noise does not grow with the signal).
    fidelity.core.errors.InvalidValueError
        ``design_effect`` below 1, a ``saturation`` not above the black level.

    References
    ----------
    EMVA 1288 Release 4.0: the photon transfer method (the slope ``K``), the absolute
    sensitivity threshold (SNR = 1), the dynamic range ``mu_sat / mu_min``.
    """
    mu = _vector(means, "means") - float(black_level)
    var = _vector(variances, "variances")
    n = _vector(counts, "counts")
    _check_deff(design_effect)
    if not mu.shape == var.shape == n.shape:
        raise RefusedFit("shape", f"means, variances, counts: shapes differ ({mu.shape}, "
                                  f"{var.shape}, {n.shape})")
    k = mu.size
    if k < 2 or np.any(n < 2):
        raise RefusedFit("too-few", f"patches: {k} patches with counts {n.tolist()}; the fit "
                                    "needs at least 2 patches of at least 2 pixels")
    if np.any(var < 0):
        raise RefusedFit("shape", "variances: negative values")
    if not np.any(mu != mu[0]):  # one level (finite, k >= 2); np.unique imports np.ma
        raise RefusedFit("singular", f"means: all {k} patches at one level ({mu[0]:g}); the "
                                     "line needs at least 2 distinct means")
    if not np.any(var > ZERO_VARIANCE * float(np.max(mu * mu))):
        raise RefusedFit("zero-variance", "variances: all zero (a noiseless or posterised "
                                          "chart has no photon transfer to fit)")
    x = np.stack([np.ones(k), mu], axis=1)
    floor = WEIGHT_FLOOR * median(var[var > 0])  # some var > 0: checked above
    pred = np.ones(k)  # the first pass unweighted (a posterised patch's 0 is no weight)
    beta: F64 = np.zeros(2)
    for _ in range(PTC_ITERATIONS):
        w = (n - 1.0) / (2.0 * pred * pred * design_effect)
        xtwx = x.T @ (x * w[:, None])
        try:
            beta = np.asarray(np.linalg.solve(xtwx, x.T @ (w * var)), dtype=np.float64)
        except np.linalg.LinAlgError as e:
            raise RefusedFit("singular", "means: the photon-transfer fit is singular") from e
        pred = np.maximum(x @ beta, floor)
    w = (n - 1.0) / (2.0 * pred * pred * design_effect)
    xtwx = x.T @ (x * w[:, None])
    resid = var - x @ beta
    chi2 = float(np.sum(w * resid * resid))
    dof = k - 2
    cov = np.linalg.inv(xtwx)
    if dof > 0 and chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)
    a, gain = float(beta[0]), float(beta[1])
    if not gain > 0:
        raise RefusedFit("negative-slope", f"variances: the photon-transfer slope {gain:.4g} "
                                           "is not positive (noise does not grow with signal)")
    u_a, u_gain = math.sqrt(max(0.0, float(cov[0, 0]))), math.sqrt(max(0.0, float(cov[1, 1])))
    read = math.sqrt(max(a, 0.0))
    u_read = u_a / (2.0 * read) if read > 0 else math.sqrt(u_a)
    a0 = max(a, 0.0)
    root = math.sqrt(gain * gain + 4.0 * a0)
    mu_min = 0.5 * (gain + root)
    grad = np.array([1.0 / root if a > 0 else 0.0, 0.5 * (1.0 + gain / root)])
    u_mu_min = float(math.sqrt(max(0.0, float(grad @ cov @ grad))))
    sat: float | None = None
    if saturation is not None:
        sat = float(saturation) - float(black_level)
        if not sat > 0:
            raise InvalidValueError(f"{saturation}: saturation must be above the black level "
                                    f"{black_level}")
    grey: float | None
    if grey_mean is not None:
        grey = float(grey_mean) - float(black_level)
    else:
        grey = None if sat is None else GREY_REFLECTANCE * sat
    snr_grey = snr_grey_db = None
    if grey is not None:
        s2 = a0 + gain * grey
        snr_grey = _snr(grey, math.sqrt(s2)) if s2 > 0 else math.inf
        snr_grey_db = _db(snr_grey)
    dr = dr_db = dr_stops = u_dr_db = None
    if sat is not None:
        dr = sat / mu_min
        dr_db = 20.0 * math.log10(dr)
        dr_stops = math.log2(dr)
        u_dr_db = 20.0 / math.log(10.0) * u_mu_min / mu_min
    return PhotonTransfer(
        read_variance=a, u_read_variance=u_a, read_noise=read, u_read_noise=u_read, gain=gain,
        u_gain=u_gain, electrons_per_unit=1.0 / gain, read_noise_electrons=read / gain,
        covariance=((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1]))),
        chi2=chi2, dof=dof, patches=k, black_level=float(black_level), grey_mean=grey,
        snr_grey=snr_grey, snr_grey_db=snr_grey_db, saturation=sat, mu_min=mu_min,
        u_mu_min=u_mu_min, dynamic_range=dr, dynamic_range_db=dr_db,
        dynamic_range_stops=dr_stops, u_dynamic_range_db=u_dr_db)


# --------------------------------------------------------------------------------------------
# several frames


@record
class FrameNoise:
    """Temporal and fixed-pattern noise of a stack of frames (:func:`temporal_and_fixed_pattern`).

    Attributes
    ----------
    frames
        ``L``, the frames.
    rows
        ``M``, rows of a frame.
    columns
        ``N``, columns of a frame.
    mean
        Mean over every pixel of every frame.
    temporal_variance
        ``sigma^2_y``: the mean over pixels of each pixel's variance over the frames
        (``ddof = 1``) after each frame's mean offset is removed; for two frames EMVA 1288's
        ``(1 / 2NM) sum((y_A - mu_A) - (y_B - mu_B))^2``, i.e. ``var(A - B) / 2``.
    u_temporal_variance
        Its standard uncertainty, ``sigma^2_y sqrt(2 / (M N (L - 1)))`` (normal data).
    temporal_noise
        ``sqrt(temporal_variance)``.
    spatial_variance
        ``s^2_y = s^2_y.measured - sigma^2_y / L``: the variance over pixels of the mean frame
        (``ddof = 1``) less the temporal variance the average keeps (EMVA 1288 4.0); may be
        slightly negative without fixed-pattern noise.
    u_spatial_variance
        Its standard uncertainty (normal data): ``s^2_y.measured sqrt(2 / (M N - 1))`` and
        ``u(sigma^2_y) / L`` combined in quadrature.
    fixed_pattern_noise
        ``sqrt(max(spatial_variance, 0))`` (DSNU in the dark, PRNU times the mean when lit).
    column_variance
        ``s^2_y.col``: the part of ``spatial_variance`` that columns share (EMVA 1288 4.0).
    row_variance
        ``s^2_y.row``: the part that rows share.
    pixel_variance
        ``s^2_y.pixel``: the rest, pixel to pixel.
    frame_means
        Each frame's mean.
    method
        :data:`FRAME_METHOD`.
    """

    frames: int
    rows: int
    columns: int
    mean: float
    temporal_variance: float
    u_temporal_variance: float
    temporal_noise: float
    spatial_variance: float
    u_spatial_variance: float
    fixed_pattern_noise: float
    column_variance: float
    row_variance: float
    pixel_variance: float
    frame_means: tuple[float, ...]
    method: str = FRAME_METHOD

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, ``frame_means`` as a list."""
        out = dict(self.__dict__)
        out["frame_means"] = list(self.frame_means)
        return out


def temporal_and_fixed_pattern(frames: ArrayLike) -> FrameNoise:
    """Temporal and fixed-pattern noise of several frames of one flat region (EMVA 1288 4.0).

    Temporal: each frame's mean offset from the stack's mean is removed (a drift of the level
    between frames is not noise), then the mean over pixels of each pixel's variance over the
    frames (``ddof = 1``). For two frames A, B this is EMVA 1288's
    ``sigma^2_y = (1 / 2NM) sum((y_A - mu_A) - (y_B - mu_B))^2``, i.e. ``var(A - B) / 2``.

    Fixed pattern: the mean frame ``<y>``'s spatial variance ``s^2_y.measured`` (``ddof = 1``)
    keeps ``sigma^2_y / L`` of the temporal noise, which is taken off:
    ``s^2_y = s^2_y.measured - sigma^2_y / L``. Its column and row parts (EMVA 1288 4.0): with
    ``s^2_y.cav`` the variance (``ddof = 0``) of the column means less ``sigma^2_y / (L M)`` and
    ``s^2_y.rav`` that of the row means less ``sigma^2_y / (L N)``,
    ``s^2_y.col = ((MN - M) s^2_y.cav - N (s^2_y - s^2_y.rav)) / (MN - M - N)``,
    ``s^2_y.row`` likewise, ``s^2_y.pixel = MN (s^2_y - s^2_y.cav - s^2_y.rav) / (MN - M - N)``.

    Parameters
    ----------
    frames
        Shape ``(L, M, N)``: L >= 2 frames of M x N pixels (M, N >= 2) of the same flat region
        at the same exposure, linear values (DN or normalised), finite.

    Returns
    -------
    FrameNoise
        The temporal variance with its uncertainty, the spatial (fixed-pattern) variance and
        its column, row and pixel parts.

    Raises
    ------
    RefusedFit
        Not 3-D, fewer than 2 frames or fewer than 2 rows or columns, non-finite values.

    References
    ----------
    EMVA 1288 Release 4.0: the temporal variance of two frames, the spatial variance of the
    average of L frames (``s^2_y.measured - sigma^2_y.stack / L``), its column, row and pixel
    variances.
    """
    a = np.asarray(frames, dtype=np.float64)
    if a.ndim != 3:
        raise RefusedFit("shape", f"frames: must have shape (frames, rows, columns), got "
                                  f"{a.shape}")
    big_l, m, nn = a.shape
    if big_l < 2 or m < 2 or nn < 2:
        raise RefusedFit("too-few", f"frames: shape {a.shape}; at least 2 frames of 2 x 2 "
                                    "pixels")
    if not np.all(np.isfinite(a)):
        raise RefusedFit("non-finite", f"frames: {int(np.sum(~np.isfinite(a)))} NaN or Inf "
                                       "values")
    frame_means = a.mean(axis=(1, 2))
    grand = float(frame_means.mean())
    centred = a - (frame_means - grand)[:, None, None]
    temporal = float(np.mean(np.var(centred, axis=0, ddof=1)))
    u_temporal = temporal * math.sqrt(2.0 / (m * nn * (big_l - 1)))
    avg = a.mean(axis=0)
    measured = float(np.var(avg, ddof=1))
    spatial = measured - temporal / big_l
    mu = float(avg.mean())
    cav = float(np.mean((avg.mean(axis=0) - mu) ** 2)) - temporal / (big_l * m)
    rav = float(np.mean((avg.mean(axis=1) - mu) ** 2)) - temporal / (big_l * nn)
    mn = m * nn
    den = mn - m - nn
    col = ((mn - m) * cav - nn * (spatial - rav)) / den
    row = ((mn - nn) * rav - m * (spatial - cav)) / den
    pix = mn * (spatial - cav - rav) / den
    return FrameNoise(frames=big_l, rows=m, columns=nn, mean=grand, temporal_variance=temporal,
                      u_temporal_variance=u_temporal, temporal_noise=math.sqrt(temporal),
                      spatial_variance=spatial,
                      u_spatial_variance=math.hypot(measured * math.sqrt(2.0 / (m * nn - 1)),
                                                    u_temporal / big_l),
                      fixed_pattern_noise=math.sqrt(max(spatial, 0.0)), column_variance=col,
                      row_variance=row, pixel_variance=pix,
                      frame_means=tuple(float(v) for v in frame_means))
