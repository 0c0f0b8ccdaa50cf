"""Shared test fixtures: locations of the project's data and of ../shared."""

from __future__ import annotations

from pathlib import Path

import pytest

from fidelity.resources import shared_dir

pytest_plugins = ["pytester"]

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def shared() -> Path:
    """The shared data folder (../shared or $FIDELITY_SHARED); skips the test when absent."""
    path = shared_dir()
    if path is None:
        pytest.skip("../shared (or $FIDELITY_SHARED) is not present: COCO images and ONNX models needed")
    return path


@pytest.fixture
def pytester(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    """pytest's ``pytester``, its runs as a user's own pytest run: without the environment
    pytest-xdist gives its workers (``PYTEST_XDIST_*``), which plugins read as "this run is
    distributed" (pytest-benchmark then warns, an error under ``-W error``)."""
    import os

    for name in [n for n in os.environ if n.startswith("PYTEST_XDIST_")]:
        monkeypatch.delenv(name)
    return pytester


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files marked ``early`` (the longest) first, the rest in their order: with
    ``--dist loadfile`` the workers take files in this order, so a parallel run does not wait
    at its end on one long file (a stable sort: the same order on every worker)."""
    items.sort(key=lambda item: item.get_closest_marker("early") is None)
