"""Calibration: the transform parameter that puts a chart at a target mean ΔE00.

SAFE-COLOR ("Calibration" in ``shared/reference/safecolor.md``): for each transform f and target
ΔE_t find x with mean-ΔE00(f(chart, x), reference) = ΔE_t, inside the transform's range on the
side of its direction. The chart image is the reference Lab converted to sRGB and clipped to
[0, 1]; ΔE_t is absolute (measured against the reference Lab), so the untransformed chart's own
ΔE (about 0.29, from gamut clipping) is the baseline, reported beside the table.

Method: the ΔE curve of each transform is evaluated once on a scan grid from the identity
outwards (one vectorised call); the first grid interval whose ends straddle the target brackets
the root, and Brent's method (``scipy.optimize.brentq``) solves it to ``|ΔE - target| <= 1e-4``
(typically 1e-10). The paper used ``minimize_scalar`` and stopped within 0.3 %. One target
alone (:func:`calibrate_transform`, as a prediction asks for its ΔE) evaluates the same grid
from the identity outwards in growing chunks and stops at the first bracket: the same entry
for the points up to the target.

Root choice (several roots exist for hue, whose ΔE is not monotonic in h, and wherever a curve
turns back): the root nearest the identity along the scan, i.e. the smallest perturbation that
reaches the target. For ``hue`` the positive rotations (0..180°) are scanned first, then the
negative ones (0..-180°). A target the curve never reaches is reported unreachable together with
the largest ΔE the transform reaches in its range.
"""

from __future__ import annotations

import json
import math
from collections.abc import Generator, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.charts import DEFAULT_CHART, Chart, load_chart
from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab
from fidelity.core.errors import InputFileError, InvalidValueError, UnreachableTargetError
from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.prediction.scalar import brent_search
from fidelity.prediction.transforms import TRANSFORMS, TransformSpec, get_transform

__all__ = [
    "DEFAULT_TARGETS",
    "MAX_TARGETS",
    "TOLERANCE",
    "CalibrationEntry",
    "CalibrationTable",
    "calibrate_transform",
    "calibrate_transforms",
    "calibration_table",
    "calibration_table_csv",
    "calibration_table_text",
    "delta_e_curve",
    "load_calibration_table",
    "transform_delta_e",
]

#: SAFE-COLOR targets: ΔE 1, 2, ..., 12, then 15, 18, ..., 45.
#: Most target ΔE values of one calibration table (each costs a root search per transform).
MAX_TARGETS = 1000
DEFAULT_TARGETS: tuple[float, ...] = tuple(float(t) for t in [*range(1, 13), *range(15, 46, 3)])
#: Largest accepted ``|ΔE - target|`` of a calibrated parameter.
TOLERANCE = 1e-4
#: File name of the shipped default table (package data).
DEFAULT_TABLE_FILE = "calibration-safecolor.json"

_SCAN_POINTS = 401


@record
class CalibrationEntry:
    """The calibrated parameter of one (transform, target); ``param`` is None when unreachable.

    ``delta_e`` is the chart ΔE reached at ``param``, or, for an unreachable target, the
    largest ΔE the transform reaches in its range.
    """

    transform: str
    target: float
    param: float | None
    delta_e: float
    reachable: bool

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@record
class CalibrationTable:
    """A calibration table for one chart: one entry per (transform, target)."""

    chart: str
    baseline_delta_e: float
    entries: tuple[CalibrationEntry, ...]

    def param(self, transform: str, target: float) -> float | None:
        """The parameter for (transform, target); None if unreachable. KeyError if absent."""
        return self.entry(transform, target).param

    def entry(self, transform: str, target: float) -> CalibrationEntry:
        for e in self.entries:
            if e.transform == transform and abs(e.target - float(target)) < 1e-9:
                return e
        raise KeyError(f"no calibration entry for ({transform}, ΔE {target:g})")

    @property
    def transforms(self) -> list[str]:
        return list(dict.fromkeys(e.transform for e in self.entries))

    @property
    def targets(self) -> list[float]:
        return sorted({e.target for e in self.entries})

    def to_json(self) -> dict[str, Any]:
        """The documented JSON form: chart, baseline_delta_e, entries."""
        return {
            "chart": self.chart,
            "baseline_delta_e": self.baseline_delta_e,
            "entries": [e.to_json() for e in self.entries],
        }

    @classmethod
    def from_json(cls, doc: dict[str, Any], source: str = "calibration table") -> CalibrationTable:
        try:
            entries = tuple(
                CalibrationEntry(
                    transform=str(e["transform"]),
                    target=float(e["target"]),
                    param=None if e["param"] is None else float(e["param"]),
                    delta_e=float(e["delta_e"]),
                    reachable=bool(e["reachable"]),
                )
                for e in doc["entries"]
            )
            return cls(str(doc["chart"]), float(doc["baseline_delta_e"]), entries)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputFileError(f"{source}: not a calibration table ({exc})") from None


def _chart(chart: Chart | str | None) -> Chart:
    if chart is None:
        return load_chart(DEFAULT_CHART)
    return chart if isinstance(chart, Chart) else load_chart(chart)


def transform_delta_e(
    transform: str | TransformSpec, param: float | NDArray[np.float64], chart: Chart | str | None = None
) -> NDArray[np.float64]:
    """Chart ΔE (mean ΔE00 over patches) after ``transform`` with ``param`` (scalar or 1-D array).

    Returns an array of the shape of ``param``.
    """
    spec = get_transform(transform) if isinstance(transform, str) else transform
    c = _chart(chart)
    return _chart_delta_e(_transformed(spec, np.asarray(param, dtype=np.float64), c), c)


def _transformed(spec: TransformSpec, p: NDArray[np.float64], chart: Chart
                 ) -> NDArray[np.float64]:
    """The chart's sRGB image through ``spec`` at each parameter of ``p``: (*p.shape, n, 3)."""
    image = chart.srgb.reshape((1,) * p.ndim + chart.srgb.shape)  # (1.., n, 3)
    return np.asarray(spec.function(image, p[..., None]), np.float64)  # param over patches


def _chart_delta_e(images: NDArray[np.float64], chart: Chart) -> NDArray[np.float64]:
    """Mean ΔE00 of each transformed chart image (..., n, 3) against the reference."""
    return np.asarray(delta_e_2000(srgb_to_lab(images), chart.lab).mean(axis=-1),
                      dtype=np.float64)


def _scan_grid(spec: TransformSpec) -> list[NDArray[np.float64]]:
    """Scan paths from the identity outwards (one path, or two for two-sided ``hue``)."""
    near, far = spec.param_range
    if spec.name == "hue":
        return [np.linspace(0.0, 180.0, _SCAN_POINTS), np.linspace(0.0, -180.0, _SCAN_POINTS)]
    if spec.scale == "log":
        path = np.geomspace(near, far, _SCAN_POINTS)
    else:
        path = np.linspace(near, far, _SCAN_POINTS)
    # Refine towards the far end, where curves that approach a limit (a uniform grey chart at
    # c -> 0, a clipped channel) change fastest: a log-spaced tail down to 1e-6 of the interval.
    tail = far + (near - far) * np.geomspace(1e-6, 1.0 / (_SCAN_POINTS - 1), 64)
    path = np.concatenate([path[:-1], tail[::-1], [far]])
    return [path]


def delta_e_curve(
    transform: str, chart: Chart | str | None = None
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The scan paths of a transform and the chart ΔE along each: [(params, delta_e), ...]."""
    spec = get_transform(transform)
    c = _chart(chart)
    return [(path, transform_delta_e(spec, path, c)) for path in _scan_grid(spec)]


def _first_crossing(des: NDArray[np.float64], target: float) -> tuple[int, bool] | None:
    """The first grid point on ``target`` (``(i, True)``) or grid interval ``[i, i + 1]`` that
    straddles it (``(i, False)``) along a scan path, nearest the identity; None if neither."""
    diff = des - target
    exact = np.flatnonzero(diff == 0.0)
    crossing = np.flatnonzero(np.sign(diff[:-1]) * np.sign(diff[1:]) < 0)
    candidates = sorted([(int(i), True) for i in exact] + [(int(i), False) for i in crossing],
                        key=lambda c: c[0])  # an exact point before a crossing at the same i
    return candidates[0] if candidates else None


def _root(spec: TransformSpec, chart: Chart, target: float, params: NDArray[np.float64],
          first: tuple[int, bool]) -> CalibrationEntry | None:
    """The entry at the scan's first candidate ``first`` on ``params``: the grid point, or
    Brent's root inside the interval; None when the interval holds a jump, not a root
    (:func:`_root_search` with its chart ΔE evaluated here)."""
    search = _root_search(spec, target, params, first)
    request = next(search)
    while True:
        try:
            request = search.send(_chart_delta_e(_transformed(spec, request, chart), chart))
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]


def _solve(
    spec: TransformSpec,
    chart: Chart,
    target: float,
    curves: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
) -> CalibrationEntry:
    """The entry of ``target`` from the transform's scanned ``curves`` (:func:`delta_e_curve`)."""
    for params, des in curves:
        first = _first_crossing(des, target)
        if first is not None and (entry := _root(spec, chart, target, params, first)):
            return entry
    largest = max(float(np.max(d)) for _, d in curves)
    return CalibrationEntry(spec.name, target, None, largest, False)


#: Scan points evaluated at once by :func:`_search` first (doubling on each step).
_FIRST_CHUNK = 32


#: A search's request (:func:`_search`): the chart ΔE at these parameters of its transform.
_Request = NDArray[np.float64]


def _search(spec: TransformSpec, target: float
            ) -> Generator[_Request, NDArray[np.float64], CalibrationEntry]:
    """:func:`_solve` on scan paths evaluated from the identity outwards in growing chunks,
    stopping at the first candidate: the same grid points, hence the same entry, as the
    whole scan (one chart ΔE per point, independent of the other points), for the cost of
    the points up to the target (a few dozen of 465 for ΔE below 10). A coroutine: it yields
    the parameters whose chart ΔE it needs and is sent them (:func:`_run_searches`)."""
    largest = -math.inf
    for params in _scan_grid(spec):
        des = np.empty(0)
        size = _FIRST_CHUNK
        first: tuple[int, bool] | None = None
        while des.size < params.size:
            stop = min(params.size, des.size + size)
            des = np.concatenate([des, (yield params[des.size:stop])])
            size *= 2
            first = _first_crossing(des, target)
            # a candidate found on a prefix is the whole path's first: any later one needs a
            # point beyond the prefix, so its index is at least the prefix's last
            if first is not None:
                break
        if first is not None and (entry := (yield from _root_search(spec, target, params,
                                                                     first))):
            return entry
        if first is not None:  # a jump: the rest of the path for the largest ΔE reached
            rest = (yield params[des.size:]) if des.size < params.size else np.empty(0)
            des = np.concatenate([des, rest])
        largest = max(largest, float(np.max(des)))
    return CalibrationEntry(spec.name, target, None, largest, False)


def _root_search(spec: TransformSpec, target: float, params: NDArray[np.float64],
                 first: tuple[int, bool]
                 ) -> Generator[_Request, NDArray[np.float64], CalibrationEntry | None]:
    """:func:`_root` as a coroutine of :func:`_search` (Brent's root by
    :func:`fidelity.prediction.scalar.brent_search`)."""
    i, on_grid = first
    if on_grid:
        x = float(params[i])
    else:
        a, b = float(params[i]), float(params[i + 1])
        zero = brent_search(min(a, b), max(a, b), xtol=1e-14, maxiter=200)
        at = next(zero)
        while True:
            value = float((yield np.array([at]))[0]) - target
            try:
                at = zero.send(value)
            except StopIteration as done:
                x = float(done.value)
                break
    reached = (float((yield np.array([x]))[0]) - target) + target
    if abs(reached - target) > TOLERANCE:  # a jump, not a root: keep looking on this path
        return None
    return CalibrationEntry(spec.name, target, x, reached, True)


def _run_searches(specs: Sequence[TransformSpec], chart: Chart, target: float
                  ) -> list[CalibrationEntry]:
    """:func:`_search` of each transform, in lockstep: each round's requests, of every search
    still running, are one chart ΔE evaluation (the transformed images stacked), so that ten
    transforms' Brent iterations cost about one's. The same entries as each search alone
    (each point's ΔE is independent of the others)."""
    searches = [_search(spec, target) for spec in specs]
    pending = {k: next(s) for k, s in enumerate(searches)}
    found: dict[int, CalibrationEntry] = {}
    while pending:
        order = list(pending)
        images = [_transformed(specs[k], pending[k], chart) for k in order]
        values = _chart_delta_e(np.concatenate(images), chart)
        ends = np.cumsum([len(v) for v in images])[:-1]
        pending = {}
        for k, v in zip(order, np.split(values, ends), strict=True):
            try:
                pending[k] = searches[k].send(v)
            except StopIteration as done:
                found[k] = done.value
    return [found[k] for k in range(len(searches))]


def calibrate_transform(
    transform: str, target: float, chart: Chart | str | None = None, *, strict: bool = False
) -> CalibrationEntry:
    """The parameter of ``transform`` that puts ``chart`` at mean ΔE00 ``target``.

    ``target`` > 0. Returns an unreachable entry (``param=None``, ``delta_e`` = the largest ΔE
    the transform reaches) when the target is out of reach, or raises
    :class:`~fidelity.core.errors.UnreachableTargetError` if ``strict``.

    Parameters
    ----------
    transform
        A transform of :data:`fidelity.prediction.transforms.TRANSFORMS` (``gamma-inc``,
        ``hue``, ...).
    target
        The chart ΔE to reach: mean ΔE00 over the patches against the reference Lab, > 0 and
        finite (absolute: the untransformed chart's own ΔE, about 0.29, is the baseline).
    chart
        The chart whose clipped sRGB image is transformed: a :class:`Chart`, a chart name or
        file (:func:`fidelity.colour.charts.load_chart`); None: :data:`DEFAULT_CHART`
        (``safecolor``).
    strict
        Raise for a target out of reach instead of returning an unreachable entry.

    Returns
    -------
    CalibrationEntry
        ``param``: the transform's parameter nearest the identity along its scan whose chart
        ΔE is within :data:`TOLERANCE` (1e-4 ΔE00) of ``target``, and ``delta_e`` the ΔE
        reached; for an unreachable target ``param`` is None, ``reachable`` False and
        ``delta_e`` the largest ΔE the transform reaches in its range.

    Raises
    ------
    InvalidValueError
        ``target`` not a positive finite number. Exit code 2.
    UnknownNameError
        An unknown transform or chart name. Exit code 2.
    InputFileError
        A chart file that is missing or does not fit the chart schema. Exit code 2.
    UnreachableTargetError
        ``strict`` and the target is out of the transform's reach. Exit code 2.

    References
    ----------
    Damschen, Avula, Mohamad, SAFE-COLOR, IEEE IV 2025 ("Calibration" in
    ``shared/reference/safecolor.md``); Brent's method, R. P. Brent, *Algorithms for
    Minimization without Derivatives*, 1973.
    """
    t = float(target)
    if not np.isfinite(t) or t <= 0:
        raise InvalidValueError(f"target ΔE must be a positive finite number, got {target}")
    spec = get_transform(transform)
    c = _chart(chart)
    (entry,) = _run_searches([spec], c, t)
    if strict and not entry.reachable:
        raise UnreachableTargetError(
            f"{transform} cannot reach ΔE {t:g} on chart {c.name!r}: "
            f"it reaches at most ΔE {entry.delta_e:.4f}"
        )
    return entry


def calibrate_transforms(transforms: Sequence[str], target: float,
                         chart: Chart | str | None = None) -> list[CalibrationEntry]:
    """:func:`calibrate_transform` of each of ``transforms`` at ``target`` (not strict): the
    same entries, their searches run in lockstep (one chart ΔE evaluation per round for all
    of them; a prediction asks for every transform at its chart's ΔE)."""
    t = float(target)
    if not np.isfinite(t) or t <= 0:
        raise InvalidValueError(f"target ΔE must be a positive finite number, got {target}")
    return _run_searches([get_transform(n) for n in transforms], _chart(chart), t)


def calibration_table(
    chart: Chart | str | None = None,
    targets: Iterable[float] = DEFAULT_TARGETS,
    transforms: Sequence[str] | None = None,
) -> CalibrationTable:
    """The calibration table: every (transform, target), transforms in registry order."""
    c = _chart(chart)
    names = list(TRANSFORMS) if transforms is None else list(transforms)
    tlist = [float(t) for t in targets]
    if len(tlist) > MAX_TARGETS:
        raise InvalidValueError(f"{len(tlist)} target ΔE values: at most {MAX_TARGETS}")
    for t in tlist:
        if not np.isfinite(t) or t <= 0:
            raise InvalidValueError(f"target ΔE must be a positive finite number, got {t}")
    entries: list[CalibrationEntry] = []
    for name in names:
        spec = get_transform(name)
        curves = delta_e_curve(name, c)
        entries.extend(_solve(spec, c, t, curves) for t in tlist)
    baseline = float(delta_e_2000(srgb_to_lab(c.srgb), c.lab).mean())
    return CalibrationTable(c.name, baseline, tuple(entries))


def load_calibration_table(path: str | Path | None = None) -> CalibrationTable:
    """The shipped SAFE-COLOR calibration table (package data), or a table from a JSON file."""
    p = Path(path) if path is not None else resource_dir("data") / DEFAULT_TABLE_FILE
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputFileError(f"{p}: calibration table does not exist") from None
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{p}: cannot read calibration table ({exc})") from None
    return CalibrationTable.from_json(doc, str(p))


def calibration_table_csv(table: CalibrationTable) -> str:
    """The table as CSV: transform, target, param (empty if unreachable), delta_e, reachable."""
    lines = ["transform,target,param,delta_e,reachable"]
    for e in table.entries:
        param = "" if e.param is None else f"{e.param:.10g}"
        lines.append(f"{e.transform},{e.target:g},{param},{e.delta_e:.10g},{str(e.reachable).lower()}")
    return "\n".join(lines) + "\n"


def calibration_table_text(table: CalibrationTable, markdown: bool = False) -> str:
    """The table for people: one row per target, one column per transform, 4 decimals.

    Unreachable cells read "-" and a footer gives each transform's largest reachable ΔE.
    """
    names = table.transforms
    header = ["ΔE", *names]
    rows: list[list[str]] = []
    for t in table.targets:
        row = [f"{t:g}"]
        for n in names:
            try:
                p = table.param(n, t)
            except KeyError:
                p = None
            row.append("-" if p is None else f"{p:.4f}")
        rows.append(row)
    largest = {}
    for e in table.entries:
        if not e.reachable:
            largest[e.transform] = e.delta_e
    if markdown:
        out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        out += ["| " + " | ".join(r) + " |" for r in rows]
    else:
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
        out = ["  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True))]
        out += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    notes = [f"Chart {table.chart!r}; baseline (untransformed chart) ΔE00 = {table.baseline_delta_e:.4f}."]
    if largest:
        notes.append("'-' = unreachable; largest ΔE reached: "
                     + ", ".join(f"{n} {v:.2f}" for n, v in largest.items()) + ".")
    sep = "\n\n" if markdown else "\n"
    return "\n".join(out) + sep + sep.join(notes) + "\n"
