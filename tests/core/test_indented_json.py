""":func:`fidelity.core.fileio.indented_json` writes what ``json.dumps(obj, indent=2,
allow_nan=False)`` writes (issue 59), and leaves what it does not handle to it."""

from __future__ import annotations

import enum
import json
import math
import random
from collections import OrderedDict
from pathlib import Path

import pytest

from fidelity.core.fileio import indented_json, write_json_atomic

ROOT = Path(__file__).resolve().parents[2]


def _stdlib(obj: object) -> str:
    return json.dumps(obj, indent=2, allow_nan=False)


def _random_value(rng: random.Random, depth: int = 0) -> object:
    kinds = ["str", "int", "float", "bool", "none"] + (["list", "dict", "tuple"] if depth < 4
                                                      else [])
    kind = rng.choice(kinds)
    if kind == "str":
        return "".join(rng.choice('aZ09 "\\\n\t\x00\x1fé✓ΔE\U0001f600/<>&') for _ in
                       range(rng.randint(0, 6)))
    if kind == "int":
        return rng.choice([0, -1, 7, 2**70, -(2**64)])
    if kind == "float":
        return rng.choice([0.0, -0.0, 0.1, 1e300, -1e-300, 5e-324, 1.0, 123456789.123,
                           rng.uniform(-1e6, 1e6)])
    if kind == "bool":
        return rng.random() < 0.5
    if kind == "none":
        return None
    items = [_random_value(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    if kind == "list":
        return items
    if kind == "tuple":
        return tuple(items)
    return {"".join(rng.choice("ab\"é\n") for _ in range(rng.randint(0, 3))) + str(i): v
            for i, v in enumerate(items)}


def test_random_values_are_written_as_the_standard_library_writes_them() -> None:
    rng = random.Random(59)
    for _ in range(2000):
        value = _random_value(rng)
        assert indented_json(value) == _stdlib(value)


@pytest.mark.parametrize("folder", ["fidelity/data", "tests/data"])
def test_the_shipped_and_recorded_json_files_are_written_alike(folder: str) -> None:
    files = sorted((ROOT / folder).rglob("*.json"))
    assert files
    for path in files:
        value = json.loads(path.read_text(encoding="utf-8"))
        assert indented_json(value) == _stdlib(value), path


class _Level(enum.IntEnum):
    HIGH = 3


class _Kind(enum.StrEnum):
    MEASURED = "measured"


class _Float(float):
    pass


@pytest.mark.parametrize("value", [
    {2: "int key", None: "none key", 2.5: "float key", False: "bool key"},  # keys json converts
    [_Level.HIGH, _Float(1.5), _Kind.MEASURED], OrderedDict(a=1), {_Kind.MEASURED: 1},
    {"nested": [{"x": _Float(2.0)}]}, [True, False, 1, 0, 1.0],
])
def test_subclasses_and_other_keys_are_written_alike(value: object) -> None:
    assert indented_json(value) == _stdlib(value)


@pytest.mark.parametrize("value", [math.nan, [1.0, math.inf], {"a": -math.inf}, {"a": {1, 2}},
                                   object()])
def test_what_json_refuses_is_refused_alike(value: object) -> None:
    with pytest.raises((ValueError, TypeError)) as expected:
        _stdlib(value)
    with pytest.raises(expected.type):
        indented_json(value)


def test_a_cycle_is_refused_alike() -> None:
    loop: list[object] = []
    loop.append(loop)
    with pytest.raises(ValueError, match="Circular"):
        indented_json(loop)


def test_write_json_atomic_writes_the_standard_text(tmp_path: Path) -> None:
    value = {"a": [1, 2.5, None, True, {"b": "é"}], "c": {}}
    path = write_json_atomic(tmp_path / "x.json", value)
    assert path.read_text(encoding="utf-8") == _stdlib(value) + "\n"
