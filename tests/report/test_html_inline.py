"""The plain-text path of :func:`fidelity.report.html.markdown_inline` (issue 59): a line
without any of :data:`~fidelity.report.html.INLINE_SYNTAX` is written as markdown-it writes it,
without its parser."""

from __future__ import annotations

import random

import pytest

from fidelity.report.html import INLINE_SYNTAX, _markdown, markdown_inline

#: Lines as a report's table cells hold them, and lines at the edges of the plain-text path.
LINES = [
    "", " ", "  two spaces  ", "\t tab", "ΔE00 1.02 ± 0.024 (k=1)", "1. not a list", "# no heading",
    "- no item", "> no quote", "a > b", 'say "this"', "it's", "x = y + z - w", "50 %", "a/b",
    "#1", "a: b; c", "x^2", "{braces}", "@user", "$5", "http://example.com", "www.example.com",
    "a.b.c", "--", "---", "1) x", "    four spaces", "|a|b|", "a|b", "=", "+ x",
    "-0.36", "√2 ≥ 1", "e\u0301", "\u00a0nbsp", "trailing \t",
]


def _real(line: str) -> str:
    return str(_markdown().renderInline(line))


@pytest.mark.parametrize("line", LINES)
def test_plain_lines_render_as_markdown_it_does(line: str) -> None:
    assert INLINE_SYNTAX.isdisjoint(line)
    assert str(markdown_inline(line)) == _real(line)


def test_random_lines_render_as_markdown_it_does() -> None:
    rng = random.Random(59)
    alphabet = "ab 1.-+#>|:=()'\"%/$^{}@\t" + "".join(sorted(INLINE_SYNTAX))
    for _ in range(3000):
        line = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 12)))
        assert str(markdown_inline(line)) == _real(line), repr(line)


def test_markdown_lines_still_go_through_markdown_it() -> None:
    assert str(markdown_inline("a\\* b")) == "a* b"
    assert str(markdown_inline("**no**")) == "<strong>no</strong>"
    assert str(markdown_inline("`code` & <b>")) == "<code>code</code> &amp; &lt;b&gt;"
