"""Pass/fail verdicts for CI gates: a limit on the chart ΔE or on the predicted detection loss.

Criteria (one per gate):

- ``max-delta-e``: pass when the chart's mean ΔE00 <= limit. The default limit is
  :data:`DEFAULT_MAX_DELTA_E` = 3, SAFE-COLOR's published threshold. It is a limit on the
  colour error, not on the loss: with the shipped measured table the worst case at ΔE00 3 is
  up to 2.39 % of the baseline mAP (0.92 points) for its detectors, not "below 1 %"; a
  verdict records what its limit allows (:attr:`Verdict.limit_loss_relative`, from the
  table), and ``--max-dmap`` limits the loss itself.
- ``max-dmap``: pass when the predicted worst-case loss of a class (``all``: mAP,
  ``person`` or ``bicycle``: class AP) in ``unit`` (``points`` or, for ``all``, ``relative``)
  <= limit. A prediction answered outside its table's range uses the table's conservative
  answer; a column without data fails (nothing supports a pass).

Decision rules (:class:`DecisionRule`, ``--decision``; ILAC-G8:09/2019, JCGM 106:2012):

- ``simple``: pass when value <= limit (the uncertainty is reported, not used);
- ``guarded``: with the expanded uncertainty ``U = k u`` of the value (``k`` = 2 by default,
  about 95 % coverage for a normal distribution), pass only when value + U <= limit, fail when
  value - U > limit, and in between the verdict is ``undecided`` (exit code
  :data:`EXIT_UNDECIDED`), or a fail when the rule is ``strict``.

Exit codes of the commands: 0 pass, 1 fail, 2 error, 3 internal error, 4 undecided (guarded
rule, not strict).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict
from enum import StrEnum
from typing import Any

from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record
from fidelity.prediction.exposure import ExposureJudgement
from fidelity.prediction.interpolate import ColumnStatus
from fidelity.prediction.properties import PropertyJudgement
from fidelity.prediction.table import Prediction
from fidelity.prediction.tablefile import CLASS_COLUMNS

#: SAFE-COLOR's published threshold on the mean ΔE00 (the paper: "keeps ΔmAP below 1 %"; the
#: shipped measured table's worst case at ΔE00 3 is 2.39 % of baseline, module docstring).
DEFAULT_MAX_DELTA_E = 3.0
#: Criterion kinds.
CRITERIA = ("max-delta-e", "max-dmap")
#: Units of a ΔmAP limit.
UNITS = ("points", "relative")

EXIT_PASS = 0
EXIT_FAIL = 1
EXIT_ERROR = 2
#: A guarded verdict inside the guard band (value within U of the limit), not strict.
EXIT_UNDECIDED = 4
#: Decision rules.
DECISION_RULES = ("simple", "guarded")
#: Coverage factor of the guarded rule unless told otherwise.
DEFAULT_COVERAGE_FACTOR = 2.0


@record
class DecisionRule:
    """How a value with an uncertainty is compared with a limit (module docstring): ``rule``
    (``simple`` or ``guarded``), the coverage factor ``k`` of the expanded uncertainty a
    guarded rule uses, and ``strict`` (a guarded verdict in the guard band fails instead of
    being undecided)."""

    rule: str = "simple"
    k: float = DEFAULT_COVERAGE_FACTOR
    strict: bool = False

    def __post_init__(self) -> None:
        if self.rule not in DECISION_RULES:
            raise unknown_name("decision rule", self.rule, DECISION_RULES)
        if not (isinstance(self.k, (int, float)) and math.isfinite(self.k) and self.k > 0):
            raise InvalidValueError(f"--coverage-factor {self.k!r}: must be a finite number > 0")

    def describe(self) -> str:
        """The rule in words."""
        if self.rule == "simple":
            return "simple acceptance: pass when value <= limit (uncertainty not used)"
        band = "fail" if self.strict else "undecided"
        return (f"guarded acceptance (ILAC-G8): pass when value + U <= limit, fail when "
                f"value - U > limit, {band} in between; U = k u with k = {self.k:g}")

    def to_json(self) -> dict[str, Any]:
        """``{"rule", "k", "strict", "description"}``."""
        return {"rule": self.rule, "k": self.k, "strict": self.strict,
                "description": self.describe()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DecisionRule:
        """Inverse of :meth:`to_json`."""
        return cls(str(data.get("rule", "simple")),
                   float(data.get("k", DEFAULT_COVERAGE_FACTOR)), bool(data.get("strict")))


#: The rule of a verdict unless told otherwise.
SIMPLE = DecisionRule()


@record
class Criterion:
    """What a gate checks: ``kind`` in :data:`CRITERIA`, ``limit`` >= 0, and for ``max-dmap``
    the class (``all``, ``person``, ``bicycle``) and unit (``points``, ``relative``).

    Attributes
    ----------
    kind
        ``max-delta-e`` (the chart's mean ΔE00 against the limit) or ``max-dmap`` (the
        predicted loss against it) (:data:`CRITERIA`).
    limit
        The limit, a finite number >= 0: ΔE00 for ``max-delta-e``; for ``max-dmap`` in
        ``unit``: percentage points, or percent of the baseline mAP.
    cls
        The detection class of a ``max-dmap`` limit: ``all`` (ΔmAP, default), ``person`` or
        ``bicycle`` (ΔAP).
    unit
        ``points`` (percentage points, default) or ``relative`` (percent of the baseline mAP;
        only with ``cls`` ``all``) (:data:`UNITS`).

    Raises
    ------
    UnknownNameError
        An unknown kind, class or unit. Exit code 2.
    InvalidValueError
        A limit that is not a finite number >= 0, or a relative limit of a single class.
        Exit code 2.
    """

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
    #: a guarded rule's guard band: within U of the limit
    UNDECIDED = "undecided"


@record
class Verdict:
    """The outcome of a gate.

    ``passed`` and its ``reason``; the ``value`` compared with the criterion's limit (the chart
    ΔE, or the predicted loss in the criterion's unit; None without a prediction); the chart
    ΔE the verdict was made at (``delta_e``); for a ``max-dmap`` gate, which prediction decided
    it (``bound``: ``classic`` or ``directional``), the answering column's ``status``, whether
    the value is a published ``upper_bound``, the prediction ``table``'s name, and whether it
    is a ``conservative`` answer (outside the table's range, or no prediction). The sentence a
    report prints is :func:`fidelity.report.words.verdict_message`.

    Attributes
    ----------
    passed
        True when the gate passed (False for a fail and for an undecided guarded verdict).
    criterion
        The criterion applied.
    value
        The value compared with the limit: the chart's mean ΔE00 (``max-delta-e``), or the
        predicted loss in the criterion's unit (percentage points or percent of baseline);
        None without a prediction (a fail).
    reason
        ``within-limit``, ``over-limit``, ``no-prediction`` or ``undecided``
        (:class:`VerdictReason`).
    delta_e
        The chart ΔE (mean ΔE00) the verdict was made at; NaN when a report read back does
        not record it.
    conservative
        True when the answer is conservative: outside the table's range, or no prediction.
    bound
        Which prediction decided a ``max-dmap`` verdict: ``classic`` (default) or
        ``directional``.
    status
        The answering column's status (interpolated, below or above the table's range, no
        data); None for ``max-delta-e``.
    upper_bound
        True when ``value`` is a published upper bound, not a measured worst case.
    table
        The prediction table's name; None for ``max-delta-e``.
    decision
        The decision rule applied (:class:`DecisionRule`: simple, or guarded by the expanded
        uncertainty).
    uncertainty
        The standard uncertainty (k = 1) of ``value``, in its unit; None: not known.
    properties
        Sharpness and noise judged with colour
        (:class:`fidelity.prediction.properties.PropertyJudgement`): a ``max-dmap`` verdict's
        ``value`` is then the combined loss; None: colour alone.
    exposure
        The image's exposure judged against the expected one
        (:class:`fidelity.prediction.exposure.ExposureJudgement`): one over its limit fails
        the verdict; None: not judged (auto exposure, or no expected exposure).
    limit_loss_relative
        For ``max-delta-e``: what the limit allows, the predicted worst-case ΔmAP in percent
        of the baseline mAP at ΔE00 = limit from the verdict's prediction table; None: not
        known (no table, or a report read back that does not record it).
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
    #: the decision rule applied (:class:`DecisionRule`)
    decision: DecisionRule = SIMPLE
    #: the standard uncertainty (k = 1) of ``value``, in its unit; None: not known
    uncertainty: float | None = None
    #: sharpness and noise judged with colour
    #: (:class:`fidelity.prediction.properties.PropertyJudgement`; None: colour alone)
    properties: PropertyJudgement | None = None
    #: the image's exposure judged against the expected one
    #: (:class:`fidelity.prediction.exposure.ExposureJudgement`; None: not judged)
    exposure: ExposureJudgement | None = None
    #: for ``max-delta-e``: the predicted ΔmAP (% of baseline) at ΔE00 = limit; None: unknown
    limit_loss_relative: float | None = None

    @property
    def exposure_failed(self) -> bool:
        """True when the exposure was judged and is over its limit (the verdict fails)."""
        return self.exposure is not None and not self.exposure.passed

    @property
    def expanded_uncertainty(self) -> float | None:
        """U = k u of the decision rule (None when ``uncertainty`` is unknown)."""
        return None if self.uncertainty is None else self.decision.k * self.uncertainty

    @property
    def undecided(self) -> bool:
        """True when a guarded rule left the verdict undecided (not strict)."""
        return self.reason is VerdictReason.UNDECIDED and not self.decision.strict

    @property
    def exit_code(self) -> int:
        """0 pass, 1 fail, 4 undecided."""
        if self.undecided:
            return EXIT_UNDECIDED
        return EXIT_PASS if self.passed else EXIT_FAIL

    @property
    def label(self) -> str:
        """``"PASS"``, ``"FAIL"`` or ``"UNDECIDED"``."""
        if self.undecided:
            return "UNDECIDED"
        return "PASS" if self.passed else "FAIL"

    def to_json(self) -> dict[str, Any]:
        """JSON form of the fields: ``passed``, ``label``, ``reason``, ``criterion``, ``value``,
        ``limit``, ``delta_e``, ``bound``, ``status``, ``upper_bound``, ``table``,
        ``conservative_answer``, the ``decision`` rule, the value's ``standard_uncertainty``
        and ``expanded_uncertainty`` (U = k u), with ``properties`` and ``exposure`` where judged.
        The report's JSON adds the ``message``
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
            "decision": self.decision.to_json(),
            "standard_uncertainty": self.uncertainty,
            "expanded_uncertainty": self.expanded_uncertainty,
            **({"limit_loss_relative": self.limit_loss_relative}
               if self.limit_loss_relative is not None else {}),
            **({"properties": self.properties.to_json()} if self.properties is not None
               else {}),
            **({"exposure": self.exposure.to_json()} if self.exposure is not None else {}),
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
                   bool(data.get("upper_bound", False)), data.get("table"),
                   DecisionRule.from_json(data["decision"]) if data.get("decision") else SIMPLE,
                   (None if data.get("standard_uncertainty") is None
                    else float(data["standard_uncertainty"])),
                   _properties_from_json(data.get("properties")),
                   (ExposureJudgement.from_json(data["exposure"]) if data.get("exposure")
                    else None),
                   (None if data.get("limit_loss_relative") is None
                    else float(data["limit_loss_relative"])))


def _properties_from_json(d: Any) -> Any:
    """The verdict's :class:`fidelity.prediction.properties.PropertyJudgement` (None: colour
    alone)."""
    if not d:
        return None
    return PropertyJudgement.from_json(d)


def worst_exit_code(codes: Iterable[int]) -> int:
    """The exit code of several verdicts: 2 (error) before 1 (fail) before 4 (undecided)
    before 0 (pass); others (3, internal error) first of all."""
    order = {EXIT_PASS: 0, EXIT_UNDECIDED: 1, EXIT_FAIL: 2, EXIT_ERROR: 3}
    return max(codes, key=lambda c: order.get(c, 4), default=EXIT_PASS)


def judge_value(criterion: Criterion, value: float | None, delta_e: float, *,
                decision: DecisionRule = SIMPLE, uncertainty: float | None = None,
                **fields: Any) -> Verdict:
    """The verdict of ``criterion`` on ``value`` (None: no prediction, a fail) at chart ΔE
    ``delta_e`` by the ``decision`` rule, ``uncertainty`` the value's standard uncertainty
    (k = 1; a guarded rule without one takes U = 0 and says so through
    ``expanded_uncertainty`` None); ``fields`` are the verdict's other fields (``bound``,
    ``status`` ...)."""
    fields = {"decision": decision, "uncertainty": uncertainty, **fields}
    if value is None:
        return Verdict(False, criterion, None, VerdictReason.NO_PREDICTION, float(delta_e),
                       **{"conservative": True, **fields})
    v, limit = float(value), criterion.limit
    if decision.rule == "guarded":
        u_exp = decision.k * (uncertainty or 0.0)
        if v + u_exp <= limit:
            reason, passed = VerdictReason.WITHIN_LIMIT, True
        elif v - u_exp > limit:
            reason, passed = VerdictReason.OVER_LIMIT, False
        else:
            reason, passed = VerdictReason.UNDECIDED, False
        return Verdict(passed, criterion, v, reason, float(delta_e), **fields)
    passed = v <= limit
    return Verdict(passed, criterion, v,
                   VerdictReason.WITHIN_LIMIT if passed else VerdictReason.OVER_LIMIT,
                   float(delta_e), **fields)


def evaluate(mean_delta_e: float, prediction: Prediction | None, criterion: Criterion, *,
             decision: DecisionRule = SIMPLE, delta_e_uncertainty: float | None = None,
             loss_uncertainty: float | None = None) -> Verdict:
    """Apply ``criterion`` to a chart's mean ΔE00 and (for ``max-dmap``) its prediction by the
    ``decision`` rule; ``delta_e_uncertainty`` and ``loss_uncertainty`` are the standard
    uncertainties of the ΔE and of the criterion's predicted loss.

    Parameters
    ----------
    mean_delta_e
        The chart ΔE: mean ΔE00 over the patches, >= 0.
    prediction
        The predicted loss at the chart ΔE (:func:`fidelity.prediction.table.predict`); may
        be None for a ``max-delta-e`` criterion.
    criterion
        The criterion: ``max-delta-e`` or ``max-dmap`` with its limit, class and unit.
    decision
        ``simple`` (pass when value <= limit, default) or ``guarded`` (ILAC-G8: pass when
        value + U <= limit, fail when value - U > limit, undecided between, U = k u;
        ``strict``: fail between).
    delta_e_uncertainty
        Standard uncertainty (k = 1) of ``mean_delta_e``, ΔE00, >= 0; None: unknown (U = 0).
        Used by a guarded ``max-delta-e`` verdict.
    loss_uncertainty
        Standard uncertainty (k = 1) of the criterion's predicted loss, in its unit, >= 0;
        None: unknown (U = 0). Used by a guarded ``max-dmap`` verdict.

    Returns
    -------
    Verdict
        Passed or not, why, the value compared and, for ``max-dmap``, the answering column's
        status, whether it is conservative or a published upper bound, and the table's name.
        A ``max-dmap`` criterion whose column has no prediction fails (``no-prediction``).

    Raises
    ------
    InvalidValueError
        A ``max-dmap`` criterion without a prediction. Exit code 2.

    References
    ----------
    ILAC-G8:09/2019, *Guidelines on Decision Rules and Statements of Conformity* (the guarded
    rule).
    """
    if criterion.kind == "max-delta-e":
        return judge_value(criterion, float(mean_delta_e), float(mean_delta_e),
                           decision=decision, uncertainty=delta_e_uncertainty)
    if prediction is None:
        raise InvalidValueError("a --max-dmap gate needs a prediction")
    col = prediction.columns[criterion.column]
    return judge_value(criterion, prediction.value(criterion.cls, criterion.unit),
                       prediction.delta_e, status=col.status,
                       conservative=col.status is not ColumnStatus.INTERPOLATED,
                       upper_bound=prediction.upper_bound, table=prediction.table.name,
                       decision=decision, uncertainty=loss_uncertainty)


__all__ = [
    "CRITERIA",
    "DECISION_RULES",
    "DEFAULT_COVERAGE_FACTOR",
    "DEFAULT_MAX_DELTA_E",
    "EXIT_ERROR",
    "EXIT_FAIL",
    "EXIT_PASS",
    "EXIT_UNDECIDED",
    "SIMPLE",
    "DecisionRule",
    "UNITS",
    "Criterion",
    "Verdict",
    "VerdictReason",
    "evaluate",
    "judge_value",
    "worst_exit_code",
]
