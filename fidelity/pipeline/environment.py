"""What this installation can do: versions, Mitsuba variant, ONNX providers, data found.

:func:`describe_environment` gathers it as a JSON-ready dict for ``fidelity info`` (and for bug
reports and CI logs): the version of every dependency the installed ``fidelity`` distribution
declares (read from its metadata, so the list cannot drift from ``pyproject.toml``), which
Mitsuba variant renders here and with which libLLVM (the probe of
:func:`fidelity.camera.mitsuba.probe_variant`, run in a subprocess), onnxruntime's execution
providers and the ones a detector would use, the COCO scorer ``auto`` picks, whether chart
detection (OpenCV with its contrib modules, cv2.mcc) is usable, the shared data folder and what it
holds, and the prediction tables shipped.

Nothing here changes state; a check that fails is reported as such, never raised.
"""

from __future__ import annotations

import os
import platform
import re
from importlib import metadata  # noqa: TID253 (a command's own module, not on every start-up)
from typing import Any

from fidelity.camera.mitsuba import probe_variant
from fidelity.coco.detectors import default_providers
from fidelity.coco.machine import cpu_description
from fidelity.coco.scoring import resolve_scorer
from fidelity.core.errors import FidelityError
from fidelity.core.resources import shared_dir
from fidelity.core.version import __version__, installed_version
from fidelity.prediction.tablefile import DEFAULT_TABLE, available_tables

__all__ = ["IMPORT_NAMES", "available_cpus", "describe_environment", "dependency_versions",
           "missing_extra"]


def available_cpus() -> int:
    """CPU cores this process may run on (its affinity where the OS tells, else all)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


#: The distribution's name on the package index (the import name is ``fidelity``).
DISTRIBUTION = "camera-fidelity"
#: Extras whose packages the tool runs with (not the test and docs tools).
RUNTIME_EXTRAS = ("render", "scene", "coco", "ray", "fast", "ros", "video", "fit", "ocio", "ssp",
                  "qc")


#: The import name of each package a runtime extra declares (its requirement name where the
#: two differ): a missing module is traced back to the extra that installs it.
IMPORT_NAMES: dict[str, str] = {
    "mitsuba": "mitsuba", "drjit": "drjit", "pygltflib": "pygltflib", "pxr": "usd-core",
    "onnxruntime": "onnxruntime", "onnx": "onnx", "pycocotools": "pycocotools",
    "faster_coco_eval": "faster-coco-eval", "PIL": "Pillow", "tqdm": "tqdm", "ray": "ray",
    "numba": "numba", "rosbags": "rosbags", "av": "av", "PyOpenColorIO": "opencolorio",
    "tomli_w": "tomli-w", "lxml": "lxml", "qc_baselib": "asam-qc-baselib",
}


def missing_extra(module: str | None, distribution: str = DISTRIBUTION) -> tuple[str, str] | None:
    """``(requirement, extra)`` for a module that is not installed (the ``name`` of a
    :class:`ModuleNotFoundError`, dotted or not) when a runtime extra of ``distribution``
    installs it (:data:`IMPORT_NAMES`; of several such extras the one with the fewest
    requirements), else None."""
    requirement = IMPORT_NAMES.get((module or "").split(".")[0])
    if requirement is None:
        return None
    try:
        requires = metadata.requires(distribution) or []
    except metadata.PackageNotFoundError:
        return None
    declared: dict[str, set[str]] = {}
    for req in requires:
        extra = re.search(r"""extra\s*==\s*["']([^"']+)["']""", req)
        name = re.split(r"[\s<>=!~;\[]", req, maxsplit=1)[0]
        if extra:
            declared.setdefault(name.lower(), set()).add(extra.group(1))
    sizes = {e: sum(e in extras for extras in declared.values()) for e in RUNTIME_EXTRAS}
    holding = [e for e in RUNTIME_EXTRAS if e in declared.get(requirement.lower(), set())]
    return (requirement, min(holding, key=lambda e: sizes[e])) if holding else None


def dependency_versions(distribution: str = DISTRIBUTION,
                        extras: tuple[str, ...] = ()) -> dict[str, str | None]:
    """Installed version of each requirement ``distribution`` declares: the core, and those of
    ``extras``; None for a requirement that is not installed."""
    try:
        requires = metadata.requires(distribution) or []
    except metadata.PackageNotFoundError:
        return {}
    out: dict[str, str | None] = {}
    for req in requires:
        extra = re.search(r"""extra\s*==\s*["']([^"']+)["']""", req)
        if extra and extra.group(1) not in extras:
            continue
        name = re.split(r"[\s<>=!~;\[]", req, maxsplit=1)[0]
        if name == distribution:  # an extra that names others ("all")
            continue
        out[name] = installed_version(name)
    return out


def _mitsuba(probe: bool) -> dict[str, Any]:
    if not probe:
        return {"probed": False}

    try:
        p = probe_variant()
    except (FidelityError, ImportError) as exc:
        return {"probed": True, "variant": None, "error": str(exc)}
    return {"probed": True, "variant": p.variant, "libllvm": p.libllvm, "notes": list(p.notes)}


def _onnxruntime() -> dict[str, Any]:
    try:
        import onnxruntime as ort
    except ImportError as exc:  # the [coco] extra is not installed
        return {"error": str(exc), "available": [], "used": []}

    return {"available": list(ort.get_available_providers()), "used": default_providers(),
            "device": ort.get_device()}


def _coco_scorer() -> str | None:
    """The COCO scorer ``auto`` picks; None without the [coco] extra."""
    try:
        return resolve_scorer("auto")
    except (FidelityError, ImportError):
        return None


def _chart_detection() -> dict[str, Any]:
    try:
        import cv2
    except ImportError as exc:
        return {"usable": False, "error": f"{type(exc).__name__}: {exc}"}
    if not hasattr(cv2, "mcc"):
        return {"usable": False, "opencv": cv2.__version__,
                "error": f"OpenCV {cv2.__version__} at {cv2.__file__} has no contrib modules "
                         f"(cv2.mcc): install opencv-contrib-python-headless alone"}
    return {"usable": True, "opencv": cv2.__version__}


def _shared() -> dict[str, Any]:
    folder = shared_dir()
    if folder is None:
        return {"folder": None, "looked_in": os.environ.get("FIDELITY_SHARED") or "../shared "
                "beside the source tree ($FIDELITY_SHARED unset)"}
    ann = folder / "coco" / "annotations"
    images = folder / "coco" / "val2017"
    return {"folder": str(folder),
            "models": sorted(p.name for p in (folder / "models").glob("*.onnx")),
            "coco_images": sum(1 for _ in images.glob("*.jpg")) if images.is_dir() else 0,
            "coco_annotations": sorted(p.name for p in ann.glob("*.json"))}


def describe_environment(probe: bool = True) -> dict[str, Any]:
    """The installation's capabilities (module docstring); ``probe``: run the Mitsuba probe
    (a few seconds, subprocesses)."""
    core = dependency_versions()

    return {
        "fidelity": __version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpus": available_cpus(),
        "cpu": cpu_description(),
        "dependencies": core,
        "extras": {extra: {k: v for k, v in dependency_versions(extras=(extra,)).items()
                           if k not in core} for extra in RUNTIME_EXTRAS},
        "mitsuba": _mitsuba(probe),
        "onnxruntime": _onnxruntime(),
        "coco_scorer": _coco_scorer(),
        "chart_detection": _chart_detection(),
        "shared": _shared(),
        "prediction_tables": {"default": DEFAULT_TABLE, "available": available_tables()},
    }
