"""Errors that reach the user.

Every failure caused by input (a missing file, a corrupt image, an unknown name, an unreachable
target) raises a :class:`FidelityError`. The command line prints its message as one line on
stderr and exits with code 2; no traceback.
"""

from __future__ import annotations


class FidelityError(Exception):
    """An error caused by the user's input, with a message that names the input and the problem.

    The base of the typed errors: :class:`InputFileError`, :class:`InvalidValueError`,
    :class:`UnknownNameError`, :class:`UnreachableTargetError`.

    Parameters
    ----------
    *args
        As :class:`Exception`'s: the message, one line that names the input first
        (``<file or value>: <problem>``).

    Attributes
    ----------
    exit_code
        The command line's exit status for this error: 2 (a usage or input error); the CLI
        prints the message on stderr without a traceback.
    """

    exit_code: int = 2


class InputFileError(FidelityError):
    """A file is missing, unreadable, truncated or of the wrong kind."""


class InvalidValueError(FidelityError):
    """A value is out of its domain (NaN, out of range, wrong shape)."""


class RefusedMeasurement(InvalidValueError):
    """A measurement refused for a stated reason (exit code 2).

    Parameters
    ----------
    reason
        A short machine-readable code of why (each measurement lists its codes).
    message
        The one-line message (``<input>: <problem>``).

    Attributes
    ----------
    reason
        The code given.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class UnknownNameError(FidelityError):
    """A name (method, transform, chart, camera, table) is not in its registry."""


class UnreachableTargetError(FidelityError):
    """A target ΔE cannot be reached by a transform inside its parameter range."""


def unknown_name(kind: str, name: str, known: object) -> UnknownNameError:
    """Build an :class:`UnknownNameError` that names the input first, as every input error
    does (``nope: unknown camera; known: ideal, nikon-5100``), and lists the names that are
    known; a name that is empty or has spaces at its ends is quoted."""
    names = ", ".join(sorted(str(k) for k in known))  # type: ignore[attr-defined]
    shown = name if name and name == name.strip() else repr(name)
    return UnknownNameError(f"{shown}: unknown {kind}; known: {names}")
