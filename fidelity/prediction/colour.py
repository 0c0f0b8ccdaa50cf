"""Colour's part of a prediction: the SAFE-COLOR transform parameters that give a chart ΔE.

A :class:`~fidelity.prediction.table.Prediction` lists, per transform of SAFE-COLOR's Table I
(:mod:`fidelity.prediction.transforms`), the parameter that moves the chart by the ΔE predicted
for (:func:`transform_parameters`, from the shipped calibration table,
:mod:`fidelity.prediction.calibration`). A second camera property lists its own transforms'
parameters from a sibling module.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fidelity.core.record import record
from fidelity.prediction.calibration import calibrate_transforms, load_calibration_table
from fidelity.prediction.transforms import TRANSFORMS


@record
class TransformParameter:
    """The parameter of one SAFE-COLOR transform that gives chart ΔE ``delta_e``.

    ``param`` is None when ``reachable`` is False; ``method`` says how it was found
    (``calibrated``, ``solved``, ``interpolated``) or why it is unreachable; ``bracket`` holds
    the two calibrated (ΔE, parameter) points around ``delta_e``, when there are two.
    """

    transform: str
    delta_e: float
    param: float | None
    reachable: bool
    method: str | None
    bracket: tuple[tuple[float, float], tuple[float, float]] | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form (``bracket`` as two ``{"delta_e", "param"}`` objects)."""
        return {"transform": self.transform, "delta_e": self.delta_e, "param": self.param,
                "reachable": self.reachable, "method": self.method,
                "bracket": None if self.bracket is None else
                [{"delta_e": e, "param": q} for e, q in self.bracket]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TransformParameter:
        """Inverse of :meth:`to_json`."""
        b = data.get("bracket")
        param = data.get("param")
        return cls(str(data["transform"]), float(data["delta_e"]),
                   None if param is None else float(param), bool(data["reachable"]),
                   data.get("method"),
                   None if not b else ((float(b[0]["delta_e"]), float(b[0]["param"])),
                                       (float(b[1]["delta_e"]), float(b[1]["param"]))))


def transform_parameters(delta_e: float, calibration: Any = None, *,
                         solve: bool = True) -> list[TransformParameter]:
    """The SAFE-COLOR transform parameters that give chart ΔE ``delta_e``, one per transform.

    From the shipped calibration table (``fidelity.prediction.calibration.load_calibration_table()``): at
    a calibrated target, the table's parameter (``method: "calibrated"``). Between targets the
    table's two bracketing entries are given (``bracket``) and the parameter is solved on the
    chart for this exact ΔE (``fidelity.prediction.calibration.calibrate_transforms``, every
    transform at once; ``method: "solved"``),
    or, with ``solve=False``, interpolated linearly in ΔE between the bracket
    (``method: "interpolated"``; below the first target the identity at the chart's baseline ΔE
    is the lower end). A ΔE below the chart's baseline or beyond a transform's reach is
    reported as unreachable (``param: null``), not as a number.
    """
    if calibration is None:
        calibration = load_calibration_table()

    baseline = float(calibration.baseline_delta_e)
    by_transform: dict[str, list[Any]] = {}
    for e in calibration.entries:
        by_transform.setdefault(e.transform, []).append(e)
    for name in by_transform:
        by_transform[name].sort(key=lambda e: float(e.target))
    calibrated = {name: _calibrated(entries, delta_e) for name, entries in by_transform.items()}
    solved: dict[str, Any] = {}
    if solve and delta_e > baseline:  # the transforms to solve, at once (in lockstep)
        ask = [name for name, entry in calibrated.items() if entry is None]
        solved = dict(zip(ask, calibrate_transforms(ask, delta_e), strict=True))
    out: list[TransformParameter] = []
    for name, entries in by_transform.items():
        spec = TRANSFORMS.get(name)
        nodes: list[tuple[float, float]] = []
        if spec is not None:
            nodes.append((baseline, float(spec.identity)))
        unreachable_from = None
        for e in entries:
            if e.reachable and e.param is not None:
                nodes.append((float(e.target), float(e.param)))
            elif unreachable_from is None:
                unreachable_from = float(e.target)
        row: dict[str, Any] = {"transform": name, "delta_e": delta_e, "param": None,
                               "reachable": False, "method": None, "bracket": None}
        below = [n for n in nodes if n[0] <= delta_e]
        above = [n for n in nodes if n[0] >= delta_e]
        if below and above:
            row["bracket"] = [{"delta_e": below[-1][0], "param": below[-1][1]},
                              {"delta_e": above[0][0], "param": above[0][1]}]
        if (exact := calibrated[name]) is not None:
            row.update(param=float(exact.param), reachable=True, method="calibrated",
                       bracket=None)
        elif delta_e <= baseline:
            row.update(method=f"unreachable: at or below the chart's baseline ΔE {baseline:.4g}")
        elif solve:
            entry = solved[name]
            if entry.reachable and entry.param is not None:
                row.update(param=float(entry.param), reachable=True, method="solved")
            else:
                row.update(method=f"unreachable: the transform reaches at most ΔE "
                                  f"{entry.delta_e:.4g}")
        elif row["bracket"] and (unreachable_from is None or delta_e < unreachable_from):
            (e0, p0), (e1, p1) = below[-1], above[0]
            p = p0 if e1 == e0 else p0 + (p1 - p0) * (delta_e - e0) / (e1 - e0)
            row.update(param=float(p), reachable=True, method="interpolated")
        else:
            row.update(method="unreachable within the transform's range")
        out.append(TransformParameter(
            name, float(row["delta_e"]), row["param"], row["reachable"], row["method"],
            None if row["bracket"] is None else (
                (float(row["bracket"][0]["delta_e"]), float(row["bracket"][0]["param"])),
                (float(row["bracket"][1]["delta_e"]), float(row["bracket"][1]["param"])))))
    return out


def _calibrated(entries: list[Any], delta_e: float) -> Any:
    """The reachable entry of ``entries`` (sorted by target) calibrated at ``delta_e`` itself
    (the first at that target), or None."""
    exact = [e for e in entries if abs(float(e.target) - delta_e) < 1e-9]
    if exact and exact[0].reachable and exact[0].param is not None:
        return exact[0]
    return None


__all__ = [
    "TransformParameter",
    "transform_parameters",
]
