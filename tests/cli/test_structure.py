"""The command line's place in the package: the library never imports it, and its modules
share only public names."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from click.testing import CliRunner

import fidelity
from fidelity.cli import COMMANDS, main

PACKAGE = Path(fidelity.__file__).parent


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names) of every import in ``path``, at module level or inside functions."""
    found: list[tuple[str, list[str]]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            found += [(a.name, []) for a in node.names]
    return found


def test_the_library_never_imports_the_command_line():
    cli = PACKAGE / "cli"
    offenders = [f"{p.relative_to(PACKAGE)}: {module}"
                 for p in sorted(PACKAGE.rglob("*.py"))
                 if cli not in p.parents and p.name != "__main__.py"
                 for module, _ in _imports(p)
                 if module == "fidelity.cli" or module.startswith("fidelity.cli.")]
    assert offenders == []


def test_command_modules_import_no_private_name():
    offenders = [f"{p.name}: {module}.{name}"
                 for p in sorted((PACKAGE / "cli").glob("*.py"))
                 for module, names in _imports(p) if module.startswith("fidelity")
                 for name in names if name.startswith("_") and not name.startswith("__")]
    assert offenders == []


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_prints_its_help(name):
    r = CliRunner().invoke(main, [name, "--help"])
    assert r.exit_code == 0 and "--quiet" in r.output, r.output
    assert "%%" not in r.output  # click prints help as written: no printf escapes
