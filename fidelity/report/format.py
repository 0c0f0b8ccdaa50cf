"""Numbers and provenance in words, for every report (one formatter, no Python dict text).

- :func:`number`: one number as a report prints it (fixed digits; ``–`` for a missing value);
- :func:`words`: a provenance mapping (versions, machine) as ``key value, key value``;
- :func:`listing`: a list as ``a, b, c`` (no brackets or quotes).

A report never shows ``str(dict)``: provenance values are spelt out with these.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

#: What a report prints for a value that does not exist (not measured, not defined).
MISSING = "–"


def number(value: float | int | str | None, digits: int = 2) -> str:
    """``value`` with ``digits`` decimals (floats), as it is (ints, strings), or :data:`MISSING`.

    >>> number(0.12345), number(3), number(None), number(1.0, 4)
    ('0.12', '3', '–', '1.0000')
    """
    if value is None:
        return MISSING
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def listing(values: Iterable[Any], sep: str = ", ") -> str:
    """The items of ``values`` joined by ``sep`` (``[416, 416]`` -> ``416, 416``)."""
    return sep.join(_plain(v) for v in values)


def _plain(value: Any) -> str:
    if isinstance(value, Mapping):
        return words(value)
    if isinstance(value, list | tuple):
        return listing(value)
    return MISSING if value is None else str(value)


def words(mapping: Mapping[str, Any] | None, sep: str = ", ") -> str:
    """A provenance mapping as ``key value`` pairs (``{"python": "3.11"}`` -> ``python 3.11``);
    nested lists and mappings are spelt out the same way; :data:`MISSING` when empty."""
    if not mapping:
        return MISSING
    return sep.join(f"{k} {_plain(v)}" for k, v in mapping.items())


__all__ = ["MISSING", "listing", "number", "words"]
