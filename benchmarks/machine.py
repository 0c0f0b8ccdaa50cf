"""Shared benchmark helpers: the machine a benchmark ran on, and best-of-N timing."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from typing import Any


def machine_info() -> dict[str, Any]:
    """CPU model, core count, OS, Python and key library versions."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numpy

    info: dict[str, Any] = {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
    }
    try:
        import colour

        info["colour-science"] = colour.__version__
    except ImportError:  # pragma: no cover
        pass
    return info


def best_time(fn: Callable[[], object], repeats: int) -> float:
    """Best (smallest) wall time in seconds of ``repeats`` calls of ``fn``."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def machine_words() -> str:
    """``"CPU, N cores"`` of :func:`machine_info` (a report's line about the machine)."""
    m = machine_info()
    return f"{m['cpu']}, {m['cores']} cores"


def write_report(out: str | os.PathLike[str], doc: dict[str, Any], markdown: str) -> None:
    """``OUT.json`` (``doc``) and ``OUT.md`` (``markdown``), each written atomically, and the
    Markdown printed."""
    import json
    from pathlib import Path

    from fidelity.core.fileio import write_text_atomic

    path = Path(out)
    write_text_atomic(path.with_suffix(".json"), json.dumps(doc, indent=1) + "\n")
    write_text_atomic(path.with_suffix(".md"), markdown)
    print(markdown)
