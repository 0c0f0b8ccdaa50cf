"""fidelity.report.html's page: the same HTML, byte for byte, as the Jinja2 template it
replaced (``tests/report/data/report.html.j2``, kept here as the reference), for every kind of
block, folded and gallery sections, escaping, and a real chart check."""

from __future__ import annotations

import base64
from pathlib import Path

import pytest

from fidelity.core.version import __version__
from fidelity.report import html
from fidelity.report.document import (
    Code,
    Document,
    Facts,
    Figure,
    Headline,
    Section,
    Table,
    Text,
)

jinja2 = pytest.importorskip("jinja2")
from markupsafe import Markup  # noqa: E402  (after the skip: Jinja2's own dependency)

DATA = Path(__file__).resolve().parent / "data"
KINDS = {"Text": Text, "Table": Table, "Figure": Figure, "Facts": Facts, "Code": Code}


def _jinja(doc: Document) -> str:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(DATA)), autoescape=True,
                             undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
    env.filters["markdown"] = html.markdown_to_html
    env.filters["markdown_inline"] = html.markdown_inline
    env.filters["b64"] = lambda data: base64.b64encode(data).decode("ascii")
    env.filters["svg"] = Markup
    env.tests["kind"] = lambda obj, name: isinstance(obj, KINDS[name])
    return env.get_template("report.html.j2").render(doc=doc, version=__version__)


PNG = b"\x89PNG\r\n\x1a\nnot really"
SVG = '<svg xmlns="http://www.w3.org/2000/svg" aria-label="a &amp; b"><rect/></svg>'
TRICKY = "a <b> & \"c\" 'd' **e** `f` x_y"


def _documents() -> list[Document]:
    blocks = (
        Text("Prose with **bold**, `code` and a list:\n\n- one\n- two <3"),
        Figure(PNG, "f.png", "alt \"text\" <here>", caption="caption *em* & more"),
        Figure(PNG, "g.svg", "an svg", svg=SVG),
        Facts((("label <1>", "value `v`"), ("plain", "a > b \"q\""))),
        Table(("h<1>", "h2", "h3"), (("a", "1.0", "*x*"), ("b", "2 & 3", "<y>"))),
        Table(("name", "value"), (("p", "q"),), caption="the caption", numeric=(False, True)),
        Table(("only",), ()),
        Code('{"json": "<&>"}\n', "json"),
    )
    return [
        Document("Minimal", Headline("one line")),
        Document(TRICKY, Headline(TRICKY, tone="fail",
                                  figure=Figure(PNG, "h.png", TRICKY, caption=TRICKY)),
                 sections=(Section("Open <s>", blocks),
                           Section("Folded & closed", blocks, folded=True),
                           Section("Gallery", blocks[1:3], gallery=True, level=3),
                           Section("Empty", ())),
                 subtitle="sub *title*", footer="footer `code`\n\nsecond paragraph"),
        Document("Tones", Headline("**PASS**: fine", tone="pass"),
                 sections=(Section("s", (Text(""),)),), footer=""),
        Document("Outside", Headline("- a\n- b", tone="outside"), subtitle=TRICKY),
    ]


@pytest.mark.parametrize("doc", _documents(), ids=lambda d: d.title[:12])
def test_page_as_the_jinja2_template(doc: Document) -> None:
    assert html.render_html(doc) == _jinja(doc)


def test_chart_check_page_as_the_jinja2_template() -> None:
    from fidelity.pipeline.check import check_camera
    from fidelity.report.chart import chart_document

    doc = chart_document(check_camera())
    assert html.render_html(doc) == _jinja(doc)


def test_page_imports_no_jinja2() -> None:
    import subprocess
    import sys

    code = ("import sys\n"
            "from fidelity.report.document import Document, Headline\n"
            "from fidelity.report.html import render_html\n"
            "render_html(Document('t', Headline('**m**')))\n"
            "print('jinja2' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
