"""The report document: what every report says, before it is HTML or Markdown.

Every report of the project (a chart check, the COCO benchmark tables, the validation of the
camera suite, the render benchmark) is built as one :class:`Document` from its data and then
written both ways by :mod:`fidelity.report.html`: HTML for people (one page layout, plots
embedded, the headline and the verdict first, details folded away) and Markdown from the same
document. A document is a title, a :class:`Headline` (the verdict or the main finding, with an
optional headline figure) and :class:`Section` objects holding blocks:

- :class:`Text`: Markdown prose (inline emphasis, code, links, lists);
- :class:`Table`: a header and rows of cells (strings, already formatted);
- :class:`Figure`: a PNG (bytes) or an SVG (text) with a caption; embedded in HTML, a file
  link in Markdown;
- :class:`Facts`: label/value pairs (a summary table);
- :class:`Code`: preformatted text (JSON provenance).

A section with ``folded=True`` is collapsed in HTML (``<details>``); Markdown shows it all.
"""

from __future__ import annotations

import html
import re
from collections.abc import Sequence
from typing import Literal

from fidelity.core.record import record

#: Look of a headline: a pass, a fail, information without a verdict, or a pass outside the
#: validity domain of its evidence (amber, not a plain green pass).
Tone = Literal["pass", "fail", "info", "outside"]


@record
class Text:
    """Markdown prose (one or more paragraphs, lists allowed)."""

    markdown: str


@record
class Table:
    """A table of formatted cells: ``header`` (n,, plain text) and ``rows`` (m, n; Markdown);
    ``numeric`` marks the columns to right-align (default: every column but the first)."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    numeric: tuple[bool, ...] | None = None

    def alignment(self) -> tuple[bool, ...]:
        """Per column: True to right-align (numbers)."""
        if self.numeric is not None:
            return self.numeric
        return tuple(i > 0 for i in range(len(self.header)))


@record
class Figure:
    """A figure: ``png`` bytes or ``svg`` text (an ``<svg>`` element, inlined in HTML), its
    ``name`` (its file name when written next to Markdown), ``alt`` text and a ``caption``."""

    png: bytes
    name: str
    alt: str
    caption: str = ""
    svg: str = ""

    @property
    def data(self) -> bytes:
        """The figure's file content: the SVG text (UTF-8) if it has one, else the PNG."""
        return self.svg.encode("utf-8") if self.svg else self.png


def svg_figure(svg: str, name: str, alt: str, caption: str = "") -> Figure:
    """A :class:`Figure` of SVG text (``name`` ends in ``.svg``); the ``<svg>`` element's
    accessible name (``role="img" aria-label``) becomes ``alt``."""
    head, sep, rest = svg.partition(">")
    if not sep or not head.startswith("<svg"):
        raise ValueError("svg_figure needs the text of an <svg> element")
    head = re.sub(r'\s(role|aria-label)="[^"]*"', "", head)
    svg = f"{head} role=\"img\" aria-label=\"{html.escape(alt)}\">{rest}"
    return Figure(b"", name, alt, caption, svg=svg)


@record
class Facts:
    """Label/value pairs shown as a two-column summary (labels plain text, values Markdown)."""

    items: tuple[tuple[str, str], ...]


@record
class Code:
    """Preformatted text (JSON, a command line), shown as it is."""

    text: str
    language: str = ""


Block = Text | Table | Figure | Facts | Code


@record
class Section:
    """A titled part of a report; ``folded`` sections are collapsed in HTML; a ``gallery``
    shows its figures side by side where the page is wide enough."""

    title: str
    blocks: tuple[Block, ...]
    folded: bool = False
    level: int = 2
    gallery: bool = False


@record
class Headline:
    """What a reader must see first: ``message`` (Markdown), its ``tone`` and an optional
    headline ``figure``."""

    message: str
    tone: Tone = "info"
    figure: Figure | None = None


@record
class Document:
    """A whole report: ``title``, an optional ``subtitle`` (Markdown), the :class:`Headline`,
    its :class:`Section` objects in reading order and a ``footer`` (Markdown)."""

    title: str
    headline: Headline
    sections: tuple[Section, ...] = ()
    subtitle: str = ""
    footer: str = ""

    def figures(self) -> list[Figure]:
        """Every figure of the document, headline first, in reading order."""
        out = [self.headline.figure] if self.headline.figure else []
        for s in self.sections:
            out += [b for b in s.blocks if isinstance(b, Figure)]
        return out


def section(title: str, *blocks: Block | None, folded: bool = False, level: int = 2,
            gallery: bool = False) -> Section:
    """A :class:`Section` of the blocks that are not ``None`` (optional parts drop out)."""
    return Section(title, tuple(b for b in blocks if b is not None), folded=folded, level=level,
                   gallery=gallery)


def table(header: Sequence[str], rows: Sequence[Sequence[str]], caption: str = "",
          numeric: Sequence[bool] | None = None) -> Table:
    """A :class:`Table` from any sequences (checks that every row has the header's width)."""
    head = tuple(header)
    body = tuple(tuple(r) for r in rows)
    for i, r in enumerate(body):
        if len(r) != len(head):
            raise ValueError(f"table row {i} has {len(r)} cells, the header {len(head)}")
    return Table(head, body, caption, tuple(numeric) if numeric is not None else None)


__all__ = [
    "Block",
    "Code",
    "Document",
    "Facts",
    "Figure",
    "Headline",
    "Section",
    "Table",
    "Text",
    "Tone",
    "section",
    "svg_figure",
    "table",
]

