"""The uncertainty of a predicted loss and the domain its evidence covers.

:func:`prediction_interval`: a predicted loss (``dmap_points`` or another column of a
:class:`~fidelity.prediction.table.Prediction`) with its standard uncertainty from two sources,
combined as uncorrelated (JCGM 100 5.1.2):

- the table's sampling error at that ΔE: the larger of the standard errors the sweep
  recorded at the two table points around the ΔE (the larger of the paired image bootstrap
  and the jackknife, or what tables measured before it recorded: the table's provenance says
  which)
  (:class:`~fidelity.prediction.interpolate.SamplingError`; measured tables, each column
  its own: ``dmap_points``, ``dmap_relative`` (% of baseline), ``dap_person_points``,
  ``dap_bicycle_points``, from the ``<column>_se`` of the table's points; None otherwise);
- the chart ΔE's own standard uncertainty ``u(ΔE)`` (:mod:`fidelity.measure.uncertainty`)
  propagated through the table: ``|c| u(ΔE)`` with the sensitivity ``c`` the slope of the
  table's answer, by central differences over ``±h`` (``h`` = max(u(ΔE), 0.01), one-sided at
  ΔE < h).

:func:`validity_domain`: whether an answer lies inside the domain of its evidence: the ΔE range
the table measured (a ΔE outside is answered by a conservative ceiling, not extrapolated), the
detector sizes it measured (a size it has no curve of is answered by another size's curve), and
whether the table holds measured losses or published bounds.

:class:`ValidatedCameras`: the camera models the prediction was validated on (their
illuminants and the kinds of their processing stages, shipped as ``validation-domain.json``),
and :meth:`ValidatedCameras.camera_checks`: whether a camera model lies among them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import field
from functools import lru_cache
from typing import Any

from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.prediction.interpolate import ColumnStatus
from fidelity.prediction.table import Prediction, predict

#: Smallest ΔE step of the slope's central difference.
MIN_STEP = 0.01


@record
class PredictionInterval:
    """A predicted loss ``value`` of ``column`` (percentage points, or % for
    ``dmap_relative``) with its uncertainty: the table's sampling error ``table_se`` (None:
    unknown), the ``slope`` of the table (loss per ΔE00) and the chart ΔE's standard uncertainty
    ``delta_e_uncertainty``. ``k`` is the coverage factor of the stated ``interval``.
    ``validated_upper``: the validated bound with the model's own error
    (:mod:`fidelity.prediction.validated`), and ``validated_method`` its words; None where
    none applies."""

    column: str
    value: float
    table_se: float | None
    slope: float
    delta_e_uncertainty: float
    k: float = 2.0
    validated_upper: float | None = None
    validated_method: str | None = None

    @property
    def propagated(self) -> float:
        """``|slope| u(ΔE)``: the part of the ΔE's uncertainty."""
        return abs(self.slope) * self.delta_e_uncertainty

    @property
    def standard_uncertainty(self) -> float:
        """Combined standard uncertainty (k = 1)."""
        return math.sqrt((self.table_se or 0.0) ** 2 + self.propagated ** 2)

    @property
    def swamped(self) -> bool:
        """True when the standard uncertainty is at least the value itself (``u >= |value|``,
        ``u > 0``): the table does not resolve the loss from zero (e.g. the bicycle column
        below ΔE 6, docs/predict.md); a guarded decision at a limit above the value is
        undecided there unless ``value + k u`` is below the limit."""
        u = self.standard_uncertainty
        return u > 0 and u >= abs(self.value)

    def plus_minus(self) -> str:
        """``" ± 0.27 (k=1)"``: the standard uncertainty as the reports print it after the
        predicted value."""
        return f" ± {self.standard_uncertainty:.2f} (k=1)"

    def interval(self, k: float | None = None) -> tuple[float, float]:
        """``value ± k u`` (``k`` default :attr:`k`)."""
        kk = self.k if k is None else k
        u = kk * self.standard_uncertainty
        return (self.value - u, self.value + u)

    def to_json(self) -> dict[str, Any]:
        """The fields, the ``propagated`` part, the ``standard_uncertainty`` (k = 1), the
        ``interval`` at ``k`` and the ``method``."""
        lo, hi = self.interval()
        return {"column": self.column, "value": self.value, "table_se": self.table_se,
                "slope": self.slope, "delta_e_uncertainty": self.delta_e_uncertainty,
                "propagated": self.propagated,
                "standard_uncertainty": self.standard_uncertainty, "k": self.k,
                "interval": [lo, hi],
                "method": ("sqrt(table_se^2 + (slope u(ΔE))^2); table_se the larger SE of "
                           "the table points around ΔE; slope by central differences"),
                **({} if self.validated_upper is None else
                   {"validated_upper": self.validated_upper,
                    "validated_method": self.validated_method})}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PredictionInterval:
        """Inverse of :meth:`to_json`."""
        se = d.get("table_se")
        upper = d.get("validated_upper")
        return cls(str(d["column"]), float(d["value"]), None if se is None else float(se),
                   float(d["slope"]), float(d["delta_e_uncertainty"]), float(d.get("k", 2.0)),
                   None if upper is None else float(upper), d.get("validated_method"))


def _column_value(p: Prediction, column: str) -> float | None:
    c = p.columns.get(column)
    return None if c is None else c.value


def prediction_interval(prediction: Prediction, delta_e_uncertainty: float,
                        column: str = "dmap_points", k: float = 2.0
                        ) -> PredictionInterval | None:
    """The predicted loss of ``column`` with its uncertainty (module docstring); None when the
    column has no value or the prediction's table has no curves (read back from JSON)."""
    value = _column_value(prediction, column)
    if value is None or not prediction.table.curves:
        return None
    de, u = prediction.delta_e, max(float(delta_e_uncertainty), 0.0)
    h = max(u, MIN_STEP)
    lo, hi = max(de - h, 0.0), de + h

    def at(x: float) -> float | None:
        return _column_value(predict(x, prediction.size, prediction.table,
                                     method=prediction.method,
                                     baseline_map=prediction.baseline_map, transforms=False),
                             column)

    a, b = at(lo), at(hi)
    slope = 0.0 if a is None or b is None or hi <= lo else (b - a) / (hi - lo)
    sampling = prediction.se(column)
    se = None if sampling is None else sampling.high
    return PredictionInterval(column, float(value), se, float(slope), u, k)


@record
class DomainCheck:
    """One check of the validity domain: ``name``, whether the answer is ``inside`` and the
    ``detail`` in words."""

    name: str
    inside: bool
    detail: str

    def to_json(self) -> dict[str, Any]:
        """``{"name", "inside", "detail"}``."""
        return {"name": self.name, "inside": self.inside, "detail": self.detail}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DomainCheck:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["name"]), bool(d["inside"]), str(d["detail"]))


@record
class ValidityDomain:
    """The checks of an answer against the domain its evidence covers; ``inside`` when all
    are."""

    checks: tuple[DomainCheck, ...]

    @property
    def inside(self) -> bool:
        """True when every check is inside."""
        return all(c.inside for c in self.checks)

    @property
    def outside(self) -> tuple[DomainCheck, ...]:
        """The checks outside the domain."""
        return tuple(c for c in self.checks if not c.inside)

    def with_check(self, check: DomainCheck) -> ValidityDomain:
        """This domain with one more check."""
        return ValidityDomain((*self.checks, check))

    def to_json(self) -> dict[str, Any]:
        """``{"inside", "checks"}``."""
        return {"inside": self.inside, "checks": [c.to_json() for c in self.checks]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidityDomain:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(DomainCheck.from_json(c) for c in d["checks"]))


def validity_domain(prediction: Prediction, column: str = "dmap_points") -> ValidityDomain:
    """Whether ``prediction``'s answer of ``column`` lies inside its table's evidence: the ΔE
    range measured, the detector sizes measured, measured losses (not published bounds)."""
    col = prediction.columns[column]
    rng = col.delta_e_range
    span = f"[{rng[0]:g}, {rng[1]:g}]" if rng else "none"
    if col.status is ColumnStatus.INTERPOLATED:
        de = DomainCheck("table ΔE range", True,
                         f"ΔE {prediction.delta_e:.2f} inside the table's range {span}")
    elif col.status is ColumnStatus.NO_DATA:
        de = DomainCheck("table ΔE range", False, f"the table has no {column} data")
    else:
        where = "below" if col.status is ColumnStatus.BELOW_RANGE else "above"
        de = DomainCheck("table ΔE range", False,
                         f"ΔE {prediction.delta_e:.2f} {where} the table's range {span}: "
                         f"answered by a conservative ceiling, not extrapolated")
    sizes = prediction.table.sizes()
    measured = ", ".join(sizes) or "none"
    same = prediction.size in sizes
    if prediction.size == "any" and sizes:  # the worst case over the sizes the table measured
        size = DomainCheck("detector size", True,
                           f"any detector size: the table's measured sizes ({measured})")
    else:
        size = DomainCheck(
            "detector size", same,
            f"detector size {prediction.size} measured by the table (sizes {measured})" if same
            else f"detector size {prediction.size} not measured by the table (sizes "
                 f"{measured}); answered by the curves of {prediction.size_used}")
    kind = DomainCheck(
        "table kind", prediction.table.kind.measured,
        f"table {prediction.table.name}: {prediction.table.kind.value}"
        + ("" if prediction.table.kind.measured else
           " (published bounds, not measured by this tool)"))
    return ValidityDomain((de, size, kind))


#: The processing stages a camera's kind is stated in (:meth:`fidelity.camera.model.
#: CameraModel.stage_kinds`), in the order the checks name them.
STAGES = ("exposure", "white balance", "colour correction", "tone curve", "bit depth")

#: The shipped record of the validated cameras (written by ``fidelity validate`` as
#: ``domain.json`` beside its report; copied here by ``benchmarks.tools.after_resweep``).
VALIDATED_CAMERAS_FILE = "validation-domain.json"


@record
class ValidatedCameras:
    """The camera models the prediction was validated on (``fidelity validate``, the
    validation report) and how it held on them.

    ``cameras``: how many; ``illuminants``: the scene illuminants they were rendered under;
    ``stages``: per stage of :data:`STAGES`, the kinds the cameras had (e.g. ``"tone curve":
    ("gamma", "lut", "srgb")``); ``sensitivities``: the sensors' spectral sensitivities;
    ``models``: the detectors measured; ``cells``, ``within``, ``within_2se``: the (camera,
    detector) cells, and how many had their measured mAP loss within the measured table's
    bound, and within it plus two standard errors; ``degradations``: per degradation of
    :data:`DEGRADATIONS` (noise, optics, vignetting), the ``kinds`` the cameras had
    (``"none"`` for one without it) and the ``ranges`` ``(lo, hi)`` of each numeric parameter
    they had (:meth:`~fidelity.camera.model.CameraModel.degradations`); empty when the
    record predates them (no check is claimed then)."""

    cameras: int
    illuminants: tuple[str, ...]
    stages: Mapping[str, tuple[str, ...]]
    sensitivities: tuple[str, ...]
    models: tuple[str, ...]
    cells: int
    within: int
    within_2se: int
    degradations: Mapping[str, ValidatedDegradation] = field(default_factory=dict)
    properties: ValidatedProperties | None = None

    def to_json(self) -> dict[str, Any]:
        """The layout of :data:`VALIDATED_CAMERAS_FILE` (``properties`` only when stated)."""
        out: dict[str, Any] = {
            "cameras": self.cameras, "illuminants": list(self.illuminants),
            "stages": {k: list(v) for k, v in self.stages.items()},
            "sensitivities": list(self.sensitivities), "models": list(self.models),
            "cells": self.cells, "within": self.within, "within_2se": self.within_2se,
            "degradations": {k: v.to_json() for k, v in self.degradations.items()}}
        if self.properties is not None:
            out["properties"] = self.properties.to_json()
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidatedCameras:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["cameras"]), tuple(d["illuminants"]),
                   {k: tuple(v) for k, v in d["stages"].items()},
                   tuple(d["sensitivities"]), tuple(d["models"]), int(d["cells"]),
                   int(d["within"]), int(d["within_2se"]),
                   {k: ValidatedDegradation.from_json(v)
                    for k, v in (d.get("degradations") or {}).items()},
                   ValidatedProperties.from_json(d["properties"]) if d.get("properties")
                   else None)

    def camera_checks(self, stage_kinds: Mapping[str, str], illuminant: str,
                      degradations: Mapping[str, tuple[str, Mapping[str, float]]] | None = None
                      ) -> tuple[DomainCheck, ...]:
        """Whether a camera (its :meth:`~fidelity.camera.model.CameraModel.stage_kinds`)
        rendered under ``illuminant`` is like the cameras validated: the ``validated
        illuminant`` check (the illuminant is one they were rendered under) and the
        ``validated camera kind`` check (each stage of a kind some validated camera had; a bit
        depth inside the range validated, a float output only if one was); then, given the
        camera's ``degradations`` (:meth:`~fidelity.camera.model.CameraModel.degradations`),
        a ``validated noise``, ``validated optics`` and ``validated vignetting`` check for
        each degradation this record states (:func:`degradation_check`), against what the
        colour validation's cameras and, where stated, the sharpness and noise validation's
        (:attr:`properties`) had."""
        held = (f"{self.cameras} cameras, {self.within} of {self.cells} (camera, detector) "
                f"cells within the measured bound")
        light = illuminant in self.illuminants
        ill = DomainCheck(
            "validated illuminant", light,
            f"illuminant {illuminant}: among those the validation rendered "
            f"({', '.join(self.illuminants)}; {held})" if light else
            f"illuminant {illuminant}: not among those the validation rendered "
            f"({', '.join(self.illuminants)}); the prediction was not validated under it")
        off = [f"{stage} {stage_kinds[stage]} (validated: {', '.join(self.stages[stage])})"
               for stage in STAGES if stage in stage_kinds and stage in self.stages
               and not _kind_validated(stage, stage_kinds[stage], self.stages[stage])]
        like = ", ".join(f"{stage} {stage_kinds[stage]}" for stage in STAGES
                         if stage in stage_kinds)
        kind = DomainCheck(
            "validated camera kind", not off,
            f"a camera like those validated: {like} ({held})" if not off else
            f"not validated: {'; '.join(off)}; the prediction was not validated on such a "
            f"camera")
        extra = [degradation_check(name, *degradations[name], *self.degradation(name))
                 for name in DEGRADATIONS
                 if degradations is not None and name in degradations
                 and name in self.degradations]
        return (ill, kind, *extra)

    def degradation(self, name: str) -> tuple[ValidatedDegradation, str | None]:
        """What the validated cameras had of degradation ``name``: the colour validation's
        (:attr:`degradations`) joined with the sharpness and noise validation's
        (:func:`joined_degradation`), and the words naming that second validation (None when
        this record states none)."""
        own = self.degradations[name]
        p = self.properties
        if p is None or name not in p.degradations:
            return own, None
        return joined_degradation(own, p.degradations[name]), p.words()


#: The image degradations the validity domain states besides the colour stages, in the order
#: its checks name them (:meth:`fidelity.camera.model.CameraModel.degradations`).
DEGRADATIONS = ("noise", "optics", "vignetting")

#: The unit of each numeric degradation parameter, in the checks' words.
PARAMETER_UNITS = {"full_well": "e-", "read_noise": "e- rms", "sigma_px": "px",
                   "radius_px": "px", "f_number": "", "diagonal_fov_deg": "deg"}


@record
class ValidatedDegradation:
    """What the validated cameras had of one degradation (noise, optics, vignetting): the
    ``kinds`` (``"none"``: a camera without it) and, per numeric parameter, the ``ranges``
    ``(lo, hi)`` of the values they had."""

    kinds: tuple[str, ...]
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """``{"kinds": [...], "ranges": {"full_well": [lo, hi], ...}}``."""
        return {"kinds": list(self.kinds),
                "ranges": {k: [lo, hi] for k, (lo, hi) in self.ranges.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidatedDegradation:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(d["kinds"]),
                   {k: (float(v[0]), float(v[1])) for k, v in (d.get("ranges") or {}).items()})

    def words(self) -> str:
        """``none only`` or ``shot+read (full_well 1000 to 40000 e-), none``."""
        if self.kinds == ("none",):
            return "none only"
        spans = ", ".join(f"{k} {lo:g} to {hi:g} {PARAMETER_UNITS.get(k, '')}".rstrip()
                          for k, (lo, hi) in self.ranges.items())
        return ", ".join(self.kinds) + (f" ({spans})" if spans else "")


@record
class ValidatedProperties:
    """The camera models the sharpness and noise verdict was validated on (``fidelity validate
    --properties``, ``reports/validation/properties.md``): ``cameras``, the ``models`` measured,
    the (camera, detector) ``cells``, how many had their measured ΔmAP within the verdict's
    combined loss (``within``) and within it plus two standard errors (``within_2se``), and per
    degradation of :data:`DEGRADATIONS` what those cameras had (``degradations``)."""

    cameras: int
    models: tuple[str, ...]
    cells: int
    within: int
    within_2se: int
    degradations: Mapping[str, ValidatedDegradation]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"cameras": self.cameras, "models": list(self.models), "cells": self.cells,
                "within": self.within, "within_2se": self.within_2se,
                "degradations": {k: v.to_json() for k, v in self.degradations.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidatedProperties:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["cameras"]), tuple(d["models"]), int(d["cells"]), int(d["within"]),
                   int(d["within_2se"]),
                   {k: ValidatedDegradation.from_json(v)
                    for k, v in (d.get("degradations") or {}).items()})

    def words(self) -> str:
        """``the sharpness and noise validation: 39 cameras, 74 of 78 (camera, detector)
        cells within the combination rule's loss, before the validated margin``."""
        return (f"the sharpness and noise validation: {self.cameras} cameras, {self.within} of "
                f"{self.cells} (camera, detector) cells within the combination rule's loss, "
                f"before the validated margin")


def joined_degradation(a: ValidatedDegradation, b: ValidatedDegradation
                       ) -> ValidatedDegradation:
    """What two validations' cameras had of one degradation together: the union of their
    kinds (sorted), and per parameter the smallest and largest value either had."""
    ranges = dict(a.ranges)
    for k, (lo, hi) in b.ranges.items():
        ranges[k] = (min(lo, ranges[k][0]), max(hi, ranges[k][1])) if k in ranges else (lo, hi)
    return ValidatedDegradation(tuple(sorted({*a.kinds, *b.kinds})), dict(sorted(ranges.items())))


def validated_degradation(seen: list[tuple[str, Mapping[str, float]]]
                          ) -> ValidatedDegradation:
    """The :class:`ValidatedDegradation` of the validated cameras' ``seen`` degradations
    (each a camera's ``(kind, parameters)``): the kinds in sorted order, each parameter's
    smallest and largest value."""
    values: dict[str, list[float]] = {}
    for _, params in seen:
        for k, v in params.items():
            values.setdefault(k, []).append(float(v))
    return ValidatedDegradation(tuple(sorted({kind for kind, _ in seen})),
                                {k: (min(v), max(v)) for k, v in sorted(values.items())})


def degradation_check(name: str, kind: str, params: Mapping[str, float],
                      validated: ValidatedDegradation, source: str | None = None
                      ) -> DomainCheck:
    """Whether a camera's degradation ``name`` (``kind`` and its numeric ``params``) lies
    among the validated cameras' (``validated``): inside when its kind is one they had and
    each of its parameters lies within their range (a kind none of them had, or a parameter
    none of them had a value of, is outside). The detail gives the value and the range, and
    ``source``, the validation the range comes from, where given."""
    shown = ", ".join(f"{k} {v:g} {PARAMETER_UNITS.get(k, '')}".rstrip()
                      for k, v in params.items())
    this = (f"no {name}" if kind == "none" else f"{name} {kind}") + (
        f" ({shown})" if shown else "")
    off = [k for k, v in params.items()
           if k not in validated.ranges
           or not validated.ranges[k][0] <= v <= validated.ranges[k][1]]
    inside = kind in validated.kinds and not off
    of = f"{name}: {validated.words()}" + ("" if source is None else f"; {source}")
    return DomainCheck(
        f"validated {name}", inside,
        f"{this}: like the cameras validated ({of})" if inside else
        f"{this}: not validated (the validated cameras' {of}); the prediction was not "
        f"validated on such a camera")


def _kind_validated(stage: str, kind: str, validated: tuple[str, ...]) -> bool:
    """``kind`` among ``validated``; a bit depth within the range of those validated."""
    if stage != "bit depth" or kind == "float":
        return kind in validated
    depths = [int(v) for v in validated if v.isdigit()]
    return bool(depths) and min(depths) <= int(kind) <= max(depths)


def shipped_domain(colour: Mapping[str, Any], properties: Mapping[str, Any] | None
                   ) -> dict[str, Any]:
    """The shipped :data:`VALIDATED_CAMERAS_FILE` from what the two validations write beside
    their reports: the colour validation's ``domain.json`` (``colour``) with the sharpness and
    noise validation's ``properties-domain.json`` (``properties``, its ``source`` left out) as
    its ``properties``."""
    out = dict(colour)
    if properties is not None:
        out["properties"] = {k: v for k, v in properties.items() if k != "source"}
    return out


@lru_cache(maxsize=1)
def load_validated_cameras() -> ValidatedCameras | None:
    """The shipped :class:`ValidatedCameras` (:data:`VALIDATED_CAMERAS_FILE`); None when the
    package ships none."""
    path = resource_dir("data") / VALIDATED_CAMERAS_FILE
    if not path.is_file():
        return None
    return ValidatedCameras.from_json(json.loads(path.read_text(encoding="utf-8")))


__all__ = [
    "DEGRADATIONS",
    "MIN_STEP",
    "PARAMETER_UNITS",
    "STAGES",
    "VALIDATED_CAMERAS_FILE",
    "DomainCheck",
    "PredictionInterval",
    "ValidatedCameras",
    "ValidatedDegradation",
    "ValidatedProperties",
    "ValidityDomain",
    "load_validated_cameras",
    "prediction_interval",
    "shipped_domain",
    "degradation_check",
    "joined_degradation",
    "validated_degradation",
    "validity_domain",
]
