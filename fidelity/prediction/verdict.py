"""Pass/fail verdicts for CI gates: a limit on the chart ΔE or on the predicted detection loss.

Criteria (one per gate):

- ``max-delta-e``: pass when the chart's mean ΔE00 <= limit. The default limit is
  :data:`DEFAULT_MAX_DELTA_E` = 3, the SAFE-COLOR threshold that keeps ΔmAP below 1 %.
- ``max-dmap``: pass when the predicted worst-case loss of a class (``all``: mAP,
  ``person`` or ``bicycle``: class AP) in ``unit`` (``points`` or, for ``all``, ``relative``)
  <= limit. A prediction answered outside its table's range uses the table's conservative
  answer; a column without data fails (nothing supports a pass).

Exit codes of the commands: 0 pass, 1 fail, 2 error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from enum import StrEnum
from typing import Any

from fidelity.errors import InvalidValueError, unknown_name
from fidelity.prediction.table import CLASS_COLUMNS, ColumnStatus, Prediction

#: SAFE-COLOR: "ΔE ≤ 3 keeps ΔmAP below 1 %" (with a safety margin).
DEFAULT_MAX_DELTA_E = 3.0
#: Criterion kinds.
CRITERIA = ("max-delta-e", "max-dmap")
#: Units of a ΔmAP limit.
UNITS = ("points", "relative")

EXIT_PASS = 0
EXIT_FAIL = 1
EXIT_ERROR = 2


@dataclass(frozen=True)
class Criterion:
    """What a gate checks: ``kind`` in :data:`CRITERIA`, ``limit`` >= 0, and for ``max-dmap``
    the class (``all``, ``person``, ``bicycle``) and unit (``points``, ``relative``)."""

    kind: str
    limit: float
    cls: str = "all"
    unit: str = "points"

    def __post_init__(self) -> None:
        if self.kind not in CRITERIA:
            raise unknown_name("gate criterion", self.kind, CRITERIA)
        if not (isinstance(self.limit, (int, float)) and math.isfinite(self.limit)
                and self.limit >= 0):
            raise InvalidValueError(f"--{self.kind} {self.limit!r}: the limit must be a finite "
                                    "number >= 0")
        if self.cls not in CLASS_COLUMNS:
            raise unknown_name("class", self.cls, CLASS_COLUMNS)
        if self.unit not in UNITS:
            raise unknown_name("unit", self.unit, UNITS)
        if self.kind == "max-dmap" and self.unit == "relative" and self.cls != "all":
            raise InvalidValueError(
                f"--class {self.cls}: a relative limit exists only for the mean over all "
                f"classes; use points")

    @property
    def column(self) -> str:
        """The prediction column a ``max-dmap`` criterion reads (``dmap_relative`` or the
        class's points column)."""
        return "dmap_relative" if self.unit == "relative" else CLASS_COLUMNS[self.cls]

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``kind``, ``limit``, ``cls``, ``unit`` and the ``description``."""
        return {**asdict(self), "description": self.describe()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Criterion:
        """Inverse of :meth:`to_json` (checked like any criterion)."""
        return cls(str(data["kind"]), float(data["limit"]), str(data.get("cls", "all")),
                   str(data.get("unit", "points")))

    def describe(self) -> str:
        """``"mean ΔE00 <= 3"`` or ``"predicted person ΔAP <= 1 points"``."""
        if self.kind == "max-delta-e":
            return f"mean ΔE00 <= {self.limit:g}"
        what = "ΔmAP" if self.cls == "all" else f"{self.cls} ΔAP"
        unit = "percentage points" if self.unit == "points" else "% of baseline"
        return f"predicted {what} <= {self.limit:g} {unit}"


class VerdictReason(StrEnum):
    """Why a gate passed or failed: the value is within the limit, over it, or there is no
    prediction to compare (a ``max-dmap`` gate on a column without data fails)."""

    WITHIN_LIMIT = "within-limit"
    OVER_LIMIT = "over-limit"
    NO_PREDICTION = "no-prediction"


@dataclass(frozen=True)
class Verdict:
    """The outcome of a gate.

    ``passed`` and its ``reason``; the ``value`` compared with the criterion's limit (the chart
    ΔE, or the predicted loss in the criterion's unit; None without a prediction); the chart
    ΔE the verdict was made at (``delta_e``); for a ``max-dmap`` gate, which prediction decided
    it (``bound``: ``classic`` or ``directional``), the answering column's ``status``, whether
    the value is a published ``upper_bound``, the prediction ``table``'s name, and whether it
    is a ``conservative`` answer (outside the table's range, or no prediction). The sentence a
    report prints is :func:`fidelity.report.words.verdict_message`.
    """

    passed: bool
    criterion: Criterion
    value: float | None
    reason: VerdictReason
    delta_e: float
    conservative: bool = False
    bound: str = "classic"
    status: ColumnStatus | None = None
    upper_bound: bool = False
    table: str | None = None

    @property
    def exit_code(self) -> int:
        """0 pass, 1 fail."""
        return EXIT_PASS if self.passed else EXIT_FAIL

    @property
    def label(self) -> str:
        """``"PASS"`` or ``"FAIL"``."""
        return "PASS" if self.passed else "FAIL"

    def to_json(self) -> dict[str, Any]:
        """JSON form of the fields: ``passed``, ``label``, ``reason``, ``criterion``, ``value``,
        ``limit``, ``delta_e``, ``bound``, ``status``, ``upper_bound``, ``table``,
        ``conservative_answer``. The report's JSON adds the ``message``
        (:func:`fidelity.report.jsonform.verdict_json`)."""
        return {
            "passed": self.passed,
            "label": self.label,
            "reason": self.reason.value,
            "criterion": self.criterion.to_json(),
            "value": self.value,
            "limit": self.criterion.limit,
            "delta_e": self.delta_e,
            "bound": self.bound,
            "status": self.status.value if self.status is not None else None,
            "upper_bound": self.upper_bound,
            "table": self.table,
            "conservative_answer": self.conservative,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any], delta_e: float | None = None) -> Verdict:
        """Inverse of :meth:`to_json`; a report written before the verdict's fields were
        recorded gives its reason from ``passed`` and ``value``, its ΔE as ``delta_e``."""
        value = data.get("value")
        passed = bool(data["passed"])
        reason = data.get("reason") or (
            "within-limit" if passed else "no-prediction" if value is None else "over-limit")
        status = data.get("status")
        de = data.get("delta_e", delta_e)
        return cls(passed, Criterion.from_json(data["criterion"]),
                   None if value is None else float(value), VerdictReason(str(reason)),
                   float("nan") if de is None else float(de),
                   bool(data.get("conservative_answer", False)),
                   str(data.get("bound") or "classic"),
                   ColumnStatus(str(status)) if status else None,
                   bool(data.get("upper_bound", False)), data.get("table"))


def judge_value(criterion: Criterion, value: float | None, delta_e: float, **fields: Any
                ) -> Verdict:
    """The verdict of ``criterion`` on ``value`` (None: no prediction, a fail) at chart ΔE
    ``delta_e``; ``fields`` are the verdict's other fields (``bound``, ``status`` ...)."""
    if value is None:
        return Verdict(False, criterion, None, VerdictReason.NO_PREDICTION, float(delta_e),
                       **{"conservative": True, **fields})
    passed = value <= criterion.limit
    return Verdict(passed, criterion, float(value),
                   VerdictReason.WITHIN_LIMIT if passed else VerdictReason.OVER_LIMIT,
                   float(delta_e), **fields)


def evaluate(mean_delta_e: float, prediction: Prediction | None, criterion: Criterion) -> Verdict:
    """Apply ``criterion`` to a chart's mean ΔE00 and (for ``max-dmap``) its prediction."""
    if criterion.kind == "max-delta-e":
        return judge_value(criterion, float(mean_delta_e), float(mean_delta_e))
    if prediction is None:
        raise InvalidValueError("a --max-dmap gate needs a prediction")
    col = prediction.columns[criterion.column]
    return judge_value(criterion, prediction.value(criterion.cls, criterion.unit),
                       prediction.delta_e, status=col.status,
                       conservative=col.status is not ColumnStatus.INTERPOLATED,
                       upper_bound=prediction.upper_bound, table=prediction.table.name)


__all__ = [
    "CRITERIA",
    "DEFAULT_MAX_DELTA_E",
    "EXIT_ERROR",
    "EXIT_FAIL",
    "EXIT_PASS",
    "UNITS",
    "Criterion",
    "Verdict",
    "VerdictReason",
    "evaluate",
    "judge_value",
]
