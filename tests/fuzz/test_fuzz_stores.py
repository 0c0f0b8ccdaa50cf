"""Fuzz: results stores that are garbage, cut short or hold provenance that is not what the
code wrote, for ``sweep --status``, ``tables`` and ``validate --report-only``.

Stores are issue 23's item 5 (fidelity/coco/store.py, sweep.py, validate.py): a damaged,
empty or cut-short store is refused in one line naming it, and a reader never writes to it.
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzzkit import FAST, LONG, assert_promise, budget, damaged_bytes, fingerprint, run

EXAMPLES = [FAST, pytest.param(LONG, marks=pytest.mark.fuzz)]


@pytest.fixture(scope="module")
def sweep_store(coco: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished one-cell sweep of the stand-in detector."""
    out = tmp_path_factory.mktemp("store")
    r = run("sweep", "--models", coco["model"], "--images", coco["images"], "--annotations",
            coco["annotations"], "--out", out, "--transforms", "hue", "--targets", "0",
            "--no-progress")
    assert r.code == 0, r
    return out


def _commands(store: Path, out: Path) -> dict[str, list[Any]]:
    return {"sweep --status": ["sweep", "--status", "--out", store],
            "tables": ["tables", store, "--no-standard-errors", "--out", out, "--no-progress"]}


def _store_promise(folder: Path, command: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        argv = _commands(folder, Path(tmp) / "report")[command]
        # the database itself must not change (its WAL companions may be checkpointed)
        before = fingerprint([folder / "sweep.sqlite"])
        outcome = run(*argv)
        assert_promise(outcome, names=[str(folder), "store"], before=before,
                       folders=[Path(tmp)])


@pytest.mark.parametrize("examples", EXAMPLES)
def test_damaged_store_files(examples: int, sweep_store: Path) -> None:
    """The store's SQLite file cut short, overwritten or replaced."""
    raw = (sweep_store / "sweep.sqlite").read_bytes()

    @budget(examples)
    @given(data=st.data(), command=st.sampled_from(["sweep --status", "tables"]))
    def check(data: st.DataObject, command: str) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "store"
            folder.mkdir()
            (folder / "sweep.sqlite").write_bytes(data.draw(damaged_bytes(raw)))
            _store_promise(folder, command)

    check()


@pytest.mark.parametrize("examples", EXAMPLES)
def test_store_provenance(examples: int, sweep_store: Path) -> None:
    """A store whose ``meta`` values (JSON provenance) were changed: reported, or refused."""

    @budget(examples)
    @given(key=st.sampled_from(["grid", "data", "versions", "scorers", "machine"]),
           value=st.sampled_from(["null", "3", "\"x\"", "[]", "{}", "not json", "{\"transforms\": 3}",
                                  "{\"targets\": [\"a\"]}", "{\"images\": null}"]),
           command=st.sampled_from(["sweep --status", "tables"]))
    def check(key: str, value: str, command: str) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "store"
            shutil.copytree(sweep_store, folder)
            with sqlite3.connect(folder / "sweep.sqlite") as db:
                db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))
            _store_promise(folder, command)

    check()
