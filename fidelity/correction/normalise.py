"""Match a simulated chart to a real one on the neutral patches before comparing them: its
exposure, and optionally its white balance (``fidelity compare`` and ``fidelity fit``,
``--normalise``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.measure.pixels import luminance_linear_srgb


@dataclass(frozen=True)
class Normalisation:
    """What was matched: the ``mode``, the exposure change applied to the simulated chart
    (``exposure_ev``, EV; 0 for ``none``) and the per-channel ``gains`` (``exposure+wb``:
    R, G, B, including the exposure; None otherwise)."""

    mode: str
    exposure_ev: float
    gains: tuple[float, float, float] | None = None

    def describe(self) -> str:
        """In words, for reports."""
        if self.mode == "none":
            return "none: the charts compared as audited"
        text = f"exposure of the simulation {self.exposure_ev:+z.3f} EV (neutral patches)"
        if self.gains is not None:
            g = ", ".join(f"{v:.4f}" for v in self.gains)
            text += f"; white balance gains R, G, B {g} (neutral patches, incl. exposure)"
        return text

    def to_json(self) -> dict[str, Any]:
        """``{"mode", "exposure_ev", "gains", "description"}``."""
        return {"mode": self.mode, "exposure_ev": self.exposure_ev,
                "gains": list(self.gains) if self.gains is not None else None,
                "description": self.describe()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Normalisation:
        """Inverse of :meth:`to_json`."""
        g = d.get("gains")
        return cls(str(d["mode"]), float(d["exposure_ev"]),
                   (float(g[0]), float(g[1]), float(g[2])) if g else None)



#: How the simulated chart is matched to the real one before comparing (:func:`normalise`).
NORMALISATIONS: tuple[str, ...] = ("exposure", "exposure+wb", "none")


def normalise(sim_srgb: NDArray[np.float64], real_srgb: NDArray[np.float64],
              neutral: Sequence[int], mode: str = "exposure"
              ) -> tuple[NDArray[np.float64], Normalisation]:
    """Match simulated patch colours (n, 3 encoded sRGB) to the real ones on the ``neutral``
    patches: the exposure (EV, the log mean of the luminance ratios), and for ``exposure+wb`` also
    per-channel gains; returns the normalised encoded sRGB (clipped to [0, 1]) and
    what was done."""
    if mode not in NORMALISATIONS:
        raise unknown_name("normalisation", mode, NORMALISATIONS)
    sim = np.asarray(linearize_srgb(np.clip(sim_srgb, 0.0, 1.0)), np.float64)
    real = np.asarray(linearize_srgb(np.clip(real_srgb, 0.0, 1.0)), np.float64)
    idx = list(neutral)
    if mode == "none" or not idx:
        if mode != "none":
            raise InvalidValueError("the chart has no neutral patches to normalise on; use "
                                    "--normalise none")
        return np.clip(np.asarray(sim_srgb, np.float64), 0.0, 1.0), Normalisation("none", 0.0)
    ys, yr = luminance_linear_srgb(sim[idx]), luminance_linear_srgb(real[idx])
    ok = (ys > 0) & (yr > 0)
    if not np.any(ok):
        raise InvalidValueError("cannot normalise the exposure: the neutral patches are black "
                                "in one of the charts; use --normalise none")
    ev = float(np.mean(np.log2(yr[ok] / ys[ok])))
    sim = sim * 2.0 ** ev
    gains = None
    if mode == "exposure+wb":
        s, r = sim[idx].sum(axis=0), real[idx].sum(axis=0)
        if np.any(s <= 0):
            raise InvalidValueError("cannot normalise the white balance: a channel of the "
                                    "simulated neutral patches is black")
        g = r / s
        sim = sim * g
        gains = (float(g[0] * 2.0 ** ev), float(g[1] * 2.0 ** ev), float(g[2] * 2.0 ** ev))
    out = np.clip(np.asarray(delinearize_srgb(np.clip(sim, 0.0, None)), np.float64), 0.0, 1.0)
    return out, Normalisation(mode, ev, gains)


__all__ = ["NORMALISATIONS", "Normalisation", "normalise"]
