"""fidelity.core.record against the standard library's frozen dataclass (the reference)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pytest

from fidelity.core.record import record


def _pair(body: dict[str, object], annotations: dict[str, str]) -> tuple[type, type]:
    """The same class body made by :func:`record` and by ``dataclass(frozen=True)``, both
    named ``Item``."""
    def make() -> type:
        return type("Item", (), {"__annotations__": dict(annotations), **body})

    return record(make()), dataclass(frozen=True)(make())


ANNOTATIONS = {"a": "int", "b": "str", "c": "tuple[int, ...]", "hidden": "int",
               "loose": "float", "unhashed": "int"}
BODY = {"b": "x", "c": (), "hidden": field(default=0, repr=False),
        "loose": field(default=0.5, compare=False), "unhashed": field(default=1, hash=False)}
CASES = [dict(a=1), dict(a=1, b="y"), dict(a=2, c=(1, 2)), dict(a=1, hidden=5),
         dict(a=1, loose=9.0), dict(a=1, unhashed=7), dict(a=-3, b="", c=(0,))]


@pytest.mark.parametrize("kwargs", CASES)
def test_equality_hash_and_repr_are_the_frozen_dataclass_s(kwargs):
    """Equality (over the compared fields), hash (the hashed ones: ``hash=None`` follows
    ``compare``) and repr (the shown ones) of a record equal the frozen dataclass's, for
    every pair of the cases."""
    ours, theirs = _pair(BODY, ANNOTATIONS)
    x, y = ours(**kwargs), theirs(**kwargs)
    assert repr(x) == repr(y)
    assert hash(x) == hash(y)
    for other in CASES:
        assert (x == ours(**other)) == (y == theirs(**other))
        assert (x != ours(**other)) == (y != theirs(**other))
        if x == ours(**other):
            assert hash(x) == hash(ours(**other))


def test_a_record_is_a_frozen_dataclass():
    """fields, replace and asdict work; assigning or deleting a field raises the dataclass's
    FrozenInstanceError; another class with the same fields is not equal (NotImplemented, as
    the dataclass's); a record is usable as a dict key."""
    ours, theirs = _pair(BODY, ANNOTATIONS)
    x = ours(a=1, c=(2,))
    assert dataclasses.is_dataclass(x)
    assert [f.name for f in dataclasses.fields(x)] == list(ANNOTATIONS)
    assert dataclasses.replace(x, a=4) == ours(a=4, c=(2,))
    assert dataclasses.asdict(x)["c"] == (2,)
    with pytest.raises(dataclasses.FrozenInstanceError):
        x.a = 2  # type: ignore[attr-defined]
    with pytest.raises(dataclasses.FrozenInstanceError):
        del x.a  # type: ignore[attr-defined]
    assert x.__eq__(theirs(a=1, c=(2,))) is NotImplemented
    assert x != theirs(a=1, c=(2,))
    assert {x: 1}[ours(a=1, c=(2,))] == 1
    assert ours.__match_args__ == theirs.__match_args__


def test_a_method_of_its_own_is_kept():
    """A class's own __eq__, __hash__ or __repr__ stays, as a dataclass keeps it; an __eq__
    of its own without __hash__ gets the fields' hash, as a frozen dataclass's does."""
    def eq(self, other):
        return True

    own_eq = {"__eq__": eq}
    ours, theirs = _pair(own_eq, {"a": "int"})
    assert ours(1) == ours(2) and theirs(1) == theirs(2)
    assert hash(ours(3)) == hash(theirs(3))
    ours, theirs = _pair({"__hash__": lambda self: 7, "__repr__": lambda self: "R"},
                         {"a": "int"})
    assert hash(ours(1)) == hash(theirs(1)) == 7
    assert repr(ours(1)) == repr(theirs(1)) == "R"


def test_nested_recursive_and_array_fields_behave_alike():
    """A record inside a record shows the inner repr; a record that holds itself shows
    ``...`` as the dataclass does; fields holding numpy arrays compare as the dataclass's
    (the tuple comparison: identical arrays equal, others raise numpy's ambiguity error)."""
    ours, theirs = _pair({}, {"a": "object"})
    assert repr(ours(ours(1))) == repr(theirs(theirs(1)))
    loop_ours, loop_theirs = ours([]), theirs([])
    loop_ours.a.append(loop_ours)
    loop_theirs.a.append(loop_theirs)
    assert repr(loop_ours) == repr(loop_theirs) == "Item(a=[...])"
    arr = np.arange(3)
    assert ours(arr) == ours(arr) and theirs(arr) == theirs(arr)
    for make in (ours, theirs):
        with pytest.raises(ValueError, match="ambiguous"):
            _ = make(np.arange(3)) == make(np.arange(3))


def test_subclasses_and_empty_records():
    """A record subclassing a record compares over both classes' fields, and not with its
    parent; a record without fields equals another of its class and hashes as ``()``."""
    @record
    class Base:
        a: int

    @record
    class Child(Base):
        b: int = 0

    @dataclass(frozen=True)
    class RefBase:
        a: int

    @dataclass(frozen=True)
    class RefChild(RefBase):
        b: int = 0

    assert Child(1, 2) == Child(1, 2) and Child(1, 2) != Child(1, 3)
    assert Child(1) != Base(1) and RefChild(1) != RefBase(1)
    assert hash(Child(1, 2)) == hash(RefChild(1, 2))
    assert repr(Child(1, 2)).endswith("Child(a=1, b=2)")

    @record
    class Empty:
        pass

    assert Empty() == Empty() and hash(Empty()) == hash(()) and repr(Empty()).endswith("Empty()")


def test_a_record_is_made_with_fewer_compiled_methods(monkeypatch):
    """The point of it: making a record compiles three methods (__init__, __setattr__,
    __delattr__), a frozen dataclass six (and __repr__, __eq__, __hash__): the dataclasses
    module's generator counted."""
    made: list[str] = []
    create = dataclasses._create_fn  # type: ignore[attr-defined]

    def counted(name, *args, **kwargs):
        made.append(name)
        return create(name, *args, **kwargs)

    monkeypatch.setattr(dataclasses, "_create_fn", counted)
    record(type("Item", (), {"__annotations__": {"a": "int", "b": "str"}}))
    ours = sorted(made)
    made.clear()
    dataclass(frozen=True)(type("Item", (), {"__annotations__": {"a": "int", "b": "str"}}))
    assert ours == ["__delattr__", "__init__", "__setattr__"]
    assert sorted(made) == ["__delattr__", "__eq__", "__hash__", "__init__", "__repr__",
                            "__setattr__"]
