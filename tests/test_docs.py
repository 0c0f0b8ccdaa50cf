"""The documentation site builds without a warning, and documents every library module."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _missing_docs_packages() -> list[str]:
    return [name for name in ("sphinx", "myst_parser", "furo")
            if importlib.util.find_spec(name) is None]


def test_every_library_module_has_an_api_page():
    """Each module under fidelity/ (the CLI aside) is named by one ``automodule`` directive."""
    documented: list[str] = []
    for page in sorted((DOCS / "api").glob("*.rst")) + [DOCS / "api.md"]:
        documented += re.findall(r"^\.\. automodule:: (\S+)", page.read_text(encoding="utf-8"),
                                 re.M)
    modules = set()
    for path in (ROOT / "fidelity").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        name = ".".join(parts)
        if name.startswith("fidelity.cli") or name == "fidelity.__main__":
            continue
        modules.add(name)
    assert sorted(modules - set(documented)) == [], "add these modules to a page in docs/api/"
    assert len(documented) == len(set(documented)), "a module is documented twice"


def test_readme_is_short_and_links_existing_pages():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.encode("utf-8")) < 8 * 1024
    links = re.findall(r"\]\((docs/[^)#]+)", readme)
    assert links
    for link in links:
        assert (ROOT / link).is_file(), link


@pytest.mark.skipif(bool(_missing_docs_packages()),
                    reason="the docs extra is not installed (pip install -e '.[docs]'): "
                           f"missing {', '.join(_missing_docs_packages())}")
@pytest.mark.skipif(os.environ.get("FIDELITY_DOCS_BUILT_WITH_WARNINGS_AS_ERRORS") == "1",
                    reason=".ci/run built the documentation with warnings as errors (the HTML "
                           "builder) before the suite: the same check, not run twice")
def test_docs_build_without_warnings(tmp_path):
    """Sphinx with warnings as errors: bad reStructuredText in a docstring, a module that does
    not import, a page outside the table of contents or a link to a missing heading fail."""
    r = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "dummy",
         str(DOCS), str(tmp_path / "build")],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    assert r.returncode == 0, r.stderr[-4000:]


def _option_defaults() -> dict[str, set[str]]:
    """Each long option of every command (subcommands included) -> the defaults it has."""
    import click

    from fidelity.cli import main

    found: dict[str, set[str]] = {}
    ctx = click.Context(main)

    def walk(cmd: click.Command | None) -> None:
        assert cmd is not None
        for param in cmd.params:
            if isinstance(param, click.Option) and param.default is not None:
                for opt in param.opts:
                    found.setdefault(opt, set()).add(str(param.default))
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name))

    walk(main)
    assert "--reference" in found
    return found


def test_defaults_stated_in_the_docs_are_the_commands_defaults():
    """"`--opt VALUE` (default)" or "`--opt VALUE`, the default" in a page names the default
    of every command that has the option (issue 57: audit.md named safecolor, the CLI scene)."""
    defaults = _option_defaults()
    stated = re.compile(r"`(--[a-z][a-z-]*) ([^`\s]+)`(?: \(default\)|, the default)")
    claims = [(page.name, m.group(1), m.group(2))
              for page in sorted(DOCS.glob("*.md")) + [ROOT / "README.md"]
              for m in stated.finditer(page.read_text(encoding="utf-8"))]
    assert len(claims) >= 2  # audit.md and check.md state --reference's
    wrong = [(page, opt, value, sorted(defaults.get(opt, set())))
             for page, opt, value in claims if defaults.get(opt) != {value}]
    assert wrong == [], "a page states a default the commands do not have"
