"""The validation report's words come from its numbers: the "Answer" section is generated from
the cells (checked here against a count made from the committed ``validation.json`` by hand),
and the written notes shipped beside the report state no result that could go stale."""

from __future__ import annotations

import copy
import json
import re
import statistics
from pathlib import Path
from typing import Any

from fidelity.coco.validate.colour import ValidationResults
from fidelity.report.html import render_markdown
from fidelity.report.validation import validation_document

REPO = Path(__file__).resolve().parents[2]
VALIDATION = REPO / "reports" / "validation"


def _answer(d: dict[str, Any]) -> str:
    doc = validation_document(ValidationResults.from_json(d), figures={})
    md = render_markdown(doc)
    start = md.index("## Answer")
    return md[start:md.index("\n## ", start + 1)]


def _committed() -> dict[str, Any]:
    return json.loads((VALIDATION / "validation.json").read_text(encoding="utf-8"))


def test_the_answer_counts_what_the_cells_hold() -> None:
    d = _committed()
    text = _answer(d)
    bounds = [r["bound"]["all"] for r in d["rows"] if r["bound"]["all"]["within"] is not None]
    misses = [r for r in d["rows"] if r["bound"]["all"]["within"] is False]
    table = d["summary"]["bound_table"]
    assert f"`{table}` bounds the measured loss in **{len(bounds) - len(misses)} of " \
           f"{len(bounds)}** cells; it is exceeded in {len(misses)}:" in text
    for r in misses:
        b = r["bound"]["all"]
        assert (f"`{r['camera']}` / {r['model']} ({r['illuminant']}, chart ΔE "
                f"{r['chart_delta_e']:.2f}): measured {b['measured']:.2f}") in text
    low = sum(1 for r in misses if r["chart_delta_e"] <= 3)
    assert f"- {low} of these {len(misses)} cells have chart ΔE ≤ 3 " in text
    resolved = [b for b in bounds if b["se"] and b["measured"] > 2 * b["se"]]
    assert f"resolves {len(resolved)} of {len(bounds)} losses" in text
    ratio = statistics.median(b["predicted"] / b["measured"] for b in resolved)
    assert f"predicts a median {ratio:.1f}× the measured loss" in text


def test_the_answer_follows_a_changed_cell() -> None:
    """The words move with the numbers: a cell pushed over the bound is counted and named."""
    d = copy.deepcopy(_committed())
    cell = next(r for r in d["rows"] if r["bound"]["all"]["within"]
                and r["camera"] == "nikon5100-cheung-d65")
    b = cell["bound"]["all"]
    b["measured"] = b["predicted"] + 1.0
    b["excess"], b["within"], b["within_2se"] = 1.0, False, False
    before, after = _answer(_committed()), _answer(d)
    n = int(re.search(r"exceeded in (\d+):", before).group(1))  # type: ignore[union-attr]
    assert f"exceeded in {n + 1}:" in after
    assert "`nikon5100-cheung-d65` / " + cell["model"] in after
    assert "`nikon5100-cheung-d65` / " not in before


def test_the_shipped_notes_state_no_result() -> None:
    """reports/validation/analysis.md, the report's written notes, quotes no measured number:
    no decimal, no percentage, no "N of M" count, no ratio (the code block's command aside)."""
    text = (VALIDATION / "analysis.md").read_text(encoding="utf-8")
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    found = re.findall(r"\d+\.\d+|\d+ ?%|\d+ of \d+|\d+(?:\.\d+)?×|ρ", prose)
    assert not found, found


def test_the_committed_report_is_built_with_the_answer() -> None:
    md = (VALIDATION / "validation.md").read_text(encoding="utf-8")
    assert _answer(_committed()).strip() in md
