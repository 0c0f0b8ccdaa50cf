"""Sharpness and noise, simulation against real camera: the two charts' curves side by side.

:func:`texture_comparison` takes the two audits of :func:`fidelity.pipeline.compare.compare_charts`
and keeps, for each side (:class:`TextureSide`), the luminance MTF curve of its softer measured
edge (the edge :func:`fidelity.prediction.properties.chart_mtf50` takes the chart's MTF50 from)
and its neutral patches' noise points (mean ``mu`` with the black level off, standard deviation
``sigma`` of the photon-transfer channel, :data:`fidelity.measure.chartnoise.PTC_CHANNEL`) with
the photon-transfer fit ``sigma^2(mu) = sigma_read^2 + K mu`` or its refusal; then the MTF50
ratio (simulation over real, at each chart's own resolution) and the SNR difference at the
18 % grey in dB (simulation minus real). Where one side's sharpness or noise was not measured
or was refused, that comparison is None and ``not_compared`` says why.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from fidelity.core.fileio import finite_or_none, optional_float
from fidelity.core.record import record
from fidelity.measure.chartnoise import PTC_CHANNEL
from fidelity.prediction.properties import chart_mtf50


@record
class TextureSide:
    """One chart's sharpness and noise curves.

    Attributes
    ----------
    mtf50
        The luminance MTF50 of the softer measured edge (cy/px); None: none measured.
    direction
        That edge's direction (``"horizontal"``/``"vertical"``); None with no MTF50.
    method
        How its curve was measured (``"e-SFR"`` or ``"edge fit"``); None with no MTF50.
    frequencies, mtf
        Its luminance MTF curve (cy/px, unitless); empty where not kept.
    patches
        The neutral patches' names (chart order); empty: noise not measured.
    mu, sigma
        Each neutral patch's mean (black level off) and standard deviation of the
        photon-transfer channel (the image's linear units).
    read_variance, gain
        The photon-transfer line ``sigma^2 = read_variance + gain mu``; None where refused.
    fit_refusal
        Why the photon-transfer fit was refused; None where fitted or not measured.
    grey_snr, grey_snr_db
        SNR of the 18 % grey patch's luminance (``mu / sigma``) and in dB; None: noise not
        measured.
    sharpness_missing, noise_missing
        Why there is no MTF50, no noise (None where there is).
    """

    mtf50: float | None
    direction: str | None
    method: str | None
    frequencies: tuple[float, ...]
    mtf: tuple[float, ...]
    patches: tuple[str, ...]
    mu: tuple[float, ...]
    sigma: tuple[float, ...]
    read_variance: float | None
    gain: float | None
    fit_refusal: str | None
    grey_snr: float | None
    grey_snr_db: float | None
    sharpness_missing: str | None = None
    noise_missing: str | None = None

    def to_json(self) -> dict[str, Any]:
        """``mtf50``, ``direction``, ``method``, ``curve`` ``{frequencies, mtf}``, ``noise``
        ``{patches, mu, sigma}``, ``photon_transfer`` ``{read_variance, gain}`` or None,
        ``fit_refusal``, ``grey_snr``, ``grey_snr_db`` and the two ``missing`` reasons."""
        fin = finite_or_none
        return {"mtf50": fin(self.mtf50), "direction": self.direction, "method": self.method,
                "curve": {"frequencies": list(self.frequencies), "mtf": list(self.mtf)},
                "noise": {"patches": list(self.patches), "mu": list(self.mu),
                          "sigma": list(self.sigma)},
                "photon_transfer": (None if self.read_variance is None or self.gain is None
                                    else {"read_variance": self.read_variance,
                                          "gain": self.gain}),
                "fit_refusal": self.fit_refusal, "grey_snr": fin(self.grey_snr),
                "grey_snr_db": fin(self.grey_snr_db),
                "sharpness_missing": self.sharpness_missing,
                "noise_missing": self.noise_missing}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TextureSide:
        """Inverse of :meth:`to_json` (an infinite SNR, written as None, reads back None)."""
        c, n, pt = d["curve"], d["noise"], d.get("photon_transfer")
        return cls(optional_float(d.get("mtf50")), d.get("direction"), d.get("method"),
                   tuple(float(v) for v in c["frequencies"]), tuple(float(v) for v in c["mtf"]),
                   tuple(str(v) for v in n["patches"]), tuple(float(v) for v in n["mu"]),
                   tuple(float(v) for v in n["sigma"]),
                   None if pt is None else float(pt["read_variance"]),
                   None if pt is None else float(pt["gain"]), d.get("fit_refusal"),
                   optional_float(d.get("grey_snr")), optional_float(d.get("grey_snr_db")),
                   d.get("sharpness_missing"), d.get("noise_missing"))


@record
class TextureComparison:
    """The simulated chart's sharpness and noise against the real chart's (module docstring).

    Attributes
    ----------
    sim, real
        Each side's :class:`TextureSide`.
    mtf50_ratio
        Simulation's MTF50 over the real camera's; None where either is missing.
    snr_difference_db
        Simulation's grey SNR minus the real camera's, dB; None where either is missing or
        infinite (a noiseless chart).
    not_compared
        ``(property, reason)`` for each of sharpness and noise not compared.
    """

    sim: TextureSide
    real: TextureSide
    mtf50_ratio: float | None
    snr_difference_db: float | None
    not_compared: tuple[tuple[str, str], ...] = ()

    def to_json(self) -> dict[str, Any]:
        """``sim``, ``real``, ``mtf50_ratio``, ``snr_difference_db``, ``not_compared`` as
        ``[{property, reason}]``."""
        return {"sim": self.sim.to_json(), "real": self.real.to_json(),
                "mtf50_ratio": finite_or_none(self.mtf50_ratio),
                "snr_difference_db": finite_or_none(self.snr_difference_db),
                "not_compared": [{"property": p, "reason": r} for p, r in self.not_compared]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TextureComparison:
        """Inverse of :meth:`to_json`."""
        return cls(TextureSide.from_json(d["sim"]), TextureSide.from_json(d["real"]),
                   optional_float(d.get("mtf50_ratio")), optional_float(d.get("snr_difference_db")),
                   tuple((str(x["property"]), str(x["reason"]))
                         for x in d.get("not_compared") or ()))



def texture_side(report: Any) -> TextureSide:
    """One audit's :class:`TextureSide` (``report``: a
    :class:`fidelity.pipeline.records.ChartReport`)."""
    s, n = report.sharpness, report.noise
    mtf50 = direction = method = None
    freqs: tuple[float, ...] = ()
    mtf: tuple[float, ...] = ()
    sharp_missing: str | None = None
    best = chart_mtf50(s)
    if s is None:
        sharp_missing = "sharpness not measured"
    elif best is None:
        sharp_missing = "; ".join(
            f"{e.direction}: {(e.refusal or (y.refusal if y else None) or ('', 'no luminance'))[1]}"
            for e in s.edges for y in (e.channel("Y"),)) or "no edge measured"
    else:
        mtf50 = best[0]
        for e in s.edges:
            y = e.channel("Y") if e.refusal is None else None
            if y is not None and y.refusal is None and y.mtf50 == mtf50:
                direction, method = e.direction, e.method
                if y.curve is not None:
                    freqs, mtf = y.curve
                break
    patches: tuple[str, ...] = ()
    mu: tuple[float, ...] = ()
    sigma: tuple[float, ...] = ()
    read_var = gain = snr = snr_db = None
    fit_refusal = noise_missing = None
    if n is None:
        noise_missing = "noise not measured"
    else:
        black = n.transfer.black_level if n.transfer is not None else 0.0
        chans = [p.channel(PTC_CHANNEL) for p in n.noise]
        patches = tuple(n.patches)
        mu = tuple(float(c.mean) - black for c in chans)
        sigma = tuple(float(c.sigma) for c in chans)
        if n.transfer is not None:
            read_var, gain = float(n.transfer.read_variance), float(n.transfer.gain)
        elif n.refusal is not None:
            fit_refusal = f"{n.refusal[0]}: {n.refusal[1]}"
        snr, snr_db = float(n.grey_snr), float(n.grey_snr_db)
    return TextureSide(mtf50, direction, method, tuple(freqs), tuple(mtf), patches, mu, sigma,
                       read_var, gain, fit_refusal, snr, snr_db, sharp_missing, noise_missing)


def texture_comparison(sim: Any, real: Any) -> TextureComparison:
    """The two audits' sharpness and noise side by side (module docstring); ``sim``,
    ``real``: :class:`fidelity.pipeline.records.ChartReport`."""
    a, b = texture_side(sim), texture_side(real)
    missing: list[tuple[str, str]] = []
    ratio = snr_db = None
    if a.mtf50 is not None and b.mtf50 is not None:
        ratio = a.mtf50 / b.mtf50
    else:
        missing.append(("sharpness", "; ".join(
            f"{who}: {why}" for who, why in (("simulation", a.sharpness_missing),
                                             ("real camera", b.sharpness_missing)) if why)))
    if a.noise_missing is None and b.noise_missing is None:
        if (a.grey_snr_db is not None and b.grey_snr_db is not None
                and math.isfinite(a.grey_snr_db) and math.isfinite(b.grey_snr_db)):
            snr_db = a.grey_snr_db - b.grey_snr_db
        else:
            missing.append(("noise", "a noiseless chart: infinite SNR"))
    else:
        missing.append(("noise", "; ".join(
            f"{who}: {why}" for who, why in (("simulation", a.noise_missing),
                                             ("real camera", b.noise_missing)) if why)))
    return TextureComparison(a, b, ratio, snr_db, tuple(missing))


__all__ = ["TextureComparison", "TextureSide", "texture_comparison", "texture_side"]
