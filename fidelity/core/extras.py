"""The optional extras: a module that one of them installs, imported where it is needed, or one
clear error naming what needs it and the ``pip install`` line that brings it."""

from __future__ import annotations

import importlib
from typing import Any

from fidelity.core.errors import InvalidValueError


def optional_module(name: str, needed_for: str, extra: str) -> Any:
    """Import the module ``name`` that an optional extra installs.

    Parameters
    ----------
    name
        The module's import name (``"PyOpenColorIO"``, ``"mitsuba"``, ...).
    needed_for
        What needs it, as the start of the error's sentence (``"--ocio-colourspace converts
        with OpenColorIO"``).
    extra
        The command that installs it (``"pip install 'camera-fidelity[ocio]'"``).

    Returns
    -------
    module
        The imported module.

    Raises
    ------
    InvalidValueError
        ``"<needed_for>, which is not installed: <extra>"`` when the module cannot be imported.
    """
    try:
        return importlib.import_module(name)
    except ImportError:
        raise InvalidValueError(f"{needed_for}, which is not installed: {extra}") from None


__all__ = ["optional_module"]
