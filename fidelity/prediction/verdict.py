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
from typing import Any

from fidelity.errors import InvalidValueError, unknown_name
from fidelity.prediction.table import CLASS_COLUMNS, Prediction

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


@dataclass(frozen=True)
class Verdict:
    """The outcome of a gate: ``passed``, the ``value`` compared with the criterion's limit,
    and a one-line ``message``."""

    passed: bool
    criterion: Criterion
    value: float | None
    message: str
    conservative: bool = False

    @property
    def exit_code(self) -> int:
        """0 pass, 1 fail."""
        return EXIT_PASS if self.passed else EXIT_FAIL

    @property
    def label(self) -> str:
        """``"PASS"`` or ``"FAIL"``."""
        return "PASS" if self.passed else "FAIL"

    def to_json(self) -> dict[str, Any]:
        """JSON form: ``passed``, ``label``, ``criterion``, ``value``, ``limit``,
        ``conservative_answer``, ``message``."""
        return {
            "passed": self.passed,
            "label": self.label,
            "criterion": self.criterion.to_json(),
            "value": self.value,
            "limit": self.criterion.limit,
            "conservative_answer": self.conservative,
            "message": self.message,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Verdict:
        """Inverse of :meth:`to_json`."""
        value = data.get("value")
        return cls(bool(data["passed"]), Criterion.from_json(data["criterion"]),
                   None if value is None else float(value), str(data["message"]),
                   bool(data.get("conservative_answer", False)))


def evaluate(mean_delta_e: float, prediction: Prediction | None, criterion: Criterion) -> Verdict:
    """Apply ``criterion`` to a chart's mean ΔE00 and (for ``max-dmap``) its prediction."""
    if criterion.kind == "max-delta-e":
        value = float(mean_delta_e)
        passed = value <= criterion.limit
        return Verdict(passed, criterion, value,
                       f"{'PASS' if passed else 'FAIL'}: mean ΔE00 {value:.2f} "
                       f"{'<=' if passed else '>'} {criterion.limit:g}")
    if prediction is None:
        raise InvalidValueError("a --max-dmap gate needs a prediction")
    loss = prediction.value(criterion.cls, criterion.unit)
    col = prediction.columns[criterion.column]
    what = criterion.describe().removeprefix("predicted ").split(" <=")[0]
    unit = "points" if criterion.unit == "points" else "%"
    if loss is None:
        return Verdict(False, criterion, None,
                       f"FAIL: table {prediction.table.name!r} has no {what} prediction "
                       f"(nothing supports a pass)", conservative=True)
    passed = loss <= criterion.limit
    conservative = col.status != "interpolated"
    extra = f" ({col.status}: conservative answer)" if conservative else ""
    bound = " (upper bound)" if prediction.table.kind.upper_bound else ""
    return Verdict(
        passed, criterion, float(loss),
        f"{'PASS' if passed else 'FAIL'}: predicted {what} {loss:.2f} {unit}{bound}"
        f"{extra} {'<=' if passed else '>'} {criterion.limit:g} at mean ΔE00 "
        f"{prediction.delta_e:.2f}",
        conservative=conservative,
    )


__all__ = [
    "CRITERIA",
    "DEFAULT_MAX_DELTA_E",
    "EXIT_ERROR",
    "EXIT_FAIL",
    "EXIT_PASS",
    "UNITS",
    "Criterion",
    "Verdict",
    "evaluate",
]
