"""Frozen records: :func:`record`, ``dataclasses.dataclass(frozen=True)`` at less start-up cost.

A frozen dataclass gets six methods, each generated as source text and compiled when its class
is created. Python 3.11 compiles each on its own (about 0.2 ms a method: 0.2 s of every
``fidelity`` process for the records it imports). :func:`record` keeps ``__init__``,
``__setattr__`` and ``__delattr__`` generated and gives every record the same ``__eq__``,
``__hash__`` and ``__repr__``, which read the class's field names (stored when the class is
made) and behave as the generated ones do: the fields compared (``compare=True``) as a tuple
against an instance of the very same class (else ``NotImplemented``), the hash of the tuple of
the hashed fields (``hash=None`` follows ``compare``), and ``Name(field=value!r, ...)`` of the
fields shown (``repr=True``), a recursive reference shown as ``...``. A class that defines one
of the three itself keeps its own, as a dataclass keeps it. Tests compare all three with
``dataclasses.dataclass(frozen=True)``'s.
"""

from __future__ import annotations

import dataclasses
import reprlib
from collections.abc import Callable
from operator import attrgetter
from typing import Any, TypeVar, dataclass_transform

T = TypeVar("T")


def _getter(names: tuple[str, ...]) -> Callable[[Any], tuple[Any, ...]]:
    """A function of an instance giving the tuple of its attributes ``names``."""
    if len(names) > 1:
        return attrgetter(*names)
    if len(names) == 1:
        one = attrgetter(names[0])
        return lambda obj: (one(obj),)
    return lambda obj: ()


def _eq(self: Any, other: Any) -> Any:
    """The generated ``__eq__``: the compared fields as tuples, the same class only."""
    if other.__class__ is self.__class__:
        compared = self.__class__.__record_compared__
        return compared(self) == compared(other)
    return NotImplemented


def _hash(self: Any) -> int:
    """The generated ``__hash__`` of a frozen dataclass: the hashed fields' tuple's."""
    return hash(self.__class__.__record_hashed__(self))


@reprlib.recursive_repr()
def _repr(self: Any) -> str:
    """The generated ``__repr__``: ``Name(field=value!r, ...)`` of the fields shown."""
    inner = ", ".join(f"{name}={getattr(self, name)!r}"
                      for name in self.__class__.__record_shown__)
    return f"{self.__class__.__qualname__}({inner})"


@dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field,))
def record(cls: type[T]) -> type[T]:
    """``cls`` as a frozen dataclass (``dataclasses.dataclass(frozen=True)``), its
    ``__eq__``, ``__hash__`` and ``__repr__`` the shared ones (module docstring).

    Parameters
    ----------
    cls
        The class, with its fields annotated as for a dataclass.

    Returns
    -------
    type
        The same class, a frozen dataclass (``dataclasses.fields``, ``replace``, ``asdict``
        work on it).
    """
    own = dict(cls.__dict__)
    made: Any = dataclasses.dataclass(frozen=True, repr=False, eq=False)(cls)
    fields = dataclasses.fields(made)
    compared = tuple(f.name for f in fields if f.compare)
    hashed = tuple(f.name for f in fields if (f.compare if f.hash is None else f.hash))
    shown = tuple(f.name for f in fields if f.repr)
    made.__record_compared__ = staticmethod(_getter(compared))
    made.__record_hashed__ = staticmethod(_getter(hashed))
    made.__record_shown__ = shown
    if "__eq__" not in own:
        made.__eq__ = _eq
    # as a frozen dataclass: a hash of its own kept, else the fields' (a class that defines
    # __eq__ alone has __hash__ None in its body, which the dataclass replaces)
    explicit_hash = "__hash__" in own and not (own["__hash__"] is None and "__eq__" in own)
    if not explicit_hash:
        made.__hash__ = _hash
    if "__repr__" not in own:
        made.__repr__ = _repr
    out: type[T] = made
    return out


__all__ = ["record"]
