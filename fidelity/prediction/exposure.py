"""The image's exposure judged against the one the chart scene expects (issue 57).

Auto exposure (the default for linear pixels) scales the chart so that its neutral patches
match the reference: it removes any overall brightness error, which is then neither seen by
the chart ΔE nor judged. A render with four times the light (a missing importer factor, a
changed exposure or gamma in a simulator upgrade) passes a colour gate that way. When the
expected exposure is known -- the scene manifest's ``expected_exposure.gate_exposure_ev``
(``--manifest``), or ``--exposure EV`` given -- the pixels are measured at that exposure and
the neutral patches' own exposure correction :math:`EV_n` (:func:`fidelity.measure.pixels.
exposure_from_neutrals`) gives the image's exposure error

.. math::  e = EV_{fixed} - EV_n \\quad \\text{(EV; +2: the image is 4 x brighter)},

which :func:`judge_exposure` compares with a limit (``--max-exposure-error``, default
:data:`DEFAULT_MAX_EXPOSURE_ERROR_EV`): ``|e| <= limit`` passes. A failed exposure fails the
verdict whatever the colour's outcome, and the verdict names it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

__all__ = ["DEFAULT_MAX_EXPOSURE_ERROR_EV", "EXPOSURE_SOURCES", "ExposureJudgement",
           "judge_exposure"]

#: The default limit of the exposure error, in EV (``--max-exposure-error``).
DEFAULT_MAX_EXPOSURE_ERROR_EV = 0.3

#: Where the expected exposure came from: the scene manifest or ``--exposure``.
EXPOSURE_SOURCES: tuple[str, ...] = ("manifest", "--exposure")


@record
class ExposureJudgement:
    """An image's exposure judged against the expected one.

    Attributes
    ----------
    expected_ev
        The fixed exposure correction the pixels were measured at, in EV (the manifest's
        ``gate_exposure_ev`` or ``--exposure``).
    error_ev
        How much brighter than expected the image is, in EV (``expected_ev`` minus the
        correction its neutral patches ask for).
    limit_ev
        The largest ``|error_ev|`` that passes, in EV (> 0).
    source
        Where ``expected_ev`` came from (:data:`EXPOSURE_SOURCES`).
    """

    expected_ev: float
    error_ev: float
    limit_ev: float
    source: str

    @property
    def passed(self) -> bool:
        """True when ``|error_ev| <= limit_ev``."""
        return abs(self.error_ev) <= self.limit_ev

    @property
    def factor(self) -> float:
        """The image's brightness over the expected one (``2**error_ev``)."""
        return float(2.0 ** self.error_ev)

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``expected_ev``, ``error_ev``, ``limit_ev``, ``source``, ``passed``,
        ``factor``."""
        return {"expected_ev": self.expected_ev, "error_ev": self.error_ev,
                "limit_ev": self.limit_ev, "source": self.source, "passed": self.passed,
                "factor": self.factor}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ExposureJudgement:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["expected_ev"]), float(d["error_ev"]), float(d["limit_ev"]),
                   str(d["source"]))


def judge_exposure(expected_ev: float, neutral_ev: float | None, limit_ev: float,
                   source: str) -> ExposureJudgement | None:
    """Judge a fixed exposure against what the image's neutral patches ask for.

    Parameters
    ----------
    expected_ev
        The fixed exposure correction the pixels were measured at, in EV (finite).
    neutral_ev
        The correction the neutral patches ask for, in EV
        (:attr:`fidelity.measure.pixels.ImageMeasurement.neutral_ev`); None: they set none
        (black): nothing is judged.
    limit_ev
        The largest exposure error that passes, in EV, > 0 and finite.
    source
        Where ``expected_ev`` came from (:data:`EXPOSURE_SOURCES`).

    Returns
    -------
    ExposureJudgement or None
        None when ``neutral_ev`` is None.

    Raises
    ------
    InvalidValueError
        A limit that is not a positive finite number, an unknown source.
    """
    if not (math.isfinite(limit_ev) and limit_ev > 0):
        raise InvalidValueError(f"--max-exposure-error {limit_ev!r}: must be a positive "
                                f"number of EV")
    if source not in EXPOSURE_SOURCES:
        raise InvalidValueError(f"exposure source {source!r}: expected one of "
                                f"{', '.join(EXPOSURE_SOURCES)}")
    if neutral_ev is None:
        return None
    return ExposureJudgement(float(expected_ev), float(expected_ev - neutral_ev) + 0.0,
                             float(limit_ev), source)
