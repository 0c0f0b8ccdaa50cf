"""Fuzz: option values — numbers of every size and sign, NaN, Inf, text — for the options that
take numbers: used, or refused in one line naming the option (never an overflow traceback, a
ZeroDivisionError or a MemoryError)."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzzkit import FAST, LONG, assert_promise, budget, fingerprint, run

EXAMPLES = [FAST, pytest.param(LONG, marks=pytest.mark.fuzz)]

#: Option values: integers and floats of any size, NaN, Inf, and short text.
values = (st.integers(-(10**30), 10**30).map(str)
          | st.floats(allow_nan=True, allow_infinity=True).map(repr)
          | st.sampled_from(["0", "-0", "1e-320", "1e308", "1e400", "-1", "nan", "inf",
                             "2**64", "", " ", "1,2", "3-1", "1-1e9", "0.001", "512", "513"])
          | st.text(max_size=4))

#: (command line with the value, the option named in an error)
OPTIONS: dict[str, tuple[Callable[[str, dict[str, Path]], list[Any]], str]] = {
    "render --step": (lambda v, w: ["render", "--step", v, "-q"], "--step"),
    "render --pixels-per-patch": (lambda v, w: ["render", "--pixels-per-patch", v, "-q"],
                                  "--pixels-per-patch"),
    "render --seed": (lambda v, w: ["render", "--seed", v, "-q"], "--seed"),
    "render --spp": (lambda v, w: ["render", "--spp", v, "-q"], "--spp"),
    "audit --exposure": (lambda v, w: ["audit", w["image"], "--corners",
                                       "12,12,112,12,112,72,12,72", "--exposure", v],
                         "--exposure"),
    "audit --corners": (lambda v, w: ["audit", w["image"], "--corners",
                                      f"12,12,112,12,112,72,12,{v}"], "--corners"),
    "audit --max-pixels": (lambda v, w: ["audit", w["image"], "--corners",
                                         "12,12,112,12,112,72,12,72", "--max-pixels", v],
                           "--max-pixels"),
    "predict --delta-e": (lambda v, w: ["predict", "--delta-e", v], "--delta-e"),
    "predict --max-dmap": (lambda v, w: ["predict", "--max-dmap", v], "--max-dmap"),
    "predict --baseline-map": (lambda v, w: ["predict", "--delta-e", "3", "--baseline-map", v],
                               "--baseline-map"),
    "calibrate --targets": (lambda v, w: ["calibrate", "--transforms", "hue", "--targets", v,
                                          "-q"], "--targets"),
    "gate --max-delta-e": (lambda v, w: ["gate", w["image"], "--corners",
                                         "12,12,112,12,112,72,12,72", "--max-delta-e", v],
                           "--max-delta-e"),
    "audit --ocio-colourspace": (lambda v, w: ["audit", w["image"], "--corners",
                                               "12,12,112,12,112,72,12,72",
                                               "--ocio-colourspace", v], "--ocio-colourspace"),
    "gate --frames": (lambda v, w: ["gate", w["image"], "--max-delta-e", "3", "--frames", v],
                      "--frames"),
}


@pytest.mark.parametrize("examples", EXAMPLES)
def test_option_values(examples: int, chart_images: dict[str, Path]) -> None:
    world = {"image": chart_images["png"]}

    @budget(examples)
    @given(option=st.sampled_from(sorted(OPTIONS)), value=values)
    def check(option: str, value: str) -> None:
        argv, name = OPTIONS[option]
        if option == "render --pixels-per-patch" and value.strip().isdigit() \
                and 64 < int(value) <= 512:
            value = "64"  # valid but slow: the fast suite keeps to small charts
        before = fingerprint([world["image"]])
        with tempfile.TemporaryDirectory() as tmp:
            outcome = run(*argv(value, world))
            # an audit's corners and exposure are about its image: the line may name either
            assert_promise(outcome, names=[name, value.strip() or name, str(world["image"])],
                           before=before, folders=[Path(tmp)])

    check()


@pytest.mark.parametrize(("option", "value"), [
    ("render --step", "0"), ("render --step", "0.001"), ("render --step", "1e-320"),
    ("render --pixels-per-patch", "100000"), ("render --seed", "-1"),
    ("render --spp", "10000000000"), ("audit --exposure", "1e300"),
    ("audit --exposure", "nan"), ("calibrate --targets", "1-1e300"),
    ("calibrate --targets", "1-999999999"), ("predict --delta-e", "nan"),
    ("audit --max-pixels", "0"),
])
def test_option_corner_cases(option: str, value: str, chart_images: dict[str, Path]) -> None:
    """The values the issue tried: refused, exit 2, one line naming the option."""
    argv, name = OPTIONS[option]
    before = fingerprint([chart_images["png"]])
    outcome = run(*argv(value, {"image": chart_images["png"]}))
    assert_promise(outcome, names=[name, value], before=before, codes=(2,))
