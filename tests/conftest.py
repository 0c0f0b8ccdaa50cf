"""Shared test fixtures: locations of the project's data and of ../shared."""

from __future__ import annotations

from pathlib import Path

import pytest

from fidelity.core.resources import shared_dir

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


# The suite never writes the package's shipped data (prediction tables, COCO-C table, validation
# domain): a documented command once did, through an output option the docs test took for an
# input. Their digests before and after the session (on the controller, not xdist's workers).
SHIPPED_DATA = Path(__file__).resolve().parents[1] / "fidelity" / "data"


def _shipped_digests() -> dict[str, str]:
    import hashlib

    return {str(p.relative_to(SHIPPED_DATA)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(SHIPPED_DATA.rglob("*")) if p.is_file()}


def pytest_sessionstart(session: pytest.Session) -> None:
    if not hasattr(session.config, "workerinput"):
        session.config.stash[_DIGESTS] = _shipped_digests()


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    before = session.config.stash.get(_DIGESTS, None)
    if before is None or hasattr(session.config, "workerinput"):
        return
    after = _shipped_digests()
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    if changed:
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line(f"the suite changed fidelity/data: {', '.join(changed)}",
                                red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


_DIGESTS = pytest.StashKey[dict[str, str]]()
