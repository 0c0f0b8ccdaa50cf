"""The installed version of the ``camera-fidelity`` distribution (provenance of every record).

A leaf module: recorded by the stores and reports without importing the package's public API
(:mod:`fidelity` re-exports :data:`__version__`).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("camera-fidelity")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+source"

__all__ = ["__version__"]
