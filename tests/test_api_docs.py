"""Every public API name documents its parameters (numpydoc sections).

The rules, simplified from numpydoc's (https://numpydoc.readthedocs.io/en/latest/format.html):
a section is a title line underlined by dashes; an entry of ``Parameters`` / ``Attributes`` is
a line at the section's indentation, ``name``, ``name : type`` or ``a, b : type`` (``*args`` /
``**kwargs`` keep their stars); its description is indented below it.

- a function lists exactly its signature's parameters, in order, in ``Parameters``, and has a
  ``Returns`` (or ``Yields``) section unless it is annotated ``-> None``;
- a class lists in ``Attributes`` or ``Parameters`` every dataclass field, or, for any other
  class, its own ``__init__``'s parameters and its annotated class attributes; any other name
  it lists must be an attribute of the class (a property), or ``*args`` / ``**kwargs`` of an
  inherited constructor; an ``Attributes`` entry names one attribute (napoleon renders
  ``a, b`` there as an attribute ``b`` of type ``a,``).
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from typing import Any

import pytest

import fidelity

_UNDERLINE = re.compile(r"^\s*-{3,}\s*$")


def sections(doc: str | None) -> dict[str, list[str]]:
    """A cleaned docstring's sections by title: ``{title: lines of its body}`` (the summary
    and prose before the first section are under ``""``)."""
    lines = inspect.cleandoc(doc or "").splitlines()
    found: dict[str, list[str]] = {"": []}
    title = ""
    i = 0
    while i < len(lines):
        line = lines[i]
        underline = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and _UNDERLINE.match(underline) and len(underline.strip()) >= 3:
            title = line.strip()
            found[title] = []
            i += 2
            continue
        found[title].append(line)
        i += 1
    return found


def entry_heads(body: list[str]) -> list[str]:
    """The name part of each entry of an entry list (``Parameters``, ``Attributes``): ``a``,
    ``a, b`` (the type after `` : `` left out)."""
    text = [line for line in body if line.strip()]
    if not text:
        return []
    indent = min(len(line) - len(line.lstrip()) for line in text)
    return [line.strip().split(" : ", 1)[0].rstrip(":").strip() for line in text
            if len(line) - len(line.lstrip()) == indent]


def entry_names(body: list[str]) -> list[str]:
    """The names an entry list (``Parameters``, ``Attributes``) documents, in order."""
    return [name.strip() for head in entry_heads(body) for name in head.split(",")
            if name.strip()]


def _signature_names(func: Any) -> list[str]:
    names = []
    for p in inspect.signature(func).parameters.values():
        if p.name in ("self", "cls"):
            continue
        star = {p.VAR_POSITIONAL: "*", p.VAR_KEYWORD: "**"}.get(p.kind, "")
        names.append(star + p.name)
    return names


def _returns_none(func: Any) -> bool:
    annotation = inspect.signature(func).return_annotation
    return annotation is None or annotation == "None"


def _class_names(cls: type) -> list[str]:
    if dataclasses.is_dataclass(cls):
        return [f.name for f in dataclasses.fields(cls)]
    names: list[str] = []
    init = cls.__dict__.get("__init__")
    if init is not None:
        names.extend(_signature_names(init))
    names.extend(n for n in cls.__dict__.get("__annotations__", {}) if n not in names)
    return names


def doc_problems(obj: Any) -> list[str]:
    """What the docstring of a public function or class lacks (empty: nothing)."""
    found = sections(obj.__doc__)
    problems: list[str] = []
    if inspect.isclass(obj):
        documented = entry_names(found.get("Attributes", [])) + entry_names(
            found.get("Parameters", []))
        if "Attributes" not in found and "Parameters" not in found:
            problems.append("no Attributes or Parameters section")
        # napoleon (``napoleon_use_ivar``) renders ``a, b`` of an Attributes section as the
        # attribute ``b`` of type ``a,``: one attribute per entry
        combined = [h for h in entry_heads(found.get("Attributes", [])) if "," in h]
        if combined:
            problems.append(f"Attributes entries naming several: {'; '.join(combined)}")
        missing = [n for n in _class_names(obj) if n not in documented]
        if missing:
            problems.append(f"undocumented fields: {', '.join(missing)}")
        # a documented ``*args`` / ``**kwargs`` is an inherited constructor's (an exception's
        # message), not an attribute
        unknown = [n for n in documented if n not in _class_names(obj) and not hasattr(obj, n)
                   and not n.startswith("*")]
        if unknown:
            problems.append(f"documented names that are not attributes: {', '.join(unknown)}")
        return problems
    expected = _signature_names(obj)
    if expected and "Parameters" not in found:
        problems.append("no Parameters section")
    documented = entry_names(found.get("Parameters", []))
    missing = [n for n in expected if n not in documented]
    if missing:
        problems.append(f"undocumented parameters: {', '.join(missing)}")
    extra = [n for n in documented if n not in expected]
    if extra:
        problems.append(f"documented parameters not in the signature: {', '.join(extra)}")
    if not missing and not extra and documented != expected:
        problems.append(f"parameters documented out of order: {', '.join(documented)}")
    if not _returns_none(obj) and "Returns" not in found and "Yields" not in found:
        problems.append("no Returns section")
    return problems


@pytest.mark.parametrize("name", [n for n in fidelity.__all__ if n != "__version__"])
def test_public_name_documents_its_parameters(name):
    assert doc_problems(getattr(fidelity, name)) == []


# The checker itself: it finds what it should.


def _documented(delta_e: float, size: str = "any") -> float:
    """Summary.

    Parameters
    ----------
    delta_e : float
        ΔE00, >= 0.
    size
        Detector size class.

    Returns
    -------
    float
        Percentage points.
    """
    return delta_e


def _undocumented_parameter(delta_e: float, size: str = "any") -> float:  # noqa: D417
    """Summary.

    Parameters
    ----------
    delta_e
        ΔE00, >= 0.

    Returns
    -------
    float
        Percentage points.
    """
    return delta_e


def _no_sections(delta_e: float, *args: Any, **kwargs: Any) -> float:
    """Summary that names delta_e in prose only."""
    return delta_e


def _returns_nothing(path: str) -> None:
    """Summary.

    Parameters
    ----------
    path, *args
        A file; and a parameter it does not have.
    """


@dataclasses.dataclass
class _Record:
    """Summary.

    Attributes
    ----------
    kind
        A field.
    value : float
        Another.
    """

    kind: str
    value: float
    reason: str = ""


class _Error(Exception):
    """Summary.

    Attributes
    ----------
    exit_code
        Exit code.
    """

    exit_code: int = 2
    hint: str = ""


def test_the_sections_and_entries_are_parsed():
    found = sections(_documented.__doc__)
    assert list(found) == ["", "Parameters", "Returns"]
    assert entry_names(found["Parameters"]) == ["delta_e", "size"]
    assert entry_names(sections(_Record.__doc__)["Attributes"]) == ["kind", "value"]
    assert entry_names(sections(_returns_nothing.__doc__)["Parameters"]) == ["path", "*args"]


def test_a_documented_function_passes():
    assert doc_problems(_documented) == []


def test_an_undocumented_parameter_is_reported():
    assert doc_problems(_undocumented_parameter) == ["undocumented parameters: size"]


def test_missing_sections_and_star_parameters_are_reported():
    assert doc_problems(_no_sections) == [
        "no Parameters section",
        "undocumented parameters: delta_e, *args, **kwargs",
        "no Returns section",
    ]


def test_a_parameter_not_in_the_signature_is_reported_and_none_needs_no_returns():
    assert doc_problems(_returns_nothing) == [
        "documented parameters not in the signature: *args"]


def test_an_undocumented_field_is_reported():
    assert doc_problems(_Record) == ["undocumented fields: reason"]
    assert doc_problems(_Error) == ["undocumented fields: hint"]


@dataclasses.dataclass
class _Misnamed:
    """Summary.

    Attributes
    ----------
    kind, valeu
        A field and a misspelt one.
    """

    kind: str
    value: float


class _NoSections:
    """Summary that names ``path`` in prose only."""

    def __init__(self, path: str) -> None:
        self.path = path


def test_a_class_documents_only_its_attributes_in_sections():
    assert doc_problems(_Misnamed) == [
        "Attributes entries naming several: kind, valeu",
        "undocumented fields: value",
        "documented names that are not attributes: valeu",
    ]
    assert doc_problems(_NoSections) == [
        "no Attributes or Parameters section", "undocumented fields: path"]
