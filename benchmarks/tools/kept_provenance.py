"""Where each kept model of a merged ``tables.json`` was measured, recovered from git history.

``fidelity tables STORE --earlier FILE`` records, per run that measured some of the kept
models, that run's versions, machine(s), scorers and imported scores files
(``meta["earlier"]["runs"]``). Versions before that wrote one record for every kept model, the
meta of the tables they were last kept in, so a model kept through two merges was named with
the machine of a run that did not measure it. The merges of the re-sweeps
(``benchmarks/tools/resweep_model.sh``) read a copy of the committed tables named
``reports-coco-tables-at-<commit>.json``: each such record names a commit whose
``reports/coco/tables.json`` has the recorded SHA-256, and that file's own meta is the run
that measured the models it did not keep. This walks that chain back for every kept model
(checking each SHA-256) and writes the tables, their report and the prediction tables with
the recovered ``runs``; nothing else changes.

Usage: python -m benchmarks.tools.kept_provenance TABLES_JSON --out DIR [--prediction FILE]
           [--directional FILE]
       (TABLES_JSON: a copy, as the merge reads one; DIR/tables.json must not be it)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import subprocess
from pathlib import Path
from typing import Any

from fidelity.coco.tables.provenance import RUN_KEYS, earlier_runs, record_by_name, runs_passed_on

REPO = Path(__file__).resolve().parents[2]
_COMMIT = re.compile(r"reports-coco-tables-at-([0-9a-f]{7,40})\.json$")


def committed_tables(commit: str, sha256: str, repo: Path = REPO) -> dict[str, Any]:
    """``reports/coco/tables.json`` at ``commit``, which must have the recorded SHA-256."""
    blob = subprocess.run(["git", "show", f"{commit}:reports/coco/tables.json"], cwd=repo,
                          capture_output=True, check=True).stdout
    if hashlib.sha256(blob).hexdigest() != sha256:
        raise ValueError(f"reports/coco/tables.json at {commit} is not the recorded file "
                         f"(SHA-256 {sha256[:12]}…)")
    return dict(json.loads(blob)["tables"])


def recovered_runs(record: dict[str, Any], wanted: list[str],
                   via: list[dict[str, Any]] | None = None, repo: Path = REPO
                   ) -> list[dict[str, Any]]:
    """The runs that measured ``wanted`` (models kept from the file ``record`` names), one
    record each, with ``via``: the files they passed through since (newest last). A record
    that names no commit, or one that already holds ``runs``, is taken as it is."""
    via = via or []
    match = _COMMIT.search(str(record.get("file")))
    if "runs" in record or match is None:  # this version's runs, or the first full run's
        return runs_passed_on(earlier_runs(record), wanted, via)
    tables = committed_tables(match.group(1), str(record["sha256"]), repo)
    meta = tables["meta"]
    earlier = meta.get("earlier") or {}
    carried = set(earlier.get("models") or ())
    here = record_by_name({"file": record["file"], "sha256": record["sha256"]})
    own = [m for m in wanted if m not in carried]
    runs = [here | {"models": own} | {k: meta[k] for k in RUN_KEYS if meta.get(k) is not None}
            | ({"via": via} if via else {})] if own else []
    rest = [m for m in wanted if m in carried]
    if rest:
        runs += recovered_runs(earlier, rest, [here, *via], repo)
    return runs


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("tables")
    ap.add_argument("--out", required=True)
    ap.add_argument("--prediction")
    ap.add_argument("--directional")
    args = ap.parse_args(argv)
    from dataclasses import replace

    from fidelity.cli.tables import _write_directional
    from fidelity.coco.tables.colour import TablesResult
    from fidelity.report.coco import write_tables_report

    source = Path(args.tables)
    if (Path(args.out) / "tables.json").resolve() == source.resolve():
        raise SystemExit(f"{source}: the input; write the repaired tables elsewhere")
    result = TablesResult.from_json(json.loads(source.read_text(encoding="utf-8")))
    tables = result.tables
    earlier = dict(tables.meta.get("earlier") or {})
    if not earlier:
        raise SystemExit(f"{source}: no kept models")
    kept = list(earlier["models"])
    first = {"file": earlier["file"], "sha256": earlier["sha256"]}
    # the record this file holds is of the file it read (first): recover from there
    runs = recovered_runs(first, kept)
    assert sorted(m for r in runs for m in r["models"]) == sorted(kept), runs
    repaired = {"file": earlier["file"], "sha256": earlier["sha256"], "models": kept,
                "runs": runs}
    result = replace(result, tables=replace(tables, meta=tables.meta | {"earlier": repaired}))
    written = write_tables_report(result, args.out, args.prediction, "coco1000-measured")
    if args.directional:
        written["directional"] = _write_directional(result.tables, args.directional)
    for k, p in written.items():
        print(f"{k:<14} {p}")
    for r in runs:
        print(f"{', '.join(r['models'])}: measured in {r['file']} "
              f"(via {', '.join(v['file'] for v in r.get('via', [])) or '-'}) on "
              f"{(r.get('machine') or {}).get('cpu')} "
              f"{' '.join((r.get('machine') or {}).get('instructions') or [])}")


if __name__ == "__main__":
    main()
