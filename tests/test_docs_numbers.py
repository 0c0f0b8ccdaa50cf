"""The manual's result tables are the reports' own: a table (or list) in README.md, docs/*.md or
reports/coco/README.md that is introduced by a line ending "as in `reports/....md`:" must be,
line for line, lines of that report, which the code generates (``fidelity tables``,
``fidelity validate``). When a table is re-measured and its report rebuilt, a page still
quoting the earlier numbers fails here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks.tools.after_resweep import SEPARATOR, cococ_readme_row, quoted_blocks, quoting_pages

REPO = Path(__file__).resolve().parent.parent


def quoted_tables(text: str) -> list[tuple[str, list[str]]]:
    """(report, the block's lines) of every quoted table or list in ``text``."""
    lines = text.split("\n")
    return [(report, lines[start:end]) for report, start, end in quoted_blocks(text)]


def _pages() -> list[Path]:
    return quoting_pages(REPO)


QUOTED = [(page.relative_to(REPO).as_posix(), report, rows)
          for page in _pages()
          for report, rows in quoted_tables(page.read_text(encoding="utf-8"))]


def test_quoted_tables_are_found_where_the_results_are_stated():
    pages = {(page, report) for page, report, _ in QUOTED}
    assert {("docs/coco.md", "reports/coco/report.md"),
            ("docs/predict.md", "reports/coco/report.md"),
            ("docs/predict.md", "reports/validation/validation.md"),
            ("docs/validation.md", "reports/validation/validation.md"),
            ("reports/coco/README.md", "reports/coco/report.md")} <= pages, pages


@pytest.mark.parametrize("page,report,rows", QUOTED,
                         ids=[f"{p}<-{r}" for p, r, _ in QUOTED])
def test_a_quoted_table_is_the_reports_own(page, report, rows):
    """Header and rows are lines of the report as it stands (the separator line aside, whose
    alignment marks may differ), so every number in the quoted table is the report's."""
    assert rows, f"{page}: the table or list quoted from {report} has no lines"
    have = set((REPO / report).read_text(encoding="utf-8").split("\n"))
    stale = [r for r in rows if not SEPARATOR.fullmatch(r) and r not in have]
    assert not stale, (f"{page}: these lines of a table quoted from {report} are not in it "
                       "(rebuilt since?); copy them again:\n" + "\n".join(stale))


def test_quoted_tables_need_their_report_to_hold_the_row():
    """The check itself can fail: a row changed by one digit is not found."""
    text = "Numbers as in `reports/x.md`:\n\n| a | b |\n|---|---|\n| 1 | 2 |\n"
    (report, rows), = quoted_tables(text)
    assert report == "reports/x.md" and rows == ["| a | b |", "|---|---|", "| 1 | 2 |"]
    have = {"| a | b |", "| 1 | 3 |"}
    assert [r for r in rows if not SEPARATOR.fullmatch(r) and r not in have] \
        == ["| 1 | 2 |"]


def test_the_coco_c_readme_table_is_the_reports_json():
    """``reports/cococ/README.md`` restates each cell of ``cococ.json`` (rebuilt with the
    prediction tables by ``benchmarks/tools/after_resweep.py``): the same rows, in its order."""
    import json

    cells = json.loads((REPO / "reports/cococ/cococ.json").read_text())["cells"]
    text = (REPO / "reports/cococ/README.md").read_text(encoding="utf-8")
    rows = [line for line in text.split("\n") if re.match(r"\| [a-z]+ \| \d \|", line)]
    want = [cococ_readme_row(c) for c in cells]
    assert len(want) == 15
    assert rows == want, "reports/cococ/README.md: its table, as cococ.json gives it now:\n" \
        + "\n".join(want)


def _loss_allowed_at_default_limit() -> tuple[str, str]:
    """What ΔE00 3 allows by the shipped measured table: (% of baseline, points), as the docs
    round them."""
    from fidelity.prediction.table import predict
    from fidelity.prediction.verdict import DEFAULT_MAX_DELTA_E

    p = predict(DEFAULT_MAX_DELTA_E)
    assert p.dmap_relative is not None and p.dmap_points is not None
    return f"{p.dmap_relative:.2f} %", f"{p.dmap_points:.2f} points"


def test_the_default_limit_is_quoted_with_what_it_allows():
    """docs/check.md, the verdict module and ``check --help`` say what ΔE00 <= 3 allows, and
    the number is the shipped table's at ΔE 3, not the paper's "below 1 %"."""
    from click.testing import CliRunner

    from fidelity.cli import main

    relative, points = _loss_allowed_at_default_limit()
    check_md = (REPO / "docs/check.md").read_text(encoding="utf-8")
    assert f"up to {relative}" in check_md and f"({points})" in check_md
    assert "keeps ΔmAP below\n1 %" not in check_md and "keeps ΔmAP below 1 %" not in check_md
    verdict_py = (REPO / "fidelity/prediction/verdict.py").read_text(encoding="utf-8")
    assert f"up to {relative} of the baseline mAP ({points})" in verdict_py
    help_text = " ".join(CliRunner().invoke(main, ["check", "--help"]).output.split())
    assert f"allows up to {relative} of baseline" in help_text


def test_the_allowed_loss_is_the_sweeps_largest_cell_at_the_limit():
    """A second path to the same number: the largest relative loss of any measured cell (model,
    transform) at ΔE 3 in the sweep's own cells, ``reports/coco/tables.json``."""
    import json

    relative, _ = _loss_allowed_at_default_limit()
    cells = json.loads((REPO / "reports/coco/tables.json").read_text())["tables"]["cells"]
    at3 = [c["dmap_relative"] for rows in cells.values() for c in rows
           if c["status"] == "done" and c["delta_e"] == 3.0]
    assert len(at3) >= 20
    assert f"{max(at3):.2f} %" == relative


def _threshold_words(comparison: list[dict[str, str]]) -> str:
    """The "Thresholds" sentence of ``reports/coco/README.md`` as the sweep's comparison rows
    (``fidelity tables``' verdict on each of SAFE-COLOR's ΔE budgets) make it: the budgets that
    hold in points, the ones exceeded in points within or beyond 2 SE, and whether every one
    is exceeded as a share of the baseline."""
    rows = [c for c in comparison if re.match(r"ΔE ≤ \d+ keeps", c["claim"])]
    assert len(rows) == 3, [c["claim"] for c in comparison]

    def de(c: dict[str, str]) -> str:
        return "ΔE " + re.findall(r"ΔE ≤ (\d+)", c["claim"])[0]

    def joined(names: list[str]) -> str:
        return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]

    hold = [de(c) for c in rows if c["verdict"].startswith("agrees if read as points")]
    within = [de(c) for c in rows if "exceeded in points (within 2 SE)" in c["verdict"]]
    beyond = [de(c) for c in rows if "exceeded in points (beyond 2 SE)" in c["verdict"]]
    assert len(hold) + len(within) + len(beyond) == len(rows), [c["verdict"] for c in rows]
    parts = [f"the paper's {joined(hold)} budgets hold for every model"] if hold else []
    parts += [f"{joined(within)}'s is exceeded, within 2 SE"] if within else []
    parts += [f"{joined(beyond)}'s is exceeded beyond 2 SE"] if beyond else []
    share = all("as a share of baseline" in c["verdict"] for c in rows)
    return ("Read as points of mAP, " + " and ".join(parts) + "; read as a share of the "
            "baseline mAP, the paper's own unit, "
            + ("every threshold is exceeded." if share else "not every threshold is exceeded."))


def test_the_coco_readme_threshold_words_follow_the_sweeps_verdicts():
    """Issue 58 (stale words): the README's reading of SAFE-COLOR's thresholds is what the
    comparison rows of ``reports/coco/tables.json`` say (ΔE 12 was "at the edge" where its row
    says exceeded in points within 2 SE); a changed verdict changes the sentence wanted."""
    import json

    comparison = json.loads((REPO / "reports/coco/tables.json").read_text())["comparison"]
    readme = " ".join((REPO / "reports/coco/README.md").read_text(encoding="utf-8").split())
    want = _threshold_words(comparison)
    assert want in readme, f"reports/coco/README.md should read: {want}"
    moved = [dict(c) for c in comparison]
    for c in moved:
        if c["claim"].startswith("ΔE ≤ 12"):
            c["verdict"] = "agrees if read as points; exceeded as a share of baseline"
    assert "the paper's ΔE 3, ΔE 6 and ΔE 12 budgets hold for every model;" in \
        _threshold_words(moved)


def test_the_blur_noise_over_prediction_quoted_is_the_tables():
    """Issue 58 (stale words): docs/validation.md's over-prediction "for the blur-noise pairs"
    is the range of the quoted table's median over-prediction (ΔmAP in points) over the groups
    with both sharpness and noise (it said 2.5-2.6x where the rows read 2.64x and 2.56x)."""
    text = (REPO / "docs/validation.md").read_text(encoding="utf-8")
    ratios = [float(m.group(1)) for m in re.finditer(
        r"^\| ΔmAP \(points\) \| [a-z+]*sharpness\+noise \| (?:[^|]*\|){4} ([\d.]+)× ", text,
        flags=re.M)]
    assert len(ratios) == 2, ratios
    quoted = " ".join(text.split())
    assert f"for the blur-noise pairs ({min(ratios):.2f}-{max(ratios):.2f}x" in quoted


def test_the_coco_c_readme_names_the_standard_error_its_cells_carry():
    """Issue 58 (stale words): ``reports/cococ/README.md`` says which standard error its ±
    are, as every measurement of ``cococ.json`` records it (it said "the paired standard
    error of 5 image folds", the rule before the bootstrap, under cells measured with the
    larger of the bootstrap and the jackknife)."""
    import json

    cells = json.loads((REPO / "reports/cococ/cococ.json").read_text())["cells"]
    methods = {m["settings"]["standard_error"]["method"] for c in cells for m in c["measured"]}
    folds = {m["settings"]["folds"] for c in cells for m in c["measured"]}
    words = {"larger": "the larger of the paired image bootstrap and the leave-one-fold-out "
                       "jackknife over {folds} image folds, every cell's"}
    assert len(methods) == 1 and len(folds) == 1, (methods, folds)
    method, = methods
    text = " ".join((REPO / "reports/cococ/README.md").read_text(encoding="utf-8").split())
    assert method in words, f"say in reports/cococ/README.md what the SE {method!r} is"
    assert "± one standard error (" + words[method].format(folds=folds.pop()) + ")" in text
    assert "paired standard error of 5 image folds" not in text
