"""The one result schema of the speed benchmarks, as typed records and as the JSON Schema file
``result.schema.json`` beside this module (the declaration: the runner and the tests validate
every result against it).

A result (:class:`Result`) is one run of one benchmark: where and what it ran (machine,
versions, commit, date, load), its parameters, its cases and its own further figures
(``details``). A case (:class:`Case`) is one comparison measured in the same run: the figures of
ours and of the anchor (:class:`Figures`: wall seconds per unit of the case's statistic, and
where measured the fastest run, CPU seconds, the whole process's max RSS, bytes read) and their
ratio (:class:`Ratio`: ours / anchor, so below 1 is faster or smaller than the anchor).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NotRequired, TypedDict

#: The schema's name, the ``schema`` field of every result.
SCHEMA = "benchmarks.speed/1"
#: The JSON Schema file of :data:`SCHEMA`.
SCHEMA_FILE = Path(__file__).with_name("result.schema.json")


class Figures(TypedDict):
    """What one side of a case measured: ``wall_s`` is the case's statistic (seconds per
    ``Case.per``)."""

    label: str
    wall_s: float | None
    best_s: NotRequired[float | None]
    cpu_s: NotRequired[float | None]
    max_rss_mb: NotRequired[float | None]
    read_mb: NotRequired[float | None]
    exit: NotRequired[int]
    runs_s: NotRequired[list[float]]


class Ratio(TypedDict, total=False):
    """Ours over the anchor, per figure; ``of`` says how ``wall`` was formed when it is not
    ``ours.wall_s / anchor.wall_s`` (e.g. the median of paired runs' ratios)."""

    wall: float | None
    best: float | None
    cpu: float | None
    max_rss: float | None
    of: str


class Case(TypedDict):
    name: str
    per: str
    statistic: str
    process: bool
    ours: Figures
    anchor: Figures | None
    ratio: Ratio | None
    target_s: NotRequired[float]
    note: NotRequired[str]


class Commit(TypedDict):
    id: str
    dirty: bool | None


class ConvertedFrom(TypedDict):
    file: str
    commit: str


class Result(TypedDict):
    schema: str
    benchmark: str
    title: str
    anchor: str
    date: str | None
    commit: Commit | None
    machine: dict[str, Any]
    versions: dict[str, str]
    parameters: dict[str, Any]
    load_average: float | None
    seconds: float | None
    cases: list[Case]
    details: dict[str, Any]
    converted_from: NotRequired[ConvertedFrom]


def _significant(x: float | None) -> float | None:
    return None if x is None else float(f"{x:.4g}")


def figures(label: str, wall_s: float | None, **more: Any) -> Figures:
    """A :class:`Figures` (``more``: best_s, cpu_s, max_rss_mb, read_mb, exit, runs_s; None
    values left out)."""
    out: dict[str, Any] = {"label": label, "wall_s": None if wall_s is None else float(wall_s)}
    for key, value in more.items():
        if key not in Figures.__annotations__:
            raise TypeError(f"figures: unknown field {key!r}")
        if value is not None:
            out[key] = value
    return out  # type: ignore[return-value]


def ratio(ours: Figures, anchor: Figures | None, **given: Any) -> Ratio | None:
    """Ours / anchor of every figure both sides have (4 significant digits); ``given``
    (e.g. ``wall=..., of=...``) where the benchmark forms a ratio otherwise."""
    if anchor is None:
        return None
    out: dict[str, Any] = {}
    for key, field in (("wall", "wall_s"), ("best", "best_s"), ("cpu", "cpu_s"),
                       ("max_rss", "max_rss_mb")):
        a, b = ours.get(field), anchor.get(field)
        if isinstance(a, int | float) and isinstance(b, int | float) and b > 0:
            out[key] = _significant(a / b)
    for key, value in given.items():
        out[key] = _significant(value) if isinstance(value, float) else value
    return out  # type: ignore[return-value]


def case(name: str, ours: Figures, anchor: Figures | None, *, per: str, statistic: str,
         process: bool = False, target_s: float | None = None, note: str | None = None,
         **ratio_given: Any) -> Case:
    """A :class:`Case`, its ratio formed by :func:`ratio`."""
    out: dict[str, Any] = {"name": name, "per": per, "statistic": statistic,
                           "process": process, "ours": ours, "anchor": anchor,
                           "ratio": ratio(ours, anchor, **ratio_given)}
    if target_s is not None:
        out["target_s"] = float(target_s)
    if note:
        out["note"] = note
    return out  # type: ignore[return-value]


def schema() -> dict[str, Any]:
    """The JSON Schema of :data:`SCHEMA` (``result.schema.json``)."""
    doc: dict[str, Any] = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    return doc


def problems(doc: Any) -> list[str]:
    """Where ``doc`` departs from the schema (empty: it is a valid result). Needs
    ``jsonschema`` (the ``test`` extra)."""
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema())
    return [f"{'/'.join(str(p) for p in e.absolute_path) or '(top)'}: {e.message}"
            for e in sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))]


__all__ = ["SCHEMA", "SCHEMA_FILE", "Case", "Commit", "ConvertedFrom", "Figures", "Ratio",
           "Result", "case", "figures", "problems", "ratio", "schema"]
