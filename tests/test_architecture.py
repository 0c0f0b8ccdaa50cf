"""The package's import graph: layered, acyclic, no private name used across modules (issue 33).

Every ``import`` and ``from ... import`` of ``fidelity/`` is read from the source (module level,
inside functions and under ``TYPE_CHECKING`` alike: an import hidden in a function still ties
two modules together). The layers, lowest first, are the ones docs/development.md names:

0. ``core``: errors, version, resources, file I/O, schemas, settings
1. ``colour``: colorimetry, spectral data, the reference charts
2. ``chart``: reading images and recordings, finding and locating the chart
3. ``measure``: one module per camera property measured on a located chart
4. ``camera`` (camera models and the chart's render), ``correction`` (colour corrections)
5. ``prediction``, ``scene`` (the chart scene for simulators: colour + camera data)
6. ``coco``: the COCO benchmark behind the prediction tables
7. ``pipeline``: check, audit and gate, compare, fit, qualify and their records
8. ``report``: renders records (terminal, HTML, JSON, evidence formats)
9. the edges: ``cli``, ``pytest_plugin``, ``__main__`` and the package itself (its lazy
   public API)

A module may import its own layer and the ones below; a cycle is an error at any layer.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "fidelity"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("fidelity.core",),
    ("fidelity.colour",),
    ("fidelity.chart",),
    ("fidelity.measure",),
    ("fidelity.camera", "fidelity.correction"),
    ("fidelity.prediction", "fidelity.scene"),
    ("fidelity.coco",),
    ("fidelity.pipeline",),
    ("fidelity.report",),
    ("fidelity.cli", "fidelity.pytest_plugin", "fidelity.__main__", "fidelity"),
)


def modules(root: Path = PACKAGE) -> dict[str, Path]:
    """Module name -> file, for every ``.py`` file of the package."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def imports(root: Path = PACKAGE) -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    """The import graph (module -> the package's modules it imports) and each private name
    imported from another module (importer, module, name)."""
    mods = modules(root)
    graph: dict[str, set[str]] = defaultdict(set)
    private: list[tuple[str, str, str]] = []
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, *([base] if base else [])])
                targets = [(base, a.name) for a in node.names]
            else:
                continue
            for module, member in targets:
                if not module.startswith("fidelity"):
                    continue
                full = f"{module}.{member}" if member else module
                target = full if full in mods else module
                if target != name:
                    graph[name].add(target)
                if (member and member.startswith("_") and not member.startswith("__")
                        and target != name):
                    private.append((name, target, member))
    return graph, private


def layer(module: str) -> int:
    """The layer of a module: that of the longest package prefix in :data:`LAYERS`."""
    best, length = -1, -1
    for i, names in enumerate(LAYERS):
        for prefix in names:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > length:
                best, length = i, len(prefix)
    return best


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


@pytest.fixture(scope="module")
def graph() -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    return imports()


def test_every_module_has_a_layer() -> None:
    assert [m for m in modules() if layer(m) < 0] == []


def test_no_import_cycle(graph) -> None:
    assert cycles(graph[0]) == []


def test_no_lower_layer_imports_a_higher_one(graph) -> None:
    upward = [f"{m} (layer {layer(m)}) imports {t} (layer {layer(t)})"
              for m, targets in sorted(graph[0].items()) for t in sorted(targets)
              if layer(t) > layer(m)]
    assert upward == []


def test_no_private_name_crosses_modules(graph) -> None:
    assert graph[1] == []


def test_the_checks_find_what_they_look_for(tmp_path) -> None:
    """The walker sees imports inside functions, relative imports and private names, and the
    cycle finder finds a two-module cycle: the checks above can fail."""
    pkg = tmp_path / "fidelity"
    (pkg / "colour").mkdir(parents=True)
    (pkg / "core").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "colour" / "__init__.py").write_text("")
    (pkg / "core" / "__init__.py").write_text("")
    (pkg / "core" / "errors.py").write_text("def f():\n    from fidelity.colour.a import _hidden\n")
    (pkg / "colour" / "a.py").write_text("from ..core.errors import f\n_hidden = 1\n")
    g, private = imports(pkg)
    assert g["fidelity.core.errors"] == {"fidelity.colour.a"}
    assert g["fidelity.colour.a"] == {"fidelity.core.errors"}
    assert private == [("fidelity.core.errors", "fidelity.colour.a", "_hidden")]
    assert cycles(g) == [["fidelity.colour.a", "fidelity.core.errors"]]
    assert layer("fidelity.core.errors") < layer("fidelity.colour.a")


#: The package's own modules a module may import inside a function (marked ``noqa: PLC0415``), and
#: the folder whose modules import them at module level: the COCO benchmark, which a check or
#: an audit loads only with ``--measure``, the chart finder, which only an image whose chart is
#: found or checked loads, the evidence formats that need an extra, and what ``check`` loads
#: only for an option (issue 59): the suite runner and the qualification run
#: (``fidelity.cli.suite``: a suite file, ``--context``), the record writers
#: (``fidelity.report.evidence``: ``--evidence``). The
#: third-party modules imported at the call are ruff's ``banned-module-level-imports``
#: (pyproject.toml); everything else is imported at module level (ruff's PLC0415).
DEFERRED = {"fidelity.coco": "fidelity.coco", "fidelity.chart.find": "fidelity.chart.find",
            "fidelity.report.ssp": "fidelity.report.ssp",
            "fidelity.report.xqar": "fidelity.report.xqar",
            "fidelity.camera.mitsuba": "fidelity.camera.mitsuba",
            "fidelity.cli.suite": "fidelity.cli.suite",
            "fidelity.report.evidence": "fidelity.report.evidence"}


def deferred_imports(root: Path = PACKAGE) -> list[tuple[str, int, str]]:
    """(module, line, imported module) of every import marked ``noqa: PLC0415``."""
    found = []
    for name, path in modules(root).items():
        lines = path.read_text(encoding="utf-8").splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if isinstance(node, ast.Import | ast.ImportFrom) and "noqa: PLC0415" in lines[
                    node.end_lineno - 1]:
                target = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
                found.append((name, node.lineno, target or ""))
    return found


def test_only_the_listed_modules_are_imported_inside_functions() -> None:
    """An import kept in a function by ``noqa: PLC0415`` names one of :data:`DEFERRED`, from
    outside the folder that owns it."""
    wrong = [f"{m}:{line} imports {t} inside a function"
             for m, line, t in deferred_imports()
             if not any((t == k or t.startswith(k + ".")) and not m.startswith(owner)
                        for k, owner in DEFERRED.items())]
    assert wrong == []


def test_the_deferred_import_check_can_fail(tmp_path) -> None:
    pkg = tmp_path / "fidelity"
    (pkg / "pipeline").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "pipeline" / "__init__.py").write_text("")
    (pkg / "pipeline" / "a.py").write_text(
        "def f():\n    from fidelity.coco.emulation import x  # noqa: PLC0415\n"
        "    from fidelity.measure.colour import y  # noqa: PLC0415\n")
    assert deferred_imports(pkg) == [("fidelity.pipeline.a", 2, "fidelity.coco.emulation"),
                                     ("fidelity.pipeline.a", 3, "fidelity.measure.colour")]
