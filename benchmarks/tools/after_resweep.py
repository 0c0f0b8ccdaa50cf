"""Rebuild what reads the shipped COCO tables, after ``benchmarks/tools/resweep_model.sh`` has merged
re-measured detectors into ``reports/coco`` and ``fidelity/data/prediction`` (issue 32), so
that one commit carries the tables and everything computed from them:

1. the per-cell before/after of every re-measured detector against the tables of
   :data:`OLD_PREPROCESSING_REV` (the last measured wholly with the earlier preprocessing):
   ``reports/coco/preprocessing_change_cells.{md,json}`` (``benchmarks.tools.compare_tables``);
2. the validation report from its store (``fidelity validate --report-only``: the measured
   cells as stored, the predictions from the new tables) into ``reports/validation``, and its
   validated cameras (``domain.json``, with the sharpness and noise validation's
   ``properties-domain.json`` as its ``properties``) into ``fidelity/data/validation-domain.json``;
3. the COCO-C report (``fidelity coco-c --report-only``, its predictions recomputed from the
   new tables) into ``reports/cococ`` and the shipped ``fidelity/data/coco-c.json``;
4. the recorded JSON outputs of the test suite (``FIDELITY_RECORD_JSON=1``);
5. the tables README.md and docs/*.md quote from the rebuilt reports (:func:`requote`: each
   line of a quoted table or list copied again from its report, found by its first cell) and
   the table of ``reports/cococ/README.md`` from ``cococ.json`` (``tests/test_docs_numbers.py``
   checks both).

Only files that already exist in the report folders are replaced. What stays by hand: the
``AWAITING_RESWEEP`` set in ``tests/report/test_evidence.py`` and the prose (``reports/coco/
preprocessing_change.md``, ``reports/validation/analysis.md``, README, docs), whose numbers
it prints (:func:`prose_numbers`).

    python -m benchmarks.tools.after_resweep --validation-store ~/.cache/fidelity/validation-v3

On a machine without that store, the validation's committed scores file
(:data:`VALIDATION_SCORES`, ``fidelity validate --export-scores``) is imported into it first.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from fidelity.prediction.interval import shipped_domain

REPO = Path(__file__).resolve().parents[2]
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
        _run([sys.executable, "-m", "benchmarks.tools.compare_tables", name,
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
        properties = REPO / "reports" / "validation" / "properties-domain.json"
        doc = shipped_domain(json.loads((Path(out) / "domain.json").read_text("utf-8")),
                             json.loads(properties.read_text("utf-8"))
                             if properties.is_file() else None)
        text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
        if text != shipped.read_text("utf-8"):
            shipped.write_text(text, "utf-8")
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


#: The line of a manual page that introduces a table (or list) quoted from a report.
QUOTE = re.compile(r"as in `(reports/[^`]+\.md)`(?: \([^)]*\))?:$")
#: A table's separator line, whose alignment marks may differ from the report's.
SEPARATOR = re.compile(r"\|[-:| ]+\|")


def quoted_blocks(text: str) -> list[tuple[str, int, int]]:
    """(report, first line, end line) of every table or list in ``text`` introduced by
    :data:`QUOTE`: the introducing line, blank lines, then the ``|`` or ``- `` lines."""
    lines = text.split("\n")
    out = []
    for i, line in enumerate(lines):
        m = QUOTE.search(line)
        if m:
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            k = j
            while k < len(lines) and lines[k].startswith(("|", "- ")):
                k += 1
            out.append((m.group(1), j, k))
    return out


def _key(line: str) -> str:
    """What names a quoted line in its report: a table row's first cell, a list item's text up
    to its first colon."""
    return line.split("|")[1].strip() if line.startswith("|") else line.split(":")[0]


def _matching_block(report: str, quoted: list[str]) -> dict[str, str]:
    """The lines of the table or list in ``report`` that ``quoted`` copies, by key: the one
    with the same header line, else the one sharing the most keys (a report names a model in
    the first cell of several tables)."""
    blocks: list[list[str]] = []
    run: list[str] = []
    for line in [*report.split("\n"), ""]:
        if line.startswith(("|", "- ")):
            run.append(line)
        elif run:
            blocks.append(run)
            run = []
    keys = {_key(q) for q in quoted if not SEPARATOR.fullmatch(q)}
    best = max(blocks, default=[], key=lambda b: (bool(quoted) and b[0] == quoted[0],
                                                  len(keys & {_key(r) for r in b})))
    return {_key(r): r for r in best if not SEPARATOR.fullmatch(r)}


def cococ_readme_row(cell: dict[str, object]) -> str:
    """A row of ``reports/cococ/README.md``'s table from a cell of ``cococ.json``."""
    parts = cell["parts"]
    pred = cell["prediction"]
    assert isinstance(parts, dict) and isinstance(pred, dict)
    measured = {m["model"]: f"{m['dmap_points']:.2f} ± {m['dmap_points_se']:.2f}"
                for m in cell["measured"]}  # type: ignore[attr-defined]
    return (f"| {cell['corruption']} | {cell['severity']} | {cell['chart_delta_e']:.2f} | "
            f"{parts['lightness']:.2f} / {parts['chroma']:.2f} / {parts['hue']:.2f} | "
            f"{pred['classic']:.2f} | {pred['directional']:.2f} | "
            f"{measured['yolox_nano']} | {measured['yolo11n-int8dyn']} |")


COCOC_ROW = re.compile(r"\| [a-z]+ \| \d \|")


def quoting_pages(root: Path = REPO) -> list[Path]:
    """The pages whose quoted tables (:func:`quoted_blocks`) are the reports' own lines:
    README.md, docs/*.md and the COCO and COCO-C reports' hand-written guides."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md")),
            root / "reports" / "coco" / "README.md", root / "reports" / "cococ" / "README.md"]


def requote(root: Path = REPO) -> list[str]:
    """Copy the quoted tables of :func:`quoting_pages` under ``root`` again from their
    reports, and ``reports/cococ/README.md``'s table from ``cococ.json``; the files changed. A
    quoted line whose key the report no longer has is left for the test to name."""
    changed = []
    for page in quoting_pages(root):
        if not page.is_file():
            continue
        lines = page.read_text("utf-8").split("\n")
        new = list(lines)
        for report, start, end in quoted_blocks("\n".join(lines)):
            have = _matching_block((root / report).read_text("utf-8"), new[start:end])
            for i in range(start, end):
                if not SEPARATOR.fullmatch(new[i]) and _key(new[i]) in have:
                    new[i] = have[_key(new[i])]
        if new != lines:
            page.write_text("\n".join(new), "utf-8")
            changed.append(page.relative_to(root).as_posix())
    readme = root / "reports" / "cococ" / "README.md"
    cells = json.loads((root / "reports" / "cococ" / "cococ.json").read_text("utf-8"))["cells"]
    lines = readme.read_text("utf-8").split("\n")
    at = [i for i, line in enumerate(lines) if COCOC_ROW.match(line)]
    if len(at) == len(cells):
        new = list(lines)
        for i, cell in zip(at, cells, strict=True):
            new[i] = cococ_readme_row(cell)
        if new != lines:
            readme.write_text("\n".join(new), "utf-8")
            changed.append(readme.relative_to(root).as_posix())
    return changed


def prose_numbers(root: Path = REPO) -> list[str]:
    """The numbers the hand-written prose of a merge quotes (``reports/coco/
    preprocessing_change.md``, ``reports/validation/analysis.md``): per re-measured detector of
    ``preprocessing_change_cells.json`` the median and largest change of a cell, the cells
    beyond one and two after-SE, the baseline and the largest change of the worst case per ΔE
    (over ΔE >= 2 in units of its SE, and whether its transform stayed); then the validation's
    cells over the classic bound (by how much, in SE) and the bound lines of the validation and
    COCO-C reports."""
    out = []
    models = json.loads((root / "reports" / "coco" / "preprocessing_change_cells.json")
                        .read_text("utf-8"))["models"]
    for model, d in models.items():
        cells = d["cells"]
        big = max(cells, key=lambda c: abs(c["change"]))
        beyond = [sum(abs(c["change"]) > k * c["se_after"] for c in cells) for k in (1, 2)]
        out.append(f"{model}: {len(cells)} cells, median |change| "
                   f"{statistics.median(abs(c['change']) for c in cells):.3f}, largest "
                   f"{big['change']:+.3f} ({big['transform']} ΔE {big['delta_e']:g}: "
                   f"{big['before']:.3f} -> {big['after']:.3f}), beyond 1 SE {beyond[0]}, "
                   f"beyond 2 SE {beyond[1]}; baseline mAP {d['baseline_map_before']:.4f} -> "
                   f"{d['baseline_map_after']:.4f}")
        wc = d["worst_case"]
        w = max(wc, key=lambda r: abs(r["change"]))
        up = [r for r in wc if r["delta_e"] >= 2]
        moved = [f"ΔE {r['delta_e']:g} {r['before_transform']} -> {r['after_transform']}"
                 for r in wc if r["before_transform"] != r["after_transform"]]
        out.append(f"  worst case: largest |change| {abs(w['change']):.3f} (ΔE {w['delta_e']:g}: "
                   f"{w['before_transform']} {w['before']:.3f} -> {w['after_transform']} "
                   f"{w['after']:.3f}); ΔE >= 2: {min(r['change'] for r in up):+.2f}.."
                   f"{max(r['change'] for r in up):+.2f}, at most "
                   f"{max(abs(r['change']) / r['se_after'] for r in up):.2f} SE; worst "
                   f"transform changed: {', '.join(moved) or 'nowhere'}")
    rows = json.loads((root / "reports" / "validation" / "validation.json")
                      .read_text("utf-8"))["rows"]
    over = [(r["camera"], r["model"], r["bound"]["all"]["excess"],
             r["bound"]["all"]["excess"] / r["bound"]["all"]["se"])
            for r in rows if not r["bound"]["all"]["within"]]
    out.append(f"validation: {len(over)} of {len(rows)} cells over the classic bound"
               + "".join(f"; {c} ({m}) by {e:.3f} points, {k:.2f} SE" for c, m, e, k in over))
    for report in ("validation/validation.md", "cococ/cococ.md"):
        out += [line for line in (root / "reports" / report).read_text("utf-8").splitlines()
                if line.startswith(("> - mAP@", "> - Classic", "> - Direction-aware"))]
    return out


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
          "tests/cli/test_json_outputs.py"], env={**os.environ, "FIDELITY_RECORD_JSON": "1"})
    print("quoted tables:", requote())
    _run(["git", "status", "--short"])
    print("\n".join(["numbers for the prose:", *prose_numbers()]))
    print("by hand: AWAITING_RESWEEP in tests/report/test_evidence.py; the prose of "
          "reports/coco/preprocessing_change.md, reports/validation/analysis.md, README, docs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
