"""Rebuild what reads the shipped COCO tables, after ``benchmarks/resweep_model.sh`` has merged
re-measured detectors into ``reports/coco`` and ``fidelity/data/prediction`` (issue 32), so
that one commit carries the tables and everything computed from them:

1. the per-cell before/after of every re-measured detector against the tables of
   :data:`OLD_PREPROCESSING_REV` (the last measured wholly with the earlier preprocessing):
   ``reports/coco/preprocessing_change_cells.{md,json}`` (``benchmarks.compare_tables``);
2. the validation report from its store (``fidelity validate --report-only``: the measured
   cells as stored, the predictions from the new tables) into ``reports/validation``, and its
   validated cameras (``domain.json``) into ``fidelity/data/validation-domain.json``;
3. the COCO-C report (``fidelity coco-c --report-only``, its predictions recomputed from the
   new tables) into ``reports/cococ`` and the shipped ``fidelity/data/coco-c.json``;
4. the recorded JSON outputs of the test suite (``FIDELITY_RECORD_JSON=1``).

Only files that already exist in the report folders are replaced. What stays by hand: the
``AWAITING_RESWEEP`` set in ``tests/test_evidence.py`` and the prose (``reports/coco/
preprocessing_change.md``, ``reports/validation/analysis.md``, README, docs).

    python -m benchmarks.after_resweep --validation-store ~/.cache/fidelity/validation-v3

On a machine without that store, the validation's committed scores file
(:data:`VALIDATION_SCORES`, ``fidelity validate --export-scores``) is imported into it first.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
#: The validation store's cells without their detections (``fidelity validate
#: --export-scores``), committed so that a new machine can report the validation again.
VALIDATION_SCORES = REPO / "reports" / "validation" / "validation.scores.json.gz"
#: The commit whose ``reports/coco/tables.json`` is the "before" of every re-measured detector.
OLD_PREPROCESSING_REV = "1ebe250"


def _run(argv: list[str], env: dict[str, str] | None = None) -> None:
    print("+", " ".join(argv), flush=True)
    subprocess.run(argv, check=True, cwd=REPO, env=env)


def _replace_existing(src: Path, dst: Path) -> list[str]:
    """Copy each file of ``src`` over the file of the same name in ``dst`` when ``dst`` has it
    and the content differs; the names replaced."""
    changed = []
    for f in sorted(src.iterdir()):
        target = dst / f.name
        if f.is_file() and target.is_file() and f.read_bytes() != target.read_bytes():
            shutil.copyfile(f, target)
            changed.append(f.name)
    return changed


def before_after() -> None:
    name = f"tables-at-{OLD_PREPROCESSING_REV}.json"  # relative: the report names no machine path
    before = REPO / name
    before.write_bytes(subprocess.run(
        ["git", "show", f"{OLD_PREPROCESSING_REV}:reports/coco/tables.json"], cwd=REPO,
        check=True, capture_output=True).stdout)
    try:
        _run([sys.executable, "-m", "benchmarks.compare_tables", name,
              "reports/coco/tables.json", "--out", "reports/coco/preprocessing_change_cells"])
    finally:
        before.unlink()


def validation(store: Path, shared: Path) -> list[str]:
    with tempfile.TemporaryDirectory() as out:
        _run([sys.executable, "-m", "fidelity", "validate", "--cameras", "cameras",
              "--images", str(shared / "coco" / "val2017"), "--annotations",
              str(shared / "coco" / "annotations" / "instances_val2017_subset.json"),
              "--store", str(store), "--report-only", "--notes",
              "reports/validation/analysis.md", "--out", out])
        changed = _replace_existing(Path(out), REPO / "reports" / "validation")
        # the validated cameras, shipped for the validity domain of a check's prediction
        shipped = REPO / "fidelity" / "data" / "validation-domain.json"
        domain = Path(out) / "domain.json"
        if domain.read_bytes() != shipped.read_bytes():
            shutil.copyfile(domain, shipped)
            changed.append("fidelity/data/validation-domain.json")
        return changed


def coco_c() -> list[str]:
    with tempfile.TemporaryDirectory() as out:
        doc = json.loads((REPO / "reports" / "cococ" / "cococ.json").read_text("utf-8"))
        for cells in _cells(doc):  # the predictions are recomputed from the shipped tables
            cells.pop("prediction", None)
        (Path(out) / "cococ.json").write_text(json.dumps(doc, indent=1) + "\n", "utf-8")
        data = Path(out) / "data"
        data.mkdir()
        _run([sys.executable, "-m", "fidelity", "coco-c", "--report-only", "--out", out,
              "--notes", "reports/cococ/analysis.md", "--data", str(data / "coco-c.json")])
        # the shipped table holds the same run, its predictions included
        return (_replace_existing(Path(out), REPO / "reports" / "cococ")
                + _replace_existing(data, REPO / "fidelity" / "data"))


def _cells(doc: object) -> list[dict[str, object]]:
    """Every mapping in ``doc`` that holds a ``prediction``."""
    found: list[dict[str, object]] = []
    if isinstance(doc, dict):
        if "prediction" in doc:
            found.append(doc)
        for v in doc.values():
            found.extend(_cells(v))
    elif isinstance(doc, list):
        for v in doc:
            found.extend(_cells(v))
    return found


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--validation-store", type=Path, required=True)
    ap.add_argument("--shared", type=Path,
                    default=Path(os.environ.get("FIDELITY_SHARED", REPO.parent / "shared")))
    a = ap.parse_args(argv)
    store = a.validation_store.expanduser()
    if not (store / "validation.sqlite").is_file() and VALIDATION_SCORES.is_file():
        _run([sys.executable, "-m", "fidelity", "validate", "--import-scores",
              str(VALIDATION_SCORES), "--store", str(store)])
    before_after()
    print("validation:", validation(store, a.shared.resolve()))
    print("COCO-C:", coco_c())
    _run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
          "tests/test_json_outputs.py"], env={**os.environ, "FIDELITY_RECORD_JSON": "1"})
    _run(["git", "status", "--short"])
    print("by hand: AWAITING_RESWEEP in tests/test_evidence.py; the prose of "
          "reports/coco/preprocessing_change.md, reports/validation/analysis.md, README, docs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
