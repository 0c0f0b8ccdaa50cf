"""A full disk and a read-only folder as output: one line naming the output, exit 2, the
partial file removed, earlier outputs as they were.

Two ways to fill the disk: a 64 KiB tmpfs (real ENOSPC and EROFS; needs root and a kernel that
lets the test mount one, skipped otherwise) and a file-size limit (``RLIMIT_FSIZE``: writes past
a few hundred bytes fail with EFBIG, anywhere, for anyone).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.fuzz.fuzzkit import fingerprint, leftovers, run

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="tmpfs and RLIMIT_FSIZE: Linux")

#: Bytes a file may grow to under the file-size limit.
FILE_LIMIT = 300


@contextlib.contextmanager
def _tmpfs(folder: Path) -> Iterator[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)],
                         capture_output=True, check=False)
    if res.returncode:
        pytest.skip(f"cannot mount a tmpfs here ({res.stderr.decode().strip()})")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


@contextlib.contextmanager
def _file_limit() -> Iterator[None]:
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_LIMIT, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old)


def _commands(w: dict[str, Any], out: Path) -> dict[str, tuple[list[Any], Path]]:
    """Each command writing into ``out``: its command line and the output that exists from
    an earlier run (which must survive)."""
    c = w.get("coco")
    cmds: dict[str, tuple[list[Any], Path]] = {
        "render --out": (["render", "--out", out / "r", "-q"], out / "r" / "raw_camera.exr"),
        "audit --html": (["audit", w["image"], "--corners", "12,12,112,12,112,72,12,72",
                          "--html", out / "a.html"], out / "a.html"),
        "calibrate --json": (["calibrate", "--targets", "1-6", "--json", out / "c.json", "-q"],
                             out / "c.json"),
        "predict --json": (["predict", "--delta-e", "3", "--json", out / "p.json"],
                           out / "p.json"),
    }
    if c is not None:
        cmds.update({
            "evaluate --json": (["evaluate", "--models", c["model"], "--images", c["images"],
                                 "--annotations", c["annotations"], "--json", out / "e.json",
                                 "--no-progress"], out / "e.json"),
            "dataset": (["dataset", "--images", c["images"], "--out", out / "d", "--transforms",
                         "hue", "--targets", "3", "--no-progress", "--workers", "1"],
                        out / "d" / "hue_de3" / "000000000001.jpg"),
            "sweep": (["sweep", "--models", c["model"], "--images", c["images"],
                       "--annotations", c["annotations"], "--out", out / "s", "--transforms",
                       "hue", "--targets", "0", "--no-progress"], out / "s" / "earlier.txt"),
        })
    return cmds


def _prepare(earlier: Path) -> None:
    earlier.parent.mkdir(parents=True, exist_ok=True)
    earlier.write_bytes(b"earlier")


def _fill(folder: Path) -> None:
    """Fill the file system of ``folder`` to the last byte."""
    with contextlib.suppress(OSError), open(folder / "filler", "wb", buffering=0) as fh:
        while True:
            fh.write(b"\0" * 1024)


def _check(outcome: Any, out: Path, earlier: Path, before: dict[str, str]) -> None:
    assert outcome.code == 2, outcome
    lines = [ln for ln in outcome.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), outcome
    assert str(out) in lines[0] or "results store" in lines[0], outcome
    assert "Traceback" not in outcome.stderr + outcome.stdout, outcome
    assert earlier.read_bytes() == b"earlier", outcome
    assert not leftovers([out]), leftovers([out])
    assert fingerprint(Path(p) for p in before) == before


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path_factory: pytest.TempPathFactory,
                monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """An empty ``$FIDELITY_CACHE``, as on a fresh machine: the caches fidelity fills are
    written under the same limits as the outputs."""
    monkeypatch.setenv("FIDELITY_CACHE", str(tmp_path_factory.mktemp("cache")))
    yield


@pytest.fixture
def world(chart_images: dict[str, Path], request: pytest.FixtureRequest) -> dict[str, Any]:
    w: dict[str, Any] = {"image": chart_images["png"]}
    with contextlib.suppress(pytest.skip.Exception):
        w["coco"] = request.getfixturevalue("coco")
    return w


COMMANDS = ["render --out", "audit --html", "calibrate --json", "predict --json",
            "evaluate --json", "dataset", "sweep"]


@pytest.mark.parametrize("command", COMMANDS)
def test_file_size_limit(command: str, world: dict[str, Any], tmp_path: Path) -> None:
    """Writes fail with EFBIG past a few hundred bytes: one line, nothing half written."""
    cmds = _commands(world, tmp_path)
    if command not in cmds:
        pytest.skip("needs the COCO extra")
    argv, earlier = cmds[command]
    _prepare(earlier)
    inputs = [world["image"]] + ([world["coco"]["folder"]] if "coco" in world else [])
    before = fingerprint(inputs)
    with _file_limit():
        outcome = run(*argv)
    _check(outcome, tmp_path, earlier, before)


@pytest.mark.fuzz
@pytest.mark.parametrize("read_only", [False, True], ids=["full", "read-only"])
@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="mounting a tmpfs needs root")
def test_full_and_read_only_tmpfs(command: str, read_only: bool, world: dict[str, Any],
                                  tmp_path: Path) -> None:
    """A 64 KiB tmpfs, nearly full or read-only, as the output folder (what the issue tried)."""
    disk = tmp_path / "disk"
    cmds = _commands(world, disk)
    if command not in cmds:
        pytest.skip("needs the COCO extra")
    argv, earlier = cmds[command]
    with _tmpfs(disk) as folder:
        _prepare(earlier)
        if read_only:
            subprocess.run(["mount", "-o", "remount,ro", str(folder)], check=True)
        else:
            _fill(folder)
        inputs = [world["image"]] + ([world["coco"]["folder"]] if "coco" in world else [])
        before = fingerprint(inputs)
        outcome = run(*argv)
        _check(outcome, folder, earlier, before)
