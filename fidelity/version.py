"""The version of the ``camera-fidelity`` distribution (provenance of every record).

A leaf module: recorded by the stores and reports without importing the package's public API
(:mod:`fidelity` re-exports :data:`__version__`). The one place the version is written: the
build reads it from here (``[tool.hatch.version]`` in ``pyproject.toml``), so the installed
distribution's metadata carries the same string, and no command pays for
``importlib.metadata`` (about 30 ms of start-up) to learn it.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
