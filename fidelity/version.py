"""The version of the ``camera-fidelity`` distribution (provenance of every record), and of any
installed distribution (:func:`installed_version`).

A leaf module: recorded by the stores and reports without importing the package's public API
(:mod:`fidelity` re-exports :data:`__version__`). The one place the version is written: the
build reads it from here (``[tool.hatch.version]`` in ``pyproject.toml``), so the installed
distribution's metadata carries the same string, and no command pays for
``importlib.metadata`` (about 30 ms of start-up) to learn it.
"""

from __future__ import annotations

__version__ = "0.1.0"


def installed_version(distribution: str) -> str | None:
    """The installed version of ``distribution`` (None: not installed), as
    ``importlib.metadata.version`` gives it, read from the ``Version:`` field of its metadata
    header: ``version()`` parses the whole file with the e-mail parser, 5-8 ms for a
    distribution with a long description (SciPy, matplotlib) in every report."""
    import re
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import distribution as find

    try:
        dist = find(distribution)
    except PackageNotFoundError:
        return None
    text = dist.read_text("METADATA") or dist.read_text("PKG-INFO") or ""
    header = text.replace("\r\n", "\n").split("\n\n", 1)[0]
    field = re.search(r"^Version:[ \t]*(\S+)[ \t]*$", header, re.M)
    return field.group(1) if field else dist.version


__all__ = ["__version__", "installed_version"]
