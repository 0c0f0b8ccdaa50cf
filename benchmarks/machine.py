"""Shared benchmark helpers: the machine a benchmark ran on (:func:`machine_info`), the versions
of what it ran (:func:`versions`), the commit (:func:`commit_info`), and best-of-N timing."""

from __future__ import annotations

import os
import platform
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: The repository root.
REPO = Path(__file__).resolve().parents[1]

#: The distributions whose versions a benchmark record states, where installed (the package's
#: own, its libraries and the anchors' libraries).
DISTRIBUTIONS = ("camera-fidelity", "numpy", "scipy", "colour-science",
                 "opencv-contrib-python-headless", "OpenImageIO", "Pillow", "onnxruntime",
                 "onnxruntime-gpu", "pycocotools", "faster-coco-eval", "numba", "mitsuba",
                 "drjit", "rosbags", "opencolorio", "ray", "imagecorruptions",
                 "colour-checker-detection", "matplotlib")


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


def versions() -> dict[str, str]:
    """Python's version and that of each installed distribution of :data:`DISTRIBUTIONS`
    (``camera-fidelity``: the version of the source the benchmark imports)."""
    from importlib.metadata import PackageNotFoundError, version

    from fidelity.core.version import __version__

    out = {"python": platform.python_version(), "camera-fidelity": __version__}
    for name in DISTRIBUTIONS[1:]:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def commit_info(repo: Path = REPO) -> dict[str, Any] | None:
    """``{"id": short commit, "dirty": uncommitted changes under fidelity/ or benchmarks/}`` of
    the checkout the benchmark ran from; None outside a git checkout."""
    try:
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
                              check=True, capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain", "fidelity",
                                "benchmarks"], check=True, capture_output=True,
                               text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return {"id": head, "dirty": bool(dirty)}


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
