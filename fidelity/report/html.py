"""Write a :class:`~fidelity.report.document.Document` as HTML (one Jinja2 template) or Markdown.

HTML is self-contained: figures are inlined SVG or embedded as base64 PNG, prose is Markdown rendered by
markdown-it-py (CommonMark, HTML in the source escaped), every other string is escaped by
Jinja2's autoescape. Markdown is written from the same document; its figures are files next to
it (:func:`write_document`).
"""

from __future__ import annotations

import base64
import contextlib
import os
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.core.fileio import write_bytes_atomic, write_text_atomic
from fidelity.core.version import __version__
from fidelity.report.document import Code, Document, Facts, Figure, Table, Text

if TYPE_CHECKING:
    import jinja2
    from markupsafe import Markup

#: The template every HTML report is rendered with (``fidelity/report/templates``).
TEMPLATE = "report.html.j2"

_KINDS: dict[str, type] = {"Text": Text, "Table": Table, "Figure": Figure, "Facts": Facts,
                           "Code": Code}


@lru_cache(maxsize=1)
def _markdown() -> Any:
    from markdown_it import MarkdownIt

    # CommonMark with tables; raw HTML in the source is escaped, not passed through
    return MarkdownIt("commonmark", {"html": False}).enable("table")


def _markup(text: str) -> Markup:
    from markupsafe import Markup

    return Markup(text)


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


@lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """The Jinja2 environment of the report templates (autoescape on, strict undefined)."""
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("fidelity.report", "templates"),
        autoescape=True, undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
        bytecode_cache=_bytecode_cache(),
    )
    env.filters["markdown"] = markdown_to_html
    env.filters["markdown_inline"] = markdown_inline
    env.filters["b64"] = lambda data: base64.b64encode(data).decode("ascii")
    # SVG made by fidelity.report.svg (its text escaped there), inlined as it is
    env.filters["svg"] = lambda text: _markup(text)
    env.tests["kind"] = lambda obj, name: isinstance(obj, _KINDS[name])
    return env


def _bytecode_cache() -> Any:
    """Jinja2's cache of compiled templates in ``$FIDELITY_CACHE/jinja2`` (default
    ``~/.cache/fidelity``): compiling the report template costs about 0.1 s of every report;
    checked against the template's modification time by Jinja2. None where no such folder can
    be made (the template is then compiled each time)."""
    import jinja2

    base = Path(os.environ.get("FIDELITY_CACHE") or Path.home() / ".cache" / "fidelity")
    folder = base / "jinja2"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if not os.access(folder, os.W_OK):
        return None

    class _QuietCache(jinja2.FileSystemBytecodeCache):
        """A cache that never fails a report: a template that cannot be stored (a full disk,
        a file-size limit) is compiled again next time."""

        def dump_bytecode(self, bucket: Any) -> None:
            with contextlib.suppress(OSError):
                super().dump_bytecode(bucket)

        def load_bytecode(self, bucket: Any) -> None:
            with contextlib.suppress(OSError):
                super().load_bytecode(bucket)

    return _QuietCache(str(folder))


def render_html(doc: Document) -> str:
    """The self-contained HTML page of ``doc``."""
    return environment().get_template(TEMPLATE).render(doc=doc, version=__version__)


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
    "TEMPLATE",
    "environment",
    "markdown_inline",
    "markdown_to_html",
    "render_html",
    "render_markdown",
    "write_document",
]
