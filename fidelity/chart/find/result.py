"""What the chart finder returns: the chart found (:class:`FoundChart`) and how well it matches
the 24-patch reference layout (:class:`ChartChecks`), with their JSON forms for the records.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import field, replace
from typing import Any

import numpy as np

from fidelity.chart.locate import CORNER_PATCHES
from fidelity.core.record import record


@record
class ChartChecks:
    """How well the chart found matches the 24-patch reference layout.

    ``colour_order`` the mean Spearman rank correlation of R, G, B, log(R/G), log(B/G) between
    measured and reference patches (1: same order); ``neutral_order`` the fraction of the 15
    pairs of neutral patches in order of lightness; ``margin`` the lead of ``colour_order``
    over the next-best placement (another row, column or orientation) of the same candidate;
    ``uniformity`` the median over the patches of the standard deviation of the sampled
    linear values beyond their white noise
    (:func:`~fidelity.chart.find.placement.structured_spread`) relative to their mean (0:
    flat patches, however noisy).
    """

    colour_order: float
    neutral_order: float
    margin: float
    uniformity: float

    def to_json(self) -> dict[str, float]:
        """JSON form: the four numbers, rounded to 1e-4."""
        return {k: round(float(v), 4) for k, v in vars(self).items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ChartChecks:
        """Inverse of :meth:`to_json`."""
        return cls(colour_order=float(data["colour_order"]),
                   neutral_order=float(data["neutral_order"]), margin=float(data["margin"]),
                   uniformity=float(data["uniformity"]))


@record
class FoundChart:
    """A chart found in an image.

    ``corners`` is ``(4, 2)`` image ``(x, y)`` of the dark skin, bluish green, black and white
    patch centres; ``method`` the detector whose candidate won (``mcc`` or ``segmentation``);
    ``candidates`` the number of candidates verified; ``swatches`` the number of patch outlines
    that refined the fit at full size (0: the search's fit answered); ``residual_px`` the RMS
    distance, in image pixels, between those outlines' centres and the fitted grid (NaN
    without refinement); ``orientation`` how the chart lies in the image (its top edge's turn
    from the image's x axis, and whether it is seen mirrored); ``region`` the ``(x0, y0, x1,
    y1)`` part of the image the final fit was made in; ``confidence`` the verification's mean
    rank correlation (0-1, :class:`ChartChecks`); ``chart`` the chart type found;
    ``other_charts`` patch charts found beside it that are not the 24-patch layout (a
    Passport's other page) and were not measured; ``seconds`` the time taken; ``occluded``
    the patches (0-based, chart order: dark skin first, row by row) judged covered
    (:func:`~fidelity.chart.find.reference.occluded_patches`), left out of the checks and of
    the audit's statistics; ``flat_off_fit`` the patches far from what the others predict
    (:func:`~fidelity.chart.find.reference.off_the_camera_fit`) whose window is flat: the
    camera's own error or a flat cover, measured and named in a note, never left out (a
    camera's error is not hidden).

    Attributes
    ----------
    corners
        Image ``(x, y)`` of the dark skin, bluish green, black and white patch centres, in
        pixels, shape (4, 2) (:data:`~fidelity.chart.locate.CORNER_PATCHES`).
    method
        The detector whose candidate won: ``mcc`` or ``segmentation``.
    candidates
        Candidates verified, >= 1.
    swatches
        Patch outlines that refined the fit at full size, >= 0 (0: the search's fit).
    residual_px
        RMS distance in image pixels between the outlines' centres and the fitted grid,
        >= 0; NaN without refinement.
    orientation
        How the chart lies in the image: its top edge's turn from the image's x axis, and
        whether it is seen mirrored (``as found`` when not stated).
    region
        The ``(x0, y0, x1, y1)`` pixel part of the image the final fit was made in; None when
        not stated.
    confidence
        The verification's rank correlation of measured and reference colours, in [0, 1];
        NaN when not stated.
    checks
        How well the patches found match the reference layout; None when not checked.
    chart
        The chart type found (``24-patch ColorChecker``, noting a Passport's other page).
    other_charts
        Patch charts found beside it that are not the 24-patch layout, >= 0 (not measured).
    seconds
        Wall-clock seconds the search took; NaN when not stated.
    notes
        What a report should say about the find (other charts, covered or far-off patches).
    occluded
        0-based chart-order indices of the patches judged covered, left out of the checks and
        of the audit's statistics.
    flat_off_fit
        0-based chart-order indices of flat patches far from what the others predict:
        measured and named in a note, never left out.
    """

    corners: np.ndarray
    method: str
    candidates: int
    swatches: int
    residual_px: float
    orientation: str = "as found"
    region: tuple[int, int, int, int] | None = None
    confidence: float = math.nan
    checks: ChartChecks | None = None
    chart: str = "24-patch ColorChecker"
    other_charts: int = 0
    seconds: float = math.nan
    notes: tuple[str, ...] = field(default_factory=tuple)
    occluded: tuple[int, ...] = ()
    flat_off_fit: tuple[int, ...] = ()

    def without_flat_off_fit(self, explained: Sequence[int], note: str) -> FoundChart:
        """This find with the ``explained`` patches taken out of :attr:`flat_off_fit` and its
        note, and ``note`` (why they are far from the others: a reference colour outside the
        sRGB gamut, clipped as every sRGB render clips it) added."""
        gone = {int(k) for k in explained} & set(self.flat_off_fit)
        if not gone:
            return self
        rest = tuple(k for k in self.flat_off_fit if k not in gone)
        old = flat_off_fit_note(self.flat_off_fit)
        notes = [n for n in self.notes if n != old]
        if rest:
            notes.append(flat_off_fit_note(rest))
        notes.append(note)
        return replace(self, flat_off_fit=rest, notes=tuple(notes))

    def corners_text(self) -> str:
        """The corners as ``--corners`` takes them: ``X1,Y1,...,X4,Y4`` (0.1 px)."""
        return ",".join(f"{v:.1f}" for v in self.corners.ravel())

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``method``, ``corners``, ``corner_patches``, ``corners_text``,
        ``candidates``, ``swatches``, ``residual_px`` (null without refinement),
        ``orientation``, ``region``, ``confidence``, ``checks``, ``chart``, ``other_charts``,
        ``seconds``, ``notes``, ``occluded``, ``flat_off_fit``."""
        return {
            "method": self.method,
            "corners": np.round(self.corners, 3).tolist(),
            "corner_patches": list(CORNER_PATCHES),
            "corners_text": self.corners_text(),
            "candidates": self.candidates,
            "swatches": self.swatches,
            "residual_px": None if math.isnan(self.residual_px) else round(self.residual_px, 3),
            "orientation": self.orientation,
            "region": list(self.region) if self.region else None,
            "confidence": None if math.isnan(self.confidence) else round(self.confidence, 4),
            "checks": self.checks.to_json() if self.checks else None,
            "chart": self.chart,
            "other_charts": self.other_charts,
            "seconds": None if math.isnan(self.seconds) else round(self.seconds, 4),
            "notes": list(self.notes),
            "occluded": list(self.occluded),
            "flat_off_fit": list(self.flat_off_fit),
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FoundChart:
        """Inverse of :meth:`to_json` (corners as stored, to 0.001 px; keys added since are
        optional)."""
        residual = data.get("residual_px")
        region = data.get("region")
        confidence = data.get("confidence")
        seconds = data.get("seconds")
        checks = data.get("checks")
        return cls(
            corners=np.asarray(data["corners"], dtype=np.float64), method=str(data["method"]),
            candidates=int(data["candidates"]), swatches=int(data["swatches"]),
            residual_px=math.nan if residual is None else float(residual),
            orientation=str(data.get("orientation", "as found")),
            region=(int(region[0]), int(region[1]), int(region[2]), int(region[3]))
            if region else None,
            confidence=math.nan if confidence is None else float(confidence),
            checks=ChartChecks.from_json(checks) if checks else None,
            chart=str(data.get("chart", "24-patch ColorChecker")),
            other_charts=int(data.get("other_charts", 0)),
            seconds=math.nan if seconds is None else float(seconds),
            notes=tuple(str(n) for n in data.get("notes", ())),
            occluded=tuple(int(k) for k in data.get("occluded", ())),
        )


def flat_off_fit_note(patches: Sequence[int]) -> str:
    """The note of a find whose flat ``patches`` (0-based, chart order) lie far from what the
    other patches predict (:attr:`FoundChart.flat_off_fit`)."""
    return (f"patch(es) {', '.join(str(k + 1) for k in patches)} (in chart order) far from "
            f"what the other patches predict but flat: the camera's own error or a flat "
            f"cover; measured (check the image)")


__all__ = [
    "ChartChecks",
    "FoundChart",
    "flat_off_fit_note",
]
