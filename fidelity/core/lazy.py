"""Public names imported on first use (PEP 562): a package lists each name's module, and
importing the package loads none of them, so that ``import fidelity`` or one submodule of the
chart finder costs no more than it needs."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, MutableMapping
from typing import Any


def lazy_attributes(package: str, names: Mapping[str, str],
                    namespace: MutableMapping[str, Any]) -> Callable[[str], Any]:
    """A module ``__getattr__`` that imports a public name's module on first use.

    Parameters
    ----------
    package
        The package's name, for the error of an unknown attribute.
    names
        Public name -> the module that defines it.
    namespace
        The package's ``globals()``: a name once imported is kept there, so that the next
        access does not come back here.

    Returns
    -------
    callable
        ``__getattr__(name)``: the attribute, or :class:`AttributeError` for a name not in
        ``names``.
    """

    def __getattr__(name: str) -> Any:
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    return __getattr__


__all__ = ["lazy_attributes"]
