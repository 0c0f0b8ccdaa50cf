"""The noise of a located chart in linear light: each neutral patch's noise, the one-frame
photon transfer over them and the SNR at the 18 % grey patch.

:func:`chart_noise` takes the pixels of the chart's neutral patches' sampling windows (the
windows :func:`fidelity.chart.locate.locate_chart` gives, in LINEAR light: an encoded image
decoded first) and measures

- each neutral patch's noise, :func:`fidelity.measure.noise.patch_noise` (per channel and for
  the luminance Y: mean, variance with its uncertainty, SNR in dB; the chroma noise);
- the photon-transfer line ``sigma^2(mu) = sigma_read^2 + K mu`` of the patches' G means and
  variances (:data:`PTC_CHANNEL`), :func:`fidelity.measure.noise.photon_transfer` (read noise, gain ``K``,
  the dynamic range where the saturation level is known); a fit the method refuses (a
  noiseless or posterised chart, a noise that does not grow with the signal) is stated with its
  reason (:data:`fidelity.measure.noise.REFUSALS`), not raised;
- the SNR of the 18 % grey patch (the chart's ``neutral 5``, or the neutral patch whose
  reference luminance is nearest 0.18), ``mu / sigma`` of its luminance pixels.

Values are in the image's linear units (normalised code values for an integer image: 1 is the
largest code); one frame counts every spatial variation within a patch (fixed-pattern noise,
shading, texture, compression) as noise (:mod:`fidelity.measure.noise`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import optional_float
from fidelity.core.record import record
from fidelity.measure.noise import (
    ChannelNoise,
    PatchNoise,
    PhotonTransfer,
    RefusedFit,
    patch_noise,
    photon_transfer,
)

#: Name of the 18 % grey patch of the ColorChecker (Munsell N5).
GREY_PATCH = "neutral 5"
#: The channel the photon transfer is fitted on: a sensor's noise is per channel (the
#: luminance of independent channels has ``sum w^2`` = 0.56 of their variance), and G carries
#: most of the luminance.
PTC_CHANNEL = "G"
#: Reference luminance of the grey patch looked for where no patch bears :data:`GREY_PATCH`.
GREY_LUMINANCE = 0.18
METHOD = ("per neutral patch: sample statistics of its sampling window's pixels in linear "
          "light; photon transfer: weighted line of the patches' G variance on mean; "
          "SNR at grey: mean / standard deviation of the grey patch's luminance pixels")


def grey_index(names: Sequence[str], neutral: Sequence[int],
               reference_y: Sequence[float] | np.ndarray | None = None) -> int:
    """The chart index of the 18 % grey patch.

    Parameters
    ----------
    names
        The chart's patch names.
    neutral
        Indices of its neutral patches.
    reference_y
        Reference luminance (CIE Y, white = 1) of every patch; None: by name only.

    Returns
    -------
    int
        The index of the patch named :data:`GREY_PATCH`, else of the neutral patch whose
        reference Y is nearest :data:`GREY_LUMINANCE`, else the middle neutral patch.
    """
    for k in neutral:
        if names[k].lower().startswith(GREY_PATCH):
            return int(k)
    if reference_y is not None:
        return int(min(neutral, key=lambda k: abs(float(reference_y[k]) - GREY_LUMINANCE)))
    return int(list(neutral)[len(neutral) // 2])


def _num(x: Any) -> float:
    return math.nan if x is None else float(x)



def _patch_from_json(d: Mapping[str, Any]) -> PatchNoise:
    chans = tuple(ChannelNoise(str(c["channel"]), float(c["mean"]), float(c["variance"]),
                               float(c["u_variance"]), float(c["sigma"]), _num(c["snr"]),
                               _num(c["snr_db"])) for c in d["channels"])
    return PatchNoise(chans, optional_float(d.get("chroma_r")), optional_float(d.get("chroma_b")),
                      optional_float(d.get("chroma")), int(d["n"]), float(d["design_effect"]),
                      str(d["method"]))


def _transfer_from_json(d: Mapping[str, Any]) -> PhotonTransfer:
    optional = {"grey_mean", "snr_grey", "snr_grey_db", "saturation", "dynamic_range",
                "dynamic_range_db", "dynamic_range_stops", "u_dynamic_range_db"}
    kw: dict[str, Any] = {}
    for key, value in d.items():
        if key == "covariance":
            (a, b), (c, e) = value
            kw[key] = ((_num(a), _num(b)), (_num(c), _num(e)))
        elif key in ("dof", "patches"):
            kw[key] = int(value)
        elif key == "method":
            kw[key] = str(value)
        elif key in optional:
            kw[key] = optional_float(value)
        else:
            kw[key] = _num(value)
    return PhotonTransfer(**kw)


@record
class ChartNoise:
    """The noise of a chart's neutral patches (:func:`chart_noise`).

    Attributes
    ----------
    patches
        The neutral patches' names, in chart order.
    noise
        Their :class:`~fidelity.measure.noise.PatchNoise`, in the same order (the image's
        linear units).
    grey_patch
        Name of the 18 % grey patch.
    grey_snr
        ``mu / sigma`` of the grey patch's luminance (unitless; inf for a noiseless patch).
    grey_snr_db
        ``20 log10(grey_snr)`` (dB).
    transfer
        The photon-transfer fit over the neutral patches' G channel; None where refused.
    refusal
        Why the photon-transfer fit was refused: ``(reason, message)`` with ``reason`` one of
        :data:`fidelity.measure.noise.REFUSALS`; None where it was fitted.
    linearisation
        How the pixels were brought to linear light (``"none (linear input)"``, ``"sRGB
        transfer function (IEC 61966-2-1)"``, with any conversion of primaries).
    method
        :data:`METHOD`.
    """

    patches: tuple[str, ...]
    noise: tuple[PatchNoise, ...]
    grey_patch: str
    grey_snr: float
    grey_snr_db: float
    transfer: PhotonTransfer | None
    refusal: tuple[str, str] | None
    linearisation: str
    method: str = METHOD

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``patches`` (each name with its noise), the grey patch's SNR, the
        ``photon_transfer`` fit or None with its ``refusal`` (``reason``, ``message``), the
        ``linearisation`` and ``method``; non-finite numbers as None."""
        def fin(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None
        return {
            "patches": [{"name": n, **p.to_json()}
                        for n, p in zip(self.patches, self.noise, strict=True)],
            "grey_patch": self.grey_patch, "grey_snr": fin(self.grey_snr),
            "grey_snr_db": fin(self.grey_snr_db),
            "photon_transfer": self.transfer.to_json() if self.transfer else None,
            "refusal": ({"reason": self.refusal[0], "message": self.refusal[1]}
                        if self.refusal else None),
            "linearisation": self.linearisation, "method": self.method,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ChartNoise:
        """Inverse of :meth:`to_json` (a None SNR reads as inf)."""
        patches = [dict(p) for p in d["patches"]]
        names = tuple(str(p.pop("name")) for p in patches)
        ref = d.get("refusal")
        return cls(names, tuple(_patch_from_json(p) for p in patches), str(d["grey_patch"]),
                   math.inf if d.get("grey_snr") is None else float(d["grey_snr"]),
                   math.inf if d.get("grey_snr_db") is None else float(d["grey_snr_db"]),
                   (_transfer_from_json(d["photon_transfer"]) if d.get("photon_transfer")
                    else None),
                   (str(ref["reason"]), str(ref["message"])) if ref else None,
                   str(d["linearisation"]), str(d.get("method", METHOD)))


def chart_noise(samples: Sequence[np.ndarray], names: Sequence[str], grey: str, *,
                linearisation: str, saturation: float | None = None,
                black_level: float = 0.0, method: str = METHOD) -> ChartNoise:
    """The noise of a chart's neutral patches from their window pixels in linear light.

    Parameters
    ----------
    samples
        Each neutral patch's valid window pixels, ``(n_k, 3)`` linear R, G, B (the image's
        linear units), n_k >= 2.
    names
        The patches' names, in the same order.
    grey
        The name (one of ``names``) of the 18 % grey patch (:func:`grey_index`).
    linearisation
        How the pixels were linearised (kept in the record).
    saturation
        The saturation level in the pixels' units (1.0 for an integer or display-referred
        image); None: unknown (scene-linear floats), no dynamic range.
    black_level
        The signal of no light, taken off the means of the photon-transfer fit.
    method
        How the samples were taken (kept in the record; default :data:`METHOD`).

    Returns
    -------
    ChartNoise
        Each patch's noise, the grey patch's SNR and the photon transfer (or its refusal).

    Raises
    ------
    fidelity.measure.noise.RefusedFit
        A patch with fewer than 2 pixels or non-finite values (:func:`patch_noise`).
    fidelity.core.errors.InvalidValueError
        ``grey`` not among ``names``, or the lengths differ.
    """
    if len(samples) != len(names):
        raise InvalidValueError(f"{len(samples)} patches of samples for {len(names)} names")
    if grey not in names:
        raise InvalidValueError(f"grey patch {grey!r} is not among the neutral patches")
    noise = tuple(patch_noise(s) for s in samples)
    ys = [p.channel(PTC_CHANNEL) for p in noise]
    g = noise[list(names).index(grey)].channel("Y")
    transfer: PhotonTransfer | None = None
    refusal: tuple[str, str] | None = None
    try:
        transfer = photon_transfer([y.mean for y in ys], [y.variance for y in ys],
                                   [p.n for p in noise], black_level=black_level,
                                   saturation=saturation, grey_mean=g.mean)
    except RefusedFit as e:
        refusal = (e.reason, str(e))
    except InvalidValueError as e:  # a saturation not above the black level
        refusal = ("shape", str(e))
    return ChartNoise(tuple(names), noise, grey, g.snr, g.snr_db, transfer, refusal,
                      linearisation, method)


__all__ = ["GREY_LUMINANCE", "GREY_PATCH", "METHOD", "PTC_CHANNEL", "ChartNoise", "chart_noise", "grey_index"]
