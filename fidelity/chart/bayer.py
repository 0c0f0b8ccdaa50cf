"""The CFA pattern of a raw mosaic, read from the chart in it.

A one-channel raw frame read without ``--bayer`` is split into half-size R, G, B images for
each of the four Bayer patterns (:func:`superpixels`); the chart finder
(:func:`fidelity.chart.find.cascade.find_chart`) is run on each, and the pattern in which it
finds the chart clearly better than in any other is taken (:func:`bayer_pattern`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fidelity.chart.image import BAYER_PATTERNS
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

#: Least lead in confidence of the best-fitting CFA pattern over the next one (a pattern the
#: finder refuses counts as 0) for a one-channel mosaic's pattern to be taken as found.
BAYER_MARGIN = 0.15


@record
class BayerFit:
    """How each CFA pattern fits a one-channel mosaic: ``confidence`` per pattern (the
    chart finder's, 0 where it found no chart), the ``pattern`` taken (None: none fits
    unambiguously) and the ``margin`` of the best over the next."""

    confidence: Mapping[str, float]
    pattern: str | None
    margin: float

    def describe(self) -> str:
        """The confidences in words: ``RGGB 0.99, BGGR 0.00, ...``."""
        return ", ".join(f"{k} {v:.2f}" for k, v in self.confidence.items())


def superpixels(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """``(H, W)`` Bayer mosaic -> ``(H // 2, W // 2, 3)`` float32 R, G, B: each 2 x 2 block's
    red and blue sample and the mean of its two green ones, for CFA ``pattern``
    (:data:`~fidelity.chart.image.BAYER_PATTERNS`). No interpolation: enough to find a chart,
    cheap for all four."""
    arr = np.asarray(mosaic, dtype=np.float32)
    h, w = arr.shape[0] // 2 * 2, arr.shape[1] // 2 * 2
    if pattern.upper() not in BAYER_PATTERNS:
        raise unknown_name("CFA pattern", pattern, BAYER_PATTERNS)
    sites = {(dy, dx): arr[dy:h:2, dx:w:2] for dy in (0, 1) for dx in (0, 1)}
    where = {c: [divmod(k, 2) for k, x in enumerate(pattern.upper()) if x == c] for c in "RGB"}
    out = np.empty((h // 2, w // 2, 3), np.float32)
    out[..., 0] = sites[where["R"][0]]
    out[..., 1] = (sites[where["G"][0]] + sites[where["G"][1]]) / 2.0
    out[..., 2] = sites[where["B"][0]]
    return out


def bayer_pattern(mosaic: np.ndarray) -> BayerFit:
    """Which CFA pattern a one-channel raw mosaic holding a 24-patch chart was taken with.

    The chart is searched in the half-size image of each of the four patterns
    (:func:`superpixels`, linear); a pattern is taken when the finder accepts the chart in it
    and its confidence leads every other pattern's by at least :data:`BAYER_MARGIN`. A wrong
    pattern swaps red with blue (the chart's colours out of order) or takes green from the red
    and blue sites (greys for colours), so a chart tells them apart; a mosaic with no chart,
    or one in which two patterns fit nearly as well, gives ``pattern`` None."""
    from fidelity.chart.find.cascade import find_chart  # noqa: PLC0415 (the finder)

    arr = np.asarray(mosaic)
    if arr.ndim != 2:
        raise InvalidValueError(f"a mosaic must be (H, W), got shape {arr.shape}")
    confidence: dict[str, float] = {}
    for pattern in BAYER_PATTERNS:
        try:
            found = find_chart(superpixels(arr, pattern), encoding="linear", refine=False)
            confidence[pattern] = float(found.confidence)
        except InvalidValueError:
            confidence[pattern] = 0.0
    ranked = sorted(confidence.values(), reverse=True)
    margin = ranked[0] - ranked[1]
    best = max(confidence, key=lambda k: confidence[k])
    chosen = best if ranked[0] > 0.0 and margin >= BAYER_MARGIN else None
    return BayerFit(confidence=confidence, pattern=chosen, margin=margin)


__all__ = [
    "BAYER_MARGIN",
    "BayerFit",
    "bayer_pattern",
    "superpixels",
]
