"""Declarative schemas for the files fidelity reads, and the one validator that walks them.

Every input file type (camera files, prediction tables, chart files, COCO annotations, the
Mitsuba scene template, a results store's provenance) is described by a schema object next to
the code that reads it: which fields a table has, their types and ranges, which are required,
which sections nest, and the few rules that tie fields together ("``gains`` is required when
``method = 'gains'``"). :func:`validate` walks a parsed document along its schema and raises
one :class:`SchemaError` at the first problem, as ``<file>: <field>: <problem>``::

    curves[2].points[0].delta_e: must be a finite number, got 'x'
    [noise].read_noise: must be >= 0, got -1

:func:`load_document` reads a JSON, TOML or YAML file with the limits every input gets
(nesting depth :data:`MAX_DEPTH`, an optional size limit; a parse error, a file name or text
that is not UTF-8, or Python's own recursion limit becomes a :class:`SchemaError` naming the
file).

Schema nodes (all frozen dataclasses; each may carry ``describe``, the words used instead of
its own message when anything inside it is wrong: ``expected <describe>, got <value>``, e.g.
``describe="a 3x3 array of finite numbers"``):

- :class:`Number` (finite; ``lo``/``hi`` bounds, open or closed), :class:`Integer`,
  :class:`String` (optional ``choices``), :class:`Boolean`, :class:`AnyValue`;
- :class:`ListOf` (item schema, item counts), :class:`MapOf` (free keys, one value schema);
- :class:`Table` of :class:`Field` (name, schema, required, default) with ``extra`` (allow
  unknown fields) and ``rules``: :class:`RequiredWhen`, :class:`Exclusive`, :class:`Check`;
- :class:`OneOf` (the first option that fits) and ``nullable`` on every node.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import field
from pathlib import Path
from typing import Any

from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import display_path
from fidelity.core.record import record

#: Deepest nesting of lists and tables accepted in any input document (the deepest schema,
#: COCO annotations' segmentation polygons, needs 5).
MAX_DEPTH = 32


class SchemaError(InputFileError, InvalidValueError):
    """An input file whose content does not fit its schema: the message is
    ``<file>: <field>: <problem>``. Both an :class:`~fidelity.core.errors.InputFileError` (the file is
    wrong) and an :class:`~fidelity.core.errors.InvalidValueError` (a value is out of its domain)."""


#: A location inside a document: table keys and list indices from the top.
Location = tuple[str | int, ...]


class _Invalid(Exception):
    """A problem at ``location`` (internal: :func:`validate` turns it into a SchemaError)."""

    def __init__(self, location: Location, problem: str) -> None:
        super().__init__(problem)
        self.location = location
        self.problem = problem


def _show(value: Any, limit: int = 60) -> str:
    """A short ``repr`` of a value for a message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


#: The types of the hot ``isinstance`` tests, as tuples: ``int | float`` written in a test
#: makes a new union at every call, and a union's test is slower than a tuple's.
_NUMBERS = (int, float)
_LISTS = (list, tuple)
_CONTAINERS = (dict, list, tuple)
#: Types that are no container (of a value from JSON, TOML or YAML): a list of them is not
#: walked further, by :func:`check_depth`, item by item.
_SCALARS = frozenset({float, int, str, bool, type(None)})


def _kind(value: Any) -> str:
    """The JSON/TOML word for a Python value's type."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list | tuple):
        return "a list"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


@record
class Node:
    """Base of the schema nodes: ``nullable`` accepts ``null``/``None``; ``describe`` replaces
    the message of any problem inside the node by ``expected <describe>, got <value>``."""

    nullable: bool = field(default=False, kw_only=True)
    describe: str | None = field(default=None, kw_only=True)

    def check(self, value: Any, at: Location) -> Any:
        """``value`` validated (defaults filled in, numbers as float/int); raises _Invalid."""
        if value is None and self.nullable:
            return None
        if self.describe is None:
            return self._check(value, at)
        try:
            return self._check(value, at)
        except _Invalid:
            raise _Invalid(at, f"expected {self.describe}, got {_show(value)}") from None

    def _check(self, value: Any, at: Location) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError


@record
class AnyValue(Node):
    """Any value (free-form provenance and comments)."""

    def check(self, value: Any, at: Location) -> Any:
        return value


@record
class Number(Node):
    """A finite number (not a boolean) in ``[lo, hi]`` (``lo_open``/``hi_open``: excluded)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def _check(self, value: Any, at: Location) -> float:
        if isinstance(value, bool) or not isinstance(value, _NUMBERS):
            raise _Invalid(at, f"must be a finite number, got {_show(value)}")
        try:
            v = float(value)
        except OverflowError:  # an integer beyond float's range
            raise _Invalid(at, f"must be a finite number, got {_show(value)}") from None
        if not math.isfinite(v):
            raise _Invalid(at, f"must be a finite number, got {_show(value)}")
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            raise _Invalid(at, f"must be {'>' if self.lo_open else '>='} {self.lo:g}, "
                               f"got {_show(value)}")
        if self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)):
            raise _Invalid(at, f"must be {'<' if self.hi_open else '<='} {self.hi:g}, "
                               f"got {_show(value)}")
        return v


@record
class Integer(Node):
    """An integer (not a boolean, not a float) in ``[lo, hi]``."""

    lo: int | None = None
    hi: int | None = None

    def _check(self, value: Any, at: Location) -> int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        if not ok or (self.lo is not None and value < self.lo) or (
                self.hi is not None and value > self.hi):
            lo = "-inf" if self.lo is None else str(self.lo)
            hi = "inf" if self.hi is None else str(self.hi)
            raise _Invalid(at, f"must be an integer in [{lo}, {hi}], got {_show(value)}")
        return int(value)


@record
class String(Node):
    """A string; with ``choices``, one of them (``ignore_case``: compared in lower case;
    ``lower``: returned in lower case); ``nonempty``: not ``""``."""

    choices: tuple[str, ...] | None = None
    ignore_case: bool = True
    lower: bool = False
    nonempty: bool = False

    def _check(self, value: Any, at: Location) -> str:
        if not isinstance(value, str):
            if self.choices is not None:
                raise _Invalid(at, f"must be one of {', '.join(self.choices)}, got "
                                   f"{_show(value)}")
            raise _Invalid(at, f"must be a string, got {_show(value)}")
        if self.nonempty and not value.strip():
            raise _Invalid(at, "must be a non-empty string")
        if self.choices is not None:
            known = [c.lower() for c in self.choices] if self.ignore_case else self.choices
            if (value.lower() if self.ignore_case else value) not in known:
                raise _Invalid(at, f"must be one of {', '.join(self.choices)}, got "
                                   f"{_show(value)}")
        return value.lower() if self.lower else value


@record
class Boolean(Node):
    """``true`` or ``false``."""

    def _check(self, value: Any, at: Location) -> bool:
        if not isinstance(value, bool):
            raise _Invalid(at, f"must be true or false, got {_show(value)}")
        return value


@record
class ListOf(Node):
    """A list whose items fit ``item``, with ``min_items`` to ``max_items`` of them."""

    item: Node = field(default_factory=AnyValue)
    min_items: int = 0
    max_items: int | None = None

    def _check(self, value: Any, at: Location) -> list[Any]:
        if not isinstance(value, _LISTS):
            raise _Invalid(at, f"must be a list, got {_kind(value)}")
        n = len(value)
        if n < self.min_items or (self.max_items is not None and n > self.max_items):
            want = (f"{self.min_items}" if self.max_items == self.min_items else
                    f"at least {self.min_items}" if self.max_items is None else
                    f"{self.min_items} to {self.max_items}")
            one = (self.max_items or self.min_items) == 1
            raise _Invalid(at, f"must have {want} item{'' if one else 's'}, got {n}")
        return [self.item.check(v, (*at, i)) for i, v in enumerate(value)]


@record
class MapOf(Node):
    """A table with free (string) keys whose values fit ``value``."""

    value: Node = field(default_factory=AnyValue)

    def _check(self, value: Any, at: Location) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise _Invalid(at, f"must be a table, got {_kind(value)}")
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise _Invalid((*at, str(k)), "keys must be strings")
            out[k] = self.value.check(v, (*at, k))
        return out


@record
class Field:
    """A field of a :class:`Table`: ``name``, its ``schema``, ``required``, and the ``default``
    filled in when it is absent (``...``: none, the field stays absent; a section's default,
    a :class:`Table`, is validated too, so its own defaults fill in). ``when``: the field is
    read only when another field has one of some values (``("method", ("gains",))``);
    otherwise it is ignored, whatever it holds."""

    name: str
    schema: Node
    required: bool = False
    default: Any = ...
    when: tuple[str, tuple[str, ...]] | None = None

    def applies(self, table: Mapping[str, Any]) -> bool:
        """Whether the field is read in ``table`` (its ``when`` condition holds)."""
        if self.when is None:
            return True
        v = table.get(self.when[0])
        return isinstance(v, str) and v.lower() in self.when[1]


@record
class RequiredWhen:
    """``field`` is required when ``when`` (a string field) is one of ``values`` (any case)."""

    field: str
    when: str
    values: tuple[str, ...]

    def apply(self, table: Mapping[str, Any], at: Location) -> None:
        v = table.get(self.when)
        if isinstance(v, str) and v.lower() in self.values and self.field not in table:
            raise _Invalid((*at, self.field), f"required when {self.when} = {v.lower()!r}")


@record
class Exclusive:
    """Give either ``first`` or ``second``, not both."""

    first: str
    second: str

    def apply(self, table: Mapping[str, Any], at: Location) -> None:
        if table.get(self.first) is not None and table.get(self.second) is not None:
            raise _Invalid((*at, self.second), f"give either {self.first} or {self.second}, "
                                               "not both")


@record
class Check:
    """A rule in code: ``test(table)`` returns None or ``(field, problem)`` (field ``""``: the
    table itself). Runs after the fields are valid; ``table`` holds the validated values."""

    test: Callable[[Mapping[str, Any]], tuple[str, str] | None]

    def apply(self, table: Mapping[str, Any], at: Location) -> None:
        found = self.test(table)
        if found is not None:
            name, problem = found
            raise _Invalid((*at, name) if name else at, problem)


Rule = RequiredWhen | Exclusive | Check


@record
class Table(Node):
    """A table (JSON object, TOML table, YAML mapping) of :class:`Field` s. Unknown fields are
    an error unless ``extra``; ``rules`` run after the fields (in order)."""

    fields: tuple[Field, ...] = ()
    extra: bool = False
    rules: tuple[Rule, ...] = ()

    def _check(self, value: Any, at: Location) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise _Invalid(at, f"must be a table, got {_kind(value)}")
        known = {f.name: f for f in self.fields}
        if not self.extra:
            unknown = [k for k in value if k not in known]
            if unknown:
                raise _Invalid((*at, str(unknown[0])),
                               f"unknown field; known: {', '.join(known)}")
        for f in self.fields:  # a missing field first, before the values of the others
            if f.required and f.when is None and f.name not in value:
                raise _Invalid((*at, f.name), "required")
        out: dict[str, Any] = {}
        for f in self.fields:  # fields without a condition first: conditions read them
            if f.when is None and f.name in value:
                out[f.name] = f.schema.check(value[f.name], (*at, f.name))
        for f in self.fields:
            if f.when is not None and f.name in value and f.applies(out):
                out[f.name] = f.schema.check(value[f.name], (*at, f.name))
        for rule in self.rules:
            rule.apply(out, at)
        for f in self.fields:
            if f.name not in out and f.default is not ...:
                out[f.name] = (f.schema.check(f.default, (*at, f.name))
                               if isinstance(f.schema, Table) else f.default)
        if self.extra:
            out.update({k: v for k, v in value.items() if k not in known})
        return out


@record
class OneOf(Node):
    """The first of ``options`` that fits; otherwise ``expected <describe>``."""

    options: tuple[Node, ...] = ()

    def _check(self, value: Any, at: Location) -> Any:
        for option in self.options:
            try:
                return option.check(value, at)
            except _Invalid:
                continue
        words = self.describe or " or ".join(type(o).__name__.lower() for o in self.options)
        raise _Invalid(at, f"expected {words}, got {_show(value)}")


def format_location(location: Location, sections: bool = False) -> str:
    """``("curves", 2, "points")`` -> ``curves[2].points``; with ``sections`` (TOML camera
    files) the first key is written as a section: ``[noise].read_noise``."""
    text = ""
    for i, part in enumerate(location):
        if isinstance(part, int):
            text += f"[{part}]"
        elif i == 0 and sections:
            text += f"[{part}]"
        else:
            text += ("." if text else "") + str(part)
    return text or "top level"


def validate(document: Any, schema: Node, origin: str, *, sections: bool = False) -> Any:
    """``document`` checked against ``schema``; returns the validated values (defaults filled
    in). Raises :class:`SchemaError` ``<origin>: <field>: <problem>`` at the first problem
    (``sections``: fields written the TOML way, :func:`format_location`)."""
    check_depth(document, origin)
    try:
        return schema.check(document, ())
    except _Invalid as exc:
        where = format_location(exc.location, sections)
        raise SchemaError(f"{origin}: {where}: {exc.problem}") from None


def check_depth(document: Any, origin: str, max_depth: int = MAX_DEPTH) -> None:
    """Raise :class:`SchemaError` when lists and tables nest deeper than ``max_depth`` (walked
    without recursion; a node shared by YAML aliases is walked once)."""
    stack: list[tuple[Any, int]] = [(document, 0)]
    seen: set[int] = set()
    push = stack.append
    while stack:
        node, depth = stack.pop()
        if not isinstance(node, _CONTAINERS) or id(node) in seen:
            continue
        if depth >= max_depth:
            raise SchemaError(f"{origin}: nested more than {max_depth} levels deep")
        seen.add(id(node))
        children = node.values() if isinstance(node, dict) else node
        if _SCALARS.issuperset(map(type, children)):  # numbers and strings only: no walk
            continue
        below = depth + 1
        for child in children:
            if isinstance(child, _CONTAINERS):
                push((child, below))


#: Document formats by file suffix.
FORMATS: dict[str, str] = {".json": "json", ".toml": "toml", ".yaml": "yaml", ".yml": "yaml"}


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} is beyond the range of a floating-point number")
    return value


def parse_text(text: str, fmt: str, origin: str) -> Any:
    """Parse ``text`` as ``fmt`` (``json``, ``toml`` or ``yaml``); errors name ``origin``.

    JSON is read strictly: ``NaN``, ``Infinity`` and numbers beyond the floating-point range
    (which Python's reader would turn into ``nan`` and ``inf``) are errors."""
    try:
        if fmt == "json":
            try:
                return json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
            except ValueError as exc:  # JSONDecodeError, or an integer of > 4300 digits
                raise SchemaError(f"{origin}: not valid JSON ({exc})") from None
        if fmt == "toml":
            try:
                return tomllib.loads(text)
            except ValueError as exc:  # TOMLDecodeError, or an integer of > 4300 digits
                raise SchemaError(f"{origin}: invalid TOML ({exc})") from None
        if fmt == "yaml":
            import yaml

            try:
                return yaml.safe_load(text)
            except (yaml.YAMLError, ValueError) as exc:
                msg = " ".join(str(exc).split())
                raise SchemaError(f"{origin}: invalid YAML ({msg})") from None
    except RecursionError:
        raise SchemaError(f"{origin}: nested too deeply to read (more than "
                          f"{sys.getrecursionlimit()} levels)") from None
    raise InvalidValueError(f"{origin}: unknown document format {fmt!r}")


def load_document(path: str | os.PathLike[str], origin: str | None = None, *,
                  fmt: str | None = None, max_bytes: int | None = None,
                  what: str = "file") -> Any:
    """Read and parse a JSON, TOML or YAML file (``fmt``, default from the suffix,
    :data:`FORMATS`), with its nesting depth checked (:func:`check_depth`).

    ``origin`` names the file in messages (default: the path); ``max_bytes`` refuses a larger
    file before reading it. Raises :class:`SchemaError` for a missing or unreadable file, a
    file over ``max_bytes``, text that is not UTF-8, a parse error or too deep a nesting.
    """
    p = Path(path)
    where = origin or display_path(p)
    fmt = fmt or FORMATS.get(p.suffix.lower())
    if fmt is None:
        raise SchemaError(f"{where}: expected a {', '.join(sorted(FORMATS))} file")
    try:
        size = p.stat().st_size
        if not p.is_file():
            raise SchemaError(f"{where}: {what} is not a regular file")
        if max_bytes is not None and size > max_bytes:
            raise SchemaError(f"{where}: {what} is {size / 2**20:.1f} MiB, more than the "
                              f"{max_bytes / 2**20:g} MiB such a file may have")
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise SchemaError(f"{where}: {what} does not exist") from None
    except UnicodeDecodeError as exc:
        raise SchemaError(f"{where}: not UTF-8 text ({exc.reason} at byte {exc.start})") \
            from None
    except OSError as exc:
        raise SchemaError(f"{where}: cannot read {what} ({exc.strerror or exc})") from None
    document = parse_text(text, fmt, where)
    check_depth(document, where)
    return document


__all__ = [
    "FORMATS",
    "MAX_DEPTH",
    "AnyValue",
    "Boolean",
    "Check",
    "Exclusive",
    "Field",
    "Integer",
    "ListOf",
    "Location",
    "MapOf",
    "Node",
    "Number",
    "OneOf",
    "RequiredWhen",
    "SchemaError",
    "String",
    "Table",
    "check_depth",
    "format_location",
    "load_document",
    "parse_text",
    "validate",
]
