"""Fuzz: images for audit and gate (odd sizes, channels and pixel types, NaN/Inf, damaged bytes,
decompression bombs, file names that are not UTF-8, the pixel limit)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzzkit import (
    FAST,
    LONG,
    assert_promise,
    budget,
    damaged_bytes,
    fingerprint,
    image_arrays,
    png_header_only,
    run,
    write_image,
)

EXAMPLES = [FAST, pytest.param(LONG, marks=pytest.mark.fuzz)]

#: Corner-patch centres of the conftest's rendered chart (16 px patches, 4 px gaps).
CORNERS = "12,12,112,12,112,72,12,72"


def _audit_promise(image: Path, out: Path, command: str = "audit",
                   corners: str | None = None) -> None:
    before = fingerprint([image])
    json_out = out / "report.json"
    args = (["audit", image, "--json", json_out] if command == "audit" else
            ["gate", image, "--max-delta-e", "3", "--json", json_out,
             "--junit", out / "junit.xml"])
    if corners:
        args += ["--corners", corners]
    outcome = run(*args)
    # a gate writes its JUnit file (the error as a test case) even when the image is bad
    assert_promise(outcome, names=[str(image), image.name], before=before,
                   outputs=[json_out], folders=[image.parent, out])


@pytest.mark.parametrize("examples", EXAMPLES)
def test_generated_images(examples: int) -> None:
    """Images of every size, channel count and pixel type the formats hold, with NaN, Inf,
    negative and huge values: audited, or refused in one line naming the file."""

    @budget(examples)
    @given(image=image_arrays(), command=st.sampled_from(["audit", "gate"]),
           corners=st.sampled_from(["8,8,80,8,80,56,8,56", "0,0,1,0,1,1,0,1",
                                    "1e30,0,1,1,2,2,3,3", "nan,1,2,3,4,5,6,7"]))
    def check(image: tuple[str, object], command: str, corners: str) -> None:
        # corners given: the reading and measuring paths (chart finding is fuzzed on real
        # charts in test_damaged_images; on noise it takes seconds per image)
        suffix, pixels = image
        with tempfile.TemporaryDirectory() as tmp:
            path = write_image(Path(tmp) / f"img{suffix}", pixels)  # type: ignore[arg-type]
            out = Path(tmp) / "out"
            out.mkdir()
            _audit_promise(path, out, command, corners)

    check()


@pytest.mark.parametrize("examples", EXAMPLES)
def test_damaged_images(examples: int, chart_images: dict[str, Path]) -> None:
    """A real chart image cut short, overwritten, padded with garbage or replaced."""

    @budget(examples)
    @given(kind=st.sampled_from(sorted(chart_images)), data=st.data())
    def check(kind: str, data: st.DataObject) -> None:
        raw = data.draw(damaged_bytes(chart_images[kind].read_bytes()))
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"damaged.{kind}"
            path.write_bytes(raw)
            _audit_promise(path, Path(tmp))

    check()


@pytest.mark.parametrize("examples", EXAMPLES)
def test_decompression_bombs_are_refused_from_the_header(examples: int) -> None:
    """A PNG declaring up to 2**31 - 1 pixels a side is refused before decoding (or found
    corrupt), never allocated."""

    @budget(examples)
    @given(width=st.integers(1, 2**31 - 1), height=st.integers(1, 2**31 - 1),
           padding=st.sampled_from([0, 300_000]))
    def check(width: int, height: int, padding: int) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bomb.png"
            path.write_bytes(png_header_only(width, height, padding))
            _audit_promise(path, Path(tmp))

    check()


def test_pixel_limit_flag_and_environment(chart_images: dict[str, Path], tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The limit comes from --max-pixels, else FIDELITY_MAX_PIXELS, else the default; the
    message names the file, its size and how to raise the limit."""
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(png_header_only(30000, 30000, padding=300_000))
    r = run("audit", bomb)
    assert r.code == 2 and "30000x30000" in r.stderr and "--max-pixels" in r.stderr, r
    image = chart_images["png"]
    corners = ("--corners", CORNERS)
    assert run("audit", image, *corners).code == 0
    r = run("audit", image, "--max-pixels", 1000)
    assert r.code == 2 and "more than the limit of 0.001 megapixels" in r.stderr, r
    r = run("gate", image, "--max-delta-e", "3", "--max-pixels", 1000)
    assert r.code == 2 and str(image) in r.stderr, r
    monkeypatch.setenv("FIDELITY_MAX_PIXELS", "1000")
    assert run("audit", image).code == 2
    assert run("audit", image, "--max-pixels", 10**7, *corners).code == 0  # the flag wins
    monkeypatch.setenv("FIDELITY_MAX_PIXELS", "lots")
    r = run("audit", image)
    assert r.code == 2 and "FIDELITY_MAX_PIXELS=lots" in r.stderr, r


@pytest.mark.skipif(os.name != "posix", reason="file names as bytes are a POSIX matter")
def test_file_names_that_are_not_utf8(chart_images: dict[str, Path], tmp_path: Path) -> None:
    """audit and gate on a file whose name is not UTF-8: measured like any other (issue 30:
    read through a plain-named link), the input untouched, no temporary file left, the JUnit
    case naming it with \\xNN."""
    raw = os.path.join(os.fsencode(tmp_path), b"chart\xff.png")
    with open(raw, "wb") as fh:
        fh.write(chart_images["png"].read_bytes())
    name = os.fsdecode(raw)
    before = fingerprint([Path(name)])
    for args in (["audit", name], ["gate", name, "--max-delta-e", "3", "--junit",
                                   tmp_path / "j.xml"]):
        r = run(*args)
        assert_promise(r, names=["chart\\xff.png"], before=before, folders=[tmp_path],
                       codes=(0, 1))
    assert "chart\\xff.png" in (tmp_path / "j.xml").read_text(encoding="utf-8")
