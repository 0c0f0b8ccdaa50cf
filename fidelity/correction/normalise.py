"""Match a simulated chart to a real one on the neutral patches before comparing them: its
exposure, and optionally its white balance (``fidelity compare`` and ``fidelity fit``,
``--normalise``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.measure.pixels import luminance_linear_srgb


@record
class Normalisation:
    """What was matched: the ``mode``, the exposure change applied to the simulated chart
    (``exposure_ev``, EV; 0 for ``none``) and the per-channel ``gains`` (``exposure+wb``:
    R, G, B, including the exposure; None otherwise)."""

    mode: str
    exposure_ev: float
    gains: tuple[float, float, float] | None = None
    #: the exposure correction each image's neutral patches ask for (EV: simulation, real;
    #: None: not recorded), and whether each image's audit applied it (auto exposure)
    neutral_ev: tuple[float, float] | None = None
    audit_auto: tuple[bool, bool] = (False, False)

    @property
    def difference_ev(self) -> float | None:
        """How much brighter the simulation's pixels are than the real camera's, in EV,
        before any exposure correction (``neutral_real - neutral_sim``, from the linear patch
        means: unclipped, whatever the normalisation); None when not recorded."""
        if self.neutral_ev is None:
            return None
        return self.neutral_ev[1] - self.neutral_ev[0] + 0.0

    def describe(self) -> str:
        """In words, for reports."""
        if self.mode == "none":
            text = "none: the charts compared as audited"
        else:
            text = f"exposure of the simulation {self.exposure_ev:+z.3f} EV (neutral patches)"
            if self.gains is not None:
                g = ", ".join(f"{v:.4f}" for v in self.gains)
                text += f"; white balance gains R, G, B {g} (neutral patches, incl. exposure)"
        return text

    def difference_words(self) -> str | None:
        """The exposure difference in words, e.g. ``the simulation's pixels are +2.000 EV
        from the real camera's (neutral patches, before any exposure correction; simulation
        and real image auto-exposed by the audit, which takes it out: --exposure EV keeps
        it)``; None when not recorded."""
        d = self.difference_ev
        if d is None:
            return None
        text = (f"the simulation's pixels are {d:+z.3f} EV from the real camera's (neutral "
                f"patches, before any exposure correction")
        auto = [name for name, a in zip(("simulation", "real image"), self.audit_auto,
                                        strict=True) if a]
        if auto:
            text += (f"; {' and '.join(auto)} auto-exposed by the audit, which takes it out: "
                     f"--exposure EV keeps it")
        return text + ")"

    def to_json(self) -> dict[str, Any]:
        """``{"mode", "exposure_ev", "gains", "neutral_ev", "audit_auto", "difference_ev",
        "description", "difference"}``."""
        return {"mode": self.mode, "exposure_ev": self.exposure_ev,
                "gains": list(self.gains) if self.gains is not None else None,
                "neutral_ev": list(self.neutral_ev) if self.neutral_ev is not None else None,
                "audit_auto": list(self.audit_auto), "difference_ev": self.difference_ev,
                "description": self.describe(), "difference": self.difference_words()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Normalisation:
        """Inverse of :meth:`to_json`."""
        g, a = d.get("gains"), d.get("neutral_ev")
        auto = d.get("audit_auto") or (False, False)
        return cls(str(d["mode"]), float(d["exposure_ev"]),
                   (float(g[0]), float(g[1]), float(g[2])) if g else None,
                   (float(a[0]), float(a[1])) if a else None,
                   (bool(auto[0]), bool(auto[1])))



#: How the simulated chart is matched to the real one before comparing (:func:`normalise`).
NORMALISATIONS: tuple[str, ...] = ("exposure", "exposure+wb", "none")


def normalise(sim_srgb: NDArray[np.float64], real_srgb: NDArray[np.float64],
              neutral: Sequence[int], mode: str = "exposure", *,
              sim_linear: NDArray[np.float64] | None = None
              ) -> tuple[NDArray[np.float64], Normalisation]:
    """Match simulated patch colours (n, 3 encoded sRGB) to the real ones on the ``neutral``
    patches: the exposure (EV, the log mean of the luminance ratios), and for ``exposure+wb`` also
    per-channel gains; returns the normalised encoded sRGB (clipped to [0, 1]) and
    what was done. ``sim_linear``: the simulated patches' linear values (n, 3), unclipped (a
    scene-linear render whose values pass 1), matched instead of ``sim_srgb`` decoded."""
    if mode not in NORMALISATIONS:
        raise unknown_name("normalisation", mode, NORMALISATIONS)
    sim = (np.asarray(linearize_srgb(np.clip(sim_srgb, 0.0, 1.0)), np.float64)
           if sim_linear is None else np.asarray(sim_linear, np.float64))
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
