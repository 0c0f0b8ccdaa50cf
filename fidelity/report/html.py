"""Write a :class:`~fidelity.report.document.Document` as HTML (one page layout) or Markdown.

HTML is self-contained: figures are inlined SVG or embedded as base64 PNG, prose is Markdown rendered by
markdown-it-py (CommonMark, HTML in the source escaped), every other string is HTML-escaped
(:func:`markupsafe.escape`). The page is put together here in Python (:func:`render_html`), the
same page, byte for byte, that the former Jinja2 template ``report.html.j2`` made (a test
renders both): Jinja2's import alone cost a chart check about 40 ms. Markdown is written from
the same document; its figures are files next to it (:func:`write_document`).
"""

from __future__ import annotations

import base64
import os
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.core.fileio import write_bytes_atomic, write_text_atomic
from fidelity.core.version import __version__
from fidelity.report.document import Code, Document, Facts, Figure, Table, Text

if TYPE_CHECKING:
    from markupsafe import Markup


@lru_cache(maxsize=1)
def _markdown() -> Any:
    from markdown_it import MarkdownIt

    # CommonMark with tables; raw HTML in the source is escaped, not passed through
    return MarkdownIt("commonmark", {"html": False}).enable("table")


def markdown_to_html(text: str) -> Markup:
    """Markdown prose as safe HTML (block level: paragraphs, lists, tables)."""
    from markupsafe import Markup

    return Markup(_markdown().render(text))


#: The characters markdown-it's inline rules of the CommonMark preset start at (a backslash
#: escape, code, emphasis, a link or image, an autolink or raw HTML, an entity, a line break;
#: ``~`` of strikethrough, off there, kept to be safe) and those its normalisation changes
#: (CR, NUL). A line with none of them is plain text: :func:`markdown_inline` HTML-escapes it
#: as markdown-it would, without its parser (most of a report's table cells; a test checks
#: the two agree).
INLINE_SYNTAX = frozenset("\\`*_[]!<&~\n\r\0")


def markdown_inline(text: str) -> Markup:
    """Markdown of one line (emphasis, code, links) as safe HTML, without a paragraph."""
    from markupsafe import Markup

    line = str(text)
    if INLINE_SYNTAX.isdisjoint(line):  # plain text: markdown-it's escapeHtml of it
        return Markup(line.replace(">", "&gt;").replace('"', "&quot;"))
    return Markup(_markdown().renderInline(line))


def _escape(value: object) -> str:
    """``value`` as HTML text (``&<>"'`` escaped), as Jinja2's autoescape wrote it: a value
    that is already HTML (``__html__``, a :class:`markupsafe.Markup`) as it is."""
    from markupsafe import escape

    return str(escape(value))


def _figure(f: Figure) -> str:
    body = f.svg if f.svg else (f'<img alt="{_escape(f.alt)}" src="data:image/png;base64,'
                                f'{base64.b64encode(f.png).decode("ascii")}">')
    caption = f"<figcaption>{markdown_inline(f.caption)}</figcaption>" if f.caption else ""
    return f"\n<figure>{body}{caption}</figure>"


#: The class of a numeric column's cells.
_NUM = ' class="num"'


def _cells(tag: str, cells: tuple[str, ...], align: tuple[bool, ...], html: bool) -> str:
    return "".join(f"<{tag}{_NUM if align[i] else ''}>"
                   f"{markdown_inline(c) if html else _escape(c)}</{tag}>"
                   for i, c in enumerate(cells))


def _block(b: object) -> str:
    if isinstance(b, Text):
        return f"\n{markdown_to_html(b.markdown)}"
    if isinstance(b, Figure):
        return f"\n{_figure(b)}"
    if isinstance(b, Facts):
        rows = "".join(f"\n<tr><th>{_escape(label)}</th><td>{markdown_inline(value)}</td></tr>"
                       for label, value in b.items)
        return f'\n<div class="table-wrap"><table class="facts">{rows}\n</table></div>'
    if isinstance(b, Table):
        align = b.alignment()
        caption = f"<caption>{markdown_inline(b.caption)}</caption>" if b.caption else ""
        rows = "".join(f"\n<tr>{_cells('td', row, align, True)}</tr>" for row in b.rows)
        return (f'\n<div class="table-wrap"><table>{caption}\n<thead><tr>'
                f"{_cells('th', b.header, align, False)}</tr></thead>\n<tbody>{rows}"
                "\n</tbody></table></div>")
    if isinstance(b, Code):
        return f"\n<pre><code>{_escape(b.text)}</code></pre>"
    return ""


#: The page's style sheet (every report's).
_STYLE = """:root{--fg:#1d232b;--muted:#5b6572;--line:#dde2e8;--bg-soft:#f5f7f9;--accent:#2456a6}
*{box-sizing:border-box}
body{font-family:system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;color:var(--fg);
max-width:1120px;margin:0 auto;padding:1.5em 1.2em 3em;line-height:1.45}
header.top{display:flex;justify-content:space-between;align-items:baseline;gap:1em;
border-bottom:2px solid var(--line);margin-bottom:1em}
header.top h1{font-size:1.45em;margin:.2em 0}
header.top .brand{color:var(--muted);font-size:.85em;white-space:nowrap}
.subtitle{color:var(--muted);margin:.2em 0 1em}
.headline{padding:.9em 1.1em;border-radius:8px;font-size:1.08em;font-weight:600;margin:.6em 0 1em}
.headline p{margin:.2em 0}
.tone-pass{background:#e3f5e1;color:#1d5e1a;border:1px solid #b9e2b4}
.tone-fail{background:#fbe3e1;color:#8a1c12;border:1px solid #f0b9b2}
.tone-info{background:#eef2fb;color:#1f3a73;border:1px solid #c9d5f0}
.tone-outside{background:#fdf0d5;color:#6b4300;border:1px solid #eccb85}
h2{font-size:1.18em;margin:1.6em 0 .5em;padding-bottom:.2em;border-bottom:1px solid var(--line)}
h3{font-size:1.02em;margin:1.2em 0 .4em}
details{margin:1.2em 0;border:1px solid var(--line);border-radius:6px;padding:.3em .9em}
details>summary{cursor:pointer;font-weight:600;padding:.35em 0;color:var(--accent)}
details[open]>summary{border-bottom:1px solid var(--line);margin-bottom:.6em}
figure{margin:.8em 0}
figure img,figure>svg{max-width:100%;height:auto;border:1px solid var(--line);border-radius:4px;background:#fff}
figure>svg{display:block}
figcaption{color:var(--muted);font-size:.85em;margin-top:.3em}
section.gallery{display:flex;flex-wrap:wrap;gap:0 1em;align-items:flex-start}
section.gallery>h2,section.gallery>h3{flex:0 0 100%}
section.gallery>figure{flex:1 1 420px;margin:.4em 0}
.table-wrap{overflow-x:auto;margin:.6em 0}
table{border-collapse:collapse;font-size:.84em;font-variant-numeric:tabular-nums}
caption{caption-side:top;text-align:left;color:var(--muted);padding:.2em 0}
td,th{border:1px solid var(--line);padding:3px 8px;text-align:left;vertical-align:top}
th{background:var(--bg-soft)}
td.num,th.num{text-align:right}
table.facts th{width:1%;white-space:nowrap}
pre{background:var(--bg-soft);padding:.8em;overflow-x:auto;font-size:.78em;border-radius:4px}
code{background:var(--bg-soft);padding:0 .25em;border-radius:3px;font-size:.92em}
footer{margin-top:2.5em;color:var(--muted);font-size:.82em;border-top:1px solid var(--line);padding-top:.6em}
"""


def render_html(doc: Document) -> str:
    """The self-contained HTML page of ``doc``.

    Parameters
    ----------
    doc
        The report document.

    Returns
    -------
    str
        The page: head and style, the title, the subtitle, the headline and its figure, the
        sections (folded ones as ``<details>``) and the footer; prose as Markdown rendered by
        markdown-it-py, every other string HTML-escaped, figures inlined.
    """
    version = _escape(__version__)
    title = _escape(doc.title)
    out = ['\n<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
           '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
           f'<meta name="generator" content="fidelity {version}">\n<title>{title}</title>\n'
           f"<style>\n{_STYLE}</style>\n</head>\n<body>\n"
           f'<header class="top"><h1>{title}</h1><span class="brand">fidelity {version}'
           "</span></header>"]
    if doc.subtitle:
        out.append(f'\n<div class="subtitle">{markdown_to_html(doc.subtitle)}</div>')
    out.append(f'\n<div class="headline tone-{_escape(doc.headline.tone)}">'
               f"{markdown_to_html(doc.headline.message)}</div>")
    if doc.headline.figure:
        out.append(f"\n{_figure(doc.headline.figure)}")
    for s in doc.sections:
        blocks = "".join(_block(b) for b in s.blocks)
        if s.folded:
            out.append(f"\n<details><summary>{_escape(s.title)}</summary>{blocks}\n</details>")
        else:
            level = _escape(s.level)
            gallery = ' class="gallery"' if s.gallery else ""
            out.append(f"\n<section{gallery}>\n<h{level}>{_escape(s.title)}</h{level}>{blocks}"
                       "\n</section>")
    if doc.footer:
        out.append(f"\n<footer>{markdown_to_html(doc.footer)}</footer>")
    out.append("\n</body>\n</html>\n")
    return "".join(out)


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def render_markdown(doc: Document) -> str:
    """``doc`` as Markdown: figures as image links to their ``name`` (see :func:`write_document`),
    folded sections written out like the others."""
    out = [f"# {doc.title}", ""]
    if doc.subtitle:
        out += [doc.subtitle, ""]
    out += ["> " + line for line in doc.headline.message.splitlines()] + [""]
    if doc.headline.figure:
        out += [f"![{doc.headline.figure.alt}]({doc.headline.figure.name})", ""]
    for s in doc.sections:
        out += ["#" * s.level + f" {s.title}", ""]
        for b in s.blocks:
            if isinstance(b, Text):
                out += [b.markdown.rstrip(), ""]
            elif isinstance(b, Figure):
                out += [f"![{b.alt}]({b.name})", ""]
                if b.caption:
                    out += [f"*{b.caption}*", ""]
            elif isinstance(b, Facts):
                out += ["| | |", "|---|---|"]
                out += [f"| {_md_cell(k)} | {_md_cell(v)} |" for k, v in b.items]
                out += [""]
            elif isinstance(b, Table):
                if b.caption:
                    out += [b.caption, ""]
                align = b.alignment()
                out += ["| " + " | ".join(_md_cell(h) for h in b.header) + " |",
                        "|" + "|".join("---:" if a else "---" for a in align) + "|"]
                out += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in b.rows]
                out += [""]
            elif isinstance(b, Code):
                out += [f"```{b.language}", b.text.rstrip(), "```", ""]
    if doc.footer:
        out += [doc.footer, ""]
    return "\n".join(out).rstrip() + "\n"


def write_document(doc: Document, *, html: str | os.PathLike[str] | None = None,
                   markdown: str | os.PathLike[str] | None = None) -> list[Path]:
    """Write ``doc`` as HTML and/or Markdown, atomically; with Markdown, every figure is
    written as a PNG or SVG file next to it (under its ``name``). Returns the paths written."""
    written: list[Path] = []
    if markdown is not None:
        md_path = Path(markdown)
        for f in doc.figures():
            written.append(write_bytes_atomic(md_path.parent / f.name, f.data))
        written.append(write_text_atomic(md_path, render_markdown(doc)))
    if html is not None:
        written.append(write_text_atomic(html, render_html(doc)))
    return written


__all__ = [
    "INLINE_SYNTAX",
    "markdown_inline",
    "markdown_to_html",
    "render_html",
    "render_markdown",
    "write_document",
]
