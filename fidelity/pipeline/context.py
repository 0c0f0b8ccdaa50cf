"""The context of use of a camera check and the credibility its evidence earns there.

A context file (``--context context.toml`` of ``check`` and ``suite``) states, after ASME V&V
40-2018 (risk-informed credibility assessment), what the camera model is used for:

.. code-block:: toml

    name = "AEB pedestrian detection, urban, day and dusk"   # optional
    question = "Does the camera model's colour change what the detector sees?"  # optional

    [detectors]                  # the detector(s) under test
    models = ["yolox_nano"]      # detector names (as the validation names them)

    [conditions]                 # the operating conditions
    illuminants = ["D65", "A"]   # scene illuminants (fidelity.colour.spectral names)
    exposures_ev = [0.0]         # exposure offsets the camera runs at (EV)

    [acceptance]                 # the acceptance criteria, each optional
    max_delta_e = 3.0            # mean chart ΔE00
    max_dmap = 1.0               # predicted ΔmAP, percentage points

    [risk]                       # V&V 40 model risk
    model_influence = "medium"       # low | medium | high
    decision_consequence = "high"    # low | medium | high

:func:`load_context` reads and validates it (an unknown table or field, a wrong type or a value
outside the allowed ones is one error naming the file, the field and what is allowed).

:func:`assess` scores the evidence for that context on three factors, each 1 (lowest) to 5,
computed from facts the tool has:

- **code verification**: the reference checks of ``fidelity qualify`` that the camera check
  rests on (:data:`CODE_CHECKS`), run here: level ``1 + round(4 * passed / run)``;
- **validation coverage**: the share ``c`` of the context's illuminants and detectors among
  those the prediction was validated on (:mod:`fidelity.prediction.interval`,
  ``validation-domain.json``), times the share of validation cells whose measured loss held
  within the bound: level ``1 + round(4 * c)``;
- **applicability**: the share ``a`` of the context's conditions inside the validity domain
  (illuminants validated; exposure offsets are not recorded by the validation, so they are
  named outside) and of the checked subjects' validity checks inside: level
  ``1 + round(4 * a)``.

The credibility level is the lowest factor level; the model risk level is V&V 40's matrix
``1 + influence + consequence`` (low 0, medium 1, high 2; 1 to 5); the evidence is sufficient
when the credibility level is at least the risk level. The acceptance criteria are judged on
each subject's mean ΔE00 and predicted ΔmAP.
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from fidelity.colour.spectral import load_illuminant
from fidelity.core.errors import FidelityError, InputFileError
from fidelity.core.record import record
from fidelity.prediction.interval import ValidatedCameras, load_validated_cameras

if TYPE_CHECKING:
    from fidelity.prediction.interval import ValidityDomain
    from fidelity.prediction.table import Prediction


class CheckedSubject(Protocol):
    """What :func:`assess` reads of a checked subject
    (:class:`fidelity.pipeline.records.ChartReport` is one; a protocol, as the report records
    this module's assessment)."""

    @property
    def mean_delta_e(self) -> float: ...  # noqa: D102

    @property
    def prediction(self) -> Prediction | None: ...  # noqa: D102

    @property
    def validity(self) -> ValidityDomain | None: ...  # noqa: D102

#: The V&V 40 levels of model influence and decision consequence, lowest first.
LEVELS = ("low", "medium", "high")

#: The reference checks of :mod:`fidelity.pipeline.qualify` the camera check rests on (each
#: under a second; the renderer, chart-finder and installation checks are not run here).
CODE_CHECKS = ("ciede2000", "srgb-matrix", "illuminant-white", "calibration",
               "chart-baseline", "ideal-camera")

#: Tables and fields of a context file: table -> {field: (kind, description)}; ``""`` holds
#: the top-level fields.
SCHEMA: dict[str, dict[str, str]] = {
    "": {"name": "string", "question": "string"},
    "detectors": {"models": "list of strings"},
    "conditions": {"illuminants": "list of strings", "exposures_ev": "list of numbers"},
    "acceptance": {"max_delta_e": "number > 0", "max_dmap": "number > 0"},
    "risk": {"model_influence": "one of low, medium, high",
             "decision_consequence": "one of low, medium, high"},
}


@record
class Context:
    """A context of use (module docstring): ``path`` the file it was read from; ``detectors``
    the detectors under test; ``illuminants`` and ``exposures_ev`` the operating conditions
    (EV); ``max_delta_e`` (mean ΔE00) and ``max_dmap`` (percentage points) the acceptance
    criteria (None: not stated); ``model_influence`` and ``decision_consequence`` in
    :data:`LEVELS`."""

    path: str
    name: str
    question: str
    detectors: tuple[str, ...]
    illuminants: tuple[str, ...]
    exposures_ev: tuple[float, ...]
    max_delta_e: float | None
    max_dmap: float | None
    model_influence: str
    decision_consequence: str

    @property
    def risk_level(self) -> int:
        """V&V 40 model risk, 1 (low influence, low consequence) to 5 (high, high)."""
        return 1 + LEVELS.index(self.model_influence) + LEVELS.index(self.decision_consequence)

    def to_json(self) -> dict[str, Any]:
        """Every field, and ``risk_level``."""
        return {"path": self.path, "name": self.name, "question": self.question,
                "detectors": list(self.detectors), "illuminants": list(self.illuminants),
                "exposures_ev": list(self.exposures_ev), "max_delta_e": self.max_delta_e,
                "max_dmap": self.max_dmap, "model_influence": self.model_influence,
                "decision_consequence": self.decision_consequence,
                "risk_level": self.risk_level}


def _field(path: str, where: str, key: str, value: Any) -> Any:
    """``value`` of field ``where.key`` checked against :data:`SCHEMA`."""
    kind = SCHEMA[where][key]
    name = f"{where}.{key}" if where else key
    ok: bool
    if kind == "string":
        ok = isinstance(value, str)
    elif kind == "list of strings":
        ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
    elif kind == "list of numbers":
        ok = isinstance(value, list) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in value)
    elif kind == "number > 0":
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
              and math.isfinite(value) and value > 0)
    else:  # one of LEVELS
        ok = value in LEVELS
    if not ok:
        raise InputFileError(f"{path}: {name}: must be {kind}, got {value!r}")
    return value


def load_context(path: str | os.PathLike[str]) -> Context:
    """The :class:`Context` of the TOML file ``path`` (module docstring).

    Raises
    ------
    InputFileError
        A missing or invalid file; an unknown table or field (the message lists the known
        ones); a value of the wrong type or outside the allowed ones; an unknown illuminant;
        a missing ``[risk]`` field. Each message names the file and the field.
    """
    p = os.fspath(path)
    try:
        data = tomllib.loads(Path(p).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputFileError(f"{p}: context file does not exist") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputFileError(f"{p}: invalid TOML ({exc})") from None
    values: dict[str, dict[str, Any]] = {t: {} for t in SCHEMA}
    tables = [t for t in SCHEMA if t]
    for key, value in data.items():
        if key in SCHEMA[""]:
            values[""][key] = _field(p, "", key, value)
        elif key in tables:
            if not isinstance(value, dict):
                raise InputFileError(f"{p}: {key}: must be a table ([{key}])")
            for k, v in value.items():
                if k not in SCHEMA[key]:
                    raise InputFileError(f"{p}: {key}.{k}: unknown field; known: "
                                         f"{', '.join(SCHEMA[key])}")
                values[key][k] = _field(p, key, k, v)
        else:
            raise InputFileError(f"{p}: {key}: unknown field; known: "
                                 f"{', '.join([*SCHEMA[''], *tables])}")
    for k in SCHEMA["risk"]:
        if k not in values["risk"]:
            raise InputFileError(f"{p}: risk.{k}: missing; must be one of {', '.join(LEVELS)}")
    illuminants = tuple(values["conditions"].get("illuminants", ("D65",)))
    if not illuminants:
        raise InputFileError(f"{p}: conditions.illuminants: must name at least one illuminant")
    for ill in illuminants:
        try:
            load_illuminant(ill)
        except FidelityError as exc:
            raise InputFileError(f"{p}: conditions.illuminants: {exc}") from None
    acc = values["acceptance"]
    return Context(
        path=p, name=values[""].get("name", Path(p).stem),
        question=values[""].get("question", ""),
        detectors=tuple(values["detectors"].get("models", ())), illuminants=illuminants,
        exposures_ev=tuple(float(x) for x in values["conditions"].get("exposures_ev", ())),
        max_delta_e=float(acc["max_delta_e"]) if "max_delta_e" in acc else None,
        max_dmap=float(acc["max_dmap"]) if "max_dmap" in acc else None,
        model_influence=values["risk"]["model_influence"],
        decision_consequence=values["risk"]["decision_consequence"])


@record
class Factor:
    """One credibility factor: its ``name``, ``level`` (1 to 5), the share ``score`` (0 to 1)
    the level is computed from, and the ``reason`` (the facts, in words)."""

    name: str
    level: int
    score: float
    reason: str

    def to_json(self) -> dict[str, Any]:
        """Every field."""
        return {"name": self.name, "level": self.level, "score": self.score,
                "reason": self.reason}


@record
class Acceptance:
    """One acceptance criterion judged on one subject: ``criterion`` (``max_delta_e``,
    ``max_dmap``), its ``limit``, the subject's ``value`` (None: no prediction) and whether it
    ``passed``."""

    subject: str
    criterion: str
    limit: float
    value: float | None
    passed: bool

    def to_json(self) -> dict[str, Any]:
        """Every field."""
        return {"subject": self.subject, "criterion": self.criterion, "limit": self.limit,
                "value": self.value, "passed": self.passed}


@record
class ContextAssessment:
    """A context's credibility assessment (:func:`assess`): the ``context``, the credibility
    ``factors``, the conditions ``outside`` the validity domain (in words) and the
    ``acceptance`` criteria judged per subject."""

    context: Context
    factors: tuple[Factor, ...]
    outside: tuple[str, ...]
    acceptance: tuple[Acceptance, ...]

    @property
    def credibility_level(self) -> int:
        """The lowest factor level (1 to 5)."""
        return min(f.level for f in self.factors)

    @property
    def required_level(self) -> int:
        """The level the model risk requires: :attr:`Context.risk_level`."""
        return self.context.risk_level

    @property
    def sufficient(self) -> bool:
        """The credibility level reaches the required level."""
        return self.credibility_level >= self.required_level

    @property
    def accepted(self) -> bool:
        """Every acceptance criterion passed on every subject."""
        return all(a.passed for a in self.acceptance)

    @property
    def exit_code(self) -> int:
        """0 when the credibility is sufficient and every criterion passed, else 1."""
        return 0 if self.sufficient and self.accepted else 1

    def to_json(self) -> dict[str, Any]:
        """The context, the factors, the levels, what lies outside, the acceptance."""
        return {"context": self.context.to_json(),
                "factors": [f.to_json() for f in self.factors],
                "credibility_level": self.credibility_level,
                "required_level": self.required_level, "sufficient": self.sufficient,
                "outside_domain": list(self.outside),
                "acceptance": [a.to_json() for a in self.acceptance],
                "accepted": self.accepted}


def _level(share: float) -> int:
    """Level 1 to 5 of a share in [0, 1]."""
    return 1 + round(4 * min(1.0, max(0.0, share)))


def code_verification(run: Callable[[Sequence[str]], Any]) -> Factor:
    """The code-verification factor: :data:`CODE_CHECKS` of ``fidelity qualify`` run here
    (``run``: :func:`fidelity.pipeline.qualify.qualify`, which the command line passes, or a
    stand-in in tests; taken as an argument because qualify audits through the check
    pipeline, which records this module's assessment)."""
    result = run(CODE_CHECKS)
    ran = [c for c in result.checks if c.status != "not run"]
    passed = [c for c in ran if c.status == "pass"]
    share = len(passed) / len(ran) if ran else 0.0
    failed = [c.name for c in ran if c.status != "pass"]
    reason = (f"{len(passed)} of {len(ran)} reference checks of fidelity qualify passed here "
              f"({', '.join(c.name for c in ran)})"
              + (f"; failed: {', '.join(failed)}" if failed else ""))
    return Factor("code verification", _level(share), share, reason)


def validation_coverage(context: Context, validated: ValidatedCameras | None) -> Factor:
    """The validation-coverage factor of ``context`` (module docstring)."""
    if validated is None:
        return Factor("validation coverage", 1, 0.0, "no validation record shipped")
    ill = [i for i in context.illuminants if i in validated.illuminants]
    det = [d for d in context.detectors if d in validated.models]
    held = validated.within / validated.cells if validated.cells else 0.0
    parts = [len(ill) / len(context.illuminants)]
    words = [f"{len(ill)} of {len(context.illuminants)} illuminants validated "
             f"({', '.join(ill) or 'none'}; validated: {', '.join(validated.illuminants)})"]
    if context.detectors:
        parts.append(len(det) / len(context.detectors))
        words.append(f"{len(det)} of {len(context.detectors)} detectors validated "
                     f"({', '.join(det) or 'none'}; validated: {', '.join(validated.models)})")
    share = min(parts) * held
    words.append(f"{validated.within} of {validated.cells} validation cells of "
                 f"{validated.cameras} cameras within the bound")
    return Factor("validation coverage", _level(share), share, "; ".join(words))


def assess(context: Context, reports: Sequence[tuple[str, CheckedSubject]], *,
           validated: ValidatedCameras | None = None,
           run: Callable[[Sequence[str]], Any]) -> ContextAssessment:
    """The credibility assessment of the checked ``reports`` (subject name, report) for
    ``context`` (module docstring); ``validated`` default: the shipped
    :func:`~fidelity.prediction.interval.load_validated_cameras`; ``run`` as for
    :func:`code_verification`."""
    validated = validated if validated is not None else load_validated_cameras()
    outside: list[str] = []
    inside = total = 0
    known = validated.illuminants if validated is not None else ()
    for ill in context.illuminants:
        total += 1
        if ill in known:
            inside += 1
        else:
            outside.append(f"illuminant {ill}: not among those validated "
                           f"({', '.join(known) or 'none'})")
    for ev in context.exposures_ev:
        total += 1
        outside.append(f"exposure {ev:+g} EV: the validation records no exposure offsets")
    for name, report in reports:
        for check in report.validity.checks if report.validity else ():
            total += 1
            if check.inside:
                inside += 1
            else:
                outside.append(f"{name}: {check.detail}")
    share = inside / total if total else 0.0
    applicability = Factor(
        "applicability", _level(share), share,
        f"{inside} of {total} context conditions and subject validity checks inside the "
        f"validity domain" + (f"; outside: {len(outside)}" if outside else ""))
    acceptance: list[Acceptance] = []
    for name, report in reports:
        if context.max_delta_e is not None:
            de = float(report.mean_delta_e)
            acceptance.append(Acceptance(name, "max_delta_e", context.max_delta_e, de,
                                         de <= context.max_delta_e))
        if context.max_dmap is not None:
            p = report.prediction
            dm = float(p.dmap_points) if p is not None and p.dmap_points is not None else None
            acceptance.append(Acceptance(name, "max_dmap", context.max_dmap, dm,
                                         dm is not None and dm <= context.max_dmap))
    return ContextAssessment(
        context, (code_verification(run), validation_coverage(context, validated),
                  applicability), tuple(outside), tuple(acceptance))


def context_lines(a: ContextAssessment) -> list[str]:
    """The assessment in a few terminal lines."""
    c = a.context
    lines = [f"context {c.name} ({c.path}): model risk level {a.required_level} "
             f"(influence {c.model_influence}, consequence {c.decision_consequence})"]
    lines += [f"  {f.name}: level {f.level} ({f.reason})" for f in a.factors]
    verdict = "sufficient" if a.sufficient else "INSUFFICIENT"
    lines.append(f"  credibility level {a.credibility_level} (lowest factor), required "
                 f"{a.required_level}: {verdict}")
    lines += [f"  outside the validity domain: {o}" for o in a.outside]
    failed = [x for x in a.acceptance if not x.passed]
    if a.acceptance:
        lines.append(f"  acceptance: {len(a.acceptance) - len(failed)} of {len(a.acceptance)} "
                     "criteria met" + "".join(
                         f"; {x.subject} {x.criterion} "
                         f"{'none' if x.value is None else f'{x.value:.2f}'} > {x.limit:g}"
                         for x in failed))
    return lines


def criteria_entries(a: ContextAssessment) -> Mapping[str, Any]:
    """The context's requirements and acceptance criteria as flat key/value pairs (for the
    STMD's classification entries)."""
    c = a.context
    out: dict[str, Any] = {"context": c.name, "context file": c.path,
                           "model influence": c.model_influence,
                           "decision consequence": c.decision_consequence,
                           "model risk level": c.risk_level,
                           "credibility level": a.credibility_level,
                           "credibility sufficient": a.sufficient,
                           "illuminants": ", ".join(c.illuminants)}
    if c.detectors:
        out["detectors"] = ", ".join(c.detectors)
    if c.max_delta_e is not None:
        out["acceptance max mean delta E00"] = c.max_delta_e
    if c.max_dmap is not None:
        out["acceptance max delta mAP (points)"] = c.max_dmap
    out["acceptance met"] = a.accepted
    return out


__all__ = ["CODE_CHECKS", "LEVELS", "SCHEMA", "Acceptance", "Context", "ContextAssessment",
           "Factor", "assess", "code_verification", "context_lines", "criteria_entries",
           "load_context", "validation_coverage"]
