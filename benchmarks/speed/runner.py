"""The one runner of the speed benchmarks: ``python -m benchmarks.speed [NAME ...]``.

It discovers the benchmarks by name (every public module of :mod:`benchmarks.speed` that
defines ``measure`` and ``cases``), sets their parameters (the module's ``PARAMETERS``, ``-p
NAME=VALUE``, ``--quick``), checks what each needs (``NEEDS``), runs it and writes its result in
the one schema (:mod:`benchmarks.speed.record`) to ``reports/benchmarks/NAME.json``: the machine
(:func:`benchmarks.machine.machine_info`), the versions, the commit, the date and load, and per
case the figures of ours and of the anchor measured in the same run and their ratio.

A benchmark module defines:

``ANCHOR``
    what ours is compared against, in words;
``PARAMETERS``
    ``{name: Parameter(default, help)}``; ``QUICK``: the parameters of a smoke run (``--quick``);
``NEEDS``
    what it needs to run here (:data:`NEEDS`): the shared COCO data, Mitsuba, a CUDA device...;
``measure(ctx)``
    the run, with :class:`Context` (parameters, the folder for its other files): returns its
    ``details``, the figures as the benchmark itself records them;
``cases(details)``
    the cases of the one schema, formed from those details (so that a committed result can be
    reshaped again without measuring: ``--report-only``);
``ARTEFACTS`` and ``report(result, folder)`` (optional)
    where its human-readable files go (a table, a figure, an HTML page) and how they are
    written from a result.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple

from benchmarks.machine import REPO, commit_info, machine_info, versions
from benchmarks.speed.record import SCHEMA, Case, Result, problems

#: Where results go: ``reports/benchmarks/NAME.json``.
RESULTS = REPO / "reports" / "benchmarks"
#: Where ``--quick`` results go unless told (ignored by git: ``build/``).
QUICK_RESULTS = REPO / "build" / "benchmarks-quick"
#: Modules of the package that are not benchmarks.
INFRASTRUCTURE = frozenset({"runner", "record", "timing"})


class Parameter(NamedTuple):
    """A benchmark's parameter: its default, what it is, and how a ``-p`` value is read
    (default: the type of the default; ``str`` when the default is None)."""

    default: Any
    help: str
    type: Callable[[str], Any] | None = None

    def parse(self, text: str) -> Any:
        if self.type is not None:
            return self.type(text)
        if isinstance(self.default, bool):
            if text.lower() not in ("1", "0", "true", "false", "yes", "no"):
                raise ValueError(f"not a boolean: {text!r}")
            return text.lower() in ("1", "true", "yes")
        if self.default is None:
            return None if text.lower() in ("", "none") else text
        return type(self.default)(text)


def _have_module(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


def _shared() -> bool:
    from fidelity.core.resources import shared_dir

    return shared_dir() is not None


def _cuda() -> bool:
    try:
        import onnxruntime
    except ImportError:
        return False
    return "CUDAExecutionProvider" in onnxruntime.get_available_providers()


#: What a benchmark may need, and how the runner checks it here.
NEEDS: dict[str, tuple[str, Callable[[], bool]]] = {
    "shared": ("the shared data (../shared or $FIDELITY_SHARED: COCO images, ONNX models)",
               _shared),
    "fidelity-command": ("the fidelity command on PATH (pip install -e .)",
                         lambda: shutil.which("fidelity") is not None),
    "git": ("a git checkout (the anchor is an earlier commit)",
            lambda: (REPO / ".git").exists() and shutil.which("git") is not None),
    "mitsuba": ("Mitsuba 3 (the render extra)", lambda: _have_module("mitsuba")),
    "ray": ("Ray (the ray extra)", lambda: _have_module("ray")),
    "rosbags": ("rosbags (the ros extra)", lambda: _have_module("rosbags")),
    "onnxruntime": ("onnxruntime (the coco extra)", lambda: _have_module("onnxruntime")),
    "imagecorruptions": ("imagecorruptions (the anchor of the COCO-C corruptions)",
                         lambda: _have_module("imagecorruptions")),
    "cuda": ("onnxruntime with the CUDA execution provider", _cuda),
    "blender": ("Blender's Python ($FIDELITY_BPY_PYTHON, docs/simulators.md)",
                lambda: bool(os.environ.get("FIDELITY_BPY_PYTHON"))),
    "opencolorio": ("OpenColorIO (the fit extra)", lambda: _have_module("PyOpenColorIO")),
}


@dataclass(frozen=True)
class Context:
    """What a benchmark's ``measure`` gets: its parameters and the folder for its other files
    (tables, figures, pages: ``ARTEFACTS``, or beside the result when it goes elsewhere)."""

    name: str
    params: dict[str, Any]
    artefacts: Path
    started: float = field(default_factory=time.perf_counter)

    def __getitem__(self, key: str) -> Any:
        return self.params[key]

    def log(self, message: str) -> None:
        print(message, flush=True)


def benchmark_names() -> list[str]:
    """The benchmarks' names: the public modules of :mod:`benchmarks.speed`."""
    import benchmarks.speed

    return sorted(m.name for m in pkgutil.iter_modules(benchmarks.speed.__path__)
                  if not m.name.startswith("_") and m.name not in INFRASTRUCTURE)


def load(name: str) -> ModuleType:
    """The benchmark module ``name``; it must define ``ANCHOR``, ``measure`` and ``cases``."""
    if name not in benchmark_names():
        raise SystemExit(f"benchmarks.speed: no benchmark {name!r} "
                         f"(python -m benchmarks.speed --list)")
    module = importlib.import_module(f"benchmarks.speed.{name}")
    for attr in ("ANCHOR", "measure", "cases"):
        if not hasattr(module, attr):
            raise SystemExit(f"benchmarks.speed.{name}: defines no {attr}")
    return module


def title(module: ModuleType) -> str:
    """The first paragraph of the module's docstring, on one line."""
    first = (module.__doc__ or module.__name__).strip().split("\n\n")[0]
    return " ".join(first.split())


def parameters(module: ModuleType, given: dict[str, str], quick: bool) -> dict[str, Any]:
    """The module's parameters: defaults, then ``QUICK`` (with ``quick``), then ``given``."""
    declared: dict[str, Parameter] = getattr(module, "PARAMETERS", {})
    params = {k: p.default for k, p in declared.items()}
    if quick:
        params.update(getattr(module, "QUICK", {}))
    for key, text in given.items():
        if key in declared:
            params[key] = declared[key].parse(text)
    return params


def missing(module: ModuleType) -> list[str]:
    """What the module needs and this machine lacks, in words."""
    return [NEEDS[n][0] for n in getattr(module, "NEEDS", ()) if not NEEDS[n][1]()]


def result(name: str, module: ModuleType, params: dict[str, Any], details: dict[str, Any], *,
           date: str | None, commit: dict[str, Any] | None, machine: dict[str, Any],
           versions: dict[str, str], load_average: float | None, seconds: float | None,
           converted_from: dict[str, str] | None = None) -> Result:
    """The result of a run in the one schema, its cases formed by the module's ``cases``."""
    cases: list[Case] = module.cases(details)
    doc: dict[str, Any] = {
        "schema": SCHEMA, "benchmark": name, "title": title(module), "anchor": module.ANCHOR,
        "date": date, "commit": commit, "machine": machine, "versions": versions,
        "parameters": params, "load_average": load_average,
        "seconds": None if seconds is None else round(seconds, 1), "cases": cases,
        "details": details}
    if converted_from is not None:
        doc["converted_from"] = converted_from
    return doc  # type: ignore[return-value]


def write(doc: Result, path: Path) -> None:
    """Validate ``doc`` (when jsonschema is installed) and write it to ``path``."""
    from fidelity.core.fileio import write_text_atomic

    try:
        wrong = problems(doc)
    except ImportError:  # pragma: no cover - jsonschema is in the test extra
        wrong = []
    if wrong:
        raise SystemExit(f"{path}: the result does not fit the schema:\n" + "\n".join(wrong))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(doc, indent=1, ensure_ascii=False) + "\n")


def artefacts_folder(module: ModuleType, out: Path) -> Path:
    """Where the module's other files go: its ``ARTEFACTS`` folder for a result written to
    :data:`RESULTS`, else the result's own folder."""
    folder = getattr(module, "ARTEFACTS", None)
    if folder is not None and out.parent.resolve() == RESULTS.resolve():
        return REPO / folder
    return out.parent


def run(name: str, module: ModuleType, params: dict[str, Any], out: Path) -> Result:
    """Measure ``name`` with ``params`` and write its result to ``out``."""
    folder = artefacts_folder(module, out)
    ctx = Context(name, params, folder)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    commit = commit_info()
    machine = machine_info()
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    t0 = time.perf_counter()
    details = module.measure(ctx)
    doc = result(name, module, params, details, date=date, commit=commit, machine=machine,
                 versions=versions(), load_average=None if load is None else round(load, 2),
                 seconds=time.perf_counter() - t0)
    write(doc, out)
    if hasattr(module, "report"):
        folder.mkdir(parents=True, exist_ok=True)
        module.report(doc, folder)
    return doc


def rewrite(name: str, module: ModuleType, path: Path) -> Result:
    """The result at ``path`` with its cases formed again from its details (and the module's
    other files written again from it), without measuring."""
    old = json.loads(path.read_text(encoding="utf-8"))
    keep = {k: old.get(k) for k in ("date", "commit", "machine", "versions", "load_average",
                                    "seconds")}
    doc = result(name, module, old["parameters"], old["details"],
                 converted_from=old.get("converted_from"), **keep)
    write(doc, path)
    if hasattr(module, "report"):
        folder = artefacts_folder(module, path)
        folder.mkdir(parents=True, exist_ok=True)
        module.report(doc, folder)
    return doc


def summary_lines(doc: Result) -> list[str]:
    """One line per case: ours, the anchor and the ratio."""
    lines = []
    for c in doc["cases"]:
        ours, anchor, r = c["ours"], c["anchor"], c["ratio"] or {}

        def fmt(f: dict[str, Any]) -> str:
            text = "-" if f.get("wall_s") is None else f"{f['wall_s']:.4g} s"
            if f.get("max_rss_mb") is not None:
                text += f", {f['max_rss_mb']:.0f} MB"
            return text

        line = f"  {c['name']}: {fmt(dict(ours))}"
        if anchor is not None:
            line += f" against {fmt(dict(anchor))} ({anchor['label']})"
        if r.get("wall") is not None:
            line += f": {r['wall']:.3g}x"
        if r.get("max_rss") is not None:
            line += f", max RSS {r['max_rss']:.3g}x"
        lines.append(line + f" [{c['statistic']}, per {c['per']}]")
    return lines


def describe(name: str) -> str:
    """A benchmark in a few lines (``--list``)."""
    module = load(name)
    lines = [f"{name}: {title(module)}", f"    anchor: {module.ANCHOR}"]
    needs = getattr(module, "NEEDS", ())
    if needs:
        lacking = missing(module)
        lines.append(f"    needs: {', '.join(needs)}"
                     + (f" (missing here: {'; '.join(lacking)})" if lacking else ""))
    for key, p in getattr(module, "PARAMETERS", {}).items():
        lines.append(f"    -p {key}={p.default!r}: {p.help}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.speed",
        description="Run speed benchmarks (every one, or those named) and write each result "
                    "in the one schema to reports/benchmarks/NAME.json.")
    ap.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all)")
    ap.add_argument("--list", action="store_true", help="the benchmarks, anchors, parameters")
    ap.add_argument("-p", "--param", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter of the benchmarks named (--list shows them)")
    ap.add_argument("--quick", action="store_true",
                    help="a smoke run: small parameters, results under build/benchmarks-quick")
    ap.add_argument("--out-dir", type=Path, default=None,
                    help="folder of the results (default reports/benchmarks)")
    ap.add_argument("--out", type=Path, default=None,
                    help="the result file of the one benchmark named (e.g. a second set)")
    ap.add_argument("--report-only", action="store_true",
                    help="form the cases and other files again from the written results")
    args = ap.parse_args(argv)
    names = args.names or benchmark_names()
    if args.list:
        print("\n".join(describe(n) for n in names))
        return 0
    given: dict[str, str] = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            ap.error(f"-p {item}: give NAME=VALUE")
        given[key] = value
    modules = {n: load(n) for n in names}
    unknown = [k for k in given
               if not any(k in getattr(m, "PARAMETERS", {}) for m in modules.values())]
    if unknown:
        ap.error(f"no benchmark of {', '.join(names)} has parameter(s) {', '.join(unknown)}")
    if args.out is not None and len(names) != 1:
        ap.error("--out needs exactly one NAME")
    folder = args.out_dir or (QUICK_RESULTS if args.quick else RESULTS)
    if len(names) > 1 and not args.report_only:
        # one process per benchmark, as each script had: no imports, caches or environment
        # carried from one benchmark into the next
        failed = 0
        for name in names:
            child = [sys.executable, "-m", "benchmarks.speed", name, "--out-dir", str(folder)]
            child += [f"-p{k}={v}" for k, v in given.items()
                      if k in getattr(modules[name], "PARAMETERS", {})]
            child += ["--quick"] if args.quick else []
            code = subprocess.run(child, cwd=REPO, check=False).returncode
            failed += code != 0 and (bool(args.names) or code != 2)
        return 2 if failed else 0
    failed = 0
    for name, module in modules.items():
        out = args.out or folder / f"{name}.json"
        if args.report_only:
            if not out.is_file():
                print(f"{name}: no result {out} to form again", file=sys.stderr)
                failed += 1
                continue
            doc = rewrite(name, module, out)
            print(f"{name}: {out} formed again from its details")
            continue
        lacking = missing(module)
        if lacking:
            print(f"{name}: skipped, needs {'; '.join(lacking)}", file=sys.stderr)
            failed += bool(args.names)
            continue
        params = parameters(module, {k: v for k, v in given.items()
                                     if k in getattr(module, "PARAMETERS", {})}, args.quick)
        print(f"{name}: {title(module)} ({', '.join(f'{k}={v}' for k, v in params.items())})",
              flush=True)
        doc = run(name, module, params, out)
        print("\n".join(summary_lines(doc)))
        print(f"{name}: wrote {out}", flush=True)
    return 2 if failed else 0


__all__ = ["NEEDS", "QUICK_RESULTS", "RESULTS", "Context", "Parameter", "benchmark_names",
           "load", "main", "parameters", "result", "rewrite", "run", "write"]
